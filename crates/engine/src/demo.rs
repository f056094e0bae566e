//! The MRI head built into the binary: the demo volume `volsplat render` shows with no input
//! (`PhantomKind::Brain`). VolPack's `brainsmall` (128 × 128 × 84 u8, BSD-3; licence and source in
//! `crates/engine/data/README.md`), turned (a rotation, no mirror) so that it stands like the
//! other built-in heads: top towards +y, face towards +z, the left ear towards +x. Spacing 1 (not
//! recorded in the source).

use crate::error::{EngineError, Result};
use std::io::Read;
use volsplat_core::glam::DMat3;
use volsplat_core::{AnyVolume, Grid, Volume};

/// The voxels, gzip-compressed, x fastest (589 KB).
static BRAIN_GZ: &[u8] = include_bytes!("../data/mri_brainsmall.u8.gz");

/// Grid of the built-in MRI, voxels (x, y, z).
pub const BRAIN_DIMS: [usize; 3] = [84, 128, 128];

/// Decompresses the built-in MRI head (about 5 ms).
pub fn brain_volume() -> Result<AnyVolume> {
    let n: usize = BRAIN_DIMS.iter().product();
    let mut data = Vec::with_capacity(n);
    flate2::read::GzDecoder::new(BRAIN_GZ)
        .take(n as u64 + 1)
        .read_to_end(&mut data)
        .map_err(|e| EngineError::request("volume", format!("built-in MRI: {e}")))?;
    if data.len() != n {
        return Err(EngineError::request(
            "volume",
            format!("built-in MRI holds {} bytes, expected {n}", data.len()),
        ));
    }
    // Centred on the world origin (world units: voxels, i.e. millimetres if the scan was 1 mm).
    let origin = BRAIN_DIMS.map(|d| -0.5 * (d as f64 - 1.0));
    let grid = Grid::new(BRAIN_DIMS, [1.0; 3], origin, DMat3::IDENTITY)?;
    Ok(Volume::new(grid, data)?.into())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_built_in_mri_decompresses_to_its_grid_with_the_head_in_the_middle() {
        let v = brain_volume().unwrap();
        assert_eq!(v.grid().dims, BRAIN_DIMS);
        let (lo, hi) = v.value_range();
        assert!(lo == 0.0 && hi > 150.0, "{lo} {hi}");
        let AnyVolume::U8(v) = v else {
            panic!("u8 expected")
        };
        // The head fills the middle and air the corners.
        let at = |x: usize, y: usize, z: usize| v.data()[x + 84 * (y + 128 * z)];
        assert!(at(0, 0, 0) < 16, "{}", at(0, 0, 0));
        assert!(at(42, 64, 64) > 20, "{}", at(42, 64, 64));
    }
}
