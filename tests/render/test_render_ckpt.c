/* Render checkpoints (kpcn_render_settings.checkpoint, kpcn-render --checkpoint):
 *  - a render cancelled part-way and resumed, at another thread count, is bit-identical to an
 *    uninterrupted one, and reports what it resumed and traced;
 *  - a checkpoint of another render (spp, scene key) is refused naming the difference; a
 *    damaged, truncated or foreign file is refused; nothing is rendered either way;
 *  - periodic saves, a bad interval and an unwritable path;
 *  - kpcn-render: SIGINT saves the rows and exits 130; the same command resumes (saying so)
 *    to the pixels of a render never interrupted, and removes the checkpoint; a texture
 *    edited in between is refused; a checkpoint path that is the output or the scene is a
 *    usage error. */
#define _GNU_SOURCE
#include "render_testutil.h"
#include "testutil.h"

#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

extern char **environ;

#define CORNELL KPCN_TESTDATA "/scenes/cornell-box/scene.json"
#define RENDER_BIN KPCN_BINARY_DIR "/tools/kpcn-render/kpcn-render"
enum { W = 48, H = 40, SPP = 16 };

static int sets_equal(const kpcn_aov_set *a, const kpcn_aov_set *b) {
  if (!a || !b || a->width != b->width || a->height != b->height) return 0;
  const size_t plane = kpcn_aov_plane_size(a);
  for (int k = 0; k < KPCN_BUF_COUNT; k++) {
    const size_t n = plane * (size_t)kpcn_buffer_channels((kpcn_buffer)k);
    if (!a->buf[k] != !b->buf[k] || !a->var[k] != !b->var[k]) return 0;
    if (a->buf[k] && memcmp(a->buf[k], b->buf[k], n * sizeof(float))) return 0;
    if (a->var[k] && memcmp(a->var[k], b->var[k], plane * sizeof(float))) return 0;
  }
  return 1;
}

static kpcn_render_settings settings(int threads, const char *ckpt) {
  kpcn_render_settings rs = kpcn_render_settings_defaults();
  rs.spp = SPP, rs.seed = 7, rs.nthreads = threads, rs.width = W, rs.height = H;
  rs.checkpoint = ckpt;
  rs.checkpoint_every_s = 0;
  rs.scene_key = 0x1234;
  return rs;
}

static int cancel_after(void *user, double f) {
  (void)f;
  return --*(int *)user <= 0;
}

static int file_exists(const char *p) {
  struct stat sb;
  return stat(p, &sb) == 0;
}

static void corrupt(const char *src, const char *dst, long at, long keep) {
  FILE *f = fopen(src, "rb");
  CHECK(f != NULL);
  if (!f) return;
  fseek(f, 0, SEEK_END);
  long n = ftell(f);
  fseek(f, 0, SEEK_SET);
  unsigned char *b = malloc((size_t)n);
  CHECK(fread(b, 1, (size_t)n, f) == (size_t)n);
  fclose(f);
  if (at >= 0 && at < n) b[at] ^= 0x40;
  FILE *g = fopen(dst, "wb");
  fwrite(b, 1, (size_t)(keep >= 0 && keep < n ? keep : n), g);
  fclose(g);
  free(b);
}

/* Renders with rs; *st gets the status; the set on success. */
static kpcn_aov_set *render(const kpcn_scene *s, const kpcn_render_settings *rs, kpcn_status *st,
                            kpcn_render_stats *stats) {
  kpcn_aov_set *out = (kpcn_aov_set *)1;
  *st = kpcn_render_ex(s, rs, &out, stats);
  if (*st != KPCN_OK) CHECK(out == NULL);
  return *st == KPCN_OK ? out : NULL;
}

static void test_library(const kpcn_scene *s) {
  kpcn_status st;
  kpcn_render_stats full_stats, stats;
  kpcn_render_settings rs = settings(2, NULL);
  kpcn_aov_set *full = render(s, &rs, &st, &full_stats);
  CHECK(full != NULL);
  remove("c.ckpt");

  /* cancelled after 10 rows (one thread: rows 0-9), then resumed with two threads */
  rs = settings(1, "c.ckpt");
  int calls = 10;
  rs.progress = cancel_after, rs.progress_user = &calls;
  CHECK(render(s, &rs, &st, NULL) == NULL && st == KPCN_ERR_CANCELLED);
  CHECK(strstr(kpcn_last_error(), "checkpoint") != NULL);
  CHECK(file_exists("c.ckpt"));
  /* resumed, then cancelled again: the cancel's stats say what was resumed (kpcn-render's log
   * line "resumed N of H rows" reads them; they were left unwritten, so garbage) */
  memset(&stats, 0xA5, sizeof stats);
  rs = settings(1, "c.ckpt");
  calls = 1;
  rs.progress = cancel_after, rs.progress_user = &calls;
  CHECK(render(s, &rs, &st, &stats) == NULL && st == KPCN_ERR_CANCELLED);
  CHECK(stats.rows_resumed == 10 && stats.checkpoint_errors == 0 && stats.samples == 0 &&
        stats.rays == 0 && stats.seconds >= 0.0 && stats.seconds < 1e6);
  memset(&stats, 0xA5, sizeof stats); /* an error return leaves them zero */
  kpcn_aov_set *none = NULL;
  CHECK(kpcn_render_ex(NULL, &rs, &none, &stats) == KPCN_ERR_INVALID_ARGUMENT && !none);
  CHECK(stats.rows_resumed == 0 && stats.samples == 0 && stats.seconds == 0.0);
  rs = settings(2, "c.ckpt");
  kpcn_aov_set *resumed = render(s, &rs, &st, &stats);
  CHECK(resumed != NULL && sets_equal(full, resumed));
  CHECK(stats.rows_resumed == 11);
  CHECK(stats.samples == (uint64_t)(H - 11) * W * SPP);
  CHECK(stats.rays > 0 && stats.rays < full_stats.rays);
  CHECK(stats.nonfinite_samples == full_stats.nonfinite_samples);
  CHECK(file_exists("c.ckpt")); /* the caller removes it once the result is safe */
  kpcn_aov_destroy(resumed);

  /* another render's checkpoint: refused, naming the difference */
  rs = settings(2, "c.ckpt");
  rs.spp = SPP / 2;
  CHECK(render(s, &rs, &st, NULL) == NULL && st == KPCN_ERR_INVALID_ARGUMENT);
  CHECK(strstr(kpcn_last_error(), "its spp is 16, this render's is 8") != NULL);
  rs = settings(2, "c.ckpt");
  rs.scene_key = 99;
  CHECK(render(s, &rs, &st, NULL) == NULL && strstr(kpcn_last_error(), "its scene_key is") != NULL);
  rs = settings(2, "c.ckpt");
  rs.albedo_footprint = 2;
  CHECK(render(s, &rs, &st, NULL) == NULL &&
        strstr(kpcn_last_error(), "its albedo_footprint is 0") != NULL);
  /* every other setting that changes a pixel (renderer.md, "Checkpoints"): each refused by
   * its name, so no render mixes its rows with another's */
  for (int k = 0; k < 7; k++) {
    static const char *const field[7] = {"seed",       "resolution",  "crop",  "albedo_spp",
                                         "color_only", "max_bounces", "lights"};
    rs = settings(2, "c.ckpt");
    switch (k) {
    case 0: rs.seed = 8; break;
    case 1: rs.width = W + 2; break;
    case 2: rs.crop_x = 0, rs.crop_y = 0, rs.crop_w = W, rs.crop_h = H - 1; break;
    case 3: rs.albedo_spp = 2 * SPP; break;
    case 4: rs.color_only = 1; break;
    case 5: rs.max_bounces = 1; break;
    default: rs.lights = KPCN_LIGHTS_NEE_ONLY; break;
    }
    char want[64];
    snprintf(want, sizeof want, "its %s is", field[k]);
    CHECK(render(s, &rs, &st, NULL) == NULL && st == KPCN_ERR_INVALID_ARGUMENT);
    if (!strstr(kpcn_last_error(), want)) fprintf(stderr, "%s: %s\n", field[k], kpcn_last_error());
    CHECK(strstr(kpcn_last_error(), want) != NULL);
  }

  /* damaged files: a flipped pixel bit, a truncation, something else entirely */
  static const struct {
    long at, keep;
    const char *msg;
  } bad[] = {{-1, 5, "is not a kpcn-render checkpoint"},
             {-1, 1000, "is damaged"},
             {20000, -1, "checksum does not match"},
             {16, -1, "is damaged: its header is not JSON"}};
  for (int i = 0; i < (int)(sizeof bad / sizeof bad[0]); i++) {
    corrupt("c.ckpt", "bad.ckpt", bad[i].at, bad[i].keep);
    rs = settings(2, "bad.ckpt");
    CHECK(render(s, &rs, &st, NULL) == NULL && st == KPCN_ERR_FORMAT);
    if (!strstr(kpcn_last_error(), bad[i].msg))
      printf("case %d: '%s' lacks '%s'\n", i, kpcn_last_error(), bad[i].msg);
    CHECK(strstr(kpcn_last_error(), bad[i].msg) != NULL);
  }
  remove("bad.ckpt");
  remove("c.ckpt");

  /* periodic saves: one thread saving after every row leaves every row in the file, and a
   * second call resumes all of them and traces nothing */
  rs = settings(1, "p.ckpt");
  rs.checkpoint_every_s = 1e-9;
  kpcn_aov_set *a = render(s, &rs, &st, NULL);
  CHECK(a != NULL && sets_equal(full, a) && file_exists("p.ckpt"));
  kpcn_aov_set *b = render(s, &rs, &st, &stats);
  CHECK(b != NULL && sets_equal(full, b) && stats.rows_resumed == H && stats.samples == 0);
  kpcn_aov_destroy(a);
  kpcn_aov_destroy(b);
  remove("p.ckpt");

  rs = settings(1, "p.ckpt");
  rs.checkpoint_every_s = -1;
  CHECK(render(s, &rs, &st, NULL) == NULL && st == KPCN_ERR_INVALID_ARGUMENT);
  rs = settings(1, "no_such_dir/p.ckpt");
  rs.checkpoint_every_s = 1e-9;
  CHECK(render(s, &rs, &st, NULL) == NULL && st == KPCN_ERR_IO);
  CHECK(strstr(kpcn_last_error(), "no_such_dir/p.ckpt") != NULL);
  kpcn_aov_destroy(full);
}

/* Starts argv with stderr into err_path (NULL: inherited). */
static pid_t spawn(char *const argv[], const char *err_path) {
  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  if (err_path)
    posix_spawn_file_actions_addopen(&fa, 2, err_path, O_WRONLY | O_CREAT | O_TRUNC, 0644);
  pid_t pid;
  int r = posix_spawn(&pid, argv[0], &fa, NULL, argv, environ);
  posix_spawn_file_actions_destroy(&fa);
  return r == 0 ? pid : -1;
}

static int file_contains(const char *path, const char *text) {
  FILE *f = fopen(path, "rb");
  if (!f) return 0;
  char buf[8192];
  size_t n = fread(buf, 1, sizeof buf - 1, f);
  fclose(f);
  buf[n] = 0;
  return strstr(buf, text) != NULL;
}

static int wait_status(pid_t pid) {
  int ws = 0;
  waitpid(pid, &ws, 0);
  return WIFEXITED(ws) ? WEXITSTATUS(ws) : 1000 + (WIFSIGNALED(ws) ? WTERMSIG(ws) : 0);
}

static void test_cli(void) {
  /* kpcn-render is built with this test (tests/render/CMakeLists.txt): missing is a failure,
   * not a skip that reports success */
  CHECK(access(RENDER_BIN, X_OK) == 0);
  if (access(RENDER_BIN, X_OK) != 0) {
    fprintf(stderr, "no %s\n", RENDER_BIN);
    return;
  }
  remove("cli.ckpt");
  remove("cli.exr");
  /* long enough (1 thread, 2048 spp) that the signal lands mid-render */
  char *run[] = {
      RENDER_BIN,           CORNELL, "-o",           "cli.exr", "--spp",        "2048",
      "--threads",          "1",     "--resolution", "64x64",   "--checkpoint", "cli.ckpt",
      "--checkpoint-every", "0.05",  "--quiet",      NULL};
  pid_t pid = spawn(run, NULL);
  CHECK(pid > 0);
  for (int i = 0; i < 6000 && !file_exists("cli.ckpt"); i++)
    usleep(10000);
  CHECK(file_exists("cli.ckpt"));
  kill(pid, SIGINT);
  CHECK(wait_status(pid) == 130);
  CHECK(file_exists("cli.ckpt") && !file_exists("cli.exr"));
  run[7] = "2"; /* resumed with two threads */
  pid = spawn(run, "cli.err");
  CHECK(wait_status(pid) == 0);
  CHECK(file_contains("cli.err", "kpcn-render: resumed ")); /* it did not start again */
  CHECK(file_exists("cli.exr") && !file_exists("cli.ckpt"));
  char *plain[] = {RENDER_BIN,  CORNELL, "-o",           "plain.exr", "--spp",   "2048",
                   "--threads", "2",     "--resolution", "64x64",     "--quiet", NULL};
  CHECK(wait_status(spawn(plain, NULL)) == 0);
  kpcn_aov_set *x = NULL, *y = NULL;
  CHECK(kpcn_exr_read_aov("cli.exr", &x) == KPCN_OK &&
        kpcn_exr_read_aov("plain.exr", &y) == KPCN_OK);
  CHECK(sets_equal(x, y));
  kpcn_aov_destroy(x);
  kpcn_aov_destroy(y);
  remove("cli.exr");
  remove("plain.exr");
  remove("cli.err");
  /* without --checkpoint a signal stops the render too (exit 128 + the signal, nothing written,
   * no temporary file): the default action used to kill it even while it wrote the output */
  char *nock[] = {RENDER_BIN,  CORNELL, "-o",           "nock.exr", "--spp", "4096",
                  "--threads", "1",     "--resolution", "64x64",    NULL};
  pid = spawn(nock, "nock.err");
  CHECK(pid > 0);
  usleep(1500000); /* past the scene's loading, also under the sanitizers */
  kill(pid, SIGTERM);
  CHECK(wait_status(pid) == 143);
  CHECK(file_contains("nock.err", "stopped by signal 15; nothing written"));
  CHECK(!file_exists("nock.exr") && system("ls nock.exr.tmp* >/dev/null 2>&1") != 0);
  remove("nock.err");

  /* a checkpoint path that is the output or the scene file: a usage error */
  char *alias[] = {RENDER_BIN, CORNELL, "-o", "a.exr", "--checkpoint", "./a.exr", "--quiet", NULL};
  CHECK(wait_status(spawn(alias, "a.err")) == 2 && file_contains("a.err", "is the output"));
  alias[5] = CORNELL;
  CHECK(wait_status(spawn(alias, "a.err")) == 2 && file_contains("a.err", "is the scene file"));
  CHECK(!file_exists("a.exr"));
  /* an output that is a file the scene reads (here an EXR texture) was written over it */
  {
    const char *names[3] = {"R", "G", "B"};
    kpcn_image *tex = NULL;
    CHECK(kpcn_image_create(&tex, 2, 2, 3, names) == KPCN_OK);
    if (tex) {
      for (int i = 0; i < 12; i++)
        tex->data[i] = 0.5f;
      CHECK(kpcn_exr_write_image("tex.exr", tex, NULL) == KPCN_OK);
      kpcn_image_destroy(tex);
    }
    FILE *f = fopen("texscene.json", "w");
    CHECK(f != NULL);
    if (f) {
      fputs("{\"primitives\": [{\"type\": \"quad\", \"bsdf\": {\"type\": \"lambert\", "
            "\"albedo\": \"tex.exr\"}}, {\"type\": \"infinite_sphere\", \"emission\": 1}], "
            "\"camera\": {\"type\": \"pinhole\", \"resolution\": 8, \"transform\": {\"position\": "
            "[0, 2, 0], "
            "\"look_at\": [0, 0, 0], \"up\": [0, 0, 1]}}}",
            f);
      fclose(f);
    }
    struct stat before, after;
    CHECK(stat("tex.exr", &before) == 0);
    char *clash[] = {RENDER_BIN, "texscene.json", "-o", "./tex.exr", "--spp", "1", "--quiet", NULL};
    CHECK(wait_status(spawn(clash, "a.err")) == 2 &&
          file_contains("a.err", "-o './tex.exr' is './tex.exr', a file the scene reads"));
    CHECK(stat("tex.exr", &after) == 0 && after.st_size == before.st_size &&
          after.st_mtime == before.st_mtime);
    clash[3] = "ok.exr"; /* the same scene renders */
    CHECK(wait_status(spawn(clash, "a.err")) == 0 && file_exists("ok.exr"));
    remove("ok.exr"), remove("tex.exr"), remove("texscene.json");
  }
  /* --time-limit without a checkpoint would throw the rows away: a usage error */
  char *nolimit[] = {RENDER_BIN, CORNELL, "-o", "a.exr", "--time-limit", "1", "--quiet", NULL};
  CHECK(wait_status(spawn(nolimit, "a.err")) == 2 && file_contains("a.err", "needs --checkpoint"));
  CHECK(!file_exists("a.exr"));
  remove("a.err");

  /* A texture edited between a stop and a resume is refused: the scene's identity covers the
   * files it names. The checkpoint comes from --time-limit 0: one thread stops after its first
   * row (exit 3, no output). */
  CHECK(system("rm -rf tx && mkdir -p tx/scenes && cp -r " KPCN_TESTDATA
               "/scenes/textures tx/scenes/") == 0);
  char *tx[] = {RENDER_BIN,
                "tx/scenes/textures/scene.json",
                "-o",
                "t.exr",
                "--spp",
                "2",
                "--resolution",
                "24x16",
                "--checkpoint",
                "t.ckpt",
                "--threads",
                "1",
                "--time-limit",
                "0",
                NULL};
  remove("t.ckpt");
  remove("t.exr");
  CHECK(wait_status(spawn(tx, "t.err")) == 3 && file_exists("t.ckpt") && !file_exists("t.exr"));
  CHECK(file_contains("t.err", "stopped by --time-limit"));
  tx[12] = NULL; /* from here on without the limit */
  CHECK(system("printf x >> tx/scenes/textures/bricks.png") == 0);
  CHECK(wait_status(spawn(tx, "t.err")) == 1 && file_contains("t.err", "its scene_key is"));
  CHECK(!file_exists("t.exr"));
  CHECK(system("cp " KPCN_TESTDATA "/scenes/textures/bricks.png tx/scenes/textures/") == 0);
  CHECK(wait_status(spawn(tx, "t.err")) == 0 && file_contains("t.err", "resumed 1 of 16 rows"));
  CHECK(file_exists("t.exr") && !file_exists("t.ckpt"));
  remove("t.exr");
  remove("t.err");
}

int main(void) {
  /* fixed names in the test's folder: nothing of an earlier, failed run may be resumed */
  static const char *const old[] = {"c.ckpt",    "p.ckpt", "bad.ckpt", "cli.ckpt", "cli.exr",
                                    "plain.exr", "a.exr",  "t.ckpt",   "t.exr"};
  for (size_t i = 0; i < sizeof old / sizeof old[0]; i++)
    remove(old[i]);
  kpcn_scene *s = NULL;
  CHECK(kpcn_scene_load(CORNELL, &s) == KPCN_OK);
  if (s) test_library(s);
  kpcn_scene_destroy(s);
  test_cli();
  return kt_summary("render_ckpt");
}
