/* Private layout of kpcn_bsdf and the per-type entry points (bsdf_*.c). */
#ifndef KPCN_RENDER_BSDF_INTERNAL_H
#define KPCN_RENDER_BSDF_INTERNAL_H

#include "render/bsdf.h"

struct kpcn_bsdf {
  kpcn_bsdf_type type;
  int lobes;
  const kpcn_texture *albedo;    /* never NULL (a shared white constant by default) */
  const kpcn_texture *roughness; /* NULL: roughness_value */
  float roughness_value;
  kpcn_microfacet_dist dist;
  kpcn_vec3 eta, k;
  float ior;
  int enable_refraction;
  float thickness;
  kpcn_vec3 sigma_a;
  /* derived */
  kpcn_vec3 scaled_sigma_a; /* thickness * sigma_a */
  int has_absorption;       /* max(scaled_sigma_a) > 0 */
  float avg_transmittance;  /* exp(-2 avg(scaled_sigma_a)) */
  float diffuse_fresnel;    /* plastic: internal diffuse reflectance of the coat */
  const kpcn_bsdf *substrate;
};

static inline kpcn_vec3 kb_albedo(const kpcn_bsdf *b, const kpcn_shading_point *sp) {
  return kpcn_texture_is_constant(b->albedo) ? b->albedo->value
                                             : kpcn_texture_eval(b->albedo, sp->u, sp->v);
}
static inline float kb_roughness(const kpcn_bsdf *b, const kpcn_shading_point *sp) {
  return b->roughness ? kpcn_texture_eval_scalar(b->roughness, sp->u, sp->v) : b->roughness_value;
}
static inline void kb_eval_zero(kpcn_bsdf_eval_result *r) {
  r->f_cos = r->f_cos_diffuse = kv3s(0.0f);
  r->pdf = 0.0f;
}
static inline kpcn_vec3 kb_reflect_z(kpcn_vec3 w) { return kv3(-w.x, -w.y, w.z); }
/* Fills a delta-lobe sample (mirror, smooth dielectric, specular coat): no diffuse part. */
static inline void kb_set_delta(kpcn_bsdf_sample_result *s, kpcn_vec3 wi, kpcn_vec3 weight,
                                float pdf, int lobe) {
  s->wi = wi;
  s->weight = weight;
  s->weight_diffuse = kv3s(0.0f);
  s->pdf = pdf;
  s->lobe = lobe;
  s->is_delta = 1;
}

/* bsdf_microfacet.c */
int kb_rough_conductor_sample(const kpcn_bsdf *b, const kpcn_shading_point *sp, kpcn_vec3 wo,
                              float u1, float u2, kpcn_bsdf_sample_result *s);
void kb_rough_conductor_eval(const kpcn_bsdf *b, const kpcn_shading_point *sp, kpcn_vec3 wo,
                             kpcn_vec3 wi, kpcn_bsdf_eval_result *r);
/* Rough dielectric interface (also the glossy coat of rough_plastic): allow_r / allow_t select
 * the lobes. Returns the albedo-free value; *weight is f*cos/pdf. */
int kb_rough_dielectric_sample_base(kpcn_vec3 wo, float u1, float u2, float ulobe, int allow_r,
                                    int allow_t, float roughness, float ior,
                                    kpcn_microfacet_dist dist, kpcn_vec3 *wi, float *weight,
                                    float *pdf, int *reflected);
float kb_rough_dielectric_eval_base(kpcn_vec3 wo, kpcn_vec3 wi, int allow_r, int allow_t,
                                    float roughness, float ior, kpcn_microfacet_dist dist,
                                    float *pdf);
int kb_rough_dielectric_sample(const kpcn_bsdf *b, const kpcn_shading_point *sp, kpcn_vec3 wo,
                               float u1, float u2, float ulobe, kpcn_bsdf_sample_result *s);
void kb_rough_dielectric_eval(const kpcn_bsdf *b, const kpcn_shading_point *sp, kpcn_vec3 wo,
                              kpcn_vec3 wi, kpcn_bsdf_eval_result *r);

/* bsdf_layered.c */
int kb_plastic_sample(const kpcn_bsdf *b, const kpcn_shading_point *sp, kpcn_vec3 wo, float u1,
                      float u2, float ulobe, kpcn_bsdf_sample_result *s);
void kb_plastic_eval(const kpcn_bsdf *b, const kpcn_shading_point *sp, kpcn_vec3 wo, kpcn_vec3 wi,
                     kpcn_bsdf_eval_result *r);
int kb_rough_plastic_sample(const kpcn_bsdf *b, const kpcn_shading_point *sp, kpcn_vec3 wo,
                            float u1, float u2, float ulobe, kpcn_bsdf_sample_result *s);
void kb_rough_plastic_eval(const kpcn_bsdf *b, const kpcn_shading_point *sp, kpcn_vec3 wo,
                           kpcn_vec3 wi, kpcn_bsdf_eval_result *r);
int kb_smooth_coat_sample(const kpcn_bsdf *b, const kpcn_shading_point *sp, kpcn_vec3 wo, float u1,
                          float u2, float ulobe, kpcn_bsdf_sample_result *s);
void kb_smooth_coat_eval(const kpcn_bsdf *b, const kpcn_shading_point *sp, kpcn_vec3 wo,
                         kpcn_vec3 wi, kpcn_bsdf_eval_result *r);

#endif
