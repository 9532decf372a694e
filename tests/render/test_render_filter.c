/* Reconstruction filters and the pinhole mapping against analytic truth: a camera looks
 * straight at a half-plane emitter of radiance 1 whose edge falls at a known fractional pixel
 * position; each pixel's value must be the filter's CDF at (edge - pixel centre), i.e.
 * box: clamp(t + 1/2), tent: (1+t)^2/2 | 1-(1-t)^2/2, gaussian exp(-2x^2)-exp(-8) on [-2, 2]
 * (integrated here by a fine midpoint rule). A thin lens focused on the emitter plane must give
 * the same edge whatever its aperture. */
#include "render_testutil.h"
#include "testutil.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>

static double cdf(const char *f, double t) {
  if (f[0] == 'b') return t < -0.5 ? 0.0 : (t > 0.5 ? 1.0 : t + 0.5);
  if (f[0] == 't') {
    if (t <= -1.0) return 0.0;
    if (t >= 1.0) return 1.0;
    return t < 0.0 ? 0.5 * (1.0 + t) * (1.0 + t) : 1.0 - 0.5 * (1.0 - t) * (1.0 - t);
  }
  double num = 0.0, den = 0.0;
  const int n = 40000;
  for (int i = 0; i < n; i++) {
    double x = -2.0 + 4.0 * (i + 0.5) / n;
    double g = fmax(exp(-2.0 * x * x) - exp(-8.0), 0.0);
    den += g;
    if (x < t) num += g;
  }
  return num / den;
}

/* focus < 0: in focus (on the emitter); otherwise the edge must be visibly blurred */
static void check_filter(const char *filter, double aperture, double focus) {
  const int W = 16, H = 2;
  const double fov = 10.0, dist = 10.0, edge_px = 7.3; /* edge between pixel 7's centre and 8 */
  double pd = 1.0 / tan(fov * 3.14159265358979 / 360.0);
  double xndc = edge_px * 2.0 / W - 1.0;
  double e = xndc * dist / pd; /* world x of the edge on the plane z = 0 */
  char json[1024], lens[128] = "";
  if (aperture > 0) /* focused on the emitter plane: the edge must stay exactly as sharp */
    snprintf(lens, sizeof(lens), "\"focus_distance\":%g,\"aperture_size\":%g,",
             focus > 0 ? focus : dist, aperture);
  /* quad (rotation 90 about x faces +z): spans x in [e - 20, e], emits towards the camera */
  snprintf(json, sizeof(json),
           "{\"primitives\":[{\"type\":\"quad\",\"bsdf\":{\"type\":\"null\"},\"emission\":1,"
           "\"transform\":{\"position\":[%.9f,0,0],\"scale\":[20,1,20],\"rotation\":[90,0,0]}}],"
           "\"camera\":{\"type\":\"%s\",%s\"fov\":%g,\"resolution\":[%d,%d],"
           "\"reconstruction_filter\":\"%s\",\"transform\":{\"position\":[0,0,%g],"
           "\"look_at\":[0,0,0],\"up\":[0,1,0]}},\"integrator\":{\"type\":\"path_tracer\"}}",
           e - 10.0, aperture > 0 ? "thinlens" : "pinhole", lens, fov, W, H, filter, dist);
  kpcn_scene *s = NULL;
  CHECK(kpcn_scene_load_json(json, NULL, "filter-test", &s) == KPCN_OK);
  if (!s) {
    fprintf(stderr, "%s\n", kpcn_last_error());
    return;
  }
  kpcn_aov_set *a = rt_render(s, 1024, 1, 0, 0, 0, KPCN_LIGHTS_SCENE, -1);
  CHECK(a != NULL);
  if (a) {
    double maxerr = 0.0;
    for (int px = 0; px < W; px++) {
      double want = cdf(filter, edge_px - (px + 0.5));
      double got = a->buf[KPCN_BUF_COLOR][W + px]; /* row 1, channel R */
      maxerr = kt_worst(maxerr, fabs(got - want));
      if (focus <= 0) CHECK_NEAR(got, want, 3e-3);
    }
    if (focus > 0) CHECK(maxerr > 0.05);
    printf("%-8s filter, aperture %.2f focus %g: max |pixel - analytic CDF| = %.2e\n", filter,
           aperture, focus, maxerr);
  }
  kpcn_aov_destroy(a);
  kpcn_scene_destroy(s);
}

int main(void) {
  check_filter("box", 0.0, -1);
  check_filter("tent", 0.0, -1);
  check_filter("gaussian", 0.0, -1);
  check_filter("tent", 0.5, -1);  /* thin lens focused on the edge */
  check_filter("tent", 0.5, 5.0); /* out of focus: blurred */
  return kt_summary("render_filter");
}
