//! Issue 28 follow-ups on the command line: files with NaN samples (as nibabel, ITK, 3D Slicer
//! and napari read them) render with a note; a render whose buffers do not fit in memory is an
//! error (exit 1), not an abort; an orbit over the pole is a picture.

use std::path::Path;
use std::process::Command;

mod util;
use util::{stderr, volsplat};

/// Largest 8-bit channel of a PNG.
fn brightest(path: &Path) -> u8 {
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    buf[..info.buffer_size()].iter().copied().max().unwrap_or(0)
}

/// 24 × 20 × 16 float samples: a smooth blob of 50..250 in an ellipsoid, NaN outside (the
/// masked background of SPM's output), i fastest.
fn masked_samples() -> Vec<f32> {
    (0..24 * 20 * 16)
        .map(|n| {
            let (i, j, k) = ((n % 24) as f64, ((n / 24) % 20) as f64, (n / 480) as f64);
            let r2 =
                ((i - 11.5) / 11.0).powi(2) + ((j - 9.5) / 9.0).powi(2) + ((k - 7.5) / 7.0).powi(2);
            if r2 > 1.0 {
                f32::NAN
            } else {
                (50.0 + 200.0 * (1.0 - r2)) as f32
            }
        })
        .collect()
}

/// A NIfTI-1 file (`.nii`, float32, unit spacing, no orientation) holding `samples`.
fn nifti(dims: [i16; 3], samples: &[f32]) -> Vec<u8> {
    let mut h = vec![0u8; 352];
    h[0..4].copy_from_slice(&348i32.to_le_bytes());
    for (n, d) in [3, dims[0], dims[1], dims[2], 1, 1, 1, 1]
        .iter()
        .enumerate()
    {
        h[40 + 2 * n..42 + 2 * n].copy_from_slice(&d.to_le_bytes());
    }
    h[70..72].copy_from_slice(&16i16.to_le_bytes()); // DT_FLOAT32
    h[72..74].copy_from_slice(&32i16.to_le_bytes());
    for n in 0..8 {
        h[76 + 4 * n..80 + 4 * n].copy_from_slice(&1f32.to_le_bytes());
    }
    h[108..112].copy_from_slice(&352f32.to_le_bytes());
    h[344..348].copy_from_slice(b"n+1\0");
    h.extend(samples.iter().flat_map(|v| v.to_le_bytes()));
    h
}

/// Issue 28 follow-up: "invalid sample #0: NaN (float samples must be finite)" refused whole
/// files that peers read (nibabel's own `resampled_anat_moved.nii`, SPM output). Now NaN is
/// the lowest finite value (background: transparent under the automatic transfer function,
/// never a MIP's maximum), the render is not black, holds no NaN, and `render` and `info` say
/// what NaN became.
#[test]
fn files_with_a_nan_background_render_with_a_note() {
    let dir = tempfile::tempdir().unwrap();
    let samples = masked_samples();
    let nans = samples.iter().filter(|v| v.is_nan()).count();
    let lowest = samples
        .iter()
        .filter(|v| v.is_finite())
        .fold(f32::INFINITY, |m, &v| m.min(v));
    let note = format!("{nans} samples were NaN, taken as the lowest finite value {lowest}");
    let nii = dir.path().join("masked.nii");
    std::fs::write(&nii, nifti([24, 20, 16], &samples)).unwrap();
    let nrrd = dir.path().join("masked.nrrd");
    let mut file =
        b"NRRD0004\ntype: float\ndimension: 3\nsizes: 24 20 16\nendian: little\nencoding: raw\n\n"
            .to_vec();
    file.extend(samples.iter().flat_map(|v| v.to_le_bytes()));
    std::fs::write(&nrrd, file).unwrap();
    for input in [&nii, &nrrd] {
        let input = input.to_str().unwrap();
        for mode in ["composite", "mip"] {
            let png = dir.path().join(format!("{mode}.png"));
            let o = volsplat(&[
                "render",
                input,
                "--mode",
                mode,
                "--azimuth",
                "30",
                "--size",
                "48",
                "-o",
                png.to_str().unwrap(),
            ]);
            assert!(o.status.success(), "{input} {mode}: {}", stderr(&o));
            assert!(stderr(&o).contains(&note), "{input}: {}", stderr(&o));
            assert!(brightest(&png) > 20, "{input} {mode}: black");
        }
        // The float output: every pixel finite (the writer refuses NaN; this checks the
        // values it got), the composite premultiplied RGBA.
        let npy = dir.path().join("c.npy");
        let o = volsplat(&[
            "render",
            input,
            "--size",
            "32",
            "-q",
            "-o",
            npy.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{input}: {}", stderr(&o));
        let bytes = std::fs::read(&npy).unwrap();
        let header = 10 + u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
        let floats: Vec<f32> = bytes[header..]
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect();
        assert_eq!(floats.len(), 32 * 32 * 4);
        assert!(
            floats.iter().all(|v| v.is_finite()),
            "{input}: NaN in the output"
        );
        assert!(floats.iter().any(|&v| v > 0.05), "{input}: black");
        let o = volsplat(&["info", input]);
        assert!(o.status.success(), "{input}: {}", stderr(&o));
        let out = String::from_utf8_lossy(&o.stdout);
        assert!(out.contains(&note), "{input} info: {out}");
        let range = format!("range:     {} ..", lowest as f64);
        assert!(out.contains(&range), "{input} info: {out}");
    }
    // Nothing finite is still an error, naming the file.
    std::fs::write(&nii, nifti([2, 2, 1], &[f32::NAN; 4])).unwrap();
    let o = volsplat(&["render", nii.to_str().unwrap(), "-o", "x.png"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("masked.nii") && stderr(&o).contains("no sample is finite"),
        "{}",
        stderr(&o)
    );
}

/// Issue 28 follow-up: some orbits with an elevation of exactly ±90 (`--azimuth 36`, about one
/// in twenty) were an error, "invalid view_up: [NaN, NaN, NaN]"; VTK looks straight down.
#[test]
fn an_orbit_over_the_pole_renders() {
    let dir = tempfile::tempdir().unwrap();
    for (az, el) in [("36", "90"), ("43", "-90"), ("0", "120")] {
        let png = dir.path().join("pole.png");
        let o = volsplat(&[
            "render",
            "--azimuth",
            az,
            "--elevation",
            el,
            "--size",
            "32",
            "-q",
            "-o",
            png.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{az} {el}: {}", stderr(&o));
        assert!(brightest(&png) > 20, "{az} {el}: black");
    }
}

/// Issue 28 follow-up: a 524 MB u8 volume is read under a 1.25 GiB address-space limit, but
/// its normal field (shading at the voxels, 2 bytes per voxel, 1 GB) is not: the render
/// aborted (SIGABRT, "memory allocation of 1048576002 bytes failed"). Now exit status 1 and
/// "not enough memory for the normal field … (1048576002 bytes)"; the same for a MIP's splat
/// list, which keeps every voxel. The file is sparse: zeros
/// with a bright cube, which the automatic transfer function shows shaded. Two worker threads
/// and two malloc arenas keep the address space the threads reserve small on any machine.
#[cfg(target_os = "linux")]
#[test]
fn a_render_whose_normal_field_does_not_fit_is_an_error_not_an_abort() {
    use std::io::{Seek, SeekFrom, Write};
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("big.nrrd");
    let (nx, ny, nz) = (1024u64, 1024u64, 500u64);
    let mut f = std::fs::File::create(&path).unwrap();
    f.write_all(b"NRRD0004\ntype: uint8\ndimension: 3\nsizes: 1024 1024 500\nencoding: raw\n\n")
        .unwrap();
    let base = f.stream_position().unwrap();
    for k in 200..300 {
        for j in 400..600 {
            f.seek(SeekFrom::Start(base + (k * ny + j) * nx + 400))
                .unwrap();
            f.write_all(&[200u8; 200]).unwrap();
        }
    }
    f.set_len(base + nx * ny * nz).unwrap();
    drop(f);
    let png = dir.path().join("big.png");
    let limited = |extra: &[&str]| {
        let limit_kib = 1280 * 1024; // 1.25 GiB
        Command::new("sh")
            .arg("-c")
            .arg(format!("ulimit -v {limit_kib} && exec \"$0\" \"$@\""))
            .arg(env!("CARGO_BIN_EXE_volsplat"))
            .args([
                "render",
                path.to_str().unwrap(),
                "--size",
                "32",
                "--threads",
                "2",
            ])
            .args(extra)
            .arg("-o")
            .arg(&png)
            .env("MALLOC_ARENA_MAX", "2")
            .output()
            .unwrap()
    };
    // Lit at the voxels, as VTK lights them: the default lights the samples (decision 0036),
    // which needs no normal field.
    let o = limited(&["--shade-at", "voxels"]);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "not exit 1 (a signal?): {err}");
    assert!(
        err.contains("not enough memory for the normal field")
            && err.contains("(1048576002 bytes)"),
        "{err}"
    );
    // The splat list of a MIP keeps every voxel (24 bytes each, 12.6 GB): an error too.
    let o = limited(&["--splat-list", "--mode", "mip"]);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "not exit 1 (a signal?): {err}");
    assert!(
        err.contains("not enough memory for the splat list ("),
        "{err}"
    );
    assert!(!png.exists());
}
