//! The latency benchmark's client: recorded input replayed against a running viewer over its
//! WebSocket, as a page would send it, with what a user would feel measured
//! (docs/BENCHMARKS.md, "Interactive viewer").
//!
//! Two recordings ([`Recording`]): a 10-second orbit drag at 60 events a second, and a
//! 5-second drag of a transfer-function opacity point at 60 a second. For each the report
//! ([`ReplayReport`]) gives:
//! - input-to-frame latency, p50 and p95: for every event, the time from sending it to having
//!   received and decoded the first frame that shows it (frames echo the latest event applied);
//! - frames per second while dragging;
//! - preview PSNR against the final frame of the same scene: at ten points of the drag the
//!   scene is asked for (`save_scene`), and after the replay each is shown again as a preview
//!   (pointer held) and as the final frame (released); the preview is upscaled bilinearly, as
//!   the page draws it, and compared over 8-bit RGB;
//! - the time from release to the final frame.

use crate::protocol::{ClientMessage, FrameHeader, ServerMessage, split_binary};
use serde::Serialize;
use std::net::{SocketAddr, TcpStream};
use std::time::{Duration, Instant};
use tungstenite::client::IntoClientRequest;
use tungstenite::{Message, WebSocket};
use volsplat::RenderRequest;
use volsplat::core::TransferFunction;
use volsplat::session::Event;

/// A message from the server as the client sees it.
#[derive(Debug, Clone)]
pub enum Incoming {
    /// A JSON text message.
    Text(ServerMessage),
    /// A binary frame or file.
    Frame(FrameHeader, Vec<u8>),
}

/// A WebSocket client of the viewer (the benchmark's and the tests').
pub struct Client {
    ws: WebSocket<TcpStream>,
    seq: u64,
    /// The last final frame received, its `seq` raised by `shown` messages.
    last_final: Option<(FrameHeader, Vec<u8>)>,
}

impl std::fmt::Debug for Client {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Client").field("seq", &self.seq).finish()
    }
}

impl Client {
    /// Connects to `ws://addr/ws?token=…`, sending `origin` as the `Origin` header if given.
    /// Errors carry the server's refusal (status and text).
    pub fn connect(addr: SocketAddr, token: &str, origin: Option<&str>) -> Result<Client, String> {
        Client::connect_sized(addr, token, origin, None)
    }

    /// [`Client::connect`] as the page connects when its image follows its view: with the
    /// view's size in pixels (`&view=WxH`).
    pub fn connect_sized(
        addr: SocketAddr,
        token: &str,
        origin: Option<&str>,
        view: Option<(usize, usize)>,
    ) -> Result<Client, String> {
        let mut url = format!("ws://{addr}/ws?token={token}");
        if let Some((w, h)) = view {
            url.push_str(&format!("&view={w}x{h}"));
        }
        let mut req = url.into_client_request().map_err(|e| e.to_string())?;
        if let Some(o) = origin {
            let value = o.parse().map_err(|_| format!("bad origin {o}"))?;
            req.headers_mut().insert("Origin", value);
        }
        let stream = TcpStream::connect(addr).map_err(|e| e.to_string())?;
        let _ = stream.set_nodelay(true);
        let (ws, _) = tungstenite::client(req, stream).map_err(|e| match e {
            tungstenite::HandshakeError::Failure(tungstenite::Error::Http(r)) => format!(
                "HTTP {}: {}",
                r.status().as_u16(),
                r.body()
                    .as_deref()
                    .map(String::from_utf8_lossy)
                    .unwrap_or_default()
                    .trim()
            ),
            other => other.to_string(),
        })?;
        Ok(Client {
            ws,
            seq: 0,
            last_final: None,
        })
    }

    /// Sends a text message as is (tests send malformed ones).
    pub fn send_text(&mut self, text: &str) -> Result<(), String> {
        self.ws.send(Message::text(text)).map_err(|e| e.to_string())
    }

    /// Sends a message.
    pub fn send(&mut self, msg: &ClientMessage) -> Result<(), String> {
        let text = serde_json::to_string(msg).map_err(|e| e.to_string())?;
        self.send_text(&text)
    }

    /// Sends an event with the next sequence number and returns it.
    pub fn event(&mut self, event: Event) -> Result<u64, String> {
        self.seq += 1;
        let seq = self.seq;
        self.send(&ClientMessage::Event { seq, event })?;
        Ok(seq)
    }

    /// Acknowledges frame `id`.
    pub fn ack(&mut self, id: u64) -> Result<(), String> {
        self.send(&ClientMessage::Ack { frame: id })
    }

    /// The next message, waiting at most `timeout`; `Ok(None)` on timeout, `Err` once the
    /// connection is closed or broken.
    pub fn recv(&mut self, timeout: Duration) -> Result<Option<Incoming>, String> {
        let t = timeout.max(Duration::from_micros(100));
        let _ = self.ws.get_ref().set_read_timeout(Some(t));
        match self.ws.read() {
            Ok(Message::Text(t)) => serde_json::from_str(t.as_str())
                .map(|m| Some(Incoming::Text(m)))
                .map_err(|e| format!("unreadable server message {t}: {e}")),
            Ok(Message::Binary(b)) => match split_binary(&b) {
                Some((h, payload)) => Ok(Some(Incoming::Frame(h, payload.to_vec()))),
                None => Err("unreadable binary message".into()),
            },
            Ok(Message::Close(_)) => Err("closed".into()),
            Ok(_) => Ok(None),
            Err(tungstenite::Error::Io(e))
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) =>
            {
                Ok(None)
            }
            Err(e) => Err(e.to_string()),
        }
    }

    /// Waits (at most `timeout`) for a message `pick` accepts, acknowledging frames as they
    /// come; other messages are dropped.
    pub fn wait_for<T>(
        &mut self,
        timeout: Duration,
        mut pick: impl FnMut(&Incoming) -> Option<T>,
    ) -> Result<T, String> {
        let end = Instant::now() + timeout;
        loop {
            let left = end.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Err(format!("nothing in {timeout:?}"));
            }
            if let Some(m) = self.recv(left)? {
                match &m {
                    Incoming::Frame(h, b) if h.kind == "frame" => {
                        self.ack(h.id)?;
                        if h.quality == "final" {
                            self.last_final = Some((h.clone(), b.clone()));
                        }
                    }
                    Incoming::Text(ServerMessage::Shown { frame, seq }) => {
                        if let Some((h, _)) = self.last_final.as_mut()
                            && h.id == *frame
                        {
                            h.seq = h.seq.max(*seq);
                        }
                    }
                    _ => {}
                }
                if let Some(t) = pick(&m) {
                    return Ok(t);
                }
            }
        }
    }

    /// Asks for the screenshot (the PNG file of the latest final frame) and waits for it.
    pub fn screenshot(&mut self, timeout: Duration) -> Result<Vec<u8>, String> {
        self.send(&ClientMessage::Screenshot {})?;
        self.wait_for(timeout, |m| match m {
            Incoming::Frame(h, b) if h.kind == "file" && h.format == "png" => Some(b.clone()),
            _ => None,
        })
    }

    /// Waits for the final frame showing event `seq` or later: a new one, or the last one
    /// received once a `shown` message says it shows `seq` (the events since changed nothing
    /// that is seen). Returns its header (`seq` raised) and PNG. `seq` 0: the next final frame.
    pub fn wait_final(
        &mut self,
        seq: u64,
        timeout: Duration,
    ) -> Result<(FrameHeader, Vec<u8>), String> {
        if let Some(last) = self
            .last_final
            .as_ref()
            .filter(|(h, _)| seq > 0 && h.seq >= seq)
        {
            return Ok(last.clone());
        }
        let mut last = self.last_final.clone();
        self.wait_for(timeout, |m| match m {
            Incoming::Frame(h, b) if h.quality == "final" => {
                last = Some((h.clone(), b.clone()));
                (h.seq >= seq).then(|| (h.clone(), b.clone()))
            }
            Incoming::Text(ServerMessage::Shown { frame, seq: shows }) => match last.as_mut() {
                Some((h, b)) if h.id == *frame => {
                    h.seq = h.seq.max(*shows);
                    (h.seq >= seq).then(|| (h.clone(), b.clone()))
                }
                _ => None,
            },
            _ => None,
        })
    }

    /// Asks for the scene and waits for it.
    pub fn scene(&mut self, timeout: Duration) -> Result<RenderRequest, String> {
        self.send(&ClientMessage::SaveScene {})?;
        self.wait_for(timeout, |m| match m {
            Incoming::Text(ServerMessage::Scene { request }) => Some((**request).clone()),
            _ => None,
        })
    }
}

/// Which recorded input to replay.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Recording {
    /// A 10-second orbit drag, 60 events a second.
    Orbit,
    /// A 5-second drag of an opacity point of the transfer function, 60 events a second.
    TransferFunction,
}

/// Events a second of the recordings (a display's refresh, as browsers deliver pointer moves).
pub const EVENTS_PER_SECOND: f64 = 60.0;

impl Recording {
    /// Length, seconds.
    pub fn seconds(self) -> f64 {
        match self {
            Recording::Orbit => 10.0,
            Recording::TransferFunction => 5.0,
        }
    }

    /// Event `n` of the recording (0-based), for a view `width` pixels wide; `tf` is the
    /// transfer function when the drag starts (the point dragged is the opacity point nearest
    /// the middle of its value span).
    pub fn event(self, n: usize, tf: &TransferFunction) -> Event {
        let t = n as f64 / EVENTS_PER_SECOND;
        match self {
            // About 70° a second on a 512-pixel view, with a slow nod up and down.
            Recording::Orbit => Event::Orbit {
                dx: 3.0,
                dy: 1.5 * (std::f64::consts::TAU * t / 5.0).sin(),
            },
            Recording::TransferFunction => {
                let mut tf = tf.clone();
                let pts = &mut tf.scalar_opacity;
                if pts.len() >= 2 {
                    let (lo, hi) = (pts[0][0], pts[pts.len() - 1][0]);
                    let k = (1..pts.len() - 1)
                        .min_by(|&a, &b| {
                            let mid = 0.5 * (lo + hi);
                            (pts[a][0] - mid).abs().total_cmp(&(pts[b][0] - mid).abs())
                        })
                        .unwrap_or(pts.len() - 1);
                    let left = if k > 0 { pts[k - 1][0] } else { lo };
                    let right = if k + 1 < pts.len() { pts[k + 1][0] } else { hi };
                    let phase = (std::f64::consts::TAU * t / 2.5).sin();
                    // Slide the point within its neighbours and raise or lower it.
                    let centre = 0.5 * (left + right);
                    let half = 0.35 * (right - left);
                    pts[k][0] = (centre + half * phase).clamp(left, right);
                    pts[k][1] = (pts[k][1] * (1.0 + 0.5 * phase)).clamp(0.0, 1.0);
                }
                Event::SetTransferFunction {
                    transfer_function: volsplat::TransferSpec::Function(tf),
                }
            }
        }
    }
}

/// Percentiles and counts of one replay.
#[derive(Debug, Clone, Serialize)]
pub struct ReplayReport {
    /// The recording.
    pub recording: Recording,
    /// Events sent.
    pub events: usize,
    /// Input-to-frame latency (received and decoded), median, ms.
    pub latency_p50_ms: f64,
    /// Input-to-frame latency, 95th percentile, ms.
    pub latency_p95_ms: f64,
    /// Frames received while dragging, per second.
    pub drag_fps: f64,
    /// Preview frames received while dragging.
    pub previews: usize,
    /// Final frames received while dragging (cheap scenes need no preview).
    pub finals_while_dragging: usize,
    /// Median preview height over the view's height.
    pub preview_scale_median: f64,
    /// Median render time of the previews, ms (server side).
    pub preview_render_ms_median: f64,
    /// Median encode time of the previews, ms (server side).
    pub preview_encode_ms_median: f64,
    /// Median preview size, bytes.
    pub preview_bytes_median: f64,
    /// Time from the release to the final frame, ms.
    pub release_to_final_ms: f64,
    /// Final frame size, bytes, and its server render and encode times, ms.
    pub final_bytes: usize,
    /// Server render time of the final frame after release, ms.
    pub final_render_ms: f64,
    /// Server PNG encode time of the final frame, ms.
    pub final_encode_ms: f64,
    /// Time from asking for the screenshot (render's exact PNG bytes, encoded on demand from
    /// the last final frame) to having it, ms.
    pub screenshot_ms: f64,
    /// The screenshot's size, bytes.
    pub screenshot_bytes: usize,
    /// Preview PSNR against the final frame of the same scene at ten points of the drag, dB.
    pub preview_psnr_db: Vec<f64>,
}

/// The p-th percentile (0..=100) of `v` by nearest rank; 0 for an empty slice.
pub fn percentile(v: &[f64], p: f64) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let rank = ((p / 100.0) * s.len() as f64).ceil() as usize;
    s[rank.clamp(1, s.len()) - 1]
}

/// Decodes a frame to 8-bit RGB: JPEG previews, PNG finals (RGB or grey, 8 or 16 bits).
pub fn decode_rgb(format: &str, bytes: &[u8]) -> Result<(usize, usize, Vec<u8>), String> {
    match format {
        "jpeg" => {
            let mut d = jpeg_decoder::Decoder::new(bytes);
            let px = d.decode().map_err(|e| e.to_string())?;
            let info = d.info().ok_or("no JPEG info")?;
            let (w, h) = (info.width as usize, info.height as usize);
            let rgb = match info.pixel_format {
                jpeg_decoder::PixelFormat::RGB24 => px,
                jpeg_decoder::PixelFormat::L8 => px.iter().flat_map(|&g| [g, g, g]).collect(),
                other => return Err(format!("JPEG pixel format {other:?}")),
            };
            Ok((w, h, rgb))
        }
        "png" => {
            let mut decoder = png::Decoder::new(std::io::Cursor::new(bytes));
            decoder.set_transformations(png::Transformations::STRIP_16);
            let mut r = decoder.read_info().map_err(|e| e.to_string())?;
            let mut buf = vec![0; r.output_buffer_size().ok_or("PNG too large")?];
            let info = r.next_frame(&mut buf).map_err(|e| e.to_string())?;
            buf.truncate(info.buffer_size());
            let (w, h) = (info.width as usize, info.height as usize);
            let rgb = match info.color_type {
                png::ColorType::Rgb => buf,
                png::ColorType::Grayscale => buf.iter().flat_map(|&g| [g, g, g]).collect(),
                png::ColorType::Rgba => buf
                    .chunks_exact(4)
                    .flat_map(|p| [p[0], p[1], p[2]])
                    .collect(),
                other => return Err(format!("PNG colour type {other:?}")),
            };
            Ok((w, h, rgb))
        }
        other => Err(format!("unknown frame format {other}")),
    }
}

/// Bilinear upscaling of 8-bit RGB to `w × h` (pixel centres aligned, edges clamped), as a
/// browser draws a small image into a large canvas.
pub fn upscale(src: &[u8], sw: usize, sh: usize, w: usize, h: usize) -> Vec<u8> {
    let mut out = vec![0u8; w * h * 3];
    for y in 0..h {
        let fy = ((y as f64 + 0.5) * sh as f64 / h as f64 - 0.5).clamp(0.0, (sh - 1) as f64);
        let (y0, ty) = (fy.floor() as usize, fy - fy.floor());
        let y1 = (y0 + 1).min(sh - 1);
        for x in 0..w {
            let fx = ((x as f64 + 0.5) * sw as f64 / w as f64 - 0.5).clamp(0.0, (sw - 1) as f64);
            let (x0, tx) = (fx.floor() as usize, fx - fx.floor());
            let x1 = (x0 + 1).min(sw - 1);
            for c in 0..3 {
                let p = |xx: usize, yy: usize| src[(yy * sw + xx) * 3 + c] as f64;
                let top = p(x0, y0) * (1.0 - tx) + p(x1, y0) * tx;
                let bottom = p(x0, y1) * (1.0 - tx) + p(x1, y1) * tx;
                out[(y * w + x) * 3 + c] = (top * (1.0 - ty) + bottom * ty).round() as u8;
            }
        }
    }
    out
}

/// PSNR of `a` against `b` (8-bit, peak 255), dB; infinite when equal.
pub fn psnr(a: &[u8], b: &[u8]) -> f64 {
    let n = a.len().min(b.len()).max(1);
    let mse = a
        .iter()
        .zip(b)
        .map(|(&x, &y)| {
            let d = x as f64 - y as f64;
            d * d
        })
        .sum::<f64>()
        / n as f64;
    if mse == 0.0 {
        f64::INFINITY
    } else {
        10.0 * (255.0f64 * 255.0 / mse).log10()
    }
}

/// One frame received during a replay.
#[derive(Debug, Clone)]
struct Received {
    at: Instant,
    header: FrameHeader,
    bytes: usize,
}

/// Replays `recording` on a connected client whose first final frame has arrived; `tf` is the
/// transfer function in use. Returns the report.
pub fn replay(
    client: &mut Client,
    recording: Recording,
    tf: &TransferFunction,
) -> Result<ReplayReport, String> {
    let events = (recording.seconds() * EVENTS_PER_SECOND).round() as usize;
    let start_seq = client.event(Event::Interaction { active: true })?;
    let _ = start_seq;
    let t0 = Instant::now();
    let mut sent: Vec<(u64, Instant)> = Vec::with_capacity(events);
    let mut frames: Vec<Received> = Vec::new();
    let mut displayed_at: Vec<(u64, Instant)> = Vec::new();
    let mut samples: Vec<RenderRequest> = Vec::new();
    let sample_every = events / 10;
    let mut scene_pending = 0usize;
    let mut n = 0;
    while n < events || scene_pending > 0 {
        let due = t0 + Duration::from_secs_f64(n as f64 / EVENTS_PER_SECOND);
        let now = Instant::now();
        if n < events && now >= due {
            let seq = client.event(recording.event(n, tf))?;
            sent.push((seq, Instant::now()));
            if sample_every > 0 && n % sample_every == sample_every / 2 {
                client.send(&ClientMessage::SaveScene {})?;
                scene_pending += 1;
            }
            n += 1;
            continue;
        }
        let wait = if n < events {
            due.saturating_duration_since(now)
        } else {
            Duration::from_millis(200)
        };
        match client.recv(wait)? {
            Some(Incoming::Frame(h, b)) if h.kind == "frame" => {
                client.ack(h.id)?;
                decode_rgb(&h.format, &b)?; // the page decodes before it shows
                let at = Instant::now();
                displayed_at.push((h.seq, at));
                frames.push(Received {
                    at,
                    header: h,
                    bytes: b.len(),
                });
            }
            Some(Incoming::Text(m)) => match m {
                ServerMessage::Scene { request } => {
                    samples.push(*request);
                    scene_pending = scene_pending.saturating_sub(1);
                }
                ServerMessage::Error { message, .. } => {
                    return Err(format!("the server refused an event: {message}"));
                }
                _ => {}
            },
            _ => {}
        }
    }
    let drag_end = Instant::now();
    let release = client.event(Event::Interaction { active: false })?;
    let released_at = Instant::now();
    let (final_header, final_png) = client.wait_final(release, Duration::from_secs(60))?;
    decode_rgb(&final_header.format, &final_png)?;
    displayed_at.push((final_header.seq, Instant::now()));
    let release_to_final_ms = released_at.elapsed().as_secs_f64() * 1e3;
    let asked = Instant::now();
    let screenshot = client.screenshot(Duration::from_secs(60))?;
    let screenshot_ms = asked.elapsed().as_secs_f64() * 1e3;
    let latencies: Vec<f64> = sent
        .iter()
        .filter_map(|(seq, t)| {
            displayed_at
                .iter()
                .find(|(s, at)| s >= seq && at >= t)
                .map(|(_, at)| (*at - *t).as_secs_f64() * 1e3)
        })
        .collect();
    let dragging: Vec<&Received> = frames.iter().filter(|f| f.at <= drag_end).collect();
    let previews: Vec<&&Received> = dragging
        .iter()
        .filter(|f| f.header.quality == "preview")
        .collect();
    let med = |v: Vec<f64>| percentile(&v, 50.0);
    let drag_s = (drag_end - t0).as_secs_f64();
    let psnr = preview_psnr(client, &samples)?;
    Ok(ReplayReport {
        recording,
        events: sent.len(),
        latency_p50_ms: percentile(&latencies, 50.0),
        latency_p95_ms: percentile(&latencies, 95.0),
        drag_fps: dragging.len() as f64 / drag_s,
        previews: previews.len(),
        finals_while_dragging: dragging.len() - previews.len(),
        preview_scale_median: med(previews.iter().map(|f| f.header.scale).collect()),
        preview_render_ms_median: med(previews.iter().map(|f| f.header.render_ms).collect()),
        preview_encode_ms_median: med(previews.iter().map(|f| f.header.encode_ms).collect()),
        preview_bytes_median: med(previews.iter().map(|f| f.bytes as f64).collect()),
        release_to_final_ms,
        final_bytes: final_png.len(),
        final_render_ms: final_header.render_ms,
        final_encode_ms: final_header.encode_ms,
        screenshot_ms,
        screenshot_bytes: screenshot.len(),
        preview_psnr_db: psnr,
    })
}

/// For each sampled scene: its preview (pointer held) and its final frame (released), and the
/// preview's PSNR against the final frame once upscaled.
fn preview_psnr(client: &mut Client, samples: &[RenderRequest]) -> Result<Vec<f64>, String> {
    let mut out = Vec::new();
    for req in samples {
        let camera = match &req.scene.camera {
            volsplat::CameraSpec::Explicit { camera, .. } => camera.clone(),
            volsplat::CameraSpec::Orbit(_) => {
                return Err("the scene's camera is not explicit".into());
            }
        };
        client.event(Event::Interaction { active: true })?;
        // A change first, so that a frame follows even where the sample is the scene already.
        client.event(Event::Zoom { factor: 1.001 })?;
        client.event(Event::SetTransferFunction {
            transfer_function: req.scene.transfer_function.clone(),
        })?;
        let seq = client.event(Event::SetCamera { camera })?;
        let preview = client.wait_for(Duration::from_secs(30), |m| match m {
            Incoming::Frame(h, b) if h.seq >= seq => Some((h.clone(), b.clone())),
            _ => None,
        })?;
        let release = client.event(Event::Interaction { active: false })?;
        let (fh, fb) = client.wait_final(release, Duration::from_secs(60))?;
        let (pw, ph, p) = decode_rgb(&preview.0.format, &preview.1)?;
        let (w, h, f) = decode_rgb(&fh.format, &fb)?;
        let up = upscale(&p, pw, ph, w, h);
        out.push(psnr(&up, &f));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_by_nearest_rank() {
        let v: Vec<f64> = (1..=100).map(f64::from).collect();
        assert_eq!(percentile(&v, 50.0), 50.0);
        assert_eq!(percentile(&v, 95.0), 95.0);
        assert_eq!(percentile(&v, 100.0), 100.0);
        assert_eq!(percentile(&[3.0], 95.0), 3.0);
        assert_eq!(percentile(&[], 50.0), 0.0);
    }

    #[test]
    fn upscaling_a_constant_or_a_ramp_is_exact() {
        let c = vec![77u8; 4 * 3 * 3];
        assert!(upscale(&c, 4, 3, 16, 12).iter().all(|&v| v == 77));
        // A horizontal ramp 0, 100 upscaled ×2: centres at 0.25 and 0.75 of each pixel.
        let ramp = [0u8, 0, 0, 100, 100, 100];
        let up = upscale(&ramp, 2, 1, 4, 1);
        let r: Vec<u8> = up.chunks(3).map(|p| p[0]).collect();
        assert_eq!(r, vec![0, 25, 75, 100]);
    }

    #[test]
    fn psnr_of_a_known_error() {
        let a = vec![100u8; 300];
        let mut b = a.clone();
        assert_eq!(psnr(&a, &b), f64::INFINITY);
        b.iter_mut().for_each(|v| *v += 5);
        let expect = 10.0 * (255.0f64 * 255.0 / 25.0).log10();
        assert!((psnr(&a, &b) - expect).abs() < 1e-12);
    }

    #[test]
    fn the_tf_recording_moves_a_middle_point_within_its_neighbours() {
        let tf = volsplat::core::Preset::CtBone.transfer_function((-1024.0, 3071.0));
        let mut moved = false;
        for n in 0..300 {
            let Event::SetTransferFunction {
                transfer_function: volsplat::TransferSpec::Function(mut t),
            } = Recording::TransferFunction.event(n, &tf)
            else {
                panic!("not a transfer function");
            };
            t.validate().unwrap();
            moved |= t != tf;
        }
        assert!(moved);
    }
}
