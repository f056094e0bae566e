//! `mpirun -np N volsplat-mpi render --scene SCENE.json -o OUT [--brick B]`: sort-last rendering
//! of a scene file (as `volsplat render … --save-scene SCENE.json` writes it, so every render flag
//! is available) across the ranks of `MPI_COMM_WORLD` (issue 32, decision 0038). The volume is
//! cut into bricks of `B` cells (64 by default; the cut does not depend on N), rank `r` draws
//! its run of the bricks, the ranks composite the partial images over a tree fixed by the
//! bricks, and rank 0 writes the image as `volsplat render` writes it. The image is the same bits
//! for any N. Every rank still loads the whole volume (reading only a rank's bricks needs the
//! brick seam's cache, not built yet).

use anyhow::{Context, Result, bail};
use mpi::traits::{Communicator as _, Destination, Source};
use std::path::PathBuf;
use volsplat::distributed::{Communicator, DistributedError, render_sort_last};

/// MPI point-to-point messages on `MPI_COMM_WORLD`: buffered sends (`MPI_Bsend`, into the
/// buffer `main` attaches), so every rank may send to every rank before it receives, as
/// [`Communicator`] requires; a message to itself is queued in memory.
struct World {
    world: mpi::topology::SimpleCommunicator,
    /// Messages sent and not yet known to be delivered, completed in order.
    pending: std::sync::Mutex<Vec<Vec<u8>>>,
}

impl Communicator for World {
    fn rank(&self) -> usize {
        self.world.rank() as usize
    }

    fn size(&self) -> usize {
        self.world.size() as usize
    }

    fn send(&self, to: usize, data: Vec<u8>) -> std::result::Result<(), DistributedError> {
        if to >= self.size() {
            return Err(DistributedError::Protocol(
                "a send to a rank that does not exist",
            ));
        }
        // A length first, then the bytes: the receiver sizes its buffer.
        let p = self.world.process_at_rank(to as i32);
        let len = data.len() as u64;
        if to == self.rank() {
            self.pending
                .lock()
                .map_err(|_| DistributedError::Protocol("a poisoned queue"))?
                .push(data);
            return Ok(());
        }
        // Buffered (MPI_Bsend): the send returns once the message is copied into the buffer
        // attached in `main`, whether or not the receiver has posted its receive.
        p.buffered_send(&len);
        p.buffered_send(&data[..]);
        Ok(())
    }

    fn recv(&self, from: usize) -> std::result::Result<Vec<u8>, DistributedError> {
        if from >= self.size() {
            return Err(DistributedError::Protocol(
                "a receive from a rank that does not exist",
            ));
        }
        if from == self.rank() {
            let mut q = self
                .pending
                .lock()
                .map_err(|_| DistributedError::Protocol("a poisoned queue"))?;
            if q.is_empty() {
                return Err(DistributedError::Protocol(
                    "a receive from itself before a send",
                ));
            }
            return Ok(q.remove(0));
        }
        let p = self.world.process_at_rank(from as i32);
        let (len, _) = p.receive::<u64>();
        let mut buf = vec![0u8; len as usize];
        p.receive_into(&mut buf[..]);
        Ok(buf)
    }
}

struct Args {
    scene: PathBuf,
    output: PathBuf,
    brick: usize,
}

fn parse() -> Result<Args> {
    let mut it = std::env::args().skip(1);
    if it.next().as_deref() != Some("render") {
        bail!("usage: volsplat-mpi render --scene SCENE.json -o OUT [--brick B]");
    }
    let (mut scene, mut output, mut brick) = (None, None, 64usize);
    while let Some(a) = it.next() {
        let mut value = || it.next().with_context(|| format!("{a} needs a value"));
        match a.as_str() {
            "--scene" => scene = Some(PathBuf::from(value()?)),
            "-o" | "--output" => output = Some(PathBuf::from(value()?)),
            "--brick" => brick = value()?.parse().context("--brick: a number of cells")?,
            other => bail!("unknown argument {other:?}"),
        }
    }
    Ok(Args {
        scene: scene.context("--scene SCENE.json is required (volsplat render … --save-scene)")?,
        output: output.context("-o OUT is required")?,
        brick,
    })
}

/// The scene file's request, with its warnings printed once (rank 0).
fn load(args: &Args, rank: i32) -> Result<volsplat::RenderRequest> {
    let (request, warnings) = volsplat::RenderRequest::load(&args.scene)
        .with_context(|| format!("reading {}", args.scene.display()))?;
    if rank == 0 {
        for w in warnings {
            eprintln!("warning: {w}");
        }
    }
    Ok(request)
}

fn run(world: &World, args: &Args, request: &volsplat::RenderRequest) -> Result<()> {
    let mut renderer = volsplat::Renderer::new();
    let image = render_sort_last(world, &mut renderer, request, args.brick)
        .with_context(|| format!("rank {} of {}", world.rank(), world.size()))?;
    if let Some(image) = image {
        let options = request.output.write_options()?;
        volsplat::write_image(&args.output, &image, None, request.mode, &options)
            .with_context(|| format!("writing {}", args.output.display()))?;
        eprintln!(
            "wrote {} ({}×{}, {} ranks, bricks of {} cells)",
            args.output.display(),
            image.width(),
            image.height(),
            world.size(),
            args.brick
        );
    }
    Ok(())
}

fn main() {
    let Some(mut universe) = mpi::initialize() else {
        eprintln!("error: MPI could not be initialised");
        std::process::exit(1);
    };
    let rank = universe.world().rank();
    let loaded = parse().and_then(|a| load(&a, rank).map(|r| (a, r)));
    let result = loaded.and_then(|(args, request)| {
        // The buffer of the buffered sends: a rank sends its subtrees' images (the roots of its
        // run of the tree: a few) once, split in stripes, and its stripe once more; 16 bytes a
        // pixel, room for 8 whole images and MPI's per-message overhead.
        let bytes = request.width * request.height * 16 * 8 + (1 << 20);
        universe.set_buffer_size(bytes);
        let world = World {
            world: universe.world(),
            pending: std::sync::Mutex::new(Vec::new()),
        };
        run(&world, &args, &request)
    });
    if let Err(e) = result {
        eprintln!("error: {e:#}");
        // Every rank reaches here with the same error (the protocol shares a rank's failure);
        // exiting non-zero lets mpirun report it.
        drop(universe);
        std::process::exit(1);
    }
}
