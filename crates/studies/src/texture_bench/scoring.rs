//! Scoring rendered images (thesis §5-2): the 8-bit MSE and SNR of each row against its
//! reference row, over the whole image, over the small footprints and against the closed-form
//! box, and the share of the NIL fallbacks in the error.

use super::plan::PlanRow;
use super::{ReportRow, SMALL_FOOTPRINT};
use crate::metrics::snr_db;
use volsplat_core::ScalarImage;
use volsplat_filter::render::Rendered;
use volsplat_filter::scene::{Footprint, Scene};

/// Same-size images: the 8-bit MSE of thesis §5-2; `None` if the sizes differ or the images
/// are empty.
pub(super) fn mse_8bit(a: &ScalarImage, b: &ScalarImage) -> Option<f64> {
    mse_8bit_where(a, b, |_| true)
}

/// [`mse_8bit`] over the pixels (row-major index) for which `keep` is true; `None` if the sizes
/// differ or no pixel is kept.
pub(super) fn mse_8bit_where(
    a: &ScalarImage,
    b: &ScalarImage,
    keep: impl Fn(usize) -> bool,
) -> Option<f64> {
    if a.width() != b.width() || a.height() != b.height() {
        return None;
    }
    let m = crate::metrics::mse_8bit_where(a.values(), b.values(), keep);
    (!m.is_nan()).then_some(m)
}

/// Per pixel: `None` if the pixel does not hit the object with a regular footprint, else
/// whether its ellipse's semi-major axis is at most [`SMALL_FOOTPRINT`].
pub(super) fn small_footprint_mask(scene: &Scene) -> Vec<Option<bool>> {
    let (w, h) = (scene.width(), scene.height());
    (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .map(|(x, y)| match scene.footprint(x, y) {
            Footprint::Hit(fp) => Some(fp.ellipse.major() <= SMALL_FOOTPRINT),
            _ => None,
        })
        .collect()
}

/// Pixel counts of the main scene used by the findings.
pub(super) struct SceneStats {
    /// All pixels.
    pub(super) pixels: usize,
    /// Pixels with a regular footprint.
    pub(super) hits: usize,
    /// Of those, pixels with a small footprint.
    pub(super) small: usize,
}

/// Scores rendered images: MSE/SNR against the reference row, MSE over small footprints,
/// MSE against the exact box, fallback counts and their MSE share.
pub(super) fn score(
    plan: &[PlanRow],
    rendered: &[Rendered],
    exact: &ScalarImage,
    small: &[Option<bool>],
) -> Vec<ReportRow> {
    let mut rows = Vec::with_capacity(plan.len());
    for (i, (row, r)) in plan.iter().zip(rendered).enumerate() {
        let refimg = row
            .reference
            .and_then(|k| rendered.get(k - 1))
            .map(|x| &x.image);
        let mse = refimg.and_then(|ri| mse_8bit(&r.image, ri));
        let mse_small = refimg
            .and_then(|ri| mse_8bit_where(&r.image, ri, |p| small.get(p) == Some(&Some(true))));
        let fallback_mse_share = refimg.and_then(|ri| {
            let n = r.image.values().len() as f64;
            let k = r.fallback_pixels.len() as f64;
            if k == 0.0 {
                return Some(0.0);
            }
            mse_8bit_where(&r.image, ri, |p| {
                r.fallback_pixels.binary_search(&p).is_ok()
            })
            .map(|m| m * k / n)
        });
        rows.push(ReportRow {
            index: i + 1,
            technique: row.label.clone(),
            seconds: r.seconds,
            preprocess_seconds: r.preprocess_seconds,
            work: r.work,
            reference: row.reference,
            mse,
            snr_db: mse.map(snr_db),
            mse_small_footprints: mse_small,
            mse_exact_box: mse_8bit(&r.image, exact),
            fallbacks: r.fallbacks,
            fallback_mse_share,
        });
    }
    rows
}
