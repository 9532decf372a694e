#!/usr/bin/env bash
# The main job: set up + build, render a held-out scene at low spp with kpcn-render, denoise
# it with the shipped KPCN model (and non-local means for comparison), write the EXRs, a
# labelled comparison mosaic PNG (OCIO display transform, plus a false-colour relMSE error
# map), the error map as EXR and the metrics against the bundled reference.
#   tools/main-job.sh [outdir]        (default: out/)
# Environment: KPCN_SCENE, KPCN_REF, KPCN_MODEL, KPCN_SPP, KPCN_RES override the defaults
# (KPCN_RES must match the reference's size: give KPCN_REF with it).
set -euo pipefail
here=$(cd "$(dirname "$0")/.." && pwd)
out=${1:-"$here/out"}
"$here/tools/setup.sh" "$here/build"
bin="$here/build/tools"
scene=${KPCN_SCENE:-"$here/testdata/scenes/diffuse-interreflection/scene.json"}
ref=${KPCN_REF:-"$here/testdata/references/diffuse-interreflection_256.exr"}
model=${KPCN_MODEL:-"$here/testdata/models/kpcn-cpu.safetensors"}
spp=${KPCN_SPP:-16}
res=${KPCN_RES:-256x256}
tool="$bin/kpcntool/kpcntool"
# Everything is made in a fresh folder next to the output folder and moved into it only when
# every step succeeded: a failed run leaves the previous outputs as they were, not a mix.
final=$out
mkdir -p "$(dirname "$final")"
out=$(mktemp -d "$final.partial.XXXXXX")
trap 'rm -rf "$out"' EXIT

echo "== render: $(basename "$(dirname "$scene")") at $spp spp, $res (held out from training)"
"$bin/kpcn-render/kpcn-render" "$scene" --spp "$spp" --seed 1 --resolution "$res" -o "$out/noisy.exr"
echo "== denoise: KPCN ($(basename "$model")) and non-local means"
"$tool" "$out/noisy.exr" --denoise:model="$model" -o "$out/kpcn.exr"
# the same model averaged over the 8 mirrored / rotated copies of the input (8x the time)
"$tool" "$out/noisy.exr" --denoise:model="$model":ensemble=8 -o "$out/kpcn-x8.exr"
"$tool" "$out/noisy.exr" --denoise:method=nlmeans -o "$out/nlmeans.exr"
echo "== mosaic and error map"
# four images through the OCIO Filmic view, then kpcn's per-pixel relMSE in false colour
# (inferno, 0 .. 0.01: ten times the image mean of a good result) as the fifth panel
view=--ociodisplay:view=Filmic
"$tool" "$out/noisy.exr" --ch R,G,B $view "$out/nlmeans.exr" $view "$out/kpcn.exr" $view \
  "$ref" --ch R,G,B $view "$out/kpcn.exr" "$ref" --ch R,G,B --errormap:metric=relmse \
  --colormap:max=0.01 --mosaic:n=5:labels="noisy,nlmeans,kpcn,reference,kpcn relMSE 0-0.01" \
  -o "$out/mosaic.png"
"$tool" "$out/kpcn.exr" "$ref" --ch R,G,B --errormap:metric=relmse -o "$out/kpcn_relmse.exr"
echo "== metrics against the reference ($(basename "$ref"))"
for name in noisy nlmeans kpcn kpcn-x8; do
  img="$out/$name.exr"
  printf '%-8s ' "$name"
  "$tool" "$img" --ch R,G,B "$ref" --ch R,G,B --relmse --ssim:display=srgb --psnr:display=srgb --json \
    | tee "$out/metrics_$name.json"
done
mkdir -p "$final"
for f in noisy.exr kpcn.exr kpcn-x8.exr nlmeans.exr mosaic.png kpcn_relmse.exr metrics_noisy.json \
  metrics_nlmeans.json metrics_kpcn.json metrics_kpcn-x8.json; do
  mv "$out/$f" "$final/$f"
done
echo "outputs in $final: noisy.exr kpcn.exr kpcn-x8.exr nlmeans.exr mosaic.png kpcn_relmse.exr metrics_*.json"
