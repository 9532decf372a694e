/* The light list: every emissive primitive plus the environment. Lights are chosen in
 * proportion to an estimate of their power (area x mean emission) among area lights; the
 * environment, whose power cannot be compared in the same units, gets half of the
 * selection probability when area lights exist too. Any positive choice is unbiased; this
 * one keeps small bright lights from being starved. */
#include "core/internal.h"
#include "scene/scene_internal.h"

#include <stdlib.h>
#include <string.h>

kpcn_status kpcn_scene_build_lights(kpcn_scene *s) {
  s->lights = kpcn_calloc((size_t)s->nprims + 1, sizeof(kpcn_light), "light list");
  if (!s->lights) return KPCN_ERR_OUT_OF_MEMORY;
  float *w = kpcn_calloc((size_t)s->nprims + 1, sizeof(float), "light weights");
  if (!w) return KPCN_ERR_OUT_OF_MEMORY;
  int n = 0, narea = 0;
  for (int i = 0; i < s->nprims; i++)
    s->prims[i].light_index = -1;
  double area_total = 0.0;
  for (int i = 0; i < s->nprims; i++) {
    kpcn_prim *p = &s->prims[i];
    if (!p->emissive || p->type == KPCN_PRIM_INFINITE_SPHERE) continue;
    if (!(p->area > 0.0f)) {
      free(w);
      return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                       "primitives[%d].emission: emitter '%s' has zero area", i, p->name);
    }
    if (p->type == KPCN_PRIM_MESH) {
      /* triangle selection by area for sampling points on an emissive mesh */
      kpcn_mesh *m = &p->mesh;
      float *ta = kpcn_alloc((size_t)m->ntris * sizeof(float), "triangle areas");
      if (!ta) {
        free(w);
        return KPCN_ERR_OUT_OF_MEMORY;
      }
      for (int t = 0; t < m->ntris; t++) {
        const unsigned *id = m->idx + 3 * t;
        kpcn_vec3 a = kv3(m->pos[3 * id[0]], m->pos[3 * id[0] + 1], m->pos[3 * id[0] + 2]);
        kpcn_vec3 b = kv3(m->pos[3 * id[1]], m->pos[3 * id[1] + 1], m->pos[3 * id[1] + 2]);
        kpcn_vec3 c = kv3(m->pos[3 * id[2]], m->pos[3 * id[2] + 1], m->pos[3 * id[2] + 2]);
        ta[t] = 0.5f * kv3_length(kv3_cross(kv3_sub(b, a), kv3_sub(c, a)));
      }
      kpcn_status st = kpcn_distrib1d_init(&m->area_cdf, ta, m->ntris);
      free(ta);
      if (st != KPCN_OK) {
        free(w);
        return st;
      }
    }
    s->lights[n].prim = i;
    p->light_index = n;
    w[n] = p->area * kv3_avg(p->emission);
    area_total += w[n];
    n++;
    narea++;
  }
  if (s->env_prim >= 0) {
    s->lights[n].prim = -1;
    s->env_light = n;
    w[n] = narea > 0 ? (float)area_total : 1.0f; /* half of the probability */
    n++;
  }
  s->nlights = n;
  if (n > 0) {
    kpcn_status st = kpcn_distrib1d_init(&s->light_cdf, w, n);
    if (st != KPCN_OK) {
      free(w);
      return st;
    }
    double tot = 0.0;
    for (int i = 0; i < n; i++)
      tot += w[i];
    for (int i = 0; i < n; i++)
      s->lights[i].select_pdf = tot > 0.0 ? (float)(w[i] / tot) : 1.0f / n;
  }
  free(w);
  return KPCN_OK;
}
