/* The kernel layer's argument checks (kpa.c), shared with its chain of passes (kpa_passes.c),
 * which indexes the logits through the layout before the plain layer would check it. */
#ifndef KPCN_NN_KPA_INTERNAL_H
#define KPCN_NN_KPA_INTERNAL_H
#include "kpcn/nn.h"

/* K odd in [1, KPCN_NN_MAX_KERNEL], n >= 1, nc in [1, 64], a valid size, and a non-NULL layout
 * of nlogits channels per pixel that does not overlap itself. Fails naming fn. */
kpcn_status kpcn_kpa_check_call(const char *fn, int K, int n, int nc, int h, int w,
                                const kpcn_logits_layout *layout, int nlogits);
#endif
