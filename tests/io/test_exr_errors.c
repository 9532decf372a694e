/* Bad input to the EXR reader/writer: missing, garbage, truncated and corrupted files, absurd
 * header sizes, failing writes (which must leave neither a partial file nor a temp file). */
#include "kpcn/exr.h"

#include "testutil.h"

#include <dirent.h>
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
  return kt_summary("test_exr_errors");
}
