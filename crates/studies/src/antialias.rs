//! The anti-aliasing study of Swan et al. 1997 (§5, Fig. 7): measurements of aliasing and
//! flicker for the splatting renderers of `volsplat-splat`, and [`write_figures`], which draws
//! the Fig. 7 figures and writes them with a Markdown report of the measurements
//! (`volsplat aa-figures`).
//!
//! - [`minification_error`]: an orthographic view of a one-voxel sheet of fine squares at
//!   several voxels per pixel. The alias-free image is the sheet's average colour everywhere
//!   inside it; the error is the RMS deviation from it, relative to the red–white contrast.
//! - [`perspective_errors`]: a perspective view against a reference rendered at `factor`× the
//!   resolution and box-filtered down, split at the distance `k` (eq. 3).
//! - [`temporal_highpass`]: flicker of an animation, the mean energy of the second temporal
//!   difference `f(t+1) − 2f(t) + f(t−1)` over a region.
//! - [`minified_box_errors`]: a volume shown small (orthographic, dense renderer) against the
//!   same scene rendered `factor`× larger without anti-aliasing and box-filtered down, the
//!   reference of issue 12 item 4 (the MRI minification table).
//!
//! Errors are RMS over the R, G, B channels of premultiplied colour (over black,
//! [`metrics::rms_rgb`](crate::metrics::rms_rgb)).

use crate::Written;
use crate::metrics::rms_rgb;
use anyhow::{Context as _, Result, bail};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;
use volsplat_core::glam::DVec3;
use volsplat_core::{Camera, CrioTables, Image, Projection, Scalar, ScalarImage, Volume, scenes};
use volsplat_io::PngSettings;
use volsplat_splat::list::{draw_depth_contour, k_distance, render_list_depth};
use volsplat_splat::{Antialias, ExtractSettings, RenderSettings, SplatList, render_list};

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
        bail!(
            "cannot box-downsample {}×{} by {f}",
            img.width(),
            img.height()
        );
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
    Image::from_pixels(w, h, out).context("image size")
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
        let hi = {
            let mut s = base.clone();
            s.width = w * f;
            s.height = h * f;
            s.antialias = Antialias::Swan;
            s
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
    let k = k_distance(list.grid(), 1, &proj)
        .context("perspective_errors needs a perspective camera")?;
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
    let plain = render_list(list, camera, tables, &{
        let mut s = base.clone();
        s.antialias = Antialias::None;
        s
    })?
    .image;
    let black = Image::new(w, h);
    let plain_rms = rms_rgb(&plain, &black, Some(&before));
    let mut out = Vec::new();
    for aa in RULES {
        let img = render_list(list, camera, tables, &{
            let mut s = base.clone();
            s.antialias = aa;
            s
        })?
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

/// The anti-aliasing rules every table of the study compares, in column order.
pub const RULES: [Antialias; 5] = [
    Antialias::None,
    Antialias::Swan,
    Antialias::SwanPerpendicular,
    Antialias::Ewa,
    Antialias::Area,
];

/// A volume shown small: renders `volume` with the dense renderer (`base`: its settings, size
/// `w × h`) under each rule of `rules`, and compares each image with the same scene rendered at
/// `factor × w` by `factor × h` without anti-aliasing and box-filtered `factor × factor` down
/// (there a voxel covers `factor²` as many pixels, so with `factor` ≥ the voxels per pixel no
/// rule would widen anything: the reference averages each pixel's area). Returns the RMS error
/// (premultiplied RGB) per rule, in the order of `rules`.
pub fn minified_box_errors<T: Scalar>(
    volume: &Volume<T>,
    camera: &Camera,
    tables: &CrioTables,
    base: &RenderSettings,
    factor: usize,
    rules: &[Antialias],
) -> Result<Vec<f64>> {
    let (w, h) = (base.width, base.height);
    let hi = {
        let mut s = base.clone();
        s.width = w * factor;
        s.height = h * factor;
        s.antialias = Antialias::None;
        s
    };
    let reference = box_downsample(
        &volsplat_splat::render(volume, camera, tables, &hi)?.image,
        factor,
    )?;
    rules
        .iter()
        .map(|&aa| {
            let s = {
                let mut s = base.clone();
                s.antialias = aa;
                s
            };
            let img = volsplat_splat::render(volume, camera, tables, &s)?.image;
            Ok(rms_rgb(&img, &reference, None))
        })
        .collect()
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
        bail!("temporal_highpass needs ≥ 3 frames");
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
    let s = {
        let mut s = settings.clone();
        s.width = px;
        s.height = px;
        s
    };
    let draw = |v: &Volume<f32>| -> Result<Image> {
        if use_list {
            let list = SplatList::build(v, &tables, &Default::default())?;
            Ok(render_list(&list, &camera, &tables, &s)?.image)
        } else {
            Ok(volsplat_splat::render_by_visibility(v, &camera, &tables, &s, &mut |_| true)?.image)
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
        bail!("image too small to measure");
    }
    Ok((sum / contrast).sqrt())
}

const BG: [f32; 3] = [0.32, 0.34, 0.55];

/// Two images side by side with a 4-pixel white gutter.
fn side_by_side(a: &Image, b: &Image) -> Image {
    let (w, h) = (a.width(), a.height());
    let gw = 2 * w + 4;
    let mut px = vec![[1.0, 1.0, 1.0, 1.0]; gw * h];
    for y in 0..h {
        for x in 0..w {
            px[y * gw + x] = a.pixels()[y * w + x];
            px[y * gw + w + 4 + x] = b.pixels()[y * w + x];
        }
    }
    Image::from_pixels(gw, h, px).unwrap_or_else(|| Image::new(gw, h))
}

fn png(path: &Path, img: &Image) -> Result<()> {
    volsplat_io::write_png(
        path,
        img,
        &PngSettings {
            background: BG,
            ..PngSettings::default()
        },
    )
    .with_context(|| format!("writing {}", path.display()))
}

/// Renders a scene without and with Swan's anti-aliasing, draws the k line on both, and
/// writes them side by side. Returns the two render times (ms) and the splat count.
fn figure(
    path: &Path,
    list: &SplatList,
    camera: &Camera,
    tables: &CrioTables,
    size: (usize, usize),
) -> Result<(f64, f64)> {
    let mut times = [0.0; 2];
    let mut imgs = Vec::new();
    for (i, aa) in [Antialias::None, Antialias::Swan].into_iter().enumerate() {
        let s = {
            let mut s = RenderSettings::default();
            s.width = size.0;
            s.height = size.1;
            s.antialias = aa;
            s
        };
        let r = render_list(list, camera, tables, &s)?;
        times[i] = r.stats.total_ms;
        let mut img = r.image;
        let proj = Projection::new(camera, size.0, size.1)?;
        if let Some(k) = k_distance(list.grid(), 1, &proj) {
            let depth = render_list_depth(list, camera, tables, &s)?;
            draw_depth_contour(&mut img, &depth, k as f32, [0.0, 0.0, 0.0])?;
        }
        imgs.push(img);
    }
    png(path, &side_by_side(&imgs[0], &imgs[1]))?;
    Ok((times[0], times[1]))
}

/// The MRI minification table of [`write_figures`]: the orthographic scenes of `data/scenes`
/// (brainsmall composite and shaded composite, Colin27 composite) at 96², 112² and 128², each
/// against its own 4× box reference ([`minified_box_errors`]). Volumes missing from `data` are
/// left out.
fn mri_minification(md: &mut String, data: &Path) -> Result<()> {
    writeln!(
        md,
        "\n## Real MRIs shown small, against a 4× box-filtered reference\n"
    )?;
    writeln!(
        md,
        "The orthographic scenes of `{}/scenes`, rendered by the dense sheet-buffer renderer at \
         n² and compared with the same scene at (4n)² without anti-aliasing, box-filtered 4×4 \
         (the pixel-area average, issue 12 item 4). RMS error of premultiplied RGB (0–1). \
         `area` adds a one-pixel box's variance, 1/12 px², to each footprint; Swan's rule widens \
         a minified footprint to the kernel's variance, 0.35 px². The reference uses the same \
         Gaussian kernel, so it measures the pre-filter alone.\n",
        data.display()
    )?;
    writeln!(
        md,
        "| scene | size | voxels per pixel | none | swan | swan-perpendicular | ewa | area | \
         area / none |"
    )?;
    writeln!(md, "|---|---|---|---|---|---|---|---|---|")?;
    let mut missing = Vec::new();
    for (file, scene) in [
        ("mri_brainsmall.nrrd", "mri_brainsmall__composite_ortho"),
        (
            "mri_brainsmall.nrrd",
            "mri_brainsmall__composite_shaded_ortho",
        ),
        ("mri_colin27.nhdr", "mri_colin27__composite_ortho"),
    ] {
        let path = data.join(file);
        let json = |kind: &str| data.join("scenes").join(format!("{scene}.{kind}.json"));
        if !path.is_file() || !json("camera").is_file() || !json("tf").is_file() {
            missing.push(scene);
            continue;
        }
        let vol = volsplat_io::read_volume(&path)
            .with_context(|| format!("reading {}", path.display()))?
            .to_f32();
        let (camera, _) = volsplat_io::load_camera(json("camera"))?;
        let (tf, _) = volsplat_io::load_transfer_function(json("tf"))?;
        let tables = CrioTables::from_transfer_function(&tf, 1024)?;
        let spacing = vol
            .grid()
            .spacing
            .iter()
            .copied()
            .fold(f64::INFINITY, f64::min);
        for n in [96usize, 112, 128] {
            let base = {
                let mut s = RenderSettings::default();
                s.width = n;
                s.height = n;
                s
            };
            let e = minified_box_errors(&vol, &camera, &tables, &base, 4, &RULES)?;
            let vpp = 2.0 * camera.parallel_scale / n as f64 / spacing;
            write!(md, "| `{scene}` | {n}² | {vpp:.2} |")?;
            for v in &e {
                write!(md, " {v:.5} |")?;
            }
            writeln!(md, " {:.2} |", e[4] / e[0])?;
        }
    }
    if !missing.is_empty() {
        writeln!(md, "\nLeft out (data missing): {}.", missing.join(", "))?;
    }
    writeln!(md)?;
    Ok(())
}

/// Settings of [`write_figures`].
#[derive(Debug, Clone, PartialEq)]
pub struct AaFiguresSettings {
    /// Output folder for `README.md` and the figures (created if missing).
    pub out: PathBuf,
    /// Frames of the dolly used to measure flicker (at least 3 are rendered).
    pub frames: usize,
    /// The folder holding `mri_brainsmall.nrrd`, `mri_colin27.nhdr` and `scenes/` (the shared
    /// data set), for the MRI minification table; rows whose data is missing are left out.
    pub data: PathBuf,
}

impl Default for AaFiguresSettings {
    /// `docs/figures`, 60 frames, data in `../shared/data` (what `volsplat aa-figures` writes
    /// by default).
    fn default() -> Self {
        AaFiguresSettings {
            out: PathBuf::from("docs/figures"),
            frames: 60,
            data: PathBuf::from("../shared/data"),
        }
    }
}

/// The figures and measurements of Swan et al. 1997 §5: Fig. 7a–f (checkerboard sheet,
/// terrain, dense fibres; left without, right with anti-aliasing, the line at `k` drawn on
/// both) as `fig7-*.png`, and `README.md` with the render times, the aliasing under
/// orthographic minification ([`minification_error`]), real MRIs shown small against their 4×
/// box-filtered references ([`minified_box_errors`]; those `data` holds), in the perspective
/// checkerboard
/// ([`perspective_errors`]) and the flicker of a dolly ([`temporal_highpass`]). Runs on the
/// current rayon pool; about 25 s on 2 cores at the default 60 frames.
pub fn write_figures(a: &AaFiguresSettings) -> Result<Written> {
    let t0 = Instant::now();
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let mut md = String::new();
    writeln!(
        md,
        "# Anti-aliased splatting: figures and measurements (Swan et al. 1997)\n"
    )?;
    writeln!(
        md,
        "Written by `volsplat aa-figures --out {}` ({} threads). Left: no anti-aliasing; right: \
         Swan et al.'s rule (eq. 4 and 8). The black line is the distance k = s·D/p (eq. 3) \
         beyond which a voxel covers less than a pixel.\n",
        a.out.display(),
        rayon::current_num_threads()
    )?;

    let checkerboard = fig7_checkerboard(&a.out, &mut md)?;
    fig7_terrain(&a.out, &mut md)?;
    fig7_filaments(&a.out, &mut md)?;
    orthographic_minification(&mut md)?;
    // (i′) a real MRI shown small (issue 12 item 4).
    mri_minification(&mut md, &a.data)?;
    perspective_checkerboard(&mut md, &checkerboard)?;
    flicker(&mut md, &checkerboard, a.frames)?;
    writeln!(md, "\n## Energy of far-away X-ray images\n")?;
    writeln!(
        md,
        "Checked by `crates/splat/tests/antialias.rs` (far_away_xray_keeps_its_energy_when_splats_grow) \
         and `list.rs` (orthographic_minification_conserves_x_ray_energy_with_swan), for swan, \
         ewa and area: the image's integral stays within 1 % of the volume's mass when \
         anti-aliasing enlarges the splats.\n"
    )?;
    writeln!(md, "Total time: {:.1} s.", t0.elapsed().as_secs_f64())?;
    let report = a.out.join("README.md");
    volsplat_io::write_bytes_atomic(&report, md.as_bytes())
        .with_context(|| format!("writing {}", report.display()))?;
    Ok(Written {
        report,
        markdown: md,
        images: 3,
    })
}

/// The checkerboard scene of Fig. 7a–b, which the perspective and flicker measurements reuse.
struct Checkerboard {
    /// Sheet size, voxels.
    nx: usize,
    /// Sheet size, voxels.
    ny: usize,
    /// Its classification.
    tables: CrioTables,
    /// The splat list of the paper's sheet.
    list: SplatList,
    /// [`checkerboard_camera`].
    camera: Camera,
}

/// Fig. 7a–b: the checkerboard sheet, `fig7-checkerboard.png` and its section.
fn fig7_checkerboard(out: &Path, md: &mut String) -> Result<Checkerboard> {
    let (nx, ny, sq) = scenes::CHECKERBOARD_PAPER;
    let cb_tables = CrioTables::from_transfer_function(&scenes::checkerboard_tf(), 1024)?;
    let sheet = scenes::checkerboard_sheet(nx, ny, sq)?;
    let cb = SplatList::build(&sheet, &cb_tables, &ExtractSettings::default())?;
    let cb_cam = checkerboard_camera(nx, ny);
    let (t_none, t_swan) = figure(
        &out.join("fig7-checkerboard.png"),
        &cb,
        &cb_cam,
        &cb_tables,
        (270, 157),
    )?;
    writeln!(
        md,
        "## Fig. 7a–b: checkerboard sheet {nx}×{ny}×1, {sq}×{sq} squares, 270×157\n"
    )?;
    writeln!(md, "![checkerboard](fig7-checkerboard.png)\n")?;
    writeln!(
        md,
        "{} splats; {t_none:.0} ms without and {t_swan:.0} ms with anti-aliasing.\n",
        cb.len()
    )?;

    Ok(Checkerboard {
        nx,
        ny,
        tables: cb_tables,
        list: cb,
        camera: cb_cam,
    })
}

/// Fig. 7c–d: the terrain, `fig7-terrain.png` and its section.
fn fig7_terrain(out: &Path, md: &mut String) -> Result<()> {
    let [tx, ty, tz] = scenes::TERRAIN_PAPER;
    let terrain = scenes::terrain(tx, ty, tz, 1)?;
    let t_tables = CrioTables::from_transfer_function(&scenes::terrain_tf(), 1024)?;
    let tl = SplatList::build(&terrain, &t_tables, &ExtractSettings::default())?;
    let t_cam = Camera {
        position: [-10.0, -10.0, tz as f64 + 40.0],
        focal_point: [tx as f64 * 0.45, ty as f64 * 0.45, tz as f64 * 0.3],
        view_up: [0.0, 0.0, 1.0],
        view_angle: 60.0,
        parallel_projection: false,
        parallel_scale: 1.0,
    };
    let (t_none, t_swan) = figure(
        &out.join("fig7-terrain.png"),
        &tl,
        &t_cam,
        &t_tables,
        (270, 175),
    )?;
    writeln!(md, "## Fig. 7c–d: terrain {tx}×{ty}×{tz}, 270×175\n")?;
    writeln!(md, "![terrain](fig7-terrain.png)\n")?;
    writeln!(
        md,
        "{} splats (the paper: 386K); {t_none:.0} ms without and {t_swan:.0} ms with \
         anti-aliasing.\n",
        tl.len()
    )?;

    Ok(())
}

/// Fig. 7e–f: dense fibres finer than the image, `fig7-filaments.png` and its section.
fn fig7_filaments(out: &Path, md: &mut String) -> Result<()> {
    let [fx, fy, fz] = scenes::FILAMENTS_PAPER;
    let fil = scenes::filaments(fx, fy, fz, 1)?;
    let f_tables = CrioTables::from_transfer_function(&scenes::filaments_tf(), 1024)?;
    let fl = SplatList::build(&fil, &f_tables, &ExtractSettings::default())?;
    let (lo, hi) = fil.grid().bounds_world();
    let mut f_cam = Camera::reset_to_bounds(lo, hi, false);
    f_cam.elevation(-35.0);
    f_cam.orthogonalize_view_up();
    f_cam.azimuth(20.0);
    let (t_none, t_swan) = figure(
        &out.join("fig7-filaments.png"),
        &fl,
        &f_cam,
        &f_tables,
        (270, 270),
    )?;
    writeln!(md, "## Fig. 7e–f: dense fibres {fx}×{fy}×{fz}, 270×270\n")?;
    writeln!(md, "![filaments](fig7-filaments.png)\n")?;
    writeln!(
        md,
        "{} splats; every voxel lies beyond k, so the whole image is filtered. {t_none:.0} ms \
         without and {t_swan:.0} ms with anti-aliasing.\n",
        fl.len()
    )?;

    Ok(())
}

/// The orthographic minification table ([`minification_error`]) for every rule, both
/// renderers, at 2 to 8 voxels per pixel.
fn orthographic_minification(md: &mut String) -> Result<()> {
    writeln!(md, "## Aliasing under orthographic minification\n")?;
    writeln!(
        md,
        "A 240×240×1 sheet of 2×2-voxel squares seen face-on. The alias-free image is the \
         sheet's average colour; the error is the RMS deviation from it inside the sheet, \
         relative to the red–white contrast.\n"
    )?;
    writeln!(
        md,
        "| voxels per pixel | renderer | none | swan | swan-perpendicular | ewa | area | none / \
         swan |"
    )?;
    writeln!(md, "|---|---|---|---|---|---|---|---|")?;
    for vpp in [2.0, 3.0, 5.0, 8.0] {
        for use_list in [false, true] {
            let e = |aa: Antialias| {
                minification_error(
                    240,
                    2,
                    vpp,
                    &{
                        let mut s = RenderSettings::default();
                        s.antialias = aa;
                        s
                    },
                    use_list,
                )
            };
            let (n, s, p, w, r) = (
                e(Antialias::None)?,
                e(Antialias::Swan)?,
                e(Antialias::SwanPerpendicular)?,
                e(Antialias::Ewa)?,
                e(Antialias::Area)?,
            );
            writeln!(
                md,
                "| {vpp} | {} | {n:.4} | {s:.4} | {p:.4} | {w:.4} | {r:.4} | {:.0}× |",
                if use_list {
                    "splat list"
                } else {
                    "dense table"
                },
                n / s
            )?;
        }
    }

    Ok(())
}

/// The perspective checkerboard ([`perspective_errors`]) with 10×10 and 2×2 squares against
/// the 8× supersampled reference.
fn perspective_checkerboard(md: &mut String, c: &Checkerboard) -> Result<()> {
    let (nx, ny, cb_tables, cb_cam) = (c.nx, c.ny, &c.tables, &c.camera);
    writeln!(md, "\n## Aliasing in the perspective checkerboard\n")?;
    writeln!(
        md,
        "Against the same scene rendered at 8× the resolution and box-filtered down. RMS error \
         of premultiplied RGB (0–1). *Beyond k* counts the pixels where the 8× and 4× \
         references agree within 0.02 (the reference has converged); *all* counts every pixel \
         beyond k. *Change before k* is the RMS change from the un-anti-aliased image in front \
         of k, relative to its RMS value.\n"
    )?;
    for square in [10usize, 2] {
        let sheet = scenes::checkerboard_sheet(nx, ny, square)?;
        let list = SplatList::build(&sheet, cb_tables, &ExtractSettings::default())?;
        let base = {
            let mut s = RenderSettings::default();
            s.width = 270;
            s.height = 157;
            s
        };
        let (k, conv, errs) = perspective_errors(&list, cb_cam, cb_tables, &base, 8)?;
        writeln!(
            md,
            "**{square}×{square} squares** (k = {k:.1} voxels; reference converged on {:.0} % \
             of the pixels beyond k)\n",
            100.0 * conv
        )?;
        writeln!(
            md,
            "| rule | whole image | before k | beyond k | beyond k (all) | change before k |"
        )?;
        writeln!(md, "|---|---|---|---|---|---|")?;
        let none_beyond = errs[0].beyond_k;
        for e in &errs {
            writeln!(
                md,
                "| {} | {:.4} | {:.4} | {:.4} ({:.2}× none) | {:.4} | {:.3} % |",
                e.antialias.name(),
                e.whole,
                e.before_k,
                e.beyond_k,
                e.beyond_k / none_beyond,
                e.beyond_k_all,
                100.0 * e.before_k_change
            )?;
        }
        writeln!(md)?;
    }

    Ok(())
}

/// The flicker of a `frames`-frame dolly ([`temporal_highpass`]) for every rule.
fn flicker(md: &mut String, c: &Checkerboard, frames: usize) -> Result<()> {
    let (cb, cb_tables, cb_cam) = (&c.list, &c.tables, &c.camera);
    writeln!(
        md,
        "## Flicker of a {}-frame dolly towards the horizon\n",
        frames
    )?;
    writeln!(
        md,
        "The 10×10 checkerboard, the eye moving 1.5 voxels per frame along the view. Mean \
         energy of the second temporal difference f(t+1) − 2f(t) + f(t−1) over the pixels \
         beyond k (RGB, 0–1 scale).\n"
    )?;
    writeln!(md, "| rule | temporal high-pass energy | ratio to none |")?;
    writeln!(md, "|---|---|---|")?;
    let mut none_e = 0.0;
    for aa in RULES {
        let s = {
            let mut s = RenderSettings::default();
            s.width = 270;
            s.height = 157;
            s.antialias = aa;
            s
        };
        let e = temporal_highpass(cb, cb_cam, cb_tables, &s, frames.max(3), 1.5)?;
        if aa == Antialias::None {
            none_e = e;
        }
        writeln!(md, "| {} | {e:.3e} | {:.2} |", aa.name(), e / none_e)?;
    }

    Ok(())
}
