//! The brute-force reference integrator: the independent oracle for the splatting renderer.
//!
//! For every pixel of a [`Projection`] (centre `(x + ½, y + ½)`, or `n × n` sub-pixel positions
//! `x + (s + ½)/n`), one ray per position:
//!
//! - [`Projection::Ortho`]: the ray leaves the image-plane point
//!   [`OrthoProjection::world_from_raster`](volsplat_core::OrthoProjection::world_from_raster) along `frame.forward` and covers the whole line (no
//!   near or far clipping; volumes behind the eye plane are in view, as in VTK).
//! - [`Projection::Perspective`]: the ray leaves the eye along
//!   [`PerspectiveProjection::ray_direction`](volsplat_core::PerspectiveProjection::ray_direction) and covers only the forward half-line `t ≥ 0`
//!   (eye-space depth ≥ 0), so an eye inside the volume sees what lies in front of it.
//!
//! The ray is clipped exactly to the box of voxel centres, `[0, dims − 1]³` in index space, an
//! axis of one sample spanning its voxel, `[−½, ½]` ([`Grid::drawn_box_index`],
//! `docs/decisions/0023-thin-volumes.md`), or with [`Extent::Cells`] to every voxel's cell,
//! `[−½, dims − ½]³`, the extent the splatting kernels cover ([`ray_box_interval`]); it is
//! marched at a fixed world-space step along the ray, and the field is reconstructed by
//! trilinear interpolation in index space ([`trilinear`]), constant beyond the outer voxel
//! centres. Nothing here shares code with the renderer beyond the core types and the CRIO
//! classifier.
//!
//! - [`reference_xray`]: `∫ f ds` (data units × world units), trapezoid rule between the exact
//!   entry and exit points.
//! - [`reference_mip`] / [`reference_minip`]: maximum / minimum of the samples along the ray.
//! - [`reference_composite`]: Westover's CRIO classification of each sample (via
//!   [`FrameClassifier`]) composited front to back with premultiplied *over*.
//! - [`analytic_xray`]: the closed-form X-ray image of a [`Phantom`], for comparison.
//!
//! Rows are computed in parallel with rayon; each pixel is computed independently, so results
//! are bit-for-bit the same for any thread count.

use rayon::prelude::*;
use volsplat_core::glam::{DVec3, Vec3};
use volsplat_core::image::over_front_to_back;
use volsplat_core::phantom::Phantom;
use volsplat_core::{
    CrioTables, FrameClassifier, Grid, Image, Projection, Rgba, SampleInput, ScalarImage, Volume,
};

/// Settings of the reference integrator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReferenceSettings {
    /// Sample spacing along the ray in world units. Zero, negative or non-finite means the
    /// default: the smallest grid spacing / 8 (see [`ReferenceSettings::step_for`]).
    pub step: f64,
    /// Sub-pixel rays per axis (`n × n` rays per pixel, averaged); 0 is treated as 1.
    pub supersample: usize,
    /// Composite: shade at the voxels (VTK's order) instead of at the samples: each sample is
    /// classified with each of its cell's eight voxel gradients and the eight colours are
    /// blended with the trilinear weights (equal to blending the voxels' light where no
    /// channel clamps at 1). Default `false`: the gradient is interpolated, then classified.
    pub shade_at_voxels: bool,
    /// The box the rays are clipped to. Default [`Extent::Centres`].
    pub extent: Extent,
}

/// Which box of a grid the reference integrates over (`docs/decisions/0023-thin-volumes.md`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Extent {
    /// The box of voxel centres, with an axis of one sample spanning its voxel
    /// ([`Grid::drawn_box_index`]): what the ray casters (VTK's, the image-aligned slabs)
    /// sample.
    #[default]
    Centres,
    /// Every voxel's cell, `[−½, n − ½]` per axis: what the splatting renderers cover, each
    /// voxel's kernel integrating to one voxel along the ray. Equal to `Centres` along an axis
    /// of one sample.
    Cells,
}

impl Extent {
    /// The index-space box `(lo, hi)` of `grid` under this extent.
    pub fn box_index(self, grid: &Grid) -> (DVec3, DVec3) {
        match self {
            Extent::Centres => grid.drawn_box_index(),
            Extent::Cells => (
                DVec3::splat(-0.5),
                DVec3::from(grid.dims.map(|n| n as f64 - 0.5)),
            ),
        }
    }
}

impl Default for ReferenceSettings {
    /// Automatic step (smallest spacing / 8), one ray per pixel.
    fn default() -> Self {
        ReferenceSettings {
            step: 0.0,
            supersample: 1,
            shade_at_voxels: false,
            extent: Extent::Centres,
        }
    }
}

impl ReferenceSettings {
    /// The step actually used for `grid`, world units: `step` if positive and finite, else the
    /// smallest spacing / 8.
    pub fn step_for(&self, grid: &Grid) -> f64 {
        if self.step.is_finite() && self.step > 0.0 {
            self.step
        } else {
            grid.spacing.iter().fold(f64::INFINITY, |m, &s| m.min(s)) / 8.0
        }
    }

    fn rays_per_axis(&self) -> usize {
        self.supersample.max(1)
    }
}

/// Slack, in voxel (index) units, by which the box of voxel centres is widened when clipping a
/// ray, so rays lying exactly on a face are not lost to rounding.
const BOX_SLACK: f64 = 1e-9;

/// The parameter interval `[t0, t1]` (world units for a unit `dir`) over which the world line
/// `origin + t·dir` lies inside the box of voxel centres `[0, dims − 1]³` (index space) of
/// `grid`, an axis of one sample spanning `[−½, ½]` ([`Grid::drawn_box_index`]), or `None` if
/// it misses. Slab method in index space; the box is widened by 1e-9 voxels against rounding.
pub fn ray_box_interval(grid: &Grid, origin: DVec3, dir: DVec3) -> Option<(f64, f64)> {
    ray_extent_interval(grid, Extent::Centres, origin, dir)
}

/// [`ray_box_interval`] for the box of `extent`.
pub fn ray_extent_interval(
    grid: &Grid,
    extent: Extent,
    origin: DVec3,
    dir: DVec3,
) -> Option<(f64, f64)> {
    let q0 = grid.index_from_world(origin);
    let dq = grid.index_from_world(origin + dir) - q0;
    let (box_lo, box_hi) = extent.box_index(grid);
    let mut t0 = f64::NEG_INFINITY;
    let mut t1 = f64::INFINITY;
    for a in 0..3 {
        let lo = box_lo[a] - BOX_SLACK;
        let hi = box_hi[a] + BOX_SLACK;
        if dq[a] == 0.0 {
            if q0[a] < lo || q0[a] > hi {
                return None;
            }
        } else {
            let (ta, tb) = ((lo - q0[a]) / dq[a], (hi - q0[a]) / dq[a]);
            t0 = t0.max(ta.min(tb));
            t1 = t1.min(ta.max(tb));
        }
    }
    (t0 <= t1 && t0.is_finite() && t1.is_finite()).then_some((t0, t1))
}

/// Trilinear interpolation of `vol` at the continuous index position `p_index` (voxel units;
/// integers are voxel centres), in data units. Positions outside `[0, dims − 1]³` are clamped to
/// the box.
pub fn trilinear(vol: &Volume<f32>, p_index: DVec3) -> f64 {
    let data = vol.data();
    let grid = vol.grid();
    let [nx, ny, _] = grid.dims;
    let (base, frac) = cell(grid, p_index);
    let stride = [1, nx, nx * ny];
    let mut v = 0.0;
    for corner in 0..8usize {
        let mut w = 1.0;
        let mut idx = 0;
        for a in 0..3 {
            let up = corner >> a & 1 == 1;
            let step = usize::from(up && grid.dims[a] > 1);
            idx += (base[a] + step) * stride[a];
            w *= if up { frac[a] } else { 1.0 - frac[a] };
        }
        if w != 0.0 {
            v += w * data[idx] as f64;
        }
    }
    v
}

/// The cell of a (clamped) index position: lower corner and fractional offsets in [0, 1].
fn cell(grid: &Grid, p: DVec3) -> ([usize; 3], [f64; 3]) {
    let mut base = [0usize; 3];
    let mut frac = [0.0f64; 3];
    for a in 0..3 {
        let n = grid.dims[a];
        if n < 2 {
            continue;
        }
        let x = p[a].clamp(0.0, (n - 1) as f64);
        let i = (x.floor() as usize).min(n - 2);
        base[a] = i;
        frac[a] = x - i as f64;
    }
    (base, frac)
}

/// World-space gradients of every voxel (data units per world unit), `i` fastest: central
/// differences divided by `2·spacing` along each grid axis, one-sided differences divided by
/// `spacing` at the border (zero along an axis with one sample), mapped to world as
/// `D · g` (docs/design.md §4.4).
pub fn voxel_gradients(vol: &Volume<f32>) -> Vec<[f32; 3]> {
    let grid = vol.grid();
    let [nx, ny, nz] = grid.dims;
    let stride = [1, nx, nx * ny];
    let data = vol.data();
    let mut out = Vec::with_capacity(grid.voxel_count());
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                let pos = [i, j, k];
                let here = grid.linear_index(i, j, k);
                let mut g = DVec3::ZERO;
                for a in 0..3 {
                    let n = grid.dims[a];
                    if n < 2 {
                        continue;
                    }
                    let (lo, hi, span) = if pos[a] == 0 {
                        (here, here + stride[a], 1.0)
                    } else if pos[a] == n - 1 {
                        (here - stride[a], here, 1.0)
                    } else {
                        (here - stride[a], here + stride[a], 2.0)
                    };
                    g[a] = (data[hi] as f64 - data[lo] as f64) / (span * grid.spacing[a]);
                }
                out.push((grid.direction * g).as_vec3().to_array());
            }
        }
    }
    out
}

/// The eight corners of the cell at `p_index`: each one's linear voxel index and trilinear
/// weight (f64).
fn cell_corners(grid: &Grid, p_index: DVec3) -> [(usize, f64); 8] {
    let [nx, ny, _] = grid.dims;
    let (base, frac) = cell(grid, p_index);
    let stride = [1, nx, nx * ny];
    std::array::from_fn(|corner| {
        let mut w = 1.0f64;
        let mut idx = 0;
        for a in 0..3 {
            let up = corner >> a & 1 == 1;
            idx += (base[a] + usize::from(up && grid.dims[a] > 1)) * stride[a];
            w *= if up { frac[a] } else { 1.0 - frac[a] };
        }
        (idx, w)
    })
}

fn trilinear_gradient(grads: &[[f32; 3]], grid: &Grid, p_index: DVec3) -> Vec3 {
    let mut g = Vec3::ZERO;
    for (idx, w) in cell_corners(grid, p_index) {
        if w != 0.0 {
            g += Vec3::from(grads[idx]) * w as f32;
        }
    }
    g
}

/// One sub-pixel ray: world origin, unit world direction, and the smallest admissible parameter
/// (`−∞` for orthographic rays, `0` — the eye — for perspective rays).
#[derive(Clone, Copy)]
struct Ray {
    origin: DVec3,
    dir: DVec3,
    t_min: f64,
}

/// Per-view ray geometry shared by the integrators.
struct Rays<'a> {
    vol: &'a Volume<f32>,
    proj: &'a Projection,
    n: usize,
    extent: Extent,
}

impl Rays<'_> {
    /// Calls `f(ray)` for each sub-pixel ray of pixel `(x, y)`.
    fn for_each_ray(&self, x: usize, y: usize, mut f: impl FnMut(Ray)) {
        let n = self.n as f64;
        for sy in 0..self.n {
            for sx in 0..self.n {
                let rx = x as f64 + (sx as f64 + 0.5) / n;
                let ry = y as f64 + (sy as f64 + 0.5) / n;
                f(pixel_ray(self.proj, rx, ry));
            }
        }
    }

    /// The clipped ray: entry parameter, length (world units), and index-space start and
    /// direction (index units per world unit).
    fn clip(&self, ray: &Ray) -> Option<(f64, f64, DVec3, DVec3)> {
        let grid = self.vol.grid();
        let (t0, t1) = ray_extent_interval(grid, self.extent, ray.origin, ray.dir)?;
        let t0 = t0.max(ray.t_min);
        if t1 < t0 {
            return None;
        }
        let q0 = grid.index_from_world(ray.origin + ray.dir * t0);
        let dq = grid.index_from_world(ray.origin + ray.dir) - grid.index_from_world(ray.origin);
        Some((t0, t1 - t0, q0, dq))
    }
}

/// The ray through raster point `(x, y)` (pixels): for orthographic views from the image-plane
/// point through the focal point, unbounded both ways; for perspective views from the eye,
/// forward only.
fn pixel_ray(proj: &Projection, x: f64, y: f64) -> Ray {
    match proj {
        Projection::Ortho(p) => Ray {
            origin: p.world_from_raster(x, y),
            dir: p.frame.forward,
            t_min: f64::NEG_INFINITY,
        },
        Projection::Perspective(p) => Ray {
            origin: p.frame.eye,
            dir: p.ray_direction(x, y),
            t_min: 0.0,
        },
    }
}

fn render_scalar(
    vol: &Volume<f32>,
    proj: &Projection,
    settings: &ReferenceSettings,
    pixel: impl Fn(&Rays, usize, usize) -> f32 + Sync,
) -> ScalarImage {
    let rays = Rays {
        vol,
        proj,
        n: settings.rays_per_axis(),
        extent: settings.extent,
    };
    let (width, height) = proj.size();
    let mut values = vec![0.0f32; width * height];
    if values.is_empty() {
        return ScalarImage::new(width, height);
    }
    values
        .par_chunks_mut(width)
        .enumerate()
        .for_each(|(y, row)| {
            for (x, v) in row.iter_mut().enumerate() {
                *v = pixel(&rays, x, y);
            }
        });
    ScalarImage::from_values(width, height, values)
        .unwrap_or_else(|| ScalarImage::new(width, height))
}

/// The X-ray image `∫ f ds` along each pixel's ray (data units × world units), trapezoid rule
/// with `⌈L/step⌉` equal intervals between the exact entry and exit points (`L` the clipped
/// length). Rays that miss the volume give 0. Sub-pixel rays are averaged.
pub fn reference_xray(
    vol: &Volume<f32>,
    proj: &Projection,
    settings: &ReferenceSettings,
) -> ScalarImage {
    let step = settings.step_for(vol.grid());
    render_scalar(vol, proj, settings, |rays, x, y| {
        let mut sum = 0.0f64;
        let mut count = 0usize;
        rays.for_each_ray(x, y, |ray| {
            count += 1;
            let Some((_, len, q0, dq)) = rays.clip(&ray) else {
                return;
            };
            if len <= 0.0 {
                return;
            }
            let intervals = (len / step).ceil().max(1.0) as usize;
            let h = len / intervals as f64;
            let mut acc = 0.5 * (trilinear(vol, q0) + trilinear(vol, q0 + dq * len));
            for i in 1..intervals {
                acc += trilinear(vol, q0 + dq * (i as f64 * h));
            }
            sum += acc * h;
        });
        (sum / count.max(1) as f64) as f32
    })
}

/// Extremum of the samples along each ray: `better(candidate, current)` picks.
fn extremum_image(
    vol: &Volume<f32>,
    proj: &Projection,
    settings: &ReferenceSettings,
    better: fn(f64, f64) -> bool,
) -> ScalarImage {
    let step = settings.step_for(vol.grid());
    render_scalar(vol, proj, settings, |rays, x, y| {
        let mut sum = 0.0f64;
        let mut hits = 0usize;
        rays.for_each_ray(x, y, |ray| {
            let Some((_, len, q0, dq)) = rays.clip(&ray) else {
                return;
            };
            let intervals = (len / step).ceil().max(1.0) as usize;
            let h = len / intervals as f64;
            let mut best = trilinear(vol, q0);
            for i in 1..=intervals {
                let v = trilinear(vol, q0 + dq * (i as f64 * h));
                if better(v, best) {
                    best = v;
                }
            }
            sum += best;
            hits += 1;
        });
        if hits == 0 {
            f32::NAN
        } else {
            (sum / hits as f64) as f32
        }
    })
}

/// Maximum intensity projection: the largest trilinear sample along each ray (samples every
/// ≤ `step` world units, entry and exit included), data units. Rays that miss the volume give
/// `f32::NAN`; with supersampling, the maxima of the sub-pixel rays that hit are averaged.
pub fn reference_mip(
    vol: &Volume<f32>,
    proj: &Projection,
    settings: &ReferenceSettings,
) -> ScalarImage {
    extremum_image(vol, proj, settings, |v, best| v > best)
}

/// Minimum intensity projection, the counterpart of [`reference_mip`]: the smallest sample
/// along each ray; `f32::NAN` for rays that miss the volume.
pub fn reference_minip(
    vol: &Volume<f32>,
    proj: &Projection,
    settings: &ReferenceSettings,
) -> ScalarImage {
    extremum_image(vol, proj, settings, |v, best| v < best)
}

/// Accumulated opacity at which a ray stops (the remaining contribution is below 1e-6).
/// The trilinear blend over the cell at `p_index` of `f` evaluated with each corner's voxel
/// gradient (f64 weights), `None` where every corner gives `None`.
fn corner_blend(
    grads: &[[f32; 3]],
    grid: &Grid,
    p_index: DVec3,
    f: impl Fn(Vec3) -> Option<Rgba>,
) -> Option<Rgba> {
    let mut sum = [0.0f64; 4];
    let mut any = false;
    for (idx, w) in cell_corners(grid, p_index) {
        if let Some(c) = f(Vec3::from(grads[idx])) {
            any = true;
            for ch in 0..4 {
                sum[ch] += w * c[ch] as f64;
            }
        }
    }
    any.then(|| sum.map(|v| v as f32))
}

const OPAQUE: f32 = 1.0 - 1e-6;

/// Direct volume rendering by ray casting: premultiplied RGBA, no background.
///
/// Each clipped ray is cut into segments of `step` world units from its entry point (the last
/// one shorter); each segment is represented by a sample at its midpoint with density
/// (trilinear), world gradient (trilinear interpolation of [`voxel_gradients`], only if the
/// tables need it) and depth (distance along the view, normalised to [0, 1] over the volume's
/// eight corners), classified by `FrameClassifier::new(tables, proj.frame(), step)` (Westover
/// §3.6) and composited front to back with [`over_front_to_back`]. The step is measured along
/// the ray in world units for both projections, so the CRIO opacity correction
/// `1 − (1 − α)^(step/unit)` uses the true path length of a perspective ray too; lights and the
/// specular half-vector are those of the frame (viewer at infinity along the direction of
/// projection, as in Westover's per-frame classification), also for perspective views. The
/// last, shorter segment of length `ℓ` has its opacity rescaled to `1 − (1 − a)^(ℓ/step)` and
/// its colour by the same factor (exact for unmodulated opacity). Rays stop once opacity
/// exceeds `1 − 10⁻⁶`. Sub-pixel rays are averaged.
pub fn reference_composite(
    vol: &Volume<f32>,
    proj: &Projection,
    tables: &CrioTables,
    settings: &ReferenceSettings,
) -> Image {
    let grid = vol.grid();
    let step = settings.step_for(grid);
    let frame = *proj.frame();
    let classifier = FrameClassifier::new(tables, &frame, step);
    let grads = classifier.needs_gradient.then(|| voxel_gradients(vol));
    let forward = frame.forward;
    let depths = grid
        .drawn_corners_world()
        .map(|c| (c - frame.eye).dot(forward));
    let dmin = depths.iter().fold(f64::INFINITY, |m, &d| m.min(d));
    let dmax = depths.iter().fold(f64::NEG_INFINITY, |m, &d| m.max(d));
    let depth_scale = if dmax > dmin {
        1.0 / (dmax - dmin)
    } else {
        0.0
    };
    let rays = Rays {
        vol,
        proj,
        n: settings.rays_per_axis(),
        extent: settings.extent,
    };
    let (width, height) = proj.size();
    let mut pixels = vec![[0.0f32; 4]; width * height];
    if pixels.is_empty() {
        return Image::new(width, height);
    }
    pixels
        .par_chunks_mut(width)
        .enumerate()
        .for_each(|(y, row)| {
            for (x, px) in row.iter_mut().enumerate() {
                let mut sum = [0.0f64; 4];
                let mut count = 0usize;
                rays.for_each_ray(x, y, |ray| {
                    count += 1;
                    let Some((t0, len, q0, dq)) = rays.clip(&ray) else {
                        return;
                    };
                    let mut acc: Rgba = [0.0; 4];
                    let mut start = 0.0f64;
                    while start < len && acc[3] < OPAQUE {
                        let seg = step.min(len - start);
                        let mid = start + 0.5 * seg;
                        start += step;
                        let q = q0 + dq * mid;
                        let density = trilinear(vol, q) as f32;
                        if classifier.density_opacity(density) == Some(0.0) {
                            continue;
                        }
                        let p_world = ray.origin + ray.dir * (t0 + mid);
                        let depth = ((p_world - frame.eye).dot(forward) - dmin) * depth_scale;
                        let depth = depth.clamp(0.0, 1.0) as f32;
                        let classified = match &grads {
                            Some(g) if settings.shade_at_voxels => {
                                corner_blend(g, grid, q, |gradient| {
                                    classifier.classify(&SampleInput {
                                        density,
                                        gradient,
                                        depth,
                                    })
                                })
                            }
                            _ => classifier.classify(&SampleInput {
                                density,
                                gradient: match &grads {
                                    Some(g) => trilinear_gradient(g, grid, q),
                                    None => Vec3::ZERO,
                                },
                                depth,
                            }),
                        };
                        let Some(mut rgba) = classified else {
                            continue;
                        };
                        if seg < step {
                            let a = rgba[3];
                            let a_seg = if a >= 1.0 {
                                1.0
                            } else {
                                1.0 - (1.0 - a).powf((seg / step) as f32)
                            };
                            let scale = if a > 0.0 { a_seg / a } else { 0.0 };
                            rgba = rgba.map(|c| c * scale);
                        }
                        over_front_to_back(&mut acc, rgba);
                    }
                    for c in 0..4 {
                        sum[c] += acc[c] as f64;
                    }
                });
                let inv = 1.0 / count.max(1) as f64;
                *px = sum.map(|s| (s * inv) as f32);
            }
        });
    Image::from_pixels(width, height, pixels).unwrap_or_else(|| Image::new(width, height))
}

/// The closed-form X-ray image of a phantom: each pixel's (sub-pixel-averaged) exact line
/// integral [`Phantom::line_integral`] along the pixel's ray (the same rays as the reference
/// integrator), over the whole line (data units × world units; background excluded). `None` if
/// the phantom has no closed form. For a perspective view the part of the line behind the eye
/// is included too, so compare with [`reference_xray`] only for an eye outside the phantom's
/// support. Note that a volume sampled from the phantom is truncated at its bounds while this
/// integral is not.
pub fn analytic_xray<P: Phantom + ?Sized>(
    phantom: &P,
    proj: &Projection,
    supersample: usize,
) -> Option<ScalarImage> {
    let n = supersample.max(1);
    let (width, height) = proj.size();
    let probe = pixel_ray(proj, width as f64 * 0.5, height as f64 * 0.5);
    phantom.line_integral(probe.origin, probe.dir)?;
    let mut values = vec![0.0f32; width * height];
    if values.is_empty() {
        return Some(ScalarImage::new(width, height));
    }
    values
        .par_chunks_mut(width)
        .enumerate()
        .for_each(|(y, row)| {
            for (x, v) in row.iter_mut().enumerate() {
                let mut sum = 0.0;
                for sy in 0..n {
                    for sx in 0..n {
                        let rx = x as f64 + (sx as f64 + 0.5) / n as f64;
                        let ry = y as f64 + (sy as f64 + 0.5) / n as f64;
                        let ray = pixel_ray(proj, rx, ry);
                        sum += phantom
                            .line_integral(ray.origin, ray.dir)
                            .unwrap_or(f64::NAN);
                    }
                }
                *v = (sum / (n * n) as f64) as f32;
            }
        });
    ScalarImage::from_values(width, height, values)
}

#[cfg(test)]
mod tests {
    use super::*;
    use volsplat_core::crio::{LookupTable, Shading};
    use volsplat_core::glam::DMat3;
    use volsplat_core::phantom::{Blob, GaussianBlobs, sample};
    use volsplat_core::{Camera, OrthoProjection};

    fn ortho(focal: DVec3, from: DVec3, up: DVec3, scale: f64, w: usize, h: usize) -> Projection {
        let cam = Camera {
            position: (focal + from).to_array(),
            focal_point: focal.to_array(),
            view_up: up.to_array(),
            view_angle: 30.0,
            parallel_projection: true,
            parallel_scale: scale,
        };
        Projection::Ortho(OrthoProjection::new(&cam, w, h).unwrap())
    }

    fn constant_tables(color: [f32; 3], alpha: f32, unit: f64) -> CrioTables {
        CrioTables {
            emission: LookupTable::constant(color),
            opacity: LookupTable::constant([alpha]),
            reflection: LookupTable::constant([0.0; 3]),
            modulation: LookupTable::constant([1.0]),
            opacity_unit_distance: unit,
            shading: Shading::default(),
        }
    }

    fn constant_volume(dims: [usize; 3], value: f32) -> Volume<f32> {
        let grid = Grid::with_dims(dims).unwrap();
        Volume::new(grid, vec![value; dims[0] * dims[1] * dims[2]]).unwrap()
    }

    #[test]
    fn xray_of_sampled_blob_matches_closed_form() {
        let blobs = GaussianBlobs::new(vec![Blob {
            center: DVec3::new(0.05, -0.03, 0.02),
            sigma: 0.3,
            amplitude: 0.8,
        }]);
        let vol = sample(&blobs, [97, 97, 97], 1).unwrap();
        let mut cam = Camera::reset_to_bounds(blobs.bounds.0, blobs.bounds.1, true);
        cam.azimuth(30.0);
        cam.elevation(20.0);
        cam.orthogonalize_view_up();
        cam.parallel_scale = 1.0;
        let proj = Projection::Ortho(OrthoProjection::new(&cam, 40, 40).unwrap());
        let img = reference_xray(&vol, &proj, &ReferenceSettings::default());
        let exact = analytic_xray(&blobs, &proj, 1).unwrap();
        let peak = exact.values().iter().fold(0.0f32, |m, &v| m.max(v));
        let mut checked = 0;
        for (got, want) in img.values().iter().zip(exact.values()) {
            if *want > 0.1 * peak {
                checked += 1;
                let rel = ((got - want) / want).abs();
                assert!(rel < 0.005, "{got} vs {want}: {rel}");
            }
        }
        assert!(checked > 100, "{checked}");
    }

    #[test]
    fn xray_of_constant_box_is_the_chord_length() {
        // Unit values in a 40 × 40 × 4 box seen 30° off its normal: L = 4 / cos 30°.
        let vol = constant_volume([41, 41, 5], 1.0);
        let theta = 30f64.to_radians();
        let proj = ortho(
            DVec3::new(20.0, 20.0, 2.0),
            DVec3::new(0.0, -theta.sin(), theta.cos()) * 100.0,
            DVec3::Y,
            4.0,
            8,
            8,
        );
        let img = reference_xray(&vol, &proj, &ReferenceSettings::default());
        let expect = 4.0 / theta.cos();
        for v in img.values() {
            assert!((*v as f64 - expect).abs() < 1e-5, "{v} vs {expect}");
        }
        // Rays that miss the box integrate to 0.
        let far = ortho(
            DVec3::new(100.0, 0.0, 0.0),
            DVec3::Z * 10.0,
            DVec3::Y,
            1.0,
            2,
            2,
        );
        assert!(
            reference_xray(&vol, &far, &ReferenceSettings::default())
                .values()
                .iter()
                .all(|&v| v == 0.0)
        );
    }

    /// Decision 0023: a single slice is one spacing thick (it integrated to 0 before), a slice of
    /// two samples too; under `Extent::Cells` two samples are two spacings thick.
    #[test]
    fn thin_volumes_have_the_extent_of_their_voxels() {
        let theta = 30f64.to_radians();
        for (nz, spacing, centres, cells) in [
            (1usize, 1.5, 1.5, 1.5),
            (2, 1.5, 1.5, 3.0),
            (3, 0.5, 1.0, 1.5),
        ] {
            let grid =
                Grid::new([41, 41, nz], [1.0, 1.0, spacing], [0.0; 3], DMat3::IDENTITY).unwrap();
            let vol = Volume::new(grid, vec![2.0f32; 41 * 41 * nz]).unwrap();
            let z = (nz - 1) as f64 * spacing * 0.5;
            let proj = ortho(
                DVec3::new(20.0, 20.0, z),
                DVec3::new(0.0, -theta.sin(), theta.cos()) * 100.0,
                DVec3::Y,
                4.0,
                8,
                8,
            );
            for (extent, thick) in [(Extent::Centres, centres), (Extent::Cells, cells)] {
                let settings = ReferenceSettings {
                    extent,
                    ..ReferenceSettings::default()
                };
                let expect = 2.0 * thick / theta.cos();
                for v in reference_xray(&vol, &proj, &settings).values() {
                    assert!(
                        (*v as f64 - expect).abs() < 1e-5,
                        "{nz} samples, {extent:?}: {v} vs {expect}"
                    );
                }
                let (alpha, unit) = (0.3f32, 1.5);
                let tables = constant_tables([1.0; 3], alpha, unit);
                let a = 1.0 - (1.0 - alpha as f64).powf(thick / theta.cos() / unit);
                for p in reference_composite(&vol, &proj, &tables, &settings).pixels() {
                    assert!((p[3] as f64 - a).abs() < 2e-5, "{nz}: {} vs {a}", p[3]);
                }
                for v in reference_mip(&vol, &proj, &settings).values() {
                    assert_eq!(*v, 2.0);
                }
            }
        }
    }

    #[test]
    fn composite_of_constant_slab_matches_closed_form() {
        let vol = constant_volume([41, 41, 5], 1.0);
        let (color, alpha, unit) = ([0.2f32, 0.6, 0.9], 0.3f32, 1.5);
        let tables = constant_tables(color, alpha, unit);
        for deg in [0.0f64, 30.0, 50.0] {
            let theta = deg.to_radians();
            let proj = ortho(
                DVec3::new(20.0, 20.0, 2.0),
                DVec3::new(0.0, -theta.sin(), theta.cos()) * 100.0,
                DVec3::Y,
                3.0,
                6,
                6,
            );
            let len = 4.0 / theta.cos();
            let a = 1.0 - (1.0 - alpha as f64).powf(len / unit);
            for settings in [
                ReferenceSettings::default(),
                ReferenceSettings {
                    step: 0.37,
                    supersample: 2,
                    ..ReferenceSettings::default()
                },
            ] {
                let img = reference_composite(&vol, &proj, &tables, &settings);
                for p in img.pixels() {
                    assert!((p[3] as f64 - a).abs() < 2e-5, "{deg}°: {} vs {a}", p[3]);
                    for c in 0..3 {
                        assert!((p[c] as f64 - color[c] as f64 * a).abs() < 2e-5);
                    }
                }
            }
        }
    }

    #[test]
    fn mip_and_minip_of_a_bright_block() {
        let grid = Grid::with_dims([21, 21, 21]).unwrap();
        let vol = Volume::from_fn(grid, |i, j, k| {
            if [i, j, k].iter().all(|c| (8..=10).contains(c)) {
                5.0
            } else {
                0.0
            }
        })
        .unwrap();
        // Pixel size 1; pixel x sees world x − 2, pixel y sees world y = 20 − y.
        let proj = ortho(DVec3::splat(10.0), DVec3::Z * 50.0, DVec3::Y, 10.5, 25, 21);
        let mip = reference_mip(&vol, &proj, &ReferenceSettings::default());
        let minip = reference_minip(&vol, &proj, &ReferenceSettings::default());
        for y in 0..21 {
            for x in 0..25 {
                let (wx, wy) = (x as i64 - 2, 20 - y as i64);
                let (m, n) = (mip.get(x, y), minip.get(x, y));
                if !(0..=20).contains(&wx) {
                    assert!(m.is_nan() && n.is_nan(), "({x}, {y}) should miss");
                } else if (8..=10).contains(&wx) && (8..=10).contains(&wy) {
                    assert_eq!((m, n), (5.0, 0.0), "({x}, {y})");
                } else {
                    assert_eq!((m, n), (0.0, 0.0), "({x}, {y})");
                }
            }
        }
        // Obliquely, the ray through the block's centre still finds the maximum.
        let proj = ortho(DVec3::splat(9.0), DVec3::ONE * 50.0, DVec3::Y, 10.0, 21, 21);
        let mip = reference_mip(&vol, &proj, &ReferenceSettings::default());
        let c = proj.raster_from_world(DVec3::splat(9.0));
        assert_eq!(mip.get(c.x as usize, c.y as usize), 5.0);
    }

    #[test]
    fn gradients_of_a_linear_field_are_exact() {
        // f = 2x + 3y − z in world, on a rotated grid with anisotropic spacing.
        let rot = DMat3::from_euler(volsplat_core::glam::EulerRot::ZYX, 0.3, -0.5, 0.2);
        let grid = Grid::new([6, 5, 4], [0.5, 1.5, 2.0], [1.0, -2.0, 3.0], rot).unwrap();
        let g = DVec3::new(2.0, 3.0, -1.0);
        let vol = Volume::from_fn(grid.clone(), |i, j, k| {
            g.dot(grid.world_from_index(DVec3::new(i as f64, j as f64, k as f64))) as f32
        })
        .unwrap();
        for v in voxel_gradients(&vol) {
            assert!((DVec3::new(v[0] as f64, v[1] as f64, v[2] as f64) - g).length() < 1e-4);
        }
        // Trilinear interpolation reproduces the linear field.
        let p = DVec3::new(2.3, 1.7, 2.9);
        let want = g.dot(grid.world_from_index(p));
        assert!((trilinear(&vol, p) - want).abs() < 1e-4);
    }

    #[test]
    fn images_do_not_depend_on_the_thread_count() {
        let vol = sample(&GaussianBlobs::demo(), [24, 20, 22], 1).unwrap();
        let mut cam = Camera::reset_to_bounds(DVec3::splat(-1.0), DVec3::splat(1.0), true);
        cam.azimuth(25.0);
        cam.elevation(-35.0);
        cam.orthogonalize_view_up();
        let proj = Projection::Ortho(OrthoProjection::new(&cam, 33, 29).unwrap());
        let mut tables = constant_tables([1.0, 0.5, 0.2], 0.2, 0.3);
        tables.opacity =
            LookupTable::from_fn(volsplat_core::TableIndex::Density, 0.0, 1.0, 64, |x| [x]);
        tables.shading.diffuse = true;
        tables.reflection = LookupTable::constant([0.5; 3]);
        let settings = ReferenceSettings {
            step: 0.05,
            supersample: 2,
            ..ReferenceSettings::default()
        };
        cam.parallel_projection = false;
        cam.dolly(1.5);
        let persp = Projection::new(&cam, 33, 29).unwrap();
        let run = |threads: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| {
                    (
                        reference_composite(&vol, &proj, &tables, &settings),
                        reference_xray(&vol, &proj, &settings),
                        reference_composite(&vol, &persp, &tables, &settings),
                        reference_mip(&vol, &persp, &settings),
                    )
                })
        };
        let (a, b) = (run(1), run(3));
        assert_eq!(a.0, b.0);
        assert_eq!(a.1, b.1);
        assert_eq!(a.2, b.2);
        // MIP images hold NaN for missed rays; compare bit patterns.
        let bits = |img: &ScalarImage| img.values().iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&a.3), bits(&b.3));
        assert!(a.0.pixels().iter().any(|p| p[3] > 0.1));
        assert!(a.2.pixels().iter().any(|p| p[3] > 0.1));
    }

    /// A perspective camera looking at `focal` from `focal + from`.
    fn perspective(
        focal: DVec3,
        from: DVec3,
        up: DVec3,
        fov: f64,
        w: usize,
        h: usize,
    ) -> Projection {
        let cam = Camera {
            position: (focal + from).to_array(),
            focal_point: focal.to_array(),
            view_up: up.to_array(),
            view_angle: fov,
            parallel_projection: false,
            parallel_scale: 1.0,
        };
        Projection::new(&cam, w, h).unwrap()
    }

    #[test]
    fn perspective_xray_of_sampled_blobs_matches_closed_form() {
        let blobs = GaussianBlobs::new(vec![
            Blob {
                center: DVec3::new(0.05, -0.03, 0.02),
                sigma: 0.3,
                amplitude: 0.8,
            },
            Blob {
                center: DVec3::new(-0.2, 0.25, -0.1),
                sigma: 0.2,
                amplitude: 1.0,
            },
        ]);
        let vol = sample(&blobs, [97, 97, 97], 1).unwrap();
        let mut cam = Camera::reset_to_bounds(blobs.bounds.0, blobs.bounds.1, false);
        cam.azimuth(30.0);
        cam.elevation(20.0);
        cam.orthogonalize_view_up();
        cam.dolly(1.4);
        let proj = Projection::new(&cam, 40, 36).unwrap();
        // Strong perspective: the rays diverge by tens of degrees across the image.
        let (_, d0) = proj.ray(0.5, 0.5);
        let (_, d1) = proj.ray(39.5, 35.5);
        assert!(d0.dot(d1) < 0.92, "{}", d0.dot(d1));
        for n in [1, 2] {
            let settings = ReferenceSettings {
                step: 0.0,
                supersample: n,
                ..ReferenceSettings::default()
            };
            let img = reference_xray(&vol, &proj, &settings);
            let exact = analytic_xray(&blobs, &proj, n).unwrap();
            let err = crate::metrics::relative_l2(img.values(), exact.values());
            eprintln!("perspective X-ray, {n}×{n} rays/pixel: relative L2 error {err:.2e}");
            assert!(err < 2e-3, "{err}");
            assert!(img.values().iter().all(|v| v.is_finite()));
        }
    }

    #[test]
    fn perspective_eye_inside_the_volume_integrates_the_forward_half_ray() {
        // The eye sits on the centre of a Gaussian: every ray's forward half-line carries
        // exactly half of the full line integral, A·σ·√(2π)/2.
        let (a, sigma) = (1.0, 0.25);
        let blobs = GaussianBlobs::new(vec![Blob {
            center: DVec3::ZERO,
            sigma,
            amplitude: a,
        }]);
        let vol = sample(&blobs, [81, 81, 81], 1).unwrap();
        let proj = perspective(
            DVec3::ZERO,
            DVec3::new(0.3, -0.2, 1.0),
            DVec3::Y,
            70.0,
            24,
            20,
        );
        // Move the eye onto the blob's centre, looking the same way.
        let Projection::Perspective(mut p) = proj else {
            unreachable!()
        };
        let shift = p.frame.eye;
        p.frame.eye -= shift;
        p.frame.focal -= shift;
        let proj = Projection::Perspective(p);
        let half = 0.5 * a * sigma * (2.0 * std::f64::consts::PI).sqrt();
        let settings = ReferenceSettings {
            step: 0.0,
            supersample: 2,
            ..ReferenceSettings::default()
        };
        let img = reference_xray(&vol, &proj, &settings);
        let mut worst = 0.0f64;
        for &v in img.values() {
            assert!(v.is_finite());
            worst = worst.max((v as f64 / half - 1.0).abs());
        }
        eprintln!("eye inside: worst relative error of the half-ray integral {worst:.2e}");
        assert!(worst < 3e-3, "{worst}");
        // MIP: the maximum is at the eye; MinIP: the far tail; composite: finite everywhere.
        let mip = reference_mip(&vol, &proj, &settings);
        let minip = reference_minip(&vol, &proj, &settings);
        for (m, n) in mip.values().iter().zip(minip.values()) {
            assert!((*m as f64 - a).abs() < 1e-3, "{m}");
            assert!(*n < 1e-3, "{n}");
        }
        let tables = constant_tables([1.0, 0.5, 0.25], 0.2, 0.3);
        let comp = reference_composite(&vol, &proj, &tables, &settings);
        assert!(comp.pixels().iter().flatten().all(|c| c.is_finite()));
        // The eye and everything within 0.9 of it lies inside [-1, 1]³, so every ray has
        // path length ≥ 0.9 of constant opacity: α ≥ 1 − 0.8^3.
        for px in comp.pixels() {
            assert!(px[3] as f64 > 1.0 - 0.8f64.powi(3), "{}", px[3]);
        }
    }

    #[test]
    fn perspective_composite_of_a_constant_box_uses_the_path_length_along_the_ray() {
        // Eye on the axis in front of a slab 4 thick: a ray at angle θ to the slab normal
        // crosses 4/cos θ world units, so α = 1 − (1 − α₀)^(4/(cos θ · unit)).
        let vol = constant_volume([41, 41, 5], 1.0);
        let (color, alpha, unit) = ([0.2f32, 0.6, 0.9], 0.3f32, 1.5);
        let tables = constant_tables(color, alpha, unit);
        let proj = perspective(
            DVec3::new(20.0, 20.0, 2.0),
            DVec3::Z * 20.0,
            DVec3::Y,
            60.0,
            9,
            9,
        );
        for settings in [
            ReferenceSettings::default(),
            ReferenceSettings {
                step: 0.37,
                supersample: 1,
                ..ReferenceSettings::default()
            },
        ] {
            let img = reference_composite(&vol, &proj, &tables, &settings);
            for y in 0..9 {
                for x in 0..9 {
                    let (_, dir) = proj.ray(x as f64 + 0.5, y as f64 + 0.5);
                    let len = 4.0 / dir.dot(-DVec3::Z);
                    let a = 1.0 - (1.0 - alpha as f64).powf(len / unit);
                    let p = img.pixels()[y * 9 + x];
                    assert!(
                        (p[3] as f64 - a).abs() < 2e-5,
                        "({x}, {y}): {} vs {a}",
                        p[3]
                    );
                }
            }
        }
        // A volume entirely behind the eye is invisible in perspective.
        let behind = perspective(
            DVec3::new(20.0, 20.0, 30.0),
            DVec3::Z * -5.0,
            DVec3::Y,
            60.0,
            4,
            4,
        );
        let img = reference_xray(&vol, &behind, &ReferenceSettings::default());
        assert!(img.values().iter().all(|&v| v == 0.0));
    }
}
