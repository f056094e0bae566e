//! How a render becomes an image file ([`OutputOptions`]): the part of a [`crate::RenderRequest`]
//! that `render`'s output flags set, so that a scene file renders to the same bytes as the
//! picture it was saved from. [`crate::write`] reads it.

use crate::error::{EngineError, Result};
use crate::request::Mode;
use serde::{Deserialize, Serialize};

/// How a render becomes an image file: what `render`'s output flags (`--background`, `--srgb`,
/// `--bit-depth`, `--window`/`--wl`) set. Part of the request, so that a scene file (`render
/// --save-scene`, the viewer's "save scene") renders to the same bytes as the picture it was
/// saved from. The renderers ignore it; [`crate::write`] reads it.
///
/// In a scene file the `output` object and each of its fields may be left out (the defaults
/// below), so scene files written before it existed load and render as before.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct OutputOptions {
    /// Opaque background colour under the composite image, linear RGB, each in [0, 1] (default
    /// black). PNG only: `.npy` files hold the premultiplied image itself, and grey
    /// (windowed) pictures have no background.
    pub background: [f32; 3],
    /// PNG: encode values with the sRGB transfer curve (default `false`: linear code values,
    /// as VTK, ParaView and 3D Slicer write their framebuffers; decision 0012).
    pub srgb: bool,
    /// PNG bits per channel: 8 (default) or 16.
    pub bit_depth: u32,
    /// Grey window `[lo, hi]` of MIP, MinIP and X-ray, `lo < hi`, in the values' units (data
    /// units; X-ray: data units × world units): `lo` → black, `hi` → white, linear between,
    /// clamped outside. `None` (default): MIP and MinIP through the transfer function, X-ray
    /// from 0 to its brightest pixel. Composite takes no window.
    pub window: Option<[f32; 2]>,
}

impl Default for OutputOptions {
    fn default() -> Self {
        OutputOptions {
            background: [0.0; 3],
            srgb: false,
            bit_depth: 8,
            window: None,
        }
    }
}

impl OutputOptions {
    /// Checks the options for a render in `mode`: a background of three linear values in
    /// [0, 1], a bit depth of 8 or 16, a window finite with `lo < hi` and only for MIP, MinIP
    /// and X-ray. Errors name the scene-file field (`output.window`).
    pub fn validate(&self, mode: Mode) -> Result<()> {
        crate::write::check_background(self.background)
            .map_err(|m| EngineError::request("output.background", m))?;
        if volsplat_io::PngBitDepth::from_bits(self.bit_depth).is_none() {
            return Err(EngineError::request(
                "output.bit_depth",
                format!("must be 8 or 16, got {}", self.bit_depth),
            ));
        }
        if let Some([lo, hi]) = self.window {
            if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                return Err(EngineError::request(
                    "output.window",
                    format!("needs finite values with lo < hi, got [{lo}, {hi}]"),
                ));
            }
            if mode == Mode::Composite {
                return Err(EngineError::request(
                    "output.window",
                    "a grey window applies to MIP, MinIP and X-ray; composite images take \
                     their colours from the transfer function",
                ));
            }
        }
        Ok(())
    }

    /// The writer's options ([`crate::write_image`], [`crate::encode_png`]). Errors as
    /// [`OutputOptions::validate`] for an unknown bit depth.
    pub fn write_options(&self) -> Result<crate::write::WriteOptions> {
        let bits = volsplat_io::PngBitDepth::from_bits(self.bit_depth).ok_or_else(|| {
            EngineError::request(
                "output.bit_depth",
                format!("must be 8 or 16, got {}", self.bit_depth),
            )
        })?;
        Ok(crate::write::WriteOptions {
            png: volsplat_io::PngSettings {
                bits,
                srgb: self.srgb,
                background: self.background,
            },
            window: self.window.map(|[lo, hi]| (lo, hi)),
        })
    }
}

impl Mode {
    /// Whether a grey window made for `self` means the same in `other`: MIP and MinIP share
    /// data units; X-ray's line integrals are data units × world units; composite takes none.
    /// Front ends drop the window when the mode changes to one where it does not.
    pub fn shares_window_with(self, other: Mode) -> bool {
        match (self, other) {
            (Mode::Composite, _) | (_, Mode::Composite) => false,
            (Mode::Mip | Mode::Minip, Mode::Mip | Mode::Minip) => true,
            (a, b) => a == b,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::request::RenderRequest;
    use crate::scene::Scene;

    /// Scene files written before `output` existed load with the defaults (and so render to
    /// the bytes they rendered to before); a partial `output` takes the defaults for the rest;
    /// a saved request reads back equal.
    #[test]
    fn scene_files_without_output_options_load_with_the_defaults() {
        let dir = tempfile::tempdir().unwrap();
        let old = dir.path().join("old.json");
        std::fs::write(
            &old,
            r#"{"scene": {"volume": {"phantom": {"phantom": "blobs"}}}, "width": 8, "height": 6, "mode": "mip"}"#,
        )
        .unwrap();
        let (req, warnings) = RenderRequest::load(&old).unwrap();
        assert!(warnings.is_empty(), "{warnings:?}");
        assert_eq!(req.output, OutputOptions::default());
        let partial = dir.path().join("partial.json");
        std::fs::write(
            &partial,
            r#"{"scene": {"volume": {"phantom": {"phantom": "blobs"}}}, "width": 8, "height": 6,
                "mode": "mip", "output": {"window": [1, 2.5]}}"#,
        )
        .unwrap();
        let (mut req, warnings) = RenderRequest::load(&partial).unwrap();
        assert!(warnings.is_empty(), "{warnings:?}");
        assert_eq!(req.output.window, Some([1.0, 2.5]));
        assert_eq!((req.output.bit_depth, req.output.srgb), (8, false));
        req.output.background = [0.25, 0.5, 1.0];
        req.output.bit_depth = 16;
        let saved = dir.path().join("saved.json");
        req.save(&saved).unwrap();
        assert_eq!(RenderRequest::load(&saved).unwrap().0, req);
    }

    /// Each bad output option is refused naming its field; a window on composite is refused,
    /// and a window carries over only between modes of the same units.
    #[test]
    fn output_options_are_checked_by_field() {
        let mut req = RenderRequest::new(Scene::default(), 16, 16);
        req.mode = Mode::Mip;
        req.validate().unwrap();
        type Case = (fn(&mut OutputOptions), &'static str, &'static str);
        let cases: [Case; 5] = [
            (
                |o| o.background = [0.0, f32::NAN, 0.0],
                "output.background",
                "green is NaN",
            ),
            (
                |o| o.background = [2.0, 0.0, 0.0],
                "output.background",
                "red is 2",
            ),
            (|o| o.bit_depth = 12, "output.bit_depth", "got 12"),
            (|o| o.window = Some([3.0, 1.0]), "output.window", "lo < hi"),
            (
                |o| o.window = Some([0.0, f32::INFINITY]),
                "output.window",
                "finite",
            ),
        ];
        for (change, field, words) in cases {
            let mut bad = req.clone();
            change(&mut bad.output);
            let e = bad.validate().unwrap_err().to_string();
            assert!(e.contains(field) && e.contains(words), "{e}");
        }
        req.output.window = Some([0.0, 1.0]);
        req.validate().unwrap();
        req.mode = Mode::Composite;
        let e = req.validate().unwrap_err().to_string();
        assert!(
            e.contains("output.window") && e.contains("composite"),
            "{e}"
        );
        assert!(Mode::Mip.shares_window_with(Mode::Minip));
        assert!(Mode::Xray.shares_window_with(Mode::Xray));
        assert!(!Mode::Mip.shares_window_with(Mode::Xray));
        assert!(!Mode::Composite.shares_window_with(Mode::Composite));
    }
}
