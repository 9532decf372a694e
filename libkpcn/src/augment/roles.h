/* Channel roles for augmentation, derived from channel names (kpcn/augment.h): colour triples
 * "<p>R <p>G <p>B" (p empty or ending in '.') and normals under any accepted alias. */
#ifndef KPCN_AUGMENT_ROLES_H
#define KPCN_AUGMENT_ROLES_H

#include "kpcn/augment.h"

typedef struct kpcn_channel_roles {
  int n;
  int *src_channel;      /* after the colour permutation: input channel feeding channel c */
  int *normal_role;      /* -1 none, 0 = N.X, 1 = N.Y, 2 = N.Z */
  int (*normal_pair)[3]; /* for normal channels: indices of N.X, N.Y, N.Z of its group (-1) */
} kpcn_channel_roles;

/* names may be NULL (every channel purely geometric); perm NULL = identity. */
kpcn_status kpcn_channel_roles_init(kpcn_channel_roles *r, const char *const *names, int n,
                                    const int perm[3]);
void kpcn_channel_roles_free(kpcn_channel_roles *r);

/* Internal helpers shared by the augment module (defined in augment.c). */
kpcn_status kpcn_augment_xform_ptrs(float *const *dst, const float *const *src, int nch,
                                    const char *const *names, int W, int H,
                                    const kpcn_augment_xform *x, int nthreads);
int kpcn_aov_collect_planes(const kpcn_aov_set *set, float **planes, const char **names);
kpcn_status kpcn_aov_like(kpcn_aov_set **out, const kpcn_aov_set *like, int w, int h);
/* An operation on per-plane pointers; arg carries its parameters (xform, angle). */
typedef kpcn_status (*kpcn_augment_ptrs_fn)(float *const *dst, const float *const *src, int nch,
                                            const char *const *names, int W, int H, const void *arg,
                                            int nthreads);
kpcn_status kpcn_augment_contiguous(float *dst, const float *src, int nch, const char *const *names,
                                    int W, int H, kpcn_augment_ptrs_fn fn, const void *arg,
                                    int nthreads);
#define KPCN_AOV_MAX_PLANES (KPCN_BUF_COUNT * 4)

#endif
