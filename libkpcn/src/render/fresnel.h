/* Fresnel terms with Tungsten's conventions (Fresnel.hpp there).
 * eta in kpcn_fresnel_dielectric is the RELATIVE index n_incident / n_transmitted, e.g. 1/ior
 * for a ray arriving from air; a negative cos_i flips the side (eta -> 1/eta). */
#ifndef KPCN_RENDER_FRESNEL_H
#define KPCN_RENDER_FRESNEL_H

#include "render/vec3.h"

/* Unpolarised dielectric reflectance. *cos_t (may be NULL) receives |cos| of the refracted
 * direction (0 under total internal reflection, where the result is 1). */
float kpcn_fresnel_dielectric(float eta, float cos_i, float *cos_t);
/* Conductor reflectance for complex IOR eta + i k (Shirley's thesis formula, as Tungsten). */
float kpcn_fresnel_conductor(float eta, float k, float cos_i);
kpcn_vec3 kpcn_fresnel_conductor3(kpcn_vec3 eta, kpcn_vec3 k, float cos_i);
/* Cosine-weighted hemispherical average of internal reflectance F(ior, cos) (Tungsten's
 * computeDiffuseFresnel), used by plastic's diffuse multiple-scattering term. */
float kpcn_fresnel_diffuse_reflectance(float ior);

#endif
