/* The integrator compiled a second time with GFNI enabled (-mgfni, set by libkpcn's
 * CMakeLists.txt), as kpcn_trace_pixel_gfni: the Owen-scrambled Sobol sampler's bit
 * reversals become one affine byte transform each (render/sampler.h), ~3 % of the render
 * time on Zen 4/5. Same arithmetic otherwise, so the same output bits (test_render_packets);
 * kpcn_render_ctx_init picks it on CPUs that have GFNI. */
#ifdef KPCN_HAVE_GFNI_VARIANT
#define KPCN_TRACE_PIXEL kpcn_trace_pixel_gfni
#include "render/integrator.c"
#else
typedef int kpcn_integrator_gfni_not_built; /* ISO C wants a non-empty file */
#endif
