//! 1-D NIL maps (thesis §4-4, eqs 4.1–4.9, App. A eqs A.1–A.4, Figs 4.17–4.22).
//!
//! The 1-D pyramid of a periodic sampled signal (sample-and-hold or linear) or of a cosine
//! series, binary hierarchies from trigger points, and the normalised level-weighted
//! evaluation. This is the setting of the thesis's level-weighting example (§4-4.2, Fig 4.22),
//! used by the tests to show why the printed weight `2^{γ_max−γ}` is wrong.

use super::axis::{AxisSampling, cell_row};
use super::basis::{MAX_ORDER, PatchBasis};
use super::cosine::cos_cell_moments;
use super::eval::LevelWeighting;
use crate::error::{FilterError, Result};
use crate::texture::Reconstruction;

#[derive(Debug, Clone)]
enum Signal {
    Discrete {
        samples: Vec<f64>,
        sampling: AxisSampling,
    },
    Cosine {
        coeffs: Vec<f64>,
        offset: f64,
    },
}

/// A 1-D NIL map: levels `0..=γ_max` stored, negative levels on demand.
#[derive(Debug, Clone)]
pub struct NilMap1d {
    basis: PatchBasis,
    signal: Signal,
    gamma_max: i32,
    /// Per level: phase classes × M moments.
    levels: Vec<Vec<[f64; MAX_ORDER]>>,
}

impl NilMap1d {
    /// The pyramid of a periodic signal of `samples` (texel `s` at `[s, s+1)` or, for linear
    /// reconstruction, sample `s` at the point `s`).
    pub fn discrete(
        samples: &[f64],
        recon: Reconstruction,
        order: usize,
        gamma_max: i32,
    ) -> Result<Self> {
        if samples.is_empty() || samples.iter().any(|v| !v.is_finite()) {
            return Err(FilterError::invalid(
                "samples",
                samples.len(),
                "need at least one finite sample",
            ));
        }
        let sampling = match recon {
            Reconstruction::SampleAndHold => AxisSampling::Hold,
            Reconstruction::Trilinear => AxisSampling::Linear,
        };
        Self::build(
            Signal::Discrete {
                samples: samples.to_vec(),
                sampling,
            },
            order,
            gamma_max,
        )
    }

    /// The analytic pyramid of `offset + Σ_r coeffs[r]·cos(2π r x)` (unit period).
    pub fn cosine(coeffs: &[f64], offset: f64, order: usize, gamma_max: i32) -> Result<Self> {
        if coeffs.iter().any(|v| !v.is_finite()) || !offset.is_finite() {
            return Err(FilterError::invalid(
                "coeffs",
                coeffs.len(),
                "must be finite",
            ));
        }
        Self::build(
            Signal::Cosine {
                coeffs: coeffs.to_vec(),
                offset,
            },
            order,
            gamma_max,
        )
    }

    fn build(signal: Signal, order: usize, gamma_max: i32) -> Result<Self> {
        if !(0..=30).contains(&gamma_max) {
            return Err(FilterError::invalid(
                "gamma_max",
                gamma_max,
                "must be in 0..=30",
            ));
        }
        let basis = PatchBasis::new(order)?;
        let mut map = NilMap1d {
            basis,
            signal,
            gamma_max,
            levels: Vec::new(),
        };
        for g in 0..=gamma_max {
            let n = map.phases(g);
            let level = (0..n as i64).map(|m| map.compute(g, m)).collect();
            map.levels.push(level);
        }
        Ok(map)
    }

    fn phases(&self, gamma: i32) -> usize {
        match &self.signal {
            Signal::Discrete { samples, .. } => {
                let n = samples.len();
                let p = (1usize << gamma.clamp(0, 40)) % n;
                let mut a = n;
                let mut b = p;
                while b != 0 {
                    (a, b) = (b, a % b);
                }
                n / a
            }
            Signal::Cosine { .. } => 1,
        }
    }

    fn compute(&self, gamma: i32, m: i64) -> [f64; MAX_ORDER] {
        let mut out = [0.0; MAX_ORDER];
        match &self.signal {
            Signal::Discrete { samples, sampling } => {
                for (s, w) in cell_row(&self.basis, *sampling, samples.len(), gamma, m) {
                    for i in 0..MAX_ORDER {
                        out[i] += w[i] * samples[s];
                    }
                }
            }
            Signal::Cosine { coeffs, offset } => {
                let h = 2f64.powi(gamma);
                for (r, a) in coeffs.iter().enumerate() {
                    let x = cos_cell_moments(&self.basis, r, m as f64 * h, h);
                    for i in 0..MAX_ORDER {
                        out[i] += a * x[i];
                    }
                }
                for (i, o) in out.iter_mut().enumerate().take(self.basis.order()) {
                    *o += offset * self.basis.mean(i);
                }
            }
        }
        out
    }

    /// The basis.
    pub fn basis(&self) -> &PatchBasis {
        &self.basis
    }

    /// Highest stored level.
    pub fn gamma_max(&self) -> i32 {
        self.gamma_max
    }

    /// Moments `C^{γ,m}_i = ∫₀¹ B_i(t) T(2^γ(m + t)) dt` (eq 4.9); `None` above `γ_max`.
    pub fn cell(&self, gamma: i32, m: i64) -> Option<[f64; MAX_ORDER]> {
        if gamma > self.gamma_max {
            None
        } else if gamma < 0 {
            Some(self.compute(gamma, m))
        } else {
            let level = &self.levels[gamma as usize];
            Some(level[m.rem_euclid(level.len() as i64) as usize])
        }
    }
}

/// A 1-D cell `(γ, m)` covering `[2^γ m, 2^γ (m+1))`.
pub type Cell1d = (i32, i64);

/// Smallest cell (level in `gamma_min..=gamma_max`) holding all points.
pub fn enclosing_cell_1d(points: &[f64], gamma_min: i32, gamma_max: i32) -> Option<Cell1d> {
    let lo = points.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = points.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if !lo.is_finite() || !hi.is_finite() {
        return None;
    }
    (gamma_min..=gamma_max).find_map(|g| {
        let h = 2f64.powi(g);
        let (a, b) = ((lo / h).floor() as i64, (hi / h).floor() as i64);
        (a == b).then_some((g, a))
    })
}

/// Binary version of Fig 4.19.
pub fn find_hierarchy_1d(
    points: &[f64],
    root: Cell1d,
    tol: usize,
    gamma_min: i32,
    out: &mut Vec<Cell1d>,
) {
    let (g, m) = root;
    let h = 2f64.powi(g);
    let inside: Vec<f64> = points
        .iter()
        .copied()
        .filter(|p| (p / h).floor() as i64 == m)
        .collect();
    if inside.len() <= tol || g <= gamma_min {
        out.push(root);
        return;
    }
    for c in 0..2 {
        find_hierarchy_1d(&inside, (g - 1, 2 * m + c), tol, gamma_min, out);
    }
}

/// Normalised, level-weighted evaluation over explicit cells (eqs 4.8, 4.16; §4-4.2):
/// `Σ w Σ b_i C_i / Σ w Σ b_i B̄_i` with control points `b_i = filter(node)`.
pub fn evaluate_1d(
    map: &NilMap1d,
    cells: &[Cell1d],
    filter: &dyn Fn(f64) -> f64,
    weighting: LevelWeighting,
) -> Option<f64> {
    let b = map.basis();
    let (mut num, mut den) = (0.0, 0.0);
    for &(g, m) in cells {
        let h = 2f64.powi(g);
        let c = map.cell(g, m)?;
        let w = match weighting {
            LevelWeighting::CellVolume => h,
            LevelWeighting::Printed => 2f64.powi(map.gamma_max() - g),
            LevelWeighting::Unweighted => 1.0,
        };
        for (i, &node) in b.nodes().iter().enumerate() {
            let f = filter(h * (m as f64 + node));
            num += w * f * c[i];
            den += w * f * b.mean(i);
        }
    }
    (den.abs() > 0.0).then_some(num / den)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::quadrature::composite_gauss_1d;

    /// Thesis §4-4.2 / Fig 4.22: a half-0, half-1 texture, one level-2 cell over the zero half
    /// and two level-1 cells over the one half. A box filter must return ½.
    #[test]
    fn level_weighting_step_example_shows_printed_form_is_wrong() {
        let t = [0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0];
        let map = NilMap1d::discrete(&t, Reconstruction::SampleAndHold, 1, 3).unwrap();
        let cells = [(2, 0), (1, 2), (1, 3)];
        let one = |_x: f64| 1.0;
        let corrected = evaluate_1d(&map, &cells, &one, LevelWeighting::CellVolume).unwrap();
        let printed = evaluate_1d(&map, &cells, &one, LevelWeighting::Printed).unwrap();
        let unweighted = evaluate_1d(&map, &cells, &one, LevelWeighting::Unweighted).unwrap();
        assert!((corrected - 0.5).abs() < 1e-15);
        // Printed 2^{γmax−γ}: weights 2 (level 2) and 4 (level 1) → 8/10.
        assert!((printed - 0.8).abs() < 1e-15, "{printed}");
        // Unweighted: 2/3.
        assert!((unweighted - 2.0 / 3.0).abs() < 1e-15);
    }

    /// With the corrected weight, a filter that is a polynomial patch on every cell gives the
    /// exact filtered integral of the reconstructed signal, even over mixed levels (A-1;
    /// thesis §4-4.2); the printed weight does not.
    #[test]
    fn corrected_weighting_is_exact_over_mixed_levels() {
        let samples: Vec<f64> = (0..16).map(|i| ((i * 7) % 5) as f64 / 4.0).collect();
        let map = NilMap1d::discrete(&samples, Reconstruction::Trilinear, 4, 5).unwrap();
        let cells = [(2, 0), (3, 1), (1, 2), (0, 6), (0, 7), (-1, 0), (-1, 1)];
        // Cells tile [0, 16) minus nothing? (2,0)=[0,4), (1,2)=[4,6), (0,6)=[6,7), (0,7)=[7,8), (3,1)=[8,16).
        let cells = &cells[..5];
        let f = |x: f64| 1.0 + 0.3 * x - 0.01 * x * x + 0.0004 * x * x * x; // cubic: exact in each patch
        let tbar = |x: f64| {
            let s = x.floor();
            let i = s as usize % 16;
            let fr = x - s;
            samples[i] * (1.0 - fr) + samples[(i + 1) % 16] * fr
        };
        let num = composite_gauss_1d(&|x| f(x) * tbar(x), 0.0, 16.0, 16, 5);
        let den = composite_gauss_1d(&f, 0.0, 16.0, 16, 5);
        let exact = num / den;
        let corrected = evaluate_1d(&map, cells, &f, LevelWeighting::CellVolume).unwrap();
        let printed = evaluate_1d(&map, cells, &f, LevelWeighting::Printed).unwrap();
        assert!((corrected - exact).abs() < 1e-12, "{corrected} vs {exact}");
        assert!(
            (printed - exact).abs() > 1e-3,
            "printed {printed} vs {exact}"
        );
    }

    #[test]
    fn cosine_1d_and_negative_levels() {
        let map = NilMap1d::cosine(&[0.0, 0.3, 0.0, 0.2], 0.5, 3, 10).unwrap();
        for (g, m) in [(0, 5i64), (-2, 3), (-3, -7), (4, 1)] {
            let c = map.cell(g, m).unwrap();
            let h = 2f64.powi(g);
            for i in 0..3 {
                let f = |t: f64| {
                    let x = h * (m as f64 + t);
                    map.basis().eval(i, t)
                        * (0.5
                            + 0.3 * (std::f64::consts::TAU * x).cos()
                            + 0.2 * (std::f64::consts::TAU * 3.0 * x).cos())
                };
                let q = composite_gauss_1d(&f, 0.0, 1.0, 1024, 5);
                assert!(
                    (c[i] - q).abs() < 1e-10,
                    "γ={g} m={m} i={i}: {} vs {q}",
                    c[i]
                );
            }
        }
        let pts: Vec<f64> = (0..8).map(|k| 0.2 + 0.05 * k as f64).collect();
        let root = enclosing_cell_1d(&pts, -6, 10).unwrap();
        let mut cells = Vec::new();
        find_hierarchy_1d(&pts, root, 2, -6, &mut cells);
        let total: f64 = cells.iter().map(|c| 2f64.powi(c.0)).sum();
        assert!((total - 2f64.powi(root.0)).abs() < 1e-12);
    }
}
