//! OME-Zarr on the command line (issue 31): `convert -o X.zarr` writes a pyramid, `info` lists
//! its levels, `render` and `convert` read any level with `--zarr-level`, scene files keep the
//! choice, and wrong choices are clear errors.

use std::path::Path;

mod util;
use util::{stderr, stdout, volsplat};

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

#[test]
fn convert_writes_a_pyramid_that_info_lists_and_render_reads() {
    let dir = tempfile::tempdir().unwrap();
    let nrrd = dir.path().join("sl.nrrd");
    let o = volsplat(&[
        "phantom",
        "shepp-logan",
        "--grid",
        "40,36,30",
        "-o",
        s(&nrrd),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    for version in ["2", "3"] {
        let zarr = dir.path().join(format!("sl{version}.zarr"));
        let o = volsplat(&[
            "convert",
            s(&nrrd),
            "-o",
            s(&zarr),
            "--chunk",
            "16",
            "--zarr-version",
            version,
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        // 40×36×30 → 21×19×16 → 12×11×9 (fits one 16³ chunk: the last level).
        let said = stderr(&o);
        assert!(
            said.contains("3 levels: 40×36×30, 21×19×16, 12×11×9"),
            "{said}"
        );
        // An uncompressed NRRD is streamed slice by slice.
        assert!(said.contains("streamed slice by slice"), "{said}");
        let text = stdout(&volsplat(&["info", s(&zarr)]));
        assert!(text.contains("levels:    3"), "{text}");
        assert!(text.contains("1: 21 x 19 x 16, spacing "), "{text}");
        assert!(text.contains("chunks [16, 16, 16], float32"), "{text}");
        assert!(text.contains("dims:      40 x 36 x 30"), "{text}");
        let text = stdout(&volsplat(&["info", s(&zarr), "--zarr-level", "2"]));
        assert!(text.contains("dims:      12 x 11 x 9"), "{text}");
        let json = stdout(&volsplat(&["info", s(&zarr), "--json"]));
        let v: serde_json::Value = serde_json::from_str(&json).unwrap();
        assert_eq!(v["levels"].as_array().unwrap().len(), 3);
        assert_eq!(v["levels"][2]["dims"], serde_json::json!([12, 11, 9]));
        // Level 0 holds the NRRD's samples: converting back gives the same file content.
        let back = dir.path().join(format!("back{version}.nrrd"));
        let o = volsplat(&["convert", s(&zarr), "-o", s(&back)]);
        assert!(o.status.success(), "{}", stderr(&o));
        let a = stdout(&volsplat(&["info", s(&nrrd), "--json"]));
        let b = stdout(&volsplat(&["info", s(&back), "--json"]));
        let (a, b): (serde_json::Value, serde_json::Value) = (
            serde_json::from_str(&a).unwrap(),
            serde_json::from_str(&b).unwrap(),
        );
        for k in ["dims", "spacing", "origin", "value_range", "scalar_type"] {
            assert_eq!(a[k], b[k], "{k}");
        }
    }
    let zarr = dir.path().join("sl2.zarr");
    let png = dir.path().join("l1.png");
    let scene = dir.path().join("l1.json");
    let o = volsplat(&[
        "render",
        s(&zarr),
        "--zarr-level",
        "1",
        "--size",
        "24x24",
        "-o",
        s(&png),
        "--save-scene",
        s(&scene),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = std::fs::read_to_string(&scene).unwrap();
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(v["scene"]["volume"]["file"]["level"], 1, "{text}");
    // The scene renders the same picture again.
    let png2 = dir.path().join("l1b.png");
    let o = volsplat(&["render", "--scene", s(&scene), "-o", s(&png2)]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(std::fs::read(&png).unwrap(), std::fs::read(&png2).unwrap());
}

#[test]
fn wrong_zarr_choices_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let nrrd = dir.path().join("b.nrrd");
    let o = volsplat(&["phantom", "blobs", "--grid", "20", "-o", s(&nrrd)]);
    assert!(o.status.success(), "{}", stderr(&o));
    let zarr = dir.path().join("b.zarr");
    let o = volsplat(&["convert", s(&nrrd), "-o", s(&zarr)]);
    assert!(o.status.success(), "{}", stderr(&o));
    let x_zarr = dir.path().join("x.zarr");
    let cases: [(&[&str], &str); 6] = [
        (
            &["info", s(&zarr), "--zarr-level", "5"],
            "level 5 requested, but the store holds 1 levels",
        ),
        (
            &["info", s(&zarr), "--channel", "1"],
            "channel 1 requested, but the store holds 1",
        ),
        (
            &["info", s(&nrrd), "--zarr-level", "1"],
            "applies to OME-Zarr stores only, not to NRRD",
        ),
        (
            &["convert", s(&nrrd), "-o", "x.nrrd", "--chunk", "32"],
            "apply to .zarr outputs only",
        ),
        (
            &["convert", s(&nrrd), "-o", s(&x_zarr), "--zarr-version", "4"],
            "--zarr-version 4",
        ),
        (
            &["convert", s(&nrrd), "-o", s(&zarr), "--gzip"],
            "--gzip does not apply",
        ),
    ];
    for (args, want) in cases {
        let o = volsplat(args);
        assert!(!o.status.success(), "{args:?}");
        let e = stderr(&o);
        assert!(e.contains(want), "{args:?}: {e}");
        assert!(!e.contains("panicked"), "{e}");
    }
    // A folder that is not a store is not replaced.
    let other = dir.path().join("keep.zarr");
    std::fs::create_dir(&other).unwrap();
    std::fs::write(other.join("data.txt"), b"keep").unwrap();
    let o = volsplat(&["convert", s(&nrrd), "-o", s(&other)]);
    // Named .zarr, it looks like a store by name; a folder without Zarr metadata is refused.
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("not an OME-Zarr store"),
        "{}",
        stderr(&o)
    );
    assert_eq!(std::fs::read(other.join("data.txt")).unwrap(), b"keep");
}

/// `--zarr-level auto` (issue 31 item 5): the coarsest level whose voxel is no larger than a
/// pixel at the focal plane, per frame. A small image of the whole volume takes a coarse level,
/// a large or zoomed one the full level; the picture is the bits of the level given by number,
/// a note says which, scene files keep `"auto"`, and `info`/`convert` refuse it.
#[test]
fn zarr_level_auto_follows_the_pixel_size() {
    let dir = tempfile::tempdir().unwrap();
    let nrrd = dir.path().join("b.nrrd");
    let o = volsplat(&["phantom", "blobs", "--grid", "64,64,64", "-o", s(&nrrd)]);
    assert!(o.status.success(), "{}", stderr(&o));
    let zarr = dir.path().join("b.zarr");
    let o = volsplat(&["convert", s(&nrrd), "-o", s(&zarr), "--chunk", "16"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let render = |extra: &[&str], out: &str| {
        let path = dir.path().join(out);
        let mut args = vec!["render", s(&zarr), "-o", s(&path)];
        args.extend_from_slice(extra);
        let o = volsplat(&args);
        assert!(o.status.success(), "{extra:?}: {}", stderr(&o));
        (std::fs::read(&path).unwrap(), stderr(&o))
    };
    // 64 voxels across about 32 pixels: a pixel spans about two voxels, so level 1 (spacing 2).
    let (auto_small, said) = render(&["--zarr-level", "auto", "--size", "32"], "a.npy");
    assert!(said.contains("OME-Zarr level auto: level 1 of"), "{said}");
    let (one, _) = render(&["--zarr-level", "1", "--size", "32"], "one.npy");
    assert!(auto_small == one, "auto drew another picture than level 1");
    // 64 voxels across 256 pixels: the full level.
    let (auto_big, said) = render(&["--zarr-level", "auto", "--size", "256"], "b.npy");
    assert!(said.contains("OME-Zarr level auto: level 0 of"), "{said}");
    let (zero, _) = render(&["--size", "256"], "zero.npy");
    assert!(auto_big == zero, "auto drew another picture than level 0");
    // Zoomed in 4× at 32 pixels: finer than without the zoom.
    let (_, said) = render(
        &["--zarr-level", "auto", "--size", "32", "--zoom", "4"],
        "z.npy",
    );
    assert!(said.contains("OME-Zarr level auto: level 0 of"), "{said}");
    // Scene files keep the choice, not the level it resolved to.
    let scene = dir.path().join("s.json");
    render(
        &[
            "--zarr-level",
            "auto",
            "--size",
            "32",
            "--save-scene",
            s(&scene),
        ],
        "s.npy",
    );
    let text = std::fs::read_to_string(&scene).unwrap();
    assert!(text.contains("\"level\": \"auto\""), "{text}");
    let again = dir.path().join("again.npy");
    let o = volsplat(&["render", "--scene", s(&scene), "-o", s(&again)]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("OME-Zarr level auto: level 1 of"),
        "{}",
        stderr(&o)
    );
    assert!(
        std::fs::read(&again).unwrap() == one,
        "the scene file drew another picture"
    );
    // No camera: a clear refusal.
    let o = volsplat(&["info", s(&zarr), "--zarr-level", "auto"]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("--zarr-level auto is chosen from the camera"),
        "{}",
        stderr(&o)
    );
    let o = volsplat(&[
        "render",
        s(&nrrd),
        "--zarr-level",
        "auto",
        "-o",
        s(&dir.path().join("n.png")),
    ]);
    assert!(!o.status.success(), "level auto on an NRRD file");
}

/// `info --memory SIZE` of a store summarises the level from its metadata and a bounded ranges
/// scan (what `volsplat info` does by itself for a level larger than half the available
/// memory, which it must never read whole): the same dims, geometry, type, range and levels
/// as the level read whole, a note saying so, and the ranges kept for the next open (in the
/// test's own cache folder).
#[test]
fn info_of_a_store_out_of_core_reads_no_level_whole_and_agrees_with_the_whole_read() {
    let dir = tempfile::tempdir().unwrap();
    let nrrd = dir.path().join("h.nrrd");
    let o = volsplat(&["phantom", "head", "--grid", "70,60,50", "-o", s(&nrrd)]);
    assert!(o.status.success(), "{}", stderr(&o));
    let zarr = dir.path().join("h.zarr");
    let o = volsplat(&["convert", s(&nrrd), "-o", s(&zarr), "--chunk", "32"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let cache = dir.path().join("cache");
    let info = |extra: &[&str]| -> serde_json::Value {
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_volsplat"))
            .args(["info", s(&zarr), "--json"])
            .args(extra)
            .env("VOLSPLAT_CACHE_DIR", &cache)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", stderr(&o));
        serde_json::from_str(&stdout(&o)).unwrap()
    };
    let whole = info(&[]);
    let paged = info(&["--memory", "4MiB"]);
    for k in [
        "dims",
        "voxels",
        "scalar_type",
        "spacing",
        "origin",
        "direction",
        "bounds",
        "value_range",
        "frames",
        "levels",
        "format",
    ] {
        assert_eq!(whole[k], paged[k], "{k}");
    }
    let notes = paged["notes"].to_string();
    assert!(notes.contains("not read whole"), "{notes}");
    assert!(notes.contains("kept in"), "{notes}");
    assert!(!whole["notes"].to_string().contains("out of core"));
    // The next open finds the ranges kept.
    let again = info(&["--memory", "4MiB"]);
    assert!(
        again["notes"]
            .to_string()
            .contains("kept from an earlier open"),
        "{}",
        again["notes"]
    );
    assert_eq!(again["value_range"], whole["value_range"]);
    // A bad size is refused by name.
    let o = volsplat(&["info", s(&zarr), "--memory", "lots"]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("--memory"), "{}", stderr(&o));
}
