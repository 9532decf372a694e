/* Microfacet distributions (Beckmann, GGX, Phong) with Tungsten's roughness convention:
 * alpha = max(roughness, 1e-3) for Beckmann/GGX (roughness IS alpha), and
 * alpha = 2/roughness^2 - 2 for Phong. Shadowing: Smith G1 (Walter 2007 rational approximation
 * for Beckmann/Phong, exact for GGX), G = G1(wi) G1(wo). Half vectors are sampled from
 * D(m) cos(theta_m) (not visible normals), as Tungsten does. Local frame, z = normal. */
#ifndef KPCN_RENDER_MICROFACET_H
#define KPCN_RENDER_MICROFACET_H

#include "render/bsdf.h"
#include "render/vec3.h"

float kpcn_mf_roughness_to_alpha(kpcn_microfacet_dist d, float roughness);
float kpcn_mf_D(kpcn_microfacet_dist d, float alpha, kpcn_vec3 m);
float kpcn_mf_G1(kpcn_microfacet_dist d, float alpha, kpcn_vec3 v, kpcn_vec3 m);
static inline float kpcn_mf_G(kpcn_microfacet_dist d, float alpha, kpcn_vec3 i, kpcn_vec3 o,
                              kpcn_vec3 m) {
  return kpcn_mf_G1(d, alpha, i, m) * kpcn_mf_G1(d, alpha, o, m);
}
/* pdf of sample(): D(m) * cos(theta_m), w.r.t. solid angle of m. */
static inline float kpcn_mf_pdf(kpcn_microfacet_dist d, float alpha, kpcn_vec3 m) {
  return kpcn_mf_D(d, alpha, m) * m.z;
}
kpcn_vec3 kpcn_mf_sample(kpcn_microfacet_dist d, float alpha, float u1, float u2);
/* Parses "beckmann" | "ggx" | "phong" (Tungsten's names). Returns 0 when unknown. */
int kpcn_mf_from_name(const char *name, kpcn_microfacet_dist *out);

#endif
