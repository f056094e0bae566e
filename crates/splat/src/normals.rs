//! Shading at the voxels, interpolated: the order in which VTK's CPU ray caster shades
//! (`vtkFixedPointVolumeRayCastMapper`), as an option of the image-aligned slabs
//! ([`ShadeAt::Voxels`]; decision 0019).
//!
//! Mueller, Möller & Crawfis (*Splatting without the blur*, Visualization '99, §3) and the
//! exact integral shade each sample with the gradient interpolated there ("Phong" order:
//! [`ShadeAt::Samples`]). VTK instead
//!
//! 1. estimates one gradient per voxel by central differences in world units and stores its
//!    direction as a 2-byte code (`vtkFiniteDifferenceGradientEstimator`,
//!    `vtkSphericalDirectionEncoder`),
//! 2. shades every code once per frame into diffuse and specular tables
//!    (`vtkEncodedGradientShader`), and
//! 3. per sample, interpolates the eight corners' table entries with the trilinear weights
//!    (`VTKKWRCHelper_InterpolateShading`) and applies them to the colour classified from the
//!    interpolated scalar: `c·D + S` ("Gouraud" order).
//!
//! Classification stays after reconstruction (post-classified), only the lighting is
//! interpolated. On noisy data the two orders differ visibly (the interpolated gradient of
//! noise is smaller and smoother than the voxels'); against VTK's pictures, shading at the
//! voxels scores SSIM 0.99 where shading the samples scores 0.96–0.97 (`docs/BENCHMARKS.md`
//! §15).
//!
//! Here the direction code is an octahedral map (Meyer et al. 2010, *On floating-point normal
//! vectors*): 255 × 255 cells over the unfolded octahedron (worst angular error 0.94°, a 2-byte
//! code as VTK's is), with one code, [`ZERO_NORMAL`], for voxels whose gradient is
//! zero (they reflect nothing, as a sample with a zero gradient does in
//! [`volsplat_core::FrameClassifier::classify`]).

use crate::error::{Result, try_filled};
use crate::gradient::index_gradient_in;
use crate::slab::ShadeTable;
use crate::voxels::Linear;
use rayon::prelude::*;
use volsplat_core::glam::Vec3;
use volsplat_core::{Scalar, Volume};

/// Where shaded composite evaluates the lights (image-aligned slabs only; the sheet renderers
/// shade each voxel before splatting, Westover §3.3).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ShadeAt {
    /// At every sample, with the voxels' central differences interpolated there (Mueller,
    /// Möller & Crawfis 1999; what the exact integral computes). The library's default.
    #[default]
    Samples,
    /// At the voxels, interpolated: each voxel's gradient direction is shaded once per frame
    /// and the sample takes the trilinear blend of its cell's eight corners' diffuse and
    /// specular light (VTK's CPU ray caster; [`crate::normals`]). Falls back to
    /// [`ShadeAt::Samples`] where the transfer function depends on more than the density.
    Voxels,
}

/// Number of direction codes (a code is a `u16`).
pub const CODES: usize = 1 << 16;

/// Cells per side of the octahedral map.
const Q: usize = 255;

/// The code of a voxel whose gradient is zero (or not finite): it reflects no light.
pub const ZERO_NORMAL: u16 = u16::MAX;

/// Every voxel's gradient direction as a 2-byte code ([`encode`]), built once per volume.
#[derive(Debug, Clone, PartialEq)]
pub struct NormalField {
    /// One code per voxel in the volume's order, then one [`ZERO_NORMAL`] of padding (the
    /// AVX2 kernel reads two codes per 32-bit load).
    codes: Vec<u16>,
    /// The volume dimensions this field was built for.
    pub volume_dims: [usize; 3],
    /// Per index axis, the world direction of that axis divided by its spacing: what turns the
    /// index-space differences into world gradients ([`NormalField::build`]).
    pub grad_to_world: [[f32; 3]; 3],
}

impl NormalField {
    /// The gradient of every voxel of `volume` by central differences along each index axis,
    /// `(ρ(p + e) − ρ(p − e)) · ½` (one-sided on the faces of the grid, `(ρ(p + e) − ρ(p)) · 1`;
    /// zero along an axis of one voxel: the differences the sample-order shading interpolates),
    /// turned into a world gradient with `grad_to_world` (as the sample-order shading does) and
    /// encoded ([`encode`]). Parallel over z slices; the codes do not depend on the thread
    /// count.
    ///
    /// The field takes 2 bytes per voxel, twice a `u8` volume; it is allocated fallibly:
    /// [`crate::SplatError::OutOfMemory`] when the memory cannot be had, never an abort.
    pub fn build<T: Scalar>(volume: &Volume<T>) -> Result<Self> {
        let grid = volume.grid();
        let dims = grid.dims;
        let grad_to_world = grad_to_world(grid);
        let data = volume.data();
        // Read through `Voxels` (the brick seam, docs/design/brick-seam.md C4).
        let vox = Linear::new(volume);
        let (nx, ny) = (dims[0], dims[1]);
        let m = grad_to_world;
        let mut codes = try_filled(
            data.len() + 1,
            ZERO_NORMAL,
            "the normal field of shading at the voxels",
        )?;
        codes[..data.len()]
            .par_chunks_mut(nx * ny)
            .enumerate()
            .for_each(|(k, slice)| {
                for j in 0..ny {
                    for i in 0..nx {
                        let g = index_gradient_in(&vox, dims, [i, j, k]);
                        let gw: [f32; 3] = std::array::from_fn(|c| {
                            m[0][c] * g[0] + m[1][c] * g[1] + m[2][c] * g[2]
                        });
                        slice[i + j * nx] = encode(gw);
                    }
                }
            });
        Ok(NormalField {
            codes,
            volume_dims: dims,
            grad_to_world,
        })
    }

    /// The codes, one per voxel in the volume's order, followed by one [`ZERO_NORMAL`].
    pub fn codes(&self) -> &[u16] {
        &self.codes
    }

    /// Whether this field was built for a volume on `grid` (same dimensions and axes).
    pub fn fits(&self, grid: &volsplat_core::Grid) -> bool {
        self.volume_dims == grid.dims && self.grad_to_world == grad_to_world(grid)
    }

    /// Bytes held.
    pub fn bytes(&self) -> usize {
        std::mem::size_of_val(self.codes.as_slice())
    }
}

/// Per index axis: the world direction of the axis divided by its spacing.
pub(crate) fn grad_to_world(grid: &volsplat_core::Grid) -> [[f32; 3]; 3] {
    [0, 1, 2].map(|a| {
        (grid.direction.col(a) / grid.spacing[a])
            .as_vec3()
            .to_array()
    })
}

/// The code of direction `g` (any length; world frame): `g / (|x| + |y| + |z|)` on the
/// octahedron, its lower half folded over the upper one, and the square `[−1, 1]²` cut into
/// 255 × 255 cells, code `i + 255·j`. [`ZERO_NORMAL`] where `g` is zero or not finite.
pub fn encode(g: [f32; 3]) -> u16 {
    let s = g[0].abs() + g[1].abs() + g[2].abs();
    if !(s > 0.0 && s.is_finite()) {
        return ZERO_NORMAL;
    }
    let (mut u, mut v) = (g[0] / s, g[1] / s);
    if g[2] < 0.0 {
        let (au, av) = (u.abs(), v.abs());
        u = (1.0 - av).copysign(u);
        v = (1.0 - au).copysign(v);
    }
    let cell = |t: f32| (((t * 0.5 + 0.5) * (Q - 1) as f32).round().max(0.0) as usize).min(Q - 1);
    (cell(u) + Q * cell(v)) as u16
}

/// The unit direction at the centre of code `code`'s cell, or `None` for [`ZERO_NORMAL`] and
/// codes past the map.
pub fn decode(code: u16) -> Option<Vec3> {
    let c = code as usize;
    if c >= Q * Q {
        return None;
    }
    let at = |i: usize| i as f64 / (Q - 1) as f64 * 2.0 - 1.0;
    let (u, v) = (at(c % Q), at(c / Q));
    let z = 1.0 - u.abs() - v.abs();
    let (x, y) = if z < 0.0 {
        ((1.0 - v.abs()).copysign(u), (1.0 - u.abs()).copysign(v))
    } else {
        (u, v)
    };
    let n = volsplat_core::glam::DVec3::new(x, y, z).normalize();
    Some(n.as_vec3())
}

/// The lights of one frame applied to every direction code ([`crate::normals`] step 2): per
/// code the diffuse light `Σ_L c_L·(N·L)` over the lights with `N·L > 0` (`|N·L|` two-sided)
/// and the specular light `Σ_L c_L·(N·H)^n` over those with also `N·H > 0`, with the
/// classifier's switches and specular power ([`ShadeTable`]). Stored as 16-bit fixed point,
/// the diffuse light in the low and the specular light in the high half of one 32-bit word
/// per code (so one gather reads both), in units of `scale` (the largest value / 65535: a
/// relative step of 1.5·10⁻⁵, as VTK's shading tables are fixed point too). One plane of
/// [`CODES`] words where every light is grey (equal channels; the usual white lights), else
/// one per channel.
pub(crate) struct VoxelShading {
    pub(crate) planes: Vec<u32>,
    pub(crate) chromatic: bool,
    /// Per plane: what one unit of the diffuse and of the specular half is worth.
    pub(crate) scale: [[f32; 2]; 3],
}

impl VoxelShading {
    pub(crate) fn new(t: &ShadeTable) -> Self {
        let lights = t.lights();
        let chromatic = lights.iter().any(|l| {
            let c = l.color;
            c.x != c.y || c.y != c.z
        });
        let n_planes = if chromatic { 3 } else { 1 };
        let (diffuse, specular, two_sided) = t.switches();
        // Per code and channel: diffuse and specular light.
        let light: Vec<[[f32; 2]; 3]> = (0..CODES)
            .into_par_iter()
            .map(|code| {
                let mut out = [[0.0f32; 2]; 3];
                let Some(n) = decode(code as u16) else {
                    return out;
                };
                for light in lights {
                    let (l, h, lc) = (light.l, light.h, light.color.to_array());
                    let mut ndl = n.dot(l);
                    let mut ndh = n.dot(h);
                    if two_sided && ndl < 0.0 {
                        ndl = -ndl;
                        ndh = -ndh;
                    }
                    if ndl.is_nan() || ndl <= 0.0 {
                        continue;
                    }
                    let p = if specular && ndh > 0.0 {
                        t.spec(ndh)
                    } else {
                        0.0
                    };
                    for ch in 0..3 {
                        if diffuse {
                            out[ch][0] += lc[ch] * ndl;
                        }
                        out[ch][1] += lc[ch] * p;
                    }
                }
                out
            })
            .collect();
        let mut scale = [[0.0f32; 2]; 3];
        for (ch, sc) in scale.iter_mut().enumerate().take(n_planes) {
            for (half, v) in sc.iter_mut().enumerate() {
                let max = light.iter().fold(0.0f32, |m, e| m.max(e[ch][half]));
                *v = if max > 0.0 && max.is_finite() {
                    max / 65535.0
                } else {
                    0.0
                };
            }
        }
        let mut planes = vec![0u32; n_planes * CODES];
        for (ch, sc) in scale.iter().enumerate().take(n_planes) {
            let q = |v: f32, s: f32| {
                if s > 0.0 {
                    (v / s).round().clamp(0.0, 65535.0) as u32
                } else {
                    0
                }
            };
            for (code, e) in light.iter().enumerate() {
                planes[ch * CODES + code] = q(e[ch][0], sc[0]) | q(e[ch][1], sc[1]) << 16;
            }
        }
        VoxelShading {
            planes,
            chromatic,
            scale,
        }
    }

    /// Plane `p` (channel `p` where the lights are coloured, else the only one).
    #[inline(always)]
    pub(crate) fn plane(&self, p: usize) -> &[u32] {
        &self.planes[p * CODES..(p + 1) * CODES]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use volsplat_core::Grid;

    #[test]
    fn codes_round_trip_within_one_degree() {
        let mut worst = 0.0f64;
        // A spiral over the sphere, poles and axes included.
        let mut dirs: Vec<Vec3> = (0..20_000)
            .map(|i| {
                let t = (i as f64 + 0.5) / 20_000.0;
                let z = 1.0 - 2.0 * t;
                let r = (1.0 - z * z).sqrt();
                let phi = i as f64 * 2.399_963_229_728_653;
                Vec3::new((r * phi.cos()) as f32, (r * phi.sin()) as f32, z as f32)
            })
            .collect();
        for a in 0..3 {
            for s in [1.0f32, -1.0] {
                let mut v = [0.0f32; 3];
                v[a] = s;
                dirs.push(Vec3::from_array(v));
            }
        }
        for d in dirs {
            let code = encode((d * 3.7).to_array());
            assert_ne!(code, ZERO_NORMAL);
            assert!((code as usize) < Q * Q);
            let n = decode(code).unwrap();
            let ang = (n.dot(d.normalize()) as f64)
                .clamp(-1.0, 1.0)
                .acos()
                .to_degrees();
            worst = worst.max(ang);
        }
        // Measured 0.94° (the cells' far corners along the fold of the lower half).
        assert!(worst < 1.0, "worst angular error {worst}°");
        assert!(worst > 0.05, "the map is quantised: {worst}°");
    }

    #[test]
    fn zero_and_non_finite_gradients_have_the_zero_code() {
        assert_eq!(encode([0.0; 3]), ZERO_NORMAL);
        assert_eq!(encode([f32::NAN, 1.0, 0.0]), ZERO_NORMAL);
        assert_eq!(encode([f32::INFINITY, 1.0, 0.0]), ZERO_NORMAL);
        assert!(decode(ZERO_NORMAL).is_none());
    }

    #[test]
    fn the_field_holds_the_directions_of_the_central_differences() {
        // ρ = 2x − 3y + 5z on an anisotropic grid: the world gradient is the same everywhere,
        // faces included (one-sided differences of a linear field are exact).
        let mut grid = Grid::with_dims([6, 5, 4]).unwrap();
        grid.spacing = [0.5, 2.0, 1.0];
        let v = Volume::from_fn(grid.clone(), |i, j, k| {
            2.0 * i as f32 * 0.5 - 3.0 * j as f32 * 2.0 + 5.0 * k as f32
        })
        .unwrap();
        let f = NormalField::build(&v).unwrap();
        assert!(f.fits(&grid));
        assert_eq!(f.codes().len(), 6 * 5 * 4 + 1);
        let want = encode([2.0, -3.0, 5.0]);
        assert!(f.codes()[..120].iter().all(|&c| c == want));
        assert_eq!(f.codes()[120], ZERO_NORMAL);
        // A constant volume has no gradient anywhere.
        let flat = Volume::from_fn(Grid::with_dims([3, 3, 3]).unwrap(), |_, _, _| 1.0f32).unwrap();
        let f = NormalField::build(&flat).unwrap();
        assert!(f.codes().iter().all(|&c| c == ZERO_NORMAL));
    }
}
