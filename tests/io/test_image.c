/* Unit tests of kpcn/image.h: images, buffers, AOV sets, channel-name aliases. */
#include "kpcn/image.h"

#include "core/internal.h"

#include "testutil.h"

#include <math.h>
#include <string.h>

static void test_image_basics(void) {
  const char *names[] = {"R", "G", "B", "extra"};
  kpcn_image *img = NULL;
  CHECK(kpcn_image_create(&img, 7, 5, 4, names) == KPCN_OK);
  CHECK(img && img->width == 7 && img->height == 5 && img->nchannels == 4);
  if (!img) return;
  CHECK(strcmp(img->names[3], "extra") == 0);
  float sum = 0;
  for (size_t i = 0; i < 7 * 5 * 4; i++)
    sum += fabsf(img->data[i]);
  CHECK(sum == 0.0f); /* zero-filled */
  CHECK(kpcn_image_find_channel(img, "G") == 1);
  CHECK(kpcn_image_find_channel(img, "extra") == 3);
  CHECK(kpcn_image_find_channel(img, "A") == -1);
  CHECK(kpcn_image_find_channel(img, "r") == -1); /* exact names, case-sensitive */
  /* plane layout: data[c*w*h + y*w + x] */
  kpcn_image_plane(img, 2)[3 * 7 + 4] = 42.0f;
  CHECK(img->data[2 * 35 + 3 * 7 + 4] == 42.0f);

  kpcn_image *cl = NULL;
  CHECK(kpcn_image_clone(&cl, img) == KPCN_OK);
  CHECK(cl && cl->data != img->data && cl->names[0] != img->names[0]);
  if (cl) {
    CHECK(memcmp(cl->data, img->data, 7 * 5 * 4 * sizeof(float)) == 0);
    CHECK(strcmp(cl->names[2], "B") == 0);
    cl->data[0] = 1.0f; /* deep copy: the source is unchanged */
    CHECK(img->data[0] == 0.0f);
  }
  kpcn_image_destroy(cl);
  kpcn_image_destroy(img);

  CHECK(kpcn_image_create(&img, 3, 2, 2, NULL) == KPCN_OK);
  if (img) CHECK(strcmp(img->names[0], "0") == 0 && strcmp(img->names[1], "1") == 0);
  kpcn_image_destroy(img);
  kpcn_image_destroy(NULL); /* no-op */
}

static void test_image_bad_sizes(void) {
  kpcn_image *img = (kpcn_image *)1;
  CHECK(kpcn_image_create(&img, 0, 5, 1, NULL) == KPCN_ERR_INVALID_ARGUMENT);
  CHECK(img == NULL);
  CHECK(kpcn_image_create(&img, 5, -1, 1, NULL) == KPCN_ERR_INVALID_ARGUMENT);
  CHECK(kpcn_image_create(&img, 5, 5, 0, NULL) == KPCN_ERR_INVALID_ARGUMENT);
  CHECK(kpcn_image_create(&img, KPCN_MAX_DIM + 1, 1, 1, NULL) == KPCN_ERR_OUT_OF_MEMORY);
  CHECK(strstr(kpcn_last_error(), "absurd") != NULL);
  CHECK(kpcn_image_create(&img, 60000, 60000, 3, NULL) == KPCN_ERR_OUT_OF_MEMORY);
  /* a block larger than any machine's memory is refused by name, not overcommitted (every
   * large buffer, an image's planes included, comes from kpcn_aligned_alloc) */
  CHECK(kpcn_aligned_alloc((size_t)1 << 62, "a test block") == NULL);
  CHECK(strstr(kpcn_last_error(), "more than this machine's") &&
        strstr(kpcn_last_error(), "a test block"));
  kpcn_aov_set *s = NULL;
  CHECK(kpcn_aov_create(&s, 0, 0) == KPCN_ERR_INVALID_ARGUMENT);
  CHECK(kpcn_aov_create(&s, 100000, 2) == KPCN_ERR_OUT_OF_MEMORY);
}

static void test_buffers(void) {
  CHECK(kpcn_buffer_channels(KPCN_BUF_COLOR) == 3);
  CHECK(kpcn_buffer_channels(KPCN_BUF_NORMAL) == 3);
  CHECK(kpcn_buffer_channels(KPCN_BUF_DEPTH) == 1);
  CHECK(kpcn_buffer_channels(KPCN_BUF_VISIBILITY) == 1);
  CHECK(strcmp(kpcn_buffer_channel_name(KPCN_BUF_COLOR, 0), "R") == 0);
  CHECK(strcmp(kpcn_buffer_channel_name(KPCN_BUF_DIFFUSE, 1), "diffuse.G") == 0);
  CHECK(strcmp(kpcn_buffer_channel_name(KPCN_BUF_NORMAL, 2), "N.Z") == 0);
  CHECK(strcmp(kpcn_buffer_channel_name(KPCN_BUF_DEPTH, 0), "Z") == 0);
  CHECK(kpcn_buffer_channel_name(KPCN_BUF_DEPTH, 1) == NULL);
  CHECK(strcmp(kpcn_buffer_variance_name(KPCN_BUF_NORMAL), "N.var") == 0);
  CHECK(strcmp(kpcn_buffer_variance_name(KPCN_BUF_VISIBILITY), "visibility.var") == 0);
  for (int b = 0; b < KPCN_BUF_COUNT; b++)
    CHECK(kpcn_buffer_from_name(kpcn_buffer_name((kpcn_buffer)b)) == b);
  CHECK(kpcn_buffer_from_name("nope") == -1);
  CHECK(kpcn_buffer_is_color(KPCN_BUF_ALBEDO) && !kpcn_buffer_is_color(KPCN_BUF_NORMAL));
}

/* Expected mapping of one name; b = -1 means "not recognised". */
static void expect(const char *name, int b, int c) {
  kpcn_buffer bb = KPCN_BUF_COUNT;
  int cc = -9;
  int ok = kpcn_aov_channel_lookup(name, &bb, &cc, NULL);
  if (b < 0) {
    CHECK(!ok);
    if (ok) fprintf(stderr, "  '%s' unexpectedly recognised\n", name);
    return;
  }
  CHECK(ok && (int)bb == b && cc == c);
  if (!(ok && (int)bb == b && cc == c))
    fprintf(stderr, "  '%s' -> ok=%d b=%d c=%d, want b=%d c=%d\n", name, ok, (int)bb, cc, b, c);
}

static void test_aliases(void) {
  /* canonical */
  for (int b = 0; b < KPCN_BUF_COUNT; b++) {
    for (int c = 0; c < kpcn_buffer_channels((kpcn_buffer)b); c++)
      expect(kpcn_buffer_channel_name((kpcn_buffer)b, c), b, c);
    expect(kpcn_buffer_variance_name((kpcn_buffer)b), b, -1);
  }
  /* Blender / Cycles */
  expect("ViewLayer.Combined.R", KPCN_BUF_COLOR, 0);
  expect("ViewLayer.Combined.B", KPCN_BUF_COLOR, 2);
  expect("RenderLayer.Noisy Image.G", KPCN_BUF_COLOR, 1);
  expect("ViewLayer.Denoising Albedo.R", KPCN_BUF_ALBEDO, 0);
  expect("Denoising Albedo.B", KPCN_BUF_ALBEDO, 2);
  expect("ViewLayer.Denoising Normal.X", KPCN_BUF_NORMAL, 0);
  expect("Denoising Normal.Z", KPCN_BUF_NORMAL, 2);
  expect("ViewLayer.Denoising Depth.Z", KPCN_BUF_DEPTH, 0);
  expect("ViewLayer.Depth.Z", KPCN_BUF_DEPTH, 0);
  /* generic */
  expect("normal.X", KPCN_BUF_NORMAL, 0);
  expect("normal.Y", KPCN_BUF_NORMAL, 1);
  expect("Normal.z", KPCN_BUF_NORMAL, 2);
  expect("normal.R", KPCN_BUF_NORMAL, 0);
  expect("depth.Z", KPCN_BUF_DEPTH, 0);
  expect("depth.V", KPCN_BUF_DEPTH, 0);
  expect("diffuse.r", KPCN_BUF_DIFFUSE, 0);
  expect("Specular.B", KPCN_BUF_SPECULAR, 2);
  expect("ALBEDO.g", KPCN_BUF_ALBEDO, 1);
  expect("normal.var", KPCN_BUF_NORMAL, -1);
  expect("depth.var", KPCN_BUF_DEPTH, -1);
  /* not AOV channels */
  expect("A", -1, 0);
  expect("Y", -1, 0);
  expect("var", -1, 0);
  expect("emission.R", -1, 0);
  expect("diffuse.A", -1, 0);
  expect("N.W", -1, 0);
  expect("", -1, 0);
  expect("Z.X", -1, 0);
  /* canonical ranks 0, aliases more */
  int r0 = -1, r1 = -1, r2 = -1;
  kpcn_aov_channel_lookup("N.X", NULL, NULL, &r0);
  kpcn_aov_channel_lookup("normal.X", NULL, NULL, &r1);
  kpcn_aov_channel_lookup("ViewLayer.Denoising Normal.X", NULL, NULL, &r2);
  CHECK(r0 == 0 && r1 > r0 && r2 > r1);
  kpcn_aov_channel_lookup("color.var", NULL, NULL, &r0);
  CHECK(r0 == 0);
}

static void test_map_channels(void) {
  int chan[KPCN_BUF_COUNT][3], var[KPCN_BUF_COUNT];
  /* canonical and aliases together: canonical wins even when listed later */
  const char *n1[] = {"ViewLayer.Combined.B",
                      "ViewLayer.Combined.G",
                      "ViewLayer.Combined.R",
                      "B",
                      "G",
                      "R",
                      "normal.X",
                      "normal.Y",
                      "normal.Z",
                      "color.var",
                      "A"};
  CHECK(kpcn_aov_map_channels(n1, 11, chan, var, "t1") == KPCN_OK);
  CHECK(chan[KPCN_BUF_COLOR][0] == 5 && chan[KPCN_BUF_COLOR][1] == 4 &&
        chan[KPCN_BUF_COLOR][2] == 3);
  CHECK(chan[KPCN_BUF_NORMAL][0] == 6 && chan[KPCN_BUF_NORMAL][2] == 8);
  CHECK(var[KPCN_BUF_COLOR] == 9 && var[KPCN_BUF_NORMAL] == -1);
  CHECK(chan[KPCN_BUF_DEPTH][0] == -1 && chan[KPCN_BUF_ALBEDO][0] == -1);

  /* a partial buffer is an error naming the buffer and the file */
  const char *n2[] = {"R", "G", "B", "N.X", "N.Y"};
  CHECK(kpcn_aov_map_channels(n2, 5, chan, var, "file.exr") == KPCN_ERR_MISSING_CHANNEL);
  CHECK(strstr(kpcn_last_error(), "normal") && strstr(kpcn_last_error(), "N.Z") &&
        strstr(kpcn_last_error(), "file.exr"));
  /* ... unless another complete group provides it */
  const char *n3[] = {"N.X", "N.Y", "Denoising Normal.X", "Denoising Normal.Y",
                      "Denoising Normal.Z"};
  CHECK(kpcn_aov_map_channels(n3, 5, chan, var, "t3") == KPCN_OK);
  CHECK(chan[KPCN_BUF_NORMAL][0] == 2 && chan[KPCN_BUF_NORMAL][2] == 4);
  /* Cycles: the un-denoised "Noisy Image" is preferred over "Combined" */
  const char *n5[] = {"ViewLayer.Combined.B",    "ViewLayer.Combined.G",
                      "ViewLayer.Combined.R",    "ViewLayer.Noisy Image.B",
                      "ViewLayer.Noisy Image.G", "ViewLayer.Noisy Image.R"};
  CHECK(kpcn_aov_map_channels(n5, 6, chan, var, "t5") == KPCN_OK);
  CHECK(chan[KPCN_BUF_COLOR][0] == 5 && chan[KPCN_BUF_COLOR][2] == 3);
  /* channels from two different layers never mix */
  const char *n4[] = {"L1.Combined.R", "L1.Combined.G", "L2.Combined.B"};
  CHECK(kpcn_aov_map_channels(n4, 3, chan, var, "t4") == KPCN_ERR_MISSING_CHANNEL);
}

static void fill(float *p, size_t n, float base) {
  for (size_t i = 0; i < n; i++)
    p[i] = base + (float)i * 0.25f;
}

static void test_aov_sets(void) {
  kpcn_aov_set *s = NULL;
  CHECK(kpcn_aov_create(&s, 4, 3) == KPCN_OK);
  if (!s) return;
  CHECK(s->spp == -1 && s->seed == -1 && s->scene[0] == 0);
  CHECK(kpcn_aov_require(s, KPCN_BUF_ALBEDO, 0, "x.exr") == KPCN_ERR_MISSING_CHANNEL);
  CHECK(strstr(kpcn_last_error(), "albedo") && strstr(kpcn_last_error(), "x.exr"));
  CHECK(kpcn_aov_add(s, KPCN_BUF_ALBEDO, 0) == KPCN_OK);
  CHECK(kpcn_aov_require(s, KPCN_BUF_ALBEDO, 0, "x.exr") == KPCN_OK);
  CHECK(kpcn_aov_require(s, KPCN_BUF_ALBEDO, 1, "x.exr") == KPCN_ERR_MISSING_CHANNEL);
  CHECK(strstr(kpcn_last_error(), "albedo.var") != NULL);
  CHECK(kpcn_aov_add(s, KPCN_BUF_DEPTH, 1) == KPCN_OK);
  CHECK(kpcn_aov_add(s, KPCN_BUF_COLOR, 1) == KPCN_OK);
  /* the list form names every absent buffer and variance in one message, in the list's
   * order, and nothing present (albedo's variance, normal and visibility here) */
  {
    const kpcn_buffer need[] = {KPCN_BUF_ALBEDO, KPCN_BUF_DEPTH, KPCN_BUF_NORMAL,
                                KPCN_BUF_VISIBILITY, KPCN_BUF_COLOR};
    CHECK(kpcn_aov_require_list(s, need, 5, 1, "in.exr") == KPCN_ERR_MISSING_CHANNEL);
    const char *e = kpcn_last_error();
    CHECK(strcmp(e, "in.exr: missing variance of 'albedo' (channel albedo.var), buffer 'normal' "
                    "(channels N.X N.Y N.Z, and its variance N.var), buffer 'visibility' "
                    "(channel visibility.V, and its variance visibility.var)") == 0);
    if (strcmp(e, "in.exr: missing variance of 'albedo' (channel albedo.var), buffer 'normal' "
                  "(channels N.X N.Y N.Z, and its variance N.var), buffer 'visibility' "
                  "(channel visibility.V, and its variance visibility.var)") != 0)
      fprintf(stderr, "  got: %s\n", e);
    CHECK(kpcn_aov_require_list(s, need, 5, 0, "in.exr") == KPCN_ERR_MISSING_CHANNEL);
    CHECK(strcmp(kpcn_last_error(), "in.exr: missing buffer 'normal' (channels N.X N.Y N.Z), "
                                    "buffer 'visibility' (channel visibility.V)") == 0);
    CHECK(kpcn_aov_require_list(s, need + 1, 1, 1, "in.exr") == KPCN_OK);
    CHECK(kpcn_aov_require_list(s, need, 0, 1, "in.exr") == KPCN_OK);
    CHECK(kpcn_aov_require_list(s, NULL, 1, 1, "in.exr") == KPCN_ERR_INVALID_ARGUMENT);
    const kpcn_buffer bad = (kpcn_buffer)99;
    CHECK(kpcn_aov_require_list(s, &bad, 1, 1, "in.exr") == KPCN_ERR_INVALID_ARGUMENT);
  }
  size_t n = kpcn_aov_plane_size(s);
  fill(s->buf[KPCN_BUF_ALBEDO], 3 * n, 1);
  fill(s->buf[KPCN_BUF_DEPTH], n, 100);
  fill(s->var[KPCN_BUF_DEPTH], n, 200);
  fill(s->buf[KPCN_BUF_COLOR], 3 * n, 300);
  fill(s->var[KPCN_BUF_COLOR], n, 400);
  s->spp = 8;
  s->seed = 5;
  strcpy(s->scene, "sc");
  float *keep = s->buf[KPCN_BUF_ALBEDO];
  CHECK(kpcn_aov_add(s, KPCN_BUF_ALBEDO, 1) == KPCN_OK); /* keeps the existing plane */
  CHECK(s->buf[KPCN_BUF_ALBEDO] == keep && s->buf[KPCN_BUF_ALBEDO][5] == 1 + 5 * 0.25f);
  fill(s->var[KPCN_BUF_ALBEDO], n, 500);

  kpcn_aov_set *c = NULL;
  CHECK(kpcn_aov_clone(&c, s) == KPCN_OK);
  if (c) {
    CHECK(c->spp == 8 && c->seed == 5 && strcmp(c->scene, "sc") == 0);
    CHECK(c->buf[KPCN_BUF_NORMAL] == NULL && c->var[KPCN_BUF_NORMAL] == NULL);
    CHECK(memcmp(c->buf[KPCN_BUF_COLOR], s->buf[KPCN_BUF_COLOR], 3 * n * 4) == 0);
    CHECK(memcmp(c->var[KPCN_BUF_ALBEDO], s->var[KPCN_BUF_ALBEDO], n * 4) == 0);
    CHECK(c->buf[KPCN_BUF_COLOR] != s->buf[KPCN_BUF_COLOR]);
  }

  kpcn_image *img = NULL;
  CHECK(kpcn_aov_to_image(&img, s) == KPCN_OK);
  if (img) {
    CHECK(img->nchannels == 3 + 1 + 3 + 1 + 1 + 1); /* color+var, albedo+var, Z+var */
    int ig = kpcn_image_find_channel(img, "G"), iz = kpcn_image_find_channel(img, "Z.var");
    int ia = kpcn_image_find_channel(img, "albedo.B");
    CHECK(ig >= 0 && iz >= 0 && ia >= 0);
    if (ig >= 0) CHECK(kpcn_image_plane(img, ig)[2] == s->buf[KPCN_BUF_COLOR][n + 2]);
    if (iz >= 0) CHECK(kpcn_image_plane(img, iz)[7] == s->var[KPCN_BUF_DEPTH][7]);
    if (ia >= 0) CHECK(kpcn_image_plane(img, ia)[11] == s->buf[KPCN_BUF_ALBEDO][2 * n + 11]);
    kpcn_aov_set *back = NULL;
    CHECK(kpcn_aov_from_image(&back, img) == KPCN_OK);
    if (back) {
      for (int b = 0; b < KPCN_BUF_COUNT; b++) {
        CHECK((back->buf[b] == NULL) == (s->buf[b] == NULL));
        CHECK((back->var[b] == NULL) == (s->var[b] == NULL));
        if (s->buf[b] && back->buf[b])
          CHECK(memcmp(back->buf[b], s->buf[b], n * kpcn_buffer_channels(b) * 4) == 0);
        if (s->var[b] && back->var[b]) CHECK(memcmp(back->var[b], s->var[b], n * 4) == 0);
      }
    }
    kpcn_aov_destroy(back);
  }
  kpcn_image_destroy(img);

  /* kpcn_aov_create_for_channels: which plane each source channel belongs in (NULL for a
   * channel the set does not use), a variance without its buffer kept, a partly present
   * buffer refused naming the source */
  {
    const char *names[6] = {"N.X", "Z.var", "junk", "N.Z", "N.Y", "diffuse.var"};
    float *dst[6];
    kpcn_aov_set *fc = NULL;
    CHECK(kpcn_aov_create_for_channels(&fc, 4, 3, 6, names, dst, "chan-test") == KPCN_OK);
    if (fc) {
      CHECK(dst[0] == fc->buf[KPCN_BUF_NORMAL] && dst[4] == fc->buf[KPCN_BUF_NORMAL] + 12 &&
            dst[3] == fc->buf[KPCN_BUF_NORMAL] + 24);
      CHECK(dst[2] == NULL && fc->var[KPCN_BUF_NORMAL] == NULL);
      CHECK(dst[1] == fc->var[KPCN_BUF_DEPTH] && fc->buf[KPCN_BUF_DEPTH] == NULL);
      CHECK(dst[5] == fc->var[KPCN_BUF_DIFFUSE] && fc->buf[KPCN_BUF_DIFFUSE] == NULL);
      CHECK(fc->width == 4 && fc->height == 3);
    }
    kpcn_aov_destroy(fc);
    const char *partial[2] = {"N.X", "N.Y"};
    CHECK(kpcn_aov_create_for_channels(&fc, 4, 3, 2, partial, dst, "chan-test") ==
          KPCN_ERR_MISSING_CHANNEL);
    CHECK(fc == NULL && strstr(kpcn_last_error(), "chan-test") != NULL);
  }

  /* non-finite counting */
  const char *first = NULL;
  CHECK(kpcn_aov_count_nonfinite(s, &first) == 0 && first == NULL);
  s->var[KPCN_BUF_DEPTH][3] = NAN;
  s->buf[KPCN_BUF_ALBEDO][n + 1] = INFINITY;
  s->buf[KPCN_BUF_ALBEDO][2 * n + 1] = -INFINITY;
  CHECK(kpcn_aov_count_nonfinite(s, &first) == 3);
  CHECK(first && strcmp(first, "albedo.G") == 0);

  kpcn_aov_set *empty = NULL;
  kpcn_aov_create(&empty, 2, 2);
  CHECK(kpcn_aov_to_image(&img, empty) == KPCN_ERR_MISSING_CHANNEL);
  kpcn_aov_destroy(empty);
  kpcn_aov_destroy(c);
  kpcn_aov_destroy(s);
}

int main(void) {
  test_image_basics();
  test_image_bad_sizes();
  test_buffers();
  test_aliases();
  test_map_channels();
  test_aov_sets();
  return kt_summary("test_image");
}
