//! The ranges of a store's level, kept between runs (issue 31 item 4, "computed once and kept in
//! a sidecar file"; decision 0039): the first out-of-core open of a level reads every brick once
//! (`scan_level`); the result is written to the user's cache folder, and later opens of the same
//! unchanged level read it back instead of the whole level.
//!
//! **Where.** `$VOLSPLAT_CACHE_DIR`, else `$XDG_CACHE_HOME/volsplat`, else `~/.cache/volsplat`,
//! in `ranges/`; never inside the store (which may be read-only or shared). One file per store
//! level, channel, time point and brick size, named by a hash of them and of the store's path.
//!
//! **When it is trusted.** The file holds a fingerprint of what the ranges were read from: the
//! store's canonical path, the level, selection, brick size, dims and sample type, and, over
//! every file of the level's array folder, their count, total size and latest modification
//! time (ns). Any change to the array (a chunk rewritten, added or removed) changes the
//! fingerprint, and the level is scanned again. A file that does not parse, or holds other
//! sizes than the level's bricks, is ignored, never trusted. Writes are atomic; a failed write
//! only costs the next open a scan.

use std::collections::hash_map::DefaultHasher;
use std::hash::{Hash, Hasher};
use std::path::{Path, PathBuf};
use volsplat_core::NonFiniteSamples;
use volsplat_core::source::BrickLayout;
use volsplat_splat::LevelScan;

/// What a level's ranges were read from ([`Sidecar::fingerprint`]).
#[derive(Debug, Clone, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub(super) struct Fingerprint {
    store: PathBuf,
    level: usize,
    channel: usize,
    timepoint: usize,
    brick: usize,
    dims: [usize; 3],
    scalar_type: String,
    files: u64,
    bytes: u64,
    newest_ns: u128,
}

/// The file header (JSON, one line), followed by the ranges as little-endian f32.
#[derive(serde::Serialize, serde::Deserialize)]
struct Header {
    magic: String,
    fingerprint: Fingerprint,
    finite: Option<[f32; 2]>,
    /// NaN, +∞, −∞ counts and the lowest/highest finite values they became.
    non_finite: Option<(usize, usize, usize, f32, f32)>,
    bricks: usize,
    ranges8: usize,
}

const MAGIC: &str = "volsplat level ranges 1";

impl Fingerprint {
    /// The fingerprint of level `level` (array folder `array_dir`) of the store at `store`.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn of(
        store: &Path,
        array_dir: &Path,
        (level, channel, timepoint): (usize, usize, usize),
        layout: &BrickLayout,
        scalar_type: &str,
    ) -> Option<Fingerprint> {
        let (mut files, mut bytes, mut newest_ns) = (0u64, 0u64, 0u128);
        let mut stack = vec![array_dir.to_path_buf()];
        while let Some(dir) = stack.pop() {
            for entry in std::fs::read_dir(&dir).ok()? {
                let entry = entry.ok()?;
                let meta = entry.metadata().ok()?;
                if meta.is_dir() {
                    stack.push(entry.path());
                } else {
                    files += 1;
                    bytes += meta.len();
                    let t = meta.modified().ok()?;
                    let ns = t.duration_since(std::time::UNIX_EPOCH).ok()?.as_nanos();
                    newest_ns = newest_ns.max(ns);
                }
            }
        }
        Some(Fingerprint {
            store: std::fs::canonicalize(store).ok()?,
            level,
            channel,
            timepoint,
            brick: layout.size(),
            dims: layout.grid().dims,
            scalar_type: scalar_type.to_string(),
            files,
            bytes,
            newest_ns,
        })
    }

    /// The sidecar file of this level in the cache folder, if there is one to use.
    fn path(&self) -> Option<PathBuf> {
        let dir = match std::env::var_os("VOLSPLAT_CACHE_DIR") {
            Some(d) => PathBuf::from(d),
            None => match std::env::var_os("XDG_CACHE_HOME") {
                Some(d) => PathBuf::from(d).join("volsplat"),
                None => PathBuf::from(std::env::var_os("HOME")?).join(".cache/volsplat"),
            },
        };
        let mut h = DefaultHasher::new();
        (
            &self.store,
            self.level,
            self.channel,
            self.timepoint,
            self.brick,
        )
            .hash(&mut h);
        Some(dir.join("ranges").join(format!("{:016x}.bin", h.finish())))
    }

    /// The scan kept for this fingerprint, if a file holds it (and it fits `layout`).
    pub(super) fn load(&self, layout: &BrickLayout) -> Option<LevelScan> {
        let bytes = std::fs::read(self.path()?).ok()?;
        let nl = bytes.iter().position(|&b| b == b'\n')?;
        let header: Header = serde_json::from_slice(&bytes[..nl]).ok()?;
        let per = (layout.size() / 8).pow(3);
        let n = layout.brick_count();
        if header.magic != MAGIC
            || header.fingerprint != *self
            || header.bricks != n
            || header.ranges8 != n * per
        {
            return None;
        }
        let floats: Vec<f32> = bytes[nl + 1..]
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect();
        if floats.len() != 2 * (n * per + n) {
            return None;
        }
        let pairs: Vec<[f32; 2]> = floats.chunks_exact(2).map(|p| [p[0], p[1]]).collect();
        let (ranges8, ranges) = pairs.split_at(n * per);
        Some(LevelScan {
            layout: layout.clone(),
            ranges8: ranges8.to_vec(),
            ranges: ranges.to_vec(),
            finite: header.finite,
            non_finite: header
                .non_finite
                .map(
                    |(nan, pos_inf, neg_inf, lowest, highest)| NonFiniteSamples {
                        nan,
                        pos_inf,
                        neg_inf,
                        lowest,
                        highest,
                    },
                ),
            bricks: n,
            bytes_read: 0,
            read: vec![true; n],
        })
    }

    /// Keeps `scan` for this fingerprint (atomically; a failure is returned for a note).
    pub(super) fn save(&self, scan: &LevelScan) -> Result<PathBuf, String> {
        let path = self.path().ok_or("no cache folder (HOME is not set)")?;
        if let Some(dir) = path.parent() {
            std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        }
        let header = Header {
            magic: MAGIC.into(),
            fingerprint: self.clone(),
            finite: scan.finite,
            non_finite: scan
                .non_finite
                .map(|n| (n.nan, n.pos_inf, n.neg_inf, n.lowest, n.highest)),
            bricks: scan.ranges.len(),
            ranges8: scan.ranges8.len(),
        };
        let mut out = serde_json::to_vec(&header).map_err(|e| e.to_string())?;
        out.push(b'\n');
        for r in scan.ranges8.iter().chain(&scan.ranges) {
            out.extend_from_slice(&r[0].to_le_bytes());
            out.extend_from_slice(&r[1].to_le_bytes());
        }
        volsplat_io::write_bytes_atomic(&path, &out).map_err(|e| e.to_string())?;
        Ok(path)
    }
}
