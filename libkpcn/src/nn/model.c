/* kpcn_model: the two branches' conv weights, Xavier init and user metadata. */
#include "core/internal.h"
#include "nn/model_internal.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

const char *const kpcn_nn_branch_names[KPCN_N_BRANCHES] = {"diffuse", "specular"};

size_t kpcn_model_weight_count(const kpcn_arch *a, int l) {
  return (size_t)kpcn_arch_layer_out(a, l) * (size_t)kpcn_arch_layer_in(a, l) *
         (size_t)a->conv_size[l] * (size_t)a->conv_size[l];
}

/* Tensors start at 64-byte boundaries so the optimizer / reorders read aligned memory. */
static size_t round16(size_t n) { return (n + 15) & ~(size_t)15; }

kpcn_status kpcn_model_alloc(const kpcn_arch *arch, kpcn_model **out) {
  KPCN_TRY(kpcn_arch_validate(arch));
  kpcn_model *m = kpcn_calloc(1, sizeof *m, "kpcn_model");
  if (!m) return KPCN_ERR_OUT_OF_MEMORY;
  m->arch = *arch;
  size_t total = 0;
  int nl = arch->n_hidden + 1;
  for (int b = 0; b < KPCN_N_BRANCHES; b++)
    for (int l = 0; l < nl; l++)
      total += round16(kpcn_model_weight_count(arch, l)) + round16(kpcn_arch_layer_out(arch, l));
  m->block = kpcn_aligned_alloc(total * sizeof(float), "model weights");
  if (!m->block) {
    free(m);
    return KPCN_ERR_OUT_OF_MEMORY;
  }
  memset(m->block, 0, total * sizeof(float));
  m->block_floats = total;
  float *p = m->block;
  for (int b = 0; b < KPCN_N_BRANCHES; b++)
    for (int l = 0; l < nl; l++) {
      m->w[b][l] = p;
      p += round16(kpcn_model_weight_count(arch, l));
      m->b[b][l] = p;
      p += round16(kpcn_arch_layer_out(arch, l));
    }
  *out = m;
  return KPCN_OK;
}

/* splitmix64: tiny, well-mixed, and the same on every platform. */
static uint64_t splitmix64(uint64_t *s) {
  uint64_t z = (*s += 0x9E3779B97F4A7C15ull);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

kpcn_status kpcn_model_create(const kpcn_arch *arch, uint64_t seed, kpcn_model **out) {
  if (!arch || !out)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_model_create: NULL argument");
  *out = NULL;
  kpcn_model *m;
  KPCN_TRY(kpcn_model_alloc(arch, &m));
  int nl = arch->n_hidden + 1;
  for (int b = 0; b < KPCN_N_BRANCHES; b++)
    for (int l = 0; l < nl; l++) {
      /* One stream per tensor, so init does not depend on layer order of evaluation. */
      uint64_t st = seed ^ (0xA24BAED4963EE407ull * (uint64_t)(b * KPCN_NN_MAX_LAYERS + l + 1));
      int k2 = arch->conv_size[l] * arch->conv_size[l];
      double fan_in = (double)kpcn_arch_layer_in(arch, l) * k2;
      double fan_out = (double)kpcn_arch_layer_out(arch, l) * k2;
      double lim = sqrt(6.0 / (fan_in + fan_out)); /* Glorot & Bengio 2010, uniform */
      size_t n = kpcn_model_weight_count(arch, l);
      for (size_t i = 0; i < n; i++) {
        double u = (double)(splitmix64(&st) >> 11) * (1.0 / 9007199254740992.0);
        m->w[b][l][i] = (float)((2.0 * u - 1.0) * lim);
      }
    }
  *out = m;
  return KPCN_OK;
}

/* Copies src's user metadata into m; on failure destroys m. */
static kpcn_status copy_meta(kpcn_model *m, const kpcn_model *src) {
  for (int i = 0; i < src->n_meta; i++) {
    kpcn_status s = kpcn_model_set_meta(m, src->meta_key[i], src->meta_val[i]);
    if (s != KPCN_OK) {
      kpcn_model_destroy(m);
      return s;
    }
  }
  return KPCN_OK;
}

kpcn_status kpcn_model_clone(const kpcn_model *src, kpcn_model **out) {
  if (!src || !out) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_model_clone: NULL argument");
  *out = NULL;
  kpcn_model *m;
  KPCN_TRY(kpcn_model_alloc(&src->arch, &m));
  memcpy(m->block, src->block, src->block_floats * sizeof(float));
  KPCN_TRY(copy_meta(m, src));
  *out = m;
  return KPCN_OK;
}

kpcn_status kpcn_model_widen(const kpcn_model *src, int channels, uint64_t seed, kpcn_model **out) {
  if (!src || !out) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_model_widen: NULL argument");
  *out = NULL;
  if (channels < src->arch.channels)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "kpcn_model_widen: channels %d is fewer than the model's %d", channels,
                     src->arch.channels);
  kpcn_arch a = src->arch;
  a.channels = channels;
  kpcn_model *m;
  KPCN_TRY(kpcn_model_create(&a, seed, &m)); /* Xavier everywhere, zero biases */
  for (int b = 0; b < KPCN_N_BRANCHES; b++)
    for (int l = 0; l <= a.n_hidden; l++) {
      const int k2 = a.conv_size[l] * a.conv_size[l];
      const int oo = kpcn_arch_layer_out(&src->arch, l), io = kpcn_arch_layer_in(&src->arch, l);
      const int in = kpcn_arch_layer_in(&a, l);
      /* rows of the old units: their old weights, and zero from every new input channel, so
       * they compute what they did; rows of new units keep their random weights */
      for (int o = 0; o < oo; o++) {
        float *row = m->w[b][l] + (size_t)o * in * k2;
        memcpy(row, src->w[b][l] + (size_t)o * io * k2, sizeof(float) * (size_t)io * k2);
        memset(row + (size_t)io * k2, 0, sizeof(float) * (size_t)(in - io) * k2);
        m->b[b][l][o] = src->b[b][l][o];
      }
    }
  KPCN_TRY(copy_meta(m, src));
  *out = m;
  return KPCN_OK;
}

kpcn_status kpcn_model_set_kpa_passes(kpcn_model *m, int passes) {
  if (!m) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_model_set_kpa_passes: NULL model");
  if (passes < 1 || passes > KPCN_NN_MAX_KPA_PASSES)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpa_passes = %d not in [1, %d]", passes,
                     KPCN_NN_MAX_KPA_PASSES);
  m->arch.kpa_passes = passes;
  return KPCN_OK;
}

/* The model takes `a` (a copy of its architecture with one field changed; the weights stay)
 * only if it validates as a whole. */
static kpcn_status replace_arch(kpcn_model *m, const kpcn_arch *a) {
  KPCN_TRY(kpcn_arch_validate(a));
  m->arch = *a;
  return KPCN_OK;
}

kpcn_status kpcn_model_set_eps(kpcn_model *m, float eps) {
  if (!m) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_model_set_eps: NULL model");
  kpcn_arch a = m->arch;
  a.eps = eps;
  return replace_arch(m, &a);
}

kpcn_status kpcn_model_set_exposure(kpcn_model *m, float exposure) {
  if (!m) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_model_set_exposure: NULL model");
  kpcn_arch a = m->arch;
  a.exposure = exposure;
  return replace_arch(m, &a);
}

kpcn_status kpcn_model_graft_branch(kpcn_model *m, const kpcn_model *from, kpcn_branch b) {
  if (!m || !from)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_model_graft_branch: NULL model");
  if (b != KPCN_BRANCH_DIFFUSE && b != KPCN_BRANCH_SPECULAR)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_model_graft_branch: branch %d", (int)b);
  const char *name = b == KPCN_BRANCH_DIFFUSE ? "diffuse" : "specular";
  /* eps enters only the diffuse branch's input and remodulation, so a specular branch may come
   * from a model of another eps; everything else (shape, inputs, kernel passes) must agree */
  kpcn_arch same = from->arch; /* eps and exposure are checked below, with their own messages */
  same.eps = m->arch.eps;
  same.exposure = m->arch.exposure;
  char *ja = kpcn_arch_to_json(&m->arch), *jb = kpcn_arch_to_json(&same);
  int differ = !ja || !jb || strcmp(ja, jb) != 0;
  free(ja);
  free(jb);
  if (differ)
    return kpcn_fail(KPCN_ERR_FORMAT,
                     "kpcn_model_graft_branch: the %s branch's model has another architecture",
                     name);
  if (b == KPCN_BRANCH_DIFFUSE && from->arch.eps != m->arch.eps)
    return kpcn_fail(KPCN_ERR_FORMAT,
                     "kpcn_model_graft_branch: the diffuse branch was trained at eps %.9g, the "
                     "model demodulates at %.9g (set one eps first: kpcn-train --set-eps)",
                     (double)from->arch.eps, (double)m->arch.eps);
  /* a branch expects its inputs at the exposure it was trained around */
  if (from->arch.exposure != m->arch.exposure)
    return kpcn_fail(KPCN_ERR_FORMAT,
                     "kpcn_model_graft_branch: the %s branch's model records exposure %.9g, the "
                     "model %.9g: the branches would expect inputs at other scales (record one "
                     "store's exposure in both first: kpcn-train --record-exposure)",
                     name, (double)from->arch.exposure, (double)m->arch.exposure);
  for (int l = 0; l <= m->arch.n_hidden; l++) {
    memcpy(m->w[b][l], from->w[b][l], sizeof(float) * kpcn_model_weight_count(&m->arch, l));
    memcpy(m->b[b][l], from->b[b][l], sizeof(float) * (size_t)kpcn_arch_layer_out(&m->arch, l));
  }
  return KPCN_OK;
}

kpcn_status kpcn_model_add_source_weight(const kpcn_model *src, kpcn_model **out) {
  if (!src || !out)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_model_add_source_weight: NULL argument");
  *out = NULL;
  kpcn_arch a = src->arch;
  a.source_weight = 1;
  kpcn_model *m;
  KPCN_TRY(kpcn_model_alloc(&a, &m)); /* zeroed */
  /* OIHW: the source score is the last output row, so every old tensor is a prefix of the
   * new one and the added row stays zero */
  for (int b = 0; b < KPCN_N_BRANCHES; b++)
    for (int l = 0; l <= a.n_hidden; l++) {
      memcpy(m->w[b][l], src->w[b][l], sizeof(float) * kpcn_model_weight_count(&src->arch, l));
      memcpy(m->b[b][l], src->b[b][l], sizeof(float) * (size_t)kpcn_arch_layer_out(&src->arch, l));
    }
  KPCN_TRY(copy_meta(m, src));
  *out = m;
  return KPCN_OK;
}

void kpcn_model_destroy(kpcn_model *m) {
  if (!m) return;
  kpcn_aligned_free(m->block);
  for (int i = 0; i < m->n_meta; i++) {
    free(m->meta_key[i]);
    free(m->meta_val[i]);
  }
  free(m->meta_key);
  free(m->meta_val);
  free(m);
}

const kpcn_arch *kpcn_model_arch(const kpcn_model *m) { return m ? &m->arch : NULL; }

kpcn_status kpcn_model_layer(kpcn_model *m, kpcn_branch b, int l, kpcn_layer_view *v) {
  if (!m || !v) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_model_layer: NULL argument");
  if ((int)b < 0 || (int)b >= KPCN_N_BRANCHES)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_model_layer: branch %d invalid", (int)b);
  if (l < 0 || l > m->arch.n_hidden)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_model_layer: layer %d not in [0, %d]", l,
                     m->arch.n_hidden);
  v->weight = m->w[b][l];
  v->bias = m->b[b][l];
  v->out_ch = kpcn_arch_layer_out(&m->arch, l);
  v->in_ch = kpcn_arch_layer_in(&m->arch, l);
  v->size = m->arch.conv_size[l];
  v->dilation = m->arch.dilation[l];
  v->relu = l < m->arch.n_hidden;
  return KPCN_OK;
}

static char *dupstr(const char *s) {
  size_t n = strlen(s) + 1;
  char *d = kpcn_alloc(n, "metadata string");
  if (d) memcpy(d, s, n);
  return d;
}

kpcn_status kpcn_model_set_meta(kpcn_model *m, const char *key, const char *value) {
  if (!m || !key || !value)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_model_set_meta: NULL argument");
  if (!key[0] || !strncmp(key, "kpcn.", 5))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "metadata key '%s' is empty or uses the reserved prefix 'kpcn.'", key);
  for (int i = 0; i < m->n_meta; i++)
    if (!strcmp(m->meta_key[i], key)) {
      char *v = dupstr(value);
      if (!v) return KPCN_ERR_OUT_OF_MEMORY;
      free(m->meta_val[i]);
      m->meta_val[i] = v;
      return KPCN_OK;
    }
  /* a file with more could be saved but not loaded again */
  if (m->n_meta >= KPCN_MODEL_MAX_META_ENTRIES - KPCN_MODEL_KPCN_KEYS)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "kpcn_model_set_meta: the model already holds %d user entries, the most a "
                     "model file takes",
                     m->n_meta);
  char **k2 = realloc(m->meta_key, (size_t)(m->n_meta + 1) * sizeof *k2);
  if (!k2) return kpcn_fail(KPCN_ERR_OUT_OF_MEMORY, "out of memory for the metadata table");
  m->meta_key = k2;
  char **v2 = realloc(m->meta_val, (size_t)(m->n_meta + 1) * sizeof *v2);
  if (!v2) return kpcn_fail(KPCN_ERR_OUT_OF_MEMORY, "out of memory for the metadata table");
  m->meta_val = v2;
  char *k = dupstr(key), *v = dupstr(value);
  if (!k || !v) {
    free(k);
    free(v);
    return KPCN_ERR_OUT_OF_MEMORY;
  }
  m->meta_key[m->n_meta] = k;
  m->meta_val[m->n_meta] = v;
  m->n_meta++;
  return KPCN_OK;
}

const char *kpcn_model_get_meta(const kpcn_model *m, const char *key) {
  if (!m || !key) return NULL;
  for (int i = 0; i < m->n_meta; i++)
    if (!strcmp(m->meta_key[i], key)) return m->meta_val[i];
  return NULL;
}

int kpcn_model_meta_count(const kpcn_model *m) { return m ? m->n_meta : 0; }
const char *kpcn_model_meta_key(const kpcn_model *m, int i) {
  return m && i >= 0 && i < m->n_meta ? m->meta_key[i] : NULL;
}
