"""Rendering: images, modes, cameras, transfer functions, scenes, the reusable renderer,
progress, cancellation, Ctrl-C, threads and errors."""

from __future__ import annotations

import _thread
import json
import threading
import time
import warnings

import numpy as np
import pytest
import volsplat
from conftest import blob


@pytest.fixture(scope="module")
def vol():
    return volsplat.Volume(blob(dtype=np.int16), spacing=(1.5, 1.0, 1.0))


def test_composite_image(vol):
    img = volsplat.render(vol, size=(40, 30), azimuth=30)
    assert img.rgba.shape == (30, 40, 4) and img.shape == (30, 40)
    assert img.values is None and img.mode == "composite"
    assert not img.rgba.flags.writeable
    rgba = img.rgba
    assert np.all(rgba[..., :3] <= rgba[..., 3:4] + 1e-6), "premultiplied"
    assert 0 < rgba[..., 3].max() <= 1
    assert np.asarray(img).shape == (30, 40, 4)
    stats = img.stats
    # Shaded composite: `auto` draws one-voxel slabs lit at the samples (decision 0036).
    assert stats["width"] == 40 and stats["renderer"] == "slab" and stats["total_ms"] > 0
    assert "volsplat.Image 40×30" in repr(img)


@pytest.mark.parametrize("mode", ["mip", "minip", "xray"])
def test_projection_modes_give_values(vol, mode):
    img = volsplat.render(vol, size=32, mode=mode)
    v = img.values
    assert v.shape == (32, 32) and v.dtype == np.float32 and img.mode == mode
    if mode == "mip":
        # The projected reconstruction: near the largest sample, never far above it.
        assert 0.7 * vol.array.max() < np.nanmax(v) <= 1.01 * vol.array.max()
    if mode == "xray":
        assert np.all(np.isfinite(v)) and np.abs(v).max() > 0


def test_to_uint8_and_png(vol, tmp_path):
    img = volsplat.render(vol, size=24)
    u8 = img.to_uint8()
    assert u8.shape == (24, 24, 4) and u8.dtype == np.uint8
    expect = np.round(np.clip(img.rgba.astype(np.float64), 0, 1) * 255).astype(np.uint8)
    np.testing.assert_array_equal(u8, expect)  # linear, premultiplied (= over black)
    rgb = img.to_uint8(background=(0, 0, 0))
    np.testing.assert_array_equal(rgb, u8[..., :3])
    straight = img.to_uint8(premultiplied=False)
    a = img.rgba[..., 3:4].astype(np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        s = np.where(a > 0, img.rgba[..., :3] / a, 0)
    np.testing.assert_array_equal(straight[..., :3], np.round(np.clip(s, 0, 1) * 255))
    srgb = img.to_uint8(srgb=True)
    assert srgb.astype(int).sum() >= u8.astype(int).sum(), "sRGB lifts mid-tones"
    np.testing.assert_array_equal(srgb[..., 3], u8[..., 3])
    white = img.to_uint8(background=(1, 1, 1))
    assert white.shape == (24, 24, 3) and white[0, 0].tolist() == [255, 255, 255]
    png = img._repr_png_()
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    img.save(tmp_path / "a.png")
    assert (tmp_path / "a.png").read_bytes() == png
    img.save(tmp_path / "a16.png", bits=16, srgb=True, background=(0.2, 0.2, 0.2))
    assert (tmp_path / "a16.png").read_bytes() != png
    img.save(tmp_path / "a.npy")
    np.testing.assert_array_equal(np.load(tmp_path / "a.npy"), img.rgba)
    with pytest.raises(volsplat.InvalidInputError, match="extension"):
        img.save(tmp_path / "a.jpg")
    with pytest.raises(volsplat.InvalidInputError, match="bits"):
        img.save(tmp_path / "b.png", bits=12)
    with pytest.raises(volsplat.InvalidInputError, match="window"):
        img.save(tmp_path / "b.png", window=(0, 1))  # composite has no grey window
    with pytest.raises(volsplat.FileError):
        img.save(tmp_path / "no" / "such" / "dir.png")


def test_xray_and_window_outputs(vol, tmp_path):
    img = volsplat.render(vol, size=24, mode="xray")
    img.save(tmp_path / "x.npy")
    np.testing.assert_array_equal(np.load(tmp_path / "x.npy"), img.values)
    mip = volsplat.render(vol, size=24, mode="mip")
    mip.save(tmp_path / "m.npy", window=(0, 1000))
    np.testing.assert_array_equal(np.load(tmp_path / "m.npy"), mip.values)
    assert mip.to_png(window=(0, 1000)) == mip.to_png(wl=(500, 1000))


def test_camera_objects(vol, tmp_path):
    cam = volsplat.Camera(azimuth=30, elevation=15, zoom=1.2)
    assert not cam.is_explicit and cam.azimuth == 30 and cam.position is None
    img = volsplat.render(vol, camera=cam, size=32)
    used = img.camera
    assert used.is_explicit and used.parallel_projection is True
    # The explicit camera reproduces the image.
    again = volsplat.render(vol, camera=used, size=32)
    np.testing.assert_array_equal(img.rgba, again.rgba)
    used.save(tmp_path / "cam.json")
    loaded = volsplat.Camera.load(tmp_path / "cam.json")
    assert loaded == used
    np.testing.assert_array_equal(
        volsplat.render(vol, camera=tmp_path / "cam.json", size=32).rgba, img.rgba
    )
    # Orbit keywords change the camera; replace() too.
    side = volsplat.render(vol, camera=used, azimuth=90, size=32)
    assert not np.array_equal(side.rgba, img.rgba)
    assert cam.replace(azimuth=45).azimuth == 45
    p = volsplat.render(vol, perspective=True, size=32)
    assert p.camera.parallel_projection is False and p.stats["renderer"] == "slab"
    with pytest.raises(volsplat.InvalidInputError, match="focal_point"):
        volsplat.Camera(position=(0, 0, 1))
    with pytest.raises(volsplat.InvalidInputError, match="zoom"):
        volsplat.Camera(zoom=-1)
    with pytest.raises(volsplat.InvalidInputError, match="pending orbit|explicit"):
        cam.save(tmp_path / "c.json")
    with pytest.raises(volsplat.InvalidInputError):
        volsplat.Camera(position=(0, 0, 0), focal_point=(0, 0, 0))


def test_transfer_functions(vol, tmp_path):
    tf = volsplat.TransferFunction(
        color=[[0, 0, 0, 0], [1500, 1, 0.5, 0.2], [3000, 1, 1, 1]],
        opacity=np.array([[0, 0.0], [800, 0.05], [3000, 0.8]]),
        shade=True,
        ambient=0.2,
    )
    assert tf.kind == "function" and tf.shade is True
    a = volsplat.render(vol, transfer_function=tf, size=32)
    assert a.transfer_function == tf
    tf.save(tmp_path / "tf.json")
    assert volsplat.TransferFunction.load(tmp_path / "tf.json") == tf
    b = volsplat.render(vol, transfer_function=tmp_path / "tf.json", size=32)
    np.testing.assert_array_equal(a.rgba, b.rgba)
    preset = volsplat.render(vol, transfer_function="ramp", size=32)
    resolved = volsplat.TransferFunction.preset("ramp", data_range=vol.value_range)
    np.testing.assert_array_equal(
        preset.rgba, volsplat.render(vol, transfer_function=resolved, size=32).rgba
    )
    with pytest.raises(volsplat.InvalidInputError, match="order"):
        volsplat.TransferFunction(opacity=[[10, 0.1], [5, 0.2]])
    with pytest.raises(volsplat.InvalidInputError, match="opacity"):
        volsplat.TransferFunction(color=[[0, 1, 1, 1]])
    with pytest.raises(volsplat.InvalidInputError, match="preset"):
        volsplat.render(vol, transfer_function=volsplat.TransferFunction.preset("nope"))
    with pytest.raises(volsplat.InvalidInputError):
        volsplat.TransferFunction(opacity=[[0, 2.0]])  # alpha out of [0, 1]


def test_paraview_preset_files(vol, tmp_path):
    preset = [
        {"Name": "other", "RGBPoints": [0, 0, 0, 0, 1, 1, 1, 1]},
        {
            "Name": "bone",
            "ColorSpace": "RGB",
            "RGBPoints": [0, 0, 0, 0, 1500, 1, 0.8, 0.6, 3000, 1, 1, 1],
            "Points": [0, 0, 0.5, 0, 800, 0.1, 0.5, 0, 3000, 0.9, 0.5, 0],
        },
    ]
    (tmp_path / "pv.json").write_text(json.dumps(preset))
    tf = volsplat.TransferFunction.load(tmp_path / "pv.json", name="bone")
    assert tf.color[1] == [1500, 1, 0.8, 0.6] and tf.opacity[1] == [800, 0.1]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        first = volsplat.TransferFunction.load(tmp_path / "pv.json")
    messages = " ".join(str(w.message) for w in caught)
    assert "2 presets" in messages and "no opacity Points" in messages
    assert first.color[-1][0] == 1 and first.opacity == [[0, 0.0], [1, 1.0]]
    scaled = volsplat.TransferFunction.load(tmp_path / "pv.json", name="bone", data_range=(0, 300))
    assert scaled.color[-1][0] == 300
    with pytest.raises(volsplat.InvalidInputError, match="no preset named"):
        volsplat.TransferFunction.load(tmp_path / "pv.json", name="x")
    assert volsplat.render(vol, transfer_function=tf, size=16).rgba[..., 3].max() > 0


def test_scene_objects_and_files(vol, tmp_path):
    vol.save(tmp_path / "v.nrrd")
    scene = volsplat.Scene(
        volsplat.load(tmp_path / "v.nrrd"),
        size=(40, 24),
        mode="mip",
        azimuth=20,
        kernel="tent",
        threads=1,
    )
    assert scene.width == 40 and scene.mode == "mip" and scene.quality["kernel"] == "tent"
    scene.save(tmp_path / "s.json")
    back = volsplat.Scene.load(tmp_path / "s.json")
    assert back.volume == str(tmp_path / "v.nrrd")
    assert back.to_dict() == scene.to_dict()
    np.testing.assert_array_equal(back.render().values, scene.render().values)
    # An array cannot be named in a scene file.
    with pytest.raises(volsplat.InvalidInputError, match="NRRD"):
        volsplat.Scene(np.asarray(vol.array)).save(tmp_path / "t.json")
    # Image.scene is what --save-scene writes: camera and transfer function resolved.
    img = scene.render()
    d = img.scene.to_dict()
    assert "explicit" in d["scene"]["camera"] and "function" in d["scene"]["transfer_function"]
    with pytest.raises(TypeError, match="unexpected keyword"):
        volsplat.Scene(vol, colour="red")
    with pytest.raises(volsplat.InvalidInputError, match="mode"):
        volsplat.Scene(vol, mode="mipp")
    with pytest.raises(volsplat.InvalidInputError, match="width"):
        volsplat.Scene(vol, width=0)
    with pytest.raises(volsplat.InvalidInputError, match="threads"):
        volsplat.Scene(vol, threads=0)
    with pytest.raises(volsplat.InvalidInputError, match="unknown"):
        volsplat.Scene(vol, quality={"kernal": "tent"})
    (tmp_path / "w.json").write_text(
        json.dumps(
            {
                "scene": {"volume": {"phantom": {"phantom": "blobs", "grid": [16]}}},
                "width": 8,
                "height": 8,
                "extra": 1,
            }
        )
    )
    with pytest.warns(UserWarning, match="extra"):
        volsplat.Scene.load(tmp_path / "w.json")


def test_lights_shading_and_options(vol):
    base = volsplat.render(vol, size=24, transfer_function="ct-bone")
    lit = volsplat.render(
        vol,
        size=24,
        transfer_function="ct-bone",
        lights=[(1, 1, 1, 1, 0.5, 0.5)],
        shading={"specular": False},
    )
    assert not np.array_equal(base.rgba, lit.rgba)
    with pytest.raises(volsplat.InvalidInputError, match="lights"):
        volsplat.render(vol, lights=[(0, 0, 0)])
    sub = volsplat.render(vol, size=24, subsample=2)
    assert sub.stats["voxels"] < base.stats["voxels"]


def test_renderer_reuses_tables_across_frames(vol):
    r = volsplat.Renderer(vol, size=32, transfer_function="ct-bone")
    first = r.render(azimuth=0)
    assert first.stats["prepare_ms"] > 0
    frames = [r.render(azimuth=a) for a in (30, 60, 90)]
    assert all(f.stats["prepare_ms"] == 0 and f.stats["load_ms"] == 0 for f in frames)
    changed = r.render(transfer_function="ramp")
    assert changed.stats["prepare_ms"] > 0, "a new transfer function builds new tables"
    assert r.camera(azimuth=30) == frames[0].camera
    assert r.transfer_function().kind == "function"
    r.clear()
    assert r.render().stats["prepare_ms"] > 0


def test_threads_option_does_not_change_the_image(vol):
    one = volsplat.render(vol, size=48, threads=1)
    two = volsplat.render(vol, size=48, threads=2)
    assert one.stats["threads"] == 1 and two.stats["threads"] == 2
    np.testing.assert_array_equal(one.rgba, two.rgba)


def test_two_python_threads_render_at_once():
    head = volsplat.phantom("head")
    ref = volsplat.render(head, size=160, azimuth=40)
    results = {}
    errors = []
    ticks = [0]
    stop = threading.Event()

    def work(name, renderer):
        try:
            results[name] = renderer.render(size=160, azimuth=40)
        except Exception as e:  # noqa: BLE001 (reported below)
            errors.append(e)

    def tick():
        while not stop.is_set():
            ticks[0] += 1
            time.sleep(0.001)

    shared = volsplat.Renderer(head)
    threads = [
        threading.Thread(target=work, args=("a", volsplat.Renderer(head))),
        threading.Thread(target=work, args=("b", volsplat.Renderer(head))),
        threading.Thread(target=work, args=("c", shared)),
        threading.Thread(target=work, args=("d", shared)),
    ]
    ticker = threading.Thread(target=tick)
    ticker.start()
    t0 = time.perf_counter()
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    elapsed = time.perf_counter() - t0
    stop.set()
    ticker.join()
    assert not errors, errors
    for name in "abcd":
        np.testing.assert_array_equal(results[name].rgba, ref.rgba)
    # The GIL was free while rendering: the ticking thread kept running.
    assert ticks[0] > 0.2 * elapsed / 0.001 * 0.1


def test_progress_callback_and_cancel():
    head = volsplat.phantom("head")
    seen = []
    img = volsplat.render(head, size=64, progress=lambda f, s: seen.append((f, s)))
    assert seen and seen[-1] == (1.0, "done")
    assert all(0 <= f <= 1 for f, _ in seen)
    r = volsplat.Renderer(head, size=1024, threads=1)
    with pytest.raises(volsplat.CancelledError):
        r.render(progress=lambda f, s: False, poll_interval=0.001)
    boom = RuntimeError("from the callback")

    def bad(f, s):
        raise boom

    with pytest.raises(RuntimeError, match="from the callback"):
        r.render(progress=bad, poll_interval=0.001)
    # The renderer still works after a cancelled render.
    assert r.render(size=32).rgba.shape == (32, 32, 4)
    assert img.rgba.shape == (64, 64, 4)


def test_ctrl_c_interrupts_a_render():
    head = volsplat.phantom("head")
    r = volsplat.Renderer(head, size=2048, threads=1, kernel="bspline")
    calls = []

    def interrupt_once(f, s):
        if not calls:
            _thread.interrupt_main()  # as Ctrl-C: SIGINT's flag for the main thread
        calls.append(f)

    t0 = time.perf_counter()
    with pytest.raises(KeyboardInterrupt):
        r.render(progress=interrupt_once, poll_interval=0.01)
    interrupted = time.perf_counter() - t0
    t1 = time.perf_counter()
    full = r.render(size=2048)
    assert full.rgba.shape == (2048, 2048, 4)
    assert interrupted < time.perf_counter() - t1, "stopped before the end"


def test_errors_are_python_exceptions(vol, tmp_path):
    with pytest.raises(volsplat.InvalidInputError, match="renderer"):
        volsplat.render(vol, renderer="splat", perspective=True, size=8)
    with pytest.raises(volsplat.InvalidInputError, match="Chapter 6|mode"):
        volsplat.render(vol, renderer="nil", mode="xray", size=8)
    with pytest.raises(volsplat.FileError):
        volsplat.render(tmp_path / "missing.nrrd", size=8)
    with pytest.raises(volsplat.InvalidInputError, match="only apply"):
        volsplat.render(vol, spacing=2)
    with pytest.raises(volsplat.InvalidInputError):
        volsplat.render("not a volume.xyz")
    with pytest.raises(volsplat.InvalidInputError, match="volume"):
        volsplat.Scene(object())


def test_clipping_is_a_scene_option(vol):
    """The scene file's clipping object: a plane keeping everything changes nothing, one keeping
    nothing empties the image, a crop removes part of it, and a bad plane names its field."""
    plain = volsplat.render(vol, size=32, mode="xray")
    keep = {"planes": [{"normal": (1, 0, 0), "offset": 1e4}]}
    none = {"planes": [{"normal": (1, 0, 0), "offset": -1e4}]}
    assert np.array_equal(volsplat.render(vol, size=32, mode="xray", clipping=keep).values,
                          plain.values)
    assert np.all(volsplat.render(vol, size=32, mode="xray", clipping=none).values == 0)
    crop = {"crop": {"min": (0, 0, 0), "max": (3, 100, 100), "units": "voxels"}}
    cropped = volsplat.render(vol, size=32, mode="xray", clipping=crop).values
    # The blob's data have negative values too: compare magnitudes.
    assert 0 < np.abs(cropped).sum() < 0.9 * np.abs(plain.values).sum()
    with pytest.raises(volsplat.VolsplatError, match="clipping"):
        volsplat.render(vol, size=32, clipping={"planes": [{"normal": (0, 0, 0), "offset": 0}]})


def test_visibility_and_slab(vol):
    """`visibility` picks the renderer (decision 0016) and `slab` sets the slab thickness."""
    tf = volsplat.TransferFunction(
        color=[[0, 0.2, 0.3, 0.9], [3000, 1, 1, 1]],
        opacity=[[0, 0.0], [500, 0.0], [3000, 0.6]],
        shade=False,
    )
    image = volsplat.render(vol, transfer_function=tf, size=48, visibility="image")
    sheet = volsplat.render(vol, transfer_function=tf, size=48, visibility="sheet")
    auto = volsplat.render(vol, transfer_function=tf, size=48)
    assert image.stats["renderer"] == "slab" and sheet.stats["renderer"] == "sheets"
    np.testing.assert_array_equal(auto.rgba, image.rgba)  # unshaded: auto draws slabs
    assert image.rgba[..., 3].max() > 0.05
    thick = volsplat.render(vol, transfer_function=tf, size=48, visibility="image", slab=2.0)
    assert thick.stats["sheet_spacing"] == pytest.approx(2.0 * 1.0)
    assert not np.array_equal(thick.rgba, image.rgba)
    with pytest.raises(volsplat.InvalidInputError, match="slab"):
        volsplat.render(vol, transfer_function=tf, size=48, visibility="image", slab=0.0)


def test_shade_at(vol):
    """Shaded composite: `auto` (the default) draws one-voxel slabs lit at the samples, twice per
    slab (decision 0036); `shade_at="voxels"` lights the voxels as VTK does (decision 0019);
    `shade_at="samples"` lights every sample, in the slabs under `auto` visibility too (issue 33:
    the sheets light the voxels, and say so when they draw it)."""
    tf = volsplat.TransferFunction(
        color=[[0, 0.2, 0.3, 0.9], [3000, 1, 1, 1]],
        opacity=[[0, 0.0], [500, 0.0], [3000, 0.6]],
        shade=True,
    )
    auto = volsplat.render(vol, transfer_function=tf, size=48)
    voxels = volsplat.render(vol, transfer_function=tf, size=48, visibility="image",
                             shade_at="voxels")
    samples = volsplat.render(vol, transfer_function=tf, size=48, visibility="image",
                              shade_at="samples")
    samples_auto = volsplat.render(vol, transfer_function=tf, size=48, shade_at="samples")
    assert auto.stats["renderer"] == "slab" and samples_auto.stats["renderer"] == "slab"
    assert auto.stats["shade_at"] == "samples" and voxels.stats["shade_at"] == "voxels"
    np.testing.assert_array_equal(samples_auto.rgba, samples.rgba)
    np.testing.assert_array_equal(auto.rgba, samples.rgba)
    assert samples.stats["sheet_spacing"] == pytest.approx(1.0)
    assert voxels.stats["sheet_spacing"] == pytest.approx(1.0)
    assert auto.rgba[..., 3].max() > 0.05
    assert not np.array_equal(voxels.rgba, auto.rgba)
    with pytest.raises(volsplat.InvalidInputError, match="shade_at|shade-at"):
        volsplat.render(vol, transfer_function=tf, size=48, shade_at="corners")


def test_preintegrate(vol):
    """Composite slabs: `preintegrate` classifies each slab by its segment of the ray ("on"), by
    its one sample ("off"), or by segment where the ramp is sharp ("auto", decision 0020); the
    stats say which was used."""
    sharp = volsplat.TransferFunction(
        color=[[0, 0.9, 0.6, 0.4], [3000, 1, 1, 1]],
        opacity=[[0, 0.0], [990, 0.0], [1010, 0.5], [3000, 0.6]],
    )
    smooth = volsplat.TransferFunction(
        color=[[0, 0.9, 0.6, 0.4], [3000, 1, 1, 1]],
        opacity=[[0, 0.0], [3000, 0.02]],
    )
    on = volsplat.render(vol, transfer_function=sharp, size=48, preintegrate="on")
    off = volsplat.render(vol, transfer_function=sharp, size=48, preintegrate="off")
    auto = volsplat.render(vol, transfer_function=sharp, size=48)
    assert on.stats["preintegrated"] and not off.stats["preintegrated"]
    assert auto.stats["preintegrated"]
    np.testing.assert_array_equal(auto.rgba, on.rgba)
    assert not np.array_equal(on.rgba, off.rgba)
    assert not volsplat.render(vol, transfer_function=smooth, size=48).stats["preintegrated"]
    with pytest.raises(volsplat.InvalidInputError, match="preintegrate"):
        volsplat.render(vol, transfer_function=sharp, size=48, preintegrate="sometimes")


def test_xray_offset_keyword():
    # --xray-offset VALUE|auto|none as a keyword of render, Scene and Renderer.
    ct = volsplat.phantom("head", 24)
    s = volsplat.Scene(ct, mode="xray", size=24)
    assert s.xray_offset == "auto" and "xray_density" not in s.to_dict()["scene"]
    assert s.replace(xray_offset=1000).xray_offset == 1000.0
    assert s.replace(xray_offset="none").to_dict()["scene"]["xray_density"] == "raw"
    assert s.replace(xray_offset="-2.5").xray_offset == -2.5
    assert s.replace(xray_offset=7).replace(xray_offset=None).xray_offset == "auto"
    # The head is CT in Hounsfield units: `auto` is 1000 (attenuation relative to air).
    auto = s.render().values
    assert np.array_equal(s.replace(xray_offset=1000).render().values, auto)
    raw = volsplat.Renderer(s, xray_offset="none").render().values
    assert raw.min() < 0 <= auto.min()
    # A saved scene keeps it.
    assert volsplat.Scene.from_dict(s.replace(xray_offset=250).to_dict()).xray_offset == 250.0
    for bad in ["water", float("nan"), float("inf"), True, [1]]:
        with pytest.raises(volsplat.InvalidInputError, match="xray_offset"):
            s.replace(xray_offset=bad)
