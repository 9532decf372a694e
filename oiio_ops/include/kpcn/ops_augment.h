// kpcn/ops_augment.h — post-render augmentation and patch extraction as ImageBufAlgo-style
// operations (DESIGN.md §6, §8). Thin adapters over libkpcn's augment module
// (kpcn/augment.h holds the exact semantics and the sign conventions).
//
// Channel roles come from channel names, so any ImageBuf works: every "<p>R <p>G <p>B"
// triple is colour (permuted by colorswap), "<p>N.X <p>N.Y" are camera-space normals
// (negated by mirrors, rotated by rotations), everything else only moves. Header metadata
// (kpcn:spp, kpcn:seed, ...) is kept, also when dst is src. These act on the whole data
// window (no ROI: an augmentation of part of an image would misalign it with its reference).
// Mirrors and quarter turns act on the whole frame (full window), as oiiotool's --flop, --flip
// and --rotate90 do: a crop's data window moves inside the transformed frame; colour swaps,
// shifts (wrapping inside the pixels) and other angles keep it. The result is float whatever
// the source's pixel type (libkpcn works in float; unlike IBA::flop, a half image comes back
// float). Errors are reported on dst (dst.geterror()).
//
//   ImageBuf out = kpcn::ops::rotate(src, 90);          // exact quarter turn
//   kpcn::ops::colorswap(dst, src, "BRG");
//   kpcn_augment_xform x; kpcn_augment_draw(&x, &ds, seed, i);   // one draw ...
//   kpcn::ops::augment(n2, noisy, x); kpcn::ops::augment(r2, ref, x);  // ... for the pair
#pragma once

#include <OpenImageIO/imagebuf.h>

#include <string>
#include <vector>

#include "kpcn/augment.h"

namespace kpcn {
namespace ops {

// Applies one exact transform (colour permutation, mirrors, quarter turns, wrap shift).
bool augment(OIIO::ImageBuf &dst, const OIIO::ImageBuf &src, const kpcn_augment_xform &x,
             int nthreads = 0);
OIIO::ImageBuf augment(const OIIO::ImageBuf &src, const kpcn_augment_xform &x, int nthreads = 0);

// vertical=false: left-right (N.X negated); true: top-bottom (N.Y negated).
bool mirror(OIIO::ImageBuf &dst, const OIIO::ImageBuf &src, bool vertical = false,
            int nthreads = 0);
OIIO::ImageBuf mirror(const OIIO::ImageBuf &src, bool vertical = false, int nthreads = 0);

// Counter-clockwise degrees on screen. Multiples of 90 are exact; any other angle
// resamples bilinearly (same size, outside = 0), which ALTERS THE NOISE STATISTICS;
// ".var" channels are propagated as sum(w^2 var).
bool rotate(OIIO::ImageBuf &dst, const OIIO::ImageBuf &src, double degrees, int nthreads = 0);
OIIO::ImageBuf rotate(const OIIO::ImageBuf &src, double degrees, int nthreads = 0);

// perm: "BRG" etc. (new R = old B, new G = old R, new B = old G).
bool colorswap(OIIO::ImageBuf &dst, const OIIO::ImageBuf &src, const std::string &perm,
               int nthreads = 0);
OIIO::ImageBuf colorswap(const OIIO::ImageBuf &src, const std::string &perm, int nthreads = 0);

// Wrap-around translation by (dx, dy) pixels (x right, y down); size unchanged.
bool shift(OIIO::ImageBuf &dst, const OIIO::ImageBuf &src, int dx, int dy, int nthreads = 0);
OIIO::ImageBuf shift(const OIIO::ImageBuf &src, int dx, int dy, int nthreads = 0);

// Patch origins in noisy, relative to its data window's corner (culling on ref's colour when
// ref is given, else on noisy's). Only an empty ImageBuf is no reference: one whose file
// failed to open is an error, and a reference must cover the same pixels (size and data
// window). Returns false and sets err on failure.
bool select_patches(const OIIO::ImageBuf &noisy, const OIIO::ImageBuf &ref,
                    const kpcn_patch_settings &s, std::vector<kpcn_patch_origin> &out,
                    kpcn_patch_stats &stats, std::string &err);

// Writes the selected patches: `out` ending in ".kps" -> a patch store (the default
// channel list of kpcn/dataset.h: noisy needs every AOV, ref color/diffuse/specular);
// otherwise a directory receiving noisy_NNNN.exr (+ ref_NNNN.exr) with all channels (a store
// needs ref; both refuse a ref as select_patches does, before anything is written). A store
// records `stats` (the selection's candidates, kept, culled; none when null) and
// `settings_json` (a JSON object, e.g. the selection's settings) in its metadata.
bool write_patches(const std::string &out, const OIIO::ImageBuf &noisy, const OIIO::ImageBuf &ref,
                   const std::vector<kpcn_patch_origin> &origins, int size, std::string &err,
                   const kpcn_patch_stats *stats = nullptr, const std::string &settings_json = "");

} // namespace ops
} // namespace kpcn
