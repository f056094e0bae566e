//! Shading a sample: the lights on the reconstruction's gradient (at the sample), or the
//! voxels' light interpolated (at the voxels, [`crate::normals`]); and the gradients.

use super::march::{Ctx, RowCtx};
use super::math::{exp2_neg, lerp, max_ps, min_ps};
use super::tables::ShadeTable;
use super::view::Walk;
use crate::normals::VoxelShading;
use crate::voxels::Voxels;
use volsplat_core::Scalar;
use volsplat_core::glam::Vec3;
use volsplat_core::image::Rgba;

/// The premultiplied, shaded colour of a sample of density `rho` whose interpolated voxel
/// gradient is `g` ([`Ctx::gradient_lerp`], index units), with slab exponent `k`, or `None`
/// where it has no opacity: [`FrameClassifier::classify`]'s formula (emission, then per
/// light the diffuse term `d·c_L·(N·L)` and the specular term `s·c_L·(N·H)^n` where `N·L > 0`
/// (`|N·L|` two-sided), clamped to [0, 1], times the opacity), with the terms read from
/// [`ShadeTable`]. The scalar twin of [`shade_terms8`] and [`shade_light8`]: every operation in the same order, the
/// `if`s written as the kernel's masks (a term that does not apply adds `+0`) and the clamps
/// as `maxps`/`minps`, so the bits agree.
///
/// [`shade_terms8`]: super::avx2::shade::shade_terms8
/// [`shade_light8`]: super::avx2::shade::shade_light8
/// [`FrameClassifier::classify`]: volsplat_core::FrameClassifier::classify
#[inline(always)]
pub(crate) fn shaded_src(
    t: &ShadeTable,
    rho: f32,
    g: [f32; 3],
    k: f32,
    corrected: bool,
) -> Option<Rgba> {
    let v = t.entry(rho);
    let a = shade_opacity(&v, k, corrected)?;
    Some(premultiplied(lit_colour(t, &v, g, |x| t.spec(x)), a))
}

/// The premultiplied, shaded colour of a sample with [`ShadeTable`] entry `v` (at its density,
/// [`ShadeTable::entry`], or its segment's, [`ShadeTable::segment_entry`]) in a slab of the
/// image-aligned slabs lit at the samples (decision 0036): [`shaded_src`]'s colour lit at each
/// of the two index-space gradients `g` (at `±¼` of the slab's step from the sample, or at ¼
/// and ¾ of a pre-integrated segment: `light_fractions`, [`Ctx::gradient_lerp`]), each clamped to [0, 1], averaged, and multiplied by the sample's
/// opacity; the specular power by [`ShadeTable::spec_at_sample`]. The light is then the
/// two-point midpoint rule over the slab's extent, where one light at the sample is the
/// one-point rule. The scalar twin of [`ShadeSource`]'s `src` ([`shade_light8`] twice, then
/// `average8`): every operation in the same order.
///
/// [`ShadeSource`]: super::avx2::shade::ShadeSource
/// [`shade_light8`]: super::avx2::shade::shade_light8
#[inline(always)]
pub(super) fn shaded_src_two(
    t: &ShadeTable,
    v: [f32; 8],
    g: [[f32; 3]; 2],
    k: f32,
    corrected: bool,
) -> Option<Rgba> {
    let a = shade_opacity(&v, k, corrected)?;
    let spec = |x| t.spec_at_sample(x);
    let c0 = clamp01(lit_colour(t, &v, g[0], spec));
    let c1 = clamp01(lit_colour(t, &v, g[1], spec));
    Some(premultiplied(
        [0, 1, 2].map(|ch| (c0[ch] + c1[ch]) * 0.5),
        a,
    ))
}

/// The colour of a sample with [`ShadeTable`] entry `v` lit at the index-space gradient `g`,
/// before it is clamped: the emission, then per light the diffuse term `d·c_L·(N·L)` and the
/// specular term `s·c_L·spec(N·H)` where `N·L > 0` (`|N·L|` two-sided). The scalar twin of
/// [`lit_colour8`].
///
/// [`lit_colour8`]: super::avx2::shade::lit_colour8
#[inline(always)]
fn lit_colour(t: &ShadeTable, v: &[f32; 8], g: [f32; 3], spec: impl Fn(f32) -> f32) -> [f32; 3] {
    let m = &t.to_world;
    let gw: [f32; 3] = std::array::from_fn(|i| m[0][i] * g[0] + m[1][i] * g[1] + m[2][i] * g[2]);
    let g2 = gw[0] * gw[0] + gw[1] * gw[1] + gw[2] * gw[2];
    let mut col = [v[1], v[2], v[3]];
    if (t.diffuse || t.specular) && g2 > 0.0 {
        let inv = 1.0 / g2.sqrt();
        let n = gw.map(|c| c * inv);
        for light in &t.lights {
            let (l, h, lc) = (light.l, light.h, light.color.to_array());
            let mut ndl = n[0] * l.x + n[1] * l.y + n[2] * l.z;
            let mut ndh = n[0] * h.x + n[1] * h.y + n[2] * h.z;
            if t.two_sided && ndl < 0.0 {
                ndl = -ndl;
                ndh = -ndh;
            }
            let lit = ndl > 0.0;
            if !lit {
                continue;
            }
            if t.diffuse {
                for ch in 0..3 {
                    col[ch] += v[4 + ch] * lc[ch] * ndl;
                }
            }
            if t.specular && ndh > 0.0 {
                let p = spec(ndh);
                for ch in 0..3 {
                    let s = t.spec_color.map_or(v[4 + ch], |c| c[ch]);
                    col[ch] += s * lc[ch] * p;
                }
            }
        }
    }
    col
}

/// The premultiplied, shaded colour of a sample with [`ShadeTable`] entry `v` (at its density,
/// [`ShadeTable::entry`], or its segment's, [`ShadeTable::segment_entry`]) lit at fractions `f`
/// in a cell whose eight corners (`x` fastest) have the direction codes `codes`, with slab
/// exponent `k`, or `None` where it has no opacity: shaded at the voxels ([`ShadeAt::Voxels`]):
/// the diffuse and specular light of each corner's code ([`VoxelShading`]) interpolated as
/// [`Ctx::sample_cell`] interpolates the values, then `e + d·D + s·S` per channel (emission `e`
/// and reflection colour `d` from `v`; `s` the specular colour), clamped to [0, 1], times the
/// opacity. The scalar twin of [`VoxelShadeSource`]: the same f32 operations
/// in the same order.
///
/// [`ShadeAt::Voxels`]: crate::normals::ShadeAt::Voxels
/// [`VoxelShadeSource`]: super::avx2::shade::VoxelShadeSource
#[inline(always)]
pub(super) fn voxel_shaded_src(
    t: &ShadeTable,
    vs: &VoxelShading,
    v: [f32; 8],
    codes: &[u16; 8],
    f: [f32; 3],
    k: f32,
    corrected: bool,
) -> Option<Rgba> {
    let a = shade_opacity(&v, k, corrected)?;
    let mut col = [v[1], v[2], v[3]];
    let (diffuse, specular, _) = t.switches();
    if diffuse || specular {
        // Per plane: the corners' diffuse and specular units interpolated, then scaled.
        let light = |p: usize| {
            let plane = vs.plane(p);
            let w = codes.map(|q| plane[q as usize]);
            let tri = |c: [f32; 8]| {
                let c00 = lerp(c[0], c[1], f[0]);
                let c10 = lerp(c[2], c[3], f[0]);
                let c01 = lerp(c[4], c[5], f[0]);
                let c11 = lerp(c[6], c[7], f[0]);
                lerp(lerp(c00, c10, f[1]), lerp(c01, c11, f[1]), f[2])
            };
            let d = tri(w.map(|w| (w & 0xffff) as i32 as f32));
            let s = tri(w.map(|w| (w >> 16) as i32 as f32));
            [d * vs.scale[p][0], s * vs.scale[p][1]]
        };
        let l = if vs.chromatic {
            [light(0), light(1), light(2)]
        } else {
            [light(0); 3]
        };
        if diffuse {
            for ch in 0..3 {
                col[ch] += v[4 + ch] * l[ch][0];
            }
        }
        if specular {
            for ch in 0..3 {
                let sc = t.spec_color.map_or(v[4 + ch], |c| c[ch]);
                col[ch] += sc * l[ch][1];
            }
        }
    }
    Some(premultiplied(col, a))
}

/// The opacity of a shaded sample from its [`ShadeTable`] entry `v`: path-corrected
/// (`1 − 2^(k·log2(1 − α))`) where `corrected`, else `α`; `None` where it has none (NaN entries
/// contribute nothing, as in the kernels' ordered comparisons): the scalar twin of
/// [`shade_terms8`]'s opacity.
///
/// [`shade_terms8`]: super::avx2::shade::shade_terms8
#[inline(always)]
pub(super) fn shade_opacity(v: &[f32; 8], k: f32, corrected: bool) -> Option<f32> {
    if corrected {
        (v[7] < 0.0).then(|| 1.0 - exp2_neg(k * v[7]))
    } else {
        (v[0] > 0.0).then_some(v[0])
    }
}

/// Pre-integration shaded at the voxels: where along its segment a slab is lit, as the fraction
/// of the way back from this plane's sample to the plane before's: the middle. A ramp that the
/// segment crosses is crossed anywhere along it with equal chance, and the middle is where the
/// segment's path is centred. Two better-founded placements were measured against it and not
/// kept (the visible centroid of an evenly spread extinction, which lit opaque segments near
/// their front, in the air before a sharp ramp; and the centroid of a step in extinction
/// between the segment's two samples, which cost more than it gained): the numbers are in
/// `docs/decisions/0020-preintegration-for-sharp-ramps.md`, its amendment of 2026-11-25.
pub(super) const SEGMENT_LIGHT_AT: f32 = 0.5;

/// Lit at the samples: where a slab's two lights sit, as the fraction of the step between
/// planes before and after the sample (decision 0036): at `±¼`, the midpoints of the slab's two
/// halves, so that the light is the two-point midpoint rule over the slab.
pub(super) const LIGHT_SHIFT: f32 = 0.25;

/// Lit at the samples and pre-integrated: where the second light of a segment sits, as the
/// fraction of the step back towards the plane before (the first is at [`LIGHT_SHIFT`]): the
/// midpoints of the segment's two halves, as [`SEGMENT_LIGHT_AT`] is its middle.
pub(super) const SEGMENT_SECOND_LIGHT: f32 = 0.75;

/// The shaded colour `col` clamped to [0, 1] (as `maxps`/`minps` clamp) and multiplied by the
/// opacity `a`: the premultiplied RGBA of a shaded sample. The scalar twin of
/// `premultiplied8` (`avx2/shade.rs`).
#[inline(always)]
pub(super) fn premultiplied(col: [f32; 3], a: f32) -> Rgba {
    let c = clamp01(col).map(|c| c * a);
    [c[0], c[1], c[2], a]
}

/// `col` clamped to [0, 1] as `maxps`/`minps` clamp (NaN to 0): the scalar twin of `clamp01_8`
/// (`avx2/shade.rs`).
#[inline(always)]
fn clamp01(col: [f32; 3]) -> [f32; 3] {
    col.map(|c| min_ps(max_ps(c, 0.0), 1.0))
}

impl<T: Scalar, V: Voxels<T>> Ctx<'_, T, V> {
    /// The difference of the voxels around the voxel with linear index `at` (index `p`) along
    /// axis `a` (of two voxels or more), and whether it is central: `(ρ(p + 1) − ρ(p − 1), true)`
    /// inside the grid, one-sided on its faces (`ρ(p + 1) − ρ(p)` at `p = 0`, `ρ(p) − ρ(p − 1)`
    /// at `p = n − 1`; `false`). A central difference spans two index steps, so the derivative
    /// per index step is half of it. The stencil of both [`Ctx::gradient_at`] and
    /// [`Ctx::gradient_lerp`].
    #[inline(always)]
    fn difference(&self, at: usize, p: usize, a: usize) -> (f32, bool) {
        let s = self.vox.stride()[a];
        let data = self.vox.data();
        let v = |q: usize| data[q].to_f32();
        if p == 0 {
            (v(at + s) - v(at), false)
        } else if p == self.dims[a] - 1 {
            (v(at) - v(at - s), false)
        } else {
            (v(at + s) - v(at - s), true)
        }
    }

    /// The world gradient of the reconstruction in cell `c` at fractions `f` (data units per
    /// world unit; `f` may leave [0, 1], where the cell's trilinear form is extrapolated: a
    /// light's fractions, decision 0036): the tent kernel's interpolation of the voxels' central differences (one-sided on
    /// the faces of the grid), i.e. gradient splats gathered at the sample, which is what VTK's
    /// ray caster and the reference integrator shade with. Computed only for samples with
    /// opacity, by the per-sample classifier ([`Ctx::band_plain`]). Its corner weights are the
    /// products `Π (f or 1 − f)`, not [`Ctx::gradient_lerp`]'s nested interpolations: the two
    /// agree to rounding, not to the bit, so each keeps its own arithmetic (the images of the
    /// per-sample classifier were recorded with this one).
    ///
    /// [`Ctx::band_plain`]: super::march::Ctx::band_plain
    pub(super) fn gradient_at(&self, c: [usize; 3], f: [f32; 3]) -> Vec3 {
        let mut g = [0.0f32; 3];
        // The corners are reached from the cell's anchor (in bricks, its own slot, whose halo
        // holds every difference's stencil), not each from its own brick.
        let base = self.vox.cell_base(c);
        let up = self.vox.up();
        for corner in 0..8usize {
            let mut w = 1.0f32;
            let mut p = [0usize; 3];
            let mut here = base;
            for a in 0..3 {
                let is_up = corner >> a & 1 == 1;
                p[a] = c[a] + usize::from(is_up && self.dims[a] > 1);
                here += if is_up { up[a] } else { 0 };
                w *= if is_up { f[a] } else { 1.0 - f[a] };
            }
            if w == 0.0 {
                continue;
            }
            for a in 0..3 {
                if self.dims[a] < 2 {
                    continue;
                }
                let (d, central) = self.difference(here, p[a], a);
                g[a] += w * d / if central { 2.0 } else { 1.0 };
            }
        }
        self.grad_to_world[0] * g[0] + self.grad_to_world[1] * g[1] + self.grad_to_world[2] * g[2]
    }

    /// The voxels' central differences (one-sided on the faces of the grid, zero along an axis
    /// of one voxel), in data units per index step, interpolated trilinearly in cell `c` at
    /// each of the fractions `fs` (the two lights', decision 0036): per axis, the same
    /// interpolation as [`Ctx::sample_cell`] of the differences at the cell's eight corners,
    /// each `(ρ(p + e) − ρ(p − e)) · ½` (one-sided: `(ρ(p + e) − ρ(p)) · 1`), which are read
    /// once for both. The scalar twin of [`ShadeSource`]'s gradients (interior cells).
    ///
    /// [`ShadeSource`]: super::avx2::shade::ShadeSource
    #[inline(always)]
    pub(super) fn gradient_lerp(&self, c: [usize; 3], fs: [[f32; 3]; 2]) -> [[f32; 3]; 2] {
        let base = self.vox.cell_base(c);
        let [ux, uy, uz] = self.vox.up();
        // Corner k of the cell is (k & 1, k >> 1 & 1, k >> 2) voxels from its lower corner.
        let offs = [0, ux, uy, uy + ux, uz, uz + ux, uz + uy, uz + uy + ux];
        let mut g = [[0.0f32; 3]; 2];
        for a in 0..3 {
            if self.dims[a] < 2 {
                continue;
            }
            let mut d = [0.0f32; 8];
            for (k, (dk, &o)) in d.iter_mut().zip(&offs).enumerate() {
                let (d, central) = self.difference(base + o, c[a] + (k >> a & 1), a);
                *dk = d * if central { 0.5 } else { 1.0 };
            }
            for (out, f) in g.iter_mut().zip(&fs) {
                let c00 = lerp(d[0], d[1], f[0]);
                let c10 = lerp(d[2], d[3], f[0]);
                let c01 = lerp(d[4], d[5], f[0]);
                let c11 = lerp(d[6], d[7], f[0]);
                out[a] = lerp(lerp(c00, c10, f[1]), lerp(c01, c11, f[1]), f[2]);
            }
        }
        g
    }

    /// Pre-integration shaded at the voxels: the cell and fractions where the segment of
    /// pixel `x` is lit, `q + h·(back_s + x·back_st)` with `q` the sample's position
    /// ([`Ctx::cell_f32`]) and `h` the fraction [`SEGMENT_LIGHT_AT`]; the scalar twin of
    /// [`VoxelShadeSource::light_cells`].
    ///
    /// [`VoxelShadeSource::light_cells`]: super::avx2::shade::VoxelShadeSource::light_cells
    #[inline(always)]
    pub(super) fn light_cell(
        &self,
        walk: &Walk,
        row: &RowCtx<'_>,
        x: usize,
        h: f32,
    ) -> ([usize; 3], [f32; 3]) {
        let xf = x as f32;
        let mut c = [0usize; 3];
        let mut f = [0.0f32; 3];
        for a in 0..3 {
            let q = walk.s32[a] + xf * walk.st32[a];
            let q = q + h * (row.back_s[a] + xf * row.back_st[a]);
            let i = (q as i32).clamp(0, self.max_cell[a] as i32);
            c[a] = i as usize;
            f[a] = (q - i as f32).clamp(0.0, 1.0);
        }
        (c, f)
    }
}
