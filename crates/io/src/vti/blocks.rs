//! VTK's binary array blocks (`vtkXMLDataParser`): a byte-count header of `header_type` words
//! and the samples, or with a compressor `[blocks, block size, last block size, compressed
//! sizes…]` and the compressed blocks.
//!
//! Every size a block header declares is checked before anything is allocated: against the
//! bytes the array's block really holds in the file (its *region*: the decoded inline text, or
//! the appended data from the array's offset to the next array's offset or the end of
//! `<AppendedData>`), and for compressed blocks against the most that many compressed bytes can
//! decode to (zlib 1032:1, LZ4 255:1). A header whose words are of the other width than
//! `header_type` says (a `UInt64` file written with 4-byte counts would otherwise decode
//! shifted by one sample) is an error that says so.

use crate::error::{IoError, Result};
use base64::Engine;
use std::io::Read;
use std::path::Path;

/// The most a deflate stream can expand: 258-byte matches in 2 bits each (RFC 1951 §3.2.5),
/// 1032 output bytes per input byte; the allowance covers stream headers.
const ZLIB_MAX_RATIO: u64 = 1032;
/// The most an LZ4 block can expand: each further byte of a match length adds 255 bytes
/// (LZ4 block format, "Match length"); 256 leaves room for the token and offset.
const LZ4_MAX_RATIO: u64 = 256;
/// Slack added to the ratio bounds (stream headers, a final short match).
const RATIO_SLACK: u64 = 1024;

/// How a binary array block is laid out (VTK's `vtkXMLDataElement` binary formats).
pub(super) struct Layout<'a> {
    pub(super) path: &'a Path,
    /// The array, for messages (`DataArray "density" data`).
    pub(super) what: String,
    pub(super) header64: bool,
    pub(super) big_endian: bool,
    pub(super) compressed: bool,
    /// Compressed blocks are raw LZ4 blocks (`vtkLZ4DataCompressor`) rather than zlib streams.
    pub(super) lz4: bool,
    /// Bytes of samples needed.
    pub(super) needed: usize,
}

/// A compression header `[blocks, block size, last size, sizes…]`, checked.
struct Compression {
    blocks: u64,
    block_size: u64,
    last: u64,
    /// Bytes of the header (3 + blocks words).
    header_bytes: usize,
}

impl Layout<'_> {
    fn word(&self) -> usize {
        if self.header64 { 8 } else { 4 }
    }

    fn header_type(&self) -> &'static str {
        if self.header64 { "UInt64" } else { "UInt32" }
    }

    /// The same layout with words of the other width (for the hint in error messages).
    fn other_width(&self) -> Layout<'_> {
        Layout {
            path: self.path,
            what: String::new(),
            header64: !self.header64,
            ..*self
        }
    }

    fn read_word(&self, b: &[u8]) -> u64 {
        if self.header64 {
            let a: [u8; 8] = b.get(..8).and_then(|s| s.try_into().ok()).unwrap_or([0; 8]);
            if self.big_endian {
                u64::from_be_bytes(a)
            } else {
                u64::from_le_bytes(a)
            }
        } else {
            let a: [u8; 4] = b.get(..4).and_then(|s| s.try_into().ok()).unwrap_or([0; 4]);
            (if self.big_endian {
                u32::from_be_bytes(a)
            } else {
                u32::from_le_bytes(a)
            }) as u64
        }
    }

    fn truncated(&self, part: &str, expected: u64, actual: u64) -> IoError {
        IoError::Truncated {
            path: self.path.to_path_buf(),
            what: format!("{} ({part})", self.what),
            expected,
            actual,
            unit: "bytes",
        }
    }

    /// `"; …"` when the block's first bytes make sense read with words of the other width:
    /// the writer used another `header_type` than the file declares.
    fn width_hint(&self, region: &[u8]) -> String {
        let other = self.other_width();
        let fits = if self.compressed {
            other.counts(region).is_ok()
        } else {
            region.len() >= other.word() + self.needed
                && other.read_word(region) == self.needed as u64
        };
        if fits {
            format!(
                "; read as {}-byte words ({}) the header fits this array: the block was \
                 written with header_type=\"{}\" although the file declares \"{}\", and \
                 would decode shifted",
                other.word(),
                other.header_type(),
                other.header_type(),
                self.header_type()
            )
        } else {
            String::new()
        }
    }

    /// An error about the block's header, naming the array and its `header_type`.
    fn header_error(&self, part: &str, value: String, reason: String, region: &[u8]) -> IoError {
        IoError::field(
            self.path,
            format!("{} {part} (header_type {})", self.what, self.header_type()),
            &value,
            format!("{reason}{}", self.width_hint(region)),
        )
    }

    /// The counts of a compression header (its first three words, at the start of `first`),
    /// if consistent with the samples needed; else `Err(None)` when `first` is too short, or
    /// `Err(Some(reason))`. Does not look at the compressed sizes.
    fn counts(&self, first: &[u8]) -> std::result::Result<Compression, Option<String>> {
        let w = self.word();
        if first.len() < 3 * w {
            return Err(None);
        }
        let blocks = self.read_word(first);
        let block_size = self.read_word(&first[w..]);
        let last = self.read_word(&first[2 * w..]);
        let needed = self.needed as u128;
        if blocks == 0 || block_size == 0 {
            if needed == 0 {
                return Ok(Compression {
                    blocks: 0,
                    block_size,
                    last,
                    header_bytes: 3 * w,
                });
            }
            return Err(Some("no blocks, or blocks of 0 bytes".into()));
        }
        if last > block_size {
            return Err(Some("the last block is larger than the block size".into()));
        }
        let last_size = if last == 0 { block_size } else { last } as u128;
        let full = (blocks as u128 - 1) * block_size as u128;
        if full + last_size < needed {
            return Err(Some(format!(
                "the blocks must hold the {needed} bytes of samples"
            )));
        }
        if full >= needed.max(1) {
            return Err(Some(format!(
                "more blocks than the {needed} bytes of samples fill"
            )));
        }
        // (blocks − 1)·block_size < needed, so blocks ≤ needed and the size fits in usize.
        Ok(Compression {
            blocks,
            block_size,
            last,
            header_bytes: (3 + blocks as usize) * w,
        })
    }

    /// [`Self::counts`] as an error naming the array and the header's values.
    fn compression_counts(&self, first: &[u8]) -> Result<Compression> {
        let w = self.word();
        self.counts(first).map_err(|reason| match reason {
            None => self.truncated("compression header", 3 * w as u64, first.len() as u64),
            Some(reason) => self.header_error(
                "compression header",
                format!(
                    "{} blocks of {} bytes, last {}",
                    self.read_word(first),
                    self.read_word(&first[w..]),
                    self.read_word(&first[2 * w..])
                ),
                reason,
                first,
            ),
        })
    }

    /// Checks the compression header at the start of `region`: its counts, and the header
    /// (with one compressed size per block) within the region.
    fn compression(&self, region: &[u8]) -> Result<Compression> {
        let c = self.compression_counts(region)?;
        if region.len() < c.header_bytes {
            return Err(self.truncated(
                "compression header",
                c.header_bytes as u64,
                region.len() as u64,
            ));
        }
        Ok(c)
    }

    /// An appended raw block (`region`: from the array's offset to the end of its data).
    pub(super) fn raw_block(&self, region: &[u8]) -> Result<Vec<u8>> {
        if !self.compressed {
            return self.uncompressed(region);
        }
        let c = self.compression(region)?;
        let w = self.word();
        let sizes: Vec<u64> = (0..c.blocks as usize)
            .map(|k| self.read_word(&region[(3 + k) * w..]))
            .collect();
        self.inflate_blocks(&region[c.header_bytes..], &sizes, &c)
    }

    /// An uncompressed block: a byte count, then at least `needed` bytes of samples.
    fn uncompressed(&self, region: &[u8]) -> Result<Vec<u8>> {
        let w = self.word();
        if region.len() < w {
            return Err(self.truncated("byte-count header", w as u64, region.len() as u64));
        }
        let n = self.read_word(region);
        if n < self.needed as u64 {
            return Err(self.header_error(
                "byte count",
                n.to_string(),
                format!("fewer than the {} bytes of samples needed", self.needed),
                region,
            ));
        }
        let held = region.len() - w;
        if n > held as u64 && self.width_hint(region).is_empty() && n == self.needed as u64 {
            return Err(self.truncated("samples", n, held as u64));
        }
        if n > held as u64 {
            return Err(self.header_error(
                "byte count",
                n.to_string(),
                format!("more than the {held} bytes the array's block holds in the file"),
                region,
            ));
        }
        // An 8-byte count under header_type UInt32: its high half (zero) would be read as the
        // first sample and everything would shift by 4 bytes. Seen when the block, without
        // trailing whitespace, is exactly 8 + count bytes long.
        if !self.header64
            && region.len() >= 8
            && region[4..8] == [0; 4]
            && region.trim_ascii_end().len() as u64 == 8 + n
        {
            return Err(self.header_error(
                "byte count",
                n.to_string(),
                "the block is 4 bytes longer than the count says and the 4 bytes after the \
                 count are zero: the count was written as an 8-byte word (header_type=\"UInt64\") \
                 although the file declares \"UInt32\", and would decode shifted"
                    .into(),
                region,
            ));
        }
        Ok(region[w..w + self.needed].to_vec())
    }

    /// A base64 block (inline `binary`, or appended `base64`), `text` without whitespace and
    /// limited to the array's region: the header and the data are encoded separately when
    /// compressed, and either way when not.
    pub(super) fn base64_block(&self, text: &[u8]) -> Result<Vec<u8>> {
        let engine = base64::engine::general_purpose::STANDARD;
        let chars = |bytes: usize| bytes.div_ceil(3) * 4;
        let dec = |t: &[u8], part: &str| -> Result<Vec<u8>> {
            engine.decode(t).map_err(|e| {
                IoError::field(
                    self.path,
                    format!("{} ({part})", self.what),
                    &String::from_utf8_lossy(&t[..t.len().min(60)]),
                    format!("invalid base64: {e}"),
                )
            })
        };
        // The end of one base64 stream: through its '=' padding, else the end of the text.
        let stream_end = |t: &[u8]| {
            t.iter().position(|&c| c == b'=').map_or(t.len(), |p| {
                p + t[p..].iter().take_while(|&&c| c == b'=').count()
            })
        };
        let w = self.word();
        if !self.compressed {
            let hc = chars(w);
            if text.len() < hc {
                return Err(self.truncated(
                    "base64 byte-count header",
                    hc as u64,
                    text.len() as u64,
                ));
            }
            // Header encoded on its own (padded with '=') or together with the data.
            let all = if text[hc - 1] == b'=' {
                let mut h = dec(&text[..hc], "byte-count header")?;
                let end = hc + stream_end(&text[hc..]);
                h.extend(dec(&text[hc..end], "samples")?);
                h
            } else {
                dec(&text[..stream_end(text)], "samples")?
            };
            return self.uncompressed(&all);
        }
        // Compressed: the first three words tell the header size.
        let first = dec(&text[..chars(3 * w).min(text.len())], "compression header")?;
        let c = self.compression_counts(&first)?;
        let hc = chars(c.header_bytes);
        if text.len() < hc {
            return Err(self.truncated("base64 compression header", hc as u64, text.len() as u64));
        }
        let header = dec(&text[..hc], "compression header")?;
        let c = self.compression(&header)?;
        let sizes: Vec<u64> = (0..c.blocks as usize)
            .map(|k| self.read_word(&header[(3 + k) * w..]))
            .collect();
        let rest = &text[hc..];
        let data = dec(&rest[..stream_end(rest)], "compressed samples")?;
        self.inflate_blocks(&data, &sizes, &c)
    }

    /// The uncompressed size block `k` of `c` declares.
    fn declared(c: &Compression, k: usize) -> u64 {
        if k as u64 + 1 == c.blocks && c.last != 0 {
            c.last
        } else {
            c.block_size
        }
    }

    /// Checks the declared compressed sizes against the data present and against what they
    /// can decode to, before anything is allocated; returns each block's `(start, compressed
    /// size, bytes wanted from it)` up to the samples needed.
    fn plan_blocks(
        &self,
        data: &[u8],
        sizes: &[u64],
        c: &Compression,
    ) -> Result<Vec<(usize, usize, usize)>> {
        let (codec, ratio) = if self.lz4 {
            ("LZ4", LZ4_MAX_RATIO)
        } else {
            ("zlib", ZLIB_MAX_RATIO)
        };
        let total: u128 = sizes.iter().map(|&s| s as u128).sum();
        if total > data.len() as u128 {
            return Err(self.truncated(
                &format!(
                    "compressed blocks; the header declares {total} bytes in {} blocks",
                    sizes.len()
                ),
                total.min(u64::MAX as u128) as u64,
                data.len() as u64,
            ));
        }
        let mut plan = Vec::new();
        let (mut at, mut got) = (0usize, 0usize);
        for (k, &cs) in sizes.iter().enumerate() {
            if got >= self.needed {
                break;
            }
            // `total` ≤ data.len(), so every size and offset fits in usize.
            let cs = cs as usize;
            let want = (Self::declared(c, k) as usize).min(self.needed - got);
            let most = (cs as u64)
                .saturating_mul(ratio)
                .saturating_add(RATIO_SLACK);
            if want as u64 > most {
                return Err(IoError::field(
                    self.path,
                    format!("{} compression header (block {k})", self.what),
                    &format!("block size {}, compressed size {cs}", Self::declared(c, k)),
                    format!(
                        "{codec} block {k} must decode to {want} bytes of samples, but {cs} \
                         compressed bytes decode to at most {most}"
                    ),
                ));
            }
            plan.push((at, cs, want));
            at += cs;
            got += want;
        }
        Ok(plan)
    }

    /// Inflates zlib (or LZ4) blocks of the given compressed sizes into exactly `needed` bytes.
    fn inflate_blocks(&self, data: &[u8], sizes: &[u64], c: &Compression) -> Result<Vec<u8>> {
        let plan = self.plan_blocks(data, sizes, c)?;
        // Grows block by block, each block's share reserved only once its compressed size has
        // been found able to produce it.
        let mut out: Vec<u8> = Vec::new();
        for (k, &(at, cs, want)) in plan.iter().enumerate() {
            let block = &data[at..at + cs];
            let before = out.len();
            out.reserve_exact(want);
            let codec = if self.lz4 { "LZ4" } else { "zlib" };
            if self.lz4 {
                // A raw LZ4 block (LZ4_compress_default): decoded into at most `want` bytes.
                out.resize(before + want, 0);
                let n =
                    lz4_flex::block::decompress_into(block, &mut out[before..]).map_err(|e| {
                        IoError::Decompress {
                            path: self.path.to_path_buf(),
                            what: format!("{} (LZ4 block {k})", self.what),
                            error: std::io::Error::new(std::io::ErrorKind::InvalidData, e),
                        }
                    })?;
                out.truncate(before + n);
            } else {
                let mut z = flate2::read::ZlibDecoder::new(block).take(want as u64);
                z.read_to_end(&mut out).map_err(|e| IoError::Decompress {
                    path: self.path.to_path_buf(),
                    what: format!("{} (zlib block {k})", self.what),
                    error: e,
                })?;
            }
            if out.len() - before < want {
                return Err(self.truncated(
                    &format!("{codec} block {k}, decompressed"),
                    want as u64,
                    (out.len() - before) as u64,
                ));
            }
        }
        if out.len() < self.needed {
            return Err(self.truncated(
                "decompressed samples",
                self.needed as u64,
                out.len() as u64,
            ));
        }
        Ok(out)
    }
}
