//! Continuous (C⁰) NIL patches: the data's per-cell projections averaged at shared nodes
//! (decision 0027).
//!
//! With control points by projection (decision 0007) the NIL value of a filter `F` is
//! `Σ_cells Σ b·C = Σ_c ⟨F, P_c T⟩`: the filter integrated against `P_c T`, the L² projection of
//! the data onto the cell's patch space, cell by cell. Neighbouring cells are fitted
//! independently, so this approximation of the data jumps across every cell face. A display
//! filter is a tube half a pixel wide; as the pixel's ray crosses a face parallel to it, the
//! tube moves from one cell's fit to the other's and the image shows the jump: a seam along
//! every projected cell face (issue 28).
//!
//! Here the data's approximation is made continuous, as a discontinuous Galerkin solution is
//! post-processed into a continuous one:
//! - every cell's projection is evaluated at its Lagrange nodes: `a = (G⁻¹ ⊗ G⁻¹ ⊗ G⁻¹) C`
//!   (Lagrange coefficients are the values at the nodes);
//! - a node on a face, edge or corner takes the mean of the values that the cells of its level
//!   sharing it give it (cells outside the box of voxel centres, where the density is zero by
//!   eq 4.2, take no part);
//! - the cell's patch interpolates these shared values.
//!
//! Two cells of one level then agree on their common face (the Lagrange nodes include 0 and 1
//! for `M ≥ 2`), so the approximated density `Q T` is continuous. The display value is
//! `Σ_c Σ_ijk m_ijk · v_ijk`, with `m = ∫_cell F·B_ijk` the projection moments of the filter
//! (decision 0007) and `v` the shared node values. `Q T` is linear in the data, so a transfer
//! function still changes through the `D` channels exactly (eq 4.24). It is not clamped to the
//! data's range: clamping the nodes next to a silhouette (where a fit overshoots below zero in
//! the air) cost 4 dB against Sabella on a 197×233×189 MRI (54.0 → 50.1 dB at 256², level 1),
//! because the undershoot balances the overshoot on the other side of the edge; the display
//! clamps its final value at zero instead.
//!
//! The node values of a level depend on the data alone: they are computed once per render and
//! level, on first use ([`NodeGrids`]), like a pyramid level of a MIP map.
//!
//! Levels `γ ≤ 0` need no averaging: a cell of level `≤ 0` lies inside one voxel cell, where the
//! trilinear (or sample-and-hold) data is itself in the patch space (`M ≥ 2`), so every cell's
//! projection is the data and the cells already agree. Negative levels, and cells of the
//! hierarchy outside the box, use their own projection. Level 0 of a plain map of trilinear
//! data has a grid too, only because looking a node up is cheaper than projecting the cell
//! again for every ray: its averages are the voxel values (to rounding). Sample-and-hold data
//! and transfer `D` maps keep each level-0 cell's own projection, which the averages would
//! change. Every projection reproduces polynomials of degree
//! `< M`, so the averages do too: a constant volume stays exact. Cells of different levels
//! meeting at a face share no nodes and stay discontinuous there.

use super::project::Projector;
use crate::nil::{Cell, NilSource};
use std::sync::OnceLock;

/// The shared node values of one level.
#[derive(Debug)]
struct NodeGrid {
    /// Cells per axis covered (`0..cells[a]`: those overlapping the box of voxel centres).
    cells: [i64; 3],
    /// Nodes per axis: `(M − 1)·cells + 1`.
    nodes: [usize; 3],
    /// Node values, node-major, `channels` per node.
    values: Vec<f64>,
}

/// Shared node values of every level `γ ≥ 1` of a NIL map (and of level 0 where its cells
/// hold the data exactly), built on first use (module docs).
pub(crate) struct NodeGrids<'a> {
    map: &'a dyn NilSource,
    proj: &'a Projector,
    /// Upper corner of the box of voxel centres, index space (`n − 1` per axis).
    hi: [f64; 3],
    /// Whether level 0 gets a grid: a plain map of trilinear data.
    level0: bool,
    /// Level `γ` at index `γ`.
    levels: Vec<OnceLock<NodeGrid>>,
}

impl<'a> NodeGrids<'a> {
    /// Node grids of `map` for a volume whose box of voxel centres is `[0, hi]` (index space);
    /// `level0`: whether `map`'s level-0 cells hold the data exactly (a plain map of trilinear
    /// data), so that level 0 may use a grid as well.
    pub(super) fn new(
        map: &'a dyn NilSource,
        proj: &'a Projector,
        hi: [f64; 3],
        level0: bool,
    ) -> Self {
        let levels = (0..=map.gamma_max().max(0))
            .map(|_| OnceLock::new())
            .collect();
        NodeGrids {
            map,
            proj,
            hi,
            level0,
            levels,
        }
    }

    /// The grid of level `gamma` (≥ 1, or 0 if `level0`), built on first use; `None` for other
    /// levels, constant patches (`M = 1`, no shared nodes) or a level the map lacks.
    fn grid(&self, gamma: i32) -> Option<&NodeGrid> {
        let first = if self.level0 { 0 } else { 1 };
        if gamma < first || self.map.basis().order() < 2 {
            return None;
        }
        let lock = self.levels.get(gamma as usize)?;
        let g = lock.get_or_init(|| self.build(gamma));
        (!g.values.is_empty()).then_some(g)
    }

    fn build(&self, gamma: i32) -> NodeGrid {
        let m = self.map.basis().order();
        let m3 = m * m * m;
        let ch = self.map.channels();
        let h = 2f64.powi(gamma);
        // Cells whose lower corner lies below the box's upper corner (they overlap the box).
        let cells = self.hi.map(|x| ((x / h).ceil() as i64).max(1));
        let nodes = cells.map(|c| (m - 1) * c as usize + 1);
        let count = nodes[0] * nodes[1] * nodes[2];
        let mut sum = vec![0.0; count * ch];
        let mut hits = vec![0u32; count];
        let mut raw = vec![0.0; ch * m3];
        let mut a = [0.0; 64];
        for cz in 0..cells[2] {
            for cy in 0..cells[1] {
                for cx in 0..cells[0] {
                    if !self.map.cell(gamma, [cx, cy, cz], &mut raw) {
                        return NodeGrid {
                            cells,
                            nodes,
                            values: Vec::new(),
                        };
                    }
                    let base = [cx, cy, cz].map(|c| (m - 1) * c as usize);
                    for c in 0..ch {
                        self.proj
                            .apply_ginv(&mut raw[c * m3..(c + 1) * m3], &mut a[..m3]);
                        for k in 0..m {
                            for j in 0..m {
                                for i in 0..m {
                                    let n = ((base[2] + k) * nodes[1] + base[1] + j) * nodes[0]
                                        + base[0]
                                        + i;
                                    sum[n * ch + c] += a[(k * m + j) * m + i];
                                    if c == 0 {
                                        hits[n] += 1;
                                    }
                                }
                            }
                        }
                    }
                }
            }
        }
        for (n, &k) in hits.iter().enumerate() {
            for v in &mut sum[n * ch..(n + 1) * ch] {
                *v /= k.max(1) as f64;
            }
        }
        NodeGrid {
            cells,
            nodes,
            values: sum,
        }
    }
}

/// `Σ_cells Σ_ijk m_ijk · v_ijk` per channel, added to `num`: the filter moments `ms` (`M³` per
/// cell, `None` where the filter misses the cell) against the shared node values of the cell's
/// level, or against the cell's own projection where there are none (module docs). `raw` is a
/// buffer. False if a cell is unavailable.
pub(crate) fn integrate_continuous(
    grids: &NodeGrids<'_>,
    cells: &[Cell],
    ms: &[Option<[f64; 64]>],
    raw: &mut Vec<f64>,
    num: &mut [f64],
) -> bool {
    let map = grids.map;
    let m = map.basis().order();
    let m3 = m * m * m;
    let ch = map.channels();
    raw.resize(ch * m3, 0.0);
    let mut a = [0.0; 64];
    for (cell, mom) in cells.iter().zip(ms) {
        let Some(mom) = mom else { continue };
        let inside = |g: &NodeGrid| (0..3).all(|x| (0..g.cells[x]).contains(&cell.index[x]));
        match grids.grid(cell.gamma).filter(|g| inside(g)) {
            Some(g) => {
                let base = cell.index.map(|c| (m - 1) * c as usize);
                for k in 0..m {
                    for j in 0..m {
                        let row = ((base[2] + k) * g.nodes[1] + base[1] + j) * g.nodes[0] + base[0];
                        for i in 0..m {
                            let w = mom[(k * m + j) * m + i];
                            let v = &g.values[(row + i) * ch..(row + i + 1) * ch];
                            for (n, x) in num.iter_mut().zip(v) {
                                *n += w * x;
                            }
                        }
                    }
                }
            }
            None => {
                if !map.cell(cell.gamma, cell.index, raw) {
                    return false;
                }
                for (c, n) in num.iter_mut().enumerate() {
                    grids
                        .proj
                        .apply_ginv(&mut raw[c * m3..(c + 1) * m3], &mut a[..m3]);
                    *n += mom[..m3]
                        .iter()
                        .zip(&a[..m3])
                        .map(|(x, y)| x * y)
                        .sum::<f64>();
                }
            }
        }
    }
    true
}
