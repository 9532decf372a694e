/* Warps, piecewise-constant distributions and the environment map: chi-square tests of the
 * samplers against their densities, pdf normalisation by independent quadrature, Tungsten's
 * direction <-> uv convention, and unbiasedness of environment importance sampling. */
#include "bsdf_testlib.h"
#include "chi2.h"
#include "testutil.h"

#include "render/envmap.h"
#include "render/sampling.h"
#include "render/texture.h"

#include <stdlib.h>
#include <string.h>

#define N 300000

/* chi2 of directions against a solid-angle pdf on (cos theta, phi) cells of equal area */
static double dir_chi2_sub(kpcn_vec3 (*gen)(void *, float, float), float (*pdf)(void *, kpcn_vec3),
                           void *ctx, unsigned seed, int SUB) {
  enum { NC = 20, NPH = 40 };
  static double obs[NC * NPH], ex[NC * NPH];
  memset(obs, 0, sizeof(obs));
  kt_rng r = {seed};
  for (int i = 0; i < N; ++i) {
    kpcn_vec3 d = gen(ctx, kt_next(&r), kt_next(&r));
    int ic = (int)((d.z + 1.0f) * 0.5f * NC);
    double ph = atan2(d.y, d.x);
    if (ph < 0) ph += 2 * KPCN_PI;
    int ip = (int)(ph / (2 * KPCN_PI) * NPH);
    ic = ic < 0 ? 0 : (ic >= NC ? NC - 1 : ic);
    ip = ip >= NPH ? NPH - 1 : ip;
    obs[ic * NPH + ip] += 1;
  }
  for (int ic = 0; ic < NC; ++ic)
    for (int ip = 0; ip < NPH; ++ip) {
      double acc = 0;
      for (int a = 0; a < SUB; ++a)
        for (int b = 0; b < SUB; ++b) {
          double z = -1 + 2.0 * (ic + (a + 0.5) / SUB) / NC;
          double ph = 2 * KPCN_PI * (ip + (b + 0.5) / SUB) / NPH;
          double s = sqrt(fmax(0, 1 - z * z));
          acc += pdf(ctx, kv3((float)(s * cos(ph)), (float)(s * sin(ph)), (float)z));
        }
      ex[ic * NPH + ip] = acc / (SUB * SUB) * (4 * KPCN_PI / (NC * NPH)) * N;
    }
  const char *why;
  double p = kt_chi2_test(obs, ex, NC * NPH, 5, &why);
  if (why) printf("  %s\n", why);
  return p;
}
static double dir_chi2(kpcn_vec3 (*gen)(void *, float, float), float (*pdf)(void *, kpcn_vec3),
                       void *ctx, unsigned seed) {
  return dir_chi2_sub(gen, pdf, ctx, seed, 8);
}

static kpcn_vec3 g_cos(void *c, float a, float b) {
  (void)c;
  return kpcn_warp_cosine_hemisphere(a, b);
}
static float p_cos(void *c, kpcn_vec3 w) {
  (void)c;
  return kpcn_warp_cosine_hemisphere_pdf(w);
}
static kpcn_vec3 g_sph(void *c, float a, float b) {
  (void)c;
  return kpcn_warp_uniform_sphere(a, b);
}
static float p_sph(void *c, kpcn_vec3 w) {
  (void)c;
  (void)w;
  return KPCN_INV_4PI;
}
static kpcn_vec3 g_hem(void *c, float a, float b) {
  (void)c;
  return kpcn_warp_uniform_hemisphere(a, b);
}
static float p_hem(void *c, kpcn_vec3 w) {
  (void)c;
  return w.z > 0 ? KPCN_INV_2PI : 0;
}
static kpcn_vec3 g_cone(void *c, float a, float b) {
  return kpcn_warp_uniform_cone(a, b, *(float *)c);
}
static float p_cone(void *c, kpcn_vec3 w) {
  float cm = *(float *)c;
  return w.z >= cm ? kpcn_warp_uniform_cone_pdf(cm) : 0;
}
static kpcn_vec3 g_env(void *c, float a, float b) {
  kpcn_vec3 d, L;
  float pdf;
  if (!kpcn_envmap_sample(c, a, b, &d, &L, &pdf)) return kv3(0, 0, 1);
  return d;
}
static float p_env(void *c, kpcn_vec3 w) { return kpcn_envmap_pdf(c, w); }

/* The cell a distribution's search finds (a guide table, then a short bisection) against a
 * linear scan: the largest i in [0, n-1] with cdf[i] <= u, 0 for NaN. Probed at random u, at
 * every cdf value and the floats beside it, on shapes with zero cells at the ends and in
 * runs, a spike, one cell and an all-zero function. Returns the mismatches. */
static int cell_search_vs_scan(const float *f, int n, unsigned seed) {
  kpcn_distrib1d d;
  if (kpcn_distrib1d_init(&d, f, n) != KPCN_OK) return 1;
  kt_rng r = {seed};
  int bad = 0;
  for (int t = 0; t < 3 * (n + 1) + 2000; ++t) {
    const int j = t / 3 % (n + 1);
    float u = t >= 3 * (n + 1) ? kt_next(&r)
              : t % 3 == 0     ? d.cdf[j]
              : t % 3 == 1     ? nextafterf(d.cdf[j], 0.0f)
                               : nextafterf(d.cdf[j], 2.0f);
    if (u >= 1.0f) u = 0x1.fffffep-1f;
    if (t == 0) u = NAN;
    int want = 0;
    for (int i = 0; i < n; ++i)
      if (d.cdf[i] <= u) want = i;
    float pmf;
    bad += kpcn_distrib1d_sample_discrete(&d, u, &pmf) != want;
  }
  kpcn_distrib1d_free(&d);
  return bad;
}

static void cell_search(void) {
  enum { M = 4096 };
  static float f[M];
  kt_rng r = {11};
  int bad = 0, n;
  const float one = 1.0f, zero = 0.0f;
  bad += cell_search_vs_scan(&one, 1, 1) + cell_search_vs_scan(&zero, 1, 2);
  for (int shape = 0; shape < 6; ++shape) {
    n = shape < 3 ? 1000 : shape == 3 ? M : shape == 4 ? 7 : 33;
    for (int i = 0; i < n; ++i)
      f[i] = shape == 5 ? 0.0f : kt_next(&r) < 0.3f ? 0.0f : kt_next(&r);
    if (shape == 0) /* zero runs at both ends and inside */
      for (int i = 0; i < n; ++i)
        f[i] = i < 100 || i >= 900 || (i >= 400 && i < 600) ? 0.0f : f[i];
    if (shape == 1) f[517] = 1e6f; /* a sun: cells around it hold almost nothing */
    if (shape == 3) f[5] = 1e-9f;  /* a cell narrower than a float step of the cdf */
    bad += cell_search_vs_scan(f, n, 20 + shape);
  }
  printf("distribution cell search vs a linear scan: %d mismatches\n", bad);
  CHECK(bad == 0);
}

int main(void) {
  const double alpha = 0.01 / 10;
  cell_search();
  double p;
  CHECK((p = dir_chi2(g_cos, p_cos, NULL, 1)) > alpha);
  printf("cosine hemisphere p=%.3f\n", p);
  CHECK((p = dir_chi2(g_sph, p_sph, NULL, 2)) > alpha);
  printf("uniform sphere p=%.3f\n", p);
  CHECK((p = dir_chi2(g_hem, p_hem, NULL, 3)) > alpha);
  printf("uniform hemisphere p=%.3f\n", p);
  float cm = 0.7f;
  CHECK((p = dir_chi2(g_cone, p_cone, &cm, 4)) > alpha);
  printf("uniform cone p=%.3f\n", p);
  /* a wrong pdf must be detected: cosine samples against the uniform hemisphere pdf */
  CHECK(dir_chi2(g_cos, p_hem, NULL, 5) < 1e-6);

  /* concentric disk and triangle: uniform area, checked on a grid */
  {
    enum { G = 10 };
    double obs[G * G] = {0}, ex[G * G];
    kt_rng r = {6};
    for (int i = 0; i < N; ++i) {
      float b0, b1;
      kpcn_warp_uniform_triangle(kt_next(&r), kt_next(&r), &b0, &b1);
      CHECK(b0 >= 0 && b1 >= 0 && b0 + b1 <= 1.0001f);
      int x = (int)(b0 * G), y = (int)(b1 * G);
      obs[(y < G ? y : G - 1) * G + (x < G ? x : G - 1)] += 1;
    }
    /* exact area of the triangle b0+b1<=1 inside each grid cell */
    for (int y = 0; y < G; ++y)
      for (int x = 0; x < G; ++x)
        ex[y * G + x] = (x + y < G - 1) ? 1.0 : (x + y == G - 1 ? 0.5 : 0.0);
    for (int i = 0; i < G * G; ++i)
      ex[i] *= (double)N / (G * G / 2.0);
    const char *why;
    CHECK(kt_chi2_test(obs, ex, G * G, 5, &why) > alpha);
    double r2max = 0;
    for (int i = 0; i < 10000; ++i) {
      float x, y;
      kpcn_warp_concentric_disk(kt_next(&r), kt_next(&r), &x, &y);
      r2max = kt_worst(r2max, x * x + y * y);
    }
    CHECK(r2max <= 1.0001);
  }

  /* 1D / 2D distributions */
  {
    float f[7] = {0.5f, 0.0f, 3.0f, 1.0f, 0.0f, 2.0f, 0.25f};
    kpcn_distrib1d d;
    CHECK(kpcn_distrib1d_init(&d, f, 7) == KPCN_OK);
    double obs[7] = {0}, ex[7], tot = 6.75;
    kt_rng r = {7};
    for (int i = 0; i < N; ++i) {
      float pdf;
      int idx;
      float x = kpcn_distrib1d_sample(&d, kt_next(&r), &pdf, &idx);
      CHECK(x >= 0 && x < 1 && idx == (int)(x * 7));
      CHECK_NEAR(pdf, f[idx] * 7 / tot, 1e-5);
      obs[idx] += 1;
    }
    for (int i = 0; i < 7; ++i)
      ex[i] = f[i] / tot * N;
    const char *why;
    CHECK(kt_chi2_test(obs, ex, 7, 5, &why) > alpha);
    CHECK(obs[1] == 0 && obs[4] == 0);
    CHECK_NEAR(kpcn_distrib1d_pdf(&d, 0.3f), 3.0 * 7 / tot, 1e-5);
    float pmf;
    int ii = kpcn_distrib1d_sample_discrete(&d, 0.999f, &pmf);
    CHECK(ii == 6 && fabs(pmf - 0.25 / tot) < 1e-6);
    kpcn_distrib1d_free(&d);
    float z[3] = {0, 0, 0}; /* all-zero -> uniform */
    CHECK(kpcn_distrib1d_init(&d, z, 3) == KPCN_OK);
    CHECK_NEAR(kpcn_distrib1d_pdf(&d, 0.5f), 1.0, 1e-6);
    kpcn_distrib1d_free(&d);
    CHECK(kpcn_distrib1d_init(&d, z, 0) != KPCN_OK);
  }
  {
    enum { NU = 13, NV = 9 };
    float f[NU * NV];
    kt_rng r = {8};
    double tot = 0;
    for (int i = 0; i < NU * NV; ++i) {
      f[i] = kt_next(&r) < 0.2f ? 0.0f : kt_next(&r) * kt_next(&r) * 4;
      tot += f[i];
    }
    for (int u = 0; u < NU; ++u)
      f[4 * NU + u] = 0; /* an empty row */
    tot = 0;
    for (int i = 0; i < NU * NV; ++i)
      tot += f[i];
    kpcn_distrib2d d;
    CHECK(kpcn_distrib2d_init(&d, f, NU, NV) == KPCN_OK);
    double obs[NU * NV] = {0}, ex[NU * NV];
    int badpdf = 0;
    for (int i = 0; i < N; ++i) {
      float u, v, pdf;
      kpcn_distrib2d_sample(&d, kt_next(&r), kt_next(&r), &u, &v, &pdf);
      int iu = (int)(u * NU), iv = (int)(v * NV);
      obs[iv * NU + iu] += 1;
      double want = f[iv * NU + iu] * NU * NV / tot;
      if (fabs(pdf - want) > 1e-4 * want || fabs(kpcn_distrib2d_pdf(&d, u, v) - want) > 1e-4 * want)
        badpdf++;
    }
    CHECK(badpdf == 0);
    for (int i = 0; i < NU * NV; ++i)
      ex[i] = f[i] / tot * N;
    const char *why;
    p = kt_chi2_test(obs, ex, NU * NV, 5, &why);
    printf("distrib2d p=%.3f %s\n", p, why ? why : "");
    CHECK(p > alpha);
    CHECK_NEAR(kpcn_distrib2d_pdf(&d, 0.5f, 4.5f / NV), 0.0, 0.0);
    kpcn_distrib2d_free(&d);
  }

  /* ---- environment map ---- */
  kpcn_texture_cache *tc;
  CHECK(kpcn_texture_cache_create(&tc) == KPCN_OK);
  enum { W = 32, H = 16 };
  float px[W * H * 3];
  kt_rng r = {9};
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x)
      for (int c = 0; c < 3; ++c)
        px[3 * (y * W + x) + c] = 0.05f + 0.1f * kt_next(&r) + (c == 0 ? 0.02f * y : 0);
  for (int c = 0; c < 3; ++c)
    px[3 * (3 * W + 20) + c] = 60.0f; /* a sun */
  px[3 * (12 * W + 5) + 1] = 15.0f;   /* a green light */
  const kpcn_texture *tex;
  CHECK(kpcn_texture_from_pixels(tc, W, H, px, &tex) == KPCN_OK);
  /* rotation: 30 degrees about y and 20 about x */
  float ay = 0.5236f, ax = 0.349f;
  float ry[9] = {cosf(ay), 0, sinf(ay), 0, 1, 0, -sinf(ay), 0, cosf(ay)};
  float rx[9] = {1, 0, 0, 0, cosf(ax), -sinf(ax), 0, sinf(ax), cosf(ax)};
  float rot[9];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      rot[3 * i + j] = 0;
      for (int k = 0; k < 3; ++k)
        rot[3 * i + j] += ry[3 * i + k] * rx[3 * k + j];
    }
  kpcn_envmap *env;
  CHECK(kpcn_envmap_create(tex, rot, 1, &env) == KPCN_OK);
  /* the env pdf is discontinuous at texel edges: integrate the cells finely */
  CHECK((p = dir_chi2_sub(g_env, p_env, env, 10, 48)) > alpha);
  printf("envmap importance sampling p=%.3f\n", p);
  /* pdf integrates to 1 over the sphere, by world-space quadrature */
  {
    double acc = 0;
    const int nt = 800, np = 1600;
    for (int i = 0; i < nt; ++i) {
      double th = (i + 0.5) * KPCN_PI / nt;
      for (int j = 0; j < np; ++j) {
        double ph = (j + 0.5) * 2 * KPCN_PI / np;
        kpcn_vec3 d = kv3((float)(sin(th) * cos(ph)), (float)(sin(th) * sin(ph)), (float)cos(th));
        acc += kpcn_envmap_pdf(env, d) * sin(th);
      }
    }
    acc *= (KPCN_PI / nt) * (2 * KPCN_PI / np);
    printf("envmap pdf integral %.5f\n", acc);
    CHECK_NEAR(acc, 1.0, 2e-3);
  }
  /* importance-sampled estimate of the irradiance-like integral of L equals quadrature */
  {
    double q = 0;
    const int nt = 400, np = 800;
    for (int i = 0; i < nt; ++i) {
      double th = (i + 0.5) * KPCN_PI / nt;
      for (int j = 0; j < np; ++j) {
        double ph = (j + 0.5) * 2 * KPCN_PI / np;
        kpcn_vec3 d = kv3((float)(sin(th) * cos(ph)), (float)(sin(th) * sin(ph)), (float)cos(th));
        q += kpcn_envmap_eval(env, d).y * sin(th);
      }
    }
    q *= (KPCN_PI / nt) * (2 * KPCN_PI / np);
    double s = 0, s2 = 0;
    int badpdf = 0, polediff = 0;
    for (int i = 0; i < N; ++i) {
      kpcn_vec3 d, L;
      float pdf;
      double v = 0;
      if (kpcn_envmap_sample(env, kt_next(&r), kt_next(&r), &d, &L, &pdf)) {
        v = L.y / pdf;
        /* near the poles sin(theta) from v and from the direction differ in float */
        if (fabsf(kpcn_envmap_pdf(env, d) - pdf) > 1e-3f * pdf && fabsf(d.y) < 0.995f) badpdf++;
        kpcn_vec3 Le = kpcn_envmap_eval(env, d);
        /* The sample's radiance is looked up at its texture coordinates, eval's at the (float)
         * direction made from them and rotated back: they may differ by the lookup's change
         * over the direction's float error (~3e-7 rad), which is large in the bilinear skirt
         * of the 60-unit sun. Allowed: the largest change over a 1e-6 rad step. */
        double step = 0;
        for (int a = 0; a < 3; ++a)
          for (int sg = -1; sg <= 1; sg += 2) {
            kpcn_vec3 e = d;
            if (a == 0) e.x += sg * 1e-6f;
            if (a == 1) e.y += sg * 1e-6f;
            if (a == 2) e.z += sg * 1e-6f;
            step = fmax(step, fabs(kpcn_envmap_eval(env, kv3_normalize(e)).y - Le.y));
          }
        /* the pole band: v from the direction and from the sample differ more there */
        if (fabsf(d.y) < 0.995f)
          CHECK_NEAR(L.y, Le.y, 1e-3 * fabs(Le.y) + 1e-6 + step);
        else if (fabs(L.y - Le.y) > 1e-3 * fabs(Le.y) + 1e-6 + step)
          polediff++;
      }
      s += v;
      s2 += v * v;
    }
    printf("envmap pdf mismatches: %d of %d; radiance differing in the pole band: %d\n", badpdf, N,
           polediff);
    CHECK(polediff < N / 1000);
    CHECK(badpdf <= N / 2000); /* float rounding at texel edges only */
    double m = s / N, sig = sqrt((s2 / N - m * m) / N);
    printf("envmap integral: quadrature %.5f, importance %.5f +- %.5f\n", q, m, sig);
    CHECK(fabs(m - q) < 3 * sig + 1e-3 * q);
  }
  kpcn_envmap_destroy(env);
  /* Tungsten's mapping with identity rotation: u = atan2(z,x)/2pi + 0.5, v = acos(-y)/pi */
  CHECK(kpcn_envmap_create(tex, NULL, 0, &env) == KPCN_OK);
  float u, v;
  kpcn_envmap_dir_to_uv(env, kv3(0, 1, 0), &u, &v);
  CHECK_NEAR(v, 1.0, 1e-6); /* zenith = v 1 = top row of the image */
  kpcn_envmap_dir_to_uv(env, kv3(1, 0, 0), &u, &v);
  CHECK_NEAR(u, 0.5, 1e-6);
  CHECK_NEAR(v, 0.5, 1e-6);
  kpcn_envmap_dir_to_uv(env, kv3(0, 0, -1), &u, &v);
  CHECK_NEAR(u, 0.25, 1e-6);
  kpcn_vec3 dd = kpcn_envmap_uv_to_dir(env, 0.8f, 0.3f);
  kpcn_envmap_dir_to_uv(env, dd, &u, &v);
  CHECK_NEAR(u, 0.8, 1e-5);
  CHECK_NEAR(v, 0.3, 1e-5);
  /* near the zenith we see the top row of the image (row 0): texel centre of (5, 0) */
  kpcn_vec3 up = kpcn_envmap_eval(env, kpcn_envmap_uv_to_dir(env, 5.5f / W, 1.0f - 0.5f / H));
  CHECK_NEAR(up.x, px[3 * 5], 1e-4);
  CHECK_NEAR(up.y, px[3 * 5 + 1], 1e-4);
  CHECK(kpcn_envmap_uv_to_dir(env, 5.5f / W, 1.0f - 0.5f / H).y > 0.99f);
  CHECK_NEAR(kpcn_envmap_pdf(env, kv3(0, 1, 0)), KPCN_INV_4PI, 1e-7); /* no importance */
  kpcn_envmap_destroy(env);
  /* A repeating map lit in its bottom row only: lookups in the top row's upper half blend the
   * bottom row in (v wraps), so light sampling must reach those directions too (the pdf's
   * 3x3 dilation clamped v, leaving radiance there with pdf 0) */
  {
    float lit[8 * 4 * 3] = {0};
    for (int i = 3 * 8 * 3; i < 8 * 4 * 3; ++i)
      lit[i] = 1.0f;
    const kpcn_texture *lt;
    kpcn_envmap *le = NULL;
    CHECK(kpcn_texture_from_pixels(tc, 8, 4, lit, &lt) == KPCN_OK &&
          kpcn_envmap_create(lt, NULL, 1, &le) == KPCN_OK);
    if (le) {
      const kpcn_vec3 top = kpcn_envmap_uv_to_dir(le, 0.3f, 1.0f - 0.05f / 4);
      const kpcn_vec3 Lt = kpcn_envmap_eval(le, top);
      printf("bottom-lit map, near the zenith: radiance %.3f, pdf %.4f\n", (double)Lt.y,
             (double)kpcn_envmap_pdf(le, top));
      CHECK(Lt.y > 0.1f && kpcn_envmap_pdf(le, top) > 0.0f);
      kpcn_envmap_destroy(le);
    }
  }
  /* constant background */
  const kpcn_texture *cst;
  CHECK(kpcn_texture_constant(tc, kv3(0.2f, 0.3f, 0.4f), &cst) == KPCN_OK);
  CHECK(kpcn_envmap_create(cst, NULL, 1, &env) == KPCN_OK);
  kpcn_vec3 d, L;
  float pdf;
  CHECK(kpcn_envmap_sample(env, 0.3f, 0.7f, &d, &L, &pdf));
  CHECK_NEAR(pdf, KPCN_INV_4PI, 1e-7);
  CHECK_NEAR(L.z, 0.4, 1e-7);
  CHECK_NEAR(kv3_length(d), 1.0, 1e-6);
  kpcn_envmap_destroy(env);
  kpcn_texture_cache_destroy(tc);
  return kt_summary("render_sampling");
}
