/* Layered materials as Tungsten models them: plastic (smooth dielectric coat over a diffuse
 * base with Fresnel-weighted internal re-reflection A/(1 - A*Fdr)), rough_plastic (same base
 * under a rough dielectric reflection lobe) and smooth_coat (a smooth dielectric layer with
 * absorption over any non-transmissive substrate bsdf). Lobe choice uses the specular/substrate
 * weights Fi : avgTransmittance*(1-Fi), like Tungsten. */
#include "render/bsdf_internal.h"
#include "render/fresnel.h"
#include "render/sampling.h"

#include <math.h>

static inline kpcn_vec3 absorption(const kpcn_bsdf *b, float cos_a, float cos_b) {
  if (!b->has_absorption) return kv3s(1.0f);
  return kv3_exp(kv3_scale(b->scaled_sigma_a, -1.0f / cos_a - 1.0f / cos_b));
}

static inline float spec_probability(const kpcn_bsdf *b, float Fi) {
  float sub = b->avg_transmittance * (1.0f - Fi);
  float tot = Fi + sub;
  return tot > 0.0f ? Fi / tot : 0.0f;
}

/* f*cos of the diffuse base of (rough) plastic (Tungsten's "substrate" term). */
static kpcn_vec3 plastic_diffuse(const kpcn_bsdf *b, const kpcn_shading_point *sp, kpcn_vec3 wo,
                                 kpcn_vec3 wi) {
  float eta = 1.0f / b->ior;
  float Fi = kpcn_fresnel_dielectric(eta, wo.z, NULL);
  float Fo = kpcn_fresnel_dielectric(eta, wi.z, NULL);
  kpcn_vec3 a = kb_albedo(b, sp);
  kpcn_vec3 denom = kv3_sub(kv3s(1.0f), kv3_scale(a, b->diffuse_fresnel));
  kpcn_vec3 f =
      kv3_scale(kv3_div(a, denom), (1.0f - Fi) * (1.0f - Fo) * eta * eta * wi.z * KPCN_INV_PI);
  return kv3_mul(f, absorption(b, wi.z, wo.z));
}

/* ---- plastic ---- */

int kb_plastic_sample(const kpcn_bsdf *b, const kpcn_shading_point *sp, kpcn_vec3 wo, float u1,
                      float u2, float ulobe, kpcn_bsdf_sample_result *s) {
  if (wo.z <= 0.0f) return 0;
  float Fi = kpcn_fresnel_dielectric(1.0f / b->ior, wo.z, NULL);
  float ps = spec_probability(b, Fi);
  if (ulobe < ps) {
    kb_set_delta(s, kb_reflect_z(wo), kv3s(Fi / ps), ps, KPCN_LOBE_SPECULAR);
    return 1;
  }
  kpcn_vec3 wi = kpcn_warp_cosine_hemisphere(u1, u2);
  if (wi.z <= 0.0f) return 0;
  float pdf = wi.z * KPCN_INV_PI * (1.0f - ps);
  s->wi = wi;
  s->weight = s->weight_diffuse = kv3_scale(plastic_diffuse(b, sp, wo, wi), 1.0f / pdf);
  s->pdf = pdf;
  s->lobe = KPCN_LOBE_DIFFUSE;
  s->is_delta = 0;
  return 1;
}

void kb_plastic_eval(const kpcn_bsdf *b, const kpcn_shading_point *sp, kpcn_vec3 wo, kpcn_vec3 wi,
                     kpcn_bsdf_eval_result *r) {
  kb_eval_zero(r);
  if (wo.z <= 0.0f || wi.z <= 0.0f) return;
  float Fi = kpcn_fresnel_dielectric(1.0f / b->ior, wo.z, NULL);
  float ps = spec_probability(b, Fi);
  r->f_cos = r->f_cos_diffuse = plastic_diffuse(b, sp, wo, wi);
  r->pdf = wi.z * KPCN_INV_PI * (1.0f - ps);
}

/* ---- rough plastic ---- */

void kb_rough_plastic_eval(const kpcn_bsdf *b, const kpcn_shading_point *sp, kpcn_vec3 wo,
                           kpcn_vec3 wi, kpcn_bsdf_eval_result *r) {
  kb_eval_zero(r);
  if (wo.z <= 0.0f || wi.z <= 0.0f) return;
  float rough = kb_roughness(b, sp);
  float gpdf;
  float glossy = kb_rough_dielectric_eval_base(wo, wi, 1, 0, rough, b->ior, b->dist, &gpdf);
  kpcn_vec3 diff = plastic_diffuse(b, sp, wo, wi);
  float Fi = kpcn_fresnel_dielectric(1.0f / b->ior, wo.z, NULL);
  float ps = spec_probability(b, Fi);
  r->f_cos = kv3_add(diff, kv3s(glossy));
  r->f_cos_diffuse = diff;
  r->pdf = gpdf * ps + wi.z * KPCN_INV_PI * (1.0f - ps);
}

int kb_rough_plastic_sample(const kpcn_bsdf *b, const kpcn_shading_point *sp, kpcn_vec3 wo,
                            float u1, float u2, float ulobe, kpcn_bsdf_sample_result *s) {
  if (wo.z <= 0.0f) return 0;
  float Fi = kpcn_fresnel_dielectric(1.0f / b->ior, wo.z, NULL);
  float ps = spec_probability(b, Fi);
  kpcn_vec3 wi;
  int lobe;
  if (ulobe < ps) {
    float w, p;
    int refl;
    if (!kb_rough_dielectric_sample_base(wo, u1, u2, 0.0f, 1, 0, kb_roughness(b, sp), b->ior,
                                         b->dist, &wi, &w, &p, &refl))
      return 0;
    lobe = KPCN_LOBE_GLOSSY;
  } else {
    wi = kpcn_warp_cosine_hemisphere(u1, u2);
    lobe = KPCN_LOBE_DIFFUSE;
  }
  if (wi.z <= 0.0f) return 0;
  /* one-sample MIS over the two lobes: weight = (f_glossy + f_diffuse) / (mixture pdf) */
  kpcn_bsdf_eval_result r;
  kb_rough_plastic_eval(b, sp, wo, wi, &r);
  if (!(r.pdf > 0.0f)) return 0;
  s->wi = wi;
  s->weight = kv3_scale(r.f_cos, 1.0f / r.pdf);
  s->weight_diffuse = kv3_scale(r.f_cos_diffuse, 1.0f / r.pdf);
  s->pdf = r.pdf;
  s->lobe = lobe;
  s->is_delta = 0;
  return 1;
}

/* ---- smooth coat ---- */

int kb_smooth_coat_sample(const kpcn_bsdf *b, const kpcn_shading_point *sp, kpcn_vec3 wo, float u1,
                          float u2, float ulobe, kpcn_bsdf_sample_result *s) {
  if (wo.z <= 0.0f) return 0;
  float eta = 1.0f / b->ior;
  float cos_ti;
  float Fi = kpcn_fresnel_dielectric(eta, wo.z, &cos_ti);
  float ps = spec_probability(b, Fi);
  if (ulobe < ps) {
    kb_set_delta(s, kb_reflect_z(wo), kv3s(Fi / ps), ps, KPCN_LOBE_SPECULAR);
    return 1;
  }
  /* reuse the lobe number for the substrate's own lobe choice */
  float ul = (ulobe - ps) / (1.0f - ps);
  if (ul >= 1.0f) ul = 0x1.fffffep-1f;
  kpcn_vec3 wo_sub = kv3(wo.x * eta, wo.y * eta, cos_ti);
  kpcn_bsdf_sample_result ss;
  if (!kpcn_bsdf_sample(b->substrate, sp, wo_sub, u1, u2, ul, &ss)) return 0;
  float cos_sub = ss.wi.z;
  if (cos_sub <= 0.0f) return 0;
  float cos_to;
  float Fo = kpcn_fresnel_dielectric(b->ior, cos_sub, &cos_to);
  if (Fo >= 1.0f) return 0;
  kpcn_vec3 wi = kv3(ss.wi.x * b->ior, ss.wi.y * b->ior, cos_to);
  kpcn_vec3 scale =
      kv3_scale(absorption(b, cos_sub, cos_ti), (1.0f - Fi) * (1.0f - Fo) / (1.0f - ps));
  s->wi = wi;
  s->weight = kv3_mul(ss.weight, scale);
  s->weight_diffuse = kv3_mul(ss.weight_diffuse, scale);
  s->pdf = ss.is_delta ? ss.pdf * (1.0f - ps) : ss.pdf * (1.0f - ps) * eta * eta * cos_to / cos_sub;
  s->lobe = ss.lobe;
  s->is_delta = ss.is_delta;
  return 1;
}

void kb_smooth_coat_eval(const kpcn_bsdf *b, const kpcn_shading_point *sp, kpcn_vec3 wo,
                         kpcn_vec3 wi, kpcn_bsdf_eval_result *r) {
  kb_eval_zero(r);
  if (wo.z <= 0.0f || wi.z <= 0.0f) return;
  float eta = 1.0f / b->ior;
  float cos_ti, cos_to;
  float Fi = kpcn_fresnel_dielectric(eta, wo.z, &cos_ti);
  float Fo = kpcn_fresnel_dielectric(eta, wi.z, &cos_to);
  if (cos_to <= 0.0f || cos_ti <= 0.0f) return;
  kpcn_vec3 wo_sub = kv3(wo.x * eta, wo.y * eta, cos_ti);
  kpcn_vec3 wi_sub = kv3(wi.x * eta, wi.y * eta, cos_to);
  kpcn_bsdf_eval_result sr;
  kpcn_bsdf_eval(b->substrate, sp, wo_sub, wi_sub, &sr);
  float laplacian = eta * eta * wi.z / cos_to;
  kpcn_vec3 scale = kv3_scale(absorption(b, cos_to, cos_ti), laplacian * (1.0f - Fi) * (1.0f - Fo));
  r->f_cos = kv3_mul(sr.f_cos, scale);
  r->f_cos_diffuse = kv3_mul(sr.f_cos_diffuse, scale);
  float ps = spec_probability(b, Fi);
  r->pdf = sr.pdf * (1.0f - ps) * eta * eta * fabsf(wi.z / cos_to);
}
