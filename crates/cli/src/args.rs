//! Command-line arguments.

use clap::{Args, Parser, Subcommand, ValueEnum};
use std::path::PathBuf;
pub(crate) use volsplat::{
    AntialiasChoice, KernelChoice, Mode, OrderChoice, PhantomKind, PreintegrateChoice,
    ShadeAtChoice, VisibilityChoice, VolumeLevel,
};

/// Direct volume rendering on the CPU by splatting (Westover 1991; Swan et al. 1997), image-aligned
/// slabs and Buchanan's NIL-map displays.
#[derive(Debug, Parser)]
#[command(name = "volsplat", version, long_about = None)]
pub(crate) struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Subcommand)]
pub(crate) enum Command {
    /// Render a volume (or the built-in MRI head) to a PNG or .npy image.
    Render(Box<RenderArgs>),
    /// Render a turntable or a keyframed camera flight to PNG frames, GIF, APNG or video.
    Movie(Box<crate::movie::MovieArgs>),
    /// Print a volume's dimensions, type, spacing, orientation and value range.
    Info(InfoArgs),
    /// List the built-in transfer-function presets, one line each.
    Presets,
    /// Convert a volume (any format `render` reads, a DICOM series included) to NRRD, NIfTI or
    /// MetaImage, keeping its geometry (world frame LPS; NIfTI in its own RAS frame), or to .npy
    /// (samples only, shape z, y, x).
    Convert(ConvertArgs),
    /// Write a built-in phantom as an NRRD file.
    Phantom(PhantomArgs),
    /// Time repeated renders of an orbit around the volume; prints the median per frame.
    Bench(Box<BenchArgs>),
    /// Explore a volume in the browser: previews while dragging, the exact `render` frame at
    /// rest. Prints `open http://127.0.0.1:PORT/?token=…`; Ctrl-C stops.
    View(Box<crate::view::ViewCmdArgs>),
    /// The viewer's latency benchmark: replays a recorded orbit and transfer-function drag
    /// against an in-process server; prints JSON.
    BenchView(Box<crate::view::BenchViewArgs>),
    /// Buchanan's texture-filtering comparison (Tables 5.1–5.11, Plates 5.1–5.16): renders the
    /// test images with every technique and writes a Markdown report and PNG images.
    TextureBench(TextureBenchArgs),
    /// Buchanan's Chapter 6 volume displays (Plates 6.1–6.14, Tables 6.1–6.2): renders every
    /// display on one volume, times them against splatting, and writes a report and images.
    DisplayBench(Box<crate::display::DisplayBenchArgs>),
    /// Swan et al. 1997 anti-aliasing study: Fig. 7 figures (no AA | AA) and the aliasing,
    /// flicker and energy measurements, written to a folder with a Markdown report.
    AaFigures(crate::aa_figures::AaFiguresArgs),
}

/// Where the volume comes from.
#[derive(Debug, Args)]
pub(crate) struct InputArgs {
    /// Volume file: NRRD (.nrrd, .nhdr), MetaImage (.mha, .mhd), NIfTI (.nii, .nii.gz, .hdr),
    /// VTK image data (.vti), TIFF (.tif, .tiff, or a folder of TIFF slices), DICOM (a folder
    /// of a series, or one of its files; --series chooses), an OME-Zarr store (.zarr;
    /// --zarr-level, --channel, --timepoint choose), or raw with --raw-dims. Omit for the
    /// built-in MRI head.
    pub input: Option<PathBuf>,
    /// Built-in volume to use when no INPUT is given. Default: `brain`, the MRI head built into
    /// the binary; `head` when only --phantom-size is given.
    #[arg(long, value_enum, help_heading = "Input")]
    pub phantom: Option<PhantomKind>,
    /// Phantom grid size: N (cube) or X,Y,Z (checkerboard: X,Y[,SQUARE]). Default: the
    /// phantom's own size (the built-in MRI has a fixed grid).
    #[arg(long, value_name = "N|X,Y,Z", help_heading = "Input")]
    pub phantom_size: Option<String>,
    /// Headerless raw input: dimensions X,Y,Z.
    #[arg(long, value_name = "X,Y,Z", help_heading = "Input")]
    pub raw_dims: Option<String>,
    /// Headerless raw input: sample type (u8, i8, u16, i16, f32).
    #[arg(long, default_value = "u8", help_heading = "Input")]
    pub raw_type: String,
    /// Headerless raw input: spacing X,Y,Z in world units.
    #[arg(
        long,
        value_name = "X,Y,Z",
        default_value = "1,1,1",
        help_heading = "Input"
    )]
    pub raw_spacing: String,
    /// Headerless raw input: big-endian samples.
    #[arg(long, hide_short_help = true, help_heading = "Input")]
    pub raw_big_endian: bool,
    /// Headerless raw input: bytes to skip at the start of the file.
    #[arg(
        long,
        default_value_t = 0,
        hide_short_help = true,
        help_heading = "Input"
    )]
    pub raw_skip: u64,
    /// Which volume of a 4-D file (NIfTI, ImageJ hyperstack), from 0.
    #[arg(long, value_name = "N", default_value_t = 0, help_heading = "Input")]
    pub frame: usize,
    /// Which point-data array of a VTK .vti file (default: the active scalars, else the first).
    #[arg(
        long,
        value_name = "NAME",
        hide_short_help = true,
        help_heading = "Input"
    )]
    pub array: Option<String>,
    /// The DICOM series to read from a folder holding several: its SeriesInstanceUID or its
    /// SeriesNumber (`volsplat info FOLDER` lists them).
    #[arg(long, value_name = "UID|NUMBER", help_heading = "Input")]
    pub series: Option<String>,
    /// Which resolution level of an OME-Zarr store to load: 0 (full resolution, the default)
    /// to the coarsest (`volsplat info STORE` lists them), or `auto` when rendering: the
    /// coarsest level whose voxel is no larger than a pixel at the focal plane, chosen per
    /// frame from the camera. Not the renderer's own pyramid (--level), which is built from the
    /// volume loaded.
    #[arg(
        long,
        value_name = "N|auto",
        default_value_t = volsplat::StoreLevel::Index(0),
        hide_short_help = true,
        help_heading = "Input"
    )]
    pub zarr_level: volsplat::StoreLevel,
    /// Which channel of a multi-channel OME-Zarr image, from 0.
    #[arg(
        long,
        value_name = "N",
        default_value_t = 0,
        hide_short_help = true,
        help_heading = "Input"
    )]
    pub channel: usize,
    /// Which time point of an OME-Zarr image, from 0.
    #[arg(
        long,
        value_name = "N",
        default_value_t = 0,
        hide_short_help = true,
        help_heading = "Input"
    )]
    pub timepoint: usize,
    /// Reader limits against untrusted or unusually large files, KEY=VALUE[,KEY=VALUE…]:
    /// voxels (default 2^34), header-bytes (1 MiB), json-bytes (16 MiB), xml-bytes (4 GiB);
    /// values may use exponents (voxels=4e10).
    #[arg(
        long,
        value_name = "KEY=VALUE,…",
        hide_short_help = true,
        help_heading = "Input"
    )]
    pub limits: Option<String>,
}

// Camera and view. Without `--camera` the view starts from VTK's reset camera around the volume
// (looking down −z, +y up); with it, from the file's camera. Either way the flags are then applied
// in VTK's order: Azimuth, Elevation, OrthogonalizeViewUp, Roll, Zoom, Dolly.
#[derive(Debug, Args)]
#[command(next_help_heading = "Camera")]
pub(crate) struct ViewArgs {
    /// Camera JSON file (VTK's camera; format in README.md, section "Files"). --azimuth,
    /// --elevation, --roll, --zoom, --dolly and --perspective/--view-angle are applied to it.
    #[arg(long, value_name = "FILE")]
    pub camera: Option<PathBuf>,
    /// Start from an anatomical view of the patient frame (LPS): anterior, posterior, left,
    /// right, superior or inferior (head up; superior/inferior: anterior up), as 3D Slicer's
    /// view buttons. The rotations below then apply to it.
    #[arg(long, value_name = "SIDE", value_parser = parse_view)]
    pub view: Option<volsplat::core::AnatomicalView>,
    /// Degrees about the view-up axis (VTK's Azimuth) [default: 0].
    #[arg(long, value_name = "DEG", allow_negative_numbers = true)]
    pub azimuth: Option<f64>,
    /// Degrees up over the focal point (VTK's Elevation) [default: 0].
    #[arg(long, value_name = "DEG", allow_negative_numbers = true)]
    pub elevation: Option<f64>,
    /// Degrees about the view direction (VTK's Roll) [default: 0].
    #[arg(long, value_name = "DEG", allow_negative_numbers = true)]
    pub roll: Option<f64>,
    /// Magnification (VTK's Zoom: divides the parallel scale, or the view angle in
    /// perspective) [default: 1].
    #[arg(long, value_name = "FACTOR", allow_negative_numbers = true)]
    pub zoom: Option<f64>,
    /// Perspective projection (VTK's default camera) instead of orthographic; switches a
    /// --camera file's camera to perspective too. Drawn with image-aligned slabs where
    /// `--visibility auto` picks them (composite, MIP, MinIP), else with the splat list (Swan et
    /// al. 1997), which takes the radial kernels only.
    #[arg(long, conflicts_with = "orthographic")]
    pub perspective: bool,
    /// Switch a --camera file's perspective camera to orthographic (VTK's ParallelProjectionOn);
    /// its parallel scale becomes the half-height of the perspective view at the focal point,
    /// so the focal plane keeps its framing. Orthographic is already the default without a file.
    #[arg(long, requires = "camera", hide_short_help = true)]
    pub orthographic: bool,
    /// Perspective only: vertical field of view in degrees (VTK's ViewAngle) [default: 30, or
    /// the --camera file's view_angle].
    #[arg(long, value_name = "DEG")]
    pub view_angle: Option<f64>,
    /// Move the eye towards the focal point, dividing their distance by this factor (VTK's
    /// Dolly; > 1 moves closer) [default: 1].
    #[arg(long, value_name = "FACTOR", allow_negative_numbers = true)]
    pub dolly: Option<f64>,
    /// Write the camera actually used to this JSON file.
    #[arg(long, value_name = "FILE")]
    pub save_camera: Option<PathBuf>,
}

/// Classification and rendering options.
#[derive(Debug, Args)]
pub(crate) struct RenderOptions {
    /// Image size in pixels: WxH (e.g. 640x480), or N for N×N.
    #[arg(
        long,
        value_name = "WxH|N",
        default_value = "512x512",
        help_heading = "Output",
        allow_hyphen_values = true
    )]
    pub size: String,
    /// Ray function. xray: the line integral ∫ρ ds; its PNG is scaled so that the brightest
    /// pixel is white, its .npy holds the unscaled values (data units × world units). X-ray
    /// ignores the transfer function, MIP, MinIP and X-ray the lights, shading switches, surface
    /// enhancement and depth cueing (a warning names what is ignored).
    #[arg(long, value_enum, default_value = "composite", help_heading = "Output")]
    pub mode: Mode,
    /// X-ray: integrate max(ρ + VALUE, 0) instead of ρ. auto (default): 1000 where the values
    /// look like CT in Hounsfield units (−900 or below and 300 or above: attenuation relative
    /// to air, a radiograph), none otherwise; none: the raw values.
    #[arg(
        long,
        value_name = "VALUE|auto|none",
        allow_hyphen_values = true,
        value_parser = |s: &str| s.parse::<volsplat::XrayDensity>(),
        help_heading = "Output",
        hide_short_help = true
    )]
    pub xray_offset: Option<volsplat::XrayDensity>,
    /// Transfer-function JSON file (VTK's volume property; format in README.md, section
    /// "Files").
    #[arg(
        long,
        value_name = "FILE",
        conflicts_with = "preset",
        help_heading = "Transfer function"
    )]
    pub tf: Option<PathBuf>,
    /// Built-in transfer function: 3D Slicer's presets (CT-Bone, CT-AAA, MR-Default, …; in
    /// absolute data units, e.g. Hounsfield) and volsplat's ct-skin and ramp; `volsplat presets`
    /// lists them. `auto` (the default): a function from the volume's histogram that makes the
    /// background transparent (ct-skin for the synthetic CT `head` phantom; an opaque grey
    /// window for MIP/MinIP). With --scene, a --mode other than the scene's takes the new mode's
    /// default unless --tf or --preset is given.
    #[arg(
        long,
        value_name = "NAME",
        value_parser = parse_preset,
        help_heading = "Transfer function"
    )]
    pub preset: Option<String>,
    /// Surface enhancement: modulate opacity by a 0→1 ramp on gradient magnitude LO:HI
    /// (data units per world unit). Replaces gradient opacity.
    #[arg(
        long,
        value_name = "LO:HI",
        help_heading = "Transfer function",
        hide_short_help = true
    )]
    pub surface_enhance: Option<String>,
    /// Crop box in voxel indices, X0:X1,Y0:Y1,Z0:Z1 (inclusive, may be fractional): keeps those
    /// voxels, cut smoothly half a voxel outside them (as VTK's cropping region).
    #[arg(
        long,
        value_name = "X0:X1,Y0:Y1,Z0:Z1",
        conflicts_with = "crop_mm",
        help_heading = "Clipping"
    )]
    pub crop: Option<String>,
    /// Crop box in world coordinates (mm for medical volumes, LPS), X0:X1,Y0:Y1,Z0:Z1.
    #[arg(
        long,
        value_name = "X0:X1,Y0:Y1,Z0:Z1",
        allow_hyphen_values = true,
        help_heading = "Clipping"
    )]
    pub crop_mm: Option<String>,
    /// A clipping plane NX,NY,NZ,D (world frame): keeps the points with N·x + D ≥ 0, the side
    /// the normal points to, as VTK. Repeat for several (at most 64); the cut is smooth, not
    /// voxel-stepped.
    #[arg(
        long,
        value_name = "NX,NY,NZ,D",
        allow_hyphen_values = true,
        help_heading = "Clipping"
    )]
    pub clip_plane: Vec<String>,
    /// Depth cueing: modulate opacity from NEAR (front) to FAR (back), both in [0, 1].
    #[arg(
        long,
        value_name = "NEAR:FAR",
        help_heading = "Transfer function",
        hide_short_help = true
    )]
    pub depth_cue: Option<String>,
    /// A directional light: direction X,Y,Z towards the light in the camera frame (x right, y up,
    /// z towards the viewer), optionally followed by colour R,G,B and ambient colour AR,AG,AB
    /// (what the transfer function's `ambient` multiplies; black unless given, as VTK's
    /// lights). Repeat for several lights (at most 16). Default: one white headlight (0,0,1)
    /// with a black ambient colour, as VTK.
    #[arg(
        long,
        value_name = "X,Y,Z[,R,G,B[,AR,AG,AB]]",
        allow_hyphen_values = true,
        help_heading = "Transfer function",
        hide_short_help = true
    )]
    pub light: Vec<String>,
    /// Leave out the emission term (Westover §3.6.1 switches): unshaded, the colour itself;
    /// shaded, the transfer function's `ambient` × the lights' ambient colour, which is black
    /// (no term) unless a --light gives one.
    #[arg(long, help_heading = "Transfer function", hide_short_help = true)]
    pub no_emission: bool,
    /// Leave out the diffuse term.
    #[arg(long, help_heading = "Transfer function", hide_short_help = true)]
    pub no_diffuse: bool,
    /// Leave out the specular term.
    #[arg(long, help_heading = "Transfer function", hide_short_help = true)]
    pub no_specular: bool,
    /// Reconstruction kernel (perspective views and --splat-list take the radial ones:
    /// gaussian or crawfis-max).
    #[arg(long, value_enum, default_value = "gaussian", help_heading = "Quality")]
    pub kernel: KernelChoice,
    /// Anti-aliasing of voxels smaller than a pixel. Sheet renderers: Swan et al. 1997 eq. 4
    /// and 8 (`swan`), its §4.6 perpendicular-distance estimate (`swan-perpendicular`),
    /// Zwicker et al.'s EWA screen filter (`ewa`), a one-pixel box's variance added to each
    /// footprint (`area`), or none; image-aligned slabs average ⌈pixel/voxel⌉² rays unless
    /// `none`. Changes nothing where voxels cover a pixel or more (`area` and `ewa` widen a
    /// little).
    #[arg(long, value_enum, default_value = "area", help_heading = "Quality")]
    pub antialias: AntialiasChoice,
    /// Visibility: image-aligned slabs classified and shaded per pixel after reconstruction
    /// (`image`), Westover's sheet buffers (`sheet`), composite-every-sample (`every`), or `auto`:
    /// slabs for composite, MIP and MinIP; sheets for X-ray and for composite that needs the
    /// gradient with tables of more than the density (gradient-magnitude opacity, shading with
    /// depth cueing) unless `--shade-at samples` (docs/decisions/0016, 0019, 0036).
    #[arg(
        long,
        value_enum,
        default_value = "auto",
        help_heading = "Quality",
        hide_short_help = true
    )]
    pub visibility: VisibilityChoice,
    /// Traversal order.
    #[arg(
        long,
        value_enum,
        default_value = "ftb",
        help_heading = "Quality",
        hide_short_help = true
    )]
    pub order: OrderChoice,
    /// Splat every N-th voxel per axis (successive refinement preview).
    #[arg(
        long,
        default_value_t = 1,
        help_heading = "Quality",
        hide_short_help = true
    )]
    pub subsample: usize,
    /// Front-to-back early termination: a pixel whose opacity reaches this value takes no more
    /// samples or splats. The default, 1 − 255/32767 ≈ 0.9922, is where VTK's fixed-point ray
    /// caster stops (a pixel changes by at most 0.78 % of the light behind where it stops;
    /// docs/decisions/0018); 0.999999 changes no pixel by more than 1e-6; values ≥ 1 disable it.
    #[arg(
        long,
        default_value_t = volsplat::DEFAULT_OPACITY_CUTOFF,
        help_heading = "Quality",
        hide_short_help = true
    )]
    pub opacity_cutoff: f32,
    /// `--visibility image`: slab thickness (plane spacing along the view) in units of the
    /// smallest voxel spacing, in [0.01, 16]. Default: 1 for composite (unshaded or shaded at
    /// the voxels), 0.5 for MIP, MinIP and composite shaded at the samples
    /// (docs/decisions/0017-slab-thickness-by-mode.md, 0019).
    #[arg(long, help_heading = "Quality", hide_short_help = true)]
    pub slab: Option<f64>,
    /// Shaded composite: evaluate the lights at every sample with the interpolated gradient
    /// (`samples`, the exact integral's order: the slabs light each one-voxel slab twice), at the
    /// voxels with the light interpolated (`voxels`, as VTK's CPU ray caster does: for pictures
    /// that match VTK's), or `auto`: at the samples where the slabs' kernel can (transfer
    /// functions of the density alone), at the voxels otherwise (docs/decisions/0019, 0036).
    #[arg(
        long,
        value_enum,
        default_value = "auto",
        help_heading = "Quality",
        hide_short_help = true
    )]
    pub shade_at: ShadeAtChoice,
    /// Image-aligned slabs, composite: classify each slab by the ray's segment from the
    /// previous plane's sample to its own (`on`, pre-integrated: no rings where a
    /// transfer-function ramp is sharper than the data's steps), by its one sample (`off`), or
    /// by segment only where the ramp is sharp (`auto`; docs/decisions/0020).
    #[arg(
        long,
        value_enum,
        default_value = "auto",
        help_heading = "Quality",
        hide_short_help = true
    )]
    pub preintegrate: PreintegrateChoice,
    /// Image-aligned slabs: the level of the volume's resolution pyramid to draw: `full` (the
    /// volume itself), `auto` (the level whose voxel is about a pixel at the focal point: a
    /// preview whose cost falls with the pixel count) or a level number, each level low-pass
    /// filtered and halved once more (docs/decisions/0031).
    #[arg(
        long,
        default_value = "full",
        help_heading = "Quality",
        hide_short_help = true
    )]
    pub level: VolumeLevel,
    /// Worker threads (default: all cores).
    #[arg(long, help_heading = "Performance")]
    pub threads: Option<usize>,
    /// OME-Zarr stores: read the level in bricks through a cache of at most SIZE (bytes, or
    /// with KiB, MiB, GiB; K, M, G), out of core, instead of whole. The picture is the same
    /// bits. Default: whole, unless the level is larger than half the available memory.
    /// Drawn by the image-aligned slabs (composite, MIP, MinIP).
    #[arg(long, value_name = "SIZE", value_parser = parse_size, help_heading = "Performance")]
    pub memory: Option<u64>,
    /// Render from a sparse splat list (Swan et al. §5): the visible voxels (every voxel for
    /// MIP and MinIP) are extracted once and reused for every frame. Perspective views use it where image-aligned slabs are not
    /// chosen (X-ray, sheet-only options, --visibility sheet or every).
    #[arg(long, help_heading = "Performance", hide_short_help = true)]
    pub splat_list: bool,
    /// Splat list: keep voxels whose opacity (scalar × gradient opacity) exceeds this, in
    /// [0, 1). 0 keeps every voxel that is not fully transparent.
    #[arg(
        long,
        default_value_t = 0.0,
        help_heading = "Performance",
        hide_short_help = true
    )]
    pub list_threshold: f32,
}

/// How images become PNG files (render and movie).
#[derive(Debug, Clone, Args)]
pub(crate) struct ImageOptions {
    /// PNG bit depth: 8 or 16.
    #[arg(
        long = "bit-depth",
        id = "bits",
        visible_alias = "bits",
        value_name = "8|16",
        default_value_t = 8,
        help_heading = "Output"
    )]
    pub bits: u8,
    /// Encode PNG values with the sRGB transfer curve. Default: linear values, as VTK, ParaView
    /// and 3D Slicer write their framebuffers (docs/decisions/0012).
    #[arg(long, help_heading = "Output")]
    pub srgb: bool,
    /// Linear PNG values: the default now; kept so that older command lines still work.
    #[arg(long, hide = true, conflicts_with = "srgb")]
    pub linear: bool,
    /// Background colour R,G,B, each a linear value in [0, 1], composited under the image.
    #[arg(
        long,
        value_name = "R,G,B",
        default_value = "0,0,0",
        help_heading = "Output"
    )]
    pub background: String,
    /// Grey window for --mode mip, minip and xray: values LO..HI (data units; X-ray: data units
    /// × world units) map to black..white, linearly; values outside are clamped. Default: MIP and
    /// MinIP through the transfer function, X-ray from 0 to its brightest pixel.
    #[arg(
        long,
        value_name = "LO:HI",
        allow_hyphen_values = true,
        conflicts_with = "wl",
        help_heading = "Output"
    )]
    pub window: Option<String>,
    /// The same grey window as radiologists give it: LEVEL,WIDTH (centre and width; CT bone is
    /// 300,1500), i.e. --window LEVEL−WIDTH/2:LEVEL+WIDTH/2.
    #[arg(
        long,
        value_name = "LEVEL,WIDTH",
        allow_hyphen_values = true,
        help_heading = "Output"
    )]
    pub wl: Option<String>,
}

/// A `--view` value (also A, P, L, R, S, I): the engine's names, as Python's `view=`.
fn parse_view(s: &str) -> Result<volsplat::core::AnatomicalView, String> {
    volsplat::core::AnatomicalView::from_name(s).map_err(|_| {
        format!("`{s}`: expected anterior, posterior, left, right, superior or inferior")
    })
}

/// A `--preset` value: `auto`, or a preset's canonical name (case and `_`/`-` as the user
/// likes; an unknown name is a usage error listing the names).
fn parse_preset(s: &str) -> Result<String, String> {
    if s.eq_ignore_ascii_case("auto") {
        return Ok("auto".into());
    }
    s.parse::<volsplat::core::Preset>()
        .map(|p| p.name().to_string())
        .map_err(|e| e.to_string())
}

#[derive(Debug, Args)]
pub(crate) struct RenderArgs {
    #[command(flatten)]
    pub input: InputArgs,
    /// Output image: .png (8-bit linear values as VTK writes them; --srgb encodes, --bit-depth 16)
    /// or .npy (float32 H×W×4, premultiplied; H×W line integrals for --mode xray). Its folder
    /// must exist.
    #[arg(short, long, value_name = "FILE", help_heading = "Output")]
    pub output: PathBuf,
    #[command(flatten)]
    pub view: ViewArgs,
    #[command(flatten)]
    pub options: RenderOptions,
    #[command(flatten)]
    pub image: ImageOptions,
    /// Print per-stage timings and counters as one JSON object on stdout.
    #[arg(long, help_heading = "Output")]
    pub stats: bool,
    /// Don't print notes or what was written (warnings and errors are still printed).
    #[arg(short, long, help_heading = "Output")]
    pub quiet: bool,
    /// Render the request of a scene file (as written by --save-scene) instead of starting from
    /// the defaults; flags given on the command line override its fields.
    #[arg(long, value_name = "FILE", help_heading = "Input")]
    pub scene: Option<PathBuf>,
    /// Write the complete request that was rendered (volume, resolved camera and transfer
    /// function, size, mode, renderer, quality) to this JSON file; `--scene` renders it again,
    /// bit for bit.
    #[arg(long, value_name = "FILE", help_heading = "Output")]
    pub save_scene: Option<PathBuf>,
    /// Also write the successive-refinement previews (every 4th and 2nd voxel) next to OUTPUT.
    #[arg(long, help_heading = "Output", hide_short_help = true)]
    pub ladder: bool,
    /// Perspective: draw the line at distance k = s·D/p beyond which a voxel covers less than
    /// a pixel (Swan et al. Fig. 7a, c), in the colour R,G,B (default black).
    #[arg(
        long,
        value_name = "R,G,B",
        num_args = 0..=1,
        default_missing_value = "0,0,0",
        help_heading = "Output",
        hide_short_help = true
    )]
    pub draw_k: Option<String>,
    /// Which renderer draws the image: the splatting renderers, chosen per request (`auto`), or
    /// one of Buchanan's Chapter 6 displays (Sabella's density-emitter model, or the NIL-map linearised display;
    /// README.md, section "Volume display as filtering"). Their options: see --help.
    #[arg(
        long,
        value_enum,
        default_value = "auto",
        help_heading = "Research (Chapter 6 displays)"
    )]
    pub renderer: RendererArg,
    #[command(flatten)]
    pub display: crate::display::DisplayArgs,
    /// The Chapter 6 display flags given on the command line (filled in by `main`), to warn
    /// when the splatting renderer would ignore them.
    #[arg(skip)]
    pub given_display_flags: Vec<String>,
    /// The splatting-only flags given on the command line (filled in by `main`), to warn when
    /// a Chapter 6 display would ignore them.
    #[arg(skip)]
    pub given_splat_flags: Vec<String>,
    /// Every flag given on the command line (clap ids, filled in by `main`): with `--scene`,
    /// only these override the scene file.
    #[arg(skip)]
    pub given: Vec<String>,
}

/// `render` flags that only the splatting renderer reads (clap ids and their flags).
pub(crate) const SPLAT_ONLY_FLAGS: &[(&str, &str)] = &[
    ("kernel", "--kernel"),
    ("visibility", "--visibility"),
    ("order", "--order"),
    ("subsample", "--subsample"),
    ("surface_enhance", "--surface-enhance"),
    ("depth_cue", "--depth-cue"),
    ("light", "--light"),
    ("no_emission", "--no-emission"),
    ("no_diffuse", "--no-diffuse"),
    ("no_specular", "--no-specular"),
    ("opacity_cutoff", "--opacity-cutoff"),
    ("slab", "--slab"),
    ("shade_at", "--shade-at"),
    ("preintegrate", "--preintegrate"),
    ("level", "--level"),
    ("antialias", "--antialias"),
    ("splat_list", "--splat-list"),
    ("list_threshold", "--list-threshold"),
    ("ladder", "--ladder"),
    ("draw_k", "--draw-k"),
];

/// Renderers reachable from `render --renderer`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub(crate) enum RendererArg {
    /// The splatting renderers, chosen per request as the engine's `auto` chooses: the
    /// image-aligned slabs, Westover's sheets or the splat list with Swan's anti-aliasing
    /// (docs/architecture.md, "Which renderer draws a request"). `splat` is its earlier name.
    #[value(alias = "splat")]
    Auto,
    /// Sabella's density-emitter display integrated along each ray (Buchanan eq. 3.1).
    Sabella,
    /// Sabella's display evaluated with NIL maps (Buchanan ch. 6; decision 0027), or another
    /// Chapter 6 display (--display).
    Nil,
}

#[derive(Debug, Args)]
pub(crate) struct InfoArgs {
    #[command(flatten)]
    pub input: InputArgs,
    /// Print one JSON object (stable field names, documented in README.md "Files") instead of
    /// text.
    #[arg(long)]
    pub json: bool,
    /// OME-Zarr stores: summarise the level from its metadata and a ranges scan that holds at
    /// most SIZE of bricks at once (bytes, or with KiB, MiB, GiB), as `render --memory` reads
    /// it, instead of reading it whole. Default: whole, unless the level is larger than half
    /// the available memory. The scan's ranges are kept for the next open.
    #[arg(long, value_name = "SIZE", value_parser = parse_size)]
    pub memory: Option<u64>,
}

#[derive(Debug, Args)]
pub(crate) struct ConvertArgs {
    #[command(flatten)]
    pub input: InputArgs,
    /// Output, by its extension: .nrrd (attached header, space left-posterior-superior), .nii or
    /// .nii.gz (NIfTI-1, sform and qform; geometry rounded to float32), .mha or .mhd (MetaImage
    /// as ITK writes it; .mhd with a .raw/.zraw data file beside it), .npy (the samples in
    /// their own type, shape (z, y, x), no geometry), or .zarr (an OME-Zarr pyramid: levels
    /// halved by the renderer's own prefilter until one fits a chunk; zstd-compressed).
    #[arg(short, long, value_name = "FILE")]
    pub output: PathBuf,
    /// .zarr output: chunk edge in samples (cubic chunks), 1 to 1024.
    #[arg(long, value_name = "N", default_value_t = 64)]
    pub chunk: usize,
    /// .zarr output: 2 writes OME-Zarr 0.4 on Zarr v2 (blosc-zstd; read by zarr 2.x and 3.x,
    /// ome-zarr-py, napari), 3 writes OME-Zarr 0.5 on Zarr v3 (zstd; zarr 3.x).
    #[arg(long, value_name = "2|3", default_value_t = 2)]
    pub zarr_version: u8,
    /// Compress the samples: NRRD gzip encoding, MetaImage zlib (.mhd: a .zraw data file). For
    /// NIfTI name the output .nii.gz; .npy is never compressed.
    #[arg(long)]
    pub gzip: bool,
    /// Don't print what was written.
    #[arg(short, long)]
    pub quiet: bool,
}

#[derive(Debug, Args)]
pub(crate) struct PhantomArgs {
    /// Which phantom.
    #[arg(value_enum)]
    pub kind: PhantomKind,
    /// Output NRRD file.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Grid size: N (cube) or X,Y,Z (checkerboard: X,Y[,SQUARE]), as `render --phantom-size`.
    /// Default: the phantom's own size, the one `render --phantom KIND` uses (brain: fixed,
    /// 84×128×128; head 128×160×144; shepp-logan, blobs, marschner-lobb 128³).
    #[arg(long, value_name = "N|X,Y,Z")]
    pub grid: Option<String>,
    /// Renamed: `--size` means the image size in `render` and `bench`; use --grid here.
    #[arg(long, hide = true, allow_hyphen_values = true)]
    pub size: Option<String>,
    /// Gzip the payload.
    #[arg(long)]
    pub gzip: bool,
}

#[derive(Debug, Args)]
pub(crate) struct BenchArgs {
    #[command(flatten)]
    pub input: InputArgs,
    #[command(flatten)]
    pub view: ViewArgs,
    #[command(flatten)]
    pub options: RenderOptions,
    /// Frames to time, after one warm-up frame (at most 100000).
    #[arg(long, default_value_t = 8)]
    pub frames: usize,
    /// Degrees of azimuth between frames (default 360/frames; 0 keeps the view fixed).
    #[arg(long, allow_negative_numbers = true)]
    pub orbit: Option<f64>,
    /// Time the request of a scene file (as written by `render --save-scene`); flags given
    /// override its fields.
    #[arg(long, value_name = "FILE")]
    pub scene: Option<PathBuf>,
    /// Every flag given on the command line (filled in by `main`).
    #[arg(skip)]
    pub given: Vec<String>,
}

/// Image size presets of the texture-filtering benchmark.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub(crate) enum TextureBenchSize {
    /// 48×36: a quick look (seconds).
    Quick,
    /// 128×96 (default; about a minute on 2 cores).
    Default,
    /// 100×100, the thesis's size.
    Thesis,
}

#[derive(Debug, Args)]
pub(crate) struct TextureBenchArgs {
    /// Output folder for report.md and the images (created if missing).
    #[arg(short, long, default_value = "texture-bench")]
    pub out: PathBuf,
    /// Image size preset.
    #[arg(long, value_enum, default_value = "default")]
    pub size: TextureBenchSize,
    /// Worker threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
}

/// A size in bytes: a whole number, optionally followed by `KiB`, `MiB`, `GiB`, `TiB` (or `K`,
/// `M`, `G`, `T`, `KB`, `MB`, `GB`, `TB`, all powers of 1024, as memory is counted).
pub(crate) fn parse_size(text: &str) -> Result<u64, String> {
    let t = text.trim();
    let split = t.find(|c: char| !c.is_ascii_digit()).unwrap_or(t.len());
    let (num, unit) = t.split_at(split);
    let n: u64 = num
        .parse()
        .map_err(|_| format!("`{text}` is not a size (a whole number, then KiB, MiB or GiB)"))?;
    let shift = match unit.trim().to_ascii_lowercase().as_str() {
        "" | "b" => 0,
        "k" | "kb" | "kib" => 10,
        "m" | "mb" | "mib" => 20,
        "g" | "gb" | "gib" => 30,
        "t" | "tb" | "tib" => 40,
        u => return Err(format!("`{u}` is not a size unit (KiB, MiB, GiB, TiB)")),
    };
    n.checked_mul(1u64 << shift)
        .filter(|&b| b > 0)
        .ok_or_else(|| format!("`{text}` must be a size above 0 and below 16 EiB"))
}

#[cfg(test)]
mod size_tests {
    use super::parse_size;

    #[test]
    fn sizes_parse_in_powers_of_1024_and_bad_ones_are_errors() {
        assert_eq!(parse_size("2GiB"), Ok(2 << 30));
        assert_eq!(parse_size("512MiB"), Ok(512 << 20));
        assert_eq!(parse_size("16M"), Ok(16 << 20));
        assert_eq!(parse_size("4096"), Ok(4096));
        assert_eq!(parse_size("1 kb"), Ok(1024));
        for bad in ["", "0", "GiB", "2 PiB", "-1G", "1.5G", "99999999999999T"] {
            assert!(parse_size(bad).is_err(), "{bad}");
        }
    }
}
