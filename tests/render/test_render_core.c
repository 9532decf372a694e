/* Path tracer properties checked against independent truth:
 *  - determinism: 1 and 2 threads give bit-identical buffers;
 *  - colour = diffuse + specular per pixel (on a glossy/mirror scene);
 *  - camera convention and AOV semantics against analytic ray-plane distances, the scene's
 *    albedos and the walls' known normals (camera space);
 *  - NEE-only, BSDF-only and MIS estimates agree within their variance (area + env light);
 *  - error falls as 1/spp (or faster: the sampler is stratified). */
#include "render_testutil.h"
#include "testutil.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define CORNELL KPCN_TESTDATA "/scenes/cornell-box/scene.json"

static kpcn_scene *load(const char *path) {
  kpcn_scene *s = NULL;
  if (kpcn_scene_load(path, &s) != KPCN_OK) fprintf(stderr, "%s\n", kpcn_last_error());
  return s;
}

static void test_determinism(const kpcn_scene *s) {
  kpcn_aov_set *a = rt_render(s, 8, 42, 1, 48, 48, KPCN_LIGHTS_SCENE, -1);
  kpcn_aov_set *b = rt_render(s, 8, 42, 2, 48, 48, KPCN_LIGHTS_SCENE, -1);
  kpcn_aov_set *c = rt_render(s, 8, 43, 2, 48, 48, KPCN_LIGHTS_SCENE, -1);
  CHECK(a && b && c);
  if (a && b && c) {
    size_t plane = kpcn_aov_plane_size(a);
    for (int k = 0; k < KPCN_BUF_COUNT; k++) {
      size_t n = plane * (size_t)kpcn_buffer_channels((kpcn_buffer)k);
      CHECK(a->buf[k] && a->var[k]);
      CHECK(memcmp(a->buf[k], b->buf[k], n * sizeof(float)) == 0);
      CHECK(memcmp(a->var[k], b->var[k], plane * sizeof(float)) == 0);
    }
    /* a different seed gives a different image */
    CHECK(memcmp(a->buf[KPCN_BUF_COLOR], c->buf[KPCN_BUF_COLOR], 3 * plane * sizeof(float)) != 0);
  }
  kpcn_aov_destroy(a);
  kpcn_aov_destroy(b);
  kpcn_aov_destroy(c);
}

static void test_split(const char *path) {
  kpcn_scene *s = load(path);
  CHECK(s != NULL);
  if (!s) return;
  kpcn_aov_set *a = rt_render(s, 8, 5, 0, 48, 48, KPCN_LIGHTS_SCENE, -1);
  CHECK(a != NULL);
  if (a) {
    size_t n = 3 * kpcn_aov_plane_size(a);
    double maxerr = 0, sd = 0, ss = 0;
    for (size_t i = 0; i < n; i++) {
      double c = a->buf[KPCN_BUF_COLOR][i], d = a->buf[KPCN_BUF_DIFFUSE][i],
             sp = a->buf[KPCN_BUF_SPECULAR][i];
      maxerr = kt_worst(maxerr, fabs(c - (d + sp)) / (1.0 + fabs(c)));
      sd += d, ss += sp;
    }
    printf("%s: max |color - (diffuse+specular)| %.2e, diffuse sum %.1f, specular sum %.1f\n", path,
           maxerr, sd, ss);
    CHECK(maxerr < 1e-5);
    CHECK(sd > 0.0 && ss > 0.0); /* both parts present in a scene with glossy and diffuse */
  }
  kpcn_aov_destroy(a);
  kpcn_scene_destroy(s);
}

/* Camera convention + AOVs: cornell-box at 64x64 (fov 35 horizontal, camera at z=6.8). */
static void test_aovs(const kpcn_scene *s) {
  const int W = 64;
  kpcn_aov_set *a = rt_render(s, 16, 3, 0, W, W, KPCN_LIGHTS_SCENE, -1);
  CHECK(a != NULL);
  if (!a) return;
  size_t plane = kpcn_aov_plane_size(a);
  float pd = 1.0f / tanf(17.5f * 3.14159265f / 180.0f);
  /* back wall pixel (32, 20): analytic distance to z = -1 */
  {
    int px = 32, py = 20;
    size_t i = (size_t)py * W + px;
    double x = -1.0 + (px + 0.5) * 2.0 / W, y = 1.0 - (py + 0.5) * 2.0 / W;
    double len = sqrt(x * x + y * y + (double)pd * pd);
    double depth = 7.8 * len / pd;
    printf("back wall depth %.4f (analytic %.4f), N %.3f %.3f %.3f, albedo %.3f\n",
           a->buf[KPCN_BUF_DEPTH][i], depth, a->buf[KPCN_BUF_NORMAL][i],
           a->buf[KPCN_BUF_NORMAL][plane + i], a->buf[KPCN_BUF_NORMAL][2 * plane + i],
           a->buf[KPCN_BUF_ALBEDO][i]);
    CHECK_NEAR(a->buf[KPCN_BUF_DEPTH][i], depth, 2e-3 * depth);
    CHECK_NEAR(a->buf[KPCN_BUF_NORMAL][i], 0.0, 1e-4);
    CHECK_NEAR(a->buf[KPCN_BUF_NORMAL][plane + i], 0.0, 1e-4);
    CHECK_NEAR(a->buf[KPCN_BUF_NORMAL][2 * plane + i], 1.0, 1e-4);
    CHECK_NEAR(a->buf[KPCN_BUF_ALBEDO][i], 0.725, 1e-5);
    CHECK_NEAR(a->buf[KPCN_BUF_ALBEDO][plane + i], 0.71, 1e-5);
    CHECK_NEAR(a->buf[KPCN_BUF_ALBEDO][2 * plane + i], 0.68, 1e-5);
    CHECK(a->buf[KPCN_BUF_VISIBILITY][i] > 0.5f); /* upper back wall sees the light */
    CHECK(a->var[KPCN_BUF_DEPTH][i] < 1e-3f);
  }
  /* Visibility is a mean of 0/1 over the n <= 16 samples that traced a shadow ray from their
   * feature surface, so each pixel's value is k/n and its variance of the mean the Bernoulli
   * p(1-p)/(n-1) for the same n (Tungsten's visibility.var follows the same formula). */
  {
    int bad = 0, partial = 0;
    for (size_t i = 0; i < plane; i++) {
      const double p = a->buf[KPCN_BUF_VISIBILITY][i], v = a->var[KPCN_BUF_VISIBILITY][i];
      int ok = v == 0.0 && (p == 0.0 || p == 1.0); /* all alike (or one ray, or none) */
      for (int n = 2; n <= 16 && !ok; n++)
        ok = fabs(p * n - round(p * n)) < 1e-4 && fabs(v - p * (1.0 - p) / (n - 1)) < 1e-6;
      for (int n = 2; n < 16 && !partial; n++)
        partial =
            v > 0.0 && fabs(p * n - round(p * n)) < 1e-4 && fabs(p * 16 - round(p * 16)) > 1e-4;
      bad += !ok;
    }
    printf(
        "visibility: %d of %zu pixels not k/n with variance p(1-p)/(n-1); some with n < 16: %s\n",
        bad, plane, partial ? "yes" : "no");
    CHECK(bad == 0);
    CHECK(partial); /* some pixels mix samples that trace one with samples that trace none */
  }
  /* left wall pixel (16, 32): red wall x = -1 faces +x = camera right */
  {
    int px = 16, py = 32;
    size_t i = (size_t)py * W + px;
    double x = -1.0 + (px + 0.5) * 2.0 / W, y = 1.0 - (py + 0.5) * 2.0 / W;
    double len = sqrt(x * x + y * y + (double)pd * pd);
    double depth = (1.0 / -x) * len; /* reaches x = -1 after |1/x| plane units */
    printf("left wall depth %.4f (analytic %.4f), N.X %.3f, albedo.R %.3f\n",
           a->buf[KPCN_BUF_DEPTH][i], depth, a->buf[KPCN_BUF_NORMAL][i],
           a->buf[KPCN_BUF_ALBEDO][i]);
    CHECK_NEAR(a->buf[KPCN_BUF_DEPTH][i], depth, 5e-3 * depth);
    CHECK_NEAR(a->buf[KPCN_BUF_NORMAL][i], 1.0, 1e-4);
    CHECK_NEAR(a->buf[KPCN_BUF_ALBEDO][i], 0.63, 1e-5);
    CHECK_NEAR(a->buf[KPCN_BUF_ALBEDO][2 * plane + i], 0.05, 1e-5);
  }
  /* corner pixel: the ray leaves the open box: miss -> zeros everywhere */
  for (int k = 0; k < KPCN_BUF_COUNT; k++)
    CHECK(a->buf[k][0] == 0.0f);
  /* the bounce limit cuts the light transport, not the features: with max_bounces 0 (direct
   * emission only) albedo, normal and depth are the full render's, bit for bit */
  kpcn_aov_set *z = rt_render(s, 16, 3, 0, W, W, KPCN_LIGHTS_SCENE, 0);
  CHECK(z != NULL);
  if (z) {
    const kpcn_buffer feat[] = {KPCN_BUF_ALBEDO, KPCN_BUF_NORMAL, KPCN_BUF_DEPTH};
    for (int f = 0; f < 3; f++) {
      const int nc = feat[f] == KPCN_BUF_DEPTH ? 1 : 3;
      CHECK(memcmp(z->buf[feat[f]], a->buf[feat[f]], sizeof(float) * nc * plane) == 0);
    }
    kpcn_aov_destroy(z);
  }
  kpcn_aov_destroy(a);
}

/* integrator.min_bounces as Tungsten counts it: light that reaches the camera over fewer than
 * min_bounces surfaces is dropped. With one sample sequence for every setting, per pixel:
 *   min 0 - min 1 = the emitters seen directly (what max_bounces 0 renders),
 *   min 1 - min 2 = the direct lighting (max_bounces 1 less max_bounces 0),
 * and min_bounces past the last surface gives black, the features unchanged. */
/* The cornell box with integrator.min_bounces set (NULL on failure). */
static kpcn_scene *with_min_bounces(int k) {
  cJSON *doc = rt_read_json(CORNELL);
  if (!doc) return NULL;
  cJSON_ReplaceItemInObject(cJSON_GetObjectItem(doc, "integrator"), "min_bounces",
                            cJSON_CreateNumber(k));
  kpcn_scene *s = NULL;
  if (rt_load(doc, KPCN_TESTDATA "/scenes/cornell-box", &s) != KPCN_OK) s = NULL;
  cJSON_Delete(doc);
  return s;
}

static void test_min_bounces(const kpcn_scene *s) {
  const int W = 24, spp = 4;
  kpcn_aov_set *m[3] = {NULL, NULL, NULL},
               *b0 = rt_render(s, spp, 5, 0, W, W, KPCN_LIGHTS_SCENE, 0),
               *b1 = rt_render(s, spp, 5, 0, W, W, KPCN_LIGHTS_SCENE, 1), *none = NULL;
  for (int k = 0; k < 4; k++) {
    kpcn_scene *sk = with_min_bounces(k < 3 ? k : 9); /* 9: past max_bounces 6 */
    CHECK(sk != NULL);
    if (!sk) continue;
    kpcn_aov_set *r = rt_render(sk, spp, 5, 0, W, W, KPCN_LIGHTS_SCENE, 6);
    if (k < 3)
      m[k] = r;
    else
      none = r;
    kpcn_scene_destroy(sk);
  }
  CHECK(m[0] && m[1] && m[2] && b0 && b1 && none);
  if (m[0] && m[1] && m[2] && b0 && b1 && none) {
    const size_t n = 3 * kpcn_aov_plane_size(m[0]);
    const float *c0 = m[0]->buf[KPCN_BUF_COLOR], *c1 = m[1]->buf[KPCN_BUF_COLOR],
                *c2 = m[2]->buf[KPCN_BUF_COLOR], *e = b0->buf[KPCN_BUF_COLOR],
                *d = b1->buf[KPCN_BUF_COLOR];
    double worst = 0, direct = 0, emit = 0;
    int black = 1;
    for (size_t i = 0; i < n; i++) {
      worst = kt_worst(worst, fabs((c0[i] - c1[i]) - e[i]) / (1.0 + e[i]));
      worst = kt_worst(worst, fabs((c1[i] - c2[i]) - (d[i] - e[i])) / (1.0 + d[i]));
      direct += d[i] - e[i], emit += e[i];
      black &= none->buf[KPCN_BUF_COLOR][i] == 0.0f;
    }
    printf("min_bounces: worst decomposition error %.2e (emitters %.3g, direct %.3g in all)\n",
           worst, emit, direct);
    CHECK(worst < 1e-5);
    CHECK(emit > 0 && direct > 0); /* the identities are about something */
    CHECK(black);
    CHECK(memcmp(none->buf[KPCN_BUF_ALBEDO], m[0]->buf[KPCN_BUF_ALBEDO], sizeof(float) * n) == 0);
  }
  for (int k = 0; k < 3; k++)
    kpcn_aov_destroy(m[k]);
  kpcn_aov_destroy(b0), kpcn_aov_destroy(b1), kpcn_aov_destroy(none);
}

/* A mesh without "smooth" is flat-shaded, as in Tungsten (smooth was the default until
 * session 58): the same image as "smooth": false, another than "smooth": true. */
static void test_mesh_smooth_default(void) {
  const char *dir = KPCN_TESTDATA "/scenes/envmap-lighting";
  cJSON *doc = rt_read_json(KPCN_TESTDATA "/scenes/envmap-lighting/scene.json");
  CHECK(doc != NULL);
  if (!doc) return;
  cJSON *mesh = cJSON_GetArrayItem(cJSON_GetObjectItem(doc, "primitives"), 1);
  CHECK(mesh && cJSON_GetObjectItem(mesh, "smooth") != NULL);
  kpcn_aov_set *img[3] = {NULL, NULL, NULL}; /* absent, false, true */
  for (int k = 0; k < 3 && mesh; k++) {
    cJSON_DeleteItemFromObject(mesh, "smooth");
    if (k) cJSON_AddBoolToObject(mesh, "smooth", k == 2);
    kpcn_scene *sc = NULL;
    CHECK(rt_load(doc, dir, &sc) == KPCN_OK);
    if (sc) img[k] = rt_render(sc, 2, 3, 0, 32, 24, KPCN_LIGHTS_SCENE, -1);
    kpcn_scene_destroy(sc);
  }
  CHECK(img[0] && img[1] && img[2]);
  if (img[0] && img[1] && img[2]) {
    const size_t n = sizeof(float) * 3 * kpcn_aov_plane_size(img[0]);
    CHECK(memcmp(img[0]->buf[KPCN_BUF_COLOR], img[1]->buf[KPCN_BUF_COLOR], n) == 0);
    CHECK(memcmp(img[0]->buf[KPCN_BUF_NORMAL], img[2]->buf[KPCN_BUF_NORMAL], n) != 0);
  }
  for (int k = 0; k < 3; k++)
    kpcn_aov_destroy(img[k]);
  cJSON_Delete(doc);
}

/* recompute_normals keeps creases hard, as Tungsten: a cube of 8 shared vertices, smooth with
 * recomputed normals, shades like the flat cube (its faces meet at 90 degrees, past the 27-degree
 * crease limit); averaging every face at a vertex (until session 58) rounded it. */
static void test_mesh_creases(void) {
  const char *obj = kt_tmpfile("cube.obj");
  FILE *f = fopen(obj, "w");
  CHECK(f != NULL);
  if (!f) return;
  fputs("v -0.5 -0.5 -0.5\nv 0.5 -0.5 -0.5\nv 0.5 0.5 -0.5\nv -0.5 0.5 -0.5\n"
        "v -0.5 -0.5 0.5\nv 0.5 -0.5 0.5\nv 0.5 0.5 0.5\nv -0.5 0.5 0.5\n"
        "f 1 3 2\nf 1 4 3\nf 5 6 7\nf 5 7 8\nf 1 2 6\nf 1 6 5\n"
        "f 4 7 3\nf 4 8 7\nf 1 5 8\nf 1 8 4\nf 2 3 7\nf 2 7 6\n",
        f);
  fclose(f);
  cJSON *doc = rt_read_json(KPCN_TESTDATA "/scenes/envmap-lighting/scene.json");
  CHECK(doc != NULL);
  if (!doc) return;
  cJSON *mesh = cJSON_GetArrayItem(cJSON_GetObjectItem(doc, "primitives"), 1);
  cJSON_ReplaceItemInObject(mesh, "file", cJSON_CreateString(obj));
  kpcn_aov_set *img[2] = {NULL, NULL}; /* flat; smooth with recomputed normals */
  for (int k = 0; k < 2; k++) {
    cJSON_DeleteItemFromObject(mesh, "smooth");
    cJSON_DeleteItemFromObject(mesh, "recompute_normals");
    cJSON_AddBoolToObject(mesh, "smooth", k == 1);
    if (k) cJSON_AddBoolToObject(mesh, "recompute_normals", 1);
    kpcn_scene *sc = NULL;
    CHECK(rt_load(doc, KPCN_TESTDATA "/scenes/envmap-lighting", &sc) == KPCN_OK);
    if (sc) img[k] = rt_render(sc, 1, 3, 0, 32, 24, KPCN_LIGHTS_SCENE, -1);
    kpcn_scene_destroy(sc);
  }
  CHECK(img[0] && img[1]);
  if (img[0] && img[1]) {
    const size_t n = 3 * kpcn_aov_plane_size(img[0]);
    double worst = 0, seen = 0;
    for (size_t i = 0; i < n; i++) {
      worst =
          kt_worst(worst, fabs(img[0]->buf[KPCN_BUF_NORMAL][i] - img[1]->buf[KPCN_BUF_NORMAL][i]));
      seen += fabs(img[0]->buf[KPCN_BUF_NORMAL][i]);
    }
    printf("mesh creases: worst normal difference to the flat cube %.2e\n", worst);
    CHECK(seen > 0 && worst < 1e-5);
  }
  kpcn_aov_destroy(img[0]), kpcn_aov_destroy(img[1]);
  cJSON_Delete(doc);
}

/* Renders the JSON scene text (pinhole camera at `cam` looking at the origin, 16x16, a box
 * filter) at 4 spp; NULL on failure. */
static kpcn_aov_set *render_text(const char *prims, const char *cam, kpcn_scene **keep) {
  char buf[4096];
  snprintf(buf, sizeof buf,
           "{\"primitives\": [%s], \"camera\": {\"type\": \"pinhole\", \"resolution\": 16, "
           "\"fov\": 60, \"reconstruction_filter\": \"box\", \"transform\": {\"position\": "
           "%s, \"look_at\": [0, 0, 0], \"up\": [0, 1, 0]}}}",
           prims, cam);
  cJSON *doc = cJSON_Parse(buf);
  CHECK(doc != NULL);
  kpcn_scene *sc = NULL;
  kpcn_aov_set *a = NULL;
  if (doc && rt_load(doc, kt_tmpdir(), &sc) == KPCN_OK)
    a = rt_render(sc, 4, 1, 1, 16, 16, KPCN_LIGHTS_SCENE, -1);
  else
    printf("scene: %s\n", kpcn_last_error());
  cJSON_Delete(doc);
  if (keep)
    *keep = sc;
  else
    kpcn_scene_destroy(sc);
  return a;
}

/* Mean of channel c of buffer b over rows [y0, y1) and columns [x0, x1) of a 16x16 image. */
static double region_mean(const kpcn_aov_set *a, int b, int c, int x0, int x1, int y0, int y1) {
  double s = 0;
  for (int y = y0; y < y1; y++)
    for (int x = x0; x < x1; x++)
      s += a->buf[b][(size_t)c * 256 + (size_t)y * 16 + (size_t)x];
  return s / ((x1 - x0) * (y1 - y0));
}

/* Tungsten's conventions where kpcn differed silently until session 60 (a helper's review):
 * a disk takes its uv in Tungsten's TangentFrame (a disk facing +x was textured turned by 90
 * degrees); a mesh's winding defines its outside (vertex normals against it turned the face);
 * a mesh without texture coordinates has uv (0, 0) everywhere; a constant texture without a
 * value is 0; renderer.spp defaults to 32. */
static void test_tungsten_conventions(void) {
  /* a disk facing +x with a two-cell checker in u: Tungsten's u = atan2(y, z) splits it into
   * a lit top and a dark bottom (the old frame split it left / right) */
  kpcn_aov_set *a = render_text(
      "{\"type\": \"disk\", \"transform\": {\"rotation\": [0, 0, -90]}, \"bsdf\": {\"type\": "
      "\"null\"}, \"emission\": {\"type\": \"checker\", \"on_color\": 1, \"off_color\": 0, "
      "\"res_u\": 2, \"res_v\": 1}}",
      "[3, 0, 0]", NULL);
  CHECK(a != NULL);
  if (a) {
    const double top = region_mean(a, KPCN_BUF_COLOR, 0, 4, 12, 4, 8),
                 bottom = region_mean(a, KPCN_BUF_COLOR, 0, 4, 12, 8, 12),
                 left = region_mean(a, KPCN_BUF_COLOR, 0, 4, 8, 4, 12),
                 right = region_mean(a, KPCN_BUF_COLOR, 0, 8, 12, 4, 12);
    printf("disk facing +x, checker in u: top %.3f bottom %.3f left %.3f right %.3f\n", top, bottom,
           left, right);
    CHECK(top > 0.5 && bottom < 0.05 && fabs(left - right) < 0.05);
  }
  kpcn_aov_destroy(a);
  /* a quad mesh wound towards the camera (+z) whose file's normals point away, emitting 1:
   * seen from the front as in Tungsten (it was dark); without texture coordinates a checker
   * albedo is its value at (0, 0) everywhere (it was laid out per triangle) */
  const char *obj = kt_tmpfile("quad_flipn.obj");
  FILE *f = fopen(obj, "w");
  CHECK(f != NULL);
  if (f) {
    fputs("v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nvn 0 0 -1\n"
          "f 1//1 2//1 3//1\nf 1//1 3//1 4//1\n",
          f);
    fclose(f);
  }
  char prims[1024];
  snprintf(prims, sizeof prims,
           "{\"type\": \"mesh\", \"file\": \"%s\", \"bsdf\": {\"type\": \"null\"}, "
           "\"emission\": 1}",
           obj);
  a = render_text(prims, "[0, 0, 3]", NULL);
  CHECK(a && fabs(region_mean(a, KPCN_BUF_COLOR, 0, 6, 10, 6, 10) - 1.0) < 1e-4);
  kpcn_aov_destroy(a);
  snprintf(prims, sizeof prims,
           "{\"type\": \"mesh\", \"file\": \"%s\", \"bsdf\": {\"type\": \"lambert\", "
           "\"albedo\": {\"type\": \"checker\", \"on_color\": 1, \"off_color\": 0.25, "
           "\"res_u\": 4, \"res_v\": 4}}}, {\"type\": \"infinite_sphere\", \"emission\": 1}",
           obj);
  a = render_text(prims, "[0, 0, -3]", NULL); /* the quad's back: lambert is two-sided */
  CHECK(a != NULL);
  if (a) {
    double lo = 1e9, hi = -1e9;
    for (int y = 5; y < 11; y++)
      for (int x = 5; x < 11; x++) {
        const double v = a->buf[KPCN_BUF_ALBEDO][(size_t)y * 16 + (size_t)x];
        lo = fmin(lo, v), hi = fmax(hi, v);
      }
    printf("mesh without uv, checker albedo: %.4f .. %.4f\n", lo, hi);
    CHECK(hi - lo < 1e-6 && (fabs(lo - 0.25) < 1e-6 || fabs(lo - 1.0) < 1e-6));
  }
  kpcn_aov_destroy(a);
  /* {"type": "constant"} without a value is 0: this quad emits nothing; no renderer block:
   * 32 spp */
  kpcn_scene *sc = NULL;
  a = render_text("{\"type\": \"quad\", \"transform\": {\"rotation\": [90, 0, 0]}, "
                  "\"bsdf\": {\"type\": \"null\"}, \"emission\": {\"type\": \"constant\"}}, "
                  "{\"type\": \"quad\", \"transform\": {\"position\": [0, 0, -1], "
                  "\"scale\": 9, \"rotation\": [90, 0, 0]}, \"bsdf\": {\"type\": \"null\"}, "
                  "\"emission\": 0.5}",
                  "[0, 0, 3]", &sc);
  CHECK(a && sc);
  if (a) CHECK(fabs(region_mean(a, KPCN_BUF_COLOR, 0, 6, 10, 6, 10)) < 1e-6);
  kpcn_scene_info info;
  CHECK(sc && kpcn_scene_get_info(sc, &info) == KPCN_OK && info.spp == 32);
  kpcn_aov_destroy(a);
  kpcn_scene_destroy(sc);
}

/* mean of colour over the image and the standard deviation of that mean */
static void image_mean(const kpcn_aov_set *a, double *m, double *sd) {
  size_t plane = kpcn_aov_plane_size(a);
  double acc = 0, var = 0;
  for (size_t i = 0; i < plane; i++) {
    acc += (a->buf[KPCN_BUF_COLOR][i] + a->buf[KPCN_BUF_COLOR][plane + i] +
            a->buf[KPCN_BUF_COLOR][2 * plane + i]) /
           3.0;
    var += a->var[KPCN_BUF_COLOR][i]; /* channel-averaged: conservative for the channel mean */
  }
  *m = acc / plane;
  *sd = sqrt(var) / plane;
}

static void test_estimators(const char *path, int w, int h, int spp) {
  kpcn_scene *s = load(path);
  CHECK(s != NULL);
  if (!s) return;
  kpcn_light_strategy st[3] = {KPCN_LIGHTS_MIS, KPCN_LIGHTS_NEE_ONLY, KPCN_LIGHTS_BSDF_ONLY};
  const char *nm[3] = {"MIS", "NEE only", "BSDF only"};
  double m[3], sd[3];
  kpcn_aov_set *a[3];
  for (int k = 0; k < 3; k++) {
    a[k] = rt_render(s, spp, 11 + k, 0, w, h, st[k], -1);
    CHECK(a[k] != NULL);
    if (!a[k]) return;
    image_mean(a[k], &m[k], &sd[k]);
    printf("%s %-9s: image mean %.5f +- %.5f\n", path, nm[k], m[k], sd[k]);
  }
  for (int k = 1; k < 3; k++)
    CHECK(fabs(m[k] - m[0]) <= 4.0 * sqrt(sd[k] * sd[k] + sd[0] * sd[0]));
  /* per pixel: few pixels beyond 4 sigma. Only for NEE: BSDF-only hits a small light so rarely
   * (0.3% of the samples at a ceiling pixel of the cornell box) that its per-pixel variance
   * estimate is unreliable at test sample counts; its image mean is checked above. */
  size_t plane = kpcn_aov_plane_size(a[0]);
  for (int k = 1; k < 2; k++) {
    size_t bad = 0;
    for (size_t i = 0; i < plane; i++)
      for (int c = 0; c < 3; c++) {
        double d =
            a[k]->buf[KPCN_BUF_COLOR][c * plane + i] - a[0]->buf[KPCN_BUF_COLOR][c * plane + i];
        double v = a[k]->var[KPCN_BUF_COLOR][i] + a[0]->var[KPCN_BUF_COLOR][i];
        if (d * d > 16.0 * v + 1e-12) bad++;
      }
    printf("  %s vs MIS: %.2f%% pixel channels beyond 4 sigma\n", nm[k],
           100.0 * bad / (3.0 * plane));
    CHECK(bad <= 0.02 * 3 * plane);
  }
  /* MIS is never much worse than the better single strategy */
  double v[3];
  for (int k = 0; k < 3; k++)
    v[k] = rt_mean(a[k]->var[KPCN_BUF_COLOR], plane);
  printf("  mean variance: MIS %.3e NEE %.3e BSDF %.3e\n", v[0], v[1], v[2]);
  CHECK(v[0] <= 1.5 * fmin(v[1], v[2]));
  for (int k = 0; k < 3; k++)
    kpcn_aov_destroy(a[k]);
  kpcn_scene_destroy(s);
}

static void test_convergence(const kpcn_scene *s) {
  const int W = 32;
  kpcn_aov_set *ref = rt_render(s, 4096, 999, 0, W, W, KPCN_LIGHTS_SCENE, -1);
  CHECK(ref != NULL);
  if (!ref) return;
  size_t plane = kpcn_aov_plane_size(ref);
  int spps[3] = {4, 16, 64};
  double e[3];
  for (int k = 0; k < 3; k++) {
    /* average the error over a few seeds so the ratio is stable */
    e[k] = 0;
    for (int seed = 0; seed < 4; seed++) {
      kpcn_aov_set *a = rt_render(s, spps[k], 100 + seed, 0, W, W, KPCN_LIGHTS_SCENE, -1);
      CHECK(a != NULL);
      if (!a) return;
      e[k] += rt_relmse(a->buf[KPCN_BUF_COLOR], ref->buf[KPCN_BUF_COLOR], plane) / 4;
      kpcn_aov_destroy(a);
    }
    printf("spp %3d: relMSE %.4e\n", spps[k], e[k]);
  }
  /* 4x the samples: Monte Carlo gives 4x less error, stratification may give more */
  for (int k = 0; k < 2; k++) {
    double r = e[k] / e[k + 1];
    printf("ratio %d->%d spp: %.2f\n", spps[k], spps[k + 1], r);
    CHECK(r > 3.0 && r < 12.0);
  }
  kpcn_aov_destroy(ref);
}

/* The variance buffers against the spread of independent renders: each buffer's reported
 * variance of the pixel mean (its samples' variance / spp), summed over the image, against the
 * variance of that pixel's value across NSEED seeds. Every test tolerance built on var (furnace,
 * estimators, Tungsten) relies on it. The sampler stratifies (Owen-scrambled Sobol), so a render
 * varies less than independent samples would: the reported figure may only be larger, and not
 * by the spp factor (16) a variance left undivided would give. Measured (48 seeds): colour 2.9,
 * diffuse 1.5; over six sets of 48 seeds colour 2.54-3.00, diffuse 1.47-1.58, hence the upper
 * bounds 4 and 2 (a variance 1.4x too large fails). The ratio is above 1 because the pairs of
 * the camera and the first two bounces are stratified per pixel while the buffer is the
 * i.i.d. estimate; colour gains more than diffuse through its directly seen light, whose only
 * randomness is the stratified pixel position. Where nothing is stratified the ratio is 1:
 * test_render_furnace pins the buffer to 1 +- 0.05 on a box whose only randomness is Russian
 * roulette. The first-hit features (albedo 9.3, normal 6.8) integrate smooth pixel-coverage
 * functions, where stratification gains about the spp factor itself, so for them the test
 * could not tell that gain from the bug; they are printed, not checked. */
static void test_variance_calibration(const kpcn_scene *s) {
  enum { NSEED = 48, W = 16, H = 16, SPP = 16 };
  const int bufs[] = {KPCN_BUF_COLOR, KPCN_BUF_DIFFUSE, KPCN_BUF_ALBEDO, KPCN_BUF_NORMAL};
  const char *names[] = {"color", "diffuse", "albedo", "normal"};
  const size_t P = (size_t)W * H;
  double *sum = calloc(4 * 3 * P, sizeof(double)), *sq = calloc(4 * 3 * P, sizeof(double));
  double rep[4] = {0};
  for (int seed = 0; seed < NSEED; seed++) {
    kpcn_aov_set *a = rt_render(s, SPP, 500 + seed, 0, W, H, KPCN_LIGHTS_SCENE, -1);
    CHECK(a != NULL);
    if (!a) break;
    for (int k = 0; k < 4; k++) {
      for (size_t i = 0; i < 3 * P; i++) {
        const double v = a->buf[bufs[k]][i];
        sum[k * 3 * P + i] += v;
        sq[k * 3 * P + i] += v * v;
      }
      for (size_t i = 0; i < P; i++)
        rep[k] += a->var[bufs[k]][i] / NSEED;
    }
    kpcn_aov_destroy(a);
  }
  for (int k = 0; k < 4; k++) {
    double emp = 0; /* per pixel: the channel mean of the across-seed variance */
    for (size_t i = 0; i < 3 * P; i++) {
      const double m = sum[k * 3 * P + i] / NSEED;
      emp += (sq[k * 3 * P + i] / NSEED - m * m) * NSEED / (NSEED - 1) / 3.0;
    }
    const double r = rep[k] / emp;
    printf("variance calibration %-8s: reported / measured across %d seeds = %.3f\n", names[k],
           NSEED, r);
    if (k < 2) CHECK(r > 0.8 && r < (k == 0 ? 4.0 : 2.0));
  }
  free(sum);
  free(sq);
}

/* settings.albedo_spp: the albedo pass traces the first albedo_spp samples of the colour
 * pass's own sequence features-only, so its albedo and variance equal, bit for bit, those of a
 * full render at albedo_spp (delta bounces to the feature surface included: a glass scene),
 * every other buffer is the spp render's, the header records it, and its albedo is closer to
 * a converged one than the colour pass's; bad values are refused. */
static void test_albedo_pass(const char *path) {
  kpcn_scene *s = load(path);
  CHECK(s != NULL);
  if (!s) return;
  kpcn_render_settings st = kpcn_render_settings_defaults();
  st.width = 40, st.height = 32, st.nthreads = 2, st.seed = 9;
  kpcn_aov_set *lo = NULL, *hi = NULL, *both = NULL, *conv = NULL;
  st.spp = 8;
  CHECK(kpcn_render(s, &st, &lo) == KPCN_OK);
  st.albedo_spp = 48;
  CHECK(kpcn_render(s, &st, &both) == KPCN_OK);
  st.albedo_spp = 0, st.spp = 48;
  CHECK(kpcn_render(s, &st, &hi) == KPCN_OK);
  st.spp = 8, st.albedo_spp = 2048;
  CHECK(kpcn_render(s, &st, &conv) == KPCN_OK);
  if (lo && hi && both && conv) {
    const size_t plane = kpcn_aov_plane_size(lo);
    CHECK(both->spp == 8 && both->albedo_spp == 48 && lo->albedo_spp == 0);
    int same_other = 1;
    for (int b = 0; b < KPCN_BUF_COUNT; b++) {
      if (b == KPCN_BUF_ALBEDO) continue;
      const size_t n = plane * (size_t)kpcn_buffer_channels((kpcn_buffer)b);
      same_other &= !memcmp(both->buf[b], lo->buf[b], n * sizeof(float)) &&
                    !memcmp(both->var[b], lo->var[b], plane * sizeof(float));
    }
    CHECK(same_other);
    CHECK(!memcmp(both->buf[KPCN_BUF_ALBEDO], hi->buf[KPCN_BUF_ALBEDO], 3 * plane * sizeof(float)));
    CHECK(!memcmp(both->var[KPCN_BUF_ALBEDO], hi->var[KPCN_BUF_ALBEDO], plane * sizeof(float)));
    double e8 = 0, e48 = 0;
    for (size_t i = 0; i < 3 * plane; i++) {
      const double r = conv->buf[KPCN_BUF_ALBEDO][i];
      e8 += (lo->buf[KPCN_BUF_ALBEDO][i] - r) * (lo->buf[KPCN_BUF_ALBEDO][i] - r);
      e48 += (both->buf[KPCN_BUF_ALBEDO][i] - r) * (both->buf[KPCN_BUF_ALBEDO][i] - r);
    }
    printf("%s: albedo pass of 48 == a 48-spp render's albedo; albedo MSE vs 2048 samples: 8 spp "
           "%.3g, 48 %.3g\n",
           path, e8 / (3 * plane), e48 / (3 * plane));
    CHECK(e8 > 0 && e48 < 0.5 * e8); /* edges exist, and more samples resolve them */
    /* the header keeps it */
    kpcn_aov_set *rd = rt_exr_roundtrip(both, kt_tmpfile("albedo_pass.exr"));
    CHECK(rd && rd->albedo_spp == 48 && rd->spp == 8);
    kpcn_aov_destroy(rd);
  }
  kpcn_aov_set *bad = NULL;
  st.spp = 8, st.albedo_spp = 4; /* fewer than the colour's */
  CHECK(kpcn_render(s, &st, &bad) == KPCN_ERR_INVALID_ARGUMENT && !bad);
  CHECK(strstr(kpcn_last_error(), "albedo_spp") != NULL);
  st.albedo_spp = 16, st.color_only = 1; /* no albedo buffer to fill */
  CHECK(kpcn_render(s, &st, &bad) == KPCN_ERR_INVALID_ARGUMENT && !bad);
  kpcn_aov_destroy(lo), kpcn_aov_destroy(hi), kpcn_aov_destroy(both), kpcn_aov_destroy(conv);
  kpcn_scene_destroy(s);
}

/* Two-sided shading flips the frame where the shading normal faces away from the viewer, as
 * Tungsten does (it was decided by the geometric normal): one triangle facing +z whose vertex
 * normals lean to +x, seen from -x and above (45 degrees), under a white environment. Its shading
 * normal faces away from the camera while its face does not; Lambert albedo 0.5 shaded with the
 * flipped frame is lit (about 0.5 · the upper hemisphere), where it rendered black. */
static void test_backface_by_shading_normal(void) {
  FILE *f = fopen(kt_tmpfile("leaning.obj"), "w");
  CHECK(f != NULL);
  if (!f) return;
  fputs("v -1 -1 0\nv 1 -1 0\nv 0 1 0\nvn 0.98058 0 0.19612\nvn 0.98058 0 0.19612\n"
        "vn 0.98058 0 0.19612\nf 1//1 2//2 3//3\n",
        f);
  fclose(f);
  kpcn_aov_set *a =
      render_text("{\"type\": \"mesh\", \"file\": \"leaning.obj\", \"smooth\": true, \"bsdf\": "
                  "{\"type\": \"lambert\", \"albedo\": 0.5}}, {\"type\": \"infinite_sphere\", "
                  "\"emission\": 1}",
                  "[-3, 0, 3]", NULL);
  CHECK(a != NULL);
  if (!a) return;
  double sum = 0;
  int n = 0;
  for (size_t i = 0; i < 256; i++)
    if (fabsf(a->buf[KPCN_BUF_ALBEDO][i] - 0.5f) < 1e-6f) /* the triangle's pixels */
      sum += a->buf[KPCN_BUF_COLOR][i], n++;
  printf("triangle whose shading normal faces away: %d pixels, mean red %.3f\n", n,
         n ? sum / n : 0.0);
  CHECK(n >= 4 && sum / n > 0.2);
  kpcn_aov_destroy(a);
}

int main(void) {
  test_albedo_pass(KPCN_TESTDATA "/scenes/glass-caustics/scene.json");
  test_albedo_pass(KPCN_TESTDATA "/scenes/textures/scene.json");
  kpcn_scene *cb = load(CORNELL);
  CHECK(cb != NULL);
  if (!cb) return kt_summary("render_core");
  test_determinism(cb);
  test_aovs(cb);
  test_min_bounces(cb);
  test_mesh_smooth_default();
  test_mesh_creases();
  test_tungsten_conventions();
  test_backface_by_shading_normal();
  test_split(KPCN_TESTDATA "/scenes/glossy-mirror/scene.json");
  test_estimators(CORNELL, 32, 32, 256);
  test_estimators(KPCN_TESTDATA "/scenes/sky-plastics/scene.json", 32, 24, 128);
  test_estimators(KPCN_TESTDATA "/scenes/glossy-mirror/scene.json", 32, 32, 256);
  /* textured emitters (bitmap quad, checker disk): NEE must look emission up where BSDF hits do */
  test_estimators(KPCN_TESTDATA "/scenes/textured-emitters/scene.json", 32, 24, 256);
  test_convergence(cb);
  test_variance_calibration(cb);
  kpcn_scene_destroy(cb);
  return kt_summary("render_core");
}
