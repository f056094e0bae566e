//! Chunk decodes of the out-of-core read path (decision 0039, amendment 1): the ranges scan
//! (`scan_level_within`) and a pass of the brick cache over a level, reading a store of 64³
//! chunks in bricks of 64³ cells (each brick's halo box meets up to 27 chunks), decode each
//! chunk at most twice through the chunk faces cache, not once per brick that meets it.

use std::sync::Arc;
use volsplat::core::source::{BrickKey, BrickSource};
use volsplat::core::{AnyVolume, Grid, Volume};
use volsplat::io::{Limits, ZarrSelection, ZarrSource, ZarrStore, ZarrWriteOptions};
use volsplat_splat::BrickCache;

/// 256 × 192 × 256 u16 in chunks of 64³: 4 × 3 × 4 = 48 chunks, as many bricks of 64³ cells.
fn store(dir: &std::path::Path) -> Arc<ZarrStore> {
    let grid = Grid::new(
        [256, 192, 256],
        [1.0; 3],
        [0.0; 3],
        volsplat::core::glam::DMat3::IDENTITY,
    )
    .unwrap();
    let v = Volume::from_fn(grid, |i, j, k| ((i * 7 + j * 13 + k * 101) % 4001) as u16).unwrap();
    let path = dir.join("d.zarr");
    let mut options = ZarrWriteOptions::default();
    options.chunk = 64;
    volsplat::io::write_zarr(&path, &AnyVolume::U16(v), &options).unwrap();
    Arc::new(ZarrStore::open(&path, &Limits::default()).unwrap())
}

const CHUNKS: u64 = 48;

fn source(store: &Arc<ZarrStore>, cache: u64) -> ZarrSource<u16> {
    ZarrSource::<u16>::new(Arc::clone(store), ZarrSelection::default(), 64)
        .unwrap()
        .with_chunk_cache(cache)
}

#[test]
fn the_scan_and_a_cache_pass_decode_each_chunk_at_most_twice() {
    let dir = tempfile::tempdir().unwrap();
    let store = store(dir.path());
    // The scan, its batches bounded as the engine bounds them (a quarter of 64 MiB).
    let scan_decodes = |cache: u64| {
        let s = source(&store, cache);
        let scan = volsplat_splat::cache::scan_level_within(&s, 0, 16 << 20).unwrap();
        assert_eq!(scan.bricks, CHUNKS as usize);
        s.chunk_decodes()
    };
    let without = scan_decodes(0);
    assert!(without >= 8 * CHUNKS, "{without}");
    // Three planes of 4 × 3 chunks' faces (72 KiB each) and more: 8 MiB, 1/8 of 64 MiB.
    let with = scan_decodes(8 << 20);
    assert!(
        (CHUNKS..=2 * CHUNKS).contains(&with),
        "{with} (without: {without})"
    );

    // A pass of the brick cache (arena of 16 slots) over the level, a plane of 12 bricks at
    // a time, as frames make bands resident.
    let s = Arc::new(source(&store, 8 << 20));
    let mut cache = BrickCache::new(s.clone() as Arc<dyn BrickSource<u16>>, 0, 16 << 20).unwrap();
    let d = cache.layout().dims();
    for k in 0..d[2] {
        let keys: Vec<BrickKey> = (0..d[1])
            .flat_map(|j| (0..d[0]).map(move |i| [i, j, k]))
            .map(|b| cache.layout().key(b).unwrap())
            .collect();
        cache.make_resident(&keys).unwrap();
    }
    assert_eq!(cache.stats().reads, CHUNKS);
    let n = s.chunk_decodes();
    assert!((CHUNKS..=2 * CHUNKS).contains(&n), "{n}");
}
