//! The rows of the main comparison table (the analogue of Tables 5.1, 5.2, 5.4, 5.6): which
//! technique each row renders, the row its image is scored against, and the plate it becomes.
//! Row numbers are 1-based and fixed by the order here: rows 4 (Simpson box) and 6 (Simpson
//! Gaussian) are the references the others cite.

use super::TextureBenchSettings;
use volsplat_filter::Result;
use volsplat_filter::clamp::{ClampKind, ClampSettings};
use volsplat_filter::direct::{DirectSettings, QuadratureRule};
use volsplat_filter::ewa::{EwaCentre, EwaSettings, EwaVariant, SampleCount};
use volsplat_filter::filters::FilterKind;
use volsplat_filter::nil::NilSettings;
use volsplat_filter::render::{RegionKind, Rendered, Technique, render};
use volsplat_filter::scene::Scene;
use volsplat_filter::texture::SolidTexture;

/// Row number of the Simpson box reference in the main table.
const BOX_REFERENCE: usize = 4;
/// Row number of the Simpson Gaussian reference in the main table.
const GAUSSIAN_REFERENCE: usize = 6;

/// One row of a comparison table before it is rendered.
pub(super) struct PlanRow {
    /// Technique and parameters, as the table shows them.
    pub(super) label: String,
    /// What renders the row.
    pub(super) technique: Technique,
    /// Row number (1-based) of the image this row is scored against; `None` for a reference.
    pub(super) reference: Option<usize>,
    /// File-name prefix of the plate showing this row's image (e.g. `plate_5_1`), if any.
    pub(super) plate: Option<&'static str>,
}

impl PlanRow {
    /// A row with a label, technique, reference row and plate.
    pub(super) fn new(
        label: impl Into<String>,
        technique: Technique,
        reference: Option<usize>,
        plate: Option<&'static str>,
    ) -> Self {
        PlanRow {
            label: label.into(),
            technique,
            reference,
            plate,
        }
    }
}

/// Direct evaluation over `V_tan` with `rule` and `filter` at the settings' reference
/// tolerance and depth cap (§4-2).
pub(super) fn direct(
    settings: &TextureBenchSettings,
    rule: QuadratureRule,
    filter: FilterKind,
) -> Technique {
    Technique::Direct {
        settings: DirectSettings {
            rule,
            filter,
            tolerance: settings.reference_tolerance,
            max_depth: settings.max_depth,
        },
        region: RegionKind::Tangent,
    }
}

/// The settings' Gaussian filter `exp(−α(s²+t²))`.
pub(super) fn gaussian(settings: &TextureBenchSettings) -> FilterKind {
    FilterKind::Gaussian {
        alpha: settings.gaussian_alpha,
    }
}

/// EWA with the settings' Gaussian exponent (§4-3).
fn ewa_settings(
    settings: &TextureBenchSettings,
    variant: EwaVariant,
    count: SampleCount,
    max_samples: usize,
) -> EwaSettings {
    EwaSettings {
        variant,
        count,
        max_samples,
        alpha: settings.gaussian_alpha,
        ..Default::default()
    }
}

/// A NIL row with patch order `m` and tolerance `tol` filtering with the settings' Gaussian
/// (§4-4), scored against `reference`.
pub(super) fn nil_row(
    settings: &TextureBenchSettings,
    m: usize,
    tol: usize,
    reference: usize,
    plate: Option<&'static str>,
) -> PlanRow {
    PlanRow::new(
        format!("NIL, M={m}, tol={tol}"),
        Technique::Nil {
            order: m,
            settings: NilSettings {
                tolerance: tol,
                ..Default::default()
            },
            filter: gaussian(settings),
        },
        Some(reference),
        plate,
    )
}

/// Every row of the main table, in table order.
pub(super) fn main_plan(settings: &TextureBenchSettings) -> Vec<PlanRow> {
    let mut plan = reference_rows(settings);
    plan.extend(nil_rows(settings));
    plan.extend(ewa_rows(settings));
    plan.extend(extra_rows(settings));
    plan
}

/// Rows 1–6: point sampling, step and quadratic clamping (§4-1), and direct evaluation with
/// Simpson's and Gauss-27 rules — rows 4 and 6 are the box and Gaussian references.
fn reference_rows(settings: &TextureBenchSettings) -> Vec<PlanRow> {
    let clamp = |kind| {
        Technique::Clamp(ClampSettings {
            kind,
            phi_max: 0.25,
        })
    };
    let b = Some(BOX_REFERENCE);
    vec![
        PlanRow::new(
            "Point sampled",
            Technique::PointSample,
            b,
            Some("plate_5_1"),
        ),
        PlanRow::new("Step clamped", clamp(ClampKind::Step), b, Some("plate_5_2")),
        PlanRow::new(
            "Quadratic clamped",
            clamp(ClampKind::Quadratic),
            b,
            Some("plate_5_3"),
        ),
        PlanRow::new(
            "Direct Simpson's (box)",
            direct(settings, QuadratureRule::AdaptiveSimpson, FilterKind::Box),
            None,
            Some("plate_5_4"),
        ),
        PlanRow::new(
            "Direct Gauss-27 (box)",
            direct(settings, QuadratureRule::Gauss3, FilterKind::Box),
            b,
            None,
        ),
        PlanRow::new(
            "Direct Simpson's (Gaussian)",
            direct(
                settings,
                QuadratureRule::AdaptiveSimpson,
                gaussian(settings),
            ),
            None,
            Some("plate_5_5"),
        ),
    ]
}

/// The NIL rows (Table 5.6): every patch order by every tolerance; Plates 5.9–5.12 at
/// tolerances 5 and 2.
fn nil_rows(settings: &TextureBenchSettings) -> Vec<PlanRow> {
    let mut rows = Vec::new();
    for &m in &settings.nil_orders {
        for &tol in &settings.nil_tolerances {
            let plate = match (m, tol) {
                (1, 5) => Some("plate_5_9"),
                (4, 5) => Some("plate_5_10"),
                (1, 2) => Some("plate_5_11"),
                (4, 2) => Some("plate_5_12"),
                _ => None,
            };
            rows.push(nil_row(settings, m, tol, GAUSSIAN_REFERENCE, plate));
        }
    }
    rows
}

/// The EWA rows (Table 5.4): EWA-3 adaptive at every max-samples value (Plates 5.7 and 5.8 at
/// the first and last), the fixed and EWA-2 variants at 11 (or the last value), and two
/// probes of the thesis's EWA error at the last value.
fn ewa_rows(settings: &TextureBenchSettings) -> Vec<PlanRow> {
    let g = Some(GAUSSIAN_REFERENCE);
    let ewa = |variant, count, n| ewa_settings(settings, variant, count, n);
    let mut rows = Vec::new();
    let last = settings.ewa_max_samples.len().saturating_sub(1);
    for (k, &n) in settings.ewa_max_samples.iter().enumerate() {
        let plate = if k == 0 {
            Some("plate_5_7")
        } else if k == last {
            Some("plate_5_8")
        } else {
            None
        };
        rows.push(PlanRow::new(
            format!("EWA-3 adaptive ({n})"),
            Technique::Ewa(ewa(EwaVariant::Ewa3, SampleCount::Adaptive, n)),
            g,
            plate,
        ));
    }
    if let Some(&n) = settings
        .ewa_max_samples
        .iter()
        .find(|&&n| n == 11)
        .or(settings.ewa_max_samples.last())
    {
        for (label, variant, count) in [
            ("EWA-3 fixed", EwaVariant::Ewa3, SampleCount::Fixed),
            ("EWA-2 adaptive", EwaVariant::Ewa2, SampleCount::Adaptive),
            ("EWA-2 fixed", EwaVariant::Ewa2, SampleCount::Fixed),
        ] {
            rows.push(PlanRow::new(
                format!("{label} ({n})"),
                Technique::Ewa(ewa(variant, count, n)),
                g,
                None,
            ));
        }
    }
    if let Some(&n) = settings.ewa_max_samples.last() {
        // Figs 4.15/4.16: the thesis blames EWA's error on centring the Gaussian at the
        // ellipse centre; the same EWA centred at the pixel's ray hit measures that effect.
        rows.push(PlanRow::new(
            format!("EWA-3 adaptive ({n}), centred at the ray hit"),
            Technique::Ewa(EwaSettings {
                centre: EwaCentre::PixelRay,
                ..ewa(EwaVariant::Ewa3, SampleCount::Adaptive, n)
            }),
            g,
            None,
        ));
        // A Gaussian four times narrower than the reference's: a kernel-width mismatch.
        rows.push(PlanRow::new(
            format!(
                "EWA-3 adaptive ({n}), α = {}",
                4.0 * settings.gaussian_alpha
            ),
            Technique::Ewa(EwaSettings {
                alpha: 4.0 * settings.gaussian_alpha,
                ..ewa(EwaVariant::Ewa3, SampleCount::Adaptive, n)
            }),
            g,
            None,
        ));
    }
    rows
}

/// The rows beyond the thesis's tables: Norton clamping, the hybrid-75 rule (box) and
/// Gauss-27 with the Gaussian.
fn extra_rows(settings: &TextureBenchSettings) -> Vec<PlanRow> {
    vec![
        PlanRow::new(
            "Norton clamped",
            Technique::Clamp(ClampSettings {
                kind: ClampKind::Norton,
                phi_max: 0.25,
            }),
            Some(BOX_REFERENCE),
            None,
        ),
        PlanRow::new(
            "Direct hybrid-75 (box)",
            direct(settings, QuadratureRule::Hybrid, FilterKind::Box),
            Some(BOX_REFERENCE),
            None,
        ),
        PlanRow::new(
            "Direct Gauss-27 (Gaussian)",
            direct(settings, QuadratureRule::Gauss3, gaussian(settings)),
            Some(GAUSSIAN_REFERENCE),
            None,
        ),
    ]
}

/// Renders every row of `plan` in order (each render is itself parallel over pixels).
pub(super) fn render_plan(
    scene: &Scene,
    texture: &dyn SolidTexture,
    plan: &[PlanRow],
) -> Result<Vec<Rendered>> {
    plan.iter()
        .map(|row| render(scene, texture, &row.technique))
        .collect()
}
