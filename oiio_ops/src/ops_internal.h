// Helpers shared by the ImageBuf ops' sources (not installed).
#pragma once

#include <OpenImageIO/imagebuf.h>

namespace kpcn {
namespace ops {

// A caller's ROI must hold pixels: true (with the error on dst) for a defined ROI that is
// empty, inverted or not one slice deep. An empty one was "accepted" (dst came back
// uninitialised with a true return; render's all-zero window meant the whole image).
bool empty_roi(OIIO::ImageBuf &dst, OIIO::ROI roi, const char *what);

} // namespace ops
} // namespace kpcn
