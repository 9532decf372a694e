/* Exact augmentation ops: inverses, compositions, explicit per-pixel definitions, and
 * the camera-space sign convention checked against a geometric normal field. */
#include "kpcn/augment.h"
#include "testutil.h"

#include <math.h>
#include <stdlib.h>
#include <limits.h>
#include <string.h>

static unsigned g_rng = 12345;

/* A full AOV set with random content (all buffers and variances). */
static kpcn_aov_set *random_set(int w, int h) {
  kpcn_aov_set *s = NULL;
  if (kpcn_aov_create(&s, w, h) != KPCN_OK) return NULL;
  for (int b = 0; b < KPCN_BUF_COUNT; b++) {
    kpcn_aov_add(s, (kpcn_buffer)b, 1);
    size_t n = kpcn_aov_plane_size(s) * (size_t)kpcn_buffer_channels((kpcn_buffer)b);
    for (size_t i = 0; i < n; i++)
      s->buf[b][i] = kt_randf(&g_rng) * 2 - 0.5f;
    for (size_t i = 0; i < kpcn_aov_plane_size(s); i++)
      s->var[b][i] = kt_randf(&g_rng);
  }
  s->spp = 16;
  return s;
}

static int sets_equal(const kpcn_aov_set *a, const kpcn_aov_set *b) {
  if (a->width != b->width || a->height != b->height) return 0;
  size_t np = kpcn_aov_plane_size(a);
  for (int k = 0; k < KPCN_BUF_COUNT; k++) {
    size_t n = np * (size_t)kpcn_buffer_channels((kpcn_buffer)k);
    if ((a->buf[k] == NULL) != (b->buf[k] == NULL)) return 0;
    if (a->buf[k] && memcmp(a->buf[k], b->buf[k], n * sizeof(float))) return 0;
    if ((a->var[k] == NULL) != (b->var[k] == NULL)) return 0;
    if (a->var[k] && memcmp(a->var[k], b->var[k], np * sizeof(float))) return 0;
  }
  return 1;
}

/* Applies a sequence of transforms. */
static kpcn_aov_set *apply(const kpcn_aov_set *in, const kpcn_augment_xform *x) {
  kpcn_aov_set *o = NULL;
  kpcn_status s = kpcn_augment_aov(&o, in, x, 0);
  CHECK(s == KPCN_OK);
  return o;
}

static float px(const kpcn_aov_set *s, kpcn_buffer b, int c, int x, int y) {
  return s->buf[b][(size_t)c * kpcn_aov_plane_size(s) + (size_t)y * s->width + x];
}

static void test_mirror_twice(void) {
  kpcn_aov_set *a = random_set(7, 5);
  for (int v = 0; v < 2; v++) {
    kpcn_augment_xform m;
    kpcn_augment_identity(&m);
    if (v)
      m.mirror_v = 1;
    else
      m.mirror_h = 1;
    kpcn_aov_set *b = apply(a, &m), *c = apply(b, &m);
    CHECK(!sets_equal(a, b));
    CHECK(sets_equal(a, c));
    /* Explicit definition: pixel and normal sign. */
    int ok = 1;
    for (int y = 0; y < 5; y++)
      for (int x = 0; x < 7; x++) {
        int sx = v ? x : 6 - x, sy = v ? 4 - y : y;
        ok &= px(b, KPCN_BUF_COLOR, 1, x, y) == px(a, KPCN_BUF_COLOR, 1, sx, sy);
        ok &= px(b, KPCN_BUF_NORMAL, 0, x, y) == (v ? 1 : -1) * px(a, KPCN_BUF_NORMAL, 0, sx, sy);
        ok &= px(b, KPCN_BUF_NORMAL, 1, x, y) == (v ? -1 : 1) * px(a, KPCN_BUF_NORMAL, 1, sx, sy);
        ok &= px(b, KPCN_BUF_NORMAL, 2, x, y) == px(a, KPCN_BUF_NORMAL, 2, sx, sy);
        ok &= b->var[KPCN_BUF_DEPTH][y * 7 + x] == a->var[KPCN_BUF_DEPTH][sy * 7 + sx];
      }
    CHECK(ok);
    kpcn_aov_destroy(b);
    kpcn_aov_destroy(c);
  }
  kpcn_aov_destroy(a);
}

static void test_rotations(void) {
  kpcn_aov_set *a = random_set(7, 5);
  kpcn_augment_xform r;
  kpcn_augment_identity(&r);
  r.rot90 = 1;
  kpcn_aov_set *cur = apply(a, &r);
  CHECK(cur->width == 5 && cur->height == 7);
  /* Definition of one CCW turn: (x, y) -> (y, W-1-x), (nx, ny) -> (-ny, nx). */
  int ok = 1;
  for (int y = 0; y < 5; y++)
    for (int x = 0; x < 7; x++) {
      int ox = y, oy = 6 - x;
      ok &= px(cur, KPCN_BUF_ALBEDO, 2, ox, oy) == px(a, KPCN_BUF_ALBEDO, 2, x, y);
      ok &= px(cur, KPCN_BUF_NORMAL, 0, ox, oy) == -px(a, KPCN_BUF_NORMAL, 1, x, y);
      ok &= px(cur, KPCN_BUF_NORMAL, 1, ox, oy) == px(a, KPCN_BUF_NORMAL, 0, x, y);
      ok &= px(cur, KPCN_BUF_NORMAL, 2, ox, oy) == px(a, KPCN_BUF_NORMAL, 2, x, y);
    }
  CHECK(ok);
  for (int t = 1; t < 4; t++) {
    kpcn_aov_set *n = apply(cur, &r);
    kpcn_aov_destroy(cur);
    cur = n;
    CHECK(sets_equal(cur, a) == (t == 3));
  }
  kpcn_aov_destroy(cur);
  /* rot90 = 3 equals three single turns; rot 180 = mirror H + mirror V. */
  kpcn_augment_xform r180, hv;
  kpcn_augment_identity(&r180);
  r180.rot90 = 2;
  kpcn_augment_identity(&hv);
  hv.mirror_h = hv.mirror_v = 1;
  kpcn_aov_set *p = apply(a, &r180), *q = apply(a, &hv);
  CHECK(sets_equal(p, q));
  kpcn_augment_xform h, v;
  kpcn_augment_identity(&h);
  h.mirror_h = 1;
  kpcn_augment_identity(&v);
  v.mirror_v = 1;
  kpcn_aov_set *q1 = apply(a, &h), *q2 = apply(q1, &v);
  CHECK(sets_equal(p, q2));
  kpcn_aov_destroy(p);
  kpcn_aov_destroy(q);
  kpcn_aov_destroy(q1);
  kpcn_aov_destroy(q2);
  kpcn_aov_destroy(a);
}

static void test_colorswap(void) {
  kpcn_aov_set *a = random_set(6, 4);
  kpcn_augment_xform p, pi;
  kpcn_augment_identity(&p);
  CHECK(kpcn_augment_parse_perm("BRG", p.perm) == KPCN_OK);
  CHECK(p.perm[0] == 2 && p.perm[1] == 0 && p.perm[2] == 1);
  kpcn_augment_identity(&pi);
  CHECK(kpcn_augment_parse_perm("gbr", pi.perm) == KPCN_OK); /* inverse of BRG */
  kpcn_aov_set *b = apply(a, &p), *c = apply(b, &pi);
  CHECK(sets_equal(a, c));
  int ok = 1;
  for (int y = 0; y < 4; y++)
    for (int x = 0; x < 6; x++) {
      for (int k = KPCN_BUF_COLOR; k <= KPCN_BUF_ALBEDO; k++) {
        ok &= px(b, (kpcn_buffer)k, 0, x, y) == px(a, (kpcn_buffer)k, 2, x, y); /* new R = old B */
        ok &= px(b, (kpcn_buffer)k, 1, x, y) == px(a, (kpcn_buffer)k, 0, x, y);
        ok &= px(b, (kpcn_buffer)k, 2, x, y) == px(a, (kpcn_buffer)k, 1, x, y);
      }
      for (int c3 = 0; c3 < 3; c3++)
        ok &= px(b, KPCN_BUF_NORMAL, c3, x, y) == px(a, KPCN_BUF_NORMAL, c3, x, y);
      ok &= px(b, KPCN_BUF_DEPTH, 0, x, y) == px(a, KPCN_BUF_DEPTH, 0, x, y);
      for (int k = 0; k < KPCN_BUF_COUNT; k++)
        ok &= b->var[k][y * 6 + x] == a->var[k][y * 6 + x];
    }
  CHECK(ok);
  int bad[3];
  CHECK(kpcn_augment_parse_perm("RRB", bad) == KPCN_ERR_INVALID_ARGUMENT);
  CHECK(strstr(kpcn_last_error(), "RRB") != NULL);
  CHECK(kpcn_augment_parse_perm("RGBA", bad) == KPCN_ERR_INVALID_ARGUMENT);
  kpcn_augment_xform broken = p;
  broken.perm[1] = 2;
  kpcn_aov_set *z = NULL;
  CHECK(kpcn_augment_aov(&z, a, &broken, 0) == KPCN_ERR_INVALID_ARGUMENT && z == NULL);
  kpcn_aov_destroy(b);
  kpcn_aov_destroy(c);
  kpcn_aov_destroy(a);
}

static void test_shift_and_inverse(void) {
  kpcn_aov_set *a = random_set(9, 6);
  kpcn_augment_xform s, si;
  kpcn_augment_identity(&s);
  s.dx = 4;
  s.dy = -7; /* more than the height: reduced modulo 6 */
  kpcn_aov_set *b = apply(a, &s);
  int ok = 1;
  for (int y = 0; y < 6; y++)
    for (int x = 0; x < 9; x++)
      ok &= px(b, KPCN_BUF_SPECULAR, 1, (x + 4) % 9, ((y - 7) % 6 + 6) % 6) ==
            px(a, KPCN_BUF_SPECULAR, 1, x, y);
  CHECK(ok);
  kpcn_augment_identity(&si);
  si.dx = -4;
  si.dy = 7;
  kpcn_aov_set *c = apply(b, &si);
  CHECK(sets_equal(a, c));
  kpcn_aov_destroy(b);
  kpcn_aov_destroy(c);
  /* Random full transforms undone by kpcn_augment_inverse. */
  kpcn_augment_draw_settings ds;
  kpcn_augment_draw_defaults(&ds);
  ds.mirror_v = 1;
  ds.max_shift = 5;
  int all = 1;
  for (uint64_t i = 0; i < 40; i++) {
    kpcn_augment_xform x, inv;
    kpcn_augment_draw(&x, &ds, 99, i);
    kpcn_augment_inverse(&inv, &x, 9, 6);
    kpcn_aov_set *f = apply(a, &x), *g = apply(f, &inv);
    all &= sets_equal(a, g);
    kpcn_aov_destroy(f);
    kpcn_aov_destroy(g);
  }
  CHECK(all);
  kpcn_aov_destroy(a);
  /* Shifts drawn within [-max_shift, max_shift] up to INT_MAX (2 * max_shift + 1 overflowed
   * int from 2^30 on), both signs and both ends' neighbourhoods reached */
  const int maxes[3] = {5, 1 << 30, INT_MAX};
  for (int k = 0; k < 3; k++) {
    kpcn_augment_draw_defaults(&ds);
    ds.colorswap = ds.mirror = ds.rotate = 0;
    ds.max_shift = maxes[k];
    int inside = 1, neg = 0, pos = 0;
    for (uint64_t i = 0; i < 2000; i++) {
      kpcn_augment_xform x;
      kpcn_augment_draw(&x, &ds, 7, i);
      inside &= x.dx >= -maxes[k] && x.dx <= maxes[k] && x.dy >= -maxes[k] && x.dy <= maxes[k];
      neg |= x.dx<-maxes[k] / 2, pos |= x.dx> maxes[k] / 2;
    }
    CHECK(inside && neg && pos);
    if (!(inside && neg && pos))
      fprintf(stderr, "  max_shift %d: inside %d, below -max/2 %d, above max/2 %d\n", maxes[k],
              inside, neg, pos);
  }
}

/* A hemisphere bulging toward the camera: its camera-space normal at image pixel (x, y)
 * is (u, v, sqrt(1-u^2-v^2)) with u = (x-cx)/R to the right and v = -(y-cy)/R UP. Any
 * exact geometric transform of the image must give the same formula in the new image,
 * which checks the sign convention of mirrors and rotations independently. */
static void dome(kpcn_aov_set *s) {
  int w = s->width, h = s->height;
  double cx = 0.5 * (w - 1), cy = 0.5 * (h - 1), R = 0.75 * (w > h ? w : h);
  size_t np = kpcn_aov_plane_size(s);
  for (int y = 0; y < h; y++)
    for (int x = 0; x < w; x++) {
      double u = (x - cx) / R, v = -(y - cy) / R;
      s->buf[KPCN_BUF_NORMAL][(size_t)y * w + x] = (float)u;
      s->buf[KPCN_BUF_NORMAL][np + (size_t)y * w + x] = (float)v;
      s->buf[KPCN_BUF_NORMAL][2 * np + (size_t)y * w + x] = (float)sqrt(1 - u * u - v * v);
    }
}

static void test_normal_convention(void) {
  kpcn_aov_set *a = NULL, *expect = NULL;
  kpcn_aov_create(&a, 8, 6);
  kpcn_aov_add(a, KPCN_BUF_NORMAL, 0);
  dome(a);
  for (int k = 0; k < 16; k++) {
    kpcn_augment_xform x;
    kpcn_augment_identity(&x);
    x.mirror_h = k & 1;
    x.mirror_v = (k >> 1) & 1;
    x.rot90 = k >> 2;
    kpcn_aov_set *b = apply(a, &x);
    kpcn_aov_create(&expect, b->width, b->height);
    kpcn_aov_add(expect, KPCN_BUF_NORMAL, 0);
    dome(expect);
    size_t n = 3 * kpcn_aov_plane_size(b);
    double maxd = 0;
    for (size_t i = 0; i < n; i++) {
      double d = fabs(b->buf[KPCN_BUF_NORMAL][i] - expect->buf[KPCN_BUF_NORMAL][i]);
      maxd = d > maxd ? d : maxd;
    }
    CHECK_NEAR(maxd, 0, 1e-6);
    kpcn_aov_destroy(b);
    kpcn_aov_destroy(expect);
  }
  kpcn_aov_destroy(a);
}

/* A pair whose reference is a pixelwise function of the noisy set stays one after any
 * transform applied to both with the same draw. */
static void test_pair_alignment(void) {
  kpcn_aov_set *n = random_set(10, 7), *r = NULL;
  kpcn_aov_create(&r, 10, 7);
  kpcn_aov_add(r, KPCN_BUF_COLOR, 0);
  kpcn_aov_add(r, KPCN_BUF_DIFFUSE, 0);
  size_t np = kpcn_aov_plane_size(n);
  for (size_t i = 0; i < 3 * np; i++) {
    r->buf[KPCN_BUF_COLOR][i] = 2 * n->buf[KPCN_BUF_COLOR][i] + 1;
    r->buf[KPCN_BUF_DIFFUSE][i] = n->buf[KPCN_BUF_DIFFUSE][i] - 3;
  }
  kpcn_augment_draw_settings ds;
  kpcn_augment_draw_defaults(&ds);
  ds.max_shift = 4;
  int ok = 1;
  for (uint64_t i = 0; i < 20; i++) {
    kpcn_augment_xform x;
    kpcn_augment_draw(&x, &ds, 7, i);
    kpcn_aov_set *n2 = apply(n, &x), *r2 = apply(r, &x);
    for (size_t k = 0; k < 3 * np; k++) {
      ok &= r2->buf[KPCN_BUF_COLOR][k] == 2 * n2->buf[KPCN_BUF_COLOR][k] + 1;
      ok &= r2->buf[KPCN_BUF_DIFFUSE][k] == n2->buf[KPCN_BUF_DIFFUSE][k] - 3;
    }
    kpcn_aov_destroy(n2);
    kpcn_aov_destroy(r2);
  }
  CHECK(ok);
  kpcn_aov_destroy(n);
  kpcn_aov_destroy(r);
}

static void test_draw(void) {
  kpcn_augment_draw_settings ds;
  kpcn_augment_draw_defaults(&ds);
  int perms[6] = {0}, rots[4] = {0}, mir[2] = {0};
  for (uint64_t i = 0; i < 600; i++) {
    kpcn_augment_xform x, y;
    kpcn_augment_draw(&x, &ds, 5, i);
    kpcn_augment_draw(&y, &ds, 5, i);
    CHECK(memcmp(&x, &y, sizeof x) == 0);
    perms[x.perm[0] * 2 + (x.perm[1] > x.perm[2])]++;
    rots[x.rot90]++;
    mir[x.mirror_h]++;
  }
  for (int i = 0; i < 6; i++)
    CHECK(perms[i] > 60);
  for (int i = 0; i < 4; i++)
    CHECK(rots[i] > 100);
  CHECK(mir[0] > 240 && mir[1] > 240);
  /* ONE_OF: exactly one op differs from identity. */
  ds.mode = KPCN_AUGMENT_ONE_OF;
  ds.max_shift = 3;
  int ok = 1;
  for (uint64_t i = 0; i < 200; i++) {
    kpcn_augment_xform x;
    kpcn_augment_draw(&x, &ds, 11, i);
    int nops = (x.perm[0] != 0 || x.perm[1] != 1) + x.mirror_h + x.mirror_v + (x.rot90 != 0) +
               (x.dx != 0 || x.dy != 0);
    ok &= nops == 1;
  }
  CHECK(ok);
}

/* Arbitrary angle: 90 degrees matches the exact turn on a square image; 45 degrees of a
 * constant-variance field lowers the propagated variance (sum of w^2 < 1). */
static void test_rotate_any(void) {
  kpcn_aov_set *a = random_set(9, 9), *b = NULL, *e = NULL;
  CHECK(kpcn_augment_rotate_any_aov(&b, a, 90.0, 0) == KPCN_OK);
  kpcn_augment_xform r;
  kpcn_augment_identity(&r);
  r.rot90 = 1;
  e = apply(a, &r);
  double maxd = 0;
  size_t np = kpcn_aov_plane_size(a);
  for (size_t i = 0; i < 3 * np; i++) {
    double d = fabs(b->buf[KPCN_BUF_COLOR][i] - e->buf[KPCN_BUF_COLOR][i]);
    maxd = d > maxd ? d : maxd;
  }
  CHECK_NEAR(maxd, 0, 1e-5);
  kpcn_aov_destroy(b);
  for (size_t i = 0; i < np; i++)
    a->var[KPCN_BUF_COLOR][i] = 1.0f;
  CHECK(kpcn_augment_rotate_any_aov(&b, a, 45.0, 0) == KPCN_OK);
  /* Centre pixel maps onto itself (weight 1); an off-centre one splits over 4 taps. */
  CHECK_NEAR(b->var[KPCN_BUF_COLOR][4 * 9 + 4], 1.0, 1e-6);
  CHECK(b->var[KPCN_BUF_COLOR][4 * 9 + 5] < 0.9f);
  kpcn_aov_destroy(a);
  kpcn_aov_destroy(b);
  kpcn_aov_destroy(e);
}

/* Arbitrary angles against geometry: a counter-clockwise turn by t about the image centre shows
 * at output pixel p the source point R(-t) p (screen coordinates, y up). Bilinear interpolation
 * reproduces a linear field exactly, so colour = (x, y, 1) must come out as that source point's
 * (x, y) wherever its four taps lie inside the image, and a constant normal (1, 0, 0) as
 * (cos t, sin t, 0): a wrong centre, interpolation or turning direction fails here. */
static void test_rotate_any_geometry(void) {
  const int W = 21, H = 15;
  const double degs[3] = {30.0, 45.0, -70.0};
  for (int k = 0; k < 3; k++) {
    kpcn_aov_set *a = NULL, *b = NULL;
    CHECK(kpcn_aov_create(&a, W, H) == KPCN_OK);
    if (!a) return;
    kpcn_aov_add(a, KPCN_BUF_COLOR, 0);
    kpcn_aov_add(a, KPCN_BUF_NORMAL, 0);
    const size_t P = kpcn_aov_plane_size(a);
    for (int y = 0; y < H; y++)
      for (int x = 0; x < W; x++) {
        const size_t i = (size_t)y * W + x;
        a->buf[KPCN_BUF_COLOR][i] = (float)x;
        a->buf[KPCN_BUF_COLOR][P + i] = (float)y;
        a->buf[KPCN_BUF_COLOR][2 * P + i] = 1.0f;
        a->buf[KPCN_BUF_NORMAL][i] = 1.0f;
        a->buf[KPCN_BUF_NORMAL][P + i] = 0.0f;
        a->buf[KPCN_BUF_NORMAL][2 * P + i] = 0.0f;
      }
    CHECK(kpcn_augment_rotate_any_aov(&b, a, degs[k], 1) == KPCN_OK);
    if (!b) {
      kpcn_aov_destroy(a);
      return;
    }
    const double t = degs[k] * 3.14159265358979323846 / 180.0, cx = 0.5 * (W - 1),
                 cy = 0.5 * (H - 1);
    double maxd = 0, maxn = 0;
    int interior = 0;
    for (int y = 0; y < H; y++)
      for (int x = 0; x < W; x++) {
        const double u = x - cx, v = cy - y; /* y up */
        const double su = cos(t) * u + sin(t) * v, sv = -sin(t) * u + cos(t) * v;
        const double xs = cx + su, ys = cy - sv;
        if (xs < 0 || ys < 0 || xs > W - 1 || ys > H - 1) continue;
        const size_t i = (size_t)y * W + x;
        interior++;
        maxd = kt_worst(maxd, fabs(b->buf[KPCN_BUF_COLOR][i] - xs));
        maxd = kt_worst(maxd, fabs(b->buf[KPCN_BUF_COLOR][P + i] - ys));
        maxd = kt_worst(maxd, fabs(b->buf[KPCN_BUF_COLOR][2 * P + i] - 1.0));
        maxn = kt_worst(maxn, fabs(b->buf[KPCN_BUF_NORMAL][i] - cos(t)));
        maxn = kt_worst(maxn, fabs(b->buf[KPCN_BUF_NORMAL][P + i] - sin(t)));
        maxn = kt_worst(maxn, fabs(b->buf[KPCN_BUF_NORMAL][2 * P + i]));
      }
    printf("rotate %.0f deg: %d interior pixels, max |colour - source point| %.2e, normal %.2e\n",
           degs[k], interior, maxd, maxn);
    CHECK(interior > W * H / 3);
    CHECK(maxd < 1e-4 && maxn < 1e-6);
    kpcn_aov_destroy(a);
    kpcn_aov_destroy(b);
  }
}

/* Normals under every name the AOV readers accept (docs/aov-exr.md) are mirrored and rotated
 * like "N.X N.Y N.Z", and never colour-swapped (also when stored as "normal.R G B"): the same
 * planes under each naming give the canonical naming's result bit for bit. */
static void test_normal_aliases(void) {
  enum { W = 6, H = 4, NCH = 7 };
  static const char *const schemes[][3] = {
      {"N.X", "N.Y", "N.Z"},
      {"normal.X", "normal.Y", "normal.Z"},
      {"Denoising Normal.X", "Denoising Normal.Y", "Denoising Normal.Z"},
      {"ref.N.X", "ref.N.Y", "ref.N.Z"},
      {"normal.R", "normal.G", "normal.B"},
      {"ViewLayer.Denoising Normal.X", "ViewLayer.Denoising Normal.Y",
       "ViewLayer.Denoising Normal.Z"}};
  float src[NCH * W * H], want[NCH * W * H], got[NCH * W * H];
  unsigned st = 5;
  for (int i = 0; i < NCH * W * H; i++)
    src[i] = kt_randf(&st) - 0.5f;
  kpcn_augment_xform x;
  kpcn_augment_identity(&x);
  x.perm[0] = 2, x.perm[1] = 0, x.perm[2] = 1;
  x.mirror_h = 1;
  x.rot90 = 1;
  for (int s = 0; s < (int)(sizeof schemes / sizeof schemes[0]); s++) {
    const char *names[NCH] = {"R", "G", "B", schemes[s][0], schemes[s][1], schemes[s][2], "Z"};
    CHECK(kpcn_augment_planes(s ? got : want, src, NCH, names, W, H, &x, 1) == KPCN_OK);
    if (s) CHECK(memcmp(got, want, sizeof got) == 0);
  }
  /* and the canonical result is the definition: (nx, ny) -> mirrored, then turned */
  int ok = 1;
  for (int y = 0; y < H; y++)
    for (int xx = 0; xx < W; xx++) {
      const int sx = W - 1 - xx, ox = y, oy = W - 1 - xx; /* mirror, then (x,y) -> (y, W-1-x) */
      const float nx = -src[3 * W * H + y * W + sx], ny = src[4 * W * H + y * W + sx];
      ok &= want[3 * W * H + oy * H + ox] == -ny && want[4 * W * H + oy * H + ox] == nx;
      ok &= want[0 * W * H + oy * H + ox] == src[2 * W * H + y * W + sx]; /* new R = old B */
    }
  CHECK(ok);
}

/* Edge cases found in session 61: a shift of INT_MIN (xo - dx overflowed int: 7 wide gave a
 * roll by 2, not by -2^31 mod 7 = 5) and its inverse (negating INT_MIN); the albedo metadata
 * kept by augment, crop and arbitrary rotation; a lone N.Y refused by the arbitrary rotation
 * as by the quarter turns. */
static void test_edge_cases(void) {
  kpcn_aov_set *a = random_set(7, 5);
  a->albedo_spp = 16;
  a->albedo_footprint = 3;
  kpcn_augment_xform s, inv;
  kpcn_augment_identity(&s);
  s.dx = INT_MIN;
  s.dy = INT_MIN; /* -2^31 mod 5 = 2 */
  kpcn_aov_set *b = apply(a, &s);
  int ok = 1;
  for (int y = 0; y < 5; y++)
    for (int x = 0; x < 7; x++)
      ok &= px(b, KPCN_BUF_COLOR, 0, (x + 5) % 7, (y + 2) % 5) == px(a, KPCN_BUF_COLOR, 0, x, y);
  CHECK(ok);
  kpcn_augment_inverse(&inv, &s, 7, 5);
  kpcn_aov_set *c = apply(b, &inv);
  CHECK(sets_equal(a, c));
  CHECK(b->albedo_spp == 16 && b->albedo_footprint == 3);
  kpcn_aov_set *d = NULL, *e = NULL;
  CHECK(kpcn_augment_crop_aov(&d, a, 1, 1, 3, 2) == KPCN_OK);
  CHECK(d && d->albedo_spp == 16 && d->albedo_footprint == 3);
  CHECK(kpcn_augment_rotate_any_aov(&e, a, 30.0, 1) == KPCN_OK);
  CHECK(e && e->albedo_spp == 16 && e->albedo_footprint == 3);
  /* planes R, N.Y: a normal without its N.X */
  float src[2 * 35], dst[2 * 35];
  for (int i = 0; i < 70; i++)
    src[i] = 0.5f;
  const char *names[2] = {"R", "N.Y"};
  CHECK(kpcn_augment_rotate_any_planes(dst, src, 2, names, 7, 5, 30.0, 1) ==
        KPCN_ERR_MISSING_CHANNEL);
  CHECK(strstr(kpcn_last_error(), "needs its N.X") != NULL);
  kpcn_aov_destroy(a);
  kpcn_aov_destroy(b);
  kpcn_aov_destroy(c);
  kpcn_aov_destroy(d);
  kpcn_aov_destroy(e);
}

int main(void) {
  test_edge_cases();
  test_normal_aliases();
  test_mirror_twice();
  test_rotations();
  test_colorswap();
  test_shift_and_inverse();
  test_normal_convention();
  test_pair_alignment();
  test_draw();
  test_rotate_any();
  test_rotate_any_geometry();
  return kt_summary("augment_ops");
}
