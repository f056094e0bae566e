//! What is rendered: the volume, the camera, the transfer function and the lights.
//!
//! Every type here is plain data, serialisable with serde, so that a whole scene (and a whole
//! [`crate::RenderRequest`]) is one JSON file; the camera and transfer function inside it are
//! objects in the formats of the README's camera and transfer-function files.

use crate::error::{EngineError, Result};
use serde::{Deserialize, Serialize};
use std::path::PathBuf;
use std::sync::Arc;
use volsplat_core::phantom::{self, EllipsoidPhantom, GaussianBlobs, MarschnerLobb};
use volsplat_core::{
    AnyVolume, Camera, Light, Orbit, Preset, ScalarType, TransferFunction, scenes,
};

/// Built-in phantoms (world units as each phantom defines them).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum PhantomKind {
    /// An MRI of a head built into the binary (VolPack's `brainsmall`, 84 × 128 × 128 u8,
    /// BSD-3), face towards +z, top towards +y: the demo. Its grid is fixed.
    Brain,
    /// CT-like head in Hounsfield units (i16), face towards +z, top towards +y.
    Head,
    /// 3-D modified Shepp–Logan phantom (f32).
    SheppLogan,
    /// Gaussian blobs (f32) with closed-form line integrals.
    Blobs,
    /// Marschner–Lobb test function (f32, f_M = 6, α = 0.25).
    MarschnerLobb,
    /// Swan et al. Fig. 7a–b: a one-voxel sheet of red and white squares.
    Checkerboard,
    /// Swan et al. Fig. 7c–d: a fractal terrain height field with a detailed "photo" draped on it.
    Terrain,
    /// Swan et al. Fig. 7e–f: a dense tangle of thin bright fibres, finer than the image.
    Filaments,
}

impl PhantomKind {
    /// The transfer function a built-in scene is meant to be seen with (Swan et al.'s Fig. 7
    /// scenes), if any.
    pub fn scene_transfer_function(self) -> Option<TransferFunction> {
        match self {
            PhantomKind::Checkerboard => Some(scenes::checkerboard_tf()),
            PhantomKind::Terrain => Some(scenes::terrain_tf()),
            PhantomKind::Filaments => Some(scenes::filaments_tf()),
            _ => None,
        }
    }
}

/// Largest built-in phantom, voxels (2³⁰: 4 GiB as f32).
pub const PHANTOM_MAX_VOXELS: u128 = 1 << 30;

/// Builds a phantom. `grid`: `None` for the phantom's own size; `[n]` for an n³ cube or
/// `[x, y, z]` (each in 2..=4096, at most [`PHANTOM_MAX_VOXELS`]); for the checkerboard
/// `[x, y]` or `[x, y, square]` (sheet sides in 1..=8192). Errors name `field`.
pub fn make_phantom(kind: PhantomKind, grid: Option<&[usize]>, field: &str) -> Result<AnyVolume> {
    let bad = |m: String| EngineError::request(field, m);
    let cube = |g: &[usize]| -> Result<[usize; 3]> {
        let dims = match *g {
            [n] => [n; 3],
            [x, y, z] => [x, y, z],
            _ => return Err(bad(format!("expected N or X,Y,Z, got {g:?}"))),
        };
        if dims.iter().any(|d| !(2..=4096).contains(d)) {
            return Err(bad(format!("each size must be in 2..=4096, got {dims:?}")));
        }
        let voxels: u128 = dims.iter().map(|&d| d as u128).product();
        if voxels > PHANTOM_MAX_VOXELS {
            return Err(bad(format!(
                "{dims:?} is {voxels} voxels; built-in phantoms are limited to \
                 {PHANTOM_MAX_VOXELS} (4 GiB as f32)"
            )));
        }
        Ok(dims)
    };
    Ok(match kind {
        PhantomKind::Brain => {
            if let Some(g) = grid {
                return Err(bad(format!(
                    "the built-in MRI has a fixed grid of {:?} voxels; a grid ({g:?}) applies \
                     to the synthetic phantoms (e.g. head)",
                    crate::demo::BRAIN_DIMS
                )));
            }
            crate::demo::brain_volume()?
        }
        PhantomKind::Checkerboard => {
            let (nx, ny, sq) = scenes::CHECKERBOARD_PAPER;
            let (nx, ny, sq) = match grid {
                None => (nx, ny, sq),
                Some(&[x, y]) => (x, y, sq),
                Some(&[x, y, q]) => (x, y, q),
                Some(g) => return Err(bad(format!("expected X,Y[,SQUARE], got {g:?}"))),
            };
            if !(1..=8192).contains(&nx) || !(1..=8192).contains(&ny) {
                return Err(bad(format!(
                    "sheet sides must be in 1..=8192, got {nx}x{ny}"
                )));
            }
            scenes::checkerboard_sheet(nx, ny, sq)?.into()
        }
        PhantomKind::Terrain => {
            let d = grid.map(cube).transpose()?.unwrap_or(scenes::TERRAIN_PAPER);
            scenes::terrain(d[0], d[1], d[2], 1)?.into()
        }
        PhantomKind::Filaments => {
            let d = grid
                .map(cube)
                .transpose()?
                .unwrap_or(scenes::FILAMENTS_PAPER);
            scenes::filaments(d[0], d[1], d[2], 1)?.into()
        }
        PhantomKind::Head => {
            let d = grid.map(cube).transpose()?.unwrap_or([128, 160, 144]);
            phantom::ct_head_volume(d)?.into()
        }
        PhantomKind::SheppLogan => {
            let d = grid.map(cube).transpose()?.unwrap_or([128; 3]);
            phantom::sample(&EllipsoidPhantom::shepp_logan_3d(), d, 2)?.into()
        }
        PhantomKind::Blobs => {
            let d = grid.map(cube).transpose()?.unwrap_or([128; 3]);
            phantom::sample(&GaussianBlobs::demo(), d, 1)?.into()
        }
        PhantomKind::MarschnerLobb => {
            let d = grid.map(cube).transpose()?.unwrap_or([128; 3]);
            let ml = MarschnerLobb {
                f_m: 6.0,
                alpha: 0.25,
            };
            phantom::sample(&ml, d, 1)?.into()
        }
    })
}

/// How a headerless raw file is laid out.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RawLayout {
    /// Samples per axis, x fastest.
    pub dims: [usize; 3],
    /// Sample type name: `u8`, `i8`, `u16`, `i16`, `f32`.
    pub scalar_type: String,
    /// Voxel spacing, world units.
    #[serde(default = "unit_spacing")]
    pub spacing: [f64; 3],
    /// World position of voxel (0, 0, 0).
    #[serde(default)]
    pub origin: [f64; 3],
    /// Big-endian samples.
    #[serde(default)]
    pub big_endian: bool,
    /// Bytes to skip before the first sample.
    #[serde(default)]
    pub header_bytes: u64,
}

fn is_zero(n: &usize) -> bool {
    *n == 0
}

/// Which resolution level of an OME-Zarr store a [`VolumeSource::File`] reads (issue 31).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StoreLevel {
    /// Level `n`, 0 (the full resolution, the default) to the coarsest (`volsplat info STORE`
    /// lists them). In scene files: the number.
    Index(usize),
    /// The coarsest level whose smallest voxel spacing is no larger than a pixel at the camera's
    /// focal plane: chosen by the renderer for each frame from the camera and the image size
    /// (`Renderer::render`), from the store's metadata alone. In scene files: `"auto"`.
    Auto,
}

impl Default for StoreLevel {
    fn default() -> Self {
        StoreLevel::Index(0)
    }
}

impl StoreLevel {
    /// Level 0, the full resolution (the default, left out of scene files).
    pub fn is_full(&self) -> bool {
        *self == StoreLevel::Index(0)
    }

    /// The level number, or `None` for [`StoreLevel::Auto`].
    pub fn index(self) -> Option<usize> {
        match self {
            StoreLevel::Index(n) => Some(n),
            StoreLevel::Auto => None,
        }
    }
}

impl std::fmt::Display for StoreLevel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            StoreLevel::Index(n) => write!(f, "{n}"),
            StoreLevel::Auto => f.write_str("auto"),
        }
    }
}

impl std::str::FromStr for StoreLevel {
    type Err = String;

    /// `auto` or a level number.
    fn from_str(s: &str) -> std::result::Result<Self, Self::Err> {
        if s.eq_ignore_ascii_case("auto") {
            return Ok(StoreLevel::Auto);
        }
        s.parse()
            .map(StoreLevel::Index)
            .map_err(|_| format!("expected \"auto\" or a level number, got {s:?}"))
    }
}

impl Serialize for StoreLevel {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        match self {
            StoreLevel::Index(n) => s.serialize_u64(*n as u64),
            StoreLevel::Auto => s.serialize_str("auto"),
        }
    }
}

impl<'de> Deserialize<'de> for StoreLevel {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum Raw {
            Number(usize),
            Text(String),
        }
        match Raw::deserialize(d)? {
            Raw::Number(n) => Ok(StoreLevel::Index(n)),
            Raw::Text(t) => t.parse().map_err(serde::de::Error::custom),
        }
    }
}

fn unit_spacing() -> [f64; 3] {
    [1.0; 3]
}

/// Where the volume comes from.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum VolumeSource {
    /// A volume file (format by extension: NRRD, MetaImage, …), or a headerless raw file with
    /// its layout.
    File {
        /// The file, or a folder of TIFF slices.
        path: PathBuf,
        /// Layout of a headerless raw file.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        raw: Option<RawLayout>,
        /// Which volume of a 4-D file (NIfTI, ImageJ TIFF hyperstack), 0-based.
        #[serde(default, skip_serializing_if = "is_zero")]
        frame: usize,
        /// Which point-data array of a VTK `.vti` file (default: the active scalars, else the
        /// first).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        array: Option<String>,
        /// Which DICOM series of a folder holding several: its SeriesInstanceUID, or its
        /// SeriesNumber where that is unique (default: the only one).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        series: Option<String>,
        /// Which resolution level of an OME-Zarr store: a number, 0 (the full resolution, the
        /// default) to the coarsest (`volsplat info STORE` lists them), or `"auto"`
        /// ([`StoreLevel::Auto`], chosen per frame from the camera).
        #[serde(default, skip_serializing_if = "StoreLevel::is_full")]
        level: StoreLevel,
        /// Which channel of a multi-channel OME-Zarr image, 0-based.
        #[serde(default, skip_serializing_if = "is_zero")]
        channel: usize,
        /// Which time point of an OME-Zarr image, 0-based.
        #[serde(default, skip_serializing_if = "is_zero")]
        timepoint: usize,
    },
    /// A built-in phantom; `grid` as in [`make_phantom`].
    Phantom {
        /// Which phantom.
        phantom: PhantomKind,
        /// Its grid (`None`: the phantom's own size).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        grid: Option<Vec<usize>>,
    },
    /// A volume already in memory (from a library caller). It cannot be saved in a scene file.
    #[serde(skip)]
    Memory(Arc<AnyVolume>),
}

impl PartialEq for VolumeSource {
    /// Volumes in memory are equal when they are the same allocation; files and phantoms when
    /// every field is.
    fn eq(&self, other: &Self) -> bool {
        match (self, other) {
            (VolumeSource::Memory(a), VolumeSource::Memory(b)) => Arc::ptr_eq(a, b),
            (VolumeSource::Memory(_), _) | (_, VolumeSource::Memory(_)) => false,
            _ => serde_json::to_value(self).ok() == serde_json::to_value(other).ok(),
        }
    }
}

impl Default for VolumeSource {
    /// The demo: the built-in MRI head.
    fn default() -> Self {
        VolumeSource::Phantom {
            phantom: PhantomKind::Brain,
            grid: None,
        }
    }
}

impl VolumeSource {
    /// Loads (or builds) the volume.
    pub fn load(&self) -> Result<Arc<AnyVolume>> {
        Ok(self.load_with_notes()?.0)
    }

    /// Loads (or builds) the volume, with the reader's notes for the user (frames available,
    /// spacing assumed, NaN samples replaced, …), under the readers' default
    /// [`volsplat_io::Limits`].
    pub fn load_with_notes(&self) -> Result<(Arc<AnyVolume>, Vec<String>)> {
        self.load_with_limits(&volsplat_io::Limits::default())
    }

    /// Like [`VolumeSource::load_with_notes`] with the caller's reader limits (largest header,
    /// voxel count, JSON and XML sizes), for example a server that must refuse volumes larger
    /// than its memory.
    pub fn load_with_limits(
        &self,
        limits: &volsplat_io::Limits,
    ) -> Result<(Arc<AnyVolume>, Vec<String>)> {
        Ok(match self {
            VolumeSource::Memory(v) => (Arc::clone(v), v.non_finite_note().into_iter().collect()),
            VolumeSource::Phantom { phantom, grid } => (
                Arc::new(make_phantom(*phantom, grid.as_deref(), "volume.grid")?),
                Vec::new(),
            ),
            VolumeSource::File {
                path, raw: Some(r), ..
            } => {
                let spec = volsplat_io::RawSpec {
                    dims: r.dims,
                    scalar_type: ScalarType::from_name(&r.scalar_type)?,
                    spacing: r.spacing,
                    origin: r.origin,
                    big_endian: r.big_endian,
                    header_bytes: r.header_bytes,
                };
                let options = volsplat_io::ReadOptions::default().with_limits(limits.clone());
                let v = volsplat_io::read_raw_with(path, &spec, &options)?.volume;
                let notes = v.non_finite_note().into_iter().collect();
                (Arc::new(v), notes)
            }
            VolumeSource::File {
                path,
                raw: None,
                frame,
                array,
                series,
                level,
                channel,
                timepoint,
            } => {
                let Some(level) = level.index() else {
                    return Err(EngineError::request(
                        "volume.level",
                        "\"auto\" is chosen from the camera when a frame is rendered \
                         (Renderer::render); to load a volume, give a level number",
                    ));
                };
                let options = volsplat_io::ReadOptions::default()
                    .with_frame(*frame)
                    .with_array(array.clone())
                    .with_series(series.clone())
                    .with_level(level)
                    .with_channel(*channel)
                    .with_timepoint(*timepoint)
                    .with_limits(limits.clone());
                let loaded = volsplat_io::read_volume_with(path, &options)?;
                let mut notes = loaded.notes;
                if loaded.frames > 1 {
                    // OME-Zarr counts time points; other formats frames.
                    let flag = if loaded.format.starts_with("OME-Zarr") {
                        "--timepoint"
                    } else {
                        "--frame"
                    };
                    notes.push(format!(
                        "{} holds {} volumes; rendering volume {} (choose with {flag})",
                        path.display(),
                        loaded.frames,
                        loaded.frame
                    ));
                }
                (Arc::new(loaded.volume), notes)
            }
        })
    }

    /// A short label for messages: the file name or the phantom.
    pub fn label(&self) -> String {
        match self {
            VolumeSource::File { path, .. } => path.display().to_string(),
            VolumeSource::Phantom { phantom, .. } => format!(
                "built-in `{}`",
                serde_json::to_value(phantom)
                    .ok()
                    .and_then(|v| v.as_str().map(str::to_string))
                    .unwrap_or_else(|| format!("{phantom:?}"))
            ),
            VolumeSource::Memory(_) => "volume in memory".into(),
        }
    }

    /// Whether this is the synthetic CT head phantom ([`PhantomKind::Head`], the demo before the
    /// built-in MRI), whose default transfer function is `ct-skin`.
    pub fn is_demo_head(&self) -> bool {
        matches!(
            self,
            VolumeSource::Phantom {
                phantom: PhantomKind::Head,
                ..
            }
        )
    }
}

/// The camera: VTK's reset view around the volume or a given camera, then view changes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CameraSpec {
    /// VTK's `ResetCamera` view of the volume's bounds (looking down −z, +y up), then the orbit.
    Orbit(Orbit),
    /// A camera in the camera-file format (world units), then the orbit.
    Explicit {
        /// The camera.
        camera: Camera,
        /// View changes applied to it (none by default).
        #[serde(default, skip_serializing_if = "Orbit::is_identity")]
        orbit: Orbit,
    },
}

impl Default for CameraSpec {
    fn default() -> Self {
        CameraSpec::Orbit(Orbit::default())
    }
}

impl CameraSpec {
    /// The camera for a volume whose world bounds are `lo..hi`.
    pub fn resolve(
        &self,
        bounds: (volsplat_core::glam::DVec3, volsplat_core::glam::DVec3),
    ) -> Result<Camera> {
        Ok(match self {
            CameraSpec::Orbit(o) => o.reset_camera(bounds.0, bounds.1)?,
            CameraSpec::Explicit { camera, orbit } => {
                camera.validate()?;
                let mut c = camera.clone();
                orbit.apply(&mut c)?;
                c
            }
        })
    }
}

/// The transfer function.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TransferSpec {
    /// Chosen from the data and mode: a built-in scene's own function; for MIP and MinIP an
    /// opaque grey window over the data range; `ct-skin` for the synthetic CT head phantom
    /// ([`PhantomKind::Head`]); otherwise the
    /// automatic function from the volume's histogram (background made transparent, opacity
    /// ramped over robust percentiles of the foreground; [`volsplat_core::AutoTransfer`],
    /// docs/presets.md).
    #[default]
    Auto,
    /// A built-in preset by name ([`volsplat_core::Preset`]: 3D Slicer's `CT-Bone`, `MR-Default`,
    /// … in absolute data units, and volsplat's `ct-skin` and `ramp`; case-insensitive).
    Preset(Preset),
    /// A transfer function in the transfer-function-file format (values in data units).
    Function(TransferFunction),
}

/// A directional light, in the camera frame (x right, y up, z towards the viewer).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LightSpec {
    /// Direction towards the light (any length but zero).
    pub direction: [f64; 3],
    /// Linear RGB colour (≥ 0; default white).
    #[serde(default = "white")]
    pub color: [f32; 3],
    /// Linear RGB ambient colour (≥ 0), which a transfer function's `ambient` coefficient
    /// multiplies (the emission term of shaded composite). Default black, as `vtkLight`'s
    /// and VTK's default headlight's: then `ambient` changes nothing, as in VTK's CPU ray
    /// caster.
    #[serde(default, skip_serializing_if = "is_black")]
    pub ambient: [f32; 3],
}

fn white() -> [f32; 3] {
    [1.0; 3]
}

fn is_black(c: &[f32; 3]) -> bool {
    c.iter().all(|&x| x == 0.0)
}

impl LightSpec {
    /// The core light, checked: finite, non-zero direction; colour ≥ 0.
    pub fn to_light(&self, field: &str) -> Result<Light> {
        if self.direction.iter().any(|x| !x.is_finite()) || self.direction.iter().all(|&x| x == 0.0)
        {
            return Err(EngineError::request(
                field,
                format!(
                    "direction must be finite and non-zero, got {:?}",
                    self.direction
                ),
            ));
        }
        if self.color.iter().any(|&c| !(c >= 0.0 && c.is_finite())) {
            return Err(EngineError::request(
                field,
                format!(
                    "colour components must be finite and ≥ 0, got {:?}",
                    self.color
                ),
            ));
        }
        if self.ambient.iter().any(|&c| !(c >= 0.0 && c.is_finite())) {
            return Err(EngineError::request(
                field,
                format!(
                    "ambient colour components must be finite and ≥ 0, got {:?}",
                    self.ambient
                ),
            ));
        }
        Ok(Light {
            direction: self.direction,
            color: self.color,
            ambient_color: self.ambient,
            ..Light::headlight()
        })
    }
}

/// Westover's shading switches (§3.6.1): which terms of the lighting model are kept.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default)]
pub struct ShadingTerms {
    /// The emission (ambient) term.
    pub emission: bool,
    /// The diffuse term.
    pub diffuse: bool,
    /// The specular term.
    pub specular: bool,
}

impl Default for ShadingTerms {
    fn default() -> Self {
        ShadingTerms {
            emission: true,
            diffuse: true,
            specular: true,
        }
    }
}

/// Everything about what is seen: volume, camera, transfer function, lights.
/// In a scene file `volume` is required; every other field has the default given.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Scene {
    /// The volume (default: the built-in MRI head, [`PhantomKind::Brain`]; required in a scene
    /// file).
    pub volume: VolumeSource,
    /// The camera (default: VTK's reset view, orthographic).
    #[serde(default)]
    pub camera: CameraSpec,
    /// The transfer function (default: chosen from the data and mode).
    #[serde(default)]
    pub transfer_function: TransferSpec,
    /// Directional lights in the camera frame; empty means VTK's white headlight. At most
    /// [`MAX_LIGHTS`].
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub lights: Vec<LightSpec>,
    /// Shading terms kept.
    #[serde(default)]
    pub shading: ShadingTerms,
    /// Surface enhancement: opacity × a 0→1 ramp on gradient magnitude `[lo, hi]` (data units
    /// per world unit), replacing gradient opacity.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub surface_enhance: Option<[f64; 2]>,
    /// Depth cueing: opacity × a ramp from `near` (front) to `far` (back), both in [0, 1].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub depth_cue: Option<[f64; 2]>,
    /// Cropping and clipping planes (splatting renderers), cut smoothly.
    #[serde(default, skip_serializing_if = "Clipping::is_empty")]
    pub clipping: Clipping,
    /// X-ray mode: what is integrated (default `auto`: CT in Hounsfield units relative to air,
    /// `max(HU + 1000, 0)`; other data as they are). See [`crate::xray`].
    #[serde(default, skip_serializing_if = "crate::xray::XrayDensity::is_auto")]
    pub xray_density: crate::xray::XrayDensity,
}

/// Most lights a scene may hold. Each light is evaluated for every shaded voxel or sample, so
/// the cost grows with their number (10 000 lights took 10–14 s for a 16 × 16 image, issue 28);
/// OpenGL's fixed-function pipeline, from which VTK's lighting model comes, guarantees 8
/// (`GL_MAX_LIGHTS`), and VTK scenes rarely use more. 16 leaves room for key, fill, rim and
/// coloured lights.
pub const MAX_LIGHTS: usize = 16;

/// Most clipping planes a scene may hold (besides a crop box's six). Every plane is tested
/// for every voxel and sample (100 000 planes took 15 s, issue 28); a convex region needs a
/// handful, and 64 leaves room for polyhedral cuts.
pub const MAX_CLIP_PLANES: usize = 64;

/// A clipping plane: keeps the world points `x` with `normal·x + offset ≥ 0` (the side the
/// normal points to, as VTK's clipping planes).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlaneSpec {
    /// Normal in world coordinates (any non-zero length).
    pub normal: [f64; 3],
    /// Offset, world units × |normal|.
    pub offset: f64,
}

/// The units of a [`CropBox`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CropUnits {
    /// Voxel indices (0-based, may be fractional); the box keeps voxels `min..=max` whole, its
    /// faces half a voxel outside them.
    #[default]
    Voxels,
    /// World coordinates (usually mm, LPS for medical volumes); faces exactly at `min` and `max`.
    World,
}

/// A crop box (VTK's cropping region): keeps what lies inside, cut smoothly at its faces.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CropBox {
    /// Lower corner (x, y, z) in `units`.
    pub min: [f64; 3],
    /// Upper corner (x, y, z) in `units`; each ≥ the lower.
    pub max: [f64; 3],
    /// Voxel indices or world coordinates.
    #[serde(default)]
    pub units: CropUnits,
}

/// Cropping and clipping of a scene.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Clipping {
    /// A crop box.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub crop: Option<CropBox>,
    /// Clipping planes; a point is kept when every plane keeps it. At most [`MAX_CLIP_PLANES`].
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub planes: Vec<PlaneSpec>,
}

impl Clipping {
    /// Whether nothing is cut.
    pub fn is_empty(&self) -> bool {
        self.crop.is_none() && self.planes.is_empty()
    }

    /// Checks what needs no volume: at most [`MAX_CLIP_PLANES`] planes, each with a finite,
    /// non-zero normal and a finite offset; a crop box with finite corners, `min ≤ max` on every
    /// axis. Errors name the field (`scene.clipping.crop`, `scene.clipping.planes[i]`).
    pub fn validate(&self) -> Result<()> {
        if self.planes.len() > MAX_CLIP_PLANES {
            return Err(EngineError::request(
                "scene.clipping.planes",
                format!(
                    "{} clipping planes; at most {MAX_CLIP_PLANES} (each plane is tested for \
                     every voxel and sample)",
                    self.planes.len()
                ),
            ));
        }
        if let Some(c) = &self.crop {
            for k in 0..3 {
                if !(c.min[k].is_finite() && c.max[k].is_finite() && c.min[k] <= c.max[k]) {
                    return Err(EngineError::request(
                        "scene.clipping.crop",
                        format!(
                            "axis {k}: min {} and max {} must be finite with min ≤ max",
                            c.min[k], c.max[k]
                        ),
                    ));
                }
            }
        }
        for (i, p) in self.planes.iter().enumerate() {
            let plane = volsplat_splat::ClipPlane {
                normal: p.normal,
                offset: p.offset,
            };
            if !plane.is_valid() {
                return Err(EngineError::request(
                    format!("scene.clipping.planes[{i}]"),
                    format!(
                        "normal {:?}, offset {}: needs a finite, non-zero normal and a finite \
                         offset",
                        p.normal, p.offset
                    ),
                ));
            }
        }
        Ok(())
    }

    /// The world-space planes of the crop box and the clipping planes for a volume on `grid`,
    /// checked as [`Clipping::validate`].
    pub fn world_planes(
        &self,
        grid: &volsplat_core::Grid,
    ) -> Result<Vec<volsplat_splat::ClipPlane>> {
        use volsplat_core::glam::DVec3;
        use volsplat_splat::ClipPlane;
        self.validate()?;
        let mut out = Vec::new();
        if let Some(c) = &self.crop {
            let origin = DVec3::from(grid.origin);
            for k in 0..3 {
                let (normal, lo, hi) = match c.units {
                    CropUnits::World => (DVec3::AXES[k], c.min[k], c.max[k]),
                    // Lattice coordinate l_k = (d_k · (x − o)) / s_k.
                    CropUnits::Voxels => (
                        grid.direction.col(k) / grid.spacing[k],
                        c.min[k] - 0.5,
                        c.max[k] + 0.5,
                    ),
                };
                let base = match c.units {
                    CropUnits::World => 0.0,
                    CropUnits::Voxels => normal.dot(origin),
                };
                // normal·x − base − lo ≥ 0 and −normal·x + base + hi ≥ 0.
                out.push(ClipPlane {
                    normal: normal.to_array(),
                    offset: -base - lo,
                });
                out.push(ClipPlane {
                    normal: (-normal).to_array(),
                    offset: base + hi,
                });
            }
        }
        out.extend(self.planes.iter().map(|p| ClipPlane {
            normal: p.normal,
            offset: p.offset,
        }));
        Ok(out)
    }
}
