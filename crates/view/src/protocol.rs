//! The page ↔ server protocol over one WebSocket (docs/viewer.md, "Protocol").
//!
//! The page sends JSON text messages ([`ClientMessage`]), at most [`MAX_MESSAGE_BYTES`] each,
//! tagged by `type`, with unknown fields refused at any depth. The server answers with JSON text
//! ([`ServerMessage`]) and binary frames: a little-endian `u32` header length, the header as
//! JSON ([`FrameHeader`]), then the image bytes (JPEG previews, PNG final frames) or a file
//! (the turntable GIF).

use serde::{Deserialize, Serialize};
use volsplat::session::Event;

/// Largest client message, bytes. Larger ones get an error reply and change nothing.
pub const MAX_MESSAGE_BYTES: usize = 64 * 1024;

/// Most frames of a turntable the page may ask for.
pub const MAX_TURNTABLE_FRAMES: usize = 180;

/// A message from the page.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
pub enum ClientMessage {
    /// An input event; `seq` numbers the page's events (frames echo the latest applied).
    Event {
        /// The page's event number, increasing.
        seq: u64,
        /// The event.
        event: Event,
    },
    /// The page has shown frame `frame`: the server sends the next (one frame in flight).
    Ack {
        /// The frame's id.
        frame: u64,
    },
    /// Ask for the current scene (the JSON `volsplat render --scene` reads).
    SaveScene {},
    /// Ask for the PNG file of the latest final frame: the bytes `volsplat render` writes.
    Screenshot {},
    /// Render a turntable GIF of the current scene on the server.
    Turntable {
        /// Frames, 1..=[`MAX_TURNTABLE_FRAMES`].
        frames: usize,
        /// Degrees of the turn about the view-up axis (360: a closed loop), within ±3600.
        degrees: f64,
        /// Frames per second of the GIF, in (0, 100].
        fps: f64,
        /// Largest side of the GIF, pixels (16..=1024); the view's aspect ratio is kept.
        max_size: usize,
    },
    /// Stop a running turntable.
    Cancel {},
    /// Open a volume of the `--data-dir` folder by its listed name.
    Open {
        /// A name from the hello message's `volumes`.
        name: String,
    },
}

/// Why a client message was refused.
#[derive(Debug, Clone, PartialEq)]
pub struct Refusal {
    /// What is wrong, naming the field.
    pub message: String,
    /// The `seq` of a refused event, where the message is JSON that carries one (so the
    /// error reply names the event, as for events refused later).
    pub seq: Option<u64>,
}

/// Parses a client message: at most [`MAX_MESSAGE_BYTES`], UTF-8 JSON, a known `type`, every
/// field known (an unknown field anywhere is refused with its path), numbers in range for
/// the turntable and names without path separators for `open`. Never panics (fuzzed:
/// `fuzz/fuzz_targets/view_message.rs`).
pub fn parse_client_message(bytes: &[u8]) -> Result<ClientMessage, Refusal> {
    parse_checked(bytes).map_err(|mut r| {
        if bytes.len() <= MAX_MESSAGE_BYTES {
            r.seq = serde_json::from_slice::<serde_json::Value>(bytes)
                .ok()
                .filter(|v| v.get("type").and_then(|t| t.as_str()) == Some("event"))
                .and_then(|v| v.get("seq").and_then(|s| s.as_u64()));
        }
        r
    })
}

fn parse_checked(bytes: &[u8]) -> Result<ClientMessage, Refusal> {
    let refuse = |message: String| Err(Refusal { message, seq: None });
    if bytes.len() > MAX_MESSAGE_BYTES {
        return refuse(format!(
            "message of {} bytes; the limit is {MAX_MESSAGE_BYTES}",
            bytes.len()
        ));
    }
    let text = match std::str::from_utf8(bytes) {
        Ok(t) => t,
        Err(e) => return refuse(format!("not UTF-8 text: {e}")),
    };
    let msg: ClientMessage = match serde_json::from_str(text) {
        Ok(m) => m,
        Err(e) => return refuse(e.to_string()),
    };
    if let ClientMessage::Event { event, .. } = &msg {
        // Tagged enums parse their variants from a buffered copy, where only types that deny
        // unknown fields themselves can refuse them; the scene's own types accept unknown
        // fields (scene files warn about them), so parse those parts again, strictly.
        let value: serde_json::Value = serde_json::from_str(text).unwrap_or_default();
        let part = |key: &str| value.get("event").and_then(|e| e.get(key));
        match event {
            Event::SetTransferFunction { .. } => strict::<volsplat::TransferSpec>(
                part("transfer_function"),
                "event.transfer_function",
            )?,
            Event::SetQuality { .. } => {
                strict::<volsplat::Quality>(part("quality"), "event.quality")?
            }
            Event::SetCamera { .. } => {
                strict::<volsplat::core::Camera>(part("camera"), "event.camera")?
            }
            _ => {}
        }
    }
    check(&msg)?;
    Ok(msg)
}

/// Parses `value` as a `T`, refusing any field `T` does not know (named by its path under
/// `at`).
fn strict<T: serde::de::DeserializeOwned>(
    value: Option<&serde_json::Value>,
    at: &str,
) -> Result<(), Refusal> {
    let Some(value) = value else {
        return Ok(());
    };
    let mut unknown = Vec::new();
    let parsed: Result<T, _> =
        serde_ignored::deserialize(value, |path| unknown.push(path.to_string()));
    if let Err(e) = parsed {
        return Err(Refusal {
            message: format!("{at}: {e}"),
            seq: None,
        });
    }
    match unknown.first() {
        Some(path) => Err(Refusal {
            message: format!("unknown field `{at}.{}`", written_path(value, path)),
            seq: None,
        }),
        None => Ok(()),
    }
}

/// `path` (serde_ignored's, under `value`) as the page wrote it: serde_ignored marks the
/// content of an externally tagged enum variant with `?`, which is the variant's key (the one
/// key of the object there).
fn written_path(value: &serde_json::Value, path: &str) -> String {
    let mut at = Some(value);
    let mut out = Vec::new();
    for seg in path.split('.') {
        let here = at;
        let variant = here
            .and_then(|v| v.as_object())
            .filter(|obj| obj.len() == 1)
            .and_then(|obj| obj.iter().next());
        match (seg, variant) {
            ("?", Some((key, inner))) => {
                out.push(key.clone());
                at = Some(inner);
            }
            ("?", None) => {}
            _ => {
                out.push(seg.to_string());
                at = here.and_then(|v| match seg.parse::<usize>() {
                    Ok(i) if v.is_array() => v.get(i),
                    _ => v.get(seg),
                });
            }
        }
    }
    out.join(".")
}

/// The checks serde cannot express.
fn check(msg: &ClientMessage) -> Result<(), Refusal> {
    let refuse = |message: String| Err(Refusal { message, seq: None });
    match msg {
        ClientMessage::Turntable {
            frames,
            degrees,
            fps,
            max_size,
        } => {
            if !(1..=MAX_TURNTABLE_FRAMES).contains(frames) {
                return refuse(format!(
                    "turntable.frames: must be in 1..={MAX_TURNTABLE_FRAMES}, got {frames}"
                ));
            }
            if !(degrees.is_finite() && degrees.abs() <= 3600.0) {
                return refuse(format!(
                    "turntable.degrees: must be within ±3600, got {degrees}"
                ));
            }
            if !(fps.is_finite() && *fps > 0.0 && *fps <= 100.0) {
                return refuse(format!("turntable.fps: must be in (0, 100], got {fps}"));
            }
            if !(16..=1024).contains(max_size) {
                return refuse(format!(
                    "turntable.max_size: must be in 16..=1024, got {max_size}"
                ));
            }
        }
        ClientMessage::Open { name } if !is_plain_name(name) => {
            return refuse(format!(
                "open.name: `{}` is not a name from the volume list",
                name.escape_debug()
            ));
        }
        _ => {}
    }
    Ok(())
}

/// A file name without folders: no separators, no `..`, no control characters, not hidden,
/// 1 to 255 bytes.
pub fn is_plain_name(name: &str) -> bool {
    !name.is_empty()
        && name.len() <= 255
        && !name.starts_with('.')
        && !name
            .chars()
            .any(|c| c == '/' || c == '\\' || c.is_control())
}

/// What the server tells the page about the volume and the choices it offers, first thing on
/// a new connection.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Hello {
    /// The server's version.
    pub version: String,
    /// A label for the volume (its file name, or the phantom).
    pub volume: String,
    /// Samples per axis.
    pub dims: [usize; 3],
    /// Spacing per axis, world units.
    pub spacing: [f64; 3],
    /// World bounds of the voxel centres, lower and upper corner (world units, LPS for
    /// medical volumes).
    pub bounds: [[f64; 3]; 2],
    /// Smallest and largest value, data units.
    pub value_range: [f64; 2],
    /// Sample counts over `value_range` in equal bins (the transfer-function editor draws
    /// over it).
    pub histogram: Vec<u64>,
    /// Built-in transfer functions by name (`auto` first).
    pub presets: Vec<String>,
    /// Volumes of the `--data-dir` folder (empty without one).
    pub volumes: Vec<String>,
    /// The frame budget, ms.
    pub budget_ms: f64,
    /// Whether the image follows the page's view: the page sends `resize` events with its
    /// view's size in device pixels (each side at most `max_fit_side`). `false`: a fixed size
    /// (`--size`, a scene file's).
    #[serde(default)]
    pub fit: bool,
    /// Longest side, pixels, of a view that follows the page.
    #[serde(default)]
    pub max_fit_side: usize,
}

/// The scene as the page shows it: sent after every change.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct State {
    /// The full-quality request (`render --scene` reads it).
    pub request: volsplat::RenderRequest,
    /// The grey window of MIP, MinIP and X-ray, if set (the request's `output.window`).
    pub window: Option<[f32; 2]>,
    /// The transfer function in use, as points (data units), for the editor.
    pub transfer_function: Option<volsplat::core::TransferFunction>,
    /// The latest event applied.
    pub seq: u64,
}

/// A text message from the server.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum ServerMessage {
    /// First message of a connection.
    Hello(Box<Hello>),
    /// The scene changed.
    State(Box<State>),
    /// A message was refused or a render failed; nothing changed.
    Error {
        /// The event number, for an event.
        seq: Option<u64>,
        /// What is wrong.
        message: String,
    },
    /// Progress of a long job (loading, classifying, a final frame, a turntable).
    Progress {
        /// `load`, `classify`, `render`, `turntable`.
        stage: String,
        /// Fraction done, in [0, 1].
        fraction: f64,
    },
    /// The current scene, for "save scene".
    Scene {
        /// The request as `render --scene` reads it.
        request: Box<volsplat::RenderRequest>,
    },
    /// A note from the reader or the renderer (assumed spacing, a preset outside the data).
    Note {
        /// The text.
        message: String,
    },
    /// The final frame `frame`, already sent, shows every event up to `seq`: the events since
    /// it was sent changed nothing that is seen (a click without a drag, a release after the
    /// final frame, a refused event), so no new frame comes for them.
    Shown {
        /// The frame's id.
        frame: u64,
        /// The latest event it shows.
        seq: u64,
    },
}

/// The header of a binary message.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrameHeader {
    /// `frame` or `file`.
    #[serde(rename = "type")]
    pub kind: String,
    /// Frame number within the connection (acknowledge it with [`ClientMessage::Ack`]).
    pub id: u64,
    /// The latest event this frame shows.
    pub seq: u64,
    /// `preview` or `final`.
    pub quality: String,
    /// `jpeg`, `png` or `gif`.
    pub format: String,
    /// Image width and height, pixels.
    pub width: usize,
    /// Image height, pixels.
    pub height: usize,
    /// The full-quality frame's size the image stands for (previews are shown upscaled).
    pub view: [usize; 2],
    /// Render time, ms.
    pub render_ms: f64,
    /// Encoding time, ms.
    pub encode_ms: f64,
    /// Preview: height over the final frame's height.
    pub scale: f64,
    /// Preview: slab thickness over the final frame's.
    pub slab_factor: f64,
    /// Preview: the volume's pyramid level (0: the volume itself).
    pub volume_level: u8,
    /// MIP, MinIP and X-ray: the smallest and largest finite value of the frame.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub values_range: Option<[f32; 2]>,
    /// A file's name (`file` messages).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
}

/// A binary message: `u32` little-endian header length, header JSON, payload.
pub fn binary_message(header: &FrameHeader, payload: &[u8]) -> Vec<u8> {
    // Serialising a struct of numbers and strings cannot fail.
    let head = serde_json::to_vec(header).unwrap_or_default();
    let mut out = Vec::with_capacity(4 + head.len() + payload.len());
    out.extend_from_slice(&(head.len() as u32).to_le_bytes());
    out.extend_from_slice(&head);
    out.extend_from_slice(payload);
    out
}

/// Splits a binary message into its header and payload (the replay client and tests).
pub fn split_binary(message: &[u8]) -> Option<(FrameHeader, &[u8])> {
    let len = u32::from_le_bytes(message.get(..4)?.try_into().ok()?) as usize;
    let head = message.get(4..4usize.checked_add(len)?)?;
    let header = serde_json::from_slice(head).ok()?;
    Some((header, &message[4 + len..]))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A refused event names the field by the path the page wrote (no `?` for an enum's
    /// content) and carries the event's `seq`, as events refused later do; other refused
    /// messages carry none.
    #[test]
    fn refusals_name_the_path_and_the_events_seq() {
        let r = parse_client_message(
            br#"{"type":"event","seq":7,"event":{"type":"set_transfer_function",
                "transfer_function":{"function":{"color":[[0,0,0,0],[1,1,1,1]],
                "scalar_opacity":[[0,0],[1,1]],"bogus":1}}}}"#,
        )
        .unwrap_err();
        assert_eq!(r.seq, Some(7));
        assert!(
            r.message
                .contains("unknown field `event.transfer_function.function.bogus`"),
            "{}",
            r.message
        );
        assert!(!r.message.contains('?'), "{}", r.message);
        let r = parse_client_message(br#"{"type":"event","seq":8,"event":{"type":"nope"}}"#)
            .unwrap_err();
        assert_eq!(r.seq, Some(8));
        let r = parse_client_message(br#"{"type":"screenshot","bogus":1}"#).unwrap_err();
        assert_eq!(r.seq, None);
    }

    #[test]
    fn events_and_commands_parse() {
        let m = parse_client_message(
            br#"{"type":"event","seq":3,"event":{"type":"orbit","dx":1,"dy":2}}"#,
        )
        .unwrap();
        assert_eq!(
            m,
            ClientMessage::Event {
                seq: 3,
                event: Event::Orbit { dx: 1.0, dy: 2.0 }
            }
        );
        assert_eq!(
            parse_client_message(br#"{"type":"ack","frame":9}"#).unwrap(),
            ClientMessage::Ack { frame: 9 }
        );
        assert_eq!(
            parse_client_message(br#"{"type":"save_scene"}"#).unwrap(),
            ClientMessage::SaveScene {}
        );
        let tf = r#"{"type":"event","seq":1,"event":{"type":"set_transfer_function",
            "transfer_function":{"function":{"color":[[0,0,0,0],[100,1,1,1]],
            "scalar_opacity":[[0,0],[100,0.5]]}}}}"#;
        assert!(parse_client_message(tf.as_bytes()).is_ok());
    }

    #[test]
    fn unknown_fields_are_refused_at_any_depth_with_their_path() {
        let cases = [
            (r#"{"type":"ack","frame":1,"extra":2}"#, "extra"),
            (
                r#"{"type":"event","seq":1,"event":{"type":"zoom","factor":2,"f":1}}"#,
                "f",
            ),
            (
                r#"{"type":"event","seq":1,"event":{"type":"set_transfer_function",
                "transfer_function":{"function":{"color":[[0,0,0,0]],"scalar_opacity":[[0,0]],
                "colr":1}}}}"#,
                "colr",
            ),
            (
                r#"{"type":"event","seq":1,"event":{"type":"set_quality",
                "quality":{"antialias":"none","sharpness":3}}}"#,
                "sharpness",
            ),
            (
                r#"{"type":"event","seq":1,"event":{"type":"set_camera","camera":
                {"position":[0,0,1],"focal_point":[0,0,0],"view_up":[0,1,0],"fov":30}}}"#,
                "fov",
            ),
            (
                r#"{"type":"event","seq":1,"event":{"type":"set_crop","crop":
                {"min":[0,0,0],"max":[1,1,1],"unit":"voxels"}}}"#,
                "unit",
            ),
            (
                r#"{"type":"event","seq":1,"event":{"type":"set_clip","planes":
                [{"normal":[0,0,1],"offset":1,"side":1}]}}"#,
                "side",
            ),
        ];
        for (text, field) in cases {
            let e = parse_client_message(text.as_bytes()).unwrap_err().message;
            assert!(e.contains(field), "{text}: {e}");
        }
    }

    #[test]
    fn malformed_messages_are_refused_with_a_reason() {
        let big = format!(
            r#"{{"type":"save_scene","pad":"{}"}}"#,
            "x".repeat(MAX_MESSAGE_BYTES)
        );
        let cases: Vec<(&[u8], &str)> = vec![
            (b"", "EOF"),
            (b"{", "EOF"),
            (b"\xff\xfe", "UTF-8"),
            (br#"{"type":"launch"}"#, "unknown variant"),
            (br#"{"seq":1}"#, "type"),
            (
                br#"{"type":"event","seq":-1,"event":{"type":"reset"}}"#,
                "invalid value",
            ),
            (
                br#"{"type":"event","seq":1,"event":{"type":"zoom","factor":"2"}}"#,
                "invalid type",
            ),
            (
                br#"{"type":"turntable","frames":0,"degrees":360,"fps":10,"max_size":256}"#,
                "frames",
            ),
            (
                br#"{"type":"turntable","frames":10,"degrees":1e400,"fps":10,"max_size":256}"#,
                "number out of range",
            ),
            (
                br#"{"type":"turntable","frames":10,"degrees":360,"fps":0,"max_size":256}"#,
                "fps",
            ),
            (br#"{"type":"open","name":"../etc/passwd"}"#, "not a name"),
            (br#"{"type":"open","name":"a/b.nrrd"}"#, "not a name"),
            (br#"{"type":"open","name":".hidden"}"#, "not a name"),
            (big.as_bytes(), "limit"),
        ];
        for (bytes, why) in cases {
            let e = parse_client_message(bytes).unwrap_err().message;
            assert!(e.contains(why), "{:?}: {e}", String::from_utf8_lossy(bytes));
        }
    }

    #[test]
    fn binary_messages_round_trip() {
        let h = FrameHeader {
            kind: "frame".into(),
            id: 4,
            seq: 17,
            quality: "preview".into(),
            format: "jpeg".into(),
            width: 64,
            height: 48,
            view: [512, 384],
            render_ms: 12.5,
            encode_ms: 1.5,
            scale: 0.125,
            slab_factor: 1.0,
            volume_level: 0,
            values_range: None,
            name: None,
        };
        let m = binary_message(&h, b"\xff\xd8payload");
        let (back, payload) = split_binary(&m).unwrap();
        assert_eq!(back, h);
        assert_eq!(payload, b"\xff\xd8payload");
        assert!(split_binary(&m[..3]).is_none());
        assert!(split_binary(&[255, 255, 255, 255, b'{']).is_none());
    }
}
