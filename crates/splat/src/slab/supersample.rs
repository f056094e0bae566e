//! Anti-aliasing of minified views: more rays than pixels where a pixel spans more than a
//! voxel, filtered down to the picture (decision 0020).

use super::{Access, render_slabs_in};
use crate::bricks::BrickGrid;
use crate::error::Result;
use crate::sheets::{Progress, RenderSettings, Rendered, validate};
use volsplat_core::{Camera, CrioTables, Image, Projection, Scalar, ScalarImage};

/// Sub-pixel rays per pixel and axis for the anti-aliasing of minified views, from `r`, the
/// pixel's size at the volume's centre over the smallest voxel spacing: 1 where a voxel spans a
/// pixel (`r ≤ 1`, up to rounding) or with [`crate::aa::Antialias::None`]; `r` itself, a
/// fraction, below [`WHOLE_RAYS_FROM`], so that a pixel a few percent larger than a voxel costs
/// a few percent more rays, not 4× (a CT whose in-plane spacing is just under the pixel;
/// decision 0020); `⌈r⌉` (at most 4) from there on, each pixel the box average of
/// `⌈r⌉ × ⌈r⌉` rays, as before. Perspective views measure the pixel at the depth of the volume's
/// centre.
pub(super) fn supersampling(
    settings: &RenderSettings,
    proj: &Projection,
    grid: &volsplat_core::Grid,
    min_spacing: f64,
) -> f64 {
    if settings.antialias == crate::aa::Antialias::None {
        return 1.0;
    }
    let frame = proj.frame();
    let depth = (grid.center_world() - frame.eye).dot(frame.forward);
    if (depth.is_nan() || depth <= 0.0) && matches!(proj, Projection::Perspective(_)) {
        return 1.0;
    }
    let ratio = proj.pixel_size_at(depth) / min_spacing;
    // A little slack so that one voxel per pixel, up to rounding, is not supersampled.
    if !(ratio.is_finite() && ratio > 1.0 + 1e-3) {
        1.0
    } else if ratio < WHOLE_RAYS_FROM {
        ratio
    } else {
        (ratio - 1e-3).ceil().min(4.0)
    }
}

/// Where the anti-aliasing of minified views (`supersampling`) turns from fractional rays per
/// pixel to whole ones: pixel sizes of 1.5 voxels and more take `⌈r⌉ × ⌈r⌉` rays.
pub const WHOLE_RAYS_FROM: f64 = 1.5;

/// The weights of the fine pixels `0..fine` that cover each of the coarse pixels `0..n` along
/// one axis, for fine pixels of `step` coarse pixels starting `offset` coarse pixels before the
/// coarse image's edge: per coarse pixel the first fine pixel and the fractions of the coarse
/// pixel that each fine pixel covers (summing to 1 where the fine image covers it).
fn area_weights(n: usize, fine: usize, step: f64, offset: f64) -> Vec<(usize, Vec<f32>)> {
    (0..n)
        .map(|x| {
            let (a, b) = (x as f64, x as f64 + 1.0);
            let first = (((a + offset) / step).floor().max(0.0) as usize).min(fine - 1);
            let mut w = Vec::new();
            let mut i = first;
            while i < fine {
                let (fa, fb) = (i as f64 * step - offset, (i + 1) as f64 * step - offset);
                if fa >= b {
                    break;
                }
                w.push((fb.min(b) - fa.max(a)).max(0.0) as f32);
                i += 1;
            }
            (first, w)
        })
        .collect()
}

/// [`render_slabs`] at `ss` times the size, filtered down ([`supersampling`]): for a whole `ss`,
/// each pixel the box average of its `ss × ss` rays; for a fraction, `⌈H·ss⌉` rows and as many
/// columns as keep the camera's aspect without narrowing the view, each pixel the mean of the
/// fine pixels over its area, weighted by the part of it each covers.
pub(super) fn render_supersampled<T: Scalar>(
    volume: &mut Access<'_, T>,
    camera: &Camera,
    tables: &CrioTables,
    settings: &RenderSettings,
    bricks: &BrickGrid,
    progress: &mut dyn FnMut(&Progress) -> bool,
    ss: f64,
) -> Result<Rendered> {
    if ss.fract() == 0.0 {
        return render_box_supersampled(
            volume,
            camera,
            tables,
            settings,
            bricks,
            progress,
            ss as usize,
        );
    }
    let (w, h) = (settings.width, settings.height);
    // The view's height spans the rows; its width is the aspect times that, so the fine pixels
    // are square of `h / fh` coarse pixels, and the fine image is centred on the coarse one.
    let fh = (h as f64 * ss - 1e-9).ceil() as usize;
    let step = h as f64 / fh as f64;
    let fw = ((w as f64 / step) - 1e-9).ceil() as usize;
    let fine = RenderSettings {
        width: fw,
        height: fh,
        antialias: crate::aa::Antialias::None,
        ..settings.clone()
    };
    validate(&fine)?;
    let out = render_slabs_in(volume, camera, tables, &fine, bricks, progress)?;
    let x_off = 0.5 * (fw as f64 * step - w as f64);
    let (wx, wy) = (
        area_weights(w, fw, step, x_off),
        area_weights(h, fh, step, 0.0),
    );
    let fine_px = out.image.pixels();
    let mut pixels = vec![[0.0f32; 4]; w * h];
    for (i, px) in pixels.iter_mut().enumerate() {
        let ((x0, cx), (y0, cy)) = (&wx[i % w], &wy[i / w]);
        let mut sum = [0.0f32; 4];
        for (dy, &ky) in cy.iter().enumerate() {
            let row = &fine_px[(y0 + dy) * fw + x0..][..cx.len()];
            for (p, &kx) in row.iter().zip(cx) {
                let k = ky * kx;
                for c in 0..4 {
                    sum[c] += k * p[c];
                }
            }
        }
        *px = sum;
    }
    // MIP/MinIP values: the weighted mean over the sub-pixel rays that met the volume (NaN if
    // none).
    let values = out.values.as_ref().map(|v| {
        let fv = v.values();
        let mut vals = vec![f32::NAN; w * h];
        for (i, val) in vals.iter_mut().enumerate() {
            let ((x0, cx), (y0, cy)) = (&wx[i % w], &wy[i / w]);
            let (mut sum, mut n) = (0.0f32, 0.0f32);
            for (dy, &ky) in cy.iter().enumerate() {
                let row = &fv[(y0 + dy) * fw + x0..][..cx.len()];
                for (&f, &kx) in row.iter().zip(cx) {
                    if !f.is_nan() && ky * kx > 0.0 {
                        sum += ky * kx * f;
                        n += ky * kx;
                    }
                }
            }
            if n > 0.0 {
                *val = sum / n;
            }
        }
        vals
    });
    let image = Image::from_pixels(w, h, pixels).unwrap_or_else(|| Image::new(w, h));
    let values = values.and_then(|v| ScalarImage::from_values(w, h, v));
    let mut stats = out.stats;
    stats.supersampling = ss;
    Ok(Rendered {
        image,
        values,
        stats,
    })
}

/// [`render_supersampled`] for a whole factor: `ss × ss` rays per pixel, box-averaged.
fn render_box_supersampled<T: Scalar>(
    volume: &mut Access<'_, T>,
    camera: &Camera,
    tables: &CrioTables,
    settings: &RenderSettings,
    bricks: &BrickGrid,
    progress: &mut dyn FnMut(&Progress) -> bool,
    ss: usize,
) -> Result<Rendered> {
    let fine = RenderSettings {
        width: settings.width * ss,
        height: settings.height * ss,
        antialias: crate::aa::Antialias::None,
        ..settings.clone()
    };
    validate(&fine)?;
    let out = render_slabs_in(volume, camera, tables, &fine, bricks, progress)?;
    let (w, h) = (settings.width, settings.height);
    let fw = fine.width;
    let inv = 1.0 / (ss * ss) as f32;
    let mut pixels = vec![[0.0f32; 4]; w * h];
    let fine_px = out.image.pixels();
    for (i, px) in pixels.iter_mut().enumerate() {
        let (x, y) = (i % w, i / w);
        let mut sum = [0.0f32; 4];
        for sy in 0..ss {
            let row = &fine_px[(y * ss + sy) * fw + x * ss..][..ss];
            for p in row {
                for c in 0..4 {
                    sum[c] += p[c];
                }
            }
        }
        *px = sum.map(|v| v * inv);
    }
    // MIP/MinIP values: the mean over the sub-pixel rays that met the volume (NaN if none).
    let values = out.values.as_ref().map(|v| {
        let fv = v.values();
        let mut vals = vec![f32::NAN; w * h];
        for (i, val) in vals.iter_mut().enumerate() {
            let (x, y) = (i % w, i / w);
            let (mut sum, mut n) = (0.0f32, 0u32);
            for sy in 0..ss {
                for &f in &fv[(y * ss + sy) * fw + x * ss..][..ss] {
                    if !f.is_nan() {
                        sum += f;
                        n += 1;
                    }
                }
            }
            if n > 0 {
                *val = sum / n as f32;
            }
        }
        vals
    });
    let image = Image::from_pixels(w, h, pixels).unwrap_or_else(|| Image::new(w, h));
    let values = values.and_then(|v| ScalarImage::from_values(w, h, v));
    let mut stats = out.stats;
    stats.supersampling = ss as f64;
    Ok(Rendered {
        image,
        values,
        stats,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The area weights of the fractional anti-aliasing: every coarse pixel inside the fine
    /// image gets weights summing to 1, each the overlap of a fine pixel with it; a whole
    /// factor gives `ss` equal weights.
    #[test]
    fn area_weights_cover_each_pixel_once() {
        for (n, ss) in [(7usize, 1.26f64), (50, 1.037), (33, 1.49), (16, 2.0)] {
            let fine = (n as f64 * ss - 1e-9).ceil() as usize;
            let step = n as f64 / fine as f64;
            for offset in [0.0, 0.5 * (fine as f64 * step - n as f64), 0.3 * step] {
                for (x, (first, w)) in area_weights(n, fine, step, offset).iter().enumerate() {
                    let sum: f32 = w.iter().sum();
                    let covered = (x as f64 + 1.0 + offset) <= fine as f64 * step + 1e-9;
                    if covered {
                        assert!((sum - 1.0).abs() < 1e-5, "n {n} ss {ss} x {x}: {sum}");
                    }
                    for (k, &wk) in w.iter().enumerate() {
                        let i = (first + k) as f64;
                        let (a, b) = (i * step - offset, (i + 1.0) * step - offset);
                        let exact = (b.min(x as f64 + 1.0) - a.max(x as f64)).max(0.0);
                        assert!((f64::from(wk) - exact).abs() < 1e-6);
                    }
                }
            }
        }
        let w = area_weights(4, 8, 0.5, 0.0);
        assert!(
            w.iter()
                .enumerate()
                .all(|(x, (f, k))| *f == 2 * x && k == &[0.5, 0.5])
        );
    }
}
