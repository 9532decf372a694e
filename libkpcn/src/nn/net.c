/* kpcn_net: one KPCN branch executed with oneDNN (C API, OpenMP runtime).
 *
 * Layout strategy: every conv primitive is created with format "any" for weights and a fixed
 * activation layout per layer (net_layer.c, kpcn_net_choose_tags: nhwc for inference and bf16
 * with AVX-512, nChw16c where oneDNN has a jit kernel for f32 training, nChw8c for f32 without
 * AVX-512), so activations stay in a layout
 * oneDNN's fast kernels take from layer to layer. Reorders happen at the ends (user NCHW
 * input -> layer 0, last layer -> user NCHW logits, and the weights from the model's OIHW
 * arrays, which are re-read each forward so an optimizer can update them in place) and
 * between layers of different layouts (a Winograd logits layer; the dilation-8 layer of a
 * training net), both ways in training.
 * Backward (training nets, f32 or bf16 mixed precision): ReLU backward (from the stored
 * post-ReLU activation) in place on the gradient buffer, then backward-weights and
 * backward-data per layer; weight and bias gradients are f32 in either precision.
 * One user-mode scratchpad is shared by all primitives. */
#include "nn/net_internal.h"

#include <omp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

static double now_s(void) {
  struct timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

/* oneDNN's OpenMP runtime sizes its parallel regions from omp_get_max_threads() of the
 * calling thread, both when a primitive is created and when it runs; its kernels also run
 * with denormals flushed (see kpcn_fast_fp_begin). */
typedef struct thr_guard {
  int saved, n;
  unsigned csr;
} thr_guard;
static thr_guard thr_push(int n) {
  thr_guard g = {omp_get_max_threads(), n, 0};
  omp_set_num_threads(n);
  g.csr = kpcn_fast_fp_begin(n);
  return g;
}
static void thr_pop(thr_guard g) {
  kpcn_fast_fp_end(g.csr, g.n);
  omp_set_num_threads(g.saved);
}

void *kpcn_net_alloc(kpcn_net *n, size_t bytes, const char *what) {
  void *p = kpcn_aligned_alloc(bytes ? bytes : 64, what);
  if (p) n->bytes += bytes;
  return p;
}

kpcn_status kpcn_net_mem(kpcn_net *n, dnnl_memory_t *m, const dnnl_memory_desc_t *md, void *h) {
  DN(dnnl_memory_create(m, md, n->eng, h ? h : DNNL_MEMORY_NONE));
  return KPCN_OK;
}

size_t kpcn_net_pd_scratch(const_dnnl_primitive_desc_t pd) {
  const dnnl_memory_desc_t *md = dnnl_primitive_desc_query_md(pd, dnnl_query_scratchpad_md, 0);
  return md ? dnnl_memory_desc_get_size(md) : 0;
}

/* Creates a reorder between two descriptors; memories get their handles later. */
kpcn_status kpcn_net_make_reorder(kpcn_net *n, reorder *r, const dnnl_memory_desc_t *from,
                                  const dnnl_memory_desc_t *to, size_t *scratch) {
  dnnl_primitive_desc_t pd;
  DN(dnnl_reorder_primitive_desc_create(&pd, from, n->eng, to, n->eng, n->attr));
  size_t s = kpcn_net_pd_scratch(pd);
  if (s > *scratch) *scratch = s;
  dnnl_status_t d = dnnl_primitive_create(&r->prim, pd);
  dnnl_primitive_desc_destroy(pd);
  DN(d);
  KPCN_TRY(kpcn_net_mem(n, &r->src, from, NULL));
  KPCN_TRY(kpcn_net_mem(n, &r->dst, to, NULL));
  return KPCN_OK;
}

kpcn_status kpcn_net_run_reorder(kpcn_net *n, reorder *r, const void *src, void *dst) {
  DN(dnnl_memory_set_data_handle(r->src, (void *)src));
  DN(dnnl_memory_set_data_handle(r->dst, dst));
  dnnl_exec_arg_t a[3] = {
      {DNNL_ARG_FROM, r->src}, {DNNL_ARG_TO, r->dst}, {DNNL_ARG_SCRATCHPAD, n->scratch_mem}};
  DN(dnnl_primitive_execute(r->prim, n->stream, 3, a));
  return KPCN_OK;
}

/* Weight reorders are tiny (kilobytes to a few MB); an OpenMP team costs more than the copy,
 * especially on a loaded machine, so they run on the calling thread only. */
kpcn_status kpcn_net_run_reorder_1t(kpcn_net *n, reorder *r, const void *src, void *dst) {
  omp_set_num_threads(1);
  kpcn_status s = kpcn_net_run_reorder(n, r, src, dst);
  omp_set_num_threads(n->nt);
  return s;
}

void kpcn_net_free_reorder(reorder *r) {
  if (r->prim) dnnl_primitive_destroy(r->prim);
  if (r->src) dnnl_memory_destroy(r->src);
  if (r->dst) dnnl_memory_destroy(r->dst);
}

kpcn_status kpcn_net_make_pd(kpcn_net *n, dnnl_primitive_desc_t *pd, const void *desc,
                             const_dnnl_primitive_attr_t attr, const_dnnl_primitive_desc_t hint,
                             const char *what, int l, size_t *scratch) {
  dnnl_status_t d = dnnl_primitive_desc_create(pd, desc, attr, n->eng, hint);
  /* oneDNN 2.6 has bf16 convolutions on AVX-512 CPUs only (emulated without AVX512_BF16). */
  if (d == dnnl_unimplemented && n->o.precision == KPCN_PREC_BF16)
    return kpcn_fail(KPCN_ERR_UNSUPPORTED,
                     "bf16 is not available on this CPU: oneDNN has no bf16 %s implementation "
                     "for conv layer %d (it needs AVX-512); run in fp32 instead",
                     what, l);
  if (d != dnnl_success)
    return kpcn_fail(d == dnnl_unimplemented ? KPCN_ERR_UNSUPPORTED : KPCN_ERR_INTERNAL,
                     "oneDNN has no %s implementation for conv layer %d (%s)", what, l,
                     dnnl_status2str(d));
  size_t s = kpcn_net_pd_scratch(*pd);
  if (s > *scratch) *scratch = s;
  const char *impl = NULL;
  if (dnnl_primitive_desc_query(*pd, dnnl_query_impl_info_str, 0, &impl) == dnnl_success && impl &&
      !strncmp(impl, "ref", 3))
    n->n_slow++;
  return KPCN_OK;
}

size_t kpcn_plane_stride(size_t pixels) {
  size_t blocks = (pixels + 15) / 16;
  return 16 * (blocks | 1);
}

void kpcn_net_options_defaults(kpcn_net_options *o) {
  memset(o, 0, sizeof *o);
  o->batch = 1;
  o->height = o->width = 64;
}

static size_t md_size(const dnnl_memory_desc_t *md) { return dnnl_memory_desc_get_size(md); }

/* Allocates buffers and binds them to the memories created by build_layer. */
static kpcn_status bind_buffers(kpcn_net *n, size_t scratch) {
  const int nl = n->nl;
  size_t wbytes = 0, gfloats = 0, pp[2] = {0, 0}, db = 0;
  for (int l = 0; l < nl; l++) {
    layer *y = &n->L[l];
    wbytes += (md_size(&y->w_md) + 63) & ~(size_t)63;
    if (y->bwdd) wbytes += (md_size(&y->bw_md) + 63) & ~(size_t)63;
    if (y->bwdw) wbytes += (md_size(&y->dw_md) + 63) & ~(size_t)63;
    gfloats += (((size_t)y->cout * y->cin * y->k * y->k + 15) & ~(size_t)15) +
               (((size_t)y->cout + 15) & ~(size_t)15);
    size_t ds = md_size(&y->dst_md);
    if (ds > pp[l & 1]) pp[l & 1] = ds;
    if (n->o.training && md_size(&y->ddst_md) > db) db = md_size(&y->ddst_md);
    if (md_size(&y->src_md) > db) db = md_size(&y->src_md);
  }
  n->wbuf = kpcn_net_alloc(n, wbytes, "net weight copies");
  n->xbuf = kpcn_net_alloc(n, md_size(&n->L[0].src_md), "net input");
  size_t rb = 0;
  for (int l = 1; l < nl && !n->o.training; l++)
    if (n->L[l].src_in.prim && md_size(&n->L[l].src_md) > rb) rb = md_size(&n->L[l].src_md);
  if (rb && !(n->rbuf = kpcn_net_alloc(n, rb, "net reordered activations")))
    return KPCN_ERR_OUT_OF_MEMORY;
  n->scratch = kpcn_net_alloc(n, scratch, "oneDNN scratchpad");
  if (!n->wbuf || !n->xbuf || !n->scratch) return KPCN_ERR_OUT_OF_MEMORY;
  dnnl_memory_desc_t smd;
  dnnl_dims_t sd = {(dnnl_dim_t)(scratch ? scratch : 1)};
  DN(dnnl_memory_desc_init_by_tag(&smd, 1, sd, dnnl_u8, dnnl_x));
  KPCN_TRY(kpcn_net_mem(n, &n->scratch_mem, &smd, n->scratch));
  if (n->o.training) {
    n->grads = kpcn_net_alloc(n, gfloats * sizeof(float), "net gradients");
    n->dbuf[0] = kpcn_net_alloc(n, db, "net gradient buffer");
    n->dbuf[1] = kpcn_net_alloc(n, db, "net gradient buffer");
    if (!n->grads || !n->dbuf[0] || !n->dbuf[1]) return KPCN_ERR_OUT_OF_MEMORY;
    memset(n->grads, 0, gfloats * sizeof(float));
  } else {
    n->pp[0] = kpcn_net_alloc(n, pp[0], "net activations");
    n->pp[1] = kpcn_net_alloc(n, pp[1] ? pp[1] : 64, "net activations");
    if (!n->pp[0] || !n->pp[1]) return KPCN_ERR_OUT_OF_MEMORY;
  }
  /* sbuf[side] holds one side of a space-to-batch layer; pbuf[0] is what gathers read (side
   * 0 forward, side 1 backward), pbuf[1] what scatters write (side 1 forward, 0 backward) */
  size_t sb[2] = {0, 0}, pb[2] = {0, 0};
  for (int l = 0; l < nl; l++) {
    const layer *y = &n->L[l];
    for (int side = 0; side < 2 && y->s2b; side++) {
      const size_t bytes = y->s2b_bytes[side];
      if (bytes > sb[side]) sb[side] = bytes;
      if (y->pad[side].prim && bytes > pb[0]) pb[0] = bytes;
      if (y->crop[side].prim && bytes > pb[1]) pb[1] = bytes;
    }
  }
  for (int i = 0; i < 2; i++) {
    if (sb[i] && !(n->sbuf[i] = kpcn_net_alloc(n, sb[i], "net space-to-batch activations")))
      return KPCN_ERR_OUT_OF_MEMORY;
    if (pb[i] && !(n->pbuf[i] = kpcn_net_alloc(n, pb[i], "net space-to-batch padding")))
      return KPCN_ERR_OUT_OF_MEMORY;
  }
  n->pbuf_bytes = pb[0];
  char *wp = n->wbuf;
  float *gp = n->grads;
  for (int l = 0; l < nl; l++) {
    layer *y = &n->L[l];
    if (n->o.training) {
      y->act = kpcn_net_alloc(n, md_size(&y->dst_md), "net activations");
      if (!y->act) return KPCN_ERR_OUT_OF_MEMORY;
      if (y->src_in.prim && !(y->rin = kpcn_net_alloc(n, md_size(&y->src_md), "net activations")))
        return KPCN_ERR_OUT_OF_MEMORY;
      if (y->s2b && !(y->sin = kpcn_net_alloc(n, y->s2b_bytes[0], "net space-to-batch input")))
        return KPCN_ERR_OUT_OF_MEMORY;
      y->gw = gp;
      gp += ((size_t)y->cout * y->cin * y->k * y->k + 15) & ~(size_t)15;
      y->gb = gp;
      gp += ((size_t)y->cout + 15) & ~(size_t)15;
    } else {
      y->act = n->pp[l & 1];
    }
    y->wp = wp;
    DN(dnnl_memory_set_data_handle(y->w, wp));
    wp += (md_size(&y->w_md) + 63) & ~(size_t)63;
    if (y->bwdd) {
      y->bwp = wp;
      DN(dnnl_memory_set_data_handle(y->bw, wp));
      wp += (md_size(&y->bw_md) + 63) & ~(size_t)63;
    }
    if (y->bwdw) {
      y->dwp = wp;
      DN(dnnl_memory_set_data_handle(y->dw, wp));
      wp += (md_size(&y->dw_md) + 63) & ~(size_t)63;
    }
    DN(dnnl_memory_set_data_handle(y->src, l == 0           ? n->xbuf
                                           : y->rin         ? y->rin
                                           : y->src_in.prim ? n->rbuf
                                                            : n->L[l - 1].act));
    DN(dnnl_memory_set_data_handle(y->dst, y->act));
    if (y->s2b) {
      DN(dnnl_memory_set_data_handle(y->ssrc, y->sin ? y->sin : n->sbuf[0]));
      DN(dnnl_memory_set_data_handle(y->sdst, n->sbuf[1]));
      if (y->sdsrc) DN(dnnl_memory_set_data_handle(y->sdsrc, n->sbuf[0]));
    }
  }
  return KPCN_OK;
}

/* The kpa layer reads planar, pixel-major and channel-blocked f32 or bf16 layouts in place
 * (see kpcn_logits_layout); anything else oneDNN might pick returns 0 (then we reorder). */
static int logits_layout_of(const dnnl_memory_desc_t *md, int C, int H, int W,
                            kpcn_logits_layout *out) {
  if (md->ndims != 4 || (md->data_type != dnnl_f32 && md->data_type != dnnl_bf16) ||
      md->format_kind != dnnl_blocked || md->offset0 != 0)
    return 0;
  out->bf16 = md->data_type == dnnl_bf16;
  const dnnl_blocking_desc_t *b = &md->format_desc.blocking;
  const dnnl_dim_t *st = b->strides;
  if (st[2] != (dnnl_dim_t)W * st[3]) return 0; /* rows of pixels must be contiguous */
  out->image_stride = (size_t)st[0];
  out->pixel_stride = (int)st[3];
  if (b->inner_nblks == 0 && st[1] == 1 && st[3] >= C) { /* pixel-major (nhwc) */
    out->block = C, out->block_stride = 0;
    return 1;
  }
  if (b->inner_nblks == 0 && st[3] == 1) { /* planar (nchw) */
    out->block = 1, out->block_stride = (size_t)st[1];
    return st[1] >= (dnnl_dim_t)H * W;
  }
  if (b->inner_nblks == 1 && b->inner_idxs[0] == 1 && st[3] == b->inner_blks[0]) { /* nChwXc */
    out->block = (int)b->inner_blks[0], out->block_stride = (size_t)st[1];
    return 1;
  }
  return 0;
}

static kpcn_status build(kpcn_net *n) {
  const kpcn_arch *a = &n->model->arch;
  const int N = n->o.batch, H = n->o.height, W = n->o.width;
  DN(dnnl_engine_create(&n->eng, dnnl_cpu, 0));
  DN(dnnl_stream_create(&n->stream, n->eng, dnnl_stream_default_flags));
  DN(dnnl_primitive_attr_create(&n->attr));
  DN(dnnl_primitive_attr_set_scratchpad_mode(n->attr, dnnl_scratchpad_mode_user));
  DN(dnnl_primitive_attr_create(&n->attr_relu));
  DN(dnnl_primitive_attr_set_scratchpad_mode(n->attr_relu, dnnl_scratchpad_mode_user));
  dnnl_post_ops_t po;
  DN(dnnl_post_ops_create(&po));
  dnnl_status_t d = dnnl_post_ops_append_eltwise(po, 1.f, dnnl_eltwise_relu, 0.f, 0.f);
  if (d == dnnl_success) d = dnnl_primitive_attr_set_post_ops(n->attr_relu, po);
  dnnl_post_ops_destroy(po);
  DN(d);
  size_t scratch = 0;
  const dnnl_data_type_t adt = n->o.precision == KPCN_PREC_BF16 ? dnnl_bf16 : dnnl_f32;
  dnnl_dims_t xd = {N, a->n_inputs, H, W};
  dnnl_memory_desc_t xany, user_in;
  KPCN_TRY(kpcn_net_choose_tags(n));
  DN(dnnl_memory_desc_init_by_tag(&xany, 4, xd, adt, n->L[0].tag));
  const dnnl_dim_t ps = n->o.input_plane_stride ? (dnnl_dim_t)n->o.input_plane_stride : H * W;
  dnnl_dims_t xstrides = {a->n_inputs * ps, ps, W, 1};
  DN(dnnl_memory_desc_init_by_strides(&user_in, 4, xd, dnnl_f32, xstrides));
  for (int l = 0; l < n->nl; l++)
    KPCN_TRY(kpcn_net_build_layer(n, l, l == 0 ? &xany : &n->L[l - 1].dst_md, &scratch));
  /* We asked backward for the exact forward layouts; make sure oneDNN honoured them. */
  for (int l = 0; l < n->nl; l++) {
    const layer *y = &n->L[l];
    const dnnl_memory_desc_t *m;
    if (y->bwdd_pd && !y->bwdd_fwd &&
        (!(m = dnnl_primitive_desc_query_md(y->bwdd_pd, dnnl_query_diff_src_md, 0)) ||
         !dnnl_memory_desc_equal(m, y->s2b ? &y->s2b_md[0] : &y->src_md)))
      return kpcn_fail(KPCN_ERR_UNSUPPORTED,
                       "oneDNN chose a different layout for the "
                       "backward-data gradient of conv layer %d",
                       l);
    if (y->bwdw_pd && (!(m = dnnl_primitive_desc_query_md(y->bwdw_pd, dnnl_query_src_md, 0)) ||
                       !dnnl_memory_desc_equal(m, y->s2b ? &y->s2b_md[0] : &y->src_md)))
      return kpcn_fail(KPCN_ERR_UNSUPPORTED,
                       "oneDNN chose a different input layout for the "
                       "backward-weights of conv layer %d",
                       l);
  }
  KPCN_TRY(kpcn_net_make_reorder(n, &n->in, &user_in, &n->L[0].src_md, &scratch));
  const layer *last = &n->L[n->nl - 1];
  dnnl_dims_t od = {N, last->cout, H, W};
  dnnl_memory_desc_t user_out, logits_md = last->dst_md;
  DN(dnnl_memory_desc_init_by_tag(&user_out, 4, od, dnnl_f32, dnnl_nchw));
  if (last->cpad != last->cout) { /* the first cout channels of the padded output */
    const dnnl_dims_t zero = {0, 0, 0, 0};
    DN(dnnl_memory_desc_init_submemory(&logits_md, &last->dst_md, od, zero));
  }
  KPCN_TRY(kpcn_net_make_reorder(n, &n->out, &logits_md, &user_out, &scratch));
  n->native_ok = logits_layout_of(&last->dst_md, last->cout, H, W, &n->native);
  if (n->o.training) {
    KPCN_TRY(kpcn_net_make_reorder(n, &n->dout_in, &user_out, &last->ddst_md, &scratch));
    /* dlogits in the logits' own layout (kpcn_net_backward_logits): f32 nets take them as
     * they are (the last layer has no ReLU, so backward never writes its dst gradient), bf16
     * nets convert them in place of layout (f32 -> bf16, same order: a streaming pass, where
     * the planar dlogits needed a transpose) */
    if (n->native_ok) {
      n->dout_direct = !last->has_relu && dnnl_memory_desc_equal(&last->dst_md, &last->ddst_md);
      if (!n->dout_direct)
        KPCN_TRY(
            kpcn_net_make_reorder(n, &n->dout_native, &last->dst_md, &last->ddst_md, &scratch));
    }
    if (n->o.input_grad) { /* dinput is dense [N][n_inputs][H][W] whatever the input's stride */
      dnnl_memory_desc_t user_din;
      DN(dnnl_memory_desc_init_by_tag(&user_din, 4, xd, dnnl_f32, dnnl_nchw));
      KPCN_TRY(kpcn_net_make_reorder(n, &n->dinput_out, &n->L[0].src_md, &user_din, &scratch));
    }
  }
  return bind_buffers(n, scratch);
}

kpcn_status kpcn_net_create(kpcn_model *m, kpcn_branch b, const kpcn_net_options *o,
                            kpcn_net **out) {
  if (!m || !o || !out)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_net_create: NULL argument");
  *out = NULL;
  if ((int)b < 0 || (int)b >= KPCN_N_BRANCHES)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_net_create: branch %d invalid", (int)b);
  if (o->batch < 1 || o->batch > 4096)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_net_create: batch = %d not in [1, 4096]",
                     o->batch);
  KPCN_TRY(kpcn_check_size(o->width, o->height, "kpcn_net_create"));
  if (o->input_plane_stride && o->input_plane_stride < (size_t)o->width * (size_t)o->height)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "kpcn_net_create: input plane stride %zu is smaller than the %dx%d plane",
                     o->input_plane_stride, o->width, o->height);
  if ((int64_t)o->batch * o->width * o->height > KPCN_MAX_PIXELS)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_net_create: batch x pixels too large");
  if (o->precision != KPCN_PREC_F32 && o->precision != KPCN_PREC_BF16)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_net_create: unknown precision %d",
                     (int)o->precision);
  if ((int)o->layout < 0 || (int)o->layout > KPCN_LAYOUT_NHWC)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_net_create: unknown layout %d",
                     (int)o->layout);
  if (o->layout == KPCN_LAYOUT_AUTO &&
      !(o->precision == KPCN_PREC_F32 && (o->training || !kpcn_cpu_allows_avx512()))) {
    /* nhwc first (brgconv / AMX kernels); if oneDNN falls back to its slow reference kernel
     * for some layer (e.g. f32 jit with large dilation), try nChw16c and keep the better.
     * f32 nets without AVX-512 choose per layer instead (kpcn_net_choose_tags). */
    kpcn_net_options oo = *o;
    oo.layout = KPCN_LAYOUT_NHWC;
    KPCN_TRY(kpcn_net_create(m, b, &oo, out));
    if ((*out)->n_slow == 0) return KPCN_OK;
    kpcn_net *alt = NULL;
    oo.layout = KPCN_LAYOUT_NCHW16C;
    if (kpcn_net_create(m, b, &oo, &alt) == KPCN_OK && alt->n_slow < (*out)->n_slow) {
      kpcn_net_destroy(*out);
      *out = alt;
    } else {
      kpcn_net_destroy(alt);
    }
    kpcn_clear_error();
    return KPCN_OK;
  }
  kpcn_net *n = kpcn_calloc(1, sizeof *n, "kpcn_net");
  if (!n) return KPCN_ERR_OUT_OF_MEMORY;
  n->model = m;
  n->branch = b;
  n->o = *o;
  n->o.training = o->training != 0;
  n->o.input_grad = n->o.training && o->input_grad;
  n->nl = m->arch.n_hidden + 1;
  n->nt = kpcn_resolve_threads(o->nthreads);
  thr_guard g = thr_push(n->nt);
  kpcn_status s = build(n);
  thr_pop(g);
  if (s != KPCN_OK) {
    kpcn_net_destroy(n);
    return s;
  }
  *out = n;
  return KPCN_OK;
}

void kpcn_net_destroy(kpcn_net *n) {
  if (!n) return;
  for (int l = 0; l < n->nl; l++) {
    layer *y = &n->L[l];
    dnnl_primitive_desc_t pds[4] = {y->fwd_pd, y->bwdd_pd, y->bwdw_pd, y->relu_pd};
    dnnl_primitive_t ps[4] = {y->fwd, y->bwdd, y->bwdw, y->relu};
    for (int i = 0; i < 4; i++) {
      if (ps[i]) dnnl_primitive_destroy(ps[i]);
      if (pds[i]) dnnl_primitive_desc_destroy(pds[i]);
    }
    dnnl_memory_t ms[12] = {y->src, y->dst,  y->w,    y->bias, y->bw,   y->dw,
                            y->db,  y->ddst, y->dsrc, y->ssrc, y->sdst, y->sdsrc};
    for (int i = 0; i < 12; i++)
      if (ms[i]) dnnl_memory_destroy(ms[i]);
    for (int side = 0; side < 2; side++) {
      kpcn_net_free_reorder(&y->gather[side]);
      kpcn_net_free_reorder(&y->scatter[side]);
      kpcn_net_free_reorder(&y->pad[side]);
      kpcn_net_free_reorder(&y->crop[side]);
    }
    kpcn_aligned_free(y->sin);
    kpcn_net_free_reorder(&y->w_in);
    kpcn_net_free_reorder(&y->bw_in);
    kpcn_net_free_reorder(&y->dw_out);
    kpcn_net_free_reorder(&y->src_in);
    kpcn_net_free_reorder(&y->dsrc_out);
    if (n->o.training) kpcn_aligned_free(y->act);
    kpcn_aligned_free(y->rin);
    kpcn_aligned_free(y->wflip);
    kpcn_aligned_free(y->wpad);
  }
  kpcn_net_free_reorder(&n->in);
  kpcn_net_free_reorder(&n->out);
  kpcn_net_free_reorder(&n->dout_in);
  kpcn_net_free_reorder(&n->dout_native);
  kpcn_net_free_reorder(&n->dinput_out);
  if (n->scratch_mem) dnnl_memory_destroy(n->scratch_mem);
  kpcn_aligned_free(n->xbuf);
  kpcn_aligned_free(n->rbuf);
  kpcn_aligned_free(n->pp[0]);
  kpcn_aligned_free(n->pp[1]);
  kpcn_aligned_free(n->sbuf[0]);
  kpcn_aligned_free(n->sbuf[1]);
  kpcn_aligned_free(n->pbuf[0]);
  kpcn_aligned_free(n->pbuf[1]);
  kpcn_aligned_free(n->dbuf[0]);
  kpcn_aligned_free(n->dbuf[1]);
  kpcn_aligned_free(n->wbuf);
  kpcn_aligned_free(n->grads);
  kpcn_aligned_free(n->scratch);
  kpcn_aligned_free(n->planar_logits);
  if (n->attr) dnnl_primitive_attr_destroy(n->attr);
  if (n->attr_relu) dnnl_primitive_attr_destroy(n->attr_relu);
  if (n->stream) dnnl_stream_destroy(n->stream);
  if (n->eng) dnnl_engine_destroy(n->eng);
  free(n);
}

kpcn_status kpcn_net_set_branch(kpcn_net *n, kpcn_branch b) {
  if (!n) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_net_set_branch: net is NULL");
  if ((int)b < 0 || (int)b >= KPCN_N_BRANCHES)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_net_set_branch: branch %d invalid", (int)b);
  n->branch = b;
  return KPCN_OK;
}

/* Space-to-batch layer (net_layer.c, try_space_to_batch): one side of it (0: input channels,
 * 1: output channels) from the whole image src into the batch of d*d sub-images dst, through
 * the zero-bordered buffer where d does not divide the size. That buffer's border must be
 * zero in this side's layout; layers of other channel counts or dilations lay it out
 * differently (the cpu preset's layers share one, so it is cleared once). */
static kpcn_status s2b_gather(kpcn_net *n, layer *y, int side, const void *src, void *dst) {
  if (y->pad[side].prim) {
    const int key[4] = {side ? y->cout : y->cin, (int)y->tag, y->s2b_hp, y->s2b_wp};
    if (memcmp(n->pbuf_zeroed, key, sizeof key)) {
      memset(n->pbuf[0], 0, n->pbuf_bytes);
      memcpy(n->pbuf_zeroed, key, sizeof key);
    }
    KPCN_TRY(kpcn_net_run_reorder(n, &y->pad[side], src, n->pbuf[0]));
    src = n->pbuf[0];
  }
  return kpcn_net_run_reorder(n, &y->gather[side], src, dst);
}

/* ... and back: sub-images src into the whole image dst. */
static kpcn_status s2b_scatter(kpcn_net *n, layer *y, int side, const void *src, void *dst) {
  if (!y->crop[side].prim) return kpcn_net_run_reorder(n, &y->scatter[side], src, dst);
  KPCN_TRY(kpcn_net_run_reorder(n, &y->scatter[side], src, n->pbuf[1]));
  return kpcn_net_run_reorder(n, &y->crop[side], n->pbuf[1], dst);
}

static kpcn_status forward(kpcn_net *n, const float *input, float *logits) {
  const kpcn_model *m = n->model;
  if (input) KPCN_TRY(kpcn_net_run_reorder(n, &n->in, input, n->xbuf)); /* else already there */
  for (int l = 0; l < n->nl; l++) {
    layer *y = &n->L[l];
    const float *w = m->w[n->branch][l], *b = m->b[n->branch][l];
    if (y->cpad != y->cout) { /* the padded rows stay zero */
      memcpy(y->wpad, w, sizeof(float) * (size_t)y->cout * y->cin * y->k * y->k);
      memcpy(y->bpad, b, sizeof(float) * (size_t)y->cout);
      w = y->wpad, b = y->bpad;
    }
    KPCN_TRY(kpcn_net_run_reorder_1t(n, &y->w_in, w, y->wp));
    if (y->src_in.prim)
      KPCN_TRY(kpcn_net_run_reorder(n, &y->src_in, n->L[l - 1].act, y->rin ? y->rin : n->rbuf));
    DN(dnnl_memory_set_data_handle(y->bias, (void *)b));
    if (y->s2b) {
      void *src = NULL;
      DN(dnnl_memory_get_data_handle(y->src, &src));
      KPCN_TRY(s2b_gather(n, y, 0, src, y->sin ? y->sin : n->sbuf[0]));
    }
    dnnl_exec_arg_t a[5] = {{DNNL_ARG_SRC, y->s2b ? y->ssrc : y->src},
                            {DNNL_ARG_WEIGHTS, y->w},
                            {DNNL_ARG_BIAS, y->bias},
                            {DNNL_ARG_DST, y->s2b ? y->sdst : y->dst},
                            {DNNL_ARG_SCRATCHPAD, n->scratch_mem}};
    double t0 = now_s();
    DN(dnnl_primitive_execute(y->fwd, n->stream, 5, a));
    DN(dnnl_stream_wait(n->stream));
    n->st.fwd_conv_s += now_s() - t0;
    if (y->s2b) KPCN_TRY(s2b_scatter(n, y, 1, n->sbuf[1], y->act));
  }
  return logits ? kpcn_net_run_reorder(n, &n->out, n->L[n->nl - 1].act, logits) : KPCN_OK;
}

/* Pixel stride of the net's input buffer when it is pixel-major (inference nets), else 0. */
static int input_pixel_stride(const kpcn_net *n) {
  const dnnl_memory_desc_t *md = &n->L[0].src_md;
  if (n->o.training || md->ndims != 4 || md->format_kind != dnnl_blocked || md->offset0 != 0 ||
      (md->data_type != dnnl_f32 && md->data_type != dnnl_bf16))
    return 0;
  const dnnl_blocking_desc_t *b = &md->format_desc.blocking;
  const dnnl_dim_t *st = b->strides, ps = st[3];
  const dnnl_dim_t H = n->o.height, W = n->o.width;
  return b->inner_nblks == 0 && st[1] == 1 && ps >= md->dims[1] && st[2] == W * ps &&
                 st[0] == H * W * ps
             ? (int)ps
             : 0;
}

void *kpcn_net_input_buffer(kpcn_net *n, int *pixel_stride, int *bf16) {
  const int ps = n ? input_pixel_stride(n) : 0;
  if (!ps) return NULL;
  if (pixel_stride) *pixel_stride = ps;
  if (bf16) *bf16 = n->L[0].src_md.data_type == dnnl_bf16;
  return n->xbuf;
}

/* input NULL: the caller wrote it into kpcn_net_input_buffer */
static kpcn_status check_input(const kpcn_net *n, const float *input, const char *fn) {
  if (!input && !input_pixel_stride(n))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "%s: NULL input, and the net has no pixel-major input buffer to read", fn);
  return KPCN_OK;
}

kpcn_status kpcn_net_forward(kpcn_net *n, const float *input, float *logits) {
  if (!n || !logits) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_net_forward: NULL argument");
  KPCN_TRY(check_input(n, input, "kpcn_net_forward"));
  thr_guard g = thr_push(n->nt);
  double t0 = now_s();
  kpcn_status s = forward(n, input, logits);
  n->st.fwd_s += now_s() - t0;
  n->st.n_fwd++;
  thr_pop(g);
  return s;
}

kpcn_status kpcn_net_forward_logits(kpcn_net *n, const float *input, const void **logits,
                                    kpcn_logits_layout *layout) {
  if (!n || !logits || !layout)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_net_forward_logits: NULL argument");
  KPCN_TRY(check_input(n, input, "kpcn_net_forward_logits"));
  const int N = n->o.batch, H = n->o.height, W = n->o.width, C = n->L[n->nl - 1].cout;
  if (!n->native_ok && !n->planar_logits) {
    n->planar_logits = kpcn_net_alloc(n, sizeof(float) * (size_t)N * C * H * W, "planar logits");
    if (!n->planar_logits) return KPCN_ERR_OUT_OF_MEMORY;
  }
  thr_guard g = thr_push(n->nt);
  double t0 = now_s();
  kpcn_status s = forward(n, input, n->native_ok ? NULL : n->planar_logits);
  n->st.fwd_s += now_s() - t0;
  n->st.n_fwd++;
  thr_pop(g);
  *logits = n->native_ok ? (const void *)n->L[n->nl - 1].act : (const void *)n->planar_logits;
  *layout = n->native_ok ? n->native : kpcn_logits_layout_planar(C, H, W);
  return s;
}

/* native: dlogits are in the layout kpcn_net_forward_logits reported, else planar */
static kpcn_status backward(kpcn_net *n, const float *dlogits, float *dinput, int native) {
  const kpcn_model *m = n->model;
  int cur = 0;
  const int direct = native && n->dout_direct;
  if (!direct)
    KPCN_TRY(
        kpcn_net_run_reorder(n, native ? &n->dout_native : &n->dout_in, dlogits, n->dbuf[cur]));
  for (int l = n->nl - 1; l >= 0; l--) {
    layer *y = &n->L[l];
    double t0;
    void *ddst = direct && l == n->nl - 1 ? (void *)dlogits : n->dbuf[cur];
    DN(dnnl_memory_set_data_handle(y->ddst, ddst));
    if (y->has_relu) {
      dnnl_exec_arg_t a[4] = {{DNNL_ARG_DST, y->dst},
                              {DNNL_ARG_DIFF_DST, y->ddst},
                              {DNNL_ARG_DIFF_SRC, y->ddst},
                              {DNNL_ARG_SCRATCHPAD, n->scratch_mem}};
      DN(dnnl_primitive_execute(y->relu, n->stream, 4, a));
    }
    /* a space-to-batch layer's backward reads its gathered input (kept by forward) and its
     * output gradient gathered the same way */
    if (y->s2b) KPCN_TRY(s2b_gather(n, y, 1, ddst, n->sbuf[1]));
    dnnl_memory_t bddst = y->s2b ? y->sdst : y->ddst;
    DN(dnnl_memory_set_data_handle(y->db, y->gb));
    dnnl_exec_arg_t aw[5] = {{DNNL_ARG_SRC, y->s2b ? y->ssrc : y->src},
                             {DNNL_ARG_DIFF_DST, bddst},
                             {DNNL_ARG_DIFF_WEIGHTS, y->dw},
                             {DNNL_ARG_DIFF_BIAS, y->db},
                             {DNNL_ARG_SCRATCHPAD, n->scratch_mem}};
    t0 = now_s();
    DN(dnnl_primitive_execute(y->bwdw, n->stream, 5, aw));
    DN(dnnl_stream_wait(n->stream));
    n->st.bwd_conv_s += now_s() - t0;
    KPCN_TRY(kpcn_net_run_reorder_1t(n, &y->dw_out, y->dwp, y->gw));
    if (y->bwdd) {
      if (y->bwdd_fwd) kpcn_net_flip_weights(y, m->w[n->branch][l]);
      KPCN_TRY(kpcn_net_run_reorder_1t(n, &y->bw_in, y->bwdd_fwd ? y->wflip : m->w[n->branch][l],
                                       y->bwp));
      DN(dnnl_memory_set_data_handle(y->dsrc, n->dbuf[cur ^ 1]));
      /* a forward primitive standing in for backward-data reads SRC and writes DST */
      dnnl_exec_arg_t ad[4] = {
          {y->bwdd_fwd ? DNNL_ARG_SRC : DNNL_ARG_DIFF_DST, bddst},
          {DNNL_ARG_WEIGHTS, y->bw},
          {y->bwdd_fwd ? DNNL_ARG_DST : DNNL_ARG_DIFF_SRC, y->s2b ? y->sdsrc : y->dsrc},
          {DNNL_ARG_SCRATCHPAD, n->scratch_mem}};
      t0 = now_s();
      DN(dnnl_primitive_execute(y->bwdd, n->stream, 4, ad));
      DN(dnnl_stream_wait(n->stream));
      n->st.bwd_conv_s += now_s() - t0;
      if (y->s2b) KPCN_TRY(s2b_scatter(n, y, 0, n->sbuf[0], n->dbuf[cur ^ 1]));
      /* into the previous layer's layout, over this layer's spent output gradient */
      if (y->dsrc_out.prim)
        KPCN_TRY(kpcn_net_run_reorder(n, &y->dsrc_out, n->dbuf[cur ^ 1], n->dbuf[cur]));
      else
        cur ^= 1;
    }
  }
  if (n->o.input_grad) KPCN_TRY(kpcn_net_run_reorder(n, &n->dinput_out, n->dbuf[cur], dinput));
  return KPCN_OK;
}

static kpcn_status backward_checked(kpcn_net *n, const float *dlogits, float *dinput, int native,
                                    const char *fn) {
  if (!n || !dlogits) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s: NULL argument", fn);
  if (!n->o.training)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "%s: net was created for inference (options.training = 0)", fn);
  if (n->st.n_fwd == 0)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s: no forward pass to differentiate", fn);
  if (n->o.input_grad && !dinput)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "%s: dinput is NULL but the net was created with input_grad", fn);
  thr_guard g = thr_push(n->nt);
  double t0 = now_s();
  kpcn_status s = backward(n, dlogits, dinput, native);
  n->st.bwd_s += now_s() - t0;
  n->st.n_bwd++;
  thr_pop(g);
  return s;
}

kpcn_status kpcn_net_backward(kpcn_net *n, const float *dlogits, float *dinput) {
  return backward_checked(n, dlogits, dinput, 0, "kpcn_net_backward");
}

kpcn_status kpcn_net_backward_logits(kpcn_net *n, const float *dlogits, float *dinput) {
  /* without a native layout, kpcn_net_forward_logits reported planar logits */
  return backward_checked(n, dlogits, dinput, n && n->native_ok, "kpcn_net_backward_logits");
}

int kpcn_net_param_count(const kpcn_net *n) { return n ? 2 * n->nl : 0; }

kpcn_status kpcn_net_params(kpcn_net *n, kpcn_param *out, int max) {
  if (!n || !out) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_net_params: NULL argument");
  if (max < 2 * n->nl)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_net_params: max = %d < %d parameters", max,
                     2 * n->nl);
  for (int l = 0; l < n->nl; l++) {
    layer *y = &n->L[l];
    for (int isb = 0; isb < 2; isb++) {
      kpcn_param *p = &out[2 * l + isb];
      kpcn_model_tensor_name(p->name, sizeof p->name, n->branch, l, isb);
      p->value = isb ? n->model->b[n->branch][l] : n->model->w[n->branch][l];
      p->grad = n->o.training ? (isb ? y->gb : y->gw) : NULL;
      p->count = isb ? (size_t)y->cout : (size_t)y->cout * y->cin * y->k * y->k;
    }
  }
  return KPCN_OK;
}

void kpcn_net_get_stats(const kpcn_net *n, kpcn_net_stats *s) {
  if (!n || !s) return;
  *s = n->st;
  s->bytes = n->bytes;
  s->n_slow = n->n_slow;
  s->n_bwdd_fwd = n->n_bwdd_fwd;
  s->n_space_to_batch = 0;
  for (int l = 0; l < n->nl; l++)
    s->n_space_to_batch += n->L[l].s2b;
  s->n_relayout = n->n_relayout;
}

const char *kpcn_net_impl_name(const kpcn_net *n, int l) {
  return n && l >= 0 && l < n->nl ? n->impl[l] : "";
}
