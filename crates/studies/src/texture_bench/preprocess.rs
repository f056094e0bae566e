//! The pre-processing costs (Tables 5.5, 5.9): NIL maps of the cosine texture, the EWA weight
//! table, and NIL maps of discrete textures of several sizes.

use super::{PreprocessRow, TextureBenchSettings};
use glam::DVec3;
use std::time::Instant;
use volsplat_filter::Result;
use volsplat_filter::ewa::{EwaSettings, EwaTable};
use volsplat_filter::nil::{CosineNilMap, DiscreteNilMap, DiscreteNilSettings};
use volsplat_filter::texture::{CosineTexture, DiscreteTexture, Reconstruction};

/// Builds each pre-processed structure once and times it: NIL maps of `tex` for `M = 1, 4`
/// (`γ_max = 10`), the default EWA table, and for each of the settings' pyramid sizes `n` the
/// NIL maps (`M = 1, 4`) of `tex` sampled on an `n³` trilinear grid.
pub(super) fn preprocessing(
    settings: &TextureBenchSettings,
    tex: &CosineTexture,
) -> Result<Vec<PreprocessRow>> {
    let mut preprocessing = Vec::new();
    for m in [1usize, 4] {
        let t = Instant::now();
        let map = CosineNilMap::build(tex, m, 10)?;
        preprocessing.push(PreprocessRow {
            what: format!("NIL M={m}, cosine 4×4×4, γ_max = 10"),
            seconds: t.elapsed().as_secs_f64(),
            stored_values: map.stored_values(),
        });
    }
    let t = Instant::now();
    let table = EwaTable::new(&EwaSettings::default())?;
    preprocessing.push(PreprocessRow {
        what: "EWA table".into(),
        seconds: t.elapsed().as_secs_f64(),
        stored_values: table.len(),
    });
    for &n in &settings.pyramid_sizes {
        let d = DiscreteTexture::sample(
            tex,
            [n, n, n],
            DVec3::ZERO,
            1.0 / n as f64,
            Reconstruction::Trilinear,
        )?;
        for m in [1usize, 4] {
            let map = DiscreteNilMap::build(
                &d,
                &DiscreteNilSettings {
                    order: m,
                    ..Default::default()
                },
            )?;
            preprocessing.push(PreprocessRow {
                what: format!("NIL M={m}, discrete {n}³ trilinear"),
                seconds: map.build_seconds(),
                stored_values: map.stored_values(),
            });
        }
    }
    Ok(preprocessing)
}
