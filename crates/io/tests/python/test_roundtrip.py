"""Round trips through the peer libraries: files written by ``volsplat convert`` read back by
nibabel (NIfTI), SimpleITK (NIfTI, MetaImage, NRRD) and pynrrd (NRRD), and files written by
those libraries read by ``volsplat info --json``, with the same samples and the same geometry.

volsplat's world frame is LPS (docs/decisions/0008); NIfTI's is RAS, so a NIfTI affine is
volsplat's with x and y negated. SimpleITK reports LPS for every format.

Run (from the repository root, after ``cargo build -p volsplat-cli``)::

    python3 -m venv /tmp/venv && /tmp/venv/bin/pip install pytest numpy nibabel SimpleITK pynrrd
    /tmp/venv/bin/pytest crates/io/tests/python

The binary is ``$VOLSPLAT_BIN``, else ``target/release/volsplat``, else ``target/debug/volsplat``
(the newer of the two). Each test is skipped when its library or the binary is missing.
"""

import json
import math
import os
import subprocess
from pathlib import Path

import pytest

np = pytest.importorskip("numpy")

ROOT = Path(__file__).resolve().parents[4]
RAS_FROM_LPS = np.diag([-1.0, -1.0, 1.0])


def volsplat_bin():
    env = os.environ.get("VOLSPLAT_BIN")
    if env:
        return Path(env)
    found = [ROOT / "target" / p / "volsplat" for p in ("release", "debug")]
    found = [p for p in found if p.exists()]
    if not found:
        pytest.skip("no volsplat binary: cargo build -p volsplat-cli, or set VOLSPLAT_BIN")
    return max(found, key=lambda p: p.stat().st_mtime)


def run(*args):
    out = subprocess.run(
        [str(volsplat_bin()), *map(str, args)], capture_output=True, text=True
    )
    assert out.returncode == 0, out.stderr
    return out


def rotation(axis, degrees):
    axis = np.asarray(axis, float)
    axis /= np.linalg.norm(axis)
    x, y, z = axis
    c, s = math.cos(math.radians(degrees)), math.sin(math.radians(degrees))
    k = np.array([[0, -z, y], [z, 0, -x], [-y, x, 0]])
    return np.eye(3) * c + s * k + (1 - c) * np.outer(axis, axis)


# Geometries (LPS): direction columns are the world directions of i, j, k.
GEOMETRIES = {
    "identity": np.eye(3),
    "flips": np.diag([-1.0, 1.0, -1.0]),
    "permuted": np.array([[0.0, 1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]]),
    "oblique": rotation([0.2, 1.0, -0.4], 37.0),
    "oblique-reflection": rotation([1.0, -0.3, 0.5], 120.0) @ np.diag([1.0, 1.0, -1.0]),
}
SPACING = np.array([0.5, 1.25, 2.0])
ORIGIN = np.array([-10.5, 3.0, 7.25])
DIMS = (5, 4, 3)  # i, j, k


def samples():
    """int16 samples, i fastest: array indexed [k, j, i]."""
    n = DIMS[0] * DIMS[1] * DIMS[2]
    return (np.arange(n, dtype=np.int16) * 37 - 600).reshape(DIMS[::-1])


def write_nrrd(path, direction):
    """The input: an LPS NRRD written by hand (no library involved)."""
    cols = direction * SPACING
    vec = lambda v: "(" + ",".join(repr(float(x)) for x in v) + ")"
    header = (
        "NRRD0004\ntype: int16\ndimension: 3\nspace: left-posterior-superior\n"
        f"sizes: {DIMS[0]} {DIMS[1]} {DIMS[2]}\n"
        f"space directions: {vec(cols[:, 0])} {vec(cols[:, 1])} {vec(cols[:, 2])}\n"
        f"endian: little\nencoding: raw\nspace origin: {vec(ORIGIN)}\n\n"
    )
    path.write_bytes(header.encode() + samples().astype("<i2").tobytes())


def lps_affine(direction):
    a = np.eye(4)
    a[:3, :3] = direction * SPACING
    a[:3, 3] = ORIGIN
    return a


@pytest.fixture(params=sorted(GEOMETRIES))
def source(request, tmp_path):
    direction = GEOMETRIES[request.param]
    path = tmp_path / "in.nrrd"
    write_nrrd(path, direction)
    return path, direction


@pytest.mark.parametrize("name", ["out.nii", "out.nii.gz"])
def test_nifti_read_by_nibabel(source, tmp_path, name):
    nib = pytest.importorskip("nibabel")
    src, direction = source
    out = tmp_path / name
    run("convert", src, "-o", out, "-q")
    img = nib.load(str(out))
    want = np.diag([-1.0, -1.0, 1.0, 1.0]) @ lps_affine(direction)
    # float32 storage: agree to float32 precision.
    np.testing.assert_allclose(img.affine, want, atol=2e-6)
    np.testing.assert_allclose(img.get_sform(), want, atol=2e-6)
    np.testing.assert_allclose(img.get_qform(), want, atol=2e-6)
    assert int(img.header["sform_code"]) == 1 and int(img.header["qform_code"]) == 1
    assert img.header.get_data_dtype() == np.dtype("<i2")
    # nibabel moves the header's scaling into the array proxy when it loads.
    assert (img.dataobj.slope, img.dataobj.inter) == (1.0, 0.0)
    # nibabel's array is indexed [i, j, k].
    np.testing.assert_array_equal(np.asanyarray(img.dataobj), samples().transpose(2, 1, 0))


@pytest.mark.parametrize("name", ["out.nii.gz", "out.mha", "out.mhd", "out.nrrd"])
@pytest.mark.parametrize("gzip", [False, True])
def test_read_by_simpleitk(source, tmp_path, name, gzip):
    sitk = pytest.importorskip("SimpleITK")
    src, direction = source
    out = tmp_path / name
    run("convert", src, "-o", out, "-q", *(["--gzip"] if gzip else []))
    img = sitk.ReadImage(str(out))
    assert img.GetSize() == DIMS
    exact = not name.startswith("out.nii")
    tol = 0.0 if exact else 2e-6
    np.testing.assert_allclose(img.GetSpacing(), SPACING, atol=tol)
    np.testing.assert_allclose(img.GetOrigin(), ORIGIN, atol=tol * 8)
    np.testing.assert_allclose(
        np.array(img.GetDirection()).reshape(3, 3), direction, atol=tol if exact else 1e-5
    )
    np.testing.assert_array_equal(sitk.GetArrayFromImage(img), samples())


def test_nrrd_read_by_pynrrd(source, tmp_path):
    nrrd = pytest.importorskip("nrrd")
    src, direction = source
    out = tmp_path / "out.nrrd"
    run("convert", src, "-o", out, "-q")
    data, header = nrrd.read(str(out))
    assert header["space"] == "left-posterior-superior"
    np.testing.assert_array_equal(header["space directions"], (direction * SPACING).T)
    np.testing.assert_array_equal(header["space origin"], ORIGIN)
    np.testing.assert_array_equal(data, samples().transpose(2, 1, 0))


def info(path):
    return json.loads(run("info", path, "--json").stdout)


def test_nibabel_files_read_by_volsplat(tmp_path):
    """NIfTI written by nibabel (sform, qform-only with qfac −1): volsplat's LPS geometry is
    nibabel's affine with x and y negated."""
    nib = pytest.importorskip("nibabel")
    data = samples().transpose(2, 1, 0)
    ras = np.diag([-1.0, -1.0, 1.0, 1.0]) @ lps_affine(GEOMETRIES["oblique-reflection"])
    img = nib.Nifti1Image(data, ras)
    img.set_qform(ras, code=1)
    img.set_sform(None, code=0)
    path = tmp_path / "nib.nii.gz"
    nib.save(img, str(path))
    j = info(path)
    lps = RAS_FROM_LPS @ nib.load(str(path)).affine[:3]
    np.testing.assert_allclose(j["origin"], lps[:, 3], atol=1e-5)
    np.testing.assert_allclose(np.array(j["direction"]) * j["spacing"], lps[:, :3], atol=1e-5)
    assert j["dims"] == list(DIMS)
    assert j["value_range"] == [float(data.min()), float(data.max())]


def test_simpleitk_files_read_by_volsplat(tmp_path):
    """MetaImage and NRRD written by SimpleITK: the same LPS geometry in volsplat."""
    sitk = pytest.importorskip("SimpleITK")
    direction = GEOMETRIES["oblique"]
    img = sitk.GetImageFromArray(samples())
    img.SetSpacing(SPACING.tolist())
    img.SetOrigin(ORIGIN.tolist())
    img.SetDirection(direction.flatten().tolist())
    for name in ["itk.mha", "itk.mhd", "itk.nrrd", "itk.nii.gz"]:
        path = tmp_path / name
        sitk.WriteImage(img, str(path))
        j = info(path)
        tol = 1e-5 if name.endswith(".nii.gz") else 1e-12
        np.testing.assert_allclose(j["spacing"], SPACING, atol=tol, err_msg=name)
        np.testing.assert_allclose(j["origin"], ORIGIN, atol=tol, err_msg=name)
        np.testing.assert_allclose(j["direction"], direction, atol=tol, err_msg=name)
        assert j["value_range"] == [float(samples().min()), float(samples().max())], name
