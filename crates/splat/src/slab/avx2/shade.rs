//! Shaded classification on eight lanes: at the samples, with the central differences
//! gathered from the volume ([`ShadeSource`]), and at the voxels ([`VoxelShadeSource`]).

use super::composite::{Source8, segment_average8};
use super::sampler::{Cells8, Sampler8};
use super::{dot8, exp2_neg8, interp8, lerp8, splat3, table_pos8};
use crate::normals::VoxelShading;
use crate::slab::shade::{LIGHT_SHIFT, SEGMENT_LIGHT_AT, SEGMENT_SECOND_LIGHT};
use crate::slab::tables::ShadeTable;
use volsplat_core::Scalar;

/// Shaded classification lit at the samples ([`shade_terms8`], then [`lit_colour8`] twice:
/// decision 0036) with the voxels' central differences gathered from the volume itself and
/// interpolated in the sample's cell at the two lights' fractions: lane `l` does exactly
/// [`Ctx::gradient_lerp`]'s and [`shaded_src_two`]'s f32 operations. A cell's differences read
/// the 4×4×4 block around it without its edges: four rows of four voxels along x through the
/// cell's own four (y, z) corners, and eight rows of two beside them (the rows one before and two
/// after along y and z). On the faces of the grid the twin's differences are one-sided, from
/// the cell's own corners: lanes there take them from the four central rows (blended in place
/// of the central ones), and the reads beyond the face land on other voxels of the volume
/// (their values are dropped; the neighbour rows' indices are clamped into the data). Only the
/// grid's first cell and the few cells by its last corner, whose reads would pass the data's
/// ends ([`ShadeSource::end_cells`]), take the scalar twin.
///
/// [`shaded_src_two`]: crate::slab::shade::shaded_src_two
/// [`Ctx::gradient_lerp`]: crate::slab::march::Ctx::gradient_lerp
pub(in crate::slab) struct ShadeSource<'a, T> {
    pub(super) t: &'a ShadeTable,
    pub(super) sampler: &'a Sampler8<T>,
    /// `n − 3` per axis: the largest interior cell.
    pub(super) inner_max: [std::arch::x86_64::__m256i; 3],
    /// `n − 2` per axis: the last cell (on the upper face).
    pub(super) top: [std::arch::x86_64::__m256i; 3],
    /// `n − 5, n − 4, n − 4`: cells above these on every axis lie near the data's end
    /// ([`ShadeSource::end_cells`]).
    pub(super) near_end: [std::arch::x86_64::__m256i; 3],
    /// The largest index a neighbour row's read of two samples may start at and stay inside
    /// the data; face lanes' neighbour rows are clamped to `[0, it]` (every read that is inside
    /// starts there or before, so the clamp leaves them).
    pub(super) clamp_hi: std::arch::x86_64::__m256i,
    /// The linear index of cell (1, 1, 1), read in place of the lanes that take the scalar
    /// twin (their results are dropped).
    pub(super) safe_base: std::arch::x86_64::__m256i,
    /// [`RowCtx::back_s`], [`RowCtx::back_st`] broadcast: the step back to the plane before,
    /// which places the two lights ([`ShadeSource::light_fractions`]).
    ///
    /// [`RowCtx::back_s`]: crate::slab::march::RowCtx::back_s
    /// [`RowCtx::back_st`]: crate::slab::march::RowCtx::back_st
    pub(super) back_s: [std::arch::x86_64::__m256; 3],
    pub(super) back_st: [std::arch::x86_64::__m256; 3],
    /// Classify the segment from `u` to `rho` ([`shade_segment8`]) and light it at ¼ and ¾ of
    /// the way back ([`SEGMENT_SECOND_LIGHT`]).
    pub(super) preint: bool,
}

impl<T: Scalar> ShadeSource<'_, T> {
    /// The mask of lanes in the grid's first cell (0 on every axis), whose central rows would
    /// start before the data, or near its last one (`x ≥ n − 4`, `y, z ≥ n − 3`), where a read
    /// of the last rows would end after it (an 8-bit pair is read as a 4-byte word: two bytes
    /// past the pair; clamping that read would move the pair it needs).
    #[inline]
    #[target_feature(enable = "avx2")]
    fn end_cells(&self, cells: &Cells8) -> std::arch::x86_64::__m256 {
        use std::arch::x86_64::*;
        let zero = _mm256_setzero_si256();
        let (mut first, mut last) = (_mm256_set1_epi32(-1), _mm256_set1_epi32(-1));
        for ax in 0..3 {
            let c = cells.cell[ax];
            first = _mm256_and_si256(first, _mm256_cmpeq_epi32(c, zero));
            last = _mm256_and_si256(last, _mm256_cmpgt_epi32(c, self.near_end[ax]));
        }
        _mm256_castsi256_ps(_mm256_or_si256(first, last))
    }

    /// Per axis, the masks of lanes on the lower face (cell 0) and on the upper face (cell
    /// `n − 2`).
    #[inline]
    #[target_feature(enable = "avx2")]
    fn faces(
        cells: &[std::arch::x86_64::__m256i; 3],
        top: &[std::arch::x86_64::__m256i; 3],
    ) -> [[std::arch::x86_64::__m256; 3]; 2] {
        use std::arch::x86_64::*;
        let zero = _mm256_setzero_si256();
        [
            std::array::from_fn(|a| _mm256_castsi256_ps(_mm256_cmpeq_epi32(cells[a], zero))),
            std::array::from_fn(|a| _mm256_castsi256_ps(_mm256_cmpeq_epi32(cells[a], top[a]))),
        ]
    }

    /// The mask of lanes whose cell is interior (between 1 and `n − 3` on every axis).
    #[inline]
    #[target_feature(enable = "avx2")]
    fn interior(&self, cells: &Cells8) -> std::arch::x86_64::__m256 {
        use std::arch::x86_64::*;
        let zero = _mm256_setzero_si256();
        let mut m = _mm256_set1_epi32(-1);
        for ax in 0..3 {
            let c = cells.cell[ax];
            let inside = _mm256_andnot_si256(
                _mm256_cmpgt_epi32(c, self.inner_max[ax]),
                _mm256_cmpgt_epi32(c, zero),
            );
            m = _mm256_and_si256(m, inside);
        }
        _mm256_castsi256_ps(m)
    }

    /// [`light_fractions`] on eight lanes: `frac + ¼·s` and `frac + second·s`, with
    /// `s = back_s + xf·back_st`.
    ///
    /// [`light_fractions`]: crate::slab::march::light_fractions
    #[inline]
    #[target_feature(enable = "avx2")]
    fn light_fractions(
        &self,
        frac: [std::arch::x86_64::__m256; 3],
        xf: std::arch::x86_64::__m256,
        second: std::arch::x86_64::__m256,
    ) -> [[std::arch::x86_64::__m256; 3]; 2] {
        use std::arch::x86_64::*;
        let first = _mm256_set1_ps(LIGHT_SHIFT);
        let step: [__m256; 3] = std::array::from_fn(|a| {
            _mm256_add_ps(self.back_s[a], _mm256_mul_ps(xf, self.back_st[a]))
        });
        [
            std::array::from_fn(|a| _mm256_add_ps(frac[a], _mm256_mul_ps(step[a], first))),
            std::array::from_fn(|a| _mm256_add_ps(frac[a], _mm256_mul_ps(step[a], second))),
        ]
    }
}

impl<T: Scalar> Source8<T> for ShadeSource<'_, T> {
    /// The rows' first voxels (`base` with lanes that are not interior moved to cell
    /// (1, 1, 1)), `c[j][k]`: voxels x − 1 … x + 2 of row (y + j, z + k), and the pixel
    /// columns.
    type Pre = (
        std::arch::x86_64::__m256i,
        [[[std::arch::x86_64::__m256; 4]; 2]; 2],
        std::arch::x86_64::__m256,
        Option<[std::arch::x86_64::__m256i; 3]>,
    );

    #[inline]
    #[target_feature(enable = "avx2")]
    unsafe fn scalar_lanes(
        &self,
        cells: &Cells8,
        live: std::arch::x86_64::__m256,
    ) -> std::arch::x86_64::__m256 {
        use std::arch::x86_64::*;
        _mm256_and_ps(self.end_cells(cells), live)
    }

    /// The sample from the four central rows (the cell's corners are their voxels x and
    /// x + 1), which the differences read again.
    #[inline]
    #[target_feature(enable = "avx2")]
    unsafe fn sample(
        &self,
        cells: &Cells8,
        base: std::arch::x86_64::__m256i,
        frac: [std::arch::x86_64::__m256; 3],
    ) -> Option<(std::arch::x86_64::__m256, Self::Pre)> {
        use std::arch::x86_64::*;
        let any_face = _mm256_movemask_ps(self.interior(cells)) != 0xff;
        let base = if any_face {
            _mm256_blendv_epi8(
                base,
                self.safe_base,
                _mm256_castps_si256(self.end_cells(cells)),
            )
        } else {
            base
        };
        let s = self.sampler;
        let first = _mm256_sub_epi32(base, _mm256_set1_epi32(1));
        let (y1, z1) = (_mm256_add_epi32(first, s.sy), _mm256_add_epi32(first, s.sz));
        // SAFETY: voxels x − 1 … x + 2 of rows y, y + 1 and z, z + 1 lie in the data for every
        // cell but the grid's first and last, which (with the `end_cells` near the last) read
        // cell (1, 1, 1) instead (x − 1 and x + 2 may belong to the rows before and after on
        // the faces: dropped there).
        let c = unsafe {
            [
                [s.gather4(first), s.gather4(z1)],
                [s.gather4(y1), s.gather4(_mm256_add_epi32(y1, s.sz))],
            ]
        };
        // Sampler8::sample_at's interpolation of the corners (voxels x and x + 1 of each row).
        let c00 = lerp8(c[0][0][1], c[0][0][2], frac[0]);
        let c10 = lerp8(c[1][0][1], c[1][0][2], frac[0]);
        let c01 = lerp8(c[0][1][1], c[0][1][2], frac[0]);
        let c11 = lerp8(c[1][1][1], c[1][1][2], frac[0]);
        let rho = lerp8(lerp8(c00, c10, frac[1]), lerp8(c01, c11, frac[1]), frac[2]);
        let faces = any_face.then_some(cells.cell);
        Some((rho, (base, c, cells.xf, faces)))
    }

    #[inline]
    #[target_feature(enable = "avx2")]
    unsafe fn src(
        &self,
        pre: &Self::Pre,
        frac: [std::arch::x86_64::__m256; 3],
        u: std::arch::x86_64::__m256,
        rho: std::arch::x86_64::__m256,
        k: std::arch::x86_64::__m256,
        corrected: std::arch::x86_64::__m256,
    ) -> ([std::arch::x86_64::__m256; 4], std::arch::x86_64::__m256) {
        use std::arch::x86_64::*;
        // SAFETY (both): the caller guarantees AVX2; positions are clamped to [0, last], and
        // row last + 1 exists.
        let (v, second) = if self.preint {
            // Lanes whose segment is more than one value are lit at ¼ and ¾ of it.
            let along = _mm256_cmp_ps::<_CMP_NEQ_UQ>(u, rho);
            let second = _mm256_blendv_ps(
                _mm256_set1_ps(-LIGHT_SHIFT),
                _mm256_set1_ps(SEGMENT_SECOND_LIGHT),
                along,
            );
            (unsafe { shade_segment8(self.t, u, rho) }, second)
        } else {
            let pos = table_pos8(rho, self.t.axis);
            (
                unsafe { interp8(&self.t.rows, pos, false) },
                _mm256_set1_ps(-LIGHT_SHIFT),
            )
        };
        let (v, a, contributes) = shade_terms8(v, k, corrected);
        if _mm256_movemask_ps(contributes) == 0 {
            return ([_mm256_setzero_ps(); 4], contributes);
        }
        let (base, c, xf, faces) = pre;
        let s = self.sampler;
        let (sy, sz) = (s.sy, s.sz);
        let (ny, nz) = (_mm256_sub_epi32(*base, sy), _mm256_sub_epi32(*base, sz));
        let (y2, z2) = (
            _mm256_add_epi32(*base, _mm256_add_epi32(sy, sy)),
            _mm256_add_epi32(*base, _mm256_add_epi32(sz, sz)),
        );
        // The neighbour rows' first voxels: beyond a face they may fall outside the data, so
        // where the group has face lanes they are clamped into it (interior lanes' rows lie
        // well inside: the clamp leaves them).
        let row = |i: __m256i| match faces {
            Some(_) => _mm256_min_epi32(_mm256_max_epi32(i, _mm256_setzero_si256()), self.clamp_hi),
            None => i,
        };
        // SAFETY: as in `sample`; a 4-byte read starting in these rows ends in the data (for
        // interior lanes the last row read is (y + 2, z + 1) or (y + 1, z + 2), never the grid's
        // last row; face lanes' starts are clamped to `clamp_hi`).
        let (yo, zo) = unsafe {
            (
                // yo[0][k]: row (y − 1, z + k); yo[1][k]: row (y + 2, z + k); voxels x, x + 1.
                [
                    [s.gather2(row(ny)), s.gather2(row(_mm256_add_epi32(ny, sz)))],
                    [s.gather2(row(y2)), s.gather2(row(_mm256_add_epi32(y2, sz)))],
                ],
                // zo[j][0]: row (y + j, z − 1); zo[j][1]: row (y + j, z + 2).
                [
                    [s.gather2(row(nz)), s.gather2(row(z2))],
                    [
                        s.gather2(row(_mm256_add_epi32(nz, sy))),
                        s.gather2(row(_mm256_add_epi32(z2, sy))),
                    ],
                ],
            )
        };
        let half = _mm256_set1_ps(0.5);
        // The differences along each axis at corner (dx, dy, dz), as `Ctx::gradient_lerp`.
        let mut d = [[[[_mm256_setzero_ps(); 2]; 2]; 2]; 3];
        for dy in 0..2 {
            for dz in 0..2 {
                for dx in 0..2 {
                    let r = &c[dy][dz];
                    let (hi_y, lo_y) = if dy == 0 {
                        (c[1][dz][dx + 1], yo[0][dz][dx])
                    } else {
                        (yo[1][dz][dx], c[0][dz][dx + 1])
                    };
                    let (hi_z, lo_z) = if dz == 0 {
                        (c[dy][1][dx + 1], zo[dy][0][dx])
                    } else {
                        (zo[dy][1][dx], c[dy][0][dx + 1])
                    };
                    d[0][dz][dy][dx] = _mm256_mul_ps(_mm256_sub_ps(r[dx + 2], r[dx]), half);
                    d[1][dz][dy][dx] = _mm256_mul_ps(_mm256_sub_ps(hi_y, lo_y), half);
                    d[2][dz][dy][dx] = _mm256_mul_ps(_mm256_sub_ps(hi_z, lo_z), half);
                }
            }
        }
        if let Some(cell) = faces {
            // On a face the twin's difference at the corner on it is one-sided, `ρ(p + e) − ρ(p)`
            // forward on the lower face and `ρ(p) − ρ(p − e)` backward on the upper, times 1:
            // between the cell's own two corners along the axis, for either corner.
            let [lo, hi] = Self::faces(cell, &self.top);
            for dy in 0..2 {
                for dz in 0..2 {
                    for dx in 0..2 {
                        let r = &c[dy][dz];
                        let one = [
                            _mm256_sub_ps(r[2], r[1]),
                            _mm256_sub_ps(c[1][dz][dx + 1], c[0][dz][dx + 1]),
                            _mm256_sub_ps(c[dy][1][dx + 1], c[dy][0][dx + 1]),
                        ];
                        let at = [dx, dy, dz];
                        for ax in 0..3 {
                            let on = if at[ax] == 0 { lo[ax] } else { hi[ax] };
                            let e = &mut d[ax][dz][dy][dx];
                            *e = _mm256_blendv_ps(*e, one[ax], on);
                        }
                    }
                }
            }
        }
        // The gradient at each light's fractions (`Ctx::gradient_lerp`), lit, clamped and
        // averaged (`shaded_src_two`).
        let gradient = |f: [__m256; 3]| -> [__m256; 3] {
            std::array::from_fn(|ax| {
                let e = &d[ax];
                let c00 = lerp8(e[0][0][0], e[0][0][1], f[0]);
                let c10 = lerp8(e[0][1][0], e[0][1][1], f[0]);
                let c01 = lerp8(e[1][0][0], e[1][0][1], f[0]);
                let c11 = lerp8(e[1][1][0], e[1][1][1], f[0]);
                lerp8(lerp8(c00, c10, f[1]), lerp8(c01, c11, f[1]), f[2])
            })
        };
        let [fa, fb] = self.light_fractions(frac, *xf, second);
        let c0 = clamp01_8(lit_colour8(self.t, &v, contributes, gradient(fa)));
        let c1 = clamp01_8(lit_colour8(self.t, &v, contributes, gradient(fb)));
        let avg = std::array::from_fn(|ch| _mm256_mul_ps(_mm256_add_ps(c0[ch], c1[ch]), half));
        (premultiplied8(avg, a), contributes)
    }
}

/// Shaded composite at the voxels ([`ShadeAt::Voxels`]) for [`composite_groups_avx2`]: the
/// sample as [`Sampler8::sample_at`], the classifier's terms from [`ShadeTable`]
/// ([`shade_terms8`]), the eight corners' direction codes (four 32-bit gathers, two codes
/// each along x), their diffuse and specular light gathered from [`VoxelShading`] and
/// interpolated; lane by lane the f32 operations of [`voxel_shaded_src`]. Every cell can be
/// read (the codes hold the faces' one-sided differences), so no lane needs the scalar twin.
///
/// [`ShadeAt::Voxels`]: crate::normals::ShadeAt::Voxels
/// [`composite_groups_avx2`]: super::composite::composite_groups_avx2
/// [`voxel_shaded_src`]: crate::slab::shade::voxel_shaded_src
pub(in crate::slab) struct VoxelShadeSource<'a, T> {
    pub(super) t: &'a ShadeTable,
    pub(super) vs: &'a VoxelShading,
    pub(super) sampler: &'a Sampler8<T>,
    /// The codes ([`NormalField::codes`], padded by one code so that a 4-byte read at the
    /// last voxel stays inside).
    ///
    /// [`NormalField::codes`]: crate::normals::NormalField::codes
    pub(super) codes: *const i32,
    /// Bits from a corner's code to the next one's along x in a 32-bit word: `16·ux`.
    pub(super) x_shift: std::arch::x86_64::__m128i,
    /// Classify the segment from `u` to `rho` ([`shade_segment8`]) and light it at its middle
    /// ([`VoxelShadeSource::light_cells`]).
    pub(super) preint: bool,
    /// [`RowCtx::back_s`], [`RowCtx::back_st`] broadcast.
    ///
    /// [`RowCtx::back_s`]: crate::slab::march::RowCtx::back_s
    /// [`RowCtx::back_st`]: crate::slab::march::RowCtx::back_st
    pub(super) back_s: [std::arch::x86_64::__m256; 3],
    pub(super) back_st: [std::arch::x86_64::__m256; 3],
}

impl<T: Scalar> VoxelShadeSource<'_, T> {
    /// [`Ctx::light_cell`] on eight lanes: the linear indices and fractions of the cells
    /// where the segments are lit, `h` of the way back from the samples at `pos`.
    ///
    /// # Safety
    /// The CPU must support AVX2.
    ///
    /// [`Ctx::light_cell`]: crate::slab::march::Ctx::light_cell
    #[inline]
    #[target_feature(enable = "avx2")]
    pub(in crate::slab) unsafe fn light_cells(
        &self,
        pos: &[std::arch::x86_64::__m256; 3],
        xf: std::arch::x86_64::__m256,
        h: std::arch::x86_64::__m256,
    ) -> (std::arch::x86_64::__m256i, [std::arch::x86_64::__m256; 3]) {
        use std::arch::x86_64::*;
        let (zero, one) = (_mm256_setzero_ps(), _mm256_set1_ps(1.0));
        let izero = _mm256_setzero_si256();
        let mut cell = [izero; 3];
        let mut frac = [zero; 3];
        for a in 0..3 {
            let step = _mm256_add_ps(self.back_s[a], _mm256_mul_ps(xf, self.back_st[a]));
            let q = _mm256_add_ps(pos[a], _mm256_mul_ps(h, step));
            cell[a] = _mm256_min_epi32(
                _mm256_max_epi32(_mm256_cvttps_epi32(q), izero),
                self.sampler.maxc[a],
            );
            let d = _mm256_sub_ps(q, _mm256_cvtepi32_ps(cell[a]));
            frac[a] = _mm256_min_ps(_mm256_max_ps(d, zero), one);
        }
        // SAFETY: the caller guarantees AVX2.
        let base = unsafe {
            self.sampler.base_of(&Cells8 {
                cell,
                pos: *pos,
                xf,
            })
        };
        (base, frac)
    }

    /// The diffuse and specular light of plane `p` at the corners' codes `q` (`x` fastest),
    /// interpolated and scaled ([`voxel_shaded_src`]'s operations).
    ///
    /// # Safety
    /// The CPU must support AVX2; every code must be below [`crate::normals::CODES`].
    ///
    /// [`voxel_shaded_src`]: crate::slab::shade::voxel_shaded_src
    #[inline]
    #[target_feature(enable = "avx2")]
    unsafe fn light8(
        &self,
        p: usize,
        q: &[std::arch::x86_64::__m256i; 8],
        frac: [std::arch::x86_64::__m256; 3],
    ) -> [std::arch::x86_64::__m256; 2] {
        use std::arch::x86_64::*;
        let plane = self.vs.plane(p).as_ptr() as *const i32;
        let mask = _mm256_set1_epi32(0xffff);
        // SAFETY: codes are u16, and a plane holds CODES = 2^16 words.
        let w: [__m256i; 8] =
            std::array::from_fn(|k| unsafe { _mm256_i32gather_epi32::<4>(plane, q[k]) });
        let tri = |c: [__m256; 8]| {
            let c00 = lerp8(c[0], c[1], frac[0]);
            let c10 = lerp8(c[2], c[3], frac[0]);
            let c01 = lerp8(c[4], c[5], frac[0]);
            let c11 = lerp8(c[6], c[7], frac[0]);
            lerp8(lerp8(c00, c10, frac[1]), lerp8(c01, c11, frac[1]), frac[2])
        };
        let d = tri(w.map(|w| _mm256_cvtepi32_ps(_mm256_and_si256(w, mask))));
        let s = tri(w.map(|w| _mm256_cvtepi32_ps(_mm256_srli_epi32::<16>(w))));
        let [sd, ss] = self.vs.scale[p];
        [
            _mm256_mul_ps(d, _mm256_set1_ps(sd)),
            _mm256_mul_ps(s, _mm256_set1_ps(ss)),
        ]
    }
}

impl<T: Scalar> Source8<T> for VoxelShadeSource<'_, T> {
    /// The cells' linear indices, the samples' positions and the pixel columns.
    type Pre = (
        std::arch::x86_64::__m256i,
        [std::arch::x86_64::__m256; 3],
        std::arch::x86_64::__m256,
    );

    #[inline]
    #[target_feature(enable = "avx2")]
    unsafe fn sample(
        &self,
        cells: &Cells8,
        base: std::arch::x86_64::__m256i,
        frac: [std::arch::x86_64::__m256; 3],
    ) -> Option<(std::arch::x86_64::__m256, Self::Pre)> {
        // SAFETY: the caller's guarantees are sample_at's.
        unsafe { self.sampler.sample_at(base, frac) }.map(|rho| (rho, (base, cells.pos, cells.xf)))
    }

    #[inline]
    #[target_feature(enable = "avx2")]
    unsafe fn src(
        &self,
        pre: &Self::Pre,
        frac: [std::arch::x86_64::__m256; 3],
        u: std::arch::x86_64::__m256,
        rho: std::arch::x86_64::__m256,
        k: std::arch::x86_64::__m256,
        corrected: std::arch::x86_64::__m256,
    ) -> ([std::arch::x86_64::__m256; 4], std::arch::x86_64::__m256) {
        use std::arch::x86_64::*;
        // SAFETY (both): the caller guarantees AVX2; positions are clamped to [0, last], and
        // row last + 1 exists.
        let v = if self.preint {
            unsafe { shade_segment8(self.t, u, rho) }
        } else {
            let pos = table_pos8(rho, self.t.axis);
            unsafe { interp8(&self.t.rows, pos, false) }
        };
        let (v, a, contributes) = shade_terms8(v, k, corrected);
        if _mm256_movemask_ps(contributes) == 0 {
            return ([_mm256_setzero_ps(); 4], contributes);
        }
        let mut col = [v[1], v[2], v[3]];
        let (diffuse, specular, _) = self.t.switches();
        if diffuse || specular {
            let (base, frac) = if self.preint {
                // Lanes that contribute and whose segment is not one value (`SEGMENT_LIGHT_AT`).
                let mid = _mm256_and_ps(_mm256_cmp_ps::<_CMP_NEQ_UQ>(u, rho), contributes);
                let h = _mm256_and_ps(_mm256_set1_ps(SEGMENT_LIGHT_AT), mid);
                // SAFETY: the caller guarantees AVX2.
                unsafe { self.light_cells(&pre.1, pre.2, h) }
            } else {
                (pre.0, frac)
            };
            let base = &base;
            let o = self.sampler.offs;
            let mask = _mm256_set1_epi32(0xffff);
            let mut q = [_mm256_setzero_si256(); 8];
            for pair in 0..4 {
                let idx = _mm256_add_epi32(*base, _mm256_set1_epi32(o[2 * pair]));
                // SAFETY: `idx` is a voxel of the volume (cells are clamped to the grid), and
                // the codes hold one more u16 than the volume has voxels.
                let w = unsafe { _mm256_i32gather_epi32::<2>(self.codes, idx) };
                q[2 * pair] = _mm256_and_si256(w, mask);
                q[2 * pair + 1] = _mm256_and_si256(_mm256_srl_epi32(w, self.x_shift), mask);
            }
            // SAFETY (light8): codes are u16.
            let l = if self.vs.chromatic {
                [0, 1, 2].map(|p| unsafe { self.light8(p, &q, frac) })
            } else {
                [unsafe { self.light8(0, &q, frac) }; 3]
            };
            if diffuse {
                for ch in 0..3 {
                    col[ch] = _mm256_add_ps(col[ch], _mm256_mul_ps(v[4 + ch], l[ch][0]));
                }
            }
            if specular {
                for ch in 0..3 {
                    let sc = match self.t.spec_color {
                        Some(c) => _mm256_set1_ps(c[ch]),
                        None => v[4 + ch],
                    };
                    col[ch] = _mm256_add_ps(col[ch], _mm256_mul_ps(sc, l[ch][1]));
                }
            }
        }
        (premultiplied8(col, a), contributes)
    }
}

/// [`ShadeTable::segment_entry`] on eight lanes ([`segment_average8`]).
///
/// # Safety
/// The CPU must support AVX2.
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn shade_segment8(
    t: &ShadeTable,
    u: std::arch::x86_64::__m256,
    v: std::arch::x86_64::__m256,
) -> [std::arch::x86_64::__m256; 8] {
    // SAFETY: both tables repeat their last row, so row last + 1 exists.
    unsafe { segment_average8::<8, 0, 7>(t.axis, u, v, &t.rows, &t.integ, false) }
}

/// The first half of [`shaded_src`] on eight lanes, from the table's entries `v` (at the
/// samples, or of the segments, [`shade_segment8`]): the opacity (path-corrected in the
/// `corrected` lanes) and the mask of lanes that contribute.
///
/// [`shaded_src`]: crate::slab::shade::shaded_src
#[inline]
#[target_feature(enable = "avx2")]
pub(in crate::slab) fn shade_terms8(
    v: [std::arch::x86_64::__m256; 8],
    k: std::arch::x86_64::__m256,
    corrected: std::arch::x86_64::__m256,
) -> (
    [std::arch::x86_64::__m256; 8],
    std::arch::x86_64::__m256,
    std::arch::x86_64::__m256,
) {
    use std::arch::x86_64::*;
    let zero = _mm256_setzero_ps();
    let one = _mm256_set1_ps(1.0);
    let corrected_bits = _mm256_movemask_ps(corrected);
    let mut a = v[0];
    let mut contributes = _mm256_cmp_ps::<_CMP_GT_OQ>(v[0], zero);
    if corrected_bits != 0 {
        let ac = _mm256_sub_ps(one, exp2_neg8(_mm256_mul_ps(k, v[7])));
        a = _mm256_blendv_ps(a, ac, corrected);
        let ok = _mm256_cmp_ps::<_CMP_LT_OQ>(v[7], zero);
        contributes = _mm256_blendv_ps(contributes, ok, corrected);
    }
    (v, a, contributes)
}

/// `lit_colour` (`slab/shade.rs`) on eight lanes (the conditions as masks): the colours,
/// before they are clamped, of the samples with the entries `v` of [`shade_terms8`] lit at the
/// interpolated index-space gradients `g` in the lanes that contribute, the specular power by
/// [`spec_at_sample8`].
#[inline]
#[target_feature(enable = "avx2")]
pub(in crate::slab) fn lit_colour8(
    t: &ShadeTable,
    v: &[std::arch::x86_64::__m256; 8],
    contributes: std::arch::x86_64::__m256,
    g: [std::arch::x86_64::__m256; 3],
) -> [std::arch::x86_64::__m256; 3] {
    use std::arch::x86_64::*;
    let zero = _mm256_setzero_ps();
    let one = _mm256_set1_ps(1.0);
    let [m0, m1, m2] = t.to_world;
    let (m0, m1, m2) = (splat3(m0), splat3(m1), splat3(m2));
    // World gradient, component i: (m0ᵢ·g₀ + m1ᵢ·g₁) + m2ᵢ·g₂.
    let gw = [
        dot8([m0[0], m1[0], m2[0]], g),
        dot8([m0[1], m1[1], m2[1]], g),
        dot8([m0[2], m1[2], m2[2]], g),
    ];
    let g2 = dot8(gw, gw);
    let mut col = [v[1], v[2], v[3]];
    let lit = _mm256_and_ps(_mm256_cmp_ps::<_CMP_GT_OQ>(g2, zero), contributes);
    if (t.diffuse || t.specular) && _mm256_movemask_ps(lit) != 0 {
        let inv = _mm256_div_ps(one, _mm256_sqrt_ps(g2));
        let n = [
            _mm256_mul_ps(gw[0], inv),
            _mm256_mul_ps(gw[1], inv),
            _mm256_mul_ps(gw[2], inv),
        ];
        let sign = _mm256_set1_ps(-0.0);
        for light in &t.lights {
            let lc = splat3(light.color.to_array());
            let mut ndl = dot8(n, splat3(light.l.to_array()));
            let mut ndh = dot8(n, splat3(light.h.to_array()));
            if t.two_sided {
                let flip = _mm256_cmp_ps::<_CMP_LT_OQ>(ndl, zero);
                ndl = _mm256_blendv_ps(ndl, _mm256_xor_ps(ndl, sign), flip);
                ndh = _mm256_blendv_ps(ndh, _mm256_xor_ps(ndh, sign), flip);
            }
            let dm = _mm256_and_ps(lit, _mm256_cmp_ps::<_CMP_GT_OQ>(ndl, zero));
            if _mm256_movemask_ps(dm) == 0 {
                continue;
            }
            if t.diffuse {
                for ch in 0..3 {
                    let term = _mm256_mul_ps(_mm256_mul_ps(v[4 + ch], lc[ch]), ndl);
                    col[ch] = _mm256_add_ps(col[ch], _mm256_and_ps(term, dm));
                }
            }
            let sm = _mm256_and_ps(dm, _mm256_cmp_ps::<_CMP_GT_OQ>(ndh, zero));
            if t.specular && _mm256_movemask_ps(sm) != 0 {
                let p = spec_at_sample8(t, ndh);
                for ch in 0..3 {
                    let sc = match t.spec_color {
                        Some(c) => _mm256_set1_ps(c[ch]),
                        None => v[4 + ch],
                    };
                    let term = _mm256_mul_ps(_mm256_mul_ps(sc, lc[ch]), p);
                    col[ch] = _mm256_add_ps(col[ch], _mm256_and_ps(term, sm));
                }
            }
        }
    }
    col
}

/// [`ShadeTable::spec_at_sample`] on eight lanes: [`pow_int8`] where the power is whole, else
/// the table, lane by lane (lanes the caller masks out clamp to a valid entry).
#[inline]
#[target_feature(enable = "avx2")]
fn spec_at_sample8(t: &ShadeTable, x: std::arch::x86_64::__m256) -> std::arch::x86_64::__m256 {
    use std::arch::x86_64::*;
    if let Some(n) = t.spec_int {
        return pow_int8(x, n);
    }
    let zero = _mm256_setzero_ps();
    let spec_max = _mm256_set1_ps(ShadeTable::SPEC as f32);
    let s = _mm256_min_ps(_mm256_max_ps(_mm256_mul_ps(x, spec_max), zero), spec_max);
    let i = _mm256_cvttps_epi32(s);
    let f = _mm256_sub_ps(s, _mm256_cvtepi32_ps(i));
    let tab = t.spec_pow.as_ptr();
    // SAFETY: i ∈ [0, SPEC], and spec_pow has SPEC + 2 entries.
    let (p0, p1) = unsafe {
        (
            _mm256_i32gather_ps::<4>(tab, i),
            _mm256_i32gather_ps::<4>(tab.add(1), i),
        )
    };
    _mm256_add_ps(p0, _mm256_mul_ps(f, _mm256_sub_ps(p1, p0)))
}

/// [`pow_int`] on eight lanes: `x^n` (`n ≥ 1`) by repeated squaring, the same multiplications
/// in the same order.
///
/// [`pow_int`]: crate::slab::tables::pow_int
#[inline]
#[target_feature(enable = "avx2")]
fn pow_int8(x: std::arch::x86_64::__m256, n: u32) -> std::arch::x86_64::__m256 {
    use std::arch::x86_64::*;
    let (mut base, mut n) = (x, n);
    let mut acc: Option<__m256> = None;
    loop {
        if n & 1 == 1 {
            acc = Some(acc.map_or(base, |a| _mm256_mul_ps(a, base)));
        }
        n >>= 1;
        if n == 0 {
            return acc.unwrap_or(_mm256_set1_ps(1.0));
        }
        base = _mm256_mul_ps(base, base);
    }
}

/// The shaded colour `col` clamped to [0, 1] and multiplied by the opacity `a`, on eight lanes
/// ([`premultiplied`]'s operations).
///
/// [`premultiplied`]: crate::slab::shade::premultiplied
#[inline]
#[target_feature(enable = "avx2")]
fn premultiplied8(
    col: [std::arch::x86_64::__m256; 3],
    a: std::arch::x86_64::__m256,
) -> [std::arch::x86_64::__m256; 4] {
    use std::arch::x86_64::*;
    let c = clamp01_8(col).map(|c| _mm256_mul_ps(c, a));
    [c[0], c[1], c[2], a]
}

/// `col` clamped to [0, 1] (NaN to 0): the twin of `clamp01` (`slab/shade.rs`).
#[inline]
#[target_feature(enable = "avx2")]
fn clamp01_8(col: [std::arch::x86_64::__m256; 3]) -> [std::arch::x86_64::__m256; 3] {
    use std::arch::x86_64::*;
    let (zero, one) = (_mm256_setzero_ps(), _mm256_set1_ps(1.0));
    col.map(|c| _mm256_min_ps(_mm256_max_ps(c, zero), one))
}
