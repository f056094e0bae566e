#!/usr/bin/env python3
"""How far VTK's fixed-point ray caster sits from the transfer function it is given, and how much of
issue 16's gap against its VTK-made reference that explains. Optional; never run in CI.

    python3 bench/vtk_bias.py [--bin target/release/volsplat] [--data DIR] [--size 512]
                              [--shifts 0,0.5,1] [--only SUBSTR] [--out docs/convergence/vtk-bias.md]
                              [--no-docs]

1. **Probe.** A u8 volume whose value rises 2 units per voxel along x (constant along y and z),
   white, opacity per unit length 0.0001 × value; orthographic rays along z, 256² pixels over the
   volume. Each column's opacity `P` implies the value the renderer classified,
   `v = (1 − (1 − P)^(1/L)) / 0.0001` (`L` = 63, the path through the volume). Reported: the mean
   over the columns of that value minus the column's true value, for VTK's
   `vtkFixedPointVolumeRayCastMapper` at sample distance 1/2 and 1/8 of the spacing (issue 16's
   "usual" and "converged" settings) and at 1/16 and 1/32 (does it converge?), and for volsplat's
   default render.
2. **Scenes.** For each composite scene that `bench/convergence.py` measures, the PSNR against its
   VTK-made converged reference (the same cache) of volsplat's default render with the scene's
   transfer function moved *down* by δ data units (so the value `v` is classified as `v + δ`, what
   VTK's rounding does), for each δ of `--shifts`, beside VTK's usual render.
3. **Refinement.** For the same scenes, whether the reference's own sampling has converged: VTK at
   sample distance 1/8, 1/16 and 1/32 of the smallest spacing (at the size itself, one ray per
   pixel: the supersampling is not what is in question; VTK's default threads, whose gradient
   planes of item 4 are the same at every step), the PSNR between successive ones and the
   mean change of the image over the object (pixels that any of them lights); and the same for
   volsplat's slabs classified by point (`--visibility image --preintegrate off`) at 1/8 and 1/16
   of a voxel. A converged integrator changes by far less than the 1 dB margin issue 16 allows.
4. **Threads.** For the shaded scenes, VTK at sample distance 1/8 with 1 thread (what the reference
   uses, `convergence.REF_THREADS`) against 2, 4 and 16 threads: VTK computes its gradients in one
   z-chunk per thread and gives the last slice of each chunk a one-sided, half-weighted z
   difference (`vtkFixedPointVolumeRayCastMapperComputeCS1CGradientsFunctor`), so its shaded
   picture depends on the machine's core count.

The transfer-function shift is a diagnostic, not a mode: the renders with δ = 0 are what users get.
It reuses `bench/vs_vtk.py`'s virtual environment and VTK set-up.
"""

import argparse
import datetime
import json
import os
import platform
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import convergence  # noqa: E402  (same folder)
import vs_vtk  # noqa: E402

ROOT = vs_vtk.ROOT
PROBE_N = 64
PROBE_SLOPE = 2  # data units per voxel along x
PROBE_K = 0.0001  # opacity per unit length per data unit
REFINE = (0.125, 0.0625, 0.03125)  # sample distances of the refinement check (× smallest spacing)
THREADS = (2, 4, 16)  # VTK thread counts compared with one thread on the shaded scenes


def write_probe(work):
    """The probe volume (NRRD, u8), camera and transfer function; returns their paths."""
    import numpy as np
    n = PROBE_N
    x = np.arange(n, dtype=np.int32) * PROBE_SLOPE
    vol = np.broadcast_to(x[None, None, :], (n, n, n)).astype(np.uint8).copy()
    raw = os.path.join(work, "probe.raw")
    vol.tofile(raw)
    nhdr = os.path.join(work, "probe.nhdr")
    with open(nhdr, "w") as f:
        f.write(f"NRRD0004\ntype: uint8\ndimension: 3\nsizes: {n} {n} {n}\nspacings: 1 1 1\n"
                f"encoding: raw\ndata file: probe.raw\n")
    c = (n - 1) / 2
    cam = os.path.join(work, "probe.camera.json")
    json.dump({"position": [c, c, 400.0], "focal_point": [c, c, c], "view_up": [0, 1, 0],
               "view_angle": 30.0, "parallel_projection": True, "parallel_scale": c}, open(cam, "w"))
    tf = os.path.join(work, "probe.tf.json")
    json.dump({"color": [[0, 1, 1, 1], [255, 1, 1, 1]],
               "scalar_opacity": [[0, 0], [255, 255 * PROBE_K]],
               "scalar_opacity_unit_distance": 1.0, "shade": False}, open(tf, "w"))
    return nhdr, cam, tf


def probe_offset(img, size):
    """Mean (classified − true) value over the probe's columns, from a rendered RGB image."""
    import numpy as np
    n = PROBE_N
    length = n - 1
    row = size // 2
    cols = np.arange(size // 8, size - size // 8)  # away from the volume's side faces
    x_world = (cols + 0.5) / size * (n - 1)  # the image spans voxel centres 0 … n − 1
    true_v = PROBE_SLOPE * x_world
    p = np.clip(img[row, cols, 0], 0, 0.999)
    seen_v = (1 - (1 - p) ** (1 / length)) / PROBE_K
    return float(np.mean(seen_v - true_v))


def main():
    import numpy as np
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    convergence.add_scene_args(ap)
    ap.add_argument("--shifts", default="0,0.5,1")
    ap.add_argument("--out", default=os.path.join(ROOT, "docs", "convergence", "vtk-bias.md"))
    ap.add_argument("--no-docs", action="store_true")
    a = ap.parse_args()
    shifts = [float(s) for s in a.shifts.split(",")]
    cache = os.path.join(ROOT, "target", "convergence-cache")
    os.makedirs(cache, exist_ok=True)
    work = tempfile.mkdtemp(prefix="vtk-bias-")
    env, prefix = vs_vtk.vtk_env_and_prefix(work)

    # 1. The probe.
    vol, cam, tf = write_probe(work)
    size = 256
    probe = {}
    for label, factor in (("VTK, sample distance 1/2", 0.5), ("VTK, sample distance 1/8", 0.125),
                          ("VTK, sample distance 1/16", 0.0625),
                          ("VTK, sample distance 1/32", 0.03125)):
        out = os.path.join(work, f"probe.{factor}.png")
        convergence.vtk_render(env, prefix, vol, cam, tf, out, size, factor)
        probe[label] = probe_offset(vs_vtk.read_png(out), size)
    out = os.path.join(work, "probe.volsplat.npy")
    subprocess.run([a.bin, "render", vol, "--camera", cam, "--tf", tf, "--size", str(size), "-q",
                    "-o", out], check=True)
    probe["volsplat (defaults)"] = probe_offset(np.load(out)[..., :3].astype(np.float64), size)
    for k, v in probe.items():
        print(f"probe: {k}: classified value − true value = {v:+.2f}", file=sys.stderr, flush=True)

    # 2. The scenes.
    rows = []
    for label, _vol_name, name, vol, cam, tf in vs_vtk.scene_list(
            os.path.join(a.data, "scenes"), a.data, a.only):
        if name not in convergence.SCENES:
            continue
        _key, ref = convergence.converged_reference(env, prefix, cache, label, vol, cam, tf, a.size)
        vtk_png = os.path.join(work, f"{label}.vtk.png")
        convergence.vtk_render(env, prefix, vol, cam, tf, vtk_png, a.size, 0.5)
        row = {"scene": label, "VTK usual": convergence.psnr(vs_vtk.read_png(vtk_png), ref)}
        tf_j = json.load(open(tf))
        for d in shifts:
            moved = dict(tf_j)
            for k in ("color", "scalar_opacity"):
                moved[k] = [[p[0] - d] + list(p[1:]) for p in tf_j[k]]
            tf_d = os.path.join(work, f"{label}.shift{d}.tf.json")
            json.dump(moved, open(tf_d, "w"))
            out = os.path.join(work, f"{label}.shift{d}.png")
            subprocess.run([a.bin, "render", vol, "--camera", cam, "--tf", tf_d, "--size",
                            str(a.size), "-q", "-o", out] + vs_vtk.volsplat_flags(name, cam),
                           check=True)
            row[d] = convergence.psnr(vs_vtk.read_png(out), ref)
        # 3. Refinement of the reference's own sampling, and of volsplat's.
        vtk_imgs = []
        for factor in REFINE:
            out = os.path.join(work, f"{label}.vtk{factor}.png")
            convergence.vtk_render(env, prefix, vol, cam, tf, out, a.size, factor)
            vtk_imgs.append(vs_vtk.read_png(out))
        ours_imgs = []
        for slab in REFINE[:2]:
            out = os.path.join(work, f"{label}.slab{slab}.png")
            subprocess.run([a.bin, "render", vol, "--camera", cam, "--tf", tf, "--size",
                            str(a.size), "-q", "-o", out, "--visibility", "image", "--slab",
                            str(slab), "--preintegrate", "off"] + vs_vtk.volsplat_flags(name, cam),
                           check=True)
            ours_imgs.append(vs_vtk.read_png(out))
        lit = np.zeros(vtk_imgs[0].shape[:2], dtype=bool)
        for img in vtk_imgs + ours_imgs:
            lit |= img.max(axis=-1) > 0
        row["refine"] = {
            "vtk": [(convergence.psnr(x, y), float((y - x)[lit].mean()))
                    for x, y in zip(vtk_imgs, vtk_imgs[1:])],
            "ours": (convergence.psnr(*ours_imgs), float((ours_imgs[1] - ours_imgs[0])[lit].mean())),
        }
        # 4. VTK's thread count, shaded scenes.
        if tf_j.get("shade", False):
            one = os.path.join(work, f"{label}.thr1.png")
            convergence.vtk_render(env, prefix, vol, cam, tf, one, a.size, 0.125, 1)
            row["threads"] = {}
            for t in THREADS:
                out = os.path.join(work, f"{label}.thr{t}.png")
                convergence.vtk_render(env, prefix, vol, cam, tf, out, a.size, 0.125, t)
                row["threads"][t] = convergence.psnr(vs_vtk.read_png(one), vs_vtk.read_png(out))
        rows.append(row)
        print(f"{label}: " + ", ".join(f"{k} {v:.2f}" for k, v in row.items()
                                       if k not in ("scene", "refine", "threads")) +
              f", refine {row['refine']}, threads {row.get('threads')}", file=sys.stderr,
              flush=True)

    probe_lines = ["| renderer | classified − true value (data units) |", "|---|---|"]
    probe_lines += [f"| {k} | {v:+.2f} |" for k, v in probe.items()]
    scene_lines = ["| scene | VTK usual | " + " | ".join(f"volsplat, δ = {d:g}" for d in shifts) + " |",
                   "|---|---|" + "---|" * len(shifts)]
    for r in rows:
        scene_lines.append(f"| {r['scene']} | {r['VTK usual']:.2f} | " +
                           " | ".join(f"{r[d]:.2f}" for d in shifts) + " |")
    refine_lines = ["| scene | VTK usual vs reference | VTK 1/8 vs 1/16 | change 1/8 → 1/16 | "
                    "VTK 1/16 vs 1/32 | change 1/16 → 1/32 | volsplat 1/8 vs 1/16 | change |",
                    "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        (p1, m1), (p2, m2) = r["refine"]["vtk"]
        po, mo = r["refine"]["ours"]
        refine_lines.append(f"| {r['scene']} | {r['VTK usual']:.2f} | {p1:.2f} | {m1:+.4f} | "
                            f"{p2:.2f} | {m2:+.4f} | {po:.2f} | {mo:+.5f} |")
    thread_lines = ["| scene | " + " | ".join(f"1 vs {t} threads" for t in THREADS) + " |",
                    "|---|" + "---|" * len(THREADS)]
    for r in rows:
        if "threads" in r:
            thread_lines.append(f"| {r['scene']} | " +
                                " | ".join(f"{r['threads'][t]:.2f}" for t in THREADS) + " |")
    print("\n".join(probe_lines) + "\n\n" + "\n".join(scene_lines) + "\n\n" +
          "\n".join(refine_lines) + "\n\n" + "\n".join(thread_lines))
    if a.no_docs:
        return
    cmd = "python3 bench/vtk_bias.py " + " ".join(sys.argv[1:])
    text = f"""# What VTK's converged reference carries

Generated by `{cmd.strip()}` on {datetime.date.today()} ({platform.machine()}, {os.cpu_count()} cores;
VTK {convergence.vtk_version()}). Do not edit by hand: run the script again. The method is in the
script's docstring.

## The probe: which value each renderer classifies

A u8 ramp, 2 units per voxel along x, white, opacity per unit length proportional to the value; rays
along z. The value implied by each column's opacity, minus the column's true value, averaged over
the columns:

{chr(10).join(probe_lines)}

VTK's `vtkFixedPointVolumeRayCastMapper` rounds the interpolated value *up* to the next table entry
(it adds `0x7fff` before its 15-bit shift) and rounds each compositing step up, so it classifies
values above the true ones, and more so the more samples it takes: the 1/8-spacing "converged"
reference is not the limit of the exact integral but of VTK's rounding.

## The scenes: the same offset applied to volsplat

PSNR (dB) against issue 16's VTK-made converged reference (`bench/convergence.py`'s cache) of
volsplat's default render with the scene's transfer function moved down by δ data units, i.e.
classifying `v` as `v + δ` as VTK's rounding does; δ = 0 is what users get:

{chr(10).join(scene_lines)}

Where a δ of about one data unit lifts volsplat to VTK's usual score or beyond, the gap in the
first column of `docs/convergence/README.md` is VTK's rounding, not blur, rings or popping in
volsplat. volsplat does not emulate it; against the exact float integral (the second table of
`docs/convergence/README.md`) volsplat's default is the closer picture.

## Refinement: does the reference converge?

PSNR (dB) between VTK's renders at successive sample distances (1/8, 1/16 and 1/32 of the smallest
spacing, {a.size}², one ray per pixel) and the mean change of the image over the object (RGB values
in [0, 1]); the same for volsplat's slabs classified by point at 1/8 and 1/16 of a voxel; and, for
scale, VTK's usual render against the reference (the first column of the table above), the number
issue 16 asks volsplat to come within 1 dB of:

{chr(10).join(refine_lines)}

An integrator that converges changes less and less as its step halves. VTK's picture does the
opposite: each halving brightens it by about twice as much as the one before, because every sample
adds its rounding. Where its change from 1/8 to 1/16 is larger than the distance of VTK's usual
render to the 1/8 reference (the PSNR is lower), the reference's own sampling error is larger than
the margin it is used to judge.

## Threads: VTK's shaded picture depends on the core count

PSNR (dB) of VTK at sample distance 1/8 with one thread against the same render with more threads
(shaded scenes only; unshaded renders do not compute gradients):

{chr(10).join(thread_lines) if thread_lines[2:] else "(no shaded scene)"}

`vtkFixedPointVolumeRayCastMapper` computes its gradients in one z-chunk per thread and the last
slice of each chunk gets a one-sided, half-weighted z difference (its threads share no halo), so
each thread adds a plane of wrongly lit voxels. The converged reference of `bench/convergence.py`
is rendered with one thread; VTK's usual render with its default, all cores.
"""
    with open(a.out, "w") as f:
        f.write(text)


if __name__ == "__main__":
    vs_vtk.ensure_venv(__file__)
    main()
