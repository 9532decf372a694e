/* kpcn-train — trains the two-branch KPCN on a patch store (seed ch. 4.4-6).
 * See docs/training.md. Exit status: 0 done (or stopped cleanly and checkpointed), 1 error,
 * 2 bad usage. */
#include "cli_parse.h"
#include "kpcn/dataset.h"
#include "kpcn/train.h"

#include <errno.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

static volatile sig_atomic_t g_stop = 0; /* the signal that asked to stop, 0 if none */
static void on_signal(int sig) { g_stop = sig; }

static void usage(FILE *f) {
  fputs("usage: kpcn-train --store PATCHES.kps -o MODEL.safetensors [options]\n"
        "  --preset cpu|paper|tiny   architecture preset (default cpu)\n"
        "  --layers N --channels C --conv K --kernel K --dilations D1,D2,...\n"
        "                            architecture overrides (hidden layers, width, conv size\n"
        "                            of every layer, prediction window, per-layer dilation)\n"
        "  --init MODEL              start from an existing model (fine-tuning)\n"
        "  --widen C                 with --init: first widen it to C hidden channels (same\n"
        "                            function: new units get zero outgoing weights)\n"
        "  --kpa-passes N            apply the predicted kernels N times (1..3, default 1;\n"
        "                            with --init: the model's own unless given)\n"
        "  --eps X                   the albedo epsilon of the diffuse demodulation, in\n"
        "                            [1e-9, 0.5] (default 0.00316; with --init: the model's own\n"
        "                            unless given)\n"
        "  --source-weight           predict a per-pixel source weight too (arch.source_weight;\n"
        "                            with --init: added with zero weights, same function)\n"
        "  --source-lr-scale X       the source score's weights learn at X times the rate\n"
        "                            (needs a source weight: --source-weight or the --init's)\n"
        "  --freeze diffuse|specular with --init: that branch keeps its weights bit for bit\n"
        "                            (fine-tune the other branch alone)\n"
        "  --loss l1|l2|relmse|rell1|ssim|relmse-sg|rell1-sg   stage-1 loss (default l1;\n"
        "                            mse is l2)\n"
        "  --loss2 NAME              stage-2 loss (default: same as --loss)\n"
        "  --ssim-window N           SSIM window (odd, default 11), --loss-margin M\n"
        "  --lr X (1e-3) --lr-decay X (0.96) --decay-every N (100000; 0 = no decay)\n"
        "                            --staircase --clip X\n"
        "  --lr2 X                   base learning rate of stage 2 (default: --lr); its decay\n"
        "                            counts the run's iterations, not stage 2's\n"
        "  --batch N (16) --patch P (64) --iters N (1000) --stage1-iters N (0.6*iters)\n"
        "  --threads N (0 = all) --seed N (1)\n"
        "  --bf16                    mixed precision: bf16 convolutions (about 2x the conv\n"
        "                            throughput where the CPU has AVX512_BF16), f32 weights,\n"
        "                            gradients and Adam\n"
        "  --val NOISY.exr,REF.exr   validation pair (repeatable)\n"
        "  --val-store VAL.kps       validate on the full renders another store was cut from\n"
        "                            (e.g. kpcn-dataset patches --split val)\n"
        "  --val-every N --ckpt-every N   (default 0: only at the end and when stopped;\n"
        "                            --val-every needs --val or --val-store)\n"
        "  --log-every N             CSV row every N iterations (10)\n"
        "  --ckpt PATH --csv PATH --plot PATH   (default MODEL.ckpt/.csv/.png; '' = none)\n"
        "  --best PATH               also write the model with the lowest validation relMSE\n"
        "  --best-by mean|geomean    which: mean (default) or geometric mean over the pairs\n"
        "                            (needs --best)\n"
        "  --snapshots DIR           keep every checkpoint in DIR (for --average)\n"
        "  --time-limit MINUTES      stop cleanly and checkpoint after MINUTES of this call\n"
        "                            (not counting earlier sessions of a --resume; 0 = none)\n"
        "  --resume                  continue bit-exactly from the checkpoint\n"
        "  --no-colorswap --no-mirror --no-rotate --no-shift   disable augmentations\n"
        "  --normalize-exposure      show every patch at the model's exposure (the median of\n"
        "                            the store's; as the denoiser shows every input)\n"
        "  --firefly R               bound each patch's isolated diffuse fireflies (ratio R >= 1)\n"
        "                            before its features, as the denoiser does (its default is\n"
        "                            4; training's is off)\n"
        "  --quiet                   no log lines\n"
        "  --version                 the versions and the instruction set (avx512 or avx2)\n"
        "\n"
        "usage: kpcn-train --compare OUT.png [--x iter|elapsed_s] [--y COLUMN] [--title T]\n"
        "                  [--linear] LABEL=RUN.csv ...\n"
        "  draws one CSV column (default loss; val_relmse, val_ssim, val_psnr ...) of up to 8\n"
        "  runs against the iteration or the elapsed seconds (default elapsed_s)\n"
        "\n"
        "usage: kpcn-train --average OUT.safetensors MODEL_OR_CHECKPOINT...\n"
        "  weight averaging (SWA): the mean of the weights of snapshots of one run (model\n"
        "  files and/or checkpoints of one architecture)\n"
        "\n"
        "usage: kpcn-train --record-exposure OUT.safetensors MODEL STORE.kps\n"
        "  a copy of MODEL (same weights) recording the median exposure of the training images\n"
        "  of the patch store it was trained on (a model trained by kpcn-train records it\n"
        "  itself); the denoiser shows the network every input at that exposure\n"
        "\n"
        "usage: kpcn-train --set-eps OUT.safetensors MODEL EPS\n"
        "  a copy of MODEL (same weights) with the albedo epsilon EPS (1e-9 <= EPS <= 0.5) in its\n"
        "  diffuse demodulation, diffuse / (albedo + EPS)\n"
        "\n"
        "usage: kpcn-train --graft OUT.safetensors MODEL diffuse|specular FROM\n"
        "  a copy of MODEL whose diffuse or specular branch has FROM's weights (same\n"
        "  architecture and exposure; a specular branch may come from a model of another eps)\n",
        f);
}

static int g_quiet = 0;
static void log_cb(void *u, kpcn_log_level l, const char *msg) {
  (void)u;
  if (!g_quiet || l == KPCN_LOG_WARNING) fprintf(stderr, "kpcn-train: %s\n", msg);
}

static void fmt_time(char *b, size_t n, double s) {
  if (!(s >= 0) || s > 1e8) s = 0;
  long t = (long)(s + 0.5);
  snprintf(b, n, "%ld:%02ld:%02ld", t / 3600, (t / 60) % 60, t % 60);
}

static int progress_cb(void *u, const kpcn_train_progress *p) {
  int tty = *(int *)u;
  if (p->has_val && !g_quiet)
    fprintf(stderr,
            "%sval @%lld: relMSE %.4g (geometric mean %.4g)  SSIM %.4f  PSNR %.2f dB (linear)\n",
            tty ? "\r\033[K" : "", (long long)p->iter, p->val_relmse, p->val_relmse_geo,
            p->val_ssim, p->val_psnr);
  if (tty) {
    char el[32], eta[32];
    fmt_time(el, sizeof el, p->elapsed_s);
    fmt_time(eta, sizeof eta, p->eta_s);
    fprintf(stderr,
            "\r\033[K%lld/%lld (%.1f%%) stage %d  loss %.4g  lr %.3g  %.2f it/s  %s, %s left",
            (long long)p->iter, (long long)p->total, 100.0 * p->iter / (p->total ? p->total : 1),
            p->stage, p->loss, p->lr, p->its_per_s, el, eta);
    fflush(stderr);
  }
  return g_stop;
}

static int parse_ll(const char *s, long long lo, long long hi, long long *out, const char *opt) {
  long long v = 0;
  if (!cli_parse_ll(s, lo, hi, &v)) {
    fprintf(stderr, "kpcn-train: %s: '%s' is not an integer in [%lld, %lld]\n", opt, s, lo, hi);
    return 0;
  }
  *out = v;
  return 1;
}

static int parse_d(const char *s, double lo, double hi, double *out, const char *opt) {
  double v = 0;
  if (!cli_parse_double(s, &v) || !(v >= lo && v <= hi)) {
    fprintf(stderr, "kpcn-train: %s: '%s' is not a number in [%g, %g]\n", opt, s, lo, hi);
    return 0;
  }
  *out = v;
  return 1;
}

#define MAX_VAL 512 /* full images kept in memory: 160x160 AOVs are ~4 MB each */
static char *g_valn[MAX_VAL], *g_valr[MAX_VAL];
static int g_nval = 0;

static int add_val(const char *noisy, const char *ref, size_t nlen) {
  if (g_nval >= MAX_VAL) {
    fprintf(stderr, "kpcn-train: at most %d validation pairs\n", MAX_VAL);
    return 0;
  }
  g_valn[g_nval] = strndup(noisy, nlen);
  g_valr[g_nval] = strdup(ref);
  g_nval++;
  return 1;
}

/* --val-store: every source of a validation store (the recipe's `patches --split val` store)
 * becomes a --val pair, its paths relative to the store's folder (as kpcn-dataset records
 * them). Returns 0 (message printed) on failure. */
static int val_from_store(const char *store) {
  kpcn_patchstore *ps;
  if (kpcn_patchstore_open(&ps, store, NULL, 0) != KPCN_OK) {
    fprintf(stderr, "kpcn-train: --val-store: %s\n", kpcn_last_error());
    return 0;
  }
  char dir[4096];
  snprintf(dir, sizeof dir, "%s", store);
  char *sl = strrchr(dir, '/');
  if (sl)
    sl[1] = 0;
  else
    dir[0] = 0;
  int ok = 1;
  for (int i = 0; i < kpcn_patchstore_nsources(ps) && ok; i++) {
    const kpcn_patch_source *s = kpcn_patchstore_source(ps, i);
    char n[8192], r[8192];
    snprintf(n, sizeof n, "%s%s", s->noisy[0] == '/' ? "" : dir, s->noisy);
    snprintf(r, sizeof r, "%s%s", s->reference[0] == '/' ? "" : dir, s->reference);
    struct stat sb;
    if (stat(n, &sb) != 0 || stat(r, &sb) != 0) {
      fprintf(stderr, "kpcn-train: --val-store: source '%s' / '%s' of '%s' not found\n", n, r,
              store);
      ok = 0;
      break;
    }
    ok = add_val(n, r, strlen(n));
  }
  kpcn_patchstore_close(ps);
  return ok;
}

/* The start of every mode that writes a file: out must be writable as a new file renamed into
 * place and must not be one of the n inputs. Returns 0, or the exit code 2 after the message. */
static int check_mode_output(const char *out, const char *mode, const char *const *in, int n) {
  kpcn_status st = kpcn_check_output_path(out, "output");
  for (int i = 0; st == KPCN_OK && i < n; i++)
    st = kpcn_check_not_input(out, "output", in[i], "input");
  if (st == KPCN_OK) return 0;
  fprintf(stderr, "kpcn-train %s: %s\n", mode, kpcn_last_error());
  return 2;
}

static int compare_main(int argc, char **argv) {
  if (argc < 3) {
    fprintf(stderr, "kpcn-train --compare: expected OUT.png LABEL=RUN.csv ... (see --help)\n");
    return 2;
  }
  const char *png = argv[2], *x = "elapsed_s", *y = "loss", *title = NULL;
  const char *labels[KPCN_PLOT_MAX_SERIES], *csvs[KPCN_PLOT_MAX_SERIES];
  char *owned[KPCN_PLOT_MAX_SERIES];
  int n = 0, log_y = 1;
  for (int i = 3; i < argc; i++) {
    if (!strcmp(argv[i], "--x") && i + 1 < argc)
      x = argv[++i];
    else if (!strcmp(argv[i], "--y") && i + 1 < argc)
      y = argv[++i];
    else if (!strcmp(argv[i], "--title") && i + 1 < argc)
      title = argv[++i];
    else if (!strcmp(argv[i], "--linear"))
      log_y = 0;
    else {
      const char *eq = strchr(argv[i], '=');
      if (!eq || eq == argv[i] || !eq[1] || n == KPCN_PLOT_MAX_SERIES) {
        fprintf(stderr, "kpcn-train --compare: expected LABEL=RUN.csv (at most %d), got '%s'\n",
                KPCN_PLOT_MAX_SERIES, argv[i]);
        return 2;
      }
      owned[n] = strndup(argv[i], (size_t)(eq - argv[i]));
      labels[n] = owned[n];
      csvs[n++] = eq + 1;
    }
  }
  if (!n) {
    fprintf(stderr, "kpcn-train --compare: no runs given\n");
    return 2;
  }
  if (kpcn_check_extension(png, ".png", "the plot", "PNG") != KPCN_OK) {
    fprintf(stderr, "kpcn-train --compare: %s\n", kpcn_last_error());
    for (int i = 0; i < n; i++)
      free(owned[i]);
    return 2;
  }
  if (check_mode_output(png, "--compare", csvs, n)) {
    for (int i = 0; i < n; i++)
      free(owned[i]);
    return 2;
  }
  kpcn_status st = kpcn_train_plot_compare(png, title ? title : y, x, y, log_y, n, labels, csvs);
  for (int i = 0; i < n; i++)
    free(owned[i]);
  if (st != KPCN_OK) {
    fprintf(stderr, "kpcn-train --compare: %s\n", kpcn_last_error());
    return 1;
  }
  return 0;
}

/* The end of every mode that writes a model: saves m to out if st is still KPCN_OK, frees
 * m, and on failure names the mode and the error. Returns the exit code (0 or 1). */
static int save_model_copy(kpcn_status st, kpcn_model *m, const char *out, const char *mode) {
  if (st == KPCN_OK) st = kpcn_model_save(m, out);
  kpcn_model_destroy(m);
  if (st != KPCN_OK) {
    fprintf(stderr, "kpcn-train %s: %s\n", mode, kpcn_last_error());
    return 1;
  }
  return 0;
}

static int average_main(int argc, char **argv) {
  if (argc < 4) {
    fprintf(stderr, "kpcn-train --average: expected OUT.safetensors and at least one input\n");
    return 2;
  }
  if (check_mode_output(argv[2], "--average", (const char *const *)argv + 3, argc - 3)) return 2;
  kpcn_model *m = NULL;
  kpcn_status st = kpcn_model_average((const char *const *)argv + 3, argc - 3, &m);
  if (save_model_copy(st, m, argv[2], "--average")) return 1;
  if (!g_quiet) printf("kpcn-train: %s = mean of %d snapshots\n", argv[2], argc - 3);
  return 0;
}

static int set_eps_main(int argc, char **argv) {
  if (argc != 5) {
    fprintf(stderr, "kpcn-train --set-eps: expected OUT.safetensors MODEL EPS\n");
    return 2;
  }
  double e = 0;
  if (!cli_parse_double(argv[4], &e) || !(e >= 1e-9 && e <= 0.5)) { /* --eps's range */
    fprintf(stderr, "kpcn-train --set-eps: EPS '%s' is not a number in [1e-9, 0.5]\n", argv[4]);
    return 2;
  }
  if (check_mode_output(argv[2], "--set-eps", (const char *const *)argv + 3, 1)) return 2;
  kpcn_model *m = NULL;
  kpcn_status st = kpcn_model_load(argv[3], &m);
  if (st == KPCN_OK) st = kpcn_model_set_eps(m, (float)e);
  if (save_model_copy(st, m, argv[2], "--set-eps")) return 1;
  if (!g_quiet) printf("kpcn-train: %s = %s with eps %.9g\n", argv[2], argv[3], (double)(float)e);
  return 0;
}

static int graft_main(int argc, char **argv) {
  if (argc != 6) {
    fprintf(stderr, "kpcn-train --graft: expected OUT.safetensors MODEL diffuse|specular FROM\n");
    return 2;
  }
  kpcn_branch b;
  if (!strcmp(argv[4], "diffuse"))
    b = KPCN_BRANCH_DIFFUSE;
  else if (!strcmp(argv[4], "specular"))
    b = KPCN_BRANCH_SPECULAR;
  else {
    fprintf(stderr, "kpcn-train --graft: branch '%s' is not diffuse or specular\n", argv[4]);
    return 2;
  }
  const char *const graft_in[2] = {argv[3], argv[5]};
  if (check_mode_output(argv[2], "--graft", graft_in, 2)) return 2;
  kpcn_model *m = NULL, *from = NULL;
  kpcn_status st = kpcn_model_load(argv[3], &m);
  if (st == KPCN_OK) st = kpcn_model_load(argv[5], &from);
  if (st == KPCN_OK) st = kpcn_model_graft_branch(m, from, b);
  char note[600];
  const char *base = strrchr(argv[5], '/');
  snprintf(note, sizeof note, "%s branch from %s", argv[4], base ? base + 1 : argv[5]);
  if (st == KPCN_OK) st = kpcn_model_set_meta(m, "train.grafted", note);
  kpcn_model_destroy(from);
  if (save_model_copy(st, m, argv[2], "--graft")) return 1;
  if (!g_quiet) printf("kpcn-train: %s = %s with the %s\n", argv[2], argv[3], note);
  return 0;
}

static int record_exposure_main(int argc, char **argv) {
  if (argc != 5) {
    fprintf(stderr, "kpcn-train --record-exposure: expected OUT.safetensors MODEL STORE.kps\n");
    return 2;
  }
  if (check_mode_output(argv[2], "--record-exposure", (const char *const *)argv + 3, 2)) return 2;
  kpcn_model *m = NULL;
  kpcn_patchstore *ps = NULL;
  double e = 0.0;
  kpcn_status st = kpcn_model_load(argv[3], &m);
  if (st == KPCN_OK) st = kpcn_patchstore_open(&ps, argv[4], NULL, 0);
  if (st == KPCN_OK) st = kpcn_patchstore_exposure(ps, &e);
  kpcn_patchstore_close(ps);
  if (st == KPCN_OK && !(e > 0.0)) {
    fprintf(stderr,
            "kpcn-train --record-exposure: patch store '%s' records no exposure of its "
            "training images (written before kpcn-dataset recorded them: run kpcn-dataset "
            "patches again)\n",
            argv[4]);
    kpcn_model_destroy(m);
    return 1;
  }
  if (st == KPCN_OK) st = kpcn_model_set_exposure(m, (float)e);
  if (save_model_copy(st, m, argv[2], "--record-exposure")) return 1;
  printf("kpcn-train: %s = %s recording exposure %.9g\n", argv[2], argv[3], (double)(float)e);
  return 0;
}

/* An --init model keeps its architecture; a shape option that disagrees with it is a mistake to
 * report, not to ignore (--widen, --kpa-passes, --eps and --source-weight are the changes it
 * takes). */
static int check_init_arch(const kpcn_train_settings *s, int preset, int layers, int channels,
                           int conv, int kernel, int dil) {
  kpcn_model *m = NULL;
  if (kpcn_model_load(s->init_model, &m) != KPCN_OK) {
    fprintf(stderr, "kpcn-train: %s\n", kpcn_last_error());
    return 1;
  }
  const kpcn_arch *a = kpcn_model_arch(m), *w = &s->arch;
  const char *bad = NULL;
  char want[64] = "", has[64] = "";
  if ((preset || layers) && w->n_hidden != a->n_hidden) {
    bad = layers ? "--layers" : "--preset";
    snprintf(want, sizeof want, "%d hidden layers", w->n_hidden);
    snprintf(has, sizeof has, "%d", a->n_hidden);
  } else if ((preset || channels) && !s->widen_channels && w->channels != a->channels) {
    bad = channels ? "--channels" : "--preset";
    snprintf(want, sizeof want, "%d channels", w->channels);
    snprintf(has, sizeof has, "%d", a->channels);
  } else if ((preset || kernel) && w->kernel_size != a->kernel_size) {
    bad = kernel ? "--kernel" : "--preset";
    snprintf(want, sizeof want, "kernel %d", w->kernel_size);
    snprintf(has, sizeof has, "%d", a->kernel_size);
  } else {
    for (int l = 0; l <= a->n_hidden && !bad; l++) {
      if ((preset || conv) && w->conv_size[l] != a->conv_size[l]) {
        bad = conv ? "--conv" : "--preset";
        snprintf(want, sizeof want, "conv size %d in layer %d", w->conv_size[l], l);
        snprintf(has, sizeof has, "%d", a->conv_size[l]);
      } else if ((preset || dil) && w->dilation[l] != a->dilation[l]) {
        bad = dil ? "--dilations" : "--preset";
        snprintf(want, sizeof want, "dilation %d in layer %d", w->dilation[l], l);
        snprintf(has, sizeof has, "%d", a->dilation[l]);
      }
    }
  }
  kpcn_model_destroy(m);
  if (!bad) return 0;
  fprintf(
      stderr,
      "kpcn-train: %s asks for %s, the --init model '%s' has %s: an --init model keeps its "
      "architecture (--widen, --kpa-passes, --eps and --source-weight are the changes it takes)\n",
      bad, want, s->init_model, has);
  return 2;
}

int main(int argc, char **argv) {
  if (argc >= 2 && !strcmp(argv[1], "--compare")) return compare_main(argc, argv);
  if (argc >= 2 && !strcmp(argv[1], "--record-exposure")) return record_exposure_main(argc, argv);
  if (argc >= 2 && !strcmp(argv[1], "--average")) return average_main(argc, argv);
  if (argc >= 2 && !strcmp(argv[1], "--set-eps")) return set_eps_main(argc, argv);
  if (argc >= 2 && !strcmp(argv[1], "--graft")) return graft_main(argc, argv);
  kpcn_train_settings s;
  kpcn_train_settings_defaults(&s);
  const char *preset = "cpu", *dil = NULL, *loss2 = NULL, *best_by = NULL;
  long long layers = -1, channels = -1, conv = -1, kernel = -1, ssim_win = -1, kpa_passes = -1, v;
  int source_weight = 0, preset_given = 0;
  const char *val_store = NULL; /* --val-store */
  double d, eps = 0;
  for (int i = 1; i < argc; i++) {
    const char *a = argv[i];
    const char *arg = i + 1 < argc ? argv[i + 1] : NULL;
#define NEEDARG                                                                                    \
  do {                                                                                             \
    if (!arg) {                                                                                    \
      fprintf(stderr, "kpcn-train: %s needs a value\n", a);                                        \
      return 2;                                                                                    \
    }                                                                                              \
    i++;                                                                                           \
  } while (0)
#define INT(name, lo, hi, dst)                                                                     \
  else if (!strcmp(a, name)) {                                                                     \
    NEEDARG;                                                                                       \
    if (!parse_ll(arg, lo, hi, &v, a)) return 2;                                                   \
    dst = v;                                                                                       \
  }
#define DBL(name, lo, hi, dst)                                                                     \
  else if (!strcmp(a, name)) {                                                                     \
    NEEDARG;                                                                                       \
    if (!parse_d(arg, lo, hi, &d, a)) return 2;                                                    \
    dst = d;                                                                                       \
  }
#define STR(name, dst)                                                                             \
  else if (!strcmp(a, name)) {                                                                     \
    NEEDARG;                                                                                       \
    dst = arg;                                                                                     \
  }
    if (!strcmp(a, "-h") || !strcmp(a, "--help")) {
      usage(stdout);
      return 0;
    }
    if (!strcmp(a, "--version")) {
      printf("kpcn-train %s\n%s\n", KPCN_VERSION_STRING, kpcn_build_info());
      return 0;
    }
    STR("--store", s.store_path)
    STR("-o", s.out_path)
    else if (!strcmp(a, "--preset")) {
      NEEDARG;
      preset = arg;
      preset_given = 1;
    }
    STR("--init", s.init_model)
    STR("--dilations", dil)
    STR("--ckpt", s.ckpt_path)
    STR("--csv", s.csv_path)
    STR("--plot", s.plot_path)
    STR("--best", s.best_path)
    STR("--snapshots", s.snapshot_dir)
    STR("--loss2", loss2)
    STR("--best-by", best_by)
    INT("--layers", 1, KPCN_NN_MAX_LAYERS - 1, layers)
    INT("--channels", 1, 1024, channels)
    INT("--widen", 1, 1024, s.widen_channels)
    INT("--kpa-passes", 1, KPCN_NN_MAX_KPA_PASSES, kpa_passes)
    else if (!strcmp(a, "--source-weight")) source_weight = 1;
    INT("--conv", 1, 11, conv)
    INT("--kernel", 3, KPCN_NN_MAX_KERNEL, kernel)
    INT("--ssim-window", 1, 63, ssim_win)
    INT("--loss-margin", 0, 512, s.loss_margin)
    INT("--batch", 1, 256, s.batch)
    INT("--patch", 8, 1024, s.patch)
    INT("--iters", 0, (long long)1e12, s.iters)
    INT("--stage1-iters", 0, (long long)1e12, s.stage1_iters)
    INT("--threads", 0, 1024, s.nthreads)
    INT("--seed", 0, (long long)9e18, s.seed)
    INT("--val-every", 0, (long long)1e12, s.val_every)
    INT("--ckpt-every", 0, (long long)1e12, s.ckpt_every)
    INT("--log-every", 1, (long long)1e12, s.log_every)
    INT("--decay-every", 0, (long long)1e12, s.adam.decay_every)
    DBL("--source-lr-scale", 1e-3, 1e4, s.source_lr_scale)
    DBL("--firefly", 1, 1e30, s.firefly)
    DBL("--lr", 1e-12, 10, s.adam.lr)
    DBL("--eps", 1e-9, 0.5, eps)
    DBL("--lr2", 1e-12, 1, s.stage2_lr)
    DBL("--lr-decay", 1e-6, 1, s.adam.lr_decay)
    DBL("--clip", 0, 1e12, s.adam.clip_norm)
    DBL("--time-limit", 0, 1e7, s.time_limit_s)
    else if (!strcmp(a, "--loss")) {
      NEEDARG;
      if (kpcn_loss_parse(arg, &s.loss1) != KPCN_OK) {
        fprintf(stderr, "kpcn-train: --loss: %s\n", kpcn_last_error());
        return 2;
      }
    }
    else if (!strcmp(a, "--val")) {
      NEEDARG;
      const char *comma = strchr(arg, ',');
      if (!comma || comma == arg || !comma[1]) {
        fprintf(stderr, "kpcn-train: --val expects NOISY.exr,REF.exr, got '%s'\n", arg);
        return 2;
      }
      if (!add_val(arg, comma + 1, (size_t)(comma - arg))) return 2;
    }
    else if (!strcmp(a, "--freeze")) {
      NEEDARG;
      if (!strcmp(arg, "diffuse"))
        s.frozen[KPCN_BRANCH_DIFFUSE] = 1;
      else if (!strcmp(arg, "specular"))
        s.frozen[KPCN_BRANCH_SPECULAR] = 1;
      else {
        fprintf(stderr, "kpcn-train: --freeze: '%s' is not diffuse or specular\n", arg);
        return 2;
      }
      if (s.frozen[0] && s.frozen[1]) {
        fprintf(stderr, "kpcn-train: --freeze given for both branches: nothing would train\n");
        return 2;
      }
    }
    else if (!strcmp(a, "--val-store")) {
      NEEDARG;
      val_store = arg;
    }
    else if (!strcmp(a, "--val-from-store")) {
      /* a store holds the one split it was cut from: its own 'val' sources would be images it
       * trains on, and a train store has none (the option then validated on nothing) */
      fprintf(stderr, "kpcn-train: --val-from-store is replaced by --val-store VAL.kps (a store "
                      "holds one split, so the training store's 'val' sources are images it "
                      "trains on, or none)\n");
      return 2;
    }
    else if (!strcmp(a, "--staircase")) s.adam.staircase = 1;
    else if (!strcmp(a, "--resume")) s.resume = 1;
    else if (!strcmp(a, "--bf16")) s.bf16 = 1;
    else if (!strcmp(a, "--no-colorswap")) s.augment.colorswap = 0;
    else if (!strcmp(a, "--no-mirror")) s.augment.mirror = s.augment.mirror_v = 0;
    else if (!strcmp(a, "--no-rotate")) s.augment.rotate = 0;
    else if (!strcmp(a, "--no-shift")) s.crop_jitter = 0;
    else if (!strcmp(a, "--normalize-exposure")) s.normalize_exposure = 1;
    else if (!strcmp(a, "--quiet")) g_quiet = 1;
    else if (!strcmp(a, "--compare") || !strcmp(a, "--average") ||
             !strcmp(a, "--record-exposure") || !strcmp(a, "--set-eps") || !strcmp(a, "--graft")) {
      /* These are modes of their own, not options of a training run. */
      fprintf(stderr,
              "kpcn-train: %s must be the first argument (and takes its own arguments; see "
              "--help)\n",
              a);
      return 2;
    }
    else {
      fprintf(stderr, "kpcn-train: unknown option '%s' (see --help)\n", a);
      return 2;
    }
  }
  if (!s.store_path || !s.out_path) {
    fprintf(stderr, "kpcn-train: --store and -o are required\n");
    usage(stderr);
    return 2;
  }
  s.time_limit_s *= 60.0;
  if (best_by && strcmp(best_by, "mean") && strcmp(best_by, "geomean")) {
    fprintf(stderr, "kpcn-train: --best-by: '%s' is not mean or geomean\n", best_by);
    return 2;
  }
  if (best_by) s.best_by = strcmp(best_by, "geomean") == 0 ? KPCN_VAL_GEOMEAN : KPCN_VAL_MEAN;
  s.loss2 = s.loss1;
  if (loss2 && kpcn_loss_parse(loss2, &s.loss2) != KPCN_OK) {
    fprintf(stderr, "kpcn-train: --loss2: %s\n", kpcn_last_error());
    return 2;
  }
  if (ssim_win > 0) s.loss.ssim_window = (int)ssim_win;
  if (kpcn_arch_preset(preset, &s.arch) != KPCN_OK) {
    fprintf(stderr, "kpcn-train: --preset: %s\n", kpcn_last_error());
    return 2;
  }
  if (layers > 0) {
    /* hidden layers keep the preset's first conv size (dilation 1 beyond the preset's
     * depth); the output layer keeps its own conv size */
    int hid = s.arch.conv_size[0], out = s.arch.conv_size[s.arch.n_hidden], old = s.arch.n_hidden;
    for (int l = 0; l < layers; l++) {
      s.arch.conv_size[l] = hid;
      if (l >= old) s.arch.dilation[l] = 1;
    }
    s.arch.n_hidden = (int)layers;
    s.arch.conv_size[layers] = out;
    s.arch.dilation[layers] = 1;
  }
  if (channels > 0) s.arch.channels = (int)channels;
  if (conv > 0)
    for (int l = 0; l <= s.arch.n_hidden; l++)
      s.arch.conv_size[l] = (int)conv;
  if (kernel > 0) s.arch.kernel_size = (int)kernel;
  if (kpa_passes > 0) s.arch.kpa_passes = s.kpa_passes = (int)kpa_passes;
  if (source_weight) s.arch.source_weight = s.source_weight = 1;
  if (eps > 0) s.arch.eps = s.eps = (float)eps;
  if (dil) {
    const char *p = dil;
    for (int l = 0; l <= s.arch.n_hidden; l++) {
      char *end;
      /* digits only: strtol would also take a blank or a sign before them */
      long dv = *p >= '0' && *p <= '9' ? strtol(p, &end, 10) : (end = (char *)p, 0);
      if (end == p || dv < 1 || dv > 64) {
        fprintf(stderr,
                "kpcn-train: --dilations '%s': item %d is not an integer in [1, 64] (up to %d "
                "items, one per conv layer; the rest are 1)\n",
                dil, l + 1, s.arch.n_hidden + 1);
        return 2;
      }
      s.arch.dilation[l] = (int)dv;
      p = end;
      if (*p == ',' && l < s.arch.n_hidden)
        p++;
      else if (*p == 0 && l < s.arch.n_hidden) {
        for (int r = l + 1; r <= s.arch.n_hidden; r++)
          s.arch.dilation[r] = 1; /* rest: 1 */
        break;
      }
    }
    if (*p) {
      fprintf(stderr,
              "kpcn-train: --dilations '%s': at most %d positive integers (one per conv "
              "layer), separated by commas\n",
              dil, s.arch.n_hidden + 1);
      return 2;
    }
  }
  if (ssim_win > 0 && s.loss1 != KPCN_LOSS_SSIM && s.loss2 != KPCN_LOSS_SSIM) {
    fprintf(stderr,
            "kpcn-train: --ssim-window has no effect: neither --loss nor --loss2 is ssim\n");
    return 2;
  }
  if (ssim_win > 0 && ssim_win % 2 == 0) {
    fprintf(stderr, "kpcn-train: --ssim-window %lld: the window must be odd\n", ssim_win);
    return 2;
  }
  if (channels > 0 && s.widen_channels > 0 && channels != s.widen_channels) {
    fprintf(stderr, "kpcn-train: --channels %lld conflicts with --widen %d\n", channels,
            s.widen_channels);
    return 2;
  }
  if (s.source_lr_scale > 0 && !s.arch.source_weight && !s.init_model) {
    fprintf(stderr, "kpcn-train: --source-lr-scale has no effect without --source-weight\n");
    return 2;
  }
  if (s.init_model &&
      (preset_given || layers > 0 || channels > 0 || conv > 0 || kernel > 0 || dil)) {
    int r = check_init_arch(&s, preset_given, layers > 0, channels > 0, conv > 0, kernel > 0,
                            dil != NULL);
    if (r) return r;
  }
  if (val_store && s.store_path && kpcn_same_file(val_store, s.store_path)) {
    fprintf(stderr,
            "kpcn-train: --val-store '%s' is the training store: it would validate on "
            "the images it trains on\n",
            val_store);
    return 2;
  }
  /* the validation store's pairs first, so that the usage check below sees them (an output
   * that is one of their files is a usage mistake, exit 2) */
  if (val_store && !val_from_store(val_store)) return 1;
  if (s.val_every > 0 && g_nval == 0) {
    fprintf(stderr, "kpcn-train: --val-every has no effect without --val or --val-store\n");
    return 2;
  }
  if (best_by && !(s.best_path && *s.best_path)) {
    fprintf(stderr, "kpcn-train: --best-by has no effect without --best\n");
    return 2;
  }
  s.nval = g_nval;
  s.val_noisy = (const char *const *)g_valn;
  s.val_ref = (const char *const *)g_valr;
  /* usage mistakes (an output in a missing folder, --freeze without --init, ...) exit 2
   * before the store is read, as in the other tools */
  if (kpcn_train_settings_check(&s) != KPCN_OK) {
    fprintf(stderr, "kpcn-train: %s\n", kpcn_last_error());
    return 2;
  }
  s.log = log_cb;
  int tty = isatty(2);
  s.progress = progress_cb;
  s.progress_user = &tty;
  signal(SIGINT, on_signal);
  signal(SIGTERM, on_signal);

  kpcn_trainer *t = NULL;
  if (kpcn_trainer_create(&t, &s) != KPCN_OK) {
    fprintf(stderr, "kpcn-train: %s\n", kpcn_last_error());
    return 1;
  }
  if (!g_quiet)
    fprintf(stderr,
            "kpcn-train: %s architecture%s, %lld iterations (stage 1: %lld), batch %d of %dx%d, "
            "%.1f GFLOP/iteration%s\n",
            kpcn_model_arch(kpcn_trainer_model(t))->name, s.init_model ? " (from --init)" : "",
            (long long)s.iters, (long long)kpcn_trainer_stage1_iters(t), s.batch, s.patch, s.patch,
            kpcn_trainer_flops_per_iter(t) * 1e-9, s.resume ? ", resuming" : "");
  int stopped = 0;
  kpcn_status st = kpcn_trainer_run(t, &stopped);
  if (tty) fputs("\n", stderr);
  if (st != KPCN_OK) {
    fprintf(stderr, "kpcn-train: %s\n", kpcn_last_error());
    kpcn_trainer_destroy(t);
    return 1;
  }
  if (!g_quiet)
    fprintf(stderr, "kpcn-train: %s at iteration %lld; model '%s'%s\n",
            stopped ? "stopped" : "finished", (long long)kpcn_trainer_iteration(t), s.out_path,
            stopped ? " (resume with --resume)" : "");
  kpcn_trainer_destroy(t);
  for (int i = 0; i < g_nval; i++)
    free(g_valn[i]), free(g_valr[i]);
  /* stopped by a signal: checkpointed, but not finished, which a script must be able to tell
   * (128 + the signal, as kpcn-render and kpcn-dataset); a --time-limit stop is the run's plan */
  return g_stop ? 128 + g_stop : 0;
}
