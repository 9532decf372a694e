/* Bad input to the EXR reader/writer: missing, garbage, truncated and corrupted files, absurd
 * header sizes, failing writes (which must leave neither a partial file nor a temp file);
 * files the reader refuses by design (deep, subsampled channels) or converts (uint, half),
 * written here at test time with OpenEXR Core from raw uncompressed chunks. */
#include "kpcn/exr.h"

#include "testutil.h"

#include <dirent.h>
#include <openexr.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

static long file_size(const char *p) {
  struct stat st;
  return stat(p, &st) == 0 ? (long)st.st_size : -1;
}

static void spit(const char *p, const unsigned char *b, long n) {
  FILE *f = fopen(p, "wb");
  if (!f) return;
  fwrite(b, 1, (size_t)n, f);
  fclose(f);
}

/* Number of entries in the test's temp dir whose name contains `frag`. */
static int count_in_tmpdir(const char *frag) {
  DIR *d = opendir(kt_tmpdir());
  int n = 0;
  struct dirent *e;
  while (d && (e = readdir(d)))
    if (strstr(e->d_name, frag)) n++;
  if (d) closedir(d);
  return n;
}

static const char *write_valid(const char *name, int w, int h, kpcn_exr_compression comp) {
  const char *names[] = {"R", "G", "B", "Z"};
  kpcn_image *img = NULL;
  kpcn_image_create(&img, w, h, 4, names);
  unsigned st = 17;
  for (size_t i = 0; i < (size_t)w * h * 4; i++)
    img->data[i] = kt_randf(&st);
  const char *path = kt_tmpfile(name);
  kpcn_exr_write_options o = kpcn_exr_write_options_defaults();
  o.compression = comp;
  CHECK(kpcn_exr_write_image(path, img, &o) == KPCN_OK);
  kpcn_image_destroy(img);
  return path;
}

/* Every read entry point must fail on `path` with a message naming it. */
static void expect_read_fails(const char *path, const char *tag, int header_ok) {
  kpcn_image *img = (kpcn_image *)1;
  kpcn_status s = kpcn_exr_read_image(path, &img);
  CHECK(s != KPCN_OK && img == NULL);
  CHECK(strstr(kpcn_last_error(), path) != NULL);
  if (s == KPCN_OK || !strstr(kpcn_last_error(), path))
    fprintf(stderr, "  [%s] read_image: status %d, '%s'\n", tag, s, kpcn_last_error());
  kpcn_aov_set *set = (kpcn_aov_set *)1;
  s = kpcn_exr_read_aov(path, &set);
  CHECK(s != KPCN_OK && set == NULL && strstr(kpcn_last_error(), path));
  kpcn_exr_info_t info;
  s = kpcn_exr_info(path, &info);
  if (!header_ok) CHECK(s != KPCN_OK && strstr(kpcn_last_error(), path));
}

/* ---- EXR files written at test time with OpenEXR Core (no committed binaries) ----
 * Uncompressed chunks are laid out by hand (a scanline chunk holds, per line, each channel in
 * name order, a subsampled channel only on lines y % ys == 0 and with w / xs values), so the
 * files do not depend on kpcn's writer. Checked once by hand against independent readers:
 * OpenEXR's C++ InputFile (with xSampling/ySampling slices) read the subsampled files with
 * the values written here; OpenImageIO 2.4 read the deep ones as deep with the sample counts
 * and values written here, the mixed-type one with these values (uint divided by 2^32 - 1),
 * and refuses the subsampled ones, as kpcn does. */
typedef struct gen_channel {
  const char *name;
  exr_pixel_type_t type;
  int xs, ys;
} gen_channel;

/* half bit patterns and the floats they are; uint values and the nearest floats (above 2^24
 * a uint is not a float: it becomes the nearest one, as a C conversion gives) */
static const uint16_t k_half_bits[8] = {0x0000, 0x3c00, 0xb800, 0x4900,
                                        0x0001, 0x7bff, 0x7c00, 0x8000};
static const float k_half_vals[8] = {0.0f, 1.0f, -0.5f, 10.0f, 0x1p-24f, 65504.0f, INFINITY, -0.0f};
static const uint32_t k_uints[8] = {0u,        1u,        7u,          65535u,
                                    16777216u, 16777217u, 2147483649u, 4294967295u};

/* The value channel c holds at (x, y) (sample coordinates of a subsampled channel), as the
 * float the reader should give; its bytes in the file go to `bytes` (when non-NULL). */
static float gen_value(const gen_channel *ch, int c, int x, int y, unsigned char *bytes) {
  const int k = (x + 3 * y + c) & 7;
  if (ch->type == EXR_PIXEL_HALF) {
    if (bytes) memcpy(bytes, &k_half_bits[k], 2); /* little-endian host, as EXR */
    return k_half_vals[k];
  }
  if (ch->type == EXR_PIXEL_UINT) {
    if (bytes) memcpy(bytes, &k_uints[k], 4);
    return (float)k_uints[k];
  }
  const float f = -0.125f - (float)(100 * c + 10 * y + x);
  if (bytes) memcpy(bytes, &f, 4);
  return f;
}

static void gen_error(exr_const_context_t ctxt, exr_result_t code, const char *msg) {
  (void)ctxt;
  fprintf(stderr, "  OpenEXR (generator): %s (%d)\n", msg ? msg : "", (int)code);
}

/* Starts a one-part file of w x h, no compression, with the channels (given in name order). */
static exr_context_t gen_start(const char *path, exr_storage_t storage, int w, int h,
                               const gen_channel *ch, int nch) {
  exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
  init.error_handler_fn = gen_error;
  exr_context_t ctx = NULL;
  int part = -1;
  int ok =
      exr_start_write(&ctx, path, EXR_WRITE_FILE_DIRECTLY, &init) == EXR_ERR_SUCCESS &&
      exr_add_part(ctx, "", storage, &part) == EXR_ERR_SUCCESS &&
      exr_initialize_required_attr_simple(ctx, part, w, h, EXR_COMPRESSION_NONE) == EXR_ERR_SUCCESS;
  for (int c = 0; ok && c < nch; c++)
    ok = exr_add_channel(ctx, part, ch[c].name, ch[c].type, EXR_PERCEPTUALLY_LINEAR, ch[c].xs,
                         ch[c].ys) == EXR_ERR_SUCCESS;
  if (ok && storage == EXR_STORAGE_DEEP_TILED)
    ok = exr_set_tile_descriptor(ctx, part, (uint32_t)w, (uint32_t)h, EXR_TILE_ONE_LEVEL,
                                 EXR_TILE_ROUND_DOWN) == EXR_ERR_SUCCESS; /* one tile */
  if (ok && (storage == EXR_STORAGE_DEEP_SCANLINE || storage == EXR_STORAGE_DEEP_TILED))
    ok = exr_set_version(ctx, part, 1) == EXR_ERR_SUCCESS;
  if (ok) ok = exr_write_header(ctx) == EXR_ERR_SUCCESS;
  if (!ok) exr_finish(&ctx);
  return ok ? ctx : NULL;
}

/* A scanline file whose channels may be subsampled and of any pixel type. */
static int gen_scanline(const char *path, int w, int h, const gen_channel *ch, int nch) {
  exr_context_t ctx = gen_start(path, EXR_STORAGE_SCANLINE, w, h, ch, nch);
  if (!ctx) return 0;
  unsigned char line[4096];
  int ok = 1;
  for (int y = 0; ok && y < h; y++) {
    size_t n = 0;
    for (int c = 0; c < nch; c++) {
      if (y % ch[c].ys) continue;
      for (int x = 0; x < w / ch[c].xs; x++) {
        gen_value(&ch[c], c, x, y / ch[c].ys, line + n);
        n += ch[c].type == EXR_PIXEL_HALF ? 2 : 4;
      }
    }
    ok = exr_write_scanline_chunk(ctx, 0, y, line, n) == EXR_ERR_SUCCESS;
  }
  return exr_finish(&ctx) == EXR_ERR_SUCCESS && ok;
}

/* A deep file (scanline, or one tile) of w x h <= 8x8 with one float channel Z: pixel (x, y)
 * holds (x + y) % 3 samples. The sample counts are stored cumulative along a chunk's line (a
 * tile's restart on each of its rows). */
static int gen_deep(const char *path, int tiled, int w, int h) {
  const gen_channel z = {"Z", EXR_PIXEL_FLOAT, 1, 1};
  exr_context_t ctx =
      gen_start(path, tiled ? EXR_STORAGE_DEEP_TILED : EXR_STORAGE_DEEP_SCANLINE, w, h, &z, 1);
  if (!ctx) return 0;
  int32_t counts[64];
  float data[128];
  int ok = 1, np = 0, ns = 0;
  for (int y = 0; y < h; y++) {
    if (!tiled) np = ns = 0;
    int row = 0;
    for (int x = 0; x < w; x++) {
      for (int s = 0; s < (x + y) % 3; s++, row++)
        data[ns++] = (float)(100 * y + 10 * x + s);
      counts[np++] = row;
    }
    if (!tiled)
      ok = ok && exr_write_deep_scanline_chunk(ctx, 0, y, data, sizeof(float) * (size_t)ns,
                                               sizeof(float) * (size_t)ns, counts,
                                               sizeof(int32_t) * (size_t)np) == EXR_ERR_SUCCESS;
  }
  if (tiled)
    ok = exr_write_deep_tile_chunk(ctx, 0, 0, 0, 0, 0, data, sizeof(float) * (size_t)ns,
                                   sizeof(float) * (size_t)ns, counts,
                                   sizeof(int32_t) * (size_t)np) == EXR_ERR_SUCCESS;
  return exr_finish(&ctx) == EXR_ERR_SUCCESS && ok;
}

/* Every reader entry point refuses `path` as unsupported, naming it and `why`; *out stays
 * NULL (and ASan in CI sees nothing leaked on the way). */
static void expect_unsupported(const char *path, const char *why) {
  kpcn_image *img = (kpcn_image *)1;
  CHECK(kpcn_exr_read_image(path, &img) == KPCN_ERR_UNSUPPORTED && img == NULL);
  const char *e = kpcn_last_error();
  CHECK(strstr(e, path) != NULL && strstr(e, why) != NULL);
  if (!strstr(e, path) || !strstr(e, why))
    fprintf(stderr, "  %s: want '%s' in '%s'\n", path, why, e);
  img = (kpcn_image *)1;
  CHECK(kpcn_exr_read_image_mt(path, 2, &img) == KPCN_ERR_UNSUPPORTED && img == NULL);
  kpcn_aov_set *set = (kpcn_aov_set *)1;
  CHECK(kpcn_exr_read_aov(path, &set) == KPCN_ERR_UNSUPPORTED && set == NULL);
  CHECK(strstr(kpcn_last_error(), path) != NULL && strstr(kpcn_last_error(), why) != NULL);
  set = (kpcn_aov_set *)1;
  CHECK(kpcn_exr_read_aov_mt(path, 1, &set) == KPCN_ERR_UNSUPPORTED && set == NULL);
  expect_read_fails(path, why, 1);
}

/* exr.h / aov-exr.md: "subsampled channels (x/y sampling != 1) and deep files give
 * KPCN_ERR_UNSUPPORTED", every message naming the file. The same generator with 1x1 sampling
 * makes a file the reader takes, value for value, so the refusals are the sampling's. */
static void test_deep_and_subsampled(void) {
  const int w = 8, h = 4;
  gen_channel ch[2] = {{"A", EXR_PIXEL_FLOAT, 1, 1}, {"C", EXR_PIXEL_FLOAT, 1, 1}};
  const char *plain = kt_tmpfile("sampling_1x1.exr");
  CHECK(gen_scanline(plain, w, h, ch, 2));
  kpcn_image *img = NULL;
  CHECK(kpcn_exr_read_image(plain, &img) == KPCN_OK);
  if (img) {
    CHECK(img->width == w && img->height == h && img->nchannels == 2);
    int bad = 0;
    for (int c = 0; c < 2 && img->nchannels == 2; c++)
      for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++)
          bad += img->data[((size_t)c * h + y) * w + x] != gen_value(&ch[c], c, x, y, NULL);
    CHECK(bad == 0 && strcmp(img->names[0], "A") == 0 && strcmp(img->names[1], "C") == 0);
    kpcn_image_destroy(img);
  }
  const int samp[3][2] = {{2, 2}, {2, 1}, {1, 2}};
  for (int k = 0; k < 3; k++) {
    ch[1].xs = samp[k][0];
    ch[1].ys = samp[k][1];
    char name[64], why[64];
    snprintf(name, sizeof name, "sampling_%dx%d.exr", ch[1].xs, ch[1].ys);
    snprintf(why, sizeof why, "channel 'C' is subsampled (%dx%d)", ch[1].xs, ch[1].ys);
    const char *path = kt_tmpfile(name);
    CHECK(gen_scanline(path, w, h, ch, 2));
    expect_unsupported(path, why);
  }
  for (int tiled = 0; tiled < 2; tiled++) {
    const char *path = kt_tmpfile(tiled ? "deep_tiled.exr" : "deep_scanline.exr");
    CHECK(gen_deep(path, tiled, 5, 3));
    expect_unsupported(path, "deep EXR files are not supported");
  }
}

/* exr.h: "half/float/uint channels are all converted to float32"; aov-exr.md: "a uint keeps
 * its integer value" (OIIO divides by 2^32 - 1; test_exr_oiio reads oiiotool's uint file).
 * Here uint values across the whole range (exact up to 2^24, the nearest float above), half
 * values including a denormal, 65504, +inf and -0, and floats, mixed in one chunk (each
 * channel's bytes at its own offset), through the image and the AOV reader. */
static void test_uint_and_half(void) {
  const int w = 7, h = 5;
  const gen_channel ch[5] = {{"B", EXR_PIXEL_UINT, 1, 1},
                             {"G", EXR_PIXEL_HALF, 1, 1},
                             {"R", EXR_PIXEL_FLOAT, 1, 1},
                             {"Z", EXR_PIXEL_UINT, 1, 1},
                             {"Z.var", EXR_PIXEL_HALF, 1, 1}};
  const char *path = kt_tmpfile("mixed_types.exr");
  CHECK(gen_scanline(path, w, h, ch, 5));
  kpcn_exr_info_t info;
  CHECK(kpcn_exr_info(path, &info) == KPCN_OK);
  CHECK(info.nchannels == 5 && info.channel_is_half[0] == 2 && info.channel_is_half[1] == 1 &&
        info.channel_is_half[2] == 0 && info.channel_is_half[3] == 2);
  kpcn_image *img = NULL;
  CHECK(kpcn_exr_read_image_mt(path, 3, &img) == KPCN_OK);
  if (img) {
    int bad = 0, misnamed = 0;
    for (int c = 0; c < 5; c++) {
      const int p = kpcn_image_find_channel(img, ch[c].name);
      misnamed += p < 0;
      for (int y = 0; p >= 0 && y < h; y++)
        for (int x = 0; x < w; x++) {
          const float got = kpcn_image_plane(img, p)[(size_t)y * w + x];
          const float want = gen_value(&ch[c], c, x, y, NULL);
          /* bit for bit: -0 stays -0 */
          bad += memcmp(&got, &want, sizeof got) != 0;
          if (memcmp(&got, &want, sizeof got) != 0 && bad <= 3)
            fprintf(stderr, "  %s (%d,%d): %.9g, want %.9g\n", ch[c].name, x, y, got, want);
        }
    }
    CHECK(img->width == w && img->height == h && img->nchannels == 5);
    CHECK(misnamed == 0 && bad == 0);
    kpcn_image_destroy(img);
  }
  kpcn_aov_set *set = NULL;
  CHECK(kpcn_exr_read_aov(path, &set) == KPCN_OK);
  if (set) {
    const size_t P = (size_t)w * h;
    CHECK(set->buf[KPCN_BUF_COLOR] && set->buf[KPCN_BUF_DEPTH] && set->var[KPCN_BUF_DEPTH]);
    int bad = 0;
    for (int y = 0; set->buf[KPCN_BUF_COLOR] && set->buf[KPCN_BUF_DEPTH] && y < h; y++)
      for (int x = 0; x < w; x++) {
        const size_t i = (size_t)y * w + x;
        bad += set->buf[KPCN_BUF_COLOR][0 * P + i] != gen_value(&ch[2], 2, x, y, NULL); /* R */
        bad += set->buf[KPCN_BUF_COLOR][1 * P + i] != gen_value(&ch[1], 1, x, y, NULL); /* G */
        bad += set->buf[KPCN_BUF_COLOR][2 * P + i] != gen_value(&ch[0], 0, x, y, NULL); /* B */
        bad += set->buf[KPCN_BUF_DEPTH][i] != gen_value(&ch[3], 3, x, y, NULL);
        if (set->var[KPCN_BUF_DEPTH])
          bad += set->var[KPCN_BUF_DEPTH][i] != gen_value(&ch[4], 4, x, y, NULL);
      }
    CHECK(bad == 0);
    kpcn_aov_destroy(set);
  }
}

static void test_missing_and_garbage(void) {
  const char *nx = kt_tmpfile("does_not_exist.exr");
  kpcn_image *img = NULL;
  CHECK(kpcn_exr_read_image(nx, &img) == KPCN_ERR_IO);
  expect_read_fails(nx, "missing", 0);
  CHECK(kpcn_exr_read_image(kt_tmpdir(), &img) == KPCN_ERR_IO); /* a directory */
  CHECK(kpcn_exr_read_image("", &img) == KPCN_ERR_INVALID_ARGUMENT);
  CHECK(kpcn_exr_read_image(nx, NULL) == KPCN_ERR_INVALID_ARGUMENT);

  unsigned char junk[3000];
  unsigned st = 5;
  for (size_t i = 0; i < sizeof junk; i++)
    junk[i] = (unsigned char)(kt_randf(&st) * 256);
  const char *g = kt_tmpfile("garbage.exr");
  spit(g, junk, sizeof junk);
  CHECK(kpcn_exr_read_image(g, &img) == KPCN_ERR_FORMAT);
  expect_read_fails(g, "garbage", 0);
  /* a valid magic number followed by garbage */
  junk[0] = 0x76, junk[1] = 0x2f, junk[2] = 0x31, junk[3] = 0x01, junk[4] = 2, junk[5] = 0,
  junk[6] = 0, junk[7] = 0;
  spit(g, junk, sizeof junk);
  CHECK(kpcn_exr_read_image(g, &img) == KPCN_ERR_FORMAT);
  expect_read_fails(g, "magic+garbage", 0);
  const char *e = kt_tmpfile("empty.exr");
  spit(e, junk, 0);
  CHECK(kpcn_exr_read_image(e, &img) == KPCN_ERR_FORMAT);
  expect_read_fails(e, "empty", 0);
}

static void test_truncated(void) {
  const kpcn_exr_compression comps[] = {KPCN_EXR_ZIP, KPCN_EXR_NONE, KPCN_EXR_PIZ};
  for (int k = 0; k < 3; k++) {
    char name[64];
    snprintf(name, sizeof name, "valid%d.exr", k);
    const char *path = write_valid(name, 61, 45, comps[k]);
    long n = 0;
    unsigned char *b = (unsigned char *)kt_slurp(path, &n);
    CHECK(b != NULL && n > 1000);
    if (!b) continue;
    /* cut points: inside the header, half the file (the brief's case), one byte short */
    long cuts[] = {20, 200, n / 2, n - 100, n - 1};
    for (int c = 0; c < 5; c++) {
      char tn[64];
      snprintf(tn, sizeof tn, "trunc%d_%ld.exr", k, cuts[c]);
      const char *tp = kt_tmpfile(tn);
      spit(tp, b, cuts[c]);
      kpcn_image *img = NULL;
      kpcn_status s = kpcn_exr_read_image(tp, &img);
      CHECK(s == KPCN_ERR_FORMAT);
      if (s != KPCN_ERR_FORMAT)
        fprintf(stderr, "  cut at %ld of %ld (comp %d): status %d '%s'\n", cuts[c], n, k, s,
                kpcn_last_error());
      expect_read_fails(tp, tn, cuts[c] > 300);
      kpcn_image_destroy(img);
    }
    /* flipped bytes in the pixel data: either detected or decoded; never a crash */
    for (long i = n / 3; i < n / 3 + 64; i++)
      b[i] ^= 0x5a;
    const char *cp = kt_tmpfile("corrupt.exr");
    spit(cp, b, n);
    kpcn_image *img = NULL;
    kpcn_status s = kpcn_exr_read_image(cp, &img);
    CHECK(s == KPCN_OK || s == KPCN_ERR_FORMAT);
    if (s != KPCN_OK) CHECK(strstr(kpcn_last_error(), "corrupt.exr") != NULL);
    kpcn_image_destroy(img);
    free(b);
  }
}

/* Patches the dataWindow box of a valid file: absurd or empty windows must be rejected
 * before any allocation. */
static void test_absurd_header(void) {
  const char *path = write_valid("small.exr", 3, 2, KPCN_EXR_NONE);
  long n = 0;
  unsigned char *b = (unsigned char *)kt_slurp(path, &n);
  CHECK(b != NULL);
  if (!b) return;
  const char key[] = "dataWindow\0box2i"; /* name, NUL, type; then size (4) + 4 ints */
  long at = -1;
  for (long i = 0; i + (long)sizeof key < n && at < 0; i++)
    if (memcmp(b + i, key, sizeof key) == 0) at = i + (long)sizeof key + 4;
  CHECK(at > 0);
  if (at < 0) {
    free(b);
    return;
  }
  struct {
    int32_t box[4];
    const char *tag;
  } cases[] = {{{0, 0, 199999, 1}, "wide"},
               {{0, 0, 40000, 40000}, "huge"},
               {{0, 0, -5, 1}, "negative"},
               {{10, 10, 9, 9}, "empty"},
               {{-2147483647, 0, 2147483647, 0}, "overflow"}};
  for (size_t k = 0; k < sizeof cases / sizeof cases[0]; k++) {
    memcpy(b + at, cases[k].box, 16); /* little-endian host, as EXR */
    char tn[64];
    snprintf(tn, sizeof tn, "absurd_%s.exr", cases[k].tag);
    const char *tp = kt_tmpfile(tn);
    spit(tp, b, n);
    kpcn_image *img = NULL;
    kpcn_status s = kpcn_exr_read_image(tp, &img);
    CHECK(s == KPCN_ERR_FORMAT || s == KPCN_ERR_OUT_OF_MEMORY);
    if (!(s == KPCN_ERR_FORMAT || s == KPCN_ERR_OUT_OF_MEMORY))
      fprintf(stderr, "  %s: status %d '%s'\n", tn, s, kpcn_last_error());
    expect_read_fails(tp, tn, 0);
  }
  free(b);
  /* absurd sizes on the write side */
  kpcn_image fake = {KPCN_MAX_DIM + 1, 1, 1, NULL, NULL};
  char *nm[] = {"R"};
  float px = 0;
  fake.names = nm;
  fake.data = &px;
  CHECK(kpcn_exr_write_image(kt_tmpfile("w_absurd.exr"), &fake, NULL) == KPCN_ERR_OUT_OF_MEMORY);
  fake.width = 0;
  CHECK(kpcn_exr_write_image(kt_tmpfile("w_zero.exr"), &fake, NULL) == KPCN_ERR_INVALID_ARGUMENT);
  CHECK(file_size(kt_tmpfile("w_absurd.exr")) < 0 && file_size(kt_tmpfile("w_zero.exr")) < 0);
}

static void test_atomic_writes(void) {
  const char *names[] = {"R", "G", "B"};
  kpcn_image *img = NULL;
  kpcn_image_create(&img, 8, 8, 3, names);
  if (!img) return;
  /* into a directory that does not exist */
  char bad[600];
  snprintf(bad, sizeof bad, "%s/no/such/dir/out.exr", kt_tmpdir());
  CHECK(kpcn_exr_write_image(bad, img, NULL) == KPCN_ERR_IO);
  CHECK(strstr(kpcn_last_error(), "out.exr") != NULL);
  CHECK(kpcn_exr_write_image("/nonexistent_kpcn_dir/x.exr", img, NULL) == KPCN_ERR_IO);

  /* a failure after the temporary file was created (an attribute that clashes with a
   * required one) leaves the previous file untouched and no temporary file behind */
  const char *path = kt_tmpfile("keep.exr");
  CHECK(kpcn_exr_write_image(path, img, NULL) == KPCN_OK);
  long before = file_size(path);
  img->data[0] = 7.0f;
  kpcn_exr_write_options o = kpcn_exr_write_options_defaults();
  CHECK(kpcn_exr_options_add_int(&o, "dataWindow", 3) == KPCN_OK);
  kpcn_status s = kpcn_exr_write_image(path, img, &o);
  CHECK(s != KPCN_OK && strstr(kpcn_last_error(), "keep.exr"));
  CHECK(file_size(path) == before);
  kpcn_image *old = NULL;
  CHECK(kpcn_exr_read_image(path, &old) == KPCN_OK && old && old->data[0] == 0.0f);
  kpcn_image_destroy(old);
  CHECK(count_in_tmpdir(".tmp.") == 0);

  /* duplicate / empty channel names, bad options: nothing written */
  const char *dup[] = {"R", "G", "R"};
  kpcn_image *d = NULL;
  kpcn_image_create(&d, 2, 2, 3, dup);
  CHECK(kpcn_exr_write_image(kt_tmpfile("dup.exr"), d, NULL) == KPCN_ERR_INVALID_ARGUMENT);
  CHECK(strstr(kpcn_last_error(), "duplicate channel 'R'") != NULL);
  d->names[2][0] = 0;
  CHECK(kpcn_exr_write_image(kt_tmpfile("dup.exr"), d, NULL) == KPCN_ERR_INVALID_ARGUMENT);
  CHECK(file_size(kt_tmpfile("dup.exr")) < 0);
  o = kpcn_exr_write_options_defaults();
  o.compression = (kpcn_exr_compression)99;
  CHECK(kpcn_exr_write_image(kt_tmpfile("opt.exr"), img, &o) == KPCN_ERR_INVALID_ARGUMENT);
  CHECK(file_size(kt_tmpfile("opt.exr")) < 0);
  o = kpcn_exr_write_options_defaults();
  for (int i = 0; i < KPCN_EXR_MAX_ATTRS; i++) {
    char an[32];
    snprintf(an, sizeof an, "a%d", i);
    CHECK(kpcn_exr_options_add_int(&o, an, i) == KPCN_OK);
  }
  CHECK(kpcn_exr_options_add_int(&o, "one_too_many", 1) == KPCN_ERR_INVALID_ARGUMENT);
  /* a count outside [0, max] is refused, not used as an index (-1 wrote before the array) */
  o = kpcn_exr_write_options_defaults();
  o.nattrs = -1;
  CHECK(kpcn_exr_options_add_int(&o, "x", 1) == KPCN_ERR_INVALID_ARGUMENT &&
        strstr(kpcn_last_error(), "nattrs -1") != NULL);
  o.nattrs = KPCN_EXR_MAX_ATTRS + 1;
  CHECK(kpcn_exr_options_add_string(&o, "x", "y") == KPCN_ERR_INVALID_ARGUMENT);
  CHECK(kpcn_exr_write_image(kt_tmpfile("opt.exr"), img, &o) == KPCN_ERR_INVALID_ARGUMENT);
  CHECK(file_size(kt_tmpfile("opt.exr")) < 0);
  kpcn_aov_set *empty = NULL;
  kpcn_aov_create(&empty, 4, 4);
  CHECK(kpcn_exr_write_aov(kt_tmpfile("empty_aov.exr"), empty, NULL) == KPCN_ERR_MISSING_CHANNEL);
  CHECK(file_size(kt_tmpfile("empty_aov.exr")) < 0);
  CHECK(count_in_tmpdir(".tmp.") == 0);
  kpcn_aov_destroy(empty);
  kpcn_image_destroy(d);
  kpcn_image_destroy(img);
}

int main(void) {
  test_missing_and_garbage();
  test_truncated();
  test_absurd_header();
  test_atomic_writes();
  test_deep_and_subsampled();
  test_uint_and_half();
  return kt_summary("test_exr_errors");
}
