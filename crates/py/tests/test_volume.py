"""Volumes from numpy arrays: dtypes, axis orders, layouts, geometry, bad input, files."""

from __future__ import annotations

import re

import numpy as np
import pytest
import volsplat
from conftest import blob

KEPT = [np.uint8, np.int8, np.uint16, np.int16, np.float32]
CONVERTED = [np.float64, np.int32, np.uint32, np.int64, np.float16]


def render(vol, **kw):
    kw.setdefault("size", 48)
    kw.setdefault("azimuth", 30)
    kw.setdefault("elevation", 20)
    return volsplat.render(vol, **kw)


@pytest.mark.parametrize("dtype", KEPT)
def test_native_dtypes_are_kept_and_render(dtype):
    a = blob(dtype=dtype)
    v = volsplat.Volume(a)
    assert v.dtype == np.dtype(dtype).name
    assert v.array.dtype == dtype
    assert v.shape == a.shape
    np.testing.assert_array_equal(v.array, a)
    img = render(v)
    assert img.rgba.shape == (48, 48, 4) and img.rgba.dtype == np.float32
    assert img.rgba[..., 3].max() > 0.05, "the volume is visible"
    assert img.rgba[0, 0, 3] == 0.0, "the corner is empty"


@pytest.mark.parametrize("dtype", CONVERTED)
def test_other_real_dtypes_become_float32(dtype):
    a = blob(dtype=np.int16).astype(dtype)
    v = volsplat.Volume(a)
    assert v.dtype == "float32"
    np.testing.assert_array_equal(v.array, a.astype(np.float32))
    assert any("float32" in n for n in v.notes)
    # The same values as int16 and as float32 render alike (the engine classifies in f32).
    ref = render(volsplat.Volume(a.astype(np.float32)))
    np.testing.assert_array_equal(render(v).rgba, ref.rgba)


def test_bool_becomes_uint8():
    a = blob() > 300
    v = volsplat.Volume(a)
    assert v.dtype == "uint8"
    np.testing.assert_array_equal(v.array, a.astype(np.uint8))


def test_explicit_dtype_conversion_and_its_checks():
    a = blob(dtype=np.int16).astype(np.float64)
    v = volsplat.Volume(a, dtype="int16")
    assert v.dtype == "int16"
    np.testing.assert_array_equal(v.array, a.astype(np.int16))
    with pytest.raises(volsplat.InvalidInputError, match="cannot\\s+represent"):
        volsplat.Volume(a + 0.5, dtype="int16")
    with pytest.raises(volsplat.InvalidInputError, match="uint8"):
        volsplat.Volume(a, dtype="uint8")  # negative values
    with pytest.raises(volsplat.InvalidInputError, match="dtype"):
        volsplat.Volume(a, dtype="complex64")


def test_big_endian_arrays_are_converted():
    a = blob(dtype=np.int16)
    v = volsplat.Volume(a.astype(">i2"))
    assert v.dtype == "int16"
    np.testing.assert_array_equal(v.array, a)


@pytest.mark.parametrize("dtype", [np.uint8, np.int16, np.float32])
def test_xyz_order_is_the_same_volume(dtype):
    a = blob(dtype=dtype)
    zyx = volsplat.Volume(a, spacing=(3.0, 2.0, 1.0))
    xyz = volsplat.Volume(a.transpose(), spacing=(1.0, 2.0, 3.0), axes="xyz")
    assert zyx.info()["dims_xyz"] == xyz.info()["dims_xyz"] == [32, 28, 24]
    assert zyx.info()["spacing_xyz"] == xyz.info()["spacing_xyz"] == [1.0, 2.0, 3.0]
    assert xyz.spacing == (1.0, 2.0, 3.0) and zyx.spacing == (3.0, 2.0, 1.0)
    assert xyz.shape == (32, 28, 24)
    np.testing.assert_array_equal(xyz.array, a.transpose())
    np.testing.assert_array_equal(render(zyx).rgba, render(xyz).rgba)
    # nibabel's arrays are usually Fortran-ordered (x, y, z): the same memory as C (z, y, x).
    f = np.asfortranarray(a.transpose())
    np.testing.assert_array_equal(
        render(volsplat.Volume(f, spacing=(1, 2, 3), axes="xyz")).rgba, render(zyx).rgba
    )


def test_with_axes_shares_the_samples():
    v = volsplat.Volume(blob())
    w = v.with_axes("xyz")
    assert w.axes == "xyz" and w.shape == v.shape[::-1]
    np.testing.assert_array_equal(w.array, v.array.T)
    assert np.shares_memory(w.array, v.array)


@pytest.mark.parametrize(
    "make",
    [
        lambda a: a[::2, :, ::3],  # strided view
        lambda a: a[:, ::-1, :],  # negative strides
        lambda a: np.asfortranarray(a),  # Fortran order, declared (z, y, x)
        lambda a: a.transpose(1, 0, 2),  # permuted view
        lambda a: np.broadcast_to(a[:1], a.shape),  # zero stride
    ],
)
def test_non_contiguous_arrays(make):
    view = make(blob())
    assert not view.flags.c_contiguous or view.strides[0] == 0
    v = volsplat.Volume(view)
    np.testing.assert_array_equal(v.array, np.ascontiguousarray(view))
    np.testing.assert_array_equal(
        render(v).rgba, render(volsplat.Volume(np.ascontiguousarray(view))).rgba
    )


def test_array_is_a_read_only_zero_copy_view():
    v = volsplat.Volume(blob())
    a1, a2 = v.array, v.array
    assert not a1.flags.writeable
    assert np.shares_memory(a1, a2), "the same samples each time, no copy"
    with pytest.raises(ValueError):
        a1[0, 0, 0] = 1
    # The view outlives the Python name of its volume.
    del v
    assert a1.sum() > 0
    assert np.asarray(volsplat.Volume(blob())).shape == (24, 28, 32)


def test_the_input_array_is_copied_once():
    a = blob()
    v = volsplat.Volume(a)
    a[...] = 0  # changing the caller's array does not change the volume
    assert v.array.max() > 0


@pytest.mark.parametrize(
    "array, match",
    [
        (np.zeros((4, 5), np.float32), "3-D"),
        (np.zeros((2, 3, 4, 5), np.float32), "3-D"),
        (np.zeros((0, 3, 4), np.float32), "at least one"),
        (np.zeros((3, 4, 5), np.complex64), "unsupported dtype"),
        (np.zeros((3, 4, 5), object), "unsupported dtype"),
        (np.full((3, 4, 5), "a"), "unsupported dtype"),
        (np.zeros((3, 4, 5), "datetime64[s]"), "unsupported dtype"),
    ],
)
def test_bad_shapes_and_dtypes(array, match):
    with pytest.raises(volsplat.InvalidInputError, match=match) as e:
        volsplat.Volume(array)
    assert isinstance(e.value, ValueError) and isinstance(e.value, volsplat.VolsplatError)


def test_nan_becomes_the_lowest_finite_value_with_a_warning():
    # Issue 28 follow-up: NaN (a masked background, as nibabel gives SPM's output) was an error.
    a = blob()
    lowest, highest = float(a.min()), float(a.max())
    a[3, 4, 5] = np.nan
    a[0, 1, 2] = np.nan
    a[7, 7, 7] = np.inf
    with pytest.warns(UserWarning, match="2 samples were NaN, taken as the lowest finite value"):
        v = volsplat.Volume(a)
    [note] = [n for n in v.notes if "NaN" in n]
    m = re.fullmatch(
        r"2 samples were NaN, taken as the lowest finite value (\S+); "
        r"1 sample was \+inf, taken as the highest finite value (\S+)",
        note,
    )
    assert m, note
    assert (np.float32(m[1]), np.float32(m[2])) == (np.float32(lowest), np.float32(highest))
    b = v.array
    assert np.all(np.isfinite(b))
    assert b[3, 4, 5] == b[0, 1, 2] == np.float32(lowest) and b[7, 7, 7] == np.float32(highest)
    rest = np.isfinite(a)
    assert np.array_equal(b[rest], a[rest])
    # The same in (x, y, z) order, and after a conversion from float64.
    with pytest.warns(UserWarning, match="NaN"):
        assert np.array_equal(volsplat.Volume(a.transpose(), axes="xyz").array, b.transpose())
    with pytest.warns(UserWarning, match="NaN"):
        assert np.array_equal(volsplat.Volume(a.astype(np.float64)).array, b)


def test_an_array_with_no_finite_value_and_float32_overflow_are_errors():
    with pytest.raises(volsplat.InvalidInputError, match="no sample is finite"):
        volsplat.Volume(np.full((2, 2, 2), np.nan, np.float32))
    big = np.ones((2, 3, 4))
    big[1, 2, 3] = 1e300  # float64 beyond float32: an error, not a silent clamp
    with np.errstate(over="ignore"), pytest.raises(
        volsplat.InvalidInputError, match=r"\[1, 2, 3\].*float32 range"
    ):
        volsplat.Volume(big)
    with np.errstate(over="ignore"), pytest.raises(volsplat.InvalidInputError, match="float32"):
        volsplat.Volume(np.full((2, 2, 2), 1e300))


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"spacing": (1, 2)}, "spacing"),
        ({"spacing": (1, -2, 3)}, "spacing"),
        ({"spacing": 0}, "spacing"),
        ({"spacing": "abc"}, "spacing"),
        ({"origin": (1, 2)}, "origin"),
        ({"direction": np.eye(2)}, "direction"),
        ({"direction": [[1, 1, 0], [0, 1, 0], [0, 0, 1]]}, "orthogonal"),
        ({"axes": "yxz"}, "axes"),
        ({"space": "RAI"}, "space"),
        ({"affine": np.eye(3)}, "affine"),
        ({"affine": [[1, 0.5, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]}, "orthogonal"),
        ({"affine": np.eye(4), "spacing": 2}, "not both"),
    ],
)
def test_bad_geometry(kwargs, match):
    with pytest.raises(volsplat.InvalidInputError, match=match):
        volsplat.Volume(blob(), **kwargs)


def test_geometry_in_array_order_and_world_xyz():
    a = blob()
    rot = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # columns: x, y, z axes
    v = volsplat.Volume(a, spacing=(3, 2, 1), origin=(10, 20, 30), direction=rot[:, ::-1])
    info = v.info()
    assert info["spacing_xyz"] == [1, 2, 3]
    assert info["origin"] == [10, 20, 30]
    np.testing.assert_array_equal(np.array(info["direction_xyz"]), rot)
    np.testing.assert_array_equal(v.direction, rot[:, ::-1])
    # The affines map array indices to world points (LPS, volsplat's world; RAS, nibabel's) and
    # rebuild the same volume.
    k, j, i = 5, 6, 7
    expect = np.array([10, 20, 30]) + rot @ (np.array([i, j, k]) * [1, 2, 3])
    np.testing.assert_allclose((v.affine_lps @ [k, j, i, 1])[:3], expect)
    np.testing.assert_allclose((v.affine @ [k, j, i, 1])[:3], expect * [-1, -1, 1])
    for w in (
        volsplat.Volume(a, affine=v.affine, axes="zyx"),
        volsplat.Volume(a, affine=v.affine_lps, axes="zyx", space="LPS"),
    ):
        assert w.info()["spacing_xyz"] == info["spacing_xyz"] and w.origin == v.origin
        np.testing.assert_array_equal(render(v).rgba, render(w).rgba)
    # Without axes=, an affine takes nibabel's (x, y, z) order: the same world geometry (the
    # affine's columns follow the array's axes either way), another memory layout.
    w = volsplat.Volume(a, affine=v.affine)
    assert w.axes == "xyz" and w.info()["spacing_xyz"] == [3, 2, 1]
    np.testing.assert_allclose(w.info()["bounds"], info["bounds"])
    np.testing.assert_array_equal(w.array, a)


def test_ras_affine_is_converted_to_lps():
    a = blob().transpose()
    ras = np.diag([0.5, 0.75, 2.0, 1.0])
    ras[:3, 3] = (10, 20, 30)
    v = volsplat.Volume(a, affine=ras, axes="xyz", space="RAS")
    np.testing.assert_allclose(v.affine_lps, np.diag([-1, -1, 1, 1]) @ ras)
    np.testing.assert_allclose(v.affine, ras)
    assert v.origin == (-10.0, -20.0, 30.0)
    # RAS is what an affine means without space= (nibabel's convention).
    w = volsplat.Volume(a, affine=ras)
    assert w.origin == v.origin and w.axes == "xyz"
    np.testing.assert_array_equal(w.affine_lps, v.affine_lps)


def test_info_and_repr():
    v = volsplat.Volume(blob(dtype=np.int16), spacing=2.0)
    info = v.info()
    for key in (
        "source",
        "format",
        "dtype",
        "shape",
        "axes",
        "dims_xyz",
        "spacing",
        "origin",
        "direction",
        "bounds",
        "value_range",
        "voxels",
        "nbytes",
        "notes",
    ):
        assert key in info
    assert info["dtype"] == "int16" and info["voxels"] == 24 * 28 * 32
    assert v.nbytes == 2 * 24 * 28 * 32
    assert "Volume(shape=(24, 28, 32)" in repr(v)


def test_nrrd_round_trip(tmp_path):
    a = blob(dtype=np.int16)
    rot = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
    v = volsplat.Volume(a, spacing=(1.5, 0.5, 0.25), origin=(-1, 2, 3.5), direction=rot)
    v.save(tmp_path / "v.nrrd")
    w = volsplat.load(tmp_path / "v.nrrd")
    assert w.dtype == "int16" and w.path is not None
    np.testing.assert_array_equal(w.array, a)
    assert w.spacing == v.spacing and w.origin == v.origin
    np.testing.assert_array_equal(w.direction, v.direction)
    np.testing.assert_array_equal(render(v).rgba, render(w).rgba)
    x = volsplat.load(tmp_path / "v.nrrd", axes="xyz")
    np.testing.assert_array_equal(x.array, a.transpose())
    v.save(tmp_path / "g.nrrd", gzip=True)
    np.testing.assert_array_equal(volsplat.load(tmp_path / "g.nrrd").array, a)
    with pytest.raises(volsplat.InvalidInputError, match="NRRD"):
        v.save(tmp_path / "v.nii")


def test_raw_files(tmp_path):
    a = blob(dtype=np.uint16)
    (tmp_path / "v.raw").write_bytes(b"HDR!" + a.astype(">u2").tobytes())
    v = volsplat.load(
        tmp_path / "v.raw",
        raw={"dims": (32, 28, 24), "dtype": ">u2", "spacing": (1, 1, 2), "header_bytes": 4},
    )
    assert v.dtype == "uint16" and v.spacing == (2.0, 1.0, 1.0)
    np.testing.assert_array_equal(v.array, a)
    with pytest.raises(volsplat.InvalidInputError, match="dims"):
        volsplat.load(tmp_path / "v.raw", raw={"dtype": "u8"})


def test_nifti_reader_and_the_xyz_affine_path(tmp_path):
    from conftest import write_nifti

    a = blob(dtype=np.int16).transpose()  # (x, y, z)
    ras = np.array([[-0.75, 0, 0, 12.0], [0, 1.25, 0, -20.0], [0, 0, 2.0, 5.0], [0, 0, 0, 1]])
    write_nifti(tmp_path / "b.nii", a, ras)
    v = volsplat.load(tmp_path / "b.nii", axes="xyz")
    assert v.info()["format"].startswith("NIfTI")
    np.testing.assert_array_equal(v.array, a)
    w = volsplat.Volume(a, affine=ras, axes="xyz", space="RAS")
    np.testing.assert_allclose(w.affine, v.affine)
    np.testing.assert_array_equal(render(v).rgba, render(w).rgba)


def test_load_errors_are_oserror_or_valueerror(tmp_path):
    with pytest.raises(volsplat.FileError) as e:
        volsplat.load(tmp_path / "missing.nrrd")
    assert isinstance(e.value, OSError) and e.value.errno == 2
    (tmp_path / "bad.nrrd").write_text("NRRD0004\ntype: banana\n\n")
    with pytest.raises(volsplat.InvalidInputError):
        volsplat.load(tmp_path / "bad.nrrd")
    with pytest.raises(volsplat.InvalidInputError, match="extension"):
        volsplat.load(tmp_path / "x.xyz")
    with pytest.raises(volsplat.InvalidInputError, match="frame"):
        volsplat.load(tmp_path / "bad.nrrd", frame=2)
    (tmp_path / "big.nrrd").write_text(
        "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 100 100 100\nencoding: raw\n\n"
    )
    with pytest.raises(volsplat.InvalidInputError, match="limit"):
        volsplat.load(tmp_path / "big.nrrd", max_voxels=1000)


def test_phantoms():
    v = volsplat.phantom("blobs", 16)
    assert v.shape == (16, 16, 16) and v.dtype == "float32"
    h = volsplat.phantom("head", (20, 24, 28))
    assert h.shape == (28, 24, 20) and h.dtype == "int16"
    with pytest.raises(volsplat.InvalidInputError, match="teapot.*shepp-logan"):
        volsplat.phantom("teapot")
    demo = volsplat.phantom()  # the command line's demo
    assert demo.size > 1000
    with pytest.raises(volsplat.InvalidInputError, match="grid"):
        volsplat.phantom("blobs", (1, 2))


def test_nibabel_and_simpleitk_helpers(tmp_path):
    nib = pytest.importorskip("nibabel")
    from conftest import write_nifti

    a = blob(dtype=np.int16).transpose()
    ras = np.array([[0.0, 0, 1.5, 1.0], [-1.25, 0, 0, 2.0], [0, 0.5, 0, 3.0], [0, 0, 0, 1]])
    write_nifti(tmp_path / "n.nii", a, ras)
    v = volsplat.from_nibabel(nib.load(tmp_path / "n.nii"))
    w = volsplat.load(tmp_path / "n.nii", axes="xyz")
    np.testing.assert_array_equal(v.array, w.array)
    np.testing.assert_allclose(v.affine, w.affine)
    np.testing.assert_array_equal(render(v).rgba, render(w).rgba)
