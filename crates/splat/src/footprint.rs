//! Footprint tables (Westover 1991, §3.7.1–3.7.4, with the corrections listed in `docs/papers.md`,
//! rows §3.7.3–3.7.4).
//!
//! The footprint of a sample is the line integral of its reconstruction kernel along the view,
//! `footprint(x, y) = ∫ h(x, y, z) dz` (§3.7.1). In an orthographic view of a rectilinear lattice
//! every sample has the same footprint up to a sub-pixel offset, so it is tabulated once per
//! frame (§3.7.2) at `P × P` sub-pixel phases; each phase stores the weights at the pixel centres
//! a sample with that phase covers, contiguously, so splatting reads one small dense block.
//!
//! **Radial kernels** (the Gaussian): the ray through raster offset `δ` passes the kernel centre
//! at lattice distance `ρ = ‖L δ‖`, where `LᵀL = Q = Bᵀ(I − ĝĝᵀ)B`, `B` maps raster offsets to
//! lattice offsets and `ĝ` is the view direction in lattice space. `L = Λ^{1/2} Uᵀ` comes from the
//! symmetric eigen-decomposition `Q = U Λ Uᵀ` (docs/design.md §4.3): the projected ellipse maps
//! exactly onto the circle of the generic radial footprint, with no 45° singularity and no shape
//! error (the thesis's §3.7.4 formulas are inconsistent; §5.4's anisotropy error disappears).
//!
//! **Separable kernels** (tent, Mitchell–Netravali, box): the line integral is evaluated per table
//! entry by splitting the ray at every knot of the piecewise-cubic kernel and integrating each
//! polynomial piece exactly with 5-point Gauss–Legendre quadrature.
//!
//! **Normalisation** (docs/design.md §4.1): weights are `∫h ds / Δs` where `Δs` is the world path
//! between sheets, so the footprints of one constant sheet sum to the constant (partition of
//! unity over the projected sheet lattice); multiplying by `Δs` gives the world-space line
//! integral used by X-ray mode.

use crate::aa::{Antialias, footprint_variance, sym_eigen, widen};
use crate::error::{Result, SplatError};
use crate::geometry::SplatGeometry;
use volsplat_core::Kernel;
use volsplat_core::glam::{DMat2, DVec2, DVec3};

/// How the per-frame footprint table is sized.
#[derive(Debug, Clone, Copy, PartialEq)]
#[non_exhaustive]
pub struct FootprintSettings {
    /// Upper bound on the table's total entries (phases² × block size). Westover used about
    /// 128 × 128 = 16 384 with at most 9 × 9 phases; the default 2¹⁵ (128 KiB, cache-resident)
    /// gives about 17 phases per axis at 1–2 pixels per voxel, and with the first-order phase
    /// blend a constant sheet reconstructs within ±0.3 %. 2¹⁷ is 25 % slower and no more
    /// accurate in rendered images (decision 0002).
    pub max_entries: usize,
    /// Largest number of sub-pixel phases per axis.
    pub max_phases: usize,
    /// Largest footprint block side, in pixels (default 1024): a footprint wider or taller
    /// than this (one voxel projecting onto hundreds of pixels: an extreme zoom, a tiny camera
    /// `parallel_scale`, or a spacing like `1 3e7 1`) is an error instead of a table of
    /// gigabytes. At the default a table holds at most 4 × 1024² weights (16 MiB).
    pub max_block_side: usize,
}

impl Default for FootprintSettings {
    fn default() -> Self {
        FootprintSettings {
            max_entries: 1 << 15,
            max_phases: 64,
            max_block_side: 1024,
        }
    }
}

/// The pixel block shared by all phases, relative to a sample's base pixel.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct PhaseBlock {
    /// Pixel offset of the block's first column relative to the sample's base pixel.
    pub kx0: i32,
    /// Pixel offset of the block's first row relative to the sample's base pixel.
    pub ky0: i32,
    /// Block width in pixels.
    pub width: u32,
    /// Block height in pixels.
    pub height: u32,
}

/// Where a sample's weights are: the pixel of its block's first entry, the three phase blocks
/// to blend (only `w00` for the single-point kernel), the blend fractions, and each row's
/// non-zero column span.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Located<'a> {
    /// Image column of the block's first column.
    pub x0: i32,
    /// Image row of the block's first row.
    pub y0: i32,
    /// Weights of the phase at or below the sample.
    pub w00: &'a [f32],
    /// Weights of the next phase in x (empty when not blending).
    pub w10: &'a [f32],
    /// Weights of the next phase in y (empty when not blending).
    pub w01: &'a [f32],
    /// Blend fraction towards `w10`, in [0, 1).
    pub fx: f32,
    /// Blend fraction towards `w01`, in [0, 1).
    pub fy: f32,
    /// Lower bound of a blended weight: 0 when every table entry is ≥ 0 (the blend extrapolates
    /// where `fx + fy > 1` and must not make a negative weight from non-negative ones), −∞ for
    /// kernels with negative lobes.
    pub floor: f32,
    /// Per row: non-zero columns `[start, end)`.
    pub spans: &'a [(u16, u16)],
}

impl Located<'_> {
    /// The blended weight at block index `i` (the renderers blend whole rows in their own
    /// loops; the tests check those against this).
    #[cfg(test)]
    #[inline(always)]
    pub(crate) fn weight(&self, i: usize) -> f32 {
        if self.w10.is_empty() {
            return self.w00[i];
        }
        let a = self.w00[i];
        (a + self.fx * (self.w10[i] - a) + self.fy * (self.w01[i] - a)).max(self.floor)
    }
}

/// The per-frame footprint table (Westover §3.7.2): for each of `P × P` sub-pixel phases, the
/// weights at the pixel centres a sample with that phase covers, as one dense block of a shape
/// common to all phases, plus each row's non-zero column span.
#[derive(Debug, Clone)]
pub(crate) struct FootprintTable {
    /// Sub-pixel phases per axis (`P`).
    pub phases: usize,
    /// Whether neighbouring phases are blended (all kernels but single-point).
    blend: bool,
    /// Lower bound of blended weights ([`Located::floor`]).
    floor: f32,
    /// Half-widths of the footprint's axis-aligned extent, pixels (x, y).
    pub half_extent: [f64; 2],
    /// Weights of all phases, block after block, row-major inside a block.
    entries: Vec<f32>,
    /// Per phase and row: the non-zero columns `[start, end)` of that row.
    row_spans: Vec<(u16, u16)>,
    block: PhaseBlock,
    /// Blending tables only: per phase `(px, py)` in `0..P` × `0..P`, three planes of the block's
    /// shape, `w₀₀`, `w₁₀ − w₀₀` and `w₀₁ − w₀₀` (the differences the first-order blend takes,
    /// computed once per frame in the same f32 arithmetic, so blended weights keep their bits),
    /// followed by [`BLEND_PAD`] zeros so that the row loops may read whole SIMD vectors.
    blend_planes: Vec<f32>,
}

/// Zeros after the last blend plane: a row loop may read up to this many entries past its end.
pub(crate) const BLEND_PAD: usize = 8;

/// A sample's blend planes ([`FootprintTable::locate_planes`]): the weight at block index `i` is
/// `max(floor, a[i] + fx·dx[i] + fy·dy[i])`, bit for bit [`Located::weight`].
#[derive(Debug, Clone, Copy)]
pub(crate) struct LocatedPlanes<'a> {
    pub(crate) x0: i32,
    pub(crate) y0: i32,
    /// `w₀₀`, then `w₁₀ − w₀₀`, then `w₀₁ − w₀₀`, each followed by at least [`BLEND_PAD`]
    /// readable entries.
    pub(crate) a: &'a [f32],
    pub(crate) dx: &'a [f32],
    pub(crate) dy: &'a [f32],
    pub(crate) fx: f32,
    pub(crate) fy: f32,
    pub(crate) floor: f32,
    pub(crate) spans: &'a [(u16, u16)],
}

/// The continuous footprint of one frame, before tabulation.
pub(crate) struct FootprintFunction {
    kind: Kind,
    /// Anti-aliasing (crate::aa): the weight at `δ` is `energy · inner(pre · δ)`.
    pre: DMat2,
    energy: f64,
    /// 1 / (|g| Δs): converts an index-length line integral into a sheet-normalised weight.
    scale: f64,
    half_extent: [f64; 2],
}

enum Kind {
    Radial {
        #[cfg_attr(not(test), allow(dead_code))]
        kernel: Kernel,
        l: DMat2,
        radial_table: Vec<f64>,
        radius2: f64,
    },
    Separable {
        kernel: Kernel,
        b: [DVec3; 2],
        g_hat: DVec3,
    },
    Nearest {
        inv_cell: DMat2,
    },
    Point {
        weight: f64,
    },
}

const RADIAL_TABLE_LEN: usize = 4096;

impl FootprintFunction {
    pub(crate) fn new(kernel: &Kernel, geom: &SplatGeometry, aa: Antialias) -> Self {
        let mut f = Self::unfiltered(kernel, geom);
        let q = lattice_metric(geom);
        if aa != Antialias::None && !matches!(f.kind, Kind::Point { .. }) {
            let (q2, e) = widen(aa, q, footprint_variance(kernel));
            if e < 1.0 {
                // M = L⁻¹L′ maps the widened ellipse onto the original: MᵀQM = Q′.
                let m = ellipse_to_circle(q).inverse() * ellipse_to_circle(q2);
                let mi = m.inverse();
                let [hx, hy] = f.half_extent;
                f.half_extent = [
                    mi.col(0).x.abs() * hx + mi.col(1).x.abs() * hy,
                    mi.col(0).y.abs() * hx + mi.col(1).y.abs() * hy,
                ];
                f.pre = m;
                f.energy = e;
            }
        }
        f
    }

    /// The true projected footprint, without anti-aliasing.
    fn unfiltered(kernel: &Kernel, geom: &SplatGeometry) -> Self {
        // Raster offsets (dx, dy) → lattice offsets: columns of J⁻¹ for x and y at fixed depth.
        let j_inv = geom.jacobian.inverse();
        let b = [j_inv.col(0), j_inv.col(1)];
        // View direction in lattice space: a unit depth step at fixed (x, y).
        let g = j_inv.col(2);
        let g_len = g.length();
        let g_hat = g / g_len;
        let scale = 1.0 / (g_len * geom.sheet_spacing);
        let ju = geom.jacobian.col(geom.in_sheet_axes[0]);
        let jv = geom.jacobian.col(geom.in_sheet_axes[1]);
        match *kernel {
            Kernel::SinglePoint | Kernel::Nearest => {}
            k if k.is_radial() => {
                let radius = k.radius();
                // Q = Bᵀ (I − ĝĝᵀ) B, the projected ellipse's quadratic form.
                let q = lattice_metric(geom);
                let l = ellipse_to_circle(q);
                let qi = q.inverse();
                let half_extent = [radius * qi.col(0).x.sqrt(), radius * qi.col(1).y.sqrt()];
                let radius2 = radius * radius;
                let radial_table = (0..RADIAL_TABLE_LEN)
                    .map(|n| {
                        let r2 = radius2 * n as f64 / (RADIAL_TABLE_LEN - 1) as f64;
                        kernel.line_integral_radial(r2.sqrt()).unwrap_or(0.0)
                    })
                    .collect();
                return FootprintFunction {
                    kind: Kind::Radial {
                        kernel: *kernel,
                        l,
                        radial_table,
                        radius2,
                    },
                    scale,
                    half_extent,
                    pre: DMat2::IDENTITY,
                    energy: 1.0,
                };
            }
            _ => {
                let r = kernel.radius();
                let jac = geom.jacobian;
                let half_extent = [
                    r * (jac.col(0).x.abs() + jac.col(1).x.abs() + jac.col(2).x.abs()),
                    r * (jac.col(0).y.abs() + jac.col(1).y.abs() + jac.col(2).y.abs()),
                ];
                return FootprintFunction {
                    kind: Kind::Separable {
                        kernel: *kernel,
                        b,
                        g_hat,
                    },
                    scale,
                    half_extent,
                    pre: DMat2::IDENTITY,
                    energy: 1.0,
                };
            }
        }
        match *kernel {
            Kernel::SinglePoint => FootprintFunction {
                kind: Kind::Point {
                    weight: geom.cell_volume
                        / (geom.pixel_size * geom.pixel_size * geom.sheet_spacing),
                },
                scale: 1.0,
                half_extent: [0.0, 0.0],
                pre: DMat2::IDENTITY,
                energy: 1.0,
            },
            Kernel::Nearest => {
                let cell = DMat2::from_cols(DVec2::new(ju.x, ju.y), DVec2::new(jv.x, jv.y));
                FootprintFunction {
                    kind: Kind::Nearest {
                        inv_cell: cell.inverse(),
                    },
                    scale: 1.0,
                    half_extent: [
                        0.5 * (ju.x.abs() + jv.x.abs()),
                        0.5 * (ju.y.abs() + jv.y.abs()),
                    ],
                    pre: DMat2::IDENTITY,
                    energy: 1.0,
                }
            }
            _ => FootprintFunction {
                kind: Kind::Point { weight: 0.0 },
                scale: 1.0,
                half_extent: [0.0, 0.0],
                pre: DMat2::IDENTITY,
                energy: 1.0,
            },
        }
    }

    /// The sheet-normalised weight at raster offset `(dx, dy)` pixels from the sample's centre.
    pub(crate) fn weight(&self, dx: f64, dy: f64) -> f64 {
        if self.energy != 1.0 {
            let d = self.pre * DVec2::new(dx, dy);
            return self.energy * self.inner_weight(d.x, d.y);
        }
        self.inner_weight(dx, dy)
    }

    fn inner_weight(&self, dx: f64, dy: f64) -> f64 {
        match &self.kind {
            Kind::Radial {
                l,
                radial_table,
                radius2,
                ..
            } => {
                let u = *l * DVec2::new(dx, dy);
                let r2 = u.length_squared();
                if r2 >= *radius2 {
                    return 0.0;
                }
                let t = r2 / radius2 * (RADIAL_TABLE_LEN - 1) as f64;
                let i = (t as usize).min(RADIAL_TABLE_LEN - 2);
                let f = t - i as f64;
                (radial_table[i] * (1.0 - f) + radial_table[i + 1] * f) * self.scale
            }
            Kind::Separable { kernel, b, g_hat } => {
                let o = b[0] * dx + b[1] * dy;
                separable_line_integral(kernel, o, *g_hat) * self.scale
            }
            Kind::Nearest { inv_cell } => {
                let ab = *inv_cell * DVec2::new(dx, dy);
                let inside = |v: f64| (-0.5..0.5).contains(&v);
                if inside(ab.x) && inside(ab.y) {
                    1.0
                } else {
                    0.0
                }
            }
            Kind::Point { weight } => {
                if dx == 0.0 && dy == 0.0 {
                    *weight
                } else {
                    0.0
                }
            }
        }
    }

    /// The exact (untabulated) weight, for tests: radial kernels use the closed form directly.
    #[cfg(test)]
    pub(crate) fn exact_weight(&self, dx: f64, dy: f64) -> f64 {
        match &self.kind {
            Kind::Radial { kernel, l, .. } => {
                let d = self.pre * DVec2::new(dx, dy);
                let rho = (*l * d).length();
                self.energy * kernel.line_integral_radial(rho).unwrap_or(0.0) * self.scale
            }
            _ => self.weight(dx, dy),
        }
    }
}

/// The frame's lattice metric `Q = Bᵀ(I − ĝĝᵀ)B` (lattice units² per pixel²): a ray through
/// raster offset `δ` passes a sample at lattice distance `√(δᵀQδ)` ([`crate::aa`]).
pub(crate) fn lattice_metric(geom: &SplatGeometry) -> DMat2 {
    let j_inv = geom.jacobian.inverse();
    metric_from(j_inv.col(0), j_inv.col(1), j_inv.col(2))
}

/// `Q = Bᵀ(I − ĝĝᵀ)B` from the lattice displacements of a one-pixel step in x and y (`b0`, `b1`)
/// and the lattice direction of the ray (`g`, any length).
pub(crate) fn metric_from(b0: DVec3, b1: DVec3, g: DVec3) -> DMat2 {
    let g_hat = g.normalize();
    let perp = |v: DVec3| v - g_hat * v.dot(g_hat);
    let (p0, p1) = (perp(b0), perp(b1));
    DMat2::from_cols(
        DVec2::new(p0.dot(p0), p0.dot(p1)),
        DVec2::new(p1.dot(p0), p1.dot(p1)),
    )
}

/// `L` with `LᵀL = Q` for a symmetric positive-definite 2×2 `Q`, from its eigen-decomposition
/// `Q = U Λ Uᵀ` (the cancellation-free [`crate::aa`] form): `L = Λ^{1/2} Uᵀ`. Maps the ellipse
/// `δᵀQδ = 1` onto the unit circle. A negative eigenvalue (rounding of a degenerate `Q`) is
/// taken as 0.
pub(crate) fn ellipse_to_circle(q: DMat2) -> DMat2 {
    let (l1, l2, e1) = sym_eigen(q);
    let l2 = l2.max(0.0);
    let e2 = DVec2::new(-e1.y, e1.x);
    // Rows of L are √λᵢ eᵢᵀ.
    DMat2::from_cols(
        DVec2::new(l1.sqrt() * e1.x, l2.sqrt() * e2.x),
        DVec2::new(l1.sqrt() * e1.y, l2.sqrt() * e2.y),
    )
}

/// ∫ h(o + t·ĝ) dt over all t (index-length units) for a separable piecewise-polynomial kernel,
/// exact up to rounding: the line is split at every knot and each piece is integrated with
/// 5-point Gauss–Legendre, exact for polynomials up to degree 9.
fn separable_line_integral(kernel: &Kernel, o: DVec3, g: DVec3) -> f64 {
    let r = kernel.radius();
    // Clip the line to the support cube |o + t g|∞ ≤ r.
    let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
    for c in 0..3 {
        if g[c].abs() < 1e-12 {
            if o[c].abs() > r {
                return 0.0;
            }
        } else {
            let a = (-r - o[c]) / g[c];
            let b = (r - o[c]) / g[c];
            t0 = t0.max(a.min(b));
            t1 = t1.min(a.max(b));
        }
    }
    if t1 <= t0 {
        return 0.0;
    }
    // Knots: where a coordinate crosses an integer multiple of ... the kernel's breakpoints
    // (integers for tent and BC cubics).
    let mut knots = vec![t0, t1];
    for c in 0..3 {
        if g[c].abs() >= 1e-12 {
            let lo = (-r).ceil() as i32;
            let hi = r.floor() as i32;
            for m in lo..=hi {
                let t = (m as f64 - o[c]) / g[c];
                if t > t0 && t < t1 {
                    knots.push(t);
                }
            }
        }
    }
    knots.sort_by(f64::total_cmp);
    const X: [f64; 5] = [
        0.0,
        -0.538_469_310_105_683_1,
        0.538_469_310_105_683_1,
        -0.906_179_845_938_664,
        0.906_179_845_938_664,
    ];
    const W: [f64; 5] = [
        0.568_888_888_888_888_9,
        0.478_628_670_499_366_5,
        0.478_628_670_499_366_5,
        0.236_926_885_056_189_1,
        0.236_926_885_056_189_1,
    ];
    let mut sum = 0.0;
    for w in knots.windows(2) {
        let (a, b) = (w[0], w[1]);
        if b - a <= 0.0 {
            continue;
        }
        let (m, h) = (0.5 * (a + b), 0.5 * (b - a));
        for q in 0..5 {
            let p = o + g * (m + h * X[q]);
            sum += W[q] * h * kernel.eval_1d(p.x) * kernel.eval_1d(p.y) * kernel.eval_1d(p.z);
        }
    }
    sum
}

/// A footprint block side (`2⌈h⌉ + 2` pixels) for messages.
/// The block side `2⌈h⌉ + 2` in pixels for a half extent `h` (non-finite stays as it is).
fn block_side(h: f64) -> f64 {
    if h.is_finite() {
        2.0 * h.ceil() + 2.0
    } else {
        h
    }
}

impl FootprintTable {
    /// Tabulates the footprint of `kernel` for the frame `geom`.
    ///
    /// Errors ([`SplatError::FootprintTooLarge`]) if the footprint's block (`2⌈half extent⌉ + 2` pixels
    /// per axis) exceeds [`FootprintSettings::max_block_side`] or is not finite, before
    /// anything is allocated.
    pub(crate) fn build(
        kernel: &Kernel,
        geom: &SplatGeometry,
        settings: &FootprintSettings,
        antialias: Antialias,
    ) -> Result<Self> {
        let f = FootprintFunction::new(kernel, geom, antialias);
        Self::from_function(&f, settings)
    }

    pub(crate) fn from_function(
        f: &FootprintFunction,
        settings: &FootprintSettings,
    ) -> Result<Self> {
        let [hx, hy] = f.half_extent;
        let max_side = settings.max_block_side;
        // The largest half extent whose block 2⌈h⌉ + 2 fits in max_side pixels.
        let max_half = (max_side.saturating_sub(2) / 2) as f64;
        if !(hx.is_finite() && hy.is_finite() && hx <= max_half && hy <= max_half) {
            return Err(SplatError::FootprintTooLarge {
                width: block_side(hx),
                height: block_side(hy),
                limit: max_side,
            });
        }
        let point = matches!(f.kind, Kind::Point { .. });
        // Pixel offsets k ∈ [−⌈h⌉, ⌈h⌉ + 1] hold every pixel a sample with phase in [0, 1) covers.
        let (kx0, ky0) = (-(hx.ceil() as i32), -(hy.ceil() as i32));
        let (width, height) = ((2 * hx.ceil() as usize) + 2, (2 * hy.ceil() as usize) + 2);
        let phases = if point {
            1
        } else {
            let per_phase = (width * height).max(1);
            (((settings.max_entries / per_phase) as f64).sqrt().floor() - 1.0)
                .clamp(1.0, settings.max_phases.max(1) as f64) as usize
        };
        // Phases 0..=P per axis (phase P is phase 0 one pixel on), so every phase has a +x and
        // a +y neighbour to blend with.
        let np = if point { 1 } else { phases + 1 };
        let p = phases as f64;
        let mut raw = vec![0f32; np * np * width * height];
        for py in 0..np {
            for px in 0..np {
                let (ox, oy) = (px as f64 / p, py as f64 / p);
                let base = (py * np + px) * width * height;
                for r in 0..height {
                    for c in 0..width {
                        let (kx, ky) = (kx0 + c as i32, ky0 + r as i32);
                        raw[base + r * width + c] = f.weight(kx as f64 - ox, ky as f64 - oy) as f32;
                    }
                }
            }
        }
        // Trim the border rows and columns that are zero in every phase.
        let n = np * np;
        let (mut c0, mut c1, mut r0, mut r1) = (width, 0, height, 0);
        for b in 0..n {
            for r in 0..height {
                for c in 0..width {
                    if raw[b * width * height + r * width + c] != 0.0 {
                        c0 = c0.min(c);
                        c1 = c1.max(c + 1);
                        r0 = r0.min(r);
                        r1 = r1.max(r + 1);
                    }
                }
            }
        }
        if c1 <= c0 || r1 <= r0 {
            (c0, c1, r0, r1) = (0, 0, 0, 0);
        }
        let (tw, th) = (c1 - c0, r1 - r0);
        let mut entries = Vec::with_capacity(n * tw * th);
        let mut own_spans = Vec::with_capacity(n * th);
        for b in 0..n {
            for r in r0..r1 {
                let row = &raw[b * width * height + r * width + c0..][..tw];
                entries.extend_from_slice(row);
                let first = row.iter().position(|&v| v != 0.0).unwrap_or(tw);
                let last = row.iter().rposition(|&v| v != 0.0).map_or(first, |i| i + 1);
                own_spans.push((first as u16, last.max(first) as u16));
            }
        }
        // A phase's span must cover its own and its +x, +y neighbours' non-zero weights.
        let mut row_spans = own_spans.clone();
        if !point {
            for py in 0..phases {
                for px in 0..phases {
                    for r in 0..th {
                        let at = |qx: usize, qy: usize| own_spans[(qy * np + qx) * th + r];
                        let corners = [at(px, py), at(px + 1, py), at(px, py + 1)];
                        let lo = corners
                            .iter()
                            .filter(|s| s.1 > s.0)
                            .map(|s| s.0)
                            .min()
                            .unwrap_or(0);
                        let hi = corners
                            .iter()
                            .filter(|s| s.1 > s.0)
                            .map(|s| s.1)
                            .max()
                            .unwrap_or(0);
                        row_spans[(py * np + px) * th + r] = (lo, hi.max(lo));
                    }
                }
            }
        }
        let floor = if entries.iter().all(|&v| v >= 0.0) {
            0.0
        } else {
            f32::NEG_INFINITY
        };
        let mut blend_planes = Vec::new();
        if !point {
            let wh = tw * th;
            let block = |qx: usize, qy: usize| &entries[(qy * np + qx) * wh..][..wh];
            blend_planes.reserve(phases * phases * 3 * wh + BLEND_PAD);
            for py in 0..phases {
                for px in 0..phases {
                    let (a, b, c) = (block(px, py), block(px + 1, py), block(px, py + 1));
                    blend_planes.extend_from_slice(a);
                    blend_planes.extend(b.iter().zip(a).map(|(&b, &a)| b - a));
                    blend_planes.extend(c.iter().zip(a).map(|(&c, &a)| c - a));
                }
            }
            blend_planes.resize(blend_planes.len() + BLEND_PAD, 0.0);
        }
        Ok(FootprintTable {
            phases,
            blend: !point,
            floor,
            half_extent: [hx, hy],
            entries,
            row_spans,
            block: PhaseBlock {
                kx0: kx0 + c0 as i32,
                ky0: ky0 + r0 as i32,
                width: tw as u32,
                height: th as u32,
            },
            blend_planes,
        })
    }

    /// A table from raw parts (tests): one phase.
    #[cfg(test)]
    pub(crate) fn from_raw(half_extent: [f64; 2], entries: Vec<f32>, block: PhaseBlock) -> Self {
        let spans = (0..block.height).map(|_| (0, block.width as u16)).collect();
        FootprintTable {
            phases: 1,
            blend: false,
            floor: f32::NEG_INFINITY,
            half_extent,
            entries,
            row_spans: spans,
            block,
            blend_planes: Vec::new(),
        }
    }

    /// Total number of stored weights.
    pub(crate) fn entry_count(&self) -> usize {
        self.entries.len()
    }

    /// The block shape shared by every phase.
    pub(crate) fn block(&self) -> PhaseBlock {
        self.block
    }

    /// The sample at raster `(x, y)` (pixels; pixel centres at half-integers): see [`Located`].
    ///
    /// The sample sits between tabulated phases; its weights are the first-order blend
    /// `max(floor, w₀₀ + fx·(w₁₀ − w₀₀) + fy·(w₀₁ − w₀₀))` of the phase at or below it and the
    /// next phase in x and in y. The blend keeps partition of unity and leaves an O(1/P²) error
    /// (nearest phase alone: O(1/P), about ±1 % ripple on a constant sheet at P = 45). Where
    /// `fx + fy > 1` it extrapolates, and at the footprint's edge (`w₀₀ > 0`, neighbours 0) made
    /// slightly negative weights: X-ray images of non-negative data held values down to
    /// −0.004. For non-negative kernels the blend is therefore clamped at 0 ([`Located::floor`];
    /// the clamp only removes those edge undershoots, of the order of the blend's own error).
    /// A convex (barycentric, two-triangle) blend was measured 10 % slower per frame
    /// (decision 0002). The single-point kernel (`P = 1`) lands on the nearest pixel.
    #[inline(always)]
    pub(crate) fn locate(&self, x: f32, y: f32) -> Located<'_> {
        let p = self.phases as f32;
        let (w, h) = (self.block.width as usize, self.block.height as usize);
        // Floor without a libm call; positions are finite and far inside the i32 range.
        let floor = |v: f32| {
            let i = v as i32;
            if (i as f32) > v { i - 1 } else { i }
        };
        if !self.blend {
            let (bx, by) = (floor(x), floor(y));
            return Located {
                x0: bx + self.block.kx0,
                y0: by + self.block.ky0,
                w00: &self.entries[..w * h],
                w10: &[],
                w01: &[],
                fx: 0.0,
                fy: 0.0,
                floor: f32::NEG_INFINITY,
                spans: &self.row_spans[..h],
            };
        }
        // Base pixel, then the phase within it: float arithmetic only (no integer division).
        let (cx, cy) = (x - 0.5, y - 0.5);
        let (bx, by) = (floor(cx), floor(cy));
        let last = (self.phases - 1) as f32;
        let (tx, ty) = (
            ((cx - bx as f32) * p).min(last + 0.999_9),
            ((cy - by as f32) * p).min(last + 0.999_9),
        );
        let (px, py) = (
            (tx as usize).min(self.phases - 1),
            (ty as usize).min(self.phases - 1),
        );
        let (fx, fy) = (tx - px as f32, ty - py as f32);
        let np = self.phases + 1;
        let block = |qx: usize, qy: usize| &self.entries[(qy * np + qx) * w * h..][..w * h];
        Located {
            x0: bx + self.block.kx0,
            y0: by + self.block.ky0,
            w00: block(px, py),
            w10: block(px + 1, py),
            w01: block(px, py + 1),
            fx,
            fy,
            floor: self.floor,
            spans: &self.row_spans[(py * np + px) * h..][..h],
        }
    }

    /// Whether every weight is ≥ 0, so that blended weights are too ([`Located::floor`] = 0).
    pub(crate) fn non_negative(&self) -> bool {
        self.floor == 0.0
    }

    /// The image pixel of the block's first entry for a sample at `(x, y)`: `(x0, y0)` of
    /// [`FootprintTable::locate`], computed the same way.
    #[inline(always)]
    pub(crate) fn origin(&self, x: f32, y: f32) -> (i32, i32) {
        let floor = |v: f32| {
            let i = v as i32;
            if (i as f32) > v { i - 1 } else { i }
        };
        let (bx, by) = if self.blend {
            (floor(x - 0.5), floor(y - 0.5))
        } else {
            (floor(x), floor(y))
        };
        (bx + self.block.kx0, by + self.block.ky0)
    }

    /// Like [`FootprintTable::locate`], for blending tables, with the blend's differences
    /// precomputed ([`LocatedPlanes`]); `None` for the single-point kernel. The base pixel, phase
    /// and fractions are computed exactly as `locate` computes them.
    #[inline(always)]
    pub(crate) fn locate_planes(&self, x: f32, y: f32) -> Option<LocatedPlanes<'_>> {
        if !self.blend {
            return None;
        }
        let p = self.phases as f32;
        let (w, h) = (self.block.width as usize, self.block.height as usize);
        let floor = |v: f32| {
            let i = v as i32;
            if (i as f32) > v { i - 1 } else { i }
        };
        let (cx, cy) = (x - 0.5, y - 0.5);
        let (bx, by) = (floor(cx), floor(cy));
        let last = (self.phases - 1) as f32;
        let (tx, ty) = (
            ((cx - bx as f32) * p).min(last + 0.999_9),
            ((cy - by as f32) * p).min(last + 0.999_9),
        );
        let (px, py) = (
            (tx as usize).min(self.phases - 1),
            (ty as usize).min(self.phases - 1),
        );
        let (fx, fy) = (tx - px as f32, ty - py as f32);
        let wh = w * h;
        let planes = &self.blend_planes[(py * self.phases + px) * 3 * wh..];
        Some(LocatedPlanes {
            x0: bx + self.block.kx0,
            y0: by + self.block.ky0,
            a: planes,
            dx: &planes[wh..],
            dy: &planes[2 * wh..],
            fx,
            fy,
            floor: self.floor,
            spans: &self.row_spans[(py * (self.phases + 1) + px) * h..][..h],
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::aa::Antialias;
    use crate::geometry::{Order, SplatGeometry};
    use volsplat_core::glam::{DMat3, DVec3};
    use volsplat_core::{Camera, Grid, OrthoProjection};

    fn geometry(spacing: [f64; 3], az: f64, el: f64, scale: f64) -> SplatGeometry {
        let grid = Grid::new([16, 16, 16], spacing, [0.0; 3], DMat3::IDENTITY).unwrap();
        let mut c = Camera::reset_to_bounds(DVec3::ZERO, DVec3::splat(15.0), true);
        c.azimuth(az);
        c.elevation(el);
        c.orthogonalize_view_up();
        c.parallel_scale = 32.0 / scale;
        let proj = OrthoProjection::new(&c, 64, 64).unwrap();
        SplatGeometry::new(&grid, &proj, 1, Order::FrontToBack).unwrap()
    }

    /// Numerically integrates the 3-D kernel along the view ray through raster offset δ,
    /// normalised like the table (divided by Δs), straight from the definition.
    fn brute_force(kernel: &Kernel, geom: &SplatGeometry, dx: f64, dy: f64) -> f64 {
        let j_inv = geom.jacobian.inverse();
        let o = j_inv * DVec3::new(dx, dy, 0.0);
        let g = j_inv.col(2); // lattice displacement per world unit of depth
        let n = 40000;
        let range = 8.0 / g.length();
        let h = 2.0 * range / n as f64;
        let mut s = 0.0;
        for i in 0..n {
            let t = -range + (i as f64 + 0.5) * h;
            s += kernel.eval_3d(o + g * t) * h;
        }
        s / geom.sheet_spacing
    }

    /// F-W16/F-W18: the ellipse-mapped generic footprint equals the numerical z-integral of the
    /// transformed kernel, including Westover's Fig 5.03 worst case (x-spacing 2× z, 45° about y).
    #[test]
    fn gaussian_footprint_matches_numerical_integration() {
        let k = Kernel::default();
        for (spacing, az, el) in [
            ([2.0, 1.0, 1.0], 45.0, 0.0),
            ([1.0, 1.3, 2.0], 33.0, 27.0),
            ([1.0; 3], 0.0, 0.0),
        ] {
            let g = geometry(spacing, az, el, 2.0);
            let f = FootprintFunction::new(&k, &g, Antialias::None);
            for (dx, dy) in [(0.0, 0.0), (0.7, -0.3), (1.5, 1.1), (-2.2, 0.4)] {
                let a = f.exact_weight(dx, dy);
                let t = f.weight(dx, dy);
                let b = brute_force(&k, &g, dx, dy);
                assert!(
                    (a - b).abs() < 1e-5 * (1.0 + b),
                    "{spacing:?} {az} {el} ({dx},{dy}): {a} vs {b}"
                );
                assert!(
                    (t - a).abs() < 2e-4 * (1.0 + a),
                    "table interpolation: {t} vs {a}"
                );
            }
        }
    }

    #[test]
    fn separable_footprints_match_numerical_integration() {
        for k in [
            Kernel::Tent,
            Kernel::MitchellNetravali { b: 1.0, c: 0.0 },
            Kernel::MitchellNetravali { b: 0.0, c: 0.5 },
        ] {
            let g = geometry([1.0, 1.0, 1.5], 28.0, 17.0, 1.7);
            let f = FootprintFunction::new(&k, &g, Antialias::None);
            for (dx, dy) in [(0.0, 0.0), (0.9, -0.35), (2.1, 1.3)] {
                let a = f.weight(dx, dy);
                let b = brute_force(&k, &g, dx, dy);
                assert!(
                    (a - b).abs() < 2e-4 * (1.0 + b),
                    "{} ({dx},{dy}): {a} vs {b}",
                    k.name()
                );
            }
        }
    }

    /// The CLI's camera for a grid: VTK's reset view turned by azimuth and elevation.
    fn view(grid: &Grid, az: f64, el: f64, w: usize, h: usize) -> SplatGeometry {
        let (lo, hi) = grid.bounds_world();
        let mut c = Camera::reset_to_bounds(lo, hi, true);
        c.azimuth(az);
        c.elevation(el);
        c.orthogonalize_view_up();
        let proj = OrthoProjection::new(&c, w, h).unwrap();
        SplatGeometry::new(grid, &proj, 1, Order::FrontToBack).unwrap()
    }

    /// Regression test for issue 17's root cause: mri_colin27 (181×217×181, spacing 1) at
    /// 512×512 and azimuth 30° has a lattice metric isotropic to rounding with an exactly zero
    /// off-diagonal; the eigenvector cancelled to NaN, every footprint weight was NaN, and the
    /// image came out black (composite) or NaN (X-ray) with exit code 0.
    #[test]
    fn isotropic_metric_rounding_gave_nan_footprints() {
        let grid = Grid::new([181, 217, 181], [1.0; 3], [0.0; 3], DMat3::IDENTITY).unwrap();
        for (az, w, h) in [(30.0, 512, 512), (45.0, 512, 512), (30.0, 256, 256)] {
            let g = view(&grid, az, 0.0, w, h);
            let q = lattice_metric(&g);
            let l = ellipse_to_circle(q);
            assert!(l.is_finite(), "az {az} {w}×{h}: Q = {q}, L = {l}");
            let t =
                FootprintTable::build(&Kernel::default(), &g, &Default::default(), Antialias::Swan)
                    .unwrap();
            assert!(
                t.entries.iter().all(|v| v.is_finite() && *v >= 0.0),
                "az {az} {w}×{h}"
            );
        }
    }

    /// Every view, not a few: the footprint is finite, non-negative and keeps partition of
    /// unity over the projected sheet lattice (docs/design.md §4.1) for azimuths 0–355° in 5° steps
    /// and odd angles between,
    /// six elevations, square, wide, tall and odd image sizes, and four spacings, with and
    /// without anti-aliasing (the weights are ∫h ds / Δs, so the footprints of a constant sheet
    /// sum to the constant at every pixel).
    #[test]
    fn footprints_are_finite_and_keep_unity_at_every_angle() {
        let spacings = [[1.0; 3], [0.5; 3], [2.0 / 63.0; 3], [0.9, 1.1, 1.7]];
        let sizes = [(128, 128), (512, 512), (200, 100), (90, 161), (97, 97)];
        let mut worst = 0.0f64;
        let mut n = 0;
        for (si, spacing) in spacings.into_iter().enumerate() {
            let grid = Grid::new([64, 64, 64], spacing, [0.0; 3], DMat3::IDENTITY).unwrap();
            // Every multiple of 5° and, between them, a spread of odd angles.
            for az in (0..360).filter(|a| a % 5 == 0 || a % 7 == 3) {
                for el in [-80.0, -45.0, 0.0, 30.0, 60.0, 85.0] {
                    let (w, h) = sizes[(az + si) % sizes.len()];
                    let g = view(&grid, az as f64, el, w, h);
                    let aa = if az % 2 == 0 {
                        Antialias::Swan
                    } else {
                        Antialias::None
                    };
                    let f = FootprintFunction::new(&Kernel::default(), &g, aa);
                    let [hx, hy] = f.half_extent;
                    assert!(hx.is_finite() && hy.is_finite() && hx > 0.0 && hy > 0.0);
                    let [ju, jv] = g.in_sheet_axes.map(|a| g.jacobian.col(a));
                    let cell = (ju.x * jv.y - ju.y * jv.x).abs();
                    // Σ over the projected sheet lattice of the weights seen from one pixel:
                    // a constant sheet must reconstruct the constant.
                    let reach =
                        hx.max(hy) * ju.truncate().length().max(jv.truncate().length()) / cell;
                    let m = reach.ceil() as i32 + 1;
                    assert!(m < 400, "az {az} el {el}: lattice reach {m}");
                    let (ox, oy) = (0.37, 0.61);
                    let mut sum = 0.0;
                    for v in -m..=m {
                        for u in -m..=m {
                            let dx = u as f64 * ju.x + v as f64 * jv.x - ox;
                            let dy = u as f64 * ju.y + v as f64 * jv.y - oy;
                            let wt = f.weight(dx, dy);
                            assert!(wt.is_finite() && wt >= 0.0, "az {az} el {el} {w}×{h}");
                            sum += wt;
                        }
                    }
                    worst = worst.max((sum - 1.0).abs());
                    n += 1;
                }
            }
        }
        assert!(n > 1000, "only {n} views checked");
        eprintln!("{n} views, partition of unity within {worst:.2e}");
        assert!(worst < 0.01, "partition of unity off by {worst}");
    }

    /// Blended weights of a non-negative kernel are never negative (issue 17: X-ray of
    /// non-negative data was −0.004 at footprint edges, where the blend extrapolates), while a
    /// kernel with negative lobes keeps them.
    #[test]
    fn blended_weights_keep_the_sign_of_the_kernel() {
        let g = geometry([1.0, 1.3, 2.0], 33.0, 21.0, 1.7);
        for (kernel, negative) in [
            (Kernel::default(), false),
            (Kernel::MitchellNetravali { b: 0.0, c: 0.5 }, true),
        ] {
            let t =
                FootprintTable::build(&kernel, &g, &FootprintSettings::default(), Antialias::Swan)
                    .unwrap();
            let b = t.block();
            let mut min = f32::INFINITY;
            let mut extrapolated = 0;
            for n in 0..400 {
                let (x, y) = (
                    10.0 + (n as f32 * 0.618_034).fract(),
                    20.0 + (n as f32 * 0.414_213_5).fract(),
                );
                let loc = t.locate(x, y);
                extrapolated += usize::from(loc.fx + loc.fy > 1.0);
                for i in 0..(b.width * b.height) as usize {
                    min = min.min(loc.weight(i));
                }
            }
            assert!(extrapolated > 50, "the test must exercise extrapolation");
            if negative {
                assert!(
                    min < -1e-3,
                    "{}: negative lobes lost ({min})",
                    kernel.name()
                );
            } else {
                assert!(min >= 0.0, "{}: {min}", kernel.name());
            }
        }
    }

    /// The ellipse→circle map sends the ellipse boundary to the unit circle, with no singular
    /// angle (F-W20; the thesis needed a 0.01° fudge at 45°).
    #[test]
    fn ellipse_maps_onto_unit_circle_at_every_angle() {
        for deg in [0.0f64, 10.0, 45.0, 90.0, 135.0, 200.0] {
            let th = deg.to_radians();
            let u = DMat2::from_cols(
                DVec2::new(th.cos(), th.sin()),
                DVec2::new(-th.sin(), th.cos()),
            );
            let q = u * DMat2::from_diagonal(DVec2::new(4.0, 0.25)) * u.transpose();
            let l = ellipse_to_circle(q);
            for n in 0..360 {
                let a = (n as f64).to_radians();
                // Boundary of δᵀQδ = 1: δ = U diag(1/2, 2) (cos a, sin a).
                let d = u * DVec2::new(0.5 * a.cos(), 2.0 * a.sin());
                assert!(((l * d).length() - 1.0).abs() < 1e-12, "deg {deg}");
            }
        }
        let iso = ellipse_to_circle(DMat2::from_diagonal(DVec2::splat(9.0)));
        assert!((iso.col(0).x.abs() - 3.0).abs() < 1e-12 && iso.col(0).y.abs() < 1e-12);
    }

    /// F-W22: extents of 9 px at scale 2 and 13 px at scale 3 (2⌊s·r⌋+1), and 9×17 with a
    /// 2× spaced axis in the image plane.
    #[test]
    fn gaussian_extents_match_the_thesis() {
        let k = Kernel::default();
        let width = |h: f64| 2 * (h + 1e-9).floor() as i32 + 1;
        let f = FootprintFunction::new(&k, &geometry([1.0; 3], 0.0, 0.0, 2.0), Antialias::None);
        assert_eq!((width(f.half_extent[0]), width(f.half_extent[1])), (9, 9));
        let f = FootprintFunction::new(&k, &geometry([1.0; 3], 0.0, 0.0, 3.0), Antialias::None);
        assert_eq!(width(f.half_extent[0]), 13);
        let f = FootprintFunction::new(
            &k,
            &geometry([1.0, 2.0, 1.0], 0.0, 0.0, 2.0),
            Antialias::None,
        );
        assert_eq!((width(f.half_extent[0]), width(f.half_extent[1])), (9, 17));
    }

    /// Table sizing: phases² × block ≤ max_entries, phases ≤ max_phases; the single-point
    /// kernel has one phase.
    /// Fuzzing regression (issue 13): a spacing like `1 3e7 1`, a zoom of 1e9 or a
    /// parallel_scale of 1e-12 made footprint tables of gigabytes (or a capacity overflow).
    #[test]
    fn oversized_footprints_are_an_error() {
        let s = FootprintSettings::default();
        for (spacing, scale) in [
            ([1.0, 3e7, 1.0], 2.0),
            ([3e7, 1.0, 1.0], 2.0),
            ([1.0, 1.0, 3e7], 2.0),
            ([1.0; 3], 1e9),
            ([1.0; 3], 3.2e13),
            ([1.0; 3], 1000.0),
        ] {
            let g = geometry(spacing, 30.0, 20.0, scale);
            // (Nearest covers only the in-sheet cell, which can stay small when the long axis
            // is the sheet axis.)
            for k in [Kernel::default(), Kernel::Tent] {
                for aa in [Antialias::None, Antialias::Swan] {
                    match FootprintTable::build(&k, &g, &s, aa) {
                        Ok(t) => panic!(
                            "{} {spacing:?} ×{scale}: built a table of half extent {:?}",
                            k.name(),
                            t.half_extent
                        ),
                        Err(e) => {
                            let m = e.to_string();
                            assert!(m.contains("max_block_side") && m.contains("1024"), "{m}");
                        }
                    }
                }
            }
            // Point splats have no extent, whatever the view.
            assert!(FootprintTable::build(&Kernel::SinglePoint, &g, &s, Antialias::None).is_ok());
        }
        // Just inside the limit builds; a raised limit admits more.
        let g = geometry([1.0; 3], 0.0, 0.0, 100.0);
        let t = FootprintTable::build(&Kernel::default(), &g, &s, Antialias::None)
            .map_err(|e| e.to_string())
            .unwrap();
        assert!(t.block().width <= 1024 && t.block().height <= 1024);
        let g = geometry([1.0; 3], 30.0, 20.0, 300.0);
        let big = FootprintSettings {
            max_block_side: 4096,
            ..s
        };
        assert!(FootprintTable::build(&Kernel::default(), &g, &big, Antialias::None).is_ok());
    }

    #[test]
    fn table_resolution_rule() {
        let g = geometry([1.0; 3], 0.0, 0.0, 2.0);
        for k in [Kernel::default(), Kernel::Tent, Kernel::Nearest] {
            let t = FootprintTable::build(&k, &g, &FootprintSettings::default(), Antialias::None)
                .unwrap();
            assert!(t.entry_count() <= 1 << 17, "{}", k.name());
            assert!(
                t.phases >= 16 && t.phases <= 64,
                "{}: {}",
                k.name(),
                t.phases
            );
        }
        let t = FootprintTable::build(
            &Kernel::default(),
            &g,
            &FootprintSettings {
                max_entries: 1 << 17,
                max_phases: 9,
                ..FootprintSettings::default()
            },
            Antialias::None,
        )
        .unwrap();
        assert_eq!(t.phases, 9);
        let t = FootprintTable::build(
            &Kernel::SinglePoint,
            &g,
            &FootprintSettings::default(),
            Antialias::None,
        )
        .unwrap();
        assert_eq!(t.phases, 1);
    }

    /// A sample's blended table weights reproduce the continuous footprint at the pixel centres
    /// (F-W21) to the blend's second-order error, and row spans cover every non-zero weight.
    #[test]
    fn weights_at_pixel_centres_match_the_footprint() {
        for k in [
            Kernel::default(),
            Kernel::MitchellNetravali { b: 1.0, c: 0.0 },
        ] {
            let g = geometry([1.0, 1.3, 2.0], 20.0, 10.0, 2.0);
            let f = FootprintFunction::new(&k, &g, Antialias::None);
            let t = FootprintTable::from_function(&f, &FootprintSettings::default()).unwrap();
            let peak = f.weight(0.0, 0.0);
            for (x, y) in [(10.25f32, 7.8125f32), (3.1234, 9.87), (5.5, 5.5)] {
                let loc = t.locate(x, y);
                let b = t.block();
                for r in 0..b.height as usize {
                    for c in 0..b.width as usize {
                        let wt = loc.weight(r * b.width as usize + c) as f64;
                        let dx = (loc.x0 + c as i32) as f64 + 0.5 - x as f64;
                        let dy = (loc.y0 + r as i32) as f64 + 0.5 - y as f64;
                        let expect = f.weight(dx, dy);
                        // Near the truncation edge the footprint jumps; elsewhere it is smooth.
                        let tol =
                            if f.weight(dx + 0.05, dy) == 0.0 || f.weight(dx - 0.05, dy) == 0.0 {
                                0.01
                            } else {
                                2e-3
                            };
                        assert!(
                            (wt - expect).abs() < tol * peak,
                            "{}: {wt} vs {expect}",
                            k.name()
                        );
                        if wt != 0.0 {
                            assert!(
                                (loc.spans[r].0 as usize..loc.spans[r].1 as usize).contains(&c),
                                "{} row {r} col {c}",
                                k.name()
                            );
                        }
                    }
                }
            }
        }
    }
}
