/* Camera-ray packets (kpcn_trace_pixel): a pixel's samples traced as one 16-wide packet, one
 * by one, or in other groupings give byte-identical per-sample outputs (colour split, AOVs,
 * ray counts). The renderer's determinism whatever the thread count rests on this, and so
 * does the claim that Embree's packet traversal reports each lane's single-ray hit. Scenes:
 * area light + quads (cornell-box), thin-lens camera (depth-discontinuities), environment
 * light (envmap-lighting), glass and rough materials (materialtest). */
#include "testutil.h"

#include "core/internal.h"
#include "render/render_internal.h"

#include <stdio.h>
#include <string.h>

/* traces samples [0, 16) of pixel (px, py) in groups of the given sizes */
static void trace_grouped(const kpcn_render_ctx *ctx, int px, int py, const int *groups,
                          int ngroups, kpcn_sample_out out[16]) {
  kpcn_sampler_cache cache;
  kpcn_sampler_cache_reset(&cache, kpcn_pixel_seed(ctx->seed, (uint32_t)px, (uint32_t)py));
  int first = 0;
  for (int g = 0; g < ngroups; g++) {
    kpcn_sampler smp[16];
    for (int k = 0; k < groups[g]; k++)
      kpcn_sampler_start(&smp[k], ctx->seed, (uint32_t)px, (uint32_t)py, (uint32_t)(first + k),
                         &cache);
    kpcn_trace_pixel(ctx, px, py, smp, groups[g], out + first);
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
  static const int one[] = {16}, singles[] = {1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1},
                   split[] = {5, 11};
  unsigned fp = kpcn_fast_fp_begin(1); /* the renderer's own float mode */
  int differ = 0, rays = 0, hits = 0;
  for (int py = 0; py < 24; py += 3)
    for (int px = 0; px < 24; px += 3) {
      kpcn_sample_out a[16], b[16], c[16];
      memset(a, 0, sizeof(a)), memset(b, 0, sizeof(b)), memset(c, 0, sizeof(c));
      trace_grouped(&ctx, px, py, one, 1, a);
      trace_grouped(&ctx, px, py, singles, 16, b);
      trace_grouped(&ctx, px, py, split, 2, c);
      differ += memcmp(a, b, sizeof(a)) != 0;
      differ += memcmp(a, c, sizeof(a)) != 0;
      for (int k = 0; k < 16; k++) {
        rays += (int)a[k].rays;
        hits += a[k].depth > 0.0f;
      }
    }
  kpcn_fast_fp_end(fp, 1);
  printf("%-40s 64 pixels x 16 samples: %d rays, %d first hits, %d differing groupings\n", name,
         rays, hits, differ);
  CHECK(differ == 0);
  CHECK(rays > 64 * 16 && hits > 0); /* the paths were really traced */
  kpcn_scene_destroy(s);
}

int main(void) {
  check_scene("cornell-box/scene.json");
  check_scene("depth-discontinuities/scene.json");
  check_scene("envmap-lighting/scene.json");
  check_scene("materialtest/materialtest.json");
  return kt_summary("render_packets");
}
