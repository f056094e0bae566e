//! The innermost loop of the orthographic splatter: one row of one footprint added into a sheet
//! buffer (Westover 1991 §3.7.2, Fig 3.08: the footprint table's weights scaled by the sample's
//! value and summed into the sheet).
//!
//! Each weight is the first-order blend of three tabulated phases,
//! `max(floor, a + fx·dx + fy·dy)` with `dx = w₁₀ − w₀₀` and `dy = w₀₁ − w₀₀` precomputed per
//! frame ([`crate::footprint::LocatedPlanes`]), and each pixel takes `px[c] + w·v[c]` per channel.
//! The SIMD version evaluates four weights at once and updates one RGBA pixel per 128-bit
//! operation; it performs the very same IEEE operations in the same order (no fused multiply–add,
//! which would round once instead of twice), so `deposit_row_scalar` gives the same bits. SSE2
//! is part of the x86-64 baseline, so no run-time detection is needed; other targets use the
//! scalar loop.
//!
//! Why a hand-written row: rows are short (about 4 pixels at 1.5 pixels per voxel), and the
//! compiler's auto-vectorised loop spent more instructions choosing between its vector and
//! remainder paths than on the updates (docs/design/pipeline.md §1.3).

use volsplat_core::image::Rgba;

/// Adds `w(i)·v` into `out[i]` for every pixel of the row, `w(i) = max(floor, a[i] + fx·dx[i] +
/// fy·dy[i])` (`max` as `x > floor ? x : floor`; it differs from `f32::max` only in the sign of a
/// zero weight, which leaves every sum unchanged).
///
/// `a`, `dx` and `dy` must hold at least `out.len()` rounded up to a multiple of 4 entries (the
/// footprint table pads its planes); panics otherwise.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub(crate) fn deposit_row(
    out: &mut [Rgba],
    a: &[f32],
    dx: &[f32],
    dy: &[f32],
    fx: f32,
    fy: f32,
    floor: f32,
    v: &Rgba,
) {
    #[cfg(target_arch = "x86_64")]
    {
        sse2::deposit_row(out, a, dx, dy, fx, fy, floor, v)
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        deposit_row_scalar(out, a, dx, dy, fx, fy, floor, v)
    }
}

/// The portable reference of [`deposit_row`]: the same operations, one lane at a time.
#[cfg(any(test, not(target_arch = "x86_64")))]
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub(crate) fn deposit_row_scalar(
    out: &mut [Rgba],
    a: &[f32],
    dx: &[f32],
    dy: &[f32],
    fx: f32,
    fy: f32,
    floor: f32,
    v: &Rgba,
) {
    let n = out.len();
    let (a, dx, dy) = (&a[..n], &dx[..n], &dy[..n]);
    for i in 0..n {
        let t = a[i] + fx * dx[i] + fy * dy[i];
        let wt = if t > floor { t } else { floor };
        let px = &mut out[i];
        px[0] += wt * v[0];
        px[1] += wt * v[1];
        px[2] += wt * v[2];
        px[3] += wt * v[3];
    }
}

#[cfg(target_arch = "x86_64")]
mod sse2 {
    use super::Rgba;
    use core::arch::x86_64::*;

    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    pub(super) fn deposit_row(
        out: &mut [Rgba],
        a: &[f32],
        dx: &[f32],
        dy: &[f32],
        fx: f32,
        fy: f32,
        floor: f32,
        v: &Rgba,
    ) {
        let n = out.len();
        let n4 = n.next_multiple_of(4);
        assert!(a.len() >= n4 && dx.len() >= n4 && dy.len() >= n4);
        let p = out.as_mut_ptr() as *mut f32;
        // SAFETY: `v` is four f32; the weight loads read `i..i + 4 ≤ n4` entries of slices of at
        // least `n4` (asserted); the pixel loads and stores touch pixels `i + k < n` of `out`
        // (an `Rgba` is four contiguous f32). SSE2 is enabled on every x86-64 target.
        unsafe {
            let (vfx, vfy, vfl) = (_mm_set1_ps(fx), _mm_set1_ps(fy), _mm_set1_ps(floor));
            let vv = _mm_loadu_ps(v.as_ptr());
            let mut i = 0;
            while i < n {
                let wa = _mm_loadu_ps(a.as_ptr().add(i));
                let wx = _mm_loadu_ps(dx.as_ptr().add(i));
                let wy = _mm_loadu_ps(dy.as_ptr().add(i));
                // (a + fx·dx) + fy·dy, then max(·, floor): the scalar order, lane by lane.
                let t = _mm_add_ps(_mm_add_ps(wa, _mm_mul_ps(vfx, wx)), _mm_mul_ps(vfy, wy));
                let w = _mm_max_ps(t, vfl);
                let q = p.add(4 * i);
                macro_rules! pixel {
                    ($k:literal, $imm:literal) => {{
                        let wk = _mm_shuffle_ps::<$imm>(w, w);
                        let px = q.add(4 * $k);
                        _mm_storeu_ps(px, _mm_add_ps(_mm_loadu_ps(px), _mm_mul_ps(wk, vv)));
                    }};
                }
                pixel!(0, 0x00);
                let left = n - i;
                if left > 1 {
                    pixel!(1, 0x55);
                }
                if left > 2 {
                    pixel!(2, 0xAA);
                }
                if left > 3 {
                    pixel!(3, 0xFF);
                }
                i += 4;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The SIMD row and the scalar reference agree bit for bit, and both agree with the blend of
    /// `Located::weight` (`f32::max`) followed by the per-channel update of `render::deposit`.
    #[test]
    fn simd_row_matches_the_scalar_reference_bit_for_bit() {
        let mut seed = 0x2545_f491_4f6c_dd1du64;
        let mut rnd = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 40) as f32 / (1u64 << 24) as f32
        };
        for n in 0..20 {
            for &floor in &[0.0f32, f32::NEG_INFINITY] {
                let w00: Vec<f32> = (0..n + 4).map(|_| rnd() - 0.2).collect();
                let w10: Vec<f32> = (0..n + 4).map(|_| rnd() - 0.2).collect();
                let w01: Vec<f32> = (0..n + 4).map(|_| rnd() - 0.2).collect();
                let dx: Vec<f32> = w10.iter().zip(&w00).map(|(b, a)| b - a).collect();
                let dy: Vec<f32> = w01.iter().zip(&w00).map(|(c, a)| c - a).collect();
                let (fx, fy) = (rnd(), rnd());
                let v = [rnd(), rnd() * 3.0, rnd() * 1e-3, rnd()];
                let start: Vec<Rgba> = (0..n).map(|_| [rnd(), rnd(), rnd(), rnd()]).collect();
                let mut simd = start.clone();
                let mut scalar = start.clone();
                let mut reference = start.clone();
                deposit_row(&mut simd, &w00, &dx, &dy, fx, fy, floor, &v);
                deposit_row_scalar(&mut scalar, &w00, &dx, &dy, fx, fy, floor, &v);
                for (i, px) in reference.iter_mut().enumerate() {
                    let (a, b, c) = (w00[i], w10[i], w01[i]);
                    let wt = (a + fx * (b - a) + fy * (c - a)).max(floor);
                    for ch in 0..4 {
                        px[ch] += wt * v[ch];
                    }
                }
                let bits = |p: &[Rgba]| p.iter().flatten().map(|f| f.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&simd), bits(&scalar), "n = {n}");
                assert_eq!(bits(&scalar), bits(&reference), "n = {n}");
            }
        }
    }
}
