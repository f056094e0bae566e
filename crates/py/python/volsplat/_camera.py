"""Cameras: VTK's reset view of the volume followed by an orbit, or an explicit VTK camera."""

from __future__ import annotations

import json
from typing import Any, Dict, Optional, Sequence

from . import _volsplat as _core
from ._errors import InvalidInputError
from ._util import dumps, floats, fspath, number, warn_all

_ORBIT = ("azimuth", "elevation", "roll", "zoom", "dolly", "view_angle")


def _view(value: Any) -> str:
    """An anatomical view name as the command line's ``--view`` takes it, in the scene file's
    spelling (``"A"``, ``"front"`` → ``"anterior"``)."""
    if not isinstance(value, str):
        raise InvalidInputError(
            f"view: expected anterior, posterior, left, right, superior or inferior, got {value!r}"
        )
    return _core.anatomical_view(value)


class Camera:
    """A view of the volume, with VTK's semantics (world units, degrees).

    Two kinds, as in a scene file:

    - **Relative to the volume** (no ``position``/``focal_point``): VTK's ``ResetCamera`` view
      of the volume's bounds (looking down −z with +y up, orthographic unless
      ``perspective=True``), then the orbit. This is what the command line's ``--azimuth``,
      ``--elevation``, ``--roll``, ``--zoom``, ``--dolly``, ``--perspective`` and
      ``--view-angle`` build::

          Camera(azimuth=30, elevation=15, zoom=1.3)

      ``view`` (``--view``) starts from an anatomical view of the patient frame (LPS) instead
      of VTK's direction: ``"anterior"``, ``"posterior"``, ``"left"``, ``"right"`` (head up),
      ``"superior"``, ``"inferior"`` (anterior up), as 3D Slicer's view buttons (also ``"A"``,
      ``"P"``, ``"L"``, ``"R"``, ``"S"``, ``"I"``); the rotations then apply to it::

          Camera(view="anterior", azimuth=20)

    - **Explicit**: a VTK camera (``position``, ``focal_point``, ``view_up`` in world units;
      ``parallel_projection``; ``parallel_scale``, half the image height in world units, for
      orthographic views; ``view_angle``, the vertical field of view in degrees, for
      perspective ones), optionally followed by an orbit (as ``--camera file --azimuth 90``)::

          Camera(position=(394.4, 802.9, 284.5), focal_point=(122, 122, 80.25),
                 view_up=(0, 0, 1), parallel_projection=True, parallel_scale=194.1)

    With an explicit camera, ``view`` turns it to that side about its focal point (keeping the
    distance), as ``--camera file --view left`` does. The orbit is applied in VTK's order:
    anatomical view, projection switch and view angle, ``Azimuth``,
    ``Elevation``, ``OrthogonalizeViewUp``, ``Roll``, ``Zoom``, ``Dolly``. Cameras are
    immutable; :meth:`replace` returns a changed copy. ``Image.camera`` is the explicit camera
    a render used, which :meth:`save` writes as a camera file for ``volsplat render --camera``,
    VTK or ParaView.
    """

    __slots__ = ("_spec",)

    def __init__(
        self,
        position: Optional[Sequence[float]] = None,
        focal_point: Optional[Sequence[float]] = None,
        view_up: Optional[Sequence[float]] = None,
        *,
        parallel_projection: Optional[bool] = None,
        parallel_scale: Optional[float] = None,
        view_angle: Optional[float] = None,
        azimuth: Optional[float] = None,
        elevation: Optional[float] = None,
        roll: Optional[float] = None,
        zoom: Optional[float] = None,
        dolly: Optional[float] = None,
        perspective: Optional[bool] = None,
        view: Optional[str] = None,
    ) -> None:
        orbit: Dict[str, Any] = {}
        if view is not None:
            orbit["view"] = _view(view)
        for name, v in (
            ("azimuth", azimuth),
            ("elevation", elevation),
            ("roll", roll),
            ("zoom", zoom),
            ("dolly", dolly),
        ):
            if v is not None:
                orbit[name] = number(v, name)
        if (position is None) != (focal_point is None):
            raise InvalidInputError(
                "an explicit camera needs both position and focal_point; leave both out for "
                "VTK's reset view of the volume"
            )
        if position is None:
            if parallel_scale is not None or view_up is not None:
                raise InvalidInputError(
                    "parallel_scale and view_up belong to an explicit camera (give position "
                    "and focal_point); on the reset view use zoom= and roll="
                )
            if parallel_projection is not None and perspective is None:
                perspective = not parallel_projection
            if view_angle is not None:
                orbit["view_angle"] = number(view_angle, "view_angle")
            if perspective is not None:
                orbit["projection"] = "perspective" if perspective else "orthographic"
            spec: Dict[str, Any] = {"orbit": orbit}
        else:
            cam = {
                "position": floats(position, 3, "position"),
                "focal_point": floats(focal_point, 3, "focal_point"),
                "view_up": floats(view_up if view_up is not None else (0, 1, 0), 3, "view_up"),
                "parallel_projection": True
                if parallel_projection is None
                else bool(parallel_projection),
                "parallel_scale": 1.0
                if parallel_scale is None
                else number(parallel_scale, "parallel_scale"),
                "view_angle": 30.0 if view_angle is None else number(view_angle, "view_angle"),
            }
            if perspective is not None:
                orbit["projection"] = "perspective" if perspective else "orthographic"
            spec = {"explicit": {"camera": cam, "orbit": orbit}}
        self._spec = json.loads(_core.check_camera_spec(dumps(spec)))

    # -- construction from files and dicts ------------------------------------------------

    @classmethod
    def load(cls, path: Any) -> "Camera":
        """Reads a camera file (JSON: ``position``, ``focal_point``, ``view_up``,
        ``parallel_projection`` required; ``parallel_scale``, ``view_angle`` default to VTK's 1
        and 30). Unknown fields draw a warning, as on the command line."""
        text, warnings_ = _core.load_camera(fspath(path))
        warn_all(warnings_)
        return cls._from_spec({"explicit": {"camera": json.loads(text)}})

    @classmethod
    def from_dict(cls, d: Dict[str, Any]) -> "Camera":
        """A camera from a scene file's ``camera`` object (``{"orbit": {...}}`` or
        ``{"explicit": {"camera": {...}, "orbit": {...}}}``) or from a camera-file object
        (``{"position": ..., "focal_point": ..., ...}``)."""
        if not isinstance(d, dict):
            raise InvalidInputError(f"camera: expected a dict, got {d!r}")
        if "orbit" in d or "explicit" in d:
            return cls._from_spec(d)
        return cls._from_spec({"explicit": {"camera": d}})

    @classmethod
    def _from_spec(cls, spec: Dict[str, Any]) -> "Camera":
        c = cls.__new__(cls)
        c._spec = json.loads(_core.check_camera_spec(dumps(spec)))
        return c

    def to_dict(self) -> Dict[str, Any]:
        """The scene file's ``camera`` object."""
        return json.loads(json.dumps(self._spec))

    def save(self, path: Any) -> None:
        """Writes an explicit camera (with no orbit left to apply) as a camera file, which
        ``volsplat render --camera``, VTK and ParaView reproduce. A camera relative to the
        volume has no position until it meets a volume: save ``Image.camera`` instead."""
        cam = self._explicit_camera()
        if cam is None or self._orbit():
            raise InvalidInputError(
                "only an explicit camera without a pending orbit can be saved as a camera "
                "file; render once and save image.camera (the camera actually used)"
            )
        _core.save_camera(fspath(path), dumps(cam))

    # -- changes ---------------------------------------------------------------------------

    def replace(self, **changes: Any) -> "Camera":
        """A copy with some fields replaced: the orbit's ``view``, ``azimuth``, ``elevation``,
        ``roll``, ``zoom``, ``dolly``, ``view_angle``, ``perspective`` (``None`` removes one), or an
        explicit camera's ``position``, ``focal_point``, ``view_up``, ``parallel_projection``,
        ``parallel_scale``."""
        spec = self.to_dict()
        cam = spec.get("explicit", {}).get("camera")
        orbit = dict(spec["orbit"]) if "orbit" in spec else dict(spec["explicit"].get("orbit", {}))
        for key, value in changes.items():
            if key in ("azimuth", "elevation", "roll", "zoom", "dolly"):
                orbit[key] = None if value is None else number(value, key)
            elif key == "view":
                orbit[key] = None if value is None else _view(value)
            elif key == "view_angle":
                v = None if value is None else number(value, key)
                if cam is not None and v is not None:
                    cam["view_angle"] = v
                else:
                    orbit["view_angle"] = v
            elif key == "perspective":
                orbit["projection"] = (
                    None if value is None else ("perspective" if value else "orthographic")
                )
            elif key in ("position", "focal_point", "view_up"):
                if cam is None:
                    raise InvalidInputError(
                        f"{key}: this camera is VTK's reset view of the volume; build an explicit "
                        "Camera(position=..., focal_point=...) instead"
                    )
                cam[key] = floats(value, 3, key)
            elif key in ("parallel_projection",):
                if cam is None:
                    orbit["projection"] = "orthographic" if value else "perspective"
                else:
                    cam[key] = bool(value)
            elif key == "parallel_scale":
                if cam is None:
                    raise InvalidInputError(
                        "parallel_scale belongs to an explicit camera; use zoom= on the reset view"
                    )
                cam[key] = number(value, key)
            else:
                raise TypeError(f"Camera.replace() got an unexpected keyword argument {key!r}")
        orbit = {k: v for k, v in orbit.items() if v is not None}
        if cam is None:
            return Camera._from_spec({"orbit": orbit})
        return Camera._from_spec({"explicit": {"camera": cam, "orbit": orbit}})

    # -- fields ----------------------------------------------------------------------------

    def _explicit_camera(self) -> Optional[Dict[str, Any]]:
        e = self._spec.get("explicit")
        return dict(e["camera"]) if e else None

    def _orbit(self) -> Dict[str, Any]:
        o = (
            self._spec["orbit"]
            if "orbit" in self._spec
            else self._spec["explicit"].get("orbit", {})
        )
        return {k: v for k, v in o.items() if v is not None}

    @property
    def is_explicit(self) -> bool:
        """Whether this is an explicit VTK camera (rather than the reset view of the volume)."""
        return "explicit" in self._spec

    def _cam_field(self, name: str) -> Any:
        cam = self._explicit_camera()
        if cam is None:
            return None
        v = cam[name]
        return tuple(v) if isinstance(v, list) else v

    @property
    def position(self) -> Optional[tuple]:
        """Eye position (world units); ``None`` for the reset view."""
        return self._cam_field("position")

    @property
    def focal_point(self) -> Optional[tuple]:
        """The point looked at (world units); ``None`` for the reset view."""
        return self._cam_field("focal_point")

    @property
    def view_up(self) -> Optional[tuple]:
        """Up direction of the image; ``None`` for the reset view."""
        return self._cam_field("view_up")

    @property
    def parallel_projection(self) -> Optional[bool]:
        """``True`` for orthographic; ``None`` for the reset view (see ``perspective``)."""
        return self._cam_field("parallel_projection")

    @property
    def parallel_scale(self) -> Optional[float]:
        """Half the image height in world units (orthographic); ``None`` for the reset view."""
        return self._cam_field("parallel_scale")

    @property
    def view_angle(self) -> Optional[float]:
        """Vertical field of view in degrees (perspective), or the orbit's view angle."""
        v = self._cam_field("view_angle")
        return v if v is not None else self._orbit().get("view_angle")

    @property
    def orbit(self) -> Dict[str, Any]:
        """The view changes applied to the camera (only the fields given)."""
        return self._orbit()

    @property
    def view(self) -> Optional[str]:
        """The anatomical view the orbit starts from (``"anterior"``, …), or ``None``."""
        return self._orbit().get("view")

    @property
    def azimuth(self) -> Optional[float]:
        return self._orbit().get("azimuth")

    @property
    def elevation(self) -> Optional[float]:
        return self._orbit().get("elevation")

    @property
    def roll(self) -> Optional[float]:
        return self._orbit().get("roll")

    @property
    def zoom(self) -> Optional[float]:
        return self._orbit().get("zoom")

    @property
    def dolly(self) -> Optional[float]:
        return self._orbit().get("dolly")

    @property
    def perspective(self) -> Optional[bool]:
        """Whether the view is perspective, if known without a volume."""
        p = self._orbit().get("projection")
        if p is not None:
            return p == "perspective"
        pp = self.parallel_projection
        return None if pp is None else not pp

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Camera) and self._spec == other._spec

    def __hash__(self) -> int:
        return hash(json.dumps(self._spec, sort_keys=True))

    def __repr__(self) -> str:
        cam = self._explicit_camera()
        orbit = ", ".join(f"{k}={v!r}" for k, v in self._orbit().items())
        if cam is None:
            return f"volsplat.Camera({orbit})"
        fields = ", ".join(
            f"{k}={tuple(v) if isinstance(v, list) else v!r}" for k, v in cam.items()
        )
        return f"volsplat.Camera({fields}{', ' + orbit if orbit else ''})"


def as_camera(value: Any) -> Optional[Camera]:
    """A camera argument: a :class:`Camera`, a dict (scene-file or camera-file object), a path
    to a camera file, or ``None``."""
    if value is None or isinstance(value, Camera):
        return value
    if isinstance(value, dict):
        return Camera.from_dict(value)
    try:
        path = fspath(value)
    except InvalidInputError:
        raise InvalidInputError(
            f"camera: expected a volsplat.Camera, a dict or a camera file, got {value!r}"
        ) from None
    return Camera.load(path)
