/* `kpcn-dataset patches`: finished renders -> patch store (.kps) with flat-patch culling.
 * Only the chosen split (default train) is used; rejected variants are skipped; missing
 * renders are an error unless --allow-partial, so a half-finished run never silently
 * yields a smaller training set. Several dataset directories (made by separate `plan`s,
 * e.g. a later batch of scenes) go into one store; with more than one, the store's source
 * file names carry the directory. */
#define _GNU_SOURCE
#include "ds.h"
#include "kpcn/augment.h"
#include "kpcn/dataset.h"
#include "kpcn/exr.h"

#include <cjson/cJSON.h>
#include <signal.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

static int rejected(const char *dir, const ds_job *j) {
  if (!j->preview[0]) return 0;
  char rel[DS_PATH], vp[DS_PATH];
  snprintf(rel, sizeof rel, "%s", j->preview);
  char *dot = strrchr(rel, '.');
  if (dot) *dot = 0;
  char tmp[DS_PATH + 16];
  snprintf(tmp, sizeof tmp, "%s.verdict.json", rel);
  ds_join(vp, sizeof vp, dir, tmp);
  char *t = ds_slurp(vp, NULL, NULL);
  if (!t) return 0;
  cJSON *o = cJSON_Parse(t);
  free(t);
  int rej = cJSON_IsFalse(cJSON_GetObjectItemCaseSensitive(o, "ok"));
  cJSON_Delete(o);
  return rej;
}

static int spp_selected(const int *spps, int n, int spp) {
  if (n == 0) return 1;
  for (int i = 0; i < n; i++)
    if (spps[i] == spp) return 1;
  return 0;
}

static volatile sig_atomic_t g_patch_stop = 0; /* the signal that asked to stop, 0 if none */
static void on_signal(int sig) { g_patch_stop = sig; }

/* Rule 56's store takes 18 directories (session 51); each costs a manifest on the stack. */
enum { MAX_DIRS = 64 };

typedef struct pair_t {
  int dir, job, ref; /* dataset directory index, noisy job, its variant's reference job */
} pair_t;

/* Appends to pairs every selected noisy job of one dataset directory with its variant's
 * reference; counts rejected variants and (up to five printed) missing renders. */
static void collect_pairs(const char *dir, int dir_index, const ds_manifest *m, const char *split,
                          const int *spps, int nspp, int allow_partial, pair_t *pairs, int *np,
                          int *missing, int *nrej, int *stale) {
  for (int i = 0; i < m->n && !*stale; i++) {
    const ds_job *j = &m->jobs[i];
    if (j->kind != DS_NOISY || strcmp(j->split, split) != 0 || !spp_selected(spps, nspp, j->spp))
      continue;
    int r = -1;
    for (int k = 0; k < m->n && r < 0; k++)
      if (m->jobs[k].kind == DS_REFERENCE && !strcmp(m->jobs[k].scene, j->scene) &&
          m->jobs[k].variant == j->variant)
        r = k;
    if (rejected(dir, j)) {
      (*nrej)++;
      continue;
    }
    char a[DS_PATH], b[DS_PATH];
    ds_join(a, sizeof a, dir, j->out);
    if (r >= 0) ds_join(b, sizeof b, dir, m->jobs[r].out);
    if (r < 0 || !ds_exists(a) || !ds_exists(b)) {
      if (!allow_partial && *missing < 5)
        ds_err("patches: %s not rendered yet (%s)", j->id,
               r < 0           ? "no reference job"
               : !ds_exists(a) ? a
                               : b);
      (*missing)++;
      continue;
    }
    /* a render left by an earlier plan, or a manifest edited since: named, and no store */
    if (ds_check_render(a, j) != 0 || ds_check_render(b, &m->jobs[r]) != 0) {
      *stale = 1;
      return;
    }
    pairs[*np] = (pair_t){dir_index, i, r};
    (*np)++;
  }
}

/* Why no pair was found, when the manifests say so: the split has no noisy job at all, or none
 * at the asked spp (the message lists what there is). 0 when neither: the pairs exist but are
 * not rendered or were rejected, which the caller's message says. */
static int explain_no_pairs(const ds_manifest *m, int ndirs, const char *split,
                            const char *spp_list, const int *spps, int nspp) {
  int in_split = 0, have[32], nhave = 0;
  for (int d = 0; d < ndirs; d++)
    for (int i = 0; i < m[d].n; i++) {
      const ds_job *j = &m[d].jobs[i];
      if (j->kind != DS_NOISY || strcmp(j->split, split) != 0) continue;
      in_split++;
      int k = 0;
      while (k < nhave && have[k] != j->spp)
        k++;
      if (k == nhave && nhave < 32) have[nhave++] = j->spp;
      if (spp_selected(spps, nspp, j->spp)) return 0;
    }
  if (!in_split) {
    ds_err("patches: the manifest%s plan%s no noisy render in split '%s'", ndirs > 1 ? "s" : "",
           ndirs > 1 ? "" : "s", split);
    return 1;
  }
  char list[32 * 12] = "";
  for (int k = 0; k < nhave; k++)
    snprintf(list + strlen(list), sizeof list - strlen(list), "%s%d", k ? "," : "", have[k]);
  ds_err("patches: no %s render at --spp %s (the %s split's noisy renders have spp %s)", split,
         spp_list, split, list);
  return 1;
}

/* to stdout when --help asked for it, to stderr beside an error */
static void usage(FILE *f) {
  fprintf(
      f,
      "usage: kpcn-dataset patches DATASET_DIR... -o OUT.kps [--split train] [--spp "
      "all|16,32,...]\n"
      "         [--size 65] [--per-image 100 | --stride S] [--cull 0.9] [--cull-tol 0.05]\n"
      "         [--cull-abs 0.01] [--importance] [--seed 1] [--dtype f32|f16] [--allow-partial]\n"
      "         [--progress-every 60]\n");
}

int ds_cmd_patches(int argc, char **argv) {
  const char *dirs[MAX_DIRS], *out = NULL, *split = "train", *spp_list = "all", *dtype = "f32";
  int ndirs = 0, allow_partial = 0, per_image_given = 0, stride_given = 0;
  double progress_every = 60.0; /* seconds between progress lines off a terminal */
  kpcn_patch_settings ps;
  kpcn_patch_settings_defaults(&ps);
  ps.count = 100;
  for (int i = 1; i < argc; i++) {
    const char *a = argv[i], *v = i + 1 < argc ? argv[i + 1] : NULL;
    if (!strcmp(a, "--importance")) {
      ps.importance = 1;
      continue;
    }
    if (!strcmp(a, "--allow-partial")) {
      allow_partial = 1;
      continue;
    }
    if (!strcmp(a, "-h") || !strcmp(a, "--help")) {
      usage(stdout);
      return 0;
    }
    if (a[0] != '-') {
      if (ndirs == MAX_DIRS) {
        ds_err("patches: more than %d dataset directories", MAX_DIRS);
        return 2;
      }
      dirs[ndirs++] = a;
      continue;
    }
    if (!v) {
      ds_err("patches: %s needs a value", a);
      return 2;
    }
    int ok = 1, iv;
    const char *want = ""; /* what the option takes, for the error */
    if (!strcmp(a, "-o") || !strcmp(a, "--output"))
      out = v;
    else if (!strcmp(a, "--split"))
      split = v;
    else if (!strcmp(a, "--spp"))
      spp_list = v;
    else if (!strcmp(a, "--dtype")) {
      dtype = v;
      ok = !strcmp(v, "f32") || !strcmp(v, "f16");
      want = " (f32 or f16)";
    } else if (!strcmp(a, "--size")) {
      ok = cli_parse_int(v, 2, 4096, &ps.size);
      want = " (an integer in [2, 4096])";
    } else if (!strcmp(a, "--per-image")) {
      ok = cli_parse_int(v, 1, 1 << 20, &ps.count);
      per_image_given = 1;
      want = " (an integer in [1, 1048576])";
    } else if (!strcmp(a, "--stride")) {
      ok = cli_parse_int(v, 1, 4096, &ps.stride);
      stride_given = 1;
      want = " (an integer in [1, 4096])";
    } else if (!strcmp(a, "--cull") || !strcmp(a, "--cull-tol") || !strcmp(a, "--cull-abs")) {
      /* Finite (cli_parse_double): they are recorded in the store's settings JSON, which has
       * no inf. --cull above 1 disables culling. */
      double *dst = !strcmp(a, "--cull")       ? &ps.cull
                    : !strcmp(a, "--cull-tol") ? &ps.cull_tol
                                               : &ps.cull_abs;
      ok = cli_parse_double(v, dst) && *dst >= 0;
      want = " (a finite number >= 0)";
    } else if (!strcmp(a, "--progress-every")) {
      ok = cli_parse_double(v, &progress_every) && progress_every >= 0;
      want = " (seconds >= 0)";
    } else if (!strcmp(a, "--seed")) {
      ok = cli_parse_int(v, 0, 2147483647, &iv);
      ps.seed = (uint64_t)iv;
      want = " (an integer in [0, 2147483647])";
    } else {
      ds_err("patches: unknown option '%s'", a);
      usage(stderr);
      return 2;
    }
    if (!ok) {
      ds_err("patches: bad value '%s' for %s%s", v, a, want);
      return 2;
    }
    i++;
  }
  if (!ndirs || !out) {
    usage(stderr);
    return 2;
  }
  /* one or the other: which one won used to depend on their order on the command line */
  if (per_image_given && stride_given) {
    ds_err("patches: --per-image (random patches) and --stride (a regular grid) exclude each "
           "other");
    return 2;
  }
  if (stride_given) ps.count = 0;
  int spps[32], nspp = 0;
  if (strcmp(spp_list, "all") != 0 && (nspp = ds_parse_int_list(spp_list, 1 << 24, spps, 32)) < 1) {
    ds_err("patches: --spp '%s': expected 'all' or a comma list of at most 32 distinct "
           "integers in [1, %d]",
           spp_list, 1 << 24);
    return 2;
  }
  /* before any work: the store is written last, after every image was read */
  if (kpcn_check_output_path(out, "-o") != KPCN_OK) {
    ds_err("patches: %s", kpcn_last_error());
    return 2;
  }
  for (int d = 0; d < ndirs; d++)
    for (int e = 0; e < d; e++) {
      struct stat sd, se;
      if (stat(dirs[d], &sd) == 0 && stat(dirs[e], &se) == 0 && sd.st_dev == se.st_dev &&
          sd.st_ino == se.st_ino) {
        ds_err("patches: the dataset directory '%s' is given twice (as '%s'): its pairs would "
               "be cut twice",
               dirs[d], dirs[e]);
        return 2;
      }
    }
  ds_manifest m[MAX_DIRS];
  memset(m, 0, sizeof m);
  pair_t *pairs = NULL;
  int np = 0, missing = 0, nrej = 0, rc = 0, stale = 0;
  for (int d = 0; d < ndirs && rc == 0; d++) {
    if (ds_manifest_read(dirs[d], &m[d]) != 0) {
      rc = 1;
      break;
    }
    pair_t *grown = realloc(pairs, sizeof *pairs * (size_t)(np + m[d].n + 1));
    if (!grown) {
      ds_err("patches: out of memory");
      rc = 1;
      break;
    }
    pairs = grown;
    collect_pairs(dirs[d], d, &m[d], split, spps, nspp, allow_partial, pairs, &np, &missing, &nrej,
                  &stale);
    if (stale) rc = 1;
  }
  /* the store must not replace a file of a dataset it reads: the manifest, the plan, */
  for (int d = 0; d < ndirs && rc == 0; d++) {
    char mf[DS_PATH], pf[DS_PATH];
    ds_join(mf, sizeof mf, dirs[d], "manifest.jsonl");
    ds_join(pf, sizeof pf, dirs[d], "plan.json");
    if (kpcn_check_not_input(out, "-o", mf, "the manifest") != KPCN_OK ||
        kpcn_check_not_input(out, "-o", pf, "the plan") != KPCN_OK)
      rc = 2;
  }
  /* nor any other file of the dataset (a render of another split or spp, a variant's scene) */
  for (int d = 0; d < ndirs && rc == 0; d++)
    for (int i = 0; i < m[d].n && rc == 0; i++)
      for (int k = 0; k < 2 && rc == 0; k++) {
        char a[DS_PATH];
        ds_join(a, sizeof a, dirs[d], k ? m[d].jobs[i].scene_file : m[d].jobs[i].out);
        if (kpcn_check_not_input(
                out, "-o", a, k ? "a scene of the dataset" : "a render of the dataset") != KPCN_OK)
          rc = 2;
      }
  if (rc == 2) ds_err("patches: %s", kpcn_last_error());
  if (rc == 0 && ((missing && !allow_partial) || np == 0)) {
    if (np == 0 && !explain_no_pairs(m, ndirs, split, spp_list, spps, nspp))
      ds_err("patches: no finished %s image pairs in '%s'%s", split, dirs[0],
             ndirs > 1 ? " and the other directories" : "");
    if (missing && !allow_partial)
      ds_err("patches: %d image pairs missing: finish `kpcn-dataset run` or pass --allow-partial",
             missing);
    rc = 1;
  }
  if (rc != 0) {
    free(pairs);
    for (int d = 0; d < ndirs; d++)
      ds_manifest_free(&m[d]);
    return rc;
  }
  kpcn_patchstore_settings ss;
  kpcn_patchstore_settings_defaults(&ss);
  ss.patch_size = ps.size;
  ss.dtype = !strcmp(dtype, "f16") ? KPCN_DTYPE_F16 : KPCN_DTYPE_F32;
  /* Built with cJSON, not printf: a split name may hold any character, which must be
   * escaped (the keys and their order are those of stores written before). */
  cJSON *sj = cJSON_CreateObject();
  cJSON_AddStringToObject(sj, "split", split);
  cJSON_AddStringToObject(sj, "spp", spp_list);
  cJSON_AddNumberToObject(sj, "per_image", ps.count);
  cJSON_AddNumberToObject(sj, "stride", ps.stride);
  cJSON_AddNumberToObject(sj, "cull", ps.cull);
  cJSON_AddNumberToObject(sj, "cull_tol", ps.cull_tol);
  cJSON_AddNumberToObject(sj, "cull_abs", ps.cull_abs);
  cJSON_AddNumberToObject(sj, "importance", ps.importance);
  cJSON_AddNumberToObject(sj, "seed", (double)ps.seed);
  char *settings = cJSON_PrintUnformatted(sj);
  cJSON_Delete(sj);
  if (!settings) {
    ds_err("patches: out of memory");
    free(pairs);
    for (int d = 0; d < ndirs; d++)
      ds_manifest_free(&m[d]);
    return 1;
  }
  ss.settings_json = settings;
  /* A stop removes the unfinished store (its temporary can be gigabytes). The handlers are
   * in place from before the temporary exists until it is renamed or removed, so no signal
   * in between ends the process with the temporary left behind. */
  struct sigaction sa, old_int, old_term;
  memset(&sa, 0, sizeof sa);
  sa.sa_handler = on_signal;
  sigaction(SIGINT, &sa, &old_int);
  sigaction(SIGTERM, &sa, &old_term);
  kpcn_patchstore_writer *w = NULL;
  kpcn_status cst = kpcn_patchstore_create(&w, out, &ss); /* keeps a copy of settings */
  free(settings);
  if (cst != KPCN_OK) {
    sigaction(SIGINT, &old_int, NULL);
    sigaction(SIGTERM, &old_term, NULL);
    ds_err("patches: %s", kpcn_last_error());
    free(pairs);
    for (int d = 0; d < ndirs; d++)
      ds_manifest_free(&m[d]);
    return 1;
  }
  kpcn_patch_stats tot = {0, 0, 0};
  double t0 = ds_now(), last_line = -1e300;
  int done = 0; /* pairs read whole */
  for (int p = 0; p < np && rc == 0 && !g_patch_stop; p++) {
    const char *dir = dirs[pairs[p].dir];
    const ds_job *j = &m[pairs[p].dir].jobs[pairs[p].job], *r = &m[pairs[p].dir].jobs[pairs[p].ref];
    char a[DS_PATH], b[DS_PATH];
    ds_join(a, sizeof a, dir, j->out);
    ds_join(b, sizeof b, dir, r->out);
    kpcn_aov_set *noisy = NULL, *ref = NULL;
    kpcn_patch_origin *o = NULL;
    int n = 0;
    kpcn_patch_stats st;
    kpcn_patch_settings pi = ps;
    pi.seed = ds_hash(j->id, ps.seed);
    kpcn_patch_source src;
    memset(&src, 0, sizeof src);
    uint32_t sid = 0;
    const char *unreadable = NULL;
    if (kpcn_exr_read_aov(a, &noisy) != KPCN_OK)
      unreadable = a;
    else if (kpcn_exr_read_aov(b, &ref) != KPCN_OK)
      unreadable = b;
    if (unreadable) {
      /* `run` takes a render whose header matches its job as done, so a file damaged after it
       * was written (a copy cut short) is only found here: say how to make it again */
      const char *e = kpcn_last_error();
      if (strstr(e, "truncated or corrupt"))
        ds_err("patches: %s: %s (remove '%s' and run `kpcn-dataset run` again to render it "
               "anew)",
               j->id, e, unreadable);
      else
        ds_err("patches: %s: %s", j->id, e);
      rc = 1;
    } else if (kpcn_patches_select(&o, &n, &st, noisy, ref, &pi) != KPCN_OK ||
               kpcn_patch_source_image_stats(&src, noisy) != KPCN_OK) {
      ds_err("patches: %s: %s", j->id, kpcn_last_error());
      rc = 1;
    }
    if (rc == 0) {
      snprintf(src.scene, sizeof src.scene, "%s", j->scene);
      snprintf(src.split, sizeof src.split, "%s", j->split);
      src.variant = j->variant;
      src.spp = j->spp;
      src.ref_spp = r->spp;
      snprintf(src.noisy, sizeof src.noisy, "%.255s", ndirs > 1 ? a : j->out);
      snprintf(src.reference, sizeof src.reference, "%.255s", ndirs > 1 ? b : r->out);
      kpcn_patchstore_add_source(w, &src, &sid);
      for (int k = 0; k < n && rc == 0; k++) {
        kpcn_patch_record rec = {sid, o[k].x, o[k].y, 0, o[k].flat_frac, o[k].weight, 0};
        if (kpcn_patchstore_append_aov(w, &rec, noisy, ref) != KPCN_OK) {
          /* the files, not the scene their header names (which may be another dataset's) */
          ds_err("patches: %s (noisy %s, reference %s): %s", j->id, a, b, kpcn_last_error());
          rc = 1;
        }
      }
      kpcn_patchstore_add_stats(w, st.candidates, st.kept, st.culled);
      tot.candidates += st.candidates;
      tot.kept += st.kept;
      tot.culled += st.culled;
    }
    free(o);
    kpcn_aov_destroy(noisy);
    kpcn_aov_destroy(ref);
    char detail[96];
    snprintf(detail, sizeof detail, "%lld patches kept, %lld culled", (long long)tot.kept,
             (long long)tot.culled);
    const double el = ds_now() - t0;
    ds_progress(&last_line, progress_every, p + 1 == np || rc != 0, p + 1, np, el,
                el / (p + 1) * (np - p - 1), detail);
    if (rc == 0) done = p + 1;
  }
  if (ds_isatty()) fputc('\n', stderr);
  /* A signal during the last pair stops the run too, and one that broke a read (EINTR on a
   * slow device) is reported as the stop it was, not only as the read's error. */
  if (g_patch_stop) {
    ds_err("patches: stopped by signal %d after %d of %d pairs; nothing written", (int)g_patch_stop,
           done, np);
    rc = 128 + g_patch_stop;
  }
  if (rc == 0 && tot.kept == 0) { /* a store of nothing, which kpcn-train refuses only later */
    ds_err("patches: no patch kept (%lld candidates, all culled at --cull %g): no store written",
           (long long)tot.candidates, ps.cull);
    rc = 1;
  }
  if (rc == 0 && kpcn_patchstore_finish(w) != KPCN_OK) {
    ds_err("patches: %s", kpcn_last_error());
    rc = 1;
  } else if (rc != 0) {
    kpcn_patchstore_abort(w);
  }
  sigaction(SIGINT, &old_int, NULL);
  sigaction(SIGTERM, &old_term, NULL);
  if (rc == 0) {
    struct stat sb;
    stat(out, &sb);
    printf("%s: %d image pairs (%d rejected variants' images skipped%s), %lld candidates, "
           "%lld kept, %lld culled (%.1f%%), %.1f MB, %.1f s\n",
           out, np, nrej, missing ? ", some missing" : "", (long long)tot.candidates,
           (long long)tot.kept, (long long)tot.culled,
           tot.candidates ? 100.0 * tot.culled / tot.candidates : 0.0, sb.st_size / 1e6,
           ds_now() - t0);
  }
  free(pairs);
  for (int d = 0; d < ndirs; d++)
    ds_manifest_free(&m[d]);
  return rc;
}
