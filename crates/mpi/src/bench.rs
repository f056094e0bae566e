//! The benchmark modes (not tests): a whole sort-last frame ([`frames`]) and the compositing
//! alone ([`composite`]), timed on rank 0 from a barrier to the image, medians over rounds.

use crate::world::World;
use anyhow::{Context, Result};
use mpi::collective::CommunicatorCollectives as _;
use std::time::Instant;
use volsplat::distributed::{
    BrickTree, Combine, Communicator, Eye, Pixels, composite_direct_send, render_sort_last,
};

/// Median and minimum of `t` (ms; not empty).
fn summary(mut t: Vec<f64>) -> (f64, f64) {
    t.sort_by(f64::total_cmp);
    let n = t.len();
    let median = if n % 2 == 1 {
        t[n / 2]
    } else {
        0.5 * (t[n / 2 - 1] + t[n / 2])
    };
    (median, t[0])
}

/// The threads each rank's renderer uses: `RAYON_NUM_THREADS`, else rayon's default (the
/// cores), as text.
fn threads() -> String {
    std::env::var("RAYON_NUM_THREADS").unwrap_or_else(|_| "default".into())
}

/// A whole sort-last frame of `request` in bricks of `brick` cells: one warm-up (the volume
/// loaded, the tables built), then `rounds` frames, each between barriers; rank 0 prints the
/// median and minimum frame time in ms.
pub fn frames(
    world: &World,
    request: &volsplat::RenderRequest,
    brick: usize,
    rounds: usize,
) -> Result<()> {
    let mut renderer = volsplat::Renderer::new();
    let mut times = Vec::with_capacity(rounds);
    for round in 0..=rounds {
        world.world.barrier();
        let t0 = Instant::now();
        render_sort_last(world, &mut renderer, request, brick)
            .with_context(|| format!("rank {} of {}", world.rank(), world.size()))?;
        let ms = t0.elapsed().as_secs_f64() * 1e3;
        world.world.barrier();
        if round > 0 {
            times.push(ms);
        } else {
            // The cold frame: the volume (or the rank's bricks) read, the tables built.
            if world.rank() == 0 {
                println!("bench first frame: np={} first_ms={ms:.1}", world.size());
            }
            if let Some(line) = crate::reads_line(world, &renderer) {
                println!("{line}");
            }
        }
    }
    if world.rank() == 0 {
        let (median, min) = summary(times);
        println!(
            "bench frame: np={} threads={} {}x{} {:?} brick={brick} rounds={rounds} \
             median_ms={median:.1} min_ms={min:.1}",
            world.size(),
            threads(),
            request.width,
            request.height,
            request.mode,
        );
    }
    Ok(())
}

/// A deterministic partial image: premultiplied RGBA with opacity in [0, 0.9] (xorshift from
/// `seed`).
fn image(pixels: usize, seed: u64) -> Pixels {
    let mut s = 0x9e37_79b9_7f4a_7c15u64 ^ (seed + 1).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    let mut next = || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 40) as f32 / (1u64 << 24) as f32
    };
    (0..pixels)
        .map(|_| {
            let a = 0.9 * next();
            [next() * a, next() * a, next() * a, a]
        })
        .collect()
}

/// `composite_direct_send` alone on `size × size` images, one per brick of a `bricks` grid,
/// `rounds` times after one warm-up; the images of a rank's bricks are made before the timed
/// region and handed to the protocol without a copy. Rank 0 prints the median and minimum in ms.
pub fn composite(
    universe: &mut mpi::environment::Universe,
    size: usize,
    bricks: [usize; 3],
    rounds: usize,
) -> Result<()> {
    use mpi::traits::Communicator as _;
    let tree = BrickTree::new(bricks, 8).context("--bricks: each count ≥ 1")?;
    let (rank, n) = (
        universe.world().rank() as usize,
        universe.world().size() as usize,
    );
    let run = tree.rank_leaves(rank, n);
    let roots = tree.local_roots(run).len();
    // Its subtrees' stripes to every rank, and its stripe to rank 0.
    universe.set_buffer_size(size * size * 16 * (roots + 1) + (1 << 20));
    let world = World::new(universe);
    let eye = Eye::Direction([0.3, -0.5, 0.8]);
    let pixels = size * size;
    let mut times = Vec::with_capacity(rounds);
    for round in 0..=rounds {
        let mut mine: Vec<(usize, Option<Pixels>)> = tree.leaves[run.0..run.1]
            .iter()
            .map(|&b| (b, Some(image(pixels, b as u64))))
            .collect();
        world.world.barrier();
        let t0 = Instant::now();
        composite_direct_send(&world, &tree, eye, Combine::Over, (size, size), &mut |b| {
            Ok(mine
                .iter_mut()
                .find(|(x, _)| *x == b)
                .and_then(|(_, p)| p.take()))
        })
        .with_context(|| format!("rank {rank} of {n}"))?;
        let ms = t0.elapsed().as_secs_f64() * 1e3;
        world.world.barrier();
        if round > 0 {
            times.push(ms);
        }
    }
    if rank == 0 {
        let (median, min) = summary(times);
        println!(
            "bench composite: np={n} {size}x{size} bricks={}x{}x{} roots_rank0={roots} \
             rounds={rounds} median_ms={median:.1} min_ms={min:.1} ns_per_pixel={:.2}",
            bricks[0],
            bricks[1],
            bricks[2],
            median * 1e6 / pixels as f64
        );
    }
    Ok(())
}
