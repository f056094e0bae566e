#!/usr/bin/env bash
# VTK parity check: renders real and phantom volumes with volsplat and with VTK's CPU ray caster
# (vtkFixedPointVolumeRayCastMapper) from the same camera and transfer-function files, lit at the
# voxels as VTK lights them, and requires structural similarity ≥ 0.98. Installs VTK (PyPI, into the virtual environment
# target/vtk-venv or $VTK_VENV) and Xvfb (Debian) if missing; if
# they cannot be installed it says SKIPPED and exits 0.
#
#   bash tools/vtk_parity.sh [path/to/volsplat]
#   KEEP=/tmp/parity bash tools/vtk_parity.sh && \
#     python3 tools/vtk_compare.py --montage docs/figures/vtk-parity.png /tmp/parity/{mr,head,colin}
set -euo pipefail
cd "$(dirname "$0")/.."
bin="${1:-target/release/volsplat}"
data="../shared/data"
# VTK and numpy live in their own virtual environment (kept under target/, reused between runs).
venv="${VTK_VENV:-target/vtk-venv}"
if ! "$venv/bin/python" -c "import vtk, numpy" >/dev/null 2>&1; then
  { python3 -m venv "$venv" && "$venv/bin/pip" install -q vtk numpy; } >/dev/null 2>&1 \
    || { echo "SKIPPED: VTK parity (could not install vtk from PyPI into $venv)"; exit 0; }
fi
python3() { "$venv/bin/python" "$@"; }
if ! command -v xvfb-run >/dev/null 2>&1; then
  (apt-get update -qq && apt-get install -y -qq xvfb) >/dev/null 2>&1 || { echo "SKIPPED: VTK parity (could not install xvfb)"; exit 0; }
fi
if [ -n "${KEEP:-}" ]; then
  work="$KEEP"; mkdir -p "$work"          # keep the images (e.g. for docs/figures/vtk-parity.png)
else
  work="$(mktemp -d)"; trap 'rm -rf "$work"' EXIT
fi
cp docs/bench/parity/*.json "$work/"
"$bin" phantom head --grid 120,150,135 -o "$work/head.nrrd" 2>/dev/null
cases=("head bone $work/head.nrrd 30 20 1.0" "skin skin $work/head.nrrd -40 10 1.3")
if [ -f "$data/mri_brainsmall.nrrd" ]; then cases+=("mr mr $data/mri_brainsmall.nrrd 30 20 1.0"); fi
if [ -f "$data/mri_colin27.nhdr" ]; then
  cases+=("colin colin $data/mri_colin27.nhdr 120 15 1.2")
  # Issue 17: square images at azimuth 30° and 45° were black (NaN footprints).
  cases+=("colin_az30 colin $data/mri_colin27.nhdr 30 0 1.0" "colin_az45 colin $data/mri_colin27.nhdr 45 0 1.0")
fi
fail=0
for c in "${cases[@]}"; do
  set -- $c
  # `--shade-at voxels`: VTK's order of lighting, the parity mode (the default lights the
  # samples, closer to the exact integral and further from VTK's picture; decision 0036).
  "$bin" render "$3" --tf "$work/$2_tf.json" --azimuth "$4" --elevation "$5" --zoom "$6" --linear \
    --shade-at voxels -q -o "$work/$1.vs.png" --save-camera "$work/$1_cam.json"
  xvfb-run -a "$venv/bin/python" tools/vtk_compare.py "$3" "$work/$1_cam.json" "$work/$2_tf.json" "$work/$1" --frames 1 >/dev/null
  ssim=$(python3 tools/vtk_compare.py --ssim "$work/$1.vtk.png" "$work/$1.vs.png" | python3 -c "import json,sys; print(json.load(sys.stdin)['ssim_luma'])")
  ok=$(python3 -c "print(int($ssim >= 0.98))")
  echo "VTK parity $1: SSIM $ssim $([ "$ok" = 1 ] && echo ok || echo FAIL)"
  [ "$ok" = 1 ] || fail=1
done
exit $fail
