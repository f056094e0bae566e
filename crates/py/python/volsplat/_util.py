"""Small helpers shared by the modules of the package."""

from __future__ import annotations

import json
import math
import os
import warnings
from typing import Any, Iterable, List, Sequence

from ._errors import InvalidInputError


def floats(value: Any, n: int, name: str) -> List[float]:
    """``value`` as a list of ``n`` finite floats (sequences and numpy arrays accepted)."""
    if hasattr(value, "tolist"):
        value = value.tolist()
    try:
        items = [float(v) for v in value]
    except (TypeError, ValueError) as e:
        raise InvalidInputError(f"{name}: expected {n} numbers, got {value!r}") from e
    if len(items) != n:
        raise InvalidInputError(f"{name}: expected {n} numbers, got {len(items)}: {value!r}")
    if not all(math.isfinite(v) for v in items):
        raise InvalidInputError(f"{name}: every number must be finite, got {items}")
    return items


def points(value: Any, width: int, name: str) -> List[List[float]]:
    """``value`` as a list of points of ``width`` numbers (an ``N×width`` array or nested lists)."""
    if hasattr(value, "tolist"):
        value = value.tolist()
    if isinstance(value, (str, bytes)) or not isinstance(value, Iterable):
        raise InvalidInputError(
            f"{name}: expected a list of points [value, ...] ({width} numbers each), got {value!r}"
        )
    out = []
    for i, p in enumerate(value):
        out.append(floats(p, width, f"{name}[{i}]"))
    if not out:
        raise InvalidInputError(f"{name}: needs at least one point")
    return out


def number(value: Any, name: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError) as e:
        raise InvalidInputError(f"{name}: expected a number, got {value!r}") from e
    if not math.isfinite(v):
        raise InvalidInputError(f"{name}: must be finite, got {v}")
    return v


def fspath(path: Any, name: str = "path") -> str:
    try:
        return os.fspath(path)
    except TypeError as e:
        raise InvalidInputError(
            f"{name}: expected a file name (str or os.PathLike), got {path!r}"
        ) from e


def warn_all(messages: Sequence[str], stacklevel: int = 3) -> None:
    for m in messages:
        warnings.warn(m, stacklevel=stacklevel + 1)


def dumps(value: Any) -> str:
    return json.dumps(value, allow_nan=False)


def size_pair(size: Any) -> List[int]:
    """``size`` (N or (width, height)) as ``[width, height]``."""
    if isinstance(size, int) and not isinstance(size, bool):
        return [size, size]
    try:
        w, h = size
        return [int(w), int(h)]
    except (TypeError, ValueError) as e:
        raise InvalidInputError(f"size: expected N or (width, height), got {size!r}") from e
