#!/usr/bin/env bash
# Installs the build into a fresh prefix and uses it the way an embedding application would:
# the installed tools run (their RPATH finds the installed libkpcn), examples/embed builds
# with find_package(kpcn) and with pkg-config, and its programs denoise a render made by the
# installed kpcn-render with the shipped model, giving kpcntool's pixels exactly.
#   test_install_consumer.sh <build dir> <source dir> <work dir>
set -u
build=$1
src=$2
wd=$3
rm -rf "$wd"
mkdir -p "$wd"
cd "$wd" || exit 1
fails=0
fail() {
  echo "FAIL: $*"
  fails=$((fails + 1))
}
pfx=$wd/prefix
cmake --install "$build" --prefix "$pfx" >install.log || {
  cat install.log
  echo "FAIL: cmake --install"
  exit 1
}
# The consumer must not lean on anything from the build tree or the environment.
unset LD_LIBRARY_PATH PKG_CONFIG_PATH CMAKE_PREFIX_PATH
model=$src/testdata/models/kpcn-cpu.safetensors
scene=$src/testdata/scenes/cornell-box/scene.json

"$pfx/bin/kpcn-render" "$scene" --spp 4 --seed 7 --resolution 48x40 --quiet -o noisy.exr ||
  fail "installed kpcn-render"
"$pfx/bin/kpcntool" noisy.exr --denoise:model="$model" -o kpcntool.exr || fail "installed kpcntool"
# the display transform finds the OCIO config installed next to the tool
OCIO= "$pfx/bin/kpcntool" kpcntool.exr --ociodisplay:view=Filmic -o view.png || fail "installed --ociodisplay"

# CMake consumer (examples/embed/CMakeLists.txt: find_package(kpcn)).
if cmake -S "$src/examples/embed" -B cmake-build -DCMAKE_PREFIX_PATH="$pfx" \
  -DCMAKE_BUILD_TYPE=Release >cmake.log 2>&1 && cmake --build cmake-build >>cmake.log 2>&1; then
  cmake-build/denoise_framebuffer noisy.exr "$model" fb.exr || fail "denoise_framebuffer (CMake build)"
  cmake-build/denoise_imagebuf noisy.exr "$model" ib.exr || fail "denoise_imagebuf"
  for f in fb.exr ib.exr; do
    d=$("$pfx/bin/kpcntool" "$f" kpcntool.exr --ch R,G,B --l1 2>&1 | awk '{print $NF}')
    [ "$d" = 0 ] || fail "$f differs from kpcntool's result (L1 $d)"
  done
  # libkpcn's own dependencies stay private: the consumer links libkpcn alone.
  grep -q -i "dnnl\|embree\|assimp" cmake-build/CMakeFiles/denoise_framebuffer.dir/link.txt &&
    fail "a C consumer's link line names kpcn's private dependencies"
else
  cat cmake.log
  fail "examples/embed does not configure/build against the installed kpcn"
fi

# pkg-config consumer.
pc=$(dirname "$(find "$pfx" -name kpcn.pc | head -1)")
if [ -d "$pc" ]; then
  export PKG_CONFIG_PATH=$pc
  libdir=$(pkg-config --variable=libdir kpcn)
  # shellcheck disable=SC2046
  if cc -O2 -o pc_framebuffer "$src/examples/embed/denoise_framebuffer.c" \
    $(pkg-config --cflags --libs kpcn) -lm -Wl,-rpath,"$libdir"; then
    ./pc_framebuffer noisy.exr "$model" pc.exr || fail "denoise_framebuffer (pkg-config build)"
  else
    fail "pkg-config build of denoise_framebuffer"
  fi
  # shellcheck disable=SC2046
  c++ -std=c++17 -O2 -o pc_imagebuf "$src/examples/embed/denoise_imagebuf.cpp" \
    $(pkg-config --cflags --libs kpcn-oiio) -Wl,-rpath,"$libdir" || fail "pkg-config build (kpcn-oiio)"
  ./pc_imagebuf noisy.exr "$model" pci.exr || fail "denoise_imagebuf (pkg-config build)"
  for f in pc.exr pci.exr; do
    d=$("$pfx/bin/kpcntool" "$f" kpcntool.exr --ch R,G,B --l1 2>&1 | awk '{print $NF}')
    [ "$d" = 0 ] || fail "$f (pkg-config build) differs from kpcntool's result (L1 $d)"
  done
else
  fail "no kpcn.pc installed"
fi

# The installed library exports the kpcn_ namespace only (its public API: test_exports): nothing
# that could take the place of an application's own symbols (stb_image, OpenMP locks, helpers).
lib=$(ls "$pfx"/lib*/libkpcn.so 2>/dev/null | head -1)
if [ -n "$lib" ]; then
  foreign=$(nm -D --defined-only "$lib" | awk '{print $3}' | grep -v -E '^(kpcn_|KPCN_)' |
    grep -v -E '^$' | head -5)
  [ -z "$foreign" ] || fail "libkpcn exports symbols outside kpcn_: $foreign"
else
  fail "no installed libkpcn.so"
fi

# Bad input through the embedding API: a clear error and a non-zero exit, no output file.
printf 'not an exr' >bad.exr
if cmake-build/denoise_framebuffer bad.exr "$model" never.exr 2>err.txt; then
  fail "a non-EXR input was accepted"
fi
grep -q "bad.exr" err.txt || fail "the error does not name the file: $(cat err.txt)"
[ -e never.exr ] && fail "an output file was written for bad input"

[ "$fails" -eq 0 ] && echo "install + consumer: all checks passed"
exit "$fails"
