//! Westover's table-driven classification and shading: the CRIO process (Westover 1991, §3.6).
//!
//! Four lookup tables — emission colour, opacity, reflection colour and opacity modulation —
//! each indexed by a chosen quantity ([`TableIndex`]): density, gradient magnitude or depth.
//! Per sample (Westover §3.6.1, with correction 10 of `docs/papers.md`, "where the thesis is
//! wrong or silent"):
//!
//! ```text
//! I = clamp( E[iₑ] + Σ_lights Lc · ( R[iᵣ]·max(0, N·L) + S·max(0, N·H)^n ) )
//! A = (1 − (1 − O[iₒ])^(Δs/u)) · M[iₘ]
//! ```
//!
//! where `N` is the unit world-space gradient (central differences divided by `2·spacing`),
//! `S` is a constant specular colour (VTK) or the reflection colour (Westover), `Δs` the path
//! length one sample stands for and `u` the opacity unit distance. The opacity correction is
//! applied to the opacity table once per frame and the modulation multiplies afterwards, as VTK
//! does with gradient opacity. Samples whose opacity is zero are culled before shading
//! ("shade first", Westover §5.2).

use crate::camera::ViewFrame;
use crate::error::{CoreError, Result};
use crate::transfer::TransferFunction;
use glam::{DVec3, Vec3};

/// The quantity a CRIO table is indexed by.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TableIndex {
    /// The sample's value in data units.
    Density,
    /// The gradient magnitude in data units per world unit.
    GradientMagnitude,
    /// Depth along the view, normalised to [0, 1] over the volume's extent (0 = nearest corner).
    Depth,
}

/// A 1-D lookup table of `N`-vectors over `[lo, hi]` of its index quantity, linearly
/// interpolated and clamped at the ends.
#[derive(Debug, Clone, PartialEq)]
pub struct LookupTable<const N: usize> {
    /// What indexes the table.
    pub index: TableIndex,
    /// Index value of the first entry.
    pub lo: f32,
    /// Index value of the last entry (≥ `lo`).
    pub hi: f32,
    /// The entries, evenly spaced over `[lo, hi]`; at least one.
    pub values: Vec<[f32; N]>,
    scale: f32,
}

impl<const N: usize> LookupTable<N> {
    /// Samples `f` at `len` evenly spaced points of `[lo, hi]`.
    pub fn from_fn(
        index: TableIndex,
        lo: f64,
        hi: f64,
        len: usize,
        f: impl Fn(f64) -> [f64; N],
    ) -> Self {
        let len = if hi > lo { len.max(2) } else { 1 };
        let values = (0..len)
            .map(|n| {
                let x = if len == 1 {
                    lo
                } else {
                    lo + (hi - lo) * n as f64 / (len - 1) as f64
                };
                f(x).map(|v| v as f32)
            })
            .collect();
        Self::from_values(index, lo as f32, hi as f32, values)
    }

    /// A table from explicit entries evenly spaced over `[lo, hi]`.
    pub fn from_values(index: TableIndex, lo: f32, hi: f32, values: Vec<[f32; N]>) -> Self {
        let scale = if values.len() > 1 && hi > lo {
            (values.len() - 1) as f32 / (hi - lo)
        } else {
            0.0
        };
        LookupTable {
            index,
            lo,
            hi,
            values,
            scale,
        }
    }

    /// A table with one constant entry.
    pub fn constant(value: [f32; N]) -> Self {
        Self::from_values(TableIndex::Density, 0.0, 0.0, vec![value])
    }

    /// The interpolated entry at index value `x`.
    #[inline(always)]
    pub fn lookup(&self, x: f32) -> [f32; N] {
        let n = self.values.len();
        if n == 1 {
            return self.values[0];
        }
        let t = (x - self.lo) * self.scale;
        if t.is_nan() || t <= 0.0 {
            return self.values[0];
        }
        let i = t as usize;
        if i >= n - 1 {
            return self.values[n - 1];
        }
        let f = t - i as f32;
        let a = self.values[i];
        let b = self.values[i + 1];
        let mut out = a;
        for c in 0..N {
            out[c] = a[c] + f * (b[c] - a[c]);
        }
        out
    }

    /// Applies `f` to every entry.
    pub fn map(&self, f: impl Fn([f32; N]) -> [f32; N]) -> Self {
        Self::from_values(
            self.index,
            self.lo,
            self.hi,
            self.values.iter().map(|v| f(*v)).collect(),
        )
    }
}

/// An infinitely distant light (Westover §3.6.1).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Light {
    /// Unit direction *towards* the light. In the camera frame (x right, y up, z towards the
    /// viewer) when `follow_camera`, else in world coordinates.
    pub direction: [f64; 3],
    /// Diffuse and specular colour of the light (linear RGB, typically in [0, 1]).
    pub color: [f32; 3],
    /// Ambient colour of the light, multiplying a transfer function's `ambient` coefficient.
    /// Black by default, as `vtkLight`'s, so `ambient` has no effect under the default
    /// headlight, exactly as in VTK's volume mappers.
    pub ambient_color: [f32; 3],
    /// Whether `direction` is relative to the camera (a headlight is `(0, 0, 1)`).
    pub follow_camera: bool,
}

impl Light {
    /// VTK's default light: a white headlight with a black ambient colour.
    pub fn headlight() -> Self {
        Light {
            direction: [0.0, 0.0, 1.0],
            color: [1.0; 3],
            ambient_color: [0.0; 3],
            follow_camera: true,
        }
    }
}

/// Where the specular colour comes from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SpecularColor {
    /// A constant colour (VTK: `specular` × white).
    Constant([f32; 3]),
    /// The reflection table's colour (Westover's `I_spec = T_refl · (H·G)^n`).
    Reflection,
}

/// Illumination switches and parameters (Westover §3.6.1).
#[derive(Debug, Clone, PartialEq)]
pub struct Shading {
    /// Include the emission term.
    pub emission: bool,
    /// Include the diffuse term.
    pub diffuse: bool,
    /// Include the specular term.
    pub specular: bool,
    /// Specular colour source.
    pub specular_color: SpecularColor,
    /// Specular exponent `n` ≥ 0.
    pub specular_power: f32,
    /// Light both faces of a surface (`|N·L|`), as VTK's default two-sided lighting does.
    pub two_sided: bool,
    /// The lights; their contributions add.
    pub lights: Vec<Light>,
}

impl Default for Shading {
    /// Emission only, one headlight available.
    fn default() -> Self {
        Shading {
            emission: true,
            diffuse: false,
            specular: false,
            specular_color: SpecularColor::Constant([0.2; 3]),
            specular_power: 10.0,
            two_sided: true,
            lights: vec![Light::headlight()],
        }
    }
}

/// Westover's four CRIO tables plus shading parameters.
#[derive(Debug, Clone, PartialEq)]
pub struct CrioTables {
    /// Emitted colour (RGB in [0, 1]).
    pub emission: LookupTable<3>,
    /// Base opacity in [0, 1], defined for a path of `opacity_unit_distance`.
    pub opacity: LookupTable<1>,
    /// Reflected (diffuse) colour, RGB.
    pub reflection: LookupTable<3>,
    /// Opacity modulation factor in [0, 1] (surface enhancement, depth cueing, gradient opacity).
    pub modulation: LookupTable<1>,
    /// World-space path length for which `opacity` is defined (> 0).
    pub opacity_unit_distance: f64,
    /// Illumination.
    pub shading: Shading,
}

/// Default number of entries of the tables compiled from a transfer function.
pub const DEFAULT_TABLE_LEN: usize = 4096;

impl CrioTables {
    /// Compiles a VTK-style transfer function into the four tables (docs/design.md §3), lit by VTK's
    /// default white two-sided headlight: see [`CrioTables::from_transfer_function_lit`].
    pub fn from_transfer_function(tf: &TransferFunction, table_len: usize) -> Result<Self> {
        Self::from_transfer_function_lit(tf, table_len, vec![Light::headlight()])
    }

    /// Compiles a VTK-style transfer function for the given lights, following
    /// `vtkEncodedGradientShader` (the shading of VTK's CPU ray caster):
    /// unshaded, emission = colour; shaded, emission = `ambient` × colour × Σ light ambient
    /// colours (zero under VTK's default lights), reflection = `diffuse` × colour, specular =
    /// `specular` × light colour, added only where `N·L > 0`; opacity = scalar opacity;
    /// modulation = gradient opacity (or 1).
    pub fn from_transfer_function_lit(
        tf: &TransferFunction,
        table_len: usize,
        lights: Vec<Light>,
    ) -> Result<Self> {
        let mut tf = tf.clone();
        tf.validate()?;
        let (clo, chi) = (tf.color[0][0], tf.color[tf.color.len() - 1][0]);
        let (olo, ohi) = (
            tf.scalar_opacity[0][0],
            tf.scalar_opacity[tf.scalar_opacity.len() - 1][0],
        );
        let ambient_light = lights.iter().fold([0.0f64; 3], |acc, l| {
            [
                acc[0] + l.ambient_color[0] as f64,
                acc[1] + l.ambient_color[1] as f64,
                acc[2] + l.ambient_color[2] as f64,
            ]
        });
        let ambient = if tf.shade {
            ambient_light.map(|a| a * tf.ambient)
        } else {
            [1.0; 3]
        };
        let emission = LookupTable::from_fn(TableIndex::Density, clo, chi, table_len, |x| {
            let c = tf.color_at(x);
            [c[0] * ambient[0], c[1] * ambient[1], c[2] * ambient[2]]
        });
        let reflection = LookupTable::from_fn(TableIndex::Density, clo, chi, table_len, |x| {
            tf.color_at(x).map(|c| c * tf.diffuse)
        });
        let opacity = LookupTable::from_fn(TableIndex::Density, olo, ohi, table_len, |x| {
            [tf.opacity_at(x)]
        });
        let modulation = match &tf.gradient_opacity {
            None => LookupTable::constant([1.0]),
            Some(g) => LookupTable::from_fn(
                TableIndex::GradientMagnitude,
                g[0][0],
                g[g.len() - 1][0],
                table_len,
                |x| [tf.gradient_opacity_at(x)],
            ),
        };
        let s = tf.specular as f32;
        Ok(CrioTables {
            emission,
            opacity,
            reflection,
            modulation,
            opacity_unit_distance: tf.scalar_opacity_unit_distance,
            shading: Shading {
                emission: true,
                diffuse: tf.shade,
                specular: tf.shade && tf.specular > 0.0,
                specular_color: SpecularColor::Constant([s; 3]),
                specular_power: tf.specular_power as f32,
                two_sided: true,
                lights,
            },
        })
    }

    /// Surface enhancement (Westover §3.6.2, Fig 3.04): modulation becomes a 0 → 1 ramp on
    /// gradient magnitude over `[lo, hi]` (data units per world unit).
    pub fn with_surface_enhancement(mut self, lo: f64, hi: f64) -> Result<Self> {
        if !(lo.is_finite() && hi.is_finite() && hi > lo && lo >= 0.0) {
            return Err(CoreError::invalid(
                "surface enhancement ramp",
                (lo, hi),
                "needs 0 ≤ lo < hi",
            ));
        }
        self.modulation = LookupTable::from_fn(TableIndex::GradientMagnitude, lo, hi, 2, |x| {
            [((x - lo) / (hi - lo)).clamp(0.0, 1.0)]
        });
        Ok(self)
    }

    /// Depth cueing (Westover §3.6.2, Fig 3.05): modulation becomes a linear ramp on normalised
    /// depth from `near` (at depth 0) to `far` (at depth 1), both in [0, 1].
    pub fn with_depth_cue(mut self, near: f64, far: f64) -> Result<Self> {
        for (name, v) in [("depth cue near", near), ("depth cue far", far)] {
            if !(0.0..=1.0).contains(&v) {
                return Err(CoreError::invalid(name, v, "must be in [0, 1]"));
            }
        }
        self.modulation =
            LookupTable::from_fn(
                TableIndex::Depth,
                0.0,
                1.0,
                2,
                |x| [near + (far - near) * x],
            );
        Ok(self)
    }

    /// Whether the opacity, emission and reflection tables are indexed by density and the
    /// modulation is one constant entry: then classification before shading depends on the
    /// density alone, and renderers may tabulate it per density
    /// ([`FrameClassifier::surface_terms`] is `Some` exactly then).
    pub fn density_only(&self) -> bool {
        [
            self.opacity.index,
            self.emission.index,
            self.reflection.index,
        ]
        .iter()
        .all(|&i| i == TableIndex::Density)
            && self.modulation.values.len() == 1
    }

    /// Whether any table or the shading needs the gradient.
    pub fn needs_gradient(&self) -> bool {
        self.shading.diffuse
            || self.shading.specular
            || [self.emission.index, self.reflection.index].contains(&TableIndex::GradientMagnitude)
            || [self.opacity.index, self.modulation.index].contains(&TableIndex::GradientMagnitude)
    }
}

/// Inputs of one CRIO evaluation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SampleInput {
    /// Value in data units.
    pub density: f32,
    /// World-space gradient, data units per world unit (zero if not needed).
    pub gradient: Vec3,
    /// Normalised depth in [0, 1].
    pub depth: f32,
}

/// Opacity (step-corrected), emission and reflection fused into one density-indexed table, so
/// a sample needs one lookup instead of three (used when all three are indexed by density).
struct FusedDensityTable {
    lo: f32,
    scale: f32,
    last: f32,
    /// `[α, e_r, e_g, e_b, r_r, r_g, r_b, 0]` per entry.
    values: Vec<[f32; 8]>,
}

impl FusedDensityTable {
    const LEN: usize = 4096;

    fn new(
        opacity: &LookupTable<1>,
        emission: &LookupTable<3>,
        reflection: &LookupTable<3>,
    ) -> Option<Self> {
        let tables = [opacity.index, emission.index, reflection.index];
        if tables.iter().any(|&i| i != TableIndex::Density) {
            return None;
        }
        let lo = opacity.lo.min(emission.lo).min(reflection.lo);
        let hi = opacity.hi.max(emission.hi).max(reflection.hi);
        let n = if hi > lo { Self::LEN } else { 1 };
        let values = (0..n)
            .map(|k| {
                let x = if n == 1 {
                    lo
                } else {
                    lo + (hi - lo) * k as f32 / (n - 1) as f32
                };
                let ([a], e, r) = (opacity.lookup(x), emission.lookup(x), reflection.lookup(x));
                [a, e[0], e[1], e[2], r[0], r[1], r[2], 0.0]
            })
            .collect();
        let scale = if n > 1 {
            (n - 1) as f32 / (hi - lo)
        } else {
            0.0
        };
        Some(FusedDensityTable {
            lo,
            scale,
            last: (n - 1) as f32,
            values,
        })
    }

    /// Linearly interpolated opacity only (the cull test).
    #[inline(always)]
    fn alpha(&self, density: f32) -> f32 {
        let t = ((density - self.lo) * self.scale).max(0.0).min(self.last);
        let i = t as usize;
        let f = t - i as f32;
        let a = self.values[i][0];
        let b = self.values[(i + 1).min(self.values.len() - 1)][0];
        a + f * (b - a)
    }

    /// Linearly interpolated entry; NaN maps to the first entry.
    #[inline(always)]
    fn lookup(&self, density: f32) -> [f32; 8] {
        let t = ((density - self.lo) * self.scale).max(0.0).min(self.last);
        let i = t as usize;
        let f = t - i as f32;
        let a = &self.values[i];
        let b = &self.values[(i + 1).min(self.values.len() - 1)];
        let mut out = [0.0; 8];
        for c in 0..8 {
            out[c] = a[c] + f * (b[c] - a[c]);
        }
        out
    }
}

/// One light prepared for a frame ([`FrameClassifier::lights`]): unit vectors in the world
/// frame and the light's RGB colour (each channel ≥ 0).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameLight {
    /// Unit direction towards the light (world frame).
    pub l: Vec3,
    /// Unit half-vector between `l` and the direction towards the viewer (Blinn), or `l` where
    /// the two are opposite.
    pub h: Vec3,
    /// RGB colour of the light.
    pub color: Vec3,
}

/// What [`FrameClassifier::classify`] combines for one density before it shades: the opacity
/// (step-corrected, modulated, in `[0, 1]`), the emission it adds (zero where the emission term
/// is off) and the reflection colour (RGB in `[0, 1]`) that the diffuse term (and a
/// reflection-coloured specular term) scales.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurfaceTerms {
    /// Opacity for the frame's step, in `[0, 1]`; `0` where the sample is culled.
    pub alpha: f32,
    /// Emitted RGB added before the lights (zero when [`Shading::emission`] is off).
    pub emission: [f32; 3],
    /// Reflection RGB.
    pub reflection: [f32; 3],
}

/// The CRIO tables prepared for one frame: opacity corrected for the step, lights in world
/// space, half-vectors computed once (Westover transforms lights once per frame, §3.6.1).
pub struct FrameClassifier {
    emission: LookupTable<3>,
    opacity: LookupTable<1>,
    reflection: LookupTable<3>,
    modulation: LookupTable<1>,
    shading: Shading,
    lights: Vec<FrameLight>,
    spec_pow: LookupTable<1>,
    fused: Option<FusedDensityTable>,
    constant_modulation: Option<f32>,
    /// Whether [`FrameClassifier::classify`] reads the gradient.
    pub needs_gradient: bool,
}

impl FrameClassifier {
    /// Prepares `tables` for a view with orthographic direction `frame.forward` and a sample
    /// path length of `step` world units (> 0).
    pub fn new(tables: &CrioTables, frame: &ViewFrame, step: f64) -> Self {
        let ratio = (step / tables.opacity_unit_distance) as f32;
        let opacity = tables.opacity.map(|[a]| {
            let a = a.clamp(0.0, 1.0);
            [if a >= 1.0 {
                1.0
            } else {
                1.0 - (1.0 - a).powf(ratio)
            }]
        });
        let to_viewer = (-frame.forward).normalize();
        let lights = tables
            .shading
            .lights
            .iter()
            .map(|light| {
                let d = DVec3::from(light.direction);
                let l_world = if light.follow_camera {
                    frame.right * d.x + frame.up * d.y + to_viewer * d.z
                } else {
                    d
                }
                .normalize();
                let h = (l_world + to_viewer).normalize_or(l_world);
                FrameLight {
                    l: l_world.as_vec3(),
                    h: h.as_vec3(),
                    color: Vec3::from(light.color),
                }
            })
            .collect();
        let p = tables.shading.specular_power as f64;
        let spec_pow = LookupTable::from_fn(TableIndex::Density, 0.0, 1.0, 4097, |x| [x.powf(p)]);
        let fused = FusedDensityTable::new(&opacity, &tables.emission, &tables.reflection);
        let constant_modulation =
            (tables.modulation.values.len() == 1).then(|| tables.modulation.values[0][0]);
        FrameClassifier {
            fused,
            constant_modulation,
            emission: tables.emission.clone(),
            opacity,
            reflection: tables.reflection.clone(),
            modulation: tables.modulation.clone(),
            shading: tables.shading.clone(),
            lights,
            spec_pow,
            needs_gradient: tables.needs_gradient(),
        }
    }

    /// The step-corrected opacity times modulation, without shading; `0` means the sample is
    /// culled.
    #[inline]
    pub fn opacity(&self, s: &SampleInput) -> f32 {
        let a = self.opacity.lookup(index_value(self.opacity.index, s))[0];
        if a <= 0.0 {
            return 0.0;
        }
        a * self
            .modulation
            .lookup(index_value(self.modulation.index, s))[0]
    }

    /// The lights of this frame, in the world frame.
    pub fn lights(&self) -> &[FrameLight] {
        &self.lights
    }

    /// The shading switches and parameters the classifier was made with.
    pub fn shading(&self) -> &Shading {
        &self.shading
    }

    /// The terms [`FrameClassifier::classify`] combines for `density` before it shades, where
    /// every table is indexed by density and the modulation is a constant (so that they depend
    /// on the density alone); `None` otherwise. Renderers that shade many samples build their
    /// own tables from these (the slab renderer's shaded kernel).
    pub fn surface_terms(&self, density: f32) -> Option<SurfaceTerms> {
        let (f, m) = (self.fused.as_ref()?, self.constant_modulation?);
        let v = f.lookup(density);
        let a = v[0] * m;
        let alpha = if a.is_nan() || a <= 0.0 {
            0.0
        } else {
            a.min(1.0)
        };
        let emission = if self.shading.emission {
            [v[1], v[2], v[3]]
        } else {
            [0.0; 3]
        };
        Some(SurfaceTerms {
            alpha,
            emission,
            reflection: [v[4], v[5], v[6]],
        })
    }

    /// Opacity-table value only when the opacity table is indexed by density (a cheap cull test
    /// before the gradient is computed); `None` if it is indexed by something else.
    #[inline]
    pub fn density_opacity(&self, density: f32) -> Option<f32> {
        if let Some(f) = &self.fused {
            return Some(f.alpha(density));
        }
        (self.opacity.index == TableIndex::Density).then(|| self.opacity.lookup(density)[0])
    }

    /// Classifies and shades one sample. Returns premultiplied `[r·a, g·a, b·a, a]`, or `None`
    /// when the opacity is zero (culled).
    #[inline]
    pub fn classify(&self, s: &SampleInput) -> Option<[f32; 4]> {
        // One fused lookup when every table is density-indexed; separate lookups otherwise.
        let (a, emission, refl) = match &self.fused {
            Some(f) => {
                let v = f.lookup(s.density);
                let m = match self.constant_modulation {
                    Some(m) => m,
                    None => self
                        .modulation
                        .lookup(index_value(self.modulation.index, s))[0],
                };
                (
                    v[0] * m,
                    Vec3::new(v[1], v[2], v[3]),
                    Vec3::new(v[4], v[5], v[6]),
                )
            }
            None => {
                let a = self.opacity(s);
                if a.is_nan() || a <= 0.0 {
                    return None;
                }
                (
                    a,
                    Vec3::from(self.emission.lookup(index_value(self.emission.index, s))),
                    Vec3::from(
                        self.reflection
                            .lookup(index_value(self.reflection.index, s)),
                    ),
                )
            }
        };
        if a.is_nan() || a <= 0.0 {
            return None;
        }
        let a = a.min(1.0);
        let sh = &self.shading;
        let mut c = Vec3::ZERO;
        if sh.emission {
            c += emission;
        }
        if sh.diffuse || sh.specular {
            let g2 = s.gradient.length_squared();
            if g2 > 0.0 {
                let n = s.gradient * g2.sqrt().recip();
                let spec_color = match sh.specular_color {
                    SpecularColor::Constant(c) => Vec3::from(c),
                    SpecularColor::Reflection => refl,
                };
                for light in &self.lights {
                    let mut ndl = n.dot(light.l);
                    let mut ndh = n.dot(light.h);
                    if sh.two_sided && ndl < 0.0 {
                        ndl = -ndl;
                        ndh = -ndh;
                    }
                    if sh.diffuse && ndl > 0.0 {
                        c += refl * light.color * ndl;
                    }
                    if sh.specular && ndl > 0.0 && ndh > 0.0 {
                        c += spec_color * light.color * self.spec_pow.lookup(ndh)[0];
                    }
                }
            }
        }
        let c = c.clamp(Vec3::ZERO, Vec3::ONE) * a;
        Some([c.x, c.y, c.z, a])
    }
}

#[inline(always)]
fn index_value(index: TableIndex, s: &SampleInput) -> f32 {
    match index {
        TableIndex::Density => s.density,
        TableIndex::GradientMagnitude => s.gradient.length(),
        TableIndex::Depth => s.depth,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Camera;

    fn frame() -> ViewFrame {
        Camera {
            parallel_projection: true,
            ..Camera::default()
        }
        .frame()
    }

    /// A headlight whose ambient colour is white, so `ambient` contributes.
    fn ambient_headlight() -> Light {
        Light {
            ambient_color: [1.0; 3],
            ..Light::headlight()
        }
    }

    /// VTK semantics: the default headlight has a black ambient colour, so `ambient` adds
    /// nothing (vtkEncodedGradientShader: ambient = Ka · light ambient colour).
    #[test]
    fn default_headlight_ignores_ambient_like_vtk() {
        let mut tf = TransferFunction::ramp(0.0, 1.0, 1.0);
        tf.color = vec![[0.0, 0.5, 0.5, 0.5]];
        tf.scalar_opacity = vec![[0.0, 1.0]];
        tf.shade = true;
        tf.ambient = 1.0;
        tf.diffuse = 0.0;
        tf.specular = 0.0;
        let t = CrioTables::from_transfer_function(&tf, 8).unwrap();
        let c = FrameClassifier::new(&t, &frame(), 1.0)
            .classify(&input(0.5, Vec3::Z))
            .unwrap();
        assert_eq!(&c[..3], &[0.0, 0.0, 0.0]);
        let lit =
            CrioTables::from_transfer_function_lit(&tf, 8, vec![ambient_headlight()]).unwrap();
        let c = FrameClassifier::new(&lit, &frame(), 1.0)
            .classify(&input(0.5, Vec3::Z))
            .unwrap();
        assert!((c[0] - 0.5).abs() < 1e-6);
    }

    fn input(density: f32, gradient: Vec3) -> SampleInput {
        SampleInput {
            density,
            gradient,
            depth: 0.0,
        }
    }

    #[test]
    fn opacity_is_corrected_for_the_step() {
        let mut tf = TransferFunction::ramp(0.0, 1.0, 1.0);
        tf.scalar_opacity = vec![[0.0, 0.5], [1.0, 0.5]];
        tf.scalar_opacity_unit_distance = 2.0;
        let t = CrioTables::from_transfer_function(&tf, 16).unwrap();
        let fc = FrameClassifier::new(&t, &frame(), 1.0);
        let a = fc.classify(&input(0.5, Vec3::ZERO)).unwrap()[3];
        // Half the unit distance: 1 − 0.5^(1/2).
        assert!((a - (1.0 - 0.5f32.sqrt())).abs() < 1e-6, "{a}");
        // Two half steps compose to one unit step.
        let two = 1.0 - (1.0 - a) * (1.0 - a);
        assert!((two - 0.5).abs() < 1e-6);
    }

    #[test]
    fn zero_opacity_is_culled() {
        let t =
            CrioTables::from_transfer_function(&TransferFunction::ramp(0.0, 1.0, 1.0), 64).unwrap();
        let fc = FrameClassifier::new(&t, &frame(), 1.0);
        assert!(fc.classify(&input(0.0, Vec3::ZERO)).is_none());
        assert!(fc.classify(&input(0.5, Vec3::ZERO)).is_some());
    }

    #[test]
    fn shading_matches_hand_computation() {
        // Headlight along +z (camera at +z looking down −z). Normal at 60° to the light.
        let mut tf = TransferFunction::ramp(0.0, 1.0, 1.0);
        tf.color = vec![[0.0, 0.5, 0.25, 1.0]];
        tf.scalar_opacity = vec![[0.0, 1.0]];
        tf.shade = true;
        tf.ambient = 0.1;
        tf.diffuse = 0.6;
        tf.specular = 0.3;
        tf.specular_power = 4.0;
        let t = CrioTables::from_transfer_function_lit(&tf, 8, vec![ambient_headlight()]).unwrap();
        let fc = FrameClassifier::new(&t, &frame(), 1.0);
        let n = Vec3::new(3f32.sqrt() / 2.0, 0.0, 0.5) * 7.0; // |n·L| = 0.5
        let out = fc.classify(&input(0.3, n)).unwrap();
        let expect = |c: f32| (0.1 * c + 0.6 * c * 0.5 + 0.3 * 0.5f32.powi(4)).min(1.0);
        for (ch, c) in [0.5f32, 0.25, 1.0].iter().enumerate() {
            assert!(
                (out[ch] - expect(*c)).abs() < 1e-3,
                "channel {ch}: {} vs {}",
                out[ch],
                expect(*c)
            );
        }
        // Two-sided: the flipped normal shades the same.
        let back = fc.classify(&input(0.3, -n)).unwrap();
        assert_eq!(out, back);
        // One-sided: the back face gets ambient only.
        let mut t1 = t.clone();
        t1.shading.two_sided = false;
        let fc1 = FrameClassifier::new(&t1, &frame(), 1.0);
        let back1 = fc1.classify(&input(0.3, -n)).unwrap();
        assert!((back1[0] - 0.05).abs() < 1e-5);
    }

    #[test]
    fn switches_remove_only_their_term() {
        let mut tf = TransferFunction::ramp(0.0, 1.0, 1.0);
        tf.color = vec![[0.0, 0.4, 0.4, 0.4]];
        tf.scalar_opacity = vec![[0.0, 1.0]];
        tf.shade = true;
        tf.ambient = 0.25;
        let t = CrioTables::from_transfer_function_lit(&tf, 8, vec![ambient_headlight()]).unwrap();
        let g = Vec3::Z;
        let full = FrameClassifier::new(&t, &frame(), 1.0)
            .classify(&input(0.5, g))
            .unwrap()[0];
        let mut no_spec = t.clone();
        no_spec.shading.specular = false;
        let ns = FrameClassifier::new(&no_spec, &frame(), 1.0)
            .classify(&input(0.5, g))
            .unwrap()[0];
        assert!(
            (full - ns - 0.2).abs() < 1e-5,
            "specular term is 0.2: {full} {ns}"
        );
        let mut emit_only = no_spec.clone();
        emit_only.shading.diffuse = false;
        let e = FrameClassifier::new(&emit_only, &frame(), 1.0)
            .classify(&input(0.5, g))
            .unwrap()[0];
        assert!((e - 0.1).abs() < 1e-6);
        assert!((ns - e - 0.7 * 0.4).abs() < 1e-5);
    }

    #[test]
    fn surface_enhancement_and_depth_cue_modulate_opacity() {
        let mut tf = TransferFunction::ramp(0.0, 1.0, 1.0);
        tf.scalar_opacity = vec![[0.0, 1.0]];
        let t = CrioTables::from_transfer_function(&tf, 8).unwrap();
        let se = t.clone().with_surface_enhancement(0.0, 10.0).unwrap();
        let fc = FrameClassifier::new(&se, &frame(), 1.0);
        assert!(
            fc.classify(&input(0.5, Vec3::ZERO)).is_none(),
            "flat regions vanish"
        );
        let a = fc.classify(&input(0.5, Vec3::X * 5.0)).unwrap()[3];
        assert!((a - 0.5).abs() < 1e-6);
        let dc = t.with_depth_cue(1.0, 0.0).unwrap();
        let fc = FrameClassifier::new(&dc, &frame(), 1.0);
        for d in [0.0f32, 0.25, 0.75] {
            let s = SampleInput {
                density: 0.5,
                gradient: Vec3::ZERO,
                depth: d,
            };
            assert!((fc.classify(&s).unwrap()[3] - (1.0 - d)).abs() < 1e-6);
        }
    }

    #[test]
    fn lookup_table_interpolates_linearly() {
        let t = LookupTable::from_fn(TableIndex::Density, 0.0, 4.0, 5, |x| [x * x]);
        assert_eq!(t.lookup(2.0), [4.0]);
        assert_eq!(t.lookup(2.5), [6.5]);
        assert_eq!(t.lookup(-1.0), [0.0]);
        assert_eq!(t.lookup(9.0), [16.0]);
        assert_eq!(t.lookup(f32::NAN), [0.0]);
    }
}
