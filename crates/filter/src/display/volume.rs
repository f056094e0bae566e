//! The density field and the per-pixel ray geometry of the Chapter 6 displays (Buchanan §6-0.1,
//! App. B steps 1–2).
//!
//! Frames: *world* coordinates are the volume's (docs/design.md §3); *index* (texture) coordinates
//! put voxel `(i, j, k)` at the integer point `(i, j, k)` — the texture space of
//! [`DiscreteTexture`] and of the NIL cells. Lengths given to the displays in *unit lengths* are
//! multiples of [`DisplayVolume::unit`], the largest world extent of the volume's bounds: the
//! thesis normalises its volume to the unit cube (open point A-17 of the
//! display module's decisions; the `√3` bound of App. B).

use crate::error::{FilterError, Result};
use crate::texture::{DiscreteTexture, Reconstruction, SolidTexture};
use glam::{DMat3, DVec3};
use volsplat_core::{Grid, Projection};

/// Least number of samples appended on the high side of every axis, so that the periodic
/// texture of the NIL machinery (decision A-5 of the texture crate) never sees the opposite face
/// next to the last voxel. Each axis is padded to `max(n + PAD, 2^⌈log₂ n⌉)` samples, so every
/// NIL root cell enclosing points of the volume (inside `[0, 2^⌈log₂ n⌉)`) lies inside the
/// padded texture and never wraps. The padding samples repeat the edge voxel (see
/// [`DisplayVolume`]): the density *field* is still zero outside the box of voxel centres
/// (eq 4.2), because every display filter is masked to that box; the padding is only what a
/// NIL patch that straddles the face sees beyond it (decision 0007).
pub const PAD: usize = 2;

/// Padded size of an axis of `n` samples (see [`PAD`]).
pub fn padded(n: usize) -> usize {
    (n + PAD).max(n.next_power_of_two())
}

/// A density field on a volume grid: densities per voxel (dimensionless, normally `[0, 1]`),
/// reconstructed by sample-and-hold or trilinear interpolation, zero outside the box of voxel
/// centres. The NIL texture behind it ([`DisplayVolume::texture`]) is padded by repeating the
/// edge voxels ([`PAD`]).
#[derive(Debug, Clone)]
pub struct DisplayVolume {
    texture: DiscreteTexture,
    dims: [usize; 3],
    world_from_index: DMat3,
    index_from_world: DMat3,
    origin: DVec3,
    unit: f64,
    min_spacing: f64,
    max_spacing: f64,
}

impl DisplayVolume {
    /// Wraps `densities` (x fastest, `grid.dims` samples, finite). Each axis needs at least two
    /// samples. The texture is padded by repeating the edge samples (see [`PAD`]).
    pub fn new(grid: &Grid, densities: &[f64], recon: Reconstruction) -> Result<Self> {
        let dims = grid.dims;
        for (a, &n) in dims.iter().enumerate() {
            if n < 2 {
                return Err(FilterError::invalid(
                    format!("dims[{a}]"),
                    n,
                    "a display volume needs at least 2 samples per axis",
                ));
            }
        }
        let count = dims.iter().map(|&n| n as u128).product::<u128>();
        if densities.len() as u128 != count {
            return Err(FilterError::invalid(
                "densities",
                densities.len(),
                format!("expected {count} samples"),
            ));
        }
        let pd = dims.map(padded);
        let texture = DiscreteTexture::from_fn(pd, recon, |i, j, k| {
            let (i, j, k) = (i.min(dims[0] - 1), j.min(dims[1] - 1), k.min(dims[2] - 1));
            densities[(k * dims[1] + j) * dims[0] + i]
        })?;
        let world_from_index = grid.world_from_index_linear();
        let det = world_from_index.determinant();
        if !(det.is_finite() && det.abs() > 0.0) {
            return Err(FilterError::invalid(
                "grid",
                det,
                "spacing × direction must be invertible",
            ));
        }
        let (lo, hi) = grid.bounds_world();
        let unit = (hi - lo).max_element();
        let min_spacing = grid.spacing.iter().fold(f64::INFINITY, |m, &s| m.min(s));
        let max_spacing = grid.spacing.iter().fold(0.0f64, |m, &s| m.max(s));
        Ok(DisplayVolume {
            texture,
            dims,
            world_from_index,
            index_from_world: world_from_index.inverse(),
            origin: grid.world_from_index(DVec3::ZERO),
            unit,
            min_spacing,
            max_spacing,
        })
    }

    /// The same field with every density mapped through `f` (e.g. a transfer function
    /// applied to the samples: classification before reconstruction).
    pub fn map(&self, f: impl Fn(f64) -> f64) -> Result<Self> {
        let dims = self.dims;
        let pd = self.texture.dims();
        let tex = &self.texture;
        let texture = DiscreteTexture::from_fn(pd, tex.reconstruction(), |i, j, k| {
            let (i, j, k) = (i.min(dims[0] - 1), j.min(dims[1] - 1), k.min(dims[2] - 1));
            f(tex.at(i as i64, j as i64, k as i64))
        })?;
        Ok(DisplayVolume {
            texture,
            ..self.clone()
        })
    }

    /// Sample counts of the volume (without padding).
    pub fn dims(&self) -> [usize; 3] {
        self.dims
    }

    /// The padded periodic texture the NIL maps are built from (texel units = index space).
    pub fn texture(&self) -> &DiscreteTexture {
        &self.texture
    }

    /// One unit length in world units: the largest extent of the bounds of voxel centres.
    pub fn unit(&self) -> f64 {
        self.unit
    }

    /// World volume of one index-space unit cube (`|det world_from_index|`).
    pub fn voxel_volume(&self) -> f64 {
        self.world_from_index.determinant().abs()
    }

    /// Smallest grid spacing, world units.
    pub fn min_spacing(&self) -> f64 {
        self.min_spacing
    }

    /// Largest grid spacing, world units.
    pub fn max_spacing(&self) -> f64 {
        self.max_spacing
    }

    /// Whether an index-space point lies in the box of voxel centres `[0, n − 1]³`.
    #[inline]
    pub fn inside(&self, p_index: DVec3) -> bool {
        let e = 1e-9;
        p_index.x >= -e
            && p_index.y >= -e
            && p_index.z >= -e
            && p_index.x <= (self.dims[0] - 1) as f64 + e
            && p_index.y <= (self.dims[1] - 1) as f64 + e
            && p_index.z <= (self.dims[2] - 1) as f64 + e
    }

    /// Reconstructed density at an index-space point; 0 outside the box of voxel centres.
    #[inline]
    pub fn density_index(&self, p_index: DVec3) -> f64 {
        if self.inside(p_index) {
            self.texture.value(p_index)
        } else {
            0.0
        }
    }

    /// Reconstructed density at a world point; 0 outside the box of voxel centres.
    #[inline]
    pub fn density(&self, p_world: DVec3) -> f64 {
        self.density_index(self.index_from_world(p_world))
    }

    /// World → index (texture) coordinates.
    #[inline]
    pub fn index_from_world(&self, p_world: DVec3) -> DVec3 {
        self.index_from_world * (p_world - self.origin)
    }

    /// Index (texture) → world coordinates.
    #[inline]
    pub fn world_from_index(&self, p_index: DVec3) -> DVec3 {
        self.origin + self.world_from_index * p_index
    }

    /// Parameter interval `[t0, t1]` (world units along the unit direction `dir`) over which
    /// `origin + t·dir` lies in the box of voxel centres; `None` if it misses or only touches
    /// it (App. B: a single hit is a miss).
    pub fn clip(&self, origin: DVec3, dir: DVec3) -> Option<(f64, f64)> {
        let q0 = self.index_from_world(origin);
        let dq = self.index_from_world * dir;
        let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
        for a in 0..3 {
            let hi = (self.dims[a] - 1) as f64;
            if dq[a].abs() < 1e-300 {
                if q0[a] < -1e-9 || q0[a] > hi + 1e-9 {
                    return None;
                }
                continue;
            }
            let ta = (0.0 - q0[a]) / dq[a];
            let tb = (hi - q0[a]) / dq[a];
            t0 = t0.max(ta.min(tb));
            t1 = t1.min(ta.max(tb));
        }
        (t0.is_finite() && t1.is_finite() && t1 > t0).then_some((t0, t1))
    }
}

/// One pixel's central ray (App. B step 1–2) with its local frame and screen-filter scale.
#[derive(Debug, Clone, Copy)]
pub(crate) struct PixelRay {
    /// Ray origin (world): the eye, or the eye plane for orthographic views.
    pub o: DVec3,
    /// Unit direction (world).
    pub d: DVec3,
    /// Unit vectors perpendicular to `d` (world).
    pub e1: DVec3,
    pub e2: DVec3,
    /// Entry and exit parameters (world units along `d`).
    pub ta: f64,
    pub tb: f64,
    /// `d · forward` (converts `t` to depth along the direction of projection).
    pub cos: f64,
    /// Where the lines of a tube around this ray may start: 0 (the eye) under perspective,
    /// `−∞` for orthographic rays (whose origin may lie inside the volume, VTK semantics).
    pub t_min: f64,
}

/// Ray generation for one projection (either kind, through [`Projection::ray`]).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Rays {
    pub proj: Projection,
}

impl Rays {
    pub(crate) fn ray(&self, vol: &DisplayVolume, x: f64, y: f64) -> Option<PixelRay> {
        let (o, d) = self.proj.ray(x, y);
        let (ta, tb) = vol.clip(o, d)?;
        let f = self.proj.frame();
        let mut e1 = f.right - d * f.right.dot(d);
        if e1.length_squared() < 1e-12 {
            e1 = f.up - d * f.up.dot(d);
        }
        let e1 = e1.normalize();
        let e2 = d.cross(e1);
        // Orthographic rays may start behind the volume's front (VTK semantics); clip anyway.
        let t_min = if matches!(self.proj, Projection::Perspective(_)) {
            0.0
        } else {
            f64::NEG_INFINITY
        };
        let ta = ta.max(t_min);
        (tb > ta).then_some(PixelRay {
            o,
            d,
            e1,
            e2,
            ta,
            tb,
            cos: d.dot(f.forward),
            t_min,
        })
    }

    /// World size of one pixel at parameter `t` along `ray` (constant for orthographic).
    #[inline]
    pub(crate) fn pixel_size(&self, ray: &PixelRay, t: f64) -> f64 {
        self.proj.pixel_size_at((t * ray.cos).max(1e-9))
    }
}
