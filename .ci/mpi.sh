#!/usr/bin/env bash
# Sort-last rendering across MPI processes (issue 32, decision 0038): Debian's Open MPI and
# libclang (rsmpi's bindings), the crate's formatting and lints, then `mpirun -np 1/2/3/4` on
# scene files in both projections, whose images must be the same bytes for every rank count,
# and a missing volume, which must stop every rank with an error, not hang. crates/mpi is a
# workspace of its own (the root's `exclude`), so `cargo test --workspace` never needs MPI.
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
cargo fmt --manifest-path crates/mpi/Cargo.toml -- --check
cargo clippy --release --manifest-path crates/mpi/Cargo.toml --all-targets -- -D warnings
cargo build --release --manifest-path crates/mpi/Cargo.toml
cargo build --release -p volsplat-cli

step "mpi: the same image for 1, 2, 3 and 4 ranks"
bin="$PWD/target/release/volsplat"
mpi="$PWD/crates/mpi/target/release/volsplat-mpi"
work="$(mktemp -d)"; trap 'rm -rf "$work"' EXIT
run() { timeout 300 mpirun --allow-run-as-root --oversubscribe -np "$@"; }
for view in "--azimuth 30 --elevation 15" "--azimuth -50 --elevation 20 --perspective"; do
  # shellcheck disable=SC2086
  "$bin" render --size 96x80 $view --save-scene "$work/s.json" -q -o "$work/whole.npy"
  for n in 1 2 3 4; do
    run "$n" "$mpi" render --scene "$work/s.json" --brick 32 -o "$work/out$n.npy"
  done
  for n in 2 3 4; do
    cmp "$work/out1.npy" "$work/out$n.npy" || { echo "FAIL: $n ranks differ from 1 ($view)"; exit 1; }
  done
  echo "ok: 1–4 ranks give the same bytes ($view)"
done

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
