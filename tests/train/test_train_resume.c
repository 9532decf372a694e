/* Trainer determinism and checkpoint/resume on a synthetic store, with validation every
 * iteration and a best model: two runs with the same seed write the same outputs, and a run
 * stopped at iteration 2 (stage 1) and at 4 (stage 2) and resumed each time writes exactly the
 * outputs of the uninterrupted run: the final model, the best model (which is not the last one,
 * and comes before the last resume, so a resumed run must recover the best-so-far figure from
 * the CSV), the final checkpoint (weights, Adam moments m and v, Adam step counts, RNG state,
 * iteration) and the CSV log -- byte for byte but for the wall-clock fields (model
 * train.seconds, checkpoint train.elapsed_s, CSV its_per_s and elapsed_s). In f32, with two
 * kernel passes, with source weights and in bf16. Also: the model records its training images'
 * median exposure, and a resume with another seed, precision, setting or architecture, past
 * --iters or from a truncated checkpoint is refused, naming the key. */
#include "kpcn/train.h"
#include "testutil.h"
#include "train_fixture.h"

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const char *g_store;
static int g_bf16;                    /* settings(): mixed-precision training */
static int g_passes = 1;              /* settings(): arch.kpa_passes */
static int g_sw;                      /* settings(): arch.source_weight */
static const char *g_vn[1], *g_vr[1]; /* the validation pair */
static int g_val_every = 1;           /* settings(): validation interval */

/* tf_settings in the variant, validated on one pair every iteration (so every iteration is a
 * CSV row), keeping the best model at `best`; lr 5e-2 in stage 1 (iterations 1-3: steps so
 * large that the validation gets worse after iteration 1) and 1e-4 in stage 2 (it recovers
 * little), so the best model is iteration 1's in every variant (measured), before both
 * resumes. */
static void settings(kpcn_train_settings *s, const char *out, const char *best) {
  tf_settings(s, g_store, out);
  s->bf16 = g_bf16;
  s->arch.kpa_passes = g_passes;
  s->arch.source_weight = g_sw;
  s->nval = 1, s->val_noisy = g_vn, s->val_ref = g_vr;
  s->val_every = g_val_every;
  s->best_path = best;
  s->adam.lr = 5e-2;
  s->stage2_lr = 1e-4;
}

static float *weights(kpcn_trainer *t, size_t *n) {
  return tf_model_weights(kpcn_trainer_model(t), n);
}

/* A safetensors file (model or checkpoint) split into its JSON header, without the padding and
 * with the value of the metadata key `clock` blanked, and its tensor bytes. */
typedef struct st_parts {
  char *buf, *hdr;
  const unsigned char *data;
  size_t ndata;
} st_parts;

static int st_split(const char *path, const char *clock, st_parts *p) {
  long len = 0;
  p->buf = kt_slurp(path, &len);
  if (!p->buf || len < 8) return 0;
  uint64_t hl = 0;
  for (int i = 0; i < 8; i++)
    hl |= (uint64_t)(unsigned char)p->buf[i] << (8 * i);
  if (hl > (uint64_t)len - 8) return 0;
  p->hdr = malloc(hl + 1);
  memcpy(p->hdr, p->buf + 8, hl);
  p->hdr[hl] = 0;
  for (size_t e = hl; e > 0 && p->hdr[e - 1] == ' '; e--)
    p->hdr[e - 1] = 0;
  p->data = (const unsigned char *)p->buf + 8 + hl;
  p->ndata = (size_t)len - 8 - hl;
  char key[80];
  snprintf(key, sizeof key, "\"%s\":\"", clock);
  char *v = strstr(p->hdr, key), *end = v ? strchr(v + strlen(key), '"') : NULL;
  if (!end) return 0; /* the clock key must be there: it is what may differ */
  memmove(v + strlen(key), end, strlen(end) + 1);
  return 1;
}

/* Whether safetensors files a and b are byte for byte equal but for the value of metadata key
 * `clock` (a wall-clock time); prints where they differ. */
static int same_but_clock(const char *what, const char *a, const char *b, const char *clock) {
  st_parts pa = {0}, pb = {0};
  int ok = st_split(a, clock, &pa) & st_split(b, clock, &pb);
  if (!ok) printf("%s: '%s' or '%s' unreadable or without \"%s\"\n", what, a, b, clock);
  if (ok && strcmp(pa.hdr, pb.hdr) != 0) {
    size_t i = 0;
    while (pa.hdr[i] == pb.hdr[i])
      i++;
    i = i > 60 ? i - 60 : 0;
    printf("%s: headers differ:\n  %.160s\n  %.160s\n", what, pa.hdr + i, pb.hdr + i);
    ok = 0;
  }
  if (ok && (pa.ndata != pb.ndata || memcmp(pa.data, pb.data, pa.ndata) != 0)) {
    size_t i = 0;
    while (i < pa.ndata && i < pb.ndata && pa.data[i] == pb.data[i])
      i++;
    printf("%s: tensor bytes differ (%zu vs %zu bytes, first at byte %zu)\n", what, pa.ndata,
           pb.ndata, i);
    ok = 0;
  }
  free(pa.buf), free(pa.hdr), free(pb.buf), free(pb.hdr);
  return ok;
}

/* The CSV log without its wall-clock columns, 5 (its_per_s) and 6 (elapsed_s), which the
 * header must name (malloc'ed); *rows receives the number of data rows, *best_it the
 * iteration of the lowest val_relmse (column 7) and val[it - 1] (up to 6) that value. */
static char *csv_no_clock(const char *path, int *rows, int *best_it, double val[6]) {
  char *text = kt_slurp(path, NULL), *out = text ? malloc(strlen(text) + 2) : NULL, *o = out;
  *rows = 0, *best_it = -1;
  double best = INFINITY;
  for (const char *line = text; out && line && *line;) {
    const char *nl = strchr(line, '\n'), *eol = nl ? nl : line + strlen(line);
    const char *f = line;
    for (int col = 1; f <= eol; col++) { /* the fields of this line */
      const char *c = memchr(f, ',', (size_t)(eol - f)), *fe = c ? c : eol;
      if (line == text && (col == 5 || col == 6))
        CHECK(!strncmp(f, col == 5 ? "its_per_s," : "elapsed_s,", 10));
      if (col != 5 && col != 6) {
        if (col > 1) *o++ = ',';
        memcpy(o, f, (size_t)(fe - f)), o += fe - f;
      }
      if (line != text && col == 7 && fe > f) {
        const long it = atol(line);
        const double v = strtod(f, NULL);
        if (it >= 1 && it <= 6) val[it - 1] = v;
        if (v < best) best = v, *best_it = (int)it;
      }
      f = fe + 1;
    }
    *o++ = '\n';
    *rows += line != text;
    line = nl ? nl + 1 : NULL;
  }
  if (o) *o = 0;
  free(text);
  return out;
}

static float *run_full(const char *out, const char *best, size_t *n) {
  kpcn_train_settings s;
  settings(&s, out, best);
  remove(best);
  kpcn_trainer *t = NULL;
  CHECK(kpcn_trainer_create(&t, &s) == KPCN_OK);
  if (!t) {
    fprintf(stderr, "%s\n", kpcn_last_error());
    return NULL;
  }
  int stopped = -1;
  CHECK(kpcn_trainer_run(t, &stopped) == KPCN_OK);
  CHECK(stopped == 0 && kpcn_trainer_iteration(t) == 6);
  float *w = weights(t, n);
  kpcn_trainer_destroy(t);
  return w;
}

/* The outputs of runs `a` and `b` (model, best model, checkpoint, CSV) are equal but for the
 * wall-clock fields. */
static int same_outputs(const char *what, const char *a, const char *b, int nrows) {
  static const char *file[4] = {".safetensors", ".best.safetensors", ".safetensors.ckpt",
                                ".safetensors.csv"};
  char pa[4][600], pb[4][600];
  for (int k = 0; k < 4; k++) { /* tf_tmp's names are copied: its pool wraps */
    snprintf(pa[k], sizeof pa[k], "%s", tf_tmp(a)), strcat(pa[k], file[k]);
    snprintf(pb[k], sizeof pb[k], "%s", tf_tmp(b)), strcat(pb[k], file[k]);
  }
  int ok = same_but_clock(what, pa[0], pb[0], "train.seconds");
  ok &= same_but_clock(what, pa[1], pb[1], "train.seconds");
  ok &= same_but_clock(what, pa[2], pb[2], "train.elapsed_s");
  int ra, rb, ia, ib;
  double va[6], vb[6];
  char *ca = csv_no_clock(pa[3], &ra, &ia, va), *cb = csv_no_clock(pb[3], &rb, &ib, vb);
  ok &= ca && cb && ra == nrows && rb == nrows;
  if (ca && cb && strcmp(ca, cb)) {
    printf("%s: CSV logs (wall-clock columns dropped) differ:\n%s--\n%s", what, ca, cb);
    ok = 0;
  }
  free(ca), free(cb);
  return ok;
}

/* Run once in f32 and once in bf16 (g_bf16): the file names are reused; a bf16 run's
 * weights must differ from the f32 run's (the precision is really switched). */
static void test_determinism_and_resume(void) {
  static float *f32_weights;
  static size_t f32_n;
  size_t n1, n2, n3 = 0;
  float *w1 = run_full(tf_tmp("a.safetensors"), tf_tmp("a.best.safetensors"), &n1);
  float *w2 = run_full(tf_tmp("b.safetensors"), tf_tmp("b.best.safetensors"), &n2), *w3 = NULL;
  CHECK(w1 && w2 && n1 == n2 && memcmp(w1, w2, n1 * sizeof(float)) == 0);
  CHECK(same_outputs("two runs", "a", "b", 6)); /* iterations 1..6, each validated */
  const char *c = tf_tmp("c.safetensors"), *cbest = tf_tmp("c.best.safetensors");
  kpcn_train_settings s;
  settings(&s, c, cbest);
  kpcn_trainer *t = NULL;
  CHECK(kpcn_trainer_create(&t, &s) == KPCN_OK);
  if (!t) {
    fprintf(stderr, "%s\n", kpcn_last_error());
    return;
  }
  size_t n0; /* the training changed the weights (not a no-op) */
  float *w0 = weights(t, &n0);
  CHECK(n0 == n1 && memcmp(w0, w1, n0 * sizeof(float)) != 0);
  { /* the model records its training images' median exposure (one source: its own) */
    kpcn_patchstore *ps = NULL;
    CHECK(kpcn_patchstore_open(&ps, g_store, NULL, 0) == KPCN_OK);
    const float e = ps ? (float)kpcn_patchstore_source(ps, 0)->exposure : 0.0f;
    CHECK(e > 0.0f && kpcn_model_arch(kpcn_trainer_model(t))->exposure == e);
    kpcn_patchstore_close(ps);
  }
  kpcn_trainer_destroy(t);
  /* stopped at iteration 2 (stage 1) and at 4 (stage 2), resumed each time, to 6 */
  remove(cbest);
  s.progress = tf_stop_cb;
  for (int seg = 0; seg < 3; seg++) {
    tf_stop_at = seg < 2 ? 2 + 2 * seg : 7;
    s.resume = seg > 0;
    t = NULL;
    CHECK(kpcn_trainer_create(&t, &s) == KPCN_OK);
    if (!t) break;
    CHECK(kpcn_trainer_iteration(t) == 2 * seg);
    int stopped = -1;
    CHECK(kpcn_trainer_run(t, &stopped) == KPCN_OK);
    CHECK(stopped == (seg < 2) && kpcn_trainer_iteration(t) == 2 + 2 * seg);
    if (seg == 2) w3 = weights(t, &n3);
    kpcn_trainer_destroy(t);
  }
  CHECK(w3 && n3 == n1 && memcmp(w3, w1, n1 * sizeof(float)) == 0);
  const int same = same_outputs("resumed twice", "a", "c", 6);
  CHECK(same);
  /* the best model is not the last, and precedes the last resume (at 4): a resumed run that
   * forgot the best-so-far figure would write its own first iteration's model as the best */
  int rows, best_it;
  double val[6] = {0};
  free(csv_no_clock(tf_tmp("a.safetensors.csv"), &rows, &best_it, val));
  kpcn_model *m = NULL;
  CHECK(kpcn_model_load(tf_tmp("a.best.safetensors"), &m) == KPCN_OK);
  const char *bit = m ? kpcn_model_get_meta(m, "train.iterations") : NULL;
  printf("validation relMSE at iterations 1..6: %.6g %.6g %.6g %.6g %.6g %.6g; best model of "
         "iteration %s\n",
         val[0], val[1], val[2], val[3], val[4], val[5], bit ? bit : "?");
  CHECK(bit && atoi(bit) == best_it && best_it >= 1 && best_it <= 4);
  if (m) {
    size_t nb;
    float *wb = tf_model_weights(m, &nb);
    CHECK(nb == n1 && memcmp(wb, w1, n1 * sizeof(float)) != 0);
    free(wb);
  }
  kpcn_model_destroy(m);
  printf("determinism and resume (%s, %d kernel passes%s): model, best model, checkpoint, CSV "
         "%s\n",
         g_bf16 ? "bf16" : "f32", g_passes, g_sw ? ", source weights" : "",
         same ? "identical" : "DIFFER");
  /* bf16, two kernel passes or source weights really change the training (the run without
   * any is first); source weights also add parameters */
  if (g_bf16 || g_passes > 1 || g_sw)
    CHECK(f32_weights && (f32_n != n1 || memcmp(f32_weights, w1, n1 * sizeof(float)) != 0));
  /* a checkpoint written in the other precision is refused, naming the key */
  settings(&s, c, cbest);
  s.bf16 = !g_bf16;
  s.resume = 1;
  if (s.bf16 == 0 || kt_have_bf16("a bf16 resume of an f32 checkpoint")) {
    CHECK(kpcn_trainer_create(&t, &s) == KPCN_ERR_FORMAT);
    CHECK(strstr(kpcn_last_error(), "train.precision") != NULL);
  }
  /* outputs: model loads, plot exists */
  m = NULL;
  CHECK(kpcn_model_load(c, &m) == KPCN_OK);
  if (m)
    CHECK(kpcn_model_get_meta(m, "train.iterations") &&
          !strcmp(kpcn_model_get_meta(m, "train.iterations"), "6"));
  kpcn_model_destroy(m);
  FILE *p = fopen(tf_tmp("c.safetensors.png"), "rb");
  CHECK(p != NULL);
  if (p) fclose(p);
  /* a checkpoint of another run (other seed) is refused, naming the key */
  settings(&s, c, cbest);
  s.seed = 6;
  s.resume = 1;
  CHECK(kpcn_trainer_create(&t, &s) == KPCN_ERR_FORMAT);
  CHECK(strstr(kpcn_last_error(), "train.seed") != NULL);
  /* so is a resume that changes a setting the remaining iterations depend on, naming it */
  settings(&s, c, cbest);
  s.loss1 = KPCN_LOSS_RELMSE;
  s.resume = 1;
  CHECK(kpcn_trainer_create(&t, &s) == KPCN_ERR_FORMAT);
  CHECK(strstr(kpcn_last_error(), "train.loss1 = l1") && strstr(kpcn_last_error(), "--loss"));
  settings(&s, c, cbest);
  s.adam.lr *= 2;
  s.resume = 1;
  CHECK(kpcn_trainer_create(&t, &s) == KPCN_ERR_FORMAT);
  CHECK(strstr(kpcn_last_error(), "train.lr =") != NULL);
  settings(&s, c, cbest);
  s.augment.rotate = 0;
  s.resume = 1;
  CHECK(kpcn_trainer_create(&t, &s) == KPCN_ERR_FORMAT);
  CHECK(strstr(kpcn_last_error(), "train.augment") != NULL);
  /* and one that would stop before the checkpoint's iteration (6) */
  settings(&s, c, cbest);
  s.iters = 4;
  s.resume = 1;
  CHECK(kpcn_trainer_create(&t, &s) == KPCN_ERR_FORMAT);
  CHECK(strstr(kpcn_last_error(), "beyond this run's 4 iterations") != NULL);
  /* a truncated checkpoint is refused */
  FILE *src = fopen(tf_tmp("c.safetensors.ckpt"), "rb");
  FILE *dst = fopen(tf_tmp("trunc.ckpt"), "wb");
  if (src && dst) {
    char buf[1000];
    size_t k = fread(buf, 1, sizeof buf, src);
    fwrite(buf, 1, k, dst);
  }
  if (src) fclose(src);
  if (dst) fclose(dst);
  settings(&s, c, cbest);
  s.ckpt_path = tf_tmp("trunc.ckpt");
  s.resume = 1;
  CHECK(kpcn_trainer_create(&t, &s) == KPCN_ERR_FORMAT);
  if (g_passes > 1 || g_sw) {
    /* the checkpoint of a two-pass or source-weighted run does not resume as a plain one */
    settings(&s, c, cbest);
    s.arch.kpa_passes = 1;
    s.arch.source_weight = 0;
    s.resume = 1;
    CHECK(kpcn_trainer_create(&t, &s) == KPCN_ERR_FORMAT);
    CHECK(strstr(kpcn_last_error(), "architecture") != NULL);
  } else if (!g_bf16) {
    free(f32_weights);
    f32_weights = w1, f32_n = n1, w1 = NULL;
  } else {
    free(f32_weights);
    f32_weights = NULL;
  }
  free(w0), free(w1), free(w2), free(w3);
}

/* Stops between CSV rows (validation every 3 iterations, a row every 2: rows at 2, 3, 4 and
 * 6), at iterations 1 and 5: each stop validates and writes a row of its own, which the
 * uninterrupted run has not, and each resume starts the loss average of the next row part
 * way. The resumed run's outputs equal the uninterrupted one's all the same: the stop rows
 * are dropped on resume and pick no best model, and the loss accumulator comes back from the
 * checkpoint (before session 60 the CSV differed in both). */
static void test_resume_between_rows(void) {
  g_val_every = 3;
  size_t n1;
  float *w1 = run_full(tf_tmp("d.safetensors"), tf_tmp("d.best.safetensors"), &n1);
  kpcn_train_settings s;
  settings(&s, tf_tmp("e.safetensors"), tf_tmp("e.best.safetensors"));
  remove(tf_tmp("e.best.safetensors"));
  s.progress = tf_stop_cb;
  int stop_rows = 0;
  for (int seg = 0; seg < 3; seg++) {
    static const int stop_at[3] = {1, 5, 7};
    tf_stop_at = stop_at[seg];
    s.resume = seg > 0;
    kpcn_trainer *t = NULL;
    CHECK(kpcn_trainer_create(&t, &s) == KPCN_OK);
    if (!t) break;
    CHECK(kpcn_trainer_run(t, NULL) == KPCN_OK);
    kpcn_trainer_destroy(t);
    if (seg < 2) { /* the stop row is there until the resume */
      int rows, best_it;
      double val[6] = {0};
      free(csv_no_clock(tf_tmp("e.safetensors.csv"), &rows, &best_it, val));
      stop_rows += val[stop_at[seg] - 1] > 0;
    }
  }
  CHECK(stop_rows == 2);
  CHECK(same_outputs("stopped between rows", "d", "e", 4));
  printf("resume between CSV rows (stops at 1 and 5, rows at 2, 3, 4, 6): outputs identical\n");
  free(w1);
  g_val_every = 1;
}

int main(void) {
  g_store = tf_make_test_store("train.kps");
  if (!g_store) return 1;
  kpcn_train_settings vs;       /* only writes the pair's files */
  static char vn[512], vr[512]; /* tf_tmp's pool wraps */
  tf_val_pair(&vs, "val", g_vn, g_vr);
  snprintf(vn, sizeof vn, "%s", g_vn[0]), snprintf(vr, sizeof vr, "%s", g_vr[0]);
  g_vn[0] = vn, g_vr[0] = vr;
  test_determinism_and_resume();
  test_resume_between_rows();
  g_passes = 2;
  test_determinism_and_resume();
  g_sw = 1;
  test_determinism_and_resume();
  g_passes = 1;
  g_sw = 0;
  g_bf16 = 1;
  if (kt_have_bf16("determinism and resume")) test_determinism_and_resume();
  return kt_summary("train_resume");
}
