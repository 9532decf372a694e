/* Tiny 3-vector type shared by the render and scene modules (colours use it too).
 * Everything is static inline so the path tracer's inner loop stays free of calls. */
#ifndef KPCN_RENDER_VEC3_H
#define KPCN_RENDER_VEC3_H

#include <math.h>

typedef struct kpcn_vec3 {
  float x, y, z;
} kpcn_vec3;

static inline kpcn_vec3 kv3(float x, float y, float z) {
  kpcn_vec3 r = {x, y, z};
  return r;
}
static inline kpcn_vec3 kv3s(float s) { return kv3(s, s, s); }
static inline kpcn_vec3 kv3_add(kpcn_vec3 a, kpcn_vec3 b) {
  return kv3(a.x + b.x, a.y + b.y, a.z + b.z);
}
static inline kpcn_vec3 kv3_sub(kpcn_vec3 a, kpcn_vec3 b) {
  return kv3(a.x - b.x, a.y - b.y, a.z - b.z);
}
static inline kpcn_vec3 kv3_mul(kpcn_vec3 a, kpcn_vec3 b) {
  return kv3(a.x * b.x, a.y * b.y, a.z * b.z);
}
static inline kpcn_vec3 kv3_div(kpcn_vec3 a, kpcn_vec3 b) {
  return kv3(a.x / b.x, a.y / b.y, a.z / b.z);
}
static inline kpcn_vec3 kv3_scale(kpcn_vec3 a, float s) { return kv3(a.x * s, a.y * s, a.z * s); }
static inline kpcn_vec3 kv3_neg(kpcn_vec3 a) { return kv3(-a.x, -a.y, -a.z); }
/* a + b*s */
static inline kpcn_vec3 kv3_madd(kpcn_vec3 a, kpcn_vec3 b, float s) {
  return kv3(a.x + b.x * s, a.y + b.y * s, a.z + b.z * s);
}
static inline float kv3_dot(kpcn_vec3 a, kpcn_vec3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
static inline kpcn_vec3 kv3_cross(kpcn_vec3 a, kpcn_vec3 b) {
  return kv3(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x);
}
static inline float kv3_length2(kpcn_vec3 a) { return kv3_dot(a, a); }
static inline float kv3_length(kpcn_vec3 a) { return sqrtf(kv3_dot(a, a)); }
static inline kpcn_vec3 kv3_normalize(kpcn_vec3 a) {
  float l = kv3_length(a);
  return l > 0.0f ? kv3_scale(a, 1.0f / l) : a;
}
/* max/min as one compare-select instruction: fmaxf/fminf are library calls unless NaN rules
 * are relaxed. These return b when either operand is NaN, so with the possibly-NaN value
 * first and a constant second they clamp a NaN like fmaxf/fminf do. */
static inline float kpcn_maxf(float a, float b) { return a > b ? a : b; }
static inline float kpcn_minf(float a, float b) { return a < b ? a : b; }
static inline kpcn_vec3 kv3_min(kpcn_vec3 a, kpcn_vec3 b) {
  return kv3(kpcn_minf(a.x, b.x), kpcn_minf(a.y, b.y), kpcn_minf(a.z, b.z));
}
static inline kpcn_vec3 kv3_max(kpcn_vec3 a, kpcn_vec3 b) {
  return kv3(kpcn_maxf(a.x, b.x), kpcn_maxf(a.y, b.y), kpcn_maxf(a.z, b.z));
}
static inline kpcn_vec3 kv3_exp(kpcn_vec3 a) { return kv3(expf(a.x), expf(a.y), expf(a.z)); }
static inline kpcn_vec3 kv3_sqrt(kpcn_vec3 a) { return kv3(sqrtf(a.x), sqrtf(a.y), sqrtf(a.z)); }
static inline float kv3_max_comp(kpcn_vec3 a) { return kpcn_maxf(a.x, kpcn_maxf(a.y, a.z)); }
static inline float kv3_min_comp(kpcn_vec3 a) { return kpcn_minf(a.x, kpcn_minf(a.y, a.z)); }
static inline float kv3_avg(kpcn_vec3 a) { return (a.x + a.y + a.z) * (1.0f / 3.0f); }
static inline float kv3_luminance(kpcn_vec3 a) {
  return 0.2126f * a.x + 0.7152f * a.y + 0.0722f * a.z;
}
static inline int kv3_equal(kpcn_vec3 a, kpcn_vec3 b) {
  return a.x == b.x && a.y == b.y && a.z == b.z;
}
static inline int kv3_is_zero(kpcn_vec3 a) { return a.x == 0.0f && a.y == 0.0f && a.z == 0.0f; }
static inline int kv3_is_finite(kpcn_vec3 a) {
  return isfinite(a.x) && isfinite(a.y) && isfinite(a.z);
}
static inline float kv3_get(kpcn_vec3 a, int i) { return i == 0 ? a.x : (i == 1 ? a.y : a.z); }

/* Orthonormal basis (t, b, n): z axis = n. Duff et al. 2017 "Building an orthonormal basis,
 * revisited" (branchless, continuous except at n.z = -1 sign flip). n must be unit length. */
typedef struct kpcn_frame {
  kpcn_vec3 t, b, n;
} kpcn_frame;

static inline kpcn_frame kpcn_frame_from_normal(kpcn_vec3 n) {
  float sign = copysignf(1.0f, n.z);
  float a = -1.0f / (sign + n.z);
  float b = n.x * n.y * a;
  kpcn_frame f;
  f.t = kv3(1.0f + sign * n.x * n.x * a, sign * b, -sign * n.x);
  f.b = kv3(b, sign + n.y * n.y * a, -n.y);
  f.n = n;
  return f;
}
static inline kpcn_vec3 kpcn_frame_to_local(const kpcn_frame *f, kpcn_vec3 v) {
  return kv3(kv3_dot(v, f->t), kv3_dot(v, f->b), kv3_dot(v, f->n));
}
static inline kpcn_vec3 kpcn_frame_to_world(const kpcn_frame *f, kpcn_vec3 v) {
  return kv3_add(kv3_add(kv3_scale(f->t, v.x), kv3_scale(f->b, v.y)), kv3_scale(f->n, v.z));
}

#endif
