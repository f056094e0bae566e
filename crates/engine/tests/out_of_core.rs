//! OME-Zarr stores read out of core (issue 31 item 4, decision 0039): a level rendered through
//! the brick cache under a budget is the same bits as the level read whole, in every mode the
//! slabs draw, orthographic and perspective; what out-of-core frames cannot draw is refused by
//! name.

use volsplat::core::phantom::{self, Blob, GaussianBlobs};
use volsplat::core::{AnyVolume, Orbit, Preset, ProjectionKind, Volume};
use volsplat::{
    CameraSpec, EngineError, Mode, RenderRequest, Renderer, Scene, TransferSpec, VolumeSource,
};

fn blobs() -> GaussianBlobs {
    let b = |x: f64, y: f64, z: f64, sigma: f64, amplitude: f64| Blob {
        center: volsplat::core::glam::DVec3::new(x, y, z),
        sigma,
        amplitude,
    };
    GaussianBlobs::new(vec![
        b(0.0, 0.0, 0.0, 0.2, 1.0),
        b(0.3, 0.25, -0.2, 0.14, 0.8),
        b(-0.32, 0.2, 0.3, 0.12, 0.9),
    ])
}

/// A u16 volume of `dims` written as an OME-Zarr store with chunks of 32 in `dir`. The ranges
/// sidecars go to a folder of the test's own (`VOLSPLAT_CACHE_DIR`), not the user's cache.
fn store(dir: &std::path::Path, dims: [usize; 3]) -> std::path::PathBuf {
    // SAFETY: every test of this file sets the same kind of value (a temporary folder); a race
    // only changes which one a sidecar goes to.
    unsafe { std::env::set_var("VOLSPLAT_CACHE_DIR", dir.join("cache")) };
    let f = phantom::sample(&blobs(), dims, 1).unwrap();
    let v = Volume::new(
        f.grid().clone(),
        f.data().iter().map(|&x| (x * 3000.0) as u16).collect(),
    )
    .unwrap();
    let path = dir.join("b.zarr");
    let mut options = volsplat::io::ZarrWriteOptions::default();
    options.chunk = 32;
    volsplat::io::write_zarr(&path, &AnyVolume::U16(v), &options).unwrap();
    path
}

fn scene(path: &std::path::Path, azimuth: f64, perspective: bool) -> Scene {
    Scene {
        volume: VolumeSource::File {
            path: path.to_path_buf(),
            raw: None,
            frame: 0,
            array: None,
            series: None,
            level: Default::default(),
            channel: 0,
            timepoint: 0,
        },
        camera: CameraSpec::Orbit(Orbit {
            azimuth: Some(azimuth),
            elevation: Some(25.0),
            projection: perspective.then_some(ProjectionKind::Perspective),
            ..Orbit::default()
        }),
        transfer_function: TransferSpec::Preset(Preset::CtBone),
        ..Scene::default()
    }
}

fn bits(out: &volsplat::Output) -> Vec<u32> {
    let mut v: Vec<u32> = out
        .image
        .pixels()
        .iter()
        .flatten()
        .map(|x| x.to_bits())
        .collect();
    if let Some(values) = &out.values {
        v.extend(values.values().iter().map(|x| x.to_bits()));
    }
    v
}

/// 160 × 150 × 140 u16 (6.4 MiB, 27 bricks of 64³ in slots of 0.57 MiB; the arena is 0.64 of
/// the budget less the skip-block grid): a budget of 16 MiB holds 17 of them, one of 14 MiB
/// fifteen (so frames evict and read again: a thin slab of rows through a 3 × 3 × 3 grid of
/// bricks meets up to 17 of them), one of 10 MiB eleven (fewer than some bands meet: bands
/// march their planes in pieces). Composite (CT-Bone, lit at the samples),
/// MIP and MinIP, from two eyes in each projection: the same bits as the level read whole.
#[test]
fn out_of_core_frames_equal_in_memory_ones_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap();
    let path = store(dir.path(), [160, 150, 140]);
    let mut whole = Renderer::new();
    let mut paged = Renderer::new();
    let mut evicted = 0;
    let mut pieced = 0;
    for mode in [Mode::Composite, Mode::Mip, Mode::Minip] {
        for (azimuth, perspective) in [(30.0, false), (125.0, false), (60.0, true), (200.0, true)] {
            let mut req = RenderRequest::new(scene(&path, azimuth, perspective), 96, 80);
            req.mode = mode;
            let want = whole.render(&req, &mut |_| true).unwrap();
            assert!(
                want.notes.iter().all(|n| !n.contains("out of core")),
                "{:?}",
                want.notes
            );
            for budget in [16u64 << 20, 14 << 20, 10 << 20] {
                req.memory = Some(budget);
                let got = paged.render(&req, &mut |_| true).unwrap();
                let note = got
                    .notes
                    .iter()
                    .find(|n| n.starts_with("out of core: ") && n.contains("read ("));
                assert!(note.is_some(), "{:?}", got.notes);
                pieced += got.notes.iter().filter(|n| n.contains("in pieces")).count();
                // "… read (x MiB), N evicted, …"
                evicted += note
                    .and_then(|n| n.split(", ").nth(1))
                    .and_then(|w| w.split(' ').next())
                    .and_then(|w| w.parse::<usize>().ok())
                    .unwrap();
                assert!(
                    bits(&got) == bits(&want),
                    "{mode:?} azimuth {azimuth} perspective {perspective} budget {budget}: \
                     the out-of-core picture differs"
                );
                assert_eq!(got.camera, want.camera);
            }
        }
    }
    assert!(
        evicted > 0,
        "no frame evicted a brick: the small budget tests nothing"
    );
    assert!(
        pieced > 0,
        "no band was drawn in pieces: the smallest budget tests nothing"
    );
}

/// A volume wider than the budget's bricks, seen along its short axis: one plane of one band
/// of rows crosses a row of 6 bricks, up to two high and two deep (24), and 8 MiB holds 8
/// bricks (decision 0039's least budget), so bands are cut into columns and rows as
/// well as planes (a note says so). The picture is still the level read whole, bit for bit, in
/// composite and MIP, both projections.
#[test]
fn a_plane_of_a_band_above_the_budget_is_drawn_in_columns_with_the_same_bits() {
    let dir = tempfile::tempdir().unwrap();
    let path = store(dir.path(), [384, 128, 128]);
    let mut whole = Renderer::new();
    let mut paged = Renderer::new();
    let mut split = 0;
    for mode in [Mode::Composite, Mode::Mip] {
        for perspective in [false, true] {
            let mut scene = scene(&path, 0.0, perspective);
            if let CameraSpec::Orbit(o) = &mut scene.camera {
                o.elevation = Some(0.0);
            }
            let mut req = RenderRequest::new(scene, 96, 64);
            req.mode = mode;
            let want = whole.render(&req, &mut |_| true).unwrap();
            req.memory = Some(8 << 20);
            let got = paged.render(&req, &mut |_| true).unwrap();
            split += got
                .notes
                .iter()
                .filter(|n| n.contains("pieces of columns or rows"))
                .count();
            assert!(
                bits(&got) == bits(&want),
                "{mode:?} perspective {perspective}: the out-of-core picture differs"
            );
        }
    }
    assert!(
        split > 0,
        "no band was cut into columns: the budget tests nothing"
    );
}

/// What the slabs cannot draw from bricks is an error naming it: X-ray (the sheets read every
/// voxel), a budget below one band's bricks (naming the budget), shading at the voxels.
#[test]
fn what_out_of_core_frames_cannot_draw_is_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let path = store(dir.path(), [100, 90, 80]);
    let mut r = Renderer::new();
    let mut req = RenderRequest::new(scene(&path, 30.0, false), 64, 64);
    req.memory = Some(16 << 20);
    req.mode = Mode::Xray;
    let e = r.render(&req, &mut |_| true).unwrap_err();
    assert!(
        matches!(&e, EngineError::Request { field, .. } if field == "renderer"),
        "{e}"
    );
    req.mode = Mode::Composite;
    req.memory = Some(100_000);
    let e = r.render(&req, &mut |_| true).unwrap_err().to_string();
    assert!(e.contains("budget"), "{e}");
}

/// Previews (`quality.level`, what the viewer draws while the user moves) of a store read out
/// of core draw the store's own coarser level, read whole: a store written by volsplat holds the
/// renderer's pyramid, so the picture is the in-memory pyramid preview's, bit for bit, for a
/// level number and for `auto`; a note names the level.
#[test]
fn previews_of_a_store_out_of_core_are_its_coarser_levels() {
    let dir = tempfile::tempdir().unwrap();
    let path = store(dir.path(), [160, 150, 140]);
    let mut whole = Renderer::new();
    let mut paged = Renderer::new();
    for level in [
        volsplat::VolumeLevel::Level(1),
        volsplat::VolumeLevel::Level(2),
        volsplat::VolumeLevel::Auto,
    ] {
        for (mode, perspective) in [(Mode::Composite, false), (Mode::Mip, true)] {
            let mut req = RenderRequest::new(scene(&path, 40.0, perspective), 48, 40);
            req.mode = mode;
            req.quality.level = level;
            let want = whole.render(&req, &mut |_| true).unwrap();
            req.memory = Some(16 << 20);
            let got = paged.render(&req, &mut |_| true).unwrap();
            assert!(
                got.notes.iter().any(|n| n.starts_with("preview: level ")),
                "{level:?}: {:?}",
                got.notes
            );
            assert!(
                bits(&got) == bits(&want),
                "{level:?} {mode:?}: the store's level differs from the pyramid's"
            );
            assert_eq!(got.camera, want.camera);
        }
    }
}

/// The level's ranges are kept between opens: the second open reads them from the sidecar
/// (a note says so) and gives the same picture; a chunk written again (a newer file) makes
/// the next open read the level again, and so does a corrupt sidecar, never trusted.
#[test]
fn ranges_are_kept_between_opens_and_read_again_when_the_store_changes() {
    let dir = tempfile::tempdir().unwrap();
    let path = store(dir.path(), [100, 90, 80]);
    let mut req = RenderRequest::new(scene(&path, 30.0, false), 48, 40);
    req.memory = Some(16 << 20);
    let open = |req: &RenderRequest| Renderer::new().render(req, &mut |_| true).unwrap();
    let kept = |out: &volsplat::Output| {
        out.notes
            .iter()
            .any(|n| n.contains("kept from an earlier open"))
    };
    let first = open(&req);
    assert!(!kept(&first), "{:?}", first.notes);
    let second = open(&req);
    assert!(kept(&second), "{:?}", second.notes);
    assert!(bits(&first) == bits(&second));
    // A chunk written again: the fingerprint changes.
    let chunk = walk(&path.join("0"))
        .into_iter()
        .find(|p| !p.ends_with(".zarray") && !p.ends_with(".zattrs"))
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(20));
    std::fs::write(&chunk, std::fs::read(&chunk).unwrap()).unwrap();
    let third = open(&req);
    assert!(!kept(&third), "{:?}", third.notes);
    assert!(bits(&first) == bits(&third));
    // A corrupt sidecar is ignored.
    for f in walk(&dir.path().join("cache")) {
        std::fs::write(&f, b"{not json\n").unwrap();
    }
    let fourth = open(&req);
    assert!(!kept(&fourth), "{:?}", fourth.notes);
    assert!(bits(&first) == bits(&fourth));
}

fn walk(dir: &std::path::Path) -> Vec<std::path::PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            out.extend(walk(&p));
        } else {
            out.push(p);
        }
    }
    out.sort();
    out
}

/// Front ends' questions about a store read out of core are answered from its metadata and its
/// coarsest level: the grid is level 0's, the camera resolves against it as a frame's does, and
/// the overview (histograms) is the coarsest level.
#[test]
fn grid_camera_and_overview_of_a_store_out_of_core_read_no_full_level() {
    let dir = tempfile::tempdir().unwrap();
    let path = store(dir.path(), [100, 90, 80]);
    let mut req = RenderRequest::new(scene(&path, 30.0, true), 48, 40);
    req.memory = Some(16 << 20);
    let mut r = Renderer::new();
    let (grid, kind) = r.volume_grid(&req).unwrap();
    assert_eq!(grid.dims, [100, 90, 80]);
    assert_eq!(kind, volsplat::core::ScalarType::U16);
    let overview = r.overview(&req).unwrap();
    let store = volsplat::io::ZarrStore::open(&path, &Default::default()).unwrap();
    let coarsest = store.levels().last().unwrap().dims.map(|d| d as usize);
    assert_eq!(overview.grid().dims, coarsest);
    assert!(coarsest[0] < 100);
    let camera = r.camera(&req).unwrap();
    let frame = r.render(&req, &mut |_| true).unwrap();
    assert_eq!(camera, frame.camera);
}
