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
# --outside 0 is the default, byte for byte (older seeds' rooms unchanged); --outside 1 opens
# every room at the front and puts the camera outside it, looking in; such a room renders
/usr/bin/python3 "$S" --count 6 --seed 5 --outside 0 -o "$D/o0" >/dev/null || fail "write --outside 0"
/usr/bin/python3 "$S" --count 6 --seed 5 --outside 1 -o "$D/o1" >/dev/null || fail "write --outside 1"
for i in 0 1 2 3 4 5; do
  cmp -s "$D/a/room-5-$i/scene.json" "$D/o0/room-5-$i/scene.json" || fail "--outside 0 changed room $i"
done
/usr/bin/python3 -c "
import json, sys
for i in range(6):
    d = json.load(open('%s/room-5-%d/scene.json' % (sys.argv[1], i)))
    names = [b['name'] for b in d['bsdfs']]
    back = [p for p in d['primitives'] if p['bsdf'] == 'back'][0]
    depth = -2 * back['transform']['position'][2]  # the back wall is at z = -d/2
    z = d['camera']['transform']['position'][2]
    if 'front' in names or not z > depth / 2:
        sys.exit('room %d: front wall %s, camera z %.2f, room front at %.2f' % (i, 'front' in names, z, depth / 2))
" "$D/o1" || fail "--outside 1 room not open / camera not outside"
"$R" "$D/o1/room-5-0/scene.json" --spp 2 --resolution 24x24 --threads 1 --quiet -o "$D/o1.exr" ||
  fail "outside-view room does not render"
# bad arguments: an error naming the problem, no output folder
for args in "--count 0 --seed 1" "--count 2 --seed 1 --resolution 160" "--count 2 --seed 1 --resolution 0x5" \
            "--count 2 --seed 1 --outside 1.5"; do
  if /usr/bin/python3 "$S" $args -o "$D/bad" 2>"$D/err"; then fail "accepted: $args"; fi
  grep -q "rooms.py:" "$D/err" || fail "no clear error for $args: $(cat "$D/err")"
  [ -e "$D/bad" ] && fail "wrote output for: $args"
done
echo "rooms.py: deterministic, seed-dependent, 6 rooms render, --outside views; bad arguments refused"
