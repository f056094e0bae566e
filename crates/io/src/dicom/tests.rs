//! Synthetic DICOM series written with dicom-object (no files from elsewhere).

use super::header::*;
use super::*;
use dicom_core::header::Length;
use dicom_core::value::{PrimitiveValue, Value};
use dicom_core::{DataElement, VR};
use dicom_object::FileMetaTableBuilder;
use volsplat_core::ScalarType;

pub(crate) const EXPLICIT_LE: &str = "1.2.840.10008.1.2.1";
pub(crate) const IMPLICIT_LE: &str = "1.2.840.10008.1.2";
pub(crate) const EXPLICIT_BE: &str = "1.2.840.10008.1.2.2";
pub(crate) const DEFLATED: &str = "1.2.840.10008.1.2.1.99";
pub(crate) const RLE: &str = "1.2.840.10008.1.2.5";
pub(crate) const JPEG_BASELINE: &str = "1.2.840.10008.1.2.4.50";
pub(crate) const ENCAPSULATED_RAW: &str = "1.2.840.10008.1.2.1.98";
pub(crate) const DEFLATED_FRAMES: &str = "1.2.840.10008.1.2.8.1";
pub(crate) const JPEG_2000: &str = "1.2.840.10008.1.2.4.90";
pub(crate) const JPEG_2000_LOSSY: &str = "1.2.840.10008.1.2.4.91";
pub(crate) const JPEG_LS: &str = "1.2.840.10008.1.2.4.80";
pub(crate) const JPEG_LS_NEAR: &str = "1.2.840.10008.1.2.4.81";
pub(crate) const JPEG_EXTENDED: &str = "1.2.840.10008.1.2.4.51";
pub(crate) const JPEG_LOSSLESS_SV1: &str = "1.2.840.10008.1.2.4.70";
/// High-Throughput JPEG 2000 (no decoder built in).
pub(crate) const HTJ2K: &str = "1.2.840.10008.1.2.4.201";

/// One slice to write.
#[derive(Debug, Clone)]
pub(crate) struct Slice {
    pub series: String,
    pub number: i64,
    pub description: String,
    pub instance: i64,
    pub ipp: Option<[f64; 3]>,
    pub iop: Option<[f64; 6]>,
    pub rows: u16,
    pub cols: u16,
    /// [between rows, between columns].
    pub spacing: [f64; 2],
    pub slope: f64,
    pub intercept: f64,
    pub bits: u16,
    pub signed: bool,
    /// Stored values, row by row.
    pub values: Vec<i32>,
    pub ts: &'static str,
    pub thickness: f64,
    pub tilt: Option<f64>,
}

impl Slice {
    /// A 4 × 3 CT slice at height `z`, axial, u16 stored with intercept −1024.
    pub(crate) fn ct(z: f64, k: i32) -> Self {
        Slice {
            series: "1.2.826.0.1.3680043.2.1125.1".into(),
            number: 3,
            description: "HEAD 2.5".into(),
            instance: 1,
            ipp: Some([-10.0, -20.0, z]),
            iop: Some([1.0, 0.0, 0.0, 0.0, 1.0, 0.0]),
            rows: 3,
            cols: 4,
            spacing: [0.5, 0.75],
            slope: 1.0,
            intercept: -1024.0,
            bits: 16,
            signed: false,
            values: (0..12).map(|p| 1000 + 100 * k + p).collect(),
            ts: EXPLICIT_LE,
            thickness: 5.0,
            tilt: None,
        }
    }

    pub(crate) fn ds(v: &[f64]) -> PrimitiveValue {
        PrimitiveValue::from(
            v.iter()
                .map(|x| format!("{x}"))
                .collect::<Vec<_>>()
                .join("\\"),
        )
    }

    /// Native little-endian words of the stored values.
    pub(crate) fn le_bytes(&self) -> Vec<u8> {
        match self.bits {
            8 => self.values.iter().map(|&v| v as u8).collect(),
            16 => self
                .values
                .iter()
                .flat_map(|&v| (v as u16).to_le_bytes())
                .collect(),
            _ => self
                .values
                .iter()
                .flat_map(|&v| (v as u32).to_le_bytes())
                .collect(),
        }
    }

    /// The data set without pixel data.
    pub(crate) fn object(&self, sop: &str) -> InMemDicomObject {
        let mut o = InMemDicomObject::new_empty();
        let put = |o: &mut InMemDicomObject, a: Attr, vr: VR, v: PrimitiveValue| {
            o.put(DataElement::new(a.tag(), vr, v));
        };
        put(
            &mut o,
            SOP_CLASS,
            VR::UI,
            "1.2.840.10008.5.1.4.1.1.2".into(),
        );
        put(
            &mut o,
            Attr(0x0008, 0x0018, "SOPInstanceUID"),
            VR::UI,
            sop.into(),
        );
        put(&mut o, MODALITY, VR::CS, "CT".into());
        put(
            &mut o,
            SERIES_DESCRIPTION,
            VR::LO,
            self.description.clone().into(),
        );
        put(&mut o, SLICE_THICKNESS, VR::DS, Self::ds(&[self.thickness]));
        if let Some(t) = self.tilt {
            put(&mut o, GANTRY_TILT, VR::DS, Self::ds(&[t]));
        }
        put(&mut o, SERIES_UID, VR::UI, self.series.clone().into());
        put(
            &mut o,
            SERIES_NUMBER,
            VR::IS,
            self.number.to_string().into(),
        );
        put(
            &mut o,
            Attr(0x0020, 0x0013, "InstanceNumber"),
            VR::IS,
            self.instance.to_string().into(),
        );
        if let Some(p) = self.ipp {
            put(&mut o, IPP, VR::DS, Self::ds(&p));
        }
        if let Some(p) = self.iop {
            put(&mut o, IOP, VR::DS, Self::ds(&p));
        }
        put(&mut o, SAMPLES, VR::US, PrimitiveValue::from(1u16));
        put(&mut o, PHOTOMETRIC, VR::CS, "MONOCHROME2".into());
        put(&mut o, ROWS, VR::US, PrimitiveValue::from(self.rows));
        put(&mut o, COLUMNS, VR::US, PrimitiveValue::from(self.cols));
        put(&mut o, PIXEL_SPACING, VR::DS, Self::ds(&self.spacing));
        put(
            &mut o,
            BITS_ALLOCATED,
            VR::US,
            PrimitiveValue::from(self.bits),
        );
        put(&mut o, BITS_STORED, VR::US, PrimitiveValue::from(self.bits));
        put(
            &mut o,
            HIGH_BIT,
            VR::US,
            PrimitiveValue::from(self.bits - 1),
        );
        put(
            &mut o,
            PIXEL_REPRESENTATION,
            VR::US,
            PrimitiveValue::from(u16::from(self.signed)),
        );
        put(&mut o, SLOPE, VR::DS, Self::ds(&[self.slope]));
        put(&mut o, INTERCEPT, VR::DS, Self::ds(&[self.intercept]));
        o
    }

    /// Pixel data in the slice's transfer syntax.
    pub(crate) fn pixel_element(&self) -> DataElement<InMemDicomObject> {
        let raw = self.le_bytes();
        let tag = dicom_dictionary_std::tags::PIXEL_DATA;
        let frag = |f: Vec<u8>| -> Value<InMemDicomObject> {
            Value::from(dicom_core::value::PixelFragmentSequence::new(
                Vec::<u32>::new(),
                vec![f],
            ))
        };
        match self.ts {
            RLE => DataElement::new(tag, VR::OB, frag(rle_encode(self))),
            JPEG_BASELINE => DataElement::new(tag, VR::OB, frag(jpeg_encode(self))),
            ENCAPSULATED_RAW => DataElement::new(tag, VR::OB, frag(raw)),
            DEFLATED_FRAMES => {
                use std::io::Write;
                let mut e =
                    flate2::write::DeflateEncoder::new(Vec::new(), flate2::Compression::fast());
                e.write_all(&raw).unwrap();
                DataElement::new(tag, VR::OB, frag(e.finish().unwrap()))
            }
            JPEG_2000 | HTJ2K => DataElement::new(tag, VR::OB, frag(vec![0xFF, 0x4F, 0xFF, 0x51])),
            _ if self.bits == 16 => DataElement::new(
                tag,
                VR::OW,
                PrimitiveValue::U16(self.values.iter().map(|&v| v as u16).collect()),
            ),
            _ => DataElement::new(tag, VR::OB, PrimitiveValue::U8(raw.into())),
        }
    }

    /// The file's bytes.
    pub(crate) fn bytes(&self, sop: &str) -> Vec<u8> {
        let mut o = self.object(sop);
        o.put(self.pixel_element());
        file_bytes(o, self.ts)
    }

    pub(crate) fn write(&self, path: &Path) {
        std::fs::write(path, self.bytes(&format!("1.2.3.{}", self.instance))).unwrap();
    }
}

/// A data set with a file meta group, as a PS3.10 file (preamble included).
pub(crate) fn file_bytes(o: InMemDicomObject, ts: &str) -> Vec<u8> {
    let f = o
        .with_meta(FileMetaTableBuilder::new().transfer_syntax(ts))
        .unwrap();
    let mut out = Vec::new();
    f.write_all(&mut out).unwrap();
    out
}

/// RLE Lossless (PS3.5 Annex G): literal runs only, most significant byte first.
pub(crate) fn rle_encode(s: &Slice) -> Vec<u8> {
    let bpp = s.bits as usize / 8;
    let raw = s.le_bytes();
    let mut segs: Vec<Vec<u8>> = Vec::new();
    for b in (0..bpp).rev() {
        let bytes: Vec<u8> = raw.chunks(bpp).map(|w| w[b]).collect();
        let mut seg = Vec::new();
        for chunk in bytes.chunks(128) {
            seg.push((chunk.len() - 1) as u8);
            seg.extend_from_slice(chunk);
        }
        if seg.len() % 2 == 1 {
            seg.push(0x80);
        }
        segs.push(seg);
    }
    let mut out = vec![0u8; 64];
    out[..4].copy_from_slice(&(segs.len() as u32).to_le_bytes());
    let mut at = 64u32;
    for (k, seg) in segs.iter().enumerate() {
        out[4 + 4 * k..8 + 4 * k].copy_from_slice(&at.to_le_bytes());
        at += seg.len() as u32;
    }
    for seg in segs {
        out.extend(seg);
    }
    out
}

/// JPEG baseline, 8-bit grayscale, quality 100.
pub(crate) fn jpeg_encode(s: &Slice) -> Vec<u8> {
    let px: Vec<u8> = s.values.iter().map(|&v| v as u8).collect();
    let mut out = Vec::new();
    jpeg_encoder::Encoder::new(&mut out, 100)
        .encode(&px, s.cols, s.rows, jpeg_encoder::ColorType::Luma)
        .unwrap();
    out
}

pub(crate) fn series_dir(slices: &[Slice], names: &[&str]) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    for (s, n) in slices.iter().zip(names) {
        s.write(&dir.path().join(n));
    }
    dir
}

pub(crate) fn err_of(r: Result<LoadedVolume>) -> String {
    match r {
        Ok(_) => panic!("expected an error"),
        Err(e) => e.to_string(),
    }
}

pub(crate) fn opts() -> ReadOptions {
    ReadOptions::default()
}

/// Five slices 2.5 apart, written under shuffled names with shuffled InstanceNumbers.
pub(crate) fn five() -> Vec<Slice> {
    let zs = [30.0, 20.0, 27.5, 25.0, 22.5];
    let inst = [4, 9, 1, 7, 2];
    zs.iter()
        .zip(inst)
        .map(|(&z, i)| {
            let k = ((z - 20.0) / 2.5) as i32;
            let mut s = Slice::ct(z, k);
            s.instance = i;
            s
        })
        .collect()
}

pub(crate) const NAMES: [&str; 5] = ["b.dcm", "IM0001", "z9", "a10.dcm", "0.dcm"];

#[test]
fn shuffled_names_and_instance_numbers_sort_by_position_with_rescale() {
    let dir = series_dir(&five(), &NAMES);
    let l = read_dicom_with(dir.path(), &opts()).unwrap();
    assert_eq!(l.format, "DICOM");
    assert_eq!(l.volume.scalar_type(), ScalarType::I16);
    let g = l.volume.grid();
    assert_eq!(g.dims, [4, 3, 5]);
    assert_eq!(g.spacing, [0.75, 0.5, 2.5]);
    assert_eq!(g.origin, [-10.0, -20.0, 20.0]);
    assert_eq!(g.direction, DMat3::IDENTITY);
    let v = l.volume.to_f32();
    for k in 0..5 {
        for p in 0..12 {
            let want = (1000 + 100 * k + p) as f32 - 1024.0;
            assert_eq!(v.data()[k as usize * 12 + p as usize], want, "k {k} p {p}");
        }
    }
    assert_eq!(l.series.len(), 1);
    assert_eq!(l.series[0].images, 5);
    assert_eq!(l.series[0].description, "HEAD 2.5");
    assert_eq!(
        l.series_uid.as_deref(),
        Some("1.2.826.0.1.3680043.2.1125.1")
    );
    let notes = l.notes.join("\n");
    assert!(notes.contains("sorted by ImagePositionPatient"), "{notes}");
    assert!(notes.contains("SliceThickness 5"), "{notes}");
    assert!(notes.contains("RescaleIntercept -1024"), "{notes}");
    // Through the dispatcher: the folder, a .dcm file, a file with no extension.
    for p in [
        dir.path().to_path_buf(),
        dir.path().join("b.dcm"),
        dir.path().join("IM0001"),
    ] {
        let w = crate::read_volume(&p).unwrap();
        assert_eq!(w.to_f32().data(), v.data(), "{}", p.display());
    }
}

#[test]
fn fractional_rescale_gives_f32_and_no_rescale_keeps_u16() {
    let mut s = five();
    for x in &mut s {
        x.slope = 0.5;
        x.intercept = -10.25;
    }
    let dir = series_dir(&s, &NAMES);
    let l = read_dicom_with(dir.path(), &opts()).unwrap();
    assert_eq!(l.volume.scalar_type(), ScalarType::F32);
    assert_eq!(l.volume.to_f32().data()[0], 1000.0 * 0.5 - 10.25);
    let mut s = five();
    for x in &mut s {
        x.intercept = 0.0;
    }
    let dir = series_dir(&s, &NAMES);
    let l = read_dicom_with(dir.path(), &opts()).unwrap();
    assert_eq!(l.volume.scalar_type(), ScalarType::U16);
    // Signed stored values.
    let mut s = five();
    for x in &mut s {
        x.signed = true;
        x.intercept = 0.0;
        x.values = (0..12).map(|p| -2000 + p).collect();
    }
    let dir = series_dir(&s, &NAMES);
    let l = read_dicom_with(dir.path(), &opts()).unwrap();
    assert_eq!(l.volume.scalar_type(), ScalarType::I16);
    assert_eq!(l.volume.value_range(), (-2000.0, -1989.0));
}

#[test]
fn oblique_orientation_gives_the_direction_matrix() {
    // Rows along r, columns along c: 30° about z, then 20° about x.
    let rot =
        DMat3::from_rotation_x(20f64.to_radians()) * DMat3::from_rotation_z(30f64.to_radians());
    let (r, c) = (rot * DVec3::X, rot * DVec3::Y);
    let n = r.cross(c);
    let o = DVec3::new(5.0, -7.0, 11.0);
    let order = [2, 0, 3, 1];
    let slices: Vec<Slice> = order
        .iter()
        .map(|&k| {
            let mut s = Slice::ct(0.0, k);
            s.ipp = Some((o + n * (3.0 * k as f64)).to_array());
            s.iop = Some([r.x, r.y, r.z, c.x, c.y, c.z]);
            s
        })
        .collect();
    let dir = series_dir(&slices, &["a", "b", "c", "d"]);
    let l = read_dicom_with(dir.path(), &opts()).unwrap();
    let g = l.volume.grid();
    assert!(g.direction.abs_diff_eq(DMat3::from_cols(r, c, n), 1e-9));
    assert!((g.spacing[2] - 3.0).abs() < 1e-9);
    // Voxel (i, j, k) sits at IPP_k + i·Δc·r + j·Δr·c (PS3.3 Equation C.7.6.2.1-1).
    for k in 0..4 {
        let p = g.world_from_index(DVec3::new(2.0, 1.0, k as f64));
        let want = o + n * (3.0 * k as f64) + r * (2.0 * 0.75) + c * 0.5;
        assert!((p - want).length() < 1e-9, "{p} {want}");
    }
    // Reversed stacking (positions decreasing along n in file order) sorts the same way.
    let v = l.volume.to_f32();
    assert_eq!(v.data()[0], 1000.0 - 1024.0);
    assert_eq!(v.data()[12 * 3], 1300.0 - 1024.0);
}

#[test]
fn two_series_in_one_folder() {
    let dir = tempfile::tempdir().unwrap();
    for (i, s) in five().iter().enumerate() {
        s.write(&dir.path().join(format!("a{i}.dcm")));
    }
    for i in 0..2 {
        let mut s = Slice::ct(i as f64, i);
        s.series = "1.2.3.4.5.99".into();
        s.number = 7;
        s.description = "SCOUT".into();
        s.instance = 100 + i as i64;
        s.write(&dir.path().join(format!("s{i}.dcm")));
    }
    std::fs::write(dir.path().join("notes.txt"), b"not dicom").unwrap();
    let e = err_of(read_dicom_with(dir.path(), &opts()));
    assert!(e.contains("2 DICOM series"), "{e}");
    assert!(e.contains("HEAD 2.5") && e.contains("5 images"), "{e}");
    assert!(e.contains("SCOUT") && e.contains("2 images"), "{e}");
    assert!(e.contains("1.2.3.4.5.99"), "{e}");
    let list = list_dicom_series(dir.path(), &Limits::default()).unwrap();
    assert_eq!(list.len(), 2);
    assert_eq!((list[0].number, list[0].images), (Some(3), 5));
    assert_eq!((list[1].number, list[1].images), (Some(7), 2));
    for want in ["1.2.3.4.5.99", "7"] {
        let o = ReadOptions {
            series: Some(want.into()),
            ..opts()
        };
        let l = crate::read_volume_with(dir.path(), &o).unwrap();
        assert_eq!(l.volume.grid().dims, [4, 3, 2]);
        assert_eq!(l.series.len(), 2);
        assert!(
            l.notes.iter().any(|n| n.contains("non-DICOM")),
            "{:?}",
            l.notes
        );
    }
    let o = ReadOptions {
        series: Some("42".into()),
        ..opts()
    };
    let e = err_of(read_dicom_with(dir.path(), &o));
    assert!(e.contains("no series with UID or number \"42\""), "{e}");
    // A file stands for its own series.
    let l = read_dicom_with(dir.path().join("s1.dcm"), &opts()).unwrap();
    assert_eq!(l.volume.grid().dims, [4, 3, 2]);
    let l = read_dicom_with(dir.path().join("a1.dcm"), &opts()).unwrap();
    assert_eq!(l.volume.grid().dims, [4, 3, 5]);
    // A list of files.
    let files: Vec<PathBuf> = (0..5)
        .map(|i| dir.path().join(format!("a{i}.dcm")))
        .collect();
    let l = read_dicom_files(&files, &opts()).unwrap();
    assert_eq!(l.volume.grid().dims, [4, 3, 5]);
}

#[test]
fn missing_slice_and_unequal_gaps_are_errors() {
    let mut s = five();
    s.remove(2); // z = 27.5
    let dir = series_dir(&s, &NAMES);
    let e = err_of(read_dicom_with(dir.path(), &opts()));
    assert!(e.contains("missing slice: 1 slice between"), "{e}");
    assert!(e.contains("ImagePositionPatient"), "{e}");
    let mut s = five();
    s[2].ipp = Some([-10.0, -20.0, 27.0]);
    let dir = series_dir(&s, &NAMES);
    let e = err_of(read_dicom_with(dir.path(), &opts()));
    assert!(e.contains("unequal gaps"), "{e}");
    // Small jitter (0.1 % of the gap) is accepted; the spacing is the mean.
    let mut s = five();
    s[2].ipp = Some([-10.0, -20.0, 27.5025]);
    let dir = series_dir(&s, &NAMES);
    let l = read_dicom_with(dir.path(), &opts()).unwrap();
    assert!((l.volume.grid().spacing[2] - 2.5).abs() < 1e-9);
    // Duplicate positions.
    let mut s = five();
    s[2].ipp = s[0].ipp;
    let dir = series_dir(&s, &NAMES);
    let e = err_of(read_dicom_with(dir.path(), &opts()));
    assert!(e.contains("same position"), "{e}");
}

#[test]
fn mixed_sizes_orientations_and_gantry_tilt_are_errors() {
    let mut s = five();
    s[3].rows = 2;
    s[3].values.truncate(8);
    let dir = series_dir(&s, &NAMES);
    let e = err_of(read_dicom_with(dir.path(), &opts()));
    assert!(e.contains("different sizes"), "{e}");

    let mut s = five();
    s[1].iop = Some([1.0, 0.0, 0.0, 0.0, 0.0, -1.0]);
    let dir = series_dir(&s, &NAMES);
    let e = err_of(read_dicom_with(dir.path(), &opts()));
    assert!(e.contains("different orientations"), "{e}");

    let mut s = five();
    s[4].spacing = [0.6, 0.75];
    let dir = series_dir(&s, &NAMES);
    let e = err_of(read_dicom_with(dir.path(), &opts()));
    assert!(e.contains("different pixel spacing"), "{e}");

    // 15° gantry tilt: each slice shifts in y by tan(15°) · 2.5.
    let mut s = five();
    for x in &mut s {
        let z = x.ipp.unwrap()[2];
        x.ipp = Some([-10.0, -20.0 + (z - 20.0) * 15f64.to_radians().tan(), z]);
        x.tilt = Some(15.0);
    }
    let dir = series_dir(&s, &NAMES);
    let e = err_of(read_dicom_with(dir.path(), &opts()));
    assert!(e.contains("gantry tilt"), "{e}");
    assert!(
        e.contains("15.00° tilt") && e.contains("GantryDetectorTilt"),
        "{e}"
    );

    // Missing positions on several slices.
    let mut s = five();
    s[0].ipp = None;
    let dir = series_dir(&s, &NAMES);
    let e = err_of(read_dicom_with(dir.path(), &opts()));
    assert!(e.contains("cannot be ordered"), "{e}");
}

#[test]
fn single_slice_spacing_from_thickness() {
    let dir = series_dir(&[Slice::ct(4.0, 0)], &["one.dcm"]);
    let l = read_dicom_with(dir.path(), &opts()).unwrap();
    assert_eq!(l.volume.grid().dims, [4, 3, 1]);
    assert_eq!(l.volume.grid().spacing[2], 5.0);
    let mut s = Slice::ct(4.0, 0);
    s.ipp = None;
    s.iop = None;
    let dir = series_dir(&[s], &["one.dcm"]);
    let l = read_dicom_with(dir.path(), &opts()).unwrap();
    assert_eq!(l.volume.grid().origin, [0.0; 3]);
}

#[test]
fn transfer_syntaxes_read_the_same_samples() {
    let reference = {
        let dir = series_dir(&five(), &NAMES);
        read_dicom(dir.path()).unwrap().to_f32()
    };
    for ts in [
        IMPLICIT_LE,
        EXPLICIT_BE,
        DEFLATED,
        RLE,
        ENCAPSULATED_RAW,
        DEFLATED_FRAMES,
    ] {
        let mut s = five();
        for x in &mut s {
            x.ts = ts;
        }
        let dir = series_dir(&s, &NAMES);
        let l = read_dicom_with(dir.path(), &opts()).unwrap_or_else(|e| panic!("{ts}: {e}"));
        assert_eq!(l.volume.to_f32(), reference, "{ts}");
        assert!(
            l.notes.iter().any(|n| n.starts_with("transfer syntax")),
            "{:?}",
            l.notes
        );
    }
    // 8-bit RLE and JPEG baseline (lossy: within a few grey levels).
    let mut s = five();
    for (k, x) in s.iter_mut().enumerate() {
        x.bits = 8;
        x.intercept = 0.0;
        x.values = (0..12).map(|p| 20 * p + k as i32).collect();
    }
    let dir = series_dir(&s, &NAMES);
    let plain = read_dicom(dir.path()).unwrap();
    assert_eq!(plain.scalar_type(), ScalarType::U8);
    for ts in [RLE, JPEG_BASELINE] {
        let mut t = s.clone();
        for x in &mut t {
            x.ts = ts;
        }
        let dir = series_dir(&t, &NAMES);
        let v = read_dicom(dir.path()).unwrap_or_else(|e| panic!("{ts}: {e}"));
        assert_eq!(v.scalar_type(), ScalarType::U8);
        let tol = if ts == RLE { 0.0 } else { 8.0 };
        for (a, b) in v.to_f32().data().iter().zip(plain.to_f32().data()) {
            assert!((a - b).abs() <= tol, "{ts}: {a} vs {b}");
        }
    }
    // No decoder: the error names the syntax.
    let mut s = five();
    for x in &mut s {
        x.ts = HTJ2K;
    }
    let dir = series_dir(&s, &NAMES);
    let e = err_of(read_dicom_with(dir.path(), &opts()));
    assert!(e.contains(HTJ2K), "{e}");
}

#[test]
fn enhanced_multi_frame_sorted_by_per_frame_positions() {
    let base = Slice::ct(0.0, 0);
    let mut o = base.object("1.2.3.77");
    o.put(DataElement::new(
        SOP_CLASS.tag(),
        VR::UI,
        PrimitiveValue::from("1.2.840.10008.5.1.4.1.1.2.1"),
    ));
    o.remove_element(IPP.tag());
    o.remove_element(IOP.tag());
    o.remove_element(PIXEL_SPACING.tag());
    o.remove_element(SLOPE.tag());
    o.remove_element(INTERCEPT.tag());
    let seq = |a: Attr, item: InMemDicomObject| {
        DataElement::new(
            a.tag(),
            VR::SQ,
            Value::new_sequence(vec![item], Length::UNDEFINED),
        )
    };
    let mut measures = InMemDicomObject::new_empty();
    measures.put(DataElement::new(
        PIXEL_SPACING.tag(),
        VR::DS,
        Slice::ds(&[0.5, 0.75]),
    ));
    let mut orient = InMemDicomObject::new_empty();
    orient.put(DataElement::new(
        IOP.tag(),
        VR::DS,
        Slice::ds(&[1.0, 0.0, 0.0, 0.0, 1.0, 0.0]),
    ));
    let mut shared = InMemDicomObject::new_empty();
    shared.put(seq(PIXEL_MEASURES, measures));
    shared.put(seq(PLANE_ORIENTATION, orient));
    let mut xf = InMemDicomObject::new_empty();
    xf.put(DataElement::new(SLOPE.tag(), VR::DS, Slice::ds(&[1.0])));
    xf.put(DataElement::new(
        INTERCEPT.tag(),
        VR::DS,
        Slice::ds(&[-1024.0]),
    ));
    shared.put(seq(VALUE_TRANSFORM, xf));
    o.put(seq(SHARED_GROUPS, shared));
    // Frames stored at z = 4, 0, 2: frame f holds values 1000 + 100·(z/2).
    let zs = [4.0, 0.0, 2.0];
    let mut items = Vec::new();
    let mut words = Vec::new();
    for &z in &zs {
        let mut pos = InMemDicomObject::new_empty();
        pos.put(DataElement::new(
            IPP.tag(),
            VR::DS,
            Slice::ds(&[0.0, 0.0, z]),
        ));
        let mut it = InMemDicomObject::new_empty();
        it.put(seq(PLANE_POSITION, pos));
        items.push(it);
        let k = (z / 2.0) as u16;
        words.extend((0..12u16).map(|p| 1000 + 100 * k + p));
    }
    o.put(DataElement::new(
        PER_FRAME_GROUPS.tag(),
        VR::SQ,
        Value::new_sequence(items, Length::UNDEFINED),
    ));
    o.put(DataElement::new(
        FRAMES.tag(),
        VR::IS,
        PrimitiveValue::from("3"),
    ));
    o.put(DataElement::new(
        dicom_dictionary_std::tags::PIXEL_DATA,
        VR::OW,
        PrimitiveValue::U16(words.into()),
    ));
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("enhanced.dcm");
    std::fs::write(&p, file_bytes(o, EXPLICIT_LE)).unwrap();
    let l = crate::read_volume_with(&p, &opts()).unwrap();
    let g = l.volume.grid();
    assert_eq!(g.dims, [4, 3, 3]);
    assert_eq!(g.spacing, [0.75, 0.5, 2.0]);
    assert_eq!(l.series[0].images, 3);
    let v = l.volume.to_f32();
    assert_eq!(l.volume.scalar_type(), ScalarType::I16);
    for k in 0..3 {
        assert_eq!(v.data()[k * 12], (1000 + 100 * k) as f32 - 1024.0);
    }
}

#[test]
fn truncated_and_corrupted_files_are_errors_never_panics() {
    let s = five();
    let good = s[0].bytes("1.2.3.1");
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("x.dcm");
    for cut in [0, 100, 131, 140, 200, 300, good.len() - 10, good.len() - 1] {
        std::fs::write(&p, &good[..cut]).unwrap();
        let e = err_of(crate::read_volume_with(&p, &opts()));
        assert!(e.contains("x.dcm"), "cut {cut}: {e}");
    }
    // A truncated slice in a series.
    let dir = series_dir(&s, &NAMES);
    let q = dir.path().join(NAMES[2]);
    let b = std::fs::read(&q).unwrap();
    std::fs::write(&q, &b[..b.len() - 7]).unwrap();
    let e = err_of(read_dicom_with(dir.path(), &opts()));
    assert!(e.contains(NAMES[2]), "{e}");
    // A value declaring 4 GiB in a small file: refused before allocating.
    let mut huge = good.clone();
    let at = find(&huge, &[0x08, 0x00, 0x3E, 0x10]).unwrap(); // SeriesDescription, LO
    huge[at + 6..at + 8].copy_from_slice(&0xFFFEu16.to_le_bytes());
    std::fs::write(&p, &huge).unwrap();
    let e = err_of(crate::read_volume_with(&p, &opts()));
    assert!(e.contains("declares 65534 bytes"), "{e}");
    let at = find(&huge, &[0xE0, 0x7F, 0x10, 0x00]).unwrap(); // PixelData, OW
    huge[at + 8..at + 12].copy_from_slice(&0xFFFF_FFF0u32.to_le_bytes());
    std::fs::write(&p, &huge).unwrap();
    assert!(crate::read_volume_with(&p, &opts()).is_err());
}

pub(crate) fn find(h: &[u8], n: &[u8]) -> Option<usize> {
    h.windows(n.len()).position(|w| w == n)
}

#[test]
fn deeply_nested_sequences_are_refused() {
    // (0008,1115) ReferencedSeriesSequence, nested 200 deep with undefined lengths.
    let mut body = Vec::new();
    for _ in 0..200 {
        body.extend([
            0x08, 0x00, 0x15, 0x11, b'S', b'Q', 0, 0, 0xFF, 0xFF, 0xFF, 0xFF,
        ]);
        body.extend([0xFE, 0xFF, 0x00, 0xE0, 0xFF, 0xFF, 0xFF, 0xFF]);
    }
    let mut good = Slice::ct(0.0, 0).bytes("1.2.3");
    // Splice before (0008,0016) SOPClassUID, the first data set element.
    let at = find(&good, &[0x08, 0x00, 0x16, 0x00, b'U', b'I']).unwrap();
    good.splice(at..at, body);
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("deep.dcm");
    std::fs::write(&p, &good).unwrap();
    let e = err_of(crate::read_volume_with(&p, &opts()));
    assert!(e.contains("nest deeper"), "{e}");
}

#[test]
fn random_corruption_never_panics() {
    let mut state = 0x9E37_79B9_7F4A_7C15u64;
    let mut rnd = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("c.dcm");
    let small = ReadOptions {
        limits: Limits {
            max_voxels: 1 << 16,
            ..Limits::default()
        },
        ..opts()
    };
    for ts in [
        EXPLICIT_LE,
        IMPLICIT_LE,
        DEFLATED,
        RLE,
        JPEG_BASELINE,
        EXPLICIT_BE,
    ] {
        let mut s = Slice::ct(0.0, 0);
        s.ts = ts;
        if ts == JPEG_BASELINE {
            s.bits = 8;
            s.values = (0..12).map(|p| p * 10).collect();
        }
        let good = s.bytes("1.2.3");
        for _ in 0..150 {
            let mut b = good.clone();
            match rnd() % 3 {
                0 => b.truncate(rnd() as usize % b.len()),
                1 => {
                    for _ in 0..1 + rnd() % 6 {
                        let i = 128 + rnd() as usize % (b.len() - 128);
                        b[i] = rnd() as u8;
                    }
                }
                _ => {
                    let i = 128 + rnd() as usize % (b.len() - 128);
                    let v = [0xFFu8, 0x00, 0x7F, 0x80][rnd() as usize % 4];
                    for x in b.iter_mut().skip(i).take(4) {
                        *x = v;
                    }
                }
            }
            std::fs::write(&p, &b).unwrap();
            let _ = crate::read_volume_with(&p, &small);
        }
    }
}

/// Fuzzing found (cargo-fuzz `dicom`): a numeric element (FD) whose length is not a multiple of
/// 8 makes dicom-parser read fewer bytes than its length; the structure walk assumed it read
/// them all, lost step with the parser, and let a 1.5 GB Pixel Data length through to an
/// allocation. The walk now follows the parser's actual reads.
#[test]
fn fuzz_numeric_length_not_a_multiple_of_the_value_size() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("x.dcm");
    std::fs::write(&p, include_bytes!("testdata/fuzz-fd-odd-length.dcm")).unwrap();
    let e = err_of(crate::read_volume_with(&p, &opts()));
    // Refused by the walk, before dicom-object allocates.
    assert!(
        e.contains("x.dcm") && e.contains("declares 1546715148 bytes"),
        "{e}"
    );
}

#[test]
fn sub_folders_are_searched_from_a_folder_not_from_a_file() {
    let dir = tempfile::tempdir().unwrap();
    let a = dir.path().join("PAT/ST0/SE1");
    std::fs::create_dir_all(&a).unwrap();
    for (i, s) in five().iter().enumerate() {
        s.write(&a.join(format!("IM{i}")));
    }
    let l = crate::read_volume_with(dir.path(), &opts()).unwrap();
    assert_eq!(l.volume.grid().dims, [4, 3, 5]);
    // A file of the top folder stands for its series there, without the sub-folders.
    let mut s = Slice::ct(0.0, 0);
    s.series = "1.2.3.4.5.99".into();
    s.write(&dir.path().join("top.dcm"));
    let l = crate::read_volume_with(dir.path().join("top.dcm"), &opts()).unwrap();
    assert_eq!((l.volume.grid().dims, l.series.len()), ([4, 3, 1], 1));
    let list = list_dicom_series(dir.path(), &Limits::default()).unwrap();
    assert_eq!(list.len(), 2);
}

/// Issue 29 item 5: when the read of a DICOM file is confined to its folder, the scan of the
/// folder reads no file that leads out of it (its series, its description, its pixels), and
/// says so; unconfined, the links are followed as before.
#[test]
#[cfg(unix)]
fn confined_scans_skip_files_outside_the_folder() {
    use crate::confine::tests::layout;
    let l = layout(&[]);
    Slice::ct(0.0, 0).write(&l.data.join("a.dcm"));
    let mut b = Slice::ct(2.5, 1);
    b.instance = 2;
    b.write(&l.root.path().join("b.dcm"));
    let mut other = Slice::ct(0.0, 2);
    other.instance = 3;
    other.series = "1.2.826.0.1.3680043.2.1125.99".into();
    other.description = "SECRET".into();
    other.write(&l.root.path().join("other.dcm"));
    std::os::unix::fs::symlink("../b.dcm", l.data.join("b.dcm")).unwrap();
    std::os::unix::fs::symlink("../other.dcm", l.data.join("other.dcm")).unwrap();
    let open = read_dicom_with(l.data.join("a.dcm"), &opts()).unwrap();
    assert_eq!(open.volume.grid().dims, [4, 3, 2]);
    assert!(open.series.iter().any(|s| s.description == "SECRET"));
    let o = ReadOptions {
        limits: l.limits.clone(),
        ..opts()
    };
    for given in [l.data.join("a.dcm"), l.data.clone()] {
        let c = read_dicom_with(&given, &o).unwrap();
        assert_eq!(c.volume.grid().dims, [4, 3, 1], "{}", given.display());
        assert_eq!(c.volume.to_f32().data()[0], 1000.0 - 1024.0);
        assert!(!c.series.iter().any(|s| s.description == "SECRET"));
        assert!(
            c.notes.iter().any(|n| n.contains("file(s) leading out of")),
            "{:?}",
            c.notes
        );
    }
    let list = list_dicom_series(&l.data, &l.limits).unwrap();
    assert!(!list.iter().any(|s| s.description == "SECRET"), "{list:?}");
    // Named one by one, a link out is refused.
    let e = read_dicom_files(&[l.data.join("a.dcm"), l.data.join("b.dcm")], &o).unwrap_err();
    assert!(matches!(e, IoError::OutsideFolder { .. }), "{e}");
    assert!(e.to_string().contains("b.dcm"), "{e}");
}
