/* BSDF construction, dispatch, and the simple types (lambert, mirror, conductor, dielectric,
 * null). Conventions: see bsdf.h. Tungsten's "wi" is our wo and its "wo" our wi. */
#include "render/bsdf_internal.h"

#include "core/internal.h"
#include "render/fresnel.h"
#include "render/microfacet.h"
#include "render/sampling.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

static const kpcn_texture k_white = {.type = KPCN_TEX_CONSTANT,
                                     .value = {1.0f, 1.0f, 1.0f},
                                     .average = {1.0f, 1.0f, 1.0f},
                                     .scale = 1.0f};

static const char *const k_names[KPCN_BSDF_TYPE_COUNT] = {
    "lambert",          "mirror",  "conductor",     "rough_conductor", "dielectric",
    "rough_dielectric", "plastic", "rough_plastic", "smooth_coat",     "null"};

const char *kpcn_bsdf_type_name(kpcn_bsdf_type t) {
  return (t >= 0 && t < KPCN_BSDF_TYPE_COUNT) ? k_names[t] : "unknown";
}

void kpcn_bsdf_params_defaults(kpcn_bsdf_params *p, kpcn_bsdf_type type) {
  memset(p, 0, sizeof(*p));
  p->type = type;
  p->distribution = KPCN_MF_GGX;
  p->roughness_value = type == KPCN_BSDF_ROUGH_PLASTIC ? 0.02f : 0.1f;
  kpcn_conductor_lookup("Cu", &p->eta, &p->k);
  p->ior = type == KPCN_BSDF_SMOOTH_COAT ? 1.3f : 1.5f;
  p->enable_refraction = 1;
  p->thickness = 1.0f;
  p->sigma_a = kv3s(0.0f);
}

static int compute_lobes(const kpcn_bsdf_params *p) {
  switch (p->type) {
  case KPCN_BSDF_LAMBERT: return KPCN_LOBE_DIFFUSE;
  case KPCN_BSDF_MIRROR:
  case KPCN_BSDF_CONDUCTOR: return KPCN_LOBE_SPECULAR;
  case KPCN_BSDF_ROUGH_CONDUCTOR: return KPCN_LOBE_GLOSSY;
  case KPCN_BSDF_DIELECTRIC:
    return KPCN_LOBE_SPECULAR | (p->enable_refraction ? KPCN_LOBE_TRANSMISSION : 0);
  case KPCN_BSDF_ROUGH_DIELECTRIC:
    return KPCN_LOBE_GLOSSY | (p->enable_refraction ? KPCN_LOBE_TRANSMISSION : 0);
  case KPCN_BSDF_PLASTIC: return KPCN_LOBE_SPECULAR | KPCN_LOBE_DIFFUSE;
  case KPCN_BSDF_ROUGH_PLASTIC: return KPCN_LOBE_GLOSSY | KPCN_LOBE_DIFFUSE;
  case KPCN_BSDF_SMOOTH_COAT: return KPCN_LOBE_SPECULAR | p->substrate->lobes;
  case KPCN_BSDF_NULL: return KPCN_LOBE_FORWARD;
  default: return 0;
  }
}

kpcn_status kpcn_bsdf_create(const kpcn_bsdf_params *p, kpcn_bsdf **out) {
  if (!p || !out) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_bsdf_create: NULL argument");
  *out = NULL;
  const char *tn = kpcn_bsdf_type_name(p->type);
  if (p->type < 0 || p->type >= KPCN_BSDF_TYPE_COUNT)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "bsdf: unknown type %d", (int)p->type);
  if (!(p->roughness_value >= 0.0f) || !isfinite(p->roughness_value))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s: roughness %g must be finite and >= 0", tn,
                     p->roughness_value);
  if (!(p->ior > 0.0f) || !isfinite(p->ior))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s: ior %g must be finite and > 0", tn, p->ior);
  if (!isfinite(p->thickness) || p->thickness < 0.0f)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s: thickness %g must be finite and >= 0", tn,
                     p->thickness);
  if (!kv3_is_finite(p->sigma_a) || kv3_min_comp(p->sigma_a) < 0.0f)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s: sigma_a must be finite and >= 0", tn);
  if (!kv3_is_finite(p->eta) || !kv3_is_finite(p->k))
    return kpcn_fail(KPCN_ERR_NONFINITE, "%s: eta/k must be finite", tn);
  if (p->distribution != KPCN_MF_BECKMANN && p->distribution != KPCN_MF_GGX &&
      p->distribution != KPCN_MF_PHONG)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s: unknown distribution %d", tn,
                     (int)p->distribution);
  if (p->type == KPCN_BSDF_SMOOTH_COAT && !p->substrate)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "smooth_coat: substrate is required");
  if (p->type == KPCN_BSDF_SMOOTH_COAT && kpcn_bsdf_is_transmissive(p->substrate))
    return kpcn_fail(KPCN_ERR_UNSUPPORTED,
                     "smooth_coat: a transmissive substrate (%s) is not supported",
                     kpcn_bsdf_type_name(p->substrate->type));
  kpcn_bsdf *b = kpcn_calloc(1, sizeof(kpcn_bsdf), "bsdf");
  if (!b) return KPCN_ERR_OUT_OF_MEMORY;
  b->type = p->type;
  b->albedo = p->albedo ? p->albedo : &k_white;
  b->roughness = p->roughness;
  b->roughness_value = p->roughness_value;
  b->dist = p->distribution;
  b->eta = p->eta;
  b->k = p->k;
  b->ior = p->ior;
  b->enable_refraction = p->enable_refraction;
  b->thickness = p->thickness;
  b->sigma_a = p->sigma_a;
  b->substrate = p->substrate;
  b->scaled_sigma_a = kv3_scale(p->sigma_a, p->thickness);
  b->has_absorption = kv3_max_comp(b->scaled_sigma_a) > 0.0f;
  b->avg_transmittance = expf(-2.0f * kv3_avg(b->scaled_sigma_a));
  if (p->type == KPCN_BSDF_PLASTIC || p->type == KPCN_BSDF_ROUGH_PLASTIC)
    b->diffuse_fresnel = kpcn_fresnel_diffuse_reflectance(p->ior);
  b->lobes = compute_lobes(p);
  *out = b;
  return KPCN_OK;
}

void kpcn_bsdf_destroy(kpcn_bsdf *b) { free(b); }

kpcn_bsdf_type kpcn_bsdf_get_type(const kpcn_bsdf *b) { return b->type; }
int kpcn_bsdf_lobes(const kpcn_bsdf *b) { return b->lobes; }
int kpcn_bsdf_is_delta_only(const kpcn_bsdf *b) {
  return (b->lobes & (KPCN_LOBE_DIFFUSE | KPCN_LOBE_GLOSSY)) == 0;
}
int kpcn_bsdf_is_transmissive(const kpcn_bsdf *b) {
  return (b->lobes & (KPCN_LOBE_TRANSMISSION | KPCN_LOBE_FORWARD)) != 0;
}
int kpcn_bsdf_is_null(const kpcn_bsdf *b) { return b->type == KPCN_BSDF_NULL; }

kpcn_vec3 kpcn_bsdf_albedo(const kpcn_bsdf *b, const kpcn_shading_point *sp) {
  if (b->type == KPCN_BSDF_SMOOTH_COAT) return kpcn_bsdf_albedo(b->substrate, sp);
  return kb_albedo(b, sp);
}

int kpcn_bsdf_albedo_is_textured(const kpcn_bsdf *b) {
  if (b->type == KPCN_BSDF_SMOOTH_COAT) return kpcn_bsdf_albedo_is_textured(b->substrate);
  return !kpcn_texture_is_constant(b->albedo);
}

/* ---- smooth dielectric (Tungsten DielectricBsdf) ---- */
static int dielectric_sample(const kpcn_bsdf *b, const kpcn_shading_point *sp, kpcn_vec3 wo,
                             float ulobe, kpcn_bsdf_sample_result *s) {
  float eta = wo.z < 0.0f ? b->ior : 1.0f / b->ior;
  float cos_t = 0.0f;
  float F = kpcn_fresnel_dielectric(eta, fabsf(wo.z), &cos_t);
  kpcn_vec3 a = kb_albedo(b, sp);
  if (!b->enable_refraction) {
    kb_set_delta(s, kb_reflect_z(wo), kv3_scale(a, F), 1.0f, KPCN_LOBE_SPECULAR);
    return 1;
  }
  if (ulobe < F) {
    kb_set_delta(s, kb_reflect_z(wo), a, F, KPCN_LOBE_SPECULAR);
    return 1;
  }
  if (F >= 1.0f) return 0;
  kpcn_vec3 wi = kv3(-wo.x * eta, -wo.y * eta, -copysignf(cos_t, wo.z));
  kb_set_delta(s, wi, a, 1.0f - F, KPCN_LOBE_SPECULAR | KPCN_LOBE_TRANSMISSION);
  return 1;
}

int kpcn_bsdf_sample(const kpcn_bsdf *b, const kpcn_shading_point *sp, kpcn_vec3 wo, float u1,
                     float u2, float ulobe, kpcn_bsdf_sample_result *s) {
  switch (b->type) {
  case KPCN_BSDF_LAMBERT: {
    if (wo.z <= 0.0f) return 0;
    kpcn_vec3 wi = kpcn_warp_cosine_hemisphere(u1, u2);
    if (wi.z <= 0.0f) return 0;
    s->wi = wi;
    s->weight = s->weight_diffuse = kb_albedo(b, sp);
    s->pdf = wi.z * KPCN_INV_PI;
    s->lobe = KPCN_LOBE_DIFFUSE;
    s->is_delta = 0;
    return 1;
  }
  case KPCN_BSDF_MIRROR:
    if (wo.z <= 0.0f) return 0;
    kb_set_delta(s, kb_reflect_z(wo), kb_albedo(b, sp), 1.0f, KPCN_LOBE_SPECULAR);
    return 1;
  case KPCN_BSDF_CONDUCTOR:
    if (wo.z <= 0.0f) return 0;
    kb_set_delta(s, kb_reflect_z(wo),
                 kv3_mul(kb_albedo(b, sp), kpcn_fresnel_conductor3(b->eta, b->k, wo.z)), 1.0f,
                 KPCN_LOBE_SPECULAR);
    return 1;
  case KPCN_BSDF_ROUGH_CONDUCTOR: return kb_rough_conductor_sample(b, sp, wo, u1, u2, s);
  case KPCN_BSDF_DIELECTRIC: return dielectric_sample(b, sp, wo, ulobe, s);
  case KPCN_BSDF_ROUGH_DIELECTRIC: return kb_rough_dielectric_sample(b, sp, wo, u1, u2, ulobe, s);
  case KPCN_BSDF_PLASTIC: return kb_plastic_sample(b, sp, wo, u1, u2, ulobe, s);
  case KPCN_BSDF_ROUGH_PLASTIC: return kb_rough_plastic_sample(b, sp, wo, u1, u2, ulobe, s);
  case KPCN_BSDF_SMOOTH_COAT: return kb_smooth_coat_sample(b, sp, wo, u1, u2, ulobe, s);
  case KPCN_BSDF_NULL:
  default: return 0;
  }
}

void kpcn_bsdf_eval(const kpcn_bsdf *b, const kpcn_shading_point *sp, kpcn_vec3 wo, kpcn_vec3 wi,
                    kpcn_bsdf_eval_result *r) {
  switch (b->type) {
  case KPCN_BSDF_LAMBERT:
    if (wo.z <= 0.0f || wi.z <= 0.0f) {
      kb_eval_zero(r);
      return;
    }
    r->f_cos = r->f_cos_diffuse = kv3_scale(kb_albedo(b, sp), wi.z * KPCN_INV_PI);
    r->pdf = wi.z * KPCN_INV_PI;
    return;
  case KPCN_BSDF_ROUGH_CONDUCTOR: kb_rough_conductor_eval(b, sp, wo, wi, r); return;
  case KPCN_BSDF_ROUGH_DIELECTRIC: kb_rough_dielectric_eval(b, sp, wo, wi, r); return;
  case KPCN_BSDF_PLASTIC: kb_plastic_eval(b, sp, wo, wi, r); return;
  case KPCN_BSDF_ROUGH_PLASTIC: kb_rough_plastic_eval(b, sp, wo, wi, r); return;
  case KPCN_BSDF_SMOOTH_COAT: kb_smooth_coat_eval(b, sp, wo, wi, r); return;
  default: kb_eval_zero(r); return; /* delta-only and null: nothing to evaluate */
  }
}

float kpcn_bsdf_pdf(const kpcn_bsdf *b, const kpcn_shading_point *sp, kpcn_vec3 wo, kpcn_vec3 wi) {
  kpcn_bsdf_eval_result r;
  kpcn_bsdf_eval(b, sp, wo, wi, &r);
  return r.pdf;
}
