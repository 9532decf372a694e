/* Textures (checker, bitmap from memory / PNG / HDR, Tungsten's gamma table and addressing)
 * and the Tungsten JSON parser for bsdfs and textures, including its error messages. */
#include "bsdf_testlib.h"
#include "testutil.h"

#include "render/bsdf.h"
#include "render/texture.h"

#include <cjson/cJSON.h>
#include <stdlib.h>
#include <string.h>

#define STB_IMAGE_WRITE_IMPLEMENTATION
#if defined(__GNUC__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wunused-function"
#pragma GCC diagnostic ignored "-Wsign-compare"
#pragma GCC diagnostic ignored "-Wmissing-field-initializers"
#endif
#include <stb/stb_image_write.h>
#if defined(__GNUC__)
#pragma GCC diagnostic pop
#endif

static int contains(const char *s, const char *sub) { return s && strstr(s, sub) != NULL; }

/* Parses json text holding {"bsdfs": [...]} and returns the status of parse_bsdfs. */
static kpcn_status parse_lib(const char *text, kpcn_material_lib **lib) {
  cJSON *root = cJSON_Parse(text);
  CHECK(root != NULL);
  CHECK(kpcn_material_lib_create(KPCN_TESTDATA "/scenes/materialtest", lib) == KPCN_OK);
  kpcn_status s = kpcn_material_lib_parse_bsdfs(*lib, cJSON_GetObjectItem(root, "bsdfs"), "bsdfs");
  cJSON_Delete(root);
  return s;
}

static void expect_error(const char *text, const char *msg_part) {
  kpcn_material_lib *lib = NULL;
  kpcn_status s = parse_lib(text, &lib);
  CHECK(s != KPCN_OK);
  if (!contains(kpcn_last_error(), msg_part))
    printf("expected error containing '%s', got '%s'\n", msg_part, kpcn_last_error());
  CHECK(contains(kpcn_last_error(), msg_part));
  kpcn_material_lib_destroy(lib);
}

int main(void) {
  /* ---- Tungsten's 8-bit gamma table (ImageIO.cpp GammaCorrection[]), recorded entries ---- */
  int idx[] = {0, 20, 21, 64, 100, 128, 200, 254, 255};
  int val[] = {0, 0, 1, 12, 32, 55, 149, 252, 255};
  for (int i = 0; i < 9; ++i)
    CHECK(kpcn_gamma_byte(idx[i]) == val[i]);

  kpcn_texture_cache *tc;
  CHECK(kpcn_texture_cache_create(&tc) == KPCN_OK);
  /* ---- checker ---- */
  const kpcn_texture *ck;
  CHECK(kpcn_texture_checker(tc, kv3(1, 0, 0), kv3(0, 0, 1), 20, 10, &ck) == KPCN_OK);
  CHECK(kpcn_texture_eval(ck, 0.01f, 0.01f).z == 1.0f); /* cell (0,0): off */
  CHECK(kpcn_texture_eval(ck, 0.06f, 0.01f).x == 1.0f); /* cell (1,0): on */
  CHECK(kpcn_texture_eval(ck, 0.06f, 0.15f).z == 1.0f); /* cell (1,1): off */
  CHECK(kpcn_texture_eval(ck, 0.01f, 0.15f).x == 1.0f); /* cell (0,1): on */
  CHECK(kpcn_texture_checker(tc, kv3(1, 0, 0), kv3(0, 0, 1), 0, 10, &ck) != KPCN_OK);

  /* ---- bitmap from memory: 4x2, row 0 = top (v = 1) ---- */
  float px[4 * 2 * 3];
  for (int i = 0; i < 8; ++i)
    for (int c = 0; c < 3; ++c)
      px[3 * i + c] = (float)(i * 10 + c);
  const kpcn_texture *bm;
  CHECK(kpcn_texture_from_pixels(tc, 4, 2, px, &bm) == KPCN_OK);
  for (int y = 0; y < 2; ++y)
    for (int x = 0; x < 4; ++x) {
      kpcn_vec3 v = kpcn_texture_eval(bm, (x + 0.5f) / 4, 1.0f - (y + 0.5f) / 2);
      CHECK_NEAR(v.x, (y * 4 + x) * 10, 1e-4);
      CHECK_NEAR(v.z, (y * 4 + x) * 10 + 2, 1e-4);
    }
  /* halfway between texel (1,0) and (2,0): the mean; u = 0 wraps to blend columns 3 and 0 */
  CHECK_NEAR(kpcn_texture_eval(bm, 0.5f, 0.75f).x, 15.0, 1e-4);
  CHECK_NEAR(kpcn_texture_eval(bm, 0.0f, 0.75f).x, 15.0, 1e-4);
  CHECK_NEAR(kpcn_texture_eval(bm, 1.0f + 0.375f, 0.75f).x, 10.0, 1e-4); /* repeat */
  CHECK_NEAR(kpcn_texture_eval(bm, -0.625f, 0.75f).x, 10.0, 1e-4);
  CHECK_NEAR(bm->average.x, 35.0, 1e-4);

  /* ---- PNG: gamma-corrected, linear, and scalar (averaged raw bytes) ---- */
  unsigned char png[3 * 2 * 3] = {128, 64, 200, 255, 0,  21, 20, 100, 254,
                                  10,  20, 30,  40,  50, 60, 70, 80,  90};
  const char *png_path = kt_tmpfile("t.png");
  CHECK(stbi_write_png(png_path, 3, 2, 3, png, 3 * 3) != 0);
  kpcn_bitmap_options o;
  kpcn_bitmap_options_defaults(&o);
  o.interpolate = 0;
  const kpcn_texture *tg, *tl, *ts;
  CHECK(kpcn_texture_bitmap(tc, png_path, &o, &tg) == KPCN_OK);
  kpcn_vec3 v = kpcn_texture_eval(tg, 0.1f, 0.9f); /* texel (0,0) */
  CHECK_NEAR(v.x, 55 / 255.0, 1e-6);
  CHECK_NEAR(v.y, 12 / 255.0, 1e-6);
  CHECK_NEAR(v.z, kpcn_gamma_byte(200) / 255.0, 1e-6);
  o.gamma_correct = 0;
  CHECK(kpcn_texture_bitmap(tc, png_path, &o, &tl) == KPCN_OK);
  CHECK(tl != tg);
  v = kpcn_texture_eval(tl, 0.5f, 0.9f); /* texel (1,0) */
  CHECK_NEAR(v.x, 1.0, 1e-6);
  CHECK_NEAR(v.z, 21 / 255.0, 1e-6);
  o.gamma_correct = 1;
  o.scalar = 1;
  CHECK(kpcn_texture_bitmap(tc, png_path, &o, &ts) == KPCN_OK);
  CHECK_NEAR(kpcn_texture_eval_scalar(ts, 0.9f, 0.9f), ((20 + 100 + 254) / 3) / 255.0, 1e-6);
  const kpcn_texture *again;
  o.scalar = 0;
  o.gamma_correct = 1;
  CHECK(kpcn_texture_bitmap(tc, png_path, &o, &again) == KPCN_OK);
  CHECK(again == tg); /* cached */

  /* ---- HDR (RGBE, ~1% quantisation) ---- */
  float hdr[2 * 2 * 3] = {0.5f,   1.5f, 3.0f, 10.0f, 0.01f, 0.2f,
                          100.0f, 2.0f, 0.7f, 0.3f,  0.3f,  0.3f};
  const char *hdr_path = kt_tmpfile("t.hdr");
  CHECK(stbi_write_hdr(hdr_path, 2, 2, 3, hdr) != 0);
  const kpcn_texture *th;
  CHECK(kpcn_texture_bitmap(tc, hdr_path, NULL, &th) == KPCN_OK);
  v = kpcn_texture_eval(th, 0.25f, 0.25f); /* texel (0,1) */
  CHECK_CLOSE(v.x, 100.0, 0.01, 0.0);
  CHECK_CLOSE(v.y, 2.0, 0.01, 0.0);

  /* ---- errors name the file ---- */
  CHECK(kpcn_texture_bitmap(tc, "/nonexistent/tex.png", NULL, &th) == KPCN_ERR_IO);
  CHECK(contains(kpcn_last_error(), "/nonexistent/tex.png"));
  const char *junk = kt_tmpfile("junk.png");
  FILE *f = fopen(junk, "wb");
  fputs("not a png", f);
  fclose(f);
  CHECK(kpcn_texture_bitmap(tc, junk, NULL, &th) == KPCN_ERR_FORMAT);
  CHECK(contains(kpcn_last_error(), "junk.png"));
  kpcn_texture_cache_destroy(tc);

  /* ---- JSON: Tungsten's materialtest bsdfs ---- */
  {
    FILE *mf = fopen(KPCN_TESTDATA "/scenes/materialtest/materialtest.json", "rb");
    CHECK(mf != NULL);
    if (mf) {
      fseek(mf, 0, SEEK_END);
      long n = ftell(mf);
      fseek(mf, 0, SEEK_SET);
      char *txt = malloc((size_t)n + 1);
      CHECK(fread(txt, 1, (size_t)n, mf) == (size_t)n);
      txt[n] = 0;
      fclose(mf);
      kpcn_material_lib *lib;
      CHECK(parse_lib(txt, &lib) == KPCN_OK);
      free(txt);
      const kpcn_bsdf *mat = kpcn_material_lib_find(lib, "Material");
      const kpcn_bsdf *floor = kpcn_material_lib_find(lib, "Floor");
      const kpcn_bsdf *metal = kpcn_material_lib_find(lib, "rough_metal");
      CHECK(mat && floor && metal);
      CHECK(kpcn_bsdf_get_type(mat) == KPCN_BSDF_SMOOTH_COAT);
      CHECK(kpcn_bsdf_lobes(mat) == (KPCN_LOBE_SPECULAR | KPCN_LOBE_GLOSSY));
      kpcn_shading_point sp = {0.01f, 0.01f};
      CHECK_NEAR(kpcn_bsdf_albedo(floor, &sp).x, 0.325, 1e-6); /* checker off colour */
      sp.u = 0.06f;
      CHECK_NEAR(kpcn_bsdf_albedo(floor, &sp).x, 0.725, 1e-6);
      /* the same material built by hand evaluates identically */
      kpcn_bsdf_params p;
      kpcn_bsdf_params_defaults(&p, KPCN_BSDF_ROUGH_CONDUCTOR);
      p.distribution = KPCN_MF_BECKMANN;
      p.roughness_value = 0.1f;
      kpcn_bsdf *cu;
      CHECK(kpcn_bsdf_create(&p, &cu) == KPCN_OK);
      kpcn_bsdf_params_defaults(&p, KPCN_BSDF_SMOOTH_COAT);
      p.ior = 1.7f;
      p.thickness = 5.0f;
      p.sigma_a = kv3(0.1f, 0.2f, 0.5f);
      p.substrate = cu;
      kpcn_bsdf *coat;
      CHECK(kpcn_bsdf_create(&p, &coat) == KPCN_OK);
      kpcn_bsdf_eval_result e1, e2;
      kpcn_vec3 wo = kt_dir(30, 0), wi = kt_dir(28, 175);
      kpcn_bsdf_eval(mat, &sp, wo, wi, &e1);
      kpcn_bsdf_eval(coat, &sp, wo, wi, &e2);
      CHECK(e1.f_cos.x > 0 && e1.f_cos.x == e2.f_cos.x && e1.f_cos.z == e2.f_cos.z &&
            e1.pdf == e2.pdf);
      kpcn_bsdf_destroy(coat);
      kpcn_bsdf_destroy(cu);
      /* inline bsdf and name reference through kpcn_bsdf_parse */
      cJSON *node = cJSON_Parse("{\"type\": \"rough_plastic\", \"albedo\": [0.2, 0.4, 0.6], "
                                "\"roughness\": 0.3, \"distribution\": \"beckmann\"}");
      const kpcn_bsdf *b;
      CHECK(kpcn_bsdf_parse(lib, node, "primitives[1].bsdf", &b) == KPCN_OK);
      CHECK(kpcn_bsdf_get_type(b) == KPCN_BSDF_ROUGH_PLASTIC);
      CHECK_NEAR(kpcn_bsdf_albedo(b, &sp).y, 0.4, 1e-7);
      cJSON_Delete(node);
      node = cJSON_CreateString("Stand");
      CHECK(kpcn_bsdf_parse(lib, node, "primitives[2].bsdf", &b) == KPCN_OK);
      CHECK(kpcn_bsdf_get_type(b) == KPCN_BSDF_LAMBERT);
      cJSON_Delete(node);
      node = cJSON_CreateString("Nope");
      CHECK(kpcn_bsdf_parse(lib, node, "primitives[3].bsdf", &b) != KPCN_OK);
      CHECK(contains(kpcn_last_error(), "primitives[3].bsdf") &&
            contains(kpcn_last_error(), "Nope"));
      cJSON_Delete(node);
      kpcn_material_lib_destroy(lib);
    }
  }
  /* forward references, every type, texture objects */
  {
    kpcn_material_lib *lib;
    CHECK(parse_lib("{\"bsdfs\": ["
                    "{\"name\": \"c\", \"type\": \"smooth_coat\", \"substrate\": \"m\"},"
                    "{\"name\": \"m\", \"type\": \"conductor\", \"material\": \"Au\"},"
                    "{\"name\": \"e\", \"type\": \"conductor\", \"eta\": [0.2,0.9,1.1], \"k\": 3},"
                    "{\"name\": \"g\", \"type\": \"dielectric\", \"ior\": 1.33, "
                    "\"enable_refraction\": false},"
                    "{\"name\": \"h\", \"type\": \"rough_dielectric\", \"roughness\": 0.2},"
                    "{\"name\": \"i\", \"type\": \"mirror\", \"albedo\": 0.9},"
                    "{\"name\": \"j\", \"type\": \"plastic\", \"ior\": 1.4, \"thickness\": 2, "
                    "\"sigma_a\": 0.1},"
                    "{\"name\": \"n\", \"type\": \"null\"},"
                    "{\"name\": \"t\", \"type\": \"lambert\", \"albedo\": {\"type\": \"constant\", "
                    "\"value\": [1,0.5,0.25]}},"
                    "{\"name\": \"k\", \"type\": \"lambert\", \"albedo\": {\"type\": \"checker\"}},"
                    "{\"name\": \"r\", \"type\": \"rough_conductor\", \"roughness\": {\"type\": "
                    "\"checker\", \"on_color\": 0.5, \"off_color\": 0.1}}"
                    "]}",
                    &lib) == KPCN_OK);
    kpcn_shading_point sp = {0.01f, 0.01f};
    CHECK(kpcn_bsdf_is_delta_only(kpcn_material_lib_find(lib, "c")));
    CHECK(kpcn_bsdf_is_null(kpcn_material_lib_find(lib, "n")));
    CHECK(!kpcn_bsdf_is_transmissive(kpcn_material_lib_find(lib, "g")));
    CHECK(kpcn_bsdf_is_transmissive(kpcn_material_lib_find(lib, "h")));
    CHECK_NEAR(kpcn_bsdf_albedo(kpcn_material_lib_find(lib, "t"), &sp).z, 0.25, 1e-7);
    CHECK_NEAR(kpcn_bsdf_albedo(kpcn_material_lib_find(lib, "k"), &sp).z, 0.2,
               1e-7); /* default off */
    kpcn_material_lib_destroy(lib);
  }
  /* ---- errors carry the JSON path ---- */
  expect_error(
      "{\"bsdfs\": [{\"name\": \"a\", \"type\": \"rough_conductor\", \"distribution\": \"foo\"}]}",
      "bsdfs[0].distribution: unknown value 'foo'");
  expect_error("{\"bsdfs\": [{\"name\": \"a\", \"type\": \"lambert\"}, {\"name\": \"b\", \"type\": "
               "\"velvet\"}]}",
               "bsdfs[1].type: unsupported bsdf type 'velvet'");
  expect_error("{\"bsdfs\": [{\"name\": \"a\", \"type\": \"lambert\", \"roughness\": 0.2}]}",
               "bsdfs[0].roughness: unsupported field");
  expect_error(
      "{\"bsdfs\": [{\"name\": \"a\", \"type\": \"conductor\", \"material\": \"Kryptonite\"}]}",
      "bsdfs[0].material: unknown conductor 'Kryptonite'");
  expect_error("{\"bsdfs\": [{\"name\": \"a\", \"type\": \"smooth_coat\", \"substrate\": \"zz\"}]}",
               "bsdfs[0].substrate: no bsdf named 'zz'");
  expect_error("{\"bsdfs\": [{\"name\": \"a\", \"type\": \"smooth_coat\", \"substrate\": \"a\"}]}",
               "cycle");
  expect_error(
      "{\"bsdfs\": [{\"name\": \"a\", \"type\": \"lambert\", \"albedo\": \"missing.png\"}]}",
      "missing.png");
  expect_error(
      "{\"bsdfs\": [{\"name\": \"a\", \"type\": \"lambert\", \"albedo\": {\"type\": \"wood\"}}]}",
      "bsdfs[0].albedo.type: unsupported texture type 'wood'");
  expect_error("{\"bsdfs\": [{\"name\": \"a\", \"type\": \"lambert\", \"albedo\": [1, 2]}]}",
               "bsdfs[0].albedo");
  expect_error("{\"bsdfs\": [{\"name\": \"a\", \"type\": \"dielectric\", \"ior\": -1}]}",
               "bsdfs[0].ior");
  expect_error("{\"bsdfs\": [{\"name\": \"a\", \"type\": \"conductor\", \"eta\": 1}]}",
               "bsdfs[0].eta");
  expect_error("{\"bsdfs\": [{\"type\": \"lambert\"}]}", "bsdfs[0].name");
  expect_error("{\"bsdfs\": [{\"name\": \"a\", \"type\": \"smooth_coat\", \"albedo\": 0.5}]}",
               "bsdfs[0].albedo: smooth_coat ignores albedo");
  expect_error("{\"bsdfs\": [{\"name\": \"a\", \"type\": \"lambert\"}, {\"name\": \"a\", \"type\": "
               "\"lambert\"}]}",
               "duplicate");
  expect_error("{\"bsdfs\": [{\"name\": \"a\", \"type\": \"lambert\", \"bump\": \"b.png\"}]}",
               "bsdfs[0].bump: unsupported field");
  return kt_summary("render_texture_json");
}
