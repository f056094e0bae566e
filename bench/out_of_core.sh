#!/usr/bin/env bash
# Issue 31 item 8 (a benchmark, not a test): an 8 GiB uint16 volume generated on disk, converted to
# OME-Zarr (streamed), rendered at 1024² under --memory 1GiB. Prints the disk's sequential read
# bandwidth (dd iflag=direct), the time to the first full frame with the page cache dropped, the
# bytes it read, peak RSS, the cached frame time (volsplat bench), the time to a coarse preview, and
# zarr-python's time to read level 0 whole. Needs root for drop_caches (skipped otherwise: say so),
# python3 with numpy, and for the zarr comparison a venv with zarr (ZARR_PY, default /tmp/zv/bin/python).
#
#   bench/out_of_core.sh [phase…]     phases: gen convert measure clean (default: all four)
#
# Env: VOLSPLAT (binary, default target/release/volsplat), WORK (default /tmp/volsplat-ooc-bench;
# needs ~14 GB: 8 GiB raw + ~5.5 GiB store; the raw file is deleted after conversion), DIMS
# (default 2048,1024,2048; the view is anterior: along y, rows along z, so that one band of rows, 32 × 16 bricks per brick row, fits the budget),
# MEMORY (default 1GiB), SIZE (default 1024), FRAMES (default 5).
set -euo pipefail
here=$(cd "$(dirname "$0")/.." && pwd)
V=${VOLSPLAT:-$here/target/release/volsplat}
WORK=${WORK:-/tmp/volsplat-ooc-bench}
DIMS=${DIMS:-2048,1024,2048}
MEMORY=${MEMORY:-1GiB}
SIZE=${SIZE:-1024}
FRAMES=${FRAMES:-5}
ZARR_PY=${ZARR_PY:-/tmp/zv/bin/python}
VIEW=(--view anterior)
phases=("$@"); [ ${#phases[@]} -gt 0 ] || phases=(gen convert measure clean)
mkdir -p "$WORK"
raw=$WORK/v.raw store=$WORK/v.zarr
IFS=, read -r nx ny nz <<<"$DIMS"

drop() { sync; if echo 3 >/proc/sys/vm/drop_caches 2>/dev/null; then echo "(page cache dropped)"; else echo "(page cache NOT dropped: not root)"; fi; }
# Runs "$@" under /usr/bin/time; prints wall seconds and peak RSS (MiB) after the label.
timed() { local label=$1; shift; /usr/bin/time -f "%e %M" -o "$WORK/time" "$@" >"$WORK/out" 2>&1 || { cat "$WORK/out"; return 1; }
  read -r s kb <"$WORK/time"; printf '%-44s %8.2f s  peak RSS %7.1f MiB\n' "$label" "$s" "$(echo "$kb/1024" | bc -l)"; }

for phase in "${phases[@]}"; do case $phase in
gen)
  # A smooth blob, a ramp and 6 bits of noise (the store compresses to ~2/3), slice by slice.
  python3 - "$nx" "$ny" "$nz" "$raw" <<'PY'
import sys, numpy as np
nx, ny, nz = map(int, sys.argv[1:4]); out = sys.argv[4]
y, x = np.mgrid[0:ny, 0:nx].astype(np.float32)
rng = np.random.default_rng(7)
with open(out, "wb") as f:
    for z in range(nz):
        r2 = ((x - nx/2)/(0.35*nx))**2 + ((y - ny/2)/(0.35*ny))**2 + ((z - nz/2)/(0.35*nz))**2
        v = 30000*np.exp(-2*r2) + 8000*np.sin(x*0.05)*np.cos(y*0.03 + z*0.02) + 10000
        v += rng.integers(0, 64, size=v.shape)
        f.write(v.astype(np.uint16).tobytes())
PY
  ls -l "$raw" ;;
convert)
  # The disk's sequential read bandwidth, the same day: the raw file read with O_DIRECT.
  drop; dd if="$raw" of=/dev/null bs=16M iflag=direct 2>&1 | tail -1
  rm -rf "$store"
  timed "convert (streamed)" "$V" convert "$raw" --raw-dims "$DIMS" --raw-type u16 -o "$store" -q
  rm -f "$raw"
  du -sb "$store" "$store/0" ;;
measure)
  # (`volsplat info` without --memory would read level 0 whole to report its range when the
  # level fits half the available memory; with --memory it reads only metadata and ranges.)
  levels=$(find "$store" -mindepth 1 -maxdepth 1 -type d -name '[0-9]*' | wc -l)
  echo "levels: $levels; level 0: $(du -sb "$store/0" | cut -f1) bytes stored"
  # The level's ranges go to a folder of the benchmark's own, empty at first: the first run
  # scans the level (its note gives the scan's time), the second finds the ranges kept.
  export VOLSPLAT_CACHE_DIR=$WORK/ranges; rm -rf "$VOLSPLAT_CACHE_DIR"
  drop; timed "scan + first frame (--memory $MEMORY, cold cache)" "$V" render "$store" --memory "$MEMORY" "${VIEW[@]}" --size "$SIZE" -o "$WORK/first.png"
  grep -E "out of core" "$WORK/out" || true
  drop; timed "first frame (ranges kept, cold cache)" "$V" render "$store" --memory "$MEMORY" "${VIEW[@]}" --size "$SIZE" -o "$WORK/first.png"
  grep -E "out of core" "$WORK/out" || true
  drop; timed "bench $FRAMES frames (cold open)" "$V" bench "$store" --memory "$MEMORY" "${VIEW[@]}" --size "$SIZE" --frames "$FRAMES" --orbit 0
  cat "$WORK/out"
  coarsest=$((levels - 1))
  drop; timed "coarse preview (level $coarsest, 256², cold)" "$V" render "$store" --zarr-level "$coarsest" "${VIEW[@]}" --size 256 -o "$WORK/coarse.png"
  timed "coarse preview (level $coarsest, 256², warm)" "$V" render "$store" --zarr-level "$coarsest" "${VIEW[@]}" --size 256 -o "$WORK/coarse.png"
  drop; timed "--zarr-level auto at 128² (cold)" "$V" render "$store" --zarr-level auto "${VIEW[@]}" --size 128 -o "$WORK/auto.png"
  grep -i "level" "$WORK/out" | head -3 || true
  if [ -x "$ZARR_PY" ]; then
    drop; timed "zarr-python: level 0 whole (cold)" "$ZARR_PY" -c "
import time, zarr, numpy as np
t = time.perf_counter(); a = zarr.open_array('$store/0', mode='r')[...]
print(f'read {a.nbytes/2**30:.2f} GiB in {time.perf_counter()-t:.2f} s, max {int(a.max())}')"
    cat "$WORK/out"
  fi ;;
clean) rm -rf "$WORK" ;;
*) echo "unknown phase $phase" >&2; exit 2 ;;
esac; done
