/* Derives colour-triple and normal roles of channels from their names. Name-based so
 * the same rule serves AOV sets, images, patch-store patches ("ref." prefixes) and
 * ImageBufs without a separate layout description. */
#include "augment/roles.h"

#include "core/internal.h"

#include <stdlib.h>
#include <string.h>

/* If name is "<p>S" with suffix S and p empty or ending in '.', returns the prefix length;
 * else -1. */
static int prefix_len(const char *name, const char *suffix) {
  size_t n = strlen(name), s = strlen(suffix);
  if (n < s || strcmp(name + n - s, suffix) != 0) return -1;
  size_t p = n - s;
  if (p > 0 && name[p - 1] != '.') return -1;
  return (int)p;
}

static int find_with_prefix(const char *const *names, int n, const char *prefix, int plen,
                            const char *suffix) {
  for (int c = 0; c < n; c++) {
    if (!names[c]) continue;
    if (prefix_len(names[c], suffix) == plen && strncmp(names[c], prefix, (size_t)plen) == 0)
      return c;
  }
  return -1;
}

/* Component 0..2 (X, Y, Z) if name is a normal channel under any name the AOV readers accept
 * ("N.X", "normal.X", "Denoising Normal.X", "ref.N.X", ...; kpcn_aov_channel_lookup), else
 * -1: a mirror that negated "N.X" but not "normal.X" would leave such a file's normals
 * disagreeing with its flipped image. */
static int normal_component(const char *name) {
  kpcn_buffer b;
  int c;
  return name && kpcn_aov_channel_lookup(name, &b, &c, NULL) && b == KPCN_BUF_NORMAL && c >= 0 ? c
                                                                                               : -1;
}

/* Length of name's group: everything before its last '.' (0 if none). */
static size_t group_len(const char *name) {
  const char *dot = strrchr(name, '.');
  return dot ? (size_t)(dot - name) : 0;
}

kpcn_status kpcn_channel_roles_init(kpcn_channel_roles *r, const char *const *names, int n,
                                    const int perm[3]) {
  memset(r, 0, sizeof *r);
  r->n = n;
  r->src_channel = kpcn_alloc(sizeof(int) * (size_t)n, "channel roles");
  r->normal_role = kpcn_alloc(sizeof(int) * (size_t)n, "channel roles");
  r->normal_pair = kpcn_alloc(sizeof(*r->normal_pair) * (size_t)n, "channel roles");
  if (!r->src_channel || !r->normal_role || !r->normal_pair) {
    kpcn_channel_roles_free(r);
    return KPCN_ERR_OUT_OF_MEMORY;
  }
  static const int id[3] = {0, 1, 2};
  if (!perm) perm = id;
  static const char *const rgb[3] = {"R", "G", "B"};
  for (int c = 0; c < n; c++) {
    r->src_channel[c] = c;
    r->normal_role[c] = -1;
    r->normal_pair[c][0] = r->normal_pair[c][1] = r->normal_pair[c][2] = -1;
    const char *nm = names ? names[c] : NULL;
    if (!nm) continue;
    const int k = normal_component(nm);
    if (k >= 0) { /* a normal (also one stored as "normal.R"): never a colour triple */
      r->normal_role[c] = k;
      const size_t g = group_len(nm);
      for (int j = 0; j < n; j++)
        if (names[j] && group_len(names[j]) == g && strncmp(names[j], nm, g) == 0) {
          const int kj = normal_component(names[j]);
          if (kj >= 0 && r->normal_pair[c][kj] < 0) r->normal_pair[c][kj] = j;
        }
      continue;
    }
    for (int q = 0; q < 3; q++) {
      int p = prefix_len(nm, rgb[q]);
      if (p < 0) continue;
      int idx[3];
      for (int j = 0; j < 3; j++)
        idx[j] = find_with_prefix(names, n, nm, p, rgb[j]);
      if (idx[0] >= 0 && idx[1] >= 0 && idx[2] >= 0) r->src_channel[c] = idx[perm[q]];
    }
  }
  return KPCN_OK;
}

void kpcn_channel_roles_free(kpcn_channel_roles *r) {
  free(r->src_channel);
  free(r->normal_role);
  free(r->normal_pair);
  memset(r, 0, sizeof *r);
}
