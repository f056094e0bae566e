//! Trigger points, approximating hierarchies and normalised, level-weighted NIL evaluation
//! (thesis §4-4, Fig 4.19, eqs 4.13–4.16, 4.24, 4.32 corrected).

use super::NilSource;
use crate::error::{FilterError, Result};
use crate::filters::FilterKind;
use crate::region::OrientedBox;
use glam::DVec3;

/// How cells of different levels are weighted (thesis §4-4.2, eq 4.32).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum LevelWeighting {
    /// Corrected (open point A-1; thesis §4-4.2, Fig 4.22): weight = cell volume `2^{3γ}`, so that
    /// `Σ_cells 2^{3γ} Σ b·C` is the exact integral of the patch-approximated filter times the
    /// texture. Default.
    CellVolume,
    /// As printed: `2^{γ_max − γ}` — the *inverse* of the worked example, and a 1-D factor.
    /// Kept only to demonstrate (in tests) why it is wrong.
    Printed,
    /// No weighting: every cell counts equally (the §4-4.2 counter-example).
    Unweighted,
}

/// Settings of a NIL evaluation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NilSettings {
    /// Trigger points per axis of the filter region (`N_t = n³`; thesis Chapter 5 uses 5).
    pub triggers_per_axis: usize,
    /// Subdivision tolerance: a cell holding at most `tol` triggers is not subdivided.
    pub tolerance: usize,
    /// Lowest level `γ_min` (may be negative: sub-texel / sub-period cells; decision A-19).
    pub gamma_min: i32,
    /// Level weighting.
    pub weighting: LevelWeighting,
    /// Scale-factor guard (decision A-4): if `Σ w b·B̄ ≤ guard · Σ w |b|·B̄`, the evaluation is
    /// reported as collapsed and the caller falls back (to a point sample in
    /// [`crate::render`]).
    pub guard: f64,
}

impl Default for NilSettings {
    fn default() -> Self {
        NilSettings {
            triggers_per_axis: 5,
            tolerance: 5,
            gamma_min: -8,
            weighting: LevelWeighting::CellVolume,
            guard: 1e-3,
        }
    }
}

impl NilSettings {
    /// Validates the settings.
    pub fn validate(&self) -> Result<()> {
        if !(1..=64).contains(&self.triggers_per_axis) {
            return Err(FilterError::invalid(
                "triggers_per_axis",
                self.triggers_per_axis,
                "must be in 1..=64",
            ));
        }
        if !(-40..=40).contains(&self.gamma_min) {
            return Err(FilterError::invalid(
                "gamma_min",
                self.gamma_min,
                "must be in -40..=40",
            ));
        }
        if !(self.guard.is_finite() && self.guard >= 0.0 && self.guard < 1.0) {
            return Err(FilterError::invalid(
                "guard",
                self.guard,
                "must be in [0, 1)",
            ));
        }
        Ok(())
    }
}

/// `n³` trigger points uniformly (cell-centred) in a box (thesis §4-4.8; open point A-3).
pub fn box_triggers(region: &OrientedBox, n: usize) -> Vec<DVec3> {
    let c = |k: usize| -1.0 + (2 * k + 1) as f64 / n as f64;
    let mut out = Vec::with_capacity(n * n * n);
    for a in 0..n {
        for b in 0..n {
            for d in 0..n {
                out.push(region.point(c(a), c(b), c(d)));
            }
        }
    }
    out
}

/// A NIL cell: level `γ` and integer index `m` (covers `[2^γ m, 2^γ (m+1))` per axis).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Cell {
    /// Level `γ`.
    pub gamma: i32,
    /// Index per axis.
    pub index: [i64; 3],
}

impl Cell {
    /// Side length `2^γ`, texture units.
    pub fn size(&self) -> f64 {
        2f64.powi(self.gamma)
    }
}

fn cell_of(p: DVec3, gamma: i32) -> [i64; 3] {
    let h = 2f64.powi(gamma);
    [
        (p.x / h).floor() as i64,
        (p.y / h).floor() as i64,
        (p.z / h).floor() as i64,
    ]
}

/// The smallest cell of level `≥ gamma_min` enclosing all points (ties on boundaries go to the
/// upper cell: cells are half-open). `None` if the points are empty, not finite, or need a
/// level above `gamma_max`.
pub fn enclosing_cell(points: &[DVec3], gamma_min: i32, gamma_max: i32) -> Option<Cell> {
    let first = *points.first()?;
    let (mut lo, mut hi) = (first, first);
    for p in points {
        lo = lo.min(*p);
        hi = hi.max(*p);
    }
    if !lo.is_finite() || !hi.is_finite() {
        return None;
    }
    (gamma_min..=gamma_max).find_map(|g| {
        let (a, b) = (cell_of(lo, g), cell_of(hi, g));
        (a == b).then_some(Cell { gamma: g, index: a })
    })
}

/// Fig 4.19: subdivide while a cell holds more than `tol` triggers and is above `γ_min`.
/// Children with no triggers are kept, so the output partitions the root.
pub fn find_hierarchy(
    points: &[DVec3],
    root: Cell,
    tol: usize,
    gamma_min: i32,
    out: &mut Vec<Cell>,
) {
    let mut idx: Vec<usize> = (0..points.len()).collect();
    recurse(points, &mut idx, root, tol, gamma_min, &mut |c, _| {
        out.push(c)
    });
}

/// [`find_hierarchy`] that also reports how many triggers each cell holds.
pub fn find_hierarchy_counted(
    points: &[DVec3],
    root: Cell,
    tol: usize,
    gamma_min: i32,
    out: &mut Vec<(Cell, usize)>,
) {
    let mut idx: Vec<usize> = (0..points.len()).collect();
    recurse(points, &mut idx, root, tol, gamma_min, &mut |c, n| {
        out.push((c, n))
    });
}

fn recurse(
    points: &[DVec3],
    idx: &mut [usize],
    cell: Cell,
    tol: usize,
    gamma_min: i32,
    out: &mut dyn FnMut(Cell, usize),
) {
    if idx.len() <= tol || cell.gamma <= gamma_min {
        out(cell, idx.len());
        return;
    }
    let g = cell.gamma - 1;
    let child_of = |p: DVec3| {
        let c = cell_of(p, g);
        ((c[0] - 2 * cell.index[0])
            + 2 * (c[1] - 2 * cell.index[1])
            + 4 * (c[2] - 2 * cell.index[2]))
            .clamp(0, 7) as usize
    };
    // Partition indices by child (stable counting sort).
    let mut counts = [0usize; 9];
    for &i in idx.iter() {
        counts[child_of(points[i]) + 1] += 1;
    }
    for c in 1..9 {
        counts[c] += counts[c - 1];
    }
    let mut sorted = vec![0usize; idx.len()];
    let mut pos = counts;
    for &i in idx.iter() {
        let c = child_of(points[i]);
        sorted[pos[c]] = i;
        pos[c] += 1;
    }
    idx.copy_from_slice(&sorted);
    for c in 0..8 {
        let child = Cell {
            gamma: g,
            index: [
                2 * cell.index[0] + (c & 1) as i64,
                2 * cell.index[1] + ((c >> 1) & 1) as i64,
                2 * cell.index[2] + (c >> 2) as i64,
            ],
        };
        let (a, b) = (counts[c], counts[c + 1]);
        recurse(points, &mut idx[a..b], child, tol, gamma_min, out);
    }
}

/// The outcome of a NIL evaluation.
#[derive(Debug, Clone, PartialEq)]
pub struct NilResult {
    /// Normalised value per channel: `Σ w Σ b·C_ch / Σ w Σ b·B̄` (eq 4.16). For `D` maps apply
    /// the transfer coefficients with [`NilResult::apply_transfer`].
    pub channels: Vec<f64>,
    /// Number of patches in the hierarchy.
    pub patches: usize,
    /// Level of the hierarchy root, if one was found.
    pub root_level: Option<i32>,
    /// True if the scale factor collapsed (or no root within `γ_max`): `channels` then hold
    /// the texture mean and the caller should fall back (decision A-4).
    pub collapsed: bool,
}

impl NilResult {
    /// `I_β = Σ_l b_βl I_l` (eq 4.24): the filtered value of transfer function `b` from a `D`
    /// map, without rebuilding.
    pub fn apply_transfer(&self, b: &[f64]) -> f64 {
        self.channels.iter().zip(b).map(|(c, w)| c * w).sum()
    }

    /// The first channel (the filtered texture value of a plain map).
    pub fn value(&self) -> f64 {
        self.channels[0]
    }
}

/// NIL evaluation of a [`FilterKind`] over a box region: `N_t = n³` triggers uniform in the
/// box (§4-4.8), filter weights from the box's local coordinates (zero outside the box).
pub fn nil_filter_box(
    source: &dyn NilSource,
    region: &OrientedBox,
    filter: FilterKind,
    settings: &NilSettings,
    scratch: &mut NilScratch,
) -> NilResult {
    let triggers = box_triggers(region, settings.triggers_per_axis);
    let f = |p: DVec3| {
        let l = region.local(p);
        filter.weight(l.x, l.y, l.z)
    };
    nil_filter_with(source, &triggers, &f, settings, scratch)
}

/// Reusable buffers for [`nil_filter_with`].
#[derive(Debug, Default, Clone)]
pub struct NilScratch {
    cells: Vec<Cell>,
    moments: Vec<f64>,
}

/// Evaluates the filter `filter(p)` (texture-space point → weight) approximated by NIL patches
/// over the hierarchy the triggers induce (thesis §4-4, Appendix B loop).
pub fn nil_filter(
    source: &dyn NilSource,
    triggers: &[DVec3],
    filter: &dyn Fn(DVec3) -> f64,
    settings: &NilSettings,
) -> NilResult {
    nil_filter_with(
        source,
        triggers,
        filter,
        settings,
        &mut NilScratch::default(),
    )
}

/// [`nil_filter`] with caller-provided scratch buffers.
pub fn nil_filter_with(
    source: &dyn NilSource,
    triggers: &[DVec3],
    filter: &dyn Fn(DVec3) -> f64,
    settings: &NilSettings,
    scratch: &mut NilScratch,
) -> NilResult {
    let channels = source.channels();
    let collapsed = |root_level, patches| NilResult {
        channels: vec![source.mean(); channels],
        patches,
        root_level,
        collapsed: true,
    };
    let gmax = source.gamma_max();
    // Decision A-3: the texture is periodic, so the triggers (and the filter) may be moved by
    // whole periods; this avoids huge roots for footprints straddling a dyadic boundary such
    // as the origin (no cell contains both signs of a coordinate).
    let direct = enclosing_cell(triggers, settings.gamma_min, gmax);
    let shift = match triggers.iter().copied().reduce(DVec3::min) {
        Some(lo) if lo.is_finite() => {
            let p = DVec3::from(source.period());
            -(lo / p).floor() * p
        }
        _ => DVec3::ZERO,
    };
    let shifted: Vec<DVec3>;
    let (root, shift) = if shift != DVec3::ZERO {
        shifted = triggers.iter().map(|t| *t + shift).collect();
        match (direct, enclosing_cell(&shifted, settings.gamma_min, gmax)) {
            (Some(d), Some(s)) if s.gamma < d.gamma => (Some(s), shift),
            (None, Some(s)) => (Some(s), shift),
            (d, _) => (d, DVec3::ZERO),
        }
    } else {
        (direct, DVec3::ZERO)
    };
    let Some(root) = root else {
        return collapsed(None, 0);
    };
    scratch.cells.clear();
    if shift == DVec3::ZERO {
        find_hierarchy(
            triggers,
            root,
            settings.tolerance,
            settings.gamma_min,
            &mut scratch.cells,
        );
    } else {
        let moved: Vec<DVec3> = triggers.iter().map(|t| *t + shift).collect();
        find_hierarchy(
            &moved,
            root,
            settings.tolerance,
            settings.gamma_min,
            &mut scratch.cells,
        );
    }
    let moved_filter = |p: DVec3| filter(p - shift);
    evaluate_cells(
        source,
        &scratch.cells,
        &moved_filter,
        settings.weighting,
        settings.guard,
        &mut scratch.moments,
    )
    .map(|mut r| {
        r.root_level = Some(root.gamma);
        r
    })
    .unwrap_or_else(|| collapsed(Some(root.gamma), scratch.cells.len()))
}

/// Evaluates explicit cells (used by [`nil_filter`] and by tests that build hierarchies by
/// hand). `None` if a cell is unavailable or the scale factor collapses.
pub fn evaluate_cells(
    source: &dyn NilSource,
    cells: &[Cell],
    filter: &dyn Fn(DVec3) -> f64,
    weighting: LevelWeighting,
    guard: f64,
    moments: &mut Vec<f64>,
) -> Option<NilResult> {
    let basis = *source.basis();
    let m = basis.order();
    let m3 = m * m * m;
    let channels = source.channels();
    moments.resize(m3 * channels, 0.0);
    let nodes = basis.nodes();
    let mean: Vec<f64> = (0..m).map(|i| basis.mean(i)).collect();
    let mut num = vec![0.0; channels];
    let (mut den, mut den_abs) = (0.0, 0.0);
    let gmax = source.gamma_max();
    let mut b = [0.0; 64];
    for cell in cells {
        let h = cell.size();
        // Control points: the filter at the Lagrange nodes (decision A-2).
        let mut any = false;
        let base = DVec3::new(
            cell.index[0] as f64,
            cell.index[1] as f64,
            cell.index[2] as f64,
        );
        for k in 0..m {
            for j in 0..m {
                for i in 0..m {
                    let p = (base + DVec3::new(nodes[i], nodes[j], nodes[k])) * h;
                    let v = filter(p);
                    any |= v != 0.0;
                    b[(k * m + j) * m + i] = v;
                }
            }
        }
        if !any {
            continue;
        }
        if !source.cell(cell.gamma, cell.index, moments) {
            return None;
        }
        let w = match weighting {
            LevelWeighting::CellVolume => h * h * h,
            LevelWeighting::Printed => 2f64.powi(gmax - cell.gamma),
            LevelWeighting::Unweighted => 1.0,
        };
        for k in 0..m {
            for j in 0..m {
                for i in 0..m {
                    let q = (k * m + j) * m + i;
                    let bb = mean[i] * mean[j] * mean[k];
                    den += w * b[q] * bb;
                    den_abs += w * b[q].abs() * bb.abs();
                }
            }
        }
        for (ch, n) in num.iter_mut().enumerate() {
            let c = &moments[ch * m3..(ch + 1) * m3];
            let s: f64 = b[..m3].iter().zip(c).map(|(x, y)| x * y).sum();
            *n += w * s;
        }
    }
    if den.is_nan() || den <= guard * den_abs || den <= 0.0 {
        return None;
    }
    Some(NilResult {
        channels: num.iter().map(|n| n / den).collect(),
        patches: cells.len(),
        root_level: None,
        collapsed: false,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nil::{CosineNilMap, DiscreteNilMap, DiscreteNilSettings};
    use crate::texture::{
        CosineTexture, DiscreteTexture, Reconstruction, SolidTexture, SplitMix64,
    };

    fn random_points(n: usize, seed: u64, scale: f64) -> Vec<DVec3> {
        let mut r = SplitMix64(seed);
        (0..n)
            .map(|_| {
                DVec3::new(r.next_f64(), r.next_f64(), r.next_f64()) * scale + DVec3::splat(3.1)
            })
            .collect()
    }

    #[test]
    fn hierarchy_partitions_root_f_b21() {
        for (tol, seed) in [(0usize, 1u64), (2, 2), (5, 3), (200, 4)] {
            let pts = random_points(125, seed, 0.7);
            let root = enclosing_cell(&pts, -6, 10).unwrap();
            let mut cells = Vec::new();
            find_hierarchy(&pts, root, tol, -6, &mut cells);
            // Volumes sum to the root's, and cells are disjoint (each point in exactly one).
            let vol: f64 = cells.iter().map(|c| c.size().powi(3)).sum();
            assert!((vol - root.size().powi(3)).abs() < 1e-9 * root.size().powi(3));
            for p in &pts {
                let n = cells
                    .iter()
                    .filter(|c| cell_of(*p, c.gamma) == c.index)
                    .count();
                assert_eq!(n, 1);
            }
            for c in &cells {
                let k = pts
                    .iter()
                    .filter(|p| cell_of(**p, c.gamma) == c.index)
                    .count();
                assert!(k <= tol || c.gamma == -6);
            }
            let bound = 7 * (root.gamma + 6) as usize * 125 / (tol + 1) + 1;
            assert!(cells.len() <= bound.max(1));
            if tol >= 125 {
                assert_eq!(cells.len(), 1);
            }
        }
    }

    #[test]
    fn constant_texture_is_reproduced_exactly() {
        let t =
            DiscreteTexture::from_fn([6, 5, 7], Reconstruction::Trilinear, |_, _, _| 0.42).unwrap();
        let region = OrientedBox {
            center: DVec3::new(2.3, 1.7, 3.2),
            axes: [
                DVec3::new(1.2, 0.4, 0.0),
                DVec3::new(-0.1, 0.3, 0.0),
                DVec3::new(0.0, 0.0, 0.05),
            ],
        };
        let trig = box_triggers(&region, 5);
        let f = |p: DVec3| {
            let l = region.local(p);
            if l.abs().max_element() > 1.0 {
                0.0
            } else {
                (-2.0 * (l.x * l.x + l.y * l.y)).exp()
            }
        };
        for order in 1..=4 {
            let map = DiscreteNilMap::build(
                &t,
                &DiscreteNilSettings {
                    order,
                    ..Default::default()
                },
            )
            .unwrap();
            for tol in [0, 2, 10] {
                let s = NilSettings {
                    tolerance: tol,
                    gamma_min: -4,
                    ..Default::default()
                };
                let r = nil_filter(&map, &trig, &f, &s);
                assert!(!r.collapsed);
                assert!(
                    (r.value() - 0.42).abs() < 1e-12,
                    "M={order} tol={tol}: {}",
                    r.value()
                );
            }
        }
        // Cosine map of a constant texture (all coefficients zero).
        let c = CosineTexture::new([2, 2, 2], vec![0.0; 8], 1.0, 0.7).unwrap();
        let map = CosineNilMap::build(&c, 3, 10).unwrap();
        let r = nil_filter(&map, &trig, &f, &NilSettings::default());
        assert!((r.value() - 0.7).abs() < 1e-12);
        assert!((c.mean() - 0.7).abs() < 1e-15);
    }
}
