//! Writing an [`Output`] as the command line writes `-o FILE`: one rule for every front end (the
//! CLI, the Python package), so their files cannot drift apart.
//!
//! By extension: `.png` holds the premultiplied linear image composited over a background
//! (decision 0012: linear code values unless `srgb`), or — for X-ray always, and for MIP/MinIP when
//! a grey window is given — the scalar values through a grey window (X-ray without a window:
//! 0 to its brightest pixel); `.npy` holds the float32 `H×W×4` image or the `H×W` values.
//!
//! The options are the request's own ([`crate::OutputOptions`], `RenderRequest::output`):
//! [`Output::write`] and [`Output::png_bytes`] take them from the request that was rendered, so
//! a scene file renders to the same bytes wherever it is rendered.

use crate::error::{EngineError, Result};
use crate::renderer::Output;
use crate::request::{Mode, RenderRequest};
use std::path::Path;
use volsplat_core::{Image, ScalarImage};
use volsplat_io::PngSettings;

/// The image extensions [`Output::write`] knows.
pub const OUTPUT_EXTENSIONS: &[&str] = &["png", "npy"];

/// How an [`Output`] becomes a file.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct WriteOptions {
    /// PNG bit depth, encoding (linear or sRGB) and background.
    pub png: PngSettings,
    /// Grey window `(lo, hi)` for MIP, MinIP and X-ray values: `lo` → black, `hi` → white, in the
    /// values' units (data units; X-ray: data units × world units).
    pub window: Option<(f32, f32)>,
}

/// Checks a PNG background colour: three finite linear values in [0, 1]. The message names the
/// offending component and value (`red is NaN; …`).
pub fn check_background(background: [f32; 3]) -> std::result::Result<(), String> {
    for (name, v) in ["red", "green", "blue"].iter().zip(background) {
        if !(v.is_finite() && (0.0..=1.0).contains(&v)) {
            return Err(format!(
                "{name} is {v}; each component must be a linear value in [0, 1]"
            ));
        }
    }
    Ok(())
}

impl WriteOptions {
    /// Checks the options that need no image: the background ([`check_background`]) and the
    /// grey window (finite, `lo < hi`). Errors name the field (`background`, `window`).
    pub fn validate(&self) -> Result<()> {
        check_background(self.png.background).map_err(|m| EngineError::request("background", m))?;
        if let Some((lo, hi)) = self.window
            && !(lo.is_finite() && hi.is_finite() && lo < hi)
        {
            return Err(EngineError::request(
                "window",
                format!("needs finite values with lo < hi, got {lo}:{hi}"),
            ));
        }
        Ok(())
    }
}

/// Whether a render in `mode` is written as its scalar values (when it has them) rather than
/// its RGBA image: X-ray always, MIP and MinIP when `window` is given.
pub fn writes_values(has_values: bool, mode: Mode, window: Option<(f32, f32)>) -> bool {
    has_values
        && match mode {
            Mode::Xray => true,
            Mode::Mip | Mode::Minip => window.is_some(),
            Mode::Composite => false,
        }
}

impl Output {
    /// Writes the image (or the values) of the render of `request` to `path` as `volsplat
    /// render -o PATH` writes it: [`write_image`] with the request's mode and output options
    /// (`request.output`).
    pub fn write(&self, path: &Path, request: &RenderRequest) -> Result<()> {
        let options = request.output.write_options()?;
        write_image(
            path,
            &self.image,
            self.values.as_ref(),
            request.mode,
            &options,
        )
    }

    /// The bytes [`Output::write`] writes to a `.png` file for `request`, in memory
    /// ([`encode_png`]): a viewer's screenshot.
    pub fn png_bytes(&self, request: &RenderRequest) -> Result<Vec<u8>> {
        let options = request.output.write_options()?;
        encode_png(&self.image, self.values.as_ref(), request.mode, &options)
    }
}

/// Writes `image` (or `values`, see [`writes_values`]) of a render in `mode` to `path`,
/// atomically; see the module docs. Errors name the file: a background outside [0, 1] or not
/// finite, a window that is not finite with `lo < hi`, a window on a composite image, an unknown
/// extension, or the writer's own errors.
pub fn write_image(
    path: &Path,
    image: &Image,
    values: Option<&ScalarImage>,
    mode: Mode,
    options: &WriteOptions,
) -> Result<()> {
    let bad = |message: String| EngineError::request("output", message);
    check_options(&path.display().to_string(), mode, options)?;
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    let grey = grey_window(values, mode, options.window);
    match (ext.as_deref(), grey) {
        (Some("png"), Some((values, lo, hi))) => {
            volsplat_io::write_png_gray(path, values, lo, hi, options.png.bits)?
        }
        (Some("png"), None) => volsplat_io::write_png(path, image, &options.png)?,
        (Some("npy"), Some((values, _, _))) => volsplat_io::write_npy_scalar(path, values)?,
        (Some("npy"), None) => volsplat_io::write_npy_rgba(path, image)?,
        _ => {
            return Err(bad(format!(
                "{}: unsupported extension; use .png or .npy",
                path.display()
            )));
        }
    }
    Ok(())
}

/// The bytes [`write_image`] writes to a `.png` file for the same arguments, in memory: what a
/// viewer sends as its full-quality frame, so that its screenshot is the file `volsplat render`
/// writes (the same encoder; tested byte for byte).
pub fn encode_png(
    image: &Image,
    values: Option<&ScalarImage>,
    mode: Mode,
    options: &WriteOptions,
) -> Result<Vec<u8>> {
    check_options("image", mode, options)?;
    Ok(match grey_window(values, mode, options.window) {
        Some((values, lo, hi)) => volsplat_io::encode_png_gray(values, lo, hi, options.png.bits)?,
        None => volsplat_io::encode_png(image, &options.png)?,
    })
}

/// The options [`WriteOptions::validate`] checks, and a grey window only for MIP, MinIP and
/// X-ray; `what` names the output in the error.
fn check_options(what: &str, mode: Mode, options: &WriteOptions) -> Result<()> {
    let bad = |message: String| EngineError::request("output", message);
    options.validate().map_err(|e| match e {
        EngineError::Request { field, message } => bad(format!("{what}: {field} {message}")),
        e => e,
    })?;
    if options.window.is_some() && mode == Mode::Composite {
        return Err(bad(format!(
            "{what}: a grey window applies to MIP, MinIP and X-ray; composite images take their \
             colours from the transfer function"
        )));
    }
    Ok(())
}

/// The values and window an image is written through when it is written grey
/// ([`writes_values`]): the given window, or for X-ray without one 0 to the brightest value.
fn grey_window(
    values: Option<&ScalarImage>,
    mode: Mode,
    window: Option<(f32, f32)>,
) -> Option<(&ScalarImage, f32, f32)> {
    let values = values.filter(|_| writes_values(true, mode, window))?;
    let (lo, hi) = window.unwrap_or_else(|| {
        let max = values
            .values()
            .iter()
            .filter(|v| v.is_finite())
            .fold(0.0f32, |m, &v| m.max(v));
        (0.0, max.max(f32::MIN_POSITIVE))
    });
    Some((values, lo, hi))
}

/// MIP, MinIP or X-ray values through a grey window as an opaque grey image: `lo` → black,
/// `hi` → white, linear between, clamped outside, NaN (no sample) → black — the picture
/// [`write_image`] writes for them, as an [`Image`] (for movies and viewers).
pub fn windowed_image(values: &ScalarImage, lo: f32, hi: f32) -> Image {
    let mut img = Image::new(values.width(), values.height());
    let span = if hi > lo { hi - lo } else { 1.0 };
    for (p, &v) in img.pixels_mut().iter_mut().zip(values.values()) {
        let g = if v.is_nan() {
            0.0
        } else {
            ((v - lo) / span).clamp(0.0, 1.0)
        };
        *p = [g, g, g, 1.0];
    }
    img
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `encode_png` gives the bytes `write_image` writes: composite over a background, MIP
    /// through a window, X-ray scaled to its brightest value, 16-bit sRGB; and refuses what
    /// `write_image` refuses.
    #[test]
    fn encoded_png_is_the_written_file() {
        let dir = tempfile::tempdir().unwrap();
        let px: Vec<[f32; 4]> = (0..12)
            .map(|n| {
                let v = n as f32 / 12.0;
                [v * 0.3, v * 0.6, v * 0.9, v]
            })
            .collect();
        let image = Image::from_pixels(4, 3, px).unwrap();
        let values =
            ScalarImage::from_values(4, 3, (0..12).map(|n| n as f32 * 1.5).collect()).unwrap();
        let mut srgb16 = WriteOptions::default();
        srgb16.png.srgb = true;
        srgb16.png.bits = volsplat_io::PngBitDepth::Sixteen;
        srgb16.png.background = [0.2, 0.1, 0.0];
        let windowed = WriteOptions {
            window: Some((2.0, 9.0)),
            ..WriteOptions::default()
        };
        let cases = [
            (Mode::Composite, None, WriteOptions::default()),
            (Mode::Composite, None, srgb16),
            (Mode::Mip, Some(&values), windowed.clone()),
            (Mode::Mip, Some(&values), WriteOptions::default()),
            (Mode::Xray, Some(&values), WriteOptions::default()),
            (Mode::Xray, Some(&values), windowed.clone()),
        ];
        for (n, (mode, values, options)) in cases.iter().enumerate() {
            let path = dir.path().join(format!("{n}.png"));
            write_image(&path, &image, *values, *mode, options).unwrap();
            let bytes = encode_png(&image, *values, *mode, options).unwrap();
            assert_eq!(bytes, std::fs::read(&path).unwrap(), "case {n}");
        }
        assert!(encode_png(&image, None, Mode::Composite, &windowed).is_err());
        let backwards = WriteOptions {
            window: Some((3.0, 1.0)),
            ..WriteOptions::default()
        };
        assert!(encode_png(&image, Some(&values), Mode::Mip, &backwards).is_err());
    }

    /// Issue 28: `--background nan,0,0` wrote red as 0 and `2,2,2` was accepted; both are
    /// errors naming the component, and nothing is written.
    #[test]
    fn backgrounds_outside_zero_to_one_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.png");
        let image = Image::new(2, 2);
        for (bg, word) in [
            ([f32::NAN, 0.0, 0.0], "red is NaN"),
            ([2.0, 2.0, 2.0], "red is 2"),
            ([0.0, -0.5, 0.0], "green is -0.5"),
            ([0.0, 0.0, f32::INFINITY], "blue is inf"),
        ] {
            let options = WriteOptions {
                png: PngSettings {
                    background: bg,
                    ..PngSettings::default()
                },
                window: None,
            };
            let e = write_image(&path, &image, None, Mode::Composite, &options)
                .unwrap_err()
                .to_string();
            assert!(e.contains(word) && e.contains("[0, 1]"), "{e}");
            assert!(!path.exists());
        }
        let ok = WriteOptions {
            png: PngSettings {
                background: [0.0, 0.5, 1.0],
                ..PngSettings::default()
            },
            window: None,
        };
        write_image(&path, &image, None, Mode::Composite, &ok).unwrap();
        assert!(path.exists());
    }

    #[test]
    fn windows_map_linearly_clamp_and_blacken_uncovered_pixels() {
        let v = ScalarImage::from_values(5, 1, vec![f32::NAN, -1.0, 2.0, 6.0, 20.0]).unwrap();
        let img = windowed_image(&v, 2.0, 10.0);
        let g: Vec<f32> = img.pixels().iter().map(|p| p[0]).collect();
        assert_eq!(g, vec![0.0, 0.0, 0.0, 0.5, 1.0]);
        assert!(
            img.pixels()
                .iter()
                .all(|p| p[3] == 1.0 && p[1] == p[0] && p[2] == p[0])
        );
    }
}
