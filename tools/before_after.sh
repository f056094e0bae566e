#!/usr/bin/env bash
# Two volsplat binaries on the shared MRI scenes, alternating, 3 rounds; 2 threads, 512²;
# each scene by the automatic choice and with --visibility sheet (the sheets or the splat list).
# Prints one line per scene, round and choice: the median ms/frame and the renderer of each.
cd "$(dirname "$0")/.."
D=../shared/data; S=$D/scenes; P=python3
A="${1:?usage: tools/before_after.sh OLD_BINARY [NEW_BINARY]}"; B="${2:-./target/release/volsplat}"
for round in 1 2 3; do
for vol in mri_brainsmall mri_colin27; do
  f=$D/$vol.nrrd; [ -f $f ] || f=$D/$vol.nhdr
  for sc in composite_ortho composite_persp composite_shaded_ortho mip_ortho; do
    cam=$S/${vol}__$sc.camera.json; tf=$S/${vol}__$sc.tf.json
    mode=composite; [[ $sc == mip* ]] && mode=mip
    for extra in "" "--visibility sheet"; do
      r=""
      for bin in $A $B; do
        r="$r $($bin bench $f --tf $tf --camera $cam --mode $mode --threads 2 --frames 8 --orbit 0 $extra 2>/dev/null | tail -1 | $P -c "import json,sys; d=json.load(sys.stdin); print(round(d['median_ms'],1), d['renderer'], sep='/')")"
      done
      echo "$round $vol $sc [${extra:-auto}] before/after:$r"
    done
  done
done
done
