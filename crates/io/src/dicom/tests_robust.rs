//! Issue 28: files as real systems write them, and files made to hurt. Crafted here with
//! dicom-object; compressed frames come from `testdata/` (made by reference encoders, see
//! `testdata/make_codec_fixtures.py`).

use super::header::*;
use super::tests::*;
use super::*;
use dicom_core::header::Length;
use dicom_core::value::{PixelFragmentSequence, PrimitiveValue, Value};
use dicom_core::{DataElement, VR};
use dicom_object::FileMetaTableBuilder;
use volsplat_core::ScalarType;

fn put(o: &mut InMemDicomObject, a: Attr, vr: VR, v: PrimitiveValue) {
    o.put(DataElement::new(a.tag(), vr, v));
}

fn fragments(frags: Vec<Vec<u8>>) -> DataElement<InMemDicomObject> {
    DataElement::new(
        PIXEL_DATA.tag(),
        VR::OB,
        Value::from(PixelFragmentSequence::new(Vec::<u32>::new(), frags)),
    )
}

fn write_file(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

fn i32s(bytes: &[u8]) -> Vec<i32> {
    bytes
        .chunks_exact(4)
        .map(|c| i32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect()
}

/// The fixtures: name, transfer syntax, bits allocated, signed, tolerance against the
/// reference decoder (grey levels).
const FIXTURES: [(&str, &str, u16, bool, i32); 6] = [
    ("j2k_lossless_s16", JPEG_2000, 16, true, 0),
    ("j2k_lossy_u12", JPEG_2000_LOSSY, 16, false, 1),
    ("jls_lossless_u16", JPEG_LS, 16, false, 0),
    ("jls_near2_u8", JPEG_LS_NEAR, 8, false, 0),
    ("jpeg_extended_u12", JPEG_EXTENDED, 16, false, 1),
    ("jpeg_lossless_u12", JPEG_LOSSLESS_SV1, 16, false, 0),
];

fn fixture(name: &str) -> (Vec<u8>, Vec<i32>) {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("src/dicom/testdata");
    let stream = std::fs::read(dir.join(format!("{name}.bin"))).unwrap();
    let want = i32s(&std::fs::read(dir.join(format!("{name}.i32"))).unwrap());
    (stream, want)
}

/// A 24 × 20 slice (the fixtures' size) without rescale.
fn fixture_slice(ts: &'static str, bits: u16, signed: bool) -> Slice {
    let mut s = Slice::ct(0.0, 0);
    (s.rows, s.cols, s.bits, s.signed, s.ts) = (20, 24, bits, signed, ts);
    s.intercept = 0.0;
    s
}

fn encapsulated(s: &Slice, frags: Vec<Vec<u8>>) -> Vec<u8> {
    let mut o = s.object("1.2.3.9");
    o.put(fragments(frags));
    file_bytes(o, s.ts)
}

/// JPEG 2000 (.90 lossless, .91 lossy), JPEG-LS (.80, .81), 12-bit JPEG extended (.51) and
/// 12-bit JPEG lossless (.70) read the samples OpenJPEG, CharLS and libjpeg-turbo read from the
/// same codestreams (lossless ones: exactly the source image).
#[test]
fn compressed_frames_match_the_reference_decoders() {
    let dir = tempfile::tempdir().unwrap();
    for (name, ts, bits, signed, tol) in FIXTURES {
        let (stream, want) = fixture(name);
        let s = fixture_slice(ts, bits, signed);
        let p = write_file(
            dir.path(),
            &format!("{name}.dcm"),
            &encapsulated(&s, vec![stream]),
        );
        let l = crate::read_volume_with(&p, &opts()).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(l.volume.grid().dims, [24, 20, 1], "{name}");
        let got = l.volume.to_f32();
        let worst = got
            .data()
            .iter()
            .zip(&want)
            .map(|(&a, &b)| (a as i64 - b as i64).abs())
            .max()
            .unwrap();
        assert!(worst <= tol as i64, "{name}: differs by up to {worst}");
        // Lossy streams really are lossy here (the comparison is not with the source).
        if tol > 0 {
            assert!(want.iter().any(|&v| v != want[0]), "{name}");
        }
        let notes = l.notes.join("\n");
        assert!(notes.contains("transfer syntax"), "{notes}");
        std::fs::remove_file(&p).unwrap();
    }
}

/// A codestream whose size or components disagree with Rows/Columns/SamplesPerPixel is refused
/// before decoding; corrupted codestreams are errors naming the file and frame, never panics.
#[test]
fn malformed_compressed_frames_are_errors() {
    for (name, ts, bits, signed, _) in FIXTURES {
        let dir = tempfile::tempdir().unwrap();
        let (stream, _) = fixture(name);
        let mut s = fixture_slice(ts, bits, signed);
        s.rows = 19;
        let p = write_file(dir.path(), "x.dcm", &encapsulated(&s, vec![stream.clone()]));
        let e = err_of(crate::read_volume_with(&p, &opts()));
        assert!(
            e.contains("x.dcm") && e.contains("frame 0") && e.contains("24 × 20"),
            "{name}: {e}"
        );
        std::fs::remove_file(&p).unwrap();
        let s = fixture_slice(ts, bits, signed);
        let mut state = 0x2545_F491_4F6C_DD1Du64;
        for k in 0..60 {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            let mut b = stream.clone();
            if k % 3 == 0 {
                b.truncate(state as usize % b.len());
            } else {
                for j in 0..1 + k % 5 {
                    let i = (state >> (8 * j)) as usize % b.len();
                    b[i] ^= (state >> 32) as u8 | 1;
                }
            }
            let p = write_file(dir.path(), "c.dcm", &encapsulated(&s, vec![b]));
            // Either an error or a volume of the declared size: never a panic.
            if let Ok(l) = crate::read_volume_with(&p, &opts()) {
                assert_eq!(l.volume.grid().dims, [24, 20, 1], "{name} {k}");
            }
        }
    }
}

/// Issue 28 §2: Rows × Columns 65535² (or 20000²) with a few bytes of pixel data is refused
/// from the header, before anything of that size is allocated.
#[test]
fn huge_rows_and_columns_with_few_pixel_bytes_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    for (side, ts) in [
        (65535u16, EXPLICIT_LE),
        (20000, IMPLICIT_LE),
        (65535, DEFLATED),
        (65535, RLE),
        (40000, DEFLATED_FRAMES),
    ] {
        let mut s = Slice::ct(0.0, 0);
        (s.rows, s.cols, s.ts) = (side, side, ts);
        s.values = vec![7; 6];
        let p = write_file(dir.path(), "big.dcm", &s.bytes("1.2.3.4"));
        let e = err_of(crate::read_volume_with(&p, &opts()));
        assert!(e.contains("big.dcm"), "{ts}: {e}");
        let native = matches!(ts, EXPLICIT_LE | IMPLICIT_LE | DEFLATED);
        if native {
            assert!(
                e.contains("PixelData (7FE0,0010)") && e.contains("truncated"),
                "{ts}: {e}"
            );
        } else {
            assert!(e.contains("frame 0"), "{ts}: {e}");
        }
    }
}

/// Issue 28 §2: a folder of tiny files each declaring 65536 frames without per-frame
/// positions; each is refused as it is scanned (no per-frame geometry is built).
#[test]
fn files_declaring_many_frames_without_positions_are_refused_when_scanned() {
    let dir = tempfile::tempdir().unwrap();
    for i in 0..40 {
        let mut s = Slice::ct(i as f64, 0);
        s.instance = i;
        let mut o = s.object(&format!("1.2.3.{i}"));
        put(&mut o, FRAMES, VR::IS, "65536".into());
        o.put(s.pixel_element());
        write_file(
            dir.path(),
            &format!("f{i}.dcm"),
            &file_bytes(o, EXPLICIT_LE),
        );
    }
    let e = err_of(read_dicom_with(dir.path(), &opts()));
    assert!(
        e.contains("NumberOfFrames") || e.contains("PixelData"),
        "{e}"
    );
    assert!(e.contains("f0.dcm"), "{e}");
    // The same with the pixel data the frames need, but no positions: refused by the frame
    // rule (cine and other multi-frame images without positions are not volumes).
    let s = Slice::ct(0.0, 0);
    let mut o = s.object("1.2.3.77");
    put(&mut o, FRAMES, VR::IS, "3".into());
    let words: Vec<u16> = (0..36).collect();
    o.put(DataElement::new(
        PIXEL_DATA.tag(),
        VR::OW,
        PrimitiveValue::U16(words.into()),
    ));
    let d2 = tempfile::tempdir().unwrap();
    let p = write_file(d2.path(), "cine.dcm", &file_bytes(o, EXPLICIT_LE));
    let e = err_of(crate::read_volume_with(&p, &opts()));
    assert!(
        e.contains("NumberOfFrames") && e.contains("positions"),
        "{e}"
    );
}

/// Issue 28 §2: a deflated data set inflates at most to the image it declares plus 64 MiB
/// (it used to be allowed up to 4 bytes per voxel of the voxel limit, 64 GiB).
#[test]
fn deflated_data_set_is_capped_by_its_declared_image() {
    let s = Slice::ct(0.0, 0);
    let dir = tempfile::tempdir().unwrap();
    let with = |tag: Tag, mib: usize| {
        let mut o = s.object("1.2.3.5");
        // Zeros: 80 MiB deflate to ~80 KB.
        let zeros = PrimitiveValue::U8(vec![0u8; mib << 20].into());
        if tag == PIXEL_DATA.tag() {
            o.put(DataElement::new(tag, VR::OB, zeros));
        } else {
            o.put(DataElement::new(tag, VR::OB, zeros));
            o.put(s.pixel_element());
        }
        file_bytes(o, DEFLATED)
    };
    // 80 MiB of pixel data for a 4 × 3 image: refused at 64 MiB past the image.
    let bytes = with(PIXEL_DATA.tag(), 80);
    assert!(bytes.len() < 1 << 20, "{}", bytes.len());
    let p = write_file(dir.path(), "bomb.dcm", &bytes);
    let e = err_of(crate::read_volume_with(&p, &opts()));
    assert!(
        e.contains("bomb.dcm") && e.contains("inflated size") && e.contains("Rows 3 × Columns 4"),
        "{e}"
    );
    // 80 MiB in a private element before the pixel data: refused while reading the header.
    let p = write_file(dir.path(), "bomb.dcm", &with(Tag(0x0029, 0x1010), 80));
    let e = err_of(crate::read_volume_with(&p, &opts()));
    assert!(e.contains("before Pixel Data"), "{e}");
    // 60 MiB of other elements is within the allowance: read.
    let p = write_file(dir.path(), "bomb.dcm", &with(Tag(0x0029, 0x1010), 60));
    let l = crate::read_volume_with(&p, &opts()).unwrap();
    assert_eq!(l.volume.grid().dims, [4, 3, 1]);
}

/// Issue 28 §4: unusable siblings of a file (no SeriesInstanceUID, a corrupt header, a DICOMDIR
/// whose records are broken, a broken file of another series) are skipped with a note; only the
/// series asked for must be good.
#[test]
fn unusable_siblings_are_skipped_with_a_note() {
    let dir = series_dir(&five(), &NAMES);
    // No SeriesInstanceUID.
    let mut o = Slice::ct(50.0, 0).object("1.2.3.60");
    o.remove_element(SERIES_UID.tag());
    o.put(Slice::ct(50.0, 0).pixel_element());
    write_file(dir.path(), "nouid.dcm", &file_bytes(o, EXPLICIT_LE));
    // A header cut short.
    let good = Slice::ct(60.0, 0).bytes("1.2.3.61");
    write_file(dir.path(), "cut.dcm", &good[..200]);
    // A DICOMDIR whose records are garbage.
    let mut dd = InMemDicomObject::new_empty();
    put(
        &mut dd,
        Attr(0x0004, 0x1130, "FileSetID"),
        VR::CS,
        "X".into(),
    );
    let meta = FileMetaTableBuilder::new()
        .transfer_syntax(EXPLICIT_LE)
        .media_storage_sop_class_uid("1.2.840.10008.1.3.10")
        .media_storage_sop_instance_uid("1.2.3.62");
    let mut ddb = Vec::new();
    dd.with_meta(meta).unwrap().write_all(&mut ddb).unwrap();
    ddb.extend([
        0x04, 0x00, 0x20, 0x12, b'S', b'Q', 0, 0, 0xF0, 0xFF, 0xFF, 0x0F,
    ]);
    write_file(dir.path(), "DICOMDIR", &ddb);
    // A file of another series whose pixel data is short.
    let mut other = Slice::ct(0.0, 0);
    other.series = "1.2.3.4.5.99".into();
    let b = other.bytes("1.2.3.63");
    write_file(dir.path(), "other.dcm", &b[..b.len() - 10]);

    for p in [dir.path().join(NAMES[0]), dir.path().to_path_buf()] {
        let o = if p.is_dir() {
            ReadOptions {
                series: Some("3".into()),
                ..opts()
            }
        } else {
            opts()
        };
        let l = read_dicom_with(&p, &o).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
        assert_eq!(l.volume.grid().dims, [4, 3, 5]);
        let notes = l.notes.join("\n");
        for name in ["nouid.dcm", "cut.dcm", "other.dcm"] {
            assert!(notes.contains(name), "{name} not in\n{notes}");
        }
        assert!(notes.contains("SeriesInstanceUID"), "{notes}");
        assert!(!notes.contains("DICOMDIR ("), "{notes}");
    }
    // The broken series, asked for: its file's error.
    let o = ReadOptions {
        series: Some("1.2.3.4.5.99".into()),
        ..opts()
    };
    let e = err_of(read_dicom_with(dir.path(), &o));
    assert!(e.contains("other.dcm") && e.contains("truncated"), "{e}");
    // The file without a series UID, given: read alone.
    let l = read_dicom_with(dir.path().join("nouid.dcm"), &opts()).unwrap();
    assert_eq!(l.volume.grid().dims, [4, 3, 1]);
    assert!(
        l.notes.iter().any(|n| n.contains("read alone")),
        "{:?}",
        l.notes
    );
}

/// Copies of one instance (same SOPInstanceUID and geometry, other transfer syntaxes) beside
/// the file given are one image, not two slices at one position.
#[test]
fn copies_of_an_instance_are_read_once() {
    let dir = tempfile::tempdir().unwrap();
    let mut s = Slice::ct(0.0, 0);
    s.write(&dir.path().join("a.dcm"));
    s.ts = RLE;
    s.write(&dir.path().join("b_rle.dcm"));
    let l = read_dicom_with(dir.path().join("b_rle.dcm"), &opts()).unwrap();
    assert_eq!(l.volume.grid().dims, [4, 3, 1]);
    let notes = l.notes.join("\n");
    assert!(notes.contains("a.dcm (as b_rle.dcm)"), "{notes}");
    assert!(notes.contains("RLE"), "{notes}");
    // Same UID, another position: the given file's instance all the same; from the folder
    // (no file given) it is not a copy and stays a slice.
    s.ipp = Some([-10.0, -20.0, 5.0]);
    s.write(&dir.path().join("c.dcm"));
    let l = read_dicom_with(dir.path().join("b_rle.dcm"), &opts()).unwrap();
    assert_eq!(l.volume.grid().dims, [4, 3, 1]);
    assert!(l.notes.join("\n").contains("c.dcm (as b_rle.dcm)"));
    let l = read_dicom_with(dir.path(), &opts()).unwrap();
    assert_eq!(l.volume.grid().dims, [4, 3, 2]);
}

/// An enhanced multi-frame object with `n` frames of `rows` × `cols` u16 at z = 2k (stored in
/// reverse order), frame k holding `k + p` at pixel p.
pub(crate) fn enhanced(n: usize, rows: u16, cols: u16) -> Vec<u8> {
    let mut s = Slice::ct(0.0, 0);
    (s.rows, s.cols) = (rows, cols);
    let mut o = s.object("1.2.3.77");
    put(
        &mut o,
        SOP_CLASS,
        VR::UI,
        "1.2.840.10008.5.1.4.1.1.4.1".into(),
    );
    for a in [IPP, IOP, PIXEL_SPACING] {
        o.remove_element(a.tag());
    }
    let seq = |a: Attr, item: InMemDicomObject| {
        DataElement::new(
            a.tag(),
            VR::SQ,
            Value::new_sequence(vec![item], Length::UNDEFINED),
        )
    };
    let mut shared = InMemDicomObject::new_empty();
    let mut m = InMemDicomObject::new_empty();
    put(&mut m, PIXEL_SPACING, VR::DS, Slice::ds(&[0.5, 0.75]));
    shared.put(seq(PIXEL_MEASURES, m));
    let mut or = InMemDicomObject::new_empty();
    put(
        &mut or,
        IOP,
        VR::DS,
        Slice::ds(&[1.0, 0.0, 0.0, 0.0, 1.0, 0.0]),
    );
    shared.put(seq(PLANE_ORIENTATION, or));
    o.put(seq(SHARED_GROUPS, shared));
    let mut items = Vec::with_capacity(n);
    let plane = rows as usize * cols as usize;
    let mut words: Vec<u16> = Vec::with_capacity(n * plane);
    for f in 0..n {
        let k = n - 1 - f;
        let mut pos = InMemDicomObject::new_empty();
        put(
            &mut pos,
            IPP,
            VR::DS,
            Slice::ds(&[0.0, 0.0, 2.0 * k as f64]),
        );
        let mut it = InMemDicomObject::new_empty();
        it.put(seq(PLANE_POSITION, pos));
        items.push(it);
        words.extend((0..plane).map(|p| (k + p) as u16));
    }
    o.put(DataElement::new(
        PER_FRAME_GROUPS.tag(),
        VR::SQ,
        Value::new_sequence(items, Length::UNDEFINED),
    ));
    put(&mut o, FRAMES, VR::IS, n.to_string().into());
    o.put(DataElement::new(
        PIXEL_DATA.tag(),
        VR::OW,
        PrimitiveValue::U16(words.into()),
    ));
    file_bytes(o, EXPLICIT_LE)
}

/// Many frames, sorted by their per-frame positions; the per-frame sequence may hold more items
/// than frames (a file cut to fewer frames): the first are used, with a note.
#[test]
fn enhanced_multi_frame_with_many_frames() {
    let dir = tempfile::tempdir().unwrap();
    let p = write_file(dir.path(), "mf.dcm", &enhanced(40, 6, 5));
    let l = crate::read_volume_with(&p, &opts()).unwrap();
    let g = l.volume.grid();
    assert_eq!((g.dims, g.spacing), ([5, 6, 40], [0.75, 0.5, 2.0]));
    let v = l.volume.to_f32();
    for k in 0..40 {
        for p in [0, 7, 29] {
            assert_eq!(v.data()[k * 30 + p], (k + p) as f32 - 1024.0, "k {k} p {p}");
        }
    }
    // Declare 39 frames over the 40 items and 40 frames of data.
    let mut b = enhanced(40, 6, 5);
    // NumberOfFrames (0028,0008) IS, 2 bytes: "40".
    let at = find(&b, &[0x28, 0x00, 0x08, 0x00, b'I', b'S', 2, 0]).unwrap() + 8;
    assert_eq!(&b[at..at + 2], b"40");
    b[at..at + 2].copy_from_slice(b"39");
    let dir = tempfile::tempdir().unwrap();
    let p = write_file(dir.path(), "cut.dcm", &b);
    let l = crate::read_volume_with(&p, &opts()).unwrap();
    assert_eq!(l.volume.grid().dims[2], 39);
    assert!(
        l.notes.iter().any(|n| n.contains("first 39 used")),
        "{:?}",
        l.notes
    );
}

/// RT Dose (PS3.3 §C.8.8.3.2): a classic multi-frame image placed by GridFrameOffsetVector,
/// relative (first offset 0) or absolute z (axial), scaled by DoseGridScaling.
#[test]
fn grid_frame_offsets_make_a_dose_volume() {
    let dir = tempfile::tempdir().unwrap();
    for (offsets, origin_z) in [([0.0, 2.5, 5.0], 10.0), ([-4.0, -1.5, 1.0], -4.0)] {
        let mut s = Slice::ct(10.0, 0);
        s.intercept = 0.0;
        s.slope = 1.0;
        let mut o = s.object("1.2.3.8");
        put(&mut o, FRAMES, VR::IS, "3".into());
        put(&mut o, GRID_FRAME_OFFSETS, VR::DS, Slice::ds(&offsets));
        put(&mut o, DOSE_GRID_SCALING, VR::DS, Slice::ds(&[0.5]));
        put(&mut o, DOSE_UNITS, VR::CS, "GY".into());
        let words: Vec<u16> = (0..36).collect();
        o.put(DataElement::new(
            PIXEL_DATA.tag(),
            VR::OW,
            PrimitiveValue::U16(words.into()),
        ));
        let p = write_file(dir.path(), "dose.dcm", &file_bytes(o, IMPLICIT_LE));
        let l = crate::read_volume_with(&p, &opts()).unwrap();
        let g = l.volume.grid();
        assert_eq!(g.dims, [4, 3, 3]);
        assert_eq!(g.spacing[2], 2.5);
        assert_eq!(g.origin, [-10.0, -20.0, origin_z]);
        assert_eq!(l.volume.scalar_type(), ScalarType::F32);
        let v = l.volume.to_f32();
        assert_eq!(v.data()[35], 17.5);
        let notes = l.notes.join("\n");
        assert!(
            notes.contains("DoseGridScaling") && notes.contains("GY"),
            "{notes}"
        );
        assert!(notes.contains("GridFrameOffsetVector"), "{notes}");
    }
}

/// PALETTE COLOR: a grey palette is applied (values are the palette's); a colour palette is a
/// colour image, refused with a message saying so.
#[test]
fn palette_color_grey_applied_colour_refused() {
    let dir = tempfile::tempdir().unwrap();
    for grey in [true, false] {
        let mut s = Slice::ct(0.0, 0);
        (s.bits, s.intercept) = (8, 0.0);
        s.values = (0..12).collect();
        let mut o = s.object("1.2.3.9");
        put(&mut o, PHOTOMETRIC, VR::CS, "PALETTE COLOR".into());
        // 8 entries from stored value 2, 16 bits each: entry e is 1000 + 100 e.
        for k in 0..3 {
            o.put(DataElement::new(
                PALETTE_DESCRIPTORS[k].tag(),
                VR::US,
                PrimitiveValue::U16(vec![8u16, 2, 16].into()),
            ));
            let table: Vec<u16> = (0..8)
                .map(|e| 1000 + 100 * e + if grey { 0 } else { k as u16 })
                .collect();
            o.put(DataElement::new(
                PALETTE_DATA[k].tag(),
                VR::OW,
                PrimitiveValue::U16(table.into()),
            ));
        }
        o.put(s.pixel_element());
        let p = write_file(dir.path(), "pal.dcm", &file_bytes(o, EXPLICIT_LE));
        let r = crate::read_volume_with(&p, &opts());
        if grey {
            let l = r.unwrap();
            let v = l.volume.to_f32();
            // Below the first mapped value: entry 0; above the last: entry 7.
            assert_eq!(v.data()[..4], [1000.0, 1000.0, 1000.0, 1100.0]);
            assert_eq!(v.data()[11], 1700.0);
            assert!(l.notes.iter().any(|n| n.contains("grey palette")));
        } else {
            let e = err_of(r);
            assert!(e.contains("colour palette"), "{e}");
        }
    }
}

/// Attributes stored with VR UN (here ImagePositionPatient and Rows) are decoded by their
/// dictionary VR, as pydicom does.
#[test]
fn un_attributes_are_read_by_their_dictionary_vr() {
    let s = Slice::ct(7.5, 0);
    let mut o = s.object("1.2.3.10");
    o.put(DataElement::new(
        IPP.tag(),
        VR::UN,
        PrimitiveValue::U8(b"-10\\-20\\7.5 ".to_vec().into()),
    ));
    o.put(DataElement::new(
        ROWS.tag(),
        VR::UN,
        PrimitiveValue::U8(3u16.to_le_bytes().to_vec().into()),
    ));
    o.put(s.pixel_element());
    let dir = tempfile::tempdir().unwrap();
    let p = write_file(dir.path(), "un.dcm", &file_bytes(o, EXPLICIT_LE));
    let l = crate::read_volume_with(&p, &opts()).unwrap();
    assert_eq!(l.volume.grid().origin, [-10.0, -20.0, 7.5]);
    assert_eq!(l.volume.grid().dims, [4, 3, 1]);
}

/// A meta group declaring explicit VR little endian before a data set written in implicit VR
/// (and the reverse) is read as written, with a note.
#[test]
fn data_set_in_the_other_vr_encoding_is_read_as_written() {
    let reference = {
        let dir = series_dir(&five()[..1], &["a.dcm"]);
        read_dicom(dir.path()).unwrap().to_f32()
    };
    let dir = tempfile::tempdir().unwrap();
    for (declared, written) in [(EXPLICIT_LE, IMPLICIT_LE), (IMPLICIT_LE, EXPLICIT_LE)] {
        let s = &five()[0];
        let mut o = s.object("1.2.3.11");
        o.put(s.pixel_element());
        let meta = FileMetaTableBuilder::new()
            .transfer_syntax(declared)
            .media_storage_sop_class_uid("1.2.840.10008.5.1.4.1.1.2")
            .media_storage_sop_instance_uid("1.2.3.11")
            .build()
            .unwrap();
        let mut b = vec![0u8; 128];
        b.extend(b"DICM");
        meta.write(&mut b).unwrap();
        let ts = dicom_transfer_syntax_registry::TransferSyntaxRegistry
            .get(written)
            .unwrap();
        o.write_dataset_with_ts(&mut b, ts).unwrap();
        let p = write_file(dir.path(), "x.dcm", &b);
        let l = crate::read_volume_with(&p, &opts()).unwrap_or_else(|e| panic!("{declared}: {e}"));
        assert_eq!(l.volume.to_f32(), reference, "{declared}");
        let notes = l.notes.join("\n");
        assert!(notes.contains("read as written"), "{notes}");
    }
}

use dicom_encoding::TransferSyntaxIndex;

/// Bits Allocated 1 (segmentation-like masks): packed bits, first pixel in the least significant
/// bit, frames not byte-aligned (PS3.5 §8.1.1).
#[test]
fn one_bit_samples_are_unpacked() {
    let s = Slice::ct(0.0, 0);
    let mut o = s.object("1.2.3.12");
    for (a, v) in [(BITS_ALLOCATED, 1u16), (BITS_STORED, 1), (HIGH_BIT, 0)] {
        put(&mut o, a, VR::US, PrimitiveValue::from(v));
    }
    put(&mut o, INTERCEPT, VR::DS, Slice::ds(&[0.0]));
    put(&mut o, FRAMES, VR::IS, "3".into());
    put(
        &mut o,
        GRID_FRAME_OFFSETS,
        VR::DS,
        Slice::ds(&[0.0, 1.0, 2.0]),
    );
    // 36 bits: bit b is set when b % 3 == 0 or b == 35.
    let mut bits = [0u8; 6];
    for b in (0..36).filter(|b| b % 3 == 0 || *b == 35) {
        bits[b / 8] |= 1 << (b % 8);
    }
    o.put(DataElement::new(
        PIXEL_DATA.tag(),
        VR::OB,
        PrimitiveValue::U8(bits.to_vec().into()),
    ));
    let dir = tempfile::tempdir().unwrap();
    let p = write_file(dir.path(), "mask.dcm", &file_bytes(o, EXPLICIT_LE));
    let l = crate::read_volume_with(&p, &opts()).unwrap();
    assert_eq!(l.volume.grid().dims, [4, 3, 3]);
    assert_eq!(l.volume.scalar_type(), ScalarType::U8);
    let v = l.volume.to_f32();
    for b in 0..36 {
        let want = if b % 3 == 0 || b == 35 { 1.0 } else { 0.0 };
        assert_eq!(v.data()[b], want, "bit {b}");
    }
}

/// Seeds for the `dicom` fuzz target (`fuzz/seeds/dicom/`), one per kind of file this module
/// reads since issue 28: `VOLSPLAT_FUZZ_SEEDS=fuzz/seeds cargo test -p volsplat-io
/// write_dicom_fuzz_seeds -- --ignored`.
#[test]
#[ignore]
fn write_dicom_fuzz_seeds() {
    let Some(root) = std::env::var_os("VOLSPLAT_FUZZ_SEEDS") else {
        return;
    };
    let d = PathBuf::from(root).join("dicom");
    std::fs::create_dir_all(&d).unwrap();
    for (name, ts, bits, signed, _) in FIXTURES {
        let (stream, _) = fixture(name);
        let s = fixture_slice(ts, bits, signed);
        std::fs::write(
            d.join(format!("{name}.dcm")),
            encapsulated(&s, vec![stream]),
        )
        .unwrap();
    }
    std::fs::write(d.join("enhanced.dcm"), enhanced(3, 4, 3)).unwrap();
    let mut s = Slice::ct(0.0, 0);
    s.ts = RLE;
    std::fs::write(d.join("rle16.dcm"), s.bytes("1.2.3.20")).unwrap();
    s.ts = DEFLATED_FRAMES;
    std::fs::write(d.join("deflated_frames.dcm"), s.bytes("1.2.3.21")).unwrap();
    // RT dose with GridFrameOffsetVector.
    let s = Slice::ct(10.0, 0);
    let mut o = s.object("1.2.3.22");
    put(&mut o, FRAMES, VR::IS, "2".into());
    put(&mut o, GRID_FRAME_OFFSETS, VR::DS, Slice::ds(&[0.0, 2.5]));
    put(&mut o, DOSE_GRID_SCALING, VR::DS, Slice::ds(&[0.5]));
    let words: Vec<u16> = (0..24).collect();
    o.put(DataElement::new(
        PIXEL_DATA.tag(),
        VR::OW,
        PrimitiveValue::U16(words.into()),
    ));
    std::fs::write(d.join("dose.dcm"), file_bytes(o, IMPLICIT_LE)).unwrap();
    // Grey palette, 8-bit indices.
    let mut s = Slice::ct(0.0, 0);
    (s.bits, s.intercept) = (8, 0.0);
    let mut o = s.object("1.2.3.23");
    put(&mut o, PHOTOMETRIC, VR::CS, "PALETTE COLOR".into());
    for k in 0..3 {
        o.put(DataElement::new(
            PALETTE_DESCRIPTORS[k].tag(),
            VR::US,
            PrimitiveValue::U16(vec![4u16, 0, 16].into()),
        ));
        o.put(DataElement::new(
            PALETTE_DATA[k].tag(),
            VR::OW,
            PrimitiveValue::U16(vec![0u16, 10, 20, 30].into()),
        ));
    }
    o.put(s.pixel_element());
    std::fs::write(d.join("palette.dcm"), file_bytes(o, EXPLICIT_LE)).unwrap();
    // Issue 28's crafted files: 65535² with a few bytes; 65536 frames without positions.
    let mut s = Slice::ct(0.0, 0);
    (s.rows, s.cols) = (65535, 65535);
    s.values = vec![7; 6];
    std::fs::write(d.join("huge.dcm"), s.bytes("1.2.3.24")).unwrap();
    let s = Slice::ct(0.0, 0);
    let mut o = s.object("1.2.3.25");
    put(&mut o, FRAMES, VR::IS, "65536".into());
    o.put(s.pixel_element());
    std::fs::write(d.join("frames.dcm"), file_bytes(o, EXPLICIT_LE)).unwrap();
}

/// Fuzzing found (cargo-fuzz `dicom`): an item delimiter (FFFE,E00D) at the top level, before a
/// header declaring 2.4 GB. The structure walk took the delimiter for an element past Pixel
/// Data and stopped, while dicom-object's `read_until` read on and allocated the 2.4 GB.
#[test]
fn fuzz_top_level_item_delimiter_before_a_huge_length() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("x.dcm");
    std::fs::write(&p, include_bytes!("testdata/fuzz-top-level-item-end.dcm")).unwrap();
    let e = err_of(crate::read_volume_with(&p, &opts()));
    assert!(
        e.contains("x.dcm") && e.contains("declares 2433941536 bytes"),
        "{e}"
    );
}

/// A colour image is refused as colour, whatever else it holds (here two frames without
/// positions and pixel data sized for subsampled chroma).
#[test]
fn colour_is_the_reason_given_for_colour_images() {
    let s = Slice::ct(0.0, 0);
    let mut o = s.object("1.2.3.13");
    put(&mut o, SAMPLES, VR::US, PrimitiveValue::from(3u16));
    put(&mut o, PHOTOMETRIC, VR::CS, "YBR_FULL_422".into());
    put(&mut o, FRAMES, VR::IS, "2".into());
    o.put(s.pixel_element());
    let dir = tempfile::tempdir().unwrap();
    let p = write_file(dir.path(), "rgb.dcm", &file_bytes(o, EXPLICIT_LE));
    let e = err_of(crate::read_volume_with(&p, &opts()));
    assert!(
        e.contains("colour image") && e.contains("YBR_FULL_422"),
        "{e}"
    );
}

/// Fuzzing found (cargo-fuzz `dicom`): a TransferSyntaxUID ending in a tab. dicom-object trims
/// it (implicit VR); the structure walk compared it untrimmed, walked explicit VR, and let a
/// 1.1 GB value length through to the parser.
#[test]
fn fuzz_transfer_syntax_uid_with_a_trailing_tab() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("x.dcm");
    std::fs::write(&p, include_bytes!("testdata/fuzz-ts-uid-trailing-tab.dcm")).unwrap();
    let e = err_of(crate::read_volume_with(&p, &opts()));
    assert!(
        e.contains("x.dcm") && e.contains("declares 1128875008 bytes"),
        "{e}"
    );
}
