//! `volsplat view` as a user starts it: the printed URL, the token, a drag over the WebSocket,
//! the final frame against `volsplat render --scene` of the saved scene, and Ctrl-C.

use std::io::{BufRead, BufReader};
use std::net::SocketAddr;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::Duration;
use volsplat::session::Event;
use volsplat_view::replay::Client;

const WAIT: Duration = Duration::from_secs(120);

fn bin() -> &'static str {
    env!("CARGO_BIN_EXE_volsplat")
}

/// Starts `volsplat view ARGS --no-browser` and reads its one line of standard output.
fn start(args: &[&str]) -> (Child, SocketAddr, String) {
    let mut child = Command::new(bin())
        .arg("view")
        .args(args)
        .arg("--no-browser")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let url = line
        .strip_prefix("open ")
        .unwrap_or_else(|| panic!("first line: {line:?}"))
        .trim()
        .to_string();
    let rest = url.strip_prefix("http://").unwrap();
    let (host_port, query) = rest.split_once("/?token=").unwrap();
    assert_eq!(query.len(), 32, "a 128-bit token in hex: {url}");
    (child, host_port.parse().unwrap(), query.to_string())
}

#[cfg(unix)]
fn interrupt(child: &mut Child) -> String {
    Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    let out = child.wait().unwrap();
    let mut err = String::new();
    std::io::Read::read_to_string(&mut child.stderr.take().unwrap(), &mut err).unwrap();
    assert!(out.success(), "exit {out:?}: {err}");
    err
}

fn render_scene(scene: &Path, out: &Path, extra: &[&str]) -> Vec<u8> {
    let r = Command::new(bin())
        .arg("render")
        .arg("--scene")
        .arg(scene)
        .arg("-o")
        .arg(out)
        .args(extra)
        .arg("--quiet")
        .output()
        .unwrap();
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    std::fs::read(out).unwrap()
}

/// The final frame after a drag is the file `volsplat render --scene` writes from the saved
/// scene alone: the output flags the viewer started with (a background, sRGB; a MIP through a
/// grey window) travel in the scene, so `render` needs none of them again.
#[cfg(unix)]
#[test]
fn view_drag_save_render_and_stop() {
    for flags in [
        vec!["--azimuth", "20", "--background", "0.2,0.3,0.4", "--srgb"],
        vec!["--mode", "mip", "--wl", "300,1200"],
    ] {
        let mut args = vec![
            "--phantom",
            "head",
            "--phantom-size",
            "40,48,44",
            "--size",
            "80x64",
        ];
        args.extend(&flags);
        let (mut child, addr, token) = start(&args);
        assert!(Client::connect(addr, "", None).unwrap_err().contains("403"));
        let mut c = Client::connect(addr, &token, None).unwrap();
        c.wait_final(0, WAIT).unwrap();
        c.event(Event::Interaction { active: true }).unwrap();
        for _ in 0..5 {
            c.event(Event::Orbit { dx: 8.0, dy: -3.0 }).unwrap();
        }
        let release = c.event(Event::Interaction { active: false }).unwrap();
        let (header, png) = c.wait_final(release, WAIT).unwrap();
        assert_eq!((header.width, header.height), (80, 64));
        let scene = c.scene(WAIT).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("scene.json");
        scene.save(&path).unwrap();
        let rendered = render_scene(&path, &dir.path().join("r.png"), &[]);
        let decode = |b: &[u8]| volsplat_view::replay::decode_rgb("png", b).unwrap();
        assert_eq!(decode(&png), decode(&rendered), "{flags:?}");
        assert_eq!(c.screenshot(WAIT).unwrap(), rendered, "{flags:?}");
        assert_eq!(
            scene.output,
            match flags[1] {
                "mip" => volsplat::OutputOptions {
                    window: Some([-300.0, 900.0]),
                    ..Default::default()
                },
                _ => volsplat::OutputOptions {
                    background: [0.2, 0.3, 0.4],
                    srgb: true,
                    ..Default::default()
                },
            }
        );
        let err = interrupt(&mut child);
        assert!(err.contains("stopped"), "{err}");
    }
}

#[test]
fn view_refuses_what_it_cannot_serve() {
    let cases: [(&[&str], &str); 3] = [
        (&["/no/such/volume.nrrd"], "no/such/volume.nrrd"),
        (&["--host", "0.0.0.0"], "--allow-remote"),
        (&["--mode", "composite", "--wl", "1,2"], "grey window"),
    ];
    for (args, expect) in cases {
        let out = Command::new(bin())
            .arg("view")
            .args(args)
            .arg("--no-browser")
            .output()
            .unwrap();
        assert!(!out.status.success());
        assert!(out.stdout.is_empty(), "printed a URL for {args:?}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(expect), "{args:?}: {err}");
    }
}

/// Without `--size` the image follows the page's view (the size the page gives when it
/// connects); with `--size`, or a `--scene` (whose request has its size), it stays fixed.
#[cfg(unix)]
#[test]
fn the_image_fills_the_view_unless_a_size_is_given() {
    use volsplat_view::protocol::ServerMessage;
    use volsplat_view::replay::Incoming;
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("s.json");
    let phantom = ["--phantom", "head", "--phantom-size", "40,48,44"];
    let out = Command::new(bin())
        .arg("render")
        .args(phantom)
        .args(["--size", "72x40", "-q", "-o"])
        .arg(dir.path().join("s.png"))
        .arg("--save-scene")
        .arg(&scene)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let scene_arg = ["--scene", scene.to_str().unwrap()];
    let cases: [(&[&str], bool, (usize, usize)); 3] = [
        (&phantom, true, (100, 70)),
        (
            &[&phantom[..], &["--size", "80x64"]].concat(),
            false,
            (80, 64),
        ),
        (&scene_arg, false, (72, 40)),
    ];
    for (args, fit, size) in cases {
        let (mut child, addr, token) = start(args);
        let mut c = Client::connect_sized(addr, &token, None, Some((100, 70))).unwrap();
        let hello = c
            .wait_for(WAIT, |m| match m {
                Incoming::Text(ServerMessage::Hello(h)) => Some((**h).clone()),
                _ => None,
            })
            .unwrap();
        assert_eq!(hello.fit, fit, "{args:?}");
        let (header, _) = c.wait_final(0, WAIT).unwrap();
        assert_eq!((header.width, header.height), size, "{args:?}");
        interrupt(&mut child);
    }
}

/// `--data-dir` naming no folder says so (it used to say "no volume files there"), with or
/// without a volume given.
#[test]
fn a_data_dir_that_is_not_a_folder_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("v.nrrd");
    std::fs::write(&file, "x").unwrap();
    let none = dir.path().join("none");
    for (d, expect) in [
        (&none, "no such folder"),
        (&file, "is a file, not a folder"),
    ] {
        for volume in [&[][..], &["--phantom", "blobs"][..]] {
            let out = Command::new(bin())
                .arg("view")
                .args(volume)
                .arg("--data-dir")
                .arg(d)
                .arg("--no-browser")
                .output()
                .unwrap();
            assert!(!out.status.success());
            assert!(out.stdout.is_empty(), "printed a URL for {d:?}");
            let err = String::from_utf8_lossy(&out.stderr);
            assert!(
                err.contains(expect) && err.contains("--data-dir") && !err.contains("no volume"),
                "{volume:?} {d:?}: {err}"
            );
        }
    }
}

/// With only `--data-dir`, a first file that does not read is said and passed over: the
/// viewer shows the next one (and fails, naming the file, only when none reads).
#[cfg(unix)]
#[test]
fn a_data_dir_whose_first_file_does_not_read_shows_the_next() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("a_broken.nrrd"),
        "NRRD0004\ntype: nonsense\n\n",
    )
    .unwrap();
    let good = dir.path().join("b_good.nrrd");
    let made = Command::new(bin())
        .args(["phantom", "blobs", "--grid", "16", "-o"])
        .arg(&good)
        .output()
        .unwrap();
    assert!(
        made.status.success(),
        "{}",
        String::from_utf8_lossy(&made.stderr)
    );
    let (mut child, _, _) = start(&["--data-dir", dir.path().to_str().unwrap()]);
    let err = interrupt(&mut child);
    assert!(
        err.contains("a_broken.nrrd") && err.contains("showing the next file"),
        "{err}"
    );
    assert!(err.contains("b_good.nrrd"), "{err}");
    // Nothing that reads: the last file's error, named.
    std::fs::remove_file(&good).unwrap();
    let out = Command::new(bin())
        .args(["view", "--no-browser", "--data-dir"])
        .arg(dir.path())
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(out.stdout.is_empty());
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("a_broken.nrrd"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}
