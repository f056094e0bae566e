#!/usr/bin/env python3
"""The viewer's latency replay (issue 29, item 9) with VTK's level of detail on the same input.

    cargo build --release
    python3 tools/view_latency.py                          # the two MRIs and the CT-like head
    python3 tools/view_latency.py --only ct --json /tmp/lat.json --markdown /tmp/lat.md

For each volume, at 512 x 512, orthographic composite:

- volsplat: `volsplat bench-view VOL … --size 512` (the server in-process, a WebSocket client
  replaying a 10-second orbit drag at 60 events a second and a 5-second drag of a
  transfer-function opacity point; crates/view/src/replay.rs): input-to-frame latency p50/p95,
  frames per second while dragging, preview PSNR against the final frame of the same scene at
  ten points of the drag, release-to-final time.
- VTK: vtkFixedPointVolumeRayCastMapper (2 threads, linear interpolation, sample distance half
  the smallest spacing) with its own level of detail: DesiredUpdateRate 30 while dragging,
  AutoAdjustSampleDistances on, a still render (DesiredUpdateRate 0.0001) at release. The same
  events replayed in real time into an event loop that, as a GUI toolkit's does, coalesces the
  events that arrived during a render (camera: VTK's trackball Azimuth/Elevation for the same
  pixel drags; transfer function: the same opacity point moved the same way); latency = the end
  of the render that includes an event minus the event's time. Preview PSNR: after the replay,
  at the same ten scenes, the interactive frame (rate 30, after the replay's time history)
  against the still frame.

Both start from the scene volsplat resolves for the flags (`render --save-scene`): the same
camera and transfer-function files. VTK draws offscreen through EGL (bench/vs_vtk.py's route,
xvfb-run otherwise), in bench/vs_vtk.py's virtual environment (target/vtk-venv).
"""
import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "bench"))
import vs_vtk  # noqa: E402  (ensure_venv, vtk_env_and_prefix)

DATA = os.path.join(ROOT, "..", "shared", "data")
EVENTS_PER_SECOND = 60.0


def cases(data, work, binary):
    """(name, volume, volsplat flags) for each volume of the run."""
    scenes = os.path.join(data, "scenes")
    out = []
    for name, file in [("mri_brainsmall", "mri_brainsmall.nrrd"), ("mri_colin27", "mri_colin27.nhdr")]:
        vol = os.path.join(data, file)
        if os.path.exists(vol):
            s = os.path.join(scenes, name + "__composite_ortho")
            out.append((name, vol, ["--camera", s + ".camera.json", "--tf", s + ".tf.json"]))
    ct = os.path.join(work, "ct_head_256x256x108.nrrd")
    subprocess.run([binary, "phantom", "head", "--grid", "256,256,108", "-o", ct],
                   check=True, capture_output=True)
    out.append(("ct", ct, ["--preset", "CT-Bone", "--azimuth", "30", "--elevation", "15"]))
    return out


# --------------------------------------------------------------------------------------------
# The recordings (the same as crates/view/src/replay.rs: Recording::event)

def orbit_event(n):
    t = n / EVENTS_PER_SECOND
    return 3.0, 1.5 * math.sin(2 * math.pi * t / 5.0)


def tf_event(n, tf):
    t = n / EVENTS_PER_SECOND
    tf = json.loads(json.dumps(tf))
    pts = tf["scalar_opacity"]
    if len(pts) >= 2:
        lo, hi = pts[0][0], pts[-1][0]
        mid = 0.5 * (lo + hi)
        inner = range(1, len(pts) - 1)
        k = min(inner, key=lambda a: abs(pts[a][0] - mid)) if len(pts) > 2 else len(pts) - 1
        left = pts[k - 1][0] if k > 0 else lo
        right = pts[k + 1][0] if k + 1 < len(pts) else hi
        phase = math.sin(2 * math.pi * t / 2.5)
        centre, half = 0.5 * (left + right), 0.35 * (right - left)
        pts[k][0] = min(max(centre + half * phase, left), right)
        pts[k][1] = min(max(pts[k][1] * (1 + 0.5 * phase), 0.0), 1.0)
    return tf


# --------------------------------------------------------------------------------------------
# VTK side (in the virtual environment: `view_latency.py --vtk-worker VOL SCENE SIZE`)

def vtk_worker(vol, scene_path, size):
    import numpy as np
    import vtk
    scene = json.load(open(scene_path))
    cam_j = scene["scene"]["camera"]["explicit"]["camera"]
    tf_j = scene["scene"]["transfer_function"]["function"]
    reader = vtk.vtkNrrdReader()
    reader.SetFileName(vol)
    reader.Update()
    img = reader.GetOutput()
    mapper = vtk.vtkFixedPointVolumeRayCastMapper()
    mapper.SetInputData(img)
    mapper.SetBlendModeToComposite()
    mapper.SetSampleDistance(0.5 * min(img.GetSpacing()))
    mapper.AutoAdjustSampleDistancesOn()
    mapper.SetNumberOfThreads(2)
    prop = vtk.vtkVolumeProperty()
    prop.SetInterpolationTypeToLinear()

    def set_tf(tf):
        color = vtk.vtkColorTransferFunction()
        for p in tf["color"]:
            color.AddRGBPoint(*p)
        opacity = vtk.vtkPiecewiseFunction()
        for p in tf["scalar_opacity"]:
            opacity.AddPoint(*p)
        prop.SetColor(color)
        prop.SetScalarOpacity(opacity)
        if tf.get("gradient_opacity"):
            go = vtk.vtkPiecewiseFunction()
            for p in tf["gradient_opacity"]:
                go.AddPoint(*p)
            prop.SetGradientOpacity(go)
        prop.SetScalarOpacityUnitDistance(tf.get("scalar_opacity_unit_distance", 1.0))
        prop.SetShade(bool(tf.get("shade", False)))
        prop.SetAmbient(tf.get("ambient", 0.0))
        prop.SetDiffuse(tf.get("diffuse", 0.7))
        prop.SetSpecular(tf.get("specular", 0.2))
        prop.SetSpecularPower(tf.get("specular_power", 10.0))

    set_tf(tf_j)
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

    def set_camera(c):
        cam.SetPosition(*c["position"])
        cam.SetFocalPoint(*c["focal_point"])
        cam.SetViewUp(*c["view_up"])
        cam.SetViewAngle(c.get("view_angle", 30.0))
        cam.SetParallelProjection(bool(c.get("parallel_projection", False)))
        cam.SetParallelScale(c.get("parallel_scale", 1.0))
        ren.ResetCameraClippingRange()

    def camera_json():
        return {"position": list(cam.GetPosition()), "focal_point": list(cam.GetFocalPoint()),
                "view_up": list(cam.GetViewUp()), "view_angle": cam.GetViewAngle(),
                "parallel_projection": bool(cam.GetParallelProjection()),
                "parallel_scale": cam.GetParallelScale()}

    def grab():
        w2i = vtk.vtkWindowToImageFilter()
        w2i.SetInput(rw)
        w2i.ShouldRerenderOff()
        w2i.ReadFrontBufferOff()
        w2i.Update()
        out = w2i.GetOutput()
        from vtk.util.numpy_support import vtk_to_numpy
        a = vtk_to_numpy(out.GetPointData().GetScalars())
        return a.reshape(size, size, -1)[:, :, :3].astype(np.float64)

    def still():
        rw.SetDesiredUpdateRate(0.0001)
        t = time.perf_counter()
        rw.Render()
        return (time.perf_counter() - t) * 1e3

    set_camera(cam_j)
    still()  # warm-up: gradients encoded, the first frame
    still()

    def replay(kind):
        set_camera(cam_j)
        set_tf(tf_j)
        still()
        n_events = int((10.0 if kind == "orbit" else 5.0) * EVENTS_PER_SECOND)
        sample_every = n_events // 10
        samples = []
        rw.SetDesiredUpdateRate(30.0)
        latencies, frame_ms, renders = [], [], 0
        t0 = time.perf_counter()
        n = 0
        while n < n_events:
            now = time.perf_counter()
            due = [k for k in range(n, n_events) if t0 + k / EVENTS_PER_SECOND <= now]
            if not due:
                time.sleep(max(0.0, t0 + n / EVENTS_PER_SECOND - now))
                continue
            for k in due:
                if kind == "orbit":
                    dx, dy = orbit_event(k)
                    cam.Azimuth(-dx * 20.0 / size * 10.0)
                    cam.Elevation(dy * 20.0 / size * 10.0)
                    cam.OrthogonalizeViewUp()
                    ren.ResetCameraClippingRange()
                else:
                    set_tf(tf_event(k, tf_j))
                if sample_every and k % sample_every == sample_every // 2:
                    samples.append((camera_json(), tf_event(k, tf_j) if kind == "tf" else tf_j))
            t = time.perf_counter()
            rw.Render()
            done = time.perf_counter()
            frame_ms.append((done - t) * 1e3)
            renders += 1
            latencies += [(done - (t0 + k / EVENTS_PER_SECOND)) * 1e3 for k in due]
            n = due[-1] + 1
        drag_s = time.perf_counter() - t0
        isd = mapper.GetImageSampleDistance()
        release_ms = still()
        psnr = []
        for c, tf in samples:
            set_camera(c)
            set_tf(tf)
            rw.SetDesiredUpdateRate(30.0)
            rw.Render()
            lod = grab()
            still()
            full = grab()
            mse = float(np.mean((lod - full) ** 2))
            psnr.append(float("inf") if mse == 0 else 10 * math.log10(255.0 ** 2 / mse))
        lat = np.array(latencies)
        return {"recording": kind, "events": n_events, "renders": renders,
                "latency_p50_ms": float(np.percentile(lat, 50, method="inverted_cdf")),
                "latency_p95_ms": float(np.percentile(lat, 95, method="inverted_cdf")),
                "drag_fps": renders / drag_s,
                "frame_ms_median": float(np.median(frame_ms)),
                "release_to_final_ms": release_ms,
                "preview_psnr_db": psnr,
                "image_sample_distance_at_release": isd}

    set_camera(cam_j)
    still()
    start = grab()
    np.save(scene_path + ".vtk_start.npy", start.astype("uint8"))
    print(json.dumps({"window": rw.GetClassName(), "replays": [replay("orbit"), replay("tf")]}))


# --------------------------------------------------------------------------------------------

def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--bin", default=os.path.join(ROOT, "target", "release", "volsplat"))
    ap.add_argument("--data", default=DATA)
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--only", help="run the cases whose name contains this")
    ap.add_argument("--json", help="write all results to this file")
    ap.add_argument("--markdown", help="write the table to this file")
    ap.add_argument("--no-vtk", action="store_true")
    args = ap.parse_args()
    results = []
    with tempfile.TemporaryDirectory() as work:
        env, prefix = vs_vtk.vtk_env_and_prefix(work) if not args.no_vtk else (None, [])
        for name, vol, flags in cases(args.data, work, args.bin):
            if args.only and args.only not in name:
                continue
            print(f"{name}: volsplat …", file=sys.stderr)
            scene = os.path.join(work, name + ".scene.json")
            subprocess.run([args.bin, "render", vol, *flags, "--size", str(args.size),
                            "--save-scene", scene, "-o", os.path.join(work, name + ".png"),
                            "--quiet"], check=True)
            load = os.getloadavg()[0]
            r = subprocess.run([args.bin, "bench-view", vol, *flags, "--size", str(args.size)],
                               capture_output=True)
            if r.returncode != 0:
                sys.exit(f"bench-view failed on {name}:\n{r.stderr.decode()[-3000:]}")
            ours = json.loads(r.stdout)
            entry = {"case": name, "volume": os.path.basename(vol), "size": args.size,
                     "load_before": load, "volsplat": ours}
            if not args.no_vtk:
                print(f"{name}: VTK …", file=sys.stderr)
                out = subprocess.run(prefix + [sys.executable, os.path.abspath(__file__),
                                               "--vtk-worker", vol, scene, str(args.size)],
                                     check=True, capture_output=True, env=env).stdout
                entry["vtk"] = json.loads(out)
                entry["start_frame_psnr_db"] = start_psnr(os.path.join(work, name + ".png"),
                                                          scene + ".vtk_start.npy")
            results.append(entry)
            print(json.dumps(entry), file=sys.stderr)
    table = markdown(results, args)
    print(table)
    if args.json:
        json.dump(results, open(args.json, "w"), indent=1)
    if args.markdown:
        open(args.markdown, "w").write(table)


def start_psnr(png_path, npy_path):
    """PSNR of volsplat's start frame against VTK's still frame (the two tools agree on the
    scene: a check of the set-up, not a result)."""
    import numpy as np
    a = vs_vtk.read_png(png_path) * 255.0  # rows top-down, values in [0, 1]
    b = np.load(npy_path).astype(np.float64)[::-1]  # VTK's rows run bottom-up
    mse = float(np.mean((a - b) ** 2))
    return float("inf") if mse == 0 else 10 * math.log10(255.0 ** 2 / mse)


def markdown(results, args):
    rows = ["| volume | recording | tool | p50 ms | p95 ms | frames/s dragging | preview PSNR dB (min / mean) | release → final ms |",
            "|---|---|---|---|---|---|---|---|"]
    for e in results:
        tools = [("volsplat", e["volsplat"]["replays"])]
        if "vtk" in e:
            tools.append(("VTK LOD", e["vtk"]["replays"]))
        for k in range(2):
            for tool, reps in tools:
                r = reps[k]
                # JSON has no infinity: a preview identical to the final frame is null.
                p = [x for x in r["preview_psnr_db"] if x is not None and math.isfinite(x)]
                p = p or [float("inf")]
                rows.append(f"| {e['case']} | {r['recording']} | {tool} | {r['latency_p50_ms']:.0f} | "
                            f"{r['latency_p95_ms']:.0f} | {r['drag_fps']:.0f} | "
                            f"{min(p):.1f} / {sum(p) / len(p):.1f} | {r['release_to_final_ms']:.0f} |")
    return "\n".join(rows) + "\n"


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--vtk-worker":
        vs_vtk.ensure_venv(__file__)
        vtk_worker(sys.argv[2], sys.argv[3], int(sys.argv[4]))
    else:
        vs_vtk.ensure_venv(__file__)
        main()
