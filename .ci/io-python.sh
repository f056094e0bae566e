#!/usr/bin/env bash
# The volume writers and readers against the peer libraries (issue 28 §5): nibabel, SimpleITK and
# pynrrd read what `volsplat convert` writes, and volsplat reads what they write
# (crates/io/tests/python/test_roundtrip.py); zarr and ome-zarr-py read what `convert -o X.zarr`
# writes and volsplat reads their OME-Zarr stores (test_zarr_roundtrip.py; issue 31). A fresh
# virtual environment from PyPI.
set -euo pipefail
cd "$(dirname "$0")/.."
python="${PYTHON:-python3}"
venv="target/io-venv-ci"
"$python" -m venv --clear "$venv"
"$venv/bin/python" -m pip install --quiet --progress-bar off --upgrade pip
"$venv/bin/python" -m pip install --quiet --progress-bar off pytest numpy nibabel SimpleITK pynrrd zarr ome-zarr
cargo build --release -p volsplat-cli
VOLSPLAT_BIN="$PWD/target/release/volsplat" \
  "$venv/bin/python" -m pytest crates/io/tests/python -q -p no:cacheprovider
