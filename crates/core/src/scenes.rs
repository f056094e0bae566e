//! Synthetic stand-ins for the test scenes of Swan et al. 1997, Fig. 7 (§5).
//!
//! The paper renders three data sets to show the aliasing of standard splatting and its cure:
//!
//! - (a)–(b) a 498 × 398 × 1 sheet with alternating red and white 10 × 10 squares
//!   ([`checkerboard_sheet`]);
//! - (c)–(d) a 512 × 512 × 103 terrain built from a satellite photograph and a height field, each
//!   column of splats carrying the colour of its photo pixel ([`terrain`]; the original data are
//!   not public, so ours is a deterministic fractal landscape with a synthetic "photo");
//! - (e)–(f) a 420 × 468 × 62 confocal-microscopy study of microtubules ([`filaments`]; ours is a
//!   deterministic tangle of thin bright fibres).
//!
//! The renderer classifies scalars through a transfer function, so colour is encoded as a
//! scalar: each scene documents its encoding and comes with a matching VTK-style
//! [`TransferFunction`] ([`checkerboard_tf`], [`terrain_tf`], [`filaments_tf`]). Every volume has
//! unit spacing, zero origin and identity orientation (world units = voxels); value 0 is empty
//! space everywhere (opacity 0 in each transfer function), so a splatter culls it.
//!
//! Generation is deterministic: the same arguments give the same volume bit for bit, on every
//! platform (a SplitMix64 generator and integer hashing, no global state).

use crate::error::{CoreError, Result};
use crate::transfer::TransferFunction;
use crate::volume::{Grid, Volume};

/// Scalar value of empty space in every scene.
pub const EMPTY: f32 = 0.0;

// ---------------------------------------------------------------------------------------------
// Checkerboard sheet (Fig. 7 a–b)
// ---------------------------------------------------------------------------------------------

/// The paper's checkerboard sheet: `(nx, ny, square)` = 498 × 398 voxels, 10 × 10 squares
/// (Swan et al. 1997, §5, Fig. 7 a–b). The sheet is one voxel thick (`nz = 1`).
pub const CHECKERBOARD_PAPER: (usize, usize, usize) = (498, 398, 10);

/// Scalar value of a red square of [`checkerboard_sheet`].
pub const CHECKER_RED: f32 = 1.0;

/// Scalar value of a white square of [`checkerboard_sheet`].
pub const CHECKER_WHITE: f32 = 0.5;

/// A one-voxel-thick `nx × ny × 1` sheet of alternating `square × square`-voxel squares
/// (Swan et al. 1997, §5, Fig. 7 a–b; the finer variant is `square = 2`).
///
/// Voxel `(i, j, 0)` holds [`CHECKER_RED`] (1.0) when `⌊i/square⌋ + ⌊j/square⌋` is even — so the
/// square at the origin corner is red — and [`CHECKER_WHITE`] (0.5) otherwise. Every voxel is
/// occupied (no [`EMPTY`] voxels). Render with [`checkerboard_tf`].
///
/// Note that the box of voxel centres has zero thickness along z: a splatter renders the sheet
/// as it renders any volume, but a ray caster that clips rays to the box of voxel centres (such
/// as the testkit reference integrator) sees a zero-length path.
///
/// Errors if `nx`, `ny` or `square` is 0 (or the grid is too large, see [`Grid::new`]).
pub fn checkerboard_sheet(nx: usize, ny: usize, square: usize) -> Result<Volume<f32>> {
    if square == 0 {
        return Err(CoreError::invalid(
            "square",
            square,
            "must be at least 1 voxel",
        ));
    }
    let grid = Grid::with_dims([nx, ny, 1])?;
    Volume::from_fn(grid, |i, j, _| {
        if (i / square + j / square).is_multiple_of(2) {
            CHECKER_RED
        } else {
            CHECKER_WHITE
        }
    })
}

/// The transfer function for [`checkerboard_sheet`]: values ≤ 0.5 white, 1.0 pure red, linear
/// in between (reconstruction at a square's edge gives pink); opacity 0 at [`EMPTY`] rising to 1
/// (per world unit) at 0.5 and above; unshaded.
pub fn checkerboard_tf() -> TransferFunction {
    TransferFunction {
        color: vec![
            [0.0, 1.0, 1.0, 1.0],
            [CHECKER_WHITE as f64, 1.0, 1.0, 1.0],
            [CHECKER_RED as f64, 1.0, 0.0, 0.0],
        ],
        scalar_opacity: vec![[0.0, 0.0], [CHECKER_WHITE as f64, 1.0], [1.0, 1.0]],
        ..unshaded()
    }
}

// ---------------------------------------------------------------------------------------------
// Terrain (Fig. 7 c–d)
// ---------------------------------------------------------------------------------------------

/// The paper's terrain size: 512 × 512 × 103 (Swan et al. 1997, §5, Fig. 7 c–d).
pub const TERRAIN_PAPER: [usize; 3] = [512, 512, 103];

/// Smallest "photo" value of an occupied terrain voxel; occupied voxels lie in
/// `[TERRAIN_MIN, 1]`, empty ones are [`EMPTY`].
pub const TERRAIN_MIN: f32 = 0.2;

/// Period in voxels of the grid of bright "roads" in the terrain photo.
pub const TERRAIN_ROAD_PERIOD: usize = 16;

/// A terrain-like height-field volume `nx × ny × nz` (Swan et al. 1997, §5, Fig. 7 c–d: a
/// satellite photograph draped on a height field, each column of splats coloured by its photo
/// pixel).
///
/// **Height.** A fractal height field — six octaves of value noise (smooth quintic
/// interpolation of hashed lattice values, lacunarity 2, gain ½), coarsest period
/// `max(nx, ny)/4` voxels — normalised to `[0, 1]` over the field, shaped as `t^1.5` (flat
/// valleys, steep peaks) and mapped to integer column tops `h(i, j) ∈ [1, nz − 1]`.
///
/// **Occupancy.** A shell: voxel `(i, j, k)` is occupied when
/// `min(h(i, j), h_n) − 1 ≤ k ≤ h(i, j)`, where `h_n` is the lowest of the 4-neighbours' tops
/// (clamped at the border). Every column is therefore at least two voxels thick and reaches
/// down to its lowest neighbour's top, so there are no holes between neighbouring columns of
/// different height (the paper's "extra splats … to fill in the holes").
///
/// **Value** (the "photo", identical along a column, in `[TERRAIN_MIN, 1]`):
/// `0.2 + 0.8 · clamp(0.45·e + 0.35·d + 0.2·r)`, where `e` is the normalised elevation
/// (vegetation low, rock higher, snow on top under [`terrain_tf`]), `d ∈ [0, 1]` fine detail —
/// 0.4 per-voxel speckle (white noise) + 0.3 value noise of period 2 voxels + 0.3 of period
/// 6 — and `r` a grid of one-voxel-wide bright "roads" every
/// [`TERRAIN_ROAD_PERIOD`] voxels in both directions. The detail and the regular roads alias
/// (moiré, flicker) as soon as more than one voxel falls into a pixel.
///
/// Errors if `nx` or `ny` is 0, `nz < 2`, or the grid is too large.
pub fn terrain(nx: usize, ny: usize, nz: usize, seed: u64) -> Result<Volume<f32>> {
    if nz < 2 {
        return Err(CoreError::invalid(
            "nz",
            nz,
            "a terrain needs at least 2 voxels of height",
        ));
    }
    let grid = Grid::with_dims([nx, ny, nz])?;
    let base_period = (nx.max(ny) as f64 / 4.0).max(2.0);
    let mut elevation = vec![0.0f64; nx * ny];
    for j in 0..ny {
        for i in 0..nx {
            elevation[j * nx + i] = fbm(i as f64, j as f64, base_period, 6, seed);
        }
    }
    let (lo, hi) = elevation
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    let span = if hi > lo { hi - lo } else { 1.0 };
    for e in &mut elevation {
        *e = ((*e - lo) / span).clamp(0.0, 1.0);
    }
    let top_max = (nz - 1) as f64;
    let tops: Vec<usize> = elevation
        .iter()
        .map(|&e| (1.0 + e.powf(1.5) * (top_max - 1.0)).round() as usize)
        .collect();
    let detail_seed = seed ^ 0x5EED_DE7A_11ED_0001;
    let mut photo = vec![0.0f32; nx * ny];
    for j in 0..ny {
        for i in 0..nx {
            let (x, y) = (i as f64, j as f64);
            let d = 0.4 * lattice(i as i64, j as i64, detail_seed)
                + 0.3 * value_noise(x / 2.0, y / 2.0, detail_seed.wrapping_add(1))
                + 0.3 * value_noise(x / 6.0, y / 6.0, detail_seed.wrapping_add(2));
            let road =
                if i.is_multiple_of(TERRAIN_ROAD_PERIOD) || j.is_multiple_of(TERRAIN_ROAD_PERIOD) {
                    1.0
                } else {
                    0.0
                };
            let v = (0.45 * elevation[j * nx + i] + 0.35 * d + 0.2 * road).clamp(0.0, 1.0);
            photo[j * nx + i] = TERRAIN_MIN + (1.0 - TERRAIN_MIN) * v as f32;
        }
    }
    // Bottom of each column's shell: one below the lowest of itself and its 4-neighbours.
    let mut bottoms = vec![0usize; nx * ny];
    for j in 0..ny {
        for i in 0..nx {
            let c = j * nx + i;
            let mut m = tops[c];
            if i > 0 {
                m = m.min(tops[c - 1]);
            }
            if i + 1 < nx {
                m = m.min(tops[c + 1]);
            }
            if j > 0 {
                m = m.min(tops[c - nx]);
            }
            if j + 1 < ny {
                m = m.min(tops[c + nx]);
            }
            bottoms[c] = m.saturating_sub(1);
        }
    }
    let plane = nx * ny;
    let mut data = vec![EMPTY; grid.voxel_count()];
    for (k, slab) in data.chunks_mut(plane).enumerate() {
        for (c, v) in slab.iter_mut().enumerate() {
            if k >= bottoms[c] && k <= tops[c] {
                *v = photo[c];
            }
        }
    }
    Volume::new(grid, data)
}

/// The transfer function for [`terrain`]: opaque for every occupied value (opacity 0 at
/// [`EMPTY`], 0 up to 0.1, 1 from [`TERRAIN_MIN`] on), colour by photo value — dark green (0.2),
/// green (0.45), brown (0.65), grey rock (0.85), white snow (1.0); unshaded, as the paper's
/// columns carry the photo's colour.
pub fn terrain_tf() -> TransferFunction {
    TransferFunction {
        color: vec![
            [0.0, 0.10, 0.25, 0.08],
            [TERRAIN_MIN as f64, 0.10, 0.25, 0.08],
            [0.45, 0.30, 0.50, 0.18],
            [0.65, 0.55, 0.43, 0.28],
            [0.85, 0.68, 0.66, 0.62],
            [1.0, 1.0, 1.0, 1.0],
        ],
        scalar_opacity: vec![
            [0.0, 0.0],
            [0.1, 0.0],
            [TERRAIN_MIN as f64, 1.0],
            [1.0, 1.0],
        ],
        ..unshaded()
    }
}

// ---------------------------------------------------------------------------------------------
// Filaments (Fig. 7 e–f)
// ---------------------------------------------------------------------------------------------

/// The paper's microtubule study size: 420 × 468 × 62 (Swan et al. 1997, §5, Fig. 7 e–f).
pub const FILAMENTS_PAPER: [usize; 3] = [420, 468, 62];

/// Lateral area, in voxels², per fibre of [`filaments`]: the fibre count is
/// `⌈nx·ny / FILAMENT_AREA⌉`.
pub const FILAMENT_AREA: usize = 600;

/// Standard deviation, in voxels, of a fibre's Gaussian cross-section in [`filaments`]
/// (full width at half maximum ≈ 1.4 voxels).
pub const FILAMENT_SIGMA: f64 = 0.6;

/// A dense tangle of thin, bright, curved fibres on a dark background, `nx × ny × nz` — a
/// stand-in for the confocal microtubule study of Swan et al. 1997, §5, Fig. 7 e–f, finer than
/// the image it is rendered into.
///
/// `⌈nx·ny / FILAMENT_AREA⌉` fibres (328 at the paper's size). Each starts at a random voxel,
/// runs mostly parallel to the xy plane with a random heading whose curvature drifts randomly
/// (|κ| ≤ 0.05 rad/voxel), bobs in z sinusoidally within the volume, and is
/// `[0.3, 1]·max(nx, ny)` voxels long (or until it leaves the volume laterally). Its brightness
/// `b ∈ [0.5, 1]` is constant along it. The value of a voxel is the largest
/// `b·exp(−d²/2σ²)` over the fibres, `d` its distance to the fibre's centre line (sampled
/// every ¼ voxel), `σ =` [`FILAMENT_SIGMA`]; values below 1/256 are set to [`EMPTY`], so the
/// background is exactly 0 and values lie in `{0} ∪ [1/256, 1]`. Render with
/// [`filaments_tf`].
///
/// Errors if a dimension is 0 or the grid is too large.
pub fn filaments(nx: usize, ny: usize, nz: usize, seed: u64) -> Result<Volume<f32>> {
    let grid = Grid::with_dims([nx, ny, nz])?;
    let mut data = vec![EMPTY; grid.voxel_count()];
    let mut rng = SplitMix64(seed ^ 0xF1BE_F1BE_0000_0003);
    let count = (nx * ny).div_ceil(FILAMENT_AREA);
    let size = nx.max(ny) as f64;
    let (fx, fy, fz) = (nx as f64, ny as f64, nz as f64);
    let step = 0.25;
    let two_sigma2 = 2.0 * FILAMENT_SIGMA * FILAMENT_SIGMA;
    let reach = 2i64; // voxels: exp(−(2.0)²/0.72) < 1/256
    let floor_value = 1.0 / 256.0;
    for _ in 0..count {
        let brightness = 0.5 + 0.5 * rng.unit();
        let length = (0.3 + 0.7 * rng.unit()) * size;
        let (mut x, mut y) = (rng.unit() * (fx - 1.0), rng.unit() * (fy - 1.0));
        let mut heading = rng.unit() * std::f64::consts::TAU;
        let mut curvature = (rng.unit() - 0.5) * 0.06;
        let z_mid = rng.unit() * (fz - 1.0);
        let z_amp = rng.unit() * 0.35 * (fz - 1.0);
        let z_freq = (0.5 + rng.unit()) * std::f64::consts::TAU / size.max(1.0);
        let z_phase = rng.unit() * std::f64::consts::TAU;
        let mut s = 0.0;
        while s < length {
            let z = (z_mid + z_amp * (z_freq * s + z_phase).sin()).clamp(0.0, fz - 1.0);
            splat_point(&mut data, [nx, ny, nz], [x, y, z], reach, |d2| {
                let v = brightness * (-d2 / two_sigma2).exp();
                if v >= floor_value { v as f32 } else { EMPTY }
            });
            // Curvature drifts as a bounded random walk.
            curvature = (curvature + (rng.unit() - 0.5) * 0.004).clamp(-0.05, 0.05);
            heading += curvature * step;
            x += heading.cos() * step;
            y += heading.sin() * step;
            s += step;
            if x < -1.0 || y < -1.0 || x > fx || y > fy {
                break;
            }
        }
    }
    Volume::new(grid, data)
}

/// Writes `max(current, value(d²))` into the voxels within `reach` voxels of `p` (index space).
fn splat_point(
    data: &mut [f32],
    dims: [usize; 3],
    p: [f64; 3],
    reach: i64,
    value: impl Fn(f64) -> f32,
) {
    let [nx, ny, nz] = dims;
    let centre = p.map(|c| c.round() as i64);
    let lo = |a: usize| (centre[a] - reach).max(0);
    let hi = |a: usize, n: usize| (centre[a] + reach).min(n as i64 - 1);
    for k in lo(2)..=hi(2, nz) {
        let dz = k as f64 - p[2];
        for j in lo(1)..=hi(1, ny) {
            let dy = j as f64 - p[1];
            let row = (k as usize * ny + j as usize) * nx;
            for i in lo(0)..=hi(0, nx) {
                let dx = i as f64 - p[0];
                let v = value(dx * dx + dy * dy + dz * dz);
                let cell = &mut data[row + i as usize];
                if v > *cell {
                    *cell = v;
                }
            }
        }
    }
}

/// The transfer function for [`filaments`]: a fluorescence look — colour black → green
/// (0.3) → bright yellow-green (1.0); opacity 0 at [`EMPTY`] and up to 0.1 (the fibres' faint
/// halo), rising linearly to 0.8 per world unit at 1.0; unshaded.
pub fn filaments_tf() -> TransferFunction {
    TransferFunction {
        color: vec![
            [0.0, 0.0, 0.0, 0.0],
            [0.3, 0.1, 0.7, 0.2],
            [1.0, 0.85, 1.0, 0.55],
        ],
        scalar_opacity: vec![[0.0, 0.0], [0.1, 0.0], [1.0, 0.8]],
        ..unshaded()
    }
}

// ---------------------------------------------------------------------------------------------
// Shared helpers
// ---------------------------------------------------------------------------------------------

/// An unshaded transfer function with VTK's default coefficients and a grey ramp over [0, 1];
/// the scene constructors override colour and opacity.
fn unshaded() -> TransferFunction {
    TransferFunction::ramp(0.0, 1.0, 1.0)
}

/// SplitMix64 (Steele, Lea & Flood, "Fast splittable pseudorandom number generators",
/// OOPSLA 2014): a tiny, well-mixed 64-bit generator.
struct SplitMix64(u64);

impl SplitMix64 {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        mix64(self.0)
    }

    /// Uniform in [0, 1) with 53 random bits.
    fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }
}

/// SplitMix64's output function (a 64-bit finaliser).
fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Hashed lattice value in [0, 1) at integer point `(ix, iy)`.
fn lattice(ix: i64, iy: i64, seed: u64) -> f64 {
    let h = mix64(
        seed ^ mix64((ix as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ (iy as u64).rotate_left(32)),
    );
    (h >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
}

/// Value noise in [0, 1] at `(x, y)` (lattice units): bilinear blend of hashed lattice values
/// with the quintic fade `6t⁵ − 15t⁴ + 10t³` (Perlin 2002, "Improving noise"), so the field is
/// C².
fn value_noise(x: f64, y: f64, seed: u64) -> f64 {
    let (x0, y0) = (x.floor(), y.floor());
    let (tx, ty) = (x - x0, y - y0);
    let fade = |t: f64| t * t * t * (t * (t * 6.0 - 15.0) + 10.0);
    let (sx, sy) = (fade(tx), fade(ty));
    let (ix, iy) = (x0 as i64, y0 as i64);
    let a = lattice(ix, iy, seed);
    let b = lattice(ix + 1, iy, seed);
    let c = lattice(ix, iy + 1, seed);
    let d = lattice(ix + 1, iy + 1, seed);
    let top = a + (b - a) * sx;
    let bottom = c + (d - c) * sx;
    top + (bottom - top) * sy
}

/// Fractal Brownian motion: `octaves` octaves of [`value_noise`], the first with period
/// `period` voxels, each next one at twice the frequency and half the amplitude; in [0, 1].
fn fbm(x: f64, y: f64, period: f64, octaves: u32, seed: u64) -> f64 {
    let (mut sum, mut norm, mut amp, mut freq) = (0.0, 0.0, 1.0, 1.0 / period);
    for o in 0..octaves {
        sum += amp
            * value_noise(
                x * freq,
                y * freq,
                seed.wrapping_add(o as u64 * 0x1234_5678),
            );
        norm += amp;
        amp *= 0.5;
        freq *= 2.0;
    }
    sum / norm
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn checkerboard_colours_known_voxels() {
        let (nx, ny, sq) = CHECKERBOARD_PAPER;
        let v = checkerboard_sheet(nx, ny, sq).unwrap();
        assert_eq!(v.grid().dims, [498, 398, 1]);
        assert_eq!(v.get(0, 0, 0), CHECKER_RED);
        assert_eq!(v.get(9, 9, 0), CHECKER_RED);
        assert_eq!(v.get(10, 0, 0), CHECKER_WHITE);
        assert_eq!(v.get(0, 10, 0), CHECKER_WHITE);
        assert_eq!(v.get(10, 10, 0), CHECKER_RED);
        assert_eq!(v.get(497, 397, 0), CHECKER_RED); // squares (49, 39): even sum
        let reds = v.data().iter().filter(|&&x| x == CHECKER_RED).count();
        let whites = v.data().iter().filter(|&&x| x == CHECKER_WHITE).count();
        assert_eq!(reds + whites, 498 * 398);
        assert!((reds as f64 / whites as f64 - 1.0).abs() < 0.01);
        let fine = checkerboard_sheet(8, 4, 2).unwrap();
        let row: Vec<f32> = (0..8).map(|i| fine.get(i, 0, 0)).collect();
        let (r, w) = (CHECKER_RED, CHECKER_WHITE);
        assert_eq!(row, [r, r, w, w, r, r, w, w]);
        assert_eq!(fine.get(0, 2, 0), w);
        assert!(
            checkerboard_sheet(8, 4, 0)
                .unwrap_err()
                .to_string()
                .contains("square")
        );
        assert!(checkerboard_sheet(0, 4, 2).is_err());
        let mut tf = checkerboard_tf();
        tf.validate().unwrap();
        assert_eq!(tf.color_at(1.0), [1.0, 0.0, 0.0]);
        assert_eq!(tf.color_at(0.5), [1.0, 1.0, 1.0]);
        assert_eq!(tf.opacity_at(0.0), 0.0);
        assert_eq!(tf.opacity_at(0.5), 1.0);
    }

    #[test]
    fn terrain_columns_are_filled_without_gaps() {
        let (nx, ny, nz) = (96, 80, 24);
        let v = terrain(nx, ny, nz, 7).unwrap();
        assert_eq!(v.grid().dims, [nx, ny, nz]);
        let mut top = vec![0usize; nx * ny];
        let mut bottom = vec![0usize; nx * ny];
        for j in 0..ny {
            for i in 0..nx {
                let column: Vec<f32> = (0..nz).map(|k| v.get(i, j, k)).collect();
                let filled: Vec<usize> = (0..nz).filter(|&k| column[k] != EMPTY).collect();
                let (lo, hi) = (filled[0], filled[filled.len() - 1]);
                // One contiguous run, ≥ 2 voxels, one value per column, in range.
                assert_eq!(filled.len(), hi - lo + 1, "column ({i}, {j}) has a gap");
                assert!(filled.len() >= 2, "column ({i}, {j}) too thin");
                let c = column[hi];
                assert!((TERRAIN_MIN..=1.0).contains(&c));
                assert!(filled.iter().all(|&k| column[k] == c));
                assert!(hi >= 1 && hi < nz);
                top[j * nx + i] = hi;
                bottom[j * nx + i] = lo;
            }
        }
        // No holes: each column reaches down to (below) every 4-neighbour's top.
        for j in 0..ny {
            for i in 0..nx {
                let c = j * nx + i;
                for (di, dj) in [(1i64, 0i64), (-1, 0), (0, 1), (0, -1)] {
                    let (a, b) = (i as i64 + di, j as i64 + dj);
                    if a < 0 || b < 0 || a >= nx as i64 || b >= ny as i64 {
                        continue;
                    }
                    let n = b as usize * nx + a as usize;
                    assert!(
                        bottom[c] < top[n].max(1),
                        "hole between ({i},{j}) and ({a},{b})"
                    );
                }
            }
        }
        // The relief spans the height range, and the photo has fine detail.
        let (tmin, tmax) = (top.iter().min().unwrap(), top.iter().max().unwrap());
        assert!(*tmin <= 2 && *tmax == nz - 1, "{tmin}..{tmax}");
        let photo_top = |i: usize, j: usize| v.get(i, j, top[j * nx + i]);
        let mut jumps = 0;
        for i in 1..nx {
            if (photo_top(i, 40) - photo_top(i - 1, 40)).abs() > 0.04 {
                jumps += 1;
            }
        }
        assert!(jumps > nx / 3, "{jumps}");
        // Deterministic for a seed, different for another.
        assert_eq!(terrain(nx, ny, nz, 7).unwrap(), v);
        assert_ne!(terrain(nx, ny, nz, 8).unwrap(), v);
        assert!(terrain(4, 4, 1, 0).unwrap_err().to_string().contains("nz"));
        let mut tf = terrain_tf();
        tf.validate().unwrap();
        assert_eq!(tf.opacity_at(TERRAIN_MIN as f64), 1.0);
        assert_eq!(tf.opacity_at(0.0), 0.0);
    }

    #[test]
    fn scenes_at_paper_size_are_fast() {
        let [nx, ny, nz] = TERRAIN_PAPER;
        let t = std::time::Instant::now();
        let v = terrain(nx, ny, nz, 1).unwrap();
        let secs = t.elapsed().as_secs_f64();
        let filled = v.data().iter().filter(|&&x| x != EMPTY).count();
        eprintln!("terrain {nx}×{ny}×{nz}: {secs:.3} s, {filled} occupied voxels");
        // Generous: debug builds are ~10× slower than release.
        assert!(secs < 20.0);
        assert!(filled >= 2 * nx * ny);
        let [fx, fy, fz] = FILAMENTS_PAPER;
        let t = std::time::Instant::now();
        let f = filaments(fx, fy, fz, 1).unwrap();
        let secs = t.elapsed().as_secs_f64();
        let lit = f.data().iter().filter(|&&x| x != EMPTY).count();
        eprintln!("filaments {fx}×{fy}×{fz}: {secs:.3} s, {lit} non-empty voxels");
        assert!(secs < 20.0);
    }

    #[test]
    fn filaments_are_thin_bright_and_deterministic() {
        let (nx, ny, nz) = (120, 100, 20);
        let v = filaments(nx, ny, nz, 3).unwrap();
        assert_eq!(v.grid().dims, [nx, ny, nz]);
        let data = v.data();
        assert!(
            data.iter()
                .all(|&x| x == EMPTY || (1.0 / 256.0..=1.0).contains(&x))
        );
        let occupied = data.iter().filter(|&&x| x != EMPTY).count();
        let bright = data.iter().filter(|&&x| x > 0.5).count();
        let fraction = occupied as f64 / data.len() as f64;
        eprintln!("filaments: {occupied} occupied ({fraction:.3}), {bright} above 0.5");
        // Sparse (a dark background) but dense enough to matter.
        assert!(fraction > 0.005 && fraction < 0.15, "{fraction}");
        assert!(bright > 300, "{bright}");
        let peak = data.iter().fold(0.0f32, |m, &x| m.max(x));
        assert!(peak > 0.9, "{peak}");
        // Thin: a bright voxel's value drops below half within 2 voxels along some axis
        // direction (the fibre's cross-section).
        let mut thin = 0;
        let mut checked = 0;
        for k in 2..nz - 2 {
            for j in 2..ny - 2 {
                for i in 2..nx - 2 {
                    let c = v.get(i, j, k);
                    if c < 0.7 {
                        continue;
                    }
                    checked += 1;
                    let across = [
                        v.get(i + 2, j, k).min(v.get(i - 2, j, k)),
                        v.get(i, j + 2, k).min(v.get(i, j - 2, k)),
                        v.get(i, j, k + 2).min(v.get(i, j, k - 2)),
                    ];
                    if across.iter().any(|&a| a < 0.5 * c) {
                        thin += 1;
                    }
                }
            }
        }
        assert!(
            checked > 100 && thin as f64 > 0.95 * checked as f64,
            "{thin}/{checked}"
        );
        assert_eq!(filaments(nx, ny, nz, 3).unwrap(), v);
        assert_ne!(filaments(nx, ny, nz, 4).unwrap(), v);
        assert!(filaments(0, 1, 1, 0).is_err());
        let mut tf = filaments_tf();
        tf.validate().unwrap();
        assert_eq!(tf.opacity_at(0.0), 0.0);
    }
}
