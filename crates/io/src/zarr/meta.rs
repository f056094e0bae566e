//! OME-Zarr `multiscales` metadata (NGFF v0.4 in `.zattrs`, v0.5 in `zarr.json` under
//! `attributes.ome`), parsed from JSON by hand so that every error names the field and value.
//!
//! Specification: <https://ngff.openmicroscopy.org/0.4/#multiscale-md> and
//! <https://ngff.openmicroscopy.org/0.5/#multiscale-md>: `axes` (name, type, unit) ordered
//! time, channel (or custom), space; `datasets[i].path` and `coordinateTransformations` (one
//! `scale`, then at most one `translation`); optional multiscale-level transformations applied
//! after the datasets'.

use crate::error::{IoError, Result, clip};
use serde_json::Value;
use std::path::Path;

/// What an OME axis is (its `type`, or for v0.3-style string axes, its name).
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) enum AxisKind {
    /// `space`.
    Space,
    /// `time`.
    Time,
    /// `channel`.
    Channel,
    /// Any other type (custom axes); readable only when its size is 1.
    Other(String),
}

/// One OME axis.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Axis {
    pub name: String,
    pub kind: AxisKind,
    pub unit: Option<String>,
}

/// One level (`datasets[i]`): its array path and its full transformation (the dataset's, then
/// the multiscale's), per array dimension.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Dataset {
    pub path: String,
    pub scale: Vec<f64>,
    pub translation: Vec<f64>,
}

/// The first `multiscales` entry of a store.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Multiscales {
    /// `0.4`, `0.5`, ... as written (`unknown` where absent).
    pub version: String,
    pub axes: Vec<Axis>,
    pub datasets: Vec<Dataset>,
}

/// The largest JSON metadata document read (`zarr.json`, `.zattrs`): far above any real one.
pub(crate) const MAX_METADATA_BYTES: u64 = 16 << 20;

fn field_err(path: &Path, field: &str, value: &Value, reason: impl Into<String>) -> IoError {
    IoError::field(path, field, &clip(&value.to_string()), reason)
}

/// Parses the multiscales of a store root from its group attributes (`attrs`: the `.zattrs`
/// object or `zarr.json`'s `attributes`). `file` names the JSON file in errors.
pub(crate) fn parse(file: &Path, attrs: &Value) -> Result<Multiscales> {
    // v0.5: attributes.ome.{version, multiscales}; v0.4: attributes.multiscales[i].version.
    let (list, ome_version, prefix) = match attrs.get("ome") {
        Some(ome) => (
            ome.get("multiscales"),
            ome.get("version").and_then(Value::as_str),
            "attributes.ome.multiscales",
        ),
        None => (attrs.get("multiscales"), None, "multiscales"),
    };
    let list = list.ok_or_else(|| IoError::missing(file, prefix))?;
    let first = match list.as_array().map(Vec::as_slice) {
        Some([first, ..]) => first,
        _ => return Err(field_err(file, prefix, list, "must be a non-empty list")),
    };
    let at = format!("{prefix}[0]");
    let version = ome_version
        .or_else(|| first.get("version").and_then(Value::as_str))
        .unwrap_or("unknown")
        .to_string();
    let axes = parse_axes(file, &at, first)?;
    let n = axes.len();
    let outer = match first.get("coordinateTransformations") {
        Some(t) => Some(transforms(
            file,
            &format!("{at}.coordinateTransformations"),
            t,
            n,
        )?),
        None => None,
    };
    let datasets_v = first
        .get("datasets")
        .ok_or_else(|| IoError::missing(file, format!("{at}.datasets")))?;
    let items = match datasets_v.as_array() {
        Some(a) if !a.is_empty() => a,
        _ => {
            return Err(field_err(
                file,
                &format!("{at}.datasets"),
                datasets_v,
                "must be a non-empty list of levels",
            ));
        }
    };
    let mut datasets = Vec::with_capacity(items.len().min(64));
    for (i, d) in items.iter().enumerate() {
        let at_d = format!("{at}.datasets[{i}]");
        let path = dataset_path(file, &at_d, d)?;
        let t = d
            .get("coordinateTransformations")
            .ok_or_else(|| IoError::missing(file, format!("{at_d}.coordinateTransformations")))?;
        let (mut scale, mut translation) =
            transforms(file, &format!("{at_d}.coordinateTransformations"), t, n)?;
        if let Some((s2, t2)) = &outer {
            for a in 0..n {
                scale[a] *= s2[a];
                translation[a] = translation[a] * s2[a] + t2[a];
            }
        }
        datasets.push(Dataset {
            path,
            scale,
            translation,
        });
    }
    Ok(Multiscales {
        version,
        axes,
        datasets,
    })
}

/// `datasets[i].path`: a relative path of plain components (no `..`, no leading `/`), so a
/// level never leads out of the store.
fn dataset_path(file: &Path, at: &str, d: &Value) -> Result<String> {
    let field = format!("{at}.path");
    let v = d
        .get("path")
        .ok_or_else(|| IoError::missing(file, field.clone()))?;
    let Some(s) = v.as_str() else {
        return Err(field_err(file, &field, v, "must be a string"));
    };
    let ok = !s.is_empty()
        && !s.starts_with('/')
        && s.split('/').all(|c| !c.is_empty() && c != ".." && c != ".")
        && !s.contains('\\');
    if !ok {
        return Err(field_err(
            file,
            &field,
            v,
            "must be a relative path inside the store (no `..`, `.`, empty or absolute parts)",
        ));
    }
    Ok(s.to_string())
}

fn parse_axes(file: &Path, at: &str, m: &Value) -> Result<Vec<Axis>> {
    let field = format!("{at}.axes");
    let v = m.get("axes").ok_or_else(|| {
        IoError::unsupported(
            file,
            &field,
            "(absent)",
            "OME-Zarr 0.4 and 0.5 stores, which name their axes",
        )
    })?;
    let list = match v.as_array() {
        Some(a) if (2..=5).contains(&a.len()) => a,
        _ => return Err(field_err(file, &field, v, "must be a list of 2 to 5 axes")),
    };
    let mut axes = Vec::with_capacity(list.len());
    for (i, a) in list.iter().enumerate() {
        let at_a = format!("{field}[{i}]");
        let (name, kind, unit) = if let Some(s) = a.as_str() {
            // v0.3: axis names only.
            (s.to_string(), None, None)
        } else {
            let name = a
                .get("name")
                .and_then(Value::as_str)
                .ok_or_else(|| IoError::missing(file, format!("{at_a}.name")))?;
            let kind = a.get("type").map(|t| {
                t.as_str()
                    .map(str::to_string)
                    .ok_or_else(|| field_err(file, &format!("{at_a}.type"), t, "must be a string"))
            });
            let unit = match a.get("unit") {
                None | Some(Value::Null) => None,
                Some(u) => Some(
                    u.as_str()
                        .ok_or_else(|| {
                            field_err(file, &format!("{at_a}.unit"), u, "must be a string")
                        })?
                        .to_string(),
                ),
            };
            (name.to_string(), kind.transpose()?, unit)
        };
        let kind = match kind.as_deref().unwrap_or(match name.as_str() {
            "x" | "y" | "z" => "space",
            "t" => "time",
            "c" => "channel",
            other => other,
        }) {
            "space" => AxisKind::Space,
            "time" => AxisKind::Time,
            "channel" => AxisKind::Channel,
            other => AxisKind::Other(other.to_string()),
        };
        axes.push(Axis { name, kind, unit });
    }
    Ok(axes)
}

/// A `coordinateTransformations` list: one `scale` first, then at most one `translation`;
/// each of `n` finite numbers. Returns (scale, translation), translation 0 where absent.
fn transforms(file: &Path, at: &str, v: &Value, n: usize) -> Result<(Vec<f64>, Vec<f64>)> {
    let list = match v.as_array() {
        Some(a) if (1..=2).contains(&a.len()) => a,
        _ => {
            return Err(field_err(
                file,
                at,
                v,
                "must hold one `scale`, optionally followed by one `translation`",
            ));
        }
    };
    let mut scale = None;
    let mut translation = vec![0.0; n];
    for (i, t) in list.iter().enumerate() {
        let at_t = format!("{at}[{i}]");
        let kind = t.get("type").and_then(Value::as_str).unwrap_or("");
        let want = if i == 0 { "scale" } else { "translation" };
        if kind != want {
            return Err(field_err(
                file,
                &format!("{at_t}.type"),
                t.get("type").unwrap_or(&Value::Null),
                format!("expected `{want}` here (a scale first, then a translation)"),
            ));
        }
        let values = t.get(kind).ok_or_else(|| {
            if t.get("path").is_some() {
                IoError::unsupported(
                    file,
                    format!("{at_t}.path"),
                    &t["path"].to_string(),
                    "transformations given inline as lists of numbers",
                )
            } else {
                IoError::missing(file, format!("{at_t}.{kind}"))
            }
        })?;
        let nums = numbers(file, &format!("{at_t}.{kind}"), values, n)?;
        if i == 0 {
            scale = Some(nums);
        } else {
            translation = nums;
        }
    }
    Ok((scale.unwrap_or_else(|| vec![1.0; n]), translation))
}

fn numbers(file: &Path, at: &str, v: &Value, n: usize) -> Result<Vec<f64>> {
    let list = match v.as_array() {
        Some(a) if a.len() == n => a,
        _ => {
            return Err(field_err(
                file,
                at,
                v,
                format!("must be a list of {n} numbers, one per axis"),
            ));
        }
    };
    list.iter()
        .enumerate()
        .map(|(i, x)| match x.as_f64() {
            Some(f) if f.is_finite() => Ok(f),
            _ => Err(field_err(
                file,
                &format!("{at}[{i}]"),
                x,
                "must be a finite number",
            )),
        })
        .collect()
}

/// Millimetres per unit for the OME length units (UDUNITS-2 names, as the specification
/// lists them) and a few common spellings; `None` for others.
pub(crate) fn mm_per_unit(unit: &str) -> Option<f64> {
    Some(match unit {
        "angstrom" => 1e-7,
        "picometer" => 1e-9,
        "nanometer" | "nm" => 1e-6,
        "micrometer" | "micron" | "um" | "µm" | "μm" => 1e-3,
        "millimeter" | "mm" => 1.0,
        "centimeter" | "cm" => 10.0,
        "decimeter" => 100.0,
        "meter" | "m" => 1e3,
        "kilometer" => 1e6,
        "inch" => 25.4,
        "foot" => 304.8,
        _ => return None,
    })
}
