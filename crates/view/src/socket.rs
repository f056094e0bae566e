//! One WebSocket read by one thread and written by two.
//!
//! The tab's reader thread blocks in tungstenite's `read` for the page's messages while its
//! worker thread sends frames. Both write through [`Outgoing`]: every `write` call takes its
//! lock and writes the whole buffer, and tungstenite hands whole frames to each call (its
//! out-buffer), so frames never interleave. The worker formats its frames with tungstenite's
//! own [`Frame`] encoder.

use std::io::{Read, Write};
use std::net::TcpStream;
use std::sync::Mutex;
use std::time::Duration;
use tungstenite::protocol::frame::Frame;
use tungstenite::protocol::frame::coding::{Data, OpCode};

/// How long a write may block on a client that does not read (then the tab closes).
pub(crate) const WRITE_TIMEOUT: Duration = Duration::from_secs(20);

/// The writing end of a connection, shared by its threads.
#[derive(Debug)]
pub(crate) struct Outgoing {
    stream: Mutex<TcpStream>,
}

impl Outgoing {
    /// The writing end of `stream` (a clone of the socket), with a write timeout.
    pub(crate) fn new(stream: TcpStream) -> std::io::Result<Outgoing> {
        stream.set_write_timeout(Some(WRITE_TIMEOUT))?;
        Ok(Outgoing {
            stream: Mutex::new(stream),
        })
    }

    /// Writes `bytes` whole, under the lock.
    pub(crate) fn write_all(&self, bytes: &[u8]) -> std::io::Result<()> {
        let mut s = self.stream.lock().unwrap_or_else(|e| e.into_inner());
        s.write_all(bytes)?;
        s.flush()
    }

    /// Sends one unmasked server frame holding a whole message.
    fn send(&self, payload: Vec<u8>, data: Data) -> std::io::Result<()> {
        let mut buf = Vec::with_capacity(payload.len() + 14);
        Frame::message(payload, OpCode::Data(data), true)
            .format(&mut buf)
            .map_err(std::io::Error::other)?;
        self.write_all(&buf)
    }

    /// Sends a text message.
    pub(crate) fn text(&self, text: &str) -> std::io::Result<()> {
        self.send(text.as_bytes().to_vec(), Data::Text)
    }

    /// Sends a binary message.
    pub(crate) fn binary(&self, bytes: Vec<u8>) -> std::io::Result<()> {
        self.send(bytes, Data::Binary)
    }

    /// Closes the socket both ways (wakes the reader).
    pub(crate) fn shutdown(&self) {
        let s = self.stream.lock().unwrap_or_else(|e| e.into_inner());
        let _ = s.shutdown(std::net::Shutdown::Both);
    }
}

/// The stream tungstenite reads: the bytes already read with the request head first, then the
/// socket; its writes go through the shared [`Outgoing`].
#[derive(Debug)]
pub(crate) struct SocketStream {
    prefix: Vec<u8>,
    at: usize,
    read: TcpStream,
    out: std::sync::Arc<Outgoing>,
}

impl SocketStream {
    /// A stream that first yields `prefix` (the request head and anything after it).
    pub(crate) fn new(prefix: Vec<u8>, read: TcpStream, out: std::sync::Arc<Outgoing>) -> Self {
        SocketStream {
            prefix,
            at: 0,
            read,
            out,
        }
    }
}

impl Read for SocketStream {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        if self.at < self.prefix.len() {
            let n = buf.len().min(self.prefix.len() - self.at);
            buf[..n].copy_from_slice(&self.prefix[self.at..self.at + n]);
            self.at += n;
            return Ok(n);
        }
        self.read.read(buf)
    }
}

impl Write for SocketStream {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.out.write_all(buf)?;
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}
