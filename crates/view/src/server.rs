//! The server: a listening socket, one thread per connection, the state the tabs share (one
//! renderer and volume, the token, the data folder).

use crate::error::{Result, ViewError};
use crate::http::{self, HeadError, HostRule, Route};
use crate::socket::{Outgoing, SocketStream};
use crate::token::Token;
use std::collections::HashMap;
use std::net::{IpAddr, SocketAddr, TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;
use volsplat::core::AnyVolume;
use volsplat::session::{Clock, SessionSettings, SystemClock};
use volsplat::{CameraSpec, RenderRequest, Renderer, TransferSpec, VolumeSource};

/// How a viewer listens and paces its frames.
#[derive(Debug, Clone)]
pub struct ViewerSettings {
    /// Address to listen on (default `127.0.0.1`).
    pub host: String,
    /// Port (0, the default: a free one).
    pub port: u16,
    /// Listen on an address other than loopback (`--allow-remote`); the token is still needed.
    pub allow_remote: bool,
    /// A folder whose volume files the page may list and open (read-only), by name only.
    pub data_dir: Option<PathBuf>,
    /// Frame pacing of each tab's session.
    pub session: SessionSettings,
    /// JPEG quality of previews, 1..=100.
    pub preview_quality: u8,
    /// Most tabs at once (default 16).
    pub max_tabs: usize,
    /// Most connections at once that are not (yet) tabs: page loads and request heads being
    /// read (default [`MAX_PENDING_CONNECTIONS`]). One beyond it is answered 503 and closed at
    /// once, so idle connections cannot pile up threads; tabs have their own cap.
    pub max_connections: usize,
    /// The image follows the page's view (`false`, the default: the request's size, fixed):
    /// the page sends the size of its view in device pixels (up to [`MAX_FIT_SIDE`] on the
    /// long side) and the session renders at that size, as ParaView's and napari's views fill
    /// their window. `volsplat view` sets it unless `--size` or `--scene` gives a size.
    pub fit_view: bool,
}

/// Default of [`ViewerSettings::max_connections`].
pub const MAX_PENDING_CONNECTIONS: usize = 32;

/// Longest side, pixels, of a view that follows the page ([`ViewerSettings::fit_view`]).
pub const MAX_FIT_SIDE: usize = 2048;

impl Default for ViewerSettings {
    fn default() -> Self {
        ViewerSettings {
            host: "127.0.0.1".into(),
            port: 0,
            allow_remote: false,
            data_dir: None,
            session: SessionSettings::default(),
            preview_quality: crate::frames::DEFAULT_PREVIEW_QUALITY,
            max_tabs: 16,
            max_connections: MAX_PENDING_CONNECTIONS,
            fit_view: false,
        }
    }
}

/// Histogram counts over a value range (data units).
type Histogram = (Vec<u64>, [f64; 2]);

/// What every tab shares.
pub(crate) struct Shared {
    renderer: Mutex<Renderer>,
    /// The request the command line (or the caller) started with.
    start: RenderRequest,
    pub(crate) settings: ViewerSettings,
    token: Token,
    hosts: HostRule,
    stopping: AtomicBool,
    tabs: AtomicUsize,
    /// Connections not (yet) tabs: page loads and heads being read.
    pending: AtomicUsize,
    /// Sockets of open connections, to close them when the server stops.
    open: Mutex<HashMap<u64, Arc<Outgoing>>>,
    next_conn: AtomicUsize,
    histograms: Mutex<HashMap<String, Histogram>>,
    pub(crate) clock: Arc<dyn Clock>,
    /// The scene of the tab that changed last (the start request before any), for library
    /// callers ([`ViewerHandle::scene`]).
    latest: Mutex<RenderRequest>,
}

impl Shared {
    /// The renderer, shared by the tabs: their renders take turns.
    pub(crate) fn renderer(&self) -> MutexGuard<'_, Renderer> {
        self.renderer.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Whether the server is stopping.
    pub(crate) fn stopping(&self) -> bool {
        self.stopping.load(Ordering::Acquire)
    }

    /// The histogram of the volume labelled `label`, computed once.
    pub(crate) fn histogram(
        &self,
        label: &str,
        vol: &AnyVolume,
        bins: usize,
    ) -> (Vec<u64>, [f64; 2]) {
        let mut h = self.histograms.lock().unwrap_or_else(|e| e.into_inner());
        h.entry(label.to_string())
            .or_insert_with(|| crate::frames::histogram(vol, bins))
            .clone()
    }

    /// The volume files of the data folder, by name, sorted (empty without a folder).
    pub(crate) fn volume_names(&self) -> Vec<String> {
        self.settings
            .data_dir
            .as_deref()
            .map(list_volumes)
            .unwrap_or_default()
    }

    /// The request that opens `name` from the data folder: the start request's settings on
    /// that volume, with VTK's reset camera and the automatic transfer function, at `size`
    /// (the tab's view) when given. Errors are messages for the page (they never name server
    /// paths).
    pub(crate) fn open_request(
        &self,
        name: &str,
        size: Option<(usize, usize)>,
    ) -> std::result::Result<RenderRequest, String> {
        let Some(dir) = self.settings.data_dir.as_deref() else {
            return Err("this server has no data folder (start it with --data-dir)".into());
        };
        if !self.volume_names().iter().any(|n| n == name) {
            return Err(format!(
                "`{}` is not in the volume list",
                name.escape_debug()
            ));
        }
        let path = dir.join(name);
        // The listing follows no links out of the folder; check again at opening.
        let inside = match (path.canonicalize(), dir.canonicalize()) {
            (Ok(p), Ok(d)) => p.starts_with(d),
            _ => false,
        };
        if !inside {
            return Err(format!(
                "`{}` is not in the volume list",
                name.escape_debug()
            ));
        }
        let mut req = self.start.clone();
        req.scene.volume = VolumeSource::File {
            path,
            raw: None,
            frame: 0,
            array: None,
            series: None,
            level: volsplat::StoreLevel::Index(0),
            channel: 0,
            timepoint: 0,
        };
        req.scene.camera = CameraSpec::default();
        req.scene.transfer_function = TransferSpec::Auto;
        req.scene.clipping = Default::default();
        if let Some((w, h)) = size {
            (req.width, req.height) = (w, h);
        }
        Ok(req)
    }

    /// The request a new tab starts from: the start request, at the page's view size when
    /// the view follows the page and the page gave a size it may have.
    pub(crate) fn tab_request(&self, view: Option<(usize, usize)>) -> RenderRequest {
        let mut req = self.start.clone();
        if let (true, Some((w, h))) = (self.settings.fit_view, view)
            && fits(w, h, self.settings.session.max_size)
        {
            (req.width, req.height) = (w, h);
        }
        req
    }

    /// Records the scene a tab has just changed to.
    pub(crate) fn set_latest(&self, request: &RenderRequest) {
        *self.latest.lock().unwrap_or_else(|e| e.into_inner()) = request.clone();
    }

    fn register(&self, out: &Arc<Outgoing>) -> u64 {
        let id = self.next_conn.fetch_add(1, Ordering::AcqRel) as u64;
        self.open
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .insert(id, Arc::clone(out));
        id
    }

    fn unregister(&self, id: u64) {
        self.open
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .remove(&id);
    }
}

/// Why `dir` cannot be a data folder (`--data-dir`): it does not exist, or is not a folder.
pub fn check_data_dir(dir: &Path) -> std::result::Result<(), String> {
    match std::fs::metadata(dir) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            Err(format!("{}: no such folder", dir.display()))
        }
        Err(e) => Err(format!("{}: cannot be read: {e}", dir.display())),
        Ok(m) if !m.is_dir() => Err(format!(
            "{} is a file, not a folder (to view the file, give it as the volume; \
             --data-dir names the folder whose volume files the page may open)",
            dir.display()
        )),
        Ok(_) => Ok(()),
    }
}

/// Regular files of `dir` whose names have a volume extension volsplat reads, and OME-Zarr
/// stores (folders named `.zarr`), sorted; hidden files and links that leave the folder are
/// left out. Files whose headers name a file outside
/// the folder are listed: opening one is refused with the reader's error (reading every
/// header at each listing would be slow on large folders).
pub fn list_volumes(dir: &Path) -> Vec<String> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    let canonical = dir.canonicalize().ok();
    let mut names: Vec<String> = entries
        .filter_map(|e| e.ok())
        .filter_map(|e| {
            let name = e.file_name().into_string().ok()?;
            let path = e.path();
            let inside = match (path.canonicalize(), &canonical) {
                (Ok(p), Some(d)) => p.starts_with(d),
                _ => false,
            };
            let lower = name.to_ascii_lowercase();
            let known = volsplat::io::VOLUME_EXTENSIONS
                .iter()
                .any(|ext| lower.ends_with(&format!(".{ext}")));
            // An OME-Zarr store is a folder named `.zarr`.
            let readable = path.is_file() || (lower.ends_with(".zarr") && path.is_dir());
            (crate::protocol::is_plain_name(&name) && readable && inside && known).then_some(name)
        })
        .collect();
    names.sort();
    names
}

/// A viewer bound to its port, not yet serving.
pub struct Viewer {
    listener: TcpListener,
    shared: Arc<Shared>,
    url: String,
    addr: SocketAddr,
}

impl std::fmt::Debug for Viewer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Viewer").field("addr", &self.addr).finish()
    }
}

impl Viewer {
    /// Checks the settings, starts a session on `request` once (loading the volume into
    /// `renderer`, so a bad volume is an error before any URL is shown), binds the port and
    /// draws the token.
    pub fn bind(
        request: RenderRequest,
        mut renderer: Renderer,
        settings: ViewerSettings,
    ) -> Result<Viewer> {
        settings.session.validate()?;
        if !(1..=100).contains(&settings.preview_quality) {
            return Err(ViewError::settings(
                "preview quality",
                format!("must be in 1..=100, got {}", settings.preview_quality),
            ));
        }
        let ip = parse_host(&settings.host)?;
        if !ip.is_loopback() && !settings.allow_remote {
            return Err(ViewError::settings(
                "--host",
                format!(
                    "{} is reachable from other machines; add --allow-remote to listen there \
                     (every request still needs the token), or use an SSH tunnel to 127.0.0.1",
                    settings.host
                ),
            ));
        }
        if let Some(d) = &settings.data_dir {
            check_data_dir(d).map_err(|e| ViewError::settings("--data-dir", e))?;
            // The page chooses the folder's files, so they are untrusted: a volume file there
            // may open only files there (a header's `data file`, a `.hdr`'s `.img`, the other
            // slices of a DICOM series), whoever asks the renderer to read it. The volume given
            // on the command line, outside the folder, is read as without it (decision 0033).
            let limits = renderer.limits().clone().with_confine_to(Some(d.clone()));
            renderer = Renderer::with_limits(limits);
        }
        if settings.max_connections == 0 || settings.max_tabs == 0 {
            return Err(ViewError::settings(
                "connections",
                "max_connections and max_tabs must be at least 1",
            ));
        }
        let clock: Arc<dyn Clock> = Arc::new(SystemClock::new());
        let probe = volsplat::session::Session::start(
            request.clone(),
            &mut renderer,
            settings.session,
            Arc::clone(&clock),
        )?;
        let listener = TcpListener::bind((ip, settings.port))
            .map_err(|e| ViewError::socket(format!("listening on {ip}:{}", settings.port), e))?;
        let addr = listener
            .local_addr()
            .map_err(|e| ViewError::socket("the listening address", e))?;
        let token = Token::random()?;
        let hosts = if ip.is_loopback() {
            HostRule::Loopback
        } else if ip.is_unspecified() {
            HostRule::Any
        } else {
            HostRule::LoopbackOr(settings.host.clone())
        };
        let url_host = match ip {
            ip if ip.is_unspecified() => "127.0.0.1".to_string(),
            IpAddr::V6(v6) => format!("[{v6}]"),
            IpAddr::V4(v4) => v4.to_string(),
        };
        let url = format!("http://{url_host}:{}/?token={}", addr.port(), token.hex());
        let latest = Mutex::new(probe.request().clone());
        Ok(Viewer {
            listener,
            shared: Arc::new(Shared {
                renderer: Mutex::new(renderer),
                start: request,
                settings,
                token,
                hosts,
                stopping: AtomicBool::new(false),
                tabs: AtomicUsize::new(0),
                pending: AtomicUsize::new(0),
                open: Mutex::new(HashMap::new()),
                next_conn: AtomicUsize::new(1),
                histograms: Mutex::new(HashMap::new()),
                clock,
                latest,
            }),
            url,
            addr,
        })
    }

    /// The page's URL with the token (`http://127.0.0.1:PORT/?token=…`).
    pub fn url(&self) -> &str {
        &self.url
    }

    /// The address listened on.
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// The token's hex form.
    pub fn token(&self) -> String {
        self.shared.token.hex()
    }

    /// Serves on a background thread until [`ViewerHandle::stop`] (or the handle is dropped).
    pub fn spawn(self) -> Result<ViewerHandle> {
        let shared = Arc::clone(&self.shared);
        let (url, addr) = (self.url.clone(), self.addr);
        let thread = std::thread::Builder::new()
            .name("volsplat-view".into())
            .spawn(move || self.serve())
            .map_err(|e| ViewError::socket("starting the server thread", e))?;
        Ok(ViewerHandle {
            shared,
            url,
            addr,
            thread: Some(thread),
        })
    }

    /// Serves on this thread until the server is stopped from a [`StopHandle`].
    pub fn serve(self) {
        for conn in self.listener.incoming() {
            if self.shared.stopping() {
                break;
            }
            let Ok(stream) = conn else { continue };
            // Counted before its thread starts, so a flood of connections cannot outrun the
            // cap; the thread gives the count back once its head is answered (or it becomes a
            // tab, which `max_tabs` caps).
            let pending = self.shared.pending.fetch_add(1, Ordering::AcqRel) + 1;
            if pending > self.shared.settings.max_connections {
                self.shared.pending.fetch_sub(1, Ordering::AcqRel);
                busy(stream);
                continue;
            }
            let shared = Arc::clone(&self.shared);
            let spawned = std::thread::Builder::new()
                .name("volsplat-view-conn".into())
                .spawn(move || connection(shared, stream));
            if spawned.is_err() {
                self.shared.pending.fetch_sub(1, Ordering::AcqRel);
            }
        }
    }

    /// A handle that stops [`Viewer::serve`] from another thread (a Ctrl-C handler).
    pub fn stop_handle(&self) -> StopHandle {
        StopHandle {
            shared: Arc::clone(&self.shared),
            addr: self.addr,
        }
    }
}

/// Stops a serving [`Viewer`] from another thread.
#[derive(Clone)]
pub struct StopHandle {
    shared: Arc<Shared>,
    addr: SocketAddr,
}

impl std::fmt::Debug for StopHandle {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("StopHandle")
            .field("addr", &self.addr)
            .finish()
    }
}

impl StopHandle {
    /// Stops accepting, closes every open connection and cancels renders in flight.
    pub fn stop(&self) {
        if self.shared.stopping.swap(true, Ordering::AcqRel) {
            return;
        }
        let open: Vec<Arc<Outgoing>> = self
            .shared
            .open
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .values()
            .cloned()
            .collect();
        for o in open {
            o.shutdown();
        }
        // Wake the accept loop.
        let wake = match self.addr {
            SocketAddr::V4(a) if a.ip().is_unspecified() => {
                SocketAddr::from(([127, 0, 0, 1], a.port()))
            }
            SocketAddr::V6(a) if a.ip().is_unspecified() => {
                SocketAddr::from((std::net::Ipv6Addr::LOCALHOST, a.port()))
            }
            a => a,
        };
        let _ = TcpStream::connect_timeout(&wake, Duration::from_secs(1));
    }
}

/// A viewer serving on a background thread; dropping it stops the server.
pub struct ViewerHandle {
    shared: Arc<Shared>,
    url: String,
    addr: SocketAddr,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl std::fmt::Debug for ViewerHandle {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ViewerHandle")
            .field("addr", &self.addr)
            .finish()
    }
}

impl ViewerHandle {
    /// The page's URL with the token.
    pub fn url(&self) -> &str {
        &self.url
    }

    /// The address listened on.
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// The token's hex form.
    pub fn token(&self) -> String {
        self.shared.token.hex()
    }

    /// The scene of the tab that changed last (the starting scene before any tab did): its
    /// request, camera explicit, with its output options (grey window, background, PNG
    /// encoding), as `volsplat render --scene` reads it.
    pub fn scene(&self) -> RenderRequest {
        self.shared
            .latest
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clone()
    }

    /// Number of tabs connected now.
    pub fn tabs(&self) -> usize {
        self.shared.tabs.load(Ordering::Acquire)
    }

    /// Number of connections now that are not tabs (page loads, heads being read); at most
    /// [`ViewerSettings::max_connections`].
    pub fn pending_connections(&self) -> usize {
        self.shared.pending.load(Ordering::Acquire)
    }

    /// Stops the server and waits for its accept loop to end.
    pub fn stop(&mut self) {
        StopHandle {
            shared: Arc::clone(&self.shared),
            addr: self.addr,
        }
        .stop();
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl Drop for ViewerHandle {
    fn drop(&mut self) {
        self.stop();
    }
}

fn parse_host(host: &str) -> Result<IpAddr> {
    if host.eq_ignore_ascii_case("localhost") {
        return Ok(IpAddr::from([127, 0, 0, 1]));
    }
    host.trim_matches(|c| c == '[' || c == ']')
        .parse::<IpAddr>()
        .map_err(|_| {
            ViewError::settings(
                "--host",
                format!("`{host}` is not an IP address (e.g. 127.0.0.1, ::1, 0.0.0.0)"),
            )
        })
}

/// Time a client has to send its request head.
const HEAD_TIMEOUT: Duration = Duration::from_secs(10);

/// Whether a view of `w × h` pixels may follow the page: each side in `1..=max` and the long
/// side at most [`MAX_FIT_SIDE`].
fn fits(w: usize, h: usize, max: usize) -> bool {
    (1..=max.min(MAX_FIT_SIDE)).contains(&w) && (1..=max.min(MAX_FIT_SIDE)).contains(&h)
}

/// Answers a connection beyond [`ViewerSettings::max_connections`] with 503 without reading
/// it, on the accepting thread: a short write to a new socket's empty buffer, which never
/// waits; the socket is closed at once.
fn busy(stream: TcpStream) {
    let mut stream = stream;
    let _ = stream.set_nonblocking(true);
    let _ = http::refuse(
        &mut stream,
        http::Refused {
            status: 503,
            reason: "too many connections; try again",
        },
    );
    let _ = stream.shutdown(std::net::Shutdown::Both);
}

/// One connection: read the head, check it, answer the page or run a tab. It counts as
/// pending (see [`Viewer::serve`]) until its head is answered or it becomes a tab.
fn connection(shared: Arc<Shared>, mut stream: TcpStream) {
    struct Pending<'a>(Option<&'a Shared>);
    impl Pending<'_> {
        fn release(&mut self) {
            if let Some(s) = self.0.take() {
                s.pending.fetch_sub(1, Ordering::AcqRel);
            }
        }
    }
    impl Drop for Pending<'_> {
        fn drop(&mut self) {
            self.release();
        }
    }
    let mut pending = Pending(Some(&shared));
    if shared.stopping() {
        return;
    }
    let _ = stream.set_read_timeout(Some(HEAD_TIMEOUT));
    let _ = stream.set_nodelay(true);
    let (head, bytes) = match http::read_head(&mut stream) {
        Ok(h) => h,
        Err(HeadError::Malformed(_)) => {
            let _ = http::refuse(
                &mut stream,
                http::Refused {
                    status: 400,
                    reason: "malformed request",
                },
            );
            return;
        }
        Err(HeadError::Io(_)) => return,
    };
    match http::check(&head, &shared.token, &shared.hosts) {
        Err(r) => {
            let _ = http::refuse(&mut stream, r);
        }
        Ok(Route::Page) => {
            let (page, nonce) = crate::assets::page();
            let csp = format!(
                "Content-Security-Policy: default-src 'none'; script-src 'nonce-{nonce}'; \
                 style-src 'unsafe-inline'; img-src blob: data:; connect-src 'self'; \
                 base-uri 'none'; form-action 'none'\r\n"
            );
            let _ = http::respond(&mut stream, 200, "text/html; charset=utf-8", &csp, &page);
        }
        Ok(Route::Socket) => {
            pending.release();
            drop(pending);
            socket(shared, stream, bytes, head.view)
        }
    }
}

/// Accepts the WebSocket (tungstenite answers the handshake) and runs the tab.
fn socket(shared: Arc<Shared>, stream: TcpStream, head: Vec<u8>, view: Option<(usize, usize)>) {
    let tabs = shared.tabs.fetch_add(1, Ordering::AcqRel) + 1;
    struct Leave<'a>(&'a Shared);
    impl Drop for Leave<'_> {
        fn drop(&mut self) {
            self.0.tabs.fetch_sub(1, Ordering::AcqRel);
        }
    }
    let _leave = Leave(&shared);
    let Ok(write_half) = stream.try_clone() else {
        return;
    };
    let Ok(out) = Outgoing::new(write_half).map(Arc::new) else {
        return;
    };
    if tabs > shared.settings.max_tabs {
        let _ = out.write_all(
            b"HTTP/1.1 503 Service Unavailable\r\nContent-Length: 14\r\nConnection: close\r\n\r\ntoo many tabs\n",
        );
        return;
    }
    let conn = shared.register(&out);
    // The head is read; the tab's reader blocks until the page speaks or the socket closes.
    let _ = stream.set_read_timeout(None);
    let config = tungstenite::protocol::WebSocketConfig::default()
        .max_message_size(Some(crate::tab::WS_MAX))
        .max_frame_size(Some(crate::tab::WS_MAX));
    let stream_for_ws = SocketStream::new(head, stream, Arc::clone(&out));
    let accepted = tungstenite::accept_with_config(stream_for_ws, Some(config));
    if let Ok(ws) = accepted {
        let request = shared.tab_request(view);
        crate::tab::run(Arc::clone(&shared), ws, Arc::clone(&out), request);
    }
    shared.unregister(conn);
}
