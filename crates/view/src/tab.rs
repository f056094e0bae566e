//! One tab: a WebSocket, a [`Session`], a reader thread applying the page's messages and a
//! worker thread rendering and sending frames.
//!
//! Input never waits for a render: the reader applies events to the session at once (under a
//! lock held only for that), so a render picks up whatever is newest when it starts (events
//! are coalesced into the scene), and the session cancels a render the scene has left behind.
//! At most one frame is in flight: the worker renders the next frame while the page shows the
//! last, but sends it only once the page has acknowledged the last.

use crate::frames;
use crate::protocol::{
    ClientMessage, FrameHeader, Hello, ServerMessage, State, binary_message, parse_client_message,
};
use crate::server::Shared;
use crate::socket::{Outgoing, SocketStream};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::time::{Duration, Instant};
use tungstenite::{Message, WebSocket};
use volsplat::core::TransferFunction;
use volsplat::session::{Job, JobKind, JobOutcome, Session};
use volsplat::{EngineError, Progress, RenderRequest};

/// Bins of the histogram sent to the page.
pub(crate) const HISTOGRAM_BINS: usize = 256;

/// Work the reader hands to the worker besides frames.
#[derive(Debug)]
enum Command {
    Turntable {
        frames: usize,
        degrees: f64,
        fps: f64,
        max_size: usize,
    },
    Open(Box<RenderRequest>),
    Screenshot,
}

/// The latest final frame of a tab and the request it rendered, for the screenshot button.
struct LastFinal {
    out: volsplat::Output,
    request: RenderRequest,
}

#[derive(Default)]
struct TabState {
    session: Option<Session>,
    /// The page's latest event applied.
    seq: u64,
    /// The frame sent and not yet acknowledged.
    unacked: Option<u64>,
    closed: bool,
    commands: Vec<Command>,
    last_final: Option<Arc<LastFinal>>,
    /// The last frame sent: events that change nothing after it are shown by it.
    shown: Option<ShownFrame>,
}

/// A frame as sent: its id, the scene generation it shows, whether it is final, and the
/// latest event it shows.
#[derive(Debug, Clone, Copy)]
struct ShownFrame {
    id: u64,
    generation: u64,
    is_final: bool,
    seq: u64,
}

/// One tab's shared state.
pub(crate) struct Tab {
    shared: Arc<Shared>,
    out: Arc<Outgoing>,
    state: Mutex<TabState>,
    wake: Condvar,
    cancel_turntable: AtomicBool,
}

impl Tab {
    fn lock(&self) -> MutexGuard<'_, TabState> {
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn send(&self, msg: &ServerMessage) {
        // A serialisation of our own types cannot fail; a write error means the page is gone,
        // which the reader sees and ends the tab.
        if let Ok(text) = serde_json::to_string(msg) {
            let _ = self.out.text(&text);
        }
    }

    fn error(&self, seq: Option<u64>, message: String) {
        self.send(&ServerMessage::Error { seq, message });
    }
}

/// Runs a tab on an accepted WebSocket until the page closes it or the server stops.
pub(crate) fn run(
    shared: Arc<Shared>,
    mut ws: WebSocket<SocketStream>,
    out: Arc<Outgoing>,
    request: RenderRequest,
) {
    let tab = Arc::new(Tab {
        shared,
        out,
        state: Mutex::new(TabState::default()),
        wake: Condvar::new(),
        cancel_turntable: AtomicBool::new(false),
    });
    let worker = {
        let tab = Arc::clone(&tab);
        std::thread::Builder::new()
            .name("volsplat-view-worker".into())
            .spawn(move || worker(&tab, request))
    };
    read_loop(&tab, &mut ws);
    tab.lock().closed = true;
    tab.cancel_turntable.store(true, Ordering::Release);
    tab.wake.notify_all();
    if let Ok(w) = worker {
        let _ = w.join();
    }
    let _ = ws.close(None);
    let _ = ws.flush();
    tab.out.shutdown();
}

/// The reader: applies the page's messages until the socket closes.
fn read_loop(tab: &Tab, ws: &mut WebSocket<SocketStream>) {
    loop {
        if tab.shared.stopping() {
            return;
        }
        match ws.read() {
            Ok(Message::Text(text)) => on_message(tab, text.as_bytes()),
            Ok(Message::Binary(_)) => tab.error(
                None,
                "binary messages are not accepted; send JSON text".into(),
            ),
            Ok(Message::Close(_)) => return,
            Ok(_) => {} // ping, pong: tungstenite answers pings itself
            Err(tungstenite::Error::Capacity(e)) => {
                tab.error(
                    None,
                    format!("{e}; the connection is closed (limit {} bytes)", WS_MAX),
                );
                return;
            }
            Err(_) => return,
        }
    }
}

/// Largest WebSocket message tungstenite accepts before closing; messages between
/// [`crate::protocol::MAX_MESSAGE_BYTES`] and this get an error reply and the tab stays.
pub(crate) const WS_MAX: usize = 1 << 20;

fn on_message(tab: &Tab, bytes: &[u8]) {
    let msg = match parse_client_message(bytes) {
        Ok(m) => m,
        Err(r) => return tab.error(r.seq, r.message),
    };
    match msg {
        ClientMessage::Event { seq, event } => {
            let mut guard = tab.lock();
            let st = &mut *guard;
            let Some(session) = st.session.as_mut() else {
                drop(guard);
                return tab.error(Some(seq), "the volume is still loading".into());
            };
            use volsplat::session::Event as E;
            // The page is told the scene after changes it did not make itself step by step:
            // not for camera moves and not during a drag (it knows), but after a button, a
            // preset, and at the end of a drag.
            let camera_move = matches!(
                event,
                E::Orbit { .. } | E::Pan { .. } | E::Zoom { .. } | E::Roll { .. }
            );
            match session.apply(event) {
                Ok(()) => {
                    tab.shared.set_latest(session.request());
                    st.seq = st.seq.max(seq);
                    let quiet = camera_move || session.interacting();
                    let state = (!quiet).then(|| state_of(session, st.seq, None));
                    drop(guard);
                    tab.wake.notify_all();
                    if let Some(s) = state {
                        tab.send(&ServerMessage::State(Box::new(s)));
                    }
                }
                Err(e) => {
                    // A refused event changes nothing: the frame on screen shows it too.
                    st.seq = st.seq.max(seq);
                    drop(guard);
                    tab.wake.notify_all();
                    tab.error(Some(seq), e.to_string());
                }
            }
        }
        ClientMessage::Ack { frame } => {
            let mut st = tab.lock();
            if st.unacked == Some(frame) {
                st.unacked = None;
                drop(st);
                tab.wake.notify_all();
            }
        }
        ClientMessage::SaveScene {} => {
            // As a scene file holds it: the volume's path absolute, so that `render --scene`
            // reads it from any folder.
            let request = tab
                .lock()
                .session
                .as_ref()
                .map(|s| s.request().with_absolute_paths());
            match request {
                Some(request) => tab.send(&ServerMessage::Scene {
                    request: Box::new(request),
                }),
                None => tab.error(None, "the volume is still loading".into()),
            }
        }
        ClientMessage::Turntable {
            frames,
            degrees,
            fps,
            max_size,
        } => {
            tab.cancel_turntable.store(false, Ordering::Release);
            tab.lock().commands.push(Command::Turntable {
                frames,
                degrees,
                fps,
                max_size,
            });
            tab.wake.notify_all();
        }
        ClientMessage::Cancel {} => tab.cancel_turntable.store(true, Ordering::Release),
        ClientMessage::Screenshot {} => {
            tab.lock().commands.push(Command::Screenshot);
            tab.wake.notify_all();
        }
        ClientMessage::Open { name } => match tab.shared.open_request(&name, fitted_size(tab)) {
            Ok(request) => {
                tab.lock().commands.push(Command::Open(Box::new(request)));
                tab.wake.notify_all();
            }
            Err(message) => tab.error(None, message),
        },
    }
}

/// The size of the tab's view when it follows the page ([`crate::ViewerSettings::fit_view`]):
/// a volume opened from the data folder keeps it.
fn fitted_size(tab: &Tab) -> Option<(usize, usize)> {
    if !tab.shared.settings.fit_view {
        return None;
    }
    let st = tab.lock();
    st.session
        .as_ref()
        .map(|s| (s.request().width, s.request().height))
}

/// The state message of a session.
fn state_of(session: &Session, seq: u64, tf: Option<TransferFunction>) -> State {
    State {
        request: session.request().clone(),
        window: session.request().output.window,
        transfer_function: tf,
        seq,
    }
}

/// The worker: starts the session, then renders and sends frames until the tab closes.
fn worker(tab: &Tab, request: RenderRequest) {
    if !start_session(tab, request) {
        return;
    }
    let mut frame_id = 0u64;
    let mut last_tf: Option<TransferFunction> = None;
    loop {
        let next = {
            let mut st = tab.lock();
            loop {
                if st.closed || tab.shared.stopping() {
                    return;
                }
                if let Some(c) = pop_command(&mut st) {
                    break Next::Command(c);
                }
                let state = &mut *st;
                let seq = state.seq;
                let Some(session) = state.session.as_mut() else {
                    return;
                };
                if let Some(job) = session.next_job() {
                    let go = session.keep_going(&job);
                    let view = [session.request().width, session.request().height];
                    break Next::Job(Box::new(job), Sent { seq, view }, Box::new(go));
                }
                let generation = session.generation();
                let timeout = session
                    .wake_at()
                    .map(|t| t.saturating_sub(tab.shared.clock.now()))
                    .unwrap_or(Duration::from_secs(1));
                if let Some(sh) = state.shown.as_mut()
                    && sh.is_final
                    && sh.generation == generation
                    && sh.seq < seq
                {
                    // Events since the final frame changed nothing: it shows them.
                    sh.seq = seq;
                    break Next::Shown(sh.id, seq);
                }
                st = tab
                    .wake
                    .wait_timeout(st, timeout.max(Duration::from_millis(1)))
                    .map(|(g, _)| g)
                    .unwrap_or_else(|e| e.into_inner().0);
            }
        };
        match next {
            Next::Command(Command::Open(request)) => {
                if !start_session(tab, *request) {
                    return;
                }
                last_tf = None;
            }
            Next::Command(Command::Screenshot) => screenshot(tab),
            Next::Command(Command::Turntable {
                frames,
                degrees,
                fps,
                max_size,
            }) => turntable(tab, frames, degrees, fps, max_size),
            Next::Shown(frame, seq) => tab.send(&ServerMessage::Shown { frame, seq }),
            Next::Job(job, sent, go) => {
                frame_id += 1;
                render_and_send(tab, &job, sent, frame_id, go, &mut last_tf);
            }
        }
    }
}

type KeepGoing = Box<dyn FnMut(&Progress) -> bool + Send>;

enum Next {
    Command(Command),
    Job(Box<Job>, Sent, KeepGoing),
    /// The final frame with this id shows the events up to this seq.
    Shown(u64, u64),
}

/// What a frame tells the page beside its image: the latest event it shows and the size of
/// the full-quality frame it stands for, both as they were when the job was made.
#[derive(Debug, Clone, Copy)]
struct Sent {
    seq: u64,
    view: [usize; 2],
}

fn pop_command(st: &mut TabState) -> Option<Command> {
    (!st.commands.is_empty()).then(|| st.commands.remove(0))
}

/// Loads the volume and starts a session on `request`, then greets the page. `false` if the
/// tab should end (the volume cannot be loaded is reported and the tab stays).
fn start_session(tab: &Tab, request: RenderRequest) -> bool {
    tab.send(&ServerMessage::Progress {
        stage: "load".into(),
        fraction: 0.0,
    });
    let started = {
        let mut renderer = tab.shared.renderer();
        Session::start(
            request,
            &mut renderer,
            tab.shared.settings.session,
            Arc::clone(&tab.shared.clock),
        )
        .and_then(|s| {
            // The volume itself, or a store read out of core's coarsest level: the histogram.
            let vol = renderer.overview(s.request())?;
            Ok((s, vol))
        })
    };
    let (session, vol) = match started {
        Ok(s) => s,
        Err(e) => {
            tab.error(None, format!("cannot open the volume: {e}"));
            // Keep the old session, if any; a first session that fails ends nothing either:
            // the page shows the error.
            return tab.lock().session.is_some();
        }
    };
    let label = session.request().scene.volume.label();
    let (histogram, range) = tab.shared.histogram(&label, &vol, HISTOGRAM_BINS);
    // The full level's geometry (`vol` may be a store's coarsest level).
    let g = session.grid();
    let hello = Hello {
        version: env!("CARGO_PKG_VERSION").into(),
        volume: display_label(&session.request().scene.volume),
        dims: g.dims,
        spacing: g.spacing,
        bounds: {
            let (lo, hi) = g.bounds_world();
            [lo.to_array(), hi.to_array()]
        },
        value_range: range,
        histogram,
        presets: std::iter::once("auto".to_string())
            .chain(
                volsplat::core::Preset::ALL
                    .iter()
                    .map(|p| p.name().to_string()),
            )
            .collect(),
        volumes: tab.shared.volume_names(),
        budget_ms: session.settings().budget_ms(),
        fit: tab.shared.settings.fit_view,
        max_fit_side: crate::server::MAX_FIT_SIDE.min(session.settings().max_size),
    };
    tab.send(&ServerMessage::Hello(Box::new(hello)));
    tab.shared.set_latest(session.request());
    let mut st = tab.lock();
    let seq = st.seq;
    let state = state_of(&session, seq, None);
    st.session = Some(session);
    st.unacked = None;
    st.last_final = None;
    st.shown = None;
    drop(st);
    tab.send(&ServerMessage::State(Box::new(state)));
    tab.wake.notify_all();
    true
}

/// The volume's name for the page: a file's name without its folders (the page never learns
/// server paths), or the phantom.
fn display_label(source: &volsplat::VolumeSource) -> String {
    match source {
        volsplat::VolumeSource::File { path, .. } => path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| "volume".into()),
        other => other.label(),
    }
}

/// Renders one job, encodes it, waits for the page to acknowledge the previous frame, sends
/// it, and hands the job back to the session.
fn render_and_send(
    tab: &Tab,
    job: &Job,
    sent: Sent,
    id: u64,
    mut go: KeepGoing,
    last_tf: &mut Option<TransferFunction>,
) {
    let seq = sent.seq;
    let t0 = Instant::now();
    let mut last_progress = Instant::now();
    let is_final = job.is_final();
    let out = {
        let mut renderer = tab.shared.renderer();
        renderer.render(&job.request, &mut |p: &Progress| {
            if is_final && last_progress.elapsed() > Duration::from_millis(150) {
                last_progress = Instant::now();
                tab.send(&ServerMessage::Progress {
                    stage: p.stage.as_str().into(),
                    fraction: p.fraction,
                });
            }
            go(p) && !tab.shared.stopping()
        })
    };
    let render_ms = t0.elapsed().as_secs_f64() * 1e3;
    let out = match out {
        Ok(out) => out,
        Err(EngineError::Cancelled) => return finish(tab, job, JobOutcome::Cancelled),
        Err(e) => {
            // A refused scene goes back to the last one that rendered (Session::finished),
            // and the page is told so and shown that scene's state.
            let restored = {
                let mut st = tab.lock();
                let seq_now = st.seq;
                st.session.as_mut().and_then(|s| {
                    s.finished(job, JobOutcome::Failed)
                        .then(|| state_of(s, seq_now, None))
                })
            };
            tab.wake.notify_all();
            let back = if restored.is_some() {
                "; the scene is back to the last one that rendered"
            } else {
                ""
            };
            tab.error(Some(seq), format!("rendering: {e}{back}"));
            if let Some(state) = restored {
                tab.send(&ServerMessage::State(Box::new(state)));
            }
            return;
        }
    };
    let t1 = Instant::now();
    let encoded = match job.kind {
        JobKind::Final => frames::final_frame(&out, &job.request),
        JobKind::Preview(_) => {
            frames::preview_jpeg(&out, &job.request, tab.shared.settings.preview_quality)
        }
    };
    let bytes = match encoded {
        Ok(b) => b,
        Err(e) => {
            tab.error(Some(seq), e.to_string());
            return finish(tab, job, JobOutcome::Failed);
        }
    };
    let encode_ms = t1.elapsed().as_secs_f64() * 1e3;
    let (scale, slab_factor) = match job.kind {
        JobKind::Preview(p) => (p.scale, p.slab_factor),
        JobKind::Final => (1.0, 1.0),
    };
    // The pyramid level drawn (0: the volume itself, also where the renderer has no pyramid).
    let volume_level = out
        .stats
        .level
        .map_or(0, |l| u8::try_from(l).unwrap_or(u8::MAX));
    // Marked in flight before it is sent: the page may acknowledge it before `send` returns.
    let Some(seq) = wait_for_ack_then_mark(tab, job, id, sent.seq) else {
        return finish(tab, job, JobOutcome::Cancelled);
    };
    let header = FrameHeader {
        kind: "frame".into(),
        id,
        seq,
        quality: if is_final { "final" } else { "preview" }.into(),
        format: if is_final { "png" } else { "jpeg" }.into(),
        width: out.image.width(),
        height: out.image.height(),
        view: sent.view,
        render_ms,
        encode_ms,
        scale,
        slab_factor,
        volume_level,
        values_range: frames::values_range(&out),
        name: None,
    };
    if tab.out.binary(binary_message(&header, &bytes)).is_err() {
        return finish(tab, job, JobOutcome::Cancelled);
    }
    // The budget is about the machine's work (render and encode), not the page's pace.
    let ms = render_ms + encode_ms;
    let state = {
        let mut st = tab.lock();
        let seq = st.seq;
        let tf_changed = last_tf.as_ref() != Some(&out.transfer_function);
        let session = st.session.as_mut();
        session.map(|s| {
            s.finished(job, JobOutcome::Rendered { ms });
            tf_changed.then(|| state_of(s, seq, Some(out.transfer_function.clone())))
        })
    };
    if let Some(Some(state)) = state {
        *last_tf = Some(out.transfer_function.clone());
        tab.send(&ServerMessage::State(Box::new(state)));
    }
    for note in out.notes.iter().chain(&out.warnings) {
        tab.send(&ServerMessage::Note {
            message: note.clone(),
        });
    }
    if is_final {
        tab.lock().last_final = Some(Arc::new(LastFinal {
            out,
            request: job.request.clone(),
        }));
    }
}

/// Sends the PNG file of the latest final frame (the page's screenshot button).
fn screenshot(tab: &Tab) {
    let Some(last) = tab.lock().last_final.clone() else {
        return tab.error(None, "no full-quality frame yet".into());
    };
    match frames::screenshot_png(&last.out, &last.request) {
        Ok(bytes) => {
            let header = file_header("screenshot.png", "png");
            let _ = tab.out.binary(binary_message(&header, &bytes));
        }
        Err(e) => tab.error(None, format!("screenshot: {e}")),
    }
}

/// The header of a file message.
fn file_header(name: &str, format: &str) -> FrameHeader {
    FrameHeader {
        kind: "file".into(),
        id: 0,
        seq: 0,
        quality: "final".into(),
        format: format.into(),
        width: 0,
        height: 0,
        view: [0, 0],
        render_ms: 0.0,
        encode_ms: 0.0,
        scale: 1.0,
        slab_factor: 1.0,
        volume_level: 0,
        values_range: None,
        name: Some(name.into()),
    }
}

/// Waits until no frame is in flight, then marks frame `id` of `job` as in flight and as the
/// frame shown; returns the latest event it shows (`None` if the tab closed meanwhile): every
/// event applied so far when the scene is still the job's (events since the job was made
/// changed nothing that is seen), else `made_at`, the latest event when the job was made.
fn wait_for_ack_then_mark(tab: &Tab, job: &Job, id: u64, made_at: u64) -> Option<u64> {
    let mut st = tab.lock();
    while st.unacked.is_some() {
        if st.closed || tab.shared.stopping() {
            return None;
        }
        st = tab
            .wake
            .wait_timeout(st, Duration::from_millis(500))
            .map(|(g, _)| g)
            .unwrap_or_else(|e| e.into_inner().0);
    }
    if st.closed {
        return None;
    }
    st.unacked = Some(id);
    let current = st.session.as_ref().is_some_and(|s| s.is_current(job));
    let seq = if current { st.seq } else { made_at };
    st.shown = Some(ShownFrame {
        id,
        generation: job.generation,
        is_final: job.is_final(),
        seq,
    });
    Some(seq)
}

fn finish(tab: &Tab, job: &Job, outcome: JobOutcome) {
    if let Some(s) = tab.lock().session.as_mut() {
        s.finished(job, outcome);
    }
    tab.wake.notify_all();
}

/// Renders a turntable of the current scene on the server and sends it as a GIF file.
fn turntable(tab: &Tab, frames: usize, degrees: f64, fps: f64, max_size: usize) {
    let Some((request, camera)) = tab
        .lock()
        .session
        .as_ref()
        .map(|s| (s.request().clone(), s.camera().clone()))
    else {
        return;
    };
    match crate::turntable::render(tab, &request, &camera, frames, degrees, fps, max_size) {
        Ok(Some(bytes)) => {
            let header = file_header("turntable.gif", "gif");
            let _ = tab.out.binary(binary_message(&header, &bytes));
        }
        Ok(None) => tab.send(&ServerMessage::Progress {
            stage: "turntable".into(),
            fraction: 1.0,
        }),
        Err(e) => tab.error(None, format!("turntable: {e}")),
    }
    // The scene's frame is shown again after the turntable's progress.
    tab.wake.notify_all();
}

impl Tab {
    /// Progress of a turntable, and whether to go on.
    pub(crate) fn turntable_progress(&self, fraction: f64) -> bool {
        self.send(&ServerMessage::Progress {
            stage: "turntable".into(),
            fraction,
        });
        !self.cancel_turntable.load(Ordering::Acquire) && !self.shared.stopping()
    }

    /// Whether the turntable was cancelled.
    pub(crate) fn turntable_cancelled(&self) -> bool {
        self.cancel_turntable.load(Ordering::Acquire) || self.shared.stopping()
    }

    /// The shared server state.
    pub(crate) fn shared(&self) -> &Shared {
        &self.shared
    }
}
