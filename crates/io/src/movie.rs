//! Movie output: a numbered PNG sequence, an animated GIF (one palette for the whole movie), an
//! animated PNG (APNG), or MP4/WebM/MKV/MOV by piping raw frames to `ffmpeg`. The format follows
//! the output path ([`MovieFormat::from_path`]). Every file appears whole or not at all: frames
//! of a sequence are written atomically one by one; GIF, APNG and video go to a temporary file
//! renamed at [`MovieWriter::finish`], and a writer dropped before that leaves nothing behind.
//!
//! Pixel values are those of [`crate::write_png`]: premultiplied linear RGBA composited over the
//! background, then linear (default) or sRGB-encoded code values.

use crate::atomic::write_atomic;
use crate::error::{IoError, Result};
use crate::image::{PngBitDepth, PngSettings, rgb_codes, write_png};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use volsplat_core::Image;

/// Largest total size of the frames a GIF or APNG movie holds in memory before encoding.
pub const MAX_BUFFERED_MOVIE_BYTES: u64 = 4 << 30;

/// Video containers handed to `ffmpeg`, by extension.
pub const VIDEO_EXTENSIONS: &[&str] = &["mp4", "webm", "mkv", "mov", "avi"];

/// How a movie is stored.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum MovieFormat {
    /// One PNG per frame; `pattern` holds one printf-style `%d` / `%0Nd` for the frame number
    /// (from 0).
    PngSequence {
        /// Path pattern, e.g. `frames/frame_%04d.png`.
        pattern: String,
    },
    /// An animated GIF (looping), one 256-colour palette for the whole movie.
    Gif,
    /// An animated PNG (looping), lossless, 8 or 16 bits.
    Apng,
    /// A video written by `ffmpeg` (the container follows the extension).
    Video,
}

impl MovieFormat {
    /// The format of an output path: a path with `%d` or `%0Nd` is a PNG sequence; an existing
    /// folder, a path ending in `/`, or one without extension is a folder of
    /// `frame_0000.png` …; `.gif`, `.png`/`.apng`, and [`VIDEO_EXTENSIONS`] otherwise.
    pub fn from_path(path: &Path) -> Result<MovieFormat> {
        let text = path.to_string_lossy();
        if frame_pattern_width(&text).is_some() {
            return Ok(MovieFormat::PngSequence {
                pattern: text.into_owned(),
            });
        }
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        if path.is_dir() || text.ends_with('/') || ext.is_none() {
            return Ok(MovieFormat::PngSequence {
                pattern: path.join("frame_%04d.png").to_string_lossy().into_owned(),
            });
        }
        match ext.as_deref() {
            Some("gif") => Ok(MovieFormat::Gif),
            Some("png" | "apng") => Ok(MovieFormat::Apng),
            Some(e) if VIDEO_EXTENSIONS.contains(&e) => Ok(MovieFormat::Video),
            _ => Err(IoError::invalid_argument(
                path,
                "movie output",
                "unsupported extension; use a folder or a %04d pattern (PNG frames), .gif, \
                 .png/.apng, or .mp4/.webm/.mkv/.mov/.avi (with ffmpeg)",
            )),
        }
    }
}

/// The zero-padding width of the first `%d` / `%0Nd` in `text`, if it has one.
fn frame_pattern_width(text: &str) -> Option<(usize, usize, usize)> {
    let start = text.find('%')?;
    let rest = &text[start + 1..];
    let digits: String = rest.chars().take_while(|c| c.is_ascii_digit()).collect();
    if rest[digits.len()..].starts_with('d') {
        let width = digits.parse().unwrap_or(0);
        Some((start, start + 1 + digits.len() + 1, width))
    } else {
        None
    }
}

/// The path of frame `n` of a sequence pattern.
pub fn sequence_path(pattern: &str, n: usize) -> PathBuf {
    match frame_pattern_width(pattern) {
        Some((a, b, width)) => {
            PathBuf::from(format!("{}{:0width$}{}", &pattern[..a], n, &pattern[b..]))
        }
        None => PathBuf::from(pattern),
    }
}

/// Settings of a movie.
#[derive(Debug, Clone, PartialEq)]
pub struct MovieSettings {
    /// Frames per second, in (0, 1000].
    pub fps: f64,
    /// Code values: bit depth (APNG and PNG frames; GIF and video are 8-bit), encoding and
    /// background, as for still PNGs.
    pub png: PngSettings,
    /// The `ffmpeg` program for videos (default `ffmpeg`, looked up on PATH).
    pub ffmpeg: PathBuf,
}

impl Default for MovieSettings {
    fn default() -> Self {
        MovieSettings {
            fps: 24.0,
            png: PngSettings::default(),
            ffmpeg: PathBuf::from("ffmpeg"),
        }
    }
}

enum Sink {
    Sequence { pattern: String },
    Buffered { gif: bool, frames: Vec<Vec<u8>> },
    Video { child: Child, tmp: PathBuf },
}

/// Writes the frames of one movie; see the module docs.
pub struct MovieWriter {
    path: PathBuf,
    width: usize,
    height: usize,
    frames_expected: usize,
    frames_written: usize,
    settings: MovieSettings,
    written: Vec<PathBuf>,
    sink: Option<Sink>,
}

impl MovieWriter {
    /// Starts a movie of `frames` frames of `width × height` pixels at `path` (format by
    /// [`MovieFormat::from_path`]). Checks everything that can be checked before rendering:
    /// the folder exists (a sequence's folder is created if its parent exists), the size and
    /// frame count fit, and `ffmpeg` starts for a video (a clear error names the missing
    /// program otherwise).
    pub fn create(
        path: impl AsRef<Path>,
        width: usize,
        height: usize,
        frames: usize,
        settings: &MovieSettings,
    ) -> Result<MovieWriter> {
        let path = path.as_ref();
        if width == 0 || height == 0 || width > 1 << 16 || height > 1 << 16 {
            return Err(IoError::invalid_argument(
                path,
                "frame size",
                format!("{width}×{height} pixels; movies need 1 to 65536 pixels per side"),
            ));
        }
        if frames == 0 {
            return Err(IoError::invalid_argument(
                path,
                "frames",
                "a movie needs ≥ 1 frame",
            ));
        }
        if !(settings.fps.is_finite() && settings.fps > 0.0 && settings.fps <= 1000.0) {
            return Err(IoError::invalid_argument(
                path,
                "fps",
                format!(
                    "{} frames per second; give a rate in (0, 1000]",
                    settings.fps
                ),
            ));
        }
        let format = MovieFormat::from_path(path)?;
        let sink = match format {
            MovieFormat::PngSequence { pattern } => {
                let first = sequence_path(&pattern, 0);
                if let Some(dir) = first.parent().filter(|d| !d.as_os_str().is_empty())
                    && !dir.is_dir()
                {
                    std::fs::create_dir(dir)
                        .map_err(|e| IoError::os(dir, "create the frames folder", e))?;
                }
                Sink::Sequence { pattern }
            }
            MovieFormat::Gif | MovieFormat::Apng => {
                check_parent(path)?;
                let gif = format == MovieFormat::Gif;
                let bytes_per = if !gif && settings.png.bits == PngBitDepth::Sixteen {
                    6
                } else {
                    3
                };
                let total = (width * height * bytes_per) as u64 * frames as u64;
                if total > MAX_BUFFERED_MOVIE_BYTES {
                    return Err(IoError::TooLarge {
                        path: path.to_path_buf(),
                        what: format!(
                            "{frames} frames of {width}×{height} held in memory for a GIF/APNG \
                             (write PNG frames or a video instead)"
                        ),
                        value: total as u128,
                        limit: MAX_BUFFERED_MOVIE_BYTES as u128,
                    });
                }
                Sink::Buffered {
                    gif,
                    frames: Vec::with_capacity(frames),
                }
            }
            MovieFormat::Video => {
                check_parent(path)?;
                let tmp = temp_sibling(path);
                let child = Command::new(&settings.ffmpeg)
                    .args(["-hide_banner", "-loglevel", "error", "-y", "-f", "rawvideo"])
                    .args(["-pixel_format", "rgb24", "-video_size"])
                    .arg(format!("{width}x{height}"))
                    .arg("-framerate")
                    .arg(format!("{}", settings.fps))
                    .args(["-i", "-", "-vf", "pad=ceil(iw/2)*2:ceil(ih/2)*2"])
                    .args(["-pix_fmt", "yuv420p"])
                    .arg(&tmp)
                    .stdin(Stdio::piped())
                    .stdout(Stdio::null())
                    .stderr(Stdio::piped())
                    .spawn()
                    .map_err(|e| {
                        if e.kind() == std::io::ErrorKind::NotFound {
                            IoError::invalid_argument(
                                path,
                                "movie output",
                                format!(
                                    "writing video needs the program `{}`, and it was not found \
                                     on PATH; install ffmpeg, or write a .gif, an animated .png, \
                                     or a folder of PNG frames",
                                    settings.ffmpeg.display()
                                ),
                            )
                        } else {
                            IoError::os(path, "start ffmpeg", e)
                        }
                    })?;
                Sink::Video { child, tmp }
            }
        };
        Ok(MovieWriter {
            path: path.to_path_buf(),
            width,
            height,
            frames_expected: frames,
            frames_written: 0,
            settings: settings.clone(),
            written: Vec::new(),
            sink: Some(sink),
        })
    }

    /// Adds the next frame (premultiplied linear RGBA, the movie's size).
    pub fn push(&mut self, image: &Image) -> Result<()> {
        if image.width() != self.width || image.height() != self.height {
            return Err(IoError::invalid_argument(
                &self.path,
                "frame size",
                format!(
                    "frame {} is {}×{}, the movie is {}×{}",
                    self.frames_written,
                    image.width(),
                    image.height(),
                    self.width,
                    self.height
                ),
            ));
        }
        if self.frames_written >= self.frames_expected {
            return Err(IoError::invalid_argument(
                &self.path,
                "frames",
                format!("more than the {} frames announced", self.frames_expected),
            ));
        }
        let n = self.frames_written;
        let png = self.settings.png.clone();
        match self.sink.as_mut() {
            Some(Sink::Sequence { pattern }) => {
                let p = sequence_path(pattern, n);
                write_png(&p, image, &png)?;
                self.written.push(p);
            }
            Some(Sink::Buffered { gif, frames }) => {
                let bits = if *gif { PngBitDepth::Eight } else { png.bits };
                let codes = rgb_codes(
                    image,
                    &PngSettings {
                        bits,
                        ..png.clone()
                    },
                );
                frames.push(match bits {
                    PngBitDepth::Eight => codes.iter().map(|&c| c as u8).collect(),
                    PngBitDepth::Sixteen => codes.iter().flat_map(|c| c.to_be_bytes()).collect(),
                });
            }
            Some(Sink::Video { child, .. }) => {
                let codes = rgb_codes(
                    image,
                    &PngSettings {
                        bits: PngBitDepth::Eight,
                        ..png.clone()
                    },
                );
                let bytes: Vec<u8> = codes.iter().map(|&c| c as u8).collect();
                let stdin = child.stdin.as_mut().ok_or_else(|| {
                    IoError::os(
                        &self.path,
                        "write to ffmpeg",
                        std::io::Error::other("no pipe"),
                    )
                })?;
                if let Err(e) = stdin.write_all(&bytes) {
                    let msg = ffmpeg_stderr(child);
                    return Err(IoError::os(
                        &self.path,
                        format!("write frame {n} to ffmpeg ({msg})"),
                        e,
                    ));
                }
            }
            None => {}
        }
        self.frames_written += 1;
        Ok(())
    }

    /// Finishes the movie and returns the files written (the frames of a sequence, or the one
    /// movie file). Errors if fewer frames were pushed than announced.
    pub fn finish(mut self) -> Result<Vec<PathBuf>> {
        if self.frames_written != self.frames_expected {
            return Err(IoError::invalid_argument(
                &self.path,
                "frames",
                format!(
                    "{} of the {} frames announced were given",
                    self.frames_written, self.frames_expected
                ),
            ));
        }
        let delay_s = 1.0 / self.settings.fps;
        match self.sink.take() {
            Some(Sink::Sequence { .. }) | None => Ok(std::mem::take(&mut self.written)),
            Some(Sink::Buffered { gif: true, frames }) => {
                write_gif(&self.path, self.width, self.height, &frames, delay_s)?;
                Ok(vec![self.path.clone()])
            }
            Some(Sink::Buffered { gif: false, frames }) => {
                write_apng(
                    &self.path,
                    self.width,
                    self.height,
                    &frames,
                    self.settings.fps,
                    &self.settings.png,
                )?;
                Ok(vec![self.path.clone()])
            }
            Some(Sink::Video { mut child, tmp }) => {
                drop(child.stdin.take());
                let status = child
                    .wait()
                    .map_err(|e| IoError::os(&self.path, "wait for ffmpeg", e))?;
                if !status.success() {
                    let msg = ffmpeg_stderr(&mut child);
                    let _ = std::fs::remove_file(&tmp);
                    return Err(IoError::invalid_argument(
                        &self.path,
                        "ffmpeg",
                        format!("exited with {status}: {msg}"),
                    ));
                }
                std::fs::rename(&tmp, &self.path).map_err(|e| {
                    let _ = std::fs::remove_file(&tmp);
                    IoError::os(&self.path, "rename temporary file", e)
                })?;
                Ok(vec![self.path.clone()])
            }
        }
    }
}

impl Drop for MovieWriter {
    fn drop(&mut self) {
        // A movie abandoned before `finish` leaves no partial video behind.
        if let Some(Sink::Video { mut child, tmp }) = self.sink.take() {
            let _ = child.kill();
            let _ = child.wait();
            let _ = std::fs::remove_file(tmp);
        }
    }
}

fn check_parent(path: &Path) -> Result<()> {
    match path.parent() {
        Some(d) if !d.as_os_str().is_empty() && !d.is_dir() => Err(IoError::invalid_argument(
            path,
            "movie output",
            format!("the folder {} does not exist", d.display()),
        )),
        _ => Ok(()),
    }
}

/// A temporary name next to `path` with the same extension (ffmpeg picks the container by it).
fn temp_sibling(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    path.with_file_name(format!(".tmp-{}-{name}", std::process::id()))
}

fn ffmpeg_stderr(child: &mut Child) -> String {
    use std::io::Read;
    let mut s = String::new();
    if let Some(mut e) = child.stderr.take() {
        let _ = e.read_to_string(&mut s);
    }
    let s = s.trim();
    if s.is_empty() {
        "no message".into()
    } else {
        s.chars().take(500).collect()
    }
}

/// Encodes RGB8 frames as a looping GIF with one NeuQuant palette (Dekker 1994) trained on
/// pixels from every frame, so colours do not flicker between frames.
fn write_gif(path: &Path, w: usize, h: usize, frames: &[Vec<u8>], delay_s: f64) -> Result<()> {
    // Train on at most ~2 M pixels spread over all frames.
    let total = frames.len() * w * h;
    let stride = total.div_ceil(2_000_000).max(1);
    let mut sample = Vec::with_capacity(4 * total.div_ceil(stride));
    let mut k = 0usize;
    for f in frames {
        for px in f.chunks_exact(3) {
            if k.is_multiple_of(stride) {
                sample.extend_from_slice(&[px[0], px[1], px[2], 255]);
            }
            k += 1;
        }
    }
    let nq = color_quant::NeuQuant::new(10, 256, &sample);
    let palette = nq.color_map_rgb();
    let delay = (delay_s * 100.0).round().clamp(1.0, u16::MAX as f64) as u16;
    let gif_err = |e: gif::EncodingError| match e {
        gif::EncodingError::Io(e) => IoError::os(path, "write", e),
        other => IoError::invalid_argument(path, "GIF", other.to_string()),
    };
    write_atomic(path, |out| {
        let mut enc = gif::Encoder::new(out, w as u16, h as u16, &palette).map_err(gif_err)?;
        enc.set_repeat(gif::Repeat::Infinite).map_err(gif_err)?;
        for f in frames {
            let indices: Vec<u8> = f
                .chunks_exact(3)
                .map(|p| nq.index_of(&[p[0], p[1], p[2], 255]) as u8)
                .collect();
            let frame = gif::Frame {
                width: w as u16,
                height: h as u16,
                delay,
                buffer: std::borrow::Cow::Owned(indices),
                ..gif::Frame::default()
            };
            enc.write_frame(&frame).map_err(gif_err)?;
        }
        Ok(())
    })
}

/// Encodes frames (RGB, 8 or 16 bits big-endian) as a looping APNG.
fn write_apng(
    path: &Path,
    w: usize,
    h: usize,
    frames: &[Vec<u8>],
    fps: f64,
    png_settings: &PngSettings,
) -> Result<()> {
    let png_err = |e: png::EncodingError| match e {
        png::EncodingError::IoError(e) => IoError::os(path, "write", e),
        other => IoError::Png {
            path: path.to_path_buf(),
            message: other.to_string(),
        },
    };
    // Frame delay num/den seconds with den ≤ 65535.
    let (num, den) = if fps >= 1.0 {
        (100u16, (fps * 100.0).round().min(u16::MAX as f64) as u16)
    } else {
        ((100.0 / fps).round().min(u16::MAX as f64) as u16, 100u16)
    };
    write_atomic(path, |out| {
        let mut enc = png::Encoder::new(out, w as u32, h as u32);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(match png_settings.bits {
            PngBitDepth::Eight => png::BitDepth::Eight,
            PngBitDepth::Sixteen => png::BitDepth::Sixteen,
        });
        if png_settings.srgb {
            enc.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
        } else {
            enc.set_source_gamma(png::ScaledFloat::new(1.0));
        }
        enc.set_animated(frames.len() as u32, 0).map_err(png_err)?;
        enc.set_frame_delay(num, den).map_err(png_err)?;
        let mut writer = enc.write_header().map_err(png_err)?;
        for f in frames {
            writer.write_image_data(f).map_err(png_err)?;
        }
        writer.finish().map_err(png_err)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(w: usize, h: usize, v: f32) -> Image {
        let mut img = Image::new(w, h);
        for (i, p) in img.pixels_mut().iter_mut().enumerate() {
            let x = (i % w) as f32 / w as f32;
            *p = [v * x, v * (1.0 - x), v, 1.0];
        }
        img
    }

    #[test]
    fn formats_follow_the_path() {
        let f = |p: &str| MovieFormat::from_path(Path::new(p));
        assert_eq!(f("a.gif").unwrap(), MovieFormat::Gif);
        assert_eq!(f("a.PNG").unwrap(), MovieFormat::Apng);
        assert_eq!(f("a.mp4").unwrap(), MovieFormat::Video);
        assert_eq!(
            f("out/f_%03d.png").unwrap(),
            MovieFormat::PngSequence {
                pattern: "out/f_%03d.png".into()
            }
        );
        assert!(matches!(
            f("frames/").unwrap(),
            MovieFormat::PngSequence { .. }
        ));
        assert!(matches!(
            f("frames").unwrap(),
            MovieFormat::PngSequence { .. }
        ));
        let e = f("a.jpg").unwrap_err().to_string();
        assert!(e.contains("a.jpg") && e.contains(".gif"), "{e}");
        assert_eq!(
            sequence_path("x/f_%04d.png", 7),
            PathBuf::from("x/f_0007.png")
        );
        assert_eq!(sequence_path("f%d.png", 12), PathBuf::from("f12.png"));
    }

    #[test]
    fn a_sequence_writes_every_frame_as_the_still_writer_would() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("frames");
        let s = MovieSettings::default();
        let mut m = MovieWriter::create(&out, 8, 6, 3, &s).unwrap();
        for n in 0..3 {
            m.push(&frame(8, 6, 0.3 * n as f32)).unwrap();
        }
        let files = m.finish().unwrap();
        assert_eq!(files.len(), 3);
        let still = dir.path().join("still.png");
        write_png(&still, &frame(8, 6, 0.3), &s.png).unwrap();
        assert_eq!(
            std::fs::read(&files[1]).unwrap(),
            std::fs::read(&still).unwrap()
        );
        assert!(files[2].ends_with("frame_0002.png"));
    }

    #[test]
    fn gif_and_apng_hold_every_frame_and_nothing_is_left_on_error() {
        let dir = tempfile::tempdir().unwrap();
        let s = MovieSettings {
            fps: 10.0,
            ..MovieSettings::default()
        };
        for name in ["m.gif", "m.png"] {
            let out = dir.path().join(name);
            let mut m = MovieWriter::create(&out, 10, 7, 4, &s).unwrap();
            for n in 0..4 {
                m.push(&frame(10, 7, 0.25 * n as f32)).unwrap();
            }
            // A frame of the wrong size is refused, naming it.
            let e = m.push(&frame(9, 7, 0.0)).unwrap_err().to_string();
            assert!(e.contains("9×7"), "{e}");
            m.finish().unwrap();
            let bytes = std::fs::read(&out).unwrap();
            if name.ends_with("gif") {
                let mut opts = gif::DecodeOptions::new();
                opts.set_color_output(gif::ColorOutput::RGBA);
                let mut dec = opts.read_info(std::io::Cursor::new(bytes)).unwrap();
                let mut n = 0;
                while let Some(f) = dec.read_next_frame().unwrap() {
                    assert_eq!((f.width, f.height, f.delay), (10, 7, 10));
                    n += 1;
                }
                assert_eq!(n, 4);
            } else {
                let dec = png::Decoder::new(std::io::Cursor::new(bytes));
                let reader = dec.read_info().unwrap();
                let anim = reader.info().animation_control.unwrap();
                assert_eq!(anim.num_frames, 4);
            }
        }
        // Too few frames: an error, and no file.
        let out = dir.path().join("short.gif");
        let mut m = MovieWriter::create(&out, 4, 4, 3, &s).unwrap();
        m.push(&frame(4, 4, 0.5)).unwrap();
        assert!(m.finish().is_err());
        assert!(!out.exists());
        let names: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        assert!(names.iter().all(|n| !n.contains("tmp")), "{names:?}");
    }

    #[cfg(unix)]
    #[test]
    fn video_frames_go_to_ffmpeg_and_a_missing_program_is_named() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().unwrap();
        // A stand-in for ffmpeg that stores its input in its last argument, the output file.
        let fake = dir.path().join("fake-ffmpeg");
        std::fs::write(&fake, "#!/bin/sh\nfor last; do :; done\ncat > \"$last\"\n").unwrap();
        std::fs::set_permissions(&fake, std::fs::Permissions::from_mode(0o755)).unwrap();
        let s = MovieSettings {
            ffmpeg: fake,
            ..MovieSettings::default()
        };
        let out = dir.path().join("m.mp4");
        let mut m = MovieWriter::create(&out, 6, 4, 2, &s).unwrap();
        m.push(&frame(6, 4, 0.5)).unwrap();
        m.push(&frame(6, 4, 1.0)).unwrap();
        m.finish().unwrap();
        let raw = std::fs::read(&out).unwrap();
        assert_eq!(raw.len(), 2 * 6 * 4 * 3);
        let want: Vec<u8> = rgb_codes(&frame(6, 4, 1.0), &s.png)
            .iter()
            .map(|&c| c as u8)
            .collect();
        assert_eq!(&raw[72..], &want[..]);
        let missing = MovieSettings {
            ffmpeg: dir.path().join("no-such-ffmpeg"),
            ..MovieSettings::default()
        };
        let e = MovieWriter::create(dir.path().join("n.mp4"), 6, 4, 2, &missing)
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("no-such-ffmpeg") && e.contains(".gif"), "{e}");
        // Abandoned before finish: no file, no temporary.
        let out = dir.path().join("gone.webm");
        let mut m = MovieWriter::create(&out, 6, 4, 2, &s).unwrap();
        m.push(&frame(6, 4, 0.5)).unwrap();
        drop(m);
        assert!(!out.exists());
        let names: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        assert!(names.iter().all(|n| !n.contains("tmp")), "{names:?}");
    }
}
