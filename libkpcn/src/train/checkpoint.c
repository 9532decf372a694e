/* Training checkpoints: ONE safetensors file (inspectable with Python's safetensors)
 * written atomically (temp file + rename), holding
 *   tensors  "<branch>.conv<l>.weight|bias"            the weights (names as the model file)
 *            "adam.m.<name>", "adam.v.<name>"           Adam moments, F32, 1-D
 *   __metadata__ (strings)
 *            kpcn.format        "kpcn-checkpoint-1"
 *            kpcn.architecture  kpcn_arch_to_json (must equal the trainer's on load)
 *            train.iteration, train.rng (hex splitmix64 word), train.adam_steps.<branch>,
 *            train.elapsed_s, train.seed, train.batch, train.patch, train.stage1_iters,
 *            train.precision ("f32" | "bf16"), train.loss1, train.loss2,
 *            train.log_loss_sum, train.log_loss_n (the CSV's loss accumulator; session 60)
 * Loading checks format, architecture and the settings that change the trajectory (seed,
 * batch, patch, stage-1 length, precision) and names the first mismatch with its option. A
 * stage-1 length left to its default (0.6 * iters) is taken from the checkpoint, so a resume
 * may raise --iters. */
#include "core/internal.h"
#include "train/train_internal.h"

#include <cjson/cJSON.h>
#include <errno.h>
#include <inttypes.h>
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define CKPT_FORMAT "kpcn-checkpoint-1"

typedef struct ck_tensor {
  char name[64];
  float *data;
  size_t count;
} ck_tensor;

/* The tensor list in file order; returns count (tensors may be NULL to count). */
static int ck_list(kpcn_trainer *t, ck_tensor *ts) {
  int n = 0;
  for (int kind = 0; kind < 3; kind++)
    for (int b = 0; b < KT_NB; b++) {
      size_t off = 0;
      for (int i = 0; i < t->nparams[b]; i++) {
        const kpcn_param *p = &t->params[b][i];
        if (ts) {
          static const char *pre[3] = {"", "adam.m.", "adam.v."};
          snprintf(ts[n].name, sizeof ts[n].name, "%s%s", pre[kind], p->name);
          ts[n].count = p->count;
          ts[n].data = kind == 0   ? p->value
                       : kind == 1 ? kpcn_adam_moment1(t->adam[b]) + off
                                   : kpcn_adam_moment2(t->adam[b]) + off;
        }
        off += p->count;
        n++;
      }
    }
  return n;
}

/* Settings that change what the remaining iterations compute: a resumed run must use the
 * values its checkpoint was written with, or it would not continue bit-exactly. Written as
 * strings; a key an older checkpoint lacks is not checked. (Architecture, seed, batch, patch,
 * stage split, precision, exposure normalisation and firefly bound are checked separately.) */
enum { CK_NSET = 14 };
typedef struct ck_setting {
  const char *key, *option;
  char value[64];
} ck_setting;

static int ck_settings(const kpcn_trainer *t, ck_setting out[CK_NSET]) {
  const kpcn_train_settings *s = &t->s;
  const int ssim = s->loss1 == KPCN_LOSS_SSIM || s->loss2 == KPCN_LOSS_SSIM;
  int n = 0;
#define SET(k, opt, ...)                                                                           \
  do {                                                                                             \
    out[n].key = k, out[n].option = opt;                                                           \
    snprintf(out[n].value, sizeof out[n].value, __VA_ARGS__);                                      \
    n++;                                                                                           \
  } while (0)
  SET("train.loss1", "--loss", "%s", kpcn_loss_name(s->loss1));
  SET("train.loss2", "--loss2", "%s", kpcn_loss_name(s->loss2));
  SET("train.lr", "--lr", "%.17g", s->adam.lr);
  SET("train.lr2", "--lr2", "%.17g", s->stage2_lr);
  SET("train.lr_decay", "--lr-decay", "%.17g", s->adam.lr_decay);
  SET("train.decay_every", "--decay-every", "%lld", (long long)s->adam.decay_every);
  SET("train.staircase", "--staircase", "%d", s->adam.staircase);
  SET("train.clip", "--clip", "%.17g", s->adam.clip_norm);
  SET("train.loss_margin", "--loss-margin", "%d", s->loss_margin);
  SET("train.ssim_window", "--ssim-window", "%d", ssim ? s->loss.ssim_window : 0);
  SET("train.augment", "--no-colorswap/--no-mirror/--no-rotate",
      "colorswap %d mirror %d mirror_v %d rotate %d shift %d mode %d", s->augment.colorswap,
      s->augment.mirror, s->augment.mirror_v, s->augment.rotate, s->augment.max_shift,
      (int)s->augment.mode);
  SET("train.crop_jitter", "--no-shift", "%d", s->crop_jitter);
  SET("train.source_lr_scale", "--source-lr-scale", "%.17g",
      t->arch.source_weight ? s->source_lr_scale : 0.0);
  /* what identifies the patches a run draws from (the draws depend on the count) */
  SET("train.store", "--store", "%llu patches of %d px, %d channels, %d sources",
      (unsigned long long)kpcn_patchstore_count(t->ps), kpcn_patchstore_patch_size(t->ps),
      kpcn_patchstore_nchannels(t->ps), kpcn_patchstore_nsources(t->ps));
#undef SET
  return n;
}

static void meta_i64(cJSON *m, const char *k, int64_t v) {
  char buf[32];
  snprintf(buf, sizeof buf, "%" PRId64, v);
  cJSON_AddStringToObject(m, k, buf);
}

kpcn_status kt_checkpoint_save(kpcn_trainer *t, const char *path) {
  int n = ck_list(t, NULL);
  ck_tensor *ts = kpcn_calloc((size_t)n, sizeof *ts, "checkpoint tensor list");
  if (!ts) return kpcn_last_status();
  ck_list(t, ts);
  cJSON *root = cJSON_CreateObject(), *meta = cJSON_CreateObject();
  char *arch = kpcn_arch_to_json(&t->arch), buf[64];
  cJSON_AddStringToObject(meta, "kpcn.format", CKPT_FORMAT);
  cJSON_AddStringToObject(meta, "kpcn.architecture", arch ? arch : "");
  free(arch);
  meta_i64(meta, "train.iteration", t->iter);
  snprintf(buf, sizeof buf, "%016" PRIx64, t->rng.state);
  cJSON_AddStringToObject(meta, "train.rng", buf);
  meta_i64(meta, "train.adam_steps.diffuse", kpcn_adam_steps(t->adam[0]));
  meta_i64(meta, "train.adam_steps.specular", kpcn_adam_steps(t->adam[1]));
  snprintf(buf, sizeof buf, "%.17g", t->elapsed_prev);
  cJSON_AddStringToObject(meta, "train.elapsed_s", buf);
  snprintf(buf, sizeof buf, "%.17g", t->log_loss_sum);
  cJSON_AddStringToObject(meta, "train.log_loss_sum", buf);
  meta_i64(meta, "train.log_loss_n", t->log_loss_n);
  snprintf(buf, sizeof buf, "%" PRIu64, t->s.seed);
  cJSON_AddStringToObject(meta, "train.seed", buf);
  meta_i64(meta, "train.batch", t->N);
  meta_i64(meta, "train.patch", t->P);
  meta_i64(meta, "train.stage1_iters", t->s.stage1_iters);
  cJSON_AddStringToObject(meta, "train.precision", t->s.bf16 ? "bf16" : "f32");
  if (t->s.normalize_exposure) cJSON_AddStringToObject(meta, "train.normalize_exposure", "1");
  if (t->s.frozen[0] || t->s.frozen[1])
    cJSON_AddStringToObject(meta, "train.frozen", kt_frozen_name(&t->s));
  if (t->s.firefly > 0.0) {
    snprintf(buf, sizeof buf, "%.17g", t->s.firefly);
    cJSON_AddStringToObject(meta, "train.firefly", buf);
  }
  ck_setting set[CK_NSET];
  for (int i = 0, ns = ck_settings(t, set); i < ns; i++)
    cJSON_AddStringToObject(meta, set[i].key, set[i].value);
  /* the best model kept so far, so that a resume keeps comparing against it (the CSV, which
   * earlier checkpoints relied on, may be off); "none": no best model was written. A session
   * without --best passes on the record it resumed from. */
  if (isfinite(t->best_val) && (t->best_path || t->ckpt_best == 1)) {
    snprintf(buf, sizeof buf, "%.17g", t->best_val);
    cJSON_AddStringToObject(meta, "train.best_val", buf);
    cJSON_AddStringToObject(meta, "train.best_by",
                            t->s.best_by == KPCN_VAL_GEOMEAN ? "geomean" : "mean");
  } else {
    cJSON_AddStringToObject(meta, "train.best_val", "none");
  }
  cJSON_AddItemToObject(root, "__metadata__", meta);
  uint64_t off = 0;
  for (int i = 0; i < n; i++) {
    cJSON *e = cJSON_CreateObject();
    cJSON_AddStringToObject(e, "dtype", "F32");
    double shape[1] = {(double)ts[i].count};
    cJSON_AddItemToObject(e, "shape", cJSON_CreateDoubleArray(shape, 1));
    double offs[2] = {(double)off, (double)(off + ts[i].count * 4)};
    cJSON_AddItemToObject(e, "data_offsets", cJSON_CreateDoubleArray(offs, 2));
    cJSON_AddItemToObject(root, ts[i].name, e);
    off += ts[i].count * 4;
  }
  char *hdr = cJSON_PrintUnformatted(root);
  cJSON_Delete(root);
  if (!hdr) {
    free(ts);
    return kpcn_fail(KPCN_ERR_OUT_OF_MEMORY, "out of memory for the checkpoint header");
  }
  size_t hl = strlen(hdr), padded = (hl + 7) / 8 * 8;
  char tmp[4096];
  kpcn_status st = kpcn_temp_path(tmp, sizeof tmp, path);
  FILE *f = st == KPCN_OK ? fopen(tmp, "wb") : NULL;
  if (st == KPCN_OK && !f) {
    st = kpcn_fail(KPCN_ERR_IO, "cannot write checkpoint '%s': %s", path, strerror(errno));
  } else if (f) {
    unsigned char len[8];
    for (int i = 0; i < 8; i++)
      len[i] = (unsigned char)((uint64_t)padded >> (8 * i));
    int ok = fwrite(len, 1, 8, f) == 8 && fwrite(hdr, 1, hl, f) == hl;
    for (size_t i = hl; i < padded && ok; i++)
      ok = fputc(' ', f) != EOF;
    for (int i = 0; i < n && ok; i++) /* little-endian host (x86-64) */
      ok = fwrite(ts[i].data, 4, ts[i].count, f) == ts[i].count;
    int err = ok ? 0 : errno; /* the failed call's reason, before fclose can change errno */
    if (fclose(f) != 0 && ok) ok = 0, err = errno;
    if (!ok) {
      kpcn_abort_file(tmp);
      st = kpcn_fail(KPCN_ERR_IO, "writing checkpoint '%s' failed: %s", path,
                     kpcn_write_reason(err));
    } else {
      st = kpcn_commit_file(tmp, path);
    }
  }
  free(hdr);
  free(ts);
  return st;
}

static const char *meta_str(cJSON *meta, const char *key) {
  cJSON *e = cJSON_GetObjectItemCaseSensitive(meta, key);
  return cJSON_IsString(e) ? e->valuestring : NULL;
}

static kpcn_status meta_expect(cJSON *meta, const char *key, const char *option, long long want,
                               const char *path, long long *got) {
  const char *s = meta_str(meta, key);
  char *end = NULL;
  long long v = s ? strtoll(s, &end, 10) : 0;
  if (!s || !end || *end)
    return kpcn_fail(KPCN_ERR_FORMAT, "checkpoint '%s': metadata '%s' missing or malformed", path,
                     key);
  if (got) {
    *got = v;
    return KPCN_OK;
  }
  if (v != want)
    return kpcn_fail(KPCN_ERR_FORMAT,
                     "checkpoint '%s' was written with %s = %lld, this run uses %lld (%s): a "
                     "resumed run must keep its settings",
                     path, key, v, want, option);
  return KPCN_OK;
}

/* An open checkpoint: its parsed header and where the tensor data starts. */
typedef struct ck_file {
  FILE *f;
  char *hdr;
  cJSON *root, *meta;
  uint64_t fsize, data0;
} ck_file;

static void ck_close(ck_file *c) {
  if (c->f) fclose(c->f);
  cJSON_Delete(c->root);
  free(c->hdr);
  memset(c, 0, sizeof *c);
}

/* Fails with KPCN_ERR_FORMAT and jumps to the function's cleanup label `done`. */
#define BAD(...)                                                                                   \
  do {                                                                                             \
    st = kpcn_fail(KPCN_ERR_FORMAT, __VA_ARGS__);                                                  \
    goto done;                                                                                     \
  } while (0)

/* Opens path, reads and parses the header and checks kpcn.format; on failure everything is
 * closed again. */
static kpcn_status ck_open(const char *path, ck_file *c) {
  memset(c, 0, sizeof *c);
  const char *why;
  c->f = kpcn_fopen_input(path, &why);
  if (!c->f) return kpcn_fail(KPCN_ERR_IO, "cannot open checkpoint '%s': %s", path, why);
  kpcn_status st = KPCN_OK;
  unsigned char len8[8];
  uint64_t hl = 0;
  fseek(c->f, 0, SEEK_END);
  c->fsize = (uint64_t)ftell(c->f);
  fseek(c->f, 0, SEEK_SET);
  if (fread(len8, 1, 8, c->f) != 8) BAD("checkpoint '%s' is truncated (no header length)", path);
  for (int i = 0; i < 8; i++)
    hl |= (uint64_t)len8[i] << (8 * i);
  if (hl == 0 || hl > c->fsize - 8 || hl > (64u << 20))
    BAD("checkpoint '%s': header length %" PRIu64 " does not fit the %" PRIu64 "-byte file", path,
        hl, c->fsize);
  c->hdr = kpcn_alloc(hl + 1, "checkpoint header");
  if (!c->hdr) {
    st = kpcn_last_status();
    goto done;
  }
  if (fread(c->hdr, 1, hl, c->f) != hl) BAD("checkpoint '%s' is truncated (header)", path);
  c->hdr[hl] = 0;
  c->data0 = 8 + hl;
  c->root = cJSON_Parse(c->hdr);
  if (!c->root) BAD("checkpoint '%s': header is not JSON", path);
  c->meta = cJSON_GetObjectItemCaseSensitive(c->root, "__metadata__");
  const char *fmt = meta_str(c->meta, "kpcn.format");
  if (!fmt || strcmp(fmt, CKPT_FORMAT) != 0)
    BAD("checkpoint '%s': kpcn.format is '%s', expected '" CKPT_FORMAT "'", path,
        fmt ? fmt : "(missing)");
done:
  if (st != KPCN_OK) ck_close(c);
  return st;
}

/* Reads the n listed tensors (F32, exact sizes, offsets inside the file). */
static kpcn_status ck_read(ck_file *c, const char *path, const ck_tensor *ts, int n) {
  kpcn_status st = KPCN_OK;
  for (int i = 0; i < n; i++) {
    cJSON *e = cJSON_GetObjectItemCaseSensitive(c->root, ts[i].name);
    if (!e) BAD("checkpoint '%s' lacks tensor '%s'", path, ts[i].name);
    cJSON *dt = cJSON_GetObjectItemCaseSensitive(e, "dtype");
    cJSON *of = cJSON_GetObjectItemCaseSensitive(e, "data_offsets");
    if (!cJSON_IsString(dt) || strcmp(dt->valuestring, "F32") != 0)
      BAD("checkpoint '%s': tensor '%s' is not F32", path, ts[i].name);
    if (!cJSON_IsArray(of) || cJSON_GetArraySize(of) != 2)
      BAD("checkpoint '%s': tensor '%s' has no data_offsets", path, ts[i].name);
    double b0 = cJSON_GetArrayItem(of, 0)->valuedouble, b1 = cJSON_GetArrayItem(of, 1)->valuedouble;
    if (b0 < 0 || b1 - b0 != (double)ts[i].count * 4 || c->data0 + b1 > (double)c->fsize)
      BAD("checkpoint '%s': tensor '%s' offsets [%.0f, %.0f) do not match %zu floats in the "
          "file",
          path, ts[i].name, b0, b1, ts[i].count);
    if (fseek(c->f, (long)(c->data0 + (uint64_t)b0), SEEK_SET) != 0 ||
        fread(ts[i].data, 4, ts[i].count, c->f) != ts[i].count)
      BAD("checkpoint '%s' is truncated (tensor '%s')", path, ts[i].name);
  }
done:
  return st;
}

/* The first architecture field that differs, as "key: A in the checkpoint, B in this run",
 * with the option that sets it; the whole key's name when the JSON does not parse. */
static void arch_diff(const char *was, const char *mine, char *buf, size_t n) {
  static const char *const hint[][2] = {{"exposure", " (another --store?)"},
                                        {"eps", " (--eps)"},
                                        {"kpa_passes", " (--kpa-passes)"},
                                        {"source_weight", " (--source-weight)"},
                                        {"channels", " (--channels, --widen)"}};
  snprintf(buf, n, "kpcn.architecture");
  cJSON *a = was ? cJSON_Parse(was) : NULL, *b = mine ? cJSON_Parse(mine) : NULL;
  for (int pass = 0; a && b && pass < 2; pass++) { /* keys of the checkpoint, then the run's */
    cJSON *x = pass ? b : a, *y = pass ? a : b;
    for (cJSON *ix = x->child; ix; ix = ix->next) {
      cJSON *iy = cJSON_GetObjectItemCaseSensitive(y, ix->string);
      char *px = cJSON_PrintUnformatted(ix), *py = iy ? cJSON_PrintUnformatted(iy) : NULL;
      int differ = px && (!py || strcmp(px, py));
      if (differ) {
        const char *h = "";
        for (size_t k = 0; k < sizeof hint / sizeof hint[0]; k++)
          if (!strcmp(ix->string, hint[k][0])) h = hint[k][1];
        char vx[96], vy[96];
        snprintf(vx, sizeof vx, "%s", px);
        snprintf(vy, sizeof vy, "%s", py ? py : "(absent)");
        snprintf(buf, n, "kpcn.architecture's %s: %s in the checkpoint, %s in this run%s",
                 ix->string, pass ? vy : vx, pass ? vx : vy, h);
      }
      free(px), free(py);
      if (differ) pass = 2;
      if (differ) break;
    }
  }
  cJSON_Delete(a), cJSON_Delete(b);
}

/* A checkpoint's decimal metadata value in [lo, hi], strictly parsed. */
static kpcn_status meta_range(cJSON *meta, const char *key, long long lo, long long hi,
                              const char *path, long long *got) {
  KPCN_TRY(meta_expect(meta, key, NULL, 0, path, got));
  if (*got < lo || *got > hi)
    return kpcn_fail(KPCN_ERR_FORMAT, "checkpoint '%s': metadata '%s' = %lld is out of range", path,
                     key, *got);
  return KPCN_OK;
}

kpcn_status kt_checkpoint_load(kpcn_trainer *t, const char *path) {
  ck_file c;
  KPCN_TRY(ck_open(path, &c));
  kpcn_status st = KPCN_OK;
  ck_tensor *ts = NULL;
  cJSON *meta = c.meta;
  const char *arch = meta_str(meta, "kpcn.architecture");
  char *mine = kpcn_arch_to_json(&t->arch), diff[400];
  int same = arch && mine && strcmp(arch, mine) == 0;
  if (!same) arch_diff(arch, mine, diff, sizeof diff);
  free(mine);
  if (!same) BAD("checkpoint '%s' holds a different architecture than this run: %s", path, diff);
  const char *seed = meta_str(meta, "train.seed");
  char *seed_end = NULL;
  const unsigned long long seed_v = seed ? strtoull(seed, &seed_end, 10) : 0;
  if (!seed || !seed_end || *seed_end || seed_end == seed || *seed == '-' || *seed == ' ')
    BAD("checkpoint '%s': metadata 'train.seed' missing or malformed", path);
  if (seed_v != t->s.seed)
    BAD("checkpoint '%s' was written with train.seed = %s, this run uses %" PRIu64, path, seed,
        t->s.seed);
  if (t->stage1_default) { /* not given: the checkpoint's, so that --iters may grow */
    long long s1 = 0;
    if ((st = meta_expect(meta, "train.stage1_iters", NULL, 0, path, &s1)) != KPCN_OK) goto done;
    if (s1 < 0) BAD("checkpoint '%s': train.stage1_iters %lld is negative", path, s1);
    t->s.stage1_iters = s1;
  }
  if ((st = meta_expect(meta, "train.batch", "--batch", t->N, path, NULL)) ||
      (st = meta_expect(meta, "train.patch", "--patch", t->P, path, NULL)) ||
      (st = meta_expect(meta, "train.stage1_iters", "--stage1-iters", t->s.stage1_iters, path,
                        NULL)))
    goto done;
  /* checkpoints from before mixed precision carry no train.precision: they were f32 */
  const char *prec = meta_str(meta, "train.precision"), *mine_prec = t->s.bf16 ? "bf16" : "f32";
  if (strcmp(prec ? prec : "f32", mine_prec))
    BAD("checkpoint '%s' was written with train.precision = %s, this run uses %s (--bf16)", path,
        prec ? prec : "f32 (no key: older checkpoint)", mine_prec);
  /* absent in checkpoints of runs that showed patches as rendered */
  const char *nx = meta_str(meta, "train.normalize_exposure");
  if ((nx && !strcmp(nx, "1")) != (t->s.normalize_exposure != 0))
    BAD("checkpoint '%s' was written %s exposure normalisation, this run %s it", path,
        nx ? "with" : "without", t->s.normalize_exposure ? "uses" : "does not use");
  /* absent in checkpoints of runs that trained both branches */
  const char *fz = meta_str(meta, "train.frozen");
  if (strcmp(fz ? fz : "none", kt_frozen_name(&t->s)))
    BAD("checkpoint '%s' was written with %s%s branch frozen, this run freezes %s (--freeze)", path,
        fz ? "the " : "no", fz ? fz : "", kt_frozen_name(&t->s));
  /* absent in checkpoints of runs that showed patches without the firefly bound */
  const char *ff = meta_str(meta, "train.firefly");
  if ((ff ? strtod(ff, NULL) : 0.0) != t->s.firefly)
    BAD("checkpoint '%s' was written with firefly %s, this run uses %g (--firefly)", path,
        ff ? ff : "off", t->s.firefly);
  ck_setting set[CK_NSET];
  for (int i = 0, ns = ck_settings(t, set); i < ns; i++) {
    const char *was = meta_str(meta, set[i].key);
    if (was && strcmp(was, set[i].value))
      BAD("checkpoint '%s' was written with %s = %s, this run uses %s (%s): a resumed run must "
          "keep its settings",
          path, set[i].key, was, set[i].value, set[i].option);
  }
  long long iter = 0, steps[2] = {0, 0};
  if ((st = meta_range(meta, "train.iteration", 0, LLONG_MAX, path, &iter)) ||
      (st = meta_range(meta, "train.adam_steps.diffuse", 0, iter, path, &steps[0])) ||
      (st = meta_range(meta, "train.adam_steps.specular", 0, iter, path, &steps[1])))
    goto done;
  /* absent in checkpoints from before session 60: the next CSV row then averages only the
   * iterations after the resume */
  double log_sum = 0.0;
  long long log_n = 0;
  const char *ls = meta_str(meta, "train.log_loss_sum");
  if (ls) {
    char *end = NULL;
    log_sum = strtod(ls, &end);
    if (!end || *end || !isfinite(log_sum) ||
        meta_expect(meta, "train.log_loss_n", NULL, 0, path, &log_n) != KPCN_OK || log_n < 0)
      BAD("checkpoint '%s': train.log_loss_sum / train.log_loss_n malformed", path);
  }
  if (iter > t->s.iters)
    BAD("checkpoint '%s' is at iteration %lld, beyond this run's %lld iterations (--iters)", path,
        iter, (long long)t->s.iters);
  const char *rng = meta_str(meta, "train.rng"), *el = meta_str(meta, "train.elapsed_s");
  if (!rng || !el) BAD("checkpoint '%s': train.rng or train.elapsed_s missing", path);
  /* the generator's state as written: 16 hex digits; the elapsed time a finite count */
  if (strlen(rng) != 16 || strspn(rng, "0123456789abcdefABCDEF") != 16)
    BAD("checkpoint '%s': metadata 'train.rng' malformed (16 hex digits expected)", path);
  char *el_end = NULL;
  const double elapsed = strtod(el, &el_end);
  if (!el_end || *el_end || el_end == el || !isfinite(elapsed) || elapsed < 0)
    BAD("checkpoint '%s': metadata 'train.elapsed_s' malformed", path);
  /* the best model kept before the checkpoint (absent in checkpoints before session 63) */
  const char *bv = meta_str(meta, "train.best_val"), *bb = meta_str(meta, "train.best_by");
  t->ckpt_best = 0;
  if (bv && !strcmp(bv, "none")) {
    t->ckpt_best = 2;
  } else if (bv) {
    char *bv_end = NULL;
    const double best = strtod(bv, &bv_end);
    if (!bv_end || *bv_end || bv_end == bv || !(best >= 0) || !isfinite(best) || !bb ||
        (strcmp(bb, "mean") && strcmp(bb, "geomean")))
      BAD("checkpoint '%s': metadata 'train.best_val' / 'train.best_by' malformed", path);
    /* another figure than this run's --best-by: compare by the CSV's column instead */
    if (!strcmp(bb, t->s.best_by == KPCN_VAL_GEOMEAN ? "geomean" : "mean")) {
      t->ckpt_best = 1;
      t->best_val = best;
    }
  }
  int n = ck_list(t, NULL);
  ts = kpcn_calloc((size_t)n, sizeof *ts, "checkpoint tensor list");
  if (!ts) {
    st = kpcn_last_status();
    goto done;
  }
  ck_list(t, ts);
  if ((st = ck_read(&c, path, ts, n)) != KPCN_OK) goto done;
  t->iter = iter;
  kpcn_adam_set_steps(t->adam[0], steps[0]);
  kpcn_adam_set_steps(t->adam[1], steps[1]);
  t->rng.state = strtoull(rng, NULL, 16);
  t->elapsed_prev = elapsed;
  t->log_loss_sum = log_sum;
  t->log_loss_n = log_n;
done:
  ck_close(&c);
  free(ts);
  return st;
}

kpcn_status kpcn_checkpoint_load_model(const char *path, kpcn_model **out) {
  if (!path || !out)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_checkpoint_load_model: NULL");
  *out = NULL;
  ck_file c;
  KPCN_TRY(ck_open(path, &c));
  kpcn_status st = KPCN_OK;
  kpcn_model *m = NULL;
  kpcn_arch a;
  const char *arch = meta_str(c.meta, "kpcn.architecture");
  if (!arch) BAD("checkpoint '%s': kpcn.architecture missing", path);
  if (kpcn_arch_from_json(arch, &a) != KPCN_OK)
    BAD("checkpoint '%s': kpcn.architecture: %s", path, kpcn_last_error());
  if ((st = kpcn_model_create(&a, 0, &m)) != KPCN_OK) goto done;
  for (int b = 0; b < KPCN_N_BRANCHES && st == KPCN_OK; b++)
    for (int l = 0; l <= a.n_hidden && st == KPCN_OK; l++) {
      kpcn_layer_view v;
      if ((st = kpcn_model_layer(m, (kpcn_branch)b, l, &v)) != KPCN_OK) break;
      ck_tensor ts[2] = {{"", v.weight, (size_t)v.out_ch * v.in_ch * v.size * v.size},
                         {"", v.bias, (size_t)v.out_ch}};
      for (int k = 0; k < 2; k++)
        kpcn_model_tensor_name(ts[k].name, sizeof ts[k].name, (kpcn_branch)b, l, k);
      st = ck_read(&c, path, ts, 2);
      for (int k = 0; k < 2 && st == KPCN_OK; k++)
        for (size_t i = 0; i < ts[k].count; i++)
          if (!isfinite(ts[k].data[i]))
            BAD("checkpoint '%s': tensor '%s' is not finite", path, ts[k].name);
    }
#undef BAD
done:
  ck_close(&c);
  if (st != KPCN_OK)
    kpcn_model_destroy(m);
  else
    *out = m;
  return st;
}

kpcn_status kpcn_trainer_save_checkpoint(kpcn_trainer *t, const char *path) {
  if (!t || !path) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "save checkpoint: NULL");
  return kt_checkpoint_save(t, path);
}

kpcn_status kpcn_trainer_load_checkpoint(kpcn_trainer *t, const char *path) {
  if (!t || !path) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "load checkpoint: NULL");
  return kt_checkpoint_load(t, path);
}
