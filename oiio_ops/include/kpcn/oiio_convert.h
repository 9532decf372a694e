// kpcn/oiio_convert.h — conversions between OIIO::ImageBuf and libkpcn's planar images.
//
// Every op family in oiio_ops (metrics, denoise, augment ...) is a thin adapter: convert the
// ImageBuf to a kpcn_image / kpcn_aov_set, call the C core, convert back. These helpers are
// that shared glue.
//
// Conventions
//  - Channels are matched by NAME (the ImageSpec channelnames), never by position, except
//    where a function says otherwise.
//  - Pixel data is always converted to float (any source format OIIO can read).
//  - kpcn_image / kpcn_aov_set are owned through the unique_ptr aliases below; pass
//    `.get()` to the C API.
//  - Failures return an empty pointer / false and put a message naming the problem
//    (channel, size) in `err`; the ImageBuf-returning forms set dst.errorfmt(...) instead,
//    as ImageBufAlgo does.
//  - AOV metadata travels as ImageSpec attributes "kpcn:spp" (int), "kpcn:seed" (int64 stored
//    as string when it does not fit an int), "kpcn:albedoSpp" and "kpcn:albedoFootprint" (int),
//    "kpcn:scene" and "kpcn:version" (strings).
//  - A ROI must lie inside the source's data window (an error otherwise: OIIO would fill the
//    outside with zeros).
#pragma once

#include <OpenImageIO/imagebuf.h>

#include <memory>
#include <string>
#include <vector>

#include "kpcn/image.h"

namespace kpcn {

struct ImageDeleter {
  void operator()(kpcn_image *p) const { kpcn_image_destroy(p); }
};
struct AovDeleter {
  void operator()(kpcn_aov_set *p) const { kpcn_aov_destroy(p); }
};
using ImagePtr = std::unique_ptr<kpcn_image, ImageDeleter>;
using AovPtr = std::unique_ptr<kpcn_aov_set, AovDeleter>;

namespace ops {

// ImageBuf -> planar kpcn_image. `roi` (default: src's data window, all channels) selects
// pixels and the channel range [roi.chbegin, roi.chend). Channel names come from the spec.
// Reads the pixels (forcing a read of a file-backed ImageBuf). Fails on zero/absurd sizes.
ImagePtr to_kpcn_image(const OIIO::ImageBuf &src, std::string &err, OIIO::ROI roi = {});

// ImageBuf -> kpcn_image holding only the named channels, in the order given.
// Fails naming the first channel that src lacks.
ImagePtr to_kpcn_image(const OIIO::ImageBuf &src, const std::vector<std::string> &channels,
                       std::string &err, OIIO::ROI roi = {});

// kpcn_image -> float ImageBuf (origin 0,0, channel names copied). Returns false and sets
// dst.errorfmt on failure.
bool from_kpcn_image(OIIO::ImageBuf &dst, const kpcn_image &img);
OIIO::ImageBuf from_kpcn_image(const kpcn_image &img);

// ImageBuf -> AOV set: channels recognised by canonical name or alias (kpcn_aov_from_image),
// metadata from the kpcn:* attributes. Unknown channels are ignored.
AovPtr to_aov_set(const OIIO::ImageBuf &src, std::string &err);

// AOV set -> float ImageBuf with canonical channel names (only the buffers present, in the
// order kpcn_aov_to_image gives them) and the kpcn:* attributes set.
bool from_aov_set(OIIO::ImageBuf &dst, const kpcn_aov_set &set);
OIIO::ImageBuf from_aov_set(const kpcn_aov_set &set);

// Index of the channel named `name` in spec, or -1 (thin wrapper kept for symmetry).
int channel_index(const OIIO::ImageSpec &spec, const std::string &name);

// Splits "R,G,B" into {"R","G","B"} (empty items dropped).
std::vector<std::string> split_names(const std::string &list, char sep = ',');

} // namespace ops
} // namespace kpcn
