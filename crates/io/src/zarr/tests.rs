//! OME-Zarr read and write: stores written by [`write_zarr`] and hand-written fixtures
//! (hostile metadata, missing and corrupt chunks, multi-dimensional images).

use super::*;
use crate::{IoError, Limits, ReadOptions, read_volume_with};
use serde_json::{Value, json};
use std::path::{Path, PathBuf};
use volsplat_core::glam::DMat3;
use volsplat_core::{AnyVolume, Grid, Volume};

fn ramp_u16(dims: [usize; 3]) -> Volume<u16> {
    let grid = Grid::new(dims, [0.5, 0.75, 2.0], [-3.0, 4.0, 10.5], DMat3::IDENTITY).unwrap();
    Volume::from_fn(grid, |i, j, k| ((i * 7 + j * 13 + k * 101) % 4099) as u16).unwrap()
}

fn opts() -> ReadOptions {
    ReadOptions::default()
}

/// A hand-written OME-Zarr v0.4 store: `.zgroup`, `.zattrs` with `multiscales`, and one
/// uncompressed v2 array per level (`compressor: null`, chunks = the whole array, written as
/// raw little-endian bytes in C order).
struct Fixture {
    _dir: tempfile::TempDir,
    path: PathBuf,
}

impl Fixture {
    fn new(multiscales: Value) -> Self {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("f.zarr");
        std::fs::create_dir(&path).unwrap();
        std::fs::write(path.join(".zgroup"), r#"{"zarr_format": 2}"#).unwrap();
        std::fs::write(
            path.join(".zattrs"),
            json!({ "multiscales": [multiscales] }).to_string(),
        )
        .unwrap();
        Fixture { _dir: dir, path }
    }

    /// Array `name` of `shape` with dtype `dtype` and `bytes` as its single chunk (none when
    /// `None`), fill value `fill`.
    fn array(&self, name: &str, shape: &[u64], dtype: &str, fill: Value, bytes: Option<&[u8]>) {
        let d = self.path.join(name);
        std::fs::create_dir_all(&d).unwrap();
        // One chunk holding everything where bytes are given; else chunks of at most 64.
        let chunks: Vec<u64> = match bytes {
            Some(_) => shape.to_vec(),
            None => shape.iter().map(|&n| n.clamp(1, 64)).collect(),
        };
        let meta = json!({
            "zarr_format": 2, "shape": shape, "chunks": chunks, "dtype": dtype,
            "compressor": null, "fill_value": fill, "order": "C", "filters": null,
            "dimension_separator": "/"
        });
        std::fs::write(d.join(".zarray"), meta.to_string()).unwrap();
        if let Some(b) = bytes {
            let mut p = d.clone();
            for _ in 0..shape.len() - 1 {
                p = p.join("0");
            }
            std::fs::create_dir_all(&p).unwrap();
            std::fs::write(p.join("0"), b).unwrap();
        }
    }
}

fn axes(names: &str) -> Value {
    Value::Array(
        names
            .chars()
            .map(|c| {
                let t = match c {
                    't' => "time",
                    'c' => "channel",
                    _ => "space",
                };
                if t == "space" {
                    json!({ "name": c.to_string(), "type": t, "unit": "micrometer" })
                } else {
                    json!({ "name": c.to_string(), "type": t })
                }
            })
            .collect(),
    )
}

fn level(path: &str, scale: Value, translation: Value) -> Value {
    json!({ "path": path, "coordinateTransformations": [
        { "type": "scale", "scale": scale },
        { "type": "translation", "translation": translation } ] })
}

/// A t=2, c=3, z=2, y=2, x=3 uint8 image whose sample is 100·t + 10·c + (x + 3y + 6z).
fn five_d() -> Fixture {
    let f = Fixture::new(json!({
        "version": "0.4", "axes": axes("tczyx"),
        "datasets": [level("0", json!([1.0, 1.0, 2.0, 0.5, 0.25]), json!([0.0, 0.0, 10.0, 20.0, 30.0]))]
    }));
    let mut bytes = Vec::new();
    for t in 0..2u8 {
        for c in 0..3u8 {
            for v in 0..12u8 {
                bytes.push(100 * t + 10 * c + v);
            }
        }
    }
    f.array("0", &[2, 3, 2, 2, 3], "|u1", json!(0), Some(&bytes));
    f
}

#[test]
fn converted_levels_equal_in_memory_levels() {
    let v = ramp_u16([150, 70, 40]);
    let any: AnyVolume = v.clone().into();
    for version in [ZarrVersion::V2, ZarrVersion::V3] {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("r.zarr");
        let o = ZarrWriteOptions::default()
            .with_version(version)
            .with_chunk(32);
        let w = write_zarr(&p, &any, &o).unwrap();
        // 150 → 76 → 39 → 21 along x (y, z join in as they catch up): stop when ≤ 32.
        assert_eq!(
            w.levels.iter().map(|g| g.dims).collect::<Vec<_>>(),
            vec![[150, 70, 40], [76, 36, 40], [39, 19, 21], [21, 11, 12]],
            "{version:?}"
        );
        let store = ZarrStore::open(&p, &Limits::default()).unwrap();
        assert_eq!(store.levels().len(), 4);
        let mut expect = v.clone();
        for l in 0..4 {
            if l > 0 {
                expect = expect.halved(expect.grid().pyramid_axes()).unwrap();
            }
            let o = opts().with_level(l);
            let got = read_volume_with(&p, &o).unwrap();
            let AnyVolume::U16(got) = got.volume else {
                panic!("type")
            };
            assert_eq!(got.data(), expect.data(), "{version:?} level {l} samples");
            let (g, e) = (got.grid(), expect.grid());
            assert_eq!(g.dims, e.dims);
            for a in 0..3 {
                assert!((g.spacing[a] - e.spacing[a]).abs() <= 1e-12 * e.spacing[a]);
                assert!((g.origin[a] - e.origin[a]).abs() <= 1e-12, "{l} {a}");
            }
            let chunks: Vec<u64> = [2, 1, 0]
                .iter()
                .map(|&a| e.dims[a].min(32) as u64)
                .collect();
            assert_eq!(store.levels()[l].chunks, chunks);
        }
        let l = read_volume_with(&p, &opts()).unwrap();
        let want = match version {
            ZarrVersion::V2 => "OME-Zarr 0.4 (Zarr v2)",
            _ => "OME-Zarr 0.5 (Zarr v3)",
        };
        assert_eq!(l.format, want);
    }
}

#[test]
fn regions_are_boxes_of_the_level() {
    let v = ramp_u16([70, 45, 33]);
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("r.zarr");
    write_zarr(
        &p,
        &v.clone().into(),
        &ZarrWriteOptions::default().with_chunk(16),
    )
    .unwrap();
    let s = ZarrStore::open(&p, &Limits::default()).unwrap();
    let (lo, hi) = ([5u64, 14, 9], [40u64, 33, 33]);
    let r = s
        .read_region::<u16>(0, ZarrSelection::default(), lo, hi)
        .unwrap();
    let mut k = 0;
    for z in lo[2]..hi[2] {
        for y in lo[1]..hi[1] {
            for x in lo[0]..hi[0] {
                assert_eq!(
                    r[k],
                    v.get(x as usize, y as usize, z as usize),
                    "{x} {y} {z}"
                );
                k += 1;
            }
        }
    }
    assert_eq!(k, r.len());
    // The wrong type, an empty or outside box: errors.
    let e = s
        .read_region::<u8>(0, ZarrSelection::default(), lo, hi)
        .unwrap_err();
    assert!(e.to_string().contains("uint16"), "{e}");
    let e = s
        .read_region::<u16>(0, ZarrSelection::default(), [0; 3], [71, 1, 1])
        .unwrap_err();
    assert!(e.to_string().contains("outside level 0"), "{e}");
    let e = s
        .read_region::<u16>(0, ZarrSelection::default(), [3; 3], [3, 4, 4])
        .unwrap_err();
    assert!(e.to_string().contains("empty"), "{e}");
}

#[test]
fn channels_and_timepoints_are_chosen_and_geometry_is_in_mm() {
    let f = five_d();
    let l = read_volume_with(&f.path, &opts().with_channel(2).with_timepoint(1)).unwrap();
    let v = l.volume.to_f32();
    assert_eq!(v.grid().dims, [3, 2, 2]);
    let want: Vec<f32> = (0..12).map(|s| (100 + 20 + s) as f32).collect();
    assert_eq!(v.data(), &want[..]);
    assert_eq!((l.frames, l.frame), (2, 1));
    // µm → mm: x scale 0.25 µm, y 0.5, z 2; translation 30, 20, 10 µm.
    assert_eq!(v.grid().spacing, [0.00025, 0.0005, 0.002]);
    assert_eq!(v.grid().origin, [0.03, 0.02, 0.01]);
    assert!(
        l.notes.iter().any(|n| n.contains("micrometer")),
        "{:?}",
        l.notes
    );
    assert!(
        l.notes.iter().any(|n| n.contains("channel 2 of 3")),
        "{:?}",
        l.notes
    );
    for (o, what) in [
        (
            opts().with_channel(3),
            "channel 3 requested, but the store holds 3",
        ),
        (
            opts().with_timepoint(2),
            "timepoint 2 requested, but the store holds 2",
        ),
        (
            opts().with_level(1),
            "level 1 requested, but the store holds 1 levels",
        ),
        (
            opts().with_frame(1),
            "time points are chosen with `timepoint`",
        ),
        (
            opts().with_series(Some("1".into())),
            "series applies to DICOM",
        ),
    ] {
        let e = read_volume_with(&f.path, &o).unwrap_err().to_string();
        assert!(e.contains(what) && e.contains("f.zarr"), "{e}");
    }
}

#[test]
fn zarr_options_are_refused_by_other_formats() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("v.nrrd");
    std::fs::write(
        &p,
        b"NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 1 1\nencoding: raw\n\n\x01\x02",
    )
    .unwrap();
    for (o, what) in [
        (opts().with_level(1), "level 1 requested"),
        (opts().with_channel(1), "channel 1 requested"),
        (opts().with_timepoint(1), "timepoint 1 requested"),
    ] {
        let e = read_volume_with(&p, &o).unwrap_err().to_string();
        assert!(e.contains(what) && e.contains("not to NRRD"), "{e}");
    }
}

#[test]
fn missing_chunks_read_as_the_fill_value() {
    // No chunk at all: every sample is the fill value.
    let f = Fixture::new(json!({
        "version": "0.4", "axes": axes("zyx"),
        "datasets": [level("0", json!([1.0, 1.0, 1.0]), json!([0.0, 0.0, 0.0]))]
    }));
    f.array("0", &[2, 3, 4], "<i2", json!(-7), None);
    let v = read_volume_with(&f.path, &opts()).unwrap().volume;
    assert_eq!(v.scalar_type(), volsplat_core::ScalarType::I16);
    assert!(v.to_f32().data().iter().all(|&x| x == -7.0));
    // A written store with one chunk removed: that chunk reads as 0, the others as written.
    let vol = ramp_u16([40, 20, 20]);
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("m.zarr");
    write_zarr(
        &p,
        &vol.clone().into(),
        &ZarrWriteOptions::default().with_chunk(16),
    )
    .unwrap();
    std::fs::remove_file(p.join("0/0/0/1")).unwrap();
    let AnyVolume::U16(got) = read_volume_with(&p, &opts()).unwrap().volume else {
        panic!()
    };
    for (z, y, x) in [
        (0, 0, 16),
        (15, 15, 31),
        (0, 0, 15),
        (16, 0, 16),
        (0, 0, 32),
    ] {
        let inside = (16..32).contains(&x) && z < 16 && y < 16;
        let want = if inside { 0 } else { vol.get(x, y, z) };
        assert_eq!(got.get(x, y, z), want, "{x} {y} {z}");
    }
}

#[test]
fn corrupt_chunks_are_errors_naming_the_store_and_level() {
    let vol = ramp_u16([40, 20, 20]);
    for version in [ZarrVersion::V2, ZarrVersion::V3] {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("c.zarr");
        let o = ZarrWriteOptions::default()
            .with_chunk(16)
            .with_version(version);
        write_zarr(&p, &vol.clone().into(), &o).unwrap();
        let chunk = match version {
            ZarrVersion::V2 => p.join("1/0/0/0"),
            _ => p.join("1/c/0/0/0"),
        };
        let mut bytes = std::fs::read(&chunk).unwrap();
        let n = bytes.len();
        bytes.truncate(n / 2);
        bytes.extend([0xA5; 7]);
        std::fs::write(&chunk, &bytes).unwrap();
        let e = read_volume_with(&p, &opts().with_level(1)).unwrap_err();
        assert!(matches!(e, IoError::Zarr { .. }), "{e}");
        let s = e.to_string();
        assert!(s.contains("c.zarr") && s.contains("level 1"), "{s}");
        // Level 0 is intact.
        read_volume_with(&p, &opts()).unwrap();
    }
}

fn open_err(ms: Value, shape: &[u64], dtype: &str) -> String {
    let f = Fixture::new(ms);
    f.array("0", shape, dtype, json!(0), None);
    let e = read_volume_with(&f.path, &opts()).unwrap_err().to_string();
    assert!(e.contains("f.zarr"), "{e}");
    e
}

#[test]
fn hostile_metadata_gives_errors_naming_field_and_value() {
    let t0 = json!([0.0, 0.0, 0.0]);
    let ok = |scale: Value| {
        json!({ "version": "0.4", "axes": axes("zyx"),
        "datasets": [level("0", scale, json!([0.0, 0.0, 0.0]))] })
    };
    // Huge shapes: refused by the voxel limit before any allocation.
    let e = open_err(
        ok(json!([1.0, 1.0, 1.0])),
        &[1 << 20, 1 << 20, 1 << 20],
        "|u1",
    );
    assert!(
        e.contains("exceeds the limit") && e.contains("`shape`") && e.contains("1048576"),
        "{e}"
    );
    // A huge chunk shape too (a chunk is decoded whole).
    let f = Fixture::new(ok(json!([1.0, 1.0, 1.0])));
    f.array(
        "0",
        &[1 << 20, 1 << 20, 1 << 20],
        "|u1",
        json!(0),
        Some(&[]),
    );
    let e = read_volume_with(&f.path, &opts()).unwrap_err().to_string();
    assert!(
        e.contains("`chunks`") && e.contains("exceeds the limit"),
        "{e}"
    );
    // Negative, zero and non-numeric scales.
    let e = open_err(ok(json!([1.0, -2.0, 1.0])), &[2, 2, 2], "|u1");
    assert!(
        e.contains("scale[1]") && e.contains("-2") && e.contains("positive"),
        "{e}"
    );
    let e = open_err(ok(json!([0.0, 1.0, 1.0])), &[2, 2, 2], "|u1");
    assert!(e.contains("scale[0]") && e.contains("positive"), "{e}");
    let e = open_err(ok(json!([1.0, "x", 1.0])), &[2, 2, 2], "|u1");
    assert!(e.contains("scale[1]") && e.contains("finite number"), "{e}");
    let e = open_err(ok(json!([1.0, 1.0])), &[2, 2, 2], "|u1");
    assert!(e.contains("3 numbers"), "{e}");
    // Missing multiscales.
    let f = Fixture::new(json!({}));
    std::fs::write(f.path.join(".zattrs"), r#"{"omero": {}}"#).unwrap();
    let e = read_volume_with(&f.path, &opts()).unwrap_err().to_string();
    assert!(e.contains("missing required field `multiscales`"), "{e}");
    // Empty datasets, a path out of the store, the wrong axes order, no axes.
    let e = open_err(
        json!({ "axes": axes("zyx"), "datasets": [] }),
        &[2, 2, 2],
        "|u1",
    );
    assert!(e.contains("datasets") && e.contains("non-empty"), "{e}");
    let e = open_err(
        json!({ "axes": axes("zyx"), "datasets": [level("../0", json!([1, 1, 1]), t0.clone())] }),
        &[2, 2, 2],
        "|u1",
    );
    assert!(e.contains("datasets[0].path") && e.contains("../0"), "{e}");
    let e = open_err(
        json!({ "axes": axes("xyz"), "datasets": [level("0", json!([1, 1, 1]), t0.clone())] }),
        &[2, 2, 2],
        "|u1",
    );
    assert!(e.contains("ordered z, y, x"), "{e}");
    let e = open_err(
        json!({ "axes": axes("zcyx"), "datasets": [level("0", json!([1, 1, 1, 1]), json!([0, 0, 0, 0]))] }),
        &[2, 2, 2, 2],
        "|u1",
    );
    assert!(e.contains("spatial axes must come last"), "{e}");
    let e = open_err(
        json!({ "datasets": [level("0", json!([1, 1, 1]), t0.clone())] }),
        &[2, 2, 2],
        "|u1",
    );
    assert!(e.contains("axes") && e.contains("0.4 and 0.5"), "{e}");
    // Dimensions that do not match the axes; a zero-length axis.
    let e = open_err(ok(json!([1.0, 1.0, 1.0])), &[2, 2], "|u1");
    assert!(e.contains("2 dimensions") && e.contains("3 axes"), "{e}");
    let e = open_err(ok(json!([1.0, 1.0, 1.0])), &[2, 0, 2], "|u1");
    assert!(e.contains("no samples"), "{e}");
    // An unsupported data type names the array and the type.
    let e = open_err(ok(json!([1.0, 1.0, 1.0])), &[2, 2, 2], "<i8");
    assert!(
        e.contains("data_type") && e.contains("int64") && e.contains("f.zarr/0"),
        "{e}"
    );
    // Scale first, translation second, no `path` transformations.
    let bad_order = json!({ "axes": axes("zyx"), "datasets": [{ "path": "0",
        "coordinateTransformations": [{ "type": "translation", "translation": [0, 0, 0] }] }] });
    let e = open_err(bad_order, &[2, 2, 2], "|u1");
    assert!(e.contains("expected `scale`"), "{e}");
    // Metadata that is not JSON.
    let f = Fixture::new(json!({}));
    std::fs::write(f.path.join(".zattrs"), b"{\"multiscales\": [").unwrap();
    let e = read_volume_with(&f.path, &opts()).unwrap_err();
    assert!(matches!(e, IoError::Json { .. }), "{e}");
}

#[test]
fn wide_types_read_as_f32_and_out_of_range_doubles_are_errors() {
    let ms = json!({ "version": "0.4", "axes": axes("zyx"),
        "datasets": [level("0", json!([1.0, 1.0, 1.0]), json!([0.0, 0.0, 0.0]))] });
    let f = Fixture::new(ms.clone());
    let vals: Vec<u8> = [-5i32, 1 << 20]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    f.array("0", &[1, 1, 2], "<i4", json!(0), Some(&vals));
    let l = read_volume_with(&f.path, &opts()).unwrap();
    assert_eq!(l.volume.to_f32().data(), &[-5.0, 1048576.0]);
    assert!(
        l.notes
            .iter()
            .any(|n| n.contains("int32 samples converted to f32")),
        "{:?}",
        l.notes
    );
    let f = Fixture::new(ms);
    let vals: Vec<u8> = [0.5f64, 1e300]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    f.array("0", &[1, 1, 2], "<f8", json!(0), Some(&vals));
    let e = read_volume_with(&f.path, &opts()).unwrap_err().to_string();
    assert!(e.contains("float32 range") && e.contains("1e300"), "{e}");
}

#[test]
fn stores_are_found_by_name_or_by_metadata() {
    // A 2-D image (y, x) in a folder not named .zarr: found by its .zattrs, read as one slice.
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("plain");
    std::fs::create_dir(&p).unwrap();
    std::fs::write(p.join(".zgroup"), r#"{"zarr_format": 2}"#).unwrap();
    let ms = json!({ "version": "0.4", "axes": [
        { "name": "y", "type": "space", "unit": "millimeter" },
        { "name": "x", "type": "space", "unit": "millimeter" } ],
        "datasets": [level("s0", json!([2.0, 3.0]), json!([1.0, -1.0]))] });
    std::fs::write(
        p.join(".zattrs"),
        json!({ "multiscales": [ms] }).to_string(),
    )
    .unwrap();
    let f = Fixture {
        _dir: tempfile::tempdir().unwrap(),
        path: p.clone(),
    };
    f.array("s0", &[2, 3], "|u1", json!(0), Some(&[1, 2, 3, 4, 5, 6]));
    let l = read_volume_with(&p, &opts()).unwrap();
    let v = l.volume.to_f32();
    assert_eq!(v.grid().dims, [3, 2, 1]);
    assert_eq!(v.grid().spacing, [3.0, 2.0, 1.0]);
    assert_eq!(v.grid().origin, [-1.0, 1.0, 0.0]);
    assert_eq!(v.data(), &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
    assert!(crate::zarr::is_zarr_store(&p));
    assert!(!crate::zarr::is_zarr_store(dir.path()));
}

#[test]
fn writing_is_atomic_and_replaces_a_store() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("a.zarr");
    let small: AnyVolume = ramp_u16([10, 9, 8]).into();
    write_zarr(&p, &small, &ZarrWriteOptions::default()).unwrap();
    let big: AnyVolume = ramp_u16([20, 9, 8]).into();
    write_zarr(&p, &big, &ZarrWriteOptions::default()).unwrap();
    assert_eq!(read_volume_with(&p, &opts()).unwrap().volume, big);
    // Nothing left beside it.
    let names: Vec<String> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(names, vec!["a.zarr".to_string()]);
    // A regular file in the way is refused and left as it was.
    let file = dir.path().join("f.zarr");
    std::fs::write(&file, b"keep").unwrap();
    let e = write_zarr(&file, &small, &ZarrWriteOptions::default()).unwrap_err();
    assert!(e.to_string().contains("refusing to replace"), "{e}");
    assert_eq!(std::fs::read(&file).unwrap(), b"keep");
    let names = std::fs::read_dir(dir.path()).unwrap().count();
    assert_eq!(names, 2);
    // Bad chunk sizes are refused before anything is written.
    let e = write_zarr(
        dir.path().join("c.zarr"),
        &small,
        &ZarrWriteOptions::default().with_chunk(0),
    );
    assert!(e.unwrap_err().to_string().contains("chunk"));
}

#[test]
fn every_sample_type_round_trips_and_rotations_are_noted() {
    let dir = tempfile::tempdir().unwrap();
    let g = Grid::new(
        [9, 5, 3],
        [1.0, 2.0, 3.0],
        [0.0; 3],
        DMat3::from_rotation_z(0.3),
    )
    .unwrap();
    let f = |i: usize, j: usize, k: usize| (i + 3 * j + 7 * k) as f64 - 20.0;
    let vols: Vec<AnyVolume> = vec![
        Volume::<u8>::from_fn(g.clone(), |i, j, k| (f(i, j, k) + 20.0) as u8)
            .unwrap()
            .into(),
        Volume::<i8>::from_fn(g.clone(), |i, j, k| f(i, j, k) as i8)
            .unwrap()
            .into(),
        Volume::<u16>::from_fn(g.clone(), |i, j, k| (f(i, j, k) + 20.0) as u16)
            .unwrap()
            .into(),
        Volume::<i16>::from_fn(g.clone(), |i, j, k| f(i, j, k) as i16)
            .unwrap()
            .into(),
        Volume::<f32>::from_fn(g.clone(), |i, j, k| f(i, j, k) as f32 * 0.25)
            .unwrap()
            .into(),
    ];
    for (n, v) in vols.iter().enumerate() {
        for version in [ZarrVersion::V2, ZarrVersion::V3] {
            let p = dir.path().join(format!("t{n}{version:?}.zarr"));
            let w = write_zarr(&p, v, &ZarrWriteOptions::default().with_version(version)).unwrap();
            assert!(
                w.notes.iter().any(|s| s.contains("direction")),
                "{:?}",
                w.notes
            );
            let back = read_volume_with(&p, &opts()).unwrap().volume;
            assert_eq!(back.scalar_type(), v.scalar_type());
            assert_eq!(back.to_f32().data(), v.to_f32().data());
            assert_eq!(back.grid().direction, DMat3::IDENTITY);
            assert_eq!(back.grid().spacing, [1.0, 2.0, 3.0]);
        }
    }
}

#[test]
fn missing_stores_and_files_named_zarr_are_clear_errors() {
    // A store path that does not exist names it.
    let e = ZarrStore::open(Path::new("/nonexistent/x.zarr"), &Limits::default()).unwrap_err();
    assert!(
        matches!(&e, IoError::Os { error, .. } if error.kind() == std::io::ErrorKind::NotFound)
    );
    assert!(e.to_string().contains("x.zarr"), "{e}");
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("f.zarr");
    std::fs::write(&file, b"not a folder").unwrap();
    let e = read_volume_with(&file, &opts()).unwrap_err().to_string();
    assert!(e.contains("f.zarr") && e.contains("is a folder"), "{e}");
}

/// An attached-header NRRD of `v` (little-endian, raw or gzip), geometry in `spacings`.
fn nrrd_of(path: &Path, v: &AnyVolume, gzip: bool) {
    crate::write_nrrd(path, v, gzip).unwrap();
}

/// Every level of two stores, read back, is equal (samples and grids).
fn assert_same_stores(a: &Path, b: &Path) {
    let (sa, sb) = (
        ZarrStore::open(a, &Limits::default()).unwrap(),
        ZarrStore::open(b, &Limits::default()).unwrap(),
    );
    assert_eq!(sa.levels(), sb.levels());
    for l in 0..sa.levels().len() {
        let (va, vb) = (
            sa.read_level(l, ZarrSelection::default()).unwrap(),
            sb.read_level(l, ZarrSelection::default()).unwrap(),
        );
        assert_eq!(va, vb, "level {l}");
    }
}

#[test]
fn streamed_conversions_equal_whole_ones() {
    let dir = tempfile::tempdir().unwrap();
    let v = ramp_u16([37, 29, 45]);
    let any: AnyVolume = v.clone().into();
    let o = ZarrWriteOptions::default().with_chunk(8);
    let whole = dir.path().join("whole.zarr");
    write_zarr(&whole, &any, &o).unwrap();
    // Uncompressed NRRD: streamed.
    let nrrd = dir.path().join("v.nrrd");
    nrrd_of(&nrrd, &any, false);
    let out = dir.path().join("s.zarr");
    let c = convert_to_zarr(&nrrd, None, &opts(), &out, &o).unwrap();
    assert!(c.streamed);
    assert_eq!(c.format, "NRRD");
    assert_eq!(c.written.levels, pyramid_grids(v.grid(), 8));
    assert_eq!(c.written.levels.len(), 5);
    assert_same_stores(&whole, &out);
    // Headerless raw, big-endian, with a header to skip: streamed too.
    let raw = dir.path().join("v.raw");
    let mut bytes = vec![9u8; 5];
    bytes.extend(v.data().iter().flat_map(|x| x.to_be_bytes()));
    std::fs::write(&raw, bytes).unwrap();
    let mut spec = crate::RawSpec::new([37, 29, 45], volsplat_core::ScalarType::U16);
    spec.spacing = v.grid().spacing;
    spec.origin = v.grid().origin;
    spec.big_endian = true;
    spec.header_bytes = 5;
    let out = dir.path().join("r.zarr");
    let c = convert_to_zarr(&raw, Some(&spec), &opts(), &out, &o).unwrap();
    assert!(c.streamed && c.format == "raw");
    assert_same_stores(&whole, &out);
    // Gzip NRRD: read whole, the same store.
    let gz = dir.path().join("g.nrrd");
    nrrd_of(&gz, &any, true);
    let out = dir.path().join("g.zarr");
    let c = convert_to_zarr(&gz, None, &opts(), &out, &o).unwrap();
    assert!(!c.streamed);
    assert_same_stores(&whole, &out);
    // A truncated raw file is an error before anything is written.
    std::fs::write(&raw, [0u8; 100]).unwrap();
    let out = dir.path().join("t.zarr");
    let e = convert_to_zarr(&raw, Some(&spec), &opts(), &out, &o).unwrap_err();
    assert!(e.to_string().contains("size mismatch"), "{e}");
    assert!(!out.exists());
}

#[test]
fn streamed_float_files_with_nan_are_converted_whole() {
    let dir = tempfile::tempdir().unwrap();
    let g = Grid::new([12, 10, 9], [1.0; 3], [0.0; 3], DMat3::IDENTITY).unwrap();
    let mut v = Volume::<f32>::from_fn(g, |i, j, k| (i + 2 * j + 3 * k) as f32).unwrap();
    let nrrd = dir.path().join("f.nrrd");
    // The same file with two NaN samples (written by hand: Volume::new would replace them).
    let mut data = v.data().to_vec();
    data[5] = f32::NAN;
    data[700] = f32::NAN;
    let mut file =
        b"NRRD0004\ntype: float\ndimension: 3\nsizes: 12 10 9\nencoding: raw\nendian: little\n\n"
            .to_vec();
    file.extend(data.iter().flat_map(|x| x.to_le_bytes()));
    std::fs::write(&nrrd, file).unwrap();
    let o = ZarrWriteOptions::default().with_chunk(4);
    let out = dir.path().join("f.zarr");
    let c = convert_to_zarr(&nrrd, None, &opts(), &out, &o).unwrap();
    assert!(!c.streamed, "NaN samples: read whole");
    assert!(c.notes.iter().any(|n| n.contains("NaN")), "{:?}", c.notes);
    let whole = crate::read_volume(&nrrd).unwrap();
    let back = read_volume_with(&out, &opts()).unwrap().volume;
    assert_eq!(back.to_f32().data(), whole.to_f32().data());
    // Without NaN the float file streams.
    v.set_grid(v.grid().clone()).unwrap();
    let clean = dir.path().join("c.nrrd");
    nrrd_of(&clean, &v.into(), false);
    let c = convert_to_zarr(&clean, None, &opts(), dir.path().join("c.zarr"), &o).unwrap();
    assert!(c.streamed);
}

/// Random mutations of a small store's metadata (group and array JSON) and chunks, v2 and v3
/// (sharded too): every read is a volume or an error, never a panic.
#[test]
fn corrupted_stores_are_errors_or_volumes_never_panics() {
    let mut state = 0x9E37_79B9_7F4A_7C15u64;
    let mut rnd = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    let dir = tempfile::tempdir().unwrap();
    let v: AnyVolume = ramp_u16([20, 12, 10]).into();
    for version in [ZarrVersion::V2, ZarrVersion::V3] {
        let p = dir.path().join(format!("{version:?}.zarr"));
        write_zarr(
            &p,
            &v,
            &ZarrWriteOptions::default()
                .with_chunk(8)
                .with_version(version),
        )
        .unwrap();
        let files: Vec<PathBuf> = match version {
            ZarrVersion::V2 => vec![p.join(".zattrs"), p.join("0/.zarray"), p.join("0/0/0/0")],
            _ => vec![
                p.join("zarr.json"),
                p.join("0/zarr.json"),
                p.join("0/c/0/0/0"),
            ],
        };
        for file in &files {
            let valid = std::fs::read(file).unwrap();
            for k in 0..150 {
                let mut b = valid.clone();
                match k % 4 {
                    0 => b.truncate(rnd() as usize % (valid.len() + 1)),
                    1 => {
                        for _ in 0..1 + rnd() % 6 {
                            let i = rnd() as usize % b.len();
                            b[i] = rnd() as u8;
                        }
                    }
                    2 => {
                        // A digit of a number made huge, zero or negative.
                        let digits: Vec<usize> =
                            (0..b.len()).filter(|&i| b[i].is_ascii_digit()).collect();
                        if let Some(&i) = digits.get(rnd() as usize % digits.len().max(1)) {
                            let s: &[u8] =
                                [&b"99999999999"[..], b"0", b"-1", b"1e308"][rnd() as usize % 4];
                            b.splice(i..i + 1, s.iter().copied());
                        }
                    }
                    _ => {
                        let i = rnd() as usize % b.len();
                        b.insert(i, rnd() as u8);
                    }
                }
                std::fs::write(file, &b).unwrap();
                for level in 0..2 {
                    let _ = read_volume_with(&p, &opts().with_level(level));
                }
            }
            std::fs::write(file, &valid).unwrap();
        }
        read_volume_with(&p, &opts()).unwrap();
    }
    // A sharded v3 array (written by zarrs from hand-written metadata), its shard corrupted.
    let p = dir.path().join("sharded.zarr");
    std::fs::create_dir_all(p.join("0")).unwrap();
    let ms = json!({ "axes": axes("zyx"),
        "datasets": [level("0", json!([1.0, 1.0, 1.0]), json!([0.0, 0.0, 0.0]))] });
    let root = json!({ "zarr_format": 3, "node_type": "group",
        "attributes": { "ome": { "version": "0.5", "multiscales": [ms] } } });
    std::fs::write(p.join("zarr.json"), root.to_string()).unwrap();
    let arr = json!({ "zarr_format": 3, "node_type": "array", "shape": [8, 8, 8],
        "data_type": "uint16",
        "chunk_grid": { "name": "regular", "configuration": { "chunk_shape": [8, 8, 8] } },
        "chunk_key_encoding": { "name": "default", "configuration": { "separator": "/" } },
        "fill_value": 0,
        "codecs": [{ "name": "sharding_indexed", "configuration": {
            "chunk_shape": [4, 4, 4],
            "codecs": [{ "name": "bytes", "configuration": { "endian": "little" } },
                       { "name": "zstd", "configuration": { "level": 1, "checksum": false } }],
            "index_codecs": [{ "name": "bytes", "configuration": { "endian": "little" } },
                             { "name": "crc32c" }] } }] });
    std::fs::write(p.join("0/zarr.json"), arr.to_string()).unwrap();
    let store = std::sync::Arc::new(zarrs::filesystem::FilesystemStore::new(&p).unwrap());
    let a = zarrs::array::Array::open(store, "/0").unwrap();
    let data: Vec<u16> = (0..512).map(|i| i as u16 * 3).collect();
    a.store_chunk(&[0, 0, 0], &data[..]).unwrap();
    let back = read_volume_with(&p, &opts()).unwrap().volume;
    assert_eq!(
        back.to_f32().data(),
        data.iter().map(|&x| x as f32).collect::<Vec<_>>()
    );
    let shard = p.join("0/c/0/0/0");
    let valid = std::fs::read(&shard).unwrap();
    for k in 0..200 {
        let mut b = valid.clone();
        if k % 2 == 0 {
            b.truncate(rnd() as usize % valid.len());
        } else {
            // Mostly the index at the end: offsets and lengths.
            let i = valid.len() - 1 - rnd() as usize % valid.len().min(64 * 2 * 8 + 4);
            b[i] = rnd() as u8;
        }
        std::fs::write(&shard, &b).unwrap();
        let _ = read_volume_with(&p, &opts());
    }
}

#[test]
fn auto_level_is_the_coarsest_whose_voxel_fits_a_pixel() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("a.zarr");
    let g = Grid::new([200, 200, 200], [0.5; 3], [0.0; 3], DMat3::IDENTITY).unwrap();
    let v = Volume::<u8>::from_fn(g, |i, _, _| i as u8).unwrap();
    write_zarr(&p, &v.into(), &ZarrWriteOptions::default()).unwrap();
    let s = ZarrStore::open(&p, &Limits::default()).unwrap();
    // Levels' spacings 0.5, 1, 2 (200 → 101 → 52 ≤ 64).
    let sp: Vec<f64> = s.levels().iter().map(|l| l.spacing[0]).collect();
    assert_eq!(sp, [0.5, 1.0, 2.0]);
    assert_eq!(s.auto_level(0.4, 1.0), 0);
    assert_eq!(s.auto_level(0.99, 1.0), 0);
    assert_eq!(s.auto_level(1.0, 1.0), 1);
    assert_eq!(s.auto_level(100.0, 1.0), 2);
    let r2 = std::f64::consts::SQRT_2;
    assert_eq!(s.auto_level(1.0 / r2 * 1.001, r2), 1);
    assert_eq!(s.auto_level(1.0 / r2 * 0.999, r2), 0);
    assert_eq!(s.auto_level(f64::NAN, 1.0), 0);
    assert_eq!(s.auto_level(-1.0, 1.0), 0);
}

#[test]
fn bioformats2raw_layouts_read_image_0() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("b2r.zarr");
    std::fs::create_dir(&p).unwrap();
    std::fs::write(p.join(".zgroup"), r#"{"zarr_format": 2}"#).unwrap();
    std::fs::write(p.join(".zattrs"), r#"{"bioformats2raw.layout": 3}"#).unwrap();
    let v: AnyVolume = ramp_u16([9, 8, 7]).into();
    write_zarr(p.join("0"), &v, &ZarrWriteOptions::default()).unwrap();
    let l = read_volume_with(&p, &opts()).unwrap();
    assert_eq!(l.volume, v);
    assert!(
        l.notes.iter().any(|n| n.contains("bioformats2raw")),
        "{:?}",
        l.notes
    );
    // Without the layout attribute the root is not an image.
    std::fs::write(p.join(".zattrs"), r#"{}"#).unwrap();
    let e = read_volume_with(&p, &opts()).unwrap_err().to_string();
    assert!(e.contains("multiscales"), "{e}");
}

/// Decision 0033: a store inside the folder reads are confined to may not reach out of it
/// through a symbolic link (a chunk, or a level's folder).
#[cfg(unix)]
#[test]
fn confined_reads_refuse_links_out_of_the_folder() {
    let root = tempfile::tempdir().unwrap();
    let data = root.path().join("data");
    std::fs::create_dir(&data).unwrap();
    let v: AnyVolume = ramp_u16([9, 8, 7]).into();
    let store = data.join("s.zarr");
    write_zarr(&store, &v, &ZarrWriteOptions::default()).unwrap();
    let confined = opts().with_limits(Limits::default().with_confine_to(Some(data.clone())));
    assert_eq!(read_volume_with(&store, &confined).unwrap().volume, v);
    // A chunk replaced by a link to a file outside: refused (read unconfined, it would be used).
    let outside = root.path().join("secret");
    std::fs::copy(store.join("0/0/0/0"), &outside).unwrap();
    std::fs::remove_file(store.join("0/0/0/0")).unwrap();
    std::os::unix::fs::symlink(&outside, store.join("0/0/0/0")).unwrap();
    let e = read_volume_with(&store, &confined).unwrap_err();
    assert!(matches!(e, IoError::OutsideFolder { .. }), "{e}");
    assert!(
        e.to_string().contains("symbolic link inside the store"),
        "{e}"
    );
    read_volume_with(&store, &opts()).unwrap();
}
