#!/usr/bin/env python3
"""Same-run speed and quality comparison of volsplat against VTK's CPU ray caster
(`vtkFixedPointVolumeRayCastMapper`), issue 12 item 6 and docs/design.md §7. Optional; never run in CI.

    python3 bench/vs_vtk.py [--bin [LABEL=]target/release/volsplat ...] [--scenes DIR] [--data DIR]
                            [--size 512] [--threads 2] [--frames 5] [--rounds 1] [--only SUBSTR]
                            [--markdown OUT.md] [--keep DIR]

For every scene `<volume>__<name>.camera.json` + `.tf.json` of `../shared/data/scenes` (the two
MRIs × composite, shaded, MIP, perspective) it

1. renders the scene with VTK (linear interpolation, sample distance 0.5 × the smallest spacing,
   image sample distance 1, `AutoAdjustSampleDistancesOff`, `--threads` threads; one warm-up frame,
   which also encodes VTK's gradients, then the median of `--frames` frames), in a subprocess so that
   its peak memory is its own;
2. times `volsplat bench VOL --camera … --tf … --size N --threads T --frames F --orbit 0` (one
   warm-up frame, then the median; `bench` counts everything but file loading);
3. renders `volsplat render` with the same files (PNG, linear values as VTK writes them) and computes
   SSIM (luma; Wang et al. 2004, as `tools/vtk_compare.py`) and PSNR (RGB) against VTK's image;

and prints a Markdown table of the ratios volsplat / VTK. VTK and volsplat alternate scene by scene
(and `--rounds` times), so both see the same machine load; compare ratios, not absolute times.
`--bin` may be repeated (`--bin before=/tmp/a --bin after=target/release/volsplat`) to compare builds
against the same VTK timings.

The script runs itself inside its own virtual environment (`target/vtk-venv`, or `$VTK_VENV`),
installing `vtk` and `numpy` from PyPI on first use, as `tools/vtk_parity.sh` does. VTK draws
offscreen through EGL (`VTK_DEFAULT_OPENGL_WINDOW=vtkEGLRenderWindow`, Mesa's EGL) and falls back to
`xvfb-run` when EGL cannot make a context.
"""
import argparse
import json
import math
import os
import statistics
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
VOLUMES = {"mri_brainsmall": "mri_brainsmall.nrrd", "mri_colin27": "mri_colin27.nhdr"}
ORDER = ["composite_ortho", "composite_shaded_ortho", "mip_ortho", "composite_persp",
         "composite_shaded_persp"]


def ensure_venv(script=None):
    """Re-executes `script` (default: this one) with the virtual environment's Python, creating
    it if needed."""
    venv = os.environ.get("VTK_VENV", os.path.join(ROOT, "target", "vtk-venv"))
    py = os.path.join(venv, "bin", "python")
    if os.path.realpath(sys.prefix) == os.path.realpath(venv):
        return
    ok = os.path.exists(py) and subprocess.run(
        [py, "-c", "import vtk, numpy"], capture_output=True).returncode == 0
    if not ok:
        print(f"installing vtk and numpy into {venv} …", file=sys.stderr)
        subprocess.run([sys.executable, "-m", "venv", venv], check=True)
        subprocess.run([py, "-m", "pip", "install", "-q", "vtk", "numpy"], check=True)
    os.execv(py, [py, os.path.abspath(script or __file__)] + sys.argv[1:])


def run_measured(cmd, env=None):
    """Runs `cmd`, returning its stdout."""
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
    out, err = p.communicate()
    if p.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed ({p.returncode}):\n{err.decode()[-2000:]}")
    return out.decode()


def peak_rss_cmd(cmd, env=None):
    """Runs `cmd` and returns (stdout, peak RSS MiB) using os.wait4 for a per-process peak."""
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
    # Read all output before reaping (wait4 would deadlock on a full pipe); stderr is small.
    out = p.stdout.read()
    err = p.stderr.read()
    _, status, ru = os.wait4(p.pid, 0)
    p.returncode = os.waitstatus_to_exitcode(status)
    if p.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed ({p.returncode}):\n{err.decode()[-2000:]}")
    return out.decode(), ru.ru_maxrss / 1024.0


# ---------------------------------------------------------------------------------------------
# VTK side (runs in a subprocess: `vs_vtk.py --vtk-worker VOL CAM TF OUT.png SIZE THREADS FRAMES`)

def vtk_worker(vol, cam_path, tf_path, out_png, size, threads, frames, sample_factor=0.5):
    """Renders one scene with VTK; `sample_factor` × the smallest spacing is the sample distance."""
    import numpy as np
    import vtk
    cam_j = json.load(open(cam_path))
    tf_j = json.load(open(tf_path))
    mip = "__mip" in os.path.basename(tf_path)
    reader = vtk.vtkNrrdReader()
    reader.SetFileName(vol)
    reader.Update()
    img = reader.GetOutput()
    mapper = vtk.vtkFixedPointVolumeRayCastMapper()
    mapper.SetInputData(img)
    if mip:
        mapper.SetBlendModeToMaximumIntensity()
    else:
        mapper.SetBlendModeToComposite()
    mapper.AutoAdjustSampleDistancesOff()
    mapper.SetSampleDistance(sample_factor * min(img.GetSpacing()))
    mapper.SetImageSampleDistance(1.0)
    mapper.SetNumberOfThreads(threads)
    color = vtk.vtkColorTransferFunction()
    for p in tf_j["color"]:
        color.AddRGBPoint(*p)
    opacity = vtk.vtkPiecewiseFunction()
    for p in tf_j["scalar_opacity"]:
        opacity.AddPoint(*p)
    prop = vtk.vtkVolumeProperty()
    prop.SetColor(color)
    prop.SetScalarOpacity(opacity)
    if tf_j.get("gradient_opacity"):
        go = vtk.vtkPiecewiseFunction()
        for p in tf_j["gradient_opacity"]:
            go.AddPoint(*p)
        prop.SetGradientOpacity(go)
    prop.SetScalarOpacityUnitDistance(tf_j.get("scalar_opacity_unit_distance", 1.0))
    prop.SetInterpolationTypeToLinear()
    prop.SetShade(bool(tf_j.get("shade", False)))
    prop.SetAmbient(tf_j.get("ambient", 0.0))
    prop.SetDiffuse(tf_j.get("diffuse", 0.7))
    prop.SetSpecular(tf_j.get("specular", 0.2))
    prop.SetSpecularPower(tf_j.get("specular_power", 10.0))
    volume = vtk.vtkVolume()
    volume.SetMapper(mapper)
    volume.SetProperty(prop)
    ren = vtk.vtkRenderer()
    ren.AddVolume(volume)
    ren.SetBackground(0, 0, 0)
    rw = vtk.vtkRenderWindow()
    rw.SetOffScreenRendering(1)
    rw.AddRenderer(ren)
    rw.SetSize(size, size)
    cam = ren.GetActiveCamera()
    cam.SetPosition(*cam_j["position"])
    cam.SetFocalPoint(*cam_j["focal_point"])
    cam.SetViewUp(*cam_j["view_up"])
    cam.SetViewAngle(cam_j.get("view_angle", 30.0))
    cam.SetParallelProjection(bool(cam_j.get("parallel_projection", False)))
    cam.SetParallelScale(cam_j.get("parallel_scale", 1.0))
    ren.ResetCameraClippingRange()
    rw.Render()  # warm-up: gradients and normals are encoded here
    w2i = vtk.vtkWindowToImageFilter()
    w2i.SetInput(rw)
    w2i.Update()
    writer = vtk.vtkPNGWriter()
    writer.SetFileName(out_png)
    writer.SetInputConnection(w2i.GetOutputPort())
    writer.Write()
    times = []
    for _ in range(frames):
        volume.Modified()
        t = time.perf_counter()
        rw.Render()
        times.append((time.perf_counter() - t) * 1e3)
    print(json.dumps({"median_ms": float(np.median(times)), "frames_ms": times,
                      "threads": mapper.GetNumberOfThreads(),
                      "window": rw.GetClassName()}))


def vtk_env_and_prefix(tmp):
    """Picks an offscreen route that works: EGL first, then xvfb-run."""
    env = dict(os.environ, VTK_DEFAULT_OPENGL_WINDOW="vtkEGLRenderWindow")
    probe = [sys.executable, "-c",
             "import vtk; w=vtk.vtkRenderWindow(); w.SetOffScreenRendering(1); w.SetSize(8,8);"
             "r=vtk.vtkRenderer(); w.AddRenderer(r); w.Render(); print(w.GetClassName())"]
    r = subprocess.run(probe, capture_output=True, env=env, timeout=120)
    if r.returncode == 0 and b"EGL" in r.stdout:
        return env, []
    return dict(os.environ), ["xvfb-run", "-a"]


# ---------------------------------------------------------------------------------------------
# Image comparison

def read_png(path):
    import numpy as np
    import vtk
    from vtk.util import numpy_support as ns
    r = vtk.vtkPNGReader()
    r.SetFileName(path)
    r.Update()
    img = r.GetOutput()
    w, h, _ = img.GetDimensions()
    arr = ns.vtk_to_numpy(img.GetPointData().GetScalars()).reshape(h, w, -1)[::-1]
    scale = 65535.0 if arr.dtype == np.uint16 else 255.0
    return arr[..., :3].astype(np.float64) / scale


def compare(a_png, b_png):
    import numpy as np
    sys.path.insert(0, os.path.join(ROOT, "tools"))
    from vtk_compare import ssim_gray  # the same SSIM as tools/vtk_parity.sh
    a, b = read_png(a_png), read_png(b_png)
    luma = np.array([0.2126, 0.7152, 0.0722])
    mse = float(np.mean((a - b) ** 2))
    psnr = float("inf") if mse == 0 else 10 * math.log10(1.0 / mse)
    return ssim_gray(a @ luma, b @ luma), psnr


# ---------------------------------------------------------------------------------------------

def volumes(scenes_dir, data_dir):
    """The volumes to measure: our two MRIs first, then any other `<name>.nrrd` or `<name>.nhdr` in
    `data_dir` that has a scene file `<name>__<scene>.camera.json` in `scenes_dir` (so a CT or a
    large MRI dropped beside them, with its own cameras and transfer functions, is measured too)."""
    found = dict(VOLUMES)
    names = set()
    if os.path.isdir(scenes_dir):
        names = {f.split("__", 1)[0] for f in os.listdir(scenes_dir) if "__" in f}
    for name in sorted(names - set(found)):
        for ext in (".nrrd", ".nhdr"):
            if os.path.exists(os.path.join(data_dir, name + ext)):
                found[name] = name + ext
                break
    return found


def scene_list(scenes_dir, data_dir, only):
    out = []
    for vol_name, vol_file in volumes(scenes_dir, data_dir).items():
        vol = os.path.join(data_dir, vol_file)
        if not os.path.exists(vol):
            print(f"skipping {vol_name}: {vol} not found", file=sys.stderr)
            continue
        for name in ORDER:
            stem = os.path.join(scenes_dir, f"{vol_name}__{name}")
            if not os.path.exists(stem + ".camera.json"):
                continue
            label = f"{vol_name}__{name}"
            if only and not any(o in label for o in only.split(",")):
                continue
            out.append((label, vol_name, name, vol, stem + ".camera.json", stem + ".tf.json"))
    return out


# ---------------------------------------------------------------------------------------------

def make_synthetic(n, vol):
    """Writes the synthetic probe volume (see `synthetic_scene`) to `vol`, atomically."""
    import numpy as np
    rng = np.random.default_rng(12)
    z, y, x = np.ogrid[0:n, 0:n, 0:n]
    field = np.zeros((n, n, n), dtype=np.float32)
    for _ in range(12):
        c = rng.uniform(0.2 * n, 0.8 * n, 3)
        r = rng.uniform(0.06 * n, 0.16 * n)
        field += np.exp(-(((x - c[0]) ** 2 + (y - c[1]) ** 2 + (z - c[2]) ** 2) / (2 * r * r)),
                        dtype=np.float32)
    field = field / field.max() * 230 + rng.uniform(0, 25, field.shape).astype(np.float32)
    data = np.clip(field, 0, 255).astype(np.uint8)
    with open(vol + ".tmp", "wb") as f:
        f.write(f"NRRD0004\ntype: uint8\ndimension: 3\nsizes: {n} {n} {n}\n"
                "spacings: 1 1 1\nencoding: raw\n\n".encode())
        f.write(data.tobytes())
    os.replace(vol + ".tmp", vol)


def synthetic_scene(n, work):
    """Issue 12's probe: an `n`³ u8 volume (smooth blobs plus a little noise, 0–255, spacing 1),
    written as NRRD with an orthographic camera and a composite transfer function; returns a
    scene tuple like `scene_list`'s. Made once per `n` in `work`."""
    vol = os.path.join(work, f"synthetic{n}.nrrd")
    cam = os.path.join(work, f"synthetic{n}__composite_ortho.camera.json")
    tf = os.path.join(work, f"synthetic{n}__composite_ortho.tf.json")
    if not os.path.exists(vol):
        # In a child process: the parent's peak memory would otherwise count in every later
        # child's peak RSS (a forked child shares its parent's pages until it execs).
        subprocess.run([sys.executable, os.path.abspath(__file__), "--make-synthetic", str(n), vol],
                       check=True)
    c = (n - 1) / 2.0
    json.dump({"position": [c + 1.2 * n, c - 0.9 * n, c + 1.5 * n], "focal_point": [c, c, c],
               "view_up": [0, 0, 1], "parallel_projection": True, "parallel_scale": 0.9 * n,
               "view_angle": 30.0}, open(cam, "w"))
    json.dump({"color": [[0, 0, 0, 0], [80, 0.8, 0.4, 0.2], [160, 1, 0.9, 0.7], [255, 1, 1, 1]],
               "scalar_opacity": [[0, 0], [60, 0], [120, 0.02], [255, 0.2]],
               "scalar_opacity_unit_distance": 1.0, "shade": False}, open(tf, "w"))
    label = f"synthetic{n}__composite_ortho"
    return (label, f"synthetic{n}", "composite_ortho", vol, cam, tf)


def volsplat_flags(name, cam):
    flags = []
    if name.startswith("mip"):
        flags += ["--mode", "mip"]
    if not json.load(open(cam)).get("parallel_projection", False):
        flags += ["--perspective"]
    return flags


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--bin", action="append", default=None,
                    help="volsplat binary, or LABEL=PATH; repeat to compare builds in the same run "
                         "(default target/release/volsplat)")
    ap.add_argument("--data", default=os.path.join(ROOT, "..", "shared", "data"))
    ap.add_argument("--scenes", default=None, help="default: DATA/scenes")
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--frames", type=int, default=5)
    ap.add_argument("--rounds", type=int, default=1, help="repeat the VTK/volsplat alternation")
    ap.add_argument("--only", default="", help="comma-separated substrings of scene names")
    ap.add_argument("--extra", default="", help="extra flags for volsplat (bench and render)")
    ap.add_argument("--markdown", default=None, help="also write the table to this file")
    ap.add_argument("--keep", default=None, help="keep the images in this folder")
    ap.add_argument("--synthetic", type=int, default=0,
                    help="add issue 12's probe: an N³ u8 volume rendered at 2N² (e.g. 512)")
    a = ap.parse_args()
    bins = []
    for i, b in enumerate(a.bin or [os.path.join(ROOT, "target", "release", "volsplat")]):
        label, _, path = b.rpartition("=")
        bins.append((label or ("volsplat" if not a.bin or len(a.bin) == 1 else f"bin{i + 1}"), path))
    scenes_dir = a.scenes or os.path.join(a.data, "scenes")
    work = a.keep or tempfile.mkdtemp(prefix="vs_vtk.")
    os.makedirs(work, exist_ok=True)
    env, prefix = vtk_env_and_prefix(work)
    extra = a.extra.split()
    rows = []
    window = "?"
    scenes = scene_list(scenes_dir, a.data, a.only)
    if a.synthetic:
        synth = os.path.join(ROOT, "target", "vs_vtk-synthetic")
        os.makedirs(synth, exist_ok=True)
        scenes.append(synthetic_scene(a.synthetic, synth))
    for label, vol_name, name, vol, cam, tf in scenes:
        size = 2 * a.synthetic if vol_name.startswith("synthetic") else a.size
        flags = volsplat_flags(name, cam) + extra
        common = [vol, "--camera", cam, "--tf", tf, "--size", str(size), "--threads", str(a.threads)]
        vtk_png = os.path.join(work, label + ".vtk.png")
        vtk_ms, vtk_rss = [], 0.0
        vs_ms = {b: [] for b, _ in bins}
        vs_rss = {b: 0.0 for b, _ in bins}
        vs_last = {}
        for _ in range(a.rounds):
            out, rss = peak_rss_cmd(prefix + [sys.executable, os.path.abspath(__file__), "--vtk-worker",
                                              vol, cam, tf, vtk_png, str(size), str(a.threads),
                                              str(a.frames)], env=env)
            vtk = json.loads(out.strip().splitlines()[-1])
            window = vtk.get("window", window)
            vtk_ms.append(vtk["median_ms"])
            vtk_rss = max(vtk_rss, rss)
            for b, path in bins:
                out, rss = peak_rss_cmd([path, "bench"] + common + flags +
                                        ["--frames", str(a.frames), "--orbit", "0"])
                vs = json.loads(out.strip().splitlines()[-1])
                vs_ms[b].append(vs["median_ms"])
                vs_rss[b] = max(vs_rss[b], rss)
                vs_last[b] = vs
        vt = statistics.median(vtk_ms)
        for b, path in bins:
            vs_png = os.path.join(work, f"{label}.{b}.vs.png")
            run_measured([path, "render"] + common + flags + ["-q", "-o", vs_png])
            # In a subprocess: importing vtk here would inflate the peak RSS of later children
            # (a forked child counts its parent's pages until it execs).
            ssim, psnr = json.loads(run_measured([sys.executable, os.path.abspath(__file__), "--compare",
                                                  vtk_png, vs_png]).strip().splitlines()[-1])
            st = statistics.median(vs_ms[b])
            vs = vs_last[b]
            rows.append(dict(scene=label, bin=b, vtk_ms=vt, vs_ms=st, ratio=st / vt, ssim=ssim,
                             psnr=psnr, vtk_rss=vtk_rss, vs_rss=vs_rss[b], renderer=vs.get("renderer"),
                             updates=vs.get("pixel_updates") or 0))
            print(f"{label} [{b}]: VTK {vt:.1f} ms, volsplat {st:.1f} ms, ratio {st / vt:.2f}, "
                  f"SSIM {ssim:.4f}, PSNR {psnr:.1f} dB", file=sys.stderr, flush=True)
    cmd = "python3 bench/vs_vtk.py " + " ".join(sys.argv[1:])
    many = len(bins) > 1
    lines = [
        f"Command: `{cmd.strip()}`; VTK window `{window}`, {a.threads} threads, {a.size}², "
        f"{a.frames} frames after a warm-up, median; {a.rounds} round(s) alternating VTK and volsplat.",
        "",
        "| scene |" + (" build |" if many else "") + " VTK ms | volsplat ms | ratio volsplat/VTK | SSIM "
        "| PSNR dB | peak RSS VTK / volsplat MiB | renderer | pixel updates |",
        "|---|" + ("---|" if many else "") + "---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(f"| {r['scene']} |" + (f" {r['bin']} |" if many else "") +
                     f" {r['vtk_ms']:.1f} | {r['vs_ms']:.1f} | **{r['ratio']:.2f}** | "
                     f"{r['ssim']:.4f} | {r['psnr']:.1f} | {r['vtk_rss']:.0f} / {r['vs_rss']:.0f} | "
                     f"{r['renderer']} | {r['updates'] / 1e6:.1f} M |")
    for b, _ in bins:
        sel = [r for r in rows if r["bin"] == b]
        if sel:
            gm = math.exp(sum(math.log(r["ratio"]) for r in sel) / len(sel))
            lines.append("| geometric mean |" + (f" {b} |" if many else "") + f" | | **{gm:.2f}** | | | | | |")
    text = "\n".join(lines)
    print(text)
    if a.markdown:
        with open(a.markdown, "w") as f:
            f.write(text + "\n")


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--make-synthetic":
        make_synthetic(int(sys.argv[2]), sys.argv[3])
    elif len(sys.argv) > 1 and sys.argv[1] == "--compare":
        print(json.dumps(compare(sys.argv[2], sys.argv[3])))
    elif len(sys.argv) > 1 and sys.argv[1] == "--vtk-worker":
        v, c, t, o, s, th, fr = sys.argv[2:9]
        factor = float(sys.argv[9]) if len(sys.argv) > 9 else 0.5
        vtk_worker(v, c, t, o, int(s), int(th), int(fr), factor)
    else:
        ensure_venv()
        main()
