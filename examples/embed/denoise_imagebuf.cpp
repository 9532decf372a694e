// The same through OpenImageIO: an AOV EXR as an ImageBuf, kpcn::ops::denoise as an
// ImageBufAlgo-style operation (errors on dst), the result written by OIIO.
//   denoise_imagebuf noisy.exr model.safetensors out.exr
#include <kpcn/ops_denoise.h>

#include <OpenImageIO/imagebuf.h>

#include <cstdio>

int main(int argc, char **argv) {
  if (argc != 4) {
    std::fprintf(stderr, "usage: denoise_imagebuf noisy.exr model.safetensors out.exr\n");
    return 2;
  }
  OIIO::ImageBuf aovs(argv[1]);
  kpcn::ops::DenoiseOptions opt;
  opt.model = argv[2];
  OIIO::ImageBuf out = kpcn::ops::denoise(aovs, opt);
  if (out.has_error() || !out.write(argv[3])) {
    std::fprintf(stderr, "denoise_imagebuf: %s\n", out.geterror().c_str());
    return 1;
  }
  std::printf("denoised %dx%d (%d channels) into %s\n", out.spec().width, out.spec().height,
              out.nchannels(), argv[3]);
  return 0;
}
