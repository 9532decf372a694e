/* kpcn-render: renders a Tungsten scene.json into an AOV EXR (DESIGN.md §4).
 *   kpcn-render scene.json -o out.exr [--spp N] [--seed S] [--threads N] [--resolution WxH]
 *               [--crop x,y,w,h] [--color-only] [--max-bounces N] [--albedo-spp N]
 *               [--half] [--quiet] [--checkpoint PATH [--checkpoint-every S]
 *               [--time-limit M]]
 * A progress line (percent, samples/s, time left) is shown only when stderr is a terminal.
 * The output is written atomically; on any error nothing is written and the exit code is 1
 * (2 for usage errors). SIGINT/SIGTERM stop the render at the next row and exit 128 + the
 * signal with no output; with --checkpoint the finished rows are saved there first, and
 * --time-limit stops the same way after M minutes (exit 3); the same command resumes, and the
 * file is removed once the output is written. A signal never interrupts a file being written
 * (a checkpoint save or the output): it takes effect once the file is in place, so no
 * temporary file is left behind. */
#include "cli_parse.h"
#include "kpcn/exr.h"
#include "kpcn/render.h"
#include "kpcn/scene.h"

#include <errno.h>
#include <signal.h>
#include <stdint.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

static void usage(FILE *f) {
  fprintf(
      f,
      "usage: kpcn-render scene.json -o out.exr [--spp N] [--seed S] [--threads N (0=all)]\n"
      "                   [--resolution WxH] [--crop x,y,w,h] [--color-only] [--max-bounces N]\n"
      "                   [--albedo-spp N] [--albedo-footprint K] [--half] [--quiet]\n"
      "                   [--compression zip|zips|piz|rle|none]\n"
      "                   [--checkpoint PATH [--checkpoint-every S] [--time-limit M]]\n"
      "  --albedo-spp N   the albedo buffer from N >= spp camera samples of a features-only\n"
      "                   pass (less edge noise for the denoiser's remodulation)\n"
      "  --albedo-footprint K  each sample's textured albedo averaged over K x K points of\n"
      "                   its pixel's footprint (texture lookups, no rays; 1 = off)\n"
      "  --compression C  the EXR's compression (default zip: a 960x540 living-room render\n"
      "                   at 4 spp is 14 MB, 50 MB with none, which writes 0.3 s faster)\n"
      "  --checkpoint PATH  save finished rows there every S seconds (default 60) and on\n"
      "                   SIGINT/SIGTERM; the same command resumes from it (bit-identical)\n"
      "                   and removes it once the output is written\n"
      "  --time-limit M   with --checkpoint: stop after M minutes (at the next finished row;\n"
      "                   0 = after the first), save the rows and exit 3 without an output,\n"
      "                   so a long render can be split across runs of the same command\n"
      "  --version        the versions and the instruction set (avx512 or avx2) in use: renders\n"
      "                   are bit-identical for a seed only on one of the two\n");
}

typedef struct progress_state {
  int show; /* a terminal, not --quiet */
  double t0;
  double limit_s; /* --time-limit in seconds; < 0 for none */
  double f0;      /* the fraction done when this call started (a resumed render), < 0 until known */
  double row;
  double samples_total;
} progress_state;

static volatile sig_atomic_t g_signal = 0;
static void on_signal(int sig) { g_signal = sig; }

static double now_s(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* Also how a signal reaches the render: a non-zero return cancels it (and saves its rows). */
static int on_progress(void *user, double f) {
  progress_state *p = user;
  if (p->f0 < 0) p->f0 = f - p->row > 0 ? f - p->row : 0; /* the first call follows one row */
  if (p->show) {
    double el = now_s() - p->t0, df = f - p->f0;
    double rate = el > 0 ? df * p->samples_total / el : 0.0;
    double left = df > 0 ? el * (1.0 - f) / df : 0.0;
    fprintf(stderr, "\r%5.1f%%  %.2f M samples/s  %.0f s left   ", 100.0 * f, rate * 1e-6, left);
    fflush(stderr);
  }
  return g_signal != 0 || (p->limit_s >= 0 && now_s() - p->t0 >= p->limit_s);
}

/* Folds a file's bytes into the FNV-1a hash *h; 0 if it cannot be read. */
static int hash_file(const char *path, uint64_t *h) {
  FILE *f = kpcn_fopen_input(path, NULL);
  if (!f) return 0;
  unsigned char buf[65536];
  size_t n;
  while ((n = fread(buf, 1, sizeof buf, f)) > 0)
    for (size_t i = 0; i < n; i++)
      *h = (*h ^ buf[i]) * 0x100000001b3ull;
  int ok = !ferror(f);
  fclose(f);
  return ok;
}

/* Calls fn(path, user) for every file the scene names: any string in its JSON that is a regular
 * file, absolute or next to it (meshes, textures, environment maps). 0 if the scene cannot be
 * read or fn returns 0. */
static int for_each_named_file(const char *scene_path, int (*fn)(const char *, void *),
                               void *user) {
  size_t n = 0;
  FILE *f = fopen(scene_path, "rb");
  if (!f) return 0;
  fseek(f, 0, SEEK_END);
  long len = ftell(f);
  fseek(f, 0, SEEK_SET);
  char *text = len >= 0 && len < (1L << 30) ? malloc((size_t)len + 1) : NULL;
  int ok = text && fread(text, 1, (size_t)len, f) == (size_t)len;
  fclose(f);
  if (!ok) {
    free(text);
    return 0;
  }
  n = (size_t)len;
  text[n] = 0;
  const char *slash = strrchr(scene_path, '/');
  const int dirlen = slash ? (int)(slash - scene_path) : 1;
  const char *dir = slash ? scene_path : ".";
  for (char *q = strchr(text, '"'); q && ok; q = strchr(q + 1, '"')) {
    char *end = strchr(q + 1, '"');
    if (!end) break;
    char path[8192];
    const int plen = (int)(end - q - 1);
    if (plen > 0 && plen < 4096) {
      if (q[1] == '/')
        snprintf(path, sizeof path, "%.*s", plen, q + 1);
      else
        snprintf(path, sizeof path, "%.*s/%.*s", dirlen, dir, plen, q + 1);
      struct stat sb;
      if (stat(path, &sb) == 0 && S_ISREG(sb.st_mode)) ok = fn(path, user);
    }
    q = end; /* the closing quote is not the next string's opening one */
  }
  free(text);
  return ok;
}

static int hash_named(const char *path, void *h) { return hash_file(path, h); }

/* The scene's identity in a checkpoint: the scene file's bytes and those of every file it
 * names, so that a scene or texture edited between a stop and a resume is refused instead of
 * mixed into one image. */
static int scene_key(const char *scene_path, uint64_t *out) {
  uint64_t h = 0xcbf29ce484222325ull;
  if (!hash_file(scene_path, &h) || !for_each_named_file(scene_path, hash_named, &h)) return 0;
  *out = h;
  return 1;
}

/* An output (-o, --checkpoint) that is a file the scene reads, a texture or an environment map,
 * was written over it (session 60); the scene file itself was already refused. */
typedef struct output_check {
  const char *path, *what, *named; /* named: the scene's file it is, when found */
} output_check;
static int not_named(const char *path, void *user) {
  output_check *c = user;
  if (!kpcn_same_file(c->path, path)) return 1;
  c->named = path;
  return 0;
}
static int output_clashes(const char *scene_path, const char *out, const char *what) {
  output_check c = {out, what, NULL};
  if (for_each_named_file(scene_path, not_named, &c) || !c.named) return 0;
  fprintf(stderr, "kpcn-render: %s '%s' is '%s', a file the scene reads\n", what, out, c.named);
  return 1;
}

int main(int argc, char **argv) {
  const char *scene_path = NULL, *out_path = NULL;
  kpcn_render_settings rs = kpcn_render_settings_defaults();
  int quiet = 0, half = 0;
  kpcn_exr_compression compression = KPCN_EXR_ZIP;
  double time_limit_min = -1.0;
  int every_given = 0;
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
      NEED_VALUE if (!cli_parse_int(v, 1, 1 << 24, &rs.spp)) {
        fprintf(stderr, "kpcn-render: --spp: expected an integer in [1, %d], got '%s'\n", 1 << 24,
                v);
        return 2;
      }
    } else if (strcmp(a, "--seed") == 0) {
      /* 0 .. 2^63-1: what kpcn_render accepts and the EXR header records as kpcn:seed; an
       * out-of-range value is an error, not strtoll's silent clamp to the limit */
      NEED_VALUE char *end;
      errno = 0;
      long long s = strtoll(v, &end, 10);
      if (*v < '0' || *v > '9' || *end != 0 || errno == ERANGE) {
        fprintf(stderr, "kpcn-render: --seed: expected an integer in [0, 2^63-1], got '%s'\n", v);
        return 2;
      }
      rs.seed = s;
    } else if (strcmp(a, "--threads") == 0) {
      NEED_VALUE if (!cli_parse_int(v, 0, KPCN_MAX_THREADS, &rs.nthreads)) {
        fprintf(stderr, "kpcn-render: --threads: expected an integer in [0, %d], got '%s'\n",
                KPCN_MAX_THREADS, v);
        return 2;
      }
    } else if (strcmp(a, "--albedo-spp") == 0) {
      NEED_VALUE if (!cli_parse_int(v, 1, 1 << 24, &rs.albedo_spp)) {
        fprintf(stderr, "kpcn-render: --albedo-spp: expected an integer in [1, %d], got '%s'\n",
                1 << 24, v);
        return 2;
      }
    } else if (strcmp(a, "--albedo-footprint") == 0) {
      NEED_VALUE if (!cli_parse_int(v, 1, 16, &rs.albedo_footprint)) {
        fprintf(stderr,
                "kpcn-render: --albedo-footprint: expected an integer in [1, 16], got '%s'\n", v);
        return 2;
      }
    } else if (strcmp(a, "--max-bounces") == 0) {
      NEED_VALUE if (!cli_parse_int(v, 0, 100000, &rs.max_bounces)) {
        fprintf(stderr,
                "kpcn-render: --max-bounces: expected an integer in [0, 100000], got '%s'\n", v);
        return 2;
      }
    } else if (strcmp(a, "--resolution") == 0) {
      NEED_VALUE static const long lo[2] = {1, 1}, hi[2] = {KPCN_MAX_DIM, KPCN_MAX_DIM};
      int wh[2];
      if (!cli_parse_int_list(v, 'x', 2, lo, hi, wh)) {
        fprintf(stderr, "kpcn-render: --resolution: expected WxH with W, H in [1, %d], got '%s'\n",
                KPCN_MAX_DIM, v);
        return 2;
      }
      rs.width = wh[0], rs.height = wh[1];
    } else if (strcmp(a, "--crop") == 0) {
      NEED_VALUE static const long lo[4] = {0, 0, 1, 1},
                                   hi[4] = {KPCN_MAX_DIM - 1, KPCN_MAX_DIM - 1, KPCN_MAX_DIM,
                                            KPCN_MAX_DIM};
      int c4[4];
      if (!cli_parse_int_list(v, ',', 4, lo, hi, c4)) {
        fprintf(stderr,
                "kpcn-render: --crop: expected x,y,w,h with x, y in [0, %d) and w, h in [1, %d], "
                "got '%s'\n",
                KPCN_MAX_DIM, KPCN_MAX_DIM, v);
        return 2;
      }
      rs.crop_x = c4[0], rs.crop_y = c4[1], rs.crop_w = c4[2], rs.crop_h = c4[3];
    } else if (strcmp(a, "--checkpoint") == 0) {
      NEED_VALUE rs.checkpoint = v;
    } else if (strcmp(a, "--checkpoint-every") == 0) {
      NEED_VALUE double sec;
      if (!cli_parse_double(v, &sec) || !(sec >= 0 && sec <= 1e9)) {
        fprintf(stderr, "kpcn-render: --checkpoint-every: expected seconds in [0, 1e9], got '%s'\n",
                v);
        return 2;
      }
      rs.checkpoint_every_s = sec;
      every_given = 1;
    } else if (strcmp(a, "--time-limit") == 0) {
      NEED_VALUE if (!cli_parse_double(v, &time_limit_min) ||
                     !(time_limit_min >= 0 && time_limit_min <= 1e9)) {
        fprintf(stderr, "kpcn-render: --time-limit: expected minutes in [0, 1e9], got '%s'\n", v);
        return 2;
      }
    } else if (strcmp(a, "--color-only") == 0) {
      rs.color_only = 1;
    } else if (strcmp(a, "--half") == 0) {
      half = 1;
    } else if (strcmp(a, "--compression") == 0) {
      NEED_VALUE if (kpcn_exr_compression_parse(v, &compression) != KPCN_OK) {
        fprintf(stderr, "kpcn-render: --%s\n", kpcn_last_error());
        return 2;
      }
    } else if (strcmp(a, "--quiet") == 0 || strcmp(a, "-q") == 0) {
      quiet = 1;
    } else if (strcmp(a, "-h") == 0 || strcmp(a, "--help") == 0) {
      usage(stdout);
      return 0;
    } else if (strcmp(a, "--version") == 0) {
      printf("kpcn-render %s\n%s\n", KPCN_VERSION_STRING, kpcn_build_info());
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
  if (every_given && !rs.checkpoint) { /* it would be ignored */
    fprintf(stderr, "kpcn-render: --checkpoint-every needs --checkpoint (where the rows are "
                    "saved)\n");
    return 2;
  }
  if (time_limit_min >= 0 && !rs.checkpoint) {
    fprintf(stderr, "kpcn-render: --time-limit needs --checkpoint (the rows it stops with are "
                    "kept there)\n");
    return 2;
  }
  if (kpcn_check_extension(out_path, ".exr", "-o", "OpenEXR") != KPCN_OK) {
    fprintf(stderr, "kpcn-render: %s\n", kpcn_last_error());
    return 2;
  }
  if (kpcn_same_file(out_path, scene_path)) {
    fprintf(stderr, "kpcn-render: -o '%s' is the scene file\n", out_path);
    return 2;
  }
  if (output_clashes(scene_path, out_path, "-o") ||
      (rs.checkpoint && output_clashes(scene_path, rs.checkpoint, "--checkpoint")))
    return 2;
  /* before rendering: a device, FIFO, directory or missing folder is refused now, not after */
  if (kpcn_check_output_path(out_path, "-o") != KPCN_OK ||
      (rs.checkpoint && kpcn_check_output_path(rs.checkpoint, "--checkpoint") != KPCN_OK)) {
    fprintf(stderr, "kpcn-render: %s\n", kpcn_last_error());
    return 2;
  }
  if (rs.checkpoint &&
      (kpcn_same_file(rs.checkpoint, out_path) || kpcn_same_file(rs.checkpoint, scene_path))) {
    fprintf(stderr, "kpcn-render: --checkpoint '%s' is the %s\n", rs.checkpoint,
            kpcn_same_file(rs.checkpoint, out_path) ? "output" : "scene file");
    return 2;
  }
  if (rs.checkpoint && !scene_key(scene_path, &rs.scene_key)) {
    fprintf(stderr, "kpcn-render: cannot read '%s' or a file it names: %s\n", scene_path,
            strerror(errno));
    return 1;
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
  ps.f0 = -1.0;
  ps.limit_s = time_limit_min >= 0 ? 60.0 * time_limit_min : -1.0;
  ps.row = 1.0 / h;
  ps.show = !quiet && isatty(2);
  /* A signal stops the render at the next row (saving the rows with --checkpoint). It only
   * sets a flag: the default action killed the process in the middle of writing the output or
   * a checkpoint save and left the temporary file (session 60), and so did a second signal
   * while the first one's save was under way. */
  rs.progress = on_progress;
  rs.progress_user = &ps;
  struct sigaction sa;
  memset(&sa, 0, sizeof sa);
  sa.sa_handler = on_signal;
  sigaction(SIGINT, &sa, NULL);
  sigaction(SIGTERM, &sa, NULL);
  kpcn_aov_set *aov = NULL;
  kpcn_render_stats stats = {0};
  kpcn_status st = kpcn_render_ex(scene, &rs, &aov, &stats);
  if (ps.show) fprintf(stderr, "\n");
  kpcn_scene_destroy(scene);
  /* also with --quiet: a job's log (kpcn-dataset run) should say that it resumed, also when
   * this run is stopped again */
  if (stats.rows_resumed)
    fprintf(stderr, "kpcn-render: resumed %d of %d rows from '%s'\n", stats.rows_resumed, h,
            rs.checkpoint);
  if (st == KPCN_ERR_CANCELLED && g_signal) {
    if (rs.checkpoint)
      fprintf(stderr,
              "kpcn-render: stopped by signal %d; finished rows saved in '%s' (the same "
              "command resumes)\n",
              (int)g_signal, rs.checkpoint);
    else
      fprintf(stderr, "kpcn-render: stopped by signal %d; nothing written\n", (int)g_signal);
    return 128 + g_signal;
  }
  if (st == KPCN_ERR_CANCELLED) { /* the time limit */
    fprintf(stderr,
            "kpcn-render: stopped by --time-limit; finished rows saved in '%s' (the same command "
            "resumes)\n",
            rs.checkpoint);
    return 3;
  }
  if (st != KPCN_OK) {
    fprintf(stderr, "kpcn-render: %s\n", kpcn_last_error());
    return 1;
  }
  if (stats.checkpoint_errors)
    fprintf(stderr, "kpcn-render: warning: %d checkpoint save(s) to '%s' failed\n",
            stats.checkpoint_errors, rs.checkpoint);
  /* not silent: these pixels are darker than the scene says (kpcn_render_stats) */
  if (stats.nonfinite_samples)
    fprintf(stderr,
            "kpcn-render: warning: %llu samples had a non-finite value (radiance beyond float "
            "range) and count as black\n",
            (unsigned long long)stats.nonfinite_samples);
  /* half holds at most 65504: beyond it the file would say Inf, where a float render says
   * a large value (a bright light's colour variance). Saturated instead, and said. */
  if (half) {
    const size_t plane = (size_t)aov->width * (size_t)aov->height;
    uint64_t saturated = 0;
    for (int b = 0; b < KPCN_BUF_COUNT; b++) {
      const size_t n[2] = {aov->buf[b] ? plane * (size_t)kpcn_buffer_channels(b) : 0,
                           aov->var[b] ? plane : 0};
      float *p[2] = {aov->buf[b], aov->var[b]};
      for (int k = 0; k < 2; k++)
        for (size_t i = 0; i < n[k]; i++)
          if (fabsf(p[k][i]) > 65504.0f) p[k][i] = copysignf(65504.0f, p[k][i]), saturated++;
    }
    if (saturated)
      fprintf(stderr,
              "kpcn-render: warning: %llu values beyond half's range were stored as +-65504 "
              "(write float, without --half, to keep them)\n",
              (unsigned long long)saturated);
  }
  kpcn_exr_write_options opt = kpcn_exr_write_options_defaults();
  if (half) opt.pixel_type = KPCN_EXR_HALF;
  opt.compression = compression;
  opt.nthreads = rs.nthreads; /* --threads bounds the writer's compression threads too */
  st = kpcn_exr_write_aov(out_path, aov, &opt);
  kpcn_aov_destroy(aov);
  if (st != KPCN_OK) {
    fprintf(stderr, "kpcn-render: %s\n", kpcn_last_error());
    return 1;
  }
  /* a signal that came while the output was written: the render was complete, and so is the
   * file, which stays; the exit status still says a signal stopped the command */
  if (g_signal) {
    if (rs.checkpoint) remove(rs.checkpoint);
    fprintf(stderr,
            "kpcn-render: signal %d arrived while '%s' was written; the output is complete\n",
            (int)g_signal, out_path);
    return 128 + g_signal;
  }
  if (rs.checkpoint && remove(rs.checkpoint) != 0 && errno != ENOENT)
    fprintf(stderr, "kpcn-render: warning: cannot remove checkpoint '%s': %s\n", rs.checkpoint,
            strerror(errno));
  if (!quiet && isatty(2))
    fprintf(stderr, "%s: %dx%d, %.2f s, %.2f M samples/s, %.1f M rays/s\n", out_path, w, h,
            stats.seconds, stats.samples / stats.seconds * 1e-6, stats.rays / stats.seconds * 1e-6);
  return 0;
}
