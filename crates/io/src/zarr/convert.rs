//! `convert IN -o OUT.zarr`: a volume file to an OME-Zarr pyramid ([`convert_to_zarr`]),
//! streamed slice by slice from uncompressed raw and NRRD files (memory bounded by about a
//! chunk's height of slices per level, whatever the file's size), whole from other formats.

use super::write::{
    WrittenZarr, ZarrWriteOptions, in_temp_dir, prepare, pyramid_grids, write_levels,
};
use crate::error::{IoError, Result};
use crate::payload::RawSlices;
use crate::raw::RawSpec;
use crate::read::{LoadedVolume, ReadOptions, VolumeFormat};
use std::path::Path;
use volsplat_core::{AnyVolume, Grid, Scalar, ScalarType};
use zarrs::array::Element;

/// What [`convert_to_zarr`] read and wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct ConvertedZarr {
    /// The pyramid written.
    pub written: WrittenZarr,
    /// The input's format as read (`NRRD`, `raw`, `NIfTI-1`, …).
    pub format: String,
    /// The samples' type as read.
    pub scalar_type: ScalarType,
    /// Whether the input was streamed slice by slice (uncompressed raw and NRRD files), rather
    /// than read whole.
    pub streamed: bool,
    /// The reader's notes, then the writer's.
    pub notes: Vec<String>,
}

/// Converts the volume file `input` (a headerless raw file when `raw` is given) to an
/// OME-Zarr pyramid at `out`, as [`super::write_zarr`] writes it from the whole volume (the
/// same bits). Uncompressed raw and NRRD files are **streamed**: one z slice is read at a
/// time and each level keeps about a chunk's height of slices (float files are read twice:
/// first to check that no sample is NaN or infinite, which a whole read would replace with
/// the volume's extremes; a file with such samples is read whole, with a note). Other
/// formats, gzip-compressed files and files whose options do not apply are read whole with
/// [`crate::read_volume_with`] ([`crate::read_raw_with`]). The output is checked
/// ([`super::check_zarr_output`]) before the input's samples are read.
pub fn convert_to_zarr(
    input: impl AsRef<Path>,
    raw: Option<&RawSpec>,
    read: &ReadOptions,
    out: impl AsRef<Path>,
    options: &ZarrWriteOptions,
) -> Result<ConvertedZarr> {
    let (input, out) = (input.as_ref(), out.as_ref());
    if let Some((slices, grid, notes, format)) = open_slices(input, raw, read)? {
        let (aligned, mut more) = prepare(out, &grid, options)?;
        // The float check reads the file once more, from a fresh reader.
        let again = open_slices(input, raw, read)?;
        let non_finite = match again {
            Some((s, ..)) => s.count_non_finite().unwrap_or(1),
            None => 1,
        };
        if non_finite == 0 {
            let grids = pyramid_grids(&aligned, options.chunk);
            let scalar_type = stream(out, slices, &grids, options)?;
            let mut all = notes;
            all.append(&mut more);
            return Ok(ConvertedZarr {
                written: WrittenZarr {
                    levels: grids,
                    notes: more,
                },
                format: format.into(),
                scalar_type,
                streamed: true,
                notes: all,
            });
        }
    }
    let loaded: LoadedVolume = match raw {
        Some(spec) => crate::read_raw_with(input, spec, read)?,
        None => crate::read_volume_with(input, read)?,
    };
    let written = super::write_zarr(out, &loaded.volume, options)?;
    let mut notes = loaded.notes;
    notes.extend(written.notes.iter().cloned());
    Ok(ConvertedZarr {
        written,
        format: loaded.format,
        scalar_type: loaded.volume.scalar_type(),
        streamed: false,
        notes,
    })
}

type Opened = (RawSlices, Grid, Vec<String>, &'static str);

/// A slice reader for an uncompressed raw or NRRD file; `None` for anything else.
fn open_slices(input: &Path, raw: Option<&RawSpec>, read: &ReadOptions) -> Result<Option<Opened>> {
    Ok(match raw {
        Some(spec) => {
            crate::raw::raw_slices(input, spec, read)?.map(|(s, g)| (s, g, Vec::new(), "raw"))
        }
        None if !input.is_dir() && VolumeFormat::from_path(input) == Some(VolumeFormat::Nrrd) => {
            crate::nrrd::nrrd_slices(input, read)?.map(|(s, g, n)| (s, g, n, "NRRD"))
        }
        None => None,
    })
}

/// Streams `slices` into the pyramid `grids` at `out`; returns the samples' type.
fn stream(
    out: &Path,
    mut slices: RawSlices,
    grids: &[Grid],
    options: &ZarrWriteOptions,
) -> Result<ScalarType> {
    let first = slices.next_slice()?;
    let t = first.scalar_type();
    macro_rules! typed {
        ($ty:ty, $variant:ident) => {
            typed::<$ty>(out, first, slices, grids, options, |v| match v {
                AnyVolume::$variant(v) => Some(v.into_data()),
                _ => None,
            })
        };
    }
    match t {
        ScalarType::U8 => typed!(u8, U8),
        ScalarType::I8 => typed!(i8, I8),
        ScalarType::U16 => typed!(u16, U16),
        ScalarType::I16 => typed!(i16, I16),
        ScalarType::F32 => typed!(f32, F32),
    }?;
    Ok(t)
}

fn typed<T: Scalar + Element>(
    out: &Path,
    first: AnyVolume,
    mut slices: RawSlices,
    grids: &[Grid],
    options: &ZarrWriteOptions,
    take: fn(AnyVolume) -> Option<Vec<T>>,
) -> Result<()> {
    let mut first = Some(first);
    in_temp_dir(out, |tmp| {
        write_levels(out, tmp, grids, options, &mut |_| {
            let v = match first.take() {
                Some(v) => v,
                None => slices.next_slice()?,
            };
            take(v).ok_or_else(|| {
                IoError::invalid_argument(out, "slice", "a slice changed sample type")
            })
        })
    })
}
