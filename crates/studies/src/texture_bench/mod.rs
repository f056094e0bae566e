//! The `texture-bench` evaluation (Buchanan's thesis Chapter 5: Tables 5.1–5.11, Plates
//! 5.1–5.16, Appendix C): renders the test images with every technique of `volsplat-filter`
//! and scores them with MSE/SNR against the direct-evaluation references. Beyond the thesis's
//! tables it reports the error over small footprints and the NIL fallbacks' share, a depth
//! study (NIL and EWA with a thick `V_tan`), and the convergence of each NIL patch order on
//! uniform hierarchies; the findings explain where the results differ from the thesis
//! (`docs/texture-bench/findings.md`).
//!
//! [`run_texture_bench`] takes [`TextureBenchSettings`] and returns a [`TextureBenchReport`]:
//! images as data ([`BenchImage`], grey `f32` in `[0, 1]`) and tables
//! ([`TextureBenchReport::to_markdown`]); [`write_folder`] runs it and writes `report.md` and
//! one 8-bit PNG per image into a folder (`volsplat texture-bench`).
//!
//! The evaluation's parts, one file each: `plan` (the rows of the main table and what each
//! renders), `scoring` (MSE/SNR of §5-2 against the reference rows), `depth` (the thick-`V_tan`
//! study), `preprocess` (Tables 5.5, 5.9), `blur` (marble grid and motion blur), `convergence`
//! (patch orders on uniform hierarchies), `findings` (the conclusions checked on this run) and
//! `markdown` (the report).

mod blur;
mod convergence;
mod depth;
mod findings;
mod markdown;
mod plan;
mod preprocess;
mod scoring;

pub use blur::arc_triggers;
pub use convergence::patch_order_convergence;

use crate::Written;
use anyhow::Context as _;
use std::path::Path;
use std::time::Instant;
use volsplat_core::ScalarImage;
use volsplat_filter::render::{Rendered, Technique, render};
use volsplat_filter::scene::{Scene, SceneSettings};
use volsplat_filter::texture::CosineTexture;
use volsplat_filter::{FilterError, Result};

/// Checks that `value` is finite and strictly positive.
fn check_positive(field: &str, value: f64) -> Result<()> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(FilterError::invalid(
            field,
            value,
            "must be a positive finite number",
        ))
    }
}

/// Settings of the evaluation.
#[derive(Debug, Clone, PartialEq)]
pub struct TextureBenchSettings {
    /// Image width, pixels (default 128; the thesis used 100).
    pub width: usize,
    /// Image height, pixels (default 96; the thesis used 100).
    pub height: usize,
    /// Seed of the cosine coefficients and the marble noise.
    pub seed: u64,
    /// Tolerance of the adaptive-Simpson references (thesis: 0.004 ≈ 1/255).
    pub reference_tolerance: f64,
    /// Depth cap of the adaptive rules.
    pub max_depth: u32,
    /// Gaussian exponent `α` (`exp(−α(s²+t²))` over `V_tan`).
    pub gaussian_alpha: f64,
    /// Extrusion depth `ε`, texture units.
    pub epsilon: f64,
    /// NIL patch orders to run (thesis: 1 and 4).
    pub nil_orders: Vec<usize>,
    /// NIL tolerances to run (thesis: 10, 5, 2).
    pub nil_tolerances: Vec<usize>,
    /// EWA max-samples values (thesis: 3, 5, 7, 11; we add 15, 21 and 41 to show where the
    /// error saturates and the floor it saturates at).
    pub ewa_max_samples: Vec<usize>,
    /// Depth study: re-runs the NIL and EWA rows on the same plane with a thick `V_tan`
    /// (this `ε`, texture units) against their own Simpson Gaussian reference, at half the
    /// image size (at least 32 × 24); `None` skips it. See `docs/texture-bench/findings.md`.
    pub thick_epsilon: Option<f64>,
    /// Render the marble scenes (Plate 5.6, Table 5.3).
    pub marble: bool,
    /// Render the motion-blur scenes (Plates 5.13–5.16, Appendix C).
    pub motion_blur: bool,
    /// Measure NIL pre-processing on discrete textures of these sizes (Table 5.9).
    pub pyramid_sizes: Vec<usize>,
}

impl Default for TextureBenchSettings {
    fn default() -> Self {
        TextureBenchSettings {
            width: 128,
            height: 96,
            seed: 1,
            reference_tolerance: 1.0 / 255.0,
            max_depth: 8,
            gaussian_alpha: 2.0,
            epsilon: 0.01,
            nil_orders: vec![1, 4],
            nil_tolerances: vec![10, 5, 2],
            ewa_max_samples: vec![3, 5, 7, 11, 15, 21, 41],
            thick_epsilon: Some(0.25),
            marble: true,
            motion_blur: true,
            pyramid_sizes: vec![8, 16, 32],
        }
    }
}

impl TextureBenchSettings {
    /// The thesis's configuration: 100 × 100 pixels.
    pub fn thesis_size() -> Self {
        TextureBenchSettings {
            width: 100,
            height: 100,
            ..Default::default()
        }
    }

    /// A small, fast configuration for tests (48 × 36, fewer variants).
    pub fn quick() -> Self {
        TextureBenchSettings {
            width: 48,
            height: 36,
            nil_orders: vec![1, 4],
            nil_tolerances: vec![10, 2],
            ewa_max_samples: vec![3, 7],
            pyramid_sizes: vec![8],
            ..Default::default()
        }
    }

    fn validate(&self) -> Result<()> {
        check_positive("reference_tolerance", self.reference_tolerance)?;
        check_positive("gaussian_alpha", self.gaussian_alpha)?;
        check_positive("epsilon", self.epsilon)?;
        if let Some(e) = self.thick_epsilon {
            check_positive("thick_epsilon", e)?;
        }
        Ok(())
    }
}

/// One row of the comparison table (analogue of Tables 5.1, 5.2, 5.4, 5.6).
#[derive(Debug, Clone, PartialEq)]
pub struct ReportRow {
    /// Row number (as in Table 5.2: references are cited by it).
    pub index: usize,
    /// Technique and parameters.
    pub technique: String,
    /// Wall-clock seconds to render (all threads).
    pub seconds: f64,
    /// Pre-processing seconds.
    pub preprocess_seconds: f64,
    /// Work: texture evaluations, or NIL patches.
    pub work: u64,
    /// Row index of the reference image, if scored.
    pub reference: Option<usize>,
    /// MSE (8-bit²) against the reference.
    pub mse: Option<f64>,
    /// SNR (dB) against the reference.
    pub snr_db: Option<f64>,
    /// MSE against the reference over the pixels whose footprint is small: the pixel's
    /// tangent-plane ellipse has semi-major axis ≤ [`SMALL_FOOTPRINT`] (at most one texture
    /// period across), averaged over those pixels.
    pub mse_small_footprints: Option<f64>,
    /// MSE against the closed-form box average (the exact box filter).
    pub mse_exact_box: Option<f64>,
    /// Pixels that fell back (NIL scale collapse).
    pub fallbacks: usize,
    /// The part of `mse` contributed by the fallback pixels (their squared errors summed and
    /// divided by the number of *all* pixels, so `mse − share` is the rest's contribution).
    pub fallback_mse_share: Option<f64>,
}

/// Semi-major axis (texture units) below which a footprint counts as small in
/// [`ReportRow::mse_small_footprints`]: a diameter of one texture period (the level-0 NIL
/// cell).
pub const SMALL_FOOTPRINT: f64 = 0.5;

/// Error of NIL evaluations on uniform hierarchies (all cells of one level `γ`) against the
/// exact filtered value, per patch order (see [`patch_order_convergence`]).
#[derive(Debug, Clone, PartialEq)]
pub struct ConvergenceRow {
    /// Patch order `M`.
    pub order: usize,
    /// `(γ, NIL value − exact)` for each level, coarse to fine.
    pub errors: Vec<(i32, f64)>,
}

impl ConvergenceRow {
    /// Observed order `log₂(|e(γ)| / |e(γ−1)|)` between the two finest levels.
    pub fn last_order(&self) -> f64 {
        match self.errors.as_slice() {
            [.., (_, a), (_, b)] => (a.abs() / b.abs()).log2(),
            _ => f64::NAN,
        }
    }
}

/// A rendered image with a file stem and a caption (a "plate").
#[derive(Debug, Clone)]
pub struct BenchImage {
    /// File stem, e.g. `plate_5_1_point_sampled`.
    pub name: String,
    /// Human-readable caption.
    pub caption: String,
    /// Grey values in `[0, 1]`.
    pub image: ScalarImage,
}

/// A pre-processing measurement (Tables 5.5, 5.9).
#[derive(Debug, Clone, PartialEq)]
pub struct PreprocessRow {
    /// What was built.
    pub what: String,
    /// Seconds.
    pub seconds: f64,
    /// Stored values (f64).
    pub stored_values: usize,
}

/// A blur measurement (Appendix C motion blur; Table 5.3 marble grid).
#[derive(Debug, Clone, PartialEq)]
pub struct BlurRow {
    /// Scene and parameter.
    pub what: String,
    /// Mean absolute neighbour difference (lower = blurrier).
    pub total_variation: f64,
    /// Motion blur: MSE (8-bit²) against the `θ = 0` image (same NIL filter, no rotation).
    pub mse_vs_unblurred: Option<f64>,
    /// Seconds.
    pub seconds: f64,
}

/// The full report.
#[derive(Debug, Clone)]
pub struct TextureBenchReport {
    /// Settings used.
    pub settings: TextureBenchSettings,
    /// The comparison table.
    pub rows: Vec<ReportRow>,
    /// Depth study (thick `V_tan`, [`TextureBenchSettings::thick_epsilon`]): Simpson Gaussian
    /// reference (row 1), point sampling, NIL and EWA rows, scored against row 1.
    pub depth_rows: Vec<ReportRow>,
    /// Patch-order convergence of NIL maps on a smooth filter ([`patch_order_convergence`]).
    pub convergence: Vec<ConvergenceRow>,
    /// Pre-processing costs.
    pub preprocessing: Vec<PreprocessRow>,
    /// Blur measurements (marble grid and motion blur).
    pub blur: Vec<BlurRow>,
    /// Rendered images.
    pub images: Vec<BenchImage>,
    /// Qualitative findings checked on this run (the Chapter 5 conclusions).
    pub findings: Vec<String>,
    /// Total wall-clock seconds.
    pub total_seconds: f64,
}

/// A file-name stem of `s`: lower-case ASCII letters and digits, other runs of characters as
/// one `_`.
fn slug(s: &str) -> String {
    let mut out = String::new();
    for c in s.chars() {
        if c.is_ascii_alphanumeric() {
            out.push(c.to_ascii_lowercase());
        } else if !out.ends_with('_') {
            out.push('_');
        }
    }
    out.trim_matches('_').to_string()
}

/// Runs the whole evaluation: the main table on the cosine plane, the pre-processing costs,
/// the blur measurements, the depth study, the patch-order convergence and the findings.
pub fn run_texture_bench(settings: &TextureBenchSettings) -> Result<TextureBenchReport> {
    settings.validate()?;
    let t_all = Instant::now();
    let tex = CosineTexture::seeded(4, settings.seed)?;
    let main = main_table(settings, &tex)?;
    let mut images = main.images;
    let preprocessing = preprocess::preprocessing(settings, &tex)?;
    let mut blur = Vec::new();
    if settings.marble {
        blur::marble_grid(settings, &mut blur, &mut images)?;
    }
    if settings.motion_blur {
        blur::motion_blur(settings, &tex, &mut blur, &mut images)?;
    }
    let depth_rows = match settings.thick_epsilon {
        Some(e) => depth::depth_study(settings, &tex, e)?,
        None => Vec::new(),
    };
    let convergence = patch_order_convergence(&tex)?;
    let findings = findings::findings(
        &main.rows,
        &depth_rows,
        settings,
        &convergence,
        &blur,
        &main.stats,
    );
    Ok(TextureBenchReport {
        settings: settings.clone(),
        rows: main.rows,
        depth_rows,
        convergence,
        preprocessing,
        blur,
        images,
        findings,
        total_seconds: t_all.elapsed().as_secs_f64(),
    })
}

/// The main comparison table, scored, with its plates and the pixel counts the findings use.
struct MainTable {
    rows: Vec<ReportRow>,
    images: Vec<BenchImage>,
    stats: scoring::SceneStats,
}

/// Renders every row of [`plan::main_plan`] and the closed-form box on the cosine plane
/// (thesis §5-1) and scores them; the plates are the rows that have one, then the exact box.
fn main_table(settings: &TextureBenchSettings, tex: &CosineTexture) -> Result<MainTable> {
    let mut scene_settings = SceneSettings::test_plane(settings.width, settings.height);
    scene_settings.epsilon = settings.epsilon;
    let scene = Scene::new(scene_settings)?;
    let plan = plan::main_plan(settings);
    let exact = render(&scene, tex, &Technique::ExactBox)?;
    let rendered: Vec<Rendered> = plan::render_plan(&scene, tex, &plan)?;
    let small = scoring::small_footprint_mask(&scene);
    let rows = scoring::score(&plan, &rendered, &exact.image, &small);
    let mut images = Vec::new();
    for (row, r) in plan.iter().zip(&rendered) {
        if let Some(p) = row.plate {
            images.push(BenchImage {
                name: format!("{p}_{}", slug(&row.label)),
                caption: row.label.clone(),
                image: r.image.clone(),
            });
        }
    }
    let stats = scoring::SceneStats {
        pixels: small.len(),
        hits: small.iter().filter(|s| s.is_some()).count(),
        small: small.iter().filter(|s| **s == Some(true)).count(),
    };
    images.push(BenchImage {
        name: "exact_box".into(),
        caption: "Closed-form box average".into(),
        image: exact.image,
    });
    Ok(MainTable {
        rows,
        images,
        stats,
    })
}

/// Runs [`run_texture_bench`] and writes its report into `out` (created if missing):
/// `report.md` ([`TextureBenchReport::to_markdown`]) and one 8-bit grey PNG per image
/// (`<name>.png`, grey 0…1 → 0…255). The folder is created before the evaluation starts, so an
/// unwritable folder fails at once.
pub fn write_folder(settings: &TextureBenchSettings, out: &Path) -> anyhow::Result<Written> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let report = run_texture_bench(settings)?;
    for img in &report.images {
        let path = out.join(format!("{}.png", img.name));
        volsplat_io::write_png_gray(&path, &img.image, 0.0, 1.0, volsplat_io::PngBitDepth::Eight)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    let markdown = report.to_markdown();
    let path = out.join("report.md");
    volsplat_io::write_bytes_atomic(&path, markdown.as_bytes())
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(Written {
        report: path,
        markdown,
        images: report.images.len(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::metrics::snr_db;

    #[test]
    fn quick_bench_runs_and_reproduces_chapter_5_orderings() {
        let report = run_texture_bench(&TextureBenchSettings::quick()).unwrap();
        let md = report.to_markdown();
        eprintln!("{md}");
        let row = |n: &str| report.rows.iter().find(|r| r.technique == n).unwrap();
        // Every scored row has an MSE; NIL never produces NaN.
        for r in &report.rows {
            if r.reference.is_some() {
                assert!(r.mse.is_some_and(|m| m.is_finite()), "{}", r.technique);
            }
        }
        // Gauss-27 approximates the Simpson box reference closely (anchor 1: ≥ 40 dB in the thesis).
        assert!(row("Direct Gauss-27 (box)").snr_db.unwrap() > 35.0);
        // … and reaches the anchor where footprints span at most one texture period (the rest of
        // its error comes from footprints spanning many periods, towards the horizon).
        let g27 = row("Direct Gauss-27 (box)");
        assert!(snr_db(g27.mse_small_footprints.unwrap()) >= 40.0, "{g27:?}");
        assert!(g27.mse_small_footprints.unwrap() < 0.5 * g27.mse.unwrap());
        // NIL: on the thin V_tan the fallbacks are the same for M=1 and M=4 (no node in the slab).
        assert_eq!(
            row("NIL, M=1, tol=10").fallbacks,
            row("NIL, M=4, tol=10").fallbacks
        );
        // Depth study (thick V_tan): Table 5.6's ordering — M=4 beats M=1 at every tolerance
        // (by more than 2×) and both fall as the tolerance shrinks.
        let depth = |n: &str| {
            report
                .depth_rows
                .iter()
                .find(|r| r.technique == n)
                .and_then(|r| r.mse)
                .unwrap()
        };
        for t in [10, 2] {
            assert!(
                depth(&format!("NIL, M=4, tol={t}")) < 0.5 * depth(&format!("NIL, M=1, tol={t}"))
            );
        }
        for m in [1, 4] {
            assert!(depth(&format!("NIL, M={m}, tol=2")) < depth(&format!("NIL, M={m}, tol=10")));
        }
        // Patch-order convergence: constant and linear second order, cubic faster.
        let conv = &report.convergence;
        assert_eq!(conv.len(), 4);
        assert!(conv[3].last_order() > 3.0 && (1.6..2.5).contains(&conv[0].last_order()));
        // The Simpson reference is close to the closed-form box.
        assert!(row("Direct Simpson's (box)").mse_exact_box.unwrap() < 2.0);
        assert!(
            report
                .images
                .iter()
                .any(|i| i.name.starts_with("plate_5_1_"))
        );
        assert!(!report.findings.is_empty());
    }

    #[test]
    fn patch_orders_converge_at_their_rates() {
        // Uniform hierarchies (γ = −1 … −4) and a smooth filter: the constant patch (node at the
        // centre) is a midpoint rule and the linear one (nodes on the faces) a trapezoid rule —
        // both second order, the linear one with about twice the error — so "M=2 worse than M=1"
        // is a property of the Lagrange nodes, not a bug; M = 3, 4 converge at fourth order.
        let tex = CosineTexture::seeded(4, 1).unwrap();
        let rows = patch_order_convergence(&tex).unwrap();
        for r in &rows {
            eprintln!("M={}: {:?} order {:.2}", r.order, r.errors, r.last_order());
        }
        let fine = |m: usize| rows[m - 1].errors.last().unwrap().1.abs();
        for m in [1, 2] {
            let p = rows[m - 1].last_order();
            assert!((1.6..2.5).contains(&p), "M={m}: order {p}");
        }
        for m in [3, 4] {
            let p = rows[m - 1].last_order();
            assert!(p > 3.0, "M={m}: order {p}");
            assert!(fine(m) < 0.05 * fine(1), "M={m}");
        }
        let ratio = fine(2) / fine(1);
        assert!(
            (1.3..2.5).contains(&ratio),
            "trapezoid/midpoint ratio {ratio}"
        );
    }
}
