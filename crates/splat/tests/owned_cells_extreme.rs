//! A brick's partial MIP/MinIP in the image-aligned slabs (`RenderSettings::owned_cells`,
//! issue 32): each sample is drawn by the one box that holds its cell, so the extreme of the
//! boxes' projections is the whole projection bit for bit (max and min are exact), in both
//! projections, with the AVX2 path and without (one ray per pixel: the supersampling of a
//! minified view averages rays, which does not commute with the extreme).

use volsplat_core::glam::DMat3;
use volsplat_core::{CrioTables, Grid, TransferFunction, Volume};
use volsplat_splat::{Antialias, RenderMode, RenderSettings, Visibility, render_slabs};

/// 37 × 29 × 42 voxels, anisotropic, with a few maxima and minima inside.
fn volume() -> Volume<f32> {
    let grid = Grid::new(
        [37, 29, 42],
        [1.0, 1.4, 0.8],
        [0.5, -2.0, 1.0],
        DMat3::IDENTITY,
    )
    .unwrap();
    Volume::from_fn(grid, |i, j, k| {
        let (x, y, z) = (i as f64, j as f64, k as f64);
        (2.0 + (0.31 * x).sin() * (0.23 * y + 0.17 * z).cos() + 0.4 * (0.11 * x * z).sin()) as f32
    })
    .unwrap()
}

#[test]
fn brick_extremes_are_the_whole_extreme_bit_for_bit() {
    let vol = volume();
    let tables =
        CrioTables::from_transfer_function(&TransferFunction::ramp(0.5, 3.5, 1.0), 256).unwrap();
    let cells = vol.grid().dims.map(|d| d - 1);
    let b = 16;
    let n = cells.map(|c| c.div_ceil(b));
    for mode in [RenderMode::Mip, RenderMode::Minip] {
        for parallel in [true, false] {
            for simd in [true, false] {
                let cam =
                    volsplat_testkit::fixtures::orbit_camera(vol.grid(), 28.0, -33.0, parallel);
                let mut s = RenderSettings::default();
                (s.width, s.height) = (44, 38);
                s.mode = mode;
                s.visibility = Visibility::ImageAligned;
                s.simd = simd;
                // One ray per pixel, as sort-last draws: a minified view's supersampling
                // averages the rays, which does not commute with the extreme.
                s.antialias = Antialias::None;
                let draw = |s: &RenderSettings| -> Vec<f32> {
                    let r = render_slabs(&vol, &cam, &tables, s, None, &mut |_| true).unwrap();
                    r.values.unwrap().values().to_vec()
                };
                let whole = draw(&s);
                assert!(whole.iter().filter(|v| !v.is_nan()).count() > 500);
                let mut acc = vec![f32::NAN; whole.len()];
                let mut partial = 0;
                for z in 0..n[2] {
                    for y in 0..n[1] {
                        for x in 0..n[0] {
                            let at = [x, y, z];
                            let mut sb = s.clone();
                            sb.owned_cells = Some([at.map(|a| a * b), at.map(|a| (a + 1) * b)]);
                            let part = draw(&sb);
                            partial += usize::from(
                                part.iter()
                                    .zip(&whole)
                                    .any(|(p, w)| p.to_bits() != w.to_bits()),
                            );
                            for (a, v) in acc.iter_mut().zip(part) {
                                let wins = match mode {
                                    RenderMode::Mip => v > *a,
                                    _ => v < *a,
                                };
                                if a.is_nan() || wins {
                                    *a = v;
                                }
                            }
                        }
                    }
                }
                let label = format!("{mode:?} parallel={parallel} simd={simd}");
                // Every box draws only its part (none is the whole picture)...
                assert_eq!(partial, n.iter().product::<usize>(), "{label}");
                // ...and their extreme is the whole one, bit for bit.
                let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&acc), bits(&whole), "{label}");
            }
        }
    }
}
