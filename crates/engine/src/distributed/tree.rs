//! The compositing tree over a volume's bricks (issue 32; `docs/design/brick-seam.md` §4): a
//! k-d tree fixed by the brick grid alone, so that the order in which partial images meet does
//! not depend on the number of processes; the view only decides which child of each split is
//! in front.

/// Where the camera looks from, in the volume's **index** space (voxel units, the frame of
/// `Grid::index_to_world`'s input): what decides, at each split of the tree, which side is in
/// front.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Eye {
    /// Orthographic: the direction of view (from the camera into the scene), index units; any
    /// length but zero.
    Direction([f64; 3]),
    /// Perspective: the eye's position, index units.
    Point([f64; 3]),
}

/// One node of a [`BrickTree`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Node {
    /// Brick `index` (x fastest: `bx + nbx·(by + nby·bz)`).
    Leaf {
        /// The brick's linear index in the brick grid.
        index: usize,
    },
    /// The bricks below `at` along `axis` (brick coordinates; node `lo`) and the others (`hi`).
    /// The plane between them lies at voxel index `at·brick` along the axis (the first voxel of
    /// brick `at`; the shared face belongs to both, as in `BrickGrid`).
    Split {
        /// 0, 1, 2: x, y, z.
        axis: usize,
        /// The first brick coordinate of the `hi` side.
        at: usize,
        /// Node index of the lower side.
        lo: usize,
        /// Node index of the upper side.
        hi: usize,
    },
}

/// A k-d tree over a grid of `dims` bricks of `brick` cells per side: each box of bricks is
/// split at the middle of its longest axis (in bricks; ties to the lowest axis) until one brick
/// is left. The tree depends on the brick grid only: the number of processes and the view
/// change neither its nodes nor the leaves' order (depth first, `lo` before `hi`), which is
/// what makes a sort-last image bit-identical for any process count.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BrickTree {
    /// Bricks per axis (each ≥ 1).
    pub dims: [usize; 3],
    /// Cells per brick side (voxel units), used to place the split planes.
    pub brick: usize,
    /// The nodes; the root is node 0.
    pub nodes: Vec<Node>,
    /// Per node, the range of leaf positions (in [`BrickTree::leaves`]) below it.
    pub spans: Vec<(usize, usize)>,
    /// The bricks in the tree's leaf order.
    pub leaves: Vec<usize>,
}

impl BrickTree {
    /// The tree over `dims` bricks of `brick` cells. `None` when a count is zero.
    pub fn new(dims: [usize; 3], brick: usize) -> Option<Self> {
        if dims.contains(&0) || brick == 0 {
            return None;
        }
        let mut t = BrickTree {
            dims,
            brick,
            nodes: Vec::new(),
            spans: Vec::new(),
            leaves: Vec::new(),
        };
        t.build([0; 3], dims);
        Some(t)
    }

    /// Builds the node for the box of bricks `[lo, hi)`; returns its index.
    fn build(&mut self, lo: [usize; 3], hi: [usize; 3]) -> usize {
        let id = self.nodes.len();
        self.nodes.push(Node::Leaf { index: 0 });
        self.spans.push((self.leaves.len(), 0));
        let ext = [0, 1, 2].map(|a| hi[a] - lo[a]);
        let axis = (0..3).fold(0, |m, a| if ext[a] > ext[m] { a } else { m });
        if ext[axis] == 1 {
            let [x, y, z] = lo;
            let index = x + self.dims[0] * (y + self.dims[1] * z);
            self.nodes[id] = Node::Leaf { index };
            self.leaves.push(index);
        } else {
            let at = lo[axis] + ext[axis] / 2;
            let mut mid_hi = hi;
            mid_hi[axis] = at;
            let mut mid_lo = lo;
            mid_lo[axis] = at;
            let l = self.build(lo, mid_hi);
            let h = self.build(mid_lo, hi);
            self.nodes[id] = Node::Split {
                axis,
                at,
                lo: l,
                hi: h,
            };
        }
        self.spans[id].1 = self.leaves.len();
        id
    }

    /// Whether the `lo` side of split node `node` is in front (nearer the eye along every ray
    /// that crosses the plane) for `eye`; `None` for a leaf. An eye on the plane sees neither
    /// side through the other: `lo` first.
    pub fn lo_in_front(&self, node: usize, eye: Eye) -> Option<bool> {
        let Node::Split { axis, at, .. } = self.nodes[node] else {
            return None;
        };
        Some(match eye {
            // Looking towards +axis: the lower side is met first.
            Eye::Direction(d) => d[axis] >= 0.0,
            Eye::Point(p) => p[axis] <= (at * self.brick) as f64,
        })
    }

    /// The leaf positions owned by rank `r` of `n` (`n ≥ 1`): the `r`-th of `n` contiguous runs
    /// of [`BrickTree::leaves`], as equal as integer division makes them (a rank may own none
    /// when there are fewer bricks than ranks).
    pub fn rank_leaves(&self, r: usize, n: usize) -> (usize, usize) {
        let b = self.leaves.len();
        (r * b / n, (r + 1) * b / n)
    }

    /// The nodes whose leaves all belong to the run `[a, b)` of leaf positions and whose parent's
    /// do not: the roots of the subtrees one rank composites alone, in tree order.
    pub fn local_roots(&self, (a, b): (usize, usize)) -> Vec<usize> {
        let mut out = Vec::new();
        if a < b {
            self.collect_roots(0, (a, b), &mut out);
        }
        out
    }

    fn collect_roots(&self, node: usize, (a, b): (usize, usize), out: &mut Vec<usize>) {
        let (s, e) = self.spans[node];
        if e <= a || s >= b {
            return;
        }
        if a <= s && e <= b {
            out.push(node);
            return;
        }
        if let Node::Split { lo, hi, .. } = self.nodes[node] {
            self.collect_roots(lo, (a, b), out);
            self.collect_roots(hi, (a, b), out);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_brick_is_one_leaf_and_spans_nest() {
        for dims in [[1, 1, 1], [3, 1, 1], [2, 5, 3], [4, 4, 4], [7, 2, 1]] {
            let t = BrickTree::new(dims, 8).unwrap();
            let n = dims.iter().product::<usize>();
            let mut seen = t.leaves.clone();
            seen.sort_unstable();
            assert_eq!(seen, (0..n).collect::<Vec<_>>(), "{dims:?}");
            assert_eq!(t.spans[0], (0, n));
            for (i, node) in t.nodes.iter().enumerate() {
                if let Node::Split { lo, hi, .. } = *node {
                    assert_eq!(t.spans[lo].0, t.spans[i].0);
                    assert_eq!(t.spans[lo].1, t.spans[hi].0);
                    assert_eq!(t.spans[hi].1, t.spans[i].1);
                }
            }
        }
        assert!(BrickTree::new([0, 1, 1], 8).is_none());
    }

    #[test]
    fn local_roots_cover_a_run_exactly_once() {
        let t = BrickTree::new([3, 2, 5], 16).unwrap();
        for n in 1..=7 {
            for r in 0..n {
                let run = t.rank_leaves(r, n);
                let roots = t.local_roots(run);
                let mut covered: Vec<usize> = roots
                    .iter()
                    .flat_map(|&x| t.spans[x].0..t.spans[x].1)
                    .collect();
                covered.sort_unstable();
                assert_eq!(covered, (run.0..run.1).collect::<Vec<_>>(), "{r}/{n}");
            }
        }
    }

    #[test]
    fn the_front_side_follows_the_eye() {
        let t = BrickTree::new([2, 1, 1], 8).unwrap();
        assert_eq!(
            t.lo_in_front(0, Eye::Direction([1.0, 0.0, 0.0])),
            Some(true)
        );
        assert_eq!(
            t.lo_in_front(0, Eye::Direction([-1.0, 0.2, 0.0])),
            Some(false)
        );
        // The split plane is at voxel 8.
        assert_eq!(t.lo_in_front(0, Eye::Point([7.9, 50.0, 0.0])), Some(true));
        assert_eq!(t.lo_in_front(0, Eye::Point([8.1, 50.0, 0.0])), Some(false));
        assert_eq!(t.lo_in_front(1, Eye::Point([8.1, 50.0, 0.0])), None);
    }
}
