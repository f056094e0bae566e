//! Successive refinement (Westover 1991, §4.1–4.2.4): a ladder of previews, each a complete
//! picture, from subsampled input with cheap kernels up to the full render.
//!
//! Subsampling by `s` splats every `s`-th voxel per axis with the kernel scaled to the coarser
//! lattice, so previews have no holes and keep the same opacity per unit length (opacity is
//! corrected for the longer sheet spacing, which the thesis omits: Westover digest §7.1.11, listed in `docs/papers.md`).
//! The preview is "partial but unbiased" only for band-limited data (§4.2.3): finer detail
//! aliases.

use crate::error::Result;
use crate::sheets::{RenderSettings, Rendered, render};
use volsplat_core::{Camera, CrioTables, Kernel, Scalar, Volume};

/// One rung of the ladder.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RefinementStep {
    /// Subsampling stride per axis (1 = full resolution).
    pub subsample: usize,
    /// Kernel for this rung.
    pub kernel: Kernel,
}

/// The default ladder ending with `final_kernel` at full resolution: every 4th voxel with the
/// nearest-neighbour kernel (64× less work), every 2nd with the final kernel (8×), then all.
pub fn default_ladder(final_kernel: Kernel) -> Vec<RefinementStep> {
    vec![
        RefinementStep {
            subsample: 4,
            kernel: Kernel::Nearest,
        },
        RefinementStep {
            subsample: 2,
            kernel: final_kernel,
        },
        RefinementStep {
            subsample: 1,
            kernel: final_kernel,
        },
    ]
}

/// Renders each rung of `ladder` in turn with `settings` (its `subsample` and `kernel` replaced
/// by the rung's), passing each result to `on_step(rung index, result)`. Returning `false` from
/// the callback stops the ladder (e.g. because the view changed) and returns that rung's result.
/// Returns the last rendered rung; errors if `ladder` is empty. Every rung is drawn by the sheet
/// renderer ([`crate::sheets::render`]), which refuses image-aligned visibility outside X-ray.
pub fn render_ladder<T: Scalar>(
    volume: &Volume<T>,
    camera: &Camera,
    tables: &CrioTables,
    settings: &RenderSettings,
    ladder: &[RefinementStep],
    on_step: &mut dyn FnMut(usize, &Rendered) -> bool,
) -> Result<Rendered> {
    let mut last = None;
    for (n, step) in ladder.iter().enumerate() {
        let s = RenderSettings {
            subsample: step.subsample,
            kernel: step.kernel,
            ..settings.clone()
        };
        let out = render(volume, camera, tables, &s)?;
        let go_on = on_step(n, &out);
        last = Some(out);
        if !go_on {
            break;
        }
    }
    last.ok_or(crate::SplatError::EmptyLadder)
}

#[cfg(test)]
mod tests {
    use super::*;
    use volsplat_core::glam::DVec3;
    use volsplat_core::{Grid, TransferFunction};

    #[test]
    fn ladder_previews_are_cheaper_and_end_with_the_full_render() {
        let grid = Grid::with_dims([32, 32, 32]).unwrap();
        let vol = Volume::from_fn(grid.clone(), |i, j, k| {
            let d = DVec3::new(i as f64, j as f64, k as f64) - DVec3::splat(15.5);
            (1.0 - d.length() / 15.0).max(0.0) as f32
        })
        .unwrap();
        let (lo, hi) = grid.bounds_world();
        let mut cam = Camera::reset_to_bounds(lo, hi, true);
        cam.azimuth(25.0);
        let tables =
            CrioTables::from_transfer_function(&TransferFunction::ramp(0.0, 1.0, 0.5), 256)
                .unwrap();
        let settings = RenderSettings {
            width: 48,
            height: 48,
            ..RenderSettings::default()
        };
        let mut counts = Vec::new();
        let last = render_ladder(
            &vol,
            &cam,
            &tables,
            &settings,
            &default_ladder(Kernel::default()),
            &mut |_, r| {
                counts.push(r.stats.voxels);
                true
            },
        )
        .unwrap();
        assert_eq!(counts, vec![512, 4096, 32768]);
        let direct = render(&vol, &cam, &tables, &settings).unwrap();
        assert_eq!(last.image, direct.image);
        // Stopping after the first rung returns it.
        let mut calls = 0;
        let first = render_ladder(
            &vol,
            &cam,
            &tables,
            &settings,
            &default_ladder(Kernel::default()),
            &mut |_, _| {
                calls += 1;
                false
            },
        )
        .unwrap();
        assert_eq!((calls, first.stats.voxels), (1, 512));
    }
}
