//! The page's "turntable" button: a GIF of the current scene turned about the view-up axis,
//! rendered on the server at full quality with the engine's turntable cameras
//! ([`volsplat::movie::turntable`]) and volsplat-io's movie writer (one palette for the whole
//! movie), as `volsplat movie` writes it.

use crate::error::{Result, ViewError};
use crate::tab::Tab;
use volsplat::core::Camera;
use volsplat::io::{MovieSettings, MovieWriter};
use volsplat::movie::{TurnAxis, turntable};
use volsplat::{CameraSpec, RenderRequest};

/// The GIF's frame size: the view scaled so that its larger side is at most `max_size`.
pub fn gif_size(width: usize, height: usize, max_size: usize) -> (usize, usize) {
    let s = (max_size as f64 / width.max(height) as f64).min(1.0);
    (
        ((width as f64 * s).round() as usize).max(1),
        ((height as f64 * s).round() as usize).max(1),
    )
}

/// Renders the turntable and returns the GIF's bytes, or `None` if it was cancelled. Frames
/// are shown as the view shows them: the request's background and encoding, MIP, MinIP and
/// X-ray through its grey window.
pub(crate) fn render(
    tab: &Tab,
    request: &RenderRequest,
    camera: &Camera,
    frames: usize,
    degrees: f64,
    fps: f64,
    max_size: usize,
) -> Result<Option<Vec<u8>>> {
    let cameras = turntable(camera, TurnAxis::ViewUp, degrees, frames)?;
    let (w, h) = gif_size(request.width, request.height, max_size);
    let dir = tempfile::tempdir().map_err(|e| ViewError::socket("a temporary folder", e))?;
    let path = dir.path().join("turntable.gif");
    let display = request.output.write_options()?;
    let settings = MovieSettings {
        fps,
        png: display.png.clone(),
        ..MovieSettings::default()
    };
    let mut writer =
        MovieWriter::create(&path, w, h, frames, &settings).map_err(volsplat::EngineError::from)?;
    let mut req = request.clone();
    (req.width, req.height) = (w, h);
    for (n, cam) in cameras.into_iter().enumerate() {
        if !tab.turntable_progress(n as f64 / frames as f64) {
            return Ok(None);
        }
        req.scene.camera = CameraSpec::Explicit {
            camera: cam,
            orbit: Default::default(),
        };
        let out = {
            let mut renderer = tab.shared().renderer();
            renderer.render(&req, &mut |_| !tab.turntable_cancelled())
        };
        let out = match out {
            Err(volsplat::EngineError::Cancelled) => return Ok(None),
            r => r?,
        };
        let image = match (&out.values, display.window) {
            (Some(values), Some((lo, hi))) => volsplat::windowed_image(values, lo, hi),
            (Some(values), None) if req.mode == volsplat::Mode::Xray => {
                let max = values
                    .values()
                    .iter()
                    .filter(|v| v.is_finite())
                    .fold(0.0f32, |m, &v| m.max(v));
                volsplat::windowed_image(values, 0.0, max.max(f32::MIN_POSITIVE))
            }
            _ => out.image,
        };
        writer.push(&image).map_err(volsplat::EngineError::from)?;
    }
    writer.finish().map_err(volsplat::EngineError::from)?;
    let bytes = std::fs::read(&path).map_err(|e| ViewError::socket("reading the GIF back", e))?;
    Ok(Some(bytes))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gif_sizes_keep_the_aspect_and_never_grow() {
        assert_eq!(gif_size(512, 512, 256), (256, 256));
        assert_eq!(gif_size(800, 400, 256), (256, 128));
        assert_eq!(gif_size(100, 50, 256), (100, 50));
        assert_eq!(gif_size(3000, 1, 16), (16, 1));
    }
}
