/* `kpcn-dataset plan`: base scenes -> perturbed scene JSONs + manifest of render jobs.
 * Split by BASE scene (every variant of a scene lands in the same split); only training
 * scenes are perturbed (seed Table 3.1), unless --eval-variants is given. */
#define _GNU_SOURCE
#include "ds.h"
#include "kpcn/dataset.h"

#include <cjson/cJSON.h>
#include <dirent.h>
#include <limits.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

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
    ds_err("--scenes: cannot open directory '%s'", dir);
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
  char buf[4096];
  snprintf(buf, sizeof buf, "%s", spec);
  char names[8][16];
  double frac[8];
  int nsplit = 0, fractions = -1;
  char *save = NULL;
  for (char *tok = strtok_r(buf, ",", &save); tok; tok = strtok_r(NULL, ",", &save)) {
    char *colon = strchr(tok, ':');
    if (!colon || colon == tok || nsplit == 8 || colon - tok >= 16) {
      ds_err("--split: '%s' is not split:value (e.g. train:0.8 or val:sceneA+sceneB)", tok);
      return -1;
    }
    *colon = 0;
    const char *val = colon + 1;
    snprintf(names[nsplit], 16, "%s", tok);
    double f;
    int isf = ds_parse_double(val, &f);
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
    int pos = 0;
    for (int k = nsplit - 1; k >= 1; k--) {
      int cnt = (int)lround(frac[k] * n);
      for (int c = 0; c < cnt && pos < n; c++)
        strcpy(s[order[pos++]].split, names[k]);
    }
    while (pos < n)
      strcpy(s[order[pos++]].split, names[0]);
    free(order);
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

static int scene_resolution(const char *json, int *w, int *h) {
  cJSON *r = cJSON_Parse(json);
  const cJSON *res =
      cJSON_GetObjectItemCaseSensitive(cJSON_GetObjectItemCaseSensitive(r, "camera"), "resolution");
  int ok = 0;
  if (cJSON_IsArray(res) && cJSON_GetArraySize(res) == 2) {
    *w = cJSON_GetArrayItem(res, 0)->valueint;
    *h = cJSON_GetArrayItem(res, 1)->valueint;
    ok = *w > 0 && *h > 0;
  } else if (cJSON_IsNumber(res)) {
    *w = *h = res->valueint;
    ok = *w > 0;
  }
  cJSON_Delete(r);
  return ok;
}

static void usage(void) {
  fprintf(stderr,
          "usage: kpcn-dataset plan --scenes DIR -o OUTDIR [--variants N] [--seed S]\n"
          "         [--spp 4,8,16,32,64] [--ref-spp 1024] [--resolution WxH]\n"
          "         [--split train:0.7,val:0.15,test:0.15 | train:a+b,val:c,test:d]\n"
          "         [--eval-variants] [--preview-spp 4] [--preview-scale 4] [--no-preview]\n"
          "         [--camera X] [--fov X] [--material X] [--bsdf-swap P] [--light X] [--env X]\n"
          "         [--texture-swap P] [--texture-dir DIR] [--force]\n");
}

int ds_cmd_plan(int argc, char **argv) {
  const char *scenes = NULL, *outdir = NULL, *split = NULL, *spp_list = "4,8,16,32,64";
  int variants = 10, ref_spp = 1024, W = 0, H = 0, preview_spp = 4, preview_scale = 4;
  int no_preview = 0, eval_variants = 0, force = 0;
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
      usage();
      return 0;
    }
    if (!takes) continue;
    if (!v) {
      ds_err("plan: %s needs a value", a);
      usage();
      return 2;
    }
    int ok = 1;
    if (!strcmp(a, "--scenes"))
      scenes = v;
    else if (!strcmp(a, "-o") || !strcmp(a, "--output"))
      outdir = v;
    else if (!strcmp(a, "--split"))
      split = v;
    else if (!strcmp(a, "--spp"))
      spp_list = v;
    else if (!strcmp(a, "--variants"))
      ok = ds_parse_int(v, 0, 100000, &variants);
    else if (!strcmp(a, "--ref-spp"))
      ok = ds_parse_int(v, 1, 1 << 24, &ref_spp);
    else if (!strcmp(a, "--preview-spp"))
      ok = ds_parse_int(v, 1, 1 << 16, &preview_spp);
    else if (!strcmp(a, "--preview-scale"))
      ok = ds_parse_int(v, 1, 64, &preview_scale);
    else if (!strcmp(a, "--seed")) {
      char *end;
      seed = strtoull(v, &end, 10);
      ok = *v && !*end;
    } else if (!strcmp(a, "--resolution")) {
      char extra;
      ok = sscanf(v, "%dx%d%c", &W, &H, &extra) == 2 && W > 0 && H > 0 && W <= 16384 && H <= 16384;
    } else if (!strcmp(a, "--camera"))
      dst = &ps.camera;
    else if (!strcmp(a, "--fov"))
      dst = &ps.fov;
    else if (!strcmp(a, "--material"))
      dst = &ps.material;
    else if (!strcmp(a, "--bsdf-swap"))
      dst = &ps.bsdf_swap;
    else if (!strcmp(a, "--light"))
      dst = &ps.light;
    else if (!strcmp(a, "--env"))
      dst = &ps.env;
    else if (!strcmp(a, "--texture-swap")) {
      ok = ds_parse_double(v, &ps.texture_swap) && ps.texture_swap >= 0 && ps.texture_swap <= 1;
    } else if (!strcmp(a, "--texture-dir")) {
      /* Absolute, so plan.json names the same images from any working directory. */
      char *rp = realpath(v, NULL);
      if (!rp) {
        ds_err("plan: --texture-dir '%s' does not exist", v);
        return 2;
      }
      snprintf(texture_dir, sizeof texture_dir, "%s", rp);
      free(rp);
      ps.texture_dir = texture_dir;
    } else {
      ds_err("plan: unknown option '%s'", a);
      usage();
      return 2;
    }
    if (dst) ok = ds_parse_double(v, dst) && *dst >= 0;
    if (!ok) {
      ds_err("plan: bad value '%s' for %s", v, a);
      return 2;
    }
    i++;
  }
  if (!scenes || !outdir) {
    ds_err("plan: --scenes and -o are required");
    usage();
    return 2;
  }
  int spps[32], nspp = 0;
  {
    char b[512];
    snprintf(b, sizeof b, "%s", spp_list);
    char *save = NULL;
    for (char *t = strtok_r(b, ",", &save); t; t = strtok_r(NULL, ",", &save)) {
      if (nspp == 32 || !ds_parse_int(t, 1, 1 << 20, &spps[nspp])) {
        ds_err("plan: --spp '%s': expected a comma list of positive integers", spp_list);
        return 2;
      }
      nspp++;
    }
    if (!nspp) {
      ds_err("plan: --spp is empty");
      return 2;
    }
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
  double pv[6] = {ps.camera, ps.fov, ps.material, ps.bsdf_swap, ps.light, ps.env};
  cJSON_AddItemToObject(pj, "perturb", cJSON_CreateDoubleArray(pv, 6));
  cJSON_AddNumberToObject(pj, "texture_swap", ps.texture_swap);
  if (ps.texture_dir)
    cJSON_AddStringToObject(pj, "texture_dir", texture_dir);
  else
    cJSON_AddNullToObject(pj, "texture_dir");
  cJSON *sj = cJSON_AddObjectToObject(pj, "scenes");
  for (int i = 0; i < nsc; i++) {
    cJSON *o = cJSON_AddObjectToObject(sj, sc[i].name);
    cJSON_AddStringToObject(o, "file", sc[i].file);
    cJSON_AddStringToObject(o, "split", sc[i].split);
  }
  char *ptxt = cJSON_Print(pj);
  cJSON_Delete(pj);
  char path[DS_PATH];
  if (ds_mkdir_p(outdir) != 0) {
    ds_err("plan: cannot create '%s'", outdir);
    free(sc);
    free(ptxt);
    return 1;
  }
  ds_join(path, sizeof path, outdir, "plan.json");
  char *old = ds_slurp(path, NULL);
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

  ds_manifest m = {0};
  int rc = 0;
  double samples = 0;
  for (int i = 0; i < nsc && rc == 0; i++) {
    char *base = ds_slurp(sc[i].file, NULL);
    int sw = W, sh = H;
    if (!base || (!(W && H) && !scene_resolution(base, &sw, &sh))) {
      ds_err("plan: %s: %s", sc[i].file,
             base ? "no camera.resolution (give --resolution)" : "cannot read");
      free(base);
      rc = 1;
      break;
    }
    int is_train = !strcmp(sc[i].split, "train");
    int nvar = (is_train || eval_variants) ? variants : 0;
    char sdir[DS_PATH], rel[DS_PATH];
    snprintf(rel, sizeof rel, "scenes/%s", sc[i].name);
    ds_join(sdir, sizeof sdir, outdir, rel);
    ds_mkdir_p(sdir);
    snprintf(rel, sizeof rel, "renders/%s", sc[i].name);
    ds_join(path, sizeof path, outdir, rel);
    ds_mkdir_p(path);
    static char variants_txt[1 << 20];
    size_t variants_len = 0;
    variants_txt[0] = 0;
    for (int v = 0; v <= nvar && rc == 0; v++) {
      char *pert = NULL, summary[512];
      if (kpcn_perturb_scene(&pert, base, ds_hash(sc[i].name, seed), v, &ps, summary,
                             sizeof summary) != KPCN_OK) {
        ds_err("plan: %s: %s", sc[i].file, kpcn_last_error());
        rc = 1;
        break;
      }
      cJSON *pjs = cJSON_Parse(pert);
      free(pert);
      rebase_paths(pjs, sc[i].dir);
      char *txt = cJSON_Print(pjs);
      cJSON_Delete(pjs);
      /* What changed, beside the scene (renderers reject unknown scene fields). */
      char line[1024];
      snprintf(line, sizeof line, "{\"variant\":%d,\"perturbation\":\"%s\"}\n", v, summary);
      size_t ll = strlen(line);
      if (variants_len + ll + 1 > sizeof variants_txt)
        variants_len = 0; /* absurd count: keep last */
      memcpy(variants_txt + variants_len, line, ll + 1);
      variants_len += ll;
      ds_job j;
      memset(&j, 0, sizeof j);
      snprintf(j.scene, sizeof j.scene, "%s", sc[i].name);
      snprintf(j.split, sizeof j.split, "%s", sc[i].split);
      j.variant = v;
      snprintf(j.scene_file, sizeof j.scene_file, "scenes/%s/v%03d.json", sc[i].name, v);
      ds_join(path, sizeof path, outdir, j.scene_file);
      if (ds_write_atomic(path, txt, strlen(txt)) != 0) rc = 1;
      free(txt);
      /* Variant 0 is the artist's scene: never rejected. */
      if (!no_preview && v > 0)
        snprintf(j.preview, sizeof j.preview, "renders/%s/v%03d_preview.exr", sc[i].name, v);
      if (j.preview[0]) {
        ds_job p = j;
        p.kind = DS_PREVIEW;
        p.spp = preview_spp;
        p.width = sw / preview_scale > 16 ? sw / preview_scale : (sw < 16 ? sw : 16);
        p.height = sh / preview_scale > 16 ? sh / preview_scale : (sh < 16 ? sh : 16);
        snprintf(p.id, sizeof p.id, "%s/v%03d/preview", sc[i].name, v);
        snprintf(p.out, sizeof p.out, "%s", j.preview);
        p.seed = ds_hash(p.id, seed) & 0x7fffffffu;
        ds_manifest_push(&m, &p);
      }
      j.width = sw;
      j.height = sh;
      for (int k = 0; k <= nspp; k++) {
        ds_job r = j;
        r.kind = k < nspp ? DS_NOISY : DS_REFERENCE;
        r.spp = k < nspp ? spps[k] : ref_spp;
        if (k < nspp) {
          snprintf(r.id, sizeof r.id, "%s/v%03d/%dspp", sc[i].name, v, r.spp);
          snprintf(r.out, sizeof r.out, "renders/%s/v%03d_%dspp.exr", sc[i].name, v, r.spp);
        } else {
          snprintf(r.id, sizeof r.id, "%s/v%03d/ref", sc[i].name, v);
          snprintf(r.out, sizeof r.out, "renders/%s/v%03d_ref%dspp.exr", sc[i].name, v, r.spp);
        }
        r.seed = ds_hash(r.id, seed) & 0x7fffffffu; /* fits any renderer's int seed */
        samples += (double)r.spp * sw * sh;
        ds_manifest_push(&m, &r);
      }
    }
    if (rc == 0) {
      ds_join(path, sizeof path, sdir, "variants.jsonl");
      rc = ds_write_atomic(path, variants_txt, variants_len) != 0;
    }
    free(base);
  }
  if (rc == 0) rc = ds_manifest_write(outdir, &m) != 0;
  if (rc == 0) {
    ds_join(path, sizeof path, outdir, "plan.json");
    rc = ds_write_atomic(path, ptxt, strlen(ptxt)) != 0;
  }
  if (rc == 0) {
    int cnt[3] = {0, 0, 0};
    for (int i = 0; i < m.n; i++)
      cnt[m.jobs[i].kind]++;
    printf("planned %d scenes:", nsc);
    for (int i = 0; i < nsc; i++)
      printf(" %s(%s)", sc[i].name, sc[i].split);
    printf("\n%d jobs (%d noisy, %d reference, %d preview), %.3g camera samples -> "
           "%s/manifest.jsonl\n",
           m.n, cnt[DS_NOISY], cnt[DS_REFERENCE], cnt[DS_PREVIEW], samples, outdir);
  }
  ds_manifest_free(&m);
  free(sc);
  free(ptxt);
  return rc;
}
