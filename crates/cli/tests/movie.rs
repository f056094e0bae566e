//! `volsplat movie`: turntables and keyframed flights through one renderer, written as PNG
//! frames, GIF, APNG or video.

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

const SCENE: [&str; 8] = [
    "--phantom-size",
    "32",
    "--size",
    "40x32",
    "--elevation",
    "20",
    "--azimuth",
    "10",
];

fn run(cmd: &str, extra: &[&str], out: &Path) -> Output {
    let mut args = vec![cmd];
    args.extend_from_slice(&SCENE);
    args.extend_from_slice(extra);
    args.extend_from_slice(&["-q", "-o", out.to_str().unwrap()]);
    volsplat(&args)
}

fn gif_frames(path: &Path) -> Vec<Vec<u8>> {
    let mut opts = gif::DecodeOptions::new();
    opts.set_color_output(gif::ColorOutput::RGBA);
    let mut dec = opts.read_info(std::fs::File::open(path).unwrap()).unwrap();
    let mut frames = Vec::new();
    while let Some(f) = dec.read_next_frame().unwrap() {
        frames.push(f.buffer.to_vec());
    }
    frames
}

/// Frame 0 of a turntable is the image `render` writes for the same flags, bit for bit; the
/// frames differ from one another; a GIF holds the requested number of frames.
#[test]
fn a_turntable_starts_at_the_render_and_holds_every_frame() {
    let dir = tempfile::tempdir().unwrap();
    let still = dir.path().join("still.png");
    let o = run("render", &[], &still);
    assert!(o.status.success(), "{}", stderr(&o));
    let folder = dir.path().join("frames");
    let o = run("movie", &["--frames", "4"], &folder);
    assert!(o.status.success(), "{}", stderr(&o));
    let f0 = std::fs::read(folder.join("frame_0000.png")).unwrap();
    assert_eq!(f0, std::fs::read(&still).unwrap());
    let f1 = std::fs::read(folder.join("frame_0001.png")).unwrap();
    assert_ne!(f0, f1);
    assert!(folder.join("frame_0003.png").exists() && !folder.join("frame_0004.png").exists());

    let gif = dir.path().join("t.gif");
    let o = run("movie", &["--frames", "6", "--axis", "S", "--stats"], &gif);
    assert!(o.status.success(), "{}", stderr(&o));
    let frames = gif_frames(&gif);
    assert_eq!(frames.len(), 6);
    assert!(frames.windows(2).all(|w| w[0] != w[1]));
    let stats: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(stats["frames"], 6);
    assert_eq!(stats["frames_ms"].as_array().unwrap().len(), 6);
}

/// A keyframed flight: fps × duration + 1 frames; its first frame is the render of the first
/// keyframe's camera; a bad keyframe file names the field.
#[test]
fn a_keyframe_flight_has_its_frames_and_bad_files_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let keys = dir.path().join("keys.json");
    std::fs::write(
        &keys,
        r#"{ "keyframes": [ { "time": 0 },
                            { "time": 0.5, "orbit": { "azimuth": 60, "zoom": 1.4 } },
                            { "time": 1.0, "orbit": { "azimuth": 120, "elevation": 30 } } ] }"#,
    )
    .unwrap();
    let out = dir.path().join("f_%02d.png");
    let o = run(
        "movie",
        &["--keyframes", keys.to_str().unwrap(), "--fps", "8"],
        &out,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let still = dir.path().join("still.png");
    assert!(run("render", &[], &still).status.success());
    assert_eq!(
        std::fs::read(dir.path().join("f_00.png")).unwrap(),
        std::fs::read(&still).unwrap()
    );
    assert!(dir.path().join("f_08.png").exists() && !dir.path().join("f_09.png").exists());

    let apng = dir.path().join("f.png");
    let o = run(
        "movie",
        &["--keyframes", keys.to_str().unwrap(), "--fps", "4"],
        &apng,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let reader = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(&apng).unwrap()))
        .read_info()
        .unwrap();
    assert_eq!(reader.info().animation_control.unwrap().num_frames, 5);

    std::fs::write(
        &keys,
        r#"{ "keyframes": [ { "time": 0 }, { "time": 0 } ] }"#,
    )
    .unwrap();
    let o = run("movie", &["--keyframes", keys.to_str().unwrap()], &apng);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("keyframes[1].time"), "{}", stderr(&o));
}

/// Video output without ffmpeg on PATH: exit 1 naming ffmpeg, before any rendering, and no file.
#[test]
fn video_without_ffmpeg_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("m.mp4");
    let mut args = vec!["movie"];
    args.extend_from_slice(&SCENE);
    args.extend_from_slice(&["--frames", "2", "-o", out.to_str().unwrap()]);
    let o = Command::new(env!("CARGO_BIN_EXE_volsplat"))
        .args(&args)
        .env("PATH", dir.path())
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    let e = stderr(&o);
    assert!(e.contains("ffmpeg") && e.contains("PATH"), "{e}");
    assert!(!out.exists());
}

/// Keyframes move clipping planes: a plane that keeps everything at t = 0 and nothing at t = 1
/// gives the plain render first and an empty frame last; keyframes whose clippings differ in
/// kind are refused before rendering, naming the keyframe.
#[test]
fn keyframes_move_clipping_planes() {
    let dir = tempfile::tempdir().unwrap();
    let keys = dir.path().join("keys.json");
    std::fs::write(
        &keys,
        r#"{ "keyframes": [
              { "time": 0, "clipping": { "planes": [ { "normal": [1, 0, 0], "offset": 1000 } ] } },
              { "time": 1, "clipping": { "planes": [ { "normal": [1, 0, 0], "offset": -1000 } ] } } ] }"#,
    )
    .unwrap();
    let out = dir.path().join("c_%d.png");
    let o = run(
        "movie",
        &["--keyframes", keys.to_str().unwrap(), "--fps", "2"],
        &out,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let still = dir.path().join("still.png");
    assert!(run("render", &[], &still).status.success());
    assert_eq!(
        std::fs::read(dir.path().join("c_0.png")).unwrap(),
        std::fs::read(&still).unwrap()
    );
    let last = png::Decoder::new(std::io::BufReader::new(
        std::fs::File::open(dir.path().join("c_2.png")).unwrap(),
    ));
    let mut reader = last.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    reader.next_frame(&mut buf).unwrap();
    assert!(buf.iter().all(|&b| b == 0), "the last frame keeps nothing");

    std::fs::write(
        &keys,
        r#"{ "keyframes": [ { "time": 0 },
              { "time": 1, "clipping": { "planes": [ { "normal": [1, 0, 0], "offset": 0 } ] } } ] }"#,
    )
    .unwrap();
    let o = run("movie", &["--keyframes", keys.to_str().unwrap()], &out);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("keyframes[1].clipping"),
        "{}",
        stderr(&o)
    );
}
