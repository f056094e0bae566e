//! The viewer in a real browser: headless Chromium, driven over the DevTools protocol, loads
//! the page with the token, drags on the view with the mouse (the page sees pointer events),
//! waits for the final frame, saves the scene and the screenshot with the page's own buttons,
//! and compares them with `volsplat render --scene` of the saved scene: the screenshot file bit
//! for bit, the view as the browser shows it by PSNR.
//!
//! Runs only with `VOLSPLAT_BROWSER_TEST=1` (`.ci/view.sh` installs Debian's `chromium` and sets
//! it); `VOLSPLAT_CHROMIUM` names the browser (default `chromium`), and
//! `VOLSPLAT_PAGE_SCREENSHOT=FILE.png` also keeps a picture of the whole page.

use base64::Engine;
use serde_json::{Value, json};
use std::io::{BufRead, BufReader};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};
use tungstenite::{Message, WebSocket};

const WAIT: Duration = Duration::from_secs(120);

/// A DevTools session on one page.
struct Cdp {
    ws: WebSocket<TcpStream>,
    session: Option<String>,
    next: u64,
}

impl Cdp {
    fn connect(url: &str) -> Cdp {
        let addr = url
            .trim_start_matches("ws://")
            .split('/')
            .next()
            .unwrap()
            .to_string();
        let stream = TcpStream::connect(addr).unwrap();
        let (ws, _) = tungstenite::client(url, stream).unwrap();
        Cdp {
            ws,
            session: None,
            next: 0,
        }
    }

    /// Sends a command and waits for its result (events in between are dropped).
    fn call(&mut self, method: &str, params: Value) -> Value {
        self.next += 1;
        let id = self.next;
        let mut msg = json!({"id": id, "method": method, "params": params});
        if let Some(s) = &self.session {
            msg["sessionId"] = json!(s);
        }
        self.ws.send(Message::text(msg.to_string())).unwrap();
        loop {
            let m = self.ws.read().unwrap();
            let Message::Text(t) = m else { continue };
            let v: Value = serde_json::from_str(t.as_str()).unwrap();
            if v["id"] == json!(id) {
                assert!(v.get("error").is_none(), "{method}: {v}");
                return v["result"].clone();
            }
        }
    }

    /// Evaluates a JavaScript expression in the page and returns its value.
    fn eval(&mut self, expr: &str) -> Value {
        let r = self.call(
            "Runtime.evaluate",
            json!({"expression": expr, "returnByValue": true, "awaitPromise": true}),
        );
        assert!(r.get("exceptionDetails").is_none(), "{expr}: {r}");
        r["result"]["value"].clone()
    }

    /// Polls `expr` until it is true.
    fn wait(&mut self, expr: &str, what: &str) {
        let end = Instant::now() + WAIT;
        while Instant::now() < end {
            if self.eval(expr) == json!(true) {
                return;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        let errors = self.eval("JSON.stringify(window.__volsplat && window.__volsplat.errors)");
        panic!("timed out waiting for {what} (page errors: {errors})");
    }

    fn mouse(&mut self, kind: &str, x: f64, y: f64, buttons: u32) {
        self.call(
            "Input.dispatchMouseEvent",
            json!({"type": kind, "x": x, "y": y, "button": "left", "buttons": buttons,
                   "clickCount": if kind == "mouseMoved" { 0 } else { 1 }}),
        );
    }
}

/// Starts headless Chromium with a DevTools port; returns it and the browser's endpoint.
fn chromium(profile: &Path) -> (Child, String) {
    let exe = std::env::var("VOLSPLAT_CHROMIUM").unwrap_or_else(|_| "chromium".into());
    let mut child = Command::new(&exe)
        .args([
            "--headless=new",
            "--no-sandbox",
            "--disable-gpu",
            "--hide-scrollbars",
            "--force-device-scale-factor=1",
            "--force-color-profile=srgb",
            "--remote-debugging-port=0",
            "--window-size=1300,860",
        ])
        .arg(format!("--user-data-dir={}", profile.display()))
        .arg("about:blank")
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("cannot start {exe}: {e} (set VOLSPLAT_CHROMIUM)"));
    let mut lines = BufReader::new(child.stderr.take().unwrap()).lines();
    let url = loop {
        let line = lines.next().expect("chromium ended").unwrap();
        if let Some(u) = line.strip_prefix("DevTools listening on ") {
            break u.trim().to_string();
        }
    };
    // Keep draining its messages so it never blocks on a full pipe.
    std::thread::spawn(move || for _ in lines {});
    (child, url)
}

/// `volsplat view ARGS --no-browser`: the process and its URL.
fn viewer(args: &[&str]) -> (Child, String) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_volsplat"))
        .arg("view")
        .args(args)
        .arg("--no-browser")
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let url = line.trim().strip_prefix("open ").unwrap().to_string();
    (child, url)
}

fn decode_png(bytes: &[u8]) -> (usize, usize, Vec<u8>) {
    let mut d = png::Decoder::new(std::io::Cursor::new(bytes));
    d.set_transformations(png::Transformations::STRIP_16 | png::Transformations::EXPAND);
    let mut r = d.read_info().unwrap();
    let mut buf = vec![0; r.output_buffer_size().unwrap()];
    let info = r.next_frame(&mut buf).unwrap();
    buf.truncate(info.buffer_size());
    let channels = info.color_type.samples();
    let rgb = buf
        .chunks_exact(channels)
        .flat_map(|p| match channels {
            1 | 2 => [p[0], p[0], p[0]],
            _ => [p[0], p[1], p[2]],
        })
        .collect();
    (info.width as usize, info.height as usize, rgb)
}

fn psnr(a: &[u8], b: &[u8]) -> f64 {
    assert_eq!(a.len(), b.len());
    let mse = a
        .iter()
        .zip(b)
        .map(|(&x, &y)| (x as f64 - y as f64).powi(2))
        .sum::<f64>()
        / a.len() as f64;
    if mse == 0.0 {
        f64::INFINITY
    } else {
        10.0 * (255.0f64.powi(2) / mse).log10()
    }
}

/// Waits for a finished download named `name` in `dir`.
fn downloaded(dir: &Path, name: &str) -> PathBuf {
    let path = dir.join(name);
    let end = Instant::now() + WAIT;
    while Instant::now() < end {
        if path.is_file() && std::fs::metadata(&path).is_ok_and(|m| m.len() > 0) {
            std::thread::sleep(Duration::from_millis(100));
            return path;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    panic!("no download {name} in {}", dir.display());
}

/// A page in headless Chromium on `volsplat view ARGS`, with its server and download folder.
struct Page {
    cdp: Cdp,
    server: Child,
    browser: Child,
    downloads: PathBuf,
    tmp: tempfile::TempDir,
}

impl Page {
    /// Starts the viewer and the browser, opens the page at `width × height` CSS pixels
    /// (device scale 1) and waits for the first final frame.
    fn open(args: &[&str], width: u32, height: u32) -> Page {
        let tmp = tempfile::tempdir().unwrap();
        let downloads = tmp.path().join("downloads");
        std::fs::create_dir(&downloads).unwrap();
        let (server, url) = viewer(args);
        let (browser, endpoint) = chromium(&tmp.path().join("profile"));
        let mut cdp = Cdp::connect(&endpoint);
        cdp.call(
            "Browser.setDownloadBehavior",
            json!({"behavior": "allow", "downloadPath": downloads.to_str().unwrap()}),
        );
        let target = cdp.call("Target.createTarget", json!({"url": "about:blank"}));
        let attached = cdp.call(
            "Target.attachToTarget",
            json!({"targetId": target["targetId"], "flatten": true}),
        );
        cdp.session = Some(attached["sessionId"].as_str().unwrap().to_string());
        let mut page = Page {
            cdp,
            server,
            browser,
            downloads,
            tmp,
        };
        page.set_size(width, height);
        page.cdp.call("Page.navigate", json!({"url": url}));
        page.cdp.wait(
            "!!(window.__volsplat && window.__volsplat.finalFrames >= 1)",
            "the first final frame",
        );
        page
    }

    /// The window's size, CSS pixels (device scale 1).
    fn set_size(&mut self, width: u32, height: u32) {
        self.cdp.call(
            "Emulation.setDeviceMetricsOverride",
            json!({"width": width, "height": height, "deviceScaleFactor": 1, "mobile": false}),
        );
    }

    /// An element's box: left, top, width, height (CSS pixels).
    fn rect(&mut self, id: &str) -> [f64; 4] {
        let v = self.cdp.eval(&format!(
            "(() => {{ const r = document.getElementById('{id}').getBoundingClientRect(); \
             return [r.left, r.top, r.width, r.height]; }})()"
        ));
        let r: Vec<f64> = v
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        [r[0], r[1], r[2], r[3]]
    }

    /// The stage's size in CSS pixels (= device pixels here).
    fn stage_size(&mut self) -> (usize, usize) {
        let v = self.cdp.eval(
            "(() => { const s = document.getElementById('stage'); \
             return [s.clientWidth, s.clientHeight]; })()",
        );
        (
            v[0].as_u64().unwrap() as usize,
            v[1].as_u64().unwrap() as usize,
        )
    }

    /// Waits for a final frame newer than `finals` that shows the page's latest event.
    fn wait_final_after(&mut self, finals: u64, what: &str) {
        self.cdp.wait(
            &format!(
                "(() => {{ const v = window.__volsplat; const h = v.lastHeader; \
                 return v.finalFrames > {finals} && h.quality === 'final' \
                 && h.seq >= v.seq(); }})()"
            ),
            what,
        );
    }

    fn finals(&mut self) -> u64 {
        self.cdp
            .eval("window.__volsplat.finalFrames")
            .as_u64()
            .unwrap()
    }

    /// The size of the last final frame, pixels.
    fn final_size(&mut self) -> (usize, usize) {
        let h = self.cdp.eval("window.__volsplat.lastHeader");
        (
            h["width"].as_u64().unwrap() as usize,
            h["height"].as_u64().unwrap() as usize,
        )
    }

    /// Drags across the view with the mouse (the page sees pointer events) and waits for the
    /// final frame after the release; returns the previews seen during the drag.
    fn drag(&mut self) -> u64 {
        let r = self.rect("view");
        let (cx, cy) = (r[0] + r[2] / 2.0, r[1] + r[3] / 2.0);
        let finals = self.finals();
        let previews = self
            .cdp
            .eval("window.__volsplat.previewFrames")
            .as_u64()
            .unwrap();
        self.cdp.mouse("mousePressed", cx, cy, 1);
        for k in 1..=12 {
            self.cdp
                .mouse("mouseMoved", cx + 6.0 * k as f64, cy + 2.5 * k as f64, 1);
            std::thread::sleep(Duration::from_millis(16));
        }
        self.cdp.mouse("mouseReleased", cx + 72.0, cy + 30.0, 0);
        self.wait_final_after(finals, "the final frame after the drag");
        let orbit = self
            .cdp
            .eval("JSON.stringify(window.__volsplat.state().request.scene.camera)");
        assert!(
            orbit.as_str().unwrap().contains("explicit"),
            "the drag did not move the camera: {orbit}"
        );
        self.cdp
            .eval("window.__volsplat.previewFrames")
            .as_u64()
            .unwrap()
            - previews
    }

    /// Saves the scene and the screenshot with the page's own buttons, renders the scene with
    /// `volsplat render --scene`, and checks the screenshot file byte for byte, the final frame
    /// the page received pixel for pixel, and the view as the browser draws it by PSNR.
    /// Returns the scene.
    fn save_and_compare(&mut self, shot_name: &str) -> Value {
        self.cdp
            .eval("document.getElementById('save-scene').click()");
        let scene_path = downloaded(&self.downloads, "scene.json");
        let scene: Value =
            serde_json::from_str(&std::fs::read_to_string(&scene_path).unwrap()).unwrap();
        self.cdp
            .eval("document.getElementById('screenshot').click()");
        let shot = downloaded(&self.downloads, shot_name);
        let rendered = self.tmp.path().join("render.png");
        let out = Command::new(env!("CARGO_BIN_EXE_volsplat"))
            .arg("render")
            .arg("--scene")
            .arg(&scene_path)
            .arg("-o")
            .arg(&rendered)
            .arg("--quiet")
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let render_png = std::fs::read(&rendered).unwrap();
        assert_eq!(
            std::fs::read(&shot).unwrap(),
            render_png,
            "the screenshot button's PNG is not render's file"
        );
        let page_png = self.cdp.eval(
            "(() => { const b = window.__volsplat.lastFinalPng; let s = ''; \
             for (const x of b) s += String.fromCharCode(x); return btoa(s); })()",
        );
        let page_png = base64::engine::general_purpose::STANDARD
            .decode(page_png.as_str().unwrap())
            .unwrap();
        assert_eq!(
            decode_png(&page_png),
            decode_png(&render_png),
            "the final frame the page received has other pixels than render's file"
        );
        // The view as the browser draws it, once the frame-info overlay (which lies on the
        // picture when it fills the view) has faded.
        self.cdp.wait(
            "getComputedStyle(document.getElementById('overlay')).opacity === '0'",
            "the overlay to fade",
        );
        let r = self.rect("view");
        let shown = self.cdp.call(
            "Page.captureScreenshot",
            json!({"format": "png", "clip": {"x": r[0], "y": r[1], "width": r[2],
                   "height": r[3], "scale": 1}}),
        );
        let view_png = base64::engine::general_purpose::STANDARD
            .decode(shown["data"].as_str().unwrap())
            .unwrap();
        let (w, h, shown) = decode_png(&view_png);
        let (rw, rh, expect) = decode_png(&render_png);
        assert_eq!((w, h), (rw, rh), "the view is not shown 1:1");
        let db = psnr(&shown, &expect);
        eprintln!("browser view vs render ({rw}×{rh}): {db:.1} dB");
        assert!(
            db >= 40.0,
            "the view in the browser differs from render: {db:.1} dB"
        );
        assert!(
            expect.iter().filter(|&&v| v > 40).count() > expect.len() / 50,
            "an empty picture proves nothing"
        );
        // The next downloads get the same names.
        std::fs::remove_file(&scene_path).unwrap();
        std::fs::remove_file(&shot).unwrap();
        scene
    }

    fn page_screenshot(&mut self, path: &Path) {
        let page = self
            .cdp
            .call("Page.captureScreenshot", json!({"format": "png"}));
        let bytes = base64::engine::general_purpose::STANDARD
            .decode(page["data"].as_str().unwrap())
            .unwrap();
        std::fs::write(path, bytes).unwrap();
    }
}

impl Drop for Page {
    fn drop(&mut self) {
        let _ = self.browser.kill();
        let _ = self.browser.wait();
        let _ = self.server.kill();
        let _ = self.server.wait();
    }
}

fn enabled() -> bool {
    if std::env::var_os("VOLSPLAT_BROWSER_TEST").is_none() {
        eprintln!("skipped: set VOLSPLAT_BROWSER_TEST=1 (and have chromium) to run");
        return false;
    }
    true
}

/// A fixed `--size`: the view is shown 1:1; a drag, then the screenshot and the saved scene
/// against `volsplat render --scene`.
#[test]
fn a_real_browser_drags_the_view_and_matches_render() {
    if !enabled() {
        return;
    }
    let mut page = Page::open(
        &[
            "--phantom",
            "head",
            "--phantom-size",
            "64,80,72",
            "--size",
            "384",
            "--preset",
            "ct-bone",
        ],
        1300,
        860,
    );
    let r = page.rect("view");
    assert_eq!((r[2], r[3]), (384.0, 384.0), "the view is shown 1:1");
    let previews = page.drag();
    eprintln!("{previews} previews during the drag");
    let scene = page.save_and_compare("head.png");
    assert_eq!(
        (scene["width"].as_u64(), scene["height"].as_u64()),
        (Some(384), Some(384))
    );
    let lod = page.cdp.eval("document.getElementById('lod').textContent");
    assert!(
        lod.as_str().unwrap().contains("fixed size"),
        "the overlay does not say the size is fixed: {lod}"
    );
    if let Some(path) = std::env::var_os("VOLSPLAT_PAGE_SCREENSHOT") {
        page.page_screenshot(Path::new(&path));
    }
}

/// Without `--size` the image fills the view (ParaView's and napari's behaviour): the final
/// frame's size is the stage's in device pixels, at two window sizes, and the screenshot and
/// saved scene (a MIP through a grey window and a background) are `render --scene`'s.
#[test]
fn a_real_browser_fills_the_view_and_matches_render() {
    if !enabled() {
        return;
    }
    let mut page = Page::open(
        &[
            "--phantom",
            "head",
            "--phantom-size",
            "64,80,72",
            "--preset",
            "ct-bone",
            "--background",
            "0.1,0.1,0.2",
        ],
        1400,
        900,
    );
    let stage = page.stage_size();
    assert!(stage.0 > 900 && stage.1 > 700, "{stage:?}");
    assert_eq!(
        page.final_size(),
        stage,
        "the first frame does not fill the view"
    );
    let r = page.rect("view");
    assert_eq!(
        (r[2] as usize, r[3] as usize),
        stage,
        "the view is not the stage"
    );
    let lod = page.cdp.eval("document.getElementById('lod').textContent");
    assert!(!lod.as_str().unwrap().contains("fixed"), "{lod}");
    page.drag();
    let scene = page.save_and_compare("head.png");
    assert_eq!(
        (scene["width"].as_u64(), scene["height"].as_u64()),
        (Some(stage.0 as u64), Some(stage.1 as u64))
    );
    assert_eq!(scene["output"]["background"], json!([0.1, 0.1, 0.2]));

    // A smaller window: the image follows once the resize settles.
    let finals = page.finals();
    page.set_size(1000, 700);
    let small = page.stage_size();
    assert!(
        small.0 < stage.0 && small.1 < stage.1,
        "{small:?} {stage:?}"
    );
    page.cdp.wait(
        &format!(
            "(() => {{ const v = window.__volsplat; const h = v.lastHeader; \
             return v.finalFrames > {finals} && h.quality === 'final' \
             && h.width === {} && h.height === {} && h.seq >= v.seq(); }})()",
            small.0, small.1
        ),
        "the final frame at the new view size",
    );
    // MIP through a grey window (the page's window/level): the scene keeps it.
    page.cdp
        .eval("document.querySelector('[data-mode=mip]').click()");
    page.cdp.eval(
        "(() => { const l = document.getElementById('level'); l.value = 400; \
         l.dispatchEvent(new Event('input')); })()",
    );
    page.wait_final_after(0, "the windowed MIP frame");
    page.cdp.wait(
        "(() => { const s = window.__volsplat.state(); return !!(s && s.window); })()",
        "the window in the page's state",
    );
    page.wait_final_after(0, "the final frame of the window");
    let scene = page.save_and_compare("head.png");
    assert_eq!(
        (scene["width"].as_u64(), scene["height"].as_u64()),
        (Some(small.0 as u64), Some(small.1 as u64))
    );
    assert_eq!(scene["mode"], json!("mip"));
    assert!(scene["output"]["window"].is_array(), "{}", scene["output"]);
    if let Some(path) = std::env::var_os("VOLSPLAT_PAGE_SCREENSHOT") {
        let path = PathBuf::from(path);
        page.page_screenshot(&path.with_extension("fit.png"));
    }
}
