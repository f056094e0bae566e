//! Brute-force reference for the density-emitter model (Sabella's display, Buchanan eq 3.1):
//! `I = ∫_{ta}^{tb} exp(−τ ∫_{ta}^{t} ρ dμ) ρ(t) dt` along each ray, integrated numerically
//! without the closed form: the optical depth by the trapezoid rule at a fine fixed step and
//! the outer integral by the trapezoid rule on the same samples. Density by trilinear
//! interpolation of a `Volume<f32>` in index space, zero outside the box of voxel centres.
//! Shares no code with `volsplat-filter`'s display (only the core camera types).

use volsplat_core::glam::DVec3;
use volsplat_core::{Projection, ScalarImage, Volume};

fn density(vol: &Volume<f32>, q: DVec3) -> f64 {
    let d = vol.grid().dims;
    let e = 1e-9;
    for a in 0..3 {
        if q[a] < -e || q[a] > (d[a] - 1) as f64 + e {
            return 0.0;
        }
    }
    let mut base = [0usize; 3];
    let mut frac = [0.0; 3];
    for a in 0..3 {
        let x = q[a].clamp(0.0, (d[a] - 1) as f64);
        let b = (x.floor() as usize).min(d[a].saturating_sub(2));
        base[a] = b;
        frac[a] = x - b as f64;
    }
    let mut v = 0.0;
    for c in 0..8usize {
        let mut w = 1.0;
        let mut idx = [0usize; 3];
        for a in 0..3 {
            let up = (c >> a) & 1 == 1;
            idx[a] = (base[a] + usize::from(up)).min(d[a] - 1);
            w *= if up { frac[a] } else { 1.0 - frac[a] };
        }
        if w != 0.0 {
            v += w * vol.get(idx[0], idx[1], idx[2]) as f64;
        }
    }
    v
}

/// `τ·I` per pixel (dimensionless) for `n × n` rays per pixel at `x + (s + ½)/n`, with `τ` per
/// world unit and a fixed world `step` (the last interval shortened to end at the exit). Rays
/// are clipped to the box of voxel centres by slabs in index space; perspective rays start at
/// the eye. Rays that miss contribute 0.
pub fn reference_emitter(
    vol: &Volume<f32>,
    proj: &Projection,
    tau: f64,
    step: f64,
    n: usize,
) -> ScalarImage {
    let (w, h) = proj.size();
    let grid = vol.grid();
    let n = n.max(1);
    let mut values = Vec::with_capacity(w * h);
    for y in 0..h {
        for x in 0..w {
            let mut acc = 0.0;
            for sy in 0..n {
                for sx in 0..n {
                    let fx = x as f64 + (sx as f64 + 0.5) / n as f64;
                    let fy = y as f64 + (sy as f64 + 0.5) / n as f64;
                    let (o, d) = proj.ray(fx, fy);
                    // Interval of the line inside the box, by slabs in index space.
                    let q0 = grid.index_from_world(o);
                    let dq = grid.index_from_world(o + d) - q0;
                    let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
                    let mut miss = false;
                    for a in 0..3 {
                        let hi = (grid.dims[a] - 1) as f64;
                        if dq[a].abs() < 1e-300 {
                            miss |= q0[a] < 0.0 || q0[a] > hi;
                            continue;
                        }
                        let (ta, tb) = (-q0[a] / dq[a], (hi - q0[a]) / dq[a]);
                        t0 = t0.max(ta.min(tb));
                        t1 = t1.min(ta.max(tb));
                    }
                    if matches!(proj, Projection::Perspective(_)) {
                        t0 = t0.max(0.0);
                    }
                    if miss || t1.partial_cmp(&t0) != Some(std::cmp::Ordering::Greater) {
                        continue;
                    }
                    let k = ((t1 - t0) / step).ceil().max(1.0) as usize;
                    let hs = (t1 - t0) / k as f64;
                    let rho = |i: usize| density(vol, q0 + dq * (t0 + i as f64 * hs));
                    // Trapezoid in both integrals.
                    let mut depth = 0.0;
                    let mut prev_rho = rho(0);
                    let mut prev_f = prev_rho;
                    let mut inten = 0.0;
                    for i in 1..=k {
                        let r = rho(i);
                        depth += 0.5 * (prev_rho + r) * hs;
                        let f = (-tau * depth).exp() * r;
                        inten += 0.5 * (prev_f + f) * hs;
                        prev_rho = r;
                        prev_f = f;
                    }
                    acc += tau * inten;
                }
            }
            values.push((acc / (n * n) as f64) as f32);
        }
    }
    ScalarImage::from_values(w, h, values).unwrap_or_else(|| ScalarImage::new(w, h))
}
