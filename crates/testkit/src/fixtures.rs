//! Shared test fixtures: the classification used by the oracle tests of every renderer, so
//! orthographic and perspective checks compare like with like.

use volsplat_core::{Camera, CrioTables, Grid, Result, TransferFunction};

/// A shaded, semi-transparent transfer function over data in `[0, 1]`: transparent below 0.1,
/// opacity rising to 0.35 per 0.05 world units at 1, blue → green → white, VTK shading with
/// ambient 0.3, diffuse 0.7, specular 0.2 (power 10).
pub fn shaded_transfer_function() -> TransferFunction {
    TransferFunction {
        color: vec![
            [0.0, 0.2, 0.3, 0.9],
            [0.4, 0.9, 0.6, 0.3],
            [1.0, 1.0, 1.0, 0.9],
        ],
        scalar_opacity: vec![[0.0, 0.0], [0.1, 0.0], [1.0, 0.35]],
        scalar_opacity_unit_distance: 0.05,
        shade: true,
        ambient: 0.3,
        diffuse: 0.7,
        specular: 0.2,
        specular_power: 10.0,
        ..TransferFunction::ramp(0.0, 1.0, 1.0)
    }
}

/// [`shaded_transfer_function`] compiled into 1024-entry CRIO tables.
pub fn shaded_tables() -> Result<CrioTables> {
    CrioTables::from_transfer_function(&shaded_transfer_function(), 1024)
}

/// VTK's reset view of `grid`'s bounds (world units), then `Azimuth(az)` and `Elevation(el)`
/// (degrees) and `OrthogonalizeViewUp`: the orbit the command line's `--azimuth`/`--elevation`
/// build; `parallel` for an orthographic camera.
pub fn orbit_camera(grid: &Grid, az: f64, el: f64, parallel: bool) -> Camera {
    let (lo, hi) = grid.bounds_world();
    let mut c = Camera::reset_to_bounds(lo, hi, parallel);
    c.azimuth(az);
    c.elevation(el);
    c.orthogonalize_view_up();
    c
}
