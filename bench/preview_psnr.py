#!/usr/bin/env python3
"""How close the pyramid's previews are to the full-quality frame (issue 29 item 7, decision 0031;
docs/BENCHMARKS.md §21). Optional; never run in CI; needs numpy.

    python3 bench/preview_psnr.py [--bin target/release/volsplat] [--out DIR] -- RENDER-ARGS

`RENDER-ARGS` choose the volume, camera and transfer function as for `volsplat render` (for
example `ct.nrrd --preset ct-skin`). The script saves that request at 512² (`--save-scene`), then
renders it as `.npy` at 128², 256² and 512² with `quality.level` `full` and, at 128² and 256²,
`auto`, and prints per size: the level `auto` drew, the PSNR of the preview against the full
frame of the same size, and the PSNR of both, upscaled to 512² (bilinear, pixel centres kept),
against the full 512² frame. PSNR is over RGB of the premultiplied linear image, peak 1.
"""
import argparse
import json
import math
import os
import subprocess
import sys
import tempfile

import numpy as np


def psnr(a, b):
    mse = float(np.mean((a[..., :3].astype(np.float64) - b[..., :3]) ** 2))
    return float("inf") if mse == 0 else 10 * math.log10(1 / mse)


def up2(a):
    """2× bilinear upscale with pixel centres kept (fine pixel i sits at coarse (i + ½)/2 − ½)."""
    a = a.astype(np.float64)
    for axis in (0, 1):
        n = a.shape[axis]
        src = (np.arange(2 * n) + 0.5) / 2 - 0.5
        i0 = np.clip(np.floor(src).astype(int), 0, n - 1)
        i1 = np.clip(i0 + 1, 0, n - 1)
        shape = [1] * a.ndim
        shape[axis] = -1
        t = np.clip(src - np.floor(src), 0, 1).reshape(shape)
        a = np.take(a, i0, axis) * (1 - t) + np.take(a, i1, axis) * t
    return a


def upto(a, n):
    while a.shape[0] < n:
        a = up2(a)
    return a


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bin", default="target/release/volsplat")
    ap.add_argument("--out", default=None, help="keep the scenes and images here")
    own, args = sys.argv[1:], []
    if "--" in own:
        i = own.index("--")
        own, args = own[:i], own[i + 1:]
    argv = ap.parse_args(own)
    out = argv.out or tempfile.mkdtemp(prefix="preview_psnr_")
    os.makedirs(out, exist_ok=True)
    base = os.path.join(out, "request.json")
    subprocess.run([argv.bin, "render", *args, "--size", "512", "-o",
                    os.path.join(out, "first.png"), "--save-scene", base],
                   check=True, capture_output=True)
    request = json.load(open(base))

    def render(n, level):
        r = json.loads(json.dumps(request))
        r["width"] = r["height"] = n
        r["quality"]["level"] = level
        scene = os.path.join(out, f"{level}_{n}.json")
        json.dump(r, open(scene, "w"))
        image = os.path.join(out, f"{level}_{n}.npy")
        subprocess.run([argv.bin, "render", "--scene", scene, "-o", image],
                       check=True, capture_output=True)
        stats = subprocess.run([argv.bin, "bench", "--scene", scene, "--frames", "1",
                                "--orbit", "0"], check=True, capture_output=True)
        level_drawn = json.loads(stats.stdout.decode().strip().splitlines()[-1]).get("level")
        return np.load(image), level_drawn

    full = {n: render(n, "full")[0] for n in (128, 256, 512)}
    for n in (128, 256):
        preview, level = render(n, "auto")
        print(f"{n}²: level {level}; preview vs full {n}²: {psnr(preview, full[n]):.2f} dB; "
              f"upscaled to 512² vs full 512²: preview {psnr(upto(preview, 512), full[512]):.2f} dB, "
              f"full {n}² {psnr(upto(full[n], 512), full[512]):.2f} dB")


if __name__ == "__main__":
    main()
