"""OME-Zarr stores through ``volsplat.load`` (issue 31 item 6): a level, a channel and a time
point are chosen as on the command line (``--zarr-level``, ``--channel``, ``--timepoint``);
wrong choices raise ``InvalidInputError``. The stores are written here by hand (OME-Zarr 0.4,
Zarr v2, uncompressed chunks), so no Zarr package is needed."""

from __future__ import annotations

import json

import numpy as np
import pytest
import volsplat


def write_store(path, levels, axes="zyx", unit="micrometer"):
    """An OME-Zarr 0.4 store: one array per (samples, scale) of ``levels``, a single chunk
    each; the samples are indexed in ``axes`` order."""
    path.mkdir()
    (path / ".zgroup").write_text(json.dumps({"zarr_format": 2}))
    ax = []
    for a in axes:
        kind = {"t": "time", "c": "channel"}.get(a, "space")
        ax.append({"name": a, "type": kind, **({"unit": unit} if kind == "space" else {})})
    datasets = []
    for n, (data, scale) in enumerate(levels):
        d = path / str(n)
        d.mkdir()
        meta = {
            "zarr_format": 2, "shape": list(data.shape), "chunks": list(data.shape),
            "dtype": data.dtype.str, "compressor": None, "fill_value": 0, "order": "C",
            "filters": None, "dimension_separator": "/",
        }
        (d / ".zarray").write_text(json.dumps(meta))
        chunk = d.joinpath(*["0"] * (data.ndim - 1))
        chunk.mkdir(parents=True, exist_ok=True)
        (chunk / "0").write_bytes(np.ascontiguousarray(data).tobytes())
        datasets.append({
            "path": str(n),
            "coordinateTransformations": [
                {"type": "scale", "scale": scale},
                {"type": "translation", "translation": [0.0] * (data.ndim - 3) + [10.0, 20.0, 30.0]},
            ],
        })
    ms = {"version": "0.4", "axes": ax, "datasets": datasets}
    (path / ".zattrs").write_text(json.dumps({"multiscales": [ms]}))


def test_levels_load_with_their_geometry(tmp_path):
    fine = (np.arange(6 * 8 * 10, dtype=np.uint16) * 3).reshape(6, 8, 10)
    coarse = fine[::2, ::2, ::2].copy()
    store = tmp_path / "a.zarr"
    write_store(store, [(fine, [1.0, 0.5, 0.25]), (coarse, [2.0, 1.0, 0.5])])
    v = volsplat.load(store)
    np.testing.assert_array_equal(v.array, fine)
    # zyx order; micrometres become mm.
    np.testing.assert_allclose(v.spacing, [0.001, 0.0005, 0.00025])
    np.testing.assert_allclose(v.origin, [0.03, 0.02, 0.01])
    assert v.info()["format"] == "OME-Zarr 0.4 (Zarr v2)"
    w = volsplat.load(store, level=1)
    np.testing.assert_array_equal(w.array, coarse)
    np.testing.assert_allclose(w.spacing, [0.002, 0.001, 0.0005])
    img = volsplat.render(w, size=24)
    assert img.rgba.shape == (24, 24, 4)
    with pytest.raises(volsplat.InvalidInputError, match="level 2 requested.*2 levels"):
        volsplat.load(store, level=2)


def test_channels_and_time_points(tmp_path):
    data = np.stack(
        [np.stack([np.full((2, 3, 4), 10 * t + c, np.uint8) for c in range(3)]) for t in range(2)]
    )
    store = tmp_path / "tc.zarr"
    write_store(store, [(data, [1.0, 1.0, 1.0, 1.0, 1.0])], axes="tczyx")
    v = volsplat.load(store, channel=2, timepoint=1)
    assert v.shape == (2, 3, 4)
    assert np.all(v.array == 12)
    with pytest.raises(volsplat.InvalidInputError, match="channel 3 requested"):
        volsplat.load(store, channel=3)
    with pytest.raises(volsplat.InvalidInputError, match="timepoint 2 requested"):
        volsplat.load(store, timepoint=2)


def test_zarr_options_are_refused_for_other_files(tmp_path):
    p = tmp_path / "v.nrrd"
    p.write_bytes(b"NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 1 1\nencoding: raw\n\n\x01\x02")
    for kw in ({"level": 1}, {"channel": 1}, {"timepoint": 1}):
        with pytest.raises(volsplat.InvalidInputError, match="OME-Zarr stores only"):
            volsplat.load(p, **kw)
    with pytest.raises(volsplat.InvalidInputError, match="do not apply to headerless raw"):
        volsplat.load(p, raw={"dims": (2, 1, 1), "dtype": "uint8"}, level=1)


def test_memory_reads_a_store_out_of_core_with_the_same_picture(tmp_path):
    """``memory=`` (``--memory``): the store is read in bricks through a cache of that size;
    the picture is the same bytes as the store read whole. Bad sizes are refused by name."""
    z, y, x = np.mgrid[0:40, 0:36, 0:44].astype(np.float32)
    blob = 3000 * np.exp(-(((x - 22) / 12) ** 2 + ((y - 18) / 10) ** 2 + ((z - 20) / 11) ** 2))
    store = tmp_path / "b.zarr"
    write_store(store, [(blob.astype(np.uint16), [1.0, 1.0, 1.0])], unit="millimeter")
    for mode in ("composite", "mip"):
        whole = volsplat.render(str(store), size=32, mode=mode, azimuth=30, elevation=20)
        paged = volsplat.render(
            str(store), size=32, mode=mode, azimuth=30, elevation=20, memory="2MiB"
        )
        assert any("out of core" in n for n in paged.notes), paged.notes
        assert not any("out of core" in n for n in whole.notes)
        np.testing.assert_array_equal(paged.rgba, whole.rgba)
    scene = volsplat.Scene(str(store), memory="512MiB")
    assert scene.memory == 512 << 20
    assert scene.replace(memory=4096).memory == 4096
    for bad in ("0", "2 PiB", "1.5G", True, -1, [1]):
        with pytest.raises(volsplat.InvalidInputError, match="memory"):
            volsplat.Scene(str(store), memory=bad)
