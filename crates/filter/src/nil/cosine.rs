//! Analytic NIL maps of cosine-series textures (thesis §4-4.4–§4-4.6, eqs 4.25–4.27,
//! 4.31).
//!
//! Per axis, `𝒳^{γ,m}_{r,i} = ∫₀¹ B_i(t) cos(2π r 2^γ (m + t)) dt` is computed exactly from
//! the monomial moments `∫₀¹ tᵖ e^{iαt} dt` with `α = 2π r 2^γ` and the cell's phase — the
//! corrected form of the printed negative-level formula (A-13: no spurious "2t" in §4-4.6's `F_1`, sum
//! over `p` restored; `r = 0` gives `B̄_i`). For `γ ≥ 0` the cell is a whole number of periods
//! and the value does not depend on `m` (one cell per positive level); negative levels are
//! computed on demand. The 3-D cell is the separable product
//! `C_{abc} = S Σ T_ijk 𝒳_{ia} 𝒳_{jb} 𝒳_{kc} + offset·B̄_a B̄_b B̄_c`.
//!
//! Decision A-14: the level-0 cell is one texture period (one texture unit).

use super::NilSource;
use super::basis::{MAX_ORDER, PatchBasis};
use crate::error::{FilterError, Result};
use crate::texture::CosineTexture;
use std::f64::consts::TAU;
use std::time::Instant;

/// `[∫₀¹ tᵖ e^{iαt} dt]_{p=0..3}` as (re, im) pairs; series for small `|α|`, recurrence else.
fn exp_moments(alpha: f64) -> [(f64, f64); 4] {
    let mut out = [(0.0, 0.0); 4];
    if alpha.abs() < 1.0 {
        for (p, o) in out.iter_mut().enumerate() {
            // Σ_k (iα)^k / (k! (p + k + 1)).
            let (mut re, mut im) = (0.0, 0.0);
            let mut term = 1.0; // α^k / k!
            for k in 0..30 {
                let v = term / (p + k + 1) as f64;
                match k % 4 {
                    0 => re += v,
                    1 => im += v,
                    2 => re -= v,
                    _ => im -= v,
                }
                term *= alpha / (k + 1) as f64;
            }
            *o = (re, im);
        }
    } else {
        let (s, c) = alpha.sin_cos();
        // J_0 = (e^{iα} − 1)/(iα); J_p = (e^{iα} − p·J_{p−1})/(iα); 1/(iα) = −i/α.
        let div = |(re, im): (f64, f64)| (im / alpha, -re / alpha);
        out[0] = div((c - 1.0, s));
        for p in 1..4 {
            let prev = out[p - 1];
            out[p] = div((c - p as f64 * prev.0, s - p as f64 * prev.1));
        }
    }
    out
}

/// `∫₀¹ B_i(t) cos(2π r (x0 + h t)) dt` for `i < M`, with `x0 = 2^γ m`, `h = 2^γ`.
pub(crate) fn cos_cell_moments(basis: &PatchBasis, r: usize, x0: f64, h: f64) -> [f64; MAX_ORDER] {
    let mut out = [0.0; MAX_ORDER];
    if r == 0 {
        for (i, o) in out.iter_mut().enumerate().take(basis.order()) {
            *o = basis.mean(i);
        }
        return out;
    }
    let alpha = TAU * r as f64 * h;
    let phase = TAU * ((r as f64 * x0.rem_euclid(1.0)).rem_euclid(1.0));
    let (sp, cp) = phase.sin_cos();
    let j = exp_moments(alpha);
    // Re(e^{iφ}·J_p) = cosφ·Re J_p − sinφ·Im J_p.
    let mono: [f64; 4] = std::array::from_fn(|p| cp * j[p].0 - sp * j[p].1);
    for (i, o) in out.iter_mut().enumerate().take(basis.order()) {
        let c = basis.coefficients(i);
        *o = (0..4).map(|p| c[p] * mono[p]).sum();
    }
    out
}

/// An analytic NIL map of a [`CosineTexture`].
#[derive(Debug, Clone)]
pub struct CosineNilMap {
    basis: PatchBasis,
    texture: CosineTexture,
    gamma_max: i32,
    /// Cells of levels `0..=γ_max` (one per level, independent of the cell index).
    positive: Vec<Vec<f64>>,
    build_seconds: f64,
}

impl CosineNilMap {
    /// Builds levels `0..=gamma_max` (the thesis uses `γ_max = 10`, §4-4.6).
    pub fn build(texture: &CosineTexture, order: usize, gamma_max: i32) -> Result<Self> {
        let start = Instant::now();
        if !(0..=40).contains(&gamma_max) {
            return Err(FilterError::invalid(
                "gamma_max",
                gamma_max,
                "must be in 0..=40",
            ));
        }
        let basis = PatchBasis::new(order)?;
        let mut map = CosineNilMap {
            basis,
            texture: texture.clone(),
            gamma_max,
            positive: Vec::new(),
            build_seconds: 0.0,
        };
        let m = order;
        for g in 0..=gamma_max {
            let mut out = vec![0.0; m * m * m];
            map.compute(g, [0, 0, 0], &mut out);
            map.positive.push(out);
        }
        map.build_seconds = start.elapsed().as_secs_f64();
        Ok(map)
    }

    /// Wall-clock build time in seconds (Table 5.5).
    pub fn build_seconds(&self) -> f64 {
        self.build_seconds
    }

    /// Number of stored f64 values.
    pub fn stored_values(&self) -> usize {
        self.positive.iter().map(|v| v.len()).sum()
    }

    fn compute(&self, gamma: i32, cell: [i64; 3], out: &mut [f64]) {
        let m = self.basis.order();
        let h = 2f64.powi(gamma);
        let [ni, nj, nk] = self.texture.dims();
        let x: Vec<Vec<[f64; MAX_ORDER]>> = (0..3)
            .map(|a| {
                let n = [ni, nj, nk][a];
                (0..n)
                    .map(|r| cos_cell_moments(&self.basis, r, cell[a] as f64 * h, h))
                    .collect()
            })
            .collect();
        let coeffs = self.texture.coeffs();
        // Contract k (z), then j (y), then i (x).
        let mut a = vec![0.0; ni * nj * m]; // [i][j][c]
        for i in 0..ni {
            for j in 0..nj {
                for k in 0..nk {
                    let t = coeffs[(i * nj + j) * nk + k];
                    if t == 0.0 {
                        continue;
                    }
                    for c in 0..m {
                        a[(i * nj + j) * m + c] += t * x[2][k][c];
                    }
                }
            }
        }
        let mut b = vec![0.0; ni * m * m]; // [i][b][c]
        for i in 0..ni {
            for j in 0..nj {
                for bb in 0..m {
                    for c in 0..m {
                        b[(i * m + bb) * m + c] += x[1][j][bb] * a[(i * nj + j) * m + c];
                    }
                }
            }
        }
        let s = self.texture.scale();
        let off = self.texture.offset();
        for c in 0..m {
            for bb in 0..m {
                for aa in 0..m {
                    let mut v = 0.0;
                    for i in 0..ni {
                        v += x[0][i][aa] * b[(i * m + bb) * m + c];
                    }
                    out[(c * m + bb) * m + aa] = s * v
                        + off * self.basis.mean(aa) * self.basis.mean(bb) * self.basis.mean(c);
                }
            }
        }
    }
}

impl NilSource for CosineNilMap {
    fn basis(&self) -> &PatchBasis {
        &self.basis
    }

    fn channels(&self) -> usize {
        1
    }

    fn gamma_max(&self) -> i32 {
        self.gamma_max
    }

    fn mean(&self) -> f64 {
        use crate::texture::SolidTexture;
        self.texture.mean()
    }

    fn period(&self) -> [f64; 3] {
        [1.0; 3]
    }

    fn cell(&self, gamma: i32, cell: [i64; 3], out: &mut [f64]) -> bool {
        if gamma > self.gamma_max {
            return false;
        }
        if gamma >= 0 {
            out[..self.positive[gamma as usize].len()]
                .copy_from_slice(&self.positive[gamma as usize]);
        } else {
            self.compute(gamma, cell, out);
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::quadrature::composite_gauss_1d;
    use crate::texture::SolidTexture;
    use glam::DVec3;
    use std::f64::consts::PI;

    #[test]
    fn thesis_closed_form_cubic_pattern_f_b30() {
        let b = PatchBasis::new(4).unwrap();
        for r in 1..=8usize {
            for g in 0..=10 {
                let h = 2f64.powi(g);
                let x = cos_cell_moments(&b, r, 0.0, h);
                let v = 9.0 / (8.0 * PI * PI * (h * r as f64).powi(2));
                let expect = [v, -v, -v, v];
                for i in 0..4 {
                    assert!(
                        (x[i] - expect[i]).abs() < 1e-12,
                        "r={r} γ={g} i={i}: {} vs {}",
                        x[i],
                        expect[i]
                    );
                }
            }
        }
    }

    #[test]
    fn negative_levels_match_quadrature_f_b30() {
        for m in [1, 3, 4] {
            let b = PatchBasis::new(m).unwrap();
            for r in [1usize, 2, 5, 8] {
                for g in [-4, -2, -1] {
                    for cell in [-3i64, 0, 3, 17] {
                        let h = 2f64.powi(g);
                        let x = cos_cell_moments(&b, r, cell as f64 * h, h);
                        for i in 0..m {
                            let f = |t: f64| {
                                b.eval(i, t) * (TAU * r as f64 * h * (cell as f64 + t)).cos()
                            };
                            let q = composite_gauss_1d(&f, 0.0, 1.0, 64, 5);
                            assert!(
                                (x[i] - q).abs() < 1e-12,
                                "M={m} r={r} γ={g} m={cell} i={i}: {} vs {q}",
                                x[i]
                            );
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn cells_match_texture_quadrature() {
        let t = CosineTexture::seeded(4, 3).unwrap();
        let map = CosineNilMap::build(&t, 2, 4).unwrap();
        let mut out = vec![0.0; 8];
        for (g, cell) in [(0i32, [0i64, 0, 0]), (-1, [1, 0, 1]), (-3, [5, -2, 3])] {
            assert!(map.cell(g, cell, &mut out));
            let h = 2f64.powi(g);
            let b = map.basis;
            for idx in 0..8 {
                let (i, j, k) = (idx % 2, (idx / 2) % 2, idx / 4);
                let n = 8;
                let mut s = 0.0;
                let (xi, wq) = crate::quadrature::gauss_legendre(5);
                for pz in 0..n {
                    for py in 0..n {
                        for px in 0..n {
                            for (a, wa) in xi.iter().zip(wq) {
                                for (c, wc) in xi.iter().zip(wq) {
                                    for (d, wd) in xi.iter().zip(wq) {
                                        let tx = (px as f64 + 0.5 * (a + 1.0)) / n as f64;
                                        let ty = (py as f64 + 0.5 * (c + 1.0)) / n as f64;
                                        let tz = (pz as f64 + 0.5 * (d + 1.0)) / n as f64;
                                        let p = DVec3::new(
                                            cell[0] as f64 + tx,
                                            cell[1] as f64 + ty,
                                            cell[2] as f64 + tz,
                                        ) * h;
                                        s += wa * wc * wd / 8.0 / (n * n * n) as f64
                                            * b.eval(i, tx)
                                            * b.eval(j, ty)
                                            * b.eval(k, tz)
                                            * t.value(p);
                                    }
                                }
                            }
                        }
                    }
                }
                assert!(
                    (s - out[idx]).abs() < 1e-9,
                    "γ={g} idx={idx}: {s} vs {}",
                    out[idx]
                );
            }
        }
    }
}
