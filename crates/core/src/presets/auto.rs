//! The automatic transfer function: a volume's [`Histogram`], Otsu's split of it, and
//! [`AutoTransfer`], which makes the background transparent and ramps opacity and colour over
//! robust percentiles of the rest (`docs/presets.md`).

use super::*;

/// Sample counts in equal-width bins over a range of values (data units). Built in one pass
/// over the samples once the range is known, so a volume streamed in slabs can be counted as
/// it passes (docs/design.md §5).
#[derive(Debug, Clone, PartialEq)]
pub struct Histogram {
    /// Lower edge of bin 0, data units.
    lo: f64,
    /// Bin width, data units (0 when the range is a single value).
    width: f64,
    counts: Vec<u64>,
}

impl Histogram {
    /// Number of bins [`Histogram::for_scalar_type`] uses for float data.
    pub const FLOAT_BINS: usize = 4096;
    /// Largest number of bins: enough for one bin per value of any 16-bit type.
    pub const MAX_BINS: usize = 1 << 16;

    /// An empty histogram of `bins` equal bins over `[lo, hi]` (data units, finite,
    /// `lo ≤ hi`, `1 ≤ bins ≤` [`Histogram::MAX_BINS`]). With `lo == hi` every value falls in
    /// bin 0.
    pub fn new(lo: f64, hi: f64, bins: usize) -> Result<Self> {
        if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
            return Err(CoreError::invalid(
                "histogram range",
                (lo, hi),
                "needs finite lo <= hi",
            ));
        }
        if !(1..=Self::MAX_BINS).contains(&bins) {
            return Err(CoreError::invalid(
                "histogram bins",
                bins,
                format!("must be in 1..={}", Self::MAX_BINS),
            ));
        }
        let width = (hi - lo) / bins as f64;
        Ok(Histogram {
            lo,
            width: if width.is_finite() { width } else { 0.0 },
            counts: vec![0; bins],
        })
    }

    /// An empty histogram suited to samples of type `t` spanning `range` (smallest and largest
    /// sample, data units): for integer types one bin per integer value (bin centres on the
    /// integers; at most [`Histogram::MAX_BINS`], which every 8- and 16-bit type fits), for
    /// `f32` [`Histogram::FLOAT_BINS`] bins over the range.
    pub fn for_scalar_type(t: ScalarType, range: (f64, f64)) -> Result<Self> {
        match t {
            ScalarType::F32 => Self::new(range.0, range.1, Self::FLOAT_BINS),
            _ => {
                let (lo, hi) = (range.0.floor(), range.1.ceil());
                let span = hi - lo + 1.0;
                if !(span >= 1.0 && span <= Self::MAX_BINS as f64) {
                    return Self::new(range.0, range.1, Self::MAX_BINS);
                }
                Self::new(lo - 0.5, hi + 0.5, span as usize)
            }
        }
    }

    /// The histogram of every sample of `vol`, with the bins of
    /// [`Histogram::for_scalar_type`] over the volume's value range.
    pub fn from_volume(vol: &AnyVolume) -> Self {
        let range = vol.value_range();
        let mut h = Self::for_scalar_type(vol.scalar_type(), range).unwrap_or(Histogram {
            lo: 0.0,
            width: 0.0,
            counts: vec![0],
        });
        crate::with_volume!(vol, v => {
            for x in v.data() {
                h.add(x.to_f32() as f64);
            }
        });
        h
    }

    /// Counts one sample (data units). Values beyond the range go to the end bins; NaN and
    /// infinities are ignored.
    #[inline]
    pub fn add(&mut self, value: f64) {
        if !value.is_finite() {
            return;
        }
        let last = self.counts.len() - 1;
        let bin = if self.width > 0.0 {
            let t = ((value - self.lo) / self.width).floor();
            if t <= 0.0 {
                0
            } else if t >= last as f64 {
                last
            } else {
                t as usize
            }
        } else {
            0
        };
        self.counts[bin] += 1;
    }

    /// The counts, bin 0 (lowest values) first.
    pub fn counts(&self) -> &[u64] {
        &self.counts
    }

    /// Number of samples counted.
    pub fn total(&self) -> u64 {
        self.counts.iter().sum()
    }

    /// Bin width, data units (0 when the range is one value).
    pub fn bin_width(&self) -> f64 {
        self.width
    }

    /// Centre of bin `n`, data units.
    pub fn bin_center(&self, n: usize) -> f64 {
        self.lo + (n as f64 + 0.5) * self.width
    }

    /// Upper edge of bin `n`, data units.
    pub fn bin_upper(&self, n: usize) -> f64 {
        self.lo + (n as f64 + 1.0) * self.width
    }

    /// The centre (data units) of the first bin at which the cumulative count reaches the
    /// fraction `q` (clamped to [0, 1]) of all samples; `None` for an empty histogram.
    pub fn quantile(&self, q: f64) -> Option<f64> {
        self.quantile_from(0, q)
    }

    /// [`Histogram::quantile`] of the samples in bins `start..`.
    fn quantile_from(&self, start: usize, q: f64) -> Option<f64> {
        let counts = self.counts.get(start..)?;
        let total: u64 = counts.iter().sum();
        if total == 0 {
            return None;
        }
        let q = if q.is_nan() { 0.5 } else { q.clamp(0.0, 1.0) };
        let need = (q * total as f64).ceil().max(1.0);
        let mut acc = 0u64;
        for (n, c) in counts.iter().enumerate() {
            acc += c;
            if acc as f64 >= need {
                return Some(self.bin_center(start + n));
            }
        }
        Some(self.bin_center(self.counts.len() - 1))
    }

    /// Otsu's threshold (Otsu 1979, between-class variance) over bins `range`: `None` if fewer
    /// than two of them are occupied. Ties go to the lowest bin, so the result is deterministic.
    fn otsu(&self, range: std::ops::Range<usize>) -> Option<OtsuSplit> {
        let counts = self.counts.get(range.clone())?;
        let (mut n_all, mut s_all) = (0.0f64, 0.0f64);
        for (n, &c) in counts.iter().enumerate() {
            n_all += c as f64;
            s_all += c as f64 * self.bin_center(range.start + n);
        }
        let (mut w0, mut s0) = (0.0f64, 0.0f64);
        let mut best: Option<(f64, usize)> = None;
        for (n, &c) in counts.iter().enumerate() {
            w0 += c as f64;
            s0 += c as f64 * self.bin_center(range.start + n);
            let w1 = n_all - w0;
            if w0 == 0.0 || w1 == 0.0 {
                continue;
            }
            let d = s0 / w0 - (s_all - s0) / w1;
            let between = w0 * w1 * d * d;
            if best.is_none_or(|(b, _)| between > b) {
                best = Some((between, range.start + n));
            }
        }
        let (_, k) = best?;
        let moments = |bins: std::ops::Range<usize>| {
            let (mut w, mut s, mut ss, mut occupied) = (0.0f64, 0.0f64, 0.0f64, 0usize);
            for n in bins {
                let c = self.counts[n] as f64;
                let x = self.bin_center(n);
                w += c;
                s += c * x;
                ss += c * x * x;
                occupied += usize::from(c > 0.0);
            }
            let mean = s / w;
            (w, mean, (ss / w - mean * mean).max(0.0).sqrt(), occupied)
        };
        let (weight0, mean0, sigma0, occupied0) = moments(range.start..k + 1);
        let (_, mean1, _, _) = moments(k + 1..range.end);
        Some(OtsuSplit {
            k,
            weight0,
            mean0,
            sigma0,
            occupied0,
            mean1,
        })
    }
}

/// Otsu's split of a run of bins: the lower class is bins `..=k`.
struct OtsuSplit {
    k: usize,
    weight0: f64,
    mean0: f64,
    sigma0: f64,
    occupied0: usize,
    mean1: f64,
}

/// How [`AutoTransfer`] found the background.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum BackgroundRule {
    /// Otsu's lower class, which was tight and far below the rest (see [`AutoTransfer`]).
    Otsu,
    /// Only the lowest value, a fill value (padding, a mask's outside) apart from the rest; the
    /// rest had no background of its own.
    FillValue,
    /// No background was found: every value above the data minimum is shown.
    None,
    /// The histogram is empty or holds a single value: the grey [`Preset::Ramp`].
    Degenerate,
}

/// The automatic transfer function for data with no preset, and how it was chosen.
///
/// The rule (deterministic; `docs/presets.md` discusses its limits):
/// 1. **Background.** Otsu's threshold splits the histogram in two. If the lower class is
///    essentially one value (the lowest value holds [`AutoTransfer::FILL_SHARE`] of it: a *fill
///    value*, such as the −3024 HU padding outside a CT's field of view or the 0 outside a
///    masked MRI), that value is background and Otsu is applied once more to the values above
///    it. Otherwise (and in that second round) Otsu's lower class is background when it is tight
///    and far below the rest: its mean at least [`AutoTransfer::SEPARATION`] of its standard
///    deviations (at least one bin width) below the upper class's mean, as air is below tissue
///    in CT and noise below tissue in MR, but not the two halves of one tissue's range.
///    Otherwise there is no further background.
/// 2. **Foreground percentiles.** Of the samples above the background threshold `t`, the
///    percentiles [`AutoTransfer::PERCENTILES`] (5th, 50th, 99th: robust to outliers such as
///    metal or hot voxels).
/// 3. **Transfer function.** 3D Slicer's `MR-Default` re-fitted to these landmarks: its control
///    points at 20, 40, 120, 220 and 1024 move to `t`, P5, P50, P99 and the data maximum, with
///    opacity 0, 0.15, 0.3, 0.375, 0.5 and colour dark red → brown → tan → ivory → white;
///    opacity is 0 at and below `t`. Shading as `MR-Default` (ambient 0.2, diffuse 1,
///    specular 0). Opacities are per `scalar_opacity_unit_distance`, which
///    [`AutoTransfer::from_volume`] sets to the smallest voxel spacing (so they are per voxel
///    step, whatever the world unit) and [`AutoTransfer::from_histogram`] leaves at 1.
/// 4. **Few values** (a binary mask, a label image: at most [`AutoTransfer::FEW_VALUES`]
///    distinct values above `t`, at bin resolution) replace step 3: every foreground value is
///    opaque, [`AutoTransfer::FEW_OPACITY`] per unit distance from halfway between `t` and the
///    lowest foreground value on, each in its own colour of [`AutoTransfer::LABEL_COLORS`]
///    (ivory for the first). The percentile ramp would give such data a dim, dark shell of
///    partial-volume values around an interior whose zero gradient reflects no light: a nearly
///    black picture. With the opacity reached at the boundary, the lit surface hides it.
/// 5. **One value** (constant data): the unshaded grey ramp of [`Preset::Ramp`], ending at the
///    value, so that it shows (opacity 0.5, white) rather than nothing.
#[derive(Debug, Clone, PartialEq)]
pub struct AutoTransfer {
    /// The transfer function (values in data units).
    pub transfer_function: TransferFunction,
    /// How the background was found.
    pub rule: BackgroundRule,
    /// The fill value found (data units), if any; it is part of the background.
    pub fill_value: Option<f64>,
    /// Background threshold `t`, data units: samples at or below it are transparent.
    pub threshold: f64,
    /// The foreground percentiles [`AutoTransfer::PERCENTILES`] of the samples above
    /// `threshold`, data units (at bin resolution).
    pub foreground: [f64; 3],
    /// The distinct foreground values (bin centres, data units) where there are at most
    /// [`AutoTransfer::FEW_VALUES`] of them (rule step 4: each opaque in its own colour);
    /// empty otherwise.
    pub labels: Vec<f64>,
}

impl AutoTransfer {
    /// The foreground percentiles (fractions) that place the opacity and colour ramp.
    pub const PERCENTILES: [f64; 3] = [0.05, 0.5, 0.99];
    /// The lowest value is a fill value when it holds at least this share (90%) of Otsu's lower
    /// class: Otsu's threshold next to a spike takes in a few samples of the other class's
    /// tail, so the class is rarely the spike alone.
    pub const FILL_SHARE: f64 = 0.9;
    /// Otsu's lower class is background only if `(mean₁ − mean₀) ≥ SEPARATION · σ₀`: 4.5,
    /// between what splitting one noisy tissue gives (2.7 for a Gaussian, 3.5 for a uniform
    /// spread, 3.1 and 3.9 for the Colin27 MRI's head above its fill value and for a
    /// skull-stripped version of it) and a real background (6.2 for Colin27's, 11 for
    /// brainsmall's, about 60 for CT air).
    pub const SEPARATION: f64 = 4.5;
    /// At most this many distinct foreground values make a label image (rule step 4): a binary
    /// mask has one, a small segmentation a few.
    pub const FEW_VALUES: usize = 8;
    /// Opacity per unit distance (per voxel step from [`AutoTransfer::from_volume`]) of every
    /// value of a label image: the boundary between background and label is opaque within a
    /// voxel, so its surface, which has a gradient, is what is seen and lit.
    pub const FEW_OPACITY: f64 = 0.8;
    /// The colours of a label image's foreground values, lowest first (cycled beyond eight):
    /// ivory (`MR-Default`'s tissue colour at its 99th percentile), then well-separated hues.
    pub const LABEL_COLORS: [[f64; 3]; 8] = [
        [0.847059, 0.835294, 0.788235],
        [0.87, 0.45, 0.35],
        [0.45, 0.68, 0.88],
        [0.55, 0.80, 0.45],
        [0.95, 0.80, 0.35],
        [0.72, 0.55, 0.88],
        [0.95, 0.60, 0.25],
        [0.45, 0.85, 0.80],
    ];

    /// The automatic transfer function of `vol`, with `scalar_opacity_unit_distance` the
    /// smallest voxel spacing (world units), so that opacities hold per voxel step.
    ///
    /// A volume of one sample along an axis (a 2-D image, a single slice) is drawn unshaded:
    /// its gradients lie in its plane (zero along the one-sample axis, and zero wherever the
    /// image is flat), so lights would leave it black but for its edges.
    pub fn from_volume(vol: &AnyVolume) -> Self {
        let mut auto = Self::from_histogram(&Histogram::from_volume(vol));
        let spacing = vol.grid().spacing;
        let unit = spacing.iter().copied().fold(f64::INFINITY, f64::min);
        if unit.is_finite() && unit > 0.0 {
            auto.transfer_function.scalar_opacity_unit_distance = unit;
        }
        if vol.grid().dims.contains(&1) {
            auto.transfer_function.shade = false;
        }
        auto
    }

    /// The automatic transfer function for a histogram (see [`AutoTransfer`] for the rule);
    /// `scalar_opacity_unit_distance` is 1 world unit.
    pub fn from_histogram(h: &Histogram) -> Self {
        let counts = h.counts();
        let first = counts.iter().position(|&c| c > 0);
        let last = counts.iter().rposition(|&c| c > 0);
        let (Some(first), Some(last)) = (first, last) else {
            return Self::degenerate(0.0, 1.0);
        };
        let (lo, hi) = (h.bin_center(first), h.bin_center(last));
        if first == last {
            return Self::degenerate(lo, hi);
        }
        let separated = |s: &OtsuSplit| {
            let sigma = s.sigma0.max(h.bin_width());
            s.occupied0 >= 2 && s.mean1 - s.mean0 >= Self::SEPARATION * sigma
        };
        let otsu = |s: &OtsuSplit| (BackgroundRule::Otsu, s.k + 1, h.bin_upper(s.k));
        let mut fill_value = None;
        // Bins of the foreground start at `start`; the threshold is the background's top.
        let (rule, start, threshold) = match h.otsu(first..last + 1) {
            Some(s) if counts[first] as f64 >= Self::FILL_SHARE * s.weight0 => {
                fill_value = Some(lo);
                match h.otsu(first + 1..last + 1) {
                    Some(r) if separated(&r) => otsu(&r),
                    _ => (BackgroundRule::FillValue, first + 1, h.bin_upper(first)),
                }
            }
            Some(s) if separated(&s) => otsu(&s),
            _ => (BackgroundRule::None, first, lo),
        };
        let q = |p: f64| h.quantile_from(start, p).unwrap_or(hi);
        let labels: Vec<f64> = (start..=last)
            .filter(|&n| counts[n] > 0)
            .map(|n| h.bin_center(n))
            .collect();
        if !labels.is_empty() && labels.len() <= Self::FEW_VALUES {
            let foreground = [q(0.05), q(0.5), q(0.99)];
            return Self::label_image(rule, fill_value, threshold, lo, labels, foreground);
        }
        let p = Self::PERCENTILES;
        let p_lo = q(p[0]).max(threshold);
        let p_mid = q(p[1]).max(p_lo);
        let p_hi = q(p[2]).max(p_mid);
        let top = hi.max(p_hi);
        let bottom = lo.min(threshold);
        // Slicer's MR-Default (colours and opacities), moved to these landmarks.
        let tf = TransferFunction {
            color: vec![
                [bottom, 0.0, 0.0, 0.0],
                [threshold, 0.168627, 0.0, 0.0],
                [p_lo, 0.403922, 0.145098, 0.0784314],
                [p_mid, 0.780392, 0.607843, 0.380392],
                [p_hi, 0.847059, 0.835294, 0.788235],
                [top, 1.0, 1.0, 1.0],
            ],
            scalar_opacity: vec![
                [bottom, 0.0],
                [threshold, 0.0],
                [p_lo, 0.15],
                [p_mid, 0.3],
                [p_hi, 0.375],
                [top, 0.5],
            ],
            gradient_opacity: None,
            scalar_opacity_unit_distance: 1.0,
            shade: true,
            ambient: 0.2,
            diffuse: 1.0,
            specular: 0.0,
            specular_power: 1.0,
        };
        AutoTransfer {
            transfer_function: tf,
            rule,
            fill_value,
            threshold,
            foreground: [p_lo, p_mid, p_hi],
            labels: Vec::new(),
        }
    }

    /// Rule step 4: the foreground is the few values `labels` (ascending, above `threshold`),
    /// each opaque in its own colour; `lo` is the lowest value of the data.
    fn label_image(
        rule: BackgroundRule,
        fill_value: Option<f64>,
        threshold: f64,
        lo: f64,
        labels: Vec<f64>,
        foreground: [f64; 3],
    ) -> Self {
        let color = |n: usize| Self::LABEL_COLORS[n % Self::LABEL_COLORS.len()];
        let first = labels[0];
        let top = labels[labels.len() - 1];
        let bottom = lo.min(threshold);
        let rgb = |x: f64, c: [f64; 3]| [x, c[0], c[1], c[2]];
        let mut colors = vec![rgb(bottom, color(0)), rgb(threshold, color(0))];
        colors.extend(labels.iter().enumerate().map(|(n, &v)| rgb(v, color(n))));
        // Opaque from halfway to the first label: the background–label boundary's middle.
        let a = Self::FEW_OPACITY;
        let tf = TransferFunction {
            color: colors,
            scalar_opacity: vec![
                [bottom, 0.0],
                [threshold, 0.0],
                [0.5 * (threshold + first), a],
                [top, a],
            ],
            gradient_opacity: None,
            scalar_opacity_unit_distance: 1.0,
            shade: true,
            ambient: 0.2,
            diffuse: 1.0,
            specular: 0.0,
            specular_power: 1.0,
        };
        AutoTransfer {
            transfer_function: tf,
            rule,
            fill_value,
            threshold,
            foreground,
            labels,
        }
    }

    /// Rule step 5 (and an empty histogram): the grey ramp of [`Preset::Ramp`] over
    /// `[lo, hi]`, or, for one value, over the unit below it, which the value ends.
    fn degenerate(lo: f64, hi: f64) -> Self {
        let range = if hi > lo { (lo, hi) } else { (lo - 1.0, lo) };
        AutoTransfer {
            transfer_function: Preset::Ramp.transfer_function(range),
            rule: BackgroundRule::Degenerate,
            fill_value: None,
            threshold: range.0,
            foreground: [lo, lo, hi],
            labels: Vec::new(),
        }
    }

    /// One line for a log: the rule, the threshold and the ramp's landmarks (data units).
    pub fn describe(&self) -> String {
        let [a, b, c] = self.foreground;
        let t = self.threshold;
        let fill = self
            .fill_value
            .map(|f| format!("fill value {f}, "))
            .unwrap_or_default();
        match self.rule {
            BackgroundRule::Degenerate => {
                format!("automatic transfer function: constant or empty data, grey ramp up to {c}")
            }
            _ if !self.labels.is_empty() => {
                let values: Vec<String> = self.labels.iter().map(|v| v.to_string()).collect();
                format!(
                    "automatic transfer function: {fill}background <= {t} transparent; {} \
                     foreground value{} ({}) opaque, {} per voxel, one colour each (a mask or \
                     label image)",
                    values.len(),
                    if values.len() == 1 { "" } else { "s" },
                    values.join(", "),
                    Self::FEW_OPACITY
                )
            }
            BackgroundRule::None => format!(
                "automatic transfer function: no background found; opacity ramp from {t} over \
                 {a} / {b} / {c} (foreground P5 / P50 / P99)"
            ),
            BackgroundRule::FillValue | BackgroundRule::Otsu => format!(
                "automatic transfer function: {fill}background <= {t} ({}) transparent; opacity \
                 ramp over {a} / {b} / {c} (foreground P5 / P50 / P99)",
                if self.rule == BackgroundRule::Otsu {
                    "Otsu"
                } else {
                    "fill value"
                }
            ),
        }
    }
}
