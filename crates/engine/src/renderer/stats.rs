//! What a render reports: [`Progress`] during it, [`Stats`] after it, each built by conversion
//! from the drawing library's own counters.

use crate::request::{AntialiasChoice, ShadeAtChoice};
use serde::{Serialize, Serializer};
use std::fmt;
use volsplat_core::ProjectionKind;

/// The stage a render is in ([`Progress::stage`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "lowercase")]
#[non_exhaustive]
pub enum Stage {
    /// Loading or building the volume.
    Load,
    /// Building the classification state: CRIO tables, splat list, display volume, NIL map,
    /// bricks and pyramid levels.
    Classify,
    /// Drawing the frame.
    Render,
    /// Finished.
    Done,
}

impl Stage {
    /// The stage's name: `load`, `classify`, `render` or `done` (what Python's progress
    /// callback and the viewer receive).
    pub fn as_str(self) -> &'static str {
        match self {
            Stage::Load => "load",
            Stage::Classify => "classify",
            Stage::Render => "render",
            Stage::Done => "done",
        }
    }
}

impl fmt::Display for Stage {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Progress of a render, passed to the caller's callback.
#[derive(Debug, Clone, Copy, PartialEq)]
#[non_exhaustive]
pub struct Progress {
    /// Fraction done, in [0, 1].
    pub fraction: f64,
    /// What is being done.
    pub stage: Stage,
}

/// Which renderer actually drew an image: one name per renderer across the request
/// ([`crate::RendererChoice`]), these stats, the modules and `docs/architecture.md`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "kebab-case")]
#[non_exhaustive]
pub enum UsedRenderer {
    /// Westover's dense orthographic sheet-buffer renderer (`volsplat_splat::render`).
    Sheets,
    /// The sparse splat list (`volsplat_splat::list`), orthographic or perspective.
    SplatList,
    /// Image-aligned, post-classified slabs (`volsplat_splat::slab`), orthographic or
    /// perspective.
    Slab,
    /// Sabella's display (`volsplat_filter::display`).
    Sabella,
    /// A Chapter 6 display with NIL maps or direct quadrature (`volsplat_filter::display`).
    Nil,
}

impl UsedRenderer {
    /// The renderer's name in messages (`sheet renderer`, `splat-list renderer`, …).
    pub fn name(self) -> &'static str {
        match self {
            UsedRenderer::Sheets => "sheet renderer",
            UsedRenderer::SplatList => "splat-list renderer",
            UsedRenderer::Slab => "image-aligned slab renderer",
            UsedRenderer::Sabella => "Sabella display",
            UsedRenderer::Nil => "NIL renderer",
        }
    }
}

impl fmt::Display for UsedRenderer {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// The renderer's name in messages ([`UsedRenderer::name`]).
pub fn renderer_name(r: UsedRenderer) -> &'static str {
    r.name()
}

/// The axis the sheets or slabs are stacked along ([`Stats::sheet_axis`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "lowercase")]
#[non_exhaustive]
pub enum SheetAxis {
    /// The lattice's first index axis.
    I,
    /// The second.
    J,
    /// The third.
    K,
    /// The view direction (image-aligned slabs).
    View,
}

impl SheetAxis {
    /// The axis of `volsplat_splat::RenderStats::sheet_axis`: 0, 1, 2 the lattice axes i, j,
    /// k; 3 the view direction (the slabs); `None` otherwise.
    pub fn from_index(axis: usize) -> Option<SheetAxis> {
        [SheetAxis::I, SheetAxis::J, SheetAxis::K, SheetAxis::View]
            .get(axis)
            .copied()
    }
}

/// Writes `None` as `""`, as these fields were strings before they were enums.
fn or_empty<T: Serialize, S: Serializer>(v: &Option<T>, s: S) -> Result<S::Ok, S::Error> {
    match v {
        Some(v) => v.serialize(s),
        None => s.serialize_str(""),
    }
}

/// Timings (milliseconds) and counters of one render: one type for every renderer. Fields a
/// renderer does not have are zero or absent.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
#[non_exhaustive]
pub struct Stats {
    /// The renderer that drew the image.
    pub renderer: Option<UsedRenderer>,
    /// `orthographic` or `perspective` (`""` in JSON when unset).
    #[serde(serialize_with = "or_empty")]
    pub projection: Option<ProjectionKind>,
    /// Loading or building the volume in this call (0 when the renderer kept it).
    pub load_ms: f64,
    /// Classification state built in this call: CRIO tables, splat list or display volume and
    /// NIL map (0 when kept from an earlier frame).
    pub prepare_ms: f64,
    /// Frame set-up of the splatting renderer: geometry, footprint table, classifier tables.
    pub setup_ms: f64,
    /// Transform + classification and shading (splatting).
    pub classify_ms: f64,
    /// Splatting into sheet buffers.
    pub splat_ms: f64,
    /// Compositing sheets.
    pub composite_ms: f64,
    /// The frame itself (excluding load and prepare).
    pub render_ms: f64,
    /// Everything in this call.
    pub total_ms: f64,
    /// Lattice points visited.
    pub voxels: u64,
    /// Samples splatted.
    pub splats: u64,
    /// Samples skipped because their footprint was already opaque.
    pub splats_terminated: u64,
    /// Perspective: splats clipped at the near plane.
    pub splats_clipped: u64,
    /// Splats widened by anti-aliasing.
    pub splats_widened: u64,
    /// Pixel updates (multiply–adds of one RGBA weight).
    pub pixel_updates: u64,
    /// Average pixels per splat.
    pub kernel_cost: f64,
    /// Kernel name.
    pub kernel: String,
    /// Anti-aliasing rule (`""` in JSON for the Chapter 6 displays, which have none).
    #[serde(serialize_with = "or_empty")]
    pub antialias: Option<AntialiasChoice>,
    /// Image-aligned slabs, shaded composite: where the lights were evaluated, `voxels` (VTK's
    /// order) or `samples` (also where `voxels` was asked for but the transfer function depends
    /// on more than the density; decision 0019). Absent otherwise.
    pub shade_at: Option<ShadeAtChoice>,
    /// Image-aligned slabs: rays per pixel and axis, area-averaged into each pixel, where the
    /// view is minified (anti-aliasing; decision 0020). Absent with one ray per pixel.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub supersampling: Option<f64>,
    /// Image-aligned slabs, composite: whether the slabs were classified by segment
    /// (pre-integrated; decision 0020). Absent otherwise.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub preintegrated: Option<bool>,
    /// Image-aligned slabs, composite: how sharp the transfer function's steepest ramp is
    /// against the data (`volsplat_splat::slab::ring_risk`; `auto` pre-integrates above 4).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ring_risk: Option<f64>,
    /// Image-aligned slabs asked for a pyramid level (`quality.level` other than `full`): the
    /// level drawn, 0 for the full volume (decision 0031). Absent otherwise.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub level: Option<usize>,
    /// With `level`: the smallest spacing of the level drawn, world units (`auto` keeps it at
    /// most √2 × `focal_pixel`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub level_spacing: Option<f64>,
    /// With `level`: the size of a pixel at the focal point, world units.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub focal_pixel: Option<f64>,
    /// Sheets.
    pub sheets: usize,
    /// Sheet-normal axis: `i`, `j` or `k`, `view` for the slabs (`""` in JSON for the
    /// Chapter 6 displays).
    #[serde(serialize_with = "or_empty")]
    pub sheet_axis: Option<SheetAxis>,
    /// World path between sheets along the view.
    pub sheet_spacing: f64,
    /// Footprint table entries.
    pub footprint_entries: usize,
    /// Footprint sub-pixel phases per axis.
    pub footprint_phases: usize,
    /// Footprint half-extent, pixels.
    pub footprint_half_extent_px: [f64; 2],
    /// Worker threads.
    pub threads: usize,
    /// Image width, pixels.
    pub width: usize,
    /// Image height, pixels.
    pub height: usize,
    /// Splat list: splats kept.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub list_splats: Option<usize>,
    /// Splat list: bytes.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub list_bytes: Option<usize>,
    /// Splat list: extraction time (whenever it was built).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub list_build_ms: Option<f64>,
    /// Chapter 6 displays: per-stage timings and counters.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub display: Option<DisplayStats>,
}

/// The splatting renderers' counters (sheets and splat list): every field the splat library
/// measures. The kernel and anti-aliasing rule come from the settings, not the counters.
impl From<&volsplat_splat::RenderStats> for Stats {
    fn from(s: &volsplat_splat::RenderStats) -> Stats {
        Stats {
            render_ms: s.total_ms,
            setup_ms: s.setup_ms,
            classify_ms: s.classify_ms,
            splat_ms: s.splat_ms,
            composite_ms: s.composite_ms,
            voxels: s.voxels,
            splats: s.splats,
            splats_terminated: s.splats_terminated,
            splats_clipped: s.splats_clipped,
            splats_widened: s.splats_widened,
            pixel_updates: s.pixel_updates,
            kernel_cost: s.kernel_cost(),
            sheets: s.sheets,
            sheet_axis: SheetAxis::from_index(s.sheet_axis),
            sheet_spacing: s.sheet_spacing,
            footprint_entries: s.footprint_entries,
            footprint_phases: s.footprint_phases,
            footprint_half_extent_px: s.footprint_half_extent,
            threads: s.threads,
            ..Stats::default()
        }
    }
}

impl From<volsplat_splat::Antialias> for AntialiasChoice {
    fn from(a: volsplat_splat::Antialias) -> AntialiasChoice {
        use volsplat_splat::Antialias;
        match a {
            Antialias::None => AntialiasChoice::None,
            Antialias::Swan => AntialiasChoice::Swan,
            Antialias::SwanPerpendicular => AntialiasChoice::SwanPerpendicular,
            Antialias::Ewa => AntialiasChoice::Ewa,
            Antialias::Area => AntialiasChoice::Area,
        }
    }
}

impl From<volsplat_splat::ShadeAt> for ShadeAtChoice {
    fn from(a: volsplat_splat::ShadeAt) -> ShadeAtChoice {
        match a {
            volsplat_splat::ShadeAt::Voxels => ShadeAtChoice::Voxels,
            volsplat_splat::ShadeAt::Samples => ShadeAtChoice::Samples,
        }
    }
}

/// Timings (milliseconds) and counters of a Chapter 6 display.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
#[non_exhaustive]
pub struct DisplayStats {
    /// NIL map construction (whenever it was built; 0 without a map).
    pub map_build_ms: f64,
    /// Trigger placement.
    pub trigger_ms: f64,
    /// Patch selection.
    pub hierarchy_ms: f64,
    /// NIL control points.
    pub control_points_ms: f64,
    /// Evaluation.
    pub evaluation_ms: f64,
    /// Ray search.
    pub search_ms: f64,
    /// Ray marching.
    pub march_ms: f64,
    /// Pixels.
    pub pixels: u64,
    /// Rays that hit the volume.
    pub rays: u64,
    /// Trigger points.
    pub triggers: u64,
    /// NIL patches used.
    pub patches: u64,
    /// NIL evaluations that fell back to point sampling.
    pub fallbacks: u64,
}

/// The display's counters, seconds to milliseconds; the map's build time is the caller's
/// (`map_build_ms` 0 here).
impl From<&volsplat_filter::display::DisplayStats> for DisplayStats {
    fn from(s: &volsplat_filter::display::DisplayStats) -> DisplayStats {
        DisplayStats {
            map_build_ms: 0.0,
            trigger_ms: s.trigger_s * 1e3,
            hierarchy_ms: s.hierarchy_s * 1e3,
            control_points_ms: s.control_s * 1e3,
            evaluation_ms: s.evaluation_s * 1e3,
            search_ms: s.search_s * 1e3,
            march_ms: s.march_s * 1e3,
            pixels: s.pixels,
            rays: s.rays,
            triggers: s.triggers,
            patches: s.patches,
            fallbacks: s.fallbacks,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The enums write the strings the fields held before they were enums (`--stats` JSON and
    /// Python's `stats` dictionary read them).
    #[test]
    fn stats_json_keeps_its_strings() {
        let j = |s: &Stats| serde_json::to_value(s).unwrap();
        let empty = j(&Stats::default());
        for field in ["projection", "antialias", "sheet_axis"] {
            assert_eq!(empty[field], "", "{field}");
        }
        assert!(empty["shade_at"].is_null());
        assert!(empty["renderer"].is_null());
        let s = Stats {
            renderer: Some(UsedRenderer::Sheets),
            projection: Some(ProjectionKind::Perspective),
            antialias: Some(AntialiasChoice::SwanPerpendicular),
            shade_at: Some(ShadeAtChoice::Samples),
            sheet_axis: Some(SheetAxis::View),
            ..Stats::default()
        };
        let v = j(&s);
        assert_eq!(v["renderer"], "sheets");
        assert_eq!(v["projection"], "perspective");
        assert_eq!(v["antialias"], "swan-perpendicular");
        assert_eq!(v["shade_at"], "samples");
        assert_eq!(v["sheet_axis"], "view");
        let names = |r| serde_json::to_value(r).unwrap();
        assert_eq!(names(UsedRenderer::SplatList), "splat-list");
        assert_eq!(names(UsedRenderer::Slab), "slab");
        assert_eq!(names(UsedRenderer::Sabella), "sabella");
        assert_eq!(names(UsedRenderer::Nil), "nil");
        assert_eq!(
            j(&Stats {
                projection: Some(ProjectionKind::Orthographic),
                ..s
            })["projection"],
            "orthographic"
        );
    }

    /// Every splat-library anti-aliasing rule keeps its name, and the sheet axes their
    /// letters; a stage prints as the string it replaced.
    #[test]
    fn names_match_the_libraries() {
        use volsplat_splat::Antialias;
        for a in [
            Antialias::None,
            Antialias::Swan,
            Antialias::SwanPerpendicular,
            Antialias::Ewa,
            Antialias::Area,
        ] {
            let c = AntialiasChoice::from(a);
            assert_eq!(serde_json::to_value(c).unwrap(), a.name());
        }
        let axes: Vec<_> = (0..5).map(SheetAxis::from_index).collect();
        assert_eq!(
            axes,
            [
                Some(SheetAxis::I),
                Some(SheetAxis::J),
                Some(SheetAxis::K),
                Some(SheetAxis::View),
                None
            ]
        );
        for (s, name) in [
            (Stage::Load, "load"),
            (Stage::Classify, "classify"),
            (Stage::Render, "render"),
            (Stage::Done, "done"),
        ] {
            assert_eq!(s.to_string(), name);
            assert_eq!(serde_json::to_value(s).unwrap(), name);
        }
    }

    /// The conversions carry every counter across (milliseconds from seconds for the
    /// displays).
    #[test]
    fn conversions_carry_every_counter() {
        let s = {
            let mut s = volsplat_splat::RenderStats::default();
            s.setup_ms = 1.0;
            s.classify_ms = 2.0;
            s.splat_ms = 3.0;
            s.composite_ms = 4.0;
            s.total_ms = 10.0;
            s.voxels = 5;
            s.splats = 4;
            s.splats_terminated = 3;
            s.splats_clipped = 2;
            s.splats_widened = 1;
            s.pixel_updates = 12;
            s.sheets = 7;
            s.sheet_axis = 1;
            s.sheet_spacing = 0.5;
            s.footprint_entries = 9;
            s.footprint_phases = 8;
            s.footprint_half_extent = [1.5, 2.5];
            s.threads = 3;
            s
        };
        let t = Stats::from(&s);
        assert_eq!(
            (
                t.render_ms,
                t.setup_ms,
                t.classify_ms,
                t.splat_ms,
                t.composite_ms
            ),
            (10.0, 1.0, 2.0, 3.0, 4.0)
        );
        assert_eq!(
            (
                t.voxels,
                t.splats,
                t.splats_terminated,
                t.splats_clipped,
                t.splats_widened
            ),
            (5, 4, 3, 2, 1)
        );
        assert_eq!((t.pixel_updates, t.kernel_cost), (12, 3.0));
        assert_eq!(
            (t.sheets, t.sheet_axis, t.sheet_spacing),
            (7, Some(SheetAxis::J), 0.5)
        );
        assert_eq!(
            (
                t.footprint_entries,
                t.footprint_phases,
                t.footprint_half_extent_px,
                t.threads
            ),
            (9, 8, [1.5, 2.5], 3)
        );
        let d = volsplat_filter::display::DisplayStats {
            trigger_s: 0.001,
            hierarchy_s: 0.002,
            control_s: 0.003,
            evaluation_s: 0.004,
            search_s: 0.005,
            march_s: 0.006,
            total_s: 1.0,
            pixels: 6,
            rays: 5,
            triggers: 4,
            patches: 3,
            fallbacks: 2,
        };
        let e = DisplayStats::from(&d);
        let close = |a: f64, b: f64| (a - b).abs() < 1e-12;
        assert!(close(e.trigger_ms, 1.0) && close(e.hierarchy_ms, 2.0));
        assert!(close(e.control_points_ms, 3.0) && close(e.evaluation_ms, 4.0));
        assert!(close(e.search_ms, 5.0) && close(e.march_ms, 6.0));
        assert_eq!(
            (e.pixels, e.rays, e.triggers, e.patches, e.fallbacks),
            (6, 5, 4, 3, 2)
        );
        assert_eq!(e.map_build_ms, 0.0);
    }
}
