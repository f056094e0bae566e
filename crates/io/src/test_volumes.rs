//! Test fixtures the writers' round trips share: one volume of every sample type on a grid.

use volsplat_core::{AnyVolume, Grid, Volume};

/// One volume of each sample type (u8, i8, u16, i16, f32) on `g`, with values that use each
/// type's range (negative where signed); the f32 samples step by `f32_step` from −3.
pub(crate) fn every_type(g: &Grid, f32_step: f32) -> Vec<AnyVolume> {
    let n = g.voxel_count();
    vec![
        Volume::new(g.clone(), (0..n).map(|i| (i * 7 % 256) as u8).collect())
            .unwrap()
            .into(),
        Volume::new(g.clone(), (0..n).map(|i| i as i8 - 12).collect())
            .unwrap()
            .into(),
        Volume::new(g.clone(), (0..n).map(|i| (i * 2731) as u16).collect())
            .unwrap()
            .into(),
        Volume::new(g.clone(), (0..n).map(|i| i as i16 * -1000 + 5).collect())
            .unwrap()
            .into(),
        Volume::new(
            g.clone(),
            (0..n).map(|i| i as f32 * f32_step - 3.0).collect(),
        )
        .unwrap()
        .into(),
    ]
}
