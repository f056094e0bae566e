//! Clipping planes and crop boxes with smooth cuts.
//!
//! A plane keeps the world points `x` with `n·x + d ≥ 0` (VTK's clipping planes keep the side
//! the normal points to). Cutting a splatted volume by dropping the voxels on the far side would
//! step the cut along the lattice; instead every voxel is weighted by the part of its
//! reconstruction kernel that lies on the kept side (issue 15). For a kernel of standard deviation
//! `σ` (lattice units) on a grid with direction columns `dₖ` and spacings `sₖ`, the kernel's
//! spread along the plane's unit normal `n̂` is `σₙ = σ·√(Σₖ (n̂·dₖ)² sₖ²)` (world units), and a
//! voxel at signed distance `t` from the plane keeps the fraction `Φ(t/σₙ)` of a Gaussian of that
//! spread (Φ: the standard normal distribution function). Weights of several planes multiply.
//!
//! The weight scales a composite splat's premultiplied colour and opacity (the voxel covers that
//! fraction of the space), an X-ray splat's density, and a MIP splat's value (so the maximum
//! fades smoothly across the cut); a MinIP splat is kept when its weight is at least ½ (scaling
//! would lower the minimum).

use volsplat_core::glam::{DMat3, DVec3};
use volsplat_core::{Grid, Kernel};

/// A clipping plane in world coordinates: keeps the points with `normal·x + offset ≥ 0`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClipPlane {
    /// Normal (world frame; any non-zero length): points towards the kept side.
    pub normal: [f64; 3],
    /// Offset `d`, world units × |normal|.
    pub offset: f64,
}

impl ClipPlane {
    /// Whether the plane is usable: a finite, non-zero normal and a finite offset.
    pub fn is_valid(&self) -> bool {
        let n = DVec3::from(self.normal);
        n.is_finite() && n.length() > 1e-300 && self.offset.is_finite()
    }
}

/// The standard deviation of `kernel` along one axis, in voxels: exact for the Gaussian, the
/// box (1/√12), the tent (1/√6) and the cubic B-spline (1/√3); 0.5 voxel for the others, whose
/// unit-area profiles have about that spread.
pub fn kernel_sigma(kernel: &Kernel) -> f64 {
    match *kernel {
        Kernel::Gaussian { sigma, .. } => sigma,
        Kernel::SinglePoint => 0.25,
        Kernel::Nearest => (1.0f64 / 12.0).sqrt(),
        Kernel::Tent => (1.0f64 / 6.0).sqrt(),
        Kernel::MitchellNetravali { b, c } if b == 1.0 && c == 0.0 => (1.0f64 / 3.0).sqrt(),
        _ => 0.5,
    }
}

/// Planes turned into affine functions of lattice indices: `t = a·l + b` is the signed distance
/// of lattice point `l` (full-resolution voxel indices) from each plane, in units of the kernel's
/// spread along the plane normal.
#[derive(Debug, Clone, Default)]
pub struct LatticeClip {
    planes: Vec<(DVec3, f64)>,
}

impl LatticeClip {
    /// Prepares `planes` for `grid` sampled with `stride` (the kernel widens with the stride)
    /// and reconstructed with `kernel`. Invalid planes (zero or non-finite normal) are skipped
    /// by the caller's validation ([`ClipPlane::is_valid`]).
    pub fn new(planes: &[ClipPlane], grid: &Grid, kernel: &Kernel, stride: usize) -> Self {
        let sigma = kernel_sigma(kernel).max(0.05) * stride.max(1) as f64;
        let spacing = DVec3::from(grid.spacing);
        let dir: DMat3 = grid.direction;
        let origin = DVec3::from(grid.origin);
        let planes = planes
            .iter()
            .filter(|p| p.is_valid())
            .map(|p| {
                let n = DVec3::from(p.normal);
                let len = n.length();
                let nh = n / len;
                // n̂ · dₖ sₖ: world distance along n̂ of one lattice step along k.
                let step = DVec3::new(
                    nh.dot(dir.col(0)) * spacing.x,
                    nh.dot(dir.col(1)) * spacing.y,
                    nh.dot(dir.col(2)) * spacing.z,
                );
                let spread = sigma * step.length();
                let spread = if spread > 0.0 { spread } else { sigma };
                (step / spread, (nh.dot(origin) + p.offset / len) / spread)
            })
            .collect();
        LatticeClip { planes }
    }

    /// Whether there is nothing to clip.
    pub fn is_empty(&self) -> bool {
        self.planes.is_empty()
    }

    /// The kept fraction `Π Φ(tᵢ)` at full-resolution lattice point `l`, in [0, 1].
    #[inline]
    pub fn weight(&self, l: [f64; 3]) -> f64 {
        let l = DVec3::from(l);
        let mut w = 1.0;
        for (a, b) in &self.planes {
            let t = a.dot(l) + b;
            if t < -6.0 {
                return 0.0;
            }
            if t < 6.0 {
                w *= normal_cdf(t);
            }
        }
        w
    }
}

/// Φ(t), the standard normal distribution function, by Abramowitz & Stegun 7.1.26 for erf
/// (absolute error below 1.5e-7); odd-symmetric about ½.
pub fn normal_cdf(t: f64) -> f64 {
    let x = t.abs() / std::f64::consts::SQRT_2;
    let k = 1.0 / (1.0 + 0.327_591_1 * x);
    let poly = k
        * (0.254_829_592
            + k * (-0.284_496_736
                + k * (1.421_413_741 + k * (-1.453_152_027 + k * 1.061_405_429))));
    let erf = 1.0 - poly * (-x * x).exp();
    if t >= 0.0 {
        0.5 * (1.0 + erf)
    } else {
        0.5 * (1.0 - erf)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_normal_cdf_is_accurate_and_symmetric() {
        for (t, want) in [
            (0.0, 0.5),
            (1.0, 0.841_344_746_068_543),
            (-1.0, 0.158_655_253_931_457),
            (2.5, 0.993_790_334_674_224),
            (-3.0, 0.001_349_898_031_630),
        ] {
            assert!((normal_cdf(t) - want).abs() < 2e-7, "{t}");
        }
        for t in [-4.0, -1.3, 0.2, 2.0] {
            assert!((normal_cdf(t) + normal_cdf(-t) - 1.0).abs() < 1e-12);
        }
    }

    #[test]
    fn weights_are_a_half_on_the_plane_and_follow_the_kernel_spread() {
        let grid = Grid::new(
            [10, 10, 10],
            [2.0, 1.0, 1.0],
            [5.0, 0.0, 0.0],
            DMat3::IDENTITY,
        )
        .unwrap();
        let kernel = Kernel::default();
        let sigma = kernel_sigma(&kernel);
        // Keep x ≥ 9 (world): lattice i = (x − 5)/2, so the plane is at i = 2.
        let clip = LatticeClip::new(
            &[ClipPlane {
                normal: [2.0, 0.0, 0.0],
                offset: -18.0,
            }],
            &grid,
            &kernel,
            1,
        );
        assert!((clip.weight([2.0, 3.0, 7.0]) - 0.5).abs() < 1e-9);
        // One voxel further in is 2 mm, i.e. 2/(2σ) kernel spreads.
        let want = normal_cdf(1.0 / sigma);
        assert!((clip.weight([3.0, 0.0, 0.0]) - want).abs() < 1e-9);
        assert!(clip.weight([9.0, 0.0, 0.0]) > 0.999_999);
        assert_eq!(clip.weight([-9.0, 0.0, 0.0]), 0.0);
        // Weights of two planes multiply; a plane parallel to y ignores j.
        let two = LatticeClip::new(
            &[
                ClipPlane {
                    normal: [1.0, 0.0, 0.0],
                    offset: -9.0,
                },
                ClipPlane {
                    normal: [0.0, 0.0, -1.0],
                    offset: 4.0,
                },
            ],
            &grid,
            &kernel,
            1,
        );
        let w = two.weight([2.0, 5.0, 4.0]);
        assert!((w - 0.25).abs() < 1e-9, "{w}");
        assert_eq!(two.weight([2.0, 1.0, 4.0]), w);
    }
}
