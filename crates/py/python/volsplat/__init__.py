"""volsplat: direct volume rendering by splatting, on the CPU, from Python.

numpy in, picture out, with the same engine (and the same bytes) as the ``volsplat`` command::

    import numpy as np
    import volsplat

    vol = volsplat.load("head.nrrd")                 # or volsplat.Volume(array, spacing=...)
    img = volsplat.render(vol, azimuth=30, elevation=15, transfer_function="ct-bone")
    img.save("head.png")                             # what `volsplat render ... -o` writes
    img.rgba                                         # float32 (H, W, 4), premultiplied, linear

    r = volsplat.Renderer(vol, size=256)             # keeps tables between frames
    frames = [r.render(azimuth=a).to_uint8(srgb=True) for a in range(0, 360, 10)]

    v = volsplat.view(vol, transfer_function="ct-bone")  # the interactive viewer (Jupyter
    v.screenshot()                                   # shows the page); the frame on screen

Arrays are (z, y, x) in C order by default (SimpleITK, napari); ``axes="xyz"`` takes nibabel's
order. World space, cameras and transfer functions follow VTK (world units, degrees; LPS for
medical data). See ``Volume``, ``load``, ``Camera``, ``TransferFunction``, ``Scene``,
``Renderer``, ``Image`` and ``render``; errors derive from ``VolsplatError``.
"""

from __future__ import annotations

from . import _volsplat
from ._camera import Camera
from ._errors import (
    CancelledError,
    FileError,
    InvalidInputError,
    RenderError,
    VolsplatError,
)
from ._io import VOLUME_EXTENSIONS, from_nibabel, from_simpleitk, load, phantom
from ._scene import OPTIONS, Image, Renderer, Scene, render
from ._transfer import PRESETS, TransferFunction
from ._view import Viewer, view
from ._volsplat import Volume

__version__: str = _volsplat.__version__

__all__ = [
    "Volume",
    "load",
    "phantom",
    "from_nibabel",
    "from_simpleitk",
    "Camera",
    "TransferFunction",
    "Scene",
    "Renderer",
    "Image",
    "render",
    "view",
    "Viewer",
    "VolsplatError",
    "InvalidInputError",
    "FileError",
    "CancelledError",
    "RenderError",
    "PRESETS",
    "VOLUME_EXTENSIONS",
    "OPTIONS",
    "__version__",
]
