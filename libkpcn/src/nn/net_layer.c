/* One conv layer of a kpcn_net: its activation layout (choose_tag), its forward primitive
 * (direct, or Winograd for an fp32 inference logits layer) and, for training nets, its
 * backward-weights, backward-data (or a forward conv standing in for it) and ReLU-backward
 * primitives, with the weight reorders from the model's OIHW arrays. See net.c for the
 * net as a whole. */
#include "nn/net_internal.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* Winograd F(2,3) for the logits layer when it is 3x3 undilated (fp32 inference): oneDNN
 * implements it only on channel-blocked (nChw16c) activations, so the layer gets its own
 * input layout (build_layer adds the reorder from the previous layer's) and writes blocked
 * logits, which the kpa layer reads in place. Measured on the cpu preset (1024x534 tiles,
 * Zen 4): 48->121 channels 182 ms instead of ~300 direct (+18 ms for the input reorder);
 * the 36->48 first layer was slower than direct (97 vs ~88 ms, plus a reorder), and
 * inner layers would pay two reorders, so only the last layer uses it. Not an error when
 * oneDNN has no such kernel (other ISAs): y->winograd stays 0 and the layer is built
 * direct. */
static kpcn_status try_winograd(kpcn_net *n, int l, dnnl_memory_desc_t wany, dnnl_memory_desc_t bmd,
                                size_t *scratch) {
  layer *y = &n->L[l];
  dnnl_dims_t sd = {n->o.batch, y->cin, n->o.height, n->o.width};
  dnnl_dims_t dd = {n->o.batch, y->cout, n->o.height, n->o.width};
  dnnl_dims_t strides = {1, 1}, dil = {0, 0}, pad = {1, 1};
  dnnl_memory_desc_t smd, dmd;
  DN(dnnl_memory_desc_init_by_tag(&smd, 4, sd, dnnl_f32, dnnl_nChw16c));
  DN(dnnl_memory_desc_init_by_tag(&dmd, 4, dd, dnnl_f32, dnnl_nChw16c));
  dnnl_convolution_desc_t cd;
  DN(dnnl_dilated_convolution_forward_desc_init(&cd, dnnl_forward_inference,
                                                dnnl_convolution_winograd, &smd, &wany, &bmd, &dmd,
                                                strides, dil, pad, pad));
  if (dnnl_primitive_desc_create(&y->fwd_pd, &cd, y->has_relu ? n->attr_relu : n->attr, n->eng,
                                 NULL) != dnnl_success) {
    y->fwd_pd = NULL;
    return KPCN_OK;
  }
  size_t s = kpcn_net_pd_scratch(y->fwd_pd);
  /* For some sizes (a 1024x540 tile of the cpu preset's logits layer) oneDNN 2.6 schedules
   * the Winograd transform over the whole image, with a scratchpad of about 3x the layer's
   * output; the direct convolution is then the better trade (a few % slower, no 0.9 GB). */
  const size_t dst_bytes = sizeof(float) * (size_t)n->o.batch * (size_t)((y->cout + 15) & ~15) *
                           (size_t)n->o.height * (size_t)n->o.width;
  if (s > dst_bytes) {
    dnnl_primitive_desc_destroy(y->fwd_pd);
    y->fwd_pd = NULL;
    return KPCN_OK;
  }
  if (s > *scratch) *scratch = s;
  y->winograd = 1;
  return KPCN_OK;
}

int kpcn_net_impl_is(const_dnnl_primitive_desc_t pd, const char *prefix) {
  const char *impl = NULL;
  return dnnl_primitive_desc_query(pd, dnnl_query_impl_info_str, 0, &impl) == dnnl_success &&
         impl && !strncmp(impl, prefix, strlen(prefix));
}

/* oneDNN's generic fallbacks (reference loops, im2col + GEMM) rather than a direct kernel */
static int is_fallback(const_dnnl_primitive_desc_t pd) {
  return kpcn_net_impl_is(pd, "ref") || kpcn_net_impl_is(pd, "gemm") ||
         kpcn_net_impl_is(pd, "x64:gemm");
}

/* *slot (a primitive descriptor made by kpcn_net_make_pd) replaced by pd, a better kernel for
 * the same job: the slow-kernel count forgets the old one, the scratchpad covers the new. */
static void replace_pd(kpcn_net *n, dnnl_primitive_desc_t *slot, dnnl_primitive_desc_t pd,
                       size_t *scratch) {
  if (kpcn_net_impl_is(*slot, "ref")) n->n_slow--; /* make_pd counted the one replaced */
  dnnl_primitive_desc_destroy(*slot);
  *slot = pd;
  const size_t s = kpcn_net_pd_scratch(pd);
  if (s > *scratch) *scratch = s;
}

/* The gradient of a stride-1 "same" convolution with respect to its input is the forward
 * convolution of the output gradient with the weights transposed (in <-> out channels) and
 * flipped in space, at the same dilation and padding. Where oneDNN 2.6 has no direct
 * backward-data kernel for a layer (f32 nhwc with dilation 8 on 64 x 64 patches: it falls back
 * to im2col + GEMM, 18.5 ms a call against 8.5 for the forward brgconv), the layer's
 * backward-data runs as that forward primitive instead (y->bwdd_pd replaced, y->bwdd_fwd
 * set; the flipped OIHW weights are built in y->wflip before each use). Kept only when the
 * forward kernel is not itself a fallback. *iohw: the flipped weights' user descriptor. */
static int g_bwdd_as_forward_always;
void kpcn_net_set_bwdd_as_forward_always(int on) { g_bwdd_as_forward_always = on != 0; }

static kpcn_status try_bwdd_as_forward(kpcn_net *n, int l, const dnnl_dims_t strides,
                                       const dnnl_dims_t dil, const dnnl_dims_t pl,
                                       const dnnl_dims_t pr, dnnl_memory_desc_t *iohw,
                                       size_t *scratch) {
  layer *y = &n->L[l];
  if (!g_bwdd_as_forward_always && !is_fallback(y->bwdd_pd)) return KPCN_OK;
  dnnl_dims_t wd = {y->cin, y->cout, y->k, y->k};
  dnnl_memory_desc_t wany;
  DN(dnnl_memory_desc_init_by_tag(&wany, 4, wd, dnnl_f32, dnnl_format_tag_any));
  DN(dnnl_memory_desc_init_by_tag(iohw, 4, wd, dnnl_f32, dnnl_oihw));
  dnnl_convolution_desc_t cd;
  DN(dnnl_dilated_convolution_forward_desc_init(&cd, dnnl_forward_inference,
                                                dnnl_convolution_direct, &y->ddst_md, &wany, NULL,
                                                &y->src_md, strides, dil, pl, pr));
  dnnl_primitive_desc_t pd;
  if (dnnl_primitive_desc_create(&pd, &cd, n->attr, n->eng, NULL) != dnnl_success) return KPCN_OK;
  const dnnl_memory_desc_t *s = dnnl_primitive_desc_query_md(pd, dnnl_query_src_md, 0),
                           *d = dnnl_primitive_desc_query_md(pd, dnnl_query_dst_md, 0);
  if (is_fallback(pd) || !s || !d || !dnnl_memory_desc_equal(s, &y->ddst_md) ||
      !dnnl_memory_desc_equal(d, &y->src_md)) {
    dnnl_primitive_desc_destroy(pd);
    return KPCN_OK;
  }
  y->wflip =
      kpcn_net_alloc(n, sizeof(float) * (size_t)y->cin * y->cout * y->k * y->k, "net weights");
  if (!y->wflip) {
    dnnl_primitive_desc_destroy(pd);
    return KPCN_ERR_OUT_OF_MEMORY;
  }
  replace_pd(n, &y->bwdd_pd, pd, scratch);
  y->bwdd_fwd = 1;
  n->n_bwdd_fwd++;
  return KPCN_OK;
}

/* wflip[i][o][a][b] = w[o][i][k-1-a][k-1-b] */
void kpcn_net_flip_weights(const layer *y, const float *w) {
  const int k = y->k, kk = k * k;
  for (int o = 0; o < y->cout; o++)
    for (int i = 0; i < y->cin; i++)
      for (int t = 0; t < kk; t++)
        y->wflip[((size_t)i * y->cout + o) * kk + (kk - 1 - t)] =
            w[((size_t)o * y->cin + i) * kk + t];
}

/* Space-to-batch views. An activation laid out nhwc or channel-blocked (nChwBc) is, with
 * channels split as Cb x B (nhwc: one block, B = C), N x Cb x H x W blocks of B floats. */
static int s2b_block(const layer *y, int C) {
  return y->tag == dnnl_nChw16c ? 16 : y->tag == dnnl_nChw8c ? 8 : C;
}

/* A 7-D view of an N x C x H x W activation as N x Cb x B x H/d x d x W/d x d (row = hs*d + dy,
 * column = ws*d + dx): whole (sub = 0) or as the d*d sub-images (dy, dx) of the batch
 * (dy*d + dx)*N + n, each H/d x W/d in the same layout (sub = 1). A reorder between the two
 * is the space-to-batch gather (or its inverse). */
static kpcn_status s2b_view(dnnl_memory_desc_t *md, int N, int C, int B, int H, int W, int d,
                            int sub) {
  const dnnl_dim_t hs = H / d, ws = W / d, b = B, cb = C / B;
  dnnl_dims_t dims = {N, cb, b, hs, d, ws, d};
  dnnl_dims_t whole = {
      cb * H * W * b, (dnnl_dim_t)H * W * b, 1, d * (dnnl_dim_t)W * b, (dnnl_dim_t)W * b, d * b, b};
  const dnnl_dim_t img = cb * hs * ws * b;
  dnnl_dims_t split = {img, hs * ws * b,        1, ws * b, d * (dnnl_dim_t)N * img,
                       b,   (dnnl_dim_t)N * img};
  DN(dnnl_memory_desc_init_by_strides(md, 7, dims, dnnl_f32, sub ? split : whole));
  return KPCN_OK;
}

/* N x Cb x B x H x W: the image of a buffer laid out for Hs x Ws (rows and columns beyond H,
 * W are padding; Hs = H, Ws = W: the image itself). */
static kpcn_status padded_view(dnnl_memory_desc_t *md, int N, int C, int B, int H, int W, int Hs,
                               int Ws) {
  const dnnl_dim_t b = B, cb = C / B;
  dnnl_dims_t dims = {N, cb, b, H, W};
  dnnl_dims_t st = {cb * Hs * Ws * b, (dnnl_dim_t)Hs * Ws * b, 1, (dnnl_dim_t)Ws * b, b};
  DN(dnnl_memory_desc_init_by_strides(md, 5, dims, dnnl_f32, st));
  return KPCN_OK;
}

/* The reorders of one side of a space-to-batch layer (0: input, C = cin; 1: output, C = cout):
 * the gather into the batch of sub-images and / or the scatter back, each through the padded
 * Hp x Wp buffer where d does not divide the size. */
static kpcn_status make_s2b_side(kpcn_net *n, layer *y, int side, int gather, int scatter,
                                 size_t *scratch) {
  const int N = n->o.batch, H = n->o.height, W = n->o.width, d = y->d;
  const int C = side ? y->cout : y->cin, B = s2b_block(y, C), Hp = y->s2b_hp, Wp = y->s2b_wp;
  dnnl_memory_desc_t whole, padded, split, in_p; /* in_p: the padded buffer (or the image) */
  KPCN_TRY(padded_view(&whole, N, C, B, H, W, H, W));
  KPCN_TRY(padded_view(&padded, N, C, B, H, W, Hp, Wp));
  KPCN_TRY(s2b_view(&split, N, C, B, Hp, Wp, d, 1));
  KPCN_TRY(s2b_view(&in_p, N, C, B, Hp, Wp, d, 0));
  const int pads = Hp != H || Wp != W;
  if (gather) {
    if (pads) KPCN_TRY(kpcn_net_make_reorder(n, &y->pad[side], &whole, &padded, scratch));
    KPCN_TRY(kpcn_net_make_reorder(n, &y->gather[side], &in_p, &split, scratch));
  }
  if (scatter) {
    KPCN_TRY(kpcn_net_make_reorder(n, &y->scatter[side], &split, &in_p, scratch));
    if (pads) KPCN_TRY(kpcn_net_make_reorder(n, &y->crop[side], &padded, &whole, scratch));
  }
  return KPCN_OK;
}

/* *out = 1 if oneDNN has only a fallback backward-weights kernel for layer y as it stands
 * (its dilation, its layout): on AVX2 every dilated f32 layer's (GEMM in nhwc, reference
 * loops channel-blocked). */
static kpcn_status bwdw_is_fallback(kpcn_net *n, const layer *y, const dnnl_memory_desc_t *wany,
                                    const dnnl_memory_desc_t *bmd, int *out) {
  const int pad = y->d * (y->k - 1) / 2;
  dnnl_dims_t strides = {1, 1}, dil = {y->d - 1, y->d - 1}, pads = {pad, pad};
  const dnnl_memory_desc_t *s = dnnl_primitive_desc_query_md(y->fwd_pd, dnnl_query_src_md, 0),
                           *d = dnnl_primitive_desc_query_md(y->fwd_pd, dnnl_query_dst_md, 0);
  dnnl_convolution_desc_t cd;
  DN(dnnl_dilated_convolution_backward_weights_desc_init(&cd, dnnl_convolution_direct, s, wany, bmd,
                                                         d, strides, dil, pads, pads));
  dnnl_primitive_desc_t pd;
  *out = 1;
  if (dnnl_primitive_desc_create(&pd, &cd, n->attr, n->eng, y->fwd_pd) != dnnl_success)
    return KPCN_OK;
  *out = is_fallback(pd);
  dnnl_primitive_desc_destroy(pd);
  return KPCN_OK;
}

/* oneDNN 2.6 has no direct kernel for dilations >= 4 on AVX2 (nhwc falls back to im2col +
 * GEMM: ~3x slower, with an im2col scratchpad of 9x the layer input; nChw8c to reference
 * loops). A dilation-d conv equals an undilated one on the d x d interleaved sub-images of
 * its input, zero padding included, so for an f32 layer whose direct forward kernel is such
 * a fallback the net gathers its input into that batch (a reorder), runs the undilated jit
 * kernel and scatters the result back. Where d does not divide H or W the input is first
 * copied into a zero-bordered Hp x Wp buffer (the next multiples of d: the extra rows and
 * columns are exactly the zeros the conv's padding would read) and the result cropped from
 * one. Training nets run the layer's backward the same way: the output gradient gathered
 * (its padding rows are outputs that do not exist, so zero), the undilated backward-weights
 * and backward-data kernels, the input gradient scattered (its padding rows dropped).
 * *pd is replaced when this is used. */
static kpcn_status try_space_to_batch(kpcn_net *n, int l, const dnnl_memory_desc_t *wany,
                                      const dnnl_memory_desc_t *bmd, size_t *scratch) {
  layer *y = &n->L[l];
  const int N = n->o.batch, H = n->o.height, W = n->o.width, d = y->d;
  if (n->o.precision != KPCN_PREC_F32 || d < 2 || y->cin % s2b_block(y, y->cin) ||
      y->cout % s2b_block(y, y->cout))
    return KPCN_OK;
  int fallback = is_fallback(y->fwd_pd);
  if (!fallback && n->o.training) KPCN_TRY(bwdw_is_fallback(n, y, wany, bmd, &fallback));
  if (!fallback) return KPCN_OK;
  const int Hp = (H + d - 1) / d * d, Wp = (W + d - 1) / d * d;
  dnnl_dims_t sd = {(dnnl_dim_t)N * d * d, y->cin, Hp / d, Wp / d},
              dd = {(dnnl_dim_t)N * d * d, y->cout, Hp / d, Wp / d};
  dnnl_dims_t strides = {1, 1}, dil = {0, 0}, pad = {(y->k - 1) / 2, (y->k - 1) / 2};
  dnnl_memory_desc_t smd, dmd;
  DN(dnnl_memory_desc_init_by_tag(&smd, 4, sd, dnnl_f32, y->tag));
  DN(dnnl_memory_desc_init_by_tag(&dmd, 4, dd, dnnl_f32, y->tag));
  dnnl_convolution_desc_t cd;
  DN(dnnl_dilated_convolution_forward_desc_init(
      &cd, n->o.training ? dnnl_forward_training : dnnl_forward_inference, dnnl_convolution_direct,
      &smd, wany, bmd, &dmd, strides, dil, pad, pad));
  dnnl_primitive_desc_t pd;
  if (dnnl_primitive_desc_create(&pd, &cd, y->has_relu ? n->attr_relu : n->attr, n->eng, NULL) !=
      dnnl_success)
    return KPCN_OK;
  if (is_fallback(pd)) {
    dnnl_primitive_desc_destroy(pd);
    return KPCN_OK;
  }
  replace_pd(n, &y->fwd_pd, pd, scratch);
  y->s2b = 1;
  y->s2b_md[0] = smd, y->s2b_md[1] = dmd;
  y->s2b_bytes[0] = dnnl_memory_desc_get_size(&smd);
  y->s2b_bytes[1] = dnnl_memory_desc_get_size(&dmd);
  y->s2b_hp = Hp, y->s2b_wp = Wp;
  KPCN_TRY(kpcn_net_mem(n, &y->ssrc, &smd, NULL));
  KPCN_TRY(kpcn_net_mem(n, &y->sdst, &dmd, NULL));
  const int tr = n->o.training;
  KPCN_TRY(make_s2b_side(n, y, 0, 1, tr, scratch));
  return make_s2b_side(n, y, 1, tr, 1, scratch);
}

/* *out = 1 if oneDNN has direct (not fallback) f32 kernels for a cin -> cout k x k conv of
 * dilation d on N x H x W activations in layout tag: the forward, and for training nets the
 * backward-weights too. */
static kpcn_status kernels_are_direct(kpcn_net *n, int cin, int cout, int k, int d, int N, int H,
                                      int W, dnnl_format_tag_t tag, int *out) {
  const int pad = d * (k - 1) / 2;
  dnnl_dims_t sd = {N, cin, H, W}, dd = {N, cout, H, W}, wd = {cout, cin, k, k}, bd = {cout},
              strides = {1, 1}, dil = {d - 1, d - 1}, pads = {pad, pad};
  dnnl_memory_desc_t smd, dmd, wmd, bmd;
  DN(dnnl_memory_desc_init_by_tag(&smd, 4, sd, dnnl_f32, tag));
  DN(dnnl_memory_desc_init_by_tag(&dmd, 4, dd, dnnl_f32, tag));
  DN(dnnl_memory_desc_init_by_tag(&wmd, 4, wd, dnnl_f32, dnnl_format_tag_any));
  DN(dnnl_memory_desc_init_by_tag(&bmd, 1, bd, dnnl_f32, dnnl_x));
  dnnl_convolution_desc_t cd;
  const int tr = n->o.training;
  DN(dnnl_dilated_convolution_forward_desc_init(
      &cd, tr ? dnnl_forward_training : dnnl_forward_inference, dnnl_convolution_direct, &smd, &wmd,
      &bmd, &dmd, strides, dil, pads, pads));
  dnnl_primitive_desc_t fwd, bwdw;
  *out = 0;
  if (dnnl_primitive_desc_create(&fwd, &cd, n->attr, n->eng, NULL) != dnnl_success) return KPCN_OK;
  dnnl_status_t st = dnnl_success;
  if (!tr)
    *out = !is_fallback(fwd);
  else if (!is_fallback(fwd)) {
    st = dnnl_dilated_convolution_backward_weights_desc_init(
        &cd, dnnl_convolution_direct, &smd, &wmd, &bmd, &dmd, strides, dil, pads, pads);
    if (st == dnnl_success &&
        dnnl_primitive_desc_create(&bwdw, &cd, n->attr, n->eng, fwd) == dnnl_success) {
      *out = !is_fallback(bwdw);
      dnnl_primitive_desc_destroy(bwdw);
    }
  }
  dnnl_primitive_desc_destroy(fwd);
  DN(st);
  return KPCN_OK;
}

/* The activation layout of layer l. Explicit layouts apply to every layer. AUTO: nhwc, except
 * for f32 training nets, and f32 inference nets on CPUs without AVX-512, where a layer runs
 * channel-blocked (nChw16c; nChw8c where the CPU lacks AVX-512) when oneDNN has jit kernels
 * for it there (the forward; for training also backward-weights), or for the undilated conv
 * space-to-batch runs it as, and padding its channels to multiples of the block adds at most
 * 15 % to its work, with reorders between layers of different layouts. Why: oneDNN 2.6's f32
 * backward-weights kernel is ~1.4x faster on nChw16c than on nhwc (cpu preset, batch 16 of
 * 64 x 64: 8.5 vs 12 ms per 48-channel layer; 121 logits pad to 128), while the padding ate
 * the gain where channels are far from a multiple of 16 (paper preset, 100 -> 112: 288-315 vs
 * 321 GFLOP/s in nhwc). With AVX-512 the inference forward is best in nhwc (brgconv), and bf16
 * has its brgconv kernels only there. Without it oneDNN's jit:avx2 forward runs nChw8c 1.5-2x
 * faster than nhwc (Zen 3, 1024², 48 -> 48: 141 vs 86 GFLOP/s at dilation 2, 172 vs 120 for
 * space-to-batch's batch 16 of 256²; the 48 -> 121 logits 179 vs 92). */
static kpcn_status choose_tag(kpcn_net *n, int l) {
  layer *y = &n->L[l];
  y->tag = n->o.layout == KPCN_LAYOUT_NCHW16C ? dnnl_nChw16c : dnnl_nhwc;
  if (n->o.layout != KPCN_LAYOUT_AUTO || n->o.precision != KPCN_PREC_F32 ||
      (!n->o.training && kpcn_cpu_allows_avx512()))
    return KPCN_OK;
  const kpcn_arch *a = &n->model->arch;
  const int cin = kpcn_arch_layer_in(a, l), cout = kpcn_arch_layer_out(a, l);
  const int blk = kpcn_cpu_allows_avx512() ? 16 : 8;
  const dnnl_format_tag_t btag = blk == 16 ? dnnl_nChw16c : dnnl_nChw8c;
  if (blk * ceil((double)cin / blk) * blk * ceil((double)cout / blk) > 1.15 * cin * cout)
    return KPCN_OK;
  const int k = a->conv_size[l], d = a->dilation[l];
  int fast = 0;
  KPCN_TRY(
      kernels_are_direct(n, cin, cout, k, d, n->o.batch, n->o.height, n->o.width, btag, &fast));
  /* A dilated layer without them there (AVX2: reference loops for the forward from d = 4 and
   * for backward-weights from d = 2; AVX-512: the forward at d = 8) still goes blocked where
   * space-to-batch will carry it: its channels fill whole blocks and the undilated kernels
   * exist. */
  if (!fast && d > 1 && cin % blk == 0 && cout % blk == 0)
    KPCN_TRY(kernels_are_direct(n, cin, cout, k, 1, n->o.batch * d * d, (n->o.height + d - 1) / d,
                                (n->o.width + d - 1) / d, btag, &fast));
  if (fast) y->tag = btag;
  return KPCN_OK;
}

/* Every layer's activation layout (choose_tag). An inference net keeps no activations, but a
 * layer fed from one of another layout needs a buffer for the reordered input, as large as
 * an activation: so an inference net goes blocked only where every layer can (the cpu
 * preset). The paper preset, whose 36 -> 100 first layer would pad by 16 %, stays nhwc: the
 * reorder buffer took a 4K frame's peak RSS from 3.7 to 4.2 GB for 5-8 % less time (Zen 3). */
kpcn_status kpcn_net_choose_tags(kpcn_net *n) {
  int mixed = 0;
  for (int l = 0; l < n->nl; l++) {
    KPCN_TRY(choose_tag(n, l));
    mixed |= l > 0 && n->L[l].tag != n->L[0].tag;
  }
  if (mixed && !n->o.training)
    for (int l = 0; l < n->nl; l++)
      n->L[l].tag = dnnl_nhwc;
  return KPCN_OK;
}

/* Whether layer y (an inference net's logits layer in the pixel-major layout) computes its
 * output channels rounded up to 16. oneDNN's brgconv pads them to its block anyway; with the
 * output padded too, each pixel's logits start on a cache line (a pixel stride of 128 floats
 * instead of 121) and the kernel stores whole lines: the cpu preset's 48 -> 121 logits layer
 * on a 1024² image in bf16, Zen 4: 270 -> 255 ms. The kpa layer reads the first cout of each
 * pixel's slots (kpcn_logits_layout.pixel_stride); the extra rows have zero weights and bias. */
static int pad_logits(const kpcn_net *n, const layer *y) {
  return !n->o.training && !y->has_relu && y->d == 1 && y->tag == dnnl_nhwc && y->cout % 16 != 0;
}

/* Builds the primitives of layer l; src_md is the previous layer's destination. */
kpcn_status kpcn_net_build_layer(kpcn_net *n, int l, const dnnl_memory_desc_t *src_md,
                                 size_t *scratch) {
  const kpcn_arch *a = &n->model->arch;
  layer *y = &n->L[l];
  y->cin = kpcn_arch_layer_in(a, l);
  y->cout = kpcn_arch_layer_out(a, l);
  y->k = a->conv_size[l];
  y->d = a->dilation[l];
  y->has_relu = l < a->n_hidden;
  const int bf = n->o.precision == KPCN_PREC_BF16;
  const dnnl_data_type_t adt = bf ? dnnl_bf16 : dnnl_f32;
  /* bf16 nets keep their activations in bf16; the logits too when inferring (the kpa layer
   * reads them as they are, half the bytes of f32 from memory), f32 when training (their
   * gradient comes back in f32). */
  const dnnl_data_type_t ddt = (bf && (y->has_relu || !n->o.training)) ? dnnl_bf16 : dnnl_f32;
  const int N = n->o.batch, H = n->o.height, W = n->o.width;
  dnnl_dims_t wd = {y->cout, y->cin, y->k, y->k}, bd = {y->cout}, dd = {N, y->cout, H, W};
  dnnl_dims_t strides = {1, 1}, dil = {y->d - 1, y->d - 1};
  const int pad = y->d * (y->k - 1) / 2;
  dnnl_dims_t pl = {pad, pad}, pr = {pad, pad};
  dnnl_memory_desc_t wany, bmd, dany;
  DN(dnnl_memory_desc_init_by_tag(&wany, 4, wd, adt, dnnl_format_tag_any));
  DN(dnnl_memory_desc_init_by_tag(&bmd, 1, bd, dnnl_f32, dnnl_x));
  /* A fixed activation layout per layer (choose_tag): with "any" oneDNN may pick different
   * layouts for consecutive layers and then find no optimized kernel for the pair. */
  const dnnl_format_tag_t tag = y->tag;
  DN(dnnl_memory_desc_init_by_tag(&dany, 4, dd, ddt, tag));
  /* the layer's own input layout; src_md (the previous output) differs after a Winograd layer */
  dnnl_dims_t sd = {N, y->cin, H, W};
  dnnl_memory_desc_t sany;
  DN(dnnl_memory_desc_init_by_tag(&sany, 4, sd, adt, tag));
  dnnl_convolution_desc_t cd;
  if (!n->o.training && !n->o.direct_conv && !bf && y->k == 3 && y->d == 1 && l == n->nl - 1)
    KPCN_TRY(try_winograd(n, l, wany, bmd, scratch));
  y->cpad = y->cout;
  if (!y->winograd) {
    if (pad_logits(n, y)) {
      y->cpad = (y->cout + 15) & ~15;
      wd[0] = bd[0] = dd[1] = y->cpad;
      DN(dnnl_memory_desc_init_by_tag(&wany, 4, wd, adt, dnnl_format_tag_any));
      DN(dnnl_memory_desc_init_by_tag(&bmd, 1, bd, dnnl_f32, dnnl_x));
      DN(dnnl_memory_desc_init_by_tag(&dany, 4, dd, ddt, tag));
      const size_t wn = (size_t)y->cpad * y->cin * y->k * y->k;
      y->wpad = kpcn_net_alloc(n, sizeof(float) * (wn + (size_t)y->cpad), "padded logits weights");
      if (!y->wpad) return KPCN_ERR_OUT_OF_MEMORY;
      memset(y->wpad, 0, sizeof(float) * (wn + (size_t)y->cpad));
      y->bpad = y->wpad + wn;
    }
    DN(dnnl_dilated_convolution_forward_desc_init(
        &cd, n->o.training ? dnnl_forward_training : dnnl_forward_inference,
        dnnl_convolution_direct, &sany, &wany, &bmd, &dany, strides, dil, pl, pr));
    /* the direct kernel's scratchpad counts only if the layer keeps it */
    size_t direct_scratch = 0;
    KPCN_TRY(kpcn_net_make_pd(n, &y->fwd_pd, &cd, y->has_relu ? n->attr_relu : n->attr, NULL,
                              "forward", l, &direct_scratch));
    KPCN_TRY(try_space_to_batch(n, l, &wany, &bmd, scratch));
    if (!y->s2b && direct_scratch > *scratch) *scratch = direct_scratch;
  }
  /* the layer's activations as the net sees them (whole images, also for space-to-batch) */
  y->src_md = y->s2b ? sany : *dnnl_primitive_desc_query_md(y->fwd_pd, dnnl_query_src_md, 0);
  y->w_md = *dnnl_primitive_desc_query_md(y->fwd_pd, dnnl_query_weights_md, 0);
  y->dst_md = y->s2b ? dany : *dnnl_primitive_desc_query_md(y->fwd_pd, dnnl_query_dst_md, 0);
  if (l > 0 && !dnnl_memory_desc_equal(src_md, &y->src_md)) {
    KPCN_TRY(kpcn_net_make_reorder(n, &y->src_in, src_md, &y->src_md, scratch));
    n->n_relayout++;
  }
  const char *impl = NULL;
  dnnl_primitive_desc_query(y->fwd_pd, dnnl_query_impl_info_str, 0, &impl);
  snprintf(n->impl[l], sizeof n->impl[l], "%s", impl ? impl : "?");
  DN(dnnl_primitive_create(&y->fwd, y->fwd_pd));
  KPCN_TRY(kpcn_net_mem(n, &y->src, &y->src_md, NULL));
  KPCN_TRY(kpcn_net_mem(n, &y->dst, &y->dst_md, NULL));
  KPCN_TRY(kpcn_net_mem(n, &y->w, &y->w_md, NULL));
  KPCN_TRY(kpcn_net_mem(n, &y->bias, &bmd, NULL));
  dnnl_memory_desc_t oihw;
  DN(dnnl_memory_desc_init_by_tag(&oihw, 4, wd, dnnl_f32, dnnl_oihw));
  KPCN_TRY(kpcn_net_make_reorder(n, &y->w_in, &oihw, &y->w_md, scratch));
  if (!n->o.training) return KPCN_OK;

  /* backward: weights (always), data (for l > 0, or l == 0 when input_grad). bf16 nets train
   * mixed-precision: activations, weight copies and output gradients in bf16 (oneDNN's bf16
   * backward kernels take bf16 diff_dst only, so the f32 logits' gradient is rounded too),
   * weight and bias gradients accumulated and returned in f32 for the f32 master weights. */
  y->ddst_md = y->dst_md;
  if (bf && !y->has_relu) DN(dnnl_memory_desc_init_by_tag(&y->ddst_md, 4, dd, dnnl_bf16, tag));
  dnnl_memory_desc_t dwany;
  DN(dnnl_memory_desc_init_by_tag(&dwany, 4, wd, dnnl_f32, dnnl_format_tag_any));
  /* a space-to-batch layer's backward runs undilated on the sub-images, like its forward */
  const dnnl_memory_desc_t *bsrc = y->s2b ? &y->s2b_md[0] : &y->src_md,
                           *bdst = y->s2b ? &y->s2b_md[1] : &y->ddst_md;
  if (y->s2b) {
    dil[0] = dil[1] = 0;
    pl[0] = pl[1] = pr[0] = pr[1] = (y->k - 1) / 2;
  }
  dnnl_convolution_desc_t bwd;
  DN(dnnl_dilated_convolution_backward_weights_desc_init(&bwd, dnnl_convolution_direct, bsrc,
                                                         &dwany, &bmd, bdst, strides, dil, pl, pr));
  KPCN_TRY(
      kpcn_net_make_pd(n, &y->bwdw_pd, &bwd, n->attr, y->fwd_pd, "backward-weights", l, scratch));
  y->dw_md = *dnnl_primitive_desc_query_md(y->bwdw_pd, dnnl_query_diff_weights_md, 0);
  DN(dnnl_primitive_create(&y->bwdw, y->bwdw_pd));
  KPCN_TRY(kpcn_net_mem(n, &y->dw, &y->dw_md, NULL));
  KPCN_TRY(kpcn_net_mem(n, &y->db, &bmd, NULL));
  KPCN_TRY(kpcn_net_mem(n, &y->ddst, &y->ddst_md, NULL));
  KPCN_TRY(kpcn_net_make_reorder(n, &y->dw_out, &y->dw_md, &oihw, scratch));
  if (l > 0 || n->o.input_grad) {
    DN(dnnl_dilated_convolution_backward_data_desc_init(&bwd, dnnl_convolution_direct, bsrc, &wany,
                                                        bdst, strides, dil, pl, pr));
    KPCN_TRY(
        kpcn_net_make_pd(n, &y->bwdd_pd, &bwd, n->attr, y->fwd_pd, "backward-data", l, scratch));
    const dnnl_memory_desc_t *from = &oihw;
    dnnl_memory_desc_t iohw;
    if (!bf && !y->s2b) KPCN_TRY(try_bwdd_as_forward(n, l, strides, dil, pl, pr, &iohw, scratch));
    if (y->bwdd_fwd) from = &iohw;
    y->bw_md = *dnnl_primitive_desc_query_md(y->bwdd_pd, dnnl_query_weights_md, 0);
    DN(dnnl_primitive_create(&y->bwdd, y->bwdd_pd));
    KPCN_TRY(kpcn_net_mem(n, &y->bw, &y->bw_md, NULL));
    KPCN_TRY(kpcn_net_mem(n, &y->dsrc, &y->src_md, NULL));
    if (y->s2b) KPCN_TRY(kpcn_net_mem(n, &y->sdsrc, &y->s2b_md[0], NULL));
    KPCN_TRY(kpcn_net_make_reorder(n, &y->bw_in, from, &y->bw_md, scratch));
    if (y->src_in.prim)
      KPCN_TRY(kpcn_net_make_reorder(n, &y->dsrc_out, &y->src_md, &n->L[l - 1].ddst_md, scratch));
  }
  if (y->has_relu) {
    /* eltwise backward needs a forward hint; ReLU derivative from the stored output */
    dnnl_eltwise_desc_t ef, eb;
    dnnl_primitive_desc_t hint;
    DN(dnnl_eltwise_forward_desc_init(&ef, dnnl_forward_training, dnnl_eltwise_relu_use_dst_for_bwd,
                                      &y->dst_md, 0.f, 0.f));
    KPCN_TRY(kpcn_net_make_pd(n, &hint, &ef, n->attr, NULL, "relu-forward", l, scratch));
    DN(dnnl_eltwise_backward_desc_init(&eb, dnnl_eltwise_relu_use_dst_for_bwd, &y->dst_md,
                                       &y->dst_md, 0.f, 0.f));
    kpcn_status s =
        kpcn_net_make_pd(n, &y->relu_pd, &eb, n->attr, hint, "relu-backward", l, scratch);
    dnnl_primitive_desc_destroy(hint);
    KPCN_TRY(s);
    DN(dnnl_primitive_create(&y->relu, y->relu_pd));
  }
  return KPCN_OK;
}
