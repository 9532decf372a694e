/* Training batches: patch-store channels -> crop (shift) -> augmentation -> features and
 * targets, one sample per OpenMP iteration. Everything random is drawn beforehand in the
 * calling thread (patch index, crop offset from the trainer's RNG; the rotation / mirror /
 * colour draw from kpcn_augment_draw(seed, sample counter)), so a batch depends only on the
 * RNG state and the iteration, never on the thread count. */
#include "core/internal.h"
#include "train/train_internal.h"

#include <math.h>
#include <omp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const kpcn_buffer k_needed[] = {KPCN_BUF_DIFFUSE, KPCN_BUF_SPECULAR, KPCN_BUF_ALBEDO,
                                       KPCN_BUF_NORMAL,  KPCN_BUF_DEPTH,    KPCN_BUF_VISIBILITY};
#define N_NEEDED ((int)(sizeof k_needed / sizeof k_needed[0]))

static kpcn_status find_ch(kpcn_trainer *t, const char *name, int *out) {
  *out = kpcn_patchstore_find_channel(t->ps, name);
  if (*out < 0)
    return kpcn_fail(KPCN_ERR_FORMAT,
                     "patch store '%s' has no channel '%s', which the trainer needs (the model's "
                     "%d input features are built from the noisy diffuse, specular, albedo, N, Z, "
                     "visibility buffers and their variances; targets from ref.R/G/B, "
                     "ref.diffuse.*, ref.specular.*)",
                     t->store_path, name, t->nfeat);
  return KPCN_OK;
}

kpcn_status kt_batch_setup(kpcn_trainer *t) {
  t->S = kpcn_patchstore_patch_size(t->ps);
  t->nch = kpcn_patchstore_nchannels(t->ps);
  if (t->P > t->S)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "training patch size %d (kpcn-train --patch, default 64) is larger than "
                     "the patch store's %d ('%s'): train with --patch %d or less, or cut the "
                     "store with kpcn-dataset patches --size %d or more (one pixel more than "
                     "the training patch leaves room for the random shift)",
                     t->P, t->S, t->store_path, t->S, t->P + 1);
  for (int b = 0; b < KPCN_BUF_COUNT; b++) {
    t->ch_var[b] = -1;
    for (int c = 0; c < 3; c++)
      t->ch_buf[b][c] = -1;
  }
  for (int i = 0; i < N_NEEDED; i++) {
    kpcn_buffer b = k_needed[i];
    for (int c = 0; c < kpcn_buffer_channels(b); c++)
      KPCN_TRY(find_ch(t, kpcn_buffer_channel_name(b, c), &t->ch_buf[b][c]));
    KPCN_TRY(find_ch(t, kpcn_buffer_variance_name(b), &t->ch_var[b]));
  }
  static const char *rc[3] = {"ref.R", "ref.G", "ref.B"};
  static const char *rd[3] = {"ref.diffuse.R", "ref.diffuse.G", "ref.diffuse.B"};
  static const char *rs[3] = {"ref.specular.R", "ref.specular.G", "ref.specular.B"};
  for (int c = 0; c < 3; c++) {
    KPCN_TRY(find_ch(t, rc[c], &t->ch_ref_color[c]));
    KPCN_TRY(find_ch(t, rd[c], &t->ch_ref_diff[c]));
    KPCN_TRY(find_ch(t, rs[c], &t->ch_ref_spec[c]));
  }
  /* training subset: sources whose split is "train" (all when none is marked) */
  uint64_t n = kpcn_patchstore_count(t->ps);
  if (n == 0) return kpcn_fail(KPCN_ERR_FORMAT, "patch store '%s' holds no patches", t->store_path);
  int nsrc = kpcn_patchstore_nsources(t->ps), any_train = 0;
  for (int i = 0; i < nsrc; i++)
    if (strcmp(kpcn_patchstore_source(t->ps, i)->split, "train") == 0) any_train = 1;
  t->train_idx = kpcn_alloc(n * sizeof(uint64_t), "training patch index");
  if (!t->train_idx) return kpcn_last_status();
  t->ntrain = 0;
  for (uint64_t i = 0; i < n; i++) {
    if (any_train) { /* the record alone: a store larger than memory is not read here */
      kpcn_patch_record rec;
      KPCN_TRY(kpcn_patchstore_record(t->ps, i, &rec));
      const kpcn_patch_source *src = kpcn_patchstore_source(t->ps, (int)rec.source);
      if (!src || strcmp(src->split, "train") != 0) continue;
    }
    t->train_idx[t->ntrain++] = i;
  }
  if (t->ntrain == 0)
    return kpcn_fail(KPCN_ERR_FORMAT, "patch store '%s' has no training patches", t->store_path);
  kpcn_log(t->s.log, t->s.log_user, KPCN_LOG_INFO,
           "patch store '%s': %llu patches (%llu for training), %dx%d, %d channels", t->store_path,
           (unsigned long long)n, (unsigned long long)t->ntrain, t->S, t->S, t->nch);
  return KPCN_OK;
}

/* Per-thread scratch: raw S*S*nch, crop P*P*nch, augmented P*P*nch, canonical 24 planes. */
size_t kt_scratch_floats(int S, int P, int nch) {
  return (size_t)nch * S * S + 2 * (size_t)nch * P * P + 24 * (size_t)P * P;
}

static kpcn_status one_sample(kpcn_trainer *t, int b, float *scr) {
  const int S = t->S, P = t->P, nch = t->nch;
  const size_t pp = (size_t)P * P;
  float *raw = scr, *crop = raw + (size_t)nch * S * S, *aug = crop + (size_t)nch * pp;
  float *canon = aug + (size_t)nch * pp;
  kpcn_patch_record rec;
  KPCN_TRY(kpcn_patchstore_get(t->ps, t->batch_idx[b], raw, &rec));
  /* a NaN/Inf in the store would surface iterations later as a diverged loss; name it here */
  for (size_t i = 0; i < (size_t)nch * S * S; i++)
    if (!isfinite(raw[i]))
      return kpcn_fail(KPCN_ERR_NONFINITE,
                       "patch %llu (source %u at %d,%d) holds a non-finite value in channel '%s'",
                       (unsigned long long)t->batch_idx[b], rec.source, rec.x, rec.y,
                       kpcn_patchstore_channels(t->ps)[i / ((size_t)S * S)]);
  const kpcn_patch_source *src = kpcn_patchstore_source(t->ps, (int)rec.source);
  int ox = t->batch_ox[b], oy = t->batch_oy[b];
  for (int c = 0; c < nch; c++)
    for (int y = 0; y < P; y++)
      memcpy(crop + c * pp + (size_t)y * P, raw + ((size_t)c * S + y + oy) * S + ox,
             (size_t)P * sizeof(float));
  kpcn_augment_xform xf;
  kpcn_augment_draw(&xf, &t->s.augment, t->s.seed,
                    (uint64_t)t->iter * (uint64_t)t->N + (uint64_t)b);
  KPCN_TRY(kpcn_augment_planes(aug, crop, nch, kpcn_patchstore_channels(t->ps), P, P, &xf, 1));
  /* canonical AOV view (3 contiguous planes per colour buffer) */
  kpcn_aov_set aov;
  memset(&aov, 0, sizeof aov);
  aov.width = aov.height = P;
  aov.spp = -1;
  aov.seed = -1;
  float *cur = canon;
  for (int i = 0; i < N_NEEDED; i++) {
    kpcn_buffer bb = k_needed[i];
    aov.buf[bb] = cur;
    for (int c = 0; c < kpcn_buffer_channels(bb); c++, cur += pp)
      memcpy(cur, aug + (size_t)t->ch_buf[bb][c] * pp, pp * sizeof(float));
    aov.var[bb] = cur;
    memcpy(cur, aug + (size_t)t->ch_var[bb] * pp, pp * sizeof(float));
    cur += pp;
  }
  /* depth normalisation of the SOURCE image (same as full-image inference), and its
   * exposure scale when patches are shown at the model's exposure (record_exposure in
   * trainer.c checked that every source records one) */
  kpcn_features_norm norm = {0.0f, 1.0f, 1.0f};
  if (src) {
    double range = (double)src->depth_max - (double)src->depth_min;
    norm.depth_offset = src->depth_min;
    norm.depth_scale = range >= 1e-12 ? (float)(1.0 / range) : 1.0f;
    if (t->s.normalize_exposure) norm.color_scale = (float)(t->arch.exposure / src->exposure);
  }
  if (norm.color_scale != 1.0f) /* the targets at the same exposure as the input */
    for (int c = 0; c < 3; c++) {
      const int ch[3] = {t->ch_ref_diff[c], t->ch_ref_spec[c], t->ch_ref_color[c]};
      for (int k = 0; k < 3; k++)
        for (size_t i = 0; i < pp; i++)
          aug[(size_t)ch[k] * pp + i] *= norm.color_scale;
    }
  float eps = t->arch.eps;
  if (t->s.firefly > 0.0) /* the denoiser's input conditioning, on the (augmented) patch */
    KPCN_TRY(
        kpcn_aov_bound_fireflies(&aov, (float)t->s.firefly, eps, src ? src->exposure : 0.0, NULL));
  size_t f3 = 3 * pp;
  for (int br = 0; br < KT_NB; br++)
    KPCN_TRY(kpcn_features_build(&aov, br, eps, &norm, t->feat[br] + (size_t)b * t->nfeat * pp,
                                 t->noisy[br] + (size_t)b * f3, 1));
  float *alb = t->albedo + (size_t)b * f3;
  memcpy(alb, aov.buf[KPCN_BUF_ALBEDO], f3 * sizeof(float));
  for (int c = 0; c < 3; c++) {
    kpcn_demodulate_diffuse(aug + (size_t)t->ch_ref_diff[c] * pp, alb + c * pp, eps, pp,
                            t->target[0] + (size_t)b * f3 + c * pp);
    kpcn_log_specular(aug + (size_t)t->ch_ref_spec[c] * pp, pp,
                      t->target[1] + (size_t)b * f3 + c * pp);
    memcpy(t->refc + (size_t)b * f3 + c * pp, aug + (size_t)t->ch_ref_color[c] * pp,
           pp * sizeof(float));
  }
  return KPCN_OK;
}

kpcn_status kt_batch_assemble(kpcn_trainer *t) {
  /* all random draws first, in order, in this thread */
  for (int b = 0; b < t->N; b++) {
    t->batch_idx[b] = t->train_idx[kpcn_rng_below(&t->rng, (uint32_t)t->ntrain)];
    int span = t->S - t->P + 1;
    if (t->s.crop_jitter) {
      t->batch_ox[b] = (int)kpcn_rng_below(&t->rng, (uint32_t)span);
      t->batch_oy[b] = (int)kpcn_rng_below(&t->rng, (uint32_t)span);
    } else {
      t->batch_ox[b] = t->batch_oy[b] = (t->S - t->P) / 2;
    }
  }
  kpcn_status bad = KPCN_OK;
  char msg[512] = "";
  int nt = t->nt < t->N ? t->nt : t->N;
#pragma omp parallel for num_threads(nt) schedule(static)
  for (int b = 0; b < t->N; b++) {
    float *scr = t->scratch + (size_t)omp_get_thread_num() * t->scratch_per_thread;
    kpcn_status sb = one_sample(t, b, scr);
    if (sb != KPCN_OK) {
#pragma omp critical(kt_batch_err)
      if (bad == KPCN_OK) {
        bad = sb;
        snprintf(msg, sizeof msg, "%s", kpcn_last_error());
      }
    }
  }
  if (bad != KPCN_OK) return kpcn_fail(bad, "building training batch: %s", msg);
  return KPCN_OK;
}

kpcn_status kt_loss(kpcn_trainer *t, kpcn_loss_kind kind, const float *pred, const float *ref,
                    float *grad, double *value) {
  int m = t->s.loss_margin, P = t->P;
  if (m <= 0)
    return kpcn_loss_compute(kind, &t->s.loss, pred, ref, t->N, 3, P, P, grad, value, t->nt);
  int Q = P - 2 * m;
  size_t qq = (size_t)Q * Q, planes = (size_t)t->N * 3;
  float *cp = t->lossbuf, *cr = cp + planes * qq, *cg = cr + planes * qq;
  for (size_t p = 0; p < planes; p++)
    for (int y = 0; y < Q; y++) {
      memcpy(cp + p * qq + (size_t)y * Q, pred + (p * P + y + m) * P + m, Q * sizeof(float));
      memcpy(cr + p * qq + (size_t)y * Q, ref + (p * P + y + m) * P + m, Q * sizeof(float));
    }
  KPCN_TRY(kpcn_loss_compute(kind, &t->s.loss, cp, cr, t->N, 3, Q, Q, cg, value, t->nt));
  memset(grad, 0, planes * P * P * sizeof(float));
  for (size_t p = 0; p < planes; p++)
    for (int y = 0; y < Q; y++)
      memcpy(grad + (p * P + y + m) * P + m, cg + p * qq + (size_t)y * Q, Q * sizeof(float));
  return KPCN_OK;
}
