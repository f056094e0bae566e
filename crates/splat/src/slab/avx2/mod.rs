//! The AVX2 kernels: eight pixels of a row at a time, for x86-64 CPUs that have AVX2
//! (detected at run time, `super::simd_available`). This module is the only one behind
//! `#[cfg(target_arch = "x86_64")]` (in `super`, and at the three call sites in `super::march`
//! that try a kernel before the scalar loop). Every kernel names its scalar twin, which does the
//! same f32 operations in the same order (no fused multiply–add), so the bits do not depend on
//! the CPU, and every twin names its kernel:
//!
//! | kernel (here) | scalar twin |
//! |---|---|
//! | [`sample_run_avx2`], [`sampler::Sampler8`] | `Ctx::sample_scalar`, `Ctx::cell_f32` (`march.rs`), `trilinear` (`math.rs`) |
//! | [`composite_run_avx2`] and its skeleton `composite_groups_avx2` | `Ctx::composite_one` (`march.rs`) |
//! | `composite::Run::slab_exponents` | `boundary_factor` (`path.rs`) |
//! | `composite::PostSource`, `post_segment8`, `segment_average8` | `Ctx::post_src`, `PostTable::segment`, `segment_average` (`march.rs`, `tables.rs`) |
//! | `shade::ShadeSource` (`shade_terms8`, `lit_colour8`, `light_fractions`, `spec_at_sample8`, `pow_int8`) | `Ctx::gradient_lerp`, `shaded_src_two`, `lit_colour` (`shade.rs`), `light_fractions` (`march.rs`), `ShadeTable::spec_at_sample`, `pow_int` (`tables.rs`) |
//! | `shade::VoxelShadeSource`, `light_cells`, `shade_segment8` | `voxel_shaded_src`, `Ctx::light_cell`, `ShadeTable::segment_entry` |
//! | [`extreme_row_avx2`] | `Ctx::extreme_one` (`march.rs`) |
//! | `table_pos8`, `lerp8`, `exp2_neg8`, `premultiplied8`, `clamp01_8` | `TableAxis::pos`, `lerp`, `exp2_neg`, `premultiplied`, `clamp01` |
//!
//! Sampling is in [`sampler`], the composite skeleton and the unshaded classification in
//! [`composite`], the shaded classifications in [`shade`]; the lane helpers shared by them are
//! here.

pub(super) mod composite;
pub(super) mod sampler;
pub(super) mod shade;

pub(super) use composite::composite_run_avx2;

use super::march::{Counters, Ctx};
use super::tables::TableAxis;
use super::view::Walk;
use crate::voxels::Voxels;
use sampler::Sampler8;
use volsplat_core::Scalar;

/// Samples pixels `a..=b` of a row eight at a time ([`Sampler8`]; the last group partly);
/// returns the first pixel not done (`b + 1`, or earlier where a group's reads would pass the
/// end of the data).
///
/// # Safety
/// The CPU must support AVX2.
#[target_feature(enable = "avx2")]
pub(super) unsafe fn sample_run_avx2<T: Scalar, V: Voxels<T>>(
    ctx: &Ctx<'_, T, V>,
    walk: &Walk,
    a: usize,
    b: usize,
    out: &mut [f32],
) -> usize {
    use std::arch::x86_64::*;
    // SAFETY (all calls below): the caller guarantees AVX2.
    let sampler = unsafe { Sampler8::new(ctx, walk) };
    let mut x = a;
    while x <= b {
        let Some(r) = (unsafe { sampler.at(x) }) else {
            break;
        };
        if x + 7 <= b {
            // SAFETY: x + 7 ≤ b < out.len().
            unsafe { _mm256_storeu_ps(out.as_mut_ptr().add(x), r) };
        } else {
            // The last, partial group: lanes past `b` sampled clamped cells (valid reads) and
            // are dropped here.
            let mut tmp = [0.0f32; 8];
            // SAFETY: tmp holds 8 floats.
            unsafe { _mm256_storeu_ps(tmp.as_mut_ptr(), r) };
            out[x..=b].copy_from_slice(&tmp[..=b - x]);
        }
        x += 8;
    }
    x
}

/// MIP (`mip`) or MinIP over pixels `lo..=hi` of a row, eight at a time: each lane's cell is
/// located first, and a group none of whose pixels its cells' bricks can beat (a brick's maximum
/// (minimum) no larger (smaller) than the pixel's extreme) is not sampled; the others are
/// sampled ([`Sampler8`]) and each open lane keeps the larger (smaller) value, as
/// [`Ctx::extreme_one`] does (a NaN pixel, not yet reached, takes the sample). Returns the first
/// pixel not done (`hi + 1`, or the last pixels of the row where a group would pass it).
///
/// # Safety
/// The CPU must support AVX2.
#[target_feature(enable = "avx2")]
pub(super) unsafe fn extreme_row_avx2<T: Scalar, V: Voxels<T>>(
    ctx: &Ctx<'_, T, V>,
    walk: &Walk,
    lo: usize,
    hi: usize,
    row: &mut [f32],
    mip: bool,
    c: &mut Counters,
) -> usize {
    use std::arch::x86_64::*;
    // SAFETY (all intrinsics and calls below): the caller guarantees AVX2; loads and stores
    // are of pixels x..x + 8 ≤ the row's length; brick indices come from cells clamped to the
    // grid, so they index `extreme_bounds`.
    let sampler = unsafe { Sampler8::new(ctx, walk) };
    let bounds = ctx.extreme_bounds.as_ptr();
    let mut x = lo;
    // As in `composite_groups_avx2`: a chunk of groups is tested and sampled, then compared, so
    // that the gathers' cache misses overlap; each pixel gets the same operations.
    const CHUNK: usize = 4;
    let mut chunk = [(
        0usize,
        _mm256_setzero_ps(),
        _mm256_setzero_ps(),
        _mm256_setzero_ps(),
    ); CHUNK];
    loop {
        let mut filled = 0;
        let mut stop = false;
        while filled < CHUNK && x <= hi && x + 8 <= row.len() {
            let in_row = first_lanes((hi - x + 1).min(8));
            let cur = unsafe { _mm256_loadu_ps(row.as_ptr().add(x)) };
            let cells = unsafe { sampler.locate(x) };
            let brick = unsafe { sampler.bricks_of(&cells) };
            let bound = unsafe { _mm256_i32gather_ps::<4>(bounds, brick) };
            let in_row = _mm256_and_ps(in_row, _mm256_cmp_ps::<_CMP_ORD_Q>(bound, bound));
            let unset = _mm256_and_ps(_mm256_cmp_ps::<_CMP_UNORD_Q>(cur, cur), in_row);
            let open = _mm256_and_ps(
                if mip {
                    _mm256_cmp_ps::<_CMP_LT_OQ>(cur, bound)
                } else {
                    _mm256_cmp_ps::<_CMP_GT_OQ>(cur, bound)
                },
                in_row,
            );
            let todo = _mm256_movemask_ps(_mm256_or_ps(unset, open));
            if todo == 0 {
                x += 8;
                continue;
            }
            let Some(v) = (unsafe { sampler.sample(&cells) }) else {
                stop = true;
                break;
            };
            c.samples += u64::from(lanes(todo));
            chunk[filled] = (x, cur, v, _mm256_or_ps(unset, open));
            // `unset` is kept apart from `open` below through `cur` (NaN where unset).
            filled += 1;
            x += 8;
        }
        for &(gx, cur, v, todo) in &chunk[..filled] {
            let better = if mip {
                _mm256_cmp_ps::<_CMP_GT_OQ>(v, cur)
            } else {
                _mm256_cmp_ps::<_CMP_LT_OQ>(v, cur)
            };
            // Lanes whose brick cannot beat them keep their value even where rounding put a
            // sample an ulp beyond the brick's range: the scalar twin does not sample them.
            // An unset lane (NaN) is in `todo` and takes the sample; a set lane in `todo` is
            // open and takes it where it is better.
            let unset = _mm256_cmp_ps::<_CMP_UNORD_Q>(cur, cur);
            let take = _mm256_and_ps(todo, _mm256_or_ps(unset, better));
            let p = unsafe { row.as_mut_ptr().add(gx) };
            unsafe { _mm256_storeu_ps(p, _mm256_blendv_ps(cur, v, take)) };
        }
        if stop || filled == 0 {
            return x;
        }
    }
}

/// An 8×8 transpose: lane `l` of output `c` is element `c` of input row `l`.
#[inline]
#[target_feature(enable = "avx2")]
fn transpose8(r: [std::arch::x86_64::__m256; 8]) -> [std::arch::x86_64::__m256; 8] {
    use std::arch::x86_64::*;
    let t0 = _mm256_unpacklo_ps(r[0], r[1]);
    let t1 = _mm256_unpackhi_ps(r[0], r[1]);
    let t2 = _mm256_unpacklo_ps(r[2], r[3]);
    let t3 = _mm256_unpackhi_ps(r[2], r[3]);
    let t4 = _mm256_unpacklo_ps(r[4], r[5]);
    let t5 = _mm256_unpackhi_ps(r[4], r[5]);
    let t6 = _mm256_unpacklo_ps(r[6], r[7]);
    let t7 = _mm256_unpackhi_ps(r[6], r[7]);
    let u0 = _mm256_shuffle_ps::<0x44>(t0, t2);
    let u1 = _mm256_shuffle_ps::<0xee>(t0, t2);
    let u2 = _mm256_shuffle_ps::<0x44>(t1, t3);
    let u3 = _mm256_shuffle_ps::<0xee>(t1, t3);
    let u4 = _mm256_shuffle_ps::<0x44>(t4, t6);
    let u5 = _mm256_shuffle_ps::<0xee>(t4, t6);
    let u6 = _mm256_shuffle_ps::<0x44>(t5, t7);
    let u7 = _mm256_shuffle_ps::<0xee>(t5, t7);
    [
        _mm256_permute2f128_ps::<0x20>(u0, u4),
        _mm256_permute2f128_ps::<0x20>(u1, u5),
        _mm256_permute2f128_ps::<0x20>(u2, u6),
        _mm256_permute2f128_ps::<0x20>(u3, u7),
        _mm256_permute2f128_ps::<0x31>(u0, u4),
        _mm256_permute2f128_ps::<0x31>(u1, u5),
        _mm256_permute2f128_ps::<0x31>(u2, u6),
        _mm256_permute2f128_ps::<0x31>(u3, u7),
    ]
}

/// Rows `idx + off` of a table of 32-byte rows, transposed ([`transpose8`]): lane `l` of output
/// `c` is element `c` of row `idx[l] + off`.
///
/// # Safety
/// The CPU must support AVX2, and every `idx[l] + off` must be a row of `rows`.
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn rows8(rows: &[[f32; 8]], idx: &[i32; 8], off: usize) -> [std::arch::x86_64::__m256; 8] {
    use std::arch::x86_64::*;
    let base = rows.as_ptr();
    let mut r = [_mm256_setzero_ps(); 8];
    for l in 0..8 {
        // SAFETY: the caller guarantees the rows exist.
        r[l] = unsafe { _mm256_loadu_ps(base.add(idx[l] as usize + off) as *const f32) };
    }
    transpose8(r)
}

/// Linear interpolation at positions `pos` (clamped to `[0, last]`) in a table of entries of
/// eight channels, lane by lane: `(i, f)` from `pos`, then `row_i + f·(row_{i+1} − row_i)` per
/// channel. With `paired`, row `i` holds entry `i` in its first four floats and entry `i + 1` in
/// its last four (four channels, one load per lane); otherwise entry `i + 1` is the next row.
///
/// # Safety
/// The CPU must support AVX2; the rows read must exist (`i ≤ last`, and `i + 1` too unless
/// `paired`).
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn interp8(
    rows: &[[f32; 8]],
    pos: std::arch::x86_64::__m256,
    paired: bool,
) -> [std::arch::x86_64::__m256; 8] {
    use std::arch::x86_64::*;
    let i = _mm256_cvttps_epi32(pos);
    let f = _mm256_sub_ps(pos, _mm256_cvtepi32_ps(i));
    let mut idx = [0i32; 8];
    // SAFETY: idx holds 8 i32; the rows' existence is the caller's guarantee.
    unsafe { _mm256_storeu_si256(idx.as_mut_ptr() as *mut __m256i, i) };
    let mut out = unsafe { rows8(rows, &idx, 0) };
    if paired {
        for ch in 0..4 {
            let (p, q) = (out[ch], out[ch + 4]);
            out[ch] = _mm256_add_ps(p, _mm256_mul_ps(f, _mm256_sub_ps(q, p)));
        }
    } else {
        let next = unsafe { rows8(rows, &idx, 1) };
        for ch in 0..8 {
            let (p, q) = (out[ch], next[ch]);
            out[ch] = _mm256_add_ps(p, _mm256_mul_ps(f, _mm256_sub_ps(q, p)));
        }
    }
    out
}

/// `(p₀q₀ + p₁q₁) + p₂q₂` on eight lanes (the order of the scalar twins' dot products).
#[inline]
#[target_feature(enable = "avx2")]
fn dot8(
    p: [std::arch::x86_64::__m256; 3],
    q: [std::arch::x86_64::__m256; 3],
) -> std::arch::x86_64::__m256 {
    use std::arch::x86_64::*;
    _mm256_add_ps(
        _mm256_add_ps(_mm256_mul_ps(p[0], q[0]), _mm256_mul_ps(p[1], q[1])),
        _mm256_mul_ps(p[2], q[2]),
    )
}

/// `v` broadcast to eight lanes per component.
#[inline]
#[target_feature(enable = "avx2")]
fn splat3(v: [f32; 3]) -> [std::arch::x86_64::__m256; 3] {
    use std::arch::x86_64::*;
    [
        _mm256_set1_ps(v[0]),
        _mm256_set1_ps(v[1]),
        _mm256_set1_ps(v[2]),
    ]
}

/// A table position on eight lanes, `min(max((ρ − lo)·scale, 0), last)` (NaN → 0): lane by
/// lane the operations of its scalar twin [`TableAxis::pos`].
#[inline]
#[target_feature(enable = "avx2")]
fn table_pos8(rho: std::arch::x86_64::__m256, axis: TableAxis) -> std::arch::x86_64::__m256 {
    use std::arch::x86_64::*;
    let t = _mm256_mul_ps(
        _mm256_sub_ps(rho, _mm256_set1_ps(axis.lo)),
        _mm256_set1_ps(axis.scale),
    );
    _mm256_min_ps(
        _mm256_max_ps(t, _mm256_setzero_ps()),
        _mm256_set1_ps(axis.last),
    )
}

/// `p + f·(q − p)` on eight lanes: its scalar twin [`lerp`].
///
/// [`lerp`]: crate::slab::math::lerp
#[inline]
#[target_feature(enable = "avx2")]
fn lerp8(
    p: std::arch::x86_64::__m256,
    q: std::arch::x86_64::__m256,
    f: std::arch::x86_64::__m256,
) -> std::arch::x86_64::__m256 {
    use std::arch::x86_64::*;
    _mm256_add_ps(p, _mm256_mul_ps(f, _mm256_sub_ps(q, p)))
}

/// A mask of the first `n` (≤ 8) of eight lanes: the pixels of a partial last group that belong
/// to the run.
#[inline]
#[target_feature(enable = "avx2")]
fn first_lanes(n: usize) -> std::arch::x86_64::__m256 {
    use std::arch::x86_64::*;
    _mm256_castsi256_ps(_mm256_cmpgt_epi32(
        _mm256_set1_epi32(n as i32),
        _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7),
    ))
}

/// The number of lanes set in an 8-lane `movemask`: a table, as `popcnt` is not part of AVX2
/// (and not detected here).
#[inline(always)]
fn lanes(bits: i32) -> u32 {
    const POP: [u8; 256] = {
        let mut t = [0u8; 256];
        let mut i = 0;
        while i < 256 {
            t[i] = (i as u32).count_ones() as u8;
            i += 1;
        }
        t
    };
    u32::from(POP[(bits & 0xff) as usize])
}

/// [`exp2_neg`] on eight lanes, with the same operations in the same order.
///
/// [`exp2_neg`]: crate::slab::math::exp2_neg
#[inline]
#[target_feature(enable = "avx2")]
fn exp2_neg8(z: std::arch::x86_64::__m256) -> std::arch::x86_64::__m256 {
    use std::arch::x86_64::*;
    let bad = _mm256_or_ps(
        _mm256_cmp_ps::<_CMP_UNORD_Q>(z, z),
        _mm256_cmp_ps::<_CMP_LT_OQ>(z, _mm256_set1_ps(-126.0)),
    );
    let i = _mm256_cvttps_epi32(z);
    let f = _mm256_add_ps(_mm256_sub_ps(z, _mm256_cvtepi32_ps(i)), _mm256_set1_ps(0.5));
    let c = |v: f32| _mm256_set1_ps(v);
    let mut p = _mm256_mul_ps(f, c(0.000_154_04));
    p = _mm256_mul_ps(f, _mm256_add_ps(c(0.001_333_36), p));
    p = _mm256_mul_ps(f, _mm256_add_ps(c(0.009_618_13), p));
    p = _mm256_mul_ps(f, _mm256_add_ps(c(0.055_504_1), p));
    p = _mm256_mul_ps(f, _mm256_add_ps(c(0.240_226_5), p));
    p = _mm256_mul_ps(f, _mm256_add_ps(c(std::f32::consts::LN_2), p));
    p = _mm256_add_ps(c(1.0), p);
    let pow = _mm256_castsi256_ps(_mm256_slli_epi32::<23>(_mm256_add_epi32(
        i,
        _mm256_set1_epi32(127),
    )));
    let r = _mm256_mul_ps(_mm256_mul_ps(pow, p), c(std::f32::consts::FRAC_1_SQRT_2));
    _mm256_andnot_ps(bad, r)
}
