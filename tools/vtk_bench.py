#!/usr/bin/env python3
"""Same-machine CPU baseline: VTK's vtkFixedPointVolumeRayCastMapper on the Marschner–Lobb
volume of research/anchors.md Appendix A (our own script), for docs/BENCHMARKS.md.

    python3 tools/vtk_bench.py write OUT.nrrd N          # the u8 ML volume, also for volsplat
    xvfb-run -a python3 tools/vtk_bench.py time VOL.nrrd 512 THREADS [parallel]

Prints the median ms/frame over 8 frames orbiting 45° each, after one warm-up render.
"""
import json
import sys
import time

import numpy as np


def ml(n, f_m=6.0, a=0.25):
    x = np.linspace(-1, 1, n)
    X, Y, Z = np.meshgrid(x, x, x, indexing="ij")
    rho = np.cos(2 * np.pi * f_m * np.cos(np.pi * np.sqrt(X * X + Y * Y) / 2))
    v = (1 - np.sin(np.pi * Z / 2) + a * (1 + rho)) / (2 * (1 + a))
    return (np.clip(v, 0, 1) * 255).astype(np.uint8)  # [x, y, z]


def write(path, n):
    v = ml(n)
    with open(path, "wb") as f:
        f.write(f"NRRD0004\ntype: uint8\ndimension: 3\nsizes: {n} {n} {n}\nspacings: 1 1 1\nencoding: raw\n\n".encode())
        f.write(np.ascontiguousarray(v.transpose(2, 1, 0)).tobytes())  # x fastest


def time_vtk(path, size, threads, parallel):
    import vtk
    r = vtk.vtkNrrdReader()
    r.SetFileName(path)
    r.Update()
    img = r.GetOutput()
    lo, hi = img.GetScalarRange()
    m = vtk.vtkFixedPointVolumeRayCastMapper()
    m.SetInputData(img)
    m.SetBlendModeToComposite()
    m.SetAutoAdjustSampleDistances(0)
    m.SetNumberOfThreads(threads)
    c = vtk.vtkColorTransferFunction()
    c.AddRGBPoint(lo, 0, 0, 0)
    c.AddRGBPoint(hi * 0.5, 1, 0.5, 0.3)
    c.AddRGBPoint(hi, 1, 1, 1)
    o = vtk.vtkPiecewiseFunction()
    o.AddPoint(lo, 0)
    o.AddPoint(lo + 0.3 * (hi - lo), 0)
    o.AddPoint(hi, 0.6)
    p = vtk.vtkVolumeProperty()
    p.SetColor(c)
    p.SetScalarOpacity(o)
    p.SetInterpolationTypeToLinear()
    p.SetShade(True)
    v = vtk.vtkVolume()
    v.SetMapper(m)
    v.SetProperty(p)
    ren = vtk.vtkRenderer()
    ren.AddVolume(v)
    rw = vtk.vtkRenderWindow()
    rw.SetOffScreenRendering(1)
    rw.AddRenderer(ren)
    rw.SetSize(size, size)
    ren.ResetCamera()
    cam = ren.GetActiveCamera()
    cam.SetParallelProjection(parallel)
    cam.Elevation(20)
    cam.OrthogonalizeViewUp()
    rw.Render()
    times = []
    for _ in range(8):
        cam.Azimuth(45)
        ren.ResetCameraClippingRange()
        t = time.perf_counter()
        rw.Render()
        times.append((time.perf_counter() - t) * 1e3)
    return {"vtk_median_ms": float(np.median(times)), "frames_ms": [round(t, 1) for t in times],
            "threads": threads, "parallel_projection": parallel}


if __name__ == "__main__":
    if sys.argv[1] == "write":
        write(sys.argv[2], int(sys.argv[3]))
    else:
        print(json.dumps(time_vtk(sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), len(sys.argv) > 5)))
