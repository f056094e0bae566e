//! A brick's partial X-ray (`RenderSettings::owned_cells` in the sheet renderer and the splat
//! list, issue 32): over a partition of the cells into boxes, every voxel is drawn by exactly one
//! box (a voxel belongs to the cell of which it is the lower corner, the last voxel to the last
//! cell), so the boxes' X-rays sum to the whole X-ray up to f32 reassociation, in both
//! projections; boxes that share their faces' voxels do not.

use volsplat_core::glam::DMat3;
use volsplat_core::{CrioTables, Grid, TransferFunction, Volume};
use volsplat_splat::{
    ExtractSettings, ListVoxels, RenderMode, RenderSettings, Rendered, SplatError, SplatList,
    render, render_list,
};

/// 21 × 19 × 26 voxels (20 × 18 × 25 cells), anisotropic, positive everywhere, with structure.
fn volume() -> Volume<f32> {
    let grid = Grid::new(
        [21, 19, 26],
        [1.0, 1.3, 0.8],
        [2.0, -1.0, 0.5],
        DMat3::IDENTITY,
    )
    .unwrap();
    Volume::from_fn(grid, |i, j, k| {
        (1.0 + 0.5 * ((i as f64) * 0.7).sin() * ((j as f64) * 0.4 + k as f64 * 0.3).cos()) as f32
    })
    .unwrap()
}

/// The boxes of cells of a cut into `b`-cell bricks, the last one along each axis running to the
/// last cell (its upper bound past it); `grow` cells added to each upper bound (0: a partition).
fn boxes(cells: [usize; 3], b: usize, grow: usize) -> Vec<[[usize; 3]; 2]> {
    let n = cells.map(|c| c.div_ceil(b));
    let mut out = Vec::new();
    for z in 0..n[2] {
        for y in 0..n[1] {
            for x in 0..n[0] {
                let at = [x, y, z];
                out.push([at.map(|a| a * b), at.map(|a| (a + 1) * b + grow)]);
            }
        }
    }
    out
}

fn values(r: &Rendered) -> Vec<f32> {
    r.values.as_ref().expect("X-ray values").values().to_vec()
}

/// The largest difference between `parts` summed and `whole`, relative to `whole`'s peak.
fn relative_error(parts: &[Vec<f32>], whole: &[f32]) -> f64 {
    let peak = whole.iter().fold(0.0f32, |m, v| m.max(v.abs())) as f64;
    assert!(peak > 1.0, "the X-ray sees the volume ({peak})");
    (0..whole.len())
        .map(|i| {
            let s: f64 = parts.iter().map(|p| f64::from(p[i])).sum();
            (s - f64::from(whole[i])).abs()
        })
        .fold(0.0, f64::max)
        / peak
}

fn settings() -> RenderSettings {
    let mut s = RenderSettings::default();
    (s.width, s.height) = (40, 36);
    s.mode = RenderMode::Xray;
    s
}

#[test]
fn brick_x_rays_sum_to_the_whole_in_the_sheets_and_the_list() {
    let vol = volume();
    let tables =
        CrioTables::from_transfer_function(&TransferFunction::ramp(0.0, 2.0, 1.0), 256).unwrap();
    let mut e = ExtractSettings::default();
    e.voxels = ListVoxels::for_mode(RenderMode::Xray);
    let list = SplatList::build(&vol, &tables, &e).unwrap();
    let cells = vol.grid().dims.map(|d| d - 1);
    for parallel in [true, false] {
        let cam = volsplat_testkit::fixtures::orbit_camera(vol.grid(), 31.0, -22.0, parallel);
        let draw = |s: &RenderSettings| -> Vec<f32> {
            let r = if parallel {
                render(&vol, &cam, &tables, s).unwrap()
            } else {
                render_list(&list, &cam, &tables, s).unwrap()
            };
            values(&r)
        };
        let whole = draw(&settings());
        for (grow, ok) in [(0, true), (1, false)] {
            let parts: Vec<Vec<f32>> = boxes(cells, 8, grow)
                .into_iter()
                .map(|owned| {
                    let mut s = settings();
                    s.owned_cells = Some(owned);
                    draw(&s)
                })
                .collect();
            assert_eq!(parts.len(), 3 * 3 * 4);
            let err = relative_error(&parts, &whole);
            eprintln!("parallel={parallel} grow={grow}: {err:.2e} of the peak");
            if ok {
                assert!(err < 1e-5, "parallel={parallel}: {err:.2e}");
            } else {
                // The faces' voxels drawn twice: far from the whole.
                assert!(err > 1e-2, "parallel={parallel}: {err:.2e}");
            }
        }
        // One box holding every cell draws the same bits as no box at all.
        let mut s = settings();
        s.owned_cells = Some([[0; 3], cells]);
        assert_eq!(draw(&s), whole, "parallel={parallel}");
    }
}

#[test]
fn owned_voxels_are_x_ray_only_in_the_voxel_renderers() {
    let vol = volume();
    let tables =
        CrioTables::from_transfer_function(&TransferFunction::ramp(0.0, 2.0, 1.0), 256).unwrap();
    let cam = volsplat_testkit::fixtures::orbit_camera(vol.grid(), 10.0, 5.0, true);
    let list = SplatList::build(&vol, &tables, &ExtractSettings::default()).unwrap();
    for (mode, owned) in [
        (RenderMode::Composite, [[0; 3], [8; 3]]),
        (RenderMode::Mip, [[0; 3], [8; 3]]),
        (RenderMode::Xray, [[8, 0, 0], [8, 8, 8]]),
    ] {
        let mut s = settings();
        s.mode = mode;
        s.owned_cells = Some(owned);
        for e in [
            render(&vol, &cam, &tables, &s).unwrap_err(),
            render_list(&list, &cam, &tables, &s).unwrap_err(),
        ] {
            assert!(
                matches!(
                    e,
                    SplatError::Setting {
                        name: "owned_cells",
                        ..
                    }
                ),
                "{mode:?}: {e}"
            );
        }
    }
}
