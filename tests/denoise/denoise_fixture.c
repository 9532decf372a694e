/* Writes the inputs of test_denoise_cli.sh into a folder: aov.exr (synthetic AOV set with
 * every buffer), aov_nodiffuse.exr (the same without diffuse.*), model.safetensors (tiny
 * random model with the feature list), and bilateral_api.exr / nlmeans_api.exr / kpcn_api.exr:
 * the baselines' and the KPCN's (that model file, f32, default options, 2 threads) results
 * through the C API (kpcn_denoise_aov), which kpcntool's must equal. */
#include <stdlib.h>

#include "kpcn/denoise.h"
#include "kpcn/exr.h"
#include "synth.h"

int main(int argc, char **argv) {
  if (argc != 2) return fprintf(stderr, "usage: denoise_fixture DIR\n"), 2;
  char p[1024], model[1024];
  kpcn_aov_set *a = synth_aov(48, 36, 4);
  kpcn_arch arch;
  kpcn_model *m = NULL;
  if (!a || kpcn_arch_preset("tiny", &arch) || kpcn_features_set_arch(&arch) ||
      kpcn_model_create(&arch, 3, &m))
    return fprintf(stderr, "fixture: %s\n", kpcn_last_error()), 1;
  snprintf(p, sizeof p, "%s/aov.exr", argv[1]);
  if (kpcn_exr_write_aov(p, a, NULL)) return fprintf(stderr, "%s\n", kpcn_last_error()), 1;
  snprintf(model, sizeof model, "%s/model.safetensors", argv[1]);
  if (kpcn_model_save(m, model)) return fprintf(stderr, "%s\n", kpcn_last_error()), 1;
  const int methods[3] = {KPCN_DENOISE_BILATERAL, KPCN_DENOISE_NLMEANS, KPCN_DENOISE_KPCN};
  const char *names[3] = {"bilateral", "nlmeans", "kpcn"};
  for (int k = 0; k < 3; k++) {
    kpcn_denoiser_options o;
    kpcn_denoiser_options_defaults(&o);
    o.method = methods[k];
    if (methods[k] == KPCN_DENOISE_KPCN) o.model_path = model, o.nthreads = 2;
    kpcn_image *rgb = NULL;
    snprintf(p, sizeof p, "%s/%s_api.exr", argv[1], names[k]);
    if (kpcn_denoise_aov(a, &o, &rgb) || kpcn_exr_write_image(p, rgb, NULL))
      return fprintf(stderr, "fixture: %s\n", kpcn_last_error()), 1;
    kpcn_image_destroy(rgb);
  }
  free(a->buf[KPCN_BUF_DIFFUSE]);
  free(a->var[KPCN_BUF_DIFFUSE]);
  a->buf[KPCN_BUF_DIFFUSE] = a->var[KPCN_BUF_DIFFUSE] = NULL;
  snprintf(p, sizeof p, "%s/aov_nodiffuse.exr", argv[1]);
  if (kpcn_exr_write_aov(p, a, NULL)) return fprintf(stderr, "%s\n", kpcn_last_error()), 1;
  kpcn_model_destroy(m);
  kpcn_aov_destroy(a);
  return 0;
}
