//! Trilinear samples of eight pixels: the cells located and the corners gathered.

use super::super::march::Ctx;
use super::super::view::Walk;
use crate::bricks::BRICK;
use crate::voxels::Voxels;
use volsplat_core::Scalar;
use volsplat_core::source::HALO;

/// Trilinear samples of one row of one plane, eight pixels at a time with AVX2: lane `l` does
/// exactly [`Ctx::sample_scalar`]'s f32 operations for pixel `x + l` (no fused multiply–add:
/// AVX2 without FMA), and reads the volume with `vpgatherdd`: 8-bit and 16-bit samples are
/// gathered as 32-bit words holding two corners along x and masked (sign-extended for signed
/// types), so a group whose last corner lies within 3 bytes of the end of the data is left to
/// the scalar path.
pub(in crate::slab) struct Sampler8<T> {
    ptr: *const i32,
    kind: volsplat_core::ScalarType,
    small: bool,
    pub(super) offs: [i32; 8],
    s: [std::arch::x86_64::__m256; 3],
    st: [std::arch::x86_64::__m256; 3],
    pub(super) maxc: [std::arch::x86_64::__m256i; 3],
    pub(super) sy: std::arch::x86_64::__m256i,
    pub(super) sz: std::arch::x86_64::__m256i,
    last_ok: std::arch::x86_64::__m256i,
    /// Bits from a corner's sample to the next one's along x within a 32-bit word (8- and
    /// 16-bit samples): `8·ux` or `16·ux`.
    x_shift: std::arch::x86_64::__m128i,
    /// Bricks along x and y ([`Sampler8::bricks_of`]).
    bdims: [std::arch::x86_64::__m256i; 2],
    /// The slot table of a bricked addressing ([`Voxels::slots`]); `None` for one array.
    slots: Option<Slots8>,
    _t: std::marker::PhantomData<T>,
}

/// [`crate::voxels::Slots`] broadcast to eight lanes ([`Sampler8::base_of`]).
struct Slots8 {
    bases: *const i32,
    shift: std::arch::x86_64::__m128i,
    mask: std::arch::x86_64::__m256i,
    /// Bricks along x and y.
    bdims: [std::arch::x86_64::__m256i; 2],
    /// `H·(1 + E + E²)`: the halo's offset of a slot's first owned voxel.
    halo: std::arch::x86_64::__m256i,
}

/// Eight lanes' index positions and cells ([`Sampler8::locate`]); the fractions in the cells
/// are computed only for groups that are sampled ([`Cells8::fractions`]).
pub(in crate::slab) struct Cells8 {
    pub(super) cell: [std::arch::x86_64::__m256i; 3],
    pub(super) pos: [std::arch::x86_64::__m256; 3],
    /// The lanes' pixel columns as f32.
    pub(super) xf: std::arch::x86_64::__m256,
}

impl Cells8 {
    /// The fractions in the cells, clamped to [0, 1]: [`Ctx::cell_f32`] lane by lane.
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[inline]
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn fractions(&self) -> [std::arch::x86_64::__m256; 3] {
        use std::arch::x86_64::*;
        let (zero, one) = (_mm256_setzero_ps(), _mm256_set1_ps(1.0));
        let mut frac = [zero; 3];
        for (ax, f) in frac.iter_mut().enumerate() {
            let d = _mm256_sub_ps(self.pos[ax], _mm256_cvtepi32_ps(self.cell[ax]));
            *f = _mm256_min_ps(_mm256_max_ps(d, zero), one);
        }
        frac
    }
}

impl<T: Scalar> Sampler8<T> {
    /// # Safety
    /// The CPU must support AVX2.
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn new<V: Voxels<T>>(ctx: &Ctx<'_, T, V>, walk: &Walk) -> Self {
        use std::arch::x86_64::*;
        let data = ctx.vox.data();
        let bytes = std::mem::size_of::<T>();
        // Largest index whose 4-byte read stays inside the data.
        let safe_last = std::mem::size_of_val(data).saturating_sub(4) / bytes;
        let [ux, uy, uz] = ctx.vox.up();
        Sampler8 {
            ptr: data.as_ptr() as *const i32,
            kind: T::TYPE,
            small: bytes < 4,
            offs: [0, ux, uy, uy + ux, uz, uz + ux, uz + uy, uz + uy + ux].map(|o| o as i32),
            s: walk.s32.map(|v| _mm256_set1_ps(v)),
            st: walk.st32.map(|v| _mm256_set1_ps(v)),
            maxc: ctx.max_cell.map(|m| _mm256_set1_epi32(m as i32)),
            sy: _mm256_set1_epi32(ctx.vox.stride()[1] as i32),
            sz: _mm256_set1_epi32(ctx.vox.stride()[2] as i32),
            last_ok: _mm256_set1_epi32(safe_last as i32),
            x_shift: _mm_cvtsi32_si128((8 * bytes * ux).min(32) as i32),
            bdims: [
                _mm256_set1_epi32(ctx.bricks.dims[0] as i32),
                _mm256_set1_epi32(ctx.bricks.dims[1] as i32),
            ],
            slots: ctx.vox.slots().map(|s| Slots8 {
                bases: s.bases.as_ptr() as *const i32,
                shift: _mm_cvtsi32_si128(s.shift as i32),
                mask: _mm256_set1_epi32(((1usize << s.shift) - 1) as i32),
                bdims: [
                    _mm256_set1_epi32(s.bdims[0] as i32),
                    _mm256_set1_epi32(s.bdims[1] as i32),
                ],
                halo: _mm256_set1_epi32((HALO * (1 + s.e + s.e * s.e)) as i32),
            }),
            _t: std::marker::PhantomData,
        }
    }

    /// The samples of pixels `x..x + 8` (all of whose cells are clamped to the grid), or `None`
    /// where an 8/16-bit read would pass the end of the data.
    ///
    /// # Safety
    /// The CPU must support AVX2, and the sampler must have been made for this volume.
    #[inline]
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn at(&self, x: usize) -> Option<std::arch::x86_64::__m256> {
        // SAFETY: the caller's guarantees are these calls' own.
        unsafe { self.sample(&self.locate(x)) }
    }

    /// The cells of pixels `x..x + 8` (clamped to the grid) and the fractions in them:
    /// [`Ctx::cell_f32`] lane by lane.
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[inline]
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn locate(&self, x: usize) -> Cells8 {
        use std::arch::x86_64::*;
        let zero = _mm256_setzero_ps();
        let izero = _mm256_setzero_si256();
        // x + lane as f32: exact (x < 2^24), equal to the scalar `x as f32`.
        let xf = _mm256_add_ps(
            _mm256_set1_ps(x as f32),
            _mm256_setr_ps(0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0),
        );
        let mut cell = [izero; 3];
        let mut pos = [zero; 3];
        for ax in 0..3 {
            let q = _mm256_add_ps(self.s[ax], _mm256_mul_ps(xf, self.st[ax]));
            pos[ax] = q;
            cell[ax] = _mm256_min_epi32(
                _mm256_max_epi32(_mm256_cvttps_epi32(q), izero),
                self.maxc[ax],
            );
        }
        Cells8 { cell, pos, xf }
    }

    /// The brick (`BrickGrid::index`) of each lane's cell.
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[inline]
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn bricks_of(&self, c: &Cells8) -> std::arch::x86_64::__m256i {
        use std::arch::x86_64::*;
        let bdims = self.bdims;
        const S: i32 = BRICK.trailing_zeros() as i32;
        let [i, j, k] = c.cell.map(|v| _mm256_srli_epi32::<S>(v));
        _mm256_add_epi32(
            _mm256_mullo_epi32(
                _mm256_add_epi32(_mm256_mullo_epi32(k, bdims[1]), j),
                bdims[0],
            ),
            i,
        )
    }

    /// The trilinear samples at located cells ([`Sampler8::locate`]), or `None` where an
    /// 8/16-bit read would pass the end of the data.
    ///
    /// # Safety
    /// The CPU must support AVX2, and the sampler must have been made for this volume.
    #[inline]
    #[target_feature(enable = "avx2")]
    pub(in crate::slab) unsafe fn sample(&self, c: &Cells8) -> Option<std::arch::x86_64::__m256> {
        // SAFETY: the caller's guarantees are these calls' own.
        unsafe { self.sample_at(self.base_of(c), c.fractions()) }
    }

    /// The linear index of each lane's cell (its lower corner).
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[inline]
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn base_of(&self, c: &Cells8) -> std::arch::x86_64::__m256i {
        use std::arch::x86_64::*;
        let cell = &c.cell;
        if let Some(sl) = &self.slots {
            // SAFETY: the caller's guarantees.
            return unsafe { self.slotted_base(sl, c) };
        }
        _mm256_add_epi32(
            cell[0],
            _mm256_add_epi32(
                _mm256_mullo_epi32(cell[1], self.sy),
                _mm256_mullo_epi32(cell[2], self.sz),
            ),
        )
    }

    /// [`Sampler8::base_of`] for resident bricks ([`crate::voxels::Slotted::cell_base`]): the
    /// slot of each lane's brick, gathered, plus the cell's place in it. Kept out of line so
    /// that `base_of` stays small enough for the kernels around it to be inlined whole (inlined,
    /// it cost in-memory shaded frames 20 %, measured with perf on Colin27).
    ///
    /// # Safety
    /// The CPU must support AVX2, and `c` must be located by this sampler.
    #[inline(never)]
    #[target_feature(enable = "avx2")]
    unsafe fn slotted_base(&self, sl: &Slots8, c: &Cells8) -> std::arch::x86_64::__m256i {
        use std::arch::x86_64::*;
        let cell = &c.cell;
        let [i, j, k] = cell.map(|v| _mm256_srl_epi32(v, sl.shift));
        let brick = _mm256_add_epi32(
            _mm256_mullo_epi32(
                _mm256_add_epi32(_mm256_mullo_epi32(k, sl.bdims[1]), j),
                sl.bdims[0],
            ),
            i,
        );
        // SAFETY: cells are clamped to the grid, so their bricks index `bases`.
        let slot = unsafe { _mm256_i32gather_epi32::<4>(sl.bases, brick) };
        let [li, lj, lk] = cell.map(|v| _mm256_and_si256(v, sl.mask));
        _mm256_add_epi32(
            _mm256_add_epi32(slot, sl.halo),
            _mm256_add_epi32(
                li,
                _mm256_add_epi32(
                    _mm256_mullo_epi32(lj, self.sy),
                    _mm256_mullo_epi32(lk, self.sz),
                ),
            ),
        )
    }

    /// Voxels `idx, idx + 1, …, idx + N − 1` of each lane as f32 (`N` = 2 or 4): one 32-bit
    /// gather for four 8-bit voxels, one per two 16-bit voxels, one per 32-bit voxel.
    ///
    /// # Safety
    /// The CPU must support AVX2; for every lane the voxels read must lie in the data, and for
    /// 8/16-bit samples the 4-byte word read at each gathered voxel too.
    #[inline]
    #[target_feature(enable = "avx2")]
    unsafe fn gather_run<const N: usize>(
        &self,
        idx: std::arch::x86_64::__m256i,
    ) -> [std::arch::x86_64::__m256; N] {
        use std::arch::x86_64::*;
        use volsplat_core::ScalarType;
        let mut out = [_mm256_setzero_ps(); N];
        let ptr = self.ptr;
        // SAFETY (gathers): the caller guarantees the reads.
        match self.kind {
            ScalarType::U8 | ScalarType::I8 => {
                let w = unsafe { _mm256_i32gather_epi32::<1>(ptr, idx) };
                for (j, o) in out.iter_mut().enumerate() {
                    let v = if self.kind == ScalarType::U8 {
                        _mm256_and_si256(
                            _mm256_srlv_epi32(w, _mm256_set1_epi32(8 * j as i32)),
                            _mm256_set1_epi32(0xff),
                        )
                    } else {
                        _mm256_srai_epi32::<24>(_mm256_sllv_epi32(
                            w,
                            _mm256_set1_epi32(24 - 8 * j as i32),
                        ))
                    };
                    *o = _mm256_cvtepi32_ps(v);
                }
            }
            ScalarType::U16 | ScalarType::I16 => {
                for p in 0..N / 2 {
                    let at = _mm256_add_epi32(idx, _mm256_set1_epi32(2 * p as i32));
                    let w = unsafe { _mm256_i32gather_epi32::<2>(ptr, at) };
                    let (lo, hi) = if self.kind == ScalarType::U16 {
                        (
                            _mm256_and_si256(w, _mm256_set1_epi32(0xffff)),
                            _mm256_srli_epi32::<16>(w),
                        )
                    } else {
                        (
                            _mm256_srai_epi32::<16>(_mm256_slli_epi32::<16>(w)),
                            _mm256_srai_epi32::<16>(w),
                        )
                    };
                    out[2 * p] = _mm256_cvtepi32_ps(lo);
                    out[2 * p + 1] = _mm256_cvtepi32_ps(hi);
                }
            }
            ScalarType::F32 => {
                for (j, o) in out.iter_mut().enumerate() {
                    let at = _mm256_add_epi32(idx, _mm256_set1_epi32(j as i32));
                    *o = unsafe { _mm256_i32gather_ps::<4>(ptr as *const f32, at) };
                }
            }
        }
        out
    }

    /// Voxels `idx … idx + 3` ([`Sampler8::gather_run`]).
    ///
    /// # Safety
    /// As [`Sampler8::gather_run`].
    #[inline]
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn gather4(
        &self,
        idx: std::arch::x86_64::__m256i,
    ) -> [std::arch::x86_64::__m256; 4] {
        // SAFETY: the caller's guarantees.
        unsafe { self.gather_run::<4>(idx) }
    }

    /// Voxels `idx` and `idx + 1` ([`Sampler8::gather_run`]).
    ///
    /// # Safety
    /// As [`Sampler8::gather_run`].
    #[inline]
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn gather2(
        &self,
        idx: std::arch::x86_64::__m256i,
    ) -> [std::arch::x86_64::__m256; 2] {
        // SAFETY: the caller's guarantees.
        unsafe { self.gather_run::<2>(idx) }
    }

    /// The trilinear samples in the cells with linear indices `base` ([`Sampler8::base_of`]) at
    /// fractions `frac` ([`Cells8::fractions`]), or `None` where an 8/16-bit read would pass the
    /// end of the data.
    ///
    /// # Safety
    /// The CPU must support AVX2, and `base` must come from cells located by this sampler (or
    /// one with the same grid).
    #[inline]
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn sample_at(
        &self,
        base: std::arch::x86_64::__m256i,
        frac: [std::arch::x86_64::__m256; 3],
    ) -> Option<std::arch::x86_64::__m256> {
        use std::arch::x86_64::*;
        use volsplat_core::ScalarType;
        let top = _mm256_add_epi32(base, _mm256_set1_epi32(self.offs[7]));
        if self.small && _mm256_movemask_epi8(_mm256_cmpgt_epi32(top, self.last_ok)) != 0 {
            return None;
        }
        let ptr = self.ptr;
        let kind = self.kind;
        let shift = self.x_shift;
        // One 32-bit read per pair of corners along x: for 8- and 16-bit samples the voxel
        // `ux` further (the next byte or half-word, or the same one where the grid is one voxel
        // wide) lies in the same word, so four gathers fetch the eight corners; 32-bit samples
        // need one gather per corner.
        macro_rules! gather_pair {
            ($o:expr, $ox:expr) => {{
                let idx = _mm256_add_epi32(base, _mm256_set1_epi32($o));
                // SAFETY: every index is a voxel of the volume (cells are clamped to the grid), and
                // for 8/16-bit samples the 4-byte read ends inside the data (checked above).
                // The word's low sample and the one `shift` bits up, zero-extended under `mask`
                // or sign-extended from the top `bits` of the word.
                macro_rules! unsigned {
                    ($w:expr, $mask:expr) => {{
                        let (w, m) = ($w, _mm256_set1_epi32($mask));
                        (
                            _mm256_cvtepi32_ps(_mm256_and_si256(w, m)),
                            _mm256_cvtepi32_ps(_mm256_and_si256(_mm256_srl_epi32(w, shift), m)),
                        )
                    }};
                }
                macro_rules! signed {
                    ($w:expr, $bits:literal) => {{
                        let w = $w;
                        let hi = _mm256_srl_epi32(w, shift);
                        (
                            _mm256_cvtepi32_ps(_mm256_srai_epi32::<$bits>(_mm256_slli_epi32::<
                                $bits,
                            >(w))),
                            _mm256_cvtepi32_ps(_mm256_srai_epi32::<$bits>(_mm256_slli_epi32::<
                                $bits,
                            >(hi))),
                        )
                    }};
                }
                unsafe {
                    match kind {
                        ScalarType::U8 => unsigned!(_mm256_i32gather_epi32::<1>(ptr, idx), 0xff),
                        ScalarType::I8 => signed!(_mm256_i32gather_epi32::<1>(ptr, idx), 24),
                        ScalarType::U16 => unsigned!(_mm256_i32gather_epi32::<2>(ptr, idx), 0xffff),
                        ScalarType::I16 => signed!(_mm256_i32gather_epi32::<2>(ptr, idx), 16),
                        ScalarType::F32 => {
                            let p = ptr as *const f32;
                            (
                                _mm256_i32gather_ps::<4>(p, idx),
                                _mm256_i32gather_ps::<4>(
                                    p,
                                    _mm256_add_epi32(base, _mm256_set1_epi32($ox)),
                                ),
                            )
                        }
                    }
                }
            }};
        }
        macro_rules! lerp8 {
            ($a:expr, $b:expr, $t:expr) => {{
                let (a, b) = ($a, $b);
                _mm256_add_ps(a, _mm256_mul_ps($t, _mm256_sub_ps(b, a)))
            }};
        }
        let o = self.offs;
        let (v0, v1) = gather_pair!(o[0], o[1]);
        let (v2, v3) = gather_pair!(o[2], o[3]);
        let (v4, v5) = gather_pair!(o[4], o[5]);
        let (v6, v7) = gather_pair!(o[6], o[7]);
        let v = [v0, v1, v2, v3, v4, v5, v6, v7];
        let c00 = lerp8!(v[0], v[1], frac[0]);
        let c10 = lerp8!(v[2], v[3], frac[0]);
        let c01 = lerp8!(v[4], v[5], frac[0]);
        let c11 = lerp8!(v[6], v[7], frac[0]);
        Some(lerp8!(
            lerp8!(c00, c10, frac[1]),
            lerp8!(c01, c11, frac[1]),
            frac[2]
        ))
    }
}
