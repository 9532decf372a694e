#!/bin/sh
# testdata/scenes/rooms.py (procedural training / distinct-validation rooms): a pure function
# of (seed, index), different seeds give different rooms, every room renders, bad arguments
# are a clear error with nothing written.
# usage: test_rooms.sh ROOMS_PY KPCN_RENDER
set -u
S=$1; R=$2
D=$(mktemp -d /tmp/kpcn_rooms_XXXXXX)
trap 'rm -rf "$D"' EXIT
fail() { echo "FAIL: $*"; exit 1; }
/usr/bin/python3 "$S" --count 6 --seed 5 -o "$D/a" >/dev/null || fail "write seed 5"
/usr/bin/python3 "$S" --count 6 --seed 5 -o "$D/b" >/dev/null || fail "write seed 5 again"
/usr/bin/python3 "$S" --count 6 --seed 6 -o "$D/c" >/dev/null || fail "write seed 6"
for i in 0 1 2 3 4 5; do
  cmp -s "$D/a/room-5-$i/scene.json" "$D/b/room-5-$i/scene.json" || fail "room $i differs between runs"
  cmp -s "$D/a/room-5-$i/scene.json" "$D/c/room-6-$i/scene.json" && fail "seeds 5 and 6 made the same room $i"
  # the renderer accepts it (materials, texture paths, lights) and it is not black
  "$R" "$D/a/room-5-$i/scene.json" --spp 2 --resolution 24x24 --threads 1 --quiet -o "$D/r$i.exr" ||
    fail "room $i does not render"
  /usr/bin/python3 -c "
import OpenImageIO as oiio, sys
b = oiio.ImageBuf(sys.argv[1]); s = oiio.ImageBufAlgo.computePixelStats(b)
n = list(b.spec().channelnames)
sys.exit(0 if max(s.avg[n.index(c)] for c in 'RGB') > 0 else 1)" "$D/r$i.exr" || fail "room $i renders black"
done
# bad arguments: an error naming the problem, no output folder
for args in "--count 0 --seed 1" "--count 2 --seed 1 --resolution 160" "--count 2 --seed 1 --resolution 0x5"; do
  if /usr/bin/python3 "$S" $args -o "$D/bad" 2>"$D/err"; then fail "accepted: $args"; fi
  grep -q "rooms.py:" "$D/err" || fail "no clear error for $args: $(cat "$D/err")"
  [ -e "$D/bad" ] && fail "wrote output for: $args"
done
echo "rooms.py: deterministic, seed-dependent, 6 rooms render; bad arguments refused"
