//! The report as Markdown: the comparison tables, the convergence, pre-processing and blur
//! tables and the findings ([`TextureBenchReport::to_markdown`]).

use super::depth::depth_size;
use super::{ReportRow, SMALL_FOOTPRINT, TextureBenchReport};
use std::fmt::Write as _;

/// Writes a comparison table; row numbers and references get `prefix`.
fn rows_table(s: &mut String, rows: &[ReportRow], prefix: &str) {
    let _ = writeln!(
        s,
        "| # | Technique | Time (s) | Pre (s) | Work | MSE (ref) | SNR (dB) | MSE ≤1 period | MSE vs exact box | Fallbacks (MSE share) |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|---|");
    for r in rows {
        let mse = match (r.mse, r.reference) {
            (Some(m), Some(k)) => format!("{m:.2} ({prefix}{k})"),
            _ => "—".into(),
        };
        let snr = r.snr_db.map_or("—".into(), |v| {
            if v.is_finite() {
                format!("{v:.1}")
            } else {
                "∞".into()
            }
        });
        let fb = match (r.fallbacks, r.fallback_mse_share) {
            (0, _) => "0".to_string(),
            (n, Some(m)) => format!("{n} ({m:.2})"),
            (n, None) => n.to_string(),
        };
        let _ = writeln!(
            s,
            "| {prefix}{} | {} | {:.3} | {:.4} | {} | {} | {} | {} | {} | {} |",
            r.index,
            r.technique,
            r.seconds,
            r.preprocess_seconds,
            r.work,
            mse,
            snr,
            r.mse_small_footprints
                .map_or("—".into(), |m| format!("{m:.2}")),
            r.mse_exact_box.map_or("—".into(), |m| format!("{m:.2}")),
            fb
        );
    }
}

impl TextureBenchReport {
    /// The tables as Markdown (the analogue of Tables 5.2/5.4/5.5/5.6 plus blur measurements).
    pub fn to_markdown(&self) -> String {
        let mut s = String::new();
        let st = &self.settings;
        let _ = writeln!(
            s,
            "## texture-bench: {}×{} cosine plane (I=J=K=4, seed {}), references at tol {:.4}\n",
            st.width, st.height, st.seed, st.reference_tolerance
        );
        let _ = writeln!(
            s,
            "V_tan depth ε = {}. \"MSE ≤1 period\": against the same reference, averaged over the object pixels whose \
             footprint is at most one texture period across (semi-major axis ≤ {SMALL_FOOTPRINT}). \"Fallbacks\": NIL pixels \
             whose scale factor collapsed (point sample instead) and their share of the MSE.\n",
            st.epsilon
        );
        rows_table(&mut s, &self.rows, "");
        if let (Some(e), false) = (st.thick_epsilon, self.depth_rows.is_empty()) {
            let (w, h) = depth_size(st);
            let _ = writeln!(
                s,
                "\n### Depth study: NIL and EWA with a thick V_tan (ε = {e}, {w}×{h} pixels)\n"
            );
            rows_table(&mut s, &self.depth_rows, "D");
        }
        if !self.convergence.is_empty() {
            let _ = writeln!(
                s,
                "\n### NIL patch order vs cell size (smooth 3-D Gaussian, uniform hierarchies)\n"
            );
            let levels: Vec<i32> = self.convergence[0].errors.iter().map(|e| e.0).collect();
            let head: Vec<String> = levels.iter().map(|g| format!("|error|, γ={g}")).collect();
            let _ = writeln!(s, "| M | {} | order (finest step) |", head.join(" | "));
            let _ = writeln!(s, "|---|{}---|", "---|".repeat(levels.len()));
            for c in &self.convergence {
                let e: Vec<String> = c
                    .errors
                    .iter()
                    .map(|(_, e)| format!("{:.2e}", e.abs()))
                    .collect();
                let _ = writeln!(
                    s,
                    "| {} | {} | {:.2} |",
                    c.order,
                    e.join(" | "),
                    c.last_order()
                );
            }
        }
        let _ = writeln!(s, "\n### Pre-processing (Tables 5.5, 5.9)\n");
        let _ = writeln!(s, "| Built | Time (s) | Stored values |");
        let _ = writeln!(s, "|---|---|---|");
        for p in &self.preprocessing {
            let _ = writeln!(s, "| {} | {:.4} | {} |", p.what, p.seconds, p.stored_values);
        }
        if !self.blur.is_empty() {
            let _ = writeln!(
                s,
                "\n### Blur (Table 5.3 marble grid, Appendix C motion blur)\n"
            );
            let _ = writeln!(s, "| Scene | Total variation | MSE vs θ=0 | Time (s) |");
            let _ = writeln!(s, "|---|---|---|---|");
            for b in &self.blur {
                let m = b.mse_vs_unblurred.map_or("—".into(), |m| format!("{m:.1}"));
                let _ = writeln!(
                    s,
                    "| {} | {:.4} | {} | {:.3} |",
                    b.what, b.total_variation, m, b.seconds
                );
            }
        }
        let _ = writeln!(s, "\n### Findings\n");
        for f in &self.findings {
            let _ = writeln!(s, "- {f}");
        }
        let _ = writeln!(s, "\nTotal: {:.1} s.", self.total_seconds);
        s
    }
}
