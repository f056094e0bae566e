//! Scalar volumes on rectilinear grids, in VTK's world-space convention.
//!
//! Voxel `(i, j, k)` has its centre at `origin + D · (i·sx, j·sy, k·sz)` where `D` is the
//! direction (orientation) matrix whose *columns* are the world directions of the grid's
//! i, j and k axes (docs/design.md §3). Data are stored with `i` fastest, then `j`, then `k`.

use crate::error::{CoreError, Result};
use glam::{DMat3, DVec3};

/// Largest number of voxels a volume may hold (2³⁴ ≈ 17 G samples). Readers check their headers
/// against this before allocating.
pub const MAX_VOXELS: u128 = 1 << 34;

/// The geometry of a rectilinear grid: dimensions, spacing, origin and orientation.
#[derive(Debug, Clone, PartialEq)]
pub struct Grid {
    /// Number of samples along i, j, k (each ≥ 1).
    pub dims: [usize; 3],
    /// Distance between neighbouring samples along i, j, k in world units (usually mm), each > 0.
    pub spacing: [f64; 3],
    /// World position of the centre of voxel (0, 0, 0), world units.
    pub origin: [f64; 3],
    /// Direction matrix: column `c` is the unit world-space direction of grid axis `c`.
    /// Must be orthonormal (a rotation or a reflection).
    pub direction: DMat3,
}

impl Grid {
    /// A grid with unit spacing, zero origin and identity orientation.
    pub fn with_dims(dims: [usize; 3]) -> Result<Self> {
        Grid::new(dims, [1.0; 3], [0.0; 3], DMat3::IDENTITY)
    }

    /// Builds and validates a grid.
    ///
    /// Errors if a dimension is zero, the voxel count exceeds [`MAX_VOXELS`], a spacing is not a
    /// positive finite number, the origin is not finite, or the direction matrix is not orthonormal
    /// (columns of unit length, mutually perpendicular, to 1e-3).
    pub fn new(
        dims: [usize; 3],
        spacing: [f64; 3],
        origin: [f64; 3],
        direction: DMat3,
    ) -> Result<Self> {
        for (a, &d) in dims.iter().enumerate() {
            if d == 0 {
                return Err(CoreError::invalid(
                    format!("dims[{a}]"),
                    d,
                    "must be at least 1",
                ));
            }
        }
        // Checked: three 64-bit sizes can overflow even u128 (2⁶³ · 2⁶³ · 4 = 2¹²⁸).
        let count = dims
            .iter()
            .try_fold(1u128, |acc, &d| acc.checked_mul(d as u128))
            .unwrap_or(u128::MAX);
        if count > MAX_VOXELS {
            return Err(CoreError::TooLarge {
                what: "voxel count".into(),
                value: count,
                limit: MAX_VOXELS,
            });
        }
        for (a, &s) in spacing.iter().enumerate() {
            if !(s.is_finite() && s > 0.0) {
                return Err(CoreError::invalid(
                    format!("spacing[{a}]"),
                    s,
                    "must be a positive finite number",
                ));
            }
        }
        for (a, &o) in origin.iter().enumerate() {
            if !o.is_finite() {
                return Err(CoreError::invalid(
                    format!("origin[{a}]"),
                    o,
                    "must be finite",
                ));
            }
        }
        let gram = direction.transpose() * direction;
        let err = (gram - DMat3::IDENTITY)
            .to_cols_array()
            .iter()
            .fold(0.0f64, |m, v| m.max(v.abs()));
        if err.is_nan() || err >= 1e-3 {
            return Err(CoreError::invalid(
                "direction",
                direction.to_cols_array_2d(),
                "columns must be orthonormal unit vectors",
            ));
        }
        Ok(Grid {
            dims,
            spacing,
            origin,
            direction,
        })
    }

    /// Total number of voxels.
    pub fn voxel_count(&self) -> usize {
        self.dims[0] * self.dims[1] * self.dims[2]
    }

    /// Linear index of voxel (i, j, k) in the data array (i fastest).
    #[inline]
    pub fn linear_index(&self, i: usize, j: usize, k: usize) -> usize {
        i + self.dims[0] * (j + self.dims[1] * k)
    }

    /// The 3×3 linear part of `world_from_index`: `D · diag(spacing)`. Column `c` is the world
    /// displacement of one step along grid axis `c`.
    pub fn world_from_index_linear(&self) -> DMat3 {
        self.direction * DMat3::from_diagonal(DVec3::from(self.spacing))
    }

    /// World position (world units) of a continuous index position (voxel units; integers are
    /// voxel centres).
    pub fn world_from_index(&self, p_index: DVec3) -> DVec3 {
        DVec3::from(self.origin) + self.world_from_index_linear() * p_index
    }

    /// Continuous index position of a world point; inverse of [`Grid::world_from_index`].
    pub fn index_from_world(&self, p_world: DVec3) -> DVec3 {
        let inv =
            DMat3::from_diagonal(DVec3::from(self.spacing).recip()) * self.direction.transpose();
        inv * (p_world - DVec3::from(self.origin))
    }

    /// The eight world-space corners of the box spanned by the first and last voxel centres.
    pub fn corners_world(&self) -> [DVec3; 8] {
        let hi = DVec3::new(
            (self.dims[0] - 1) as f64,
            (self.dims[1] - 1) as f64,
            (self.dims[2] - 1) as f64,
        );
        let mut out = [DVec3::ZERO; 8];
        for (n, c) in out.iter_mut().enumerate() {
            let p = DVec3::new(
                if n & 1 != 0 { hi.x } else { 0.0 },
                if n & 2 != 0 { hi.y } else { 0.0 },
                if n & 4 != 0 { hi.z } else { 0.0 },
            );
            *c = self.world_from_index(p);
        }
        out
    }

    /// Axis-aligned world bounds `(min, max)` of the voxel centres (VTK's `GetBounds`).
    pub fn bounds_world(&self) -> (DVec3, DVec3) {
        let c = self.corners_world();
        let mut lo = c[0];
        let mut hi = c[0];
        for p in &c[1..] {
            lo = lo.min(*p);
            hi = hi.max(*p);
        }
        (lo, hi)
    }

    /// The index-space box `(lo, hi)` that the renderers draw (voxel units; integers are voxel
    /// centres; `docs/decisions/0023-thin-volumes.md`): per axis the box of voxel centres
    /// `[0, n − 1]`, except that an axis of one sample spans that sample's voxel, `[−½, ½]`, so
    /// a single slice is one spacing thick, as a slice of two samples is. Along such an axis
    /// the reconstruction is the one sample's value.
    pub fn drawn_box_index(&self) -> (DVec3, DVec3) {
        let lo = self.dims.map(|n| if n == 1 { -0.5 } else { 0.0 });
        let hi = self.dims.map(|n| if n == 1 { 0.5 } else { (n - 1) as f64 });
        (DVec3::from(lo), DVec3::from(hi))
    }

    /// The eight world-space corners of [`Grid::drawn_box_index`]; [`Grid::corners_world`] on
    /// every grid with at least two samples per axis.
    pub fn drawn_corners_world(&self) -> [DVec3; 8] {
        let (lo, hi) = self.drawn_box_index();
        std::array::from_fn(|n| {
            self.world_from_index(DVec3::new(
                if n & 1 != 0 { hi.x } else { lo.x },
                if n & 2 != 0 { hi.y } else { lo.y },
                if n & 4 != 0 { hi.z } else { lo.z },
            ))
        })
    }

    /// Axis-aligned world bounds `(min, max)` of [`Grid::drawn_corners_world`]: the bounds the
    /// front ends' reset view frames. Equal to [`Grid::bounds_world`] unless an axis has one
    /// sample, which then spans one spacing centred on it.
    pub fn drawn_bounds_world(&self) -> (DVec3, DVec3) {
        let c = self.drawn_corners_world();
        c[1..]
            .iter()
            .fold((c[0], c[0]), |(lo, hi), p| (lo.min(*p), hi.max(*p)))
    }

    /// World-space centre of the grid (midpoint of the first and last voxel centres).
    pub fn center_world(&self) -> DVec3 {
        let (lo, hi) = self.bounds_world();
        (lo + hi) * 0.5
    }

    /// The axes the next level of a resolution pyramid halves (docs/design.md §5; decision 0031):
    /// those whose spacing is at most twice the smallest spacing, so that anisotropic data
    /// become more isotropic level by level (BigDataViewer's rule, `bdv.export.ProposeMipmaps`
    /// in bigdataviewer-core), and that hold at least [`PYRAMID_MIN_SAMPLES`] samples. All
    /// `false` when no axis qualifies: the pyramid ends.
    pub fn pyramid_axes(&self) -> [bool; 3] {
        let min = self.spacing.iter().fold(f64::INFINITY, |m, &s| m.min(s));
        std::array::from_fn(|a| {
            self.dims[a] >= PYRAMID_MIN_SAMPLES && self.spacing[a] <= 2.0 * min * (1.0 + 1e-9)
        })
    }

    /// The grids of a resolution pyramid over this grid: itself, then each level halved
    /// ([`Grid::halved`]) along its [`Grid::pyramid_axes`], ending when no axis qualifies, after
    /// the first level for which `last(level)` holds, or at `max_levels` levels. Geometry only:
    /// no sample is read. The one rule of the renderer's in-memory pyramid and of the OME-Zarr
    /// pyramids volsplat writes, so that level `l` is the same grid in both.
    pub fn pyramid_grids(&self, max_levels: usize, last: impl Fn(&Grid) -> bool) -> Vec<Grid> {
        let mut grids = vec![self.clone()];
        while grids.len() < max_levels {
            let top = &grids[grids.len() - 1];
            if last(top) {
                break;
            }
            let axes = top.pyramid_axes();
            if !axes.contains(&true) {
                break;
            }
            match top.halved(axes) {
                Ok(g) => grids.push(g),
                Err(_) => break,
            }
        }
        grids
    }

    /// The grid of the level that halves `axes` ([`Volume::halved`]): along a halved axis of
    /// `n` samples, `⌈n/2⌉ + 1` samples at twice the spacing, sample `m` centred on the fine
    /// index `2m − ½` (the centre of the filter's taps `2m − 2 … 2m + 1`), so the origin moves
    /// back by half a fine spacing along that axis (VTK's world convention, docs/design.md §3) and the
    /// level's first and last samples lie ½ (n even) or 1½ (n odd) fine spacings outside the
    /// fine ones: the level's box covers the fine level's. Other axes are kept as they are.
    pub fn halved(&self, axes: [bool; 3]) -> Result<Grid> {
        let mut dims = self.dims;
        let mut spacing = self.spacing;
        let mut shift = DVec3::ZERO;
        for a in 0..3 {
            if axes[a] {
                dims[a] = self.dims[a].div_ceil(2) + 1;
                spacing[a] = 2.0 * self.spacing[a];
                shift[a] = -0.5;
            }
        }
        let origin = self.world_from_index(shift).to_array();
        Grid::new(dims, spacing, origin, self.direction)
    }
}

/// An axis with fewer samples is not halved by a pyramid level ([`Grid::pyramid_axes`]).
pub const PYRAMID_MIN_SAMPLES: usize = 8;

/// The pyramid's low-pass filter per halved axis, applied at the fine indices `2m − 2 … 2m + 1`
/// for coarse sample `m` (decision 0031): the binomial `[1, 3, 3, 1] / 8`, the two-sample box
/// applied three times (Burt 1981, *Fast filter transforms for image processing*; the
/// even-length member of the binomial family of Burt & Adelson's pyramid). Its response
/// `cos³(πf)` (f in cycles per fine sample) is 0.35 at the coarse level's Nyquist frequency
/// (¼) and 0 at the fine one's, where the box `[1, 1] / 2` passes 0.71: 3 % of white noise's
/// energy aliases against the box's 18 %. The weights sum to 1 (a constant stays constant),
/// and every interior fine sample gets ½ in total (the integral is kept).
pub const PYRAMID_TAPS: [f64; 4] = [0.125, 0.375, 0.375, 0.125];

/// The sample types a volume may hold.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ScalarType {
    /// Unsigned 8-bit integer.
    U8,
    /// Signed 8-bit integer.
    I8,
    /// Unsigned 16-bit integer.
    U16,
    /// Signed 16-bit integer (e.g. CT in Hounsfield units).
    I16,
    /// 32-bit IEEE float.
    F32,
}

impl ScalarType {
    /// Bytes per sample.
    pub fn size_bytes(self) -> usize {
        match self {
            ScalarType::U8 | ScalarType::I8 => 1,
            ScalarType::U16 | ScalarType::I16 => 2,
            ScalarType::F32 => 4,
        }
    }

    /// Lower-case name (`u8`, `i16`, ...), as used on the command line.
    pub fn name(self) -> &'static str {
        match self {
            ScalarType::U8 => "u8",
            ScalarType::I8 => "i8",
            ScalarType::U16 => "u16",
            ScalarType::I16 => "i16",
            ScalarType::F32 => "f32",
        }
    }

    /// Parses a name as accepted by [`ScalarType::name`], plus common aliases
    /// (`uint8`, `uchar`, `short`, `float`, ...).
    pub fn from_name(name: &str) -> Result<Self> {
        Ok(match name.trim().to_ascii_lowercase().as_str() {
            "u8" | "uint8" | "uchar" | "unsigned char" | "uint8_t" => ScalarType::U8,
            "i8" | "int8" | "char" | "signed char" | "int8_t" => ScalarType::I8,
            "u16" | "uint16" | "ushort" | "unsigned short" | "uint16_t" => ScalarType::U16,
            "i16" | "int16" | "short" | "signed short" | "int16_t" => ScalarType::I16,
            "f32" | "float" | "float32" => ScalarType::F32,
            _ => {
                return Err(CoreError::UnknownName {
                    kind: "scalar type".into(),
                    name: name.into(),
                    known: "u8, i8, u16, i16, f32".into(),
                });
            }
        })
    }
}

/// A sample type that volumes can hold. Implemented for `u8`, `i8`, `u16`, `i16` and `f32`.
pub trait Scalar: Copy + Send + Sync + PartialOrd + std::fmt::Debug + 'static {
    /// The runtime tag of this type.
    const TYPE: ScalarType;
    /// Converts to `f32` (exact for every integer type here).
    fn to_f32(self) -> f32;
    /// The sample nearest `v`: integer types round half away from zero and saturate at their
    /// range (NaN gives 0); `f32` rounds to the nearest float.
    fn from_f64(v: f64) -> Self;
    /// Replaces the samples that are not finite (NaN, ±∞) by finite ones, as
    /// [`NonFiniteSamples`] documents, and says what was replaced (`None`: every sample was
    /// finite, nothing changed). Integer types are always finite. Errors if no sample is finite.
    fn replace_non_finite(data: &mut [Self]) -> Result<Option<NonFiniteSamples>> {
        let _ = data;
        Ok(None)
    }
}

macro_rules! impl_scalar {
    ($t:ty, $tag:ident) => {
        impl Scalar for $t {
            const TYPE: ScalarType = ScalarType::$tag;
            #[inline(always)]
            fn to_f32(self) -> f32 {
                self as f32
            }
            #[inline(always)]
            fn from_f64(v: f64) -> Self {
                // `as` saturates and maps NaN to 0.
                v.round() as $t
            }
        }
    };
}
impl_scalar!(u8, U8);
impl_scalar!(i8, I8);
impl_scalar!(u16, U16);
impl_scalar!(i16, I16);

impl Scalar for f32 {
    const TYPE: ScalarType = ScalarType::F32;
    #[inline(always)]
    fn to_f32(self) -> f32 {
        self
    }
    #[inline(always)]
    fn from_f64(v: f64) -> Self {
        v as f32
    }
    fn replace_non_finite(data: &mut [f32]) -> Result<Option<NonFiniteSamples>> {
        // The common case, every sample finite, costs one read-only pass.
        if data.iter().all(|v| v.is_finite()) {
            return Ok(None);
        }
        let mut r = NonFiniteSamples {
            nan: 0,
            pos_inf: 0,
            neg_inf: 0,
            lowest: f32::INFINITY,
            highest: f32::NEG_INFINITY,
        };
        for &v in data.iter() {
            if v.is_nan() {
                r.nan += 1;
            } else if v == f32::INFINITY {
                r.pos_inf += 1;
            } else if v == f32::NEG_INFINITY {
                r.neg_inf += 1;
            } else {
                r.lowest = r.lowest.min(v);
                r.highest = r.highest.max(v);
            }
        }
        if r.count() == data.len() {
            return Err(CoreError::invalid(
                "samples",
                format!(
                    "{} NaN, {} +inf and {} -inf of {}",
                    r.nan,
                    r.pos_inf,
                    r.neg_inf,
                    data.len()
                ),
                "no sample is finite, so the volume holds no value to draw",
            ));
        }
        for v in data.iter_mut() {
            if v.is_nan() || *v == f32::NEG_INFINITY {
                *v = r.lowest;
            } else if *v == f32::INFINITY {
                *v = r.highest;
            }
        }
        Ok(Some(r))
    }
}

/// The float samples that were not finite when a volume was built, and what they became
/// (`docs/decisions/0030-non-finite-samples.md`): NaN (no value: the background of SPM, FSL
/// and resampled NIfTI files) the lowest finite value of the volume, so that it is background
/// under the automatic transfer function and never the maximum of a MIP; −∞ the lowest and +∞
/// the highest finite value (clamped to the finite range). Values in data units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NonFiniteSamples {
    /// Samples that were NaN.
    pub nan: usize,
    /// Samples that were +∞.
    pub pos_inf: usize,
    /// Samples that were −∞.
    pub neg_inf: usize,
    /// The lowest finite sample (data units): what NaN and −∞ became.
    pub lowest: f32,
    /// The highest finite sample (data units): what +∞ became.
    pub highest: f32,
}

impl NonFiniteSamples {
    /// Samples replaced in all.
    pub fn count(&self) -> usize {
        self.nan + self.pos_inf + self.neg_inf
    }

    /// A note for the user: `"120 samples were NaN, taken as the lowest finite value 0"`, with
    /// the infinities after it.
    pub fn note(&self) -> String {
        let were = |n: usize| {
            if n == 1 {
                "1 sample was".to_string()
            } else {
                format!("{n} samples were")
            }
        };
        let mut parts = Vec::new();
        if self.nan > 0 {
            parts.push(format!(
                "{} NaN, taken as the lowest finite value {}",
                were(self.nan),
                self.lowest
            ));
        }
        if self.neg_inf > 0 {
            parts.push(format!(
                "{} -inf, taken as the lowest finite value {}",
                were(self.neg_inf),
                self.lowest
            ));
        }
        if self.pos_inf > 0 {
            parts.push(format!(
                "{} +inf, taken as the highest finite value {}",
                were(self.pos_inf),
                self.highest
            ));
        }
        parts.join("; ")
    }
}

/// A scalar volume: a [`Grid`] and one sample per voxel, `i` fastest.
#[derive(Debug, Clone, PartialEq)]
pub struct Volume<T> {
    grid: Grid,
    data: Vec<T>,
    /// What [`Volume::new`] replaced (float samples that were not finite).
    non_finite: Option<NonFiniteSamples>,
}

impl<T: Scalar> Volume<T> {
    /// Wraps `data` (length `dims.x·dims.y·dims.z`, i fastest) on `grid`.
    ///
    /// Float samples that are not finite are replaced once, here: NaN and −∞ by the lowest
    /// finite sample, +∞ by the highest ([`NonFiniteSamples`], decision 0030); what was
    /// replaced is kept ([`Volume::non_finite`]) for the readers' notes.
    ///
    /// Errors if the length does not match, or if no float sample is finite.
    pub fn new(grid: Grid, mut data: Vec<T>) -> Result<Self> {
        let expected = grid.voxel_count();
        if data.len() != expected {
            return Err(CoreError::DataLength {
                dims: grid.dims,
                expected,
                actual: data.len(),
            });
        }
        let non_finite = T::replace_non_finite(&mut data)?;
        Ok(Volume {
            grid,
            data,
            non_finite,
        })
    }

    /// The float samples that were not finite when this volume was built and what they became
    /// (`None` if every sample was finite).
    pub fn non_finite(&self) -> Option<&NonFiniteSamples> {
        self.non_finite.as_ref()
    }

    /// Builds a volume by evaluating `f(i, j, k)` at every voxel.
    pub fn from_fn(grid: Grid, mut f: impl FnMut(usize, usize, usize) -> T) -> Result<Self> {
        let [nx, ny, nz] = grid.dims;
        let mut data = Vec::with_capacity(grid.voxel_count());
        for k in 0..nz {
            for j in 0..ny {
                for i in 0..nx {
                    data.push(f(i, j, k));
                }
            }
        }
        Volume::new(grid, data)
    }

    /// The grid geometry.
    pub fn grid(&self) -> &Grid {
        &self.grid
    }

    /// Replaces the geometry (same dims required).
    pub fn set_grid(&mut self, grid: Grid) -> Result<()> {
        if grid.dims != self.grid.dims {
            return Err(CoreError::invalid("dims", grid.dims, "must match the data"));
        }
        self.grid = grid;
        Ok(())
    }

    /// The samples, i fastest.
    pub fn data(&self) -> &[T] {
        &self.data
    }

    /// Consumes the volume, returning its samples.
    pub fn into_data(self) -> Vec<T> {
        self.data
    }

    /// Sample at voxel (i, j, k). Panics if out of range (callers index within `dims`).
    #[inline]
    pub fn get(&self, i: usize, j: usize, k: usize) -> T {
        self.data[self.grid.linear_index(i, j, k)]
    }

    /// Smallest and largest sample, in data units.
    pub fn value_range(&self) -> (f64, f64) {
        let mut lo = f32::INFINITY;
        let mut hi = f32::NEG_INFINITY;
        for v in &self.data {
            let x = v.to_f32();
            lo = lo.min(x);
            hi = hi.max(x);
        }
        (lo as f64, hi as f64)
    }

    /// A copy converted to `f32` samples.
    pub fn to_f32(&self) -> Volume<f32> {
        Volume {
            grid: self.grid.clone(),
            data: self.data.iter().map(|v| v.to_f32()).collect(),
            non_finite: self.non_finite,
        }
    }

    /// The next level of a resolution pyramid: `axes` halved ([`Grid::halved`]), each filtered
    /// with [`PYRAMID_TAPS`] (separable; fine indices outside the grid take the nearest edge
    /// sample), summed in f64 and rounded to the sample type ([`Scalar::from_f64`]). Integer
    /// samples times the taps' eighths are exact in f64, so a constant volume gives the same
    /// constant. One slice at a time ([`Volume::halved_slice`], which callers may run in
    /// parallel).
    pub fn halved(&self, axes: [bool; 3]) -> Result<Volume<T>> {
        let grid = self.grid.halved(axes)?;
        let slice = grid.dims[0] * grid.dims[1];
        let mut data = Vec::with_capacity(grid.voxel_count());
        let mut out = vec![self.data[0]; slice];
        for k in 0..grid.dims[2] {
            self.halved_slice(axes, k, &mut out);
            data.extend_from_slice(&out);
        }
        Volume::new(grid, data)
    }

    /// Slice `k` (the coarse index along the third axis) of [`Volume::halved`] into `out`, whose
    /// length must be the coarse slice's (`dims[0] · dims[1]` of `self.grid().halved(axes)`).
    pub fn halved_slice(&self, axes: [bool; 3], k: usize, out: &mut [T]) {
        let [nx, ny, nz] = self.grid.dims;
        let taps_of = |halved: bool, n: usize, m: usize| -> Vec<(usize, f64)> {
            if halved {
                (0..4)
                    .map(|t| {
                        let i = (2 * m + t).saturating_sub(2).min(n - 1);
                        (i, PYRAMID_TAPS[t])
                    })
                    .collect()
            } else {
                vec![(m, 1.0)]
            }
        };
        let mx = if axes[0] { nx.div_ceil(2) + 1 } else { nx };
        let my = if axes[1] { ny.div_ceil(2) + 1 } else { ny };
        assert_eq!(out.len(), mx * my, "halved_slice: output slice length");
        let tx: Vec<Vec<(usize, f64)>> = (0..mx).map(|m| taps_of(axes[0], nx, m)).collect();
        let ty: Vec<Vec<(usize, f64)>> = (0..my).map(|m| taps_of(axes[1], ny, m)).collect();
        // Along z, then y, into a fine row; then x into the coarse row.
        let mut rows = vec![0.0f64; nx];
        for (j, tyj) in ty.iter().enumerate() {
            rows.fill(0.0);
            for &(kz, wz) in &taps_of(axes[2], nz, k) {
                for &(jy, wy) in tyj {
                    let w = wz * wy;
                    let row = &self.data[(kz * ny + jy) * nx..][..nx];
                    for (acc, v) in rows.iter_mut().zip(row) {
                        *acc += w * v.to_f32() as f64;
                    }
                }
            }
            for (i, txi) in tx.iter().enumerate() {
                let v: f64 = txi.iter().map(|&(ix, wx)| wx * rows[ix]).sum();
                out[j * mx + i] = T::from_f64(v);
            }
        }
    }
}

/// A volume whose sample type is known only at run time (what readers return).
#[derive(Debug, Clone, PartialEq)]
pub enum AnyVolume {
    /// Unsigned 8-bit samples.
    U8(Volume<u8>),
    /// Signed 8-bit samples.
    I8(Volume<i8>),
    /// Unsigned 16-bit samples.
    U16(Volume<u16>),
    /// Signed 16-bit samples.
    I16(Volume<i16>),
    /// 32-bit float samples.
    F32(Volume<f32>),
}

/// Calls `$body` with `$v` bound to the typed volume inside an [`AnyVolume`].
#[macro_export]
macro_rules! with_volume {
    ($any:expr, $v:ident => $body:expr) => {
        match $any {
            $crate::volume::AnyVolume::U8($v) => $body,
            $crate::volume::AnyVolume::I8($v) => $body,
            $crate::volume::AnyVolume::U16($v) => $body,
            $crate::volume::AnyVolume::I16($v) => $body,
            $crate::volume::AnyVolume::F32($v) => $body,
        }
    };
}

impl AnyVolume {
    /// The runtime sample type.
    pub fn scalar_type(&self) -> ScalarType {
        with_volume!(self, v => scalar_type_of(v))
    }

    /// The grid geometry.
    pub fn grid(&self) -> &Grid {
        with_volume!(self, v => v.grid())
    }

    /// Replaces the geometry (same dims required).
    pub fn set_grid(&mut self, grid: Grid) -> Result<()> {
        with_volume!(self, v => v.set_grid(grid))
    }

    /// Smallest and largest sample, in data units.
    pub fn value_range(&self) -> (f64, f64) {
        with_volume!(self, v => v.value_range())
    }

    /// A copy converted to `f32` samples.
    pub fn to_f32(&self) -> Volume<f32> {
        with_volume!(self, v => v.to_f32())
    }

    /// The float samples that were not finite when the volume was built and what they became
    /// ([`Volume::non_finite`]).
    pub fn non_finite(&self) -> Option<&NonFiniteSamples> {
        with_volume!(self, v => v.non_finite())
    }

    /// [`NonFiniteSamples::note`] of [`AnyVolume::non_finite`], for the readers' notes.
    pub fn non_finite_note(&self) -> Option<String> {
        self.non_finite().map(NonFiniteSamples::note)
    }
}

fn scalar_type_of<T: Scalar>(_: &Volume<T>) -> ScalarType {
    T::TYPE
}

macro_rules! impl_from_volume {
    ($t:ty, $tag:ident) => {
        impl From<Volume<$t>> for AnyVolume {
            fn from(v: Volume<$t>) -> Self {
                AnyVolume::$tag(v)
            }
        }
    };
}
impl_from_volume!(u8, U8);
impl_from_volume!(i8, I8);
impl_from_volume!(u16, U16);
impl_from_volume!(i16, I16);
impl_from_volume!(f32, F32);

#[cfg(test)]
mod tests {
    use super::*;

    /// Fuzzing regression (issue 13): `2⁶³ · 2⁶³ · 4` wrapped to 0 in u128 and was accepted.
    #[test]
    fn overflowing_voxel_counts_are_rejected() {
        for dims in [
            [1usize << 63, 1 << 63, 4],
            [usize::MAX; 3],
            [1 << 40, 1 << 40, 1],
        ] {
            let e = Grid::with_dims(dims).unwrap_err();
            assert!(matches!(e, CoreError::TooLarge { .. }), "{e}");
        }
    }

    #[test]
    fn world_index_round_trip_with_rotation_and_spacing() {
        let rot = DMat3::from_rotation_z(0.3) * DMat3::from_rotation_x(-1.1);
        let g = Grid::new([4, 5, 6], [0.5, 2.0, 1.5], [10.0, -3.0, 7.0], rot).unwrap();
        let p = DVec3::new(1.25, 3.5, -0.75);
        let w = g.world_from_index(p);
        assert!((g.index_from_world(w) - p).length() < 1e-12);
        // One step along k moves by spacing z along the third direction column.
        let step = g.world_from_index(DVec3::Z) - g.world_from_index(DVec3::ZERO);
        assert!((step - rot.z_axis * 1.5).length() < 1e-12);
    }

    #[test]
    fn bounds_span_first_to_last_voxel_centre() {
        let g = Grid::new([3, 2, 5], [2.0, 1.0, 0.5], [1.0, 1.0, 1.0], DMat3::IDENTITY).unwrap();
        let (lo, hi) = g.bounds_world();
        assert_eq!(lo, DVec3::new(1.0, 1.0, 1.0));
        assert_eq!(hi, DVec3::new(5.0, 2.0, 3.0));
    }

    #[test]
    fn a_one_sample_axis_is_drawn_one_voxel_thick() {
        let rot = DMat3::from_rotation_z(0.4);
        let g = Grid::new([3, 1, 2], [2.0, 0.5, 1.5], [1.0, 2.0, 3.0], rot).unwrap();
        let (lo, hi) = g.drawn_box_index();
        assert_eq!(lo, DVec3::new(0.0, -0.5, 0.0));
        assert_eq!(hi, DVec3::new(2.0, 0.5, 1.0));
        // One spacing along j, centred on the sample; the other axes as the voxel centres.
        let c = g.drawn_corners_world();
        let j = (c[2] - c[0]).length();
        assert!((j - 0.5).abs() < 1e-12, "{j}");
        assert!(((c[1] - c[0]).length() - 4.0).abs() < 1e-12);
        let mid = (c[0] + c[7]) * 0.5;
        assert!((mid - g.center_world()).length() < 1e-12);
        let (blo, bhi) = g.drawn_bounds_world();
        assert!(bhi.z - blo.z == 1.5 && bhi.x - blo.x > 0.0);
        // Grids with two or more samples per axis: the box of voxel centres, bit for bit.
        let g = Grid::new([3, 2, 5], [2.0, 1.0, 0.5], [1.0, 1.0, 1.0], rot).unwrap();
        assert_eq!(g.drawn_corners_world(), g.corners_world());
        assert_eq!(g.drawn_bounds_world(), g.bounds_world());
    }

    #[test]
    fn invalid_grids_are_rejected_with_field_names() {
        let e = Grid::new([0, 1, 1], [1.0; 3], [0.0; 3], DMat3::IDENTITY).unwrap_err();
        assert!(e.to_string().contains("dims[0]"), "{e}");
        let e = Grid::new([1, 1, 1], [1.0, -1.0, 1.0], [0.0; 3], DMat3::IDENTITY).unwrap_err();
        assert!(e.to_string().contains("spacing[1]"), "{e}");
        let e = Grid::new(
            [1, 1, 1],
            [1.0; 3],
            [0.0; 3],
            DMat3::from_diagonal(DVec3::splat(2.0)),
        )
        .unwrap_err();
        assert!(e.to_string().contains("direction"), "{e}");
        let e = Grid::new(
            [1 << 20, 1 << 20, 1 << 20],
            [1.0; 3],
            [0.0; 3],
            DMat3::IDENTITY,
        )
        .unwrap_err();
        assert!(matches!(e, CoreError::TooLarge { .. }));
    }

    #[test]
    fn data_length_is_checked() {
        let g = Grid::with_dims([2, 2, 2]).unwrap();
        assert!(Volume::<u8>::new(g.clone(), vec![0; 7]).is_err());
        let e = Volume::<f32>::new(g, vec![0.0; 9]).unwrap_err();
        assert!(matches!(e, CoreError::DataLength { actual: 9, .. }), "{e}");
    }

    /// Issue 28 follow-up: NaN backgrounds (SPM, nibabel's `resampled_anat_moved.nii`) were
    /// refused ("invalid sample #0: NaN"). NaN and −∞ become the lowest finite sample, +∞ the
    /// highest, once, and the volume says so.
    #[test]
    fn non_finite_floats_become_the_finite_extremes_and_are_reported() {
        let g = Grid::with_dims([4, 2, 1]).unwrap();
        let nan = f32::NAN;
        let d = vec![
            nan,
            -2.5,
            7.0,
            nan,
            f32::INFINITY,
            3.0,
            f32::NEG_INFINITY,
            nan,
        ];
        let v = Volume::new(g.clone(), d).unwrap();
        assert_eq!(v.data(), &[-2.5, -2.5, 7.0, -2.5, 7.0, 3.0, -2.5, -2.5]);
        let r = *v.non_finite().unwrap();
        assert_eq!((r.nan, r.pos_inf, r.neg_inf, r.count()), (3, 1, 1, 5));
        assert_eq!((r.lowest, r.highest), (-2.5, 7.0));
        assert_eq!(
            r.note(),
            "3 samples were NaN, taken as the lowest finite value -2.5; 1 sample was -inf, \
             taken as the lowest finite value -2.5; 1 sample was +inf, taken as the highest \
             finite value 7"
        );
        assert_eq!(v.value_range(), (-2.5, 7.0));
        // Carried by conversions and the run-time type.
        let any: AnyVolume = v.clone().into();
        assert_eq!(any.non_finite(), Some(&r));
        assert_eq!(any.non_finite_note(), Some(r.note()));
        assert_eq!(v.to_f32().non_finite(), Some(&r));
        // Finite data and integer data are untouched and say nothing.
        let fine = Volume::new(g.clone(), vec![1.0f32; 8]).unwrap();
        assert!(fine.non_finite().is_none());
        let ints: AnyVolume = Volume::new(g.clone(), vec![3u8; 8]).unwrap().into();
        assert!(ints.non_finite_note().is_none());
    }

    #[test]
    fn a_volume_with_no_finite_sample_is_an_error() {
        let g = Grid::with_dims([3, 1, 1]).unwrap();
        for d in [
            vec![f32::NAN; 3],
            vec![f32::NAN, f32::INFINITY, f32::NEG_INFINITY],
        ] {
            let e = Volume::new(g.clone(), d).unwrap_err().to_string();
            assert!(
                e.contains("samples") && e.contains("no sample is finite"),
                "{e}"
            );
        }
    }

    /// A rotated, anisotropic grid for the pyramid's tests.
    fn tilted(dims: [usize; 3]) -> Grid {
        let rot = DMat3::from_rotation_z(0.3) * DMat3::from_rotation_x(-1.1);
        Grid::new(dims, [0.7, 0.9, 1.2], [10.0, -3.0, 7.0], rot).unwrap()
    }

    #[test]
    fn a_pyramid_level_keeps_a_constant() {
        let g = tilted([19, 16, 9]);
        let axes = [true; 3];
        let v = Volume::new(g.clone(), vec![200u8; g.voxel_count()]).unwrap();
        assert!(v.halved(axes).unwrap().data().iter().all(|&x| x == 200));
        let v = Volume::new(g.clone(), vec![-1000i16; g.voxel_count()]).unwrap();
        let h = v.halved(axes).unwrap();
        assert_eq!(h.grid().dims, [11, 9, 6]);
        assert!(h.data().iter().all(|&x| x == -1000));
        let v = Volume::new(g.clone(), vec![0.3f32; g.voxel_count()]).unwrap();
        let h = v.halved([true, false, true]).unwrap();
        assert_eq!(h.grid().dims, [11, 16, 6]);
        assert!(h.data().iter().all(|&x| x == 0.3));
        // Again, level after level.
        let h2 = h.halved([true, true, false]).unwrap();
        assert!(h2.data().iter().all(|&x| x == 0.3));
    }

    /// Pseudo-random values in [0, 1) inside a margin of `margin` voxels, 0 outside it.
    fn speckle(g: &Grid, margin: usize) -> Volume<f32> {
        let n = g.dims;
        let mut seed = 0x2545_f491_4f6c_dd1du64;
        Volume::from_fn(g.clone(), |i, j, k| {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            let inside = [i, j, k]
                .iter()
                .zip(n)
                .all(|(&c, n)| c >= margin && c + margin < n);
            if inside {
                (seed >> 40) as f32 / (1u64 << 24) as f32
            } else {
                0.0
            }
        })
        .unwrap()
    }

    #[test]
    fn a_pyramid_level_keeps_the_integral_and_the_mean() {
        let g = tilted([24, 19, 14]);
        let v = speckle(&g, 2);
        let sum = |v: &Volume<f32>| v.data().iter().map(|&x| x as f64).sum::<f64>();
        let voxel = |g: &Grid| g.spacing.iter().product::<f64>();
        let fine = sum(&v) * voxel(&g);
        for axes in [[true; 3], [true, false, true], [false, true, false]] {
            let h = v.halved(axes).unwrap();
            let coarse = sum(&h) * voxel(h.grid());
            // Exact in f64; the f32 rounding of each coarse sample is all that is left.
            assert!(
                (coarse - fine).abs() < 1e-6 * fine,
                "{axes:?}: {coarse} against {fine}"
            );
        }
        // Integer samples: the same up to the rounding of each coarse sample (±½).
        let q = Volume::from_fn(g.clone(), |i, j, k| (v.get(i, j, k) * 1000.0) as i16).unwrap();
        let h = q.halved([true; 3]).unwrap();
        let fine: f64 = q.data().iter().map(|&x| x as f64).sum();
        let coarse: f64 = h.data().iter().map(|&x| x as f64).sum::<f64>() * 8.0;
        let bound = 0.5 * 8.0 * h.data().len() as f64;
        assert!((coarse - fine).abs() < bound, "{coarse} against {fine}");
        // Data up to the edges: the mean of the coarse samples stays within the edge samples'
        // share of the mean (the level reaches half a voxel past the fine one and repeats the
        // edge there).
        let full = speckle(&g, 0);
        let h = full.halved([true; 3]).unwrap();
        let mean = |v: &Volume<f32>| sum(v) / v.data().len() as f64;
        assert!(
            (mean(&h) - mean(&full)).abs() < 0.02,
            "{} {}",
            mean(&h),
            mean(&full)
        );
    }

    #[test]
    fn a_pyramid_level_covers_the_fine_box_and_keeps_the_centroid() {
        for dims in [[24, 19, 14], [9, 8, 31]] {
            let g = tilted(dims);
            let h = g.halved([true; 3]).unwrap();
            // Sample m lies on the fine index 2m − ½.
            for m in [0, 3, h.dims[0] - 1] {
                let c = h.world_from_index(DVec3::new(m as f64, 1.0, 2.0));
                let f = g.world_from_index(DVec3::new(2.0 * m as f64 - 0.5, 1.5, 3.5));
                assert!((c - f).length() < 1e-9, "{dims:?} m = {m}");
            }
            // The level's box (index space of the fine grid) covers the fine box by ½ or 1½.
            let corner =
                g.index_from_world(h.world_from_index(DVec3::from(h.dims.map(|n| (n - 1) as f64))));
            let lo = g.index_from_world(DVec3::from(h.origin));
            for a in 0..3 {
                assert!((lo[a] + 0.5).abs() < 1e-9, "{dims:?} axis {a}: {}", lo[a]);
                let past = corner[a] - (dims[a] - 1) as f64;
                let expect = if dims[a] % 2 == 0 { 0.5 } else { 1.5 };
                assert!((past - expect).abs() < 1e-9, "{dims:?} axis {a}: {past}");
            }
            // The filter is centred where the grid says: the world centroid of a compact
            // object is the same at both levels.
            let v = speckle(&g, 3);
            let centroid = |v: &Volume<f32>| {
                let [nx, ny, _] = v.grid().dims;
                let (mut m, mut p) = (0.0f64, DVec3::ZERO);
                for (n, &x) in v.data().iter().enumerate() {
                    let ijk =
                        DVec3::new((n % nx) as f64, (n / nx % ny) as f64, (n / nx / ny) as f64);
                    m += x as f64;
                    p += v.grid().world_from_index(ijk) * x as f64;
                }
                p / m
            };
            let hv = v.halved([true; 3]).unwrap();
            let (a, b) = (centroid(&v), centroid(&hv));
            assert!((a - b).length() < 1e-5, "{dims:?}: {a} against {b}");
        }
    }

    #[test]
    fn pyramid_axes_make_anisotropic_grids_more_isotropic() {
        // The CT-like head: x and y first, z (2.6× the smallest spacing) from the second level.
        let ct = Grid::new(
            [256, 256, 108],
            [0.706, 0.863, 1.869],
            [0.0; 3],
            DMat3::IDENTITY,
        )
        .unwrap();
        assert_eq!(ct.pyramid_axes(), [true, true, false]);
        let l1 = ct.halved(ct.pyramid_axes()).unwrap();
        assert_eq!(l1.dims, [129, 129, 108]);
        assert_eq!(l1.pyramid_axes(), [true; 3]);
        // Short axes stay; a grid of short axes ends the pyramid.
        let thin = Grid::with_dims([64, 64, 4]).unwrap();
        assert_eq!(thin.pyramid_axes(), [true, true, false]);
        assert_eq!(
            Grid::with_dims([7, 5, 1]).unwrap().pyramid_axes(),
            [false; 3]
        );
    }

    #[test]
    fn samples_round_to_the_nearest_and_saturate() {
        assert_eq!(u8::from_f64(254.5), 255);
        assert_eq!(u8::from_f64(300.0), 255);
        assert_eq!(u8::from_f64(-3.0), 0);
        assert_eq!(i16::from_f64(-1000.5), -1001);
        assert_eq!(i16::from_f64(-999.49), -999);
        assert_eq!(i8::from_f64(f64::NAN), 0);
        assert_eq!(f32::from_f64(0.1), 0.1f32);
    }

    #[test]
    fn any_volume_reports_type_and_range() {
        let g = Grid::with_dims([3, 1, 1]).unwrap();
        let v: AnyVolume = Volume::new(g, vec![-5i16, 7, 2]).unwrap().into();
        assert_eq!(v.scalar_type(), ScalarType::I16);
        assert_eq!(v.value_range(), (-5.0, 7.0));
        assert_eq!(v.to_f32().data(), &[-5.0, 7.0, 2.0]);
    }
}
