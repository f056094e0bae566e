#!/usr/bin/env bash
# Sort-last rendering across MPI processes (issue 32, decision 0038): Debian's Open MPI and
# libclang (rsmpi's bindings), the crate's formatting and lints, then `mpirun -np 1/2/3/4` on
# scene files in both projections, composite, X-ray, MIP and MinIP, whose images must be the same
# bytes for every rank count (the X-ray within 60 dB of one process, MIP and MinIP the same bytes
# as one process); ranks reading only their bricks of an OME-Zarr store and of a raw NRRD file
# in every mode (the bytes of the gzip NRRD read whole; X-ray: the same bytes for np 1-4 and
# within 60 dB of the gzip NRRD read whole; each rank's reads checked); a missing volume, and one rank's truncated volume (the others' reads
# succeed), which must stop every rank with an error naming the file, not hang (each mpirun runs
# under `timeout`). crates/mpi is a workspace of its own (the root's `exclude`), so `cargo test
# --workspace` never needs MPI.
set -euo pipefail
cd "$(dirname "$0")/.."
export CARGO_TERM_COLOR=never
export CARGO_INCREMENTAL=0

step() { echo; echo "=== $* ==="; }

step "mpi: Open MPI and libclang"
if ! command -v mpirun >/dev/null 2>&1 || ! ls /usr/lib/llvm-*/lib/libclang*.so* >/dev/null 2>&1; then
  sudo_="$(command -v sudo || true)"
  $sudo_ apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo_ apt-get install -y -qq libopenmpi-dev openmpi-bin libclang-dev
fi
mpirun --version | head -1

step "mpi: fmt, clippy, build"
# The crate's build shares the root's target folder: its Cargo.lock pins the root's versions
# (copy the root's Cargo.lock over it after `cargo update`), so the engine and its dependencies
# built by the root's clippy and `cargo test --release` are reused instead of built again
# (about 1 min instead of several on 2 cores). Clippy runs in the dev profile, as the root's.
export CARGO_TARGET_DIR="$PWD/target"
cargo fmt --manifest-path crates/mpi/Cargo.toml -- --check
cargo clippy --manifest-path crates/mpi/Cargo.toml --all-targets -- -D warnings
cargo build --release --manifest-path crates/mpi/Cargo.toml
cargo build --release -p volsplat-cli

step "mpi: the same image for 1, 2, 3 and 4 ranks"
bin="$PWD/target/release/volsplat"
mpi="$PWD/target/release/volsplat-mpi"
work="$(mktemp -d)"; trap 'rm -rf "$work"' EXIT
run() { timeout 300 mpirun --allow-run-as-root --oversubscribe -np "$@"; }
# The PSNR of summed line integrals (argument 1) against a reference X-ray (argument 2, what it
# is: argument 3): at least 60 dB.
cat > "$work/psnr.py" <<'PY'
import math, struct, sys
def npy(path):
    b = open(path, "rb").read()
    n = struct.unpack("<H", b[8:10])[0]
    body = b[10 + n:]
    return struct.unpack("<%df" % (len(body) // 4), body)
a, w = npy(sys.argv[1]), npy(sys.argv[2])
assert len(a) == len(w), (len(a), len(w))
mse = sum((x - y) ** 2 for x, y in zip(a, w)) / len(w)
peak = max(w)
psnr = 10 * math.log10(peak * peak / mse) if mse > 0 else float("inf")
what = sys.argv[3] if len(sys.argv) > 3 else "one process"
print(f"X-ray: {psnr:.1f} dB from {what}")
assert peak > 0 and psnr >= 60, psnr
PY
for mode in composite xray mip minip; do
  for view in "--azimuth 30 --elevation 15" "--azimuth -50 --elevation 20 --perspective"; do
    # MIP/MinIP: one ray per pixel, as sort-last draws, so that the bytes can be compared.
    aa=""; case "$mode" in mip|minip) aa="--antialias none";; esac
    # shellcheck disable=SC2086
    "$bin" render --mode "$mode" --size 96x80 $view $aa --save-scene "$work/s.json" -q -o "$work/whole.npy"
    for n in 1 2 3 4; do
      run "$n" "$mpi" render --scene "$work/s.json" --brick 32 -o "$work/out$n.npy"
    done
    for n in 2 3 4; do
      cmp "$work/out1.npy" "$work/out$n.npy" || { echo "FAIL: $n ranks differ from 1 ($mode $view)"; exit 1; }
    done
    if [ "$mode" = xray ]; then
      # The summed line integrals against the single-process X-ray (the same request).
      python3 "$work/psnr.py" "$work/out1.npy" "$work/whole.npy"
    fi
    if [ "$mode" = mip ] || [ "$mode" = minip ]; then
      cmp "$work/out1.npy" "$work/whole.npy" || { echo "FAIL: $mode differs from one process ($view)"; exit 1; }
      echo "ok: $mode is the single-process projection, byte for byte ($view)"
    fi
    echo "ok: 1–4 ranks give the same bytes ($mode $view)"
  done
done

step "mpi: ranks read only their bricks of an OME-Zarr store and of a NRRD raw file"
# The demo head as a store, as a raw NRRD and as a gzip NRRD: from the store and the raw NRRD
# each rank reads only the bricks of its part (it prints what it read: from the NRRD also the
# bytes read from the file); the gzip NRRD has no random access and is read whole by every rank
# (the in-memory sort-last render of the same samples). The bytes are the same for np 1-4 and
# the same as the ranks reading the gzip NRRD whole.
"$bin" convert -o "$work/head.zarr" -q
"$bin" convert -o "$work/head.nrrd" -q
"$bin" convert -o "$work/headgz.nrrd" --gzip -q
cat > "$work/reads.py" <<'PY'
import re, sys
# mpirun may interleave the ranks' lines: match the records, not the lines.
pat = (r"rank (\d+) of \d+: read (\d+) of (\d+) bricks of \d+. cells: scan_bytes=(\d+) "
       r"\([^)]*\), frame_bytes=(\d+) \([^)]*\), level_bytes=(\d+) \([^)]*\)"
       r"(?:, scan_file_bytes=(\d+) \([^)]*\), frame_file_bytes=(\d+))?")
text = open(sys.argv[1]).read()
recs = re.findall(pat, text)
n, nrrd = int(sys.argv[2]), sys.argv[3] == "nrrd"
if n == 0:
    assert not recs, "a rank read in bricks a file it must read whole: %s" % (recs,)
    sys.exit(0)
assert sorted(int(r[0]) for r in recs) == list(range(n)), recs
total = 0
for r in recs:
    rank, mine, level, scan, frame, whole = map(int, r[:6])
    total += mine
    assert frame <= scan, r
    if n > 1:
        assert mine < level and scan < whole, r
    # From the NRRD file: the bytes read from the file, the scan's less than the file's
    # samples with several ranks (no rank reads the whole file), the frame's no more.
    assert (r[6] != "") == nrrd, r
    if nrrd:
        scan_file, frame_file = int(r[6]), int(r[7])
        assert frame_file <= scan_file, r
        if n > 1:
            assert scan_file < whole, r
assert total == level, (total, level)
print("np=%d %s: %s" % (n, sys.argv[3], "; ".join(
    "rank %s read %s/%s bricks, scan %s B, frame %s B of a %s B level%s" % (
        r[0], r[1], r[2], r[3], r[4], r[5],
        ", %s B and %s B of the file" % (r[6], r[7]) if r[6] else "")
    for r in sorted(recs))))
PY
for mode in composite xray mip minip; do
  for view in "--azimuth 30 --elevation 15" "--azimuth -50 --elevation 20 --perspective"; do
    # shellcheck disable=SC2086
    "$bin" render "$work/head.zarr" --mode "$mode" --size 96x80 $view --save-scene "$work/z.json" -q -o "$work/z.png"
    python3 - "$work/z.json" "$work" <<'PY'
import json, sys
for name, out in [("head.nrrd", "zn.json"), ("headgz.nrrd", "zg.json")]:
    s = json.load(open(sys.argv[1]))
    s["scene"]["volume"] = {"file": {"path": sys.argv[2] + "/" + name}}
    json.dump(s, open(sys.argv[2] + "/" + out, "w"))
PY
    run 2 "$mpi" render --scene "$work/zg.json" --brick 32 -o "$work/whole.npy" 2> "$work/gz.txt"
    python3 "$work/reads.py" "$work/gz.txt" 0 gzip
    for n in 1 2 3 4; do
      run "$n" "$mpi" render --scene "$work/z.json" --brick 32 -o "$work/z$n.npy" 2> "$work/reads$n.txt"
      run "$n" "$mpi" render --scene "$work/zn.json" --brick 32 -o "$work/n$n.npy" 2> "$work/nreads$n.txt"
      if [ "$mode" = xray ]; then
        # X-ray per rank draws each brick's voxels as a sub-volume (decision 0038): the same
        # bytes for every np, from the store as from the raw NRRD, and within 60 dB of the
        # ranks reading the gzip NRRD whole (which draw the bricks from the whole volume).
        cmp "$work/z1.npy" "$work/z$n.npy" || { echo "FAIL: np=$n from the store differs from np=1 ($mode $view)"; exit 1; }
        cmp "$work/z1.npy" "$work/n$n.npy" || { echo "FAIL: np=$n from the raw NRRD differs from the store ($mode $view)"; exit 1; }
        python3 "$work/psnr.py" "$work/z$n.npy" "$work/whole.npy" "the gzip NRRD read whole (np=$n)"
      else
        cmp "$work/whole.npy" "$work/z$n.npy" || { echo "FAIL: np=$n from the store differs from the NRRD read whole ($mode $view)"; exit 1; }
        cmp "$work/whole.npy" "$work/n$n.npy" || { echo "FAIL: np=$n from the raw NRRD differs from the NRRD read whole ($mode $view)"; exit 1; }
      fi
      # Every rank read its part only: the parts' bricks add up to the level's, and with
      # several ranks each read less than the level (from the NRRD: less than the file).
      python3 "$work/reads.py" "$work/reads$n.txt" "$n" store
      python3 "$work/reads.py" "$work/nreads$n.txt" "$n" nrrd
    done
    echo "ok: np 1-4 read their bricks of the store and of the raw NRRD, the same bytes for every np (and as the gzip NRRD read whole; X-ray: within 60 dB of it) ($mode $view)"
  done
done

step "mpi: volsplat render's and volsplat movie's own arguments"
# `volsplat-mpi render FILE [render flags] -o OUT` (issue 32's form): the bytes of the same
# flags saved as a scene and given as --scene, for 1 and 3 ranks.
"$bin" convert --phantom head --phantom-size 48,40,36 -q -o "$work/f.nrrd"
flags=(--mode composite --preset CT-Bone --azimuth -40 --elevation 25 --size 80x64)
"$bin" render "$work/f.nrrd" "${flags[@]}" --antialias none --save-scene "$work/f.json" -q -o "$work/f_whole.png"
run 1 "$mpi" render "$work/f.nrrd" "${flags[@]}" -o "$work/f1.png" --brick 16 2>/dev/null
run 3 "$mpi" render "$work/f.nrrd" "${flags[@]}" -o "$work/f3.png" --brick=16 2>/dev/null
run 2 "$mpi" render --scene "$work/f.json" -o "$work/fs.png" --brick 16 2>/dev/null
cmp "$work/f1.png" "$work/f3.png" && cmp "$work/f1.png" "$work/fs.png" \
  || { echo "FAIL: render flags and --scene differ, or 1 and 3 ranks"; exit 1; }
if run 2 "$mpi" render "$work/f.nrrd" --bogus -o "$work/x.png" 2> "$work/err.txt"; then
  echo "FAIL: an unknown flag rendered"; exit 1
fi
grep -q -- "--bogus" "$work/err.txt" || { cat "$work/err.txt"; echo "FAIL: the error does not name the flag"; exit 1; }
echo "ok: render's own flags, --scene and 1/3 ranks give the same bytes; a bad flag is named"
# `volsplat-mpi movie`: a 3-frame turntable, the same frame bytes for 1 and 3 ranks.
for n in 1 3; do
  run "$n" "$mpi" movie "$work/f.nrrd" --preset CT-Bone --frames 3 --degrees 90 --size 64x48 -q -o "$work/mv$n/" --brick 16 2>/dev/null
done
[ "$(ls "$work/mv1" | wc -l)" = 3 ] || { ls "$work/mv1"; echo "FAIL: not 3 frames"; exit 1; }
for f in "$work"/mv1/*.png; do
  cmp "$f" "$work/mv3/$(basename "$f")" || { echo "FAIL: movie frame $f differs between 1 and 3 ranks"; exit 1; }
done
echo "ok: movie frames are the same bytes for 1 and 3 ranks"

step "mpi: a rank that cannot read its volume stops every rank"
"$bin" render --phantom-size 40 --save-scene "$work/bad0.json" -q -o "$work/b.png"
python3 - "$work/bad0.json" "$work/bad.json" "$work/missing.nrrd" <<'PY'
import json, sys
s = json.load(open(sys.argv[1]))
s["scene"]["volume"] = {"file": {"path": sys.argv[3]}}
json.dump(s, open(sys.argv[2], "w"))
PY
if run 2 "$mpi" render --scene "$work/bad.json" -o "$work/bad.npy" 2> "$work/err.txt"; then
  echo "FAIL: a missing volume rendered"; exit 1
fi
grep -q "missing.nrrd" "$work/err.txt" || { cat "$work/err.txt"; echo "FAIL: the error does not name the file"; exit 1; }
[ ! -e "$work/bad.npy" ] || { echo "FAIL: an output was written"; exit 1; }
echo "ok: every rank stopped with an error naming the file"

step "mpi: one rank whose volume read fails stops every rank"
# MPMD: every rank gets the same scene except one, whose volume file is truncated, so that only
# its read fails (a real read error, no test hook); the others load and render, and must learn
# of it in the exchange instead of waiting for its images.
"$bin" convert -o "$work/vol.nrrd" -q
head -c 20000 "$work/vol.nrrd" > "$work/trunc.nrrd"
"$bin" render "$work/vol.nrrd" --size 64x48 --save-scene "$work/ok.json" -q -o "$work/b.png"
python3 - "$work/ok.json" "$work/one_bad.json" "$work/trunc.nrrd" <<'PY'
import json, sys
s = json.load(open(sys.argv[1]))
s["scene"]["volume"] = {"file": {"path": sys.argv[3]}}
json.dump(s, open(sys.argv[2], "w"))
PY
run 2 "$mpi" render --scene "$work/ok.json" --brick 16 -o "$work/ok.npy" \
  || { echo "FAIL: the good volume did not render"; exit 1; }
for n in 2 3 4; do
  for bad in 0 $((n - 1)); do
    spec=()
    for ((r = 0; r < n; r++)); do
      [ "$r" -gt 0 ] && spec+=(:)
      scene="$work/ok.json"; [ "$r" -eq "$bad" ] && scene="$work/one_bad.json"
      spec+=(-np 1 "$mpi" render --scene "$scene" --brick 16 -o "$work/one.npy")
    done
    set +e
    # --tag-output: each rank's lines whole and tagged [job,rank] (untagged, the ranks' lines
    # on the shared stderr can interleave mid-line).
    timeout 120 mpirun --allow-run-as-root --oversubscribe --tag-output "${spec[@]}" \
      2> "$work/err.txt"
    rc=$?
    set -e
    [ "$rc" -ne 124 ] || { echo "FAIL: np=$n, rank $bad failing: mpirun hung (timeout)"; exit 1; }
    [ "$rc" -ne 0 ] || { echo "FAIL: np=$n, rank $bad failing: exit 0"; exit 1; }
    got=$(grep "rank $bad failed: .*trunc.nrrd" "$work/err.txt" \
      | sed -n 's/^\[[0-9]*,\([0-9]*\)\].*/\1/p' | sort -u | wc -l)
    [ "$got" -eq "$n" ] || { cat "$work/err.txt"; echo "FAIL: np=$n: $got of $n ranks named rank $bad and the file"; exit 1; }
    [ ! -e "$work/one.npy" ] || { echo "FAIL: an output was written"; exit 1; }
  done
  echo "ok: np=$n, rank 0 or rank $((n - 1)) failing its read: every rank named it, none hung"
done
