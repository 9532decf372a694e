/* Chi-square goodness of fit of every non-delta bsdf's sample() against the pdf its eval()
 * reports, plus per-sample consistency: sample weight == eval f*cos / pdf and sample pdf ==
 * eval pdf. Expected counts come from numerical integration of the pdf over each
 * (theta, phi) cell; delta and failed samples share one extra cell whose expected count is
 * the pdf's missing mass. */
#include "bsdf_testlib.h"
#include "chi2.h"
#include "testutil.h"

#include "render/texture.h"

#include <stdlib.h>
#include <string.h>

#define NT 40 /* theta cells over [0, pi] */
#define NP 40 /* phi cells */
#define ST 24 /* integration sub-steps per cell */
#define SP 12
#define NSAMPLES 400000
#define NCONFIGS_FOR_ALPHA 24

static const kpcn_shading_point k_sp = {0.3f, 0.6f};

static void run_chi2(const char *label, const kpcn_bsdf *b, kpcn_vec3 wo, unsigned seed) {
  static double obs[NT * NP + 1], expd[NT * NP + 1];
  memset(obs, 0, sizeof(obs));
  memset(expd, 0, sizeof(expd));
  const double dt = KPCN_PI / NT, dp = 2.0 * KPCN_PI / NP;
  /* expected counts */
  double total = 0.0;
  for (int it = 0; it < NT; ++it)
    for (int ip = 0; ip < NP; ++ip) {
      double acc = 0.0;
      for (int a = 0; a < ST; ++a) {
        double th = (it + (a + 0.5) / ST) * dt;
        double st = sin(th), ct = cos(th);
        for (int c = 0; c < SP; ++c) {
          double ph = (ip + (c + 0.5) / SP) * dp;
          kpcn_vec3 wi = kv3((float)(st * cos(ph)), (float)(st * sin(ph)), (float)ct);
          acc += kpcn_bsdf_pdf(b, &k_sp, wo, wi) * st;
        }
      }
      acc *= dt * dp / (ST * SP);
      expd[it * NP + ip] = acc * NSAMPLES;
      total += acc;
    }
  expd[NT * NP] = total < 1.0 ? (1.0 - total) * NSAMPLES : 0.0;
  /* samples */
  kt_rng rng = {seed * 7919ull + 17ull};
  long bad_weight = 0, bad_pdf = 0, nondelta = 0;
  double worst = 0.0;
  for (int i = 0; i < NSAMPLES; ++i) {
    float u1 = kt_next(&rng), u2 = kt_next(&rng), ul = kt_next(&rng);
    kpcn_bsdf_sample_result s;
    if (!kpcn_bsdf_sample(b, &k_sp, wo, u1, u2, ul, &s) || s.is_delta) {
      obs[NT * NP] += 1.0;
      continue;
    }
    nondelta++;
    kpcn_vec3 wi = kv3_normalize(s.wi);
    double th = acos(fmax(-1.0, fmin(1.0, wi.z)));
    double ph = atan2(wi.y, wi.x);
    if (ph < 0) ph += 2.0 * KPCN_PI;
    int it = (int)(th / dt), ip = (int)(ph / dp);
    if (it >= NT) it = NT - 1;
    if (ip >= NP) ip = NP - 1;
    obs[it * NP + ip] += 1.0;
    kpcn_bsdf_eval_result e;
    kpcn_bsdf_eval(b, &k_sp, wo, s.wi, &e);
    double rp = fabs(e.pdf - s.pdf) / fmax(s.pdf, 1e-6);
    if (!(rp <= 2e-3)) bad_pdf++; /* a NaN pdf counts as bad */
    if (!(e.pdf <= 0)) {          /* and so do the weights it would give */
      for (int c = 0; c < 3; ++c) {
        double w_eval = kv3_get(e.f_cos, c) / e.pdf, w = kv3_get(s.weight, c);
        double wd_eval = kv3_get(e.f_cos_diffuse, c) / e.pdf, wd = kv3_get(s.weight_diffuse, c);
        double r =
            fabs(w_eval - w) / fmax(fabs(w), 1e-4) + fabs(wd_eval - wd) / fmax(fabs(w), 1e-4);
        worst = kt_worst(worst, r);
        if (!(r <= 2e-3)) bad_weight++;
      }
    }
  }
  const char *why;
  double p = kt_chi2_test(obs, expd, NT * NP + 1, 5.0, &why);
  double alpha = 0.01 / NCONFIGS_FOR_ALPHA; /* Sidak-style correction over all configurations */
  printf("%-44s p=%.4f  nondelta=%ld  pdf-mass=%.4f  bad_pdf=%ld bad_weight=%ld worst=%.2g%s%s\n",
         label, p, nondelta, total, bad_pdf, bad_weight, worst, why ? "  " : "", why ? why : "");
  CHECK(p > alpha);
  if (!(p > alpha)) { /* show the worst cells to make a failure diagnosable */
    for (int k = 0; k < 5; ++k) {
      int wi_ = -1;
      double wv = -1;
      for (int i = 0; i <= NT * NP; ++i) {
        double d = fabs(obs[i] - expd[i]) / sqrt(fmax(expd[i], 1.0));
        if (d > wv) {
          wv = d;
          wi_ = i;
        }
      }
      printf("   cell theta#%d phi#%d obs %.0f exp %.1f\n", wi_ / NP, wi_ % NP, obs[wi_],
             expd[wi_]);
      obs[wi_] = expd[wi_];
    }
  }
  /* float rounding at grazing angles may disagree in a handful of samples, never more */
  CHECK(bad_pdf <= NSAMPLES / 20000);
  CHECK(bad_weight <= NSAMPLES / 20000);
  CHECK(nondelta > 0);
}

static kpcn_bsdf *mk(kpcn_bsdf_type t, void (*tweak)(kpcn_bsdf_params *)) {
  kpcn_bsdf_params p;
  kpcn_bsdf_params_defaults(&p, t);
  if (tweak) tweak(&p);
  kpcn_bsdf *b = NULL;
  kpcn_status s = kpcn_bsdf_create(&p, &b);
  CHECK(s == KPCN_OK);
  if (s != KPCN_OK) {
    fprintf(stderr, "create %s: %s\n", kpcn_bsdf_type_name(t), kpcn_last_error());
    exit(1);
  }
  return b;
}

static const kpcn_texture *g_albedo;
static const kpcn_bsdf *g_substrate;
static void t_albedo(kpcn_bsdf_params *p) { p->albedo = g_albedo; }
static void t_ggx03(kpcn_bsdf_params *p) {
  p->roughness_value = 0.3f;
  p->distribution = KPCN_MF_GGX;
}
static void t_beck02(kpcn_bsdf_params *p) {
  p->roughness_value = 0.2f;
  p->distribution = KPCN_MF_BECKMANN;
}
static void t_phong(kpcn_bsdf_params *p) {
  p->roughness_value = 0.3f;
  p->distribution = KPCN_MF_PHONG;
}
static void t_beck01(kpcn_bsdf_params *p) {
  p->roughness_value = 0.1f;
  p->distribution = KPCN_MF_BECKMANN;
}
static void t_noref(kpcn_bsdf_params *p) {
  p->roughness_value = 0.3f;
  p->enable_refraction = 0;
}
static void t_plastic(kpcn_bsdf_params *p) {
  p->albedo = g_albedo;
  p->sigma_a = kv3(0.3f, 0.1f, 0.0f);
}
static void t_rplastic(kpcn_bsdf_params *p) {
  p->albedo = g_albedo;
  p->roughness_value = 0.2f;
}
static void t_rplastic_b(kpcn_bsdf_params *p) {
  p->albedo = g_albedo;
  p->roughness_value = 0.3f;
  p->distribution = KPCN_MF_BECKMANN;
  p->thickness = 2.0f;
  p->sigma_a = kv3(0.1f, 0.2f, 0.3f);
}
static void t_coat(kpcn_bsdf_params *p) {
  p->ior = 1.7f;
  p->thickness = 5.0f;
  p->sigma_a = kv3(0.1f, 0.2f, 0.5f);
  p->substrate = g_substrate;
}

int main(void) {
  kpcn_texture_cache *tc;
  CHECK(kpcn_texture_cache_create(&tc) == KPCN_OK);
  CHECK(kpcn_texture_constant(tc, kv3(0.7f, 0.5f, 0.3f), &g_albedo) == KPCN_OK);

  kpcn_bsdf *lam = mk(KPCN_BSDF_LAMBERT, t_albedo);
  run_chi2("lambert wo=30", lam, kt_dir(30, 10), 1);

  kpcn_bsdf *rc = mk(KPCN_BSDF_ROUGH_CONDUCTOR, t_ggx03);
  run_chi2("rough_conductor ggx 0.3 wo=20", rc, kt_dir(20, 40), 2);
  run_chi2("rough_conductor ggx 0.3 wo=70", rc, kt_dir(70, 200), 3);
  kpcn_bsdf *rcb = mk(KPCN_BSDF_ROUGH_CONDUCTOR, t_beck02);
  run_chi2("rough_conductor beckmann 0.2 wo=45", rcb, kt_dir(45, 100), 4);
  kpcn_bsdf *rcp = mk(KPCN_BSDF_ROUGH_CONDUCTOR, t_phong);
  run_chi2("rough_conductor phong 0.3 wo=35", rcp, kt_dir(35, 300), 5);

  kpcn_bsdf *rd = mk(KPCN_BSDF_ROUGH_DIELECTRIC, t_ggx03);
  run_chi2("rough_dielectric ggx 0.3 outside wo=30", rd, kt_dir(30, 20), 6);
  run_chi2("rough_dielectric ggx 0.3 inside wo=140", rd, kt_dir(140, 70), 7);
  run_chi2("rough_dielectric ggx 0.3 inside TIR wo=120", rd, kt_dir(120, 250), 8);
  kpcn_bsdf *rdb = mk(KPCN_BSDF_ROUGH_DIELECTRIC, t_beck02);
  run_chi2("rough_dielectric beckmann 0.2 outside wo=60", rdb, kt_dir(60, 0), 9);
  kpcn_bsdf *rdn = mk(KPCN_BSDF_ROUGH_DIELECTRIC, t_noref);
  run_chi2("rough_dielectric no refraction wo=50", rdn, kt_dir(50, 123), 10);

  kpcn_bsdf *pl = mk(KPCN_BSDF_PLASTIC, t_plastic);
  run_chi2("plastic (diffuse part) wo=40", pl, kt_dir(40, 33), 11);
  kpcn_bsdf *rp = mk(KPCN_BSDF_ROUGH_PLASTIC, t_rplastic);
  run_chi2("rough_plastic ggx 0.2 wo=60", rp, kt_dir(60, 80), 12);
  run_chi2("rough_plastic ggx 0.2 wo=5", rp, kt_dir(5, 80), 13);
  kpcn_bsdf *rpb = mk(KPCN_BSDF_ROUGH_PLASTIC, t_rplastic_b);
  run_chi2("rough_plastic beckmann 0.3 absorbing wo=30", rpb, kt_dir(30, 180), 14);

  /* Tungsten's materialtest: smooth_coat over a Beckmann rough copper of roughness 0.1 */
  kpcn_bsdf *cu = mk(KPCN_BSDF_ROUGH_CONDUCTOR, t_beck01);
  g_substrate = cu;
  kpcn_bsdf *coat = mk(KPCN_BSDF_SMOOTH_COAT, t_coat);
  run_chi2("smooth_coat(rough Cu beckmann 0.1) wo=30", coat, kt_dir(30, 45), 15);
  run_chi2("smooth_coat(rough Cu beckmann 0.1) wo=75", coat, kt_dir(75, 300), 16);
  g_substrate = lam;
  kpcn_bsdf *coat2 = mk(KPCN_BSDF_SMOOTH_COAT, t_coat);
  run_chi2("smooth_coat(lambert) wo=50", coat2, kt_dir(50, 10), 17);
  g_substrate = rp;
  kpcn_bsdf *coat3 = mk(KPCN_BSDF_SMOOTH_COAT, t_coat);
  run_chi2("smooth_coat(rough_plastic) wo=20", coat3, kt_dir(20, 10), 18);

  kpcn_bsdf *all[] = {lam, rc, rcb, rcp, rd, rdb, rdn, pl, rp, rpb, cu, coat, coat2, coat3};
  for (size_t i = 0; i < sizeof(all) / sizeof(all[0]); ++i)
    kpcn_bsdf_destroy(all[i]);
  kpcn_texture_cache_destroy(tc);
  return kt_summary("render_bsdf_sampling");
}
