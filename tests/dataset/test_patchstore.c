/* Patch store: round trip (float32 exact, float16 within half precision), extraction from
 * AOV sets, metadata, atomic finish/abort, and malformed stores rejected with clear errors. */
#include "kpcn/augment.h"
#include "kpcn/dataset.h"
#include "testutil.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

static int exists(const char *p) {
  struct stat sb;
  return stat(p, &sb) == 0;
}

static kpcn_aov_set *make_set(int W, int H, int with_all, unsigned seed) {
  kpcn_aov_set *s = NULL;
  kpcn_aov_create(&s, W, H);
  unsigned rng = seed;
  for (int b = 0; b < KPCN_BUF_COUNT; b++) {
    if (!with_all && b > KPCN_BUF_SPECULAR) break;
    kpcn_aov_add(s, (kpcn_buffer)b, with_all);
    size_t n = kpcn_aov_plane_size(s) * (size_t)kpcn_buffer_channels((kpcn_buffer)b);
    for (size_t i = 0; i < n; i++)
      s->buf[b][i] = kt_randf(&rng) * 4;
    if (with_all)
      for (size_t i = 0; i < kpcn_aov_plane_size(s); i++)
        s->var[b][i] = kt_randf(&rng) * 0.1f;
  }
  return s;
}

/* Value of channel `name` at (x, y) read directly from the AOV sets (independent of the
 * store's own extraction code). */
static float truth(const kpcn_aov_set *n, const kpcn_aov_set *r, const char *name, int x, int y) {
  const kpcn_aov_set *s = strncmp(name, "ref.", 4) == 0 ? r : n;
  const char *nm = s == r ? name + 4 : name;
  size_t np = kpcn_aov_plane_size(s), i = (size_t)y * s->width + x;
  for (int b = 0; b < KPCN_BUF_COUNT; b++) {
    for (int c = 0; c < kpcn_buffer_channels((kpcn_buffer)b); c++)
      if (!strcmp(kpcn_buffer_channel_name((kpcn_buffer)b, c), nm)) return s->buf[b][c * np + i];
    if (!strcmp(kpcn_buffer_variance_name((kpcn_buffer)b), nm)) return s->var[b][i];
  }
  return -12345.0f;
}

static void round_trip(kpcn_dtype dt) {
  const char *path = kt_tmpfile(dt == KPCN_DTYPE_F32 ? "rt32.kps" : "rt16.kps");
  kpcn_aov_set *n = make_set(40, 30, 1, 7), *r = make_set(40, 30, 0, 8);
  kpcn_patchstore_settings s;
  kpcn_patchstore_settings_defaults(&s);
  s.patch_size = 9;
  s.dtype = dt;
  s.settings_json = "{\"cull\":0.9}";
  kpcn_patchstore_writer *w = NULL;
  CHECK(kpcn_patchstore_create(&w, path, &s) == KPCN_OK);
  kpcn_patch_source src;
  memset(&src, 0, sizeof src);
  snprintf(src.scene, sizeof src.scene, "cornell-box");
  snprintf(src.split, sizeof src.split, "train");
  src.variant = 3;
  src.spp = 16;
  src.ref_spp = 1024;
  CHECK(kpcn_patch_source_image_stats(&src, n) == KPCN_OK);
  uint32_t id = 99;
  CHECK(kpcn_patchstore_add_source(w, &src, &id) == KPCN_OK && id == 0);
  int xs[3] = {0, 31, 10}, ys[3] = {0, 21, 5};
  for (int k = 0; k < 3; k++) {
    kpcn_patch_record rec = {0, xs[k], ys[k], 0, 0.25f * k, 1.0f, 0};
    CHECK(kpcn_patchstore_append_aov(w, &rec, n, r) == KPCN_OK);
  }
  kpcn_patch_record bad = {0, 32, 0, 0, 0, 1, 0};
  CHECK(kpcn_patchstore_append_aov(w, &bad, n, r) == KPCN_ERR_INVALID_ARGUMENT);
  kpcn_patchstore_add_stats(w, 10, 3, 7);
  CHECK(!exists(path)); /* nothing visible before finish */
  CHECK(kpcn_patchstore_finish(w) == KPCN_OK);
  CHECK(exists(path));

  kpcn_patchstore *ps = NULL;
  CHECK(kpcn_patchstore_open(&ps, path, kpcn_patchstore_default_channels,
                             KPCN_PATCHSTORE_NUM_DEFAULT) == KPCN_OK);
  if (!ps) return;
  CHECK(kpcn_patchstore_count(ps) == 3 && kpcn_patchstore_patch_size(ps) == 9);
  CHECK(kpcn_patchstore_nchannels(ps) == 33 && kpcn_patchstore_dtype(ps) == dt);
  CHECK(kpcn_patchstore_find_channel(ps, "ref.specular.B") == 32);
  CHECK(kpcn_patchstore_find_channel(ps, "nope") == -1);
  const kpcn_patch_source *rs = kpcn_patchstore_source(ps, 0);
  CHECK(kpcn_patchstore_nsources(ps) == 1 && rs && !strcmp(rs->scene, "cornell-box"));
  CHECK(rs && rs->variant == 3 && rs->spp == 16 && rs->ref_spp == 1024 && rs->width == 40);
  /* Depth stats vs a naive loop. */
  double mn = 1e30, mx = -1e30, sum = 0;
  for (int i = 0; i < 1200; i++) {
    float z = n->buf[KPCN_BUF_DEPTH][i];
    mn = z < mn ? z : mn;
    mx = z > mx ? z : mx;
    sum += z;
  }
  CHECK(rs && rs->depth_min == (float)mn && rs->depth_max == (float)mx);
  /* the whole image's exposure travels with the source (the trainer records the range) */
  double ex = 0.0;
  CHECK(kpcn_aov_exposure(n, &ex) == KPCN_OK && ex > 0.0);
  CHECK(rs && src.exposure == ex && fabs(rs->exposure - ex) <= 1e-12 * ex);
  CHECK_CLOSE(rs ? rs->depth_mean : 0, sum / 1200, 1e-5, 0);
  float *buf = malloc(sizeof(float) * 33 * 81);
  const char *const *ch = kpcn_patchstore_channels(ps);
  double maxrel = 0;
  for (int k = 0; k < 3; k++) {
    kpcn_patch_record rec;
    CHECK(kpcn_patchstore_get(ps, (uint64_t)k, buf, &rec) == KPCN_OK);
    CHECK(rec.x == xs[k] && rec.y == ys[k] && rec.source == 0 && rec.flat_frac == 0.25f * k);
    for (int c = 0; c < 33; c++)
      for (int y = 0; y < 9; y++)
        for (int x = 0; x < 9; x++) {
          double t = truth(n, r, ch[c], xs[k] + x, ys[k] + y), v = buf[(c * 9 + y) * 9 + x];
          double rel =
              fabs(v - t) / (fabs(t) + 6e-8 * 2048); /* half: 2^-11 relative, 6e-8 absolute */
          maxrel = rel > maxrel ? rel : maxrel;
        }
  }
  if (dt == KPCN_DTYPE_F32)
    CHECK(maxrel == 0);
  else
    CHECK(maxrel <= 1.0 / 2048 && maxrel > 0);
  CHECK(kpcn_patchstore_get(ps, 3, buf, NULL) == KPCN_ERR_INVALID_ARGUMENT);
  /* the record alone is the one get() returns, and is bounds-checked the same way */
  for (int k = 0; k < 3; k++) {
    kpcn_patch_record a, b;
    CHECK(kpcn_patchstore_get(ps, (uint64_t)k, buf, &a) == KPCN_OK);
    CHECK(kpcn_patchstore_record(ps, (uint64_t)k, &b) == KPCN_OK);
    CHECK(memcmp(&a, &b, sizeof a) == 0 && b.x == xs[k] && b.y == ys[k]);
  }
  {
    kpcn_patch_record r;
    CHECK(kpcn_patchstore_record(ps, 3, &r) == KPCN_ERR_INVALID_ARGUMENT);
    CHECK(kpcn_patchstore_record(ps, 0, NULL) == KPCN_ERR_INVALID_ARGUMENT);
    CHECK(kpcn_patchstore_record(NULL, 0, &r) == KPCN_ERR_INVALID_ARGUMENT);
  }
  /* Augmenting a stored patch through its names keeps noisy/reference aligned. */
  float *aug = malloc(sizeof(float) * 33 * 81);
  kpcn_augment_xform x;
  kpcn_augment_identity(&x);
  x.rot90 = 1;
  x.perm[0] = 2, x.perm[1] = 0, x.perm[2] = 1;
  CHECK(kpcn_augment_planes(aug, buf, 33, ch, 9, 9, &x, 1) == KPCN_OK);
  /* new ref.R at rotated position (y, 8-x) = old ref.B at (x, y). */
  CHECK(aug[(24 * 9 + (8 - 2)) * 9 + 1] == buf[(26 * 9 + 1) * 9 + 2]);
  CHECK(aug[(0 * 9 + (8 - 2)) * 9 + 1] == buf[(2 * 9 + 1) * 9 + 2]);
  free(aug);
  free(buf);
  kpcn_patchstore_close(ps);
  kpcn_aov_destroy(n);
  kpcn_aov_destroy(r);
}

static void write_bytes(const char *path, const unsigned char *d, size_t n) {
  FILE *f = fopen(path, "wb");
  fwrite(d, 1, n, f);
  fclose(f);
}

static void put64le(unsigned char *o, uint64_t v) {
  for (int i = 0; i < 8; i++)
    o[i] = (unsigned char)(v >> (8 * i));
}

/* A header whose fields are each consistent but whose metadata offset + length wraps past
 * 2^64 to exactly the file size: both the "truncated" and the "trailing bytes" checks passed
 * on the sum, and the metadata was then read from before the mapping (a crash). */
static void wrapping_header(void) {
  enum { SIZE = 8192 };
  unsigned char *d = calloc(SIZE, 1);
  if (!d) {
    CHECK(0);
    return;
  }
  FILE *f = fopen(kt_tmpfile("rt32.kps"), "rb"); /* its magic (written by round_trip) */
  CHECK(f && fread(d, 1, 8, f) == 8);
  if (f) fclose(f);
  d[8] = 1;               /* version */
  d[12] = KPCN_DTYPE_F16; /* dtype */
  d[16] = 1, d[20] = 1;   /* patch size 1, one channel: 2 bytes a patch */
  const uint64_t rec = 2 + 32, count = (UINT64_MAX - KPCN_PATCHSTORE_DATA_OFFSET) / rec;
  const uint64_t index_offset = KPCN_PATCHSTORE_DATA_OFFSET + count * 2;
  const uint64_t meta_offset = index_offset + count * 32;
  put64le(d + 24, count);
  put64le(d + 32, 2);
  put64le(d + 40, index_offset);
  put64le(d + 48, meta_offset);
  put64le(d + 56, (uint64_t)SIZE - meta_offset); /* meta_offset + this wraps to SIZE */
  const char *p = kt_tmpfile("wrap.kps");
  write_bytes(p, d, SIZE);
  kpcn_patchstore *ps = NULL;
  CHECK(kpcn_patchstore_open(&ps, p, NULL, 0) == KPCN_ERR_FORMAT && !ps);
  CHECK(strstr(kpcn_last_error(), "truncated") != NULL);
  free(d);
}

static void malformed(void) {
  const char *good = kt_tmpfile("rt32.kps"); /* written by round_trip */
  FILE *f = fopen(good, "rb");
  if (!f) {
    CHECK(0);
    return;
  }
  fseek(f, 0, SEEK_END);
  size_t n = (size_t)ftell(f);
  fseek(f, 0, SEEK_SET);
  unsigned char *d = malloc(n);
  CHECK(fread(d, 1, n, f) == n);
  fclose(f);
  const char *p = kt_tmpfile("bad.kps");
  kpcn_patchstore *ps = NULL;
  /* wrong magic */
  d[0] ^= 0xff;
  write_bytes(p, d, n);
  CHECK(kpcn_patchstore_open(&ps, p, NULL, 0) == KPCN_ERR_FORMAT && !ps);
  CHECK(strstr(kpcn_last_error(), "magic") != NULL);
  d[0] ^= 0xff;
  /* truncated */
  write_bytes(p, d, n - 10);
  CHECK(kpcn_patchstore_open(&ps, p, NULL, 0) == KPCN_ERR_FORMAT);
  CHECK(strstr(kpcn_last_error(), "truncated") != NULL);
  write_bytes(p, d, 30);
  CHECK(kpcn_patchstore_open(&ps, p, NULL, 0) == KPCN_ERR_FORMAT);
  /* version from the future */
  d[8] = 9;
  write_bytes(p, d, n);
  CHECK(kpcn_patchstore_open(&ps, p, NULL, 0) == KPCN_ERR_UNSUPPORTED);
  d[8] = 1;
  /* channel count in header disagrees with patch_bytes */
  d[20]++;
  write_bytes(p, d, n);
  CHECK(kpcn_patchstore_open(&ps, p, NULL, 0) == KPCN_ERR_FORMAT);
  d[20]--;
  /* channel list mismatch */
  const char *exp[2] = {"R", "G"};
  write_bytes(p, d, n);
  CHECK(kpcn_patchstore_open(&ps, p, exp, 2) == KPCN_ERR_FORMAT);
  CHECK(strstr(kpcn_last_error(), "channel list mismatch") != NULL);
  const char *const *dc = kpcn_patchstore_default_channels;
  const char *swapped[33];
  memcpy(swapped, dc, sizeof swapped);
  swapped[5] = "diffuse.X";
  CHECK(kpcn_patchstore_open(&ps, p, swapped, 33) == KPCN_ERR_FORMAT);
  CHECK(strstr(kpcn_last_error(), "diffuse.X") != NULL);
  /* index records: a weight that is not positive and finite, a flat fraction outside [0, 1]
   * and reserved flags are refused naming the patch (a NaN weight was accepted) */
  uint64_t index_offset;
  memcpy(&index_offset, d + 40, 8);
  unsigned char *rec0 = d + index_offset;
  const float bad_weight = NAN, bad_flat = 1.5f;
  const uint32_t bad_flags = 1;
  const struct {
    size_t at;
    const void *v;
  } bad_fields[3] = {{20, &bad_weight}, {16, &bad_flat}, {12, &bad_flags}};
  for (int i = 0; i < 3; i++) {
    unsigned char keep[4];
    memcpy(keep, rec0 + bad_fields[i].at, 4);
    memcpy(rec0 + bad_fields[i].at, bad_fields[i].v, 4);
    write_bytes(p, d, n);
    CHECK(kpcn_patchstore_open(&ps, p, NULL, 0) == KPCN_ERR_FORMAT && !ps);
    CHECK(strstr(kpcn_last_error(), "patch 0 has an invalid record") != NULL);
    memcpy(rec0 + bad_fields[i].at, keep, 4);
  }
  write_bytes(p, d, n);
  CHECK(kpcn_patchstore_open(&ps, p, NULL, 0) == KPCN_OK && ps);
  kpcn_patchstore_close(ps);
  ps = NULL;
  /* corrupt JSON */
  d[n - 1] = '#';
  write_bytes(p, d, n);
  CHECK(kpcn_patchstore_open(&ps, p, NULL, 0) == KPCN_ERR_FORMAT);
  CHECK(strstr(kpcn_last_error(), "JSON") != NULL);
  /* missing file */
  CHECK(kpcn_patchstore_open(&ps, kt_tmpfile("nonexistent.kps"), NULL, 0) == KPCN_ERR_IO);
  free(d);
  wrapping_header();
}

static void writer_errors(void) {
  const char *path = kt_tmpfile("abort.kps");
  kpcn_patchstore_settings s;
  kpcn_patchstore_settings_defaults(&s);
  s.patch_size = 4;
  const char *names[2] = {"R", "Z"};
  s.channels = names;
  s.nchannels = 2;
  kpcn_patchstore_writer *w = NULL;
  CHECK(kpcn_patchstore_create(&w, path, &s) == KPCN_OK);
  float p[32] = {0};
  kpcn_patch_record rec = {0, 0, 0, 0, 0, 1, 0};
  CHECK(kpcn_patchstore_append(w, &rec, p) == KPCN_ERR_INVALID_ARGUMENT); /* no source */
  kpcn_patch_source src;
  memset(&src, 0, sizeof src);
  CHECK(kpcn_patchstore_add_source(w, &src, NULL) == KPCN_OK);
  CHECK(kpcn_patchstore_append(w, &rec, p) == KPCN_OK);
  p[17] = NAN;
  CHECK(kpcn_patchstore_append(w, &rec, p) == KPCN_ERR_NONFINITE);
  CHECK(strstr(kpcn_last_error(), "'Z'") != NULL);
  kpcn_patchstore_abort(w);
  CHECK(!exists(path));
  /* a finite value beyond float16's range would be stored as Inf */
  s.dtype = KPCN_DTYPE_F16;
  CHECK(kpcn_patchstore_create(&w, path, &s) == KPCN_OK);
  CHECK(kpcn_patchstore_add_source(w, &src, NULL) == KPCN_OK);
  p[17] = 65504.0f;
  CHECK(kpcn_patchstore_append(w, &rec, p) == KPCN_OK);
  p[17] = 70000.0f;
  CHECK(kpcn_patchstore_append(w, &rec, p) == KPCN_ERR_NONFINITE);
  CHECK(strstr(kpcn_last_error(), "overflows float16") != NULL);
  kpcn_patchstore_abort(w);
  s.dtype = KPCN_DTYPE_F32;
  s.settings_json = "[1,2";
  CHECK(kpcn_patchstore_create(&w, path, &s) == KPCN_ERR_INVALID_ARGUMENT);
  /* Missing buffer when extracting from an AOV set. */
  s.settings_json = NULL;
  s.channels = NULL;
  CHECK(kpcn_patchstore_create(&w, path, &s) == KPCN_OK);
  kpcn_patchstore_add_source(w, &src, NULL);
  kpcn_aov_set *n = make_set(8, 8, 0, 1);
  CHECK(kpcn_patchstore_append_aov(w, &rec, n, n) == KPCN_ERR_MISSING_CHANNEL);
  CHECK(strstr(kpcn_last_error(), "albedo.R") != NULL);
  kpcn_patchstore_abort(w);
  kpcn_aov_destroy(n);
}

static void half_conv(void) {
  /* Against known binary16 encodings. */
  CHECK(kpcn_float_to_half(1.0f) == 0x3c00);
  CHECK(kpcn_float_to_half(-2.0f) == 0xc000);
  CHECK(kpcn_float_to_half(65504.0f) == 0x7bff);
  CHECK(kpcn_float_to_half(65520.0f) == 0x7c00);
  CHECK(kpcn_float_to_half(5.9604645e-8f) == 0x0001);      /* smallest subnormal */
  CHECK(kpcn_float_to_half(6.1035156e-5f) == 0x0400);      /* smallest normal */
  CHECK(kpcn_float_to_half(1.0f + 1.0f / 2048) == 0x3c00); /* tie to even */
  CHECK(kpcn_float_to_half(1.0f + 3.0f / 2048) == 0x3c02);
  CHECK(kpcn_half_to_float(0x3555) == 0.333251953125f);
  CHECK(kpcn_half_to_float(0x0001) == 5.9604645e-8f);
  int ok = 1;
  for (uint32_t h = 0; h < 0x7c00; h++)
    ok &= kpcn_float_to_half(kpcn_half_to_float((uint16_t)h)) == h;
  CHECK(ok);
}

int main(void) {
  round_trip(KPCN_DTYPE_F32);
  round_trip(KPCN_DTYPE_F16);
  malformed();
  writer_errors();
  half_conv();
  return kt_summary("patchstore");
}
