/* The training loop: iterations, CSV log, validation, periodic atomic checkpoints, the time
 * limit and stop requests, then the final model, checkpoint and plot.
 *
 * CSV columns: iter,stage,lr,loss,its_per_s,elapsed_s,val_relmse,val_ssim,val_psnr,
 * val_relmse_geo
 * (loss = mean training loss since the previous row; validation columns empty when no
 * validation ran at that iteration). A run that stops early (time limit, signal) ends with a
 * validation row at its last iteration; on resume the log is cut back to the rows at or before
 * the checkpoint's iteration, without that stop row, and the loss accumulator comes back from
 * the checkpoint, so the log reads as one uninterrupted run (but for its wall-clock columns).
 * A fresh run writes its log under a temporary name until its first checkpoint: a run that
 * fails before it leaves an earlier run's log (and model) as they were. */
#include "core/internal.h"
#include "train/train_internal.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define CSV_HEADER                                                                                 \
  "iter,stage,lr,loss,its_per_s,elapsed_s,val_relmse,val_ssim,val_psnr,val_relmse_geo\n"

/* Whether an uninterrupted run writes a CSV row at iteration it (run's do_log). */
static int regular_row(const kpcn_trainer *t, int64_t it) {
  return it % t->s.log_every == 0 || it == t->s.iters ||
         (t->nval && t->s.val_every > 0 && it % t->s.val_every == 0);
}

/* The CSV log being written: its stream, and while uncommitted (a fresh run before its first
 * checkpoint) the temporary name it is written under. */
typedef struct csv_log {
  FILE *f;
  const char *path;
  char tmp[4096];
  int committed;
} csv_log;

/* Gives the log its name (once): the run has a checkpoint the log belongs to. */
static kpcn_status csv_commit(csv_log *c) {
  if (!c->f || c->committed) return KPCN_OK;
  if (fflush(c->f) != 0) return kpcn_fail(KPCN_ERR_IO, "cannot write CSV log '%s'", c->path);
  KPCN_TRY(kpcn_commit_file(c->tmp, c->path)); /* a rename: the open stream follows it */
  c->committed = 1;
  return KPCN_OK;
}

/* Closes the log; an uncommitted one is removed (the run failed before its first checkpoint,
 * so an earlier run's log stays). */
static void csv_close(csv_log *c) {
  if (!c->f) return;
  fclose(c->f);
  c->f = NULL;
  if (!c->committed) kpcn_abort_file(c->tmp);
}

/* Opens the CSV for appending: fresh (header only, under a temporary name) or cut back to the
 * rows an uninterrupted run has at or before keep_iter (the checkpoint's iteration). best_val
 * receives the lowest value of column best_col (1-based: 7 val_relmse, 10 val_relmse_geo)
 * among the kept rows (+inf if none), so a resumed run keeps the best-model record of the
 * interrupted one. */
static kpcn_status csv_open(const kpcn_trainer *t, const char *path, int resume, int64_t keep_iter,
                            int best_col, csv_log *out, double *best_val) {
  memset(out, 0, sizeof *out);
  out->path = path;
  *best_val = INFINITY;
  if (!path || !*path) return KPCN_OK;
  char *kept = NULL;
  size_t klen = 0;
  if (resume) {
    FILE *in = kpcn_fopen_input(path, NULL);
    if (in) {
      char line[1024];
      size_t cap = 1 << 16;
      kept = kpcn_alloc(cap, "CSV log");
      if (!kept) {
        fclose(in);
        return kpcn_last_status();
      }
      int64_t prev = -1;
      while (fgets(line, sizeof line, in)) {
        if (strncmp(line, "iter,", 5) == 0) continue;
        long long it = strtoll(line, NULL, 10);
        if (it > keep_iter) continue;
        /* a stop row: the last iteration of an interrupted session, which an uninterrupted
         * run has no row for (or has its regular row for, first) */
        if (it == keep_iter && (it == prev || !regular_row(t, it))) continue;
        prev = it;
        const char *c = line; /* column best_col follows comma best_col - 1 */
        for (int k = 0; k < best_col - 1 && c; k++)
          c = strchr(c, ','), c = c ? c + 1 : NULL;
        if (c && *c && *c != ',') {
          double v = strtod(c, NULL);
          if (v < *best_val) *best_val = v;
        }
        size_t l = strlen(line);
        if (klen + l + 1 > cap) {
          char *nk = realloc(kept, cap * 2 + l);
          if (!nk) {
            free(kept);
            fclose(in);
            return kpcn_fail(KPCN_ERR_OUT_OF_MEMORY, "CSV log '%s'", path);
          }
          kept = nk, cap = cap * 2 + l;
        }
        memcpy(kept + klen, line, l);
        klen += l;
      }
      fclose(in);
    }
  }
  if (kpcn_temp_path(out->tmp, sizeof out->tmp, path) != KPCN_OK) {
    free(kept);
    return kpcn_last_status();
  }
  out->f = fopen(out->tmp, "w");
  if (!out->f) {
    free(kept);
    return kpcn_fail(KPCN_ERR_IO, "cannot write CSV log '%s': %s", path, strerror(errno));
  }
  fputs(CSV_HEADER, out->f);
  if (klen) fwrite(kept, 1, klen, out->f);
  free(kept);
  /* a resumed run's log belongs to the checkpoint it resumes from: named at once */
  if (resume) {
    kpcn_status st = csv_commit(out);
    if (st != KPCN_OK) {
      csv_close(out);
      return st;
    }
  }
  return KPCN_OK;
}

static kpcn_status save_model(kpcn_trainer *t, double elapsed, const char *path) {
  char buf[64];
  snprintf(buf, sizeof buf, "%lld", (long long)t->iter);
  KPCN_TRY(kpcn_model_set_meta(t->model, "train.iterations", buf));
  snprintf(buf, sizeof buf, "%lld", (long long)t->s.stage1_iters);
  KPCN_TRY(kpcn_model_set_meta(t->model, "train.stage1_iters", buf));
  snprintf(buf, sizeof buf, "%s/%s", kpcn_loss_name(t->s.loss1), kpcn_loss_name(t->s.loss2));
  KPCN_TRY(kpcn_model_set_meta(t->model, "train.loss", buf));
  snprintf(buf, sizeof buf, "%.1f", elapsed);
  KPCN_TRY(kpcn_model_set_meta(t->model, "train.seconds", buf));
  snprintf(buf, sizeof buf, "%llu", (unsigned long long)t->s.seed);
  KPCN_TRY(kpcn_model_set_meta(t->model, "train.seed", buf));
  snprintf(buf, sizeof buf, "%d x %dx%d", t->N, t->P, t->P);
  KPCN_TRY(kpcn_model_set_meta(t->model, "train.batch", buf));
  /* always written: a model fine-tuned from one trained with a frozen branch must not
   * inherit that key */
  KPCN_TRY(kpcn_model_set_meta(t->model, "train.frozen", kt_frozen_name(&t->s)));
  const char *slash = strrchr(t->store_path, '/');
  KPCN_TRY(kpcn_model_set_meta(t->model, "train.dataset", slash ? slash + 1 : t->store_path));
  return kpcn_model_save(t->model, path);
}

static kpcn_status checkpoint(kpcn_trainer *t, double elapsed, csv_log *csv) {
  double keep = t->elapsed_prev;
  t->elapsed_prev = elapsed;
  /* an empty checkpoint path means none (kpcn-train --ckpt ''): snapshots are still kept */
  kpcn_status st = *t->ckpt_path ? kt_checkpoint_save(t, t->ckpt_path) : KPCN_OK;
  if (st == KPCN_OK && t->snapshot_dir) {
    char snap[4096];
    snprintf(snap, sizeof snap, "%s/ckpt_%06lld.safetensors", t->snapshot_dir, (long long)t->iter);
    st = kt_checkpoint_save(t, snap);
  }
  t->elapsed_prev = keep;
  if (st == KPCN_OK) st = csv_commit(csv);
  if (st == KPCN_OK && *t->ckpt_path)
    kpcn_log(t->s.log, t->s.log_user, KPCN_LOG_INFO, "checkpoint '%s' at iteration %lld",
             t->ckpt_path, (long long)t->iter);
  return st;
}

/* The validation figure that picks the best model. */
static double best_figure(const kpcn_trainer *t, const kpcn_val_result *v) {
  return t->s.best_by == KPCN_VAL_GEOMEAN ? v->relmse_geo : v->relmse;
}

static void log_val(const kpcn_trainer *t, const char *what, const kpcn_val_result *v) {
  kpcn_log(t->s.log, t->s.log_user, KPCN_LOG_INFO,
           "%s: relMSE %.4g (geometric mean %.4g)  SSIM %.4f  PSNR %.2f dB (linear)", what,
           v->relmse, v->relmse_geo, v->ssim, v->psnr);
}

/* A fine-tune's starting point, before its first step: the --init model as given (at its own
 * recorded exposure, as kpcntool --denoise runs it) and, when the store's differs, at the
 * store's exposure, which the trained model records instead (training.md, "Exposure"): its
 * later figures compare with that one. Leaves the model and the last validation as they were. */
static kpcn_status validate_init(kpcn_trainer *t, kpcn_val_result *given) {
  const float store_exposure = kpcn_model_arch(t->model)->exposure;
  const kpcn_val_result last = t->last_val;
  const int had = t->have_val;
  kpcn_status st = KPCN_OK;
  if (t->init_exposure != store_exposure) {
    kpcn_val_result at_store;
    st = kpcn_trainer_validate(t, &at_store);
    if (st == KPCN_OK) {
      char what[160];
      snprintf(what, sizeof what, "the --init model at the store's exposure %.6g", store_exposure);
      log_val(t, what, &at_store);
    }
    if (st == KPCN_OK) st = kpcn_model_set_exposure(t->model, t->init_exposure);
  }
  if (st == KPCN_OK) st = kpcn_trainer_validate(t, given);
  if (t->init_exposure != store_exposure) {
    kpcn_status r = kpcn_model_set_exposure(t->model, store_exposure);
    if (st == KPCN_OK) st = r;
  }
  t->last_val = last;
  t->have_val = had;
  KPCN_TRY(st);
  char what[160];
  snprintf(what, sizeof what, "the --init model as given (exposure %.6g)", t->init_exposure);
  log_val(t, what, given);
  return KPCN_OK;
}

kpcn_status kpcn_trainer_run(kpcn_trainer *t, int *stopped) {
  if (!t) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_trainer_run: NULL trainer");
  if (stopped) *stopped = 0;
  csv_log csvlog;
  double best_csv;
  KPCN_TRY(csv_open(t, t->csv_path, t->s.resume, t->iter, t->s.best_by == KPCN_VAL_GEOMEAN ? 10 : 7,
                    &csvlog, &best_csv));
  FILE *csv = csvlog.f;
  /* the checkpoint's record of the best model kept, else (older checkpoints) the CSV's best
   * validation row */
  if (t->s.resume && t->ckpt_best == 0) t->best_val = best_csv;
  if (t->s.resume && t->ckpt_best == 2) t->best_val = INFINITY;
  if (t->s.resume && t->ckpt_best == 2 && t->best_path && t->iter > 0)
    kpcn_log(t->s.log, t->s.log_user, KPCN_LOG_INFO,
             "no best model was kept before iteration %lld: '%s' will hold the best from here on",
             (long long)t->iter, t->best_path);
  const double t0 = kt_now();
  double last_t = t0;
  int64_t last_it = t->iter, last_val_it = -1, start_it = t->iter;
  int stop = 0;
  kpcn_status st = KPCN_OK;
  /* the inputs' own figures first: a validation relMSE means little without them */
  kpcn_val_result noisy, init;
  const int have_init = t->nval && t->s.init_model && !t->s.resume && t->iter == 0;
  if (t->nval) {
    st = kpcn_trainer_validate_noisy(t, &noisy);
    if (st == KPCN_OK) log_val(t, "validation inputs as rendered (noisy)", &noisy);
    if (st == KPCN_OK && have_init) st = validate_init(t, &init);
    if (st != KPCN_OK) {
      csv_close(&csvlog);
      return st;
    }
  }
  while (t->iter < t->s.iters && st == KPCN_OK) {
    double elapsed = t->elapsed_prev + (kt_now() - t0);
    if (t->s.time_limit_s > 0 && kt_now() - t0 >= t->s.time_limit_s) {
      kpcn_log(t->s.log, t->s.log_user, KPCN_LOG_INFO,
               "time limit reached at iteration %lld: checkpointing", (long long)t->iter);
      stop = 1;
      break;
    }
    int stage = t->iter < t->s.stage1_iters ? 1 : 2;
    double lr = kt_lr_at(t, t->iter), loss = 0;
    if ((st = kpcn_trainer_step(t, &loss)) != KPCN_OK) break;
    t->log_loss_sum += loss, t->log_loss_n++;
    int64_t it = t->iter;
    int do_val = t->nval && ((t->s.val_every > 0 && it % t->s.val_every == 0) || it == t->s.iters);
    int do_log = it % t->s.log_every == 0 || it == t->s.iters || do_val;
    kpcn_train_progress p;
    memset(&p, 0, sizeof p);
    kpcn_val_result v;
    if (do_val) {
      if ((st = kpcn_trainer_validate(t, &v)) != KPCN_OK) break;
      p.val_relmse = v.relmse, p.val_ssim = v.ssim, p.val_psnr = v.psnr;
      p.val_relmse_geo = v.relmse_geo;
      p.has_val = 1;
      last_val_it = it;
    }
    double now = kt_now();
    elapsed = t->elapsed_prev + (now - t0);
    if (p.has_val && t->best_path && best_figure(t, &v) < t->best_val) {
      if ((st = save_model(t, elapsed, t->best_path)) != KPCN_OK) break;
      t->best_val = best_figure(t, &v);
      kpcn_log(t->s.log, t->s.log_user, KPCN_LOG_INFO,
               "best model so far (val relMSE %s %.4g) written to '%s' at iteration %lld",
               t->s.best_by == KPCN_VAL_GEOMEAN ? "geometric mean" : "mean", t->best_val,
               t->best_path, (long long)it);
    }
    p.iter = it;
    p.total = t->s.iters;
    p.stage = stage;
    p.loss = t->log_loss_sum / (double)t->log_loss_n;
    p.lr = lr;
    p.its_per_s = (double)(it - last_it) / fmax(now - last_t, 1e-9);
    p.elapsed_s = elapsed;
    p.eta_s = (double)(t->s.iters - it) / fmax(p.its_per_s, 1e-9);
    if (do_log) {
      if (csv) {
        fprintf(csv, "%lld,%d,%.6g,%.9g,%.4g,%.2f", (long long)it, stage, lr, p.loss, p.its_per_s,
                elapsed);
        if (p.has_val)
          fprintf(csv, ",%.9g,%.9g,%.6g,%.9g\n", p.val_relmse, p.val_ssim, p.val_psnr,
                  p.val_relmse_geo);
        else
          fputs(",,,,\n", csv);
        fflush(csv);
      }
      t->log_loss_sum = 0, t->log_loss_n = 0, last_it = it, last_t = now;
    }
    if (t->s.ckpt_every > 0 && it % t->s.ckpt_every == 0 && it < t->s.iters)
      if ((st = checkpoint(t, elapsed, &csvlog)) != KPCN_OK) break;
    if (t->s.progress && t->s.progress(t->s.progress_user, &p)) {
      stop = 1;
      break;
    }
  }
  /* a run that stopped early (time limit, request) still ends with a validation row, so
   * equal-time comparisons have a final figure. It does not pick --best (an uninterrupted run
   * validates only every --val-every), and a resume drops it (csv_open). */
  if (st == KPCN_OK && t->nval && last_val_it != t->iter && t->iter > start_it) {
    kpcn_val_result v;
    st = kpcn_trainer_validate(t, &v);
    if (st == KPCN_OK && csv) {
      double now = kt_now();
      fprintf(csv, "%lld,%d,%.6g,", (long long)t->iter, t->iter - 1 < t->s.stage1_iters ? 1 : 2,
              kt_lr_at(t, t->iter - 1));
      if (t->log_loss_n) fprintf(csv, "%.9g", t->log_loss_sum / (double)t->log_loss_n);
      /* no iterations since the last row: no rate (an empty cell, as the loss's) */
      fputc(',', csv);
      if (t->iter > last_it)
        fprintf(csv, "%.4g", (double)(t->iter - last_it) / fmax(now - last_t, 1e-9));
      fprintf(csv, ",%.2f,%.9g,%.9g,%.6g,%.9g\n", t->elapsed_prev + (now - t0), v.relmse, v.ssim,
              v.psnr, v.relmse_geo);
      fflush(csv);
    }
  }
  if (st != KPCN_OK) {
    csv_close(&csvlog);
    return st;
  }
  if (t->nval && t->have_val && t->last_val.relmse_geo > noisy.relmse_geo)
    kpcn_log(t->s.log, t->s.log_user, KPCN_LOG_WARNING,
             "the model is worse than its noisy inputs on the validation pairs (relMSE geometric "
             "mean %.4g against %.4g as rendered): train longer, on more data, or fine-tune a "
             "trained model (--init; docs/training.md, \"Train your own\")",
             t->last_val.relmse_geo, noisy.relmse_geo);
  else if (have_init && t->have_val && t->last_val.relmse_geo > init.relmse_geo)
    kpcn_log(t->s.log, t->s.log_user, KPCN_LOG_WARNING,
             "the model ends worse than the --init model as given on the validation pairs "
             "(relMSE geometric mean %.4g against %.4g): keep the --init model, or train with "
             "a lower learning rate or on more data",
             t->last_val.relmse_geo, init.relmse_geo);
  double elapsed = t->elapsed_prev + (kt_now() - t0);
  st = checkpoint(t, elapsed, &csvlog);
  csv_close(&csvlog);
  KPCN_TRY(st);
  KPCN_TRY(save_model(t, elapsed, t->out_path));
  if (t->plot_path && *t->plot_path && t->csv_path && *t->csv_path)
    KPCN_TRY(kpcn_train_plot_csv(t->csv_path, t->plot_path, "kpcn-train"));
  if (stopped) *stopped = stop;
  return KPCN_OK;
}
