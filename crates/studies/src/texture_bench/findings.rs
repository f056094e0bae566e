//! The findings: the Chapter 5 conclusions checked on this run, each a sentence group of the
//! report with the numbers that support or contradict it (discussed in
//! `docs/texture-bench/findings.md`).

use super::scoring::SceneStats;
use super::{BlurRow, ConvergenceRow, ReportRow, TextureBenchSettings};
use crate::metrics::snr_db;
use std::fmt::Write as _;
use volsplat_filter::scene::{SceneSettings, Surface};

/// The coarsest level `γ ≤ 10` (down to −8) at which some dyadic cell has a node
/// `2^γ(m + node)` inside the slab `[z0 − half, z0 + half]`: coarser cells see a zero filter at
/// all their nodes along the slab's normal.
fn first_level_with_node_in_slab(z0: f64, half: f64, nodes: &[f64]) -> Option<i32> {
    (-8..=10).rev().find(|&g| {
        let h = 2f64.powi(g);
        let (lo, hi) = (
            ((z0 - half) / h).floor() as i64,
            ((z0 + half) / h).floor() as i64,
        );
        (lo..=hi).any(|m| {
            nodes.iter().any(|&t| {
                let z = (m as f64 + t) * h;
                (z0 - half..=z0 + half).contains(&z)
            })
        })
    })
}

/// Smallest `n` of `curve` (pairs `(n, MSE)`) from which every MSE stays within
/// `max(0.25·floor, 1)` of the last (the floor).
fn saturation_point(curve: &[(usize, f64)]) -> Option<usize> {
    let floor = curve.last()?.1;
    let band = floor + (0.25 * floor).max(1.0);
    let mut from = curve.last()?.0;
    for &(n, m) in curve.iter().rev() {
        if m > band {
            break;
        }
        from = n;
    }
    Some(from)
}

fn list(rows: &[&ReportRow]) -> String {
    rows.iter()
        .map(|r| {
            let fb = if r.fallbacks > 0 {
                format!(
                    " ({} fallbacks, share {:.1})",
                    r.fallbacks,
                    r.fallback_mse_share.unwrap_or(f64::NAN)
                )
            } else {
                String::new()
            };
            format!("{} → {:.1}{fb}", r.technique, r.mse.unwrap_or(f64::NAN))
        })
        .collect::<Vec<_>>()
        .join("; ")
}

/// `(n, MSE)` of the "EWA-3 adaptive (n)" rows.
fn ewa_curve(rows: &[ReportRow]) -> Vec<(usize, f64)> {
    rows.iter()
        .filter_map(|r| {
            let n = r
                .technique
                .strip_prefix("EWA-3 adaptive (")?
                .strip_suffix(')')?
                .parse()
                .ok()?;
            Some((n, r.mse?))
        })
        .collect()
}

/// M=4 beats M=1 at every tolerance, and each order's error falls as the tolerance shrinks.
fn nil_ordering(rows: &[ReportRow], tolerances: &[usize]) -> (bool, bool) {
    let mse = |m: usize, t: usize| {
        rows.iter()
            .find(|r| r.technique == format!("NIL, M={m}, tol={t}"))
            .and_then(|r| r.mse)
    };
    let mut by_m = true;
    let mut by_tol = true;
    let mut tols = tolerances.to_vec();
    tols.sort_unstable_by(|a, b| b.cmp(a));
    for &t in &tols {
        match (mse(1, t), mse(4, t)) {
            (Some(a), Some(b)) => by_m &= b < a,
            _ => by_m = false,
        }
    }
    for m in [1, 4] {
        for w in tols.windows(2) {
            match (mse(m, w[0]), mse(m, w[1])) {
                (Some(a), Some(b)) => by_tol &= b < a,
                _ => by_tol = false,
            }
        }
    }
    (by_m, by_tol)
}

/// The qualitative findings checked on this run (the Chapter 5 conclusions), one sentence
/// group each, in report order; a finding whose rows were not run is left out.
pub(super) fn findings(
    rows: &[ReportRow],
    depth_rows: &[ReportRow],
    settings: &TextureBenchSettings,
    convergence: &[ConvergenceRow],
    blur: &[BlurRow],
    stats: &SceneStats,
) -> Vec<String> {
    [
        clamping(rows),
        gauss27_against_simpson(rows, stats),
        nil_thin_slab(rows, settings.epsilon),
        settings
            .thick_epsilon
            .and_then(|e| nil_depth_study(depth_rows, e)),
        patch_order(convergence),
        ewa_saturation(rows, depth_rows, settings),
        motion_blur(blur),
    ]
    .into_iter()
    .flatten()
    .collect()
}

/// Where the EWA error curve saturates, as the findings say it; only meaningful on a curve that
/// reaches well past the thesis's n = 11.
fn saturation(c: &[(usize, f64)]) -> String {
    if c.len() >= 4 && c.last().is_some_and(|l| l.0 >= 21) {
        saturation_point(c).map_or("—".into(), |n| format!("from n = {n}"))
    } else {
        "— (run more max-samples values to locate)".to_string()
    }
}

/// "yes" or "NO".
fn yes(b: bool) -> &'static str {
    if b { "yes" } else { "NO" }
}

/// Clamping (§5-3, Table 5.1): quadratic clamping's MSE above step clamping's.
fn clamping(rows: &[ReportRow]) -> Option<String> {
    let find = |name: &str| rows.iter().find(|r| r.technique == name);
    if let (Some(s), Some(q)) = (find("Step clamped"), find("Quadratic clamped"))
        && let (Some(ms), Some(mq)) = (s.mse, q.mse)
    {
        return Some(format!(
            "Clamping (§5-3): quadratic MSE {mq:.1} vs step {ms:.1} against the Simpson box reference — {}.",
            if mq > ms {
                "quadratic is higher, as in Table 5.1 (it attenuates components long before they alias)"
            } else {
                "NOT reproduced"
            }
        ));
    }
    None
}

/// Gauss-27 against the Simpson box reference (§5-4): the whole image and the small
/// footprints, and why they differ.
fn gauss27_against_simpson(rows: &[ReportRow], stats: &SceneStats) -> Option<String> {
    let find = |name: &str| rows.iter().find(|r| r.technique == name);
    if let (Some(g), Some(s)) = (
        find("Direct Gauss-27 (box)"),
        find("Direct Simpson's (box)"),
    ) && let Some(m) = g.mse
    {
        let small_mse = g.mse_small_footprints.unwrap_or(f64::NAN);
        return Some(format!(
            "Gauss-27 vs Simpson box (§5-4; thesis 44.7 dB at 3.5× less time): SNR {:.1} dB at {:.1}× less time over the whole image, \
             but {:.1} dB (MSE {:.2}) over the {} of {} object pixels whose footprint is at most one texture period across; the other {} pixels \
             (footprints up to {:.0} periods, towards the horizon) carry {:.0} % of the squared error. The rule is right (nodes 0, ±√(3/5), weights 8/9, 5/9, \
             exact to degree 5 per axis; same V_tan box and normalised box filter as the reference, whose MSE against the closed-form box is {:.2}): \
             three nodes per axis cannot integrate a footprint spanning several periods of the 5.2 cycles/unit texture. The thesis's 3.5× time ratio, \
             against a 125 : 27 minimum-evaluation ratio, says its Simpson reference hardly refined, i.e. its image had few such footprints; \
             ours takes {:.0} evaluations per object pixel on average.",
            snr_db(m),
            s.seconds / g.seconds.max(1e-9),
            snr_db(small_mse),
            small_mse,
            stats.small,
            stats.hits,
            stats.hits - stats.small,
            2.0 * SceneSettings::test_plane(1, 1).max_footprint,
            100.0 * (1.0 - small_mse * stats.small as f64 / (m * stats.pixels as f64)),
            s.mse_exact_box.unwrap_or(f64::NAN),
            s.work as f64 / stats.hits.max(1) as f64,
        ));
    }
    None
}

/// NIL on the thin `V_tan` (Table 5.6): why M=4 is not better than M=1 there.
fn nil_thin_slab(rows: &[ReportRow], eps: f64) -> Option<String> {
    let nil: Vec<&ReportRow> = rows
        .iter()
        .filter(|r| r.technique.starts_with("NIL"))
        .collect();
    if !nil.is_empty() {
        let z0 = match SceneSettings::test_plane(1, 1).surface {
            Surface::Plane { point, .. } => point.z,
            Surface::Sphere { center, .. } => center.z,
        };
        let show = |g: Option<i32>| g.map_or("—".into(), |g| g.to_string());
        let rest = |m: usize| {
            nil.iter()
                .filter(|r| r.technique.starts_with(&format!("NIL, M={m},")))
                .map(|r| {
                    format!(
                        "{:.1}",
                        r.mse.unwrap_or(f64::NAN) - r.fallback_mse_share.unwrap_or(0.0)
                    )
                })
                .collect::<Vec<_>>()
                .join(", ")
        };
        return Some(format!(
            "NIL MSE (Table 5.6), V_tan depth ε = {eps}: {}. M=4 is not better than M=1 here. Cause: a V_tan ε = {eps} periods thick is a slab \
             that cubic dyadic cells cannot represent — a patch has non-zero control points only if one of its node planes falls inside the slab \
             (for the plane z = {z0} that first happens at γ = {} for the node {{½}} and γ = {} for {{0, ⅓, ⅔, 1}}), so the pixels whose hierarchy \
             stays coarser collapse for M=1 and M=4 alike (same fallback counts), and at tol 2 the hierarchy descends to γ_min around each \
             trigger column, reducing NIL to sampling the filter at the 5 × 5 trigger columns whatever M. The point-sample fallback replaces the \
             thesis's 0/0 white pixels (its 6416); its share of the MSE is listed; the rest (M=1: {}; M=4: {}, by tolerance) shows no \
             M=4 advantage either.",
            list(&nil),
            show(first_level_with_node_in_slab(z0, 0.5 * eps, &[0.5])),
            show(first_level_with_node_in_slab(
                z0,
                0.5 * eps,
                &[0.0, 1.0 / 3.0, 2.0 / 3.0, 1.0]
            )),
            rest(1),
            rest(4)
        ));
    }
    None
}

/// The NIL depth study at `ε = e`: Table 5.6's ordering once the cells resolve the depth.
fn nil_depth_study(depth_rows: &[ReportRow], e: f64) -> Option<String> {
    let depth_nil: Vec<&ReportRow> = depth_rows
        .iter()
        .filter(|r| r.technique.starts_with("NIL"))
        .collect();
    if !depth_nil.is_empty() {
        let tols: Vec<usize> = {
            let mut t: Vec<usize> = depth_nil
                .iter()
                .filter_map(|r| r.technique.rsplit("tol=").next()?.parse().ok())
                .collect();
            t.sort_unstable();
            t.dedup();
            t
        };
        let (by_m, by_tol) = nil_ordering(depth_rows, &tols);
        return Some(format!(
            "NIL depth study (ε = {e}, V_tan about as thick as mid-image footprints, own Simpson Gaussian reference): {}. \
             M=4 better than M=1 at every tolerance: {}; error falls as the tolerance shrinks: {} — the thesis's Table 5.6 ordering, \
             once the cells can resolve the filter's depth.",
            list(&depth_nil),
            yes(by_m),
            yes(by_tol)
        ));
    }
    None
}

/// The patch orders' convergence on uniform hierarchies.
fn patch_order(convergence: &[ConvergenceRow]) -> Option<String> {
    if convergence.len() >= 2 {
        let errs = convergence
            .iter()
            .map(|c| {
                format!(
                    "M={}: {} (order {:.1})",
                    c.order,
                    c.errors
                        .iter()
                        .map(|(_, e)| format!("{:.1e}", e.abs()))
                        .collect::<Vec<_>>()
                        .join(", "),
                    c.last_order()
                )
            })
            .collect::<Vec<_>>()
            .join("; ");
        let ratio = match (convergence[0].errors.last(), convergence[1].errors.last()) {
            (Some((_, a)), Some((_, b))) => b.abs() / a.abs(),
            _ => f64::NAN,
        };
        return Some(format!(
            "Patch order (smooth 3-D Gaussian, uniform hierarchies γ = −1 … −4, |error|): {errs}. Constant patches (node at the cell \
             centre: a midpoint rule) and linear ones (nodes on the faces: a trapezoid rule) are both O(h²), linear with {ratio:.1}× the \
             error at the finest level; quadratic and cubic converge faster. So linear not beating constant is a property of the Lagrange \
             nodes (A-2), not a bug; the error falls with M from {{1, 2}} to {{3, 4}}."
        ));
    }
    None
}

/// EWA-3's error by max samples (Table 5.4), its saturation, the depth study's curve and the
/// probes of the thesis's flat error.
fn ewa_saturation(
    rows: &[ReportRow],
    depth_rows: &[ReportRow],
    settings: &TextureBenchSettings,
) -> Option<String> {
    let thick = settings.thick_epsilon;
    let eps = settings.epsilon;
    let curve = ewa_curve(rows);
    if !curve.is_empty() {
        let fmt = |c: &[(usize, f64)]| {
            c.iter()
                .map(|(n, m)| format!("{n}: {m:.1}"))
                .collect::<Vec<_>>()
                .join(", ")
        };
        let mut line = format!(
            "EWA-3 adaptive MSE by max samples (Table 5.4), ε = {eps}: {}; saturated (within max(25 %, 1) of the last) {}. \
             The cap, not the 1/(2 f_max) spacing, binds where the error is (footprints wider than n spacings); once it stops binding the \
             error sits on the floor of the kernel mismatch (EWA truncates the Gaussian at the ellipse, the reference at the V_tan \
             rectangle; same α = 2, same centre).",
            fmt(&curve),
            saturation(&curve)
        );
        let dcurve = ewa_curve(depth_rows);
        if let (Some(e), false) = (thick, dcurve.is_empty()) {
            let ewa2 = depth_rows
                .iter()
                .find(|r| r.technique.starts_with("EWA-2 adaptive"))
                .and_then(|r| r.mse);
            let _ = write!(
                line,
                " Depth study (ε = {e}): {}; saturated {} at the floor of EWA-3's 3-D Gaussian ellipsoid against the reference's \
                 2-D Gaussian × box in depth (EWA-2, which ignores the depth: {:.1}).",
                fmt(&dcurve),
                saturation(&dcurve),
                ewa2.unwrap_or(f64::NAN)
            );
        }
        let centred = rows
            .iter()
            .find(|r| r.technique.ends_with("centred at the ray hit"))
            .and_then(|r| r.mse);
        let narrow = rows
            .iter()
            .find(|r| r.technique.starts_with("EWA-3 adaptive (") && r.technique.contains("α ="))
            .and_then(|r| r.mse);
        let _ = write!(
            line,
            " The thesis's flat 192–196 from n = 3 needs an n-independent discrepancy between its EWA and its reference far above \
             the cap error; §7-0.1 blames the centring, but here moving the Gaussian from the ellipse centre to the ray hit gives {:.1} \
             at the largest n, and a Gaussian four times narrower than the reference's gives {:.1} — a floor near 190 is not \
             reproduced (unexplained); our EWA and reference share centre, width and box, so the cap error shows at small n and the \
             floor is low.",
            centred.unwrap_or(f64::NAN),
            narrow.unwrap_or(f64::NAN)
        );
        return Some(line);
    }
    None
}

/// Appendix C's motion blur: MSE against the unrotated image by angle.
fn motion_blur(blur: &[BlurRow]) -> Option<String> {
    let mb: Vec<String> = blur
        .iter()
        .filter(|b| b.what.starts_with("motion"))
        .map(|b| format!("{:.1}", b.mse_vs_unblurred.unwrap_or(f64::NAN)))
        .collect();
    if !mb.is_empty() {
        return Some(format!(
            "Motion blur MSE against the unrotated image for θ = 0, π/24, π/12, π/6: {}.",
            mb.join(", ")
        ));
    }
    None
}
