/* Synthetic patch stores for the trainer tests. */
#ifndef KPCN_TRAIN_FIXTURE_H
#define KPCN_TRAIN_FIXTURE_H
#include "kpcn/dataset.h"

/* Builds a noisy/reference AOV pair of size w x h from seed: smooth reference buffers,
 * noisy = reference + noise. If box_ref, the reference diffuse/specular are instead the
 * 3x3 box blur (clamped borders) of the noisy ones in the network's preprocessed domains
 * (demodulated diffuse, log specular), so a kernel-predicting net can fit them exactly. */
int tf_make_pair(kpcn_aov_set **noisy, kpcn_aov_set **ref, int w, int h, unsigned seed,
                 int box_ref);

/* Writes a store of `count` patches of size S cut from one w x h pair (grid positions),
 * with the given channel list (NULL = default). Returns 0 on success. */
int tf_make_store(const char *path, int S, int w, int h, int count, unsigned seed, int box_ref,
                  const char *const *channels, int nchannels);
#endif
