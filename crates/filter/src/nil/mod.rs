//! NIL maps ("nodus in largo"; Fournier & Fiume 1988, extended to 3-D, procedural textures and
//! transfer functions by Buchanan §4-4, §5-6, App. A–C).
//!
//! A NIL map stores, per pyramid cell `(γ, m)`, the moments `C_{ijk} = ∫_{[0,1]³} B_i B_j B_k ·
//! T(2^γ(m + ·))` of the texture against a patch basis ([`PatchBasis`]). A filter is
//! approximated by one patch per cell of a hierarchy chosen by trigger points
//! ([`find_hierarchy`]); its control points are filter values at the basis nodes, and the
//! filtered value is the normalised, level-weighted sum ([`nil_filter`]).
//!
//! - [`CosineNilMap`]: analytic maps of cosine textures (one cell per positive level).
//! - [`DiscreteNilMap`]: pyramids of sampled textures (sample-and-hold or trilinear, any size),
//!   optionally with transfer-function `D` maps ([`TransferBasis`]).
//! - [`one_d`]: the 1-D versions (pyramids, hierarchies, evaluation) used to show the level
//!   weighting of §4-4.2.

mod axis;
pub mod basis;
pub mod cosine;
pub mod discrete;
pub mod eval;
pub mod one_d;
#[cfg(test)]
mod tests;

pub use basis::PatchBasis;
pub use cosine::CosineNilMap;
pub use discrete::{DiscreteNilMap, DiscreteNilSettings, TransferBasis};
pub use eval::{
    Cell, LevelWeighting, NilResult, NilScratch, NilSettings, box_triggers, enclosing_cell,
    evaluate_cells, find_hierarchy, find_hierarchy_counted, nil_filter, nil_filter_box,
    nil_filter_with,
};

/// A source of NIL cells (a pyramid, analytic or pre-computed).
pub trait NilSource: Send + Sync {
    /// The patch basis (order `M`).
    fn basis(&self) -> &PatchBasis;

    /// Number of channels per cell: 1 for a plain map, `N` for a transfer `D` map.
    fn channels(&self) -> usize;

    /// Highest available level `γ_max`; roots above it fall back to the DC value.
    fn gamma_max(&self) -> i32;

    /// The texture's DC value (fall-back result).
    fn mean(&self) -> f64;

    /// The texture's period along x, y, z (texture units): cells and filters may be translated
    /// by whole periods to find a smaller hierarchy root (decision A-3).
    fn period(&self) -> [f64; 3];

    /// Writes the moments of cell `(gamma, index)` into `out` (channel-major, `channels × M³`,
    /// moment `(k·M + j)·M + i`). Returns false if the level is unavailable.
    fn cell(&self, gamma: i32, index: [i64; 3], out: &mut [f64]) -> bool;
}
