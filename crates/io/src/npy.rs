//! NumPy `.npy` files of 32-bit floats (format version 1.0 written; 1.0–3.0 read).
//!
//! Written files hold little-endian `'<f4'` data in C order with a header padded (with spaces
//! and a final newline) so that the data start at a multiple of 64 bytes.

use crate::atomic::{write_atomic, write_err};
use crate::error::{IoError, Result};
use std::fs::File;
use std::io::{Read, Write};
use std::path::Path;
use volsplat_core::{Image, ScalarImage};

const MAGIC: &[u8; 6] = b"\x93NUMPY";

/// The version-1.0 header (magic, version, length, dictionary, padding) for `<f4` data of `shape`.
fn header(shape: &[usize]) -> Vec<u8> {
    header_typed(shape, "<f4")
}

/// The version-1.0 header for data of NumPy type `descr` (e.g. `|u1`, `<i2`, `<f4`) and `shape`.
fn header_typed(shape: &[usize], descr: &str) -> Vec<u8> {
    let dims: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
    let shape_str = if dims.len() == 1 {
        format!("({},)", dims[0])
    } else {
        format!("({})", dims.join(", "))
    };
    let dict = format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape_str}, }}");
    let unpadded = MAGIC.len() + 2 + 2 + dict.len() + 1;
    let pad = (64 - unpadded % 64) % 64;
    let header_len = dict.len() + pad + 1;
    let mut out = Vec::with_capacity(unpadded + pad);
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&[1, 0]);
    // A few dozen bytes: always fits the version-1.0 u16 length.
    out.extend_from_slice(&(header_len as u16).to_le_bytes());
    out.extend_from_slice(dict.as_bytes());
    out.resize(out.len() + pad, b' ');
    out.push(b'\n');
    out
}

fn write_f32s(path: &Path, shape: &[usize], values: impl Iterator<Item = f32>) -> Result<()> {
    let head = header(shape);
    write_atomic(path, |w| {
        w.write_all(&head).map_err(write_err(path))?;
        for v in values {
            w.write_all(&v.to_le_bytes()).map_err(write_err(path))?;
        }
        Ok(())
    })
}

/// Writes a premultiplied RGBA float image as `.npy`: `'<f4'`, shape `(height, width, 4)`, row 0
/// first (the top row), channels `r·a, g·a, b·a, a` unchanged. Written atomically.
pub fn write_npy_rgba(path: impl AsRef<Path>, image: &Image) -> Result<()> {
    write_f32s(
        path.as_ref(),
        &[image.height(), image.width(), 4],
        image.pixels().iter().flatten().copied(),
    )
}

/// Writes a volume's samples as `.npy` in their own type (`|u1`, `|i1`, `<u2`, `<i2`, `<f4`),
/// shape `(nz, ny, nx)` in C order — the (z, y, x) order of NumPy, SimpleITK and napari, with x
/// fastest as in the volume. The geometry (spacing, origin, direction) is not stored: `.npy`
/// has no place for it. Written atomically.
pub fn write_npy_volume(path: impl AsRef<Path>, volume: &volsplat_core::AnyVolume) -> Result<()> {
    use volsplat_core::AnyVolume as V;
    let path = path.as_ref();
    let [nx, ny, nz] = volume.grid().dims;
    let shape = [nz, ny, nx];
    let descr = match volume {
        V::U8(_) => "|u1",
        V::I8(_) => "|i1",
        V::U16(_) => "<u2",
        V::I16(_) => "<i2",
        V::F32(_) => "<f4",
    };
    let head = header_typed(&shape, descr);
    write_atomic(path, |w| {
        w.write_all(&head).map_err(write_err(path))?;
        let bytes: Vec<u8> = match volume {
            V::U8(v) => v.data().to_vec(),
            V::I8(v) => v.data().iter().map(|&x| x as u8).collect(),
            V::U16(v) => v.data().iter().flat_map(|x| x.to_le_bytes()).collect(),
            V::I16(v) => v.data().iter().flat_map(|x| x.to_le_bytes()).collect(),
            V::F32(v) => v.data().iter().flat_map(|x| x.to_le_bytes()).collect(),
        };
        w.write_all(&bytes).map_err(write_err(path))
    })
}

/// Writes a scalar image (e.g. X-ray line integrals, data units × world units) as `.npy`:
/// `'<f4'`, shape `(height, width)`, row 0 first. Written atomically.
pub fn write_npy_scalar(path: impl AsRef<Path>, image: &ScalarImage) -> Result<()> {
    write_f32s(
        path.as_ref(),
        &[image.height(), image.width()],
        image.values().iter().copied(),
    )
}

/// Reads a `.npy` file of 32-bit floats (`'<f4'` or `'>f4'`, C order, any shape): returns the
/// shape and the values in C order. The header is limited to [`crate::MAX_HEADER_BYTES`] and the
/// element count to [`volsplat_core::volume::MAX_VOXELS`]; the data size must match the shape exactly and is checked
/// against the file size before allocating.
pub fn read_npy_f32(path: impl AsRef<Path>) -> Result<(Vec<usize>, Vec<f32>)> {
    read_npy_f32_with(path, &crate::Limits::default())
}

/// [`read_npy_f32`] with caller-set [`crate::Limits`] (header bytes, element count).
pub fn read_npy_f32_with(
    path: impl AsRef<Path>,
    limits: &crate::Limits,
) -> Result<(Vec<usize>, Vec<f32>)> {
    let path = path.as_ref();
    let max_header = limits.max_header_bytes as u64;
    let max_count = limits.voxel_limit();
    crate::limits::require_regular_file(path, "npy file")?;
    let bad = |reason: String| IoError::Npy {
        path: path.to_path_buf(),
        reason,
    };
    let mut file = File::open(path).map_err(|e| IoError::os(path, "open", e))?;
    let file_len = file
        .metadata()
        .map_err(|e| IoError::os(path, "stat", e))?
        .len();
    let mut pre = [0u8; 8];
    file.read_exact(&mut pre)
        .map_err(|_| bad("file shorter than the 8-byte magic and version".into()))?;
    if &pre[..6] != MAGIC {
        return Err(bad("missing magic \\x93NUMPY".into()));
    }
    let (header_len, prefix) = match pre[6] {
        1 => {
            let mut l = [0u8; 2];
            file.read_exact(&mut l)
                .map_err(|_| bad("truncated header length".into()))?;
            (u16::from_le_bytes(l) as u64, 10u64)
        }
        2 | 3 => {
            let mut l = [0u8; 4];
            file.read_exact(&mut l)
                .map_err(|_| bad("truncated header length".into()))?;
            (u32::from_le_bytes(l) as u64, 12u64)
        }
        v => return Err(bad(format!("unsupported format version {v}.{}", pre[7]))),
    };
    if header_len > max_header {
        return Err(IoError::TooLarge {
            path: path.to_path_buf(),
            what: "npy header length".into(),
            value: header_len as u128,
            limit: max_header as u128,
        });
    }
    if prefix + header_len > file_len {
        return Err(IoError::Truncated {
            path: path.to_path_buf(),
            what: "npy header".into(),
            expected: header_len,
            actual: file_len.saturating_sub(prefix),
            unit: "bytes",
        });
    }
    let mut head = vec![0u8; header_len as usize];
    file.read_exact(&mut head)
        .map_err(|e| IoError::os(path, "read header", e))?;
    let dict = String::from_utf8_lossy(&head).into_owned();

    let descr = dict_value(&dict, "descr").ok_or_else(|| bad("no 'descr' in header".into()))?;
    let big_endian = match quoted(descr) {
        Some("<f4") => false,
        Some(">f4") => true,
        Some(other) => {
            return Err(bad(format!(
                "dtype '{other}' is not supported; only float32 ('<f4' or '>f4')"
            )));
        }
        None => return Err(bad("malformed 'descr' value".into())),
    };
    let fortran =
        dict_value(&dict, "fortran_order").ok_or_else(|| bad("no 'fortran_order'".into()))?;
    if fortran.starts_with("True") {
        return Err(bad("fortran_order True is not supported".into()));
    } else if !fortran.starts_with("False") {
        return Err(bad("malformed 'fortran_order' value".into()));
    }
    let shape_text = dict_value(&dict, "shape").ok_or_else(|| bad("no 'shape'".into()))?;
    let inner = shape_text
        .strip_prefix('(')
        .and_then(|t| t.find(')').map(|e| &t[..e]))
        .ok_or_else(|| bad("malformed 'shape' value".into()))?;
    let mut shape = Vec::new();
    for t in inner.split(',').map(str::trim).filter(|t| !t.is_empty()) {
        shape.push(
            t.parse::<usize>()
                .map_err(|_| bad(format!("shape entry `{t}` is not a whole number")))?,
        );
    }
    // Checked: the product of the shape can overflow even u128 (it used to, in the error path).
    let product = shape
        .iter()
        .try_fold(1u128, |acc, &d| acc.checked_mul(d as u128));
    let count = product
        .filter(|&c| c <= max_count)
        .ok_or_else(|| IoError::TooLarge {
            path: path.to_path_buf(),
            what: format!(
                "element count of shape {shape:?}{}",
                if product.is_none() {
                    " (the product overflows)"
                } else {
                    ""
                }
            ),
            value: product.unwrap_or(u128::MAX),
            limit: max_count,
        })?;
    let needed = (count * 4) as u64;
    let available = file_len - prefix - header_len;
    if available < needed {
        return Err(IoError::Truncated {
            path: path.to_path_buf(),
            what: "npy data".into(),
            expected: needed,
            actual: available,
            unit: "bytes",
        });
    }
    if available > needed {
        return Err(bad(format!(
            "{} bytes of trailing data after the {needed} bytes the shape needs",
            available - needed
        )));
    }
    let mut bytes = vec![0u8; needed as usize];
    file.read_exact(&mut bytes)
        .map_err(|e| IoError::os(path, "read data", e))?;
    let values = bytes
        .chunks_exact(4)
        .map(|c| {
            let a = [c[0], c[1], c[2], c[3]];
            if big_endian {
                f32::from_be_bytes(a)
            } else {
                f32::from_le_bytes(a)
            }
        })
        .collect();
    Ok((shape, values))
}

/// The text after `'key':` in a Python dict literal, with leading spaces removed.
fn dict_value<'a>(dict: &'a str, key: &str) -> Option<&'a str> {
    for q in ['\'', '"'] {
        let pat = format!("{q}{key}{q}");
        if let Some(i) = dict.find(&pat) {
            let rest = dict[i + pat.len()..].trim_start();
            return rest.strip_prefix(':').map(str::trim_start);
        }
    }
    None
}

/// The contents of a leading quoted string.
fn quoted(text: &str) -> Option<&str> {
    let q = text.chars().next().filter(|c| *c == '\'' || *c == '"')?;
    let rest = &text[1..];
    rest.find(q).map(|e| &rest[..e])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_is_padded_to_64_bytes() {
        for shape in [
            vec![3usize, 2, 4],
            vec![480, 640],
            vec![7],
            vec![123456, 654321, 4],
        ] {
            let h = header(&shape);
            assert_eq!(h.len() % 64, 0, "{shape:?}");
            assert_eq!(*h.last().unwrap(), b'\n');
            let len = u16::from_le_bytes([h[8], h[9]]) as usize;
            assert_eq!(len + 10, h.len());
        }
        let h = header(&[2, 3, 4]);
        let text = String::from_utf8_lossy(&h[10..]);
        assert!(text.starts_with("{'descr': '<f4', 'fortran_order': False, 'shape': (2, 3, 4), }"));
        assert_eq!(&h[..8], b"\x93NUMPY\x01\x00");
    }

    #[test]
    fn rgba_and_scalar_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let px: Vec<[f32; 4]> = (0..6)
            .map(|i| [i as f32 * 0.1, 0.5, -1.25, 1.0 / (i as f32 + 1.0)])
            .collect();
        let img = Image::from_pixels(3, 2, px.clone()).unwrap();
        let p = dir.path().join("img.npy");
        write_npy_rgba(&p, &img).unwrap();
        let (shape, vals) = read_npy_f32(&p).unwrap();
        assert_eq!(shape, vec![2, 3, 4]);
        assert_eq!(vals, px.iter().flatten().copied().collect::<Vec<_>>());
        let raw = std::fs::read(&p).unwrap();
        // numpy pads this header to 128 bytes too.
        assert_eq!(raw.len(), 128 + 6 * 4 * 4);

        let s = ScalarImage::from_values(2, 3, vec![1.0, 2.0, 3.0, 4.0, 5.0, 1e30]).unwrap();
        let p = dir.path().join("s.npy");
        write_npy_scalar(&p, &s).unwrap();
        let (shape, vals) = read_npy_f32(&p).unwrap();
        assert_eq!(shape, vec![3, 2]);
        assert_eq!(vals, s.values());
        let raw = std::fs::read(&p).unwrap();
        assert_eq!(raw.len(), 128 + 6 * 4);
        let head = String::from_utf8_lossy(&raw[10..128]);
        assert!(head.starts_with("{'descr': '<f4', 'fortran_order': False, 'shape': (3, 2), }"));
        assert!(head.ends_with(" \n"));
    }

    /// Fuzzing regression: a shape whose product overflows u128 panicked (in debug builds)
    /// while building the error message.
    #[test]
    fn overflowing_shapes_are_an_error() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("o.npy");
        let m = usize::MAX;
        for shape in [
            vec![m, m, m],
            vec![1 << 63, 1 << 63, 4],
            vec![100_000, 100_000, 100_000],
        ] {
            let mut bytes = header(&shape);
            bytes.extend_from_slice(&[0; 16]);
            std::fs::write(&p, &bytes).unwrap();
            let e = read_npy_f32(&p).unwrap_err().to_string();
            assert!(
                e.contains("exceeds the limit") && e.contains("o.npy"),
                "{e}"
            );
        }
        let mut bytes = header(&[2, 2]);
        bytes.extend_from_slice(&[0; 16]);
        std::fs::write(&p, &bytes).unwrap();
        assert!(read_npy_f32(&p).is_ok());
        let small = crate::Limits {
            max_voxels: 3,
            ..crate::Limits::default()
        };
        let e = read_npy_f32_with(&p, &small).unwrap_err().to_string();
        assert!(e.contains("exceeds the limit 3"), "{e}");
    }

    #[test]
    fn reader_rejects_bad_files() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("x.npy");
        let s = ScalarImage::from_values(2, 2, vec![1.0; 4]).unwrap();
        write_npy_scalar(&p, &s).unwrap();
        let good = std::fs::read(&p).unwrap();

        std::fs::write(&p, &good[..good.len() - 3]).unwrap();
        let e = read_npy_f32(&p).unwrap_err();
        assert!(
            matches!(
                e,
                IoError::Truncated {
                    expected: 16,
                    actual: 13,
                    ..
                }
            ),
            "{e}"
        );

        let mut long = good.clone();
        long.push(0);
        std::fs::write(&p, &long).unwrap();
        assert!(
            read_npy_f32(&p)
                .unwrap_err()
                .to_string()
                .contains("trailing")
        );

        let mut f8b = good.clone();
        let at = f8b.windows(3).position(|w| w == b"<f4").unwrap();
        f8b[at + 2] = b'8';
        std::fs::write(&p, &f8b).unwrap();
        assert!(read_npy_f32(&p).unwrap_err().to_string().contains("<f8"));

        std::fs::write(&p, b"\x93NUMP").unwrap();
        assert!(read_npy_f32(&p).is_err());
        std::fs::write(&p, b"PK\x03\x04 not numpy at all").unwrap();
        assert!(read_npy_f32(&p).unwrap_err().to_string().contains("magic"));

        // A shape that would need far more memory than the file holds.
        let h = header(&[99_999_999_999, 9_999]);
        let mut file = h;
        file.extend_from_slice(&[0; 16]);
        std::fs::write(&p, &file).unwrap();
        let e = read_npy_f32(&p).unwrap_err();
        assert!(matches!(e, IoError::TooLarge { .. }), "{e}");
        let mut file = header(&[1000, 1000]);
        file.extend_from_slice(&[0; 16]);
        std::fs::write(&p, &file).unwrap();
        let e = read_npy_f32(&p).unwrap_err();
        assert!(matches!(e, IoError::Truncated { .. }), "{e}");
    }

    /// Volumes are written in their own type, shape (z, y, x), x fastest: an f32 volume reads
    /// back through the reader; an i16 volume's bytes follow its header.
    #[test]
    fn volumes_are_written_zyx_in_their_own_type() {
        use volsplat_core::{AnyVolume, Grid, Volume};
        let dir = tempfile::tempdir().unwrap();
        let grid = Grid::with_dims([3, 2, 4]).unwrap();
        let f: Vec<f32> = (0..24).map(|i| i as f32 * 0.5).collect();
        let p = dir.path().join("f.npy");
        write_npy_volume(
            &p,
            &AnyVolume::F32(Volume::new(grid.clone(), f.clone()).unwrap()),
        )
        .unwrap();
        let (shape, values) = read_npy_f32(&p).unwrap();
        assert_eq!(shape, vec![4, 2, 3]);
        assert_eq!(values, f);
        let i: Vec<i16> = (0..24).map(|v| v as i16 * -7).collect();
        let p = dir.path().join("i.npy");
        write_npy_volume(&p, &AnyVolume::I16(Volume::new(grid, i.clone()).unwrap())).unwrap();
        let bytes = std::fs::read(&p).unwrap();
        let start = 10 + u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
        assert_eq!(start % 64, 0);
        let text = String::from_utf8_lossy(&bytes[..start]).to_string();
        assert!(
            text.contains("'<i2'") && text.contains("(4, 2, 3)"),
            "{text}"
        );
        assert_eq!(bytes.len(), start + 48);
        let back: Vec<i16> = bytes[start..]
            .chunks(2)
            .map(|c| i16::from_le_bytes([c[0], c[1]]))
            .collect();
        assert_eq!(back, i);
    }
}
