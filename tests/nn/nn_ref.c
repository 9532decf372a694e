/* Direct convolution loops in double: the independent truth for the oneDNN net. */
#include "nn_ref.h"

#include <stdlib.h>
#include <string.h>

static size_t wcount(const kpcn_arch *a, int l) {
  return (size_t)kpcn_arch_layer_out(a, l) * kpcn_arch_layer_in(a, l) * a->conv_size[l] *
         a->conv_size[l];
}

void nn_ref_init(nn_ref *r, kpcn_model *m, kpcn_branch b, int n, int h, int w) {
  memset(r, 0, sizeof *r);
  r->a = kpcn_model_arch(m);
  r->n = n, r->h = h, r->w = w, r->nl = r->a->n_hidden + 1;
  size_t px = (size_t)n * h * w;
  r->act[0] = calloc(px * r->a->n_inputs, sizeof(double));
  r->dinput = calloc(px * r->a->n_inputs, sizeof(double));
  for (int l = 0; l < r->nl; l++) {
    kpcn_layer_view v;
    kpcn_model_layer(m, b, l, &v);
    size_t nw = wcount(r->a, l);
    double *wt = malloc(nw * sizeof(double)), *bs = malloc((size_t)v.out_ch * sizeof(double));
    for (size_t i = 0; i < nw; i++)
      wt[i] = v.weight[i];
    for (int i = 0; i < v.out_ch; i++)
      bs[i] = v.bias[i];
    r->wt[l] = wt, r->bs[l] = bs;
    r->act[l + 1] = calloc(px * v.out_ch, sizeof(double));
    r->gw[l] = calloc(nw, sizeof(double));
    r->gb[l] = calloc((size_t)v.out_ch, sizeof(double));
  }
}

void nn_ref_free(nn_ref *r) {
  for (int l = 0; l < r->nl; l++) {
    free((void *)r->wt[l]), free((void *)r->bs[l]), free(r->act[l + 1]);
    free(r->gw[l]), free(r->gb[l]);
  }
  free(r->act[0]), free(r->dinput);
}

void nn_ref_set_param(nn_ref *r, int l, int isb, size_t i, double v) {
  ((double *)(isb ? r->bs[l] : r->wt[l]))[i] = v;
}
double nn_ref_get_param(nn_ref *r, int l, int isb, size_t i) {
  return (isb ? r->bs[l] : r->wt[l])[i];
}

#define AT(p, C, c, y, x) (p)[(((size_t)b * (C) + (c)) * H + (y)) * W + (x)]

const double *nn_ref_forward(nn_ref *r, const float *input) {
  const kpcn_arch *a = r->a;
  const int N = r->n, H = r->h, W = r->w;
  for (size_t i = 0; i < (size_t)N * H * W * a->n_inputs; i++)
    r->act[0][i] = input[i];
  for (int l = 0; l < r->nl; l++) {
    const int ci = kpcn_arch_layer_in(a, l), co = kpcn_arch_layer_out(a, l);
    const int k = a->conv_size[l], d = a->dilation[l], p = d * (k - 1) / 2;
    const double *src = r->act[l], *wt = r->wt[l];
    double *dst = r->act[l + 1];
    for (int b = 0; b < N; b++)
      for (int o = 0; o < co; o++)
        for (int y = 0; y < H; y++)
          for (int x = 0; x < W; x++) {
            double s = r->bs[l][o];
            for (int i = 0; i < ci; i++)
              for (int ky = 0; ky < k; ky++)
                for (int kx = 0; kx < k; kx++) {
                  int yy = y + ky * d - p, xx = x + kx * d - p;
                  if (yy < 0 || yy >= H || xx < 0 || xx >= W) continue;
                  s += wt[(((size_t)o * ci + i) * k + ky) * k + kx] * AT(src, ci, i, yy, xx);
                }
            if (l < a->n_hidden && s < 0) s = 0;
            AT(dst, co, o, y, x) = s;
          }
  }
  return r->act[r->nl];
}

void nn_ref_backward(nn_ref *r, const float *dlogits) {
  const kpcn_arch *a = r->a;
  const int N = r->n, H = r->h, W = r->w;
  size_t px = (size_t)N * H * W;
  int cl = kpcn_arch_layer_out(a, r->nl - 1);
  double *g = malloc(px * cl * sizeof(double));
  for (size_t i = 0; i < px * cl; i++)
    g[i] = dlogits[i];
  for (int l = r->nl - 1; l >= 0; l--) {
    const int ci = kpcn_arch_layer_in(a, l), co = kpcn_arch_layer_out(a, l);
    const int k = a->conv_size[l], d = a->dilation[l], p = d * (k - 1) / 2;
    const double *src = r->act[l], *dst = r->act[l + 1], *wt = r->wt[l];
    if (l < a->n_hidden) /* ReLU: gradient passes where the output was positive */
      for (size_t i = 0; i < px * co; i++)
        if (!(dst[i] > 0)) g[i] = 0;
    double *gs = calloc(px * ci, sizeof(double));
    memset(r->gw[l], 0, wcount(a, l) * sizeof(double));
    memset(r->gb[l], 0, (size_t)co * sizeof(double));
    for (int b = 0; b < N; b++)
      for (int o = 0; o < co; o++)
        for (int y = 0; y < H; y++)
          for (int x = 0; x < W; x++) {
            double gv = AT(g, co, o, y, x);
            r->gb[l][o] += gv;
            for (int i = 0; i < ci; i++)
              for (int ky = 0; ky < k; ky++)
                for (int kx = 0; kx < k; kx++) {
                  int yy = y + ky * d - p, xx = x + kx * d - p;
                  if (yy < 0 || yy >= H || xx < 0 || xx >= W) continue;
                  size_t wi = (((size_t)o * ci + i) * k + ky) * k + kx;
                  r->gw[l][wi] += gv * AT(src, ci, i, yy, xx);
                  AT(gs, ci, i, yy, xx) += gv * wt[wi];
                }
          }
    free(g);
    g = gs;
  }
  memcpy(r->dinput, g, px * a->n_inputs * sizeof(double));
  free(g);
}
