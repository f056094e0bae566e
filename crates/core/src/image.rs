//! Images and compositing operators (docs/design.md §3).
//!
//! [`Image`] is RGBA `f32` with premultiplied (associated) colour, row 0 at the top, pixel
//! `(x, y)` centred at `(x + 0.5, y + 0.5)` in raster coordinates. [`ScalarImage`] holds one
//! float per pixel (X-ray line integrals, projection values). The *over* operator is
//! associative on premultiplied colour, which is what lets sheets, tiles and (later) bricks be
//! composited in any grouping as long as their visibility order is kept.

/// Premultiplied RGBA pixel: `[r·a, g·a, b·a, a]`.
pub type Rgba = [f32; 4];

/// Front-to-back over: `acc` is in front of everything composited so far; `src` lies behind it.
/// `C += (1 − A)·c`, `A += (1 − A)·a` (Westover §3.8.1, premultiplied form).
#[inline(always)]
pub fn over_front_to_back(acc: &mut Rgba, src: Rgba) {
    let t = 1.0 - acc[3];
    acc[0] += t * src[0];
    acc[1] += t * src[1];
    acc[2] += t * src[2];
    acc[3] += t * src[3];
}

/// Back-to-front over: `src` lies in front of `acc`. `C = c + (1 − a)·C`, `A = a + (1 − a)·A`.
#[inline(always)]
pub fn over_back_to_front(acc: &mut Rgba, src: Rgba) {
    let t = 1.0 - src[3];
    acc[0] = src[0] + t * acc[0];
    acc[1] = src[1] + t * acc[1];
    acc[2] = src[2] + t * acc[2];
    acc[3] = src[3] + t * acc[3];
}

/// A premultiplied RGBA float image.
#[derive(Debug, Clone, PartialEq)]
pub struct Image {
    width: usize,
    height: usize,
    pixels: Vec<Rgba>,
}

impl Image {
    /// A transparent black image.
    pub fn new(width: usize, height: usize) -> Self {
        Image {
            width,
            height,
            pixels: vec![[0.0; 4]; width * height],
        }
    }

    /// Wraps pixels (row-major, row 0 at the top); `None` if the length is wrong.
    pub fn from_pixels(width: usize, height: usize, pixels: Vec<Rgba>) -> Option<Self> {
        (pixels.len() == width * height).then_some(Image {
            width,
            height,
            pixels,
        })
    }

    /// Width in pixels.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Height in pixels.
    pub fn height(&self) -> usize {
        self.height
    }

    /// All pixels, row-major.
    pub fn pixels(&self) -> &[Rgba] {
        &self.pixels
    }

    /// All pixels, mutable.
    pub fn pixels_mut(&mut self) -> &mut [Rgba] {
        &mut self.pixels
    }

    /// Pixel at column `x`, row `y`.
    pub fn get(&self, x: usize, y: usize) -> Rgba {
        self.pixels[y * self.width + x]
    }

    /// Composites the image over an opaque background colour (linear RGB); the result is opaque.
    pub fn over_background(&self, background: [f32; 3]) -> Image {
        let pixels = self
            .pixels
            .iter()
            .map(|p| {
                let t = 1.0 - p[3];
                [
                    p[0] + t * background[0],
                    p[1] + t * background[1],
                    p[2] + t * background[2],
                    1.0,
                ]
            })
            .collect();
        Image {
            width: self.width,
            height: self.height,
            pixels,
        }
    }
}

/// A single-channel float image (e.g. X-ray line integrals in data units × world units).
#[derive(Debug, Clone, PartialEq)]
pub struct ScalarImage {
    width: usize,
    height: usize,
    values: Vec<f32>,
}

impl ScalarImage {
    /// A zero image.
    pub fn new(width: usize, height: usize) -> Self {
        ScalarImage {
            width,
            height,
            values: vec![0.0; width * height],
        }
    }

    /// Wraps values (row-major, row 0 at the top); `None` if the length is wrong.
    pub fn from_values(width: usize, height: usize, values: Vec<f32>) -> Option<Self> {
        (values.len() == width * height).then_some(ScalarImage {
            width,
            height,
            values,
        })
    }

    /// Width in pixels.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Height in pixels.
    pub fn height(&self) -> usize {
        self.height
    }

    /// All values, row-major.
    pub fn values(&self) -> &[f32] {
        &self.values
    }

    /// All values, mutable.
    pub fn values_mut(&mut self) -> &mut [f32] {
        &mut self.values
    }

    /// Value at column `x`, row `y`.
    pub fn get(&self, x: usize, y: usize) -> f32 {
        self.values[y * self.width + x]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn layer() -> impl Strategy<Value = Rgba> {
        (0.0f32..=1.0, 0.0f32..=1.0, 0.0f32..=1.0, 0.0f32..=1.0)
            .prop_map(|(r, g, b, a)| [r * a, g * a, b * a, a])
    }

    proptest! {
        /// FTB and BTF accumulate the same stack (Westover §3.8.1 "equivalent").
        #[test]
        fn ftb_equals_btf(stack in proptest::collection::vec(layer(), 0..20)) {
            let mut f = [0.0; 4];
            for l in &stack { over_front_to_back(&mut f, *l); }
            let mut b = [0.0; 4];
            for l in stack.iter().rev() { over_back_to_front(&mut b, *l); }
            for c in 0..4 { prop_assert!((f[c] - b[c]).abs() < 1e-5); prop_assert!(f[c] <= 1.0 + 1e-5); }
        }

        /// Over is associative: compositing two groups separately then together is the same.
        #[test]
        fn over_is_associative(stack in proptest::collection::vec(layer(), 0..20), cut in 0usize..20) {
            let cut = cut.min(stack.len());
            let mut all = [0.0; 4];
            for l in &stack { over_front_to_back(&mut all, *l); }
            let (mut front, mut back) = ([0.0; 4], [0.0; 4]);
            for l in &stack[..cut] { over_front_to_back(&mut front, *l); }
            for l in &stack[cut..] { over_front_to_back(&mut back, *l); }
            over_front_to_back(&mut front, back);
            for c in 0..4 { prop_assert!((all[c] - front[c]).abs() < 1e-5); }
        }
    }

    #[test]
    fn transparent_image_shows_background_exactly() {
        let img = Image::new(2, 2).over_background([0.1, 0.2, 0.3]);
        assert_eq!(img.get(1, 1), [0.1, 0.2, 0.3, 1.0]);
    }
}
