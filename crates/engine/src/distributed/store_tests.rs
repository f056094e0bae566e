//! Sort-last ranks that read only their bricks of an OME-Zarr store or a NRRD file with a raw
//! payload (issue 32 item 2): the same bits as the ranks drawing the same samples from the
//! volume in memory, for 1–4 ranks, and each rank's reads counted.

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

/// The demo head written as a NRRD file with a raw payload in `dir`, and the file read whole.
fn nrrd(dir: &Path) -> (PathBuf, Arc<AnyVolume>) {
    let head = Renderer::new().volume(&Scene::default().volume).unwrap();
    let path = dir.join("head.nrrd");
    volsplat_io::write_nrrd(&path, &head, false).unwrap();
    let whole = volsplat_io::read_nrrd(&path).unwrap();
    (path, Arc::new(whole))
}

/// The bytes of the halo boxes of the bricks of 16 cells whose cells meet `region`, as stored
/// (`size` bytes a sample): what a scan of a NRRD part reads from the file.
fn halo_bytes(dims: [usize; 3], region: &[[[usize; 3]; 2]], size: usize) -> u64 {
    let layout = volsplat_core::source::BrickLayout::new(
        volsplat_core::Grid::with_dims(dims).unwrap(),
        0,
        16,
    )
    .unwrap();
    let meets = volsplat_splat::bricks_meeting(&layout, region);
    let d = layout.dims();
    let mut total = 0;
    for (i, _) in meets.iter().enumerate().filter(|(_, m)| **m) {
        let key = layout
            .key([i % d[0], i / d[0] % d[1], i / (d[0] * d[1])])
            .unwrap();
        let h = layout.halo_voxels(key).unwrap();
        total += (h.iter().map(|r| r.len()).product::<usize>() * size) as u64;
    }
    total
}

/// For each mode (composite with `tf`, MIP and MinIP with the automatic window: both need the
/// level's value range, which the ranks share) and projection, the file at `path` rendered
/// sort-last by 1–4 ranks reading their parts gives the bits of the same sort-last render of
/// `whole` in memory, and every rank reads exactly the cache bricks of its sort-last bricks
/// (bricks of 16 cells: the same boxes), each once in its scan and at most once in its frame,
/// their union the level once; from a NRRD file, the bytes read from the file are those bricks'
/// halo boxes (scanned once, or twice where the part held NaN or ±∞: `rescans`), fewer than the
/// file's with several ranks.
fn assert_ranks_draw_the_in_memory_bits(
    path: &Path,
    whole: &Arc<AnyVolume>,
    tf: TransferSpec,
    rescans: bool,
) {
    let dims = whole.grid().dims;
    let cells = dims.map(|d| d - 1);
    let sort_bricks = cells.map(|c| c.div_ceil(16)).iter().product::<usize>();
    for mode in [Mode::Composite, Mode::Mip, Mode::Minip] {
        for perspective in [false, true] {
            let mut mem = RenderRequest::new(Scene::default(), 40, 32);
            mem.mode = mode;
            mem.scene.volume = VolumeSource::Memory(Arc::clone(whole));
            if mode == Mode::Composite {
                mem.scene.transfer_function = tf.clone();
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
            req.scene.volume = file(path);
            for ranks in 1..=4 {
                let label = format!(
                    "{} {mode:?} perspective={perspective} ranks={ranks}",
                    path.display()
                );
                let out = run_ranks(&req, cells, ranks);
                let mut union = 0;
                for (rank, (image, reads, leaves, region)) in out.iter().enumerate() {
                    let reads = assert_rank_reads(
                        &label,
                        rank,
                        *reads,
                        (*leaves, region),
                        whole,
                        (ranks, rescans),
                    );
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

/// What each of `ranks` in-process ranks returns for the sort-last render of `req` (bricks of
/// 16 cells over a level of `cells`): its image, what it read, how many of the tree's leaves it
/// drew, and its region.
type RankOut = (
    Result<Option<SortLastImage>>,
    Option<RankReads>,
    usize,
    Vec<[[usize; 3]; 2]>,
);

fn run_ranks(req: &RenderRequest, cells: [usize; 3], ranks: usize) -> Vec<RankOut> {
    let tree = BrickTree::new(cells.map(|c| c.div_ceil(16)), 16).unwrap();
    FakeCluster { size: ranks }.run(|comm| {
        let mut r = Renderer::new();
        let image = render_sort_last(comm, &mut r, req, 16);
        let (a, b) = tree.rank_leaves(comm.rank(), comm.size());
        let region = super::render::rank_region(&tree, comm.rank(), comm.size());
        (image, r.rank_reads(), b - a, region)
    })
}

/// One rank's reads of its part of the file at `path` (bricks of 16 cells, the sort-last
/// bricks' size): exactly its `leaves` sort-last bricks (the boxes of cells `region`), each
/// scanned once (twice where the part held NaN or ±∞: `rescans`) and read at most once by the
/// frames; from a NRRD file, the bytes read are those bricks' halo boxes, fewer than the
/// file's with several ranks. Returns the reads.
fn assert_rank_reads(
    label: &str,
    rank: usize,
    reads: Option<RankReads>,
    (leaves, region): (usize, &[[[usize; 3]; 2]]),
    whole: &AnyVolume,
    (ranks, rescans): (usize, bool),
) -> RankReads {
    let dims = whole.grid().dims;
    let cells = dims.map(|d| d - 1);
    let sort_bricks = cells.map(|c| c.div_ceil(16)).iter().product::<usize>();
    let size = whole.scalar_type().size_bytes();
    let level_bytes = dims.iter().product::<usize>() as u64 * size as u64;
    let leaves = &leaves;
    let is_nrrd = label.contains(".nrrd");
    let reads = reads.unwrap_or_else(|| panic!("{label}: rank {rank} read whole"));
    assert_eq!(reads.brick, 16, "{label}");
    assert_eq!(reads.level_bricks, sort_bricks, "{label}");
    assert_eq!(reads.level_bytes, level_bytes);
    // Exactly the rank's bricks: scanned once each (twice where rescanned),
    // read at most once by the frame (the cache holds them all).
    assert_eq!(reads.region_bricks, *leaves, "{label} rank {rank}");
    let slot = 19u64.pow(3) * size as u64;
    let scans = reads.scan_bytes / (slot * *leaves as u64).max(1);
    assert_eq!(
        reads.scan_bytes % (slot * *leaves as u64).max(1),
        0,
        "{label}"
    );
    assert!(scans == 1 || (rescans && scans == 2), "{label}: {reads:?}");
    assert!(reads.frames.reads as usize <= *leaves, "{label}: {reads:?}");
    assert_eq!(reads.frames.evictions, 0);
    if ranks > 1 {
        assert!(reads.region_bricks < sort_bricks, "{label}: {reads:?}");
        // Decoded slots (19³ samples for 17³ owned) of a level as large as
        // the head's (1 MiB or more): fewer bytes than the level (not so for
        // the small float volume, whose halos weigh more).
        if !rescans && level_bytes >= 1 << 20 {
            assert!(reads.scan_bytes < level_bytes, "{label}: {reads:?}");
        }
    }
    // From a NRRD file: only the halo boxes of its bricks, as stored.
    assert_eq!(reads.scan_file_bytes.is_some(), is_nrrd, "{label}");
    assert_eq!(reads.frame_file_bytes.is_some(), is_nrrd, "{label}");
    if let (Some(scan), Some(frame)) = (reads.scan_file_bytes, reads.frame_file_bytes) {
        let boxes = halo_bytes(dims, region, size);
        assert_eq!(scan, boxes * scans, "{label} rank {rank}");
        assert!(frame <= boxes, "{label} rank {rank}: {frame} of {boxes}");
        assert!(frame > 0, "{label} rank {rank}: the frame read its bricks");
        if ranks > 1 {
            assert!(boxes < level_bytes, "{label}: {boxes} of {level_bytes}");
        }
    }
    reads
}

/// Ranks reading their bricks of an OME-Zarr store (chunks of 16) draw the bits of the
/// in-memory sort-last render ([`assert_ranks_draw_the_in_memory_bits`]).
#[test]
fn ranks_read_only_their_bricks_of_a_store_and_draw_the_in_memory_bits() {
    let dir = tempfile::tempdir().unwrap();
    let (path, whole) = store(dir.path());
    let tf = TransferSpec::Preset(volsplat_core::presets::Preset::CtSkin);
    assert_ranks_draw_the_in_memory_bits(&path, &whole, tf, false);
}

/// Ranks reading their bricks of a NRRD file with a raw payload (issue 32 item 2: no rank
/// reads the whole file) draw the bits of the in-memory sort-last render of the file read
/// whole, and read from the file only the halo boxes of their bricks.
#[test]
fn ranks_read_only_their_bricks_of_a_nrrd_file_and_draw_the_in_memory_bits() {
    let dir = tempfile::tempdir().unwrap();
    let (path, whole) = nrrd(dir.path());
    let tf = TransferSpec::Preset(volsplat_core::presets::Preset::CtSkin);
    assert_ranks_draw_the_in_memory_bits(&path, &whole, tf, false);
}

/// A float NRRD file (41 × 37 × 34, raw) in `dir` holding NaN, +∞ and −∞ scattered over
/// every rank's part (where `holes`), its lowest finite sample `lowest` near one corner and its highest, 700,
/// near the opposite one (elsewhere −150 to 120).
fn nan_file(dir: &Path, lowest: f32, holes: bool) -> PathBuf {
    let dims = [41usize, 37, 34];
    let c = [20.0, 18.0, 16.5];
    let mut bytes = Vec::new();
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                let p = [i as f32, j as f32, k as f32];
                let r2: f32 = (0..3).map(|a| (p[a] - c[a]).powi(2)).sum();
                let mut v = 100.0 - r2 * 0.25 + (i as f32) * 0.5;
                let hole = if holes {
                    (i * 7 + j * 11 + k * 13) % 101
                } else {
                    3
                };
                match hole {
                    0 => v = f32::NAN,
                    1 => v = f32::INFINITY,
                    2 => v = f32::NEG_INFINITY,
                    _ => {}
                }
                // The extremes: the lowest finite sample near one corner, the highest near
                // the opposite one.
                if [i, j, k] == [1, 1, 1] {
                    v = lowest;
                }
                if [i, j, k] == [39, 35, 32] {
                    v = 700.0;
                }
                bytes.extend_from_slice(&v.to_le_bytes());
            }
        }
    }
    let path = dir.join("nan.nrrd");
    let mut file = format!(
        "NRRD0004\ntype: float\ndimension: 3\nspace: left-posterior-superior\n\
         sizes: {} {} {}\nspace directions: (1,0,0) (0,1,0) (0,0,1)\nencoding: raw\n\
         endian: little\n\n",
        dims[0], dims[1], dims[2]
    )
    .into_bytes();
    file.extend(bytes);
    std::fs::write(&path, file).unwrap();
    path
}

/// A float NRRD file holding NaN, +∞ and −∞ scattered over every rank's part, its lowest and
/// highest finite samples in different parts: the ranks share their parts' finite ranges in
/// the set-up round and replace the non-finite samples by the union's extremes (decision
/// 0030), drawing the bits of the in-memory sort-last render of the file read whole (where
/// `Volume::new` replaced them) for 1–4 ranks, a preset that follows the level's range in
/// composite. Before, every rank refused the file.
#[test]
fn a_float_file_with_nan_and_infinities_renders_per_rank_as_in_memory() {
    let dir = tempfile::tempdir().unwrap();
    let path = nan_file(dir.path(), -500.0, true);
    let whole = volsplat_io::read_nrrd(&path).unwrap();
    let nf = *whole.non_finite().unwrap();
    assert_eq!((nf.lowest, nf.highest), (-500.0, 700.0));
    assert!(
        nf.nan > 100 && nf.pos_inf > 100 && nf.neg_inf > 100,
        "{nf:?}"
    );
    let tf = TransferSpec::Preset(volsplat_core::presets::Preset::Ramp);
    assert_ranks_draw_the_in_memory_bits(&path, &Arc::new(whole), tf, true);
}

/// The PSNR (dB) of line integrals `got` against `reference`, peak the largest |reference|.
fn psnr(got: &[f32], reference: &[f32]) -> f64 {
    assert_eq!(got.len(), reference.len());
    let peak = reference
        .iter()
        .fold(0f64, |m, &x| m.max(f64::from(x).abs()));
    let mse = got
        .iter()
        .zip(reference)
        .map(|(&a, &b)| (f64::from(a) - f64::from(b)).powi(2))
        .sum::<f64>()
        / got.len() as f64;
    assert!(peak > 0.0);
    if mse == 0.0 {
        return f64::INFINITY;
    }
    10.0 * (peak * peak / mse).log10()
}

/// X-ray sort-last from the file at `path`, read per rank (each brick's voxels read from the
/// rank's bricks and drawn as a sub-volume, decision 0038), both projections: the same bits
/// for 1–4 ranks, ≥ 60 dB from the single-process X-ray of `whole` (the file read whole), and
/// every rank reads exactly its bricks ([`assert_rank_reads`]); the scene cut by `clipping`.
/// Returns the lowest PSNR.
fn assert_xray_ranks_read_their_bricks(
    path: &Path,
    whole: &Arc<AnyVolume>,
    rescans: bool,
    clipping: &crate::scene::Clipping,
) -> f64 {
    let cells = whole.grid().dims.map(|d| d - 1);
    let sort_bricks = cells.map(|c| c.div_ceil(16)).iter().product::<usize>();
    let mut worst = f64::INFINITY;
    for perspective in [false, true] {
        let mut mem = RenderRequest::new(Scene::default(), 40, 32);
        mem.mode = Mode::Xray;
        mem.scene.volume = VolumeSource::Memory(Arc::clone(whole));
        mem.scene.clipping = clipping.clone();
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
        let single = Renderer::new().render(&mem, &mut |_| true).unwrap();
        let single = single.values.unwrap();
        let drawn = single.values().iter().filter(|&&x| x != 0.0).count();
        assert!(drawn > 200, "{drawn} pixels drawn");
        let mut req = mem.clone();
        req.scene.volume = file(path);
        let mut first: Option<(Vec<u32>, Option<Vec<u32>>)> = None;
        for ranks in 1..=4 {
            let label = format!(
                "{} X-ray perspective={perspective} ranks={ranks}",
                path.display()
            );
            let out = run_ranks(&req, cells, ranks);
            let mut union = 0;
            for (rank, (image, reads, leaves, region)) in out.iter().enumerate() {
                let reads = assert_rank_reads(
                    &label,
                    rank,
                    *reads,
                    (*leaves, region),
                    whole,
                    (ranks, rescans),
                );
                union += reads.region_bricks;
                let image = image.as_ref().unwrap();
                if rank != 0 {
                    assert!(image.is_none(), "{label}");
                    continue;
                }
                let image = image.as_ref().unwrap();
                let values = image.values.as_ref().unwrap().values();
                let db = psnr(values, single.values());
                assert!(
                    db >= 60.0,
                    "{label}: {db:.1} dB from the single-process X-ray"
                );
                eprintln!("{label}: {db:.1} dB from the single-process X-ray");
                worst = worst.min(db);
                match &first {
                    None => first = Some(bits(image)),
                    Some(b) => assert_eq!(&bits(image), b, "{label}: not the bits of 1 rank"),
                }
            }
            assert_eq!(union, sort_bricks, "{label}: the parts partition the level");
        }
    }
    worst
}

/// X-ray ranks read only their bricks of an OME-Zarr store (issue 32 item 2): the same bits
/// for 1–4 ranks in both projections, ≥ 60 dB from the single-process X-ray of the level read
/// whole. Before, every rank read the level whole in X-ray (no part: `rank_reads` was `None`).
#[test]
fn x_ray_ranks_read_only_their_bricks_of_a_store() {
    let dir = tempfile::tempdir().unwrap();
    let (path, whole) = store(dir.path());
    assert_xray_ranks_read_their_bricks(&path, &whole, false, &Default::default());
}

/// X-ray ranks read only the halo boxes of their bricks of a NRRD file with a raw payload,
/// with the same bits for 1–4 ranks and ≥ 60 dB from the single-process X-ray.
#[test]
fn x_ray_ranks_read_only_their_bricks_of_a_nrrd_file() {
    let dir = tempfile::tempdir().unwrap();
    let (path, whole) = nrrd(dir.path());
    assert_xray_ranks_read_their_bricks(&path, &whole, false, &Default::default());
}

/// A float NRRD file whose range looks like CT only as a whole (its lowest sample, −950, in
/// one rank's part; the others' parts hold −150 to 700): the automatic X-ray offset (1000,
/// `crate::xray`) is resolved from the level's range, which the ranks share, so the X-ray per
/// rank is ≥ 60 dB from the single-process X-ray for 1–4 ranks (a brick resolving the offset
/// from its own voxels integrates the raw values: checked to fail so).
#[test]
fn x_ray_per_rank_resolves_the_automatic_offset_from_the_level_s_range() {
    let dir = tempfile::tempdir().unwrap();
    let path = nan_file(dir.path(), -950.0, false);
    let whole = volsplat_io::read_nrrd(&path).unwrap();
    let (offset, _) = crate::xray::XrayDensity::Auto.resolve(whole.value_range());
    assert_eq!(offset, Some(1000.0));
    assert_xray_ranks_read_their_bricks(&path, &Arc::new(whole), false, &Default::default());
}

/// A float NRRD file with NaN, +∞ and −∞ in every part, its finite extremes in different
/// parts: each part replaces them by the level's finite extremes (shared in the set-up round,
/// the part scanned again), so the X-ray per rank is ≥ 60 dB from the single-process X-ray of
/// the file read whole for 1–4 ranks.
#[test]
fn x_ray_per_rank_replaces_non_finite_samples_by_the_level_s_extremes() {
    let dir = tempfile::tempdir().unwrap();
    let path = nan_file(dir.path(), -500.0, true);
    let whole = volsplat_io::read_nrrd(&path).unwrap();
    assert!(whole.non_finite().is_some());
    assert_xray_ranks_read_their_bricks(&path, &Arc::new(whole), true, &Default::default());
}

/// A crop box in voxels (moved to each brick's indices, whose origin is the brick's first
/// voxel) and a clipping plane (world) cut the X-ray per rank as they cut the single-process
/// X-ray: ≥ 60 dB from it for 1–4 ranks, the same bits for every N. Not moving the crop box
/// would cut every brick at the level's box read in the brick's indices.
#[test]
fn x_ray_per_rank_is_cropped_and_clipped_as_the_whole() {
    let dir = tempfile::tempdir().unwrap();
    let (path, whole) = nrrd(dir.path());
    let dims = whole.grid().dims;
    let clipping = crate::scene::Clipping {
        crop: Some(crate::scene::CropBox {
            min: [dims[0] as f64 * 0.2, 3.5, dims[2] as f64 * 0.3],
            max: [
                dims[0] as f64 * 0.85,
                dims[1] as f64 * 0.7,
                dims[2] as f64 - 4.0,
            ],
            units: crate::scene::CropUnits::Voxels,
        }),
        planes: vec![crate::PlaneSpec {
            normal: [0.3, 0.2, 1.0],
            offset: whole
                .grid()
                .world_from_index([0.0, 0.0, dims[2] as f64 * 0.5].into())
                .z,
        }],
    };
    assert_xray_ranks_read_their_bricks(&path, &whole, false, &clipping);
}

/// A gzip NRRD file has no random access: every rank reads it whole in X-ray too (no part
/// opened), and the sort-last X-ray is still the same bits for 1–3 ranks.
#[test]
fn x_ray_of_a_gzip_nrrd_file_is_read_whole_by_every_rank() {
    let dir = tempfile::tempdir().unwrap();
    let head = Renderer::new().volume(&Scene::default().volume).unwrap();
    let path = dir.path().join("head.nrrd");
    volsplat_io::write_nrrd(&path, &head, true).unwrap();
    let mut req = RenderRequest::new(Scene::default(), 32, 24);
    req.mode = Mode::Xray;
    req.scene.volume = file(&path);
    let mut first = None;
    for ranks in 1..=3 {
        let out = FakeCluster { size: ranks }.run(|comm| {
            let mut r = Renderer::new();
            let image = render_sort_last(comm, &mut r, &req, 16);
            (image.unwrap(), r.rank_reads())
        });
        for (rank, (_, reads)) in out.iter().enumerate() {
            assert!(reads.is_none(), "ranks={ranks} rank {rank}: {reads:?}");
        }
        let image = bits(out[0].0.as_ref().unwrap());
        match &first {
            None => first = Some(image),
            Some(b) => assert_eq!(&image, b, "ranks={ranks}"),
        }
    }
}

/// What a rank reading its bricks cannot draw as the whole volume would is refused on every
/// rank alike: the automatic composite transfer function (a histogram of the whole level).
/// X-ray, which draws no transfer function, opens a part (reads only its bricks).
#[test]
fn the_automatic_composite_function_is_refused_and_x_ray_reads_a_part() {
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
    assert!(matches!(out[0], (Ok(true), Some(_))), "{:?}", out[0]);
    assert!(matches!(out[1], (Ok(false), Some(_))), "{:?}", out[1]);
}
