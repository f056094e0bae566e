"""The exceptions volsplat raises.

Every error volsplat raises derives from :class:`VolsplatError`, and also from the built-in
class it belongs to, so ``except ValueError`` and ``except OSError`` work as usual:

- :class:`InvalidInputError` (``ValueError``): bad arguments or arrays (shape, dtype, no finite value),
  request fields out of range, invalid camera or transfer-function values, malformed or
  unsupported files. The message names the argument, field or header entry and the value.
- :class:`FileError` (``OSError``): the operating system refused to open, read or write a file
  (``errno`` is set when it gave one), or a path is not a regular file.
- :class:`CancelledError`: the ``progress`` callback returned ``False``.
- :class:`RenderError` (``RuntimeError``): an internal error (non-finite pixels, a thread pool
  that could not start, a crash inside the renderer). Please report it.

Ctrl-C during a render raises Python's own :class:`KeyboardInterrupt`.
"""

from __future__ import annotations

__all__ = [
    "VolsplatError",
    "InvalidInputError",
    "FileError",
    "CancelledError",
    "RenderError",
]


class VolsplatError(Exception):
    """Base class of every exception volsplat raises."""


class InvalidInputError(VolsplatError, ValueError):
    """An argument, array, request field or file content is invalid."""


class FileError(VolsplatError, OSError):
    """The operating system refused to open, read or write a file."""


class CancelledError(VolsplatError):
    """The render was cancelled by its progress callback."""


class RenderError(VolsplatError, RuntimeError):
    """An internal error of the renderer (please report it)."""
