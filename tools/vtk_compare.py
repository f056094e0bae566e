#!/usr/bin/env python3
"""Render a volume with VTK's CPU ray caster (vtkFixedPointVolumeRayCastMapper) using a volsplat
camera file and transfer-function file (formats: README.md, section "Files"; conventions:
docs/architecture.md, "Frames and units"), and compare with volsplat's image.

Development tool; needs `pip install vtk numpy` (a virtual environment: tools/vtk_parity.sh keeps
one in target/vtk-venv). VTK draws offscreen: without an X display the script asks the `vtk`
wheel for its EGL window (`VTK_DEFAULT_OPENGL_WINDOW=vtkEGLRenderWindow`, Mesa's libEGL), so no
X server is needed; set VTK_DEFAULT_OPENGL_WINDOW yourself to choose another (the wheel's
`vtkOSOpenGLRenderWindow` needs libOSMesa), or run under `xvfb-run -a` where EGL is missing.

    python3 tools/vtk_compare.py VOLUME.nrrd CAMERA.json TF.json OUT_PREFIX [--size 512] [--frames 8]

Writes OUT_PREFIX.vtk.png (VTK) and prints the median VTK render time and the render window
class used. Compare with a volsplat render (its PNGs hold linear values, as VTK writes its
framebuffer; decision 0012) using `--ssim A B`; `--montage OUT.png PREFIX...` puts
PREFIX.vtk.png beside PREFIX.vs.png, one row per prefix.
"""
import json
import os
import sys
import time

import numpy as np


def ssim_gray(a, b):
    """Mean SSIM (Wang et al. 2004): 11×11 Gaussian window σ=1.5, K1=0.01, K2=0.03, L=1."""
    a = a.astype(np.float64)
    b = b.astype(np.float64)
    r = 5
    x = np.arange(-r, r + 1)
    g = np.exp(-x * x / (2 * 1.5 ** 2))
    g /= g.sum()

    def blur(im):
        im = np.apply_along_axis(lambda m: np.convolve(m, g, mode="valid"), 0, im)
        return np.apply_along_axis(lambda m: np.convolve(m, g, mode="valid"), 1, im)

    mu_a, mu_b = blur(a), blur(b)
    saa = blur(a * a) - mu_a ** 2
    sbb = blur(b * b) - mu_b ** 2
    sab = blur(a * b) - mu_a * mu_b
    c1, c2 = 0.01 ** 2, 0.03 ** 2
    s = ((2 * mu_a * mu_b + c1) * (2 * sab + c2)) / ((mu_a ** 2 + mu_b ** 2 + c1) * (saa + sbb + c2))
    return float(s.mean())


def read_png_gray(path):
    import vtk
    from vtk.util import numpy_support as ns
    r = vtk.vtkPNGReader()
    r.SetFileName(path)
    r.Update()
    img = r.GetOutput()
    w, h, _ = img.GetDimensions()
    arr = ns.vtk_to_numpy(img.GetPointData().GetScalars()).reshape(h, w, -1)[::-1].astype(np.float64) / 255.0
    rgb = arr[..., :3]
    return rgb @ np.array([0.2126, 0.7152, 0.0722]), rgb


def montage(out, prefixes):
    """Writes PREFIX.vtk.png | PREFIX.vs.png pairs, one row per prefix, at half size."""
    import zlib
    import struct

    def rgb(path):
        return (read_png_gray(path)[1] * 255 + 0.5).astype(np.uint8)[::2, ::2]

    rows = []
    for p in prefixes:
        a, b = rgb(p + ".vtk.png"), rgb(p + ".vs.png")
        gap = np.full((a.shape[0], 4, 3), 40, np.uint8)
        rows.append(np.concatenate([a, gap, b], axis=1))
        rows.append(np.full((4, rows[-1].shape[1], 3), 40, np.uint8))
    im = np.ascontiguousarray(np.concatenate(rows[:-1], axis=0))
    h, w, _ = im.shape
    raw = b"".join(b"\x00" + im[y].tobytes() for y in range(h))

    def chunk(t, d):
        return struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d) & 0xFFFFFFFF)

    with open(out, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
                + chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b""))


def offscreen():
    """Chooses VTK's EGL window when there is no X display and the user chose none; must run
    before the first render window is made."""
    if not os.environ.get("DISPLAY"):
        os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")


def main():
    offscreen()
    if sys.argv[1] == "--montage":
        montage(sys.argv[2], sys.argv[3:])
        return
    if sys.argv[1] == "--ssim":
        ga, ra = read_png_gray(sys.argv[2])
        gb, rb = read_png_gray(sys.argv[3])
        print(json.dumps({"ssim_luma": ssim_gray(ga, gb),
                          "ssim_rgb_mean": float(np.mean([ssim_gray(ra[..., c], rb[..., c]) for c in range(3)])),
                          "mean_abs_diff": float(np.abs(ra - rb).mean())}))
        return
    import vtk
    vol_path, cam_path, tf_path, prefix = sys.argv[1:5]
    size = int(sys.argv[sys.argv.index("--size") + 1]) if "--size" in sys.argv else 512
    frames = int(sys.argv[sys.argv.index("--frames") + 1]) if "--frames" in sys.argv else 8
    cam_j = json.load(open(cam_path))
    tf_j = json.load(open(tf_path))
    reader = vtk.vtkNrrdReader()
    reader.SetFileName(vol_path)
    reader.Update()
    img = reader.GetOutput()
    mapper = vtk.vtkFixedPointVolumeRayCastMapper()
    mapper.SetInputData(img)
    mapper.SetBlendModeToComposite()
    mapper.SetAutoAdjustSampleDistances(0)
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
    writer.SetFileName(prefix + ".vtk.png")
    writer.SetInputConnection(w2i.GetOutputPort())
    writer.Write()
    times = []
    for _ in range(frames):
        cam.Azimuth(0.0)
        ren.ResetCameraClippingRange()
        volume.Modified()
        t = time.perf_counter()
        rw.Render()
        times.append((time.perf_counter() - t) * 1e3)
    print(json.dumps({"vtk_median_ms": float(np.median(times)), "vtk_frames_ms": times,
                      "threads": mapper.GetNumberOfThreads(), "window": rw.GetClassName()}))


if __name__ == "__main__":
    main()
