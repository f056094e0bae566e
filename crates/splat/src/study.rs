//! Measurements of anti-aliasing (Swan et al. 1997 §5, Fig. 7), shared by the tests and by
//! `volsplat aa-figures`.
//!
//! - [`minification_error`]: an orthographic view of a one-voxel sheet of fine squares at
//!   several voxels per pixel. The alias-free image is the sheet's average colour everywhere
//!   inside it; the error is the RMS deviation from it, relative to the red–white contrast.
//! - [`perspective_errors`]: a perspective view against a reference rendered at `factor`× the
//!   resolution and box-filtered down, split at the distance `k` (eq. 3).
//! - [`temporal_highpass`]: flicker of an animation, the mean energy of the second temporal
//!   difference `f(t+1) − 2f(t) + f(t−1)` over a region.
//!
//! Errors are RMS over the R, G, B channels of premultiplied colour (over black).

use crate::aa::Antialias;
use crate::error::{Result, SplatError};
use crate::list::{SplatList, k_distance, render_list, render_list_depth};
use crate::render::RenderSettings;
use volsplat_core::glam::DVec3;
use volsplat_core::{Camera, CrioTables, Image, Projection, ScalarImage, Volume, scenes};

/// The perspective view of the `nx × ny` checkerboard sheet used for Fig. 7a–b: the eye 24
/// voxels above the sheet's first corner, looking along its diagonal and slightly down, with a
/// 90° field of view, so the sheet runs from several pixels per voxel at the bottom of the image
/// to about ten voxels per pixel at the far corner (`k` ≈ 78 voxels at 157 rows; the far corner
/// is about 8k away). Sheet in the plane `z = 0`, origin at its first voxel, unit spacing.
pub fn checkerboard_camera(nx: usize, ny: usize) -> Camera {
    let (fx, fy) = (nx as f64 * 0.4, ny as f64 * 0.4);
    Camera {
        position: [-6.0, -6.0, 24.0],
        focal_point: [fx, fy, 0.0],
        view_up: [0.0, 0.0, 1.0],
        view_angle: 90.0,
        parallel_projection: false,
        parallel_scale: 1.0,
    }
}

/// Averages `f × f` blocks of pixels (the box pre-filter of a supersampled reference).
pub fn box_downsample(img: &Image, f: usize) -> Result<Image> {
    let (w, h) = (img.width() / f.max(1), img.height() / f.max(1));
    if f == 0 || w == 0 || h == 0 || img.width() != w * f || img.height() != h * f {
        return Err(SplatError::Settings(format!(
            "cannot box-downsample {}×{} by {f}",
            img.width(),
            img.height()
        )));
    }
    let src = img.pixels();
    let inv = 1.0 / (f * f) as f32;
    let mut out = Vec::with_capacity(w * h);
    for y in 0..h {
        for x in 0..w {
            let mut acc = [0.0f32; 4];
            for yy in 0..f {
                for p in &src[(y * f + yy) * img.width() + x * f..][..f] {
                    for c in 0..4 {
                        acc[c] += p[c];
                    }
                }
            }
            out.push(acc.map(|v| v * inv));
        }
    }
    Image::from_pixels(w, h, out).ok_or_else(|| SplatError::Settings("image size".into()))
}

/// RMS difference over R, G, B of two premultiplied images, over the pixels where `mask` is
/// true (all pixels if `None`). `NaN` if the mask is empty.
pub fn rms_rgb(a: &Image, b: &Image, mask: Option<&[bool]>) -> f64 {
    let (mut sum, mut n) = (0.0f64, 0usize);
    for (i, (p, q)) in a.pixels().iter().zip(b.pixels()).enumerate() {
        if mask.is_some_and(|m| !m[i]) {
            continue;
        }
        for c in 0..3 {
            let d = (p[c] - q[c]) as f64;
            sum += d * d;
        }
        n += 3;
    }
    (sum / n as f64).sqrt()
}

/// Splits the pixels with a finite depth into those in front of `k` and those beyond it.
pub fn depth_regions(depth: &ScalarImage, k: f64) -> (Vec<bool>, Vec<bool>) {
    let d = depth.values();
    (
        d.iter().map(|&v| v.is_finite() && (v as f64) < k).collect(),
        d.iter()
            .map(|&v| v.is_finite() && (v as f64) >= k)
            .collect(),
    )
}

/// Error of one anti-aliasing rule against the supersampled reference, split at `k`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RegionErrors {
    /// The rule.
    pub antialias: Antialias,
    /// RMS error over every pixel the sheet covers.
    pub whole: f64,
    /// RMS error in front of `k`.
    pub before_k: f64,
    /// RMS error beyond `k`, over the pixels where the reference has converged (see
    /// [`perspective_errors`]).
    pub beyond_k: f64,
    /// RMS error over every pixel beyond `k`, converged or not.
    pub beyond_k_all: f64,
    /// RMS change from the un-anti-aliased image in front of `k`, relative to that image's
    /// RMS value there.
    pub before_k_change: f64,
}

/// Renders `list` with each rule at `w × h` and compares with the same scene rendered with
/// Swan's rule at `factor × w` by `factor × h` and box-filtered down (there splats cover
/// `factor²` as many pixels and `k` moves `factor` times farther). Where the scene is finer
/// than even the supersampled raster (near the horizon of a grazing view) the box-filtered
/// reference is itself aliased; a pixel counts as converged where the references at `factor`
/// and `factor/2` agree within 0.02 RMS. Returns `k`, the fraction of pixels beyond `k` that
/// converged, and the errors.
pub fn perspective_errors(
    list: &SplatList,
    camera: &Camera,
    tables: &CrioTables,
    base: &RenderSettings,
    factor: usize,
) -> Result<(f64, f64, Vec<RegionErrors>)> {
    let (w, h) = (base.width, base.height);
    let supersampled = |f: usize| -> Result<Image> {
        let hi = RenderSettings {
            width: w * f,
            height: h * f,
            antialias: Antialias::Swan,
            ..base.clone()
        };
        box_downsample(&render_list(list, camera, tables, &hi)?.image, f)
    };
    let reference = supersampled(factor)?;
    let half = supersampled((factor / 2).max(1))?;
    let converged: Vec<bool> = reference
        .pixels()
        .iter()
        .zip(half.pixels())
        .map(|(a, b)| {
            let d: f32 = (0..3).map(|c| (a[c] - b[c]) * (a[c] - b[c])).sum::<f32>() / 3.0;
            d.sqrt() < 0.02
        })
        .collect();
    let proj = Projection::new(camera, w, h)?;
    let k = k_distance(list.grid(), 1, &proj).ok_or_else(|| {
        SplatError::Settings("perspective_errors needs a perspective camera".into())
    })?;
    let depth = render_list_depth(list, camera, tables, base)?;
    let (before, beyond_all) = depth_regions(&depth, k);
    let beyond: Vec<bool> = beyond_all
        .iter()
        .zip(&converged)
        .map(|(a, b)| *a && *b)
        .collect();
    let n_beyond = beyond_all.iter().filter(|&&b| b).count().max(1);
    let frac = beyond.iter().filter(|&&b| b).count() as f64 / n_beyond as f64;
    let covered: Vec<bool> = before
        .iter()
        .zip(&beyond_all)
        .map(|(a, b)| *a || *b)
        .collect();
    let plain = render_list(
        list,
        camera,
        tables,
        &RenderSettings {
            antialias: Antialias::None,
            ..base.clone()
        },
    )?
    .image;
    let black = Image::new(w, h);
    let plain_rms = rms_rgb(&plain, &black, Some(&before));
    let mut out = Vec::new();
    for aa in [
        Antialias::None,
        Antialias::Swan,
        Antialias::SwanPerpendicular,
        Antialias::Ewa,
    ] {
        let img = render_list(
            list,
            camera,
            tables,
            &RenderSettings {
                antialias: aa,
                ..base.clone()
            },
        )?
        .image;
        out.push(RegionErrors {
            antialias: aa,
            whole: rms_rgb(&img, &reference, Some(&covered)),
            before_k: rms_rgb(&img, &reference, Some(&before)),
            beyond_k: rms_rgb(&img, &reference, Some(&beyond)),
            beyond_k_all: rms_rgb(&img, &reference, Some(&beyond_all)),
            before_k_change: rms_rgb(&img, &plain, Some(&before)) / plain_rms,
        });
    }
    Ok((k, frac, out))
}

/// The flicker of a dolly: `frames` renders with the eye moving `step` world units per frame
/// along the view direction, measured as the mean over frames and masked pixels of the squared
/// second temporal difference (RGB). The mask is the region beyond `k` in the middle frame.
pub fn temporal_highpass(
    list: &SplatList,
    camera: &Camera,
    tables: &CrioTables,
    settings: &RenderSettings,
    frames: usize,
    step: f64,
) -> Result<f64> {
    if frames < 3 {
        return Err(SplatError::Settings(
            "temporal_highpass needs ≥ 3 frames".into(),
        ));
    }
    let at = |t: usize| {
        let mut c = camera.clone();
        let f = c.frame();
        let d = f.forward * (step * t as f64);
        c.position = (DVec3::from(c.position) + d).to_array();
        c.focal_point = (DVec3::from(c.focal_point) + d).to_array();
        c
    };
    let mid = at(frames / 2);
    let proj = Projection::new(&mid, settings.width, settings.height)?;
    let k = k_distance(list.grid(), 1, &proj).unwrap_or(0.0);
    let depth = render_list_depth(list, &mid, tables, settings)?;
    let (_, beyond) = depth_regions(&depth, k);
    let imgs: Vec<Image> = (0..frames)
        .map(|t| Ok(render_list(list, &at(t), tables, settings)?.image))
        .collect::<Result<_>>()?;
    let (mut sum, mut n) = (0.0f64, 0usize);
    for t in 1..frames - 1 {
        let (a, b, c) = (imgs[t - 1].pixels(), imgs[t].pixels(), imgs[t + 1].pixels());
        for i in 0..a.len() {
            if !beyond[i] {
                continue;
            }
            for ch in 0..3 {
                let d = (c[i][ch] - 2.0 * b[i][ch] + a[i][ch]) as f64;
                sum += d * d;
                n += 1;
            }
        }
    }
    Ok(sum / n.max(1) as f64)
}

/// Orthographic minification of an `n × n × 1` checkerboard sheet of `square × square`-voxel
/// squares, seen face-on at `voxels_per_pixel`: the RMS deviation from the sheet's uniform
/// average colour over the pixels at least two pixels inside the sheet, relative to the
/// red–white contrast. The average colour is measured by rendering uniformly red and uniformly
/// white sheets the same way (so footprint normalisation errors do not count as aliasing).
pub fn minification_error(
    n: usize,
    square: usize,
    voxels_per_pixel: f64,
    settings: &RenderSettings,
    use_list: bool,
) -> Result<f64> {
    let sheet = scenes::checkerboard_sheet(n, n, square)?;
    let uniform = |v: f32| Volume::from_fn(sheet.grid().clone(), |_, _, _| v);
    let tables = CrioTables::from_transfer_function(&scenes::checkerboard_tf(), 1024)?;
    let px = (n as f64 / voxels_per_pixel).round() as usize;
    let c = (n as f64 - 1.0) * 0.5;
    let camera = Camera {
        position: [c, c, 100.0],
        focal_point: [c, c, 0.0],
        view_up: [0.0, 1.0, 0.0],
        view_angle: 30.0,
        parallel_projection: true,
        parallel_scale: n as f64 * 0.5,
    };
    let s = RenderSettings {
        width: px,
        height: px,
        ..settings.clone()
    };
    let draw = |v: &Volume<f32>| -> Result<Image> {
        if use_list {
            let list = SplatList::build(v, &tables, &Default::default())?;
            Ok(render_list(&list, &camera, &tables, &s)?.image)
        } else {
            Ok(crate::render::render(v, &camera, &tables, &s)?.image)
        }
    };
    let img = draw(&sheet)?;
    let red = draw(&uniform(scenes::CHECKER_RED)?)?;
    let white = draw(&uniform(scenes::CHECKER_WHITE)?)?;
    let (mut sum, mut count, mut contrast) = (0.0f64, 0usize, 0.0f64);
    for y in 2..px.saturating_sub(2) {
        for x in 2..px.saturating_sub(2) {
            let i = y * px + x;
            let (p, r, w) = (img.pixels()[i], red.pixels()[i], white.pixels()[i]);
            for ch in 0..3 {
                let mean = 0.5 * (r[ch] + w[ch]) as f64;
                let d = p[ch] as f64 - mean;
                sum += d * d;
                contrast += ((r[ch] - w[ch]) as f64).powi(2);
                count += 1;
            }
        }
    }
    if count == 0 {
        return Err(SplatError::Settings("image too small to measure".into()));
    }
    Ok((sum / contrast).sqrt())
}
