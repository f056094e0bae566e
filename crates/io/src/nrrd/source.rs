//! [`NrrdSource`]: a NRRD file with a raw payload served brick by brick (the brick seam,
//! `docs/design/brick-seam.md` §2.1; issue 32 item 2): each brick reads only its halo box from
//! the file, so a sort-last rank never reads the whole volume.
//!
//! **Encodings.** Only `encoding: raw` (attached or detached) is served: a raw payload is a
//! plain array at a known offset, so a box is a few seeks and reads. A gzip (or text) payload
//! has no random access: a box would need the stream decompressed from its start up to the
//! box's last row, once per brick (or once per rank keeping only its region, which is still a
//! pass over the whole compressed file on every rank). [`NrrdHeader::source`] refuses them with
//! an error naming the encoding; the engine reads such files whole instead.

use super::with_payload;
use crate::error::{IoError, Result};
use crate::limits::Limits;
use crate::payload::{Encoding, FileType, raw_payload_offset};
use std::fs::File;
use std::marker::PhantomData;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use volsplat_core::source::{Brick, BrickKey, BrickLayout, BrickSource};
use volsplat_core::{Grid, Scalar, ScalarType};

/// What a NRRD header says, read without a sample: the grid (LPS, as [`super::read_nrrd`]
/// gives it), the type the samples are read as, and where a raw payload lies.
#[derive(Debug, Clone)]
pub struct NrrdHeader {
    path: PathBuf,
    grid: Grid,
    scalar_type: ScalarType,
    file_type: FileType,
    encoding: Encoding,
    /// The header's `encoding` as written, for messages.
    encoding_name: &'static str,
    big_endian: bool,
    /// Raw payloads: the data file, the offset of the first sample and the payload's bytes.
    raw: Option<(PathBuf, u64, u64)>,
    notes: Vec<String>,
}

impl NrrdHeader {
    /// Parses the header of the NRRD file `path` (`.nrrd` or `.nhdr`) under `limits`, as
    /// [`super::read_nrrd_with`] does, and for a raw payload finds where its samples start
    /// (line and byte skips, `byte skip: -1`) and checks that the data file holds them all. No
    /// sample is read. Errors as the whole-file reader's, naming the file and field (a
    /// truncated data file: [`IoError::Truncated`] naming it).
    pub fn open(path: impl AsRef<Path>, limits: &Limits) -> Result<Self> {
        let path = path.as_ref();
        with_payload(path, limits, |spec, grid, notes| {
            let raw = match spec.encoding {
                Encoding::Raw => {
                    let (offset, needed) = raw_payload_offset(spec, &grid)?;
                    Some((spec.data_path.to_path_buf(), offset, needed))
                }
                _ => None,
            };
            let scalar_type = match spec.file_type {
                FileType::U8 => ScalarType::U8,
                FileType::I8 => ScalarType::I8,
                FileType::U16 => ScalarType::U16,
                FileType::I16 => ScalarType::I16,
                FileType::F32 | FileType::I32 | FileType::U32 | FileType::F64 => ScalarType::F32,
            };
            Ok(NrrdHeader {
                path: path.to_path_buf(),
                grid,
                scalar_type,
                file_type: spec.file_type,
                encoding: spec.encoding,
                encoding_name: match spec.encoding {
                    Encoding::Raw => "raw",
                    Encoding::Gzip | Encoding::ZlibOrGzip => "gzip",
                    Encoding::Ascii => "ascii",
                },
                big_endian: spec.big_endian,
                raw,
                notes,
            })
        })
    }

    /// The header file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The volume's geometry (world frame LPS, as [`super::read_nrrd`] reads it).
    pub fn grid(&self) -> &Grid {
        &self.grid
    }

    /// The type the samples are read as: the file's, or `f32` for `int32`, `uint32` and
    /// `double` (converted as [`super::read_nrrd`] converts them).
    pub fn scalar_type(&self) -> ScalarType {
        self.scalar_type
    }

    /// Whether the payload is raw, so that [`NrrdHeader::source`] serves it.
    pub fn is_raw(&self) -> bool {
        self.encoding == Encoding::Raw
    }

    /// The reader's notes (how the world frame was taken), as the whole-file reader gives them.
    pub fn notes(&self) -> &[String] {
        &self.notes
    }

    /// The file's samples served in bricks of `size` cells per side (a power of two and a
    /// multiple of 8, [`BrickLayout::new`]). Opens the data file (kept open: every brick reads
    /// from it).
    ///
    /// Errors naming the file: a payload not raw (`encoding`: gzip and text have no random
    /// access; read those whole), `T` other than [`NrrdHeader::scalar_type`], a bad brick size,
    /// a data file that cannot be opened.
    pub fn source<T: Scalar>(&self, size: usize) -> Result<NrrdSource<T>> {
        let path = &self.path;
        let Some((data_path, offset, needed)) = self.raw.clone() else {
            return Err(IoError::unsupported(
                path,
                "encoding",
                self.encoding_name,
                "raw (a brick source reads each brick's box from the file; a gzip or text \
                 payload has no random access and is read whole)",
            ));
        };
        if T::TYPE != self.scalar_type {
            return Err(IoError::invalid_argument(
                path,
                "type",
                format!(
                    "the file's {} samples are read as {}; a brick source of {} was asked for",
                    self.file_type.name(),
                    self.scalar_type.name(),
                    T::TYPE.name()
                ),
            ));
        }
        let layout =
            BrickLayout::new(self.grid.clone(), 0, size).map_err(|e| IoError::core(path, e))?;
        let file =
            File::open(&data_path).map_err(|e| IoError::os(&data_path, "open data file", e))?;
        Ok(NrrdSource {
            file: Arc::new(RawFile {
                file,
                path: data_path,
                offset,
                needed,
                file_type: self.file_type,
                big_endian: self.big_endian,
                bytes_read: Arc::new(AtomicU64::new(0)),
            }),
            grids: [self.grid.clone()],
            layout,
            finite: None,
            as_stored: false,
            _sample: PhantomData,
        })
    }
}

/// The open data file of a raw payload.
#[derive(Debug)]
struct RawFile {
    file: File,
    path: PathBuf,
    /// Byte offset of sample 0.
    offset: u64,
    /// Bytes of the payload (checked against the file when the header was opened).
    needed: u64,
    file_type: FileType,
    big_endian: bool,
    /// Bytes read from the file so far, by every brick.
    bytes_read: Arc<AtomicU64>,
}

/// A [`BrickSource`] over a NRRD file's raw payload (one level; [`NrrdHeader::source`]):
/// [`BrickSource::brick`] reads the brick's halo box ([`BrickLayout::halo_voxels`]) from the
/// file, one read per row of the box (one per z slab of rows where the box spans whole rows,
/// one in all where it spans whole slices), decodes it as the whole-file reader does (byte
/// order; `int32`, `uint32`, `double` to `f32`, a finite `double` beyond the `f32` range an
/// error) and cuts the slot with [`Brick::from_region`]: a brick holds the samples of the brick
/// of the file read whole ([`super::read_nrrd`]) served by [`volsplat_core::InMemory`].
/// [`BrickSource::whole`] is `None`.
///
/// **Float files** (decision 0030), as [`crate::ZarrSource`]: a volume read whole replaces NaN
/// and −∞ by its lowest finite sample and +∞ by its highest, which a brick cannot know; a brick
/// holding a non-finite sample is an error until the level's finite range is given
/// ([`NrrdSource::with_finite_range`]), or served as stored ([`NrrdSource::as_stored`], for a
/// ranges scan).
#[derive(Debug, Clone)]
pub struct NrrdSource<T> {
    file: Arc<RawFile>,
    grids: [Grid; 1],
    layout: BrickLayout,
    finite: Option<[f32; 2]>,
    as_stored: bool,
    _sample: PhantomData<fn() -> T>,
}

impl<T: Scalar> NrrdSource<T> {
    /// This source with the volume's finite sample range `[lowest, highest]` (data units, the
    /// lowest and highest finite samples of the whole volume): NaN and −∞ samples of its bricks
    /// become `lowest`, +∞ become `highest`, as [`volsplat_core::Volume::new`] replaces them in
    /// the volume read whole. Errors (naming the file and `finite range`) for bounds that are
    /// not finite or `lowest > highest`.
    pub fn with_finite_range(mut self, range: [f32; 2]) -> Result<Self> {
        if !(range[0].is_finite() && range[1].is_finite() && range[0] <= range[1]) {
            return Err(IoError::invalid_argument(
                &self.file.path,
                "finite range",
                format!("{range:?}: must be two finite values, lowest ≤ highest"),
            ));
        }
        self.finite = Some(range);
        Ok(self)
    }

    /// A copy of this source that serves the samples as stored (non-finite floats kept), for
    /// the ranges scan that finds the finite range; not for rendering.
    pub fn as_stored(&self) -> Self {
        NrrdSource {
            as_stored: true,
            ..self.clone()
        }
    }

    /// Bytes read from the data file so far by this source and its copies (every brick read,
    /// rows and slabs as read).
    pub fn bytes_read(&self) -> u64 {
        self.file.bytes_read.load(Ordering::Relaxed)
    }

    /// The counter behind [`NrrdSource::bytes_read`], shared with the source's copies.
    pub fn bytes_read_counter(&self) -> Arc<AtomicU64> {
        Arc::clone(&self.file.bytes_read)
    }

    /// The samples of the box `[lo, lo + dims)` (index space, x fastest), decoded.
    fn read_box(&self, lo: [usize; 3], dims: [usize; 3]) -> Result<Vec<T>> {
        let f = &*self.file;
        let n = self.grids[0].dims;
        let size = f.file_type.size_bytes() as usize;
        let count = dims.iter().try_fold(1usize, |p, &d| p.checked_mul(d));
        let bytes = count.and_then(|c| c.checked_mul(size)).ok_or_else(|| {
            IoError::invalid_argument(&f.path, "brick", format!("a box of {dims:?} samples"))
        })?;
        let mut buf = Vec::new();
        buf.try_reserve_exact(bytes).map_err(|_| {
            IoError::os(
                &f.path,
                "allocate a brick's box",
                std::io::ErrorKind::OutOfMemory.into(),
            )
        })?;
        buf.resize(bytes, 0);
        // The runs of contiguous samples: a row, a slab of whole rows, or whole slices.
        let full_x = lo[0] == 0 && dims[0] == n[0];
        let full_xy = full_x && lo[1] == 0 && dims[1] == n[1];
        let sample = |i: usize, j: usize, k: usize| (i + n[0] * (j + n[1] * k)) as u64;
        let read = |at: u64, out: &mut [u8]| -> Result<()> {
            let pos = f.offset + at * size as u64;
            let end = pos + out.len() as u64;
            if end > f.offset + f.needed {
                return Err(IoError::invalid_argument(
                    &f.path,
                    "brick",
                    format!("bytes [{pos}, {end}) lie beyond the payload"),
                ));
            }
            read_exact_at(&f.file, out, pos).map_err(|e| {
                let what = format!("read the brick's bytes [{pos}, {end}) of the raw payload");
                if e.kind() == std::io::ErrorKind::UnexpectedEof {
                    IoError::Truncated {
                        path: f.path.clone(),
                        what: format!("raw payload (bytes [{pos}, {end}))"),
                        expected: end,
                        actual: f.file.metadata().map_or(0, |m| m.len()),
                        unit: "bytes",
                    }
                } else {
                    IoError::os(&f.path, what, e)
                }
            })?;
            f.bytes_read.fetch_add(out.len() as u64, Ordering::Relaxed);
            Ok(())
        };
        if full_xy {
            read(sample(0, 0, lo[2]), &mut buf)?;
        } else if full_x {
            for (z, slab) in buf.chunks_exact_mut(dims[0] * dims[1] * size).enumerate() {
                read(sample(0, lo[1], lo[2] + z), slab)?;
            }
        } else {
            for (r, row) in buf.chunks_exact_mut(dims[0] * size).enumerate() {
                let (j, k) = (lo[1] + r % dims[1], lo[2] + r / dims[1]);
                read(sample(lo[0], j, k), row)?;
            }
        }
        decode(&buf, f.file_type, f.big_endian, &f.path)
    }

    /// Replaces the box's non-finite floats by the finite range, or errors (the cause) where
    /// there are some and no range was given.
    fn replace_non_finite(&self, region: &mut [T]) -> std::result::Result<(), String> {
        if T::TYPE != ScalarType::F32 || self.as_stored {
            return Ok(());
        }
        if region.iter().all(|v| v.to_f32().is_finite()) {
            return Ok(());
        }
        let Some([lo, hi]) = self.finite else {
            let bad = region.iter().filter(|v| !v.to_f32().is_finite()).count();
            return Err(format!(
                "{bad} samples of the brick's box are NaN or infinite, which become the \
                 volume's finite extremes (decision 0030); scan the ranges first (over \
                 NrrdSource::as_stored) and give NrrdSource::with_finite_range its finite range"
            ));
        };
        let (lo, hi) = (T::from_f64(f64::from(lo)), T::from_f64(f64::from(hi)));
        for v in region.iter_mut() {
            let x = v.to_f32();
            if x.is_nan() || x == f32::NEG_INFINITY {
                *v = lo;
            } else if x == f32::INFINITY {
                *v = hi;
            }
        }
        Ok(())
    }
}

impl<T: Scalar> BrickSource<T> for NrrdSource<T> {
    fn levels(&self) -> &[Grid] {
        &self.grids
    }

    fn layout(&self, level: usize) -> Option<&BrickLayout> {
        (level == 0).then_some(&self.layout)
    }

    /// Unknown without reading the file: always `None`.
    fn brick_range(&self, _key: BrickKey) -> Option<[f32; 2]> {
        None
    }

    fn brick(&self, key: BrickKey) -> volsplat_core::Result<Arc<Brick<T>>> {
        let (region, lo, dims) = self.halo_box(key)?;
        Brick::from_region(&self.layout, key, &region, lo, dims).map(Arc::new)
    }

    /// [`BrickSource::brick`]'s slot written into `slot` (the halo box read, then copied in).
    fn read_slot(&self, key: BrickKey, slot: &mut [T]) -> volsplat_core::Result<()> {
        let (region, lo, dims) = self.halo_box(key)?;
        volsplat_core::source::fill_slot(&self.layout, key, &region, lo, dims, slot)
    }
}

impl<T: Scalar> NrrdSource<T> {
    /// Brick `key`'s halo box ([`BrickLayout::halo_voxels`]) read from the file, non-finite
    /// floats replaced, with its first voxel and size.
    fn halo_box(&self, key: BrickKey) -> volsplat_core::Result<(Vec<T>, [usize; 3], [usize; 3])> {
        let halo = self.layout.halo_voxels(key)?;
        let lo = halo.clone().map(|r| r.start);
        let dims = halo.map(|r| r.len());
        let mut region = self
            .read_box(lo, dims)
            .map_err(|e| key.error(e.to_string()))?;
        self.replace_non_finite(&mut region)
            .map_err(|cause| key.error(format!("{}: {cause}", self.file.path.display())))?;
        Ok((region, lo, dims))
    }
}

/// Fills `buf` from `file` at byte `pos`, without moving a shared cursor (bricks are read in
/// parallel from one open file).
#[cfg(unix)]
fn read_exact_at(file: &File, buf: &mut [u8], pos: u64) -> std::io::Result<()> {
    std::os::unix::fs::FileExt::read_exact_at(file, buf, pos)
}

/// Fills `buf` from `file` at byte `pos` (`seek_read` moves the cursor, which no other read
/// here relies on).
#[cfg(windows)]
fn read_exact_at(file: &File, mut buf: &mut [u8], mut pos: u64) -> std::io::Result<()> {
    use std::os::windows::fs::FileExt;
    while !buf.is_empty() {
        match file.seek_read(buf, pos) {
            Ok(0) => return Err(std::io::ErrorKind::UnexpectedEof.into()),
            Ok(n) => {
                buf = &mut buf[n..];
                pos += n as u64;
            }
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(())
}

/// The samples of `bytes` (the file's type and byte order) as `T`, converted as the whole-file
/// reader converts them (`crate::payload::decode`): `int32`, `uint32` and `double` to `f32`
/// (`as`), a finite `double` beyond the `f32` range an error naming the file. `T` is the
/// header's scalar type ([`NrrdHeader::source`] checks it).
fn decode<T: Scalar>(bytes: &[u8], ft: FileType, big_endian: bool, path: &Path) -> Result<Vec<T>> {
    macro_rules! conv {
        ($t:ty, $n:literal, $to:expr) => {
            bytes
                .chunks_exact($n)
                .map(|c| {
                    let mut a = [0u8; $n];
                    a.copy_from_slice(c);
                    let x = if big_endian {
                        <$t>::from_be_bytes(a)
                    } else {
                        <$t>::from_le_bytes(a)
                    };
                    $to(x)
                })
                .collect::<Result<Vec<T>>>()
        };
    }
    // Exact: every value of the file's type is a value of T (checked by `source`).
    let ok = |x: f64| Ok(T::from_f64(x));
    match ft {
        FileType::U8 => bytes.iter().map(|&b| ok(f64::from(b))).collect(),
        FileType::I8 => bytes.iter().map(|&b| ok(f64::from(b as i8))).collect(),
        FileType::U16 => conv!(u16, 2, |x: u16| ok(f64::from(x))),
        FileType::I16 => conv!(i16, 2, |x: i16| ok(f64::from(x))),
        FileType::F32 => conv!(f32, 4, |x: f32| ok(f64::from(x))),
        // i32 → f64 is exact, so f64 → f32 rounds once, as `i32 as f32`.
        FileType::I32 => conv!(i32, 4, |x: i32| ok(f64::from(x))),
        FileType::U32 => conv!(u32, 4, |x: u32| ok(f64::from(x))),
        FileType::F64 => conv!(f64, 8, |x: f64| {
            if x.is_finite() && !(x as f32).is_finite() {
                return Err(IoError::core(
                    path,
                    volsplat_core::CoreError::invalid("sample", x, "outside the float32 range"),
                ));
            }
            ok(x)
        }),
    }
}

#[cfg(test)]
mod tests;
