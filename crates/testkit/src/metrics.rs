//! Image comparison metrics, the one implementation in the workspace (decision 0011): MSE,
//! PSNR, relative L2 error and SSIM on data values; the 8-bit MSE and SNR of Buchanan's thesis
//! §5-2 ([`mse_8bit`], [`mse_8bit_where`], [`snr_db`]); a blur measure ([`total_variation`]);
//! masked RMS over RGB ([`rms_rgb`]); and helpers that turn a premultiplied [`Image`] into
//! comparable channels. `volsplat-studies` re-exports this module as its `metrics`.
//!
//! Every function works on `f64` accumulators. Inputs of mismatched sizes, or empty inputs, give
//! `NaN` rather than a panic, so any `metric < tolerance` assertion fails on them.

use volsplat_core::{Image, ScalarImage};

/// Mean squared error `Σ (a − b)² / n` in squared data units. `NaN` if the lengths differ or
/// the slices are empty.
pub fn mse(a: &[f32], b: &[f32]) -> f64 {
    if a.len() != b.len() || a.is_empty() {
        return f64::NAN;
    }
    a.iter()
        .zip(b)
        .map(|(&x, &y)| {
            let d = x as f64 - y as f64;
            d * d
        })
        .sum::<f64>()
        / a.len() as f64
}

/// Peak signal-to-noise ratio `10·log10(peak² / mse)` in dB, with `peak` in data units (1 for
/// images in [0, 1]). `+∞` when the inputs are equal; `NaN` if [`mse`] is `NaN`.
pub fn psnr(a: &[f32], b: &[f32], peak: f64) -> f64 {
    let m = mse(a, b);
    if m.is_nan() {
        f64::NAN
    } else if m == 0.0 {
        f64::INFINITY
    } else {
        10.0 * (peak * peak / m).log10()
    }
}

/// Relative L2 error `‖test − reference‖₂ / ‖reference‖₂` (dimensionless). If the reference is
/// all zero: 0 when `test` is too, `+∞` otherwise. `NaN` if the lengths differ or are zero.
pub fn relative_l2(test: &[f32], reference: &[f32]) -> f64 {
    if test.len() != reference.len() || test.is_empty() {
        return f64::NAN;
    }
    let (mut num, mut den) = (0.0f64, 0.0f64);
    for (&t, &r) in test.iter().zip(reference) {
        let d = t as f64 - r as f64;
        num += d * d;
        den += r as f64 * r as f64;
    }
    if den == 0.0 {
        if num == 0.0 { 0.0 } else { f64::INFINITY }
    } else {
        (num / den).sqrt()
    }
}

/// Mean structural similarity (SSIM) of two grey images with values in [0, 1], row-major
/// `width × height` (Wang, Bovik, Sheikh & Simoncelli, "Image quality assessment: from error
/// visibility to structural similarity", IEEE TIP 13(4), 2004, eq. 13 and §III-C):
///
/// ```text
/// SSIM = (2 μa μb + C1)(2 σab + C2) / ((μa² + μb² + C1)(σa² + σb² + C2))
/// C1 = (0.01 L)², C2 = (0.03 L)², L = 1
/// ```
///
/// with local statistics weighted by an 11 × 11 Gaussian window of σ = 1.5 (normalised), over
/// every position where the window fits inside the image ("valid" filtering, as the authors'
/// reference code), averaged. Images smaller than 11 pixels on a side use the largest odd
/// window that fits. 1 for identical images; `NaN` if a length is not `width·height` or the
/// image is empty.
pub fn ssim_gray(a: &[f32], b: &[f32], width: usize, height: usize) -> f64 {
    let n = width.checked_mul(height).unwrap_or(0);
    if n == 0 || a.len() != n || b.len() != n {
        return f64::NAN;
    }
    let mut taps = 11.min(width).min(height);
    if taps % 2 == 0 {
        taps -= 1;
    }
    let half = (taps / 2) as f64;
    let mut kernel: Vec<f64> = (0..taps)
        .map(|i| {
            let x = i as f64 - half;
            (-x * x / (2.0 * 1.5 * 1.5)).exp()
        })
        .collect();
    let sum: f64 = kernel.iter().sum();
    kernel.iter_mut().for_each(|k| *k /= sum);

    let (ow, oh) = (width - taps + 1, height - taps + 1);
    // The five weighted moments at every valid position, filtered rows then columns.
    let fields: [Box<dyn Fn(usize) -> f64>; 5] = [
        Box::new(|i| a[i] as f64),
        Box::new(|i| b[i] as f64),
        Box::new(|i| a[i] as f64 * a[i] as f64),
        Box::new(|i| b[i] as f64 * b[i] as f64),
        Box::new(|i| a[i] as f64 * b[i] as f64),
    ];
    let moments: Vec<Vec<f64>> = fields
        .iter()
        .map(|f| {
            let mut rows = vec![0.0f64; ow * height];
            for y in 0..height {
                for x in 0..ow {
                    rows[y * ow + x] = (0..taps).map(|k| kernel[k] * f(y * width + x + k)).sum();
                }
            }
            let mut out = vec![0.0f64; ow * oh];
            for y in 0..oh {
                for x in 0..ow {
                    out[y * ow + x] = (0..taps).map(|k| kernel[k] * rows[(y + k) * ow + x]).sum();
                }
            }
            out
        })
        .collect();
    let (c1, c2) = ((0.01f64).powi(2), (0.03f64).powi(2));
    let [mu_a, mu_b, aa, bb, ab] = [0, 1, 2, 3, 4].map(|m| &moments[m]);
    let mut total = 0.0;
    for ((((&ma, &mb), &saa), &sbb), &sab) in mu_a.iter().zip(mu_b).zip(aa).zip(bb).zip(ab) {
        let va = saa - ma * ma;
        let vb = sbb - mb * mb;
        let cov = sab - ma * mb;
        total +=
            ((2.0 * ma * mb + c1) * (2.0 * cov + c2)) / ((ma * ma + mb * mb + c1) * (va + vb + c2));
    }
    total / (ow * oh) as f64
}

/// Flattened RGB (`[r, g, b, r, g, b, …]`, row-major, row 0 at the top) of `img` composited
/// over the opaque linear-RGB background `bg` (premultiplied over: `c + (1 − α)·bg`).
pub fn image_rgb_over(img: &Image, bg: [f32; 3]) -> Vec<f32> {
    img.over_background(bg)
        .pixels()
        .iter()
        .flat_map(|p| [p[0], p[1], p[2]])
        .collect()
}

/// PSNR in dB over all four premultiplied RGBA channels with peak 1 (see [`psnr`]); `NaN` if
/// the image sizes differ.
pub fn image_psnr(a: &Image, b: &Image) -> f64 {
    if a.width() != b.width() || a.height() != b.height() {
        return f64::NAN;
    }
    psnr(a.pixels().as_flattened(), b.pixels().as_flattened(), 1.0)
}

/// Linear relative luminance `Y = 0.2126 R + 0.7152 G + 0.0722 B` (ITU-R BT.709 primaries, as
/// sRGB) of `img` composited over the opaque background `bg`, one value per pixel, row-major.
/// Feed it to [`ssim_gray`].
pub fn luminance(img: &Image, bg: [f32; 3]) -> Vec<f32> {
    img.over_background(bg)
        .pixels()
        .iter()
        .map(|p| 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2])
        .collect()
}

/// Converts a grey value in `[0, 1]` to an 8-bit level (clamped, rounded; non-finite → 0).
#[inline]
pub fn to_8bit(v: f32) -> u8 {
    if v.is_finite() {
        (v.clamp(0.0, 1.0) * 255.0).round() as u8
    } else {
        0
    }
}

/// Buchanan's `e²_ms = (1/NM) Σ (u − u*)²` (thesis §5-2, after Jain 1981) over the 8-bit
/// versions ([`to_8bit`]) of two grey images in `[0, 1]`, in 8-bit levels². `NaN` if the lengths
/// differ or the slices are empty.
pub fn mse_8bit(a: &[f32], b: &[f32]) -> f64 {
    if a.len() != b.len() || a.is_empty() {
        return f64::NAN;
    }
    mse_8bit_where(a, b, |_| true)
}

/// The MSE of [`mse_8bit`] over the pixels (index into the slices) for which `keep` is true,
/// averaged over those pixels. `NaN` if the lengths differ or no pixel is kept.
pub fn mse_8bit_where(a: &[f32], b: &[f32], keep: impl Fn(usize) -> bool) -> f64 {
    if a.len() != b.len() {
        return f64::NAN;
    }
    let (mut sum, mut n) = (0.0f64, 0usize);
    for (i, (x, y)) in a.iter().zip(b).enumerate() {
        if keep(i) {
            let d = to_8bit(*x) as f64 - to_8bit(*y) as f64;
            sum += d * d;
            n += 1;
        }
    }
    if n == 0 { f64::NAN } else { sum / n as f64 }
}

/// Buchanan's `SNR = 10·log₁₀(255² / MSE)` in dB for an 8-bit MSE ([`mse_8bit`]); `+∞` for
/// MSE 0.
pub fn snr_db(mse: f64) -> f64 {
    10.0 * (255.0f64 * 255.0 / mse).log10()
}

/// Mean absolute difference between horizontally and vertically adjacent pixels of a grey
/// image (a blur measure: lower = blurrier), in the image's units. 0 for an image with no
/// neighbouring pixels.
pub fn total_variation(img: &ScalarImage) -> f64 {
    let (w, h) = (img.width(), img.height());
    let v = img.values();
    let mut sum = 0.0;
    let mut n = 0usize;
    for y in 0..h {
        for x in 0..w {
            let c = v[y * w + x] as f64;
            if x + 1 < w {
                sum += (v[y * w + x + 1] as f64 - c).abs();
                n += 1;
            }
            if y + 1 < h {
                sum += (v[(y + 1) * w + x] as f64 - c).abs();
                n += 1;
            }
        }
    }
    if n == 0 { 0.0 } else { sum / n as f64 }
}

/// RMS difference over the R, G, B channels of two premultiplied images, over the pixels where
/// `mask` is true (every pixel if `None`). `NaN` if the sizes differ, the mask's length is not
/// the pixel count, or no pixel is selected.
pub fn rms_rgb(a: &Image, b: &Image, mask: Option<&[bool]>) -> f64 {
    if a.width() != b.width()
        || a.height() != b.height()
        || mask.is_some_and(|m| m.len() != a.pixels().len())
    {
        return f64::NAN;
    }
    let (mut sum, mut n) = (0.0f64, 0usize);
    for (i, (p, q)) in a.pixels().iter().zip(b.pixels()).enumerate() {
        if mask.is_some_and(|m| !m[i]) {
            continue;
        }
        for c in 0..3 {
            let d = (p[c] - q[c]) as f64;
            sum += d * d;
        }
        n += 3;
    }
    (sum / n as f64).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thesis_table_pairs_f_b45() {
        // MSE/SNR pairs printed in Buchanan's Tables 5.1–5.6.
        for (mse, snr) in [
            (115.0, 27.5),
            (224.0, 24.6),
            (2.18, 44.7),
            (255.0, 24.0),
            (165.0, 26.0),
            (238.0, 24.3),
            (138.0, 26.7),
            (117.0, 27.5),
            (196.0, 25.2),
            (193.0, 25.3),
            (192.0, 25.3),
        ] {
            assert!((snr_db(mse) - snr).abs() < 0.1, "{mse} → {}", snr_db(mse));
        }
        assert!((snr_db(6416.0) - 10.06).abs() < 0.01);
        assert_eq!(snr_db(0.0), f64::INFINITY);
    }

    #[test]
    fn eight_bit_mse_and_total_variation() {
        let a = [0.0f32, 1.0];
        let b = [10.0 / 255.0, 1.0];
        assert!((mse_8bit(&a, &b) - 50.0).abs() < 1e-12);
        assert!(mse_8bit(&a, &[0.0]).is_nan() && mse_8bit(&[], &[]).is_nan());
        assert!((mse_8bit_where(&a, &b, |i| i == 0) - 100.0).abs() < 1e-12);
        assert_eq!(mse_8bit_where(&a, &b, |i| i == 1), 0.0);
        assert!(mse_8bit_where(&a, &b, |_| false).is_nan());
        assert_eq!(to_8bit(f32::NAN), 0);
        assert_eq!(to_8bit(2.0), 255);
        let img = ScalarImage::from_values(2, 1, a.to_vec()).unwrap();
        assert_eq!(total_variation(&img), 1.0);
        assert_eq!(total_variation(&ScalarImage::new(1, 1)), 0.0);
    }

    #[test]
    fn masked_rms_rgb() {
        let a = Image::from_pixels(2, 1, vec![[0.0; 4], [0.0; 4]]).unwrap();
        let b = Image::from_pixels(2, 1, vec![[0.3, 0.3, 0.3, 1.0], [0.0; 4]]).unwrap();
        assert!((rms_rgb(&a, &b, None) - (0.09f64 / 2.0).sqrt()).abs() < 1e-6);
        assert!((rms_rgb(&a, &b, Some(&[true, false])) - 0.3).abs() < 1e-6);
        assert!(rms_rgb(&a, &b, Some(&[false, false])).is_nan());
        assert!(rms_rgb(&a, &b, Some(&[true])).is_nan());
        assert!(rms_rgb(&a, &Image::new(1, 1), None).is_nan());
    }

    #[test]
    fn mse_and_psnr() {
        let a = [0.0f32; 4];
        let b = [0.1f32; 4];
        assert!((mse(&a, &b) - 0.01).abs() < 1e-8);
        assert!((psnr(&a, &b, 1.0) - 20.0).abs() < 1e-5);
        assert!((psnr(&a, &b, 10.0) - 40.0).abs() < 1e-5);
        assert_eq!(psnr(&b, &b, 1.0), f64::INFINITY);
        assert!(mse(&a, &b[..3]).is_nan() && psnr(&[], &[], 1.0).is_nan());
    }

    #[test]
    fn relative_l2_error() {
        assert!((relative_l2(&[3.0, 4.5], &[3.0, 4.0]) - 0.1).abs() < 1e-12);
        assert_eq!(relative_l2(&[0.0, 0.0], &[0.0, 0.0]), 0.0);
        assert_eq!(relative_l2(&[1.0, 0.0], &[0.0, 0.0]), f64::INFINITY);
        assert!(relative_l2(&[1.0], &[1.0, 2.0]).is_nan());
    }

    fn pattern(w: usize, h: usize, phase: f32) -> Vec<f32> {
        (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f32, (i / w) as f32);
                0.5 + 0.4 * (0.3 * x + phase).sin() * (0.2 * y).cos()
            })
            .collect()
    }

    #[test]
    fn ssim_properties() {
        let (w, h) = (32, 24);
        let a = pattern(w, h, 0.0);
        assert!((ssim_gray(&a, &a, w, h) - 1.0).abs() < 1e-12);
        // A small brightness shift keeps structure: high but below 1.
        let shifted: Vec<f32> = a.iter().map(|v| v + 0.02).collect();
        let s = ssim_gray(&a, &shifted, w, h);
        assert!(s > 0.95 && s < 1.0, "{s}");
        // Inverted contrast destroys it.
        let inv: Vec<f32> = a.iter().map(|v| 1.0 - v).collect();
        assert!(ssim_gray(&a, &inv, w, h) < 0.0);
        // Symmetric; a different pattern scores lower than a slightly shifted one.
        let b = pattern(w, h, 0.8);
        let (ab, ba) = (ssim_gray(&a, &b, w, h), ssim_gray(&b, &a, w, h));
        assert!((ab - ba).abs() < 1e-12 && ab < s);
        // Small images use a smaller window; bad sizes give NaN.
        let t = pattern(6, 5, 0.0);
        assert!((ssim_gray(&t, &t, 6, 5) - 1.0).abs() < 1e-12);
        assert!(ssim_gray(&a, &a, w + 1, h).is_nan());
        assert!(ssim_gray(&[], &[], 0, 0).is_nan());
    }

    #[test]
    fn image_helpers() {
        let img = Image::from_pixels(2, 1, vec![[0.5, 0.0, 0.0, 0.5], [0.0; 4]]).unwrap();
        let rgb = image_rgb_over(&img, [0.0, 0.0, 1.0]);
        assert_eq!(rgb, vec![0.5, 0.0, 0.5, 0.0, 0.0, 1.0]);
        let y = luminance(&img, [1.0, 1.0, 1.0]);
        assert!((y[0] - (1.0 - 0.5 * 0.7152 - 0.5 * 0.0722)).abs() < 1e-6);
        assert!((y[1] - 1.0).abs() < 1e-6);
        assert_eq!(image_psnr(&img, &img), f64::INFINITY);
        let other = Image::from_pixels(2, 1, vec![[0.5, 0.0, 0.0, 0.5], [0.1; 4]]).unwrap();
        // mse = 4·0.01 / 8 = 0.005 → 10·log10(200).
        assert!((image_psnr(&img, &other) - 10.0 * 200f64.log10()).abs() < 1e-4);
        assert!(image_psnr(&img, &Image::new(1, 2)).is_nan());
    }
}
