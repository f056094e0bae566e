"""The same scene rendered from Python and from the command line gives identical bytes.

These tests run the `volsplat` binary (target/release/volsplat of this checkout, or
$VOLSPLAT_CLI); they are skipped when it is missing (and fail instead with
VOLSPLAT_REQUIRE_CLI=1, as in .ci/python.sh).
"""

from __future__ import annotations

import numpy as np
import pytest
import volsplat
from conftest import blob, write_nifti


def same_bytes(a, b):
    da, db = a.read_bytes(), b.read_bytes()
    assert len(da) > 100
    assert da == db, f"{a.name} and {b.name} differ"


def test_demo_phantom(cli, tmp_path):
    cli(
        "render",
        "-o",
        tmp_path / "cli.png",
        "--azimuth",
        30,
        "--elevation",
        15,
        "--size",
        "96x80",
        "-q",
    )
    img = volsplat.render(azimuth=30, elevation=15, size=(96, 80))
    img.save(tmp_path / "py.png")
    same_bytes(tmp_path / "cli.png", tmp_path / "py.png")
    assert img.to_png() == (tmp_path / "cli.png").read_bytes()


def test_array_in_memory_equals_the_file_on_the_command_line(cli, tmp_path):
    # SimpleITK-style (z, y, x) data with spacing in array order, an origin and a rotation.
    a = blob(shape_zyx=(30, 26, 34), dtype=np.int16)
    rot_xyz = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    vol = volsplat.Volume(
        a, spacing=(2.0, 0.75, 1.25), origin=(5, -3, 12), direction=rot_xyz[:, ::-1]
    )
    vol.save(tmp_path / "v.nrrd")
    cli(
        "render",
        tmp_path / "v.nrrd",
        "-o",
        tmp_path / "cli.png",
        "--preset",
        "CT-Bone",
        "--azimuth",
        40,
        "--elevation",
        -10,
        "--size",
        72,
        "--save-scene",
        tmp_path / "s.json",
        "-q",
    )
    img = volsplat.render(
        a,
        spacing=(2.0, 0.75, 1.25),
        origin=(5, -3, 12),
        direction=rot_xyz[:, ::-1],
        transfer_function="CT-Bone",
        azimuth=40,
        elevation=-10,
        size=72,
    )
    img.save(tmp_path / "py.png")
    same_bytes(tmp_path / "cli.png", tmp_path / "py.png")
    # The command line's scene file, rendered from Python.
    volsplat.Scene.load(tmp_path / "s.json").render().save(tmp_path / "scene.png")
    same_bytes(tmp_path / "cli.png", tmp_path / "scene.png")


@pytest.mark.parametrize("dtype", [np.uint8, np.int16, np.float32])
def test_nibabel_style_xyz_array_with_its_affine(cli, tmp_path, dtype):
    a = blob(shape_zyx=(20, 28, 36), dtype=dtype).transpose()  # (x, y, z)
    ras = np.array([[-0.75, 0, 0, 12.0], [0, 1.25, 0, -20.0], [0, 0, 2.0, 5.0], [0, 0, 0, 1]])
    write_nifti(tmp_path / "b.nii", a, ras)
    cli(
        "render",
        tmp_path / "b.nii",
        "-o",
        tmp_path / "cli.png",
        "--azimuth",
        60,
        "--size",
        64,
        "-q",
    )
    vol = volsplat.Volume(np.asfortranarray(a), affine=ras, axes="xyz", space="RAS")
    volsplat.render(vol, azimuth=60, size=64).save(tmp_path / "py.png")
    same_bytes(tmp_path / "cli.png", tmp_path / "py.png")
    volsplat.render(volsplat.load(tmp_path / "b.nii"), azimuth=60, size=64).save(
        tmp_path / "load.png"
    )
    same_bytes(tmp_path / "cli.png", tmp_path / "load.png")


def test_python_scene_file_on_the_command_line(cli, tmp_path):
    volsplat.Volume(blob(dtype=np.uint16), spacing=(1.5, 1, 1)).save(tmp_path / "v.nrrd")
    tf = volsplat.TransferFunction(
        color=[[0, 0.1, 0.2, 0.8], [1500, 1, 0.6, 0.3], [3000, 1, 1, 1]],
        opacity=[[0, 0.0], [900, 0.02], [3000, 0.7]],
        shade=True,
        ambient=0.15,
        diffuse=0.8,
        specular=0.3,
        specular_power=20,
    )
    scene = volsplat.Scene(
        volsplat.load(tmp_path / "v.nrrd"),
        camera=volsplat.Camera(azimuth=25, elevation=35, zoom=1.3, perspective=True),
        transfer_function=tf,
        size=(70, 50),
        lights=[(1, 1, 1), (-1, 0, 0.5, 0.3, 0.3, 0.6)],
        shading={"specular": False},
        kernel="crawfis-max",
    )
    scene.save(tmp_path / "s.json")
    cli("render", "--scene", tmp_path / "s.json", "-o", tmp_path / "cli.png", "-q")
    img = scene.render()
    assert img.stats["renderer"] == "splat-list"
    img.save(tmp_path / "py.png")
    same_bytes(tmp_path / "cli.png", tmp_path / "py.png")
    # ... and what Python says was rendered reproduces it too (--save-scene's format).
    img.scene.save(tmp_path / "resolved.json")
    cli("render", "--scene", tmp_path / "resolved.json", "-o", tmp_path / "again.png", "-q")
    same_bytes(tmp_path / "cli.png", tmp_path / "again.png")


def test_a_scene_files_output_options_are_the_default_of_save(cli, tmp_path):
    """A scene saved with output options (background, sRGB, 16 bits; a grey window for MIP)
    renders in Python to the bytes `render --scene` writes, without passing them again."""
    volsplat.Volume(blob(dtype=np.uint16), spacing=(1.5, 1, 1)).save(tmp_path / "v.nrrd")
    for name, flags in [
        ("composite", ["--background", "0.2,0.3,0.4", "--srgb", "--bit-depth", "16"]),
        ("mip", ["--mode", "mip", "--window", "100:2500", "--background", "0.5,0,0"]),
    ]:
        scene_file = tmp_path / f"{name}.json"
        cli("render", tmp_path / "v.nrrd", "--size", "48", *flags,
            "--save-scene", scene_file, "-o", tmp_path / f"{name}-cli.png", "-q")
        img = volsplat.Scene.load(scene_file).render()
        img.save(tmp_path / f"{name}-py.png")
        same_bytes(tmp_path / f"{name}-cli.png", tmp_path / f"{name}-py.png")
        assert img.to_png() == (tmp_path / f"{name}-cli.png").read_bytes()
        # Given options still win over the scene's (the composite scene is 16-bit, the MIP 8).
        assert img.to_png(bits=8 if name == "composite" else 16) != img.to_png()


def test_camera_and_transfer_function_files(cli, tmp_path):
    vol = volsplat.phantom("shepp-logan", 40)
    img = volsplat.render(
        vol,
        azimuth=10,
        elevation=70,
        roll=15,
        size=48,
        transfer_function=volsplat.TransferFunction.ramp(0, 1, 0.6),
    )
    img.camera.save(tmp_path / "cam.json")
    img.transfer_function.save(tmp_path / "tf.json")
    img.save(tmp_path / "py.png")
    cli(
        "render",
        "--phantom",
        "shepp-logan",
        "--phantom-size",
        40,
        "--camera",
        tmp_path / "cam.json",
        "--tf",
        tmp_path / "tf.json",
        "--size",
        48,
        "-o",
        tmp_path / "cli.png",
        "-q",
    )
    same_bytes(tmp_path / "cli.png", tmp_path / "py.png")


@pytest.mark.parametrize("mode", ["mip", "minip", "xray"])
def test_projection_modes(cli, tmp_path, mode):
    vol = volsplat.phantom("blobs", 32)
    img = volsplat.render(vol, mode=mode, azimuth=20, size=40, kernel="tent")
    for ext in ("png", "npy"):
        cli(
            "render",
            "--phantom",
            "blobs",
            "--phantom-size",
            32,
            "--mode",
            mode,
            "--azimuth",
            20,
            "--size",
            40,
            "--kernel",
            "tent",
            "-o",
            tmp_path / f"cli.{ext}",
            "-q",
        )
        img.save(tmp_path / f"py.{ext}")
        same_bytes(tmp_path / f"cli.{ext}", tmp_path / f"py.{ext}")


def test_png_options(cli, tmp_path):
    img = volsplat.render(volsplat.phantom("blobs", 24), size=32, mode="mip")
    cases = [
        (["--srgb"], {"srgb": True}),
        (
            ["--bit-depth", "16", "--background", "0.2,0.3,0.4"],
            {"bits": 16, "background": (0.2, 0.3, 0.4)},
        ),
        (["--window", "0.1:0.9"], {"window": (0.1, 0.9)}),
        (["--wl", "0.5,0.6"], {"wl": (0.5, 0.6)}),
    ]
    for n, (flags, kwargs) in enumerate(cases):
        try:
            cli(
                "render",
                "--phantom",
                "blobs",
                "--phantom-size",
                24,
                "--size",
                32,
                "--mode",
                "mip",
                *flags,
                "-o",
                tmp_path / f"cli{n}.png",
                "-q",
            )
        except AssertionError as e:
            if "unexpected argument" in str(e):
                pytest.skip(f"this command line has no {flags[0]}")
            raise
        img.save(tmp_path / f"py{n}.png", **kwargs)
        same_bytes(tmp_path / f"cli{n}.png", tmp_path / f"py{n}.png")


@pytest.mark.parametrize("view", ["anterior", "left", "superior"])
def test_anatomical_view(cli, tmp_path, view):
    # Issue 28 §6: Python's view= is the command line's --view (the engine's orbit field), with
    # the same names; rotations apply after it on both.
    vol = volsplat.phantom("head", 40)
    cli(
        "render",
        "--phantom",
        "head",
        "--phantom-size",
        40,
        "--view",
        view[0].upper(),
        "--azimuth",
        15,
        "--size",
        48,
        "-o",
        tmp_path / "cli.png",
        "-q",
    )
    img = volsplat.render(vol, view=view, azimuth=15, size=48)
    img.save(tmp_path / "py.png")
    same_bytes(tmp_path / "cli.png", tmp_path / "py.png")
    # The view changes the picture (a view ignored would still match the command line's if
    # both ignored it).
    volsplat.render(vol, azimuth=15, size=48).save(tmp_path / "none.png")
    assert (tmp_path / "none.png").read_bytes() != (tmp_path / "py.png").read_bytes()
    # ... and an explicit camera turned to the view, as --camera file --view.
    volsplat.render(vol, size=48).camera.save(tmp_path / "cam.json")
    cli(
        "render",
        "--phantom",
        "head",
        "--phantom-size",
        40,
        "--camera",
        tmp_path / "cam.json",
        "--view",
        view,
        "--size",
        48,
        "-o",
        tmp_path / "cli_cam.png",
        "-q",
    )
    cam = volsplat.Camera.load(tmp_path / "cam.json")
    volsplat.render(vol, camera=cam, view=view, size=48).save(tmp_path / "py_cam.png")
    same_bytes(tmp_path / "cli_cam.png", tmp_path / "py_cam.png")


def test_paraview_colour_map_file(cli, tmp_path):
    # Issue 28 §6: a ParaView colour-map preset export through --tf and through Python gives the
    # same bytes (one reader, in volsplat-io); the first preset of the file, as both take it.
    import json

    presets = [
        {
            "Name": "warm bone",
            "ColorSpace": "RGB",
            "Creator": "ParaView",
            "NanColor": [1, 1, 0],
            "RGBPoints": [0, 0.1, 0.0, 0.0, 1200, 0.9, 0.5, 0.2, 3000, 1, 1, 0.9],
            "Points": [0, 0, 0.5, 0, 900, 0.05, 0.5, 0, 3000, 0.8, 0.5, 0],
        },
        {"Name": "grey", "RGBPoints": [0, 0, 0, 0, 3000, 1, 1, 1]},
    ]
    (tmp_path / "pv.json").write_text(json.dumps(presets))
    volsplat.Volume(blob(dtype=np.uint16)).save(tmp_path / "v.nrrd")
    r = cli(
        "render",
        tmp_path / "v.nrrd",
        "--tf",
        tmp_path / "pv.json",
        "--azimuth",
        30,
        "--size",
        56,
        "-o",
        tmp_path / "cli.png",
    )
    assert "2 presets" in r.stderr, r.stderr
    with pytest.warns(UserWarning, match="2 presets"):
        tf = volsplat.TransferFunction.load(tmp_path / "pv.json")
    assert tf.color[1] == [1200, 0.9, 0.5, 0.2] and tf.opacity[1] == [900, 0.05]
    vol = volsplat.load(tmp_path / "v.nrrd")
    img = volsplat.render(vol, transfer_function=tf, azimuth=30, size=56)
    img.save(tmp_path / "py.png")
    same_bytes(tmp_path / "cli.png", tmp_path / "py.png")
    assert img.rgba[..., 3].max() > 0.05
    # The file name as the transfer function, as --tf takes it.
    with pytest.warns(UserWarning, match="2 presets"):
        img = volsplat.render(vol, transfer_function=tmp_path / "pv.json", azimuth=30, size=56)
    img.save(tmp_path / "py2.png")
    same_bytes(tmp_path / "cli.png", tmp_path / "py2.png")


@pytest.mark.parametrize("offset", ["auto", "none", 500, "-20.5"])
def test_xray_offset(cli, tmp_path, offset):
    # The CT phantom (Hounsfield units, -1000 air): `auto` integrates max(HU + 1000, 0), `none`
    # the raw values, a number max(HU + offset, 0); the Python keyword mirrors --xray-offset.
    kw = {} if offset == "auto" else {"xray_offset": offset}
    img = volsplat.render(volsplat.phantom("head", 32), mode="xray", azimuth=30, size=40, **kw)
    # The raw integral of a CT is mostly negative: its PNG is nearly black (a tiny file).
    for ext in ("npy",) if offset == "none" else ("npy", "png"):
        cli(
            "render",
            "--phantom",
            "head",
            "--phantom-size",
            32,
            "--mode",
            "xray",
            "--azimuth",
            30,
            "--size",
            40,
            "--xray-offset",
            offset,
            "-o",
            tmp_path / f"cli.{ext}",
            "-q",
        )
        img.save(tmp_path / f"py.{ext}")
        same_bytes(tmp_path / f"cli.{ext}", tmp_path / f"py.{ext}")
    # The offset changes the integral (so the parity above is not vacuous).
    raw = volsplat.render(volsplat.phantom("head", 32), mode="xray", azimuth=30, size=40,
                          xray_offset="none")
    if offset != "none":
        assert not np.array_equal(img.values, raw.values)
