//! One DICOM file's header: the attributes a series read needs, checked (PS3.3 §C.7.6.2, Image
//! Plane; §C.7.6.3, Image Pixel; §C.7.6.16, Multi-frame Functional Groups; §C.8.8.3, RT Dose),
//! read with dicom-object after the structure walk (`walk.rs`).

use super::*;
use dicom_core::VR;
use dicom_core::dictionary::{DataDictionary, DataDictionaryEntry};
use dicom_dictionary_std::StandardDataDictionary;
use dicom_encoding::TransferSyntaxIndex;
use dicom_encoding::transfer_syntax::TransferSyntax;
use dicom_transfer_syntax_registry::TransferSyntaxRegistry;

/// An attribute: tag and keyword, for lookups and messages.
#[derive(Debug, Clone, Copy)]
pub(super) struct Attr(pub u16, pub u16, pub &'static str);

impl Attr {
    pub(super) fn tag(self) -> Tag {
        Tag(self.0, self.1)
    }
    pub(super) fn label(self) -> String {
        format!("{} ({:04X},{:04X})", self.2, self.0, self.1)
    }
}

pub(super) const SOP_CLASS: Attr = Attr(0x0008, 0x0016, "SOPClassUID");
pub(super) const SOP_INSTANCE: Attr = Attr(0x0008, 0x0018, "SOPInstanceUID");
pub(super) const MODALITY: Attr = Attr(0x0008, 0x0060, "Modality");
pub(super) const SERIES_DESCRIPTION: Attr = Attr(0x0008, 0x103E, "SeriesDescription");
pub(super) const SLICE_THICKNESS: Attr = Attr(0x0018, 0x0050, "SliceThickness");
pub(super) const SPACING_BETWEEN: Attr = Attr(0x0018, 0x0088, "SpacingBetweenSlices");
pub(super) const GANTRY_TILT: Attr = Attr(0x0018, 0x1120, "GantryDetectorTilt");
pub(super) const SERIES_UID: Attr = Attr(0x0020, 0x000E, "SeriesInstanceUID");
pub(super) const SERIES_NUMBER: Attr = Attr(0x0020, 0x0011, "SeriesNumber");
pub(super) const IPP: Attr = Attr(0x0020, 0x0032, "ImagePositionPatient");
pub(super) const IOP: Attr = Attr(0x0020, 0x0037, "ImageOrientationPatient");
pub(super) const SAMPLES: Attr = Attr(0x0028, 0x0002, "SamplesPerPixel");
pub(super) const PHOTOMETRIC: Attr = Attr(0x0028, 0x0004, "PhotometricInterpretation");
pub(super) const FRAMES: Attr = Attr(0x0028, 0x0008, "NumberOfFrames");
pub(super) const ROWS: Attr = Attr(0x0028, 0x0010, "Rows");
pub(super) const COLUMNS: Attr = Attr(0x0028, 0x0011, "Columns");
pub(super) const PIXEL_SPACING: Attr = Attr(0x0028, 0x0030, "PixelSpacing");
pub(super) const BITS_ALLOCATED: Attr = Attr(0x0028, 0x0100, "BitsAllocated");
pub(super) const BITS_STORED: Attr = Attr(0x0028, 0x0101, "BitsStored");
pub(super) const HIGH_BIT: Attr = Attr(0x0028, 0x0102, "HighBit");
pub(super) const PIXEL_REPRESENTATION: Attr = Attr(0x0028, 0x0103, "PixelRepresentation");
pub(super) const INTERCEPT: Attr = Attr(0x0028, 0x1052, "RescaleIntercept");
pub(super) const SLOPE: Attr = Attr(0x0028, 0x1053, "RescaleSlope");
pub(super) const SHARED_GROUPS: Attr = Attr(0x5200, 0x9229, "SharedFunctionalGroupsSequence");
pub(super) const PER_FRAME_GROUPS: Attr = Attr(0x5200, 0x9230, "PerFrameFunctionalGroupsSequence");
pub(super) const PLANE_POSITION: Attr = Attr(0x0020, 0x9113, "PlanePositionSequence");
pub(super) const PLANE_ORIENTATION: Attr = Attr(0x0020, 0x9116, "PlaneOrientationSequence");
pub(super) const PIXEL_MEASURES: Attr = Attr(0x0028, 0x9110, "PixelMeasuresSequence");
pub(super) const VALUE_TRANSFORM: Attr = Attr(0x0028, 0x9145, "PixelValueTransformationSequence");
pub(super) const FLOAT_PIXEL_DATA: Attr = Attr(0x7FE0, 0x0008, "FloatPixelData");
pub(super) const DOUBLE_PIXEL_DATA: Attr = Attr(0x7FE0, 0x0009, "DoubleFloatPixelData");
pub(super) const PIXEL_DATA: Attr = Attr(0x7FE0, 0x0010, "PixelData");
pub(super) const GRID_FRAME_OFFSETS: Attr = Attr(0x3004, 0x000C, "GridFrameOffsetVector");
pub(super) const DOSE_GRID_SCALING: Attr = Attr(0x3004, 0x000E, "DoseGridScaling");
pub(super) const DOSE_UNITS: Attr = Attr(0x3004, 0x0002, "DoseUnits");
/// Red, green, blue palette descriptors (PS3.3 §C.7.6.3.1.5).
pub(super) const PALETTE_DESCRIPTORS: [Attr; 3] = [
    Attr(0x0028, 0x1101, "RedPaletteColorLookupTableDescriptor"),
    Attr(0x0028, 0x1102, "GreenPaletteColorLookupTableDescriptor"),
    Attr(0x0028, 0x1103, "BluePaletteColorLookupTableDescriptor"),
];
/// Red, green, blue palette data (PS3.3 §C.7.6.3.1.6).
pub(super) const PALETTE_DATA: [Attr; 3] = [
    Attr(0x0028, 0x1201, "RedPaletteColorLookupTableData"),
    Attr(0x0028, 0x1202, "GreenPaletteColorLookupTableData"),
    Attr(0x0028, 0x1203, "BluePaletteColorLookupTableData"),
];

/// The geometry and value transform of one frame, as found (validated later).
#[derive(Debug, Clone, PartialEq)]
pub(super) struct FrameGeom {
    pub(super) ipp: Option<[f64; 3]>,
    pub(super) iop: Option<[f64; 6]>,
    /// PixelSpacing as stored: [between rows, between columns].
    pub(super) pixel_spacing: Option<[f64; 2]>,
    /// RescaleSlope (times DoseGridScaling for RT Dose).
    pub(super) slope: f64,
    pub(super) intercept: f64,
}

/// What a scan keeps of one image file.
#[derive(Debug, Clone)]
pub(super) struct FileHeader {
    pub(super) path: PathBuf,
    /// SeriesInstanceUID; empty when the file has none (then it is read only when given alone).
    pub(super) series_uid: String,
    /// SOPInstanceUID; empty when absent. Copies of one instance in a folder are read once.
    pub(super) sop_uid: String,
    pub(super) series_number: Option<i64>,
    pub(super) description: String,
    pub(super) modality: String,
    pub(super) ts_uid: String,
    pub(super) ts_name: String,
    pub(super) rows: u16,
    pub(super) cols: u16,
    pub(super) samples: Option<u16>,
    pub(super) photometric: String,
    pub(super) bits_allocated: Option<u16>,
    pub(super) bits_stored: Option<u16>,
    pub(super) high_bit: Option<u16>,
    pub(super) pixel_representation: Option<u16>,
    pub(super) float_pixels: bool,
    pub(super) frames: u32,
    /// One entry per frame.
    pub(super) geom: Vec<FrameGeom>,
    pub(super) thickness: Option<f64>,
    pub(super) spacing_between: Option<f64>,
    pub(super) tilt: Option<f64>,
    /// PALETTE COLOR: whether the palette is grey (red = green = blue); `None` otherwise.
    pub(super) grey_palette: Option<bool>,
    /// Notes about this file (read as written, attributes repaired), for the series' notes.
    pub(super) notes: Vec<String>,
}

/// What reading a file's header found.
pub(super) enum Header {
    Image(Box<FileHeader>),
    /// A file of a known series that cannot be read.
    Broken(Box<BrokenFile>),
    NotImage,
    NotDicom,
}

/// A file of a known series that cannot be read: reading that series fails with its error
/// (unless a good file holds the same instance), reading another series skips it with a note.
#[derive(Debug)]
pub(super) struct BrokenFile {
    /// SeriesInstanceUID, empty if none.
    pub(super) series: String,
    /// SOPInstanceUID, empty if none.
    pub(super) sop: String,
    pub(super) path: PathBuf,
    pub(super) error: IoError,
}

/// The most bytes of one DICOM file read into memory.
pub(super) fn file_cap(limits: &Limits) -> u64 {
    let px = limits.voxel_limit().saturating_mul(4);
    u64::try_from(px)
        .unwrap_or(u64::MAX)
        .saturating_add(OTHER_BYTES)
}

/// A file's bytes from its `DICM` magic on.
pub(super) struct Loaded {
    pub(super) bytes: Vec<u8>,
    /// Whether the whole file was read (not a prefix).
    pub(super) whole: bool,
    /// Where `DICM` starts in the file (128, or 0 without a preamble).
    pub(super) offset: u64,
    /// The file's length in bytes.
    pub(super) file_len: u64,
}

/// Reads `path` from its `DICM` magic on: the first `prefix` bytes, or all of it. `None` when
/// the file does not start like a DICOM file.
pub(super) fn load(path: &Path, limits: &Limits, prefix: Option<u64>) -> Result<Option<Loaded>> {
    crate::limits::require_regular_file(path, "DICOM file")?;
    let f = std::fs::File::open(path).map_err(|e| IoError::os(path, "open", e))?;
    let len = f
        .metadata()
        .map_err(|e| IoError::os(path, "stat", e))?
        .len();
    let cap = file_cap(limits);
    let want = match prefix {
        Some(p) if p < len => p,
        _ => {
            if len > cap {
                return Err(IoError::TooLarge {
                    path: path.to_path_buf(),
                    what: "DICOM file size in bytes (4 bytes per voxel of the voxel limit + 64 \
                           MiB)"
                        .into(),
                    value: len as u128,
                    limit: cap as u128,
                });
            }
            len
        }
    };
    let mut bytes = Vec::new();
    f.take(want)
        .read_to_end(&mut bytes)
        .map_err(|e| IoError::os(path, "read", e))?;
    let Some(off) = dicm_offset(&bytes) else {
        return Ok(None);
    };
    let whole = (bytes.len() as u64) >= len;
    bytes.drain(..off);
    Ok(Some(Loaded {
        bytes,
        whole,
        offset: off as u64,
        file_len: len,
    }))
}

/// An error's message with its sources (dicom-rs errors keep the cause in `source()`).
fn chain(e: &dyn std::error::Error) -> String {
    let mut s = e.to_string();
    let mut cur = e.source();
    let mut n = 0;
    while let Some(c) = cur {
        let t = c.to_string();
        if !s.contains(&t) {
            s.push_str(": ");
            s.push_str(&t);
        }
        cur = c.source();
        n += 1;
        if n > 8 {
            break;
        }
    }
    s
}

pub(super) type DicomFile = dicom_object::FileDicomObject<InMemDicomObject>;

/// The registry, except that one UID (a little-endian syntax the meta group declares) stands
/// for the VR encoding the data set is really written in (pydicom reads such files as written).
struct AsWritten {
    declared: String,
    written: &'static TransferSyntax,
}

impl TransferSyntaxIndex for AsWritten {
    fn get(&self, uid: &str) -> Option<&TransferSyntax> {
        if uid.trim_end_matches(|c: char| c.is_whitespace() || c == '\0') == self.declared {
            Some(self.written)
        } else {
            TransferSyntaxRegistry.get(uid)
        }
    }
}

/// Checks and parses DICOM bytes (from `DICM` on).
pub(super) fn parse(
    path: &Path,
    loaded: &Loaded,
    header_only: bool,
    limits: &Limits,
) -> Result<(DicomFile, walk::Walked)> {
    let walked = walk_loaded(path, loaded, header_only, limits)?;
    let obj = parse_walked(path, loaded, &walked, header_only)?;
    Ok((obj, walked))
}

/// The structure walk of a loaded file (`walk.rs`).
fn walk_loaded(
    path: &Path,
    loaded: &Loaded,
    header_only: bool,
    limits: &Limits,
) -> Result<walk::Walked> {
    walk::walk(
        path,
        &loaded.bytes,
        loaded.offset,
        header_only,
        file_cap(limits),
        OTHER_BYTES,
    )
}

/// Parses a walked file with dicom-object (up to Pixel Data for a header), reading the data
/// set in the VR encoding it is written in.
fn parse_walked(
    path: &Path,
    loaded: &Loaded,
    walked: &walk::Walked,
    header_only: bool,
) -> Result<DicomFile> {
    let bytes = &loaded.bytes[..];
    let mut opts = OpenFileOptions::new().read_preamble(ReadPreamble::Never);
    if header_only {
        opts = opts.read_until(dicom_dictionary_std::tags::PIXEL_DATA);
    }
    let written = match &walked.vr_mismatch {
        Some(declared) => TransferSyntaxRegistry
            .get(&walked.ts_uid)
            .map(|written| AsWritten {
                declared: declared.clone(),
                written,
            }),
        _ => None,
    };
    match written {
        Some(index) => opts.transfer_syntax_index(index).from_reader(bytes),
        None => opts.from_reader(bytes),
    }
    .map_err(|e| IoError::Dicom {
        path: path.to_path_buf(),
        message: chain(&e),
    })
}

/// Reads and parses a file's header (all but the pixel data). A DICOMDIR is told by its file
/// meta group alone: its records are never parsed (a DICOMDIR with a bad offset no longer stops
/// a folder scan).
pub(super) fn read_header(path: &Path, limits: &Limits) -> Result<Header> {
    let Some(first) = load(path, limits, Some(HEADER_PREFIX))? else {
        return Ok(Header::NotDicom);
    };
    let from = |loaded: &Loaded| -> Result<Header> {
        let walked = walk_loaded(path, loaded, true, limits)?;
        if walked.media_sop_class == walk::DICOMDIR_SOP_CLASS {
            return Ok(Header::NotImage);
        }
        let obj = parse_walked(path, loaded, &walked, true)?;
        Ok(header_of(path, &obj, &walked, loaded.file_len))
    };
    match from(&first) {
        Err(_) if !first.whole => {
            let Some(all) = load(path, limits, None)? else {
                return Ok(Header::NotDicom);
            };
            from(&all)
        }
        r => r,
    }
}

/// Reads attributes from one data set: the file (for messages) and the byte order of binary
/// values stored with VR UN.
#[derive(Clone, Copy)]
pub(super) struct Ctx<'a> {
    pub(super) path: &'a Path,
    pub(super) big_endian: bool,
}

/// VRs whose values are text (PS3.5 §6.2).
fn text_vr(vr: VR) -> bool {
    matches!(
        vr,
        VR::AE
            | VR::AS
            | VR::CS
            | VR::DA
            | VR::DS
            | VR::DT
            | VR::IS
            | VR::LO
            | VR::LT
            | VR::PN
            | VR::SH
            | VR::ST
            | VR::TM
            | VR::UC
            | VR::UI
            | VR::UR
            | VR::UT
    )
}

/// The value of an element stored with VR UN (explicit VR files that wrote a known attribute as
/// unknown, PS3.5 §6.2.2), decoded by its dictionary VR as pydicom does: text as text, binary
/// integers and floats in the data set's byte order, joined by `\`. `None` when the dictionary
/// does not know the tag or the VR is another.
fn un_text(tag: Tag, bytes: &[u8], be: bool) -> Option<String> {
    let vr = StandardDataDictionary.by_tag(tag)?.vr().relaxed();
    if text_vr(vr) {
        return Some(String::from_utf8_lossy(bytes).into_owned());
    }
    macro_rules! nums {
        ($t:ty, $n:expr) => {
            bytes
                .chunks_exact($n)
                .map(|c| {
                    let a: [u8; $n] = c.try_into().unwrap_or([0; $n]);
                    if be {
                        <$t>::from_be_bytes(a).to_string()
                    } else {
                        <$t>::from_le_bytes(a).to_string()
                    }
                })
                .collect::<Vec<_>>()
                .join("\\")
        };
    }
    Some(match vr {
        VR::US => nums!(u16, 2),
        VR::SS => nums!(i16, 2),
        VR::UL => nums!(u32, 4),
        VR::SL => nums!(i32, 4),
        VR::FL => nums!(f32, 4),
        VR::FD => nums!(f64, 8),
        _ => return None,
    })
}

pub(super) fn elem_text(cx: Ctx<'_>, obj: &InMemDicomObject, a: Attr) -> Option<String> {
    let e = obj.get(a.tag())?;
    let s = if e.vr() == VR::UN {
        let bytes = e.value().to_bytes().ok()?;
        un_text(a.tag(), &bytes, cx.big_endian)?
    } else {
        e.to_str().ok()?.into_owned()
    };
    let s = s.trim_matches(|c: char| c == '\0' || c.is_whitespace());
    Some(s.to_string())
}

fn text_or_empty(cx: Ctx<'_>, obj: &InMemDicomObject, a: Attr) -> String {
    elem_text(cx, obj, a).unwrap_or_default()
}

/// A multi-valued decimal attribute of `n` finite numbers (`None` for any number); `None` when
/// absent or empty.
pub(super) fn numbers(
    cx: Ctx<'_>,
    obj: &InMemDicomObject,
    a: Attr,
    n: Option<usize>,
) -> Result<Option<Vec<f64>>> {
    let Some(t) = elem_text(cx, obj, a) else {
        return Ok(None);
    };
    if t.is_empty() {
        return Ok(None);
    }
    let path = cx.path;
    let mut v = Vec::with_capacity(n.unwrap_or(1));
    for part in t.split('\\') {
        let x: f64 = part.trim().parse().map_err(|_| {
            IoError::field(path, a.label(), &t, format!("{:?} is not a number", part))
        })?;
        if !x.is_finite() {
            return Err(IoError::field(path, a.label(), &t, "values must be finite"));
        }
        v.push(x);
    }
    if let Some(n) = n
        && v.len() != n
    {
        return Err(IoError::field(
            path,
            a.label(),
            &t,
            format!("{n} values expected, found {}", v.len()),
        ));
    }
    Ok(Some(v))
}

fn number(cx: Ctx<'_>, obj: &InMemDicomObject, a: Attr) -> Result<Option<f64>> {
    Ok(numbers(cx, obj, a, Some(1))?.map(|v| v[0]))
}

fn integer(cx: Ctx<'_>, obj: &InMemDicomObject, a: Attr) -> Result<Option<i64>> {
    let Some(t) = elem_text(cx, obj, a) else {
        return Ok(None);
    };
    if t.is_empty() {
        return Ok(None);
    }
    t.parse::<i64>()
        .map(Some)
        .map_err(|_| IoError::field(cx.path, a.label(), &t, "not an integer"))
}

fn u16_attr(cx: Ctx<'_>, obj: &InMemDicomObject, a: Attr) -> Result<Option<u16>> {
    match integer(cx, obj, a)? {
        None => Ok(None),
        Some(v) => u16::try_from(v)
            .map(Some)
            .map_err(|_| IoError::field(cx.path, a.label(), &v.to_string(), "must be 0 to 65535")),
    }
}

/// The first item of sequence `a` in `obj`.
fn item(obj: &InMemDicomObject, a: Attr) -> Option<&InMemDicomObject> {
    obj.get(a.tag())?.items()?.first()
}

/// Geometry and value transform of a frame from functional-group items (PS3.3 §C.7.6.16):
/// per-frame item first, then shared, then the top level.
fn frame_geom(
    cx: Ctx<'_>,
    top: &InMemDicomObject,
    per: Option<&InMemDicomObject>,
    shared: Option<&InMemDicomObject>,
) -> Result<FrameGeom> {
    let lookup = |seq: Attr| -> Option<&InMemDicomObject> {
        per.and_then(|p| item(p, seq))
            .or_else(|| shared.and_then(|s| item(s, seq)))
    };
    let from = |seq: Attr, a: Attr, n: usize| -> Result<Option<Vec<f64>>> {
        if let Some(it) = lookup(seq)
            && let Some(v) = numbers(cx, it, a, Some(n))?
        {
            return Ok(Some(v));
        }
        numbers(cx, top, a, Some(n))
    };
    let ipp = from(PLANE_POSITION, IPP, 3)?.map(|v| [v[0], v[1], v[2]]);
    let iop = from(PLANE_ORIENTATION, IOP, 6)?.map(|v| [v[0], v[1], v[2], v[3], v[4], v[5]]);
    let ps = from(PIXEL_MEASURES, PIXEL_SPACING, 2)?.map(|v| [v[0], v[1]]);
    if let Some(p) = ps
        && !(p[0] > 0.0 && p[1] > 0.0)
    {
        return Err(IoError::field(
            cx.path,
            PIXEL_SPACING.label(),
            &format!("{}\\{}", p[0], p[1]),
            "spacings must be positive",
        ));
    }
    let slope = from(VALUE_TRANSFORM, SLOPE, 1)?.map_or(1.0, |v| v[0]);
    let intercept = from(VALUE_TRANSFORM, INTERCEPT, 1)?.map_or(0.0, |v| v[0]);
    Ok(FrameGeom {
        ipp,
        iop,
        pixel_spacing: ps,
        slope,
        intercept,
    })
}

/// Frames of a classic multi-frame image placed by GridFrameOffsetVector (PS3.3 §C.8.8.3.2, RT
/// Dose): frame k lies at ImagePositionPatient + offset_k along the normal when the first
/// offset is 0 (relative offsets); otherwise the offsets are the frames' z coordinates, which
/// the standard allows only for axial frames (ImageOrientationPatient 1\0\0\0\1\0).
fn grid_frames(cx: Ctx<'_>, g: &FrameGeom, offsets: &[f64]) -> Result<Vec<FrameGeom>> {
    let bad = |why: &str| {
        IoError::field(
            cx.path,
            GRID_FRAME_OFFSETS.label(),
            &format!("{} values", offsets.len()),
            why,
        )
    };
    let (Some(ipp), Some(iop)) = (g.ipp, g.iop) else {
        return Err(bad(
            "needs ImagePositionPatient and ImageOrientationPatient to place the frames",
        ));
    };
    let r = DVec3::new(iop[0], iop[1], iop[2]);
    let c = DVec3::new(iop[3], iop[4], iop[5]);
    let n = r.cross(c);
    let p0 = DVec3::from(ipp);
    let relative = offsets.first() == Some(&0.0);
    let axial = (n - DVec3::Z).length() < 1e-6;
    if !relative && !axial {
        return Err(bad(
            "absolute offsets (first offset not 0) are defined for axial frames only \
             (ImageOrientationPatient 1\\0\\0\\0\\1\\0; PS3.3 C.8.8.3.2)",
        ));
    }
    Ok(offsets
        .iter()
        .map(|&o| {
            let p = if relative {
                p0 + o * n
            } else {
                DVec3::new(p0.x, p0.y, o)
            };
            FrameGeom {
                ipp: Some(p.to_array()),
                ..g.clone()
            }
        })
        .collect())
}

/// The header of an image file; [`Header::Broken`] (UIDs empty where unknown) for one that
/// cannot be read.
fn header_of(path: &Path, obj: &DicomFile, walked: &walk::Walked, file_len: u64) -> Header {
    let top: &InMemDicomObject = obj;
    let cx = Ctx {
        path,
        big_endian: walked.ts_uid == "1.2.840.10008.1.2.2",
    };
    let series = text_or_empty(cx, top, SERIES_UID);
    let sop = text_or_empty(cx, top, SOP_INSTANCE);
    let broken = |error: IoError| {
        Header::Broken(Box::new(BrokenFile {
            series: series.clone(),
            sop: sop.clone(),
            path: path.to_path_buf(),
            error,
        }))
    };
    let class = elem_text(cx, top, SOP_CLASS).unwrap_or_else(|| walked.media_sop_class.clone());
    // DICOMDIR (Media Storage Directory Storage) and other objects without an image.
    if class == walk::DICOMDIR_SOP_CLASS || walked.media_sop_class == walk::DICOMDIR_SOP_CLASS {
        return Header::NotImage;
    }
    let (rows, cols) = match (u16_attr(cx, top, ROWS), u16_attr(cx, top, COLUMNS)) {
        (Ok(Some(r)), Ok(Some(c))) => (r, c),
        (Err(e), _) | (_, Err(e)) => return broken(e),
        _ => return Header::NotImage,
    };
    let mut h = match image_header(cx, top, walked, rows, cols) {
        Ok(h) => h,
        Err(e) => return broken(e),
    };
    h.series_uid = series.clone();
    if let Err(e) = check_pixel_length(&h, walked, file_len) {
        return broken(e);
    }
    if let Some(declared) = &walked.vr_mismatch {
        h.notes.push(format!(
            "the data set is written in {} but the meta group declares {declared}; read as \
             written",
            walked.ts_name
        ));
    }
    Header::Image(Box::new(h))
}

pub(super) fn file_name(path: &Path) -> String {
    path.file_name().map_or_else(
        || path.display().to_string(),
        |n| n.to_string_lossy().into(),
    )
}

/// The image attributes of a file with Rows and Columns.
fn image_header(
    cx: Ctx<'_>,
    top: &InMemDicomObject,
    walked: &walk::Walked,
    rows: u16,
    cols: u16,
) -> Result<FileHeader> {
    let path = cx.path;
    if rows == 0 || cols == 0 {
        return Err(IoError::field(
            path,
            "Rows/Columns (0028,0010/0011)",
            &format!("{rows}/{cols}"),
            "must be at least 1",
        ));
    }
    let frames = match integer(cx, top, FRAMES)? {
        None => 1,
        Some(n) if (1..=i64::from(u32::MAX)).contains(&n) => n as u32,
        Some(n) => {
            return Err(IoError::field(
                path,
                FRAMES.label(),
                &n.to_string(),
                "must be at least 1",
            ));
        }
    };
    let photometric = text_or_empty(cx, top, PHOTOMETRIC);
    let grey_palette = if photometric == "PALETTE COLOR" {
        Some(palette_is_grey(cx, top))
    } else {
        None
    };
    let samples = u16_attr(cx, top, SAMPLES)?;
    // Colour first: it is the reason such a file is refused, whatever else it holds.
    colour_check(path, samples, &photometric, grey_palette)?;
    let mut notes = Vec::new();
    let geom = frames_geometry(cx, top, frames, &mut notes)?;
    let mut h = FileHeader {
        path: path.to_path_buf(),
        series_uid: String::new(),
        sop_uid: text_or_empty(cx, top, SOP_INSTANCE),
        series_number: integer(cx, top, SERIES_NUMBER).ok().flatten(),
        description: text_or_empty(cx, top, SERIES_DESCRIPTION),
        modality: text_or_empty(cx, top, MODALITY),
        ts_uid: walked.ts_uid.clone(),
        ts_name: walked.ts_name.clone(),
        rows,
        cols,
        samples,
        photometric,
        bits_allocated: u16_attr(cx, top, BITS_ALLOCATED)?,
        bits_stored: u16_attr(cx, top, BITS_STORED)?,
        high_bit: u16_attr(cx, top, HIGH_BIT)?,
        pixel_representation: u16_attr(cx, top, PIXEL_REPRESENTATION)?,
        float_pixels: top.get(FLOAT_PIXEL_DATA.tag()).is_some()
            || top.get(DOUBLE_PIXEL_DATA.tag()).is_some(),
        frames,
        geom,
        thickness: number(cx, top, SLICE_THICKNESS).ok().flatten(),
        spacing_between: number(cx, top, SPACING_BETWEEN).ok().flatten(),
        tilt: number(cx, top, GANTRY_TILT).ok().flatten(),
        grey_palette,
        notes,
    };
    apply_dose_scaling(cx, top, &mut h)?;
    Ok(h)
}

/// One geometry per frame: per-frame functional groups, GridFrameOffsetVector, or the top
/// level for a single frame. A multi-frame image without per-frame positions is refused here,
/// when it is scanned (issue 28: 700 files declaring 65536 frames each no longer fill memory).
fn frames_geometry(
    cx: Ctx<'_>,
    top: &InMemDicomObject,
    frames: u32,
    notes: &mut Vec<String>,
) -> Result<Vec<FrameGeom>> {
    let shared = item(top, SHARED_GROUPS);
    if let Some(items) = top.get(PER_FRAME_GROUPS.tag()).and_then(|e| e.items()) {
        if items.len() < frames as usize {
            return Err(IoError::field(
                cx.path,
                PER_FRAME_GROUPS.label(),
                &format!("{} items", items.len()),
                format!("one item per frame expected ({frames} frames)"),
            ));
        }
        if items.len() > frames as usize {
            notes.push(format!(
                "{}: {} has {} items for {frames} frame(s); the first {frames} used",
                file_name(cx.path),
                PER_FRAME_GROUPS.label(),
                items.len()
            ));
        }
        return items[..frames as usize]
            .iter()
            .map(|it| frame_geom(cx, top, Some(it), shared))
            .collect();
    }
    let g = frame_geom(cx, top, None, shared)?;
    if frames == 1 {
        return Ok(vec![g]);
    }
    if let Some(offsets) = numbers(cx, top, GRID_FRAME_OFFSETS, None)? {
        if offsets.len() != frames as usize {
            return Err(IoError::field(
                cx.path,
                GRID_FRAME_OFFSETS.label(),
                &format!("{} values", offsets.len()),
                format!("one offset per frame expected ({frames} frames)"),
            ));
        }
        notes.push(format!(
            "{}: {frames} frames placed by {}",
            file_name(cx.path),
            GRID_FRAME_OFFSETS.label()
        ));
        return grid_frames(cx, &g, &offsets);
    }
    Err(IoError::unsupported(
        cx.path,
        FRAMES.label(),
        &frames.to_string(),
        "1, or several frames with their positions (PerFrameFunctionalGroupsSequence, PS3.3 \
         §C.7.6.16, or GridFrameOffsetVector, §C.8.8.3.2); cine and other multi-frame images \
         without per-frame positions are not volumes",
    ))
}

/// RT Dose (PS3.3 §C.8.8.3): DoseGridScaling multiplies the stored values into dose units; it
/// is folded into each frame's slope.
fn apply_dose_scaling(cx: Ctx<'_>, top: &InMemDicomObject, h: &mut FileHeader) -> Result<()> {
    let Some(s) = number(cx, top, DOSE_GRID_SCALING)? else {
        return Ok(());
    };
    if s.is_nan() || s <= 0.0 {
        return Err(IoError::field(
            cx.path,
            DOSE_GRID_SCALING.label(),
            &s.to_string(),
            "must be positive",
        ));
    }
    for g in &mut h.geom {
        g.slope *= s;
    }
    let units = text_or_empty(cx, top, DOSE_UNITS);
    h.notes.push(format!(
        "{} {s} applied: values in {}",
        DOSE_GRID_SCALING.label(),
        if units.is_empty() {
            "the dose units".into()
        } else {
            units
        }
    ));
    Ok(())
}

/// Whether the red, green and blue palettes are one table (a grey palette). Malformed palettes
/// count as colour here; decoding reports what is wrong with them.
fn palette_is_grey(cx: Ctx<'_>, top: &InMemDicomObject) -> bool {
    let table = |k: usize| {
        let d = elem_text(cx, top, PALETTE_DESCRIPTORS[k])?;
        let data = top.get(PALETTE_DATA[k].tag())?.value().to_bytes().ok()?;
        Some((d, data.into_owned()))
    };
    match (table(0), table(1), table(2)) {
        (Some(r), Some(g), Some(b)) => r == g && g == b,
        _ => false,
    }
}

/// Refuses pixel data shorter than the image it must hold, from the header alone (issue 28:
/// Rows × Columns 65535² with a few bytes of pixel data no longer allocates 17 GB): native data
/// must hold every frame; encapsulated data needs at least one 8-byte item per frame.
fn check_pixel_length(h: &FileHeader, walked: &walk::Walked, file_len: u64) -> Result<()> {
    if h.float_pixels {
        return Ok(());
    }
    let Some((len, start)) = walked.pixel else {
        return Err(IoError::missing(&h.path, PIXEL_DATA.label()));
    };
    let bits = u64::from(h.bits_allocated.unwrap_or(16)).max(1);
    let samples = u64::from(h.rows) * u64::from(h.cols) * u64::from(h.samples.unwrap_or(1).max(1));
    let frames = u64::from(h.frames);
    if len == walk::UNDEFINED {
        if walked.deflated {
            return Ok(());
        }
        let room = file_len.saturating_sub(start);
        if frames.saturating_mul(8) > room {
            return Err(IoError::field(
                &h.path,
                FRAMES.label(),
                &h.frames.to_string(),
                format!(
                    "the encapsulated pixel data has {room} bytes, too few for one fragment \
                     per frame"
                ),
            ));
        }
        return Ok(());
    }
    // Bits Allocated 1: frames packed one after another, not byte-aligned (PS3.5 §8.1.1).
    let needed = frames
        .saturating_mul(samples)
        .saturating_mul(bits)
        .div_ceil(8);
    let have = if walked.deflated {
        u64::from(len)
    } else {
        u64::from(len).min(file_len.saturating_sub(start))
    };
    if have < needed {
        return Err(IoError::Truncated {
            path: h.path.clone(),
            what: format!(
                "{} of {} frame(s) of Columns {} × Rows {} × {} sample(s) of {bits} bits",
                PIXEL_DATA.label(),
                h.frames,
                h.cols,
                h.rows,
                h.samples.unwrap_or(1).max(1)
            ),
            expected: needed,
            actual: have,
            unit: "bytes",
        });
    }
    Ok(())
}

/// Refuses colour images (PS3.3 §C.7.6.3.1.2): more than one sample per pixel, a colour
/// palette, or a photometric interpretation other than MONOCHROME1/2 and grey PALETTE COLOR.
fn colour_check(
    p: &Path,
    samples: Option<u16>,
    pi: &str,
    grey_palette: Option<bool>,
) -> Result<()> {
    let spp = samples.unwrap_or(1);
    if spp != 1 {
        return Err(IoError::unsupported(
            p,
            SAMPLES.label(),
            &format!("{spp} ({pi}: a colour image)"),
            "1 (grey-scale; volsplat reads scalar volumes)",
        ));
    }
    match (pi, grey_palette) {
        ("" | "MONOCHROME1" | "MONOCHROME2", _) | ("PALETTE COLOR", Some(true)) => Ok(()),
        ("PALETTE COLOR", _) => Err(IoError::unsupported(
            p,
            PHOTOMETRIC.label(),
            "PALETTE COLOR with a colour palette (red, green and blue tables differ): a colour \
             image",
            "MONOCHROME1, MONOCHROME2, PALETTE COLOR with a grey palette",
        )),
        _ => Err(IoError::unsupported(
            p,
            PHOTOMETRIC.label(),
            pi,
            "MONOCHROME1, MONOCHROME2, PALETTE COLOR with a grey palette",
        )),
    }
}

impl FileHeader {
    /// The validated pixel layout (PS3.3 §C.7.6.3.1).
    pub(super) fn pixel_format(&self) -> Result<PixelFormat> {
        let p = &self.path;
        if self.float_pixels {
            return Err(IoError::unsupported(
                p,
                FLOAT_PIXEL_DATA.label(),
                "present",
                "integer PixelData (7FE0,0010)",
            ));
        }
        colour_check(p, self.samples, &self.photometric, self.grey_palette)?;
        let palette = self.photometric == "PALETTE COLOR";
        let ba = self
            .bits_allocated
            .ok_or_else(|| IoError::missing(p, BITS_ALLOCATED.label()))?;
        if !matches!(ba, 1 | 8 | 16 | 32) {
            return Err(IoError::unsupported(
                p,
                BITS_ALLOCATED.label(),
                &ba.to_string(),
                "1 (native transfer syntaxes), 8, 16, 32",
            ));
        }
        let bs = self.bits_stored.unwrap_or(ba);
        if bs == 0 || bs > ba {
            return Err(IoError::field(
                p,
                BITS_STORED.label(),
                &bs.to_string(),
                format!("must be 1 to BitsAllocated ({ba})"),
            ));
        }
        let hb = self.high_bit.unwrap_or(bs - 1);
        if hb + 1 < bs || hb >= ba {
            return Err(IoError::field(
                p,
                HIGH_BIT.label(),
                &hb.to_string(),
                format!(
                    "must be BitsStored − 1 ({}) to BitsAllocated − 1 ({})",
                    bs - 1,
                    ba - 1
                ),
            ));
        }
        let signed = match self.pixel_representation.unwrap_or(0) {
            0 => false,
            1 => true,
            v => {
                return Err(IoError::field(
                    p,
                    PIXEL_REPRESENTATION.label(),
                    &v.to_string(),
                    "must be 0 (unsigned) or 1 (two's complement)",
                ));
            }
        };
        Ok(PixelFormat {
            rows: self.rows,
            cols: self.cols,
            bits_allocated: ba,
            bits_stored: bs,
            high_bit: hb,
            signed,
            palette,
        })
    }

    pub(super) fn coding(&self, encapsulated: bool) -> Result<PixelCoding> {
        let big = self.ts_uid == "1.2.840.10008.1.2.2";
        PixelCoding::of(&self.ts_uid, big, encapsulated).ok_or_else(|| {
            IoError::unsupported(
                &self.path,
                "TransferSyntaxUID (0002,0010)",
                &format!("{} ({})", self.ts_uid, self.ts_name),
                pixels::SUPPORTED_SYNTAXES,
            )
        })
    }
}
