//! Camera and transfer-function JSON files (DESIGN.md §3; the README's "Files" section).
//!
//! Both are JSON objects. Unknown top-level fields are ignored with a warning (returned to the
//! caller, which decides whether to print it); missing required fields and wrong types are errors
//! naming the file and the field; the parsed value is then validated by `volsplat-core` (for a
//! transfer function: every point list in non-decreasing order of value, equal values allowed
//! for a step).
//! `//` line comments (outside strings) are removed before parsing, so the annotated examples of
//! DESIGN.md load as written. Files larger than [`MAX_JSON_BYTES`] are rejected.

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

/// The fields of a camera file (VTK's camera; DESIGN.md §3). `position`, `focal_point`,
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
/// data's own units, `scalar_opacity_unit_distance` in world units).
///
/// Every point list (`color`, `scalar_opacity`, `gradient_opacity`) must be in non-decreasing
/// order of value; equal consecutive values (a step) are allowed. An out-of-order point is an
/// error naming the file, the field, the point's index and its value.
///
/// Returns the validated transfer function and one warning per unknown top-level field.
pub fn load_transfer_function(path: impl AsRef<Path>) -> Result<(TransferFunction, Vec<String>)> {
    load_transfer_function_with(path, &Limits::default())
}

/// [`load_transfer_function`] with caller-set [`Limits`] (`max_json_bytes`).
pub fn load_transfer_function_with(
    path: impl AsRef<Path>,
    limits: &Limits,
) -> Result<(TransferFunction, Vec<String>)> {
    let path = path.as_ref();
    let (object, warnings) = load_object(path, TRANSFER_FUNCTION_FIELDS, limits.max_json_bytes)?;
    let template = serde_json::to_value(TransferFunction::ramp(0.0, 1.0, 1.0)).ok();
    let mut tf: TransferFunction = from_object(path, object, template)?;
    tf.validate().map_err(|e| IoError::core(path, e))?;
    Ok((tf, warnings))
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
/// Files may be pipes (`--camera <(…)`): reading is bounded by `max_bytes`, not by a size
/// found beforehand.
fn load_object(
    path: &Path,
    known: &[&str],
    max_bytes: u64,
) -> Result<(Map<String, Value>, Vec<String>)> {
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
    let text = strip_line_comments(&text);
    let value: Value = serde_json::from_str(&text).map_err(|e| IoError::Json {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
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
