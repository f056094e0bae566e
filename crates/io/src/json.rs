//! Camera and transfer-function JSON files (docs/design.md §3; the README's "Files" section).
//!
//! Both are JSON objects. Unknown top-level fields are ignored with a warning (returned to the
//! caller, which decides whether to print it); missing required fields and wrong types are errors
//! naming the file and the field; the parsed value is then validated by `volsplat-core` (for a
//! transfer function: every point list in non-decreasing order of value, equal values allowed
//! for a step).
//! `//` line comments (outside strings) are removed before parsing, so the annotated examples of
//! docs/design.md load as written. Files larger than [`MAX_JSON_BYTES`] are rejected.
//!
//! A transfer-function file may also be a ParaView / VTK colour-map preset, as ParaView's
//! "Choose Preset → Export" writes it (see [`load_transfer_function_named`]); the command line's
//! `--tf` and Python's `TransferFunction.load` read both through this one reader.

use crate::atomic::{write_atomic, write_err};
use crate::error::{IoError, Result};
use crate::limits::Limits;
use serde::Serialize;
use serde::de::DeserializeOwned;
use serde_json::{Map, Value};
use std::io::{Read, Write};
use std::path::Path;
use volsplat_core::transfer::TRANSFER_FUNCTION_FIELDS;
use volsplat_core::{Camera, TransferFunction};

/// Largest camera or transfer-function file accepted, in bytes (16 MiB).
pub const MAX_JSON_BYTES: u64 = 16 << 20;

/// The fields of a camera file (VTK's camera; docs/design.md §3). `position`, `focal_point`,
/// `view_up` and `parallel_projection` are required; `view_angle` and `parallel_scale` default to
/// VTK's values (30° and 1).
pub const CAMERA_FIELDS: &[&str] = &[
    "position",
    "focal_point",
    "view_up",
    "view_angle",
    "parallel_projection",
    "parallel_scale",
];

/// Loads a camera file: `position`, `focal_point` (world units), `view_up`, `view_angle`
/// (degrees), `parallel_projection`, `parallel_scale` (world units; half the image height).
///
/// `parallel_projection` is required: VTK's default (perspective) differs from volsplat's
/// (orthographic), so a file that leaves it out would look different depending on the tool.
///
/// Returns the validated camera and one warning per unknown top-level field.
pub fn load_camera(path: impl AsRef<Path>) -> Result<(Camera, Vec<String>)> {
    load_camera_with(path, &Limits::default())
}

/// [`load_camera`] with caller-set [`Limits`] (`max_json_bytes`).
pub fn load_camera_with(path: impl AsRef<Path>, limits: &Limits) -> Result<(Camera, Vec<String>)> {
    let path = path.as_ref();
    let (object, warnings) = load_object(path, CAMERA_FIELDS, limits.max_json_bytes)?;
    let has_projection = object.contains_key("parallel_projection");
    let camera: Camera = from_object(path, object, serde_json::to_value(Camera::default()).ok())?;
    if !has_projection {
        return Err(IoError::Json {
            path: path.to_path_buf(),
            message: "missing required field `parallel_projection` (true for an orthographic \
                      camera, false for perspective; VTK's default is false, volsplat's \
                      command line defaults to true)"
                .into(),
        });
    }
    camera.validate().map_err(|e| IoError::core(path, e))?;
    Ok((camera, warnings))
}

/// Loads a transfer-function file (fields [`TRANSFER_FUNCTION_FIELDS`]; point values in the
/// data's own units, `scalar_opacity_unit_distance` in world units), or a ParaView colour-map
/// preset file (see [`load_transfer_function_named`]; the first preset of the file).
///
/// Every point list (`color`, `scalar_opacity`, `gradient_opacity`) must be in non-decreasing
/// order of value; equal consecutive values (a step) are allowed. An out-of-order point is an
/// error naming the file, the field, the point's index and its value.
///
/// Returns the validated transfer function and its warnings: one per unknown top-level field
/// (volsplat's format), or what a ParaView preset loses (see [`load_transfer_function_named`]).
pub fn load_transfer_function(path: impl AsRef<Path>) -> Result<(TransferFunction, Vec<String>)> {
    load_transfer_function_with(path, &Limits::default())
}

/// [`load_transfer_function`] with caller-set [`Limits`] (`max_json_bytes`).
pub fn load_transfer_function_with(
    path: impl AsRef<Path>,
    limits: &Limits,
) -> Result<(TransferFunction, Vec<String>)> {
    load_transfer_function_named(path, None, limits)
}

/// Loads a transfer function from volsplat's transfer-function file or from a ParaView / VTK
/// colour-map preset file, told apart by their content.
///
/// A ParaView preset file (ParaView's "Choose Preset → Export") is a JSON list of preset objects,
/// or one object, each with `RGBPoints` = `[x, r, g, b, …]` (values in data units, colours in
/// [0, 1]) and optionally `Name`, `ColorSpace` and `Points` = `[x, opacity, midpoint, sharpness,
/// …]` (VTK's `vtkPiecewiseFunction` nodes). It becomes:
///
/// - `color`: the `RGBPoints`, interpolated in RGB (another `ColorSpace` draws a warning);
/// - `scalar_opacity`: `[x, opacity]` of the `Points` (midpoints and sharpnesses other than VTK's
///   0.5 and 0 draw a warning: they are approximated by straight lines); without `Points`, a ramp
///   from 0 at the first colour point to 1 at the last (ParaView's default opacity; a warning
///   says so), or opacity 1 when the colour range is a single value;
/// - `Shade`, `Ambient`, `Diffuse`, `Specular`, `SpecularPower` and
///   `ScalarOpacityUnitDistance`, if present, the fields of the same meaning; everything else
///   (`Name`, `Creator`, `NanColor`, …) is ignored.
///
/// `name` picks the preset whose `Name` it is (an error lists the names the file holds);
/// without it the first preset is used, with a warning when the file holds several. `name` is
/// an error for volsplat's own format. Errors name the file and the field (`RGBPoints[5]`).
pub fn load_transfer_function_named(
    path: impl AsRef<Path>,
    name: Option<&str>,
    limits: &Limits,
) -> Result<(TransferFunction, Vec<String>)> {
    let path = path.as_ref();
    let value = load_value(path, limits.max_json_bytes)?;
    if is_paraview(&value) {
        return from_paraview(path, &value, name);
    }
    let paraview_like = |v: &Value| {
        v.as_object()
            .is_some_and(|o| o.contains_key("IndexedColors") || o.contains_key("Annotations"))
    };
    if matches!(&value, Value::Array(items) if items.iter().any(paraview_like))
        || paraview_like(&value) && value.get("color").is_none()
    {
        return Err(IoError::Json {
            path: path.to_path_buf(),
            message: "a ParaView colour-map preset without `RGBPoints` (an indexed or \
                      categorical map?): only continuous maps, with `RGBPoints`, make a transfer \
                      function"
                .into(),
        });
    }
    if let Some(name) = name {
        return Err(IoError::Json {
            path: path.to_path_buf(),
            message: format!(
                "a preset name ({name:?}) applies to ParaView colour-map preset files only \
                 (a list of objects with `RGBPoints`); this is volsplat's transfer-function \
                 format"
            ),
        });
    }
    let (object, warnings) = into_object(path, value, TRANSFER_FUNCTION_FIELDS)?;
    tf_from_object(path, object, warnings)
}

/// The transfer function of a volsplat transfer-function object, validated.
fn tf_from_object(
    path: &Path,
    object: Map<String, Value>,
    warnings: Vec<String>,
) -> Result<(TransferFunction, Vec<String>)> {
    let template = serde_json::to_value(TransferFunction::ramp(0.0, 1.0, 1.0)).ok();
    let mut tf: TransferFunction = from_object(path, object, template)?;
    tf.validate().map_err(|e| IoError::core(path, e))?;
    Ok((tf, warnings))
}

/// Whether `value` is a ParaView colour-map preset file: an object with `RGBPoints`, or a list
/// holding one.
fn is_paraview(value: &Value) -> bool {
    let has_points = |v: &Value| v.as_object().is_some_and(|o| o.contains_key("RGBPoints"));
    match value {
        Value::Object(_) => has_points(value),
        Value::Array(items) => items.iter().any(has_points),
        _ => false,
    }
}

/// The ParaView preset fields copied as they are: (ParaView's key, volsplat's field, a bool?).
const PARAVIEW_SCALARS: [(&str, &str, bool); 6] = [
    ("Shade", "shade", true),
    ("Ambient", "ambient", false),
    ("Diffuse", "diffuse", false),
    ("Specular", "specular", false),
    ("SpecularPower", "specular_power", false),
    (
        "ScalarOpacityUnitDistance",
        "scalar_opacity_unit_distance",
        false,
    ),
];

/// A ParaView colour-map preset file as a transfer function (rules: [`load_transfer_function_named`]).
fn from_paraview(
    path: &Path,
    value: &Value,
    name: Option<&str>,
) -> Result<(TransferFunction, Vec<String>)> {
    let presets: Vec<&Map<String, Value>> = match value {
        Value::Object(o) => vec![o],
        Value::Array(items) => items
            .iter()
            .filter_map(Value::as_object)
            .filter(|o| o.contains_key("RGBPoints"))
            .collect(),
        _ => Vec::new(),
    };
    let label = |p: &Map<String, Value>| match p.get("Name") {
        Some(Value::String(s)) => format!("{s:?}"),
        Some(v) => v.to_string(),
        None => "(no Name)".into(),
    };
    let mut warnings = Vec::new();
    let preset = match name {
        Some(name) => presets
            .iter()
            .find(|p| p.get("Name").and_then(Value::as_str) == Some(name))
            .ok_or_else(|| IoError::Json {
                path: path.to_path_buf(),
                message: format!(
                    "no preset named {name:?}; the file holds {}",
                    presets
                        .iter()
                        .map(|p| label(p))
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            })?,
        None => {
            let first = presets.first().ok_or_else(|| IoError::Json {
                path: path.to_path_buf(),
                message: "no ParaView preset with `RGBPoints` in the file".into(),
            })?;
            if presets.len() > 1 {
                warnings.push(format!(
                    "{}: holds {} presets; using the first, {} (choose with a name)",
                    path.display(),
                    presets.len(),
                    label(first)
                ));
            }
            first
        }
    };
    let rgb = flat_numbers(path, preset, "RGBPoints", "[x, r, g, b, …]")?;
    let color: Vec<Value> = rgb.chunks_exact(4).map(|q| serde_json::json!(q)).collect();
    if let Some(Value::String(space)) = preset.get("ColorSpace")
        && !space.eq_ignore_ascii_case("rgb")
    {
        warnings.push(format!(
            "{}: ColorSpace {space:?} is interpolated in RGB here",
            path.display()
        ));
    }
    let opacity: Vec<Value> = match preset.get("Points") {
        None | Some(Value::Null) => {
            let (lo, hi) = (rgb[0], rgb[rgb.len() - 4]);
            warnings.push(format!(
                "{}: no opacity Points; opacity ramps 0 → 1 over the colour range",
                path.display()
            ));
            if hi > lo {
                vec![serde_json::json!([lo, 0.0]), serde_json::json!([hi, 1.0])]
            } else {
                vec![serde_json::json!([lo, 1.0])]
            }
        }
        Some(_) => {
            let pts = flat_numbers(
                path,
                preset,
                "Points",
                "[x, opacity, midpoint, sharpness, …]",
            )?;
            if pts.chunks_exact(4).any(|q| q[2] != 0.5 || q[3] != 0.0) {
                warnings.push(format!(
                    "{}: opacity midpoint/sharpness other than 0.5/0 are approximated by \
                     straight lines",
                    path.display()
                ));
            }
            pts.chunks_exact(4)
                .map(|q| serde_json::json!([q[0], q[1]]))
                .collect()
        }
    };
    let mut object = Map::new();
    object.insert("color".into(), Value::Array(color));
    object.insert("scalar_opacity".into(), Value::Array(opacity));
    for (key, field, boolean) in PARAVIEW_SCALARS {
        let Some(v) = preset.get(key) else { continue };
        if (boolean && !v.is_boolean()) || (!boolean && !v.is_number()) {
            return Err(IoError::field(
                path,
                key,
                &v.to_string(),
                if boolean {
                    "expected true or false"
                } else {
                    "expected a number"
                },
            ));
        }
        object.insert(field.into(), v.clone());
    }
    let (tf, _) = tf_from_object(path, object, Vec::new()).map_err(|e| match e {
        IoError::Core { error, .. } => IoError::Json {
            path: path.to_path_buf(),
            message: format!(
                "ParaView preset {} (RGBPoints → color, Points → scalar_opacity): {error}",
                label(preset)
            ),
        },
        e => e,
    })?;
    Ok((tf, warnings))
}

/// `preset[key]` as a flat list of numbers, a non-empty multiple of 4 long.
fn flat_numbers(
    path: &Path,
    preset: &Map<String, Value>,
    key: &str,
    layout: &str,
) -> Result<Vec<f64>> {
    let value = preset.get(key).unwrap_or(&Value::Null);
    let Value::Array(items) = value else {
        return Err(IoError::field(
            path,
            key,
            &value.to_string(),
            format!("expected a flat list {layout} of 4·N numbers"),
        ));
    };
    if items.is_empty() || items.len() % 4 != 0 {
        return Err(IoError::field(
            path,
            key,
            &value.to_string(),
            format!(
                "expected a flat list {layout} of 4·N numbers (N ≥ 1), got {} numbers",
                items.len()
            ),
        ));
    }
    items
        .iter()
        .enumerate()
        .map(|(n, v)| {
            v.as_f64().ok_or_else(|| {
                IoError::field(
                    path,
                    format!("{key}[{n}]"),
                    &v.to_string(),
                    "expected a number",
                )
            })
        })
        .collect()
}

/// Saves a camera as pretty-printed JSON with the fields of [`CAMERA_FIELDS`] (world units,
/// degrees), atomically.
pub fn save_camera(path: impl AsRef<Path>, camera: &Camera) -> Result<()> {
    save_pretty(path.as_ref(), camera)
}

/// Saves a transfer function as pretty-printed JSON (the format [`load_transfer_function`]
/// reads), atomically.
pub fn save_transfer_function(path: impl AsRef<Path>, tf: &TransferFunction) -> Result<()> {
    save_pretty(path.as_ref(), tf)
}

fn save_pretty<T: Serialize>(path: &Path, value: &T) -> Result<()> {
    let mut text = serde_json::to_string_pretty(value).map_err(|e| IoError::Json {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    text.push('\n');
    write_atomic(path, |w| {
        w.write_all(text.as_bytes()).map_err(write_err(path))
    })
}

/// Reads `path` as a JSON object; returns it and warnings for fields not in `known`.
fn load_object(
    path: &Path,
    known: &[&str],
    max_bytes: u64,
) -> Result<(Map<String, Value>, Vec<String>)> {
    into_object(path, load_value(path, max_bytes)?, known)
}

/// Reads `path` as JSON (`//` comments removed). Files may be pipes (`--camera <(…)`): reading
/// is bounded by `max_bytes`, not by a size found beforehand.
fn load_value(path: &Path, max_bytes: u64) -> Result<Value> {
    let file = std::fs::File::open(path).map_err(|e| IoError::os(path, "open", e))?;
    let mut bytes = Vec::new();
    file.take(max_bytes.saturating_add(1))
        .read_to_end(&mut bytes)
        .map_err(|e| IoError::os(path, "read", e))?;
    if bytes.len() as u64 > max_bytes {
        return Err(IoError::TooLarge {
            path: path.to_path_buf(),
            what: "JSON file size in bytes".into(),
            value: bytes.len() as u128,
            limit: max_bytes as u128,
        });
    }
    let text = String::from_utf8(bytes).map_err(|e| IoError::Json {
        path: path.to_path_buf(),
        message: format!("not valid UTF-8: {e}"),
    })?;
    // A byte-order mark, as Windows Notepad writes, is not JSON but says nothing either.
    let text = strip_line_comments(text.strip_prefix('\u{feff}').unwrap_or(&text));
    serde_json::from_str(&text).map_err(|e| IoError::Json {
        path: path.to_path_buf(),
        message: e.to_string(),
    })
}

/// `value` as a JSON object, with warnings for fields not in `known`.
fn into_object(
    path: &Path,
    value: Value,
    known: &[&str],
) -> Result<(Map<String, Value>, Vec<String>)> {
    let Value::Object(object) = value else {
        return Err(IoError::Json {
            path: path.to_path_buf(),
            message: "expected a JSON object `{ … }` at the top level".into(),
        });
    };
    let warnings = object
        .keys()
        .filter(|k| !known.contains(&k.as_str()))
        .map(|k| {
            format!(
                "{}: unknown field `{k}` ignored (known fields: {})",
                path.display(),
                known.join(", ")
            )
        })
        .collect();
    Ok((object, warnings))
}

/// Deserialises `object`; on failure, finds the field responsible by substituting each field in
/// turn into a valid `template` object, so that type errors name the field.
fn from_object<T: DeserializeOwned>(
    path: &Path,
    object: Map<String, Value>,
    template: Option<Value>,
) -> Result<T> {
    let err = match serde_json::from_value::<T>(Value::Object(object.clone())) {
        Ok(v) => return Ok(v),
        Err(e) => e,
    };
    if let Some(Value::Object(template)) = template {
        for (key, value) in &object {
            if !template.contains_key(key) && !is_optional_absent_from(key) {
                continue;
            }
            let mut probe = template.clone();
            probe.insert(key.clone(), value.clone());
            if let Err(e) = serde_json::from_value::<T>(Value::Object(probe)) {
                return Err(IoError::Json {
                    path: path.to_path_buf(),
                    message: format!("field `{key}`: {e}"),
                });
            }
        }
    }
    Err(IoError::Json {
        path: path.to_path_buf(),
        message: err.to_string(),
    })
}

/// Optional fields that a serialised template leaves out (`skip_serializing_if`).
fn is_optional_absent_from(key: &str) -> bool {
    key == "gradient_opacity"
}

/// Removes `//` comments that start outside string literals (up to the end of the line; the
/// newline is kept so that parser positions stay right).
fn strip_line_comments(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut in_string = false;
    let mut escaped = false;
    let mut chars = text.chars().peekable();
    while let Some(c) = chars.next() {
        if in_string {
            out.push(c);
            if escaped {
                escaped = false;
            } else if c == '\\' {
                escaped = true;
            } else if c == '"' {
                in_string = false;
            }
            continue;
        }
        match c {
            '"' => {
                in_string = true;
                out.push(c);
            }
            '/' if chars.peek() == Some(&'/') => {
                while chars.peek().is_some_and(|&n| n != '\n') {
                    chars.next();
                }
            }
            _ => out.push(c),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(dir: &Path, name: &str, text: &str) -> std::path::PathBuf {
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p
    }

    const DESIGN_CAMERA: &str = r#"// camera.json — world units; the same numbers reproduce the view in VTK or ParaView
{ "position": [394.4, 802.9, 284.5], "focal_point": [122.0, 122.0, 80.25], "view_up": [0, 0, 1],
  "parallel_projection": true, "parallel_scale": 194.1,   // orthographic: half image height
  "view_angle": 30.0 }                                     // perspective: vertical FOV in degrees
"#;

    const DESIGN_TF: &str = r#"// transfer-function.json — values in the data's own units (e.g. Hounsfield units for CT)
{ "color": [[-1024, 0, 0, 0], [400, 1.0, 0.9, 0.75], [3071, 1, 1, 1]],
  "scalar_opacity": [[-1024, 0.0], [400, 0.3], [3071, 0.9]],
  "gradient_opacity": [[0, 1.0], [500, 1.0]],              // optional; gradient magnitude in units/world unit
  "scalar_opacity_unit_distance": 1.0,                     // world units; default 1
  "shade": false, "ambient": 0.1, "diffuse": 0.7, "specular": 0.2, "specular_power": 10.0 }
"#;

    /// Issue 13: saved floats reload bit-exactly (serde_json's `float_roundtrip`).
    #[test]
    fn saved_floats_reload_bit_exactly() {
        let dir = tempfile::tempdir().unwrap();
        let mut state = 0x9E37_79B9_7F4A_7C15u64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            // A double in [0, 1) with a full 52-bit random mantissa and a random exponent.
            let m = f64::from_bits(0x3FF0_0000_0000_0000 | (state >> 12)) - 1.0;
            m * 0.5f64.powi((state % 40) as i32)
        };
        let mut xs: Vec<f64> = (0..3000).map(|_| next() * 1e4 - 1.0).collect();
        xs.sort_by(f64::total_cmp);
        let mut tf = TransferFunction::ramp(0.0, 1.0, 1.0);
        tf.color = xs.iter().map(|&x| [x, next(), next(), next()]).collect();
        tf.scalar_opacity = xs.iter().map(|&x| [x, next()]).collect();
        tf.scalar_opacity_unit_distance = 0.1 + next();
        let p = dir.path().join("tf.json");
        save_transfer_function(&p, &tf).unwrap();
        let (back, _) = load_transfer_function(&p).unwrap();
        for (a, b) in tf.color.iter().zip(&back.color) {
            for (x, y) in a.iter().zip(b) {
                assert_eq!(x.to_bits(), y.to_bits(), "{x:e} reloaded as {y:e}");
            }
        }
        assert_eq!(back, tf);
        let cam = Camera {
            position: [next() * 1e3, 1e-300 * next(), 123.456 + next()],
            parallel_scale: 1.0 + next(),
            ..Camera::default()
        };
        let p = dir.path().join("c.json");
        save_camera(&p, &cam).unwrap();
        let (back, _) = load_camera(&p).unwrap();
        assert_eq!(back, cam);
    }

    #[test]
    fn json_limit_is_caller_set() {
        let dir = tempfile::tempdir().unwrap();
        let p = write(dir.path(), "c.json", DESIGN_CAMERA);
        let l = Limits {
            max_json_bytes: 10,
            ..Limits::default()
        };
        let e = load_camera_with(&p, &l).unwrap_err().to_string();
        assert!(e.contains("exceeds the limit 10"), "{e}");
        let e = load_transfer_function_with(&p, &l).unwrap_err().to_string();
        assert!(e.contains("exceeds the limit 10"), "{e}");
    }

    #[test]
    fn design_examples_load_with_comments() {
        let dir = tempfile::tempdir().unwrap();
        let (cam, w) = load_camera(write(dir.path(), "c.json", DESIGN_CAMERA)).unwrap();
        assert!(w.is_empty(), "{w:?}");
        assert_eq!(cam.position, [394.4, 802.9, 284.5]);
        assert!(cam.parallel_projection);
        assert_eq!(cam.parallel_scale, 194.1);
        let (tf, w) = load_transfer_function(write(dir.path(), "t.json", DESIGN_TF)).unwrap();
        assert!(w.is_empty(), "{w:?}");
        assert_eq!(tf.color.len(), 3);
        assert_eq!(tf.gradient_opacity.as_ref().map(Vec::len), Some(2));
        assert_eq!(tf.ambient, 0.1);
    }

    #[test]
    fn comment_stripping_keeps_strings() {
        let s = strip_line_comments("{\"a\": \"http://x//y\\\"//z\", // gone\n\"b\": 1}");
        assert_eq!(s, "{\"a\": \"http://x//y\\\"//z\", \n\"b\": 1}");
    }

    #[test]
    fn unknown_fields_warn_and_defaults_apply() {
        let dir = tempfile::tempdir().unwrap();
        let p = write(
            dir.path(),
            "cam.json",
            r#"{"position": [0,0,5], "focal_point": [0,0,0], "view_up": [0,1,0], "zoom": 2,
                "parallel_projection": false}"#,
        );
        let (cam, w) = load_camera(&p).unwrap();
        assert_eq!(w.len(), 1);
        assert!(
            w[0].contains("`zoom`") && w[0].contains("cam.json"),
            "{w:?}"
        );
        assert_eq!(cam.view_angle, 30.0);
        assert_eq!(cam.parallel_scale, 1.0);
        assert!(!cam.parallel_projection);
    }

    #[test]
    fn camera_without_parallel_projection_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        let p = write(
            dir.path(),
            "noproj.json",
            r#"{"position": [0,0,5], "focal_point": [0,0,0], "view_up": [0,1,0]}"#,
        );
        let e = load_camera(&p).unwrap_err().to_string();
        assert!(
            e.contains("parallel_projection") && e.contains("noproj.json"),
            "{e}"
        );
        // Either value given explicitly loads.
        for (v, parallel) in [("true", true), ("false", false)] {
            let p = write(
                dir.path(),
                "proj.json",
                &format!(
                    r#"{{"position": [0,0,5], "focal_point": [0,0,0], "view_up": [0,1,0],
                        "parallel_projection": {v}}}"#
                ),
            );
            assert_eq!(load_camera(&p).unwrap().0.parallel_projection, parallel);
        }
    }

    #[test]
    fn transfer_function_points_must_be_in_order() {
        let dir = tempfile::tempdir().unwrap();
        let cases: &[(&str, &str, &str)] = &[
            (
                r#"{"color": [[0,0,0,0], [10,1,1,1], [5,1,1,1]], "scalar_opacity": [[0, 1]]}"#,
                "color[2]",
                "5",
            ),
            (
                r#"{"color": [[0,0,0,0]], "scalar_opacity": [[-5, 0], [300, 1], [200, 0.5], [100, 0]]}"#,
                "scalar_opacity[2]",
                "200",
            ),
            (
                r#"{"color": [[0,0,0,0]], "scalar_opacity": [[0, 1]],
                    "gradient_opacity": [[0, 0.5], [50, 1], [49.5, 1]]}"#,
                "gradient_opacity[2]",
                "49.5",
            ),
        ];
        for (text, field, value) in cases {
            let p = write(dir.path(), "unordered_tf.json", text);
            let e = load_transfer_function(&p).unwrap_err().to_string();
            assert!(
                e.contains(field)
                    && e.contains(value)
                    && e.contains("unordered_tf.json")
                    && e.contains("order"),
                "{text}: {e}"
            );
        }
        // Equal consecutive values make a step and stay allowed; the order is kept as written.
        let p = write(
            dir.path(),
            "step_tf.json",
            r#"{"color": [[0,0,0,0], [10,0,0,0], [10,1,1,1]],
                "scalar_opacity": [[0, 0], [10, 0], [10, 1], [20, 1]]}"#,
        );
        let (tf, _) = load_transfer_function(&p).unwrap();
        assert_eq!(tf.scalar_opacity[1], [10.0, 0.0]);
        assert_eq!(tf.scalar_opacity[2], [10.0, 1.0]);
        assert_eq!(tf.opacity_at(15.0), 1.0);
        assert_eq!(tf.opacity_at(5.0), 0.0);
    }

    #[test]
    fn errors_name_file_and_field() {
        let dir = tempfile::tempdir().unwrap();
        let cases: &[(&str, &str)] = &[
            (
                r#"{"focal_point": [0,0,0], "view_up": [0,1,0]}"#,
                "position",
            ),
            (
                r#"{"position": [0,0,5], "focal_point": [0,0,0], "view_up": "up", "parallel_projection": true}"#,
                "view_up",
            ),
            (
                r#"{"position": [0,0,5], "focal_point": [0,0], "view_up": [0,1,0], "parallel_projection": true}"#,
                "focal_point",
            ),
            (
                r#"{"position": [0,0,5], "focal_point": [0,0,0], "view_up": [0,1,0], "parallel_projection": 1}"#,
                "parallel_projection",
            ),
            (
                r#"{"position": [0,0,5], "focal_point": [0,0,0], "view_up": [0,0,1], "parallel_projection": false}"#,
                "view_up",
            ),
            (
                r#"{"position": [0,0,5], "focal_point": [0,0,0], "view_up": [0,1,0], "view_angle": 200, "parallel_projection": false}"#,
                "view_angle",
            ),
            (r#"[1, 2, 3]"#, "object"),
            (r#"{"position": [0,0,5],"#, "EOF"),
        ];
        for (text, field) in cases {
            let p = write(dir.path(), "bad_cam.json", text);
            let e = load_camera(&p).unwrap_err().to_string();
            assert!(
                e.contains(field) && e.contains("bad_cam.json"),
                "{text}: {e}"
            );
        }
        let tf_cases: &[(&str, &str)] = &[
            (r#"{"color": [[0,0,0,0]]}"#, "scalar_opacity"),
            (
                r#"{"color": [[0,0,0]], "scalar_opacity": [[0, 1]]}"#,
                "color",
            ),
            (
                r#"{"color": [[0,0,0,0]], "scalar_opacity": [[0, 1]], "gradient_opacity": 3}"#,
                "gradient_opacity",
            ),
            (
                r#"{"color": [[0,0,0,0]], "scalar_opacity": [[0, 1]], "ambient": 2}"#,
                "ambient",
            ),
            (
                r#"{"color": [[0,0,0,0]], "scalar_opacity": [], "shade": true}"#,
                "scalar_opacity",
            ),
        ];
        for (text, field) in tf_cases {
            let p = write(dir.path(), "bad_tf.json", text);
            let e = load_transfer_function(&p).unwrap_err().to_string();
            assert!(
                e.contains(field) && e.contains("bad_tf.json"),
                "{text}: {e}"
            );
        }
        let e = load_camera(dir.path().join("missing.json")).unwrap_err();
        assert!(e.to_string().contains("missing.json"), "{e}");
    }

    /// ParaView colour-map presets (issue 28 §6): the rules of `load_transfer_function_named`,
    /// which the command line's `--tf` and Python's `TransferFunction.load` share.
    #[test]
    fn paraview_presets_load_as_transfer_functions() {
        let dir = tempfile::tempdir().unwrap();
        let text = r#"[{"Name": "other", "RGBPoints": [0, 0, 0, 0, 1, 1, 1, 1]},
            {"Name": "bone", "ColorSpace": "Diverging", "Creator": "ParaView",
             "RGBPoints": [0, 0, 0, 0, 1500, 1, 0.8, 0.6, 3000, 1, 1, 1],
             "Points": [0, 0, 0.5, 0, 800, 0.1, 0.5, 0, 3000, 0.9, 0.5, 0],
             "Shade": true, "Specular": 0.4}]"#;
        let p = write(dir.path(), "pv.json", text);
        let l = Limits::default();
        let (tf, w) = load_transfer_function_named(&p, Some("bone"), &l).unwrap();
        assert_eq!(
            tf.color,
            vec![
                [0.0, 0.0, 0.0, 0.0],
                [1500.0, 1.0, 0.8, 0.6],
                [3000.0, 1.0, 1.0, 1.0]
            ]
        );
        assert_eq!(
            tf.scalar_opacity,
            vec![[0.0, 0.0], [800.0, 0.1], [3000.0, 0.9]]
        );
        assert!(
            tf.shade && tf.specular == 0.4 && tf.diffuse == 0.7,
            "{tf:?}"
        );
        assert_eq!(w.len(), 1, "{w:?}");
        assert!(w[0].contains("ColorSpace \"Diverging\""), "{w:?}");
        // Without a name: the first preset, a warning that there are two, and the default
        // opacity ramp over the colour range (no `Points`).
        let (first, w) = load_transfer_function(&p).unwrap();
        assert_eq!(
            first.color,
            vec![[0.0, 0.0, 0.0, 0.0], [1.0, 1.0, 1.0, 1.0]]
        );
        assert_eq!(first.scalar_opacity, vec![[0.0, 0.0], [1.0, 1.0]]);
        let all = w.join(" | ");
        assert!(
            all.contains("2 presets") && all.contains("\"other\"") && all.contains("no opacity"),
            "{all}"
        );
        // One object; a single colour value gets opacity 1; non-default midpoints warn.
        let p = write(dir.path(), "one.json", r#"{"RGBPoints": [5, 1, 0, 0]}"#);
        let (tf, _) = load_transfer_function(&p).unwrap();
        assert_eq!(tf.scalar_opacity, vec![[5.0, 1.0]]);
        let p = write(
            dir.path(),
            "mid.json",
            r#"[{"RGBPoints": [0, 0, 0, 0, 1, 1, 1, 1], "Points": [0, 0, 0.3, 0, 1, 1, 0.5, 0]}]"#,
        );
        let (tf, w) = load_transfer_function(&p).unwrap();
        assert_eq!(tf.scalar_opacity, vec![[0.0, 0.0], [1.0, 1.0]]);
        assert!(w.len() == 1 && w[0].contains("midpoint"), "{w:?}");
        // A volsplat file is not a preset list.
        let p = write(dir.path(), "tf.json", DESIGN_TF);
        let e = load_transfer_function_named(&p, Some("bone"), &l)
            .unwrap_err()
            .to_string();
        assert!(e.contains("ParaView") && e.contains("tf.json"), "{e}");
    }

    /// A byte-order mark (Windows Notepad) before the JSON is accepted; a ParaView indexed map
    /// (no `RGBPoints`) is named as such, not as "expected a JSON object".
    #[test]
    fn a_byte_order_mark_is_read_and_indexed_maps_are_named() {
        let dir = tempfile::tempdir().unwrap();
        let p = write(dir.path(), "bom.json", &format!("\u{feff}{DESIGN_TF}"));
        let (tf, _) = load_transfer_function(&p).unwrap();
        assert!(!tf.color.is_empty());
        let p = write(
            dir.path(),
            "indexed.json",
            r#"[{"Name":"Indexed","IndexedColors":[1,0,0,0,1,0],"Annotations":["0","a","1","b"]}]"#,
        );
        let e = load_transfer_function(&p).unwrap_err().to_string();
        assert!(e.contains("without `RGBPoints`"), "{e}");
    }

    #[test]
    fn paraview_errors_name_file_and_field() {
        let dir = tempfile::tempdir().unwrap();
        let cases: &[(&str, &str)] = &[
            (r#"[{"RGBPoints": [0, 0, 0]}]"#, "`RGBPoints`"),
            (r#"[{"RGBPoints": []}]"#, "`RGBPoints`"),
            (r#"[{"RGBPoints": "jet"}]"#, "`RGBPoints`"),
            (r#"[{"RGBPoints": [0, 0, 0, "red"]}]"#, "`RGBPoints[3]`"),
            (
                r#"[{"RGBPoints": [0, 0, 0, 0], "Points": [0, 1, 0.5]}]"#,
                "`Points`",
            ),
            (
                r#"[{"RGBPoints": [0, 0, 0, 0], "Points": [0, "x", 0.5, 0]}]"#,
                "`Points[1]`",
            ),
            (r#"[{"RGBPoints": [0, 0, 0, 0], "Shade": 1}]"#, "`Shade`"),
            (
                r#"[{"Name": "up-down", "RGBPoints": [10, 0, 0, 0, 5, 1, 1, 1]}]"#,
                "color[1]",
            ),
            (r#"[{"RGBPoints": [0, 2, 0, 0]}]"#, "color[0]"),
            (
                r#"[{"RGBPoints": [0, 0, 0, 0], "Points": [0, 1.5, 0.5, 0]}]"#,
                "scalar_opacity[0]",
            ),
        ];
        for (text, field) in cases {
            let p = write(dir.path(), "bad_pv.json", text);
            let e = load_transfer_function(&p).unwrap_err().to_string();
            assert!(
                e.contains(field) && e.contains("bad_pv.json"),
                "{text}: {e}"
            );
        }
        let p = write(
            dir.path(),
            "pv.json",
            r#"[{"Name": "a", "RGBPoints": [0, 0, 0, 0]}, {"Name": "b", "RGBPoints": [0, 0, 0, 0]}]"#,
        );
        let e = load_transfer_function_named(&p, Some("c"), &Limits::default())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("no preset named \"c\"") && e.contains("\"a\", \"b\""),
            "{e}"
        );
        // A list without presets stays an error of volsplat's format.
        let p = write(dir.path(), "list.json", r#"[{"Name": "a"}]"#);
        let e = load_transfer_function(&p).unwrap_err().to_string();
        assert!(e.contains("object"), "{e}");
    }

    #[test]
    fn camera_and_tf_save_load_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let cam = Camera {
            position: [1.5, -2.25, 10.0],
            focal_point: [0.1, 0.2, 0.3],
            view_up: [0.0, 0.0, 1.0],
            view_angle: 42.5,
            parallel_projection: true,
            parallel_scale: 17.0,
        };
        let p = dir.path().join("cam.json");
        save_camera(&p, &cam).unwrap();
        let (back, w) = load_camera(&p).unwrap();
        assert!(w.is_empty());
        assert_eq!(back, cam);
        let text = std::fs::read_to_string(&p).unwrap();
        assert!(text.contains("\n  \"focal_point\""), "{text}");

        let mut tf = TransferFunction::ramp(-10.0, 300.0, 0.4);
        tf.gradient_opacity = Some(vec![[0.0, 0.5], [10.0, 1.0]]);
        tf.validate().unwrap();
        let p = dir.path().join("tf.json");
        save_transfer_function(&p, &tf).unwrap();
        let (back, _) = load_transfer_function(&p).unwrap();
        assert_eq!(back, tf);
    }
}
