//! Quadrature rules (thesis §4-2, §5-4; \[Burd81\] = Burden, Faires & Reynolds): Gauss–Legendre
//! (fixed, "cubic" 3-point), composite rules, and vector-valued adaptive Simpson.

/// Gauss–Legendre nodes and weights on `[−1, 1]` for `n = 1..=5` points (exact for degree
/// `2n − 1`). Other `n` fall back to 5.
pub fn gauss_legendre(n: usize) -> (&'static [f64], &'static [f64]) {
    const X1: [f64; 1] = [0.0];
    const W1: [f64; 1] = [2.0];
    const X2: [f64; 2] = [-0.577_350_269_189_625_8, 0.577_350_269_189_625_8];
    const W2: [f64; 2] = [1.0, 1.0];
    const X3: [f64; 3] = [-0.774_596_669_241_483_4, 0.0, 0.774_596_669_241_483_4];
    const W3: [f64; 3] = [5.0 / 9.0, 8.0 / 9.0, 5.0 / 9.0];
    const X4: [f64; 4] = [
        -0.861_136_311_594_052_6,
        -0.339_981_043_584_856_3,
        0.339_981_043_584_856_3,
        0.861_136_311_594_052_6,
    ];
    const W4: [f64; 4] = [
        0.347_854_845_137_453_9,
        0.652_145_154_862_546_1,
        0.652_145_154_862_546_1,
        0.347_854_845_137_453_9,
    ];
    const X5: [f64; 5] = [
        -0.906_179_845_938_664,
        -0.538_469_310_105_683,
        0.0,
        0.538_469_310_105_683,
        0.906_179_845_938_664,
    ];
    const W5: [f64; 5] = [
        0.236_926_885_056_189_1,
        0.478_628_670_499_366_5,
        0.568_888_888_888_888_9,
        0.478_628_670_499_366_5,
        0.236_926_885_056_189_1,
    ];
    match n {
        1 => (&X1, &W1),
        2 => (&X2, &W2),
        3 => (&X3, &W3),
        4 => (&X4, &W4),
        _ => (&X5, &W5),
    }
}

/// Composite `n`-point Gauss–Legendre integral of `f` over `[a, b]` with `panels` panels.
pub fn composite_gauss_1d(f: &dyn Fn(f64) -> f64, a: f64, b: f64, panels: usize, n: usize) -> f64 {
    let (x, w) = gauss_legendre(n);
    let h = (b - a) / panels.max(1) as f64;
    let mut sum = 0.0;
    for p in 0..panels.max(1) {
        let c = a + (p as f64 + 0.5) * h;
        for (xi, wi) in x.iter().zip(w) {
            sum += wi * f(c + 0.5 * h * xi);
        }
    }
    sum * 0.5 * h
}

/// A composite product rule over `[−1, 1]³`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CompositeRule {
    /// `n`-point Gauss–Legendre per panel and axis (error `O(h^{2n})`).
    Gauss(usize),
    /// Simpson's rule per panel and axis (error `O(h⁴)`).
    Simpson,
}

/// The 1-D nodes and weights (weights sum to 1: they average over `[−1, 1]`).
fn composite_nodes(rule: CompositeRule, panels: usize) -> Vec<(f64, f64)> {
    let panels = panels.max(1);
    let h = 2.0 / panels as f64;
    let mut out = Vec::new();
    for p in 0..panels {
        let a = -1.0 + p as f64 * h;
        match rule {
            CompositeRule::Gauss(n) => {
                let (x, w) = gauss_legendre(n);
                for (xi, wi) in x.iter().zip(w) {
                    out.push((a + 0.5 * h * (xi + 1.0), wi * 0.25 * h));
                }
            }
            CompositeRule::Simpson => {
                for (x, w) in [(0.0, 1.0), (0.5, 4.0), (1.0, 1.0)] {
                    out.push((a + x * h, w * h / 12.0));
                }
            }
        }
    }
    out
}

/// Average of `f(s, t, r)` over `[−1, 1]³` by a composite product rule.
pub fn composite_average_3d(
    f: &dyn Fn(f64, f64, f64) -> f64,
    rule: CompositeRule,
    panels: usize,
) -> f64 {
    let nodes = composite_nodes(rule, panels);
    let mut sum = 0.0;
    for &(s, ws) in &nodes {
        for &(t, wt) in &nodes {
            for &(r, wr) in &nodes {
                sum += ws * wt * wr * f(s, t, r);
            }
        }
    }
    sum
}

/// Vector-valued adaptive Simpson quadrature on `[a, b]` (thesis §4-2 "mid-point adaptive";
/// \[Burd81\] §4.6).
///
/// Integrates the two components of `f` together; an interval is accepted when
/// `max_c |S_left + S_right − S_whole|_c ≤ 15·eps` (Richardson), with `eps = tol·(b − a)`
/// shared in proportion to interval length, or when `max_depth` halvings were made. Each call
/// evaluates at least 5 points. `count` receives the number of evaluations. Returns the
/// *integral* (Richardson-corrected).
pub fn adaptive_simpson(
    f: &mut dyn FnMut(f64) -> [f64; 2],
    a: f64,
    b: f64,
    tol: f64,
    max_depth: u32,
    count: &mut u64,
) -> [f64; 2] {
    let fa = f(a);
    let fm = f(0.5 * (a + b));
    let fb = f(b);
    *count += 3;
    let whole = simpson(a, b, fa, fm, fb);
    recurse(f, a, b, fa, fm, fb, whole, tol * (b - a), max_depth, count)
}

#[inline]
fn simpson(a: f64, b: f64, fa: [f64; 2], fm: [f64; 2], fb: [f64; 2]) -> [f64; 2] {
    let h = (b - a) / 6.0;
    [
        h * (fa[0] + 4.0 * fm[0] + fb[0]),
        h * (fa[1] + 4.0 * fm[1] + fb[1]),
    ]
}

#[allow(clippy::too_many_arguments)]
fn recurse(
    f: &mut dyn FnMut(f64) -> [f64; 2],
    a: f64,
    b: f64,
    fa: [f64; 2],
    fm: [f64; 2],
    fb: [f64; 2],
    whole: [f64; 2],
    eps: f64,
    depth: u32,
    count: &mut u64,
) -> [f64; 2] {
    let m = 0.5 * (a + b);
    let flm = f(0.5 * (a + m));
    let frm = f(0.5 * (m + b));
    *count += 2;
    let left = simpson(a, m, fa, flm, fm);
    let right = simpson(m, b, fm, frm, fb);
    let d = [left[0] + right[0] - whole[0], left[1] + right[1] - whole[1]];
    if depth == 0 || d[0].abs().max(d[1].abs()) <= 15.0 * eps {
        return [
            left[0] + right[0] + d[0] / 15.0,
            left[1] + right[1] + d[1] / 15.0,
        ];
    }
    let l = recurse(f, a, m, fa, flm, fm, left, 0.5 * eps, depth - 1, count);
    let r = recurse(f, m, b, fm, frm, fb, right, 0.5 * eps, depth - 1, count);
    [l[0] + r[0], l[1] + r[1]]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gauss_exactness() {
        for n in 1..=5 {
            let (x, w) = gauss_legendre(n);
            for deg in 0..2 * n {
                let q: f64 = x.iter().zip(w).map(|(x, w)| w * x.powi(deg as i32)).sum();
                let exact = if deg % 2 == 1 {
                    0.0
                } else {
                    2.0 / (deg as f64 + 1.0)
                };
                assert!((q - exact).abs() < 1e-14, "n={n} deg={deg}");
            }
        }
    }

    #[test]
    fn adaptive_simpson_exact_for_cubics_and_counts() {
        let mut count = 0;
        let r = adaptive_simpson(
            &mut |x| [x * x * x - 2.0 * x * x + 1.0, 1.0],
            -1.0,
            1.0,
            1e-9,
            10,
            &mut count,
        );
        assert!((r[0] - (2.0 - 4.0 / 3.0)).abs() < 1e-14);
        assert_eq!(count, 5);
        let mut count = 0;
        let r = adaptive_simpson(
            &mut |x| [(5.0 * x).cos(), 0.0],
            0.0,
            2.0,
            1e-8,
            20,
            &mut count,
        );
        assert!((r[0] - (10f64).sin() / 5.0).abs() < 1e-8);
        assert!(count > 5);
    }
}
