//! Reading a volume's sample payload once a header has described it: shared by the NRRD,
//! MetaImage and headerless raw readers.
//!
//! Sizes are checked before allocation: a raw payload is allocated only after the file has been
//! found long enough; a compressed or text payload grows with the data actually decoded and is
//! never inflated past the needed size (plus one byte to check for a clean end of stream).

use crate::error::{IoError, Result};
use flate2::read::{MultiGzDecoder, ZlibDecoder};
use std::fs::File;
use std::io::{BufRead, BufReader, Read, Seek, SeekFrom};
use std::path::Path;
use volsplat_core::{AnyVolume, Grid, ScalarType, Volume};

/// Sample type as stored in a file. Types without a volsplat counterpart (`I32`, `U32`, `F64`)
/// are converted to `f32` on reading.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum FileType {
    U8,
    I8,
    U16,
    I16,
    F32,
    I32,
    U32,
    F64,
}

impl FileType {
    pub(crate) fn size_bytes(self) -> u64 {
        match self {
            FileType::U8 | FileType::I8 => 1,
            FileType::U16 | FileType::I16 => 2,
            FileType::F32 | FileType::I32 | FileType::U32 => 4,
            FileType::F64 => 8,
        }
    }

    pub(crate) fn name(self) -> &'static str {
        match self {
            FileType::U8 => "uint8",
            FileType::I8 => "int8",
            FileType::U16 => "uint16",
            FileType::I16 => "int16",
            FileType::F32 => "float",
            FileType::I32 => "int32",
            FileType::U32 => "uint32",
            FileType::F64 => "double",
        }
    }

    pub(crate) fn from_scalar(t: ScalarType) -> Self {
        match t {
            ScalarType::U8 => FileType::U8,
            ScalarType::I8 => FileType::I8,
            ScalarType::U16 => FileType::U16,
            ScalarType::I16 => FileType::I16,
            ScalarType::F32 => FileType::F32,
        }
    }
}

/// How the payload is encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Encoding {
    /// Uncompressed binary.
    Raw,
    /// A gzip stream (one or more members).
    Gzip,
    /// zlib or gzip, detected from the first two bytes (MetaImage's `CompressedData`).
    ZlibOrGzip,
    /// Whitespace- or comma-separated decimal numbers.
    Ascii,
}

impl Encoding {
    fn label(self) -> &'static str {
        match self {
            Encoding::Raw => "raw payload",
            Encoding::Gzip => "gzip payload",
            Encoding::ZlibOrGzip => "compressed payload",
            Encoding::Ascii => "text payload",
        }
    }
}

/// Where the payload starts after the line skip.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum ByteSkip {
    /// Skip this many bytes (of the decompressed stream for compressed data).
    Bytes(u64),
    /// Raw only: the payload is the last `needed` bytes of the file (NRRD `byte skip: -1`,
    /// MetaImage `HeaderSize = -1`).
    FromEnd,
}

/// Everything needed to read a payload, besides the grid.
#[derive(Debug, Clone)]
pub(crate) struct PayloadSpec<'a> {
    /// The file holding the data.
    pub(crate) data_path: &'a Path,
    /// Byte offset in `data_path` where the data region starts (after an attached header).
    pub(crate) start: u64,
    /// Lines to skip from `start` (in the file's bytes, before decompression).
    pub(crate) line_skip: u64,
    /// Bytes to skip after the lines.
    pub(crate) byte_skip: ByteSkip,
    /// The header field that set `byte_skip`, for error messages.
    pub(crate) skip_field: &'a str,
    pub(crate) encoding: Encoding,
    pub(crate) file_type: FileType,
    pub(crate) big_endian: bool,
    /// Headerless raw files: the data must end exactly where the samples end.
    pub(crate) exact: bool,
}

/// Reads the payload described by `spec` into a volume on `grid`.
///
/// The steps: the bytes needed (checked to fit in memory), the data file opened at the
/// payload (after `start` and the line skip), then the samples read by encoding and decoded.
pub(crate) fn read_payload(spec: &PayloadSpec<'_>, grid: Grid) -> Result<AnyVolume> {
    let path = spec.data_path;
    let needed = needed_bytes(spec, &grid)?;
    let data = open_at_payload(spec)?;
    match spec.encoding {
        Encoding::Raw => {
            let bytes = read_raw_samples(spec, data, needed)?;
            decode(bytes, spec.file_type, spec.big_endian, grid, path)
        }
        Encoding::Gzip | Encoding::ZlibOrGzip => {
            let bytes = read_compressed_samples(spec, data.file, needed)?;
            decode(bytes, spec.file_type, spec.big_endian, grid, path)
        }
        Encoding::Ascii => {
            let skip = byte_skip_forward(spec)?;
            let mut reader = BufReader::new(data.file);
            let skipped = std::io::copy(&mut (&mut reader).take(skip), &mut std::io::sink())
                .map_err(|e| IoError::os(path, "read", e))?;
            if skipped < skip {
                return Err(IoError::Truncated {
                    path: path.to_path_buf(),
                    what: format!("text payload (within `{}`)", spec.skip_field),
                    expected: skip,
                    actual: skipped,
                    unit: "bytes",
                });
            }
            let count = grid.voxel_count() as u64;
            let values = read_ascii(&mut reader, count, spec.file_type, path)?;
            decode_values(values, spec.file_type, grid, path)
        }
    }
}

/// The bytes of samples `grid` needs in the file's type; an error unless they fit in `usize`.
fn needed_bytes(spec: &PayloadSpec<'_>, grid: &Grid) -> Result<u64> {
    let count = grid.voxel_count() as u128;
    let needed128 = count * spec.file_type.size_bytes() as u128;
    u64::try_from(needed128)
        .ok()
        .filter(|&n| usize::try_from(n).is_ok())
        .ok_or_else(|| IoError::TooLarge {
            path: spec.data_path.to_path_buf(),
            what: "payload size in bytes".into(),
            value: needed128,
            limit: usize::MAX as u128,
        })
}

/// The data file, positioned at the payload.
struct OpenPayload {
    file: File,
    /// The file's size in bytes, as found when it was opened.
    file_len: u64,
    /// Where the payload begins: `start` plus the skipped lines (before any byte skip).
    pos: u64,
}

/// Opens the data file (a regular file only), checks that `start` lies within it and skips
/// `line_skip` lines from there (never past the end of the file as found).
fn open_at_payload(spec: &PayloadSpec<'_>) -> Result<OpenPayload> {
    let path = spec.data_path;
    crate::limits::require_regular_file(path, "data file")?;
    let mut file = File::open(path).map_err(|e| IoError::os(path, "open data file", e))?;
    let file_len = file
        .metadata()
        .map_err(|e| IoError::os(path, "stat data file", e))?
        .len();
    if spec.start > file_len {
        return Err(IoError::Truncated {
            path: path.to_path_buf(),
            what: "file (header runs past the end)".into(),
            expected: spec.start,
            actual: file_len,
            unit: "bytes",
        });
    }
    file.seek(SeekFrom::Start(spec.start))
        .map_err(|e| IoError::os(path, "seek", e))?;
    let pos = if spec.line_skip > 0 {
        let mut reader = BufReader::new(file);
        let skipped = skip_lines(&mut reader, spec.line_skip, file_len - spec.start, path)?;
        file = reader.into_inner();
        let pos = spec.start + skipped;
        file.seek(SeekFrom::Start(pos))
            .map_err(|e| IoError::os(path, "seek", e))?;
        pos
    } else {
        spec.start
    };
    Ok(OpenPayload {
        file,
        file_len,
        pos,
    })
}

/// The `needed` bytes of an uncompressed payload: after the byte skip, or the file's last
/// bytes (`ByteSkip::FromEnd`). The file's size is checked before anything is allocated; a
/// headerless raw file (`exact`) must end where the samples end.
fn read_raw_samples(spec: &PayloadSpec<'_>, data: OpenPayload, needed: u64) -> Result<Vec<u8>> {
    let path = spec.data_path;
    let offset = raw_offset(spec, &data, needed)?;
    let OpenPayload { mut file, .. } = data;
    file.seek(SeekFrom::Start(offset))
        .map_err(|e| IoError::os(path, "seek", e))?;
    // `needed` fits in usize (checked by `needed_bytes`) and the file holds at least that much.
    // Fallible: a file too big for memory is an error (`OutOfMemory`), not an abort.
    let mut bytes = Vec::new();
    bytes.try_reserve_exact(needed as usize).map_err(|_| {
        let oom = std::io::ErrorKind::OutOfMemory.into();
        IoError::os(path, "allocate the raw payload", oom)
    })?;
    // Into the reserved capacity (no zero-filling pass; `take` keeps it from growing).
    let got = (&mut file)
        .take(needed)
        .read_to_end(&mut bytes)
        .map_err(|e| IoError::os(path, "read raw payload", e))?;
    if (got as u64) < needed {
        return Err(IoError::Truncated {
            path: path.to_path_buf(),
            what: format!("raw payload starting at byte {offset}"),
            expected: needed,
            actual: got as u64,
            unit: "bytes",
        });
    }
    Ok(bytes)
}

/// Where the `needed` bytes of an uncompressed payload start: after the byte skip, or at the
/// file's last bytes (`ByteSkip::FromEnd`); checked against the file's size (exactly, for a
/// headerless raw file).
fn raw_offset(spec: &PayloadSpec<'_>, data: &OpenPayload, needed: u64) -> Result<u64> {
    let path = spec.data_path;
    let (file_len, pos) = (data.file_len, data.pos);
    let offset = match spec.byte_skip {
        ByteSkip::Bytes(b) => pos.saturating_add(b),
        ByteSkip::FromEnd => {
            if file_len.saturating_sub(pos) < needed {
                return Err(IoError::Truncated {
                    path: path.to_path_buf(),
                    what: format!(
                        "raw payload at the end of the file (`{} = -1`), after byte {pos}",
                        spec.skip_field
                    ),
                    expected: needed,
                    actual: file_len.saturating_sub(pos),
                    unit: "bytes",
                });
            }
            file_len - needed
        }
    };
    let available = file_len.saturating_sub(offset);
    if spec.exact && available != needed {
        return Err(IoError::SizeMismatch {
            path: path.to_path_buf(),
            expected: offset.saturating_add(needed),
            actual: file_len,
            detail: format!("{offset} header bytes + {needed} sample bytes"),
        });
    }
    if available < needed {
        return Err(IoError::Truncated {
            path: path.to_path_buf(),
            what: format!("raw payload starting at byte {offset}"),
            expected: needed,
            actual: available,
            unit: "bytes",
        });
    }
    Ok(offset)
}

/// Where the samples of an uncompressed payload of `grid` start in `spec.data_path` (after
/// `start`, the line skip and the byte skip, or the file's last bytes for `byte skip: -1`),
/// and how many bytes they take, checked against the file's size as a whole read checks them
/// (a brick source, `nrrd::NrrdSource`, reads its boxes from there).
pub(crate) fn raw_payload_offset(spec: &PayloadSpec<'_>, grid: &Grid) -> Result<(u64, u64)> {
    debug_assert_eq!(spec.encoding, Encoding::Raw);
    let needed = needed_bytes(spec, grid)?;
    let data = open_at_payload(spec)?;
    Ok((raw_offset(spec, &data, needed)?, needed))
}

/// An uncompressed payload read one z slice at a time (`convert -o X.zarr` streams large
/// raw and NRRD files through it: memory bounded by a slice, not the volume). The sizes are
/// checked against the file before the first slice is read, as for a whole read.
pub(crate) struct RawSlices {
    file: std::io::BufReader<File>,
    path: std::path::PathBuf,
    file_type: FileType,
    big_endian: bool,
    /// Samples per slice (`nx · ny`).
    slice: usize,
    /// Slices left to read.
    left: usize,
    /// The slices' grid (one slice thick).
    grid: Grid,
}

impl RawSlices {
    /// Opens `spec` (raw encoding) for slices of `grid`.
    pub(crate) fn open(spec: &PayloadSpec<'_>, grid: &Grid) -> Result<Self> {
        debug_assert_eq!(spec.encoding, Encoding::Raw);
        let path = spec.data_path;
        let needed = needed_bytes(spec, grid)?;
        let data = open_at_payload(spec)?;
        let offset = raw_offset(spec, &data, needed)?;
        let mut file = data.file;
        file.seek(SeekFrom::Start(offset))
            .map_err(|e| IoError::os(path, "seek", e))?;
        let [nx, ny, nz] = grid.dims;
        let one = Grid::new([nx, ny, 1], grid.spacing, grid.origin, grid.direction)
            .map_err(|e| IoError::core(path, e))?;
        Ok(RawSlices {
            file: std::io::BufReader::with_capacity(1 << 20, file),
            path: path.to_path_buf(),
            file_type: spec.file_type,
            big_endian: spec.big_endian,
            slice: nx * ny,
            left: nz,
            grid: one,
        })
    }

    /// The next slice, decoded as a whole read decodes it (`int32`, `uint32`, `double` to
    /// `f32`; non-finite floats replaced within the slice: callers check a float file has
    /// none first, [`RawSlices::count_non_finite`]).
    pub(crate) fn next_slice(&mut self) -> Result<AnyVolume> {
        if self.left == 0 {
            return Err(IoError::invalid_argument(
                &self.path,
                "slice",
                "read past the last slice",
            ));
        }
        self.left -= 1;
        let n = self.slice * self.file_type.size_bytes() as usize;
        let mut bytes = vec![0u8; n];
        self.file
            .read_exact(&mut bytes)
            .map_err(|e| IoError::os(&self.path, "read raw payload", e))?;
        decode(
            bytes,
            self.file_type,
            self.big_endian,
            self.grid.clone(),
            &self.path,
        )
    }

    /// Samples that are NaN or infinite in the whole payload (0 for integer types), reading
    /// every slice; consumes the reader.
    pub(crate) fn count_non_finite(mut self) -> Result<u64> {
        if !matches!(self.file_type, FileType::F32 | FileType::F64) {
            return Ok(0);
        }
        let mut count = 0;
        while self.left > 0 {
            if let Some(n) = self.next_slice()?.non_finite() {
                count += n.count() as u64;
            }
        }
        Ok(count)
    }
}

/// The `needed` bytes of a gzip (or, for [`Encoding::ZlibOrGzip`], zlib) payload after the
/// byte skip, decompressed into a buffer that grows with the data and never past `needed`;
/// one more byte is read to check the stream's end (and, for `exact` files, that it ends there).
fn read_compressed_samples(spec: &PayloadSpec<'_>, file: File, needed: u64) -> Result<Vec<u8>> {
    let path = spec.data_path;
    let skip = byte_skip_forward(spec)?;
    let mut reader = BufReader::new(file);
    let what = spec.encoding.label();
    let mut decoder: Box<dyn Read> = if spec.encoding == Encoding::Gzip {
        Box::new(MultiGzDecoder::new(reader))
    } else {
        let head = reader
            .fill_buf()
            .map_err(|e| IoError::os(path, "read", e))?;
        if head.starts_with(&[0x1f, 0x8b]) {
            Box::new(MultiGzDecoder::new(reader))
        } else {
            Box::new(ZlibDecoder::new(reader))
        }
    };
    let skipped = read_capped(&mut decoder, skip, &mut std::io::sink(), path, what)?;
    if skipped < skip {
        return Err(IoError::Truncated {
            path: path.to_path_buf(),
            what: format!("{what} (within `{}`)", spec.skip_field),
            expected: skip.saturating_add(needed),
            actual: skipped,
            unit: "bytes",
        });
    }
    let mut out = BoundedVec {
        vec: Vec::new(),
        limit: needed as usize,
    };
    let got = read_capped(&mut decoder, needed, &mut out, path, what)?;
    if got < needed {
        return Err(IoError::Truncated {
            path: path.to_path_buf(),
            what: if skip == 0 {
                format!("{what} (decompressed)")
            } else {
                format!("{what} (decompressed, after skipping {skip} bytes)")
            },
            expected: needed,
            actual: got,
            unit: "bytes",
        });
    }
    // One more byte: reaching the end checks the stream's trailer (CRC); extra data is an error
    // only for headerless raw files, where the size is the only check we have.
    let mut one = [0u8; 1];
    match read_retrying(&mut decoder, &mut one) {
        Ok(0) => {}
        Ok(_) => {
            if spec.exact {
                return Err(IoError::SizeMismatch {
                    path: path.to_path_buf(),
                    expected: skip.saturating_add(needed),
                    actual: skip.saturating_add(needed).saturating_add(1),
                    detail: format!(
                        "decompressed: {skip} header bytes + {needed} sample bytes; \
                         the stream holds at least one byte more"
                    ),
                });
            }
        }
        Err(e) => {
            return Err(IoError::Decompress {
                path: path.to_path_buf(),
                what: format!("{what} (stream trailer after the samples)"),
                error: e,
            });
        }
    }
    Ok(out.vec)
}

fn byte_skip_forward(spec: &PayloadSpec<'_>) -> Result<u64> {
    match spec.byte_skip {
        ByteSkip::Bytes(b) => Ok(b),
        ByteSkip::FromEnd => Err(IoError::field(
            spec.data_path,
            spec.skip_field,
            "-1",
            "-1 (data at the end of the file) is only allowed with raw encoding",
        )),
    }
}

/// A growable buffer whose capacity never exceeds `limit` (a plain `Vec` may double past it), so
/// memory follows the data actually decoded and stays within the needed size.
struct BoundedVec {
    vec: Vec<u8>,
    limit: usize,
}

impl std::io::Write for BoundedVec {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let want = self.vec.len() + buf.len();
        if want > self.limit {
            return Err(std::io::Error::other("decoded data exceed the needed size"));
        }
        if want > self.vec.capacity() {
            let target = want
                .max(self.vec.capacity().saturating_mul(2))
                .min(self.limit);
            // Fallible: a file too big for memory is an error (`OutOfMemory`), not an abort.
            self.vec
                .try_reserve_exact(target - self.vec.len())
                .map_err(|_| std::io::Error::from(std::io::ErrorKind::OutOfMemory))?;
        }
        self.vec.extend_from_slice(buf);
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

fn read_retrying(r: &mut dyn Read, buf: &mut [u8]) -> std::io::Result<usize> {
    loop {
        match r.read(buf) {
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            other => return other,
        }
    }
}

/// Copies at most `cap` bytes from a decompressor into `out`; returns how many were copied
/// (fewer at a clean end of stream). A stream that breaks off mid-way yields the bytes so far
/// only if the decoder reports it as an unexpected end; other decoder errors are reported.
fn read_capped<W: std::io::Write + ?Sized>(
    r: &mut dyn Read,
    cap: u64,
    out: &mut W,
    path: &Path,
    what: &str,
) -> Result<u64> {
    let mut buf = vec![0u8; 64 * 1024];
    let mut total = 0u64;
    while total < cap {
        let want = (cap - total).min(buf.len() as u64) as usize;
        match read_retrying(r, &mut buf[..want]) {
            Ok(0) => break,
            Ok(n) => {
                out.write_all(&buf[..n])
                    .map_err(|e| IoError::os(path, "buffer decompressed data", e))?;
                total += n as u64;
            }
            Err(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => break,
            Err(e) => {
                return Err(IoError::Decompress {
                    path: path.to_path_buf(),
                    what: format!("{what} (after {total} decompressed bytes)"),
                    error: e,
                });
            }
        }
    }
    Ok(total)
}

/// Skips `n` lines (through their `\n`), returning the number of bytes consumed. Never reads
/// more than `max_bytes` (the rest of the file as its size was found), so a file that grows or
/// never ends cannot keep it reading.
fn skip_lines(reader: &mut BufReader<File>, n: u64, max_bytes: u64, path: &Path) -> Result<u64> {
    let mut consumed = 0u64;
    let mut lines = 0u64;
    while lines < n {
        if consumed >= max_bytes {
            return Err(IoError::Truncated {
                path: path.to_path_buf(),
                what: "data file while skipping lines (`line skip`)".into(),
                expected: n,
                actual: lines,
                unit: "lines",
            });
        }
        let buf = reader
            .fill_buf()
            .map_err(|e| IoError::os(path, "read (line skip)", e))?;
        if buf.is_empty() {
            return Err(IoError::Truncated {
                path: path.to_path_buf(),
                what: "data file while skipping lines (`line skip`)".into(),
                expected: n,
                actual: lines,
                unit: "lines",
            });
        }
        let take = match buf.iter().position(|&b| b == b'\n') {
            Some(p) => {
                lines += 1;
                p + 1
            }
            None => buf.len(),
        };
        reader.consume(take);
        consumed += take as u64;
    }
    Ok(consumed)
}

/// Parses up to `count` numbers separated by whitespace or commas.
fn read_ascii(
    reader: &mut BufReader<File>,
    count: u64,
    file_type: FileType,
    path: &Path,
) -> Result<Vec<f64>> {
    const MAX_TOKEN: usize = 64;
    let mut values = Vec::new();
    let mut token = Vec::with_capacity(MAX_TOKEN);
    let push = |token: &mut Vec<u8>, values: &mut Vec<f64>| -> Result<()> {
        if token.is_empty() {
            return Ok(());
        }
        let text = String::from_utf8_lossy(token).into_owned();
        let v = parse_text_value(&text, file_type).map_err(|reason| {
            IoError::field(
                path,
                format!("data (value #{})", values.len()),
                &text,
                reason,
            )
        })?;
        values.push(v);
        token.clear();
        Ok(())
    };
    loop {
        let buf = reader
            .fill_buf()
            .map_err(|e| IoError::os(path, "read text payload", e))?;
        if buf.is_empty() {
            break;
        }
        let len = buf.len();
        let mut done_at = None;
        for (i, &b) in buf.iter().enumerate() {
            if b.is_ascii_whitespace() || b == b',' {
                push(&mut token, &mut values)?;
                if values.len() as u64 == count {
                    done_at = Some(i + 1);
                    break;
                }
            } else {
                if token.len() >= MAX_TOKEN {
                    return Err(IoError::field(
                        path,
                        format!("data (value #{})", values.len()),
                        &String::from_utf8_lossy(&token),
                        format!("token longer than {MAX_TOKEN} characters"),
                    ));
                }
                token.push(b);
            }
        }
        if let Some(used) = done_at {
            reader.consume(used);
            break;
        }
        reader.consume(len);
    }
    if (values.len() as u64) < count {
        push(&mut token, &mut values)?;
    }
    if (values.len() as u64) < count {
        return Err(IoError::Truncated {
            path: path.to_path_buf(),
            what: "text payload".into(),
            expected: count,
            actual: values.len() as u64,
            unit: "values",
        });
    }
    Ok(values)
}

fn parse_text_value(text: &str, file_type: FileType) -> std::result::Result<f64, String> {
    let (lo, hi): (f64, f64) = match file_type {
        FileType::U8 => (0.0, 255.0),
        FileType::I8 => (-128.0, 127.0),
        FileType::U16 => (0.0, 65535.0),
        FileType::I16 => (-32768.0, 32767.0),
        FileType::I32 => (i32::MIN as f64, i32::MAX as f64),
        FileType::U32 => (0.0, u32::MAX as f64),
        FileType::F32 | FileType::F64 => {
            // `nan` and `inf` (as teem and ITK write them) are read; `Volume::new` replaces
            // them and says so (decision 0030).
            return text
                .parse()
                .map_err(|_| format!("not a number of type {}", file_type.name()));
        }
    };
    let v: i64 = text
        .parse()
        .map_err(|_| format!("not an integer of type {}", file_type.name()))?;
    let v = v as f64;
    if v < lo || v > hi {
        return Err(format!("out of range for type {}", file_type.name()));
    }
    Ok(v)
}

fn decode_values(values: Vec<f64>, ft: FileType, grid: Grid, path: &Path) -> Result<AnyVolume> {
    // Range was checked while parsing, so the casts are exact for integer types.
    let v: AnyVolume = match ft {
        FileType::U8 => {
            Volume::new(grid, values.iter().map(|&x| x as u8).collect()).map(Into::into)
        }
        FileType::I8 => {
            Volume::new(grid, values.iter().map(|&x| x as i8).collect()).map(Into::into)
        }
        FileType::U16 => {
            Volume::new(grid, values.iter().map(|&x| x as u16).collect()).map(Into::into)
        }
        FileType::I16 => {
            Volume::new(grid, values.iter().map(|&x| x as i16).collect()).map(Into::into)
        }
        FileType::F32 | FileType::F64 | FileType::I32 | FileType::U32 => {
            Volume::new(grid, doubles_to_f32(values.into_iter(), path)?).map(Into::into)
        }
    }
    .map_err(|e| IoError::core(path, e))?;
    Ok(v)
}

/// Doubles as float32 samples. A finite double beyond the float32 range is an error naming the
/// sample (it would become an infinity, which `Volume::new` clamps to the finite range: a
/// silently wrong value); NaN and infinities stay what they are (`Volume::new` replaces them
/// and says so, decision 0030).
pub(crate) fn doubles_to_f32(values: impl Iterator<Item = f64>, path: &Path) -> Result<Vec<f32>> {
    values
        .enumerate()
        .map(|(n, x)| {
            let y = x as f32;
            if x.is_finite() && !y.is_finite() {
                return Err(IoError::core(
                    path,
                    volsplat_core::CoreError::invalid(
                        format!("sample #{n}"),
                        x,
                        "outside the float32 range",
                    ),
                ));
            }
            Ok(y)
        })
        .collect()
}

/// Converts raw bytes (exactly `voxel_count · size` of them) into a typed volume.
pub(crate) fn decode(
    bytes: Vec<u8>,
    ft: FileType,
    big_endian: bool,
    grid: Grid,
    path: &Path,
) -> Result<AnyVolume> {
    macro_rules! conv {
        ($t:ty, $n:literal) => {
            bytes
                .chunks_exact($n)
                .map(|c| {
                    let mut a = [0u8; $n];
                    a.copy_from_slice(c);
                    if big_endian {
                        <$t>::from_be_bytes(a)
                    } else {
                        <$t>::from_le_bytes(a)
                    }
                })
                .collect::<Vec<$t>>()
        };
    }
    let v: std::result::Result<AnyVolume, _> = match ft {
        FileType::U8 => Volume::new(grid, bytes).map(Into::into),
        FileType::I8 => {
            Volume::new(grid, bytes.into_iter().map(|b| b as i8).collect()).map(Into::into)
        }
        FileType::U16 => Volume::new(grid, conv!(u16, 2)).map(Into::into),
        FileType::I16 => Volume::new(grid, conv!(i16, 2)).map(Into::into),
        FileType::F32 => Volume::new(grid, conv!(f32, 4)).map(Into::into),
        FileType::I32 => {
            Volume::new(grid, conv!(i32, 4).into_iter().map(|x| x as f32).collect()).map(Into::into)
        }
        FileType::U32 => {
            Volume::new(grid, conv!(u32, 4).into_iter().map(|x| x as f32).collect()).map(Into::into)
        }
        FileType::F64 => {
            Volume::new(grid, doubles_to_f32(conv!(f64, 8).into_iter(), path)?).map(Into::into)
        }
    };
    v.map_err(|e| IoError::core(path, e))
}

/// Writes the samples little-endian, i fastest.
pub(crate) fn write_samples_le<W: std::io::Write + ?Sized>(
    w: &mut W,
    volume: &AnyVolume,
) -> std::io::Result<()> {
    trait LeBytes: Copy {
        fn put(self, out: &mut Vec<u8>);
    }
    macro_rules! le {
        ($($t:ty),*) => {$(impl LeBytes for $t {
            fn put(self, out: &mut Vec<u8>) { out.extend_from_slice(&self.to_le_bytes()); }
        })*};
    }
    le!(u8, i8, u16, i16, f32);
    fn write_all<T: LeBytes, W: std::io::Write + ?Sized>(
        w: &mut W,
        data: &[T],
    ) -> std::io::Result<()> {
        let mut buf = Vec::with_capacity(64 * 1024);
        for chunk in data.chunks(16 * 1024) {
            buf.clear();
            for &v in chunk {
                v.put(&mut buf);
            }
            w.write_all(&buf)?;
        }
        Ok(())
    }
    volsplat_core::with_volume!(volume, v => write_all(w, v.data()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    #[test]
    fn bounded_vec_never_exceeds_its_limit() {
        let mut b = BoundedVec {
            vec: Vec::new(),
            limit: 100_003,
        };
        for _ in 0..100 {
            b.write_all(&[1u8; 1000]).unwrap();
        }
        b.write_all(&[2u8; 3]).unwrap();
        assert_eq!(b.vec.len(), 100_003);
        assert!(b.vec.capacity() <= 100_003, "{}", b.vec.capacity());
        assert!(b.write_all(&[0]).is_err());
    }
}
