/* Cross-check of the EXR reader against OpenImageIO (an independent EXR reader): values
 * recorded in testdata/io/cornell_noisy_oiio.txt by tests/io/gen_oiio_reference.sh from the
 * Tungsten render, plus OIIO-written tiled, offset-data-window (PIZ) and half files. */
#include "kpcn/exr.h"
#include "kpcn/dataset.h"

#include "testutil.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#define MAXC 32

static const char *find_render(void) {
  static const char *path = KPCN_TESTDATA "/tungsten-cornell/noisy_16spp.exr";
  return access(path, R_OK) == 0 ? path : NULL;
}

typedef struct {
  int nch;
  char names[MAXC][32]; /* OIIO's channel order */
  double avg[MAXC], mn[MAXC], mx[MAXC];
} recorded;

static int parse_list(const char *s, double *v, int max) {
  int n = 0;
  char *end;
  while (n < max) {
    double x = strtod(s, &end);
    if (end == s) break;
    v[n++] = x;
    s = end;
  }
  return n;
}

/* Checks every "Pixel (x, y):" line of the recording against img; returns pixels checked. */
static int check_recording(const kpcn_image *img, recorded *rec, const char *recpath) {
  FILE *f = fopen(recpath, "r");
  CHECK(f != NULL);
  if (!f) return 0;
  char line[4096];
  int ox = 0, oy = 0, pixels = 0;
  rec->nch = 0;
  while (fgets(line, sizeof line, f)) {
    char *p;
    if ((p = strstr(line, "channel list: "))) {
      p += 14;
      for (char *tok = strtok(p, ", \n"); tok && rec->nch < MAXC; tok = strtok(NULL, ", \n"))
        snprintf(rec->names[rec->nch++], 32, "%s", tok);
    } else if (strncmp(line, "crop ", 5) == 0) {
      int w, h;
      CHECK(sscanf(line + 5, "%dx%d+%d+%d", &w, &h, &ox, &oy) == 4);
    } else if ((p = strstr(line, "Pixel ("))) {
      int x, y;
      CHECK(sscanf(p, "Pixel (%d, %d):", &x, &y) == 2);
      double v[MAXC];
      int n = parse_list(strchr(p, ':') + 1, v, MAXC);
      CHECK(n == rec->nch);
      for (int c = 0; c < n && c < rec->nch; c++) {
        int k = kpcn_image_find_channel(img, rec->names[c]);
        CHECK(k >= 0);
        if (k < 0) continue;
        float got = kpcn_image_plane(img, k)[(size_t)(oy + y) * img->width + (ox + x)];
        /* OIIO prints 9 decimals */
        CHECK_NEAR(got, v[c], 6e-10 + 1e-7 * fabs(v[c]));
      }
      pixels++;
    } else if ((p = strstr(line, "Stats Avg:"))) {
      CHECK(parse_list(p + 10, rec->avg, MAXC) == rec->nch);
    } else if ((p = strstr(line, "Stats Min:"))) {
      CHECK(parse_list(p + 10, rec->mn, MAXC) == rec->nch);
    } else if ((p = strstr(line, "Stats Max:"))) {
      CHECK(parse_list(p + 10, rec->mx, MAXC) == rec->nch);
    }
  }
  fclose(f);
  return pixels;
}

static void test_recorded(const kpcn_image *img) {
  recorded rec;
  int pixels = check_recording(img, &rec, KPCN_TESTDATA "/io/cornell_noisy_oiio.txt");
  CHECK(pixels == 6 + 4 + 4);
  CHECK(rec.nch == 16 && img->nchannels == 16);
  /* whole-image statistics (OIIO prints 6 decimals): every pixel took part */
  size_t n = (size_t)img->width * img->height;
  for (int c = 0; c < rec.nch; c++) {
    int k = kpcn_image_find_channel(img, rec.names[c]);
    if (k < 0) continue;
    const float *p = kpcn_image_plane(img, k);
    double sum = 0, mn = INFINITY, mx = -INFINITY;
    for (size_t i = 0; i < n; i++) {
      sum += p[i];
      mn = p[i] < mn ? p[i] : mn;
      mx = p[i] > mx ? p[i] : mx;
    }
    CHECK_NEAR(sum / n, rec.avg[c], 1e-6);
    CHECK_NEAR(mn, rec.mn[c], 1e-6);
    CHECK_NEAR(mx, rec.mx[c], 1e-6);
  }
}

/* A 37x23 crop at (100,120) of the render, written by OIIO in another layout. */
static void check_crop(const kpcn_image *full, const char *file, int half) {
  char path[512];
  snprintf(path, sizeof path, "%s/io/%s", KPCN_TESTDATA, file);
  kpcn_image *img = NULL;
  kpcn_status s = kpcn_exr_read_image(path, &img);
  CHECK(s == KPCN_OK);
  if (s != KPCN_OK) {
    fprintf(stderr, "  %s: %s\n", file, kpcn_last_error());
    return;
  }
  CHECK(img->width == 37 && img->height == 23 && img->nchannels == full->nchannels);
  double maxerr = 0;
  int bad = 0;
  for (int c = 0; c < img->nchannels; c++) {
    int k = kpcn_image_find_channel(full, img->names[c]);
    CHECK(k >= 0);
    if (k < 0) continue;
    for (int y = 0; y < 23; y++)
      for (int x = 0; x < 37; x++) {
        float a = kpcn_image_plane(full, k)[(size_t)(120 + y) * full->width + 100 + x];
        float b = kpcn_image_plane(img, c)[(size_t)y * 37 + x];
        double tol = half ? 4.9e-4 * fabs(a) + 6e-8 : 0; /* half: 11-bit mantissa */
        double e = fabs((double)a - b);
        if (e > tol) bad++;
        maxerr = kt_worst(maxerr, e);
      }
  }
  CHECK(bad == 0);
  if (bad) fprintf(stderr, "  %s: %d values differ (max err %g)\n", file, bad, maxerr);
  kpcn_image_destroy(img);
}

int main(void) {
  const char *render = find_render();
  CHECK(render != NULL);
  if (!render) {
    fprintf(stderr, "Tungsten render not found in testdata/tungsten-cornell/\n");
    return kt_summary("test_exr_oiio");
  }
  kpcn_image *img = NULL;
  kpcn_status s = kpcn_exr_read_image(render, &img);
  CHECK(s == KPCN_OK);
  if (s != KPCN_OK) {
    fprintf(stderr, "  %s\n", kpcn_last_error());
    return kt_summary("test_exr_oiio");
  }
  CHECK(img->width == 256 && img->height == 256);
  test_recorded(img);

  check_crop(img, "crop_tiled.exr", 0);
  check_crop(img, "crop_offset.exr", 0);
  check_crop(img, "crop_half.exr", 1);
  kpcn_exr_info_t info;
  CHECK(kpcn_exr_info(KPCN_TESTDATA "/io/crop_tiled.exr", &info) == KPCN_OK && info.tiled);
  CHECK(kpcn_exr_info(KPCN_TESTDATA "/io/crop_offset.exr", &info) == KPCN_OK && info.data_x == 3 &&
        info.data_y == 7 && strcmp(info.compression, "piz") == 0);
  CHECK(kpcn_exr_info(KPCN_TESTDATA "/io/crop_half.exr", &info) == KPCN_OK &&
        info.channel_is_half[0] == 1);
  /* B44 chunks stored raw (a writer does so when B44 would not make them smaller), which
   * OpenEXR Core 3.1 ran through its B44 decoder: two float channels (every chunk raw, B44
   * leaves floats as they are) came back with their rows mixed up and were refused until
   * session 61; the last, one-row chunk of a half file (8 pixels: larger compressed) came back
   * as garbage. Both are the source's values: the floats exactly, the raw half row as half. */
  kpcn_image *cod = NULL;
  CHECK(kpcn_exr_read_image(KPCN_TESTDATA "/io/b44_float2.exr", &cod) == KPCN_OK);
  if (cod) {
    int same = cod->width == 8 && cod->height == 8;
    for (int c = 0; same && c < 2; c++) {
      const char *nm = c ? "G" : "R";
      const int a = kpcn_image_find_channel(cod, nm), b = kpcn_image_find_channel(img, nm);
      same &= a >= 0 && b >= 0;
      for (int y = 0; same && y < 8; y++)
        for (int x = 0; x < 8; x++)
          same &= kpcn_image_plane(cod, a)[y * 8 + x] ==
                  kpcn_image_plane(img, b)[(120 + y) * 256 + 100 + x];
    }
    CHECK(same);
    kpcn_image_destroy(cod);
    cod = NULL;
  }
  CHECK(kpcn_exr_read_image(KPCN_TESTDATA "/io/b44_lastrow.exr", &cod) == KPCN_OK);
  if (cod) {
    int same = cod->width == 8 && cod->height == 33;
    double worst = 0; /* the B44-coded rows: lossy, but near */
    for (int c = 0; same && c < 3; c++) {
      const char *nm = c == 0 ? "R" : c == 1 ? "G" : "B";
      const int a = kpcn_image_find_channel(cod, nm), b = kpcn_image_find_channel(img, nm);
      same &= a >= 0 && b >= 0;
      for (int y = 0; same && y < 33; y++)
        for (int x = 0; x < 8; x++) {
          const float got = kpcn_image_plane(cod, a)[y * 8 + x],
                      src = kpcn_image_plane(img, b)[(120 + y) * 256 + 100 + x];
          if (y == 32)
            same &= got == kpcn_half_to_float(kpcn_float_to_half(src));
          else
            worst = kt_worst(worst, fabs(got - src) / (fabs(src) + 0.05));
        }
    }
    CHECK(same);
    CHECK(worst < 0.1);
    kpcn_image_destroy(cod);
    cod = NULL;
  }
  int maj = 0, min = 0; /* the OpenEXR library as loaded, from the build line */
  const char *ev = strstr(kpcn_build_info(), "OpenEXR ");
  CHECK(ev && sscanf(ev, "OpenEXR %d.%d", &maj, &min) == 2);
  if (maj * 100 + min < 302) {
    CHECK(kpcn_exr_read_image(KPCN_TESTDATA "/io/dwaa.exr", &cod) == KPCN_ERR_UNSUPPORTED);
    CHECK(strstr(kpcn_last_error(), "DWAA compression cannot be decoded") != NULL);
  }
  /* a uint channel keeps its integer value (aov-exr.md; OIIO normalises by 2^32 - 1): the
   * file holds 0.5, 0.25 and 1 of 2^32 - 1, rounded to integers by oiiotool */
  CHECK(kpcn_exr_read_image(KPCN_TESTDATA "/io/uint32.exr", &cod) == KPCN_OK);
  if (cod) {
    const int r = kpcn_image_find_channel(cod, "R"), g = kpcn_image_find_channel(cod, "G"),
              bl = kpcn_image_find_channel(cod, "B");
    CHECK(r >= 0 && g >= 0 && bl >= 0 && cod->width == 3 && cod->height == 2);
    if (r >= 0 && g >= 0 && bl >= 0)
      for (int i = 0; i < 6; i++)
        CHECK(kpcn_image_plane(cod, r)[i] == 2147483648.0f &&
              kpcn_image_plane(cod, g)[i] == 1073741824.0f &&
              kpcn_image_plane(cod, bl)[i] == (float)4294967295u);
    kpcn_image_destroy(cod);
    cod = NULL;
  }
  CHECK(kpcn_exr_read_image(KPCN_TESTDATA "/io/b44_half.exr", &cod) == KPCN_OK);
  kpcn_image_destroy(cod);

  /* as an AOV set: the buffers Tungsten wrote, with the header metadata */
  kpcn_aov_set *set = NULL;
  CHECK(kpcn_exr_read_aov(render, &set) == KPCN_OK);
  if (set) {
    const int present[] = {KPCN_BUF_COLOR, KPCN_BUF_ALBEDO, KPCN_BUF_NORMAL, KPCN_BUF_DEPTH,
                           KPCN_BUF_VISIBILITY};
    for (int i = 0; i < 5; i++)
      CHECK(set->buf[present[i]] && set->var[present[i]]);
    CHECK(!set->buf[KPCN_BUF_DIFFUSE] && !set->buf[KPCN_BUF_SPECULAR]);
    CHECK(set->spp == 16 && set->seed == -1 && strcmp(set->scene, "tungsten cornell-box") == 0);
    size_t n = kpcn_aov_plane_size(set);
    int kz = kpcn_image_find_channel(img, "N.Z");
    if (set->buf[KPCN_BUF_NORMAL] && kz >= 0)
      CHECK(memcmp(set->buf[KPCN_BUF_NORMAL] + 2 * n, kpcn_image_plane(img, kz), n * 4) == 0);
    CHECK(kpcn_aov_count_nonfinite(set, NULL) == 0); /* OIIO: NanCount/InfCount all 0 */
  }
  kpcn_aov_destroy(set);
  kpcn_image_destroy(img);
  return kt_summary("test_exr_oiio");
}
