/* Kernel-prediction layer: forward vs a naive per-pixel double loop (softmax + clamped
 * K x K weighted sum), backward (dlogits, dnoisy) vs central finite differences, thread-count
 * independence, in-place use and argument checks; the same for several passes. */
#include "core/internal.h"
#include "kpcn/nn.h"
#include "testutil.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

static int clampi(int v, int lo, int hi) { return v < lo ? lo : v > hi ? hi : v; }

/* Naive reference: out[b][c][y][x] = sum_t softmax(l)[t] * noisy[clamp(y+dy-r)][clamp(x+dx-r)].
 * With a non-NULL sw ([n][h][w] source weights), the weighted form: sum_t k_t w(q) noisy(q) /
 * sum_t k_t w(q). lc: logit channels per image (K² or K² + 1). */
static double ref_pixel_sw(int K, int lc, int nc, int h, int w, const float *lg, const double *sw,
                           const float *nz, int b, int c, int y, int x) {
  const int K2 = lc, r = K / 2;
  const size_t pl = (size_t)h * w;
  double mx = -1e300, s = 0, o = 0;
  for (int t = 0; t < K * K; t++) {
    double v = lg[((size_t)b * K2 + t) * pl + (size_t)y * w + x];
    mx = v > mx ? v : mx;
  }
  for (int t = 0; t < K * K; t++)
    s += exp(lg[((size_t)b * K2 + t) * pl + (size_t)y * w + x] - mx);
  double den = 0;
  for (int dy = 0; dy < K; dy++)
    for (int dx = 0; dx < K; dx++) {
      int t = dy * K + dx;
      double wt = exp(lg[((size_t)b * K2 + t) * pl + (size_t)y * w + x] - mx) / s;
      int yy = clampi(y + dy - r, 0, h - 1), xx = clampi(x + dx - r, 0, w - 1);
      double sq = sw ? sw[(size_t)b * pl + (size_t)yy * w + xx] : 1.0;
      o += wt * sq * nz[((size_t)b * nc + c) * pl + (size_t)yy * w + xx];
      den += wt * sq;
    }
  return o / den;
}

static double ref_pixel(int K, int nc, int h, int w, const float *lg, const float *nz, int b, int c,
                        int y, int x) {
  return ref_pixel_sw(K, K * K, nc, h, w, lg, NULL, nz, b, c, y, x);
}

static void fill(float *p, size_t n, unsigned *rs, float lo, float hi) {
  for (size_t i = 0; i < n; i++)
    p[i] = lo + (hi - lo) * kt_randf(rs);
}

static void forward_vs_naive(int K, int n, int nc, int h, int w, float scale) {
  const int K2 = K * K;
  size_t pl = (size_t)h * w, nl = (size_t)n * K2 * pl, nn = (size_t)n * nc * pl;
  float *lg = malloc(nl * 4), *nz = malloc(nn * 4), *out = malloc(nn * 4), *wt = malloc(nl * 4);
  unsigned rs = (unsigned)(K * 131 + h * 7 + w);
  fill(lg, nl, &rs, -scale, scale);
  fill(nz, nn, &rs, 0.f, 2.f);
  CHECK(kpcn_kpa_forward(K, n, nc, h, w, lg, nz, out, wt, 2) == KPCN_OK);
  double e = 0;
  for (int b = 0; b < n; b++)
    for (int c = 0; c < nc; c++)
      for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
          double r = ref_pixel(K, nc, h, w, lg, nz, b, c, y, x);
          double d =
              fabs(out[((size_t)b * nc + c) * pl + (size_t)y * w + x] - r) / (fabs(r) + 1e-3);
          e = d > e ? d : e;
        }
  /* softmax weights sum to 1 per pixel */
  double es = 0;
  for (int b = 0; b < n; b++)
    for (size_t p = 0; p < pl; p++) {
      double s = 0;
      for (int t = 0; t < K2; t++)
        s += wt[((size_t)b * K2 + t) * pl + p];
      es = fabs(s - 1) > es ? fabs(s - 1) : es;
    }
  printf("kpa fwd K=%d n=%d nc=%d %dx%d logit scale %g: rel err %.2e, |sum w - 1| %.2e\n", K, n, nc,
         h, w, (double)scale, e, es);
  CHECK(e <= 1e-5);
  CHECK(es <= 1e-5);
  /* in place (weights aliasing logits) and other thread counts: bit-identical */
  float *out2 = malloc(nn * 4), *lg2 = malloc(nl * 4);
  memcpy(lg2, lg, nl * 4);
  CHECK(kpcn_kpa_forward(K, n, nc, h, w, lg2, nz, out2, lg2, 1) == KPCN_OK);
  CHECK(memcmp(out, out2, nn * 4) == 0);
  CHECK(memcmp(wt, lg2, nl * 4) == 0);
  /* the same logits laid out pixel-major (nhwc, padded to K2+3 per pixel) and channel-
   * blocked (nChw16c and nChw8c, the AVX-512 and AVX2 training nets' layouts, channels padded
   * to a multiple of the block) give bit-identical results; so do bf16 logits (a bf16
   * inference net's: pixel-major padded to a multiple of 16, blocked, planar) against the
   * planar f32 forward of the same values */
  uint16_t *lg16 = malloc(nl * 2);
  float *lgr = malloc(nl * 4), *outr = malloc(nn * 4), *wtr = malloc(nl * 4);
  for (size_t i = 0; i < nl; i++) {
    lg16[i] = kt_bf16_round(lg[i]);
    lgr[i] = kpcn_bf16_to_float(lg16[i]);
  }
  CHECK(kpcn_kpa_forward(K, n, nc, h, w, lgr, nz, outr, wtr, 1) == KPCN_OK);
  const int blocks[6] = {K2, 16, 8, K2, 16, 1},
            pstr[6] = {K2 + 3, 16, 8, (K2 + 15) / 16 * 16, 16, 1};
  for (int v = 0; v < 6; v++) {
    kpcn_logits_layout lay = {0};
    lay.block = blocks[v], lay.pixel_stride = pstr[v], lay.bf16 = v >= 3;
    const int nb = (K2 + lay.block - 1) / lay.block;
    lay.block_stride = pl * (size_t)lay.pixel_stride;
    lay.image_stride = (size_t)nb * lay.block_stride;
    const size_t na = (size_t)n * lay.image_stride;
    float *alt = malloc(na * 4);
    uint16_t *alt16 = (uint16_t *)alt;
    for (size_t i = 0; i < na; i++) /* padding must never be read */
      if (lay.bf16)
        alt16[i] = 0x7f80; /* +inf */
      else
        alt[i] = 1e30f;
    for (int b = 0; b < n; b++)
      for (int t = 0; t < K2; t++)
        for (size_t p = 0; p < pl; p++) {
          const size_t at = b * lay.image_stride + (size_t)(t / lay.block) * lay.block_stride +
                            p * (size_t)lay.pixel_stride + (size_t)(t % lay.block),
                       from = ((size_t)b * K2 + t) * pl + p;
          if (lay.bf16)
            alt16[at] = lg16[from];
          else
            alt[at] = lg[from];
        }
    memset(out2, 0, nn * 4);
    memset(lg2, 0, nl * 4);
    CHECK(kpcn_kpa_forward_layout(K, n, nc, h, w, alt, &lay, nz, out2, lg2, 2) == KPCN_OK);
    CHECK(memcmp(lay.bf16 ? outr : out, out2, nn * 4) == 0);
    CHECK(memcmp(lay.bf16 ? wtr : wt, lg2, nl * 4) == 0);
    if (lay.bf16) { /* backward writes f32 dlogits only */
      CHECK(kpcn_kpa_backward_layout(K, n, nc, h, w, wt, nz, out, alt, &lay, NULL, 1) ==
            KPCN_ERR_INVALID_ARGUMENT);
      lay.bf16 = 2;
      CHECK(kpcn_kpa_forward_layout(K, n, nc, h, w, alt, &lay, nz, out2, NULL, 1) ==
            KPCN_ERR_INVALID_ARGUMENT);
    }
    free(alt);
  }
  free(lg16), free(lgr), free(outr), free(wtr);
  free(lg), free(nz), free(out), free(wt), free(out2), free(lg2);
}

/* L = sum r * out; dL/dlogits and dL/dnoisy vs central differences. Unaffected outputs are
 * bit-identical between the +h and -h evaluations, so summing in double cancels them. */
/* Random logits, noisy image and dL/dout r (seeded), the forward's softmax weights wt and
 * the planar backward's dl, dn: what both backward tests start from. */
typedef struct bwd_case {
  size_t pl, nl, nn;
  float *lg, *nz, *out, *wt, *r, *dl, *dn;
  unsigned rs;
} bwd_case;

static void bwd_case_init(bwd_case *c, int K, int n, int nc, int h, int w, unsigned seed) {
  c->pl = (size_t)h * w, c->nl = (size_t)n * K * K * c->pl, c->nn = (size_t)n * nc * c->pl;
  c->lg = malloc(c->nl * 4), c->nz = malloc(c->nn * 4), c->out = malloc(c->nn * 4);
  c->wt = malloc(c->nl * 4), c->r = malloc(c->nn * 4), c->dl = malloc(c->nl * 4);
  c->dn = malloc(c->nn * 4);
  c->rs = seed;
  fill(c->lg, c->nl, &c->rs, -2.f, 2.f);
  fill(c->nz, c->nn, &c->rs, 0.f, 1.f);
  fill(c->r, c->nn, &c->rs, -1.f, 1.f);
  CHECK(kpcn_kpa_forward(K, n, nc, h, w, c->lg, c->nz, c->out, c->wt, 0) == KPCN_OK);
  CHECK(kpcn_kpa_backward(K, n, nc, h, w, c->wt, c->nz, c->r, c->dl, c->dn, 0) == KPCN_OK);
}

static void bwd_case_free(bwd_case *c) {
  free(c->lg), free(c->nz), free(c->out), free(c->wt), free(c->r), free(c->dl), free(c->dn);
}

static void backward_fd(int K, int n, int nc, int h, int w) {
  bwd_case c;
  bwd_case_init(&c, K, n, nc, h, w, 77u + (unsigned)K);
  const size_t pl = c.pl, nl = c.nl, nn = c.nn;
  float *lg = c.lg, *nz = c.nz, *out = c.out, *wt = c.wt, *r = c.r, *dl = c.dl, *dn = c.dn;
  unsigned rs = c.rs;
  int bad = 0, tot = 0;
  double emax = 0;
  for (int t = 0; t < 400; t++) {
    int wrt_noisy = t & 1;
    float *p = wrt_noisy ? nz : lg;
    size_t cnt = wrt_noisy ? nn : nl;
    /* half the noisy samples on the border rows/columns, where clamped reads accumulate */
    size_t i = (size_t)(kt_randf(&rs) * cnt) % cnt;
    if (wrt_noisy && (t & 2)) i = (i / pl) * pl + (size_t)((t & 4) ? 0 : (h - 1) * w) + i % w;
    float v = p[i];
    const float hh = 1e-2f;
    double L[2];
    for (int s = 0; s < 2; s++) {
      p[i] = v + (s ? -hh : hh);
      kpcn_kpa_forward(K, n, nc, h, w, lg, nz, out, NULL, 1);
      L[s] = 0;
      for (size_t j = 0; j < nn; j++)
        L[s] += (double)r[j] * out[j];
    }
    p[i] = v;
    double step = (double)(float)(v + hh) - (double)(float)(v - hh); /* the float step taken */
    double fd = (L[0] - L[1]) / step;
    double an = wrt_noisy ? dn[i] : dl[i];
    double err = fabs(fd - an);
    emax = err > emax ? err : emax;
    tot++;
    if (err > 2e-4 + 2e-3 * fabs(an)) {
      bad++;
      if (bad < 5)
        fprintf(stderr, "kpa fd %s[%zu]: fd %.7g analytic %.7g\n", wrt_noisy ? "noisy" : "logits",
                i, fd, an);
    }
  }
  printf("kpa bwd K=%d n=%d nc=%d %dx%d: %d/%d finite-difference mismatches, max abs err %.2e\n", K,
         n, nc, h, w, bad, tot, emax);
  CHECK(bad == 0);
  /* dnoisy: sum over all pixels equals sum over outputs of dout (weights sum to 1) */
  for (int b = 0; b < n; b++)
    for (int c = 0; c < nc; c++) {
      double s1 = 0, s2 = 0;
      for (size_t q = 0; q < pl; q++)
        s1 += dn[((size_t)b * nc + c) * pl + q], s2 += r[((size_t)b * nc + c) * pl + q];
      CHECK_NEAR(s1, s2, 1e-4 * (1 + fabs(s2)));
    }
  /* threads: bit-identical; dlogits may alias the weights */
  float *dl2 = malloc(nl * 4), *dn2 = malloc(nn * 4);
  memcpy(dl2, wt, nl * 4);
  CHECK(kpcn_kpa_backward(K, n, nc, h, w, dl2, nz, r, dl2, dn2, 1) == KPCN_OK);
  CHECK(memcmp(dl, dl2, nl * 4) == 0);
  CHECK(memcmp(dn, dn2, nn * 4) == 0);
  free(dl2), free(dn2);
  bwd_case_free(&c);
}

/* kpcn_kpa_backward_layout: dlogits written planar (through the layout), pixel-major (nhwc,
 * padded to K2+3 per pixel) and channel-blocked (nChw16c, nChw8c) hold, slot for slot, the planar
 * kpcn_kpa_backward's values (bit-identical) and zeros in every padding slot; dnoisy is unchanged.
 */
static void backward_layouts(int K, int n, int nc, int h, int w) {
  const int K2 = K * K;
  bwd_case c;
  bwd_case_init(&c, K, n, nc, h, w, 501u + (unsigned)K);
  const size_t pl = c.pl, nl = c.nl, nn = c.nn;
  const float *nz = c.nz, *wt = c.wt, *r = c.r, *dl = c.dl, *dn = c.dn;
  float *dn2 = malloc(nn * 4);
  const int blocks[4] = {1, K2, 16, 8}, pstr[4] = {1, K2 + 3, 16, 8},
            nslots[4] = {1, K2 + 3, 16, 8};
  for (int v = 0; v < 4; v++) {
    kpcn_logits_layout lay = {0};
    lay.block = blocks[v], lay.pixel_stride = pstr[v];
    const int nb = (K2 + lay.block - 1) / lay.block, slots = nslots[v];
    lay.block_stride = pl * (size_t)lay.pixel_stride;
    lay.image_stride = (size_t)nb * lay.block_stride;
    float *alt = malloc((size_t)n * lay.image_stride * 4);
    for (size_t i = 0; i < (size_t)n * lay.image_stride; i++)
      alt[i] = 1e30f; /* every slot must be written */
    CHECK(kpcn_kpa_backward_layout(K, n, nc, h, w, wt, nz, r, alt, &lay, dn2, 2) == KPCN_OK);
    size_t same = 0, zero = 0, pad = 0;
    for (int b = 0; b < n; b++)
      for (int blk = 0; blk < nb; blk++)
        for (size_t p = 0; p < pl; p++)
          for (int j = 0; j < slots; j++) {
            const int t = blk * lay.block + j;
            const float a = alt[b * lay.image_stride + blk * lay.block_stride +
                                p * (size_t)lay.pixel_stride + (size_t)j];
            if (j < lay.block && t < K2) {
              const float e = dl[((size_t)b * K2 + t) * pl + p];
              same += memcmp(&a, &e, 4) == 0;
            } else {
              pad++;
              zero += a == 0.0f;
            }
          }
    printf("kpa bwd layout block %d pixel stride %d, K=%d %dx%d: %zu of %zu dlogits identical, "
           "%zu of %zu padding slots zero\n",
           lay.block, lay.pixel_stride, K, h, w, same, nl, zero, pad);
    CHECK(same == nl);
    CHECK(zero == pad);
    CHECK(memcmp(dn, dn2, nn * 4) == 0);
    CHECK(kpcn_kpa_backward_layout(K, n, nc, h, w, wt, nz, r, c.wt, &lay, NULL, 1) ==
          KPCN_ERR_INVALID_ARGUMENT); /* may not alias the weights */
    free(alt);
  }
  free(dn2);
  bwd_case_free(&c);
}

/* kpcn_kpa_forward_passes / backward_passes (arch.kpa_passes, arch.source_weight): the forward
 * equals the naive reference applied `passes` times with the same logits (the first pass
 * weighted by w = e + (1-e)·sigmoid(score) when sw); dL/dlogits of the whole chain, the score
 * channel included, equals central differences; a channel-blocked layout gives the planar
 * dlogits slot for slot with zero padding. */
static void passes_check(int K, int passes, int sw, int n, int nc, int h, int w) {
  const int K2 = K * K, LC = K2 + sw;
  const size_t pl = (size_t)h * w, nl = (size_t)n * LC * pl, nn = (size_t)n * nc * pl;
  const size_t nwt = (size_t)n * K2 * pl;
  const kpcn_logits_layout planar = kpcn_logits_layout_planar(LC, h, w);
  float *lg = malloc(nl * 4), *nz = malloc(nn * 4), *out = malloc(nn * 4), *wt = malloc(nwt * 4);
  float *mid = malloc(kpcn_kpa_passes_mid_floats(passes, sw, n, nc, h, w) * 4 + 4);
  float *r = malloc(nn * 4), *dl = malloc(nl * 4), *a = malloc(nn * 4), *bb = malloc(nn * 4);
  float *scr = malloc(kpcn_kpa_passes_scratch_floats(passes, sw, n, nc, h, w, &planar) * 4 + 4);
  double *swv = malloc((size_t)n * pl * sizeof(double));
  unsigned rs = 900u + (unsigned)(K * passes + 7 * sw);
  fill(lg, nl, &rs, -2.f, 2.f);
  fill(nz, nn, &rs, 0.f, 1.f);
  fill(r, nn, &rs, -1.f, 1.f);
  if (sw) {
    nz[nn / 2] = 8.f; /* an outlier the score can drop */
    for (int b = 0; b < n; b++)
      for (size_t q = 0; q < pl; q++) {
        double s = lg[((size_t)b * LC + K2) * pl + q];
        swv[(size_t)b * pl + q] = 1e-3 + (1 - 1e-3) / (1 + exp(-s));
      }
  }
  CHECK(kpcn_kpa_forward_passes(K, passes, sw, n, nc, h, w, lg, &planar, nz, mid, out, wt, 2) ==
        KPCN_OK);
  /* naive: each pass through ref_pixel_sw, the intermediate rounded to float as the layer does */
  memcpy(a, nz, nn * 4);
  for (int p = 0; p < passes; p++) {
    for (int b = 0; b < n; b++)
      for (int c = 0; c < nc; c++)
        for (int y = 0; y < h; y++)
          for (int x = 0; x < w; x++)
            bb[((size_t)b * nc + c) * pl + (size_t)y * w + x] =
                (float)ref_pixel_sw(K, LC, nc, h, w, lg, p == 0 && sw ? swv : NULL, a, b, c, y, x);
    memcpy(a, bb, nn * 4);
  }
  double e = 0;
  for (size_t i = 0; i < nn; i++) {
    double d = fabs(out[i] - a[i]) / (fabs(a[i]) + 1e-3);
    e = d > e ? d : e;
  }
  CHECK(e <= 1e-5);
  CHECK(kpcn_kpa_backward_passes(K, passes, sw, n, nc, h, w, wt, nz, mid, r, dl, &planar, scr, 2) ==
        KPCN_OK);
  /* 150 random logits, then (with sw) 40 source scores */
  int bad = 0, nfd = 150 + (sw ? 40 : 0);
  double emax = 0;
  for (int t = 0; t < nfd; t++) {
    size_t i = (size_t)(kt_randf(&rs) * nl) % nl;
    if (t >= 150) {
      size_t q = (size_t)(kt_randf(&rs) * (double)(n * pl)) % (n * pl);
      i = ((q / pl) * LC + K2) * pl + q % pl;
    }
    float v = lg[i];
    const float hh = 1e-2f;
    double L[2];
    for (int sg = 0; sg < 2; sg++) {
      lg[i] = v + (sg ? -hh : hh);
      CHECK(kpcn_kpa_forward_passes(K, passes, sw, n, nc, h, w, lg, &planar, nz, mid, bb, NULL,
                                    1) == KPCN_OK);
      L[sg] = 0;
      for (size_t j = 0; j < nn; j++)
        L[sg] += (double)r[j] * bb[j];
    }
    lg[i] = v;
    double fd = (L[0] - L[1]) / ((double)(float)(v + hh) - (double)(float)(v - hh));
    double err = fabs(fd - dl[i]);
    emax = err > emax ? err : emax;
    if (err > 2e-4 + 2e-3 * fabs(dl[i])) {
      bad++;
      printf("  fd mismatch at %zu (t %zu): fd %.6e analytic %.6e\n", i, (i / pl) % LC, fd, dl[i]);
    }
  }
  /* the forward above left mid as the unperturbed forward's: redo it for the layout check */
  CHECK(kpcn_kpa_forward_passes(K, passes, sw, n, nc, h, w, lg, &planar, nz, mid, out, wt, 2) ==
        KPCN_OK);
  kpcn_logits_layout blk = {0, 0, 16, 16, 0};
  blk.block_stride = pl * 16;
  blk.image_stride = (size_t)((LC + 15) / 16) * blk.block_stride;
  float *lgb = malloc((size_t)n * blk.image_stride * 4), *outb = malloc(nn * 4);
  for (int b = 0; b < n; b++)
    for (int t = 0; t < (LC + 15) / 16 * 16; t++)
      for (size_t q = 0; q < pl; q++)
        lgb[b * blk.image_stride + (size_t)(t / 16) * blk.block_stride + q * 16 + t % 16] =
            t < LC ? lg[((size_t)b * LC + t) * pl + q] : 0.f;
  CHECK(kpcn_kpa_forward_passes(K, passes, sw, n, nc, h, w, lgb, &blk, nz, mid, outb, wt, 1) ==
        KPCN_OK);
  CHECK(memcmp(out, outb, nn * 4) == 0);
  float *dlb = malloc((size_t)n * blk.image_stride * 4);
  float *scr2 = malloc(kpcn_kpa_passes_scratch_floats(passes, sw, n, nc, h, w, &blk) * 4 + 4);
  CHECK(kpcn_kpa_backward_passes(K, passes, sw, n, nc, h, w, wt, nz, mid, r, dlb, &blk, scr2, 1) ==
        KPCN_OK);
  int lay_bad = 0;
  for (int b = 0; b < n; b++)
    for (int t = 0; t < (LC + 15) / 16 * 16; t++)
      for (size_t q = 0; q < pl; q++) {
        float v = dlb[b * blk.image_stride + (size_t)(t / 16) * blk.block_stride + q * 16 + t % 16];
        if (t >= LC) { /* padding */
          lay_bad += v != 0.f;
          continue;
        }
        float ref = dl[((size_t)b * LC + t) * pl + q];
        lay_bad += fabsf(v - ref) > 1e-6f * (1 + fabsf(ref));
      }
  printf("kpa %d passes%s K=%d n=%d nc=%d %dx%d: fwd rel err %.2e, %d/%d fd mismatches (max "
         "%.2e), %d blocked-layout mismatches\n",
         passes, sw ? " + source weights" : "", K, n, nc, h, w, e, bad, nfd, emax, lay_bad);
  CHECK(bad == 0);
  CHECK(lay_bad == 0);
  CHECK(kpcn_kpa_forward_passes(K, passes, sw, n, nc, h, w, lg, &planar, nz, NULL, out, NULL, 1) ==
        (passes > 1 || sw ? KPCN_ERR_INVALID_ARGUMENT : KPCN_OK));
  free(lg), free(nz), free(out), free(wt), free(mid), free(r), free(dl), free(a), free(bb);
  free(scr), free(dlb), free(scr2), free(swv), free(lgb), free(outb);
}

/* s must be KPCN_ERR_INVALID_ARGUMENT; otherwise says which call (what) returned what. */
static void expect_invalid(kpcn_status s, const char *what) {
  if (s != KPCN_ERR_INVALID_ARGUMENT)
    fprintf(stderr, "%s: %s, expected invalid argument\n", what, kpcn_status_string(s));
  CHECK(s == KPCN_ERR_INVALID_ARGUMENT);
}

/* The source-weighted layer and the pass chain refuse a bad logits layout before they index
 * through it: block 0 (score_at divides by it: SIGFPE before they checked), pixel stride 0, a
 * pixel stride that makes a pixel's score channel its neighbour's first logit, and (backward,
 * two passes, where the scratch layout reads its image stride) a NULL layout. */
static void layout_argument_checks(void) {
  const int K = 3, K2 = K * K, n = 1, nc = 3, h = 4, w = 4;
  const size_t pl = (size_t)h * w;
  const kpcn_logits_layout planar = kpcn_logits_layout_planar(K2 + 1, h, w);
  const size_t nbuf = 4 * (size_t)n * (nc + 1) * (K2 + 2) * pl +
                      kpcn_kpa_passes_mid_floats(2, 1, n, nc, h, w) +
                      kpcn_kpa_passes_scratch_floats(2, 1, n, nc, h, w, &planar);
  float *lg = calloc(nbuf, 4), *nz = calloc(nbuf, 4), *mid = calloc(nbuf, 4);
  float *src1 = calloc(nbuf, 4), *acc1 = calloc(nbuf, 4), *out = calloc(nbuf, 4);
  float *wt = calloc(nbuf, 4), *dl = calloc(nbuf, 4), *scr = calloc(nbuf, 4);
  kpcn_logits_layout bad[3] = {planar, planar, planar};
  const char *what[3] = {"block 0", "pixel stride 0", "pixel stride K2 < K2 + 1 logits"};
  bad[0].block = 0;
  bad[1].pixel_stride = 0;
  bad[2].block = K2 + 1, bad[2].pixel_stride = K2; /* pixel-major, a channel short */
  bad[2].block_stride = pl * (size_t)(K2 + 1), bad[2].image_stride = bad[2].block_stride;
  char call[160];
  for (int v = 0; v < 3; v++) {
    /* printed first: before the checks a bad layout could crash the calls below */
    printf("kpa layout check: source weight, %s\n", what[v]);
    fflush(stdout);
    snprintf(call, sizeof call, "kpcn_kpa_forward_weighted, layout %s", what[v]);
    expect_invalid(
        kpcn_kpa_forward_weighted(K, n, nc, h, w, lg, &bad[v], nz, src1, acc1, out, NULL, 1), call);
    for (int passes = 1; passes <= 2; passes++) {
      snprintf(call, sizeof call, "kpcn_kpa_forward_passes (%d passes), layout %s", passes,
               what[v]);
      expect_invalid(
          kpcn_kpa_forward_passes(K, passes, 1, n, nc, h, w, lg, &bad[v], nz, mid, out, wt, 1),
          call);
      snprintf(call, sizeof call, "kpcn_kpa_backward_passes (%d passes), layout %s", passes,
               what[v]);
      expect_invalid(kpcn_kpa_backward_passes(K, passes, 1, n, nc, h, w, wt, nz, mid, out, dl,
                                              &bad[v], scr, 1),
                     call);
    }
  }
  /* the valid layout passes the same checks (a forward of zero logits, then its backward) */
  CHECK(kpcn_kpa_forward_passes(K, 2, 1, n, nc, h, w, lg, &planar, nz, mid, out, wt, 1) == KPCN_OK);
  CHECK(kpcn_kpa_backward_passes(K, 2, 1, n, nc, h, w, wt, nz, mid, out, dl, &planar, scr, 1) ==
        KPCN_OK);
  printf("kpa layout check: NULL layout\n");
  fflush(stdout);
  expect_invalid(kpcn_kpa_backward_passes(K, 2, 0, n, nc, h, w, wt, nz, mid, out, dl, NULL, scr, 1),
                 "kpcn_kpa_backward_passes (2 passes), NULL layout");
  const size_t sf = kpcn_kpa_passes_scratch_floats(2, 1, n, nc, h, w, NULL);
  if (sf != 0) fprintf(stderr, "kpcn_kpa_passes_scratch_floats(NULL layout) = %zu, not 0\n", sf);
  CHECK(sf == 0);
  free(lg), free(nz), free(mid), free(src1), free(acc1), free(out), free(wt), free(dl), free(scr);
}

int main(void) {
  forward_vs_naive(3, 1, 3, 5, 4, 2.f);
  forward_vs_naive(5, 2, 3, 9, 13, 4.f);
  forward_vs_naive(11, 1, 3, 16, 7, 3.f);   /* K larger than the image height: clamping */
  forward_vs_naive(21, 1, 1, 30, 33, 50.f); /* large logits: the stable softmax path */
  forward_vs_naive(5, 1, 3, 6, 150, 4.f);   /* rows of several 64-pixel chunks, a partial last */
  forward_vs_naive(11, 1, 4, 3, 70, 3.f);   /* RGB + one more channel, chunk edge at 64 */
  backward_fd(3, 2, 3, 6, 5);
  backward_fd(5, 1, 3, 7, 9);
  backward_fd(7, 1, 2, 4, 11);
  backward_layouts(3, 2, 3, 6, 5);
  backward_layouts(7, 1, 3, 4, 11);  /* K2 = 49: three whole blocks of 16 and one tap */
  backward_layouts(11, 2, 3, 5, 37); /* the cpu preset's K, 8 x 8 transposes plus edges */
  passes_check(3, 1, 0, 1, 3, 6, 5);
  passes_check(3, 2, 0, 2, 3, 6, 5);
  passes_check(5, 3, 0, 1, 3, 7, 9);
  passes_check(11, 2, 0, 1, 3, 9, 13); /* K larger than the image: clamped reads every pass */
  passes_check(3, 1, 1, 2, 3, 6, 5);   /* source weights: one pass, two images */
  passes_check(5, 2, 1, 1, 3, 7, 9);   /* source weights, then a plain second pass */
  passes_check(11, 2, 1, 2, 3, 9, 13); /* the cpu preset's K: score in a 16-block's padding */
  layout_argument_checks();
  float x = 0;
  CHECK(kpcn_kpa_forward(4, 1, 3, 4, 4, &x, &x, &x, NULL, 1) == KPCN_ERR_INVALID_ARGUMENT);
  CHECK(kpcn_kpa_forward(3, 1, 3, 0, 4, &x, &x, &x, NULL, 1) != KPCN_OK);
  CHECK(kpcn_kpa_backward(3, 1, 3, 4, 4, NULL, &x, &x, &x, NULL, 1) == KPCN_ERR_INVALID_ARGUMENT);
  kpcn_logits_layout bad = {16, 16, 16, 4, 0}; /* pixels overlapping inside a block */
  CHECK(kpcn_kpa_forward_layout(3, 1, 3, 4, 4, &x, &bad, &x, &x, NULL, 1) ==
        KPCN_ERR_INVALID_ARGUMENT);
  /* ctest runs this test twice: as is, and as test_nn_kpa_avx2 with ONEDNN_MAX_CPU_ISA=AVX2,
   * which must have sent every check above through the AVX2 / scalar kernels. */
  const char *cap = getenv("ONEDNN_MAX_CPU_ISA");
  if (cap && strcasecmp(cap, "AVX2") == 0) CHECK(!kpcn_cpu_allows_avx512());
  printf("kernel layer kernels: %s\n", kpcn_cpu_allows_avx512() ? "AVX-512" : "AVX2 / scalar");
  return kt_summary("test_nn_kpa");
}
