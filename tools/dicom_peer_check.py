#!/usr/bin/env python3
"""Reads DICOM files with volsplat and with pydicom and compares what each got (issue 28).

For every DICOM file found (by default the test files that ship inside the pydicom and nibabel
wheels), the script runs `volsplat info --json FILE` and `volsplat convert FILE -o x.npy`, reads
the same file with pydicom (pixel array with the modality rescale per frame, PALETTE COLOR
through its palette, frames sorted along the slice normal as volsplat sorts them) and sorts the
outcome into:

  matched        both read it; same shape, same samples (lossy syntaxes: within 1 % of the
                 range or 2 grey levels, decoders differ), same spacing and origin
  wrong          both read it, and something differs: a silent surprise (listed in full)
  refused        volsplat refuses a file pydicom reads (with volsplat's message)
  colour         a colour image (RGB, YBR, colour palette): pydicom reads it, volsplat must
                 refuse it with a clear error (it does when counted here)
  both-refuse    neither reads it (pydicom fails)
  no-image       no pixel data (DICOMDIR, reports, plans): nothing to compare
  extra          volsplat reads a file pydicom cannot
  crash          volsplat died by a signal or ran past the time limit

Two modes: `alone` copies each file into a folder of its own (what the file holds); `in-place`
reads it where it lies, beside its siblings (volsplat reads a file's series from its folder).

Setup (the peer side; nothing here is needed to build or test volsplat):

    python3 -m venv /tmp/dcmvenv
    /tmp/dcmvenv/bin/pip install pydicom nibabel numpy pylibjpeg pylibjpeg-openjpeg \
        pylibjpeg-libjpeg pyjpegls
    cargo build --release -p volsplat-cli
    /tmp/dcmvenv/bin/python tools/dicom_peer_check.py [--bin target/release/volsplat] [PATH ...]

The peers' files are read where pip installed them and are not copied into this repository.
"""

from __future__ import annotations

import argparse
import gzip
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

try:
    import pydicom
    from pydicom.pixels import apply_color_lut
except ImportError:  # pragma: no cover
    sys.exit("pydicom is needed: see the setup in this script's docstring")

LOSSY = {
    "1.2.840.10008.1.2.4.50",
    "1.2.840.10008.1.2.4.51",
    "1.2.840.10008.1.2.4.81",
    "1.2.840.10008.1.2.4.91",
    "1.2.840.10008.1.2.4.203",
}


def default_paths() -> list[Path]:
    paths = []
    import pydicom.data

    paths.append(Path(pydicom.data.__file__).parent / "test_files")
    try:
        import nibabel.nicom

        paths.append(Path(nibabel.nicom.__file__).parent / "tests" / "data")
    except ImportError:
        pass
    return paths


def is_dicom(p: Path) -> bool:
    try:
        with open(p, "rb") as f:
            head = f.read(132)
    except OSError:
        return False
    return head[128:132] == b"DICM" or head[:4] == b"DICM"


def candidates(paths: list[Path], gz_dir: Path) -> list[Path]:
    """DICOM files under `paths` (gzipped ones are unpacked into `gz_dir`); files without the
    DICM magic that pydicom still reads (no meta group) are kept too."""
    out = []
    for root in paths:
        files = sorted(root.rglob("*")) if root.is_dir() else [root]
        for p in files:
            if not p.is_file():
                continue
            if p.suffix == ".gz":
                try:
                    data = gzip.decompress(p.read_bytes())
                except OSError:
                    continue
                q = gz_dir / p.name[:-3]
                q.write_bytes(data)
                p = q
            if p.suffix in {".txt", ".json", ".bin", ".icc", ".dump", ".py"}:
                continue
            if is_dicom(p):
                out.append(p)
            else:
                try:
                    pydicom.dcmread(p, force=True, stop_before_pixels=True)
                    if p.suffix == ".dcm":
                        out.append(p)
                except Exception:
                    pass
    return out


def frame_params(ds, n: int):
    """Per frame: (position, orientation, pixel spacing, slope, intercept)."""
    def attr(item, seq, name):
        if item is not None and seq in item and len(item[seq].value) > 0:
            it = item[seq].value[0]
            if name in it:
                return it[name].value
        return None

    shared = ds.SharedFunctionalGroupsSequence[0] if "SharedFunctionalGroupsSequence" in ds else None
    per = ds.PerFrameFunctionalGroupsSequence if "PerFrameFunctionalGroupsSequence" in ds else None
    offsets = None
    if "GridFrameOffsetVector" in ds and per is None and n > 1:
        offsets = [float(x) for x in ds.GridFrameOffsetVector]
    out = []
    for k in range(n):
        pf = per[k] if per is not None and k < len(per) else None

        def get(seq, name):
            v = attr(pf, seq, name)
            if v is None:
                v = attr(shared, seq, name)
            if v is None and name in ds:
                v = ds[name].value
            return v

        ipp = get("PlanePositionSequence", "ImagePositionPatient")
        iop = get("PlaneOrientationSequence", "ImageOrientationPatient")
        ps = get("PixelMeasuresSequence", "PixelSpacing")
        slope = get("PixelValueTransformationSequence", "RescaleSlope")
        icpt = get("PixelValueTransformationSequence", "RescaleIntercept")
        ipp = [float(x) for x in ipp] if ipp is not None and len(ipp) == 3 else None
        iop = [float(x) for x in iop] if iop is not None and len(iop) == 6 else None
        if offsets is not None and ipp is not None and iop is not None and len(offsets) == n:
            nrm = np.cross(iop[:3], iop[3:])
            ipp = list(np.array(ipp) + offsets[k] * nrm)
        out.append(
            (
                ipp,
                iop,
                [float(x) for x in ps] if ps is not None and len(ps) == 2 else None,
                float(slope) if slope not in (None, "") else 1.0,
                float(icpt) if icpt not in (None, "") else 0.0,
            )
        )
    return out


def peer_read(p: Path):
    """pydicom's reading: dict with samples (frames, rows, cols) sorted along the normal,
    spacing, origin; or ('colour', why) / ('refuse', why)."""
    try:
        ds = pydicom.dcmread(p, force=True)
    except Exception as e:
        return ("refuse", f"dcmread: {e}")
    if "PixelData" not in ds:
        return ("no-image", "no PixelData")
    try:
        arr = ds.pixel_array
    except Exception as e:
        return ("refuse", f"pixel_array: {e}")
    spp = int(ds.get("SamplesPerPixel", 1))
    pi = str(ds.get("PhotometricInterpretation", ""))
    n = int(ds.get("NumberOfFrames", 1) or 1)
    if spp != 1:
        return ("colour", f"SamplesPerPixel {spp} ({pi})")
    if pi == "PALETTE COLOR":
        try:
            rgb = apply_color_lut(arr, ds)
        except Exception as e:
            return ("refuse", f"palette: {e}")
        if not (np.array_equal(rgb[..., 0], rgb[..., 1]) and np.array_equal(rgb[..., 0], rgb[..., 2])):
            return ("colour", "PALETTE COLOR with a colour palette")
        arr = rgb[..., 0]
    if n == 1:
        arr = arr[None]
    if arr.ndim != 3:
        return ("refuse", f"pixel array of shape {arr.shape}")
    params = frame_params(ds, arr.shape[0])
    vals = np.empty(arr.shape, dtype=np.float64)
    # RT Dose: volsplat applies DoseGridScaling (PS3.3 C.8.8.3); pydicom's array does not.
    dose = float(ds.DoseGridScaling) if "DoseGridScaling" in ds else 1.0
    for k in range(arr.shape[0]):
        _, _, _, slope, icpt = params[k]
        if pi == "PALETTE COLOR":
            slope, icpt = 1.0, 0.0
        vals[k] = arr[k].astype(np.float64) * slope * dose + icpt
    have = all(q[0] is not None and q[1] is not None for q in params)
    origin = spacing = None
    positions = None
    if have:
        iop = params[0][1]
        nrm = np.cross(iop[:3], iop[3:])
        s = np.array([np.dot(q[0], nrm) for q in params])
        order = np.argsort(s, kind="stable")
        vals = vals[order]
        origin = params[order[0]][0]
        positions = [params[k][0] for k in order]
        ps = params[0][2] or [1.0, 1.0]
        dz = (s[order[-1]] - s[order[0]]) / (len(s) - 1) if len(s) > 1 else None
        spacing = [ps[1], ps[0], dz]
    ts = str(getattr(ds.file_meta, "TransferSyntaxUID", "")) if hasattr(ds, "file_meta") else ""
    return {"values": vals, "origin": origin, "spacing": spacing, "ts": ts, "positions": positions}


def volsplat_read(binary: str, p: Path, work: Path, timeout: float):
    npy = work / "out.npy"
    if npy.exists():
        npy.unlink()
    try:
        info = subprocess.run(
            [binary, "info", "--json", str(p)], capture_output=True, text=True, timeout=timeout
        )
    except subprocess.TimeoutExpired:
        return ("crash", f"info ran past {timeout} s")
    if info.returncode < 0:
        return ("crash", f"info killed by signal {-info.returncode}")
    if info.returncode != 0:
        msg = (info.stderr.strip().splitlines() or ["(no message)"])[-1]
        return ("refuse", msg)
    try:
        conv = subprocess.run(
            [binary, "convert", str(p), "-o", str(npy), "--quiet"],
            capture_output=True,
            text=True,
            timeout=timeout,
        )
    except subprocess.TimeoutExpired:
        return ("crash", f"convert ran past {timeout} s")
    if conv.returncode < 0:
        return ("crash", f"convert killed by signal {-conv.returncode}")
    if conv.returncode != 0:
        return ("refuse", (conv.stderr.strip().splitlines() or ["?"])[-1])
    j = json.loads(info.stdout)
    return {"values": np.load(npy).astype(np.float64), "info": j}


def series_slices(peer, ours):
    """In-place reads give the file's whole series: the volume's slices at the file's frame
    positions (index along the volume's third axis), or None."""
    info = ours["info"]
    if peer["positions"] is None:
        return None
    o = np.array(info["origin"])
    # Row by row: column c is the world direction of grid axis c.
    k_axis = np.array(info["direction"])[:, 2]
    dz = info["spacing"][2]
    ks = []
    for p in peer["positions"]:
        t = float(np.dot(np.array(p) - o, k_axis)) / dz
        k = int(round(t))
        if abs(t - k) > 0.05 or not 0 <= k < ours["values"].shape[0]:
            return None
        ks.append(k)
    return ks


def compare(peer, ours) -> str | None:
    """None when they agree, else what differs."""
    a, b = peer["values"], ours["values"]
    if a.shape != b.shape and a.shape[1:] == b.shape[1:] and b.shape[0] > a.shape[0]:
        ks = series_slices(peer, ours)
        if ks is None:
            return f"shape {b.shape} (z, y, x), pydicom {a.shape}, and the file's frames are not slices of the series"
        b = b[ks]
        ours = {"values": b, "info": dict(ours["info"], origin=list(np.array(peer["origin"])))}
        peer = dict(peer, spacing=[peer["spacing"][0], peer["spacing"][1], None])
    if a.shape != b.shape:
        return f"shape {b.shape} (z, y, x), pydicom {a.shape}"
    d = float(np.max(np.abs(a - b))) if a.size else 0.0
    if peer["ts"] in LOSSY:
        rng = float(a.max() - a.min()) if a.size else 0.0
        tol = max(2.0, 0.01 * rng)
    else:
        tol = 1e-3 * max(1.0, float(np.max(np.abs(a))) if a.size else 1.0) if a.dtype.kind == "f" else 0.0
        tol = max(tol, 1e-6 * float(np.max(np.abs(a))) if a.size else 0.0)
    if d > tol:
        return f"samples differ by up to {d:g} (tolerance {tol:g})"
    info = ours["info"]
    if peer["origin"] is not None:
        o = np.array(info["origin"])
        if np.max(np.abs(o - np.array(peer["origin"]))) > 1e-3:
            return f"origin {list(o)}, pydicom {peer['origin']}"
        sp = peer["spacing"]
        for ax in range(3):
            if sp[ax] is None:
                continue
            if abs(info["spacing"][ax] - sp[ax]) > 1e-4 * max(1.0, abs(sp[ax])):
                return f"spacing {info['spacing']}, pydicom {sp}"
    return None


def run(binary: str, files: list[Path], mode: str, timeout: float, verbose: bool):
    counts: dict[str, int] = {}
    details: list[tuple[str, str, str]] = []
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        for f in files:
            peer = peer_read(f)
            if mode == "alone":
                d = work / "alone"
                if d.exists():
                    shutil.rmtree(d)
                d.mkdir()
                target = d / f.name
                shutil.copy(f, target)
            else:
                target = f
            ours = volsplat_read(binary, target, work, timeout)
            if isinstance(ours, tuple) and ours[0] == "crash":
                cat, why = "crash", ours[1]
            elif isinstance(peer, tuple) and peer[0] == "colour":
                cat = "colour" if isinstance(ours, tuple) else "wrong"
                why = peer[1] + (f"; volsplat: {ours[1]}" if isinstance(ours, tuple) else "; volsplat read it")
            elif isinstance(peer, tuple) and peer[0] == "no-image":
                cat, why = "no-image", "" if isinstance(ours, tuple) else "volsplat read it"
            elif isinstance(peer, tuple):
                cat = "both-refuse" if isinstance(ours, tuple) else "extra"
                why = f"pydicom: {peer[1]}" + (f"; volsplat: {ours[1]}" if isinstance(ours, tuple) else "")
            elif isinstance(ours, tuple):
                cat, why = "refused", ours[1]
            else:
                diff = compare(peer, ours)
                cat, why = ("matched", "") if diff is None else ("wrong", diff)
            counts[cat] = counts.get(cat, 0) + 1
            details.append((cat, f.name, why))
    return counts, details


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("paths", nargs="*", type=Path, help="files or folders (default: the peers' test files)")
    ap.add_argument("--bin", default="target/release/volsplat", help="volsplat binary")
    ap.add_argument("--mode", choices=["alone", "in-place", "both"], default="both")
    ap.add_argument("--timeout", type=float, default=120.0, help="seconds per volsplat run")
    ap.add_argument("--verbose", "-v", action="store_true", help="list every file, not only the misses")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as gz:
        files = candidates(args.paths or default_paths(), Path(gz))
        modes = ["alone", "in-place"] if args.mode == "both" else [args.mode]
        for mode in modes:
            counts, details = run(args.bin, files, mode, args.timeout, args.verbose)
            print(f"## {mode}: {len(files)} files")
            order = ["matched", "colour", "no-image", "both-refuse", "extra", "refused", "wrong", "crash"]
            print("  " + ", ".join(f"{k} {counts.get(k, 0)}" for k in order))
            for cat, name, why in details:
                if args.verbose or cat in ("refused", "wrong", "crash", "extra"):
                    print(f"  {cat:11} {name}: {why}")


if __name__ == "__main__":
    main()
