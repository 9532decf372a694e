/* What a model records and how the denoiser uses it: the exposure statistic and the input
 * scaled to the model's exposure; a flat irradiance under a texture within the bound any convex
 * kernel must keep, at two demodulation epsilons; a model whose branches come from two models
 * gives each one's result where only its light is present. */
#include <limits.h>
#include <stdlib.h>
#include <string.h>

#include "kpcn/augment.h"
#include "model_fixture.h"
#include "synth.h"

/* Multiplies the colour buffers of a by s and their variances by s². */
static void scale_colour(kpcn_aov_set *a, float s) {
  const size_t P = kpcn_aov_plane_size(a);
  const kpcn_buffer cb[3] = {KPCN_BUF_COLOR, KPCN_BUF_DIFFUSE, KPCN_BUF_SPECULAR};
  for (int k = 0; k < 3; k++) {
    for (size_t i = 0; i < 3 * P; i++)
      a->buf[cb[k]][i] *= s;
    for (size_t i = 0; i < P; i++)
      a->var[cb[k]][i] *= s * s;
  }
}

/* Exposure: the statistic against a hand-computed median, exact scaling and symmetry; the
 * denoiser's output scales with its input exactly; bad targets and black frames. */
static void test_exposure(void) {
  /* 32x32: sixteen 8x8 blocks (the grid from the centre lands on multiples of 8), block k
   * (row-major) of luminance k + 1, blocks 0, 5 and 10 black (not counted), a NaN and an
   * Inf pixel in block 15 (skipped); the other blocks alternate 0.5 and 1.5 times their
   * mean. Lit means: 2 3 4 5 7 8 9 10 12 13 14 15 16 -> median 9. */
  kpcn_aov_set *k = synth_aov(32, 32, 5);
  const size_t Pk = kpcn_aov_plane_size(k);
  for (int y = 0; y < 32; y++)
    for (int x = 0; x < 32; x++) {
      const int blk = (x / 8) + 4 * (y / 8);
      float v = (blk == 0 || blk == 5 || blk == 10) ? 0.0f : (float)(blk + 1);
      if (blk != 15) v *= (x + y) % 2 ? 1.5f : 0.5f;
      for (int c = 0; c < 3; c++) {
        k->buf[KPCN_BUF_DIFFUSE][c * Pk + (size_t)y * 32 + x] = v;
        k->buf[KPCN_BUF_SPECULAR][c * Pk + (size_t)y * 32 + x] = 0.0f;
      }
    }
  k->buf[KPCN_BUF_DIFFUSE][31 * 32 + 30] = NAN;
  k->buf[KPCN_BUF_SPECULAR][Pk + 30 * 32 + 31] = INFINITY;
  double e = -1.0;
  CHECK(kpcn_aov_exposure(k, &e) == KPCN_OK);
  printf("exposure of the known-answer image: %.12g (want 9)\n", e);
  CHECK(fabs(e - 9.0) < 1e-9);
  kpcn_aov_destroy(k);

  kpcn_model *m = make_model(11);
  CHECK(m != NULL);
  if (!m) return;
  kpcn_aov_set *a = synth_aov(29, 23, 9), *b = synth_aov(29, 23, 9);
  const size_t P = kpcn_aov_plane_size(a);
  double ea = 0.0, eb = 0.0;
  CHECK(kpcn_aov_exposure(a, &ea) == KPCN_OK && ea > 0.0 && ea < 0.5);
  printf("exposure of the synthetic image: %.4g\n", ea);
  scale_colour(b, 1024.0f);
  CHECK(kpcn_aov_exposure(b, &eb) == KPCN_OK);
  CHECK(eb == 1024.0 * ea);     /* a power of two scales every step exactly */
  for (int i = 1; i < 8; i++) { /* odd sizes: blocks still map onto blocks */
    kpcn_augment_xform xi;
    kpcn_denoise_ensemble_xform(i, &xi);
    kpcn_aov_set *t = NULL;
    double et = 0.0;
    CHECK(kpcn_augment_aov(&t, a, &xi, 1) == KPCN_OK);
    CHECK(kpcn_aov_exposure(t, &et) == KPCN_OK);
    CHECK(fabs(et - ea) <= 1e-12 * ea);
    kpcn_aov_destroy(t);
  }
  /* A fixed exposure: the result scales with the input, bit for bit. */
  kpcn_denoiser_options o;
  kpcn_denoiser_options_defaults(&o);
  o.nthreads = 2;
  o.tile = 16;
  o.exposure = 0.37f;
  float *oa = malloc(sizeof(float) * 3 * P), *ob = malloc(sizeof(float) * 3 * P);
  float *oc = malloc(sizeof(float) * 3 * P);
  CHECK(run_opts(m, a, &o, NULL, oa) == KPCN_OK);
  CHECK(run_opts(m, b, &o, NULL, ob) == KPCN_OK);
  size_t differ = 0;
  for (size_t i = 0; i < 3 * P; i++)
    differ += ob[i] != 1024.0f * oa[i];
  CHECK(differ == 0);
  /* ... which the input as rendered does not give */
  o.exposure = KPCN_EXPOSURE_AS_RENDERED;
  CHECK(run_opts(m, b, &o, NULL, ob) == KPCN_OK);
  double worst = 0.0;
  for (size_t i = 0; i < 3 * P; i++)
    worst = kt_worst(worst, fabs(ob[i] / 1024.0 - oa[i]) / (1e-3 + fabs(oa[i])));
  printf("as rendered, input x1024 vs x1: max rel. difference %.3g\n", worst);
  CHECK(worst > 1e-3);
  /* the default is the model's exposure (0.75): the same bits as asking for it, and
   * equivariant too */
  o.exposure = 0.75f;
  CHECK(run_opts(m, a, &o, NULL, ob) == KPCN_OK);
  kpcn_denoiser_options_defaults(&o);
  o.nthreads = 2;
  o.tile = 16;
  CHECK(run_opts(m, a, &o, NULL, oc) == KPCN_OK);
  CHECK(memcmp(ob, oc, sizeof(float) * 3 * P) == 0);
  CHECK(run_opts(m, b, &o, NULL, ob) == KPCN_OK);
  differ = 0;
  for (size_t i = 0; i < 3 * P; i++)
    differ += ob[i] != 1024.0f * oc[i];
  CHECK(differ == 0);
  /* bad exposures are named */
  const float bad[] = {-2.0f, -0.5f, NAN, INFINITY};
  for (int i = 0; i < 4; i++) {
    o.exposure = bad[i];
    CHECK(run_opts(m, a, &o, NULL, oa) == KPCN_ERR_INVALID_ARGUMENT);
    CHECK(strstr(kpcn_last_error(), "exposure") != NULL);
  }
  /* bad thread counts are named (libgomp would abort on a huge one) */
  kpcn_denoiser_options_defaults(&o);
  o.nthreads = -1;
  CHECK(run_opts(m, a, &o, NULL, oa) == KPCN_ERR_INVALID_ARGUMENT);
  o.nthreads = KPCN_DENOISE_MAX_THREADS + 1;
  CHECK(run_opts(m, a, &o, NULL, oa) == KPCN_ERR_INVALID_ARGUMENT);
  CHECK(strstr(kpcn_last_error(), "nthreads") != NULL);
  /* a NaN or Inf in any input buffer is refused, naming it, for the KPCN and the baselines
   * (run_opts's denoiser is the KPCN whatever o.method says: kpcn_denoiser_create for these) */
  kpcn_denoiser_options_defaults(&o);
  const float was = b->buf[KPCN_BUF_NORMAL][7];
  b->buf[KPCN_BUF_NORMAL][7] = NAN;
  CHECK(run_opts(m, b, &o, NULL, ob) == KPCN_ERR_NONFINITE);
  CHECK(strstr(kpcn_last_error(), "N.X") != NULL);
  o.method = KPCN_DENOISE_NLMEANS;
  b->buf[KPCN_BUF_NORMAL][7] = was;
  b->var[KPCN_BUF_COLOR][3] = INFINITY;
  kpcn_denoiser *d = NULL;
  CHECK(kpcn_denoiser_create(&d, &o) == KPCN_OK);
  CHECK(kpcn_denoiser_execute_aov(d, b, ob) == KPCN_ERR_NONFINITE);
  CHECK(strstr(kpcn_last_error(), "1 non-finite") != NULL);
  kpcn_denoiser_destroy(d);
  d = NULL;
  scale_colour(a, 0.0f);
  kpcn_denoiser_options_defaults(&o);
  CHECK(kpcn_denoiser_create_with_model(&d, m, &o) == KPCN_OK);
  CHECK(kpcn_denoiser_execute_aov(d, a, oa) == KPCN_OK);
  kpcn_denoise_stats st;
  kpcn_denoiser_get_stats(d, &st);
  CHECK(st.exposure == 0.0 && st.exposure_scale == 1.0); /* a black frame: scale 1 */
  kpcn_denoiser_destroy(d);
  /* finite but absurd weights (a damaged file): the logits overflow and the softmax gives NaN;
   * the call fails naming it instead of returning NaN as a success (found by tests/fuzz) */
  kpcn_model *huge = NULL;
  CHECK(kpcn_model_clone(m, &huge) == KPCN_OK);
  const int last = kpcn_model_arch(huge)->n_hidden;
  for (int br = 0; br < 2; br++) {
    kpcn_layer_view lv;
    CHECK(kpcn_model_layer(huge, (kpcn_branch)br, last, &lv) == KPCN_OK);
    for (size_t i = 0; i < (size_t)lv.out_ch * lv.in_ch * lv.size * lv.size; i++)
      lv.weight[i] = 3e38f;
  }
  kpcn_denoiser_options_defaults(&o);
  kpcn_aov_set *fresh = synth_aov(29, 23, 9); /* finite, unlike b above */
  CHECK(run_opts(m, fresh, &o, NULL, ob) == KPCN_OK);
  CHECK(run_opts(huge, fresh, &o, NULL, ob) == KPCN_ERR_NONFINITE);
  kpcn_aov_destroy(fresh);
  CHECK(strstr(kpcn_last_error(), "weights overflow") != NULL);
  kpcn_model_destroy(huge);
  /* a negative albedo (a pixel filter's negative lobe) is refused for the KPCN, naming the
   * least value and its pixel: at -eps it gave NaN blamed on the model */
  fresh = synth_aov(29, 23, 9);
  const size_t FP = kpcn_aov_plane_size(fresh);
  fresh->buf[KPCN_BUF_ALBEDO][FP + 2 * 29 + 5] = -kpcn_model_arch(m)->eps; /* G at (5, 2) */
  fresh->buf[KPCN_BUF_ALBEDO][7] = -1e-6f;
  CHECK(run_opts(m, fresh, &o, NULL, ob) == KPCN_ERR_INVALID_ARGUMENT);
  CHECK(strstr(kpcn_last_error(), "2 negative value(s)") != NULL);
  CHECK(strstr(kpcn_last_error(), "in albedo.G at pixel (5, 2)") != NULL);
  /* for the baselines the albedo is a guide, not a divisor: accepted */
  o.method = KPCN_DENOISE_BILATERAL;
  CHECK(kpcn_denoiser_create(&d, &o) == KPCN_OK);
  CHECK(kpcn_denoiser_execute_aov(d, fresh, ob) == KPCN_OK);
  kpcn_denoiser_destroy(d);
  /* a baseline sigma whose 1 / (2 sigma^2) overflows is named, not a NaN result, and like
   * every baseline parameter it is checked at create, not at the first execute */
  o.bilateral.sigma_normal = 1e-30f;
  d = NULL;
  CHECK(kpcn_denoiser_create(&d, &o) == KPCN_ERR_INVALID_ARGUMENT && !d);
  CHECK(strstr(kpcn_last_error(), "sigma_normal 1e-30 is too small") != NULL);
  kpcn_denoiser_options_defaults(&o);
  o.method = KPCN_DENOISE_NLMEANS;
  o.nlmeans.patch_radius = 17;
  CHECK(kpcn_denoiser_create(&d, &o) == KPCN_ERR_INVALID_ARGUMENT && !d);
  CHECK(strstr(kpcn_last_error(), "patch_radius 17 outside [0, 16]") != NULL);
  /* the buffer API: every missing buffer in one message, in set_buffer's names; strides that
   * would make pixels or rows overlap refused */
  kpcn_denoiser_options_defaults(&o);
  CHECK(kpcn_denoiser_create_with_model(&d, m, &o) == KPCN_OK);
  const int FW = fresh->width, FH = fresh->height;
  float *inter = calloc((size_t)FW * FH * 3, sizeof(float));
  CHECK(kpcn_denoiser_set_buffer(d, "diffuse", inter, FW, FH, 0, 0) == KPCN_OK);
  CHECK(kpcn_denoiser_execute(d, ob, FW, FH, 0, 0) == KPCN_ERR_MISSING_CHANNEL);
  CHECK(strstr(kpcn_last_error(),
               "needs 11 more buffer(s): diffuse.var, specular, specular.var, albedo, albedo.var, "
               "normal, normal.var, depth, depth.var, visibility, visibility.var") != NULL);
  CHECK(kpcn_denoiser_set_buffer(d, "depth", inter, FW, FH, 2, 0) == KPCN_ERR_INVALID_ARGUMENT);
  CHECK(strstr(kpcn_last_error(), "whole floats") != NULL);
  CHECK(kpcn_denoiser_set_buffer(d, "normal", inter, FW, FH, 8, 0) == KPCN_ERR_INVALID_ARGUMENT);
  CHECK(strstr(kpcn_last_error(), "pixel stride 8 bytes is less than a pixel's 12") != NULL);
  CHECK(kpcn_denoiser_set_buffer(d, "normal", inter, FW, FH, 12, 12 * (FW - 1)) ==
        KPCN_ERR_INVALID_ARGUMENT);
  CHECK(strstr(kpcn_last_error(), "rows would overlap") != NULL);
  CHECK(kpcn_denoiser_set_buffer_channel(d, "depth", 0, inter, FW, FH, 4, 0) == KPCN_OK);
  CHECK(kpcn_denoiser_execute(d, ob, FW, FH, 8, 0) == KPCN_ERR_INVALID_ARGUMENT);
  CHECK(strstr(kpcn_last_error(), "denoiser output") != NULL);
  free(inter);
  kpcn_denoiser_destroy(d);
  /* `out` may be one of the inputs (denoiser.md: every input is copied before anything is
   * written): the result written over the interleaved diffuse buffer equals the one written
   * elsewhere, bit for bit */
  CHECK(kpcn_denoiser_create_with_model(&d, m, &o) == KPCN_OK);
  kpcn_aov_set *ov = synth_aov(FW, FH, 12); /* fresh holds a negative albedo by now */
  const size_t FPn = (size_t)FW * FH;
  float *din = malloc(sizeof(float) * 3 * FPn), *sep = malloc(sizeof(float) * 3 * FPn);
  for (int b = 0; b < KPCN_BUF_COUNT; b++) {
    const char *nm = kpcn_buffer_name((kpcn_buffer)b);
    for (int c = 0; c < kpcn_buffer_channels((kpcn_buffer)b); c++)
      CHECK(kpcn_denoiser_set_buffer_channel(d, nm, c, ov->buf[b] + c * FPn, FW, FH, 4, 0) ==
            KPCN_OK);
    char vn[32];
    snprintf(vn, sizeof vn, "%s.var", nm);
    CHECK(kpcn_denoiser_set_buffer(d, vn, ov->var[b], FW, FH, 0, 0) == KPCN_OK);
  }
  for (size_t i = 0; i < FPn; i++)
    for (int c = 0; c < 3; c++)
      din[3 * i + c] = ov->buf[KPCN_BUF_DIFFUSE][c * FPn + i];
  CHECK(kpcn_denoiser_set_buffer(d, "diffuse", din, FW, FH, 0, 0) == KPCN_OK);
  CHECK(kpcn_denoiser_execute(d, sep, FW, FH, 0, 0) == KPCN_OK);
  CHECK(kpcn_denoiser_execute(d, din, FW, FH, 0, 0) == KPCN_OK);
  CHECK(memcmp(din, sep, sizeof(float) * 3 * FPn) == 0);
  free(din);
  free(sep);
  kpcn_aov_destroy(ov);
  kpcn_denoiser_destroy(d);
  kpcn_aov_destroy(fresh);
  free(oa);
  free(ob);
  free(oc);
  kpcn_aov_destroy(a);
  kpcn_aov_destroy(b);
  kpcn_model_destroy(m);
}

/* A flat irradiance under a texture: diffuse = albedo * E with E constant, no specular. The
 * diffuse branch filters diffuse / (albedo + eps) = E f(albedo), f(a) = a / (a + eps), and
 * remodulates by (albedo + eps); so for ANY normalised non-negative kernel the output over
 * the input lies in [(a + eps)/a * f_lo, (a + eps)/a * f_hi] (f_lo, f_hi: f of the darkest
 * and brightest albedo). That bound, from the algebra alone, is the truth checked here, at
 * the preset eps and at 1e-4 (kpcn_model_set_eps); the random kernels mix the two albedos,
 * so the larger eps must show the texture-correlated error the bound allows
 * (docs/denoiser.md, "The demodulation epsilon"). */
static void test_eps_flat_irradiance(void) {
  const int W = 48, H = 40;
  const float lo = 0.1f, hi = 0.8f, E = 0.5f;
  kpcn_aov_set *a = synth_aov(W, H, 21);
  kpcn_model *m = make_model(9);
  CHECK(a && m);
  if (!a || !m) return;
  const size_t P = kpcn_aov_plane_size(a);
  for (int y = 0; y < H; y++)
    for (int x = 0; x < W; x++)
      for (int c = 0; c < 3; c++) {
        size_t i = c * P + (size_t)y * W + x;
        float alb = ((x / 2 + y / 2) % 2) ? hi : lo;
        a->buf[KPCN_BUF_ALBEDO][i] = alb;
        a->buf[KPCN_BUF_DIFFUSE][i] = a->buf[KPCN_BUF_COLOR][i] = alb * E;
        a->buf[KPCN_BUF_SPECULAR][i] = 0.0f;
      }
  CHECK(kpcn_model_set_eps(m, 0.0f) == KPCN_ERR_INVALID_ARGUMENT);
  CHECK(kpcn_model_set_eps(m, 1.0f) == KPCN_ERR_INVALID_ARGUMENT);
  CHECK(kpcn_model_set_eps(m, NAN) == KPCN_ERR_INVALID_ARGUMENT);
  float *out = malloc(sizeof(float) * 3 * P);
  double worst[2] = {0, 0};
  const float eps_of[2] = {kpcn_model_arch(m)->eps, 1e-4f};
  for (int k = 0; k < 2; k++) {
    const float eps = eps_of[k];
    CHECK(kpcn_model_set_eps(m, eps) == KPCN_OK && kpcn_model_arch(m)->eps == eps);
    kpcn_denoiser_options o;
    kpcn_denoiser_options_defaults(&o);
    o.firefly = 0.0f;
    o.nthreads = 2;
    CHECK(run_opts(m, a, &o, NULL, out) == KPCN_OK);
    const double f_lo = lo / (lo + eps), f_hi = hi / (hi + eps);
    int outside = 0;
    for (size_t i = 0; i < 3 * P; i++) {
      double alb = a->buf[KPCN_BUF_ALBEDO][i], r = out[i] / (alb * E);
      double g = (alb + eps) / alb;
      if (r < g * f_lo * (1 - 1e-5) || r > g * f_hi * (1 + 1e-5)) outside++;
      worst[k] = fmax(worst[k], fabs(r - 1.0));
    }
    if (outside) fprintf(stderr, "eps %g: %d values outside the bound\n", (double)eps, outside);
    CHECK(outside == 0);
  }
  /* the bound's widths: 2.7 % at 0.00316, 0.09 % at 1e-4 */
  printf("flat irradiance under a texture: worst error %.3g at eps %g, %.3g at 1e-4\n", worst[0],
         (double)eps_of[0], worst[1]);
  CHECK(worst[0] > 0.005 && worst[1] < 0.001);
  free(out);
  kpcn_aov_destroy(a);
  kpcn_model_destroy(m);
}

/* kpcn_model_graft_branch: the two branches are separate networks whose results are added, so
 * a model with m1's diffuse and m2's specular branch must give m1's result where the input has
 * no specular light and m2's where it has no diffuse light, bit for bit (a branch's result on a
 * zero colour is zero whatever its kernels: they are normalised). The specular branch may come
 * from a model of another eps; a diffuse one, another exposure or architecture may not, and a
 * refused graft leaves the model unchanged. */
static void test_graft_branch(void) {
  const int W = 40, H = 36;
  kpcn_model *m1 = make_model(31), *m2 = make_model(32), *h = NULL,
             *other = make_model_chain(33, 2, 0);
  kpcn_aov_set *a = synth_aov(W, H, 5), *nd = synth_aov(W, H, 5), *ns = synth_aov(W, H, 5);
  CHECK(m1 && m2 && other && a && nd && ns);
  if (!m1 || !m2 || !other || !a || !nd || !ns) return;
  CHECK(kpcn_model_set_eps(m2, 1e-3f) == KPCN_OK);
  CHECK(kpcn_model_clone(m1, &h) == KPCN_OK);
  CHECK(kpcn_model_graft_branch(h, m2, KPCN_BRANCH_SPECULAR) == KPCN_OK);
  CHECK(kpcn_model_arch(h)->eps == kpcn_model_arch(m1)->eps);
  const size_t P = kpcn_aov_plane_size(a), n = 3 * P;
  for (size_t i = 0; i < n; i++) { /* colour = diffuse + specular in both */
    nd->buf[KPCN_BUF_DIFFUSE][i] = 0.0f;
    nd->buf[KPCN_BUF_COLOR][i] = nd->buf[KPCN_BUF_SPECULAR][i];
    ns->buf[KPCN_BUF_SPECULAR][i] = 0.0f;
    ns->buf[KPCN_BUF_COLOR][i] = ns->buf[KPCN_BUF_DIFFUSE][i];
  }
  float *o1 = malloc(sizeof(float) * n), *o2 = malloc(sizeof(float) * n),
        *oh = malloc(sizeof(float) * n);
  CHECK(run(m1, ns, 0, 0, o1) == KPCN_OK && run(h, ns, 0, 0, oh) == KPCN_OK);
  CHECK(memcmp(o1, oh, sizeof(float) * n) == 0); /* no specular light: m1's result */
  CHECK(run(m2, nd, 0, 0, o2) == KPCN_OK && run(h, nd, 0, 0, oh) == KPCN_OK);
  CHECK(memcmp(o2, oh, sizeof(float) * n) == 0); /* no diffuse light: m2's result */
  CHECK(run(m1, a, 0, 0, o1) == KPCN_OK && run(m2, a, 0, 0, o2) == KPCN_OK &&
        run(h, a, 0, 0, oh) == KPCN_OK);
  CHECK(max_rel(oh, o1, n) > 1e-3 && max_rel(oh, o2, n) > 1e-3); /* both branches matter */
  /* refusals, each leaving h as it was */
  CHECK(kpcn_model_graft_branch(h, m2, KPCN_BRANCH_DIFFUSE) == KPCN_ERR_FORMAT);
  CHECK(strstr(kpcn_last_error(), "eps") != NULL);
  CHECK(kpcn_model_graft_branch(h, other, KPCN_BRANCH_SPECULAR) == KPCN_ERR_FORMAT);
  CHECK(strstr(kpcn_last_error(), "architecture") != NULL);
  CHECK(kpcn_model_set_exposure(m2, 0.5f) == KPCN_OK);
  CHECK(kpcn_model_graft_branch(h, m2, KPCN_BRANCH_SPECULAR) == KPCN_ERR_FORMAT);
  CHECK(strstr(kpcn_last_error(), "exposure") != NULL);
  CHECK(kpcn_model_graft_branch(h, NULL, KPCN_BRANCH_SPECULAR) == KPCN_ERR_INVALID_ARGUMENT);
  CHECK(kpcn_model_graft_branch(h, m1, (kpcn_branch)2) == KPCN_ERR_INVALID_ARGUMENT);
  float *o3 = malloc(sizeof(float) * n);
  CHECK(run(h, a, 0, 0, o3) == KPCN_OK && memcmp(o3, oh, sizeof(float) * n) == 0);
  free(o1);
  free(o2);
  free(oh);
  free(o3);
  kpcn_aov_destroy(a);
  kpcn_aov_destroy(nd);
  kpcn_aov_destroy(ns);
  kpcn_model_destroy(m1);
  kpcn_model_destroy(m2);
  kpcn_model_destroy(h);
  kpcn_model_destroy(other);
}

int main(void) {
  test_exposure();
  test_eps_flat_irradiance();
  test_graft_branch();
  return kt_summary("test_denoise_model_ops");
}
