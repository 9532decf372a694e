/* Unidirectional path tracing with next-event estimation and multiple importance sampling
 * (power heuristic), Russian roulette, and the AOV bookkeeping of DESIGN.md §4.
 *
 * Diffuse/specular split: every path carries two throughputs. Before its first non-delta
 * interaction all of it is "specular" (emitters seen directly or through mirror/glass
 * chains). At that interaction the BSDF reports which part of its weight (sampling) and of
 * its f*cos (next-event estimation) went through diffuse lobes; that part continues as the
 * diffuse throughput, the rest as the specular one. Both estimates are unbiased and their
 * sum is exactly the colour estimate of the sample. */
#include "render/render_internal.h"

#include <embree3/rtcore.h>
#include <math.h>
#include <string.h>

#define RR_THRESHOLD 0.25f

/* ---- reconstruction filters (importance sampled, Tungsten's shapes and widths) ---- */

/* integrator_gfni.c compiles this file a second time under another name for the pixel
 * tracer; the filter table is built once, by the first compilation. */
#ifndef KPCN_TRACE_PIXEL
#define KPCN_TRACE_PIXEL kpcn_trace_pixel

static double gauss_f(double x) { return fmax(exp(-2.0 * x * x) - exp(-8.0), 0.0); }

void kpcn_filter_table_init(kpcn_filter_table *t, kpcn_filter_type type) {
  memset(t, 0, sizeof(*t));
  t->type = type;
  if (type != KPCN_FILTER_GAUSSIAN) return;
  /* invert the CDF of the Gaussian on [-2, 2] numerically: two passes over a fine trapezoid
   * grid (total, then fill the equally spaced targets as the running integral passes them);
   * no shared tables, so concurrent renders are safe */
  enum { N = 65536 };
  double total = 0.0;
  for (int i = 1; i <= N; i++) {
    double x0 = -2.0 + 4.0 * (i - 1) / N, x1 = -2.0 + 4.0 * i / N;
    total += 0.5 * (gauss_f(x0) + gauss_f(x1)) * (x1 - x0);
  }
  double acc = 0.0;
  int k = 1;
  for (int i = 1; i <= N && k < KPCN_FILTER_TABLE; i++) {
    double x0 = -2.0 + 4.0 * (i - 1) / N, x1 = -2.0 + 4.0 * i / N;
    double seg = 0.5 * (gauss_f(x0) + gauss_f(x1)) * (x1 - x0);
    while (k < KPCN_FILTER_TABLE && acc + seg >= total * k / KPCN_FILTER_TABLE) {
      double f = seg > 0.0 ? (total * k / KPCN_FILTER_TABLE - acc) / seg : 0.0;
      t->inv_cdf[k++] = (float)(x0 + f * (x1 - x0));
    }
    acc += seg;
  }
  while (k < KPCN_FILTER_TABLE)
    t->inv_cdf[k++] = 2.0f;
  t->inv_cdf[0] = -2.0f;
  t->inv_cdf[KPCN_FILTER_TABLE] = 2.0f;
}

#endif

static float filter_sample(const kpcn_filter_table *t, float u) {
  switch (t->type) {
  case KPCN_FILTER_BOX: return u - 0.5f;
  case KPCN_FILTER_TENT: return u < 0.5f ? -1.0f + sqrtf(2.0f * u) : 1.0f - sqrtf(2.0f - 2.0f * u);
  case KPCN_FILTER_GAUSSIAN: {
    float x = u * KPCN_FILTER_TABLE;
    int i = (int)x;
    if (i >= KPCN_FILTER_TABLE) i = KPCN_FILTER_TABLE - 1;
    float f = x - i;
    return t->inv_cdf[i] + f * (t->inv_cdf[i + 1] - t->inv_cdf[i]);
  }
  }
  return 0.0f;
}

static inline float power_heuristic(float a, float b) {
  if (!(a > 0.0f)) return 0.0f;
  if (isinf(a)) return 1.0f;
  float a2 = a * a, b2 = b * b;
  return a2 / (a2 + b2);
}

/* Solid-angle pdf with which NEE would have chosen the point h on primitive p, seen from
 * prev_p along direction d. */
static float light_pdf_area(const kpcn_scene *s, const kpcn_prim *p, const kpcn_hit *h,
                            kpcn_vec3 prev_p, kpcn_vec3 d) {
  int li = p->light_index;
  if (li < 0) return 0.0f;
  float cosl = fabsf(kv3_dot(d, h->ng));
  if (cosl <= 0.0f) return 0.0f;
  float d2 = kv3_length2(kv3_sub(h->p, prev_p));
  return s->lights[li].select_pdf * d2 / (cosl * p->area);
}

/* Next-event estimation from the shading point, up to the shadow ray: picks a light and a
 * point on it, evaluates the BSDF, and returns 1 with the shadow ray (origin, dir, tfar) and
 * the contribution it adds if unoccluded (total and diffuse part, not yet multiplied by the
 * path throughput); 0 when no shadow ray is needed (light faces away, zero BSDF, ...). */
typedef struct nee_ray {
  kpcn_vec3 origin, dir;
  float tfar;
  kpcn_vec3 c_tot, c_diff;
} nee_ray;

static int nee_prepare(const kpcn_render_ctx *ctx, const kpcn_hit *h, const kpcn_frame *fr,
                       const kpcn_bsdf *bsdf, const kpcn_shading_point *sp, kpcn_vec3 wo_l,
                       kpcn_vec3 ng, float ul, float u1, float u2, nee_ray *r) {
  const kpcn_scene *s = ctx->scene;
  float pmf;
  int li = s->nlights == 1 ? 0 : kpcn_distrib1d_sample_discrete(&s->light_cdf, ul, &pmf);
  pmf = s->lights[li].select_pdf;
  kpcn_vec3 wi, Li;
  float pdf, dist;
  kpcn_vec3 origin, target;
  if (s->lights[li].prim < 0) {
    float epdf;
    if (!kpcn_envmap_sample(s->env, u1, u2, &wi, &Li, &epdf) || !(epdf > 0.0f)) return 0;
    pdf = epdf * pmf;
    origin = kpcn_offset_ray(h->p, kv3_dot(wi, ng) > 0.0f ? ng : kv3_neg(ng));
    dist = INFINITY;
  } else {
    const kpcn_prim *lp_prim = &s->prims[s->lights[li].prim];
    kpcn_light_point lp;
    kpcn_prim_sample_point(lp_prim, u1, u2, &lp);
    kpcn_vec3 dv = kv3_sub(lp.p, h->p);
    float d2 = kv3_length2(dv);
    if (!(d2 > 0.0f)) return 0;
    float dl = sqrtf(d2);
    wi = kv3_scale(dv, 1.0f / dl);
    float cosl = -kv3_dot(wi, lp.n);
    if (cosl <= 0.0f) return 0; /* one-sided emitters */
    Li = lp_prim->emission_tex ? kpcn_texture_eval(lp_prim->emission_tex, lp.u, lp.v)
                               : lp_prim->emission;
    if (kv3_is_zero(Li)) return 0;
    pdf = pmf * lp.pdf_area * d2 / cosl;
    origin = kpcn_offset_ray(h->p, kv3_dot(wi, ng) > 0.0f ? ng : kv3_neg(ng));
    target = kpcn_offset_ray(lp.p, lp.n);
    kpcn_vec3 sd = kv3_sub(target, origin);
    dist = kv3_length(sd);
    if (!(dist > 0.0f)) return 0;
    wi = kv3_scale(sd, 1.0f / dist);
    dist *= 0.99999f;
  }
  kpcn_vec3 wi_l = kpcn_frame_to_local(fr, wi);
  kpcn_bsdf_eval_result ev;
  kpcn_bsdf_eval(bsdf, sp, wo_l, wi_l, &ev);
  if (kv3_is_zero(ev.f_cos)) return 0;
  float w = ctx->mis ? power_heuristic(pdf, ev.pdf) : 1.0f;
  kpcn_vec3 k = kv3_scale(Li, w / pdf);
  r->origin = origin;
  r->dir = wi;
  r->tfar = dist;
  r->c_tot = kv3_mul(ev.f_cos, k);
  r->c_diff = kv3_mul(ev.f_cos_diffuse, k);
  return 1;
}

/* Where a sample's camera ray starts on the film and the lens: the pixel, the filter's two
 * uniform numbers and the lens point (camera space; 0 for a pinhole). The albedo footprint
 * re-uses it for the pixel's other film points. */
typedef struct camera_sample {
  int px, py;
  float fu, fv;
  kpcn_vec3 lens;
} camera_sample;

/* The camera ray of film point (fu, fv) of cs's pixel, through cs's lens point. */
static inline __attribute__((always_inline)) void camera_ray_at(const kpcn_render_ctx *ctx,
                                                                const camera_sample *cs, float fu,
                                                                float fv, kpcn_vec3 *o,
                                                                kpcn_vec3 *d) {
  const kpcn_camera *c = &ctx->scene->cam;
  float ox = filter_sample(&ctx->filter, fu), oy = filter_sample(&ctx->filter, fv);
  float pix = 2.0f / (float)ctx->width;
  kpcn_vec3 l = kv3(-1.0f + ((float)cs->px + 0.5f + ox) * pix,
                    ctx->ratio - ((float)cs->py + 0.5f + oy) * pix, c->plane_dist);
  kpcn_vec3 lens = cs->lens;
  if (c->thinlens && c->aperture > 0.0f) {
    l = kv3_scale(l, c->focus_dist / c->plane_dist);
    l = kv3_sub(l, lens);
  }
  l = kv3_normalize(l);
  *d = kv3_normalize(
      kv3_add(kv3_add(kv3_scale(c->right, l.x), kv3_scale(c->up, l.y)), kv3_scale(c->fwd, l.z)));
  *o = kv3_add(c->pos, kv3_add(kv3_scale(c->right, lens.x), kv3_scale(c->up, lens.y)));
}

static void camera_ray(const kpcn_render_ctx *ctx, int px, int py, kpcn_sampler *smp,
                       camera_sample *cs, kpcn_vec3 *o, kpcn_vec3 *d) {
  const kpcn_camera *c = &ctx->scene->cam;
  cs->px = px, cs->py = py;
  kpcn_sampler_2d(smp, &cs->fu, &cs->fv);
  cs->lens = kv3s(0.0f);
  if (c->thinlens && c->aperture > 0.0f) {
    float lu, lv, ax, ay;
    kpcn_sampler_2d(smp, &lu, &lv); /* pair 1 (pinholes leave it unused) */
    kpcn_warp_concentric_disk(lu, lv, &ax, &ay);
    cs->lens = kv3(ax * c->aperture, ay * c->aperture, 0.0f);
  }
  camera_ray_at(ctx, cs, cs->fu, cs->fv, o, d);
}

/* The state of one path between bounces (shade_hit advances it by one bounce). */
typedef struct path_state {
  kpcn_sampler *smp;
  kpcn_sample_out *out;
  kpcn_vec3 o, d;           /* the next extension ray */
  kpcn_vec3 tp_s, tp_d;     /* specular / diffuse throughputs */
  kpcn_vec3 Ls, Ld;         /* radiance gathered so far */
  kpcn_vec3 prev_p;         /* previous vertex (MIS weight of a hit emitter) */
  float prev_pdf, path_len; /* d is unit length: t is the distance */
  int bounce, have_feature, prev_delta, alive;
  /* this bounce's shadow ray: adds (add_d, add_s) and sets the visibility AOV if unoccluded */
  int shadow, shadow_sets_vis;
  nee_ray nee;
  kpcn_vec3 add_d, add_s;
} path_state;

/* Radiance of the escaped ray of path L (environment), with its MIS weight. */
static void shade_miss(const kpcn_render_ctx *ctx, path_state *L) {
  const kpcn_scene *s = ctx->scene;
  /* integrator.min_bounces, as Tungsten: light reaching the camera over fewer surfaces than
   * that is not counted (L->bounce surfaces were hit before this miss) */
  if (s->env && L->bounce >= ctx->min_bounces) {
    kpcn_vec3 Le = kpcn_envmap_eval(s->env, L->d);
    float w = 1.0f;
    if (!L->prev_delta) {
      if (!ctx->bsdf_emission)
        w = 0.0f;
      else if (ctx->mis)
        w = power_heuristic(L->prev_pdf,
                            s->lights[s->env_light].select_pdf * kpcn_envmap_pdf(s->env, L->d));
    }
    L->Ls = kv3_add(L->Ls, kv3_scale(kv3_mul(L->tp_s, Le), w));
    L->Ld = kv3_add(L->Ld, kv3_scale(kv3_mul(L->tp_d, Le), w));
  }
  L->alive = 0;
}

/* One bounce of path L at its hit: emission, feature AOVs, the shadow ray to trace (not yet
 * traced), BSDF sampling and Russian roulette. Leaves L->o/L->d for the next bounce, or clears
 * L->alive. */
static void shade_hit(const kpcn_render_ctx *ctx, path_state *L, unsigned geom_id, unsigned prim_id,
                      float t, float bu, float bv) {
  const kpcn_scene *s = ctx->scene;
  const kpcn_camera *cam = &s->cam;
  kpcn_sample_out *out = L->out;
  kpcn_sampler *smp = L->smp;
  kpcn_vec3 d = L->d;
  const kpcn_prim *p = &s->prims[s->geom_to_prim[geom_id]];
  kpcn_hit h;
  kpcn_hit_fill(s, p, L->o, d, t, prim_id, bu, bv, &h);
  L->path_len += h.t;
  L->alive = 0;
  if (p->emissive && L->bounce >= ctx->min_bounces) { /* L->bounce surfaces before this one */
    kpcn_vec3 Le = kpcn_prim_emission(p, &h, d);
    if (!kv3_is_zero(Le)) {
      float w = 1.0f;
      if (!L->prev_delta) {
        if (!ctx->bsdf_emission)
          w = 0.0f;
        else if (ctx->mis)
          w = power_heuristic(L->prev_pdf, light_pdf_area(s, p, &h, L->prev_p, d));
      }
      L->Ls = kv3_add(L->Ls, kv3_scale(kv3_mul(L->tp_s, Le), w));
      L->Ld = kv3_add(L->Ld, kv3_scale(kv3_mul(L->tp_d, Le), w));
    }
  }
  const kpcn_bsdf *bsdf = p->bsdf;
  if (kpcn_bsdf_is_null(bsdf)) {
    /* Tungsten's "null" BSDF absorbs (its pass-through BSDF is "forward"): the path ends
     * here, after the emission above. A directly seen one is the feature surface. */
    if (!L->have_feature) {
      kpcn_shading_point sp0 = {h.u, h.v};
      kpcn_vec3 nf = kv3_dot(h.ns, d) > 0.0f ? kv3_neg(h.ns) : h.ns;
      out->albedo = kpcn_bsdf_albedo(bsdf, &sp0);
      out->normal = kv3(kv3_dot(nf, cam->right), kv3_dot(nf, cam->up), -kv3_dot(nf, cam->fwd));
      out->depth = L->path_len;
    }
    return;
  }
  kpcn_vec3 wo = kv3_neg(d), ng = h.ng, ns = h.ns;
  /* two-sided shading, decided by the shading normal as Tungsten's makeLocalScatterEvent
   * does: where a smooth mesh's interpolated normal faces away while the face does not (near
   * silhouettes), judging by ng left wo below the shading frame, and the surface black.
   * ng's sign matters nowhere after this (ray offsets orient it by the new direction). */
  if (!kpcn_bsdf_is_transmissive(bsdf) && kv3_dot(wo, ns) < 0.0f) {
    ng = kv3_neg(ng);
    ns = kv3_neg(ns);
  }
  kpcn_frame fr = kpcn_frame_from_normal(ns);
  kpcn_vec3 wo_l = kpcn_frame_to_local(&fr, wo);
  kpcn_shading_point sp = {h.u, h.v};
  int delta_only = kpcn_bsdf_is_delta_only(bsdf);
  int at_feature = !L->have_feature && !delta_only;
  if (at_feature) {
    L->have_feature = 1;
    out->albedo = kpcn_bsdf_albedo(bsdf, &sp);
    kpcn_vec3 nf = kv3_dot(ns, wo) < 0.0f ? kv3_neg(ns) : ns;
    out->normal = kv3(kv3_dot(nf, cam->right), kv3_dot(nf, cam->up), -kv3_dot(nf, cam->fwd));
    out->depth = L->path_len;
    /* the albedo pass stops here: everything before this point is the colour pass's own
     * arithmetic, so its features are the same bits */
    if (ctx->features_only) return;
  }
  /* after the features: a path cut by the bounce limit still has its feature surface (with
   * --max-bounces 0 every surface used to get albedo, normal and depth 0) */
  if (L->bounce >= ctx->max_bounces) return;
  /* three dimension pairs per bounce: (light choice, lobe choice), light point, direction */
  kpcn_sampler_set_pair(smp, 2 + 3 * (uint32_t)L->bounce);
  float ul, ulobe, u1, u2, ub1, ub2;
  kpcn_sampler_2d(smp, &ul, &ulobe);
  kpcn_sampler_2d(smp, &u1, &u2);
  kpcn_sampler_2d(smp, &ub1, &ub2);
  if (!delta_only && ctx->nee && s->nlights > 0) {
    if (nee_prepare(ctx, &h, &fr, bsdf, &sp, wo_l, ng, ul, u1, u2, &L->nee)) {
      L->shadow = 1;
      L->shadow_sets_vis = at_feature;
      if (at_feature) {
        L->add_d = kv3_mul(L->tp_s, L->nee.c_diff);
        L->add_s = kv3_mul(L->tp_s, kv3_sub(L->nee.c_tot, L->nee.c_diff));
      } else {
        L->add_d = kv3_mul(L->tp_d, L->nee.c_tot);
        L->add_s = kv3_mul(L->tp_s, L->nee.c_tot);
      }
      /* the light reached through this shadow ray has crossed L->bounce + 1 surfaces: below
       * min_bounces it is not counted, but the ray is still traced (the visibility AOV, and
       * the same sample sequence as without min_bounces) */
      if (L->bounce + 1 < ctx->min_bounces) L->add_d = L->add_s = kv3s(0.0f);
    }
  } else if (at_feature && !ctx->color_only && s->nlights > 0) {
    /* light sampling is off (BSDF-only): still trace one shadow ray for the visibility AOV,
     * without adding its contribution */
    if (nee_prepare(ctx, &h, &fr, bsdf, &sp, wo_l, ng, ul, u1, u2, &L->nee)) {
      L->shadow = 1;
      L->shadow_sets_vis = 1;
      L->add_d = L->add_s = kv3s(0.0f);
    }
  }
  kpcn_bsdf_sample_result bs;
  if (!kpcn_bsdf_sample(bsdf, &sp, wo_l, ub1, ub2, ulobe, &bs)) return;
  kpcn_vec3 tp_s = L->tp_s, tp_d = L->tp_d;
  if (at_feature) {
    tp_d = kv3_mul(tp_s, bs.weight_diffuse);
    tp_s = kv3_mul(tp_s, kv3_sub(bs.weight, bs.weight_diffuse));
  } else {
    tp_d = kv3_mul(tp_d, bs.weight);
    tp_s = kv3_mul(tp_s, bs.weight);
  }
  kpcn_vec3 wi = kpcn_frame_to_world(&fr, bs.wi);
  L->prev_delta = bs.is_delta;
  L->prev_pdf = bs.pdf;
  L->prev_p = h.p;
  int bounce = ++L->bounce;
  /* Russian roulette after 2 bounces, only once the throughput has fallen below 0.25 (Tungsten
   * uses 0.1; 0.25 traces ~18% fewer rays on the cornell box at an error per sample still
   * below Tungsten's, see bench_render), so short paths keep their low variance */
  if (bounce > 2 && bounce >= ctx->min_bounces) {
    float q = kv3_max_comp(kv3_add(tp_s, tp_d));
    if (q < RR_THRESHOLD) {
      if (!(q > 0.0f) || kpcn_sampler_random(smp, (uint32_t)bounce) >= q) return;
      float inv = 1.0f / q;
      tp_s = kv3_scale(tp_s, inv);
      tp_d = kv3_scale(tp_d, inv);
    }
  }
  L->tp_s = tp_s, L->tp_d = tp_d;
  if (kv3_is_zero(tp_s) && kv3_is_zero(tp_d)) return;
  L->o = kpcn_offset_ray(h.p, kv3_dot(wi, ng) > 0.0f ? ng : kv3_neg(ng));
  L->d = kv3_normalize(wi);
  L->alive = 1;
}

static inline void ray_set(struct RTCRay *r, kpcn_vec3 o, kpcn_vec3 d, float tfar) {
  r->org_x = o.x, r->org_y = o.y, r->org_z = o.z;
  r->dir_x = d.x, r->dir_y = d.y, r->dir_z = d.z;
  r->tnear = 0.0f;
  r->tfar = tfar;
  r->mask = 0xffffffffU;
  r->flags = 0;
  r->time = 0.0f;
  r->id = 0;
}

/* Traces one path to its end, its state in a local the compiler keeps in registers (the same
 * loop over an array of paths in memory measured ~13 % slower). The camera ray (o, d) was
 * already answered by the caller's packet (first); the colour split lands in *out. */
static void trace_path(const kpcn_render_ctx *ctx, kpcn_sampler *smp, kpcn_sample_out *out,
                       kpcn_vec3 o, kpcn_vec3 d, const struct RTCRayHit *first) {
  RTCScene scene = (RTCScene)ctx->scene->rtc_scene;
  path_state P;
  memset(&P, 0, sizeof(P));
  P.smp = smp;
  P.out = out;
  P.o = P.prev_p = o;
  P.d = d;
  P.tp_s = kv3s(1.0f);
  P.prev_delta = 1;
  P.alive = 1;
  struct RTCIntersectContext ic;
  rtcInitIntersectContext(&ic);
  struct RTCRayHit rh = *first;
  for (int bounce0 = 1; P.alive; bounce0 = 0) {
    if (!bounce0) {
      ray_set(&rh.ray, P.o, P.d, INFINITY);
      rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
      rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
      rtcIntersect1(scene, &ic, &rh);
    }
    P.out->rays++;
    P.shadow = 0;
    if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID)
      shade_miss(ctx, &P);
    else
      shade_hit(ctx, &P, rh.hit.geomID, rh.hit.primID, rh.ray.tfar, rh.hit.u, rh.hit.v);
    if (!P.shadow) continue;
    struct RTCRay r;
    ray_set(&r, P.nee.origin, P.nee.dir, P.nee.tfar);
    rtcOccluded1(scene, &ic, &r);
    P.out->rays++;
    P.out->vis_traced |= (uint32_t)P.shadow_sets_vis;
    if (r.tfar < 0.0f) continue; /* Embree sets tfar = -inf on a hit */
    P.Ld = kv3_add(P.Ld, P.add_d);
    P.Ls = kv3_add(P.Ls, P.add_s);
    if (P.shadow_sets_vis) P.out->visibility = 1.0f;
  }
  out->diffuse = P.Ld;
  out->specular = P.Ls;
}

/* A camera sample's feature surface as the albedo footprint sees it. */
typedef struct footprint_hit {
  const kpcn_prim *prim; /* NULL: no textured surface seen directly (miss, mirror, constant) */
  kpcn_vec3 ng;          /* geometric normal */
  float ox, oy;          /* the sample's film offset from the pixel centre, in pixels */
  float u, v;            /* texture coordinates at the sample */
  int clamp;             /* the primitive's uv end at its edges (quads, cubes: kpcn_hit_fill) */
  /* spheres and disks: uv are far from linear near a pole or the centre, so each point is
   * looked up through its own ray (h, prim_id); planes use the derivatives above */
  int exact;
  unsigned prim_id;
  kpcn_hit h;
  float dudx, dvdx, dudy, dvdy; /* their change per pixel along the film's x and y */
} footprint_hit;

/* The texture coordinates at film point (fu, fv) of pixel (cs's + (dx, dy)), where its camera
 * ray meets the hit's tangent plane; 0 when it misses the plane. */
static int footprint_uv_at(const kpcn_render_ctx *ctx, const camera_sample *cs, float fu, float fv,
                           const kpcn_prim *p, unsigned prim_id, const kpcn_hit *h, int dx, int dy,
                           float *u, float *v) {
  camera_sample c = *cs;
  c.px += dx, c.py += dy; /* film points past the image edge are fine: only the ray is used */
  kpcn_vec3 o, d;
  camera_ray_at(ctx, &c, fu, fv, &o, &d);
  float t = kv3_dot(h->ng, kv3_sub(h->p, o)) / kv3_dot(h->ng, d);
  if (!(t > 0.0f && t < INFINITY)) return 0; /* parallel to the plane, or behind */
  kpcn_hit_uv_at(p, prim_id, h, kv3_madd(o, d, t), u, v);
  return 1;
}

static inline float clamp01f(float x) { return x < 0.0f ? 0.0f : (x > 1.0f ? 1.0f : x); }

static void footprint_hit_fill(const kpcn_render_ctx *ctx, const camera_sample *cs,
                               const struct RTCRayHit16 *rh, int k, footprint_hit *f) {
  const kpcn_scene *s = ctx->scene;
  f->prim = NULL;
  f->ox = filter_sample(&ctx->filter, cs->fu), f->oy = filter_sample(&ctx->filter, cs->fv);
  if (rh->hit.geomID[k] == RTC_INVALID_GEOMETRY_ID) return;
  const kpcn_prim *p = &s->prims[s->geom_to_prim[rh->hit.geomID[k]]];
  if (kpcn_bsdf_is_null(p->bsdf) || kpcn_bsdf_is_delta_only(p->bsdf) ||
      !kpcn_bsdf_albedo_is_textured(p->bsdf))
    return;
  const unsigned prim_id = rh->hit.primID[k];
  kpcn_hit h;
  kpcn_hit_fill(s, p, kv3(rh->ray.org_x[k], rh->ray.org_y[k], rh->ray.org_z[k]),
                kv3(rh->ray.dir_x[k], rh->ray.dir_y[k], rh->ray.dir_z[k]), rh->ray.tfar[k], prim_id,
                rh->hit.u[k], rh->hit.v[k], &h);
  f->prim = p;
  f->ng = h.ng;
  f->u = h.u, f->v = h.v;
  f->clamp = p->type == KPCN_PRIM_QUAD || p->type == KPCN_PRIM_CUBE;
  f->exact = p->type == KPCN_PRIM_SPHERE || p->type == KPCN_PRIM_DISK;
  f->prim_id = prim_id;
  f->h = h;
}

/* The texture coordinates' change per pixel at a plane's sample (from two rays one pixel over);
 * 0 when either misses the plane (grazing). */
static int footprint_derivatives(const kpcn_render_ctx *ctx, const camera_sample *cs,
                                 footprint_hit *f) {
  float ux, vx, uy, vy;
  if (!footprint_uv_at(ctx, cs, cs->fu, cs->fv, f->prim, f->prim_id, &f->h, 1, 0, &ux, &vx) ||
      !footprint_uv_at(ctx, cs, cs->fu, cs->fv, f->prim, f->prim_id, &f->h, 0, 1, &uy, &vy))
    return 0;
  f->dudx = ux - f->u, f->dvdx = vx - f->v;
  f->dudy = uy - f->u, f->dvdy = vy - f->v;
  return 1;
}

/* One surface: the same primitive, facing the same way (a cube's faces, a mesh's creases). */
static inline int same_surface(const footprint_hit *a, const footprint_hit *b) {
  return a->prim && a->prim == b->prim && kv3_dot(a->ng, b->ng) > 0.9f;
}

/* The generator g of a rank-1 lattice of n points {(i/n, i g/n mod 1)}: the integer nearest to
 * n/phi that is coprime to n (Korobov's choice; near the Fibonacci lattices where n is a
 * Fibonacci number). Its projections on either axis are n equally spaced values, which is what
 * box-filtering edges that run along the image's axes needs most. */
static uint32_t lattice_generator(uint32_t n) {
  uint32_t g = (uint32_t)((double)n * 0.6180339887498949 + 0.5);
  if (g < 1) g = 1;
  for (;;) {
    uint32_t a = n, b = g;
    while (b) {
      uint32_t t = a % b;
      a = b, b = t;
    }
    if (a == 1) return g;
    g++;
  }
}

/* The albedo over the pixel's footprint, for the n camera samples of one pixel traced
 * together. Sample s that sees a textured surface directly gets the mean of its own albedo
 * (already in out[s]) and of the albedo at k*k film points of the pixel's lattice (below), each
 * looked up where that point's camera ray meets s's tangent plane. No ray is traced: a lookup
 * costs a fraction of a ray. The pixel's n*k*k points form a rank-1 lattice, so together they
 * cover the pixel as evenly as n*k*k camera rays would (shifting each sample by a k x k grid
 * instead left 4x the error on test_render_footprint's checker). Where the pixel's samples see
 * more than one surface, a point counts only when the sample nearest to it on the film saw
 * s's surface too: each sample then averages its own surface's part of the pixel, and the
 * samples' coverage still weighs the surfaces (extending every surface over the whole pixel
 * doubled the point-sampled albedo's error at silhouettes). docs/renderer.md, "Albedo
 * footprint". Runs after the packet's paths, never inlined into them: the colour's arithmetic
 * must compile as it did without it (the same bits with the option off). */
__attribute__((noinline)) static void footprint_albedo(const kpcn_render_ctx *ctx,
                                                       const camera_sample *cs,
                                                       const struct RTCRayHit16 *rh, int n,
                                                       kpcn_sample_out *out) {
  footprint_hit fh[16];
  int uniform = 1;
  if (n < 1) return;
  for (int q = 0; q < n; q++) {
    footprint_hit_fill(ctx, &cs[q], rh, q, &fh[q]);
    uniform &= same_surface(&fh[q], &fh[0]);
  }
  /* a plane's uv derivatives: once per pixel where all its samples see the same surface (they
   * change by far less than a pixel's worth across it; for a mesh, sample 0's triangle stands
   * for its neighbours), else per sample; grazing: the point samples stand */
  if (uniform && fh[0].prim && !fh[0].exact) {
    if (!footprint_derivatives(ctx, &cs[0], &fh[0])) return;
    for (int q = 1; q < n; q++) {
      fh[q].dudx = fh[0].dudx, fh[q].dvdx = fh[0].dvdx;
      fh[q].dudy = fh[0].dudy, fh[q].dvdy = fh[0].dvdy;
    }
  } else {
    for (int q = 0; q < n; q++)
      if (fh[q].prim && !fh[q].exact && !footprint_derivatives(ctx, &cs[q], &fh[q]))
        fh[q].prim = NULL;
  }
  /* the pixel's n * k * k footprint points: a rank-1 lattice, rotated by sample 0's film
   * point (Cranley-Patterson); sample s takes points s, s + n, s + 2n, ... */
  const int k2 = ctx->albedo_footprint * ctx->albedo_footprint, npts = n * k2;
  const uint32_t gen = lattice_generator((uint32_t)npts);
  const float inv = 1.0f / (float)npts;
  for (int s = 0; s < n; s++) {
    const footprint_hit *f = &fh[s];
    if (!f->prim) continue;
    kpcn_vec3 sum = out[s].albedo;
    int count = 1;
    /* point m = s + n j: (m / npts, (m gen mod npts) / npts), the second kept incrementally */
    const uint32_t N = (uint32_t)npts, step = ((uint32_t)n * gen) % N;
    uint32_t mg = ((uint32_t)s * gen) % N;
    for (int j = 0; j < k2; j++, mg = mg + step >= N ? mg + step - N : mg + step) {
      float fu = cs[0].fu + (float)(s + n * j) * inv, fv = cs[0].fv + (float)mg * inv;
      if (fu >= 1.0f) fu -= 1.0f;
      if (fv >= 1.0f) fv -= 1.0f;
      float ox = filter_sample(&ctx->filter, fu), oy = filter_sample(&ctx->filter, fv);
      if (!uniform) {
        int best = s;
        float bd = INFINITY;
        for (int q = 0; q < n; q++) {
          float dx = fh[q].ox - ox, dy = fh[q].oy - oy, d2 = dx * dx + dy * dy;
          if (d2 < bd) bd = d2, best = q;
        }
        if (!same_surface(&fh[best], f)) continue;
      }
      kpcn_shading_point sp;
      if (f->exact) {
        if (!footprint_uv_at(ctx, &cs[s], fu, fv, f->prim, f->prim_id, &f->h, 0, 0, &sp.u, &sp.v))
          continue;
      } else {
        const float ex = ox - f->ox, ey = oy - f->oy;
        sp.u = f->u + ex * f->dudx + ey * f->dudy;
        sp.v = f->v + ex * f->dvdx + ey * f->dvdy;
      }
      if (f->clamp) sp.u = clamp01f(sp.u), sp.v = clamp01f(sp.v);
      sum = kv3_add(sum, kpcn_bsdf_albedo(f->prim->bsdf, &sp));
      count++;
    }
    out[s].albedo = kv3_scale(sum, 1.0f / (float)count);
  }
}

void KPCN_TRACE_PIXEL(const kpcn_render_ctx *ctx, int px, int py, kpcn_sampler *smp, int n,
                      kpcn_sample_out *out) {
  /* The camera rays of a pixel's samples differ only by sub-pixel (and lens) offsets, so
   * Embree traverses them as one coherent 16-wide packet at a fraction of the cost of single
   * queries (+7.5 % samples/s on the cornell box). Every later ray is traced on its own:
   * packets of the scattered extension rays, and even of the first bounce's shadow rays,
   * measured slower than single queries (bench_render, docs/renderer.md). Each sample's
   * arithmetic is the scalar path's and samples never interact, so the result does not
   * depend on how samples are grouped. */
  const kpcn_scene *s = ctx->scene;
  struct RTCRayHit16 rh __attribute__((aligned(64)));
  int valid[16] __attribute__((aligned(64)));
  camera_sample cs[16];
  if (n > 16) n = 16;
  for (int k = 0; k < 16; k++) {
    /* Lanes past n must hold a well-formed, empty ray (tnear 0 > tfar -inf), not stack
     * garbage: where the CPU has no native 16-wide traversal (AVX2), Embree 3.13 splits the
     * packet through its ray-stream path, which ignores `valid` and marks lanes inactive by
     * tnear > tfar; Debian's Embree then aborted on a garbage lane's assertions
     * (`ray.valid()`, `tnear >= 0`) whenever fewer than 16 samples were traced. */
    valid[k] = k < n ? -1 : 0;
    kpcn_vec3 o = kv3(0.0f, 0.0f, 0.0f), d = kv3(0.0f, 0.0f, 1.0f);
    if (k < n) {
      memset(&out[k], 0, sizeof(out[k]));
      camera_ray(ctx, px, py, &smp[k], &cs[k], &o, &d);
    }
    rh.ray.org_x[k] = o.x, rh.ray.org_y[k] = o.y, rh.ray.org_z[k] = o.z;
    rh.ray.dir_x[k] = d.x, rh.ray.dir_y[k] = d.y, rh.ray.dir_z[k] = d.z;
    rh.ray.tnear[k] = 0.0f;
    rh.ray.tfar[k] = k < n ? INFINITY : -INFINITY;
    rh.ray.mask[k] = 0xffffffffU;
    rh.ray.flags[k] = 0;
    rh.ray.time[k] = 0.0f;
    rh.ray.id[k] = (unsigned)k;
    rh.hit.geomID[k] = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0][k] = RTC_INVALID_GEOMETRY_ID;
  }
  struct RTCIntersectContext ic;
  rtcInitIntersectContext(&ic);
  ic.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
  rtcIntersect16(valid, (RTCScene)s->rtc_scene, &ic, &rh);
  for (int k = 0; k < n; k++) {
    struct RTCRayHit first;
    first.ray.tfar = rh.ray.tfar[k];
    first.hit.geomID = rh.hit.geomID[k];
    first.hit.primID = rh.hit.primID[k];
    first.hit.u = rh.hit.u[k];
    first.hit.v = rh.hit.v[k];
    trace_path(ctx, &smp[k], &out[k], kv3(rh.ray.org_x[k], rh.ray.org_y[k], rh.ray.org_z[k]),
               kv3(rh.ray.dir_x[k], rh.ray.dir_y[k], rh.ray.dir_z[k]), &first);
  }
  if (ctx->albedo_footprint > 1) footprint_albedo(ctx, cs, &rh, n, out);
}
