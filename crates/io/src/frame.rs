//! The one world frame (docs/design.md §3, decision 0008): readers return grids in **LPS**, DICOM's
//! and ITK's patient frame (+x towards the patient's left, +y posterior, +z superior). Files in
//! RAS (NIfTI, NRRD `right-anterior-superior`) or LAS are converted by negating the axes that
//! differ, which maps both the direction matrix and the origin: `D' = F·D`, `o' = F·o` with
//! `F = diag(±1, ±1, 1)`. Spacing and voxel order are unchanged, so the samples are untouched.

use crate::error::{IoError, Result};
use std::path::Path;
use volsplat_core::Grid;
use volsplat_core::glam::{DMat3, DVec3};

/// Signs that take a point from the named anatomical frame to LPS, or `None` for frames that
/// are not anatomical (`scanner-xyz`, `3d-right-handed`, ...: kept as written).
pub(crate) fn lps_signs(space: &str) -> Option<[f64; 3]> {
    match space {
        "right-anterior-superior" | "ras" => Some([-1.0, -1.0, 1.0]),
        "left-anterior-superior" | "las" => Some([1.0, -1.0, 1.0]),
        "left-posterior-superior" | "lps" => Some([1.0, 1.0, 1.0]),
        _ => None,
    }
}

/// Applies `F = diag(signs)` to a grid's direction and origin (a world-frame change).
pub(crate) fn flip_world(
    grid: &Grid,
    signs: [f64; 3],
) -> std::result::Result<Grid, volsplat_core::CoreError> {
    let f = DMat3::from_diagonal(DVec3::from(signs));
    let origin = f * DVec3::from(grid.origin);
    Grid::new(
        grid.dims,
        grid.spacing,
        origin.to_array(),
        f * grid.direction,
    )
}

/// Converts a grid given in the NRRD `space` named by `space` (lower case, words normalised) to
/// LPS; returns the grid and a note for the user when something was converted or kept as is.
pub(crate) fn to_lps(path: &Path, space: &str, grid: Grid) -> Result<(Grid, Option<String>)> {
    match lps_signs(space) {
        Some([1.0, 1.0, 1.0]) => Ok((grid, None)),
        Some(signs) => {
            let g = flip_world(&grid, signs).map_err(|e| IoError::core(path, e))?;
            Ok((
                g,
                Some(format!(
                    "world frame: `space: {space}` converted to LPS (negated {})",
                    if signs[0] < 0.0 { "x and y" } else { "y" }
                )),
            ))
        }
        None => Ok((
            grid,
            Some(format!(
                "world frame: `space: {space}` is not an anatomical frame; kept as written"
            )),
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ras_to_lps_negates_x_and_y_of_direction_and_origin() {
        let g = Grid::new(
            [2, 3, 4],
            [1.0, 2.0, 3.0],
            [10.0, 20.0, 30.0],
            DMat3::IDENTITY,
        )
        .unwrap();
        let (l, note) = to_lps(Path::new("a"), "ras", g.clone()).unwrap();
        assert!(note.unwrap().contains("LPS"));
        assert_eq!(l.origin, [-10.0, -20.0, 30.0]);
        assert_eq!(
            l.direction,
            DMat3::from_diagonal(DVec3::new(-1.0, -1.0, 1.0))
        );
        // A voxel's world position is the RAS one with x and y negated.
        let p = DVec3::new(1.0, 2.0, 3.0);
        let (a, b) = (g.world_from_index(p), l.world_from_index(p));
        assert_eq!(b, DVec3::new(-a.x, -a.y, a.z));
        let (l, note) = to_lps(Path::new("a"), "lps", g.clone()).unwrap();
        assert!(note.is_none());
        assert_eq!(l, g);
        let (l, _) = to_lps(Path::new("a"), "left-anterior-superior", g.clone()).unwrap();
        assert_eq!(l.origin, [10.0, -20.0, 30.0]);
        let (l, note) = to_lps(Path::new("a"), "scanner-xyz", g.clone()).unwrap();
        assert_eq!(l, g);
        assert!(note.unwrap().contains("kept as written"));
    }
}
