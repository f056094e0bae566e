#!/usr/bin/env bash
# The Python package (issue 14): a fresh virtual environment, `pip install ./crates/py pytest`,
# then the pytest suite, whose parity tests run the `volsplat` binary on the same scenes and
# compare bytes, and whose issue-28 tests run interpreters under address-space limits
# (RLIMIT_AS) to check that oversized volumes raise MemoryError. Works from a clean clone with
# the Rust toolchain, python3 (with venv) and the package registries (PyPI for maturin, numpy,
# pytest, nibabel; crates.io for pyo3).
set -euo pipefail
cd "$(dirname "$0")/.."
export CARGO_TERM_COLOR=never
export CARGO_INCREMENTAL=0

step() { echo; echo "=== $* ==="; }

python="${PYTHON:-python3}"
venv="target/py-venv-ci"

step "python: fresh virtual environment ($("$python" --version))"
"$python" -m venv --clear "$venv"
"$venv/bin/python" -m pip install --quiet --progress-bar off --upgrade pip

step "python: pip install ./crates/py pytest nibabel"
# nibabel (pure Python) for the tests that compare nibabel's affines with the NIfTI reader (they
# are skipped without it). The extension builds with its own Cargo workspace (crates/py is in
# the root's `exclude`); keep its build folder under target/ rather than in the source tree.
CARGO_TARGET_DIR="$PWD/target/py" "$venv/bin/python" -m pip install --progress-bar off ./crates/py pytest nibabel

step "python: the command line for the parity tests"
# A no-op after .ci/run's release build.
cargo build --release -p volsplat-cli

step "python: pytest crates/py/tests"
# crates/py/python is not on sys.path: `import volsplat` is the installed package.
export VOLSPLAT_CLI="$PWD/target/release/volsplat"
export VOLSPLAT_REQUIRE_CLI=1
"$venv/bin/python" -m pytest "$PWD/crates/py/tests" -q -p no:cacheprovider --rootdir "$PWD/crates/py"
