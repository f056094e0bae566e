//! Translation of `render` / `bench` flags into an engine [`RenderRequest`]: no rendering maths
//! here, only parsing and mapping.
//!
//! Without `--scene`, every flag applies (with its default when not given). With `--scene FILE`
//! the file's request is the starting point and only the flags given on the command line
//! override its fields.

use crate::args::*;
use crate::say::say;
use anyhow::{Context, Result, anyhow, bail};
use std::collections::HashSet;
use volsplat::core::{Orbit, ProjectionKind, ScalarType};
use volsplat::{
    CameraSpec, LightSpec, RawLayout, RenderRequest, RendererChoice, Scene, TransferSpec,
    VolumeSource,
};

/// The clap ids of the flags given on the command line.
pub(crate) type Given = HashSet<String>;

/// Parses "A,B,C" into three numbers, naming the flag on error.
pub(crate) fn triple<T: std::str::FromStr>(s: &str, flag: &str) -> Result<[T; 3]> {
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

pub(crate) fn pair(s: &str, sep: char, flag: &str) -> Result<[f64; 2]> {
    let (a, b) = s
        .split_once(sep)
        .ok_or_else(|| anyhow!("{flag}: expected A{sep}B, got `{s}`"))?;
    let p = |v: &str| {
        v.trim()
            .parse::<f64>()
            .map_err(|_| anyhow!("{flag}: `{v}` is not a number"))
    };
    Ok([p(a)?, p(b)?])
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

/// A phantom grid `N`, `X,Y,Z` (or the checkerboard's `X,Y[,SQUARE]`) as numbers.
pub(crate) fn parse_grid(s: &str, flag: &str) -> Result<Vec<usize>> {
    s.split(',')
        .map(|p| {
            p.trim()
                .parse::<usize>()
                .map_err(|_| anyhow!("{flag}: `{s}` is not a size (N or X,Y,Z)"))
        })
        .collect()
}

/// A crop box `X0:X1,Y0:Y1,Z0:Z1`.
fn parse_crop(s: &str, flag: &str, units: volsplat::CropUnits) -> Result<volsplat::CropBox> {
    let axes: Vec<&str> = s.split(',').map(str::trim).collect();
    if axes.len() != 3 {
        bail!("{flag} {s}: expected X0:X1,Y0:Y1,Z0:Z1");
    }
    let mut min = [0.0; 3];
    let mut max = [0.0; 3];
    for (k, a) in axes.iter().enumerate() {
        let [lo, hi] = pair(a, ':', flag)?;
        if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
            bail!(
                "{flag} {s}: axis {} needs LO ≤ HI, got {a}",
                ["X", "Y", "Z"][k]
            );
        }
        (min[k], max[k]) = (lo, hi);
    }
    Ok(volsplat::CropBox { min, max, units })
}

/// A clipping plane `NX,NY,NZ,D`.
fn parse_plane(s: &str) -> Result<volsplat::PlaneSpec> {
    let v: Vec<f64> = s
        .split(',')
        .map(|p| p.trim().parse::<f64>())
        .collect::<std::result::Result<_, _>>()
        .map_err(|_| anyhow!("--clip-plane {s}: expected four numbers NX,NY,NZ,D"))?;
    let [nx, ny, nz, d] = v[..] else {
        bail!("--clip-plane {s}: expected four numbers NX,NY,NZ,D");
    };
    if !(nx.is_finite() && ny.is_finite() && nz.is_finite() && d.is_finite())
        || nx == 0.0 && ny == 0.0 && nz == 0.0
    {
        bail!("--clip-plane {s}: the normal must be finite and non-zero, D finite");
    }
    Ok(volsplat::PlaneSpec {
        normal: [nx, ny, nz],
        offset: d,
    })
}

/// The reader limits of `--limits` (the defaults where not given).
pub(crate) fn reader_limits(a: &InputArgs) -> Result<volsplat::io::Limits> {
    let mut l = volsplat::io::Limits::default();
    let Some(text) = &a.limits else {
        return Ok(l);
    };
    for item in text.split(',').map(str::trim).filter(|s| !s.is_empty()) {
        let (key, value) = item
            .split_once('=')
            .ok_or_else(|| anyhow!("--limits {item}: expected KEY=VALUE"))?;
        let v: f64 = value
            .trim()
            .parse()
            .map_err(|_| anyhow!("--limits {item}: `{value}` is not a number"))?;
        if !(1.0..=1.8e19).contains(&v) {
            bail!("--limits {item}: must be a whole number from 1 to 1.8e19");
        }
        let n = v.round() as u64;
        match key.trim() {
            "voxels" => l.max_voxels = n as u128,
            "header-bytes" => l.max_header_bytes = n.min(usize::MAX as u64) as usize,
            "json-bytes" => l.max_json_bytes = n,
            "xml-bytes" => l.max_xml_bytes = n,
            other => bail!(
                "--limits {item}: unknown limit `{other}`; use voxels, header-bytes, json-bytes \
                 or xml-bytes"
            ),
        }
    }
    Ok(l)
}

/// The volume source of the input flags.
pub(crate) fn volume_source(a: &InputArgs) -> Result<VolumeSource> {
    Ok(match &a.input {
        None => VolumeSource::Phantom {
            // The synthetic head is the one with a size to choose (and was the demo before the
            // built-in MRI), so `--phantom-size` alone keeps meaning it.
            phantom: a.phantom.unwrap_or(if a.phantom_size.is_some() {
                PhantomKind::Head
            } else {
                PhantomKind::Brain
            }),
            grid: a
                .phantom_size
                .as_deref()
                .map(|s| parse_grid(s, "--phantom-size"))
                .transpose()?,
        },
        Some(path) => {
            let raw = match &a.raw_dims {
                None => None,
                Some(dims) => {
                    ScalarType::from_name(&a.raw_type).context("--raw-type")?;
                    Some(RawLayout {
                        dims: triple::<usize>(dims, "--raw-dims")?,
                        scalar_type: a.raw_type.clone(),
                        spacing: triple::<f64>(&a.raw_spacing, "--raw-spacing")?,
                        origin: [0.0; 3],
                        big_endian: a.raw_big_endian,
                        header_bytes: a.raw_skip,
                    })
                }
            };
            VolumeSource::File {
                path: path.clone(),
                raw,
                frame: a.frame,
                array: a.array.clone(),
                series: a.series.clone(),
                level: a.zarr_level,
                channel: a.channel,
                timepoint: a.timepoint,
            }
        }
    })
}

/// Parses `X,Y,Z[,R,G,B[,AR,AG,AB]]`: a camera-relative direction towards the light, an
/// optional colour and an optional ambient colour.
fn parse_light(s: &str) -> Result<LightSpec> {
    let v: Vec<f64> = s
        .split(',')
        .map(|p| {
            p.trim()
                .parse::<f64>()
                .map_err(|_| anyhow!("--light: `{p}` is not a number in `{s}`"))
        })
        .collect::<Result<_>>()?;
    if ![3, 6, 9].contains(&v.len()) {
        bail!("--light: expected X,Y,Z, X,Y,Z,R,G,B or X,Y,Z,R,G,B,AR,AG,AB, got `{s}`");
    }
    let rgb = |i: usize| [v[i] as f32, v[i + 1] as f32, v[i + 2] as f32];
    let l = LightSpec {
        direction: [v[0], v[1], v[2]],
        color: if v.len() >= 6 { rgb(3) } else { [1.0; 3] },
        ambient: if v.len() == 9 { rgb(6) } else { [0.0; 3] },
    };
    l.to_light("--light")
        .map_err(|e| anyhow!("{e} (in `{s}`)"))?;
    Ok(l)
}

/// Builds the request of `render` / `bench` from their flags; `base` is a `--scene` request.
/// Notes for the user ([`build_request_noted`]) are printed on stderr.
#[allow(clippy::too_many_arguments)]
pub(crate) fn build_request(
    input: &InputArgs,
    view: &ViewArgs,
    o: &RenderOptions,
    image: Option<&ImageOptions>,
    renderer: RendererArg,
    display: Option<&crate::display::DisplayArgs>,
    draw_k: Option<&str>,
    given: &Given,
    base: Option<RenderRequest>,
) -> Result<RenderRequest> {
    let (req, notes) = build_request_noted(
        input, view, o, image, renderer, display, draw_k, given, base,
    )?;
    for n in notes {
        say!("note: {n}");
    }
    Ok(req)
}

/// [`build_request`], returning its notes for the user instead of printing them (a caller
/// with `--quiet` leaves them out): today, that a `--mode` given over a scene file's other mode
/// replaced the scene's transfer function by the new mode's default, or dropped its grey
/// window. `image` is the output flags (`--background`, `--srgb`, `--bit-depth`,
/// `--window`/`--wl`; `None` for a command without them, which keeps a scene's).
///
/// The flags are applied in groups, in this order (so the first bad flag is the one named):
/// volume, camera, classification, clipping and cues, size and mode, output, renderer and
/// quality, display.
#[allow(clippy::too_many_arguments)]
pub(crate) fn build_request_noted(
    input: &InputArgs,
    view: &ViewArgs,
    o: &RenderOptions,
    image: Option<&ImageOptions>,
    renderer: RendererArg,
    display: Option<&crate::display::DisplayArgs>,
    draw_k: Option<&str>,
    given: &Given,
    base: Option<RenderRequest>,
) -> Result<(RenderRequest, Vec<String>)> {
    let mut notes = Vec::new();
    let fresh = base.is_none();
    let set = |id: &str| fresh || given.contains(id);
    let mut req = base.unwrap_or_else(|| RenderRequest::new(Scene::default(), 512, 512));
    apply_volume_flags(&mut req.scene, input, &set)?;
    apply_camera_flags(&mut req.scene, view)?;
    apply_classification_flags(&mut req.scene, o, fresh, &set)?;
    apply_clipping_and_cue_flags(&mut req.scene, o, &set)?;
    if set("size") {
        (req.width, req.height) = parse_image_size(&o.size, "--size")?;
    }
    if set("mode") {
        apply_mode_flag(&mut req, o, fresh, given, &mut notes);
    }
    if let Some(image) = image {
        apply_output_flags(&mut req.output, image, &set)?;
    }
    apply_renderer_and_quality_flags(&mut req, o, renderer, draw_k, &set)?;
    if let Some(d) = display {
        apply_display_flags(&mut req.display, d, &set)?;
    }
    Ok((req, notes))
}

/// The volume source, when any of its flags is given (or without a scene).
fn apply_volume_flags(s: &mut Scene, input: &InputArgs, set: &dyn Fn(&str) -> bool) -> Result<()> {
    if [
        "input",
        "phantom",
        "phantom_size",
        "raw_dims",
        "frame",
        "array",
        "series",
        "zarr_level",
        "channel",
        "timepoint",
    ]
    .iter()
    .any(|id| set(id))
    {
        s.volume = volume_source(input)?;
    }
    Ok(())
}

/// The camera: a `--camera` file replaces the scene's camera; each view flag given sets its
/// orbit field, which is then checked (the error names the flag).
fn apply_camera_flags(s: &mut Scene, view: &ViewArgs) -> Result<()> {
    if let Some(path) = &view.camera {
        let (camera, warnings) = volsplat::io::load_camera(path)?;
        for w in warnings {
            say!("warning: {w}");
        }
        s.camera = CameraSpec::Explicit {
            camera,
            orbit: Orbit::default(),
        };
    }
    let orbit = match &mut s.camera {
        CameraSpec::Orbit(o) => o,
        CameraSpec::Explicit { orbit, .. } => orbit,
    };
    let flags = [
        (&mut orbit.azimuth, view.azimuth),
        (&mut orbit.elevation, view.elevation),
        (&mut orbit.roll, view.roll),
        (&mut orbit.zoom, view.zoom),
        (&mut orbit.dolly, view.dolly),
        (&mut orbit.view_angle, view.view_angle),
    ];
    for (field, flag) in flags {
        if flag.is_some() {
            *field = flag;
        }
    }
    if view.view.is_some() {
        orbit.view = view.view;
    }
    if view.perspective {
        orbit.projection = Some(ProjectionKind::Perspective);
    } else if view.orthographic {
        orbit.projection = Some(ProjectionKind::Orthographic);
    }
    if let Err(volsplat::core::CoreError::InvalidField {
        field,
        value,
        reason,
    }) = orbit.validate()
    {
        bail!("--{}: {value} {reason}", field.replace('_', "-"));
    }
    orbit.validate()?;
    Ok(())
}

/// The classification: `--tf` or `--preset`, the lights (`--light`; without a scene, or
/// given at least once over one), the shading switches and `--surface-enhance`.
fn apply_classification_flags(
    s: &mut Scene,
    o: &RenderOptions,
    fresh: bool,
    set: &dyn Fn(&str) -> bool,
) -> Result<()> {
    if let Some(path) = &o.tf {
        let (tf, warnings) = volsplat::io::load_transfer_function(path)?;
        for w in warnings {
            say!("warning: {w}");
        }
        s.transfer_function = TransferSpec::Function(tf);
    } else if let Some(name) = &o.preset {
        s.transfer_function = if name == "auto" {
            TransferSpec::Auto
        } else {
            TransferSpec::Preset(name.parse()?)
        };
    }
    if set("light") && (fresh || !o.light.is_empty()) {
        s.lights = o
            .light
            .iter()
            .map(|l| parse_light(l))
            .collect::<Result<_>>()?;
    }
    if set("no_emission") {
        s.shading.emission = !o.no_emission;
    }
    if set("no_diffuse") {
        s.shading.diffuse = !o.no_diffuse;
    }
    if set("no_specular") {
        s.shading.specular = !o.no_specular;
    }
    if set("surface_enhance") {
        s.surface_enhance = o
            .surface_enhance
            .as_deref()
            .map(|v| pair(v, ':', "--surface-enhance"))
            .transpose()?;
    }
    Ok(())
}

/// Cropping (`--crop` in voxels or `--crop-mm` in world units), clipping planes, the X-ray
/// offset and depth cueing.
fn apply_clipping_and_cue_flags(
    s: &mut Scene,
    o: &RenderOptions,
    set: &dyn Fn(&str) -> bool,
) -> Result<()> {
    if set("crop") || set("crop_mm") {
        s.clipping.crop = match (&o.crop, &o.crop_mm) {
            (Some(c), _) => Some(parse_crop(c, "--crop", volsplat::CropUnits::Voxels)?),
            (None, Some(c)) => Some(parse_crop(c, "--crop-mm", volsplat::CropUnits::World)?),
            (None, None) => None,
        };
    }
    if set("clip_plane") {
        s.clipping.planes = o
            .clip_plane
            .iter()
            .map(|p| parse_plane(p))
            .collect::<Result<_>>()?;
    }
    if let Some(x) = o.xray_offset {
        s.xray_density = x;
    }
    if set("depth_cue") {
        s.depth_cue = o
            .depth_cue
            .as_deref()
            .map(|v| pair(v, ':', "--depth-cue"))
            .transpose()?;
    }
    Ok(())
}

/// `--mode` over `req`. Over a scene of another mode (`fresh` false), a transfer function
/// made for the scene's mode gives way to the new mode's default unless `--tf` or `--preset`
/// is given, and a grey window in other units is dropped unless `--window` or `--wl` is given;
/// each is said in `notes`.
fn apply_mode_flag(
    req: &mut RenderRequest,
    o: &RenderOptions,
    fresh: bool,
    given: &Given,
    notes: &mut Vec<String>,
) {
    let mode = o.mode;
    // A scene's transfer function was made for its mode (a MIP's grey ramp looks flat in
    // composite): another mode without --tf or --preset takes that mode's default.
    if !fresh
        && mode != req.mode
        && o.tf.is_none()
        && o.preset.is_none()
        && req.scene.transfer_function != TransferSpec::Auto
    {
        notes.push(format!(
            "--mode {}: the scene's transfer function was made for mode {}; using {}'s \
             default (auto) instead (give --tf or --preset to choose one)",
            mode_name(mode),
            mode_name(req.mode),
            mode_name(mode)
        ));
        req.scene.transfer_function = TransferSpec::Auto;
    }
    // A scene's grey window was made for its mode's values: another mode without --window
    // or --wl drops it (MIP and MinIP share units; X-ray's are data × world units).
    if let Some([lo, hi]) = req.output.window
        && !req.mode.shares_window_with(mode)
        && !given.contains("window")
        && !given.contains("wl")
    {
        notes.push(format!(
            "--mode {}: the scene's grey window {lo}:{hi} was made for mode {}; dropped \
             (give --window or --wl to set one)",
            mode_name(mode),
            mode_name(req.mode)
        ));
        req.output.window = None;
    }
    req.mode = mode;
}

/// The renderer (`--renderer`, `--splat-list`), the quality fields, `--threads` and
/// `--draw-k`.
fn apply_renderer_and_quality_flags(
    req: &mut RenderRequest,
    o: &RenderOptions,
    renderer: RendererArg,
    draw_k: Option<&str>,
    set: &dyn Fn(&str) -> bool,
) -> Result<()> {
    if set("renderer") || set("splat_list") {
        req.renderer = match renderer {
            RendererArg::Sabella => RendererChoice::Sabella,
            RendererArg::Nil => RendererChoice::Nil,
            RendererArg::Auto if o.splat_list => RendererChoice::SplatList,
            RendererArg::Auto => RendererChoice::Auto,
        };
    }
    let q = &mut req.quality;
    // Flags whose clap id is the quality field's name and whose type is the field's.
    macro_rules! copy_quality {
        ($($f:ident),*) => { $( if set(stringify!($f)) { q.$f = o.$f; } )* };
    }
    copy_quality!(
        kernel,
        antialias,
        visibility,
        order,
        opacity_cutoff,
        subsample,
        list_threshold,
        slab,
        shade_at,
        preintegrate,
        level
    );
    if set("threads") {
        req.threads = o.threads;
    }
    if set("memory") {
        req.memory = o.memory;
    }
    if set("draw_k") {
        req.k_contour = draw_k.map(|c| triple::<f32>(c, "--draw-k")).transpose()?;
    }
    Ok(())
}

/// The flags of the Chapter 6 displays (`--renderer sabella|nil`) into the request's display
/// settings.
fn apply_display_flags(
    t: &mut volsplat::DisplayOptions,
    d: &crate::display::DisplayArgs,
    set: &dyn Fn(&str) -> bool,
) -> Result<()> {
    if set("dog_sigma") {
        let sig: Vec<f64> = d
            .dog_sigma
            .split(',')
            .map(|p| p.trim().parse::<f64>())
            .collect::<std::result::Result<_, _>>()
            .context("--dog-sigma: expected S1,S2")?;
        let [a, b] = sig[..] else {
            bail!("--dog-sigma: expected two numbers S1,S2");
        };
        t.dog_sigma = [a, b];
    }
    macro_rules! copy {
        ($($f:ident),*) => { $( if set(stringify!($f)) { t.$f = d.$f.clone(); } )* };
    }
    copy!(
        display,
        density,
        control_points,
        direct,
        tau,
        screen_sigma,
        supersample,
        samples_per_ray,
        patch_order,
        tolerance,
        trigger_width,
        trigger_steps,
        gamma_min,
        slice_depth,
        slice_width,
        rho0,
        closest,
        dog_gain,
        max_map_values,
        grey,
        attenuation,
        continuous_patches,
        max_cell_width
    );
    Ok(())
}

/// The output flags into the request's output options: all of them without a scene
/// (`set` is always true), the given ones over a scene's.
fn apply_output_flags(
    out: &mut volsplat::OutputOptions,
    image: &ImageOptions,
    set: &dyn Fn(&str) -> bool,
) -> Result<()> {
    use crate::commands::{background, grey_window, png_bits};
    if set("bits") {
        out.bit_depth = png_bits(image)?.bits();
    }
    if set("srgb") || set("linear") {
        out.srgb = image.srgb;
    }
    if set("background") {
        out.background = background(image)?;
    }
    if set("window") || set("wl") {
        out.window = grey_window(image)?.map(|(lo, hi)| [lo, hi]);
    }
    Ok(())
}

/// A mode's name as `--mode` takes it.
pub(crate) fn mode_name(mode: volsplat::Mode) -> String {
    use clap::ValueEnum;
    mode.to_possible_value()
        .map(|v| v.get_name().to_string())
        .unwrap_or_else(|| format!("{mode:?}"))
}
