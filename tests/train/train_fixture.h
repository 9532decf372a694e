/* Synthetic patch stores for the trainer tests. */
#ifndef KPCN_TRAIN_FIXTURE_H
#define KPCN_TRAIN_FIXTURE_H
#include "kpcn/dataset.h"
#include "kpcn/train.h"

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
/* The same with nsources (1 to 8) sources of the same pair, source k marked with split
 * splits[k]; patch i belongs to source i % nsources. */
int tf_make_split_store(const char *path, int S, int w, int h, int count, unsigned seed,
                        int box_ref, const char *const *channels, int nchannels,
                        const char *const *splits, int nsources);

/* A temporary file path that stays valid for the test's life: kt_tmpfile cycles through 8
 * buffers, and the trainer tests hold many paths at once, so tf_tmp copies them into a pool of
 * its own (64 names, then it wraps). */
const char *tf_tmp(const char *name);

/* The 20x20-patch store of 12 patches cut from one 48x40 pair (seed 1) that the trainer tests
 * train on, written to tf's own path `name`; NULL (with the error printed) if it cannot be built.
 */
const char *tf_make_test_store(const char *name);

/* The settings the trainer tests start from: the tiny preset at 16 channels (oneDNN 2.6's jit
 * kernels need channel blocks of 16; 8 falls back to ref:any), batch 3 of 16x16, 6 iterations
 * of which 3 in stage 1, 2 threads, seed 5, lr 1e-2. */
void tf_settings(kpcn_train_settings *s, const char *store, const char *out);

/* All parameters of both branches of m, concatenated (malloc'ed); *n receives the count. */
float *tf_model_weights(kpcn_model *m, size_t *n);

/* Writes a synthetic 40x32 validation pair (seed 9) as EXRs named "<prefix>_noisy.exr" and
 * "<prefix>_ref.exr" (tf_tmp) and sets it as the settings' one validation pair (vn, vr: arrays
 * of one that must outlive the trainer); also sets nthreads 1. */
void tf_val_pair(kpcn_train_settings *s, const char *prefix, const char **vn, const char **vr);

/* A progress callback that stops the run once it reaches iteration tf_stop_at. */
extern int tf_stop_at;
int tf_stop_cb(void *user, const kpcn_train_progress *p);
#endif
