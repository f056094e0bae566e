#!/usr/bin/env bash
# Issue 31 item 7: a 1 GiB volume rendered out of core with the process under a 256 MiB memory cap,
# the PNG bit for bit the render of the same store read whole in memory (without the cap: a
# 1 GiB in-memory render cannot run under it).
#
# The volume (512 × 512 × 2048 u16, a smooth blob, a ramp and 6 bits of noise) is written slice
# by slice into a raw file and converted to OME-Zarr (streamed), in a temporary directory that
# is removed at the end. The view is anterior (along y, rows along z), so
# that one band of rows (8 × 8 × 2 bricks of 64³ u16, 73 MiB) fits the cache.
#
# The cap, the first that works: a cgroup v2 (memory.max), a cgroup v1 (memory.limit_in_bytes,
# swap off) made under this process's own cgroup, else `prlimit --as` (address space; glibc's
# per-thread malloc arenas reserve 64 MiB of it each, hence MALLOC_ARENA_MAX=2). CAP=as forces
# prlimit. Needs python3 with numpy. Env: VOLSPLAT (default target/release/volsplat), CAP_MIB
# (256), MEMORY (160MiB), KEEP=1 keeps the temporary directory.
set -euo pipefail
here=$(cd "$(dirname "$0")/.." && pwd)
V=${VOLSPLAT:-$here/target/release/volsplat}
CAP_MIB=${CAP_MIB:-256}
MEMORY=${MEMORY:-160MiB}
dims=(512 512 2048)
view=(--view anterior --size 512 --preset ramp)
tmp=$(mktemp -d "${TMPDIR:-/tmp}/volsplat-cap.XXXXXX")
cg=""
cleanup() {
  if [ -n "$cg" ] && [ -d "$cg" ]; then rmdir "$cg" 2>/dev/null || true; fi
  [ "${KEEP:-0}" = 1 ] || rm -rf "$tmp"
}
trap cleanup EXIT
t0=$SECONDS

python3 - "${dims[@]}" "$tmp/v.raw" <<'PY'
import sys, numpy as np
nx, ny, nz = map(int, sys.argv[1:4]); out = sys.argv[4]
y, x = np.mgrid[0:ny, 0:nx].astype(np.float32)
noise = np.random.default_rng(7).integers(0, 64, size=(8, ny, nx)).astype(np.float32)
with open(out, "wb") as f:
    for z in range(nz):
        r2 = ((x - nx/2)/(0.35*nx))**2 + ((y - ny/2)/(0.35*ny))**2 + ((z - nz/2)/(0.35*nz))**2
        v = 30000*np.exp(-2*r2) + 8000*np.sin(x*0.05)*np.cos(y*0.03 + z*0.02) + 10000 + noise[z % 8]
        f.write(v.astype(np.uint16).tobytes())
PY
"$V" convert "$tmp/v.raw" --raw-dims "$(IFS=,; echo "${dims[*]}")" --raw-type u16 \
  -o "$tmp/v.zarr" --zarr-version 3 -q
rm "$tmp/v.raw"
echo "store: $(du -sh "$tmp/v.zarr" | cut -f1) ($((SECONDS - t0)) s)"

# The reference: the same store's level 0 read whole, no cap.
"$V" render "$tmp/v.zarr" "${view[@]}" -o "$tmp/whole.png" -q
echo "in memory: done ($((SECONDS - t0)) s)"

# The capped run, through the first cap that can be set.
capped=()
limit=$((CAP_MIB << 20))
if [ "${CAP:-}" != as ] && [ -w /sys/fs/cgroup/cgroup.subtree_control ] \
   && grep -qw memory /sys/fs/cgroup/cgroup.controllers 2>/dev/null; then
  parent=/sys/fs/cgroup$(sed -n 's/^0:://p' /proc/self/cgroup)
  cg=$parent/volsplat-cap-$$
  if mkdir "$cg" 2>/dev/null && echo "$limit" >"$cg/memory.max" 2>/dev/null; then
    echo 0 >"$cg/memory.swap.max" 2>/dev/null || true
    capped=(sh -c 'echo $$ > "$1/cgroup.procs" && shift && exec "$@"' sh "$cg")
    echo "cap: cgroup v2 memory.max = $CAP_MIB MiB"
  else rmdir "$cg" 2>/dev/null || true; cg=""; fi
fi
if [ ${#capped[@]} = 0 ] && [ "${CAP:-}" != as ] && [ -d /sys/fs/cgroup/memory ]; then
  parent=/sys/fs/cgroup/memory$(sed -n 's/^[0-9]*:memory://p' /proc/self/cgroup)
  cg=$parent/volsplat-cap-$$
  if mkdir "$cg" 2>/dev/null && echo "$limit" >"$cg/memory.limit_in_bytes" 2>/dev/null; then
    echo "$limit" >"$cg/memory.memsw.limit_in_bytes" 2>/dev/null || true
    echo 0 >"$cg/memory.swappiness" 2>/dev/null || true
    capped=(sh -c 'echo $$ > "$1/cgroup.procs" && shift && exec "$@"' sh "$cg")
    echo "cap: cgroup v1 memory.limit_in_bytes = $CAP_MIB MiB"
  else rmdir "$cg" 2>/dev/null || true; cg=""; fi
fi
if [ ${#capped[@]} = 0 ]; then
  capped=(env MALLOC_ARENA_MAX=2 prlimit --as="$limit" --)
  echo "cap: prlimit --as = $CAP_MIB MiB (MALLOC_ARENA_MAX=2)"
fi
/usr/bin/time -f "%e %M" -o "$tmp/time" "${capped[@]}" "$V" render "$tmp/v.zarr" \
  --memory "$MEMORY" "${view[@]}" -o "$tmp/paged.png" 2>"$tmp/err" || {
  cat "$tmp/err" "$tmp/time" >&2; echo "FAIL: the capped out-of-core render failed" >&2; exit 1; }
read -r secs kb <"$tmp/time"
grep "out of core" "$tmp/err" || true
echo "capped render: ${secs} s, peak RSS $((kb / 1024)) MiB (cap $CAP_MIB MiB, --memory $MEMORY)"
if [ $((kb / 1024)) -gt "$CAP_MIB" ]; then echo "FAIL: peak RSS over the cap" >&2; exit 1; fi
cmp "$tmp/whole.png" "$tmp/paged.png" || { echo "FAIL: the PNGs differ" >&2; exit 1; }
echo "PASS: the same PNG bytes in memory and under the cap ($((SECONDS - t0)) s in all)"
