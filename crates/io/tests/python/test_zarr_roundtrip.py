"""OME-Zarr round trips through the reference Python packages (issue 31 item 7):

- stores written by ``ome-zarr-py`` (OME-Zarr 0.4 on Zarr v2, 0.5 on Zarr v3) and by ``zarr``
  3.x by hand (zstd, blosc, gzip; a sharded v3 array; a 5-D t, c, z, y, x image) are read by
  ``volsplat`` (``info --json``, ``convert --zarr-level N -o X.npy``) with the same samples,
  levels and geometry;
- stores written by ``volsplat convert -o X.zarr`` (``--zarr-version 2`` and ``3``) are read
  by ``zarr`` and ``ome-zarr-py`` with the same samples and scales.

Run (from the repository root, after ``cargo build --release -p volsplat-cli``)::

    python3 -m venv /tmp/venv && /tmp/venv/bin/pip install pytest numpy zarr ome-zarr
    /tmp/venv/bin/pytest crates/io/tests/python/test_zarr_roundtrip.py

The binary is found as in ``test_roundtrip.py``. Each test is skipped when its package is
missing (``zarr`` 3 needs Python 3.11 or later).
"""

import json

import pytest

from test_roundtrip import run, volsplat_bin  # noqa: F401  (same binary lookup)

np = pytest.importorskip("numpy")
zarr = pytest.importorskip("zarr")
if int(zarr.__version__.split(".")[0]) < 3:
    pytest.skip("zarr 3.x is needed (it writes both Zarr v2 and v3)", allow_module_level=True)


def info(path, *args):
    return json.loads(run("info", path, "--json", *args).stdout)


def npy(path, tmp_path, *args):
    """The samples volsplat reads from ``path`` (a level, channel, time point), as written by
    ``convert -o X.npy``: indexed [z, y, x]."""
    out = tmp_path / f"read{len(list(tmp_path.iterdir()))}.npy"
    run("convert", path, "-o", out, "-q", *args)
    return np.load(out)


def volume(dtype, shape=(11, 20, 27)):
    """Samples indexed [z, y, x] with every value distinct within the type's range."""
    n = int(np.prod(shape))
    v = np.arange(n, dtype=np.int64) * 37 % 20011
    if dtype in ("uint8", "int8"):
        v = v % 251 - (125 if dtype == "int8" else 0)
    elif dtype == "int16":
        v = v - 10000
    if dtype == "float32":
        return (v.astype(np.float32) * np.float32(0.25) - 77).reshape(shape)
    return v.astype(dtype).reshape(shape)


# --- stores written by ome-zarr-py -----------------------------------------------------------


@pytest.mark.parametrize("version", ["0.4", "0.5"])
@pytest.mark.parametrize("dtype", ["uint8", "int16", "uint16", "float32"])
def test_ome_zarr_py_stores_read_by_volsplat(tmp_path, version, dtype):
    pytest.importorskip("ome_zarr")
    from ome_zarr.format import FormatV04, FormatV05
    from ome_zarr.writer import write_image

    data = volume(dtype)
    path = tmp_path / "peer.zarr"
    fmt = FormatV04() if version == "0.4" else FormatV05()
    group = zarr.open_group(str(path), mode="w", zarr_format=2 if version == "0.4" else 3)
    um = {a: "micrometer" for a in "zyx"}
    write_image(
        data,
        group,
        fmt=fmt,
        axes="zyx",
        scale_factors=[2, 4],
        scale={"z": 2.0, "y": 0.5, "x": 0.25},
        axes_units=um,
        storage_options={"chunks": (4, 8, 8)},
    )
    j = info(path)
    assert j["format"] == f"OME-Zarr {version} (Zarr v{2 if version == '0.4' else 3})"
    group = zarr.open_group(str(path), mode="r")
    attrs = group.attrs.asdict()
    ms = (attrs["ome"] if version == "0.5" else attrs)["multiscales"][0]
    assert len(j["levels"]) == len(ms["datasets"]) == 3
    for level, d in enumerate(ms["datasets"]):
        lv = j["levels"][level]
        arr = np.asarray(group[d["path"]][...])
        got = npy(path, tmp_path, "--zarr-level", str(level))
        assert got.dtype == arr.dtype
        np.testing.assert_array_equal(got, arr, err_msg=f"level {level}")
        # The store's z, y, x micrometres are volsplat's x, y, z millimetres.
        t = {c["type"]: c[c["type"]] for c in d["coordinateTransformations"]}
        np.testing.assert_allclose(lv["spacing"], np.array(t["scale"][::-1]) / 1000, rtol=1e-15)
        np.testing.assert_allclose(
            lv["origin"], np.array(t.get("translation", [0, 0, 0])[::-1]) / 1000, rtol=1e-15
        )
        assert lv["dims"] == list(arr.shape[::-1])
    np.testing.assert_array_equal(npy(path, tmp_path), data)


def multiscales_v04(axes, scale):
    return {
        "multiscales": [
            {
                "version": "0.4",
                "axes": axes,
                "datasets": [
                    {
                        "path": "0",
                        "coordinateTransformations": [{"type": "scale", "scale": scale}],
                    }
                ],
            }
        ]
    }


ZYX = [{"name": a, "type": "space", "unit": "millimeter"} for a in "zyx"]


def codecs(zarr_format, name):
    if zarr_format == 2:
        import numcodecs

        return {
            "zstd": numcodecs.Zstd(level=3),
            "blosc": numcodecs.Blosc(cname="lz4", clevel=5, shuffle=numcodecs.Blosc.SHUFFLE),
            "gzip": numcodecs.GZip(level=5),
        }[name]
    from zarr.codecs import BloscCodec, GzipCodec, ZstdCodec

    return {
        "zstd": ZstdCodec(level=3),
        "blosc": BloscCodec(cname="zstd", clevel=5, shuffle="bitshuffle", typesize=2),
        "gzip": GzipCodec(level=5),
    }[name]


@pytest.mark.parametrize("zarr_format", [2, 3])
@pytest.mark.parametrize("codec", ["zstd", "blosc", "gzip"])
@pytest.mark.parametrize("sharded", [False, True])
def test_zarr_codecs_and_shards_read_by_volsplat(tmp_path, zarr_format, codec, sharded):
    if sharded and zarr_format == 2:
        pytest.skip("sharding is a Zarr v3 codec")
    data = volume("uint16", (13, 17, 33))
    path = tmp_path / "z.zarr"
    group = zarr.open_group(str(path), mode="w", zarr_format=zarr_format)
    kw = {"shards": (8, 16, 32)} if sharded else {}
    arr = group.create_array(
        "0",
        shape=data.shape,
        dtype=data.dtype,
        chunks=(4, 8, 8),
        compressors=[codecs(zarr_format, codec)],
        fill_value=0,
        **kw,
    )
    arr[...] = data
    attrs = multiscales_v04(ZYX, [3.0, 2.0, 1.0])
    if zarr_format == 3:
        ms = attrs["multiscales"][0]
        del ms["version"]
        attrs = {"ome": {"version": "0.5", "multiscales": [ms]}}
    group.attrs.update(attrs)
    np.testing.assert_array_equal(npy(path, tmp_path), data)
    j = info(path)
    assert j["spacing"] == [1.0, 2.0, 3.0]
    assert j["levels"][0]["chunks"] == ([8, 16, 32] if sharded else [4, 8, 8])


def test_missing_chunks_read_as_the_fill_value(tmp_path):
    path = tmp_path / "f.zarr"
    group = zarr.open_group(str(path), mode="w", zarr_format=3)
    arr = group.create_array("0", shape=(4, 6, 8), dtype="int16", chunks=(2, 3, 4), fill_value=-5)
    arr[0:2, 0:3, 0:4] = 7  # one chunk written, the others absent
    group.attrs.update({"ome": {"version": "0.5", "multiscales": multiscales_v04(ZYX, [1, 1, 1])["multiscales"]}})
    got = npy(path, tmp_path)
    want = np.full((4, 6, 8), -5, np.int16)
    want[0:2, 0:3, 0:4] = 7
    np.testing.assert_array_equal(got, want)


def test_channels_and_time_points_of_a_5d_image(tmp_path):
    pytest.importorskip("ome_zarr")
    from ome_zarr.format import FormatV04
    from ome_zarr.writer import write_image

    data = np.stack(
        [np.stack([volume("uint16", (5, 6, 7)) + 1000 * (3 * t + c) for c in range(3)]) for t in range(2)]
    ).astype(np.uint16)
    path = tmp_path / "tczyx.zarr"
    group = zarr.open_group(str(path), mode="w", zarr_format=2)
    write_image(data, group, fmt=FormatV04(), axes="tczyx", scale_factors=[], storage_options={"chunks": (1, 1, 5, 6, 7)})
    for t in range(2):
        for c in range(3):
            got = npy(path, tmp_path, "--timepoint", str(t), "--channel", str(c))
            np.testing.assert_array_equal(got, data[t, c], err_msg=f"t={t} c={c}")
    out = run_fail("info", path, "--channel", "3")
    assert "channel 3 requested, but the store holds 3" in out


def run_fail(*args):
    import subprocess

    out = subprocess.run([str(volsplat_bin()), *map(str, args)], capture_output=True, text=True)
    assert out.returncode != 0
    assert "panicked" not in out.stderr
    return out.stderr


# --- stores written by volsplat, read by zarr and ome-zarr-py ---------------------------------


def write_nrrd(path, data, spacing):
    """A float32 NRRD (x fastest), no anatomical space: the Zarr axes x, y, z as written."""
    nz, ny, nx = data.shape
    header = (
        "NRRD0004\ntype: float\ndimension: 3\n"
        f"sizes: {nx} {ny} {nz}\nspacings: {spacing[0]} {spacing[1]} {spacing[2]}\n"
        "endian: little\nencoding: raw\n\n"
    )
    path.write_bytes(header.encode() + data.astype("<f4").tobytes())


@pytest.mark.parametrize("zarr_version", ["2", "3"])
def test_volsplat_stores_read_by_zarr_and_ome_zarr_py(tmp_path, zarr_version):
    data = volume("float32", (20, 30, 50))
    src = tmp_path / "in.nrrd"
    write_nrrd(src, data, (0.5, 0.75, 1.0))
    path = tmp_path / "out.zarr"
    run("convert", src, "-o", path, "--chunk", "16", "--zarr-version", zarr_version, "-q")
    j = info(path)
    group = zarr.open_group(str(path), mode="r")
    attrs = group.attrs.asdict()
    ms = (attrs["ome"] if zarr_version == "3" else attrs)["multiscales"][0]
    assert len(ms["datasets"]) == len(j["levels"]) >= 3
    for level, (d, lv) in enumerate(zip(ms["datasets"], j["levels"])):
        arr = group[d["path"]]
        assert arr.chunks == tuple(min(16, n) for n in arr.shape)
        got = np.asarray(arr[...])
        np.testing.assert_array_equal(got, npy(path, tmp_path, "--zarr-level", str(level)))
        scale, translation = (t[t["type"]] for t in d["coordinateTransformations"])
        assert scale == lv["spacing"][::-1]
        assert translation == lv["origin"][::-1]
        assert list(got.shape) == lv["dims"][::-1]
    np.testing.assert_array_equal(np.asarray(group["0"][...]), data)
    # ome-zarr-py's reader sees the same pyramid.
    pytest.importorskip("ome_zarr")
    from ome_zarr.io import parse_url
    from ome_zarr.reader import Reader

    node = list(Reader(parse_url(str(path)))())[0]
    assert len(node.data) == len(j["levels"])
    np.testing.assert_array_equal(np.asarray(node.data[0]), data)
    np.testing.assert_array_equal(
        np.asarray(node.data[1]), npy(path, tmp_path, "--zarr-level", "1")
    )
