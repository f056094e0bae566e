#!/usr/bin/env python3
"""Render a scan from Python: composite, MIP and a turntable, with volsplat.

    python examples/python/render_scan.py                      # the built-in demo phantom
    python examples/python/render_scan.py brain.nii.gz --preset MR-Default
    python examples/python/render_scan.py ct.nrrd --preset CT-Bone --out renders --frames 36

Writes composite.png, mip.png and turntable/frame_000.png … into --out (default
./volsplat-renders), and shows the first two and a contact sheet of the turntable with
matplotlib if it is installed (pass --no-show to skip the window). Needs `pip install
./crates/py` (and optionally matplotlib).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import volsplat


def main() -> int:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument(
        "scan", nargs="?", help="NIfTI, NRRD, MetaImage, VTK .vti or TIFF (default: the phantom)"
    )
    p.add_argument("--preset", default=None, help="transfer-function preset (default: automatic)")
    p.add_argument("--size", type=int, default=384, help="image size in pixels (default 384)")
    p.add_argument("--frames", type=int, default=24, help="turntable frames (default 24)")
    p.add_argument("--elevation", type=float, default=15.0, help="turntable elevation, degrees")
    p.add_argument("--out", type=Path, default=Path("volsplat-renders"), help="output folder")
    p.add_argument("--no-show", action="store_true", help="do not open a matplotlib window")
    args = p.parse_args()

    # 1. The volume: a file (any format the command line reads) or the built-in phantom.
    if args.scan:
        vol = volsplat.load(args.scan)
    else:
        vol = volsplat.phantom()  # the demo phantom of `volsplat render` without an input
    info = vol.info()
    print(
        f"{info['source']}: {info['format']}, {info['dtype']}, {info['dims_xyz']} voxels "
        f"(x, y, z), spacing {info['spacing_xyz']}, values {info['value_range']}"
    )
    for note in vol.notes:
        print("note:", note)
    # vol.array is a read-only (z, y, x) numpy view of the samples, e.g. for a histogram:
    print(f"median sample {np.median(vol.array):.1f}")

    out = args.out
    (out / "turntable").mkdir(parents=True, exist_ok=True)
    tf = args.preset  # None: chosen from the data, as the command line does

    # 2. One renderer keeps the volume, tables and thread pool between frames.
    r = volsplat.Renderer(vol, size=args.size, transfer_function=tf, elevation=args.elevation)

    t = time.perf_counter()
    composite = r.render(azimuth=30)
    composite.save(out / "composite.png", srgb=True)
    wall = 1e3 * (time.perf_counter() - t)
    print(f"composite: {composite.stats['total_ms']:.0f} ms in the engine, {wall:.0f} ms wall")

    mip = r.render(azimuth=30, mode="mip")
    mip.save(out / "mip.png")
    print(f"MIP: values {np.nanmin(mip.values):.1f} … {np.nanmax(mip.values):.1f} (data units)")

    # 3. A turntable: only the camera changes, so each frame costs only the frame.
    frames = []
    t = time.perf_counter()
    for n in range(args.frames):
        img = r.render(azimuth=360.0 * n / args.frames)
        img.save(out / "turntable" / f"frame_{n:03d}.png", srgb=True)
        frames.append(img.to_uint8(srgb=True, background=(0, 0, 0)))  # RGB over black
    dt = time.perf_counter() - t
    per = 1e3 * dt / max(args.frames, 1)
    print(f"turntable: {args.frames} frames in {dt:.2f} s ({per:.0f} ms/frame)")
    print(f"wrote {out}/composite.png, {out}/mip.png, {out}/turntable/")

    # 4. Plot with matplotlib if it is there.
    try:
        import matplotlib

        if args.no_show:
            matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("(matplotlib is not installed: no plot)")
        return 0
    cols = max(2, min(6, len(frames)))
    rows = (len(frames) + cols - 1) // cols
    fig = plt.figure(figsize=(2 * cols, 4 + 2 * rows))
    gs = fig.add_gridspec(2 + rows, cols)
    ax = fig.add_subplot(gs[:2, : cols // 2])
    ax.imshow(composite.to_uint8(srgb=True, background=(0, 0, 0)))
    ax.set_title("composite")
    ax.axis("off")
    ax = fig.add_subplot(gs[:2, cols // 2 :])
    ax.imshow(np.nan_to_num(mip.values, nan=float(np.nanmin(mip.values))), cmap="gray")
    ax.set_title("MIP (values)")
    ax.axis("off")
    for n, f in enumerate(frames):
        ax = fig.add_subplot(gs[2 + n // cols, n % cols])
        ax.imshow(f)
        ax.axis("off")
    fig.tight_layout()
    fig.savefig(out / "overview.png", dpi=80)
    print(f"wrote {out}/overview.png")
    if not args.no_show:
        plt.show()
    return 0


if __name__ == "__main__":
    sys.exit(main())
