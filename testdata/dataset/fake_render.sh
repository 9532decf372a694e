#!/bin/sh
# Fake kpcn-render for the kpcn-dataset tests: same command line, but copies a sample EXR
# instead of rendering (ms instead of seconds) and logs "start/done <final output>" to
# $FAKE_LOG. $FAKE_SLEEP seconds per job; previews of scenes matching $FAKE_BLACK get a
# black image (to exercise degenerate-variant rejection); with $FAKE_DETACH the copy runs in
# a background child, as a wrapper script's renderer would. An --albedo-footprint K is logged
# as " fp=K" after the output's name. The copy is resized to --resolution and its header
# says the job's --spp and --seed (kpcn-dataset checks renders against their jobs), unless
# $FAKE_RAW is set (a render that is not the job's).
here=$(dirname "$0")
scene=$1
out=""
spp=0
seed=0
res=""
fp=""
while [ $# -gt 0 ]; do
  case "$1" in
    -o) out=$2; shift ;;
    --spp) spp=$2; shift ;;
    --seed) seed=$2; shift ;;
    --resolution) res=$2; shift ;;
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
put() { # the sample as this job's render
  if [ -n "$FAKE_RAW" ] || [ -z "$res" ]; then
    cp "$src" "$out"
  else
    oiiotool "$src" --resize "$res" --attrib:type=int kpcn:spp "$spp" \
      --attrib:type=string kpcn:seed "$seed" -o "$out"
  fi
}
if [ -n "$FAKE_DETACH" ]; then
  # like a wrapper script: the work runs in a child process that outlives a kill of this shell
  (sleep "${FAKE_SLEEP:-0}"; put && echo "done $final" >> "${FAKE_LOG:-/dev/null}") &
  wait $!
  exit $?
fi
sleep "${FAKE_SLEEP:-0}"
put || exit 1
echo "done $final" >> "${FAKE_LOG:-/dev/null}"
