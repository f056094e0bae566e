use super::*;
use std::path::PathBuf;
use volsplat_core::{ScalarType, Volume};

fn file(dir: &Path, name: &str, header: &str, data: &[u8]) -> PathBuf {
    let p = dir.join(name);
    let mut bytes = header.as_bytes().to_vec();
    bytes.extend_from_slice(data);
    std::fs::write(&p, bytes).unwrap();
    p
}

pub(crate) fn gz(data: &[u8]) -> Vec<u8> {
    let mut e = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    e.write_all(data).unwrap();
    e.finish().unwrap()
}

fn err_of(dir: &Path, header: &str, data: &[u8]) -> String {
    let p = file(dir, "bad.nrrd", header, data);
    match read_nrrd(&p) {
        Ok(_) => panic!("expected an error for header:\n{header}"),
        Err(e) => {
            let s = e.to_string();
            assert!(s.contains("bad.nrrd"), "error does not name the file: {s}");
            if std::env::var_os("VOLSPLAT_SHOW_ERRORS").is_some() {
                eprintln!("{s}");
            }
            s
        }
    }
}

/// A minimal valid u8 header for 2×2×2 with one field replaced or removed.
fn header_with(replace: &str, with: Option<&str>) -> String {
    let fields = [
        ("type", "type: uint8"),
        ("dimension", "dimension: 3"),
        ("sizes", "sizes: 2 2 2"),
        ("encoding", "encoding: raw"),
        ("endian", "endian: little"),
    ];
    let mut h = String::from("NRRD0004\n");
    for (name, line) in fields {
        if name == replace {
            if let Some(w) = with {
                h.push_str(w);
                h.push('\n');
            }
        } else {
            h.push_str(line);
            h.push('\n');
        }
    }
    h.push('\n');
    h
}

fn grids() -> Vec<Grid> {
    let rot = DMat3::from_rotation_z(0.4) * DMat3::from_rotation_x(-0.7);
    vec![
        Grid::new(
            [3, 4, 5],
            [0.5, 2.0, 1.25],
            [-10.5, 3.0, 0.1],
            DMat3::IDENTITY,
        )
        .unwrap(),
        Grid::new([3, 4, 5], [0.3, 0.7, 1.1], [1.0, 2.0, 3.0], rot).unwrap(),
        // A flip and a permutation: still exact.
        Grid::new(
            [3, 4, 5],
            [0.1, 0.2, 0.3],
            [0.0; 3],
            DMat3::from_cols(DVec3::Y, -DVec3::X, DVec3::Z),
        )
        .unwrap(),
    ]
}

fn volumes(grid: &Grid) -> Vec<AnyVolume> {
    let g = grid.clone();
    let n = |i: usize, j: usize, k: usize| (i + 3 * j + 12 * k) as i64;
    vec![
        Volume::from_fn(g.clone(), |i, j, k| (n(i, j, k) * 4) as u8)
            .unwrap()
            .into(),
        Volume::from_fn(g.clone(), |i, j, k| (n(i, j, k) * 2 - 60) as i8)
            .unwrap()
            .into(),
        Volume::from_fn(g.clone(), |i, j, k| (n(i, j, k) * 1000) as u16)
            .unwrap()
            .into(),
        Volume::from_fn(g.clone(), |i, j, k| (n(i, j, k) * 500 - 15000) as i16)
            .unwrap()
            .into(),
        Volume::from_fn(g, |i, j, k| n(i, j, k) as f32 * -0.37 + 1e-3)
            .unwrap()
            .into(),
    ]
}

#[test]
fn round_trip_every_type_raw_and_gzip() {
    let dir = tempfile::tempdir().unwrap();
    for (gi, grid) in grids().iter().enumerate() {
        for vol in volumes(grid) {
            for gzip in [false, true] {
                let p = dir.path().join(format!("v{gi}.nrrd"));
                write_nrrd(&p, &vol, gzip).unwrap();
                let back = read_nrrd(&p).unwrap();
                assert_eq!(back.scalar_type(), vol.scalar_type());
                let (a, b) = (vol.grid(), back.grid());
                if gi == 1 {
                    // General rotation: spacing is recovered as a vector length.
                    assert_eq!(a.dims, b.dims);
                    assert_eq!(a.origin, b.origin);
                    for c in 0..3 {
                        assert!((a.spacing[c] - b.spacing[c]).abs() < 1e-14);
                    }
                    assert!(a.direction.abs_diff_eq(b.direction, 1e-14));
                    let mut fixed = back.clone();
                    fixed.set_grid(a.clone()).unwrap();
                    assert_eq!(fixed, vol);
                } else {
                    assert_eq!(back, vol, "grid {gi}, gzip {gzip}");
                }
            }
        }
    }
}

#[test]
fn writes_are_atomic() {
    let dir = tempfile::tempdir().unwrap();
    let vol = volumes(&grids()[0]).remove(0);
    let p = dir.path().join("missing").join("v.nrrd");
    let e = write_nrrd(&p, &vol, true).unwrap_err();
    assert!(e.to_string().contains("v.nrrd"), "{e}");
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
    // An existing (larger) file is replaced whole.
    let p = dir.path().join("v.nrrd");
    std::fs::write(&p, vec![b'x'; 100_000]).unwrap();
    write_nrrd(&p, &vol, false).unwrap();
    assert_eq!(read_nrrd(&p).unwrap(), vol);
    assert!(std::fs::metadata(&p).unwrap().len() < 1000);
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
}

#[test]
fn written_header_is_standard() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("h.nrrd");
    let vol = volumes(&grids()[0]).remove(3);
    write_nrrd(&p, &vol, false).unwrap();
    let bytes = std::fs::read(&p).unwrap();
    let text = String::from_utf8_lossy(&bytes[..300]);
    assert!(text.starts_with("NRRD0004\n"));
    assert!(text.contains("type: int16\n"));
    // Issue 28 §5: the frame is declared, so that ITK and 3D Slicer place the volume
    // where volsplat does (`space dimension` alone left them to guess).
    assert!(
        text.contains("\nspace: left-posterior-superior\n"),
        "{text}"
    );
    assert!(!text.contains("space dimension"), "{text}");
    assert!(text.contains("space directions: (0.5,0.0,0.0) (0.0,2.0,0.0) (0.0,0.0,1.25)\n"));
    assert!(text.contains("space origin: (-10.5,3.0,0.1)\n\n"));
    assert_eq!(bytes.len(), text.find("\n\n").unwrap() + 2 + 60 * 2);
}

#[test]
fn hand_written_big_and_little_endian() {
    let dir = tempfile::tempdir().unwrap();
    let vals16: [u16; 2] = [0x0102, 0xfffe];
    let valsf: [f32; 2] = [1.5, -2.25e-3];
    for big in [false, true] {
        let endian = if big { "big" } else { "little" };
        for (ty, bytes, expect) in [
            (
                "unsigned short",
                vals16
                    .iter()
                    .flat_map(|v| {
                        if big {
                            v.to_be_bytes()
                        } else {
                            v.to_le_bytes()
                        }
                    })
                    .collect::<Vec<u8>>(),
                AnyVolume::from(
                    Volume::new(Grid::with_dims([2, 1, 1]).unwrap(), vals16.to_vec()).unwrap(),
                ),
            ),
            (
                "short",
                vals16
                    .iter()
                    .flat_map(|v| {
                        if big {
                            v.to_be_bytes()
                        } else {
                            v.to_le_bytes()
                        }
                    })
                    .collect(),
                Volume::new(
                    Grid::with_dims([2, 1, 1]).unwrap(),
                    vals16.iter().map(|&v| v as i16).collect(),
                )
                .unwrap()
                .into(),
            ),
            (
                "float",
                valsf
                    .iter()
                    .flat_map(|v| {
                        if big {
                            v.to_be_bytes()
                        } else {
                            v.to_le_bytes()
                        }
                    })
                    .collect(),
                Volume::new(Grid::with_dims([2, 1, 1]).unwrap(), valsf.to_vec())
                    .unwrap()
                    .into(),
            ),
        ] {
            for (enc, payload) in [("raw", bytes.clone()), ("gzip", gz(&bytes))] {
                let h = format!(
                    "NRRD0001\ntype: {ty}\ndimension: 3\nsizes: 2 1 1\nendian: {endian}\n\
                     encoding: {enc}\n\n"
                );
                let p = file(dir.path(), "e.nrrd", &h, &payload);
                assert_eq!(read_nrrd(&p).unwrap(), expect, "{ty} {endian} {enc}");
            }
        }
    }
}

#[test]
fn type_spellings_and_conversions() {
    let dir = tempfile::tempdir().unwrap();
    for (ty, st) in [
        ("uchar", ScalarType::U8),
        ("unsigned char", ScalarType::U8),
        ("uint8_t", ScalarType::U8),
        ("signed char", ScalarType::I8),
        ("int8", ScalarType::I8),
        ("ushort", ScalarType::U16),
        ("uint16", ScalarType::U16),
        ("unsigned  short int", ScalarType::U16),
        ("short", ScalarType::I16),
        ("int16_t", ScalarType::I16),
        ("signed short", ScalarType::I16),
        ("float", ScalarType::F32),
    ] {
        let h = format!(
            "NRRD0004\ntype: {ty}\ndimension: 3\nsizes: 1 1 1\nendian: little\nencoding: raw\n\n"
        );
        let p = file(dir.path(), "t.nrrd", &h, &[0; 4]);
        assert_eq!(read_nrrd(&p).unwrap().scalar_type(), st, "{ty}");
    }
    // int32 and double are converted to f32.
    let h = "NRRD0004\ntype: int\ndimension: 3\nsizes: 2 1 1\nendian: little\nencoding: raw\n\n";
    let data: Vec<u8> = [-70000i32, 5]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    let v = read_nrrd(file(dir.path(), "i.nrrd", h, &data)).unwrap();
    assert_eq!(v.to_f32().data(), &[-70000.0, 5.0]);
    let h = "NRRD0004\ntype: double\ndimension: 3\nsizes: 2 1 1\nendian: big\nencoding: raw\n\n";
    let data: Vec<u8> = [0.125f64, -3.5]
        .iter()
        .flat_map(|v| v.to_be_bytes())
        .collect();
    let v = read_nrrd(file(dir.path(), "d.nrrd", h, &data)).unwrap();
    assert_eq!(v.scalar_type(), ScalarType::F32);
    assert_eq!(v.to_f32().data(), &[0.125, -3.5]);
    // A double outside the f32 range is an error, not infinity.
    let data: Vec<u8> = [1e300f64, 0.0]
        .iter()
        .flat_map(|v| v.to_be_bytes())
        .collect();
    let e = read_nrrd(file(dir.path(), "d.nrrd", h, &data)).unwrap_err();
    assert!(e.to_string().contains("sample #0"), "{e}");
}

#[test]
fn detached_headers_with_data_file() {
    let dir = tempfile::tempdir().unwrap();
    let data: Vec<u8> = (0..24).collect();
    std::fs::write(dir.path().join("d.raw"), &data).unwrap();
    std::fs::write(dir.path().join("d.raw.gz"), gz(&data)).unwrap();
    let expect: AnyVolume = Volume::new(Grid::with_dims([2, 3, 4]).unwrap(), data.clone())
        .unwrap()
        .into();
    for (field, enc, name) in [
        ("data file", "raw", "d.raw"),
        ("datafile", "raw", "./d.raw"),
        ("data file", "gzip", "d.raw.gz"),
        ("data file", "gz", "d.raw.gz"),
    ] {
        let h = format!(
            "NRRD0004\n# detached\ntype: uint8\ndimension: 3\nsizes: 2 3 4\nencoding: {enc}\n\
             {field}: {name}\n"
        );
        let p = file(dir.path(), "d.nhdr", &h, b"");
        assert_eq!(read_nrrd(&p).unwrap(), expect, "{field} {enc} {name}");
        assert_eq!(crate::read_volume(&p).unwrap(), expect);
    }
    // The data file is resolved relative to the header, not the working directory.
    let sub = dir.path().join("sub");
    std::fs::create_dir(&sub).unwrap();
    std::fs::write(sub.join("x.raw"), &data).unwrap();
    let h =
        "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 3 4\nencoding: raw\ndata file: sub/x.raw\n";
    assert_eq!(
        read_nrrd(file(dir.path(), "s.nhdr", h, b"")).unwrap(),
        expect
    );
    // An absolute path works too.
    let h = format!(
        "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 3 4\nencoding: raw\ndata file: {}\n",
        sub.join("x.raw").display()
    );
    assert_eq!(
        read_nrrd(file(dir.path(), "a.nhdr", &h, b"")).unwrap(),
        expect
    );
}

#[test]
fn space_directions_anisotropic_and_rotated() {
    let dir = tempfile::tempdir().unwrap();
    let h = "NRRD0005\ntype: uint8\ndimension: 3\nspace: left-posterior-superior\nsizes: 2 2 2\n\
             space directions: (0,2,0) (-0.5,0,0) (0,0,3)\nspace origin: (10,-20,30.5)\n\
             encoding: raw\n\n";
    let v = read_nrrd(file(dir.path(), "a.nrrd", h, &[0; 8])).unwrap();
    let g = v.grid();
    assert_eq!(g.spacing, [2.0, 0.5, 3.0]);
    assert_eq!(g.origin, [10.0, -20.0, 30.5]);
    assert_eq!(g.direction, DMat3::from_cols(DVec3::Y, -DVec3::X, DVec3::Z));
    // An LPS file: world = the file's space as written.
    assert_eq!(
        g.world_from_index(DVec3::new(1.0, 1.0, 1.0)),
        DVec3::new(9.5, -18.0, 33.5)
    );

    // A rotation of 30° about z with spacing (1.5, 0.8, 2), vectors with spaces inside.
    let (c, s) = (30f64.to_radians().cos(), 30f64.to_radians().sin());
    let h = format!(
        "NRRD0004\ntype: uint8\ndimension: 3\nspace dimension: 3\nsizes: 2 2 2\n\
         space directions: ({}, {}, 0) ({}, {}, 0) (0, 0, 2)\nencoding: raw\n\n",
        1.5 * c,
        1.5 * s,
        -0.8 * s,
        0.8 * c
    );
    let v = read_nrrd(file(dir.path(), "r.nrrd", &h, &[0; 8])).unwrap();
    let g = v.grid();
    for (a, b) in g.spacing.iter().zip([1.5, 0.8, 2.0]) {
        assert!((a - b).abs() < 1e-12);
    }
    assert!(
        g.direction
            .abs_diff_eq(DMat3::from_rotation_z(30f64.to_radians()), 1e-12)
    );

    // `spacings` alone, with nan → 1, and `none` axes completed from the others.
    let h =
        "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2 2\nspacings: 0.5 nan 4\nencoding: raw\n\n";
    let g = read_nrrd(file(dir.path(), "s.nrrd", h, &[0; 8]))
        .unwrap()
        .grid()
        .clone();
    assert_eq!(g.spacing, [0.5, 1.0, 4.0]);
    assert_eq!(g.direction, DMat3::IDENTITY);
    let h = "NRRD0004\ntype: uint8\ndimension: 3\nspace: RAS\nsizes: 2 2 2\n\
             space directions: (0,0,2) none (3,0,0)\nencoding: raw\n\n";
    let g = read_nrrd(file(dir.path(), "n.nrrd", h, &[0; 8]))
        .unwrap()
        .grid()
        .clone();
    assert_eq!(g.spacing, [2.0, 1.0, 3.0]);
    // `space: RAS` is converted to LPS (decision 0008): x and y negated.
    assert_eq!(
        g.direction,
        DMat3::from_cols(DVec3::Z, -DVec3::Y, -DVec3::X)
    );
}

#[test]
fn skips_comments_crlf_and_key_values() {
    let dir = tempfile::tempdir().unwrap();
    let data: Vec<u8> = (10..18).collect();
    let expect: AnyVolume = Volume::new(Grid::with_dims([2, 2, 2]).unwrap(), data.clone())
        .unwrap()
        .into();
    // byte skip in an attached file.
    let h = "NRRD0004\r\n# a comment: with colon\r\nmy key:=my: value\r\ntype: uint8\r\n\
             dimension: 3\r\nsizes: 2 2 2\r\nencoding: raw\r\nbyte skip: 5\r\n\
             content: whatever\r\nkinds: domain domain domain\r\n\r\n";
    let mut payload = b"JUNK!".to_vec();
    payload.extend_from_slice(&data);
    assert_eq!(
        read_nrrd(file(dir.path(), "b.nrrd", h, &payload)).unwrap(),
        expect
    );
    // byte skip -1: the samples are the last bytes of the file.
    let h = "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2 2\nencoding: raw\nbyte skip: -1\n\n";
    let mut payload = vec![0xAA; 100];
    payload.extend_from_slice(&data);
    assert_eq!(
        read_nrrd(file(dir.path(), "e.nrrd", h, &payload)).unwrap(),
        expect
    );
    // line skip, then byte skip, in a detached data file.
    let mut raw = b"first line\nsecond line\nXY".to_vec();
    raw.extend_from_slice(&data);
    raw.extend_from_slice(b"trailing data is ignored");
    std::fs::write(dir.path().join("ls.raw"), &raw).unwrap();
    let h = "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n\
             data file: ls.raw\nline skip: 2\nbyte skip: 2\n";
    assert_eq!(
        read_nrrd(file(dir.path(), "ls.nhdr", h, b"")).unwrap(),
        expect
    );
    // gzip: byte skip counts decompressed bytes.
    let mut inner = vec![1, 2, 3];
    inner.extend_from_slice(&data);
    std::fs::write(dir.path().join("bs.gz"), gz(&inner)).unwrap();
    let h = "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2 2\nencoding: gzip\n\
             data file: bs.gz\nbyte skip: 3\n";
    assert_eq!(
        read_nrrd(file(dir.path(), "bs.nhdr", h, b"")).unwrap(),
        expect
    );
}

#[test]
fn ascii_encoding() {
    let dir = tempfile::tempdir().unwrap();
    let h = "NRRD0004\ntype: short\ndimension: 3\nsizes: 2 2 1\nencoding: ascii\n\n";
    let v = read_nrrd(file(dir.path(), "a.nrrd", h, b"-5 7,\n 300\t-32768\n")).unwrap();
    assert_eq!(v.to_f32().data(), &[-5.0, 7.0, 300.0, -32768.0]);
    assert_eq!(v.scalar_type(), ScalarType::I16);
    let h = "NRRD0004\ntype: float\ndimension: 3\nsizes: 3 1 1\nencoding: text\n\n";
    let v = read_nrrd(file(dir.path(), "f.nrrd", h, b"0.5 -1e3 2")).unwrap();
    assert_eq!(v.to_f32().data(), &[0.5, -1000.0, 2.0]);
    // Errors: too few values, out of range, not a number.
    let h = "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 3 1 1\nencoding: ascii\n\n";
    let e = err_of(dir.path(), h, b"1 2");
    assert!(e.contains("expected 3 values, found 2"), "{e}");
    let e = err_of(dir.path(), h, b"1 256 2");
    assert!(e.contains("value #1") && e.contains("256"), "{e}");
    let e = err_of(dir.path(), h, b"1 x 2");
    assert!(e.contains("value #1"), "{e}");
}

#[test]
fn truncated_payloads_are_rejected() {
    let dir = tempfile::tempdir().unwrap();
    let h = "NRRD0004\ntype: uint16\ndimension: 3\nsizes: 4 4 4\nendian: little\nencoding: raw\n\n";
    let e = err_of(dir.path(), h, &[0; 100]);
    assert!(e.contains("expected 128 bytes, found 100"), "{e}");
    // Truncated gzip: a complete stream that is too short, and a stream cut off.
    let h = "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 64 64 64\nencoding: gzip\n\n";
    let e = err_of(dir.path(), h, &gz(&[7; 1000]));
    assert!(e.contains("expected 262144 bytes, found 1000"), "{e}");
    let full: Vec<u8> = (0..262144u32).map(|i| (i * 7919 % 251) as u8).collect();
    let z = gz(&full);
    assert!(read_nrrd(file(dir.path(), "ok.nrrd", h, &z)).is_ok());
    let e = err_of(dir.path(), h, &z[..z.len() / 2]);
    assert!(
        e.contains("truncated") && e.contains("expected 262144 bytes"),
        "{e}"
    );
    let e = err_of(dir.path(), h, &z[..z.len() - 4]);
    assert!(e.contains("gzip"), "{e}");
    // Corrupt gzip.
    let mut bad = z.clone();
    for b in &mut bad[20..60] {
        *b ^= 0x5a;
    }
    let e = err_of(dir.path(), h, &bad);
    assert!(e.contains("gzip"), "{e}");
    // byte skip beyond the data, byte skip -1 on a short file, line skip past the end.
    let h = "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2 2\nencoding: raw\nbyte skip: 5\n\n";
    let e = err_of(dir.path(), h, &[0; 8]);
    assert!(e.contains("expected 8 bytes, found 3"), "{e}");
    let h = "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2 2\nencoding: raw\nbyte skip: -1\n\n";
    let e = err_of(dir.path(), h, &[0; 7]);
    assert!(
        e.contains("byte skip") && e.contains("expected 8 bytes"),
        "{e}"
    );
    let h = "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2 2\nencoding: raw\nline skip: 3\n\n";
    let e = err_of(dir.path(), h, b"a\nb\n");
    assert!(
        e.contains("line skip") && e.contains("expected 3 lines"),
        "{e}"
    );
}

/// Fuzzing regression (issue 13): a product of sizes overflowing even u128 was accepted.
#[test]
fn overflowing_sizes_are_an_error_naming_the_field() {
    let dir = tempfile::tempdir().unwrap();
    for sizes in [
        "sizes: 9223372036854775808 9223372036854775808 4",
        "sizes: 18446744073709551615 18446744073709551615 18446744073709551615",
    ] {
        let h = header_with("sizes", Some(sizes));
        let e = err_of(dir.path(), &h, &[0; 8]);
        assert!(
            e.contains("`sizes`") && e.contains("exceeds the limit"),
            "{e}"
        );
    }
    // A caller-set limit applies.
    let h = header_with("sizes", None).replace("NRRD0004\n", "NRRD0004\nsizes: 4 4 4\n");
    let p = file(dir.path(), "l.nrrd", &h, &[0; 64]);
    assert!(read_nrrd(&p).is_ok());
    let small = Limits {
        max_voxels: 63,
        ..Limits::default()
    };
    let e = read_nrrd_with(&p, &ReadOptions::default().with_limits(small.clone()))
        .unwrap_err()
        .to_string();
    assert!(e.contains("exceeds the limit 63"), "{e}");
    let small = Limits {
        max_header_bytes: 20,
        ..Limits::default()
    };
    let e = read_nrrd_with(&p, &ReadOptions::default().with_limits(small.clone()))
        .unwrap_err()
        .to_string();
    assert!(e.contains("header size"), "{e}");
}

/// Fuzzing regression (issue 13): `data file: /dev/zero` with `line skip` read forever.
#[test]
#[cfg(unix)]
fn device_data_files_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    for extra in ["line skip: 1\n", "", "encoding: gzip\n"] {
        let enc = if extra.starts_with("encoding") {
            ""
        } else {
            "encoding: raw\n"
        };
        let h = format!(
            "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2 2\n{enc}{extra}data file: /dev/zero\n"
        );
        let p = file(dir.path(), "z.nhdr", &h, b"");
        let e = read_nrrd(&p).unwrap_err().to_string();
        assert!(
            e.contains("/dev/zero") && e.contains("not a regular file"),
            "{e}"
        );
    }
    // The header itself must be a file too.
    let e = read_nrrd("/dev/zero").unwrap_err().to_string();
    assert!(e.contains("not a regular file"), "{e}");
    let e = read_nrrd(dir.path()).unwrap_err().to_string();
    assert!(e.contains("directory"), "{e}");
}

/// Line skipping stops at the end of the file as found, whatever `line skip` says.
#[test]
fn huge_line_skip_ends_at_the_end_of_the_file() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("d.raw"), vec![b'\n'; 100]).unwrap();
    let h = "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n\
             data file: d.raw\nline skip: 18446744073709551615\n";
    let e = read_nrrd(file(dir.path(), "s.nhdr", h, b""))
        .unwrap_err()
        .to_string();
    assert!(e.contains("line skip") && e.contains("found 100"), "{e}");
}

/// Fuzzing regression (issue 13): spacings below 1e-154 or above 1e154 did not round-trip
/// (the vector length squared under- or overflowed).
#[test]
fn extreme_spacings_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    for s in [1e-160, 3e-300, 1e154, 1e200, 1.7e300] {
        let grid = Grid::new([2, 1, 1], [s, 1.0, s * 0.5], [s, -s, 0.0], DMat3::IDENTITY).unwrap();
        let v: AnyVolume = volsplat_core::Volume::new(grid, vec![1u8, 2])
            .unwrap()
            .into();
        let p = dir.path().join("s.nrrd");
        write_nrrd(&p, &v, false).unwrap();
        let back = read_nrrd(&p).unwrap();
        assert_eq!(back.grid(), v.grid(), "spacing {s}");
        // A rotated direction too (to within a few ulps).
        let c = std::f64::consts::FRAC_1_SQRT_2;
        let rot = DMat3::from_cols(DVec3::new(c, c, 0.0), DVec3::new(-c, c, 0.0), DVec3::Z);
        let grid = Grid::new([2, 1, 1], [s, 2.0 * s, 1.0], [0.0; 3], rot).unwrap();
        let v: AnyVolume = volsplat_core::Volume::new(grid, vec![1u8, 2])
            .unwrap()
            .into();
        write_nrrd(&p, &v, false).unwrap();
        let back = read_nrrd(&p).unwrap();
        for a in 0..3 {
            let (x, y) = (back.grid().spacing[a], v.grid().spacing[a]);
            assert!((x - y).abs() <= 4.0 * f64::EPSILON * y, "{x} vs {y}");
        }
    }
}

/// Issue 28 §5: a file without `space` says that its axes are taken as LPS; one with a
/// `space` says nothing of the kind.
#[test]
fn missing_space_is_noted_as_lps() {
    let dir = tempfile::tempdir().unwrap();
    let h = "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 1 1\nencoding: raw\n\n";
    let p = file(dir.path(), "n.nrrd", h, &[1, 2]);
    let notes = read_nrrd_with(&p, &ReadOptions::default()).unwrap().notes;
    assert!(
        notes
            .iter()
            .any(|n| n.contains("no `space` field") && n.contains("LPS")),
        "{notes:?}"
    );
    let h = h.replace("dimension: 3\n", "dimension: 3\nspace dimension: 3\n");
    let p = file(dir.path(), "d.nrrd", &h, &[1, 2]);
    let notes = read_nrrd_with(&p, &ReadOptions::default()).unwrap().notes;
    assert!(
        notes.iter().any(|n| n.contains("no `space` field")),
        "{notes:?}"
    );
    let h = h.replace("space dimension: 3", "space: LPS");
    let p = file(dir.path(), "l.nrrd", &h, &[1, 2]);
    let notes = read_nrrd_with(&p, &ReadOptions::default()).unwrap().notes;
    assert!(notes.is_empty(), "{notes:?}");
    // What write_nrrd writes reads back without the note.
    let v = read_nrrd(&p).unwrap();
    let q = dir.path().join("w.nrrd");
    write_nrrd(&q, &v, false).unwrap();
    let LoadedVolume {
        volume: back,
        notes,
        ..
    } = read_nrrd_with(&q, &ReadOptions::default()).unwrap();
    assert!(notes.is_empty(), "{notes:?}");
    assert_eq!(back, v);
}

/// `space: RAS` files are converted to LPS (decision 0008).
#[test]
fn ras_space_is_converted_to_lps() {
    let dir = tempfile::tempdir().unwrap();
    let h = "NRRD0004\ntype: uint8\ndimension: 3\nspace: right-anterior-superior\n\
             sizes: 2 1 1\nspace directions: (0.5,0,0) (0,2,0) (0,0,3)\n\
             space origin: (10,20,30)\nencoding: raw\n\n";
    let LoadedVolume {
        volume: v, notes, ..
    } = read_nrrd_with(
        file(dir.path(), "r.nrrd", h, &[1, 2]),
        &ReadOptions::default(),
    )
    .unwrap();
    let g = v.grid();
    assert_eq!(g.origin, [-10.0, -20.0, 30.0]);
    assert_eq!(g.spacing, [0.5, 2.0, 3.0]);
    assert_eq!(
        g.direction,
        DMat3::from_diagonal(DVec3::new(-1.0, -1.0, 1.0))
    );
    assert!(notes[0].contains("LPS"), "{notes:?}");
    let h = h.replace("right-anterior-superior", "LPS");
    let v = read_nrrd(file(dir.path(), "l.nrrd", &h, &[1, 2])).unwrap();
    assert_eq!(v.grid().origin, [10.0, 20.0, 30.0]);
    assert_eq!(v.grid().direction, DMat3::IDENTITY);
}

#[test]
fn sizes_are_checked_before_allocating() {
    let dir = tempfile::tempdir().unwrap();
    let h = header_with("sizes", Some("sizes: 100000 100000 100000"));
    let e = err_of(dir.path(), &h, &[0; 8]);
    assert!(
        e.contains("sizes") && e.contains("exceeds the limit"),
        "{e}"
    );
    let h = header_with("sizes", Some("sizes: 18446744073709551615 2 2"));
    let e = err_of(dir.path(), &h, &[0; 8]);
    assert!(e.contains("sizes"), "{e}");
    // Within MAX_VOXELS but far larger than the file (8 GiB): rejected from the file size,
    // without allocating.
    let h = header_with("sizes", Some("sizes: 2048 2048 2048"));
    let e = err_of(dir.path(), &h, &[0; 8]);
    assert!(e.contains("expected 8589934592 bytes, found 8"), "{e}");
    // Same with gzip: the buffer only grows with the data actually decompressed.
    let h = "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2048 2048 2048\nencoding: gzip\n\n";
    let e = err_of(dir.path(), h, &gz(&[1; 4096]));
    assert!(e.contains("expected 8589934592 bytes, found 4096"), "{e}");
}

#[test]
fn header_errors_name_the_field() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let cases: Vec<(String, &str)> = vec![
        (header_with("sizes", None), "missing required field `sizes`"),
        (header_with("type", None), "missing required field `type`"),
        (
            header_with("encoding", None),
            "missing required field `encoding`",
        ),
        (
            header_with("dimension", None),
            "missing required field `dimension`",
        ),
        (
            header_with("type", Some("type: uint16")).replace("endian: little\n", ""),
            "missing required field `endian`",
        ),
        (header_with("sizes", Some("sizes: 2 x 2")), "field `sizes`"),
        (header_with("sizes", Some("sizes: 2 0 2")), "field `sizes`"),
        (header_with("sizes", Some("sizes: 2 2")), "field `sizes`"),
        (
            header_with("dimension", Some("dimension: three")),
            "field `dimension`",
        ),
        (
            header_with("dimension", Some("dimension: 2")),
            "field `dimension`",
        ),
        (
            header_with("dimension", Some("dimension: 4")),
            "field `dimension`",
        ),
        (
            header_with("type", Some("type: int64")),
            "field `type`: unsupported value \"int64\"",
        ),
        (header_with("type", Some("type: block")), "field `type`"),
        (
            header_with("encoding", Some("encoding: bzip2")),
            "field `encoding`: unsupported value \"bzip2\"",
        ),
        (
            header_with("encoding", Some("encoding: hex")),
            "field `encoding`",
        ),
        (
            header_with("endian", Some("endian: middle")),
            "field `endian`",
        ),
        (
            header_with("endian", Some("spacings: 1 -")),
            "field `spacings`",
        ),
        (
            header_with("endian", Some("spacings: 1 0 1")),
            "field `spacings`",
        ),
        (
            header_with("endian", Some("space origin: (1,a,0)")),
            "field `space origin`",
        ),
        (
            header_with("endian", Some("space origin: 1 2 3")),
            "field `space origin`",
        ),
        (
            header_with("endian", Some("space origin: (1,2)")),
            "field `space origin`",
        ),
        (
            header_with("endian", Some("byte skip: abc")),
            "field `byte skip`",
        ),
        (
            header_with("endian", Some("byte skip: -2")),
            "field `byte skip`",
        ),
        (
            header_with("endian", Some("line skip: -1")),
            "field `line skip`",
        ),
        (header_with("endian", Some("space: RAST")), "field `space`"),
        (
            header_with("endian", Some("space: martian")),
            "field `space`",
        ),
        (
            header_with("endian", Some("space dimension: 2")),
            "field `space dimension`",
        ),
        (
            header_with("endian", Some("space directions: (1,0,0) (0,1,0)")),
            "field `space directions`",
        ),
        (
            header_with("endian", Some("space directions: (1,0,0) (0,0,0) (0,0,1)")),
            "field `space directions`",
        ),
        (
            header_with("endian", Some("space directions: (1,0,0) (1,1,0) (0,0,1)")),
            "field `space directions`: invalid value \"(1,0,0) (1,1,0) (0,0,1)\": axis directions must be mutually orthogonal",
        ),
        (
            header_with(
                "endian",
                Some("space directions: (1,0,0) (0,1,0) (0,0,1,0)"),
            ),
            "field `space directions`",
        ),
        (
            header_with("endian", Some("data file: LIST")),
            "field `data file`",
        ),
        (
            header_with("endian", Some("data file: slice%03d.raw 1 10 1")),
            "field `data file`",
        ),
        (header_with("endian", Some("no colon here")), "line 6"),
        (header_with("endian", Some(": value")), "empty field name"),
        (header_with("endian", Some("sizes: 2 2 2")), "given twice"),
        (
            header_with("encoding", Some("encoding: gzip\nbyte skip: -1")),
            "field `byte skip`",
        ),
        ("NRRD0006\ntype: uint8\n\n".to_string(), "not a NRRD file"),
        ("P5 2 2 255\n".to_string(), "not a NRRD file"),
    ];
    for (h, want) in &cases {
        let e = err_of(d, h, &[0; 8]);
        assert!(e.contains(want), "want {want:?} in: {e}");
    }
    let e = err_of(d, "", b"");
    assert!(e.contains("empty file"), "{e}");
    // A float payload with no finite sample (a NaN sample alone is read: decision 0030).
    let h = header_with("type", Some("type: float"));
    let h = h.replace("sizes: 2 2 2", "sizes: 2 1 1");
    let mut data = f32::INFINITY.to_le_bytes().to_vec();
    data.extend_from_slice(&f32::NAN.to_le_bytes());
    let e = err_of(d, &h, &data);
    assert!(e.contains("no sample is finite"), "{e}");
}

#[test]
fn data_file_problems() {
    let dir = tempfile::tempdir().unwrap();
    let h = "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n";
    let e = read_nrrd(file(dir.path(), "m.nhdr", h, b"")).unwrap_err();
    assert!(
        e.to_string().contains("missing required field `data file`"),
        "{e}"
    );
    let h2 = format!("{h}data file: nowhere.raw\n");
    let e = read_nrrd(file(dir.path(), "m.nhdr", &h2, b"")).unwrap_err();
    assert!(e.to_string().contains("nowhere.raw"), "{e}");
    let e = read_nrrd(dir.path().join("absent.nrrd")).unwrap_err();
    assert!(e.to_string().contains("absent.nrrd"), "{e}");
}

#[test]
fn huge_header_is_rejected() {
    let dir = tempfile::tempdir().unwrap();
    let mut h = String::from("NRRD0004\n");
    while h.len() <= crate::MAX_HEADER_BYTES {
        h.push_str("# padding padding padding padding padding padding padding padding\n");
    }
    let e = err_of(dir.path(), &h, b"");
    assert!(e.contains("header size") && e.contains("1048576"), "{e}");
    // One line longer than the limit (no newline at all).
    let long = format!("NRRD0004\n# {}", "x".repeat(crate::MAX_HEADER_BYTES + 10));
    let e = err_of(dir.path(), &long, b"");
    assert!(e.contains("header size"), "{e}");
}

const BRAINSMALL: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../../shared/data/mri_brainsmall.nrrd"
);
const COLIN27: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../../shared/data/mri_colin27.nhdr"
);

#[test]
fn real_data_brainsmall() {
    if !Path::new(BRAINSMALL).exists() {
        eprintln!("note: {BRAINSMALL} not found; skipping");
        return;
    }
    let v = crate::read_volume(BRAINSMALL).unwrap();
    assert_eq!(v.scalar_type(), ScalarType::U8);
    assert_eq!(v.grid().dims, [128, 128, 84]);
    assert_eq!(v.grid().spacing, [1.0; 3]);
    let (lo, hi) = v.value_range();
    assert!(lo < 10.0 && hi > 100.0, "range {lo}..{hi}");
    // Round trip through our writer.
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("b.nrrd");
    write_nrrd(&p, &v, true).unwrap();
    assert_eq!(read_nrrd(&p).unwrap(), v);
}

#[test]
fn real_data_colin27() {
    if !Path::new(COLIN27).exists() {
        eprintln!("note: {COLIN27} not found; skipping");
        return;
    }
    let v = crate::read_volume(COLIN27).unwrap();
    assert_eq!(v.scalar_type(), ScalarType::U8);
    assert_eq!(v.grid().dims, [181, 217, 181]);
    assert_eq!(v.grid().spacing, [1.0; 3]);
    let (lo, hi) = v.value_range();
    assert!(lo < 10.0 && hi > 100.0, "range {lo}..{hi}");
    let mean =
        v.to_f32().data().iter().map(|&x| x as f64).sum::<f64>() / v.grid().voxel_count() as f64;
    assert!(mean > 5.0, "mean {mean}");
}

/// Issue 29 item 5: a detached header in a folder the read is confined to (a viewer's
/// `--data-dir`) cannot read a file outside it, whichever way its `data file` names it.
#[test]
fn confined_reads_refuse_data_files_outside_the_folder() {
    use crate::confine::tests::{assert_outside, layout};
    let l = layout(&[1, 2, 3, 4]);
    let secret = l.secret.display().to_string();
    let mut cases = vec![
        ("data file", "inside.raw", true),
        ("data file", "./inside.raw", true),
        ("data file", "../secret.raw", false),
        ("datafile", "../data/../secret.raw", false),
        ("data file", secret.as_str(), false),
        ("data file", "../no-such.raw", false),
    ];
    if cfg!(unix) {
        cases.push(("data file", "link.raw", false));
    }
    for (field, value, inside) in cases {
        let header = format!(
            "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 1\nencoding: raw\n{field}: {value}\n"
        );
        let p = file(&l.data, "escape.nhdr", &header, b"");
        if value != "../no-such.raw" {
            // Not confined, every one reads the bytes (the confinement makes the difference).
            let v = read_nrrd(&p).unwrap_or_else(|e| panic!("{value}: {e}"));
            assert_eq!(v.to_f32().data(), &[1.0, 2.0, 3.0, 4.0], "{value}");
        }
        let r = read_nrrd_with(&p, &ReadOptions::default().with_limits(l.limits.clone()))
            .map(|l| l.volume);
        if inside {
            let v = r.unwrap_or_else(|e| panic!("{value}: {e}"));
            assert_eq!(v.to_f32().data(), &[1.0, 2.0, 3.0, 4.0], "{value}");
        } else {
            let e = r.unwrap_err();
            assert_outside(&e, "escape.nhdr", &format!("`{field}`"), value, &l);
        }
    }
    // A file outside the folder (the one a user names) is read as without it.
    let p = file(
        l.root.path(),
        "user.nhdr",
        "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 1\nencoding: raw\ndata file: secret.raw\n",
        b"",
    );
    assert_eq!(
        read_nrrd_with(&p, &ReadOptions::default().with_limits(l.limits.clone()))
            .unwrap()
            .volume
            .to_f32()
            .data(),
        &[1.0, 2.0, 3.0, 4.0]
    );
}
