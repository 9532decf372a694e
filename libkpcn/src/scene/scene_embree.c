/* Embree 3 geometry for the loaded primitives. Analytic shapes use Embree's own analytic
 * types (quads, sphere points, oriented discs) so the silhouettes are exact; meshes are
 * triangle geometries. */
#include "core/internal.h"
#include "scene/scene_internal.h"

#include <embree3/rtcore.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static void set_v3(float *dst, kpcn_vec3 v) { dst[0] = v.x, dst[1] = v.y, dst[2] = v.z; }

/* rtcGetDeviceError clears the error it returns: the callers read it once and pass it in
 * (it was read twice, and the message always said "error 0") */
static kpcn_status embree_error(enum RTCError e, const char *what, int prim) {
  const char *why = e == RTC_ERROR_OUT_OF_MEMORY       ? "out of memory"
                    : e == RTC_ERROR_UNSUPPORTED_CPU   ? "this CPU is not supported"
                    : e == RTC_ERROR_INVALID_ARGUMENT  ? "an invalid argument"
                    : e == RTC_ERROR_INVALID_OPERATION ? "an invalid operation"
                    : e == RTC_ERROR_CANCELLED         ? "cancelled"
                    : e == RTC_ERROR_NONE              ? "no error reported"
                                                       : "an unknown error";
  if (prim >= 0)
    return kpcn_fail(KPCN_ERR_INTERNAL, "Embree failed while %s for primitives[%d]: %s (%d)", what,
                     prim, why, (int)e);
  return kpcn_fail(KPCN_ERR_INTERNAL, "Embree failed while %s: %s (%d)", what, why, (int)e);
}

static RTCGeometry make_geometry(RTCDevice dev, const kpcn_prim *p) {
  RTCGeometry g = NULL;
  switch (p->type) {
  case KPCN_PRIM_QUAD: {
    g = rtcNewGeometry(dev, RTC_GEOMETRY_TYPE_QUAD);
    float *v = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 12, 4);
    unsigned *q = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT4, 16, 1);
    if (!v || !q) break;
    set_v3(v + 0, p->base);
    set_v3(v + 3, kv3_add(p->base, p->e0));
    set_v3(v + 6, kv3_add(kv3_add(p->base, p->e0), p->e1));
    set_v3(v + 9, kv3_add(p->base, p->e1));
    q[0] = 0, q[1] = 1, q[2] = 2, q[3] = 3;
    break;
  }
  case KPCN_PRIM_CUBE: {
    g = rtcNewGeometry(dev, RTC_GEOMETRY_TYPE_QUAD);
    float *v = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 12, 8);
    unsigned *q = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT4, 16, 6);
    if (!v || !q) break;
    for (int i = 0; i < 8; i++) {
      kpcn_vec3 c = p->center;
      c = kv3_madd(c, p->axis[0], (i & 1) ? p->half.x : -p->half.x);
      c = kv3_madd(c, p->axis[1], (i & 2) ? p->half.y : -p->half.y);
      c = kv3_madd(c, p->axis[2], (i & 4) ? p->half.z : -p->half.z);
      set_v3(v + 3 * i, c);
    }
    static const unsigned faces[6][4] = {{0, 2, 6, 4}, {1, 5, 7, 3}, {0, 4, 5, 1},
                                         {2, 3, 7, 6}, {0, 1, 3, 2}, {4, 6, 7, 5}};
    memcpy(q, faces, sizeof(faces));
    break;
  }
  case KPCN_PRIM_SPHERE: {
    g = rtcNewGeometry(dev, RTC_GEOMETRY_TYPE_SPHERE_POINT);
    float *v = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT4, 16, 1);
    if (!v) break;
    set_v3(v, p->center);
    v[3] = p->radius;
    break;
  }
  case KPCN_PRIM_DISK: {
    g = rtcNewGeometry(dev, RTC_GEOMETRY_TYPE_ORIENTED_DISC_POINT);
    float *v = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT4, 16, 1);
    float *n = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_NORMAL, 0, RTC_FORMAT_FLOAT3, 12, 1);
    if (!v || !n) break;
    set_v3(v, p->center);
    v[3] = p->radius;
    set_v3(n, p->n);
    break;
  }
  case KPCN_PRIM_MESH: {
    const kpcn_mesh *m = &p->mesh;
    g = rtcNewGeometry(dev, RTC_GEOMETRY_TYPE_TRIANGLE);
    rtcSetSharedGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, m->pos, 0, 12,
                               (size_t)m->nverts);
    rtcSetSharedGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, m->idx, 0, 12,
                               (size_t)m->ntris);
    break;
  }
  case KPCN_PRIM_INFINITE_SPHERE: break;
  }
  return g;
}

/* max(c, |v|) that keeps a NaN once seen (fmaxf would drop it) */
static inline float max_abs(float c, float v) {
  float a = fabsf(v);
  return a > c || a != a ? a : c;
}

/* Largest |coordinate| primitive p reaches (its vertices, or centre ± radius); NaN if any is
 * NaN. */
static float prim_reach(const kpcn_prim *p) {
  float m = 0.0f;
  kpcn_vec3 pts[4];
  int n = 0;
  switch (p->type) {
  case KPCN_PRIM_QUAD:
    pts[0] = p->base, pts[1] = kv3_add(p->base, p->e0), pts[2] = kv3_add(p->base, p->e1);
    pts[3] = kv3_add(pts[1], p->e1), n = 4;
    break;
  case KPCN_PRIM_CUBE: /* the corners lie within |centre| + the half-diagonal */
    m = kv3_length(p->half);
    pts[0] = p->center, n = 1;
    break;
  case KPCN_PRIM_SPHERE:
  case KPCN_PRIM_DISK: m = p->radius, pts[0] = p->center, n = 1; break;
  case KPCN_PRIM_MESH:
    for (size_t i = 0; i < 3 * (size_t)p->mesh.nverts; i++)
      m = max_abs(m, p->mesh.pos[i]);
    return m;
  case KPCN_PRIM_INFINITE_SPHERE: return 0.0f;
  }
  float c = 0.0f;
  for (int i = 0; i < n; i++)
    c = max_abs(max_abs(max_abs(c, pts[i].x), pts[i].y), pts[i].z);
  return c + m; /* the caller's test rejects NaN */
}

/* Embree asserts (or returns garbage) on rays whose origin is beyond ~1.8e18 and on geometry
 * with non-finite bounds; a finite but absurd scale, position or aperture in the scene file
 * gets there through products. Refuse such scenes before building, naming the culprit. */
static kpcn_status check_extent(const kpcn_scene *s) {
  for (int i = 0; i < s->nprims; i++) {
    float r = prim_reach(&s->prims[i]);
    if (!(r <= KPCN_SCENE_MAX_EXTENT))
      return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                       "primitives[%d]%s%s%s: coordinates reach %g; supported |x| <= %g", i,
                       s->prims[i].name[0] ? " ('" : "", s->prims[i].name,
                       s->prims[i].name[0] ? "')" : "", (double)r, (double)KPCN_SCENE_MAX_EXTENT);
  }
  const kpcn_camera *c = &s->cam;
  float cr = max_abs(max_abs(max_abs(0.0f, c->pos.x), c->pos.y), c->pos.z);
  if (c->thinlens) cr += c->aperture;
  if (!(cr <= KPCN_SCENE_MAX_EXTENT))
    return kpcn_fail(
        KPCN_ERR_INVALID_ARGUMENT, "camera: position%s reaches %g; supported |x| <= %g",
        c->thinlens ? " plus aperture_size" : "", (double)cr, (double)KPCN_SCENE_MAX_EXTENT);
  return KPCN_OK;
}

kpcn_status kpcn_scene_build_embree(kpcn_scene *s) {
  KPCN_TRY(check_extent(s));
  /* Under the AVX2 cap (ONEDNN_MAX_CPU_ISA, core/cpu.c) Embree is capped too, so that an
   * AVX-512 host runs the traversal a CPU without it runs: no native 16-wide packets, which
   * Embree then splits through its ray-stream path (test_render_packets_avx2). */
  RTCDevice dev = rtcNewDevice(kpcn_cpu_allows_avx512() ? NULL : "max_isa=avx2");
  if (!dev)
    return kpcn_fail(KPCN_ERR_INTERNAL, "cannot create the Embree device (error %d)",
                     (int)rtcGetDeviceError(NULL));
  s->rtc_device = dev;
  RTCScene sc = rtcNewScene(dev);
  if (!sc) return embree_error(rtcGetDeviceError(dev), "creating the scene", -1);
  s->rtc_scene = sc;
  rtcSetSceneBuildQuality(sc, RTC_BUILD_QUALITY_HIGH);
  s->geom_to_prim = kpcn_calloc((size_t)s->nprims + 1, sizeof(unsigned), "geometry table");
  if (!s->geom_to_prim) return KPCN_ERR_OUT_OF_MEMORY;
  for (int i = 0; i < s->nprims; i++) {
    kpcn_prim *p = &s->prims[i];
    if (p->type == KPCN_PRIM_INFINITE_SPHERE) continue;
    RTCGeometry g = make_geometry(dev, p);
    const enum RTCError ge = rtcGetDeviceError(dev);
    if (!g || ge != RTC_ERROR_NONE) {
      if (g) rtcReleaseGeometry(g);
      return embree_error(ge, "creating the geometry", i);
    }
    rtcCommitGeometry(g);
    p->geom_id = rtcAttachGeometry(sc, g);
    rtcReleaseGeometry(g);
    s->geom_to_prim[p->geom_id] = (unsigned)i;
    s->ngeoms = (int)p->geom_id + 1;
  }
  rtcCommitScene(sc);
  const enum RTCError be = rtcGetDeviceError(dev);
  if (be != RTC_ERROR_NONE) return embree_error(be, "building the BVH", -1);
  struct RTCBounds b;
  rtcGetSceneBounds(sc, &b);
  float r = 1.0f;
  if (s->ngeoms > 0 && isfinite(b.lower_x) && b.upper_x >= b.lower_x) {
    float dx = b.upper_x - b.lower_x, dy = b.upper_y - b.lower_y, dz = b.upper_z - b.lower_z;
    r = 0.5f * sqrtf(dx * dx + dy * dy + dz * dz);
    float m =
        fmaxf(fmaxf(fabsf(b.lower_x), fabsf(b.upper_x)), fmaxf(fabsf(b.lower_y), fabsf(b.upper_y)));
    m = fmaxf(m, fmaxf(fabsf(b.lower_z), fabsf(b.upper_z)));
    r = fmaxf(r, m);
  }
  s->scene_radius = fmaxf(r, 1e-3f);
  return KPCN_OK;
}

void kpcn_scene_release_embree(kpcn_scene *s) {
  if (s->rtc_scene) rtcReleaseScene((RTCScene)s->rtc_scene);
  if (s->rtc_device) rtcReleaseDevice((RTCDevice)s->rtc_device);
  s->rtc_scene = s->rtc_device = NULL;
}
