//! Rendering a texture scene with one filtering technique: one value per pixel, in parallel
//! over rows (deterministic: every pixel is computed independently).

use crate::clamp::{ClampSettings, clamped_sample};
use crate::direct::{DirectSettings, filter_direct};
use crate::error::{FilterError, Result};
use crate::ewa::{EwaSettings, EwaTable, filter_ewa};
use crate::filters::FilterKind;
use crate::nil::{
    CosineNilMap, DiscreteNilMap, DiscreteNilSettings, NilScratch, NilSettings, NilSource,
    nil_filter_box,
};
use crate::region::OrientedBox;
use crate::scene::{Footprint, PixelFootprint, Scene};
use crate::texture::SolidTexture;
use rayon::prelude::*;
use std::time::Instant;
use volsplat_core::ScalarImage;

/// Which integration box a box-based technique uses (thesis §4-2).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum RegionKind {
    /// `V_tan` (opaque materials).
    Tangent,
    /// `V_ray` (translucent materials).
    Ray,
}

impl RegionKind {
    fn pick(self, fp: &PixelFootprint) -> &OrientedBox {
        match self {
            RegionKind::Tangent => &fp.v_tan,
            RegionKind::Ray => &fp.v_ray,
        }
    }
}

/// A filtering technique to render with.
#[derive(Debug, Clone, PartialEq)]
pub enum Technique {
    /// The texture at the pixel's ray hit (Plate 5.1).
    PointSample,
    /// Closed-form box average over `V_tan` (cosine textures only).
    ExactBox,
    /// Clamping (§4-1) with the `V_tan` half-axes as the footprint.
    Clamp(ClampSettings),
    /// Direct evaluation (§4-2).
    Direct {
        /// Quadrature and filter.
        settings: DirectSettings,
        /// Integration box.
        region: RegionKind,
    },
    /// 3-D EWA (§4-3).
    Ewa(EwaSettings),
    /// NIL maps (§4-4) of the texture (cosine: analytic; discrete: pyramid).
    Nil {
        /// Patch order `M`.
        order: usize,
        /// Hierarchy and evaluation settings.
        settings: NilSettings,
        /// The filter over `V_tan`.
        filter: FilterKind,
    },
}

/// A rendered image and its costs.
#[derive(Debug, Clone)]
pub struct Rendered {
    /// Grey values (row 0 at the top).
    pub image: ScalarImage,
    /// Wall-clock seconds for the per-pixel work (all threads).
    pub seconds: f64,
    /// Wall-clock seconds of pre-processing (NIL map build, EWA table).
    pub preprocess_seconds: f64,
    /// Texture evaluations (direct, EWA, point) or NIL patches, summed over pixels.
    pub work: u64,
    /// Pixels where the technique fell back (NIL scale collapse → point sample).
    pub fallbacks: usize,
    /// Row-major indices (`y·width + x`) of the pixels that fell back, ascending.
    pub fallback_pixels: Vec<usize>,
}

enum Prepared {
    None,
    Ewa(EwaTable),
    Nil(Box<dyn NilSource>),
}

/// Renders `scene` with `technique`. Background pixels get the scene background; pixels whose
/// footprint is degenerate get the texture's DC value (except point sampling, which samples
/// the hit).
pub fn render(
    scene: &Scene,
    texture: &dyn SolidTexture,
    technique: &Technique,
) -> Result<Rendered> {
    let t0 = Instant::now();
    let prepared = match technique {
        Technique::ExactBox if texture.as_cosine().is_none() => {
            return Err(FilterError::NotApplicable {
                technique: "exact box".into(),
                reason: "needs a cosine texture".into(),
            });
        }
        Technique::Clamp(c) => {
            c.validate()?;
            // Probe once so a texture without a spectrum fails before rendering.
            let probe = OrientedBox::axis_aligned(glam::DVec3::ZERO, glam::DVec3::ONE);
            clamped_sample(texture, &probe, c)?;
            Prepared::None
        }
        Technique::Direct { settings, .. } => {
            settings.validate()?;
            Prepared::None
        }
        Technique::Ewa(s) => Prepared::Ewa(EwaTable::new(s)?),
        Technique::Nil {
            order,
            settings,
            filter,
        } => {
            settings.validate()?;
            filter.validate()?;
            let src: Box<dyn NilSource> = if let Some(c) = texture.as_cosine() {
                Box::new(CosineNilMap::build(c, *order, 10)?)
            } else if let Some(d) = texture.as_discrete() {
                Box::new(DiscreteNilMap::build(
                    d,
                    &DiscreteNilSettings {
                        order: *order,
                        ..Default::default()
                    },
                )?)
            } else {
                return Err(FilterError::NotApplicable {
                    technique: "NIL maps".into(),
                    reason: format!(
                        "texture `{}` is neither a cosine series nor discrete",
                        texture.name()
                    ),
                });
            };
            Prepared::Nil(src)
        }
        _ => Prepared::None,
    };
    let preprocess_seconds = t0.elapsed().as_secs_f64();
    let (w, h) = (scene.width(), scene.height());
    let background = scene.settings().background;
    let eps = scene.settings().epsilon;
    let t1 = Instant::now();
    let rows: Vec<(Vec<f32>, u64, Vec<usize>)> = (0..h)
        .into_par_iter()
        .map(|y| {
            let mut row = Vec::with_capacity(w);
            let (mut work, mut fallbacks) = (0u64, Vec::new());
            let mut scratch = NilScratch::default();
            for x in 0..w {
                let v = match scene.footprint(x, y) {
                    Footprint::Background => background,
                    Footprint::Degenerate(hit) => match technique {
                        Technique::PointSample => {
                            work += 1;
                            texture.value(hit)
                        }
                        _ => texture.mean(),
                    },
                    Footprint::Hit(fp) => match (technique, &prepared) {
                        (Technique::PointSample, _) => {
                            work += 1;
                            texture.value(fp.hit)
                        }
                        (Technique::ExactBox, _) => texture
                            .as_cosine()
                            .map_or(0.0, |c| c.box_average(&fp.v_tan)),
                        (Technique::Clamp(c), _) => {
                            clamped_sample(texture, &fp.v_tan, c).unwrap_or(0.0)
                        }
                        (Technique::Direct { settings, region }, _) => {
                            let r = filter_direct(texture, region.pick(&fp), settings);
                            work += r.evaluations;
                            r.value
                        }
                        (Technique::Ewa(s), Prepared::Ewa(table)) => {
                            let r = filter_ewa(texture, &fp, eps, s, table);
                            work += r.samples as u64;
                            r.value
                        }
                        (
                            Technique::Nil {
                                settings, filter, ..
                            },
                            Prepared::Nil(src),
                        ) => {
                            let r = nil_filter_box(
                                src.as_ref(),
                                &fp.v_tan,
                                *filter,
                                settings,
                                &mut scratch,
                            );
                            work += r.patches as u64;
                            if r.collapsed {
                                fallbacks.push(y * w + x);
                                texture.value(fp.v_tan.center)
                            } else {
                                r.value()
                            }
                        }
                        _ => 0.0,
                    },
                };
                row.push(v as f32);
            }
            (row, work, fallbacks)
        })
        .collect();
    let seconds = t1.elapsed().as_secs_f64();
    let mut values = Vec::with_capacity(w * h);
    let (mut work, mut fallback_pixels) = (0, Vec::new());
    for (r, wk, fb) in rows {
        values.extend(r);
        work += wk;
        fallback_pixels.extend(fb);
    }
    let image = ScalarImage::from_values(w, h, values)
        .ok_or_else(|| FilterError::invalid("image", (w, h), "internal size mismatch"))?;
    Ok(Rendered {
        image,
        seconds,
        preprocess_seconds,
        work,
        fallbacks: fallback_pixels.len(),
        fallback_pixels,
    })
}
