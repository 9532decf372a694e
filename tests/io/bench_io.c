/* bench_io: EXR write/read throughput of a full AOV set (24 channels) at 1920x1080, float ZIP,
 * float NONE and half ZIP. Prints Mpixel/s (pixels of the AOV set, all channels). Not a test.
 * Usage: bench_io [width height [nthreads]] */
#include "kpcn/exr.h"

#include "testutil.h"

#include <stdlib.h>
#include <time.h>

static double now(void) {
  struct timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  return t.tv_sec + t.tv_nsec * 1e-9;
}

int main(int argc, char **argv) {
  int w = argc > 2 ? atoi(argv[1]) : 1920, h = argc > 2 ? atoi(argv[2]) : 1080;
  int nt = argc > 3 ? atoi(argv[3]) : 0;
  kpcn_aov_set *s = NULL;
  if (kpcn_aov_create(&s, w, h) != KPCN_OK) {
    fprintf(stderr, "bench_io: %s\n", kpcn_last_error());
    return 1;
  }
  unsigned st = 1;
  size_t n = kpcn_aov_plane_size(s);
  for (int b = 0; b < KPCN_BUF_COUNT; b++) {
    kpcn_aov_add(s, (kpcn_buffer)b, 1);
    /* smooth + noise, roughly like a render (pure noise would not compress) */
    for (size_t i = 0; i < n * kpcn_buffer_channels((kpcn_buffer)b); i++)
      s->buf[b][i] = (float)(i % w) / w + 0.05f * kt_randf(&st);
    for (size_t i = 0; i < n; i++)
      s->var[b][i] = 0.001f * kt_randf(&st);
  }
  struct {
    const char *name;
    kpcn_exr_compression c;
    kpcn_exr_pixel_type t;
  } cfg[] = {{"float zip", KPCN_EXR_ZIP, KPCN_EXR_FLOAT},
             {"float none", KPCN_EXR_NONE, KPCN_EXR_FLOAT},
             {"half zip", KPCN_EXR_ZIP, KPCN_EXR_HALF}};
  printf("bench_io: %dx%d AOV set, 24 channels, %d threads (timings on a shared machine are "
         "noisy)\n",
         w, h, kpcn_resolve_threads(nt));
  for (int k = 0; k < 3; k++) {
    kpcn_exr_write_options o = kpcn_exr_write_options_defaults();
    o.compression = cfg[k].c;
    o.pixel_type = cfg[k].t;
    o.nthreads = nt;
    const char *path = kt_tmpfile("bench.exr");
    double t0 = now();
    if (kpcn_exr_write_aov(path, s, &o) != KPCN_OK) {
      fprintf(stderr, "bench_io: %s\n", kpcn_last_error());
      return 1;
    }
    double t1 = now();
    kpcn_aov_set *r = NULL;
    if (kpcn_exr_read_aov_mt(path, nt, &r) != KPCN_OK) {
      fprintf(stderr, "bench_io: %s\n", kpcn_last_error());
      return 1;
    }
    double t2 = now();
    FILE *f = fopen(path, "rb");
    long sz = 0;
    if (f) {
      fseek(f, 0, SEEK_END);
      sz = ftell(f);
      fclose(f);
    }
    printf("  %-10s write %7.2f Mpix/s  read %7.2f Mpix/s  file %.1f MB\n", cfg[k].name,
           n / (t1 - t0) * 1e-6, n / (t2 - t1) * 1e-6, sz / 1e6);
    kpcn_aov_destroy(r);
    remove(path);
  }
  kpcn_aov_destroy(s);
  return 0;
}
