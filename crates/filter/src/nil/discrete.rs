//! NIL maps of discrete textures (thesis App.; §4-4.3, eqs 4.19–4.24).
//!
//! Levels `γ = 0..=γ_max` are pre-computed by separable contraction of the samples with per-axis
//! cell weights (A.15/A.16 for sample-and-hold, A.22/A.29 in separable form for trilinear).
//! Negative levels are computed on demand (A.17, A.30). Sizes need not be powers of two and may
//! differ per axis: the texture is periodic, so a level-`γ` cell along an axis of `n` samples
//! is one of `n / gcd(n, 2^γ)` phase classes, each exact — no invalid cells (decision A-12,
//! replacing the valid bits of ).
//!
//! With a [`TransferBasis`] the map stores `D^{γ}_{ijk,l}` (eqs 4.22, 4.30, A.33) for each
//! transfer basis function `B_l`, so a transfer function `𝒯 = Σ_l b_l B_l` can be changed
//! without rebuilding (eq 4.24). For trilinear data `B_l(T̄)` is not trilinear; the cells are
//! then integrated exactly by Gauss–Legendre with `q = ⌈(N + M − 1)/2⌉` nodes per texel and
//! axis (decision A-11).

use super::NilSource;
use super::axis::{AxisRow, AxisSampling, cell_row, contract, contract_cell};
use super::basis::PatchBasis;
use crate::error::{FilterError, Result};
use crate::quadrature::gauss_legendre;
use crate::texture::{DiscreteTexture, Reconstruction, SolidTexture};
use glam::DVec3;
use std::time::Instant;

/// A Lagrange basis over a value range for transfer functions (eq 4.19): `B_l(x)` is the
/// order-`N` patch basis evaluated at `(x − lo)/(hi − lo)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TransferBasis {
    basis: PatchBasis,
    lo: f64,
    hi: f64,
}

impl TransferBasis {
    /// `n` basis functions (1..=4) over `[lo, hi]` (texture value units, `lo < hi`).
    pub fn new(n: usize, lo: f64, hi: f64) -> Result<Self> {
        if !(lo.is_finite() && hi.is_finite() && lo < hi) {
            return Err(FilterError::invalid(
                "transfer range",
                (lo, hi),
                "needs finite lo < hi",
            ));
        }
        Ok(TransferBasis {
            basis: PatchBasis::new(n)?,
            lo,
            hi,
        })
    }

    /// Number of basis functions `N`.
    pub fn len(&self) -> usize {
        self.basis.order()
    }

    /// Always false (`N ≥ 1`).
    pub fn is_empty(&self) -> bool {
        false
    }

    /// `B_l(x)`.
    #[inline]
    pub fn eval(&self, l: usize, x: f64) -> f64 {
        self.basis.eval(l, (x - self.lo) / (self.hi - self.lo))
    }

    /// Node values `x_l` (texture value units).
    pub fn nodes(&self) -> Vec<f64> {
        self.basis
            .nodes()
            .iter()
            .map(|t| self.lo + t * (self.hi - self.lo))
            .collect()
    }

    /// Coefficients `b_l = f(x_l)`: exact for `f` in the span (polynomials of degree `< N`).
    pub fn coefficients(&self, f: impl Fn(f64) -> f64) -> Vec<f64> {
        self.nodes().into_iter().map(f).collect()
    }

    /// `𝒯(x) = Σ_l b_l B_l(x)` for coefficients `b`.
    pub fn apply(&self, b: &[f64], x: f64) -> f64 {
        b.iter()
            .enumerate()
            .map(|(l, bl)| bl * self.eval(l, x))
            .sum()
    }
}

/// Build settings for a discrete NIL map.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DiscreteNilSettings {
    /// Patch order `M` (1..=4).
    pub order: usize,
    /// Highest stored level; `None` = `⌈log₂ max(n)⌉ + 1` (cells cover the whole texture).
    pub gamma_max: Option<i32>,
    /// Optional transfer-function basis (builds `D` maps, one channel per basis function).
    pub transfer: Option<TransferBasis>,
    /// Largest number of stored values (f64) allowed.
    pub max_values: usize,
}

impl Default for DiscreteNilSettings {
    fn default() -> Self {
        DiscreteNilSettings {
            order: 4,
            gamma_max: None,
            transfer: None,
            max_values: 1 << 27,
        }
    }
}

#[derive(Debug, Clone)]
struct Level {
    phases: [usize; 3],
    /// Per channel: cells × M³.
    data: Vec<Vec<f64>>,
}

/// A pre-computed NIL pyramid of a discrete texture.
#[derive(Debug, Clone)]
pub struct DiscreteNilMap {
    basis: PatchBasis,
    texture: DiscreteTexture,
    transfer: Option<TransferBasis>,
    levels: Vec<Level>,
    gamma_max: i32,
    build_seconds: f64,
}

fn gcd(a: usize, b: usize) -> usize {
    if b == 0 { a } else { gcd(b, a % b) }
}

/// The highest level whose cells cover the whole texture: `⌈log₂ max(n)⌉ + 1`.
fn natural_gamma_max(dims: [usize; 3]) -> i32 {
    dims.iter()
        .map(|&n| (n as f64).log2().ceil() as i32)
        .max()
        .unwrap_or(0)
        + 1
}

/// Phase classes of level-`γ` cells along an axis of `n` samples.
fn phases(n: usize, gamma: i32) -> usize {
    let p = 1usize << gamma.clamp(0, 40);
    n / gcd(n, p % n)
}

impl DiscreteNilMap {
    /// The number of stored values (f64) of a map of a texture with `dims` samples, patch order
    /// `order` (M), levels `0..=gamma_max` (`None`: the natural `⌈log₂ max(n)⌉ + 1`) and
    /// `channels` channels: `Σ_γ Π_axes phases(n, γ) · M³ · channels`, what [`Self::build`]
    /// checks against [`DiscreteNilSettings::max_values`]. Odd sizes keep every phase at every
    /// level, so a texture padded to even sizes needs far fewer.
    pub fn values_needed_for(
        dims: [usize; 3],
        order: usize,
        gamma_max: Option<i32>,
        channels: usize,
    ) -> u128 {
        let gamma_max = gamma_max.unwrap_or_else(|| natural_gamma_max(dims));
        Self::values_needed(dims, order, gamma_max.clamp(0, 30), channels)
    }

    fn values_needed(dims: [usize; 3], m: usize, gamma_max: i32, channels: usize) -> u128 {
        let m3 = (m * m * m) as u128;
        (0..=gamma_max)
            .map(|g| {
                let cells: u128 = dims.iter().map(|&n| phases(n, g) as u128).product();
                cells * m3 * channels as u128
            })
            .sum()
    }

    /// Builds the pyramid (thesis Table 5.9: `O(M³ x³ log x)`).
    pub fn build(texture: &DiscreteTexture, settings: &DiscreteNilSettings) -> Result<Self> {
        let start = Instant::now();
        let basis = PatchBasis::new(settings.order)?;
        let m = basis.order();
        let dims = texture.dims();
        let gamma_max = settings
            .gamma_max
            .unwrap_or_else(|| natural_gamma_max(dims));
        if !(0..=30).contains(&gamma_max) {
            return Err(FilterError::invalid(
                "gamma_max",
                gamma_max,
                "must be in 0..=30",
            ));
        }
        let channels = settings.transfer.map_or(1, |t| t.len());
        let total = Self::values_needed(dims, m, gamma_max, channels);
        if total > settings.max_values as u128 {
            return Err(FilterError::TooLarge {
                what: "NIL map values".into(),
                value: total,
                limit: settings.max_values as u128,
            });
        }
        // Grids (per channel) and how they are sampled along each axis.
        let (grids, grid_dims, sampling): (Vec<Vec<f64>>, [usize; 3], AxisSampling) =
            match (settings.transfer, texture.reconstruction()) {
                (None, Reconstruction::SampleAndHold) => {
                    (vec![texture.data().to_vec()], dims, AxisSampling::Hold)
                }
                (None, Reconstruction::Trilinear) => {
                    (vec![texture.data().to_vec()], dims, AxisSampling::Linear)
                }
                (Some(tb), Reconstruction::SampleAndHold) => (
                    (0..tb.len())
                        .map(|l| texture.data().iter().map(|&v| tb.eval(l, v)).collect())
                        .collect(),
                    dims,
                    AxisSampling::Hold,
                ),
                (Some(tb), Reconstruction::Trilinear) => {
                    let q = (tb.len() + m).div_ceil(2);
                    let (xi, _) = gauss_legendre(q);
                    let gd = dims.map(|n| n * q);
                    let node = |idx: usize| (idx / q) as f64 + 0.5 * (xi[idx % q] + 1.0);
                    let mut values = Vec::with_capacity(gd[0] * gd[1] * gd[2]);
                    for z in 0..gd[2] {
                        for y in 0..gd[1] {
                            for x in 0..gd[0] {
                                values.push(texture.value(DVec3::new(node(x), node(y), node(z))));
                            }
                        }
                    }
                    let grids = (0..tb.len())
                        .map(|l| values.iter().map(|&v| tb.eval(l, v)).collect())
                        .collect();
                    (grids, gd, AxisSampling::Nodes(q))
                }
            };
        let mut levels = Vec::with_capacity(gamma_max as usize + 1);
        for g in 0..=gamma_max {
            let ph = dims.map(|n| phases(n, g));
            let rows: Vec<Vec<AxisRow>> = (0..3)
                .map(|a| {
                    (0..ph[a])
                        .map(|c| cell_row(&basis, sampling, dims[a], g, c as i64))
                        .collect()
                })
                .collect();
            let data = grids
                .iter()
                .map(|grid| contract(grid, grid_dims, [&rows[0], &rows[1], &rows[2]], m))
                .collect();
            levels.push(Level { phases: ph, data });
        }
        Ok(DiscreteNilMap {
            basis,
            texture: texture.clone(),
            transfer: settings.transfer,
            levels,
            gamma_max,
            build_seconds: start.elapsed().as_secs_f64(),
        })
    }

    /// Number of stored f64 values (thesis §5-6: `M³·Σ_γ Π_q phases_q(γ)` per channel).
    pub fn stored_values(&self) -> usize {
        self.levels
            .iter()
            .map(|l| l.data.iter().map(|d| d.len()).sum::<usize>())
            .sum()
    }

    /// Wall-clock build time in seconds (pre-processing cost, Table 5.5).
    pub fn build_seconds(&self) -> f64 {
        self.build_seconds
    }

    /// The transfer basis, if this is a `D` map.
    pub fn transfer(&self) -> Option<&TransferBasis> {
        self.transfer.as_ref()
    }

    /// The texture the map was built from.
    pub fn texture(&self) -> &DiscreteTexture {
        &self.texture
    }

    fn negative_cell(&self, gamma: i32, cell: [i64; 3], out: &mut [f64]) {
        let m = self.basis.order();
        let m3 = m * m * m;
        let dims = self.texture.dims();
        let tex = &self.texture;
        match (self.transfer, tex.reconstruction()) {
            (Some(tb), Reconstruction::Trilinear) => {
                // Inside one texel T̄ is trilinear: Gauss with enough nodes is exact.
                let q = (tb.len() + m).div_ceil(2);
                let (xi, wq) = gauss_legendre(q);
                let h = 2f64.powi(gamma);
                out[..m3 * tb.len()].iter_mut().for_each(|v| *v = 0.0);
                let mut bt = [[0.0; 4]; 5];
                for (row, x) in bt.iter_mut().zip(xi) {
                    for (i, v) in row.iter_mut().enumerate().take(m) {
                        *v = self.basis.eval(i, 0.5 * (x + 1.0));
                    }
                }
                for (gz, (z, wz)) in xi.iter().zip(wq).enumerate() {
                    for (gy, (y, wy)) in xi.iter().zip(wq).enumerate() {
                        for (gx, (x, wx)) in xi.iter().zip(wq).enumerate() {
                            let p = DVec3::new(
                                h * (cell[0] as f64 + 0.5 * (x + 1.0)),
                                h * (cell[1] as f64 + 0.5 * (y + 1.0)),
                                h * (cell[2] as f64 + 0.5 * (z + 1.0)),
                            );
                            let v = tex.value(p);
                            let w = 0.125 * wx * wy * wz;
                            for l in 0..tb.len() {
                                let bl = tb.eval(l, v) * w;
                                let o = &mut out[l * m3..(l + 1) * m3];
                                for k in 0..m {
                                    for j in 0..m {
                                        for i in 0..m {
                                            o[(k * m + j) * m + i] +=
                                                bl * bt[gz][k] * bt[gy][j] * bt[gx][i];
                                        }
                                    }
                                }
                            }
                        }
                    }
                }
            }
            (transfer, recon) => {
                let sampling = match recon {
                    Reconstruction::SampleAndHold => AxisSampling::Hold,
                    Reconstruction::Trilinear => AxisSampling::Linear,
                };
                let rows: Vec<AxisRow> = (0..3)
                    .map(|a| cell_row(&self.basis, sampling, dims[a], gamma, cell[a]))
                    .collect();
                let at = |s: usize, t: usize, u: usize| tex.at(s as i64, t as i64, u as i64);
                match transfer {
                    None => contract_cell([&rows[0], &rows[1], &rows[2]], m, at, out),
                    Some(tb) => {
                        for l in 0..tb.len() {
                            contract_cell(
                                [&rows[0], &rows[1], &rows[2]],
                                m,
                                |s, t, u| tb.eval(l, at(s, t, u)),
                                &mut out[l * m3..(l + 1) * m3],
                            );
                        }
                    }
                }
            }
        }
    }
}

impl NilSource for DiscreteNilMap {
    fn basis(&self) -> &PatchBasis {
        &self.basis
    }

    fn channels(&self) -> usize {
        self.transfer.map_or(1, |t| t.len())
    }

    fn gamma_max(&self) -> i32 {
        self.gamma_max
    }

    fn mean(&self) -> f64 {
        self.texture.mean()
    }

    fn period(&self) -> [f64; 3] {
        self.texture.dims().map(|n| n as f64)
    }

    fn cell(&self, gamma: i32, cell: [i64; 3], out: &mut [f64]) -> bool {
        if gamma > self.gamma_max {
            return false;
        }
        if gamma < 0 {
            self.negative_cell(gamma, cell, out);
            return true;
        }
        let m = self.basis.order();
        let m3 = m * m * m;
        let level = &self.levels[gamma as usize];
        let [px, py, pz] = level.phases;
        let w = |c: i64, p: usize| c.rem_euclid(p as i64) as usize;
        let idx = (w(cell[2], pz) * py + w(cell[1], py)) * px + w(cell[0], px);
        for (ch, data) in level.data.iter().enumerate() {
            out[ch * m3..(ch + 1) * m3].copy_from_slice(&data[idx * m3..(idx + 1) * m3]);
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::quadrature::gauss_legendre;

    /// Brute-force `∫ B_i B_j B_k · g(T̄)` over a cell, composite Gauss on texel sub-intervals.
    fn brute(
        tex: &DiscreteTexture,
        basis: &PatchBasis,
        gamma: i32,
        cell: [i64; 3],
        g: &dyn Fn(f64) -> f64,
    ) -> Vec<f64> {
        let m = basis.order();
        let h = 2f64.powi(gamma);
        let sub = (h.max(1.0) as usize) * 2; // panels per axis: aligned with texel boundaries
        let (xi, wq) = gauss_legendre(5);
        let mut pts = Vec::new();
        for p in 0..sub {
            for (x, w) in xi.iter().zip(wq) {
                pts.push((
                    (p as f64 + 0.5 * (x + 1.0)) / sub as f64,
                    0.5 * w / sub as f64,
                ));
            }
        }
        let mut out = vec![0.0; m * m * m];
        for &(tz, wz) in &pts {
            for &(ty, wy) in &pts {
                for &(tx, wx) in &pts {
                    let p = DVec3::new(
                        h * (cell[0] as f64 + tx),
                        h * (cell[1] as f64 + ty),
                        h * (cell[2] as f64 + tz),
                    );
                    let v = g(tex.value(p)) * wx * wy * wz;
                    for k in 0..m {
                        for j in 0..m {
                            for i in 0..m {
                                out[(k * m + j) * m + i] +=
                                    v * basis.eval(k, tz) * basis.eval(j, ty) * basis.eval(i, tx);
                            }
                        }
                    }
                }
            }
        }
        out
    }

    fn tex(recon: Reconstruction) -> DiscreteTexture {
        DiscreteTexture::from_fn([8, 6, 5], recon, |i, j, k| {
            ((i * 37 + j * 11 + k * 7) % 13) as f64 / 12.0
        })
        .unwrap()
    }

    #[test]
    fn cells_match_brute_force_f_b18_f_b19_f_b24_f_b32() {
        for recon in [Reconstruction::SampleAndHold, Reconstruction::Trilinear] {
            let t = tex(recon);
            for order in [1, 2, 4] {
                let map = DiscreteNilMap::build(
                    &t,
                    &DiscreteNilSettings {
                        order,
                        ..Default::default()
                    },
                )
                .unwrap();
                let m3 = order * order * order;
                let mut out = vec![0.0; m3];
                for (gamma, cell) in [
                    (0, [3, 2, 4]),
                    (1, [1, 2, 0]),
                    (2, [1, 1, 1]),
                    (3, [0, -1, 2]),
                    (-1, [5, 7, 3]),
                    (-2, [9, 3, 17]),
                ] {
                    assert!(map.cell(gamma, cell, &mut out));
                    let b = brute(&t, &map.basis, gamma, cell, &|v| v);
                    for (x, y) in out.iter().zip(&b) {
                        assert!(
                            (x - y).abs() < 1e-9,
                            "{recon:?} M={order} γ={gamma} {cell:?}: {x} vs {y}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn top_level_constant_is_mean_and_memory_f_b20() {
        let t = DiscreteTexture::from_fn([8, 8, 8], Reconstruction::SampleAndHold, |i, j, k| {
            (i + 2 * j + 3 * k) as f64
        })
        .unwrap();
        let map = DiscreteNilMap::build(
            &t,
            &DiscreteNilSettings {
                order: 1,
                gamma_max: Some(3),
                ..Default::default()
            },
        )
        .unwrap();
        let mut out = [0.0];
        assert!(map.cell(3, [0, 0, 0], &mut out));
        assert!((out[0] - t.mean()).abs() < 1e-12);
        assert_eq!(map.stored_values(), 512 + 64 + 8 + 1);
        let map4 = DiscreteNilMap::build(
            &t,
            &DiscreteNilSettings {
                order: 4,
                gamma_max: Some(3),
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(map4.stored_values(), 64 * (512 + 64 + 8 + 1));
    }

    #[test]
    fn transfer_d_maps_match_brute_force_f_b31() {
        for recon in [Reconstruction::SampleAndHold, Reconstruction::Trilinear] {
            let t = tex(recon);
            let tb = TransferBasis::new(3, 0.0, 1.0).unwrap();
            let map = DiscreteNilMap::build(
                &t,
                &DiscreteNilSettings {
                    order: 2,
                    transfer: Some(tb),
                    ..Default::default()
                },
            )
            .unwrap();
            let mut out = vec![0.0; 8 * 3];
            for (gamma, cell) in [(0, [3, 2, 4]), (2, [1, 1, 1]), (-1, [5, 7, 3])] {
                assert!(map.cell(gamma, cell, &mut out));
                for l in 0..3 {
                    let b = brute(&t, &map.basis, gamma, cell, &|v| tb.eval(l, v));
                    for (x, y) in out[l * 8..(l + 1) * 8].iter().zip(&b) {
                        assert!(
                            (x - y).abs() < 1e-9,
                            "{recon:?} l={l} γ={gamma}: {x} vs {y}"
                        );
                    }
                }
            }
        }
    }
}
