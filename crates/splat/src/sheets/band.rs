//! A band of scanlines: its slice of the sheet buffer, its opacity tiles, and the deposit of
//! weighted splats into the sheet buffer or the accumulation buffer (Westover §3.8.1, §4.3.2).

use super::settings::{RenderMode, RenderSettings, Visibility};
use crate::geometry::Order;
use crate::mipcull::MipTiles;
use std::time::Instant;
use volsplat_core::image::{Rgba, over_back_to_front, over_front_to_back};

/// One classified sample on its way to reconstruction (Westover's tuple D, §3.4).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Splat {
    pub(crate) x: f32,
    pub(crate) y: f32,
    /// Premultiplied RGBA (composite); `[ρ·Δs, ..]` (X-ray); `[ρ, 1, 0, 0]` (MIP/MinIP).
    pub(crate) v: Rgba,
}

pub(crate) struct BandState {
    pub(crate) sheet: Vec<Rgba>,
    pub(crate) opaque_tiles: Vec<bool>,
    pub(crate) pixel_updates: u64,
    pub(crate) terminated: u64,
    pub(crate) splat_s: f64,
    pub(crate) composite_s: f64,
    /// MIP/MinIP culling state ([`crate::mipcull`]); empty until a MIP/MinIP sheet needs it.
    pub(crate) mip: MipTiles,
}

impl BandState {
    /// Empty state for a band of `rows` scanlines of an image `w` pixels wide.
    pub(crate) fn new(rows: usize, w: usize) -> Self {
        BandState {
            sheet: vec![[0.0; 4]; rows * w],
            opaque_tiles: vec![false; w.div_ceil(TILE) * rows.div_ceil(TILE)],
            pixel_updates: 0,
            terminated: 0,
            splat_s: 0.0,
            composite_s: 0.0,
            mip: MipTiles::default(),
        }
    }

    /// The band step of the sheet renderer and the splat list (Westover §3.8.1): `splat_all` deposits one
    /// sheet's splats of this band (image rows from `y_lo`, as many as `acc`, the band's rows of
    /// the accumulation buffer, holds) through the [`SpanCtx`] it is given into the target it is
    /// given (the band's sheet buffer for [`Sink::Sheet`], else `acc`), using the band's MIP
    /// culling state if it wishes, and returns whether it culled (so the state is refreshed
    /// after compositing). Then the sheet buffer's touched columns are composited onto `acc` and
    /// cleared ([`composite_band_sheet`]). Times and counts the work in the band's counters.
    pub(crate) fn splat_sheet(
        &mut self,
        settings: &RenderSettings,
        y_lo: usize,
        acc: &mut [Rgba],
        splat_all: impl FnOnce(Sink, &mut SpanCtx, &mut [Rgba], &mut MipTiles) -> bool,
    ) {
        let w = settings.width;
        let rows = acc.len() / w;
        let mode = settings.mode;
        let every = mode == RenderMode::Composite && settings.visibility == Visibility::EverySample;
        let ftb = settings.order == Order::FrontToBack;
        let cutoff = settings.opacity_cutoff;
        let terminate = mode == RenderMode::Composite && ftb && cutoff < 1.0;
        let sink = if every {
            if ftb { Sink::OverFtb } else { Sink::OverBtf }
        } else if mode == RenderMode::Xray {
            Sink::Line
        } else {
            Sink::Sheet
        };
        let t0 = Instant::now();
        let target: &mut [Rgba] = if matches!(sink, Sink::Sheet) {
            &mut self.sheet
        } else {
            acc
        };
        let mut span = SpanCtx {
            y_lo: y_lo as i32,
            rows: rows as i32,
            width: w as i32,
            // No opaque tile in the band yet: nothing can be terminated, so skip the per-splat
            // tile check (the outcome is the same).
            terminate: terminate && self.opaque_tiles.contains(&true),
            opaque: &self.opaque_tiles,
            tx0: w,
            tx1: 0,
            updates: 0,
            terminated: 0,
        };
        let culled = splat_all(sink, &mut span, target, &mut self.mip);
        let (tx0, tx1) = (span.tx0, span.tx1);
        self.pixel_updates += span.updates;
        self.terminated += span.terminated;
        let t1 = Instant::now();
        self.splat_s += (t1 - t0).as_secs_f64();
        if !matches!(sink, Sink::Sheet) || tx0 >= tx1 {
            return;
        }
        composite_band_sheet(
            mode,
            ftb,
            terminate.then_some(cutoff),
            w,
            self,
            acc,
            (tx0, tx1),
        );
        if culled {
            self.mip
                .refresh(acc, w, (tx0, tx1), mode == RenderMode::Mip);
        }
        self.composite_s += t1.elapsed().as_secs_f64();
    }
}

/// `v / band_h` for routing splats to bands: a shift when `band_h` is a power of two (the
/// default), where a 64-bit division per splat edge was a measurable share of the routing time.
#[inline(always)]
pub(crate) fn div_band(v: usize, band_h: usize) -> usize {
    if band_h.is_power_of_two() {
        v >> band_h.trailing_zeros()
    } else {
        v / band_h
    }
}

/// Side of the square pixel tiles whose opacity is tracked for early termination.
pub(crate) const TILE: usize = 4;

/// A splat's value weighted by the kept share `k` of its kernel ([`crate::clip`]): premultiplied
/// colour and opacity (composite), density (X-ray) or value (MIP) times `k`; MinIP unchanged
/// (its splats are kept or dropped at `k = ½`).
#[inline]
pub(crate) fn scale_kept(v: Rgba, k: f32, mode: RenderMode) -> Rgba {
    match mode {
        RenderMode::Composite => [v[0] * k, v[1] * k, v[2] * k, v[3] * k],
        RenderMode::Xray | RenderMode::Mip => [v[0] * k, v[1], v[2], v[3]],
        RenderMode::Minip => v,
    }
}

/// Composites the touched columns `tx0..tx1` of one band's sheet buffer into the band's slice
/// of the accumulation buffer (premultiplied *over*, opacity clamped with colour scaled alike,
/// docs/design.md §4.2; or the normalised MIP/MinIP update) and clears them. With `cutoff`, marks the
/// 4 × 4 tiles whose pixels all reached that opacity (front-to-back early termination).
pub(crate) fn composite_band_sheet(
    mode: RenderMode,
    ftb: bool,
    cutoff: Option<f32>,
    w: usize,
    st: &mut BandState,
    acc: &mut [Rgba],
    (tx0, tx1): (usize, usize),
) {
    let rows = acc.len() / w;
    // Composite the touched columns of the sheet buffer, then clear them.
    for r in 0..rows {
        let range = r * w + tx0..r * w + tx1;
        let (srow, arow) = (&mut st.sheet[range.clone()], &mut acc[range]);
        match mode {
            RenderMode::Composite => {
                for (s, a) in srow.iter_mut().zip(arow) {
                    if s[3] > 0.0 {
                        let mut src = *s;
                        // Clamp consistently: opacity ≤ 1 with colour scaled alike
                        // (docs/design.md §4.2).
                        if src[3] > 1.0 {
                            let k = 1.0 / src[3];
                            src = [src[0] * k, src[1] * k, src[2] * k, 1.0];
                        }
                        if ftb {
                            over_front_to_back(a, src)
                        } else {
                            over_back_to_front(a, src)
                        }
                    }
                    *s = [0.0; 4];
                }
            }
            RenderMode::Mip | RenderMode::Minip => {
                let max = mode == RenderMode::Mip;
                for (s, a) in srow.iter_mut().zip(arow) {
                    // Normalised reconstruction where the sheet covers the pixel.
                    if s[1] >= 0.5 {
                        let val = s[0] / s[1];
                        if a[0].is_nan() || (max && val > a[0]) || (!max && val < a[0]) {
                            a[0] = val;
                        }
                    }
                    *s = [0.0; 4];
                }
            }
            RenderMode::Xray => {}
        }
    }
    if let Some(cutoff) = cutoff {
        let n_tiles = w.div_ceil(TILE);
        for tr in 0..rows.div_ceil(TILE) {
            let (y0, y1) = (tr * TILE, ((tr + 1) * TILE).min(rows));
            for t in tx0 / TILE..=(tx1 - 1) / TILE {
                let flag = &mut st.opaque_tiles[tr * n_tiles + t];
                if *flag {
                    continue;
                }
                let (c0, c1) = (t * TILE, ((t + 1) * TILE).min(w));
                *flag =
                    (y0..y1).all(|r| acc[r * w + c0..r * w + c1].iter().all(|p| p[3] >= cutoff));
            }
        }
    }
}

/// Where weighted splat values go.
#[derive(Debug, Clone, Copy)]
pub(crate) enum Sink {
    /// Add into the sheet buffer (sheet-buffer visibility, MIP/MinIP).
    Sheet,
    /// Add channel 0 into the accumulation buffer (X-ray line integral).
    Line,
    /// Composite directly, front to back (composite-every-sample).
    OverFtb,
    /// Composite directly, back to front (composite-every-sample).
    OverBtf,
}

/// Per-band clipping and bookkeeping shared by the splat loops.
pub(crate) struct SpanCtx<'a> {
    pub(crate) y_lo: i32,
    pub(crate) rows: i32,
    pub(crate) width: i32,
    pub(crate) terminate: bool,
    pub(crate) opaque: &'a [bool],
    pub(crate) tx0: usize,
    pub(crate) tx1: usize,
    pub(crate) updates: u64,
    pub(crate) terminated: u64,
}

impl SpanCtx<'_> {
    /// Clips the column range `[x0, x1]` to the image; `None` if empty or (FTB) every tile
    /// under columns `x0..=x1` and band rows `r0..r1` (band-relative) is already opaque.
    #[inline(always)]
    pub(crate) fn columns(&mut self, x0: i32, x1: i32, r0: i32, r1: i32) -> Option<(i32, i32)> {
        let (x0, x1) = (x0.max(0), x1.min(self.width - 1));
        if x0 > x1 {
            return None;
        }
        if self.terminate {
            let n_tiles = (self.width as usize).div_ceil(TILE);
            let (t0, t1) = (x0 as usize / TILE, x1 as usize / TILE);
            let all = (r0 as usize / TILE..=(r1 - 1) as usize / TILE).all(|tr| {
                self.opaque[tr * n_tiles + t0..=tr * n_tiles + t1]
                    .iter()
                    .all(|&o| o)
            });
            if all {
                self.terminated += 1;
                return None;
            }
        }
        Some((x0, x1))
    }
}

pub(crate) const SINK_SHEET: u8 = 0;
pub(crate) const SINK_LINE: u8 = 1;
pub(crate) const SINK_OVER_FTB: u8 = 2;
pub(crate) const SINK_OVER_BTF: u8 = 3;

impl Sink {
    pub(crate) fn code(self) -> u8 {
        match self {
            Sink::Sheet => SINK_SHEET,
            Sink::Line => SINK_LINE,
            Sink::OverFtb => SINK_OVER_FTB,
            Sink::OverBtf => SINK_OVER_BTF,
        }
    }
}

/// Accumulates `weight × v` into one pixel; `S` is a [`Sink`] code, so each splat loop is
/// compiled once per sink with no per-pixel dispatch.
#[inline(always)]
pub(crate) fn deposit<const S: u8>(px: &mut Rgba, wt: f32, v: &Rgba) {
    let sink = match S {
        SINK_SHEET => Sink::Sheet,
        SINK_LINE => Sink::Line,
        SINK_OVER_FTB => Sink::OverFtb,
        _ => Sink::OverBtf,
    };
    match sink {
        Sink::Sheet => {
            px[0] += wt * v[0];
            px[1] += wt * v[1];
            px[2] += wt * v[2];
            px[3] += wt * v[3];
        }
        Sink::Line => px[0] += wt * v[0],
        Sink::OverFtb | Sink::OverBtf => {
            let mut src = [wt * v[0], wt * v[1], wt * v[2], wt * v[3]];
            if src[3] > 1.0 {
                let k = 1.0 / src[3];
                src = [src[0] * k, src[1] * k, src[2] * k, 1.0];
            }
            if matches!(sink, Sink::OverFtb) {
                over_front_to_back(px, src)
            } else {
                over_back_to_front(px, src)
            }
        }
    }
}
