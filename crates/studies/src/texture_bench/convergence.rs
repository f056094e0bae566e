//! The convergence of each NIL patch order on uniform hierarchies (App. A, open point A-2 of
//! the `volsplat-filter` crate documentation).

use super::ConvergenceRow;
use glam::DVec3;
use volsplat_filter::nil::CosineNilMap;
use volsplat_filter::texture::{CosineTexture, SolidTexture};
use volsplat_filter::{FilterError, Result};

/// NIL maps of `texture` on *uniform* hierarchies — all `8^{−γ}` cells of level `γ = −1 … −4`
/// tiling the unit cube — for a smooth filter (a 3-D Gaussian, `σ = 0.12`, centred at
/// `(0.61, 0.37, 0.44)`), against the exact normalised filtered value over the cube (composite
/// 5-point Gauss–Legendre, 12 panels per axis). Shows the order of each patch basis: the
/// constant patch with its node at the cell centre is a midpoint rule and the linear patch with
/// nodes on the cell faces a trapezoid rule — both `O(h²)`, the latter with about twice the
/// error — while quadratic and cubic patches converge at `O(h⁴)` or faster.
pub fn patch_order_convergence(texture: &CosineTexture) -> Result<Vec<ConvergenceRow>> {
    use volsplat_filter::nil::{Cell, LevelWeighting, evaluate_cells};
    use volsplat_filter::quadrature::{CompositeRule, composite_average_3d};
    use volsplat_filter::region::OrientedBox;
    let c = DVec3::new(0.61, 0.37, 0.44);
    let sigma = 0.12;
    let f = |p: DVec3| (-(p - c).length_squared() / (2.0 * sigma * sigma)).exp();
    let cube = OrientedBox::axis_aligned(DVec3::ZERO, DVec3::ONE);
    let avg = |g: &dyn Fn(DVec3) -> f64| {
        composite_average_3d(
            &|s, t, r| g(cube.point(s, t, r)),
            CompositeRule::Gauss(5),
            12,
        )
    };
    let exact = avg(&|p| f(p) * texture.value(p)) / avg(&f);
    let mut out = Vec::new();
    let mut moments = Vec::new();
    for order in 1..=4 {
        let map = CosineNilMap::build(texture, order, 10)?;
        let mut errors = Vec::new();
        for gamma in (-4..=-1).rev() {
            let n = 1i64 << -gamma;
            let cells: Vec<Cell> = (0..n * n * n)
                .map(|q| Cell {
                    gamma,
                    index: [q % n, (q / n) % n, q / (n * n)],
                })
                .collect();
            let r = evaluate_cells(
                &map,
                &cells,
                &f,
                LevelWeighting::CellVolume,
                0.0,
                &mut moments,
            )
            .ok_or_else(|| FilterError::invalid("convergence", gamma, "NIL scale collapsed"))?;
            errors.push((gamma, r.value() - exact));
        }
        out.push(ConvergenceRow { order, errors });
    }
    Ok(out)
}
