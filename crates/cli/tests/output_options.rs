//! The output options (`--background`, `--srgb`, `--bit-depth`, `--window`/`--wl`) are part of
//! the request (`output` in a scene file): `--save-scene` keeps them, `--scene` renders them
//! again to the same bytes, flags override them, and scene files written before they existed
//! render as they did.

use std::path::Path;
use std::process::Output;

mod util;
use util::{stderr, volsplat};

/// `render` with the small blobs phantom and `extra`, writing `out`.
fn render(extra: &[&str], out: &Path) -> Output {
    let mut args = vec![
        "render",
        "--phantom",
        "blobs",
        "--phantom-size",
        "24",
        "--size",
        "40x32",
        "-q",
    ];
    args.extend_from_slice(extra);
    args.extend_from_slice(&["-o", out.to_str().unwrap()]);
    volsplat(&args)
}

fn ok(o: Output) -> Output {
    assert!(o.status.success(), "{}", stderr(&o));
    o
}

/// Before, `--save-scene` left the output flags out: `render --scene` of the saved scene wrote a
/// black background, linear 8-bit values and MIP through the transfer function instead of the
/// window. Now the scene holds them and renders to the same bytes.
#[test]
fn saved_scenes_keep_the_output_options() {
    let dir = tempfile::tempdir().unwrap();
    let p = |n: &str| dir.path().join(n);
    let cases: [&[&str]; 4] = [
        &["--background", "0.2,0.3,0.4", "--srgb", "--bit-depth", "16"],
        &["--background", "1,1,1", "--azimuth", "30"],
        &["--mode", "mip", "--wl", "0.4,0.4"],
        &["--mode", "xray", "--window", "0:3", "--bit-depth", "16"],
    ];
    for (n, flags) in cases.iter().enumerate() {
        let (a, b, s) = (
            p(&format!("a{n}.png")),
            p(&format!("b{n}.png")),
            p(&format!("s{n}.json")),
        );
        let mut args = flags.to_vec();
        args.extend_from_slice(&["--save-scene", s.to_str().unwrap()]);
        ok(render(&args, &a));
        let scene: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&s).unwrap()).unwrap();
        assert!(scene["output"].is_object(), "{flags:?}: {scene}");
        ok(volsplat(&[
            "render",
            "--scene",
            s.to_str().unwrap(),
            "-q",
            "-o",
            b.to_str().unwrap(),
        ]));
        assert_eq!(
            std::fs::read(&a).unwrap(),
            std::fs::read(&b).unwrap(),
            "{flags:?}"
        );
        // The options matter: without them the file differs.
        let plain = p(&format!("plain{n}.png"));
        let mode: Vec<&str> = flags
            .windows(2)
            .filter(|w| w[0] == "--mode")
            .flat_map(|w| w.to_vec())
            .collect();
        ok(render(&mode, &plain));
        assert_ne!(
            std::fs::read(&plain).unwrap(),
            std::fs::read(&b).unwrap(),
            "{flags:?} changed nothing"
        );
    }
    // A flag given with --scene overrides the file's option, the others stay.
    let (c, d) = (p("c.png"), p("d.png"));
    ok(volsplat(&[
        "render",
        "--scene",
        p("s0.json").to_str().unwrap(),
        "--background",
        "0,0,0",
        "-q",
        "-o",
        c.to_str().unwrap(),
    ]));
    ok(render(&["--srgb", "--bit-depth", "16"], &d));
    assert_eq!(std::fs::read(&c).unwrap(), std::fs::read(&d).unwrap());
    // A bad value in the file is named by its field.
    let text = std::fs::read_to_string(p("s0.json")).unwrap();
    let mut v: serde_json::Value = serde_json::from_str(&text).unwrap();
    v["output"]["bit_depth"] = serde_json::json!(12);
    std::fs::write(p("bad.json"), v.to_string()).unwrap();
    let o = volsplat(&[
        "render",
        "--scene",
        p("bad.json").to_str().unwrap(),
        "-q",
        "-o",
        c.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("--bit-depth (output.bit_depth): must be 8 or 16, got 12"),
        "{}",
        stderr(&o)
    );
}

/// A scene file without `output` (as written before it existed) loads with the defaults and
/// renders the bytes the plain flags render.
#[test]
fn old_scene_files_render_as_before() {
    let dir = tempfile::tempdir().unwrap();
    let p = |n: &str| dir.path().join(n);
    for (n, flags) in [&["--azimuth", "25"][..], &["--mode", "mip"]]
        .iter()
        .enumerate()
    {
        let (a, b, s, old) = (
            p(&format!("a{n}.png")),
            p(&format!("b{n}.png")),
            p(&format!("s{n}.json")),
            p(&format!("old{n}.json")),
        );
        let mut args = flags.to_vec();
        args.extend_from_slice(&["--save-scene", s.to_str().unwrap()]);
        ok(render(&args, &a));
        let mut v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&s).unwrap()).unwrap();
        assert!(v.as_object_mut().unwrap().remove("output").is_some());
        std::fs::write(&old, serde_json::to_string_pretty(&v).unwrap()).unwrap();
        let o = ok(volsplat(&[
            "render",
            "--scene",
            old.to_str().unwrap(),
            "-q",
            "-o",
            b.to_str().unwrap(),
        ]));
        assert!(stderr(&o).is_empty(), "{}", stderr(&o));
        assert_eq!(
            std::fs::read(&a).unwrap(),
            std::fs::read(&b).unwrap(),
            "{flags:?}"
        );
    }
}

/// `render --scene mip.json --wl …` was refused unless `--mode mip` was repeated: the window
/// was checked against the `--mode` flag's default (composite), not the scene's mode. Now it is
/// checked against the resolved request; a composite scene still refuses a window, and a
/// `--mode` given over a scene drops a window that does not fit the new mode, with a note.
#[test]
fn a_window_is_checked_against_the_scenes_mode() {
    let dir = tempfile::tempdir().unwrap();
    let p = |n: &str| dir.path().join(n);
    let s = |n: &str| p(n).to_str().unwrap().to_string();
    ok(render(
        &["--mode", "mip", "--save-scene", &s("mip.json")],
        &p("m.png"),
    ));
    ok(render(&["--save-scene", &s("composite.json")], &p("c.png")));
    let o = volsplat(&[
        "render",
        "--scene",
        &s("mip.json"),
        "--wl",
        "0.4,0.4",
        "-q",
        "-o",
        &s("w.png"),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    ok(render(
        &["--mode", "mip", "--wl", "0.4,0.4"],
        &p("direct.png"),
    ));
    assert_eq!(
        std::fs::read(p("w.png")).unwrap(),
        std::fs::read(p("direct.png")).unwrap()
    );
    let o = volsplat(&[
        "render",
        "--scene",
        &s("composite.json"),
        "--wl",
        "0.4,0.4",
        "-o",
        &s("x.png"),
    ]);
    assert_eq!(o.status.code(), Some(1));
    let e = stderr(&o);
    assert!(
        e.contains("--window/--wl (output.window)") && e.contains("grey window"),
        "{e}"
    );
    assert!(!p("x.png").exists());
    // The windowed MIP scene, turned to composite and to X-ray: the window goes, with a note.
    ok(volsplat(&[
        "render",
        "--scene",
        &s("mip.json"),
        "--wl",
        "0.4,0.4",
        "-q",
        "-o",
        &s("w2.png"),
        "--save-scene",
        &s("mipw.json"),
    ]));
    for mode in ["composite", "xray"] {
        let o = volsplat(&[
            "render",
            "--scene",
            &s("mipw.json"),
            "--mode",
            mode,
            "-o",
            &s("y.png"),
        ]);
        assert!(o.status.success(), "{mode}: {}", stderr(&o));
        assert!(
            stderr(&o).contains("grey window 0.2:0.6 was made for mode mip; dropped"),
            "{mode}: {}",
            stderr(&o)
        );
    }
    // MinIP shares MIP's units: the window stays (a grey file).
    let o = volsplat(&[
        "render",
        "--scene",
        &s("mipw.json"),
        "--mode",
        "minip",
        "-o",
        &s("z.png"),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(!stderr(&o).contains("dropped"), "{}", stderr(&o));
    let d = png::Decoder::new(std::io::BufReader::new(
        std::fs::File::open(p("z.png")).unwrap(),
    ));
    assert_eq!(
        d.read_info().unwrap().info().color_type,
        png::ColorType::Grayscale
    );
}
