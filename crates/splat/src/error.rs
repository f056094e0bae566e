//! The error type of `volsplat-splat`.

use thiserror::Error;
use volsplat_core::CoreError;

/// Everything that can go wrong while rendering.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum SplatError {
    /// Invalid camera, transfer function, kernel or volume.
    #[error(transparent)]
    Core(#[from] CoreError),
    /// A render setting is outside its range.
    #[error("invalid render setting {name} = {value}: {expected}")]
    Setting {
        /// The setting's field name (as in `RenderSettings` / the request file).
        name: &'static str,
        /// The value given, as text.
        value: String,
        /// What the setting accepts.
        expected: &'static str,
    },
    /// One voxel's footprint would cover more pixels than `FootprintSettings::max_block_side`
    /// allows (the zoom is too large, the camera's `parallel_scale` too small, or the grid
    /// spacing too uneven).
    #[error(
        "the footprint of one voxel would cover {width} × {height} pixels, more than the limit \
         of {limit} × {limit} (footprint max_block_side); the zoom is too large, the camera's \
         parallel_scale too small, or the grid spacing too uneven"
    )]
    FootprintTooLarge {
        /// Footprint block width in pixels (may be infinite or NaN).
        width: f64,
        /// Footprint block height in pixels (may be infinite or NaN).
        height: f64,
        /// The limit on either side, pixels.
        limit: usize,
    },
    /// The view maps the volume to non-finite raster coordinates.
    #[error(
        "the view maps the volume to non-finite raster coordinates (one voxel step = {step:?} \
         pixels); the zoom, the camera's parallel_scale or the grid spacing is too extreme"
    )]
    ExtremeView {
        /// Raster displacement of one lattice step along i, j, k (column-major 3×3).
        step: [f64; 9],
    },
    /// The view direction is perpendicular to every lattice axis (or not a number).
    #[error("degenerate view direction: no lattice axis has a non-zero component along it")]
    DegenerateView,
    /// The splat-list (perspective) renderer needs a radially symmetric kernel.
    #[error(
        "the splat-list (perspective) renderer needs a radial kernel (gaussian, crawfis-max), \
         got {kernel}"
    )]
    KernelNotRadial {
        /// The kernel's name.
        kernel: String,
    },
    /// A splat list would exceed its index range.
    #[error("splat list too large: {what}")]
    ListTooLarge {
        /// What overflowed, with the numbers.
        what: String,
    },
    /// A large per-volume buffer of the render (normal field, splat list, …) could not be
    /// allocated: the system, or an address-space limit (`ulimit -v`, a container's), refused
    /// it. Nothing was drawn; a smaller volume, subsampling or another renderer may fit.
    #[error(
        "not enough memory for {what} ({bytes} bytes): the system or its address-space limit \
         (ulimit -v, the container's memory limit) refused it"
    )]
    OutOfMemory {
        /// What the memory was for, e.g. `the normal field (shading at the voxels)`.
        what: &'static str,
        /// Bytes asked for.
        bytes: usize,
    },
    /// The brick cache's byte budget holds fewer slots than the bricks needed at once
    /// ([`crate::cache::BrickCache`]).
    #[error(
        "the brick cache's budget of {budget} bytes holds {capacity} slots of {slot_bytes} bytes \
         (one brick with its halo), but {needed} bricks are needed at once; raise the memory \
         budget or use smaller bricks"
    )]
    Budget {
        /// The budget, bytes.
        budget: u64,
        /// Bytes of one slot (`E³` samples).
        slot_bytes: u64,
        /// Slots the budget holds (after the arena's caps).
        capacity: usize,
        /// Bricks needed at once.
        needed: usize,
    },
    /// Two images that must match in size do not.
    #[error("image size mismatch: {what} is {got:?}, expected {expected:?} (width, height)")]
    SizeMismatch {
        /// Which image.
        what: &'static str,
        /// Its size, pixels.
        got: (usize, usize),
        /// The size it must have, pixels.
        expected: (usize, usize),
    },
    /// A successive-refinement ladder with no step.
    #[error("the refinement ladder is empty")]
    EmptyLadder,
    /// The progress callback asked to stop.
    #[error("render cancelled")]
    Cancelled,
    /// A render produced non-finite pixels: an internal error (a bug), reported instead of
    /// returning a picture that is silently wrong.
    #[error(
        "internal error: the {stage} produced {count} non-finite pixel values \
         (first at x = {x}, y = {y}); please report this with the command line"
    )]
    NonFinite {
        /// The renderer stage that produced them.
        stage: &'static str,
        /// How many values are NaN or infinite.
        count: usize,
        /// Column of the first one.
        x: usize,
        /// Row of the first one.
        y: usize,
    },
}

impl SplatError {
    /// [`SplatError::OutOfMemory`] for `n` elements of `T`.
    pub fn out_of_memory<T>(what: &'static str, n: usize) -> Self {
        SplatError::OutOfMemory {
            what,
            bytes: n.saturating_mul(std::mem::size_of::<T>()),
        }
    }
}

/// An empty vector with room for exactly `n` elements, allocated fallibly
/// ([`SplatError::OutOfMemory`] naming `what` when the memory cannot be had): the large
/// per-volume buffers of the render path, so that a volume too big for the memory left is an
/// error, never an abort.
pub fn try_with_capacity<T>(n: usize, what: &'static str) -> Result<Vec<T>> {
    let mut v = Vec::new();
    v.try_reserve_exact(n)
        .map_err(|_| SplatError::out_of_memory::<T>(what, n))?;
    Ok(v)
}

/// A vector of `n` copies of `value`, allocated fallibly (see [`try_with_capacity`]).
pub fn try_filled<T: Clone>(n: usize, value: T, what: &'static str) -> Result<Vec<T>> {
    let mut v = try_with_capacity(n, what)?;
    v.resize(n, value);
    Ok(v)
}

/// Result alias for rendering.
pub type Result<T> = std::result::Result<T, SplatError>;

/// `n` zero samples of a volume's type, allocated zeroed and fallibly (see
/// [`try_with_capacity`]): for large buffers that are written before they are read (the brick
/// cache's arena), the system maps zero pages on first touch, so slots never written cost
/// neither time nor resident memory (a 1.2 GB arena filled with zeros took 0.3–0.5 s before a
/// frame could start: BENCHMARKS §36). The five sample types are allocated as themselves
/// (their all-zero bytes are the value 0); any other `T` falls back to [`try_filled`].
pub fn try_zeroed<T: volsplat_core::Scalar>(n: usize, what: &'static str) -> Result<Vec<T>> {
    use std::any::{Any, TypeId};
    /// `n` zeroed values of `P`, or `None` where the allocation fails. Only for the primitive
    /// numbers below, whose all-zero bytes are a valid value (0 or +0.0).
    fn zeroed<P: Copy + 'static>(n: usize) -> Option<Vec<P>> {
        let layout = std::alloc::Layout::array::<P>(n).ok()?;
        if layout.size() == 0 {
            return Some(Vec::new());
        }
        // SAFETY: the layout has a non-zero size.
        let ptr = unsafe { std::alloc::alloc_zeroed(layout) }.cast::<P>();
        if ptr.is_null() {
            return None;
        }
        // SAFETY: `ptr` comes from the global allocator with `P`'s layout for `n` values
        // (capacity `n`), and all `n` are initialised: zero bytes, which is a valid `P` for the
        // primitive numbers this is called with.
        Some(unsafe { Vec::from_raw_parts(ptr, n, n) })
    }
    fn boxed<P: 'static>(v: Option<Vec<P>>) -> Option<Option<Box<dyn Any>>> {
        Some(v.map(|v| Box::new(v) as Box<dyn Any>))
    }
    let t = TypeId::of::<T>();
    let made = if t == TypeId::of::<u8>() {
        boxed(zeroed::<u8>(n))
    } else if t == TypeId::of::<i8>() {
        boxed(zeroed::<i8>(n))
    } else if t == TypeId::of::<u16>() {
        boxed(zeroed::<u16>(n))
    } else if t == TypeId::of::<i16>() {
        boxed(zeroed::<i16>(n))
    } else if t == TypeId::of::<f32>() {
        boxed(zeroed::<f32>(n))
    } else {
        None
    };
    match made {
        // `T` is the type allocated (same TypeId), so the downcast succeeds.
        Some(Some(v)) => v
            .downcast::<Vec<T>>()
            .map(|v| *v)
            .or_else(|_| try_filled(n, T::from_f64(0.0), what)),
        Some(None) => Err(SplatError::out_of_memory::<T>(what, n)),
        None => try_filled(n, T::from_f64(0.0), what),
    }
}

#[cfg(test)]
mod zeroed_tests {
    use super::*;

    #[test]
    fn zeroed_buffers_hold_zeros_of_every_sample_type_and_huge_ones_are_errors() {
        fn check<T: volsplat_core::Scalar>() {
            let v = try_zeroed::<T>(100_003, "test").unwrap();
            assert_eq!(v.len(), 100_003);
            assert!(
                v.iter()
                    .all(|x| x.to_f32() == 0.0 && x.to_f32().is_sign_positive())
            );
            assert!(try_zeroed::<T>(0, "test").unwrap().is_empty());
            let e = try_zeroed::<T>(usize::MAX / 4, "huge").unwrap_err();
            assert!(
                matches!(e, SplatError::OutOfMemory { what: "huge", .. }),
                "{e}"
            );
        }
        check::<u8>();
        check::<i8>();
        check::<u16>();
        check::<i16>();
        check::<f32>();
    }
}
