/* Private layout of kpcn_net and the helpers shared by net.c (create, run, backward) and
 * net_layer.c (one conv layer's primitives). */
#ifndef KPCN_NN_NET_INTERNAL_H
#define KPCN_NN_NET_INTERNAL_H
#include "core/internal.h"
#include "nn/model_internal.h"

#include <oneapi/dnnl/dnnl.h>
#include <oneapi/dnnl/dnnl_debug.h>

#define DN(call)                                                                                   \
  do {                                                                                             \
    dnnl_status_t _d = (call);                                                                     \
    if (_d != dnnl_success)                                                                        \
      return kpcn_fail(KPCN_ERR_INTERNAL, "oneDNN: %s failed: %s (%s:%d)", #call,                  \
                       dnnl_status2str(_d), __FILE__, __LINE__);                                   \
  } while (0)

typedef struct reorder {
  dnnl_primitive_t prim;
  dnnl_memory_t src, dst;
} reorder;

typedef struct layer {
  int cin, cout, k, d, has_relu;
  /* Output channels the primitive computes: cout, or for an inference net's pixel-major
   * logits layer cout rounded up to 16, the extra rows zero (net_layer.c, pad_logits). */
  int cpad;
  float *wpad, *bpad; /* ... then the model's weights and bias are copied into these first */
  dnnl_memory_desc_t src_md, dst_md, w_md, bw_md, dw_md;
  dnnl_memory_desc_t ddst_md; /* dst gradient: dst_md, but bf16 for bf16 f32-logits layers */
  dnnl_primitive_desc_t fwd_pd, bwdd_pd, bwdw_pd, relu_pd;
  dnnl_primitive_t fwd, bwdd, bwdw, relu;
  dnnl_memory_t src, dst, w, bias;      /* forward operands */
  dnnl_memory_t bw, dw, db, ddst, dsrc; /* backward operands */
  reorder w_in, bw_in, dw_out;          /* OIHW <-> primitive weight layouts */
  reorder src_in;        /* previous layer's dst -> this layer's src layout, where they differ */
  reorder dsrc_out;      /* ... and back for the input gradient (training) */
  dnnl_format_tag_t tag; /* activation layout of this layer (build_layer) */
  void *rin;             /* training: this layer's own reordered input (backward reads it) */
  int winograd;
  /* Space-to-batch (net_layer.c, try_space_to_batch): a dilated layer run as an undilated
   * conv on the d*d interleaved sub-images of its input, gathered into one batch. Side 0 is
   * the layer's input (cin channels), side 1 its output (cout): the forward pass gathers side
   * 0 and scatters side 1, the backward pass gathers side 1 (the output gradient) and
   * scatters side 0 (the input gradient). */
  int s2b;
  dnnl_memory_desc_t s2b_md[2];    /* ... both sides in the batch layout */
  dnnl_memory_t ssrc, sdst, sdsrc; /* ... operands there (net->sbuf; ssrc: sin in training) */
  size_t s2b_bytes[2];             /* ... sizes of both sides */
  int s2b_hp, s2b_wp;              /* ... the padded extent (multiples of d) */
  reorder gather[2], scatter[2];   /* ... whole image <-> sub-images, per side */
  reorder pad[2], crop[2];         /* ... through zero-bordered buffers (net->pbuf) where d
                                      does not divide the size */
  void *sin;                       /* ... training: the gathered input, for backward-weights */
  int bwdd_fwd;                    /* backward-data runs as a forward conv with flipped weights */
  float *wflip;                    /* ... whose OIHW weights (cin x cout x k x k) are built here */
  float *gw, *gb;                  /* gradients, OIHW f32 (net-owned) */
  void *act;                       /* dst buffer */
  void *wp, *bwp, *dwp;            /* weight copies in primitive layouts */
} layer;

struct kpcn_net {
  kpcn_model *model;
  kpcn_branch branch;
  kpcn_net_options o;
  int nl, nt;
  dnnl_engine_t eng;
  dnnl_stream_t stream;
  dnnl_primitive_attr_t attr, attr_relu; /* user scratchpad; + fused ReLU post-op */
  layer L[KPCN_NN_MAX_LAYERS];
  reorder in, out, dout_in, dinput_out;
  reorder dout_native; /* native-layout f32 dlogits -> the last layer's dst gradient */
  int dout_direct;     /* ... or none: native dlogits already are that gradient */
  void *xbuf;          /* layer-0 input in its primitive layout */
  void *rbuf;          /* a layer's input after src_in (inference; shared) */
  void *pp[2];         /* inference ping-pong activation buffers */
  void *sbuf[2];       /* space-to-batch layers' sides 0 and 1 in the batch layout */
  void *pbuf[2];       /* ... whole images padded to multiples of d: gathered from, scattered to */
  size_t pbuf_bytes;   /* size of pbuf[0] */
  int pbuf_zeroed[4];  /* channels, tag, Hp, Wp of the layout whose border pbuf[0] holds zero */
  void *dbuf[2];       /* backward gradient ping-pong buffers */
  void *wbuf;          /* all primitive-layout weight copies */
  float *grads;        /* all gradients */
  void *scratch;
  dnnl_memory_t scratch_mem;
  size_t bytes;
  int n_slow, n_bwdd_fwd, n_relayout;
  kpcn_net_stats st;
  char impl[KPCN_NN_MAX_LAYERS][64];
  int native_ok;             /* the last layer's output layout is readable by the kpa */
  kpcn_logits_layout native; /* ... and this is it */
  float *planar_logits;      /* fallback buffer of kpcn_net_forward_logits */
};

void *kpcn_net_alloc(kpcn_net *n, size_t bytes, const char *what);
kpcn_status kpcn_net_mem(kpcn_net *n, dnnl_memory_t *m, const dnnl_memory_desc_t *md, void *h);
size_t kpcn_net_pd_scratch(const_dnnl_primitive_desc_t pd);
kpcn_status kpcn_net_make_reorder(kpcn_net *n, reorder *r, const dnnl_memory_desc_t *from,
                                  const dnnl_memory_desc_t *to, size_t *scratch);
kpcn_status kpcn_net_run_reorder(kpcn_net *n, reorder *r, const void *src, void *dst);
kpcn_status kpcn_net_run_reorder_1t(kpcn_net *n, reorder *r, const void *src, void *dst);
void kpcn_net_free_reorder(reorder *r);
kpcn_status kpcn_net_make_pd(kpcn_net *n, dnnl_primitive_desc_t *pd, const void *desc,
                             const_dnnl_primitive_attr_t attr, const_dnnl_primitive_desc_t hint,
                             const char *what, int l, size_t *scratch);

/* net_layer.c */
int kpcn_net_impl_is(const_dnnl_primitive_desc_t pd, const char *prefix);
void kpcn_net_flip_weights(const layer *y, const float *w);
/* Tests: nets created after this with on = 1 run every layer's backward-data as a forward conv
 * wherever that forward is no fallback, not only where oneDNN's own backward-data is one
 * (which depends on the CPU: Zen 4 falls back for dilation 8, an AVX-512 Xeon does not), so
 * the path is checked on every CPU. Not thread-safe; 0 restores the default. */
void kpcn_net_set_bwdd_as_forward_always(int on);
/* Chooses every layer's activation layout (n->L[l].tag; net_layer.c says how). */
kpcn_status kpcn_net_choose_tags(kpcn_net *n);
kpcn_status kpcn_net_build_layer(kpcn_net *n, int l, const dnnl_memory_desc_t *src_md,
                                 size_t *scratch);
#endif
