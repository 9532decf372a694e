/* Patch-store internals shared by the writer and the reader (format in kpcn/dataset.h). */
#ifndef KPCN_DATASET_PS_INTERNAL_H
#define KPCN_DATASET_PS_INTERNAL_H

#include "kpcn/dataset.h"

#define KPS_MAGIC "KPCNPS\0\1"
#define KPS_HEADER_BYTES 64
#define KPS_RECORD_BYTES 32

typedef struct kps_header {
  char magic[8];
  uint32_t version;
  uint32_t dtype;
  uint32_t patch_size;
  uint32_t nchannels;
  uint64_t count;
  uint64_t patch_bytes;
  uint64_t index_offset;
  uint64_t meta_offset;
  uint64_t meta_length;
} kps_header;

/* Little-endian (de)serialisation of the fixed header and index records, independent of
 * the host's struct layout and byte order. */
void kps_put_header(unsigned char out[KPS_HEADER_BYTES], const kps_header *h);
void kps_get_header(kps_header *h, const unsigned char in[KPS_HEADER_BYTES]);
void kps_put_record(unsigned char out[KPS_RECORD_BYTES], const kpcn_patch_record *r);
void kps_get_record(kpcn_patch_record *r, const unsigned char in[KPS_RECORD_BYTES]);
size_t kps_dtype_size(uint32_t dtype);

#endif
