/* Tungsten's "transform" objects (meaning learnt from Tungsten's JsonPtr::get(Mat4f)):
 *   axes start as x=(1,0,0), y=(0,1,0), z=(0,0,1); "look_at" sets z = look_at - position,
 *   "up" sets y, "x_axis"/"y_axis"/"z_axis" set axes explicitly; the axes are made
 *   orthonormal (Gram-Schmidt in an order that keeps the explicit ones), a left-handed result
 *   flips an implicit axis; then "scale" (number or 3 numbers) scales the axes and
 *   "rotation" (degrees, Tungsten's YXZ Euler convention) rotates them; "position" translates.
 * A 16-number array is a row-major 4x4 matrix. */
#include "core/internal.h"
#include "scene/scene_internal.h"

#include <cjson/cJSON.h>
#include <math.h>
#include <string.h>

void kpcn_xform_identity(kpcn_xform *x) {
  memset(x, 0, sizeof(*x));
  x->m[0][0] = x->m[1][1] = x->m[2][2] = 1.0f;
}

kpcn_vec3 kpcn_xform_point(const kpcn_xform *x, kpcn_vec3 p) {
  return kv3(x->m[0][0] * p.x + x->m[0][1] * p.y + x->m[0][2] * p.z + x->m[0][3],
             x->m[1][0] * p.x + x->m[1][1] * p.y + x->m[1][2] * p.z + x->m[1][3],
             x->m[2][0] * p.x + x->m[2][1] * p.y + x->m[2][2] * p.z + x->m[2][3]);
}

kpcn_vec3 kpcn_xform_vector(const kpcn_xform *x, kpcn_vec3 p) {
  return kv3(x->m[0][0] * p.x + x->m[0][1] * p.y + x->m[0][2] * p.z,
             x->m[1][0] * p.x + x->m[1][1] * p.y + x->m[1][2] * p.z,
             x->m[2][0] * p.x + x->m[2][1] * p.y + x->m[2][2] * p.z);
}

kpcn_vec3 kpcn_xform_column(const kpcn_xform *x, int i) {
  return kv3(x->m[0][i], x->m[1][i], x->m[2][i]);
}

kpcn_vec3 kpcn_xform_normal(const kpcn_xform *x, kpcn_vec3 n) {
  /* inverse transpose applied to n == cofactor matrix times n (scale irrelevant: we normalise) */
  kpcn_vec3 c0 = kpcn_xform_column(x, 0), c1 = kpcn_xform_column(x, 1),
            c2 = kpcn_xform_column(x, 2);
  kpcn_vec3 r0 = kv3_cross(c1, c2), r1 = kv3_cross(c2, c0), r2 = kv3_cross(c0, c1);
  kpcn_vec3 out = kv3_add(kv3_add(kv3_scale(r0, n.x), kv3_scale(r1, n.y)), kv3_scale(r2, n.z));
  return kv3_normalize(out);
}

static kpcn_status get_vec3(const cJSON *obj, const char *key, const char *path, kpcn_vec3 *v,
                            int allow_scalar, int *found) {
  const cJSON *it = cJSON_GetObjectItemCaseSensitive(obj, key);
  *found = 0;
  if (!it) return KPCN_OK;
  if (allow_scalar && cJSON_IsNumber(it)) {
    *v = kv3s((float)it->valuedouble);
  } else if (cJSON_IsArray(it) && cJSON_GetArraySize(it) == 3) {
    float f[3];
    for (int i = 0; i < 3; i++) {
      const cJSON *e = cJSON_GetArrayItem(it, i);
      if (!cJSON_IsNumber(e))
        return kpcn_fail(KPCN_ERR_FORMAT, "%s.%s[%d]: expected a number", path, key, i);
      f[i] = (float)e->valuedouble;
    }
    *v = kv3(f[0], f[1], f[2]);
  } else {
    return kpcn_fail(KPCN_ERR_FORMAT, "%s.%s: expected %s3 numbers", path, key,
                     allow_scalar ? "a number or " : "");
  }
  if (!kv3_is_finite(*v))
    return kpcn_fail(KPCN_ERR_NONFINITE, "%s.%s: non-finite value", path, key);
  *found = 1;
  return KPCN_OK;
}

static kpcn_vec3 random_ortho(kpcn_vec3 a) {
  kpcn_vec3 r = fabsf(a.x) > fabsf(a.y) ? kv3(0, 1, 0) : kv3(1, 0, 0);
  return kv3_normalize(kv3_cross(a, r));
}

/* Orthonormalise keeping a, then b, then c. */
static void gram_schmidt(kpcn_vec3 *a, kpcn_vec3 *b, kpcn_vec3 *c) {
  *a = kv3_normalize(*a);
  *b = kv3_sub(*b, kv3_scale(*a, kv3_dot(*a, *b)));
  if (kv3_length2(*b) < 1e-5f)
    *b = random_ortho(*a);
  else
    *b = kv3_normalize(*b);
  *c = kv3_sub(*c, kv3_scale(*a, kv3_dot(*a, *c)));
  *c = kv3_sub(*c, kv3_scale(*b, kv3_dot(*b, *c)));
  if (kv3_length2(*c) < 1e-5f)
    *c = kv3_cross(*a, *b);
  else
    *c = kv3_normalize(*c);
}

/* Tungsten's YXZ Euler rotation (angles in degrees), row-major 3x3. */
static void rot_yxz(kpcn_vec3 rot, float R[3][3]) {
  const double k = 3.14159265358979323846 / 180.0;
  double cx = cos(rot.x * k), cy = cos(rot.y * k), cz = cos(rot.z * k);
  double sx = sin(rot.x * k), sy = sin(rot.y * k), sz = sin(rot.z * k);
  R[0][0] = (float)(cy * cz - sy * sx * sz);
  R[0][1] = (float)(-cy * sz - sy * sx * cz);
  R[0][2] = (float)(-sy * cx);
  R[1][0] = (float)(cx * sz);
  R[1][1] = (float)(cx * cz);
  R[1][2] = (float)(-sx);
  R[2][0] = (float)(sy * cz + cy * sx * sz);
  R[2][1] = (float)(-sy * sz + cy * sx * cz);
  R[2][2] = (float)(cy * cx);
}

static kpcn_vec3 mul3(float R[3][3], kpcn_vec3 v) {
  return kv3(R[0][0] * v.x + R[0][1] * v.y + R[0][2] * v.z,
             R[1][0] * v.x + R[1][1] * v.y + R[1][2] * v.z,
             R[2][0] * v.x + R[2][1] * v.y + R[2][2] * v.z);
}

kpcn_status kpcn_xform_parse(const void *node_, const char *path, kpcn_xform *out) {
  const cJSON *node = (const cJSON *)node_;
  kpcn_xform_identity(out);
  if (!node) return KPCN_OK;
  if (cJSON_IsArray(node)) {
    if (cJSON_GetArraySize(node) != 16)
      return kpcn_fail(KPCN_ERR_FORMAT, "%s: a matrix needs 16 numbers, got %d", path,
                       cJSON_GetArraySize(node));
    /* All 16 are checked (only the first 12 were: a last row of strings passed), each as the
     * float it becomes (1e39 is Inf). The last row must be 0 0 0 1: kpcn transforms are
     * affine, and a projective row would be dropped without a word. */
    int i = 0;
    for (const cJSON *e = node->child; e; e = e->next, i++) {
      if (!cJSON_IsNumber(e))
        return kpcn_fail(KPCN_ERR_FORMAT, "%s[%d]: expected a number", path, i);
      const float v = (float)e->valuedouble;
      if (!isfinite(v))
        return kpcn_fail(KPCN_ERR_NONFINITE, "%s[%d]: non-finite value (as a float)", path, i);
      if (i >= 12 && e->valuedouble != (i == 15 ? 1.0 : 0.0))
        return kpcn_fail(KPCN_ERR_UNSUPPORTED,
                         "%s[%d]: the last row must be 0, 0, 0, 1 (projective matrices are not "
                         "supported), got %g",
                         path, i, e->valuedouble);
      if (i < 12) out->m[i / 4][i % 4] = v;
    }
    return KPCN_OK;
  }
  if (!cJSON_IsObject(node))
    return kpcn_fail(KPCN_ERR_FORMAT, "%s: expected a transform object or 16 numbers", path);
  static const char *known[] = {"position", "scale",  "rotation", "look_at",
                                "up",       "x_axis", "y_axis",   "z_axis"};
  for (const cJSON *it = node->child; it; it = it->next) {
    int ok = 0;
    for (size_t i = 0; i < sizeof(known) / sizeof(known[0]); i++)
      if (it->string && strcmp(it->string, known[i]) == 0) ok = 1;
    if (!ok)
      return kpcn_fail(KPCN_ERR_UNSUPPORTED, "%s.%s: unsupported transform field", path,
                       it->string ? it->string : "?");
  }
  kpcn_vec3 x = kv3(1, 0, 0), y = kv3(0, 1, 0), z = kv3(0, 0, 1), pos = kv3s(0), tmp;
  int f, ex = 0, ey = 0, ez = 0;
  KPCN_TRY(get_vec3(node, "position", path, &pos, 0, &f));
  KPCN_TRY(get_vec3(node, "look_at", path, &tmp, 0, &f));
  if (f) {
    z = kv3_sub(tmp, pos);
    if (kv3_length2(z) == 0.0f)
      return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s.look_at: equals position", path);
    ez = 1;
  }
  KPCN_TRY(get_vec3(node, "up", path, &y, 0, &ey));
  KPCN_TRY(get_vec3(node, "x_axis", path, &tmp, 0, &f));
  if (f) x = tmp, ex = 1;
  KPCN_TRY(get_vec3(node, "y_axis", path, &tmp, 0, &f));
  if (f) y = tmp, ey = 1;
  KPCN_TRY(get_vec3(node, "z_axis", path, &tmp, 0, &f));
  if (f) z = tmp, ez = 1;
  if ((ex && kv3_length2(x) == 0.0f) || (ey && kv3_length2(y) == 0.0f) ||
      (ez && kv3_length2(z) == 0.0f))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s: zero-length axis (%s)", path,
                     ex && kv3_length2(x) == 0.0f   ? "x_axis"
                     : ey && kv3_length2(y) == 0.0f ? "up / y_axis"
                                                    : "look_at / z_axis");
  switch ((ez ? 4 : 0) + (ey ? 2 : 0) + (ex ? 1 : 0)) {
  case 1: gram_schmidt(&x, &z, &y); break;
  case 2: gram_schmidt(&y, &z, &x); break;
  case 3: gram_schmidt(&y, &x, &z); break;
  case 5: gram_schmidt(&z, &x, &y); break;
  default: gram_schmidt(&z, &y, &x); break;
  }
  if (kv3_dot(kv3_cross(x, y), z) < 0.0f) {
    if (!ex)
      x = kv3_neg(x);
    else if (!ey)
      y = kv3_neg(y);
    else
      z = kv3_neg(z);
  }
  kpcn_vec3 s;
  KPCN_TRY(get_vec3(node, "scale", path, &s, 1, &f));
  if (f) {
    x = kv3_scale(x, s.x);
    y = kv3_scale(y, s.y);
    z = kv3_scale(z, s.z);
  }
  kpcn_vec3 rot;
  KPCN_TRY(get_vec3(node, "rotation", path, &rot, 0, &f));
  if (f) {
    float R[3][3];
    rot_yxz(rot, R);
    x = mul3(R, x);
    y = mul3(R, y);
    z = mul3(R, z);
  }
  kpcn_vec3 cols[3] = {x, y, z};
  for (int c = 0; c < 3; c++) {
    out->m[0][c] = cols[c].x;
    out->m[1][c] = cols[c].y;
    out->m[2][c] = cols[c].z;
  }
  out->m[0][3] = pos.x;
  out->m[1][3] = pos.y;
  out->m[2][3] = pos.z;
  return KPCN_OK;
}
