/* `kpcn-dataset run`: executes the manifest's render jobs with a pool of renderer
 * processes. Resumable (a job whose output exists is skipped; outputs appear only by an
 * atomic rename after the renderer exits 0), shardable (--shard i/n takes every n-th
 * job), and rejects degenerate variants from a cheap preview render before spending
 * time on them. */
#define _GNU_SOURCE
#include "ds.h"
#include "kpcn/exr.h"

#include <cjson/cJSON.h>
#include <errno.h>
#include <fcntl.h>
#include <libgen.h>
#include <limits.h>
#include <math.h>
#include <signal.h>
#include <stdlib.h>
#include <string.h>
#include <sys/prctl.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

typedef struct run_opts {
  const char *dir;
  char renderer[DS_PATH];
  int jobs, shard_i, shard_n, threads, dry_run, list;
  double max_black, max_background, max_blown, blown_level;
  double progress_every; /* seconds between progress lines when stderr is no terminal */
  /* > 0: each render keeps a checkpoint <out>.ckpt, saved this often and when the run is
   * stopped, so a long reference render resumes instead of starting again */
  double checkpoint_every;
} run_opts;

static volatile sig_atomic_t g_stop = 0; /* the signal that stopped the run, 0 if none */
static void on_signal(int s) { g_stop = s; }

static int find_renderer(run_opts *o, const char *given) {
  if (given) {
    struct stat st; /* a directory passes access(X_OK) and then fails every job with 127 */
    if (stat(given, &st) != 0 || !S_ISREG(st.st_mode) || access(given, X_OK) != 0) {
      ds_err("run: --renderer '%s' is not an executable file", given);
      return -1;
    }
    snprintf(o->renderer, sizeof o->renderer, "%s", given);
    return 0;
  }
  char self[DS_PATH];
  ssize_t n = readlink("/proc/self/exe", self, sizeof self - 1);
  if (n > 0) {
    self[n] = 0;
    char *d = dirname(self);
    const char *cands[] = {"kpcn-render", "../kpcn-render/kpcn-render"};
    for (int i = 0; i < 2; i++) {
      char p[DS_PATH];
      ds_join(p, sizeof p, d, cands[i]);
      if (access(p, X_OK) == 0) {
        snprintf(o->renderer, sizeof o->renderer, "%s", p);
        return 0;
      }
    }
  }
  /* Fall back to $PATH (execvp). */
  snprintf(o->renderer, sizeof o->renderer, "kpcn-render");
  return 0;
}

/* ---- degenerate-variant check on the preview render ---- */
static void verdict_path(char *out, size_t n, const char *dir, const char *preview) {
  char rel[DS_PATH];
  snprintf(rel, sizeof rel, "%s", preview);
  char *dot = strrchr(rel, '.');
  if (dot) *dot = 0;
  char tmp[DS_PATH + 16];
  snprintf(tmp, sizeof tmp, "%s.verdict.json", rel);
  ds_join(out, n, dir, tmp);
}

/* Returns 1 ok, 0 rejected, -1 error; writes the verdict JSON next to the preview. */
static int judge_preview(const run_opts *o, const char *preview, char *reason, size_t rn) {
  char path[DS_PATH], vpath[DS_PATH];
  ds_join(path, sizeof path, o->dir, preview);
  verdict_path(vpath, sizeof vpath, o->dir, preview);
  kpcn_aov_set *s = NULL;
  if (kpcn_exr_read_aov(path, &s) != KPCN_OK ||
      kpcn_aov_require(s, KPCN_BUF_COLOR, 0, path) != KPCN_OK) {
    ds_err("run: preview %s: %s", path, kpcn_last_error());
    kpcn_aov_destroy(s);
    return -1;
  }
  size_t n = kpcn_aov_plane_size(s);
  const float *c = s->buf[KPCN_BUF_COLOR], *z = s->buf[KPCN_BUF_DEPTH];
  size_t black = 0, bg = 0, blown = 0;
  for (size_t i = 0; i < n; i++) {
    double L = 0.2126 * c[i] + 0.7152 * c[n + i] + 0.0722 * c[2 * n + i];
    black += !(L >= 1e-3);
    blown += L > o->blown_level;
    if (z) bg += z[i] == 0.0f;
  }
  double fb = (double)black / n, fg = (double)bg / n, fo = (double)blown / n;
  int ok = 1;
  reason[0] = 0;
  if (fb > o->max_black)
    ok = 0, snprintf(reason, rn, "mostly black (%.0f%% of pixels)", 100 * fb);
  else if (z && fg > o->max_background)
    ok = 0, snprintf(reason, rn, "mostly background (%.0f%% of pixels miss)", 100 * fg);
  else if (fo > o->max_blown)
    ok = 0,
    snprintf(reason, rn, "blown out (%.0f%% of pixels above %.3g)", 100 * fo, o->blown_level);
  kpcn_aov_destroy(s);
  cJSON *j = cJSON_CreateObject();
  cJSON_AddBoolToObject(j, "ok", ok);
  cJSON_AddStringToObject(j, "reason", reason);
  cJSON_AddNumberToObject(j, "black", fb);
  cJSON_AddNumberToObject(j, "background", fg);
  cJSON_AddNumberToObject(j, "blown", fo);
  char *t = cJSON_Print(j);
  cJSON_Delete(j);
  ds_write_atomic(vpath, t, strlen(t));
  free(t);
  return ok;
}

/* ---- process pool ---- */
typedef struct slot {
  pid_t pid;
  int job;
  char part[DS_PATH + 32];
} slot;

static void log_path(char *out, size_t n, const char *dir, const char *id) {
  char name[256];
  snprintf(name, sizeof name, "logs/%s.log", id);
  for (char *p = name + 5; *p; p++)
    if (*p == '/') *p = '_';
  ds_join(out, n, dir, name);
}

/* A job's checkpoint, beside its output; no pid in the name: the next run must find it. */
static void job_ckpt(char *ck, size_t n, const char *out) { snprintf(ck, n, "%s.ckpt", out); }

static pid_t spawn(const run_opts *o, const ds_job *j, char *part, size_t pn) {
  char scene[DS_PATH], out[DS_PATH], logp[DS_PATH], spp[16], seed[32], res[48], thr[16];
  ds_join(scene, sizeof scene, o->dir, j->scene_file);
  ds_join(out, sizeof out, o->dir, j->out);
  char od[DS_PATH];
  snprintf(od, sizeof od, "%s", out);
  ds_mkdir_p(dirname(od));
  /* The renderer writes a private part file; only a successful exit renames it. */
  snprintf(part, pn, "%.*s.part%ld.exr", (int)(strlen(out) - 4), out, (long)getpid());
  log_path(logp, sizeof logp, o->dir, j->id);
  snprintf(spp, sizeof spp, "%d", j->spp);
  snprintf(seed, sizeof seed, "%llu", (unsigned long long)j->seed);
  snprintf(res, sizeof res, "%dx%d", j->width, j->height);
  snprintf(thr, sizeof thr, "%d", o->threads);
  char fp[16], ck[DS_PATH + 8], every[32];
  snprintf(fp, sizeof fp, "%d", j->albedo_footprint);
  job_ckpt(ck, sizeof ck, out);
  snprintf(every, sizeof every, "%g", o->checkpoint_every);
  char *argv[20] = {(char *)o->renderer, scene, "-o",        part, "--spp",  spp, "--seed", seed,
                    "--resolution",      res,   "--threads", thr,  "--quiet"};
  int na = 13;
  if (j->albedo_footprint > 1) {
    argv[na++] = "--albedo-footprint";
    argv[na++] = fp;
  }
  if (o->checkpoint_every > 0) {
    argv[na++] = "--checkpoint";
    argv[na++] = ck;
    argv[na++] = "--checkpoint-every";
    argv[na++] = every;
  }
  argv[na] = NULL;
  pid_t pid = fork();
  if (pid == 0) {
    /* Its own process group, so that stopping the run reaches everything the renderer
     * started: a wrapper script's children would otherwise survive it, keep computing, and
     * could write the part file after it was removed. */
    setpgid(0, 0);
    int fd = open(logp, O_WRONLY | O_CREAT | O_TRUNC, 0666);
    if (fd >= 0) {
      dup2(fd, 1);
      dup2(fd, 2);
      close(fd);
    }
    signal(SIGINT, SIG_DFL);
    signal(SIGTERM, SIG_DFL);
    execvp(argv[0], argv);
    fprintf(stderr, "cannot execute renderer '%s': %s\n", argv[0], strerror(errno));
    _exit(127);
  }
  if (pid > 0) setpgid(pid, pid); /* also here: the group must exist before any kill */
  return pid;
}

/* After a stop: the renderer (group leader) was reaped, but members of its group (a wrapper
 * script's children) may still be dying; wait for them (up to 2 s) so that none can write
 * the part file after it is removed. */
static void wait_group_gone(pid_t pgid) {
  for (int i = 0; i < 2000; i++) {
    while (waitpid(-pgid, NULL, WNOHANG) > 0) /* orphans are ours: the run is a subreaper */
      ;
    if (kill(-pgid, 0) != 0) return;
    usleep(1000);
  }
}

typedef struct counts {
  int done, skipped, failed, rejected_jobs, total;
} counts;

/* On a terminal one line rewritten after every job; elsewhere (a log file of a run under
 * nohup, hours long) a line of its own at most every o->progress_every seconds, and after the
 * last job. */
static void progress(const run_opts *o, const counts *c, int running, double t0) {
  static double last_line = -1e300;
  double el = ds_now() - t0;
  int fin = c->done + c->failed;
  int left = c->total - fin - c->skipped - c->rejected_jobs;
  char detail[128];
  snprintf(detail, sizeof detail, "rendered %d, running %d, failed %d", c->done, running,
           c->failed);
  ds_progress(&last_line, o->progress_every, left <= 0, fin + c->skipped + c->rejected_jobs,
              c->total, el, fin > 0 ? el / fin * left : 0, detail);
}

/* Runs the jobs in idx[0..n) through a pool of o->jobs renderer processes. */
static int run_pool(const run_opts *o, const ds_manifest *m, const int *idx, int n, counts *c,
                    double t0) {
  slot *slots = calloc((size_t)o->jobs, sizeof *slots);
  int next = 0, running = 0;
  while ((next < n || running > 0)) {
    while (!g_stop && next < n && running < o->jobs) {
      const ds_job *j = &m->jobs[idx[next]];
      int k = 0;
      while (slots[k].pid)
        k++;
      slots[k].job = idx[next];
      slots[k].pid = spawn(o, j, slots[k].part, sizeof slots[k].part);
      if (slots[k].pid < 0) {
        ds_err("run: fork failed: %s", strerror(errno));
        slots[k].pid = 0;
        g_stop = 1;
        break;
      }
      running++;
      next++;
    }
    if (running == 0) break;
    int status;
    pid_t p = waitpid(-1, &status, 0);
    if (p < 0) {
      if (errno == EINTR) {
        if (g_stop)
          for (int k = 0; k < o->jobs; k++)
            if (slots[k].pid) kill(-slots[k].pid, SIGTERM); /* the renderer's group */
        continue;
      }
      break;
    }
    for (int k = 0; k < o->jobs; k++) {
      if (slots[k].pid != p) continue;
      const ds_job *j = &m->jobs[slots[k].job];
      char out[DS_PATH];
      ds_join(out, sizeof out, o->dir, j->out);
      const int exit0 = WIFEXITED(status) && WEXITSTATUS(status) == 0;
      /* what a renderer wrote must at least be an EXR (a wrapper that exits 0 after writing
       * garbage would otherwise count as done, and every later run skip the job) */
      kpcn_exr_info_t info;
      const int present = exit0 && ds_exists(slots[k].part);
      const int written = present && kpcn_exr_info(slots[k].part, &info) == KPCN_OK;
      char bad_exr[512] = "";
      if (present && !written) snprintf(bad_exr, sizeof bad_exr, "%s", kpcn_last_error());
      const int renamed = written && rename(slots[k].part, out) == 0;
      const int rename_errno = errno;
      if (renamed) {
        c->done++;
      } else {
        if (g_stop) wait_group_gone(p);
        unlink(slots[k].part);
        if (!g_stop) {
          char lp[DS_PATH];
          log_path(lp, sizeof lp, o->dir, j->id);
          if (ds_isatty()) fputc('\n', stderr);
          if (written) /* the rename failed */
            ds_err("run: job %s: cannot rename '%s' to '%s': %s", j->id, slots[k].part, out,
                   strerror(rename_errno));
          else if (present)
            ds_err("run: job %s failed: the renderer's output is not a readable EXR (%s); see %s",
                   j->id, bad_exr, lp);
          else if (exit0)
            ds_err("run: job %s failed: the renderer exited 0 without writing '%s'; see %s", j->id,
                   slots[k].part, lp);
          else
            ds_err("run: job %s failed (%s %d); see %s", j->id,
                   WIFEXITED(status) ? "exit code" : "signal",
                   WIFEXITED(status) ? WEXITSTATUS(status) : WTERMSIG(status), lp);
          c->failed++;
        }
      }
      slots[k].pid = 0;
      running--;
      break;
    }
    progress(o, c, running, t0);
  }
  free(slots);
  return g_stop ? -1 : 0;
}

/* --dry-run's line for a job, saying when a checkpoint of an earlier, stopped run is there
 * (kpcn-render resumes from it when this run passes --checkpoint-every). */
static void print_would_render(const run_opts *o, const ds_job *j) {
  char out[DS_PATH], ck[DS_PATH + 8];
  ds_join(out, sizeof out, o->dir, j->out);
  job_ckpt(ck, sizeof ck, out);
  printf("would render %s%s\n", j->id, ds_exists(ck) ? " (a checkpoint is there)" : "");
}

/* to stdout when --help asked for it, to stderr beside an error */
static void usage(FILE *f) {
  fprintf(
      f, "usage: kpcn-dataset run DATASET_DIR [--jobs N] [--shard i/n] [--renderer PATH]\n"
         "         [--threads-per-job T] [--dry-run] [--list] [--progress-every 60]\n"
         "         [--checkpoint-every S]\n"
         "         [--max-black 0.9] [--max-background 0.9] [--max-blown 0.5] [--blown-level 1]\n");
}

int ds_cmd_run(int argc, char **argv) {
  run_opts o;
  memset(&o, 0, sizeof o);
  o.jobs = 1;
  o.shard_n = 1;
  o.max_black = 0.9;
  o.max_background = 0.9;
  o.max_blown = 0.5;
  o.blown_level = 1.0;
  o.progress_every = 60.0;
  const char *renderer = NULL;
  int threads = -1;
  for (int i = 1; i < argc; i++) {
    const char *a = argv[i], *v = i + 1 < argc ? argv[i + 1] : NULL;
    if (!strcmp(a, "--dry-run"))
      o.dry_run = 1;
    else if (!strcmp(a, "--list"))
      o.list = 1;
    else if (!strcmp(a, "-h") || !strcmp(a, "--help")) {
      usage(stdout);
      return 0;
    } else if (a[0] != '-') {
      if (o.dir) {
        ds_err("run: more than one dataset directory ('%s', '%s')", o.dir, a);
        return 2;
      }
      o.dir = a;
    } else {
      if (!v) {
        ds_err("run: %s needs a value", a);
        return 2;
      }
      int ok = 1;
      const char *want = ""; /* what the option takes, for the error */
      if (!strcmp(a, "--jobs") || !strcmp(a, "-j")) {
        ok = cli_parse_int(v, 1, 1024, &o.jobs);
        want = " (an integer in [1, 1024])";
      } else if (!strcmp(a, "--threads-per-job")) {
        ok = cli_parse_int(v, 0, KPCN_MAX_THREADS, &threads);
        want = " (an integer in [0, 1024])";
      } else if (!strcmp(a, "--renderer"))
        renderer = v;
      else if (!strcmp(a, "--checkpoint-every")) {
        ok = cli_parse_double(v, &o.checkpoint_every) && o.checkpoint_every >= 0 &&
             o.checkpoint_every <= 1e9;
        want = " (seconds in [0, 1e9]; 0 = no checkpoints)";
      } else if (!strcmp(a, "--progress-every")) {
        ok = cli_parse_double(v, &o.progress_every) && o.progress_every >= 0;
        want = " (seconds >= 0)";
      } else if (!strcmp(a, "--shard")) {
        static const long lo[2] = {0, 1}, hi[2] = {INT_MAX - 1, INT_MAX};
        int in[2];
        ok = cli_parse_int_list(v, '/', 2, lo, hi, in) && in[0] < in[1];
        if (ok) o.shard_i = in[0], o.shard_n = in[1];
        want = " (expected i/n with 0 <= i < n)";
      } else if (!strcmp(a, "--max-black") || !strcmp(a, "--max-background") ||
                 !strcmp(a, "--max-blown")) {
        /* Fractions of the preview's pixels: below 0 every variant is rejected, above 1
         * none (both silently), and nan compares false, i.e. disables the check. */
        double *dst = !strcmp(a, "--max-black")        ? &o.max_black
                      : !strcmp(a, "--max-background") ? &o.max_background
                                                       : &o.max_blown;
        ok = cli_parse_double(v, dst) && *dst >= 0 && *dst <= 1;
        want = " (a fraction of pixels in [0, 1])";
      } else if (!strcmp(a, "--blown-level")) {
        /* A luminance: at 0 or below every lit pixel counts as blown out. */
        ok = cli_parse_double(v, &o.blown_level) && o.blown_level > 0;
        want = " (a luminance > 0)";
      } else {
        ds_err("run: unknown option '%s'", a);
        usage(stderr);
        return 2;
      }
      if (!ok) {
        ds_err("run: bad value '%s' for %s%s", v, a, want);
        return 2;
      }
      i++;
    }
  }
  if (!o.dir) {
    usage(stderr);
    return 2;
  }
  ds_manifest m;
  if (ds_manifest_read(o.dir, &m) != 0) return 1;
  if (find_renderer(&o, renderer) != 0) {
    ds_manifest_free(&m);
    return 2;
  }
  long ncpu = sysconf(_SC_NPROCESSORS_ONLN);
  o.threads = threads >= 0 ? threads : (int)(ncpu / o.jobs > 0 ? ncpu / o.jobs : 1);
  char logs[DS_PATH];
  ds_join(logs, sizeof logs, o.dir, "logs");
  ds_mkdir_p(logs);

  /* My shard: every shard_n-th render job (previews are not sharded: each shard renders
   * the previews its jobs need, which is cheap and idempotent). */
  int *mine = malloc(sizeof(int) * (size_t)(m.n + 1)), nmine = 0, k = 0;
  for (int i = 0; i < m.n; i++) {
    if (m.jobs[i].kind == DS_PREVIEW) continue;
    if (k++ % o.shard_n == o.shard_i) mine[nmine++] = i;
  }
  if (o.list) {
    for (int i = 0; i < nmine; i++)
      printf("%s\n", m.jobs[mine[i]].id);
    free(mine);
    ds_manifest_free(&m);
    return 0;
  }
  struct sigaction sa;
  memset(&sa, 0, sizeof sa);
  sa.sa_handler = on_signal;
  sigaction(SIGINT, &sa, NULL);
  sigaction(SIGTERM, &sa, NULL);
  /* orphans of a renderer's group (a wrapper script's children) become our children, so a
   * stop can reap them instead of leaving zombies for an init that may never reap */
  prctl(PR_SET_CHILD_SUBREAPER, 1);

  double t0 = ds_now();
  counts c = {0, 0, 0, 0, nmine};
  /* Phase 1: previews needed by my jobs and not rendered yet. */
  int *pv = malloc(sizeof(int) * (size_t)(m.n + 1)), npv = 0;
  for (int i = 0; i < m.n; i++) {
    const ds_job *p = &m.jobs[i];
    if (p->kind != DS_PREVIEW) continue;
    int needed = 0;
    for (int q = 0; q < nmine && !needed; q++) {
      const ds_job *j = &m.jobs[mine[q]];
      char out[DS_PATH];
      ds_join(out, sizeof out, o.dir, j->out);
      needed = !strcmp(j->preview, p->out) && !ds_exists(out);
    }
    char out[DS_PATH];
    ds_join(out, sizeof out, o.dir, p->out);
    if (needed && !ds_exists(out)) pv[npv++] = i;
  }
  int rc = 0;
  /* renders already there must be their jobs' (a preview too: its verdict is reused) */
  for (int i = 0; i < m.n && rc == 0; i++) {
    char out[DS_PATH];
    ds_join(out, sizeof out, o.dir, m.jobs[i].out);
    if (ds_exists(out) && ds_check_render(out, &m.jobs[i]) != 0) rc = 1;
  }
  if (rc) {
    free(pv);
    free(mine);
    ds_manifest_free(&m);
    return rc;
  }
  if (o.dry_run) {
    for (int i = 0; i < npv; i++)
      print_would_render(&o, &m.jobs[pv[i]]);
  } else if (npv) {
    counts pc = {0, 0, 0, 0, npv};
    if (run_pool(&o, &m, pv, npv, &pc, t0) != 0)
      rc = g_stop > 1 ? 128 + g_stop : 1; /* 1: fork failed */
    if (ds_isatty()) fputc('\n', stderr);
    /* Failed previews surface below as failed jobs ("no usable preview"). */
  }
  /* Phase 2: my render jobs, minus finished ones and rejected variants. */
  int *pending = malloc(sizeof(int) * (size_t)(nmine + 1)), npending = 0, nrej_var = 0;
  char last_rejected[DS_PATH] = "";
  for (int q = 0; q < nmine && rc == 0; q++) {
    const ds_job *j = &m.jobs[mine[q]];
    char out[DS_PATH];
    ds_join(out, sizeof out, o.dir, j->out);
    if (ds_exists(out)) {
      c.skipped++;
      continue;
    }
    if (j->preview[0] && !o.dry_run) {
      char pp[DS_PATH], reason[256];
      ds_join(pp, sizeof pp, o.dir, j->preview);
      /* Jobs of one variant share a preview: judge it once. */
      static char cached[DS_PATH];
      static char cached_reason[256];
      static int cached_ok;
      int ok;
      if (!strcmp(cached, j->preview)) {
        ok = cached_ok;
        snprintf(reason, sizeof reason, "%s", cached_reason);
      } else {
        ok = ds_exists(pp) ? judge_preview(&o, j->preview, reason, sizeof reason) : -1;
        snprintf(cached, sizeof cached, "%s", j->preview);
        snprintf(cached_reason, sizeof cached_reason, "%s", reason);
        cached_ok = ok;
      }
      if (ok < 0) {
        ds_err("run: job %s: no usable preview (%s); not rendered", j->id, j->preview);
        c.failed++;
        continue;
      }
      if (ok == 0) {
        if (strcmp(last_rejected, j->preview) != 0) {
          nrej_var++;
          printf("rejected %s/v%03d: %s\n", j->scene, j->variant, reason);
          snprintf(last_rejected, sizeof last_rejected, "%s", j->preview);
        }
        c.rejected_jobs++;
        continue;
      }
    }
    pending[npending++] = mine[q];
  }
  if (o.dry_run) {
    for (int i = 0; i < npending; i++)
      print_would_render(&o, &m.jobs[pending[i]]);
  } else if (rc == 0 && npending) {
    if (run_pool(&o, &m, pending, npending, &c, t0) != 0)
      rc = g_stop > 1 ? 128 + g_stop : 1; /* 1: fork failed */
    if (ds_isatty()) fputc('\n', stderr);
  }
  if (!o.dry_run)
    printf("shard %d/%d: %d jobs: rendered %d, already done %d, rejected %d (%d variants), "
           "failed %d, %.1f s%s\n",
           o.shard_i, o.shard_n, nmine, c.done, c.skipped, c.rejected_jobs, nrej_var, c.failed,
           ds_now() - t0, rc == 130 ? " (interrupted; run again to resume)" : "");
  free(pending);
  free(pv);
  free(mine);
  ds_manifest_free(&m);
  if (rc) return rc;
  return c.failed ? 1 : 0;
}
