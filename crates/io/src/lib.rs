//! # volsplat-io
//!
//! Readers and writers for volsplat: volumes in, images and scene files out. Every function
//! returns a typed [`IoError`] naming the file, the header field and the offending value; no
//! function panics on file contents, prints, or exits.
//!
//! ## Volumes (world space as in docs/design.md §3: VTK's, in the file's units, usually mm)
//!
//! Anatomical files are returned in **LPS** (DICOM/ITK's patient frame): NIfTI (always RAS) and
//! NRRD `space: right-anterior-superior` / `left-anterior-superior` are converted by negating the
//! world axes that differ (decision 0008). Files without an anatomical frame (VTK, TIFF,
//! MetaImage, NRRD without `space`) keep their coordinates as written.
//!
//! - [`read_volume`] / [`read_volume_with`] (with [`ReadOptions`]: [`Limits`], `frame`,
//!   `array`, `series`; returns a [`LoadedVolume`] with format, frame count, DICOM series and
//!   notes): dispatch by file name ([`VolumeFormat`], [`VOLUME_EXTENSIONS`]); a folder of `.tif`
//!   files is a stack, a folder of DICOM files a series.
//! - [`volume_info`] / [`VolumeInfo`]: a serialisable summary of a volume file (`info --json`).
//! - [`read_nrrd`]: NRRD with attached or detached header; raw, gzip or ascii encoding;
//!   `space directions` / `space origin` geometry, RAS/LAS spaces converted to LPS. See [`nrrd`].
//! - [`read_metaimage`]: MetaImage `.mha` / `.mhd`, raw or zlib-compressed. See [`metaimage`].
//! - [`read_nifti`]: NIfTI-1 and NIfTI-2 (`.nii`, `.nii.gz`, `.hdr`/`.img`): sform, qform or
//!   pixdim geometry, `scl_slope`/`scl_inter`, 4-D frames. See [`nifti`].
//! - [`read_vti`]: VTK XML image data (ascii, base64, appended raw/base64, zlib). See [`vti`].
//! - [`read_tiff`], [`read_tiff_dir`]: multi-page TIFF or a folder of slices; ImageJ / OME
//!   spacing. See [`tiff_stack`].
//! - [`read_dicom_with`] (also [`read_dicom`], [`read_dicom_files`]): DICOM series from a
//!   folder, a list of files or one file of the series; sorted by ImagePositionPatient along the
//!   slice normal, rescaled, enhanced multi-frame, uncompressed/deflate/RLE/JPEG transfer
//!   syntaxes; [`list_dicom_series`] lists a folder's series ([`DicomSeries`]). See [`dicom`].
//! - [`read_raw`] with a [`RawSpec`]: headerless raw files, optionally `.gz`.
//! - [`read_zarr_with`], [`ZarrStore`]: OME-Zarr v0.4 (Zarr v2) and v0.5 (Zarr v3) stores,
//!   any level (`level`), channel and time point ([`ReadOptions`]); [`ZarrStore::read_region`]
//!   reads a box of a level. See [`zarr`].
//!
//! Writers (each atomic; geometry in the file's own frame, converted from LPS where it differs):
//!
//! - [`write_volume`] with [`VolumeWriteOptions`]: dispatch by file name
//!   ([`VolumeWriteFormat`], [`VOLUME_WRITE_EXTENSIONS`]: `.nrrd`, `.nii`, `.nii.gz`, `.mha`,
//!   `.mhd`, `.npy`); [`volume_write_format`] checks an output name before a slow read.
//! - [`write_nrrd`]: attached-header NRRD (raw or gzip), `space: left-posterior-superior`, that
//!   round-trips the grid exactly.
//! - [`write_nifti`]: single-file NIfTI-1 (`.nii`, `.nii.gz`), sform and qform (code 1) in RAS,
//!   geometry rounded to float32.
//! - [`write_metaimage`]: MetaImage `.mha`, or `.mhd` with a `.raw`/`.zraw` data file, as ITK
//!   writes it (LPS, `AnatomicalOrientation`), exact.
//! - [`write_npy_volume`]: the samples only, shape (z, y, x).
//! - [`write_zarr`] with [`ZarrWriteOptions`]: an OME-Zarr pyramid (v0.4 on Zarr v2, or v0.5
//!   on Zarr v3), levels filtered as the renderer's own pyramid; written into a temporary
//!   folder and renamed.
//!
//! Each volume reader has a `*_with` form of one shape, `read_*_with(path, &ReadOptions) ->
//! LoadedVolume` ([`read_raw_with`] takes its [`RawSpec`] before the options; decision 0034),
//! that refuses the options its format cannot honour.
//!
//! ## Images (premultiplied linear RGBA `f32`, row 0 at the top)
//!
//! - [`write_png`] with [`PngSettings`]: composited over a background, 8- or 16-bit, sRGB-encoded
//!   (default) or linear.
//! - [`write_png_gray`]: a [`volsplat_core::ScalarImage`] windowed to black…white.
//! - [`encode_png`], [`encode_png_gray`]: the same files' bytes in memory (a server sends them).
//! - [`write_npy_rgba`], [`write_npy_scalar`], [`read_npy_f32`]: float `.npy` (`'<f4'`).
//!
//! ## Scene files (JSON, docs/design.md §3)
//!
//! - [`load_camera`], [`save_camera`]; [`load_transfer_function`], [`save_transfer_function`].
//!   Unknown fields come back as warnings; `//` comments are allowed.
//!
//! ## Limits against untrusted input ([`Limits`]; the defaults below)
//!
//! - Text headers (NRRD, MetaImage, `.npy`) at most [`MAX_HEADER_BYTES`] (1 MiB).
//! - Voxel (element) counts at most [`volsplat_core::volume::MAX_VOXELS`], computed with checked
//!   arithmetic from the header before anything is allocated; raw payloads are checked against
//!   the file size before allocating; compressed payloads grow with the data actually decoded
//!   and are never inflated past the needed size plus one byte.
//! - JSON files at most [`MAX_JSON_BYTES`] (16 MiB); VTK XML files at most 4 GiB; a DICOM file
//!   at most 4 bytes per voxel of the voxel limit plus 64 MiB, its structure checked (every
//!   declared length within the file, sequences at most 32 deep) before dicom-rs parses it.
//! - Data and header files must be regular files: devices (`/dev/zero`), FIFOs and sockets are
//!   refused, and line skipping stops at the end of the file as found.
//! - [`Limits::confine_to`] (none by default): a volume file inside that folder may open only
//!   files inside it (its data file, `.img`, slices), after resolving `..` and links; else
//!   [`IoError::OutsideFolder`]. A viewer serving a folder sets it (decision 0033).
//! - Camera and transfer-function floats reload bit-exactly (`serde_json`'s `float_roundtrip`).
//!
//! ## Writing
//!
//! Every writer is atomic: it writes a temporary file in the target's directory and renames it
//! over the target; on error the temporary file is removed and an existing target is untouched.
#![deny(missing_docs)]

mod atomic;
mod confine;
pub mod dicom;
pub mod error;
mod frame;
mod header;
mod image;
mod info;
mod json;
mod limits;
pub mod metaimage;
mod metaimage_write;
pub mod movie;
pub mod nifti;
mod npy;
pub mod nrrd;
mod payload;
mod raw;
mod read;
pub mod tiff_stack;
pub mod vti;
mod write;
pub mod zarr;

pub use atomic::write_bytes_atomic;
pub use dicom::{
    DicomSeries, is_dicom_file, list_dicom_series, read_dicom, read_dicom_files, read_dicom_with,
};
pub use error::{IoError, Result};
pub use header::MAX_HEADER_BYTES;
pub use image::{
    PngBitDepth, PngSettings, encode_png, encode_png_gray, rgb_codes, srgb_encode, write_png,
    write_png_gray,
};
pub use info::{LevelInfo, VOLUME_INFO_SCHEMA, VolumeInfo, volume_info};
pub use json::{
    CAMERA_FIELDS, MAX_JSON_BYTES, load_camera, load_camera_with, load_transfer_function,
    load_transfer_function_named, load_transfer_function_with, save_camera, save_transfer_function,
};
pub use limits::Limits;
pub use metaimage::{read_metaimage, read_metaimage_with};
pub use metaimage_write::write_metaimage;
pub use movie::{MovieFormat, MovieSettings, MovieWriter};
pub use nifti::{read_nifti, read_nifti_with, write_nifti};
pub use npy::{
    read_npy_f32, read_npy_f32_with, write_npy_rgba, write_npy_scalar, write_npy_volume,
};
pub use nrrd::{read_nrrd, read_nrrd_with, write_nrrd};
pub use raw::{RawSpec, read_raw, read_raw_with};
pub use read::{
    LoadedVolume, ReadOptions, VOLUME_EXTENSIONS, VolumeFormat, read_volume, read_volume_with,
};
pub use tiff_stack::{read_tiff, read_tiff_dir, read_tiff_with};
pub use vti::{read_vti, read_vti_with};
pub use write::{
    VOLUME_WRITE_EXTENSIONS, VolumeWriteFormat, VolumeWriteOptions, WrittenVolume,
    volume_write_format, write_volume,
};
pub use zarr::{
    ConvertedZarr, WrittenZarr, ZarrLevel, ZarrSelection, ZarrSource, ZarrStore, ZarrVersion,
    ZarrWriteOptions, convert_to_zarr, read_zarr_with, write_zarr,
};

#[cfg(test)]
mod test_volumes;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unknown_extension_lists_supported() {
        let e = read_volume("/tmp/does-not-matter.xyz").unwrap_err();
        let s = e.to_string();
        assert!(
            s.contains("\"xyz\"") && s.contains(".nrrd") && s.contains(".mha"),
            "{s}"
        );
        let e = read_volume("/tmp/noext").unwrap_err();
        assert!(matches!(e, IoError::UnsupportedFormat { .. }), "{e}");
    }
}
