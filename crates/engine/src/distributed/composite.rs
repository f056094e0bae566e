//! Sort-last compositing of per-brick partial images over a fixed [`BrickTree`], among the
//! processes of a [`Communicator`] (issue 32): each rank composites the subtrees whose bricks
//! it owns, then the image's rows are split into one stripe per rank and every rank sends every
//! other the stripes of its subtrees' images (direct send: radix-k with one round of k = N,
//! IceT's and OSPRay's family of methods), each rank composites the rest of the tree on its
//! stripe, and rank 0 gathers the stripes.
//!
//! **Why the bits do not depend on the number of ranks.** Every node of the tree is computed by
//! the same per-pixel operation ([`Combine::apply`]) from the same two child values, front child
//! first, whichever rank computes it and whatever rows it holds: only where the pixels travel
//! changes with N. A child that holds nothing (every brick under it empty, or skipped) is left
//! out, which is exact: over an empty image, `F + (1 − F.a)·0 = F` and `0 + (1 − 0)·B = B`.

use super::comm::Communicator;
use super::tree::{BrickTree, Eye, Node};
use super::{DistributedError, Result};

/// A partial image's pixels, rows top to bottom, `x` fastest: premultiplied RGBA for composite
/// (the renderers' accumulation), or the projected value in channel 0 for MIP/MinIP (NaN where
/// no sample) and X-ray (the line integral).
pub type Pixels = Vec<[f32; 4]>;

/// How two partial images meet at a node of the tree, pixel by pixel, the front one first.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Combine {
    /// Composite: `F + (1 − F.a)·B` per channel (premultiplied, front to back, the renderers'
    /// own order of operations).
    Over,
    /// MIP: the larger value per channel; NaN (no sample) gives way to a number; ties keep the
    /// front's.
    Max,
    /// MinIP: the smaller value per channel, as [`Combine::Max`].
    Min,
    /// X-ray: `F + B` per channel.
    Sum,
}

impl Combine {
    /// The pixel `front` combined with `back` (see each variant).
    #[inline]
    pub fn apply(self, front: [f32; 4], back: [f32; 4]) -> [f32; 4] {
        match self {
            Combine::Over => {
                let t = 1.0 - front[3];
                std::array::from_fn(|c| front[c] + t * back[c])
            }
            Combine::Max => std::array::from_fn(|c| pick(front[c], back[c], back[c] > front[c])),
            Combine::Min => std::array::from_fn(|c| pick(front[c], back[c], back[c] < front[c])),
            Combine::Sum => std::array::from_fn(|c| front[c] + back[c]),
        }
    }

    /// The value of a pixel that no brick reached: 0 (composite, X-ray) or NaN (MIP, MinIP).
    pub fn empty(self) -> [f32; 4] {
        match self {
            Combine::Over | Combine::Sum => [0.0; 4],
            Combine::Max | Combine::Min => [f32::NAN; 4],
        }
    }
}

/// `b` where `a` is NaN or `b_wins` (and `b` is a number), else `a`.
#[inline]
fn pick(a: f32, b: f32, b_wins: bool) -> f32 {
    if a.is_nan() || (b_wins && !b.is_nan()) {
        b
    } else {
        a
    }
}

/// The value of `node` over rows `rows` (a stripe of `width`-pixel rows), from `given(node)`
/// where a node's value is known, else from its children (front first for `eye`); `None` where
/// nothing below the node holds an image.
fn eval<'a>(
    tree: &BrickTree,
    node: usize,
    eye: Eye,
    combine: Combine,
    given: &dyn Fn(usize) -> Option<&'a [[f32; 4]]>,
) -> Option<Pixels> {
    if let Some(p) = given(node) {
        return Some(p.to_vec());
    }
    let Node::Split { lo, hi, .. } = tree.nodes[node] else {
        return None;
    };
    let (front, back) = if tree.lo_in_front(node, eye) == Some(true) {
        (lo, hi)
    } else {
        (hi, lo)
    };
    match (
        eval(tree, front, eye, combine, given),
        eval(tree, back, eye, combine, given),
    ) {
        (Some(mut f), Some(b)) => {
            for (f, b) in f.iter_mut().zip(&b) {
                *f = combine.apply(*f, *b);
            }
            Some(f)
        }
        (f, b) => f.or(b),
    }
}

/// The value of the subtree `node` from its bricks' partial images (`render(brick)`: `None`
/// for a brick that holds nothing visible, skipped), front to back for `eye`.
fn eval_local(
    tree: &BrickTree,
    node: usize,
    eye: Eye,
    combine: Combine,
    render: &mut dyn FnMut(usize) -> Result<Option<Pixels>>,
) -> Result<Option<Pixels>> {
    let (lo, hi) = match tree.nodes[node] {
        Node::Leaf { index } => return render(index),
        Node::Split { lo, hi, .. } => (lo, hi),
    };
    let (front, back) = if tree.lo_in_front(node, eye) == Some(true) {
        (lo, hi)
    } else {
        (hi, lo)
    };
    let f = eval_local(tree, front, eye, combine, render)?;
    let b = eval_local(tree, back, eye, combine, render)?;
    Ok(match (f, b) {
        (Some(mut f), Some(b)) => {
            for (f, b) in f.iter_mut().zip(&b) {
                *f = combine.apply(*f, *b);
            }
            Some(f)
        }
        (f, b) => f.or(b),
    })
}

/// The rows of stripe `s` of `n` in an image `height` rows high: `[s·h/n, (s+1)·h/n)`.
pub fn stripe_rows(s: usize, n: usize, height: usize) -> (usize, usize) {
    (s * height / n, (s + 1) * height / n)
}

/// Composites the partial images of `tree`'s bricks among the ranks of `comm` and returns the
/// whole `width × height` image on rank 0 (`None` on the others). Rank `r` renders only the
/// bricks of its run of leaves ([`BrickTree::rank_leaves`]), through `render(brick)`, which
/// returns the brick's full-size partial image or `None` for a brick with nothing visible.
/// A rank whose `render` fails sends its error instead of images, so that every rank returns
/// an error naming it instead of waiting. The image is the same bits for any number of ranks.
pub fn composite_direct_send(
    comm: &dyn Communicator,
    tree: &BrickTree,
    eye: Eye,
    combine: Combine,
    (width, height): (usize, usize),
    render: &mut dyn FnMut(usize) -> Result<Option<Pixels>>,
) -> Result<Option<Pixels>> {
    let (rank, n) = (comm.rank(), comm.size());
    let pixels = width * height;
    // 1. The subtrees this rank owns, each composited alone.
    let roots = tree.local_roots(tree.rank_leaves(rank, n));
    let mut local: Vec<(usize, Pixels)> = Vec::new();
    let mut failure = None;
    for &root in &roots {
        match eval_local(tree, root, eye, combine, render) {
            Ok(Some(p)) if p.len() == pixels => local.push((root, p)),
            Ok(Some(p)) => {
                failure = Some(format!(
                    "brick image of {} pixels, expected {width} × {height}",
                    p.len()
                ));
                break;
            }
            Ok(None) => {}
            Err(e) => {
                failure = Some(e.to_string());
                break;
            }
        }
    }
    // 2. Every rank gets its stripe of every subtree's image (or this rank's failure).
    for s in 0..n {
        let (y0, y1) = stripe_rows(s, n, height);
        let msg = match &failure {
            Some(why) => Message::Failed(why.clone()).encode(),
            None => encode_images(
                &local
                    .iter()
                    .map(|(root, p)| (*root, &p[y0 * width..y1 * width]))
                    .collect::<Vec<_>>(),
            ),
        };
        comm.send(s, msg)?;
    }
    let mut given: Vec<Option<Pixels>> = vec![None; tree.nodes.len()];
    let mut first_failure = None;
    for from in 0..n {
        match Message::decode(&comm.recv(from)?)? {
            Message::Failed(why) => {
                first_failure.get_or_insert(DistributedError::Rank { rank: from, why });
            }
            Message::Ready(_) => {
                return Err(DistributedError::Protocol(
                    "a set-up message in the image exchange",
                ));
            }
            Message::Images(images) => {
                for (root, p) in images {
                    let slot = given.get_mut(root).ok_or(DistributedError::Protocol(
                        "a subtree that is not in the tree",
                    ))?;
                    *slot = Some(p);
                }
            }
        }
    }
    if let Some(e) = first_failure {
        return Err(e);
    }
    // 3. The rest of the tree on this rank's stripe; 4. the stripes to rank 0.
    let (y0, y1) = stripe_rows(rank, n, height);
    let stripe = eval(tree, 0, eye, combine, &|node| given[node].as_deref());
    let rows = y1 - y0;
    let stripe = stripe.unwrap_or_else(|| vec![combine.empty(); rows * width]);
    comm.send(0, Message::Images(vec![(0, stripe)]).encode())?;
    if rank != 0 {
        return Ok(None);
    }
    let mut image = Vec::with_capacity(pixels);
    for from in 0..n {
        let (a, b) = stripe_rows(from, n, height);
        match Message::decode(&comm.recv(from)?)? {
            Message::Images(mut v) if v.len() == 1 && v[0].1.len() == (b - a) * width => {
                image.append(&mut v[0].1);
            }
            _ => return Err(DistributedError::Protocol("a stripe of the wrong size")),
        }
    }
    Ok(Some(image))
}

/// This rank's side of the first round of a sort-last render (the set-up round of
/// [`super::render_sort_last`], or [`composite_direct_send`] called alone) when it cannot take
/// part at all (its set-up failed before it knew the tree: the scene or volume could not be
/// read, a setting is bad): it sends
/// `why` to every rank in place of its images, receives every rank's message of the same round
/// (so that no rank's send is left waiting), and returns the error every rank then returns,
/// [`DistributedError::Rank`] naming the lowest failing rank. The other ranks, in
/// [`composite_direct_send`], return the same error after the exchange, without the gather.
pub fn fail_direct_send(comm: &dyn Communicator, why: String) -> DistributedError {
    let msg = Message::Failed(why.clone()).encode();
    for s in 0..comm.size() {
        if let Err(e) = comm.send(s, msg.clone()) {
            return e;
        }
    }
    let mut first = None;
    for from in 0..comm.size() {
        match comm.recv(from).and_then(|m| Message::decode(&m)) {
            Ok(Message::Failed(why)) => {
                first.get_or_insert(DistributedError::Rank { rank: from, why });
            }
            Ok(Message::Images(_) | Message::Ready(_)) => {}
            Err(e) => return e,
        }
    }
    first.unwrap_or(DistributedError::Rank {
        rank: comm.rank(),
        why,
    })
}

/// [`Message::Images`] of borrowed pixels, encoded (as [`Message::encode`]) without copying
/// them first.
fn encode_images(v: &[(usize, &[[f32; 4]])]) -> Vec<u8> {
    let bytes = 8 + v.iter().map(|(_, p)| 8 + 16 * p.len()).sum::<usize>();
    let mut out = Vec::with_capacity(bytes);
    out.extend_from_slice(&1u32.to_le_bytes());
    out.extend_from_slice(&(v.len() as u32).to_le_bytes());
    for (node, p) in v {
        out.extend_from_slice(&(*node as u32).to_le_bytes());
        out.extend_from_slice(&(p.len() as u32).to_le_bytes());
        for px in p.iter() {
            let mut b = [0u8; 16];
            for (c, v) in px.iter().enumerate() {
                b[4 * c..4 * c + 4].copy_from_slice(&v.to_le_bytes());
            }
            out.extend_from_slice(&b);
        }
    }
    out
}

/// What one rank sends another: its subtrees' stripes, or why it has none; or, in the set-up
/// round before them ([`exchange_ready`]), what it read of its part.
enum Message {
    Failed(String),
    Images(Vec<(usize, Pixels)>),
    Ready(Ready),
}

/// A rank's set-up, shared with every rank before the images ([`exchange_ready`]): the value
/// range of its part of a volume read in bricks (`None` where it read none, or read the volume
/// whole), its finite range (`None` where it holds no finite sample), and whether its part
/// holds non-finite floats (replaced by the union of the parts' finite ranges, decision 0030).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Ready {
    pub(super) range: Option<[f32; 2]>,
    pub(super) finite: Option<[f32; 2]>,
    pub(super) non_finite: bool,
}

/// The set-up round, before [`composite_direct_send`]: every rank sends every rank its
/// [`Ready`], or why it could not set up, and receives theirs (the round that
/// [`fail_direct_send`] takes part in, so a rank that fails before knowing the request stops
/// every rank here). Returns every rank's [`Ready`] in rank order, or
/// [`DistributedError::Rank`] naming the lowest failing rank (on every rank alike).
pub(super) fn exchange_ready(
    comm: &dyn Communicator,
    mine: std::result::Result<Ready, String>,
) -> Result<Vec<Ready>> {
    let msg = match &mine {
        Ok(r) => Message::Ready(*r).encode(),
        Err(why) => Message::Failed(why.clone()).encode(),
    };
    for s in 0..comm.size() {
        comm.send(s, msg.clone())?;
    }
    let mut all = Vec::with_capacity(comm.size());
    let mut first = None;
    for from in 0..comm.size() {
        match Message::decode(&comm.recv(from)?)? {
            Message::Failed(why) => {
                first.get_or_insert(DistributedError::Rank { rank: from, why });
            }
            Message::Ready(r) => all.push(r),
            Message::Images(_) => {
                return Err(DistributedError::Protocol("images in the set-up round"));
            }
        }
    }
    match first {
        Some(e) => Err(e),
        None => Ok(all),
    }
}

impl Message {
    /// Little-endian: tag (u32: 0 failed, 1 images, 2 ready); failed: the UTF-8 reason; ready:
    /// flags (u32: 1 a range, 2 non-finite samples, 4 a finite range), the range and the
    /// finite range (2 × f32 each, zeros where absent); images: count
    /// (u32), then per image the node (u32), the pixel count (u32) and the f32 channels.
    /// The buffer is sized once (a grown buffer would copy whole images and fault in their
    /// pages again; `bench-composite` under `mpirun`).
    fn encode(&self) -> Vec<u8> {
        match self {
            Message::Failed(why) => {
                let mut out = Vec::with_capacity(4 + why.len());
                out.extend_from_slice(&0u32.to_le_bytes());
                out.extend_from_slice(why.as_bytes());
                out
            }
            Message::Images(v) => encode_images(
                &v.iter()
                    .map(|(node, p)| (*node, &p[..]))
                    .collect::<Vec<_>>(),
            ),
            Message::Ready(r) => {
                let mut out = Vec::with_capacity(24);
                let flags = u32::from(r.range.is_some())
                    | u32::from(r.non_finite) << 1
                    | u32::from(r.finite.is_some()) << 2;
                out.extend_from_slice(&2u32.to_le_bytes());
                out.extend_from_slice(&flags.to_le_bytes());
                for v in r
                    .range
                    .unwrap_or([0.0; 2])
                    .iter()
                    .chain(&r.finite.unwrap_or([0.0; 2]))
                {
                    out.extend_from_slice(&v.to_le_bytes());
                }
                out
            }
        }
    }

    fn decode(bytes: &[u8]) -> Result<Message> {
        let bad = DistributedError::Protocol("a message shorter than its header says");
        let mut at = 0usize;
        let u32_at = |at: &mut usize| -> Result<u32> {
            let b = bytes.get(*at..*at + 4).ok_or(bad.clone())?;
            *at += 4;
            Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        };
        match u32_at(&mut at)? {
            0 => Ok(Message::Failed(
                String::from_utf8_lossy(&bytes[at..]).into_owned(),
            )),
            1 => {
                let count = u32_at(&mut at)? as usize;
                let mut v = Vec::new();
                for _ in 0..count {
                    let node = u32_at(&mut at)? as usize;
                    let len = u32_at(&mut at)? as usize;
                    let raw = bytes.get(at..at + len * 16).ok_or(bad.clone())?;
                    at += len * 16;
                    let mut p: Pixels = Vec::with_capacity(len);
                    p.extend(raw.chunks_exact(16).map(|px| {
                        std::array::from_fn(|c| {
                            let b = &px[4 * c..4 * c + 4];
                            f32::from_le_bytes([b[0], b[1], b[2], b[3]])
                        })
                    }));
                    v.push((node, p));
                }
                Ok(Message::Images(v))
            }
            2 => {
                let flags = u32_at(&mut at)?;
                let mut v = [0.0f32; 4];
                for x in &mut v {
                    *x = f32::from_bits(u32_at(&mut at)?);
                }
                Ok(Message::Ready(Ready {
                    range: (flags & 1 == 1).then_some([v[0], v[1]]),
                    finite: (flags & 4 == 4).then_some([v[2], v[3]]),
                    non_finite: flags & 2 == 2,
                }))
            }
            _ => Err(DistributedError::Protocol("an unknown message tag")),
        }
    }
}
