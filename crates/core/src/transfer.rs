//! Transfer functions in VTK's terms (`vtkVolumeProperty`); built-in presets and the automatic
//! transfer function are in [`crate::presets`].
//!
//! A [`TransferFunction`] is what users write in a transfer-function JSON file (docs/design.md §3):
//! piecewise-linear colour and scalar-opacity points over the data's own units, optional
//! gradient-opacity points over gradient magnitude (data units per world unit), shading
//! coefficients, and `scalar_opacity_unit_distance`. It compiles into Westover's four CRIO tables
//! with [`crate::crio::CrioTables::from_transfer_function`].

use crate::error::{CoreError, Result};
use crate::presets::{AutoTransfer, Histogram, Preset};
use crate::volume::AnyVolume;
use serde::{Deserialize, Serialize};

fn one() -> f64 {
    1.0
}
fn default_diffuse() -> f64 {
    0.7
}
fn default_specular() -> f64 {
    0.2
}
fn default_specular_power() -> f64 {
    10.0
}

/// A VTK-style volume property. Values (`x` of every point) are in the data's own units, e.g.
/// Hounsfield units for CT.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TransferFunction {
    /// Colour points `[value, r, g, b]`, colour components in [0, 1]. At least one point.
    pub color: Vec<[f64; 4]>,
    /// Scalar-opacity points `[value, alpha]`, alpha in [0, 1] for a path of
    /// `scalar_opacity_unit_distance`. At least one point.
    pub scalar_opacity: Vec<[f64; 2]>,
    /// Optional gradient-opacity points `[gradient magnitude, factor]`, magnitude in data units
    /// per world unit, factor in [0, 1]; multiplies the (step-corrected) scalar opacity.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gradient_opacity: Option<Vec<[f64; 2]>>,
    /// Path length in world units for which `scalar_opacity` is defined (> 0); opacity is
    /// corrected for the actual step Δs as `α' = 1 − (1 − α)^(Δs/unit)`. VTK's default is 1.
    #[serde(default = "one")]
    pub scalar_opacity_unit_distance: f64,
    /// Whether gradient (Phong/Blinn) shading is applied.
    #[serde(default)]
    pub shade: bool,
    /// Ambient coefficient in [0, 1] (VTK default 0).
    #[serde(default)]
    pub ambient: f64,
    /// Diffuse coefficient in [0, 1] (VTK default 0.7).
    #[serde(default = "default_diffuse")]
    pub diffuse: f64,
    /// Specular coefficient in [0, 1] (VTK default 0.2).
    #[serde(default = "default_specular")]
    pub specular: f64,
    /// Specular exponent ≥ 0 (VTK default 10).
    #[serde(default = "default_specular_power")]
    pub specular_power: f64,
}

/// The field names a transfer-function file may contain (others are ignored with a warning).
pub const TRANSFER_FUNCTION_FIELDS: &[&str] = &[
    "color",
    "scalar_opacity",
    "gradient_opacity",
    "scalar_opacity_unit_distance",
    "shade",
    "ambient",
    "diffuse",
    "specular",
    "specular_power",
];

/// Largest magnitude of a point's value (entry 0) in a transfer function, in data units (or
/// data units per world unit for gradient opacity): `1e38`, so that every value and the span
/// between any two (`≤ 2e38`) are finite `f32` numbers and the CRIO lookup tables built from
/// them hold no NaN. Larger values are an error naming the point.
pub const MAX_POINT_VALUE: f64 = 1e38;

/// Evaluates a piecewise-linear function given by points `(x, y…)` sorted by x; values outside
/// the points' range are clamped to the end points (VTK's default clamping).
pub fn piecewise_linear<const N: usize>(points: &[(f64, [f64; N])], x: f64) -> [f64; N] {
    let Some(first) = points.first() else {
        return [0.0; N];
    };
    if x <= first.0 || x.is_nan() {
        return first.1;
    }
    let last = points[points.len() - 1];
    if x >= last.0 {
        return last.1;
    }
    // First point with p.x > x; it exists and is not the first.
    let hi = points.partition_point(|p| p.0 <= x);
    let (x0, y0) = points[hi - 1];
    let (x1, y1) = points[hi];
    let t = if x1 > x0 { (x - x0) / (x1 - x0) } else { 1.0 };
    let mut out = [0.0; N];
    for c in 0..N {
        out[c] = y0[c] + t * (y1[c] - y0[c]);
    }
    out
}

/// Interpolates rows `[x, y₁, y₂, …]` sorted by `x` at `x` (clamped at the ends, like
/// [`piecewise_linear`]) without allocating; column 0 of the result is `x` itself. Empty input
/// gives zeros.
pub fn interpolate_rows<const M: usize>(rows: &[[f64; M]], x: f64) -> [f64; M] {
    let (Some(first), Some(last)) = (rows.first(), rows.last()) else {
        return [0.0; M];
    };
    if x <= first[0] || x.is_nan() {
        return *first;
    }
    if x >= last[0] {
        return *last;
    }
    let hi = rows.partition_point(|r| r[0] <= x);
    let (a, b) = (rows[hi - 1], rows[hi]);
    let t = if b[0] > a[0] {
        (x - a[0]) / (b[0] - a[0])
    } else {
        1.0
    };
    let mut out = [0.0; M];
    for c in 0..M {
        out[c] = a[c] + t * (b[c] - a[c]);
    }
    out
}

impl TransferFunction {
    /// Checks every field. Errors name the field and the point index. Point values (entry 0)
    /// must be finite and within ±[`MAX_POINT_VALUE`]; colour and opacity entries in [0, 1]. Each point list must be in
    /// non-decreasing order of value (equal consecutive values make a step, kept in the order
    /// written); points out of order are an error rather than sorted, so that a mistyped value
    /// is not silently moved elsewhere in the function.
    pub fn validate(&mut self) -> Result<()> {
        if self.color.is_empty() {
            return Err(CoreError::invalid(
                "color",
                "[]",
                "needs at least one point",
            ));
        }
        if self.scalar_opacity.is_empty() {
            return Err(CoreError::invalid(
                "scalar_opacity",
                "[]",
                "needs at least one point",
            ));
        }
        for (n, p) in self.color.iter().enumerate() {
            check_point(&format!("color[{n}]"), p)?;
        }
        check_order("color", &self.color)?;
        for (n, p) in self.scalar_opacity.iter().enumerate() {
            check_point(&format!("scalar_opacity[{n}]"), p)?;
        }
        check_order("scalar_opacity", &self.scalar_opacity)?;
        if let Some(g) = &self.gradient_opacity {
            if g.is_empty() {
                return Err(CoreError::invalid(
                    "gradient_opacity",
                    "[]",
                    "needs at least one point (or leave the field out)",
                ));
            }
            for (n, p) in g.iter().enumerate() {
                check_point(&format!("gradient_opacity[{n}]"), p)?;
            }
            check_order("gradient_opacity", g)?;
        }
        let positive = [(
            "scalar_opacity_unit_distance",
            self.scalar_opacity_unit_distance,
        )];
        for (name, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(CoreError::invalid(
                    name,
                    v,
                    "must be a positive finite number (world units)",
                ));
            }
        }
        for (name, v) in [
            ("ambient", self.ambient),
            ("diffuse", self.diffuse),
            ("specular", self.specular),
        ] {
            if !(0.0..=1.0).contains(&v) {
                return Err(CoreError::invalid(name, v, "must be in [0, 1]"));
            }
        }
        if !(self.specular_power.is_finite() && self.specular_power >= 0.0) {
            return Err(CoreError::invalid(
                "specular_power",
                self.specular_power,
                "must be ≥ 0",
            ));
        }
        Ok(())
    }

    /// Colour (r, g, b in [0, 1]) at a data value.
    pub fn color_at(&self, value: f64) -> [f64; 3] {
        let r = interpolate_rows(&self.color, value);
        [r[1], r[2], r[3]]
    }

    /// Scalar opacity (per unit distance) at a data value.
    pub fn opacity_at(&self, value: f64) -> f64 {
        interpolate_rows(&self.scalar_opacity, value)[1]
    }

    /// Gradient-opacity factor at a gradient magnitude (1 when there is no gradient opacity).
    pub fn gradient_opacity_at(&self, magnitude: f64) -> f64 {
        match &self.gradient_opacity {
            None => 1.0,
            Some(g) => interpolate_rows(g, magnitude)[1],
        }
    }

    /// A grey ramp over `[lo, hi]` (data units; `hi ≤ lo` is taken as `lo + 1`): colour black →
    /// white, opacity 0 → `max_opacity` (in [0, 1]), unshaded. The `ramp` preset uses 0.5.
    pub fn ramp(lo: f64, hi: f64, max_opacity: f64) -> Self {
        let hi = if hi > lo { hi } else { lo + 1.0 };
        TransferFunction {
            color: vec![[lo, 0.0, 0.0, 0.0], [hi, 1.0, 1.0, 1.0]],
            scalar_opacity: vec![[lo, 0.0], [hi, max_opacity]],
            gradient_opacity: None,
            scalar_opacity_unit_distance: 1.0,
            shade: false,
            ambient: 0.0,
            diffuse: 0.7,
            specular: 0.2,
            specular_power: 10.0,
        }
    }

    /// Names of the built-in presets ([`Preset::NAMES`]): 3D Slicer's volume-rendering presets
    /// and volsplat's `ct-skin` and `ramp`.
    pub const PRESETS: &'static [&'static str] = &Preset::NAMES;

    /// A built-in preset by name or alias, matched case-insensitively (see [`Preset`]; `ct-bone`,
    /// `ct-skin`, `mr` and `ramp` keep working). Control points are in the preset's own units
    /// ([`Preset::units`]: Hounsfield units for CT); only `ramp` depends on `data_range`
    /// (smallest and largest sample, data units), which it spans. An unknown name is
    /// [`CoreError::UnknownName`] listing every name.
    pub fn preset(name: &str, data_range: (f64, f64)) -> Result<Self> {
        Ok(name.parse::<Preset>()?.transfer_function(data_range))
    }

    /// The automatic transfer function for a histogram of the data (values in data units):
    /// background transparent, opacity and colour ramped over robust percentiles of the rest.
    /// See [`AutoTransfer`] for the rule; `scalar_opacity_unit_distance` is 1 world unit.
    pub fn auto_from_histogram(histogram: &Histogram) -> Self {
        AutoTransfer::from_histogram(histogram).transfer_function
    }

    /// The automatic transfer function of a volume ([`AutoTransfer::from_volume`]): as
    /// [`TransferFunction::auto_from_histogram`] of all its samples, with
    /// `scalar_opacity_unit_distance` the smallest voxel spacing (world units).
    pub fn auto_from_volume(volume: &AnyVolume) -> Self {
        AutoTransfer::from_volume(volume).transfer_function
    }
}

/// The first point of `points` whose value (entry 0) is less than its predecessor's is an error
/// naming `field[index]`, the value and the predecessor's value. Equal values are allowed.
fn check_order<const N: usize>(field: &str, points: &[[f64; N]]) -> Result<()> {
    for (n, w) in points.windows(2).enumerate() {
        let (prev, x) = (w[0][0], w[1][0]);
        if x < prev {
            return Err(CoreError::invalid(
                format!("{field}[{}]", n + 1),
                w[1],
                format!(
                    "value {x} is less than the value {prev} of {field}[{n}]; points must be in \
                     non-decreasing order of value (equal values make a step)"
                ),
            ));
        }
    }
    Ok(())
}

fn check_point<const N: usize>(field: &str, p: &[f64; N]) -> Result<()> {
    if p.iter().any(|v| !v.is_finite()) {
        return Err(CoreError::invalid(field, p, "all entries must be finite"));
    }
    if p[0].abs() > MAX_POINT_VALUE {
        return Err(CoreError::invalid(
            field,
            p,
            format!(
                "the value {} is outside ±{MAX_POINT_VALUE:e}: lookup tables are built in f32 \
                 over the span between the first and last points, which must stay finite",
                p[0]
            ),
        ));
    }
    if p[1..].iter().any(|v| !(0.0..=1.0).contains(v)) {
        return Err(CoreError::invalid(
            field,
            p,
            "colour and opacity entries must be in [0, 1]",
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn piecewise_interpolates_and_clamps() {
        let pts = [(0.0, [0.0]), (10.0, [1.0]), (20.0, [0.5])];
        assert_eq!(piecewise_linear(&pts, -5.0), [0.0]);
        assert_eq!(piecewise_linear(&pts, 5.0), [0.5]);
        assert_eq!(piecewise_linear(&pts, 15.0), [0.75]);
        assert_eq!(piecewise_linear(&pts, 25.0), [0.5]);
        assert_eq!(piecewise_linear(&pts, 10.0), [1.0]);
    }

    #[test]
    fn json_defaults_follow_vtk() {
        let mut tf: TransferFunction =
            serde_json::from_str(r#"{"color": [[0,1,1,1]], "scalar_opacity": [[0,0],[10,0.5]]}"#)
                .unwrap();
        tf.validate().unwrap();
        assert_eq!(tf.scalar_opacity_unit_distance, 1.0);
        assert_eq!(
            (tf.ambient, tf.diffuse, tf.specular, tf.specular_power),
            (0.0, 0.7, 0.2, 10.0)
        );
        assert!(!tf.shade);
        assert_eq!(tf.opacity_at(5.0), 0.25);
    }

    #[test]
    fn points_out_of_order_are_an_error_and_steps_are_allowed() {
        let mut tf = TransferFunction::ramp(0.0, 1.0, 0.5);
        tf.scalar_opacity = vec![[0.0, 0.0], [10.0, 0.5], [3.0, 0.1]];
        let e = tf.validate().unwrap_err().to_string();
        assert!(
            e.contains("scalar_opacity[2]") && e.contains("value 3") && e.contains("order"),
            "{e}"
        );
        let mut tf = TransferFunction::ramp(0.0, 1.0, 0.5);
        tf.color = vec![[1.0, 0.0, 0.0, 0.0], [0.5, 1.0, 1.0, 1.0]];
        assert!(tf.validate().unwrap_err().to_string().contains("color[1]"));
        let mut tf = TransferFunction::ramp(0.0, 1.0, 0.5);
        tf.gradient_opacity = Some(vec![[5.0, 1.0], [4.0, 0.0]]);
        assert!(
            tf.validate()
                .unwrap_err()
                .to_string()
                .contains("gradient_opacity[1]")
        );
        // A step: equal consecutive values, kept in the order written.
        let mut tf = TransferFunction::ramp(0.0, 1.0, 0.5);
        tf.scalar_opacity = vec![[0.0, 0.0], [0.5, 0.0], [0.5, 1.0], [1.0, 1.0]];
        tf.validate().unwrap();
        assert_eq!(tf.scalar_opacity[1], [0.5, 0.0]);
        assert_eq!(tf.opacity_at(0.25), 0.0);
        assert_eq!(tf.opacity_at(0.75), 1.0);
    }

    /// Fuzzing regression (issue 13): points at ±1e308 made the lookup-table span infinite and
    /// building the CRIO tables panicked on NaN.
    #[test]
    fn huge_point_values_are_an_error_not_a_panic() {
        for (lo, hi) in [
            (-1e308, 1e308),
            (0.0, 1e308),
            (-1e39, 0.0),
            (-f64::MAX, f64::MAX),
        ] {
            let mut tf = TransferFunction::ramp(0.0, 1.0, 0.5);
            tf.color[0][0] = lo;
            tf.color[1][0] = hi;
            let e = crate::CrioTables::from_transfer_function(&tf, 256).unwrap_err();
            assert!(
                e.to_string().contains("color[") && e.to_string().contains("1e38"),
                "{e}"
            );
            let mut tf = TransferFunction::ramp(0.0, 1.0, 0.5);
            tf.scalar_opacity[0][0] = lo;
            tf.scalar_opacity[1][0] = hi;
            assert!(
                tf.validate()
                    .unwrap_err()
                    .to_string()
                    .contains("scalar_opacity[")
            );
            let mut tf = TransferFunction::ramp(0.0, 1.0, 0.5);
            tf.gradient_opacity = Some(vec![[lo, 0.0], [hi, 1.0]]);
            assert!(
                tf.validate()
                    .unwrap_err()
                    .to_string()
                    .contains("gradient_opacity[")
            );
        }
        // The widest accepted span builds finite tables.
        let mut tf = TransferFunction::ramp(0.0, 1.0, 0.5);
        tf.color[0][0] = -MAX_POINT_VALUE;
        tf.color[1][0] = MAX_POINT_VALUE;
        tf.scalar_opacity[0][0] = -MAX_POINT_VALUE;
        tf.scalar_opacity[1][0] = MAX_POINT_VALUE;
        let t = crate::CrioTables::from_transfer_function(&tf, 256).unwrap();
        for x in [-3e38f32, -1e38, 0.0, 1e38, 3e38, f32::NAN] {
            let [a] = t.opacity.lookup(x);
            assert!(a.is_finite(), "{x}: {a}");
        }
        // NaN never reaches past the ends of the interpolation helpers.
        assert_eq!(
            interpolate_rows(&[[0.0, 1.0], [1.0, 2.0]], f64::NAN),
            [0.0, 1.0]
        );
        assert_eq!(
            piecewise_linear(&[(0.0, [1.0]), (1.0, [2.0])], f64::NAN),
            [1.0]
        );
    }

    #[test]
    fn missing_and_bad_fields_are_named() {
        let e = serde_json::from_str::<TransferFunction>(r#"{"color": [[0,1,1,1]]}"#).unwrap_err();
        assert!(e.to_string().contains("scalar_opacity"), "{e}");
        let mut tf = TransferFunction::ramp(0.0, 1.0, 0.5);
        tf.color[1][2] = 1.5;
        let e = tf.validate().unwrap_err();
        assert!(e.to_string().contains("color[1]"), "{e}");
        let mut tf = TransferFunction::ramp(0.0, 1.0, 0.5);
        tf.scalar_opacity_unit_distance = 0.0;
        assert!(
            tf.validate()
                .unwrap_err()
                .to_string()
                .contains("unit_distance")
        );
    }

    #[test]
    fn presets_validate_and_unknown_is_an_error() {
        for name in TransferFunction::PRESETS {
            TransferFunction::preset(name, (0.0, 255.0))
                .unwrap()
                .validate()
                .unwrap();
        }
        let e = TransferFunction::preset("nope", (0.0, 1.0)).unwrap_err();
        assert!(e.to_string().contains("CT-Bone"), "{e}");
    }
}
