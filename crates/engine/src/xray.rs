//! What an X-ray integrates ([`XrayDensity`], `Scene::xray_density`, CLI `--xray-offset`).
//!
//! The X-ray mode draws line integrals `∫ f ds` of the reconstructed field. Of a CT in Hounsfield
//! units (water 0, air −1000, padding −3024) that integral is mostly negative: the picture, scaled
//! to its brightest pixel, was black with one bright dot (issue 28 §6). Attenuation is
//! `μ = μ_water·(1 + HU/1000)`, so `max(HU + 1000, 0)` is `1000·μ/μ_water`, and its integral a
//! digitally reconstructed radiograph (DRR) in `1000 × μ/μ_water × world units`: 1000 × the
//! water-equivalent path length (mm of water for a medical volume). For other data an offset
//! may be set, or none.

use serde::{Deserialize, Serialize};
use std::str::FromStr;

/// The offset added to every value before an X-ray integrates it, clamped at zero
/// (`volsplat_splat::RenderSettings::xray_offset`).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
#[non_exhaustive]
pub enum XrayDensity {
    /// [`XRAY_CT_OFFSET`] (1000) where the data look like CT in Hounsfield units
    /// ([`looks_like_hounsfield`]), the values as they are otherwise.
    #[default]
    Auto,
    /// The values as they are: `∫ f ds`, data units × world units, negative parts included.
    Raw,
    /// `∫ max(f + offset, 0) ds`, (data units + offset) × world units; the offset is finite.
    Offset(f64),
}

/// The offset of CT in Hounsfield units: air (−1000 HU) integrates to 0, water (0 HU) to 1000
/// per world unit.
pub const XRAY_CT_OFFSET: f64 = 1000.0;

/// Whether data whose smallest and largest samples are `range` (data units) look like CT in
/// Hounsfield units: some sample at or below −900 (air is −1000; padding outside the field of
/// view −1024 to −3024) and some at or above 300 (bone, contrast, metal). No other common
/// modality is signed with that spread; MR, PET and microscopy are non-negative.
pub fn looks_like_hounsfield(range: (f64, f64)) -> bool {
    range.0 <= -900.0 && range.1 >= 300.0
}

impl XrayDensity {
    /// The offset for data whose value range is `range` (`None`: raw values), and, where
    /// `Auto` took the data for CT, a note saying so.
    pub fn resolve(self, range: (f64, f64)) -> (Option<f64>, Option<String>) {
        match self {
            XrayDensity::Raw => (None, None),
            XrayDensity::Offset(o) => (Some(o), None),
            XrayDensity::Auto if looks_like_hounsfield(range) => (
                Some(XRAY_CT_OFFSET),
                Some(format!(
                    "X-ray: the values ({} to {}) look like CT in Hounsfield units; integrating \
                     attenuation relative to air, max(HU + 1000, 0) × world units (1000 × the \
                     water-equivalent path; --xray-offset none for the raw values)",
                    range.0, range.1
                )),
            ),
            XrayDensity::Auto => (None, None),
        }
    }

    /// Whether this is the default, [`XrayDensity::Auto`] (scene files leave it out).
    pub fn is_auto(&self) -> bool {
        *self == XrayDensity::Auto
    }
}

impl FromStr for XrayDensity {
    type Err = String;

    /// `auto`, `none` (or `raw`), or a finite number (data units).
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim() {
            "auto" => Ok(XrayDensity::Auto),
            "none" | "raw" => Ok(XrayDensity::Raw),
            t => match t.parse::<f64>() {
                Ok(o) if o.is_finite() => Ok(XrayDensity::Offset(o)),
                _ => Err(format!(
                    "expected `auto`, `none` or a finite offset in data units (1000 for CT in \
                     Hounsfield units), got {s:?}"
                )),
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn auto_takes_hounsfield_ranges_for_ct() {
        assert!(looks_like_hounsfield((-1024.0, 3071.0)));
        assert!(looks_like_hounsfield((-3024.0, 1800.0)));
        // MR, an 8-bit image, a signed phase map, soft tissue only.
        assert!(!looks_like_hounsfield((0.0, 4095.0)));
        assert!(!looks_like_hounsfield((0.0, 255.0)));
        assert!(!looks_like_hounsfield((-3.2, 3.2)));
        assert!(!looks_like_hounsfield((-1000.0, 200.0)));
        let (o, note) = XrayDensity::Auto.resolve((-1024.0, 3071.0));
        assert_eq!(o, Some(1000.0));
        assert!(note.unwrap().contains("Hounsfield"));
        assert_eq!(XrayDensity::Auto.resolve((0.0, 255.0)), (None, None));
        assert_eq!(XrayDensity::Raw.resolve((-1024.0, 3071.0)), (None, None));
        assert_eq!(
            XrayDensity::Offset(5.0).resolve((0.0, 1.0)),
            (Some(5.0), None)
        );
    }

    #[test]
    fn parses_the_flag_and_round_trips_in_json() {
        assert_eq!("auto".parse(), Ok(XrayDensity::Auto));
        assert_eq!("none".parse(), Ok(XrayDensity::Raw));
        assert_eq!("1000".parse(), Ok(XrayDensity::Offset(1000.0)));
        assert_eq!("-2.5".parse(), Ok(XrayDensity::Offset(-2.5)));
        for bad in ["nan", "inf", "", "water"] {
            assert!(bad.parse::<XrayDensity>().is_err(), "{bad}");
        }
        for d in [
            XrayDensity::Auto,
            XrayDensity::Raw,
            XrayDensity::Offset(1000.0),
        ] {
            let j = serde_json::to_string(&d).unwrap();
            assert_eq!(serde_json::from_str::<XrayDensity>(&j).unwrap(), d, "{j}");
        }
        assert_eq!(
            serde_json::to_string(&XrayDensity::Offset(1000.0)).unwrap(),
            r#"{"offset":1000.0}"#
        );
    }
}
