/* Camera-ray packets (kpcn_trace_pixel): a pixel's samples traced as one 16-wide packet, one
 * by one, or in other groupings give byte-identical per-sample outputs (colour split, AOVs,
 * ray counts). The renderer's determinism whatever the thread count rests on this, and so
 * does the claim that Embree's packet traversal reports each lane's single-ray hit. Scenes:
 * area light + quads (cornell-box), thin-lens camera (depth-discontinuities), environment
 * light (envmap-lighting), glass and rough materials (materialtest).
 * The tracer the renderer picks for this CPU (ctx.trace: the GFNI build where the CPU has it)
 * gives the portable build's bytes too, and the SIMD ray offset equals its scalar formula.
 * test_render_packets_avx2 runs it again with Embree capped at AVX2 (no native 16-wide
 * packets), where partial packets go through Embree's ray-stream path. */
#include "bsdf_testlib.h"
#include "testutil.h"

#include "core/internal.h"
#include "render/render_internal.h"

#include <embree3/rtcore.h>
#include <math.h>
#include <stdio.h>
#include <string.h>

/* Fills the stack below the caller with -1e30, so that a packet lane the tracer leaves unset
 * holds a ray that is "active" by the ray-stream convention (tnear <= tfar) but malformed
 * (tnear < 0, |origin| beyond Embree's limit), not whatever an earlier call left there.
 * Embree's ray-stream path, which a CPU without native 16-wide traversal takes, ignores the
 * valid mask and traces such lanes: session 47's aborts. (NaNs would not do: tnear <= tfar
 * is false for them, so the stream path skips them.) */
static __attribute__((noinline)) void poison_stack(void) {
  volatile float junk[16384];
  for (int i = 0; i < 16384; i++)
    junk[i] = -1e30f;
  (void)junk[0];
}

/* traces samples [0, 16) of pixel (px, py) in groups of the given sizes */
static void trace_grouped(const kpcn_render_ctx *ctx, int px, int py, const int *groups,
                          int ngroups, kpcn_sample_out out[16], int portable) {
  kpcn_sampler_cache cache;
  kpcn_sampler_cache_reset(&cache, kpcn_pixel_seed(ctx->seed, (uint32_t)px, (uint32_t)py));
  int first = 0;
  for (int g = 0; g < ngroups; g++) {
    kpcn_sampler smp[16];
    for (int k = 0; k < groups[g]; k++)
      kpcn_sampler_start(&smp[k], ctx->seed, (uint32_t)px, (uint32_t)py, (uint32_t)(first + k),
                         &cache);
    poison_stack();
    if (portable)
      kpcn_trace_pixel(ctx, px, py, smp, groups[g], out + first);
    else
      ctx->trace(ctx, px, py, smp, groups[g], out + first);
    first += groups[g];
  }
}

static void check_scene(const char *name) {
  char path[512];
  snprintf(path, sizeof(path), KPCN_TESTDATA "/scenes/%s", name);
  kpcn_scene *s = NULL;
  if (kpcn_scene_load(path, &s) != KPCN_OK) {
    fprintf(stderr, "%s\n", kpcn_last_error());
    CHECK(0);
    return;
  }
  kpcn_render_settings st = kpcn_render_settings_defaults();
  st.width = st.height = 24;
  st.seed = 7;
  kpcn_render_ctx ctx;
  CHECK(kpcn_render_ctx_init(&ctx, s, &st) == KPCN_OK);
  /* under the AVX2 cap (test_render_packets_avx2) Embree must have no native 16-wide
   * packets, so the groups of 1 and 5 below go through its ray-stream split */
  int native16 = (int)rtcGetDeviceProperty((RTCDevice)s->rtc_device,
                                           RTC_DEVICE_PROPERTY_NATIVE_RAY16_SUPPORTED);
  if (!kpcn_cpu_allows_avx512()) CHECK(native16 == 0);
  static const int one[] = {16}, singles[] = {1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1},
                   split[] = {5, 11};
  unsigned fp = kpcn_fast_fp_begin(1); /* the renderer's own float mode */
  int differ = 0, rays = 0, hits = 0;
  for (int py = 0; py < 24; py += 3)
    for (int px = 0; px < 24; px += 3) {
      kpcn_sample_out a[16], b[16], c[16], d[16];
      memset(a, 0, sizeof(a)), memset(b, 0, sizeof(b)), memset(c, 0, sizeof(c));
      memset(d, 0, sizeof(d));
      trace_grouped(&ctx, px, py, one, 1, a, 1);
      trace_grouped(&ctx, px, py, singles, 16, b, 1);
      trace_grouped(&ctx, px, py, split, 2, c, 1);
      trace_grouped(&ctx, px, py, one, 1, d, 0);
      differ += memcmp(a, b, sizeof(a)) != 0;
      differ += memcmp(a, c, sizeof(a)) != 0;
      differ += memcmp(a, d, sizeof(a)) != 0;
      for (int k = 0; k < 16; k++) {
        rays += (int)a[k].rays;
        hits += a[k].depth > 0.0f;
      }
    }
  kpcn_fast_fp_end(fp, 1);
  printf("%-40s 64 pixels x 16 samples: %d rays, %d first hits, %d differing groupings%s%s\n", name,
         rays, hits, differ, ctx.trace != kpcn_trace_pixel ? " (and the GFNI build)" : "",
         native16 ? "" : " (Embree: no native 16-wide packets)");
  CHECK(differ == 0);
  CHECK(rays > 64 * 16 && hits > 0); /* the paths were really traced */
  kpcn_scene_destroy(s);
}

/* Waechter & Binder's offset as scalar code, one coordinate at a time (the bits added in
 * unsigned arithmetic: for p = -0 the sum wraps, and that result is not the one selected) */
static float offset_ref(float p, float n) {
  int o = (int)(256.0f * n);
  uint32_t i;
  memcpy(&i, &p, 4);
  i += (uint32_t)(p < 0.0f ? -o : o);
  float far;
  memcpy(&far, &i, 4);
  return fabsf(p) < 1.0f / 32.0f ? p + n * (1.0f / 65536.0f) : far;
}

static void check_offset_ray(void) {
  kt_rng r = {11};
  int bad = 0;
  for (int k = 0; k < 200000; k++) {
    /* positions from 1e-6 to 1e3 in magnitude and both signs (exact zeros, the 1/32
     * threshold on both sides included); unit normals */
    float c[3], n[3];
    for (int j = 0; j < 3; j++) {
      float m = powf(10.0f, -6.0f + 9.0f * kt_next(&r));
      int kind = (int)(kt_next(&r) * 8.0f);
      c[j] = kind == 0 ? 0.0f : kind == 1 ? 1.0f / 32.0f : m;
      if (kt_next(&r) < 0.5f) c[j] = -c[j];
      n[j] = 2.0f * kt_next(&r) - 1.0f;
    }
    kpcn_vec3 nn = kv3_normalize(kv3(n[0], n[1], n[2]));
    kpcn_vec3 o = kpcn_offset_ray(kv3(c[0], c[1], c[2]), nn);
    float e[3] = {offset_ref(c[0], nn.x), offset_ref(c[1], nn.y), offset_ref(c[2], nn.z)};
    bad += memcmp(&o.x, &e[0], 4) || memcmp(&o.y, &e[1], 4) || memcmp(&o.z, &e[2], 4);
  }
  printf("offset_ray: %d of 200000 differ from the scalar formula\n", bad);
  CHECK(bad == 0);
}

int main(void) {
  check_offset_ray();
  check_scene("cornell-box/scene.json");
  check_scene("depth-discontinuities/scene.json");
  check_scene("envmap-lighting/scene.json");
  check_scene("materialtest/materialtest.json");
  return kt_summary("render_packets");
}
