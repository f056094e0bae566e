//! The brick seam (docs/design/brick-seam.md §2.1, issue 31 item 1): a level of a volume cut
//! into bricks of a fixed size with a one-voxel halo, served by a [`BrickSource`].
//!
//! All positions here are **index space** of one pyramid level: voxel `p = (i, j, k)` with
//! `0 ≤ p < dims` (as [`Grid::dims`]), cell `c` the cube whose lower corner is voxel `c`. A brick
//! `b` owns the cells `[B·b, B·b + B)` per axis and so the voxels `[B·b, B·b + B]`, the upper face
//! shared with the next brick (as the splat crate's `BrickGrid`, whose 8³ blocks every brick holds
//! whole). A slot holds its voxels `[B·b − H, B·b + B + H]`, H = 1, so that every stencil the
//! renderers use (trilinear corners, central differences) stays inside one brick.
//!
//! An axis of one voxel (decision 0023) has one degenerate cell, cell 0 (the kernels read it with
//! a zero step to the next voxel); it belongs to brick 0.

use std::ops::Range;
use std::sync::Arc;

use crate::error::{CoreError, Result};
use crate::volume::{Grid, Scalar, Volume};

/// Halo width, in voxels, around the voxels a brick owns (each side, each axis).
pub const HALO: usize = 1;

/// Side of the skip blocks whose ranges a [`Brick`] carries ([`Brick::ranges8`]), in cells: the
/// splat crate's `BrickGrid` block.
pub const BLOCK: usize = 8;

/// Which brick: pyramid level and brick coordinates.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct BrickKey {
    /// Pyramid level (0 = full resolution).
    pub level: u8,
    /// Brick coordinates along i, j, k, in bricks, each below [`BrickLayout::dims`].
    pub b: [u32; 3],
}

impl BrickKey {
    /// The error for this key, with `cause`.
    pub fn error(self, cause: impl Into<String>) -> CoreError {
        CoreError::Brick {
            level: self.level,
            brick: self.b,
            cause: cause.into(),
        }
    }
}

/// How one level is cut into bricks: `B` cells per brick side (a power of two and a multiple of
/// 8, so every 8³ skip block lies in one brick), a halo of [`HALO`] voxels, and
/// `max(ceil((n − 1) / B), 1)` bricks per axis of `n` voxels (as `BrickGrid`). A slot holds
/// `E = B + 1 + 2H` voxels per axis, always the full `E³` (edge bricks are padded), so the slot
/// strides `[1, E, E²]` are the same for every brick.
#[derive(Debug, Clone, PartialEq)]
pub struct BrickLayout {
    grid: Grid,
    level: u8,
    size: usize,
    shift: u32,
    dims: [usize; 3],
}

impl BrickLayout {
    /// The layout of level `level`, of geometry `grid`, in bricks of `size` cells per side.
    ///
    /// Errors (naming `brick size`) if `size` is 0, not a power of two, not a multiple of 8, or
    /// so large that a slot (`E³` voxels) would exceed `i32::MAX` voxels (the arena limit of the
    /// AVX2 gathers).
    pub fn new(grid: Grid, level: u8, size: usize) -> Result<Self> {
        if size == 0 || !size.is_power_of_two() || !size.is_multiple_of(BLOCK) {
            return Err(CoreError::invalid(
                "brick size",
                size,
                "must be a power of two and a multiple of 8 (cells per brick side)",
            ));
        }
        let e = size as u128 + 1 + 2 * HALO as u128;
        let slot = e
            .checked_mul(e)
            .and_then(|s| s.checked_mul(e))
            .unwrap_or(u128::MAX);
        if slot > i32::MAX as u128 {
            return Err(CoreError::TooLarge {
                what: format!("voxels per brick slot at brick size {size}"),
                value: slot,
                limit: i32::MAX as u128,
            });
        }
        let dims = grid.dims.map(|n| n.saturating_sub(1).div_ceil(size).max(1));
        Ok(BrickLayout {
            grid,
            level,
            size,
            shift: size.trailing_zeros(),
            dims,
        })
    }

    /// The level's geometry.
    pub fn grid(&self) -> &Grid {
        &self.grid
    }

    /// The pyramid level this layout cuts (0 = full resolution).
    pub fn level(&self) -> u8 {
        self.level
    }

    /// `B`: cells per brick side.
    pub fn size(&self) -> usize {
        self.size
    }

    /// `log2 B`: a cell's brick is `c >> shift` per axis.
    pub fn shift(&self) -> u32 {
        self.shift
    }

    /// `H`: halo voxels each side ([`HALO`]).
    pub fn halo(&self) -> usize {
        HALO
    }

    /// Bricks per axis (i, j, k): `max(ceil((n − 1) / B), 1)`.
    pub fn dims(&self) -> [usize; 3] {
        self.dims
    }

    /// Number of bricks in the level.
    pub fn brick_count(&self) -> usize {
        self.dims.iter().product()
    }

    /// `E = B + 1 + 2H`: voxels per slot side.
    pub fn extent(&self) -> usize {
        self.size + 1 + 2 * HALO
    }

    /// `E³`: voxels per slot.
    pub fn slot_len(&self) -> usize {
        let e = self.extent();
        e * e * e
    }

    /// Slot strides `[1, E, E²]` (voxels), the same for every brick.
    pub fn slot_strides(&self) -> [usize; 3] {
        let e = self.extent();
        [1, e, e * e]
    }

    /// Cells per axis: `max(n − 1, 1)` (an axis of one voxel has the degenerate cell 0).
    pub fn cells(&self) -> [usize; 3] {
        self.grid.dims.map(|n| n.saturating_sub(1).max(1))
    }

    /// The key of brick `b` of this level; `None` if `b` lies outside [`BrickLayout::dims`].
    pub fn key(&self, b: [usize; 3]) -> Option<BrickKey> {
        if (0..3).any(|a| b[a] >= self.dims[a]) {
            return None;
        }
        Some(BrickKey {
            level: self.level,
            b: b.map(|x| x as u32),
        })
    }

    /// Checks that `key` is a brick of this layout, returning its coordinates.
    pub fn check(&self, key: BrickKey) -> Result<[usize; 3]> {
        if key.level != self.level {
            return Err(key.error(format!("not a brick of level {}", self.level)));
        }
        let b = key.b.map(|x| x as usize);
        if (0..3).any(|a| b[a] >= self.dims[a]) {
            return Err(key.error(format!(
                "outside the level's {}×{}×{} bricks",
                self.dims[0], self.dims[1], self.dims[2]
            )));
        }
        Ok(b)
    }

    /// The brick owning cell `c` (index space of the level); `None` if `c` is not a cell of the
    /// level (beyond [`BrickLayout::cells`]).
    pub fn brick_of_cell(&self, c: [usize; 3]) -> Option<BrickKey> {
        let cells = self.cells();
        if (0..3).any(|a| c[a] >= cells[a]) {
            return None;
        }
        self.key(c.map(|x| x >> self.shift))
    }

    /// The brick serving a stencil centred on voxel `p` (central differences: `p ± 1`, which its
    /// halo holds): `min(p >> log2 B, dims − 1)`; `None` if `p` is not a voxel of the level.
    pub fn brick_of_voxel(&self, p: [usize; 3]) -> Option<BrickKey> {
        if (0..3).any(|a| p[a] >= self.grid.dims[a]) {
            return None;
        }
        self.key(std::array::from_fn(|a| {
            (p[a] >> self.shift).min(self.dims[a] - 1)
        }))
    }

    /// The cells brick `b` owns per axis, `[B·b, B·b + B)` clamped to [`BrickLayout::cells`]
    /// (index space). Errors if `key` is not a brick of this layout.
    pub fn owned_cells(&self, key: BrickKey) -> Result<[Range<usize>; 3]> {
        let b = self.check(key)?;
        let cells = self.cells();
        Ok(std::array::from_fn(|a| {
            let lo = b[a] * self.size;
            lo..(lo + self.size).min(cells[a])
        }))
    }

    /// The voxels brick `b` owns per axis, `[B·b, B·b + B]` clamped to the level (the upper face
    /// is shared with the next brick), as half-open ranges of voxel indices.
    pub fn owned_voxels(&self, key: BrickKey) -> Result<[Range<usize>; 3]> {
        let b = self.check(key)?;
        let n = self.grid.dims;
        Ok(std::array::from_fn(|a| {
            let lo = b[a] * self.size;
            lo..(lo + self.size + 1).min(n[a])
        }))
    }

    /// The voxels a slot holds per axis, `[B·b − H, B·b + B + H]` clamped to the level, as
    /// half-open ranges of voxel indices.
    pub fn halo_voxels(&self, key: BrickKey) -> Result<[Range<usize>; 3]> {
        let b = self.check(key)?;
        let n = self.grid.dims;
        Ok(std::array::from_fn(|a| {
            let lo = b[a] * self.size;
            lo.saturating_sub(HALO)..(lo + self.size + 1 + HALO).min(n[a])
        }))
    }

    /// The slot index of voxel `p` (index space of the level) in brick `key`'s slot:
    /// `Σ (p − B·b + H)·[1, E, E²]`. `None` if `p` lies outside the slot (or `key` outside the
    /// layout).
    pub fn slot_index(&self, key: BrickKey, p: [usize; 3]) -> Option<usize> {
        let b = self.check(key).ok()?;
        let e = self.extent();
        let s = self.slot_strides();
        let mut at = 0;
        for a in 0..3 {
            let l = (p[a] + HALO).checked_sub(b[a] * self.size)?;
            if l >= e {
                return None;
            }
            at += l * s[a];
        }
        Some(at)
    }

    /// Errors ([`CoreError::Brick`] for `key`) unless `len` is a slot's `E³` samples.
    pub fn check_slot_len(&self, key: BrickKey, len: usize) -> Result<()> {
        if len == self.slot_len() {
            return Ok(());
        }
        Err(key.error(format!(
            "the slot holds {len} samples, not E³ = {}",
            self.slot_len()
        )))
    }

    /// The slot positions per axis whose voxel `B·b − H + l` lies inside the level: the halo
    /// box ([`BrickLayout::halo_voxels`]) in slot positions, `[1, …)` at a low face (brick 0)
    /// and `[…, n + H − B·b)` at a high face; the other positions of an edge brick's slot repeat
    /// the nearest of these ([`pad_slot`]).
    pub fn slot_interior(&self, key: BrickKey) -> Result<[Range<usize>; 3]> {
        let halo = self.halo_voxels(key)?;
        let b = self.check(key)?;
        Ok(std::array::from_fn(|a| {
            // halo.start ≥ B·b − H, so this is the slot position of the first voxel.
            let base = b[a] * self.size;
            halo[a].start + HALO - base..halo[a].end + HALO - base
        }))
    }
}

/// A resident brick: the voxels `[B·b − H, B·b + B + H]` of its level at slot index
/// `(p − B·b + H)·[1, E, E²]` ([`BrickLayout::slot_index`]), plus its skip-block and value ranges.
#[derive(Debug, Clone, PartialEq)]
pub struct Brick<T> {
    /// Which brick.
    pub key: BrickKey,
    /// The full `E³` slot, i fastest. Slot positions outside the level (edge bricks) hold the
    /// nearest voxel of the level (the clamped index): finite values inside the level's range,
    /// which no kernel reads (faces are tested on global indices).
    pub data: Box<[T]>,
    /// `[min, max]` (data units) of each 8³ skip block the brick owns, `(B/8)³` of them, i
    /// fastest. Block `q` (global block index `(B/8)·b + q`) covers the voxels `[8q, 8q + 8]`
    /// clamped to the level, as `BrickGrid`; a block beyond the level is empty, `[+∞, −∞]`.
    /// NaN voxels are ignored (as `f32::min`/`max` do).
    pub ranges8: Box<[[f32; 2]]>,
    /// `[min, max]` (data units) of the voxels the brick owns ([`BrickLayout::owned_voxels`]),
    /// halo excluded: the union of [`Brick::ranges8`].
    pub range: [f32; 2],
}

impl<T: Scalar> Brick<T> {
    /// Brick `key` of `layout`, cut from `region`: the box of voxels `[region_lo, region_lo +
    /// region_dims)` of the level (index space), x fastest, which must hold the brick's halo box
    /// ([`BrickLayout::halo_voxels`]; the whole level, as [`InMemory`] passes it, or exactly the
    /// halo box, as a store reads it). The slot holds voxel `B·b − H + l` clamped to the level at
    /// slot position `l` (edge padding repeats the nearest voxel of the level); the ranges are
    /// those of [`Brick::ranges8`] and [`Brick::range`], read from the slot.
    ///
    /// Errors ([`CoreError::Brick`] naming the level and brick): `key` not a brick of `layout`;
    /// a region that does not hold the halo box, lies outside the level or whose length is not
    /// `region_dims`' product; a slot that cannot be allocated.
    pub fn from_region(
        layout: &BrickLayout,
        key: BrickKey,
        region: &[T],
        region_lo: [usize; 3],
        region_dims: [usize; 3],
    ) -> Result<Brick<T>> {
        let b = check_region(layout, key, region, region_lo, region_dims)?;
        let mut data = Vec::new();
        data.try_reserve_exact(layout.slot_len())
            .map_err(|_| key.error("cannot allocate the brick's slot"))?;
        data.resize(layout.slot_len(), T::from_f64(0.0));
        copy_slot(layout, b, region, region_lo, region_dims, &mut data);
        Brick::from_slot(layout, key, data.into_boxed_slice())
    }

    /// Brick `key` of `layout` from its full slot `data` (`E³` samples, i fastest, as
    /// [`Brick::data`]), its ranges read from the slot ([`Brick::ranges8`], [`Brick::range`]).
    ///
    /// Errors ([`CoreError::Brick`]): `key` not a brick of `layout`; `data` not `E³` long; the
    /// ranges cannot be allocated.
    pub fn from_slot(layout: &BrickLayout, key: BrickKey, data: Box<[T]>) -> Result<Brick<T>> {
        layout.check(key)?;
        if data.len() != layout.slot_len() {
            return Err(key.error(format!(
                "the slot holds {} samples, not E³ = {}",
                data.len(),
                layout.slot_len()
            )));
        }
        let ranges8 = block_ranges(layout, key, &data)?;
        let range = ranges8
            .iter()
            .fold([f32::INFINITY, f32::NEG_INFINITY], |r, q| {
                [r[0].min(q[0]), r[1].max(q[1])]
            });
        Ok(Brick {
            key,
            data,
            ranges8,
            range,
        })
    }
}

/// A source of bricks for one volume and its pyramid levels (docs/design/brick-seam.md §2.1).
///
/// Reads are fallible (a store can fail); renderers call them only at serial points, never inside
/// their parallel loops.
pub trait BrickSource<T: Scalar>: Send + Sync {
    /// The geometry of each level; level 0 is full resolution.
    fn levels(&self) -> &[Grid];

    /// How level `level` is cut into bricks; `None` if there is no such level.
    fn layout(&self, level: usize) -> Option<&BrickLayout>;

    /// `[min, max]` (data units) of the voxels brick `key` owns, where known without reading a
    /// store (a sidecar, a resident copy); `None` when unknown or `key` is not a brick.
    fn brick_range(&self, key: BrickKey) -> Option<[f32; 2]>;

    /// The brick, read and decoded. Errors ([`CoreError::Brick`]) name the level, the brick and
    /// the cause.
    fn brick(&self, key: BrickKey) -> Result<Arc<Brick<T>>>;

    /// Reads brick `key`'s `E³` samples into `slot` (i fastest, as [`Brick::data`]: the voxel
    /// `B·b − H + l` clamped to the level at slot position `l`), without its ranges: what a
    /// cache of slots needs, with no slot allocated per read. The default reads
    /// [`BrickSource::brick`] and copies its slot; sources that read a box of voxels override it
    /// to write the box straight into `slot` ([`fill_slot`], [`pad_slot`]).
    ///
    /// Errors as [`BrickSource::brick`], and ([`CoreError::Brick`]) a `slot` that is not `E³`
    /// long or a served brick that is not `key` with a full slot. On error `slot`'s contents
    /// are unspecified.
    fn read_slot(&self, key: BrickKey, slot: &mut [T]) -> Result<()> {
        let brick = self.brick(key)?;
        if brick.key != key || brick.data.len() != slot.len() {
            return Err(key.error(format!(
                "the brick source served brick {:?} of level {} with {} samples, where {} were \
                 expected",
                brick.key.b,
                brick.key.level,
                brick.data.len(),
                slot.len()
            )));
        }
        slot.copy_from_slice(&brick.data);
        Ok(())
    }

    /// Reads a batch of bricks at once, `keys[i]` into `slots[i]` (each `E³`), as
    /// [`BrickSource::read_slot`] would one by one; `None` where the source has no better way
    /// than that (the default), and the caller reads them one by one (in parallel). A store
    /// whose chunks several bricks of the batch share implements it to decode each such chunk
    /// once for the batch. Errors as [`BrickSource::read_slot`] (naming a brick that needed what
    /// failed); on error the slots' contents are unspecified.
    fn read_slots(&self, keys: &[BrickKey], slots: &mut [&mut [T]]) -> Option<Result<()>> {
        let _ = (keys, slots);
        None
    }

    /// Zero-copy fast path: the whole level as one in-memory volume, where there is one.
    fn whole(&self, level: usize) -> Result<Option<Arc<Volume<T>>>> {
        let _ = level;
        Ok(None)
    }
}

/// A [`BrickSource`] over one in-memory [`Volume`]: one level, served whole with no copy
/// ([`BrickSource::whole`]); [`BrickSource::brick`] copies a region (for tests and streaming
/// passes; no in-memory render calls it).
#[derive(Debug, Clone)]
pub struct InMemory<T> {
    volume: Arc<Volume<T>>,
    levels: [Grid; 1],
    layout: BrickLayout,
}

impl<T: Scalar> InMemory<T> {
    /// `volume` cut into bricks of `size` cells per side. Errors as [`BrickLayout::new`].
    pub fn new(volume: Arc<Volume<T>>, size: usize) -> Result<Self> {
        let grid = volume.grid().clone();
        let layout = BrickLayout::new(grid.clone(), 0, size)?;
        Ok(InMemory {
            volume,
            levels: [grid],
            layout,
        })
    }

    /// The volume.
    pub fn volume(&self) -> &Arc<Volume<T>> {
        &self.volume
    }
}

impl<T: Scalar> BrickSource<T> for InMemory<T> {
    fn levels(&self) -> &[Grid] {
        &self.levels
    }

    fn layout(&self, level: usize) -> Option<&BrickLayout> {
        (level == 0).then_some(&self.layout)
    }

    fn brick_range(&self, key: BrickKey) -> Option<[f32; 2]> {
        let owned = self.layout.owned_voxels(key).ok()?;
        let n = self.volume.grid().dims;
        let data = self.volume.data();
        let mut r = [f32::INFINITY, f32::NEG_INFINITY];
        for k in owned[2].clone() {
            for j in owned[1].clone() {
                let row = (k * n[1] + j) * n[0];
                for v in &data[row + owned[0].start..row + owned[0].end] {
                    let v = v.to_f32();
                    r = [r[0].min(v), r[1].max(v)];
                }
            }
        }
        Some(r)
    }

    fn brick(&self, key: BrickKey) -> Result<Arc<Brick<T>>> {
        let n = self.volume.grid().dims;
        Brick::from_region(&self.layout, key, self.volume.data(), [0; 3], n).map(Arc::new)
    }

    fn read_slot(&self, key: BrickKey, slot: &mut [T]) -> Result<()> {
        let n = self.volume.grid().dims;
        fill_slot(&self.layout, key, self.volume.data(), [0; 3], n, slot)
    }

    fn whole(&self, level: usize) -> Result<Option<Arc<Volume<T>>>> {
        Ok((level == 0).then(|| self.volume.clone()))
    }
}

/// Fills `slot` (brick `key`'s `E³` samples, i fastest, as [`Brick::data`]) from `region`: the
/// box of voxels `[region_lo, region_lo + region_dims)` of the level (index space, x fastest),
/// which must hold the brick's halo box ([`BrickLayout::halo_voxels`]). Slot position `l` gets
/// voxel `B·b − H + l` clamped to the level, as [`Brick::from_region`]; nothing is allocated.
///
/// Errors ([`CoreError::Brick`]): as [`Brick::from_region`], and a `slot` that is not `E³`
/// long.
pub fn fill_slot<T: Scalar>(
    layout: &BrickLayout,
    key: BrickKey,
    region: &[T],
    region_lo: [usize; 3],
    region_dims: [usize; 3],
    slot: &mut [T],
) -> Result<()> {
    let b = check_region(layout, key, region, region_lo, region_dims)?;
    layout.check_slot_len(key, slot.len())?;
    copy_slot(layout, b, region, region_lo, region_dims, slot);
    Ok(())
}

/// Checks that `region` (the voxels `[lo, lo + dims)`) holds brick `key`'s halo box inside the
/// level and has `dims`' product of samples; the brick's coordinates.
fn check_region<T>(
    layout: &BrickLayout,
    key: BrickKey,
    region: &[T],
    region_lo: [usize; 3],
    region_dims: [usize; 3],
) -> Result<[usize; 3]> {
    let b = layout.check(key)?;
    let halo = layout.halo_voxels(key)?;
    let n = layout.grid().dims;
    let fits = (0..3).all(|a| {
        region_lo[a] <= halo[a].start
            && region_lo[a]
                .checked_add(region_dims[a])
                .is_some_and(|end| halo[a].end <= end && end <= n[a])
    });
    if !fits {
        return Err(key.error(format!(
            "the region of {region_dims:?} voxels at {region_lo:?} does not hold the brick's \
             voxels [{}, {}) × [{}, {}) × [{}, {}) inside the level's {n:?}",
            halo[0].start, halo[0].end, halo[1].start, halo[1].end, halo[2].start, halo[2].end
        )));
    }
    let want = region_dims
        .iter()
        .try_fold(1usize, |p, &d| p.checked_mul(d));
    if want != Some(region.len()) {
        return Err(key.error(format!(
            "the region holds {} samples where {region_dims:?} needs {}",
            region.len(),
            want.map_or_else(|| "more than usize".into(), |w| w.to_string())
        )));
    }
    Ok(b)
}

/// Fills the slot positions of brick `key` whose voxel lies outside the level (edge bricks:
/// the positions before [`BrickLayout::slot_interior`]'s start or from its end, per axis) with
/// the nearest position inside, so that a slot whose interior holds the halo box
/// ([`BrickLayout::halo_voxels`]) holds voxel `B·b − H + l` clamped to the level at every
/// position `l`, as [`Brick::from_region`]. The clamp is separable, so x is padded within the
/// interior rows, then whole rows along y within the interior planes, then whole planes along
/// z. Errors if `key` is not a brick of `layout` or `slot` is not `E³` long.
pub fn pad_slot<T: Copy>(layout: &BrickLayout, key: BrickKey, slot: &mut [T]) -> Result<()> {
    let inner = layout.slot_interior(key)?;
    let e = layout.extent();
    layout.check_slot_len(key, slot.len())?;
    let [x, y, z] = inner;
    for k in z.clone() {
        for j in y.clone() {
            let row = &mut slot[(k * e + j) * e..(k * e + j + 1) * e];
            let (first, last) = (row[x.start], row[x.end - 1]);
            row[..x.start].fill(first);
            row[x.end..].fill(last);
        }
        let plane = k * e * e;
        for j in (0..y.start).chain(y.end..e) {
            let from = plane + if j < y.start { y.start } else { y.end - 1 } * e;
            slot.copy_within(from..from + e, plane + j * e);
        }
    }
    for k in (0..z.start).chain(z.end..e) {
        let from = if k < z.start { z.start } else { z.end - 1 } * e * e;
        slot.copy_within(from..from + e * e, k * e * e);
    }
    Ok(())
}

/// Fills `out` (the `E³` slot of brick `b`) with voxel `B·b − H + l` (clamped to the level) at
/// slot position `l`, read from `region` (the voxels `[lo, lo + dims)`, x fastest, holding the
/// halo box: checked by [`check_region`]): the halo box's rows copied into the slot's interior
/// ([`BrickLayout::slot_interior`]), then the rest padded ([`pad_slot`]).
fn copy_slot<T: Scalar>(
    layout: &BrickLayout,
    b: [usize; 3],
    region: &[T],
    lo: [usize; 3],
    dims: [usize; 3],
    out: &mut [T],
) {
    let e = layout.extent();
    let n = layout.grid().dims;
    // The slot's interior: slot positions whose voxel `B·b − H + l` lies inside the level.
    let inner: [Range<usize>; 3] = std::array::from_fn(|a| {
        let g0 = b[a] * layout.size();
        let start = HALO.saturating_sub(g0);
        start..(n[a] + HALO).saturating_sub(g0).min(e)
    });
    let w = inner[0].len();
    for lz in inner[2].clone() {
        let k = b[2] * layout.size() + lz - HALO - lo[2];
        for ly in inner[1].clone() {
            let j = b[1] * layout.size() + ly - HALO - lo[1];
            let s = (k * dims[1] + j) * dims[0] + (b[0] * layout.size() + inner[0].start - HALO)
                - lo[0];
            let d = (lz * e + ly) * e + inner[0].start;
            out[d..d + w].copy_from_slice(&region[s..s + w]);
        }
    }
    let key = BrickKey {
        level: layout.level,
        b: b.map(|x| x as u32),
    };
    // Cannot fail: `b` was checked and `out` is E³ long.
    let _ = pad_slot(layout, key, out);
}

impl BrickLayout {
    /// Skip blocks per brick side: `B / 8`.
    pub fn blocks_per_brick(&self) -> usize {
        self.size / BLOCK
    }

    /// The voxels of skip block `q` of brick `key` (`q` indexes [`Brick::ranges8`]: `(B/8)³`
    /// blocks, i fastest) as slot-local ranges (slot position `p − B·b + H` per axis): global
    /// block `g = (B/8)·b + q` covers the voxels `[8g, 8g + 8]` clamped to the level, as the
    /// splat crate's `BrickGrid`. `None` for a block beyond the level (or `q` out of range).
    /// Errors if `key` is not a brick of this layout.
    pub fn block_span(&self, key: BrickKey, q: usize) -> Result<Option<[Range<usize>; 3]>> {
        let b = self.check(key)?;
        let per = self.blocks_per_brick();
        if q >= per * per * per {
            return Ok(None);
        }
        let n = self.grid.dims;
        let local = [q % per, q / per % per, q / (per * per)];
        let g: [usize; 3] = std::array::from_fn(|a| b[a] * per + local[a]);
        let blocks = n.map(|n| n.saturating_sub(1).div_ceil(BLOCK).max(1));
        if (0..3).any(|a| g[a] >= blocks[a]) {
            return Ok(None);
        }
        Ok(Some(std::array::from_fn(|a| {
            let lo = g[a] * BLOCK;
            let base = b[a] * self.size;
            lo - base + HALO..(lo + BLOCK).min(n[a] - 1) - base + HALO + 1
        })))
    }
}

/// The ranges of brick `key`'s 8³ blocks, read from its slot ([`Brick::ranges8`]).
fn block_ranges<T: Scalar>(
    layout: &BrickLayout,
    key: BrickKey,
    slot: &[T],
) -> Result<Box<[[f32; 2]]>> {
    let per = layout.blocks_per_brick();
    let s = layout.slot_strides();
    let mut out = Vec::new();
    out.try_reserve_exact(per * per * per)
        .map_err(|_| key.error("cannot allocate the brick's block ranges"))?;
    for q in 0..per * per * per {
        let mut r = [f32::INFINITY, f32::NEG_INFINITY];
        if let Some(span) = layout.block_span(key, q)? {
            for z in span[2].clone() {
                for y in span[1].clone() {
                    for x in span[0].clone() {
                        let v = slot[x + y * s[1] + z * s[2]].to_f32();
                        r = [r[0].min(v), r[1].max(v)];
                    }
                }
            }
        }
        out.push(r);
    }
    Ok(out.into_boxed_slice())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn layout(dims: [usize; 3], size: usize) -> BrickLayout {
        BrickLayout::new(Grid::with_dims(dims).unwrap(), 0, size).unwrap()
    }

    fn keys(l: &BrickLayout) -> Vec<BrickKey> {
        let d = l.dims();
        let mut out = Vec::new();
        for k in 0..d[2] {
            for j in 0..d[1] {
                for i in 0..d[0] {
                    out.push(l.key([i, j, k]).unwrap());
                }
            }
        }
        out
    }

    /// `Brick::from_region`'s slot, whose unclamped x runs are copied at once, holds at every
    /// slot position the level's sample at the clamped global index, for edge and interior
    /// bricks of odd sizes and axes of 1–2 voxels, cut from the halo box or from a larger box.
    #[test]
    fn a_slot_holds_the_clamped_samples_of_its_region() {
        for size in [8, 16] {
            for dims in [
                [1, 2, 9],
                [37, 20, 9],
                [2, 1, 30],
                [29, 17, 1],
                [40, 33, 18],
            ] {
                let l = layout(dims, size);
                let f = |i: usize, j: usize, k: usize| (i + 101 * j + 10_007 * k) as f32;
                let e = l.extent();
                for key in keys(&l) {
                    let halo = l.halo_voxels(key).unwrap();
                    // The halo box, and the whole level as a larger region.
                    for (lo, hi) in [
                        (halo.clone().map(|r| r.start), halo.clone().map(|r| r.end)),
                        ([0; 3], dims),
                    ] {
                        let rd: [usize; 3] = std::array::from_fn(|a| hi[a] - lo[a]);
                        let mut region = Vec::new();
                        for k in 0..rd[2] {
                            for j in 0..rd[1] {
                                for i in 0..rd[0] {
                                    region.push(f(lo[0] + i, lo[1] + j, lo[2] + k));
                                }
                            }
                        }
                        let brick = Brick::from_region(&l, key, &region, lo, rd).unwrap();
                        // The same slot written into a poisoned one, with nothing allocated.
                        let mut slot = vec![-7.5f32; l.slot_len()];
                        fill_slot(&l, key, &region, lo, rd, &mut slot).unwrap();
                        assert_eq!(*slot, *brick.data, "fill_slot {dims:?} B {size} {key:?}");
                        let g = |a: usize, p: usize| {
                            (key.b[a] as usize * size + p)
                                .saturating_sub(HALO)
                                .min(dims[a] - 1)
                        };
                        for lz in 0..e {
                            for ly in 0..e {
                                for lx in 0..e {
                                    let want = f(g(0, lx), g(1, ly), g(2, lz));
                                    let got = brick.data[lx + e * (ly + e * lz)];
                                    assert_eq!(
                                        got, want,
                                        "{dims:?} B {size} {key:?} ({lx},{ly},{lz})"
                                    );
                                }
                            }
                        }
                    }
                }
            }
        }
    }

    /// `pad_slot` completes a slot whose interior (`slot_interior`: the halo box) alone was
    /// written; `InMemory::read_slot` gives `brick()`'s slot; short slots are errors.
    #[test]
    fn a_slot_read_into_place_equals_the_brick() {
        for size in [8, 16] {
            for dims in [[1, 2, 9], [37, 20, 9], [29, 17, 1], [17, 17, 17]] {
                let l = layout(dims, size);
                let data: Vec<f32> = (0..dims.iter().product::<usize>())
                    .map(|i| (i * 7 % 1013) as f32)
                    .collect();
                let vol = Volume::new(Grid::with_dims(dims).unwrap(), data).unwrap();
                let mem = InMemory::new(Arc::new(vol), size).unwrap();
                let e = l.extent();
                for key in keys(&l) {
                    let want = mem.brick(key).unwrap();
                    let mut slot = vec![f32::NAN; l.slot_len()];
                    mem.read_slot(key, &mut slot).unwrap();
                    assert_eq!(*slot, *want.data, "{dims:?} B {size} {key:?}");
                    // Only the interior written, then padded.
                    let inner = l.slot_interior(key).unwrap();
                    let halo = l.halo_voxels(key).unwrap();
                    for a in 0..3 {
                        assert_eq!(inner[a].len(), halo[a].len());
                    }
                    let mut only = vec![f32::NAN; l.slot_len()];
                    for z in inner[2].clone() {
                        for y in inner[1].clone() {
                            for x in inner[0].clone() {
                                let at = x + e * (y + e * z);
                                only[at] = want.data[at];
                            }
                        }
                    }
                    pad_slot(&l, key, &mut only).unwrap();
                    assert_eq!(
                        only.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                        want.data.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                        "padded {dims:?} B {size} {key:?}"
                    );
                    let mut short = vec![0.0f32; l.slot_len() - 1];
                    assert!(mem.read_slot(key, &mut short).is_err());
                    assert!(pad_slot(&l, key, &mut short).is_err());
                }
            }
        }
    }

    #[test]
    fn bricks_per_axis_follow_brick_grid() {
        // (n, B, bricks): ceil((n − 1) / B), at least 1.
        for (n, b, want) in [
            (1, 8, 1),
            (2, 8, 1),
            (8, 8, 1),
            (9, 8, 1),
            (10, 8, 2),
            (17, 8, 2),
            (18, 8, 3),
            (37, 8, 5),
            (37, 16, 3),
            (65, 64, 1),
            (66, 64, 2),
            (200, 64, 4),
            (129, 128, 1),
            (130, 128, 2),
        ] {
            let l = layout([n, 1, 2], b);
            assert_eq!(l.dims(), [want, 1, 1], "n = {n}, B = {b}");
            assert_eq!(l.extent(), b + 3);
            assert_eq!(l.slot_strides(), [1, b + 3, (b + 3) * (b + 3)]);
            assert_eq!(l.slot_len(), (b + 3).pow(3));
        }
    }

    #[test]
    fn every_cell_belongs_to_exactly_one_brick_and_halos_clamp_at_faces() {
        for size in [8, 16, 64, 128] {
            for dims in [
                [1, 2, 9],
                [37, 20, 9],
                [2, 1, 130],
                [129, 17, 1],
                [200, 65, 8],
            ] {
                let l = layout(dims, size);
                let cells = l.cells();
                let all = keys(&l);
                for a in 0..3 {
                    // Walk one axis at a time (the ranges are per axis).
                    for c in 0..cells[a] {
                        let mut p = [0; 3];
                        p[a] = c;
                        let owner = l.brick_of_cell(p).unwrap();
                        let owning = all
                            .iter()
                            .filter(|&&k| {
                                let r = l.owned_cells(k).unwrap();
                                (0..3).all(|x| r[x].contains(&p[x]))
                            })
                            .count();
                        assert_eq!(owning, 1, "cell {p:?} in {dims:?} at B = {size}");
                        let r = l.owned_cells(owner).unwrap();
                        assert!(r[a].contains(&c));
                        // Its stencil: voxels c − 1 … c + 2, clamped, lie in the owner's halo.
                        let h = l.halo_voxels(owner).unwrap();
                        let lo = c.saturating_sub(1);
                        let hi = (c + 2).min(dims[a] - 1);
                        assert!(h[a].contains(&lo) && h[a].contains(&hi), "{c} in {h:?}");
                        for q in [lo, hi] {
                            let mut v = [0; 3];
                            v[a] = q;
                            let s = l.slot_index(owner, v).unwrap();
                            assert!(s < l.slot_len());
                        }
                    }
                    assert!(
                        l.brick_of_cell(std::array::from_fn(|x| cells[x] * (x == a) as usize))
                            .is_none()
                    );
                }
                for &k in &all {
                    let o = l.owned_voxels(k).unwrap();
                    let h = l.halo_voxels(k).unwrap();
                    for a in 0..3 {
                        let b = k.b[a] as usize;
                        assert_eq!(o[a].start, b * size);
                        assert_eq!(h[a].start, (b * size).saturating_sub(1));
                        assert_eq!(h[a].end, (b * size + size + 2).min(dims[a]));
                        if b == 0 {
                            assert_eq!(h[a].start, 0, "halo clamps at the low face");
                        }
                        if b + 1 == l.dims()[a] {
                            assert_eq!(o[a].end, dims[a], "the last brick reaches the face");
                            assert_eq!(h[a].end, dims[a], "halo clamps at the high face");
                        } else {
                            assert_eq!(o[a].end, b * size + size + 1, "shared upper face");
                        }
                        assert!(h[a].end - h[a].start <= l.extent());
                    }
                }
                // Voxel-centred stencils: the chosen brick's halo holds p ± 1.
                for a in 0..3 {
                    for q in 0..dims[a] {
                        let mut p = [0; 3];
                        p[a] = q;
                        let k = l.brick_of_voxel(p).unwrap();
                        let h = l.halo_voxels(k).unwrap();
                        assert!(h[a].contains(&q.saturating_sub(1)));
                        assert!(h[a].contains(&(q + 1).min(dims[a] - 1)));
                    }
                }
            }
        }
    }

    #[test]
    fn a_hostile_brick_size_is_a_typed_error() {
        let g = Grid::with_dims([37, 20, 9]).unwrap();
        for size in [0, 1, 4, 12, 24, 48, 100, 1 << 11, usize::MAX / 2 + 1] {
            let e = BrickLayout::new(g.clone(), 0, size).unwrap_err();
            assert!(e.to_string().contains("brick size"), "{size}: {e}");
        }
        for size in [8, 16, 32, 64, 128, 1024] {
            assert!(BrickLayout::new(g.clone(), 0, size).is_ok());
        }
    }

    #[test]
    fn keys_outside_the_level_are_errors_naming_level_and_brick() {
        let v = Arc::new(
            Volume::from_fn(Grid::with_dims([37, 20, 9]).unwrap(), |_, _, _| 0u8).unwrap(),
        );
        let s = InMemory::new(v, 8).unwrap();
        assert_eq!(s.layout(0).unwrap().dims(), [5, 3, 1]);
        for key in [
            BrickKey {
                level: 0,
                b: [5, 0, 0],
            },
            BrickKey {
                level: 0,
                b: [0, 3, 0],
            },
            BrickKey {
                level: 0,
                b: [0, 0, 1],
            },
            BrickKey {
                level: 1,
                b: [0, 0, 0],
            },
        ] {
            let e = s.brick(key).unwrap_err();
            assert!(
                matches!(e, CoreError::Brick { level, brick, .. } if level == key.level && brick == key.b),
                "{e}"
            );
            assert!(
                e.to_string().contains(&format!("level {}", key.level)),
                "{e}"
            );
            assert!(s.brick_range(key).is_none());
        }
        assert!(s.layout(1).is_none());
        assert!(s.whole(1).unwrap().is_none());
    }

    #[test]
    fn in_memory_bricks_equal_the_volume_voxel_for_voxel() {
        let dims = [37, 20, 9];
        // Distinct values everywhere (a wrong voxel cannot pass), some negative.
        let v = Volume::from_fn(Grid::with_dims(dims).unwrap(), |i, j, k| {
            (i + 37 * (j + 20 * k)) as f32 - 3000.0
        })
        .unwrap();
        let v = Arc::new(v);
        let s = InMemory::new(v.clone(), 8).unwrap();
        assert!(
            Arc::ptr_eq(&s.whole(0).unwrap().unwrap(), &v),
            "whole is the volume, no copy"
        );
        let l = s.layout(0).unwrap().clone();
        let e = l.extent();
        let mut seen = 0;
        for key in keys(&l) {
            let brick = s.brick(key).unwrap();
            assert_eq!(brick.key, key);
            assert_eq!(brick.data.len(), e * e * e);
            let h = l.halo_voxels(key).unwrap();
            for k in h[2].clone() {
                for j in h[1].clone() {
                    for i in h[0].clone() {
                        let at = l.slot_index(key, [i, j, k]).unwrap();
                        assert_eq!(brick.data[at], v.get(i, j, k), "{key:?} voxel {i},{j},{k}");
                        seen += 1;
                    }
                }
            }
            // Padding: the clamped voxel.
            let b = key.b.map(|x| x as usize);
            for (at, &got) in brick.data.iter().enumerate() {
                let l3 = [at % e, at / e % e, at / (e * e)];
                let p: [usize; 3] =
                    std::array::from_fn(|a| (b[a] * 8 + l3[a]).saturating_sub(1).min(dims[a] - 1));
                assert_eq!(got, v.get(p[0], p[1], p[2]));
            }
            // Ranges: brute force over the owned voxels (the values grow with i, j, k).
            let o = l.owned_voxels(key).unwrap();
            let lo = v.get(o[0].start, o[1].start, o[2].start);
            let hi = v.get(o[0].end - 1, o[1].end - 1, o[2].end - 1);
            assert_eq!(brick.range, [lo, hi], "{key:?}");
            assert_eq!(s.brick_range(key), Some([lo, hi]));
            assert_eq!(brick.ranges8.len(), 1);
            assert_eq!(brick.ranges8[0], [lo, hi]);
        }
        // Halo counts: per axis the sum of the clamped halo widths.
        let per_axis = |n: usize, nb: usize| -> usize {
            (0..nb)
                .map(|b| (b * 8 + 10).min(n) - (b * 8).saturating_sub(1))
                .sum()
        };
        assert_eq!(seen, per_axis(37, 5) * per_axis(20, 3) * per_axis(9, 1));
    }

    #[test]
    fn block_ranges_match_brute_force_and_empty_blocks_beyond_the_level() {
        let dims = [21, 9, 1];
        let v = Volume::from_fn(Grid::with_dims(dims).unwrap(), |i, j, _| {
            ((i * 7 + j * 13) % 11) as u16
        })
        .unwrap();
        let s = InMemory::new(Arc::new(v.clone()), 16).unwrap();
        let l = s.layout(0).unwrap();
        assert_eq!(l.dims(), [2, 1, 1]);
        for key in keys(l) {
            let brick = s.brick(key).unwrap();
            assert_eq!(brick.ranges8.len(), 8);
            for (q, r) in brick.ranges8.iter().enumerate() {
                let g = [key.b[0] as usize * 2 + q % 2, q / 2 % 2, q / 4];
                let blocks = [3, 1, 1];
                if (0..3).any(|a| g[a] >= blocks[a]) {
                    assert_eq!(*r, [f32::INFINITY, f32::NEG_INFINITY], "{key:?} {q}");
                    continue;
                }
                let mut want = [f32::INFINITY, f32::NEG_INFINITY];
                for j in g[1] * 8..=(g[1] * 8 + 8).min(dims[1] - 1) {
                    for i in g[0] * 8..=(g[0] * 8 + 8).min(dims[0] - 1) {
                        let x = v.get(i, j, 0) as f32;
                        want = [want[0].min(x), want[1].max(x)];
                    }
                }
                assert_eq!(*r, want, "{key:?} block {g:?}");
            }
        }
    }
    #[test]
    fn bricks_from_their_halo_box_equal_bricks_from_the_whole_level() {
        for (dims, size) in [
            ([37, 20, 9], 8),
            ([37, 20, 9], 16),
            ([1, 5, 9], 8),
            ([66, 3, 2], 64),
        ] {
            let v = Volume::from_fn(Grid::with_dims(dims).unwrap(), |i, j, k| {
                ((i * 31 + j * 17 + k * 7) % 251) as i16 - 100
            })
            .unwrap();
            let s = InMemory::new(Arc::new(v.clone()), size).unwrap();
            let l = s.layout(0).unwrap();
            for key in keys(l) {
                let h = l.halo_voxels(key).unwrap();
                let mut region = Vec::new();
                for k in h[2].clone() {
                    for j in h[1].clone() {
                        for i in h[0].clone() {
                            region.push(v.get(i, j, k));
                        }
                    }
                }
                let lo = h.clone().map(|r| r.start);
                let hd = h.clone().map(|r| r.len());
                let b = Brick::from_region(l, key, &region, lo, hd).unwrap();
                assert_eq!(b, *s.brick(key).unwrap(), "{dims:?} B = {size} {key:?}");
                // A region one voxel short of the halo box, or of the wrong length: errors
                // naming the brick, no panic.
                for a in 0..3 {
                    let mut short = hd;
                    short[a] -= 1;
                    let e = Brick::from_region(l, key, &region, lo, short).unwrap_err();
                    assert!(
                        matches!(e, CoreError::Brick { brick, .. } if brick == key.b),
                        "{e}"
                    );
                }
                let e = Brick::from_region(l, key, &region[1..], lo, hd).unwrap_err();
                assert!(e.to_string().contains("samples"), "{e}");
                let e = Brick::from_region(l, key, &region, lo.map(|x| x + 1), hd).unwrap_err();
                assert!(e.to_string().contains("does not hold"), "{e}");
            }
        }
    }
}
