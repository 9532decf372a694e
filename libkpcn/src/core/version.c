/* What this libkpcn is and what it runs on (kpcn_build_info, kpcn/common.h): its version, the
 * versions of the libraries it was built with or loaded, and the instruction set its compute
 * uses on this CPU. Renders and networks are bit-identical for a seed only on one instruction
 * set (docs/renderer.md, "Determinism"), so tools print this with --version and scripts that
 * compare figures across machines record it. */
#include "core/internal.h"

#include <openexr.h>
#include <pthread.h>
#include <stdio.h>

#ifdef KPCN_HAVE_DNNL
#include <oneapi/dnnl/dnnl.h>
#endif
#ifdef KPCN_HAVE_EMBREE
#include <embree3/rtcore_config.h>
#endif

static char info[256];
static pthread_once_t once = PTHREAD_ONCE_INIT;

static void build(void) {
  int maj = 0, min = 0, patch = 0;
  const char *extra = NULL;
  exr_get_library_version(&maj, &min, &patch, &extra);
  char dnnl[48] = "none";
  const char *embree = "none";
#ifdef KPCN_HAVE_DNNL
  const dnnl_version_t *v = dnnl_version(); /* the loaded library's, not the header's */
  snprintf(dnnl, sizeof dnnl, "%d.%d.%d", v->major, v->minor, v->patch);
#endif
#ifdef KPCN_HAVE_EMBREE
  embree = RTC_VERSION_STRING; /* the headers built against */
#endif
  snprintf(info, sizeof info,
           "libkpcn %s; instruction set %s; oneDNN %s, Embree %s, OpenEXR %d.%d.%d%s",
           KPCN_VERSION_STRING, kpcn_cpu_isa(), dnnl, embree, maj, min, patch, extra ? extra : "");
}

const char *kpcn_cpu_isa(void) { return kpcn_cpu_allows_avx512() ? "avx512" : "avx2"; }

const char *kpcn_build_info(void) {
  pthread_once(&once, build);
  return info;
}
