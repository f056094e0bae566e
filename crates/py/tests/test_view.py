"""volsplat.view: the viewer's server in the Python process (issue 29, item 6)."""

from __future__ import annotations

import json
import threading
import urllib.error
import urllib.request

import numpy as np
import pytest

import volsplat

from conftest import blob


def get(url: str):
    try:
        with urllib.request.urlopen(url, timeout=60) as r:
            return r.status, r.read().decode()
    except urllib.error.HTTPError as e:
        return e.code, e.read().decode()


def test_view_serves_the_page_with_the_token_only(tmp_path):
    v = volsplat.view(volsplat.phantom("head", grid=(40, 48, 44)), size=96)
    try:
        assert v.running
        assert v.url.startswith("http://127.0.0.1:") and "/?token=" in v.url
        status, body = get(v.url)
        assert status == 200 and "<canvas" in body
        base, token = v.url.split("?token=")
        assert len(token) == 32
        assert get(base)[0] == 403
        assert get(base + "?token=" + "0" * 32)[0] == 403
        frame = v._repr_html_()
        assert "<iframe" in frame and token in frame
    finally:
        v.close()
    assert not v.running
    with pytest.raises(OSError):
        urllib.request.urlopen(v.url, timeout=5)
    v.close()  # twice is fine


def test_screenshot_is_render_of_the_scene(tmp_path, cli):
    v = volsplat.view(
        volsplat.phantom("head", grid=(40, 48, 44)),
        size=(80, 64),
        azimuth=25,
        elevation=10,
        transfer_function="ct-bone",
    )
    with v:
        scene = v.scene
        assert "explicit" in scene.to_dict()["scene"]["camera"], "the camera is explicit"
        img = v.screenshot()
        assert isinstance(img, volsplat.Image) and img.shape == (64, 80)
        scene.save(tmp_path / "scene.json")
        img.save(tmp_path / "py.png")
        cli("render", "--scene", tmp_path / "scene.json", "-o", tmp_path / "cli.png", "--quiet")
        assert (tmp_path / "py.png").read_bytes() == (tmp_path / "cli.png").read_bytes()
        assert img.to_uint8()[..., :3].max() > 30


def test_view_of_an_array_keeps_the_array_and_releases_the_gil():
    data = blob((24, 28, 32))
    v = volsplat.view(data, spacing=(2.0, 1.0, 1.0), size=64, transfer_function="ramp")
    try:
        s = v.scene
        assert isinstance(s.volume, volsplat.Volume)
        assert s.volume.shape == data.shape
        # Another Python thread runs while the viewer serves and renders.
        ticks = []
        t = threading.Thread(target=lambda: [ticks.append(1) for _ in range(10000)])
        t.start()
        img = v.screenshot()
        t.join()
        assert len(ticks) == 10000
        assert np.isfinite(img.rgba).all()
    finally:
        v.close()


def test_bad_settings_are_errors():
    with pytest.raises(volsplat.InvalidInputError, match="allow-remote"):
        volsplat.view(volsplat.phantom("blobs", grid=16), host="0.0.0.0")
    with pytest.raises(volsplat.InvalidInputError):
        volsplat.view(volsplat.phantom("blobs", grid=16), bits=12)
    with pytest.raises(TypeError):
        volsplat.view(volsplat.phantom("blobs", grid=16), azimut=3)


def test_output_options_travel_with_the_scene(tmp_path, cli):
    """The grey window and background given to view() are the scene's output options, so the
    saved scene renders on the command line to the file of the viewer's picture."""
    v = volsplat.view(
        volsplat.phantom("head", grid=(40, 48, 44)),
        size=(80, 64),
        mode="mip",
        window=(-300.0, 900.0),
        background=(0.2, 0.3, 0.4),
    )
    with v:
        assert v.window == (-300.0, 900.0)
        out = v.scene.to_dict()["output"]
        assert out["window"] == [-300.0, 900.0] and out["background"] == [
            pytest.approx(0.2),
            pytest.approx(0.3),
            pytest.approx(0.4),
        ]
        v.scene.save(tmp_path / "scene.json")
        # The screenshot keeps the scene's window and background without being told.
        v.screenshot().save(tmp_path / "py.png")
        cli("render", "--scene", tmp_path / "scene.json", "-o", tmp_path / "cli.png", "--quiet")
        assert (tmp_path / "py.png").read_bytes() == (tmp_path / "cli.png").read_bytes()
    # A scene's own options are kept when view() is not given any.
    again = volsplat.view(volsplat.Scene.load(tmp_path / "scene.json"))
    with again:
        assert again.window == (-300.0, 900.0)
