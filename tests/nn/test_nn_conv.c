/* The oneDNN branch net vs the naive double reference (nn_ref.c): forward (conv + bias +
 * fused ReLU, linear last layer), backward-data, backward-weights, backward-bias, for
 * several sizes, paddings, dilations and batches; finite differences validate the
 * reference's backward; bf16 inference vs fp32 stays within a bounded difference, and so do
 * bf16 (mixed-precision) training gradients vs the exact ones. */
#include "core/internal.h"
#include "kpcn/nn.h"
#include "nn/net_internal.h"
#include "nn_ref.h"
#include "testutil.h"

#include <stdlib.h>
#include <string.h>
#include <omp.h>
#include <xmmintrin.h>

typedef struct cfg {
  int n_in, n_hidden, ch, K, N, H, W;
  int size[4], dil[4];
} cfg;

/* n inputs named in0, in1, ... (the denoiser's feature set has 36) */
static void set_inputs(kpcn_arch *a, int n) {
  char nm[KPCN_NN_MAX_INPUTS][16];
  const char *names[KPCN_NN_MAX_INPUTS];
  for (int i = 0; i < n; i++)
    snprintf(nm[i], sizeof nm[i], "in%d", i), names[i] = nm[i];
  CHECK(kpcn_arch_set_inputs(a, n, names) == KPCN_OK);
}

/* A model of preset `name` with n_in inputs (weights from seed), *a its architecture. */
static kpcn_model *preset_model(const char *name, int n_in, unsigned seed, kpcn_arch *a) {
  kpcn_model *m = NULL;
  CHECK(kpcn_arch_preset(name, a) == KPCN_OK);
  set_inputs(a, n_in);
  CHECK(kpcn_model_create(a, seed, &m) == KPCN_OK);
  return m;
}

static void make_arch(const cfg *c, kpcn_arch *a) {
  kpcn_arch_preset("tiny", a);
  a->n_hidden = c->n_hidden;
  a->channels = c->ch;
  a->kernel_size = c->K;
  for (int l = 0; l <= c->n_hidden; l++)
    a->conv_size[l] = c->size[l], a->dilation[l] = c->dil[l];
  set_inputs(a, c->n_in);
}

/* random biases (Xavier init leaves them at zero) so the ReLU mask is non-trivial */
static void randomize_bias(kpcn_model *m, unsigned *rs) {
  const kpcn_arch *a = kpcn_model_arch(m);
  for (int b = 0; b < KPCN_N_BRANCHES; b++)
    for (int l = 0; l <= a->n_hidden; l++) {
      kpcn_layer_view v;
      kpcn_model_layer(m, (kpcn_branch)b, l, &v);
      for (int i = 0; i < v.out_ch; i++)
        v.bias[i] = 0.2f * (kt_randf(rs) - 0.5f);
    }
}

static void fill(float *p, size_t n, unsigned *rs, float scale) {
  for (size_t i = 0; i < n; i++)
    p[i] = scale * (2.f * kt_randf(rs) - 1.f);
}

/* Element i of logits in the layout's element type. */
static float logit_value(const void *L, const kpcn_logits_layout *l, size_t i) {
  return l->bf16 ? kpcn_bf16_to_float(((const uint16_t *)L)[i]) : ((const float *)L)[i];
}

/* max |got - ref| <= rtol * max |ref| (normwise relative error) */

static double rel_err(const float *got, const double *ref, size_t n) {
  double mx = 0, e = 0;
  for (size_t i = 0; i < n; i++) {
    double r = ref[i], d = fabs((double)got[i] - r);
    if (fabs(r) > mx) mx = fabs(r);
    if (d > e || d != d) e = d;
  }
  return mx > 0 ? e / mx : e;
}

/* After a backward from planar dlogits dl (dinput din): a forward that leaves the logits in the
 * net's own layout and a backward from dl written in that layout (padding zero) give the same
 * parameter gradients and dinput, bit for bit. */
static int native_backward_same(kpcn_net *net, const cfg *c, const float *in, const float *dl,
                                const float *din) {
  const int K2 = c->K * c->K, np = 2 * (c->n_hidden + 1);
  const size_t nin = (size_t)c->N * c->H * c->W * c->n_in, hw = (size_t)c->H * c->W;
  kpcn_param P[2 * KPCN_NN_MAX_LAYERS];
  if (kpcn_net_params(net, P, 2 * KPCN_NN_MAX_LAYERS) != KPCN_OK) return 0;
  size_t gn = 0;
  for (int l = 0; l < np; l++)
    gn += P[l].count;
  float *g1 = malloc(gn * 4), *din2 = malloc(nin * 4);
  for (size_t l = 0, o = 0; l < (size_t)np; o += P[l].count, l++)
    memcpy(g1 + o, P[l].grad, P[l].count * 4);
  const void *nat;
  kpcn_logits_layout lay;
  int same = kpcn_net_forward_logits(net, in, &nat, &lay) == KPCN_OK && !lay.bf16;
  float *dnat = calloc((size_t)c->N * lay.image_stride, 4);
  for (int b = 0; b < c->N; b++)
    for (int t = 0; t < K2; t++)
      for (size_t p = 0; p < hw; p++)
        dnat[b * lay.image_stride + (size_t)(t / lay.block) * lay.block_stride +
             p * (size_t)lay.pixel_stride + (size_t)(t % lay.block)] =
            dl[((size_t)b * K2 + t) * hw + p];
  same &= kpcn_net_backward_logits(net, dnat, din2) == KPCN_OK;
  same &= memcmp(din, din2, nin * 4) == 0;
  for (size_t l = 0, o = 0; l < (size_t)np; o += P[l].count, l++)
    same &= memcmp(g1 + o, P[l].grad, P[l].count * 4) == 0;
  printf("  backward from dlogits in the native layout (block %d, pixel stride %d): %s\n",
         lay.block, lay.pixel_stride, same ? "bit-identical" : "DIFFERENT");
  same &= kpcn_net_backward_logits(net, NULL, din2) == KPCN_ERR_INVALID_ARGUMENT;
  free(g1), free(din2), free(dnat);
  return same;
}

static int n_bwdd_fwd_seen; /* layers whose backward-data ran as a forward conv */
static int n_relayout_seen; /* layers of mixed-layout training nets fed through a reorder */

static int n_s2b_seen, n_s2b_train_seen; /* space-to-batch layers: inference, training nets */

static void check_vs_ref(const cfg *c, int seed) {
  kpcn_arch a;
  make_arch(c, &a);
  kpcn_model *m = NULL;
  CHECK(kpcn_model_create(&a, (uint64_t)seed, &m) == KPCN_OK);
  if (!m) return;
  unsigned rs = 1234u + (unsigned)seed;
  randomize_bias(m, &rs);
  const int K2 = c->K * c->K;
  size_t px = (size_t)c->N * c->H * c->W, nin = px * c->n_in, nout = px * K2;
  float *in = malloc(nin * 4), *lg = malloc(nout * 4), *dl = malloc(nout * 4),
        *din = malloc(nin * 4), *lg2 = malloc(nout * 4);
  fill(in, nin, &rs, 1.f);
  fill(dl, nout, &rs, 1.f);
  kpcn_branch br = seed & 1 ? KPCN_BRANCH_SPECULAR : KPCN_BRANCH_DIFFUSE;
  nn_ref ref;
  nn_ref_init(&ref, m, br, c->N, c->H, c->W);
  const double *rl = nn_ref_forward(&ref, in);
  nn_ref_backward(&ref, dl);

  kpcn_net_options o;
  kpcn_net_options_defaults(&o);
  o.batch = c->N, o.height = c->H, o.width = c->W, o.training = 1, o.input_grad = 1;
  kpcn_net *net = NULL;
  kpcn_status s = kpcn_net_create(m, br, &o, &net);
  if (s != KPCN_OK) fprintf(stderr, "net create: %s\n", kpcn_last_error());
  CHECK(s == KPCN_OK);
  if (net) { /* a training net has no input buffer to write into, so no NULL input */
    CHECK(kpcn_net_input_buffer(net, NULL, NULL) == NULL);
    CHECK(kpcn_net_forward(net, NULL, lg) == KPCN_ERR_INVALID_ARGUMENT);
  }
  if (net) {
    /* the net flushes denormals while it runs and gives the caller's threads their own
     * floating-point mode back (kpcn_fast_fp_begin/_end) */
    unsigned csr_before[64] = {0}, csr_after[64] = {0}, csr_in = _mm_getcsr();
#pragma omp parallel num_threads(2)
    csr_before[omp_get_thread_num() & 63] = _mm_getcsr();
    CHECK(kpcn_net_forward(net, in, lg) == KPCN_OK);
#pragma omp parallel num_threads(2)
    csr_after[omp_get_thread_num() & 63] = _mm_getcsr();
    CHECK(_mm_getcsr() == csr_in && memcmp(csr_before, csr_after, sizeof csr_before) == 0);
    double e = rel_err(lg, rl, nout);
    printf("cfg in=%d L=%d C=%d K=%d N=%d %dx%d: fwd %.2e", c->n_in, c->n_hidden, c->ch, c->K, c->N,
           c->H, c->W, e);
    CHECK(e <= 1e-5);
    /* the inference net of the same model (its own layouts; space-to-batch for dilated
     * layers where oneDNN has only a fallback kernel) */
    kpcn_net_options oi = o;
    oi.training = 0, oi.input_grad = 0;
    kpcn_net *inf = NULL;
    {
      kpcn_status si = kpcn_net_create(m, br, &oi, &inf);
      if (si != KPCN_OK) fprintf(stderr, "inference net: %s\n", kpcn_last_error());
      CHECK(si == KPCN_OK);
    }
    float *lgi = malloc(nout * 4);
    if (inf && lgi) {
      CHECK(kpcn_net_forward(inf, in, lgi) == KPCN_OK);
      kpcn_net_stats is;
      kpcn_net_get_stats(inf, &is);
      n_s2b_seen += is.n_space_to_batch;
      double ei = rel_err(lgi, rl, nout);
      printf(" | inference fwd %.2e (%d space-to-batch)", ei, is.n_space_to_batch);
      CHECK(ei <= 1e-5);
    }
    kpcn_net_destroy(inf);
    free(lgi);
    CHECK(kpcn_net_backward(net, dl, din) == KPCN_OK);
    kpcn_param P[2 * KPCN_NN_MAX_LAYERS];
    CHECK(kpcn_net_params(net, P, 2 * KPCN_NN_MAX_LAYERS) == KPCN_OK);
    double ew = 0, eb = 0;
    for (int l = 0; l <= c->n_hidden; l++) {
      double e1 = rel_err(P[2 * l].grad, ref.gw[l], P[2 * l].count);
      double e2 = rel_err(P[2 * l + 1].grad, ref.gb[l], P[2 * l + 1].count);
      ew = e1 > ew ? e1 : ew, eb = e2 > eb ? e2 : eb;
      CHECK(e1 <= 1e-5);
      CHECK(e2 <= 1e-5);
    }
    double ed = rel_err(din, ref.dinput, nin);
    kpcn_net_stats st;
    kpcn_net_get_stats(net, &st);
    printf(" | dW %.2e db %.2e dX %.2e | %s | %d backward-data as forward, %d relayouts, %d "
           "space-to-batch\n",
           ew, eb, ed, kpcn_net_impl_name(net, 1), st.n_bwdd_fwd, st.n_relayout,
           st.n_space_to_batch);
    n_bwdd_fwd_seen += st.n_bwdd_fwd;
    n_s2b_train_seen += st.n_space_to_batch;
    n_relayout_seen += st.n_relayout;
    CHECK(ed <= 1e-5);
    /* same thread count -> bit-identical */
    CHECK(kpcn_net_forward(net, in, lg2) == KPCN_OK);
    CHECK(memcmp(lg, lg2, nout * 4) == 0);
    CHECK(native_backward_same(net, c, in, dl, din));
    kpcn_net_destroy(net);
  }
  /* inference path (ping-pong buffers) gives the same logits, with the default algorithm
   * (Winograd for a 3x3 undilated last layer where oneDNN has it) and direct only */
  o.training = 0;
  for (int direct = 1; direct >= 0; direct--) {
    o.direct_conv = direct;
    CHECK(kpcn_net_create(m, br, &o, &net) == KPCN_OK);
    if (!net) continue;
    CHECK(kpcn_net_forward(net, in, lg2) == KPCN_OK);
    double ei = rel_err(lg2, rl, nout);
    printf("  inference %-7s last layer %-30s fwd %.2e\n", direct ? "direct" : "default",
           kpcn_net_impl_name(net, c->n_hidden), ei);
    CHECK(ei <= 1e-5);
    if (direct) kpcn_net_destroy(net);
  }
  if (net) {
    CHECK(kpcn_net_backward(net, dl, NULL) == KPCN_ERR_INVALID_ARGUMENT);
    /* the logits left in the net's own layout are the same numbers */
    const void *nl;
    kpcn_logits_layout lay;
    CHECK(kpcn_net_forward_logits(net, in, &nl, &lay) == KPCN_OK);
    int same = 1;
    for (int b = 0; b < c->N; b++)
      for (int t = 0; t < K2; t++)
        for (size_t p = 0; p < (size_t)c->H * c->W; p++)
          same &= logit_value(nl, &lay,
                              b * lay.image_stride + (size_t)(t / lay.block) * lay.block_stride +
                                  p * (size_t)lay.pixel_stride + (size_t)(t % lay.block)) ==
                  lg2[((size_t)b * K2 + t) * c->H * c->W + p];
    CHECK(same);
    /* rebound to the other branch, the net computes what a net created for it computes */
    const kpcn_branch other =
        br == KPCN_BRANCH_DIFFUSE ? KPCN_BRANCH_SPECULAR : KPCN_BRANCH_DIFFUSE;
    kpcn_net *n2 = NULL;
    float *la = malloc(nout * 4), *lb = malloc(nout * 4);
    CHECK(kpcn_net_create(m, other, &o, &n2) == KPCN_OK);
    CHECK(kpcn_net_set_branch(net, other) == KPCN_OK);
    CHECK(kpcn_net_forward(net, in, la) == KPCN_OK);
    CHECK(n2 && kpcn_net_forward(n2, in, lb) == KPCN_OK);
    CHECK(memcmp(la, lb, nout * 4) == 0);
    CHECK(memcmp(la, lg2, nout * 4) != 0); /* the two branches' weights differ */
    CHECK(kpcn_net_set_branch(net, (kpcn_branch)2) == KPCN_ERR_INVALID_ARGUMENT);
    CHECK(kpcn_net_set_branch(NULL, other) == KPCN_ERR_INVALID_ARGUMENT);
    kpcn_net_destroy(n2);
    free(la);
    free(lb);
    kpcn_net_destroy(net);
  }
  /* input planes at a padded stride (what the denoiser passes) give the same logits; a
   * stride smaller than a plane is refused */
  const size_t hw = (size_t)c->H * c->W, ps = kpcn_plane_stride(hw);
  CHECK(ps >= hw && ps % 16 == 0 && (ps / 16) % 2 == 1);
  o.input_plane_stride = hw - 1;
  CHECK(kpcn_net_create(m, br, &o, &net) == KPCN_ERR_INVALID_ARGUMENT);
  o.input_plane_stride = ps;
  CHECK(kpcn_net_create(m, br, &o, &net) == KPCN_OK);
  if (net) {
    float *sin = calloc((size_t)c->N * c->n_in * ps, 4), *lg3 = malloc(nout * 4);
    for (size_t q = 0; q < (size_t)c->N * c->n_in; q++)
      memcpy(sin + q * ps, in + q * hw, hw * 4);
    CHECK(kpcn_net_forward(net, sin, lg3) == KPCN_OK);
    CHECK(memcmp(lg3, lg2, nout * 4) == 0);
    free(sin), free(lg3);
    kpcn_net_destroy(net);
  }
  nn_ref_free(&ref);
  kpcn_model_destroy(m);
  free(in), free(lg), free(dl), free(din), free(lg2);
}

/* Central differences in double on the reference validate its analytic backward. */
static void fd_reference(void) {
  cfg c = {4, 2, 6, 3, 2, 7, 6, {3, 5, 3}, {1, 1, 2}};
  kpcn_arch a;
  make_arch(&c, &a);
  kpcn_model *m = NULL;
  kpcn_model_create(&a, 7, &m);
  unsigned rs = 99;
  randomize_bias(m, &rs);
  size_t px = (size_t)c.N * c.H * c.W, nin = px * c.n_in, nout = px * c.K * c.K;
  float *in = malloc(nin * 4), *dl = malloc(nout * 4);
  fill(in, nin, &rs, 1.f);
  fill(dl, nout, &rs, 1.f);
  nn_ref r;
  nn_ref_init(&r, m, KPCN_BRANCH_DIFFUSE, c.N, c.H, c.W);
  nn_ref_forward(&r, in);
  nn_ref_backward(&r, dl);
  int bad = 0, n = 0;
  for (int t = 0; t < 60; t++) {
    int l = (int)(kt_randf(&rs) * (c.n_hidden + 1)) % (c.n_hidden + 1), isb = t % 4 == 0;
    int co = kpcn_arch_layer_out(&a, l), ci = kpcn_arch_layer_in(&a, l), k = a.conv_size[l];
    size_t cnt = isb ? (size_t)co : (size_t)co * ci * k * k;
    size_t i = (size_t)(kt_randf(&rs) * cnt) % cnt;
    double v = nn_ref_get_param(&r, l, isb, i), h = 1e-6, L[2];
    for (int sgn = 0; sgn < 2; sgn++) {
      nn_ref_set_param(&r, l, isb, i, v + (sgn ? -h : h));
      const double *o = nn_ref_forward(&r, in);
      L[sgn] = 0;
      for (size_t j = 0; j < nout; j++)
        L[sgn] += dl[j] * o[j];
    }
    nn_ref_set_param(&r, l, isb, i, v);
    double fd = (L[0] - L[1]) / (2 * h), an = isb ? r.gb[l][i] : r.gw[l][i];
    n++;
    if (fabs(fd - an) > 1e-5 * (1 + fabs(an))) {
      bad++;
      fprintf(stderr, "fd l=%d b=%d i=%zu: fd %.9g analytic %.9g\n", l, isb, i, fd, an);
    }
  }
  /* and the input gradient */
  for (int t = 0; t < 20; t++) {
    size_t i = (size_t)(kt_randf(&rs) * nin) % nin;
    float v = in[i];
    double L[2], h = 1e-3; /* input is float: perturb by an exactly representable step */
    for (int sgn = 0; sgn < 2; sgn++) {
      in[i] = v + (float)(sgn ? -h : h);
      const double *o = nn_ref_forward(&r, in);
      L[sgn] = 0;
      for (size_t j = 0; j < nout; j++)
        L[sgn] += dl[j] * o[j];
    }
    in[i] = v;
    double fd = (L[0] - L[1]) / (2 * h);
    n++;
    if (fabs(fd - r.dinput[i]) > 1e-4 * (1 + fabs(r.dinput[i]))) bad++;
  }
  printf("finite differences on the reference: %d/%d bad\n", bad, n);
  CHECK(bad <= 1); /* a ReLU kink inside [v-h, v+h] may flip one sample */
  nn_ref_free(&r);
  kpcn_model_destroy(m);
  free(in), free(dl);
}

/* Central differences directly on the oneDNN net (fp32, so a loose tolerance): perturb the
 * model's weights in place (the net re-reads them each forward) and compare with backward. */
static void fd_onednn(void) {
  cfg c = {3, 2, 8, 3, 1, 8, 9, {3, 3, 3}, {1, 2, 1}};
  kpcn_arch a;
  make_arch(&c, &a);
  kpcn_model *m = NULL;
  kpcn_model_create(&a, 11, &m);
  unsigned rs = 5;
  randomize_bias(m, &rs);
  size_t px = (size_t)c.H * c.W, nin = px * c.n_in, nout = px * c.K * c.K;
  float *in = malloc(nin * 4), *dl = malloc(nout * 4), *lg = malloc(nout * 4);
  fill(in, nin, &rs, 1.f);
  fill(dl, nout, &rs, 1.f);
  kpcn_net_options o;
  kpcn_net_options_defaults(&o);
  o.height = c.H, o.width = c.W, o.training = 1;
  kpcn_net *net = NULL;
  CHECK(kpcn_net_create(m, KPCN_BRANCH_SPECULAR, &o, &net) == KPCN_OK);
  if (!net) return;
  kpcn_net_forward(net, in, lg);
  kpcn_net_backward(net, dl, NULL);
  kpcn_param P[2 * KPCN_NN_MAX_LAYERS];
  kpcn_net_params(net, P, 2 * KPCN_NN_MAX_LAYERS);
  /* copy the analytic gradients: later forwards do not touch them, but be explicit */
  int bad = 0;
  for (int t = 0; t < 40; t++) {
    kpcn_param *p = &P[t % (2 * (c.n_hidden + 1))];
    size_t i = (size_t)(kt_randf(&rs) * p->count) % p->count;
    float v = p->value[i], h = 2e-3f;
    double L[2];
    for (int sg = 0; sg < 2; sg++) {
      p->value[i] = v + (sg ? -h : h);
      kpcn_net_forward(net, in, lg);
      L[sg] = 0;
      for (size_t j = 0; j < nout; j++)
        L[sg] += (double)dl[j] * lg[j];
    }
    p->value[i] = v;
    double fd = (L[0] - L[1]) / ((double)(float)(v + h) - (double)(float)(v - h));
    if (fabs(fd - p->grad[i]) > 1e-3 + 1e-2 * fabs(p->grad[i])) {
      bad++;
      fprintf(stderr, "onednn fd %s[%zu]: fd %.6g analytic %.6g\n", p->name, i, fd, p->grad[i]);
    }
  }
  printf("finite differences on the oneDNN net: %d/40 bad\n", bad);
  CHECK(bad <= 2); /* a ReLU kink within +-h may flip a sample */
  kpcn_net_destroy(net);
  kpcn_model_destroy(m);
  free(in), free(dl), free(lg);
}

/* bf16 inference vs fp32 on the cpu preset: bounded difference. */
static void bf16_vs_f32(void) {
  if (!kt_have_bf16("bf16 vs f32 nets")) return;
  kpcn_arch a;
  kpcn_model *m = preset_model("cpu", 27, 3, &a);
  const int H = 40, W = 48, K2 = a.kernel_size * a.kernel_size;
  size_t nin = (size_t)27 * H * W, nout = (size_t)K2 * H * W;
  float *in = malloc(nin * 4), *l32 = malloc(nout * 4), *l16 = malloc(nout * 4);
  unsigned rs = 5;
  fill(in, nin, &rs, 1.f);
  kpcn_net_options o;
  kpcn_net_options_defaults(&o);
  o.height = H, o.width = W;
  kpcn_net *n32 = NULL, *n16 = NULL;
  CHECK(kpcn_net_create(m, KPCN_BRANCH_DIFFUSE, &o, &n32) == KPCN_OK);
  o.precision = KPCN_PREC_BF16;
  kpcn_status s = kpcn_net_create(m, KPCN_BRANCH_DIFFUSE, &o, &n16);
  if (s != KPCN_OK) fprintf(stderr, "bf16 net: %s\n", kpcn_last_error());
  CHECK(s == KPCN_OK);
  if (n32 && n16) {
    CHECK(kpcn_net_forward(n32, in, l32) == KPCN_OK);
    CHECK(kpcn_net_forward(n16, in, l16) == KPCN_OK);
    double mx = 0, e = 0, se = 0, s2 = 0;
    for (size_t i = 0; i < nout; i++) {
      double d = fabs((double)l16[i] - l32[i]);
      mx = fabs(l32[i]) > mx ? fabs(l32[i]) : mx;
      e = d > e ? d : e;
      se += d * d, s2 += (double)l32[i] * l32[i];
    }
    double rms_rel = sqrt(se / s2);
    printf("bf16 vs f32 logits: max abs %.3g (max |logit| %.3g), rms rel %.3g, impl %s\n", e, mx,
           rms_rel, kpcn_net_impl_name(n16, 1));
    /* bf16 keeps 8 significant bits (rel. rounding 2^-9 ~ 0.2 %) on 7 layers of inputs
     * and weights: a few 0.1 % rms; 3 % of the largest logit is a generous ceiling. */
    CHECK(rms_rel < 0.02);
    CHECK(e < 0.03 * mx);
    /* left in the net, the logits are bf16, pixel-major, each pixel's K² = 121 in 128 slots
     * (the padded logits layer), and they are the values the planar forward returned */
    const void *nat = NULL;
    kpcn_logits_layout lay;
    CHECK(kpcn_net_forward_logits(n16, in, &nat, &lay) == KPCN_OK);
    printf("bf16 net's own logits: bf16 %d, block %d, pixel stride %d\n", lay.bf16, lay.block,
           lay.pixel_stride);
    CHECK(lay.bf16 == 1 && lay.block == K2 && lay.pixel_stride == 128);
    int same = 1;
    for (int t = 0; t < K2; t++)
      for (size_t p = 0; p < (size_t)H * W; p++)
        same &= logit_value(nat, &lay, p * (size_t)lay.pixel_stride + (size_t)t) ==
                l16[(size_t)t * H * W + p];
    CHECK(same);
    /* the input written pixel-major into the net's own buffer (bf16 rounded to nearest
     * even, as oneDNN's reorder does) and input = NULL: the same logits, bit for bit */
    for (int v = 0; v < 2; v++) {
      kpcn_net *net = v ? n16 : n32;
      const float *want = v ? l16 : l32;
      int ps = 0, bf = -1;
      void *xin = kpcn_net_input_buffer(net, &ps, &bf);
      CHECK(xin != NULL && ps >= 27 && bf == v);
      if (!xin) continue;
      for (size_t p = 0; p < (size_t)H * W; p++)
        for (int c = 0; c < 27; c++) {
          const float x = in[(size_t)c * H * W + p];
          if (bf)
            ((uint16_t *)xin)[p * ps + c] = kt_bf16_round(x);
          else
            ((float *)xin)[p * ps + c] = x;
        }
      float *got = malloc(nout * 4);
      CHECK(kpcn_net_forward(net, NULL, got) == KPCN_OK);
      CHECK(memcmp(got, want, nout * 4) == 0);
      free(got);
    }
  }
  kpcn_net_destroy(n32);
  kpcn_net_destroy(n16);
  kpcn_model_destroy(m);
  free(in), free(l32), free(l16);
}

/* rms(got - ref) / rms(ref): the bf16 error figure (a max-norm bound would be set by the
 * rare element whose bf16 rounding errors all point one way). */
static double rms_rel(const float *got, const double *ref, size_t n) {
  double se = 0, s2 = 0;
  for (size_t i = 0; i < n; i++) {
    const double d = (double)got[i] - ref[i];
    se += d * d, s2 += ref[i] * ref[i];
  }
  return s2 > 0 ? sqrt(se / s2) : sqrt(se);
}

/* Mixed-precision training (bf16 activations, weight copies and output gradients; f32
 * weight/bias gradients) against the double reference, for one linear conv layer and for a
 * cpu-preset-like net of four. The per-pixel terms of a gradient sum mostly cancel (random
 * signs), so a pixel whose pre-activation changes sign under bf16 rounding (its ReLU gate
 * flips) shows as ~1/sqrt(pixels) of the result: with gates the error is a few percent
 * (bound 15 %), without them only rounding (bound 2 %); the exact gradient for another
 * output gradient, as a wrong answer, reads > 100 %. Deterministic run to run. */
static void bf16_training_cfg(const cfg *c, double bound) {
  kpcn_arch a;
  make_arch(c, &a);
  kpcn_model *m = NULL;
  CHECK(kpcn_model_create(&a, 31, &m) == KPCN_OK);
  if (!m) return;
  unsigned rs = 4321;
  randomize_bias(m, &rs);
  const int K2 = c->K * c->K;
  const size_t px = (size_t)c->N * c->H * c->W, nin = px * c->n_in, nout = px * K2;
  float *in = malloc(nin * 4), *dl = malloc(nout * 4), *lg = malloc(nout * 4),
        *din = malloc(nin * 4), *din2 = malloc(nin * 4);
  fill(in, nin, &rs, 1.f);
  kpcn_net_options o;
  kpcn_net_options_defaults(&o);
  o.batch = c->N, o.height = c->H, o.width = c->W, o.training = 1, o.input_grad = 1;
  o.precision = KPCN_PREC_BF16;
  kpcn_net *net = NULL;
  kpcn_status s = kpcn_net_create(m, KPCN_BRANCH_DIFFUSE, &o, &net);
  if (s != KPCN_OK) fprintf(stderr, "bf16 training net: %s\n", kpcn_last_error());
  CHECK(s == KPCN_OK);
  nn_ref ref[2];
  for (int r = 0; net && r < 2; r++) {
    fill(dl, nout, &rs, 1.f);
    nn_ref_init(&ref[r], m, KPCN_BRANCH_DIFFUSE, c->N, c->H, c->W);
    nn_ref_forward(&ref[r], in);
    nn_ref_backward(&ref[r], dl);
  }
  if (net) {
    kpcn_net_stats st;
    kpcn_net_get_stats(net, &st);
    CHECK(st.n_slow == 0);
    CHECK(kpcn_net_forward(net, in, lg) == KPCN_OK);
    CHECK(kpcn_net_backward(net, dl, din) == KPCN_OK);
    const double ef = rms_rel(lg, ref[1].act[c->n_hidden + 1], nout),
                 ed = rms_rel(din, ref[1].dinput, nin);
    kpcn_param P[2 * KPCN_NN_MAX_LAYERS];
    CHECK(kpcn_net_params(net, P, 2 * KPCN_NN_MAX_LAYERS) == KPCN_OK);
    double ew = 0, eb = 0;
    for (int l = 0; l <= c->n_hidden; l++) {
      ew = kt_worst(ew, rms_rel(P[2 * l].grad, ref[1].gw[l], P[2 * l].count));
      eb = kt_worst(eb, rms_rel(P[2 * l + 1].grad, ref[1].gb[l], P[2 * l + 1].count));
    }
    float *g0 = malloc(P[0].count * 4);
    for (size_t i = 0; i < P[0].count; i++)
      g0[i] = (float)ref[0].gw[0][i];
    const double wrong = rms_rel(g0, ref[1].gw[0], P[0].count);
    free(g0);
    printf("bf16 training vs exact, %d layer(s) (rms rel): logits %.3g, dW %.3g, db %.3g, dX %.3g; "
           "a wrong dW %.3g | %s\n",
           c->n_hidden + 1, ef, ew, eb, ed, wrong, kpcn_net_impl_name(net, 0));
    CHECK(ef < 0.02 && ew < bound && eb < bound && ed < bound);
    CHECK(wrong > 1.0);
    CHECK(kpcn_net_forward(net, in, lg) == KPCN_OK);
    CHECK(kpcn_net_backward(net, dl, din2) == KPCN_OK);
    CHECK(memcmp(din, din2, nin * 4) == 0);
    CHECK(native_backward_same(net, c, in, dl, din));
    nn_ref_free(&ref[0]);
    nn_ref_free(&ref[1]);
  }
  kpcn_net_destroy(net);
  kpcn_model_destroy(m);
  free(in), free(dl), free(lg), free(din), free(din2);
}

static void bf16_training(void) {
  if (!kt_have_bf16("bf16 training")) return;
  const cfg linear = {27, 0, 0, 5, 2, 20, 24, {3}, {1}};
  const cfg deep = {27, 3, 48, 5, 2, 20, 24, {3, 3, 3, 3}, {1, 2, 4, 1}};
  bf16_training_cfg(&linear, 0.02);
  bf16_training_cfg(&deep, 0.15);
}

/* A training net with input_grad whose input planes lie input_plane_stride apart writes
 * dinput dense, [N][n_inputs][H][W], as documented (it once wrote it at the input's stride,
 * past the end of a dense buffer): nothing after the dense floats changes, and they equal the
 * dinput of a net reading the same input dense. */
static void dinput_dense_with_stride(void) {
  kpcn_arch a;
  kpcn_model *m = preset_model("tiny", 3, 5, &a);
  if (!m) return;
  unsigned rs = 4242u;
  randomize_bias(m, &rs);
  const int N = 2, H = 8, W = 8, K2 = a.kernel_size * a.kernel_size;
  const size_t hw = (size_t)H * W, ps = kpcn_plane_stride(hw), guard = 1024;
  const size_t nin = (size_t)N * a.n_inputs * hw, nout = (size_t)N * K2 * hw;
  CHECK(ps > hw); /* 64 pixels: 80 floats apart */
  float *in = malloc(nin * 4), *sin = malloc((size_t)N * a.n_inputs * ps * 4);
  float *dl = malloc(nout * 4), *lg = malloc(nout * 4), *lgs = malloc(nout * 4);
  float *dref = malloc(nin * 4), *din = malloc((nin + guard) * 4);
  fill(in, nin, &rs, 1.f);
  fill(dl, nout, &rs, 1.f);
  for (size_t i = 0; i < (size_t)N * a.n_inputs * ps; i++)
    sin[i] = 1e30f; /* the padding between planes, never read */
  for (size_t q = 0; q < (size_t)N * a.n_inputs; q++)
    memcpy(sin + q * ps, in + q * hw, hw * 4);
  const float sentinel = -12345.f;
  for (size_t i = 0; i < nin + guard; i++)
    din[i] = sentinel;
  kpcn_net_options o;
  kpcn_net_options_defaults(&o);
  o.batch = N, o.height = H, o.width = W, o.training = 1, o.input_grad = 1;
  kpcn_net *dense = NULL, *strided = NULL;
  CHECK(kpcn_net_create(m, KPCN_BRANCH_DIFFUSE, &o, &dense) == KPCN_OK);
  o.input_plane_stride = ps;
  CHECK(kpcn_net_create(m, KPCN_BRANCH_DIFFUSE, &o, &strided) == KPCN_OK);
  if (dense && strided) {
    CHECK(kpcn_net_forward(dense, in, lg) == KPCN_OK);
    CHECK(kpcn_net_backward(dense, dl, dref) == KPCN_OK);
    CHECK(kpcn_net_forward(strided, sin, lgs) == KPCN_OK);
    CHECK(memcmp(lg, lgs, nout * 4) == 0);
    CHECK(kpcn_net_backward(strided, dl, din) == KPCN_OK);
    size_t touched = 0, differ = 0;
    for (size_t i = 0; i < guard; i++)
      touched += memcmp(&din[nin + i], &sentinel, 4) != 0;
    for (size_t i = 0; i < nin; i++)
      differ += memcmp(&din[i], &dref[i], 4) != 0;
    printf("dinput with input plane stride %zu (planes of %zu): %zu of %zu floats after the "
           "dense dinput written, %zu of %zu dinput values differ from the dense net's\n",
           ps, hw, touched, guard, differ, nin);
    if (touched || differ)
      fprintf(stderr,
              "kpcn_net_backward with input_plane_stride %zu: dinput not dense "
              "[N][n_inputs][H][W] (%zu floats written past it, %zu values differ)\n",
              ps, touched, differ);
    CHECK(touched == 0);
    CHECK(differ == 0);
  }
  kpcn_net_destroy(dense);
  kpcn_net_destroy(strided);
  kpcn_model_destroy(m);
  free(in), free(sin), free(dl), free(lg), free(lgs), free(dref), free(din);
}

/* The presets must run on optimized oneDNN kernels in every mode we use (a layout mix-up once
 * sent a dilated layer to oneDNN's reference kernel, 100x slower). Creation only. */
static void presets_fast(void) {
  const char *ps[2] = {"cpu", "paper"};
  for (int p = 0; p < 2; p++) {
    kpcn_arch a;
    kpcn_model *m = preset_model(ps[p], 36, 1, &a);
    for (int mode = 0; mode < (kpcn_cpu_allows_avx512() ? 4 : 2); mode++) { /* 2, 3: bf16 */
      kpcn_net_options o;
      kpcn_net_options_defaults(&o);
      o.batch = mode == 0 ? 16 : 1;
      o.height = o.width = mode == 0 ? 64 : 256;
      o.training = mode == 0 || mode == 3;
      o.precision = mode >= 2 ? KPCN_PREC_BF16 : KPCN_PREC_F32;
      if (mode == 3) o.batch = 16, o.height = o.width = 64;
      kpcn_net *n = NULL;
      CHECK(kpcn_net_create(m, KPCN_BRANCH_DIFFUSE, &o, &n) == KPCN_OK);
      kpcn_net_stats st;
      kpcn_net_get_stats(n, &st);
      printf("preset %-5s %-9s: %d slow primitives, layer-1 %s, last layer %s\n", ps[p],
             mode == 0   ? "train"
             : mode == 1 ? "infer f32"
             : mode == 2 ? "infer bf16"
                         : "train bf16",
             st.n_slow, kpcn_net_impl_name(n, 1), kpcn_net_impl_name(n, a.n_hidden));
      CHECK(st.n_slow == 0);
      kpcn_net_destroy(n);
    }
    kpcn_model_destroy(m);
  }
}

/* The fp32 inference nets' layouts: without AVX-512 the cpu preset runs channel-blocked
 * (nChw8c, its logits read in place with block 8), the paper preset, whose first layer would
 * pad by 16 %, pixel-major throughout; with AVX-512 both pixel-major. Never mixed: a relayout
 * buffer costs an activation's memory (net_layer.c, kpcn_net_choose_tags). */
static void inference_layouts(void) {
  const char *ps[2] = {"cpu", "paper"};
  for (int p = 0; p < 2; p++) {
    kpcn_arch a;
    kpcn_model *m = preset_model(ps[p], 36, 1, &a);
    kpcn_net *n = NULL;
    kpcn_net_options o;
    kpcn_net_options_defaults(&o);
    o.height = 24, o.width = 32;
    float *x = calloc((size_t)36 * 24 * 32, sizeof *x);
    const void *lg = NULL;
    kpcn_logits_layout lay = {0};
    kpcn_net_stats st = {0};
    CHECK(x && m && kpcn_net_create(m, KPCN_BRANCH_DIFFUSE, &o, &n) == KPCN_OK &&
          kpcn_net_forward_logits(n, x, &lg, &lay) == KPCN_OK);
    if (n) kpcn_net_get_stats(n, &st);
    const int blocked = p == 0 && !kpcn_cpu_allows_avx512(), K2 = a.kernel_size * a.kernel_size;
    printf("preset %-5s inference layout: block %d, pixel stride %d, %d relayouts\n", ps[p],
           lay.block, lay.pixel_stride, st.n_relayout);
    CHECK(st.n_relayout == 0);
    CHECK(blocked ? lay.block == 8 : lay.block == K2 && lay.pixel_stride >= K2);
    kpcn_net_destroy(n);
    kpcn_model_destroy(m);
    free(x);
  }
}

/* The cpu preset's fp32 inference net on a 1024x540 tile: oneDNN 2.6's Winograd logits layer
 * would schedule its transform over the whole tile there (a scratchpad of ~3x the logits);
 * the net must take the direct convolution instead and hold little more than its
 * activations. The 1024x536 tile keeps Winograd with a small scratchpad. */
static void winograd_scratch_bounded(void) {
  kpcn_arch a;
  kpcn_model *m = preset_model("cpu", 36, 1, &a);
  const int heights[2] = {536, 540};
  for (int i = 0; i < 2; i++) {
    kpcn_net_options o;
    kpcn_net_options_defaults(&o);
    o.width = 1024, o.height = heights[i];
    kpcn_net *n = NULL;
    CHECK(kpcn_net_create(m, KPCN_BRANCH_DIFFUSE, &o, &n) == KPCN_OK);
    if (!n) continue;
    kpcn_net_stats st;
    kpcn_net_get_stats(n, &st);
    /* the largest activations alive at once: two hidden of 48 channels and the logits, 121
     * padded to 128 (nChw16c) */
    const double act = 4.0 * 1024 * heights[i] * (48 + 48 + 128);
    printf("cpu preset 1024x%d inference net: %.0f MiB held (activations %.0f MiB), logits "
           "layer %s\n",
           heights[i], st.bytes / 1048576.0, act / 1048576.0, kpcn_net_impl_name(n, a.n_hidden));
    /* (on AVX2 the dilated layers run by space-to-batch for this; see net_layer.c) */
    CHECK(st.bytes < 2.0 * act);
    /* the guard keeps Winograd where its scratchpad is small (oneDNN has it on AVX-512) */
    if (i == 0 && kpcn_cpu_allows_avx512())
      CHECK(strstr(kpcn_net_impl_name(n, a.n_hidden), "wino") != NULL);
    kpcn_net_destroy(n);
  }
  kpcn_model_destroy(m);
}

/* kpcn_model_widen: the widened model computes the same logits (exactly in the double
 * reference, to rounding in oneDNN), its zero weights from the new channels receive non-zero
 * gradients (the added capacity is trainable), and narrowing is refused. */
static void widen(void) {
  const cfg c = {27, 3, 16, 5, 2, 12, 14, {3, 3, 3, 3}, {1, 2, 4, 1}};
  kpcn_arch a;
  make_arch(&c, &a);
  kpcn_model *m = NULL, *w = NULL, *bad = NULL;
  CHECK(kpcn_model_create(&a, 77, &m) == KPCN_OK);
  if (!m) return;
  unsigned rs = 99;
  randomize_bias(m, &rs);
  CHECK(kpcn_model_set_meta(m, "train.iteration", "123") == KPCN_OK);
  CHECK(kpcn_model_widen(m, 32, 5, &w) == KPCN_OK);
  CHECK(kpcn_model_widen(m, 8, 5, &bad) == KPCN_ERR_INVALID_ARGUMENT && bad == NULL);
  CHECK(strstr(kpcn_last_error(), "channels 8") != NULL);
  if (!w) {
    kpcn_model_destroy(m);
    return;
  }
  CHECK(kpcn_model_arch(w)->channels == 32 && kpcn_model_arch(w)->n_hidden == 3);
  CHECK(kpcn_model_get_meta(w, "train.iteration") != NULL);
  const int K2 = c.K * c.K;
  const size_t px = (size_t)c.N * c.H * c.W, nin = px * c.n_in, nout = px * K2;
  float *in = malloc(nin * 4), *lm = malloc(nout * 4), *lw = malloc(nout * 4),
        *dl = malloc(nout * 4);
  fill(in, nin, &rs, 1.f);
  fill(dl, nout, &rs, 1.f);
  for (int b = 0; b < KPCN_N_BRANCHES; b++) {
    nn_ref rm, rw;
    nn_ref_init(&rm, m, (kpcn_branch)b, c.N, c.H, c.W);
    nn_ref_init(&rw, w, (kpcn_branch)b, c.N, c.H, c.W);
    const double *gm = nn_ref_forward(&rm, in), *gw = nn_ref_forward(&rw, in);
    int same = 1;
    for (size_t i = 0; i < nout; i++)
      same &= gm[i] == gw[i];
    CHECK(same);
    /* gradient of a weight from a new channel into an old unit (layer 2, zero now) */
    nn_ref_backward(&rw, dl);
    kpcn_layer_view v;
    kpcn_model_layer(w, (kpcn_branch)b, 2, &v);
    double zero_w = 0, grad = 0;
    for (int o = 0; o < 16; o++)
      for (int i = 16; i < 32; i++)
        for (int k = 0; k < 9; k++) {
          const size_t j = ((size_t)o * 32 + i) * 9 + k;
          zero_w += fabs(v.weight[j]);
          grad += fabs(rw.gw[2][j]);
        }
    CHECK(zero_w == 0.0 && grad > 0.0);
    nn_ref_free(&rm);
    nn_ref_free(&rw);
    kpcn_net_options o;
    kpcn_net_options_defaults(&o);
    o.batch = c.N, o.height = c.H, o.width = c.W;
    kpcn_net *nm = NULL, *nw = NULL;
    CHECK(kpcn_net_create(m, (kpcn_branch)b, &o, &nm) == KPCN_OK);
    CHECK(kpcn_net_create(w, (kpcn_branch)b, &o, &nw) == KPCN_OK);
    if (nm && nw) {
      CHECK(kpcn_net_forward(nm, in, lm) == KPCN_OK && kpcn_net_forward(nw, in, lw) == KPCN_OK);
      double e = 0, mx = 0;
      for (size_t i = 0; i < nout; i++)
        e = kt_worst(e, fabs((double)lm[i] - lw[i])), mx = fmax(mx, fabs((double)lm[i]));
      printf("widen 16 -> 32 channels, branch %d: reference logits identical: %s, oneDNN %.2e\n", b,
             same ? "yes" : "no", e / mx);
      CHECK(e <= 1e-5 * mx);
    }
    kpcn_net_destroy(nm);
    kpcn_net_destroy(nw);
  }
  free(in);
  free(lm);
  free(lw);
  free(dl);
  kpcn_model_destroy(m);
  kpcn_model_destroy(w);
}

int main(void) {
  presets_fast();
  dinput_dense_with_stride();
  inference_layouts();
  winograd_scratch_bounded();
  widen();
  const cfg cs[] = {
      {3, 1, 16, 3, 2, 12, 10, {3, 3}, {1, 1}},
      {7, 2, 20, 5, 3, 13, 17, {5, 3, 1}, {1, 2, 1}},
      {27, 2, 32, 5, 1, 20, 9, {3, 3, 3}, {2, 4, 1}},
      {5, 0, 0, 3, 2, 8, 8, {5}, {3}},
      {27, 3, 48, 7, 2, 16, 16, {3, 3, 3, 3}, {1, 2, 4, 1}},
      /* dilation 8 (the cpu preset's widest) on 64 x 64: oneDNN 2.6 has no direct f32
       * backward-data kernel for it and the net runs a forward conv with flipped weights
       * instead; a 9-channel input layer without an nChw16c kernel feeds nChw16c layers */
      {9, 2, 48, 3, 1, 64, 64, {3, 3, 3}, {1, 8, 1}},
      /* dilations 4 and 8 with 32 x 24 divisible by both, two images: on AVX2 the inference
       * net runs these layers by space-to-batch (oneDNN has only GEMM for them there) */
      {9, 2, 48, 3, 2, 32, 24, {3, 3, 3}, {4, 8, 1}},
      /* sizes that 4 and 8 do not divide (zero-bordered buffers, padded to 32 x 24 and
       * 28 x 24: two layouts of one buffer) and a 20-channel layer between */
      {9, 3, 24, 3, 1, 30, 21, {3, 3, 3, 3}, {8, 4, 4, 1}},
      /* the cpu preset's dilation-8 layer on a batch of 64 x 64 patches: oneDNN 2.6 has no
       * jit forward for it in nChw16c on AVX-512 (it has at batch 1), so the training net
       * runs it channel-blocked by space-to-batch, as the cpu preset's does */
      {9, 2, 48, 3, 4, 64, 64, {3, 3, 3}, {1, 8, 1}},
  };
  for (size_t i = 0; i < sizeof cs / sizeof cs[0]; i++)
    check_vs_ref(&cs[i], (int)i + 1);
  printf("backward-data as a forward conv: %d layer(s) of these nets\n", n_bwdd_fwd_seen);
  printf("mixed-layout training nets: %d relayout(s)\n", n_relayout_seen);
  /* On AVX-512 CPUs oneDNN 2.6 has no nChw16c kernel for the 9-channel input layer of the last
   * config, so the relayout path above was taken and checked against the reference (elsewhere
   * its own kernels may serve) */
  if (kpcn_cpu_allows_avx512()) CHECK(n_relayout_seen > 0);
  /* Backward-data as a forward conv: oneDNN falls back to GEMM for the dilation-8 layer's
   * backward-data on some CPUs only (Zen 4 yes, an AVX-512 Xeon no), so the path is also taken
   * on purpose, for every layer whose forward is a real kernel, and checked the same way */
  const int bwdd_natural = n_bwdd_fwd_seen;
  kpcn_net_set_bwdd_as_forward_always(1);
  check_vs_ref(&cs[0], 101);
  check_vs_ref(&cs[1], 102);
  check_vs_ref(&cs[5], 103);
  kpcn_net_set_bwdd_as_forward_always(0);
  printf("backward-data as a forward conv: %d layer(s) where oneDNN falls back, %d forced\n",
         bwdd_natural, n_bwdd_fwd_seen - bwdd_natural);
  CHECK(n_bwdd_fwd_seen - bwdd_natural >= 3);
  /* without AVX-512 (or under ONEDNN_MAX_CPU_ISA=AVX2: test_nn_conv_avx2) the last config's
   * dilated layers must have gone through space-to-batch */
  printf("space-to-batch: %d layer(s) of the inference nets, %d of the training nets\n", n_s2b_seen,
         n_s2b_train_seen);
  if (!kpcn_cpu_allows_avx512()) CHECK(n_s2b_seen >= 5 && n_s2b_train_seen >= 5);
  CHECK(n_s2b_train_seen >= 1); /* AVX-512: the single-layer net's backward-weights is GEMM */
  fd_reference();
  fd_onednn();
  bf16_vs_f32();
  bf16_training();
  return kt_summary("test_nn_conv");
}
