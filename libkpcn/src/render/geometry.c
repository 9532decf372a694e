/* Per-primitive hit shading (position, normals, Tungsten's uv parametrisation) and
 * uniform-area sampling of emissive primitives. Hit points are re-projected onto the
 * analytic surface (planes, sphere) or rebuilt from barycentrics (triangles), so the
 * float-robust offset below gets an accurate point to push off from. */
#include "render/render_internal.h"

#include <math.h>
#include <string.h>

static inline float clamp01(float x) { return x < 0.0f ? 0.0f : (x > 1.0f ? 1.0f : x); }

static inline kpcn_vec3 mesh_vtx(const kpcn_mesh *m, unsigned i) {
  return kv3(m->pos[3 * i], m->pos[3 * i + 1], m->pos[3 * i + 2]);
}

/* uv of triangle id at barycentric weights (b0, b1, b2) of its vertices: the interpolated
 * texture coordinates, or (b1, b2) when the mesh has none. */
static inline void mesh_uv(const kpcn_mesh *m, const unsigned *id, float b0, float b1, float b2,
                           float *u, float *v) {
  if (m->uv) {
    const float *t0 = m->uv + 2 * id[0], *t1 = m->uv + 2 * id[1], *t2 = m->uv + 2 * id[2];
    *u = b0 * t0[0] + b1 * t1[0] + b2 * t2[0];
    *v = b0 * t0[1] + b1 * t1[1] + b2 * t2[1];
  } else { /* no texture coordinates: (0, 0) at every vertex, as Tungsten's loaders set them
              (a texture took the barycentric weights until session 60) */
    (void)b0, (void)b1, (void)b2;
    *u = 0.0f, *v = 0.0f;
  }
}

/* Tungsten's sphere parametrisation of the outward unit normal n (hits and light samples). */
static inline void sphere_uv(const kpcn_prim *p, kpcn_vec3 n, float *u, float *v) {
  kpcn_vec3 l = kpcn_frame_to_local(&p->frame, n);
  *u = atan2f(l.y, l.x) * KPCN_INV_2PI + 0.5f;
  *v = acosf(kpcn_maxf(kpcn_minf(l.z, 1.0f), -1.0f)) * KPCN_INV_PI;
}

/* The parametrisations of the analytic shapes, shared by hits (clamped to the surface: clamp 1)
 * and by points of a hit's tangent plane (kpcn_hit_uv_at: carried on past the edges, clamp 0).
 * Quad: x on its plane. */
static inline void quad_uv(const kpcn_prim *p, kpcn_vec3 x, int clamp, float *u, float *v) {
  kpcn_vec3 r = kv3_sub(x, p->base);
  *u = kv3_dot(r, p->e0) * p->inv_e0sq;
  *v = kv3_dot(r, p->e1) * p->inv_e1sq;
  if (clamp) *u = clamp01(*u), *v = clamp01(*v);
}

/* Cube face dim (either sign), l the point's coordinates along the cube's axes. */
static inline void cube_uv(const kpcn_prim *p, const float l[3], int dim, int clamp, float *u,
                           float *v) {
  const float hf[3] = {p->half.x, p->half.y, p->half.z};
  const int a = (dim + 1) % 3, b = (dim + 2) % 3;
  *u = l[a] / hf[a] * 0.5f + 0.5f;
  *v = l[b] / hf[b] * 0.5f + 0.5f;
  if (clamp) *u = clamp01(*u), *v = clamp01(*v);
}

/* Disk: r the in-plane offset from its centre. */
static inline void disk_uv(const kpcn_prim *p, kpcn_vec3 r, float *u, float *v) {
  float a = kv3_dot(r, p->axis[1]), b = kv3_dot(r, p->axis[0]);
  *v = kpcn_minf(kv3_length(r) / p->radius, 1.0f);
  *u = (a == 0.0f && b == 0.0f) ? 0.0f : atan2f(b, a) * KPCN_INV_2PI + 0.5f;
}

void kpcn_hit_fill(const kpcn_scene *s, const kpcn_prim *p, kpcn_vec3 o, kpcn_vec3 d, float t,
                   unsigned prim_id, float bu, float bv, kpcn_hit *h) {
  (void)s;
  h->prim = p;
  h->t = t;
  kpcn_vec3 x = kv3_madd(o, d, t);
  switch (p->type) {
  case KPCN_PRIM_QUAD: {
    kpcn_vec3 r = kv3_sub(x, p->base);
    x = kv3_sub(x, kv3_scale(p->n, kv3_dot(r, p->n)));
    h->ng = p->n;
    quad_uv(p, x, 1, &h->u, &h->v);
    break;
  }
  case KPCN_PRIM_CUBE: {
    kpcn_vec3 r = kv3_sub(x, p->center);
    float l[3] = {kv3_dot(r, p->axis[0]), kv3_dot(r, p->axis[1]), kv3_dot(r, p->axis[2])};
    float hf[3] = {p->half.x, p->half.y, p->half.z};
    int dim = 0;
    float best = fabsf(l[0]) - hf[0];
    for (int i = 1; i < 3; i++)
      if (fabsf(l[i]) - hf[i] > best) best = fabsf(l[i]) - hf[i], dim = i;
    float sgn = l[dim] < 0.0f ? -1.0f : 1.0f;
    h->ng = kv3_scale(p->axis[dim], sgn);
    x = kv3_madd(x, p->axis[dim], sgn * hf[dim] - l[dim]); /* onto the face plane */
    cube_uv(p, l, dim, 1, &h->u, &h->v);
    break;
  }
  case KPCN_PRIM_SPHERE: {
    kpcn_vec3 n = kv3_normalize(kv3_sub(x, p->center));
    x = kv3_madd(p->center, n, p->radius);
    h->ng = n;
    sphere_uv(p, n, &h->u, &h->v);
    break;
  }
  case KPCN_PRIM_DISK: {
    kpcn_vec3 r = kv3_sub(x, p->center);
    x = kv3_sub(x, kv3_scale(p->n, kv3_dot(r, p->n)));
    r = kv3_sub(x, p->center);
    h->ng = p->n;
    disk_uv(p, r, &h->u, &h->v);
    break;
  }
  case KPCN_PRIM_MESH: {
    const kpcn_mesh *m = &p->mesh;
    const unsigned *id = m->idx + 3 * prim_id;
    kpcn_vec3 v0 = mesh_vtx(m, id[0]), v1 = mesh_vtx(m, id[1]), v2 = mesh_vtx(m, id[2]);
    float b0 = 1.0f - bu - bv;
    x = kv3_add(kv3_add(kv3_scale(v0, b0), kv3_scale(v1, bu)), kv3_scale(v2, bv));
    kpcn_vec3 ng = kv3_normalize(kv3_cross(kv3_sub(v1, v0), kv3_sub(v2, v0)));
    if (m->nrm) {
      const float *n0 = m->nrm + 3 * id[0], *n1 = m->nrm + 3 * id[1], *n2 = m->nrm + 3 * id[2];
      kpcn_vec3 ns = kv3(b0 * n0[0] + bu * n1[0] + bv * n2[0], b0 * n0[1] + bu * n1[1] + bv * n2[1],
                         b0 * n0[2] + bu * n1[2] + bv * n2[2]);
      ns = kv3_normalize(ns);
      /* the winding defines the outside, as in Tungsten (emitters' front, glass's inside); a
       * vertex normal against it is turned to its side (it used to turn the face instead) */
      if (kv3_dot(ns, ng) < 0.0f) ns = kv3_neg(ns);
      h->ns = (m->smooth && kv3_length2(ns) > 0.5f) ? ns : ng;
    } else {
      h->ns = ng;
    }
    h->ng = ng;
    mesh_uv(m, id, b0, bu, bv, &h->u, &h->v);
    h->p = x;
    return;
  }
  case KPCN_PRIM_INFINITE_SPHERE: break;
  }
  h->ns = h->ng;
  h->p = x;
}

void kpcn_hit_uv_at(const kpcn_prim *p, unsigned prim_id, const kpcn_hit *h, kpcn_vec3 x, float *u,
                    float *v) {
  *u = h->u, *v = h->v;
  switch (p->type) {
  case KPCN_PRIM_QUAD: quad_uv(p, x, 0, u, v); break;
  case KPCN_PRIM_CUBE: {
    /* the hit's face, not the one nearest x: x may lie past the face's edge */
    kpcn_vec3 r = kv3_sub(x, p->center);
    float l[3], best = -1.0f;
    int dim = 0;
    for (int i = 0; i < 3; i++) {
      l[i] = kv3_dot(r, p->axis[i]);
      float c = fabsf(kv3_dot(h->ng, p->axis[i]));
      if (c > best) best = c, dim = i;
    }
    cube_uv(p, l, dim, 0, u, v);
    break;
  }
  case KPCN_PRIM_SPHERE: {
    kpcn_vec3 r = kv3_sub(x, p->center);
    if (kv3_length2(r) > 0.0f) sphere_uv(p, kv3_normalize(r), u, v);
    break;
  }
  case KPCN_PRIM_DISK: disk_uv(p, kv3_sub(x, p->center), u, v); break;
  case KPCN_PRIM_MESH: {
    /* barycentric weights of x in the triangle's plane, extrapolated past its edges */
    const kpcn_mesh *m = &p->mesh;
    const unsigned *id = m->idx + 3 * prim_id;
    kpcn_vec3 v0 = mesh_vtx(m, id[0]);
    kpcn_vec3 e1 = kv3_sub(mesh_vtx(m, id[1]), v0), e2 = kv3_sub(mesh_vtx(m, id[2]), v0);
    kpcn_vec3 w = kv3_sub(x, v0);
    float d00 = kv3_dot(e1, e1), d01 = kv3_dot(e1, e2), d11 = kv3_dot(e2, e2);
    float d20 = kv3_dot(w, e1), d21 = kv3_dot(w, e2);
    float den = d00 * d11 - d01 * d01;
    if (!(den > 0.0f)) break; /* degenerate triangle: the hit's own uv */
    float b1 = (d11 * d20 - d01 * d21) / den, b2 = (d00 * d21 - d01 * d20) / den;
    mesh_uv(m, id, 1.0f - b1 - b2, b1, b2, u, v);
    break;
  }
  case KPCN_PRIM_INFINITE_SPHERE: break;
  }
}

kpcn_vec3 kpcn_prim_emission(const kpcn_prim *p, const kpcn_hit *h, kpcn_vec3 d) {
  if (!p->emissive || kv3_dot(d, h->ng) >= 0.0f) return kv3s(0.0f);
  return p->emission_tex ? kpcn_texture_eval(p->emission_tex, h->u, h->v) : p->emission;
}

void kpcn_prim_sample_point(const kpcn_prim *p, float u1, float u2, kpcn_light_point *lp) {
  lp->pdf_area = 1.0f / p->area;
  switch (p->type) {
  case KPCN_PRIM_QUAD:
    lp->p = kv3_add(kv3_add(p->base, kv3_scale(p->e0, u1)), kv3_scale(p->e1, u2));
    lp->n = p->n;
    lp->u = u1, lp->v = u2;
    break;
  case KPCN_PRIM_CUBE: {
    /* pick one of the 6 faces by area, reuse u1 inside it */
    float t = u1 * p->face_cdf[2];
    int dim = t < p->face_cdf[0] ? 0 : (t < p->face_cdf[1] ? 1 : 2);
    float lo = dim == 0 ? 0.0f : p->face_cdf[dim - 1], hi = p->face_cdf[dim];
    float w = (t - lo) / (hi - lo);
    float sgn = w < 0.5f ? -1.0f : 1.0f;
    w = w < 0.5f ? 2.0f * w : 2.0f * w - 1.0f;
    float hf[3] = {p->half.x, p->half.y, p->half.z};
    int a = (dim + 1) % 3, b = (dim + 2) % 3;
    kpcn_vec3 q = p->center;
    q = kv3_madd(q, p->axis[dim], sgn * hf[dim]);
    q = kv3_madd(q, p->axis[a], (2.0f * w - 1.0f) * hf[a]);
    q = kv3_madd(q, p->axis[b], (2.0f * u2 - 1.0f) * hf[b]);
    lp->p = q;
    lp->n = kv3_scale(p->axis[dim], sgn);
    lp->u = w, lp->v = u2;
    break;
  }
  case KPCN_PRIM_SPHERE: {
    kpcn_vec3 n = kpcn_warp_uniform_sphere(u1, u2);
    lp->p = kv3_madd(p->center, n, p->radius);
    lp->n = n;
    sphere_uv(p, n, &lp->u, &lp->v);
    break;
  }
  case KPCN_PRIM_DISK: {
    float x, y;
    kpcn_warp_concentric_disk(u1, u2, &x, &y);
    lp->p = kv3_add(p->center, kv3_add(kv3_scale(p->frame.b, x * p->radius),
                                       kv3_scale(p->frame.t, y * p->radius)));
    lp->n = p->n;
    if (kv3_equal(p->frame.b, p->axis[1]) && kv3_equal(p->frame.t, p->axis[0])) {
      /* the uv frame is the sampling frame (normals along +-y, +-z): the warp's own (x, y) */
      lp->v = kpcn_minf(sqrtf(x * x + y * y), 1.0f);
      lp->u = (x == 0.0f && y == 0.0f) ? 0.0f : atan2f(y, x) * KPCN_INV_2PI + 0.5f;
    } else {
      disk_uv(p, kv3_sub(lp->p, p->center), &lp->u, &lp->v);
    }
    break;
  }
  case KPCN_PRIM_MESH: {
    const kpcn_mesh *m = &p->mesh;
    float pmf;
    int tri = kpcn_distrib1d_sample_discrete(&m->area_cdf, u1, &pmf);
    float lo = m->area_cdf.cdf[tri], hi = m->area_cdf.cdf[tri + 1];
    float w = hi > lo ? (u1 - lo) / (hi - lo) : 0.5f;
    w = kpcn_minf(kpcn_maxf(w, 0.0f), 0.99999994f);
    float b0, b1;
    kpcn_warp_uniform_triangle(w, u2, &b0, &b1);
    const unsigned *id = m->idx + 3 * tri;
    kpcn_vec3 v0 = mesh_vtx(m, id[0]), v1 = mesh_vtx(m, id[1]), v2 = mesh_vtx(m, id[2]);
    lp->p = kv3_add(kv3_add(kv3_scale(v0, b0), kv3_scale(v1, b1)), kv3_scale(v2, 1.0f - b0 - b1));
    lp->n = kv3_normalize(kv3_cross(kv3_sub(v1, v0), kv3_sub(v2, v0))); /* the winding's */
    float b2 = 1.0f - b0 - b1; /* Embree's (u, v) are the weights of vertices 1 and 2 */
    mesh_uv(m, id, b0, b1, b2, &lp->u, &lp->v);
    break;
  }
  case KPCN_PRIM_INFINITE_SPHERE: memset(lp, 0, sizeof(*lp)); break;
  }
}
