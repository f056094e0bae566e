//! The classification tables of density-indexed transfer functions: unshaded
//! ([`PostTable`]), shaded ([`ShadeTable`]), their pre-integrated segments, the ringing
//! risk that decides pre-integration ([`ring_risk`]), and the tables of one frame together
//! ([`FrameTables`]) with the bricks they leave empty.

use super::math::{log2_unit, max_ps, min_ps};
use crate::bricks::BrickGrid;
use crate::error::Result;
use crate::normals::{NormalField, ShadeAt, VoxelShading};
use crate::sheets::{Preintegrate, RenderMode, RenderSettings};
use volsplat_core::glam::Vec3;
use volsplat_core::image::Rgba;
use volsplat_core::{CrioTables, FrameClassifier, Grid, SampleInput, Scalar, Volume};

/// How one frame classifies its samples (decisions 0016, 0019, 0020): through a density table
/// where the transfer function depends on the density alone (unshaded, [`PostTable`]; shaded,
/// [`ShadeTable`], at the samples or at the voxels), through the per-sample classifier
/// otherwise (both tables `None`); and whether the segments between planes are pre-integrated.
pub(super) struct FrameTables<'a> {
    /// Composite whose lights need the gradient.
    pub(super) shade: bool,
    /// Unshaded composite classified by density.
    pub(super) post: Option<PostTable>,
    /// Shaded composite classified by density.
    pub(super) shaded: Option<ShadeTable>,
    /// With `shaded`, shaded at the voxels ([`ShadeAt::Voxels`]): the frame's lights applied
    /// to every direction code, and the voxels' codes (empty otherwise).
    pub(super) voxel: Option<VoxelShading>,
    pub(super) codes: &'a [u16],
    /// Per index axis: the world direction of that axis divided by its spacing.
    pub(super) grad_to_world: [Vec3; 3],
    /// [`ring_risk`] of the density table (0 without one).
    pub(super) risk: f32,
    /// Pre-integrate the segments between planes ([`RenderSettings::preintegrate`], `auto`
    /// where `risk` exceeds [`RING_RISK`]).
    pub(super) preint: bool,
}

impl<'a> FrameTables<'a> {
    /// The tables of a frame of `volume` classified by `classifier` (made for the frame's
    /// slab thickness) under `settings`. The voxels' direction codes come from `bricks` where
    /// it keeps them across frames, else are built into `owned_normals`; an error where they
    /// cannot be allocated.
    pub(super) fn build<T: Scalar>(
        grid: &Grid,
        volume: Option<&Volume<T>>,
        tables: &CrioTables,
        classifier: &FrameClassifier,
        settings: &RenderSettings,
        bricks: &'a BrickGrid,
        owned_normals: &'a mut Option<NormalField>,
    ) -> Result<Self> {
        let composite = settings.mode == RenderMode::Composite;
        let shade = composite && classifier.needs_gradient;
        let post = (composite && !shade)
            .then(|| PostTable::new(tables, classifier))
            .flatten();
        let grad_to_world = [0, 1, 2].map(|a| (grid.direction.col(a) / grid.spacing[a]).as_vec3());
        // Shaded composite through tables where the classification depends on the density
        // alone; the per-sample classifier otherwise.
        let shaded = shade
            .then(|| ShadeTable::new(tables, classifier, grad_to_world))
            .flatten();
        // Shading at the voxels (VTK's order; `crate::normals`): the voxels' direction codes,
        // kept with the brick grid across frames, and the frame's lights applied to every code.
        let (voxel, codes): (Option<VoxelShading>, &[u16]) = match &shaded {
            Some(t) if settings.shade_at == ShadeAt::Voxels => {
                // The direction codes are a field of the whole volume: bricked frames light
                // the samples instead (the engine's plan; this is its check).
                let Some(volume) = volume else {
                    return Err(crate::error::SplatError::Setting {
                        name: "shade_at",
                        value: "voxels".into(),
                        expected: "samples for a volume read in bricks (the voxels' direction \
                                   codes are a field of the whole volume)",
                    });
                };
                let field = match bricks.normals(volume)? {
                    Some(f) => f,
                    None => owned_normals.insert(NormalField::build(volume)?),
                };
                (Some(VoxelShading::new(t)), field.codes())
            }
            _ => (None, &[]),
        };
        let risk = {
            let (alphas, scale): (Vec<f32>, f32) = match (&post, &shaded) {
                (Some(t), _) => (t.values.iter().map(|v| v[3]).collect(), t.axis.scale),
                (None, Some(t)) => (t.rows.iter().map(|r| r[0]).collect(), t.axis.scale),
                _ => (Vec::new(), 0.0),
            };
            let (lo, hi) = bricks
                .ranges
                .iter()
                .fold((f32::INFINITY, f32::NEG_INFINITY), |a, r| {
                    (a.0.min(r[0]), a.1.max(r[1]))
                });
            ring_risk(&alphas, scale, hi - lo)
        };
        let preint = match settings.preintegrate {
            Preintegrate::Off => false,
            Preintegrate::On => true,
            Preintegrate::Auto => risk > RING_RISK,
        };
        Ok(FrameTables {
            shade,
            post,
            shaded,
            voxel,
            codes,
            grad_to_world,
            risk,
            preint,
        })
    }

    /// Whether the frame's samples are pre-integrated: composite, asked for and classified
    /// through a density table (unshaded, or shaded at the voxels or at the samples; not the
    /// per-sample classifier).
    pub(super) fn preintegrated(&self) -> bool {
        self.preint && (self.post.is_some() || self.shaded.is_some())
    }

    /// One flag per brick of `bricks`: whether a sample in it can have opacity (empty space,
    /// module docs of [`super`]). Composite classified by a density table, one point per slab,
    /// skips the bricks whose samples read only entries without opacity from that very table
    /// (exact, [`BrickGrid::active_in_table`]); pre-integrated segments reach into the brick
    /// before, and the per-sample classifier resamples the opacity table of `tables`, so they
    /// keep the slack test ([`BrickGrid::active`]).
    pub(super) fn active_bricks(&self, bricks: &BrickGrid, tables: &CrioTables) -> Vec<bool> {
        let table_active = match (&self.post, &self.shaded) {
            (Some(t), _) if !self.preint => {
                Some(bricks.active_in_table(&t.nonzero(), |x| t.axis.pos(x)))
            }
            (None, Some(t)) if !self.preint => {
                Some(bricks.active_in_table(&t.nonzero(), |x| t.axis.pos(x)))
            }
            _ => None,
        };
        table_active.unwrap_or_else(|| {
            bricks.active(
                &tables.opacity,
                (tables.opacity.hi - tables.opacity.lo) / 4095.0,
                false,
            )
        })
    }
}

/// Premultiplied RGBA per density for unshaded classification: [`FrameClassifier::classify`]
/// evaluated at the entries of its own fused table (so the entries agree with it exactly),
/// read with linear interpolation of the premultiplied values (interpolating colour and
/// opacity separately, as `classify` does, differs between entries by the product of the
/// two increments).
pub(super) struct PostTable {
    /// Perspective: `[r, g, b, log2(1 − α)]` per entry (colour not premultiplied).
    pub(super) persp: Vec<Rgba>,
    /// Entry `i` of `values` (of `persp`) followed by entry `min(i + 1, last)`: one 32-byte row
    /// per lookup for [`composite_run_avx2`].
    ///
    /// [`composite_run_avx2`]: super::avx2::composite_run_avx2
    pub(super) pairs: Vec<[f32; 8]>,
    pub(super) persp_pairs: Vec<[f32; 8]>,
    /// Pre-integration ([`PostTable::segment`]): `[∫c_r·L, ∫c_g·L, ∫c_b·L, ∫L]` from the first
    /// entry to entry `i` (`L = log2(1 − α)`, `c` the colour of `persp`; integrals in entries,
    /// trapezoidal, summed in f64), and the same paired as `pairs`.
    integ: Vec<Rgba>,
    pub(super) integ_pairs: Vec<[f32; 8]>,
    /// The densities of the entries.
    pub(super) axis: TableAxis,
    pub(super) values: Vec<Rgba>,
}

/// The density axis of a table of entries spaced evenly from density `lo`: `scale` entries
/// per data unit, `last` the last entry's index (a table of one entry: `scale = last = 0`).
/// Shared by [`PostTable`] and [`ShadeTable`], and read by the AVX2 kernels' `table_pos8`.
#[derive(Clone, Copy)]
pub(super) struct TableAxis {
    pub(super) lo: f32,
    pub(super) scale: f32,
    pub(super) last: f32,
}

impl TableAxis {
    /// The axis of a table of `n` entries spanning `[lo, hi]`.
    fn new(lo: f32, hi: f32, n: usize) -> Self {
        let scale = if n > 1 {
            (n - 1) as f32 / (hi - lo)
        } else {
            0.0
        };
        TableAxis {
            lo,
            scale,
            last: (n - 1) as f32,
        }
    }

    /// The table position of density `x`: `min(max((x − lo)·scale, 0), last)` (NaN → 0). The
    /// scalar twin of `table_pos8` (`avx2/mod.rs`).
    #[inline(always)]
    pub(super) fn pos(&self, x: f32) -> f32 {
        ((x - self.lo) * self.scale).max(0.0).min(self.last)
    }
}

/// Linear interpolation in a table of `N`-channel entries at table position `t` (in
/// `[0, last]`): `row_i + f·(row_{i+1} − row_i)` per channel, the last entry standing for the
/// one after it (the tables whose last row is repeated never need that).
#[inline(always)]
fn lerp_rows<const N: usize>(rows: &[[f32; N]], t: f32) -> [f32; N] {
    // t ∈ [0, last] (NaN maps to 0 through `max`), so the i32 conversion is exact.
    let i = t as i32 as usize;
    let f = t - i as f32;
    let a = rows[i];
    let b = rows[(i + 1).min(rows.len() - 1)];
    std::array::from_fn(|c| a[c] + f * (b[c] - a[c]))
}

/// [`Preintegrate::Auto`] pre-integrates where [`ring_risk`] exceeds this: where the steepest
/// ramp of the transfer function takes a slab's opacity through more than 4 across a quarter of
/// the data's value range. Every case measured above it gains by segment, and every case below
/// it but the built-in demo loses: the cases are tabled in
/// `docs/decisions/0020-preintegration-for-sharp-ramps.md` ("The `auto` rule").
///
/// [`Preintegrate::Auto`]: crate::sheets::Preintegrate::Auto
pub const RING_RISK: f32 = 4.0;

/// How much a slab's opacity can change across a quarter of the data's value range at the
/// steepest ramp of a density table: `max |α[i+1] − α[i]|·entries_per_unit·data_range/4`, with
/// `alphas` the table's opacities per slab at `entries_per_unit` entries per data unit and
/// `data_range` the data's `max − min` (data units). A quarter of the range stands for the value
/// step across a sharp boundary of the data (air to skin, soft tissue to bone); 0 for an empty
/// table or range.
pub fn ring_risk(alphas: &[f32], entries_per_unit: f32, data_range: f32) -> f32 {
    let steepest = alphas
        .windows(2)
        .map(|w| (w[1] - w[0]).abs())
        .filter(|d| d.is_finite())
        .fold(0.0f32, f32::max);
    let r = steepest * entries_per_unit * data_range * 0.25;
    if r.is_finite() { r } else { 0.0 }
}

/// The most negative `log2(1 − α)` that the pre-integration tables integrate (α = 1 − 2⁻²⁴,
/// opaque at f32 precision): a bound on the integrals, so that the difference of two of them
/// keeps its precision in f32 ([`integral_rows`]).
const SEGMENT_LOG_FLOOR: f32 = -24.0;

/// Segments shorter than this many table entries are classified at their middle value (the
/// table is linear there, so that is the segment's average up to a kink), longer ones through
/// the integral tables ([`PostTable::segment`], [`ShadeTable::segment_entry`]).
pub(super) const SEGMENT_MIN_ENTRIES: f32 = 1.0;

/// The averages over the segment between table positions `tu` and `tv` ([`PostTable::segment`],
/// [`ShadeTable::segment_entry`]): shorter than [`SEGMENT_MIN_ENTRIES`], the entry at the
/// middle (`at(false, ·)`); else from the integral rows (`at(true, ·)`), `L̄ = Δ∫L / Δt` in slot
/// `L`, each other slot `Δ∫x·L / Δ∫L`, and 0 in slot `W` (where the rows hold `∫L`) if it is
/// not `L`. The post table integrates into slot 3 and returns `[c̄, L̄]` (`W = L = 3`); the
/// shade table integrates into slot 0 and returns `[0, ē, d̄, L̄]` (`W = 0`, `L = 7`). The
/// scalar twin of `segment_average8` (`avx2/composite.rs`).
#[inline(always)]
pub(super) fn segment_average<const N: usize, const W: usize, const L: usize>(
    tu: f32,
    tv: f32,
    at: impl Fn(bool, f32) -> [f32; N],
) -> [f32; N] {
    let (w, l) = (W, L);
    let dt = tv - tu;
    if dt.abs() < SEGMENT_MIN_ENTRIES {
        return at(false, (tu + tv) * 0.5);
    }
    let (a, b) = (at(true, tu), at(true, tv));
    let dl = b[w] - a[w];
    let inv = 1.0 / dl;
    std::array::from_fn(|c| {
        if c == l {
            dl / dt
        } else if c == w {
            0.0
        } else {
            (b[c] - a[c]) * inv
        }
    })
}

/// Cumulative trapezoidal integrals over table entries of `rows` (`N` channels): channel `w` of
/// the result integrates the weight `max(row[w], SEGMENT_LOG_FLOOR)` (a `log2(1 − α)`), every
/// other channel `c` integrates `row[c]·weight`; entry 0 is zero. Summed in f64 and rounded once.
fn integral_rows<const N: usize>(rows: &[[f32; N]], w: usize) -> Vec<[f32; N]> {
    let weighted = |r: &[f32; N]| -> [f64; N] {
        let l = f64::from(r[w].max(SEGMENT_LOG_FLOOR));
        std::array::from_fn(|c| if c == w { l } else { f64::from(r[c]) * l })
    };
    let mut acc = [0.0f64; N];
    let mut out = Vec::with_capacity(rows.len());
    out.push([0.0f32; N]);
    for pair in rows.windows(2) {
        let (a, b) = (weighted(&pair[0]), weighted(&pair[1]));
        for c in 0..N {
            acc[c] += 0.5 * (a[c] + b[c]);
        }
        out.push(acc.map(|v| v as f32));
    }
    out
}

impl PostTable {
    const LEN: usize = 1024;

    pub(super) fn new(tables: &CrioTables, classifier: &FrameClassifier) -> Option<Self> {
        use volsplat_core::TableIndex::Density;
        let idx = [
            tables.opacity.index,
            tables.emission.index,
            tables.reflection.index,
        ];
        if idx.iter().any(|&i| i != Density)
            || tables.modulation.values.len() != 1
            || classifier.needs_gradient
        {
            return None;
        }
        let (lo, hi) = table_range(tables);
        let n = if hi > lo { Self::LEN } else { 1 };
        let values: Vec<Rgba> = (0..n)
            .map(|k| {
                let x = if n == 1 {
                    lo
                } else {
                    lo + (hi - lo) * k as f32 / (n - 1) as f32
                };
                classifier
                    .classify(&SampleInput {
                        density: x,
                        gradient: Vec3::ZERO,
                        depth: 0.0,
                    })
                    .unwrap_or([0.0; 4])
            })
            .collect();
        // Perspective: un-premultiplied colour and log2(1 − α) (−126 for α = 1), so that
        // `1 − (1 − α)^k` is one exp2.
        let persp: Vec<Rgba> = values
            .iter()
            .map(|v: &Rgba| {
                let a = v[3];
                if a <= 0.0 {
                    [0.0; 4]
                } else {
                    let l = if a >= 1.0 {
                        -126.0
                    } else {
                        log2_unit(1.0 - a).max(-126.0)
                    };
                    [v[0] / a, v[1] / a, v[2] / a, l]
                }
            })
            .collect();
        let paired = |t: &[Rgba]| -> Vec<[f32; 8]> {
            (0..t.len())
                .map(|i| {
                    let (a, b) = (t[i], t[(i + 1).min(t.len() - 1)]);
                    [a[0], a[1], a[2], a[3], b[0], b[1], b[2], b[3]]
                })
                .collect()
        };
        let integ = integral_rows(&persp, 3);
        Some(PostTable {
            pairs: paired(&values),
            persp_pairs: paired(&persp),
            integ_pairs: paired(&integ),
            integ,
            persp,
            axis: TableAxis::new(lo, hi, n),
            values,
        })
    }

    #[inline(always)]
    pub(super) fn lookup(&self, x: f32) -> Rgba {
        self.lookup_in(&self.values, x)
    }

    /// Per entry, whether it has opacity in either form the kernels read (`values`' α > 0, or
    /// `persp`'s `log2(1 − α)` < 0; NaN counts), for [`BrickGrid::active_in_table`].
    ///
    /// [`BrickGrid::active_in_table`]: crate::bricks::BrickGrid::active_in_table
    pub(super) fn nonzero(&self) -> Vec<bool> {
        self.values
            .iter()
            .zip(&self.persp)
            .map(|(v, p)| !(v[3] <= 0.0 && p[3] >= 0.0))
            .collect()
    }

    /// Linear interpolation in `values` (either table) at density `x`.
    #[inline(always)]
    pub(super) fn lookup_in(&self, values: &[Rgba], x: f32) -> Rgba {
        lerp_rows(values, self.axis.pos(x))
    }

    /// The pre-integrated classification of the segment of a ray whose density goes linearly
    /// from `u` (the previous plane) to `v` (this plane): `[c̄_r, c̄_g, c̄_b, L̄]` with `L̄` the
    /// mean of `L = log2(1 − α)` over the segment's densities and `c̄` the colour weighted by
    /// `L` (Engel, Kraus & Ertl 2001, with the self-attenuation inside the segment left out of
    /// the colour: `c̄ = ∫c·L / ∫L`, exact where the colour is constant). Segments shorter than
    /// [`SEGMENT_MIN_ENTRIES`] take the entry at their middle (`persp`). Where the segment has
    /// no opacity (`∫L = 0`) `L̄` is 0 and the colours 0/0 (NaN): it contributes nothing
    /// ([`Ctx::post_seg_src`], and the kernels' masks).
    ///
    /// The scalar twin of `post_segment8` (`avx2/composite.rs`).
    ///
    /// [`Ctx::post_seg_src`]: super::march::Ctx::post_seg_src
    #[inline(always)]
    pub(super) fn segment(&self, u: f32, v: f32) -> Rgba {
        let at = |integ: bool, t| lerp_rows(if integ { &self.integ } else { &self.persp }, t);
        segment_average::<4, 3, 3>(self.axis.pos(u), self.axis.pos(v), at)
    }
}

/// What the shaded kernel reads per sample ([`shaded_src`]): the classifier's terms before
/// shading ([`FrameClassifier::surface_terms`]) at 1024 densities, read with linear
/// interpolation like [`PostTable`], the lights of the frame, a table of the specular power, and
/// the matrix from the stored gradient field to world gradients.
///
/// [`shaded_src`]: super::shade::shaded_src
pub(crate) struct ShadeTable {
    /// The densities of the entries of `rows` and `integ`.
    pub(super) axis: TableAxis,
    /// `[α, e_r, e_g, e_b, d_r, d_g, d_b, log2(1 − α)]` per density (α step-corrected, `e` the
    /// emission `classify` adds, `d` the reflection colour; `log2(1 − α)` is −126 for `α = 1`),
    /// with the last entry repeated so that entry `i + 1` exists for every `i ≤ last`.
    pub(super) rows: Vec<[f32; 8]>,
    /// Pre-integration ([`ShadeTable::segment_entry`]): `[∫L, ∫e·L, ∫d·L, 0]` from the first
    /// entry (as [`PostTable`]'s `integ`), the last entry repeated as in `rows`.
    pub(super) integ: Vec<[f32; 8]>,
    /// `x^n` at `x = i / SPEC` for `i` in `0..=SPEC`, the last repeated (as `classify`'s own
    /// table of 4097 entries).
    pub(super) spec_pow: Vec<f32>,
    /// The specular power where it is a whole number in `1..=`[`ShadeTable::SPEC_INT_MAX`]:
    /// the samples' specular term is then `x^n` by exact repeated squaring
    /// ([`ShadeTable::spec_at_sample`], decision 0036) instead of the table.
    pub(super) spec_int: Option<u32>,
    pub(super) lights: Vec<volsplat_core::FrameLight>,
    pub(super) diffuse: bool,
    pub(super) specular: bool,
    pub(super) two_sided: bool,
    /// Constant specular colour, or `None` for the reflection colour.
    pub(super) spec_color: Option<[f32; 3]>,
    /// Column `a`: the world gradient per unit of the index-space derivative along axis `a`
    /// (`Ctx::grad_to_world`).
    pub(super) to_world: [[f32; 3]; 3],
}

impl ShadeTable {
    const LEN: usize = 1024;
    pub(super) const SPEC: usize = 4096;
    /// The largest whole specular power taken by repeated squaring (at most 2·log2 of it
    /// multiplications; larger powers read the table).
    pub(super) const SPEC_INT_MAX: u32 = 1024;

    /// `None` where the classifier's terms depend on more than the density (tables indexed by
    /// gradient magnitude or depth, a modulation that is not constant).
    pub(crate) fn new(
        tables: &CrioTables,
        classifier: &FrameClassifier,
        grad_to_world: [Vec3; 3],
    ) -> Option<Self> {
        let (lo, hi) = table_range(tables);
        classifier.surface_terms(lo)?;
        let n = if hi > lo { Self::LEN } else { 1 };
        let mut rows: Vec<[f32; 8]> = (0..n)
            .map(|k| {
                let x = if n == 1 {
                    lo
                } else {
                    lo + (hi - lo) * k as f32 / (n - 1) as f32
                };
                let t = classifier
                    .surface_terms(x)
                    .unwrap_or(volsplat_core::SurfaceTerms {
                        alpha: 0.0,
                        emission: [0.0; 3],
                        reflection: [0.0; 3],
                    });
                let a = t.alpha;
                let l = if a <= 0.0 {
                    0.0
                } else if a >= 1.0 {
                    -126.0
                } else {
                    log2_unit(1.0 - a).max(-126.0)
                };
                let [er, eg, eb] = t.emission;
                let [dr, dg, db] = t.reflection;
                [a, er, eg, eb, dr, dg, db, l]
            })
            .collect();
        rows.push(rows[n - 1]);
        // Integrate L (channel 7) and e·L, d·L; then store as [∫L, ∫e·L, ∫d·L, 0].
        let mut integ: Vec<[f32; 8]> = integral_rows(&rows[..n], 7)
            .into_iter()
            .map(|r| [r[7], r[1], r[2], r[3], r[4], r[5], r[6], 0.0])
            .collect();
        integ.push(integ[n - 1]);
        let sh = classifier.shading();
        let p = sh.specular_power as f64;
        let mut spec_pow: Vec<f32> = (0..=Self::SPEC)
            .map(|i| (i as f64 / Self::SPEC as f64).powf(p) as f32)
            .collect();
        spec_pow.push(spec_pow[Self::SPEC]);
        Some(ShadeTable {
            axis: TableAxis::new(lo, hi, n),
            rows,
            integ,
            spec_pow,
            spec_int: (p.fract() == 0.0 && (1.0..=f64::from(Self::SPEC_INT_MAX)).contains(&p))
                .then_some(p as u32),
            lights: classifier.lights().to_vec(),
            diffuse: sh.diffuse,
            specular: sh.specular,
            two_sided: sh.two_sided,
            spec_color: match sh.specular_color {
                volsplat_core::SpecularColor::Constant(c) => Some(c),
                volsplat_core::SpecularColor::Reflection => None,
            },
            to_world: grad_to_world.map(|g| g.to_array()),
        })
    }

    /// Per entry of `rows`, whether it has opacity in either form the kernels read (α > 0, or
    /// `log2(1 − α)` < 0; NaN counts), for [`BrickGrid::active_in_table`].
    ///
    /// [`BrickGrid::active_in_table`]: crate::bricks::BrickGrid::active_in_table
    pub(super) fn nonzero(&self) -> Vec<bool> {
        self.rows
            .iter()
            .map(|r| !(r[0] <= 0.0 && r[7] >= 0.0))
            .collect()
    }

    /// The entry at density `x`, linearly interpolated.
    #[inline(always)]
    pub(super) fn entry(&self, x: f32) -> [f32; 8] {
        lerp_rows(&self.rows, self.axis.pos(x))
    }

    /// The pre-integrated entry of the segment from density `u` (the previous plane) to `v`
    /// ([`PostTable::segment`]'s averages): `[0, ē, d̄, L̄]`, emission and reflection colours
    /// weighted by `L`. The opacity slot is 0: pre-integrated samples always take the
    /// path-corrected opacity `1 − 2^(k·L̄)` ([`shade_opacity`] with `corrected`).
    ///
    /// The scalar twin of `shade_segment8` (`avx2/shade.rs`).
    ///
    /// [`shade_opacity`]: super::shade::shade_opacity
    #[inline(always)]
    pub(super) fn segment_entry(&self, u: f32, v: f32) -> [f32; 8] {
        let at = |integ: bool, t| lerp_rows(if integ { &self.integ } else { &self.rows }, t);
        segment_average::<8, 0, 7>(self.axis.pos(u), self.axis.pos(v), at)
    }

    /// The lights of the frame.
    pub(crate) fn lights(&self) -> &[volsplat_core::FrameLight] {
        &self.lights
    }

    /// Whether the diffuse and the specular terms apply, and whether lighting is two-sided.
    pub(crate) fn switches(&self) -> (bool, bool, bool) {
        (self.diffuse, self.specular, self.two_sided)
    }

    /// `x^n` for `x` in `(0, 1]`, linearly interpolated in the table.
    #[inline(always)]
    pub(crate) fn spec(&self, x: f32) -> f32 {
        let t = min_ps(max_ps(x * Self::SPEC as f32, 0.0), Self::SPEC as f32);
        let i = t as i32 as usize;
        let f = t - i as f32;
        let (a, b) = (self.spec_pow[i], self.spec_pow[i + 1]);
        a + f * (b - a)
    }

    /// The specular power `x^n` of a sample lit at the samples ([`super::shade::shaded_src`]):
    /// by exact repeated squaring ([`pow_int`]) where the power is whole ([`ShadeTable::spec_int`]),
    /// else [`ShadeTable::spec`]. The scalar twin of the kernel's `spec_at_sample8`
    /// (`avx2/shade.rs`).
    #[inline(always)]
    pub(super) fn spec_at_sample(&self, x: f32) -> f32 {
        match self.spec_int {
            Some(n) => pow_int(x, n),
            None => self.spec(x),
        }
    }
}

/// `x^n` for `n ≥ 1` by repeated squaring, from the lowest bit of `n` up: `x^10 = x²·x⁸`, four
/// multiplications, each rounded once (decision 0036; exact where the table interpolates). The
/// scalar twin of `pow_int8` (`avx2/shade.rs`): the same multiplications in the same order.
#[inline(always)]
pub(super) fn pow_int(x: f32, n: u32) -> f32 {
    let (mut base, mut n) = (x, n);
    let mut acc: Option<f32> = None;
    loop {
        if n & 1 == 1 {
            acc = Some(acc.map_or(base, |a| a * base));
        }
        n >>= 1;
        if n == 0 {
            return acc.unwrap_or(1.0);
        }
        base *= base;
    }
}

/// The density range `[lo, hi]` that the density-indexed tables cover together.
fn table_range(tables: &CrioTables) -> (f32, f32) {
    let lo = tables
        .opacity
        .lo
        .min(tables.emission.lo)
        .min(tables.reflection.lo);
    let hi = tables
        .opacity
        .hi
        .max(tables.emission.hi)
        .max(tables.reflection.hi);
    (lo, hi)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::slab::march::Ctx;

    /// A post table over `[0, n − 1]` (one entry per data unit) from `persp` entries.
    fn post_table(persp: Vec<Rgba>) -> PostTable {
        let n = persp.len();
        let integ = integral_rows(&persp, 3);
        PostTable {
            pairs: Vec::new(),
            persp_pairs: Vec::new(),
            integ_pairs: Vec::new(),
            values: Vec::new(),
            persp,
            integ,
            axis: TableAxis::new(0.0, (n - 1) as f32, n),
        }
    }

    /// [`PostTable::segment`] against the averages of the interpolated table computed by brute
    /// force (10⁵ points per segment): `L̄` the mean of `L`, `c̄` the `L`-weighted mean colour, for
    /// segments up and down the table across a sharp ramp and a colour step, and the middle
    /// entry for segments shorter than one entry (one point where `u = v`).
    #[test]
    fn segments_average_the_table() {
        let n = 64;
        let persp: Vec<Rgba> = (0..n)
            .map(|i| {
                let l = match i {
                    0..20 => 0.0,
                    20..24 => -0.75 * (i - 19) as f32,
                    _ => -3.0 - 0.01 * i as f32,
                };
                let c = if i < 30 {
                    [0.9, 0.2, 0.1]
                } else {
                    [0.3, 0.6, 1.0]
                };
                [c[0], c[1], c[2], l]
            })
            .collect();
        let t = post_table(persp);
        let brute = |u: f32, v: f32| -> Rgba {
            let m = 100_000;
            let (mut sl, mut sc) = (0.0f64, [0.0f64; 3]);
            for k in 0..m {
                let x = u + (v - u) * (k as f32 + 0.5) / m as f32;
                let e = t.lookup_in(&t.persp, x);
                sl += f64::from(e[3]);
                for c in 0..3 {
                    sc[c] += f64::from(e[c]) * f64::from(e[3]);
                }
            }
            let c = sc.map(|c| if sl != 0.0 { (c / sl) as f32 } else { 0.0 });
            [c[0], c[1], c[2], (sl / m as f64) as f32]
        };
        for (u, v) in [
            (10.0, 30.0),
            (30.0, 10.0),
            (18.3, 24.9),
            (21.2, 22.7),
            (0.0, 63.0),
            (25.5, 40.25),
        ] {
            let (s, b) = (t.segment(u, v), brute(u, v));
            for c in 0..4 {
                assert!(
                    (s[c] - b[c]).abs() < 0.01 * b[3].abs().max(0.1),
                    "segment {u}..{v}, channel {c}: {} vs {}",
                    s[c],
                    b[c]
                );
            }
        }
        // Shorter than one entry: the middle entry, exactly; one value: that entry.
        assert_eq!(t.segment(21.2, 21.9), t.lookup_in(&t.persp, 21.55));
        assert_eq!(t.segment(22.5, 22.5), t.lookup_in(&t.persp, 22.5));
        // No opacity over the segment: L̄ = 0 (colours 0/0, NaN), which contributes nothing.
        assert_eq!(t.segment(3.0, 12.0)[3], 0.0);
        assert!(Ctx::<f32>::post_seg_src(t.segment(3.0, 12.0), 1.0).is_none());
    }

    #[test]
    fn ring_risk_scales_with_the_steepest_step() {
        // 0 → 0.5 over 5 entries of 0.1 data unit each, data range 40: 0.1/entry · 10
        // entries/unit · 10 = 10.
        let alphas = [0.0, 0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.5];
        assert!((ring_risk(&alphas, 10.0, 40.0) - 10.0).abs() < 1e-4);
        assert_eq!(ring_risk(&[0.3; 16], 10.0, 40.0), 0.0);
        assert_eq!(ring_risk(&[], 10.0, 40.0), 0.0);
        assert_eq!(ring_risk(&alphas, 10.0, f32::INFINITY), 0.0);
    }
}
