"""Reading volumes (every format of the command line), phantoms, and nibabel / SimpleITK."""

from __future__ import annotations

from typing import Any, Dict, Optional

from . import _volsplat as _core
from ._errors import InvalidInputError
from ._util import dumps, floats, fspath

Volume = _core.Volume

#: File-name endings :func:`load` understands (a folder of ``.tif`` slices too).
VOLUME_EXTENSIONS = tuple(_core.VOLUME_EXTENSIONS)


def _raw_layout(raw: Dict[str, Any]) -> str:
    if not isinstance(raw, dict):
        raise InvalidInputError(f"raw: expected a dict, got {raw!r}")
    known = {"dims", "dtype", "scalar_type", "spacing", "origin", "big_endian", "header_bytes"}
    extra = set(raw) - known
    if extra:
        raise InvalidInputError(f"raw: unknown key(s) {sorted(extra)}; known: {sorted(known)}")
    if "dims" not in raw:
        raise InvalidInputError("raw: dims=(x, y, z) is required (x fastest in the file)")
    dtype = raw.get("dtype", raw.get("scalar_type"))
    if dtype is None:
        raise InvalidInputError("raw: dtype is required (uint8, int8, uint16, int16, float32)")
    big_endian = bool(raw.get("big_endian", False))
    engine_names = {
        "u8",
        "uint8",
        "uchar",
        "i8",
        "int8",
        "char",
        "u16",
        "uint16",
        "ushort",
        "i16",
        "int16",
        "short",
        "f32",
        "float32",
        "float",
    }
    if not (isinstance(dtype, str) and dtype.strip().lower() in engine_names):
        import numpy as np

        try:
            dt = np.dtype(dtype)
        except TypeError as e:
            raise InvalidInputError(f"raw: unknown dtype {dtype!r}") from e
        dtype = dt.name
        if dt.byteorder == ">" or (dt.byteorder == "=" and np.little_endian is False):
            big_endian = True
    try:
        dims = [int(d) for d in raw["dims"]]
    except (TypeError, ValueError) as e:
        raise InvalidInputError(f"raw: dims must be three integers, got {raw['dims']!r}") from e
    if len(dims) != 3 or any(d < 1 for d in dims):
        raise InvalidInputError(f"raw: dims must be three positive integers, got {dims}")
    layout = {
        "dims": dims,
        "scalar_type": dtype,
        "spacing": floats(raw.get("spacing", (1, 1, 1)), 3, "raw spacing"),
        "origin": floats(raw.get("origin", (0, 0, 0)), 3, "raw origin"),
        "big_endian": big_endian,
        "header_bytes": int(raw.get("header_bytes", 0)),
    }
    return dumps(layout)


def load(
    path: Any,
    *,
    frame: int = 0,
    array: Optional[str] = None,
    series: Optional[str] = None,
    raw: Optional[Dict[str, Any]] = None,
    axes: str = "zyx",
    max_voxels: Optional[int] = None,
    max_header_bytes: Optional[int] = None,
    max_json_bytes: Optional[int] = None,
    max_xml_bytes: Optional[int] = None,
    level: int = 0,
    channel: int = 0,
    timepoint: int = 0,
) -> Volume:
    """Reads a volume file with the command line's readers, by file name: NRRD (``.nrrd``,
    ``.nhdr``), MetaImage (``.mha``, ``.mhd``), NIfTI-1/2 (``.nii``, ``.nii.gz``,
    ``.hdr``/``.img``), VTK image data (``.vti``), TIFF stacks (``.tif``/``.tiff``, or a folder
    of slices), DICOM series (a folder, or one file of the series), OME-Zarr stores (a
    ``.zarr`` folder, OME-Zarr 0.4 and 0.5), or headerless raw with ``raw={...}``.

    Medical volumes are put in the LPS patient frame (NIfTI and RAS NRRD converted, as the
    command line does), so a scan renders alike whichever format it came in.

    Reader options (the command line's flags):

    - ``frame``: which volume of a 4-D file (``--frame``), from 0.
    - ``array``: which point-data array of a ``.vti`` file (``--array``).
    - ``series``: which DICOM series of a folder holding several (``--series``): its
      SeriesInstanceUID or SeriesNumber.
    - ``level``: which resolution level of an OME-Zarr store (``--zarr-level``), 0 (full
      resolution) to the coarsest; ``channel`` and ``timepoint`` (``--channel``,
      ``--timepoint``): which channel and time point of a multi-dimensional OME-Zarr image.
      Other formats refuse values other than 0.
    - ``raw``: layout of a headerless raw file: ``{"dims": (x, y, z), "dtype": "uint16",
      "spacing": (x, y, z), "origin": (x, y, z), "big_endian": False, "header_bytes": 0}``
      (``--raw-dims``, ``--raw-type``, ``--raw-spacing``, ``--raw-big-endian``,
      ``--raw-skip``); ``dims``, ``dtype`` and ``spacing`` are in x, y, z order, x fastest.
    - ``max_voxels``, ``max_header_bytes``, ``max_json_bytes``, ``max_xml_bytes``: limits
      against untrusted files, checked before anything is allocated.
    - ``axes``: the axis order of the result's ``.array`` (``"zyx"``, default, or ``"xyz"``).

    The samples keep the file's type (uint8, int8, uint16, int16, float32; other types become
    float32 as on the command line). The file is read with the GIL released.
    """
    return _core.load(
        fspath(path),
        frame=int(frame),
        array=array,
        series=series,
        raw_json=None if raw is None else _raw_layout(raw),
        axes=axes,
        max_voxels=max_voxels,
        max_header_bytes=max_header_bytes,
        max_json_bytes=max_json_bytes,
        max_xml_bytes=max_xml_bytes,
        level=int(level),
        channel=int(channel),
        timepoint=int(timepoint),
    )


def phantom(name: Optional[str] = None, grid: Any = None, *, axes: str = "zyx") -> Volume:
    """A built-in phantom, as ``volsplat render --phantom NAME --phantom-size GRID``:
    ``head`` (CT-like, Hounsfield units, int16), ``shepp-logan``, ``blobs``,
    ``marschner-lobb``, ``checkerboard``, ``terrain``, ``filaments``, … (an unknown name lists
    them all). ``None`` is the demo phantom the command line renders without an input. ``grid``
    is ``N`` or ``(X, Y, Z)`` voxels (x, y, z order; the checkerboard takes
    ``(X, Y[, SQUARE])``).

    A phantom renders exactly as on the command line, its own transfer function included."""
    return _core.phantom(name, grid, axes=axes)


def from_nibabel(img: Any, *, frame: int = 0, dtype: Optional[str] = None) -> Volume:
    """A volume from a nibabel image (``nibabel.load("brain.nii.gz")``) with the geometry the
    command line reads from the same file: the image's affine (sform, else qform, else
    nibabel's default), converted from RAS to volsplat's LPS world. The data come from
    ``img.dataobj`` (scaled by ``scl_slope``/``scl_inter`` as nibabel does); for 4-D images
    ``frame`` picks the volume. The result's ``.array`` is in nibabel's (x, y, z) order."""
    import numpy as np

    data = np.asanyarray(img.dataobj)
    if data.ndim > 3:
        data = data.reshape(data.shape[:3] + (-1,))
        if not 0 <= frame < data.shape[3]:
            raise InvalidInputError(
                f"frame {frame} requested, but the image holds {data.shape[3]} volumes"
            )
        data = data[..., frame]
    elif frame != 0:
        raise InvalidInputError(f"frame {frame} requested, but the image holds 1 volume")
    while data.ndim < 3:
        data = data[..., np.newaxis]
    return Volume(data, affine=np.asarray(img.affine), axes="xyz", space="RAS", dtype=dtype)


def from_simpleitk(img: Any, *, dtype: Optional[str] = None) -> Volume:
    """A volume from a 3-D SimpleITK image, with its spacing, origin and direction (ITK's
    world is LPS, as volsplat's). The result's ``.array`` is (z, y, x), as
    ``SimpleITK.GetArrayFromImage``."""
    import numpy as np
    import SimpleITK as sitk  # noqa: N813 (the package's own name)

    if img.GetDimension() != 3:
        raise InvalidInputError(f"expected a 3-D image, got {img.GetDimension()}-D")
    arr = sitk.GetArrayViewFromImage(img)
    d = np.asarray(img.GetDirection(), dtype=float).reshape(3, 3)
    return Volume(
        arr,
        spacing=tuple(img.GetSpacing())[::-1],
        origin=img.GetOrigin(),
        direction=d[:, ::-1],
        dtype=dtype,
    )
