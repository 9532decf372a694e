/* kpcn_arch: the network architecture as data, its presets, validation and JSON form. */
#include "core/internal.h"
#include "kpcn/nn.h"

#include <cjson/cJSON.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static void set_uniform(kpcn_arch *a, int n_hidden, int channels, int size, int K) {
  a->n_hidden = n_hidden;
  a->channels = channels;
  a->kernel_size = K;
  for (int l = 0; l < KPCN_NN_MAX_LAYERS; l++) {
    a->conv_size[l] = l <= n_hidden ? size : 0;
    a->dilation[l] = l <= n_hidden ? 1 : 0;
  }
}

void kpcn_arch_defaults(kpcn_arch *a) {
  memset(a, 0, sizeof *a);
  kpcn_arch_preset("cpu", a);
}

kpcn_status kpcn_arch_preset(const char *name, kpcn_arch *a) {
  if (!a || !name) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_arch_preset: NULL argument");
  kpcn_arch t;
  memset(&t, 0, sizeof t);
  if (!strcmp(name, "paper")) {
    /* Seed ch. 4.2: nine hidden layers of 100 5x5 kernels, linear output, K = 21. */
    set_uniform(&t, 9, 100, 5, 21);
  } else if (!strcmp(name, "cpu")) {
    /* Six hidden 3x3 layers of 48 channels; dilations 1,2,4,8,4,2 give a conv receptive
     * radius of 22 px (paper: 20) at ~1/19 of the paper's FLOPs; 3x3 linear output to
     * K = 11 (121 logits). See docs/nn.md. */
    set_uniform(&t, 6, 48, 3, 11);
    static const int dil[7] = {1, 2, 4, 8, 4, 2, 1};
    for (int l = 0; l < 7; l++)
      t.dilation[l] = dil[l];
  } else if (!strcmp(name, "tiny")) {
    set_uniform(&t, 2, 8, 3, 5);
  } else {
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "unknown architecture preset '%s' (known: paper, cpu, tiny)", name);
  }
  snprintf(t.name, sizeof t.name, "%s", name);
  t.eps = 0.00316f; /* Bako 2017's albedo epsilon */
  snprintf(t.preprocess, sizeof t.preprocess, "kpcn-pre-1");
  t.kpa_passes = 1;
  /* keep inputs already set by the caller */
  t.n_inputs = a->n_inputs > 0 && a->n_inputs <= KPCN_NN_MAX_INPUTS ? a->n_inputs : 0;
  memcpy(t.inputs, a->inputs, sizeof t.inputs);
  *a = t;
  return KPCN_OK;
}

kpcn_status kpcn_arch_set_inputs(kpcn_arch *a, int n, const char *const *names) {
  if (!a || (n > 0 && !names))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_arch_set_inputs: NULL argument");
  if (n < 1 || n > KPCN_NN_MAX_INPUTS)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_arch_set_inputs: n = %d not in [1, %d]", n,
                     KPCN_NN_MAX_INPUTS);
  for (int i = 0; i < n; i++) {
    if (!names[i] || !names[i][0] || strlen(names[i]) >= KPCN_NN_NAME_LEN)
      return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                       "kpcn_arch_set_inputs: input name %d is empty or longer than %d bytes", i,
                       KPCN_NN_NAME_LEN - 1);
  }
  memset(a->inputs, 0, sizeof a->inputs);
  for (int i = 0; i < n; i++)
    snprintf(a->inputs[i], KPCN_NN_NAME_LEN, "%s", names[i]);
  a->n_inputs = n;
  return KPCN_OK;
}

static int name_ok(const char *s, size_t cap) {
  size_t n = strnlen(s, cap);
  return n > 0 && n < cap;
}

kpcn_status kpcn_arch_validate(const kpcn_arch *a) {
  if (!a) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "arch is NULL");
  if (a->n_hidden < 0 || a->n_hidden > KPCN_NN_MAX_LAYERS - 1)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "arch.n_hidden = %d not in [0, %d]", a->n_hidden,
                     KPCN_NN_MAX_LAYERS - 1);
  if (a->n_hidden > 0 && (a->channels < 1 || a->channels > 1024))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "arch.channels = %d not in [1, 1024]", a->channels);
  for (int l = 0; l <= a->n_hidden; l++) {
    int k = a->conv_size[l], d = a->dilation[l];
    if (k < 1 || k > 11 || k % 2 == 0)
      return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "arch.conv_size[%d] = %d: must be odd in [1, 11]",
                       l, k);
    if (d < 1 || d > 64)
      return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "arch.dilation[%d] = %d: must be in [1, 64]", l,
                       d);
  }
  int K = a->kernel_size;
  if (K < 3 || K > KPCN_NN_MAX_KERNEL || K % 2 == 0)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "arch.kernel_size = %d: must be odd in [3, %d]", K,
                     KPCN_NN_MAX_KERNEL);
  if (a->n_inputs < 1 || a->n_inputs > KPCN_NN_MAX_INPUTS)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "arch.n_inputs = %d not in [1, %d] (set the input list with "
                     "kpcn_arch_set_inputs)",
                     a->n_inputs, KPCN_NN_MAX_INPUTS);
  for (int i = 0; i < a->n_inputs; i++) {
    if (!name_ok(a->inputs[i], KPCN_NN_NAME_LEN))
      return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "arch.inputs[%d] is empty or too long", i);
    for (int j = 0; j < i; j++)
      if (!strcmp(a->inputs[i], a->inputs[j]))
        return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "arch.inputs[%d] = '%s' duplicates inputs[%d]",
                         i, a->inputs[i], j);
  }
  /* 0 would divide by zero wherever the albedo is 0 (misses, black materials) */
  if (!(a->eps > 0.0f && a->eps < 1.0f))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "arch.eps = %g not in (0, 1)", (double)a->eps);
  if (a->kpa_passes < 0 || a->kpa_passes > KPCN_NN_MAX_KPA_PASSES)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "arch.kpa_passes = %d not in [0, %d] (0 = 1)",
                     a->kpa_passes, KPCN_NN_MAX_KPA_PASSES);
  if (a->source_weight != 0 && a->source_weight != 1)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "arch.source_weight = %d: must be 0 or 1",
                     a->source_weight);
  if (!(a->exposure >= 0.0f) || !isfinite(a->exposure))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "arch.exposure = %g: must be >= 0 and finite",
                     (double)a->exposure);
  if (!name_ok(a->name, KPCN_NN_NAME_LEN))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "arch.name is empty or too long");
  if (!name_ok(a->preprocess, KPCN_NN_NAME_LEN))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "arch.preprocess is empty or too long");
  return KPCN_OK;
}

int kpcn_arch_layer_in(const kpcn_arch *a, int l) { return l == 0 ? a->n_inputs : a->channels; }
int kpcn_arch_layer_out(const kpcn_arch *a, int l) {
  return l == a->n_hidden ? kpcn_arch_logit_channels(a) : a->channels;
}

int kpcn_arch_conv_radius(const kpcn_arch *a) {
  int r = 0;
  for (int l = 0; l <= a->n_hidden; l++)
    r += a->dilation[l] * (a->conv_size[l] - 1) / 2;
  return r;
}

int kpcn_arch_receptive_radius(const kpcn_arch *a) {
  /* source scores are read at every pixel the first pass reads: K/2 further out */
  const int k = a->kernel_size / 2, extra = (kpcn_arch_kpa_passes(a) - 1) * k;
  const int r_feat = kpcn_arch_conv_radius(a) + extra + (a->source_weight ? k : 0);
  const int r_noisy = k + extra;
  return r_feat > r_noisy ? r_feat : r_noisy;
}

double kpcn_arch_flops_per_pixel(const kpcn_arch *a) {
  double f = 0;
  for (int l = 0; l <= a->n_hidden; l++)
    f += 2.0 * kpcn_arch_layer_in(a, l) * kpcn_arch_layer_out(a, l) * a->conv_size[l] *
         a->conv_size[l];
  return f;
}

size_t kpcn_arch_param_count(const kpcn_arch *a) {
  size_t n = 0;
  for (int l = 0; l <= a->n_hidden; l++) {
    size_t o = (size_t)kpcn_arch_layer_out(a, l);
    n += o * (size_t)kpcn_arch_layer_in(a, l) * (size_t)(a->conv_size[l] * a->conv_size[l]) + o;
  }
  return n;
}

/* Adds item to o under key, or deletes it: 0 when either failed (out of memory). */
static int add_item(cJSON *o, const char *key, cJSON *item) {
  if (item && cJSON_AddItemToObject(o, key, item)) return 1;
  cJSON_Delete(item);
  return 0;
}

char *kpcn_arch_to_json(const kpcn_arch *a) {
  if (!a) return NULL;
  cJSON *o = cJSON_CreateObject();
  if (!o) return NULL;
  int nl = a->n_hidden + 1;
  if (nl < 1 || nl > KPCN_NN_MAX_LAYERS) nl = 1;
  int nin = a->n_inputs < 0                    ? 0
            : a->n_inputs > KPCN_NN_MAX_INPUTS ? KPCN_NN_MAX_INPUTS
                                               : a->n_inputs;
  /* every call checked: a description missing a field would be saved as the model's */
  int ok = cJSON_AddStringToObject(o, "name", a->name) &&
           cJSON_AddNumberToObject(o, "n_hidden", a->n_hidden) &&
           cJSON_AddNumberToObject(o, "channels", a->channels) &&
           add_item(o, "conv_size", cJSON_CreateIntArray(a->conv_size, nl)) &&
           add_item(o, "dilation", cJSON_CreateIntArray(a->dilation, nl)) &&
           cJSON_AddNumberToObject(o, "kernel_size", a->kernel_size);
  cJSON *in = ok ? cJSON_AddArrayToObject(o, "inputs") : NULL;
  ok = in != NULL;
  for (int i = 0; ok && i < nin; i++) {
    cJSON *v = cJSON_CreateString(a->inputs[i]);
    ok = v && cJSON_AddItemToArray(in, v);
    if (!ok) cJSON_Delete(v);
  }
  char eps[32];
  snprintf(eps, sizeof eps, "%.9g", (double)a->eps);
  ok = ok && cJSON_AddRawToObject(o, "eps", eps) &&
       cJSON_AddStringToObject(o, "preprocess", a->preprocess);
  /* written only when not 1, so single-pass models keep the bytes they always had */
  if (ok && kpcn_arch_kpa_passes(a) != 1)
    ok = cJSON_AddNumberToObject(o, "kpa_passes", a->kpa_passes) != NULL;
  if (ok && a->source_weight)
    ok = cJSON_AddNumberToObject(o, "source_weight", a->source_weight) != NULL;
  if (ok && a->exposure > 0.0f) {
    char e[32];
    snprintf(e, sizeof e, "%.9g", (double)a->exposure);
    ok = cJSON_AddRawToObject(o, "exposure", e) != NULL;
  }
  if (!ok) {
    cJSON_Delete(o);
    return NULL;
  }
  char *s = cJSON_PrintUnformatted(o);
  cJSON_Delete(o);
  return s;
}

static kpcn_status get_int(const cJSON *o, const char *key, int *v) {
  const cJSON *it = cJSON_GetObjectItemCaseSensitive(o, key);
  if (!cJSON_IsNumber(it) || it->valuedouble != floor(it->valuedouble) ||
      fabs(it->valuedouble) > 1e6)
    return kpcn_fail(KPCN_ERR_FORMAT, "architecture.%s: missing or not an integer", key);
  *v = (int)it->valuedouble;
  return KPCN_OK;
}

static kpcn_status get_str(const cJSON *o, const char *key, char *dst, size_t cap) {
  const cJSON *it = cJSON_GetObjectItemCaseSensitive(o, key);
  if (!cJSON_IsString(it) || !it->valuestring || strlen(it->valuestring) >= cap)
    return kpcn_fail(KPCN_ERR_FORMAT, "architecture.%s: missing, not a string or too long", key);
  snprintf(dst, cap, "%s", it->valuestring);
  return KPCN_OK;
}

static kpcn_status get_int_array(const cJSON *o, const char *key, int n, int *dst) {
  const cJSON *arr = cJSON_GetObjectItemCaseSensitive(o, key);
  if (!cJSON_IsArray(arr) || cJSON_GetArraySize(arr) != n)
    return kpcn_fail(KPCN_ERR_FORMAT, "architecture.%s: missing or not an array of %d integers",
                     key, n);
  for (int i = 0; i < n; i++) {
    const cJSON *it = cJSON_GetArrayItem(arr, i);
    if (!cJSON_IsNumber(it) || it->valuedouble != floor(it->valuedouble) ||
        fabs(it->valuedouble) > 1e6)
      return kpcn_fail(KPCN_ERR_FORMAT, "architecture.%s[%d]: not an integer", key, i);
    dst[i] = (int)it->valuedouble;
  }
  return KPCN_OK;
}

static kpcn_status from_json_obj(const cJSON *o, kpcn_arch *t) {
  if (!cJSON_IsObject(o)) return kpcn_fail(KPCN_ERR_FORMAT, "architecture: not a JSON object");
  KPCN_TRY(get_str(o, "name", t->name, sizeof t->name));
  KPCN_TRY(get_int(o, "n_hidden", &t->n_hidden));
  if (t->n_hidden < 0 || t->n_hidden > KPCN_NN_MAX_LAYERS - 1)
    return kpcn_fail(KPCN_ERR_FORMAT, "architecture.n_hidden = %d not in [0, %d]", t->n_hidden,
                     KPCN_NN_MAX_LAYERS - 1);
  KPCN_TRY(get_int(o, "channels", &t->channels));
  KPCN_TRY(get_int_array(o, "conv_size", t->n_hidden + 1, t->conv_size));
  KPCN_TRY(get_int_array(o, "dilation", t->n_hidden + 1, t->dilation));
  KPCN_TRY(get_int(o, "kernel_size", &t->kernel_size));
  const cJSON *in = cJSON_GetObjectItemCaseSensitive(o, "inputs");
  int n = cJSON_IsArray(in) ? cJSON_GetArraySize(in) : -1;
  if (n < 1 || n > KPCN_NN_MAX_INPUTS)
    return kpcn_fail(KPCN_ERR_FORMAT, "architecture.inputs: missing or not an array of 1..%d names",
                     KPCN_NN_MAX_INPUTS);
  for (int i = 0; i < n; i++) {
    const cJSON *it = cJSON_GetArrayItem(in, i);
    if (!cJSON_IsString(it) || !it->valuestring || !it->valuestring[0] ||
        strlen(it->valuestring) >= KPCN_NN_NAME_LEN)
      return kpcn_fail(KPCN_ERR_FORMAT, "architecture.inputs[%d]: not a name of 1..%d bytes", i,
                       KPCN_NN_NAME_LEN - 1);
    snprintf(t->inputs[i], KPCN_NN_NAME_LEN, "%s", it->valuestring);
  }
  t->n_inputs = n;
  const cJSON *eps = cJSON_GetObjectItemCaseSensitive(o, "eps");
  if (!cJSON_IsNumber(eps)) return kpcn_fail(KPCN_ERR_FORMAT, "architecture.eps: missing");
  t->eps = (float)eps->valuedouble;
  KPCN_TRY(get_str(o, "preprocess", t->preprocess, sizeof t->preprocess));
  t->kpa_passes = 1; /* absent in files written before the field existed */
  if (cJSON_GetObjectItemCaseSensitive(o, "kpa_passes")) {
    KPCN_TRY(get_int(o, "kpa_passes", &t->kpa_passes));
    if (t->kpa_passes < 1)
      return kpcn_fail(KPCN_ERR_FORMAT, "architecture.kpa_passes = %d: must be >= 1",
                       t->kpa_passes);
  }
  t->source_weight = 0; /* likewise */
  if (cJSON_GetObjectItemCaseSensitive(o, "source_weight"))
    KPCN_TRY(get_int(o, "source_weight", &t->source_weight));
  t->exposure = 0.0f; /* likewise */
  const cJSON *ex = cJSON_GetObjectItemCaseSensitive(o, "exposure");
  if (ex) {
    /* judged as the float it is stored as: 1e-60 would become 0, "not recorded" */
    const float ev = cJSON_IsNumber(ex) ? (float)ex->valuedouble : 0.0f;
    if (!cJSON_IsNumber(ex) || !(ev > 0.0f) || !(ex->valuedouble <= 1e30))
      return kpcn_fail(KPCN_ERR_FORMAT, "architecture.exposure: not a number in (0, 1e30]");
    t->exposure = ev;
  }
  kpcn_status s = kpcn_arch_validate(t);
  if (s != KPCN_OK) {
    char msg[512]; /* kpcn_fail must not format from its own buffer */
    snprintf(msg, sizeof msg, "%s", kpcn_last_error());
    return kpcn_fail(KPCN_ERR_FORMAT, "invalid architecture: %s", msg);
  }
  return KPCN_OK;
}

kpcn_status kpcn_arch_from_json(const char *json, kpcn_arch *a) {
  if (!json || !a)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_arch_from_json: NULL argument");
  cJSON *o = cJSON_ParseWithOpts(json, NULL, 1); /* nothing may follow the object */
  if (!o) return kpcn_fail(KPCN_ERR_FORMAT, "architecture: not valid JSON (or text after it)");
  kpcn_arch t;
  memset(&t, 0, sizeof t);
  kpcn_status s = from_json_obj(o, &t);
  cJSON_Delete(o);
  if (s == KPCN_OK) *a = t;
  return s;
}
