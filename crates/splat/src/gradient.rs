//! One-sided and central differences of the voxel data: the gradient that shading and gradient
//! opacity read, shared by the sheet renderer, the splat-list renderer and the normal field
//! ([`crate::normals::NormalField`]). The image-aligned slabs difference their own samples
//! ([`crate::slab`]).

// Both are `#[inline(always)]`: in their own module, plain `#[inline]` left `index_gradient_in`
// out of the dense renderer's classification loop, +0.35 ms per 512² frame of the built-in MRI
// (`bench --visibility sheet --orbit 0`, 2 threads: classify 5.7 against 5.3-5.5 ms).

use crate::voxels::Voxels;
use volsplat_core::Scalar;
use volsplat_core::glam::{Mat3, Vec3};

/// World-space gradient at full-resolution voxel `p`, reading the voxels through `vox` (the
/// brick seam, docs/design/brick-seam.md §2.2: [`Linear`](crate::voxels::Linear) today): central differences divided by
/// 2·spacing (one-sided differences divided by spacing at the border), rotated into world by the
/// direction matrix (`docs/architecture.md`, the LPS world frame). Data units per world unit.
/// Faces are tested on the global index `p` against `dims_full`, the values loaded at
/// [`Voxels::linear`]`(p) ± stride`.
#[inline(always)]
pub(crate) fn gradient_in<T: Scalar>(
    vox: &impl Voxels<T>,
    dims_full: [usize; 3],
    inv_spacing_full: [f32; 3],
    direction: Mat3,
    p: [usize; 3],
) -> Vec3 {
    let [nx, ny, nz] = dims_full;
    let lin = vox.linear(p);
    let strides = vox.stride();
    let data = vox.data();
    if p[0] > 0 && p[1] > 0 && p[2] > 0 && p[0] + 1 < nx && p[1] + 1 < ny && p[2] + 1 < nz {
        // Interior: central differences on all three axes, no border cases.
        let d = |s: usize| data[lin + s].to_f32() - data[lin - s].to_f32();
        let g = Vec3::new(
            d(1) * inv_spacing_full[0],
            d(strides[1]) * inv_spacing_full[1],
            d(strides[2]) * inv_spacing_full[2],
        ) * 0.5;
        return direction * g;
    }
    // On a face: `index_gradient_in`'s differences, each then times its inverse spacing (the same
    // operations in the same order as `(ρ(hi) − ρ(lo)) · half · 1/spacing`).
    let g = index_gradient_in(vox, dims_full, p);
    direction
        * Vec3::new(
            g[0] * inv_spacing_full[0],
            g[1] * inv_spacing_full[1],
            g[2] * inv_spacing_full[2],
        )
}

/// Central differences at full-resolution voxel `p` in index units (data units per voxel
/// step), reading the voxels through `vox`: `(ρ(p + e) − ρ(p − e)) · ½`, one-sided
/// `(ρ(p + e) − ρ(p)) · 1` on the faces, 0 along an axis of one voxel; [`gradient_in`] before its
/// spacing and direction. Faces tested on the global `p`, values loaded at
/// [`Voxels::linear`]`(p) ± stride`.
#[inline(always)]
pub(crate) fn index_gradient_in<T: Scalar>(
    vox: &impl Voxels<T>,
    dims_full: [usize; 3],
    p: [usize; 3],
) -> [f32; 3] {
    let lin = vox.linear(p);
    let strides = vox.stride();
    let data = vox.data();
    let mut g = [0.0f32; 3];
    for c in 0..3 {
        let n = dims_full[c];
        if n < 2 {
            continue;
        }
        let s = strides[c];
        let v = |q: usize| data[q].to_f32();
        g[c] = if p[c] == 0 {
            (v(lin + s) - v(lin)) * 1.0
        } else if p[c] == n - 1 {
            (v(lin) - v(lin - s)) * 1.0
        } else {
            (v(lin + s) - v(lin - s)) * 0.5
        };
    }
    g
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::voxels::Linear;

    /// Both helpers compute, bit for bit, the differences as the renderers wrote them before
    /// they shared these helpers: per axis `(ρ(hi) − ρ(lo)) · h · 1/spacing` with `h` ½
    /// (central) or 1 (one-sided on a face), 0 along an axis of one voxel; interior voxels
    /// `(ρ(p + e) − ρ(p − e)) · 1/spacing · ½`; then the direction matrix. Every voxel of grids
    /// with faces, edges, corners and a one-voxel axis, on irregular data.
    #[test]
    fn differences_match_the_written_out_formulas_bit_for_bit() {
        let direction = Mat3::from_cols(
            Vec3::new(0.8, 0.6, 0.0),
            Vec3::new(-0.6, 0.8, 0.0),
            Vec3::new(0.0, 0.0, 1.0),
        );
        for dims in [[5, 4, 3], [4, 1, 3], [2, 2, 2]] {
            let n = dims[0] * dims[1] * dims[2];
            let data: Vec<f32> = (0..n)
                .map(|q| ((q * 7919) % 101) as f32 * 0.37 - 11.0)
                .collect();
            let inv = [1.0 / 0.7f32, 1.0 / 1.3, 1.0 / 2.1];
            let strides = [1, dims[0], dims[0] * dims[1]];
            for k in 0..dims[2] {
                for j in 0..dims[1] {
                    for i in 0..dims[0] {
                        let p = [i, j, k];
                        let lin = i + dims[0] * (j + dims[1] * k);
                        let mut idx = [0.0f32; 3];
                        let mut world = Vec3::ZERO;
                        for c in 0..3 {
                            if dims[c] < 2 {
                                continue;
                            }
                            let s = strides[c];
                            let (lo, hi, h) = if p[c] == 0 {
                                (lin, lin + s, 1.0)
                            } else if p[c] == dims[c] - 1 {
                                (lin - s, lin, 1.0)
                            } else {
                                (lin - s, lin + s, 0.5)
                            };
                            idx[c] = (data[hi] - data[lo]) * h;
                            world[c] = (data[hi] - data[lo]) * h * inv[c];
                        }
                        let interior = (0..3).all(|c| p[c] > 0 && p[c] + 1 < dims[c]);
                        if interior {
                            let d = |c: usize| data[lin + strides[c]] - data[lin - strides[c]];
                            world = Vec3::new(d(0) * inv[0], d(1) * inv[1], d(2) * inv[2]) * 0.5;
                        }
                        let want = direction * world;
                        let vox = Linear::from_parts(&data, dims);
                        let got = gradient_in(&vox, dims, inv, direction, p);
                        assert_eq!(
                            got.to_array().map(f32::to_bits),
                            want.to_array().map(f32::to_bits),
                            "{dims:?} {p:?}"
                        );
                        let got = index_gradient_in(&Linear::from_parts(&data, dims), dims, p);
                        assert_eq!(
                            got.map(f32::to_bits),
                            idx.map(f32::to_bits),
                            "{dims:?} {p:?}"
                        );
                    }
                }
            }
        }
    }
}
