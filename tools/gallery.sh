#!/usr/bin/env bash
# Regenerates the pictures of README.md and docs/gallery.md from the built-in MRI head (no data
# files needed): bash tools/gallery.sh [path/to/volsplat]. About half a minute on 2 cores.
set -euo pipefail
cd "$(dirname "$0")/.."
bin="${1:-target/release/volsplat}"
if [ ! -x "$bin" ]; then
  cargo build --release -p volsplat-cli
  bin=target/release/volsplat
fi
out=docs/gallery
mkdir -p "$out"
view=(--azimuth 30 --elevation 15 --zoom 1.5 -q)
# The README's first command, exactly.
"$bin" render -o "$out/demo.png" --azimuth 30 --elevation 15 --zoom 1.5 -q
"$bin" render -o "$out/composite.png" --size 384 "${view[@]}" --preset ramp
"$bin" render -o "$out/shaded.png" --size 384 "${view[@]}"
"$bin" render -o "$out/mip.png" --size 384 "${view[@]}" --mode mip --window 20:200
"$bin" render -o "$out/xray.png" --size 384 "${view[@]}" --mode xray
"$bin" render -o "$out/perspective.png" --size 384 "${view[@]}" --perspective --dolly 1.6
"$bin" render -o "$out/crop.png" --size 384 "${view[@]}" --crop 0:83,0:127,0:64
"$bin" render -o "$out/clip.png" --size 384 "${view[@]}" --clip-plane 1,0,-1,0
"$bin" render -o "$out/head-phantom.png" --size 384 "${view[@]}" --phantom head
"$bin" movie -o "$out/turntable.gif" --size 256 --frames 36 --elevation 15 --zoom 1.5 -q
echo "wrote $out"
