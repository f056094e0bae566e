//! Frames as bytes: JPEG previews, the PNG final frame (`volsplat render`'s own bytes), and
//! the volume's histogram for the transfer-function editor.

use crate::error::{Result, ViewError};
use volsplat::core::{AnyVolume, Histogram, Image};
use volsplat::io::{PngBitDepth, PngSettings};
use volsplat::{Mode, Output, WriteOptions};

/// Default JPEG quality of previews (docs/viewer.md, "Frames": 512² previews at 85 encode in
/// a few milliseconds and lose less to JPEG than the preview loses to its size).
pub const DEFAULT_PREVIEW_QUALITY: u8 = 85;

/// The picture a frame shows as 8-bit RGB, row 0 at the top: composite over the background,
/// or MIP, MinIP and X-ray values through the grey window (X-ray without one: 0 to its
/// brightest value), as `write_image` writes them.
pub fn display_rgb(out: &Output, mode: Mode, display: &WriteOptions) -> (usize, usize, Vec<u8>) {
    let grey = volsplat::writes_values(out.values.is_some(), mode, display.window);
    let image: Image = match (&out.values, grey) {
        (Some(values), true) => {
            let (lo, hi) = display.window.unwrap_or_else(|| {
                let max = values
                    .values()
                    .iter()
                    .filter(|v| v.is_finite())
                    .fold(0.0f32, |m, &v| m.max(v));
                (0.0, max.max(f32::MIN_POSITIVE))
            });
            volsplat::windowed_image(values, lo, hi)
        }
        _ => out.image.clone(),
    };
    let settings = PngSettings {
        bits: PngBitDepth::Eight,
        srgb: display.png.srgb && !grey,
        background: display.png.background,
    };
    let rgb = volsplat::io::rgb_codes(&image, &settings)
        .into_iter()
        .map(|c| c.min(255) as u8)
        .collect();
    (image.width(), image.height(), rgb)
}

/// A preview as JPEG at `quality` (1..=100).
pub fn preview_jpeg(
    out: &Output,
    mode: Mode,
    display: &WriteOptions,
    quality: u8,
) -> Result<Vec<u8>> {
    let (w, h, rgb) = display_rgb(out, mode, display);
    let (w16, h16) = match (u16::try_from(w), u16::try_from(h)) {
        (Ok(w), Ok(h)) => (w, h),
        _ => return Err(ViewError::Encode(format!("{w}×{h} is too large for JPEG"))),
    };
    let mut bytes = Vec::with_capacity(w * h / 4 + 1024);
    let encoder = jpeg_encoder::Encoder::new(&mut bytes, quality.clamp(1, 100));
    encoder
        .encode(&rgb, w16, h16, jpeg_encoder::ColorType::Rgb)
        .map_err(|e| ViewError::Encode(e.to_string()))?;
    Ok(bytes)
}

/// The final frame: exactly the bytes `volsplat render -o FILE.png` writes for the same scene
/// and image options ([`volsplat::encode_png`]).
pub fn final_png(out: &Output, mode: Mode, display: &WriteOptions) -> Result<Vec<u8>> {
    Ok(volsplat::encode_png(
        &out.image,
        out.values.as_ref(),
        mode,
        display,
    )?)
}

/// The smallest and largest finite value of a MIP, MinIP or X-ray frame.
pub fn values_range(out: &Output) -> Option<[f32; 2]> {
    let values = out.values.as_ref()?;
    let (lo, hi) = values
        .values()
        .iter()
        .filter(|v| v.is_finite())
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &v| {
            (lo.min(v), hi.max(v))
        });
    (lo <= hi).then_some([lo, hi])
}

/// Sample counts of `vol` in `bins` equal bins over its value range (one pass over the
/// volume, through [`Histogram::from_volume`]'s exact bins, merged).
pub fn histogram(vol: &AnyVolume, bins: usize) -> (Vec<u64>, [f64; 2]) {
    let fine = Histogram::from_volume(vol);
    let (lo, hi) = vol.value_range();
    let bins = bins.max(1);
    let mut counts = vec![0u64; bins];
    let span = hi - lo;
    for (n, &c) in fine.counts().iter().enumerate() {
        if c == 0 {
            continue;
        }
        let t = if span > 0.0 {
            (fine.bin_center(n) - lo) / span
        } else {
            0.0
        };
        let k = ((t * bins as f64).floor().max(0.0) as usize).min(bins - 1);
        counts[k] += c;
    }
    (counts, [lo, hi])
}

#[cfg(test)]
mod tests {
    use super::*;
    use volsplat::core::{Grid, Volume};

    #[test]
    fn histogram_counts_every_sample_in_the_right_bin() {
        let data: Vec<u8> = (0..64).map(|n| (n % 8) as u8 * 10).collect();
        let grid = Grid::with_dims([4, 4, 4]).unwrap();
        let vol: AnyVolume = Volume::new(grid, data).unwrap().into();
        let (counts, range) = histogram(&vol, 8);
        assert_eq!(range, [0.0, 70.0]);
        assert_eq!(counts.iter().sum::<u64>(), 64);
        // Values 0, 10, …, 70 over [0, 70] in 8 bins of 8.75: one value per bin.
        assert_eq!(counts, vec![8; 8]);
    }
}
