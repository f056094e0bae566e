use super::*;
use std::io::Write;
use volsplat_core::ScalarType;

/// A NIfTI header built field by field (test helper; also used by the dispatcher tests).
#[derive(Clone)]
pub(crate) struct Hdr {
    pub v2: bool,
    pub big: bool,
    pub dim: Vec<i64>,
    pub datatype: i16,
    pub pixdim: [f64; 8],
    pub vox_offset: f64,
    pub slope: f64,
    pub inter: f64,
    pub qform_code: i32,
    pub sform_code: i32,
    pub quatern: [f64; 3],
    pub qoffset: [f64; 3],
    pub srow: [[f64; 4]; 3],
    pub pair: bool,
}

impl Hdr {
    pub(crate) fn new(dim: &[i64], datatype: i16) -> Self {
        Hdr {
            v2: false,
            big: false,
            dim: dim.to_vec(),
            datatype,
            pixdim: [1.0; 8],
            vox_offset: 352.0,
            slope: 0.0,
            inter: 0.0,
            qform_code: 0,
            sform_code: 0,
            quatern: [0.0; 3],
            qoffset: [0.0; 3],
            srow: [[0.0; 4]; 3],
            pair: false,
        }
    }

    pub(crate) fn bytes(&self) -> Vec<u8> {
        let size = if self.v2 { 540 } else { 348 };
        let mut b = vec![0u8; size];
        let big = self.big;
        let put = |b: &mut Vec<u8>, at: usize, x: &[u8]| {
            let mut x = x.to_vec();
            if big {
                x.reverse();
            }
            b[at..at + x.len()].copy_from_slice(&x);
        };
        put(&mut b, 0, &(size as i32).to_le_bytes());
        let mut dim = [1i64; 8];
        dim[0] = self.dim.len() as i64;
        for (k, &d) in self.dim.iter().enumerate() {
            dim[k + 1] = d;
        }
        if self.v2 {
            b[4..12].copy_from_slice(if self.pair {
                b"ni2\0\r\n\x1a\n"
            } else {
                b"n+2\0\r\n\x1a\n"
            });
            put(&mut b, 12, &self.datatype.to_le_bytes());
            for (k, dk) in dim.iter().enumerate() {
                put(&mut b, 16 + 8 * k, &dk.to_le_bytes());
                put(&mut b, 104 + 8 * k, &self.pixdim[k].to_le_bytes());
            }
            put(&mut b, 168, &(self.vox_offset as i64).to_le_bytes());
            put(&mut b, 176, &self.slope.to_le_bytes());
            put(&mut b, 184, &self.inter.to_le_bytes());
            put(&mut b, 344, &self.qform_code.to_le_bytes());
            put(&mut b, 348, &self.sform_code.to_le_bytes());
            for k in 0..3 {
                put(&mut b, 352 + 8 * k, &self.quatern[k].to_le_bytes());
                put(&mut b, 376 + 8 * k, &self.qoffset[k].to_le_bytes());
            }
            for r in 0..3 {
                for c in 0..4 {
                    put(&mut b, 400 + 32 * r + 8 * c, &self.srow[r][c].to_le_bytes());
                }
            }
        } else {
            for (k, &dk) in dim.iter().enumerate() {
                put(&mut b, 40 + 2 * k, &(dk as i16).to_le_bytes());
                put(&mut b, 76 + 4 * k, &(self.pixdim[k] as f32).to_le_bytes());
            }
            put(&mut b, 70, &self.datatype.to_le_bytes());
            put(&mut b, 108, &(self.vox_offset as f32).to_le_bytes());
            put(&mut b, 112, &(self.slope as f32).to_le_bytes());
            put(&mut b, 116, &(self.inter as f32).to_le_bytes());
            put(&mut b, 252, &(self.qform_code as i16).to_le_bytes());
            put(&mut b, 254, &(self.sform_code as i16).to_le_bytes());
            for k in 0..3 {
                put(&mut b, 256 + 4 * k, &(self.quatern[k] as f32).to_le_bytes());
                put(&mut b, 268 + 4 * k, &(self.qoffset[k] as f32).to_le_bytes());
            }
            for r in 0..3 {
                for c in 0..4 {
                    put(
                        &mut b,
                        280 + 16 * r + 4 * c,
                        &(self.srow[r][c] as f32).to_le_bytes(),
                    );
                }
            }
            b[344..348].copy_from_slice(if self.pair { b"ni1\0" } else { b"n+1\0" });
        }
        b
    }

    /// The whole single file: header, padding to vox_offset, then `data`.
    pub(crate) fn file(&self, data: &[u8]) -> Vec<u8> {
        let mut b = self.bytes();
        let n = (self.vox_offset as usize).max(b.len());
        b.resize(n, 0);
        b.extend_from_slice(data);
        b
    }
}

fn gz(data: &[u8]) -> Vec<u8> {
    let mut e = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    e.write_all(data).unwrap();
    e.finish().unwrap()
}

fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

fn i16_le(v: &[i16]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

fn close(a: [f64; 3], b: [f64; 3]) -> bool {
    a.iter().zip(&b).all(|(x, y)| (x - y).abs() < 1e-5)
}

#[test]
fn pixdim_only_is_the_analyze_convention_in_lps() {
    let dir = tempfile::tempdir().unwrap();
    for v2 in [false, true] {
        for big in [false, true] {
            let mut h = Hdr::new(&[3, 2, 2], 4);
            h.v2 = v2;
            h.big = big;
            h.vox_offset = if v2 { 544.0 } else { 352.0 };
            h.pixdim = [1.0, 0.5, 2.0, 3.0, 1.0, 1.0, 1.0, 1.0];
            let vals: Vec<i16> = (0..12).map(|i| i * 100 - 600).collect();
            let data: Vec<u8> = vals
                .iter()
                .flat_map(|x| {
                    if big {
                        x.to_be_bytes()
                    } else {
                        x.to_le_bytes()
                    }
                })
                .collect();
            let p = write(dir.path(), "a.nii", &h.file(&data));
            let l = read_nifti_with(&p, &ReadOptions::default()).unwrap();
            assert_eq!(l.format, if v2 { "NIfTI-2" } else { "NIfTI-1" });
            assert_eq!(l.frames, 1);
            let v = l.volume;
            assert_eq!(v.scalar_type(), ScalarType::I16);
            let g = v.grid();
            assert_eq!(g.dims, [3, 2, 2]);
            assert_eq!(g.spacing, [0.5, 2.0, 3.0]);
            // nibabel: RAS affine diag(−0.5, 2, 3), origin (0.5, −1, −1.5); then LPS.
            assert_eq!(g.origin, [-0.5, 1.0, -1.5]);
            assert_eq!(
                g.direction,
                DMat3::from_diagonal(DVec3::new(1.0, -1.0, 1.0))
            );
            let f: Vec<i16> = v.to_f32().data().iter().map(|&x| x as i16).collect();
            assert_eq!(f, vals);
            assert!(
                l.notes.iter().any(|n| n.contains("Analyze convention")),
                "{:?}",
                l.notes
            );
        }
    }
}

#[test]
fn sform_wins_and_is_converted_to_lps() {
    let dir = tempfile::tempdir().unwrap();
    // An oblique sform: 30° about z, spacings 0.5, 2, 3, origin (10, 20, 30) in RAS.
    let (c, s) = (30f64.to_radians().cos(), 30f64.to_radians().sin());
    for v2 in [false, true] {
        let mut h = Hdr::new(&[2, 2, 2], 2);
        h.v2 = v2;
        h.vox_offset = if v2 { 544.0 } else { 352.0 };
        h.sform_code = 2;
        h.qform_code = 1; // ignored: the sform wins
        h.quatern = [0.0, 0.0, 1.0];
        h.srow = [
            [0.5 * c, -2.0 * s, 0.0, 10.0],
            [0.5 * s, 2.0 * c, 0.0, 20.0],
            [0.0, 0.0, 3.0, 30.0],
        ];
        let p = write(dir.path(), "s.nii", &h.file(&[7; 8]));
        let l = read_nifti_with(&p, &ReadOptions::default()).unwrap();
        let g = l.volume.grid();
        assert!(close(g.spacing, [0.5, 2.0, 3.0]), "{:?}", g.spacing);
        assert!(close(g.origin, [-10.0, -20.0, 30.0]), "{:?}", g.origin);
        // World position of voxel (1, 1, 1): RAS (10 + 0.5c − 2s, 20 + 0.5s + 2c, 33) → LPS.
        let p_ras = DVec3::new(10.0 + 0.5 * c - 2.0 * s, 20.0 + 0.5 * s + 2.0 * c, 33.0);
        let p = g.world_from_index(DVec3::ONE);
        assert!(
            (p - DVec3::new(-p_ras.x, -p_ras.y, p_ras.z)).length() < 1e-5,
            "{p}"
        );
        assert!(l.notes.iter().any(|n| n.contains("sform")), "{:?}", l.notes);
        assert_eq!(l.volume.scalar_type(), ScalarType::U8);
    }
}

#[test]
fn qform_with_qfac_minus_one() {
    let dir = tempfile::tempdir().unwrap();
    // 90° about z: quaternion (a, b, c, d) = (cos 45°, 0, 0, sin 45°).
    let q = std::f64::consts::FRAC_1_SQRT_2;
    let mut h = Hdr::new(&[2, 3, 4], 16);
    h.qform_code = 1;
    h.quatern = [0.0, 0.0, q];
    h.qoffset = [1.0, 2.0, 3.0];
    h.pixdim = [-1.0, 2.0, 3.0, 4.0, 1.0, 1.0, 1.0, 1.0];
    let data: Vec<u8> = (0..24).flat_map(|i| (i as f32).to_le_bytes()).collect();
    let p = write(dir.path(), "q.nii", &h.file(&data));
    let l = read_nifti_with(&p, &ReadOptions::default()).unwrap();
    let g = l.volume.grid();
    assert!(close(g.spacing, [2.0, 3.0, 4.0]));
    assert!(close(g.origin, [-1.0, -2.0, 3.0]));
    // RAS: i → +y, j → −x, k → −z (qfac −1). LPS: negate x and y.
    let expect = DMat3::from_cols(DVec3::new(0.0, -1.0, 0.0), DVec3::X, -DVec3::Z);
    assert!(g.direction.abs_diff_eq(expect, 1e-6), "{:?}", g.direction);
    assert!(l.notes.iter().any(|n| n.contains("qform")), "{:?}", l.notes);
}

#[test]
fn scaling_makes_f32_and_zero_slope_means_none() {
    let dir = tempfile::tempdir().unwrap();
    let vals: Vec<i16> = vec![-3, 0, 5, 1000];
    let mut h = Hdr::new(&[4, 1, 1], 4);
    h.slope = 0.5;
    h.inter = -1024.0;
    let p = write(dir.path(), "sc.nii", &h.file(&i16_le(&vals)));
    let v = read_nifti(&p).unwrap();
    assert_eq!(v.scalar_type(), ScalarType::F32);
    assert_eq!(v.to_f32().data(), &[-1025.5, -1024.0, -1021.5, -524.0]);
    for (slope, inter) in [(0.0, 5.0), (1.0, 0.0), (f64::NAN, 3.0)] {
        h.slope = slope;
        h.inter = inter;
        let p = write(dir.path(), "sc.nii", &h.file(&i16_le(&vals)));
        let v = read_nifti(&p).unwrap();
        assert_eq!(v.scalar_type(), ScalarType::I16, "{slope} {inter}");
    }
    // A scale past the f32 range is an error naming the fields.
    h.slope = 1e38;
    h.inter = 0.0;
    let p = write(dir.path(), "sc.nii", &h.file(&i16_le(&vals)));
    let e = read_nifti(&p).unwrap_err().to_string();
    assert!(e.contains("scl_slope") && e.contains("sc.nii"), "{e}");
}

#[test]
fn every_datatype() {
    let dir = tempfile::tempdir().unwrap();
    let cases: Vec<(i16, Vec<u8>, ScalarType, Vec<f32>)> = vec![
        (2, vec![0, 255], ScalarType::U8, vec![0.0, 255.0]),
        (256, vec![0x80, 0x7f], ScalarType::I8, vec![-128.0, 127.0]),
        (
            512,
            [0u16, 65535].iter().flat_map(|x| x.to_le_bytes()).collect(),
            ScalarType::U16,
            vec![0.0, 65535.0],
        ),
        (
            4,
            i16_le(&[-32768, 32767]),
            ScalarType::I16,
            vec![-32768.0, 32767.0],
        ),
        (
            16,
            [1.5f32, -2.0]
                .iter()
                .flat_map(|x| x.to_le_bytes())
                .collect(),
            ScalarType::F32,
            vec![1.5, -2.0],
        ),
        (
            8,
            [-70000i32, 70000]
                .iter()
                .flat_map(|x| x.to_le_bytes())
                .collect(),
            ScalarType::F32,
            vec![-70000.0, 70000.0],
        ),
        (
            768,
            [0u32, 4_000_000]
                .iter()
                .flat_map(|x| x.to_le_bytes())
                .collect(),
            ScalarType::F32,
            vec![0.0, 4e6],
        ),
        (
            64,
            [0.25f64, -1e10]
                .iter()
                .flat_map(|x| x.to_le_bytes())
                .collect(),
            ScalarType::F32,
            vec![0.25, -1e10],
        ),
    ];
    for (dt, data, st, expect) in cases {
        let h = Hdr::new(&[2, 1, 1], dt);
        let p = write(dir.path(), "t.nii", &h.file(&data));
        let v = read_nifti(&p).unwrap();
        assert_eq!(v.scalar_type(), st, "datatype {dt}");
        assert_eq!(v.to_f32().data(), &expect[..], "datatype {dt}");
    }
    let h = Hdr::new(&[2, 1, 1], 64);
    let data: Vec<u8> = [1e300f64, 0.0]
        .iter()
        .flat_map(|x| x.to_le_bytes())
        .collect();
    let p = write(dir.path(), "t.nii", &h.file(&data));
    assert!(read_nifti(&p).is_err());
    let h = Hdr::new(&[2, 1, 1], 128);
    let p = write(dir.path(), "t.nii", &h.file(&[0; 6]));
    let e = read_nifti(&p).unwrap_err().to_string();
    assert!(e.contains("`datatype`") && e.contains("128"), "{e}");
}

#[test]
fn gzip_pairs_and_frames() {
    let dir = tempfile::tempdir().unwrap();
    // 4-D: 2×1×1 × 3 frames of u8.
    let h = Hdr::new(&[2, 1, 1, 3], 2);
    let data = [10u8, 11, 20, 21, 30, 31];
    let p = write(dir.path(), "f.nii.gz", &gz(&h.file(&data)));
    for frame in 0..3 {
        let o = ReadOptions {
            frame,
            ..ReadOptions::default()
        };
        let l = read_nifti_with(&p, &o).unwrap();
        assert_eq!(l.frames, 3);
        assert_eq!(l.frame, frame);
        let base = 10.0 * (frame + 1) as f32;
        assert_eq!(l.volume.to_f32().data(), &[base, base + 1.0]);
    }
    let o = ReadOptions {
        frame: 3,
        ..ReadOptions::default()
    };
    let e = read_nifti_with(&p, &o).unwrap_err().to_string();
    assert!(
        e.contains("holds 3 frames") && e.contains("f.nii.gz"),
        "{e}"
    );
    // .hdr/.img pair (img gzipped too), NIfTI-1 and -2.
    for v2 in [false, true] {
        let mut h = Hdr::new(&[2, 1, 1, 3], 2);
        h.v2 = v2;
        h.pair = true;
        h.vox_offset = 0.0;
        write(dir.path(), "p.hdr", &h.bytes());
        write(dir.path(), "p.img", &data);
        let l = read_nifti_with(
            dir.path().join("p.hdr"),
            &ReadOptions {
                frame: 2,
                ..ReadOptions::default()
            },
        )
        .unwrap();
        assert_eq!(l.volume.to_f32().data(), &[30.0, 31.0]);
        std::fs::remove_file(dir.path().join("p.img")).unwrap();
        write(dir.path(), "p.img.gz", &gz(&data));
        let v = read_nifti(dir.path().join("p.hdr")).unwrap();
        assert_eq!(v.to_f32().data(), &[10.0, 11.0]);
        std::fs::remove_file(dir.path().join("p.img.gz")).unwrap();
        let e = read_nifti(dir.path().join("p.hdr"))
            .unwrap_err()
            .to_string();
        // Issue 28 §4: the message names the missing file and the header, not just the
        // OS's "entity not found".
        assert!(
            e.contains("p.img")
                && e.contains("p.hdr")
                && e.contains("holds no samples")
                && !e.contains("entity not found"),
            "{e}"
        );
    }
}

#[test]
fn malformed_files_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let h = Hdr::new(&[2, 2, 2], 2);
    let full = h.file(&[1; 8]);
    // Truncated header, truncated data, truncated gzip.
    for (name, bytes, want) in [
        ("a.nii", full[..100].to_vec(), "NIfTI header is truncated"),
        ("b.nii", full[..356].to_vec(), "expected 8 bytes, found 4"),
        ("c.nii.gz", gz(&full)[..30].to_vec(), "c.nii.gz"),
        ("d.nii", vec![], "truncated"),
        (
            "e.nii",
            b"not a nifti file at all, just some text".repeat(20),
            "sizeof_hdr",
        ),
    ] {
        let p = write(dir.path(), name, &bytes);
        let e = read_nifti(&p).unwrap_err().to_string();
        assert!(e.contains(want) && e.contains(name), "{name}: {e}");
    }
    let mut bad = full.clone();
    bad[344..348].copy_from_slice(b"xyz\0");
    let p = write(dir.path(), "m.nii", &bad);
    assert!(read_nifti(&p).unwrap_err().to_string().contains("`magic`"));
    let cases: Vec<(Hdr, &str)> = vec![
        (
            {
                let mut h = h.clone();
                h.dim = vec![2, 0, 2];
                h
            },
            "`dim[2]`",
        ),
        (
            {
                let mut h = h.clone();
                h.dim = vec![];
                h
            },
            "`dim[0]`",
        ),
        (
            {
                let mut h = h.clone();
                h.vox_offset = 10.0;
                h
            },
            "`vox_offset`",
        ),
        (
            {
                let mut h = h.clone();
                h.vox_offset = 352.5;
                h
            },
            "`vox_offset`",
        ),
        (
            {
                let mut h = h.clone();
                h.pixdim[2] = 0.0;
                h
            },
            "`pixdim[2]`",
        ),
        (
            {
                let mut h = h.clone();
                h.sform_code = 1;
                h.srow = [
                    [1.0, 1.0, 0.0, 0.0],
                    [0.0, 1.0, 0.0, 0.0],
                    [0.0, 0.0, 1.0, 0.0],
                ];
                h
            },
            "`srow_x/y/z`",
        ),
    ];
    for (h, want) in cases {
        let p = write(dir.path(), "x.nii", &h.file(&[1; 8]));
        let e = read_nifti(&p).unwrap_err().to_string();
        assert!(e.contains(want), "want {want}: {e}");
    }
    // NIfTI-2 sizes that overflow.
    let mut h2 = Hdr::new(&[i64::MAX, i64::MAX, 4], 2);
    h2.v2 = true;
    h2.vox_offset = 544.0;
    let p = write(dir.path(), "o.nii", &h2.file(&[0; 8]));
    let e = read_nifti(&p).unwrap_err().to_string();
    assert!(
        e.contains("`dim`") && e.contains("exceeds the limit"),
        "{e}"
    );
    let mut h2 = Hdr::new(&[2, 1, 1, i64::MAX, i64::MAX], 2);
    h2.v2 = true;
    h2.vox_offset = 544.0;
    let p = write(dir.path(), "o.nii", &h2.file(&[0; 8]));
    let e = read_nifti(&p).unwrap_err().to_string();
    assert!(e.contains("frames overflows"), "{e}");
    // A sheared sform falls back to the qform when there is one.
    let mut h = h.clone();
    h.sform_code = 1;
    h.srow = [
        [1.0, 1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0, 0.0],
        [0.0, 0.0, 1.0, 0.0],
    ];
    h.qform_code = 1;
    let p = write(dir.path(), "x.nii", &h.file(&[1; 8]));
    let l = read_nifti_with(&p, &ReadOptions::default()).unwrap();
    assert!(
        l.notes.iter().any(|n| n.contains("sheared")),
        "{:?}",
        l.notes
    );
}

/// Issue 29 item 5: the `.img` of a `.hdr` in a folder the read is confined to must lie in
/// it: a `.img` that is a link out of the folder is refused (an Analyze/NIfTI pair names no
/// file, so a link is the only way out).
#[test]
#[cfg(unix)]
fn confined_reads_refuse_an_image_file_outside_the_folder() {
    use crate::confine::tests::{assert_outside, layout};
    let l = layout(&[1, 2, 3, 4]);
    let mut h = Hdr::new(&[2, 2, 1], 2);
    h.pair = true;
    h.vox_offset = 0.0;
    std::fs::write(l.data.join("in.hdr"), h.bytes()).unwrap();
    std::fs::copy(&l.secret, l.data.join("in.img")).unwrap();
    std::fs::write(l.data.join("escape.hdr"), h.bytes()).unwrap();
    std::os::unix::fs::symlink("../secret.raw", l.data.join("escape.img")).unwrap();
    let o = ReadOptions {
        limits: l.limits.clone(),
        ..ReadOptions::default()
    };
    let v = read_nifti_with(l.data.join("in.hdr"), &o).unwrap();
    assert_eq!(v.volume.to_f32().data(), &[1.0, 2.0, 3.0, 4.0]);
    // Not confined, the link is followed; confined, it is refused.
    let v = read_nifti(l.data.join("escape.hdr")).unwrap();
    assert_eq!(v.to_f32().data(), &[1.0, 2.0, 3.0, 4.0]);
    let e = read_nifti_with(l.data.join("escape.hdr"), &o).unwrap_err();
    assert_outside(&e, "escape.hdr", "image file", "escape.img", &l);
}
