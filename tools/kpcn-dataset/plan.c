/* `kpcn-dataset plan`: base scenes -> perturbed scene JSONs + manifest of render jobs.
 * Split by BASE scene (every variant of a scene lands in the same split); only training
 * scenes are perturbed (seed Table 3.1), unless --eval-variants is given. */
#define _GNU_SOURCE
#include "ds.h"
#include "kpcn/dataset.h"

#include <cjson/cJSON.h>
#include <dirent.h>
#include <errno.h>
#include <glob.h>
#include <limits.h>
#include <ctype.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

typedef struct base_scene {
  char name[128];
  char file[DS_PATH]; /* absolute path of its JSON */
  char dir[DS_PATH];
  char split[16];
} base_scene;

static int cmp_scene(const void *a, const void *b) {
  return strcmp(((const base_scene *)a)->name, ((const base_scene *)b)->name);
}

/* DIR/<name>/scene.json, else DIR/<name>/<the only>.json, else DIR/<name>.json. */
static int find_scenes(const char *dir, base_scene **out, int *n) {
  DIR *d = opendir(dir);
  if (!d) {
    ds_err("--scenes: cannot open directory '%s': %s", dir, strerror(errno));
    return -1;
  }
  base_scene *v = NULL;
  int cnt = 0;
  struct dirent *e;
  while ((e = readdir(d))) {
    if (e->d_name[0] == '.') continue;
    char p[DS_PATH], f[DS_PATH] = "";
    ds_join(p, sizeof p, dir, e->d_name);
    size_t nl = strlen(e->d_name);
    base_scene s;
    memset(&s, 0, sizeof s);
    if (nl > 5 && !strcmp(e->d_name + nl - 5, ".json") && ds_exists(p)) {
      snprintf(f, sizeof f, "%s", p);
      snprintf(s.name, sizeof s.name, "%.*s", (int)(nl - 5), e->d_name);
    } else {
      char sj[DS_PATH];
      ds_join(sj, sizeof sj, p, "scene.json");
      if (ds_exists(sj))
        snprintf(f, sizeof f, "%s", sj);
      else {
        DIR *sd = opendir(p);
        if (!sd) continue;
        struct dirent *se;
        int found = 0;
        while ((se = readdir(sd))) {
          size_t l = strlen(se->d_name);
          if (l > 5 && !strcmp(se->d_name + l - 5, ".json")) {
            found++;
            ds_join(f, sizeof f, p, se->d_name);
          }
        }
        closedir(sd);
        if (found != 1) {
          if (found > 1)
            ds_err("warning: '%s' holds %d .json files and no scene.json: skipped", p, found);
          continue;
        }
      }
      snprintf(s.name, sizeof s.name, "%s", e->d_name);
    }
    char *rp = realpath(f, NULL);
    if (!rp) continue;
    snprintf(s.file, sizeof s.file, "%s", rp);
    free(rp);
    snprintf(s.dir, sizeof s.dir, "%s", s.file);
    char *slash = strrchr(s.dir, '/');
    if (slash) *slash = 0;
    v = realloc(v, sizeof *v * (size_t)(cnt + 1));
    v[cnt++] = s;
  }
  closedir(d);
  if (cnt == 0) {
    ds_err("--scenes: no scene found in '%s' (expected <name>/scene.json or <name>.json)", dir);
    free(v);
    return -1;
  }
  qsort(v, (size_t)cnt, sizeof *v, cmp_scene);
  *out = v;
  *n = cnt;
  return 0;
}

/* "train:0.7,val:0.15,test:0.15" (fractions, scenes shuffled with the seed) or
 * "train:a+b,val:c,test:d" (names). */
static int assign_splits(base_scene *s, int n, const char *spec, uint64_t seed) {
  if (!spec) {
    for (int i = 0; i < n; i++)
      strcpy(s[i].split, "train");
    return 0;
  }
  /* strtok_r below would skip an empty item ("train:0.5,,val:0.5", a trailing comma): a typo */
  const size_t len = strlen(spec);
  if (!len || spec[0] == ',' || spec[len - 1] == ',' || strstr(spec, ",,")) {
    ds_err("--split: '%s' has an empty item (split:value items separated by single commas)", spec);
    return -1;
  }
  char buf[4096];
  snprintf(buf, sizeof buf, "%s", spec);
  char names[8][16];
  double frac[8];
  int nsplit = 0, fractions = -1;
  char *save = NULL;
  for (char *tok = strtok_r(buf, ",", &save); tok; tok = strtok_r(NULL, ",", &save)) {
    char *colon = strchr(tok, ':');
    if (!colon || colon == tok || colon - tok >= 16) {
      ds_err("--split: '%s' is not split:value (e.g. train:0.8 or val:sceneA+sceneB; split names "
             "up to 15 characters)",
             tok);
      return -1;
    }
    if (nsplit == 8) {
      ds_err("--split: more than 8 splits in '%s'", spec);
      return -1;
    }
    *colon = 0;
    const char *val = colon + 1;
    /* a split name is a word: " val" (from "train:0.5, val:0.5") would be another split than
     * the "val" every later step asks for */
    for (const char *c = tok; *c; c++)
      if (!isalnum((unsigned char)*c) && *c != '_' && *c != '-') {
        ds_err("--split: split name '%s' may hold only letters, digits, '_' and '-'", tok);
        return -1;
      }
    /* Each split is named once: a second "train:" would silently take the first's place
     * (fractions) or merge with it (names). */
    for (int k = 0; k < nsplit; k++)
      if (!strcmp(names[k], tok)) {
        ds_err("--split: split '%s' is named twice in '%s'", tok, spec);
        return -1;
      }
    snprintf(names[nsplit], 16, "%s", tok);
    double f;
    int isf = cli_parse_double(val, &f);
    if (fractions >= 0 && isf != fractions) {
      ds_err("--split: mix of fractions and scene names in '%s'", spec);
      return -1;
    }
    fractions = isf;
    if (isf) {
      if (!(f >= 0 && f <= 1)) {
        ds_err("--split: fraction %s of '%s' not in [0,1]", val, tok);
        return -1;
      }
      frac[nsplit] = f;
    } else {
      char vb[4096];
      snprintf(vb, sizeof vb, "%s", val);
      char *s2 = NULL;
      for (char *nm = strtok_r(vb, "+", &s2); nm; nm = strtok_r(NULL, "+", &s2)) {
        int found = 0;
        for (int i = 0; i < n; i++)
          if (!strcmp(s[i].name, nm)) {
            if (s[i].split[0]) {
              ds_err("--split: scene '%s' is in both '%s' and '%s'", nm, s[i].split, tok);
              return -1;
            }
            snprintf(s[i].split, sizeof s[i].split, "%s", tok);
            found = 1;
          }
        if (!found) {
          ds_err("--split: scene '%s' (split '%s') is not among the scenes found", nm, tok);
          return -1;
        }
      }
    }
    nsplit++;
  }
  if (fractions == 1) {
    /* The splits after the first take round(fraction * n) scenes each and the first the
     * rest: a sum above 1 would leave the first (training) split empty or short. */
    double sum = 0;
    for (int k = 0; k < nsplit; k++)
      sum += frac[k];
    if (sum > 1 + 1e-6) {
      ds_err("--split: fractions of '%s' sum to %g, more than 1 (each is the share of the base "
             "scenes in that split)",
             spec, sum);
      return -1;
    }
    /* Fisher-Yates with the seed, then consecutive blocks; the first split takes the
     * rounding remainder so every scene gets a split. */
    int *order = malloc(sizeof(int) * (size_t)n);
    for (int i = 0; i < n; i++)
      order[i] = i;
    uint64_t h = seed * 0x9e3779b97f4a7c15ull + 7;
    for (int i = n - 1; i > 0; i--) {
      h = ds_hash("split", h);
      int j = (int)(h % (uint64_t)(i + 1));
      int t = order[i];
      order[i] = order[j];
      order[j] = t;
    }
    int pos = 0, empty = -1;
    for (int k = nsplit - 1; k >= 1; k--) {
      int cnt = (int)lround(frac[k] * n), c = 0;
      for (; c < cnt && pos < n; c++)
        strcpy(s[order[pos++]].split, names[k]);
      if (c == 0 && frac[k] > 0) empty = k;
    }
    if (pos == n && frac[0] > 0) empty = 0;
    while (pos < n)
      strcpy(s[order[pos++]].split, names[0]);
    free(order);
    /* A split asked for with a share above 0 that gets no scene would leave its patch store
     * or validation set empty, found only later by `patches` ("no finished val image pairs"). */
    if (empty >= 0) {
      ds_err("--split: split '%s' (%g of %d base scene%s) gets no scene; give it a larger "
             "share, name its scenes (%s:sceneA+sceneB) or leave it out",
             names[empty], frac[empty], n, n == 1 ? "" : "s", names[empty]);
      return -1;
    }
  }
  for (int i = 0; i < n; i++)
    if (!s[i].split[0]) {
      ds_err("--split: scene '%s' is in no split", s[i].name);
      return -1;
    }
  return 0;
}

/* Rewrites relative file references (meshes, textures, env maps) to absolute paths of the
 * base scene's directory, since the perturbed JSON lives elsewhere. */
static void rebase_paths(cJSON *node, const char *dir) {
  cJSON *c;
  cJSON_ArrayForEach(c, node) {
    if (cJSON_IsString(c) && c->valuestring[0] && c->valuestring[0] != '/') {
      char p[DS_PATH];
      ds_join(p, sizeof p, dir, c->valuestring);
      if (ds_exists(p)) {
        char *rp = realpath(p, NULL);
        if (rp) {
          cJSON_SetValuestring(c, rp);
          free(rp);
        }
      }
    } else if (cJSON_IsObject(c) || cJSON_IsArray(c)) {
      rebase_paths(c, dir);
    }
  }
}

/* camera.resolution of a base scene, checked as the renderer checks it (integral numbers)
 * and against --resolution's limit: valueint would turn 1e12 into INT_MAX. Returns 1 with
 * *w, *h set, 0 when the scene has none, -1 when it is bad (error printed). */
static int scene_resolution(const base_scene *sc, const char *json, int *w, int *h) {
  cJSON *r = cJSON_Parse(json);
  if (!r) {
    ds_err("plan: scene '%s' (%s): not valid JSON", sc->name, sc->file);
    return -1;
  }
  const cJSON *res =
      cJSON_GetObjectItemCaseSensitive(cJSON_GetObjectItemCaseSensitive(r, "camera"), "resolution");
  double d[2];
  int ok = 0;
  if (cJSON_IsArray(res) && cJSON_GetArraySize(res) == 2 &&
      cJSON_IsNumber(cJSON_GetArrayItem(res, 0)) && cJSON_IsNumber(cJSON_GetArrayItem(res, 1))) {
    d[0] = cJSON_GetArrayItem(res, 0)->valuedouble;
    d[1] = cJSON_GetArrayItem(res, 1)->valuedouble;
    ok = 1;
  } else if (cJSON_IsNumber(res)) {
    d[0] = d[1] = res->valuedouble;
    ok = 1;
  } else if (res) {
    ds_err("plan: scene '%s' (%s): camera.resolution is not a number or [width, height]", sc->name,
           sc->file);
    ok = -1;
  }
  for (int k = 0; k < 2 && ok == 1; k++)
    if (!(d[k] >= 1 && d[k] <= DS_MAX_DIM) || d[k] != floor(d[k])) {
      ds_err("plan: scene '%s' (%s): camera.resolution %.15g x %.15g: each side must be an "
             "integer in [1, %d] (or give --resolution)",
             sc->name, sc->file, d[0], d[1], DS_MAX_DIM);
      ok = -1;
    }
  if (ok == 1) *w = (int)d[0], *h = (int)d[1];
  cJSON_Delete(r);
  return ok;
}

/* Finds the first value the perturbation made non-finite (cJSON prints it as null) where the
 * base scene holds no null: a strength so large that exp() or a product overflowed. Its JSON
 * path goes to path (len: the part already there). Arrays are walked alongside the base's. */
static int new_null(const cJSON *p, const cJSON *b, char *path, size_t n, size_t len) {
  if (cJSON_IsNull(p)) return !cJSON_IsNull(b);
  int i = 0;
  const cJSON *c, *bc = cJSON_IsArray(p) && cJSON_IsArray(b) ? b->child : NULL;
  cJSON_ArrayForEach(c, p) {
    const cJSON *bi = bc;
    if (cJSON_IsArray(p)) {
      snprintf(path + len, n - len, "[%d]", i++);
      bc = bc ? bc->next : NULL;
    } else {
      snprintf(path + len, n - len, "%s%s", len ? "." : "", c->string);
      bi = cJSON_IsObject(b) ? cJSON_GetObjectItemCaseSensitive(b, c->string) : NULL;
    }
    if (new_null(c, bi, path, n, strlen(path))) return 1;
  }
  path[len] = 0;
  return 0;
}

/* What one plan writes that did not exist before (files and directories, in creation
 * order), so that a failed plan removes them again: no half-planned dataset is left. */
typedef struct created {
  char **p;
  int n, cap;
} created;

static int track_push(created *c, const char *path) {
  if (c->n == c->cap) {
    int cap = c->cap ? 2 * c->cap : 64;
    char **np = realloc(c->p, sizeof *np * (size_t)cap);
    if (!np) return -1;
    c->p = np;
    c->cap = cap;
  }
  if (!(c->p[c->n] = strdup(path))) return -1;
  c->n++;
  return 0;
}

/* mkdir -p that records each directory it creates. */
static int track_mkdir(created *c, const char *path) {
  char p[DS_PATH];
  snprintf(p, sizeof p, "%s", path);
  size_t l = strlen(p);
  while (l > 1 && p[l - 1] == '/')
    p[--l] = 0;
  struct stat sb;
  if (stat(p, &sb) == 0) {
    if (S_ISDIR(sb.st_mode)) return 0;
    errno = ENOTDIR;
    return -1;
  }
  char *sl = strrchr(p, '/');
  if (sl && sl > p) {
    *sl = 0;
    int r = track_mkdir(c, p);
    *sl = '/';
    if (r != 0) return r;
  }
  if (mkdir(p, 0777) != 0) return errno == EEXIST ? 0 : -1;
  return track_push(c, p);
}

static int track_write(created *c, const char *path, const char *data, size_t len) {
  if (access(path, F_OK) != 0 && track_push(c, path) != 0) return -1;
  return ds_write_atomic(path, data, len);
}

/* Removes (newest first) what a failed plan created. */
static void track_undo(created *c) {
  for (int i = c->n - 1; i >= 0; i--)
    remove(c->p[i]);
}

static void track_free(created *c) {
  for (int i = 0; i < c->n; i++)
    free(c->p[i]);
  free(c->p);
}

typedef struct plan_ctx {
  const char *outdir;
  uint64_t seed;
  int variants, eval_variants, no_preview, preview_spp, preview_scale, ref_spp, W, H;
  int albedo_footprint; /* noisy jobs' --albedo-footprint (0 = none) */
  int force;            /* --force: a variant whose scene file changes loses its renders */
  const int *spps;
  int nspp;
  const kpcn_perturb_settings *ps;
  ds_manifest m; /* filled by the check pass */
  double samples;
  created made; /* filled by the write pass */
} plan_ctx;

/* Removes every file of one variant under renders/SCENE/ (its noisy, reference and preview
 * renders, their verdicts and checkpoints): renders of a scene file that changed would count
 * as done (a render is matched to its job by size, spp and seed only). */
static int remove_variant_renders(const plan_ctx *c, const char *scene, int v) {
  char rel[DS_PATH], pat[DS_PATH];
  snprintf(rel, sizeof rel, "renders/%s/v%03d_*", scene, v);
  ds_join(pat, sizeof pat, c->outdir, rel);
  glob_t g;
  int n = 0, rc = 0;
  if (glob(pat, GLOB_NOSORT, NULL, &g) == 0) {
    for (size_t i = 0; i < g.gl_pathc; i++) {
      if (remove(g.gl_pathv[i]) == 0) {
        n++;
      } else {
        ds_err("plan: cannot remove '%s': %s", g.gl_pathv[i], strerror(errno));
        rc = 1;
      }
    }
    globfree(&g);
  }
  if (n) printf("plan: %s/v%03d's scene changed: %d render file(s) removed\n", scene, v, n);
  return rc;
}

/* One base scene. The check pass (write = 0) reads, sizes and perturbs every variant and
 * appends the scene's jobs to the manifest, writing nothing; the write pass (write = 1),
 * run only once every scene passed, perturbs again (deterministic) and writes the variant
 * JSONs and variants.jsonl. So a bad later scene leaves no files of the earlier ones. */
static int plan_scene(plan_ctx *c, const base_scene *sc, int write) {
  const char *why = NULL;
  char *base = ds_slurp(sc->file, NULL, &why);
  if (!base) {
    ds_err("plan: scene '%s': cannot read '%s': %s", sc->name, sc->file, why ? why : "?");
    return 1;
  }
  int sw = c->W, sh = c->H;
  if (!(c->W && c->H)) {
    int r = scene_resolution(sc, base, &sw, &sh);
    if (r == 0)
      ds_err("plan: scene '%s' (%s): no camera.resolution (give --resolution)", sc->name, sc->file);
    if (r != 1) {
      free(base);
      return 1;
    }
  }
  int is_train = !strcmp(sc->split, "train");
  int nvar = (is_train || c->eval_variants) ? c->variants : 0;
  char sdir[DS_PATH], rel[DS_PATH], path[DS_PATH];
  snprintf(rel, sizeof rel, "scenes/%s", sc->name);
  ds_join(sdir, sizeof sdir, c->outdir, rel);
  if (write) {
    snprintf(rel, sizeof rel, "renders/%s", sc->name);
    ds_join(path, sizeof path, c->outdir, rel);
    if (track_mkdir(&c->made, sdir) != 0 || track_mkdir(&c->made, path) != 0) {
      ds_err("plan: cannot create '%s' or '%s': %s", sdir, path, strerror(errno));
      free(base);
      return 1;
    }
  }
  /* variants.jsonl grows with the count (a fixed buffer once kept only its last ~545 lines). */
  char *vtxt = NULL;
  size_t vlen = 0, vcap = 0;
  int rc = 0;
  cJSON *bjs = write ? NULL : cJSON_Parse(base); /* for the check of perturbed values */
  for (int v = 0; v <= nvar && rc == 0; v++) {
    char *pert = NULL, summary[512];
    if (kpcn_perturb_scene(&pert, base, ds_hash(sc->name, c->seed), v, c->ps, summary,
                           sizeof summary) != KPCN_OK) {
      ds_err("plan: scene '%s' (%s), variant %d: %s", sc->name, sc->file, v, kpcn_last_error());
      rc = 1;
      break;
    }
    ds_job j;
    memset(&j, 0, sizeof j);
    snprintf(j.scene, sizeof j.scene, "%s", sc->name);
    snprintf(j.split, sizeof j.split, "%s", sc->split);
    j.variant = v;
    snprintf(j.scene_file, sizeof j.scene_file, "scenes/%s/v%03d.json", sc->name, v);
    /* The variant's file as it will be written; one that exists with other contents (the
     * base scene or the perturbation changed) is refused in the check pass unless --force,
     * and with --force its renders are removed in the write pass. */
    char *txt = NULL;
    {
      cJSON *pjs = cJSON_Parse(pert);
      rebase_paths(pjs, sc->dir);
      txt = cJSON_Print(pjs);
      cJSON_Delete(pjs);
    }
    ds_join(path, sizeof path, c->outdir, j.scene_file);
    char *was = ds_slurp(path, NULL, NULL);
    const int changed = was && txt && strcmp(was, txt) != 0;
    free(was);
    if (changed && !write && !c->force) {
      ds_err("plan: '%s' would change (the base scene '%s' or the perturbation settings "
             "changed), and its renders would no longer match it; use another directory or "
             "--force (which removes that variant's renders)",
             path, sc->file);
      free(txt);
      free(pert);
      rc = 1;
      break;
    }
    if (changed && write && remove_variant_renders(c, sc->name, v) != 0) {
      free(txt);
      free(pert);
      rc = 1;
      break;
    }
    if (write) {
      /* What changed, beside the scene (renderers reject unknown scene fields); cJSON
       * escapes the texture names the summary may quote. */
      cJSON *lj = cJSON_CreateObject();
      cJSON_AddNumberToObject(lj, "variant", v);
      cJSON_AddStringToObject(lj, "perturbation", summary);
      char *line = cJSON_PrintUnformatted(lj);
      cJSON_Delete(lj);
      size_t ll = line ? strlen(line) : 0;
      if (vlen + ll + 2 > vcap) {
        size_t cap = vcap ? 2 * vcap : 1 << 16;
        while (cap < vlen + ll + 2)
          cap *= 2;
        char *nb = realloc(vtxt, cap);
        if (nb) vtxt = nb, vcap = cap;
      }
      if (!txt || !line || vlen + ll + 2 > vcap) {
        ds_err("plan: scene '%s': out of memory", sc->name);
        rc = 1;
      } else {
        memcpy(vtxt + vlen, line, ll);
        vlen += ll;
        vtxt[vlen++] = '\n';
        ds_join(path, sizeof path, c->outdir, j.scene_file);
        if (track_write(&c->made, path, txt, strlen(txt)) != 0) rc = 1;
      }
      free(line);
      free(txt);
      free(pert);
      continue;
    }
    free(txt);
    /* No variant may carry a non-finite number (the renderer rejects the scene, and only
     * at render time). */
    cJSON *pjs = cJSON_Parse(pert);
    char where[512] = "";
    if (new_null(pjs, bjs, where, sizeof where, 0)) {
      ds_err("plan: scene '%s' (%s), variant %d: the perturbation made %s non-finite (lower "
             "the strength of --camera, --fov, --material, --light or --env)",
             sc->name, sc->file, v, where);
      rc = 1;
    }
    cJSON_Delete(pjs);
    free(pert);
    if (rc) break;
    int oom = 0;
    /* Variant 0 is the artist's scene: never rejected. */
    if (!c->no_preview && v > 0)
      snprintf(j.preview, sizeof j.preview, "renders/%s/v%03d_preview.exr", sc->name, v);
    if (j.preview[0]) {
      ds_job p = j;
      p.kind = DS_PREVIEW;
      p.spp = c->preview_spp;
      int k = c->preview_scale;
      p.width = sw / k > 16 ? sw / k : (sw < 16 ? sw : 16);
      p.height = sh / k > 16 ? sh / k : (sh < 16 ? sh : 16);
      snprintf(p.id, sizeof p.id, "%s/v%03d/preview", sc->name, v);
      snprintf(p.out, sizeof p.out, "%s", j.preview);
      p.seed = ds_hash(p.id, c->seed) & DS_MAX_SEED;
      oom |= ds_manifest_push(&c->m, &p) != 0;
    }
    j.width = sw;
    j.height = sh;
    for (int k = 0; k <= c->nspp; k++) {
      ds_job r = j;
      r.kind = k < c->nspp ? DS_NOISY : DS_REFERENCE;
      r.spp = k < c->nspp ? c->spps[k] : c->ref_spp;
      if (k < c->nspp) {
        snprintf(r.id, sizeof r.id, "%s/v%03d/%dspp", sc->name, v, r.spp);
        snprintf(r.out, sizeof r.out, "renders/%s/v%03d_%dspp.exr", sc->name, v, r.spp);
      } else {
        snprintf(r.id, sizeof r.id, "%s/v%03d/ref", sc->name, v);
        snprintf(r.out, sizeof r.out, "renders/%s/v%03d_ref%dspp.exr", sc->name, v, r.spp);
      }
      r.seed = ds_hash(r.id, c->seed) & DS_MAX_SEED; /* fits any renderer's int seed */
      if (r.kind == DS_NOISY) r.albedo_footprint = c->albedo_footprint;
      c->samples += (double)r.spp * sw * sh;
      oom |= ds_manifest_push(&c->m, &r) != 0;
    }
    if (oom) {
      ds_err("plan: out of memory for the manifest");
      rc = 1;
    }
  }
  if (write && rc == 0) {
    ds_join(path, sizeof path, sdir, "variants.jsonl");
    rc = track_write(&c->made, path, vtxt ? vtxt : "", vlen) != 0;
  }
  cJSON_Delete(bjs);
  free(vtxt);
  free(base);
  return rc;
}

/* to stdout when --help asked for it, to stderr beside an error */
static void usage(FILE *f) {
  fprintf(f,
          "usage: kpcn-dataset plan --scenes DIR -o OUTDIR [--variants N] [--seed S]\n"
          "         [--spp 4,8,16,32,64] [--ref-spp 1024] [--resolution WxH]\n"
          "         [--split train:0.7,val:0.15,test:0.15 | train:a+b,val:c,test:d]\n"
          "         [--eval-variants] [--preview-spp 4] [--preview-scale 4] [--no-preview]\n"
          "         [--camera X] [--fov X] [--material X] [--bsdf-swap P] [--light X] [--env X]\n"
          "         [--texture-swap P] [--texture-dir DIR] [--texture-bitmap P]\n"
          "         [--albedo-footprint K] [--force]\n");
}

int ds_cmd_plan(int argc, char **argv) {
  const char *scenes = NULL, *outdir = NULL, *split = NULL, *spp_list = "4,8,16,32,64";
  int variants = 10, ref_spp = 1024, W = 0, H = 0, preview_spp = 4, preview_scale = 4;
  int no_preview = 0, eval_variants = 0, force = 0, albedo_footprint = 1;
  uint64_t seed = 1;
  static char texture_dir[DS_PATH]; /* realpath of --texture-dir */
  kpcn_perturb_settings ps;
  kpcn_perturb_settings_defaults(&ps);
  for (int i = 1; i < argc; i++) {
    const char *a = argv[i], *v = i + 1 < argc ? argv[i + 1] : NULL;
    double *dst = NULL;
    int takes = 1;
    if (!strcmp(a, "--no-preview"))
      no_preview = 1, takes = 0;
    else if (!strcmp(a, "--eval-variants"))
      eval_variants = 1, takes = 0;
    else if (!strcmp(a, "--force"))
      force = 1, takes = 0;
    else if (!strcmp(a, "-h") || !strcmp(a, "--help")) {
      usage(stdout);
      return 0;
    }
    if (!takes) continue;
    if (!v) {
      ds_err("plan: %s needs a value", a);
      usage(stderr);
      return 2;
    }
    int ok = 1;
    const char *want = ""; /* what the option takes, for the error */
    if (!strcmp(a, "--scenes"))
      scenes = v;
    else if (!strcmp(a, "-o") || !strcmp(a, "--output"))
      outdir = v;
    else if (!strcmp(a, "--split"))
      split = v;
    else if (!strcmp(a, "--spp"))
      spp_list = v;
    else if (!strcmp(a, "--variants")) {
      ok = cli_parse_int(v, 0, DS_MAX_VARIANTS, &variants);
      want = " (an integer in [0, 100000])";
    } else if (!strcmp(a, "--ref-spp")) {
      ok = cli_parse_int(v, 1, DS_MAX_SPP, &ref_spp);
      want = " (an integer in [1, 16777216])";
    } else if (!strcmp(a, "--albedo-footprint")) {
      ok = cli_parse_int(v, 1, 16, &albedo_footprint);
      want = " (an integer in [1, 16])";
    } else if (!strcmp(a, "--preview-spp")) {
      ok = cli_parse_int(v, 1, 1 << 16, &preview_spp);
      want = " (an integer in [1, 65536])";
    } else if (!strcmp(a, "--preview-scale")) {
      ok = cli_parse_int(v, 1, 64, &preview_scale);
      want = " (an integer in [1, 64])";
    } else if (!strcmp(a, "--seed")) {
      ok = ds_parse_u64(v, UINT64_MAX, &seed);
      want = " (a non-negative decimal integer below 2^64)";
    } else if (!strcmp(a, "--resolution")) {
      static const long lo[2] = {1, 1}, hi[2] = {DS_MAX_DIM, DS_MAX_DIM};
      int wh[2];
      ok = cli_parse_int_list(v, 'x', 2, lo, hi, wh);
      if (ok) W = wh[0], H = wh[1];
      want = " (WxH, each side in [1, 16384])";
    } else if (!strcmp(a, "--camera"))
      dst = &ps.camera;
    else if (!strcmp(a, "--fov"))
      dst = &ps.fov;
    else if (!strcmp(a, "--material"))
      dst = &ps.material;
    else if (!strcmp(a, "--bsdf-swap")) {
      ok = cli_parse_double(v, &ps.bsdf_swap) && ps.bsdf_swap >= 0 && ps.bsdf_swap <= 1;
      want = " (a probability in [0, 1])";
    } else if (!strcmp(a, "--light"))
      dst = &ps.light;
    else if (!strcmp(a, "--env"))
      dst = &ps.env;
    else if (!strcmp(a, "--texture-swap")) {
      ok = cli_parse_double(v, &ps.texture_swap) && ps.texture_swap >= 0 && ps.texture_swap <= 1;
      want = " (a probability in [0, 1])";
    } else if (!strcmp(a, "--texture-bitmap")) {
      ok = cli_parse_double(v, &ps.texture_bitmap) && ps.texture_bitmap >= 0 &&
           ps.texture_bitmap <= 1;
      want = " (a probability in [0, 1])";
    } else if (!strcmp(a, "--texture-dir")) {
      /* Absolute, so plan.json names the same images from any working directory. */
      char *rp = realpath(v, NULL);
      if (!rp) {
        ds_err("plan: --texture-dir '%s': %s", v, strerror(errno));
        return 2;
      }
      snprintf(texture_dir, sizeof texture_dir, "%s", rp);
      free(rp);
      ps.texture_dir = texture_dir;
    } else {
      ds_err("plan: unknown option '%s'", a);
      usage(stderr);
      return 2;
    }
    if (dst) {
      ok = cli_parse_double(v, dst) && *dst >= 0;
      want = " (a finite number >= 0)";
    }
    if (!ok) {
      ds_err("plan: bad value '%s' for %s%s", v, a, want);
      return 2;
    }
    i++;
  }
  if (!scenes || !outdir) {
    ds_err("plan: --scenes and -o are required");
    usage(stderr);
    return 2;
  }
  int spps[32];
  const int nspp = ds_parse_int_list(spp_list, 1 << 20, spps, 32);
  if (nspp < 1) {
    ds_err("plan: --spp '%s': expected a comma list of at most 32 distinct integers in [1, %d]",
           spp_list, 1 << 20);
    return 2;
  }
  if (ps.texture_dir && ps.texture_swap > 0) {
    /* Reject a directory without images now, before anything is written: perturbing a
     * one-texture scene lists the directory exactly as every variant will. */
    char *probe = NULL;
    kpcn_status st = kpcn_perturb_scene(
        &probe, "{\"bsdfs\":[{\"type\":\"lambert\",\"albedo\":\"x.png\"}]}", seed, 1, &ps, NULL, 0);
    free(probe);
    if (st != KPCN_OK) {
      ds_err("plan: --texture-dir: %s", kpcn_last_error());
      return 2;
    }
  }
  base_scene *sc = NULL;
  int nsc = 0;
  if (find_scenes(scenes, &sc, &nsc) != 0) return 1;
  if (assign_splits(sc, nsc, split, seed) != 0) {
    free(sc);
    return 2;
  }
  /* The plan's settings, for refusing to mix two different plans in one directory. */
  cJSON *pj = cJSON_CreateObject();
  cJSON_AddStringToObject(pj, "format", "kpcn-dataset-plan");
  cJSON_AddNumberToObject(pj, "version", 1);
  char sbuf[32];
  snprintf(sbuf, sizeof sbuf, "%llu", (unsigned long long)seed);
  cJSON_AddStringToObject(pj, "seed", sbuf);
  cJSON_AddNumberToObject(pj, "variants", variants);
  cJSON_AddStringToObject(pj, "spp", spp_list);
  cJSON_AddNumberToObject(pj, "ref_spp", ref_spp);
  cJSON_AddNumberToObject(pj, "width", W);
  cJSON_AddNumberToObject(pj, "height", H);
  cJSON_AddNumberToObject(pj, "preview_spp", no_preview ? 0 : preview_spp);
  cJSON_AddNumberToObject(pj, "preview_scale", preview_scale);
  cJSON_AddBoolToObject(pj, "eval_variants", eval_variants);
  /* only when set: plans made without it keep their plan.json byte for byte */
  if (albedo_footprint > 1) cJSON_AddNumberToObject(pj, "albedo_footprint", albedo_footprint);
  double pv[6] = {ps.camera, ps.fov, ps.material, ps.bsdf_swap, ps.light, ps.env};
  cJSON_AddItemToObject(pj, "perturb", cJSON_CreateDoubleArray(pv, 6));
  cJSON_AddNumberToObject(pj, "texture_swap", ps.texture_swap);
  if (ps.texture_dir)
    cJSON_AddStringToObject(pj, "texture_dir", texture_dir);
  else
    cJSON_AddNullToObject(pj, "texture_dir");
  /* only when set, as albedo_footprint */
  if (ps.texture_bitmap > 0) cJSON_AddNumberToObject(pj, "texture_bitmap", ps.texture_bitmap);
  cJSON *sj = cJSON_AddObjectToObject(pj, "scenes");
  for (int i = 0; i < nsc; i++) {
    cJSON *o = cJSON_AddObjectToObject(sj, sc[i].name);
    cJSON_AddStringToObject(o, "file", sc[i].file);
    cJSON_AddStringToObject(o, "split", sc[i].split);
  }
  char *ptxt = cJSON_Print(pj);
  cJSON_Delete(pj);
  char path[DS_PATH];
  ds_join(path, sizeof path, outdir, "plan.json");
  char *old = ds_slurp(path, NULL, NULL);
  if (old && strcmp(old, ptxt) != 0 && !force) {
    ds_err("plan: '%s' holds a different plan; use another directory or --force "
           "(existing renders would no longer match their jobs)",
           path);
    free(old);
    free(sc);
    free(ptxt);
    return 1;
  }
  free(old);

  plan_ctx c;
  memset(&c, 0, sizeof c);
  c.outdir = outdir;
  c.seed = seed;
  c.variants = variants, c.eval_variants = eval_variants, c.no_preview = no_preview;
  c.preview_spp = preview_spp, c.preview_scale = preview_scale, c.ref_spp = ref_spp;
  c.W = W, c.H = H;
  c.albedo_footprint = albedo_footprint > 1 ? albedo_footprint : 0;
  c.force = force;
  c.spps = spps, c.nspp = nspp;
  c.ps = &ps;
  /* Every scene is checked (and the manifest built) before the first file is written. */
  int rc = 0;
  for (int i = 0; i < nsc && rc == 0; i++)
    rc = plan_scene(&c, &sc[i], 0);
  if (rc == 0 && track_mkdir(&c.made, outdir) != 0) {
    ds_err("plan: cannot create '%s': %s", outdir, strerror(errno));
    rc = 1;
  }
  for (int i = 0; i < nsc && rc == 0; i++)
    rc = plan_scene(&c, &sc[i], 1);
  if (rc == 0) {
    ds_join(path, sizeof path, outdir, "manifest.jsonl");
    if (access(path, F_OK) != 0 && track_push(&c.made, path) != 0) rc = 1;
    if (rc == 0) rc = ds_manifest_write(outdir, &c.m) != 0;
  }
  if (rc == 0) {
    ds_join(path, sizeof path, outdir, "plan.json");
    rc = track_write(&c.made, path, ptxt, strlen(ptxt)) != 0;
  }
  if (rc != 0) {
    track_undo(&c.made);
  } else {
    int cnt[3] = {0, 0, 0};
    for (int i = 0; i < c.m.n; i++)
      cnt[c.m.jobs[i].kind]++;
    printf("planned %d scenes:", nsc);
    for (int i = 0; i < nsc; i++)
      printf(" %s(%s)", sc[i].name, sc[i].split);
    char mp[DS_PATH];
    ds_join(mp, sizeof mp, outdir, "manifest.jsonl");
    printf("\n%d jobs (%d noisy, %d reference, %d preview), %.3g camera samples -> %s\n", c.m.n,
           cnt[DS_NOISY], cnt[DS_REFERENCE], cnt[DS_PREVIEW], c.samples, mp);
  }
  track_free(&c.made);
  ds_manifest_free(&c.m);
  free(sc);
  free(ptxt);
  return rc;
}
