//! End-to-end tests of the `volsplat` binary: the README's commands, output formats, and clear
//! errors for bad input.

use std::path::Path;
use std::process::{Command, Output};

fn volsplat(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_volsplat"))
        .args(args)
        .output()
        .expect("binary runs")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn npy_shape(path: &Path) -> Vec<usize> {
    let bytes = std::fs::read(path).unwrap();
    assert_eq!(&bytes[..6], b"\x93NUMPY");
    let header = String::from_utf8_lossy(&bytes[10..]).to_string();
    let shape = header
        .split("'shape': (")
        .nth(1)
        .unwrap()
        .split(')')
        .next()
        .unwrap();
    shape
        .split(',')
        .filter(|s| !s.trim().is_empty())
        .map(|s| s.trim().parse().unwrap())
        .collect()
}

#[test]
fn demo_render_writes_a_png_and_stats() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("demo.png");
    let o = volsplat(&[
        "render",
        "-o",
        out.to_str().unwrap(),
        "--size",
        "96x80",
        "--phantom-size",
        "48",
        "--azimuth",
        "30",
        "--stats",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let png = std::fs::read(&out).unwrap();
    assert_eq!(&png[1..4], b"PNG");
    let stats: serde_json::Value =
        serde_json::from_slice(&o.stdout).expect("--stats prints one JSON object");
    for key in [
        "classify_ms",
        "splat_ms",
        "composite_ms",
        "total_ms",
        "splats",
        "kernel_cost",
        "threads",
    ] {
        assert!(stats.get(key).is_some(), "missing {key} in {stats}");
    }
    assert_eq!(stats["width"], 96);
    assert!(stats["splats"].as_u64().unwrap() > 0);
}

#[test]
fn npy_outputs_have_the_documented_shapes() {
    let dir = tempfile::tempdir().unwrap();
    let rgba = dir.path().join("c.npy");
    let xray = dir.path().join("x.npy");
    let o = volsplat(&[
        "render",
        "--phantom",
        "blobs",
        "--phantom-size",
        "32",
        "--size",
        "40x30",
        "-o",
        rgba.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(npy_shape(&rgba), vec![30, 40, 4]);
    let o = volsplat(&[
        "render",
        "--phantom",
        "blobs",
        "--phantom-size",
        "32",
        "--size",
        "40x30",
        "--mode",
        "xray",
        "-o",
        xray.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(npy_shape(&xray), vec![30, 40]);
}

#[test]
fn phantom_round_trips_through_nrrd_and_info() {
    let dir = tempfile::tempdir().unwrap();
    let nrrd = dir.path().join("sl.nrrd");
    let o = volsplat(&[
        "phantom",
        "shepp-logan",
        "--size",
        "24,20,16",
        "-o",
        nrrd.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = volsplat(&["info", nrrd.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("24 x 20 x 16"), "{text}");
    assert!(text.contains("f32"), "{text}");
    let png = dir.path().join("sl.png");
    let o = volsplat(&[
        "render",
        nrrd.to_str().unwrap(),
        "--mode",
        "mip",
        "--size",
        "32x32",
        "-o",
        png.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
}

#[test]
fn camera_and_transfer_function_files_are_used_and_checked() {
    let dir = tempfile::tempdir().unwrap();
    let cam = dir.path().join("cam.json");
    let out = dir.path().join("a.png");
    // --save-camera writes the camera used; rendering with it reproduces the image exactly.
    let o = volsplat(&[
        "render",
        "--phantom-size",
        "32",
        "--size",
        "48x48",
        "--azimuth",
        "40",
        "-o",
        out.to_str().unwrap(),
        "--save-camera",
        cam.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out2 = dir.path().join("b.png");
    let o = volsplat(&[
        "render",
        "--phantom-size",
        "32",
        "--size",
        "48x48",
        "--camera",
        cam.to_str().unwrap(),
        "-o",
        out2.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(std::fs::read(&out).unwrap(), std::fs::read(&out2).unwrap());

    let bad = dir.path().join("bad.json");
    std::fs::write(
        &bad,
        r#"{"position": [0, 0, 1], "focal_point": [0, 0, 0], "parallel_projection": true}"#,
    )
    .unwrap();
    let o = volsplat(&[
        "render",
        "--phantom-size",
        "16",
        "--camera",
        bad.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(e.contains("view_up") && e.contains("bad.json"), "{e}");

    let tf = dir.path().join("tf.json");
    std::fs::write(
        &tf,
        r#"{"color": [[0, 1, 1, 1]], "scalar_opacity": [[0, 0], [1, 2.0]], "colour_map": 3}"#,
    )
    .unwrap();
    let o = volsplat(&[
        "render",
        "--phantom",
        "blobs",
        "--phantom-size",
        "16",
        "--tf",
        tf.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(
        e.contains("scalar_opacity[1]") && e.contains("tf.json"),
        "{e}"
    );
}

#[test]
fn bad_input_gives_clear_errors_not_panics() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("o.png");
    let cases: Vec<(Vec<String>, &str)> = vec![
        (
            vec![
                "render".into(),
                "/nonexistent/vol.nrrd".into(),
                "-o".into(),
                out.display().to_string(),
            ],
            "/nonexistent/vol.nrrd",
        ),
        (
            vec![
                "render".into(),
                "--size".into(),
                "12by4".into(),
                "-o".into(),
                out.display().to_string(),
            ],
            "--size",
        ),
        (
            vec![
                "render".into(),
                "--kernel".into(),
                "sinc".into(),
                "-o".into(),
                out.display().to_string(),
            ],
            "sinc",
        ),
        (
            vec![
                "render".into(),
                "--preset".into(),
                "nope".into(),
                "-o".into(),
                out.display().to_string(),
            ],
            "nope",
        ),
        (
            vec![
                "render".into(),
                "--phantom-size".into(),
                "8".into(),
                "-o".into(),
                dir.path().join("o.jpg").display().to_string(),
            ],
            "o.jpg",
        ),
    ];
    for (args, needle) in cases {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let o = volsplat(&args);
        assert_eq!(o.status.code(), Some(1), "{args:?}: {}", stderr(&o));
        let e = stderr(&o);
        assert!(e.contains(needle), "{args:?}: {e}");
        assert!(!e.contains("panicked"), "{e}");
    }
    // A truncated NRRD names the file and the byte counts.
    let nrrd = dir.path().join("t.nrrd");
    std::fs::write(
        &nrrd,
        b"NRRD0004\ntype: uint8\ndimension: 3\nsizes: 10 10 10\nencoding: raw\n\n0123",
    )
    .unwrap();
    let o = volsplat(&["info", nrrd.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1));
    let e = stderr(&o);
    assert!(e.contains("t.nrrd") && e.contains("1000"), "{e}");
    // Nothing half-written: the failed render left no output file.
    assert!(!out.exists());
}

#[test]
fn ladder_writes_previews() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("final.png");
    let o = volsplat(&[
        "render",
        "--phantom-size",
        "32",
        "--size",
        "32x32",
        "--ladder",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    for name in ["final.png", "final.preview-s4.png", "final.preview-s2.png"] {
        assert!(dir.path().join(name).exists(), "{name}");
    }
}

#[test]
fn threads_do_not_change_the_output() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (dir.path().join("a.npy"), dir.path().join("b.npy"));
    for (p, t) in [(&a, "1"), (&b, "2")] {
        let o = volsplat(&[
            "render",
            "--phantom-size",
            "40",
            "--size",
            "64x64",
            "--azimuth",
            "20",
            "--elevation",
            "30",
            "--threads",
            t,
            "-o",
            p.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
    }
    assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
}

#[test]
fn lights_and_switches_change_the_picture() {
    let dir = tempfile::tempdir().unwrap();
    let tf = dir.path().join("shaded.json");
    std::fs::write(
        &tf,
        r#"{"color": [[0, 1, 0.8, 0.6]], "scalar_opacity": [[0, 0], [1, 0.3]], "shade": true,
            "diffuse": 0.8, "specular": 0.3, "scalar_opacity_unit_distance": 0.05}"#,
    )
    .unwrap();
    let render = |name: &str, extra: &[&str]| {
        let p = dir.path().join(name);
        let mut args = vec![
            "render",
            "--phantom",
            "blobs",
            "--phantom-size",
            "40",
            "--size",
            "48x48",
            "--tf",
            tf.to_str().unwrap(),
            "-o",
            p.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        let o = volsplat(&args);
        assert!(o.status.success(), "{}", stderr(&o));
        std::fs::read(&p).unwrap()
    };
    let base = render("a.npy", &[]);
    assert!(
        base[128..].iter().any(|&b| b != 0),
        "the shaded blobs are visible"
    );
    let side = render("b.npy", &["--light", "1,0,0.2,1,0.5,0.5"]);
    let two = render("c.npy", &["--light", "0,0,1", "--light", "-1,0,0.3,0,0,1"]);
    let flat = render("d.npy", &["--no-diffuse", "--no-specular"]);
    assert!(base != side && base != two && base != flat);
    // The default is exactly one white headlight.
    assert!(base == render("e.npy", &["--light", "0,0,1"]));
    let o = volsplat(&[
        "render",
        "--light",
        "0,0,0",
        "-o",
        dir.path().join("f.png").to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("--light"));
}

#[test]
fn texture_bench_writes_report_and_plates() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("tb");
    let o = volsplat(&[
        "texture-bench",
        "--size",
        "quick",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let report = std::fs::read_to_string(out.join("report.md")).unwrap();
    for row in [
        "Point sampled",
        "Step clamped",
        "Direct Gauss-27",
        "NIL, M=1",
        "EWA-3 adaptive",
    ] {
        assert!(report.contains(row), "report lacks {row}");
    }
    let png = std::fs::read(out.join("plate_5_1_point_sampled.png")).unwrap();
    assert_eq!(&png[1..4], b"PNG");
}

#[test]
fn perspective_render_with_antialiasing_and_the_k_line() {
    let dir = tempfile::tempdir().unwrap();
    let cam = dir.path().join("cam.json");
    std::fs::write(
        &cam,
        r#"{"position":[-6,-6,24],"focal_point":[60,48,0],"view_up":[0,0,1],"view_angle":90,"parallel_projection":false}"#,
    )
    .unwrap();
    let cam = cam.to_str().unwrap();
    let mut stats = Vec::new();
    for aa in ["none", "swan", "ewa"] {
        let out = dir.path().join(format!("cb-{aa}.png"));
        let o = volsplat(&[
            "render",
            "--phantom",
            "checkerboard",
            "--phantom-size",
            "150,120,4",
            "--camera",
            cam,
            "--size",
            "96x64",
            "--antialias",
            aa,
            "--draw-k",
            "--stats",
            "-o",
            out.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        assert!(stderr(&o).contains("k = s·D/p"), "{}", stderr(&o));
        let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        assert_eq!(j["projection"], "perspective");
        assert_eq!(j["list_splats"], 150 * 120);
        stats.push(j["splats_widened"].as_u64().unwrap());
    }
    // No widening without anti-aliasing; Swan widens only splats beyond k; EWA widens all.
    assert_eq!(stats[0], 0);
    assert!(stats[1] > 0 && stats[1] < stats[2]);
}

#[test]
fn perspective_options_are_checked() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("x.png");
    let o = volsplat(&[
        "render",
        "--perspective",
        "--view-angle",
        "190",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("--view-angle"), "{}", stderr(&o));
    let o = volsplat(&[
        "render",
        "--perspective",
        "--kernel",
        "tent",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("radial kernel"), "{}", stderr(&o));
    let o = volsplat(&[
        "render",
        "--phantom",
        "terrain",
        "--phantom-size",
        "4096,4096,4096",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("limited to"), "{}", stderr(&o));
    let o = volsplat(&["render", "--draw-k", "-o", out.to_str().unwrap()]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("--draw-k"), "{}", stderr(&o));
    assert!(!out.exists());
}
