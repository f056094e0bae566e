//! Fixtures shared by the unit tests of the sheet renderer and the splat list (test builds only;
//! the integration tests' fixtures are `volsplat-testkit`'s).

use volsplat_core::glam::DVec3;
use volsplat_core::{CrioTables, Grid, TransferFunction, Volume};

/// A smooth, off-centre cone of values in [0, 1] on an `n`³ unit grid.
pub(crate) fn smooth_volume(n: usize) -> Volume<f32> {
    let grid = Grid::with_dims([n, n, n]).unwrap();
    let c = (n as f64 - 1.0) / 2.0;
    Volume::from_fn(grid, |i, j, k| {
        let d = DVec3::new(i as f64 - c, j as f64 - c * 0.8, k as f64 - c * 1.1) / c;
        (1.0 - d.length()).clamp(0.0, 1.0) as f32
    })
    .unwrap()
}

/// Shaded tables of a ramp over [0, 1] with three colours and ambient 0.2.
pub(crate) fn tables() -> CrioTables {
    let mut tf = TransferFunction::ramp(0.0, 1.0, 0.6);
    tf.color = vec![
        [0.0, 0.1, 0.3, 1.0],
        [0.5, 1.0, 0.5, 0.2],
        [1.0, 1.0, 1.0, 1.0],
    ];
    tf.shade = true;
    tf.ambient = 0.2;
    CrioTables::from_transfer_function(&tf, 1024).unwrap()
}
