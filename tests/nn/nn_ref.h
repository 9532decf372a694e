/* Naive direct-loop reference of one KPCN branch in double precision (tests only). */
#ifndef KPCN_TEST_NN_REF_H
#define KPCN_TEST_NN_REF_H
#include "kpcn/nn.h"

typedef struct nn_ref {
  const kpcn_arch *a;
  int n, h, w, nl;
  const double *wt[KPCN_NN_MAX_LAYERS], *bs[KPCN_NN_MAX_LAYERS]; /* OIHW, bias */
  double *act[KPCN_NN_MAX_LAYERS + 1]; /* act[0] = input, act[l+1] = output of layer l */
  double *gw[KPCN_NN_MAX_LAYERS], *gb[KPCN_NN_MAX_LAYERS];
  double *dinput;
} nn_ref;

/* weights/biases are copied from the model's branch b (as doubles, owned by the ref) */
void nn_ref_init(nn_ref *r, kpcn_model *m, kpcn_branch b, int n, int h, int w);
void nn_ref_free(nn_ref *r);
/* forward from float input; returns pointer to the logits (N x K² x H x W) */
const double *nn_ref_forward(nn_ref *r, const float *input);
/* backward of the last forward given dL/dlogits (float) */
void nn_ref_backward(nn_ref *r, const float *dlogits);
/* set parameter element (for finite differences): layer l, bias?1:0, index i */
void nn_ref_set_param(nn_ref *r, int l, int isb, size_t i, double v);
double nn_ref_get_param(nn_ref *r, int l, int isb, size_t i);
#endif
