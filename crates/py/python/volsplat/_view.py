"""The interactive viewer from Python and Jupyter: ``volsplat.view``."""

from __future__ import annotations

import html
import json
from typing import Any, Optional, Sequence, Tuple

from . import _volsplat as _core
from ._errors import InvalidInputError
from ._scene import _VOLUME_KWARGS, Image, Renderer, Scene, _is_path
from ._util import floats, fspath
from ._volsplat import Volume


class Viewer:
    """A viewer running in this Python process (see :func:`view`).

    - ``url``: the page's address with its token (open it in a browser, or let Jupyter show
      the viewer: the object's HTML is the page in an ``<iframe>``).
    - ``scene``: the :class:`Scene` on screen (the browser tab that changed last; the starting
      scene before any did), camera explicit: ``scene.save("s.json")`` gives the file
      ``volsplat render --scene`` renders.
    - ``window``: the grey window of MIP, MinIP and X-ray on screen, or ``None``.
    - :meth:`screenshot`: the full-quality frame of ``scene`` as an :class:`Image`, the picture
      ``volsplat render`` draws (``img.save(path, window=viewer.window)`` writes its file).
    - :meth:`close` stops the server (also on ``with``-block exit and garbage collection).

    The server renders on its own threads and never holds the GIL.
    """

    __slots__ = ("_core", "_volume", "_renderer", "_frame_height")

    def __init__(self, core: Any, volume: Optional[Volume], frame_height: int) -> None:
        self._core = core
        self._volume = volume
        self._renderer: Optional[Renderer] = None
        self._frame_height = frame_height

    @property
    def url(self) -> str:
        return self._core.url

    @property
    def running(self) -> bool:
        return self._core.running

    @property
    def tabs(self) -> int:
        """Browser tabs connected now."""
        return self._core.tabs

    def _state(self) -> Tuple[Scene, Optional[Tuple[float, float]]]:
        request, window = self._core.scene()
        return Scene._from_request(json.loads(request), self._volume), window

    @property
    def scene(self) -> Scene:
        return self._state()[0]

    @property
    def window(self) -> Optional[Tuple[float, float]]:
        return self._state()[1]

    def screenshot(self) -> Image:
        """Renders the scene on screen at full quality: the final frame the page shows, bit for
        bit what ``volsplat render`` draws for :attr:`scene`."""
        scene = self.scene
        if self._renderer is None:
            self._renderer = Renderer(scene)
        else:
            self._renderer.scene = scene
        return self._renderer.render()

    def close(self) -> None:
        """Stops the server: every tab is closed and the port freed."""
        self._core.close()

    def __enter__(self) -> "Viewer":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def __del__(self) -> None:
        core = getattr(self, "_core", None)
        if core is not None:
            core.close()

    def _repr_html_(self) -> str:
        if not self.running:
            return "<p>volsplat viewer (closed)</p>"
        src = html.escape(self.url, quote=True)
        return (
            f'<iframe src="{src}" width="100%" height="{int(self._frame_height)}" '
            'style="border:0" allow="fullscreen" title="volsplat viewer"></iframe>'
        )

    def __repr__(self) -> str:
        state = "running" if self.running else "closed"
        return f"<volsplat.Viewer {state} {self.url if self.running else ''}>".replace(" >", ">")


def view(
    volume: Any = None,
    *,
    host: str = "127.0.0.1",
    port: int = 0,
    allow_remote: bool = False,
    data_dir: Any = None,
    target_fps: float = 60.0,
    target_latency: float = 50.0,
    srgb: Optional[bool] = None,
    bits: Optional[int] = None,
    background: Optional[Sequence[float]] = None,
    window: Optional[Tuple[float, float]] = None,
    frame_height: int = 640,
    **options: Any,
) -> Viewer:
    """Starts the interactive viewer (``volsplat view``) in this process and returns it.

    ``volume`` and ``options`` are those of :func:`render` (a :class:`Volume`, an array with
    ``spacing=…``, a file name, a :class:`Scene`, or ``None`` for the demo; ``camera``,
    ``transfer_function``, ``azimuth``, ``size``, ``mode``, …): they set the starting scene.
    ``host``/``port``/``allow_remote``/``data_dir``/``target_fps``/``target_latency`` are the
    server's (``--host`` …); ``srgb``, ``bits``, ``background`` and ``window`` how frames are
    shown and the screenshot written (``--srgb`` …; default: the scene's own, else 8-bit linear
    PNG on black without a window; they are kept in :attr:`Viewer.scene`, so its scene file
    renders to the screenshot's bytes). Without ``size`` (or a :class:`Scene`,
    which has one) the image follows the page's view, as ``volsplat view`` without ``--size``.
    In Jupyter the returned object displays as the page (``frame_height`` pixels high)::

        v = volsplat.view("head.nrrd", transfer_function="ct-bone")
        v                      # the page, in the notebook
        img = v.screenshot()   # the full-quality frame of what is on screen
        v.scene.save("view.json"); v.close()
    """
    vkw = {k: options.pop(k) for k in _VOLUME_KWARGS if k in options}
    if vkw:
        if volume is None or isinstance(volume, (Volume, Scene)) or _is_path(volume):
            raise InvalidInputError(f"{', '.join(vkw)}: only apply when volume is a numpy array")
        volume = Volume(volume, **vkw)
    fit_view = "size" not in options and not isinstance(volume, Scene)
    scene = volume.replace(**options) if isinstance(volume, Scene) else Scene(volume, **options)
    request, vol = scene._render_args()
    win = None if window is None else tuple(floats(window, 2, "window"))
    core = _core.ViewerCore(
        request,
        vol,
        host=str(host),
        port=int(port),
        allow_remote=bool(allow_remote),
        data_dir=None if data_dir is None else fspath(data_dir),
        target_fps=float(target_fps),
        target_latency=float(target_latency),
        srgb=srgb,
        bits=None if bits is None else int(bits),
        background=None if background is None else floats(background, 3, "background"),
        window=win,
        fit_view=fit_view,
    )
    return Viewer(core, vol, frame_height)
