#![no_main]
//! Fuzz target: the viewer's WebSocket messages (`volsplat_view::protocol::parse_client_message`),
//! and the events among them applied to a session (no rendering): never a panic, and an event
//! the session refuses changes nothing.

use libfuzzer_sys::fuzz_target;
use std::sync::{Arc, OnceLock};
use volsplat::session::{ManualClock, Session, SessionSettings};
use volsplat::{PhantomKind, RenderRequest, Scene, VolumeSource};
use volsplat_view::protocol::{ClientMessage, parse_client_message};

fn session() -> Session {
    static BASE: OnceLock<(RenderRequest, volsplat::core::Camera, volsplat::core::Grid)> =
        OnceLock::new();
    let (req, cam, grid) = BASE.get_or_init(|| {
        let scene = Scene {
            volume: VolumeSource::Phantom {
                phantom: PhantomKind::Blobs,
                grid: Some(vec![8]),
            },
            ..Scene::default()
        };
        let grid = volsplat::core::Grid::with_dims([8, 8, 8]).unwrap();
        let (lo, hi) = grid.bounds_world();
        let cam = volsplat::core::Camera::reset_to_bounds(lo, hi, true);
        (RenderRequest::new(scene, 64, 48), cam, grid)
    });
    Session::new(
        req.clone(),
        cam.clone(),
        grid.clone(),
        SessionSettings::default(),
        Arc::new(ManualClock::new()),
    )
    .unwrap()
}

fuzz_target!(|data: &[u8]| {
    let Ok(msg) = parse_client_message(data) else {
        return;
    };
    if let ClientMessage::Event { event, .. } = msg {
        let mut s = session();
        let before = (s.request().clone(), s.generation());
        if s.apply(event).is_err() {
            assert!(before == (s.request().clone(), s.generation()));
        }
        if let Some(job) = s.next_job() {
            job.request.validate().unwrap();
        }
    }
});
