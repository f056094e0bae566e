//! Writing MetaImage volumes: [`write_metaimage`] (`.mha` with the samples attached, `.mhd`
//! with a detached `.raw` or `.zraw` data file), as ITK's `MetaImageIO` writes them.

use crate::atomic::{write_atomic, write_atomic_pair, write_err};
use crate::error::{IoError, Result};
use crate::nifti::has_suffix;
use crate::payload::write_samples_le;
use std::io::Write;
use std::path::{Path, PathBuf};
use volsplat_core::glam::DMat3;
use volsplat_core::{AnyVolume, Grid, ScalarType};

/// Writes `volume` as MetaImage, choosing the layout by the file name: `.mha` keeps the samples
/// after the header (`ElementDataFile = LOCAL`); `.mhd` writes them to a data file beside it,
/// `NAME.raw`, or `NAME.zraw` when `compress` (the header names it relative to its folder).
/// Returns the files written (the header first). Both files of a pair are written atomically:
/// neither changes unless both were written whole.
///
/// - `ObjectType = Image`, `NDims = 3`, `BinaryData = True`, `BinaryDataByteOrderMSB = False`
///   (little-endian samples, i fastest), `CompressedData` (a zlib stream when `compress`, with
///   its `CompressedDataSize`).
/// - Geometry in volsplat's world frame, LPS (docs/design.md §3), which is ITK's: `Offset` the world
///   position of voxel (0,0,0); `ElementSpacing` the spacing; `TransformMatrix` the direction,
///   its consecutive triples the world directions of the i, j and k axes (ITK's order, as the
///   reader takes them); `AnatomicalOrientation` the three letters ITK derives from the
///   direction (`RAI` for the identity: i runs from right to left, j from anterior to
///   posterior, k from inferior to superior). Numbers are written in shortest round-trip form,
///   so the grid reads back exactly.
/// - `ElementType`: `MET_UCHAR`, `MET_CHAR`, `MET_USHORT`, `MET_SHORT` or `MET_FLOAT`.
///
/// A path ending neither in `.mha` nor `.mhd` is an [`IoError::UnsupportedFormat`].
pub fn write_metaimage(
    path: impl AsRef<Path>,
    volume: &AnyVolume,
    compress: bool,
) -> Result<Vec<PathBuf>> {
    let path = path.as_ref();
    let detached = if has_suffix(path, ".mhd") {
        true
    } else if has_suffix(path, ".mha") {
        false
    } else {
        return Err(IoError::UnsupportedFormat {
            path: path.to_path_buf(),
            extension: path
                .extension()
                .map(|e| e.to_string_lossy().to_ascii_lowercase())
                .unwrap_or_default(),
            supported: ".mha, .mhd".into(),
        });
    };
    let samples = if compress {
        let mut enc = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
        write_samples_le(&mut enc, volume)
            .and_then(|_| enc.finish())
            .map_err(|e| IoError::os(path, "compress samples", e))
            .map(Some)?
    } else {
        None
    };
    let data_path = detached.then(|| data_file(path, compress));
    let data_name = data_path
        .as_ref()
        .and_then(|p| p.file_name())
        .map(|n| n.to_string_lossy().into_owned());
    let header = header_text(
        volume.grid(),
        volume.scalar_type(),
        samples.as_ref().map(Vec::len),
        data_name.as_deref().unwrap_or("LOCAL"),
    );
    let write_data = |w: &mut dyn Write, at: &Path| -> Result<()> {
        match &samples {
            Some(z) => w.write_all(z).map_err(write_err(at)),
            None => write_samples_le(w, volume).map_err(write_err(at)),
        }
    };
    match &data_path {
        None => {
            write_atomic(path, |w| {
                w.write_all(header.as_bytes()).map_err(write_err(path))?;
                write_data(w, path)
            })?;
            Ok(vec![path.to_path_buf()])
        }
        Some(data) => {
            write_atomic_pair(
                data,
                |w| write_data(w, data),
                path,
                |w| w.write_all(header.as_bytes()).map_err(write_err(path)),
            )?;
            Ok(vec![path.to_path_buf(), data.clone()])
        }
    }
}

/// The data file of a `.mhd` header: the same name with `.raw` (`.zraw` when compressed).
fn data_file(header: &Path, compress: bool) -> PathBuf {
    header.with_extension(if compress { "zraw" } else { "raw" })
}

fn element_type(t: ScalarType) -> &'static str {
    match t {
        ScalarType::U8 => "MET_UCHAR",
        ScalarType::I8 => "MET_CHAR",
        ScalarType::U16 => "MET_USHORT",
        ScalarType::I16 => "MET_SHORT",
        ScalarType::F32 => "MET_FLOAT",
    }
}

/// ITK's three-letter orientation of a direction matrix (LPS world): for each grid axis, the
/// side it comes *from* along the world axis it is closest to (`R`/`L` for x, `A`/`P` for y,
/// `I`/`S` for z), each world axis used once (axes taken in order of how clearly they point
/// along one world axis, as ITK's `SpatialOrientationAdapter::FromDirectionCosines`).
pub(crate) fn orientation_letters(direction: &DMat3) -> String {
    let cols = [direction.x_axis, direction.y_axis, direction.z_axis];
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| {
        cols[b]
            .abs()
            .max_element()
            .total_cmp(&cols[a].abs().max_element())
    });
    let mut used = [false; 3];
    let mut letters = ['?'; 3];
    for &c in &order {
        // The unused world axis it points along most (the first on a tie).
        let (m, v) =
            (0..3)
                .filter(|&m| !used[m])
                .map(|m| (m, cols[c][m]))
                .fold((3, 0.0f64), |best, x| {
                    if best.0 == 3 || x.1.abs() > best.1.abs() {
                        x
                    } else {
                        best
                    }
                });
        let m = m.min(2);
        used[m] = true;
        letters[c] = match (m, v >= 0.0) {
            (0, true) => 'R',
            (0, false) => 'L',
            (1, true) => 'A',
            (1, false) => 'P',
            (_, true) => 'I',
            (_, false) => 'S',
        };
    }
    letters.iter().collect()
}

/// The header text, ending with the `ElementDataFile` line.
fn header_text(
    grid: &Grid,
    t: ScalarType,
    compressed_size: Option<usize>,
    data_file: &str,
) -> String {
    let nums = |v: &[f64]| {
        v.iter()
            .map(|x| format!("{x:?}"))
            .collect::<Vec<_>>()
            .join(" ")
    };
    let d = grid.direction;
    let matrix = [d.x_axis, d.y_axis, d.z_axis]
        .iter()
        .flat_map(|c| c.to_array())
        .collect::<Vec<f64>>();
    let compression = match compressed_size {
        Some(n) => format!("CompressedData = True\nCompressedDataSize = {n}\n"),
        None => "CompressedData = False\n".into(),
    };
    format!(
        "ObjectType = Image\n\
         NDims = 3\n\
         BinaryData = True\n\
         BinaryDataByteOrderMSB = False\n\
         {compression}\
         TransformMatrix = {matrix}\n\
         Offset = {offset}\n\
         CenterOfRotation = 0 0 0\n\
         AnatomicalOrientation = {orientation}\n\
         ElementSpacing = {spacing}\n\
         DimSize = {nx} {ny} {nz}\n\
         ElementType = {ty}\n\
         ElementDataFile = {data_file}\n",
        matrix = nums(&matrix),
        offset = nums(&grid.origin),
        orientation = orientation_letters(&d),
        spacing = nums(&grid.spacing),
        nx = grid.dims[0],
        ny = grid.dims[1],
        nz = grid.dims[2],
        ty = element_type(t),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use volsplat_core::Volume;
    use volsplat_core::glam::DVec3;

    fn volumes(g: &Grid) -> Vec<AnyVolume> {
        crate::test_volumes::every_type(g, 0.1)
    }

    /// Every type, `.mha` and `.mhd`, raw and compressed, an oblique grid with spacings and an
    /// origin that are not float32 numbers: the reader gives back the same volume, bit for bit.
    #[test]
    fn round_trip_through_the_reader() {
        let dir = tempfile::tempdir().unwrap();
        let r = DMat3::from_axis_angle(DVec3::new(0.3, -1.0, 0.5).normalize(), 0.7);
        let reflect = DMat3::from_diagonal(DVec3::new(1.0, -1.0, 1.0));
        for direction in [DMat3::IDENTITY, r, r * reflect] {
            let g = Grid::new(
                [3, 4, 2],
                [0.1, 1.0 / 3.0, 2.5],
                [-10.1, 3.7, 1e-5],
                direction,
            )
            .unwrap();
            for v in volumes(&g) {
                for (name, compress) in [
                    ("v.mha", false),
                    ("v.mha", true),
                    ("v.mhd", false),
                    ("w.mhd", true),
                ] {
                    let p = dir.path().join(name);
                    let files = write_metaimage(&p, &v, compress).unwrap();
                    assert_eq!(files[0], p);
                    let back = crate::read_metaimage(&p).unwrap();
                    assert_eq!(back, v, "{name} {compress}");
                }
            }
        }
        let mut names: Vec<String> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        assert_eq!(names, ["v.mha", "v.mhd", "v.raw", "w.mhd", "w.zraw"]);
    }

    #[test]
    fn header_is_itks() {
        let dir = tempfile::tempdir().unwrap();
        let g = Grid::new(
            [2, 3, 4],
            [0.5, 1.0, 2.0],
            [1.0, -2.0, 3.5],
            DMat3::IDENTITY,
        )
        .unwrap();
        let v: AnyVolume = Volume::new(g, vec![0i16; 24]).unwrap().into();
        let p = dir.path().join("a.mhd");
        write_metaimage(&p, &v, false).unwrap();
        let text = std::fs::read_to_string(&p).unwrap();
        for line in [
            "ObjectType = Image\n",
            "NDims = 3\n",
            "CompressedData = False\n",
            "TransformMatrix = 1.0 0.0 0.0 0.0 1.0 0.0 0.0 0.0 1.0\n",
            "Offset = 1.0 -2.0 3.5\n",
            "AnatomicalOrientation = RAI\n",
            "ElementSpacing = 0.5 1.0 2.0\n",
            "DimSize = 2 3 4\n",
            "ElementType = MET_SHORT\n",
        ] {
            assert!(text.contains(line), "{line}: {text}");
        }
        assert!(text.ends_with("ElementDataFile = a.raw\n"), "{text}");
        assert_eq!(
            std::fs::metadata(dir.path().join("a.raw")).unwrap().len(),
            48
        );
        let e = write_metaimage(dir.path().join("a.mhx"), &v, false).unwrap_err();
        assert!(e.to_string().contains(".mha, .mhd"), "{e}");
    }

    #[test]
    fn orientation_letters_follow_itk() {
        let m = |c: [DVec3; 3]| orientation_letters(&DMat3::from_cols(c[0], c[1], c[2]));
        assert_eq!(m([DVec3::X, DVec3::Y, DVec3::Z]), "RAI");
        assert_eq!(m([-DVec3::X, -DVec3::Y, DVec3::Z]), "LPI");
        // Sagittal slices: i along y (A→P), j along z going down (S→I), k along x (R→L).
        assert_eq!(m([DVec3::Y, -DVec3::Z, DVec3::X]), "ASR");
        // 45° between x and y: each world axis used once.
        let s = std::f64::consts::FRAC_1_SQRT_2;
        assert_eq!(
            m([DVec3::new(s, s, 0.0), DVec3::new(-s, s, 0.0), DVec3::Z]),
            "RAI"
        );
    }
}
