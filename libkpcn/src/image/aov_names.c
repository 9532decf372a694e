/* AOV channel names: canonical names and the aliases accepted on read (docs/aov-exr.md).
 *
 * A channel name is split at its last '.' into a prefix (the "pass", e.g. "diffuse",
 * "Denoising Normal", "" for bare "R") and a suffix ("R", "X", "var"). The prefix is
 * matched case-insensitively against the table below; if it does not match and contains a
 * '.', its first component is taken as a render-layer name (Blender's
 * "ViewLayer.Combined.R") and dropped, and the match is retried with a lower preference. */
#include "kpcn/image.h"

#include "core/internal.h"

#include <stdio.h>
#include <string.h>
#include <strings.h>

typedef enum { SUF_RGB, SUF_XYZ, SUF_NORMAL, SUF_ONE, SUF_BARE_Z, SUF_VAR_ONLY } suffix_set;

typedef struct {
  const char *prefix;
  kpcn_buffer buffer;
  suffix_set suffixes;
  int rank; /* 0 canonical, larger = less preferred */
} alias_entry;

/* Order does not matter for matching; rank decides between complete groups. */
static const alias_entry g_alias[] = {
    {"", KPCN_BUF_COLOR, SUF_RGB, 0},
    {"", KPCN_BUF_DEPTH, SUF_BARE_Z, 0},
    {"color", KPCN_BUF_COLOR, SUF_RGB, 1},
    {"Noisy Image", KPCN_BUF_COLOR, SUF_RGB, 2}, /* Cycles: the un-denoised Combined */
    {"Combined", KPCN_BUF_COLOR, SUF_RGB, 3},
    {"rgba", KPCN_BUF_COLOR, SUF_RGB, 4},
    {"diffuse", KPCN_BUF_DIFFUSE, SUF_RGB, 0},
    {"specular", KPCN_BUF_SPECULAR, SUF_RGB, 0},
    {"albedo", KPCN_BUF_ALBEDO, SUF_RGB, 0},
    {"Denoising Albedo", KPCN_BUF_ALBEDO, SUF_RGB, 1},
    {"N", KPCN_BUF_NORMAL, SUF_NORMAL, 0},
    {"normal", KPCN_BUF_NORMAL, SUF_NORMAL, 1},
    {"Denoising Normal", KPCN_BUF_NORMAL, SUF_NORMAL, 2},
    {"Z", KPCN_BUF_DEPTH, SUF_VAR_ONLY, 0}, /* only for "Z.var" */
    {"depth", KPCN_BUF_DEPTH, SUF_ONE, 1},
    {"Denoising Depth", KPCN_BUF_DEPTH, SUF_ONE, 2},
    {"visibility", KPCN_BUF_VISIBILITY, SUF_ONE, 0},
    {"Denoising Shadowing", KPCN_BUF_VISIBILITY, SUF_ONE, 2},
};
#define N_ALIAS ((int)(sizeof g_alias / sizeof g_alias[0]))

/* Channel index of `suf` within suffix set s, -1 for the variance, -2 if not accepted. */
static int match_suffix(suffix_set s, const char *suf) {
  if (strcasecmp(suf, "var") == 0 || strcasecmp(suf, "variance") == 0)
    return s == SUF_BARE_Z ? -2 : -1;
  if (s == SUF_VAR_ONLY) return -2;
  if (strlen(suf) != 1) return -2;
  static const char *const rgb = "RGB", *const xyz = "XYZ";
  char ch = suf[0] >= 'a' && suf[0] <= 'z' ? (char)(suf[0] - 32) : suf[0];
  const char *p;
  switch (s) {
  case SUF_RGB: p = strchr(rgb, ch); return ch && p ? (int)(p - rgb) : -2;
  case SUF_XYZ: p = strchr(xyz, ch); return ch && p ? (int)(p - xyz) : -2;
  case SUF_NORMAL: /* normals stored as XYZ or, by some tools, RGB */
    if (ch && (p = strchr(xyz, ch))) return (int)(p - xyz);
    if (ch && (p = strchr(rgb, ch))) return (int)(p - rgb);
    return -2;
  case SUF_ONE: return (ch == 'Z' || ch == 'V' || ch == 'Y' || ch == 'X' || ch == 'R') ? 0 : -2;
  case SUF_BARE_Z: return ch == 'Z' ? 0 : -2;
  default: return -2;
  }
}

/* Looks `prefix` (length plen) / `suf` up in the table; returns entry index or -1. */
static int match_entry(const char *prefix, size_t plen, const char *suf, int *channel) {
  for (int i = 0; i < N_ALIAS; i++) {
    const alias_entry *e = &g_alias[i];
    if (strlen(e->prefix) != plen || strncasecmp(e->prefix, prefix, plen) != 0) continue;
    int c = match_suffix(e->suffixes, suf);
    if (c == -2) continue;
    /* bare "var" (prefix "") is not a variance name */
    if (c == -1 && plen == 0) continue;
    *channel = c;
    return i;
  }
  return -1;
}

int kpcn_aov_channel_lookup(const char *name, kpcn_buffer *buffer, int *channel, int *rank) {
  if (!name || !*name) return 0;
  const char *dot = strrchr(name, '.');
  const char *prefix = name, *suf = dot ? dot + 1 : name;
  size_t plen = dot ? (size_t)(dot - name) : 0;
  int penalty = 0;
  for (;;) {
    int c, e = match_entry(prefix, plen, suf, &c);
    if (e >= 0) {
      if (buffer) *buffer = g_alias[e].buffer;
      if (channel) *channel = c;
      if (rank) {
        *rank = penalty + g_alias[e].rank;
        /* Canonical variance names ("color.var", "N.var", "Z.var") rank 0 like the data. */
        if (c == -1) {
          const char *cv = kpcn_buffer_variance_name(g_alias[e].buffer);
          *rank = strcmp(name, cv) == 0 ? 0 : *rank + 1;
        }
      }
      return 1;
    }
    /* Drop a leading render-layer component and retry ("ViewLayer.Combined.R"). */
    const char *d = plen ? memchr(prefix, '.', plen) : NULL;
    if (!d) return 0;
    plen -= (size_t)(d + 1 - prefix);
    prefix = d + 1;
    penalty += 10;
  }
}

/* Length of the group prefix of a name (everything before the last '.', 0 if none). */
static size_t group_len(const char *name) {
  const char *dot = strrchr(name, '.');
  return dot ? (size_t)(dot - name) : 0;
}

static int same_group(const char *a, const char *b) {
  size_t la = group_len(a), lb = group_len(b);
  return la == lb && strncmp(a, b, la) == 0;
}

kpcn_status kpcn_aov_map_channels(const char *const *names, int n, int chan[KPCN_BUF_COUNT][3],
                                  int var[KPCN_BUF_COUNT], const char *what) {
  if (!chan || !var || (n > 0 && !names))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_aov_map_channels: NULL argument");
  const char *w = what ? what : "image";
  kpcn_status st = KPCN_OK; /* first partial buffer; mapping goes on for the others */
  int var_rank[KPCN_BUF_COUNT];
  for (int b = 0; b < KPCN_BUF_COUNT; b++) {
    chan[b][0] = chan[b][1] = chan[b][2] = -1;
    var[b] = -1;
    var_rank[b] = 1 << 30;
  }
  for (int i = 0; i < n; i++) { /* variances: best rank wins, first on ties */
    kpcn_buffer b;
    int c, r;
    if (names[i] && kpcn_aov_channel_lookup(names[i], &b, &c, &r) && c == -1 && r < var_rank[b]) {
      var[b] = i;
      var_rank[b] = r;
    }
  }
  for (int b = 0; b < KPCN_BUF_COUNT; b++) {
    int nc = kpcn_buffer_channels((kpcn_buffer)b), best_rank = 1 << 30;
    int partial = -1, partial_missing = -1;
    for (int i = 0; i < n; i++) {
      kpcn_buffer bi;
      int ci, ri;
      if (!names[i] || !kpcn_aov_channel_lookup(names[i], &bi, &ci, &ri)) continue;
      if ((int)bi != b || ci < 0) continue;
      int seen = 0; /* is this group already evaluated (an earlier member)? */
      for (int j = 0; j < i && !seen; j++) {
        kpcn_buffer bj;
        int cj;
        seen = names[j] && kpcn_aov_channel_lookup(names[j], &bj, &cj, NULL) && bj == bi &&
               cj >= 0 && same_group(names[i], names[j]);
      }
      if (seen) continue;
      int idx[3] = {-1, -1, -1};
      for (int k = i; k < n; k++) {
        kpcn_buffer bk;
        int ck;
        if (names[k] && kpcn_aov_channel_lookup(names[k], &bk, &ck, NULL) && bk == bi && ck >= 0 &&
            same_group(names[i], names[k]) && idx[ck] < 0)
          idx[ck] = k;
      }
      int missing = -1;
      for (int c = 0; c < nc && missing < 0; c++)
        if (idx[c] < 0) missing = c;
      if (missing >= 0) {
        if (partial < 0) {
          partial = i;
          partial_missing = missing;
        }
        continue;
      }
      if (ri < best_rank) {
        best_rank = ri;
        for (int c = 0; c < nc; c++)
          chan[b][c] = idx[c];
      }
    }
    if (chan[b][0] < 0 && partial >= 0 && st == KPCN_OK) {
      const char *canon = kpcn_buffer_channel_name((kpcn_buffer)b, partial_missing);
      st = kpcn_fail(KPCN_ERR_MISSING_CHANNEL,
                     "%s: buffer '%s' is incomplete: found channel '%s' but not its channel %d "
                     "(canonical name '%s')",
                     w, kpcn_buffer_name((kpcn_buffer)b), names[partial], partial_missing, canon);
    }
  }
  return st;
}
