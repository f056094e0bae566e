//! Sort-last ranks that read only their bricks of an OME-Zarr store (issue 32 item 2): the
//! same bits as the ranks drawing the same samples from the volume in memory, for 1–4 ranks,
//! and each rank's reads counted.

use super::*;
use crate::scene::{TransferSpec, VolumeSource};
use crate::{Mode, RenderRequest, Renderer, Scene};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use volsplat_core::AnyVolume;
use volsplat_io::{ZarrSelection, ZarrStore, ZarrWriteOptions, write_zarr};

/// The demo head written as a store with chunks of 16 in `dir`, and the store's level 0 read
/// whole (the same samples and grid, in memory).
fn store(dir: &Path) -> (PathBuf, Arc<AnyVolume>) {
    let head = Renderer::new().volume(&Scene::default().volume).unwrap();
    let path = dir.join("head.zarr");
    let mut options = ZarrWriteOptions::default();
    options.chunk = 16;
    write_zarr(&path, &head, &options).unwrap();
    let store = ZarrStore::open(&path, &volsplat_io::Limits::default()).unwrap();
    let whole = store.read_level(0, ZarrSelection::default()).unwrap();
    (path, Arc::new(whole))
}

fn file(path: &Path) -> VolumeSource {
    serde_json::from_value(serde_json::json!({ "file": { "path": path } })).unwrap()
}

fn bits(out: &SortLastImage) -> (Vec<u32>, Option<Vec<u32>>) {
    let img = out
        .image
        .pixels()
        .iter()
        .flatten()
        .map(|v| v.to_bits())
        .collect();
    let values = out
        .values
        .as_ref()
        .map(|v| v.values().iter().map(|x| x.to_bits()).collect());
    (img, values)
}

/// Composite with a preset, MIP and MinIP with the automatic window (both need the level's
/// value range, which the ranks share), pre-integration left automatic (its test folds every
/// block's range), both projections, bricks of 16 cells: the store read per rank gives the
/// bits of the same sort-last render from memory for 1–4 ranks, and every rank reads exactly
/// the cache bricks of its sort-last bricks (bricks of 16 cells: the same boxes), each once in
/// its frame, their union the level once.
#[test]
fn ranks_read_only_their_bricks_of_a_store_and_draw_the_in_memory_bits() {
    let dir = tempfile::tempdir().unwrap();
    let (path, whole) = store(dir.path());
    let dims = whole.grid().dims;
    let cells = dims.map(|d| d - 1);
    let sort_bricks = cells.map(|c| c.div_ceil(16)).iter().product::<usize>();
    let level_bytes =
        dims.iter().product::<usize>() as u64 * whole.scalar_type().size_bytes() as u64;
    for mode in [Mode::Composite, Mode::Mip, Mode::Minip] {
        for perspective in [false, true] {
            let mut mem = RenderRequest::new(Scene::default(), 40, 32);
            mem.mode = mode;
            mem.scene.volume = VolumeSource::Memory(Arc::clone(&whole));
            if mode == Mode::Composite {
                mem.scene.transfer_function =
                    TransferSpec::Preset(volsplat_core::presets::Preset::CtSkin);
            }
            if perspective {
                let cam = Renderer::new().camera(&mem).unwrap();
                mem.scene.camera = crate::CameraSpec::Explicit {
                    camera: volsplat_core::Camera {
                        parallel_projection: false,
                        ..cam
                    },
                    orbit: Default::default(),
                };
            }
            let reference = FakeCluster { size: 1 }
                .run(|comm| render_sort_last(comm, &mut Renderer::new(), &mem, 16))
                .remove(0)
                .unwrap()
                .unwrap();
            let drawn = match &reference.values {
                Some(v) => v.values().iter().filter(|x| !x.is_nan()).count(),
                None => reference
                    .image
                    .pixels()
                    .iter()
                    .filter(|p| p[3] > 0.0)
                    .count(),
            };
            assert!(drawn > 200, "{mode:?}: {drawn} pixels drawn");
            let mut req = mem.clone();
            req.scene.volume = file(&path);
            for ranks in 1..=4 {
                let label = format!("{mode:?} perspective={perspective} ranks={ranks}");
                let out = FakeCluster { size: ranks }.run(|comm| {
                    let mut r = Renderer::new();
                    let image = render_sort_last(comm, &mut r, &req, 16);
                    let leaves = {
                        let t = BrickTree::new(cells.map(|c| c.div_ceil(16)), 16).unwrap();
                        let (a, b) = t.rank_leaves(comm.rank(), comm.size());
                        b - a
                    };
                    (image, r.rank_reads(), leaves)
                });
                let mut union = 0;
                for (rank, (image, reads, leaves)) in out.iter().enumerate() {
                    let reads = reads.unwrap_or_else(|| panic!("{label}: rank {rank} read whole"));
                    assert_eq!(reads.brick, 16, "{label}");
                    assert_eq!(reads.level_bricks, sort_bricks, "{label}");
                    assert_eq!(reads.level_bytes, level_bytes);
                    // Exactly the rank's bricks: scanned once each, read at most once by the
                    // frame (the cache holds them all).
                    assert_eq!(reads.region_bricks, *leaves, "{label} rank {rank}");
                    let slot = 19u64.pow(3) * whole.scalar_type().size_bytes() as u64;
                    assert_eq!(reads.scan_bytes, slot * *leaves as u64, "{label}");
                    assert!(reads.frames.reads as usize <= *leaves, "{label}: {reads:?}");
                    assert_eq!(reads.frames.evictions, 0);
                    if ranks > 1 {
                        assert!(reads.scan_bytes < level_bytes, "{label}: {reads:?}");
                    }
                    union += reads.region_bricks;
                    if rank == 0 {
                        let image = image.as_ref().unwrap().as_ref().unwrap();
                        assert_eq!(bits(image), bits(&reference), "{label}");
                    } else {
                        assert!(image.as_ref().unwrap().is_none());
                    }
                }
                assert_eq!(
                    union, sort_bricks,
                    "{label}: the ranks' bricks partition the level"
                );
            }
        }
    }
}

/// What a rank reading its bricks cannot draw as the whole volume would is refused on every
/// rank alike: the automatic composite transfer function (a histogram of the whole level).
/// X-ray reads the level whole (the sheets read every voxel): no part is opened.
#[test]
fn the_automatic_composite_function_is_refused_and_x_ray_reads_the_level_whole() {
    let dir = tempfile::tempdir().unwrap();
    let (path, _) = store(dir.path());
    let mut req = RenderRequest::new(Scene::default(), 24, 20);
    req.scene.volume = file(&path);
    let outs =
        FakeCluster { size: 2 }.run(|comm| render_sort_last(comm, &mut Renderer::new(), &req, 16));
    for out in outs {
        let e = out.unwrap_err().to_string();
        assert!(
            e.contains("transfer_function") && e.contains("histogram"),
            "{e}"
        );
    }
    req.mode = Mode::Xray;
    let out = FakeCluster { size: 2 }.run(|comm| {
        let mut r = Renderer::new();
        let image = render_sort_last(comm, &mut r, &req, 16);
        (image.map(|i| i.is_some()), r.rank_reads())
    });
    assert!(matches!(out[0], (Ok(true), None)), "{:?}", out[0]);
    assert!(matches!(out[1], (Ok(false), None)), "{:?}", out[1]);
}
