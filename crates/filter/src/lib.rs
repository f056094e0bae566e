//! # volsplat-filter
//!
//! Buchanan, *Filtering Volumetric Data* (PhD thesis, UBC; chapters 1–5, appendices A–C): four
//! ways to evaluate the space-variant 3-D filter integral `I = ∭ F(u,v,w) T(u,v,w)` of a solid
//! texture over a pixel's footprint, and the Chapter 5 evaluation that compares them. The
//! digest `research/seed-buchanan.md` rebuilds the thesis's formulas; "digest §n" and
//! "F-Bnn"/"A-n" below refer to it.
//!
//! ## Modules
//! - [`texture`]: the [`SolidTexture`](texture::SolidTexture) trait; cosine series (known
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
//! - [`render`]: renders a scene with one [`Technique`](render::Technique).
//! - [`display`]: Chapter 6 — volume display as filtering: Sabella's display (eq 3.1), the
//!   linearised display (eq 6.1) by quadrature and by NIL maps, Gaussian slices, the maximum,
//!   sample-and-filter with a difference of Gaussians, and transfer-function changes through
//!   `D` maps without rebuilding (§6-1 … §6-5, App. B); decisions on A-15 … A-18 there.
//! - [`metrics`]: MSE and SNR of §5-2.
//! - [`harness`]: the whole `texture-bench` evaluation ([`harness::run_texture_bench`]):
//!   analogues of Tables 5.1–5.11 and Plates 5.1–5.16 as data, with a Markdown rendering.
//!
//! Units: every position, length, `ε` and footprint is in *texture units* (scenes are modelled
//! in texture space); frequencies in cycles per texture unit; grey values in about `[0, 1]`;
//! angles in degrees at interfaces (camera), radians inside. Dependencies: `volsplat-core`
//! (camera, images, volumes), `glam`, `thiserror`, `rayon` (parallel rendering) only.
//!
//! ## Decisions (open points A-1…A-21 of the digest, §7)
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
//!   result is flagged collapsed and renderers fall back to a point sample (counted as
//!   "fallbacks" in the report).
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
//!   the harness adds a depth study at `ε = 0.25` (item 3 below).
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
//! ## Chapter 5 results that differ from the thesis
//! Numbers from `texture-bench` at its default size (128 × 96; `docs/texture-bench/report.md`),
//! whose findings repeat these explanations with the numbers of each run.
//! 1. **Gauss-27 (box) reaches 36.5 dB against the Simpson box, the thesis 44.7 dB** (Table
//!    5.2). Not a bug: the nodes (0, ±√(3/5)) and weights (8/9, 5/9) are exact to degree 5
//!    (`quadrature::tests`), they map onto the same `V_tan` box with the same normalised box
//!    filter as the reference, and the reference is not the cause (Simpson against the
//!    closed-form box: MSE 0.66; Gauss-27 against it: 14.4 ≈ its 14.6 against Simpson); the SNR
//!    is §5-2's over all `N·M` pixels. Three nodes per axis cannot integrate a footprint that
//!    spans several periods of the 5.2 cycles/unit texture, and our plane runs to the horizon:
//!    over the 7424 of 8832 object pixels whose footprint is at most one period across the rule
//!    gives MSE 2.87 (43.6 dB, the thesis's regime); the other 1408 carry ≈ 88 % of the squared
//!    error. The thesis's cost ratio (3.5× at a 125 : 27 minimum-evaluation ratio) says its
//!    Simpson reference hardly refined, i.e. its image had few such footprints; ours averages
//!    485 evaluations per object pixel. Scene-dependent (camera and texture scale are not
//!    given), not aligned.
//! 2. **NIL error on a smooth filter for M = 1..4: 1.0e-2, 1.5e-2, 9.6e-4, 4.9e-6** (linear
//!    worse than constant). Not a bug in the linear basis (`B₀ = 1−t`, `B₁ = t`, nodes {0, 1},
//!    tested for partition of unity, interpolation and moments): on uniform hierarchies the
//!    errors at `γ = −4` are 6.2e-4, 1.2e-3, 1.4e-5, 2.0e-6 with observed orders 1.95, 1.82,
//!    3.92, 3.58 ([`harness::patch_order_convergence`]). The constant patch with its node at the
//!    cell centre is a midpoint rule and the linear patch with nodes on the faces a
//!    trapezoid rule — the same order, the latter with about twice the error — so the error
//!    falls with M in steps of order, {1, 2} → {3, 4}; the thesis reports only M = 1 and 4.
//! 3. **NIL on the image: M=4 no better than M=1 at equal tol** (45.6 vs 44.5 at tol 10, 6.73
//!    vs 6.77 at tol 2; thesis Table 5.6: M=4 clearly better). A genuine property of NIL maps
//!    on our thin `V_tan` (`ε = 0.01`, 1/100 of a period): the filter is a slab that cubic
//!    dyadic cells cannot represent. A patch has non-zero control points only if one of its node
//!    planes falls inside the slab; for the plane `z = 0.3` that first happens at `γ = −5` for
//!    both node sets {½} and {0, ⅓, ⅔, 1}, so the same 720 (tol 10) and 272 (tol 5) pixels
//!    collapse for M=1 and M=4, and at tol 2 the hierarchy descends to `γ_min` around each
//!    trigger column (≈ 440 patches per pixel), i.e. NIL samples the filter at the 5 × 5
//!    trigger columns whatever M. The point-sample fallback hides the thesis's 0/0 white
//!    pixels (its 6416) but no M=4 advantage: the fallbacks' share of the MSE is reported
//!    (27.4 of 44.5 at M=1, tol 10), and the rest is 17.1 / 9.8 / 6.8 for M=1 against 18.2 /
//!    10.1 / 6.7 for M=4 (tol 10 / 5 / 2). Extending the filter through the cells' depth
//!    instead (no truncation along the normal) is worse (MSE ≈ 140–215 on a 64 × 48 image): the
//!    cells then average the texture's `w` variation away. The thesis does not give its `ε`;
//!    with a `V_tan` as thick as mid-image footprints (`ε = 0.25`, the harness's depth study,
//!    64 × 48, own Simpson Gaussian reference) its ordering appears: M=1 27.7 / 13.4 / 7.2,
//!    M=4 6.1 / 3.3 / 1.7 for tol 10 / 5 / 2, with M=1 tol 10 the only configuration that
//!    collapses (4 pixels).
//! 4. **EWA-3 adaptive MSE by max samples 3 … 41: 18.4, 7.3, 6.6, 2.3, 0.9, 1.1, 0.3**; the
//!    thesis is flat at 192–196 from n = 3 (Table 5.4). The spacing rule is not the cause:
//!    ¼ of `1/(2 f_max)` changes the MSE by ≤ 0.3 at every n (`ewa::tests`), because the error
//!    lives in footprints wider than n spacings, where the cap binds. The reference is row 6
//!    (Simpson Gaussian, A-16) and EWA and reference use the same Gaussian (`α = 2`, same
//!    centre, same ellipse axes); the curve saturates from n = 15 on the floor of their residual
//!    kernel difference (truncation at the ellipse against the rectangle: 0.3 at n = 41). With
//!    `ε = 0.25` that floor rises to ≈ 10 (EWA-3's 3-D Gaussian ellipsoid against a 2-D Gaussian
//!    × depth box; EWA-2: 59.6) and the curve is flat from n = 11 (24.5, 19.8, 14.3, 11.0, 10.6,
//!    10.0, 9.8). A floor near 190 is not reproduced: centring the Gaussian at the ray hit
//!    (§7-0.1's explanation) gives 0.44 at n = 41, and a Gaussian four times narrower than the
//!    reference's (`α = 8`) 5.8. What made the thesis's EWA differ from its reference by ~190
//!    independently of n remains unexplained.
//!
#![deny(missing_docs)]
// Index loops mirror the thesis's Σ_i Σ_j Σ_k notation over several arrays at once.
#![allow(clippy::needless_range_loop)]

pub mod clamp;
pub mod direct;
pub mod display;
pub mod error;
pub mod ewa;
pub mod filters;
pub mod harness;
pub mod metrics;
pub mod nil;
pub mod quadrature;
pub mod region;
pub mod render;
pub mod scene;
pub mod texture;

pub use error::{FilterError, Result};
pub use harness::{TextureBenchReport, TextureBenchSettings, run_texture_bench};
