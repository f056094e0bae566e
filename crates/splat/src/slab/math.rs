//! Scalar arithmetic shared by the scalar twins: the libm-free `log2` and `exp2`, the
//! trilinear interpolation, and `maxps`/`minps` as the AVX2 kernels compute them.

use crate::voxels::Voxels;
use volsplat_core::Scalar;

/// `log2(y)` for `y` in `(0, 1]`: the exponent plus the series of `log2((1 + t)/(1 − t))`,
/// `t = (m − 1)/(m + 1) ∈ [0, 1/3)`, to `t⁹` (error below 2·10⁻⁶). Plain arithmetic, so every
/// platform gives the same bits (no libm).
#[inline(always)]
pub(super) fn log2_unit(y: f32) -> f32 {
    let bits = y.to_bits();
    let e = ((bits >> 23) & 0xff) as i32 - 127;
    let m = f32::from_bits((bits & 0x007f_ffff) | 0x3f80_0000);
    let t = (m - 1.0) / (m + 1.0);
    let t2 = t * t;
    let p = t
        * (2.885_39
            + t2 * (0.961_796_7 + t2 * (0.577_078 + t2 * (0.412_198_6 + t2 * 0.320_598_9))));
    e as f32 + p
}

/// `2^z` for `z ≤ 0` (0 below −126): `2^(i + ½)·2^f`, `f ∈ [−½, ½]`, with the Taylor series of
/// `2^f` to `f⁶` (relative error below 2·10⁻⁷). Plain arithmetic, as [`log2_unit`]; the scalar
/// twin of `exp2_neg8` (`avx2/mod.rs`).
#[inline(always)]
pub(super) fn exp2_neg(z: f32) -> f32 {
    if z.is_nan() || z < -126.0 {
        return 0.0;
    }
    // Truncation rounds towards zero, so for z ≤ 0, i ≥ z and z − i ∈ (−1, 0].
    let i = z as i32;
    let f = z - i as f32 + 0.5;
    let p = 1.0
        + f * (std::f32::consts::LN_2
            + f * (0.240_226_5
                + f * (0.055_504_1 + f * (0.009_618_13 + f * (0.001_333_36 + f * 0.000_154_04)))));
    // 2^(i − ½) = 2^i / √2; i ≥ −126, so 2^i is a normal number.
    f32::from_bits(((i + 127) as u32) << 23) * p * std::f32::consts::FRAC_1_SQRT_2
}

/// The trilinear interpolation of the voxels `vox` in the cell whose lower corner is at `base`
/// ([`Voxels::cell_base`]), at fractions `f`; the other corners lie at [`Voxels::up`] offsets.
/// [`Sampler8::sample`] does the same operations in the same order.
///
/// [`Sampler8::sample`]: super::avx2::sampler::Sampler8::sample
#[inline(always)]
pub(super) fn trilinear<U: Scalar>(vox: &impl Voxels<U>, base: usize, f: [f32; 3]) -> f32 {
    let [ux, uy, uz] = vox.up();
    let data = vox.data();
    let v = |o: usize| data[base + o].to_f32();
    let c00 = lerp(v(0), v(ux), f[0]);
    let c10 = lerp(v(uy), v(uy + ux), f[0]);
    let c01 = lerp(v(uz), v(uz + ux), f[0]);
    let c11 = lerp(v(uz + uy), v(uz + uy + ux), f[0]);
    lerp(lerp(c00, c10, f[1]), lerp(c01, c11, f[1]), f[2])
}

/// `max(x, lo)` as `maxps` computes it (`x > lo ? x : lo`, so NaN and −0 give `lo`), for the
/// scalar twins of the AVX2 kernels.
#[inline(always)]
pub(super) fn max_ps(x: f32, lo: f32) -> f32 {
    if x > lo { x } else { lo }
}

/// `min(x, hi)` as `minps` computes it (`x < hi ? x : hi`).
#[inline(always)]
pub(super) fn min_ps(x: f32, hi: f32) -> f32 {
    if x < hi { x } else { hi }
}

/// `a + t·(b − a)`: the scalar twin of `lerp8` (`avx2/mod.rs`; no fused multiply–add).
#[inline(always)]
pub(super) fn lerp(a: f32, b: f32, t: f32) -> f32 {
    a + t * (b - a)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fast_log2_and_exp2_are_accurate() {
        let mut worst_log = 0.0f64;
        let mut worst_exp = 0.0f64;
        for n in 1..=100_000 {
            let y = n as f32 / 100_000.0;
            let e = (log2_unit(y) as f64 - (y as f64).log2()).abs();
            worst_log = worst_log.max(e);
            let z = -(n as f32) / 2_000.0; // down to −50
            let exact = (z as f64).exp2();
            let r = (exp2_neg(z) as f64 - exact).abs() / exact;
            worst_exp = worst_exp.max(r);
        }
        assert!(worst_log < 3e-6, "log2 error {worst_log}");
        assert!(worst_exp < 5e-7, "exp2 relative error {worst_exp}");
        assert!((exp2_neg(0.0) - 1.0).abs() < 1e-6);
        assert_eq!(exp2_neg(-200.0), 0.0);
        assert_eq!(exp2_neg(f32::NAN), 0.0);
    }
}
