/* Microfacet distributions, following Walter et al. 2007 with Tungsten's parameterisation. */
#include "render/microfacet.h"

#include "render/sampling.h"

#include <math.h>
#include <string.h>

float kpcn_mf_roughness_to_alpha(kpcn_microfacet_dist d, float roughness) {
  roughness = kpcn_maxf(roughness, 1e-3f);
  if (d == KPCN_MF_PHONG) return 2.0f / (roughness * roughness) - 2.0f;
  return roughness;
}

float kpcn_mf_D(kpcn_microfacet_dist d, float alpha, kpcn_vec3 m) {
  if (m.z <= 0.0f) return 0.0f;
  float c2 = m.z * m.z;
  switch (d) {
  case KPCN_MF_BECKMANN: {
    float a2 = alpha * alpha;
    float t2 = kpcn_maxf(1.0f - c2, 0.0f) / c2;
    return KPCN_INV_PI * expf(-t2 / a2) / (a2 * c2 * c2);
  }
  case KPCN_MF_PHONG: return (alpha + 2.0f) * KPCN_INV_2PI * (float)pow((double)m.z, (double)alpha);
  case KPCN_MF_GGX: {
    float a2 = alpha * alpha;
    float t2 = kpcn_maxf(1.0f - c2, 0.0f) / c2;
    float s = a2 + t2;
    return a2 * KPCN_INV_PI / (c2 * c2 * s * s);
  }
  }
  return 0.0f;
}

static float rational_g1(float a) {
  if (a >= 1.6f) return 1.0f;
  return (3.535f * a + 2.181f * a * a) / (1.0f + 2.276f * a + 2.577f * a * a);
}

float kpcn_mf_G1(kpcn_microfacet_dist d, float alpha, kpcn_vec3 v, kpcn_vec3 m) {
  if (kv3_dot(v, m) * v.z <= 0.0f) return 0.0f;
  float c2 = v.z * v.z;
  switch (d) {
  case KPCN_MF_BECKMANN: {
    float tan_t = fabsf(sqrtf(kpcn_maxf(1.0f - c2, 0.0f)) / v.z);
    return rational_g1(1.0f / (alpha * tan_t));
  }
  case KPCN_MF_PHONG: {
    float tan_t = fabsf(sqrtf(kpcn_maxf(1.0f - c2, 0.0f)) / v.z);
    return rational_g1(sqrtf(0.5f * alpha + 1.0f) / tan_t);
  }
  case KPCN_MF_GGX: {
    float t2 = kpcn_maxf(1.0f - c2, 0.0f) / c2;
    return 2.0f / (1.0f + sqrtf(1.0f + alpha * alpha * t2));
  }
  }
  return 0.0f;
}

kpcn_vec3 kpcn_mf_sample(kpcn_microfacet_dist d, float alpha, float u1, float u2) {
  float phi = u2 * 2.0f * KPCN_PI;
  float cos_t = 1.0f;
  switch (d) {
  case KPCN_MF_BECKMANN: {
    float t2 = -alpha * alpha * logf(1.0f - u1);
    cos_t = 1.0f / sqrtf(1.0f + t2);
    break;
  }
  case KPCN_MF_PHONG: cos_t = (float)pow((double)u1, 1.0 / ((double)alpha + 2.0)); break;
  case KPCN_MF_GGX: {
    float t2 = alpha * alpha * u1 / (1.0f - u1);
    cos_t = 1.0f / sqrtf(1.0f + t2);
    break;
  }
  }
  float r = sqrtf(kpcn_maxf(1.0f - cos_t * cos_t, 0.0f));
  return kv3(cosf(phi) * r, sinf(phi) * r, cos_t);
}

int kpcn_mf_from_name(const char *name, kpcn_microfacet_dist *out) {
  if (!name) return 0;
  if (strcmp(name, "beckmann") == 0)
    *out = KPCN_MF_BECKMANN;
  else if (strcmp(name, "ggx") == 0)
    *out = KPCN_MF_GGX;
  else if (strcmp(name, "phong") == 0)
    *out = KPCN_MF_PHONG;
  else
    return 0;
  return 1;
}
