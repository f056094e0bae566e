//! Patch bases: Lagrange interpolating polynomials on `[0, 1]` (thesis §4-4.5, eq 4.28).
//!
//! Nodes (decision A-2): `M = 1` the cell centre ½; `M = 2` {0, 1}; `M = 3` {0, ½, 1};
//! `M = 4` {0, ⅓, ⅔, 1}. Control points are filter values at the nodes.

use crate::error::{FilterError, Result};

/// Largest supported order (tricubic).
pub const MAX_ORDER: usize = 4;

/// A Lagrange patch basis of order `M` (number of basis functions per axis, 1..=4).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PatchBasis {
    m: usize,
    /// Monomial coefficients: `B_i(t) = Σ_p coef[i][p]·t^p`.
    coef: [[f64; MAX_ORDER]; MAX_ORDER],
    nodes: [f64; MAX_ORDER],
    mean: [f64; MAX_ORDER],
}

impl PatchBasis {
    /// The Lagrange basis with `m` functions (1 = constant … 4 = cubic).
    pub fn new(m: usize) -> Result<Self> {
        let (coef, nodes): ([[f64; 4]; 4], [f64; 4]) = match m {
            1 => (
                [[1.0, 0.0, 0.0, 0.0], [0.0; 4], [0.0; 4], [0.0; 4]],
                [0.5, 0.0, 0.0, 0.0],
            ),
            2 => (
                [
                    [1.0, -1.0, 0.0, 0.0],
                    [0.0, 1.0, 0.0, 0.0],
                    [0.0; 4],
                    [0.0; 4],
                ],
                [0.0, 1.0, 0.0, 0.0],
            ),
            3 => (
                [
                    [1.0, -3.0, 2.0, 0.0],
                    [0.0, 4.0, -4.0, 0.0],
                    [0.0, -1.0, 2.0, 0.0],
                    [0.0; 4],
                ],
                [0.0, 0.5, 1.0, 0.0],
            ),
            4 => (
                [
                    [1.0, -5.5, 9.0, -4.5],
                    [0.0, 9.0, -22.5, 13.5],
                    [0.0, -4.5, 18.0, -13.5],
                    [0.0, 1.0, -4.5, 4.5],
                ],
                [0.0, 1.0 / 3.0, 2.0 / 3.0, 1.0],
            ),
            _ => {
                return Err(FilterError::invalid(
                    "order",
                    m,
                    "patch order M must be in 1..=4",
                ));
            }
        };
        let mut b = PatchBasis {
            m,
            coef,
            nodes,
            mean: [0.0; 4],
        };
        for i in 0..m {
            b.mean[i] = b.integral(i, 0.0, 1.0);
        }
        Ok(b)
    }

    /// Order `M`.
    pub fn order(&self) -> usize {
        self.m
    }

    /// Interpolation nodes in `[0, 1]`.
    pub fn nodes(&self) -> &[f64] {
        &self.nodes[..self.m]
    }

    /// Monomial coefficients of `B_i` (`t⁰` first).
    pub fn coefficients(&self, i: usize) -> &[f64; MAX_ORDER] {
        &self.coef[i]
    }

    /// `B_i(t)`.
    #[inline]
    pub fn eval(&self, i: usize, t: f64) -> f64 {
        let c = &self.coef[i];
        ((c[3] * t + c[2]) * t + c[1]) * t + c[0]
    }

    /// `B̄_i = ∫₀¹ B_i` (eq 4.12).
    #[inline]
    pub fn mean(&self, i: usize) -> f64 {
        self.mean[i]
    }

    /// `∫_a^b B_i(t) dt` (exact).
    pub fn integral(&self, i: usize, a: f64, b: f64) -> f64 {
        self.moment(i, a, b, 1.0, 0.0)
    }

    /// `∫_a^b B_i(t)·(α + β·t) dt` (exact; the linear factor is a trilinear weight).
    pub fn moment(&self, i: usize, a: f64, b: f64, alpha: f64, beta: f64) -> f64 {
        let c = &self.coef[i];
        let mut acc = 0.0;
        for (p, &cp) in c.iter().enumerate() {
            if cp == 0.0 {
                continue;
            }
            let k = p as i32;
            let i0 = (b.powi(k + 1) - a.powi(k + 1)) / (k as f64 + 1.0);
            let i1 = (b.powi(k + 2) - a.powi(k + 2)) / (k as f64 + 2.0);
            acc += cp * (alpha * i0 + beta * i1);
        }
        acc
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lagrange_properties_f_b17() {
        for m in 1..=4 {
            let b = PatchBasis::new(m).unwrap();
            for t in [0.0, 0.1, 0.37, 0.8, 1.0] {
                let s: f64 = (0..m).map(|i| b.eval(i, t)).sum();
                assert!((s - 1.0).abs() < 1e-13, "partition of unity M={m}");
            }
            for (a, &x) in b.nodes().iter().enumerate() {
                for i in 0..m {
                    let e = if i == a { 1.0 } else { 0.0 };
                    assert!((b.eval(i, x) - e).abs() < 1e-13);
                }
            }
        }
        let c = PatchBasis::new(4).unwrap();
        let means = [1.0 / 8.0, 3.0 / 8.0, 3.0 / 8.0, 1.0 / 8.0];
        let tmom = [1.0 / 60.0, 3.0 / 40.0, 3.0 / 10.0, 13.0 / 120.0];
        for i in 0..4 {
            assert!((c.mean(i) - means[i]).abs() < 1e-14);
            assert!((c.moment(i, 0.0, 1.0, 0.0, 1.0) - tmom[i]).abs() < 1e-14);
        }
        let q = PatchBasis::new(3).unwrap();
        for (i, e) in [1.0 / 6.0, 2.0 / 3.0, 1.0 / 6.0].iter().enumerate() {
            assert!((q.mean(i) - e).abs() < 1e-14);
        }
        assert!(PatchBasis::new(5).is_err());
    }
}
