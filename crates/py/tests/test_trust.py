"""Issue 28, "no crash, no silent surprise", at the Python boundary: allocation failures are
``MemoryError`` (the interpreter keeps running), and an affine means what nibabel means."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import numpy as np
import pytest
import volsplat
from conftest import blob, write_nifti

resource = pytest.importorskip("resource", reason="address-space limits need POSIX")


def run_limited(code: str, limit_gib: float, tmp_path) -> subprocess.CompletedProcess:
    """Runs ``code`` in a fresh interpreter whose address space is limited to ``limit_gib``
    GiB (RLIMIT_AS, set after the imports); what it prints comes back."""
    script = tmp_path / "limited.py"
    script.write_text(
        textwrap.dedent(
            f"""
            import resource, sys
            import numpy as np
            import volsplat
            limit = int({limit_gib} * (1 << 30))
            resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
            """
        )
        + textwrap.dedent(code)
    )
    return subprocess.run(
        [sys.executable, str(script)], capture_output=True, text=True, timeout=300, cwd=tmp_path
    )


def exited_cleanly(r: subprocess.CompletedProcess) -> None:
    assert r.returncode == 0, (
        f"the interpreter died (exit status {r.returncode}):\n{r.stdout}\n{r.stderr[-3000:]}"
    )


@pytest.mark.skipif(sys.platform != "linux", reason="RLIMIT_AS is enforced on Linux")
def test_a_volume_too_big_to_copy_is_a_memory_error(tmp_path):
    # A 2.5 GB array (np.zeros: address space only, no memory touched) under a 4 GiB
    # address-space limit: the volume's copy does not fit. Contiguous (one memcpy), strided (a
    # gather) and converted (numpy's astype) copies all raise MemoryError, and the interpreter
    # goes on to build a small volume.
    r = run_limited(
        """
        a = np.zeros((1250, 1000, 2000), np.uint8)
        for name, arr, kw in [
            ("contiguous", a, {}),
            ("strided", a[:, :, ::-1], {}),
            ("xyz", a, {"axes": "xyz"}),
            ("converted", a.view(bool), {}),
        ]:
            try:
                volsplat.Volume(arr, **kw)
                print(name, "no error")
            except MemoryError as e:
                print(name, "MemoryError", e)
            sys.stdout.flush()
        del a
        v = volsplat.Volume(np.ones((4, 5, 6), np.int16))
        print("after", v.shape, int(v.array.sum()))
        """,
        4,
        tmp_path,
    )
    exited_cleanly(r)
    lines = r.stdout.splitlines()
    for name in ("contiguous", "strided", "xyz", "converted"):
        line = next((s for s in lines if s.startswith(name + " ")), None)
        assert line is not None and "MemoryError" in line, r.stdout
    assert "cannot allocate 2500000000 bytes" in r.stdout, r.stdout
    assert "after (4, 5, 6) 120" in lines, r.stdout


@pytest.mark.skipif(sys.platform != "linux", reason="RLIMIT_AS is enforced on Linux")
def test_loading_a_file_too_big_for_memory_raises(tmp_path):
    # Files that declare huge sizes: truncated ones are errors naming the file; a complete
    # 600 MB NRRD (gzip, or raw: a sparse file) read twice under a 1 GiB limit cannot be held
    # twice: the second read must raise (MemoryError, or the reader's own error), never abort
    # the interpreter.
    import gzip
    import zlib

    big = b"NRRD0004\ntype: float\ndimension: 3\nsizes: 1024 1024 1024\nendian: little\n"
    (tmp_path / "truncated.nrrd").write_bytes(
        big + b"encoding: gzip\n\n" + gzip.compress(b"\0" * 100000)
    )
    (tmp_path / "short.nrrd").write_bytes(big + b"encoding: raw\n\n" + b"\0" * 1000)
    c = zlib.compressobj(1, zlib.DEFLATED, 31)  # gzip
    chunk = b"\0" * (1 << 20)
    payload = b"".join(c.compress(chunk) for _ in range(600)) + c.flush()
    header = b"NRRD0004\ntype: uint8\ndimension: 3\nsizes: 1024 1024 600\nendian: little\n"
    (tmp_path / "full.nrrd").write_bytes(header + b"encoding: gzip\n\n" + payload)
    with open(tmp_path / "raw.nrrd", "wb") as f:
        f.write(header + b"encoding: raw\n\n")
        f.truncate(f.tell() + 1024 * 1024 * 600)
    r = run_limited(
        """
        for name in ["truncated.nrrd", "short.nrrd"]:
            try:
                volsplat.load(name)
            except volsplat.InvalidInputError as e:
                print(name, "InvalidInputError", e)
        for name in ["full.nrrd", "raw.nrrd"]:
            kept = volsplat.load(name)
            print(name, "first", kept.shape)
            sys.stdout.flush()
            try:
                volsplat.load(name)
                print(name, "second loaded")
            except MemoryError as e:
                print(name, "second MemoryError", e)
            except volsplat.VolsplatError as e:
                print(name, "second", type(e).__name__, e)
            sys.stdout.flush()
            del kept
        """,
        1,
        tmp_path,
    )
    exited_cleanly(r)
    out = r.stdout
    assert "truncated.nrrd InvalidInputError" in out and "short.nrrd InvalidInputError" in out
    for name in ["full.nrrd", "raw.nrrd"]:
        assert f"{name} first (600, 1024, 1024)" in out, out
        assert f"{name} second MemoryError" in out or f"{name} second InvalidInputError" in out, (
            out
        )


def oblique_ras_affine() -> np.ndarray:
    """Rotations about three axes, anisotropic spacing and an offset: an oblique scan."""

    def rot(axis: int, deg: float) -> np.ndarray:
        c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
        i, j = [k for k in range(3) if k != axis]
        m = np.eye(3)
        m[i, i], m[j, j], m[i, j], m[j, i] = c, c, -s, s
        return m

    aff = np.eye(4)
    aff[:3, :3] = rot(2, 25) @ rot(0, 15) @ rot(1, -10) @ np.diag([0.9, 1.2, 2.0])
    aff[:3, 3] = (-15.0, 22.0, 7.0)
    return aff


def test_a_nibabel_affine_is_ras(tmp_path):
    # Issue 28 §6: Volume(img.get_fdata(), affine=img.affine) is the volume volsplat.load reads
    # from the same NIfTI file (nibabel's affine is RAS; it was taken as LPS, showing the back
    # of the head from the front), bit for bit; space="LPS" takes an LPS affine.
    nib = pytest.importorskip("nibabel")
    a = blob(shape_zyx=(20, 28, 36), dtype=np.float32).transpose()  # (x, y, z)
    nib.Nifti1Image(a, oblique_ras_affine()).to_filename(tmp_path / "oblique.nii.gz")
    img = nib.load(tmp_path / "oblique.nii.gz")
    loaded = volsplat.load(tmp_path / "oblique.nii.gz")
    options = dict(size=64, azimuth=200, elevation=10, transfer_function="ramp")
    expect = volsplat.render(loaded, **options).rgba
    assert expect[..., 3].max() > 0.1

    v = volsplat.Volume(img.get_fdata(), affine=img.affine)
    np.testing.assert_array_equal(volsplat.render(v, **options).rgba, expect)
    # nibabel's (x, y, z) order, as the reader's grid: hence the same bits, not just the same
    # geometry (another memory layout rounds differently).
    assert v.axes == "xyz" and v.shape == a.shape
    np.testing.assert_array_equal(v.array, a)
    # Its affine is nibabel's again; the LPS one is volsplat's world, as the reader gives it.
    np.testing.assert_allclose(v.affine, img.affine, atol=1e-12)
    np.testing.assert_allclose(v.affine_lps, loaded.with_axes("xyz").affine_lps, atol=1e-12)
    np.testing.assert_array_equal(v.origin, loaded.origin)

    lps = np.diag([-1.0, -1.0, 1.0, 1.0]) @ img.affine
    w = volsplat.Volume(img.get_fdata(), affine=lps, space="LPS")
    np.testing.assert_array_equal(volsplat.render(w, **options).rgba, expect)
    r = volsplat.Volume(img.get_fdata(), affine=img.affine, space="ras")
    np.testing.assert_array_equal(volsplat.render(r, **options).rgba, expect)
    # The old reading (RAS numbers taken as LPS) is a different picture: the test can fail.
    wrong = volsplat.Volume(img.get_fdata(), affine=img.affine, space="LPS")
    assert not np.array_equal(volsplat.render(wrong, **options).rgba, expect)
    # origin/direction keep ITK's LPS (SimpleITK's numbers), unless space="RAS".
    d = volsplat.Volume(a, axes="xyz", origin=(1, 2, 3))
    assert d.origin == (1.0, 2.0, 3.0)
    d = volsplat.Volume(a, axes="xyz", origin=(1, 2, 3), space="RAS")
    assert d.origin == (-1.0, -2.0, 3.0)
    with pytest.raises(volsplat.InvalidInputError, match="space"):
        volsplat.Volume(a, affine=img.affine, space="LAS")


def test_view_option_and_camera_field():
    vol = volsplat.phantom("head", 24)
    cam = volsplat.Camera(view="A", azimuth=10)
    assert cam.view == "anterior" and cam.to_dict()["orbit"]["view"] == "anterior"
    assert cam.replace(view="left").view == "left" and cam.replace(view=None).view is None
    scene = volsplat.Scene(vol, view="superior", size=16)
    assert scene.camera.view == "superior"
    # Each view looks at its side of the LPS patient frame: anterior from −y, with +z up.
    c = volsplat.Renderer(vol).camera(view="anterior")
    eye = np.subtract(c.position, c.focal_point)
    np.testing.assert_allclose(eye / np.linalg.norm(eye), [0, -1, 0], atol=1e-12)
    np.testing.assert_allclose(c.view_up, [0, 0, 1], atol=1e-12)
    front = volsplat.render(vol, view="anterior", size=24).rgba
    back = volsplat.render(vol, view="posterior", size=24).rgba
    assert not np.array_equal(front, back)
    with pytest.raises(volsplat.InvalidInputError, match="sideways"):
        volsplat.render(vol, view="sideways")
    with pytest.raises(volsplat.InvalidInputError, match="view"):
        volsplat.Camera(view=3)


def nan_background(shape_zyx=(28, 32, 36)) -> np.ndarray:
    """A smooth float32 blob inside a sphere and NaN outside: a masked image as SPM writes."""
    a = blob(shape_zyx, np.float32) + 10.0
    z, y, x = np.meshgrid(*(np.linspace(-1, 1, n) for n in shape_zyx), indexing="ij")
    a[x**2 + y**2 + z**2 > 0.8] = np.nan
    return a


def test_a_nan_background_renders_and_says_so(tmp_path):
    # Issue 28 follow-up: NaN samples refused whole files that nibabel, ITK, Slicer and napari
    # read. Now NaN is the lowest finite value (background: transparent, out of MIP).
    a = nan_background()
    with pytest.warns(UserWarning, match=r"samples were NaN, taken as the lowest finite value"):
        vol = volsplat.Volume(a)
    assert not np.isnan(vol.array).any()
    assert vol.array.min() == np.nanmin(a)
    for mode in ("composite", "mip", "minip"):
        img = volsplat.render(vol, size=40, azimuth=30, mode=mode)
        assert np.all(np.isfinite(img.rgba)), mode
        if mode == "minip":
            # Rays cross the background, now the lowest value: MinIP shows it (decision 0030).
            assert img.values[20, 20] == pytest.approx(np.nanmin(a), abs=0.5)
        else:
            assert img.rgba[..., :3].max() > 0.05, f"{mode}: black"
        assert any("NaN" in n for n in img.notes), img.notes
    # MIP sees the data's maximum, not the replacement.
    mip = volsplat.render(vol, size=40, mode="mip").values
    assert 0.9 * np.nanmax(a) < np.nanmax(mip) <= 1.01 * np.nanmax(a)
    # A file: the note reaches .notes and a warning naming the file.
    write_nifti(tmp_path / "masked.nii", a.transpose(2, 1, 0), np.eye(4))
    with pytest.warns(UserWarning, match=r"masked\.nii: .*NaN"):
        f = volsplat.load(tmp_path / "masked.nii")
    assert any("taken as the lowest finite value" in n for n in f.notes), f.notes
    np.testing.assert_array_equal(np.asarray(f.with_axes("zyx").array), vol.array)


def test_nibabels_nan_test_file(tmp_path):
    # nibabel's own test file (an image resampled with NaN outside the field of view).
    nib = pytest.importorskip("nibabel")
    import os

    path = os.path.join(os.path.dirname(nib.__file__), "tests", "data", "resampled_anat_moved.nii")
    if not os.path.exists(path):
        pytest.skip("this nibabel has no resampled_anat_moved.nii")
    ref = np.asarray(nib.load(path).get_fdata(dtype=np.float32))
    assert np.isnan(ref).any()
    with pytest.warns(UserWarning, match="NaN"):
        vol = volsplat.load(path, axes="xyz")
    expect = np.where(np.isnan(ref), np.nanmin(ref), ref)
    np.testing.assert_array_equal(np.asarray(vol.array), expect)
    img = volsplat.render(vol, size=48)
    assert np.all(np.isfinite(img.rgba)) and img.rgba[..., :3].max() > 0.05


@pytest.mark.skipif(sys.platform != "linux", reason="RLIMIT_AS is enforced on Linux")
def test_a_render_whose_normal_field_does_not_fit_raises_memory_error(tmp_path):
    # Issue 28 follow-up: a 524 MB u8 volume loads under a 1.25 GiB address-space limit, but
    # its normal field (shading at the voxels, 2 bytes per voxel: 1 GB) does not; the render
    # aborted the interpreter. Now MemoryError naming it, and the interpreter goes on. The
    # file is sparse: zeros with a bright cube (which the automatic function shades).
    nx, ny, nz = 1024, 1024, 500
    with open(tmp_path / "big.nrrd", "wb") as f:
        f.write(b"NRRD0004\ntype: uint8\ndimension: 3\nsizes: 1024 1024 500\nencoding: raw\n\n")
        base = f.tell()
        for k in range(200, 300):
            for j in range(400, 600):
                f.seek(base + (k * ny + j) * nx + 400)
                f.write(b"\xc8" * 200)
        f.truncate(base + nx * ny * nz)
    r = run_limited(
        """
        vol = volsplat.load("big.nrrd")
        print("loaded", vol.shape)
        sys.stdout.flush()
        try:
            # Lit at the voxels, as VTK lights them: the default lights the samples (decision
            # 0036), which needs no normal field.
            volsplat.render(vol, size=32, threads=2, shade_at="voxels")
            print("rendered")
        except MemoryError as e:
            print("MemoryError", e)
        del vol
        img = volsplat.render(volsplat.phantom("blobs", 16), size=16)
        print("after", img.shape)
        """,
        1.25,
        tmp_path,
    )
    exited_cleanly(r)
    assert "loaded (500, 1024, 1024)" in r.stdout, r.stdout + r.stderr[-2000:]
    assert "MemoryError not enough memory for the normal field" in r.stdout, r.stdout
    assert "(1048576002 bytes)" in r.stdout and "after (16, 16)" in r.stdout, r.stdout
