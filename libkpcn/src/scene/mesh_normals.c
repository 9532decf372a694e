/* Smooth vertex normals for a mesh that asks for them (recompute_normals, or smooth without
 * normals in its file), as Tungsten computes them: shading is smooth across gentle edges and
 * stays hard at creases. A corner whose face turns more than 27 degrees (0.15 pi) from the
 * first face seen at that vertex gets a vertex of its own; then every vertex sums the
 * area-weighted normals of the faces around its position that lie within 27 degrees of its
 * own face. Until session 58 all faces at a vertex index were averaged, which rounded a cube. */
#include "core/internal.h"
#include "scene/scene_internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* cos(0.15 pi): Tungsten's split limit */
#define CREASE_COS 0.891006524f

static kpcn_vec3 vpos(const float *pos, unsigned v) {
  return kv3(pos[3 * v], pos[3 * v + 1], pos[3 * v + 2]);
}

/* a vertex's position and index, sorted so that equal positions are adjacent */
typedef struct pos_key {
  float p[3];
  unsigned v;
} pos_key;

static int cmp_pos(const void *a, const void *b) {
  const pos_key *x = a, *y = b;
  const int c = memcmp(x->p, y->p, sizeof x->p);
  return c ? c : (x->v > y->v) - (x->v < y->v);
}

kpcn_status kpcn_mesh_smooth_normals(kpcn_mesh *m) {
  const size_t nv0 = (size_t)m->nverts, cap = nv0 + 3 * (size_t)m->ntris;
  float *pos = kpcn_alloc(cap * 3 * sizeof(float), "mesh positions");
  float *uv = m->uv ? kpcn_alloc(cap * 2 * sizeof(float), "mesh uvs") : NULL;
  float *nrm = kpcn_calloc(cap * 3, sizeof(float), "mesh normals");
  float *gn = kpcn_calloc(cap * 3, sizeof(float), "mesh face normals");
  pos_key *order = kpcn_alloc(cap * sizeof(pos_key), "mesh vertex order");
  unsigned *group = kpcn_alloc(cap * sizeof(unsigned), "mesh vertex groups");
  kpcn_status st = KPCN_OK;
  if (!pos || (m->uv && !uv) || !nrm || !gn || !order || !group) {
    st = KPCN_ERR_OUT_OF_MEMORY;
    goto done;
  }
  memcpy(pos, m->pos, nv0 * 3 * sizeof(float));
  if (uv) memcpy(uv, m->uv, nv0 * 2 * sizeof(float));
  size_t nv = nv0;
  /* 1. a vertex per crease: the first face at a vertex sets its normal */
  for (int t = 0; t < m->ntris; t++) {
    unsigned *id = m->idx + 3 * t;
    kpcn_vec3 n = kv3_cross(kv3_sub(vpos(pos, id[1]), vpos(pos, id[0])),
                            kv3_sub(vpos(pos, id[2]), vpos(pos, id[0])));
    n = kv3_length2(n) > 0.0f ? kv3_normalize(n) : kv3(0.0f, 1.0f, 0.0f);
    for (int k = 0; k < 3; k++) {
      float *g = gn + 3 * id[k];
      if (g[0] == 0.0f && g[1] == 0.0f && g[2] == 0.0f) {
        g[0] = n.x, g[1] = n.y, g[2] = n.z;
      } else if (g[0] * n.x + g[1] * n.y + g[2] * n.z < CREASE_COS) {
        memcpy(pos + 3 * nv, pos + 3 * id[k], 3 * sizeof(float));
        if (uv) memcpy(uv + 2 * nv, uv + 2 * id[k], 2 * sizeof(float));
        gn[3 * nv] = n.x, gn[3 * nv + 1] = n.y, gn[3 * nv + 2] = n.z;
        id[k] = (unsigned)nv++;
      }
    }
  }
  /* 2. vertices at one position form a group: order[] sorted by position, group[v] the start
   * of v's group in it */
  for (size_t i = 0; i < nv; i++) {
    memcpy(order[i].p, pos + 3 * i, sizeof order[i].p);
    order[i].v = (unsigned)i;
  }
  qsort(order, nv, sizeof *order, cmp_pos);
  for (size_t i = 0, start = 0; i < nv; i++) {
    if (i > 0 && memcmp(order[i].p, order[i - 1].p, sizeof order[i].p) != 0) start = i;
    group[order[i].v] = (unsigned)start;
  }
  /* 3. each vertex sums the area-weighted normals of the faces at its position within the
   * crease angle of its own face */
  for (int t = 0; t < m->ntris; t++) {
    const unsigned *id = m->idx + 3 * t;
    kpcn_vec3 n = kv3_cross(kv3_sub(vpos(pos, id[1]), vpos(pos, id[0])),
                            kv3_sub(vpos(pos, id[2]), vpos(pos, id[0])));
    if (!(kv3_length2(n) > 0.0f)) continue;
    const kpcn_vec3 nn = kv3_normalize(n);
    for (int k = 0; k < 3; k++)
      for (size_t j = group[id[k]];
           j < nv && memcmp(order[j].p, pos + 3 * id[k], sizeof order[j].p) == 0; j++) {
        const unsigned v = order[j].v;
        if (gn[3 * v] * nn.x + gn[3 * v + 1] * nn.y + gn[3 * v + 2] * nn.z < CREASE_COS) continue;
        nrm[3 * v] += n.x, nrm[3 * v + 1] += n.y, nrm[3 * v + 2] += n.z;
      }
  }
  for (size_t v = 0; v < nv; v++) {
    kpcn_vec3 s = kv3(nrm[3 * v], nrm[3 * v + 1], nrm[3 * v + 2]);
    s = kv3_length2(s) > 0.0f ? kv3_normalize(s) : kv3(gn[3 * v], gn[3 * v + 1], gn[3 * v + 2]);
    nrm[3 * v] = s.x, nrm[3 * v + 1] = s.y, nrm[3 * v + 2] = s.z;
  }
  free(m->pos), free(m->uv), free(m->nrm);
  m->pos = pos, m->uv = uv, m->nrm = nrm, m->nverts = (int)nv;
  pos = uv = nrm = NULL;
done:
  free(pos), free(uv), free(nrm), free(gn), free(order), free(group);
  return st;
}
