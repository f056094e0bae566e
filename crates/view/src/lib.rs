//! # volsplat-view
//!
//! `volsplat view`: explore a volume from a browser, locally or through an SSH tunnel.
//!
//! - [`Viewer`]: a small HTTP and WebSocket server on `127.0.0.1` (a free port by default).
//!   [`Viewer::bind`] checks the settings, loads the volume and draws a 128-bit token;
//!   [`Viewer::url`] is the address to open (`http://127.0.0.1:PORT/?token=…`);
//!   [`Viewer::serve`] serves on the calling thread, [`Viewer::spawn`] on a background one.
//! - Each browser tab opens one WebSocket and gets its own
//!   [`Session`](volsplat::session::Session) (camera, transfer function, …); all tabs share one
//!   [`Renderer`](volsplat::Renderer), so the volume is loaded once and renders take turns.
//! - [`protocol`]: the messages (JSON text from the page, tagged by `type`, unknown fields
//!   refused; binary frames to it: JPEG previews, the PNG final frame that `volsplat render`
//!   writes for the same scene).
//! - [`replay`]: the latency benchmark's client: a recorded orbit or transfer-function drag
//!   replayed against a server, with input-to-frame latency, frame rate and preview PSNR.
//!
//! Security (docs/viewer.md): loopback unless [`ViewerSettings::allow_remote`]; the token on
//! every HTTP and WebSocket request, compared in constant time; the `Host` header checked
//! against DNS rebinding and the WebSocket's `Origin` against the page's own; messages capped
//! at [`protocol::MAX_MESSAGE_BYTES`] and validated (a refused message gets an error reply and
//! changes nothing); the page names volumes only from the `--data-dir` listing, never paths.
#![deny(missing_docs)]

mod assets;
pub mod error;
pub mod frames;
pub mod http;
pub mod protocol;
pub mod replay;
mod server;
mod socket;
mod tab;
pub mod token;
mod turntable;

pub use error::{Result, ViewError};
pub use server::{
    MAX_FIT_SIDE, MAX_PENDING_CONNECTIONS, StopHandle, Viewer, ViewerHandle, ViewerSettings,
    check_data_dir, list_volumes,
};
pub use turntable::gif_size;
