//! `convert_to_zarr` streams uncompressed raw files (issue 31 item 3): converting a 32 MiB
//! raw volume to an OME-Zarr pyramid never holds more than a few MiB at once. This test binary
//! counts live heap bytes (its own global allocator, so no other test is touched).

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

struct Tracking;

static LIVE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

fn grew(n: usize) {
    let now = LIVE.fetch_add(n, Ordering::Relaxed) + n;
    PEAK.fetch_max(now, Ordering::Relaxed);
}

unsafe impl GlobalAlloc for Tracking {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        grew(layout.size());
        unsafe { System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        grew(layout.size());
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if new_size >= layout.size() {
            grew(new_size - layout.size());
        } else {
            LIVE.fetch_sub(layout.size() - new_size, Ordering::Relaxed);
        }
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Tracking = Tracking;

const MIB: usize = 1 << 20;

#[test]
fn converting_a_raw_file_keeps_memory_bounded() {
    let dir = tempfile::tempdir().unwrap();
    // 256 × 256 × 256 uint16 = 32 MiB on disk, written slice by slice.
    let n = 256usize;
    let raw = dir.path().join("big.raw");
    {
        use std::io::Write;
        let mut f = std::io::BufWriter::new(std::fs::File::create(&raw).unwrap());
        let mut slice = vec![0u8; n * n * 2];
        for k in 0..n {
            for (i, c) in slice.chunks_exact_mut(2).enumerate() {
                let v = ((i % n) * 3 + (i / n) * 5 + k * 7) as u16;
                c.copy_from_slice(&v.to_le_bytes());
            }
            f.write_all(&slice).unwrap();
        }
    }
    let spec = volsplat_io::RawSpec::new([n, n, n], volsplat_core::ScalarType::U16);
    let out = dir.path().join("big.zarr");
    let options = volsplat_io::ZarrWriteOptions::default().with_chunk(32);
    let base = LIVE.load(Ordering::Relaxed);
    PEAK.store(base, Ordering::Relaxed);
    let c = volsplat_io::convert_to_zarr(
        &raw,
        Some(&spec),
        &volsplat_io::ReadOptions::default(),
        &out,
        &options,
    )
    .unwrap();
    let peak = PEAK.load(Ordering::Relaxed) - base;
    assert!(c.streamed);
    assert_eq!(c.written.levels.len(), 5, "256 → 129 → 66 → 34 → 18");
    // Level 0's chunk row (32 slices of 128 KiB = 4 MiB), the others' (smaller), a few
    // slices and zarrs' chunk buffers: well under the volume's 32 MiB.
    eprintln!("peak live heap during the conversion: {} KiB", peak / 1024);
    assert!(peak < 12 * MIB, "peak {} MiB", peak / MIB);
    // The store holds the file's samples.
    let store = volsplat_io::ZarrStore::open(&out, &volsplat_io::Limits::default()).unwrap();
    let r = store
        .read_region::<u16>(0, Default::default(), [250, 3, 200], [251, 4, 201])
        .unwrap();
    assert_eq!(r, vec![(250 * 3 + 3 * 5 + 200 * 7) as u16]);
}
