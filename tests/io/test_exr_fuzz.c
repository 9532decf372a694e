/* Mutation fuzzing of the EXR reader (deterministic seeds, a few hundred cases): byte flips,
 * random truncation and extreme integers written over the header. Every read must either
 * succeed or fail with a kpcn error naming the file -- never crash (run it under ASan/UBSan,
 * as .ci/run does). Usage: test_exr_fuzz [iterations-per-file] */
#include "kpcn/exr.h"

#include "testutil.h"

#include <stdlib.h>
#include <string.h>

static const char *make_seed(const char *name, kpcn_exr_compression comp, kpcn_exr_pixel_type pt) {
  const char *names[] = {"R", "G", "B", "N.X", "N.Y", "N.Z", "Z"};
  kpcn_image *img = NULL;
  kpcn_image_create(&img, 23, 37, 7, names);
  unsigned st = 3;
  for (size_t i = 0; i < 23 * 37 * 7; i++)
    img->data[i] = (float)(i % 23) * 0.1f + kt_randf(&st);
  kpcn_exr_write_options o = kpcn_exr_write_options_defaults();
  o.compression = comp;
  o.pixel_type = pt;
  const char *path = kt_tmpfile(name);
  CHECK(kpcn_exr_write_image(path, img, &o) == KPCN_OK);
  kpcn_image_destroy(img);
  return path;
}

static unsigned rnd(unsigned *s) {
  unsigned x = *s;
  x ^= x << 13;
  x ^= x >> 17;
  x ^= x << 5;
  return *s = x;
}

static void fuzz_file(const char *seed_path, int iters, unsigned seed, int *ok, int *err) {
  long n = 0;
  unsigned char *orig = (unsigned char *)kt_slurp(seed_path, &n);
  CHECK(orig != NULL);
  if (!orig) return;
  unsigned char *buf = malloc((size_t)n);
  const char *path = kt_tmpfile("fuzz_case.exr");
  const int extremes[] = {0, -1, 1, 0x7fffffff, (int)0x80000000, 65536, 65537, 16, 1 << 20};
  for (int it = 0; it < iters; it++) {
    memcpy(buf, orig, (size_t)n);
    long len = n;
    unsigned s = seed * 2654435761u + (unsigned)it * 40503u + 1;
    int mode = (int)(rnd(&s) % 4);
    if (mode == 0) { /* a few random byte flips anywhere */
      int k = 1 + (int)(rnd(&s) % 8);
      for (int j = 0; j < k; j++)
        buf[rnd(&s) % (unsigned)n] ^= (unsigned char)(1 + rnd(&s) % 255);
    } else if (mode == 1) { /* flips concentrated in the header / offset table */
      long hdr = n < 600 ? n : 600;
      int k = 1 + (int)(rnd(&s) % 4);
      for (int j = 0; j < k; j++)
        buf[rnd(&s) % (unsigned)hdr] ^= (unsigned char)(1 + rnd(&s) % 255);
    } else if (mode == 2) { /* random truncation */
      len = (long)(rnd(&s) % (unsigned)n);
    } else { /* an extreme 32-bit integer at a random 4-aligned header position */
      long hdr = (n < 600 ? n : 600) - 4;
      long at = (long)(rnd(&s) % (unsigned)(hdr / 4)) * 4;
      int v = extremes[rnd(&s) % (sizeof extremes / sizeof extremes[0])];
      memcpy(buf + at, &v, 4);
    }
    FILE *f = fopen(path, "wb");
    if (!f) break;
    fwrite(buf, 1, (size_t)len, f);
    fclose(f);
    kpcn_image *img = NULL;
    kpcn_status st = kpcn_exr_read_image(path, &img);
    if (st == KPCN_OK) {
      (*ok)++;
      CHECK(img && img->width > 0 && img->height > 0 && img->nchannels > 0);
    } else {
      (*err)++;
      CHECK(img == NULL && strstr(kpcn_last_error(), "fuzz_case.exr") != NULL);
      if (!strstr(kpcn_last_error(), "fuzz_case.exr"))
        fprintf(stderr, "  case %d mode %d: '%s'\n", it, mode, kpcn_last_error());
    }
    kpcn_image_destroy(img);
    kpcn_aov_set *set = NULL;
    st = kpcn_exr_read_aov(path, &set);
    CHECK(st == KPCN_OK || set == NULL);
    kpcn_aov_destroy(set);
    kpcn_exr_info_t info;
    kpcn_exr_info(path, &info);
  }
  free(buf);
  free(orig);
}

int main(int argc, char **argv) {
  int iters = argc > 1 ? atoi(argv[1]) : 40;
  int ok = 0, err = 0;
  fuzz_file(make_seed("seed_zip.exr", KPCN_EXR_ZIP, KPCN_EXR_FLOAT), iters, 1, &ok, &err);
  fuzz_file(make_seed("seed_piz.exr", KPCN_EXR_PIZ, KPCN_EXR_HALF), iters, 2, &ok, &err);
  fuzz_file(make_seed("seed_none.exr", KPCN_EXR_NONE, KPCN_EXR_FLOAT), iters, 3, &ok, &err);
  fuzz_file(make_seed("seed_rle.exr", KPCN_EXR_RLE, KPCN_EXR_HALF), iters, 4, &ok, &err);
  fuzz_file(KPCN_TESTDATA "/io/crop_tiled.exr", iters, 5, &ok, &err);
  printf("fuzz: %d cases read, %d rejected with an error\n", ok, err);
  CHECK(err > 0); /* the mutations do reach the error paths */
  return kt_summary("test_exr_fuzz");
}
