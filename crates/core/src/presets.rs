//! Built-in transfer functions: 3D Slicer's volume-rendering presets, volsplat's own, and an
//! automatic transfer function fitted to a volume's histogram.
//!
//! - [`Preset`]: a closed set of named transfer functions. All but two are 3D Slicer's
//!   volume-rendering presets with Slicer's names and control points, copied verbatim from
//!   `Modules/Loadable/VolumeRendering/Resources/presets.xml` of
//!   <https://github.com/Slicer/Slicer> (file last changed in commit `74c1358`, 2023-01-05;
//!   read at `583e9b3`), which is under the 3D Slicer License (BSD-style; `License.txt` of that
//!   repository). `ct-skin` and `ramp` are volsplat's own. Names match case-insensitively;
//!   `mr` is an alias of `MR-Default` (the same points) and `ct-bone` of `CT-Bone`.
//! - [`Histogram`] and [`AutoTransfer`]: the default for data with no preset. The background
//!   (a fill value and/or the low class of Otsu's threshold) is made transparent and opacity and
//!   colour are ramped over robust percentiles of the rest (see [`AutoTransfer`]).
//!
//! Slicer's presets are in absolute scalar units: Hounsfield units (HU) for the `CT-*` presets,
//! the scanner's arbitrary intensity for `MR-*`, fractional anisotropy (0–1) for `DTI-FA-Brain`.
//! They are not rescaled to the data (Slicer does not rescale them either); values outside a
//! preset's points take the end points' colour and opacity (VTK's clamping). A preset whose
//! visible range misses the data renders nothing: see [`Preset::range_warning`].
//! `docs/presets.md` lists the presets and the automatic rule.

use crate::error::{CoreError, Result};
use crate::transfer::{TransferFunction, interpolate_rows};
use crate::volume::{AnyVolume, Scalar, ScalarType};
use std::fmt;
use std::str::FromStr;

/// A built-in transfer function. Every preset except [`Preset::CtSkin`] and [`Preset::Ramp`] is
/// one of 3D Slicer's volume-rendering presets (same name, same control points, same shading
/// coefficients; `presets.xml` of Slicer, 3D Slicer License, BSD-style). Control-point values
/// are in the units of [`Preset::units`]; see the module documentation for data outside them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Preset {
    /// Slicer `CT-AAA` (HU).
    CtAaa,
    /// Slicer `CT-AAA2` (HU).
    CtAaa2,
    /// Slicer `CT-Bone` (HU); also reached as `ct-bone`.
    CtBone,
    /// Slicer `CT-Bones` (HU).
    CtBones,
    /// Slicer `CT-Cardiac` (HU).
    CtCardiac,
    /// Slicer `CT-Cardiac2` (HU).
    CtCardiac2,
    /// Slicer `CT-Cardiac3` (HU).
    CtCardiac3,
    /// Slicer `CT-Chest-Contrast-Enhanced` (HU); alias `CT-Chest-Contrast`.
    CtChestContrastEnhanced,
    /// Slicer `CT-Chest-Vessels` (HU).
    CtChestVessels,
    /// Slicer `CT-Coronary-Arteries` (HU).
    CtCoronaryArteries,
    /// Slicer `CT-Coronary-Arteries-2` (HU).
    CtCoronaryArteries2,
    /// Slicer `CT-Coronary-Arteries-3` (HU).
    CtCoronaryArteries3,
    /// Slicer `CT-Cropped-Volume-Bone` (HU).
    CtCroppedVolumeBone,
    /// Slicer `CT-Fat` (HU).
    CtFat,
    /// Slicer `CT-Liver-Vasculature` (HU).
    CtLiverVasculature,
    /// Slicer `CT-Lung` (HU).
    CtLung,
    /// Slicer `CT-MIP` (HU).
    CtMip,
    /// Slicer `CT-Muscle` (HU).
    CtMuscle,
    /// Slicer `CT-Pulmonary-Arteries` (HU).
    CtPulmonaryArteries,
    /// Slicer `CT-Soft-Tissue` (HU).
    CtSoftTissue,
    /// Slicer `CT-Air` (HU).
    CtAir,
    /// Slicer `CT-X-ray` (HU).
    CtXRay,
    /// Slicer `MR-Angio` (MR intensity).
    MrAngio,
    /// Slicer `MR-Default` (MR intensity); also reached as `mr`.
    MrDefault,
    /// Slicer `MR-MIP` (MR intensity).
    MrMip,
    /// Slicer `MR-T2-Brain` (MR intensity).
    MrT2Brain,
    /// Slicer `DTI-FA-Brain` (fractional anisotropy, 0–1).
    DtiFaBrain,
    /// Slicer `US-Fetal` (8-bit ultrasound intensity).
    UsFetal,
    /// Slicer `uCT-Bone-8bit` (8-bit micro-CT intensity).
    UctBone8bit,
    /// Slicer `uCT-Bone-16bit` (16-bit micro-CT intensity).
    UctBone16bit,
    /// Slicer `uCT-Skull` (micro-CT intensity, 0–1024).
    UctSkull,
    /// volsplat's `ct-skin` (HU): translucent skin over opaque bone.
    CtSkin,
    /// volsplat's `ramp`: a grey ramp over the data range (the only preset that depends on it).
    Ramp,
}

/// Accepted alternative names (matched case-insensitively, like the names) and their presets.
pub const PRESET_ALIASES: &[(&str, Preset)] = &[
    ("mr", Preset::MrDefault),
    ("ct-chest-contrast", Preset::CtChestContrastEnhanced),
];

impl Preset {
    /// Every preset, Slicer's first in the order of `presets.xml`, then volsplat's.
    pub const ALL: [Preset; 33] = [
        Preset::CtAaa,
        Preset::CtAaa2,
        Preset::CtBone,
        Preset::CtBones,
        Preset::CtCardiac,
        Preset::CtCardiac2,
        Preset::CtCardiac3,
        Preset::CtChestContrastEnhanced,
        Preset::CtChestVessels,
        Preset::CtCoronaryArteries,
        Preset::CtCoronaryArteries2,
        Preset::CtCoronaryArteries3,
        Preset::CtCroppedVolumeBone,
        Preset::CtFat,
        Preset::CtLiverVasculature,
        Preset::CtLung,
        Preset::CtMip,
        Preset::CtMuscle,
        Preset::CtPulmonaryArteries,
        Preset::CtSoftTissue,
        Preset::CtAir,
        Preset::CtXRay,
        Preset::MrAngio,
        Preset::MrDefault,
        Preset::MrMip,
        Preset::MrT2Brain,
        Preset::DtiFaBrain,
        Preset::UsFetal,
        Preset::UctBone8bit,
        Preset::UctBone16bit,
        Preset::UctSkull,
        Preset::CtSkin,
        Preset::Ramp,
    ];

    /// The canonical names, in the order of [`Preset::ALL`].
    pub const NAMES: [&'static str; 33] = [
        "CT-AAA",
        "CT-AAA2",
        "CT-Bone",
        "CT-Bones",
        "CT-Cardiac",
        "CT-Cardiac2",
        "CT-Cardiac3",
        "CT-Chest-Contrast-Enhanced",
        "CT-Chest-Vessels",
        "CT-Coronary-Arteries",
        "CT-Coronary-Arteries-2",
        "CT-Coronary-Arteries-3",
        "CT-Cropped-Volume-Bone",
        "CT-Fat",
        "CT-Liver-Vasculature",
        "CT-Lung",
        "CT-MIP",
        "CT-Muscle",
        "CT-Pulmonary-Arteries",
        "CT-Soft-Tissue",
        "CT-Air",
        "CT-X-ray",
        "MR-Angio",
        "MR-Default",
        "MR-MIP",
        "MR-T2-Brain",
        "DTI-FA-Brain",
        "US-Fetal",
        "uCT-Bone-8bit",
        "uCT-Bone-16bit",
        "uCT-Skull",
        "ct-skin",
        "ramp",
    ];

    /// The canonical name: Slicer's spelling for Slicer's presets, lower case for volsplat's.
    pub fn name(self) -> &'static str {
        Self::NAMES[self as usize]
    }

    /// One line saying what the preset shows; thresholds in the units of [`Preset::units`].
    pub fn description(self) -> &'static str {
        use Preset::*;
        match self {
            CtAaa => {
                "CT angiography (aortic aneurysm): contrast-filled vessels and bone from ~144 HU"
            }
            CtAaa2 => {
                "CT angiography (aortic aneurysm), variant: vessels from ~130 HU, multicoloured"
            }
            CtBone => "CT bone: faint soft tissue from ~-16 HU, opaque ivory bone",
            CtBones => "CT bones, translucent (opacity <= 0.2 from ~150 HU), red-yellow colours",
            CtCardiac => {
                "Cardiac CT: soft tissue from ~-78 HU, contrast-filled chambers and bone opaque"
            }
            CtCardiac2 => {
                "Cardiac CT, variant: contrast-enhanced blood and bone from ~43 HU, orange to white"
            }
            CtCardiac3 => "Cardiac CT, variant: from ~-87 HU, blue-red-yellow colours",
            CtChestContrastEnhanced => "Contrast-enhanced chest CT: vessels and bone from ~67 HU",
            CtChestVessels => {
                "Chest CT: lung vessels against translucent lung (opacity from air up to 23 HU)"
            }
            CtCoronaryArteries => {
                "Coronary CT angiography: contrast from ~136 HU, grey to white, unshaded"
            }
            CtCoronaryArteries2 => {
                "Coronary CT angiography, variant: from ~143 HU, red-orange to white"
            }
            CtCoronaryArteries3 => {
                "Coronary CT angiography, variant: from ~129 HU, red-orange to grey"
            }
            CtCroppedVolumeBone => {
                "CT of a cropped region: opaque above -450 HU, dark grey to white, unshaded"
            }
            CtFat => "CT fat: only -99 to -60 HU visible, translucent, unshaded",
            CtLiverVasculature => {
                "Contrast CT of the liver: vessels from ~149 HU, brown to white, unshaded"
            }
            CtLung => "CT lung: only -599 to -400 HU visible (lung surfaces), coloured",
            CtMip => {
                "CT for maximum-intensity projection: white, opacity from -638 HU to 1 at 700 HU"
            }
            CtMuscle => "CT muscle and soft tissue: opacity from ~-155 HU, brown to white",
            CtPulmonaryArteries => {
                "CT pulmonary angiography: lung structure and arteries from ~-569 HU"
            }
            CtSoftTissue => "CT soft tissue: opaque above -160 HU, dark grey to white, unshaded",
            CtAir => "CT air: air and gas below -500 HU (white to blue), tissue transparent",
            CtXRay => "CT as a radiograph: faint white from -200 HU (0.05 at 1500 HU), unshaded",
            MrAngio => "MR angiography: bright vessels from ~151, orange to white",
            MrDefault => "MR default: opacity from 20, dark red through tan to white",
            MrMip => "MR for maximum-intensity projection: white, opacity from 98 to 1 at 417",
            MrT2Brain => "T2-weighted brain MR: opacity from ~36, yellow to blue, glossy",
            DtiFaBrain => "DTI fractional anisotropy (0-1): opaque above FA ~0.4, coloured by FA",
            UsFetal => "Fetal 3-D ultrasound (8-bit): skin-coloured surface from ~60",
            UctBone8bit => "Micro-CT bone, 8-bit data: opaque from ~59, red-yellow-white",
            UctBone16bit => "Micro-CT bone, 16-bit data: opaque from ~33600, red-yellow-white",
            UctSkull => "Micro-CT skull (0-1024): opaque from ~25, gradient opacity on edges",
            CtSkin => "volsplat: CT translucent skin over opaque bone",
            Ramp => "volsplat: grey ramp over the data range, opacity 0 to 0.5, unshaded",
        }
    }

    /// The units of the preset's control-point values.
    pub fn units(self) -> &'static str {
        use Preset::*;
        match self {
            MrAngio | MrDefault | MrMip | MrT2Brain => "MR intensity",
            DtiFaBrain => "fractional anisotropy (0-1)",
            UsFetal => "ultrasound intensity (8-bit)",
            UctBone8bit => "micro-CT intensity (8-bit)",
            UctBone16bit => "micro-CT intensity (16-bit)",
            UctSkull => "micro-CT intensity (0-1024)",
            Ramp => "data units (spans the data range)",
            _ => "HU",
        }
    }

    /// Whether the preset is one of 3D Slicer's (`false` for `ct-skin` and `ramp`).
    pub fn is_slicer(self) -> bool {
        self.slicer().is_some()
    }

    /// The transfer function. `data_range` (smallest and largest sample, data units) is used
    /// only by [`Preset::Ramp`], which spans it (a non-finite range is taken as 0–1); every
    /// other preset has fixed control points in [`Preset::units`]. Slicer's gradient opacity
    /// is kept only where it differs from 1 for some magnitude ≥ 0 (only `uCT-Skull`): Slicer
    /// writes a constant 1 into the others, which changes nothing.
    pub fn transfer_function(self, data_range: (f64, f64)) -> TransferFunction {
        let (lo, hi) = if data_range.0.is_finite() && data_range.1.is_finite() {
            data_range
        } else {
            (0.0, 1.0)
        };
        if let Some(s) = self.slicer() {
            return s.to_transfer_function();
        }
        let base = TransferFunction::ramp(lo, hi, 0.5);
        match self {
            Preset::CtSkin => TransferFunction {
                color: vec![
                    [-1024.0, 0.0, 0.0, 0.0],
                    [-500.0, 0.55, 0.25, 0.15],
                    [-100.0, 0.93, 0.77, 0.63],
                    [200.0, 0.95, 0.80, 0.68],
                    [400.0, 1.0, 0.98, 0.92],
                    [3071.0, 1.0, 1.0, 1.0],
                ],
                scalar_opacity: vec![
                    [-1024.0, 0.0],
                    [-600.0, 0.0],
                    [-300.0, 0.006],
                    [250.0, 0.006],
                    [500.0, 0.6],
                    [3071.0, 0.9],
                ],
                shade: true,
                ambient: 0.15,
                diffuse: 0.85,
                specular: 0.25,
                specular_power: 15.0,
                ..base
            },
            _ => base,
        }
    }

    /// The values (in [`Preset::units`]) where the scalar opacity is above zero, as
    /// `(lowest, highest)`; an end is infinite where the opacity of the end point is above zero
    /// (VTK clamps, so every value beyond it is visible). For [`Preset::Ramp`] the range is that
    /// of the ramp over `data_range`. `None` if the opacity is zero everywhere.
    pub fn visible_range(self, data_range: (f64, f64)) -> Option<(f64, f64)> {
        visible_range(&self.transfer_function(data_range).scalar_opacity)
    }

    /// A warning, for the user, when the data cannot look as the preset intends: the data range
    /// (smallest and largest sample, data units) misses the values the preset shows (the image
    /// will be empty), or lies inside one span where the preset's opacity is the same at every
    /// value (the volume renders as a uniform block). `None` when the ranges overlap usefully.
    pub fn range_warning(self, data_range: (f64, f64)) -> Option<String> {
        let (lo, hi) = data_range;
        let name = self.name();
        let units = self.units();
        let Some((vlo, vhi)) = self.visible_range(data_range) else {
            return Some(format!("preset {name} has no visible values"));
        };
        if hi < vlo || lo > vhi {
            return Some(format!(
                "the data range [{lo}, {hi}] lies outside the values preset {name} shows \
                 ([{vlo}, {vhi}] {units}); the image will be empty. Presets are in absolute \
                 units and are not rescaled: pick one for this modality, or give no preset \
                 for the automatic transfer function"
            ));
        }
        let tf = self.transfer_function(data_range);
        let points = &tf.scalar_opacity;
        let first = points.first().map_or(0.0, |p| p[0]);
        let last = points.last().map_or(0.0, |p| p[0]);
        if hi <= first || lo >= last {
            return Some(format!(
                "the data range [{lo}, {hi}] lies beyond the control points of preset {name} \
                 ([{first}, {last}] {units}): every sample gets the same colour and opacity"
            ));
        }
        None
    }

    fn slicer(self) -> Option<&'static SlicerPreset> {
        use Preset::*;
        use slicer_table::*;
        Some(match self {
            CtAaa => &CT_AAA,
            CtAaa2 => &CT_AAA2,
            CtBone => &CT_BONE,
            CtBones => &CT_BONES,
            CtCardiac => &CT_CARDIAC,
            CtCardiac2 => &CT_CARDIAC2,
            CtCardiac3 => &CT_CARDIAC3,
            CtChestContrastEnhanced => &CT_CHEST_CONTRAST_ENHANCED,
            CtChestVessels => &CT_CHEST_VESSELS,
            CtCoronaryArteries => &CT_CORONARY_ARTERIES,
            CtCoronaryArteries2 => &CT_CORONARY_ARTERIES_2,
            CtCoronaryArteries3 => &CT_CORONARY_ARTERIES_3,
            CtCroppedVolumeBone => &CT_CROPPED_VOLUME_BONE,
            CtFat => &CT_FAT,
            CtLiverVasculature => &CT_LIVER_VASCULATURE,
            CtLung => &CT_LUNG,
            CtMip => &CT_MIP,
            CtMuscle => &CT_MUSCLE,
            CtPulmonaryArteries => &CT_PULMONARY_ARTERIES,
            CtSoftTissue => &CT_SOFT_TISSUE,
            CtAir => &CT_AIR,
            CtXRay => &CT_X_RAY,
            MrAngio => &MR_ANGIO,
            MrDefault => &MR_DEFAULT,
            MrMip => &MR_MIP,
            MrT2Brain => &MR_T2_BRAIN,
            DtiFaBrain => &DTI_FA_BRAIN,
            UsFetal => &US_FETAL,
            UctBone8bit => &UCT_BONE_8BIT,
            UctBone16bit => &UCT_BONE_16BIT,
            UctSkull => &UCT_SKULL,
            CtSkin | Ramp => return None,
        })
    }

    /// The comma-separated list of names and aliases used in error messages.
    fn known_names() -> String {
        let aliases = PRESET_ALIASES
            .iter()
            .map(|(a, p)| format!("{a} = {}", p.name()))
            .collect::<Vec<_>>()
            .join(", ");
        format!(
            "{} (case-insensitive; aliases: {aliases})",
            Self::NAMES.join(", ")
        )
    }
}

impl fmt::Display for Preset {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Serialised as its name ([`Preset::name`]), read back with [`Preset::from_str`] (any case,
/// aliases accepted), so scene files hold `"preset": "CT-Bone"`.
impl serde::Serialize for Preset {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        s.serialize_str(self.name())
    }
}

impl<'de> serde::Deserialize<'de> for Preset {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        let name = String::deserialize(d)?;
        name.parse().map_err(serde::de::Error::custom)
    }
}

impl FromStr for Preset {
    type Err = CoreError;

    /// Parses a name or alias, ignoring ASCII case and treating `_` as `-`
    /// (`ct-bone`, `CT_BONE` and `CT-Bone` are the same preset). Unknown names are
    /// [`CoreError::UnknownName`] listing every name.
    fn from_str(s: &str) -> Result<Self> {
        let wanted = s.trim().replace('_', "-");
        let by_name = Self::ALL
            .iter()
            .copied()
            .find(|p| p.name().eq_ignore_ascii_case(&wanted));
        let by_alias = || {
            PRESET_ALIASES
                .iter()
                .find(|(a, _)| a.eq_ignore_ascii_case(&wanted))
                .map(|(_, p)| *p)
        };
        by_name
            .or_else(by_alias)
            .ok_or_else(|| CoreError::UnknownName {
                kind: "preset".into(),
                name: s.into(),
                known: Self::known_names(),
            })
    }
}

/// See [`Preset::visible_range`].
fn visible_range(points: &[[f64; 2]]) -> Option<(f64, f64)> {
    let first = points.first()?;
    let last = points.last()?;
    let mut lo = None;
    let mut hi = None;
    for (n, p) in points.iter().enumerate() {
        // A point with zero opacity still bounds a visible segment next to a non-zero point.
        let next_visible = points.get(n + 1).is_some_and(|q| q[1] > 0.0);
        let prev_visible = n > 0 && points[n - 1][1] > 0.0;
        if p[1] > 0.0 || next_visible || prev_visible {
            lo.get_or_insert(p[0]);
            hi = Some(p[0]);
        }
    }
    let (mut lo, mut hi) = (lo?, hi?);
    if first[1] > 0.0 {
        lo = f64::NEG_INFINITY;
    }
    if last[1] > 0.0 {
        hi = f64::INFINITY;
    }
    Some((lo, hi))
}

/// One preset of Slicer's `presets.xml`, as written there: `scalarOpacity` as `[value, alpha]`,
/// `gradientOpacity` as `[magnitude, factor]`, `colorTransfer` as `[value, r, g, b]`, and the
/// shading attributes (all presets use linear interpolation, `interpolation="1"`).
struct SlicerPreset {
    scalar_opacity: &'static [[f64; 2]],
    gradient_opacity: &'static [[f64; 2]],
    color: &'static [[f64; 4]],
    shade: bool,
    ambient: f64,
    diffuse: f64,
    specular: f64,
    specular_power: f64,
}

impl SlicerPreset {
    fn to_transfer_function(&self) -> TransferFunction {
        let g = self.gradient_opacity;
        let constant_one = interpolate_rows(g, 0.0)[1] == 1.0
            && g.iter().filter(|p| p[0] >= 0.0).all(|p| p[1] == 1.0);
        TransferFunction {
            color: self.color.to_vec(),
            scalar_opacity: self.scalar_opacity.to_vec(),
            gradient_opacity: (!constant_one).then(|| g.to_vec()),
            // Slicer leaves VTK's default, 1 world unit (mm).
            scalar_opacity_unit_distance: 1.0,
            shade: self.shade,
            ambient: self.ambient,
            diffuse: self.diffuse,
            specular: self.specular,
            specular_power: self.specular_power,
        }
    }
}

/// Sample counts in equal-width bins over a range of values (data units). Built in one pass
/// over the samples once the range is known, so a volume streamed in slabs can be counted as
/// it passes (docs/design.md §5).
#[derive(Debug, Clone, PartialEq)]
pub struct Histogram {
    /// Lower edge of bin 0, data units.
    lo: f64,
    /// Bin width, data units (0 when the range is a single value).
    width: f64,
    counts: Vec<u64>,
}

impl Histogram {
    /// Number of bins [`Histogram::for_scalar_type`] uses for float data.
    pub const FLOAT_BINS: usize = 4096;
    /// Largest number of bins: enough for one bin per value of any 16-bit type.
    pub const MAX_BINS: usize = 1 << 16;

    /// An empty histogram of `bins` equal bins over `[lo, hi]` (data units, finite,
    /// `lo ≤ hi`, `1 ≤ bins ≤` [`Histogram::MAX_BINS`]). With `lo == hi` every value falls in
    /// bin 0.
    pub fn new(lo: f64, hi: f64, bins: usize) -> Result<Self> {
        if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
            return Err(CoreError::invalid(
                "histogram range",
                (lo, hi),
                "needs finite lo <= hi",
            ));
        }
        if !(1..=Self::MAX_BINS).contains(&bins) {
            return Err(CoreError::invalid(
                "histogram bins",
                bins,
                format!("must be in 1..={}", Self::MAX_BINS),
            ));
        }
        let width = (hi - lo) / bins as f64;
        Ok(Histogram {
            lo,
            width: if width.is_finite() { width } else { 0.0 },
            counts: vec![0; bins],
        })
    }

    /// An empty histogram suited to samples of type `t` spanning `range` (smallest and largest
    /// sample, data units): for integer types one bin per integer value (bin centres on the
    /// integers; at most [`Histogram::MAX_BINS`], which every 8- and 16-bit type fits), for
    /// `f32` [`Histogram::FLOAT_BINS`] bins over the range.
    pub fn for_scalar_type(t: ScalarType, range: (f64, f64)) -> Result<Self> {
        match t {
            ScalarType::F32 => Self::new(range.0, range.1, Self::FLOAT_BINS),
            _ => {
                let (lo, hi) = (range.0.floor(), range.1.ceil());
                let span = hi - lo + 1.0;
                if !(span >= 1.0 && span <= Self::MAX_BINS as f64) {
                    return Self::new(range.0, range.1, Self::MAX_BINS);
                }
                Self::new(lo - 0.5, hi + 0.5, span as usize)
            }
        }
    }

    /// The histogram of every sample of `vol`, with the bins of
    /// [`Histogram::for_scalar_type`] over the volume's value range.
    pub fn from_volume(vol: &AnyVolume) -> Self {
        let range = vol.value_range();
        let mut h = Self::for_scalar_type(vol.scalar_type(), range).unwrap_or(Histogram {
            lo: 0.0,
            width: 0.0,
            counts: vec![0],
        });
        crate::with_volume!(vol, v => {
            for x in v.data() {
                h.add(x.to_f32() as f64);
            }
        });
        h
    }

    /// Counts one sample (data units). Values beyond the range go to the end bins; NaN and
    /// infinities are ignored.
    #[inline]
    pub fn add(&mut self, value: f64) {
        if !value.is_finite() {
            return;
        }
        let last = self.counts.len() - 1;
        let bin = if self.width > 0.0 {
            let t = ((value - self.lo) / self.width).floor();
            if t <= 0.0 {
                0
            } else if t >= last as f64 {
                last
            } else {
                t as usize
            }
        } else {
            0
        };
        self.counts[bin] += 1;
    }

    /// The counts, bin 0 (lowest values) first.
    pub fn counts(&self) -> &[u64] {
        &self.counts
    }

    /// Number of samples counted.
    pub fn total(&self) -> u64 {
        self.counts.iter().sum()
    }

    /// Bin width, data units (0 when the range is one value).
    pub fn bin_width(&self) -> f64 {
        self.width
    }

    /// Centre of bin `n`, data units.
    pub fn bin_center(&self, n: usize) -> f64 {
        self.lo + (n as f64 + 0.5) * self.width
    }

    /// Upper edge of bin `n`, data units.
    pub fn bin_upper(&self, n: usize) -> f64 {
        self.lo + (n as f64 + 1.0) * self.width
    }

    /// The centre (data units) of the first bin at which the cumulative count reaches the
    /// fraction `q` (clamped to [0, 1]) of all samples; `None` for an empty histogram.
    pub fn quantile(&self, q: f64) -> Option<f64> {
        self.quantile_from(0, q)
    }

    /// [`Histogram::quantile`] of the samples in bins `start..`.
    fn quantile_from(&self, start: usize, q: f64) -> Option<f64> {
        let counts = self.counts.get(start..)?;
        let total: u64 = counts.iter().sum();
        if total == 0 {
            return None;
        }
        let q = if q.is_nan() { 0.5 } else { q.clamp(0.0, 1.0) };
        let need = (q * total as f64).ceil().max(1.0);
        let mut acc = 0u64;
        for (n, c) in counts.iter().enumerate() {
            acc += c;
            if acc as f64 >= need {
                return Some(self.bin_center(start + n));
            }
        }
        Some(self.bin_center(self.counts.len() - 1))
    }

    /// Otsu's threshold (Otsu 1979, between-class variance) over bins `range`: `None` if fewer
    /// than two of them are occupied. Ties go to the lowest bin, so the result is deterministic.
    fn otsu(&self, range: std::ops::Range<usize>) -> Option<OtsuSplit> {
        let counts = self.counts.get(range.clone())?;
        let (mut n_all, mut s_all) = (0.0f64, 0.0f64);
        for (n, &c) in counts.iter().enumerate() {
            n_all += c as f64;
            s_all += c as f64 * self.bin_center(range.start + n);
        }
        let (mut w0, mut s0) = (0.0f64, 0.0f64);
        let mut best: Option<(f64, usize)> = None;
        for (n, &c) in counts.iter().enumerate() {
            w0 += c as f64;
            s0 += c as f64 * self.bin_center(range.start + n);
            let w1 = n_all - w0;
            if w0 == 0.0 || w1 == 0.0 {
                continue;
            }
            let d = s0 / w0 - (s_all - s0) / w1;
            let between = w0 * w1 * d * d;
            if best.is_none_or(|(b, _)| between > b) {
                best = Some((between, range.start + n));
            }
        }
        let (_, k) = best?;
        let moments = |bins: std::ops::Range<usize>| {
            let (mut w, mut s, mut ss, mut occupied) = (0.0f64, 0.0f64, 0.0f64, 0usize);
            for n in bins {
                let c = self.counts[n] as f64;
                let x = self.bin_center(n);
                w += c;
                s += c * x;
                ss += c * x * x;
                occupied += usize::from(c > 0.0);
            }
            let mean = s / w;
            (w, mean, (ss / w - mean * mean).max(0.0).sqrt(), occupied)
        };
        let (weight0, mean0, sigma0, occupied0) = moments(range.start..k + 1);
        let (_, mean1, _, _) = moments(k + 1..range.end);
        Some(OtsuSplit {
            k,
            weight0,
            mean0,
            sigma0,
            occupied0,
            mean1,
        })
    }
}

/// Otsu's split of a run of bins: the lower class is bins `..=k`.
struct OtsuSplit {
    k: usize,
    weight0: f64,
    mean0: f64,
    sigma0: f64,
    occupied0: usize,
    mean1: f64,
}

/// How [`AutoTransfer`] found the background.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum BackgroundRule {
    /// Otsu's lower class, which was tight and far below the rest (see [`AutoTransfer`]).
    Otsu,
    /// Only the lowest value, a fill value (padding, a mask's outside) apart from the rest; the
    /// rest had no background of its own.
    FillValue,
    /// No background was found: every value above the data minimum is shown.
    None,
    /// The histogram is empty or holds a single value: the grey [`Preset::Ramp`].
    Degenerate,
}

/// The automatic transfer function for data with no preset, and how it was chosen.
///
/// The rule (deterministic; `docs/presets.md` discusses its limits):
/// 1. **Background.** Otsu's threshold splits the histogram in two. If the lower class is
///    essentially one value (the lowest value holds [`AutoTransfer::FILL_SHARE`] of it: a *fill
///    value*, such as the −3024 HU padding outside a CT's field of view or the 0 outside a
///    masked MRI), that value is background and Otsu is applied once more to the values above
///    it. Otherwise (and in that second round) Otsu's lower class is background when it is tight
///    and far below the rest: its mean at least [`AutoTransfer::SEPARATION`] of its standard
///    deviations (at least one bin width) below the upper class's mean, as air is below tissue
///    in CT and noise below tissue in MR, but not the two halves of one tissue's range.
///    Otherwise there is no further background.
/// 2. **Foreground percentiles.** Of the samples above the background threshold `t`, the
///    percentiles [`AutoTransfer::PERCENTILES`] (5th, 50th, 99th: robust to outliers such as
///    metal or hot voxels).
/// 3. **Transfer function.** 3D Slicer's `MR-Default` re-fitted to these landmarks: its control
///    points at 20, 40, 120, 220 and 1024 move to `t`, P5, P50, P99 and the data maximum, with
///    opacity 0, 0.15, 0.3, 0.375, 0.5 and colour dark red → brown → tan → ivory → white;
///    opacity is 0 at and below `t`. Shading as `MR-Default` (ambient 0.2, diffuse 1,
///    specular 0). Opacities are per `scalar_opacity_unit_distance`, which
///    [`AutoTransfer::from_volume`] sets to the smallest voxel spacing (so they are per voxel
///    step, whatever the world unit) and [`AutoTransfer::from_histogram`] leaves at 1.
/// 4. **Few values** (a binary mask, a label image: at most [`AutoTransfer::FEW_VALUES`]
///    distinct values above `t`, at bin resolution) replace step 3: every foreground value is
///    opaque, [`AutoTransfer::FEW_OPACITY`] per unit distance from halfway between `t` and the
///    lowest foreground value on, each in its own colour of [`AutoTransfer::LABEL_COLORS`]
///    (ivory for the first). The percentile ramp would give such data a dim, dark shell of
///    partial-volume values around an interior whose zero gradient reflects no light: a nearly
///    black picture. With the opacity reached at the boundary, the lit surface hides it.
/// 5. **One value** (constant data): the unshaded grey ramp of [`Preset::Ramp`], ending at the
///    value, so that it shows (opacity 0.5, white) rather than nothing.
#[derive(Debug, Clone, PartialEq)]
pub struct AutoTransfer {
    /// The transfer function (values in data units).
    pub transfer_function: TransferFunction,
    /// How the background was found.
    pub rule: BackgroundRule,
    /// The fill value found (data units), if any; it is part of the background.
    pub fill_value: Option<f64>,
    /// Background threshold `t`, data units: samples at or below it are transparent.
    pub threshold: f64,
    /// The foreground percentiles [`AutoTransfer::PERCENTILES`] of the samples above
    /// `threshold`, data units (at bin resolution).
    pub foreground: [f64; 3],
    /// The distinct foreground values (bin centres, data units) where there are at most
    /// [`AutoTransfer::FEW_VALUES`] of them (rule step 4: each opaque in its own colour);
    /// empty otherwise.
    pub labels: Vec<f64>,
}

impl AutoTransfer {
    /// The foreground percentiles (fractions) that place the opacity and colour ramp.
    pub const PERCENTILES: [f64; 3] = [0.05, 0.5, 0.99];
    /// The lowest value is a fill value when it holds at least this share (90%) of Otsu's lower
    /// class: Otsu's threshold next to a spike takes in a few samples of the other class's
    /// tail, so the class is rarely the spike alone.
    pub const FILL_SHARE: f64 = 0.9;
    /// Otsu's lower class is background only if `(mean₁ − mean₀) ≥ SEPARATION · σ₀`: 4.5,
    /// between what splitting one noisy tissue gives (2.7 for a Gaussian, 3.5 for a uniform
    /// spread, 3.1 and 3.9 for the Colin27 MRI's head above its fill value and for a
    /// skull-stripped version of it) and a real background (6.2 for Colin27's, 11 for
    /// brainsmall's, about 60 for CT air).
    pub const SEPARATION: f64 = 4.5;
    /// At most this many distinct foreground values make a label image (rule step 4): a binary
    /// mask has one, a small segmentation a few.
    pub const FEW_VALUES: usize = 8;
    /// Opacity per unit distance (per voxel step from [`AutoTransfer::from_volume`]) of every
    /// value of a label image: the boundary between background and label is opaque within a
    /// voxel, so its surface, which has a gradient, is what is seen and lit.
    pub const FEW_OPACITY: f64 = 0.8;
    /// The colours of a label image's foreground values, lowest first (cycled beyond eight):
    /// ivory (`MR-Default`'s tissue colour at its 99th percentile), then well-separated hues.
    pub const LABEL_COLORS: [[f64; 3]; 8] = [
        [0.847059, 0.835294, 0.788235],
        [0.87, 0.45, 0.35],
        [0.45, 0.68, 0.88],
        [0.55, 0.80, 0.45],
        [0.95, 0.80, 0.35],
        [0.72, 0.55, 0.88],
        [0.95, 0.60, 0.25],
        [0.45, 0.85, 0.80],
    ];

    /// The automatic transfer function of `vol`, with `scalar_opacity_unit_distance` the
    /// smallest voxel spacing (world units), so that opacities hold per voxel step.
    ///
    /// A volume of one sample along an axis (a 2-D image, a single slice) is drawn unshaded:
    /// its gradients lie in its plane (zero along the one-sample axis, and zero wherever the
    /// image is flat), so lights would leave it black but for its edges.
    pub fn from_volume(vol: &AnyVolume) -> Self {
        let mut auto = Self::from_histogram(&Histogram::from_volume(vol));
        let spacing = vol.grid().spacing;
        let unit = spacing.iter().copied().fold(f64::INFINITY, f64::min);
        if unit.is_finite() && unit > 0.0 {
            auto.transfer_function.scalar_opacity_unit_distance = unit;
        }
        if vol.grid().dims.contains(&1) {
            auto.transfer_function.shade = false;
        }
        auto
    }

    /// The automatic transfer function for a histogram (see [`AutoTransfer`] for the rule);
    /// `scalar_opacity_unit_distance` is 1 world unit.
    pub fn from_histogram(h: &Histogram) -> Self {
        let counts = h.counts();
        let first = counts.iter().position(|&c| c > 0);
        let last = counts.iter().rposition(|&c| c > 0);
        let (Some(first), Some(last)) = (first, last) else {
            return Self::degenerate(0.0, 1.0);
        };
        let (lo, hi) = (h.bin_center(first), h.bin_center(last));
        if first == last {
            return Self::degenerate(lo, hi);
        }
        let separated = |s: &OtsuSplit| {
            let sigma = s.sigma0.max(h.bin_width());
            s.occupied0 >= 2 && s.mean1 - s.mean0 >= Self::SEPARATION * sigma
        };
        let otsu = |s: &OtsuSplit| (BackgroundRule::Otsu, s.k + 1, h.bin_upper(s.k));
        let mut fill_value = None;
        // Bins of the foreground start at `start`; the threshold is the background's top.
        let (rule, start, threshold) = match h.otsu(first..last + 1) {
            Some(s) if counts[first] as f64 >= Self::FILL_SHARE * s.weight0 => {
                fill_value = Some(lo);
                match h.otsu(first + 1..last + 1) {
                    Some(r) if separated(&r) => otsu(&r),
                    _ => (BackgroundRule::FillValue, first + 1, h.bin_upper(first)),
                }
            }
            Some(s) if separated(&s) => otsu(&s),
            _ => (BackgroundRule::None, first, lo),
        };
        let q = |p: f64| h.quantile_from(start, p).unwrap_or(hi);
        let labels: Vec<f64> = (start..=last)
            .filter(|&n| counts[n] > 0)
            .map(|n| h.bin_center(n))
            .collect();
        if !labels.is_empty() && labels.len() <= Self::FEW_VALUES {
            let foreground = [q(0.05), q(0.5), q(0.99)];
            return Self::label_image(rule, fill_value, threshold, lo, labels, foreground);
        }
        let p = Self::PERCENTILES;
        let p_lo = q(p[0]).max(threshold);
        let p_mid = q(p[1]).max(p_lo);
        let p_hi = q(p[2]).max(p_mid);
        let top = hi.max(p_hi);
        let bottom = lo.min(threshold);
        // Slicer's MR-Default (colours and opacities), moved to these landmarks.
        let tf = TransferFunction {
            color: vec![
                [bottom, 0.0, 0.0, 0.0],
                [threshold, 0.168627, 0.0, 0.0],
                [p_lo, 0.403922, 0.145098, 0.0784314],
                [p_mid, 0.780392, 0.607843, 0.380392],
                [p_hi, 0.847059, 0.835294, 0.788235],
                [top, 1.0, 1.0, 1.0],
            ],
            scalar_opacity: vec![
                [bottom, 0.0],
                [threshold, 0.0],
                [p_lo, 0.15],
                [p_mid, 0.3],
                [p_hi, 0.375],
                [top, 0.5],
            ],
            gradient_opacity: None,
            scalar_opacity_unit_distance: 1.0,
            shade: true,
            ambient: 0.2,
            diffuse: 1.0,
            specular: 0.0,
            specular_power: 1.0,
        };
        AutoTransfer {
            transfer_function: tf,
            rule,
            fill_value,
            threshold,
            foreground: [p_lo, p_mid, p_hi],
            labels: Vec::new(),
        }
    }

    /// Rule step 4: the foreground is the few values `labels` (ascending, above `threshold`),
    /// each opaque in its own colour; `lo` is the lowest value of the data.
    fn label_image(
        rule: BackgroundRule,
        fill_value: Option<f64>,
        threshold: f64,
        lo: f64,
        labels: Vec<f64>,
        foreground: [f64; 3],
    ) -> Self {
        let color = |n: usize| Self::LABEL_COLORS[n % Self::LABEL_COLORS.len()];
        let first = labels[0];
        let top = labels[labels.len() - 1];
        let bottom = lo.min(threshold);
        let rgb = |x: f64, c: [f64; 3]| [x, c[0], c[1], c[2]];
        let mut colors = vec![rgb(bottom, color(0)), rgb(threshold, color(0))];
        colors.extend(labels.iter().enumerate().map(|(n, &v)| rgb(v, color(n))));
        // Opaque from halfway to the first label: the background–label boundary's middle.
        let a = Self::FEW_OPACITY;
        let tf = TransferFunction {
            color: colors,
            scalar_opacity: vec![
                [bottom, 0.0],
                [threshold, 0.0],
                [0.5 * (threshold + first), a],
                [top, a],
            ],
            gradient_opacity: None,
            scalar_opacity_unit_distance: 1.0,
            shade: true,
            ambient: 0.2,
            diffuse: 1.0,
            specular: 0.0,
            specular_power: 1.0,
        };
        AutoTransfer {
            transfer_function: tf,
            rule,
            fill_value,
            threshold,
            foreground,
            labels,
        }
    }

    /// Rule step 5 (and an empty histogram): the grey ramp of [`Preset::Ramp`] over
    /// `[lo, hi]`, or, for one value, over the unit below it, which the value ends.
    fn degenerate(lo: f64, hi: f64) -> Self {
        let range = if hi > lo { (lo, hi) } else { (lo - 1.0, lo) };
        AutoTransfer {
            transfer_function: Preset::Ramp.transfer_function(range),
            rule: BackgroundRule::Degenerate,
            fill_value: None,
            threshold: range.0,
            foreground: [lo, lo, hi],
            labels: Vec::new(),
        }
    }

    /// One line for a log: the rule, the threshold and the ramp's landmarks (data units).
    pub fn describe(&self) -> String {
        let [a, b, c] = self.foreground;
        let t = self.threshold;
        let fill = self
            .fill_value
            .map(|f| format!("fill value {f}, "))
            .unwrap_or_default();
        match self.rule {
            BackgroundRule::Degenerate => {
                format!("automatic transfer function: constant or empty data, grey ramp up to {c}")
            }
            _ if !self.labels.is_empty() => {
                let values: Vec<String> = self.labels.iter().map(|v| v.to_string()).collect();
                format!(
                    "automatic transfer function: {fill}background <= {t} transparent; {} \
                     foreground value{} ({}) opaque, {} per voxel, one colour each (a mask or \
                     label image)",
                    values.len(),
                    if values.len() == 1 { "" } else { "s" },
                    values.join(", "),
                    Self::FEW_OPACITY
                )
            }
            BackgroundRule::None => format!(
                "automatic transfer function: no background found; opacity ramp from {t} over \
                 {a} / {b} / {c} (foreground P5 / P50 / P99)"
            ),
            BackgroundRule::FillValue | BackgroundRule::Otsu => format!(
                "automatic transfer function: {fill}background <= {t} ({}) transparent; opacity \
                 ramp over {a} / {b} / {c} (foreground P5 / P50 / P99)",
                if self.rule == BackgroundRule::Otsu {
                    "Otsu"
                } else {
                    "fill value"
                }
            ),
        }
    }
}

/// 3D Slicer's volume-rendering presets, generated from
/// `Modules/Loadable/VolumeRendering/Resources/presets.xml` of <https://github.com/Slicer/Slicer>
/// (3D Slicer License, BSD-style): each attribute's leading count is dropped and the numbers are
/// kept as written (`.0` added to integers). Do not edit by hand; regenerate from the file.
#[rustfmt::skip]
mod slicer_table {
    use super::SlicerPreset;

pub(super) const CT_AAA: SlicerPreset = SlicerPreset {
    scalar_opacity: &[[-3024.0, 0.0], [143.556, 0.0], [166.222, 0.686275], [214.389, 0.696078], [419.736, 0.833333], [3071.0, 0.803922]],
    gradient_opacity: &[[0.0, 1.0], [255.0, 1.0]],
    color: &[[-3024.0, 0.0, 0.0, 0.0], [143.556, 0.615686, 0.356863, 0.184314], [166.222, 0.882353, 0.603922, 0.290196], [214.389, 1.0, 1.0, 1.0], [419.736, 1.0, 0.937033, 0.954531], [3071.0, 0.827451, 0.658824, 1.0]],
    shade: true,
    ambient: 0.1,
    diffuse: 0.9,
    specular: 0.2,
    specular_power: 10.0,
};
pub(super) const CT_AAA2: SlicerPreset = SlicerPreset {
    scalar_opacity: &[[-3024.0, 0.0], [129.542, 0.0], [145.244, 0.166667], [157.02, 0.5], [169.918, 0.627451], [395.575, 0.8125], [1578.73, 0.8125], [3071.0, 0.8125]],
    gradient_opacity: &[[0.0, 1.0], [255.0, 1.0]],
    color: &[[-3024.0, 0.0, 0.0, 0.0], [129.542, 0.54902, 0.25098, 0.14902], [145.244, 0.6, 0.627451, 0.843137], [157.02, 0.890196, 0.47451, 0.6], [169.918, 0.992157, 0.870588, 0.392157], [395.575, 1.0, 0.886275, 0.658824], [1578.73, 1.0, 0.829256, 0.957922], [3071.0, 0.827451, 0.658824, 1.0]],
    shade: true,
    ambient: 0.1,
    diffuse: 0.9,
    specular: 0.2,
    specular_power: 10.0,
};
pub(super) const CT_BONE: SlicerPreset = SlicerPreset {
    scalar_opacity: &[[-3024.0, 0.0], [-16.4458, 0.0], [641.385, 0.715686], [3071.0, 0.705882]],
    gradient_opacity: &[[0.0, 1.0], [255.0, 1.0]],
    color: &[[-3024.0, 0.0, 0.0, 0.0], [-16.4458, 0.729412, 0.254902, 0.301961], [641.385, 0.905882, 0.815686, 0.552941], [3071.0, 1.0, 1.0, 1.0]],
    shade: true,
    ambient: 0.1,
    diffuse: 0.9,
    specular: 0.2,
    specular_power: 10.0,
};
pub(super) const CT_BONES: SlicerPreset = SlicerPreset {
    scalar_opacity: &[[-1000.0, 0.0], [152.19, 0.0], [278.93, 0.190476], [952.0, 0.2]],
    gradient_opacity: &[[0.0, 1.0], [985.12, 1.0]],
    color: &[[-1000.0, 0.3, 0.3, 1.0], [-488.0, 0.3, 1.0, 0.3], [463.28, 1.0, 0.0, 0.0], [659.15, 1.0, 0.912535, 0.0374849], [953.0, 1.0, 0.3, 0.3]],
    shade: true,
    ambient: 0.2,
    diffuse: 1.0,
    specular: 0.0,
    specular_power: 1.0,
};
pub(super) const CT_CARDIAC: SlicerPreset = SlicerPreset {
    scalar_opacity: &[[-3024.0, 0.0], [-77.6875, 0.0], [94.9518, 0.285714], [179.052, 0.553571], [260.439, 0.848214], [3071.0, 0.875]],
    gradient_opacity: &[[0.0, 1.0], [255.0, 1.0]],
    color: &[[-3024.0, 0.0, 0.0, 0.0], [-77.6875, 0.54902, 0.25098, 0.14902], [94.9518, 0.882353, 0.603922, 0.290196], [179.052, 1.0, 0.937033, 0.954531], [260.439, 0.615686, 0.0, 0.0], [3071.0, 0.827451, 0.658824, 1.0]],
    shade: true,
    ambient: 0.1,
    diffuse: 0.9,
    specular: 0.2,
    specular_power: 10.0,
};
pub(super) const CT_CARDIAC2: SlicerPreset = SlicerPreset {
    scalar_opacity: &[[-3024.0, 0.0], [42.8964, 0.0], [163.488, 0.428571], [277.642, 0.776786], [1587.0, 0.754902], [3071.0, 0.754902]],
    gradient_opacity: &[[0.0, 1.0], [255.0, 1.0]],
    color: &[[-3024.0, 0.0, 0.0, 0.0], [42.8964, 0.54902, 0.25098, 0.14902], [163.488, 0.917647, 0.639216, 0.0588235], [277.642, 1.0, 0.878431, 0.623529], [1587.0, 1.0, 1.0, 1.0], [3071.0, 0.827451, 0.658824, 1.0]],
    shade: true,
    ambient: 0.1,
    diffuse: 0.9,
    specular: 0.2,
    specular_power: 10.0,
};
pub(super) const CT_CARDIAC3: SlicerPreset = SlicerPreset {
    scalar_opacity: &[[-3024.0, 0.0], [-86.9767, 0.0], [45.3791, 0.169643], [139.919, 0.589286], [347.907, 0.607143], [1224.16, 0.607143], [3071.0, 0.616071]],
    gradient_opacity: &[[0.0, 1.0], [255.0, 1.0]],
    color: &[[-3024.0, 0.0, 0.0, 0.0], [-86.9767, 0.0, 0.25098, 1.0], [45.3791, 1.0, 0.0, 0.0], [139.919, 1.0, 0.894893, 0.894893], [347.907, 1.0, 1.0, 0.25098], [1224.16, 1.0, 1.0, 1.0], [3071.0, 0.827451, 0.658824, 1.0]],
    shade: true,
    ambient: 0.1,
    diffuse: 0.9,
    specular: 0.2,
    specular_power: 10.0,
};
pub(super) const CT_CHEST_CONTRAST_ENHANCED: SlicerPreset = SlicerPreset {
    scalar_opacity: &[[-3024.0, 0.0], [67.0106, 0.0], [251.105, 0.446429], [439.291, 0.625], [3071.0, 0.616071]],
    gradient_opacity: &[[0.0, 1.0], [255.0, 1.0]],
    color: &[[-3024.0, 0.0, 0.0, 0.0], [67.0106, 0.54902, 0.25098, 0.14902], [251.105, 0.882353, 0.603922, 0.290196], [439.291, 1.0, 0.937033, 0.954531], [3071.0, 0.827451, 0.658824, 1.0]],
    shade: true,
    ambient: 0.1,
    diffuse: 0.9,
    specular: 0.2,
    specular_power: 10.0,
};
pub(super) const CT_CHEST_VESSELS: SlicerPreset = SlicerPreset {
    scalar_opacity: &[[-3024.0, 0.0], [-1278.35, 0.0], [22.8277, 0.428571], [439.291, 0.625], [3071.0, 0.616071]],
    gradient_opacity: &[[0.0, 1.0], [255.0, 1.0]],
    color: &[[-3024.0, 0.0, 0.0, 0.0], [-1278.35, 0.54902, 0.25098, 0.14902], [22.8277, 0.882353, 0.603922, 0.290196], [439.291, 1.0, 0.937033, 0.954531], [3071.0, 0.827451, 0.658824, 1.0]],
    shade: true,
    ambient: 0.2,
    diffuse: 1.0,
    specular: 0.0,
    specular_power: 1.0,
};
pub(super) const CT_CORONARY_ARTERIES: SlicerPreset = SlicerPreset {
    scalar_opacity: &[[-2048.0, 0.0], [136.47, 0.0], [159.215, 0.258929], [318.43, 0.571429], [478.693, 0.776786], [3661.0, 1.0]],
    gradient_opacity: &[[0.0, 1.0], [255.0, 1.0]],
    color: &[[-2048.0, 0.0, 0.0, 0.0], [136.47, 0.0, 0.0, 0.0], [159.215, 0.159804, 0.159804, 0.159804], [318.43, 0.764706, 0.764706, 0.764706], [478.693, 1.0, 1.0, 1.0], [3661.0, 1.0, 1.0, 1.0]],
    shade: false,
    ambient: 0.2,
    diffuse: 1.0,
    specular: 0.0,
    specular_power: 1.0,
};
pub(super) const CT_CORONARY_ARTERIES_2: SlicerPreset = SlicerPreset {
    scalar_opacity: &[[-2048.0, 0.0], [142.677, 0.0], [145.016, 0.116071], [192.174, 0.5625], [217.24, 0.776786], [384.347, 0.830357], [3661.0, 0.830357]],
    gradient_opacity: &[[0.0, 1.0], [255.0, 1.0]],
    color: &[[-2048.0, 0.0, 0.0, 0.0], [142.677, 0.0, 0.0, 0.0], [145.016, 0.615686, 0.0, 0.0156863], [192.174, 0.909804, 0.454902, 0.0], [217.24, 0.972549, 0.807843, 0.611765], [384.347, 0.909804, 0.909804, 1.0], [3661.0, 1.0, 1.0, 1.0]],
    shade: true,
    ambient: 0.2,
    diffuse: 1.0,
    specular: 0.0,
    specular_power: 1.0,
};
pub(super) const CT_CORONARY_ARTERIES_3: SlicerPreset = SlicerPreset {
    scalar_opacity: &[[-2048.0, 0.0], [128.643, 0.0], [129.982, 0.0982143], [173.636, 0.669643], [255.884, 0.857143], [584.878, 0.866071], [3661.0, 1.0]],
    gradient_opacity: &[[0.0, 1.0], [255.0, 1.0]],
    color: &[[-2048.0, 0.0, 0.0, 0.0], [128.643, 0.0, 0.0, 0.0], [129.982, 0.615686, 0.0, 0.0156863], [173.636, 0.909804, 0.454902, 0.0], [255.884, 0.886275, 0.886275, 0.886275], [584.878, 0.968627, 0.968627, 0.968627], [3661.0, 1.0, 1.0, 1.0]],
    shade: true,
    ambient: 0.1,
    diffuse: 0.9,
    specular: 0.2,
    specular_power: 10.0,
};
pub(super) const CT_CROPPED_VOLUME_BONE: SlicerPreset = SlicerPreset {
    scalar_opacity: &[[-2048.0, 0.0], [-451.0, 0.0], [-450.0, 1.0], [1050.0, 1.0], [3661.0, 1.0]],
    gradient_opacity: &[[0.0, 1.0], [255.0, 1.0]],
    color: &[[-2048.0, 0.0, 0.0, 0.0], [-451.0, 0.0, 0.0, 0.0], [-450.0, 0.0556356, 0.0556356, 0.0556356], [1050.0, 1.0, 1.0, 1.0], [3661.0, 1.0, 1.0, 1.0]],
    shade: false,
    ambient: 0.2,
    diffuse: 1.0,
    specular: 0.0,
    specular_power: 1.0,
};
pub(super) const CT_FAT: SlicerPreset = SlicerPreset {
    scalar_opacity: &[[-1000.0, 0.0], [-100.0, 0.0], [-99.0, 0.15], [-60.0, 0.15], [-59.0, 0.0], [101.2, 0.0], [952.0, 0.0]],
    gradient_opacity: &[[0.0, 1.0], [985.12, 1.0], [988.0, 1.0]],
    color: &[[-1000.0, 0.3, 0.3, 1.0], [-497.5, 0.3, 1.0, 0.3], [-99.0, 0.0, 0.0, 1.0], [-76.946, 0.0, 1.0, 0.0], [-65.481, 0.835431, 0.888889, 0.0165387], [83.89, 1.0, 0.0, 0.0], [463.28, 1.0, 0.0, 0.0], [659.15, 1.0, 0.912535, 0.0374849], [2952.0, 1.0, 0.300267, 0.299886]],
    shade: false,
    ambient: 0.2,
    diffuse: 1.0,
    specular: 0.0,
    specular_power: 1.0,
};
pub(super) const CT_LIVER_VASCULATURE: SlicerPreset = SlicerPreset {
    scalar_opacity: &[[-2048.0, 0.0], [149.113, 0.0], [157.884, 0.482143], [339.96, 0.660714], [388.526, 0.830357], [1197.95, 0.839286], [3661.0, 0.848214]],
    gradient_opacity: &[[0.0, 1.0], [255.0, 1.0]],
    color: &[[-2048.0, 0.0, 0.0, 0.0], [149.113, 0.0, 0.0, 0.0], [157.884, 0.501961, 0.25098, 0.0], [339.96, 0.695386, 0.59603, 0.36886], [388.526, 0.854902, 0.85098, 0.827451], [1197.95, 1.0, 1.0, 1.0], [3661.0, 1.0, 1.0, 1.0]],
    shade: false,
    ambient: 0.2,
    diffuse: 1.0,
    specular: 0.0,
    specular_power: 1.0,
};
pub(super) const CT_LUNG: SlicerPreset = SlicerPreset {
    scalar_opacity: &[[-1000.0, 0.0], [-600.0, 0.0], [-599.0, 0.15], [-400.0, 0.15], [-399.0, 0.0], [2952.0, 0.0]],
    gradient_opacity: &[[0.0, 1.0], [985.12, 1.0], [988.0, 1.0]],
    color: &[[-1000.0, 0.3, 0.3, 1.0], [-600.0, 0.0, 0.0, 1.0], [-530.0, 0.134704, 0.781726, 0.0724558], [-460.0, 0.929244, 1.0, 0.109473], [-400.0, 0.888889, 0.254949, 0.0240258], [2952.0, 1.0, 0.3, 0.3]],
    shade: true,
    ambient: 0.2,
    diffuse: 1.0,
    specular: 0.0,
    specular_power: 1.0,
};
pub(super) const CT_MIP: SlicerPreset = SlicerPreset {
    scalar_opacity: &[[-3024.0, 0.0], [-637.62, 0.0], [700.0, 1.0], [3071.0, 1.0]],
    gradient_opacity: &[[0.0, 1.0], [255.0, 1.0]],
    color: &[[-3024.0, 0.0, 0.0, 0.0], [-637.62, 1.0, 1.0, 1.0], [700.0, 1.0, 1.0, 1.0], [3071.0, 1.0, 1.0, 1.0]],
    shade: true,
    ambient: 0.1,
    diffuse: 0.9,
    specular: 0.2,
    specular_power: 10.0,
};
pub(super) const CT_MUSCLE: SlicerPreset = SlicerPreset {
    scalar_opacity: &[[-3024.0, 0.0], [-155.407, 0.0], [217.641, 0.676471], [419.736, 0.833333], [3071.0, 0.803922]],
    gradient_opacity: &[[0.0, 1.0], [255.0, 1.0]],
    color: &[[-3024.0, 0.0, 0.0, 0.0], [-155.407, 0.54902, 0.25098, 0.14902], [217.641, 0.882353, 0.603922, 0.290196], [419.736, 1.0, 0.937033, 0.954531], [3071.0, 0.827451, 0.658824, 1.0]],
    shade: true,
    ambient: 0.1,
    diffuse: 0.9,
    specular: 0.2,
    specular_power: 10.0,
};
pub(super) const CT_PULMONARY_ARTERIES: SlicerPreset = SlicerPreset {
    scalar_opacity: &[[-2048.0, 0.0], [-568.625, 0.0], [-364.081, 0.0714286], [-244.813, 0.401786], [18.2775, 0.607143], [447.798, 0.830357], [3592.73, 0.839286]],
    gradient_opacity: &[[0.0, 1.0], [255.0, 1.0]],
    color: &[[-2048.0, 0.0, 0.0, 0.0], [-568.625, 0.0, 0.0, 0.0], [-364.081, 0.396078, 0.301961, 0.180392], [-244.813, 0.611765, 0.352941, 0.0705882], [18.2775, 0.843137, 0.0156863, 0.156863], [447.798, 0.752941, 0.752941, 0.752941], [3592.73, 1.0, 1.0, 1.0]],
    shade: true,
    ambient: 0.2,
    diffuse: 1.0,
    specular: 0.0,
    specular_power: 1.0,
};
pub(super) const CT_SOFT_TISSUE: SlicerPreset = SlicerPreset {
    scalar_opacity: &[[-2048.0, 0.0], [-167.01, 0.0], [-160.0, 1.0], [240.0, 1.0], [3661.0, 1.0]],
    gradient_opacity: &[[0.0, 1.0], [255.0, 1.0]],
    color: &[[-2048.0, 0.0, 0.0, 0.0], [-167.01, 0.0, 0.0, 0.0], [-160.0, 0.0556356, 0.0556356, 0.0556356], [240.0, 1.0, 1.0, 1.0], [3661.0, 1.0, 1.0, 1.0]],
    shade: false,
    ambient: 0.2,
    diffuse: 1.0,
    specular: 0.0,
    specular_power: 1.0,
};
pub(super) const CT_AIR: SlicerPreset = SlicerPreset {
    scalar_opacity: &[[-3024.0, 0.705882], [-900.0, 0.715686], [-500.0, 0.0], [3071.0, 0.0]],
    gradient_opacity: &[[0.0, 1.0], [255.0, 1.0]],
    color: &[[-3024.0, 1.0, 1.0, 1.0], [-900.0, 0.2, 1.0, 1.0], [-500.0, 0.3, 0.3, 1.0], [3071.0, 0.0, 0.0, 0.0]],
    shade: true,
    ambient: 0.1,
    diffuse: 0.9,
    specular: 0.2,
    specular_power: 10.0,
};
pub(super) const CT_X_RAY: SlicerPreset = SlicerPreset {
    scalar_opacity: &[[-3024.0, 0.0], [-200.0, 0.0], [1500.0, 0.05], [3071.0, 0.05]],
    gradient_opacity: &[[0.0, 1.0], [255.0, 1.0]],
    color: &[[-3024.0, 1.0, 1.0, 1.0], [3071.0, 1.0, 1.0, 1.0]],
    shade: false,
    ambient: 0.1,
    diffuse: 0.9,
    specular: 0.2,
    specular_power: 10.0,
};
pub(super) const MR_ANGIO: SlicerPreset = SlicerPreset {
    scalar_opacity: &[[-2048.0, 0.0], [151.354, 0.0], [158.279, 0.4375], [190.112, 0.580357], [200.873, 0.732143], [3661.0, 0.741071]],
    gradient_opacity: &[[0.0, 1.0], [255.0, 1.0]],
    color: &[[-2048.0, 0.0, 0.0, 0.0], [151.354, 0.0, 0.0, 0.0], [158.279, 0.74902, 0.376471, 0.0], [190.112, 1.0, 0.866667, 0.733333], [200.873, 0.937255, 0.937255, 0.937255], [3661.0, 1.0, 1.0, 1.0]],
    shade: true,
    ambient: 0.2,
    diffuse: 1.0,
    specular: 0.0,
    specular_power: 1.0,
};
pub(super) const MR_DEFAULT: SlicerPreset = SlicerPreset {
    scalar_opacity: &[[0.0, 0.0], [20.0, 0.0], [40.0, 0.15], [120.0, 0.3], [220.0, 0.375], [1024.0, 0.5]],
    gradient_opacity: &[[0.0, 1.0], [255.0, 1.0]],
    color: &[[0.0, 0.0, 0.0, 0.0], [20.0, 0.168627, 0.0, 0.0], [40.0, 0.403922, 0.145098, 0.0784314], [120.0, 0.780392, 0.607843, 0.380392], [220.0, 0.847059, 0.835294, 0.788235], [1024.0, 1.0, 1.0, 1.0]],
    shade: true,
    ambient: 0.2,
    diffuse: 1.0,
    specular: 0.0,
    specular_power: 1.0,
};
pub(super) const MR_MIP: SlicerPreset = SlicerPreset {
    scalar_opacity: &[[0.0, 0.0], [98.3725, 0.0], [416.637, 1.0], [2800.0, 1.0]],
    gradient_opacity: &[[0.0, 1.0], [255.0, 1.0]],
    color: &[[0.0, 1.0, 1.0, 1.0], [98.3725, 1.0, 1.0, 1.0], [416.637, 1.0, 1.0, 1.0], [2800.0, 1.0, 1.0, 1.0]],
    shade: false,
    ambient: 0.2,
    diffuse: 1.0,
    specular: 0.0,
    specular_power: 1.0,
};
pub(super) const MR_T2_BRAIN: SlicerPreset = SlicerPreset {
    scalar_opacity: &[[0.0, 0.0], [36.05, 0.0], [218.302, 0.171429], [412.406, 1.0], [641.0, 1.0]],
    gradient_opacity: &[[0.0, 1.0], [160.25, 1.0]],
    color: &[[0.0, 0.0, 0.0, 0.0], [98.7223, 0.956863, 0.839216, 0.192157], [412.406, 0.0, 0.592157, 0.807843], [641.0, 1.0, 1.0, 1.0]],
    shade: true,
    ambient: 0.3,
    diffuse: 0.6,
    specular: 0.5,
    specular_power: 40.0,
};
pub(super) const DTI_FA_BRAIN: SlicerPreset = SlicerPreset {
    scalar_opacity: &[[0.0, 0.0], [0.0, 0.0], [0.3501, 0.0158], [0.49379, 0.7619], [0.6419, 1.0], [0.9920, 1.0], [0.9950, 0.0], [0.9950, 0.0]],
    gradient_opacity: &[[0.0, 1.0], [0.9950, 1.0]],
    color: &[[0.0, 1.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.24974, 0.4941, 1.0, 0.0], [0.49949, 0.0, 0.9882, 1.0], [0.7492, 0.51764, 0.0, 1.0], [0.9950, 1.0, 0.0, 0.0], [0.9950, 1.0, 0.0, 0.0]],
    shade: true,
    ambient: 0.3,
    diffuse: 0.9,
    specular: 0.5,
    specular_power: 40.0,
};
pub(super) const US_FETAL: SlicerPreset = SlicerPreset {
    scalar_opacity: &[[-10.0, 0.0], [60.0, 0.0], [120.0, 0.6], [255.0, 0.8], [270.0, 0.8]],
    gradient_opacity: &[[-10.0, 0.0], [-1.0, 1.0], [20.0, 1.0], [90.0, 1.0]],
    color: &[[-10.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0], [80.0, 0.54902, 0.25098, 0.14902], [102.0, 0.882353, 0.603922, 0.290196], [270.0, 0.694, 0.478, 0.396]],
    shade: true,
    ambient: 0.1,
    diffuse: 0.9,
    specular: 0.2,
    specular_power: 10.0,
};
pub(super) const UCT_BONE_8BIT: SlicerPreset = SlicerPreset {
    scalar_opacity: &[[58.5999794006348, 0.0], [58.5999794006348, 0.0], [157.723983764648, 1.0], [313.599822998047, 1.0]],
    gradient_opacity: &[[58.5999794006348, 1.0], [313.599822998047, 1.0]],
    color: &[[58.5999794006348, 0.0, 0.0, 0.0], [58.5999794006348, 0.0, 0.0, 0.0], [76.7996444702148, 0.913725490196078, 0.164705882352941, 0.113725490196078], [85.1535949707031, 0.858823529411765, 0.498039215686275, 0.137254901960784], [94.7009582519531, 0.96078431372549, 0.933333333333333, 0.105882352941176], [100.369705200195, 1.0, 1.0, 1.0], [313.599822998047, 1.0, 1.0, 1.0]],
    shade: true,
    ambient: 0.3,
    diffuse: 0.6,
    specular: 0.2,
    specular_power: 40.0,
};
pub(super) const UCT_BONE_16BIT: SlicerPreset = SlicerPreset {
    scalar_opacity: &[[33600.0, 0.0], [33600.0, 0.0], [59866.8515625, 1.0], [99135.0, 1.0]],
    gradient_opacity: &[[33600.0, 1.0], [99135.0, 1.0]],
    color: &[[33600.0, 0.0, 0.0, 0.0], [33600.0, 0.0, 0.0, 0.0], [37880.9140625, 0.913725490196078, 0.164705882352941, 0.113725490196078], [40312.05078125, 0.858823529411765, 0.498039215686275, 0.137254901960784], [42848.890625, 0.96078431372549, 0.933333333333333, 0.105882352941176], [45280.02734375, 1.0, 1.0, 1.0], [99135.0, 1.0, 1.0, 1.0]],
    shade: true,
    ambient: 0.3,
    diffuse: 0.6,
    specular: 0.2,
    specular_power: 40.0,
};
pub(super) const UCT_SKULL: SlicerPreset = SlicerPreset {
    scalar_opacity: &[[0.0, 0.0], [25.0, 0.0], [72.3597412109375, 1.0], [236.931869506836, 1.0], [806.920776367188, 1.0], [1024.0, 1.0]],
    gradient_opacity: &[[0.0, 1.0], [0.0, 1.0], [46.9644546508789, 0.1], [128.360549926758, 1.0], [255.0, 1.0]],
    color: &[[0.0, 0.0, 0.0, 0.0], [43.8543891906738, 0.780392156862745, 0.462745098039216, 0.188235294117647], [114.021408081055, 0.982130513713827, 0.96809021468468, 0.94958254408399], [1024.0, 1.0, 1.0, 1.0]],
    shade: true,
    ambient: 0.1,
    diffuse: 0.9,
    specular: 0.2,
    specular_power: 10.0,
};
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::volume::{Grid, Volume};

    #[test]
    fn every_preset_validates_with_ordered_points_and_unit_opacities() {
        for p in Preset::ALL {
            for range in [(0.0, 255.0), (-1024.0, 3071.0), (0.0, 1.0)] {
                let mut tf = p.transfer_function(range);
                tf.validate().unwrap_or_else(|e| panic!("{p}: {e}"));
                for w in tf.scalar_opacity.windows(2) {
                    assert!(w[0][0] <= w[1][0], "{p}: {w:?}");
                }
                for w in tf.color.windows(2) {
                    assert!(w[0][0] <= w[1][0], "{p}: {w:?}");
                }
                assert!(
                    tf.scalar_opacity
                        .iter()
                        .all(|q| (0.0..=1.0).contains(&q[1]))
                );
                crate::CrioTables::from_transfer_function(&tf, 256).unwrap();
            }
            assert!(!p.description().is_empty() && !p.description().contains('\n'));
            assert!(!p.units().is_empty());
        }
        assert_eq!(Preset::ALL.len(), Preset::NAMES.len());
        assert_eq!(Preset::ALL.iter().filter(|p| p.is_slicer()).count(), 31);
    }

    #[test]
    fn names_round_trip_in_any_case_and_aliases_keep_working() {
        for (n, p) in Preset::ALL.iter().enumerate() {
            assert_eq!(p.name(), Preset::NAMES[n]);
            assert_eq!(p.to_string().parse::<Preset>().unwrap(), *p);
            assert_eq!(p.name().to_uppercase().parse::<Preset>().unwrap(), *p);
            assert_eq!(p.name().to_lowercase().parse::<Preset>().unwrap(), *p);
        }
        assert_eq!(TransferFunction::PRESETS, &Preset::NAMES[..]);
        // The names of volsplat's first presets.
        assert_eq!("ct-bone".parse::<Preset>().unwrap(), Preset::CtBone);
        assert_eq!("ct-skin".parse::<Preset>().unwrap(), Preset::CtSkin);
        assert_eq!("mr".parse::<Preset>().unwrap(), Preset::MrDefault);
        assert_eq!("ramp".parse::<Preset>().unwrap(), Preset::Ramp);
        assert_eq!(
            "ct_chest_contrast".parse::<Preset>().unwrap(),
            Preset::CtChestContrastEnhanced
        );
        assert_eq!(" CT-X-RAY ".parse::<Preset>().unwrap(), Preset::CtXRay);
        let e = "ct-bonez".parse::<Preset>().unwrap_err().to_string();
        for name in Preset::NAMES {
            assert!(e.contains(name), "{name} missing from: {e}");
        }
        assert!(
            e.contains("ct-bonez") && e.contains("mr = MR-Default"),
            "{e}"
        );
    }

    /// The aliases give the same functions as volsplat's presets of the same name did before
    /// Slicer's were added (values copied from the earlier `TransferFunction::preset`).
    #[test]
    fn old_preset_names_give_the_old_functions() {
        let range = (-500.0, 900.0);
        let bone = TransferFunction::preset("ct-bone", range).unwrap();
        assert_eq!(
            bone.scalar_opacity,
            [
                [-3024.0, 0.0],
                [-16.4458, 0.0],
                [641.385, 0.715686],
                [3071.0, 0.705882]
            ]
        );
        assert_eq!(bone.color[1], [-16.4458, 0.729412, 0.254902, 0.301961]);
        assert_eq!(
            (bone.shade, bone.ambient, bone.diffuse, bone.specular),
            (true, 0.1, 0.9, 0.2)
        );
        let mr = TransferFunction::preset("mr", range).unwrap();
        assert_eq!(
            mr.scalar_opacity,
            [
                [0.0, 0.0],
                [20.0, 0.0],
                [40.0, 0.15],
                [120.0, 0.3],
                [220.0, 0.375],
                [1024.0, 0.5]
            ]
        );
        assert_eq!(mr.color[3], [120.0, 0.780392, 0.607843, 0.380392]);
        assert_eq!(
            (mr.ambient, mr.diffuse, mr.specular, mr.specular_power),
            (0.2, 1.0, 0.0, 1.0)
        );
        let skin = TransferFunction::preset("ct-skin", range).unwrap();
        assert_eq!(skin.scalar_opacity[4], [500.0, 0.6]);
        assert_eq!(skin.specular_power, 15.0);
        assert_eq!(
            TransferFunction::preset("ramp", range).unwrap(),
            TransferFunction::ramp(-500.0, 900.0, 0.5)
        );
        for tf in [&bone, &mr, &skin] {
            assert_eq!(tf.gradient_opacity, None);
            assert_eq!(tf.scalar_opacity_unit_distance, 1.0);
        }
    }

    /// Spot checks against `presets.xml` (values typed from the file, not from the table).
    #[test]
    fn control_points_match_slicer_presets_xml() {
        let tf = |p: Preset| p.transfer_function((0.0, 1.0));
        // CT-AAA: scalarOpacity="12 -3024 0 143.556 0 166.222 0.686275 ..."
        let aaa = tf(Preset::CtAaa);
        assert_eq!(aaa.scalar_opacity.len(), 6);
        assert_eq!(aaa.scalar_opacity[2], [166.222, 0.686275]);
        assert_eq!(aaa.color[5], [3071.0, 0.827451, 0.658824, 1.0]);
        // CT-Lung: colorTransfer="24 ... -530 0.134704 0.781726 0.0724558 ...", steps at -600/-599.
        let lung = tf(Preset::CtLung);
        assert_eq!(lung.color[2], [-530.0, 0.134704, 0.781726, 0.0724558]);
        assert_eq!(&lung.scalar_opacity[1..3], &[[-600.0, 0.0], [-599.0, 0.15]]);
        assert_eq!((lung.ambient, lung.diffuse, lung.specular), (0.2, 1.0, 0.0));
        // CT-Fat: 7 opacity points, 9 colours, unshaded.
        let fat = tf(Preset::CtFat);
        assert_eq!((fat.scalar_opacity.len(), fat.color.len()), (7, 9));
        assert_eq!(fat.color[8], [2952.0, 1.0, 0.300267, 0.299886]);
        assert!(!fat.shade);
        // CT-Coronary-Arteries: unshaded, last opacity point 3661 → 1.
        let cor = tf(Preset::CtCoronaryArteries);
        assert!(!cor.shade);
        assert_eq!(cor.scalar_opacity[5], [3661.0, 1.0]);
        // CT-Air: opaque air, transparent above -500.
        let air = tf(Preset::CtAir);
        assert_eq!(air.scalar_opacity[1], [-900.0, 0.715686]);
        assert_eq!(air.opacity_at(0.0), 0.0);
        // MR-T2-Brain: specular 0.5, power 40, ambient 0.3, diffuse 0.6.
        let t2 = tf(Preset::MrT2Brain);
        assert_eq!(
            (t2.ambient, t2.diffuse, t2.specular, t2.specular_power),
            (0.3, 0.6, 0.5, 40.0)
        );
        assert_eq!(t2.color[2], [412.406, 0.0, 0.592157, 0.807843]);
        // DTI-FA-Brain: "16 0 0 0 0 0.3501 0.0158 ... 0.9920 1 0.9950 0 0.9950 0".
        let fa = tf(Preset::DtiFaBrain);
        assert_eq!(fa.scalar_opacity.len(), 8);
        assert_eq!(
            &fa.scalar_opacity[5..],
            &[[0.9920, 1.0], [0.9950, 0.0], [0.9950, 0.0]]
        );
        // uCT-Bone-16bit.
        let u16b = tf(Preset::UctBone16bit);
        assert_eq!(u16b.scalar_opacity[2], [59866.8515625, 1.0]);
        // Gradient opacity: only uCT-Skull's differs from 1 at magnitudes ≥ 0.
        for p in Preset::ALL {
            assert_eq!(
                tf(p).gradient_opacity.is_some(),
                p == Preset::UctSkull,
                "{p}"
            );
        }
        let skull = tf(Preset::UctSkull).gradient_opacity.unwrap();
        assert_eq!(skull.len(), 5);
        assert_eq!(skull[2], [46.9644546508789, 0.1]);
    }

    #[test]
    fn range_warnings_say_when_a_preset_misses_the_data() {
        assert_eq!(
            Preset::CtBone.visible_range((0.0, 1.0)),
            Some((-16.4458, f64::INFINITY))
        );
        assert_eq!(
            Preset::CtLung.visible_range((0.0, 1.0)),
            Some((-600.0, -399.0))
        );
        assert_eq!(
            Preset::CtAir.visible_range((0.0, 1.0)),
            Some((f64::NEG_INFINITY, -500.0))
        );
        assert_eq!(Preset::CtBone.range_warning((-1024.0, 3071.0)), None);
        assert_eq!(Preset::MrDefault.range_warning((0.0, 255.0)), None);
        assert_eq!(Preset::Ramp.range_warning((3.0, 7.0)), None);
        // A CT lung preset on 8-bit MR data: nothing visible.
        let w = Preset::CtLung.range_warning((0.0, 255.0)).unwrap();
        assert!(w.contains("empty") && w.contains("HU"), "{w}");
        // MR-Default on data below its first visible value.
        assert!(Preset::MrDefault.range_warning((0.0, 10.0)).is_some());
        // Data beyond the last point: a uniform block.
        let w = Preset::CtBone.range_warning((4000.0, 5000.0)).unwrap();
        assert!(w.contains("same colour"), "{w}");
    }

    #[test]
    fn histogram_bins_integers_exactly_and_clamps() {
        let mut h = Histogram::for_scalar_type(ScalarType::U8, (0.0, 255.0)).unwrap();
        assert_eq!(h.counts().len(), 256);
        assert_eq!(h.bin_width(), 1.0);
        for v in [0.0, 1.0, 1.0, 255.0, 300.0, -5.0, f64::NAN] {
            h.add(v);
        }
        assert_eq!(h.total(), 6);
        assert_eq!(h.counts()[0], 2);
        assert_eq!(h.counts()[1], 2);
        assert_eq!(h.counts()[255], 2);
        assert_eq!(h.bin_center(1), 1.0);
        assert_eq!(h.quantile(0.5), Some(1.0));
        assert_eq!(h.quantile(1.0), Some(255.0));
        let h = Histogram::for_scalar_type(ScalarType::I16, (-32768.0, 32767.0)).unwrap();
        assert_eq!(h.counts().len(), Histogram::MAX_BINS);
        assert_eq!(h.bin_center(0), -32768.0);
        let h = Histogram::for_scalar_type(ScalarType::F32, (-1.0, 1.0)).unwrap();
        assert_eq!(h.counts().len(), Histogram::FLOAT_BINS);
        assert!(Histogram::new(1.0, 0.0, 4).is_err());
        assert!(Histogram::new(0.0, f64::INFINITY, 4).is_err());
        assert!(Histogram::new(0.0, 1.0, 0).is_err());
        let mut one = Histogram::new(5.0, 5.0, 1).unwrap();
        one.add(7.0);
        assert_eq!((one.total(), one.quantile(0.5)), (1, Some(5.0)));
        let vol = AnyVolume::from(
            Volume::from_fn(Grid::with_dims([4, 3, 2]).unwrap(), |i, j, k| {
                (i + 4 * j + 12 * k) as i16 - 10
            })
            .unwrap(),
        );
        let h = Histogram::from_volume(&vol);
        assert_eq!(h.counts().len(), 24);
        assert!(h.counts().iter().all(|&c| c == 1));
    }

    /// A histogram of integer values from `(value, count)` pairs.
    fn hist(pairs: &[(i32, u64)]) -> Histogram {
        let lo = pairs.iter().map(|p| p.0).min().unwrap_or(0) as f64;
        let hi = pairs.iter().map(|p| p.0).max().unwrap_or(0) as f64;
        let mut h = Histogram::for_scalar_type(ScalarType::I16, (lo, hi)).unwrap();
        for &(v, n) in pairs {
            for _ in 0..n {
                h.add(v as f64);
            }
        }
        h
    }

    /// A bell of counts `peak·exp(−((v−mean)/sd)²/2)` over mean ± 4 sd.
    fn bell(mean: i32, sd: i32, peak: f64) -> Vec<(i32, u64)> {
        (mean - 4 * sd..=mean + 4 * sd)
            .map(|v| {
                let z = (v - mean) as f64 / sd as f64;
                (v, (peak * (-0.5 * z * z).exp()).round() as u64)
            })
            .collect()
    }

    #[test]
    fn auto_finds_background_fill_values_and_their_absence() {
        // CT-like: air around −1000, tissue around 40, some bone.
        let mut ct = bell(-1000, 20, 500.0);
        ct.extend(bell(40, 20, 400.0));
        ct.extend(bell(900, 150, 20.0));
        let a = AutoTransfer::from_histogram(&hist(&ct));
        assert_eq!((a.rule, a.fill_value), (BackgroundRule::Otsu, None));
        assert!(a.threshold > -950.0 && a.threshold < -100.0, "{a:?}");
        let tf = &a.transfer_function;
        assert_eq!(tf.opacity_at(-1000.0), 0.0);
        assert_eq!(tf.opacity_at(a.threshold), 0.0);
        assert!(tf.opacity_at(40.0) > 0.2, "{}", tf.opacity_at(40.0));
        // The same with padding at −3024 outside the field of view.
        let mut padded = ct.clone();
        padded.push((-3024, 200_000));
        let b = AutoTransfer::from_histogram(&hist(&padded));
        assert_eq!(
            (b.rule, b.fill_value),
            (BackgroundRule::Otsu, Some(-3024.0))
        );
        assert!((b.threshold - a.threshold).abs() < 50.0, "{a:?} {b:?}");
        assert_eq!(b.transfer_function.opacity_at(-1000.0), 0.0);
        // A masked object: fill value 0, then one tissue with no background of its own.
        let mut masked = bell(120, 25, 300.0);
        masked.push((0, 100_000));
        let c = AutoTransfer::from_histogram(&hist(&masked));
        assert_eq!(
            (c.rule, c.fill_value),
            (BackgroundRule::FillValue, Some(0.0)),
            "{c:?}"
        );
        assert_eq!(c.threshold, 0.5);
        assert!(c.transfer_function.opacity_at(60.0) > 0.1);
        // One tissue, no background at all: everything above the minimum is shown.
        let d = AutoTransfer::from_histogram(&hist(&bell(120, 25, 300.0)));
        assert_eq!((d.rule, d.fill_value), (BackgroundRule::None, None));
        // (the bell's lowest occupied value: counts below 31 round to zero)
        assert_eq!(d.threshold, 31.0);
        assert!(d.transfer_function.opacity_at(100.0) > 0.1);
        // A label image: 0 and one value.
        let e = AutoTransfer::from_histogram(&hist(&[(0, 1000), (7, 50)]));
        assert_eq!(e.rule, BackgroundRule::FillValue);
        assert_eq!(e.transfer_function.opacity_at(0.0), 0.0);
        assert!(e.transfer_function.opacity_at(7.0) > 0.3);
        // Degenerate: one value, or nothing.
        let f = AutoTransfer::from_histogram(&hist(&[(5, 10)]));
        assert_eq!(f.rule, BackgroundRule::Degenerate);
        let g = AutoTransfer::from_histogram(&Histogram::new(0.0, 1.0, 8).unwrap());
        assert_eq!(g.rule, BackgroundRule::Degenerate);
        for x in [&a, &b, &c, &d, &e, &f, &g] {
            x.transfer_function.clone().validate().unwrap();
            assert!(x.describe().starts_with("automatic transfer function"));
        }
        // Deterministic.
        assert_eq!(AutoTransfer::from_histogram(&hist(&padded)), b);
    }

    /// Rule step 4 (issue 28 §6): a binary mask's one foreground value and a label image's few
    /// are opaque from halfway across the background–label step, each in its own colour; nine
    /// distinct foreground values take the percentile ramp. Step 5: one value shows.
    #[test]
    fn masks_and_label_images_are_opaque_and_constant_data_shows() {
        let mask = AutoTransfer::from_histogram(&hist(&[(0, 50_000), (1, 4_000)]));
        assert_eq!(mask.rule, BackgroundRule::FillValue);
        assert_eq!(mask.labels, vec![1.0]);
        let tf = &mask.transfer_function;
        assert_eq!(tf.opacity_at(0.0), 0.0);
        assert_eq!(tf.opacity_at(0.5), 0.0);
        assert_eq!(tf.opacity_at(0.75), AutoTransfer::FEW_OPACITY);
        assert_eq!(tf.opacity_at(1.0), AutoTransfer::FEW_OPACITY);
        assert!(tf.opacity_at(0.6) > 0.2 && tf.opacity_at(0.6) < 0.5);
        let ivory = AutoTransfer::LABEL_COLORS[0];
        assert_eq!(tf.color_at(1.0), ivory);
        // The colour does not darken towards the background where the opacity rises.
        assert_eq!(tf.color_at(0.6), ivory);
        assert!(mask.describe().contains("1 foreground value (1) opaque"));
        // A label image: background 0 and labels 3, 5, 9 of different sizes.
        let labels =
            AutoTransfer::from_histogram(&hist(&[(0, 90_000), (3, 500), (5, 9_000), (9, 40)]));
        assert_eq!(labels.labels, vec![3.0, 5.0, 9.0]);
        let tf = &labels.transfer_function;
        for (n, v) in [3.0, 5.0, 9.0].into_iter().enumerate() {
            assert_eq!(tf.opacity_at(v), AutoTransfer::FEW_OPACITY);
            assert_eq!(tf.color_at(v), AutoTransfer::LABEL_COLORS[n]);
        }
        assert_eq!(tf.opacity_at(0.0), 0.0);
        // Nine foreground values: the percentile ramp, as before.
        let nine: Vec<(i32, u64)> = (0..10)
            .map(|v| (v * 10, if v == 0 { 9_000 } else { 100 }))
            .collect();
        let ramp = AutoTransfer::from_histogram(&hist(&nine));
        assert!(ramp.labels.is_empty());
        assert!(ramp.transfer_function.opacity_at(10.0) <= 0.15 + 1e-12);
        // Float masks: 4096 bins over [0, 1]; the value 1 lies beyond the last bin's centre.
        let mut h = Histogram::for_scalar_type(ScalarType::F32, (0.0, 1.0)).unwrap();
        for n in 0..10_000 {
            h.add(if n % 5 == 0 { 1.0 } else { 0.0 });
        }
        let f = AutoTransfer::from_histogram(&h);
        assert_eq!(f.labels.len(), 1);
        assert_eq!(
            f.transfer_function.opacity_at(1.0),
            AutoTransfer::FEW_OPACITY
        );
        assert_eq!(f.transfer_function.opacity_at(0.0), 0.0);
        // One value (constant data): opacity 0.5 at it, white; the empty histogram as before.
        let one = AutoTransfer::from_histogram(&hist(&[(40, 1000)]));
        assert_eq!(one.rule, BackgroundRule::Degenerate);
        assert_eq!(one.transfer_function.opacity_at(40.0), 0.5);
        assert_eq!(one.transfer_function.color_at(40.0), [1.0; 3]);
        let empty = AutoTransfer::from_histogram(&Histogram::new(0.0, 1.0, 8).unwrap());
        assert_eq!(
            empty.transfer_function,
            Preset::Ramp.transfer_function((0.0, 1.0))
        );
        for x in [&mask, &labels, &ramp, &f, &one, &empty] {
            x.transfer_function.clone().validate().unwrap();
        }
    }

    #[test]
    fn auto_from_volume_uses_the_smallest_spacing_as_unit_distance() {
        let mut grid = Grid::with_dims([8, 8, 8]).unwrap();
        grid.spacing = [0.5, 0.25, 2.0];
        let vol = Volume::from_fn(grid, |i, j, k| {
            if (3..5).contains(&i) && (3..5).contains(&j) && (3..5).contains(&k) {
                200u8
            } else {
                (i + j + k) as u8 % 3
            }
        })
        .unwrap();
        let vol = AnyVolume::from(vol);
        let tf = TransferFunction::auto_from_volume(&vol);
        assert_eq!(tf.scalar_opacity_unit_distance, 0.25);
        assert_eq!(tf.opacity_at(2.0), 0.0);
        assert!(tf.opacity_at(200.0) > 0.3);
        let h = Histogram::from_volume(&vol);
        assert_eq!(
            TransferFunction::auto_from_histogram(&h).scalar_opacity,
            tf.scalar_opacity
        );
    }
}
