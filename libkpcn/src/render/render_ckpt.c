/* Render checkpoints (DESIGN.md §9; kpcn_render_settings.checkpoint): the finished rows of a
 * render, so that an interrupted one continues where it stopped. A row's pixels depend only on
 * the scene, the settings and the row (kpcn/render.h, "Determinism"), so a resumed render that
 * skips the saved rows is bit-identical to an uninterrupted one, at any thread count.
 *
 * File (native byte order; written atomically, temp file + rename):
 *   "KPCNRCK1"                      magic
 *   u64 L, L bytes of JSON          what the rows belong to (render_ckpt_header): a resume
 *                                   refuses a file whose JSON differs, naming the first key
 *   u8  done[h]                     1 for a finished row
 *   u64 rays[h], u64 nonfinite[h]   per-row statistics (kpcn_render_stats)
 *   f32 planes[P][h][w]             the set's planes (buf then var, buffer order); rows not
 *                                   done are zeros
 *   u64 hash                        FNV-1a from done[] on, one step per flag byte, per u64
 *                                   count and per float's 32 bits (4-8x fewer steps than
 *                                   per byte): damage is an error, never a render made of it */
#include "render/render_internal.h"

#include "core/internal.h"

#include <cjson/cJSON.h>
#include <errno.h>
#include <float.h>
#include <inttypes.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#define CK_MAGIC "KPCNRCK1"
#define CK_FORMAT "kpcn-render-checkpoint-1"

struct kpcn_render_ckpt {
  char *path;
  char *header; /* JSON, unformatted */
  kpcn_aov_set *set;
  int w, h;
  uint8_t *done; /* written by render threads with release stores */
  uint64_t *rays, *nonfinite;
};

#define FNV0 0xcbf29ce484222325ull
#define FNV_PRIME 0x100000001b3ull
static uint64_t fnv_bytes(uint64_t hash, const uint8_t *b, size_t n) {
  for (size_t i = 0; i < n; i++)
    hash = (hash ^ b[i]) * FNV_PRIME;
  return hash;
}
static uint64_t fnv_u64(uint64_t hash, const uint64_t *v, size_t n) {
  for (size_t i = 0; i < n; i++)
    hash = (hash ^ v[i]) * FNV_PRIME;
  return hash;
}
static uint64_t fnv_f32(uint64_t hash, const float *v, size_t n) {
  for (size_t i = 0; i < n; i++) {
    uint32_t bits;
    memcpy(&bits, &v[i], 4);
    hash = (hash ^ bits) * FNV_PRIME;
  }
  return hash;
}

/* The set's float planes in file order: per buffer its channels, then its variance. */
static int plane_count(const kpcn_aov_set *set) {
  int n = 0;
  for (int b = 0; b < KPCN_BUF_COUNT; b++)
    n += (set->buf[b] ? kpcn_buffer_channels((kpcn_buffer)b) : 0) + (set->var[b] ? 1 : 0);
  return n;
}

static float *plane_at(const kpcn_aov_set *set, int k) {
  const size_t plane = kpcn_aov_plane_size(set);
  for (int b = 0; b < KPCN_BUF_COUNT; b++) {
    const int nc = set->buf[b] ? kpcn_buffer_channels((kpcn_buffer)b) : 0;
    if (k < nc) return set->buf[b] + (size_t)k * plane;
    k -= nc;
    if (set->var[b] && k-- == 0) return set->var[b];
  }
  return NULL;
}

kpcn_status kpcn_render_ckpt_create(kpcn_render_ckpt **out, const char *path, const cJSON *what,
                                    kpcn_aov_set *set) {
  *out = NULL;
  kpcn_render_ckpt *c = calloc(1, sizeof *c);
  if (!c) return kpcn_fail(KPCN_ERR_OUT_OF_MEMORY, "render checkpoint: out of memory");
  const size_t h = (size_t)set->height;
  c->path = path ? strdup(path) : NULL;
  if (path) { /* the identity with the file's format in front */
    cJSON *hdr = cJSON_CreateObject(), *dup = cJSON_Duplicate(what, 1);
    if (hdr && dup && cJSON_AddStringToObject(hdr, "format", CK_FORMAT)) {
      cJSON *e;
      while ((e = dup->child) != NULL)
        cJSON_AddItemToObject(hdr, e->string, cJSON_DetachItemViaPointer(dup, e));
      c->header = cJSON_PrintUnformatted(hdr);
    }
    cJSON_Delete(hdr);
    cJSON_Delete(dup);
  }
  c->done = calloc(h, 1);
  c->rays = calloc(h, sizeof *c->rays);
  c->nonfinite = calloc(h, sizeof *c->nonfinite);
  c->set = set, c->w = set->width, c->h = set->height;
  if ((path && (!c->path || !c->header)) || !c->done || !c->rays || !c->nonfinite) {
    kpcn_render_ckpt_destroy(c);
    return kpcn_fail(KPCN_ERR_OUT_OF_MEMORY, "render checkpoint: out of memory");
  }
  *out = c;
  return KPCN_OK;
}

void kpcn_render_ckpt_destroy(kpcn_render_ckpt *c) {
  if (!c) return;
  free(c->path);
  free(c->header);
  free(c->done);
  free(c->rays);
  free(c->nonfinite);
  free(c);
}

void kpcn_render_ckpt_row_done(kpcn_render_ckpt *c, int row, uint64_t rays, uint64_t nonfinite) {
  c->rays[row] = rays;
  c->nonfinite[row] = nonfinite;
  __atomic_store_n(&c->done[row], 1, __ATOMIC_RELEASE); /* after the row's pixels and counts */
}

int kpcn_render_ckpt_is_done(const kpcn_render_ckpt *c, int row) {
  return __atomic_load_n(&c->done[row], __ATOMIC_ACQUIRE);
}

void kpcn_render_ckpt_totals(const kpcn_render_ckpt *c, uint64_t *rays, uint64_t *nonfinite) {
  *rays = *nonfinite = 0;
  for (int r = 0; r < c->h; r++)
    *rays += c->rays[r], *nonfinite += c->nonfinite[r];
}

/* fwrite; sets *ok = 0 on a short write. */
static void put(FILE *f, const void *p, size_t n, int *ok) {
  if (*ok && n && fwrite(p, 1, n, f) != n) *ok = 0;
}

kpcn_status kpcn_render_ckpt_probe(const kpcn_render_ckpt *c) {
  if (!c->path) return KPCN_OK;
  char tmp[4096];
  KPCN_TRY(kpcn_temp_path(tmp, sizeof tmp, c->path));
  FILE *f = fopen(tmp, "wb");
  if (!f)
    return kpcn_fail(KPCN_ERR_IO, "cannot write render checkpoint '%s': %s", tmp, strerror(errno));
  fclose(f);
  kpcn_abort_file(tmp);
  return KPCN_OK;
}

kpcn_status kpcn_render_ckpt_save(const kpcn_render_ckpt *c) {
  if (!c->path) return KPCN_OK;
  const size_t h = (size_t)c->h, w = (size_t)c->w;
  /* one snapshot of the flags: a row finishing while this runs is saved next time */
  uint8_t *done = malloc(h);
  float *zeros = calloc(w, sizeof(float));
  if (!done || !zeros) {
    free(done);
    free(zeros);
    return kpcn_fail(KPCN_ERR_OUT_OF_MEMORY, "render checkpoint '%s': out of memory", c->path);
  }
  for (size_t r = 0; r < h; r++)
    done[r] = (uint8_t)kpcn_render_ckpt_is_done(c, (int)r);
  uint64_t *rays = calloc(2 * h, sizeof(uint64_t)), *nonfinite = rays ? rays + h : NULL;
  if (!rays) {
    free(done);
    free(zeros);
    return kpcn_fail(KPCN_ERR_OUT_OF_MEMORY, "render checkpoint '%s': out of memory", c->path);
  }
  for (size_t r = 0; r < h; r++)
    if (done[r]) rays[r] = c->rays[r], nonfinite[r] = c->nonfinite[r];
  char tmp[4096];
  kpcn_status st = kpcn_temp_path(tmp, sizeof tmp, c->path);
  FILE *f = st == KPCN_OK ? fopen(tmp, "wb") : NULL;
  if (st == KPCN_OK && !f)
    st = kpcn_fail(KPCN_ERR_IO, "cannot write render checkpoint '%s': %s", tmp, strerror(errno));
  if (f) {
    int ok = 1;
    uint64_t len = strlen(c->header);
    uint64_t hash = fnv_u64(fnv_u64(fnv_bytes(FNV0, done, h), rays, h), nonfinite, h);
    put(f, CK_MAGIC, 8, &ok);
    put(f, &len, 8, &ok);
    put(f, c->header, len, &ok);
    put(f, done, h, &ok);
    put(f, rays, h * sizeof(uint64_t), &ok);
    put(f, nonfinite, h * sizeof(uint64_t), &ok);
    const int np = plane_count(c->set);
    for (int k = 0; k < np; k++) {
      const float *p = plane_at(c->set, k);
      for (size_t r = 0; r < h; r++) {
        const float *row = done[r] ? p + r * w : zeros;
        hash = fnv_f32(hash, row, w);
        put(f, row, w * sizeof(float), &ok);
      }
    }
    put(f, &hash, 8, &ok);
    /* on the disk before the rename: after a crash the name holds the old file or the new
     * one, never an empty one that every later resume would refuse as damaged */
    int err = ok ? 0 : errno; /* the failed put's reason (nothing since has touched errno) */
    if (ok && (fflush(f) != 0 || fsync(fileno(f)) != 0)) ok = 0, err = errno;
    if (fclose(f) != 0 && ok) ok = 0, err = errno;
    if (!ok) {
      kpcn_abort_file(tmp);
      st = kpcn_fail(KPCN_ERR_IO, "cannot write render checkpoint '%s': %s", c->path,
                     kpcn_write_reason(err));
    } else
      st = kpcn_commit_file(tmp, c->path);
  }
  free(done);
  free(zeros);
  free(rays);
  return st;
}

/* The first top-level key whose value differs between two headers (NULL if none). */
static const char *first_difference(const cJSON *a, const cJSON *b) {
  const cJSON *e;
  cJSON_ArrayForEach(e, a) {
    const cJSON *o = cJSON_GetObjectItemCaseSensitive(b, e->string);
    if (!o || !cJSON_Compare(e, o, 1)) return e->string;
  }
  cJSON_ArrayForEach(e, b) {
    if (!cJSON_GetObjectItemCaseSensitive(a, e->string)) return e->string;
  }
  return NULL;
}

#define DAMAGED(...)                                                                               \
  do {                                                                                             \
    st = kpcn_fail(KPCN_ERR_FORMAT, __VA_ARGS__);                                                  \
    goto done;                                                                                     \
  } while (0)

kpcn_status kpcn_render_ckpt_load(kpcn_render_ckpt *c, int *rows) {
  *rows = 0;
  if (!c->path) return KPCN_OK;
  const char *why;
  FILE *f = kpcn_fopen_input(c->path, &why);
  if (!f) {
    if (errno == ENOENT) return KPCN_OK; /* nothing saved yet: a fresh start */
    return kpcn_fail(KPCN_ERR_IO, "cannot open render checkpoint '%s': %s", c->path, why);
  }
  kpcn_status st = KPCN_OK;
  char *hdr = NULL;
  cJSON *got = NULL, *want = NULL;
  const size_t h = (size_t)c->h, w = (size_t)c->w;
  const int np = plane_count(c->set);
  const uint64_t body = h * (1 + 2 * sizeof(uint64_t)) + (uint64_t)np * h * w * sizeof(float);
  char magic[8];
  uint64_t len = 0, hash = FNV0, stored;
  fseek(f, 0, SEEK_END);
  const uint64_t fsize = (uint64_t)ftell(f);
  fseek(f, 0, SEEK_SET);
  if (fread(magic, 1, 8, f) != 8 || memcmp(magic, CK_MAGIC, 8) != 0 || fread(&len, 8, 1, f) != 1)
    DAMAGED("'%s' is not a kpcn-render checkpoint (remove it to start the render again)", c->path);
  if (len == 0 || len > (1u << 20) || 16 + len > fsize)
    DAMAGED("render checkpoint '%s' is damaged: header length %" PRIu64 " (remove it to start "
            "again)",
            c->path, len);
  hdr = malloc(len + 1);
  if (!hdr) DAMAGED("render checkpoint '%s': out of memory", c->path);
  if (fread(hdr, 1, len, f) != len) DAMAGED("render checkpoint '%s' is truncated", c->path);
  hdr[len] = 0;
  got = cJSON_Parse(hdr);
  want = cJSON_Parse(c->header);
  if (!got || !cJSON_IsObject(got))
    DAMAGED("render checkpoint '%s' is damaged: its header is not JSON (remove it to start "
            "again)",
            c->path);
  const char *key = want ? first_difference(want, got) : "format";
  if (key) {
    char *mine = cJSON_PrintUnformatted(cJSON_GetObjectItemCaseSensitive(want, key)),
         *theirs = cJSON_PrintUnformatted(cJSON_GetObjectItemCaseSensitive(got, key));
    st = kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                   "render checkpoint '%s' belongs to another render: its %s is %s, this "
                   "render's is %s (remove it, or give this render another checkpoint path)",
                   c->path, key, theirs ? theirs : "(missing)", mine ? mine : "(missing)");
    free(mine);
    free(theirs);
    goto done;
  }
  if (fsize != 16 + len + body + 8)
    DAMAGED("render checkpoint '%s' is damaged: %" PRIu64 " bytes where %" PRIu64
            " were written (remove it to start again)",
            c->path, fsize, 16 + len + body + 8);
  int ok = fread(c->done, 1, h, f) == h && fread(c->rays, 8, h, f) == h &&
           fread(c->nonfinite, 8, h, f) == h;
  hash = fnv_u64(fnv_u64(fnv_bytes(hash, c->done, h), c->rays, h), c->nonfinite, h);
  for (int k = 0; k < np && ok; k++) {
    float *p = plane_at(c->set, k);
    ok = fread(p, sizeof(float), h * w, f) == h * w;
    hash = fnv_f32(hash, p, h * w);
  }
  if (!ok || fread(&stored, 8, 1, f) != 1) DAMAGED("render checkpoint '%s' is truncated", c->path);
  if (stored != hash)
    DAMAGED("render checkpoint '%s' is damaged (its checksum does not match; remove it to start "
            "again)",
            c->path);
  for (size_t r = 0; r < h; r++) {
    if (c->done[r] > 1) DAMAGED("render checkpoint '%s' is damaged (row flags)", c->path);
    *rows += c->done[r];
  }
  /* What a render writes: finite values (non-finite samples count as black, variances are
   * clamped to FLT_MAX); albedo, depth, visibility and variances >= 0, visibility <= 1,
   * normal components in [-1, 1]. Anything else was not written by a render, whatever its
   * checksum says. */
  for (int b = 0; b < KPCN_BUF_COUNT; b++) {
    const int nc = c->set->buf[b] ? kpcn_buffer_channels((kpcn_buffer)b) : 0;
    for (int ch = 0; ch <= nc; ch++) { /* its channels, then its variance */
      const int var = ch == nc;
      const float *p = var ? c->set->var[b] : c->set->buf[b] + (size_t)ch * h * w;
      if (!p) continue;
      /* radiance is only required finite (its diffuse/specular split is a difference);
       * normals and visibility get rounding room */
      const int radiance = !var && kpcn_buffer_is_color((kpcn_buffer)b) && b != KPCN_BUF_ALBEDO;
      const float lo = radiance                       ? -FLT_MAX
                       : b == KPCN_BUF_NORMAL && !var ? -1.001f
                                                      : 0.0f,
                  hi =
                      !var && (b == KPCN_BUF_NORMAL || b == KPCN_BUF_VISIBILITY) ? 1.001f : FLT_MAX;
      for (size_t i = 0; i < h * w; i++)
        if (!(p[i] >= lo && p[i] <= hi))
          DAMAGED("render checkpoint '%s' is damaged (%s%s value %g in row %zu is not one a "
                  "render writes)",
                  c->path, kpcn_buffer_name((kpcn_buffer)b), var ? " variance" : "", (double)p[i],
                  i / w);
    }
  }
done:
  if (st != KPCN_OK) { /* leave nothing half-loaded behind: the render starts from zeros */
    memset(c->done, 0, h);
    memset(c->rays, 0, h * 8);
    memset(c->nonfinite, 0, h * 8);
    for (int k = 0; k < np; k++)
      memset(plane_at(c->set, k), 0, h * w * sizeof(float));
    *rows = 0;
  }
  fclose(f);
  free(hdr);
  cJSON_Delete(got);
  cJSON_Delete(want);
  return st;
}
