"""Scenes, the renderer, images, and the one-call ``render``."""

from __future__ import annotations

import json
import os
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple, Union

from . import _volsplat as _core
from ._camera import Camera, as_camera
from ._errors import InvalidInputError
from ._transfer import TransferFunction, as_transfer_function
from ._util import dumps, floats, fspath, number, size_pair, warn_all

Volume = _core.Volume

#: Options of a render request, by where they live in the scene file.
_TOP = ("width", "height", "mode", "renderer", "threads", "memory", "k_contour", "display")
_QUALITY = (
    "kernel",
    "antialias",
    "visibility",
    "order",
    "opacity_cutoff",
    "subsample",
    "list_threshold",
    "slab",
    "shade_at",
    "preintegrate",
    "level",
)
_SCENE = ("lights", "shading", "surface_enhance", "depth_cue", "clipping", "xray_offset")
_ORBIT = ("view", "azimuth", "elevation", "roll", "zoom", "dolly", "perspective", "view_angle")
OPTIONS: Tuple[str, ...] = (
    ("volume", "camera", "transfer_function", "size", "quality") + _TOP + _QUALITY + _SCENE + _ORBIT
)

ProgressCallback = Callable[[float, str], Optional[bool]]


def _is_path(value: Any) -> bool:
    return isinstance(value, (str, bytes, os.PathLike))


def _xray_density(value: Any) -> Any:
    """``xray_offset`` as the scene file's ``xray_density``: ``"auto"`` (``None`` too),
    ``"raw"`` (``"none"``), or ``{"offset": v}``, as ``--xray-offset VALUE|auto|none`` parses."""
    if value is None:
        return "auto"
    if isinstance(value, str):
        t = value.strip()
        if t == "auto":
            return "auto"
        if t in ("none", "raw"):
            return "raw"
        try:
            value = float(t)
        except ValueError:
            raise InvalidInputError(
                f"xray_offset: expected 'auto', 'none' or a finite offset in data units (1000 for "
                f"CT in Hounsfield units), got {value!r}"
            ) from None
    if isinstance(value, bool):
        raise InvalidInputError(f"xray_offset: expected 'auto', 'none' or a number, got {value!r}")
    return {"offset": number(value, "xray_offset")}


def _lights(value: Any) -> List[Dict[str, Any]]:
    if value is None:
        return []
    out = []
    for i, light in enumerate(value):
        name = f"lights[{i}]"
        if isinstance(light, dict):
            d = {"direction": floats(light.get("direction"), 3, name + ".direction")}
            if "color" in light:
                d["color"] = floats(light["color"], 3, name + ".color")
            if "ambient" in light:
                d["ambient"] = floats(light["ambient"], 3, name + ".ambient")
            extra = set(light) - {"direction", "color", "ambient"}
            if extra:
                raise InvalidInputError(f"{name}: unknown field(s) {sorted(extra)}")
        else:
            v = list(light.tolist() if hasattr(light, "tolist") else light)
            if len(v) not in (3, 6, 9):
                raise InvalidInputError(
                    f"{name}: expected (x, y, z), (x, y, z, r, g, b) or (x, y, z, r, g, b, ar, "
                    f"ag, ab) in the camera frame, got {light!r}"
                )
            d = {"direction": floats(v[:3], 3, name)}
            if len(v) >= 6:
                d["color"] = floats(v[3:6], 3, name + " colour")
            if len(v) == 9:
                d["ambient"] = floats(v[6:9], 3, name + " ambient colour")
        out.append(d)
    return out


class Scene:
    """A whole render request: the volume, camera, transfer function, lights, image size, ray
    function, renderer and quality, exactly what a scene file holds (``volsplat render
    --save-scene`` / ``--scene``).

    ``volume`` is a :class:`Volume` (from an array, :func:`load` or :func:`phantom`), a numpy
    array (wrapped with ``Volume(array)``), a file name (read when rendered, as the command
    line does), or ``None`` for the built-in demo phantom (the command line's without input).

    Keyword options (all optional; the command-line flag in brackets):

    - ``camera`` (:class:`Camera`, dict or camera file), or the orbit of the reset view
      directly: ``view`` (``--view``: ``"anterior"``, ``"posterior"``, ``"left"``, ``"right"``,
      ``"superior"``, ``"inferior"``, an anatomical side of the LPS patient frame to start
      from), ``azimuth``, ``elevation``, ``roll``, ``zoom``, ``dolly`` (``--azimuth`` …),
      ``perspective`` (``--perspective``), ``view_angle`` (degrees). Given with a camera, these
      change its orbit, as the flags do with ``--camera``.
    - ``transfer_function``: a :class:`TransferFunction`, preset name (``--preset``), dict, file
      (``--tf``) or ``None``/``"auto"``.
    - ``width``, ``height`` or ``size=N``/``(W, H)`` (``--size``; default 512×512).
    - ``mode``: ``"composite"`` (default), ``"mip"``, ``"minip"``, ``"xray"`` (``--mode``).
    - ``renderer``: ``"auto"``, ``"sheets"`` (also ``"splat"``, its earlier name), ``"splat_list"``,
      ``"sabella"``, ``"nil"``.
    - quality: ``kernel`` (``"gaussian"``, ``"nearest"``, ``"tent"``, ``"bspline"``, …),
      ``antialias``, ``visibility`` (``"auto"``/``"image"``/``"sheet"``/``"every"``), ``slab`` (image-aligned slab
      thickness in voxels; default ``None``: 1 for composite, 0.5 for MIP and MinIP),
      ``shade_at`` (``"auto"``, the default: at the samples where the slabs can, as
      the exact integral; ``"voxels"``, as VTK shades; or ``"samples"``),
      ``preintegrate`` (``"auto"``, the default: by segment where the transfer function's ramp
      is sharp; ``"on"``; ``"off"``: one point per slab), ``level`` (``"full"``, the default;
      ``"auto"``: a preview from the resolution pyramid level whose voxel is about a pixel, its
      cost falling with the pixel count; or a level number; ``--level``),
      ``order`` (``"ftb"``/``"btf"``),
      ``opacity_cutoff``, ``subsample``, ``list_threshold``; or ``quality={...}``.
    - ``lights``: directions in the camera frame, ``(x, y, z)``, ``(x, y, z, r, g, b)`` or
      ``(x, y, z, r, g, b, ar, ag, ab)`` with an ambient colour, which the transfer
      function's ``ambient`` multiplies (black otherwise, as VTK's lights) (``--light``); ``shading={"emission":…, "diffuse":…, "specular":…}``;
      ``surface_enhance=(lo, hi)``; ``depth_cue=(near, far)``; ``k_contour=(r, g, b)``.
    - ``clipping``: a crop box and clipping planes, the scene file's object (``--crop``,
      ``--clip-plane``): ``{"crop": {"min": (x, y, z), "max": (x, y, z), "units": "voxels"},
      "planes": [{"normal": (nx, ny, nz), "offset": d}]}``; planes keep ``n·x + d ≥ 0``.
    - ``xray_offset`` (``--xray-offset``): what ``mode="xray"`` integrates: ``"auto"`` (the
      default, also ``None``: ``max(v + 1000, 0)`` where the values look like CT in Hounsfield
      units, attenuation relative to air; the values as they are otherwise), ``"none"`` (the
      raw values, negative parts included) or a number ``o`` (``max(v + o, 0)``, data units).
    - ``display={...}``: options of the Chapter 6 displays (``renderer="sabella"|"nil"``).
    - ``threads``: worker threads (default: all cores; the image does not depend on it).
    - ``memory`` (``--memory``): OME-Zarr stores are read in bricks through a cache of at most
      this many bytes (an integer, or a string such as ``"512MiB"`` or ``"2GiB"``), out of core;
      the image does not depend on it. Default: whole, unless the level is larger than half the
      available memory.

    Scenes are immutable; :meth:`replace` returns a changed copy.
    """

    __slots__ = ("_req", "_volume", "_source")

    def __init__(self, volume: Any = None, **options: Any) -> None:
        self._req: Dict[str, Any] = {"scene": {}, "width": 512, "height": 512}
        self._volume: Optional[Volume] = None
        self._source: Optional[Dict[str, Any]] = None
        self._set_volume(volume)
        self._apply(options)
        self._check()

    # -- building --------------------------------------------------------------------------

    def _set_volume(self, volume: Any) -> None:
        self._volume, self._source = None, None
        if volume is None:
            return
        if isinstance(volume, Volume):
            self._volume = volume
        elif _is_path(volume):
            path = os.fsdecode(volume)
            self._source = {"file": {"path": path}}
        elif hasattr(volume, "__array__") or isinstance(volume, (list, tuple)):
            self._volume = Volume(volume)
        else:
            raise InvalidInputError(
                "volume: expected a volsplat.Volume, a 3-D numpy array, a file name or None "
                f"(the demo phantom), got {type(volume).__name__}"
            )

    def _apply(self, options: Dict[str, Any]) -> None:
        unknown = sorted(set(options) - set(OPTIONS))
        if unknown:
            raise TypeError(
                f"unexpected keyword argument(s) {', '.join(map(repr, unknown))}; "
                f"options are {', '.join(OPTIONS)}"
            )
        req, scene = self._req, self._req["scene"]
        if "volume" in options:
            self._set_volume(options["volume"])
        if "camera" in options:
            cam = as_camera(options["camera"])
            if cam is None:
                scene.pop("camera", None)
            else:
                scene["camera"] = cam.to_dict()
        orbit = {k: options[k] for k in _ORBIT if k in options}
        if orbit:
            cam = Camera.from_dict(scene["camera"]) if "camera" in scene else Camera()
            scene["camera"] = cam.replace(**orbit).to_dict()
        if "transfer_function" in options:
            tf = as_transfer_function(options["transfer_function"])
            scene["transfer_function"] = "auto" if tf is None else tf.to_dict()
        if options.get("size") is not None:
            req["width"], req["height"] = size_pair(options["size"])
        for k in _TOP:
            if k in options:
                v = options[k]
                if v is None:
                    if k in ("width", "height"):
                        raise InvalidInputError(f"{k}: must be a number of pixels, not None")
                    req.pop(k, None)
                elif k == "k_contour":
                    req[k] = floats(v, 3, k)
                elif k == "display":
                    if not isinstance(v, dict):
                        raise InvalidInputError(f"display: expected a dict, got {v!r}")
                    req[k] = dict(req.get(k, {}), **v)
                elif k in ("width", "height", "threads"):
                    if isinstance(v, bool) or not isinstance(v, int):
                        raise InvalidInputError(f"{k}: expected an integer, got {v!r}")
                    req[k] = int(v)
                elif k == "memory":
                    req[k] = _size_bytes(v)
                else:
                    req[k] = v
        quality = dict(req.get("quality", {}))
        if options.get("quality") is not None:
            if not isinstance(options["quality"], dict):
                raise InvalidInputError(f"quality: expected a dict, got {options['quality']!r}")
            quality.update(options["quality"])
        for k in _QUALITY:
            if k in options:
                if options[k] is None:
                    quality.pop(k, None)
                else:
                    quality[k] = options[k]
        if quality:
            req["quality"] = quality
        if "lights" in options:
            lights = _lights(options["lights"])
            if lights:
                scene["lights"] = lights
            else:
                scene.pop("lights", None)
        if "shading" in options:
            s = options["shading"]
            if s is None:
                scene.pop("shading", None)
            elif isinstance(s, dict):
                scene["shading"] = {k: bool(v) for k, v in s.items()}
            else:
                raise InvalidInputError(
                    "shading: expected a dict such as {'specular': False}, got " + repr(s)
                )
        if "clipping" in options:
            c = options["clipping"]
            if c is None:
                scene.pop("clipping", None)
            elif isinstance(c, dict):
                # Checked (and errors named) by the engine in _check.
                scene["clipping"] = json.loads(dumps(c))
            else:
                raise InvalidInputError(
                    "clipping: expected a dict with 'crop' and/or 'planes', got " + repr(c)
                )
        if "xray_offset" in options:
            d = _xray_density(options["xray_offset"])
            if d == "auto":
                scene.pop("xray_density", None)
            else:
                scene["xray_density"] = d
        for k in ("surface_enhance", "depth_cue"):
            if k in options:
                if options[k] is None:
                    scene.pop(k, None)
                else:
                    scene[k] = floats(options[k], 2, k)

    def _check(self) -> None:
        # Field ranges and names (errors name the scene-file field); the normalised request
        # writes every default out, so two equal scenes compare equal.
        normal = json.loads(_core.check_request(dumps(self._request(placeholder=True))))
        normal["scene"].pop("volume", None)
        self._req = normal

    def _request(self, placeholder: bool = False) -> Dict[str, Any]:
        req = json.loads(json.dumps(self._req))
        if self._volume is not None:
            src = self._volume._source_json()
            if src is not None and placeholder:
                req["scene"]["volume"] = json.loads(src)
        elif self._source is not None:
            req["scene"]["volume"] = self._source
        return req

    def _render_args(self) -> Tuple[str, Optional[Volume]]:
        return dumps(self._request()), self._volume

    def replace(self, **options: Any) -> "Scene":
        """A copy with some options replaced (the keyword options of the constructor,
        ``volume`` included)."""
        s = Scene.__new__(Scene)
        s._req = json.loads(json.dumps(self._req))
        s._volume, s._source = self._volume, self._source
        s._apply(options)
        s._check()
        return s

    # -- files -----------------------------------------------------------------------------

    @classmethod
    def load(cls, path: Any) -> "Scene":
        """Reads a scene file (as ``volsplat render --save-scene`` writes it). Unknown fields
        draw warnings naming their path, as on the command line. A volume file named in it is
        read when the scene is rendered (relative paths from the current folder, as the
        command line)."""
        text, warnings_ = _core.load_scene(fspath(path))
        warn_all(warnings_)
        return cls._from_request(json.loads(text), None)

    @classmethod
    def _from_request(cls, req: Dict[str, Any], volume: Optional[Volume]) -> "Scene":
        s = cls.__new__(cls)
        source = req.get("scene", {}).pop("volume", None)
        s._req = req
        s._volume = volume
        s._source = None if volume is not None else source
        s._check()
        return s

    @classmethod
    def from_dict(cls, d: Dict[str, Any], volume: Optional[Volume] = None) -> "Scene":
        """A scene from a scene-file object (``volume``, if given, replaces its volume)."""
        if not isinstance(d, dict):
            raise InvalidInputError(f"scene: expected a dict, got {d!r}")
        return cls._from_request(json.loads(json.dumps(d)), volume)

    def to_dict(self) -> Dict[str, Any]:
        """The scene-file object (``scene.volume`` left out when the volume is an array)."""
        return self._request(placeholder=True)

    def save(self, path: Any) -> None:
        """Writes the scene file that ``volsplat render --scene`` renders. The volume must be
        nameable in a file: a file (from :func:`load` or a file name) or a phantom. For an
        array, ``volume.save("v.nrrd")`` first and use ``scene.replace(volume="v.nrrd")``."""
        req = self._request(placeholder=True)
        if "volume" not in req["scene"]:
            if self._volume is not None:
                raise InvalidInputError(
                    "a volume made from an array cannot be named in a scene file; save it as "
                    "NRRD first (volume.save('v.nrrd')) and use scene.replace(volume='v.nrrd')"
                )
        _core.save_scene(fspath(path), dumps(req))

    # -- fields ----------------------------------------------------------------------------

    @property
    def volume(self) -> Union[Volume, str, None]:
        """The :class:`Volume`, the file name the renderer will read, or ``None`` (the demo)."""
        if self._volume is not None:
            return self._volume
        if self._source is not None and "file" in self._source:
            return self._source["file"]["path"]
        return None

    @property
    def camera(self) -> Camera:
        return Camera.from_dict(self._req["scene"].get("camera", {"orbit": {}}))

    @property
    def transfer_function(self) -> TransferFunction:
        return TransferFunction.from_dict(self._req["scene"].get("transfer_function", "auto"))

    @property
    def width(self) -> int:
        return int(self._req["width"])

    @property
    def height(self) -> int:
        return int(self._req["height"])

    @property
    def mode(self) -> str:
        return str(self._req.get("mode", "composite"))

    @property
    def renderer(self) -> str:
        return str(self._req.get("renderer", "auto"))

    @property
    def threads(self) -> Optional[int]:
        return self._req.get("threads")

    @property
    def memory(self) -> Optional[int]:
        """The out-of-core budget for OME-Zarr stores, bytes (``None``: whole where it fits)."""
        return self._req.get("memory")

    @property
    def quality(self) -> Dict[str, Any]:
        return dict(self._req.get("quality", {}))

    @property
    def xray_offset(self) -> Union[str, float]:
        """What ``mode="xray"`` integrates: ``"auto"``, ``"none"`` or the offset (data
        units)."""
        d = self._req["scene"].get("xray_density", "auto")
        if isinstance(d, dict):
            return float(d["offset"])
        return "none" if d == "raw" else str(d)

    def render(self, **overrides: Any) -> "Image":
        """Renders once (a fresh :class:`Renderer`; keep one to render many frames)."""
        progress = overrides.pop("progress", None)
        return Renderer(self).render(progress=progress, **overrides)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Scene):
            return False
        same_volume = (self._volume is None and other._volume is None) or (
            self._volume is not None
            and other._volume is not None
            and self._volume._same_data(other._volume)
        )
        return same_volume and self._source == other._source and self._req == other._req

    def __repr__(self) -> str:
        vol = self._volume if self._volume is not None else (self._source or "demo phantom")
        return (
            f"volsplat.Scene(volume={vol!r}, camera={self.camera!r}, "
            f"transfer_function={self.transfer_function!r}, size=({self.width}, "
            f"{self.height}), mode={self.mode!r})"
        )


def as_scene(value: Any) -> Scene:
    if isinstance(value, Scene):
        return value
    return Scene(value)


class Image:
    """The result of a render.

    - ``rgba``: premultiplied linear RGBA, float32 ``(height, width, 4)``, row 0 at the top
      (a read-only view; ``.copy()`` it to change it).
    - ``values``: for ``mode="xray"`` the line integrals ∫ρ ds (data units × world units), for
      ``"mip"``/``"minip"`` the projected data values (NaN where no sample covers the pixel),
      float32 ``(height, width)``; ``None`` for composite renders.
    - ``stats``: timings (milliseconds) and counters, as ``volsplat render --stats``.
    - ``camera``, ``transfer_function``: what the render actually used (save them as files).
    - ``scene``: the request as rendered with camera and transfer function resolved, what
      ``--save-scene`` writes; ``warnings`` and ``notes`` from the engine.
    - :meth:`save` writes ``.png``/``.npy`` exactly as the command line's ``-o``;
      :meth:`to_uint8` gives 8-bit pixels; Jupyter shows the image (``_repr_png_``).
    """

    __slots__ = ("_out", "_volume")

    def __init__(self, output: Any, volume: Optional[Volume] = None) -> None:
        self._out = output
        self._volume = volume

    @property
    def rgba(self) -> Any:
        return self._out.rgba

    @property
    def values(self) -> Any:
        return self._out.values

    @property
    def width(self) -> int:
        return self._out.width

    @property
    def height(self) -> int:
        return self._out.height

    @property
    def shape(self) -> Tuple[int, int]:
        """``(height, width)``."""
        return (self._out.height, self._out.width)

    @property
    def mode(self) -> str:
        return self._out.mode

    @property
    def stats(self) -> Dict[str, Any]:
        return self._out.stats

    @property
    def camera(self) -> Camera:
        """The explicit camera used (world units)."""
        return Camera.from_dict(json.loads(self._out.camera_json))

    @property
    def transfer_function(self) -> TransferFunction:
        """The transfer function used (data units)."""
        return TransferFunction.from_dict(
            {"function": json.loads(self._out.transfer_function_json)}
        )

    @property
    def scene(self) -> Scene:
        """The scene as rendered, camera and transfer function resolved (``--save-scene``)."""
        return Scene._from_request(json.loads(self._out.scene_json), self._volume)

    @property
    def warnings(self) -> List[str]:
        return self._out.warnings

    @property
    def notes(self) -> List[str]:
        return self._out.notes

    def save(
        self,
        path: Any,
        *,
        srgb: Optional[bool] = None,
        bits: Optional[int] = None,
        background: Optional[Sequence[float]] = None,
        window: Optional[Tuple[float, float]] = None,
        wl: Optional[Tuple[float, float]] = None,
    ) -> None:
        """Writes the image as ``volsplat render -o path`` does, byte for byte (the same
        writers, the same defaults).

        ``.png``: RGB composited over ``background`` (linear RGB, ``--background``), holding
        the linear values (``srgb=True`` applies the sRGB curve, ``--srgb``), 8 or 16 ``bits``
        (``--bit-depth``). For ``mode="xray"`` a grey image of the line integrals scaled so the
        brightest pixel is white; for ``"mip"``, ``"minip"`` and ``"xray"`` a grey
        ``window=(lo, hi)`` (``--window``) or ``wl=(level, width)`` (``--wl``) maps the values
        linearly to black…white instead. An option not given is the scene's (its ``output``
        field, as ``volsplat render --scene`` reads it; black, linear, 8 bits and no window
        unless the scene says otherwise).
        ``.npy``: float32 ``(H, W, 4)`` premultiplied RGBA, or the ``(H, W)`` values for X-ray
        (and for MIP/MinIP with a window). Written atomically.
        """
        self._out.save(fspath(path), **self._png_options(srgb, bits, background, window, wl))

    def to_png(
        self,
        *,
        srgb: Optional[bool] = None,
        bits: Optional[int] = None,
        background: Optional[Sequence[float]] = None,
        window: Optional[Tuple[float, float]] = None,
        wl: Optional[Tuple[float, float]] = None,
    ) -> bytes:
        """The bytes :meth:`save` writes to a ``.png`` file (the same defaults)."""
        return self._out.png_bytes(**self._png_options(srgb, bits, background, window, wl))

    def _png_options(
        self,
        srgb: Optional[bool],
        bits: Optional[int],
        background: Optional[Sequence[float]],
        window: Optional[Tuple[float, float]],
        wl: Optional[Tuple[float, float]],
    ) -> Dict[str, Any]:
        if window is not None and wl is not None:
            raise InvalidInputError("give window=(lo, hi) or wl=(level, width), not both")
        # What is not given comes from the scene's output options (`render --scene`).
        scene_out = json.loads(self._out.scene_json).get("output") or {}
        win = None
        if window is not None:
            win = tuple(floats(window, 2, "window"))
        elif wl is not None:
            import numpy as np

            level, width = (np.float32(v) for v in floats(wl, 2, "wl"))
            if not width > 0:
                raise InvalidInputError(f"wl: the width must be > 0, got {float(width)}")
            # As the command line computes it, in single precision.
            win = (float(level - np.float32(0.5) * width), float(level + np.float32(0.5) * width))
        elif scene_out.get("window") is not None:
            win = tuple(float(v) for v in scene_out["window"])
        if srgb is None and "srgb" in scene_out:
            srgb = bool(scene_out["srgb"])
        if bits is None:
            bits = scene_out.get("bit_depth", 8)
        if background is None:
            background = scene_out.get("background", (0.0, 0.0, 0.0))
        return {
            "srgb": None if srgb is None else bool(srgb),
            "bits": int(bits),
            "background": floats(background, 3, "background"),
            "window": win,
        }

    def to_uint8(
        self,
        srgb: bool = False,
        background: Optional[Sequence[float]] = None,
        premultiplied: bool = True,
    ) -> Any:
        """8-bit pixels, quantised exactly as the PNG writer does (``round(255·v)``).

        By default ``(H, W, 4)`` RGBA with premultiplied colour, i.e. the image over black:
        ``to_uint8(srgb=s)[..., :3]`` equals the pixels of ``save(path, srgb=s)`` (composite
        images, and MIP/MinIP without a window). ``premultiplied=False`` gives straight colour
        (for ``PIL.Image.fromarray(..., "RGBA")``). With ``background=(r, g, b)`` (linear RGB):
        ``(H, W, 3)`` composited over it. ``srgb=True`` applies the sRGB curve to colour (alpha
        stays linear)."""
        bg = None if background is None else floats(background, 3, "background")
        return self._out.to_uint8(srgb=srgb, background=bg, premultiplied=premultiplied)

    def _repr_png_(self) -> bytes:
        return self.to_png()

    def __array__(self, dtype: Any = None, copy: Any = None) -> Any:
        a = self.rgba
        if dtype is not None:
            a = a.astype(dtype)
        return a.copy() if copy else a

    def __repr__(self) -> str:
        return (
            f"<volsplat.Image {self.width}×{self.height} mode={self.mode!r} "
            f"{self.stats.get('total_ms', 0.0):.0f} ms>"
        )


class Renderer:
    """Renders a scene, frame after frame, keeping what the next frame can reuse: the loaded
    volume, the classification tables (per transfer function, lights and shading), the splat
    list, the Chapter 6 display state and the thread pool. A frame that changes only the
    camera costs only the frame.

    ``Renderer(scene_or_volume, **options)`` takes a :class:`Scene`, a :class:`Volume`, an
    array, a file name or nothing (the demo phantom), and default options for every frame
    (those of :class:`Scene`). :meth:`render` takes per-frame overrides::

        r = volsplat.Renderer(volsplat.load("head.nrrd"), transfer_function="ct-bone", size=256)
        frames = [r.render(azimuth=a) for a in range(0, 360, 10)]

    Rendering releases the GIL (other Python threads run; two threads may render at once, one
    renderer each, or share one renderer, which then renders one frame at a time). Ctrl-C
    interrupts a render (``KeyboardInterrupt``) at the next batch of sheets. ``max_voxels``
    caps the volume files this renderer reads.
    """

    __slots__ = ("_scene", "_core")

    def __init__(
        self, scene: Any = None, *, max_voxels: Optional[int] = None, **options: Any
    ) -> None:
        base = as_scene(scene)
        self._scene = base.replace(**options) if options else base
        self._core = _core.RendererCore(max_voxels=max_voxels)

    @property
    def scene(self) -> Scene:
        """The default scene of every frame."""
        return self._scene

    @scene.setter
    def scene(self, value: Any) -> None:
        self._scene = as_scene(value)

    def _frame(self, overrides: Dict[str, Any]) -> Scene:
        return self._scene.replace(**overrides) if overrides else self._scene

    def render(
        self,
        *,
        progress: Optional[ProgressCallback] = None,
        poll_interval: float = 0.05,
        **overrides: Any,
    ) -> Image:
        """Renders one frame: the renderer's scene with ``overrides`` (any option of
        :class:`Scene`: ``camera``, ``width``, ``height``, ``size``, ``mode``,
        ``transfer_function``, ``azimuth``, …).

        ``progress(fraction, stage)`` is called from this thread about every
        ``poll_interval`` seconds while the render runs (``stage`` is ``"load"``,
        ``"classify"``, ``"render"`` or ``"done"``); returning ``False`` cancels with
        :class:`CancelledError`. Returns an :class:`Image`.
        """
        scene = self._frame(overrides)
        request, volume = scene._render_args()
        out = self._core.render(request, volume, progress, number(poll_interval, "poll_interval"))
        return Image(out, volume)

    def camera(self, **overrides: Any) -> Camera:
        """The explicit camera a frame with ``overrides`` would use (loads the volume if
        needed)."""
        request, volume = self._frame(overrides)._render_args()
        return Camera.from_dict(json.loads(self._core.camera(request, volume)))

    def transfer_function(self, **overrides: Any) -> TransferFunction:
        """The transfer function a frame with ``overrides`` would use."""
        request, volume = self._frame(overrides)._render_args()
        return TransferFunction.from_dict(
            {"function": json.loads(self._core.transfer_function(request, volume))}
        )

    def clear(self) -> None:
        """Forgets everything kept between frames."""
        self._core.clear()

    def __repr__(self) -> str:
        return f"volsplat.Renderer({self._scene!r})"


_VOLUME_KWARGS = ("spacing", "origin", "direction", "axes", "affine", "space", "dtype")


def render(
    volume: Any = None,
    *,
    progress: Optional[ProgressCallback] = None,
    max_voxels: Optional[int] = None,
    **options: Any,
) -> Image:
    """Renders in one call.

    ``volume`` is a :class:`Volume`, a 3-D numpy array, a file name, a :class:`Scene`, or
    ``None`` (the demo phantom). For an array, ``spacing``, ``origin``, ``direction``, ``axes``,
    ``affine``, ``space`` and ``dtype`` are passed to :class:`Volume`; every other keyword is
    an option of :class:`Scene` (``camera``, ``transfer_function``, ``width``/``height``/
    ``size``, ``mode``, ``azimuth``, …)::

        img = volsplat.render(array, spacing=(2.0, 0.8, 0.8), azimuth=30, elevation=15,
                              transfer_function="ct-bone", size=(640, 480))
        img.save("view.png")
    """
    vkw = {k: options.pop(k) for k in _VOLUME_KWARGS if k in options}
    if vkw:
        if volume is None or isinstance(volume, (Volume, Scene)) or _is_path(volume):
            raise InvalidInputError(f"{', '.join(vkw)}: only apply when volume is a numpy array")
        volume = Volume(volume, **vkw)
    scene = volume.replace(**options) if isinstance(volume, Scene) else Scene(volume, **options)
    return Renderer(scene, max_voxels=max_voxels).render(progress=progress)


_SIZE_UNITS = {"": 0, "b": 0, "k": 10, "kb": 10, "kib": 10, "m": 20, "mb": 20, "mib": 20,
               "g": 30, "gb": 30, "gib": 30, "t": 40, "tb": 40, "tib": 40}


def _size_bytes(v: Any) -> int:
    """``memory=``: bytes as an integer, or a whole number with KiB, MiB, GiB or TiB (K, M, G,
    T, KB, … : powers of 1024, as ``--memory`` reads them)."""
    if isinstance(v, bool):
        raise InvalidInputError(f"memory: expected a size in bytes, got {v!r}")
    if isinstance(v, int):
        n = v
    elif isinstance(v, str):
        t = v.strip()
        digits = len(t) - len(t.lstrip("0123456789"))
        num, unit = t[:digits], t[digits:].strip().lower()
        if not num or unit not in _SIZE_UNITS:
            raise InvalidInputError(
                f"memory: {v!r} is not a size (a whole number, then KiB, MiB, GiB or TiB)")
        n = int(num) << _SIZE_UNITS[unit]
    else:
        raise InvalidInputError(f"memory: expected a size in bytes, got {v!r}")
    if not 0 < n < 1 << 64:
        raise InvalidInputError(f"memory: {v!r} must be above 0 bytes and below 16 EiB")
    return n
