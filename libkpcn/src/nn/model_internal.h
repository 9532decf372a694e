/* Private layout of kpcn_model, shared by model.c, safetensors.c and net.c. */
#ifndef KPCN_NN_MODEL_INTERNAL_H
#define KPCN_NN_MODEL_INTERNAL_H
#include "kpcn/nn.h"

struct kpcn_model {
  kpcn_arch arch;
  float *block; /* one aligned allocation holding every tensor */
  size_t block_floats;
  float *w[KPCN_N_BRANCHES][KPCN_NN_MAX_LAYERS];
  float *b[KPCN_N_BRANCHES][KPCN_NN_MAX_LAYERS];
  int n_meta;
  char **meta_key, **meta_val;
};

extern const char *const kpcn_nn_branch_names[KPCN_N_BRANCHES];

/* A model file's __metadata__ holds at most this many entries (the loader refuses more: each
 * is searched for among the earlier ones), KPCN_MODEL_KPCN_KEYS of them the kpcn.* keys the
 * saver writes, so a model takes at most the difference in user entries. */
#define KPCN_MODEL_MAX_META_ENTRIES 4096
#define KPCN_MODEL_KPCN_KEYS 6

/* Allocates a model with zeroed tensors for a validated arch (no init). */
kpcn_status kpcn_model_alloc(const kpcn_arch *arch, kpcn_model **out);
/* Element count of the weight tensor of layer l. */
size_t kpcn_model_weight_count(const kpcn_arch *a, int l);
#endif
