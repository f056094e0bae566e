#!/usr/bin/env python3
"""Convergence check (issue 16 item 4): each volsplat mode's PSNR against a converged reference, and
how much each changes when the camera turns across the 45° diagonal. Optional; never run in CI.

    python3 bench/convergence.py [--bin target/release/volsplat] [--data DIR] [--size 512]
                                 [--only SUBSTR] [--mode LABEL="FLAGS" ...] [--out DIR] [--no-docs]

For the composite, shaded and perspective scenes of `../shared/data/scenes`:

1. **Converged reference**: VTK's `vtkFixedPointVolumeRayCastMapper` with sample distance 1/8 of the
   smallest spacing, rendered 4× larger and box-filtered 4×4 down (cached in
   `target/convergence-cache/`, keyed by scene, size, thread count and file times), with **one**
   VTK thread: VTK's gradients are computed in one z-chunk per thread and the last slice of each
   chunk gets a one-sided, half-weighted z difference, so a shaded render changes with the thread
   count (`bench/vtk_bias.py` measures how much);
2. **VTK's usual render**: sample distance 1/2 of the smallest spacing, at the size itself, with
   VTK's default threads (all cores);
3. **volsplat** in each mode (default: `auto` = no flags, what a user gets (decisions 0016, 0017,
   0019, 0020 and 0036: one-voxel slabs for composite, shaded at the samples twice per slab,
   pre-integrated where the transfer function's ramp is sharp); `sheet` = `--visibility sheet`,
   Westover's sheet buffers; `image` = `--visibility image --slab 0.5`; `point` and `segment` =
   one-voxel slabs classified by their one sample (`--preintegrate off`) or by the ray's segment
   between two planes (`--preintegrate on`); `image-samples` = half-voxel slabs shading every
   sample, `--shade-at samples`), same camera and transfer-function files, linear PNG as VTK
   writes it;
4. **PSNR** (RGB, 8-bit linear values over black, peak 1) of each against the reference;
5. **Float reference** (a second, independent one): `testkit`'s brute-force integrator
   (`cargo run --release -p volsplat-testkit --example reference_render`): float arithmetic,
   trilinear samples every 1/8 of the smallest spacing, interpolated central-difference gradients,
   2×2 rays per pixel box-averaged; shaded scenes lit at the voxels with the light interpolated
   (VTK's order, decision 0019). It integrates exactly the model both tools claim (the transfer
   function evaluated at the interpolated value), without VTK's 15-bit fixed-point rounding (its
   table index is the interpolated value rounded *up*, and its compositing rounds up) and without
   its threads' gradient slices, so PSNR is reported against it too, for VTK as well;
6. **Popping**: the scene's camera turned by 44° and 46° about its view-up axis (VTK's `Azimuth`,
   camera files written here and used by both tools); per mode the RMS change of the image divided
   by the RMS change of VTK at 1/8 sampling (not supersampled, to keep it cheap);

and writes `docs/convergence/README.md` with the tables, plus per scene a montage (reference | VTK |
each mode) and the differences to the reference ×8.

It reuses `bench/vs_vtk.py`'s virtual environment (`target/vtk-venv`: vtk, numpy) and VTK set-up.
"""
import argparse
import datetime
import hashlib
import json
import math
import os
import platform
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import vs_vtk  # noqa: E402  (same folder)

ROOT = vs_vtk.ROOT
SCENES = ["composite_ortho", "composite_shaded_ortho", "composite_persp"]
DEFAULT_MODES = [
    ("auto", ""),
    ("sheet", "--visibility sheet"),
    ("image", "--visibility image --slab 0.5"),
    ("point", "--visibility image --slab 1 --preintegrate off"),
    ("segment", "--visibility image --slab 1 --preintegrate on"),
    ("image-samples", "--visibility image --slab 0.5 --shade-at samples"),
]


def rotated_camera(cam_path, degrees, out_path):
    """Writes the camera of `cam_path` turned by `degrees` about its view-up through the focal
    point (VTK's `vtkCamera::Azimuth`)."""
    import numpy as np
    c = json.load(open(cam_path))
    pos, foc, up = (np.array(c[k], dtype=float) for k in ("position", "focal_point", "view_up"))
    axis = up / np.linalg.norm(up)
    a = math.radians(degrees)
    v = pos - foc
    # Rodrigues' rotation of v about axis by a.
    v = v * math.cos(a) + np.cross(axis, v) * math.sin(a) + axis * np.dot(axis, v) * (1 - math.cos(a))
    c["position"] = (foc + v).tolist()
    json.dump(c, open(out_path, "w"), indent=1)
    return out_path


# VTK's threads for the reference renders. One: `vtkFixedPointVolumeRayCastMapper` computes its
# gradients in z-chunks, one per thread, and the last slice of each chunk gets a one-sided,
# half-weighted z difference (`ComputeCS1CGradientsFunctor`'s `z < z_limit - 1` test), so a shaded
# render depends on the thread count (bench/vtk_bias.py measures it). With one thread only the
# volume's own last slice is one-sided.
REF_THREADS = 1
# VTK's threads for its "usual" render: VTK's default, all the cores of this machine (2 on the
# machine of the recorded numbers).
USUAL_THREADS = os.cpu_count() or 2


def vtk_render(env, prefix, vol, cam, tf, out_png, size, factor, threads=USUAL_THREADS):
    vs_vtk.run_measured(prefix + [sys.executable, os.path.join(HERE, "vs_vtk.py"), "--vtk-worker", vol,
                                  cam, tf, out_png, str(size), str(threads), "0", str(factor)],
                        env=env)


def converged_reference(env, prefix, cache, label, vol, cam, tf, n, threads=REF_THREADS):
    """(cache key, the VTK-made converged reference as an RGB float array): rendered at 4n² with
    sample distance 1/8 of the smallest spacing and `threads` VTK threads, and box-filtered to n²,
    cached in `cache` under a key of the scene, the size, the thread count and the files' times."""
    key = hashlib.sha1(json.dumps([label, n, os.path.getmtime(vol), os.path.getmtime(cam),
                                   os.path.getmtime(tf)] + ([threads] if threads != 2 else []))
                       .encode()).hexdigest()[:12]
    ref_png = os.path.join(cache, f"{label}.{n}.{key}.ref4x.png")
    if not os.path.exists(ref_png):
        print(f"{label}: converged reference (VTK, 1/8 spacing, {4 * n}², {threads} thread(s)) …",
              file=sys.stderr, flush=True)
        vtk_render(env, prefix, vol, cam, tf, ref_png + ".tmp.png", 4 * n, 0.125, threads)
        os.replace(ref_png + ".tmp.png", ref_png)
    return key, box_down(vs_vtk.read_png(ref_png), 4)


def box_down(img, k):
    h, w, c = img.shape
    return img.reshape(h // k, k, w // k, k, c).mean(axis=(1, 3))


def psnr(a, b):
    import numpy as np
    mse = float(np.mean((a - b) ** 2))
    return float("inf") if mse == 0 else 10 * math.log10(1.0 / mse)


def rms(a, b):
    import numpy as np
    return float(np.sqrt(np.mean((a - b) ** 2)))


def save_png(arr, path):
    """Writes a float RGB array in [0, 1] (rows top-down) as an 8-bit PNG with VTK's writer."""
    import numpy as np
    import vtk
    from vtk.util import numpy_support as ns
    h, w, _ = arr.shape
    data = (np.clip(arr, 0, 1) * 255 + 0.5).astype(np.uint8)[::-1].reshape(-1, 3).copy()
    img = vtk.vtkImageData()
    img.SetDimensions(w, h, 1)
    img.GetPointData().SetScalars(ns.numpy_to_vtk(data, deep=True))
    wr = vtk.vtkPNGWriter()
    wr.SetFileName(path)
    wr.SetInputData(img)
    wr.Write()


def add_scene_args(ap):
    """The arguments this script and `bench/vtk_bias.py` share: the volsplat binary, the data folder
    (`NAME.nrrd` or `.nhdr` beside `scenes/`), the image size in pixels and a scene filter."""
    ap.add_argument("--bin", default=os.path.join(ROOT, "target", "release", "volsplat"))
    ap.add_argument("--data", default=os.path.join(ROOT, "..", "shared", "data"))
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--only", default="", help="comma-separated substrings of scene labels")


def main():
    import numpy as np
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_scene_args(ap)
    ap.add_argument("--mode", action="append", default=None, help='LABEL="volsplat flags"')
    ap.add_argument("--out", default=os.path.join(ROOT, "docs", "convergence"))
    ap.add_argument("--no-docs", action="store_true")
    ap.add_argument("--no-float", action="store_true", help="skip the float reference")
    a = ap.parse_args()
    modes = DEFAULT_MODES if not a.mode else [tuple(m.split("=", 1)) for m in a.mode]
    cache = os.path.join(ROOT, "target", "convergence-cache")
    work = os.path.join(cache, "work")
    os.makedirs(work, exist_ok=True)
    if not a.no_docs:
        os.makedirs(a.out, exist_ok=True)
    env, prefix = vs_vtk.vtk_env_and_prefix(work)
    scenes = [s for s in vs_vtk.scene_list(os.path.join(a.data, "scenes"), a.data, a.only)
              if s[2] in SCENES]
    n = a.size
    rows, pops, float_rows = [], [], []
    for label, vol_name, name, vol, cam, tf in scenes:
        flags = vs_vtk.volsplat_flags(name, cam)
        key, ref = converged_reference(env, prefix, cache, label, vol, cam, tf, n)
        vtk_png = os.path.join(work, f"{label}.vtk.png")
        vtk_render(env, prefix, vol, cam, tf, vtk_png, n, 0.5)
        images = {"reference": ref, "VTK": vs_vtk.read_png(vtk_png)}
        for m, mflags in modes:
            out = os.path.join(work, f"{label}.{m}.png")
            vs_vtk.run_measured([a.bin, "render", vol, "--camera", cam, "--tf", tf, "--size", str(n)] +
                                flags + mflags.split() + ["-q", "-o", out])
            images[m] = vs_vtk.read_png(out)
        row = {"scene": label, "VTK": psnr(images["VTK"], ref)}
        for m, _ in modes:
            row[m] = psnr(images[m], ref)
        rows.append(row)
        if not a.no_float:
            fref = float_reference(a, cache, key, label, vol, cam, tf, n)
            frow = {"scene": label, "VTK converged": psnr(ref, fref), "VTK": psnr(images["VTK"], fref)}
            for m, _ in modes:
                frow[m] = psnr(images[m], fref)
            float_rows.append(frow)
            print(f"{label} vs float reference: " +
                  ", ".join(f"{k} {v:.2f} dB" for k, v in frow.items() if k != "scene"),
                  file=sys.stderr, flush=True)
        print(f"{label}: " + ", ".join(f"{k} {v:.2f} dB" for k, v in row.items() if k != "scene"),
              file=sys.stderr, flush=True)
        # Popping across the diagonal.
        turned = {}
        for deg in (44, 46):
            cpath = rotated_camera(cam, deg, os.path.join(work, f"{label}.az{deg}.camera.json"))
            r_png = os.path.join(work, f"{label}.az{deg}.ref.png")
            vtk_render(env, prefix, vol, cpath, tf, r_png, n, 0.125, REF_THREADS)
            turned[("reference", deg)] = vs_vtk.read_png(r_png)
            for m, mflags in modes:
                out = os.path.join(work, f"{label}.az{deg}.{m}.png")
                vs_vtk.run_measured([a.bin, "render", vol, "--camera", cpath, "--tf", tf, "--size",
                                     str(n)] + flags + mflags.split() + ["-q", "-o", out])
                turned[(m, deg)] = vs_vtk.read_png(out)
        base = rms(turned[("reference", 44)], turned[("reference", 46)])
        pop = {"scene": label}
        for m, _ in modes:
            pop[m] = rms(turned[(m, 44)], turned[(m, 46)]) / base if base > 0 else float("nan")
        pops.append(pop)
        print(f"{label} popping: " + ", ".join(f"{m} {pop[m]:.3f}" for m, _ in modes), file=sys.stderr,
              flush=True)
        if not a.no_docs:
            half = [box_down(images[k], 2) for k in images]
            save_png(np.concatenate(half, axis=1), os.path.join(a.out, f"{label}.png"))
            diffs = [box_down(np.clip(np.abs(images[k] - ref) * 8, 0, 1), 2) for k in images
                     if k != "reference"]
            save_png(np.concatenate(diffs, axis=1), os.path.join(a.out, f"{label}.diff.png"))
    names = [m for m, _ in modes]
    cmd = "python3 bench/convergence.py " + " ".join(sys.argv[1:])
    lines = [
        "| scene | VTK usual | " + " | ".join(names) + " |",
        "|---|---|" + "---|" * len(names),
    ]
    for r in rows:
        lines.append(f"| {r['scene']} | {r['VTK']:.2f} | " + " | ".join(f"{r[m]:.2f}" for m in names) + " |")
    float_lines = [
        "| scene | VTK converged | VTK usual | " + " | ".join(names) + " |",
        "|---|---|---|" + "---|" * len(names),
    ]
    for r in float_rows:
        float_lines.append(f"| {r['scene']} | {r['VTK converged']:.2f} | {r['VTK']:.2f} | " +
                           " | ".join(f"{r[m]:.2f}" for m in names) + " |")
    pop_lines = [
        "| scene | " + " | ".join(names) + " |",
        "|---|" + "---|" * len(names),
    ]
    for p in pops:
        pop_lines.append(f"| {p['scene']} | " + " | ".join(f"{p[m]:.3f}" for m in names) + " |")
    print("\n".join(lines) + "\n\n" + "\n".join(float_lines) + "\n\n" + "\n".join(pop_lines))
    if a.no_docs:
        return
    mode_list = "\n".join(f"- `{m}`: `volsplat render … {f}`" for m, f in modes)
    pictures = "\n\n".join(
        f"**{r['scene']}**: reference · VTK · " + " · ".join(names) +
        f"\n\n![{r['scene']}]({r['scene']}.png)\n\n"
        f"|difference to the reference × 8: VTK · " + " · ".join(names) + "|\n|---|\n"
        f"|![{r['scene']} differences]({r['scene']}.diff.png)|" for r in rows)
    text = f"""# Convergence check (issue 16)

Generated by `{cmd.strip()}` on {datetime.date.today()} ({platform.machine()}, {os.cpu_count()} cores;
VTK {vtk_version()}). Do not edit by hand: run the script again.

**Reference.** VTK's `vtkFixedPointVolumeRayCastMapper`, linear interpolation, sample distance 1/8 of
the smallest spacing, rendered at {4 * n}² with one VTK thread and box-filtered 4×4 to {n}²; the
scene's camera and transfer-function files. **VTK usual**: the same at sample distance 1/2, {n}²,
{USUAL_THREADS} VTK threads (its default on this machine). **Modes**:

{mode_list}

## PSNR against the reference (dB; RGB, 8-bit linear values over black)

{chr(10).join(lines)}

## PSNR against the float reference (dB)

The same images against `testkit`'s float integrator (1/8 spacing, 2×2 rays per pixel), which
evaluates the transfer function at the interpolated value exactly and lights shaded scenes at the
voxels as VTK does; "VTK converged" is the reference of the first table, measured against this
one. The two references differ by VTK's fixed-point rounding, measured in
[vtk-bias.md](vtk-bias.md) (`bench/vtk_bias.py`), which also shows that VTK's reference does not
converge as its sampling is refined. `image-samples` lights every sample instead (the other order),
so on the shaded rows it is measured against a model it does not follow.

{chr(10).join(float_lines) if float_lines[2:] else "(not run: --no-float)"}

## Popping: change from azimuth +44° to +46°, relative to the reference's change

RMS(image at 46° − image at 44°) / the same for VTK at 1/8 sampling (not supersampled). 1 means
the mode changes exactly as much as the converged picture does; the issue's bar is 1.5.

{chr(10).join(pop_lines)}

## Pictures

Each montage is downscaled 2×; differences are |mode − reference| × 8 per channel.

{pictures}
"""
    with open(os.path.join(a.out, "README.md"), "w") as f:
        f.write(text)


def float_reference(a, cache, key, label, vol, cam, tf, n):
    """The float reference image (RGB, premultiplied over black, 8-bit quantised as the PNGs are),
    cached like VTK's. Shaded scenes are lit at the voxels and the light interpolated, VTK's order
    (`ReferenceSettings::shade_at_voxels`, decision 0019), so that it measures what VTK's reference
    would be without its rounding."""
    import numpy as np
    voxels = bool(json.load(open(tf)).get("shade", False))
    path = os.path.join(cache, f"{label}.{n}.{key}.float{'-voxels' if voxels else ''}.npy")
    if not os.path.exists(path):
        print(f"{label}: float reference (testkit, 1/8 spacing, 2×2 rays"
              f"{', lit at the voxels' if voxels else ''}) …", file=sys.stderr, flush=True)
        subprocess.run(["cargo", "run", "-q", "--release", "-p", "volsplat-testkit", "--example",
                        "reference_render", "--", vol, cam, tf, str(n), "0.125", "2",
                        path + ".tmp.npy"] + (["voxels"] if voxels else []), check=True, cwd=ROOT)
        os.replace(path + ".tmp.npy", path)
    rgb = np.load(path)[..., :3].astype(np.float64)
    return np.round(np.clip(rgb, 0, 1) * 255) / 255


def vtk_version():
    import vtk
    return vtk.vtkVersion.GetVTKVersion()


def ensure_venv():
    """Re-executes this script in `bench/vs_vtk.py`'s virtual environment (created by it)."""
    venv = os.environ.get("VTK_VENV", os.path.join(ROOT, "target", "vtk-venv"))
    py = os.path.join(venv, "bin", "python")
    if os.path.realpath(sys.prefix) == os.path.realpath(venv):
        return
    if not os.path.exists(py):
        subprocess.run([sys.executable, os.path.join(HERE, "vs_vtk.py"), "--help"], check=True,
                       capture_output=True)
    os.execv(py, [py, os.path.abspath(__file__)] + sys.argv[1:])


if __name__ == "__main__":
    ensure_venv()
    main()
