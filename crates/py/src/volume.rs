//! `volsplat.Volume`: a scalar volume on a grid, built from a numpy array or read from a file,
//! and its numpy view.
//!
//! Axis order. numpy arrays are `(z, y, x)` in C order by default (SimpleITK's
//! `GetArrayFromImage`, napari, tifffile), which is exactly the engine's layout (x fastest), so
//! such an array is copied with one `memcpy`. `axes="xyz"` takes nibabel's `(x, y, z)` order; a
//! Fortran-ordered `(x, y, z)` array (what nibabel usually returns) is the same memory layout
//! and is copied with one `memcpy` too. Per-axis values (spacing, the columns of `direction`
//! and of `affine`) are given in the array's axis order; world coordinates (`origin`, the rows
//! of `direction` and `affine`) are world x, y, z. volsplat's world is LPS (docs/design.md §3,
//! decision 0008). An `affine` follows nibabel: it maps to RAS unless `space="LPS"` is given
//! (converted to LPS as the NIfTI reader does), and its array is `(x, y, z)` unless `axes=` says
//! otherwise; `origin`/`direction` follow ITK: LPS unless `space="RAS"`.
//!
//! Copies. The engine's volume owns its samples (`Vec<T>`), so a numpy array is copied once into
//! it: a `memcpy` when the array is contiguous in the declared order and of a native type
//! (`uint8`, `int8`, `uint16`, `int16`, `float32`), a strided gather otherwise, and one numpy
//! `astype` first for other types (`bool` → `uint8`; other real types → `float32`). `.array`
//! is then a zero-copy, read-only view of the engine's samples, kept alive by the volume.

use crate::errors::{self, invalid};
use numpy::ndarray::ArrayView3;
use numpy::prelude::*;
use numpy::{Element, PyArray3, PyUntypedArray};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use std::path::PathBuf;
use std::sync::Arc;
use volsplat::core::glam::{DMat3, DVec3};
use volsplat::core::{AnyVolume, Grid, Scalar, ScalarType, Volume as CoreVolume};
use volsplat::{PhantomKind, RawLayout, VolumeSource};

/// The order of a numpy array's axes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Axes {
    /// `(z, y, x)`, x fastest in C order: SimpleITK, napari, tifffile.
    Zyx,
    /// `(x, y, z)`: nibabel.
    Xyz,
}

impl Axes {
    /// Parses `"zyx"` or `"xyz"` (any case).
    pub fn parse(s: &str) -> PyResult<Self> {
        match s.to_ascii_lowercase().as_str() {
            "zyx" => Ok(Axes::Zyx),
            "xyz" => Ok(Axes::Xyz),
            _ => Err(invalid(format!(
                "axes={s:?}: expected \"zyx\" (SimpleITK, napari: the default) or \"xyz\" \
                 (nibabel)"
            ))),
        }
    }

    /// The name, `"zyx"` or `"xyz"`.
    pub fn name(self) -> &'static str {
        match self {
            Axes::Zyx => "zyx",
            Axes::Xyz => "xyz",
        }
    }

    /// The grid axis (0 = x/i, 1 = y/j, 2 = z/k) of array axis `a`.
    fn grid_axis(self, a: usize) -> usize {
        match self {
            Axes::Zyx => 2 - a,
            Axes::Xyz => a,
        }
    }
}

/// numpy's name of a sample type.
pub fn numpy_name(t: ScalarType) -> &'static str {
    match t {
        ScalarType::U8 => "uint8",
        ScalarType::I8 => "int8",
        ScalarType::U16 => "uint16",
        ScalarType::I16 => "int16",
        ScalarType::F32 => "float32",
    }
}

/// A scalar volume: samples on a rectilinear grid with spacing, origin and orientation.
///
/// ``Volume(array, spacing=None, origin=None, direction=None, *, axes=None, affine=None,
/// space=None, dtype=None)`` builds one from a 3-D numpy array (or anything
/// ``numpy.asarray`` accepts):
///
/// - ``axes``: ``"zyx"`` (C order as SimpleITK's ``GetArrayFromImage``, napari, tifffile; the
///   default without ``affine``) or ``"xyz"`` (nibabel's order; the default with ``affine``).
/// - ``spacing``: voxel size in world units, one number or three **in the array's axis order**
///   (for ``"zyx"``: ``(dz, dy, dx)``; default 1).
/// - ``origin``: world position (x, y, z) of the centre of element ``[0, 0, 0]`` (default 0).
/// - ``direction``: 3×3 matrix whose **columns** are the world directions of the array's axes,
///   in the array's axis order (default: the identity for the grid axes).
/// - ``affine``: instead of the three above, a 4×4 (or 3×4) matrix mapping array indices (in
///   array order) to world coordinates (no shear), with nibabel's meaning: ``Volume(
///   img.get_fdata(), affine=img.affine)`` gives the geometry ``volsplat.load`` reads from the
///   same NIfTI file (the affine maps to RAS).
/// - ``space``: the world frame of ``origin``/``direction``/``affine``: ``"RAS"`` (NIfTI,
///   nibabel; the default for ``affine``) or ``"LPS"`` (DICOM, ITK, SimpleITK, volsplat's own
///   world; the default for ``origin``/``direction``). RAS is converted to LPS (x and y
///   negated) as the NIfTI reader does; ``.affine`` gives the RAS map back and ``.affine_lps``
///   the LPS one.
/// - ``dtype``: convert to ``"uint8"``, ``"int8"``, ``"uint16"``, ``"int16"`` or
///   ``"float32"`` (an integer type must hold every value exactly).
///
/// Samples: ``uint8``, ``int8``, ``uint16``, ``int16`` and ``float32`` are kept as they are;
/// ``bool`` becomes ``uint8`` and other real types (float64, int32, …) ``float32``, one numpy
/// ``astype`` pass. The engine's volume owns its samples, so they are copied once: one
/// ``memcpy`` when the array is contiguous in the declared order (C-order ``"zyx"``, or
/// Fortran-order ``"xyz"`` as nibabel gives it), a strided gather otherwise (views, slices,
/// transposes; about the cost of ``np.ascontiguousarray``). ``.array`` is then a read-only,
/// zero-copy view of the engine's samples. Float samples that are NaN (a masked background)
/// become the lowest finite value, and ±inf the lowest or highest, as every reader does
/// (a ``UserWarning`` and ``.notes`` say how many); an array with no finite value is an
/// error. Raises :class:`volsplat.InvalidInputError` (a ``ValueError``) for bad
/// shapes, dtypes and geometry, and ``MemoryError`` when the copy cannot be allocated (the
/// interpreter keeps running).
#[pyclass(frozen, module = "volsplat")]
pub struct Volume {
    /// The samples and grid, shared with renders (never copied again).
    pub data: Arc<AnyVolume>,
    /// Where it came from, as a scene file names it (`None` for arrays).
    pub source: Option<VolumeSource>,
    axes: Axes,
    format: String,
    frames: usize,
    frame: usize,
    arrays: Vec<String>,
    notes: Vec<String>,
}

impl Volume {
    fn from_any(data: AnyVolume, source: Option<VolumeSource>, axes: Axes, format: &str) -> Self {
        Volume {
            data: Arc::new(data),
            source,
            axes,
            format: format.into(),
            frames: 1,
            frame: 0,
            arrays: Vec::new(),
            notes: Vec::new(),
        }
    }

    /// Spacing, in the array's axis order.
    fn spacing_array_order(&self) -> [f64; 3] {
        let s = self.data.grid().spacing;
        [0, 1, 2].map(|a| s[self.axes.grid_axis(a)])
    }

    /// Direction matrix whose columns are the world directions of the array's axes, in array
    /// order (rows: world x, y, z).
    fn direction_array_order(&self) -> [[f64; 3]; 3] {
        let d = self.data.grid().direction;
        let cols = [0, 1, 2].map(|a| d.col(self.axes.grid_axis(a)));
        [0, 1, 2].map(|r| [cols[0][r], cols[1][r], cols[2][r]])
    }

    fn shape(&self) -> [usize; 3] {
        let d = self.data.grid().dims;
        [0, 1, 2].map(|a| d[self.axes.grid_axis(a)])
    }

    /// The index-to-world affine (array order) with world row `r` multiplied by `flip[r]`
    /// (`[-1, -1, 1]`: LPS → RAS).
    fn affine_in<'py>(&self, py: Python<'py>, flip: [f64; 3]) -> PyResult<Bound<'py, PyAny>> {
        let d = self.direction_array_order();
        let s = self.spacing_array_order();
        let o = self.data.grid().origin;
        let rows: Vec<Vec<f64>> = (0..3)
            .map(|r| {
                // `+ 0.0` turns the −0.0 of a flipped zero into 0.0, as nibabel prints it.
                let f = |x: f64| flip[r] * x + 0.0;
                vec![
                    f(d[r][0] * s[0]),
                    f(d[r][1] * s[1]),
                    f(d[r][2] * s[2]),
                    f(o[r]),
                ]
            })
            .chain(std::iter::once(vec![0.0, 0.0, 0.0, 1.0]))
            .collect();
        py.import("numpy")?.call_method1("array", (rows,))
    }
}

/// A C-order `(z, y, x)` view of a typed volume, or its `(x, y, z)` transpose.
fn view<T>(v: &CoreVolume<T>, axes: Axes) -> PyResult<ArrayView3<'_, T>>
where
    T: Scalar,
{
    let [nx, ny, nz] = v.grid().dims;
    let zyx = ArrayView3::from_shape((nz, ny, nx), v.data())
        .map_err(|e| errors::error(errors::Kind::Render, format!("internal error: {e}")))?;
    Ok(match axes {
        Axes::Zyx => zyx,
        Axes::Xyz => zyx.reversed_axes(),
    })
}

/// A read-only numpy view of `v`'s samples, kept alive by `owner`.
fn borrow_view<'py, T>(
    v: &CoreVolume<T>,
    axes: Axes,
    owner: Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyAny>>
where
    T: Scalar + Element,
{
    let view = view(v, axes)?;
    // SAFETY: the samples live in the `Arc<AnyVolume>` of `owner` (a frozen `Volume`), which
    // is never mutated or reallocated and is kept alive as the array's base object.
    let arr = unsafe { PyArray3::<T>::borrow_from_array(&view, owner) };
    let kwargs = PyDict::new(arr.py());
    kwargs.set_item("write", false)?;
    arr.call_method("setflags", (), Some(&kwargs))?;
    Ok(arr.into_any())
}

/// A numeric sequence or array as float64 values with its shape (via `numpy.asarray`).
fn floats(py: Python<'_>, obj: &Bound<'_, PyAny>, name: &str) -> PyResult<(Vec<usize>, Vec<f64>)> {
    let np = py.import("numpy")?;
    let kwargs = PyDict::new(py);
    kwargs.set_item("dtype", "float64")?;
    let arr = np
        .call_method("asarray", (obj,), Some(&kwargs))
        .map_err(|e| invalid(format!("{name}: expected numbers, got {obj} ({e})")))?;
    let arr = arr
        .cast_into::<PyUntypedArray>()
        .map_err(|_| invalid(format!("{name}: expected numbers")))?;
    let shape = arr.shape().to_vec();
    // Geometry has at most 16 numbers (a 4×4 affine); anything bigger is a mistake, reported
    // before it is copied.
    if arr.len() > 16 {
        return Err(invalid(format!(
            "{name}: expected at most a 4×4 matrix of numbers, got shape {shape:?}"
        )));
    }
    let flat = arr.call_method0("ravel")?.call_method0("tolist")?;
    let values: Vec<f64> = flat
        .extract()
        .map_err(|e| invalid(format!("{name}: expected numbers ({e})")))?;
    Ok((shape, values))
}

fn three(
    py: Python<'_>,
    obj: &Bound<'_, PyAny>,
    name: &str,
    allow_scalar: bool,
) -> PyResult<[f64; 3]> {
    let (shape, v) = floats(py, obj, name)?;
    match (shape.as_slice(), v.as_slice()) {
        ([], [x]) if allow_scalar => Ok([*x; 3]),
        ([3], [a, b, c]) => Ok([*a, *b, *c]),
        _ => Err(invalid(format!(
            "{name}: expected {}three numbers, got shape {shape:?}",
            if allow_scalar { "one number or " } else { "" }
        ))),
    }
}

/// The grid of an array of `shape` (array order) and its geometry arguments.
#[allow(clippy::too_many_arguments)]
fn grid_for(
    py: Python<'_>,
    shape: [usize; 3],
    axes: Axes,
    spacing: Option<&Bound<'_, PyAny>>,
    origin: Option<&Bound<'_, PyAny>>,
    direction: Option<&Bound<'_, PyAny>>,
    affine: Option<&Bound<'_, PyAny>>,
    space: Option<&str>,
) -> PyResult<Grid> {
    let ras = match space.map(str::to_ascii_uppercase).as_deref() {
        Some("LPS") => false,
        Some("RAS") => true,
        // nibabel's convention for an affine (`img.affine` is RAS); ITK's (LPS) for
        // origin/direction.
        None => affine.is_some(),
        Some(_) => {
            return Err(invalid(format!(
                "space={:?}: expected \"LPS\" (DICOM, ITK, SimpleITK, volsplat's world: the \
                 default for origin/direction) or \"RAS\" (NIfTI, nibabel: the default for \
                 affine)",
                space.unwrap_or_default()
            )));
        }
    };
    // Per array axis: spacing and world direction; then the origin (world).
    let (spacing_a, dir_cols_a, origin_w): ([f64; 3], [DVec3; 3], [f64; 3]) = match affine {
        Some(m) => {
            if spacing.is_some() || origin.is_some() || direction.is_some() {
                return Err(invalid(
                    "give either affine= or spacing=/origin=/direction=, not both",
                ));
            }
            let (s, v) = floats(py, m, "affine")?;
            if !(s == [4, 4] || s == [3, 4]) {
                return Err(invalid(format!(
                    "affine: expected a 4×4 (or 3×4) matrix mapping array indices to world \
                     coordinates, got shape {s:?}"
                )));
            }
            if v.iter().any(|x| !x.is_finite()) {
                return Err(invalid("affine: every entry must be finite"));
            }
            if s == [4, 4] && v[12..16] != [0.0, 0.0, 0.0, 1.0] {
                return Err(invalid(format!(
                    "affine: the last row must be [0, 0, 0, 1], got {:?}",
                    &v[12..16]
                )));
            }
            let col = |c: usize| DVec3::new(v[c], v[4 + c], v[8 + c]);
            let mut sp = [0.0; 3];
            let mut dirs = [DVec3::ZERO; 3];
            for a in 0..3 {
                let c = col(a);
                let len = c.length();
                if len <= 0.0 || len.is_nan() {
                    return Err(invalid(format!(
                        "affine: column {a} (array axis {a}) is zero; each axis needs a \
                         non-zero step"
                    )));
                }
                sp[a] = len;
                dirs[a] = c / len;
            }
            (sp, dirs, [v[3], v[7], v[11]])
        }
        None => {
            let sp = match spacing {
                Some(s) => three(py, s, "spacing", true)?,
                None => [1.0; 3],
            };
            for (a, s) in sp.iter().enumerate() {
                if !(s.is_finite() && *s > 0.0) {
                    return Err(invalid(format!(
                        "spacing: {s} for array axis {a} ({}); spacing must be positive and \
                         finite (world units, in the array's axis order)",
                        axis_letter(axes, a)
                    )));
                }
            }
            let o = match origin {
                Some(o) => three(py, o, "origin", false)?,
                None => [0.0; 3],
            };
            let dirs = match direction {
                Some(d) => {
                    let (s, v) = floats(py, d, "direction")?;
                    if s != [3, 3] {
                        return Err(invalid(format!(
                            "direction: expected a 3×3 matrix whose columns are the world \
                             directions of the array's axes (in array order), got shape {s:?}"
                        )));
                    }
                    [0, 1, 2].map(|c| DVec3::new(v[c], v[3 + c], v[6 + c]))
                }
                None => {
                    // The identity for the grid axes, in array order.
                    let id = [DVec3::X, DVec3::Y, DVec3::Z];
                    [0, 1, 2].map(|a| id[axes.grid_axis(a)])
                }
            };
            (sp, dirs, o)
        }
    };
    let flip = DVec3::new(
        if ras { -1.0 } else { 1.0 },
        if ras { -1.0 } else { 1.0 },
        1.0,
    );
    let mut dims = [0usize; 3];
    let mut sp = [0.0; 3];
    let mut cols = [DVec3::ZERO; 3];
    for a in 0..3 {
        let g = axes.grid_axis(a);
        dims[g] = shape[a];
        sp[g] = spacing_a[a];
        cols[g] = dir_cols_a[a] * flip;
    }
    let origin = (DVec3::from(origin_w) * flip).to_array();
    Grid::new(
        dims,
        sp,
        origin,
        DMat3::from_cols(cols[0], cols[1], cols[2]),
    )
    .map_err(|e| {
        let m = e.to_string();
        if m.contains("direction") {
            invalid(format!(
                "{m}: the direction (or affine) columns must be orthogonal unit directions, one \
                 per array axis in array order; sheared grids are not supported"
            ))
        } else {
            errors::from_core(e)
        }
    })
}

fn axis_letter(axes: Axes, a: usize) -> char {
    ['x', 'y', 'z'][axes.grid_axis(a)]
}

/// The samples of a typed numpy array, x fastest.
fn samples<T: Element + Copy>(arr: &Bound<'_, PyAny>, axes: Axes) -> PyResult<Vec<T>> {
    let arr = arr
        .cast::<PyArray3<T>>()
        .map_err(|e| invalid(format!("internal error: {e}")))?;
    let ro = arr
        .try_readonly()
        .map_err(|e| invalid(format!("the array is being written elsewhere: {e}")))?;
    let v = ro.as_array();
    // The engine's order is x fastest: C order of (z, y, x), i.e. the reversed (x, y, z) view.
    let v = match axes {
        Axes::Zyx => v,
        Axes::Xyz => v.reversed_axes(),
    };
    // Fallible allocation: an array too big to copy is a `MemoryError`, not an abort.
    const WHAT: &str = "the volume's copy of the array";
    Ok(match v.as_slice() {
        Some(s) => errors::try_copy(s, WHAT)?,
        None => {
            let mut out = errors::try_with_capacity(v.len(), WHAT)?;
            out.extend(v.iter().copied());
            out
        }
    })
}

/// A copy of `v` allocated fallibly (`MemoryError` when it does not fit).
fn try_clone(v: &AnyVolume) -> PyResult<AnyVolume> {
    const WHAT: &str = "a copy of the volume";
    fn typed<T: Scalar>(v: &CoreVolume<T>) -> PyResult<AnyVolume>
    where
        AnyVolume: From<CoreVolume<T>>,
    {
        let data = errors::try_copy(v.data(), WHAT)?;
        Ok(CoreVolume::new(v.grid().clone(), data)
            .map_err(errors::from_core)?
            .into())
    }
    match v {
        AnyVolume::U8(v) => typed(v),
        AnyVolume::I8(v) => typed(v),
        AnyVolume::U16(v) => typed(v),
        AnyVolume::I16(v) => typed(v),
        AnyVolume::F32(v) => typed(v),
    }
}

fn parse_scalar_type(name: &str) -> PyResult<ScalarType> {
    let t = match name.trim().to_ascii_lowercase().as_str() {
        "uint8" | "u8" => ScalarType::U8,
        "int8" | "i8" => ScalarType::I8,
        "uint16" | "u16" => ScalarType::U16,
        "int16" | "i16" => ScalarType::I16,
        "float32" | "f32" => ScalarType::F32,
        _ => {
            return Err(invalid(format!(
                "dtype={name:?}: volumes hold uint8, int8, uint16, int16 or float32"
            )));
        }
    };
    Ok(t)
}

/// The engine type a numpy dtype maps to, and whether numpy must convert first.
fn target_type(kind: u8, itemsize: usize, native: bool) -> Option<(ScalarType, bool)> {
    let exact = match (kind, itemsize) {
        (b'u', 1) => Some(ScalarType::U8),
        (b'i', 1) => Some(ScalarType::I8),
        (b'u', 2) => Some(ScalarType::U16),
        (b'i', 2) => Some(ScalarType::I16),
        (b'f', 4) => Some(ScalarType::F32),
        _ => None,
    };
    match exact {
        Some(t) => Some((t, !native)),
        None => match kind {
            b'b' => Some((ScalarType::U8, true)),
            b'u' | b'i' | b'f' => Some((ScalarType::F32, true)),
            _ => None,
        },
    }
}

/// `array` as a numpy array: itself if it is one, else `numpy.asarray(array)`.
fn numpy_array<'py>(
    np: &Bound<'py, PyModule>,
    array: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyAny>> {
    Ok(match array.cast::<PyUntypedArray>() {
        Ok(a) => a.clone().into_any(),
        Err(_) => np.call_method1("asarray", (array,)).map_err(|e| {
            invalid(format!(
                "array: expected a 3-D numpy array (or something numpy.asarray accepts): {e}"
            ))
        })?,
    })
}

/// The shape of a 3-D array with at least one sample per axis; otherwise an error that says
/// what to do with a 2-D slice or a 4-D series.
fn checked_shape(untyped: &Bound<'_, PyUntypedArray>, axes: Axes) -> PyResult<[usize; 3]> {
    let shape_v = untyped.shape().to_vec();
    if shape_v.len() != 3 {
        let hint = match shape_v.len() {
            2 => "; for a single slice add an axis, e.g. array[np.newaxis]",
            4 => "; choose one volume of a 4-D array, e.g. array[0] or array[..., 0]",
            _ => "",
        };
        return Err(invalid(format!(
            "array: expected a 3-D array ({} order), got {} dimensions with shape \
             {shape_v:?}{hint}",
            axes.name(),
            shape_v.len()
        )));
    }
    if shape_v.contains(&0) {
        return Err(invalid(format!(
            "array: every axis needs at least one sample, got shape {shape_v:?}"
        )));
    }
    Ok([shape_v[0], shape_v[1], shape_v[2]])
}

/// A numpy array's dtype as the constructor needs it.
struct SourceType {
    /// numpy's name of the dtype (`descr.str`, e.g. `<f8`).
    name: String,
    /// numpy's kind character (`b'u'`, `b'i'`, `b'f'`, `b'b'`, …).
    kind: u8,
    /// Bytes per sample.
    itemsize: usize,
    /// Whether the samples are in the machine's byte order.
    native: bool,
    /// The name of the dtype's Python type, for the error message of an unsupported dtype.
    type_name: String,
}

impl SourceType {
    /// The dtype of `untyped`.
    fn of(untyped: &Bound<'_, PyUntypedArray>) -> PyResult<Self> {
        let descr = untyped.dtype();
        Ok(SourceType {
            name: descr.str()?.extract()?,
            kind: descr.kind(),
            itemsize: descr.itemsize(),
            native: descr.is_native_byteorder().unwrap_or(true),
            type_name: descr
                .typeobj()
                .name()
                .map(|n| n.to_string())
                .unwrap_or_default(),
        })
    }

    /// The engine type of the volume (`dtype=` if given, else the one this dtype maps to) and
    /// whether numpy must convert the array first.
    fn target(&self, dtype: Option<&str>) -> PyResult<(ScalarType, bool)> {
        let mapped = target_type(self.kind, self.itemsize, self.native);
        match dtype {
            Some(name) => {
                let t = parse_scalar_type(name)?;
                let same = mapped == Some((t, false));
                Ok((t, !same))
            }
            None => mapped.ok_or_else(|| {
                invalid(format!(
                    "array: unsupported dtype {} ({}); volumes hold uint8, int8, uint16, \
                     int16 or float32, and other real types (bool, float64, int32, …) are \
                     converted to float32",
                    self.name, self.type_name
                ))
            }),
        }
    }
}

/// `arr` converted by numpy to `target`'s dtype, refusing what would change values silently:
/// an explicit integer `dtype=` (`explicit`) must hold every value exactly, and a finite
/// float beyond the float32 range must not become an infinity.
fn convert_array<'py>(
    py: Python<'py>,
    np: &Bound<'py, PyModule>,
    arr: &Bound<'py, PyAny>,
    source: &SourceType,
    target: ScalarType,
    explicit: bool,
) -> PyResult<Bound<'py, PyAny>> {
    let src_name = &source.name;
    if !matches!(source.kind, b'u' | b'i' | b'f' | b'b') {
        return Err(invalid(format!(
            "array: cannot convert dtype {src_name} to {}",
            numpy_name(target)
        )));
    }
    let converted = arr.call_method1("astype", (numpy_name(target),))?;
    if explicit && target != ScalarType::F32 {
        // An explicit integer type must hold every value exactly.
        let same: bool = np
            .call_method1("array_equal", (&converted, arr))?
            .extract()?;
        if !same {
            return Err(invalid(format!(
                "dtype={:?}: the array ({src_name}) holds values that {} cannot \
                 represent exactly (out of range or fractional)",
                numpy_name(target),
                numpy_name(target)
            )));
        }
    }
    if target == ScalarType::F32 && source.kind == b'f' {
        // A finite value beyond the float32 range would become an infinity, which the
        // engine clamps to the finite range: a silently wrong value. Name it instead.
        let overflow = np.call_method1(
            "logical_and",
            (
                np.call_method1("isinf", (&converted,))?,
                np.call_method1("isfinite", (arr,))?,
            ),
        )?;
        if overflow.call_method0("any")?.extract::<bool>()? {
            let first = np.call_method1("argwhere", (&overflow,))?.get_item(0)?;
            let index: Vec<usize> = first.call_method0("tolist")?.extract()?;
            let value = arr.get_item(pyo3::types::PyTuple::new(py, &index)?)?;
            return Err(invalid(format!(
                "array: the sample at index {index:?} ({value}) is outside the float32 \
                 range; scale the data first"
            )));
        }
    }
    Ok(converted)
}

/// The engine volume of `arr`'s samples (already of `target`'s dtype) on `grid`;
/// `converted_from` names the source dtype in a float32 error after a conversion.
fn typed_volume(
    grid: Grid,
    arr: &Bound<'_, PyAny>,
    axes: Axes,
    target: ScalarType,
    converted_from: Option<&str>,
) -> PyResult<AnyVolume> {
    Ok(match target {
        ScalarType::U8 => CoreVolume::new(grid, samples::<u8>(arr, axes)?)
            .map_err(errors::from_core)?
            .into(),
        ScalarType::I8 => CoreVolume::new(grid, samples::<i8>(arr, axes)?)
            .map_err(errors::from_core)?
            .into(),
        ScalarType::U16 => CoreVolume::new(grid, samples::<u16>(arr, axes)?)
            .map_err(errors::from_core)?
            .into(),
        ScalarType::I16 => CoreVolume::new(grid, samples::<i16>(arr, axes)?)
            .map_err(errors::from_core)?
            .into(),
        ScalarType::F32 => CoreVolume::new(grid, samples::<f32>(arr, axes)?)
            .map_err(|e| {
                invalid(format!(
                    "array: {e}{}",
                    match converted_from {
                        Some(src_name) => {
                            format!(" (after conversion from {src_name} to float32)")
                        }
                        None => String::new(),
                    }
                ))
            })?
            .into(),
    })
}

#[pymethods]
impl Volume {
    /// A volume from a 3-D numpy array (see the class documentation).
    #[new]
    #[pyo3(signature = (array, spacing=None, origin=None, direction=None, *, axes=None,
        affine=None, space=None, dtype=None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        array: &Bound<'_, PyAny>,
        spacing: Option<&Bound<'_, PyAny>>,
        origin: Option<&Bound<'_, PyAny>>,
        direction: Option<&Bound<'_, PyAny>>,
        axes: Option<&str>,
        affine: Option<&Bound<'_, PyAny>>,
        space: Option<&str>,
        dtype: Option<&str>,
    ) -> PyResult<Self> {
        // nibabel's (x, y, z) with its affine; SimpleITK's and napari's (z, y, x) otherwise.
        let axes = match axes {
            Some(a) => Axes::parse(a)?,
            None if affine.is_some() => Axes::Xyz,
            None => Axes::Zyx,
        };
        let np = py.import("numpy")?;
        let arr = numpy_array(&np, array)?;
        let untyped = arr
            .cast::<PyUntypedArray>()
            .map_err(|_| invalid("array: expected a numpy array"))?;
        let shape = checked_shape(untyped, axes)?;
        let source = SourceType::of(untyped)?;
        let (target, convert) = source.target(dtype)?;
        let grid = grid_for(py, shape, axes, spacing, origin, direction, affine, space)?;
        let mut notes = Vec::new();
        let arr = if convert {
            let converted = convert_array(py, &np, &arr, &source, target, dtype.is_some())?;
            notes.push(format!(
                "converted {} to {} (one pass over the array)",
                source.name,
                numpy_name(target)
            ));
            converted
        } else {
            arr
        };
        let data = typed_volume(
            grid,
            &arr,
            axes,
            target,
            convert.then_some(source.name.as_str()),
        )?;
        // NaN (a masked background, as nibabel gives SPM's output) and infinities were replaced
        // once, by the engine's rule (decision 0030): say so, as a note and a warning.
        if let Some(note) = data.non_finite_note() {
            warn_user(py, &format!("volsplat.Volume: {note}"), 1)?;
            notes.push(note);
        }
        let mut v = Volume::from_any(data, None, axes, "numpy array");
        v.notes = notes;
        Ok(v)
    }

    /// The samples as a read-only numpy array in this volume's axis order (zero-copy view).
    #[getter]
    fn array<'py>(slf: Bound<'py, Self>) -> PyResult<Bound<'py, PyAny>> {
        let this = slf.get();
        let axes = this.axes;
        let owner = slf.clone().into_any();
        match &*this.data {
            AnyVolume::U8(v) => borrow_view(v, axes, owner),
            AnyVolume::I8(v) => borrow_view(v, axes, owner),
            AnyVolume::U16(v) => borrow_view(v, axes, owner),
            AnyVolume::I16(v) => borrow_view(v, axes, owner),
            AnyVolume::F32(v) => borrow_view(v, axes, owner),
        }
    }

    /// `numpy.asarray(volume)`: the samples (a read-only view unless a copy is asked for).
    #[pyo3(signature = (dtype=None, copy=None))]
    fn __array__<'py>(
        slf: Bound<'py, Self>,
        dtype: Option<Bound<'py, PyAny>>,
        copy: Option<bool>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let arr = Volume::array(slf)?;
        let arr = match dtype {
            Some(d) => arr.call_method1("astype", (d,))?,
            None => arr,
        };
        if copy == Some(true) {
            arr.call_method0("copy")
        } else {
            Ok(arr)
        }
    }

    /// The axis order of `.array`, `.shape`, `.spacing` and `.direction`: `"zyx"` or `"xyz"`.
    #[getter]
    fn axes(&self) -> &'static str {
        self.axes.name()
    }

    /// The same volume (the same samples, no copy) seen in another axis order.
    fn with_axes(&self, axes: &str) -> PyResult<Volume> {
        Ok(Volume {
            data: Arc::clone(&self.data),
            source: self.source.clone(),
            axes: Axes::parse(axes)?,
            format: self.format.clone(),
            frames: self.frames,
            frame: self.frame,
            arrays: self.arrays.clone(),
            notes: self.notes.clone(),
        })
    }

    /// The array's shape, in `.axes` order.
    #[getter(shape)]
    fn get_shape(&self) -> (usize, usize, usize) {
        let s = self.shape();
        (s[0], s[1], s[2])
    }

    /// The numpy dtype name of the samples (`uint8`, `int8`, `uint16`, `int16`, `float32`).
    #[getter]
    fn dtype(&self) -> &'static str {
        numpy_name(self.data.scalar_type())
    }

    /// Voxel spacing in world units, in `.axes` order.
    #[getter]
    fn spacing(&self) -> (f64, f64, f64) {
        let s = self.spacing_array_order();
        (s[0], s[1], s[2])
    }

    /// World position (x, y, z; LPS for medical data) of the centre of element [0, 0, 0].
    #[getter]
    fn origin(&self) -> (f64, f64, f64) {
        let o = self.data.grid().origin;
        (o[0], o[1], o[2])
    }

    /// 3×3 numpy array whose columns are the world directions of the array's axes, in `.axes`
    /// order (rows: world x, y, z).
    #[getter]
    fn direction<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let d = self.direction_array_order();
        py.import("numpy")?
            .call_method1("array", (d.map(|r| r.to_vec()).to_vec(),))
    }

    /// 4×4 numpy array mapping array indices (in `.axes` order) to RAS world coordinates, as
    /// nibabel's `img.affine`: `ras = affine @ [a0, a1, a2, 1]`. What `Volume(array,
    /// affine=...)` takes without `space=`, and what `nibabel.Nifti1Image(v.array, v.affine)`
    /// needs (with `axes="xyz"`). `.affine_lps` is the same map into volsplat's LPS world.
    #[getter]
    fn affine<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        self.affine_in(py, [-1.0, -1.0, 1.0])
    }

    /// 4×4 numpy array mapping array indices (in `.axes` order) to volsplat's world coordinates
    /// (LPS, as `.origin` and `.direction`): `lps = affine_lps @ [a0, a1, a2, 1]`;
    /// `Volume(array, affine=v.affine_lps, space="LPS")` rebuilds the volume.
    #[getter]
    fn affine_lps<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        self.affine_in(py, [1.0; 3])
    }

    /// Smallest and largest sample, in data units.
    #[getter]
    fn value_range(&self) -> (f64, f64) {
        self.data.value_range()
    }

    /// Number of samples.
    #[getter]
    fn size(&self) -> usize {
        self.data.grid().voxel_count()
    }

    /// Bytes of sample data.
    #[getter]
    fn nbytes(&self) -> usize {
        self.data.grid().voxel_count() * self.data.scalar_type().size_bytes()
    }

    /// The file this volume was read from (or `None`).
    #[getter]
    fn path(&self) -> Option<PathBuf> {
        match &self.source {
            Some(VolumeSource::File { path, .. }) => Some(path.clone()),
            _ => None,
        }
    }

    /// What the reader said about the file: conversions applied, where the geometry came from,
    /// frames available.
    #[getter]
    fn notes(&self) -> Vec<String> {
        self.notes.clone()
    }

    /// Everything about the volume as a dict: source, format, dtype, shape and axes, dims
    /// (x, y, z), spacing (array order and x, y, z), origin, direction, bounds, value range,
    /// frames, arrays and the reader's notes.
    fn info<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let g = self.data.grid();
        let d = PyDict::new(py);
        d.set_item(
            "source",
            self.source
                .as_ref()
                .map(|s| s.label())
                .unwrap_or_else(|| "numpy array".into()),
        )?;
        d.set_item("format", &self.format)?;
        d.set_item("dtype", self.dtype())?;
        d.set_item("axes", self.axes.name())?;
        d.set_item("shape", self.get_shape())?;
        d.set_item("dims_xyz", g.dims.to_vec())?;
        d.set_item("spacing", self.spacing())?;
        d.set_item("spacing_xyz", g.spacing.to_vec())?;
        d.set_item("origin", g.origin.to_vec())?;
        let dir = self.direction_array_order();
        d.set_item("direction", dir.map(|r| r.to_vec()).to_vec())?;
        let m = g.direction;
        let rows: Vec<Vec<f64>> = (0..3)
            .map(|r| (0..3).map(|c| m.col(c)[r]).collect())
            .collect();
        d.set_item("direction_xyz", rows)?;
        let (lo, hi) = g.bounds_world();
        d.set_item(
            "bounds",
            vec![lo.to_array().to_vec(), hi.to_array().to_vec()],
        )?;
        let (vlo, vhi) = self.data.value_range();
        d.set_item("value_range", (vlo, vhi))?;
        d.set_item("voxels", g.voxel_count())?;
        d.set_item("nbytes", self.nbytes())?;
        d.set_item("frames", self.frames)?;
        d.set_item("frame", self.frame)?;
        d.set_item("arrays", PyList::new(py, &self.arrays)?)?;
        d.set_item("notes", PyList::new(py, &self.notes)?)?;
        Ok(d)
    }

    /// Writes the volume as NRRD (`.nrrd`, attached header; `gzip=True` compresses), which
    /// `volsplat.load` and the command line read back with the same grid.
    #[pyo3(signature = (path, *, gzip=false))]
    fn save(&self, py: Python<'_>, path: PathBuf, gzip: bool) -> PyResult<()> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        if ext.as_deref() != Some("nrrd") {
            return Err(invalid(format!(
                "{}: volumes are saved as NRRD; use a .nrrd file name",
                path.display()
            )));
        }
        let data = Arc::clone(&self.data);
        py.detach(|| volsplat::io::write_nrrd(&path, &data, gzip))
            .map_err(errors::from_io)
    }

    /// The volume source as a scene file writes it (JSON), or `None` for arrays.
    fn _source_json(&self) -> PyResult<Option<String>> {
        self.source
            .as_ref()
            .map(|s| {
                serde_json::to_string(s)
                    .map_err(|e| errors::error(errors::Kind::Render, e.to_string()))
            })
            .transpose()
    }

    /// Whether two volume objects share the same samples (no comparison of values).
    fn _same_data(&self, other: PyRef<'_, Volume>) -> bool {
        Arc::ptr_eq(&self.data, &other.data)
    }

    fn __repr__(&self) -> String {
        let s = self.spacing();
        let src = match &self.source {
            Some(VolumeSource::File { path, .. }) => {
                format!(", path={:?}", path.display().to_string())
            }
            Some(other) => format!(", source={:?}", other.label()),
            None => String::new(),
        };
        format!(
            "volsplat.Volume(shape={:?}, axes={:?}, dtype={}, spacing=({}, {}, {}){src})",
            self.get_shape(),
            self.axes.name(),
            self.dtype(),
            s.0,
            s.1,
            s.2
        )
    }
}

fn limits(
    max_voxels: Option<u128>,
    max_header_bytes: Option<usize>,
    max_json_bytes: Option<u64>,
    max_xml_bytes: Option<u64>,
) -> volsplat::io::Limits {
    let d = volsplat::io::Limits::default();
    d.clone()
        .with_max_voxels(max_voxels.unwrap_or(d.max_voxels))
        .with_max_header_bytes(max_header_bytes.unwrap_or(d.max_header_bytes))
        .with_max_json_bytes(max_json_bytes.unwrap_or(d.max_json_bytes))
        .with_max_xml_bytes(max_xml_bytes.unwrap_or(d.max_xml_bytes))
}

/// Reads a volume file (the formats of the command line). See `volsplat.load`.
#[pyfunction]
#[pyo3(signature = (path, *, frame=0, array=None, series=None, raw_json=None, axes="zyx",
    max_voxels=None, max_header_bytes=None, max_json_bytes=None, max_xml_bytes=None, level=0,
    channel=0, timepoint=0))]
#[allow(clippy::too_many_arguments)]
pub fn load(
    py: Python<'_>,
    path: PathBuf,
    frame: usize,
    array: Option<String>,
    series: Option<String>,
    raw_json: Option<String>,
    axes: &str,
    max_voxels: Option<u128>,
    max_header_bytes: Option<usize>,
    max_json_bytes: Option<u64>,
    max_xml_bytes: Option<u64>,
    level: usize,
    channel: usize,
    timepoint: usize,
) -> PyResult<Volume> {
    let axes = Axes::parse(axes)?;
    let limits = limits(max_voxels, max_header_bytes, max_json_bytes, max_xml_bytes);
    let raw: Option<RawLayout> = match raw_json {
        None => None,
        Some(text) => Some(serde_json::from_str(&text).map_err(|e| {
            invalid(format!(
                "raw: {e}; expected dims=(x, y, z), dtype (uint8, int8, uint16, int16, \
                 float32), and optionally spacing, origin, big_endian, header_bytes"
            ))
        })?),
    };
    if let Some(r) = &raw {
        ScalarType::from_name(&r.scalar_type).map_err(errors::from_core)?;
        if frame != 0 || array.is_some() || series.is_some() || level + channel + timepoint != 0 {
            return Err(invalid(
                "frame, array, series, level, channel and timepoint do not apply to headerless \
                 raw files",
            ));
        }
    }
    let source = VolumeSource::File {
        path: path.clone(),
        raw: raw.clone(),
        frame,
        array: array.clone(),
        series: series.clone(),
        level: volsplat::StoreLevel::Index(level),
        channel,
        timepoint,
    };
    if raw.is_some() {
        let (data, notes) = py
            .detach(|| source.load_with_limits(&limits))
            .map_err(errors::from_engine)?;
        let data = match Arc::try_unwrap(data) {
            Ok(d) => d,
            Err(shared) => try_clone(&shared)?,
        };
        if let Some(note) = data.non_finite_note() {
            warn_user(py, &format!("{}: {note}", path.display()), 2)?;
        }
        let mut v = Volume::from_any(data, Some(source), axes, "raw");
        v.notes = notes;
        return Ok(v);
    }
    let options = volsplat::io::ReadOptions::default()
        .with_frame(frame)
        .with_array(array)
        .with_series(series)
        .with_level(level)
        .with_channel(channel)
        .with_timepoint(timepoint)
        .with_limits(limits);
    let loaded = py
        .detach(|| volsplat::io::read_volume_with(&path, &options))
        .map_err(errors::from_io)?;
    if let Some(note) = loaded.volume.non_finite_note() {
        warn_user(py, &format!("{}: {note}", path.display()), 2)?;
    }
    let mut v = Volume::from_any(loaded.volume, Some(source), axes, &loaded.format);
    v.frames = loaded.frames;
    v.frame = loaded.frame;
    v.arrays = loaded.arrays;
    v.notes = loaded.notes;
    Ok(v)
}

/// A `UserWarning` for something the user should know about their data (samples replaced),
/// pointing `stacklevel` frames up (1: the caller of the Rust function; 2: its caller, past the
/// `volsplat` wrapper). An error only if a warning filter turns it into one.
fn warn_user(py: Python<'_>, message: &str, stacklevel: i32) -> PyResult<()> {
    let category = py.get_type::<pyo3::exceptions::PyUserWarning>();
    let text =
        std::ffi::CString::new(message.replace('\0', " ")).map_err(|e| invalid(e.to_string()))?;
    PyErr::warn(py, category.as_any(), &text, stacklevel)
}

/// A built-in phantom (see `volsplat.phantom`); `None` is the demo phantom the command line
/// renders without an input.
#[pyfunction]
#[pyo3(signature = (name=None, grid=None, *, axes="zyx"))]
pub fn phantom(
    py: Python<'_>,
    name: Option<&str>,
    grid: Option<&Bound<'_, PyAny>>,
    axes: &str,
) -> PyResult<Volume> {
    let axes = Axes::parse(axes)?;
    let (kind, demo_grid): (PhantomKind, Option<Vec<usize>>) = match name {
        Some(name) => (
            serde_json::from_value(serde_json::Value::String(name.into()))
                .map_err(|e| invalid(format!("phantom {name:?}: {e}")))?,
            None,
        ),
        None => match VolumeSource::default() {
            VolumeSource::Phantom { phantom, grid } => (phantom, grid),
            _ => (PhantomKind::Head, None),
        },
    };
    let grid: Option<Vec<usize>> = match grid {
        None => demo_grid,
        Some(g) => Some(match g.extract::<usize>() {
            Ok(n) => vec![n],
            Err(_) => g.extract::<Vec<usize>>().map_err(|_| {
                invalid(format!(
                    "grid: expected N or (X, Y, Z) voxels (x, y, z order), got {g}"
                ))
            })?,
        }),
    };
    let source = VolumeSource::Phantom {
        phantom: kind,
        grid: grid.clone(),
    };
    let data = py
        .detach(|| volsplat::make_phantom(kind, grid.as_deref(), "grid"))
        .map_err(errors::from_engine)?;
    Ok(Volume::from_any(data, Some(source), axes, "phantom"))
}
