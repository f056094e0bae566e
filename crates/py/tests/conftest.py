"""Shared fixtures: small test volumes, a NIfTI writer, and the command-line binary."""

from __future__ import annotations

import os
import shutil
import struct
import subprocess
from pathlib import Path
from typing import List, Optional

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[3]


def find_cli() -> Optional[List[str]]:
    """The `volsplat` binary: $VOLSPLAT_CLI, else target/release/volsplat of this checkout."""
    env = os.environ.get("VOLSPLAT_CLI")
    if env:
        return [env]
    for name in ("volsplat", "volsplat.exe"):
        p = REPO / "target" / "release" / name
        if p.is_file():
            return [str(p)]
    found = shutil.which("volsplat")
    return [found] if found else None


@pytest.fixture(scope="session")
def cli():
    """Runs the command line: ``cli("render", ..., cwd=...)``; skips (or fails when
    VOLSPLAT_REQUIRE_CLI=1, as in CI) if the binary is missing."""
    cmd = find_cli()
    if cmd is None:
        msg = (
            "the volsplat binary was not found: build it with `cargo build --release` at the "
            "repository root or set VOLSPLAT_CLI"
        )
        if os.environ.get("VOLSPLAT_REQUIRE_CLI") == "1":
            pytest.fail(msg)
        pytest.skip(msg)

    def run(*args: str, cwd: Optional[Path] = None) -> subprocess.CompletedProcess:
        r = subprocess.run(
            cmd + [str(a) for a in args], cwd=cwd, capture_output=True, text=True, timeout=600
        )
        if r.returncode != 0:
            raise AssertionError(f"volsplat {' '.join(map(str, args))} failed:\n{r.stderr}")
        return r

    return run


def blob(shape_zyx=(24, 28, 32), dtype=np.float32, seed=0) -> np.ndarray:
    """A smooth (z, y, x) volume with some structure along every axis (not symmetric)."""
    z, y, x = np.meshgrid(*(np.linspace(-1, 1, n) for n in shape_zyx), indexing="ij")
    f = np.exp(-((x - 0.2) ** 2 + (y + 0.1) ** 2 * 2 + (z - 0.3) ** 2 * 3) * 4)
    f += 0.6 * np.exp(-((x + 0.5) ** 2 + (y - 0.4) ** 2 + (z + 0.2) ** 2) * 10)
    rng = np.random.default_rng(seed)
    f += 0.02 * rng.random(shape_zyx)
    info = np.iinfo(dtype) if np.issubdtype(dtype, np.integer) else None
    if info is not None:
        lo = max(info.min, -1000)
        hi = min(info.max, 3000)
        f = lo + (hi - lo) * f / f.max()
        return np.round(f).astype(dtype)
    return (1000.0 * f).astype(dtype)


@pytest.fixture
def volume_zyx() -> np.ndarray:
    return blob()


def write_nifti(path: Path, data_xyz: np.ndarray, affine_ras: np.ndarray) -> None:
    """A minimal NIfTI-1 file (.nii): sform = ``affine_ras``, data in (x, y, z) order."""
    codes = {
        np.dtype(np.uint8): 2,
        np.dtype(np.int16): 4,
        np.dtype(np.float32): 16,
        np.dtype(np.uint16): 512,
        np.dtype(np.int8): 256,
    }
    dt = data_xyz.dtype
    hdr = bytearray(348)
    struct.pack_into("<i", hdr, 0, 348)
    struct.pack_into("<8h", hdr, 40, 3, *data_xyz.shape, 1, 1, 1, 1)
    struct.pack_into("<h", hdr, 70, codes[dt])
    struct.pack_into("<h", hdr, 72, dt.itemsize * 8)
    zooms = np.linalg.norm(affine_ras[:3, :3], axis=0)
    struct.pack_into("<8f", hdr, 76, 1.0, *zooms, 1, 1, 1, 1)
    struct.pack_into("<f", hdr, 108, 352.0)
    struct.pack_into("<f", hdr, 112, 0.0)
    hdr[123] = 2  # mm
    struct.pack_into("<h", hdr, 252, 0)  # qform_code
    struct.pack_into("<h", hdr, 254, 1)  # sform_code
    for r in range(3):
        struct.pack_into("<4f", hdr, 280 + 16 * r, *affine_ras[r].astype(np.float32))
    hdr[344:348] = b"n+1\x00"
    with open(path, "wb") as f:
        f.write(bytes(hdr))
        f.write(b"\x00" * 4)
        f.write(np.asarray(data_xyz, dtype=dt.newbyteorder("<")).ravel(order="F").tobytes())
