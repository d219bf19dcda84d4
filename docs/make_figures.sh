#!/bin/sh
# Regenerates every figure of the docs that `isotile render` makes, into OUT (default
# docs/images, the committed copies; CI writes them to a temporary folder and checks them:
# tests/check_figures.sh). Needs the shared volumes beside the checkout (../shared/data) and an
# OpenGL context (llvmpipe will do); exits 77 when the volumes are absent.
#
#   docs/make_figures.sh [OUT]     ISOTILE=path/to/isotile (default build/tiler/isotile)
#
# methods-closeup.png (README): the engine at iso 49.5, the same close-up (a hole's rim) as
# Marching Cubes, Macet and Dual Contouring, wireframe, coloured by triangle quality, joined side
# by side by compose_png.py.
set -eu
repo=$(cd "$(dirname "$0")/.." && pwd)
out=${1:-$repo/docs/images}
isotile=${ISOTILE:-$repo/build/tiler/isotile}
engine=$repo/../shared/data/engine_256x256x128_uint8.raw.gz
if [ ! -f "$engine" ]; then
  echo "make_figures.sh: $engine is absent (the shared volumes beside the checkout)" >&2
  exit 77
fi
mkdir -p "$out"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

for method in mc macet dc; do
  "$isotile" -q extract "$engine" --iso 49.5 --method "$method" -o "$tmp/engine-$method.ply"
  "$isotile" -q render "$tmp/engine-$method.ply" -o "$tmp/engine-$method.png" --size 600x600 \
    --view 70,25 --center 205,128,85 --zoom 9 --wireframe --colour quality
done
python3 "$repo/docs/compose_png.py" "$out/methods-closeup.png" \
  "$tmp/engine-mc.png" "$tmp/engine-macet.png" "$tmp/engine-dc.png"
echo "make_figures.sh: wrote $out/methods-closeup.png"
