//! Fidelity measures of thesis §5-2 (Jain 1981; F-B45): mean square error on 8-bit images and
//! `SNR = 10·log₁₀(255² / MSE)` dB.

use volsplat_core::ScalarImage;

/// Converts a grey value in `[0, 1]` to an 8-bit level (clamped, rounded; non-finite → 0).
#[inline]
pub fn to_8bit(v: f32) -> u8 {
    if v.is_finite() {
        (v.clamp(0.0, 1.0) * 255.0).round() as u8
    } else {
        0
    }
}

/// `e²_ms = (1/NM) Σ (u − u*)²` over the 8-bit versions of two images of equal size; `None`
/// if the sizes differ or the images are empty.
pub fn mse_8bit(a: &ScalarImage, b: &ScalarImage) -> Option<f64> {
    if a.width() != b.width() || a.height() != b.height() || a.values().is_empty() {
        return None;
    }
    let sum: f64 = a
        .values()
        .iter()
        .zip(b.values())
        .map(|(x, y)| {
            let d = to_8bit(*x) as f64 - to_8bit(*y) as f64;
            d * d
        })
        .sum();
    Some(sum / a.values().len() as f64)
}

/// The MSE of [`mse_8bit`] restricted to the pixels (row-major index) for which `keep` is true,
/// averaged over those pixels; `None` if the sizes differ or no pixel is kept.
pub fn mse_8bit_where(
    a: &ScalarImage,
    b: &ScalarImage,
    keep: impl Fn(usize) -> bool,
) -> Option<f64> {
    if a.width() != b.width() || a.height() != b.height() {
        return None;
    }
    let (mut sum, mut n) = (0.0, 0usize);
    for (i, (x, y)) in a.values().iter().zip(b.values()).enumerate() {
        if keep(i) {
            let d = to_8bit(*x) as f64 - to_8bit(*y) as f64;
            sum += d * d;
            n += 1;
        }
    }
    (n > 0).then(|| sum / n as f64)
}

/// `SNR = 10·log₁₀(255²/MSE)` in dB (infinite for MSE 0).
pub fn snr_db(mse: f64) -> f64 {
    10.0 * (255.0f64 * 255.0 / mse).log10()
}

/// Mean absolute difference between horizontally and vertically adjacent pixels (a blur
/// measure: lower = blurrier), grey levels in `[0, 1]`.
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thesis_table_pairs_f_b45() {
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
    }

    #[test]
    fn mse_of_images() {
        let a = ScalarImage::from_values(2, 1, vec![0.0, 1.0]).unwrap();
        let b = ScalarImage::from_values(2, 1, vec![10.0 / 255.0, 1.0]).unwrap();
        assert!((mse_8bit(&a, &b).unwrap() - 50.0).abs() < 1e-12);
        assert!(mse_8bit(&a, &ScalarImage::new(1, 1)).is_none());
        assert_eq!(total_variation(&a), 1.0);
        assert!((mse_8bit_where(&a, &b, |i| i == 0).unwrap() - 100.0).abs() < 1e-12);
        assert_eq!(mse_8bit_where(&a, &b, |i| i == 1), Some(0.0));
        assert!(mse_8bit_where(&a, &b, |_| false).is_none());
    }
}
