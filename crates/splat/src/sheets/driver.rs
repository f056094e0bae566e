//! The end of a sheet renderer's frame: the accumulation buffer turned into the picture.

use super::settings::{RenderMode, RenderSettings};
use crate::error::{Result, SplatError};
use volsplat_core::image::Rgba;
use volsplat_core::{CrioTables, Image, ScalarImage};

/// Turns the accumulation buffer into the output image and values, after checking that every
/// value the caller will see is finite (MIP/MinIP values may be NaN where nothing covers the
/// pixel, by definition). `stage` names the renderer in the error.
pub(crate) fn finish(
    acc: Vec<Rgba>,
    settings: &RenderSettings,
    tables: &CrioTables,
    stage: &'static str,
) -> Result<(Image, Option<ScalarImage>)> {
    let w = settings.width;
    let bad = |p: &Rgba| match settings.mode {
        RenderMode::Composite => p.iter().any(|c| !c.is_finite()),
        RenderMode::Xray => !p[0].is_finite(),
        RenderMode::Mip | RenderMode::Minip => p[0].is_infinite(),
    };
    if let Some(first) = acc.iter().position(bad) {
        return Err(SplatError::NonFinite {
            stage,
            count: acc.iter().filter(|p| bad(p)).count(),
            x: first % w,
            y: first / w,
        });
    }
    Ok(finish_unchecked(acc, settings, tables))
}

fn finish_unchecked(
    acc: Vec<Rgba>,
    settings: &RenderSettings,
    tables: &CrioTables,
) -> (Image, Option<ScalarImage>) {
    let (w, h) = (settings.width, settings.height);
    match settings.mode {
        RenderMode::Composite => {
            let img = Image::from_pixels(w, h, acc).unwrap_or_else(|| Image::new(w, h));
            (img, None)
        }
        RenderMode::Xray => {
            let values: Vec<f32> = acc.iter().map(|p| p[0]).collect();
            let max = values.iter().fold(0.0f32, |m, &v| m.max(v));
            let k = if max > 0.0 { 1.0 / max } else { 0.0 };
            let pixels = values.iter().map(|&v| {
                let g = (v * k).clamp(0.0, 1.0);
                [g, g, g, 1.0]
            });
            let img =
                Image::from_pixels(w, h, pixels.collect()).unwrap_or_else(|| Image::new(w, h));
            (img, ScalarImage::from_values(w, h, values))
        }
        RenderMode::Mip | RenderMode::Minip => {
            let values: Vec<f32> = acc.iter().map(|p| p[0]).collect();
            let pixels = values
                .iter()
                .map(|&v| {
                    if v.is_nan() {
                        return [0.0; 4];
                    }
                    let c = tables.emission.lookup(v);
                    let a = tables.opacity.lookup(v)[0].clamp(0.0, 1.0);
                    [
                        c[0].clamp(0.0, 1.0) * a,
                        c[1].clamp(0.0, 1.0) * a,
                        c[2].clamp(0.0, 1.0) * a,
                        a,
                    ]
                })
                .collect();
            let img = Image::from_pixels(w, h, pixels).unwrap_or_else(|| Image::new(w, h));
            (img, ScalarImage::from_values(w, h, values))
        }
    }
}
