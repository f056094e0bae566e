//! TIFF stacks: one multi-page `.tif` / `.tiff` file, each page one slice (read with the `tiff`
//! crate; uncompressed, LZW, deflate and PackBits).
//!
//! # What is read
//!
//! - Every page (image file directory) in order: page `k` is slice `k`; within a page column `x`
//!   is grid index `i` and row `y` (row 0 first, as stored) is `j`. Direction identity, origin 0
//!   (as ITK; TIFF has no world frame, and no conversion is applied).
//! - Grayscale pages of one sample: 8/16/32/64-bit unsigned or signed integers, 16/32/64-bit
//!   floats. 8- and 16-bit integers and 32-bit floats are read as they are; 32- and 64-bit
//!   integers (NumPy's default `int64`, as `tifffile` writes it) and 16/64-bit floats are
//!   converted to f32 with a note (integers above 2²⁴ in magnitude are rounded). All pages
//!   must share the size and type of the first. RGB, palette, bilevel and multi-sample pages are
//!   rejected.
//! - ImageJ hyperstacks (`frames=` > 1 in the description): the pages of frame
//!   `ReadOptions::frame` are read (default 0) and the frame count is reported; several
//!   `channels=` are an error.
//! - Spacing (world units per voxel): from ImageJ's `ImageDescription` (`ImageJ=…` lines:
//!   `spacing=` for z, `unit=`) with `XResolution`/`YResolution` (pixels per unit) for x and y;
//!   else from OME-XML (`PhysicalSizeX/Y/Z`); else 1 with a note. The unit is reported in a
//!   note and not converted. A spacing that is not a positive finite number is never used:
//!   a negative ImageJ `spacing=` becomes its magnitude (ImageJ's own rule), any other bad value
//!   (0, NaN, infinite, a resolution of 0) becomes 1, each with a note naming the tag or key and
//!   the value.
//!
//! # Limits
//!
//! The total voxel count (pages × width × height) is checked against [`crate::Limits`] before
//! each page is decoded; the `tiff` crate's own limits bound each page's buffers.

use crate::error::{IoError, Result};
use crate::limits::checked_voxel_count;
use crate::{LoadedVolume, ReadOptions};
use std::io::BufReader;
use std::path::Path;
use tiff::decoder::{Decoder, DecodingResult};
use tiff::tags::Tag;
use volsplat_core::glam::DMat3;
use volsplat_core::{AnyVolume, Grid, Volume};

/// Reads a multi-page TIFF with default limits. See the [module documentation](self).
pub fn read_tiff(path: impl AsRef<Path>) -> Result<AnyVolume> {
    read_tiff_with(path, &ReadOptions::default()).map(|l| l.volume)
}

/// Reads a multi-page TIFF with caller-set limits; notes say where the spacing came from.
pub fn read_tiff_with(path: impl AsRef<Path>, options: &ReadOptions) -> Result<LoadedVolume> {
    let path = path.as_ref();
    options.refuse_series(path)?;
    options.refuse_array(path, "TIFF")?;
    crate::confine::Confinement::of(path, &options.limits)?;
    let mut stack = Stack::default();
    read_pages(path, &mut stack, options, false)?;
    stack.finish(path, Vec::new())
}

/// Reads a folder of single-page TIFF slices (`.tif` / `.tiff`, any case), slice `k` being the
/// `k`-th file in natural order (`s2.tif` before `s10.tif`; names compared by runs of digits as
/// numbers, the rest as text). Other files are ignored; every slice must be one page of the
/// first slice's size and type. Spacing comes from the first slice's metadata as for
/// [`read_tiff`].
pub fn read_tiff_dir(dir: impl AsRef<Path>, options: &ReadOptions) -> Result<LoadedVolume> {
    let dir = dir.as_ref();
    options.refuse_series(dir)?;
    options.refuse_multiscale(dir, "TIFF")?;
    if options.array.is_some() || options.frame != 0 {
        return Err(IoError::invalid_argument(
            dir,
            "array/frame",
            "a folder of TIFF slices has one volume and no named arrays",
        ));
    }
    let files = tiff_files(dir)?;
    if let Some(c) = crate::confine::Confinement::of(dir, &options.limits)? {
        // A slice left out would be a wrong volume: a slice that leads out is an error.
        for f in &files {
            let name = f.file_name().unwrap_or_default().to_string_lossy();
            c.check(dir, "slice", &name, f)?;
        }
    }
    if files.is_empty() {
        return Err(IoError::missing(dir, "a .tif or .tiff file in the folder"));
    }
    let mut stack = Stack::default();
    for f in &files {
        read_pages(f, &mut stack, options, true)?;
    }
    let notes = vec![format!(
        "{} slices from the folder's .tif/.tiff files in natural order ({} … {})",
        files.len(),
        files[0].file_name().unwrap_or_default().to_string_lossy(),
        files[files.len() - 1]
            .file_name()
            .unwrap_or_default()
            .to_string_lossy()
    )];
    stack.finish(dir, notes)
}

/// The `.tif` / `.tiff` files of `dir`, naturally sorted.
pub(crate) fn tiff_files(dir: &Path) -> Result<Vec<std::path::PathBuf>> {
    let mut files: Vec<std::path::PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| IoError::os(dir, "list folder", e))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            let n = p
                .file_name()
                .map(|n| n.to_string_lossy().to_ascii_lowercase())
                .unwrap_or_default();
            !n.starts_with('.') && (n.ends_with(".tif") || n.ends_with(".tiff")) && p.is_file()
        })
        .collect();
    files.sort_by(|a, b| {
        natural_cmp(
            &a.file_name().unwrap_or_default().to_string_lossy(),
            &b.file_name().unwrap_or_default().to_string_lossy(),
        )
    });
    Ok(files)
}

/// Natural order: runs of ASCII digits compare as numbers (then by length, so `01` after `1`),
/// everything else character by character.
pub(crate) fn natural_cmp(a: &str, b: &str) -> std::cmp::Ordering {
    use std::cmp::Ordering;
    let (a, b) = (a.as_bytes(), b.as_bytes());
    let (mut i, mut j) = (0, 0);
    while i < a.len() && j < b.len() {
        if a[i].is_ascii_digit() && b[j].is_ascii_digit() {
            let (si, sj) = (i, j);
            while i < a.len() && a[i].is_ascii_digit() {
                i += 1;
            }
            while j < b.len() && b[j].is_ascii_digit() {
                j += 1;
            }
            let (x, y) = (&a[si..i], &b[sj..j]);
            let (xs, ys) = (strip_zeros(x), strip_zeros(y));
            let o = xs
                .len()
                .cmp(&ys.len())
                .then(xs.cmp(ys))
                .then(x.len().cmp(&y.len()));
            if o != Ordering::Equal {
                return o;
            }
        } else {
            let o = a[i].cmp(&b[j]);
            if o != Ordering::Equal {
                return o;
            }
            i += 1;
            j += 1;
        }
    }
    (a.len() - i).cmp(&(b.len() - j))
}

/// A run of digits without its leading zeros.
fn strip_zeros(d: &[u8]) -> &[u8] {
    let p = d.iter().position(|&c| c != b'0').unwrap_or(d.len());
    &d[p..]
}

/// Slices gathered so far, and the first slice's size and metadata.
#[derive(Default)]
struct Stack {
    size: Option<(u32, u32)>,
    description: Option<String>,
    xres: Option<f64>,
    yres: Option<f64>,
    acc: Option<Acc>,
    slices: u64,
    /// ImageJ hyperstacks: the number of frames (time points) and the pages kept
    /// (`[start, end)`) for the chosen frame.
    frames: u64,
    frame: u64,
    keep: Option<(u64, u64)>,
}

impl Stack {
    fn finish(self, path: &Path, mut notes: Vec<String>) -> Result<LoadedVolume> {
        let (Some(acc), Some((w, h))) = (self.acc, self.size) else {
            return Err(IoError::missing(path, "page"));
        };
        let dims = [w as usize, h as usize, self.slices as usize];
        let spacing = spacing(
            self.description.as_deref(),
            self.xres,
            self.yres,
            &mut notes,
        );
        let grid = Grid::new(dims, spacing, [0.0; 3], DMat3::IDENTITY)
            .map_err(|e| IoError::core(path, e))?;
        if let Acc::F32(_, kind, true) = &acc {
            let precision = if matches!(*kind, "int32" | "uint32" | "int64" | "uint64") {
                " (integers above 2^24 in magnitude are rounded)"
            } else {
                ""
            };
            notes.push(format!(
                "samples of type {kind} converted to float32{precision}"
            ));
        }
        let volume = acc.into_volume(grid).map_err(|e| IoError::core(path, e))?;
        Ok(LoadedVolume {
            volume,
            format: "TIFF".into(),
            frames: self.frames.max(1) as usize,
            frame: self.frame as usize,
            arrays: Vec::new(),
            series: Vec::new(),
            series_uid: None,
            notes,
        })
    }
}

/// Appends the pages of `path` to `stack` (only one page allowed when `single_page`).
fn read_pages(
    path: &Path,
    stack: &mut Stack,
    options: &ReadOptions,
    single_page: bool,
) -> Result<()> {
    crate::limits::require_regular_file(path, "TIFF file")?;
    let file = std::fs::File::open(path).map_err(|e| IoError::os(path, "open", e))?;
    let terr = |what: &str, e: tiff::TiffError| IoError::Field {
        path: path.to_path_buf(),
        field: what.to_string(),
        value: String::new(),
        reason: format!("TIFF decoding failed: {e}"),
    };
    let mut dec = Decoder::new(BufReader::new(file)).map_err(|e| terr("header", e))?;
    if stack.size.is_none() {
        let size = dec
            .dimensions()
            .map_err(|e| terr("page 0 ImageWidth/ImageLength", e))?;
        stack.size = Some(size);
        stack.description = dec
            .find_tag(Tag::ImageDescription)
            .ok()
            .flatten()
            .and_then(|v| v.into_string().ok());
        stack.xres = rational(&mut dec, Tag::XResolution);
        stack.yres = rational(&mut dec, Tag::YResolution);
        choose_frame(path, stack, options, single_page)?;
    }
    let Some((w, h)) = stack.size else {
        return Err(IoError::missing(path, "page"));
    };
    let mut page = 0u64;
    loop {
        if let Some((start, end)) = stack.keep {
            if page >= end {
                return Ok(());
            }
            if page < start {
                page += 1;
                if !dec.more_images() {
                    break;
                }
                dec.next_image()
                    .map_err(|e| terr(&format!("page {page} directory"), e))?;
                continue;
            }
        }
        let (pw, ph) = dec
            .dimensions()
            .map_err(|e| terr(&format!("page {page} ImageWidth/ImageLength"), e))?;
        if (pw, ph) != (w, h) {
            return Err(IoError::field(
                path,
                format!("page {page} size"),
                &format!("{pw}×{ph}"),
                format!("all slices must be {w}×{h} like the first"),
            ));
        }
        let value = format!("{w}×{h}×{} slices", stack.slices + 1);
        checked_voxel_count(
            path,
            "ImageWidth × ImageLength × slices",
            &value,
            &[w as u64, h as u64, stack.slices + 1],
            &options.limits,
        )?;
        let ct = dec
            .colortype()
            .map_err(|e| terr(&format!("page {page} colour type"), e))?;
        if !matches!(ct, tiff::ColorType::Gray(8 | 16 | 32 | 64)) {
            return Err(IoError::unsupported(
                path,
                format!("page {page} colour type"),
                &format!("{ct:?}"),
                "one grayscale sample of 8, 16, 32 or 64 bits",
            ));
        }
        let img = dec
            .read_image()
            .map_err(|e| terr(&format!("page {page} samples"), e))?;
        let a = stack.acc.get_or_insert_with(|| Acc::for_result(&img));
        a.push(img).map_err(|(want, got)| {
            IoError::field(
                path,
                format!("page {page} sample type"),
                got,
                format!("all slices must have the sample type of the first ({want})"),
            )
        })?;
        stack.slices += 1;
        page += 1;
        if !dec.more_images() {
            break;
        }
        if single_page {
            return Err(IoError::unsupported(
                path,
                "pages",
                "more than 1",
                "one page per file in a folder of slices",
            ));
        }
        dec.next_image()
            .map_err(|e| terr(&format!("page {page} directory"), e))?;
    }
    match stack.keep {
        Some((_, end)) if page < end => Err(IoError::Truncated {
            path: path.to_path_buf(),
            what: format!("ImageJ hyperstack (frame {})", stack.frame),
            expected: end,
            actual: page,
            unit: "pages",
        }),
        _ => Ok(()),
    }
}

/// ImageJ hyperstacks (`channels=`, `slices=`, `frames=` in the description; pages in channel,
/// slice, frame order): keeps the pages of frame `options.frame`. Several channels are an
/// error. Without ImageJ frames, only frame 0 exists.
fn choose_frame(
    path: &Path,
    stack: &mut Stack,
    options: &ReadOptions,
    single_page: bool,
) -> Result<()> {
    let d = stack.description.as_deref().unwrap_or("");
    let key = |k: &str| -> Option<u64> {
        if !d.starts_with("ImageJ=") {
            return None;
        }
        d.lines()
            .find_map(|l| l.strip_prefix(k).and_then(|r| r.strip_prefix('=')))
            .and_then(|v| v.trim().parse::<u64>().ok())
            .filter(|&v| v >= 1)
    };
    if let Some(c) = key("channels").filter(|&c| c > 1) {
        return Err(IoError::unsupported(
            path,
            "ImageDescription channels",
            &c.to_string(),
            "1 (multi-channel ImageJ stacks are not supported; split the channels first)",
        ));
    }
    let frames = if single_page {
        1
    } else {
        key("frames").unwrap_or(1)
    };
    let f = options.frame as u64;
    if f >= frames {
        return Err(IoError::invalid_argument(
            path,
            "frame",
            format!(
                "frame {f} requested, but the file holds {frames} frame{} (0 to {})",
                if frames == 1 { "" } else { "s" },
                frames - 1
            ),
        ));
    }
    stack.frames = frames;
    stack.frame = f;
    if frames > 1 {
        let z = key("slices")
            .or_else(|| key("images").map(|n| n / frames))
            .unwrap_or(1)
            .max(1);
        let start = f.checked_mul(z).ok_or_else(|| {
            IoError::field(path, "ImageDescription slices", &z.to_string(), "too large")
        })?;
        stack.keep = Some((start, start.saturating_add(z)));
    }
    Ok(())
}

/// A RATIONAL tag's value as written (not yet checked: 0, NaN and infinity come back as such).
fn rational<R: std::io::Read + std::io::Seek>(dec: &mut Decoder<R>, tag: Tag) -> Option<f64> {
    match dec.find_tag(tag).ok().flatten()? {
        tiff::decoder::ifd::Value::Rational(n, d) => Some(n as f64 / d as f64),
        tiff::decoder::ifd::Value::SRational(n, d) => Some(n as f64 / d as f64),
        v => v.into_f64().ok(),
    }
}

/// A spacing from the file's metadata, checked: a positive finite value is used as is; a
/// negative one, where `magnitude_rule` (ImageJ's `spacing=`: ImageJ's `FileOpener` takes its
/// magnitude), becomes its magnitude; anything else (0, negative, NaN, infinite, not a number)
/// becomes 1. Each replacement is said in a note naming `field` (as spelled in the file), the
/// value and the `axis`.
fn checked_spacing(
    field: &str,
    text: &str,
    value: Option<f64>,
    axis: &str,
    magnitude_rule: bool,
    notes: &mut Vec<String>,
) -> f64 {
    match value {
        Some(v) if v.is_finite() && v > 0.0 => v,
        Some(v) if v.is_finite() && v < 0.0 && magnitude_rule => {
            notes.push(format!(
                "{field} {text} is negative; {axis} spacing taken as its magnitude {}, as ImageJ does",
                -v
            ));
            -v
        }
        _ => {
            notes.push(format!(
                "{field} {text} is not a positive finite number; {axis} spacing taken as 1"
            ));
            1.0
        }
    }
}

/// The pixel size along x or y from `XResolution` / `YResolution` (pixels per unit), checked.
fn resolution_spacing(
    tag: &str,
    res: Option<f64>,
    axis: &str,
    notes: &mut Vec<String>,
) -> Option<f64> {
    let r = res?;
    if r.is_finite() && r > 0.0 {
        return Some(1.0 / r);
    }
    let text = format!("{r} (pixels per unit)");
    Some(checked_spacing(tag, &text, None, axis, false, notes))
}

/// Spacing from ImageJ or OME-XML metadata, else 1 (module documentation). Values that are not
/// positive finite numbers are replaced as [`checked_spacing`] says, with a note.
fn spacing(
    description: Option<&str>,
    xres: Option<f64>,
    yres: Option<f64>,
    notes: &mut Vec<String>,
) -> [f64; 3] {
    if let Some(d) = description {
        if d.starts_with("ImageJ=") {
            let key = |k: &str| {
                d.lines()
                    .find_map(|l| l.strip_prefix(k).and_then(|r| r.strip_prefix('=')))
            };
            let unit = key("unit").unwrap_or("pixel").replace("\\u00B5", "µ");
            let mut checks = Vec::new();
            let sx = resolution_spacing("XResolution", xres, "x", &mut checks).unwrap_or(1.0);
            let sy = resolution_spacing("YResolution", yres, "y", &mut checks).unwrap_or(sx);
            let sz = key("spacing").map_or(1.0, |t| {
                let text = format!("`spacing={}`", t.trim());
                let field = "ImageDescription (ImageJ)";
                checked_spacing(field, &text, t.trim().parse().ok(), "z", true, &mut checks)
            });
            notes.push(format!(
                "spacing from ImageJ metadata: {sx} × {sy} × {sz} {unit} (world units are {unit})"
            ));
            notes.extend(checks);
            return [sx, sy, sz];
        }
        if d.contains("<OME") {
            let mut checks = Vec::new();
            let mut attr = |name: &str, axis: &str| {
                let pat = format!("{name}=\"");
                let text = d
                    .find(&pat)
                    .and_then(|p| d[p + pat.len()..].split('"').next())?;
                let field = format!("OME-XML {name}");
                Some(checked_spacing(
                    &field,
                    &format!("\"{text}\""),
                    text.trim().parse().ok(),
                    axis,
                    false,
                    &mut checks,
                ))
            };
            let s = [
                attr("PhysicalSizeX", "x").unwrap_or(1.0),
                attr("PhysicalSizeY", "y").unwrap_or(1.0),
                attr("PhysicalSizeZ", "z").unwrap_or(1.0),
            ];
            notes.push(format!(
                "spacing from OME-XML physical sizes: {} × {} × {} (µm unless the file's \
                 PhysicalSize*Unit says otherwise)",
                s[0], s[1], s[2]
            ));
            notes.extend(checks);
            return s;
        }
    }
    notes.push("no ImageJ or OME metadata: spacing taken as 1 × 1 × 1".into());
    [1.0; 3]
}

/// Samples gathered page by page, in the volume's type.
enum Acc {
    U8(Vec<u8>),
    I8(Vec<i8>),
    U16(Vec<u16>),
    I16(Vec<i16>),
    F32(Vec<f32>, &'static str, bool),
}

fn kind(r: &DecodingResult) -> &'static str {
    match r {
        DecodingResult::U8(_) => "uint8",
        DecodingResult::I8(_) => "int8",
        DecodingResult::U16(_) => "uint16",
        DecodingResult::I16(_) => "int16",
        DecodingResult::U32(_) => "uint32",
        DecodingResult::I32(_) => "int32",
        DecodingResult::U64(_) => "uint64",
        DecodingResult::I64(_) => "int64",
        DecodingResult::F16(_) => "float16",
        DecodingResult::F32(_) => "float32",
        DecodingResult::F64(_) => "float64",
    }
}

impl Acc {
    fn for_result(r: &DecodingResult) -> Acc {
        match r {
            DecodingResult::U8(_) => Acc::U8(Vec::new()),
            DecodingResult::I8(_) => Acc::I8(Vec::new()),
            DecodingResult::U16(_) => Acc::U16(Vec::new()),
            DecodingResult::I16(_) => Acc::I16(Vec::new()),
            other => Acc::F32(Vec::new(), kind(other), kind(other) != "float32"),
        }
    }

    /// Appends a page; a page of another type is `Err((expected, found))`.
    fn push(&mut self, r: DecodingResult) -> std::result::Result<(), (&'static str, &'static str)> {
        let got = kind(&r);
        match (self, r) {
            (Acc::U8(v), DecodingResult::U8(p)) => v.extend(p),
            (Acc::I8(v), DecodingResult::I8(p)) => v.extend(p),
            (Acc::U16(v), DecodingResult::U16(p)) => v.extend(p),
            (Acc::I16(v), DecodingResult::I16(p)) => v.extend(p),
            (Acc::F32(v, want, _), r) if kind(&r) == *want => match r {
                DecodingResult::F32(p) => v.extend(p),
                DecodingResult::F64(p) => v.extend(p.iter().map(|&x| x as f32)),
                DecodingResult::F16(p) => v.extend(p.iter().map(|x| x.to_f32())),
                DecodingResult::U32(p) => v.extend(p.iter().map(|&x| x as f32)),
                DecodingResult::I32(p) => v.extend(p.iter().map(|&x| x as f32)),
                DecodingResult::U64(p) => v.extend(p.iter().map(|&x| x as f32)),
                DecodingResult::I64(p) => v.extend(p.iter().map(|&x| x as f32)),
                _ => return Err((want, got)),
            },
            (a, _) => {
                let want = match a {
                    Acc::U8(_) => "uint8",
                    Acc::I8(_) => "int8",
                    Acc::U16(_) => "uint16",
                    Acc::I16(_) => "int16",
                    Acc::F32(_, w, _) => w,
                };
                return Err((want, got));
            }
        }
        Ok(())
    }

    fn into_volume(self, grid: Grid) -> volsplat_core::Result<AnyVolume> {
        Ok(match self {
            Acc::U8(v) => Volume::new(grid, v)?.into(),
            Acc::I8(v) => Volume::new(grid, v)?.into(),
            Acc::U16(v) => Volume::new(grid, v)?.into(),
            Acc::I16(v) => Volume::new(grid, v)?.into(),
            Acc::F32(v, _, _) => Volume::new(grid, v)?.into(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;
    use tiff::encoder::{Rational, TiffEncoder, colortype};
    use tiff::tags::ResolutionUnit;
    use volsplat_core::ScalarType;

    fn write_stack<C: colortype::ColorType>(
        path: &Path,
        w: u32,
        h: u32,
        pages: &[Vec<C::Inner>],
        description: Option<&str>,
        res: Option<(u32, u32)>,
    ) where
        [C::Inner]: tiff::encoder::TiffValue,
    {
        let f = std::fs::File::create(path).unwrap();
        let mut enc = TiffEncoder::new(f).unwrap();
        for p in pages {
            let mut img = enc.new_image::<C>(w, h).unwrap();
            if let Some(d) = description {
                img.encoder().write_tag(Tag::ImageDescription, d).unwrap();
            }
            if let Some((n, d)) = res {
                img.resolution(ResolutionUnit::None, Rational { n, d });
            }
            img.write_data(p).unwrap();
        }
    }

    fn tmp(dir: &Path, name: &str) -> PathBuf {
        dir.join(name)
    }

    #[test]
    fn imagej_stack_of_u16() {
        let dir = tempfile::tempdir().unwrap();
        let p = tmp(dir.path(), "s.tif");
        let pages: Vec<Vec<u16>> = (0..4)
            .map(|k| (0..6).map(|i| k * 100 + i).collect())
            .collect();
        let desc = "ImageJ=1.54f\nimages=4\nslices=4\nunit=micron\nspacing=2.5\nloop=false\n";
        write_stack::<colortype::Gray16>(&p, 3, 2, &pages, Some(desc), Some((2, 1)));
        let l = read_tiff_with(&p, &ReadOptions::default()).unwrap();
        let v = &l.volume;
        assert_eq!(v.scalar_type(), ScalarType::U16);
        assert_eq!(v.grid().dims, [3, 2, 4]);
        assert_eq!(v.grid().spacing, [0.5, 0.5, 2.5]);
        let f = v.to_f32();
        assert_eq!(f.get(2, 1, 3), 305.0);
        assert_eq!(f.get(1, 0, 2), 201.0);
        assert!(
            l.notes.iter().any(|n| n.contains("micron")),
            "{:?}",
            l.notes
        );
        // Through the dispatcher.
        let l = crate::read_volume_with(&p, &ReadOptions::default()).unwrap();
        assert_eq!(l.format, "TIFF");
    }

    #[test]
    fn types_and_plain_files() {
        let dir = tempfile::tempdir().unwrap();
        let p = tmp(dir.path(), "t.tiff");
        write_stack::<colortype::Gray8>(&p, 2, 1, &[vec![1, 2], vec![3, 4]], None, None);
        let l = read_tiff_with(&p, &ReadOptions::default()).unwrap();
        assert_eq!(l.volume.scalar_type(), ScalarType::U8);
        assert_eq!(l.volume.grid().spacing, [1.0; 3]);
        assert!(l.notes.iter().any(|n| n.contains("spacing taken as 1")));
        write_stack::<colortype::GrayI16>(&p, 2, 1, &[vec![-1, 2]], None, None);
        assert_eq!(read_tiff(&p).unwrap().scalar_type(), ScalarType::I16);
        write_stack::<colortype::Gray32Float>(&p, 2, 1, &[vec![0.5, -2.0]], None, None);
        let v = read_tiff(&p).unwrap();
        assert_eq!(v.scalar_type(), ScalarType::F32);
        assert_eq!(v.to_f32().data(), &[0.5, -2.0]);
        write_stack::<colortype::Gray32>(&p, 2, 1, &[vec![7, 70000]], None, None);
        let l = read_tiff_with(&p, &ReadOptions::default()).unwrap();
        assert_eq!(l.volume.to_f32().data(), &[7.0, 70000.0]);
        assert!(l.notes.iter().any(|n| n.contains("float32")));
        write_stack::<colortype::GrayI32>(&p, 2, 1, &[vec![-7, 7]], None, None);
        assert_eq!(read_tiff(&p).unwrap().to_f32().data(), &[-7.0, 7.0]);
        // OME-XML sizes.
        let ome = "<?xml version=\"1.0\"?><OME><Image><Pixels PhysicalSizeX=\"0.25\" \
                   PhysicalSizeY=\"0.5\" PhysicalSizeZ=\"3\"/></Image></OME>";
        write_stack::<colortype::Gray8>(&p, 2, 1, &[vec![1, 2]], Some(ome), None);
        assert_eq!(read_tiff(&p).unwrap().grid().spacing, [0.25, 0.5, 3.0]);
    }

    #[test]
    fn imagej_hyperstack_frames() {
        let dir = tempfile::tempdir().unwrap();
        let p = tmp(dir.path(), "h.tif");
        // 2 slices × 3 frames; page value = 10·frame + slice.
        let pages: Vec<Vec<u8>> = (0..6u8).map(|k| vec![10 * (k / 2) + k % 2; 4]).collect();
        let desc = "ImageJ=1.54f\nimages=6\nslices=2\nframes=3\nhyperstack=true\n";
        write_stack::<colortype::Gray8>(&p, 2, 2, &pages, Some(desc), None);
        for f in 0..3u8 {
            let o = ReadOptions {
                frame: f as usize,
                ..ReadOptions::default()
            };
            let l = crate::read_volume_with(&p, &o).unwrap();
            assert_eq!((l.frames, l.frame), (3, f as usize));
            assert_eq!(l.volume.grid().dims, [2, 2, 2]);
            let v = l.volume.to_f32();
            assert_eq!(
                (v.get(0, 0, 0), v.get(1, 1, 1)),
                ((10 * f) as f32, (10 * f + 1) as f32)
            );
        }
        let o = ReadOptions {
            frame: 3,
            ..ReadOptions::default()
        };
        let e = read_tiff_with(&p, &o).unwrap_err().to_string();
        assert!(e.contains("holds 3 frames"), "{e}");
        let desc = "ImageJ=1.54f\nimages=6\nchannels=2\nslices=3\n";
        write_stack::<colortype::Gray8>(&p, 2, 2, &pages, Some(desc), None);
        let e = read_tiff(&p).unwrap_err().to_string();
        assert!(e.contains("channels"), "{e}");
        // A plain stack has one frame.
        write_stack::<colortype::Gray8>(&p, 2, 2, &pages, None, None);
        let o = ReadOptions {
            frame: 1,
            ..ReadOptions::default()
        };
        assert!(
            read_tiff_with(&p, &o)
                .unwrap_err()
                .to_string()
                .contains("holds 1 frame")
        );
    }

    #[test]
    fn natural_order() {
        let mut v = vec![
            "s10.tif", "s2.tif", "s1.tif", "S01.tif", "a.tif", "s2b.tif", "s002.tif",
        ];
        v.sort_by(|a, b| natural_cmp(a, b));
        assert_eq!(
            v,
            [
                "S01.tif", "a.tif", "s1.tif", "s2.tif", "s2b.tif", "s002.tif", "s10.tif"
            ]
        );
    }

    #[test]
    fn folder_of_slices() {
        let dir = tempfile::tempdir().unwrap();
        for k in [10u8, 2, 1] {
            let p = tmp(dir.path(), &format!("slice{k}.TIF"));
            let desc = "ImageJ=1.54f\nunit=mm\nspacing=3\n";
            write_stack::<colortype::Gray8>(
                &p,
                2,
                1,
                &[vec![k, k + 100]],
                Some(desc),
                Some((4, 1)),
            );
        }
        std::fs::write(dir.path().join("notes.txt"), b"ignored").unwrap();
        let l = crate::read_volume_with(dir.path(), &ReadOptions::default()).unwrap();
        assert_eq!(l.volume.grid().dims, [2, 1, 3]);
        assert_eq!(l.volume.grid().spacing, [0.25, 0.25, 3.0]);
        assert_eq!(
            l.volume.to_f32().data(),
            &[1.0, 101.0, 2.0, 102.0, 10.0, 110.0]
        );
        assert!(
            l.notes.iter().any(|n| n.contains("natural order")),
            "{:?}",
            l.notes
        );
        // A multi-page slice is an error; an empty folder too.
        let p = tmp(dir.path(), "slice3.tif");
        write_stack::<colortype::Gray8>(&p, 2, 1, &[vec![1, 2], vec![3, 4]], None, None);
        let e = read_tiff_dir(dir.path(), &ReadOptions::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("slice3.tif") && e.contains("pages"), "{e}");
        let empty = tempfile::tempdir().unwrap();
        let e = crate::read_volume(empty.path()).unwrap_err().to_string();
        assert!(e.contains("directory") || e.contains(".tif"), "{e}");
    }

    #[test]
    fn malformed_stacks_are_errors() {
        let dir = tempfile::tempdir().unwrap();
        let p = tmp(dir.path(), "m.tif");
        // Pages of different sizes.
        {
            let f = std::fs::File::create(&p).unwrap();
            let mut enc = TiffEncoder::new(f).unwrap();
            enc.write_image::<colortype::Gray8>(2, 2, &[1, 2, 3, 4])
                .unwrap();
            enc.write_image::<colortype::Gray8>(1, 1, &[1]).unwrap();
        }
        let e = read_tiff(&p).unwrap_err().to_string();
        assert!(e.contains("page 1 size") && e.contains("m.tif"), "{e}");
        // Pages of different types.
        {
            let f = std::fs::File::create(&p).unwrap();
            let mut enc = TiffEncoder::new(f).unwrap();
            enc.write_image::<colortype::Gray8>(1, 1, &[1]).unwrap();
            enc.write_image::<colortype::Gray16>(1, 1, &[1]).unwrap();
        }
        let e = read_tiff(&p).unwrap_err().to_string();
        assert!(e.contains("page 1 sample type"), "{e}");
        // RGB.
        {
            let f = std::fs::File::create(&p).unwrap();
            let mut enc = TiffEncoder::new(f).unwrap();
            enc.write_image::<colortype::RGB8>(1, 1, &[1, 2, 3])
                .unwrap();
        }
        let e = read_tiff(&p).unwrap_err().to_string();
        assert!(e.contains("colour type"), "{e}");
        // Truncated and garbage files.
        write_stack::<colortype::Gray16>(&p, 64, 64, &[vec![7; 4096], vec![8; 4096]], None, None);
        let bytes = std::fs::read(&p).unwrap();
        for cut in [0, 3, 8, 100, bytes.len() / 2, bytes.len() - 10] {
            std::fs::write(&p, &bytes[..cut]).unwrap();
            assert!(read_tiff(&p).is_err(), "cut at {cut}");
        }
        std::fs::write(&p, b"II*\0\xff\xff\xff\x7f garbage").unwrap();
        assert!(read_tiff(&p).is_err());
        // A voxel limit.
        write_stack::<colortype::Gray8>(
            &p,
            2,
            2,
            &[vec![0; 4], vec![0; 4], vec![0; 4]],
            None,
            None,
        );
        let o = ReadOptions {
            limits: crate::Limits {
                max_voxels: 10,
                ..crate::Limits::default()
            },
            ..ReadOptions::default()
        };
        let e = read_tiff_with(&p, &o).unwrap_err().to_string();
        assert!(e.contains("exceeds the limit 10"), "{e}");
    }

    /// Issue 28 §4: an int64 TIFF (what `tifffile` writes for NumPy's default integers) used to
    /// fail with "invalid sample type int64 … must have the sample type of the first (int64)";
    /// 64-bit integers are now read, converted to float32 with a note.
    #[test]
    fn int64_and_uint64_stacks_are_read_as_f32() {
        let dir = tempfile::tempdir().unwrap();
        let p = tmp(dir.path(), "i64.tif");
        let pages: Vec<Vec<i64>> = vec![vec![-5, 0, 7, 1 << 20], vec![3, -(1 << 40), 9, 11]];
        write_stack::<colortype::GrayI64>(&p, 2, 2, &pages, None, None);
        let l = read_tiff_with(&p, &ReadOptions::default()).unwrap();
        assert_eq!(l.volume.scalar_type(), ScalarType::F32);
        let f = l.volume.to_f32();
        assert_eq!(
            f.data(),
            &[-5.0, 0.0, 7.0, 1048576.0, 3.0, -1099511627776.0, 9.0, 11.0]
        );
        assert!(
            l.notes
                .iter()
                .any(|n| n.contains("int64 converted to float32") && n.contains("rounded")),
            "{:?}",
            l.notes
        );
        let p = tmp(dir.path(), "u64.tif");
        write_stack::<colortype::Gray64>(&p, 1, 1, &[vec![42u64], vec![7]], None, None);
        let l = read_tiff_with(&p, &ReadOptions::default()).unwrap();
        assert_eq!(l.volume.to_f32().data(), &[42.0, 7.0]);
        assert!(
            l.notes.iter().any(|n| n.contains("uint64")),
            "{:?}",
            l.notes
        );
    }

    /// Issue 28 §3: ImageJ spacing that is negative, 0 or NaN, and resolutions of 0, are never
    /// used silently: a negative `spacing=` becomes its magnitude (ImageJ's `FileOpener` rule),
    /// the rest 1, each with a note naming the key or tag and the value.
    #[test]
    fn bad_imagej_and_ome_spacings_are_said() {
        let dir = tempfile::tempdir().unwrap();
        let p = tmp(dir.path(), "s.tif");
        let pages: Vec<Vec<u8>> = vec![vec![1; 4], vec![2; 4]];
        let read = |desc: &str, res: Option<(u32, u32)>| {
            write_stack::<colortype::Gray8>(&p, 2, 2, &pages, Some(desc), res);
            let l = read_tiff_with(&p, &ReadOptions::default()).unwrap();
            (l.volume.grid().spacing, l.notes)
        };
        let ij = |sp: &str| format!("ImageJ=1.54f\nimages=2\nslices=2\nunit=mm\nspacing={sp}\n");
        let (s, notes) = read(&ij("-2.5"), Some((4, 1)));
        assert_eq!(s, [0.25, 0.25, 2.5]);
        assert!(
            notes.iter().any(|n| n.contains("`spacing=-2.5`")
                && n.contains("negative")
                && n.contains("magnitude 2.5")),
            "{notes:?}"
        );
        for bad in ["0", "NaN", "inf", "abc"] {
            let (s, notes) = read(&ij(bad), Some((4, 1)));
            assert_eq!(s, [0.25, 0.25, 1.0], "{bad}");
            let want =
                format!("`spacing={bad}` is not a positive finite number; z spacing taken as 1");
            assert!(notes.iter().any(|n| n.contains(&want)), "{bad}: {notes:?}");
        }
        // XResolution 0 (pixels per unit): x and y spacing 1, said.
        let (s, notes) = read(&ij("3"), Some((0, 1)));
        assert_eq!(s, [1.0, 1.0, 3.0]);
        assert!(
            notes
                .iter()
                .any(|n| n.contains("XResolution") && n.contains("taken as 1")),
            "{notes:?}"
        );
        // OME-XML: a zero and a negative physical size.
        let ome = "<?xml version=\"1.0\"?><OME><Image><Pixels PhysicalSizeX=\"0\" \
                   PhysicalSizeY=\"-0.5\" PhysicalSizeZ=\"2\"/></Image></OME>";
        let (s, notes) = read(ome, None);
        assert_eq!(s, [1.0, 1.0, 2.0]);
        assert!(
            notes
                .iter()
                .any(|n| n.contains("PhysicalSizeX \"0\"") && n.contains("x spacing taken as 1")),
            "{notes:?}"
        );
        assert!(
            notes.iter().any(|n| n.contains("PhysicalSizeY \"-0.5\"")),
            "{notes:?}"
        );
        // Good values draw no such note.
        let (s, notes) = read(&ij("2"), Some((2, 1)));
        assert_eq!(s, [0.5, 0.5, 2.0]);
        assert!(!notes.iter().any(|n| n.contains("taken as")), "{notes:?}");
    }

    /// Issue 29 item 5: in a folder the read is confined to, a TIFF slice (or a TIFF file) that
    /// is a link out of it is refused; a slice left out would make a wrong volume.
    #[test]
    #[cfg(unix)]
    fn confined_reads_refuse_slices_outside_the_folder() {
        use crate::confine::tests::{assert_outside, layout};
        let l = layout(&[]);
        let stack = l.data.join("stack");
        std::fs::create_dir(&stack).unwrap();
        let outside = l.root.path().join("outside.tif");
        write_stack::<colortype::Gray8>(&outside, 2, 1, &[vec![7, 8]], None, None);
        write_stack::<colortype::Gray8>(&stack.join("s1.tif"), 2, 1, &[vec![1, 2]], None, None);
        let o = ReadOptions {
            limits: l.limits.clone(),
            ..ReadOptions::default()
        };
        let v = read_tiff_dir(&stack, &o).unwrap();
        assert_eq!(v.volume.to_f32().data(), &[1.0, 2.0]);
        std::os::unix::fs::symlink("../../outside.tif", stack.join("s2.tif")).unwrap();
        let v = read_tiff_dir(&stack, &ReadOptions::default()).unwrap();
        assert_eq!(v.volume.to_f32().data(), &[1.0, 2.0, 7.0, 8.0]);
        let e = read_tiff_dir(&stack, &o).unwrap_err();
        assert_outside(&e, "stack", "slice", "s2.tif", &l);
        // A TIFF file that is itself a link out.
        std::os::unix::fs::symlink("../outside.tif", l.data.join("link.tif")).unwrap();
        assert!(read_tiff_with(l.data.join("link.tif"), &ReadOptions::default()).is_ok());
        let e = read_tiff_with(l.data.join("link.tif"), &o).unwrap_err();
        assert!(matches!(e, IoError::OutsideFolder { .. }), "{e}");
    }
}
