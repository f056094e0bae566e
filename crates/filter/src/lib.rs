//! # volsplat-filter
//!
//! Buchanan, *Filtering Volumetric Data* (PhD thesis, UBC; chapters 1–5, appendices A–C): four
//! ways to evaluate the space-variant 3-D filter integral `I = ∭ F(u,v,w) T(u,v,w)` of a solid
//! texture over a pixel's footprint, and the Chapter 5 evaluation that compares them. Citations
//! name the thesis's section (§4-4.2), equation (eq 4.32), figure, table, plate or appendix
//! (App. A-1); "A-n" are the points where the printed thesis is ambiguous or wrong, each with
//! the choice made, listed under *Decisions* below (`docs/papers.md` maps the thesis to the code).
//!
//! ## Modules
//! - [`texture`]: the [`texture::SolidTexture`] trait; cosine series (known
//!   spectrum, closed-form box averages), marble (turbulence of band-limited noise), 3-D step,
//!   constant, and discrete arrays of any size with sample-and-hold or trilinear reconstruction.
//! - [`scene`]: perspective camera (`volsplat_core::Camera`) over a plane running to the
//!   horizon or a sphere; per pixel the exact tangent-plane [`Ellipse`](region::Ellipse),
//!   `V_tan` and `V_ray` ([`OrientedBox`](region::OrientedBox)), degenerate-horizon policy.
//! - [`filters`]: box, Bartlett and Gaussian filters over a box's local coordinates.
//! - [`clamp`]: step, quadratic and Norton clamping of frequency components (§4-1, §5-3).
//! - [`quadrature`], [`direct`]: adaptive Simpson, 3-point Gauss–Legendre (27) and the hybrid
//!   (75) rule; the "gold standard" reference at tolerance 1/255 (§4-2, §5-4).
//! - [`ewa`]: EWA-2 and EWA-3 with a radial weight table, fixed/adaptive sample counts and the
//!   max-samples cap (§4-3, §5-5).
//! - [`nil`]: NIL maps — 1-D and 3-D pyramids of cosine and discrete textures, patch bases
//!   `M = 1…4`, trigger-point hierarchies, negative levels, normalisation, corrected level
//!   weighting and transfer-function `D` maps (§4-4, §5-6, App. A–C).
//! - [`render`]: renders a scene with one [`render::Technique`].
//! - [`display`]: Chapter 6 — volume display as filtering: Sabella's display (eq 3.1), the
//!   linearised display (eq 6.1) by quadrature and by NIL maps, Gaussian slices, the maximum,
//!   sample-and-filter with a difference of Gaussians, and transfer-function changes through
//!   `D` maps without rebuilding (§6-1 … §6-5, App. B); decisions on A-15 … A-18 there.
//!
//! The Chapter 5 evaluation itself (Tables 5.1–5.11 and Plates 5.1–5.16 analogues, the MSE and
//! SNR of §5-2) lives in the `volsplat-studies` crate (`texture_bench`), outside the library.
//!
//! Units: every position, length, `ε` and footprint is in *texture units* (scenes are modelled
//! in texture space); frequencies in cycles per texture unit; grey values in about `[0, 1]`;
//! angles in degrees at interfaces (camera), radians inside. Dependencies: `volsplat-core`
//! (camera, images, volumes), `glam`, `thiserror`, `rayon` (parallel rendering) only.
//!
//! ## Decisions (open points A-1…A-21)
//! - **A-1 level weighting**: the printed `w_γ = 2^{γmax−γ}` (text and eq 4.32) is wrong; the
//!   worked example and the mathematics need the cell extent. We weight numerator and
//!   denominator by the cell volume `2^{3γ}` ([`nil::LevelWeighting::CellVolume`]). Tests:
//!   `nil::one_d` reproduces the §4-4.2 half-0/half-1 example (corrected ½, printed 0.8,
//!   unweighted ⅔) and exactness over mixed levels; `nil::tests` shows the printed weight
//!   breaking the exact box integral in 3-D.
//! - **A-2 nodes**: Lagrange nodes ½ (M=1), {0,1}, {0,½,1}, {0,⅓,⅔,1}; control points are
//!   filter values at the nodes; Catmull-Rom is not implemented. With these nodes the constant
//!   patch is a midpoint rule and the linear one a trapezoid rule: both `O(h²)`, the linear one
//!   with about twice the error, so M=2 is not better than M=1 (see item 2 below).
//! - **A-3 triggers**: `n³` cell-centred points in the box; cells are half-open (ties go up);
//!   empty children are kept; periodic textures let the trigger set move by whole periods to
//!   find a smaller root (no dyadic cell straddles the origin).
//! - **A-4 scale collapse**: if `Σ w b·B̄ ≤ 10⁻³ Σ w |b|·B̄` (or no root within `γ_max`) the
//!   result is flagged collapsed and renderers fall back to a point sample (counted in
//!   [`render::Rendered`]'s `fallbacks`).
//! - **A-5 boundaries**: discrete textures are periodic (wrap) in every axis; `n` samples give
//!   `n` cells for both reconstructions.
//! - **A-6 cosine texture**: `T_ijk` seeded uniform in `[−1, 1)`, `T_000 = 0` (mean 0.5), `S`
//!   normalised by the sampled maximum so the range is about `[0, 1]` (see
//!   [`texture::CosineTexture::seeded`]).
//! - **A-7 clamping**: footprint frequency `φ = sqrt(Σ_q (f·a_q)²)` over the `V_tan` half-axes;
//!   `φ_max = 0.25` (Nyquist for one sample per footprint diameter) for step and quadratic;
//!   Norton = quadratic with `φ_max = √6/2π`. Each product of cosines is clamped as its four
//!   plane waves.
//! - **A-8 direct evaluation**: normalised (`∭FT/∭F`); `V_tan` symmetric about the surface,
//!   `V_ray` one-sided into the object; `ε` and spread in texture units / pixel radii; Simpson
//!   tolerance absolute on the normalised value, Richardson `15·eps`, halved per split, full
//!   tolerance for every nested inner integral, depth cap (default 8).
//! - **A-9 EWA**: ellipse from the exact conic projection of the pixel circle; Gaussian
//!   `exp(−2ρ²)` truncated at `ρ² ≤ 1`, 1024-entry table (nearest entry); adaptive sampling at
//!   `1/(2 f_max)` spacing; centred at the ellipse centre (option: the ray hit).
//! - **A-10 filters**: box along the depth axis, separable in the footprint plane; the
//!   Gaussian `exp(−α(s²+t²))`, `α = 2`, is 2-D on the tangent plane. The Chapter 5 image
//!   uses `ε = 0.01` (Table 5.3's surface value; the thesis does not state the Chapter 5 `ε`);
//!   texture-bench adds a depth study at `ε = 0.25` (`docs/texture-bench/findings.md`, item 3).
//! - **A-11 transfer functions with trilinear data**: `D` cells by Gauss–Legendre with
//!   `⌈(N+M−1)/2⌉` nodes per texel and axis (exact).
//! - **A-12 sizes**: any size per axis, exact, with no valid bits: a level-`γ` cell is one of
//!   `n/gcd(n, 2^γ)` phase classes of the periodic texture (replaces and their
//!   typo'd prefactors A.31–A.33).
//! - **A-13 printed formulas corrected**: Norton's clamp condition (§4-1), the duplicated
//!   `T_ijk` (§5-3), the spurious "2t" in `F_1` and missing `Σ_p` (§4-4.6), the duplicated `B_i`
//!   in A.19, the corrupt trilinear coefficients A.26/A.27 (replaced by the separable
//!   `β⁰_i = B̄_i − ᵗB_i`, `β¹_i = ᵗB_i` form), the missing scale factor in A.17 (negative levels
//!   are computed exactly from the parent texel), and eq 4.32's weight.
//! - **A-14 procedural unit cell**: the level-0 cell is one period of the cosine texture;
//!   `γ_max = 10`, `γ_min = −8` by default; roots above `γ_max` return the DC value.
//! - **A-15 … A-18, A-20** concern Chapter 6 (volume rendering): see [`display`].
//! - **A-16 tables**: our report numbers rows as Table 5.2 and cites the reference row; NIL and
//!   EWA are scored against row 6 (Simpson Gaussian), clamping against row 4 (Simpson box).
//! - **A-19 negative levels**: weighted like positive ones (`2^{3γ}`); `γ_min` is a parameter.
//! - **A-21 timings**: only ratios and orderings are compared with the thesis.
//!
//!
//! Also: pixel circle radius `½·pitch·spread`; footprints whose projection is a parabola or
//! hyperbola, or whose ellipse exceeds 64 texture units, take the texture's DC value
//! ([`scene::HorizonPolicy`]).
//!
//! ## Results
//! What the Chapter 5 evaluation (`volsplat texture-bench`, crate `volsplat-studies`) measures
//! with these filters, and where it differs from the thesis, is in
//! `docs/texture-bench/findings.md` and `docs/texture-bench/report.md`.
#![deny(missing_docs)]
// Index loops mirror the thesis's Σ_i Σ_j Σ_k notation over several arrays at once.
#![allow(clippy::needless_range_loop)]

pub mod clamp;
pub mod direct;
pub mod display;
pub mod error;
pub mod ewa;
pub mod filters;
pub mod nil;
pub mod quadrature;
pub mod region;
pub mod render;
pub mod scene;
pub mod texture;

pub use display::{
    DisplayImage, DisplayKind, DisplaySettings, DisplayStats, DisplayVolume, build_map,
    render_display, render_display_with_progress,
};
pub use error::{FilterError, Result};
pub use render::{RegionKind, Rendered as TextureRendered, Technique, render as render_texture};
pub use scene::{Scene as TextureScene, SceneSettings, Surface};
pub use texture::{
    ConstantTexture, CosineTexture, DiscreteTexture, MarbleTexture, Reconstruction, SolidTexture,
    StepTexture,
};
