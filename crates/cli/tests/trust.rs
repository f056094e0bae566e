//! Issue 28, "Trust": inputs a user types and outputs a user expects. A full stderr never loses
//! the image; crafted counts and colours are clear errors; ignored options and mode changes are
//! said; the help tells the truth.

use std::path::Path;
use std::process::{Command, Output, Stdio};

mod util;
use util::{npy_f32, stderr, stdout, volsplat};

/// A tiny scene: 16³ blobs, 16 × 16 pixels.
const TINY: [&str; 6] = ["--phantom", "blobs", "--phantom-size", "16", "--size", "16"];

fn render(extra: &[&str], out: &Path) -> Output {
    let mut args = vec!["render"];
    args.extend_from_slice(&TINY);
    args.extend_from_slice(extra);
    args.extend_from_slice(&["-o", out.to_str().unwrap()]);
    volsplat(&args)
}

/// Runs `args` with stderr (or stdout) going to `/dev/full`, which refuses every write.
#[cfg(target_os = "linux")]
fn with_full(args: &[&str], full_stdout: bool) -> Output {
    let full = || {
        Stdio::from(
            std::fs::OpenOptions::new()
                .write(true)
                .open("/dev/full")
                .unwrap(),
        )
    };
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_volsplat"));
    cmd.args(args);
    if full_stdout {
        cmd.stdout(full()).stderr(Stdio::piped());
    } else {
        cmd.stderr(full()).stdout(Stdio::piped());
    }
    cmd.output().unwrap()
}

/// Issue 28: `render … 2>/dev/full` panicked at the first note and wrote no image. Notes,
/// warnings and errors are written ignoring errors; `--stats` JSON that cannot be written is an
/// error, after the image.
#[cfg(target_os = "linux")]
#[test]
fn a_full_stderr_loses_no_output() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("a.png");
    let o = out.to_str().unwrap();
    // `auto` on blobs prints a note; --light with MIP a warning.
    let mut args = vec!["render"];
    args.extend_from_slice(&TINY);
    args.extend_from_slice(&["--mode", "mip", "--light", "1,0,0", "-o", o]);
    let r = with_full(&args, false);
    assert_eq!(r.status.code(), Some(0));
    assert!(out.exists());
    std::fs::remove_file(&out).unwrap();
    // An error still exits 1, not with a panic's 101.
    let r = with_full(&["render", "--size", "0", "-o", o], false);
    assert_eq!(r.status.code(), Some(1));
    // A movie, with its notes and what it wrote.
    let frames = dir.path().join("frames");
    let mut args = vec!["movie"];
    args.extend_from_slice(&TINY);
    args.extend_from_slice(&["--frames", "2", "-o", frames.to_str().unwrap()]);
    let r = with_full(&args, false);
    assert_eq!(r.status.code(), Some(0));
    assert!(frames.join("frame_0001.png").exists());
    // stdout full: the image is written, then the JSON fails with a clear error.
    let mut args = vec!["render"];
    args.extend_from_slice(&TINY);
    args.extend_from_slice(&["--stats", "-q", "-o", o]);
    let r = with_full(&args, true);
    assert_eq!(r.status.code(), Some(1), "{}", stderr(&r));
    assert!(stderr(&r).contains("standard output"), "{}", stderr(&r));
    assert!(out.exists());
}

/// Issue 28: `--background nan,0,0` wrote red as 0 and `2,2,2` was accepted.
#[test]
fn backgrounds_outside_zero_to_one_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("a.png");
    for (bg, word) in [
        ("nan,0,0", "red is NaN"),
        ("2,2,2", "red is 2"),
        ("0,-1,0", "green is -1"),
        ("0,0,inf", "blue is inf"),
    ] {
        let o = render(&["--background", bg], &out);
        assert_eq!(o.status.code(), Some(1), "{bg}");
        assert!(
            stderr(&o).contains(word) && stderr(&o).contains("[0, 1]"),
            "{bg}: {}",
            stderr(&o)
        );
        assert!(!out.exists());
        let mut args = vec!["movie"];
        args.extend_from_slice(&TINY);
        let gif = dir.path().join("m.gif");
        args.extend_from_slice(&["--background", bg, "-o", gif.to_str().unwrap()]);
        let o = volsplat(&args);
        assert_eq!(o.status.code(), Some(1), "{bg}");
        assert!(!gif.exists());
    }
    assert!(
        render(&["--background", "0.2,0.5,1"], &out)
            .status
            .success()
    );
}

/// Issue 28: 10 000 lights took 10–14 s for a 16 × 16 image, 100 000 clipping planes 15 s;
/// both are capped (16 and 64) with a clear error, from flags and from scene files.
#[test]
fn lights_and_clipping_planes_are_capped() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("a.png");
    let lights: Vec<&str> = std::iter::repeat_n(["--light", "0,0,1"], 17)
        .flatten()
        .collect();
    let o = render(&lights, &out);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("--light") && stderr(&o).contains("17 lights; at most 16"),
        "{}",
        stderr(&o)
    );
    assert!(render(&lights[2..], &out).status.success());
    let planes: Vec<&str> = std::iter::repeat_n(["--clip-plane", "0,0,1,100"], 65)
        .flatten()
        .collect();
    let o = render(&planes, &out);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("--clip-plane") && stderr(&o).contains("at most 64"),
        "{}",
        stderr(&o)
    );
    // A scene file with 100 000 lights is refused at once.
    let scene = dir.path().join("s.json");
    let many = vec![r#"{"direction": [0, 0, 1]}"#; 100_000].join(",");
    std::fs::write(
        &scene,
        format!(
            r#"{{ "width": 16, "height": 16, "scene": {{ "volume": {{ "phantom": {{
                 "phantom": "blobs", "grid": [16] }} }}, "lights": [{many}] }} }}"#
        ),
    )
    .unwrap();
    let t0 = std::time::Instant::now();
    let o = volsplat(&[
        "render",
        "--scene",
        scene.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("100000 lights"), "{}", stderr(&o));
    // Not a timing test: a guard that nothing was rendered with them (that took > 20 s).
    assert!(t0.elapsed().as_secs() < 20);
}

/// Issue 28: flags the mode ignores changed no bit and said nothing; each is named with its
/// flag. Options the mode uses are not.
#[test]
fn options_the_mode_ignores_are_warned() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("a.png");
    let o = render(
        &[
            "--mode",
            "xray",
            "--preset",
            "ct-bone",
            "--light",
            "1,0,0",
            "--surface-enhance",
            "0:1",
            "--depth-cue",
            "1:0.5",
        ],
        &out,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let e = stderr(&o);
    for flag in [
        "--tf/--preset",
        "--light",
        "--surface-enhance",
        "--depth-cue",
    ] {
        assert!(
            e.contains(&format!("warning: {flag} (")) && e.contains("ignored by --mode xray"),
            "{flag}: {e}"
        );
    }
    let o = render(
        &["--mode", "mip", "--light", "1,0,0", "--preset", "ct-bone"],
        &out,
    );
    let e = stderr(&o);
    assert!(
        e.contains("warning: --light (scene.lights) is ignored by --mode mip"),
        "{e}"
    );
    assert!(!e.contains("--tf/--preset"), "{e}");
    let o = render(&["--light", "1,0,0", "--depth-cue", "1:0.5"], &out);
    assert!(!stderr(&o).contains("warning"), "{}", stderr(&o));
}

/// Issue 28: `--scene mip.json --mode composite` kept the MIP's grey function (a flat grey
/// picture). The new mode takes its default, with a note, and is the picture `render` gives for
/// composite directly; a transfer-function flag is kept.
#[test]
fn a_mode_change_over_a_scene_takes_the_modes_default() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("mip.json");
    let mip = dir.path().join("mip.png");
    let o = render(
        &[
            "--mode",
            "mip",
            "--azimuth",
            "30",
            "--save-scene",
            scene.to_str().unwrap(),
        ],
        &mip,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let again = dir.path().join("again.png");
    let o = volsplat(&[
        "render",
        "--scene",
        scene.to_str().unwrap(),
        "--mode",
        "composite",
        "-o",
        again.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains(
            "note: --mode composite: the scene's transfer function was made for mode mip"
        ),
        "{}",
        stderr(&o)
    );
    let direct = dir.path().join("direct.png");
    assert!(render(&["--azimuth", "30"], &direct).status.success());
    assert_eq!(
        std::fs::read(&again).unwrap(),
        std::fs::read(&direct).unwrap()
    );
    // With a preset given, the preset is used and nothing is said.
    let o = volsplat(&[
        "render",
        "--scene",
        scene.to_str().unwrap(),
        "--mode",
        "composite",
        "--preset",
        "ramp",
        "-o",
        again.to_str().unwrap(),
    ]);
    assert!(
        o.status.success() && !stderr(&o).contains("note: --mode"),
        "{}",
        stderr(&o)
    );
}

/// Issue 28: help that is no longer true (the demo is an MRI; `auto` draws perspective with
/// slabs; rustdoc link syntax leaked into `phantom --help`).
#[test]
fn the_help_tells_the_truth() {
    let mut all = String::new();
    for cmd in [
        "render",
        "movie",
        "info",
        "presets",
        "convert",
        "phantom",
        "bench",
        "texture-bench",
        "display-bench",
        "aa-figures",
    ] {
        all += &stdout(&volsplat(&[cmd, "--help"]));
    }
    all += &stdout(&volsplat(&["--help"]));
    for stale in [
        "[crate::",
        "demo phantom",
        "for the demo head",
        "Implies the splat-list",
        "Always on for perspective",
        "\"Movies\"",
    ] {
        assert!(!all.contains(stale), "the help still says {stale:?}");
    }
    let phantom = stdout(&volsplat(&["phantom", "--help"]));
    assert!(
        phantom.contains("brain:") && phantom.contains("VolPack"),
        "{phantom}"
    );
}

/// Issue 28: a missing file's path was printed twice; an unknown extension advised a library
/// call.
#[test]
fn read_errors_name_the_file_once_and_point_to_flags() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("a.png");
    let missing = dir.path().join("nowhere.nrrd");
    let o = volsplat(&[
        "render",
        missing.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(1));
    let e = stderr(&o);
    assert_eq!(e.matches("nowhere.nrrd").count(), 1, "{e}");
    let odd = dir.path().join("scan.foo");
    std::fs::write(&odd, [0u8; 64]).unwrap();
    let o = volsplat(&["render", odd.to_str().unwrap(), "-o", out.to_str().unwrap()]);
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(1));
    assert!(e.contains("--raw-dims") && !e.contains("RawSpec"), "{e}");
    assert_eq!(e.matches("scan.foo").count(), 1, "{e}");
}

/// A 4 × 4 × 2 NIfTI-1 file (u8) whose units are metres, which the reader notes.
fn nifti_in_metres(path: &Path) {
    let mut h = vec![0u8; 352];
    h[0..4].copy_from_slice(&348i32.to_le_bytes());
    for (i, d) in [3i16, 4, 4, 2, 1, 1, 1, 1].iter().enumerate() {
        h[40 + 2 * i..42 + 2 * i].copy_from_slice(&d.to_le_bytes());
    }
    h[70..72].copy_from_slice(&2i16.to_le_bytes()); // DT_UINT8
    h[72..74].copy_from_slice(&8i16.to_le_bytes()); // bitpix
    for i in 0..4 {
        h[76 + 4 * i..80 + 4 * i].copy_from_slice(&1f32.to_le_bytes());
    }
    h[108..112].copy_from_slice(&352f32.to_le_bytes()); // vox_offset
    h[123] = 1; // xyzt_units: metres
    h[344..348].copy_from_slice(b"n+1\0");
    h.extend((0..32u8).collect::<Vec<_>>());
    std::fs::write(path, h).unwrap();
}

/// Issue 28: `info` printed the reader's notes before `source:`; they come after the fields.
#[test]
fn info_prints_the_notes_last() {
    let dir = tempfile::tempdir().unwrap();
    let nii = dir.path().join("m.nii");
    nifti_in_metres(&nii);
    let o = volsplat(&["info", nii.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = stdout(&o);
    let lines: Vec<&str> = text.lines().collect();
    assert!(lines[0].starts_with("source:"), "{text}");
    let first_note = lines
        .iter()
        .position(|l| l.starts_with("note:"))
        .expect("a note");
    assert!(
        lines[first_note..].iter().all(|l| l.starts_with("note:")),
        "{text}"
    );
    assert!(text.contains("metres"), "{text}");
}

/// A negative number after a flag that takes a number is that flag's value, refused with the
/// flag's own message (not clap's advice to write `-- -1`, which would make it the input file).
#[test]
fn negative_values_are_the_flags_values() {
    for (args, want) in [
        (
            &["--zoom", "-1"][..],
            "--zoom: -1.0 must be a positive number",
        ),
        (
            &["--dolly", "-2"][..],
            "--dolly: -2.0 must be a positive number",
        ),
        (&["--size", "-5"][..], "--size: expected WxH"),
    ] {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("x.png");
        let mut all = vec!["render", "-o", out.to_str().unwrap()];
        all.extend_from_slice(args);
        let o = volsplat(&all);
        assert!(
            matches!(o.status.code(), Some(1 | 2)),
            "{args:?}: {}",
            stderr(&o)
        );
        assert!(stderr(&o).contains(want), "{args:?}: {}", stderr(&o));
        assert!(!out.exists());
    }
}

/// PNG options with a `.npy` output change nothing in the file: said, not silently dropped.
#[test]
fn png_options_with_npy_output_are_warned() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("x.npy");
    let path = out.to_str().unwrap();
    let o = volsplat(&[
        "render",
        "-o",
        path,
        "--size",
        "16",
        "--bit-depth",
        "16",
        "--srgb",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("warning: --bit-depth, --srgb only apply to PNG output"),
        "{}",
        stderr(&o)
    );
    let o = volsplat(&["render", "-o", path, "--size", "16"]);
    assert!(!stderr(&o).contains("only apply to PNG"), "{}", stderr(&o));
}

/// A transfer function's `ambient` multiplies the lights' ambient colour, black for VTK's
/// default headlight (so the emission term of a shaded render is nothing, as in VTK's CPU ray
/// caster); a light given with an ambient colour lights it, in the scene file too, and
/// `--no-emission` takes it away again.
#[test]
fn a_lights_ambient_colour_lights_the_ambient_term() {
    let dir = tempfile::tempdir().unwrap();
    let run = |name: &str, extra: &[&str]| {
        let out = dir.path().join(format!("{name}.npy"));
        let mut args = vec!["render", "-o", out.to_str().unwrap(), "--size", "32"];
        args.extend_from_slice(&["--no-diffuse", "--no-specular"]);
        args.extend_from_slice(extra);
        let o = volsplat(&args);
        assert!(o.status.success(), "{}", stderr(&o));
        // The brightest colour channel (the image is premultiplied RGBA).
        npy_f32(&out)
            .chunks_exact(4)
            .flat_map(|px| px[..3].to_vec())
            .fold(0.0f32, f32::max)
    };
    let ambient_light = ["--light", "0,0,1,1,1,1,1,1,1"];
    let dark = run("default", &[]);
    let lit = run("ambient", &ambient_light);
    let off = run("off", &[&ambient_light[..], &["--no-emission"]].concat());
    assert!(dark < 0.02, "{dark}");
    assert!(lit > 0.1 && lit > 10.0 * dark, "{lit} against {dark}");
    assert!(off < 0.02, "{off}");
    let scene = dir.path().join("s.json");
    let png = dir.path().join("s.png");
    let o = volsplat(&[
        "render",
        "-o",
        png.to_str().unwrap(),
        "--size",
        "16",
        "--light",
        "0,0,1,1,1,1,0.5,0.5,0.5",
        "--save-scene",
        scene.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = std::fs::read_to_string(&scene).unwrap();
    assert!(text.contains("\"ambient\""), "{text}");
    let o = volsplat(&[
        "render",
        "-o",
        png.to_str().unwrap(),
        "--size",
        "16",
        "--light",
        "0,0,1,1,1,1,1,1",
    ]);
    assert!(
        stderr(&o).contains("X,Y,Z,R,G,B,AR,AG,AB"),
        "{}",
        stderr(&o)
    );
}

/// An X-ray of data that is negative everywhere (not CT: no DRR offset applies) is black by
/// its scaling; a note says why and what to give instead.
#[test]
fn a_black_xray_says_why() {
    let dir = tempfile::tempdir().unwrap();
    let raw = dir.path().join("neg.raw");
    let bytes: Vec<u8> = std::iter::repeat_n((-500i16).to_le_bytes(), 512)
        .flatten()
        .collect();
    std::fs::write(&raw, bytes).unwrap();
    let out = dir.path().join("x.png");
    let common = [
        "render",
        raw.to_str().unwrap(),
        "--raw-dims",
        "8,8,8",
        "--raw-type",
        "i16",
        "--mode",
        "xray",
        "--size",
        "16",
        "-o",
        out.to_str().unwrap(),
    ];
    let o = volsplat(&common);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("every line integral is ≤ 0"),
        "{}",
        stderr(&o)
    );
    let o = volsplat(&[&common[..], &["--xray-offset", "1000"]].concat());
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        !stderr(&o).contains("every line integral"),
        "{}",
        stderr(&o)
    );
}
