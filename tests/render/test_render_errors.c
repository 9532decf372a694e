/* Malformed scenes: every failure is a clear error naming the JSON path (or file), never a
 * crash or a silently different scene; the tool exits non-zero and writes no file. */
#include "core/internal.h"
#include "render/render_internal.h"
#include "render_testutil.h"
#include "testutil.h"

#include <float.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#define LIGHT "{\"type\":\"quad\",\"bsdf\":{\"type\":\"null\"},\"emission\":5}"

/* Loads json and expects failure with every `needle` in the message. */
static void expect_fail(const char *what, const char *json, const char *needle1,
                        const char *needle2) {
  kpcn_scene *s = NULL;
  kpcn_status st = kpcn_scene_load_json(json, kt_tmpdir(), "bad.json", &s);
  const char *msg = kpcn_last_error();
  printf("%-28s -> status %d: %s\n", what, (int)st, msg);
  CHECK(st != KPCN_OK);
  CHECK(s == NULL);
  if (needle1) CHECK(strstr(msg, needle1) != NULL);
  if (needle2) CHECK(strstr(msg, needle2) != NULL);
  kpcn_scene_destroy(s);
}

static void write_file(const char *path, const void *data, size_t n) {
  FILE *f = fopen(path, "wb");
  if (f) {
    fwrite(data, 1, n, f);
    fclose(f);
  }
}

static int file_exists(const char *p) {
  struct stat sb;
  return stat(p, &sb) == 0;
}

static int run(const char *cmd) {
  int rc = system(cmd);
  return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
}

/* Runs `exe scene -o out args` with stderr captured; expects exit code rc, `needle` in the
 * messages (NULL: any), and an output file exactly when rc is 0. */
static void expect_cli(const char *exe, const char *scene, const char *args, int rc,
                       const char *needle) {
  char cmd[4096], out[1024], err[1024];
  snprintf(out, sizeof(out), "%s", kt_tmpfile("cli.exr"));
  snprintf(err, sizeof(err), "%s", kt_tmpfile("cli.err"));
  remove(out);
  snprintf(cmd, sizeof(cmd), "%s %s -o %s --threads 1 %s 2>%s", exe, scene, out, args, err);
  int got = run(cmd);
  char *msg = kt_slurp(err, NULL);
  printf("kpcn-render %-40s -> rc %d: %s", args, got, msg ? msg : "(no stderr)\n");
  CHECK(got == rc);
  if (needle) CHECK(msg && strstr(msg, needle) != NULL);
  CHECK(file_exists(out) == (rc == 0));
  free(msg);
  remove(out);
}

/* Option values that used to wrap, clamp or slip through (see docs/robustness.md). */
static void test_tool_options(const char *exe) {
  const char *cornell = KPCN_TESTDATA "/scenes/cornell-box/scene.json";
  /* sscanf's %d wrapped these to 16x8 and rendered; the message quotes what was typed */
  expect_cli(exe, cornell, "--spp 1 --resolution 4294967312x4294967304", 2,
             "'4294967312x4294967304'");
  expect_cli(exe, cornell, "--spp 1 --resolution 99999999999x16", 2, "'99999999999x16'");
  expect_cli(exe, cornell, "--spp 1 --resolution 16x16x", 2, "--resolution");
  expect_cli(exe, cornell, "--spp 1 --resolution ' 16x16'", 2, "--resolution");
  /* cx + cw overflowed the bound check */
  expect_cli(exe, cornell, "--spp 1 --crop 2147483647,2147483647,1,1", 2,
             "'2147483647,2147483647,1,1'");
  expect_cli(exe, cornell, "--spp 1 --resolution 16x16 --crop 65535,0,1,1", 1, "crop");
  expect_cli(exe, cornell, "--spp 1 --crop -1,0,4,4", 2, "--crop");
  /* strtoll clamped silently; a negative seed rendered without kpcn:seed in the header */
  expect_cli(exe, cornell, "--spp 1 --seed 99999999999999999999", 2, "'99999999999999999999'");
  expect_cli(exe, cornell, "--spp 1 --seed -1", 2, "--seed");
  char out[1024];
  snprintf(out, sizeof(out), "%s", kt_tmpfile("seed.exr"));
  char cmd[4096];
  snprintf(cmd, sizeof(cmd), "%s %s -o %s --spp 1 --threads 1 --resolution 8x8 --seed %s", exe,
           cornell, out, "9223372036854775807");
  CHECK(run(cmd) == 0);
  kpcn_exr_info_t info;
  CHECK(kpcn_exr_info(out, &info) == KPCN_OK && info.seed == INT64_MAX);
  remove(out);
  /* a path whose radiance overflows float is counted as black, and said so */
  char hot[1024];
  snprintf(hot, sizeof(hot), "%s", kt_tmpfile("hot.json"));
  const char *json =
      "{\"primitives\":[{\"type\":\"quad\",\"bsdf\":{\"type\":\"null\"},\"emission\":1e15,"
      "\"transform\":{\"position\":[0,1,0],\"scale\":0.5,\"rotation\":[180,0,0]}},"
      "{\"type\":\"quad\",\"bsdf\":{\"type\":\"lambert\",\"albedo\":1e30},"
      "\"transform\":{\"scale\":4}}],\"camera\":{\"type\":\"pinhole\","
      "\"transform\":{\"position\":[0,0.5,2],\"look_at\":[0,0,0]}}}";
  write_file(hot, json, strlen(json));
  expect_cli(exe, hot, "--spp 2 --resolution 8x8", 0, "non-finite");
  /* --half holds at most 65504: a brighter value (a light of 1e5 seen directly) is stored as
   * 65504 and said, never as Inf */
  char bright[1024], half_out[1100];
  snprintf(bright, sizeof(bright), "%s", kt_tmpfile("bright.json"));
  snprintf(half_out, sizeof(half_out), "%s", kt_tmpfile("bright_half.exr"));
  const char *bjson =
      "{\"primitives\":[{\"type\":\"quad\",\"bsdf\":{\"type\":\"null\"},\"emission\":1e5,"
      "\"transform\":{\"scale\":4}}],\"camera\":{\"type\":\"pinhole\","
      "\"transform\":{\"position\":[0,2,0],\"look_at\":[0,0,0],\"up\":[0,0,1]}}}";
  write_file(bright, bjson, strlen(bjson));
  char hcmd[8192];
  snprintf(hcmd, sizeof hcmd, "%s %s -o %s --spp 2 --resolution 8x8 --half --quiet 2>%s.err", exe,
           bright, half_out, half_out);
  CHECK(run(hcmd) == 0);
  snprintf(hcmd, sizeof hcmd, "grep -q 'beyond half.s range were stored as +-65504' %s.err",
           half_out);
  CHECK(run(hcmd) == 0);
  kpcn_image *h = NULL;
  CHECK(kpcn_exr_read_image(half_out, &h) == KPCN_OK);
  int inf = 0, at_max = 0;
  for (size_t i = 0; h && i < (size_t)h->width * h->height * (size_t)h->nchannels; i++)
    inf += isinf(h->data[i]), at_max += h->data[i] == 65504.0f;
  CHECK(h && inf == 0 && at_max > 0);
  kpcn_image_destroy(h);
}

/* Output paths refused before rendering, each left as it was: a name that is not .exr, a
 * missing folder, a FIFO, a directory, and the scene file itself (through a link named .exr). */
static void test_tool_outputs(const char *exe) {
  const char *cornell = KPCN_TESTDATA "/scenes/cornell-box/scene.json";
  char dir[512];
  snprintf(dir, sizeof dir, "%s", kt_tmpfile("outs"));
  char cmd[4096];
  snprintf(cmd, sizeof cmd,
           "rm -rf %s && mkdir -p %s/adir.exr && mkfifo %s/fifo.exr && ln -s %s %s/scene.exr", dir,
           dir, dir, cornell, dir);
  CHECK(run(cmd) == 0);
  static const char *const cases[][2] = {{"x.png", "must end in .exr"},
                                         {"nodir/x.exr", "folder 'nodir'"},
                                         {"fifo.exr", "is not a regular file"},
                                         {"adir.exr", "is a directory"},
                                         {"scene.exr", "is the scene file"}};
  for (size_t k = 0; k < sizeof cases / sizeof cases[0]; k++) {
    snprintf(cmd, sizeof cmd, "cd %s && %s %s -o %s --spp 1 --resolution 8x8 --threads 1 2>err.txt",
             dir, exe, cornell, cases[k][0]);
    if (!strcmp(cases[k][0], "scene.exr"))
      snprintf(cmd, sizeof cmd, "cd %s && %s scene.exr -o ./scene.exr --spp 1 2>err.txt", dir, exe);
    const int rc = run(cmd);
    char err[1200];
    snprintf(err, sizeof err, "%s/err.txt", dir);
    char *msg = kt_slurp(err, NULL);
    printf("kpcn-render -o %-12s -> rc %d: %s", cases[k][0], rc, msg ? msg : "(no stderr)\n");
    CHECK(rc == 2 && msg && strstr(msg, cases[k][1]));
    free(msg);
  }
  struct stat st;
  char p[1200];
  snprintf(p, sizeof p, "%s/fifo.exr", dir);
  CHECK(stat(p, &st) == 0 && S_ISFIFO(st.st_mode));
  snprintf(p, sizeof p, "%s/adir.exr", dir);
  CHECK(stat(p, &st) == 0 && S_ISDIR(st.st_mode));
  snprintf(p, sizeof p, "%s/x.png", dir);
  CHECK(!file_exists(p));
  char *scene = kt_slurp(cornell, NULL);
  CHECK(scene && scene[0] == '{'); /* still the scene */
  free(scene);
  snprintf(cmd, sizeof cmd, "rm -rf %s", dir);
  CHECK(run(cmd) == 0);
}

static void test_tool(void) {
  const char *bin = getenv("KPCN_RENDER_BIN");
  char exe[1024];
  snprintf(exe, sizeof(exe), "%s", bin ? bin : KPCN_BINARY_DIR "/tools/kpcn-render/kpcn-render");
  if (!file_exists(exe)) {
    fprintf(stderr, "kpcn-render not found at %s\n", exe);
    CHECK(0);
    return;
  }
  char cmd[4096], out[1024], bad[1024];
  snprintf(out, sizeof(out), "%s", kt_tmpfile("out.exr"));
  snprintf(bad, sizeof(bad), "%s", kt_tmpfile("bad.json"));
  write_file(bad, "{\"primitives\": [", 16);
  const char *cornell = KPCN_TESTDATA "/scenes/cornell-box/scene.json";
  /* each refused naming what is wrong, with its exit status and no output file */
  expect_cli(exe, "/nonexistent/scene.json", "", 1,
             "cannot open scene '/nonexistent/scene.json': No such file");
  expect_cli(exe, bad, "", 1, "invalid JSON near line 1 (byte 16)");
  expect_cli(exe, cornell, "--spp zero", 2,
             "--spp: expected an integer in [1, 16777216], got 'zero'");
  expect_cli(exe, cornell, "--threads 100000", 2, "--threads: expected an integer in [0, 1024]");
  expect_cli(exe, cornell, "--crop 0,0,999,999 --resolution 16x16", 1,
             "crop 0,0,999,999 lies outside the 16x16 image");
  /* an albedo pass with fewer samples than the colour, or on a colour-only render: refused,
   * nothing written; a non-number: usage */
  expect_cli(exe, cornell, "--spp 8 --albedo-spp 4 --resolution 16x16", 1,
             "albedo_spp (--albedo-spp): 4 is below the render's 8 samples per pixel (as asked)");
  expect_cli(exe, cornell, "--albedo-spp 4 --resolution 16x16", 1,
             "is below the render's 64 samples per pixel (the scene's)");
  /* checkpoint timing without a checkpoint would be ignored: refused */
  expect_cli(exe, cornell, "--checkpoint-every 5", 2, "--checkpoint-every needs --checkpoint");
  expect_cli(exe, cornell, "--spp 2 --albedo-spp 8 --color-only --resolution 16x16", 1,
             "a colour-only render has no albedo buffer");
  expect_cli(exe, cornell, "--albedo-spp many", 2, "--albedo-spp: expected an integer");
  /* the albedo footprint: 1 .. 16, never on a colour-only render */
  expect_cli(exe, cornell, "--albedo-footprint 17", 2,
             "--albedo-footprint: expected an integer in [1, 16], got '17'");
  expect_cli(exe, cornell, "--albedo-footprint 0", 2, "--albedo-footprint: expected an integer");
  expect_cli(exe, cornell, "--albedo-footprint 2 --color-only --resolution 16x16", 1,
             "albedo_footprint: a colour-only render has no albedo buffer");
  /* a good render writes the file, nothing else is left behind */
  snprintf(cmd, sizeof(cmd), "%s %s -o %s --spp 1 --resolution 16x16 --threads 1", exe,
           KPCN_TESTDATA "/scenes/cornell-box/scene.json", out);
  CHECK(run(cmd) == 0);
  CHECK(file_exists(out));
  kpcn_exr_info_t info;
  CHECK(kpcn_exr_info(out, &info) == KPCN_OK);
  CHECK(info.width == 16 && info.height == 16 && info.spp == 1);
  for (int b = 0; b < KPCN_BUF_COUNT; b++)
    CHECK(info.has_buffer[b] && info.has_variance[b]);
  /* --compression: another encoding of the same pixels; an unknown one is a usage error */
  char out2[1100];
  snprintf(out2, sizeof out2, "%s.none.exr", out);
  snprintf(cmd, sizeof(cmd),
           "%s %s -o %s --spp 1 --resolution 16x16 --threads 1 --compression none", exe,
           KPCN_TESTDATA "/scenes/cornell-box/scene.json", out2);
  CHECK(run(cmd) == 0);
  kpcn_image *zip = NULL, *none = NULL;
  CHECK(kpcn_exr_read_image(out, &zip) == KPCN_OK && kpcn_exr_read_image(out2, &none) == KPCN_OK);
  CHECK(zip && none && zip->nchannels == none->nchannels &&
        memcmp(zip->data, none->data, sizeof(float) * 256 * (size_t)zip->nchannels) == 0);
  kpcn_image_destroy(zip);
  kpcn_image_destroy(none);
  remove(out2);
  expect_cli(exe, cornell, "--compression lz4", 2,
             "--compression 'lz4' is not zip, zips, piz, rle or none");
  test_tool_options(exe);
  test_tool_outputs(exe);
}

#define CAM(fields) "{\"primitives\":[" LIGHT "],\"camera\":{" fields "}}"
#define PRIM2(prim) "{\"primitives\":[" LIGHT "," prim "]}"

/* Values that passed a check on the JSON double but not as the float the renderer uses, and
 * fields whose wrong type or sign was silently accepted. */
static void test_scene_values(void) {
  /* messages name what the file holds (session 61): a texture given as a number list is
   * path[i], not path.value[i]; a degenerate view names the fields that made it; the
   * offending value is printed */
  expect_fail("albedo list item",
              "{\"primitives\":[{\"type\":\"quad\",\"bsdf\":{\"type\":\"lambert\","
              "\"albedo\":[0.5,\"x\",0.5]}}]}",
              "primitives[0].bsdf.albedo[1]: expected a finite number", NULL);
  expect_fail("degenerate lookAt",
              CAM("\"type\":\"pinhole\",\"position\":[0,0,2],\"lookAt\":[0,0,2]"),
              "camera.lookAt / camera.up: degenerate view", NULL);
  expect_fail("negative ior",
              "{\"primitives\":[{\"type\":\"quad\",\"bsdf\":{\"type\":\"dielectric\","
              "\"ior\":-1.5}}]}",
              "ior: -1.5 is outside [1e-4, 1e4]", NULL);
  /* session 62 (a review against Tungsten and the docs): values that rendered NaN, negative
   * or exploding radiance, or fields that were read and ignored, are refused by JSON path */
  expect_fail("denormal ior",
              "{\"primitives\":[{\"type\":\"quad\",\"bsdf\":{\"type\":\"plastic\","
              "\"ior\":1e-40}}]}",
              "is outside [1e-4, 1e4]", "bsdf.ior: 9.99995e-41");
  expect_fail("huge roughness",
              "{\"primitives\":[{\"type\":\"quad\",\"bsdf\":{\"type\":\"rough_conductor\","
              "\"roughness\":1e20}}]}",
              "bsdf.roughness: 1e+20 is above 1e4", NULL);
  expect_fail("RGB roughness",
              "{\"primitives\":[{\"type\":\"quad\",\"bsdf\":{\"type\":\"rough_conductor\","
              "\"roughness\":[0.1,0.2,0.3]}}]}",
              "bsdf.roughness: a colour (0.1, 0.2, 0.3) is not one roughness", NULL);
  expect_fail("RGB checker roughness",
              "{\"primitives\":[{\"type\":\"quad\",\"bsdf\":{\"type\":\"rough_plastic\","
              "\"roughness\":{\"type\":\"checker\",\"on_color\":[0.1,0.1,0.2]}}}]}",
              "bsdf.roughness: a colour", NULL);
  expect_fail("plastic albedo at its pole",
              "{\"primitives\":[{\"type\":\"quad\",\"bsdf\":{\"type\":\"plastic\","
              "\"albedo\":2}}]}",
              "bsdf.albedo: 2 reaches the plastic's limit 1/F_dr", NULL);
  expect_fail("conductor name and eta/k",
              "{\"primitives\":[{\"type\":\"quad\",\"bsdf\":{\"type\":\"conductor\","
              "\"material\":\"Au\",\"eta\":[1,1,1],\"k\":[0,0,0]}}]}",
              "bsdf.material: give a conductor name or", NULL);
  expect_fail("no palik twin",
              "{\"primitives\":[{\"type\":\"quad\",\"bsdf\":{\"type\":\"conductor\","
              "\"material\":\"Au_palik\"}}]}",
              "unknown conductor 'Au_palik'", NULL);
  expect_fail("inline bsdf name not a string",
              "{\"primitives\":[{\"type\":\"quad\",\"bsdf\":{\"type\":\"lambert\","
              "\"name\":3}}]}",
              "primitives[0].bsdf.name: not a string", NULL);
  /* 0 or a denormal as a float: 1/tan(fov/2) was Inf and Embree aborted */
  expect_fail("tiny fov", CAM("\"type\":\"pinhole\",\"fov\":1e-38"), "camera.fov", NULL);
  expect_fail("fov rounding to 180", CAM("\"type\":\"pinhole\",\"fov\":179.99999999"), "camera.fov",
              "180 as a float");
  expect_fail("huge focus distance",
              CAM("\"type\":\"thinlens\",\"focus_distance\":1e39,\"aperture_size\":0.1"),
              "camera.focus_distance", NULL);
  expect_fail("tiny focus distance",
              CAM("\"type\":\"thinlens\",\"focus_distance\":1e-300,\"aperture_size\":0.1"),
              "camera.focus_distance", NULL);
  expect_fail("negative aperture", CAM("\"type\":\"thinlens\",\"aperture_size\":-1"),
              "camera.aperture_size", NULL);
  /* emission: bounded so its square stays a float; textures follow the constants' rules */
  expect_fail("huge emission",
              "{\"primitives\":[{\"type\":\"quad\",\"bsdf\":{\"type\":\"null\"},"
              "\"emission\":1e30}]}",
              "primitives[0].emission", "maximum");
  expect_fail("huge checker emission",
              "{\"primitives\":[{\"type\":\"quad\",\"bsdf\":{\"type\":\"null\"},"
              "\"emission\":{\"type\":\"checker\",\"off_color\":[1,1e20,1]}}]}",
              "primitives[0].emission", "maximum");
  expect_fail("negative checker emission",
              "{\"primitives\":[{\"type\":\"quad\",\"bsdf\":{\"type\":\"null\"},"
              "\"emission\":{\"type\":\"checker\",\"on_color\":-1}}]}",
              "primitives[0].emission", "negative");
  expect_fail("huge environment",
              "{\"primitives\":[{\"type\":\"infinite_sphere\",\"emission\":[1,1,2e15]}]}",
              "primitives[0].emission", "maximum");
  /* Tungsten's own primitives kpcn lacks are named by type, not by their first field */
  expect_fail("skydome", "{\"primitives\":[{\"type\":\"skydome\",\"temperature\":5777}]}",
              "unsupported primitive type 'skydome'", NULL);
  expect_fail("point light", "{\"primitives\":[{\"type\":\"point\",\"power\":10}]}",
              "unsupported primitive type 'point'", NULL);
  expect_fail("bsdf list", "{\"primitives\":[{\"type\":\"quad\",\"bsdf\":[\"a\",\"b\"]}]}",
              "a list of bsdfs (one per mesh material group) is not supported", NULL);
  expect_fail("media null", "{\"media\":null,\"primitives\":[" LIGHT "]}",
              "media: expected an array", NULL);
  /* the camera: a scale in its transform, or the old fields beside it, were dropped silently */
  expect_fail("camera scale", CAM("\"type\":\"pinhole\",\"transform\":{\"scale\":[1,2,1]}"),
              "camera.transform: a scale is not supported", "y axis has length 2");
  expect_fail("camera mirror", CAM("\"type\":\"pinhole\",\"transform\":{\"scale\":[-1,1,1]}"),
              "camera.transform: a mirroring transform", NULL);
  expect_fail("camera both",
              CAM("\"type\":\"pinhole\",\"transform\":{\"position\":[0,0,0]},"
                  "\"position\":[0,1,0]"),
              "camera.position: given beside camera.transform", NULL);
  /* malformed documents */
  expect_fail("text after the document", "{\"primitives\":[" LIGHT "]} garbage", "invalid JSON",
              "text after the end");
  expect_fail("duplicate key", "{\"primitives\":[" LIGHT "],\"renderer\":{\"spp\":1,\"spp\":0}}",
              "renderer.spp", "duplicate key");
  expect_fail("nested duplicate key",
              PRIM2("{\"type\":\"quad\",\"bsdf\":{\"type\":\"lambert\",\"albedo\":0.5,"
                    "\"albedo\":0.2}}"),
              "primitives[1].bsdf.albedo", "duplicate key");
  { /* an object too large to compare pairwise: its keys are sorted */
    char big[4096] = "{\"primitives\":[" LIGHT "],\"camera\":{\"type\":\"pinhole\"";
    for (int i = 0; i < 40; i++)
      snprintf(big + strlen(big), sizeof(big) - strlen(big), ",\"k%d\":%d", i, i);
    strcat(big, ",\"k17\":[1,2]}}");
    expect_fail("duplicate key, large object", big, "camera.k17", "duplicate key");
  }
  {
    char nul[1024];
    snprintf(nul, sizeof(nul), "%s", kt_tmpfile("nul.json"));
    static const char text[] = "{\"primitives\":[" LIGHT "]}\0 garbage";
    write_file(nul, text, sizeof(text) - 1);
    kpcn_scene *sn = NULL;
    CHECK(kpcn_scene_load(nul, &sn) == KPCN_ERR_FORMAT && sn == NULL);
    CHECK(strstr(kpcn_last_error(), "NUL byte") != NULL);
  }
  /* transforms: all 16 numbers, as floats, and an affine last row */
  expect_fail("matrix, strings in the last row",
              PRIM2("{\"type\":\"cube\",\"bsdf\":{\"type\":\"lambert\"},\"transform\":"
                    "[1,0,0,0,0,1,0,0,0,0,1,0,\"a\",\"b\",\"c\",\"d\"]}"),
              "primitives[1].transform[12]", "expected a number");
  expect_fail("projective matrix",
              PRIM2("{\"type\":\"cube\",\"bsdf\":{\"type\":\"lambert\"},\"transform\":"
                    "[1,0,0,0,0,1,0,0,0,0,1,0,0,0,1,1]}"),
              "primitives[1].transform[14]", "last row");
  expect_fail("matrix entry beyond float",
              PRIM2("{\"type\":\"cube\",\"bsdf\":{\"type\":\"lambert\"},\"transform\":"
                    "[1,0,0,1e39,0,1,0,0,0,0,1,0,0,0,0,1]}"),
              "primitives[1].transform[3]", "non-finite");
  /* wrong types */
  expect_fail("numeric name",
              "{\"primitives\":[{\"type\":\"quad\",\"name\":5,\"bsdf\":{\"type\":\"null\"},"
              "\"emission\":1}]}",
              "primitives[0].name", "string");
  expect_fail("infinite_sphere bsdf",
              PRIM2("{\"type\":\"infinite_sphere\",\"emission\":1,\"bsdf\":5}"),
              "primitives[1].bsdf", NULL);
  expect_fail("numeric bool",
              PRIM2("{\"type\":\"sphere\",\"bsdf\":{\"type\":\"dielectric\","
                    "\"enable_refraction\":7}}"),
              "primitives[1].bsdf.enable_refraction", "true or false");
  /* negative albedo, as negative emission: constant, checker, bitmap scale */
  expect_fail("negative albedo",
              PRIM2("{\"type\":\"sphere\",\"bsdf\":{\"type\":\"lambert\","
                    "\"albedo\":[0.5,-0.1,0.5]}}"),
              "primitives[1].bsdf.albedo", "negative");
  expect_fail("negative checker albedo",
              PRIM2("{\"type\":\"sphere\",\"bsdf\":{\"type\":\"lambert\","
                    "\"albedo\":{\"type\":\"checker\",\"off_color\":-0.5}}}"),
              "primitives[1].bsdf.albedo", "negative");
  expect_fail("negative bitmap scale",
              PRIM2("{\"type\":\"sphere\",\"bsdf\":{\"type\":\"lambert\","
                    "\"albedo\":{\"type\":\"bitmap\",\"file\":\"x.png\",\"scale\":-1}}}"),
              "primitives[1].bsdf.albedo.scale", "negative");
  expect_fail("albedo beyond float",
              PRIM2("{\"type\":\"sphere\",\"bsdf\":{\"type\":\"lambert\","
                    "\"albedo\":{\"type\":\"checker\",\"on_color\":1e39}}}"),
              "primitives[1].bsdf.albedo.on_color", "non-finite");
  /* the edges of the accepted ranges still load */
  const char *good[] = {CAM("\"type\":\"pinhole\",\"fov\":0.001"),
                        CAM("\"type\":\"pinhole\",\"fov\":179.99"),
                        CAM("\"type\":\"thinlens\",\"focus_distance\":1e15"),
                        "{\"primitives\":[{\"type\":\"quad\",\"bsdf\":{\"type\":\"null\"},"
                        "\"emission\":1e15,\"transform\":[1,0,0,0,0,1,0,0,0,0,1,0,0,0,0,1]}]}",
                        PRIM2("{\"type\":\"infinite_sphere\",\"emission\":1,"
                              "\"bsdf\":{\"type\":\"null\",\"albedo\":1}}")};
  for (size_t i = 0; i < sizeof(good) / sizeof(good[0]); i++) {
    kpcn_scene *sg = NULL;
    kpcn_status st = kpcn_scene_load_json(good[i], NULL, "good.json", &sg);
    if (st != KPCN_OK) printf("good scene %zu: %s\n", i, kpcn_last_error());
    CHECK(st == KPCN_OK);
    kpcn_scene_destroy(sg);
  }
}

/* Settings the library refuses, and how it stores values beyond float range. */
static int cancel_always(void *user, double f) {
  (void)user, (void)f;
  return 1;
}

static void test_render_limits(void) {
  kpcn_scene *s = NULL;
  CHECK(kpcn_scene_load_json("{\"primitives\":[" LIGHT "]}", NULL, "light.json", &s) == KPCN_OK);
  kpcn_render_settings rs = kpcn_render_settings_defaults();
  rs.spp = 1, rs.nthreads = 1, rs.width = rs.height = 8;
  kpcn_aov_set *aov = NULL;
  rs.seed = -1; /* the header could not record it */
  CHECK(kpcn_render(s, &rs, &aov) == KPCN_ERR_INVALID_ARGUMENT && aov == NULL);
  CHECK(strstr(kpcn_last_error(), "seed") != NULL);
  rs.seed = 1;
  rs.crop_x = rs.crop_y = 2147483647, rs.crop_w = rs.crop_h = 1; /* cx + cw overflowed */
  CHECK(kpcn_render(s, &rs, &aov) == KPCN_ERR_INVALID_ARGUMENT && aov == NULL);
  CHECK(strstr(kpcn_last_error(), "crop") != NULL);
  /* session 61: a negative crop size at offset 0 rendered the whole image; a light strategy
   * outside the enum rendered a wrong estimate (and a checkpoint took it for BSDF-only) */
  rs.crop_x = rs.crop_y = 0, rs.crop_w = -5, rs.crop_h = 0;
  CHECK(kpcn_render(s, &rs, &aov) == KPCN_ERR_INVALID_ARGUMENT && aov == NULL);
  CHECK(strstr(kpcn_last_error(), "crop 0,0,-5,0 is empty") != NULL);
  rs.crop_w = 0;
  rs.lights = (kpcn_light_strategy)99;
  CHECK(kpcn_render(s, &rs, &aov) == KPCN_ERR_INVALID_ARGUMENT && aov == NULL);
  CHECK(strstr(kpcn_last_error(), "lights = 99") != NULL);
  rs.lights = KPCN_LIGHTS_SCENE;
  /* the camera samples of an albedo pass are counted (2 + 6 per pixel) */
  kpcn_render_stats rst;
  rs.spp = 2, rs.albedo_spp = 6;
  CHECK(kpcn_render_ex(s, &rs, &aov, &rst) == KPCN_OK && rst.samples == 8u * 8u * 8u);
  kpcn_aov_destroy(aov);
  aov = NULL;
  rs.spp = 1, rs.albedo_spp = 0;
  /* a callback that always cancels cancels a render whose rows other threads finish: the
   * final call's answer counts (14 of 40 such renders returned an image) */
  rs.progress = cancel_always, rs.nthreads = 8, rs.height = 1;
  for (int k = 0; k < 40; k++) {
    CHECK(kpcn_render(s, &rs, &aov) == KPCN_ERR_CANCELLED && aov == NULL);
    kpcn_aov_destroy(aov);
    aov = NULL;
  }
  rs.progress = NULL, rs.nthreads = 1, rs.height = 8;
  kpcn_scene_destroy(s);
  /* a scene path longer than the loader holds is refused, not cut (a shortened folder read
   * another folder's textures) */
  {
    char longdir[5000];
    memset(longdir, 'd', sizeof longdir - 1);
    longdir[sizeof longdir - 1] = 0;
    longdir[0] = '/';
    CHECK(kpcn_scene_load_json("{\"primitives\":[" LIGHT "]}", longdir, "x.json", &s) ==
              KPCN_ERR_INVALID_ARGUMENT &&
          s == NULL);
    CHECK(strstr(kpcn_last_error(), "longer than 4095") != NULL);
  }

  /* the buffer estimate against the memory available: 16384^2 x 24 planes is 25.8 GB */
  CHECK(kpcn_render_check_memory(16384, 16384, 24, 23000000000ull) == KPCN_ERR_OUT_OF_MEMORY);
  printf("memory check: %s\n", kpcn_last_error());
  CHECK(strstr(kpcn_last_error(), "25.77 GB") && strstr(kpcn_last_error(), "23.00 GB"));
  CHECK(kpcn_render_check_memory(16384, 16384, 24, 26000000000ull) == KPCN_OK);
  CHECK(kpcn_render_check_memory(1920, 1080, 24, 0) == KPCN_OK); /* this machine */
  /* by default the memory available now, at most the physical: a render that needs more than
   * is available (but less than physical) is refused, not killed part-way */
  CHECK(kpcn_available_memory() > 0 && kpcn_available_memory() <= kpcn_physical_memory());
  {
    const uint64_t avail = kpcn_available_memory(), px = avail / (24 * sizeof(float)) + 4096;
    const int side = (int)ceil(sqrt((double)px));
    if ((uint64_t)side * (uint64_t)side * 24u * sizeof(float) < kpcn_physical_memory()) {
      CHECK(kpcn_render_check_memory(side, side, 24, 0) == KPCN_ERR_OUT_OF_MEMORY);
      CHECK(strstr(kpcn_last_error(), "available") != NULL);
    }
  }

  /* a thin lens whose focus plane squares past float range at this aspect ratio */
  CHECK(kpcn_scene_load_json(CAM("\"type\":\"thinlens\",\"focus_distance\":1e15,"
                                 "\"fov\":179.99,\"aperture_size\":0.1"),
                             NULL, "lens.json", &s) == KPCN_OK);
  CHECK(kpcn_render(s, &rs, &aov) == KPCN_ERR_INVALID_ARGUMENT && aov == NULL);
  CHECK(strstr(kpcn_last_error(), "focus plane") != NULL);
  kpcn_scene_destroy(s);

  /* albedo 1e10 under emission 1e15: finite samples whose variance is beyond float range is
   * saturated at FLT_MAX; with albedo 1e30 the samples themselves overflow: counted */
  for (int k = 0; k < 2; k++) {
    char json[1024];
    snprintf(json, sizeof(json),
             "{\"primitives\":[{\"type\":\"quad\",\"bsdf\":{\"type\":\"null\"},\"emission\":"
             "1e15,\"transform\":{\"position\":[0,1,0],\"scale\":0.5,\"rotation\":[180,0,0]}},"
             "{\"type\":\"quad\",\"bsdf\":{\"type\":\"lambert\",\"albedo\":%s},"
             "\"transform\":{\"scale\":4}}],\"camera\":{\"type\":\"pinhole\","
             "\"transform\":{\"position\":[0,0.5,2],\"look_at\":[0,0,0]}}}",
             k ? "1e30" : "1e10");
    CHECK(kpcn_scene_load_json(json, NULL, "hot.json", &s) == KPCN_OK);
    rs.crop_x = rs.crop_y = rs.crop_w = rs.crop_h = 0;
    rs.spp = 4;
    kpcn_render_stats stats;
    CHECK(kpcn_render_ex(s, &rs, &aov, &stats) == KPCN_OK);
    int finite = 1;
    float vmax = 0.0f;
    size_t plane = kpcn_aov_plane_size(aov);
    for (int b = 0; b < KPCN_BUF_COUNT; b++) {
      for (size_t i = 0; i < plane * (size_t)kpcn_buffer_channels((kpcn_buffer)b); i++)
        finite &= isfinite(aov->buf[b][i]) != 0;
      for (size_t i = 0; i < plane; i++) {
        finite &= isfinite(aov->var[b][i]) != 0;
        if (b == KPCN_BUF_COLOR && aov->var[b][i] > vmax) vmax = aov->var[b][i];
      }
    }
    printf("albedo %s: max colour variance %g, %llu non-finite samples\n", k ? "1e30" : "1e10",
           (double)vmax, (unsigned long long)stats.nonfinite_samples);
    CHECK(finite);
    if (k == 0) CHECK(vmax == FLT_MAX && stats.nonfinite_samples == 0);
    if (k == 1) CHECK(stats.nonfinite_samples > 0);
    kpcn_aov_destroy(aov);
    kpcn_scene_destroy(s);
  }
}

/* A scene file in the root folder: its relative references resolve against "/", not the
 * working directory (the folder of "/scene.json" was taken as ""). Needs a writable "/"
 * (root, as in CI); elsewhere it says it was skipped. */
static void test_scene_at_root(void) {
  char scene[64], mesh[64], text[512];
  snprintf(mesh, sizeof mesh, "/kpcn-test-root-%d.obj", (int)getpid());
  snprintf(scene, sizeof scene, "/kpcn-test-root-%d.json", (int)getpid());
  FILE *f = fopen(mesh, "wb");
  if (!f) {
    printf("scene at the root folder: skipped (cannot write in /)\n");
    return;
  }
  fputs("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", f);
  fclose(f);
  const int n = snprintf(text, sizeof text,
                         "{\"primitives\":[" LIGHT ",{\"type\":\"mesh\",\"file\":\"%s\","
                         "\"bsdf\":{\"type\":\"lambert\"}}]}",
                         mesh + 1);
  write_file(scene, text, (size_t)n);
  kpcn_scene *s = NULL;
  const kpcn_status st = kpcn_scene_load(scene, &s);
  printf("scene at the root folder, mesh '%s' -> status %d%s%s\n", mesh + 1, (int)st,
         st ? ": " : "", st ? kpcn_last_error() : "");
  CHECK(st == KPCN_OK && s != NULL);
  kpcn_scene_destroy(s);
  remove(scene);
  remove(mesh);
}

int main(void) {
  test_scene_at_root();
  kpcn_scene *s = NULL;
  CHECK(kpcn_scene_load("/nonexistent/dir/scene.json", &s) == KPCN_ERR_IO);
  CHECK(strstr(kpcn_last_error(), "/nonexistent/dir/scene.json") != NULL);

  expect_fail("bad JSON", "{\"primitives\": [ {\"type\": \"quad\" ", "invalid JSON", "bad.json");
  expect_fail("unknown primitive",
              "{\"primitives\":[{\"type\":\"teapot\",\"bsdf\":{\"type\":\"lambert\"}}]}",
              "primitives[0].type", "teapot");
  expect_fail("unknown field",
              "{\"primitives\":[" LIGHT
              ",{\"type\":\"quad\",\"bsdf\":{\"type\":\"lambert\"},\"colour\":1}]}",
              "primitives[1].colour", NULL);
  expect_fail("unknown top-level field", "{\"primitives\":[" LIGHT "],\"volumes\":[]}", "volumes",
              NULL);
  expect_fail("unknown bsdf",
              "{\"primitives\":[{\"type\":\"quad\",\"bsdf\":{\"type\":\"velvet\"}}]}",
              "primitives[0].bsdf", "velvet");
  expect_fail("undefined bsdf name", "{\"primitives\":[{\"type\":\"quad\",\"bsdf\":\"nothing\"}]}",
              "primitives[0].bsdf", "nothing");
  expect_fail("unknown camera", "{\"primitives\":[" LIGHT "],\"camera\":{\"type\":\"fisheye\"}}",
              "camera.type", "fisheye");
  expect_fail("unknown filter",
              "{\"primitives\":[" LIGHT
              "],\"camera\":{\"type\":\"pinhole\",\"reconstruction_filter\":\"lanczos\"}}",
              "camera.reconstruction_filter", "lanczos");
  expect_fail("unknown integrator",
              "{\"primitives\":[" LIGHT "],\"integrator\":{\"type\":\"bdpt\"}}", "integrator.type",
              "bdpt");
  expect_fail("participating media",
              "{\"media\":[{\"type\":\"homogeneous\"}],\"primitives\":[" LIGHT "]}", "media", NULL);
  expect_fail("zero-area light",
              "{\"primitives\":[{\"type\":\"quad\",\"bsdf\":{\"type\":\"null\"},\"emission\":5,"
              "\"transform\":{\"scale\":[0,1,1]}}]}",
              "primitives[0]", "zero area");
  expect_fail("NaN in transform",
              "{\"primitives\":[{\"type\":\"quad\",\"bsdf\":{\"type\":\"lambert\"},"
              "\"transform\":{\"position\":[1e999,0,0]}}]}",
              "primitives[0].transform.position", NULL);
  expect_fail("bad rotation arity",
              "{\"primitives\":[{\"type\":\"quad\",\"bsdf\":{\"type\":\"lambert\"},"
              "\"transform\":{\"rotation\":[0,90]}}]}",
              "primitives[0].transform.rotation", NULL);
  expect_fail("negative emission",
              "{\"primitives\":[{\"type\":\"quad\",\"bsdf\":{\"type\":\"null\"},\"emission\":-1}]}",
              "primitives[0].emission", NULL);
  expect_fail("missing mesh",
              "{\"primitives\":[{\"type\":\"mesh\",\"file\":\"nope.wo3\",\"bsdf\":{\"type\":"
              "\"lambert\"}}]}",
              "primitives[0].file", "nope.wo3");
  /* a truncated .wo3 (vertex count larger than the file) */
  unsigned char junk[24] = {200, 0, 0, 0, 0, 0, 0, 0, 1, 2, 3, 4};
  write_file(kt_tmpfile("junk.wo3"), junk, sizeof(junk));
  expect_fail("bad mesh",
              "{\"primitives\":[{\"type\":\"mesh\",\"file\":\"junk.wo3\",\"bsdf\":{\"type\":"
              "\"lambert\"}}]}",
              "primitives[0].file", "junk.wo3");
  write_file(kt_tmpfile("junk.obj"), "v 1 2\nf 1 2 9\n", 14);
  expect_fail("bad obj",
              "{\"primitives\":[{\"type\":\"mesh\",\"file\":\"junk.obj\",\"bsdf\":{\"type\":"
              "\"lambert\"}}]}",
              "primitives[0].file", "junk.obj");
  expect_fail("missing texture",
              "{\"primitives\":[{\"type\":\"quad\",\"bsdf\":{\"type\":\"lambert\",\"albedo\":"
              "\"nope.png\"}}]}",
              "nope.png", NULL);
  { /* an EXR texture with a NaN and one with an Inf texel: named, not rendered as black */
    static const char *const rgb[3] = {"R", "G", "B"};
    kpcn_image *t = NULL;
    CHECK(kpcn_image_create(&t, 4, 3, 3, rgb) == KPCN_OK);
    for (int i = 0; t && i < 36; i++)
      t->data[i] = 0.5f;
    if (t) t->data[12 + 7] = NAN; /* G plane, texel (3, 1) */
    CHECK(t && kpcn_exr_write_image(kt_tmpfile("nan.exr"), t, NULL) == KPCN_OK);
    if (t) t->data[12 + 7] = 0.5f, t->data[2] = INFINITY; /* R plane, texel (2, 0) */
    CHECK(t && kpcn_exr_write_image(kt_tmpfile("inf.exr"), t, NULL) == KPCN_OK);
    kpcn_image_destroy(t);
    expect_fail("NaN texel in an EXR texture",
                "{\"primitives\":[{\"type\":\"quad\",\"bsdf\":{\"type\":\"lambert\",\"albedo\":"
                "\"nan.exr\"}}]}",
                "nan.exr", "non-finite value at texel (3, 1)");
    expect_fail("Inf texel in an EXR texture",
                "{\"primitives\":[{\"type\":\"quad\",\"bsdf\":{\"type\":\"lambert\",\"albedo\":"
                "\"inf.exr\"}}]}",
                "inf.exr", "non-finite value at texel (2, 0)");
  }
  { /* deeper than cJSON's nesting limit: said, not only "invalid JSON" */
    static char deep[2 * 1100 + 256];
    int n = snprintf(deep, sizeof deep, "{\"primitives\":[" LIGHT "],\"x\":");
    for (int i = 0; i < 1100; i++)
      deep[n++] = '[';
    for (int i = 0; i < 1100; i++)
      deep[n++] = ']';
    deep[n++] = '}';
    deep[n] = 0;
    expect_fail("nested 1100 deep", deep, "invalid JSON", "nested deeper than 1000 levels");
  }
  expect_fail("empty scene", "{\"primitives\":[]}", "primitives", NULL);
  expect_fail("bad resolution",
              "{\"primitives\":[" LIGHT "],\"camera\":{\"type\":\"pinhole\",\"resolution\":[0,5]}}",
              "camera.resolution", NULL);
  expect_fail("bad fov",
              "{\"primitives\":[" LIGHT "],\"camera\":{\"type\":\"pinhole\",\"fov\":180}}",
              "camera.fov", NULL);
  /* finite but absurd magnitudes: Embree asserted on the camera rays (found by fuzzing) */
  expect_fail("huge aperture",
              "{\"primitives\":[" LIGHT "],\"camera\":{\"type\":\"thinlens\","
              "\"aperture_size\":9.2e18}}",
              "camera", "aperture_size");
  expect_fail("huge scale",
              "{\"primitives\":[" LIGHT ",{\"type\":\"cube\",\"bsdf\":{\"type\":\"lambert\"},"
              "\"transform\":{\"scale\":1e30}}]}",
              "primitives[1]", "1e+15");
  expect_fail("huge camera position",
              "{\"primitives\":[" LIGHT "],\"camera\":{\"type\":\"pinhole\","
              "\"transform\":{\"position\":[0,0,-1e17],\"look_at\":[0,0,0]}}}",
              "camera", "position");
  expect_fail("ignored field, wrong type",
              "{\"primitives\":[" LIGHT "],\"renderer\":{\"output_file\":0.5}}",
              "renderer.output_file", "file name");
  /* a primitive that fails after its mesh loaded: the mesh is freed (a leak under ASan, found
   * by fuzzing) */
  {
    kpcn_scene *sm = NULL;
    CHECK(kpcn_scene_load_json("{\"primitives\":[" LIGHT ",{\"type\":\"mesh\",\"file\":"
                               "\"Ring.wo3\",\"bsdf\":{\"type\":\"lambert\"},"
                               "\"backface_culling\":true}]}",
                               KPCN_TESTDATA "/scenes/materialtest", "mesh.json", &sm) != KPCN_OK);
    CHECK(sm == NULL && strstr(kpcn_last_error(), "primitives[1].backface_culling") != NULL);
  }
  /* a minimal valid scene loads */
  CHECK(kpcn_scene_load_json("{\"primitives\":[" LIGHT "]}", NULL, NULL, &s) == KPCN_OK);
  kpcn_scene_destroy(s);
  test_scene_values();
  test_render_limits();
  test_tool();
  return kt_summary("render_errors");
}
