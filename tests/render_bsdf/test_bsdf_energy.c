/* White-furnace / energy tests, Fresnel closed forms and reciprocity.
 * Truths used: analytic normalisation of D and the weak white furnace of Smith G1 (Heitz 2014),
 * the closed-form normal-incidence Fresnel of dielectrics and conductors, the identity
 * eta^2 (1 - F_external_avg) = 1 - F_internal_avg that makes white smooth plastic conserve
 * energy exactly, Monte Carlo estimates with uniform sampling (independent of sample()), and
 * the F = 1 rough conductor's albedo by quadrature of D and G written here from Walter 2007. */
#include "bsdf_testlib.h"
#include "testutil.h"

#include "render/fresnel.h"
#include "render/microfacet.h"
#include "render/texture.h"

#include <stdlib.h>

static const kpcn_shading_point k_sp = {0.5f, 0.5f};

typedef struct {
  double mean, sigma;
} est;

/* Albedo (channel 0) by uniform sphere sampling of eval(): independent of sample(). */
static est albedo_uniform(const kpcn_bsdf *b, kpcn_vec3 wo, int n, unsigned seed) {
  kt_rng r = {seed};
  double s = 0, s2 = 0;
  for (int i = 0; i < n; ++i) {
    kpcn_vec3 wi = kpcn_warp_uniform_sphere(kt_next(&r), kt_next(&r));
    kpcn_bsdf_eval_result e;
    kpcn_bsdf_eval(b, &k_sp, wo, wi, &e);
    double v = e.f_cos.x * 4.0 * KPCN_PI;
    s += v;
    s2 += v * v;
  }
  est o = {s / n, sqrt(fmax(s2 / n - (s / n) * (s / n), 0.0) / n)};
  return o;
}
/* Albedo from sample() weights (delta lobes included). */
static est albedo_sampled(const kpcn_bsdf *b, kpcn_vec3 wo, int n, unsigned seed) {
  kt_rng r = {seed};
  double s = 0, s2 = 0;
  for (int i = 0; i < n; ++i) {
    kpcn_bsdf_sample_result x;
    double v = 0;
    if (kpcn_bsdf_sample(b, &k_sp, wo, kt_next(&r), kt_next(&r), kt_next(&r), &x)) v = x.weight.x;
    s += v;
    s2 += v * v;
  }
  est o = {s / n, sqrt(fmax(s2 / n - (s / n) * (s / n), 0.0) / n)};
  return o;
}

static kpcn_bsdf *mk(kpcn_bsdf_params *p) {
  kpcn_bsdf *b = NULL;
  if (kpcn_bsdf_create(p, &b) != KPCN_OK) {
    fprintf(stderr, "create: %s\n", kpcn_last_error());
    exit(1);
  }
  return b;
}

/* Quadrature over the hemisphere of m (theta, phi midpoint rule, fine enough for alpha>=0.1) */
static double mf_integral(kpcn_microfacet_dist d, float alpha, kpcn_vec3 wo, int weak) {
  const int nt = 2000, np = 400;
  double acc = 0;
  for (int i = 0; i < nt; ++i) {
    double th = (i + 0.5) * (KPCN_PI / 2) / nt;
    for (int j = 0; j < np; ++j) {
      double ph = (j + 0.5) * 2 * KPCN_PI / np;
      kpcn_vec3 m = kv3((float)(sin(th) * cos(ph)), (float)(sin(th) * sin(ph)), (float)cos(th));
      double D = kpcn_mf_D(d, alpha, m);
      double v =
          weak ? D * kpcn_mf_G1(d, alpha, wo, m) * fmax(kv3_dot(wo, m), 0.0f) / wo.z : D * m.z;
      acc += v * sin(th);
    }
  }
  return acc * (KPCN_PI / 2 / nt) * (2 * KPCN_PI / np);
}

/* ---- independent albedo of a rough conductor with F = 1 ----
 * Written from Walter et al. 2007 in double precision, calling none of the library's microfacet
 * code: D of GGX (eq. 33) and Beckmann (eq. 25), Smith G1 of GGX (eq. 34, exact) and Walter's
 * rational approximation of Beckmann's (eq. 27, the one the library documents), G = G1(wi)G1(wo)
 * (eq. 23), alpha = max(roughness, 1e-3) (Tungsten's convention, docs/materials.md). */
static double ref_alpha(double roughness) { return roughness > 1e-3 ? roughness : 1e-3; }
static double ref_D(int ggx, double a, double cm) {
  if (cm <= 0) return 0;
  double c2 = cm * cm, a2 = a * a;
  if (ggx) {
    double q = c2 * (a2 - 1) + 1; /* q^2 = cos^4 (a^2 + tan^2)^2 */
    return a2 / (KPCN_PI * q * q);
  }
  return exp((c2 - 1) / (c2 * a2)) / (KPCN_PI * a2 * c2 * c2);
}
/* G1 of direction v (cos vn with the normal, cos vm with the microfacet normal) */
static double ref_G1(int ggx, double a, double vn, double vm) {
  if (vm / vn <= 0) return 0;
  double t2 = fmax(1 - vn * vn, 0) / (vn * vn);
  if (ggx) return 2 / (1 + sqrt(1 + a * a * t2));
  if (t2 == 0) return 1;
  double b = 1 / (a * sqrt(t2));
  return b < 1.6 ? (3.535 * b + 2.181 * b * b) / (1 + 2.276 * b + 2.577 * b * b) : 1;
}
/* int_{wi.z > 0} D(h) G(wi, wo, h) / (4 cos theta_o) d wi: midpoint rule on an nt x (4 nt)
 * (theta_i, phi_i) grid. */
static double ref_albedo(int ggx, double roughness, kpcn_vec3 wo, int nt) {
  const int np = 4 * nt;
  double a = ref_alpha(roughness), o[3] = {wo.x, wo.y, wo.z}, acc = 0;
  for (int i = 0; i < nt; ++i) {
    double th = (i + 0.5) * (KPCN_PI / 2) / nt, st = sin(th), ct = cos(th);
    for (int j = 0; j < np; ++j) {
      double ph = (j + 0.5) * 2 * KPCN_PI / np;
      double w[3] = {st * cos(ph), st * sin(ph), ct}, h[3], hl = 0;
      for (int c = 0; c < 3; ++c)
        h[c] = w[c] + o[c], hl += h[c] * h[c];
      hl = sqrt(hl);
      for (int c = 0; c < 3; ++c)
        h[c] /= hl;
      double oh = o[0] * h[0] + o[1] * h[1] + o[2] * h[2];
      double ih = w[0] * h[0] + w[1] * h[1] + w[2] * h[2];
      double G = ref_G1(ggx, a, ct, ih) * ref_G1(ggx, a, o[2], oh);
      acc += ref_D(ggx, a, h[2]) * G / (4 * o[2]) * st;
    }
  }
  return acc * (KPCN_PI / 2 / nt) * (2 * KPCN_PI / np);
}

int main(void) {
  /* ---- microfacet normalisation and weak white furnace ---- */
  kpcn_microfacet_dist dists[] = {KPCN_MF_GGX, KPCN_MF_BECKMANN};
  for (int di = 0; di < 2; ++di) {
    for (float a = 0.1f; a < 0.7f; a += 0.25f) {
      CHECK_NEAR(mf_integral(dists[di], a, kv3(0, 0, 1), 0), 1.0, 2e-3);
      for (float th = 0.0f; th < 1.4f; th += 0.6f) {
        kpcn_vec3 wo = kv3(sinf(th), 0, cosf(th));
        /* exact for GGX; Walter's rational G1 for Beckmann is accurate to ~0.5% */
        CHECK_NEAR(mf_integral(dists[di], a, wo, 1), 1.0, dists[di] == KPCN_MF_GGX ? 3e-3 : 1e-2);
      }
    }
  }

  /* ---- Fresnel closed forms at normal incidence ---- */
  CHECK_NEAR(kpcn_fresnel_dielectric(1.0f / 1.5f, 1.0f, NULL), 0.04, 1e-6);
  CHECK_NEAR(kpcn_fresnel_dielectric(1.5f, -1.0f, NULL), 0.04, 1e-6); /* flipped side */
  {
    float ct;
    CHECK_NEAR(kpcn_fresnel_dielectric(1.5f, 0.5f, &ct), 1.0, 0.0); /* TIR: sin_t > 1 */
    CHECK_NEAR(ct, 0.0, 0.0);
    float ci = cosf(0.5f);
    kpcn_fresnel_dielectric(1.0f / 1.5f, ci, &ct); /* Snell */
    CHECK_NEAR(sqrtf(1 - ct * ct), sinf(0.5f) / 1.5f, 1e-6);
  }
  kpcn_vec3 eta, k;
  const char *metals[] = {"Cu", "Au", "Ag", "Al", "Cr", "W", "Cu_palik", "Ni_palik", "Ir_palik"};
  for (size_t i = 0; i < sizeof(metals) / sizeof(metals[0]); ++i) {
    CHECK(kpcn_conductor_lookup(metals[i], &eta, &k));
    for (int c = 0; c < 3; ++c) {
      double n = kv3_get(eta, c), kk = kv3_get(k, c);
      double f0 = ((n - 1) * (n - 1) + kk * kk) / ((n + 1) * (n + 1) + kk * kk);
      CHECK_NEAR(kpcn_fresnel_conductor(kv3_get(eta, c), kv3_get(k, c), 1.0f), f0, 1e-5);
    }
  }
  CHECK(!kpcn_conductor_lookup("Unobtainium", &eta, &k));
  /* a "_palik" twin only where Tungsten has one (Ir_palik is Ir's values); none for gold, and
   * no double suffix */
  kpcn_vec3 eta2, k2;
  CHECK(kpcn_conductor_lookup("Ir", &eta2, &k2) && kpcn_conductor_lookup("Ir_palik", &eta, &k) &&
        eta.x == eta2.x && k.z == k2.z);
  const char *no_twin[] = {"Au_palik",  "Ag_palik",       "Al_palik", "Cr_palik", "W_palik",
                           "a-C_palik", "Cu_palik_palik", "_palik",   "Na"};
  for (size_t i = 0; i < sizeof no_twin / sizeof no_twin[0]; ++i)
    CHECK(!kpcn_conductor_lookup(no_twin[i], &eta, &k));
  CHECK(kpcn_conductor_lookup("Au", &eta, &k));
  kpcn_vec3 fau = kpcn_fresnel_conductor3(eta, k, 1.0f);
  CHECK(fau.x > fau.z + 0.3f);                                     /* gold is yellow */
  CHECK_NEAR(kpcn_fresnel_conductor(0.0f, 1.0f, 0.3f), 1.0, 1e-6); /* eta=0: perfect mirror */

  /* ---- lambert furnace ---- */
  kpcn_bsdf_params p;
  kpcn_bsdf_params_defaults(&p, KPCN_BSDF_LAMBERT);
  kpcn_bsdf *lam = mk(&p);
  est e = albedo_uniform(lam, kt_dir(40, 0), 400000, 11);
  printf("lambert: uniform %.5f +- %.5f\n", e.mean, e.sigma);
  CHECK(fabs(e.mean - 1.0) < 3 * e.sigma);
  e = albedo_sampled(lam, kt_dir(40, 0), 1000, 12);
  CHECK_NEAR(e.mean, 1.0, 1e-6);

  /* ---- rough conductor with F = 1 ---- */
  float rough[] = {0.05f, 0.2f, 0.5f};
  for (int di = 0; di < 2; ++di)
    for (int ri = 0; ri < 3; ++ri) {
      kpcn_bsdf_params_defaults(&p, KPCN_BSDF_ROUGH_CONDUCTOR);
      p.eta = kv3s(0.0f);
      p.k = kv3s(1.0f);
      p.distribution = dists[di];
      p.roughness_value = rough[ri];
      kpcn_bsdf *b = mk(&p);
      for (float th = 0; th < 80; th += 35) {
        est u = albedo_uniform(b, kt_dir(th, 30), 400000, 100 + ri);
        est s = albedo_sampled(b, kt_dir(th, 30), 200000, 200 + ri);
        double tol = 3 * sqrt(u.sigma * u.sigma + s.sigma * s.sigma);
        printf("rough_conductor F=1 %s r=%.2f th=%2.0f: uniform %.4f+-%.4f sampled %.4f+-%.4f\n",
               di ? "beckmann" : "ggx", rough[ri], th, u.mean, u.sigma, s.mean, s.sigma);
        CHECK(fabs(u.mean - s.mean) < tol);
        CHECK(s.mean < 1.0 + 3 * s.sigma + 1e-5); /* single scattering can only lose energy */
        if (rough[ri] <= 0.05f && th < 50) CHECK(s.mean > 0.98); /* nearly smooth: ~no loss */
        if (rough[ri] >= 0.2f) { /* against the independent quadrature (and its convergence) */
          double q = ref_albedo(di == 0, rough[ri], kt_dir(th, 30), 256);
          double q2 = ref_albedo(di == 0, rough[ri], kt_dir(th, 30), 512);
          printf("  quadrature %.5f (doubled grid %.5f): sampled - quadrature %+.4f\n", q, q2,
                 s.mean - q);
          CHECK(fabs(q - q2) < 2e-4);
          CHECK(fabs(s.mean - q) < 3 * s.sigma + 5e-3 * q);
        }
      }
      kpcn_bsdf_destroy(b);
    }

  /* ---- white smooth plastic conserves energy exactly ---- */
  kpcn_bsdf_params_defaults(&p, KPCN_BSDF_PLASTIC);
  kpcn_bsdf *pl = mk(&p);
  for (float th = 0; th < 85; th += 20) {
    est s = albedo_sampled(pl, kt_dir(th, 0), 400000, 300);
    printf("plastic white: th=%2.0f sampled %.5f +- %.5f\n", th, s.mean, s.sigma);
    CHECK(fabs(s.mean - 1.0) < 3 * s.sigma + 2e-3);
  }
  /* ---- rough plastic energy <= 1 ---- */
  kpcn_bsdf_params_defaults(&p, KPCN_BSDF_ROUGH_PLASTIC);
  p.roughness_value = 0.3f;
  kpcn_bsdf *rp = mk(&p);
  for (float th = 0; th < 85; th += 20) {
    est u = albedo_uniform(rp, kt_dir(th, 0), 400000, 400);
    est s = albedo_sampled(rp, kt_dir(th, 0), 200000, 401);
    printf("rough_plastic white: th=%2.0f uniform %.4f+-%.4f sampled %.4f+-%.4f\n", th, u.mean,
           u.sigma, s.mean, s.sigma);
    CHECK(u.mean < 1.0 + 3 * u.sigma);
    CHECK(fabs(u.mean - s.mean) < 3 * sqrt(u.sigma * u.sigma + s.sigma * s.sigma));
  }
  /* ---- nearly smooth rough plastic: the white smooth plastic's albedo of 1 (above), less
   * little; a lower anchor that an eval and a sampling weight scaled alike cannot pass ---- */
  p.roughness_value = 0.02f;
  kpcn_bsdf *rp0 = mk(&p);
  for (float th = 0; th < 50; th += 20) {
    est s = albedo_sampled(rp0, kt_dir(th, 0), 200000, 410);
    printf("rough_plastic white r=0.02: th=%2.0f sampled %.4f+-%.4f\n", th, s.mean, s.sigma);
    CHECK(s.mean > 0.97 && s.mean < 1.0 + 3 * s.sigma);
  }
  kpcn_bsdf_destroy(rp0);
  /* ---- rough dielectric energy <= 1 from both sides ---- */
  kpcn_bsdf_params_defaults(&p, KPCN_BSDF_ROUGH_DIELECTRIC);
  p.roughness_value = 0.2f;
  kpcn_bsdf *rd = mk(&p);
  float ths[] = {10, 60, 170, 130};
  for (int i = 0; i < 4; ++i) {
    est u = albedo_uniform(rd, kt_dir(ths[i], 0), 400000, 500 + i);
    est s = albedo_sampled(rd, kt_dir(ths[i], 0), 200000, 600 + i);
    printf("rough_dielectric: th=%3.0f uniform %.4f+-%.4f sampled %.4f+-%.4f\n", ths[i], u.mean,
           u.sigma, s.mean, s.sigma);
    CHECK(s.mean < 1.0 + 3 * s.sigma);
    CHECK(fabs(u.mean - s.mean) < 3 * sqrt(u.sigma * u.sigma + s.sigma * s.sigma));
  }
  /* nearly smooth: reflection + transmission keep almost all the energy (smooth: exactly) */
  p.roughness_value = 0.02f;
  kpcn_bsdf *rd0 = mk(&p);
  for (int i = 0; i < 4; ++i) {
    est s = albedo_sampled(rd0, kt_dir(ths[i], 0), 200000, 700 + i);
    printf("rough_dielectric r=0.02: th=%3.0f sampled %.4f+-%.4f\n", ths[i], s.mean, s.sigma);
    if (ths[i] < 50 || ths[i] > 150) CHECK(s.mean > 0.97);
  }
  kpcn_bsdf_destroy(rd0);
  /* ---- smooth dielectric: reflection probability = Fresnel, refraction obeys Snell ---- */
  kpcn_bsdf_params_defaults(&p, KPCN_BSDF_DIELECTRIC);
  kpcn_bsdf *di = mk(&p);
  {
    kt_rng r = {77};
    int n = 200000, nrefl = 0, nfail = 0;
    for (int i = 0; i < n; ++i) {
      kpcn_bsdf_sample_result x;
      if (!kpcn_bsdf_sample(di, &k_sp, kv3(0, 0, 1), kt_next(&r), kt_next(&r), kt_next(&r), &x))
        nfail++;
      else if (x.wi.z > 0)
        nrefl++;
    }
    CHECK(nfail == 0);
    double f = (double)nrefl / n, sig = sqrt(0.04 * 0.96 / n);
    CHECK(fabs(f - 0.04) < 3 * sig);
    kpcn_bsdf_sample_result x;
    kpcn_vec3 wo = kt_dir(50, 20);
    CHECK(kpcn_bsdf_sample(di, &k_sp, wo, 0.5f, 0.5f, 0.999f, &x));
    CHECK(x.wi.z < 0);
    CHECK_NEAR(sqrtf(x.wi.x * x.wi.x + x.wi.y * x.wi.y), sinf(50 * KPCN_PI / 180) / 1.5f, 1e-5);
    CHECK(x.is_delta && (x.lobe & KPCN_LOBE_TRANSMISSION));
  }

  /* ---- reciprocity f(wo,wi) = f(wi,wo) for the reflective bsdfs ---- */
  kpcn_bsdf_params_defaults(&p, KPCN_BSDF_ROUGH_CONDUCTOR);
  p.roughness_value = 0.3f;
  kpcn_bsdf *rc = mk(&p);
  kpcn_bsdf_params_defaults(&p, KPCN_BSDF_SMOOTH_COAT);
  p.substrate = rc;
  p.sigma_a = kv3(0.2f, 0.1f, 0.0f);
  kpcn_bsdf *coat = mk(&p);
  const kpcn_bsdf *recip[] = {lam, rc, pl, rp, rd, coat};
  kt_rng r = {99};
  int bad = 0;
  for (size_t bi = 0; bi < sizeof(recip) / sizeof(recip[0]); ++bi)
    for (int i = 0; i < 2000; ++i) {
      kpcn_vec3 a = kpcn_warp_uniform_hemisphere(kt_next(&r), kt_next(&r));
      kpcn_vec3 c = kpcn_warp_uniform_hemisphere(kt_next(&r), kt_next(&r));
      if (a.z < 0.05f || c.z < 0.05f) continue;
      kpcn_bsdf_eval_result e1, e2;
      kpcn_bsdf_eval(recip[bi], &k_sp, a, c, &e1);
      kpcn_bsdf_eval(recip[bi], &k_sp, c, a, &e2);
      double f1 = e1.f_cos.y / c.z, f2 = e2.f_cos.y / a.z;
      if (!(fabs(f1 - f2) <= 1e-4 * fmax(fabs(f1), 1e-3))) { /* NaN counts */
        if (bad < 5)
          printf("reciprocity %s: %g vs %g\n", kpcn_bsdf_type_name(kpcn_bsdf_get_type(recip[bi])),
                 f1, f2);
        bad++;
      }
    }
  CHECK(bad == 0);

  /* classification helpers */
  CHECK(kpcn_bsdf_is_delta_only(di) && kpcn_bsdf_is_transmissive(di));
  CHECK(!kpcn_bsdf_is_delta_only(coat) && !kpcn_bsdf_is_transmissive(coat));
  CHECK(kpcn_bsdf_lobes(lam) == KPCN_LOBE_DIFFUSE);
  kpcn_bsdf_destroy(lam);
  kpcn_bsdf_destroy(pl);
  kpcn_bsdf_destroy(rp);
  kpcn_bsdf_destroy(rd);
  kpcn_bsdf_destroy(di);
  kpcn_bsdf_destroy(coat);
  kpcn_bsdf_destroy(rc);
  return kt_summary("render_bsdf_energy");
}
