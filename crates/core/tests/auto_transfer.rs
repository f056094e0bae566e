//! The automatic transfer function shows the object, not fog: rendered opacity inside the
//! object's silhouette against opacity outside it, on synthetic CT and MR volumes and on the two
//! real MRIs of `shared/data` (skipped when absent), compared with the former default (the
//! `ramp` preset over the data range).
//!
//! The rendering is an axis-aligned orthographic emission–absorption integral through the voxel
//! samples, with the opacity looked up in the compiled CRIO opacity table and corrected for the
//! step (`α' = 1 − (1 − α)^(Δs/unit)`, docs/design.md §3), front to back. Only opacity matters for
//! the silhouette contrast, so colour and shading are left out.

use volsplat_core::crio::DEFAULT_TABLE_LEN;
use volsplat_core::phantom::ct_head_volume;
use volsplat_core::{
    AnyVolume, AutoTransfer, BackgroundRule, CrioTables, Grid, TransferFunction, Volume,
};
use volsplat_testkit::data::{read_u8_nrrd, shared_data};

/// Accumulated opacity of the parallel projection of `vol` along grid axis `axis` (0, 1, 2):
/// one value per ray, rays over the other two axes.
fn project_alpha(vol: &Volume<f32>, tf: &TransferFunction, axis: usize) -> Vec<f32> {
    let tables = CrioTables::from_transfer_function(tf, DEFAULT_TABLE_LEN).unwrap();
    let g = vol.grid();
    let step = g.spacing[axis] / tf.scalar_opacity_unit_distance;
    let (a, b) = match axis {
        0 => (1, 2),
        1 => (0, 2),
        _ => (0, 1),
    };
    let mut out = Vec::with_capacity(g.dims[a] * g.dims[b]);
    for v in 0..g.dims[b] {
        for u in 0..g.dims[a] {
            let mut acc = 0.0f64;
            for w in 0..g.dims[axis] {
                let mut ijk = [0; 3];
                (ijk[a], ijk[b], ijk[axis]) = (u, v, w);
                let [alpha] = tables.opacity.lookup(vol.get(ijk[0], ijk[1], ijk[2]));
                let alpha = 1.0 - (1.0 - alpha as f64).powf(step);
                acc += (1.0 - acc) * alpha;
            }
            out.push(acc as f32);
        }
    }
    out
}

/// Rays (in the order of [`project_alpha`]) that count as object and as background: a ray is
/// object where at least `min_count` samples satisfy `inside`, background where none does.
fn ray_masks(
    vol: &Volume<f32>,
    axis: usize,
    min_count: usize,
    inside: impl Fn(f32) -> bool,
) -> (Vec<bool>, Vec<bool>) {
    let g = vol.grid();
    let (a, b) = match axis {
        0 => (1, 2),
        1 => (0, 2),
        _ => (0, 1),
    };
    let (mut object, mut background) = (Vec::new(), Vec::new());
    for v in 0..g.dims[b] {
        for u in 0..g.dims[a] {
            let mut n = 0;
            for w in 0..g.dims[axis] {
                let mut ijk = [0; 3];
                (ijk[a], ijk[b], ijk[axis]) = (u, v, w);
                n += usize::from(inside(vol.get(ijk[0], ijk[1], ijk[2])));
            }
            object.push(n >= min_count);
            background.push(n == 0);
        }
    }
    (object, background)
}

/// Mean opacity over the object rays and over the background rays.
#[derive(Debug, Clone, Copy)]
struct Contrast {
    object: f64,
    background: f64,
}

impl Contrast {
    /// The object stands out: nearly opaque where it is, nearly clear where it is not.
    fn shows_object(&self) -> bool {
        self.object >= 0.9 && self.background <= 0.02
    }
}

fn mean_over(alpha: &[f32], mask: &[bool]) -> f64 {
    let (mut s, mut n) = (0.0, 0usize);
    for (a, &m) in alpha.iter().zip(mask) {
        if m {
            s += *a as f64;
            n += 1;
        }
    }
    assert!(n > 0, "empty mask");
    s / n as f64
}

/// Contrast of `tf` on `vol` seen along `axis`, with masks from `truth` (same grid).
fn contrast(
    vol: &Volume<f32>,
    truth: &Volume<f32>,
    tf: &TransferFunction,
    axis: usize,
    min_count: usize,
    inside: impl Fn(f32) -> bool,
) -> Contrast {
    let alpha = project_alpha(vol, tf, axis);
    let (object, background) = ray_masks(truth, axis, min_count, inside);
    Contrast {
        object: mean_over(&alpha, &object),
        background: mean_over(&alpha, &background),
    }
}

/// The former default for a volume with no transfer function: the `ramp` preset over the data
/// range.
fn former_default(vol: &AnyVolume) -> TransferFunction {
    TransferFunction::preset("ramp", vol.value_range()).unwrap()
}

/// A deterministic normal generator (SplitMix64 and Box–Muller).
struct Noise(u64);

impl Noise {
    fn uniform(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        ((z >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }

    fn normal(&mut self) -> f64 {
        let (u, v) = (self.uniform(), self.uniform());
        (-2.0 * u.ln()).sqrt() * (2.0 * std::f64::consts::PI * v).cos()
    }

    /// A Rician sample: the magnitude of `mean + σ·(n₁ + i·n₂)`, as in MR magnitude images.
    fn rician(&mut self, mean: f64, sigma: f64) -> f64 {
        let re = mean + sigma * self.normal();
        let im = sigma * self.normal();
        re.hypot(im)
    }
}

/// Runs the comparison on every axis; prints the numbers; returns (former, auto) contrasts.
fn compare(
    name: &str,
    vol: &AnyVolume,
    truth: &Volume<f32>,
    min_count: usize,
    inside: impl Fn(f32) -> bool + Copy,
) -> Vec<(Contrast, Contrast)> {
    let f32vol = vol.to_f32();
    let auto = AutoTransfer::from_volume(vol);
    eprintln!("{name}: {}", auto.describe());
    let old = former_default(vol);
    (0..3)
        .map(|axis| {
            let before = contrast(&f32vol, truth, &old, axis, min_count, inside);
            let after = contrast(
                &f32vol,
                truth,
                &auto.transfer_function,
                axis,
                min_count,
                inside,
            );
            eprintln!(
                "{name} axis {axis}: mean alpha object / background: ramp default {:.3} / {:.3}, \
                 auto {:.3} / {:.3}",
                before.object, before.background, after.object, after.background
            );
            (before, after)
        })
        .collect()
}

/// The CT head phantom (air −1000 HU, soft tissue 40 HU, bone 1000 HU) with scanner-like noise
/// (σ = 20 HU), optionally padded with −3024 HU outside a cylindrical field of view.
fn noisy_ct(padding: bool) -> (AnyVolume, Volume<f32>) {
    let clean = ct_head_volume([64, 64, 64]).unwrap();
    let truth = clean.to_f32();
    let g = clean.grid().clone();
    let [nx, ny, _] = g.dims;
    let mut noise = Noise(7);
    let noisy = Volume::from_fn(g, |i, j, k| {
        let x = (i as f64 + 0.5) / nx as f64 * 2.0 - 1.0;
        let y = (j as f64 + 0.5) / ny as f64 * 2.0 - 1.0;
        if padding && x * x + y * y > 1.0 {
            return -3024i16;
        }
        let v = clean.get(i, j, k) as f64 + 20.0 * noise.normal();
        v.round().clamp(-1024.0, 3071.0) as i16
    })
    .unwrap();
    (AnyVolume::from(noisy), truth)
}

#[test]
fn ct_phantom_shows_the_body_with_and_without_padding() {
    for padding in [false, true] {
        let (vol, truth) = noisy_ct(padding);
        let auto = AutoTransfer::from_volume(&vol);
        assert_eq!(auto.rule, BackgroundRule::Otsu);
        assert_eq!(auto.fill_value, padding.then_some(-3024.0));
        assert!(
            auto.threshold > -950.0 && auto.threshold < -200.0,
            "{auto:?}"
        );
        let name = if padding { "CT + padding" } else { "CT" };
        for (before, after) in compare(name, &vol, &truth, 1, |v| v >= -500.0) {
            assert!(after.shows_object(), "{name}: auto {after:?}");
            assert!(!before.shows_object(), "{name}: ramp {before:?}");
        }
    }
}

#[test]
fn noisy_mr_phantom_shows_the_head() {
    // A T1-like head in 8 bits: bright scalp, dark skull, mid-grey brain, Rician noise
    // (σ = 8) everywhere, background of pure noise.
    let n = 64;
    let grid = Grid::with_dims([n, n, n]).unwrap();
    let mut noise = Noise(11);
    let c = (n as f64 - 1.0) / 2.0;
    let radius = |i: usize, j: usize, k: usize| {
        let (x, y, z) = (
            (i as f64 - c) / 28.0,
            (j as f64 - c) / 26.0,
            (k as f64 - c) / 24.0,
        );
        (x * x + y * y + z * z).sqrt()
    };
    let mr = Volume::from_fn(grid.clone(), |i, j, k| {
        let r = radius(i, j, k);
        let mean = if r > 1.0 {
            0.0
        } else if r > 0.93 {
            160.0
        } else if r > 0.86 {
            15.0
        } else {
            100.0
        };
        noise.rician(mean, 8.0).round().clamp(0.0, 255.0) as u8
    })
    .unwrap();
    let truth = Volume::from_fn(grid, |i, j, k| f32::from(radius(i, j, k) <= 1.0)).unwrap();
    let vol = AnyVolume::from(mr);
    let auto = AutoTransfer::from_volume(&vol);
    assert_eq!(auto.rule, BackgroundRule::Otsu);
    for (before, after) in compare("MR phantom", &vol, &truth, 1, |v| v > 0.5) {
        assert!(after.shows_object(), "auto {after:?}");
        assert!(!before.shows_object(), "ramp {before:?}");
    }
}

/// On real MRIs the silhouette comes from a fixed intensity, 40 (between the background noise
/// and tissue of both 8-bit scans, and independent of the automatic rule): object rays cross at
/// least 3 samples at or above it, background rays none. `former_is_foggy`: whether the former
/// default fails the same test (Colin27's background is exactly 0, a masked template, so the
/// ramp's opacity is 0 there too and its background stays nearly clear).
fn real_mri(file: &str, name: &str, former_is_foggy: bool) {
    let Some(mr) = read_u8_nrrd(&shared_data(file)) else {
        return;
    };
    let truth = mr.to_f32();
    let vol = AnyVolume::from(mr);
    let results = compare(name, &vol, &truth, 3, |v| v >= 40.0);
    for (before, after) in &results {
        assert!(after.shows_object(), "{name}: auto {after:?}");
        if former_is_foggy {
            assert!(!before.shows_object(), "{name}: ramp {before:?}");
            assert!(before.background > 0.3, "{name}: ramp {before:?}");
        }
    }
}

#[test]
fn brainsmall_mri_shows_the_head() {
    real_mri("mri_brainsmall.nrrd", "brainsmall", true);
}

#[test]
fn colin27_mri_shows_the_head() {
    real_mri("mri_colin27.nhdr", "colin27", false);
}

/// The noise-free phantom: air is exactly −1000 HU nearly everywhere, which must not hide the
/// tissue behind a "fill value" rule.
#[test]
fn noise_free_ct_phantom_shows_the_body() {
    let clean = ct_head_volume([64, 64, 64]).unwrap();
    let truth = clean.to_f32();
    let vol = AnyVolume::from(clean);
    for (_, after) in compare("noise-free CT", &vol, &truth, 1, |v| v >= -500.0) {
        assert!(after.shows_object(), "auto {after:?}");
    }
}
