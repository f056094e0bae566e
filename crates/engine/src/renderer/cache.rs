//! What a [`Renderer`](super::Renderer) keeps between frames, and the keys that say when it
//! still holds: each cache is one slot, rebuilt when its key changes.

use crate::error::{EngineError, Result};
use crate::request::{DensityChoice, Mode, RenderRequest};
use crate::scene::{LightSpec, ShadingTerms, TransferSpec, VolumeSource};
use std::sync::Arc;
use volsplat_core::{AnyVolume, AutoTransfer, CrioTables, Light, Preset, TransferFunction};
use volsplat_filter::display::DisplayVolume;
use volsplat_filter::nil::DiscreteNilMap;
use volsplat_filter::texture::Reconstruction;
use volsplat_splat::ListVoxels;

/// One cache slot: the key the value was built from, and the value.
pub(super) struct Cached<K, V> {
    pub(super) key: K,
    pub(super) value: V,
}

/// A value taken from a cache slot.
pub(super) struct Fetched<'a, V> {
    /// The value.
    pub(super) value: &'a V,
    /// Whether it was built in this call (its cost counts as preparation).
    pub(super) fresh: bool,
}

/// The value in `slot` for `key`, built by `build` unless the slot holds that key already.
pub(super) fn cached<K: PartialEq, V>(
    slot: &mut Option<Cached<K, V>>,
    key: K,
    build: impl FnOnce() -> Result<V>,
) -> Result<Fetched<'_, V>> {
    // Take the old value out first, so a rebuild never holds two copies in memory.
    let (entry, fresh) = match slot.take() {
        Some(c) if c.key == key => (c, false),
        _ => (
            Cached {
                key,
                value: build()?,
            },
            true,
        ),
    };
    Ok(Fetched {
        value: &slot.insert(entry).value,
        fresh,
    })
}

/// A loaded volume and its reader's notes.
pub(super) struct Loaded {
    pub(super) volume: Arc<AnyVolume>,
    pub(super) notes: Vec<String>,
}

/// The automatic transfer function of a volume and what the rule found.
pub(super) struct AutoTf {
    pub(super) tf: TransferFunction,
    pub(super) description: String,
}

/// The Chapter 6 state kept between frames.
pub(super) struct DisplayState {
    /// The densities.
    pub(super) volume: DisplayVolume,
    /// The NIL map, where the display evaluates one.
    pub(super) map: Option<DiscreteNilMap>,
    /// The map's build time, ms (0 without a map).
    pub(super) map_build_ms: f64,
}

/// Everything the classification tables are built from ([`build_tables`]). Equality, not a
/// hash: each cache holds one entry, and the transfer function's floats have no `Eq`.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct TablesKey {
    tf: TransferFunction,
    lights: Vec<LightSpec>,
    shading: ShadingTerms,
    surface_enhance: Option<[f64; 2]>,
    depth_cue: Option<[f64; 2]>,
}

impl TablesKey {
    /// The key of the tables of `request` with transfer function `tf`.
    pub(super) fn new(request: &RenderRequest, tf: &TransferFunction) -> TablesKey {
        let s = &request.scene;
        TablesKey {
            tf: tf.clone(),
            lights: s.lights.clone(),
            shading: s.shading,
            surface_enhance: s.surface_enhance,
            depth_cue: s.depth_cue,
        }
    }
}

/// What a splat list is built from.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct ListKey {
    pub(super) volume: VolumeSource,
    pub(super) tables: TablesKey,
    pub(super) voxels: ListVoxels,
    /// `quality.list_threshold`'s bits.
    pub(super) threshold: u32,
    pub(super) subsample: usize,
}

/// What the Chapter 6 display volume and NIL map are built from.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct DisplayKey {
    pub(super) volume: VolumeSource,
    pub(super) tf: TransferFunction,
    pub(super) density: DensityChoice,
    /// The map's patch order, where the display needs a map.
    pub(super) map_order: Option<usize>,
    pub(super) max_map_values: usize,
}

/// A request's transfer function, and what to tell the user about it.
pub(super) struct ResolvedTf {
    /// The transfer function (data units).
    pub(super) tf: TransferFunction,
    /// A preset that misses the data.
    pub(super) warning: Option<String>,
    /// What the automatic rule found, given when the function is first made.
    pub(super) note: Option<String>,
}

/// The transfer function of `request` for `vol` (whose value range is `range`): the scene's, a
/// preset, or the automatic choice (see [`TransferSpec::Auto`]). `auto` caches the histogram
/// rule per volume.
pub(super) fn resolve_tf(
    request: &RenderRequest,
    vol: &Arc<AnyVolume>,
    range: (f64, f64),
    auto: &mut Option<Cached<VolumeSource, AutoTf>>,
) -> Result<ResolvedTf> {
    let scene = match &request.scene.volume {
        VolumeSource::Phantom { phantom, .. } => phantom.scene_transfer_function(),
        _ => None,
    };
    let (mut warning, mut note) = (None, None);
    let mut tf = match &request.scene.transfer_function {
        TransferSpec::Function(tf) => tf.clone(),
        TransferSpec::Preset(preset) => {
            warning = preset.range_warning(range);
            preset.transfer_function(range)
        }
        TransferSpec::Auto => match scene {
            Some(tf) => tf,
            None if matches!(request.mode, Mode::Mip | Mode::Minip | Mode::Xray) => {
                // Projections without a transfer function: an opaque grey window over the data
                // (constant data: the unit below the value, which then shows white). X-ray does
                // not use it (`xray_weight_tf`): it is what `--save-scene` records.
                let (lo, hi) = if range.1 > range.0 {
                    range
                } else {
                    (range.0 - 1.0, range.0)
                };
                TransferFunction::ramp(lo, hi, 1.0)
            }
            None if request.scene.volume.is_demo_head() => Preset::CtSkin.transfer_function(range),
            None => {
                // The histogram rule reads the whole volume: once per volume.
                // Keyed by the source, never by the volume's address, which a later volume may
                // reuse; a `Memory` source holds its volume alive.
                let key = request.scene.volume.clone();
                let got = cached(auto, key, || {
                    let a = AutoTransfer::from_volume(vol);
                    Ok(AutoTf {
                        tf: a.transfer_function.clone(),
                        description: a.describe(),
                    })
                })?;
                if got.fresh {
                    note = Some(got.value.description.clone());
                }
                got.value.tf.clone()
            }
        },
    };
    tf.validate()?;
    Ok(ResolvedTf { tf, warning, note })
}

/// The tables of an X-ray (which ignores the transfer function): opacity 1 wherever the X-ray
/// weight (`volsplat_splat::xray_weight`) is not zero, 0 where it is, so that the splat list
/// keeps exactly the voxels that add to the integral (a transfer function made the list drop
/// the voxels it hid, air and soft tissue alike). With an offset `o`: 0 up to `−o`, 1 from
/// `−o + δ` on; raw: 0 at 0 only. `δ` is far below any data step (10⁻³ of the offset, 10⁻⁶
/// raw); a value inside it keeps its voxel, which adds (almost) nothing.
pub(super) fn xray_weight_tf(offset: Option<f64>) -> TransferFunction {
    let points = match offset {
        Some(o) => {
            let d = 1e-3 * o.abs().max(1.0);
            vec![[-o, 0.0], [-o + d, 1.0]]
        }
        None => vec![[-1e-6, 1.0], [0.0, 0.0], [1e-6, 1.0]],
    };
    let (lo, hi) = (points[0][0], points[points.len() - 1][0]);
    TransferFunction {
        color: vec![[lo, 1.0, 1.0, 1.0], [hi, 1.0, 1.0, 1.0]],
        scalar_opacity: points,
        ..TransferFunction::ramp(lo, hi, 1.0)
    }
}

/// The classification tables of `request` with transfer function `tf`: lights (a headlight
/// when the scene has none), shading switches, surface enhancement and depth cue.
pub(super) fn build_tables(request: &RenderRequest, tf: &TransferFunction) -> Result<CrioTables> {
    let s = &request.scene;
    let lights = if s.lights.is_empty() {
        vec![Light::headlight()]
    } else {
        s.lights
            .iter()
            .enumerate()
            .map(|(n, l)| l.to_light(&format!("scene.lights[{n}]")))
            .collect::<Result<Vec<_>>>()?
    };
    let mut tables =
        CrioTables::from_transfer_function_lit(tf, volsplat_core::crio::DEFAULT_TABLE_LEN, lights)?;
    tables.shading.emission &= s.shading.emission;
    tables.shading.diffuse &= s.shading.diffuse;
    tables.shading.specular &= s.shading.specular;
    if let Some([lo, hi]) = s.surface_enhance {
        tables = tables.with_surface_enhancement(lo, hi)?;
    }
    if let Some([near, far]) = s.depth_cue {
        tables = tables.with_depth_cue(near, far)?;
    }
    Ok(tables)
}

/// The densities of the Chapter 6 displays for `vol` (the transfer function's scalar opacity
/// or the data normalised to its range), averaged over `factor`³ blocks (1: as is; the last
/// block of an axis averages what it holds; the grid keeps its direction, with spacing ×
/// `factor` and the origin at the first block's centre).
pub(super) fn display_volume(
    vol: &AnyVolume,
    tf: &TransferFunction,
    density: DensityChoice,
    factor: usize,
) -> Result<DisplayVolume> {
    let f = vol.to_f32();
    let (lo, hi) = vol.value_range();
    let span = if hi > lo { hi - lo } else { 1.0 };
    let d: Vec<f64> = match density {
        DensityChoice::Tf => f.data().iter().map(|&v| tf.opacity_at(v as f64)).collect(),
        DensityChoice::Data => f.data().iter().map(|&v| (v as f64 - lo) / span).collect(),
    };
    if factor <= 1 {
        return Ok(DisplayVolume::new(f.grid(), &d, Reconstruction::Trilinear)?);
    }
    let g = f.grid();
    let [nx, ny, nz] = g.dims;
    let dims = g.dims.map(|n| n.div_ceil(factor).max(2));
    let mut sum = vec![0.0f64; dims[0] * dims[1] * dims[2]];
    let mut count = vec![0u32; sum.len()];
    for z in 0..nz {
        for y in 0..ny {
            for x in 0..nx {
                let c = [
                    (x / factor).min(dims[0] - 1),
                    (y / factor).min(dims[1] - 1),
                    (z / factor).min(dims[2] - 1),
                ];
                let i = c[0] + dims[0] * (c[1] + dims[1] * c[2]);
                sum[i] += d[x + nx * (y + ny * z)];
                count[i] += 1;
            }
        }
    }
    let avg: Vec<f64> = sum
        .iter()
        .zip(&count)
        .map(|(&s, &n)| if n > 0 { s / n as f64 } else { 0.0 })
        .collect();
    let half = (factor as f64 - 1.0) * 0.5;
    let offset = g.direction
        * volsplat_core::glam::DVec3::new(
            half * g.spacing[0],
            half * g.spacing[1],
            half * g.spacing[2],
        );
    let origin = (volsplat_core::glam::DVec3::from(g.origin) + offset).to_array();
    let grid = volsplat_core::Grid::new(
        dims,
        g.spacing.map(|s| s * factor as f64),
        origin,
        g.direction,
    )?;
    Ok(DisplayVolume::new(&grid, &avg, Reconstruction::Trilinear)?)
}

/// A NIL map size for messages: values and bytes (8 per value).
pub(super) fn map_size(values: u128) -> String {
    let bytes = values as f64 * 8.0;
    let (b, unit) = if bytes >= 1e9 {
        (bytes / 1e9, "GB")
    } else {
        (bytes / 1e6, "MB")
    };
    format!("{values} values ({b:.1} {unit})")
}

/// Half the memory the system reports available, in f64 values (2 GiB where unknown).
pub(super) fn auto_map_budget() -> usize {
    let available = std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|m| {
            m.lines()
                .find(|l| l.starts_with("MemAvailable:"))
                .and_then(|l| l.split_whitespace().nth(1))
                .and_then(|kb| kb.parse::<u64>().ok())
        })
        .map(|kb| kb.saturating_mul(1024))
        .unwrap_or(4 << 30);
    (available / 2 / 8).min(usize::MAX as u64) as usize
}

/// The rayon pool of `threads` workers (the machine's count where `None`).
pub(super) fn build_pool(threads: Option<usize>) -> Result<Arc<rayon::ThreadPool>> {
    let mut b = rayon::ThreadPoolBuilder::new();
    if let Some(n) = threads {
        b = b.num_threads(n);
    }
    b.build().map(Arc::new).map_err(|e| EngineError::Threads {
        threads: threads.unwrap_or(0),
        message: e.to_string(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A key changes exactly when something the tables are built from changes (it used to be
    /// a JSON string of the same fields).
    #[test]
    fn tables_key_follows_what_the_tables_are_built_from() {
        let req = RenderRequest::new(crate::Scene::default(), 8, 8);
        let tf = TransferFunction::ramp(0.0, 1.0, 1.0);
        let key = TablesKey::new(&req, &tf);
        assert_eq!(key, TablesKey::new(&req.clone(), &tf.clone()));
        assert_ne!(
            key,
            TablesKey::new(&req, &TransferFunction::ramp(0.0, 2.0, 1.0))
        );
        let mut r = req.clone();
        r.scene.depth_cue = Some([0.1, 0.9]);
        assert_ne!(key, TablesKey::new(&r, &tf));
        let mut r = req.clone();
        r.scene.shading.specular = false;
        assert_ne!(key, TablesKey::new(&r, &tf));
        let mut r = req.clone();
        r.scene.surface_enhance = Some([0.0, 0.5]);
        assert_ne!(key, TablesKey::new(&r, &tf));
        // Not part of the tables: the camera, the size, the quality.
        let mut r = req.clone();
        r.width = 99;
        r.quality.subsample = 3;
        assert_eq!(key, TablesKey::new(&r, &tf));
    }

    /// A slot builds once per key, reports whether it built, and rebuilds on a new key.
    #[test]
    fn a_slot_builds_once_per_key() {
        let mut slot = None;
        let mut builds = 0;
        let mut get = |k: u32| -> (u32, bool) {
            let f = cached(&mut slot, k, || {
                builds += 1;
                Ok(k * 10)
            })
            .unwrap();
            (*f.value, f.fresh)
        };
        assert_eq!(get(1), (10, true));
        assert_eq!(get(1), (10, false));
        assert_eq!(get(2), (20, true));
        assert_eq!(builds, 2);
    }
}
