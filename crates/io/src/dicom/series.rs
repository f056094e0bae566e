//! A chosen series made one volume: slices sorted along the normal and checked (PS3.3
//! §C.7.6.2.1.1), samples decoded and rescaled (PS3.3 §C.11.1.1).

use super::header::*;
use super::*;

/// One slice: a frame of a file, with its checked geometry.
#[derive(Debug, Clone)]
struct Slice<'a> {
    file: &'a FileHeader,
    frame: u32,
    geom: &'a FrameGeom,
    /// Position along the normal.
    s: f64,
}

fn unit(v: DVec3) -> Option<DVec3> {
    let l = v.length();
    (l.is_finite() && l > 0.0).then(|| v / l)
}

fn describe(sl: &Slice<'_>) -> String {
    let name = sl.file.path.display().to_string();
    if sl.file.frames > 1 {
        format!("{name} frame {}", sl.frame)
    } else {
        name
    }
}

/// Reads a series (its files' headers): geometry of the sorted stack, then the samples.
pub(super) fn read_series(
    files: &[&FileHeader],
    limits: &Limits,
    notes: &mut Vec<String>,
) -> Result<AnyVolume> {
    let first = files[0];
    let fpath = &first.path;
    let mut slices: Vec<Slice<'_>> = Vec::new();
    for f in files {
        notes.extend(f.notes.iter().cloned());
        for (k, g) in f.geom.iter().enumerate() {
            slices.push(Slice {
                file: f,
                frame: k as u32,
                geom: g,
                s: 0.0,
            });
        }
    }
    // Same size.
    for sl in &slices {
        if (sl.file.rows, sl.file.cols) != (first.rows, first.cols) {
            return Err(IoError::field(
                &sl.file.path,
                "Rows/Columns (0028,0010/0011)",
                &format!("{}/{}", sl.file.rows, sl.file.cols),
                format!(
                    "slices of different sizes in one series: {} has {}/{}",
                    fpath.display(),
                    first.rows,
                    first.cols
                ),
            ));
        }
    }
    let n = slices.len();
    let g0 = slices[0].geom;
    // Pixel spacing.
    let ps = match g0.pixel_spacing {
        Some(p) => p,
        None => {
            notes.push("no PixelSpacing (0028,0030): pixel spacing 1 assumed".into());
            [1.0, 1.0]
        }
    };
    for sl in &slices {
        let p = sl.geom.pixel_spacing.unwrap_or([1.0, 1.0]);
        if (p[0] - ps[0]).abs() > 1e-3 * ps[0] || (p[1] - ps[1]).abs() > 1e-3 * ps[1] {
            return Err(IoError::field(
                &sl.file.path,
                PIXEL_SPACING.label(),
                &format!("{}\\{}", p[0], p[1]),
                format!(
                    "slices of different pixel spacing in one series: {} has {}\\{}",
                    describe(&slices[0]),
                    ps[0],
                    ps[1]
                ),
            ));
        }
    }
    let has_geometry = slices
        .iter()
        .all(|s| s.geom.ipp.is_some() && s.geom.iop.is_some());
    let (origin, direction, dz, order) = if !has_geometry {
        if n > 1 {
            let bad = slices
                .iter()
                .find(|s| s.geom.ipp.is_none() || s.geom.iop.is_none())
                .map(describe)
                .unwrap_or_default();
            return Err(IoError::Dicom {
                path: fpath.clone(),
                message: format!(
                    "{bad} has no {} or {}: slices cannot be ordered (file names and \
                     InstanceNumber are not used; PS3.3 §C.7.6.2)",
                    IPP.label(),
                    IOP.label()
                ),
            });
        }
        notes.push(format!(
            "no {} / {}: origin 0, identity direction",
            IPP.label(),
            IOP.label()
        ));
        (
            DVec3::ZERO,
            DMat3::IDENTITY,
            single_spacing(first, notes),
            vec![0],
        )
    } else {
        stack_geometry(&mut slices, ps, notes)?
    };
    let sorted: Vec<&Slice<'_>> = order.iter().map(|&i| &slices[i]).collect();

    // Grid and limits.
    let dims = checked_dims(
        fpath,
        "Columns × Rows × slices",
        &format!("{} × {} × {}", first.cols, first.rows, n),
        [first.cols as u64, first.rows as u64, n as u64],
        limits,
    )?;
    let grid = Grid::new(dims, [ps[1], ps[0], dz], origin.to_array(), direction)
        .map_err(|e| IoError::core(fpath, e))?;

    decode_series(files, &sorted, grid, limits, notes)
}

/// The sample type and notes of a series, from its files' formats and rescales.
struct Samples<'a> {
    formats: BTreeMap<&'a Path, PixelFormat>,
    /// Whether values stay integers (slope 1, integer intercepts, at most 16 bits).
    integral: bool,
    rescaled: bool,
}

fn sample_plan<'a>(
    files: &[&'a FileHeader],
    sorted: &[&Slice<'_>],
    notes: &mut Vec<String>,
) -> Result<Samples<'a>> {
    let mut formats = BTreeMap::new();
    for f in files {
        formats.insert(f.path.as_path(), f.pixel_format()?);
    }
    let integral = sorted.iter().all(|s| {
        s.geom.slope == 1.0
            && s.geom.intercept.fract() == 0.0
            && s.geom.intercept.abs() <= 1e9
            && formats
                .get(s.file.path.as_path())
                .is_some_and(|f| f.bits_allocated <= 16 || f.palette)
    });
    let rescaled = sorted
        .iter()
        .any(|s| s.geom.slope != 1.0 || s.geom.intercept != 0.0);
    if rescaled {
        let (a, b) = (sorted[0].geom.slope, sorted[0].geom.intercept);
        let same = sorted
            .iter()
            .all(|s| s.geom.slope == a && s.geom.intercept == b);
        notes.push(if same {
            format!("RescaleSlope {a} and RescaleIntercept {b} applied: value = stored · slope + intercept")
        } else {
            "RescaleSlope/RescaleIntercept applied per slice (they differ between slices)".into()
        });
    }
    let names: std::collections::BTreeSet<&str> =
        files.iter().map(|f| f.ts_name.as_str()).collect();
    notes.push(format!(
        "transfer syntax: {}",
        names.into_iter().collect::<Vec<_>>().join(", ")
    ));
    if files.iter().any(|f| f.photometric == "MONOCHROME1") {
        notes.push(
            "MONOCHROME1: low values display bright; samples kept as stored (after rescale)".into(),
        );
    }
    if formats.values().any(|f| f.palette) {
        notes.push("PALETTE COLOR with a grey palette: stored values mapped through it".into());
    }
    Ok(Samples {
        formats,
        integral,
        rescaled,
    })
}

/// A zero-filled buffer of `n` values, or an error naming the size when it cannot be had
/// (instead of aborting the process).
fn zeroed<T: Clone + Default>(path: &Path, n: usize) -> Result<Vec<T>> {
    let mut v = Vec::new();
    v.try_reserve_exact(n).map_err(|_| IoError::Dicom {
        path: path.to_path_buf(),
        message: format!(
            "cannot allocate {} bytes for the volume's {n} samples (lower the voxel limit or \
             free memory)",
            (n as u128) * std::mem::size_of::<T>() as u128
        ),
    })?;
    v.resize(n, T::default());
    Ok(v)
}

/// Where decoded samples go: integers (later narrowed to the smallest type that holds them) or
/// f32. Allocated when the first frame has decoded, so that a file whose pixel data cannot
/// decode fails before the volume's memory is taken.
enum Sink {
    Pending,
    Ints(Vec<i32>),
    Floats(Vec<f32>),
}

/// Decodes every file once (frames in file order, linear in the frame count), into the sorted
/// positions, and makes the volume.
fn decode_series(
    files: &[&FileHeader],
    sorted: &[&Slice<'_>],
    grid: Grid,
    limits: &Limits,
    notes: &mut Vec<String>,
) -> Result<AnyVolume> {
    let fpath = &files[0].path;
    let plan = sample_plan(files, sorted, notes)?;
    let [nx, ny, nz] = grid.dims;
    let plane = nx * ny;
    let total = plane * nz;
    let mut slot_of: BTreeMap<(&Path, u32), usize> = BTreeMap::new();
    for (k, s) in sorted.iter().enumerate() {
        slot_of.insert((s.file.path.as_path(), s.frame), k);
    }
    let mut sink = Sink::Pending;
    let mut buf: Vec<i64> = Vec::new();
    for f in files {
        let Some(loaded) = load(&f.path, limits, None)? else {
            return Err(not_dicom(&f.path));
        };
        let (obj, _) = parse(&f.path, &loaded, false, limits)?;
        drop(loaded);
        let fmt = plan
            .formats
            .get(f.path.as_path())
            .copied()
            .ok_or_else(|| not_dicom(&f.path))?;
        let source = pixels::PixelSource::new(&f.path, &obj, f, &fmt)?;
        let palette = if fmt.palette {
            Some(pixels::Palette::read(
                &f.path,
                &obj,
                f.ts_uid == "1.2.840.10008.1.2.2",
            )?)
        } else {
            None
        };
        for (frame, g) in f.geom.iter().enumerate() {
            let frame = frame as u32;
            let Some(&k) = slot_of.get(&(f.path.as_path(), frame)) else {
                continue;
            };
            source.decode_frame(frame, &mut buf)?;
            if buf.len() != plane {
                return Err(IoError::Dicom {
                    path: f.path.clone(),
                    message: format!(
                        "frame {frame} decoded to {} samples, {plane} expected",
                        buf.len()
                    ),
                });
            }
            if let Some(p) = &palette {
                p.apply(&mut buf);
            }
            if matches!(sink, Sink::Pending) {
                sink = if plan.integral {
                    Sink::Ints(zeroed(fpath, total)?)
                } else {
                    Sink::Floats(zeroed(fpath, total)?)
                };
            }
            let dst = k * plane..(k + 1) * plane;
            match &mut sink {
                Sink::Ints(ints) => {
                    let icpt = g.intercept as i64;
                    for (d, &v) in ints[dst].iter_mut().zip(&buf) {
                        // |v| < 2³², |icpt| ≤ 1e9: fits i64; clamped into i32 (never reached
                        // for ≤ 16-bit samples).
                        *d = (v + icpt).clamp(i32::MIN as i64, i32::MAX as i64) as i32;
                    }
                }
                Sink::Floats(floats) => {
                    for (d, &v) in floats[dst].iter_mut().zip(&buf) {
                        let x = v as f64 * g.slope + g.intercept;
                        if !(x.is_finite() && x.abs() <= f32::MAX as f64) {
                            return Err(IoError::field(
                                &f.path,
                                SLOPE.label(),
                                &format!("{} (intercept {})", g.slope, g.intercept),
                                format!("stored value {v} rescales to {x}, outside the f32 range"),
                            ));
                        }
                        *d = x as f32;
                    }
                }
                Sink::Pending => {}
            }
        }
    }
    match sink {
        Sink::Pending => Err(IoError::Dicom {
            path: fpath.clone(),
            message: "no frame decoded".into(),
        }),
        Sink::Floats(floats) => {
            if !plan.rescaled || sorted.iter().any(|s| s.geom.slope.fract() == 0.0) {
                notes.push("samples stored as f32".into());
            }
            let big = floats.iter().any(|v| v.abs() > (1 << 24) as f32);
            if big && plan.rescaled {
                notes.push("values beyond 2²⁴ in magnitude are rounded to f32".into());
            }
            Volume::new(grid, floats)
                .map(AnyVolume::from)
                .map_err(|e| IoError::core(fpath, e))
        }
        Sink::Ints(ints) => narrow(fpath, grid, ints, plan.formats.get(fpath.as_path()), notes),
    }
}

/// Integer samples as the first type that holds their range among the stored type, i16 and
/// u16, else f32.
fn narrow(
    fpath: &Path,
    grid: Grid,
    ints: Vec<i32>,
    format: Option<&PixelFormat>,
    notes: &mut Vec<String>,
) -> Result<AnyVolume> {
    let (lo, hi) = ints
        .iter()
        .fold((i32::MAX, i32::MIN), |(a, b), &v| (a.min(v), b.max(v)));
    use volsplat_core::ScalarType as St;
    let stored = format
        .map(|f| match (f.bits_allocated, f.signed, f.palette) {
            (_, _, true) => St::U16,
            (1 | 8, false, _) => St::U8,
            (1 | 8, true, _) => St::I8,
            (_, false, _) => St::U16,
            (_, true, _) => St::I16,
        })
        .unwrap_or(St::I16);
    let fits = |t: St| match t {
        St::U8 => lo >= 0 && hi <= u8::MAX as i32,
        St::I8 => lo >= i8::MIN as i32 && hi <= i8::MAX as i32,
        St::U16 => lo >= 0 && hi <= u16::MAX as i32,
        St::I16 => lo >= i16::MIN as i32 && hi <= i16::MAX as i32,
        St::F32 => true,
    };
    let chosen = [stored, St::I16, St::U16]
        .into_iter()
        .find(|&t| fits(t))
        .unwrap_or(St::F32);
    let core = |e| IoError::core(fpath, e);
    Ok(match chosen {
        St::U8 => AnyVolume::from(
            Volume::new(grid, ints.into_iter().map(|v| v as u8).collect()).map_err(core)?,
        ),
        St::I8 => AnyVolume::from(
            Volume::new(grid, ints.into_iter().map(|v| v as i8).collect()).map_err(core)?,
        ),
        St::U16 => AnyVolume::from(
            Volume::new(grid, ints.into_iter().map(|v| v as u16).collect()).map_err(core)?,
        ),
        St::I16 => AnyVolume::from(
            Volume::new(grid, ints.into_iter().map(|v| v as i16).collect()).map_err(core)?,
        ),
        St::F32 => {
            notes.push(format!(
                "values {lo} … {hi} fit no 16-bit type: stored as f32"
            ));
            AnyVolume::from(
                Volume::new(grid, ints.into_iter().map(|v| v as f32).collect()).map_err(core)?,
            )
        }
    })
}

/// Slice spacing of a single image: SpacingBetweenSlices, else SliceThickness, else 1.
fn single_spacing(f: &FileHeader, notes: &mut Vec<String>) -> f64 {
    if let Some(s) = f.spacing_between.filter(|s| *s > 0.0) {
        notes.push(format!(
            "one slice: slice spacing {s} from {}",
            SPACING_BETWEEN.label()
        ));
        s
    } else if let Some(s) = f.thickness.filter(|s| *s > 0.0) {
        notes.push(format!(
            "one slice: slice spacing {s} from {}",
            SLICE_THICKNESS.label()
        ));
        s
    } else {
        notes.push("one slice: slice spacing 1 assumed".into());
        1.0
    }
}

/// Orientation, sorting and spacing checks (PS3.3 §C.7.6.2.1.1). Returns the origin, the
/// direction, the slice spacing and the slice order.
fn stack_geometry(
    slices: &mut [Slice<'_>],
    ps: [f64; 2],
    notes: &mut Vec<String>,
) -> Result<(DVec3, DMat3, f64, Vec<usize>)> {
    let g0 = slices[0].geom;
    let first = &slices[0];
    let iop = g0.iop.unwrap_or([1.0, 0.0, 0.0, 0.0, 1.0, 0.0]);
    let iop_text = format!(
        "{}\\{}\\{}\\{}\\{}\\{}",
        iop[0], iop[1], iop[2], iop[3], iop[4], iop[5]
    );
    let r_raw = DVec3::new(iop[0], iop[1], iop[2]);
    let c_raw = DVec3::new(iop[3], iop[4], iop[5]);
    let bad_iop = |why: &str| IoError::field(&first.file.path, IOP.label(), &iop_text, why);
    if (r_raw.length() - 1.0).abs() > 1e-3 || (c_raw.length() - 1.0).abs() > 1e-3 {
        return Err(bad_iop(
            "the row and column direction cosines must be unit vectors",
        ));
    }
    if r_raw.dot(c_raw).abs() > 1e-3 {
        return Err(bad_iop(
            "the row and column directions must be perpendicular",
        ));
    }
    let r = unit(r_raw).ok_or_else(|| bad_iop("not a direction"))?;
    let c = unit(c_raw - c_raw.dot(r) * r).ok_or_else(|| bad_iop("not a direction"))?;
    let nrm = r.cross(c);
    // Same orientation everywhere.
    for sl in slices.iter() {
        let o = sl.geom.iop.unwrap_or(iop);
        if o.iter().zip(&iop).any(|(a, b)| (a - b).abs() > 1e-3) {
            return Err(IoError::field(
                &sl.file.path,
                IOP.label(),
                &format!("{}\\{}\\{}\\{}\\{}\\{}", o[0], o[1], o[2], o[3], o[4], o[5]),
                format!(
                    "slices of different orientations in one series ({} has {iop_text}); a \
                     localizer or a multi-planar series cannot be one volume",
                    describe(first)
                ),
            ));
        }
    }
    for sl in slices.iter_mut() {
        let p = sl.geom.ipp.unwrap_or([0.0; 3]);
        sl.s = DVec3::from(p).dot(nrm);
    }
    let mut order: Vec<usize> = (0..slices.len()).collect();
    order.sort_by(|&a, &b| slices[a].s.total_cmp(&slices[b].s));
    let pos = |i: usize| DVec3::from(slices[i].geom.ipp.unwrap_or([0.0; 3]));
    let origin = pos(order[0]);
    let direction = DMat3::from_cols(r, c, nrm);
    let n = order.len();
    if n == 1 {
        let dz = single_spacing(slices[0].file, notes);
        return Ok((origin, direction, dz, order));
    }
    let gaps: Vec<f64> = order
        .windows(2)
        .map(|w| slices[w[1]].s - slices[w[0]].s)
        .collect();
    let mut sorted_gaps = gaps.clone();
    sorted_gaps.sort_by(f64::total_cmp);
    let median = sorted_gaps[sorted_gaps.len() / 2];
    let min_px = ps[0].min(ps[1]);
    // Duplicates: positions closer than 1e-3 of a pixel... or of the median gap.
    let same_tol = (1e-3 * median.max(min_px)).max(1e-6);
    for (k, &g) in gaps.iter().enumerate() {
        if g <= same_tol {
            let (a, b) = (&slices[order[k]], &slices[order[k + 1]]);
            return Err(IoError::field(
                &b.file.path,
                IPP.label(),
                &fmt3(pos(order[k + 1])),
                format!(
                    "{} and {} lie at the same position along the slice normal: several \
                     acquisitions (echoes, time points, stacks) in one series",
                    describe(a),
                    describe(b)
                ),
            ));
        }
    }
    for (k, &g) in gaps.iter().enumerate() {
        if (g - median).abs() > GAP_TOLERANCE * median {
            let (a, b) = (&slices[order[k]], &slices[order[k + 1]]);
            let m = (g / median).round();
            let reason = if m >= 2.0 && (g - m * median).abs() <= GAP_TOLERANCE * median {
                format!(
                    "missing slice{}: {} slice{} between {} (at {:.4}) and {} (at {:.4}) along \
                     the normal; the other slices are {:.4} apart",
                    if m > 2.0 { "s" } else { "" },
                    m - 1.0,
                    if m > 2.0 { "s" } else { "" },
                    describe(a),
                    a.s,
                    describe(b),
                    b.s,
                    median
                )
            } else {
                format!(
                    "unequal gaps between slices: {} and {} are {:.4} apart along the normal, \
                     the median gap is {:.4} (tolerance {} %)",
                    describe(a),
                    describe(b),
                    g,
                    median,
                    GAP_TOLERANCE * 100.0
                )
            };
            return Err(IoError::field(
                &b.file.path,
                IPP.label(),
                &fmt3(pos(order[k + 1])),
                reason,
            ));
        }
    }
    // Gantry tilt / shear: positions off the axis through the first slice along the normal.
    let p0 = origin;
    for &i in &order[1..] {
        let d = pos(i) - p0;
        let along = d.dot(nrm);
        let off = (d - along * nrm).length();
        if off > 0.1 * min_px + 1e-3 * along.abs() {
            let sl = &slices[i];
            let angle = (off / along.abs().max(f64::MIN_POSITIVE))
                .atan()
                .to_degrees();
            let tilt = sl
                .file
                .tilt
                .map(|t| format!("; {} is {t}", GANTRY_TILT.label()))
                .unwrap_or_default();
            return Err(IoError::field(
                &sl.file.path,
                IPP.label(),
                &fmt3(pos(i)),
                format!(
                    "gantry tilt or sheared stack: {} lies {off:.4} off the axis through the \
                     first slice along the slice normal ({angle:.2}° tilt{tilt}); \
                     volsplat's grids are orthogonal, resample the series first",
                    describe(sl)
                ),
            ));
        }
    }
    let dz = (slices[order[n - 1]].s - slices[order[0]].s) / (n - 1) as f64;
    let thick = slices[0]
        .file
        .thickness
        .map(|t| format!(" (SliceThickness {t})"))
        .unwrap_or_default();
    notes.push(format!(
        "{n} slices sorted by ImagePositionPatient along the slice normal; spacing between \
         slices {dz:.6} from their positions{thick}"
    ));
    Ok((origin, direction, dz, order))
}

fn fmt3(v: DVec3) -> String {
    format!("{}\\{}\\{}", v.x, v.y, v.z)
}
