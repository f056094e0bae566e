//! `mpirun -np N volsplat-mpi render FILE [render flags] -o OUT [--brick B]`: sort-last rendering
//! of what `volsplat render FILE [render flags] -o OUT` draws (its flags read by its own parser,
//! `volsplat_cli::render_flags`, so every render flag and `--scene SCENE.json` work alike)
//! across the ranks of `MPI_COMM_WORLD` (issue 32, decision 0038). The volume is
//! cut into bricks of `B` cells (64 by default; the cut does not depend on N), rank `r` draws
//! its run of the bricks, the ranks composite the partial images over a tree fixed by the
//! bricks (`over` in composite, the sum in X-ray, the maximum in MIP, the minimum in MinIP), and
//! rank 0 writes the image as `volsplat
//! render` writes it. The image is the same bits for any N. From an OME-Zarr store or a NRRD
//! file with a raw payload (X-ray included) each rank reads only the bricks of its part, and
//! prints what it read (`rank R of N: read …`; from a NRRD file also the bytes read from the
//! file); other files are read whole by every rank.
//!
//! A rank that fails before the compositing (its scene file or volume unreadable) still takes
//! its part in the one exchange, sending its error (`fail_direct_send`), so every rank exits
//! with status 1 and an error naming the failing rank and its cause; none waits.
//!
//! Two benchmark modes (not tests; `docs/BENCHMARKS.md` §30):
//! - `bench --scene SCENE.json [--brick B] [--rounds R]`: a whole sort-last frame, `R` times
//!   after one warm-up (which loads the volume), each started by a barrier; rank 0 prints the
//!   median and the minimum in ms.
//! - `bench-composite --size S [--bricks X,Y,Z] [--rounds R]`: `composite_direct_send` alone on
//!   `S × S` images, one per brick of an `X × Y × Z` brick grid (2,2,1 by default: one brick
//!   per rank at N = 4), premultiplied RGBA with opacity in [0, 0.9], made before the timed
//!   region; rank 0 prints the median and the minimum in ms.

mod bench;
mod movie;
mod world;

use anyhow::{Context, Result, bail};
use std::path::PathBuf;
use volsplat::distributed::{Communicator, fail_direct_send, render_sort_last};
use world::World;

/// What to do, from the command line.
enum Command {
    /// `volsplat render`'s arguments (without `--brick`), read on every rank.
    Render { argv: Vec<String>, brick: usize },
    /// `volsplat movie`'s arguments (without `--brick`), read on every rank.
    Movie { argv: Vec<String>, brick: usize },
    Bench {
        scene: PathBuf,
        brick: usize,
        rounds: usize,
    },
    BenchComposite {
        size: usize,
        bricks: [usize; 3],
        rounds: usize,
    },
}

const USAGE: &str = "usage: volsplat-mpi render [FILE] [volsplat render's flags] -o OUT [--brick B]\n       \
                     volsplat-mpi movie [FILE] [volsplat movie's flags] -o OUT [--brick B]\n       \
                     volsplat-mpi bench --scene SCENE.json [--brick B] [--rounds R]\n       \
                     volsplat-mpi bench-composite --size S [--bricks X,Y,Z] [--rounds R]";

fn parse() -> Result<Command> {
    let mut it = std::env::args().skip(1);
    let command = it.next().unwrap_or_default();
    if command == "render" || command == "movie" {
        // `volsplat render`'s arguments, but `--brick B` (or `--brick=B`): read in `run`.
        let (mut argv, mut brick) = (Vec::new(), 64usize);
        while let Some(a) = it.next() {
            let value = match a.strip_prefix("--brick=") {
                Some(v) => Some(v.to_string()),
                None if a == "--brick" => Some(it.next().context("--brick needs a value")?),
                None => None,
            };
            match value {
                Some(v) => brick = v.parse().context("--brick: a number of cells")?,
                None => argv.push(a),
            }
        }
        return Ok(if command == "render" {
            Command::Render { argv, brick }
        } else {
            Command::Movie { argv, brick }
        });
    }
    let (mut scene, mut brick, mut rounds) = (None, 64usize, 5usize);
    let (mut size, mut bricks) = (None, [2, 2, 1]);
    while let Some(a) = it.next() {
        let mut value = || it.next().with_context(|| format!("{a} needs a value"));
        match a.as_str() {
            "--scene" => scene = Some(PathBuf::from(value()?)),
            "--brick" => brick = value()?.parse().context("--brick: a number of cells")?,
            "--rounds" => rounds = value()?.parse().context("--rounds: a count ≥ 1")?,
            "--size" => size = Some(value()?.parse().context("--size: pixels per side")?),
            "--bricks" => {
                let v = value()?;
                let n: Vec<usize> = v
                    .split(',')
                    .map(str::parse)
                    .collect::<std::result::Result<_, _>>()
                    .with_context(|| format!("--bricks {v}: X,Y,Z brick counts"))?;
                bricks = n
                    .try_into()
                    .map_err(|_| anyhow::anyhow!("--bricks {v}: three counts, X,Y,Z"))?;
            }
            other => bail!("unknown argument {other:?}\n{USAGE}"),
        }
    }
    let scene = || {
        scene
            .clone()
            .context("--scene SCENE.json is required (volsplat render … --save-scene)")
    };
    if rounds == 0 {
        bail!("--rounds 0: at least one round");
    }
    Ok(match command.as_str() {
        "bench" => Command::Bench {
            scene: scene()?,
            brick,
            rounds,
        },
        "bench-composite" => Command::BenchComposite {
            size: size.context("--size S is required")?,
            bricks,
            rounds,
        },
        _ => bail!("{USAGE}"),
    })
}

/// The scene file's request, with its warnings printed once (rank 0).
fn load(scene: &PathBuf, rank: i32) -> Result<volsplat::RenderRequest> {
    let (request, warnings) = volsplat::RenderRequest::load(scene)
        .with_context(|| format!("reading {}", scene.display()))?;
    if rank == 0 {
        for w in warnings {
            eprintln!("warning: {w}");
        }
    }
    Ok(request)
}

fn render(
    world: &World,
    request: &volsplat::RenderRequest,
    output: &std::path::Path,
    brick: usize,
) -> Result<()> {
    let mut renderer = volsplat::Renderer::new();
    let image = render_sort_last(world, &mut renderer, request, brick)
        .with_context(|| format!("rank {} of {}", world.rank(), world.size()))?;
    if let Some(line) = reads_line(world, &renderer) {
        // One write of the whole line (the ranks share mpirun's stderr; see `main`).
        let line = format!("{line}\n");
        let _ = std::io::Write::write_all(&mut std::io::stderr().lock(), line.as_bytes());
    }
    if let Some(image) = image {
        let options = request.output.write_options()?;
        volsplat::write_image(
            output,
            &image.image,
            image.values.as_ref(),
            request.mode,
            &options,
        )
        .with_context(|| format!("writing {}", output.display()))?;
        eprintln!(
            "wrote {} ({}×{}, {} ranks, bricks of {} cells)",
            output.display(),
            image.image.width(),
            image.image.height(),
            world.size(),
            brick
        );
    }
    Ok(())
}

/// What this rank read of its part of a store, one line (`None` where it read the volume
/// whole): `.ci/mpi.sh` and BENCHMARKS §31 read it.
pub fn reads_line(world: &World, renderer: &volsplat::Renderer) -> Option<String> {
    let r = renderer.rank_reads()?;
    let mib = |b: u64| b as f64 / (1u64 << 20) as f64;
    // A NRRD file's part: the bytes read from the file itself.
    let file = match (r.scan_file_bytes, r.frame_file_bytes) {
        (Some(scan), Some(frame)) => format!(
            ", scan_file_bytes={scan} ({:.2} MiB), frame_file_bytes={frame} ({:.2} MiB)",
            mib(scan),
            mib(frame)
        ),
        _ => String::new(),
    };
    Some(format!(
        "rank {} of {}: read {} of {} bricks of {}³ cells: scan_bytes={} ({:.2} MiB), \
         frame_bytes={} ({:.2} MiB, {} bricks), level_bytes={} ({:.2} MiB){file}",
        world.rank(),
        world.size(),
        r.region_bricks,
        r.level_bricks,
        r.brick,
        r.scan_bytes,
        mib(r.scan_bytes),
        r.frames.bytes_read,
        mib(r.frames.bytes_read),
        r.frames.reads,
        r.level_bytes,
        mib(r.level_bytes)
    ))
}

/// The bytes of the buffered sends' buffer for `images` whole `width × height` images of 16
/// bytes a pixel, and MPI's per-message overhead.
pub fn buffer_bytes(width: usize, height: usize, images: usize) -> usize {
    width * height * 16 * images + (1 << 20)
}

/// A rank that could not set up (`e`) takes its part in the first exchange with its error, so
/// that every rank stops naming it; this rank's error.
pub fn fail_set_up(universe: &mut mpi::environment::Universe, e: anyhow::Error) -> anyhow::Error {
    use mpi::traits::Communicator as _;
    let rank = universe.world().rank();
    universe.set_buffer_size(1 << 20);
    let world = World::new(universe);
    let shared = fail_direct_send(&world, format!("{e:#}"));
    anyhow::anyhow!("rank {rank} of {}: {shared}", world.size())
}

fn run(universe: &mut mpi::environment::Universe, command: Result<Command>) -> Result<()> {
    use mpi::traits::Communicator as _;
    if let Ok(Command::Movie { argv, brick }) = &command {
        return movie::run(universe, argv, *brick);
    }
    let rank = universe.world().rank();
    // Everything a rank does before the exchange; its failure is shared through it.
    let ready = command.and_then(|c| {
        let request = match &c {
            Command::Render { argv, .. } => {
                let flags = volsplat_cli::render_flags(argv)?;
                if rank == 0 && !flags.quiet {
                    for n in &flags.notes {
                        eprintln!("note: {n}");
                    }
                }
                Some((flags.request, Some(flags.output)))
            }
            Command::Bench { scene, .. } => Some((load(scene, rank)?, None)),
            Command::BenchComposite { .. } | Command::Movie { .. } => None,
        };
        Ok((c, request))
    });
    let (command, request) = match ready {
        Ok(r) => r,
        Err(e) => return Err(fail_set_up(universe, e)),
    };
    match (command, request) {
        (Command::Render { brick, .. }, Some((request, Some(output)))) => {
            // A rank sends its subtrees' images (the roots of its run of the tree: a few) once,
            // split in stripes, and its stripe once more: room for 8 whole images.
            universe.set_buffer_size(buffer_bytes(request.width, request.height, 8));
            render(&World::new(universe), &request, &output, brick)
        }
        (Command::Bench { brick, rounds, .. }, Some((request, _))) => {
            universe.set_buffer_size(buffer_bytes(request.width, request.height, 8));
            bench::frames(&World::new(universe), &request, brick, rounds)
        }
        (
            Command::BenchComposite {
                size,
                bricks,
                rounds,
            },
            _,
        ) => bench::composite(universe, size, bricks, rounds),
        _ => bail!("a scene command without its scene"),
    }
}

fn main() {
    let Some(mut universe) = mpi::initialize() else {
        eprintln!("error: MPI could not be initialised");
        std::process::exit(1);
    };
    let command = parse();
    if let Err(e) = run(&mut universe, command) {
        // One write of the whole line: the ranks share mpirun's stderr, where the pieces of
        // a formatted print (each its own write on unbuffered stderr) interleave with other
        // ranks' pieces.
        let line = format!("error: {e:#}\n");
        let _ = std::io::Write::write_all(&mut std::io::stderr().lock(), line.as_bytes());
        // Every rank reaches here with the same error (the protocol shares a rank's failure);
        // exiting non-zero lets mpirun report it.
        drop(universe);
        std::process::exit(1);
    }
}
