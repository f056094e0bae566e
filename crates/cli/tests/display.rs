//! `render --renderer sabella|nil` end to end on a small phantom.

use std::process::Command;

fn volsplat() -> Command {
    Command::new(env!("CARGO_BIN_EXE_volsplat"))
}

#[test]
fn sabella_and_nil_renders_write_images_and_stats() {
    let dir = tempfile::tempdir().unwrap();
    for (renderer, extra) in [
        ("sabella", vec!["--supersample", "2"]),
        ("nil", vec!["--display", "linearised", "--density", "data"]),
        (
            "nil",
            vec![
                "--display",
                "linearised",
                "--density",
                "data",
                "--control-points",
                "interpolate",
                "--patch-order",
                "3",
            ],
        ),
        (
            "nil",
            vec!["--display", "slice", "--direct", "--density", "data"],
        ),
        (
            "nil",
            vec![
                "--display",
                "sample-filter",
                "--density",
                "data",
                "--rho0",
                "0.3",
            ],
        ),
    ] {
        let out = dir.path().join(format!("{renderer}.png"));
        let o = volsplat()
            .args([
                "render",
                "--phantom",
                "blobs",
                "--phantom-size",
                "16",
                "--size",
                "24x20",
            ])
            .args(["--renderer", renderer, "--stats", "-o"])
            .arg(&out)
            .args(&extra)
            .output()
            .unwrap();
        assert!(
            o.status.success(),
            "{renderer} {extra:?}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        assert!(std::fs::metadata(&out).unwrap().len() > 50);
        let all: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        assert_eq!(all["renderer"], renderer);
        let stats = &all["display"];
        assert_eq!(stats["pixels"], 480);
        assert!(stats["rays"].as_u64().unwrap() > 0);
        if renderer == "nil" && !extra.contains(&"--direct") {
            assert!(stats["patches"].as_u64().unwrap() > 0, "{extra:?}");
            // Projected control points never fall back (decision 0007).
            if !extra.contains(&"interpolate") {
                assert_eq!(stats["fallbacks"], 0, "{extra:?}");
            }
        }
    }
}

#[test]
fn bad_display_options_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("x.png");
    for bad in [
        ["--tau", "-1"],
        ["--patch-order", "7"],
        ["--density", "foo"],
        ["--control-points", "guess"],
        ["--trigger-width", "0"],
        ["--max-cell-width", "-1"],
        ["--attenuation", "linear"],
    ] {
        let o = volsplat()
            .args([
                "render",
                "--phantom",
                "blobs",
                "--phantom-size",
                "8",
                "--size",
                "8x8",
            ])
            .args(["--renderer", "nil", "-o"])
            .arg(&out)
            .args(bad)
            .output()
            .unwrap();
        assert!(!o.status.success(), "{bad:?}");
        assert!(
            !String::from_utf8_lossy(&o.stderr).contains("panicked"),
            "{bad:?}"
        );
    }
}

/// The NIL display's settings of decision 0027 are flags: eq 6.1 as printed (`--attenuation
/// unit-density`) is darker than Sabella's own attenuation on the blobs, whose box holds empty
/// space; `--continuous-patches=false` and `--max-cell-width 0` change the picture; the defaults
/// equal the flags spelt out.
#[test]
fn nil_display_settings_are_flags() {
    let dir = tempfile::tempdir().unwrap();
    let render = |name: &str, extra: &[&str]| -> Vec<f32> {
        let out = dir.path().join(format!("{name}.npy"));
        let o = volsplat()
            .args([
                "render",
                "--phantom",
                "blobs",
                "--phantom-size",
                "32",
                "--size",
                "48",
                "--renderer",
                "nil",
                "-q",
                "-o",
            ])
            .arg(&out)
            .args(extra)
            .output()
            .unwrap();
        assert!(
            o.status.success(),
            "{extra:?}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        let bytes = std::fs::read(&out).unwrap();
        // .npy: a header whose length is at bytes 8..10, then little-endian f32 RGBA.
        let start = 10 + u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
        bytes[start..]
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect()
    };
    let sum = |v: &[f32]| v.iter().map(|&x| x as f64).sum::<f64>();
    let default = render("default", &[]);
    let spelt = render(
        "spelt",
        &[
            "--attenuation",
            "optical-depth",
            "--continuous-patches",
            "--max-cell-width",
            "1.5",
        ],
    );
    assert_eq!(default, spelt);
    let unit = render("unit", &["--attenuation", "unit-density"]);
    assert!(
        sum(&unit) < 0.97 * sum(&default),
        "{} vs {}",
        sum(&unit),
        sum(&default)
    );
    assert_ne!(default, render("cells", &["--continuous-patches=false"]));
    // The cap splits cells that coarse triggers leave wide.
    assert_ne!(
        render("coarse", &["--trigger-steps", "4"]),
        render("nocap", &["--trigger-steps", "4", "--max-cell-width", "0"])
    );
}
