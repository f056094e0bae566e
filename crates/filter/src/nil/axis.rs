//! Per-axis cell weights for discrete textures (thesis App. A-1; eqs A.8, A.15, A.18–A.22,
//! corrected as listed under A-13 in the crate documentation).
//!
//! A level-`γ` cell `m` covers `[2^γ·m, 2^γ·(m+1))` texels along an axis. Its moments
//! `C_i = ∫₀¹ B_i(t) T̄(2^γ(m + t)) dt` are linear in the samples; this module lists, for one
//! axis, the sample indices and the weight each basis function `i` gives them. The 3-D cell is
//! the separable product (A.16, A.29), so a whole level is a three-step tensor contraction.

use super::basis::{MAX_ORDER, PatchBasis};
use crate::quadrature::gauss_legendre;

/// How samples along one axis enter a cell.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum AxisSampling {
    /// Sample-and-hold: sample `s` is constant on `[s, s+1)`.
    Hold,
    /// Linear interpolation between samples at integer points.
    Linear,
    /// `q` Gauss–Legendre nodes per texel: grid index `s·q + g` is the node
    /// `s + (ξ_g + 1)/2`; used for transfer functions with trilinear reconstruction.
    /// Valid only for cells of whole texels (`γ ≥ 0`).
    Nodes(usize),
}

/// Sparse weight row: `(grid index, [w_0 .. w_{M−1}])`, grid indices wrapped and merged.
pub(crate) type AxisRow = Vec<(usize, [f64; MAX_ORDER])>;

/// The weights of level-`gamma` cell `m` along an axis of `n` samples (periodic).
pub(crate) fn cell_row(
    basis: &PatchBasis,
    sampling: AxisSampling,
    n: usize,
    gamma: i32,
    m: i64,
) -> AxisRow {
    let h = 2f64.powi(gamma);
    let x0 = m as f64 * h;
    let x1 = x0 + h;
    let mm = basis.order();
    let mut acc: Vec<(usize, [f64; MAX_ORDER])> = Vec::new();
    let mut push = |idx: i64, len: usize, w: [f64; MAX_ORDER]| {
        let i = idx.rem_euclid(len as i64) as usize;
        acc.push((i, w));
    };
    let s_lo = x0.floor() as i64;
    let s_hi = x1.ceil() as i64;
    for s in s_lo..s_hi {
        let a = x0.max(s as f64);
        let b = x1.min(s as f64 + 1.0);
        if b <= a {
            continue;
        }
        let (ta, tb) = ((a - x0) / h, (b - x0) / h);
        match sampling {
            AxisSampling::Hold => {
                let mut w = [0.0; MAX_ORDER];
                for (i, wi) in w.iter_mut().enumerate().take(mm) {
                    *wi = basis.integral(i, ta, tb);
                }
                push(s, n, w);
            }
            AxisSampling::Linear => {
                // f = x − s = (x0 − s) + h·t over the overlap.
                let (alpha, beta) = (x0 - s as f64, h);
                let mut w0 = [0.0; MAX_ORDER];
                let mut w1 = [0.0; MAX_ORDER];
                for i in 0..mm {
                    let f = basis.moment(i, ta, tb, alpha, beta);
                    w1[i] = f;
                    w0[i] = basis.integral(i, ta, tb) - f;
                }
                push(s, n, w0);
                push(s + 1, n, w1);
            }
            AxisSampling::Nodes(q) => {
                let (xi, wq) = gauss_legendre(q);
                for (g, (x, wg)) in xi.iter().zip(wq).enumerate() {
                    let t = (s as f64 + 0.5 * (x + 1.0) - x0) / h;
                    let mut w = [0.0; MAX_ORDER];
                    for (i, wi) in w.iter_mut().enumerate().take(mm) {
                        *wi = 0.5 * wg * basis.eval(i, t) / h;
                    }
                    push(s * q as i64 + g as i64, n * q, w);
                }
            }
        }
    }
    acc.sort_by_key(|e| e.0);
    let mut out: AxisRow = Vec::with_capacity(acc.len());
    for (i, w) in acc {
        match out.last_mut() {
            Some(last) if last.0 == i => {
                for (a, b) in last.1.iter_mut().zip(w) {
                    *a += b;
                }
            }
            _ => out.push((i, w)),
        }
    }
    out
}

/// Separable contraction of a grid (`dims`, x fastest) with per-axis rows for `P_x × P_y × P_z`
/// cells. Output: cell `(cx, cy, cz)` at `((cz·P_y + cy)·P_x + cx)·M³`, moments `(k·M + j)·M + i`.
/// Each step runs in parallel over independent output slices (rayon); every output value is
/// summed in the same order whatever the thread count.
pub(crate) fn contract(
    grid: &[f64],
    dims: [usize; 3],
    rows: [&[AxisRow]; 3],
    m: usize,
) -> Vec<f64> {
    use rayon::prelude::*;
    let [nx, ny, nz] = dims;
    let [rx, ry, rz] = rows;
    let (px, py, pz) = (rx.len(), ry.len(), rz.len());
    let xm = px * m;
    // Step 2's output b[z][cy][j][cx·m + i], from step 1's a[z][y][cx][i] (x contracted).
    let b = {
        // Step 1 (x): one output line per grid line.
        let mut a = vec![0.0; nz * ny * xm];
        a.par_chunks_mut(xm.max(1))
            .zip(grid.par_chunks(nx.max(1)))
            .for_each(|(out, line)| {
                for (cx, row) in rx.iter().enumerate() {
                    for &(s, w) in row {
                        let v = line[s];
                        for i in 0..m {
                            out[cx * m + i] += w[i] * v;
                        }
                    }
                }
            });
        // Step 2 (y): one output slab per z.
        let mut b = vec![0.0; nz * py * m * xm];
        b.par_chunks_mut((py * m * xm).max(1))
            .enumerate()
            .for_each(|(z, slab)| {
                for (cy, row) in ry.iter().enumerate() {
                    for &(t, w) in row {
                        let src = &a[(z * ny + t) * xm..(z * ny + t + 1) * xm];
                        for j in 0..m {
                            let dst = &mut slab[(cy * m + j) * xm..(cy * m + j + 1) * xm];
                            let wj = w[j];
                            for (d, s) in dst.iter_mut().zip(src) {
                                *d += wj * s;
                            }
                        }
                    }
                }
            });
        b
    };
    // Step 3 (z), written straight into cell-major order: one output slab per cz.
    let m3 = m * m * m;
    let yxm = py * m * xm;
    let mut out = vec![0.0; px * py * pz * m3];
    out.par_chunks_mut((py * px * m3).max(1))
        .zip(rz.par_iter())
        .for_each(|(slab, row)| {
            for &(u, w) in row {
                let src = &b[u * yxm..(u + 1) * yxm];
                for k in 0..m {
                    let wk = w[k];
                    for cy in 0..py {
                        for j in 0..m {
                            let s_row = &src[(cy * m + j) * xm..(cy * m + j + 1) * xm];
                            for cx in 0..px {
                                let d0 = (cy * px + cx) * m3 + (k * m + j) * m;
                                let dst = &mut slab[d0..d0 + m];
                                for (d, s) in dst.iter_mut().zip(&s_row[cx * m..cx * m + m]) {
                                    *d += wk * s;
                                }
                            }
                        }
                    }
                }
            }
        });
    out
}

/// Moments of one cell from explicit rows, gathering samples with `sample(ix, iy, iz)`.
pub(crate) fn contract_cell(
    rows: [&AxisRow; 3],
    m: usize,
    mut sample: impl FnMut(usize, usize, usize) -> f64,
    out: &mut [f64],
) {
    let m3 = m * m * m;
    out[..m3].iter_mut().for_each(|v| *v = 0.0);
    for &(u, wz) in rows[2] {
        for &(t, wy) in rows[1] {
            for &(s, wx) in rows[0] {
                let v = sample(s, t, u);
                if v == 0.0 {
                    continue;
                }
                for k in 0..m {
                    for j in 0..m {
                        let wjk = wz[k] * wy[j] * v;
                        for i in 0..m {
                            out[(k * m + j) * m + i] += wx[i] * wjk;
                        }
                    }
                }
            }
        }
    }
}
