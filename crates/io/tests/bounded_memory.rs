//! Memory stays bounded on files whose headers declare more than they hold (issue 28 §2): this
//! test binary counts every allocation (its own global allocator, so no other test is touched)
//! and checks that reading small crafted files that declare gigabytes never asks for more than
//! a few megabytes at once. Before the fix, an LZ4 `.vti` block header declaring 2⁴⁰-byte
//! blocks for a 2³³-voxel float grid asked for 32 GiB up front.

use base64::Engine;
use std::alloc::{GlobalAlloc, Layout, System};
use std::path::Path;
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};

/// The system allocator, recording the largest single request.
struct Tracking;

static LARGEST: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Tracking {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        LARGEST.fetch_max(layout.size(), Ordering::Relaxed);
        unsafe { System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        LARGEST.fetch_max(layout.size(), Ordering::Relaxed);
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        LARGEST.fetch_max(new_size, Ordering::Relaxed);
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Tracking = Tracking;

/// Tests share the counter: one at a time.
static SERIAL: Mutex<()> = Mutex::new(());

/// Reads `path` and returns the error message and the largest allocation made meanwhile.
fn read_err(path: &Path) -> (String, usize) {
    LARGEST.store(0, Ordering::Relaxed);
    let e = volsplat_io::read_volume(path)
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default();
    (e, LARGEST.load(Ordering::Relaxed))
}

const MIB: usize = 1 << 20;

/// A `.vti` of a 2048³ (2³³ voxels) float grid whose one compressed block holds a few bytes.
fn huge_vti(compressor: &str, block_size: u64, payload: &[u8]) -> String {
    let b64 = base64::engine::general_purpose::STANDARD;
    let mut header = Vec::new();
    for w in [1, block_size, 0, payload.len() as u64] {
        header.extend(w.to_le_bytes());
    }
    format!(
        "<?xml version=\"1.0\"?>\n<VTKFile type=\"ImageData\" version=\"1.0\" \
         byte_order=\"LittleEndian\" header_type=\"UInt64\" compressor=\"{compressor}\">\n\
         <ImageData WholeExtent=\"0 2047 0 2047 0 2047\" Origin=\"0 0 0\" Spacing=\"1 1 1\">\n\
         <Piece Extent=\"0 2047 0 2047 0 2047\"><PointData Scalars=\"d\">\n\
         <DataArray type=\"Float32\" Name=\"d\" format=\"binary\">{}{}</DataArray>\n\
         </PointData></Piece></ImageData></VTKFile>\n",
        b64.encode(&header),
        b64.encode(payload)
    )
}

#[test]
fn vti_declared_block_sizes_do_not_allocate() {
    let _guard = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let lz4 = lz4_flex::block::compress(&[7u8; 64]);
    let zlib = {
        use std::io::Write;
        let mut e = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::fast());
        e.write_all(&[7u8; 64]).unwrap();
        e.finish().unwrap()
    };
    for (name, compressor, block_size, payload) in [
        ("lz4.vti", "vtkLZ4DataCompressor", 1u64 << 40, &lz4),
        ("lz4b.vti", "vtkLZ4DataCompressor", 1u64 << 35, &lz4),
        ("zlib.vti", "vtkZLibDataCompressor", 1u64 << 40, &zlib),
    ] {
        let p = dir.path().join(name);
        std::fs::write(&p, huge_vti(compressor, block_size, payload)).unwrap();
        let (e, largest) = read_err(&p);
        assert!(e.contains(name) && e.contains("block 0"), "{e}");
        assert!(
            largest < 4 * MIB,
            "{name}: an allocation of {largest} bytes ({e})"
        );
    }
}

#[test]
fn raw_payloads_shorter_than_declared_do_not_allocate() {
    let _guard = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    // NRRD and MetaImage declaring 2048³ float voxels with 16 bytes of data, raw and gzip.
    let gz = {
        use std::io::Write;
        let mut e = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
        e.write_all(&[0u8; 4096]).unwrap();
        e.finish().unwrap()
    };
    let cases: Vec<(&str, Vec<u8>)> = vec![
        (
            "a.nrrd",
            b"NRRD0004\ntype: float\ndimension: 3\nsizes: 2048 2048 2048\nendian: little\n\
              encoding: raw\n\n0123456789abcdef"
                .to_vec(),
        ),
        ("b.nrrd", {
            let mut v = b"NRRD0004\ntype: float\ndimension: 3\nsizes: 2048 2048 2048\n\
                          endian: little\nencoding: gzip\n\n"
                .to_vec();
            v.extend(&gz);
            v
        }),
        (
            "c.mha",
            b"NDims = 3\nDimSize = 2048 2048 2048\nElementType = MET_FLOAT\n\
              ElementDataFile = LOCAL\n0123456789abcdef"
                .to_vec(),
        ),
    ];
    for (name, bytes) in cases {
        let p = dir.path().join(name);
        std::fs::write(&p, bytes).unwrap();
        let (e, largest) = read_err(&p);
        assert!(e.contains(name) && e.contains("truncated"), "{e}");
        assert!(
            largest < 4 * MIB,
            "{name}: an allocation of {largest} bytes ({e})"
        );
    }
}
