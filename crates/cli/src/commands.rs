//! The subcommands: glue between arguments and the libraries.

use crate::args::*;
use anyhow::{Context, Result, anyhow, bail};
use serde_json::json;
use std::path::{Path, PathBuf};
use std::time::Instant;
use volsplat_core::phantom::{self, EllipsoidPhantom, GaussianBlobs, MarschnerLobb};
use volsplat_core::{AnyVolume, Camera, CrioTables, Kernel, Light, ScalarType, TransferFunction};
use volsplat_io::{PngBitDepth, PngSettings, RawSpec};
use volsplat_splat::list::{draw_depth_contour, k_distance, render_list_depth};
use volsplat_splat::refine::{default_ladder, render_ladder};
use volsplat_splat::{
    Antialias, ExtractSettings, Order, RenderMode, RenderSettings, Rendered, SplatList, Visibility,
    render_any, render_list,
};

pub fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Render(a) => render_cmd(*a),
        Command::Info(a) => info_cmd(a),
        Command::Phantom(a) => phantom_cmd(a),
        Command::Bench(a) => bench_cmd(*a),
        Command::TextureBench(a) => texture_bench_cmd(a),
        Command::DisplayBench(a) => crate::display::display_bench_cmd(*a),
        Command::AaFigures(a) => crate::aa_figures::aa_figures_cmd(a),
    }
}

/// Parses "A,B,C" into three numbers, naming the flag on error.
fn triple<T: std::str::FromStr>(s: &str, flag: &str) -> Result<[T; 3]> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    if parts.len() != 3 {
        bail!("{flag}: expected three comma-separated values, got `{s}`");
    }
    let mut out = Vec::with_capacity(3);
    for p in parts {
        out.push(
            p.parse::<T>()
                .map_err(|_| anyhow!("{flag}: `{p}` is not a valid number"))?,
        );
    }
    out.try_into()
        .map_err(|_| anyhow!("{flag}: expected three values"))
}

fn pair(s: &str, sep: char, flag: &str) -> Result<(f64, f64)> {
    let (a, b) = s
        .split_once(sep)
        .ok_or_else(|| anyhow!("{flag}: expected A{sep}B, got `{s}`"))?;
    let p = |v: &str| {
        v.trim()
            .parse::<f64>()
            .map_err(|_| anyhow!("{flag}: `{v}` is not a number"))
    };
    Ok((p(a)?, p(b)?))
}

/// Largest built-in phantom, voxels (2³⁰: 4 GiB as f32).
const PHANTOM_MAX_VOXELS: u128 = 1 << 30;

fn grid_size(s: &str, flag: &str) -> Result<[usize; 3]> {
    let dims = if s.contains(',') {
        triple::<usize>(s, flag)?
    } else {
        let n: usize = s
            .trim()
            .parse()
            .map_err(|_| anyhow!("{flag}: `{s}` is not a size"))?;
        [n; 3]
    };
    if dims.iter().any(|d| !(2..=4096).contains(d)) {
        bail!("{flag}: each size must be in 2..=4096, got {dims:?}");
    }
    // Phantoms are generated in memory as f32 (or i16): keep them well inside a workstation.
    let voxels: u128 = dims.iter().map(|&d| d as u128).product();
    if voxels > PHANTOM_MAX_VOXELS {
        bail!(
            "{flag}: {dims:?} is {voxels} voxels; built-in phantoms are limited to {PHANTOM_MAX_VOXELS} \
             (4 GiB as f32)"
        );
    }
    Ok(dims)
}

/// A built-in phantom; `size` as `render --phantom-size` / `phantom --grid` (named `flag` in
/// errors), `None` for the phantom's own size.
fn make_phantom(kind: PhantomKind, size: Option<&str>, flag: &str) -> Result<AnyVolume> {
    use volsplat_core::scenes;
    match kind {
        PhantomKind::Checkerboard => {
            let (nx, ny, sq) = scenes::CHECKERBOARD_PAPER;
            let (nx, ny, sq) = match size {
                None => (nx, ny, sq),
                Some(s) => {
                    let v: Vec<usize> = s
                        .split(',')
                        .map(|p| p.trim().parse::<usize>())
                        .collect::<std::result::Result<_, _>>()
                        .map_err(|_| anyhow!("{flag}: expected X,Y[,SQUARE], got `{s}`"))?;
                    match v[..] {
                        [x, y] => (x, y, sq),
                        [x, y, q] => (x, y, q),
                        _ => bail!("{flag}: expected X,Y[,SQUARE], got `{s}`"),
                    }
                }
            };
            if !(1..=8192).contains(&nx) || !(1..=8192).contains(&ny) {
                bail!("{flag}: sheet sides must be in 1..=8192, got {nx}x{ny}");
            }
            return Ok(scenes::checkerboard_sheet(nx, ny, sq)?.into());
        }
        PhantomKind::Terrain => {
            let d = match size {
                Some(s) => grid_size(s, flag)?,
                None => scenes::TERRAIN_PAPER,
            };
            return Ok(scenes::terrain(d[0], d[1], d[2], 1)?.into());
        }
        PhantomKind::Filaments => {
            let d = match size {
                Some(s) => grid_size(s, flag)?,
                None => scenes::FILAMENTS_PAPER,
            };
            return Ok(scenes::filaments(d[0], d[1], d[2], 1)?.into());
        }
        _ => {}
    }
    let dims = match size {
        Some(s) => grid_size(s, flag)?,
        None => match kind {
            PhantomKind::Head => [128, 160, 144],
            _ => [128; 3],
        },
    };
    Ok(match kind {
        PhantomKind::Head => phantom::ct_head_volume(dims)?.into(),
        PhantomKind::SheppLogan => {
            phantom::sample(&EllipsoidPhantom::shepp_logan_3d(), dims, 2)?.into()
        }
        PhantomKind::Blobs => phantom::sample(&GaussianBlobs::demo(), dims, 1)?.into(),
        PhantomKind::MarschnerLobb => phantom::sample(
            &MarschnerLobb {
                f_m: 6.0,
                alpha: 0.25,
            },
            dims,
            1,
        )?
        .into(),
        PhantomKind::Checkerboard | PhantomKind::Terrain | PhantomKind::Filaments => {
            unreachable!("handled above")
        }
    })
}

/// Loads the input volume; returns it with a label for messages.
fn load_volume(a: &InputArgs) -> Result<(AnyVolume, String)> {
    match &a.input {
        None => Ok((
            make_phantom(a.phantom, a.phantom_size.as_deref(), "--phantom-size")?,
            format!("demo phantom `{:?}`", a.phantom),
        )),
        Some(path) => {
            if path.is_dir() {
                bail!(
                    "{} is a directory (reading folders of DICOM files is not supported yet)",
                    path.display()
                );
            }
            let vol = if let Some(dims) = &a.raw_dims {
                let spec = RawSpec {
                    dims: triple::<usize>(dims, "--raw-dims")?,
                    scalar_type: ScalarType::from_name(&a.raw_type).context("--raw-type")?,
                    spacing: triple::<f64>(&a.raw_spacing, "--raw-spacing")?,
                    origin: [0.0; 3],
                    big_endian: a.raw_big_endian,
                    header_bytes: a.raw_skip,
                };
                volsplat_io::read_raw(path, &spec)?
            } else {
                volsplat_io::read_volume(path)?
            };
            Ok((vol, path.display().to_string()))
        }
    }
}

/// The camera: the `--camera` file's, or VTK's reset camera around the volume; then the view
/// flags that were given, in VTK's order (Azimuth, Elevation, OrthogonalizeViewUp, Roll, Zoom,
/// Dolly). `--perspective` switches a file's camera to perspective; `--view-angle` replaces its
/// view angle.
fn build_camera(v: &ViewArgs, vol: &AnyVolume) -> Result<Camera> {
    if let Some(zoom) = v.zoom
        && !(zoom.is_finite() && zoom > 0.0)
    {
        bail!("--zoom must be a positive number, got {zoom}");
    }
    for (flag, x) in [
        ("--azimuth", v.azimuth),
        ("--elevation", v.elevation),
        ("--roll", v.roll),
    ] {
        if x.is_some_and(|x| !x.is_finite()) {
            bail!("{flag} must be a finite number of degrees");
        }
    }
    if let Some(angle) = v.view_angle
        && !(angle > 0.0 && angle < 180.0)
    {
        bail!("--view-angle must be in (0, 180) degrees, got {angle}");
    }
    if let Some(dolly) = v.dolly
        && !(dolly.is_finite() && dolly > 0.0)
    {
        bail!("--dolly must be a positive number, got {dolly}");
    }
    let mut cam = if let Some(path) = &v.camera {
        let (mut cam, warnings) = volsplat_io::load_camera(path)?;
        for w in warnings {
            eprintln!("warning: {w}");
        }
        if v.perspective {
            cam.parallel_projection = false;
        }
        if v.orthographic && !cam.parallel_projection {
            use volsplat_core::glam::DVec3;
            let (eye, focal) = (DVec3::from(cam.position), DVec3::from(cam.focal_point));
            cam.parallel_scale = (eye - focal).length() * (0.5 * cam.view_angle.to_radians()).tan();
            cam.parallel_projection = true;
        }
        if let Some(angle) = v.view_angle {
            cam.view_angle = angle;
        }
        cam
    } else {
        let (lo, hi) = vol.grid().bounds_world();
        let mut cam = Camera::reset_to_bounds(lo, hi, !v.perspective);
        if let Some(angle) = v.view_angle
            && angle != cam.view_angle
        {
            // VTK's ResetCamera places the eye at radius / sin(view_angle / 2).
            let fp = volsplat_core::glam::DVec3::from(cam.focal_point);
            let radius = cam.parallel_scale;
            let dist = radius / (angle.to_radians() * 0.5).sin();
            cam.position = (fp + volsplat_core::glam::DVec3::Z * dist).to_array();
            cam.view_angle = angle;
        }
        cam
    };
    if cam.parallel_projection && v.view_angle.is_some() {
        eprintln!(
            "warning: --view-angle has no effect on an orthographic camera{} (add --perspective)",
            match &v.camera {
                Some(p) => format!(" ({} has parallel_projection: true)", p.display()),
                None => String::new(),
            }
        );
    }
    if let Some(deg) = v.azimuth {
        cam.azimuth(deg);
    }
    if let Some(deg) = v.elevation {
        cam.elevation(deg);
    }
    if v.azimuth.is_some() || v.elevation.is_some() || v.roll.is_some() {
        cam.orthogonalize_view_up();
    }
    if let Some(deg) = v.roll {
        cam.roll(deg);
    }
    if let Some(zoom) = v.zoom {
        cam.zoom(zoom);
    }
    if let Some(dolly) = v.dolly {
        cam.dolly(dolly);
    }
    cam.validate().map_err(|e| {
        anyhow!(
            "the camera after --azimuth/--elevation/--roll/--zoom/--dolly is degenerate: {e} \
             (an elevation of ±90° looks along view-up; add --roll or change --elevation)"
        )
    })?;
    Ok(cam)
}

/// The transfer function from `--tf`, `--preset`, or the default for the mode and data.
pub(crate) fn build_tf(
    o: &RenderOptions,
    vol: &AnyVolume,
    demo: bool,
    scene_tf: Option<TransferFunction>,
) -> Result<TransferFunction> {
    let range = vol.value_range();
    Ok(
        if let (None, None, Some(tf)) = (&o.tf, &o.preset, scene_tf) {
            tf
        } else if let Some(path) = &o.tf {
            let (tf, warnings) = volsplat_io::load_transfer_function(path)?;
            for w in warnings {
                eprintln!("warning: {w}");
            }
            tf
        } else if o.preset.is_none() && matches!(o.mode, ModeArg::Mip | ModeArg::Minip) {
            // Projections without a transfer function: a grey window over the data range, opaque.
            TransferFunction::ramp(range.0, range.1, 1.0)
        } else {
            let name = o.preset.clone().unwrap_or_else(|| {
                if demo {
                    "ct-skin".into()
                } else {
                    "ramp".into()
                }
            });
            TransferFunction::preset(&name, range)?
        },
    )
}

/// The transfer function a built-in scene is meant to be seen with, if the input is one.
pub(crate) fn scene_tf(a: &InputArgs) -> Option<TransferFunction> {
    use volsplat_core::scenes;
    if a.input.is_some() {
        return None;
    }
    match a.phantom {
        PhantomKind::Checkerboard => Some(scenes::checkerboard_tf()),
        PhantomKind::Terrain => Some(scenes::terrain_tf()),
        PhantomKind::Filaments => Some(scenes::filaments_tf()),
        _ => None,
    }
}

fn build_tables(
    o: &RenderOptions,
    vol: &AnyVolume,
    demo: bool,
    scene: Option<TransferFunction>,
) -> Result<CrioTables> {
    let tf = build_tf(o, vol, demo, scene)?;
    let lights = if o.light.is_empty() {
        vec![Light::headlight()]
    } else {
        o.light
            .iter()
            .map(|l| parse_light(l))
            .collect::<Result<Vec<_>>>()?
    };
    let mut tables = CrioTables::from_transfer_function_lit(
        &tf,
        volsplat_core::crio::DEFAULT_TABLE_LEN,
        lights,
    )?;
    tables.shading.emission &= !o.no_emission;
    tables.shading.diffuse &= !o.no_diffuse;
    tables.shading.specular &= !o.no_specular;
    if let Some(s) = &o.surface_enhance {
        let (lo, hi) = pair(s, ':', "--surface-enhance")?;
        tables = tables.with_surface_enhancement(lo, hi)?;
    }
    if let Some(s) = &o.depth_cue {
        let (near, far) = pair(s, ':', "--depth-cue")?;
        tables = tables.with_depth_cue(near, far)?;
    }
    Ok(tables)
}

/// Parses `X,Y,Z[,R,G,B]`: a camera-relative direction towards the light and an optional colour.
fn parse_light(s: &str) -> Result<Light> {
    let v: Vec<f64> = s
        .split(',')
        .map(|p| {
            p.trim()
                .parse::<f64>()
                .map_err(|_| anyhow!("--light: `{p}` is not a number in `{s}`"))
        })
        .collect::<Result<_>>()?;
    if v.len() != 3 && v.len() != 6 {
        bail!("--light: expected X,Y,Z or X,Y,Z,R,G,B, got `{s}`");
    }
    if v.iter().any(|x| !x.is_finite()) || v[..3].iter().all(|&x| x == 0.0) {
        bail!("--light: direction must be finite and non-zero, got `{s}`");
    }
    let color = if v.len() == 6 {
        [v[3] as f32, v[4] as f32, v[5] as f32]
    } else {
        [1.0; 3]
    };
    if color.iter().any(|&c| c < 0.0) {
        bail!("--light: colour components must be ≥ 0, got `{s}`");
    }
    Ok(Light {
        direction: [v[0], v[1], v[2]],
        color,
        ..Light::headlight()
    })
}

/// Parses an image size: `WxH` (or `WXH`) or a single `N` for N×N, each in 1..=16384.
pub(crate) fn parse_image_size(s: &str, flag: &str) -> Result<(usize, usize)> {
    let bad = || anyhow!("{flag}: expected WxH (e.g. 640x480) or N (N×N pixels), got `{s}`");
    let parse = |v: &str| v.trim().parse::<usize>().map_err(|_| bad());
    let (width, height) = match s.split_once(['x', 'X']) {
        Some((w, h)) => (parse(w)?, parse(h)?),
        None => {
            let n = parse(s)?;
            (n, n)
        }
    };
    if width == 0 || height == 0 || width > 16384 || height > 16384 {
        bail!("{flag}: width and height must be in 1..=16384, got {width}x{height} (`{s}`)");
    }
    Ok((width, height))
}

fn build_settings(o: &RenderOptions) -> Result<RenderSettings> {
    let (width, height) = parse_image_size(&o.size, "--size")?;
    if !matches!(o.subsample, 1..=64) {
        bail!("--subsample must be in 1..=64, got {}", o.subsample);
    }
    Ok(RenderSettings {
        width,
        height,
        mode: match o.mode {
            ModeArg::Composite => RenderMode::Composite,
            ModeArg::Mip => RenderMode::Mip,
            ModeArg::Minip => RenderMode::Minip,
            ModeArg::Xray => RenderMode::Xray,
        },
        visibility: match o.visibility {
            VisibilityArg::Sheet => Visibility::SheetBuffer,
            VisibilityArg::Every => Visibility::EverySample,
        },
        order: match o.order {
            OrderArg::Ftb => Order::FrontToBack,
            OrderArg::Btf => Order::BackToFront,
        },
        kernel: Kernel::from_name(&o.kernel)?,
        subsample: o.subsample,
        opacity_cutoff: if o.opacity_cutoff.is_finite() && o.opacity_cutoff > 0.0 {
            o.opacity_cutoff
        } else {
            bail!(
                "--opacity-cutoff must be a positive number, got {}",
                o.opacity_cutoff
            )
        },
        antialias: match o.antialias {
            AntialiasArg::Swan => Antialias::Swan,
            AntialiasArg::SwanPerpendicular => Antialias::SwanPerpendicular,
            AntialiasArg::Ewa => Antialias::Ewa,
            AntialiasArg::None => Antialias::None,
        },
        ..RenderSettings::default()
    })
}

/// Whether the sparse splat-list renderer draws this view (perspective, or asked for).
fn use_list(camera: &Camera, o: &RenderOptions) -> bool {
    o.splat_list || !camera.parallel_projection
}

fn build_list(o: &RenderOptions, vol: &AnyVolume, tables: &CrioTables) -> Result<SplatList> {
    if !(o.list_threshold >= 0.0 && o.list_threshold < 1.0) {
        bail!(
            "--list-threshold must be in [0, 1), got {}",
            o.list_threshold
        );
    }
    Ok(SplatList::build_any(
        vol,
        tables,
        &ExtractSettings {
            threshold: o.list_threshold,
            subsample: o.subsample,
        },
    )?)
}

pub(crate) fn thread_pool(threads: Option<usize>) -> Result<rayon::ThreadPool> {
    let mut b = rayon::ThreadPoolBuilder::new();
    if let Some(n) = threads {
        if n == 0 || n > 1024 {
            bail!("--threads must be in 1..=1024, got {n}");
        }
        b = b.num_threads(n);
    }
    Ok(b.build()?)
}

/// The image formats `render -o` writes, by extension (case-insensitive).
const OUTPUT_EXTENSIONS: &[&str] = &["png", "npy"];

/// Checks, before any work, that `path` (given with `flag`) can be written: not a folder, its
/// folder exists, and, if `extensions` is not empty, it ends in one of them.
pub(crate) fn check_output_path(path: &Path, flag: &str, extensions: &[&str]) -> Result<()> {
    if path.is_dir() {
        bail!("{flag} {}: is a folder; give a file name", path.display());
    }
    if !extensions.is_empty() {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase)
            .unwrap_or_default();
        if !extensions.contains(&ext.as_str()) {
            let list: Vec<String> = extensions.iter().map(|e| format!(".{e}")).collect();
            bail!(
                "{flag} {}: unsupported extension; use {}",
                path.display(),
                list.join(" or ")
            );
        }
    }
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty())
        && !dir.is_dir()
    {
        if dir.exists() {
            bail!(
                "{flag} {}: {} is not a folder",
                path.display(),
                dir.display()
            );
        }
        bail!(
            "{flag} {}: the folder {} does not exist",
            path.display(),
            dir.display()
        );
    }
    Ok(())
}

/// Non-finite values in what would be written: an image file must never hold NaN or infinity.
#[derive(Debug)]
pub struct NonFiniteOutput {
    /// The renderer or stage that produced the image.
    pub stage: String,
    /// Pixels with at least one non-finite value.
    pub count: usize,
    /// The file that was not written.
    pub path: PathBuf,
    /// Files this command had already written (ladder previews).
    pub written: Vec<PathBuf>,
}

impl std::fmt::Display for NonFiniteOutput {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "internal error: the {} produced {} non-finite pixel{}; ",
            self.stage,
            self.count,
            if self.count == 1 { "" } else { "s" }
        )?;
        if self.written.is_empty() {
            write!(f, "nothing was written")
        } else {
            let list: Vec<String> = self
                .written
                .iter()
                .map(|p| p.display().to_string())
                .collect();
            write!(
                f,
                "{} was not written (the previews {} had been)",
                self.path.display(),
                list.join(", ")
            )
        }
    }
}

impl std::error::Error for NonFiniteOutput {}

/// Whether `render` writes the X-ray line integrals (rather than the RGBA image) for `out`.
fn writes_values(out: &Rendered, a: &RenderArgs) -> bool {
    out_mode(a) == RenderMode::Xray && out.values.is_some()
}

/// Pixels of what would be written that hold a non-finite value: the line integrals if
/// `values`, otherwise the RGBA image (a pixel counts once however many channels are bad).
pub(crate) fn non_finite_pixels(out: &Rendered, values: bool) -> usize {
    match (&out.values, values) {
        (Some(v), true) => v.values().iter().filter(|x| !x.is_finite()).count(),
        _ => out
            .image
            .pixels()
            .iter()
            .filter(|p| p.iter().any(|c| !c.is_finite()))
            .count(),
    }
}

/// Writes `out` to `path` unless it holds non-finite values ([`NonFiniteOutput`], naming
/// `stage`; `written` lists the files already written by this command).
fn write_checked(
    path: &Path,
    out: &Rendered,
    a: &RenderArgs,
    stage: &str,
    written: &[PathBuf],
) -> Result<()> {
    let bad = non_finite_pixels(out, writes_values(out, a));
    if bad > 0 {
        return Err(NonFiniteOutput {
            stage: stage.to_string(),
            count: bad,
            path: path.to_path_buf(),
            written: written.to_vec(),
        }
        .into());
    }
    write_output(path, out, a).with_context(|| format!("writing {}", path.display()))
}

fn write_output(path: &Path, out: &Rendered, a: &RenderArgs) -> Result<()> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    match ext.as_deref() {
        Some("png") => {
            let bits = png_bits(a)?;
            if let (true, Some(values)) = (writes_values(out, a), &out.values) {
                // X-ray PNGs are scaled so that the brightest pixel is white (--mode help).
                let max = values.values().iter().fold(0.0f32, |m, &v| m.max(v));
                volsplat_io::write_png_gray(path, values, 0.0, max.max(f32::MIN_POSITIVE), bits)?;
            } else {
                let settings = PngSettings {
                    bits,
                    srgb: !a.linear,
                    background: triple::<f32>(&a.background, "--background")?,
                };
                volsplat_io::write_png(path, &out.image, &settings)?;
            }
        }
        Some("npy") => match (writes_values(out, a), &out.values) {
            (true, Some(values)) => volsplat_io::write_npy_scalar(path, values)?,
            _ => volsplat_io::write_npy_rgba(path, &out.image)?,
        },
        _ => bail!(
            "-o {}: unsupported extension; use .png or .npy",
            path.display()
        ),
    }
    Ok(())
}

fn png_bits(a: &RenderArgs) -> Result<PngBitDepth> {
    PngBitDepth::from_bits(a.bits as u32)
        .ok_or_else(|| anyhow!("--bits must be 8 or 16, got {}", a.bits))
}

/// The checks of `render` that need no volume: output paths, image size, PNG options. Run
/// before loading and rendering, which can take seconds.
fn check_render_args(a: &RenderArgs) -> Result<RenderSettings> {
    check_output_path(&a.output, "-o", OUTPUT_EXTENSIONS)?;
    if let Some(p) = &a.view.save_camera {
        check_output_path(p, "--save-camera", &[])?;
    }
    png_bits(a)?;
    triple::<f32>(&a.background, "--background")?;
    if let Some(c) = &a.draw_k {
        triple::<f32>(c, "--draw-k")?;
    }
    if !a.given_display_flags.is_empty() && a.renderer == RendererArg::Splat {
        eprintln!(
            "warning: {} only apply to --renderer sabella|nil; the splatting renderer ignores them",
            a.given_display_flags.join(", ")
        );
    }
    if a.renderer != RendererArg::Splat {
        if a.options.mode != ModeArg::Composite {
            bail!(
                "--mode {:?}: the Chapter 6 displays (--renderer sabella|nil) have their own ray \
                 function; use --renderer splat for MIP, MinIP and X-ray",
                a.options.mode
            );
        }
        if !a.given_splat_flags.is_empty() {
            eprintln!(
                "warning: {} only apply to --renderer splat; the {:?} display ignores them",
                a.given_splat_flags.join(", "),
                a.renderer
            );
        }
    }
    build_settings(&a.options)
}

fn out_mode(a: &RenderArgs) -> RenderMode {
    match a.options.mode {
        ModeArg::Composite => RenderMode::Composite,
        ModeArg::Mip => RenderMode::Mip,
        ModeArg::Minip => RenderMode::Minip,
        ModeArg::Xray => RenderMode::Xray,
    }
}

fn stats_json(out: &Rendered, settings: &RenderSettings, load_ms: f64) -> serde_json::Value {
    let s = &out.stats;
    json!({
        "load_ms": load_ms,
        "setup_ms": s.setup_ms,
        "classify_ms": s.classify_ms,
        "splat_ms": s.splat_ms,
        "composite_ms": s.composite_ms,
        "total_ms": s.total_ms,
        "voxels": s.voxels,
        "splats": s.splats,
        "splats_terminated": s.splats_terminated,
        "splats_clipped": s.splats_clipped,
        "splats_widened": s.splats_widened,
        "antialias": settings.antialias.name(),
        "pixel_updates": s.pixel_updates,
        "kernel_cost": s.kernel_cost(),
        "kernel": settings.kernel.name(),
        "sheets": s.sheets,
        "sheet_axis": (["i", "j", "k"].get(s.sheet_axis).copied().unwrap_or("?")),
        "sheet_spacing": s.sheet_spacing,
        "footprint_entries": s.footprint_entries,
        "footprint_phases": s.footprint_phases,
        "footprint_half_extent_px": s.footprint_half_extent,
        "threads": s.threads,
        "width": settings.width,
        "height": settings.height,
    })
}

fn render_cmd(a: RenderArgs) -> Result<()> {
    let t0 = Instant::now();
    let settings = check_render_args(&a)?;
    let (vol, label) = load_volume(&a.input)?;
    let load_ms = t0.elapsed().as_secs_f64() * 1e3;
    let demo = a.input.input.is_none() && a.input.phantom == PhantomKind::Head;
    let camera = build_camera(&a.view, &vol)?;
    if let Some(p) = &a.view.save_camera {
        volsplat_io::save_camera(p, &camera)?;
    }
    let wrote = || {
        if !a.quiet {
            eprintln!(
                "wrote {} ({}×{}, {:.0} ms)",
                a.output.display(),
                settings.width,
                settings.height,
                t0.elapsed().as_secs_f64() * 1e3
            );
        }
    };
    if a.renderer != RendererArg::Splat {
        let tf = build_tf(&a.options, &vol, demo, scene_tf(&a.input))?;
        let pool = thread_pool(a.options.threads)?;
        let (image, stats) = pool
            .install(|| {
                crate::display::render_display(
                    &a,
                    &vol,
                    &camera,
                    &tf,
                    settings.width,
                    settings.height,
                )
            })
            .with_context(|| format!("rendering {label}"))?;
        let out = Rendered {
            image,
            values: None,
            stats: Default::default(),
        };
        let stage = match a.renderer {
            RendererArg::Sabella => "Sabella display".to_string(),
            _ => format!(
                "NIL renderer ({} display)",
                format!("{:?}", a.display.display).to_lowercase()
            ),
        };
        write_checked(&a.output, &out, &a, &stage, &[])?;
        wrote();
        if a.stats {
            println!("{stats}");
        }
        return Ok(());
    }
    let tables = build_tables(&a.options, &vol, demo, scene_tf(&a.input))?;
    let pool = thread_pool(a.options.threads)?;
    if use_list(&camera, &a.options) {
        if a.ladder {
            bail!("--ladder works with the dense orthographic renderer only");
        }
        let (mut out, list) = pool
            .install(|| -> Result<(Rendered, SplatList)> {
                let list = build_list(&a.options, &vol, &tables)?;
                Ok((render_list(&list, &camera, &tables, &settings)?, list))
            })
            .with_context(|| format!("rendering {label}"))?;
        if let Some(color) = &a.draw_k {
            let color = triple::<f32>(color, "--draw-k")?;
            let proj = volsplat_core::Projection::new(&camera, settings.width, settings.height)?;
            match k_distance(vol.grid(), a.options.subsample, &proj) {
                Some(k) => {
                    let depth =
                        pool.install(|| render_list_depth(&list, &camera, &tables, &settings))?;
                    draw_depth_contour(&mut out.image, &depth, k as f32, color)?;
                    if !a.quiet {
                        eprintln!("k = s·D/p = {k:.4} world units from the eye");
                    }
                }
                None => eprintln!(
                    "warning: --draw-k: orthographic view, no distance k (every voxel covers {:.3} pixels)",
                    vol.grid()
                        .spacing
                        .iter()
                        .fold(f64::INFINITY, |m, &v| m.min(v))
                        / proj.pixel_size_at(1.0)
                ),
            }
        }
        write_checked(&a.output, &out, &a, "splat-list renderer", &[])?;
        wrote();
        if a.stats {
            let mut j = stats_json(&out, &settings, load_ms);
            j["renderer"] = json!("splat-list");
            j["list_splats"] = json!(list.len());
            j["list_bytes"] = json!(list.bytes());
            j["list_build_ms"] = json!(list.build_ms());
            j["projection"] = json!(if camera.parallel_projection {
                "orthographic"
            } else {
                "perspective"
            });
            println!("{j}");
        }
        return Ok(());
    }
    if a.draw_k.is_some() {
        bail!("--draw-k needs the splat-list renderer (--perspective or --splat-list)");
    }
    let mut written: Vec<PathBuf> = Vec::new();
    let out = pool
        .install(|| -> Result<Rendered> {
            if a.ladder {
                let ladder = default_ladder(settings.kernel);
                let last = ladder.len() - 1;
                let mut err = None;
                let out = volsplat_core::with_volume!(&vol, v => render_ladder(v, &camera, &tables, &settings, &ladder, &mut |n, r| {
                    if n < last {
                        let s = ladder[n].subsample;
                        let p = preview_path(&a.output, s);
                        let stage = format!("splatting renderer (preview of every {s}th voxel)");
                        if let Err(e) = write_checked(&p, r, &a, &stage, &written) {
                            err = Some(e);
                            return false;
                        }
                        written.push(p.clone());
                        if !a.quiet {
                            eprintln!("preview {}: {} ({:.1} ms)", n + 1, p.display(), r.stats.total_ms);
                        }
                    }
                    true
                }))?;
                if let Some(e) = err {
                    return Err(e);
                }
                Ok(out)
            } else {
                Ok(render_any(&vol, &camera, &tables, &settings)?)
            }
        })
        .with_context(|| format!("rendering {label}"))?;
    write_checked(&a.output, &out, &a, "splatting renderer", &written)?;
    wrote();
    if a.stats {
        println!("{}", stats_json(&out, &settings, load_ms));
    }
    Ok(())
}

fn preview_path(output: &Path, subsample: usize) -> PathBuf {
    let stem = output.file_stem().and_then(|s| s.to_str()).unwrap_or("out");
    let ext = output.extension().and_then(|s| s.to_str()).unwrap_or("png");
    output.with_file_name(format!("{stem}.preview-s{subsample}.{ext}"))
}

fn info_cmd(a: InfoArgs) -> Result<()> {
    let (vol, label) = load_volume(&a.input)?;
    let g = vol.grid();
    let (lo, hi) = vol.value_range();
    let (blo, bhi) = g.bounds_world();
    let d = g.direction;
    println!("source:    {label}");
    println!("type:      {}", vol.scalar_type().name());
    println!(
        "dims:      {} x {} x {} ({} voxels)",
        g.dims[0],
        g.dims[1],
        g.dims[2],
        g.voxel_count()
    );
    println!(
        "spacing:   {} {} {}",
        g.spacing[0], g.spacing[1], g.spacing[2]
    );
    println!("origin:    {} {} {}", g.origin[0], g.origin[1], g.origin[2]);
    for (n, c) in ["i", "j", "k"].iter().enumerate() {
        let col = d.col(n);
        println!("axis {c}:    ({:.6}, {:.6}, {:.6})", col.x, col.y, col.z);
    }
    println!(
        "bounds:    ({:.3}, {:.3}, {:.3}) .. ({:.3}, {:.3}, {:.3})",
        blo.x, blo.y, blo.z, bhi.x, bhi.y, bhi.z
    );
    println!("range:     {lo} .. {hi}");
    Ok(())
}

fn phantom_cmd(a: PhantomArgs) -> Result<()> {
    if let Some(size) = &a.size {
        bail!(
            "phantom --size was renamed --grid (e.g. `--grid {size}`): --size means the image size \
             in render and bench"
        );
    }
    check_output_path(&a.output, "-o", &[])?;
    let vol = make_phantom(a.kind, a.grid.as_deref(), "--grid")?;
    volsplat_io::write_nrrd(&a.output, &vol, a.gzip)?;
    let g = vol.grid();
    eprintln!(
        "wrote {} ({:?}, {} {:?})",
        a.output.display(),
        g.dims,
        vol.scalar_type().name(),
        g.spacing
    );
    Ok(())
}

fn bench_cmd(a: BenchArgs) -> Result<()> {
    if a.frames == 0 {
        bail!("--frames must be ≥ 1");
    }
    let (vol, label) = load_volume(&a.input)?;
    let demo = a.input.input.is_none() && a.input.phantom == PhantomKind::Head;
    let mut camera = build_camera(&a.view, &vol)?;
    let tables = build_tables(&a.options, &vol, demo, scene_tf(&a.input))?;
    let settings = build_settings(&a.options)?;
    let pool = thread_pool(a.options.threads)?;
    let mut times = Vec::with_capacity(a.frames);
    let mut last = None;
    let list_mode = use_list(&camera, &a.options);
    let mut list_info = None;
    pool.install(|| -> Result<()> {
        // The list is built once and reused while only the camera moves (Swan et al. §5).
        let list = if list_mode {
            let l = build_list(&a.options, &vol, &tables)?;
            list_info = Some((l.len(), l.bytes(), l.build_ms()));
            Some(l)
        } else {
            None
        };
        let frame = |camera: &Camera| -> Result<Rendered> {
            Ok(match &list {
                Some(l) => render_list(l, camera, &tables, &settings)?,
                None => render_any(&vol, camera, &tables, &settings)?,
            })
        };
        frame(&camera)?; // warm-up
        for _ in 0..a.frames {
            camera.azimuth(a.orbit.unwrap_or(360.0 / a.frames as f64));
            let out = frame(&camera)?;
            times.push(out.stats.total_ms);
            last = Some(out);
        }
        Ok(())
    })?;
    let mut sorted = times.clone();
    sorted.sort_by(f64::total_cmp);
    let median = sorted[sorted.len() / 2];
    let mut j = last
        .map(|o| stats_json(&o, &settings, 0.0))
        .unwrap_or(json!({}));
    j["input"] = json!(label);
    j["renderer"] = json!(if list_mode { "splat-list" } else { "dense" });
    if let Some((n, bytes, build_ms)) = list_info {
        j["list_splats"] = json!(n);
        j["list_bytes"] = json!(bytes);
        j["list_build_ms"] = json!(build_ms);
    }
    j["volume_bytes"] = json!(vol.grid().voxel_count() * vol.scalar_type().size_bytes());
    j["frames_ms"] = json!(times);
    j["median_ms"] = json!(median);
    j["min_ms"] = json!(sorted[0]);
    j["max_ms"] = json!(sorted[sorted.len() - 1]);
    println!("{j}");
    Ok(())
}

fn texture_bench_cmd(a: TextureBenchArgs) -> Result<()> {
    use volsplat_filter::{TextureBenchSettings, run_texture_bench};
    let settings = match a.size {
        TextureBenchSize::Quick => TextureBenchSettings::quick(),
        TextureBenchSize::Default => TextureBenchSettings::default(),
        TextureBenchSize::Thesis => TextureBenchSettings::thesis_size(),
    };
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let pool = thread_pool(a.threads)?;
    let report = pool.install(|| run_texture_bench(&settings))?;
    for img in &report.images {
        let path = a.out.join(format!("{}.png", img.name));
        volsplat_io::write_png_gray(&path, &img.image, 0.0, 1.0, PngBitDepth::Eight)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    let md = report.to_markdown();
    let path = a.out.join("report.md");
    volsplat_io::write_bytes_atomic(&path, md.as_bytes())
        .with_context(|| format!("writing {}", path.display()))?;
    println!("{md}");
    eprintln!(
        "wrote {} and {} images to {}",
        path.display(),
        report.images.len(),
        a.out.display()
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;
    use volsplat_core::{Image, ScalarImage};

    fn render_args(extra: &[&str]) -> RenderArgs {
        let mut argv = vec!["volsplat", "render"];
        argv.extend_from_slice(extra);
        match Cli::try_parse_from(argv).unwrap().command {
            Command::Render(a) => *a,
            other => panic!("{other:?}"),
        }
    }

    fn rendered(w: usize, h: usize) -> Rendered {
        let mut image = Image::new(w, h);
        for p in image.pixels_mut() {
            *p = [0.25, 0.5, 0.75, 1.0];
        }
        Rendered {
            image,
            values: None,
            stats: Default::default(),
        }
    }

    #[test]
    fn image_size_is_wxh_or_a_single_number() {
        assert_eq!(parse_image_size("640x480", "--size").unwrap(), (640, 480));
        assert_eq!(parse_image_size("64X48", "--size").unwrap(), (64, 48));
        assert_eq!(parse_image_size("512", "--size").unwrap(), (512, 512));
        assert_eq!(parse_image_size(" 7 ", "--size").unwrap(), (7, 7));
        for bad in [
            "", "x", "12by4", "12x", "x12", "1.5", "-3", "3x4x5", "0", "16385", "4x0",
        ] {
            let e = parse_image_size(bad, "--size").unwrap_err().to_string();
            assert!(
                e.contains("--size") && e.contains(&format!("`{bad}`")),
                "{bad}: {e}"
            );
        }
    }

    #[test]
    fn output_paths_are_checked() {
        let dir = tempfile::tempdir().unwrap();
        let ok = dir.path().join("a.PNG");
        check_output_path(&ok, "-o", OUTPUT_EXTENSIONS).unwrap();
        check_output_path(Path::new("relative.npy"), "-o", OUTPUT_EXTENSIONS).unwrap();
        let e = check_output_path(&dir.path().join("a.tif"), "-o", OUTPUT_EXTENSIONS)
            .unwrap_err()
            .to_string();
        assert!(e.contains("a.tif") && e.contains(".png or .npy"), "{e}");
        let e = check_output_path(Path::new("noext"), "-o", OUTPUT_EXTENSIONS)
            .unwrap_err()
            .to_string();
        assert!(e.contains("noext") && e.contains(".png or .npy"), "{e}");
        let missing = dir.path().join("no-such-folder");
        let e = check_output_path(&missing.join("a.png"), "-o", OUTPUT_EXTENSIONS)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(&format!("folder {} does not exist", missing.display())),
            "{e}"
        );
        let e = check_output_path(dir.path(), "-o", OUTPUT_EXTENSIONS)
            .unwrap_err()
            .to_string();
        assert!(e.contains("is a folder"), "{e}");
        // A file where the folder should be.
        let file = dir.path().join("plain");
        std::fs::write(&file, b"x").unwrap();
        let e = check_output_path(&file.join("cam.json"), "--save-camera", &[])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("--save-camera") && e.contains("is not a folder"),
            "{e}"
        );
        check_output_path(&dir.path().join("cam.json"), "--save-camera", &[]).unwrap();
    }

    #[test]
    fn non_finite_pixels_are_counted_in_what_would_be_written() {
        let mut out = rendered(4, 3);
        assert_eq!(non_finite_pixels(&out, false), 0);
        out.image.pixels_mut()[1][2] = f32::NAN;
        out.image.pixels_mut()[5] = [f32::INFINITY, f32::NAN, 0.0, f32::NEG_INFINITY];
        assert_eq!(non_finite_pixels(&out, false), 2);
        // X-ray output writes the line integrals, not the RGBA image.
        let mut v = vec![1.0f32; 12];
        v[7] = f32::NAN;
        out.values = Some(ScalarImage::from_values(4, 3, v).unwrap());
        assert_eq!(non_finite_pixels(&out, true), 1);
        assert_eq!(non_finite_pixels(&out, false), 2);
    }

    #[test]
    fn non_finite_images_are_not_written() {
        let dir = tempfile::tempdir().unwrap();
        for name in ["a.png", "a.npy"] {
            let path = dir.path().join(name);
            let a = render_args(&["-o", path.to_str().unwrap()]);
            let mut out = rendered(5, 4);
            out.image.pixels_mut()[3][0] = f32::NAN;
            out.image.pixels_mut()[9][3] = f32::INFINITY;
            let e = write_checked(&path, &out, &a, "splatting renderer", &[]).unwrap_err();
            assert_eq!(
                e.to_string(),
                "internal error: the splatting renderer produced 2 non-finite pixels; nothing \
                 was written"
            );
            assert!(e.downcast_ref::<NonFiniteOutput>().is_some());
            assert!(!path.exists(), "{name} was written");
            assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
            // The same image made finite is written.
            out.image.pixels_mut()[3][0] = 0.0;
            out.image.pixels_mut()[9][3] = 1.0;
            write_checked(&path, &out, &a, "splatting renderer", &[]).unwrap();
            assert!(path.exists());
            std::fs::remove_file(&path).unwrap();
        }
        // X-ray: the line integrals are checked, and a ladder's earlier previews are named.
        let path = dir.path().join("x.npy");
        let a = render_args(&["--mode", "xray", "-o", path.to_str().unwrap()]);
        let mut out = rendered(2, 2);
        out.values = Some(ScalarImage::from_values(2, 2, vec![0.0, f32::NAN, 1.0, 2.0]).unwrap());
        let preview = dir.path().join("x.preview-s4.npy");
        let e = write_checked(
            &path,
            &out,
            &a,
            "splatting renderer",
            std::slice::from_ref(&preview),
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("1 non-finite pixel;")
                && e.contains(&format!("{} was not written", path.display()))
                && e.contains(&preview.display().to_string()),
            "{e}"
        );
        assert!(!path.exists());
    }
}
