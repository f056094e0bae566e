//! The session's policy with a manual clock, its camera moves against VTK's, and its final
//! frame against `render` of the saved scene.

use super::*;
use crate::request::{AntialiasChoice, Mode, VolumeLevel};
use crate::scene::{CropBox, CropUnits, PhantomKind, Scene, TransferSpec, VolumeSource};
use volsplat_core::glam::DVec3;
use volsplat_core::{OrthoProjection, PerspectiveProjection, Preset};

fn head_request(size: usize) -> RenderRequest {
    let scene = Scene {
        volume: VolumeSource::Phantom {
            phantom: PhantomKind::Head,
            grid: Some(vec![40, 48, 44]),
        },
        ..Scene::default()
    };
    RenderRequest::new(scene, size, size)
}

/// A session on a small CT-like head, with a manual clock and the renderer that loaded it.
fn session(size: usize) -> (Session, Renderer, Arc<ManualClock>) {
    let clock = Arc::new(ManualClock::new());
    let mut renderer = Renderer::new();
    let s = Session::start(
        head_request(size),
        &mut renderer,
        SessionSettings::default(),
        clock.clone(),
    )
    .unwrap();
    (s, renderer, clock)
}

/// A session without a volume: a unit box, for the policy alone.
fn policy_session() -> (Session, Arc<ManualClock>) {
    policy_session_with(SessionSettings::default())
}

/// [`policy_session`] with other settings.
fn policy_session_with(settings: SessionSettings) -> (Session, Arc<ManualClock>) {
    let clock = Arc::new(ManualClock::new());
    let grid = Grid::new(
        [10, 10, 10],
        [1.0; 3],
        [0.0; 3],
        volsplat_core::glam::DMat3::IDENTITY,
    )
    .unwrap();
    let camera = Camera::reset_to_bounds(DVec3::ZERO, DVec3::splat(9.0), true);
    let s = Session::new(head_request(400), camera, grid, settings, clock.clone()).unwrap();
    (s, clock)
}

fn preview_plan(job: &Job) -> PreviewPlan {
    match job.kind {
        JobKind::Preview(p) => p,
        JobKind::Final => panic!("expected a preview, got the final job"),
    }
}

fn rendered(ms: f64) -> JobOutcome {
    JobOutcome::Rendered { ms }
}

#[test]
fn refused_events_change_nothing() {
    let (mut s, _) = policy_session();
    let before = (s.request().clone(), s.generation());
    let mut bad_tf = Preset::CtBone.transfer_function((0.0, 1000.0));
    bad_tf.scalar_opacity[0][1] = 2.0;
    let refused = [
        Event::Orbit {
            dx: f64::NAN,
            dy: 0.0,
        },
        Event::Pan { dx: 0.0, dy: 1e9 },
        Event::Zoom { factor: 0.0 },
        Event::Zoom {
            factor: f64::INFINITY,
        },
        Event::Roll { degrees: f64::NAN },
        Event::Resize {
            width: 0,
            height: 10,
        },
        Event::Resize {
            width: 10,
            height: 100_000,
        },
        Event::SetWindow {
            window: Some([0.0, 1.0]),
        }, // composite takes no window
        Event::SetTransferFunction {
            transfer_function: TransferSpec::Function(bad_tf),
        },
        Event::SetCrop {
            crop: Some(CropBox {
                min: [5.0, 0.0, 0.0],
                max: [1.0, 9.0, 9.0],
                units: CropUnits::Voxels,
            }),
        },
        Event::SetClip {
            planes: vec![crate::PlaneSpec {
                normal: [0.0; 3],
                offset: 1.0,
            }],
        },
        Event::SetQuality {
            quality: crate::Quality {
                subsample: 0,
                ..crate::Quality::default()
            },
        },
        Event::SetCamera {
            camera: Camera {
                position: [0.0; 3],
                focal_point: [0.0; 3],
                ..Camera::default()
            },
        },
    ];
    for e in refused {
        assert!(s.apply(e.clone()).is_err(), "{e:?} was accepted");
        assert_eq!(
            (s.request().clone(), s.generation()),
            before,
            "{e:?} changed the session"
        );
    }
    // MIP takes a window, but not a backwards one.
    s.apply(Event::SetMode { mode: Mode::Mip }).unwrap();
    assert!(
        s.apply(Event::SetWindow {
            window: Some([3.0, 1.0])
        })
        .is_err()
    );
    s.apply(Event::SetWindow {
        window: Some([1.0, 3.0]),
    })
    .unwrap();
    assert_eq!(s.request().output.window, Some([1.0, 3.0]));
    // MinIP shares MIP's units and keeps the window; X-ray's line integrals do not.
    s.apply(Event::SetMode { mode: Mode::Minip }).unwrap();
    assert_eq!(s.request().output.window, Some([1.0, 3.0]));
    s.apply(Event::SetMode { mode: Mode::Xray }).unwrap();
    assert_eq!(s.request().output.window, None);
    s.apply(Event::SetWindow {
        window: Some([1.0, 3.0]),
    })
    .unwrap();
    // Back to composite drops the window rather than refusing the mode.
    s.apply(Event::SetMode {
        mode: Mode::Composite,
    })
    .unwrap();
    assert_eq!(s.request().output.window, None);
}

/// A drag: previews (one ray per pixel, smaller) while the pointer is held, at most one job
/// out, nothing while the preview on screen is current, the final frame at release, then
/// nothing.
#[test]
fn a_drag_gives_previews_then_the_final_frame_at_release() {
    let (mut s, clock) = policy_session();
    s.apply(Event::Interaction { active: true }).unwrap();
    s.apply(Event::Orbit { dx: 5.0, dy: 0.0 }).unwrap();
    let job = s.next_job().unwrap();
    let plan = preview_plan(&job);
    assert_eq!(plan.antialias, AntialiasChoice::None);
    assert_eq!(job.request.quality.antialias, AntialiasChoice::None);
    assert!(plan.scale < 1.0 && job.request.height < 400, "{plan:?}");
    assert_eq!(job.request.scene.camera, s.request().scene.camera);
    assert!(s.next_job().is_none(), "two jobs out at once");
    // Input while the preview renders is applied at once (coalesced into the scene).
    s.apply(Event::Orbit { dx: 5.0, dy: 0.0 }).unwrap();
    s.apply(Event::Orbit { dx: 5.0, dy: 0.0 }).unwrap();
    clock.advance(20.0);
    s.finished(&job, rendered(20.0));
    let job2 = s.next_job().unwrap();
    preview_plan(&job2);
    assert_eq!(job2.generation, s.generation());
    assert_ne!(job2.request.scene.camera, job.request.scene.camera);
    s.finished(&job2, rendered(20.0));
    assert!(
        s.next_job().is_none(),
        "held pointer, current preview: nothing to do"
    );
    assert_eq!(
        s.wake_at(),
        None,
        "no rest deadline while the pointer is held"
    );
    s.apply(Event::Interaction { active: false }).unwrap();
    let last = s.next_job().unwrap();
    assert!(last.is_final());
    assert_eq!(&last.request, s.request());
    s.finished(&last, rendered(300.0));
    assert!(s.next_job().is_none());
    assert_eq!(s.final_ms(), Some(300.0));
}

/// Wheel steps (continuous input without a held pointer) refine only after the rest delay.
#[test]
fn wheel_steps_refine_after_the_rest_delay() {
    let (mut s, clock) = policy_session();
    s.apply(Event::Zoom { factor: 1.21 }).unwrap();
    let job = s.next_job().unwrap();
    preview_plan(&job);
    s.finished(&job, rendered(10.0));
    assert!(s.next_job().is_none());
    let wake = s.wake_at().unwrap();
    assert_eq!(wake, Duration::from_millis(120));
    clock.advance(119.0);
    assert!(s.next_job().is_none());
    clock.advance(1.0);
    assert!(s.next_job().unwrap().is_final());
}

/// A button (a discrete event) shows a preview, then refines at once.
#[test]
fn a_button_previews_then_refines_at_once() {
    let (mut s, _) = policy_session();
    s.apply(Event::SetMode { mode: Mode::Mip }).unwrap();
    let job = s.next_job().unwrap();
    preview_plan(&job);
    s.finished(&job, rendered(10.0));
    assert!(s.next_job().unwrap().is_final());
}

/// Where the final frame fits the budget there are no previews, even while dragging.
#[test]
fn a_cheap_final_frame_needs_no_preview() {
    let (mut s, _) = policy_session();
    let first = s.next_job().unwrap();
    preview_plan(&first);
    s.finished(&first, rendered(5.0));
    let f = s.next_job().unwrap();
    assert!(f.is_final());
    s.finished(&f, rendered(10.0));
    s.apply(Event::Interaction { active: true }).unwrap();
    s.apply(Event::Orbit { dx: 3.0, dy: 1.0 }).unwrap();
    assert!(s.next_job().unwrap().is_final());
}

/// The budget loop: with a frame cost proportional to the preview's pixels (plus a fixed
/// part), measured preview times settle inside the dead band around the aim, from above and
/// from below, on fast and slow machines (the slowest needs thicker slabs); with pyramid
/// previews, whose cost falls as the pixel count to the power 3/2 (a coarser level also thins
/// the samples along the ray), they settle the same way.
#[test]
fn previews_settle_on_the_budget_from_measured_times() {
    let aim = SessionSettings::default().aim_ms();
    // ms for a full-size, full-thickness frame of one ray per pixel: fast and slow machines.
    for (full_ms, pyramid) in [40.0, 300.0, 3000.0]
        .into_iter()
        .flat_map(|ms| [(ms, false), (ms, true)])
    {
        let (mut s, _) = policy_session_with(SessionSettings {
            pyramid_previews: pyramid,
            ..SessionSettings::default()
        });
        let mut times = Vec::new();
        for n in 0..30 {
            s.apply(Event::Interaction { active: true }).unwrap();
            s.apply(Event::Orbit { dx: 1.0, dy: 0.0 }).unwrap();
            let job = s.next_job().unwrap();
            let plan = preview_plan(&job);
            let (w, h) = plan.size;
            let pixels = (w * h) as f64 / (400.0 * 400.0);
            let share = if pyramid {
                assert_eq!(plan.level, VolumeLevel::Auto);
                assert_eq!(job.request.quality.level, VolumeLevel::Auto);
                pixels.powf(1.5)
            } else {
                assert_eq!(plan.level, VolumeLevel::Full);
                pixels / plan.slab_factor
            };
            let ms = 2.0 + full_ms * share;
            s.finished(&job, rendered(ms));
            if n >= 20 {
                times.push(ms);
            }
        }
        let last = *times.last().unwrap();
        // The scale moves in 1/32 steps of the side: allow one step below the dead band.
        assert!(
            last > aim * 0.6 && last < aim * 1.15,
            "{full_ms} ms machine, pyramid {pyramid}: previews settled at {last:.1} ms for an aim of {aim:.1}: \
             {times:?}"
        );
        let spread = times.iter().cloned().fold(0.0, f64::max)
            - times.iter().cloned().fold(f64::INFINITY, f64::min);
        assert!(spread < 0.3 * aim, "previews keep changing size: {times:?}");
    }
}

/// A preview larger than the dead band moves the next one the right way, and no further than
/// a factor of two in cost.
#[test]
fn one_slow_or_fast_preview_moves_the_next_one_the_right_way() {
    let (mut s, _) = policy_session();
    let aim = s.aim_ms();
    // (the cost kept before, the cost of the preview rendered, the cost kept after)
    let step = |s: &mut Session, ms: f64| {
        s.apply(Event::Orbit { dx: 1.0, dy: 0.0 }).unwrap();
        let kept = s.budget.cost();
        let job = s.next_job().unwrap();
        let rendered_cost = plan_cost(&preview_plan(&job));
        s.finished(&job, rendered(ms));
        (kept, rendered_cost, s.budget.cost())
    };
    let (_, before, after) = step(&mut s, aim * 4.0);
    assert!(
        after < before && after >= before / 2.0,
        "{before} → {after}"
    );
    let (_, before, after) = step(&mut s, aim / 4.0);
    assert!(
        after > before && after <= before * 2.0,
        "{before} → {after}"
    );
    let (kept, _, after) = step(&mut s, aim * 1.05);
    assert_eq!(after, kept, "inside the dead band the cost stays");
}

/// A final frame is cancelled as soon as the scene moves on; a preview only once it is also
/// older than three budgets (50 ms at 60 frames/s).
#[test]
fn stale_finals_cancel_at_once_and_stale_previews_after_three_budgets() {
    let (mut s, clock) = policy_session();
    let preview = s.next_job().unwrap();
    let mut go = s.keep_going(&preview);
    let p = Progress {
        fraction: 0.5,
        stage: crate::Stage::Render,
    };
    assert!(go(&p));
    s.apply(Event::Orbit { dx: 1.0, dy: 0.0 }).unwrap();
    assert!(go(&p), "a young stale preview finishes");
    let settings = SessionSettings::default();
    let limit = settings.budget_ms() * settings.stale_preview_budgets;
    clock.advance(limit - 1.0);
    assert!(go(&p));
    clock.advance(2.0);
    assert!(!go(&p), "an old stale preview is cancelled");
    s.finished(&preview, JobOutcome::Cancelled);
    let next = s.next_job().unwrap();
    preview_plan(&next);
    s.finished(&next, rendered(10.0));
    clock.advance(settings.rest_delay_ms); // past the orbit's rest delay
    let fin = s.next_job().unwrap();
    assert!(fin.is_final());
    let mut go = s.keep_going(&fin);
    assert!(go(&p));
    s.apply(Event::Zoom { factor: 1.1 }).unwrap();
    assert!(!go(&p), "a stale final frame is cancelled at once");
    assert!(!s.is_current(&fin));
}

/// Releasing the pointer cancels the preview in flight: the final frame follows at once.
#[test]
fn a_release_cancels_the_preview_in_flight() {
    let (mut s, _) = policy_session();
    s.apply(Event::Interaction { active: true }).unwrap();
    s.apply(Event::Orbit { dx: 2.0, dy: 0.0 }).unwrap();
    let preview = s.next_job().unwrap();
    preview_plan(&preview);
    let mut go = s.keep_going(&preview);
    let p = Progress {
        fraction: 0.5,
        stage: crate::Stage::Render,
    };
    assert!(go(&p));
    s.apply(Event::Interaction { active: false }).unwrap();
    assert!(!go(&p), "the preview runs on after the release");
    s.finished(&preview, JobOutcome::Cancelled);
    let f = s.next_job().unwrap();
    assert!(f.is_final());
    // A release with no drag before it (a click) cancels nothing.
    let mut go = s.keep_going(&f);
    s.apply(Event::Interaction { active: false }).unwrap();
    assert!(go(&p));
}

/// A failed final frame is not retried until the scene changes.
#[test]
fn a_failed_final_frame_settles_its_generation() {
    let (mut s, _) = policy_session();
    let p = s.next_job().unwrap();
    s.finished(&p, JobOutcome::Failed);
    let f = s.next_job().unwrap();
    assert!(f.is_final(), "a failed preview still tries the final frame");
    s.finished(&f, JobOutcome::Failed);
    assert!(s.next_job().is_none());
    s.apply(Event::Roll { degrees: 5.0 }).unwrap();
    assert!(s.next_job().is_some());
}

/// A drag on a machine where every preview takes a second; the job and plan of the last one.
fn slowest_preview(s: &mut Session) -> (Job, PreviewPlan) {
    for _ in 0..12 {
        s.apply(Event::Orbit { dx: 1.0, dy: 0.0 }).unwrap();
        let job = s.next_job().unwrap();
        preview_plan(&job);
        s.finished(&job, rendered(1000.0));
    }
    s.apply(Event::Orbit { dx: 1.0, dy: 0.0 }).unwrap();
    let job = s.next_job().unwrap();
    let plan = preview_plan(&job);
    (job, plan)
}

/// Too slow for the smallest image: previews keep 1/8 of the side and, without the pyramid,
/// thicken the slabs, which the preview request carries; with it, they keep the slabs and draw
/// the level that fits the small image.
#[test]
fn the_slowest_previews_thicken_the_slabs() {
    let (mut s, _) = policy_session_with(SessionSettings {
        pyramid_previews: true,
        ..SessionSettings::default()
    });
    let (job, plan) = slowest_preview(&mut s);
    assert_eq!((plan.size, plan.slab_factor), ((50, 50), 1.0));
    assert_eq!(job.request.quality.slab, None);
    assert_eq!(job.request.quality.level, VolumeLevel::Auto);
    assert_eq!(s.request().quality.level, VolumeLevel::Full);

    let (mut s, _) = policy_session();
    let (job, plan) = slowest_preview(&mut s);
    assert_eq!(plan.slab_factor, 4.0);
    assert_eq!(plan.size, (50, 50));
    // Composite shaded at the voxels: the renderer's own slab is one voxel.
    assert_eq!(job.request.quality.slab, Some(4.0));
    assert_eq!(
        s.request().quality.slab,
        None,
        "the final frame keeps its slab"
    );
}

/// The plan of a cost share: half the side or more with the final frame's slabs, then
/// two-voxel slabs and a larger side than the share alone would give, then thicker slabs at an
/// eighth of the side.
#[test]
fn plans_trade_slabs_for_pixels_below_half_the_side() {
    let s = SessionSettings::default();
    assert!(!s.pyramid_previews);
    let plan = |cost: f64| {
        let b = policy::Budget::with_cost(cost);
        let p = b.plan(512, 512, &s);
        (p.size.1, p.slab_factor)
    };
    assert_eq!(plan(1.0), (512, 1.0));
    assert_eq!(plan(0.3), (272, 1.0)); // √0.3 = 0.548 → 17/32
    assert_eq!(plan(0.25), (256, 1.0));
    assert_eq!(plan(0.2), (320, 2.0)); // √0.4 = 0.632 → 20/32
    assert_eq!(plan(1.0 / 128.0), (64, 2.0));
    assert_eq!(plan(1.0 / 200.0), (64, 3.125));
    assert_eq!(plan(1.0 / 1000.0), (64, 4.0));
    for cost in [1.0, 0.5, 0.25, 0.2, 0.05, 0.01] {
        let b = policy::Budget::with_cost(cost);
        let p = b.plan(512, 512, &s);
        assert!(
            plan_cost(&p) <= cost + 1e-12,
            "{cost}: {p:?} costs more than asked"
        );
        // The largest step of the side that fits: one more would cost more than asked.
        let bigger = (p.scale + 1.0 / 32.0).powi(2) / p.slab_factor;
        assert!(
            p.scale == 1.0 || bigger > cost,
            "{cost}: {p:?} wastes the budget"
        );
    }
}

/// With pyramid previews, the side alone follows the cost share (the level follows the
/// side), down to an eighth of it.
#[test]
fn pyramid_plans_follow_the_side_alone() {
    let s = SessionSettings {
        pyramid_previews: true,
        ..SessionSettings::default()
    };
    let plan = |cost: f64| {
        let p = policy::Budget::with_cost(cost).plan(512, 512, &s);
        assert_eq!((p.slab_factor, p.level), (1.0, VolumeLevel::Auto));
        p.size.1
    };
    assert_eq!(plan(1.0), 512);
    assert_eq!(plan(0.3), 272); // √0.3 = 0.548 → 17/32
    assert_eq!(plan(0.2), 224); // √0.2 = 0.447 → 14/32
    assert_eq!(plan(1.0 / 128.0), 64);
    assert_eq!(plan(1.0 / 1000.0), 64);
}

/// A drag to the right turns the camera as VTK's trackball does: `Azimuth(−dx·200/width)`,
/// then `Elevation(dy·200/height)` and `OrthogonalizeViewUp`.
#[test]
fn orbit_is_vtks_trackball_rotation() {
    let (mut s, _) = policy_session();
    let mut expect = s.camera().clone();
    s.apply(Event::Orbit {
        dx: -20.0,
        dy: 10.0,
    })
    .unwrap();
    // 400-pixel view: −(−20)·200/400 = 10°, 10·200/400 = 5°.
    expect.azimuth(10.0);
    expect.elevation(5.0);
    expect.orthogonalize_view_up();
    let got = s.camera();
    for k in 0..3 {
        assert!((got.position[k] - expect.position[k]).abs() < 1e-9);
        assert!((got.view_up[k] - expect.view_up[k]).abs() < 1e-12);
    }
}

/// A pan moves the focal point's image by exactly the drag, orthographic and perspective; a
/// zoom divides the parallel scale or the distance.
#[test]
fn pan_follows_the_cursor_and_zoom_magnifies() {
    for perspective in [false, true] {
        let (mut s, _) = policy_session();
        if perspective {
            let mut c = s.camera().clone();
            c.parallel_projection = false;
            s.apply(Event::SetCamera { camera: c }).unwrap();
        }
        s.apply(Event::Orbit {
            dx: 30.0,
            dy: -12.0,
        })
        .unwrap();
        let before = s.camera().clone();
        let focal = DVec3::from(before.focal_point);
        s.apply(Event::Pan { dx: 17.0, dy: -5.0 }).unwrap();
        let after = s.camera().clone();
        let raster = if perspective {
            PerspectiveProjection::new(&after, 400, 400)
                .unwrap()
                .raster_from_world(focal)
        } else {
            OrthoProjection::new(&after, 400, 400)
                .unwrap()
                .raster_from_world(focal)
        };
        assert!(
            (raster.x - (200.0 + 17.0)).abs() < 1e-6 && (raster.y - (200.0 - 5.0)).abs() < 1e-6,
            "perspective {perspective}: the old focal point is at {raster:?}"
        );
        s.apply(Event::Zoom { factor: 2.0 }).unwrap();
        let z = s.camera();
        if perspective {
            let d0 = (DVec3::from(after.position) - DVec3::from(after.focal_point)).length();
            let d1 = (DVec3::from(z.position) - DVec3::from(z.focal_point)).length();
            assert!((d1 - d0 / 2.0).abs() < 1e-9);
        } else {
            assert!((z.parallel_scale - after.parallel_scale / 2.0).abs() < 1e-12);
        }
    }
}

/// Anatomical views turn about the focal point and keep the zoom; reset returns to the start.
#[test]
fn views_keep_the_zoom_and_reset_returns_home() {
    let (mut s, _) = policy_session();
    let home = s.camera().clone();
    s.apply(Event::Zoom { factor: 1.5 }).unwrap();
    s.apply(Event::SetView {
        view: volsplat_core::AnatomicalView::Left,
    })
    .unwrap();
    let c = s.camera();
    let f = c.frame();
    assert!((f.forward - DVec3::new(-1.0, 0.0, 0.0)).length() < 1e-12);
    assert!((c.parallel_scale - home.parallel_scale / 1.5).abs() < 1e-12);
    s.apply(Event::Reset {}).unwrap();
    assert_eq!(s.camera(), &home);
}

/// An event that changes nothing (a reset at home) starts no frame.
#[test]
fn an_event_that_changes_nothing_keeps_the_generation() {
    let (mut s, _) = policy_session();
    let g = s.generation();
    s.apply(Event::Reset {}).unwrap();
    assert_eq!(s.generation(), g);
    s.apply(Event::Orbit { dx: 1.0, dy: 0.0 }).unwrap();
    assert_eq!(s.generation(), g + 1);
}

/// Events as the web viewer sends them: tagged JSON, unknown fields refused.
#[test]
fn events_parse_from_tagged_json_and_refuse_unknown_fields() {
    let e: Event = serde_json::from_str(r#"{"type":"orbit","dx":4,"dy":-2.5}"#).unwrap();
    assert_eq!(e, Event::Orbit { dx: 4.0, dy: -2.5 });
    let e: Event = serde_json::from_str(r#"{"type":"set_view","view":"superior"}"#).unwrap();
    assert_eq!(
        e,
        Event::SetView {
            view: volsplat_core::AnatomicalView::Superior
        }
    );
    let e: Event = serde_json::from_str(
        r#"{"type":"set_transfer_function","transfer_function":{"preset":"ct-bone"}}"#,
    )
    .unwrap();
    assert!(matches!(e, Event::SetTransferFunction { .. }));
    assert!(serde_json::from_str::<Event>(r#"{"type":"orbit","dx":1,"dy":2,"dz":3}"#).is_err());
    assert!(serde_json::from_str::<Event>(r#"{"type":"explode"}"#).is_err());
    let e: Event = serde_json::from_str(r#"{"type":"reset"}"#).unwrap();
    assert_eq!(e, Event::Reset {});
    assert!(serde_json::from_str::<Event>(r#"{"type":"reset","x":1}"#).is_err());
}

/// The final frame after a drag, a zoom, a preset, a crop and a resize is byte for byte the
/// PNG that `render --scene` writes from the saved scene (a fresh renderer, the scene file
/// read back, `write_image` as the CLI calls it); previews differ and are smaller.
#[test]
fn the_final_frame_is_render_of_the_saved_scene_bit_for_bit() {
    let (mut s, mut renderer, _) = session(96);
    for e in [
        Event::Interaction { active: true },
        Event::Orbit { dx: 14.0, dy: -9.0 },
        Event::Zoom { factor: 1.3 },
        Event::Pan { dx: 3.0, dy: 2.0 },
        Event::Roll { degrees: 12.0 },
        Event::SetTransferFunction {
            transfer_function: TransferSpec::Preset(Preset::CtBone),
        },
        Event::SetCrop {
            crop: Some(CropBox {
                min: [2.0, 0.0, 3.0],
                max: [35.0, 40.0, 43.0],
                units: CropUnits::Voxels,
            }),
        },
        Event::Resize {
            width: 80,
            height: 64,
        },
    ] {
        s.apply(e).unwrap();
    }
    let preview = s.next_job().unwrap();
    let p = s.run(&preview, &mut renderer).unwrap();
    assert!(p.image.width() < 80);
    s.finished(&preview, rendered(p.stats.total_ms));
    s.apply(Event::Interaction { active: false }).unwrap();
    let job = s.next_job().unwrap();
    assert!(job.is_final());
    let out = s.run(&job, &mut renderer).unwrap();
    s.finished(&job, rendered(out.stats.total_ms));
    let frame = out.png_bytes(&job.request).unwrap();

    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("scene.json");
    s.save(&scene).unwrap();
    let (loaded, warnings) = RenderRequest::load(&scene).unwrap();
    assert!(warnings.is_empty(), "{warnings:?}");
    let again = Renderer::new().render(&loaded, &mut |_| true).unwrap();
    let png = dir.path().join("render.png");
    again.write(&png, &loaded).unwrap();
    assert_eq!(frame, std::fs::read(&png).unwrap());
    assert!(
        out.image.pixels().iter().any(|px| px[3] > 0.1),
        "an empty frame proves nothing"
    );
}

/// A transfer-function edit reloads nothing that depends on the volume alone: the volume stays
/// the same allocation and the frame spends no time loading.
#[test]
fn a_transfer_function_edit_keeps_the_volume() {
    let (mut s, mut renderer, _) = session(48);
    let job = s.next_job().unwrap();
    s.run(&job, &mut renderer).unwrap();
    s.finished(&job, rendered(5.0));
    let vol = renderer.volume(&s.request().scene.volume).unwrap();
    let mut tf = renderer.transfer_function(s.request()).unwrap();
    tf.scalar_opacity[1][1] *= 0.5;
    s.apply(Event::SetTransferFunction {
        transfer_function: TransferSpec::Function(tf.clone()),
    })
    .unwrap();
    let job = s.next_job().unwrap();
    let out = s.run(&job, &mut renderer).unwrap();
    assert_eq!(out.stats.load_ms, 0.0);
    assert_eq!(out.transfer_function, tf);
    assert!(Arc::ptr_eq(
        &vol,
        &renderer.volume(&s.request().scene.volume).unwrap()
    ));
}

/// A final frame whose scene moves on during the render is cancelled by the render's own
/// progress callback, from another thread.
#[test]
fn a_render_in_flight_is_cancelled_by_newer_input() {
    let (mut s, mut renderer, _) = session(160);
    let first = s.next_job().unwrap();
    s.run(&first, &mut renderer).unwrap();
    s.finished(&first, rendered(1.0));
    let job = s.next_job().unwrap();
    assert!(job.is_final());
    let generation = Arc::clone(&s.generation);
    let mut go = s.keep_going(&job);
    let mut calls = 0;
    let out = renderer.render(&job.request, &mut |p| {
        calls += 1;
        if calls == 2 {
            // Another thread's event arrives mid-render.
            std::thread::scope(|t| {
                t.spawn(|| generation.fetch_add(1, Ordering::AcqRel));
            });
        }
        go(p)
    });
    assert!(
        matches!(out, Err(EngineError::Cancelled)),
        "{:?}",
        out.err()
    );
}

/// Issue 29 follow-up: the output options travel with the scene. A session started with a
/// background, sRGB and 16 bits, then turned to MIP through a grey window: each final frame's
/// PNG is the file written from the saved scene read back (before, the saved scene held
/// neither, and its file had a black background and no window).
#[test]
fn output_options_travel_with_the_saved_scene() {
    let clock = Arc::new(ManualClock::new());
    let mut renderer = Renderer::new();
    let mut request = head_request(48);
    request.output.background = [0.2, 0.35, 0.5];
    request.output.srgb = true;
    request.output.bit_depth = 16;
    let mut s = Session::start(request, &mut renderer, SessionSettings::default(), clock).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let mut final_png = |s: &mut Session, name: &str| {
        let job = loop {
            let job = s.next_job().unwrap();
            if job.is_final() {
                break job;
            }
            let out = s.run(&job, &mut renderer).unwrap();
            s.finished(&job, rendered(out.stats.total_ms));
        };
        let out = s.run(&job, &mut renderer).unwrap();
        s.finished(&job, rendered(out.stats.total_ms));
        let frame = out.png_bytes(&job.request).unwrap();
        let scene = dir.path().join(format!("{name}.json"));
        s.save(&scene).unwrap();
        let (loaded, _) = RenderRequest::load(&scene).unwrap();
        let png = dir.path().join(format!("{name}.png"));
        Renderer::new()
            .render(&loaded, &mut |_| true)
            .unwrap()
            .write(&png, &loaded)
            .unwrap();
        let file = std::fs::read(&png).unwrap();
        assert_eq!(frame, file, "{name}");
        (frame, loaded)
    };
    let (composite, loaded) = final_png(&mut s, "composite");
    assert_eq!(loaded.output.background, [0.2, 0.35, 0.5]);
    // The background shows: the corner pixel is not black (16-bit RGB, sRGB-encoded).
    let plain = {
        let mut r = loaded.clone();
        r.output = crate::OutputOptions::default();
        Renderer::new()
            .render(&r, &mut |_| true)
            .unwrap()
            .png_bytes(&r)
            .unwrap()
    };
    assert_ne!(composite, plain);
    s.apply(Event::SetMode { mode: Mode::Mip }).unwrap();
    s.apply(Event::SetWindow {
        window: Some([100.0, 900.0]),
    })
    .unwrap();
    let (_, loaded) = final_png(&mut s, "mip");
    assert_eq!(loaded.output.window, Some([100.0, 900.0]));
    assert_eq!(loaded.mode, Mode::Mip);
}

/// Options that check one by one can still make a scene the renderer refuses (a perspective
/// camera drawn by the splat list with a kernel only the orthographic sheets take): the failed
/// frame returns the session to the last scene that rendered, so later events render again,
/// and the saved scene is one `render` draws.
#[test]
fn a_refused_scene_returns_to_the_last_one_that_rendered() {
    let (mut s, mut renderer, _) = session(48);
    let job = s.next_job().unwrap();
    let out = s.run(&job, &mut renderer).unwrap();
    assert!(!s.finished(&job, rendered(out.stats.total_ms)));
    let good = s.request().clone();
    let mut camera = s.camera().clone();
    camera.parallel_projection = false;
    s.apply(Event::SetCamera { camera }).unwrap();
    let quality = crate::Quality {
        kernel: crate::KernelChoice::CatmullRom,
        visibility: crate::VisibilityChoice::Every,
        ..s.request().quality
    };
    s.apply(Event::SetQuality { quality }).unwrap();
    let bad = s.request().clone();
    assert_ne!(bad, good);
    let generation = s.generation();
    let job = s.next_job().unwrap();
    let err = s.run(&job, &mut renderer).unwrap_err();
    assert!(err.to_string().contains("radial kernel"), "{err}");
    assert!(s.finished(&job, JobOutcome::Failed), "the scene went back");
    assert_eq!(s.request(), &good);
    assert!(
        s.generation() > generation,
        "a new frame shows the restored scene"
    );
    // Later events render again.
    s.apply(Event::Orbit { dx: 5.0, dy: 0.0 }).unwrap();
    let job = s.next_job().unwrap();
    let out = s.run(&job, &mut renderer).unwrap();
    assert!(!s.finished(&job, rendered(out.stats.total_ms)));
    // A failure with nothing rendered before it has nowhere to go back to.
    let (mut fresh, _) = policy_session();
    let job = fresh.next_job().unwrap();
    assert!(!fresh.finished(&job, JobOutcome::Failed));
}
