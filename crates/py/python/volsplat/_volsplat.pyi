"""Type stubs of the compiled module ``volsplat._volsplat`` (pyo3).

The public names are re-exported by ``volsplat``: :class:`Volume` here; ``RendererCore`` and
``Output`` are wrapped by ``volsplat.Renderer`` and ``volsplat.Image``.
"""

from os import PathLike
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

_Path = Union[str, "PathLike[str]"]
_Floats = Union[Sequence[float], npt.ArrayLike]

__version__: str
PRESETS: List[str]
VOLUME_EXTENSIONS: List[str]

class Volume:
    """A scalar volume: samples on a rectilinear grid with spacing, origin and orientation.

    ``Volume(array, spacing=None, origin=None, direction=None, *, axes=None, affine=None,
    space=None, dtype=None)`` builds one from a 3-D numpy array (or anything
    ``numpy.asarray`` accepts):

    - ``axes``: ``"zyx"`` (C order as SimpleITK's ``GetArrayFromImage``, napari, tifffile; the
      default without ``affine``) or ``"xyz"`` (nibabel's order; the default with ``affine``).
    - ``spacing``: voxel size in world units, one number or three **in the array's axis order**
      (for ``"zyx"``: ``(dz, dy, dx)``; default 1).
    - ``origin``: world position (x, y, z) of the centre of element ``[0, 0, 0]`` (default 0).
    - ``direction``: 3×3 matrix whose **columns** are the world directions of the array's axes,
      in the array's axis order (default: the identity for the grid axes).
    - ``affine``: instead of the three above, a 4×4 (or 3×4) matrix mapping array indices (in
      array order) to world coordinates (no shear), with nibabel's meaning: ``Volume(
      img.get_fdata(), affine=img.affine)`` gives the geometry ``volsplat.load`` reads from the
      same NIfTI file (the affine maps to RAS).
    - ``space``: the world frame of ``origin``/``direction``/``affine``: ``"RAS"`` (NIfTI,
      nibabel; the default for ``affine``) or ``"LPS"`` (DICOM, ITK, SimpleITK, volsplat's own
      world; the default for ``origin``/``direction``). RAS is converted to LPS (x and y
      negated) as the NIfTI reader does; ``.affine`` gives the RAS map back and ``.affine_lps``
      the LPS one.
    - ``dtype``: convert to ``"uint8"``, ``"int8"``, ``"uint16"``, ``"int16"`` or
      ``"float32"`` (an integer type must hold every value exactly).

    Samples: ``uint8``, ``int8``, ``uint16``, ``int16`` and ``float32`` are kept as they are;
    ``bool`` becomes ``uint8`` and other real types (float64, int32, …) ``float32``, one numpy
    ``astype`` pass. The engine's volume owns its samples, so they are copied once: one
    ``memcpy`` when the array is contiguous in the declared order (C-order ``"zyx"``, or
    Fortran-order ``"xyz"`` as nibabel gives it), a strided gather otherwise (views, slices,
    transposes; about the cost of ``np.ascontiguousarray``). ``.array`` is then a read-only,
    zero-copy view of the engine's samples. Float samples that are NaN (a masked background)
    become the lowest finite value, and ±inf the lowest or highest, as every reader does (a
    ``UserWarning`` and ``.notes`` say how many); an array with no finite value is an error.
    Raises :class:`volsplat.InvalidInputError` (a ``ValueError``) for bad
    shapes, dtypes and geometry, and ``MemoryError`` when the copy cannot be allocated (the
    interpreter keeps running).
    """

    def __init__(
        self,
        array: npt.ArrayLike,
        spacing: Optional[Union[float, _Floats]] = None,
        origin: Optional[_Floats] = None,
        direction: Optional[npt.ArrayLike] = None,
        *,
        axes: Optional[str] = None,
        affine: Optional[npt.ArrayLike] = None,
        space: Optional[str] = None,
        dtype: Optional[str] = None,
    ) -> None: ...
    @property
    def array(self) -> np.ndarray:
        """The samples as a read-only numpy array in ``.axes`` order (a zero-copy view)."""
    def __array__(self, dtype: Any = None, copy: Optional[bool] = None) -> np.ndarray: ...
    @property
    def axes(self) -> str:
        """``"zyx"`` or ``"xyz"``: the order of ``array``, ``shape``, ``spacing``, ``direction``."""
    def with_axes(self, axes: str) -> "Volume":
        """The same samples (no copy) seen in another axis order."""
    @property
    def shape(self) -> Tuple[int, int, int]: ...
    @property
    def dtype(self) -> str:
        """numpy name of the sample type."""
    @property
    def spacing(self) -> Tuple[float, float, float]:
        """Voxel spacing (world units) in ``.axes`` order."""
    @property
    def origin(self) -> Tuple[float, float, float]:
        """World position (x, y, z) of the centre of element ``[0, 0, 0]``."""
    @property
    def direction(self) -> np.ndarray:
        """3×3; columns are the world directions of the array's axes in ``.axes`` order."""
    @property
    def affine(self) -> np.ndarray:
        """4×4 map from array indices (``.axes`` order) to RAS world coordinates, as nibabel's
        ``img.affine`` (what ``Volume(array, affine=...)`` takes without ``space=``)."""
    @property
    def affine_lps(self) -> np.ndarray:
        """4×4 map from array indices (``.axes`` order) to volsplat's LPS world coordinates."""
    @property
    def value_range(self) -> Tuple[float, float]: ...
    @property
    def size(self) -> int: ...
    @property
    def nbytes(self) -> int: ...
    @property
    def path(self) -> Optional[str]:
        """The file the volume was read from, if any."""
    @property
    def notes(self) -> List[str]:
        """The reader's notes (conversions, where the geometry came from, frames)."""
    def info(self) -> Dict[str, Any]:
        """Source, format, dtype, shape, dims (x, y, z), spacing, origin, direction, bounds,
        value range, frames, arrays and notes."""
    def save(self, path: _Path, *, gzip: bool = False) -> None:
        """Writes NRRD (``.nrrd``) that :func:`volsplat.load` and the command line read back."""
    def _source_json(self) -> Optional[str]: ...
    def _same_data(self, other: "Volume") -> bool: ...

class RendererCore:
    def __init__(self, *, max_voxels: Optional[int] = None) -> None: ...
    def render(
        self,
        request_json: str,
        volume: Optional[Volume] = None,
        progress: Optional[Callable[[float, str], Optional[bool]]] = None,
        poll_interval: float = 0.05,
    ) -> "Output": ...
    def camera(self, request_json: str, volume: Optional[Volume] = None) -> str: ...
    def transfer_function(self, request_json: str, volume: Optional[Volume] = None) -> str: ...
    def clear(self) -> None: ...

class ViewerCore:
    def __init__(
        self,
        request_json: str,
        volume: Optional[Volume] = None,
        *,
        host: str = "127.0.0.1",
        port: int = 0,
        allow_remote: bool = False,
        data_dir: Optional[str] = None,
        target_fps: float = 60.0,
        target_latency: float = 50.0,
        srgb: Optional[bool] = None,
        bits: Optional[int] = None,
        background: Optional[Sequence[float]] = None,
        window: Optional[Tuple[float, float]] = None,
        fit_view: bool = False,
    ) -> None: ...
    @property
    def url(self) -> str: ...
    @property
    def running(self) -> bool: ...
    @property
    def tabs(self) -> int: ...
    def scene(self) -> Tuple[str, Optional[Tuple[float, float]]]: ...
    def close(self) -> None: ...

class Output:
    @property
    def rgba(self) -> np.ndarray: ...
    @property
    def values(self) -> Optional[np.ndarray]: ...
    @property
    def width(self) -> int: ...
    @property
    def height(self) -> int: ...
    @property
    def mode(self) -> str: ...
    @property
    def stats(self) -> Dict[str, Any]: ...
    @property
    def camera_json(self) -> str: ...
    @property
    def transfer_function_json(self) -> str: ...
    @property
    def scene_json(self) -> str: ...
    @property
    def request_json(self) -> str: ...
    @property
    def warnings(self) -> List[str]: ...
    @property
    def notes(self) -> List[str]: ...
    @property
    def default_srgb(self) -> bool: ...
    def save(
        self,
        path: _Path,
        *,
        srgb: Optional[bool] = None,
        bits: int = 8,
        background: Sequence[float] = ...,
        window: Optional[Tuple[float, float]] = None,
    ) -> None: ...
    def png_bytes(
        self,
        *,
        srgb: Optional[bool] = None,
        bits: int = 8,
        background: Sequence[float] = ...,
        window: Optional[Tuple[float, float]] = None,
    ) -> bytes: ...
    def to_uint8(
        self,
        *,
        srgb: bool = False,
        background: Optional[Sequence[float]] = None,
        premultiplied: bool = True,
    ) -> np.ndarray: ...

def load(
    path: _Path,
    *,
    frame: int = 0,
    array: Optional[str] = None,
    series: Optional[str] = None,
    raw_json: Optional[str] = None,
    axes: str = "zyx",
    max_voxels: Optional[int] = None,
    max_header_bytes: Optional[int] = None,
    max_json_bytes: Optional[int] = None,
    max_xml_bytes: Optional[int] = None,
    level: int = 0,
    channel: int = 0,
    timepoint: int = 0,
) -> Volume: ...
def phantom(name: Optional[str] = None, grid: Any = None, *, axes: str = "zyx") -> Volume: ...
def load_camera(path: _Path) -> Tuple[str, List[str]]: ...
def save_camera(path: _Path, camera_json: str) -> None: ...
def check_camera_spec(spec_json: str) -> str: ...
def load_transfer_function(path: _Path, name: Optional[str] = None) -> Tuple[str, List[str]]: ...
def anatomical_view(name: str) -> str: ...
def save_transfer_function(path: _Path, tf_json: str) -> None: ...
def check_transfer_function(tf_json: str) -> str: ...
def preset_transfer_function(name: str, lo: float, hi: float) -> str: ...
def load_scene(path: _Path) -> Tuple[str, List[str]]: ...
def save_scene(path: _Path, request_json: str) -> None: ...
def check_request(request_json: str) -> str: ...
