//! Sort-last compositing (issue 32, `volsplat::distributed`): the cost of compositing the
//! partial images of 8 bricks (2 × 2 × 2) among N in-process ranks ([`FakeCluster`]: threads
//! and channels, so the messages are copies in memory, not a network), for 512² and 1024²
//! images, and the cost per pixel of the `over` operator itself.
//!
//! `cargo bench -p volsplat --features bench --bench composite`

use criterion::{Criterion, criterion_group, criterion_main};
use std::hint::black_box;
use volsplat::distributed::{BrickTree, Combine, Eye, FakeCluster, Pixels, composite_direct_send};

fn image(side: usize, b: usize) -> Pixels {
    (0..side * side)
        .map(|i| {
            let a = ((i * 7 + b * 13) % 97) as f32 / 120.0;
            [a * 0.5, a * 0.3, a * 0.2, a]
        })
        .collect()
}

fn bench(c: &mut Criterion) {
    let tree = BrickTree::new([2, 2, 2], 64).unwrap();
    let eye = Eye::Direction([0.3, -0.5, 0.8]);
    for side in [512usize, 1024] {
        let images: Vec<Pixels> = (0..8).map(|b| image(side, b)).collect();
        for n in [1usize, 2, 4] {
            c.bench_function(
                &format!("direct send, 8 bricks, {side}², {n} ranks"),
                |bch| {
                    bch.iter(|| {
                        let out = FakeCluster { size: n }.run(|comm| {
                            composite_direct_send(
                                comm,
                                &tree,
                                eye,
                                Combine::Over,
                                (side, side),
                                &mut |b| Ok(Some(images[b].clone())),
                            )
                        });
                        black_box(out)
                    })
                },
            );
        }
        c.bench_function(&format!("over, {side}² pixels"), |bch| {
            let (f, b) = (&images[0], &images[1]);
            bch.iter(|| {
                let out: Pixels = f
                    .iter()
                    .zip(b)
                    .map(|(f, b)| Combine::Over.apply(*f, *b))
                    .collect();
                black_box(out)
            })
        });
    }
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(10);
    targets = bench
}
criterion_main!(benches);
