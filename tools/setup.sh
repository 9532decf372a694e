#!/usr/bin/env bash
# Installs the Debian 12 packages kpcn needs (idempotent, non-interactive; apt-get update
# only when something is missing) and configures + builds the project.
#   tools/setup.sh [build-dir] [extra cmake args...]
# Environment: KPCN_SKIP_BUILD=1 installs packages only.
set -euo pipefail
here=$(cd "$(dirname "$0")/.." && pwd)
PKGS="build-essential cmake pkg-config libopenimageio-dev openimageio-tools libopenexr-dev
libopencolorio-dev opencolorio-tools libembree-dev libdnnl-dev libopenblas-dev libassimp-dev
libcjson-dev libstb-dev python3-skimage python3-numpy python3-openimageio"
missing=()
for p in $PKGS; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "setup: installing ${missing[*]}"
  SUDO=""
  [ "$(id -u)" -eq 0 ] || SUDO=sudo
  export DEBIAN_FRONTEND=noninteractive
  $SUDO apt-get update -qq
  $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi
[ "${KPCN_SKIP_BUILD:-0}" = 1 ] && exit 0
build=${1:-"$here/build"}
shift || true
cmake -S "$here" -B "$build" -DCMAKE_BUILD_TYPE=Release "$@" >/dev/null
cmake --build "$build" -j"$(nproc)"
