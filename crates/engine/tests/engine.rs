//! The engine facade: scene files round-trip bit for bit, the renderer keeps what a new camera
//! does not change, progress can cancel, and bad scene files say what is wrong.

use std::sync::Arc;
use volsplat::core::{Orbit, ProjectionKind};
use volsplat::{
    CameraSpec, EngineError, Mode, PhantomKind, RenderRequest, Renderer, RendererChoice, Scene,
    TransferSpec, UsedRenderer, VolumeSource,
};

fn blobs(grid: usize) -> Scene {
    Scene {
        volume: VolumeSource::Phantom {
            phantom: PhantomKind::Blobs,
            grid: Some(vec![grid]),
        },
        ..Scene::default()
    }
}

fn orbit(azimuth: f64, elevation: f64, perspective: bool) -> CameraSpec {
    CameraSpec::Orbit(Orbit {
        azimuth: Some(azimuth),
        elevation: Some(elevation),
        projection: perspective.then_some(ProjectionKind::Perspective),
        ..Orbit::default()
    })
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

/// `save` then `load` renders the same bytes, for orthographic, perspective, MIP and X-ray
/// requests; the saved file holds the camera and transfer function resolved to objects.
#[test]
fn a_saved_request_renders_again_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap();
    for (n, (mode, perspective)) in [
        (Mode::Composite, false),
        (Mode::Composite, true),
        (Mode::Mip, false),
        (Mode::Xray, false),
    ]
    .into_iter()
    .enumerate()
    {
        let mut scene = blobs(24);
        scene.camera = orbit(35.0 + 10.0 * n as f64, 20.0, perspective);
        let mut req = RenderRequest::new(scene, 40, 30);
        req.mode = mode;
        let mut r = Renderer::new();
        let a = r.render(&req, &mut |_| true).unwrap();
        // Resolve camera and transfer function as `render --save-scene` does.
        let mut saved = req.clone();
        saved.scene.camera = CameraSpec::Explicit {
            camera: a.camera.clone(),
            orbit: Orbit::default(),
        };
        saved.scene.transfer_function = TransferSpec::Function(a.transfer_function.clone());
        let path = dir.path().join(format!("scene{n}.json"));
        saved.save(&path).unwrap();
        let (loaded, warnings) = RenderRequest::load(&path).unwrap();
        assert!(warnings.is_empty(), "{warnings:?}");
        assert_eq!(loaded, saved, "{mode:?} perspective {perspective}");
        let b = Renderer::new().render(&loaded, &mut |_| true).unwrap();
        assert_eq!(bits(&a), bits(&b), "{mode:?} perspective {perspective}");
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(text.contains("\"parallel_projection\"") && text.contains("\"scalar_opacity\""));
    }
}

/// A second frame that changes only the camera reuses the volume, the tables and the splat
/// list; changing the transfer function rebuilds the tables.
#[test]
fn a_second_frame_with_a_new_camera_reuses_volume_tables_and_list() {
    for renderer in [RendererChoice::Auto, RendererChoice::SplatList] {
        let mut req = RenderRequest::new(blobs(32), 48, 48);
        req.renderer = renderer;
        let mut r = Renderer::new();
        let first = r.render(&req, &mut |_| true).unwrap();
        assert!(first.stats.load_ms > 0.0 && first.stats.prepare_ms > 0.0);
        req.scene.camera = orbit(40.0, 10.0, false);
        let second = r.render(&req, &mut |_| true).unwrap();
        assert_eq!(second.stats.load_ms, 0.0, "{renderer:?}");
        assert_eq!(second.stats.prepare_ms, 0.0, "{renderer:?}");
        assert_ne!(bits(&first), bits(&second));
        // The cached second frame equals a fresh render of the same request.
        let fresh = Renderer::new().render(&req, &mut |_| true).unwrap();
        assert_eq!(bits(&second), bits(&fresh), "{renderer:?}");
        req.scene.transfer_function = TransferSpec::Preset("ct-bone".parse().unwrap());
        let third = r.render(&req, &mut |_| true).unwrap();
        assert_eq!(third.stats.load_ms, 0.0);
        assert!(third.stats.prepare_ms > 0.0);
    }
}

#[test]
fn perspective_uses_the_splat_list_and_the_dense_renderer_refuses_it() {
    let mut scene = blobs(24);
    scene.camera = orbit(10.0, 10.0, true);
    let mut req = RenderRequest::new(scene, 32, 32);
    // `auto` draws the (shaded) blobs with slabs; with the sheets asked for, the splat list.
    let out = Renderer::new().render(&req, &mut |_| true).unwrap();
    assert_eq!(out.stats.renderer, Some(UsedRenderer::Slab));
    req.quality.visibility = volsplat::VisibilityChoice::Sheet;
    let out = Renderer::new().render(&req, &mut |_| true).unwrap();
    assert_eq!(out.stats.renderer, Some(UsedRenderer::SplatList));
    assert_eq!(
        out.stats.projection,
        Some(volsplat::core::ProjectionKind::Perspective)
    );
    req.renderer = RendererChoice::Sheets;
    let e = Renderer::new().render(&req, &mut |_| true).unwrap_err();
    assert!(
        matches!(e, EngineError::Request { ref field, .. } if field == "renderer"),
        "{e}"
    );
}

/// Every sheet renderer and display reports progress during the render (not only between
/// stages), and a callback that says stop half way cancels it (the slab renderer's bands:
/// `image_visibility_uses_the_slab_renderer_and_keeps_its_bricks`).
#[test]
fn progress_reports_and_cancels_for_every_renderer() {
    use volsplat::VisibilityChoice::{Auto, Sheet};
    let cases = [
        ("dense", RendererChoice::Auto, false, Sheet),
        ("splat list, perspective", RendererChoice::Auto, true, Sheet),
        (
            "splat list, orthographic",
            RendererChoice::SplatList,
            false,
            Auto,
        ),
        ("sabella", RendererChoice::Sabella, false, Auto),
        ("nil", RendererChoice::Nil, false, Auto),
    ];
    for (name, renderer, perspective, visibility) in cases {
        let mut req = RenderRequest::new(blobs(24), 32, 32);
        req.renderer = renderer;
        req.quality.visibility = visibility;
        req.scene.camera = orbit(20.0, 10.0, perspective);
        req.display.samples_per_ray = 32;
        req.display.supersample = 1;
        let mut seen = Vec::new();
        let full = Renderer::new()
            .render(&req, &mut |p| {
                seen.push(p.fraction);
                true
            })
            .unwrap();
        let during: Vec<f64> = seen
            .iter()
            .copied()
            .filter(|&f| f > 0.2 && f < 1.0)
            .collect();
        assert!(during.len() >= 2, "{name}: {seen:?}");
        assert!(seen.windows(2).all(|w| w[1] >= w[0]), "{name}: {seen:?}");
        assert_eq!(seen.last(), Some(&1.0), "{name}");
        let e = Renderer::new()
            .render(&req, &mut |p| p.fraction < 0.5)
            .unwrap_err();
        assert!(matches!(e, EngineError::Cancelled), "{name}: {e}");
        // A callback that never stops changes no bit.
        let again = Renderer::new().render(&req, &mut |_| true).unwrap();
        assert_eq!(bits(&full), bits(&again), "{name}");
    }
}

#[test]
fn the_thread_count_does_not_change_the_bits() {
    let mut req = RenderRequest::new(blobs(32), 40, 36);
    req.scene.camera = orbit(25.0, 30.0, false);
    req.threads = Some(1);
    let a = Renderer::new().render(&req, &mut |_| true).unwrap();
    req.threads = Some(3);
    let b = Renderer::new().render(&req, &mut |_| true).unwrap();
    assert_eq!(bits(&a), bits(&b));
}

#[test]
fn a_volume_in_memory_renders_but_cannot_be_saved() {
    let vol = volsplat::make_phantom(PhantomKind::Blobs, Some(&[20]), "grid").unwrap();
    let scene = Scene {
        volume: VolumeSource::Memory(Arc::new(vol)),
        ..Scene::default()
    };
    let req = RenderRequest::new(scene, 24, 24);
    let out = Renderer::new().render(&req, &mut |_| true).unwrap();
    assert!(out.image.pixels().iter().any(|p| p[3] > 0.1));
    let dir = tempfile::tempdir().unwrap();
    let e = req.save(dir.path().join("s.json")).unwrap_err().to_string();
    assert!(e.contains("in memory"), "{e}");
}

#[test]
fn scene_files_warn_on_unknown_fields_and_name_missing_ones() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("s.json");
    std::fs::write(
        &p,
        r#"{"scene": {"volume": {"phantom": {"phantom": "blobs", "grid": [16]}},
                      "camera": {"orbit": {"azimuth": 10, "azimth": 3}}, "colour": 1},
            "width": 16, "height": 12, "extra": true}"#,
    )
    .unwrap();
    let (req, warnings) = RenderRequest::load(&p).unwrap();
    assert_eq!((req.width, req.height), (16, 12));
    let all = warnings.join("\n");
    for field in ["extra", "scene.colour", "scene.camera.azimth"] {
        assert!(all.contains(&format!("`{field}`")), "{field}: {all}");
    }
    std::fs::write(
        &p,
        r#"{"scene": {"volume": {"phantom": {"phantom": "blobs"}}}, "height": 12}"#,
    )
    .unwrap();
    let e = RenderRequest::load(&p).unwrap_err().to_string();
    assert!(
        e.contains("missing field `width`") && e.contains("s.json"),
        "{e}"
    );
    std::fs::write(&p, r#"{"scene": {}, "width": 1, "height": 1}"#).unwrap();
    let e = RenderRequest::load(&p).unwrap_err().to_string();
    assert!(e.contains("missing field `volume`"), "{e}");
    // A wrong value names the field it is in.
    for (field, value) in [
        ("shade_at", r#""corners""#),
        ("visibility", r#""bogus""#),
        ("slab", r#""thick""#),
        ("preintegrate", r#""yes""#),
    ] {
        std::fs::write(
            &p,
            format!(
                r#"{{"scene": {{"volume": {{"phantom": {{"phantom": "blobs"}}}}}},
                    "width": 1, "height": 1, "quality": {{"{field}": {value}}}}}"#
            ),
        )
        .unwrap();
        let e = RenderRequest::load(&p).unwrap_err().to_string();
        assert!(
            e.contains(&format!("quality.{field}:")) && e.contains("s.json"),
            "{e}"
        );
    }
    std::fs::write(
        &p,
        r#"{"scene": {"volume": {"phantom": {"phantom": "cube"}}}, "width": 1, "height": 1}"#,
    )
    .unwrap();
    let e = RenderRequest::load(&p).unwrap_err().to_string();
    assert!(e.contains("cube"), "{e}");
}

#[test]
fn bad_requests_name_the_field() {
    let mut req = RenderRequest::new(blobs(16), 0, 10);
    let e = Renderer::new()
        .render(&req, &mut |_| true)
        .unwrap_err()
        .to_string();
    assert!(e.contains("width"), "{e}");
    req.width = 10;
    req.quality.subsample = 0;
    let e = Renderer::new()
        .render(&req, &mut |_| true)
        .unwrap_err()
        .to_string();
    assert!(e.contains("quality.subsample"), "{e}");
    req.quality.subsample = 1;
    req.renderer = RendererChoice::Sabella;
    req.mode = Mode::Xray;
    let e = Renderer::new()
        .render(&req, &mut |_| true)
        .unwrap_err()
        .to_string();
    assert!(e.contains("mode"), "{e}");
}

/// Reader limits given to the renderer reach the file reader: a 24³ volume is refused under a
/// 10 000-voxel limit with an error naming the file, and read under the default limits.
#[test]
fn the_renderers_reader_limits_reach_the_reader() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("blobs.nrrd");
    let vol = volsplat::make_phantom(PhantomKind::Blobs, Some(&[24]), "grid").unwrap();
    volsplat::io::write_nrrd(&path, &vol, false).unwrap();
    let scene = Scene {
        volume: VolumeSource::File {
            path: path.clone(),
            raw: None,
            frame: 0,
            array: None,
            series: None,
            level: volsplat::StoreLevel::Index(0),
            channel: 0,
            timepoint: 0,
        },
        ..Scene::default()
    };
    let req = RenderRequest::new(scene, 16, 16);
    let limits = volsplat::io::Limits::default().with_max_voxels(10_000);
    let mut small = Renderer::with_limits(limits);
    let e = small.render(&req, &mut |_| true).unwrap_err();
    let msg = e.to_string();
    assert!(msg.contains("blobs.nrrd") && msg.contains("10000"), "{msg}");
    assert!(Renderer::new().render(&req, &mut |_| true).is_ok());
}

/// Cropping and clipping: a crop box in voxels equals the same box given as planes in world
/// coordinates, survives a scene file, and the Chapter 6 displays refuse it rather than ignore it.
#[test]
fn crop_boxes_round_trip_and_match_their_planes() {
    use volsplat::{Clipping, CropBox, CropUnits, PlaneSpec};
    let mut req = RenderRequest::new(blobs(24), 32, 32);
    req.mode = Mode::Xray;
    req.scene.camera = orbit(20.0, 10.0, false);
    let full = Renderer::new().render(&req, &mut |_| true).unwrap();
    req.scene.clipping = Clipping {
        crop: Some(CropBox {
            min: [0.0, 0.0, 0.0],
            max: [11.0, 23.0, 23.0],
            units: CropUnits::Voxels,
        }),
        planes: Vec::new(),
    };
    let mut renderer = Renderer::new();
    let cropped = renderer.render(&req, &mut |_| true).unwrap();
    let sum = |o: &volsplat::Output| -> f64 {
        o.values
            .as_ref()
            .unwrap()
            .values()
            .iter()
            .map(|&v| v as f64)
            .sum()
    };
    // The blobs are symmetric enough that about half the mass remains.
    let ratio = sum(&cropped) / sum(&full);
    assert!(ratio > 0.2 && ratio < 0.8, "{ratio}");
    // The same box as six world planes, half a voxel outside the kept voxels (the phantom's
    // grid is axis-aligned).
    let vol = renderer.volume(&req.scene.volume).unwrap();
    let g = vol.grid();
    let at = |k: usize, l: f64| g.origin[k] + l * g.spacing[k];
    let mut six = Vec::new();
    for (k, hi) in [(0, 11.5), (1, 23.5), (2, 23.5)] {
        let mut n = [0.0; 3];
        n[k] = 1.0;
        six.push(PlaneSpec {
            normal: n,
            offset: -at(k, -0.5),
        });
        n[k] = -1.0;
        six.push(PlaneSpec {
            normal: n,
            offset: at(k, hi),
        });
    }
    let mut planes = req.clone();
    planes.scene.clipping = Clipping {
        crop: None,
        planes: six,
    };
    let by_plane = Renderer::new().render(&planes, &mut |_| true).unwrap();
    let (a, b) = (sum(&cropped), sum(&by_plane));
    assert!((a - b).abs() < 1e-5 * a, "{a} vs {b}");
    // Round trip through a scene file.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("s.json");
    req.save(&path).unwrap();
    let (back, warnings) = RenderRequest::load(&path).unwrap();
    assert!(warnings.is_empty(), "{warnings:?}");
    assert_eq!(back.scene.clipping, req.scene.clipping);
    // Chapter 6 displays do not cut: an error naming the field.
    req.renderer = RendererChoice::Sabella;
    req.mode = Mode::Composite;
    let e = Renderer::new().render(&req, &mut |_| true).unwrap_err();
    assert!(e.to_string().contains("scene.clipping"), "{e}");
}

/// `--renderer nil` never fails for memory: a map over the budget is built from a coarser
/// volume, said in the notes, and still draws the volume.
#[test]
fn a_nil_map_over_budget_is_built_coarser_and_says_so() {
    let mut req = RenderRequest::new(blobs(40), 24, 20);
    req.renderer = RendererChoice::Nil;
    let full = Renderer::new().render(&req, &mut |_| true).unwrap();
    assert!(
        !full.notes.iter().any(|n| n.contains("coarser")),
        "{:?}",
        full.notes
    );
    req.display.max_map_values = 500_000;
    let out = Renderer::new().render(&req, &mut |_| true).unwrap();
    let note = out.notes.iter().find(|n| n.contains("coarser"));
    assert!(note.is_some_and(|n| n.contains("500")), "{:?}", out.notes);
    let lit = |o: &volsplat::Output| o.image.pixels().iter().filter(|p| p[3] > 0.05).count();
    assert!(
        lit(&out) > lit(&full) / 2,
        "{} vs {}",
        lit(&out),
        lit(&full)
    );
}

/// `quality.visibility = image` draws both projections with the image-aligned slab renderer,
/// keeps the volume's bricks across frames (a new camera rebuilds nothing), renders X-ray with
/// the exact sheet renderer, reports progress and cancels, and bad slab thicknesses name the
/// field.
#[test]
fn image_visibility_uses_the_slab_renderer_and_keeps_its_bricks() {
    use volsplat::VisibilityChoice;
    for perspective in [false, true] {
        let mut scene = blobs(32);
        scene.camera = orbit(30.0, 15.0, perspective);
        let mut req = RenderRequest::new(scene, 48, 40);
        req.quality.visibility = VisibilityChoice::Image;
        let mut r = Renderer::new();
        let first = r.render(&req, &mut |_| true).unwrap();
        assert_eq!(first.stats.renderer, Some(UsedRenderer::Slab));
        assert!(first.stats.prepare_ms > 0.0);
        assert!(first.image.pixels().iter().any(|p| p[3] > 0.1));
        req.scene.camera = orbit(75.0, 5.0, perspective);
        let second = r.render(&req, &mut |_| true).unwrap();
        assert_eq!(second.stats.prepare_ms, 0.0, "perspective={perspective}");
        let fresh = Renderer::new().render(&req, &mut |_| true).unwrap();
        assert_eq!(bits(&second), bits(&fresh));
        let mut calls = 0;
        let e = Renderer::new()
            .render(&req, &mut |p| {
                if p.stage == volsplat::Stage::Render {
                    calls += 1;
                }
                calls < 2
            })
            .unwrap_err();
        assert!(matches!(e, EngineError::Cancelled), "{e}");
    }
    let mut req = RenderRequest::new(blobs(24), 32, 32);
    req.quality.visibility = VisibilityChoice::Image;
    req.mode = Mode::Xray;
    let out = Renderer::new().render(&req, &mut |_| true).unwrap();
    assert_eq!(out.stats.renderer, Some(UsedRenderer::Sheets));
    req.mode = Mode::Composite;
    req.quality.slab = Some(0.0);
    let e = Renderer::new().render(&req, &mut |_| true).unwrap_err();
    assert!(
        matches!(e, EngineError::Request { ref field, .. } if field == "quality.slab"),
        "{e}"
    );
}

/// `auto` keeps the sheet renderers when a sheet-only option is set, and draws unshaded
/// composite with slabs otherwise.
#[test]
fn auto_visibility_keeps_sheets_for_sheet_only_options() {
    use volsplat::{AntialiasChoice, KernelChoice, OrderChoice};
    let mut req = RenderRequest::new(blobs(24), 32, 32);
    req.scene.transfer_function = TransferSpec::Preset("ramp".parse().unwrap());
    let used = |req: &RenderRequest| {
        Renderer::new()
            .render(req, &mut |_| true)
            .unwrap()
            .stats
            .renderer
    };
    assert_eq!(used(&req), Some(UsedRenderer::Slab));
    let mut r = req.clone();
    r.quality.kernel = KernelChoice::Nearest;
    assert_eq!(used(&r), Some(UsedRenderer::Sheets));
    let mut r = req.clone();
    r.quality.subsample = 2;
    assert_eq!(used(&r), Some(UsedRenderer::Sheets));
    let mut r = req.clone();
    r.quality.order = OrderChoice::Btf;
    assert_eq!(used(&r), Some(UsedRenderer::Sheets));
    let mut r = req.clone();
    r.quality.antialias = AntialiasChoice::Ewa;
    assert_eq!(used(&r), Some(UsedRenderer::Sheets));
    let mut r = req.clone();
    r.quality.antialias = AntialiasChoice::None;
    assert_eq!(used(&r), Some(UsedRenderer::Slab));
}

/// Without `quality.slab` the slab thickness follows the mode (decisions 0017 and 0019): one
/// voxel for composite, unshaded or shaded at the voxels, half a voxel for MIP, MinIP and
/// composite shaded at the samples; an explicit thickness wins. Read back from the renderer's
/// reported plane spacing, in units of the smallest spacing.
#[test]
fn slab_thickness_defaults_by_mode() {
    use volsplat::{ShadeAtChoice, VisibilityChoice};
    let thickness_at = |mode: Mode, shade: Option<bool>, slab: Option<f64>, at| {
        let mut req = RenderRequest::new(blobs(24), 32, 32);
        req.quality.visibility = VisibilityChoice::Image;
        req.quality.shade_at = at;
        req.quality.slab = slab;
        req.mode = mode;
        let mut r = Renderer::new();
        if let Some(shade) = shade {
            let mut tf = r.transfer_function(&req).unwrap();
            tf.shade = shade;
            req.scene.transfer_function = TransferSpec::Function(tf);
        }
        let out = r.render(&req, &mut |_| true).unwrap();
        assert_eq!(out.stats.renderer, Some(UsedRenderer::Slab));
        let min = r
            .volume(&req.scene.volume)
            .unwrap()
            .grid()
            .spacing
            .iter()
            .fold(f64::INFINITY, |m, &s| m.min(s));
        out.stats.sheet_spacing / min
    };
    let thickness = |mode: Mode, shade: Option<bool>, slab: Option<f64>| {
        thickness_at(mode, shade, slab, ShadeAtChoice::Voxels)
    };
    let close = |a: f64, b: f64| (a - b).abs() < 1e-9;
    assert!(close(thickness(Mode::Composite, Some(false), None), 1.0));
    assert!(close(thickness(Mode::Composite, Some(true), None), 1.0));
    // The stats say where the lights were evaluated; tables that depend on more than the
    // density (a gradient-magnitude opacity ramp) shade at the samples whatever was asked.
    let shade_at = |at, surface| {
        let mut req = RenderRequest::new(blobs(24), 32, 32);
        req.quality.visibility = VisibilityChoice::Image;
        req.quality.shade_at = at;
        req.scene.surface_enhance = surface;
        Renderer::new()
            .render(&req, &mut |_| true)
            .unwrap()
            .stats
            .shade_at
    };
    assert_eq!(
        shade_at(ShadeAtChoice::Voxels, None),
        Some(ShadeAtChoice::Voxels)
    );
    assert_eq!(
        shade_at(ShadeAtChoice::Samples, None),
        Some(ShadeAtChoice::Samples)
    );
    assert_eq!(
        shade_at(ShadeAtChoice::Voxels, Some([0.01, 0.2])),
        Some(ShadeAtChoice::Samples)
    );
    // Lit at the samples: one voxel too, each slab lit twice (decision 0036).
    assert!(close(
        thickness_at(Mode::Composite, Some(true), None, ShadeAtChoice::Samples),
        1.0
    ));
    assert!(close(thickness(Mode::Mip, None, None), 0.5));
    assert!(close(thickness(Mode::Minip, None, None), 0.5));
    assert!(close(
        thickness(Mode::Composite, Some(false), Some(0.25)),
        0.25
    ));
    assert!(close(thickness(Mode::Mip, None, Some(2.0)), 2.0));
}

/// Pre-integration (decision 0020): `auto` classifies composite slabs by segment where the
/// transfer function's ramp is sharp and by point where it is smooth, `on` and `off` force it,
/// and the stats say which was used (absent for MIP).
#[test]
fn preintegration_by_choice_and_by_ramp() {
    use volsplat::{PreintegrateChoice, VisibilityChoice};
    let run = |choice, sharp: bool, mode: Mode| {
        let mut req = RenderRequest::new(blobs(24), 32, 32);
        req.quality.visibility = VisibilityChoice::Image;
        req.quality.preintegrate = choice;
        req.mode = mode;
        let mut r = Renderer::new();
        let mut tf = r.transfer_function(&req).unwrap();
        let (lo, hi) = (
            tf.scalar_opacity[0][0],
            tf.scalar_opacity.last().unwrap()[0],
        );
        let mid = 0.5 * (lo + hi);
        tf.scalar_opacity = if sharp {
            vec![
                [lo, 0.0],
                [mid - 0.005 * (hi - lo), 0.0],
                [mid + 0.005 * (hi - lo), 0.6],
                [hi, 0.7],
            ]
        } else {
            vec![[lo, 0.0], [hi, 0.05]]
        };
        req.scene.transfer_function = TransferSpec::Function(tf);
        let out = r.render(&req, &mut |_| true).unwrap();
        (out.stats.preintegrated, bits(&out))
    };
    let (auto_sharp, a) = run(PreintegrateChoice::Auto, true, Mode::Composite);
    let (on_sharp, b) = run(PreintegrateChoice::On, true, Mode::Composite);
    let (off_sharp, c) = run(PreintegrateChoice::Off, true, Mode::Composite);
    assert_eq!(
        (auto_sharp, on_sharp, off_sharp),
        (Some(true), Some(true), Some(false))
    );
    assert_eq!(a, b);
    assert_ne!(a, c);
    assert_eq!(
        run(PreintegrateChoice::Auto, false, Mode::Composite).0,
        Some(false)
    );
    assert_eq!(
        run(PreintegrateChoice::On, false, Mode::Composite).0,
        Some(true)
    );
    assert_eq!(run(PreintegrateChoice::On, true, Mode::Mip).0, None);
}

/// `quality.level` (issue 29 item 7, decision 0031) in request files: `"full"` (the default when
/// absent), `"auto"` or a level number; anything else names the field.
#[test]
fn the_volume_level_round_trips_in_request_files() {
    use volsplat::VolumeLevel;
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("s.json");
    let base = r#"{"scene": {"volume": {"phantom": {"phantom": "blobs", "grid": [16]}}},
                   "width": 8, "height": 8"#;
    std::fs::write(&p, format!("{base}}}")).unwrap();
    assert_eq!(
        RenderRequest::load(&p).unwrap().0.quality.level,
        VolumeLevel::Full
    );
    for (text, level) in [
        (r#""full""#, VolumeLevel::Full),
        (r#""auto""#, VolumeLevel::Auto),
        ("2", VolumeLevel::Level(2)),
        ("0", VolumeLevel::Level(0)),
    ] {
        std::fs::write(&p, format!(r#"{base}, "quality": {{"level": {text}}}}}"#)).unwrap();
        let (req, warnings) = RenderRequest::load(&p).unwrap();
        assert_eq!(req.quality.level, level, "{text}");
        assert!(warnings.is_empty(), "{warnings:?}");
        let back = dir.path().join("back.json");
        req.save(&back).unwrap();
        assert_eq!(RenderRequest::load(&back).unwrap().0.quality.level, level);
    }
    for bad in [r#""coarse""#, "-1", "256", "1.5", "true"] {
        std::fs::write(&p, format!(r#"{base}, "quality": {{"level": {bad}}}}}"#)).unwrap();
        let e = RenderRequest::load(&p).unwrap_err().to_string();
        assert!(
            e.contains("quality.level") && e.contains("auto"),
            "{bad}: {e}"
        );
    }
    assert_eq!("auto".parse::<VolumeLevel>(), Ok(VolumeLevel::Auto));
    assert_eq!("3".parse::<VolumeLevel>(), Ok(VolumeLevel::Level(3)));
    assert!("fine".parse::<VolumeLevel>().is_err());
}

/// A preview (`quality.level = auto`) of a small image draws a coarse level, takes a fraction
/// of the full frame's samples, says which level it drew, and looks like the full frame; the
/// level is built once per volume; an explicit level past the coarsest draws the coarsest with
/// a warning; the full level is the default and its stats say nothing of levels; renderers other
/// than the slabs draw the full volume and say so.
#[test]
fn auto_level_previews_draw_a_coarse_level_once() {
    use volsplat::VolumeLevel;
    use volsplat::core::Orbit;
    let mut scene = blobs(64);
    scene.camera = orbit(30.0, 20.0, false);
    let mut req = RenderRequest::new(scene, 32, 32);
    let mut r = Renderer::new();
    let full = r.render(&req, &mut |_| true).unwrap();
    assert_eq!(full.stats.renderer, Some(UsedRenderer::Slab));
    assert_eq!(full.stats.level, None);
    let json = serde_json::to_string(&full.stats).unwrap();
    assert!(!json.contains("level"), "{json}");
    req.quality.level = VolumeLevel::Auto;
    let preview = r.render(&req, &mut |_| true).unwrap();
    let level = preview.stats.level.expect("the level drawn");
    assert!(level >= 1, "level {level}");
    assert!(
        preview.stats.prepare_ms > 0.0,
        "the level is built in this frame"
    );
    assert!(
        preview.stats.voxels * 8 < full.stats.voxels,
        "{} samples against {}",
        preview.stats.voxels,
        full.stats.voxels
    );
    let (sp, px) = (
        preview.stats.level_spacing.unwrap(),
        preview.stats.focal_pixel.unwrap(),
    );
    assert!(sp <= px * std::f64::consts::SQRT_2 && sp * 2.0 > px * std::f64::consts::SQRT_2);
    let psnr = volsplat_testkit_psnr(&preview.image, &full.image);
    assert!(psnr > 30.0, "{psnr:.1} dB");
    // Another camera: the level is kept, and the frame is what a fresh renderer draws.
    req.scene.camera = CameraSpec::Orbit(Orbit {
        azimuth: Some(50.0),
        ..Orbit::default()
    });
    let second = r.render(&req, &mut |_| true).unwrap();
    assert_eq!(second.stats.level, Some(level));
    assert_eq!(second.stats.prepare_ms, 0.0);
    let fresh = Renderer::new().render(&req, &mut |_| true).unwrap();
    assert_eq!(bits(&second), bits(&fresh));
    // Past the coarsest level.
    req.quality.level = VolumeLevel::Level(40);
    let out = r.render(&req, &mut |_| true).unwrap();
    let coarsest = out.stats.level.unwrap();
    assert!(coarsest > level);
    assert!(
        out.warnings.iter().any(|w| w.contains("quality.level 40")),
        "{:?}",
        out.warnings
    );
    // X-ray is drawn by the sheets, from the full volume: a level number says so ...
    req.mode = Mode::Xray;
    let out = r.render(&req, &mut |_| true).unwrap();
    assert_eq!(out.stats.level, None);
    assert!(
        out.warnings.iter().any(|w| w.contains("full volume")),
        "{:?}",
        out.warnings
    );
    // ... while `auto` (what the viewer's previews ask for, whatever the renderer) quietly
    // means the full volume.
    req.quality.level = VolumeLevel::Auto;
    let out = r.render(&req, &mut |_| true).unwrap();
    assert_eq!(out.stats.level, None);
    assert!(
        !out.warnings.iter().any(|w| w.contains("level")),
        "{:?}",
        out.warnings
    );
}

/// PSNR over premultiplied RGBA, peak 1.
fn volsplat_testkit_psnr(a: &volsplat::core::Image, b: &volsplat::core::Image) -> f64 {
    let (a, b) = (a.pixels().as_flattened(), b.pixels().as_flattened());
    let mse = a
        .iter()
        .zip(b)
        .map(|(x, y)| ((x - y) as f64).powi(2))
        .sum::<f64>()
        / a.len() as f64;
    10.0 * (1.0 / mse).log10()
}

/// The sheets and the splat list draw sheet-buffer visibility where `visibility: image`
/// reaches them (X-ray; the splat list asked for by name): the same bits as `sheet`, and the
/// slabs are never reached through the sheets. `renderer: sheets` with `image` outside X-ray is
/// drawn by the slabs, as `auto` draws it, and says so.
#[test]
fn image_visibility_reaches_the_sheets_only_as_sheet_buffers() {
    use volsplat::VisibilityChoice;
    let render = |renderer, mode, visibility| {
        let mut req = RenderRequest::new(blobs(24), 32, 32);
        req.scene.camera = orbit(25.0, 10.0, false);
        req.renderer = renderer;
        req.mode = mode;
        req.quality.visibility = visibility;
        Renderer::new().render(&req, &mut |_| true).unwrap()
    };
    for (renderer, mode, used) in [
        (RendererChoice::Sheets, Mode::Xray, UsedRenderer::Sheets),
        (RendererChoice::Auto, Mode::Xray, UsedRenderer::Sheets),
        (
            RendererChoice::SplatList,
            Mode::Composite,
            UsedRenderer::SplatList,
        ),
        (
            RendererChoice::SplatList,
            Mode::Xray,
            UsedRenderer::SplatList,
        ),
    ] {
        let image = render(renderer, mode, VisibilityChoice::Image);
        let sheet = render(renderer, mode, VisibilityChoice::Sheet);
        assert_eq!(image.stats.renderer, Some(used), "{renderer:?} {mode:?}");
        assert_eq!(bits(&image), bits(&sheet), "{renderer:?} {mode:?}");
    }
    let sheets = render(
        RendererChoice::Sheets,
        Mode::Composite,
        VisibilityChoice::Image,
    );
    let auto = render(
        RendererChoice::Auto,
        Mode::Composite,
        VisibilityChoice::Image,
    );
    assert_eq!(sheets.stats.renderer, Some(UsedRenderer::Slab));
    assert_eq!(bits(&sheets), bits(&auto));
}

/// `renderer: "sheets"` is also read under its earlier names, and written as `sheets`.
#[test]
fn the_sheets_keep_their_earlier_names() {
    for name in ["sheets", "splat", "dense"] {
        let r: RendererChoice = serde_json::from_str(&format!("\"{name}\"")).unwrap();
        assert_eq!(r, RendererChoice::Sheets, "{name}");
    }
    assert_eq!(
        serde_json::to_string(&RendererChoice::Sheets).unwrap(),
        "\"sheets\""
    );
    let mut req = RenderRequest::new(blobs(16), 16, 16);
    req.quality.visibility = volsplat::VisibilityChoice::Sheet;
    let out = Renderer::new().render(&req, &mut |_| true).unwrap();
    let json = serde_json::to_value(&out.stats).unwrap();
    assert_eq!(json["renderer"], "sheets");
    assert_eq!(json["projection"], "orthographic");
    assert!(["i", "j", "k"].contains(&json["sheet_axis"].as_str().unwrap()));
    assert_eq!(json["antialias"], "area");
}
