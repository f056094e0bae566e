use super::*;
use crate::nrrd::read_nrrd;
use std::io::Write;
use volsplat_core::{AnyVolume, CoreError, InMemory, Volume};

/// How a test file lays its payload out.
#[derive(Debug, Clone, Copy)]
struct Layout {
    /// `.nhdr` with a `data file`.
    detached: bool,
    big_endian: bool,
    /// Junk lines before the payload (`line skip`).
    line_skip: usize,
    /// Junk bytes before the payload (`byte skip`), or -1: junk, then the payload at the end.
    byte_skip: i64,
}

const PLAIN: Layout = Layout {
    detached: false,
    big_endian: false,
    line_skip: 0,
    byte_skip: 0,
};

/// Sample `(i, j, k)` in the file's type, distinct-ish and signed where the type is.
fn value(ty: &str, i: usize, j: usize, k: usize) -> f64 {
    let v = ((i * 7 + j * 13 + k * 101) % 251) as f64;
    match ty {
        "uint8" | "uint16" | "uint32" => v + if ty == "uint8" { 0.0 } else { 300.0 * k as f64 },
        "float" | "double" => (v - 100.0) * 0.37,
        _ => v - 100.0 - 50.0 * k as f64,
    }
}

fn encode(ty: &str, x: f64, big: bool) -> Vec<u8> {
    macro_rules! b {
        ($v:expr) => {
            if big {
                $v.to_be_bytes().to_vec()
            } else {
                $v.to_le_bytes().to_vec()
            }
        };
    }
    match ty {
        "uint8" => vec![x as u8],
        "int8" => vec![x as i8 as u8],
        "uint16" => b!(x as u16),
        "int16" => b!(x as i16),
        "int32" => b!(x as i32),
        "uint32" => b!(x as u32),
        "float" => b!(x as f32),
        "double" => b!(x),
        _ => unreachable!(),
    }
}

/// Writes a NRRD file of `dims` samples of `ty` (`values(i, j, k)`) laid out as `layout`;
/// returns the header's path.
fn write(
    dir: &Path,
    name: &str,
    ty: &str,
    dims: [usize; 3],
    layout: Layout,
    values: &dyn Fn(usize, usize, usize) -> f64,
) -> PathBuf {
    let mut payload = Vec::new();
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                payload.extend(encode(ty, values(i, j, k), layout.big_endian));
            }
        }
    }
    let mut data = Vec::new();
    for l in 0..layout.line_skip {
        data.extend(format!("junk line {l} of the skip\n").bytes());
    }
    let skip = if layout.byte_skip < 0 {
        13
    } else {
        layout.byte_skip as usize
    };
    data.extend((0..skip).map(|b| (b * 37 % 256) as u8));
    data.extend(&payload);
    let mut header = format!(
        "NRRD0004\ntype: {ty}\ndimension: 3\nspace: left-posterior-superior\n\
         sizes: {} {} {}\nspace directions: (0.5,0,0) (0,0.75,0) (0,0,1.25)\n\
         space origin: (1,-2,3)\nencoding: raw\nendian: {}\nline skip: {}\nbyte skip: {}\n",
        dims[0],
        dims[1],
        dims[2],
        if layout.big_endian { "big" } else { "little" },
        layout.line_skip,
        layout.byte_skip
    );
    if layout.detached {
        let raw = dir.join(format!("{name}.raw"));
        std::fs::write(&raw, &data).unwrap();
        header.push_str(&format!("data file: {name}.raw\n"));
        let p = dir.join(format!("{name}.nhdr"));
        std::fs::write(&p, header).unwrap();
        p
    } else {
        header.push('\n');
        let p = dir.join(format!("{name}.nrrd"));
        let mut f = std::fs::File::create(&p).unwrap();
        f.write_all(header.as_bytes()).unwrap();
        f.write_all(&data).unwrap();
        p
    }
}

fn keys(l: &BrickLayout) -> Vec<BrickKey> {
    let d = l.dims();
    let mut out = Vec::new();
    for k in 0..d[2] {
        for j in 0..d[1] {
            for i in 0..d[0] {
                out.push(l.key([i, j, k]).unwrap());
            }
        }
    }
    out
}

/// Every brick of `source` equals the brick of `whole` served in memory; returns the bricks.
fn assert_bricks<T: Scalar>(whole: Volume<T>, source: &NrrdSource<T>, size: usize, label: &str) {
    let mem = InMemory::new(Arc::new(whole), size).unwrap();
    let l = source.layout(0).unwrap();
    assert_eq!(l, mem.layout(0).unwrap(), "{label}");
    assert!(source.whole(0).unwrap().is_none());
    for key in keys(l) {
        let got = source.brick(key).unwrap();
        assert_eq!(*got, *mem.brick(key).unwrap(), "{label} {key:?}");
    }
}

/// Every brick of every file equals the brick of the file read whole (`read_nrrd`, the volume
/// in memory): each type, both byte orders, attached and detached, line and byte skips
/// (`-1` too), odd sizes, axes of one and two samples, two brick sizes; the grid and type the
/// header gives are the whole read's.
#[test]
fn every_brick_equals_the_brick_of_the_file_read_whole() {
    let dir = tempfile::tempdir().unwrap();
    let layouts = [
        PLAIN,
        Layout {
            big_endian: true,
            ..PLAIN
        },
        Layout {
            detached: true,
            byte_skip: 7,
            ..PLAIN
        },
        Layout {
            line_skip: 2,
            byte_skip: 3,
            big_endian: true,
            ..PLAIN
        },
        Layout {
            detached: true,
            byte_skip: -1,
            ..PLAIN
        },
    ];
    let mut n = 0;
    for (t, ty) in [
        "uint8", "int8", "uint16", "int16", "float", "int32", "uint32", "double",
    ]
    .into_iter()
    .enumerate()
    {
        for (d, dims) in [[37, 20, 9], [1, 5, 19], [2, 1, 2], [18, 2, 1], [9, 17, 33]]
            .into_iter()
            .enumerate()
        {
            for (x, layout) in layouts.into_iter().enumerate() {
                if (t + d + x) % 2 == 1 && dims != [37, 20, 9] {
                    continue; // A sample of the combinations keeps the test short.
                }
                let name = format!("v{t}_{d}_{x}");
                let path = write(dir.path(), &name, ty, dims, layout, &|i, j, k| {
                    value(ty, i, j, k)
                });
                let label = format!("{ty} {dims:?} {layout:?}");
                let whole = read_nrrd(&path).unwrap();
                let header = NrrdHeader::open(&path, &Limits::default()).unwrap();
                assert_eq!(header.grid(), whole.grid(), "{label}");
                assert_eq!(header.scalar_type(), whole.scalar_type(), "{label}");
                assert!(header.is_raw());
                for size in [8, 16] {
                    match &whole {
                        AnyVolume::U8(v) => {
                            assert_bricks(v.clone(), &header.source(size).unwrap(), size, &label)
                        }
                        AnyVolume::I8(v) => {
                            assert_bricks(v.clone(), &header.source(size).unwrap(), size, &label)
                        }
                        AnyVolume::U16(v) => {
                            assert_bricks(v.clone(), &header.source(size).unwrap(), size, &label)
                        }
                        AnyVolume::I16(v) => {
                            assert_bricks(v.clone(), &header.source(size).unwrap(), size, &label)
                        }
                        AnyVolume::F32(v) => {
                            assert_bricks(v.clone(), &header.source(size).unwrap(), size, &label)
                        }
                    }
                    n += 1;
                }
            }
        }
    }
    assert!(n > 60, "{n} files");
}

/// Each brick reads its halo box only: the bytes read are the boxes' (rows, or whole slabs),
/// never the whole payload for a volume of several bricks.
#[test]
fn a_brick_reads_only_its_halo_box() {
    let dir = tempfile::tempdir().unwrap();
    let dims = [40, 30, 20];
    let path = write(dir.path(), "b", "uint16", dims, PLAIN, &|i, j, k| {
        value("uint16", i, j, k)
    });
    let source = NrrdHeader::open(&path, &Limits::default())
        .unwrap()
        .source::<u16>(16)
        .unwrap();
    let l = source.layout(0).unwrap().clone();
    assert_eq!(l.dims(), [3, 2, 2]);
    let mut total = 0;
    for key in keys(&l) {
        let before = source.bytes_read();
        source.brick(key).unwrap();
        let h = l.halo_voxels(key).unwrap();
        let want = (h.iter().map(|r| r.len()).product::<usize>() * 2) as u64;
        assert_eq!(source.bytes_read() - before, want, "{key:?}");
        total += want;
    }
    assert_eq!(source.bytes_read(), total);
    // The first brick's box: 18 × 18 × 18 samples of 40 × 30 × 20.
    assert_eq!(l.halo_voxels(l.key([0, 0, 0]).unwrap()).unwrap()[0], 0..18);
}

/// A float file with NaN and ±∞: bricks holding them are an error until the volume's finite
/// range is given; with it, every brick equals the brick of the file read whole (where
/// `Volume::new` replaced them); served as stored, they keep them.
#[test]
fn non_finite_floats_need_the_finite_range_then_match_the_whole_read() {
    let dir = tempfile::tempdir().unwrap();
    let dims = [21, 19, 10];
    let special = |i: usize, j: usize, k: usize| match (i + 3 * j + 5 * k) % 97 {
        0 => f64::NAN,
        1 => f64::INFINITY,
        2 => f64::NEG_INFINITY,
        _ => value("float", i, j, k),
    };
    for ty in ["float", "double"] {
        let path = write(dir.path(), ty, ty, dims, PLAIN, &special);
        let whole = read_nrrd(&path).unwrap();
        let AnyVolume::F32(whole) = whole else {
            panic!("float")
        };
        let nf = *whole.non_finite().unwrap();
        assert!(nf.nan > 0 && nf.pos_inf > 0 && nf.neg_inf > 0, "{nf:?}");
        let source = NrrdHeader::open(&path, &Limits::default())
            .unwrap()
            .source::<f32>(8)
            .unwrap();
        let l = source.layout(0).unwrap().clone();
        let mut refused = 0;
        for key in keys(&l) {
            match source.brick(key) {
                Ok(b) => assert!(b.data.iter().all(|v| v.is_finite())),
                Err(e) => {
                    assert!(matches!(e, CoreError::Brick { .. }), "{e}");
                    let s = e.to_string();
                    assert!(
                        s.contains(&format!("{ty}.nrrd")) && s.contains("NaN"),
                        "{s}"
                    );
                    refused += 1;
                }
            }
        }
        assert!(refused > 0);
        let stored = source.as_stored();
        assert!(
            keys(&l)
                .iter()
                .any(|&k| stored.brick(k).unwrap().data.iter().any(|v| v.is_nan()))
        );
        let e = source
            .clone()
            .with_finite_range([1.0, f32::NAN])
            .unwrap_err();
        assert!(e.to_string().contains("finite range"), "{e}");
        let fixed = source.with_finite_range([nf.lowest, nf.highest]).unwrap();
        assert_bricks(whole, &fixed, 8, ty);
    }
}

/// A data file shorter than the header's sizes is an error naming it when the header is
/// opened; a file cut short after it was opened makes the bricks past the cut errors naming
/// it (never a panic, never zeros).
#[test]
fn a_truncated_file_is_an_error_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let dims = [20, 20, 20];
    for detached in [false, true] {
        let name = if detached { "cut_d" } else { "cut_a" };
        let layout = Layout { detached, ..PLAIN };
        let path = write(dir.path(), name, "int16", dims, layout, &|i, j, k| {
            value("int16", i, j, k)
        });
        let data = if detached {
            dir.path().join(format!("{name}.raw"))
        } else {
            path.clone()
        };
        let len = std::fs::metadata(&data).unwrap().len();
        let source = NrrdHeader::open(&path, &Limits::default())
            .unwrap()
            .source::<i16>(8)
            .unwrap();
        // Cut half way: the header opened before still serves the first bricks, then errors.
        let f = std::fs::OpenOptions::new().write(true).open(&data).unwrap();
        f.set_len(len - 8000).unwrap();
        let l = source.layout(0).unwrap().clone();
        let first = source.brick(l.key([0, 0, 0]).unwrap()).unwrap();
        assert_eq!(first.data.len(), l.slot_len());
        let e = source.brick(l.key([2, 2, 2]).unwrap()).unwrap_err();
        let s = e.to_string();
        assert!(
            s.contains(data.file_name().unwrap().to_str().unwrap()) && s.contains("truncated"),
            "{s}"
        );
        // Opened again: refused at once, naming the data file.
        let e = NrrdHeader::open(&path, &Limits::default()).unwrap_err();
        let s = e.to_string();
        assert!(
            s.contains(data.file_name().unwrap().to_str().unwrap()) && s.contains("truncated"),
            "{s}"
        );
    }
}

/// A gzip payload has no random access: the header opens (grid and type, for reading whole),
/// the brick source is refused naming the encoding; the wrong sample type is refused naming
/// `type`.
#[test]
fn gzip_payloads_and_wrong_types_are_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let v: AnyVolume = Volume::from_fn(Grid::with_dims([9, 9, 9]).unwrap(), |i, j, k| {
        (i + j + k) as u16
    })
    .unwrap()
    .into();
    let gz = dir.path().join("g.nrrd");
    crate::write_nrrd(&gz, &v, true).unwrap();
    let h = NrrdHeader::open(&gz, &Limits::default()).unwrap();
    assert!(!h.is_raw());
    assert_eq!(h.grid().dims, [9, 9, 9]);
    let e = h.source::<u16>(8).unwrap_err().to_string();
    assert!(e.contains("g.nrrd") && e.contains("gzip"), "{e}");
    let raw = dir.path().join("r.nrrd");
    crate::write_nrrd(&raw, &v, false).unwrap();
    let h = NrrdHeader::open(&raw, &Limits::default()).unwrap();
    let e = h.source::<f32>(8).unwrap_err().to_string();
    assert!(e.contains("r.nrrd") && e.contains("type"), "{e}");
    let e = h.source::<u16>(12).unwrap_err().to_string();
    assert!(e.contains("brick size"), "{e}");
}
