/* Mesh files: Tungsten's binary .wo3 natively, everything else assimp reads (.obj, .ply,
 * .gltf, .glb, ...) through its C API.
 *
 * .wo3 layout (little-endian, learnt from Tungsten's MeshIO): uint64 vertex count, then per
 * vertex 8 float32 (position xyz, normal xyz, uv), uint64 triangle count, then per triangle
 * 3 uint32 vertex indices + 1 int32 material index (ignored). */
#include "core/internal.h"
#include "scene/scene_internal.h"

#include <assimp/cimport.h>
#include <assimp/postprocess.h>
#include <assimp/scene.h>
#include <errno.h>
#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

void kpcn_mesh_free(kpcn_mesh *m) {
  free(m->pos);
  free(m->nrm);
  free(m->uv);
  free(m->idx);
  kpcn_distrib1d_free(&m->area_cdf);
  memset(m, 0, sizeof(*m));
}

static kpcn_status alloc_mesh(kpcn_mesh *m, uint64_t nv, uint64_t nt, int with_nrm, int with_uv,
                              const char *path) {
  if (nv == 0 || nt == 0 || nv > (1u << 28) || nt > (1u << 28))
    return kpcn_fail(KPCN_ERR_FORMAT,
                     "mesh '%s': absurd or empty counts (%llu vertices, %llu triangles)", path,
                     (unsigned long long)nv, (unsigned long long)nt);
  m->nverts = (int)nv;
  m->ntris = (int)nt;
  m->pos = kpcn_alloc(nv * 3 * sizeof(float), "mesh positions");
  m->idx = kpcn_alloc(nt * 3 * sizeof(unsigned), "mesh indices");
  if (with_nrm) m->nrm = kpcn_alloc(nv * 3 * sizeof(float), "mesh normals");
  if (with_uv) m->uv = kpcn_alloc(nv * 2 * sizeof(float), "mesh uvs");
  if (!m->pos || !m->idx || (with_nrm && !m->nrm) || (with_uv && !m->uv))
    return KPCN_ERR_OUT_OF_MEMORY;
  return KPCN_OK;
}

static kpcn_status load_wo3(const char *path, const char *jp, kpcn_mesh *m) {
  const char *why;
  FILE *f = kpcn_fopen_input(path, &why);
  if (!f) return kpcn_fail(KPCN_ERR_IO, "%s: cannot open mesh '%s': %s", jp, path, why);
  kpcn_status st = KPCN_OK;
  uint64_t nv = 0, nt = 0;
  float *vbuf = NULL;
  uint32_t *tbuf = NULL;
  fseek(f, 0, SEEK_END);
  long fsize = ftell(f);
  fseek(f, 0, SEEK_SET);
  if (fread(&nv, 8, 1, f) != 1 || nv == 0 || (uint64_t)fsize < 16 + nv * 32) {
    st = kpcn_fail(KPCN_ERR_FORMAT, "%s: mesh '%s' is truncated or not a .wo3 file", jp, path);
    goto done;
  }
  vbuf = malloc(nv * 32);
  if (!vbuf || fread(vbuf, 32, nv, f) != nv || fread(&nt, 8, 1, f) != 1 ||
      (uint64_t)fsize != 16 + nv * 32 + nt * 16) {
    st = kpcn_fail(KPCN_ERR_FORMAT, "%s: mesh '%s' is truncated or not a .wo3 file", jp, path);
    goto done;
  }
  if ((st = alloc_mesh(m, nv, nt, 1, 1, path)) != KPCN_OK) goto done;
  tbuf = malloc(nt * 16);
  if (!tbuf || fread(tbuf, 16, nt, f) != nt) {
    st = kpcn_fail(KPCN_ERR_FORMAT, "%s: mesh '%s' is truncated", jp, path);
    goto done;
  }
  for (uint64_t i = 0; i < nv; i++) {
    memcpy(m->pos + 3 * i, vbuf + 8 * i, 12);
    memcpy(m->nrm + 3 * i, vbuf + 8 * i + 3, 12);
    memcpy(m->uv + 2 * i, vbuf + 8 * i + 6, 8);
  }
  for (uint64_t i = 0; i < nt; i++)
    for (int k = 0; k < 3; k++) {
      if (tbuf[4 * i + k] >= nv) {
        st = kpcn_fail(KPCN_ERR_FORMAT, "%s: mesh '%s': triangle %llu refers to vertex %u of %llu",
                       jp, path, (unsigned long long)i, tbuf[4 * i + k], (unsigned long long)nv);
        goto done;
      }
      m->idx[3 * i + k] = tbuf[4 * i + k];
    }
done:
  free(vbuf);
  free(tbuf);
  fclose(f);
  return st;
}

static kpcn_status load_assimp(const char *path, const char *jp, kpcn_mesh *m) {
  const char *why;
  FILE *probe = kpcn_fopen_input(path, &why);
  if (!probe) return kpcn_fail(KPCN_ERR_IO, "%s: cannot open mesh '%s': %s", jp, path, why);
  fclose(probe);
  /* assimp's aiGetErrorString() is one process-wide string every failed import writes
   * without a lock: import and read it under a lock of our own, so scenes loaded on several
   * threads each report their own mesh's reason */
  static pthread_mutex_t assimp_lock = PTHREAD_MUTEX_INITIALIZER;
  char reason[512] = "";
  pthread_mutex_lock(&assimp_lock);
  const struct aiScene *sc =
      aiImportFile(path, aiProcess_Triangulate | aiProcess_JoinIdenticalVertices |
                             aiProcess_PreTransformVertices | aiProcess_SortByPType);
  if (!sc) snprintf(reason, sizeof reason, "%s", aiGetErrorString());
  pthread_mutex_unlock(&assimp_lock);
  if (!sc) return kpcn_fail(KPCN_ERR_FORMAT, "%s: cannot read mesh '%s': %s", jp, path, reason);
  uint64_t nv = 0, nt = 0;
  int all_nrm = 1, all_uv = 1;
  for (unsigned i = 0; i < sc->mNumMeshes; i++) {
    const struct aiMesh *am = sc->mMeshes[i];
    if (!(am->mPrimitiveTypes & aiPrimitiveType_TRIANGLE)) continue;
    nv += am->mNumVertices;
    for (unsigned fi = 0; fi < am->mNumFaces; fi++)
      nt += am->mFaces[fi].mNumIndices == 3;
    all_nrm &= am->mNormals != NULL;
    all_uv &= am->mTextureCoords[0] != NULL;
  }
  kpcn_status st;
  if (nt == 0) {
    st = kpcn_fail(KPCN_ERR_FORMAT, "%s: mesh '%s' contains no triangles", jp, path);
    goto done;
  }
  if ((st = alloc_mesh(m, nv, nt, all_nrm, all_uv, path)) != KPCN_OK) goto done;
  uint64_t vo = 0, to = 0;
  for (unsigned i = 0; i < sc->mNumMeshes; i++) {
    const struct aiMesh *am = sc->mMeshes[i];
    if (!(am->mPrimitiveTypes & aiPrimitiveType_TRIANGLE)) continue;
    for (unsigned v = 0; v < am->mNumVertices; v++) {
      m->pos[3 * (vo + v) + 0] = am->mVertices[v].x;
      m->pos[3 * (vo + v) + 1] = am->mVertices[v].y;
      m->pos[3 * (vo + v) + 2] = am->mVertices[v].z;
      if (all_nrm) {
        m->nrm[3 * (vo + v) + 0] = am->mNormals[v].x;
        m->nrm[3 * (vo + v) + 1] = am->mNormals[v].y;
        m->nrm[3 * (vo + v) + 2] = am->mNormals[v].z;
      }
      if (all_uv) {
        m->uv[2 * (vo + v) + 0] = am->mTextureCoords[0][v].x;
        m->uv[2 * (vo + v) + 1] = am->mTextureCoords[0][v].y;
      }
    }
    for (unsigned fi = 0; fi < am->mNumFaces; fi++) {
      if (am->mFaces[fi].mNumIndices != 3) continue;
      for (int k = 0; k < 3; k++)
        m->idx[3 * to + k] = (unsigned)(vo + am->mFaces[fi].mIndices[k]);
      to++;
    }
    vo += am->mNumVertices;
  }
  st = KPCN_OK;
done:
  aiReleaseImport(sc);
  return st;
}

kpcn_status kpcn_mesh_load(const char *path, const char *jp, kpcn_mesh *m) {
  memset(m, 0, sizeof(*m));
  const char *dot = strrchr(path, '.');
  kpcn_status st;
  if (dot && strcasecmp(dot, ".wo3") == 0)
    st = load_wo3(path, jp, m);
  else if (dot && (strcasecmp(dot, ".obj") == 0 || strcasecmp(dot, ".ply") == 0 ||
                   strcasecmp(dot, ".gltf") == 0 || strcasecmp(dot, ".glb") == 0 ||
                   strcasecmp(dot, ".fbx") == 0 || strcasecmp(dot, ".dae") == 0))
    st = load_assimp(path, jp, m);
  else
    st = kpcn_fail(KPCN_ERR_UNSUPPORTED,
                   "%s: unsupported mesh format '%s' (wo3, obj, ply, gltf, glb, fbx, dae)", jp,
                   path);
  if (st == KPCN_OK) {
    for (int i = 0; i < 3 * m->nverts; i++)
      if (!isfinite(m->pos[i])) {
        st = kpcn_fail(KPCN_ERR_NONFINITE, "%s: mesh '%s' has non-finite vertex positions", jp,
                       path);
        break;
      }
  }
  if (st != KPCN_OK) kpcn_mesh_free(m);
  return st;
}
