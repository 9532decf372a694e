/* kpcn-render: renders a Tungsten scene.json into an AOV EXR (DESIGN.md §4).
 *   kpcn-render scene.json -o out.exr [--spp N] [--seed S] [--threads N] [--resolution WxH]
 *               [--crop x,y,w,h] [--color-only] [--max-bounces N] [--albedo-spp N] [--quiet]
 * A progress line (percent, samples/s, time left) is shown only when stderr is a terminal.
 * The output is written atomically; on any error nothing is written and the exit code is 1
 * (2 for usage errors). */
#include "kpcn/exr.h"
#include "kpcn/render.h"
#include "kpcn/scene.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

static void usage(FILE *f) {
  fprintf(
      f, "usage: kpcn-render scene.json -o out.exr [--spp N] [--seed S] [--threads N (0=all)]\n"
         "                   [--resolution WxH] [--crop x,y,w,h] [--color-only] [--max-bounces N]\n"
         "                   [--albedo-spp N] [--half] [--quiet]\n"
         "  --albedo-spp N   the albedo buffer from N >= spp camera samples of a features-only\n"
         "                   pass (less edge noise for the denoiser's remodulation)\n");
}

typedef struct progress_state {
  double t0;
  double samples_total;
} progress_state;

static double now_s(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static int on_progress(void *user, double f) {
  progress_state *p = user;
  double el = now_s() - p->t0;
  double rate = el > 0 ? f * p->samples_total / el : 0.0;
  double left = f > 0 ? el * (1.0 - f) / f : 0.0;
  fprintf(stderr, "\r%5.1f%%  %.2f M samples/s  %.0f s left   ", 100.0 * f, rate * 1e-6, left);
  fflush(stderr);
  return 0;
}

static int parse_int(const char *s, long lo, long hi, int *out) {
  char *end;
  long v = strtol(s, &end, 10);
  if (*s == 0 || *end != 0 || v < lo || v > hi) return 0;
  *out = (int)v;
  return 1;
}

int main(int argc, char **argv) {
  const char *scene_path = NULL, *out_path = NULL;
  kpcn_render_settings rs = kpcn_render_settings_defaults();
  int quiet = 0, half = 0;
  for (int i = 1; i < argc; i++) {
    const char *a = argv[i];
    const char *v = i + 1 < argc ? argv[i + 1] : NULL;
#define NEED_VALUE                                                                                 \
  if (!v) {                                                                                        \
    fprintf(stderr, "kpcn-render: %s needs a value\n", a);                                         \
    return 2;                                                                                      \
  }                                                                                                \
  i++;
    if (strcmp(a, "-o") == 0 || strcmp(a, "--output") == 0) {
      NEED_VALUE out_path = v;
    } else if (strcmp(a, "--spp") == 0) {
      NEED_VALUE if (!parse_int(v, 1, 1 << 24, &rs.spp)) {
        fprintf(stderr, "kpcn-render: --spp: expected an integer >= 1, got '%s'\n", v);
        return 2;
      }
    } else if (strcmp(a, "--seed") == 0) {
      NEED_VALUE char *end;
      long long s = strtoll(v, &end, 10);
      if (*v == 0 || *end != 0) {
        fprintf(stderr, "kpcn-render: --seed: expected an integer, got '%s'\n", v);
        return 2;
      }
      rs.seed = s;
    } else if (strcmp(a, "--threads") == 0) {
      NEED_VALUE if (!parse_int(v, 0, 4096, &rs.nthreads)) {
        fprintf(stderr, "kpcn-render: --threads: expected an integer >= 0, got '%s'\n", v);
        return 2;
      }
    } else if (strcmp(a, "--albedo-spp") == 0) {
      NEED_VALUE if (!parse_int(v, 1, 1 << 24, &rs.albedo_spp)) {
        fprintf(stderr, "kpcn-render: --albedo-spp: expected an integer >= 1, got '%s'\n", v);
        return 2;
      }
    } else if (strcmp(a, "--max-bounces") == 0) {
      NEED_VALUE if (!parse_int(v, 0, 100000, &rs.max_bounces)) {
        fprintf(stderr, "kpcn-render: --max-bounces: expected an integer >= 0, got '%s'\n", v);
        return 2;
      }
    } else if (strcmp(a, "--resolution") == 0) {
      NEED_VALUE char extra;
      if (sscanf(v, "%dx%d%c", &rs.width, &rs.height, &extra) != 2 || rs.width <= 0 ||
          rs.height <= 0) {
        fprintf(stderr, "kpcn-render: --resolution: expected WxH, got '%s'\n", v);
        return 2;
      }
    } else if (strcmp(a, "--crop") == 0) {
      NEED_VALUE char extra;
      if (sscanf(v, "%d,%d,%d,%d%c", &rs.crop_x, &rs.crop_y, &rs.crop_w, &rs.crop_h, &extra) != 4 ||
          rs.crop_w <= 0 || rs.crop_h <= 0) {
        fprintf(stderr, "kpcn-render: --crop: expected x,y,w,h, got '%s'\n", v);
        return 2;
      }
    } else if (strcmp(a, "--color-only") == 0) {
      rs.color_only = 1;
    } else if (strcmp(a, "--half") == 0) {
      half = 1;
    } else if (strcmp(a, "--quiet") == 0 || strcmp(a, "-q") == 0) {
      quiet = 1;
    } else if (strcmp(a, "-h") == 0 || strcmp(a, "--help") == 0) {
      usage(stdout);
      return 0;
    } else if (a[0] == '-') {
      fprintf(stderr, "kpcn-render: unknown option '%s'\n", a);
      usage(stderr);
      return 2;
    } else if (!scene_path) {
      scene_path = a;
    } else {
      fprintf(stderr, "kpcn-render: unexpected argument '%s'\n", a);
      return 2;
    }
  }
  if (!scene_path || !out_path) {
    usage(stderr);
    return 2;
  }
  kpcn_scene *scene = NULL;
  if (kpcn_scene_load(scene_path, &scene) != KPCN_OK) {
    fprintf(stderr, "kpcn-render: %s\n", kpcn_last_error());
    return 1;
  }
  kpcn_scene_info info;
  kpcn_scene_get_info(scene, &info);
  progress_state ps;
  int w = rs.width > 0 ? rs.width : info.width, h = rs.height > 0 ? rs.height : info.height;
  if (rs.crop_w > 0) w = rs.crop_w, h = rs.crop_h;
  ps.samples_total = (double)w * h * (rs.spp > 0 ? rs.spp : info.spp);
  ps.t0 = now_s();
  if (!quiet && isatty(2)) {
    rs.progress = on_progress;
    rs.progress_user = &ps;
  }
  kpcn_aov_set *aov = NULL;
  kpcn_render_stats stats;
  kpcn_status st = kpcn_render_ex(scene, &rs, &aov, &stats);
  if (rs.progress) fprintf(stderr, "\n");
  kpcn_scene_destroy(scene);
  if (st != KPCN_OK) {
    fprintf(stderr, "kpcn-render: %s\n", kpcn_last_error());
    return 1;
  }
  kpcn_exr_write_options opt = kpcn_exr_write_options_defaults();
  if (half) opt.pixel_type = KPCN_EXR_HALF;
  st = kpcn_exr_write_aov(out_path, aov, &opt);
  kpcn_aov_destroy(aov);
  if (st != KPCN_OK) {
    fprintf(stderr, "kpcn-render: %s\n", kpcn_last_error());
    return 1;
  }
  if (!quiet && isatty(2))
    fprintf(stderr, "%s: %dx%d, %.2f s, %.2f M samples/s, %.1f M rays/s\n", out_path, w, h,
            stats.seconds, stats.samples / stats.seconds * 1e-6, stats.rays / stats.seconds * 1e-6);
  return 0;
}
