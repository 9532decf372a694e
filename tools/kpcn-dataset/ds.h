/* kpcn-dataset internals: manifest jobs, small file helpers, the three subcommands. */
#ifndef KPCN_DATASET_TOOL_H
#define KPCN_DATASET_TOOL_H

#include "cli_parse.h"

#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

#define DS_PATH 1024
/* Largest render side `plan` accepts (--resolution, a scene's camera.resolution) and a
 * manifest may hold. */
#define DS_MAX_DIM 16384
/* Most perturbed variants per scene (--variants) and most samples per pixel (--ref-spp). */
#define DS_MAX_VARIANTS 100000
#define DS_MAX_SPP (1 << 24)
/* Render seeds are 31-bit (they fit any renderer's int --seed); docs/dataset.md. */
#define DS_MAX_SEED 2147483647u

typedef enum ds_kind { DS_PREVIEW = 0, DS_NOISY, DS_REFERENCE } ds_kind;

/* One independent render job (one line of manifest.jsonl). Paths are relative to the
 * dataset directory. */
typedef struct ds_job {
  char id[192]; /* "<scene>/v003/16spp", "<scene>/v003/ref", "<scene>/v003/preview" */
  ds_kind kind;
  char scene[128]; /* base scene name: the split unit */
  int variant;
  char split[16];
  char scene_file[DS_PATH];
  int spp;
  uint64_t seed;
  int width, height;
  char out[DS_PATH];
  char preview[DS_PATH]; /* preview render of this variant ("" = no degenerate check) */
  int albedo_footprint;  /* kpcn-render --albedo-footprint (noisy jobs; 0 = not passed) */
} ds_job;

typedef struct ds_manifest {
  ds_job *jobs;
  int n, cap;
} ds_manifest;

/* manifest.c */
int ds_manifest_push(ds_manifest *m, const ds_job *j);
void ds_manifest_free(ds_manifest *m);
/* Writes dir/manifest.jsonl atomically. Returns 0 on success (error printed). */
int ds_manifest_write(const char *dir, const ds_manifest *m);
/* Reads dir/manifest.jsonl; errors name the line. */
int ds_manifest_read(const char *dir, ds_manifest *m);
const char *ds_kind_name(ds_kind k);

/* util.c */
extern const char *ds_prog;
void ds_err(const char *fmt, ...) __attribute__((format(printf, 1, 2)));
int ds_mkdir_p(const char *path);
int ds_exists(const char *path);
int ds_check_render(const char *path, const ds_job *j);
void ds_join(char *out, size_t n, const char *a, const char *b);
/* The whole file, NUL-terminated (NULL on failure; why, if given, then says why). */
char *ds_slurp(const char *path, size_t *len, const char **why);
int ds_write_atomic(const char *path, const char *data, size_t len);
/* A comma list of distinct integers in [1, hi] ("4,16,64"): no empty item, at most cap of
 * them. Returns how many, or -1. */
int ds_parse_int_list(const char *s, long hi, int *out, int cap);
/* Decimal digits only, value <= hi (no sign, no blanks, no overflow). */
int ds_parse_u64(const char *s, uint64_t hi, uint64_t *out);
uint64_t ds_hash(const char *s, uint64_t seed);
double ds_now(void);
int ds_isatty(void);
/* A progress line on stderr, "[done/total] DETAIL, Es elapsed, ~Ls left" (DESIGN.md §9): on a
 * terminal rewritten in place at every call; elsewhere (the log of a run under nohup, hours
 * long) a line of its own at most every `every` seconds (*last: the previous line's time,
 * start at -1e300) and when final is set. */
void ds_progress(double *last, double every, int final, int done, int total, double elapsed,
                 double eta, const char *detail);

/* subcommands */
int ds_cmd_plan(int argc, char **argv);
int ds_cmd_run(int argc, char **argv);
int ds_cmd_patches(int argc, char **argv);

#endif
