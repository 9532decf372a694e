/* Shared between metrics.c and ssim.c (not installed). */
#ifndef KPCN_METRICS_INTERNAL_H
#define KPCN_METRICS_INTERNAL_H

#include "kpcn/metrics.h"

/* 1 where every one of the nch channels of x and y is finite at that pixel; *nonfinite gets
 * the number of 0 entries. Returns NULL (error set) when allocation fails. Caller frees. */
uint8_t *kpcn_metric_valid_mask(const float *x, const float *y, int w, int h, int nch, int nthreads,
                                int64_t *nonfinite);

/* SSIM over planar buffers; arguments already validated by kpcn_metric_planar. */
kpcn_status kpcn_ssim_planar(const float *x, const float *y, int w, int h, int nch,
                             const kpcn_metric_options *opt, kpcn_metric_result *res,
                             float *errormap);
#endif
