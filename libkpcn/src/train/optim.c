/* Adam optimizer (Kingma & Ba 2014, Algorithm 1), exponential learning-rate decay,
 * global-norm gradient clipping, Xavier/Glorot init and the trainer's RNG.
 *
 * Determinism: Adam is element-wise; the gradient norm is reduced over fixed 4096-float
 * chunks whose partials are summed in index order, so every result is bitwise
 * independent of the thread count. */
#include "core/internal.h"
#include "kpcn/train.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* ---- RNG: splitmix64 (one 64-bit word of state, trivially checkpointed). ---- */
void kpcn_rng_seed(kpcn_rng *r, uint64_t seed) { r->state = seed * 0x9E3779B97F4A7C15ull + 1; }

uint64_t kpcn_rng_next(kpcn_rng *r) {
  uint64_t z = (r->state += 0x9E3779B97F4A7C15ull);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

double kpcn_rng_uniform(kpcn_rng *r) { return (double)(kpcn_rng_next(r) >> 11) * 0x1.0p-53; }

uint32_t kpcn_rng_below(kpcn_rng *r, uint32_t n) {
  /* Lemire's multiply-shift; bias < n/2^64, irrelevant here. */
  return n ? (uint32_t)(((unsigned __int128)kpcn_rng_next(r) * n) >> 64) : 0;
}

/* ---- Xavier / Glorot uniform: U(-a, a), a = sqrt(6 / (fan_in + fan_out)), with
 * fan_in = Cin*k*k and fan_out = Cout*k*k for a conv (TensorFlow's glorot_uniform,
 * which the seed used through TensorFlow). ---- */
kpcn_status kpcn_xavier_uniform(float *w, size_t count, int fan_in, int fan_out, kpcn_rng *rng) {
  if (!w || !rng || fan_in <= 0 || fan_out <= 0)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "kpcn_xavier_uniform: bad argument (fan_in %d, "
                     "fan_out %d)",
                     fan_in, fan_out);
  double a = sqrt(6.0 / ((double)fan_in + (double)fan_out));
  for (size_t i = 0; i < count; i++)
    w[i] = (float)((2.0 * kpcn_rng_uniform(rng) - 1.0) * a);
  return KPCN_OK;
}

/* ---- learning-rate schedule ---- */
void kpcn_adam_settings_defaults(kpcn_adam_settings *s) {
  s->lr = 1e-3;
  s->beta1 = 0.9;
  s->beta2 = 0.999;
  s->eps = 1e-8;
  s->lr_decay = 0.96;
  s->decay_every = 100000; /* seed §6.4: x0.96 every 100k iterations */
  s->staircase = 0;
  s->clip_norm = 0.0;
}

double kpcn_adam_lr_at(const kpcn_adam_settings *s, int64_t iter) {
  if (s->decay_every <= 0 || s->lr_decay == 1.0) return s->lr;
  double e = (double)iter / (double)s->decay_every;
  if (s->staircase) e = floor(e);
  return s->lr * pow(s->lr_decay, e);
}

/* ---- Adam ---- */
struct kpcn_adam {
  kpcn_adam_settings s;
  size_t count;
  int64_t t; /* steps taken */
  float *m, *v;
};

kpcn_status kpcn_adam_create(kpcn_adam **out, const kpcn_adam_settings *s, size_t count) {
  if (!out || !s) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_adam_create: NULL argument");
  *out = NULL;
  if (!(s->lr > 0) || !(s->beta1 >= 0 && s->beta1 < 1) || !(s->beta2 >= 0 && s->beta2 < 1) ||
      !(s->eps > 0) || !(s->lr_decay > 0) || s->clip_norm < 0)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "Adam settings out of range (lr %g, beta1 %g, beta2 %g, eps %g, decay %g)",
                     s->lr, s->beta1, s->beta2, s->eps, s->lr_decay);
  kpcn_adam *a = kpcn_calloc(1, sizeof *a, "Adam state");
  if (!a) return kpcn_last_status();
  a->s = *s;
  a->count = count;
  a->m = kpcn_calloc(count ? count : 1, sizeof(float), "Adam first moments");
  a->v = kpcn_calloc(count ? count : 1, sizeof(float), "Adam second moments");
  if (!a->m || !a->v) {
    kpcn_adam_destroy(a);
    return KPCN_ERR_OUT_OF_MEMORY;
  }
  *out = a;
  return KPCN_OK;
}

void kpcn_adam_destroy(kpcn_adam *a) {
  if (!a) return;
  free(a->m);
  free(a->v);
  free(a);
}

size_t kpcn_adam_count(const kpcn_adam *a) { return a->count; }
int64_t kpcn_adam_steps(const kpcn_adam *a) { return a->t; }
float *kpcn_adam_moment1(kpcn_adam *a) { return a->m; }
float *kpcn_adam_moment2(kpcn_adam *a) { return a->v; }
void kpcn_adam_set_steps(kpcn_adam *a, int64_t t) { a->t = t; }
void kpcn_adam_set_lr(kpcn_adam *a, double lr) {
  if (a && lr > 0) a->s.lr = lr;
}
const kpcn_adam_settings *kpcn_adam_get_settings(const kpcn_adam *a) { return &a->s; }

#define NORM_CHUNK 4096

double kpcn_grad_norm(const kpcn_param_block *blocks, int nblocks, int nthreads) {
  int nt = kpcn_resolve_threads(nthreads);
  double total = 0.0;
  for (int b = 0; b < nblocks; b++) {
    size_t n = blocks[b].count, nch = (n + NORM_CHUNK - 1) / NORM_CHUNK;
    if (!n) continue;
    double stackp[64], *part = nch <= 64 ? stackp : malloc(nch * sizeof(double));
    if (!part) return NAN;
    const float *g = blocks[b].grad;
/* small tensors run serially: a parallel region costs more than the work (and far more
 * when other processes hold the cores and OpenMP barriers wait for descheduled threads) */
#pragma omp parallel for num_threads(nt) schedule(static) if (nch >= 16)
    for (long long c = 0; c < (long long)nch; c++) {
      size_t i0 = (size_t)c * NORM_CHUNK, i1 = i0 + NORM_CHUNK < n ? i0 + NORM_CHUNK : n;
      double acc = 0.0;
      for (size_t i = i0; i < i1; i++)
        acc += (double)g[i] * g[i];
      part[c] = acc;
    }
    for (size_t c = 0; c < nch; c++)
      total += part[c];
    if (part != stackp) free(part);
  }
  return sqrt(total);
}

kpcn_status kpcn_adam_step(kpcn_adam *a, const kpcn_param_block *blocks, int nblocks, int nthreads,
                           double *grad_norm) {
  if (!a || (!blocks && nblocks))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_adam_step: NULL");
  size_t total = 0;
  for (int b = 0; b < nblocks; b++)
    total += blocks[b].count;
  if (total != a->count)
    return kpcn_fail(KPCN_ERR_SIZE_MISMATCH,
                     "kpcn_adam_step: blocks hold %zu parameters, optimizer was created for %zu",
                     total, a->count);
  /* The norm is always taken: one cheap pass that also catches NaN/Inf gradients
   * before they poison the moments. */
  double gscale = 1.0, norm = kpcn_grad_norm(blocks, nblocks, nthreads);
  if (!isfinite(norm))
    return kpcn_fail(KPCN_ERR_NONFINITE, "gradient norm is %g (loss diverged?)", norm);
  if (a->s.clip_norm > 0 && norm > a->s.clip_norm) gscale = a->s.clip_norm / norm;
  if (grad_norm) *grad_norm = norm;
  a->t++;
  /* lr of this step follows the schedule at the step index (t-1 = iterations done). */
  double lr = kpcn_adam_lr_at(&a->s, a->t - 1);
  double bc1 = 1.0 - pow(a->s.beta1, (double)a->t), bc2 = 1.0 - pow(a->s.beta2, (double)a->t);
  const float b1 = (float)a->s.beta1, b2 = (float)a->s.beta2, eps = (float)a->s.eps;
  const float step = (float)(lr / bc1), ibc2 = (float)(1.0 / bc2), gs = (float)gscale;
  int nt = kpcn_resolve_threads(nthreads);
  size_t off = 0;
  for (int b = 0; b < nblocks; b++) {
    float *p = blocks[b].param, *m = a->m + off, *v = a->v + off;
    const float *g = blocks[b].grad;
    long long n = (long long)blocks[b].count;
    const float sb = step * (blocks[b].lr_scale > 0 ? blocks[b].lr_scale : 1.0f);
#pragma omp parallel for num_threads(nt) schedule(static) if (n >= 65536)
    for (long long i = 0; i < n; i++) {
      float gi = g[i] * gs;
      m[i] = b1 * m[i] + (1.0f - b1) * gi;
      v[i] = b2 * v[i] + (1.0f - b2) * gi * gi;
      /* p -= lr * m_hat / (sqrt(v_hat) + eps), Kingma & Ba Algorithm 1 */
      p[i] -= sb * m[i] / (sqrtf(v[i] * ibc2) + eps);
    }
    off += blocks[b].count;
  }
  return KPCN_OK;
}
