/* Rough conductor and rough dielectric (Walter et al. 2007), as Tungsten defines them:
 * half vectors sampled from D(m) cos(theta_m); the dielectric widens the sampling roughness by
 * (1.2 - 0.2 sqrt|cos|) to tame the weights at grazing angles. */
#include "render/bsdf_internal.h"
#include "render/fresnel.h"
#include "render/microfacet.h"

#include <math.h>

static inline float sgn_nz(float x) { return x < 0.0f ? -1.0f : 1.0f; }
static inline float sqr(float x) { return x * x; }

/* ---- rough conductor ---- */

int kb_rough_conductor_sample(const kpcn_bsdf *b, const kpcn_shading_point *sp, kpcn_vec3 wo,
                              float u1, float u2, kpcn_bsdf_sample_result *s) {
  if (wo.z <= 0.0f) return 0;
  float alpha = kpcn_mf_roughness_to_alpha(b->dist, kb_roughness(b, sp));
  kpcn_vec3 m = kpcn_mf_sample(b->dist, alpha, u1, u2);
  float wo_m = kv3_dot(wo, m);
  kpcn_vec3 wi = kv3_sub(kv3_scale(m, 2.0f * wo_m), wo);
  if (wo_m <= 0.0f || wi.z <= 0.0f) return 0;
  float G = kpcn_mf_G(b->dist, alpha, wo, wi, m);
  float D = kpcn_mf_D(b->dist, alpha, m);
  float pm = kpcn_mf_pdf(b->dist, alpha, m);
  if (!(pm > 0.0f)) return 0;
  float w = wo_m * G * D / (wo.z * pm);
  kpcn_vec3 F = kpcn_fresnel_conductor3(b->eta, b->k, wo_m);
  s->wi = wi;
  s->weight = kv3_scale(kv3_mul(kb_albedo(b, sp), F), w);
  s->weight_diffuse = kv3s(0.0f);
  s->pdf = pm * 0.25f / wo_m;
  s->lobe = KPCN_LOBE_GLOSSY;
  s->is_delta = 0;
  return 1;
}

void kb_rough_conductor_eval(const kpcn_bsdf *b, const kpcn_shading_point *sp, kpcn_vec3 wo,
                             kpcn_vec3 wi, kpcn_bsdf_eval_result *r) {
  kb_eval_zero(r);
  if (wo.z <= 0.0f || wi.z <= 0.0f) return;
  float alpha = kpcn_mf_roughness_to_alpha(b->dist, kb_roughness(b, sp));
  kpcn_vec3 h = kv3_normalize(kv3_add(wo, wi));
  float wo_h = kv3_dot(wo, h);
  if (wo_h <= 0.0f) return;
  kpcn_vec3 F = kpcn_fresnel_conductor3(b->eta, b->k, wo_h);
  float G = kpcn_mf_G(b->dist, alpha, wo, wi, h);
  float D = kpcn_mf_D(b->dist, alpha, h);
  float fr = G * D * 0.25f / wo.z;
  r->f_cos = kv3_scale(kv3_mul(kb_albedo(b, sp), F), fr);
  r->pdf = kpcn_mf_pdf(b->dist, alpha, h) * 0.25f / wo_h;
}

/* ---- rough dielectric ---- */

int kb_rough_dielectric_sample_base(kpcn_vec3 wo, float u1, float u2, float ulobe, int allow_r,
                                    int allow_t, float roughness, float ior,
                                    kpcn_microfacet_dist dist, kpcn_vec3 *wi_out, float *weight,
                                    float *pdf, int *reflected) {
  float wo_n = wo.z;
  if (wo_n == 0.0f) return 0;
  float eta = wo_n < 0.0f ? ior : 1.0f / ior;
  float sample_rough = (1.2f - 0.2f * sqrtf(fabsf(wo_n))) * roughness;
  float alpha = kpcn_mf_roughness_to_alpha(dist, roughness);
  float sample_alpha = kpcn_mf_roughness_to_alpha(dist, sample_rough);
  kpcn_vec3 m = kpcn_mf_sample(dist, sample_alpha, u1, u2);
  float pm = kpcn_mf_pdf(dist, sample_alpha, m);
  if (pm < 1e-10f) return 0;
  float wo_m = kv3_dot(wo, m);
  /* A microfacet facing away from wo has G1(wo) = 0: Tungsten returns such samples with zero
   * weight, but then the sampled directions no longer follow the pdf eval() reports. Rejecting
   * them is equivalent in expectation and keeps sample() and pdf() consistent. */
  if (wo_m * wo_n <= 0.0f) return 0;
  float cos_t = 0.0f;
  float F = kpcn_fresnel_dielectric(1.0f / ior, wo_m, &cos_t);
  float eta_m = wo_m < 0.0f ? ior : 1.0f / ior;
  int reflect;
  if (allow_r && allow_t)
    reflect = ulobe < F;
  else if (allow_t) {
    if (F >= 1.0f) return 0;
    reflect = 0;
  } else if (allow_r)
    reflect = 1;
  else
    return 0;
  kpcn_vec3 wi;
  if (reflect)
    wi = kv3_sub(kv3_scale(m, 2.0f * wo_m), wo);
  else
    wi = kv3_sub(kv3_scale(m, eta_m * wo_m - sgn_nz(wo_m) * cos_t), kv3_scale(wo, eta_m));
  float wi_n = wi.z;
  int refl = wo_n * wi_n > 0.0f;
  if (refl != reflect) return 0;
  float wi_m = kv3_dot(wi, m);
  float G = kpcn_mf_G(dist, alpha, wo, wi, m);
  float D = kpcn_mf_D(dist, alpha, m);
  float w = fabsf(wo_m) * G * D / (fabsf(wo_n) * pm);
  float p;
  if (reflect)
    p = pm * 0.25f / fabsf(wo_m);
  else
    p = pm * fabsf(wi_m) / sqr(eta * wo_m + wi_m);
  if (allow_r && allow_t)
    p *= reflect ? F : 1.0f - F;
  else
    w *= reflect ? F : 1.0f - F;
  if (!(p > 0.0f) || !isfinite(w)) return 0;
  *wi_out = wi;
  *weight = w;
  *pdf = p;
  *reflected = reflect;
  return 1;
}

float kb_rough_dielectric_eval_base(kpcn_vec3 wo, kpcn_vec3 wi, int allow_r, int allow_t,
                                    float roughness, float ior, kpcn_microfacet_dist dist,
                                    float *pdf) {
  *pdf = 0.0f;
  float wo_n = wo.z, wi_n = wi.z;
  if (wo_n == 0.0f) return 0.0f;
  int reflect = wo_n * wi_n >= 0.0f;
  if ((reflect && !allow_r) || (!reflect && !allow_t)) return 0.0f;
  float alpha = kpcn_mf_roughness_to_alpha(dist, roughness);
  float sample_rough = (1.2f - 0.2f * sqrtf(fabsf(wo_n))) * roughness;
  float sample_alpha = kpcn_mf_roughness_to_alpha(dist, sample_rough);
  float eta = wo_n < 0.0f ? ior : 1.0f / ior;
  kpcn_vec3 m;
  if (reflect)
    m = kv3_scale(kv3_normalize(kv3_add(wo, wi)), sgn_nz(wo_n));
  else
    m = kv3_neg(kv3_normalize(kv3_add(kv3_scale(wo, eta), wi)));
  float wo_m = kv3_dot(wo, m), wi_m = kv3_dot(wi, m);
  /* Only configurations sample() can produce have a pdf: m must face wo (see sample_base)
   * and a refraction must cross the microsurface. Tungsten reports a non-zero pdf (with
   * f = 0) for the others, which skews MIS weights. */
  if (wo_m * wo_n <= 0.0f || (!reflect && wo_m * wi_m >= 0.0f)) return 0.0f;
  float F = kpcn_fresnel_dielectric(1.0f / ior, wo_m, NULL);
  float G = kpcn_mf_G(dist, alpha, wo, wi, m);
  float D = kpcn_mf_D(dist, alpha, m);
  float pm = kpcn_mf_pdf(dist, sample_alpha, m);
  float f, p;
  if (reflect) {
    f = F * G * D * 0.25f / fabsf(wo_n);
    p = pm * 0.25f / fabsf(wo_m);
  } else {
    float den = sqr(eta * wo_m + wi_m);
    f = fabsf(wo_m * wi_m) * (1.0f - F) * G * D / (den * fabsf(wo_n));
    p = pm * fabsf(wi_m) / den;
  }
  if (allow_r && allow_t) p *= reflect ? F : 1.0f - F;
  if (!isfinite(f) || !isfinite(p)) return *pdf = 0.0f;
  *pdf = p;
  return f;
}

int kb_rough_dielectric_sample(const kpcn_bsdf *b, const kpcn_shading_point *sp, kpcn_vec3 wo,
                               float u1, float u2, float ulobe, kpcn_bsdf_sample_result *s) {
  kpcn_vec3 wi;
  float w, p;
  int refl;
  if (!kb_rough_dielectric_sample_base(wo, u1, u2, ulobe, 1, b->enable_refraction,
                                       kb_roughness(b, sp), b->ior, b->dist, &wi, &w, &p, &refl))
    return 0;
  s->wi = wi;
  s->weight = kv3_scale(kb_albedo(b, sp), w);
  s->weight_diffuse = kv3s(0.0f);
  s->pdf = p;
  s->lobe = KPCN_LOBE_GLOSSY | (refl ? 0 : KPCN_LOBE_TRANSMISSION);
  s->is_delta = 0;
  return 1;
}

void kb_rough_dielectric_eval(const kpcn_bsdf *b, const kpcn_shading_point *sp, kpcn_vec3 wo,
                              kpcn_vec3 wi, kpcn_bsdf_eval_result *r) {
  kb_eval_zero(r);
  float f = kb_rough_dielectric_eval_base(wo, wi, 1, b->enable_refraction, kb_roughness(b, sp),
                                          b->ior, b->dist, &r->pdf);
  r->f_cos = kv3_scale(kb_albedo(b, sp), f);
}
