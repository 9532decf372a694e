#!/bin/sh
# tools/judge_textures.py: on a folder training_data.sh planned (v1, v2val, v3val and the three
# roomsval sets), with one render standing in for every pair's noisy image and a filtered copy
# for every reference, its figures equal the ones recomputed here: the held-out textures render
# made again with the footprint and denoised (kpcn-render + kpcntool), diffuse-interreflection,
# and the geometric means of the 36 room and 32 v2val + v3val footprint pairs from its --pairs
# lines, one of them re-rendered and measured independently. Bad input is a clear error.
# usage: test_judge_textures.sh SCRIPT TRAINING_DATA_SH KPCN_BIN MODEL
set -u
S=$1; TDS=$2; B=$3; M=$4
D=$(mktemp -d /tmp/kpcn_judge_XXXXXX)
trap 'rm -rf "$D"' EXIT
fail() { echo "FAIL: $*"; exit 1; }
R=$B/kpcn-render/kpcn-render
T=$B/kpcntool/kpcntool
bad() {
  pat=$1; shift
  bin="--bin $B"
  [ "$1" != --compare ] || bin="" # --compare takes exactly its two files
  # shellcheck disable=SC2086 # bin is two words or none
  if /usr/bin/python3 "$S" "$@" $bin >"$D/out" 2>"$D/err"; then fail "accepted: $*"; fi
  grep -qF -- "$pat" "$D/err" || fail "message lacks '$pat': $(cat "$D/err")"
  [ ! -s "$D/out" ] || fail "printed a result for: $*"
}
mkdir -p "$D/empty"
bad "no model file" "$D/nope.safetensors" "$D/empty"
bad "has no dataset v1" "$M" "$D/empty"
TD=$D/td
KPCN_BIN=$B bash "$TDS" --plan-only "$TD" v1 v2val v3val roomsval roomsval2 roomsval3 >/dev/null 2>"$D/err" ||
  fail "plan: $(cat "$D/err")"
bad "no 4096-spp reference" "$M" "$TD"
V1=$TD/dataset/v1
# v1's 16-spp textures render (manifest seed) stands in for every noisy image; a bilateral
# filtering of it is every reference, a non-local-means one the two held-out references
seed=$(grep '"kind":"noisy"' "$V1/manifest.jsonl" | grep '"scene":"textures"' | grep '"variant":0,' |
  grep '"spp":16,' | sed -E 's/.*"seed":"?([0-9]+).*/\1/')
[ -n "$seed" ] || fail "no textures seed in v1's manifest"
"$R" "$V1/scenes/textures/v000.json" -o "$D/n.exr" --spp 16 --seed "$seed" --resolution 160x160 \
  --threads 2 --quiet || fail "render"
"$T" "$D/n.exr" --denoise:method=bilateral -o "$D/ref.exr" || fail "reference"
"$T" "$D/n.exr" --denoise:method=nlmeans -o "$D/ref2.exr" || fail "reference 2"
for ds in v2val v3val roomsval roomsval2 roomsval3 v1; do
  grep '"kind":"noisy"' "$TD/dataset/$ds/manifest.jsonl" | grep '"spp":16,' |
    sed -E 's/.*"out":"([^"]+)".*/\1/' | while read -r out; do
      # the renderer rejects v3val's two corridor variants as black (docs/dataset.md): no pair
      case $ds/$out in v3val/renders/corridor/v00[12]_*) continue ;; esac
      mkdir -p "$(dirname "$TD/dataset/$ds/$out")"
      cp "$D/n.exr" "$TD/dataset/$ds/$out"
      cp "$D/ref.exr" "$TD/dataset/$ds/${out%_16spp.exr}_ref1024spp.exr"
      # a baseline of relMSE 1 for every judged pair: vs_baseline's ratios are the figures
      v=$(basename "$out" _16spp.exr)
      case $ds:$v in v1:* | v[23]val:v000) ;; *)
        printf '%s\t%s\t%s\t-\t1\n' "$ds" "$(basename "$(dirname "$out")")" "$v" >>"$D/one.tsv" ;;
      esac
    done
done
for s in textures diffuse-interreflection; do cp "$D/ref2.exr" "$V1/renders/$s/v000_ref4096spp.exr"; done
j=$(/usr/bin/python3 "$S" "$M" "$TD" --bin "$B" --pairs "$D/pairs.tsv" --baseline "$D/one.tsv") ||
  fail "run"
# independent figures: the footprint render, denoised, and the plain render for DI
"$R" "$V1/scenes/textures/v000.json" -o "$D/fp.exr" --spp 16 --seed "$seed" --resolution 160x160 \
  --threads 2 --albedo-footprint 2 --quiet || fail "footprint render"
rel() { "$T" "$@" --ch R,G,B --relmse --json; }
t=$(rel "$D/fp.exr" --denoise:model="$M" "$D/ref2.exr") || fail "textures figure"
tn=$(rel "$D/fp.exr" "$D/ref2.exr") || fail "textures noisy figure"
di=$(rel "$D/n.exr" --denoise:model="$M" "$D/ref2.exr") || fail "DI figure"
# one room pair, re-rendered with the footprint from its manifest line
line=$(grep '"kind":"noisy"' "$TD/dataset/roomsval2/manifest.jsonl" | grep '"spp":16,' | head -n 1)
sf=$(echo "$line" | sed -E 's/.*"scene_file":"([^"]+)".*/\1/')
rs=$(echo "$line" | sed -E 's/.*"seed":"?([0-9]+).*/\1/')
"$R" "$TD/dataset/roomsval2/$sf" -o "$D/room.exr" --spp 16 --seed "$rs" --resolution 160x160 \
  --threads 2 --albedo-footprint 2 --quiet || fail "room render"
rp=$(rel "$D/room.exr" --denoise:model="$M" "$D/ref.exr") || fail "room figure"
/usr/bin/python3 - "$j" "$t" "$tn" "$di" "$rp" "$D/pairs.tsv" <<'PY' || fail "figures: $j"
import json, math, sys
d = json.loads(sys.argv[1])
t, tn, di, rp = (json.loads(x)["relmse"] for x in sys.argv[2:6])
close = lambda x, y: abs(x - y) <= 1e-9 * abs(y)
assert close(d["textures"], t) and close(d["textures_noisy"], tn), (d, t, tn)
assert close(d["below_noisy"], tn / t) and close(d["di"], di), d
flags = [l for l in open("/proc/cpuinfo") if l.startswith("flags")][0].split()
import os
if not os.environ.get("ONEDNN_MAX_CPU_ISA") and not os.environ.get("DNNL_MAX_CPU_ISA"):
    assert d["host"]["isa"] == ("avx512" if "avx512f" in flags else "avx2"), d["host"]
assert d["host"]["cpu"], d["host"]
rows = [l.rstrip("\n").split("\t") for l in open(sys.argv[6])]
rooms = [float(r[4]) for r in rows if r[0].startswith("roomsval")]
val = [float(r[4]) for r in rows if r[0] in ("v2val", "v3val")]
assert len(rows) == 68 and len(rooms) == 36 and len(val) == 32, len(rows)
assert {r[2] for r in rows if r[0] in ("v2val", "v3val")} == {"v001", "v002"}, rows
g = lambda xs: math.exp(sum(map(math.log, xs)) / len(xs))
assert close(d["dprime"], g(rooms)) and close(d["val32"], g(val)), d
first = [float(r[4]) for r in rows if r[0] == "roomsval2"][0]
assert close(first, rp), (first, rp)
assert len(set(rooms)) > 1, "every room pair has the same figure"
assert all(r[3] == "-" for r in rows), "the plain column was measured"
vb = d["vs_baseline"]
assert vb["pairs"] == 68 and close(vb["dprime_ratio"], d["dprime"]), vb
assert close(vb["val32_ratio"], d["val32"]), vb
assert vb["worse"] == sum(float(r[4]) > 1 for r in rows), vb
assert vb["better"] == sum(float(r[4]) < 1 for r in rows), vb
top = max(rows, key=lambda r: float(r[4]))
assert vb["worst"][0][0] == "/".join(top[:3]) and close(vb["worst"][0][1], float(top[4])), vb
PY
# the host's instruction set is kpcntool's (cli_version checks that against the CPU and caps)
isa() { env "$@" /usr/bin/python3 -c "import sys; sys.path.insert(0, sys.argv[1])
import judge_textures; print(judge_textures.host(sys.argv[2])['isa'])" "$(dirname "$S")" "$T"; }
[ "$(isa ONEDNN_MAX_CPU_ISA=AVX2)" = avx2 ] || fail "host() under the AVX2 cap"
want=avx2
! grep -qw avx512f /proc/cpuinfo || want=avx512
[ "$(isa -u ONEDNN_MAX_CPU_ISA -u DNNL_MAX_CPU_ISA)" = $want ] || fail "host() without a cap"
# --compare, no rendering: one room twice as bad, one v2val pair half, the rest equal
# (sprintf: awk would print the products to 6 digits)
awk -F'\t' 'BEGIN{OFS="\t"} $1=="roomsval2" && !a {$5=sprintf("%.17g", $5*2); a=1}
  $1=="v2val" && !b {$5=sprintf("%.17g", $5/2); b=1} 1' \
  "$D/pairs.tsv" >"$D/new.tsv"
c=$(/usr/bin/python3 "$S" --compare "$D/new.tsv" "$D/pairs.tsv") || fail "compare"
/usr/bin/python3 - "$c" "$D/pairs.tsv" <<'PY' || fail "compare figures: $c"
import json, sys
c = json.loads(sys.argv[1])
rows = [l.rstrip("\n").split("\t") for l in open(sys.argv[2])]
room = "/".join([r for r in rows if r[0] == "roomsval2"][0][:3])
val = "/".join([r for r in rows if r[0] == "v2val"][0][:3])
close = lambda x, y: abs(x - y) <= 1e-9 * abs(y)
assert c["pairs"] == 68 and c["better"] == 1 and c["worse"] == 1, c
assert c["worst"][0][0] == room and close(c["worst"][0][1], 2.0), c
assert c["best"][0][0] == val and close(c["best"][0][1], 0.5), c
assert close(c["dprime_ratio"], 2 ** (1 / 36)) and close(c["val32_ratio"], 0.5 ** (1 / 32)), c
PY
head -n 67 "$D/pairs.tsv" >"$D/short.tsv"
bad "is in only one of the two files" --compare "$D/short.tsv" "$D/pairs.tsv"
printf 'x\ty\n' >"$D/junk.tsv"
bad "is not a --pairs line" --compare "$D/junk.tsv" "$D/pairs.tsv"
bad "cannot read" --compare "$D/nope.tsv" "$D/pairs.tsv"
bad "is not a --pairs line" "$M" "$TD" --baseline "$D/junk.tsv"
# a pair missing: the count is checked, not assumed
rm "$TD/dataset/roomsval3/$(grep '"kind":"noisy"' "$TD/dataset/roomsval3/manifest.jsonl" |
  grep '"spp":16,' | head -n 1 | sed -E 's/.*"out":"([^"]+)".*/\1/')"
bad "expected 36 room pairs" "$M" "$TD"
bad "--threads must be at least 1" "$M" "$TD" --threads 0
echo "test_judge_textures: ok"
