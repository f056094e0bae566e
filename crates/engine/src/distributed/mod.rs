//! Sort-last rendering across processes (issue 32): a volume cut into bricks by a rule that
//! does not depend on the number of processes, each process rendering the partial images of its
//! bricks, and the partial images composited over a tree fixed by the bricks
//! ([`BrickTree`]), so that the image is the same bits for any number of processes
//! ([`composite_direct_send`]). The message passing is behind [`Communicator`]: in-process
//! threads here ([`FakeCluster`]), MPI in `crates/mpi`.
//!
//! What is built: the tree, the assignment of bricks to ranks, the compositing protocol and its
//! failure path, and a brick's partial image from the slabs
//! ([`volsplat_splat::RenderSettings::owned_cells`]: the whole volume in memory, only the
//! brick's cells drawn, every sample at its global position; composited, 156 dB from the
//! single-process render and the same bits for any rank count, `tests.rs`), and ranks that read
//! only their bricks of an OME-Zarr store or a NRRD file with a raw payload, float levels with
//! NaN or ±∞ included, in every mode (`store_tests.rs`; [`render_sort_last`]). What is not
//! yet: pre-integration across a brick face (a brick's first sample has no previous one),
//! early
//! termination across bricks (each brick's image runs to its own opacity). X-ray is summed from
//! bricks drawn by the sheets or the splat list, each drawing the voxels of its cells (read
//! per rank: those voxels alone, drawn as a sub-volume of the level); MIP and
//! MinIP take the extreme of the slabs' bricks, bit for bit the single-process projection.
//! The MPI communicator and the `volsplat-mpi` binary are in `crates/mpi`.

mod comm;
mod composite;
mod render;
mod tree;

pub use comm::{Communicator, FakeCluster, FakeComm};
pub use composite::{Combine, Pixels, composite_direct_send, fail_direct_send, stripe_rows};
pub use render::{SortLastImage, render_sort_last};
pub use tree::{BrickTree, Eye, Node};

/// A sort-last rank's part of a volume read in bricks
/// ([`crate::Renderer`]'s part of an OME-Zarr store or a NRRD raw file): what its ranges scan
/// found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct RankPart {
    /// `[min, max]` of the part's samples (data units); `None` for an empty part.
    pub(crate) range: Option<[f32; 2]>,
    /// `[lowest, highest]` finite sample of the part (data units); `None` where none is.
    pub(crate) finite: Option<[f32; 2]>,
    /// Whether the part holds NaN or infinite floats (replaced by the level's finite extremes
    /// once the ranks have shared their finite ranges: `Renderer::set_rank_range`).
    pub(crate) non_finite: bool,
}

/// What one rank read of its part of a store or NRRD file ([`crate::Renderer::rank_reads`]):
/// issue 32's "each
/// rank reads only its bricks, with their halo". Bytes are decoded samples of the cache's
/// bricks (`E³` samples each, `E` = cells per brick + 3: the shared face and a halo of one
/// voxel each side); a store's compressed bytes are fewer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RankReads {
    /// Cells per side of the cache's bricks (the largest power of two, at most 64, that
    /// divides the sort-last brick).
    pub brick: usize,
    /// The cache's bricks that meet the rank's sort-last bricks: the only ones it may read.
    pub region_bricks: usize,
    /// The cache's bricks of the whole level.
    pub level_bricks: usize,
    /// Bytes read by the ranges scan (each of the region's bricks once).
    pub scan_bytes: u64,
    /// The frames' reads (bricks, bytes, evictions; `capacity`: the slots).
    pub frames: volsplat_splat::CacheStats,
    /// Bytes of the level's samples, had it been read whole.
    pub level_bytes: u64,
    /// A NRRD file's part: the bytes its ranges scan read from the file (the halo boxes of
    /// the region's bricks, as stored: once, or twice where the part held NaN or ±∞ and was
    /// scanned again with the level's finite range); `None` for a store (whose chunks are
    /// compressed).
    pub scan_file_bytes: Option<u64>,
    /// A NRRD file's part: the bytes its frames read from the file (the halo boxes of the
    /// bricks they read); `None` for a store.
    pub frame_file_bytes: Option<u64>,
}

/// What can go wrong while compositing across processes.
#[derive(Debug, Clone, thiserror::Error)]
#[non_exhaustive]
pub enum DistributedError {
    /// A rank could not render its bricks; every rank returns this, naming it.
    #[error("rank {rank} failed: {why}")]
    Rank {
        /// The rank that failed.
        rank: usize,
        /// Its error, as text.
        why: String,
    },
    /// A brick's partial image could not be rendered (returned by the `render` callback).
    #[error("brick {brick}: {why}")]
    Brick {
        /// The brick's linear index.
        brick: usize,
        /// Why.
        why: String,
    },
    /// The ranks disagree about the protocol (a bug, or a rank that exited).
    #[error("compositing protocol: {0}")]
    Protocol(&'static str),
    /// A setting of the sort-last render is out of range (the message names it).
    #[error("invalid setting: {0}")]
    Setting(String),
    /// The engine could not load or resolve the request.
    #[error("{0}")]
    Engine(String),
}

/// The result type of this module.
pub type Result<T> = std::result::Result<T, DistributedError>;

#[cfg(test)]
mod store_tests;
#[cfg(test)]
mod tests;
