# --version of the four tools: exit 0, nothing on stderr, "TOOL VERSION" then libkpcn's build
# line, whose versions match the installed headers and oiiotool, and whose instruction set
# follows /proc/cpuinfo and the oneDNN ISA cap (libkpcn's rule: a cap naming an SSE or AVX
# level below AVX-512 makes everything run as on an AVX2 CPU).
# usage: bash cli_version.sh KPCNTOOL KPCN_RENDER KPCN_TRAIN KPCN_DATASET SOURCE_DIR WORKDIR
set -u
KT=$1 KR=$2 KTR=$3 KD=$4 SRC=$5 WD=$6
rm -rf "$WD" && mkdir -p "$WD" && cd "$WD" || exit 1
fails=0
pass() { echo "ok: $*"; }
fail() {
  echo "FAIL: $*"
  fails=$((fails + 1))
}
hdr() { sed -nE "s/^#define $1 \"?([^\"]*)\"?\$/\\1/p" "$2"; }
ver=$(hdr KPCN_VERSION_STRING "$SRC/libkpcn/include/kpcn/common.h")
d=/usr/include/oneapi/dnnl/dnnl_version.h
dnnl="$(hdr DNNL_VERSION_MAJOR $d).$(hdr DNNL_VERSION_MINOR $d).$(hdr DNNL_VERSION_PATCH $d)"
embree=$(hdr RTC_VERSION_STRING /usr/include/embree3/rtcore_config.h)
exr=$(cat /usr/include/OpenEXR/*.h | sed -nE 's/^#define OPENEXR_VERSION_STRING "([^"]*)"$/\1/p')
oiio=$(oiiotool --version | grep -oE '[0-9]+\.[0-9]+\.[0-9]+' | head -n 1)
native=avx2
! grep -qw avx512f /proc/cpuinfo || native=avx512
[ -n "$ver" ] && [ -n "$dnnl" ] && [ -n "$embree" ] && [ -n "$exr" ] && [ -n "$oiio" ] ||
  fail "a version missing from the headers: '$ver' '$dnnl' '$embree' '$exr' '$oiio'"
# check NAME TOOL ISA [ENV...]: TOOL --version under ENV prints the expected two lines
check() {
  local name=$1 tool=$2 isa=$3
  shift 3
  if ! env -u ONEDNN_MAX_CPU_ISA -u DNNL_MAX_CPU_ISA "$@" "$tool" --version >out.txt 2>err.txt; then
    fail "$name --version ($*) exited non-zero: $(cat err.txt)"
    return
  fi
  local want="libkpcn $ver; instruction set $isa; oneDNN $dnnl, Embree $embree, OpenEXR $exr"
  [ "$name" != kpcntool ] || want="$want, OpenImageIO $oiio"
  if [ -s err.txt ]; then
    fail "$name --version ($*) wrote to stderr: $(cat err.txt)"
  elif [ "$(wc -l <out.txt)" != 2 ] || [ "$(sed -n 1p out.txt)" != "$name $ver" ] ||
    [ "$(sed -n 2p out.txt)" != "$want" ]; then
    fail "$name --version ($*): '$(cat out.txt)', expected '$name $ver' and '$want'"
  else
    pass "$name --version $*"
  fi
}
# every tool natively and under the AVX2 cap, and --version listed in its --help
for t in "kpcntool $KT" "kpcn-render $KR" "kpcn-train $KTR" "kpcn-dataset $KD"; do
  # shellcheck disable=SC2086 # name and path
  set -- $t
  check "$1" "$2" $native
  check "$1" "$2" avx2 ONEDNN_MAX_CPU_ISA=AVX2
  if "$2" --help | grep -q -- "--version"; then pass "$1 --help lists --version"; else
    fail "$1 --help lacks --version"; fi
done
# kpcntool's single-dash forms are the same commands (kpcntool.md: -x and --x)
if "$KT" -version >out1.txt 2>err.txt && "$KT" --version >out2.txt && cmp -s out1.txt out2.txt &&
  [ ! -s err.txt ]; then pass "kpcntool -version"; else fail "kpcntool -version: $(cat err.txt)"; fi
if "$KT" -help >out1.txt 2>err.txt && "$KT" --help >out2.txt && cmp -s out1.txt out2.txt; then
  pass "kpcntool -help"; else fail "kpcntool -help: $(cat err.txt)"; fi
# help asked for goes to stdout (exit 0), every kpcn-dataset command's too
for c in plan run patches; do
  if "$KD" $c --help >out.txt 2>err.txt && grep -q "usage: kpcn-dataset $c" out.txt && [ ! -s err.txt ]; then
    pass "kpcn-dataset $c --help on stdout"
  else
    fail "kpcn-dataset $c --help: stdout '$(cat out.txt)', stderr '$(cat err.txt)'"
  fi
done
# the other cap forms, once
check kpcntool "$KT" avx2 DNNL_MAX_CPU_ISA=sse41
check kpcntool "$KT" $native ONEDNN_MAX_CPU_ISA=ALL
check kpcntool "$KT" $native ONEDNN_MAX_CPU_ISA=AVX512_CORE_BF16
[ $fails -eq 0 ] && echo "cli_version: ok" || { echo "cli_version: $fails failure(s)"; exit 1; }
