//! `mpirun -np N volsplat-mpi movie FILE [movie flags] -o OUT [--brick B]`: the frames of what
//! `volsplat movie FILE [movie flags] -o OUT` draws (its flags read by its own parser,
//! `volsplat_cli::movie_flags`: turntables and keyframed flights alike), each frame a sort-last
//! render across the ranks ([`render_sort_last`]), written by rank 0 as `volsplat movie` writes
//! them. Each frame is the same bits for any N, as `render`'s image is.
//!
//! Failures: a rank that cannot set up (its flags, keyframes or volume; rank 0's output)
//! takes its part in the first frame's exchange with its error, so every rank stops naming
//! it. A frame that cannot be written on rank 0 stops every rank at the next frame's exchange
//! (after the last frame only rank 0 fails); the writer leaves nothing half-written.

use crate::world::World;
use crate::{buffer_bytes, fail_set_up, reads_line};
use anyhow::{Context, Result, bail};
use volsplat::distributed::{Communicator, fail_direct_send, render_sort_last};
use volsplat::io::MovieWriter;

/// Runs the movie of `argv` (`volsplat movie`'s arguments) across the ranks of `universe`,
/// bricks of `brick` cells.
pub fn run(universe: &mut mpi::environment::Universe, argv: &[String], brick: usize) -> Result<()> {
    use mpi::traits::Communicator as _;
    let rank = universe.world().rank();
    let mut renderer = volsplat::Renderer::new();
    // Set-up, alike on every rank (the frames planned from the store's metadata or the file's
    // header where ranks read parts); rank 0 also creates the output.
    let ready = volsplat_cli::movie_flags(argv, &mut renderer).and_then(|flags| {
        let writer = if rank == 0 {
            let (w, h) = flags.size;
            let writer = MovieWriter::create(&flags.output, w, h, flags.len(), &flags.settings)?;
            for warning in writer.warnings() {
                eprintln!("warning: {warning}");
            }
            if !flags.quiet {
                for n in &flags.notes {
                    eprintln!("note: {n}");
                }
            }
            Some(writer)
        } else {
            None
        };
        Ok((flags, writer))
    });
    let (flags, mut writer) = match ready {
        Ok(r) => r,
        Err(e) => return Err(fail_set_up(universe, e)),
    };
    let (w, h) = flags.size;
    universe.set_buffer_size(buffer_bytes(w, h, 8));
    let world = World::new(universe);
    let t0 = std::time::Instant::now();
    let count = flags.len();
    let mut failed: Option<anyhow::Error> = None;
    for n in 0..count {
        if let Some(e) = failed.take() {
            // Rank 0 could not write frame n − 1: every rank stops at this frame's exchange.
            let shared = fail_direct_send(&world, format!("{e:#}"));
            bail!("rank {rank} of {}: {shared}", world.size());
        }
        let request = flags.frame_request(n);
        let image = render_sort_last(&world, &mut renderer, &request, brick)
            .with_context(|| format!("frame {n}: rank {rank} of {}", world.size()))?;
        if let (Some(writer), Some(image)) = (writer.as_mut(), image) {
            let picture = match (&image.values, flags.window) {
                (Some(values), Some((lo, hi))) => volsplat::windowed_image(values, lo, hi),
                _ => image.image,
            };
            if let Err(e) = writer.push(&picture) {
                failed = Some(
                    anyhow::Error::new(e)
                        .context(format!("writing frame {n} of {}", flags.output.display())),
                );
            }
        }
    }
    if let Some(e) = failed {
        return Err(e);
    }
    if let Some(line) = reads_line(&world, &renderer) {
        let line = format!("{line}\n");
        let _ = std::io::Write::write_all(&mut std::io::stderr().lock(), line.as_bytes());
    }
    if let Some(writer) = writer {
        let files = writer.finish()?;
        eprintln!(
            "wrote {} ({count} frames, {w}×{h}, {} ranks, bricks of {brick} cells, {} files, \
             {:.1} s)",
            flags.output.display(),
            world.size(),
            files.written.len(),
            t0.elapsed().as_secs_f64()
        );
    }
    Ok(())
}
