//! The HTTP side: read one request head (httparse), check it, answer a GET.
//!
//! Every response closes its connection; the page is one HTML document (its script and style
//! inlined) and everything else goes over the WebSocket, so keep-alive would buy nothing.

use crate::token::Token;
use std::io::{Read, Write};

/// Largest request head, bytes.
pub const MAX_HEAD_BYTES: usize = 16 * 1024;

/// Most headers of a request.
const MAX_HEADERS: usize = 48;

/// A parsed request head.
#[derive(Debug, Clone, PartialEq)]
pub struct RequestHead {
    /// `GET`, …
    pub method: String,
    /// The path without the query (`/`, `/ws`).
    pub path: String,
    /// The `token` query parameter, if any.
    pub token: Option<String>,
    /// The `view` query parameter of the WebSocket, `WxH` in pixels (the page's view in device
    /// pixels), if given and well formed: each side 1 to 5 decimal digits.
    pub view: Option<(usize, usize)>,
    /// The `Host` header.
    pub host: Option<String>,
    /// The `Origin` header.
    pub origin: Option<String>,
    /// Whether this asks for a WebSocket (`Upgrade: websocket`).
    pub websocket: bool,
    /// Length of the head in the bytes read (what follows belongs to the next protocol).
    pub head_len: usize,
}

/// Why a request head could not be read.
#[derive(Debug)]
pub enum HeadError {
    /// The connection failed or closed early.
    Io(std::io::Error),
    /// Not HTTP/1.x, or a head over [`MAX_HEAD_BYTES`].
    Malformed(String),
}

/// Reads from `stream` until a whole request head has arrived; returns it parsed and every
/// byte read (the head and anything after it).
pub fn read_head(stream: &mut impl Read) -> Result<(RequestHead, Vec<u8>), HeadError> {
    let mut buf = Vec::with_capacity(1024);
    let mut chunk = [0u8; 2048];
    loop {
        if let Some(head) = parse_head(&buf)? {
            return Ok((head, buf));
        }
        if buf.len() >= MAX_HEAD_BYTES {
            return Err(HeadError::Malformed(format!(
                "request head over {MAX_HEAD_BYTES} bytes"
            )));
        }
        let n = stream.read(&mut chunk).map_err(HeadError::Io)?;
        if n == 0 {
            return Err(HeadError::Io(std::io::ErrorKind::UnexpectedEof.into()));
        }
        buf.extend_from_slice(&chunk[..n]);
    }
}

/// Parses a request head if `buf` holds a whole one (`None`: read more).
pub fn parse_head(buf: &[u8]) -> Result<Option<RequestHead>, HeadError> {
    let mut headers = [httparse::EMPTY_HEADER; MAX_HEADERS];
    let mut req = httparse::Request::new(&mut headers);
    let head_len = match req.parse(buf) {
        Ok(httparse::Status::Complete(n)) => n,
        Ok(httparse::Status::Partial) => return Ok(None),
        Err(e) => return Err(HeadError::Malformed(e.to_string())),
    };
    let header = |name: &str| {
        req.headers
            .iter()
            .find(|h| h.name.eq_ignore_ascii_case(name))
            .and_then(|h| std::str::from_utf8(h.value).ok())
            .map(|v| v.trim().to_string())
    };
    let target = req.path.unwrap_or("/");
    let (path, query) = target.split_once('?').unwrap_or((target, ""));
    let param = |name: &str| {
        query
            .split('&')
            .filter_map(|kv| kv.split_once('='))
            .find(|(k, _)| *k == name)
            .map(|(_, v)| v)
    };
    let token = param("token").map(str::to_string);
    let view = param("view").and_then(parse_size);
    let websocket = header("upgrade").is_some_and(|u| u.eq_ignore_ascii_case("websocket"));
    Ok(Some(RequestHead {
        method: req.method.unwrap_or("").to_string(),
        path: path.to_string(),
        token,
        view,
        host: header("host"),
        origin: header("origin"),
        websocket,
        head_len,
    }))
}

/// `WxH`, each side 1 to 5 decimal digits and not zero.
fn parse_size(text: &str) -> Option<(usize, usize)> {
    let (w, h) = text.split_once('x')?;
    let side = |v: &str| {
        (!v.is_empty() && v.len() <= 5 && v.bytes().all(|b| b.is_ascii_digit()))
            .then(|| v.parse::<usize>().ok())
            .flatten()
            .filter(|&n| n > 0)
    };
    Some((side(w)?, side(h)?))
}

/// Which `Host` headers the server answers (against DNS rebinding: a page of another site
/// whose name resolves to this machine sends its own name).
#[derive(Debug, Clone, PartialEq)]
pub enum HostRule {
    /// Loopback names only (`127.0.0.1`, `localhost`, `[::1]`), any port: the server listens
    /// on loopback, and a tunnel (`ssh -L 9000:127.0.0.1:PORT`) arrives with its own port.
    Loopback,
    /// Loopback names or this host name or address.
    LoopbackOr(String),
    /// Any host (listening on every address, `0.0.0.0`): the token alone protects.
    Any,
}

impl HostRule {
    /// Whether a `Host` header value is accepted.
    pub fn allows(&self, host: &str) -> bool {
        let name = host_name(host);
        let loopback = matches!(name, "127.0.0.1" | "localhost" | "[::1]");
        match self {
            HostRule::Loopback => loopback,
            HostRule::LoopbackOr(h) => loopback || name.eq_ignore_ascii_case(host_name(h)),
            HostRule::Any => true,
        }
    }
}

/// The name part of `host[:port]` (`[v6]:port` keeps its brackets).
fn host_name(host: &str) -> &str {
    if let Some(end) = host.find(']') {
        return &host[..=end];
    }
    host.rsplit_once(':').map_or(host, |(h, _)| h)
}

/// What a request head asks for, once checked.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Route {
    /// The page.
    Page,
    /// The WebSocket.
    Socket,
}

/// Why a request is refused: the status line and a short text.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Refused {
    /// HTTP status code.
    pub status: u16,
    /// Short reason for the body (never names the token).
    pub reason: &'static str,
}

/// Checks a request: a GET, an allowed `Host`, the token, and for the WebSocket an `Origin`
/// that is this server's own (`http://` + the `Host` header; a client that sends no `Origin`
/// is not a browser and still needs the token). Then routes it.
pub fn check(head: &RequestHead, token: &Token, hosts: &HostRule) -> Result<Route, Refused> {
    let refuse = |status, reason| Err(Refused { status, reason });
    if head.method != "GET" {
        return refuse(405, "only GET");
    }
    let Some(host) = head.host.as_deref() else {
        return refuse(400, "no Host header");
    };
    if !hosts.allows(host) {
        return refuse(403, "this server does not answer that host name");
    }
    if !head.token.as_deref().is_some_and(|t| token.matches(t)) {
        return refuse(
            403,
            "missing or wrong token: open the URL the server printed",
        );
    }
    match (head.path.as_str(), head.websocket) {
        ("/", false) => Ok(Route::Page),
        ("/ws", true) => match head.origin.as_deref() {
            Some(origin) if !origin.eq_ignore_ascii_case(&format!("http://{host}")) => {
                refuse(403, "cross-origin WebSocket refused")
            }
            _ => Ok(Route::Socket),
        },
        ("/ws", false) => refuse(400, "expected a WebSocket upgrade"),
        _ => refuse(404, "not found"),
    }
}

/// Headers sent with every response: no caching (the URL holds the token), no referrer (it
/// would carry the token elsewhere), no MIME sniffing.
const COMMON_HEADERS: &str = "Cache-Control: no-store\r\nReferrer-Policy: no-referrer\r\n\
    X-Content-Type-Options: nosniff\r\nConnection: close\r\n";

/// Writes a complete response and flushes it.
pub fn respond(
    stream: &mut impl Write,
    status: u16,
    content_type: &str,
    extra_headers: &str,
    body: &[u8],
) -> std::io::Result<()> {
    let reason = match status {
        200 => "OK",
        400 => "Bad Request",
        403 => "Forbidden",
        404 => "Not Found",
        405 => "Method Not Allowed",
        503 => "Service Unavailable",
        _ => "Error",
    };
    let head = format!(
        "HTTP/1.1 {status} {reason}\r\nContent-Type: {content_type}\r\nContent-Length: {}\r\n\
         {COMMON_HEADERS}{extra_headers}\r\n",
        body.len()
    );
    stream.write_all(head.as_bytes())?;
    stream.write_all(body)?;
    stream.flush()
}

/// Writes a refusal as plain text.
pub fn refuse(stream: &mut impl Write, r: Refused) -> std::io::Result<()> {
    respond(
        stream,
        r.status,
        "text/plain; charset=utf-8",
        "",
        format!("{}\n", r.reason).as_bytes(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn head(text: &str) -> RequestHead {
        parse_head(text.as_bytes()).unwrap().unwrap()
    }

    fn token() -> (Token, String) {
        let t = Token::from_bytes([0x5a; 16]);
        let hex = t.hex();
        (t, hex)
    }

    #[test]
    fn heads_parse_in_pieces_and_refuse_garbage() {
        let text = "GET /?token=abc&x=1 HTTP/1.1\r\nHost: 127.0.0.1:8000\r\n\r\nrest";
        for cut in 0..text.len() - 4 {
            let r = parse_head(&text.as_bytes()[..cut]).unwrap();
            assert!(r.is_none(), "complete after {cut} bytes");
        }
        let h = head(text);
        assert_eq!(h.path, "/");
        assert_eq!(h.token.as_deref(), Some("abc"));
        assert_eq!(h.host.as_deref(), Some("127.0.0.1:8000"));
        assert_eq!(h.head_len, text.len() - 4);
        assert!(!h.websocket);
        assert_eq!(h.view, None);
        let sized = |q: &str| head(&format!("GET /ws?token=a&{q} HTTP/1.1\r\n\r\n")).view;
        assert_eq!(sized("view=1092x806"), Some((1092, 806)));
        for bad in [
            "view=0x5",
            "view=5x",
            "view=x5",
            "view=123456x5",
            "view=-1x5",
            "view=5x5x5",
            "view=+5x5",
            "view=5X5",
        ] {
            assert_eq!(sized(bad), None, "{bad}");
        }
        assert!(matches!(
            parse_head(b"\x00\x01 garbage\r\n\r\n"),
            Err(HeadError::Malformed(_))
        ));
        let long = format!("GET / HTTP/1.1\r\nX: {}\r\n", "y".repeat(MAX_HEAD_BYTES));
        let mut r = std::io::Cursor::new(long.into_bytes());
        assert!(matches!(read_head(&mut r), Err(HeadError::Malformed(_))));
    }

    #[test]
    fn the_token_host_and_origin_are_checked() {
        let (t, hex) = token();
        let rule = HostRule::Loopback;
        let get = |path: &str, host: &str, extra: &str| {
            head(&format!(
                "GET {path} HTTP/1.1\r\nHost: {host}\r\n{extra}\r\n"
            ))
        };
        let ws = "Upgrade: websocket\r\nConnection: Upgrade\r\n";
        let page = get(&format!("/?token={hex}"), "127.0.0.1:9000", "");
        assert_eq!(check(&page, &t, &rule), Ok(Route::Page));
        // Through a tunnel: another port, the name localhost.
        let tunnel = get(&format!("/?token={hex}"), "localhost:7000", "");
        assert_eq!(check(&tunnel, &t, &rule), Ok(Route::Page));
        for bad in [
            get("/", "127.0.0.1:9000", ""),
            get("/?token=", "127.0.0.1:9000", ""),
            get(&format!("/?token={}", &hex[..31]), "127.0.0.1:9000", ""),
            get(&format!("/?token={}0", &hex[..31]), "127.0.0.1:9000", ""),
            get(&format!("/?tok={hex}"), "127.0.0.1:9000", ""),
        ] {
            assert_eq!(check(&bad, &t, &rule).unwrap_err().status, 403);
        }
        // DNS rebinding: another site's name pointing here.
        let rebound = get(&format!("/?token={hex}"), "evil.example:9000", "");
        assert_eq!(check(&rebound, &t, &rule).unwrap_err().status, 403);
        let sock = |origin: &str| {
            get(
                &format!("/ws?token={hex}"),
                "127.0.0.1:9000",
                &format!("{ws}{origin}"),
            )
        };
        assert_eq!(check(&sock(""), &t, &rule), Ok(Route::Socket));
        assert_eq!(
            check(&sock("Origin: http://127.0.0.1:9000\r\n"), &t, &rule),
            Ok(Route::Socket)
        );
        for origin in [
            "Origin: http://evil.example\r\n",
            "Origin: http://127.0.0.1:9001\r\n",
            "Origin: https://127.0.0.1:9000\r\n",
            "Origin: null\r\n",
        ] {
            assert_eq!(
                check(&sock(origin), &t, &rule).unwrap_err().status,
                403,
                "{origin}"
            );
        }
        let post = head(&format!(
            "POST /?token={hex} HTTP/1.1\r\nHost: 127.0.0.1:1\r\n\r\n"
        ));
        assert_eq!(check(&post, &t, &rule).unwrap_err().status, 405);
        let other = get(&format!("/etc/passwd?token={hex}"), "127.0.0.1:1", "");
        assert_eq!(check(&other, &t, &rule).unwrap_err().status, 404);
        let nohost = head(&format!("GET /?token={hex} HTTP/1.1\r\n\r\n"));
        assert_eq!(check(&nohost, &t, &rule).unwrap_err().status, 400);
    }

    #[test]
    fn host_rules() {
        assert!(HostRule::Loopback.allows("[::1]:80"));
        assert!(HostRule::Loopback.allows("localhost"));
        assert!(!HostRule::Loopback.allows("10.0.0.2:80"));
        let lan = HostRule::LoopbackOr("10.0.0.2".into());
        assert!(lan.allows("10.0.0.2:8080") && lan.allows("127.0.0.1:1"));
        assert!(!lan.allows("10.0.0.3:8080"));
        assert!(HostRule::Any.allows("anything:1"));
    }
}
