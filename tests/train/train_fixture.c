#include "train_fixture.h"

#include "kpcn/denoise.h"
#include "kpcn/exr.h"
#include "testutil.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static void box3(const float *in, float *out, int w, int h) {
  for (int y = 0; y < h; y++)
    for (int x = 0; x < w; x++) {
      double s = 0;
      for (int dy = -1; dy <= 1; dy++)
        for (int dx = -1; dx <= 1; dx++) {
          int yy = y + dy < 0 ? 0 : y + dy >= h ? h - 1 : y + dy;
          int xx = x + dx < 0 ? 0 : x + dx >= w ? w - 1 : x + dx;
          s += in[yy * w + xx];
        }
      out[y * w + x] = (float)(s / 9);
    }
}

int tf_make_pair(kpcn_aov_set **noisy, kpcn_aov_set **ref, int w, int h, unsigned seed,
                 int box_ref) {
  kpcn_aov_set *n = NULL, *r = NULL;
  if (kpcn_aov_create(&n, w, h) || kpcn_aov_create(&r, w, h)) return 1;
  for (int b = 0; b < KPCN_BUF_COUNT; b++)
    if (kpcn_aov_add(n, (kpcn_buffer)b, 1) || kpcn_aov_add(r, (kpcn_buffer)b, 1)) return 1;
  size_t np = (size_t)w * h;
  unsigned st = seed * 7919u + 1;
  for (int y = 0; y < h; y++)
    for (int x = 0; x < w; x++) {
      size_t i = (size_t)y * w + x;
      double u = (double)x / w, v = (double)y / h;
      for (int c = 0; c < 3; c++) {
        double alb = 0.3 + 0.2 * sin(6 * u + c) * cos(5 * v);
        double dif = 0.5 + 0.3 * sin(4 * u + 3 * v + c + seed);
        double spe = 0.2 * pow(fmax(0, sin(9 * u - 2 * v + c)), 4);
        n->buf[KPCN_BUF_ALBEDO][c * np + i] = r->buf[KPCN_BUF_ALBEDO][c * np + i] = (float)alb;
        r->buf[KPCN_BUF_DIFFUSE][c * np + i] = (float)(alb * dif);
        r->buf[KPCN_BUF_SPECULAR][c * np + i] = (float)spe;
        n->buf[KPCN_BUF_DIFFUSE][c * np + i] =
            (float)fmax(0, alb * dif * (1 + 0.6 * (kt_randf(&st) - 0.5)));
        n->buf[KPCN_BUF_SPECULAR][c * np + i] = (float)fmax(0, spe + 0.1 * (kt_randf(&st) - 0.5));
      }
      double nx = 0.3 * sin(3 * u), ny = 0.3 * cos(4 * v), nz = sqrt(1 - nx * nx - ny * ny);
      float nn[3] = {(float)nx, (float)ny, (float)nz};
      for (int c = 0; c < 3; c++)
        n->buf[KPCN_BUF_NORMAL][c * np + i] = r->buf[KPCN_BUF_NORMAL][c * np + i] = nn[c];
      n->buf[KPCN_BUF_DEPTH][i] = r->buf[KPCN_BUF_DEPTH][i] = (float)(2 + 3 * u + v);
      n->buf[KPCN_BUF_VISIBILITY][i] = r->buf[KPCN_BUF_VISIBILITY][i] =
          (u + v > 0.8) ? 1.0f : 0.25f;
      for (int b = 0; b < KPCN_BUF_COUNT; b++) {
        n->var[b][i] = b == KPCN_BUF_DIFFUSE || b == KPCN_BUF_COLOR ? 0.01f : 0.001f;
        r->var[b][i] = 0;
      }
    }
  if (box_ref) {
    float eps = KPCN_FEATURES_DEFAULT_EPS;
    float *tmp = malloc(np * sizeof(float)), *tmp2 = malloc(np * sizeof(float));
    for (int c = 0; c < 3; c++) {
      const float *alb = n->buf[KPCN_BUF_ALBEDO] + c * np;
      kpcn_demodulate_diffuse(n->buf[KPCN_BUF_DIFFUSE] + c * np, alb, eps, np, tmp);
      box3(tmp, tmp2, w, h);
      kpcn_remodulate_diffuse(tmp2, alb, eps, np, r->buf[KPCN_BUF_DIFFUSE] + c * np);
      kpcn_log_specular(n->buf[KPCN_BUF_SPECULAR] + c * np, np, tmp);
      box3(tmp, tmp2, w, h);
      kpcn_exp_specular(tmp2, np, r->buf[KPCN_BUF_SPECULAR] + c * np);
    }
    free(tmp), free(tmp2);
  }
  for (size_t i = 0; i < 3 * np; i++) {
    n->buf[KPCN_BUF_COLOR][i] = n->buf[KPCN_BUF_DIFFUSE][i] + n->buf[KPCN_BUF_SPECULAR][i];
    r->buf[KPCN_BUF_COLOR][i] = r->buf[KPCN_BUF_DIFFUSE][i] + r->buf[KPCN_BUF_SPECULAR][i];
  }
  *noisy = n, *ref = r;
  return 0;
}

int tf_make_store(const char *path, int S, int w, int h, int count, unsigned seed, int box_ref,
                  const char *const *channels, int nchannels) {
  static const char *const train[1] = {"train"};
  return tf_make_split_store(path, S, w, h, count, seed, box_ref, channels, nchannels, train, 1);
}

int tf_make_split_store(const char *path, int S, int w, int h, int count, unsigned seed,
                        int box_ref, const char *const *channels, int nchannels,
                        const char *const *splits, int nsources) {
  kpcn_aov_set *n, *r;
  if (tf_make_pair(&n, &r, w, h, seed, box_ref)) return 1;
  kpcn_patchstore_settings s;
  kpcn_patchstore_settings_defaults(&s);
  s.patch_size = S;
  s.channels = channels;
  s.nchannels = channels ? nchannels : 0;
  kpcn_patchstore_writer *wr;
  int rc = 1;
  if (kpcn_patchstore_create(&wr, path, &s) != KPCN_OK) goto out;
  uint32_t id[8];
  if (nsources < 1 || nsources > 8) goto fail;
  for (int k = 0; k < nsources; k++) {
    kpcn_patch_source src;
    memset(&src, 0, sizeof src);
    snprintf(src.scene, sizeof src.scene, "synthetic%d", k);
    snprintf(src.split, sizeof src.split, "%s", splits[k]);
    src.spp = 4, src.ref_spp = 1024, src.width = w, src.height = h;
    if (kpcn_patch_source_image_stats(&src, n) != KPCN_OK) goto fail;
    if (kpcn_patchstore_add_source(wr, &src, &id[k]) != KPCN_OK) goto fail;
  }
  int per_row = (w - S) / 4 + 1;
  for (int i = 0; i < count; i++) {
    kpcn_patch_record rec;
    memset(&rec, 0, sizeof rec);
    rec.source = id[i % nsources];
    rec.x = (i % per_row) * 4;
    rec.y = ((i / per_row) * 4) % (h - S + 1);
    rec.weight = 1;
    if (kpcn_patchstore_append_aov(wr, &rec, n, r) != KPCN_OK) goto fail;
  }
  rc = kpcn_patchstore_finish(wr) != KPCN_OK;
  goto out;
fail:
  fprintf(stderr, "tf_make_store: %s\n", kpcn_last_error());
  kpcn_patchstore_abort(wr);
out:
  if (rc) fprintf(stderr, "tf_make_store: %s\n", kpcn_last_error());
  kpcn_aov_destroy(n);
  kpcn_aov_destroy(r);
  return rc;
}

const char *tf_tmp(const char *name) {
  static char pool[64][512];
  static int next = 0;
  char *p = pool[next++ % 64];
  snprintf(p, sizeof pool[0], "%s", kt_tmpfile(name));
  return p;
}

const char *tf_make_test_store(const char *name) {
  static char store[512]; /* out of tf_tmp's pool, which wraps after 64 names */
  snprintf(store, sizeof store, "%s", tf_tmp(name));
  if (tf_make_store(store, 20, 48, 40, 12, 1, 0, NULL, 0) != 0) {
    fprintf(stderr, "cannot build the synthetic store: %s\n", kpcn_last_error());
    return NULL;
  }
  return store;
}

void tf_settings(kpcn_train_settings *s, const char *store, const char *out) {
  kpcn_train_settings_defaults(s);
  kpcn_arch_preset("tiny", &s->arch);
  s->arch.channels = 16;
  s->store_path = store;
  s->out_path = out;
  s->batch = 3;
  s->patch = 16;
  s->iters = 6;
  s->stage1_iters = 3;
  s->nthreads = 2;
  s->seed = 5;
  s->adam.lr = 1e-2;
  s->log_every = 2;
}

float *tf_model_weights(kpcn_model *m, size_t *n) {
  const kpcn_arch *a = kpcn_model_arch(m);
  size_t tot = 2 * kpcn_arch_param_count(a), k = 0;
  float *w = malloc(tot * sizeof(float));
  for (int b = 0; b < 2; b++)
    for (int l = 0; l < kpcn_arch_n_layers(a); l++) {
      kpcn_layer_view v;
      kpcn_model_layer(m, (kpcn_branch)b, l, &v);
      size_t nw = (size_t)v.out_ch * v.in_ch * v.size * v.size;
      memcpy(w + k, v.weight, nw * sizeof(float)), k += nw;
      memcpy(w + k, v.bias, v.out_ch * sizeof(float)), k += v.out_ch;
    }
  *n = k;
  return w;
}

void tf_val_pair(kpcn_train_settings *s, const char *prefix, const char **vn, const char **vr) {
  kpcn_aov_set *n = NULL, *r = NULL;
  char name[64];
  CHECK(tf_make_pair(&n, &r, 40, 32, 9, 0) == 0);
  snprintf(name, sizeof name, "%s_noisy.exr", prefix);
  vn[0] = tf_tmp(name);
  snprintf(name, sizeof name, "%s_ref.exr", prefix);
  vr[0] = tf_tmp(name);
  CHECK(kpcn_exr_write_aov(vn[0], n, NULL) == KPCN_OK);
  CHECK(kpcn_exr_write_aov(vr[0], r, NULL) == KPCN_OK);
  kpcn_aov_destroy(n), kpcn_aov_destroy(r);
  s->nval = 1, s->val_noisy = vn, s->val_ref = vr;
  s->nthreads = 1;
}

int tf_stop_at;
int tf_stop_cb(void *user, const kpcn_train_progress *p) {
  (void)user;
  return p->iter >= tf_stop_at;
}
