/* Weight averaging (stochastic weight averaging, Izmailov et al. 2018): the element-wise mean
 * of the weights of several snapshots of one run. With a constant or slowly decaying learning
 * rate, Adam's iterates wander around a minimum (the validation error of single snapshots
 * varies by ±10 % from one evaluation to the next on this project's runs); their mean sits
 * nearer its centre. Inputs may be model files or training checkpoints, mixed. */
#include "core/internal.h"
#include "kpcn/train.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* A model file or, failing that, a training checkpoint; the error names both attempts. */
static kpcn_status load_any(const char *path, kpcn_model **out) {
  kpcn_status st = kpcn_model_load(path, out);
  if (st == KPCN_OK || st == KPCN_ERR_IO) return st; /* unreadable: no second try */
  char as_model[512], as_ckpt[512];
  snprintf(as_model, sizeof as_model, "%s", kpcn_last_error());
  if (kpcn_checkpoint_load_model(path, out) == KPCN_OK) return KPCN_OK;
  snprintf(as_ckpt, sizeof as_ckpt, "%s", kpcn_last_error());
  return kpcn_fail(KPCN_ERR_FORMAT, "neither a model (%s) nor a checkpoint (%s)", as_model,
                   as_ckpt);
}

/* Adds (sum != NULL) every tensor of m into sum, or writes sum / n back into m. */
static kpcn_status walk(kpcn_model *m, double *sum, const double *mean_of, int n) {
  const kpcn_arch *a = kpcn_model_arch(m);
  size_t off = 0;
  for (int b = 0; b < KPCN_N_BRANCHES; b++)
    for (int l = 0; l <= a->n_hidden; l++) {
      kpcn_layer_view v;
      KPCN_TRY(kpcn_model_layer(m, (kpcn_branch)b, l, &v));
      size_t nw = (size_t)v.out_ch * v.in_ch * v.size * v.size, nb = (size_t)v.out_ch;
      float *t[2] = {v.weight, v.bias};
      size_t c[2] = {nw, nb};
      for (int k = 0; k < 2; k++) {
        for (size_t i = 0; i < c[k]; i++) {
          if (sum)
            sum[off + i] += t[k][i];
          else
            t[k][i] = (float)(mean_of[off + i] / n);
        }
        off += c[k];
      }
    }
  return KPCN_OK;
}

kpcn_status kpcn_model_average(const char *const *paths, int n, kpcn_model **out) {
  if (!paths || !out || n < 1)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_model_average: no input (n = %d)", n);
  *out = NULL;
  kpcn_model *first = NULL;
  KPCN_TRY(load_any(paths[0], &first));
  char *arch = kpcn_arch_to_json(kpcn_model_arch(first));
  double *sum = kpcn_calloc(KPCN_N_BRANCHES * kpcn_arch_param_count(kpcn_model_arch(first)),
                            sizeof *sum, "weight average");
  kpcn_status st = arch && sum ? walk(first, sum, NULL, 0) : kpcn_last_status();
  if (!arch && st == KPCN_OK)
    st = kpcn_fail(KPCN_ERR_OUT_OF_MEMORY, "out of memory for the weight average");
  for (int i = 1; i < n && st == KPCN_OK; i++) {
    kpcn_model *m = NULL;
    if ((st = load_any(paths[i], &m)) != KPCN_OK) break;
    /* The recorded exposure is part of the arch record but not of the network's shape: a
     * mismatch there alone gets its own message, since the fix differs (record one store's
     * exposure in every input) and "another architecture" would send the user looking at
     * layer sizes. Models expecting inputs at different scales are still not averaged. */
    kpcn_arch same_exposure = *kpcn_model_arch(m);
    same_exposure.exposure = kpcn_model_arch(first)->exposure;
    char *ai = kpcn_arch_to_json(&same_exposure);
    if (!ai)
      st = kpcn_last_status();
    else if (strcmp(ai, arch) != 0)
      st =
          kpcn_fail(KPCN_ERR_FORMAT, "'%s' has another architecture than '%s'", paths[i], paths[0]);
    else if (kpcn_model_arch(m)->exposure != kpcn_model_arch(first)->exposure)
      st = kpcn_fail(KPCN_ERR_FORMAT,
                     "'%s' records exposure %.9g, '%s' %.9g: the models expect inputs at other "
                     "scales; record one store's exposure in each first (kpcn-train "
                     "--record-exposure)",
                     paths[i], kpcn_model_arch(m)->exposure, paths[0],
                     kpcn_model_arch(first)->exposure);
    else
      st = walk(m, sum, NULL, 0);
    free(ai);
    kpcn_model_destroy(m);
  }
  if (st == KPCN_OK) st = walk(first, NULL, sum, n);
  if (st == KPCN_OK) {
    char note[96];
    snprintf(note, sizeof note, "%d", n);
    st = kpcn_model_set_meta(first, "train.averaged_snapshots", note);
  }
  free(arch);
  free(sum);
  if (st != KPCN_OK) {
    kpcn_model_destroy(first);
    return st;
  }
  *out = first;
  return KPCN_OK;
}
