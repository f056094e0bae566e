//! Solid (volumetric) textures: procedural cosine series, marble and step; discrete sampled
//! arrays with sample-and-hold or trilinear reconstruction (thesis §1-4.3, §4-4.5, §5-3).
//!
//! A texture is a scalar function `T(u, v, w)` of a texture-space point, grey level in roughly
//! `[0, 1]`. The scenes of [`crate::scene`] are modelled directly in texture space.

use crate::clamp::ClampSettings;
use crate::error::{FilterError, Result, check_positive};
use crate::region::OrientedBox;
use glam::DVec3;
use std::f64::consts::TAU;
use volsplat_core::{Scalar, Volume};

/// A solid texture: a scalar function of a texture-space point.
///
/// Techniques that need more than point evaluation ask for it through the optional methods:
/// clamping needs frequency information ([`SolidTexture::clamped_value`]), NIL maps need a
/// cosine spectrum ([`SolidTexture::as_cosine`]) or samples ([`SolidTexture::as_discrete`]).
pub trait SolidTexture: Send + Sync + std::fmt::Debug {
    /// Short name for reports (`cosine`, `marble`, ...).
    fn name(&self) -> &str;

    /// The texture value at texture-space point `p` (texture units), grey level.
    fn value(&self, p: DVec3) -> f64;

    /// The DC (average) value of the texture, used where a footprint degenerates (thesis §4-2
    /// footnote 2) and as the NIL fall-back for filters larger than the pyramid.
    fn mean(&self) -> f64;

    /// Highest frequency present, cycles per texture unit, if known (sets EWA's sample spacing
    /// for procedural textures). `None` if unbounded (step) or unknown.
    fn max_frequency(&self) -> Option<f64>;

    /// The texture with each frequency component attenuated by the clamp factor for the
    /// footprint given by its three half-axis vectors (thesis §4-1, §5-3). Errors with
    /// [`FilterError::NotApplicable`] for textures without frequency information (§3-2).
    fn clamped_value(
        &self,
        p: DVec3,
        footprint: &[DVec3; 3],
        clamp: &ClampSettings,
    ) -> Result<f64> {
        let _ = (p, footprint, clamp);
        Err(FilterError::NotApplicable {
            technique: "clamping".into(),
            reason: format!("texture `{}` has no known frequency spectrum", self.name()),
        })
    }

    /// The cosine-series representation, if this texture is one (enables analytic NIL maps).
    fn as_cosine(&self) -> Option<&CosineTexture> {
        None
    }

    /// The sampled representation, if this texture is one (enables discrete NIL maps).
    fn as_discrete(&self) -> Option<&DiscreteTexture> {
        None
    }
}

/// SplitMix64: a tiny deterministic generator for seeded textures (no external dependency).
#[derive(Debug, Clone)]
pub(crate) struct SplitMix64(pub u64);

impl SplitMix64 {
    pub(crate) fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in `[0, 1)`.
    pub(crate) fn next_f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// `cos(2π·n·x)` for `n = 0..out.len()` by the Chebyshev recurrence (one `cos` call).
#[inline]
pub(crate) fn cos_harmonics(x: f64, out: &mut [f64]) {
    let c1 = (TAU * x).cos();
    let n = out.len();
    if n > 0 {
        out[0] = 1.0;
    }
    if n > 1 {
        out[1] = c1;
    }
    for k in 2..n {
        out[k] = 2.0 * c1 * out[k - 1] - out[k - 2];
    }
}

/// `sin(x)/x`, with the limit 1 at 0.
#[inline]
pub(crate) fn sinc(x: f64) -> f64 {
    if x.abs() < 1e-4 {
        1.0 - x * x / 6.0
    } else {
        x.sin() / x
    }
}

/// Cosine-series texture (thesis §4-4.5, Plate 4.2):
/// `T(u,v,w) = S·Σ_{i<I,j<J,k<K} T_ijk cos(2πiu) cos(2πjv) cos(2πkw) + offset`,
/// unit-periodic along each axis. Its spectrum is known exactly, so it supports clamping,
/// closed-form box averages and analytic NIL maps.
#[derive(Debug, Clone, PartialEq)]
pub struct CosineTexture {
    dims: [usize; 3],
    coeffs: Vec<f64>,
    scale: f64,
    offset: f64,
}

impl CosineTexture {
    /// Builds a texture from `dims = [I, J, K]` (each 1..=64) and coefficients `T_ijk` stored
    /// with `k` fastest (`index = (i·J + j)·K + k`), scale `S` and additive offset.
    pub fn new(dims: [usize; 3], coeffs: Vec<f64>, scale: f64, offset: f64) -> Result<Self> {
        for (a, &d) in dims.iter().enumerate() {
            if d == 0 || d > 64 {
                return Err(FilterError::invalid(
                    format!("dims[{a}]"),
                    d,
                    "must be in 1..=64",
                ));
            }
        }
        let n = dims[0] * dims[1] * dims[2];
        if coeffs.len() != n {
            return Err(FilterError::invalid(
                "coeffs",
                coeffs.len(),
                format!("expected {n}"),
            ));
        }
        if let Some(c) = coeffs.iter().find(|c| !c.is_finite()) {
            return Err(FilterError::invalid("coeffs", c, "must be finite"));
        }
        if !scale.is_finite() || !offset.is_finite() {
            return Err(FilterError::invalid(
                "scale/offset",
                (scale, offset),
                "must be finite",
            ));
        }
        Ok(CosineTexture {
            dims,
            coeffs,
            scale,
            offset,
        })
    }

    /// The thesis's test texture with seeded coefficients (decision A-6): `I = J = K = n`,
    /// `T_ijk` uniform in `[−1, 1)` from `seed` except `T_000 = 0` (so the mean is exactly the
    /// offset 0.5), and `S = 0.5 / max|Σ T_ijk cos cos cos|` with the maximum taken over a 48³
    /// grid of one period, so the texture spans about `[0, 1]` (a grid maximum can miss the
    /// true one by a little: values may leave `[0, 1]` by a few 10⁻³; 8-bit conversion clamps).
    /// The thesis's `S = 1/ΣT_ijk` gives `[−0.5, 1.5]`, and the safe bound `1/(2Σ|T_ijk|)`
    /// gives a washed-out texture (grey-level σ ≈ 7 for 63 components), hence this choice.
    pub fn seeded(n: usize, seed: u64) -> Result<Self> {
        let dims = [n, n, n];
        let mut rng = SplitMix64(seed);
        let mut coeffs: Vec<f64> = (0..n * n * n).map(|_| 2.0 * rng.next_f64() - 1.0).collect();
        if let Some(c0) = coeffs.first_mut() {
            *c0 = 0.0;
        }
        let unit = CosineTexture::new(dims, coeffs.clone(), 1.0, 0.0)?;
        let g = 48;
        let mut max = 0.0f64;
        for k in 0..g {
            for j in 0..g {
                for i in 0..g {
                    let p = DVec3::new(i as f64, j as f64, k as f64) / g as f64;
                    max = max.max(unit.value(p).abs());
                }
            }
        }
        let scale = if max > 0.0 { 0.5 / max } else { 1.0 };
        CosineTexture::new(dims, coeffs, scale, 0.5)
    }

    /// `[I, J, K]`.
    pub fn dims(&self) -> [usize; 3] {
        self.dims
    }

    /// Coefficients `T_ijk`, `k` fastest.
    pub fn coeffs(&self) -> &[f64] {
        &self.coeffs
    }

    /// Scale `S`.
    pub fn scale(&self) -> f64 {
        self.scale
    }

    /// Additive offset (0.5 for the thesis texture).
    pub fn offset(&self) -> f64 {
        self.offset
    }

    #[inline]
    fn coeff(&self, i: usize, j: usize, k: usize) -> f64 {
        self.coeffs[(i * self.dims[1] + j) * self.dims[2] + k]
    }

    /// Exact average of the texture over an oriented box (closed form; thesis §4-4.5). Each product
    /// of cosines is four plane waves `cos(2π f·p)`, whose average over the box is
    /// `cos(2π f·c) · Π_q sinc(2π f·a_q)`.
    pub fn box_average(&self, b: &OrientedBox) -> f64 {
        let [ni, nj, nk] = self.dims;
        let mut sum = 0.0;
        for i in 0..ni {
            for j in 0..nj {
                for k in 0..nk {
                    let c = self.coeff(i, j, k);
                    if c == 0.0 {
                        continue;
                    }
                    let mut acc = 0.0;
                    for (sj, sk) in [(1.0, 1.0), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0)] {
                        let f = DVec3::new(i as f64, sj * j as f64, sk * k as f64);
                        let mut w = (TAU * f.dot(b.center)).cos();
                        for a in &b.axes {
                            w *= sinc(TAU * f.dot(*a));
                        }
                        acc += 0.25 * w;
                    }
                    sum += c * acc;
                }
            }
        }
        self.scale * sum + self.offset
    }

    /// Calls `f(frequency, amplitude)` for each of the plane waves `amplitude·cos(2π f·p)` the
    /// texture is made of (without the offset); `f` is in cycles per texture unit.
    pub fn for_each_plane_wave(&self, mut f: impl FnMut(DVec3, f64)) {
        let [ni, nj, nk] = self.dims;
        for i in 0..ni {
            for j in 0..nj {
                for k in 0..nk {
                    let c = self.coeff(i, j, k);
                    if c == 0.0 {
                        continue;
                    }
                    for (sj, sk) in [(1.0, 1.0), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0)] {
                        f(
                            DVec3::new(i as f64, sj * j as f64, sk * k as f64),
                            0.25 * c * self.scale,
                        );
                    }
                }
            }
        }
    }
}

impl SolidTexture for CosineTexture {
    fn name(&self) -> &str {
        "cosine"
    }

    fn value(&self, p: DVec3) -> f64 {
        let [ni, nj, nk] = self.dims;
        let mut cx = [0.0; 64];
        let mut cy = [0.0; 64];
        let mut cz = [0.0; 64];
        cos_harmonics(p.x, &mut cx[..ni]);
        cos_harmonics(p.y, &mut cy[..nj]);
        cos_harmonics(p.z, &mut cz[..nk]);
        let mut sum = 0.0;
        for i in 0..ni {
            let mut si = 0.0;
            for j in 0..nj {
                let row = &self.coeffs[(i * nj + j) * nk..(i * nj + j + 1) * nk];
                let sk: f64 = row.iter().zip(&cz[..nk]).map(|(a, b)| a * b).sum();
                si += cy[j] * sk;
            }
            sum += cx[i] * si;
        }
        self.scale * sum + self.offset
    }

    fn mean(&self) -> f64 {
        self.scale * self.coeffs[0] + self.offset
    }

    fn max_frequency(&self) -> Option<f64> {
        let d = self.dims.map(|d| (d - 1) as f64);
        Some(DVec3::new(d[0], d[1], d[2]).length())
    }

    /// Thesis §5-3 (corrected: `T_ijk` appears once): every plane wave of frequency `f` is
    /// scaled by `C(φ)` with `φ² = Σ_q (f·a_q)²` over the footprint half-axes `a_q`;
    /// components with `C = 0` are skipped (thesis §5-3).
    fn clamped_value(
        &self,
        p: DVec3,
        footprint: &[DVec3; 3],
        clamp: &ClampSettings,
    ) -> Result<f64> {
        let [ni, nj, nk] = self.dims;
        // e^{2πi·n·x} per axis by repeated multiplication.
        let mut ex = [(1.0, 0.0); 64];
        let mut ey = [(1.0, 0.0); 64];
        let mut ez = [(1.0, 0.0); 64];
        for (e, x, n) in [(&mut ex, p.x, ni), (&mut ey, p.y, nj), (&mut ez, p.z, nk)] {
            let (s, c) = (TAU * x).sin_cos();
            for q in 1..n {
                let (a, b) = e[q - 1];
                e[q] = (a * c - b * s, a * s + b * c);
            }
        }
        let mut sum = 0.0;
        for i in 0..ni {
            for j in 0..nj {
                for k in 0..nk {
                    let coef = self.coeff(i, j, k);
                    if coef == 0.0 {
                        continue;
                    }
                    for (sj, sk) in [(1.0, 1.0), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0)] {
                        let f = DVec3::new(i as f64, sj * j as f64, sk * k as f64);
                        let phi2: f64 = footprint.iter().map(|a| f.dot(*a).powi(2)).sum();
                        let c = clamp.factor(phi2.sqrt());
                        if c == 0.0 {
                            continue;
                        }
                        // Re(e^{iθx} e^{±iθy} e^{±iθz}).
                        let (xr, xi) = ex[i];
                        let (yr, yi) = (ey[j].0, sj * ey[j].1);
                        let (zr, zi) = (ez[k].0, sk * ez[k].1);
                        let (ar, ai) = (xr * yr - xi * yi, xr * yi + xi * yr);
                        sum += 0.25 * coef * c * (ar * zr - ai * zi);
                    }
                }
            }
        }
        Ok(self.scale * sum + self.offset)
    }

    fn as_cosine(&self) -> Option<&CosineTexture> {
        Some(self)
    }
}

/// Ken Perlin's improved gradient noise (2002), band-limited around 1 cycle per unit, values
/// in about `[−1, 1]`; the permutation comes from a seed.
#[derive(Debug, Clone, PartialEq)]
pub struct GradientNoise {
    perm: Vec<u8>,
}

impl GradientNoise {
    /// A noise function whose permutation table is shuffled by `seed`.
    pub fn new(seed: u64) -> Self {
        let mut p: Vec<u8> = (0..=255).collect();
        let mut rng = SplitMix64(seed);
        for i in (1..256).rev() {
            let j = (rng.next_u64() % (i as u64 + 1)) as usize;
            p.swap(i, j);
        }
        let mut perm = p.clone();
        perm.extend_from_slice(&p);
        GradientNoise { perm }
    }

    #[inline]
    fn grad(hash: u8, x: f64, y: f64, z: f64) -> f64 {
        let h = hash & 15;
        let u = if h < 8 { x } else { y };
        let v = if h < 4 {
            y
        } else if h == 12 || h == 14 {
            x
        } else {
            z
        };
        (if h & 1 == 0 { u } else { -u }) + (if h & 2 == 0 { v } else { -v })
    }

    /// Noise value at `p` (texture units).
    pub fn value(&self, p: DVec3) -> f64 {
        let fl = p.floor();
        let (xi, yi, zi) = (
            (fl.x as i64 & 255) as usize,
            (fl.y as i64 & 255) as usize,
            (fl.z as i64 & 255) as usize,
        );
        let (x, y, z) = (p.x - fl.x, p.y - fl.y, p.z - fl.z);
        let fade = |t: f64| t * t * t * (t * (t * 6.0 - 15.0) + 10.0);
        let (u, v, w) = (fade(x), fade(y), fade(z));
        let pm = &self.perm;
        let a = pm[xi] as usize + yi;
        let aa = pm[a] as usize + zi;
        let ab = pm[a + 1] as usize + zi;
        let b = pm[xi + 1] as usize + yi;
        let ba = pm[b] as usize + zi;
        let bb = pm[b + 1] as usize + zi;
        let lerp = |t: f64, a: f64, b: f64| a + t * (b - a);
        let g = Self::grad;
        lerp(
            w,
            lerp(
                v,
                lerp(u, g(pm[aa], x, y, z), g(pm[ba], x - 1.0, y, z)),
                lerp(u, g(pm[ab], x, y - 1.0, z), g(pm[bb], x - 1.0, y - 1.0, z)),
            ),
            lerp(
                v,
                lerp(
                    u,
                    g(pm[aa + 1], x, y, z - 1.0),
                    g(pm[ba + 1], x - 1.0, y, z - 1.0),
                ),
                lerp(
                    u,
                    g(pm[ab + 1], x, y - 1.0, z - 1.0),
                    g(pm[bb + 1], x - 1.0, y - 1.0, z - 1.0),
                ),
            ),
        )
    }
}

/// Marble (thesis Plate 5.6; Perlin 1985): `0.5 + 0.5·sin(2π·(stripe·u + amplitude·turb(p)))`
/// with turbulence `turb(p) = Σ_{o<octaves} |noise(2^o·base·p)| / 2^o` of band-limited
/// noise. Clamping drops (or fades) octaves whose frequency aliases, as Perlin did (§5-3).
#[derive(Debug, Clone, PartialEq)]
pub struct MarbleTexture {
    noise: GradientNoise,
    /// Stripe frequency along `u`, cycles per texture unit.
    pub stripe: f64,
    /// Turbulence amplitude (stripe periods).
    pub amplitude: f64,
    /// Frequency of the first noise octave, cycles per texture unit.
    pub base: f64,
    /// Number of octaves (1..=16).
    pub octaves: usize,
}

impl MarbleTexture {
    /// A marble texture; errors if a frequency is not positive or `octaves` ∉ 1..=16.
    pub fn new(seed: u64, stripe: f64, amplitude: f64, base: f64, octaves: usize) -> Result<Self> {
        check_positive("stripe", stripe)?;
        check_positive("base", base)?;
        if !amplitude.is_finite() {
            return Err(FilterError::invalid(
                "amplitude",
                amplitude,
                "must be finite",
            ));
        }
        if !(1..=16).contains(&octaves) {
            return Err(FilterError::invalid(
                "octaves",
                octaves,
                "must be in 1..=16",
            ));
        }
        Ok(MarbleTexture {
            noise: GradientNoise::new(seed),
            stripe,
            amplitude,
            base,
            octaves,
        })
    }

    /// A default marble: stripes 2 per unit, amplitude 1, noise base 2 per unit, 6 octaves.
    pub fn default_marble(seed: u64) -> Self {
        MarbleTexture {
            noise: GradientNoise::new(seed),
            stripe: 2.0,
            amplitude: 1.0,
            base: 2.0,
            octaves: 6,
        }
    }

    fn eval(&self, p: DVec3, weight: impl Fn(f64) -> f64) -> f64 {
        let mut turb = 0.0;
        let mut f = self.base;
        let mut amp = 1.0;
        for _ in 0..self.octaves {
            let w = weight(f);
            if w == 0.0 {
                break;
            }
            turb += w * amp * self.noise.value(p * f).abs();
            f *= 2.0;
            amp *= 0.5;
        }
        0.5 + 0.5 * (TAU * (self.stripe * p.x + self.amplitude * turb)).sin()
    }
}

impl SolidTexture for MarbleTexture {
    fn name(&self) -> &str {
        "marble"
    }

    fn value(&self, p: DVec3) -> f64 {
        self.eval(p, |_| 1.0)
    }

    fn mean(&self) -> f64 {
        0.5
    }

    fn max_frequency(&self) -> Option<f64> {
        Some(
            self.stripe
                .max(self.base * 2f64.powi(self.octaves as i32 - 1)),
        )
    }

    /// Octave `o` (frequency `2^o·base`) is weighted by `C(f·|a_max|)` where `|a_max|` is the
    /// largest footprint half-axis; higher octaves stop once the weight is 0 (Perlin §5-3).
    /// The sine carrier is not attenuated (clamping cannot filter a non-linear map).
    fn clamped_value(
        &self,
        p: DVec3,
        footprint: &[DVec3; 3],
        clamp: &ClampSettings,
    ) -> Result<f64> {
        let a = footprint.iter().map(|a| a.length()).fold(0.0, f64::max);
        Ok(self.eval(p, |f| clamp.factor(f * a)))
    }
}

/// A 3-D step (half-space) texture: `high` where `n·p ≥ offset`, `low` elsewhere. Its spectrum
/// has infinite support, so it cannot be clamped (thesis §3-2); it is the half-0/half-1
/// texture of the level-weighting example (§4-4.2).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepTexture {
    /// Unit normal of the step plane.
    pub normal: DVec3,
    /// Plane offset along `normal`, texture units.
    pub offset: f64,
    /// Value below the plane.
    pub low: f64,
    /// Value on and above the plane.
    pub high: f64,
}

impl SolidTexture for StepTexture {
    fn name(&self) -> &str {
        "step"
    }

    fn value(&self, p: DVec3) -> f64 {
        if self.normal.dot(p) >= self.offset {
            self.high
        } else {
            self.low
        }
    }

    fn mean(&self) -> f64 {
        0.5 * (self.low + self.high)
    }

    fn max_frequency(&self) -> Option<f64> {
        None
    }
}

/// Reconstruction filter for discrete textures (thesis §1-4.3, App. A-1).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Reconstruction {
    /// Box / nearest: `T̄(x) = T(⌊x⌋)`; texel `s` covers `[s, s+1)`.
    SampleAndHold,
    /// Trilinear interpolation between the samples at integer coordinates.
    Trilinear,
}

/// A sampled texture of any size (rectangular, not only powers of two).
///
/// Texture space is texel units: sample `(i, j, k)` sits at the integer point `(i, j, k)`. The
/// texture is **periodic** with period `dims` along each axis (decision A-5: wrap), so it can
/// cover an infinite plane and every cell of a NIL pyramid is exact.
#[derive(Debug, Clone, PartialEq)]
pub struct DiscreteTexture {
    dims: [usize; 3],
    data: Vec<f64>,
    recon: Reconstruction,
    mean: f64,
}

/// Largest number of samples a discrete texture may hold (2²⁸).
pub const MAX_SAMPLES: usize = 1 << 28;

impl DiscreteTexture {
    /// Wraps samples (`i` fastest, then `j`, then `k`). Errors if a dimension is 0, the count
    /// exceeds [`MAX_SAMPLES`], the length does not match or a sample is not finite.
    pub fn new(dims: [usize; 3], data: Vec<f64>, recon: Reconstruction) -> Result<Self> {
        for (a, &d) in dims.iter().enumerate() {
            if d == 0 {
                return Err(FilterError::invalid(
                    format!("dims[{a}]"),
                    d,
                    "must be at least 1",
                ));
            }
        }
        let count = dims.iter().map(|&d| d as u128).product::<u128>();
        if count > MAX_SAMPLES as u128 {
            return Err(FilterError::TooLarge {
                what: "discrete texture samples".into(),
                value: count,
                limit: MAX_SAMPLES as u128,
            });
        }
        if data.len() as u128 != count {
            return Err(FilterError::invalid(
                "data",
                data.len(),
                format!("expected {count} samples"),
            ));
        }
        if let Some(pos) = data.iter().position(|v| !v.is_finite()) {
            return Err(FilterError::invalid(
                format!("sample #{pos}"),
                data[pos],
                "must be finite",
            ));
        }
        let mean = data.iter().sum::<f64>() / data.len() as f64;
        Ok(DiscreteTexture {
            dims,
            data,
            recon,
            mean,
        })
    }

    /// Samples `f(i, j, k)` on the grid.
    pub fn from_fn(
        dims: [usize; 3],
        recon: Reconstruction,
        mut f: impl FnMut(usize, usize, usize) -> f64,
    ) -> Result<Self> {
        let count = dims.iter().map(|&d| d as u128).product::<u128>();
        if count > MAX_SAMPLES as u128 {
            return Err(FilterError::TooLarge {
                what: "discrete texture samples".into(),
                value: count,
                limit: MAX_SAMPLES as u128,
            });
        }
        let mut data = Vec::with_capacity(count as usize);
        for k in 0..dims[2] {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    data.push(f(i, j, k));
                }
            }
        }
        DiscreteTexture::new(dims, data, recon)
    }

    /// Samples a procedural texture at `origin + (i, j, k)·spacing` (texture units).
    pub fn sample(
        texture: &dyn SolidTexture,
        dims: [usize; 3],
        origin: DVec3,
        spacing: f64,
        recon: Reconstruction,
    ) -> Result<Self> {
        check_positive("spacing", spacing)?;
        DiscreteTexture::from_fn(dims, recon, |i, j, k| {
            texture.value(origin + DVec3::new(i as f64, j as f64, k as f64) * spacing)
        })
    }

    /// Converts a `volsplat-core` volume (its sample values, not its world geometry).
    pub fn from_volume<T: Scalar>(volume: &Volume<T>, recon: Reconstruction) -> Result<Self> {
        let data = volume.data().iter().map(|v| v.to_f32() as f64).collect();
        DiscreteTexture::new(volume.grid().dims, data, recon)
    }

    /// Sample counts along x, y, z.
    pub fn dims(&self) -> [usize; 3] {
        self.dims
    }

    /// Samples, `i` fastest.
    pub fn data(&self) -> &[f64] {
        &self.data
    }

    /// The reconstruction filter.
    pub fn reconstruction(&self) -> Reconstruction {
        self.recon
    }

    /// A copy with another reconstruction filter.
    pub fn with_reconstruction(&self, recon: Reconstruction) -> Self {
        DiscreteTexture {
            recon,
            ..self.clone()
        }
    }

    /// A copy with every sample mapped through `f` (e.g. a transfer function).
    pub fn map(&self, f: impl Fn(f64) -> f64) -> Result<Self> {
        DiscreteTexture::new(
            self.dims,
            self.data.iter().map(|&v| f(v)).collect(),
            self.recon,
        )
    }

    /// Sample at integer coordinates, wrapped periodically.
    #[inline]
    pub fn at(&self, i: i64, j: i64, k: i64) -> f64 {
        let [nx, ny, nz] = self.dims;
        let w = |x: i64, n: usize| x.rem_euclid(n as i64) as usize;
        self.data[(w(k, nz) * ny + w(j, ny)) * nx + w(i, nx)]
    }
}

impl SolidTexture for DiscreteTexture {
    fn name(&self) -> &str {
        match self.recon {
            Reconstruction::SampleAndHold => "discrete (sample-and-hold)",
            Reconstruction::Trilinear => "discrete (trilinear)",
        }
    }

    fn value(&self, p: DVec3) -> f64 {
        let f = p.floor();
        let (i, j, k) = (f.x as i64, f.y as i64, f.z as i64);
        match self.recon {
            Reconstruction::SampleAndHold => self.at(i, j, k),
            Reconstruction::Trilinear => {
                let (x, y, z) = (p.x - f.x, p.y - f.y, p.z - f.z);
                let mut acc = 0.0;
                for (dk, wz) in [(0, 1.0 - z), (1, z)] {
                    for (dj, wy) in [(0, 1.0 - y), (1, y)] {
                        for (di, wx) in [(0, 1.0 - x), (1, x)] {
                            acc += wx * wy * wz * self.at(i + di, j + dj, k + dk);
                        }
                    }
                }
                acc
            }
        }
    }

    fn mean(&self) -> f64 {
        self.mean
    }

    fn max_frequency(&self) -> Option<f64> {
        // Nyquist of unit sampling: EWA then samples about once per texel.
        Some(0.5)
    }

    fn as_discrete(&self) -> Option<&DiscreteTexture> {
        Some(self)
    }
}

/// A constant texture (NIL normalisation tests, thesis eqs 4.10–4.16).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ConstantTexture(pub f64);

impl SolidTexture for ConstantTexture {
    fn name(&self) -> &str {
        "constant"
    }
    fn value(&self, _p: DVec3) -> f64 {
        self.0
    }
    fn mean(&self) -> f64 {
        self.0
    }
    fn max_frequency(&self) -> Option<f64> {
        Some(0.0)
    }
    fn clamped_value(&self, _p: DVec3, _f: &[DVec3; 3], _c: &ClampSettings) -> Result<f64> {
        Ok(self.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cosine_is_periodic_and_in_range() {
        let t = CosineTexture::seeded(4, 7).unwrap();
        let mut rng = SplitMix64(3);
        for _ in 0..200 {
            let p = DVec3::new(rng.next_f64(), rng.next_f64(), rng.next_f64()) * 5.0;
            let v = t.value(p);
            assert!((-0.01..=1.01).contains(&v), "{v}");
            assert!((v - t.value(p + DVec3::X)).abs() < 1e-12);
            assert!((v - t.value(p + DVec3::Z * 3.0)).abs() < 1e-12);
        }
        assert!((t.mean() - 0.5).abs() < 1e-15);
    }

    #[test]
    fn cosine_box_average_matches_brute_force() {
        let t = CosineTexture::seeded(4, 11).unwrap();
        let b = OrientedBox {
            center: DVec3::new(0.3, 0.7, 0.1),
            axes: [
                DVec3::new(0.1, 0.05, 0.0),
                DVec3::new(-0.02, 0.04, 0.0),
                DVec3::new(0.0, 0.0, 0.03),
            ],
        };
        let n = 60;
        let mut sum = 0.0;
        for a in 0..n {
            for c in 0..n {
                for d in 0..n {
                    let s = |q: usize| -1.0 + (2 * q + 1) as f64 / n as f64;
                    sum += t.value(b.point(s(a), s(c), s(d)));
                }
            }
        }
        let brute = sum / (n * n * n) as f64;
        assert!(
            (brute - t.box_average(&b)).abs() < 1e-4,
            "{brute} vs {}",
            t.box_average(&b)
        );
    }

    #[test]
    fn clamping_limits() {
        use crate::clamp::{ClampKind, ClampSettings};
        let t = CosineTexture::seeded(4, 5).unwrap();
        let p = DVec3::new(0.2, 0.4, 0.9);
        let tiny = [DVec3::X * 1e-9, DVec3::Y * 1e-9, DVec3::Z * 1e-9];
        let huge = [DVec3::X * 1e3, DVec3::Y * 1e3, DVec3::Z * 1e3];
        for kind in [ClampKind::Step, ClampKind::Quadratic, ClampKind::Norton] {
            let c = ClampSettings { kind, phi_max: 0.5 };
            assert!((t.clamped_value(p, &tiny, &c).unwrap() - t.value(p)).abs() < 1e-12);
            assert!((t.clamped_value(p, &huge, &c).unwrap() - t.mean()).abs() < 1e-12);
        }
    }

    #[test]
    fn step_cannot_be_clamped() {
        let s = StepTexture {
            normal: DVec3::X,
            offset: 0.5,
            low: 0.0,
            high: 1.0,
        };
        let c = ClampSettings::default();
        assert!(matches!(
            s.clamped_value(DVec3::ZERO, &[DVec3::X; 3], &c),
            Err(FilterError::NotApplicable { .. })
        ));
    }

    #[test]
    fn discrete_reconstruction_f_b01() {
        let t = DiscreteTexture::from_fn([5, 3, 4], Reconstruction::Trilinear, |i, j, k| {
            (i * 7 + j * 3 + k * 11) as f64 % 5.0
        })
        .unwrap();
        // Trilinear hits samples at grid points.
        for (i, j, k) in [(0, 0, 0), (4, 2, 3), (2, 1, 1)] {
            let p = DVec3::new(i as f64, j as f64, k as f64);
            assert!((t.value(p) - t.at(i, j, k)).abs() < 1e-12);
        }
        // Integral over a voxel = mean of the 8 corners (midpoint rule is exact on multilinear
        // functions when averaged over a symmetric grid).
        let n = 8;
        let mut sum = 0.0;
        for a in 0..n {
            for b in 0..n {
                for c in 0..n {
                    let f = |q: usize| (q as f64 + 0.5) / n as f64;
                    sum += t.value(DVec3::new(1.0 + f(a), 1.0 + f(b), 2.0 + f(c)));
                }
            }
        }
        let mut corners = 0.0;
        for (di, dj, dk) in (0..8).map(|c| (c & 1, (c >> 1) & 1, c >> 2)) {
            corners += t.at(1 + di, 1 + dj, 2 + dk);
        }
        assert!((sum / (n * n * n) as f64 - corners / 8.0).abs() < 1e-12);
        // Periodic wrap.
        let p = DVec3::new(0.3, 1.2, 2.7);
        assert!((t.value(p) - t.value(p + DVec3::new(5.0, -3.0, 8.0))).abs() < 1e-12);
        let h = t.with_reconstruction(Reconstruction::SampleAndHold);
        assert_eq!(h.value(DVec3::new(1.9, 0.2, 3.99)), h.at(1, 0, 3));
    }

    #[test]
    fn noise_is_bounded_and_marble_in_range() {
        let m = MarbleTexture::default_marble(1);
        let mut rng = SplitMix64(9);
        for _ in 0..500 {
            let p = DVec3::new(rng.next_f64(), rng.next_f64(), rng.next_f64()) * 10.0;
            let v = m.value(p);
            assert!((0.0..=1.0).contains(&v));
            assert!(m.noise.value(p).abs() <= 1.2);
        }
    }
}
