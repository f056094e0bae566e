//! Bit-for-bit regression of the `render` command: small scenes whose output hashes were
//! recorded before the engine facade (issue 11) moved rendering out of the binary, after the
//! every-angle fix (issue 17) had been checked against the reference integrators and VTK. A
//! change of any hash means the same flags now draw a different picture: either a bug, or an
//! intended change of the algorithm, which must then be justified and the hash re-recorded
//! (`VOLSPLAT_PRINT_HASHES=1 cargo test -p volsplat-cli --test golden -- --nocapture` prints the
//! current ones).

use std::process::Command;

/// 64-bit FNV-1a: small, stable across Rust versions (unlike `DefaultHasher`).
fn fnv1a(bytes: &[u8]) -> u64 {
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    for &b in bytes {
        h ^= b as u64;
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

/// (name, arguments before `-o`, output extension, recorded hash).
const CASES: &[(&str, &[&str], &str, u64)] = &[
    (
        "demo head, composite",
        &[
            // Westover's sheets, which `auto` drew for shaded composite before decision 0019.
            "--visibility",
            "sheet",
            // The early-termination cutoff these hashes were recorded with (the default before
            // decision 0018 made it VTK's level): 1 − 2⁻²⁰.
            "--opacity-cutoff",
            "0.99999905",
            // Swan's rule, the default anti-aliasing before decision 0006's 2026-11-24 amendment.
            "--antialias",
            "swan",
            "--phantom-size",
            "40",
            "--size",
            "48x40",
            "--azimuth",
            "30",
            "--elevation",
            "15",
        ],
        "npy",
        // Re-recorded 2026-11-25: the sheets shade through the slab kernel's table
        // (`slab::shaded_src`) instead of the per-voxel classifier: 104.5 dB from the old
        // picture, largest difference 2.5e-4.
        0xd461e8d65e33f858,
    ),
    (
        // The default since decision 0006's 2026-11-24 amendment: the `area` rule.
        "demo head, area anti-aliasing",
        &[
            // Westover's sheets (the `area` rule is theirs), which `auto` drew for shaded
            // composite before decision 0019.
            "--visibility",
            "sheet",
            "--phantom-size",
            "40",
            "--size",
            "48x40",
            "--azimuth",
            "30",
            "--elevation",
            "15",
        ],
        "npy",
        // Re-recorded 2026-11-25 for decision 0018 (early termination at VTK's 0.99 by
        // default): 95.0 dB from the picture at 1 − 2⁻²⁰, largest difference 7.8e-4, on 4.7 %
        // of the pixels; and again for the sheets' shading through the slab kernel's table:
        // 101.6 dB from that, largest difference 3.4e-4; and again when the cutoff became VTK's
        // exact 1 − 255/32767 (decision 0018's amendment): 95.2 dB from the picture at 0.99,
        // largest difference 7.8e-4, on 1.9 % of the pixels.
        0xb53f1e38f9552d74,
    ),
    (
        // sRGB-encoded, the default before decision 0012 made PNGs linear.
        "demo head, PNG --srgb",
        &[
            // Westover's sheets, which `auto` drew for shaded composite before decision 0019.
            "--visibility",
            "sheet",
            // Swan's rule, the default anti-aliasing before decision 0006's 2026-11-24 amendment.
            "--antialias",
            "swan",
            "--srgb",
            "--phantom-size",
            "40",
            "--size",
            "48x40",
            "--azimuth",
            "30",
            "--elevation",
            "15",
        ],
        "png",
        // Re-recorded 2026-11-25 for the sheets' shading through the slab kernel's table (the
        // 8-bit sRGB picture of the case above: 104.5 dB before quantisation).
        0x1371da6980f7bf19,
    ),
    (
        "perspective",
        &[
            // The splat list, which `auto` drew for shaded perspective before decision 0019.
            "--visibility",
            "sheet",
            // The early-termination cutoff these hashes were recorded with (the default before
            // decision 0018 made it VTK's level): 1 − 2⁻²⁰.
            "--opacity-cutoff",
            "0.99999905",
            // Swan's rule, the default anti-aliasing before decision 0006's 2026-11-24 amendment.
            "--antialias",
            "swan",
            "--phantom-size",
            "40",
            "--size",
            "40",
            "--perspective",
            "--azimuth",
            "-40",
            "--elevation",
            "20",
        ],
        "npy",
        0x094f898a13f48a4b,
    ),
    (
        "splat list, orthographic",
        &[
            // Swan's rule, the default anti-aliasing before decision 0006's 2026-11-24 amendment.
            "--antialias",
            "swan",
            // The function these hashes were recorded with (the default before the automatic
            // transfer function of issue 15).
            "--preset",
            "ramp",
            "--phantom",
            "blobs",
            "--phantom-size",
            "32",
            "--size",
            "36x44",
            "--splat-list",
            "--azimuth",
            "45",
        ],
        "npy",
        0xe323830d241a2101,
    ),
    (
        // Westover's sheets, the default for MIP before decision 0016.
        "MIP",
        &[
            // Swan's rule, the default anti-aliasing before decision 0006's 2026-11-24 amendment.
            "--antialias",
            "swan",
            "--visibility",
            "sheet",
            "--phantom",
            "blobs",
            "--phantom-size",
            "32",
            "--mode",
            "mip",
            "--size",
            "40",
            "--azimuth",
            "60",
        ],
        "npy",
        0x420e8883f4f46395,
    ),
    (
        // The default since decision 0016: image-aligned slabs.
        "MIP, image-aligned slabs",
        &[
            "--phantom",
            "blobs",
            "--phantom-size",
            "32",
            "--mode",
            "mip",
            "--size",
            "40",
            "--azimuth",
            "60",
        ],
        "npy",
        // Re-recorded for decision 0020: the pixel is 1.34 voxels, so 1.34 × 1.34 rays per
        // pixel, area-filtered (2 × 2 before).
        0x0b289e580f661335,
    ),
    (
        "composite, image-aligned slabs, perspective",
        &[
            "--visibility",
            "image",
            "--preset",
            "ramp",
            "--phantom",
            "blobs",
            "--phantom-size",
            "32",
            "--size",
            "36x44",
            "--perspective",
            "--azimuth",
            "45",
        ],
        "npy",
        // Re-recorded for decision 0017 (unshaded composite slabs default to one voxel; the
        // half-voxel slabs keep their bits in the next case) and decision 0020 (1.26 × 1.26 rays
        // per pixel, area-filtered, where there were 2 × 2).
        0xc068b08ed71b5297,
    ),
    (
        "composite, image-aligned half-voxel slabs, perspective",
        &[
            "--visibility",
            "image",
            "--slab",
            "0.5",
            "--preset",
            "ramp",
            "--phantom",
            "blobs",
            "--phantom-size",
            "32",
            "--size",
            "36x44",
            "--perspective",
            "--azimuth",
            "45",
        ],
        "npy",
        // Re-recorded for decision 0020 (fractional rays per pixel, area-filtered).
        0xacb41f8b18d0b810,
    ),
    (
        "shaded, image-aligned slabs",
        &[
            // The early-termination cutoff these hashes were recorded with (the default before
            // decision 0018 made it VTK's level): 1 − 2⁻²⁰.
            "--opacity-cutoff",
            "0.99999905",
            "--visibility",
            "image",
            // Shading at the samples (the slabs' shaded default before decision 0019), now at
            // one voxel with two lights per slab (decision 0036).
            "--shade-at",
            "samples",
            "--phantom-size",
            "40",
            "--size",
            "48x40",
            "--azimuth",
            "30",
            "--elevation",
            "15",
        ],
        "npy",
        // Re-recorded 2026-11-25 for the shaded slab kernel (tables and central differences
        // interpolated in the cell instead of the per-sample classifier): 99.6 dB from the old
        // picture, largest difference 5.8e-4. Re-recorded 2026-11-26 for decision 0036 (one-voxel
        // slabs lit twice, at ±¼ of the step; the specular power by repeated squaring), and
        // pre-integrated now that the samples-lit slabs are (`--preintegrate auto` takes it
        // here).
        0x163a5465191d27c4,
    ),
    (
        // Every default (decision 0036: `shade_at: auto` lights the samples, twice per
        // one-voxel slab, at ¼ and ¾ of each pre-integrated segment).
        "demo head, defaults (slabs lit at the samples, pre-integrated)",
        &[
            "--phantom-size",
            "40",
            "--size",
            "48x40",
            "--azimuth",
            "30",
            "--elevation",
            "15",
        ],
        "npy",
        // Recorded 2026-11-26.
        0x4676ca9fdc76aaa9,
    ),
    (
        // Every default before decision 0036, which lights the samples (decision 0019: `auto`
        // drew shaded composite with one-voxel slabs shaded at the voxels, VTK's order; decision 0018's cutoff (VTK's 1 − 255/32767); area anti-aliasing;
        // decision 0020: on this 40³ grid a slab is thick enough for the automatic ramp's
        // ring risk to reach 4.6, so the slabs are pre-integrated; 2.2 at the demo's 84 × 128²).
        "demo head, slabs shaded at the voxels, pre-integrated (the defaults before decision 0036)",
        &[
            "--shade-at",
            "voxels",
            "--phantom-size",
            "40",
            "--size",
            "48x40",
            "--azimuth",
            "30",
            "--elevation",
            "15",
        ],
        "npy",
        // Recorded 2026-11-25 (decision 0020); re-recorded for the cutoff 1 − 255/32767
        // (decision 0018's amendment): 70.9 dB from the picture at 0.99, largest difference
        // 4.8e-3, on 3.0 % of the pixels; and for the segments lit at their middle
        // (`SEGMENT_LIGHT_AT`): 51.0 dB from the picture before, which was 48.7 dB from the
        // same slabs at 1/8 voxel by point and is now 53.7 dB from them.
        0x7d9757c0d34419bc,
    ),
    (
        // The same by point (the defaults before decision 0020).
        "demo head, slabs shaded at the voxels, by point",
        &[
            "--shade-at",
            "voxels",
            "--phantom-size",
            "40",
            "--size",
            "48x40",
            "--azimuth",
            "30",
            "--elevation",
            "15",
            "--preintegrate",
            "off",
        ],
        "npy",
        // Recorded 2026-11-25: 44.6 dB from the same slabs shaded at the samples, 29.8 dB from
        // the sheets (blurrier on this 40³ phantom); re-recorded for the cutoff 1 − 255/32767:
        // 71.8 dB from the picture at 0.99, largest difference 4.2e-3, on 2.8 % of the pixels.
        0x862321bdf1f946d4,
    ),
    (
        "X-ray",
        &[
            // Swan's rule, the default anti-aliasing before decision 0006's 2026-11-24 amendment.
            "--antialias",
            "swan",
            "--phantom",
            "shepp-logan",
            "--phantom-size",
            "32",
            "--mode",
            "xray",
            "--size",
            "37x29",
            "--azimuth",
            "45",
        ],
        "npy",
        0xf2709a4b7ab6e221,
    ),
    (
        "Sabella display",
        &[
            // The function these hashes were recorded with (the default before the automatic
            // transfer function of issue 15).
            "--preset",
            "ramp",
            "--phantom",
            "blobs",
            "--phantom-size",
            "24",
            "--renderer",
            "sabella",
            "--size",
            "24",
            "--azimuth",
            "20",
        ],
        "npy",
        // Re-recorded for decision 0027: Sabella's display is grey by default (was red =
        // intensity, green = maximum density; `--grey=false` keeps that).
        0xfcbc25545f400a00,
    ),
    (
        "NIL display",
        &[
            // The function these hashes were recorded with (the default before the automatic
            // transfer function of issue 15).
            "--preset",
            "ramp",
            "--phantom",
            "blobs",
            "--phantom-size",
            "24",
            "--renderer",
            "nil",
            "--size",
            "24",
            "--azimuth",
            "20",
        ],
        "npy",
        // Re-recorded for decision 0027: Sabella's attenuation instead of eq 6.1's unit
        // density, continuous patches, cells at most 1.5 filter widths, 4 × 4 lines.
        0x3a6e54d0f43090bb,
    ),
];

#[test]
fn render_outputs_are_bit_for_bit_as_recorded() {
    let dir = tempfile::tempdir().unwrap();
    let print = std::env::var_os("VOLSPLAT_PRINT_HASHES").is_some();
    let mut failures = Vec::new();
    for (n, (name, args, ext, recorded)) in CASES.iter().enumerate() {
        let out = dir.path().join(format!("case{n}.{ext}"));
        let o = Command::new(env!("CARGO_BIN_EXE_volsplat"))
            .arg("render")
            .args(*args)
            .args(["-q", "-o", out.to_str().unwrap()])
            .output()
            .unwrap();
        assert!(
            o.status.success(),
            "{name}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        let h = fnv1a(&std::fs::read(&out).unwrap());
        if print {
            println!("{name}: 0x{h:016x}");
        }
        if h != *recorded {
            failures.push(format!("{name}: 0x{h:016x}, recorded 0x{recorded:016x}"));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
