//! End-to-end tests of the `volsplat` binary: the README's commands, output formats, and clear
//! errors for bad input.

use std::path::Path;
use std::process::Command;

mod util;
use util::{npy_f32, stderr, stdout, volsplat};

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
        "--grid",
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
    // A closed set parsed by clap: a usage error (exit 2) that lists the accepted names.
    let o = volsplat(&["render", "--kernel", "sinc", "-o", out.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    let e = stderr(&o);
    assert!(e.contains("sinc") && e.contains("crawfis-max"), "{e}");
    let o = volsplat(&["render", "--preset", "nope", "-o", out.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    let e = stderr(&o);
    assert!(e.contains("nope") && e.contains("CT-Bone"), "{e}");
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

#[test]
fn output_paths_are_checked_before_the_volume_is_loaded() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("no-such-folder");
    let good = dir.path().join("ok.png");
    // The input does not exist: an error about the output proves it was checked first.
    let cases: Vec<(Vec<String>, Vec<String>)> = vec![
        (
            vec!["-o".into(), dir.path().join("o.jpg").display().to_string()],
            vec!["o.jpg".into(), ".png or .npy".into()],
        ),
        (
            vec!["-o".into(), missing.join("a.png").display().to_string()],
            vec![format!("folder {} does not exist", missing.display())],
        ),
        (
            vec!["-o".into(), dir.path().display().to_string()],
            vec!["is a folder".into()],
        ),
        (
            vec![
                "-o".into(),
                good.display().to_string(),
                "--save-camera".into(),
                missing.join("cam.json").display().to_string(),
            ],
            vec![
                "--save-camera".into(),
                format!("folder {} does not exist", missing.display()),
            ],
        ),
    ];
    for (extra, needles) in cases {
        let mut args = vec!["render".to_string(), "/nonexistent/vol.nrrd".to_string()];
        args.extend(extra);
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let o = volsplat(&args);
        assert_eq!(o.status.code(), Some(1), "{args:?}");
        let e = stderr(&o);
        for needle in &needles {
            assert!(e.contains(needle.as_str()), "{args:?}: {e}");
        }
        assert!(!e.contains("vol.nrrd"), "output checked after loading: {e}");
    }
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
}

#[test]
fn render_says_what_it_wrote_unless_quiet() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("w.png");
    let base = [
        "render",
        "--phantom",
        "blobs",
        "--phantom-size",
        "16",
        "--size",
        "40x30",
        "-o",
        out.to_str().unwrap(),
    ];
    let o = volsplat(&base);
    assert!(o.status.success(), "{}", stderr(&o));
    let e = stderr(&o);
    let line = format!("wrote {} (40×30, ", out.display());
    assert!(e.contains(&line) && e.trim_end().ends_with(" ms)"), "{e}");
    assert!(stdout(&o).is_empty());
    // --stats: the JSON object stays alone on stdout; the report goes to stderr.
    let o = volsplat(&[&base[..], &["--stats"]].concat());
    assert!(o.status.success(), "{}", stderr(&o));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).expect("only JSON on stdout");
    assert_eq!(j["width"], 40);
    assert!(stderr(&o).contains(&line), "{}", stderr(&o));
    for quiet in ["-q", "--quiet"] {
        let o = volsplat(&[&base[..], &[quiet]].concat());
        assert!(o.status.success(), "{}", stderr(&o));
        assert!(!stderr(&o).contains("wrote"), "{quiet}: {}", stderr(&o));
        assert!(out.exists());
    }
    // Ladder previews are reported too, and silenced by --quiet.
    let o = volsplat(&[&base[..], &["--ladder"]].concat());
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("w.preview-s4.png"), "{}", stderr(&o));
    let o = volsplat(&[&base[..], &["--ladder", "-q"]].concat());
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).is_empty(), "{}", stderr(&o));
}

/// Never ignore a flag silently: splatting-only flags with a Chapter 6 display warn, and a ray
/// function the display cannot do is an error.
#[test]
fn splat_only_flags_with_a_display_renderer_are_not_ignored_silently() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("s.png");
    let o = volsplat(&[
        "render",
        "--phantom",
        "blobs",
        "--phantom-size",
        "24",
        "--size",
        "24",
        "--renderer",
        "sabella",
        "--kernel",
        "tent",
        "--no-specular",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let e = stderr(&o);
    assert!(
        e.contains("warning: --kernel, --no-specular only apply to --renderer auto"),
        "{e}"
    );
    assert!(out.exists());
    let o = volsplat(&[
        "render",
        "--phantom",
        "blobs",
        "--phantom-size",
        "24",
        "--size",
        "24",
        "--renderer",
        "sabella",
        "--mode",
        "xray",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("--renderer auto for MIP"),
        "{}",
        stderr(&o)
    );
    // Without such flags, no warning.
    let o = volsplat(&[
        "render",
        "--phantom",
        "blobs",
        "--phantom-size",
        "24",
        "--size",
        "24",
        "--renderer",
        "sabella",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(!stderr(&o).contains("warning"), "{}", stderr(&o));
}

/// `--orthographic` switches a perspective camera file to orthographic, framing the focal plane
/// as the perspective view did.
#[test]
fn orthographic_switches_a_perspective_camera_file() {
    let dir = tempfile::tempdir().unwrap();
    let p = |n: &str| dir.path().join(n).to_str().unwrap().to_string();
    let base = [
        "render",
        "--phantom",
        "blobs",
        "--phantom-size",
        "24",
        "--size",
        "32",
        "-q",
    ];
    let run = |extra: &[&str]| {
        let mut args: Vec<&str> = base.to_vec();
        args.extend_from_slice(extra);
        let o = volsplat(&args);
        assert!(o.status.success(), "{extra:?}: {}", stderr(&o));
    };
    run(&[
        "--perspective",
        "--azimuth",
        "20",
        "-o",
        &p("a.png"),
        "--save-camera",
        &p("persp.json"),
    ]);
    run(&[
        "--camera",
        &p("persp.json"),
        "--orthographic",
        "-o",
        &p("b.png"),
        "--save-camera",
        &p("ortho.json"),
    ]);
    let read = |n: &str| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(p(n)).unwrap()).unwrap()
    };
    let (persp, ortho) = (read("persp.json"), read("ortho.json"));
    assert_eq!(persp["parallel_projection"], false);
    assert_eq!(ortho["parallel_projection"], true);
    let v = |j: &serde_json::Value, k: &str| -> Vec<f64> {
        j[k].as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect()
    };
    let d: f64 = v(&persp, "position")
        .iter()
        .zip(v(&persp, "focal_point"))
        .map(|(a, b)| (a - b) * (a - b))
        .sum::<f64>()
        .sqrt();
    let expect = d * (0.5 * persp["view_angle"].as_f64().unwrap().to_radians()).tan();
    let got = ortho["parallel_scale"].as_f64().unwrap();
    assert!((got - expect).abs() < 1e-9 * expect, "{got} vs {expect}");
    assert_eq!(v(&ortho, "position"), v(&persp, "position"));
    // Without a camera file it is a usage error (orthographic is already the default).
    let o = volsplat(&["render", "--orthographic", "-o", &p("c.png")]);
    assert_eq!(o.status.code(), Some(2));
}

#[test]
fn a_folder_as_input_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let series = dir.path().join("series");
    std::fs::create_dir(&series).unwrap();
    let out = dir.path().join("o.png");
    for args in [
        vec![
            "render",
            series.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
        ],
        vec!["info", series.to_str().unwrap()],
    ] {
        let o = volsplat(&args);
        assert_eq!(o.status.code(), Some(1), "{args:?}");
        let e = stderr(&o);
        assert!(
            e.contains(&series.display().to_string())
                && e.contains("a directory with no .tif/.tiff slices")
                && e.contains("no DICOM files"),
            "{e}"
        );
    }
    assert!(!out.exists());
}

#[test]
fn view_flags_apply_to_a_camera_file() {
    let dir = tempfile::tempdir().unwrap();
    let p = |name: &str| dir.path().join(name).display().to_string();
    let render = |extra: &[&str], out: &str| {
        let mut args = vec![
            "render",
            "--phantom",
            "head",
            "--phantom-size",
            "24,32,28",
            "--size",
            "40x36",
            "-q",
            "-o",
            out,
        ];
        args.extend_from_slice(extra);
        let o = volsplat(&args);
        assert!(o.status.success(), "{args:?}: {}", stderr(&o));
        (std::fs::read(out).unwrap(), o)
    };
    // The reset camera, and the same view turned 90° without a file.
    let (reset_img, _) = render(&["--save-camera", &p("reset.json")], &p("reset.png"));
    let (az_img, _) = render(
        &["--azimuth", "90", "--save-camera", &p("az.json")],
        &p("az.png"),
    );
    assert_ne!(reset_img, az_img);
    // The reset camera file + --azimuth 90 is the no-file view, and the rotated file's view.
    let (file_az, _) = render(
        &["--camera", &p("reset.json"), "--azimuth", "90"],
        &p("file-az.png"),
    );
    assert_eq!(file_az, az_img);
    let (rotated, _) = render(&["--camera", &p("az.json")], &p("rotated.png"));
    assert_eq!(rotated, az_img);
    // Without flags the file's camera is used as it is.
    let (plain, _) = render(&["--camera", &p("reset.json")], &p("plain.png"));
    assert_eq!(plain, reset_img);
    // Every flag changes the view of a file's camera, as it does without one.
    let reset_json = p("reset.json");
    for flags in [
        vec!["--elevation", "40"],
        vec!["--roll", "30"],
        vec!["--zoom", "1.7"],
    ] {
        let mut with_file = vec!["--camera", reset_json.as_str()];
        with_file.extend_from_slice(&flags);
        let (a, _) = render(&with_file, &p("f.png"));
        let (b, _) = render(&flags, &p("n.png"));
        assert_ne!(a, reset_img, "{flags:?}");
        assert_eq!(a, b, "{flags:?}");
    }
    // --perspective switches the file's camera; --view-angle replaces its view angle.
    let (_, o) = render(
        &[
            "--camera",
            &p("reset.json"),
            "--perspective",
            "--view-angle",
            "20",
            "--dolly",
            "1.5",
            "--stats",
            "--save-camera",
            &p("persp.json"),
        ],
        &p("persp.png"),
    );
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(j["projection"], "perspective");
    let saved: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(p("persp.json")).unwrap()).unwrap();
    let reset: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(p("reset.json")).unwrap()).unwrap();
    assert_eq!(saved["parallel_projection"], false);
    assert_eq!(saved["view_angle"], 20.0);
    let dist = |c: &serde_json::Value| {
        (0..3)
            .map(|i| {
                (c["position"][i].as_f64().unwrap() - c["focal_point"][i].as_f64().unwrap()).powi(2)
            })
            .sum::<f64>()
            .sqrt()
    };
    assert!((dist(&saved) * 1.5 - dist(&reset)).abs() < 1e-9 * dist(&reset));
    // --view-angle on an orthographic camera says it has no effect.
    let (_, o) = render(
        &["--camera", &p("reset.json"), "--view-angle", "20"],
        &p("va.png"),
    );
    assert!(
        stderr(&o).contains("warning: --view-angle has no effect"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn camera_without_projection_and_unordered_transfer_functions_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("o.png");
    let cam = dir.path().join("noproj.json");
    std::fs::write(
        &cam,
        r#"{"position": [0, 0, 100], "focal_point": [0, 0, 0], "view_up": [0, 1, 0]}"#,
    )
    .unwrap();
    let o = volsplat(&[
        "render",
        "--phantom-size",
        "16",
        "--camera",
        cam.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(1));
    let e = stderr(&o);
    assert!(
        e.contains("noproj.json") && e.contains("missing required field `parallel_projection`"),
        "{e}"
    );
    let tf = dir.path().join("unordered.json");
    std::fs::write(
        &tf,
        r#"{"color": [[0, 1, 1, 1]], "scalar_opacity": [[0, 0], [0.8, 0.5], [0.4, 1]]}"#,
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
    assert_eq!(o.status.code(), Some(1));
    let e = stderr(&o);
    assert!(
        e.contains("unordered.json")
            && e.contains("scalar_opacity[2]")
            && e.contains("0.4")
            && e.contains("order"),
        "{e}"
    );
    assert!(!out.exists());
}

#[test]
fn size_is_the_image_size_everywhere() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("sq.npy");
    let o = volsplat(&[
        "render",
        "--phantom",
        "blobs",
        "--phantom-size",
        "16",
        "--size",
        "24",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(npy_shape(&out), vec![24, 24, 4]);
    let o = volsplat(&[
        "bench",
        "--phantom",
        "blobs",
        "--phantom-size",
        "16",
        "--size",
        "20",
        "--frames",
        "1",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(
        (j["width"].as_u64(), j["height"].as_u64()),
        (Some(20), Some(20))
    );
    for bad in ["24x", "2.5", "big"] {
        let o = volsplat(&["render", "--size", bad, "-o", out.to_str().unwrap()]);
        assert_eq!(o.status.code(), Some(1));
        let e = stderr(&o);
        assert!(
            e.contains("--size") && e.contains(&format!("`{bad}`")),
            "{e}"
        );
    }
    // phantom: --grid is the voxel grid; --size is an error pointing to it.
    let nrrd = dir.path().join("p.nrrd");
    let o = volsplat(&[
        "phantom",
        "blobs",
        "--size",
        "12",
        "-o",
        nrrd.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("--grid 12"), "{}", stderr(&o));
    assert!(!nrrd.exists());
    let o = volsplat(&[
        "phantom",
        "blobs",
        "--grid",
        "12,10,8",
        "-o",
        nrrd.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = volsplat(&["info", nrrd.to_str().unwrap()]);
    assert!(stdout(&o).contains("12 x 10 x 8"), "{}", stdout(&o));
}

#[test]
fn short_help_keeps_to_everyday_options_in_groups() {
    let short = stdout(&volsplat(&["render", "-h"]));
    let long = stdout(&volsplat(&["render", "--help"]));
    for heading in [
        "Input:",
        "Output:",
        "Camera:",
        "Transfer function:",
        "Quality:",
        "Performance:",
    ] {
        assert!(short.contains(heading), "-h lacks {heading}:\n{short}");
    }
    for everyday in [
        "--output",
        "--size",
        "--camera",
        "--azimuth",
        "--tf",
        "--quiet",
    ] {
        assert!(short.contains(everyday), "-h lacks {everyday}");
    }
    for research in [
        "--gamma-min",
        "--rho0",
        "--dog-gain",
        "--trigger-steps",
        "--ladder",
    ] {
        assert!(!short.contains(research), "-h shows {research}");
        assert!(long.contains(research), "--help lacks {research}");
    }
    assert!(long.contains("Research (Chapter 6 displays):"));
    let count = |text: &str| {
        text.lines()
            .filter(|l| l.trim_start().starts_with("--"))
            .count()
    };
    assert!(
        count(&short) * 2 < count(&long),
        "{} vs {}",
        count(&short),
        count(&long)
    );
    for cmd in ["render", "bench", "info", "phantom"] {
        let help = stdout(&volsplat(&[cmd, "--help"]));
        assert!(!help.contains("DESIGN"), "{cmd} --help cites DESIGN.md");
    }
    // The X-ray PNG's scaling is documented where the mode is chosen.
    assert!(long.contains("brightest pixel is white"), "{long}");
}

/// `--save-scene` then `--scene` writes the same bytes (orthographic, perspective, MIP, X-ray);
/// flags given with `--scene` override its fields; scene-file problems are named.
#[test]
fn saved_scenes_render_again_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap();
    let p = |n: &str| dir.path().join(n).to_str().unwrap().to_string();
    let cases: [&[&str]; 4] = [
        &["--azimuth", "30", "--elevation", "10"],
        &["--perspective", "--azimuth", "-20", "--view-angle", "40"],
        &["--mode", "mip", "--azimuth", "45"],
        &["--mode", "xray", "--roll", "15", "--zoom", "1.3"],
    ];
    for (n, extra) in cases.iter().enumerate() {
        let (a, b, s) = (
            p(&format!("a{n}.npy")),
            p(&format!("b{n}.npy")),
            p(&format!("s{n}.json")),
        );
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
        args.extend_from_slice(&["-o", &a, "--save-scene", &s]);
        let o = volsplat(&args);
        assert!(o.status.success(), "{extra:?}: {}", stderr(&o));
        let o = volsplat(&["render", "--scene", &s, "-q", "-o", &b]);
        assert!(o.status.success(), "{extra:?}: {}", stderr(&o));
        assert!(stderr(&o).is_empty(), "{}", stderr(&o));
        assert_eq!(
            std::fs::read(&a).unwrap(),
            std::fs::read(&b).unwrap(),
            "{extra:?}"
        );
    }
    // A flag given with --scene overrides the file: the size changes, the view does not.
    let c = p("c.npy");
    let o = volsplat(&[
        "render",
        "--scene",
        &p("s0.json"),
        "--size",
        "20x16",
        "-q",
        "-o",
        &c,
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(npy_shape(Path::new(&c)), vec![16, 20, 4]);
    // Unknown fields warn; a missing required field is an error naming it.
    let text = std::fs::read_to_string(p("s0.json")).unwrap();
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    let mut extra = v.clone();
    extra["colour_map"] = serde_json::json!("jet");
    std::fs::write(p("x.json"), extra.to_string()).unwrap();
    let o = volsplat(&["render", "--scene", &p("x.json"), "-q", "-o", &c]);
    assert!(o.status.success());
    assert!(
        stderr(&o).contains("warning") && stderr(&o).contains("`colour_map`"),
        "{}",
        stderr(&o)
    );
    let mut missing = v.clone();
    missing.as_object_mut().unwrap().remove("width");
    std::fs::write(p("m.json"), missing.to_string()).unwrap();
    let o = volsplat(&["render", "--scene", &p("m.json"), "-q", "-o", &c]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("missing field `width`") && stderr(&o).contains("m.json"),
        "{}",
        stderr(&o)
    );
}

/// The new readers are reachable from the command line: a VTK `.vti` file with two arrays,
/// the array chosen with `--array`, renders, and `info` reads it.
#[test]
fn vti_files_render_with_the_chosen_array() {
    let dir = tempfile::tempdir().unwrap();
    let vti = dir.path().join("v.vti");
    let n = 6usize;
    let ramp: Vec<String> = (0..n * n * n).map(|i| (i % n).to_string()).collect();
    let zero: Vec<String> = (0..n * n * n).map(|_| "0".to_string()).collect();
    std::fs::write(
        &vti,
        format!(
            r#"<?xml version="1.0"?>
<VTKFile type="ImageData" version="1.0" byte_order="LittleEndian">
  <ImageData WholeExtent="0 5 0 5 0 5" Origin="0 0 0" Spacing="1 1 2">
    <Piece Extent="0 5 0 5 0 5">
      <PointData Scalars="zero">
        <DataArray type="Float32" Name="zero" format="ascii">{}</DataArray>
        <DataArray type="Float32" Name="ramp" format="ascii">{}</DataArray>
      </PointData>
    </Piece>
  </ImageData>
</VTKFile>"#,
            zero.join(" "),
            ramp.join(" ")
        ),
    )
    .unwrap();
    let o = volsplat(&["info", vti.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stdout(&o).contains("6 x 6 x 6"), "{}", stdout(&o));
    let (a, b) = (dir.path().join("a.npy"), dir.path().join("b.npy"));
    for (out, array) in [(&a, "zero"), (&b, "ramp")] {
        let o = volsplat(&[
            "render",
            vti.to_str().unwrap(),
            "--array",
            array,
            "--mode",
            "xray",
            "--size",
            "16",
            "-q",
            "-o",
            out.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{array}: {}", stderr(&o));
    }
    let sum = |p: &Path| -> f64 {
        let bytes = std::fs::read(p).unwrap();
        let start = bytes.len() - 16 * 16 * 4;
        bytes[start..]
            .chunks(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]) as f64)
            .sum()
    };
    assert_eq!(sum(&a), 0.0);
    assert!(sum(&b) > 0.0);
    let o = volsplat(&[
        "render",
        vti.to_str().unwrap(),
        "--array",
        "nope",
        "-q",
        "-o",
        a.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("nope"), "{}", stderr(&o));
}

/// `volsplat info … | head -1`: a reader that closes the pipe early is not a crash (exit 101).
#[test]
fn a_closed_output_pipe_is_not_a_panic() {
    let mut child = Command::new(env!("CARGO_BIN_EXE_volsplat"))
        .args(["info", "--phantom", "blobs", "--phantom-size", "96"])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Close the read end before the phantom is built and anything is written.
    drop(child.stdout.take());
    let o = child.wait_with_output().unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(!stderr(&o).contains("panicked"), "{}", stderr(&o));
}

/// Reads the 8-bit RGB samples of a PNG.
fn png_rgb8(path: &Path) -> (Vec<u8>, Option<u32>) {
    // The gAMA chunk's value (gamma × 100000), read from the bytes.
    let bytes = std::fs::read(path).unwrap();
    let gamma = bytes
        .windows(4)
        .position(|w| w == b"gAMA")
        .map(|i| u32::from_be_bytes([bytes[i + 4], bytes[i + 5], bytes[i + 6], bytes[i + 7]]));
    let decoder = png::Decoder::new(std::io::Cursor::new(bytes));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!(info.color_type, png::ColorType::Rgb);
    buf.truncate(info.buffer_size());
    (buf, gamma)
}

/// Reads a float32 `.npy` written by volsplat (little-endian, C order).
/// Decision 0012: a PNG holds the linear framebuffer values, as VTK, ParaView and Slicer write
/// them (code = round(255·v) over a black background), with gAMA 1.0; `--srgb` encodes.
#[test]
fn png_output_is_linear_by_default_and_srgb_on_request() {
    let dir = tempfile::tempdir().unwrap();
    let common = [
        "render",
        "--phantom-size",
        "32",
        "--size",
        "40x30",
        "--azimuth",
        "30",
    ];
    let run = |extra: &[&str], name: &str| {
        let out = dir.path().join(name);
        let mut args: Vec<&str> = common.to_vec();
        args.extend_from_slice(extra);
        args.extend_from_slice(&["-q", "-o", out.to_str().unwrap()]);
        let o = volsplat(&args);
        assert!(o.status.success(), "{args:?}: {}", stderr(&o));
        out
    };
    let values = npy_f32(&run(&[], "v.npy"));
    let (linear, gamma) = png_rgb8(&run(&[], "l.png"));
    let (srgb, _) = png_rgb8(&run(&["--srgb"], "s.png"));
    let (old_flag, _) = png_rgb8(&run(&["--linear"], "o.png"));
    assert_eq!(gamma, Some(100_000));
    assert_eq!(linear, old_flag);
    let mut lit = 0;
    for (px, rgba) in values.chunks_exact(4).enumerate() {
        for c in 0..3 {
            let want = (rgba[c].clamp(0.0, 1.0) * 255.0).round() as u8;
            assert!(
                linear[3 * px + c].abs_diff(want) <= 1,
                "pixel {px} channel {c}: {} vs {want}",
                linear[3 * px + c]
            );
            // sRGB lifts every mid-tone.
            if want > 10 && want < 245 {
                assert!(srgb[3 * px + c] > linear[3 * px + c]);
                lit += 1;
            }
        }
    }
    assert!(lit > 100, "the test scene must have mid-tones ({lit})");
}

/// `--window` and `--wl` write MIP values as a grey PNG: LO → 0, HI → 255, linear between;
/// the two spellings of one window give the same file; a composite render refuses a window.
#[test]
fn grey_windows_map_mip_values_linearly() {
    let dir = tempfile::tempdir().unwrap();
    let base = [
        "render",
        "--phantom",
        "blobs",
        "--phantom-size",
        "24",
        "--size",
        "32",
        "--mode",
        "mip",
        "-q",
    ];
    let run = |extra: &[&str], name: &str| {
        let out = dir.path().join(name);
        let mut args: Vec<&str> = base.to_vec();
        args.extend_from_slice(extra);
        args.extend_from_slice(&["-o", out.to_str().unwrap()]);
        let o = volsplat(&args);
        (out, o)
    };
    let (npy, o) = run(&[], "m.npy");
    assert!(o.status.success(), "{}", stderr(&o));
    let (_, o) = run(&["--window", "0.2:0.6"], "m.npy");
    assert!(o.status.success(), "{}", stderr(&o));
    let values = npy_f32(&npy);
    let (win, o) = run(&["--window", "0.2:0.6"], "w.png");
    assert!(o.status.success(), "{}", stderr(&o));
    let (wl, o) = run(&["--wl", "0.4,0.4"], "l.png");
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(std::fs::read(&win).unwrap(), std::fs::read(&wl).unwrap());
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(&win).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!(info.color_type, png::ColorType::Grayscale);
    assert_eq!(values.len(), 32 * 32);
    let (mut low, mut high) = (0, 0);
    for (v, &code) in values.iter().zip(&buf) {
        let want = if v.is_nan() {
            0.0
        } else {
            ((v - 0.2) / 0.4).clamp(0.0, 1.0) * 255.0
        };
        assert!(
            (code as f32 - want).abs() <= 1.0,
            "{v} → {code}, want {want}"
        );
        low += (code == 0) as usize;
        high += (code == 255) as usize;
    }
    assert!(
        low > 0 && high > 0,
        "the window must clip both ends: {low} {high}"
    );
    let o = volsplat(&[
        "render",
        "--size",
        "16",
        "--wl",
        "40,400",
        "-o",
        dir.path().join("c.png").to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("--wl"), "{}", stderr(&o));
}

/// `--limits` sets the readers' limits: a file over the voxel limit is refused naming the file
/// and the limit; an unknown key is an error listing the known ones.
#[test]
fn reader_limits_are_one_flag() {
    let dir = tempfile::tempdir().unwrap();
    let vol = dir.path().join("b.nrrd");
    let o = volsplat(&[
        "phantom",
        "blobs",
        "--grid",
        "16",
        "-o",
        vol.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = dir.path().join("o.png");
    let o = volsplat(&[
        "render",
        vol.to_str().unwrap(),
        "--size",
        "16",
        "--limits",
        "voxels=1000",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(1));
    let e = stderr(&o);
    assert!(e.contains("b.nrrd") && e.contains("1000"), "{e}");
    assert!(!out.exists());
    let o = volsplat(&["info", vol.to_str().unwrap(), "--limits", "voxels=1e4"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = volsplat(&["info", vol.to_str().unwrap(), "--limits", "pixels=5"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("header-bytes"), "{}", stderr(&o));
}

/// `info --json` reports the geometry as one stable JSON object; `convert` keeps voxels and
/// geometry in every format it writes (NRRD, NIfTI, MetaImage), so the converted file renders to
/// the same bytes.
#[test]
fn info_json_and_convert_keep_the_geometry() {
    let dir = tempfile::tempdir().unwrap();
    let vol = dir.path().join("b.nrrd");
    let o = volsplat(&[
        "phantom",
        "blobs",
        "--grid",
        "12,14,10",
        "-o",
        vol.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = volsplat(&["info", vol.to_str().unwrap(), "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(j["schema"], 1);
    assert_eq!(j["format"], "NRRD");
    assert_eq!(j["dims"], serde_json::json!([12, 14, 10]));
    assert_eq!(j["voxels"], 12 * 14 * 10);
    assert_eq!(j["direction"][0][0], 1.0);
    assert_eq!(j["direction"][0][1], 0.0);
    assert_eq!(j["series"].as_array().unwrap().len(), 0);
    let render = |input: &Path, name: &str| {
        let out = dir.path().join(name);
        let o = volsplat(&[
            "render",
            input.to_str().unwrap(),
            "--size",
            "24",
            "--azimuth",
            "20",
            "-q",
            "-o",
            out.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        std::fs::read(out).unwrap()
    };
    let original = render(&vol, "a.png");
    // Every format `convert` writes that keeps the geometry (issue 28 §5).
    for (name, gzip) in [
        ("c.nrrd", true),
        ("c.nii", false),
        ("c.nii.gz", false),
        ("c.mha", false),
        ("c.mhd", true),
    ] {
        let conv = dir.path().join(name);
        let mut args = vec!["convert", vol.to_str().unwrap(), "-q", "-o"];
        args.push(conv.to_str().unwrap());
        if gzip {
            args.push("--gzip");
        }
        let o = volsplat(&args);
        assert!(o.status.success(), "{name}: {}", stderr(&o));
        let o = volsplat(&["info", conv.to_str().unwrap(), "--json"]);
        assert!(o.status.success(), "{name}: {}", stderr(&o));
        let k: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        for field in ["dims", "value_range", "scalar_type"] {
            assert_eq!(j[field], k[field], "{name}: {field}");
        }
        // NIfTI-1 stores the geometry as float32 (a note says so): equal to its rounding there,
        // exactly equal in the other formats, which then render to the same bytes.
        let nifti = name.contains(".nii");
        for field in ["spacing", "origin", "direction"] {
            let flat = |v: &serde_json::Value| -> Vec<f64> {
                let s = v.to_string().replace(['[', ']'], "");
                s.split(',').map(|x| x.parse().unwrap()).collect()
            };
            let (a, b) = (flat(&j[field]), flat(&k[field]));
            assert_eq!(a.len(), b.len(), "{name}: {field}");
            for (x, y) in a.iter().zip(&b) {
                let tol = if nifti { 1e-6 * x.abs().max(1.0) } else { 0.0 };
                assert!((x - y).abs() <= tol, "{name}: {field} {a:?} vs {b:?}");
            }
        }
        if !nifti {
            assert_eq!(original, render(&conv, &format!("{name}.png")), "{name}");
        }
    }
    let o = volsplat(&["convert", vol.to_str().unwrap(), "-o", "/tmp/x.png"]);
    assert_eq!(o.status.code(), Some(1));
}

/// `--view` starts from an anatomical view (the camera maths is tested in core): anterior differs
/// from the default view, `A` spells the same view, and a bad side is a usage error.
#[test]
fn anatomical_views_are_flags() {
    let dir = tempfile::tempdir().unwrap();
    let run = |extra: &[&str], name: &str| {
        let out = dir.path().join(name);
        let mut args = vec![
            "render",
            "--phantom",
            "blobs",
            "--phantom-size",
            "20",
            "--size",
            "24",
            "-q",
        ];
        args.extend_from_slice(extra);
        args.extend_from_slice(&["-o", out.to_str().unwrap()]);
        let o = volsplat(&args);
        assert!(o.status.success(), "{}", stderr(&o));
        std::fs::read(out).unwrap()
    };
    let default = run(&[], "d.png");
    let anterior = run(&["--view", "anterior"], "a.png");
    assert_ne!(default, anterior);
    // The one-letter spelling is the same view.
    assert_eq!(run(&["--view", "A"], "a2.png"), anterior);
    let o = volsplat(&["render", "--view", "sideways", "-o", "/tmp/x.png"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("anterior"), "{}", stderr(&o));
}

/// `bench` reports the process's peak memory, which holds at least the volume (Linux).
#[cfg(target_os = "linux")]
#[test]
fn bench_reports_peak_memory() {
    let o = volsplat(&[
        "bench",
        "--phantom",
        "blobs",
        "--phantom-size",
        "64",
        "--size",
        "32",
        "--frames",
        "1",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let kb = j["peak_rss_kb"].as_u64().unwrap();
    let volume = j["volume_bytes"].as_u64().unwrap();
    assert!(kb * 1024 >= volume, "{kb} KiB for a {volume}-byte volume");
}

/// `--renderer auto` (the default) lets the engine choose among the splatting renderers;
/// `splat`, its earlier name, is the same choice and the same bytes.
#[test]
fn renderer_auto_and_its_earlier_name() {
    let dir = tempfile::tempdir().unwrap();
    let run = |name: &str| {
        let out = dir.path().join(format!("{name}.npy"));
        let o = volsplat(&[
            "render",
            "--phantom",
            "blobs",
            "--phantom-size",
            "24",
            "--size",
            "24",
            "--renderer",
            name,
            "-o",
            out.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{name}: {}", stderr(&o));
        std::fs::read(&out).unwrap()
    };
    let auto = run("auto");
    assert_eq!(auto, run("splat"));
    assert_ne!(auto, run("sabella"));
}
