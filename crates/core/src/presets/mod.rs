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

mod auto;
pub use auto::{AutoTransfer, BackgroundRule, Histogram};

/// 3D Slicer's volume-rendering presets (generated; see the file).
#[rustfmt::skip]
mod slicer_table;

#[cfg(test)]
mod tests;
