/* bench_metrics: Mpixel/s of SSIM and relMSE on a 3840x2160 RGB image (a figure, not a
 * test). Usage: bench_metrics [nthreads] (default 0 = all cores). */
#include "kpcn/metrics.h"

#include <omp.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>

int main(int argc, char **argv) {
  const int w = 3840, h = 2160, nch = 3;
  int nt = argc > 1 ? atoi(argv[1]) : 0;
  size_t n = (size_t)w * h * nch;
  float *x = malloc(n * sizeof(float)), *y = malloc(n * sizeof(float));
  float *map = malloc(n * sizeof(float));
  if (!x || !y || !map) return 1;
  unsigned s = 12345;
  for (size_t i = 0; i < n; ++i) {
    s = s * 1664525u + 1013904223u;
    y[i] = (float)((i / 7) % 97) / 97.0f;
    x[i] = y[i] + ((float)(s >> 8) * 0x1p-24f - 0.5f) * 0.1f;
  }
  kpcn_metric_options o;
  kpcn_metric_options_defaults(&o);
  o.nthreads = nt;
  const kpcn_metric ms[2] = {KPCN_METRIC_SSIM, KPCN_METRIC_RELMSE};
  printf("bench_metrics: %dx%d, %d channels, threads %d\n", w, h, nch, kpcn_resolve_threads(nt));
  for (int k = 0; k < 2; ++k)
    for (int withmap = 0; withmap < 2; ++withmap) {
      kpcn_metric_result r;
      double best = 1e30, cpu = 0;
      for (int rep = 0; rep < 3; ++rep) {
        clock_t c0 = clock();
        double t0 = omp_get_wtime();
        if (kpcn_metric_planar(ms[k], x, y, w, h, nch, &o, &r, withmap ? map : NULL) != KPCN_OK) {
          fprintf(stderr, "%s\n", kpcn_last_error());
          return 1;
        }
        double t = omp_get_wtime() - t0;
        if (t < best) best = t, cpu = (double)(clock() - c0) / CLOCKS_PER_SEC;
      }
      /* CPU seconds are less disturbed than wall time on a shared machine. */
      printf("%-7s %-10s %7.1f Mpixel/s wall (%.3f s)  %7.1f Mpixel per CPU-s  value %.6f\n",
             kpcn_metric_name(ms[k]), withmap ? "+errormap" : "", (double)w * h / best / 1e6, best,
             (double)w * h / cpu / 1e6, r.value);
    }
  free(x), free(y), free(map);
  return 0;
}
