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

/* ---- Embree queries ---- */

static int intersect(const kpcn_scene *s, kpcn_vec3 o, kpcn_vec3 d, float tfar,
                     struct RTCRayHit *rh) {
  struct RTCIntersectContext ic;
  rtcInitIntersectContext(&ic);
  rh->ray.org_x = o.x, rh->ray.org_y = o.y, rh->ray.org_z = o.z;
  rh->ray.dir_x = d.x, rh->ray.dir_y = d.y, rh->ray.dir_z = d.z;
  rh->ray.tnear = 0.0f;
  rh->ray.tfar = tfar;
  rh->ray.mask = 0xffffffffU;
  rh->ray.flags = 0;
  rh->ray.time = 0.0f;
  rh->ray.id = 0;
  rh->hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rh->hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
  rtcIntersect1((RTCScene)s->rtc_scene, &ic, rh);
  return rh->hit.geomID != RTC_INVALID_GEOMETRY_ID;
}

static int occluded(const kpcn_scene *s, kpcn_vec3 o, kpcn_vec3 d, float tfar) {
  struct RTCIntersectContext ic;
  rtcInitIntersectContext(&ic);
  struct RTCRay r;
  r.org_x = o.x, r.org_y = o.y, r.org_z = o.z;
  r.dir_x = d.x, r.dir_y = d.y, r.dir_z = d.z;
  r.tnear = 0.0f;
  r.tfar = tfar;
  r.mask = 0xffffffffU;
  r.flags = 0;
  r.time = 0.0f;
  r.id = 0;
  rtcOccluded1((RTCScene)s->rtc_scene, &ic, &r);
  return r.tfar < 0.0f; /* Embree sets tfar = -inf on a hit */
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

/* Next-event estimation from the shading point: returns the unweighted-by-throughput
 * contribution split (total, diffuse part) and whether the shadow ray reached the light. */
static int sample_direct(const kpcn_render_ctx *ctx, const kpcn_hit *h, const kpcn_frame *fr,
                         const kpcn_bsdf *bsdf, const kpcn_shading_point *sp, kpcn_vec3 wo_l,
                         kpcn_vec3 ng, float ul, float u1, float u2, kpcn_vec3 *c_tot,
                         kpcn_vec3 *c_diff, uint32_t *rays) {
  const kpcn_scene *s = ctx->scene;
  *c_tot = *c_diff = kv3s(0.0f);
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
  (*rays)++;
  if (occluded(s, origin, wi, dist)) return 0;
  float w = ctx->mis ? power_heuristic(pdf, ev.pdf) : 1.0f;
  kpcn_vec3 k = kv3_scale(Li, w / pdf);
  *c_tot = kv3_mul(ev.f_cos, k);
  *c_diff = kv3_mul(ev.f_cos_diffuse, k);
  return 1;
}

static void camera_ray(const kpcn_render_ctx *ctx, int px, int py, kpcn_sampler *smp, kpcn_vec3 *o,
                       kpcn_vec3 *d) {
  const kpcn_camera *c = &ctx->scene->cam;
  float fu, fv;
  kpcn_sampler_2d(smp, &fu, &fv);
  float ox = filter_sample(&ctx->filter, fu), oy = filter_sample(&ctx->filter, fv);
  float pix = 2.0f / (float)ctx->width;
  kpcn_vec3 l = kv3(-1.0f + ((float)px + 0.5f + ox) * pix,
                    ctx->ratio - ((float)py + 0.5f + oy) * pix, c->plane_dist);
  kpcn_vec3 lens = kv3s(0.0f);
  if (c->thinlens && c->aperture > 0.0f) {
    float lu, lv, ax, ay;
    kpcn_sampler_2d(smp, &lu, &lv); /* pair 1 (pinholes leave it unused) */
    kpcn_warp_concentric_disk(lu, lv, &ax, &ay);
    lens = kv3(ax * c->aperture, ay * c->aperture, 0.0f);
    l = kv3_scale(l, c->focus_dist / c->plane_dist);
    l = kv3_sub(l, lens);
  }
  l = kv3_normalize(l);
  *d = kv3_normalize(
      kv3_add(kv3_add(kv3_scale(c->right, l.x), kv3_scale(c->up, l.y)), kv3_scale(c->fwd, l.z)));
  *o = kv3_add(c->pos, kv3_add(kv3_scale(c->right, lens.x), kv3_scale(c->up, lens.y)));
}

void kpcn_trace_sample(const kpcn_render_ctx *ctx, int px, int py, kpcn_sampler *smp,
                       kpcn_sample_out *out) {
  const kpcn_scene *s = ctx->scene;
  const kpcn_camera *cam = &s->cam;
  memset(out, 0, sizeof(*out));
  kpcn_vec3 o, d;
  camera_ray(ctx, px, py, smp, &o, &d);
  kpcn_vec3 tp_s = kv3s(1.0f), tp_d = kv3s(0.0f); /* specular / diffuse throughputs */
  kpcn_vec3 Ls = kv3s(0.0f), Ld = kv3s(0.0f);
  int have_feature = 0, prev_delta = 1;
  float prev_pdf = 0.0f, path_len = 0.0f; /* d is unit length: t is the distance */
  kpcn_vec3 prev_p = o;
  int bounce = 0;
  struct RTCRayHit rh;
  for (;;) {
    out->rays++;
    if (!intersect(s, o, d, INFINITY, &rh)) {
      if (s->env) {
        kpcn_vec3 Le = kpcn_envmap_eval(s->env, d);
        float w = 1.0f;
        if (!prev_delta) {
          if (!ctx->bsdf_emission)
            w = 0.0f;
          else if (ctx->mis)
            w = power_heuristic(prev_pdf,
                                s->lights[s->env_light].select_pdf * kpcn_envmap_pdf(s->env, d));
        }
        Ls = kv3_add(Ls, kv3_scale(kv3_mul(tp_s, Le), w));
        Ld = kv3_add(Ld, kv3_scale(kv3_mul(tp_d, Le), w));
      }
      break;
    }
    const kpcn_prim *p = &s->prims[s->geom_to_prim[rh.hit.geomID]];
    kpcn_hit h;
    kpcn_hit_fill(s, p, o, d, rh.ray.tfar, rh.hit.primID, rh.hit.u, rh.hit.v, &h);
    path_len += h.t;
    if (p->emissive) {
      kpcn_vec3 Le = kpcn_prim_emission(p, &h, d);
      if (!kv3_is_zero(Le)) {
        float w = 1.0f;
        if (!prev_delta) {
          if (!ctx->bsdf_emission)
            w = 0.0f;
          else if (ctx->mis)
            w = power_heuristic(prev_pdf, light_pdf_area(s, p, &h, prev_p, d));
        }
        Ls = kv3_add(Ls, kv3_scale(kv3_mul(tp_s, Le), w));
        Ld = kv3_add(Ld, kv3_scale(kv3_mul(tp_d, Le), w));
      }
    }
    const kpcn_bsdf *bsdf = p->bsdf;
    if (kpcn_bsdf_is_null(bsdf)) {
      /* Tungsten's "null" BSDF absorbs (its pass-through BSDF is "forward"): the path ends
       * here, after the emission above. A directly seen one is the feature surface. */
      if (!have_feature) {
        kpcn_shading_point sp0 = {h.u, h.v};
        kpcn_vec3 nf = kv3_dot(h.ns, d) > 0.0f ? kv3_neg(h.ns) : h.ns;
        out->albedo = kpcn_bsdf_albedo(bsdf, &sp0);
        out->normal = kv3(kv3_dot(nf, cam->right), kv3_dot(nf, cam->up), -kv3_dot(nf, cam->fwd));
        out->depth = path_len;
      }
      break;
    }
    if (bounce >= ctx->max_bounces) break;
    kpcn_vec3 wo = kv3_neg(d), ng = h.ng, ns = h.ns;
    if (!kpcn_bsdf_is_transmissive(bsdf) && kv3_dot(wo, ng) < 0.0f) { /* two-sided shading */
      ng = kv3_neg(ng);
      ns = kv3_neg(ns);
    }
    kpcn_frame fr = kpcn_frame_from_normal(ns);
    kpcn_vec3 wo_l = kpcn_frame_to_local(&fr, wo);
    kpcn_shading_point sp = {h.u, h.v};
    int delta_only = kpcn_bsdf_is_delta_only(bsdf);
    int at_feature = !have_feature && !delta_only;
    if (at_feature) {
      have_feature = 1;
      out->albedo = kpcn_bsdf_albedo(bsdf, &sp);
      kpcn_vec3 nf = kv3_dot(ns, wo) < 0.0f ? kv3_neg(ns) : ns;
      out->normal = kv3(kv3_dot(nf, cam->right), kv3_dot(nf, cam->up), -kv3_dot(nf, cam->fwd));
      out->depth = path_len;
    }
    /* three dimension pairs per bounce: (light choice, lobe choice), light point, direction */
    kpcn_sampler_set_pair(smp, 2 + 3 * (uint32_t)bounce);
    float ul, ulobe, u1, u2, ub1, ub2;
    kpcn_sampler_2d(smp, &ul, &ulobe);
    kpcn_sampler_2d(smp, &u1, &u2);
    kpcn_sampler_2d(smp, &ub1, &ub2);
    if (!delta_only && ctx->nee && s->nlights > 0) {
      kpcn_vec3 ct, cd;
      int vis = sample_direct(ctx, &h, &fr, bsdf, &sp, wo_l, ng, ul, u1, u2, &ct, &cd, &out->rays);
      if (at_feature) {
        out->visibility = (float)vis;
        Ld = kv3_add(Ld, kv3_mul(tp_s, cd));
        Ls = kv3_add(Ls, kv3_mul(tp_s, kv3_sub(ct, cd)));
      } else {
        Ld = kv3_add(Ld, kv3_mul(tp_d, ct));
        Ls = kv3_add(Ls, kv3_mul(tp_s, ct));
      }
    } else if (at_feature && !ctx->color_only && s->nlights > 0) {
      /* light sampling is off (BSDF-only): still trace one shadow ray for the visibility AOV,
       * without adding its contribution */
      kpcn_vec3 ct, cd;
      out->visibility =
          (float)sample_direct(ctx, &h, &fr, bsdf, &sp, wo_l, ng, ul, u1, u2, &ct, &cd, &out->rays);
    }
    kpcn_bsdf_sample_result bs;
    if (!kpcn_bsdf_sample(bsdf, &sp, wo_l, ub1, ub2, ulobe, &bs)) break;
    if (at_feature) {
      tp_d = kv3_mul(tp_s, bs.weight_diffuse);
      tp_s = kv3_mul(tp_s, kv3_sub(bs.weight, bs.weight_diffuse));
    } else {
      tp_d = kv3_mul(tp_d, bs.weight);
      tp_s = kv3_mul(tp_s, bs.weight);
    }
    kpcn_vec3 wi = kpcn_frame_to_world(&fr, bs.wi);
    prev_delta = bs.is_delta;
    prev_pdf = bs.pdf;
    prev_p = h.p;
    bounce++;
    /* Russian roulette after 2 bounces, only once the throughput has fallen below 0.25 (Tungsten
     * uses 0.1; 0.25 traces ~18% fewer rays on the cornell box at an error per sample still
     * below Tungsten's, see bench_render), so short paths keep their low variance */
    if (bounce > 2 && bounce >= ctx->min_bounces) {
      float q = kv3_max_comp(kv3_add(tp_s, tp_d));
      if (q >= RR_THRESHOLD) goto next;
      if (!(q > 0.0f) || kpcn_sampler_random(smp, (uint32_t)bounce) >= q) break;
      float inv = 1.0f / q;
      tp_s = kv3_scale(tp_s, inv);
      tp_d = kv3_scale(tp_d, inv);
    }
  next:
    if (kv3_is_zero(tp_s) && kv3_is_zero(tp_d)) break;
    o = kpcn_offset_ray(h.p, kv3_dot(wi, ng) > 0.0f ? ng : kv3_neg(ng));
    d = kv3_normalize(wi);
  }
  out->diffuse = Ld;
  out->specular = Ls;
}
