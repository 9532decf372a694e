/* Exact post-render augmentation: colour permutation, mirrors, quarter turns and
 * wrap-around shift, applied to named planar channels with one transform so that
 * noisy/reference pairs stay aligned (see kpcn/augment.h for the semantics). */
#include "kpcn/augment.h"

#include "augment/roles.h"
#include "core/internal.h"

#include <ctype.h>
#include <stdlib.h>
#include <string.h>

void kpcn_augment_identity(kpcn_augment_xform *x) {
  memset(x, 0, sizeof *x);
  x->perm[0] = 0;
  x->perm[1] = 1;
  x->perm[2] = 2;
}

kpcn_status kpcn_augment_parse_perm(const char *s, int perm[3]) {
  if (!s || strlen(s) != 3)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "colour permutation '%s': expected three letters of R, G, B such as BRG",
                     s ? s : "(null)");
  int seen = 0;
  for (int i = 0; i < 3; i++) {
    int c = toupper((unsigned char)s[i]);
    int k = c == 'R' ? 0 : c == 'G' ? 1 : c == 'B' ? 2 : -1;
    if (k < 0 || (seen & (1 << k)))
      return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                       "colour permutation '%s': must use each of R, G, B exactly once", s);
    seen |= 1 << k;
    perm[i] = k;
  }
  return KPCN_OK;
}

static int mod(int a, int m) {
  int r = a % m;
  return r < 0 ? r + m : r;
}
/* a mod m for a difference that may leave int's range (xo - dx with dx = INT_MIN) */
static int mod64(int64_t a, int m) {
  int64_t r = a % m;
  return (int)(r < 0 ? r + m : r);
}

void kpcn_augment_output_size(const kpcn_augment_xform *x, int width, int height, int *out_w,
                              int *out_h) {
  int odd = mod(x->rot90, 4) & 1;
  *out_w = odd ? height : width;
  *out_h = odd ? width : height;
}

/* Inverse, derived from: x = S(d) R^k Mv^b Mh^a (rightmost first). Its inverse
 * Mh^a Mv^b R^-k S(-d) is brought back to the canonical order with the torus identities
 *   S(v) then R  ==  R then S(dy, -dx);  S(v) then Mh == Mh then S(-dx, dy);
 *   S(v) then Mv == Mv then S(dx, -dy);  Mh^a Mv^b R^m == R^(m*(-1)^(a+b)) Mh^a Mv^b. */
void kpcn_augment_inverse(kpcn_augment_xform *inv, const kpcn_augment_xform *x, int width,
                          int height) {
  kpcn_augment_xform r;
  for (int c = 0; c < 3; c++)
    r.perm[x->perm[c]] = c;
  int a = x->mirror_h ? 1 : 0, b = x->mirror_v ? 1 : 0, k = mod(x->rot90, 4);
  /* the shift acts on the forward output (Wo x Ho): reduced there first, so negating it
   * cannot overflow (dx = INT_MIN) */
  int Wo, Ho;
  kpcn_augment_output_size(x, width, height, &Wo, &Ho);
  int dx = Wo > 0 ? -mod64(x->dx, Wo) : 0, dy = Ho > 0 ? -mod64(x->dy, Ho) : 0;
  /* Move S(-d) left through R^-k (4-k forward turns). */
  for (int t = 0; t < mod(-k, 4); t++) {
    int ndx = dy, ndy = -dx;
    dx = ndx;
    dy = ndy;
  }
  if (b) dy = -dy;
  if (a) dx = -dx;
  int m = mod(-k, 4);
  if ((a + b) & 1) m = mod(-m, 4);
  r.mirror_h = a;
  r.mirror_v = b;
  r.rot90 = m;
  r.dx = dx;
  r.dy = dy;
  *inv = r;
}

/* ---- deterministic draws ---- */
static uint64_t splitmix64(uint64_t z) {
  z += 0x9e3779b97f4a7c15ull;
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
  return z ^ (z >> 31);
}

void kpcn_augment_draw_defaults(kpcn_augment_draw_settings *s) {
  memset(s, 0, sizeof *s);
  s->colorswap = 1;
  s->mirror = 1;
  s->rotate = 1;
  s->mode = KPCN_AUGMENT_ALL;
}

static const int g_perms[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};

void kpcn_augment_draw(kpcn_augment_xform *x, const kpcn_augment_draw_settings *s, uint64_t seed,
                       uint64_t index) {
  kpcn_augment_identity(x);
  uint64_t h = splitmix64(splitmix64(seed) ^ (index * 0xd1b54a32d192ed03ull));
  uint64_t r[6];
  for (int i = 0; i < 6; i++)
    r[i] = h = splitmix64(h);
  int ops[5], nops = 0;
  if (s->colorswap) ops[nops++] = 0;
  if (s->mirror) ops[nops++] = 1;
  if (s->mirror_v) ops[nops++] = 2;
  if (s->rotate) ops[nops++] = 3;
  if (s->max_shift > 0) ops[nops++] = 4;
  if (nops == 0) return;
  int only = s->mode == KPCN_AUGMENT_ONE_OF ? ops[r[5] % (uint64_t)nops] : -1;
  /* in 64 bits: 2 * max_shift + 1 overflowed int from max_shift 2^30 on */
  const uint64_t span = 2 * (uint64_t)(s->max_shift > 0 ? s->max_shift : 0) + 1;
  for (int i = 0; i < nops; i++) {
    int op = ops[i];
    if (only >= 0 && op != only) continue;
    /* In ONE_OF mode the chosen op is forced to a non-identity value. */
    int force = only >= 0;
    switch (op) {
    case 0: {
      int p = force ? 1 + (int)(r[0] % 5) : (int)(r[0] % 6);
      memcpy(x->perm, g_perms[p], sizeof x->perm);
    } break;
    case 1: x->mirror_h = force ? 1 : (int)(r[1] & 1); break;
    case 2: x->mirror_v = force ? 1 : (int)((r[2] >> 7) & 1); break;
    case 3: x->rot90 = force ? 1 + (int)(r[3] % 3) : (int)(r[3] % 4); break;
    case 4:
      x->dx = (int)((int64_t)(r[4] % span) - s->max_shift);
      x->dy = (int)((int64_t)((r[4] >> 32) % span) - s->max_shift);
      if (force && x->dx == 0 && x->dy == 0) x->dx = s->max_shift;
      break;
    }
  }
}

/* ---- the exact transform ---- */
static kpcn_status check_xform(const kpcn_augment_xform *x) {
  int seen = 0;
  for (int c = 0; c < 3; c++) {
    if (x->perm[c] < 0 || x->perm[c] > 2 || (seen & (1 << x->perm[c])))
      return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                       "augment transform: perm {%d,%d,%d} is not a permutation of {0,1,2}",
                       x->perm[0], x->perm[1], x->perm[2]);
    seen |= 1 << x->perm[c];
  }
  return KPCN_OK;
}

/* Source pixel index of every output pixel (undoing shift, turns, mirrors in turn). */
static uint32_t *build_map(const kpcn_augment_xform *x, int W, int H, int *Wo, int *Ho) {
  kpcn_augment_output_size(x, W, H, Wo, Ho);
  size_t n = (size_t)W * (size_t)H;
  uint32_t *map = kpcn_alloc(n * sizeof *map, "augment index map");
  if (!map) return NULL;
  int k = mod(x->rot90, 4);
  for (int yo = 0; yo < *Ho; yo++) {
    for (int xo = 0; xo < *Wo; xo++) {
      int px = mod64((int64_t)xo - x->dx, *Wo), py = mod64((int64_t)yo - x->dy, *Ho);
      int cw = *Wo, ch = *Ho;
      for (int t = 0; t < k; t++) {
        /* One CCW turn maps (x, y) of a Wb x Hb image to (y, Wb-1-x); here Wb = ch. */
        int wb = ch, hb = cw;
        int sx = wb - 1 - py, sy = px;
        px = sx;
        py = sy;
        cw = wb;
        ch = hb;
      }
      if (x->mirror_v) py = H - 1 - py;
      if (x->mirror_h) px = W - 1 - px;
      map[(size_t)yo * (size_t)*Wo + (size_t)xo] = (uint32_t)((size_t)py * (size_t)W + (size_t)px);
    }
  }
  return map;
}

/* Normal matrix M (integer, entries 0/+-1): (N.X', N.Y') = M (N.X, N.Y). */
static void normal_matrix(const kpcn_augment_xform *x, int M[2][2]) {
  M[0][0] = x->mirror_h ? -1 : 1;
  M[0][1] = 0;
  M[1][0] = 0;
  M[1][1] = x->mirror_v ? -1 : 1;
  for (int t = 0; t < mod(x->rot90, 4); t++) {
    int a = M[0][0], b = M[0][1], c = M[1][0], d = M[1][1];
    /* R = [[0,-1],[1,0]]: (nx, ny) -> (-ny, nx). */
    M[0][0] = -c;
    M[0][1] = -d;
    M[1][0] = a;
    M[1][1] = b;
  }
}

kpcn_status kpcn_augment_xform_ptrs(float *const *dst, const float *const *src, int nch,
                                    const char *const *names, int W, int H,
                                    const kpcn_augment_xform *x, int nthreads) {
  if (!dst || !src || nch <= 0 || !x)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "augment: NULL buffer or no channels");
  KPCN_TRY(kpcn_check_size(W, H, "augment input"));
  KPCN_TRY(check_xform(x));
  kpcn_channel_roles roles;
  KPCN_TRY(kpcn_channel_roles_init(&roles, names, nch, x->perm));
  int Wo, Ho;
  uint32_t *map = build_map(x, W, H, &Wo, &Ho);
  if (!map) {
    kpcn_channel_roles_free(&roles);
    return kpcn_last_status();
  }
  int M[2][2];
  normal_matrix(x, M);
  size_t n = (size_t)Wo * (size_t)Ho;
  int nt = kpcn_resolve_threads(nthreads);
  kpcn_status st = KPCN_OK;
  for (int c = 0; c < nch && st == KPCN_OK; c++) {
    float *d = dst[c];
    int role = roles.normal_role[c];
    if (role == 0 || role == 1) {
      int ix = roles.normal_pair[c][0], iy = roles.normal_pair[c][1];
      int a = M[role][0], b = M[role][1];
      if ((a != 0 && ix < 0) || (b != 0 && iy < 0)) {
        st = kpcn_fail(KPCN_ERR_MISSING_CHANNEL,
                       "augment: rotating normal channel '%s' needs its partner N.%c", names[c],
                       role == 0 ? 'Y' : 'X');
        break;
      }
      const float *sx = ix >= 0 ? src[ix] : NULL, *sy = iy >= 0 ? src[iy] : NULL;
#pragma omp parallel for num_threads(nt) schedule(static)
      for (size_t i = 0; i < n; i++) {
        float v = 0.0f;
        if (a) v += a > 0 ? sx[map[i]] : -sx[map[i]];
        if (b) v += b > 0 ? sy[map[i]] : -sy[map[i]];
        d[i] = v;
      }
    } else {
      const float *s = src[roles.src_channel[c]];
#pragma omp parallel for num_threads(nt) schedule(static)
      for (size_t i = 0; i < n; i++)
        d[i] = s[map[i]];
    }
  }
  free(map);
  kpcn_channel_roles_free(&roles);
  return st;
}

/* Splits contiguous planar buffers (nch planes of W*H floats each) into per-plane pointers
 * and runs fn on them: the common body of the *_planes entry points. */
kpcn_status kpcn_augment_contiguous(float *dst, const float *src, int nch, const char *const *names,
                                    int W, int H, kpcn_augment_ptrs_fn fn, const void *arg,
                                    int nthreads) {
  float **d = kpcn_alloc(sizeof(float *) * (size_t)nch, "plane pointers");
  const float **s = kpcn_alloc(sizeof(float *) * (size_t)nch, "plane pointers");
  if (!d || !s) {
    free(d);
    free((void *)s);
    return KPCN_ERR_OUT_OF_MEMORY;
  }
  size_t n = (size_t)W * (size_t)H;
  for (int c = 0; c < nch; c++) {
    d[c] = dst + (size_t)c * n;
    s[c] = src + (size_t)c * n;
  }
  kpcn_status st = fn(d, s, nch, names, W, H, arg, nthreads);
  free(d);
  free((void *)s);
  return st;
}

static kpcn_status xform_ptrs_fn(float *const *dst, const float *const *src, int nch,
                                 const char *const *names, int W, int H, const void *arg,
                                 int nthreads) {
  return kpcn_augment_xform_ptrs(dst, src, nch, names, W, H, arg, nthreads);
}

kpcn_status kpcn_augment_planes(float *dst, const float *src, int nch, const char *const *names,
                                int width, int height, const kpcn_augment_xform *x, int nthreads) {
  if (!dst || !src || nch <= 0)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_augment_planes: NULL buffer or nch <= 0");
  KPCN_TRY(kpcn_check_size(width, height, "kpcn_augment_planes"));
  return kpcn_augment_contiguous(dst, src, nch, names, width, height, xform_ptrs_fn, x, nthreads);
}

/* Collects the present planes of an AOV set with their canonical names. */
int kpcn_aov_collect_planes(const kpcn_aov_set *set, float **planes, const char **names) {
  int n = 0;
  size_t np = kpcn_aov_plane_size(set);
  for (int b = 0; b < KPCN_BUF_COUNT; b++) {
    if (set->buf[b]) {
      for (int c = 0; c < kpcn_buffer_channels((kpcn_buffer)b); c++) {
        planes[n] = set->buf[b] + (size_t)c * np;
        names[n++] = kpcn_buffer_channel_name((kpcn_buffer)b, c);
      }
    }
    if (set->var[b]) {
      planes[n] = set->var[b];
      names[n++] = kpcn_buffer_variance_name((kpcn_buffer)b);
    }
  }
  return n;
}

/* New set of size w x h with the same buffers and metadata as `like`. */
kpcn_status kpcn_aov_like(kpcn_aov_set **out, const kpcn_aov_set *like, int w, int h) {
  kpcn_aov_set *o = NULL;
  KPCN_TRY(kpcn_aov_create(&o, w, h));
  for (int b = 0; b < KPCN_BUF_COUNT; b++) {
    if (like->buf[b]) {
      kpcn_status s = kpcn_aov_add(o, (kpcn_buffer)b, like->var[b] != NULL);
      if (s != KPCN_OK) {
        kpcn_aov_destroy(o);
        return s;
      }
    } else if (like->var[b]) {
      /* A variance without its buffer: add both, then drop the buffer. */
      kpcn_status s = kpcn_aov_add(o, (kpcn_buffer)b, 1);
      if (s != KPCN_OK) {
        kpcn_aov_destroy(o);
        return s;
      }
      free(o->buf[b]);
      o->buf[b] = NULL;
    }
  }
  o->spp = like->spp;
  o->seed = like->seed;
  o->albedo_spp = like->albedo_spp;
  o->albedo_footprint = like->albedo_footprint;
  memcpy(o->scene, like->scene, sizeof o->scene);
  memcpy(o->version, like->version, sizeof o->version);
  *out = o;
  return KPCN_OK;
}

kpcn_status kpcn_augment_aov(kpcn_aov_set **out, const kpcn_aov_set *in,
                             const kpcn_augment_xform *x, int nthreads) {
  if (!out || !in || !x) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_augment_aov: NULL");
  *out = NULL;
  KPCN_TRY(check_xform(x));
  int Wo, Ho;
  kpcn_augment_output_size(x, in->width, in->height, &Wo, &Ho);
  kpcn_aov_set *o = NULL;
  KPCN_TRY(kpcn_aov_like(&o, in, Wo, Ho));
  float *sp[KPCN_AOV_MAX_PLANES], *dp[KPCN_AOV_MAX_PLANES];
  const char *names[KPCN_AOV_MAX_PLANES], *dn[KPCN_AOV_MAX_PLANES];
  int n = kpcn_aov_collect_planes(in, sp, names);
  int m = kpcn_aov_collect_planes(o, dp, dn);
  if (n != m || n == 0) {
    kpcn_aov_destroy(o);
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_augment_aov: the AOV set has no buffers");
  }
  kpcn_status st = kpcn_augment_xform_ptrs(dp, (const float *const *)sp, n, names, in->width,
                                           in->height, x, nthreads);
  if (st != KPCN_OK) {
    kpcn_aov_destroy(o);
    return st;
  }
  *out = o;
  return KPCN_OK;
}

kpcn_status kpcn_augment_image(kpcn_image **out, const kpcn_image *in, const kpcn_augment_xform *x,
                               int nthreads) {
  if (!out || !in || !x) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_augment_image: NULL");
  *out = NULL;
  KPCN_TRY(check_xform(x));
  int Wo, Ho;
  kpcn_augment_output_size(x, in->width, in->height, &Wo, &Ho);
  kpcn_image *o = NULL;
  KPCN_TRY(kpcn_image_create(&o, Wo, Ho, in->nchannels, (const char *const *)in->names));
  kpcn_status st =
      kpcn_augment_planes(o->data, in->data, in->nchannels, (const char *const *)in->names,
                          in->width, in->height, x, nthreads);
  if (st != KPCN_OK) {
    kpcn_image_destroy(o);
    return st;
  }
  *out = o;
  return KPCN_OK;
}

kpcn_status kpcn_augment_crop_aov(kpcn_aov_set **out, const kpcn_aov_set *in, int x0, int y0, int w,
                                  int h) {
  if (!out || !in) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_augment_crop_aov: NULL");
  *out = NULL;
  if (w <= 0 || h <= 0 || x0 < 0 || y0 < 0 || x0 > in->width - w || y0 > in->height - h)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "crop window %dx%d at (%d,%d) does not fit in the %dx%d image", w, h, x0, y0,
                     in->width, in->height);
  kpcn_aov_set *o = NULL;
  KPCN_TRY(kpcn_aov_like(&o, in, w, h));
  float *sp[KPCN_AOV_MAX_PLANES], *dp[KPCN_AOV_MAX_PLANES];
  const char *names[KPCN_AOV_MAX_PLANES];
  int n = kpcn_aov_collect_planes(in, sp, names);
  kpcn_aov_collect_planes(o, dp, names);
  for (int c = 0; c < n; c++)
    for (int y = 0; y < h; y++)
      memcpy(dp[c] + (size_t)y * (size_t)w,
             sp[c] + (size_t)(y + y0) * (size_t)in->width + (size_t)x0, sizeof(float) * (size_t)w);
  *out = o;
  return KPCN_OK;
}
