//! The server through its sockets, as a browser and an attacker would reach it: a Rust
//! WebSocket client (`volsplat_view::replay::Client`) and raw HTTP.

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::time::Duration;
use volsplat::session::Event;
use volsplat::{PhantomKind, RenderRequest, Renderer, Scene, VolumeSource};
use volsplat_view::protocol::{ClientMessage, MAX_MESSAGE_BYTES, ServerMessage};
use volsplat_view::replay::{Client, Incoming};
use volsplat_view::{Viewer, ViewerHandle, ViewerSettings};

const WAIT: Duration = Duration::from_secs(60);

fn request(size: usize) -> RenderRequest {
    let scene = Scene {
        volume: VolumeSource::Phantom {
            phantom: PhantomKind::Head,
            grid: Some(vec![40, 48, 44]),
        },
        ..Scene::default()
    };
    RenderRequest::new(scene, size, size)
}

fn serve(settings: ViewerSettings) -> ViewerHandle {
    Viewer::bind(request(96), Renderer::new(), settings)
        .unwrap()
        .spawn()
        .unwrap()
}

/// A raw HTTP GET; returns the status code, the headers and the body.
fn get(addr: SocketAddr, target: &str, extra: &str) -> (u16, String, String) {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(WAIT)).unwrap();
    write!(
        s,
        "GET {target} HTTP/1.1\r\nHost: 127.0.0.1:{}\r\n{extra}\r\n",
        addr.port()
    )
    .unwrap();
    let mut text = String::new();
    s.read_to_string(&mut text).unwrap();
    let (head, body) = text.split_once("\r\n\r\n").unwrap_or((&text, ""));
    let status = head
        .split_whitespace()
        .nth(1)
        .and_then(|c| c.parse().ok())
        .unwrap_or(0);
    (status, head.to_string(), body.to_string())
}

/// Connects and waits for the hello and the first final frame.
fn connect(h: &ViewerHandle) -> (Client, volsplat_view::protocol::Hello) {
    let mut c = Client::connect(h.local_addr(), &h.token(), None).unwrap();
    let hello = c
        .wait_for(WAIT, |m| match m {
            Incoming::Text(ServerMessage::Hello(h)) => Some((**h).clone()),
            _ => None,
        })
        .unwrap();
    c.wait_final(0, WAIT).unwrap();
    (c, hello)
}

fn error_reply(c: &mut Client) -> String {
    c.wait_for(WAIT, |m| match m {
        Incoming::Text(ServerMessage::Error { message, .. }) => Some(message.clone()),
        _ => None,
    })
    .unwrap()
}

#[test]
fn the_page_needs_the_token() {
    let h = serve(ViewerSettings::default());
    let addr = h.local_addr();
    let token = h.token();
    assert!(
        h.url()
            .contains(&format!("127.0.0.1:{}/?token={token}", addr.port()))
    );
    let (status, head, body) = get(addr, &format!("/?token={token}"), "");
    assert_eq!(status, 200, "{head}");
    assert!(body.contains("<canvas"), "{body}");
    assert!(head.contains("Content-Security-Policy") && head.contains("no-store"));
    assert!(head.contains("Referrer-Policy: no-referrer"));
    let wrong = format!(
        "{}{}",
        &token[..31],
        if token.ends_with('0') { '1' } else { '0' }
    );
    for target in [
        "/".to_string(),
        "/?token=".into(),
        format!("/?token={wrong}"),
        // Not hex at all (a `g`): refused whatever the token's digits are.
        format!("/?token=g{}", &token[1..]),
    ] {
        let (status, _, body) = get(addr, &target, "");
        assert_eq!(status, 403, "{target}");
        assert!(!body.contains(&token), "the refusal leaks the token");
    }
    // The same 128 bits in upper-case hex are the token (`Token::matches` takes either case).
    let (status, _, _) = get(addr, &format!("/?token={}", token.to_ascii_uppercase()), "");
    assert_eq!(status, 200);
    let (status, _, _) = get(addr, &format!("/secret.nrrd?token={token}"), "");
    assert_eq!(status, 404);
}

#[test]
fn the_socket_needs_the_token_and_the_pages_own_origin() {
    let h = serve(ViewerSettings::default());
    let addr = h.local_addr();
    let token = h.token();
    for bad in ["", "0123", &"f".repeat(32)] {
        let e = Client::connect(addr, bad, None).unwrap_err();
        assert!(e.contains("403"), "token {bad:?}: {e}");
    }
    let e = Client::connect(addr, &token, Some("http://evil.example")).unwrap_err();
    assert!(e.contains("403"), "{e}");
    let own = format!("http://127.0.0.1:{}", addr.port());
    let mut c = Client::connect(addr, &token, Some(&own)).unwrap();
    c.wait_final(0, WAIT).unwrap();
}

/// A drag: previews while the pointer is held, each echoing the latest event, the final frame
/// after release; and the final frame's bytes are the PNG `render` writes for the saved scene.
/// Settings whose frame budget no final frame fits (1 ms), so that every drag previews.
fn previewing() -> ViewerSettings {
    let mut s = ViewerSettings::default();
    s.session.target_fps = 1000.0;
    s
}

#[test]
fn events_give_previews_then_the_final_frame_of_render() {
    let h = serve(previewing());
    let (mut c, hello) = connect(&h);
    assert_eq!(hello.dims, [40, 48, 44]);
    assert_eq!(hello.histogram.len(), 256);
    assert_eq!(
        hello.histogram.iter().sum::<u64>(),
        40 * 48 * 44,
        "every voxel counted once"
    );
    assert!(hello.presets.iter().any(|p| p == "CT-Bone"));
    c.event(Event::Interaction { active: true }).unwrap();
    let mut last = 0;
    let mut previews = 0;
    for _ in 0..6 {
        last = c.event(Event::Orbit { dx: 6.0, dy: 2.0 }).unwrap();
        let (q, seq, w) = c
            .wait_for(WAIT, |m| match m {
                Incoming::Frame(f, _) => Some((f.quality.clone(), f.seq, f.width)),
                _ => None,
            })
            .unwrap();
        assert!(seq <= last);
        if q == "preview" {
            previews += 1;
            assert!(w <= 96);
        }
    }
    assert!(previews > 0, "no previews while dragging");
    let release = c.event(Event::Interaction { active: false }).unwrap();
    assert!(release > last);
    let (header, png) = c.wait_final(release, WAIT).unwrap();
    assert_eq!(
        (header.width, header.height, header.format.as_str()),
        (96, 96, "png")
    );

    let scene = c.scene(WAIT).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("scene.json");
    scene.save(&path).unwrap();
    let (loaded, _) = RenderRequest::load(&path).unwrap();
    let out = Renderer::new().render(&loaded, &mut |_| true).unwrap();
    let expect = out.png_bytes(&loaded).unwrap();
    let decode = |b: &[u8]| volsplat_view::replay::decode_rgb("png", b).unwrap();
    assert_eq!(
        decode(&png),
        decode(&expect),
        "the final frame shows other pixels than render"
    );
    let shot = c.screenshot(WAIT).unwrap();
    assert_eq!(shot, expect, "the screenshot is not render's PNG file");
}

#[test]
fn malformed_messages_get_an_error_and_change_nothing() {
    let h = serve(ViewerSettings::default());
    let (mut c, _) = connect(&h);
    let before = c.scene(WAIT).unwrap();
    let bad = [
        "not json".to_string(),
        r#"{"type":"event","seq":1,"event":{"type":"orbit","dx":1}}"#.into(),
        r#"{"type":"event","seq":2,"event":{"type":"orbit","dx":1,"dy":2,"dz":3}}"#.into(),
        r#"{"type":"event","seq":3,"event":{"type":"zoom","factor":-1}}"#.into(),
        r#"{"type":"event","seq":4,"event":{"type":"resize","width":0,"height":5}}"#.into(),
        r#"{"type":"event","seq":5,"event":{"type":"set_window","window":[0,1]}}"#.into(),
        r#"{"type":"open","name":"../../etc/passwd"}"#.into(),
        r#"{"type":"open","name":"brain.nrrd"}"#.into(),
        r#"{"type":"rm","path":"/"}"#.into(),
        format!(
            r#"{{"type":"save_scene","x":"{}"}}"#,
            "a".repeat(MAX_MESSAGE_BYTES)
        ),
    ];
    for text in &bad {
        c.send_text(text).unwrap();
        let e = error_reply(&mut c);
        assert!(!e.is_empty());
    }
    assert_eq!(
        c.scene(WAIT).unwrap(),
        before,
        "a refused message changed the scene"
    );
    // Still alive: a good event renders.
    let seq = c.event(Event::Zoom { factor: 1.5 }).unwrap();
    c.wait_final(seq, WAIT).unwrap();
    // A message over the socket's own limit closes this tab but not the server.
    let huge = "x".repeat(2 << 20);
    let _ = c.send_text(&huge);
    let closed = (0..200).any(|_| c.recv(Duration::from_millis(50)).is_err());
    assert!(closed, "a 2 MiB message left the tab open");
    let (mut again, _) = connect(&h);
    let seq = again.event(Event::Roll { degrees: 10.0 }).unwrap();
    again.wait_final(seq, WAIT).unwrap();
}

/// Without acknowledgements the server sends one frame and waits, however much input comes;
/// the acknowledgement releases the next.
#[test]
fn at_most_one_frame_is_in_flight() {
    let h = serve(previewing());
    let (mut c, _) = connect(&h);
    c.event(Event::Interaction { active: true }).unwrap();
    let mut frames = Vec::new();
    for _ in 0..30 {
        c.event(Event::Orbit { dx: 3.0, dy: 0.0 }).unwrap();
        if let Some(Incoming::Frame(f, _)) = c.recv(Duration::from_millis(50)).unwrap() {
            frames.push(f);
        }
    }
    assert_eq!(frames.len(), 1, "{frames:?}");
    c.ack(frames[0].id).unwrap();
    let next = c
        .wait_for(WAIT, |m| match m {
            Incoming::Frame(f, _) => Some((f.id, f.seq)),
            _ => None,
        })
        .unwrap();
    assert!(next.0 > frames[0].id && next.1 > frames[0].seq, "{next:?}");
}

/// Two tabs on one volume: each has its own scene.
#[test]
fn two_tabs_watch_one_volume_with_their_own_cameras() {
    let h = serve(ViewerSettings::default());
    let (mut a, _) = connect(&h);
    let (mut b, _) = connect(&h);
    assert_eq!(h.tabs(), 2);
    let sa = a.event(Event::Orbit { dx: 40.0, dy: 0.0 }).unwrap();
    a.wait_final(sa, WAIT).unwrap();
    let sb = b.event(Event::Zoom { factor: 2.0 }).unwrap();
    b.wait_final(sb, WAIT).unwrap();
    let (ra, rb) = (a.scene(WAIT).unwrap(), b.scene(WAIT).unwrap());
    assert_ne!(ra.scene.camera, rb.scene.camera);
    assert_eq!(
        h.scene(),
        rb,
        "the handle's scene is the tab that changed last"
    );
    assert_eq!(ra.scene.volume, rb.scene.volume);
}

/// The data folder: listed by name, opened by name, nothing outside it.
#[test]
fn the_data_folder_is_listed_and_opened_by_name_only() {
    let dir = tempfile::tempdir().unwrap();
    let vol = volsplat::make_phantom(PhantomKind::Blobs, Some(&[20]), "grid").unwrap();
    volsplat::io::write_nrrd(dir.path().join("blobs.nrrd"), &vol, false).unwrap();
    std::fs::write(dir.path().join("notes.txt"), "not a volume").unwrap();
    std::fs::write(dir.path().join(".hidden.nrrd"), "hidden").unwrap();
    let h = serve(ViewerSettings {
        data_dir: Some(dir.path().to_path_buf()),
        ..ViewerSettings::default()
    });
    let (mut c, hello) = connect(&h);
    assert_eq!(hello.volumes, vec!["blobs.nrrd".to_string()]);
    c.send(&ClientMessage::Open {
        name: "notes.txt".into(),
    })
    .unwrap();
    assert!(error_reply(&mut c).contains("not in the volume list"));
    c.send(&ClientMessage::Open {
        name: "blobs.nrrd".into(),
    })
    .unwrap();
    let hello = c
        .wait_for(WAIT, |m| match m {
            Incoming::Text(ServerMessage::Hello(h)) => Some((**h).clone()),
            _ => None,
        })
        .unwrap();
    assert_eq!(hello.dims, [20, 20, 20]);
    assert_eq!(
        hello.volume, "blobs.nrrd",
        "the page sees names, never paths"
    );
    c.wait_final(0, WAIT).unwrap();
}

/// Listening beyond loopback needs `allow_remote`.
#[test]
fn remote_hosts_need_allow_remote() {
    let e = Viewer::bind(
        request(32),
        Renderer::new(),
        ViewerSettings {
            host: "0.0.0.0".into(),
            ..ViewerSettings::default()
        },
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("--allow-remote"), "{e}");
}

/// Stopping closes the tabs and frees the port.
#[test]
fn stopping_closes_tabs() {
    let mut h = serve(ViewerSettings::default());
    let (mut c, _) = connect(&h);
    let addr = h.local_addr();
    h.stop();
    let closed = (0..100).any(|_| c.recv(Duration::from_millis(50)).is_err());
    assert!(closed);
    assert!(
        std::net::TcpListener::bind(addr).is_ok(),
        "the port is still held"
    );
}

/// The turntable GIF comes back as a file.
#[test]
fn a_turntable_gif_is_rendered_on_the_server() {
    let h = serve(ViewerSettings::default());
    let (mut c, _) = connect(&h);
    c.send(&ClientMessage::Turntable {
        frames: 6,
        degrees: 360.0,
        fps: 12.0,
        max_size: 48,
    })
    .unwrap();
    let (name, bytes) = c
        .wait_for(WAIT, |m| match m {
            Incoming::Frame(f, b) if f.kind == "file" => Some((f.name.clone(), b.clone())),
            _ => None,
        })
        .unwrap();
    assert_eq!(name.as_deref(), Some("turntable.gif"));
    assert_eq!(&bytes[..6], b"GIF89a");
    let mut d = gif::DecodeOptions::new();
    d.set_color_output(gif::ColorOutput::Indexed);
    let mut r = d.read_info(std::io::Cursor::new(&bytes)).unwrap();
    assert_eq!((r.width(), r.height()), (48, 48));
    let mut n = 0;
    while r.read_next_frame().unwrap().is_some() {
        n += 1;
    }
    assert_eq!(n, 6);
}

/// Renders a saved scene as `volsplat render --scene` does: the file read back, a fresh
/// renderer, the request's own output options.
fn render_saved(scene: &RenderRequest) -> Vec<u8> {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("scene.json");
    scene.save(&path).unwrap();
    let (loaded, warnings) = RenderRequest::load(&path).unwrap();
    assert!(warnings.is_empty(), "{warnings:?}");
    let out = Renderer::new().render(&loaded, &mut |_| true).unwrap();
    out.png_bytes(&loaded).unwrap()
}

/// Issue 29 follow-up: the saved scene holds the output options (the start request's
/// background and encoding, the page's grey window), so rendering it gives the screenshot's
/// bytes; before, a window or background set in the viewer was lost from the scene file.
#[test]
fn the_saved_scene_renders_to_the_screenshot_with_its_window_and_background() {
    let mut start = request(64);
    start.output.background = [0.3, 0.15, 0.05];
    start.output.srgb = true;
    let h = Viewer::bind(start, Renderer::new(), ViewerSettings::default())
        .unwrap()
        .spawn()
        .unwrap();
    let (mut c, _) = connect(&h);
    let shot = c.screenshot(WAIT).unwrap();
    let scene = c.scene(WAIT).unwrap();
    assert_eq!(scene.output.background, [0.3, 0.15, 0.05]);
    assert_eq!(render_saved(&scene), shot, "composite over the background");
    c.event(Event::SetMode {
        mode: volsplat::Mode::Mip,
    })
    .unwrap();
    let seq = c
        .event(Event::SetWindow {
            window: Some([-100.0, 700.0]),
        })
        .unwrap();
    c.wait_final(seq, WAIT).unwrap();
    let shot = c.screenshot(WAIT).unwrap();
    let scene = c.scene(WAIT).unwrap();
    assert_eq!(scene.output.window, Some([-100.0, 700.0]));
    assert_eq!(h.scene().output.window, Some([-100.0, 700.0]));
    assert_eq!(render_saved(&scene), shot, "MIP through the window");
    let mut unwindowed = scene.clone();
    unwindowed.output.window = None;
    assert_ne!(
        render_saved(&unwindowed),
        shot,
        "the window changes the file"
    );
}

/// Issue 29 follow-up: with `fit_view` the tab starts at the size the page gives in its
/// WebSocket URL and follows `resize` events; the hello says so. Without it, or for a size
/// beyond the cap, the request's own size is kept.
#[test]
fn the_image_follows_the_view_when_asked() {
    let fit = ViewerSettings {
        fit_view: true,
        ..ViewerSettings::default()
    };
    let h = serve(fit);
    let mut c = Client::connect_sized(h.local_addr(), &h.token(), None, Some((120, 80))).unwrap();
    let hello = c
        .wait_for(WAIT, |m| match m {
            Incoming::Text(ServerMessage::Hello(h)) => Some((**h).clone()),
            _ => None,
        })
        .unwrap();
    assert!(hello.fit);
    assert_eq!(hello.max_fit_side, volsplat_view::MAX_FIT_SIDE);
    let (header, _) = c.wait_final(0, WAIT).unwrap();
    assert_eq!((header.width, header.height), (120, 80));
    let seq = c
        .event(Event::Resize {
            width: 90,
            height: 70,
        })
        .unwrap();
    let (header, _) = c.wait_final(seq, WAIT).unwrap();
    assert_eq!(
        (header.width, header.height, header.view),
        (90, 70, [90, 70])
    );
    let scene = c.scene(WAIT).unwrap();
    assert_eq!((scene.width, scene.height), (90, 70));
    assert_eq!(render_saved(&scene), c.screenshot(WAIT).unwrap());
    // A size over the cap is not taken: the request's own.
    let side = volsplat_view::MAX_FIT_SIDE + 1;
    let mut big =
        Client::connect_sized(h.local_addr(), &h.token(), None, Some((side, 10))).unwrap();
    let (header, _) = big.wait_final(0, WAIT).unwrap();
    assert_eq!((header.width, header.height), (96, 96));

    let fixed = serve(ViewerSettings::default());
    let mut c =
        Client::connect_sized(fixed.local_addr(), &fixed.token(), None, Some((120, 80))).unwrap();
    let hello = c
        .wait_for(WAIT, |m| match m {
            Incoming::Text(ServerMessage::Hello(h)) => Some((**h).clone()),
            _ => None,
        })
        .unwrap();
    assert!(!hello.fit);
    let (header, _) = c.wait_final(0, WAIT).unwrap();
    assert_eq!(
        (header.width, header.height),
        (96, 96),
        "a fixed size stays"
    );
}

/// Issue 29 follow-up: idle connections (no request head) are capped. Of 100 opened at once
/// (loopback, a bounded loop), at most `max_connections` hold a thread; the others are
/// answered 503 at once. Meanwhile an open tab keeps rendering, and once the idle sockets
/// close the count falls back and the page loads again.
#[test]
fn idle_connections_are_capped_and_the_server_goes_on() {
    let h = serve(ViewerSettings::default());
    let (mut tab, _) = connect(&h);
    let addr = h.local_addr();
    let limit = volsplat_view::MAX_PENDING_CONNECTIONS;
    let mut idle = Vec::new();
    for _ in 0..100 {
        let s = TcpStream::connect(addr).unwrap();
        s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
        idle.push(s);
        assert!(h.pending_connections() <= limit);
    }
    // Every connection was accepted or refused: the accept loop has seen all 100.
    let mut refused = 0;
    for s in idle.iter_mut().skip(limit) {
        let mut text = String::new();
        let _ = s.read_to_string(&mut text);
        refused += text.starts_with("HTTP/1.1 503") as usize;
    }
    assert!(
        refused >= 100 - limit - 2,
        "{refused} of the connections beyond the cap were answered 503"
    );
    assert!(h.pending_connections() <= limit);
    // The tab renders on through the flood.
    let seq = tab.event(Event::Orbit { dx: 10.0, dy: 0.0 }).unwrap();
    tab.wait_final(seq, WAIT).unwrap();
    drop(idle);
    let end = std::time::Instant::now() + Duration::from_secs(20);
    while h.pending_connections() > 0 && std::time::Instant::now() < end {
        std::thread::sleep(Duration::from_millis(20));
    }
    assert_eq!(
        h.pending_connections(),
        0,
        "closed connections were not let go"
    );
    let (status, _, _) = get(addr, &format!("/?token={}", h.token()), "");
    assert_eq!(status, 200);
    assert_eq!(h.tabs(), 1);
}

/// A click on the view without a drag, or a refused event, changes nothing: no new frame
/// comes, and the server says the final frame on screen shows those events (`shown`), so a
/// page waiting for "the final frame of my latest event" (the screenshot button) does not wait
/// forever. Before, the frame's `seq` stayed below the click's and nothing more was sent.
#[test]
fn events_that_change_nothing_are_shown_by_the_final_frame() {
    let h = serve(ViewerSettings::default());
    let (mut c, _) = connect(&h);
    let first = c.scene(WAIT).unwrap();
    c.event(Event::Interaction { active: true }).unwrap();
    let release = c.event(Event::Interaction { active: false }).unwrap();
    let (header, _) = c.wait_final(release, WAIT).unwrap();
    assert!(header.seq >= release);
    let refused = c.event(Event::Zoom { factor: -1.0 }).unwrap();
    assert!(error_reply(&mut c).contains("zoom.factor"));
    let (again, _) = c.wait_final(refused, WAIT).unwrap();
    assert_eq!(again.id, header.id, "no new frame was rendered for nothing");
    assert!(again.seq >= refused);
    assert_eq!(c.scene(WAIT).unwrap(), first, "the scene did not change");
    // A real change still renders a new frame.
    let moved = c.event(Event::Orbit { dx: 5.0, dy: 0.0 }).unwrap();
    let (next, _) = c.wait_final(moved, WAIT).unwrap();
    assert!(next.id > header.id);
}

/// Previews draw the volume itself unless the session asks for the pyramid; then the frame
/// header says which level each preview drew, and no note about levels reaches the page.
#[test]
fn pyramid_previews_say_their_level() {
    for pyramid in [false, true] {
        let mut settings = previewing();
        settings.session.pyramid_previews = pyramid;
        // An aim of 1 µs no preview meets, however fast the renderer: the previews shrink to
        // the smallest scale (at 1 ms, faster slabs kept some previews near full size).
        settings.session.headroom = 0.001;
        let mut h = serve(settings);
        let (mut c, _) = connect(&h);
        c.event(Event::Interaction { active: true }).unwrap();
        let mut levels = Vec::new();
        for _ in 0..8 {
            let seq = c.event(Event::Orbit { dx: 6.0, dy: 2.0 }).unwrap();
            let got = c
                .wait_for(WAIT, |m| match m {
                    Incoming::Frame(f, _) if f.seq >= seq => {
                        Some(Ok((f.quality.clone(), f.volume_level)))
                    }
                    Incoming::Text(ServerMessage::Note { message })
                        if message.contains("level") =>
                    {
                        Some(Err(message.clone()))
                    }
                    _ => None,
                })
                .unwrap();
            match got {
                Ok((q, level)) if q == "preview" => levels.push(level),
                Ok(_) => {}
                Err(note) => panic!("a note about levels: {note}"),
            }
        }
        assert!(!levels.is_empty(), "no previews while dragging");
        if pyramid {
            // The aim shrinks the previews to an eighth of the side: a coarse level.
            assert!(levels.iter().any(|&l| l >= 1), "{levels:?}");
        } else {
            assert!(levels.iter().all(|&l| l == 0), "{levels:?}");
        }
        h.stop();
    }
}

/// Issue 29 item 5: a header in the data folder whose data file lies outside it (MetaImage
/// `ElementDataFile = ../secret.raw`, NRRD `data file: /abs/secret.raw`) is listed, but opening
/// it is an error reply naming the field: no hello or frame carries the outside bytes, and the
/// server goes on answering. The volume given at start, outside the folder, reads its own
/// detached data file as before (the user named it).
#[test]
fn data_files_outside_the_data_folder_are_refused() {
    let root = tempfile::tempdir().unwrap();
    let data = root.path().join("data");
    std::fs::create_dir(&data).unwrap();
    std::fs::write(root.path().join("secret.raw"), [200u8, 201, 202, 203]).unwrap();
    let detached = |data_file: &str| {
        format!(
            "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 8 8 8\nencoding: raw\n\
             data file: {data_file}\n"
        )
    };
    std::fs::write(root.path().join("user.raw"), vec![9u8; 512]).unwrap();
    std::fs::write(root.path().join("user.nhdr"), detached("user.raw")).unwrap();
    std::fs::write(
        data.join("escape.mhd"),
        "ObjectType = Image\nNDims = 3\nDimSize = 2 2 1\nElementType = MET_UCHAR\n\
         ElementDataFile = ../secret.raw\n",
    )
    .unwrap();
    let secret = root.path().join("secret.raw");
    std::fs::write(
        data.join("escape.nhdr"),
        format!(
            "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 1\nencoding: raw\n\
             data file: {}\n",
            secret.display()
        ),
    )
    .unwrap();
    let vol = volsplat::make_phantom(PhantomKind::Blobs, Some(&[20]), "grid").unwrap();
    volsplat::io::write_nrrd(data.join("blobs.nrrd"), &vol, false).unwrap();
    let mut start = request(48);
    start.scene.volume = VolumeSource::File {
        path: root.path().join("user.nhdr"),
        raw: None,
        frame: 0,
        array: None,
        series: None,
        level: volsplat::StoreLevel::Index(0),
        channel: 0,
        timepoint: 0,
    };
    let h = Viewer::bind(
        start,
        Renderer::new(),
        ViewerSettings {
            data_dir: Some(data.clone()),
            ..ViewerSettings::default()
        },
    )
    .unwrap()
    .spawn()
    .unwrap();
    let (mut c, hello) = connect(&h);
    assert_eq!(hello.dims, [8, 8, 8], "the start volume is read unconfined");
    assert_eq!(hello.volumes, ["blobs.nrrd", "escape.mhd", "escape.nhdr"]);
    for (name, field, value) in [
        (
            "escape.mhd",
            "`ElementDataFile`",
            "../secret.raw".to_string(),
        ),
        ("escape.nhdr", "`data file`", secret.display().to_string()),
    ] {
        c.send(&ClientMessage::Open { name: name.into() }).unwrap();
        let mut hellos = 0;
        let message = c
            .wait_for(WAIT, |m| match m {
                Incoming::Text(ServerMessage::Hello(_)) => {
                    hellos += 1;
                    None
                }
                Incoming::Text(ServerMessage::Error { message, .. }) => Some(message.clone()),
                _ => None,
            })
            .unwrap();
        assert_eq!(hellos, 0, "{name}: a hello came before the error");
        for part in [name, field, &format!("`{value}`"), "lies outside"] {
            assert!(message.contains(part), "{part:?} missing from: {message}");
        }
    }
    // The server still answers, and opens a volume of the folder.
    c.send(&ClientMessage::Open {
        name: "blobs.nrrd".into(),
    })
    .unwrap();
    let hello = c
        .wait_for(WAIT, |m| match m {
            Incoming::Text(ServerMessage::Hello(h)) => Some((**h).clone()),
            _ => None,
        })
        .unwrap();
    assert_eq!(hello.dims, [20, 20, 20]);
    let (mut c2, hello) = connect(&h);
    assert_eq!(hello.dims, [8, 8, 8]);
    c2.send(&ClientMessage::Open {
        name: "escape.nhdr".into(),
    })
    .unwrap();
    assert!(error_reply(&mut c2).contains("lies outside"));
}

/// A data folder that does not exist, or a file given as one, is a settings error saying so.
#[test]
fn a_missing_or_file_data_folder_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("v.nrrd");
    std::fs::write(&file, "x").unwrap();
    for (d, want) in [
        (dir.path().join("none"), "no such folder"),
        (file, "is a file, not a folder"),
    ] {
        let e = Viewer::bind(
            request(32),
            Renderer::new(),
            ViewerSettings {
                data_dir: Some(d),
                ..ViewerSettings::default()
            },
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains(want) && e.contains("--data-dir"), "{e}");
    }
}
