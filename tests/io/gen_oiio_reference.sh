#!/bin/sh
# Regenerates testdata/io/ from the Tungsten render with OpenImageIO's tools (an EXR reader
# independent of kpcn's): recorded pixel values/statistics, plus small tiled, offset-window
# and half files written by OIIO. Run from the repository root:  sh tests/io/gen_oiio_reference.sh
set -eu
SRC=${1:-testdata/tungsten-cornell/noisy_16spp.exr}
OUT=testdata/io
mkdir -p "$OUT"
REC="$OUT/cornell_noisy_oiio.txt"
{
  echo "# Recorded with OpenImageIO $(oiiotool --version 2>/dev/null | head -1) from $SRC"
  echo "# commands:"
  echo "#   iinfo -v $SRC"
  echo "#   oiiotool $SRC --cut 3x2+100+120 -o crop.exr && oiiotool --dumpdata crop.exr   (pixel x,y relative to 100,120)"
  echo "#   oiiotool $SRC --cut 2x2+0+0 ... --dumpdata ; --cut 2x2+254+254 ..."
  echo "#   oiiotool --stats $SRC"
  iinfo -v "$SRC"
  for g in 3x2+100+120 2x2+0+0 2x2+254+254; do
    oiiotool "$SRC" --cut $g -o /tmp/kpcn_gen_crop.exr
    echo "crop $g"
    oiiotool --dumpdata /tmp/kpcn_gen_crop.exr | grep Pixel
  done
  oiiotool --stats "$SRC" | grep Stats
} > "$REC"
rm -f /tmp/kpcn_gen_crop.exr
# 37x23 region at (100,120): tiled 16x16, scanline with data window at (+3,+7), half.
oiiotool "$SRC" --cut 37x23+100+120 --tile 16 16 --compression zip -o "$OUT/crop_tiled.exr"
oiiotool "$SRC" --cut 37x23+100+120 --origin +3+7 --fullsize 50x40+0+0 --compression piz -o "$OUT/crop_offset.exr"
oiiotool "$SRC" --cut 37x23+100+120 -d half --compression zip -o "$OUT/crop_half.exr"
# 8x8 files in codecs OpenEXR Core 3.1 read wrongly or not at all (session 58; B44 read right since
# session 61), and one it reads
oiiotool "$SRC" --cut 8x8+100+120 --ch R,G -d float --compression b44 -o "$OUT/b44_float2.exr"
oiiotool "$SRC" --cut 8x8+100+120 --ch R,G,B -d half --compression b44 -o "$OUT/b44_half.exr"
# a B44 half file whose last chunk (one row of 8 pixels) the writer stored raw (session 61)
oiiotool "$SRC" --cut 8x33+100+120 --ch R,G,B -d half --compression b44 -o "$OUT/b44_lastrow.exr"
oiiotool "$SRC" --cut 8x8+100+120 --ch R,G,B -d half --compression dwaa -o "$OUT/dwaa.exr"
# uint channels: kpcn keeps the integer value (session 61)
oiiotool --pattern constant:color=0.5,0.25,1 3x2 3 -d uint32 -o "$OUT/uint32.exr"
echo "wrote $REC, $OUT/crop_*.exr and the codec files"
