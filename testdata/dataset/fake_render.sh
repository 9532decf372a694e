#!/bin/sh
# Fake kpcn-render for the kpcn-dataset tests: same command line, but copies a sample EXR
# instead of rendering (ms instead of seconds) and logs "start/done <final output>" to
# $FAKE_LOG. $FAKE_SLEEP seconds per job; previews of scenes matching $FAKE_BLACK get a
# black image (to exercise degenerate-variant rejection); with $FAKE_DETACH the copy runs in
# a background child, as a wrapper script's renderer would. An --albedo-footprint K is logged
# as " fp=K" after the output's name.
here=$(dirname "$0")
scene=$1
out=""
spp=0
fp=""
while [ $# -gt 0 ]; do
  case "$1" in
    -o) out=$2; shift ;;
    --spp) spp=$2; shift ;;
    --albedo-footprint) fp=" fp=$2"; shift ;;
  esac
  shift
done
final=$(echo "$out" | sed 's/\.part[0-9]*\.exr$/.exr/')
echo "start $final$fp" >> "${FAKE_LOG:-/dev/null}"
src=$here/sample_noisy.exr
[ "$spp" -ge 100 ] && src=$here/sample_ref.exr
if [ -n "$FAKE_BLACK" ]; then
  case "$out" in *preview*) case "$scene" in *"$FAKE_BLACK"*) src=$here/sample_black.exr ;; esac ;; esac
fi
if [ -n "$FAKE_DETACH" ]; then
  # like a wrapper script: the work runs in a child process that outlives a kill of this shell
  (sleep "${FAKE_SLEEP:-0}"; cp "$src" "$out" && echo "done $final" >> "${FAKE_LOG:-/dev/null}") &
  wait $!
  exit $?
fi
sleep "${FAKE_SLEEP:-0}"
cp "$src" "$out" || exit 1
echo "done $final" >> "${FAKE_LOG:-/dev/null}"
