/* kpcn/metrics.h — image quality metrics (DESIGN.md §7): L1, MSE, relMSE, relL1, PSNR, SSIM.
 *
 * Every metric compares a test image x against a reference y, channel by channel, and
 * returns the mean over pixels and the compared channels:
 *
 *   L1      |x - y|
 *   MSE     (x - y)^2
 *   relMSE  (x - y)^2 / (y^2 + eps)          eps = 0.01 by default
 *   relL1   |x - y| / (|y| + eps)
 *   PSNR    10 log10(range^2 / MSE)          range = data_range (default 1); +inf if MSE = 0
 *   SSIM    Wang et al. 2004, exactly as scikit-image's
 *           structural_similarity(gaussian_weights=True, sigma=1.5,
 *           use_sample_covariance=False, data_range=range): separable 11-tap Gaussian
 *           (sigma 1.5, radius int(3.5*sigma+0.5) = 5, normalised), K1 = 0.01, K2 = 0.03,
 *           population covariance, C1 = (K1 R)^2, C2 = (K2 R)^2; the SSIM map is averaged
 *           over the interior only (a border of 5 pixels is cropped), per channel, then the
 *           channel means are averaged. Images must be at least 11x11.
 *
 * Display encoding (opt.display = KPCN_DISPLAY_SRGB): both images are clamped to [0,1] and
 * sRGB-encoded (IEC 61966-2-1 piecewise curve) before the metric.
 *
 * Non-finite policy: a pixel where ANY compared channel of x or y is NaN or +-Inf is
 * excluded from the mean and counted in kpcn_metric_result.nonfinite. The library never
 * fails because of them (callers decide; kpcntool fails unless told otherwise). For SSIM every
 * compared channel of an excluded pixel is replaced by 0 in both images before filtering (windows
 * around them then see equal values there) and the pixels themselves are excluded from the mean. In
 * error maps, excluded pixels hold NaN. If no pixel is left, the call fails with
 * KPCN_ERR_NONFINITE.
 *
 * Error maps: one plane per compared channel, w*h floats each, holding the per-pixel term
 * being averaged (|x-y|, (x-y)^2, ...). PSNR's map is the squared error. SSIM's map is the
 * full per-pixel SSIM map (as skimage's full=True, 'reflect' borders), i.e. a similarity
 * where 1 means identical.
 *
 * Determinism: sums are accumulated per row in double and the rows summed in order, so the
 * result does not depend on the thread count.
 */
#ifndef KPCN_METRICS_H
#define KPCN_METRICS_H

#include "kpcn/image.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef enum kpcn_metric {
  KPCN_METRIC_L1 = 0,
  KPCN_METRIC_MSE,
  KPCN_METRIC_RELMSE,
  KPCN_METRIC_RELL1,
  KPCN_METRIC_PSNR,
  KPCN_METRIC_SSIM,
  KPCN_METRIC_COUNT
} kpcn_metric;

/* Lower-case name ("l1", "mse", "relmse", "rell1", "psnr", "ssim"). */
const char *kpcn_metric_name(kpcn_metric m);
/* Metric named `name` (case-insensitive), or -1. */
int kpcn_metric_from_name(const char *name);

typedef enum kpcn_display { KPCN_DISPLAY_LINEAR = 0, KPCN_DISPLAY_SRGB = 1 } kpcn_display;

typedef struct kpcn_metric_options {
  kpcn_display display; /* encode both images before comparing (default linear) */
  double data_range;    /* SSIM data range R and PSNR peak (default 1.0) */
  double eps;           /* relMSE / relL1 epsilon (default 0.01; must be > 0) */
  int nthreads;         /* 0 = all cores */
} kpcn_metric_options;

void kpcn_metric_options_defaults(kpcn_metric_options *opt);

typedef struct kpcn_metric_result {
  double value;      /* the metric (mean over valid pixels and compared channels) */
  int64_t npixels;   /* pixels averaged (for SSIM: interior pixels) */
  int64_t nonfinite; /* pixels excluded because x or y was non-finite there (whole image) */
  int nchannels;     /* channels compared */
} kpcn_metric_result;

/* sRGB encoding of one value: clamp to [0,1], then the piecewise IEC 61966-2-1 curve. */
double kpcn_srgb_encode(double v);

/* Core form over planar buffers: x and y hold nch planes of w*h floats each
 * (plane c at x + c*w*h). errormap (may be NULL) receives nch planes of w*h floats.
 * Fails on NULL pointers, bad sizes, SSIM on images smaller than 11x11, or when no finite
 * pixel is left. */
kpcn_status kpcn_metric_planar(kpcn_metric m, const float *x, const float *y, int w, int h, int nch,
                               const kpcn_metric_options *opt, kpcn_metric_result *res,
                               float *errormap);

/* Whether a comparison that names no channels compares R,G,B: both images have them and
 * either is an AOV image (a channel other than R, G, B, A). Otherwise every channel of the
 * reference. The one rule of kpcn_metric_image, the ImageBuf ops and kpcntool (metrics.md,
 * "Channels"): a render against its reference is measured on its colour, not on an average
 * with its variances, normals and depth. */
int kpcn_metric_default_rgb(const char *const *xnames, int nx, const char *const *ynames, int ny);

/* Image form: compares the channels named in `channels` (nnames entries; NULL with nnames 0 =
 * the default above) of x and y, matched by name. A list without its length (or a length
 * without a list) is KPCN_ERR_INVALID_ARGUMENT. Fails with
 * KPCN_ERR_SIZE_MISMATCH for different sizes or (without a channel list, when the names do
 * not match) different channel counts, KPCN_ERR_MISSING_CHANNEL naming a channel absent from
 * either image. If errormap is non-NULL it receives a new image (caller destroys) with one
 * channel per compared channel, named like them. */
kpcn_status kpcn_metric_image(kpcn_metric m, const kpcn_image *x, const kpcn_image *y,
                              const char *const *channels, int nnames,
                              const kpcn_metric_options *opt, kpcn_metric_result *res,
                              kpcn_image **errormap);

#ifdef __cplusplus
}
#endif
#endif
