//! The composite kernels' skeleton and the unshaded classification through the post table.

use super::sampler::{Cells8, Sampler8};
use super::shade::{ShadeSource, VoxelShadeSource};
use super::{exp2_neg8, first_lanes, interp8, lanes, table_pos8};
use crate::slab::march::{Counters, Ctx, Post, RowCtx};
use crate::slab::tables::{PostTable, SEGMENT_MIN_ENTRIES, TableAxis};
use crate::slab::view::Walk;
use crate::voxels::Voxels;
use std::arch::x86_64::*;
use std::mem::MaybeUninit;
use volsplat_core::Scalar;

/// The skeleton of the composite kernels: pixels `a..=b` of a row, eight at a time, skipping
/// groups that are opaque or whose cells' bricks have no opacity, sampling the volume
/// ([`Sampler8`]), computing each lane's slab exponent ([`boundary_factor`]) and compositing
/// what `src` returns front to back into the row's channel planes: lane `l` does exactly
/// [`Ctx::composite_one`]'s f32 operations for pixel `x + l`; the classification `src`
/// ([`Source8::src`]) gives the premultiplied colours and the lanes that contribute. Groups go
/// in chunks of [`CHUNK`], sampled first ([`Run::sample_group`]) and classified and composited
/// after ([`Run::composite_group`]), so that the gathers' cache misses overlap (decision 0016).
/// Returns the first pixel not done (`b + 1`, or earlier where a group's reads would pass the
/// end of the data, or the last pixels of the row where a group would pass it: those are left
/// to the scalar twin).
///
/// # Safety
/// The CPU must support AVX2.
///
/// [`boundary_factor`]: crate::slab::path::boundary_factor
#[inline]
#[target_feature(enable = "avx2")]
#[allow(clippy::too_many_arguments)]
pub(super) unsafe fn composite_groups_avx2<T: Scalar, V: Voxels<T>, S: Source8<T>>(
    ctx: &Ctx<'_, T, V>,
    walk: &Walk,
    sampler: &Sampler8<T>,
    (a, b): (usize, usize),
    row: &mut RowCtx<'_>,
    (post, src): (Post<'_>, &S),
    c: &mut Counters,
) -> usize {
    let run = Run::new(ctx, walk, sampler, row, post, src);
    let mut x = a;
    // Groups are taken in chunks: first each group of the chunk is tested and sampled, then each
    // is classified and composited. The gathers of a chunk's groups then do not wait on one
    // another's classification, so their cache misses overlap; every pixel still gets exactly
    // the operations of the one-group-at-a-time loop (the groups hold different pixels).
    // Each group is written in place into its slot and read there by reference: moving a
    // sampled group (≈ 0.8 KB with the shaded source's rows) cost 4–5 % of a shaded frame.
    let mut chunk: [MaybeUninit<Sampled<S::Pre>>; CHUNK] = [const { MaybeUninit::uninit() }; CHUNK];
    // The last group of the run may be partial: its lanes past `b` are masked (they read
    // clamped cells, valid reads, and store what they loaded).
    loop {
        let mut filled = 0;
        // Set where a group's reads would pass the end of the data: the run stops at `x`.
        let mut stop = false;
        while filled < CHUNK && x <= b && x + 8 <= row.a.len() {
            // SAFETY: the caller guarantees AVX2; x + 8 ≤ the row's length.
            match unsafe { run.sample_group(x, b, row, c, &mut chunk[filled]) } {
                Group::Done => {}
                Group::Sampled => filled += 1,
                Group::Stop => {
                    stop = true;
                    break;
                }
            }
            x += 8;
        }
        for g in &chunk[..filled] {
            // SAFETY: the first `filled` slots were written by `sample_group` (it returned
            // `Group::Sampled` for each); AVX2 and the group's pixels in the row are the
            // caller's guarantees.
            unsafe { run.composite_group(g.assume_init_ref(), row, c) };
        }
        if stop || filled == 0 {
            return x;
        }
    }
}

/// Groups of eight pixels sampled before any of them is composited ([`composite_groups_avx2`]).
const CHUNK: usize = 4;

/// A group of eight pixels tested and sampled, waiting to be classified and composited.
struct Sampled<P> {
    /// The group's first pixel.
    x: usize,
    /// The pixels' opacity before this plane.
    ar: __m256,
    /// The lanes that are below the cutoff, in the run and in bricks with opacity.
    live: __m256,
    /// The fractions in the samples' cells.
    frac: [__m256; 3],
    /// The densities at the pixels' samples on the plane before (`rho` where none).
    u: __m256,
    /// The samples.
    rho: __m256,
    /// What [`Source8::sample`] read for [`Source8::src`].
    pre: P,
}

/// What [`Run::sample_group`] made of a group.
enum Group {
    /// Nothing left to composite: every lane opaque or in empty bricks, or the scalar twin
    /// took the group.
    Done,
    /// Sampled into its slot, to be composited.
    Sampled,
    /// A read would pass the end of the data: the run stops at this group.
    Stop,
}

/// One run of [`composite_groups_avx2`] through one row of one plane: what every group reads,
/// with the row's constants broadcast to eight lanes.
struct Run<'r, 'a, T, V, S> {
    ctx: &'r Ctx<'a, T, V>,
    walk: &'r Walk,
    sampler: &'r Sampler8<T>,
    post: Post<'r>,
    src: &'r S,
    /// Pre-integrated classification ([`Ctx::preint_for`]).
    preint: bool,
    /// Every lane takes the path-corrected opacity (perspective, or pre-integration).
    all_corrected: bool,
    /// One byte per brick, padded so that a 4-byte read at the last brick stays inside
    /// ([`Ctx::active_bytes`]).
    active_bytes: *const i32,
    cutoff: __m256,
    /// [`boundary_factor`]'s bounds: `d ∓ 2·half` (a ray entering after the front or leaving
    /// before the back of the slab has a shorter path in it), `d ∓ half`, and `2·half`.
    ///
    /// [`boundary_factor`]: crate::slab::path::boundary_factor
    front: __m256,
    back: __m256,
    d_minus: __m256,
    d_plus: __m256,
    two_half: __m256,
    /// Pre-integration's stamps: this plane's index, and the next one's.
    this_plane: __m256i,
    next_stamp: __m256i,
}

impl<'r, 'a, T: Scalar, V: Voxels<T>, S: Source8<T>> Run<'r, 'a, T, V, S> {
    /// The run through `row`, classified by `src` (for `post`).
    #[inline]
    #[target_feature(enable = "avx2")]
    fn new(
        ctx: &'r Ctx<'a, T, V>,
        walk: &'r Walk,
        sampler: &'r Sampler8<T>,
        row: &RowCtx<'_>,
        post: Post<'r>,
        src: &'r S,
    ) -> Self {
        let d = row.d;
        let two_half = 2.0 * row.half;
        let preint = ctx.preint_for(post);
        Run {
            ctx,
            walk,
            sampler,
            post,
            src,
            preint,
            all_corrected: ctx.view.perspective || preint,
            active_bytes: ctx.active_bytes.as_ptr() as *const i32,
            cutoff: _mm256_set1_ps(ctx.cutoff),
            front: _mm256_set1_ps(d - two_half),
            back: _mm256_set1_ps(d + two_half),
            d_minus: _mm256_set1_ps(d - row.half),
            d_plus: _mm256_set1_ps(d + row.half),
            two_half: _mm256_set1_ps(two_half),
            this_plane: _mm256_set1_epi32(row.plane as i32),
            next_stamp: _mm256_set1_epi32(row.plane.wrapping_add(1) as i32),
        }
    }

    /// Tests the group of pixels `x..x + 8` (those up to `b` in the run) and samples its live
    /// lanes: the lanes below the cutoff, whose cells' bricks have opacity. Counts the opaque
    /// lanes as terminated and the sampled ones as samples; hands the live lanes that `src`
    /// cannot read to the scalar twin ([`Source8::scalar_lanes`]).
    ///
    /// # Safety
    /// The CPU must support AVX2, and `x + 8` may not pass the row's length.
    #[inline]
    #[target_feature(enable = "avx2")]
    unsafe fn sample_group(
        &self,
        x: usize,
        b: usize,
        row: &mut RowCtx<'_>,
        c: &mut Counters,
        slot: &mut MaybeUninit<Sampled<S::Pre>>,
    ) -> Group {
        let n = (b - x + 1).min(8);
        // SAFETY (all loads and calls below): AVX2 and x + 8 ≤ the row's length, the caller's
        // guarantees.
        let ar = unsafe { _mm256_loadu_ps(row.a.as_ptr().add(x)) };
        let live = _mm256_and_ps(_mm256_cmp_ps::<_CMP_LT_OQ>(ar, self.cutoff), first_lanes(n));
        let live_bits = _mm256_movemask_ps(live);
        if live_bits == 0 {
            c.terminated += n as u64;
            return Group::Done;
        }
        let cells = unsafe { self.sampler.locate(x) };
        c.terminated += u64::from(n as u32 - lanes(live_bits));
        let live = _mm256_and_ps(live, unsafe { self.active_lanes(&cells) });
        let live_bits = _mm256_movemask_ps(live);
        if live_bits == 0 {
            return Group::Done;
        }
        let scalar = unsafe { self.src.scalar_lanes(&cells, live) };
        let scalar_bits = _mm256_movemask_ps(scalar);
        if scalar_bits != 0 {
            // The scalar twin takes the live lanes the source cannot read now; the others go on
            // here. Every pixel gets its own operations either way (the twins agree bit for
            // bit), and the group's store later adds zero to the lanes it leaves out, which
            // keeps what the twin wrote (`Run::composite_group`).
            self.ctx
                .composite_lanes(self.walk, x, n, scalar_bits, row, self.post, c);
            if scalar_bits == live_bits {
                return Group::Done;
            }
        }
        let live = _mm256_andnot_ps(scalar, live);
        let live_bits = live_bits & !scalar_bits;
        let base = unsafe { self.sampler.base_of(&cells) };
        let frac = unsafe { cells.fractions() };
        let Some((rho, pre)) = (unsafe { self.src.sample(&cells, base, frac) }) else {
            return Group::Stop;
        };
        c.samples += u64::from(lanes(live_bits));
        let u = if self.preint {
            unsafe { self.previous_densities(row, x, rho, live) }
        } else {
            rho
        };
        slot.write(Sampled {
            x,
            ar,
            live,
            frac,
            u,
            rho,
            pre,
        });
        Group::Sampled
    }

    /// The mask of the lanes whose cell's brick can have opacity under the transfer function
    /// (every lane where no brick is skipped): lanes in other bricks contribute nothing, and a
    /// group all of whose lanes are in such bricks is not sampled.
    ///
    /// # Safety
    /// The CPU must support AVX2, and `cells` must be located by this run's sampler.
    #[inline]
    #[target_feature(enable = "avx2")]
    unsafe fn active_lanes(&self, cells: &Cells8) -> __m256 {
        if !self.ctx.skip_empty {
            return _mm256_castsi256_ps(_mm256_set1_epi32(-1));
        }
        // (One flag read where the group lies in one brick instead of the gather was
        // measured: no gain on the CT, 5 % slower on Colin27.)
        // SAFETY: the bricks of cells clamped to the grid index `active_bytes`, padded for the
        // 4-byte reads.
        let flags = unsafe {
            let brick = self.sampler.bricks_of(cells);
            _mm256_i32gather_epi32::<1>(self.active_bytes, brick)
        };
        _mm256_castsi256_ps(_mm256_cmpgt_epi32(
            _mm256_and_si256(flags, _mm256_set1_epi32(0xff)),
            _mm256_setzero_si256(),
        ))
    }

    /// Pre-integration: the densities of pixels `x..x + 8` on the plane before where they were
    /// sampled there (`rho` elsewhere), then this plane's `rho` kept for the next in the `live`
    /// lanes ([`Ctx::composite_one`]'s `prev` and `stamp`).
    ///
    /// # Safety
    /// The CPU must support AVX2, and `x + 8` may not pass the row's length (nor `prev`'s and
    /// `stamp`'s, as long as it).
    #[inline]
    #[target_feature(enable = "avx2")]
    unsafe fn previous_densities(
        &self,
        row: &mut RowCtx<'_>,
        x: usize,
        rho: __m256,
        live: __m256,
    ) -> __m256 {
        // SAFETY: x + 8 ≤ the row's length, and `prev`, `stamp` are as long as it.
        let pp = unsafe { row.prev.as_mut_ptr().add(x) };
        let sp = unsafe { row.stamp.as_mut_ptr().add(x) } as *mut __m256i;
        let (pv, st) = unsafe { (_mm256_loadu_ps(pp), _mm256_loadu_si256(sp)) };
        let have = _mm256_castsi256_ps(_mm256_cmpeq_epi32(st, self.this_plane));
        unsafe {
            _mm256_storeu_ps(pp, _mm256_blendv_ps(pv, rho, live));
            _mm256_storeu_si256(
                sp,
                _mm256_castps_si256(_mm256_blendv_ps(
                    _mm256_castsi256_ps(st),
                    _mm256_castsi256_ps(self.next_stamp),
                    live,
                )),
            );
        }
        _mm256_blendv_ps(rho, pv, have)
    }

    /// Classifies a sampled group ([`Source8::src`]) with its slab exponents and composites
    /// the lanes that contribute front to back into the row's channel planes.
    ///
    /// # Safety
    /// The CPU must support AVX2; `g` must come from [`Run::sample_group`] on this row.
    #[inline]
    #[target_feature(enable = "avx2")]
    unsafe fn composite_group(&self, g: &Sampled<S::Pre>, row: &mut RowCtx<'_>, c: &mut Counters) {
        let Sampled {
            x,
            ar,
            live,
            frac,
            u,
            rho,
            ref pre,
        } = *g;
        // SAFETY (all calls): the caller's guarantees.
        let k = unsafe { self.slab_exponents(row, x) };
        // Lanes that take the path-corrected form.
        let corrected = if self.all_corrected {
            _mm256_castsi256_ps(_mm256_set1_epi32(-1))
        } else {
            _mm256_cmp_ps::<_CMP_NEQ_UQ>(k, _mm256_set1_ps(1.0))
        };
        let (src, contributes) = unsafe { self.src.src(pre, frac, u, rho, k, corrected) };
        let mask = _mm256_and_ps(contributes, live);
        let bits = _mm256_movemask_ps(mask);
        if bits == 0 {
            return;
        }
        c.visible += u64::from(lanes(bits));
        let tr = _mm256_sub_ps(_mm256_set1_ps(1.0), ar);
        let chans: [&mut [f32]; 4] = [&mut *row.r, &mut *row.g, &mut *row.b, &mut *row.a];
        for (ch, plane) in chans.into_iter().enumerate() {
            let p = unsafe { plane.as_mut_ptr().add(x) };
            let old = unsafe { _mm256_loadu_ps(p) };
            // Masked lanes add a zero (of either sign), which leaves every value an
            // accumulation can hold (never −0) bit for bit, so the store needs no blend
            // (a blended store compiles to `vmaskmovps`, slow on AMD).
            let add = _mm256_mul_ps(tr, _mm256_and_ps(src[ch], mask));
            unsafe { _mm256_storeu_ps(p, _mm256_add_ps(old, add)) };
        }
    }

    /// The slab's opacity exponents of pixels `x..x + 8`: [`boundary_factor`] lane by lane
    /// (the path factor, shortened in the first and last slab of a ray).
    ///
    /// # Safety
    /// The CPU must support AVX2, and `x + 8` may not pass the row's length.
    ///
    /// [`boundary_factor`]: crate::slab::path::boundary_factor
    #[inline]
    #[target_feature(enable = "avx2")]
    unsafe fn slab_exponents(&self, row: &RowCtx<'_>, x: usize) -> __m256 {
        // SAFETY: x + 8 ≤ the row's length, as long as `kf`, `din` and `dout`.
        let kf = unsafe { _mm256_loadu_ps(row.kf.as_ptr().add(x)) };
        let din = unsafe { _mm256_loadu_ps(row.din.as_ptr().add(x)) };
        let dout = unsafe { _mm256_loadu_ps(row.dout.as_ptr().add(x)) };
        let lo_cut = _mm256_cmp_ps::<_CMP_LT_OQ>(self.front, din);
        let hi_cut = _mm256_cmp_ps::<_CMP_GT_OQ>(self.back, dout);
        let cut = _mm256_or_ps(lo_cut, hi_cut);
        if _mm256_movemask_ps(cut) == 0 {
            return kf;
        }
        let l = _mm256_blendv_ps(self.d_minus, din, lo_cut);
        let h = _mm256_blendv_ps(self.d_plus, dout, hi_cut);
        let q = _mm256_max_ps(
            _mm256_div_ps(_mm256_sub_ps(h, l), self.two_half),
            _mm256_setzero_ps(),
        );
        _mm256_blendv_ps(kf, _mm256_mul_ps(kf, q), cut)
    }
}

/// Composite of pixels `a..=b` of a row, eight at a time ([`composite_groups_avx2`]), classified
/// unshaded through the post table ([`PostSource`]) or shaded ([`ShadeSource`]).
///
/// # Safety
/// The CPU must support AVX2.
#[target_feature(enable = "avx2")]
pub(in crate::slab) unsafe fn composite_run_avx2<T: Scalar, V: Voxels<T>>(
    ctx: &Ctx<'_, T, V>,
    walk: &Walk,
    a: usize,
    b: usize,
    row: &mut RowCtx<'_>,
    post: Post<'_>,
    c: &mut Counters,
) -> usize {
    use std::arch::x86_64::*;
    // SAFETY (all calls): the caller guarantees AVX2.
    let sampler = unsafe { Sampler8::new(ctx, walk) };
    match post {
        Post::Table(t) => unsafe {
            let src = PostSource {
                t,
                sampler: &sampler,
                preint: ctx.preint_for(post),
            };
            composite_groups_avx2(ctx, walk, &sampler, (a, b), row, (post, &src), c)
        },
        // Central differences need a voxel each side of a cell: grids under 4 voxels on an axis
        // have no interior cell, and take the scalar twin.
        Post::Shaded(_) if ctx.dims.iter().any(|&n| n < 4) => a,
        Post::Voxel(t, vs) => {
            let src = VoxelShadeSource {
                t,
                vs,
                sampler: &sampler,
                codes: ctx.codes.as_ptr() as *const i32,
                x_shift: _mm_cvtsi32_si128(16 * ctx.vox.up()[0] as i32),
                preint: ctx.preint_for(post),
                back_s: row.back_s.map(|v| _mm256_set1_ps(v)),
                back_st: row.back_st.map(|v| _mm256_set1_ps(v)),
            };
            unsafe { composite_groups_avx2(ctx, walk, &sampler, (a, b), row, (post, &src), c) }
        }
        Post::Shaded(t) => {
            let src = ShadeSource {
                t,
                sampler: &sampler,
                inner_max: ctx.dims.map(|n| _mm256_set1_epi32(n as i32 - 3)),
                top: ctx.dims.map(|n| _mm256_set1_epi32(n as i32 - 2)),
                near_end: [0, 1, 2]
                    .map(|a| _mm256_set1_epi32(ctx.dims[a] as i32 - if a == 0 { 5 } else { 4 })),
                clamp_hi: _mm256_set1_epi32(neighbour_last::<T>(ctx.vox.data().len())),
                safe_base: _mm256_set1_epi32(
                    (1 + ctx.vox.stride()[1] + ctx.vox.stride()[2]) as i32,
                ),
                back_s: row.back_s.map(|v| _mm256_set1_ps(v)),
                back_st: row.back_st.map(|v| _mm256_set1_ps(v)),
                preint: ctx.preint_for(post),
            };
            unsafe { composite_groups_avx2(ctx, walk, &sampler, (a, b), row, (post, &src), c) }
        }
    }
}

/// The largest index at which a read of two samples ([`Sampler8::gather2`]: one 4-byte word
/// for 8- and 16-bit samples, two gathers for 32-bit ones) stays inside data of `len` samples
/// of type `T`: the bound [`ShadeSource`] clamps its face lanes' neighbour rows to.
fn neighbour_last<T>(len: usize) -> i32 {
    let bytes = std::mem::size_of::<T>();
    let last = if bytes < 4 {
        (len * bytes).saturating_sub(4) / bytes
    } else {
        len.saturating_sub(2)
    };
    last as i32
}

/// The sampling and classification of a group of eight samples for [`composite_groups_avx2`].
pub(super) trait Source8<T> {
    /// What [`Source8::sample`] read that [`Source8::src`] uses again.
    type Pre;

    /// The lanes of `live` that must take the scalar twin (the kernel cannot read what it
    /// needs there), as a mask: none by default.
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[inline]
    #[target_feature(enable = "avx2")]
    unsafe fn scalar_lanes(
        &self,
        _cells: &Cells8,
        _live: std::arch::x86_64::__m256,
    ) -> std::arch::x86_64::__m256 {
        std::arch::x86_64::_mm256_setzero_ps()
    }

    /// The trilinear samples in `cells` (linear indices `base`, fractions `frac`), as
    /// [`Sampler8::sample_at`] computes them, or `None` where a read would pass the end of the
    /// data.
    ///
    /// # Safety
    /// The CPU must support AVX2; the cells must be the volume's, and no live lane may need
    /// the scalar twin ([`Source8::scalar_lanes`]).
    unsafe fn sample(
        &self,
        cells: &Cells8,
        base: std::arch::x86_64::__m256i,
        frac: [std::arch::x86_64::__m256; 3],
    ) -> Option<(std::arch::x86_64::__m256, Self::Pre)>;

    /// The premultiplied colours of the samples `rho` at fractions `frac` with slab exponents
    /// `k`, and the mask of lanes that contribute; `corrected` is the mask of lanes whose
    /// opacity takes the path correction (perspective, `k ≠ 1`, or pre-integration). `u`:
    /// the densities at the pixels' samples on the plane before (`rho` where there are none),
    /// read by the sources that pre-integrate ([`Ctx::preint_for`]).
    ///
    /// # Safety
    /// The CPU must support AVX2; `pre` must come from [`Source8::sample`].
    unsafe fn src(
        &self,
        pre: &Self::Pre,
        frac: [std::arch::x86_64::__m256; 3],
        u: std::arch::x86_64::__m256,
        rho: std::arch::x86_64::__m256,
        k: std::arch::x86_64::__m256,
        corrected: std::arch::x86_64::__m256,
    ) -> ([std::arch::x86_64::__m256; 4], std::arch::x86_64::__m256);
}

/// Unshaded classification through the post table: lane `l` does exactly [`Ctx::post_src`]'s
/// f32 operations (table lookups with paired rows, the path correction with the same polynomial
/// `exp2`).
pub(in crate::slab) struct PostSource<'a, T> {
    t: &'a PostTable,
    sampler: &'a Sampler8<T>,
    /// Classify the segment from `u` to `rho` ([`post_segment8`]).
    preint: bool,
}

impl<T: Scalar> Source8<T> for PostSource<'_, T> {
    type Pre = ();

    #[inline]
    #[target_feature(enable = "avx2")]
    unsafe fn sample(
        &self,
        _: &Cells8,
        base: std::arch::x86_64::__m256i,
        frac: [std::arch::x86_64::__m256; 3],
    ) -> Option<(std::arch::x86_64::__m256, ())> {
        // SAFETY: the caller's guarantees.
        Some((unsafe { self.sampler.sample_at(base, frac) }?, ()))
    }

    #[inline]
    #[target_feature(enable = "avx2")]
    unsafe fn src(
        &self,
        _: &(),
        _: [std::arch::x86_64::__m256; 3],
        u: std::arch::x86_64::__m256,
        rho: std::arch::x86_64::__m256,
        k: std::arch::x86_64::__m256,
        corrected: std::arch::x86_64::__m256,
    ) -> ([std::arch::x86_64::__m256; 4], std::arch::x86_64::__m256) {
        use std::arch::x86_64::*;
        let t = self.t;
        let zero = _mm256_setzero_ps();
        let one = _mm256_set1_ps(1.0);
        if self.preint {
            // Every lane is path-corrected ([`Ctx::post_seg_src`]).
            // SAFETY: the caller guarantees AVX2.
            let v = unsafe { post_segment8(t, u, rho) };
            let l = v[3];
            let ok = _mm256_cmp_ps::<_CMP_LT_OQ>(l, zero);
            let a = _mm256_sub_ps(one, exp2_neg8(_mm256_mul_ps(k, l)));
            let src = [
                _mm256_mul_ps(v[0], a),
                _mm256_mul_ps(v[1], a),
                _mm256_mul_ps(v[2], a),
                a,
            ];
            return (src, ok);
        }
        let pos = table_pos8(rho, t.axis);
        let corrected_bits = _mm256_movemask_ps(corrected);
        let mut src = [zero; 4];
        let mut contributes = _mm256_setzero_ps();
        // SAFETY (interp8): positions are clamped to [0, last], rows of the paired tables.
        if corrected_bits != 0xff {
            let v = unsafe { interp8(&t.pairs, pos, true) };
            src = [v[0], v[1], v[2], v[3]];
            contributes = _mm256_cmp_ps::<_CMP_GT_OQ>(v[3], zero);
        }
        if corrected_bits != 0 {
            let v = unsafe { interp8(&t.persp_pairs, pos, true) };
            let l = v[3];
            let ok = _mm256_cmp_ps::<_CMP_LT_OQ>(l, zero);
            let a = _mm256_sub_ps(one, exp2_neg8(_mm256_mul_ps(k, l)));
            src[0] = _mm256_blendv_ps(src[0], _mm256_mul_ps(v[0], a), corrected);
            src[1] = _mm256_blendv_ps(src[1], _mm256_mul_ps(v[1], a), corrected);
            src[2] = _mm256_blendv_ps(src[2], _mm256_mul_ps(v[2], a), corrected);
            src[3] = _mm256_blendv_ps(src[3], a, corrected);
            contributes = _mm256_blendv_ps(contributes, ok, corrected);
        }
        (src, contributes)
    }
}

/// Which lanes of a segment from table position `tu` to `tv` take the middle entry (shorter
/// than [`SEGMENT_MIN_ENTRIES`]), the middle position, and `tv − tu`.
#[inline]
#[target_feature(enable = "avx2")]
fn segment_split8(
    tu: std::arch::x86_64::__m256,
    tv: std::arch::x86_64::__m256,
) -> (
    std::arch::x86_64::__m256,
    std::arch::x86_64::__m256,
    std::arch::x86_64::__m256,
) {
    use std::arch::x86_64::*;
    let dt = _mm256_sub_ps(tv, tu);
    let abs = _mm256_andnot_ps(_mm256_set1_ps(-0.0), dt);
    let short = _mm256_cmp_ps::<_CMP_LT_OQ>(abs, _mm256_set1_ps(SEGMENT_MIN_ENTRIES));
    let mid = _mm256_mul_ps(_mm256_add_ps(tu, tv), _mm256_set1_ps(0.5));
    (short, mid, dt)
}

/// [`segment_average`] on eight lanes: the same f32 operations, the branch as a blend;
/// `mid_rows` and `integ` are the table's entry rows and integral rows, `paired` as
/// [`interp8`] reads them.
///
/// # Safety
/// The CPU must support AVX2; for every position in `[0, last]` the rows [`interp8`] reads must
/// exist in both tables.
///
/// [`segment_average`]: crate::slab::tables::segment_average
#[inline]
#[target_feature(enable = "avx2")]
#[allow(clippy::too_many_arguments)]
pub(super) unsafe fn segment_average8<const N: usize, const W: usize, const L: usize>(
    axis: TableAxis,
    u: std::arch::x86_64::__m256,
    v: std::arch::x86_64::__m256,
    mid_rows: &[[f32; 8]],
    integ: &[[f32; 8]],
    paired: bool,
) -> [std::arch::x86_64::__m256; N] {
    use std::arch::x86_64::*;
    let (w, l) = (W, L);
    let tu = table_pos8(u, axis);
    let tv = table_pos8(v, axis);
    let (short, mid, dt) = segment_split8(tu, tv);
    let bits = _mm256_movemask_ps(short);
    let zero = _mm256_setzero_ps();
    let mut out = [zero; N];
    // SAFETY (interp8): the caller's guarantee.
    if bits != 0 {
        let m = unsafe { interp8(mid_rows, mid, paired) };
        out = std::array::from_fn(|c| m[c]);
    }
    if bits != 0xff {
        let a = unsafe { interp8(integ, tu, paired) };
        let b = unsafe { interp8(integ, tv, paired) };
        let dl = _mm256_sub_ps(b[w], a[w]);
        let inv = _mm256_div_ps(_mm256_set1_ps(1.0), dl);
        for (c, o) in out.iter_mut().enumerate() {
            let seg = if c == l {
                _mm256_div_ps(dl, dt)
            } else if c == w {
                zero
            } else {
                _mm256_mul_ps(_mm256_sub_ps(b[c], a[c]), inv)
            };
            *o = _mm256_blendv_ps(seg, *o, short);
        }
    }
    out
}

/// [`PostTable::segment`] on eight lanes ([`segment_average8`]).
///
/// # Safety
/// The CPU must support AVX2.
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn post_segment8(
    t: &PostTable,
    u: std::arch::x86_64::__m256,
    v: std::arch::x86_64::__m256,
) -> [std::arch::x86_64::__m256; 4] {
    // SAFETY: the paired tables have a row per position in [0, last].
    unsafe { segment_average8::<4, 3, 3>(t.axis, u, v, &t.persp_pairs, &t.integ_pairs, true) }
}
