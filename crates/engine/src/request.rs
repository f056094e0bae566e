//! How it is rendered: image size, ray function, renderer, quality and threads, around a
//! [`Scene`]. A [`RenderRequest`] is one JSON file ([`RenderRequest::load`], [`RenderRequest::save`]).

use crate::error::{EngineError, Result};
use crate::output::OutputOptions;
use crate::scene::Scene;
use serde::{Deserialize, Serialize};
use std::path::Path;
use volsplat_filter::display::{
    Attenuation, ControlPoints, DisplayKind, DisplaySettings, Evaluator, NilDisplaySettings,
    SearchRule,
};
use volsplat_splat::{Antialias, Order, RenderMode, RenderSettings, Visibility};

/// What is computed along each ray.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[non_exhaustive]
pub enum Mode {
    /// Emission–absorption compositing of classified, shaded samples.
    #[default]
    Composite,
    /// Maximum intensity projection (data units).
    Mip,
    /// Minimum intensity projection (data units).
    Minip,
    /// The line integral `∫ρ ds` (data units × world units).
    Xray,
}

impl Mode {
    /// The splatting renderer's mode.
    pub fn splat_mode(self) -> RenderMode {
        match self {
            Mode::Composite => RenderMode::Composite,
            Mode::Mip => RenderMode::Mip,
            Mode::Minip => RenderMode::Minip,
            Mode::Xray => RenderMode::Xray,
        }
    }
}

/// Which renderer draws the image.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[non_exhaustive]
pub enum RendererChoice {
    /// Chosen per request by the rules of `docs/architecture.md` ("Which renderer draws a
    /// request"): image-aligned slabs for composite, MIP and MinIP where visibility `auto`
    /// allows them and always with visibility `image` (X-ray excepted); otherwise splatting,
    /// the dense sheets for orthographic views and the sparse splat list for perspective ones.
    #[default]
    Auto,
    /// Westover's dense orthographic sheet-buffer renderer (Westover 1991); with visibility
    /// `image` (not X-ray) the image-aligned slabs draw instead. Also read as `splat` and
    /// `dense`, its earlier names.
    #[serde(alias = "splat", alias = "dense")]
    #[cfg_attr(feature = "clap", value(aliases = ["splat", "dense"]))]
    Sheets,
    /// The sparse splat list (Swan et al. 1997 §5), orthographic or perspective; the list is
    /// kept by the [`crate::Renderer`] across frames.
    SplatList,
    /// Sabella's density-emitter display (Buchanan eq. 3.1).
    Sabella,
    /// One of Buchanan's Chapter 6 displays evaluated with NIL maps or direct quadrature
    /// ([`DisplayOptions`]).
    Nil,
}

/// Reconstruction kernels by name.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[non_exhaustive]
pub enum KernelChoice {
    /// Westover's Gaussian, σ = 0.6 voxel, radius 2.
    #[default]
    Gaussian,
    /// A single point at the nearest pixel.
    #[cfg_attr(feature = "clap", value(aliases = ["single-point"]))]
    Point,
    /// The voxel's box (nearest neighbour).
    #[cfg_attr(feature = "clap", value(aliases = ["nearest-neighbour", "nn"]))]
    Nearest,
    /// Trilinear (tent).
    #[cfg_attr(feature = "clap", value(aliases = ["linear"]))]
    Tent,
    /// Cubic B-spline (Mitchell–Netravali B = 1, C = 0).
    #[cfg_attr(feature = "clap", value(aliases = ["b-spline"]))]
    Bspline,
    /// Catmull–Rom (B = 0, C = ½); has negative lobes.
    #[cfg_attr(feature = "clap", value(aliases = ["catmullrom"]))]
    CatmullRom,
    /// Mitchell–Netravali B = C = ⅓.
    Mitchell,
    /// Crawfis and Max's minimal-ripple radial cubic (decision 0005).
    #[cfg_attr(feature = "clap", value(aliases = ["crawfismax"]))]
    CrawfisMax,
}

impl KernelChoice {
    /// The core kernel.
    pub fn kernel(self) -> volsplat_core::Kernel {
        let name = match self {
            KernelChoice::Gaussian => "gaussian",
            KernelChoice::Point => "point",
            KernelChoice::Nearest => "nearest",
            KernelChoice::Tent => "tent",
            KernelChoice::Bspline => "bspline",
            KernelChoice::CatmullRom => "catmull-rom",
            KernelChoice::Mitchell => "mitchell",
            KernelChoice::CrawfisMax => "crawfis-max",
        };
        // Every name above is one that `Kernel::from_name` knows (tested).
        volsplat_core::Kernel::from_name(name).unwrap_or_default()
    }
}

/// Anti-aliasing of voxels smaller than a pixel (Swan et al. 1997; [`Antialias`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[non_exhaustive]
pub enum AntialiasChoice {
    /// Swan et al. eq. 4 and 8.
    Swan,
    /// Swan et al. §4.6, per principal axis.
    SwanPerpendicular,
    /// Zwicker et al.'s EWA screen filter.
    Ewa,
    /// The pixel's area (the default, decision 0006 amended 2026-11-24): the footprint's
    /// screen covariance plus a one-pixel box's, 1/12 px² (EWA with a box-sized pre-filter;
    /// Mip-Splatting's 2D filter). Image-aligned slabs average sub-pixel rays instead.
    #[default]
    Area,
    /// None: the true projection whatever its size.
    None,
}

/// How visibility is resolved: chosen per request, Westover's sheet buffers, composite every
/// sample (Westover §3.8.1), or image-aligned slabs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[non_exhaustive]
pub enum VisibilityChoice {
    /// Chosen by measurement (decisions 0016, 0019 and 0036): image-aligned slabs for composite
    /// (lit at the samples by default, at the voxels with `shade_at = voxels`), MIP and MinIP;
    /// Westover's sheet buffers for X-ray (exact line integrals), for composite that needs the
    /// gradient with tables of more than the density (gradient-magnitude opacity, or shading
    /// with depth cueing) unless `shade_at = samples` asks the slabs to light the samples,
    /// successive refinement, the k-contour, an
    /// explicit `sheets`/`splat_list` renderer, and requests that set a sheet-only option (a
    /// kernel other than the Gaussian, subsampling, back-to-front order, or the
    /// `swan-perpendicular`/`ewa` anti-aliasing rules).
    #[default]
    Auto,
    /// Sheet buffers (Westover 1990/91).
    Sheet,
    /// Composite every sample (Westover 1989; bleeds).
    Every,
    /// Image-aligned slabs classified and shaded per pixel after reconstruction (Mueller &
    /// Crawfis 1998; Mueller, Möller & Crawfis 1999): no sheet-axis popping, no pre-classified
    /// blur. Orthographic and perspective, with `renderer` `auto` or `sheets`; X-ray keeps the
    /// exact sheet renderers, and an explicit `splat_list` draws its sheet buffers. The rows of
    /// `docs/architecture.md`, "Which renderer draws a request".
    Image,
}

/// Where image-aligned slabs evaluate the lights in shaded composite
/// ([`volsplat_splat::ShadeAt`]; decision 0019).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[non_exhaustive]
pub enum ShadeAtChoice {
    /// The default (decision 0036): at the samples where the slabs' kernel lights them
    /// (transfer functions of the density alone: each one-voxel slab lit twice, 7–17 dB closer
    /// to the exact integral than VTK for about 1.2× the time of lighting the voxels), at the
    /// voxels otherwise (tables of the gradient magnitude or depth, which `auto` visibility
    /// gives to the sheets).
    #[default]
    Auto,
    /// At the voxels, interpolated: each voxel's gradient direction is shaded once per frame
    /// and a sample blends its cell's eight corners' light, as VTK's CPU ray caster
    /// (`vtkFixedPointVolumeRayCastMapper`) does: for pictures that match VTK's.
    Voxels,
    /// At every sample, with the gradient interpolated there (Mueller, Möller & Crawfis 1999;
    /// the exact integral's order), whatever the transfer function: the slabs, lit twice per
    /// slab by their kernel for tables of the density, by the per-sample classifier otherwise
    /// (several times slower).
    Samples,
}

/// Whether image-aligned slabs classify composite by the ray's segment between two planes
/// ([`volsplat_splat::Preintegrate`]; decision 0020).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[non_exhaustive]
pub enum PreintegrateChoice {
    /// By segment where the transfer function's steepest ramp is sharp against the data's value
    /// range (rings and popping otherwise: a CT's skin), by point elsewhere (noisy data, smooth
    /// ramps: an MRI). The default.
    #[default]
    Auto,
    /// Always by segment (pre-integrated classification, Engel, Kraus & Ertl 2001).
    On,
    /// Always one point per slab.
    Off,
}

/// Which level of the volume's resolution pyramid the image-aligned slabs draw
/// ([`volsplat_splat::pyramid`]; `docs/decisions/0031-prefiltered-pyramid-previews.md`). In
/// request and scene files: `"full"`, `"auto"` or a level number (`0` is the full level).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum VolumeLevel {
    /// The volume itself, minified views anti-aliased by rays averaged per pixel (the default;
    /// every image as before).
    #[default]
    Full,
    /// The level whose voxel is about a pixel at the focal point
    /// ([`volsplat_splat::auto_level`]: the coarsest whose smallest spacing is at most √2
    /// pixels); the full level (as [`VolumeLevel::Full`]) when no coarser one qualifies. For
    /// previews: the cost falls with the pixel count. Renderers without a pyramid (sheets,
    /// splat lists, X-ray) draw the full volume, silently.
    Auto,
    /// Level `n`: the volume low-pass filtered and halved `n` times (past the coarsest level:
    /// the coarsest); 0 is [`VolumeLevel::Full`]. Coarse levels take one ray per pixel.
    Level(u8),
}

impl std::fmt::Display for VolumeLevel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            VolumeLevel::Full => f.write_str("full"),
            VolumeLevel::Auto => f.write_str("auto"),
            VolumeLevel::Level(n) => write!(f, "{n}"),
        }
    }
}

impl std::str::FromStr for VolumeLevel {
    type Err = String;

    /// `full`, `auto` or a level number 0–255.
    fn from_str(s: &str) -> std::result::Result<Self, Self::Err> {
        match s.trim() {
            "full" => Ok(VolumeLevel::Full),
            "auto" => Ok(VolumeLevel::Auto),
            n => n.parse::<u8>().map(VolumeLevel::Level).map_err(|_| {
                format!("volume level {s:?}: expected full, auto or a level number 0–255")
            }),
        }
    }
}

impl Serialize for VolumeLevel {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        match self {
            VolumeLevel::Level(n) => s.serialize_u8(*n),
            other => s.serialize_str(&other.to_string()),
        }
    }
}

impl<'de> Deserialize<'de> for VolumeLevel {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum Repr {
            Number(u8),
            Name(String),
        }
        match Repr::deserialize(d).map_err(|_| {
            serde::de::Error::custom("expected \"full\", \"auto\" or a level number 0–255")
        })? {
            Repr::Number(n) => Ok(VolumeLevel::Level(n)),
            Repr::Name(name) => name.parse().map_err(serde::de::Error::custom),
        }
    }
}

impl VolumeLevel {
    /// Whether this asks for the full level ([`VolumeLevel::Full`] or level 0).
    pub fn is_full(self) -> bool {
        matches!(self, VolumeLevel::Full | VolumeLevel::Level(0))
    }
}

/// Traversal order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[non_exhaustive]
pub enum OrderChoice {
    /// Front to back (allows early termination).
    #[default]
    Ftb,
    /// Back to front.
    Btf,
}

/// Quality settings of the splatting renderers.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default)]
#[non_exhaustive]
pub struct Quality {
    /// Reconstruction kernel (the splat list takes `gaussian` or `crawfis-max`).
    pub kernel: KernelChoice,
    /// Anti-aliasing rule.
    pub antialias: AntialiasChoice,
    /// How visibility is resolved ([`VisibilityChoice`]): `auto` and `image` also pick the
    /// renderer (`docs/architecture.md`).
    pub visibility: VisibilityChoice,
    /// Traversal order (the sheets and the splat list).
    pub order: OrderChoice,
    /// Front-to-back early termination: pixels at this opacity take no more samples or splats
    /// (> 0; ≥ 1 disables it). The default, [`DEFAULT_OPACITY_CUTOFF`] (1 − 255/32767 ≈
    /// 0.9922), is VTK's level (docs/decisions/0018-early-termination-at-vtks-level.md): it
    /// changes a pixel by at most 0.78 % of the light behind the point where it stops;
    /// `1 − 2⁻²⁰` changes none by more than 1e-6.
    pub opacity_cutoff: f32,
    /// Splat every N-th voxel per axis (1..=64).
    pub subsample: usize,
    /// Splat list: keep voxels whose opacity exceeds this, in [0, 1).
    pub list_threshold: f32,
    /// Image-aligned visibility: slab thickness (plane spacing along the view) in units of the
    /// smallest voxel spacing, in [0.01, 16]; `None` (the default) picks by mode
    /// ([`volsplat_splat::slab::default_slab`]: 1 for composite, ½ for MIP and MinIP;
    /// decisions 0017, 0019 and 0036).
    pub slab: Option<f64>,
    /// Image-aligned visibility, shaded composite: where the lights are evaluated (default
    /// [`ShadeAtChoice::Auto`]: at the samples where the slabs' kernel lights them, decision
    /// 0036; `voxels` as VTK does, decision 0019).
    pub shade_at: ShadeAtChoice,
    /// Image-aligned visibility, composite: classify each slab by the ray's segment from the
    /// previous plane's sample to its own (pre-integrated classification; no rings where a
    /// transfer-function ramp is sharper than the data's steps) or by its one sample; default
    /// `auto` (decision 0020).
    pub preintegrate: PreintegrateChoice,
    /// Image-aligned visibility: which level of the volume's resolution pyramid is drawn
    /// (default [`VolumeLevel::Full`]); `auto` for previews whose cost falls with the pixel
    /// count (decision 0031). The other renderers draw the full level (with a warning for a
    /// level number above 0).
    pub level: VolumeLevel,
}

/// The front ends' early-termination opacity ([`Quality::opacity_cutoff`]), 1 − 255/32767 ≈
/// 0.99222: `vtkFixedPointVolumeRayCastMapper` stops a ray once its 15-bit remaining opacity
/// falls below `0xff` out of `0x7fff`, and issue 12 asks for termination at VTK's level. A pixel
/// changes by at most 0.78 % of what lies behind the point where it stops (decision 0018 and its
/// 2026-11-25 amendment, which replaced the rounded 0.99).
pub const DEFAULT_OPACITY_CUTOFF: f32 = 1.0 - 255.0 / 32767.0;

impl Default for Quality {
    fn default() -> Self {
        Quality {
            kernel: KernelChoice::Gaussian,
            antialias: AntialiasChoice::Area,
            visibility: VisibilityChoice::Auto,
            order: OrderChoice::Ftb,
            opacity_cutoff: DEFAULT_OPACITY_CUTOFF,
            subsample: 1,
            list_threshold: 0.0,
            slab: None,
            shade_at: ShadeAtChoice::Auto,
            preintegrate: PreintegrateChoice::Auto,
            level: VolumeLevel::Full,
        }
    }
}

/// The Chapter 6 display drawn by [`RendererChoice::Nil`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[non_exhaustive]
pub enum DisplayChoice {
    /// Sabella's display as a filter: the screen-filtered line integral `X` (through NIL maps,
    /// or by quadrature with `direct`), shown as `1 − e^{−τX}` (decision 0027). The thesis's
    /// eq 6.1 (unit density from the box's entry) is the filter library's
    /// `Attenuation::UnitDensity`.
    #[default]
    Linearised,
    /// Gaussian slice (§6-2).
    Slice,
    /// Maximum density along the ray (§6-3).
    Max,
    /// The density found by the ray search (Plate 6.10).
    Search,
    /// Search, then a difference of Gaussians there (§6-3).
    SampleFilter,
}

/// Density of the Chapter 6 displays.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[non_exhaustive]
pub enum DensityChoice {
    /// The transfer function's scalar opacity.
    #[default]
    Tf,
    /// The data value normalised to its range (the thesis's [0, 1] densities).
    Data,
}

/// How the linearised display attenuates (decision 0027).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[non_exhaustive]
pub enum AttenuationChoice {
    /// Sabella's own attenuation: `1 − e^{−τX}` of the screen-filtered line integral `X`.
    #[default]
    OpticalDepth,
    /// Buchanan's eq 6.1 as printed: unit density from the ray's entry into the volume's box
    /// (the thesis's Plates 6.3–6.6; far darker than Sabella's display where the box holds
    /// empty space).
    UnitDensity,
}

/// NIL control-point rule (decision 0007).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[non_exhaustive]
pub enum ControlChoice {
    /// L² projection of the filter onto each patch.
    #[default]
    Project,
    /// Filter values at the Lagrange nodes (the thesis).
    Interpolate,
}

/// Options of Buchanan's Chapter 6 displays (see the README's "Volume display as filtering").
/// Lengths in "unit lengths" are fractions of the volume's largest extent.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct DisplayOptions {
    /// The display of `--renderer nil`.
    pub display: DisplayChoice,
    /// Direct quadrature instead of NIL maps.
    pub direct: bool,
    /// What the density is.
    pub density: DensityChoice,
    /// Attenuation τ per unit length.
    pub tau: f64,
    /// Screen Gaussian standard deviation, pixels.
    pub screen_sigma: f64,
    /// Rays per pixel per axis (Sabella, max).
    pub supersample: usize,
    /// Samples per ray (Sabella, max, search).
    pub samples_per_ray: usize,
    /// NIL patch order (1..=4).
    pub patch_order: usize,
    /// NIL subdivision tolerance (triggers per cell).
    pub tolerance: usize,
    /// NIL control points.
    pub control_points: ControlChoice,
    /// NIL triggers per axis across the ray (default: 1 for the linearised display, 3 for
    /// slices and sample-filter).
    pub trigger_width: Option<usize>,
    /// NIL trigger slices per unit length.
    pub trigger_steps: f64,
    /// Lowest NIL level γ_min.
    pub gamma_min: i32,
    /// Slice depth in [0, 1].
    pub slice_depth: f64,
    /// Slice standard deviation, unit lengths.
    pub slice_width: f64,
    /// Search density ρ₀.
    pub rho0: f64,
    /// The sample closest to ρ₀ instead of the first crossing.
    pub closest: bool,
    /// DoG standard deviations, unit lengths.
    pub dog_sigma: [f64; 2],
    /// DoG display gain.
    pub dog_gain: f64,
    /// Largest NIL map, in stored f64 values (8 bytes each). `0` (the default): half the memory
    /// the system reports available (`MemAvailable`; 2 GiB where it is not known). A volume
    /// whose map would not fit is averaged down 2×, 3×, … per axis until it does, and the
    /// output notes say so ([`crate::Output::notes`]); raise the budget to keep full resolution.
    pub max_map_values: usize,
    /// Grey output for Sabella (the default, `true`): the intensity in all three channels, as
    /// the NIL displays write theirs, so that the two compare channel for channel. `false`: the
    /// thesis's colouring of Plate 6.1 (red = intensity, green = maximum density).
    pub grey: bool,
    /// The linearised display's attenuation (decision 0027).
    pub attenuation: AttenuationChoice,
    /// NIL continuous patches (decision 0027): neighbouring cells' fits averaged at their shared
    /// nodes, so the image has no seams along cell faces. `false`: each cell's own fit.
    pub continuous_patches: bool,
    /// Largest NIL cell a filter crosses, in multiples of the filter's narrowest cross-section
    /// (`6σ`; decision 0027); `0`: no cap (the trigger hierarchy alone, as the thesis).
    pub max_cell_width: f64,
}

impl Default for DisplayOptions {
    fn default() -> Self {
        DisplayOptions {
            display: DisplayChoice::Linearised,
            direct: false,
            density: DensityChoice::Tf,
            tau: 3.0,
            screen_sigma: 0.5,
            supersample: 4,
            samples_per_ray: 256,
            patch_order: 2,
            tolerance: 2,
            control_points: ControlChoice::Project,
            trigger_width: None,
            trigger_steps: 32.0,
            gamma_min: -1,
            slice_depth: 0.5,
            slice_width: 0.1,
            rho0: 0.18,
            closest: false,
            dog_sigma: [0.01, 0.02],
            dog_gain: 8.0,
            max_map_values: 0,
            grey: true,
            attenuation: AttenuationChoice::OpticalDepth,
            continuous_patches: true,
            max_cell_width: NilDisplaySettings::default().max_cell_width,
        }
    }
}

impl DisplayOptions {
    /// The display kind for `renderer` (Sabella or the chosen NIL display).
    pub fn kind(&self, renderer: RendererChoice) -> DisplayKind {
        match (renderer, self.display) {
            (RendererChoice::Sabella, _) => DisplayKind::Sabella,
            (_, DisplayChoice::Linearised) => DisplayKind::Linearised,
            (_, DisplayChoice::Slice) => DisplayKind::Slice,
            (_, DisplayChoice::Max) => DisplayKind::Maximum,
            (_, DisplayChoice::Search) => DisplayKind::Search,
            (_, DisplayChoice::SampleFilter) => DisplayKind::SampleFilter,
        }
    }

    /// The filter library's settings for `kind`.
    pub fn settings(&self, kind: DisplayKind) -> DisplaySettings {
        DisplaySettings {
            kind,
            evaluator: if self.direct {
                Evaluator::Direct
            } else {
                Evaluator::Nil
            },
            tau: self.tau,
            screen_sigma_px: self.screen_sigma,
            supersample: self.supersample,
            samples_per_ray: self.samples_per_ray,
            slice_depth: self.slice_depth,
            slice_width: self.slice_width,
            rho0: self.rho0,
            search: if self.closest {
                SearchRule::Closest
            } else {
                SearchRule::FirstCrossing
            },
            dog_sigma: self.dog_sigma,
            dog_gain: self.dog_gain,
            nil: NilDisplaySettings {
                control: match self.control_points {
                    ControlChoice::Project => ControlPoints::Project,
                    ControlChoice::Interpolate => ControlPoints::Interpolate,
                },
                tolerance: self.tolerance,
                trigger_width: self.trigger_width.unwrap_or(match kind {
                    DisplayKind::Slice | DisplayKind::SampleFilter => 3,
                    _ => 1,
                }),
                trigger_steps: self.trigger_steps,
                gamma_min: self.gamma_min,
                continuous: self.continuous_patches,
                max_cell_width: self.max_cell_width,
                ..Default::default()
            },
            attenuation: match self.attenuation {
                AttenuationChoice::OpticalDepth => Attenuation::OpticalDepth,
                AttenuationChoice::UnitDensity => Attenuation::UnitDensity,
            },
            transfer: None,
            ..Default::default()
        }
    }

    /// Whether the display needs a NIL map.
    pub fn needs_map(&self, kind: DisplayKind) -> bool {
        !self.direct
            && matches!(
                kind,
                DisplayKind::Linearised | DisplayKind::Slice | DisplayKind::SampleFilter
            )
    }
}

/// One render: a scene, an image size, a ray function, a renderer and its settings.
///
/// In a scene file `scene` (with its `volume`), `width` and `height` are required; every other
/// field has the default documented on its type.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RenderRequest {
    /// What is seen.
    pub scene: Scene,
    /// Image width, pixels (1..=16384).
    pub width: usize,
    /// Image height, pixels (1..=16384).
    pub height: usize,
    /// Ray function.
    #[serde(default)]
    pub mode: Mode,
    /// Renderer.
    #[serde(default)]
    pub renderer: RendererChoice,
    /// Splatting quality.
    #[serde(default)]
    pub quality: Quality,
    /// Chapter 6 display options (Sabella and NIL renderers).
    #[serde(default)]
    pub display: DisplayOptions,
    /// Splat list renderer only: draw the line at distance `k = s·D/p` beyond which a voxel
    /// covers less than a pixel (Swan et al. Fig. 7a, c) in this linear RGB colour.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub k_contour: Option<[f32; 3]>,
    /// Worker threads (`None`: all cores). Output does not depend on it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub threads: Option<usize>,
    /// OME-Zarr stores: read the level in bricks through a cache of at most this many bytes
    /// (out of core, `docs/decisions/0039-out-of-core-slabs.md`), whatever its size. `None`: in
    /// memory, unless the level is larger than half the memory the system reports available,
    /// which then is the budget. Output does not depend on it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub memory: Option<u64>,
    /// How the render is written as an image file (background, sRGB, bit depth, grey window).
    #[serde(default)]
    pub output: OutputOptions,
}

impl RenderRequest {
    /// A request for `scene` at `width × height` with every other setting at its default.
    pub fn new(scene: Scene, width: usize, height: usize) -> Self {
        RenderRequest {
            scene,
            width,
            height,
            mode: Mode::default(),
            renderer: RendererChoice::default(),
            quality: Quality::default(),
            display: DisplayOptions::default(),
            k_contour: None,
            threads: None,
            memory: None,
            output: OutputOptions::default(),
        }
    }

    /// Checks the fields that need no volume; errors name the field as in a scene file.
    pub fn validate(&self) -> Result<()> {
        let bad = |f: &str, m: String| Err(EngineError::request(f, m));
        for (f, v) in [("width", self.width), ("height", self.height)] {
            if !(1..=16384).contains(&v) {
                return bad(f, format!("must be in 1..=16384 pixels, got {v}"));
            }
        }
        let q = &self.quality;
        if !(1..=64).contains(&q.subsample) {
            return bad(
                "quality.subsample",
                format!("must be in 1..=64, got {}", q.subsample),
            );
        }
        if let Some(slab) = q.slab
            && !(slab.is_finite() && (0.01..=16.0).contains(&slab))
        {
            return Err(EngineError::request(
                "quality.slab",
                format!(
                    "must be a slab thickness in [0.01, 16] × the smallest voxel spacing, got {slab}"
                ),
            ));
        }
        if !(q.opacity_cutoff.is_finite() && q.opacity_cutoff > 0.0) {
            return bad(
                "quality.opacity_cutoff",
                format!("must be a positive number, got {}", q.opacity_cutoff),
            );
        }
        if !(q.list_threshold >= 0.0 && q.list_threshold < 1.0) {
            return bad(
                "quality.list_threshold",
                format!("must be in [0, 1), got {}", q.list_threshold),
            );
        }
        if let Some(t) = self.threads
            && !(1..=1024).contains(&t)
        {
            return bad("threads", format!("must be in 1..=1024, got {t}"));
        }
        if matches!(self.renderer, RendererChoice::Sabella | RendererChoice::Nil)
            && self.mode != Mode::Composite
        {
            return bad(
                "mode",
                format!(
                    "{:?}: the Chapter 6 displays have their own ray function; use the splatting \
                     renderer for MIP, MinIP and X-ray",
                    self.mode
                ),
            );
        }
        if let [s1, s2] = self.display.dog_sigma
            && !(s1 > 0.0 && s2 > 0.0 && s1.is_finite() && s2.is_finite())
        {
            return bad(
                "display.dog_sigma",
                format!(
                    "must be two positive numbers, got {:?}",
                    self.display.dog_sigma
                ),
            );
        }
        if let Some([lo, hi]) = self.scene.surface_enhance
            && !(lo.is_finite() && hi.is_finite() && hi > lo && lo >= 0.0)
        {
            return bad(
                "scene.surface_enhance",
                format!("expected 0 ≤ lo < hi, got [{lo}, {hi}]"),
            );
        }
        let lights = &self.scene.lights;
        if lights.len() > crate::scene::MAX_LIGHTS {
            return bad(
                "scene.lights",
                format!(
                    "{} lights; at most {} (each light is evaluated for every shaded voxel or \
                     sample)",
                    lights.len(),
                    crate::scene::MAX_LIGHTS
                ),
            );
        }
        for (n, l) in lights.iter().enumerate() {
            l.to_light(&format!("scene.lights[{n}]"))?;
        }
        self.scene.clipping.validate()?;
        self.scene.camera_orbit().validate()?;
        self.output.validate(self.mode)?;
        Ok(())
    }

    /// The options of this request that its ray function ignores, each a sentence naming the
    /// scene-file field (`scene.lights is ignored: …`), for the front ends to show as warnings:
    /// MIP and MinIP take the transfer function's colour at the extreme value, unlit, so
    /// lights, shading switches, surface enhancement and depth cueing change nothing; X-ray
    /// integrates the data itself, so the transfer function does not matter either. Empty for
    /// composite and the Chapter 6 displays.
    pub fn ignored_options(&self) -> Vec<String> {
        let s = &self.scene;
        let (mode, why) = match self.mode {
            Mode::Composite => return Vec::new(),
            Mode::Mip => (
                "mip",
                "MIP shows the transfer function's colour of the largest value, unlit",
            ),
            Mode::Minip => (
                "minip",
                "MinIP shows the transfer function's colour of the smallest value, unlit",
            ),
            Mode::Xray => (
                "xray",
                "X-ray is the line integral of the data, unclassified and unlit",
            ),
        };
        let mut fields = Vec::new();
        if self.mode == Mode::Xray && s.transfer_function != crate::TransferSpec::Auto {
            fields.push("scene.transfer_function");
        }
        if !s.lights.is_empty() {
            fields.push("scene.lights");
        }
        if s.shading != crate::ShadingTerms::default() {
            fields.push("scene.shading");
        }
        if s.surface_enhance.is_some() {
            fields.push("scene.surface_enhance");
        }
        if s.depth_cue.is_some() {
            fields.push("scene.depth_cue");
        }
        fields
            .into_iter()
            .map(|f| format!("{f} is ignored by mode {mode}: {why}"))
            .collect()
    }

    /// The splatting renderer's settings for this request.
    pub fn splat_settings(&self) -> RenderSettings {
        let q = &self.quality;
        {
            let mut s = RenderSettings::default();
            s.width = self.width;
            s.height = self.height;
            s.mode = self.mode.splat_mode();
            s.visibility = match q.visibility {
                VisibilityChoice::Auto | VisibilityChoice::Sheet => Visibility::SheetBuffer,
                VisibilityChoice::Every => Visibility::EverySample,
                VisibilityChoice::Image => Visibility::ImageAligned,
            };
            s.order = match q.order {
                OrderChoice::Ftb => Order::FrontToBack,
                OrderChoice::Btf => Order::BackToFront,
            };
            s.kernel = q.kernel.kernel();
            s.subsample = q.subsample;
            s.slab = q.slab.unwrap_or(volsplat_splat::slab::DEFAULT_SLAB);
            s.shade_at = match q.shade_at {
                ShadeAtChoice::Voxels => volsplat_splat::ShadeAt::Voxels,
                ShadeAtChoice::Auto | ShadeAtChoice::Samples => volsplat_splat::ShadeAt::Samples,
            };
            s.preintegrate = match q.preintegrate {
                PreintegrateChoice::Auto => volsplat_splat::Preintegrate::Auto,
                PreintegrateChoice::On => volsplat_splat::Preintegrate::On,
                PreintegrateChoice::Off => volsplat_splat::Preintegrate::Off,
            };
            s.opacity_cutoff = q.opacity_cutoff;
            s.antialias = match q.antialias {
                AntialiasChoice::Swan => Antialias::Swan,
                AntialiasChoice::SwanPerpendicular => Antialias::SwanPerpendicular,
                AntialiasChoice::Ewa => Antialias::Ewa,
                AntialiasChoice::Area => Antialias::Area,
                AntialiasChoice::None => Antialias::None,
            };
            s
        }
    }

    /// Reads a request from a JSON file. Unknown fields, at any depth, come back as warnings
    /// naming their path (`scene.camera.orbit.azimth`); a missing required field or a wrong
    /// type is an error naming the field. Files over 16 MiB are refused.
    pub fn load(path: impl AsRef<Path>) -> Result<(RenderRequest, Vec<String>)> {
        let path = path.as_ref();
        let scene_err = |message: String| EngineError::SceneFile {
            path: path.to_path_buf(),
            message,
        };
        let len = std::fs::metadata(path)
            .map_err(|e| scene_err(format!("cannot read: {e}")))?
            .len();
        if len > volsplat_io::MAX_JSON_BYTES {
            return Err(scene_err(format!(
                "{len} bytes; scene files are limited to {} bytes",
                volsplat_io::MAX_JSON_BYTES
            )));
        }
        let text =
            std::fs::read_to_string(path).map_err(|e| scene_err(format!("cannot read: {e}")))?;
        let mut warnings = Vec::new();
        // A byte-order mark (Windows Notepad) is not JSON and says nothing.
        let text = text.strip_prefix('\u{feff}').unwrap_or(&text);
        let de = &mut serde_json::Deserializer::from_str(text);
        // The path of the value that failed (`quality.shade_at`), for errors that serde reports
        // without it (a wrong type, an unknown enum value).
        let mut track = serde_path_to_error::Track::new();
        let tracked = serde_path_to_error::Deserializer::new(de, &mut track);
        let req: std::result::Result<RenderRequest, _> = serde_ignored::deserialize(tracked, |p| {
            // serde_ignored writes `?` for an enum variant's name, which it does not know.
            let p = p.to_string().replace(".?", "");
            warnings.push(format!("{}: unknown field `{p}` ignored", path.display()))
        });
        let req = req.map_err(|e| {
            let at = track.path().to_string();
            scene_err(if at.is_empty() || at == "." {
                e.to_string()
            } else {
                format!("{at}: {e}")
            })
        })?;
        Ok((req, warnings))
    }

    /// This request with a volume file's relative path made absolute (against the current
    /// folder, without touching the file system): what scene files hold, so that `render
    /// --scene` reads the same volume from any folder, as ParaView's state files do.
    pub fn with_absolute_paths(&self) -> RenderRequest {
        let mut r = self.clone();
        if let crate::VolumeSource::File { path, .. } = &mut r.scene.volume
            && path.is_relative()
            && let Ok(abs) = std::path::absolute(&*path)
        {
            *path = abs;
        }
        r
    }

    /// Writes the request as pretty JSON, atomically, with a volume file's path made absolute
    /// ([`RenderRequest::with_absolute_paths`]). An in-memory volume cannot be saved.
    pub fn save(&self, path: impl AsRef<Path>) -> Result<()> {
        let path = path.as_ref();
        if matches!(self.scene.volume, crate::VolumeSource::Memory(_)) {
            return Err(EngineError::request(
                "scene.volume",
                "a volume in memory cannot be saved in a scene file; save it as NRRD first",
            ));
        }
        let text = serde_json::to_string_pretty(&self.with_absolute_paths()).map_err(|e| {
            EngineError::SceneFile {
                path: path.to_path_buf(),
                message: e.to_string(),
            }
        })?;
        volsplat_io::write_bytes_atomic(path, text.as_bytes())?;
        Ok(())
    }
}

impl Scene {
    /// The orbit of the camera specification.
    pub fn camera_orbit(&self) -> volsplat_core::Orbit {
        match &self.camera {
            crate::CameraSpec::Orbit(o) => *o,
            crate::CameraSpec::Explicit { orbit, .. } => *orbit,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every kernel choice maps to the kernel of its own name, not to the fallback default.
    #[test]
    fn every_kernel_choice_is_a_known_kernel() {
        for (choice, name) in [
            (KernelChoice::Gaussian, "gaussian"),
            (KernelChoice::Point, "point"),
            (KernelChoice::Nearest, "nearest"),
            (KernelChoice::Tent, "tent"),
            (KernelChoice::Bspline, "bspline"),
            (KernelChoice::CatmullRom, "catmull-rom"),
            (KernelChoice::Mitchell, "mitchell"),
            (KernelChoice::CrawfisMax, "crawfis-max"),
        ] {
            let expect = volsplat_core::Kernel::from_name(name).unwrap();
            assert_eq!(choice.kernel(), expect, "{name}");
            // The serialised name is the one the command line accepts.
            assert_eq!(serde_json::to_value(choice).unwrap(), name);
        }
    }

    /// Issue 28: 10 000 lights took 10–14 s for a 16 × 16 image and 100 000 clipping planes 15 s;
    /// both are capped in validation, so scene files, Python and the CLI all get the cap.
    #[test]
    fn lights_and_clipping_planes_are_capped() {
        use crate::scene::{MAX_CLIP_PLANES, MAX_LIGHTS};
        use crate::{LightSpec, PlaneSpec};
        let mut req = RenderRequest::new(Scene::default(), 16, 16);
        let light = LightSpec {
            direction: [0.0, 0.0, 1.0],
            color: [1.0; 3],
            ambient: [0.0; 3],
        };
        req.scene.lights = vec![light; MAX_LIGHTS];
        req.validate().unwrap();
        req.scene.lights.push(light);
        let e = req.validate().unwrap_err().to_string();
        assert!(
            e.contains("scene.lights") && e.contains("17 lights") && e.contains("at most 16"),
            "{e}"
        );
        req.scene.lights = vec![
            light,
            LightSpec {
                direction: [0.0; 3],
                color: [1.0; 3],
                ambient: [0.0; 3],
            },
        ];
        let e = req.validate().unwrap_err().to_string();
        assert!(e.contains("scene.lights[1]"), "{e}");
        req.scene.lights.clear();
        let plane = PlaneSpec {
            normal: [0.0, 0.0, 1.0],
            offset: 0.0,
        };
        req.scene.clipping.planes = vec![plane; MAX_CLIP_PLANES];
        req.validate().unwrap();
        req.scene.clipping.planes.push(plane);
        let e = req.validate().unwrap_err().to_string();
        assert!(
            e.contains("scene.clipping.planes") && e.contains("at most 64"),
            "{e}"
        );
        // A crop box turned inside out is refused before any volume is loaded.
        req.scene.clipping.planes.clear();
        req.scene.clipping.crop = Some(crate::CropBox {
            min: [0.0, 5.0, 0.0],
            max: [1.0, 4.0, 1.0],
            units: crate::CropUnits::Voxels,
        });
        let e = req.validate().unwrap_err().to_string();
        assert!(
            e.contains("scene.clipping.crop") && e.contains("axis 1"),
            "{e}"
        );
    }

    /// Issue 28: options a ray function ignores are named (the front ends warn), and nothing is
    /// named for composite or for options at their defaults.
    #[test]
    fn ignored_options_are_named_by_mode() {
        let mut req = RenderRequest::new(Scene::default(), 16, 16);
        for mode in [Mode::Composite, Mode::Mip, Mode::Minip, Mode::Xray] {
            req.mode = mode;
            assert!(req.ignored_options().is_empty(), "{mode:?}");
        }
        req.scene.lights = vec![crate::LightSpec {
            direction: [1.0, 0.0, 0.0],
            color: [1.0; 3],
            ambient: [0.0; 3],
        }];
        req.scene.transfer_function = crate::TransferSpec::Preset(volsplat_core::Preset::CtBone);
        req.scene.surface_enhance = Some([1.0, 2.0]);
        req.scene.depth_cue = Some([1.0, 0.5]);
        req.scene.shading.specular = false;
        req.mode = Mode::Composite;
        assert!(req.ignored_options().is_empty());
        req.mode = Mode::Xray;
        let x = req.ignored_options();
        let fields: Vec<&str> = x.iter().map(|w| w.split(' ').next().unwrap()).collect();
        assert_eq!(
            fields,
            [
                "scene.transfer_function",
                "scene.lights",
                "scene.shading",
                "scene.surface_enhance",
                "scene.depth_cue"
            ]
        );
        assert!(
            x.iter().all(|w| w.contains("ignored by mode xray")),
            "{x:?}"
        );
        // MIP and MinIP use the transfer function (its colour of the extreme value).
        for mode in [Mode::Mip, Mode::Minip] {
            req.mode = mode;
            let w = req.ignored_options();
            assert_eq!(w.len(), 4, "{w:?}");
            assert!(w.iter().all(|w| !w.contains("transfer_function")), "{w:?}");
            assert!(w[0].starts_with("scene.lights is ignored by mode"), "{w:?}");
        }
    }
}

#[cfg(test)]
mod scene_file_paths {
    use super::*;
    use crate::VolumeSource;

    /// A scene file names its volume by an absolute path, so `render --scene` reads the same
    /// file from any folder; absolute paths and phantoms are kept as they are.
    #[test]
    fn scene_files_hold_absolute_volume_paths() {
        let dir = tempfile::tempdir().unwrap();
        let mut req = RenderRequest::new(Scene::default(), 8, 8);
        req.scene.volume = VolumeSource::File {
            path: "data/head.nrrd".into(),
            raw: None,
            frame: 0,
            array: None,
            series: None,
            level: crate::scene::StoreLevel::Index(0),
            channel: 0,
            timepoint: 0,
        };
        let file = dir.path().join("s.json");
        req.save(&file).unwrap();
        let (loaded, _) = RenderRequest::load(&file).unwrap();
        let VolumeSource::File { path, .. } = &loaded.scene.volume else {
            panic!("{:?}", loaded.scene.volume);
        };
        assert!(path.is_absolute(), "{path:?}");
        assert_eq!(
            path,
            &std::env::current_dir().unwrap().join("data/head.nrrd")
        );
        // Everything else is the request as it was.
        assert_eq!(loaded.with_absolute_paths(), req.with_absolute_paths());
        let abs = dir.path().join("v.nrrd");
        let mut req2 = req.clone();
        if let VolumeSource::File { path, .. } = &mut req2.scene.volume {
            *path = abs.clone();
        }
        assert_eq!(req2.with_absolute_paths(), req2);
        // A byte-order mark before the JSON (Windows Notepad) reads as the file without it.
        let text = std::fs::read_to_string(&file).unwrap();
        let bom = dir.path().join("bom.json");
        std::fs::write(&bom, format!("\u{feff}{text}")).unwrap();
        assert_eq!(RenderRequest::load(&bom).unwrap().0, loaded);
    }
}
