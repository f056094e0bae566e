"""Transfer functions: VTK's volume property (points in data units), presets, and files."""

from __future__ import annotations

import json
import os
from typing import Any, Dict, List, Optional, Sequence, Tuple

from . import _volsplat as _core
from ._errors import InvalidInputError
from ._util import dumps, fspath, number, points, warn_all

PRESETS: Tuple[str, ...] = tuple(_core.PRESETS)


class TransferFunction:
    """How data values become colour and opacity, as VTK's ``vtkVolumeProperty``.

    Values are in the data's own units (Hounsfield units for CT). Build one from points::

        TransferFunction(
            color=[[-1024, 0, 0, 0], [400, 1.0, 0.9, 0.75], [3071, 1, 1, 1]],   # [value, r, g, b]
            opacity=[[-1024, 0.0], [400, 0.3], [3071, 0.9]],                    # [value, alpha]
            gradient_opacity=[[0, 1.0], [500, 1.0]],     # optional: [|gradient|, factor]
            unit_distance=1.0, shade=True, ambient=0.1, diffuse=0.7, specular=0.2,
            specular_power=10.0)

    (``opacity`` is VTK's scalar opacity, per ``unit_distance`` world units of path; points in
    non-decreasing order of value, two equal values making a step), from a preset with
    :meth:`preset` (3D Slicer's ``CT-Bone``, ``MR-Default``, … and volsplat's ``ct-skin`` and
    ``ramp``: ``volsplat.PRESETS``), or from a file with
    :meth:`load`: volsplat's transfer-function JSON (the command line's ``--tf``) or a
    ParaView/VTK colour-map preset export (``RGBPoints``, ``Points``). ``TransferFunction.auto()``
    (the default everywhere) lets the renderer choose from the data and mode, as the command
    line does. Transfer functions are immutable.
    """

    __slots__ = ("_spec",)

    def __init__(
        self,
        color: Optional[Sequence[Sequence[float]]] = None,
        opacity: Optional[Sequence[Sequence[float]]] = None,
        *,
        gradient_opacity: Optional[Sequence[Sequence[float]]] = None,
        unit_distance: float = 1.0,
        shade: bool = False,
        ambient: float = 0.0,
        diffuse: float = 0.7,
        specular: float = 0.2,
        specular_power: float = 10.0,
    ) -> None:
        if opacity is None:
            raise InvalidInputError(
                "opacity: a transfer function needs scalar-opacity points [[value, alpha], ...] "
                "(or use TransferFunction.preset(name) / TransferFunction.auto())"
            )
        op = points(opacity, 2, "opacity")
        col = points(color, 4, "color") if color is not None else [[op[0][0], 1.0, 1.0, 1.0]]
        f: Dict[str, Any] = {
            "color": col,
            "scalar_opacity": op,
            "scalar_opacity_unit_distance": number(unit_distance, "unit_distance"),
            "shade": bool(shade),
            "ambient": number(ambient, "ambient"),
            "diffuse": number(diffuse, "diffuse"),
            "specular": number(specular, "specular"),
            "specular_power": number(specular_power, "specular_power"),
        }
        if gradient_opacity is not None:
            f["gradient_opacity"] = points(gradient_opacity, 2, "gradient_opacity")
        self._spec: Any = {"function": json.loads(_core.check_transfer_function(dumps(f)))}

    @classmethod
    def _from_spec(cls, spec: Any) -> "TransferFunction":
        t = cls.__new__(cls)
        if spec == "auto":
            t._spec = "auto"
        elif isinstance(spec, dict) and set(spec) == {"preset"}:
            name = spec["preset"]
            if not isinstance(name, str):
                raise InvalidInputError(f"preset: expected a name, got {name!r}")
            _core.preset_transfer_function(name, 0.0, 1.0)  # unknown names list the known ones
            t._spec = {"preset": name}
        elif isinstance(spec, dict) and set(spec) == {"function"}:
            t._spec = {
                "function": json.loads(_core.check_transfer_function(dumps(spec["function"])))
            }
        else:
            raise InvalidInputError(
                'transfer function: expected "auto", {"preset": name} or '
                f'{{"function": {{...}}}}, got {spec!r}'
            )
        return t

    @classmethod
    def auto(cls) -> "TransferFunction":
        """Chosen by the renderer from the data and mode, as the command line does without
        ``--tf``/``--preset`` (a built-in scene's own function; for MIP and MinIP an opaque grey
        window over the data range; ``ct-skin`` for the demo head; otherwise a function fitted
        to the volume's histogram)."""
        return cls._from_spec("auto")

    @classmethod
    def preset(
        cls, name: str, data_range: Optional[Tuple[float, float]] = None
    ) -> "TransferFunction":
        """A built-in preset, as ``--preset NAME``: 3D Slicer's volume-rendering presets
        (``CT-Bone``, ``CT-Soft-Tissue``, ``MR-Default``, …, in absolute data units) and
        volsplat's ``ct-skin`` (Hounsfield units) and ``ramp`` (over the data range); names are
        case-insensitive (``volsplat.PRESETS`` lists them). Without ``data_range`` a preset is
        resolved against each volume's range at render time, as on the command line; with it,
        now."""
        if data_range is None:
            return cls._from_spec({"preset": name})
        lo, hi = (number(v, "data_range") for v in data_range)
        return cls._from_spec(
            {"function": json.loads(_core.preset_transfer_function(name, lo, hi))}
        )

    @classmethod
    def ramp(cls, lo: float, hi: float, max_opacity: float = 1.0) -> "TransferFunction":
        """A grey ramp over ``[lo, hi]``: black → white, opacity 0 → ``max_opacity``, unshaded."""
        lo, hi, a = number(lo, "lo"), number(hi, "hi"), number(max_opacity, "max_opacity")
        if not hi > lo:
            raise InvalidInputError(f"ramp: need lo < hi, got ({lo}, {hi})")
        return cls(color=[[lo, 0, 0, 0], [hi, 1, 1, 1]], opacity=[[lo, 0.0], [hi, a]])

    @classmethod
    def load(
        cls,
        path: Any,
        *,
        name: Optional[str] = None,
        data_range: Optional[Tuple[float, float]] = None,
    ) -> "TransferFunction":
        """Reads a transfer function file.

        Both formats are read by the command line's reader (``--tf`` takes either, with the
        same result):

        - volsplat's format (``color``, ``scalar_opacity``, … as in the README): unknown fields
          draw a warning.
        - A ParaView / VTK colour-map preset as exported by ParaView's "Choose Preset → Export"
          (a JSON list of objects, or one object, with ``RGBPoints`` = [x, r, g, b, …] and
          optionally ``Points`` = [x, opacity, midpoint, sharpness, …]); ``name`` picks one of
          several presets (the command line takes the first). Midpoint and sharpness other than
          0.5 and 0 are approximated by straight lines (a warning says so); without ``Points``
          the opacity ramps 0 → 1 over the colour range, as ParaView's default.

        ``data_range=(lo, hi)`` rescales the file's points to that range (ParaView's "rescale
        to data range"), useful for presets defined on [0, 1] or [-1, 1].
        """
        ftext, warnings_ = _core.load_transfer_function(fspath(path), name)
        warn_all(warnings_)
        f = json.loads(ftext)
        if data_range is not None:
            f = _rescale(f, data_range)
        return cls._from_spec({"function": f})

    def save(self, path: Any) -> None:
        """Writes volsplat's transfer-function file (the command line's ``--tf``). A preset
        must first be resolved with ``TransferFunction.preset(name, data_range=...)``, and
        ``auto()`` cannot be saved (save ``Image.transfer_function``, the one a render used)."""
        f = self.function
        if f is None:
            raise InvalidInputError(
                f"{self!r} depends on the data; save image.transfer_function (the one a render "
                "used) or a preset resolved with data_range="
            )
        _core.save_transfer_function(fspath(path), dumps(f))

    @classmethod
    def from_dict(cls, d: Any) -> "TransferFunction":
        """From a scene file's ``transfer_function`` value (``"auto"``, ``{"preset": name}``,
        ``{"function": {...}}``) or a transfer-function-file object."""
        if d == "auto" or (
            isinstance(d, dict) and (set(d) == {"preset"} or set(d) == {"function"})
        ):
            return cls._from_spec(d)
        if isinstance(d, dict):
            return cls._from_spec({"function": d})
        raise InvalidInputError(f'transfer function: expected a dict or "auto", got {d!r}')

    def to_dict(self) -> Any:
        """The scene file's ``transfer_function`` value."""
        return json.loads(json.dumps(self._spec))

    # -- fields ----------------------------------------------------------------------------

    @property
    def kind(self) -> str:
        """``"auto"``, ``"preset"`` or ``"function"``."""
        if self._spec == "auto":
            return "auto"
        return "preset" if "preset" in self._spec else "function"

    @property
    def preset_name(self) -> Optional[str]:
        return self._spec["preset"] if self.kind == "preset" else None

    @property
    def function(self) -> Optional[Dict[str, Any]]:
        """The transfer-function-file object (``None`` for ``auto`` and unresolved presets)."""
        return json.loads(json.dumps(self._spec["function"])) if self.kind == "function" else None

    def _field(self, name: str) -> Any:
        f = self.function
        return None if f is None else f.get(name)

    @property
    def color(self) -> Optional[List[List[float]]]:
        """Colour points ``[value, r, g, b]``."""
        return self._field("color")

    @property
    def opacity(self) -> Optional[List[List[float]]]:
        """Scalar-opacity points ``[value, alpha]`` (per ``unit_distance``)."""
        return self._field("scalar_opacity")

    @property
    def gradient_opacity(self) -> Optional[List[List[float]]]:
        return self._field("gradient_opacity")

    @property
    def unit_distance(self) -> Optional[float]:
        return self._field("scalar_opacity_unit_distance")

    @property
    def shade(self) -> Optional[bool]:
        return self._field("shade")

    def __eq__(self, other: object) -> bool:
        return isinstance(other, TransferFunction) and self._spec == other._spec

    def __hash__(self) -> int:
        return hash(json.dumps(self._spec, sort_keys=True))

    def __repr__(self) -> str:
        if self.kind == "auto":
            return "volsplat.TransferFunction.auto()"
        if self.kind == "preset":
            return f"volsplat.TransferFunction.preset({self.preset_name!r})"
        f = self._spec["function"]
        return (
            f"volsplat.TransferFunction(color=<{len(f['color'])} points>, "
            f"opacity=<{len(f['scalar_opacity'])} points>, shade={f.get('shade', False)})"
        )


def _rescale(f: Dict[str, Any], data_range: Any) -> Dict[str, Any]:
    lo, hi = (number(v, "data_range") for v in data_range)
    if not hi > lo:
        raise InvalidInputError(f"data_range: need lo < hi, got ({lo}, {hi})")
    xs = [p[0] for p in f["color"]] + [p[0] for p in f["scalar_opacity"]]
    a, b = min(xs), max(xs)
    scale = (hi - lo) / (b - a) if b > a else 0.0

    def m(x: float) -> float:
        return lo + (x - a) * scale if b > a else lo

    g = dict(f)
    g["color"] = [[m(p[0])] + list(p[1:]) for p in f["color"]]
    g["scalar_opacity"] = [[m(p[0]), p[1]] for p in f["scalar_opacity"]]
    return json.loads(_core.check_transfer_function(dumps(g)))


def _looks_like_a_file(s: str) -> bool:
    return s.lower().endswith(".json") or os.sep in s or "/" in s or os.path.exists(s)


def as_transfer_function(value: Any) -> Optional[TransferFunction]:
    """A transfer-function argument: a :class:`TransferFunction`, a preset name, ``"auto"``, a
    dict, a path to a file, or ``None`` (auto)."""
    if value is None or isinstance(value, TransferFunction):
        return value
    if isinstance(value, str) and not _looks_like_a_file(value):
        return TransferFunction.auto() if value == "auto" else TransferFunction.preset(value)
    if isinstance(value, dict):
        return TransferFunction.from_dict(value)
    try:
        path = fspath(value)
    except InvalidInputError:
        raise InvalidInputError(
            "transfer_function: expected a volsplat.TransferFunction, a preset name "
            f'({", ".join(PRESETS)}), "auto", a dict or a file, got {value!r}'
        ) from None
    return TransferFunction.load(path)
