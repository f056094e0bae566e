//! # volsplat-io
//!
//! Readers and writers for volsplat: volumes in, images and scene files out. Every function
//! returns a typed [`IoError`] naming the file, the header field and the offending value; no
//! function panics on file contents, prints, or exits.
//!
//! ## Volumes (world space as in DESIGN.md §3: VTK's, in the file's units, usually mm)
//!
//! - [`read_volume`]: dispatch by extension: `.nrrd`, `.nhdr` → [`read_nrrd`]; `.mha`, `.mhd` →
//!   [`read_metaimage`].
//! - [`read_nrrd`]: NRRD with attached or detached header; raw, gzip or ascii encoding;
//!   `space directions` / `space origin` geometry (no LPS/RAS flip, as in VTK). See [`nrrd`].
//! - [`read_metaimage`]: MetaImage `.mha` / `.mhd`, raw or zlib-compressed. See [`metaimage`].
//! - [`read_raw`] with a [`RawSpec`]: headerless raw files, optionally `.gz`.
//! - [`write_nrrd`]: attached-header NRRD (raw or gzip) that round-trips the grid.
//!
//! ## Images (premultiplied linear RGBA `f32`, row 0 at the top)
//!
//! - [`write_png`] with [`PngSettings`]: composited over a background, 8- or 16-bit, sRGB-encoded
//!   (default) or linear.
//! - [`write_png_gray`]: a [`volsplat_core::ScalarImage`] windowed to black…white.
//! - [`write_npy_rgba`], [`write_npy_scalar`], [`read_npy_f32`]: float `.npy` (`'<f4'`).
//!
//! ## Scene files (JSON, DESIGN.md §3)
//!
//! - [`load_camera`], [`save_camera`]; [`load_transfer_function`], [`save_transfer_function`].
//!   Unknown fields come back as warnings; `//` comments are allowed.
//!
//! ## Limits against untrusted input
//!
//! - Text headers (NRRD, MetaImage, `.npy`) at most [`MAX_HEADER_BYTES`] (1 MiB).
//! - Voxel (element) counts at most [`volsplat_core::volume::MAX_VOXELS`], checked from the header
//!   before anything is allocated; raw payloads are checked against the file size before
//!   allocating; compressed payloads grow with the data actually decoded and are never inflated
//!   past the needed size plus one byte.
//! - JSON files at most [`MAX_JSON_BYTES`] (16 MiB).
//!
//! ## Writing
//!
//! Every writer is atomic: it writes a temporary file in the target's directory and renames it
//! over the target; on error the temporary file is removed and an existing target is untouched.
#![deny(missing_docs)]

mod atomic;
pub mod error;
mod header;
mod image;
mod json;
pub mod metaimage;
mod npy;
pub mod nrrd;
mod payload;
mod raw;

pub use atomic::write_bytes_atomic;
pub use error::{IoError, Result};
pub use header::MAX_HEADER_BYTES;
pub use image::{PngBitDepth, PngSettings, srgb_encode, write_png, write_png_gray};
pub use json::{
    CAMERA_FIELDS, MAX_JSON_BYTES, load_camera, load_transfer_function, save_camera,
    save_transfer_function,
};
pub use metaimage::read_metaimage;
pub use npy::{read_npy_f32, write_npy_rgba, write_npy_scalar};
pub use nrrd::{read_nrrd, write_nrrd};
pub use raw::{RawSpec, read_raw};

use std::path::Path;
use volsplat_core::AnyVolume;

/// The volume file extensions [`read_volume`] understands.
pub const VOLUME_EXTENSIONS: &[&str] = &["nrrd", "nhdr", "mha", "mhd"];

/// Reads a volume, choosing the format by the file extension (case-insensitive): `.nrrd` and
/// `.nhdr` ([`read_nrrd`]), `.mha` and `.mhd` ([`read_metaimage`]). Headerless raw files need a
/// [`RawSpec`]: use [`read_raw`]. Any other extension is an error listing the supported ones.
pub fn read_volume(path: impl AsRef<Path>) -> Result<AnyVolume> {
    let path = path.as_ref();
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    match ext.as_str() {
        "nrrd" | "nhdr" => read_nrrd(path),
        "mha" | "mhd" => read_metaimage(path),
        _ => Err(IoError::UnsupportedFormat {
            path: path.to_path_buf(),
            extension: ext,
            supported: ".nrrd, .nhdr, .mha, .mhd (headerless raw: use read_raw with a RawSpec)"
                .into(),
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unknown_extension_lists_supported() {
        let e = read_volume("/tmp/does-not-matter.vti").unwrap_err();
        let s = e.to_string();
        assert!(
            s.contains("\"vti\"") && s.contains(".nrrd") && s.contains(".mha"),
            "{s}"
        );
        let e = read_volume("/tmp/noext").unwrap_err();
        assert!(matches!(e, IoError::UnsupportedFormat { .. }), "{e}");
    }
}
