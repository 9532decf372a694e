/* Fresnel terms and Tungsten's table of named conductors.
 * The eta/k values are the RGB complex indices of refraction Tungsten ships
 * (ComplexIorData.hpp, derived from measured spectral data); they are physical constants. */
#include "render/fresnel.h"

#include "render/bsdf.h"

#include <math.h>
#include <string.h>

float kpcn_fresnel_dielectric(float eta, float cos_i, float *cos_t) {
  if (cos_i < 0.0f) {
    eta = 1.0f / eta;
    cos_i = -cos_i;
  }
  float sin_t2 = eta * eta * (1.0f - cos_i * cos_i);
  if (sin_t2 > 1.0f) {
    if (cos_t) *cos_t = 0.0f;
    return 1.0f;
  }
  float ct = sqrtf(kpcn_maxf(1.0f - sin_t2, 0.0f));
  if (cos_t) *cos_t = ct;
  float rs = (eta * cos_i - ct) / (eta * cos_i + ct);
  float rp = (eta * ct - cos_i) / (eta * ct + cos_i);
  return 0.5f * (rs * rs + rp * rp);
}

float kpcn_fresnel_conductor(float eta, float k, float cos_i) {
  float c2 = cos_i * cos_i;
  float s2 = kpcn_maxf(1.0f - c2, 0.0f);
  float s4 = s2 * s2;
  float inner = eta * eta - k * k - s2;
  float ab2 = sqrtf(kpcn_maxf(inner * inner + 4.0f * eta * eta * k * k, 0.0f));
  float a = sqrtf(kpcn_maxf(0.5f * (ab2 + inner), 0.0f));
  float rs = ((ab2 + c2) - 2.0f * a * cos_i) / ((ab2 + c2) + 2.0f * a * cos_i);
  float rp = ((c2 * ab2 + s4) - 2.0f * a * cos_i * s2) / ((c2 * ab2 + s4) + 2.0f * a * cos_i * s2);
  return 0.5f * (rs + rs * rp);
}

kpcn_vec3 kpcn_fresnel_conductor3(kpcn_vec3 eta, kpcn_vec3 k, float cos_i) {
  return kv3(kpcn_fresnel_conductor(eta.x, k.x, cos_i), kpcn_fresnel_conductor(eta.y, k.y, cos_i),
             kpcn_fresnel_conductor(eta.z, k.z, cos_i));
}

float kpcn_fresnel_diffuse_reflectance(float ior) {
  /* Trapezoid rule in cos^2(theta): integral of F over the projected hemisphere. 2^17 steps
   * agree with Tungsten's 10^6 to ~1e-7 and cost well under a millisecond. */
  const int n = 1 << 17;
  double sum = 0.0;
  float fb = kpcn_fresnel_dielectric(ior, 0.0f, NULL);
  for (int i = 1; i <= n; ++i) {
    float c2 = (float)i / (float)n;
    float fa = kpcn_fresnel_dielectric(ior, kpcn_minf(sqrtf(c2), 1.0f), NULL);
    sum += (double)(fa + fb) * (0.5 / n);
    fb = fa;
  }
  return (float)sum;
}

typedef struct {
  const char *name;
  float eta[3], k[3];
} complex_ior;

/* Tungsten's named materials. Names with a "_palik" twin of identical values are listed
 * once; kpcn_conductor_lookup strips the suffix. */
static const complex_ior k_ior[] = {
    {"a-C",
     {2.9440999183f, 2.2271502925f, 1.9681668794f},
     {0.8874329109f, 0.7993216383f, 0.8152862927f}},
    {"Ag",
     {0.1552646489f, 0.1167232965f, 0.1383806959f},
     {4.8283433224f, 3.1222459278f, 2.1469504455f}},
    {"Al",
     {1.6574599595f, 0.8803689579f, 0.5212287346f},
     {9.2238691996f, 6.2695232477f, 4.8370012281f}},
    {"AlAs",
     {3.6051023902f, 3.2329365777f, 2.2175611545f},
     {0.0006670247f, -0.0004999400f, 0.0074261204f}},
    {"AlSb",
     {-0.0485225705f, 4.1427547893f, 4.6697691348f},
     {-0.0363741915f, 0.0937665154f, 1.3007390124f}},
    {"Au",
     {0.1431189557f, 0.3749570432f, 1.4424785571f},
     {3.9831604247f, 2.3857207478f, 1.6032152899f}},
    {"Be",
     {4.1850592788f, 3.1850604423f, 2.7840913457f},
     {3.8354398268f, 3.0101260162f, 2.8690088743f}},
    {"Cr",
     {4.3696828663f, 2.9167024892f, 1.6547005413f},
     {5.2064337956f, 4.2313645277f, 3.7549467933f}},
    {"CsI", {2.1449030413f, 1.7023164587f, 1.6624194173f}, {0.0f, 0.0f, 0.0f}},
    {"Cu",
     {0.2004376970f, 0.9240334304f, 1.1022119527f},
     {3.9129485033f, 2.4528477015f, 2.1421879552f}},
    {"Cu2O",
     {3.5492833755f, 2.9520622449f, 2.7369202137f},
     {0.1132179294f, 0.1946659670f, 0.6001681264f}},
    {"CuO",
     {3.2453822204f, 2.4496293965f, 2.1974114493f},
     {0.5202739621f, 0.5707372756f, 0.7172250613f}},
    {"Cu_palik",
     {0.2126840430f, 0.9199880064f, 1.1024078212f},
     {3.9215626225f, 2.4571489948f, 2.1366534268f}},
    {"d-C", {2.7112524747f, 2.3185812849f, 2.2288565009f}, {0.0f, 0.0f, 0.0f}},
    {"Hg",
     {2.3989314904f, 1.4400254917f, 0.9095512090f},
     {6.3276269444f, 4.3719414152f, 3.4217899270f}},
    {"HgTe",
     {4.7795267752f, 3.2309984581f, 2.6600252401f},
     {1.6319827058f, 1.5808189339f, 1.7295753852f}},
    {"Ir",
     {3.0864098394f, 2.0821938440f, 1.6178866805f},
     {5.5921510077f, 4.0671757150f, 3.2672611269f}},
    {"K",
     {0.0640493070f, 0.0464100621f, 0.0381842017f},
     {2.1042155920f, 1.3489364357f, 0.9132113889f}},
    {"Li",
     {0.2657871942f, 0.1956102432f, 0.2209198538f},
     {3.5401743407f, 2.3111306542f, 1.6685930000f}},
    {"MgO", {2.0895885542f, 1.6507224525f, 1.5948759692f}, {0.0f, 0.0f, 0.0f}},
    {"Mo",
     {4.4837010280f, 3.5254578255f, 2.7760769438f},
     {4.1111307988f, 3.4208716252f, 3.1506031404f}},
    {"Na_palik",
     {0.0602665320f, 0.0561412435f, 0.0619909494f},
     {3.1792906496f, 2.1124800781f, 1.5790940266f}},
    {"Nb",
     {3.4201353595f, 2.7901921379f, 2.3955856658f},
     {3.4413817900f, 2.7376437930f, 2.5799132708f}},
    {"Ni_palik",
     {2.3672753521f, 1.6633583302f, 1.4670554172f},
     {4.4988329911f, 3.0501643957f, 2.3454274399f}},
    {"Rh",
     {2.5857954933f, 1.8601866068f, 1.5544279524f},
     {6.7822927110f, 4.7029501026f, 3.9760892461f}},
    {"Se-e",
     {5.7242724833f, 4.1653992967f, 4.0816099264f},
     {0.8713747439f, 1.1052845009f, 1.5647788766f}},
    {"Se",
     {4.0592611085f, 2.8426947380f, 2.8207582835f},
     {0.7543791750f, 0.6385150558f, 0.5215872029f}},
    {"SiC",
     {3.1723450205f, 2.5259677964f, 2.4793623897f},
     {0.0000007284f, -0.0000006859f, 0.0000100150f}},
    {"SnTe", {4.5251865890f, 1.9811525984f, 1.2816819226f}, {0.0f, 0.0f, 0.0f}},
    {"Ta",
     {2.0625846607f, 2.3930915569f, 2.6280684948f},
     {2.4080467973f, 1.7413705864f, 1.9470377016f}},
    {"Te-e",
     {7.5090397678f, 4.2964603080f, 2.3698732430f},
     {5.5842076830f, 4.9476231084f, 3.9975145063f}},
    {"Te",
     {7.3908396088f, 4.4821028985f, 2.6370708478f},
     {3.2561412892f, 3.5273908133f, 3.2921683116f}},
    {"ThF4", {1.8307187117f, 1.4422274283f, 1.3876488528f}, {0.0f, 0.0f, 0.0f}},
    {"TiC",
     {3.7004673762f, 2.8374356509f, 2.5823030278f},
     {3.2656905818f, 2.3515586388f, 2.1727857800f}},
    {"TiN",
     {1.6484691607f, 1.1504482522f, 1.3797795097f},
     {3.3684596226f, 1.9434888540f, 1.1020123347f}},
    {"TiO2-e",
     {3.1065574823f, 2.5131551146f, 2.5823844157f},
     {0.0000289537f, -0.0000251484f, 0.0001775555f}},
    {"TiO2",
     {3.4566203131f, 2.8017076558f, 2.9051485020f},
     {0.0001026662f, -0.0000897534f, 0.0006356902f}},
    {"VC",
     {3.6575665991f, 2.7527298065f, 2.5326814570f},
     {3.0683516659f, 2.1986687713f, 1.9631816252f}},
    {"VN",
     {2.8656011588f, 2.1191817791f, 1.9400767149f},
     {3.0323264950f, 2.0561075580f, 1.6162930914f}},
    {"V_palik",
     {4.2775126218f, 3.5131538236f, 2.7611257461f},
     {3.4911844504f, 2.8893580874f, 3.1116965117f}},
    {"W",
     {4.3707029924f, 3.3002972445f, 2.9982666528f},
     {3.5006778591f, 2.6048652781f, 2.2731930614f}},
};

static int lookup_exact(const char *name, size_t len, kpcn_vec3 *eta, kpcn_vec3 *k) {
  for (size_t i = 0; i < sizeof(k_ior) / sizeof(k_ior[0]); ++i) {
    if (strlen(k_ior[i].name) == len && strncmp(k_ior[i].name, name, len) == 0) {
      *eta = kv3(k_ior[i].eta[0], k_ior[i].eta[1], k_ior[i].eta[2]);
      *k = kv3(k_ior[i].k[0], k_ior[i].k[1], k_ior[i].k[2]);
      return 1;
    }
  }
  return 0;
}

int kpcn_conductor_lookup(const char *name, kpcn_vec3 *eta, kpcn_vec3 *k) {
  if (!name) return 0;
  size_t len = strlen(name);
  if (lookup_exact(name, len, eta, k)) return 1;
  /* Tungsten lists most materials twice, "X" and "X_palik" with the same values; the twins
   * not in the table above are found by their stem. Not every stem has a twin in Tungsten
   * (its lookup is exact, so these fall back to its default there): "Au_palik" was taken as
   * gold, and "Cu_palik_palik" as "Cu_palik". */
  static const char suffix[] = "_palik";
  static const char *const no_twin[] = {"a-C", "Ag", "Al", "Au", "Cr", "W"};
  const size_t sl = sizeof(suffix) - 1;
  if (len <= sl || strcmp(name + len - sl, suffix) != 0) return 0;
  const size_t stem = len - sl;
  if (stem > sl && strncmp(name + stem - sl, suffix, sl) == 0) return 0;
  for (size_t i = 0; i < sizeof no_twin / sizeof no_twin[0]; i++)
    if (strlen(no_twin[i]) == stem && strncmp(no_twin[i], name, stem) == 0) return 0;
  return lookup_exact(name, stem, eta, k);
}
