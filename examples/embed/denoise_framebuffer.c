/* Embedding kpcn in a renderer: the renderer keeps its auxiliary buffers interleaved in one
 * array of per-pixel records (as many renderers' framebuffers do); kpcn reads them in place
 * through pixel and row strides (kpcn/denoise.h) and writes the result into the renderer's
 * RGBA display buffer. Here the "renderer" fills its framebuffer from an AOV EXR written by
 * kpcn-render, so the example can also check itself: the strided path must give the same
 * pixels as kpcn's own planar path (kpcn_denoise_aov) on the same input.
 *
 *   denoise_framebuffer noisy.exr model.safetensors out.exr
 *
 * Build against an installed kpcn: CMake (find_package(kpcn), this folder's CMakeLists.txt)
 * or pkg-config (cc denoise_framebuffer.c $(pkg-config --cflags --libs kpcn) -lm). */
#include <kpcn/denoise.h>
#include <kpcn/exr.h>

#include <math.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>

/* One pixel of the renderer's framebuffer. Padding and field order are the renderer's own
 * business: kpcn only needs each buffer's address and the record size. */
typedef struct fb_pixel {
  float color[4], diffuse[4], specular[4], albedo[4], normal[4]; /* RGB(A) / XYZ(pad) */
  float depth, visibility;
  float variance[KPCN_BUF_COUNT]; /* variance of the mean of each buffer above */
} fb_pixel;

static float *fb_buffer(fb_pixel *p, kpcn_buffer b) {
  switch (b) {
  case KPCN_BUF_COLOR: return p->color;
  case KPCN_BUF_DIFFUSE: return p->diffuse;
  case KPCN_BUF_SPECULAR: return p->specular;
  case KPCN_BUF_ALBEDO: return p->albedo;
  case KPCN_BUF_NORMAL: return p->normal;
  case KPCN_BUF_DEPTH: return &p->depth;
  case KPCN_BUF_VISIBILITY: return &p->visibility;
  default: return NULL;
  }
}

static int fail(const char *what, kpcn_status s) {
  fprintf(stderr, "denoise_framebuffer: %s: %s (%s)\n", what, kpcn_last_error(),
          kpcn_status_string(s));
  return 1;
}

int main(int argc, char **argv) {
  if (argc != 4) {
    fprintf(stderr, "usage: denoise_framebuffer noisy.exr model.safetensors out.exr\n");
    return 2;
  }
  kpcn_aov_set *aov = NULL;
  kpcn_status s = kpcn_exr_read_aov(argv[1], &aov);
  if (s != KPCN_OK) return fail(argv[1], s);
  const int w = aov->width, h = aov->height;
  const size_t npx = (size_t)w * h;

  /* The renderer's side: its framebuffer, filled from the planar AOVs. */
  fb_pixel *fb = calloc(npx, sizeof *fb);
  float *display = calloc(npx * 4, sizeof *display); /* RGBA, alpha left alone */
  if (!fb || !display) return fail("allocation", KPCN_ERR_OUT_OF_MEMORY);
  for (int b = 0; b < KPCN_BUF_COUNT; b++)
    for (size_t i = 0; i < npx; i++) {
      for (int c = 0; aov->buf[b] && c < kpcn_buffer_channels((kpcn_buffer)b); c++)
        fb_buffer(&fb[i], (kpcn_buffer)b)[c] = aov->buf[b][c * npx + i];
      if (aov->var[b]) fb[i].variance[b] = aov->var[b][i];
    }
  for (size_t i = 0; i < npx; i++)
    display[4 * i + 3] = 1.0f;

  /* kpcn's side: one denoiser, buffers set by name with the record as pixel stride. */
  kpcn_denoiser_options opt;
  kpcn_denoiser_options_defaults(&opt);
  opt.model_path = argv[2];
  kpcn_denoiser *d = NULL;
  if ((s = kpcn_denoiser_create(&d, &opt)) != KPCN_OK) return fail(argv[2], s);
  const size_t px = sizeof(fb_pixel), row = px * (size_t)w;
  for (int b = 0; b < KPCN_BUF_COUNT; b++) {
    char var_name[64];
    snprintf(var_name, sizeof var_name, "%s.var", kpcn_buffer_name((kpcn_buffer)b));
    if (aov->buf[b] &&
        (s = kpcn_denoiser_set_buffer(d, kpcn_buffer_name((kpcn_buffer)b),
                                      fb_buffer(&fb[0], (kpcn_buffer)b), w, h, px, row)) != KPCN_OK)
      return fail("set_buffer", s);
    if (aov->var[b] &&
        (s = kpcn_denoiser_set_buffer(d, var_name, &fb[0].variance[b], w, h, px, row)) != KPCN_OK)
      return fail("set_buffer", s);
  }
  if ((s = kpcn_denoiser_execute(d, display, w, h, 4 * sizeof(float), 0)) != KPCN_OK)
    return fail("execute", s);

  /* Self-check against the planar path, then write the result for the caller. */
  kpcn_image *ref = NULL;
  if ((s = kpcn_denoise_aov(aov, &opt, &ref)) != KPCN_OK) return fail("kpcn_denoise_aov", s);
  double max_diff = 0;
  for (size_t i = 0; i < npx; i++)
    for (int c = 0; c < 3; c++)
      max_diff = fmax(max_diff, fabs((double)display[4 * i + c] - ref->data[c * npx + i]));
  for (size_t i = 0; i < npx; i++) /* ref is named R, G, B: reuse it for the output */
    for (int c = 0; c < 3; c++)
      ref->data[c * npx + i] = display[4 * i + c];
  if ((s = kpcn_exr_write_image(argv[3], ref, NULL)) != KPCN_OK) return fail(argv[3], s);
  printf("denoised %dx%d through strided buffers (%zu-byte records); max |strided - planar| = %g\n",
         w, h, px, max_diff);
  kpcn_image_destroy(ref);
  kpcn_denoiser_destroy(d);
  kpcn_aov_destroy(aov);
  free(fb);
  free(display);
  return max_diff == 0 ? 0 : 1;
}
