//! Caps on what the readers accept from a file ([`Limits`]), and the checked size arithmetic
//! every reader uses before allocating.

use crate::error::{IoError, Result};
use std::path::Path;
use volsplat_core::volume::MAX_VOXELS;

/// Limits against untrusted input, checked from headers before anything is allocated (as
/// image-rs's `Limits`). [`Limits::default`] holds the crate's historical constants; a caller
/// (the CLI's one flag, say) may raise or lower them.
///
/// Other crates build it from [`Limits::default`] with the `with_*` methods (the struct is
/// `#[non_exhaustive]`: a new limit is not a breaking change); its fields can be read and set.
///
/// ```
/// // At most 512³ voxels, other limits as by default.
/// let small = volsplat_io::Limits::default().with_max_voxels(512 * 512 * 512);
/// assert_eq!(small.voxel_limit(), 1 << 27);
/// ```
#[derive(Debug, Clone, PartialEq, Eq)]
#[non_exhaustive]
pub struct Limits {
    /// Largest text header (NRRD, MetaImage, `.npy`, VTK XML document) accepted, in bytes.
    /// Default [`crate::MAX_HEADER_BYTES`] (1 MiB); VTK XML files with inline data use
    /// [`Limits::max_xml_bytes`] instead.
    pub max_header_bytes: usize,
    /// Largest number of voxels (samples of the one volume read), default
    /// [`volsplat_core::volume::MAX_VOXELS`] (2³⁴). Raising it above that constant has no effect:
    /// `volsplat_core::Grid` refuses larger grids.
    pub max_voxels: u128,
    /// Largest camera / transfer-function JSON file, in bytes; default [`crate::MAX_JSON_BYTES`]
    /// (16 MiB).
    pub max_json_bytes: u64,
    /// Largest VTK XML (`.vti`) file read into memory whole, in bytes; default 4 GiB.
    pub max_xml_bytes: u64,
    /// A folder whose volume files may open only files inside it (`None`, the default: no
    /// such folder). When the file (or folder) read lies inside it, every further file the
    /// reader opens for it must lie inside too, after resolving `..` and symbolic links: a
    /// detached header's data file (NRRD `data file`, MetaImage `ElementDataFile`), the `.img`
    /// of a NIfTI/Analyze `.hdr`, the slices of a TIFF folder; the file itself must not be a
    /// link out. Otherwise the read fails with [`crate::IoError::OutsideFolder`] naming the
    /// header, the field and its value. DICOM scans of a folder skip files that lead out of it
    /// (and say so in the notes). Files outside the folder are read as without it: the caller
    /// named them. A viewer that serves a folder to a page sets it to that folder
    /// (decision 0033).
    pub confine_to: Option<std::path::PathBuf>,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            max_header_bytes: crate::MAX_HEADER_BYTES,
            max_voxels: MAX_VOXELS,
            max_json_bytes: crate::MAX_JSON_BYTES,
            max_xml_bytes: 4 << 30,
            confine_to: None,
        }
    }
}

impl Limits {
    /// The effective voxel limit: `max_voxels`, but never above the core's [`MAX_VOXELS`].
    pub fn voxel_limit(&self) -> u128 {
        self.max_voxels.min(MAX_VOXELS)
    }

    /// These limits with [`Limits::max_header_bytes`] set (bytes).
    pub fn with_max_header_bytes(mut self, bytes: usize) -> Self {
        self.max_header_bytes = bytes;
        self
    }

    /// These limits with [`Limits::max_voxels`] set (samples; capped at
    /// [`volsplat_core::volume::MAX_VOXELS`] by [`Limits::voxel_limit`]).
    pub fn with_max_voxels(mut self, voxels: u128) -> Self {
        self.max_voxels = voxels;
        self
    }

    /// These limits with [`Limits::max_json_bytes`] set (bytes).
    pub fn with_max_json_bytes(mut self, bytes: u64) -> Self {
        self.max_json_bytes = bytes;
        self
    }

    /// These limits with [`Limits::max_xml_bytes`] set (bytes).
    pub fn with_max_xml_bytes(mut self, bytes: u64) -> Self {
        self.max_xml_bytes = bytes;
        self
    }

    /// These limits with reads confined to `folder` ([`Limits::confine_to`]; `None`: not
    /// confined).
    pub fn with_confine_to(mut self, folder: Option<std::path::PathBuf>) -> Self {
        self.confine_to = folder;
        self
    }
}

/// The product of `sizes` with checked arithmetic, compared with the voxel limit; errors name
/// `field` (as spelled in the file format) and its text `value`.
pub(crate) fn checked_voxel_count(
    path: &Path,
    field: &str,
    value: &str,
    sizes: &[u64],
    limits: &Limits,
) -> Result<u128> {
    let limit = limits.voxel_limit();
    let mut count: u128 = 1;
    for &s in sizes {
        count = match count.checked_mul(s as u128) {
            Some(c) => c,
            None => {
                return Err(IoError::TooLarge {
                    path: path.to_path_buf(),
                    what: format!(
                        "voxel count from field `{field}` ({}; the product overflows)",
                        crate::error::clip(value)
                    ),
                    value: u128::MAX,
                    limit,
                });
            }
        };
    }
    if count > limit {
        return Err(IoError::TooLarge {
            path: path.to_path_buf(),
            what: format!(
                "voxel count from field `{field}` ({})",
                crate::error::clip(value)
            ),
            value: count,
            limit,
        });
    }
    Ok(count)
}

/// Three sizes checked as [`checked_voxel_count`] and converted to `usize`.
pub(crate) fn checked_dims(
    path: &Path,
    field: &str,
    value: &str,
    sizes: [u64; 3],
    limits: &Limits,
) -> Result<[usize; 3]> {
    checked_voxel_count(path, field, value, &sizes, limits)?;
    let mut dims = [0usize; 3];
    for (d, &s) in dims.iter_mut().zip(&sizes) {
        *d = usize::try_from(s)
            .map_err(|_| IoError::field(path, field, value, "too large for this platform"))?;
    }
    Ok(dims)
}

/// Refuses anything but a regular file (or a symbolic link to one): reading a device such as
/// `/dev/zero`, a FIFO or a socket could block or never end. `what` says which file it is
/// (e.g. `data file`).
pub(crate) fn require_regular_file(path: &Path, what: &str) -> Result<()> {
    let meta = std::fs::metadata(path).map_err(|e| IoError::os(path, format!("open {what}"), e))?;
    if meta.is_file() {
        Ok(())
    } else {
        let kind = if meta.is_dir() {
            "a directory"
        } else {
            "a device, FIFO or socket"
        };
        Err(IoError::NotAFile {
            path: path.to_path_buf(),
            what: what.to_string(),
            kind,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn overflowing_products_are_errors_naming_the_field() {
        let p = Path::new("x.nrrd");
        let l = Limits::default();
        let big = 9223372036854775808u64;
        let e = checked_voxel_count(p, "sizes", "v", &[big, big, 4], &l).unwrap_err();
        let s = e.to_string();
        assert!(s.contains("`sizes`") && s.contains("overflows"), "{s}");
        let e = checked_voxel_count(p, "sizes", "v", &[u64::MAX, u64::MAX, u64::MAX], &l);
        assert!(e.is_err());
        assert_eq!(
            checked_voxel_count(p, "sizes", "v", &[2, 3, 4], &l).unwrap(),
            24
        );
        let small = Limits {
            max_voxels: 10,
            ..Limits::default()
        };
        let e = checked_voxel_count(p, "sizes", "v", &[2, 3, 4], &small).unwrap_err();
        assert!(e.to_string().contains("exceeds the limit 10"), "{e}");
    }

    /// Issue 30 item 4: `Limits` is `#[non_exhaustive]`; the `with_*` methods set each field
    /// and nothing else.
    #[test]
    fn builders_set_one_field_each() {
        let d = Limits::default();
        let l = d
            .clone()
            .with_max_header_bytes(10)
            .with_max_voxels(20)
            .with_max_json_bytes(30)
            .with_max_xml_bytes(40)
            .with_confine_to(Some("/data".into()));
        assert_eq!(
            l,
            Limits {
                max_header_bytes: 10,
                max_voxels: 20,
                max_json_bytes: 30,
                max_xml_bytes: 40,
                confine_to: Some("/data".into()),
            }
        );
        assert_eq!(
            d.clone().with_max_voxels(7).max_header_bytes,
            d.max_header_bytes
        );
        assert_eq!(l.with_confine_to(None).confine_to, None);
    }

    #[test]
    #[cfg(unix)]
    fn devices_and_directories_are_refused() {
        let e = require_regular_file(Path::new("/dev/zero"), "data file").unwrap_err();
        assert!(e.to_string().contains("/dev/zero"), "{e}");
        assert!(e.to_string().contains("not a regular file"), "{e}");
        let d = tempfile::tempdir().unwrap();
        let e = require_regular_file(d.path(), "data file").unwrap_err();
        assert!(e.to_string().contains("directory"), "{e}");
    }
}
