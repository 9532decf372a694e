# Three documented promises that had no test (docs/robustness.md, "Still untested"):
#  1. kpcntool's exit status per error class, as the table in docs/kpcntool.md ("Errors and
#     exit status") gives it: 1 for each runtime error, 2 for each usage error, the message
#     starting with "kpcntool: error:", no output and no temporary left; kpcn-render's 1 / 2
#     (docs/renderer.md: "exit code 1 (2 for usage)").
#  2. The default render seed is 1: kpcn-render without --seed renders the pixels of --seed 1
#     (docs/renderer.md), and so does kpcntool's --render without seed= (kpcntool.md).
#  3. On a full disk (a 12 KB tmpfs) an image written in any format fails with exit 1, a
#     "kpcntool: error:" line and nothing left (kpcntool.md: every image other than EXR is read
#     back, as OIIO's PNG writer reports success on a full disk); kpcn-render's EXR too. Needs
#     unshare + mount (root, or a user namespace): where they are not permitted this part is
#     skipped and the script exits 77 (SKIP_RETURN_CODE) if everything else passed.
# usage: bash cli_exitcodes.sh KPCNTOOL KPCN_RENDER TESTDATA WORKDIR
# (absolute paths: lib.sh changes to the work folder)
KR=$(realpath "$2") || exit 1
set -- "$(realpath "$1")" "$(realpath "$3")" "$4"
. "$(dirname "$0")/lib.sh"
# Under ASan (CI) a leak's stack is unwound in full: the image libraries' error paths this
# script drives (libpng's longjmp through OpenImageIO on a failed read-back; x265 inside
# libheif) allocate in code without frame pointers, where the fast unwinder stops before the
# OpenImageIO frame that .ci/lsan.supp names, so their one-off leaks were reported as ours.
[ -n "${ASAN_OPTIONS:-}" ] && export ASAN_OPTIONS="$ASAN_OPTIONS:fast_unwind_on_malloc=0"
export LC_ALL=C
SKIP=77
SCENE=$TD/scenes/cornell-box/scene.json
MODEL=$TD/models/kpcn-cpu.safetensors

# no_leftovers WHAT OUT: OUT (if non-empty) and any temporary in the work folder are absent;
# a leftover is reported and removed so that it does not fail the checks after it.
no_leftovers() {
  local what=$1 out=$2 ok=0 tmps
  if [ -n "$out" ] && { [ -e "$out" ] || [ -L "$out" ]; }; then
    fail "$what: output '$out' left behind"
    rm -rf "$out"
    ok=1
  fi
  tmps=$(ls -A | grep '\.tmp')
  if [ -n "$tmps" ]; then
    fail "$what: temporary file(s) left: $tmps"
    rm -rf $tmps
    ok=1
  fi
  return $ok
}

# expect_code CODE PATTERN OUTFILE ARGS...: kpcntool must exit with exactly CODE, the first
# line of its stderr must start with "kpcntool: error: " (with LIBMSG=1: a line, after an image
# library's own) and the stderr contain PATTERN, and neither OUTFILE (if non-empty) nor a
# temporary file may be left. FSIZE=N: run with writes beyond N KB failing (ulimit -f).
expect_code() {
  local want=$1 pat=$2 out=$3 first
  shift 3
  if [ -n "$out" ] && [ -e "$out" ]; then
    fail "test bug: '$out' exists before: kpcntool $*"
    return
  fi
  if [ -n "${FSIZE:-}" ]; then
    (trap '' XFSZ; ulimit -f "$FSIZE"; exec "$KT" "$@") >out.txt 2>err.txt
  else
    "$KT" "$@" >out.txt 2>err.txt
  fi
  local rc=$?
  IFS= read -r first <err.txt
  [ -n "${LIBMSG:-}" ] && first=$(grep -m1 '^kpcntool: error: ' err.txt)
  if [ $rc -ne "$want" ]; then
    fail "exit $rc, expected $want: kpcntool $*: $(head -c 400 err.txt)"
  elif [ "${first#kpcntool: error: }" = "$first" ]; then
    fail "kpcntool $*: stderr does not start with 'kpcntool: error: ': $(head -c 400 err.txt)"
  elif ! grep -qF -- "$pat" err.txt; then
    fail "kpcntool $*: message lacks '$pat': $(head -c 400 err.txt)"
  elif no_leftovers "kpcntool $*" "$out"; then
    pass "exit $want naming '$pat': kpcntool $*"
  fi
}
# expect_render_code CODE PATTERN ARGS...: the same for kpcn-render ("kpcn-render: " or, with
# no output named, its usage text); its output is always o.exr.
expect_render_code() {
  local want=$1 pat=$2
  shift 2
  "$KR" "$@" >out.txt 2>err.txt
  local rc=$?
  if [ $rc -ne "$want" ]; then
    fail "exit $rc, expected $want: kpcn-render $*: $(head -c 400 err.txt)"
  elif ! grep -qF -- "$pat" err.txt; then
    fail "kpcn-render $*: message lacks '$pat': $(head -c 400 err.txt)"
  elif no_leftovers "kpcn-render $*" o.exr; then
    pass "exit $want naming '$pat': kpcn-render $*"
  fi
}

# --- inputs -----------------------------------------------------------------------------------
oiiotool --pattern constant:color=0.5,0.5,0.5 16x16 3 -o grey.exr
oiiotool --pattern constant:color=0.5,0.5,0.5 8x8 3 -o grey8.exr
# 32 Inf pixels in a 16x16 image (NaN/Inf in compared images)
oiiotool --pattern constant:color=inf,0.5,0.5 8x4 3 --pattern constant:color=0.5,0.5,0.5 16x16 3 \
  --paste +0+0 -o inf.exr
# 256x256 uniform noise: no format compresses it below 12 KB (part 3)
oiiotool --pattern noise:type=uniform:min=0:max=1 256x256 3 -d float -o noise.exr
head -c 100000 noise.exr >truncated.exr
cp noise.exr corrupt.exr
head -c 20000 /dev/zero | tr '\0' 'X' | dd of=corrupt.exr bs=1 seek=300000 conv=notrunc 2>/dev/null
echo "not an image" >garbage.exr
oiiotool --create 70000x1 1 -o wide.exr
mkdir adir.exr
mkfifo fifo.exr
ln -s /dev/null null.exr
cp "$MODEL" model.exr
cp "$SCENE" scene.exr
echo "garbage: [" >bad.ocio
# a header of 16385x16385 pixels (> 2^28) without its pixels: refused on the size alone
$PY -c '
import OpenImageIO as oiio
o = oiio.ImageOutput.create("big.exr")
assert o.open("big.exr", oiio.ImageSpec(16385, 16385, 1, oiio.HALF))
o.close()' || fail "cannot make big.exr"
# a 16x16 AOV image (the render of part 2) with one NaN in R: an image to denoise
"$KR" "$SCENE" -o aov.exr --resolution 16x16 --spp 2 --quiet || fail "kpcn-render aov.exr"
$PY -c '
import OpenImageIO as oiio
src = oiio.ImageBuf("aov.exr")
px = src.get_pixels(oiio.FLOAT)
spec = src.spec().copy()
spec.tile_width = spec.tile_height = spec.tile_depth = 0  # (OIIO 2.4 crashes setting pixels of a tiled file)
px[7, 5, list(spec.channelnames).index("R")] = float("nan")
b = oiio.ImageBuf(spec)
assert b.set_pixels(b.roi, px) and b.write("nanaov.exr", oiio.FLOAT)' || fail "cannot make nanaov.exr"

# --- 1. kpcntool: exit 1, runtime errors ---------------------------------------------------------
# unreadable / truncated / corrupt file
expect_code 1 "cannot open 'missing.exr': No such file or directory" out.exr grey.exr -o out.exr missing.exr
expect_code 1 "cannot open 'adir.exr': is a directory" out.exr grey.exr -o out.exr adir.exr
expect_code 1 "cannot read 'truncated.exr'" out.exr grey.exr -o out.exr truncated.exr
expect_code 1 "cannot read 'corrupt.exr' (truncated or corrupt?)" out.exr grey.exr -o out.exr corrupt.exr
expect_code 1 "garbage.exr" out.exr grey.exr -o out.exr garbage.exr
# absurd size: > 65536 per side, > 2^28 pixels
expect_code 1 "'wide.exr' has an unsupported or absurd size 70000x1" out.exr grey.exr -o out.exr wide.exr
expect_code 1 "'big.exr' has an unsupported or absurd size 16385x16385" out.exr grey.exr -o out.exr big.exr
# images of different sizes
expect_code 1 "image sizes differ ('grey.exr' is 16x16, 'grey8.exr' is 8x8)" out.exr \
  grey.exr -o out.exr grey8.exr --l1
# missing channel
expect_code 1 "has no channel 'Q'" out.exr grey.exr -o out.exr grey.exr --relmse:channels=R,Q
# channel counts that do not match
expect_code 1 "channel counts differ (test image 1, reference 3)" out.exr grey.exr -o out.exr \
  --ch R grey.exr --l1
# NaN/Inf in compared images, in an image to denoise
expect_code 1 "32 pixel(s) hold NaN/Inf in 'inf.exr' or 'grey.exr'" out.exr inf.exr grey.exr \
  -o out.exr --l1
expect_code 1 "non-finite value(s) (NaN/Inf)" out.exr nanaov.exr -o out.exr \
  --denoise:model="$MODEL"
# too few images on the stack
expect_code 1 "needs two images on the stack" out.exr grey.exr -o out.exr --ssim
expect_code 1 "the image stack is empty" "" --info
# bad modifier value
expect_code 1 "modifier 'range' needs a finite number (got 'abc')" out.exr grey.exr -o out.exr \
  grey.exr --psnr:range=abc
expect_code 1 "modifier 'allow_nonfinite' must be 0 or 1 (got 'maybe')" out.exr grey.exr \
  -o out.exr grey.exr --l1:allow_nonfinite=maybe
expect_code 1 "modifier 'seed' needs an integer in [0, 2^63-1] (got '-1')" out.exr --render:res=8x8:spp=1:seed=-1 "$SCENE" -o out.exr
# unknown OCIO display / view / config (missing, unreadable; by config= and by $OCIO)
expect_code 1 "display 'P3' is not in OCIO config" out.png grey.exr --ociodisplay:display=P3 -o out.png
expect_code 1 "view 'Nope' of display 'sRGB' is not in OCIO config" out.png grey.exr \
  --ociodisplay:view=Nope -o out.png
expect_code 1 "OCIO config 'none.ocio' not found" out.png grey.exr --ociodisplay:config=none.ocio -o out.png
expect_code 1 "OCIO config 'bad.ocio'" out.png grey.exr --ociodisplay:config=bad.ocio -o out.png
OCIO=$PWD/none.ocio expect_code 1 "OCIO config '$PWD/none.ocio' not found" out.png grey.exr \
  --ociodisplay -o out.png
# write failure: writes beyond 8 KB fail (EFBIG, RLIMIT_FSIZE; the full disk: part 3), also
# of a later output: the earlier one is not left either
FSIZE=8 expect_code 1 "-o a.exr: cannot write 'a.exr'" a.exr noise.exr -o a.exr
FSIZE=8 LIBMSG=1 expect_code 1 "-o a.png: cannot write 'a.png'" a.png noise.exr -o a.png
FSIZE=8 expect_code 1 "-o a.exr: cannot write 'a.exr'" out.exr grey.exr -o out.exr noise.exr -o a.exr
[ -e a.exr ] && fail "a.exr left" && rm -f a.exr

# --- 1. kpcntool: exit 2, usage errors (found before anything is read or written) ---------------
# unknown command or modifier
expect_code 2 "unknown command '--bogus'" out.exr grey.exr -o out.exr --bogus
expect_code 2 "malformed command '--'" out.exr grey.exr -o out.exr --
expect_code 2 "unknown modifier 'foo' for --l1" out.exr grey.exr grey.exr --l1:foo=1 -o out.exr
# modifier without value, given twice
expect_code 2 "modifier 'display' of --l1 needs a value" out.exr grey.exr grey.exr --l1:display -o out.exr
expect_code 2 "modifier 'range' of --l1 is given twice" out.exr grey.exr grey.exr \
  --l1:range=2:range=1 -o out.exr
# missing argument
expect_code 2 "command '-o' needs 1 argument" "" grey.exr -o
expect_code 2 "command '--render:res=8x8' needs 1 argument" "" --render:res=8x8
# an -o name with no writable format
expect_code 2 "'outfile' has no file extension" outfile grey.exr -o outfile
expect_code 2 "no image format writes '.xyz' files" out.exr grey.exr -o out.exr -o out.xyz
# an -o whose folder is missing, that is a directory, a FIFO or a device
expect_code 2 "-o 'nodir/out.exr': folder 'nodir': No such file or directory" out.exr grey.exr \
  -o out.exr -o nodir/out.exr
expect_code 2 "out= 'nodir/p.kps': folder 'nodir'" out.exr grey.exr -o out.exr grey.exr \
  --patches:size=4:count=1:out=nodir/p.kps
# a --patches:out= folder of EXR pairs too, before anything runs (checked only when written,
# with exit 1, until session 62): its parent missing, or a path that is no directory
expect_code 2 "out= 'nodir/sub': folder 'nodir'" out.exr grey.exr -o out.exr grey.exr \
  --patches:size=4:count=1:out=nodir/sub
expect_code 2 "out= '/dev/null' exists and is not a directory" out.exr grey.exr -o out.exr grey.exr \
  --patches:size=4:count=1:out=/dev/null
expect_code 2 "out= 'grey.exr' exists and is not a directory" out.exr grey.exr -o out.exr grey.exr \
  --patches:size=4:count=1:out=grey.exr
# a command's error repeats it with its arguments: the -o file is named
expect_code 1 "kpcntool: error: -o x.png: the image has 5 channels and .png files hold at most 4" x.png \
  grey.exr --ch R,G,B,A=1,Z=0 -o x.png
# an empty value is a bad value, not the default (--colormap:max= was the 99th percentile)
expect_code 1 "modifier 'max' needs a finite number (got '')" x.png grey.exr --colormap:max= -o x.png
expect_code 2 "-o 'adir.exr' is a directory" out.exr grey.exr -o out.exr -o adir.exr
[ -d adir.exr ] && [ -z "$(ls -A adir.exr)" ] || fail "adir.exr changed: $(ls -la adir.exr)"
expect_code 2 "-o 'fifo.exr' is not a regular file (a FIFO, device or socket)" out.exr grey.exr \
  -o out.exr -o fifo.exr
[ -p fifo.exr ] || fail "fifo.exr is no longer a FIFO"
expect_code 2 "-o 'null.exr' is not a regular file (a FIFO, device or socket)" out.exr grey.exr \
  -o out.exr -o null.exr
[ -L null.exr ] && [ -c /dev/null ] || fail "null.exr or /dev/null changed"
# an -o that names a model or a scene a step reads
expect_code 2 "-o 'model.exr' is the same file as model 'model.exr'" "" aov.exr \
  --denoise:model=model.exr -o model.exr
cmp -s "$MODEL" model.exr || fail "model.exr changed"
expect_code 2 "-o 'scene.exr' is the same file as the scene of --render 'scene.exr'" "" \
  --render:res=8x8:spp=1 scene.exr -o scene.exr
cmp -s "$SCENE" scene.exr || fail "scene.exr changed"
# nothing to do (no step besides --json / --threads)
expect_code 2 "nothing to do" ""
expect_code 2 "nothing to do" "" --json --threads 1
# a usage error wins over a runtime error earlier on the line: nothing is read before it
expect_code 2 "unknown command '--bogus'" out.exr missing.exr -o out.exr --bogus
expect_code 2 "-o 'nodir/x.exr': folder 'nodir'" "" missing.exr -o nodir/x.exr

# --- 1. kpcn-render: 1 for runtime errors, 2 for usage --------------------------------------------
echo '{"camera": ' >malformed.json
echo '[1, 2]' >array.json
expect_render_code 1 "cannot open scene 'missing.json': No such file or directory" missing.json -o o.exr
expect_render_code 1 "scene 'malformed.json': invalid JSON" malformed.json -o o.exr
expect_render_code 1 "scene 'array.json': (root): expected a JSON object" array.json -o o.exr
expect_render_code 1 "cannot open scene 'adir.exr': is a directory" adir.exr -o o.exr
expect_render_code 1 "absurd size 65536x65536" "$SCENE" -o o.exr --resolution 65536x65536
expect_render_code 1 "albedo_spp (--albedo-spp): 2 is below the render's 4" "$SCENE" -o o.exr \
  --resolution 8x8 --spp 4 --albedo-spp 2
expect_render_code 2 "unknown option '--bogus'" "$SCENE" -o o.exr --bogus
expect_render_code 2 "unexpected argument 'extra.json'" "$SCENE" -o o.exr extra.json
expect_render_code 2 "--spp needs a value" "$SCENE" -o o.exr --spp
expect_render_code 2 "-o needs a value" "$SCENE" -o
expect_render_code 2 "usage: kpcn-render" "$SCENE"
expect_render_code 2 "--spp: expected an integer in [1, 16777216], got 'abc'" "$SCENE" -o o.exr --spp abc
expect_render_code 2 "--seed: expected an integer in [0, 2^63-1], got '-1'" "$SCENE" -o o.exr --seed -1
expect_render_code 2 "--resolution: expected WxH" "$SCENE" -o o.exr --resolution 0x4
expect_render_code 2 "-o 'o.png' must end in .exr" "$SCENE" -o o.png
expect_render_code 2 "-o 'nodir/o.exr': folder 'nodir'" "$SCENE" -o nodir/o.exr
expect_render_code 2 "--time-limit needs --checkpoint" "$SCENE" -o o.exr --time-limit 1
# usage before the scene is read: a missing scene with a usage error is a usage error
expect_render_code 2 "unknown option '--bogus'" missing.json -o o.exr --bogus

# --- 2. the default render seed is 1 --------------------------------------------------------------
R="--resolution 16x16 --spp 2 --quiet"
for s in default 1 2; do
  if [ $s = default ]; then set -- ; else set -- --seed $s; fi
  "$KR" "$SCENE" -o r_$s.exr $R "$@" 2>err.txt || fail "kpcn-render $* exited $?: $(cat err.txt)"
  if [ $s = default ]; then m=; else m=:seed=$s; fi
  "$KT" --render:res=16x16:spp=2$m "$SCENE" -o k_$s.exr 2>err.txt ||
    fail "kpcntool --render:res=16x16:spp=2$m exited $?: $(cat err.txt)"
done
# every channel bit for bit (NaN included), and the seed the header records
$PY - <<'PY' >cmp.txt 2>&1 || echo "FAIL: the comparison script failed: $(cat cmp.txt)" >>cmp.txt
import numpy as np, OpenImageIO as oiio
def rd(f):
    b = oiio.ImageBuf(f)
    s = b.spec()
    px = b.get_pixels(oiio.FLOAT)
    assert px is not None and px.shape[:2] == (s.height, s.width), (f, b.geterror())
    px = np.ascontiguousarray(px)
    return list(s.channelnames), px.view(np.uint32), s.getattribute("kpcn:seed")
img = {f: rd(f + ".exr") for f in
       ("r_default", "r_1", "r_2", "k_default", "k_1", "k_2")}
def check(a, b, same, what):
    (ca, pa, _), (cb, pb, _) = img[a], img[b]
    if ca != cb or pa.shape != pb.shape:
        print(f"FAIL: {what}: {a} and {b} differ in channels or size: {ca} {pa.shape}, {cb} {pb.shape}")
        return
    ndiff = int(np.count_nonzero(pa != pb))
    if (ndiff == 0) == same:
        print(f"ok: {what} ({a} vs {b}: {ndiff} of {pa.size} values differ)")
    else:
        print(f"FAIL: {what}: {a} vs {b}: {ndiff} of {pa.size} values differ")
check("r_default", "r_1", True, "kpcn-render without --seed renders --seed 1's pixels")
check("r_default", "r_2", False, "kpcn-render --seed 2 renders other pixels")
check("k_default", "k_1", True, "kpcntool --render without seed= renders seed=1's pixels")
check("k_default", "k_2", False, "kpcntool --render:seed=2 renders other pixels")
check("k_default", "r_default", True, "kpcntool --render's default = kpcn-render's default")
check("k_2", "r_2", True, "kpcntool --render:seed=2 = kpcn-render --seed 2")
for f, want in (("r_default", 1), ("r_1", 1), ("r_2", 2), ("k_default", 1), ("k_1", 1), ("k_2", 2)):
    got = img[f][2]
    print(("ok: " if got == want else "FAIL: ") + f"{f}.exr records kpcn:seed {got} (expected {want})")
PY
while IFS= read -r line; do
  case $line in
  ok:*) pass "${line#ok: }" ;;
  *) fail "${line#FAIL: }" ;;
  esac
done <cmp.txt
rm -f r_*.exr k_*.exr

# --- 3. a full disk: every output format fails with exit 1 and leaves nothing ------------------
# the formats docs/kpcntool.md names, then the other writers of OIIO (skipped where this OIIO
# build has none)
FORMATS="png jpg exr tif bmp tga ppm gif ico webp dpx"
OPTIONAL="hdr sgi rla fits iff jp2 heic"
mkdir full
# full_run ARGS...: runs ARGS (a command and its arguments) in full/, a fresh 12 KB tmpfs of a
# private mount namespace; rc in FRC, stderr in ferr.txt, what is left in full/ in fls.txt.
# FRC=$SKIP where the tmpfs cannot be mounted.
# (root: unshare -m; anyone else: -rm, as root of a user namespace, where the kernel allows it)
US=-m
[ "$(id -u)" = 0 ] || US=-rm
full_run() {
  rm -f fout.txt ferr.txt fls.txt
  unshare $US sh -c 'mount -t tmpfs -o size=12k tmpfs full 2>/dev/null || exit '$SKIP'
cd full || exit '$SKIP'
"$@" >../fout.txt 2>../ferr.txt
rc=$?
ls -A >../fls.txt
exit $rc' sh "$@" 2>/dev/null
  FRC=$?
}
# the tmpfs does fill up: a plain dd of 64 KB fails with ENOSPC
full_run dd if=/dev/zero of=fill bs=1k count=64
if [ $FRC -eq $SKIP ] || ! [ -e fls.txt ]; then
  echo "SKIP: cannot mount a tmpfs in a private mount namespace (unshare $US, mount): no full-disk checks"
  full_ok=0
else
  full_ok=1
  if [ $FRC -ne 0 ] && grep -q "No space left on device" ferr.txt && [ "$(cat fls.txt)" = fill ]; then
    pass "a 12 KB tmpfs is full after 12 KB: dd of 64 KB fails with ENOSPC"
  else
    fail "the 12 KB tmpfs did not fill up: dd exited $FRC: $(cat ferr.txt)"
  fi
fi
if [ $full_ok = 1 ]; then
  # the formats named above that this OIIO writes
  WRITTEN="$FORMATS $($PY -c '
import sys, OpenImageIO as oiio
print(" ".join(e for e in sys.argv[1:] if oiio.ImageOutput.create("x." + e)))' $OPTIONAL)"
  # on a normal disk the image is written in each format, each larger than the tmpfs holds
  # (in one run; where that fails, one run per format names the format)
  set --
  for e in $WRITTEN; do set -- "$@" -o ok.$e; done
  if "$KT" noise.exr "$@" >/dev/null 2>err.txt; then
    pass "on a normal disk: noise.exr written as$(printf ' .%s' $WRITTEN)"
  else
    fail "on a normal disk: kpcntool noise.exr $* exited $?: $(head -c 300 err.txt)"
    no_leftovers "kpcntool noise.exr $*" ""
    for e in $WRITTEN; do
      "$KT" noise.exr -o ok.$e >/dev/null 2>err.txt ||
        fail "on a normal disk: kpcntool noise.exr -o ok.$e exited $?: $(head -c 300 err.txt)"
      no_leftovers "on a normal disk: kpcntool noise.exr -o ok.$e" ""
    done
  fi
  for e in $WRITTEN; do
    size=$(stat -c %s ok.$e 2>/dev/null || echo 0)
    [ "$size" -gt 16384 ] || fail "on a normal disk, ok.$e has $size bytes (not more than the tmpfs holds)"
  done
  rm -f ok.*
  for e in $WRITTEN; do
    full_run "$KT" ../noise.exr -o a.$e
    if [ $FRC -ne 1 ]; then
      fail "full disk: kpcntool noise.exr -o a.$e exited $FRC, expected 1; left: $(cat fls.txt | tr '\n' ' ') stderr: $(head -c 300 ferr.txt)"
    elif ! grep -q "^kpcntool: error: -o a\.$e: " ferr.txt; then
      fail "full disk: kpcntool noise.exr -o a.$e: no 'kpcntool: error: -o a.$e: ' line: $(head -c 300 ferr.txt)"
    elif [ -s fls.txt ]; then
      fail "full disk: kpcntool noise.exr -o a.$e left: $(tr '\n' ' ' <fls.txt)"
    else
      pass "full disk: -o a.$e exits 1 with '$(grep '^kpcntool: error:' ferr.txt | head -c 160)', leaves nothing"
    fi
  done
  # an output written before the one that fails, elsewhere, is not left either (also when the
  # image library ends the program: libjpeg)
  for e in png jpg; do
    full_run "$KT" ../noise.exr -o ../first.exr -o a.$e
    if [ $FRC -eq 1 ] && ! [ -s fls.txt ] && ! [ -e first.exr ] && no_leftovers "-o ../first.exr -o a.$e" ""; then
      pass "full disk: -o ../first.exr -o a.$e leaves neither"
    else
      fail "full disk: -o ../first.exr -o a.$e: exit $FRC, left: $(tr '\n' ' ' <fls.txt) $(ls first.exr 2>/dev/null)"
      rm -f first.exr
    fi
  done
  # kpcn-render's EXR
  full_run "$KR" "$SCENE" -o r.exr --resolution 64x64 --spp 1 --quiet
  if [ $FRC -eq 1 ] && grep -q "^kpcn-render: " ferr.txt && ! [ -s fls.txt ]; then
    pass "full disk: kpcn-render -o r.exr exits 1: $(head -c 160 ferr.txt)"
  else
    fail "full disk: kpcn-render -o r.exr: exit $FRC, left: $(tr '\n' ' ' <fls.txt) stderr: $(head -c 300 ferr.txt)"
  fi
fi
no_leftovers "the work folder" "" && pass "no stray temporaries"
if [ $fails -eq 0 ] && [ $full_ok = 0 ]; then
  echo "all other checks passed; the full-disk part was skipped"
  exit $SKIP
fi
finish
