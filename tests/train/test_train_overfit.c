/* Overfitting: a tiny net on ONE fixed patch (no augmentation, no crop jitter) whose
 * reference is an exactly representable kernel (3x3 box in the preprocessed domains)
 * must drive the stage-1 loss near zero within a time budget well under 20 s. */
#include "kpcn/train.h"
#include "testutil.h"
#include "train_fixture.h"

#include <stdio.h>
#include <time.h>

int main(void) {
  const char *store = kt_tmpfile("one.kps");
  if (tf_make_store(store, 24, 24, 24, 1, 2, 1, NULL, 0) != 0) return 1;
  kpcn_train_settings s;
  kpcn_train_settings_defaults(&s);
  kpcn_arch_preset("tiny", &s.arch);
  s.arch.channels = 16; /* oneDNN 2.6 jit kernels need channel blocks of 16 (8 -> ref:any) */
  s.store_path = store;
  s.out_path = kt_tmpfile("overfit.safetensors");
  s.batch = 1;
  s.patch = 24;
  s.iters = 100000;
  s.stage1_iters = 100000;
  s.crop_jitter = 0;
  s.augment.colorswap = s.augment.mirror = s.augment.mirror_v = s.augment.rotate = 0;
  s.augment.max_shift = 0;
  s.adam.lr = 3e-2;
  s.adam.decay_every = 0;
  s.loss1 = KPCN_LOSS_L1;
  s.nthreads = 1;
  kpcn_trainer *t = NULL;
  CHECK(kpcn_trainer_create(&t, &s) == KPCN_OK);
  if (!t) {
    fprintf(stderr, "%s\n", kpcn_last_error());
    return kt_summary("train_overfit");
  }
  struct timespec a, b;
  clock_gettime(CLOCK_MONOTONIC, &a);
  double first = 0, loss = 0, best = 1e30, el = 0;
  int it = 0;
  for (; it < 3000; it++) {
    CHECK(kpcn_trainer_step(t, &loss) == KPCN_OK);
    if (it == 0) first = loss;
    if (loss < best) best = loss;
    clock_gettime(CLOCK_MONOTONIC, &b);
    el = (double)(b.tv_sec - a.tv_sec) + 1e-9 * (double)(b.tv_nsec - a.tv_nsec);
    if (best < 0.02 * first || el > 15) break;
  }
  printf("overfit: loss %.4g -> best %.4g (%.3f%%) in %d iterations, %.2f s\n", first, best,
         100 * best / first, it + 1, el);
  CHECK(first > 0);
  CHECK(best < 0.02 * first); /* "near zero": below 2% of the initial loss */
  CHECK(el < 20);
  kpcn_trainer_destroy(t);
  return kt_summary("train_overfit");
}
