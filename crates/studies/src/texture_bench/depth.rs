//! The depth study: the NIL and EWA rows of the main table on the same plane with a thick
//! `V_tan`, where the NIL cells can resolve the filter's depth (see
//! `docs/texture-bench/findings.md`).

use super::plan::{PlanRow, direct, gaussian, nil_row, render_plan};
use super::scoring::{score, small_footprint_mask};
use super::{ReportRow, TextureBenchSettings};
use volsplat_filter::Result;
use volsplat_filter::direct::QuadratureRule;
use volsplat_filter::ewa::{EwaSettings, EwaVariant, SampleCount};
use volsplat_filter::render::{Technique, render};
use volsplat_filter::scene::{Scene, SceneSettings};
use volsplat_filter::texture::CosineTexture;

/// Image size of the depth study: half the main image, at least 32 × 24 pixels.
pub(super) fn depth_size(settings: &TextureBenchSettings) -> (usize, usize) {
    (
        settings.width.div_ceil(2).max(32),
        settings.height.div_ceil(2).max(24),
    )
}

/// The depth study: the NIL and EWA rows of the main table on the same plane with a thick
/// `V_tan` (`ε = thick`), scored against a Simpson Gaussian reference at that `ε` (row 1).
pub(super) fn depth_study(
    settings: &TextureBenchSettings,
    tex: &CosineTexture,
    thick: f64,
) -> Result<Vec<ReportRow>> {
    let (w, h) = depth_size(settings);
    let mut ss = SceneSettings::test_plane(w, h);
    ss.epsilon = thick;
    let scene = Scene::new(ss)?;
    let plan = depth_plan(settings, thick);
    let exact = render(&scene, tex, &Technique::ExactBox)?;
    let rendered = render_plan(&scene, tex, &plan)?;
    let small = small_footprint_mask(&scene);
    Ok(score(&plan, &rendered, &exact.image, &small))
}

/// The depth study's rows: the Simpson Gaussian reference at `ε = thick` (row 1), point
/// sampling, every NIL order by tolerance, EWA-3 adaptive at every max-samples value and
/// EWA-2 adaptive at the last, all scored against row 1.
fn depth_plan(settings: &TextureBenchSettings, thick: f64) -> Vec<PlanRow> {
    let mut plan = vec![
        PlanRow::new(
            format!("Direct Simpson's (Gaussian), ε={thick}"),
            direct(
                settings,
                QuadratureRule::AdaptiveSimpson,
                gaussian(settings),
            ),
            None,
            None,
        ),
        PlanRow::new("Point sampled", Technique::PointSample, Some(1), None),
    ];
    for &m in &settings.nil_orders {
        for &tol in &settings.nil_tolerances {
            plan.push(nil_row(settings, m, tol, 1, None));
        }
    }
    let ewa = |variant, n| {
        Technique::Ewa(EwaSettings {
            variant,
            count: SampleCount::Adaptive,
            max_samples: n,
            alpha: settings.gaussian_alpha,
            ..Default::default()
        })
    };
    for &n in &settings.ewa_max_samples {
        plan.push(PlanRow::new(
            format!("EWA-3 adaptive ({n})"),
            ewa(EwaVariant::Ewa3, n),
            Some(1),
            None,
        ));
    }
    if let Some(&n) = settings.ewa_max_samples.last() {
        plan.push(PlanRow::new(
            format!("EWA-2 adaptive ({n})"),
            ewa(EwaVariant::Ewa2, n),
            Some(1),
            None,
        ));
    }
    plan
}
