//! NIL control points by projection (decision 0007) and the line quadrature of the display
//! filters that feeds it.
//!
//! The thesis takes a patch's control points `b` as the filter's values at the Lagrange nodes of
//! the cell (App. B "find_the_weight_of_the_control_points", eq 4.3). A Chapter 6 filter is a
//! tube about half a pixel wide (a screen Gaussian, σ = ½ px) while the cells the trigger
//! hierarchy produces are several voxels across: most nodes miss the tube, the interpolated patch
//! is nearly zero or negative, and the normalisation of eq 4.16 collapses (thesis Plate 5.9,
//! Table 5.11; our first version fell back on 12–20 % of the pixels).
//!
//! Here `b` is instead the **L² projection** of the filter onto the cell's patch space:
//! `b = (G⊗G⊗G)⁻¹ m` with `G_ij = ∫₀¹ B_i B_j` (the 1-D Gram matrix of the Lagrange basis) and
//! `m_ijk = ∫_cell F·B_ijk` (in the cell's unit coordinates). Because the constants lie in the
//! patch space, `Σ b·B̄ = ∫_cell F` exactly, so the denominator of eq 4.15 never collapses for a
//! non-negative filter, and the NIL value `Σ_cells Σ b·C = ∫ (P F)·T` is the integral of the
//! best patch approximation of the filter against the data. Its error is
//! `⟨F − P F, T − P T⟩`, a product of two approximation errors, so it falls with patch order and
//! with cell size (the trigger count and the tolerance).
//!
//! The moments `m` are integrated along the filter's own lines: every display filter is
//! `F dV = w_ab · profile(t) dt` over straight lines `p_ab(t)` (the screen Gaussian's
//! cross-section nodes `(a, b)` over `[−3, 3]²`, composite Gauss–Legendre, times the profile
//! along the ray: `exp(−τ(t − t_a))` for eq 6.1, a Gaussian for slices and balls). Each line is
//! clipped to the box of voxel centres (the density is zero outside it, eq 4.2) and to each
//! cell, and integrated there with Gauss–Legendre of `M + 1` nodes per panel (exact for the
//! basis product, degree `3(M − 1)`), panels no longer than the profile's length scale.

use super::filter::{PixelFilter, TRUNC, composite_nodes};
use super::volume::DisplayVolume;
use crate::nil::basis::MAX_ORDER;
use crate::nil::{Cell, NilSource, PatchBasis};
use crate::quadrature::gauss_legendre;
use glam::DVec3;

/// Profile of a filter along its lines (world parameter `t`).
#[derive(Debug, Clone, Copy)]
pub(crate) enum Profile {
    /// `exp(−τ(t − t_a))` for `t ≥ t_a` (eq 6.1).
    Exp { ta: f64, tau: f64 },
    /// `exp(−½((t − t_c)/w)²)` for `|t − t_c| ≤ 3w` (slices, balls).
    Gauss { tc: f64, w: f64 },
    /// `1` for `t ≥ t_0` (the line integral of Sabella's optical depth).
    Uniform { t0: f64 },
}

impl Profile {
    #[inline]
    fn at(&self, t: f64) -> f64 {
        match *self {
            Profile::Exp { ta, tau } => {
                if t < ta {
                    0.0
                } else {
                    (-tau * (t - ta)).exp()
                }
            }
            Profile::Gauss { tc, w } => {
                let u = (t - tc) / w;
                if u.abs() > TRUNC {
                    0.0
                } else {
                    (-0.5 * u * u).exp()
                }
            }
            Profile::Uniform { t0 } => {
                if t < t0 {
                    0.0
                } else {
                    1.0
                }
            }
        }
    }

    fn support(&self) -> (f64, f64) {
        match *self {
            Profile::Exp { ta, .. } => (ta, f64::INFINITY),
            Profile::Gauss { tc, w } => (tc - TRUNC * w, tc + TRUNC * w),
            Profile::Uniform { t0 } => (t0, f64::INFINITY),
        }
    }

    /// Length over which the profile changes by about `e`: the longest quadrature panel.
    fn scale(&self) -> f64 {
        match *self {
            Profile::Exp { tau, .. } => 1.0 / tau,
            Profile::Gauss { w, .. } => w,
            Profile::Uniform { .. } => f64::INFINITY,
        }
    }

    /// `∫` over the whole support (exact for the exponential; composite Gauss–Legendre with 24
    /// panels of 5 nodes, relative error below 1e-12, for the truncated Gaussian). The uniform
    /// profile has no finite integral: its normaliser is 1 per unit length, so that
    /// `∭Fρ / K` is the screen-filtered line integral.
    fn total(&self) -> f64 {
        match *self {
            Profile::Exp { tau, .. } => 1.0 / tau,
            Profile::Uniform { .. } => 1.0,
            Profile::Gauss { tc, w } => composite_nodes(tc - TRUNC * w, tc + TRUNC * w, 24, 5)
                .iter()
                .map(|&(t, wt)| wt * self.at(t))
                .sum(),
        }
    }
}

/// One straight line of a filter in index space: `q(t) = q0 + t·dq`, weight `w` (world
/// cross-section measure), clipped to `[t0, t1]` (box of voxel centres ∩ profile support).
#[derive(Debug, Clone, Copy)]
struct Line {
    q0: DVec3,
    dq: DVec3,
    w: f64,
    t0: f64,
    t1: f64,
    /// Bounding box of the clipped segment (index space), widened by [`AABB_PAD`]: a cell
    /// outside it cannot meet the line, which saves the clip.
    lo: DVec3,
    hi: DVec3,
}

/// Widening of a line's bounding box, index units: only cells clearly apart from the segment
/// are skipped, so the skip never changes a result.
const AABB_PAD: f64 = 1e-6;

impl Line {
    /// Whether the segment's bounding box misses the box `[base, top]`.
    #[inline]
    fn misses(&self, base: DVec3, top: DVec3) -> bool {
        self.hi.x < base.x
            || self.hi.y < base.y
            || self.hi.z < base.z
            || self.lo.x > top.x
            || self.lo.y > top.y
            || self.lo.z > top.z
    }
}

/// A display filter as weighted lines (module docs).
#[derive(Debug, Clone, Default)]
pub(crate) struct LineFilter {
    lines: Vec<Line>,
    profile: Option<Profile>,
    /// `∭ F` of the whole filter, world volume (not masked by the box); for the line integral
    /// (uniform profile) the screen filter's weight per unit length.
    pub k_full: f64,
    /// `∭ F` over the box of voxel centres (the masked filter).
    pub k_box: f64,
    /// Upper corner of the box of voxel centres, index space.
    hi: DVec3,
}

/// Clips `q0 + t·dq` to the box `[lo, hi]` and to `[t0, t1]`.
#[inline]
fn clip(q0: DVec3, dq: DVec3, lo: DVec3, hi: DVec3, mut t0: f64, mut t1: f64) -> (f64, f64) {
    for a in 0..3 {
        if dq[a].abs() < 1e-300 {
            if q0[a] < lo[a] || q0[a] > hi[a] {
                return (1.0, 0.0);
            }
            continue;
        }
        let inv = 1.0 / dq[a];
        let (ta, tb) = ((lo[a] - q0[a]) * inv, (hi[a] - q0[a]) * inv);
        t0 = t0.max(ta.min(tb));
        t1 = t1.min(ta.max(tb));
    }
    (t0, t1)
}

impl LineFilter {
    /// Rebuilds `self` as the lines of `filter` with `cross` nodes (pairs `(a, w_a)` over
    /// `[−3, 3]`) per axis of the cross-section.
    pub(super) fn set(&mut self, vol: &DisplayVolume, filter: &PixelFilter, cross: &[(f64, f64)]) {
        self.lines.clear();
        // World frame: p(t) = p0 + t·d + (a·e1 + b·e2)·(s0 + s1·t), weight w_ab·jac.
        let (p0, d, e1, e2, s0, s1, jac, profile) = match *filter {
            PixelFilter::Linearised { ray, sigma, tau } => (
                ray.o,
                ray.d,
                ray.e1,
                ray.e2,
                sigma.a,
                sigma.b,
                1.0,
                Profile::Exp { ta: ray.ta, tau },
            ),
            PixelFilter::LineIntegral { ray, sigma } => (
                ray.o,
                ray.d,
                ray.e1,
                ray.e2,
                sigma.a,
                sigma.b,
                1.0,
                Profile::Uniform { t0: ray.t_min },
            ),
            PixelFilter::Slice { ray, sigma, tc, w } => (
                ray.o,
                ray.d,
                ray.e1,
                ray.e2,
                sigma.a,
                sigma.b,
                1.0,
                Profile::Gauss { tc, w },
            ),
            PixelFilter::Ball { c, s } => (
                c,
                DVec3::Z,
                DVec3::X,
                DVec3::Y,
                s,
                0.0,
                s * s,
                Profile::Gauss { tc: 0.0, w: s },
            ),
        };
        self.profile = Some(profile);
        let lo = DVec3::ZERO;
        let hi = DVec3::from(vol.dims().map(|n| (n - 1) as f64));
        let (sup0, sup1) = profile.support();
        let total = profile.total();
        let (mut k_full, mut k_box) = (0.0, 0.0);
        for &(a, wa) in cross {
            for &(b, wb) in cross {
                let w = jac * wa * wb * (-0.5 * (a * a + b * b)).exp();
                k_full += w * total;
                let off = e1 * a + e2 * b;
                let q0 = vol.index_from_world(p0 + off * s0);
                let dq = vol.index_from_world(p0 + off * s0 + d + off * s1) - q0;
                let (t0, t1) = clip(q0, dq, lo, hi, sup0, sup1);
                if t1 > t0 {
                    k_box += w * integrate(&profile, t0, t1);
                    let (a, b) = (q0 + dq * t0, q0 + dq * t1);
                    let pad = DVec3::splat(AABB_PAD);
                    self.lines.push(Line {
                        q0,
                        dq,
                        w,
                        t0,
                        t1,
                        lo: a.min(b) - pad,
                        hi: a.max(b) + pad,
                    });
                }
            }
        }
        self.k_full = k_full;
        self.k_box = k_box;
        self.hi = hi;
    }

    /// Appends the index-space end points of every clipped line (they bound the masked
    /// filter's support, so the hierarchy root must enclose them).
    /// Clamped into the box: rounding in the clip must not make a coordinate negative (no
    /// dyadic cell holds both signs of a coordinate).
    pub(super) fn endpoints(&self, out: &mut Vec<DVec3>) {
        let hi = self.hi;
        for l in &self.lines {
            out.push((l.q0 + l.dq * l.t0).clamp(DVec3::ZERO, hi));
            out.push((l.q0 + l.dq * l.t1).clamp(DVec3::ZERO, hi));
        }
    }

    /// Whether any line of the filter crosses `cell`.
    pub(super) fn hits(&self, cell: &Cell) -> bool {
        let h = cell.size();
        let lo = DVec3::new(
            cell.index[0] as f64,
            cell.index[1] as f64,
            cell.index[2] as f64,
        ) * h;
        let hi = lo + DVec3::splat(h);
        self.lines.iter().any(|l| {
            if l.misses(lo, hi) {
                return false;
            }
            let (t0, t1) = clip(l.q0, l.dq, lo, hi, l.t0, l.t1);
            t1 > t0
        })
    }

    /// The masked filter at an index-space point (the thesis's control points, decision 0007
    /// keeps them for comparison): `filter.weight` inside the box of voxel centres, else 0.
    pub(super) fn masked(vol: &DisplayVolume, filter: &PixelFilter, p_index: DVec3) -> f64 {
        if vol.inside(p_index) {
            filter.weight_index(vol, p_index)
        } else {
            0.0
        }
    }
}

impl LineFilter {
    /// Direct evaluation (the reference): `Σ_lines w ∫_{t0}^{t1} profile(t)·ρ(q(t)) dt / K`,
    /// composite 2-point Gauss–Legendre along each clipped line with panels of at most `step`
    /// world units (and of the profile's scale). `None` if the filter misses the box.
    pub(super) fn direct(&self, vol: &DisplayVolume, step: f64) -> Option<f64> {
        let profile = self.profile?;
        if self.lines.is_empty() {
            return None;
        }
        let h = step.min(profile.scale());
        let mut num = 0.0;
        for l in &self.lines {
            let panels = ((l.t1 - l.t0) / h).ceil().clamp(1.0, 1e6) as usize;
            for (t, wt) in composite_nodes(l.t0, l.t1, panels, 2) {
                let rho = vol.density_index(l.q0 + l.dq * t);
                num += l.w * wt * profile.at(t) * rho;
            }
        }
        Some(num / self.k_full)
    }
}

/// `∫_{t0}^{t1} profile` by composite Gauss–Legendre (panels ≤ the profile's scale).
fn integrate(p: &Profile, t0: f64, t1: f64) -> f64 {
    let panels = ((t1 - t0) / p.scale()).ceil().clamp(1.0, 4096.0) as usize;
    composite_nodes(t0, t1, panels, 4)
        .iter()
        .map(|&(t, w)| w * p.at(t))
        .sum()
}

/// The projection operator of one patch basis: `G⁻¹` and the along-line rule.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Projector {
    basis: PatchBasis,
    ginv: [[f64; MAX_ORDER]; MAX_ORDER],
    /// Gauss–Legendre nodes per panel along a line (`M + 1`, exact for degree `3(M − 1)`).
    nq: usize,
}

impl Projector {
    pub(super) fn new(basis: PatchBasis) -> Self {
        let m = basis.order();
        // Gram matrix by 5-point Gauss–Legendre on [0, 1] (exact to degree 9 ≥ 2(M − 1)).
        let (x, w) = gauss_legendre(5);
        let mut g = [[0.0; 2 * MAX_ORDER]; MAX_ORDER];
        for i in 0..m {
            for j in 0..m {
                g[i][j] = x
                    .iter()
                    .zip(w)
                    .map(|(&xi, &wi)| {
                        let t = 0.5 * (xi + 1.0);
                        0.5 * wi * basis.eval(i, t) * basis.eval(j, t)
                    })
                    .sum();
            }
            g[i][m + i] = 1.0;
        }
        // Gauss–Jordan (G is symmetric positive definite: no pivoting needed).
        for c in 0..m {
            let p = g[c][c];
            for v in g[c].iter_mut() {
                *v /= p;
            }
            for r in 0..m {
                if r != c {
                    let f = g[r][c];
                    let row_c = g[c];
                    for (v, pc) in g[r].iter_mut().zip(row_c) {
                        *v -= f * pc;
                    }
                }
            }
        }
        let mut ginv = [[0.0; MAX_ORDER]; MAX_ORDER];
        for i in 0..m {
            for j in 0..m {
                ginv[i][j] = g[i][m + j];
            }
        }
        Projector {
            basis,
            ginv,
            nq: m + 1,
        }
    }

    /// Moments `m_ijk = ∫_cell F·B_ijk` (world volume; `M³`, index `(k·M + j)·M + i`) of the
    /// masked filter on `cell`. Returns false if no line meets the cell.
    pub(super) fn moments(&self, filter: &LineFilter, cell: &Cell, mom: &mut [f64; 64]) -> bool {
        match self.basis.order() {
            1 => self.moments_m::<1>(filter, cell, mom),
            2 => self.moments_m::<2>(filter, cell, mom),
            3 => self.moments_m::<3>(filter, cell, mom),
            _ => self.moments_m::<4>(filter, cell, mom),
        }
    }

    /// [`Self::moments`] for `M` known at compile time (the loops unroll).
    fn moments_m<const M: usize>(
        &self,
        filter: &LineFilter,
        cell: &Cell,
        mom: &mut [f64; 64],
    ) -> bool {
        let Some(profile) = filter.profile else {
            return false;
        };
        let h = cell.size();
        // A power of two: multiplying by the inverse is exact.
        let inv_h = 1.0 / h;
        let base = DVec3::new(
            cell.index[0] as f64,
            cell.index[1] as f64,
            cell.index[2] as f64,
        ) * h;
        let top = base + DVec3::splat(h);
        let mut acc = [[[0.0f64; M]; M]; M];
        let mut any = false;
        let (xi, wi) = gauss_legendre(self.nq);
        let scale = profile.scale();
        let coef: [[f64; MAX_ORDER]; M] = std::array::from_fn(|i| *self.basis.coefficients(i));
        let eval = |t: f64| -> [f64; M] {
            std::array::from_fn(|i| {
                let c = &coef[i];
                ((c[3] * t + c[2]) * t + c[1]) * t + c[0]
            })
        };
        for l in &filter.lines {
            if l.misses(base, top) {
                continue;
            }
            let (t0, t1) = clip(l.q0, l.dq, base, top, l.t0, l.t1);
            if t1 <= t0 {
                continue;
            }
            any = true;
            let panels = ((t1 - t0) / scale).ceil().clamp(1.0, 4096.0) as usize;
            let ph = (t1 - t0) / panels as f64;
            for p in 0..panels {
                let c = t0 + (p as f64 + 0.5) * ph;
                for (&x, &w) in xi.iter().zip(wi) {
                    let t = c + 0.5 * ph * x;
                    let f = l.w * 0.5 * ph * w * profile.at(t);
                    if f == 0.0 {
                        continue;
                    }
                    let u = ((l.q0 + l.dq * t) - base) * inv_h;
                    let (bx, by, bz) = (eval(u.x), eval(u.y), eval(u.z));
                    for (plane, &z) in acc.iter_mut().zip(&bz) {
                        let fz = f * z;
                        for (row, &y) in plane.iter_mut().zip(&by) {
                            let fyz = fz * y;
                            for (o, &x) in row.iter_mut().zip(&bx) {
                                *o += fyz * x;
                            }
                        }
                    }
                }
            }
        }
        for (k, plane) in acc.iter().enumerate() {
            for (j, row) in plane.iter().enumerate() {
                mom[(k * M + j) * M..(k * M + j + 1) * M].copy_from_slice(row);
            }
        }
        any
    }

    /// Control points of `filter` on `cell` into `b` (`M³`, index `(k·M + j)·M + i`): the L²
    /// projection of the masked filter, `b = (G⁻¹ ⊗ G⁻¹ ⊗ G⁻¹) m`. Returns false if no line
    /// meets the cell.
    pub(super) fn control_points(
        &self,
        filter: &LineFilter,
        cell: &Cell,
        b: &mut [f64; 64],
    ) -> bool {
        let mut mom = [0.0; 64];
        if !self.moments(filter, cell, &mut mom) {
            return false;
        }
        // m is in world volume; the cell's `h³·det` cancels against the unit-cell
        // normalisation of the NIL moments C.
        self.apply_ginv(&mut mom, b);
        true
    }

    /// `out = (G⁻¹ ⊗ G⁻¹ ⊗ G⁻¹) x` for `M³` values (index `(k·M + j)·M + i`), one axis at a
    /// time; `x` is overwritten. Applied to a filter's moments it gives its control points;
    /// applied to a NIL cell `C` it gives the Lagrange coefficients of the cell's L²
    /// projection of the data, i.e. that projection's values at the nodes.
    pub(super) fn apply_ginv(&self, x: &mut [f64], out: &mut [f64]) {
        let m = self.basis.order();
        let g = &self.ginv;
        let mut tmp = [0.0; 64];
        // x
        for kj in 0..m * m {
            for i in 0..m {
                tmp[kj * m + i] = (0..m).map(|p| g[i][p] * x[kj * m + p]).sum();
            }
        }
        // y
        for k in 0..m {
            for j in 0..m {
                for i in 0..m {
                    x[(k * m + j) * m + i] =
                        (0..m).map(|p| g[j][p] * tmp[(k * m + p) * m + i]).sum();
                }
            }
        }
        // z
        for k in 0..m {
            for j in 0..m {
                for i in 0..m {
                    out[(k * m + j) * m + i] =
                        (0..m).map(|p| g[k][p] * x[(p * m + j) * m + i]).sum();
                }
            }
        }
    }
}

/// `Σ_cells Σ b·C` per channel for control points already computed (`bs`, `M³` per cell, cells
/// without control points marked `None`), added to `num`. False if a cell is unavailable.
pub(crate) fn integrate_cells(
    map: &dyn NilSource,
    cells: &[Cell],
    bs: &[Option<[f64; 64]>],
    moments: &mut Vec<f64>,
    num: &mut [f64],
) -> bool {
    let m = map.basis().order();
    let m3 = m * m * m;
    moments.resize(m3 * map.channels(), 0.0);
    for (cell, b) in cells.iter().zip(bs) {
        let Some(b) = b else { continue };
        if !map.cell(cell.gamma, cell.index, moments) {
            return false;
        }
        for (ch, n) in num.iter_mut().enumerate() {
            let c = &moments[ch * m3..(ch + 1) * m3];
            *n += b[..m3].iter().zip(c).map(|(x, y)| x * y).sum::<f64>();
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn projection_reproduces_the_patch_space_and_keeps_the_integral() {
        // A polynomial already in the patch space is its own projection: project the basis
        // function B_1 ⊗ B_0 ⊗ B_2 (M = 3) given as moments, get the unit vector back.
        let basis = PatchBasis::new(3).unwrap();
        let p = Projector::new(basis);
        let m = 3;
        // Gram: G_ij by 5-point GL; moments of the tensor function B_(1,0,2).
        let (x, w) = gauss_legendre(5);
        let g = |i: usize, j: usize| -> f64 {
            x.iter()
                .zip(w)
                .map(|(&xi, &wi)| {
                    let t = 0.5 * (xi + 1.0);
                    0.5 * wi * basis.eval(i, t) * basis.eval(j, t)
                })
                .sum()
        };
        let mut mom = [0.0; 64];
        for k in 0..m {
            for j in 0..m {
                for i in 0..m {
                    mom[(k * m + j) * m + i] = g(i, 1) * g(j, 0) * g(k, 2);
                }
            }
        }
        // Apply G⁻¹ ⊗ G⁻¹ ⊗ G⁻¹ by hand through the same code path as control_points.
        let gi = &p.ginv;
        let mut out = [0.0; 64];
        for k in 0..m {
            for j in 0..m {
                for i in 0..m {
                    let mut s = 0.0;
                    for c in 0..m {
                        for b in 0..m {
                            for a in 0..m {
                                s += gi[k][c] * gi[j][b] * gi[i][a] * mom[(c * m + b) * m + a];
                            }
                        }
                    }
                    out[(k * m + j) * m + i] = s;
                }
            }
        }
        for k in 0..m {
            for j in 0..m {
                for i in 0..m {
                    let want = if (i, j, k) == (1, 0, 2) { 1.0 } else { 0.0 };
                    assert!((out[(k * m + j) * m + i] - want).abs() < 1e-12);
                }
            }
        }
        // Σ_i G⁻¹ row sums against B̄: the constant 1 has coefficients all ones.
        for i in 0..m {
            let s: f64 = (0..m).map(|j| gi[i][j] * basis.mean(j)).sum();
            assert!((s - 1.0).abs() < 1e-12, "{s}");
        }
    }
}
