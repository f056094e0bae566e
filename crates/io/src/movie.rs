//! Movie output: a numbered PNG sequence, an animated GIF (one palette for the whole movie), an
//! animated PNG (APNG), or MP4/WebM/MKV/MOV by piping raw frames to `ffmpeg`. The format follows
//! the output path ([`MovieFormat::from_path`]). Every file appears whole or not at all, and a
//! movie appears whole or not at all: the frames of a sequence are written to hidden temporary
//! files (`.frame_0000.png.tmp-PID`) and renamed into place at [`MovieWriter::finish`], which then
//! removes the frames of an earlier, longer run that the pattern names (so the folder holds
//! exactly this movie's frames); GIF, APNG and video go to a temporary file renamed at `finish`.
//! A writer dropped before `finish` (an error, a signal) leaves nothing behind and the previous
//! movie untouched.
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
#[non_exhaustive]
pub enum MovieFormat {
    /// One PNG per frame; `pattern`'s file name holds one printf-style `%0Nd` for the frame
    /// number (from 0).
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

/// Widest frame number a pattern may ask for: `%020d` holds any `u64`.
pub const MAX_PATTERN_WIDTH: usize = 20;

impl MovieFormat {
    /// The format of an output path. A file name holding `%0Nd` (N = 1 to
    /// [`MAX_PATTERN_WIDTH`], zero-padded: `%04d`) is a PNG sequence; only the file name is read,
    /// so a folder may hold `%` (`pct%dir/`). An existing folder, a path ending in `/`, or one
    /// without extension is a folder of `frame_0000.png` …; `.gif`, `.png`/`.apng`, and
    /// [`VIDEO_EXTENSIONS`] otherwise, where a `%` is only a character (`100%done.gif`). A `.png`
    /// name with `%d` or `%Nd` (not zero-padded) is refused as ambiguous: frames (`%04d`) or one
    /// animated PNG?
    pub fn from_path(path: &Path) -> Result<MovieFormat> {
        let text = path.to_string_lossy();
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let bad = |reason: String| IoError::invalid_argument(path, "movie output", reason);
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        let is_folder = path.is_dir() || text.ends_with('/') || ext.is_none();
        if !is_folder {
            match find_pattern(&name).map_err(bad)? {
                Some(Pattern::Padded { .. }) if ext.as_deref() != Some("png") => {
                    return Err(bad(format!(
                        "a `%0Nd` frame pattern writes PNG frames; end the name in .png \
                         (frame_%04d.png), or leave the `%` out for one .{} file",
                        ext.as_deref().unwrap_or_default()
                    )));
                }
                Some(Pattern::Padded { .. }) => {
                    return Ok(MovieFormat::PngSequence {
                        pattern: text.into_owned(),
                    });
                }
                Some(Pattern::Loose(p)) if matches!(ext.as_deref(), Some("png" | "apng")) => {
                    return Err(bad(format!(
                        "`{p}` in the file name: write a zero-padded `%04d` for numbered PNG \
                         frames (frame_%04d.png), or choose a name without `%…d` for one \
                         animated PNG"
                    )));
                }
                _ => {}
            }
        }
        if is_folder {
            return Ok(MovieFormat::PngSequence {
                pattern: path.join("frame_%04d.png").to_string_lossy().into_owned(),
            });
        }
        match ext.as_deref() {
            Some("gif") => Ok(MovieFormat::Gif),
            Some("png" | "apng") => Ok(MovieFormat::Apng),
            Some(e) if VIDEO_EXTENSIONS.contains(&e) => Ok(MovieFormat::Video),
            _ => Err(bad(
                "unsupported extension; use a folder or a %04d pattern (PNG frames), .gif, \
                 .png/.apng, or .mp4/.webm/.mkv/.mov/.avi (with ffmpeg)"
                    .into(),
            )),
        }
    }
}

/// A `%…d` in a file name.
#[derive(Debug, PartialEq)]
enum Pattern {
    /// `%0Nd`: bytes `start..end` of the name, frame numbers `width` digits wide.
    Padded {
        start: usize,
        end: usize,
        width: usize,
    },
    /// `%d` or `%Nd` without the zero: printf would pad with spaces, or not at all.
    Loose(String),
}

/// The frame pattern of a file name: the first `%0Nd` (at most one), else the first `%d` /
/// `%Nd`. Errors for two `%0Nd` or a width outside 1..=[`MAX_PATTERN_WIDTH`].
fn find_pattern(name: &str) -> std::result::Result<Option<Pattern>, String> {
    let mut padded = None;
    let mut loose = None;
    for (start, _) in name.match_indices('%') {
        let rest = &name[start + 1..];
        let digits = rest.bytes().take_while(u8::is_ascii_digit).count();
        if !rest[digits..].starts_with('d') {
            continue;
        }
        let end = start + 1 + digits + 1;
        let spec = &name[start..end];
        if digits >= 2 && rest.starts_with('0') {
            let width = rest[..digits]
                .parse::<usize>()
                .ok()
                .filter(|w| (1..=MAX_PATTERN_WIDTH).contains(w))
                .ok_or_else(|| {
                    format!(
                        "`{}`: a frame number is 1 to {MAX_PATTERN_WIDTH} digits wide",
                        spec.chars().take(24).collect::<String>()
                    )
                })?;
            if padded.is_some() {
                return Err(format!(
                    "`{name}` holds two frame patterns; give one `%0Nd`"
                ));
            }
            padded = Some(Pattern::Padded { start, end, width });
        } else if loose.is_none() {
            loose = Some(Pattern::Loose(spec.chars().take(24).collect()));
        }
    }
    Ok(padded.or(loose))
}

/// The folder, file-name prefix, width and suffix of a sequence pattern (its `%0Nd` in the file
/// name), if it has one.
fn split_pattern(pattern: &str) -> Option<(PathBuf, String, usize, String)> {
    let path = Path::new(pattern);
    let name = path.file_name()?.to_str()?;
    match find_pattern(name) {
        Ok(Some(Pattern::Padded { start, end, width })) => Some((
            path.parent().map(Path::to_path_buf).unwrap_or_default(),
            name[..start].to_string(),
            width,
            name[end..].to_string(),
        )),
        _ => None,
    }
}

/// The path of frame `n` of a sequence pattern (`frames/frame_%04d.png` → `frames/frame_0007.png`);
/// the pattern itself if its file name holds no `%0Nd`.
pub fn sequence_path(pattern: &str, n: usize) -> PathBuf {
    match split_pattern(pattern) {
        Some((dir, prefix, width, suffix)) => dir.join(format!("{prefix}{n:0width$}{suffix}")),
        None => PathBuf::from(pattern),
    }
}

/// The frame number of `name` if `pattern` would name it so (same prefix and suffix, and the
/// number written exactly as the pattern writes it).
fn frame_number(prefix: &str, width: usize, suffix: &str, name: &str) -> Option<usize> {
    let digits = name.strip_prefix(prefix)?.strip_suffix(suffix)?;
    if digits.is_empty() || !digits.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    let n: usize = digits.parse().ok()?;
    (format!("{n:0width$}") == digits).then_some(n)
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
    Sequence {
        pattern: String,
        /// Frames written so far, each to a hidden temporary file: (temporary, final).
        staged: Vec<(PathBuf, PathBuf)>,
        /// The frames folder, when this writer created it (removed again if left empty).
        created: Option<PathBuf>,
    },
    Buffered {
        gif: bool,
        frames: Vec<Vec<u8>>,
    },
    Video {
        child: Child,
        tmp: PathBuf,
    },
}

/// Writes the frames of one movie; see the module docs.
pub struct MovieWriter {
    path: PathBuf,
    width: usize,
    height: usize,
    frames_expected: usize,
    frames_written: usize,
    settings: MovieSettings,
    warnings: Vec<String>,
    sink: Option<Sink>,
}

/// The files of a finished movie.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct MovieFiles {
    /// The files written: the frames of a sequence in order, or the one movie file.
    pub written: Vec<PathBuf>,
    /// Frames of an earlier run, named by the same pattern beyond this movie's last frame, that
    /// were removed so that the folder holds exactly this movie.
    pub removed: Vec<PathBuf>,
}

impl MovieWriter {
    /// Starts a movie of `frames` frames of `width × height` pixels at `path` (format by
    /// [`MovieFormat::from_path`]). Checks everything that can be checked before rendering:
    /// the folder exists (a sequence's folder is created if its parent exists), the size and
    /// frame count fit, the background is in [0, 1], and `ffmpeg` starts for a video (a clear
    /// error names the missing program otherwise). A frame rate that the format cannot store
    /// exactly is kept as the nearest it can, and said in [`MovieWriter::warnings`].
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
        for (name, v) in ["red", "green", "blue"].iter().zip(settings.png.background) {
            if !(v.is_finite() && (0.0..=1.0).contains(&v)) {
                return Err(IoError::invalid_argument(
                    path,
                    "background",
                    format!("{name} is {v}; each component must be a linear value in [0, 1]"),
                ));
            }
        }
        let format = MovieFormat::from_path(path)?;
        let warnings = rate_warnings(&format, settings.fps);
        let sink = match format {
            MovieFormat::PngSequence { pattern } => {
                let first = sequence_path(&pattern, 0);
                let mut created = None;
                if let Some(dir) = first.parent().filter(|d| !d.as_os_str().is_empty())
                    && !dir.is_dir()
                {
                    std::fs::create_dir(dir)
                        .map_err(|e| IoError::os(dir, "create the frames folder", e))?;
                    created = Some(dir.to_path_buf());
                }
                Sink::Sequence {
                    pattern,
                    staged: Vec::new(),
                    created,
                }
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
            warnings,
            sink: Some(sink),
        })
    }

    /// What the format changes in the movie that the caller asked for (a GIF's frame rate
    /// clamped to 100 fps, say), one sentence each, for the user.
    pub fn warnings(&self) -> &[String] {
        &self.warnings
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
            Some(Sink::Sequence {
                pattern, staged, ..
            }) => {
                let p = sequence_path(pattern, n);
                let tmp = staging_path(&p);
                write_png(&tmp, image, &png)?;
                staged.push((tmp, p));
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

    /// Finishes the movie: moves a sequence's frames into place and removes the frames of an
    /// earlier run beyond this movie's last one, or encodes the GIF/APNG, or waits for
    /// `ffmpeg`; returns the files written and removed. Errors if fewer frames were pushed than
    /// announced (and then nothing is left behind).
    pub fn finish(mut self) -> Result<MovieFiles> {
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
        let one = |p: &Path| MovieFiles {
            written: vec![p.to_path_buf()],
            removed: Vec::new(),
        };
        match self.sink.take() {
            None => Ok(MovieFiles::default()),
            Some(Sink::Sequence {
                pattern, staged, ..
            }) => finish_sequence(&pattern, staged),
            Some(Sink::Buffered { gif: true, frames }) => {
                let delay = gif_delay(self.settings.fps);
                write_gif(&self.path, self.width, self.height, &frames, delay)?;
                Ok(one(&self.path))
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
                Ok(one(&self.path))
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
                Ok(one(&self.path))
            }
        }
    }
}

impl Drop for MovieWriter {
    fn drop(&mut self) {
        // A movie abandoned before `finish` leaves no partial video and no frames behind.
        match self.sink.take() {
            Some(Sink::Video { mut child, tmp }) => {
                let _ = child.kill();
                let _ = child.wait();
                let _ = std::fs::remove_file(tmp);
            }
            Some(Sink::Sequence {
                staged, created, ..
            }) => {
                for (tmp, _) in staged {
                    let _ = std::fs::remove_file(tmp);
                }
                if let Some(dir) = created {
                    // Only if empty: never anything the user put there meanwhile.
                    let _ = std::fs::remove_dir(dir);
                }
            }
            _ => {}
        }
    }
}

/// The hidden temporary file a sequence frame is written to until [`MovieWriter::finish`].
fn staging_path(frame: &Path) -> PathBuf {
    let name = frame
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    frame.with_file_name(format!(".{name}.tmp-{}", std::process::id()))
}

/// Moves the staged frames of a sequence into place, then removes the frames of an earlier run
/// that the pattern names beyond the last one.
fn finish_sequence(pattern: &str, staged: Vec<(PathBuf, PathBuf)>) -> Result<MovieFiles> {
    let mut written = Vec::with_capacity(staged.len());
    let mut rest = staged.into_iter();
    for (tmp, path) in rest.by_ref() {
        if let Err(e) = std::fs::rename(&tmp, &path) {
            let _ = std::fs::remove_file(&tmp);
            for (tmp, _) in rest {
                let _ = std::fs::remove_file(tmp);
            }
            return Err(IoError::os(&path, "move the frame into place", e));
        }
        written.push(path);
    }
    let mut removed = Vec::new();
    if let Some((dir, prefix, width, suffix)) = split_pattern(pattern) {
        let count = written.len();
        let folder = if dir.as_os_str().is_empty() {
            PathBuf::from(".")
        } else {
            dir.clone()
        };
        let entries =
            std::fs::read_dir(&folder).map_err(|e| IoError::os(&folder, "list the frames", e))?;
        let mut stale: Vec<(usize, PathBuf)> = entries
            .filter_map(|e| e.ok())
            .filter(|e| e.file_type().is_ok_and(|t| t.is_file()))
            .filter_map(|e| {
                let name = e.file_name().into_string().ok()?;
                let n = frame_number(&prefix, width, &suffix, &name)?;
                (n >= count).then(|| (n, dir.join(&name)))
            })
            .collect();
        stale.sort();
        for (_, p) in stale {
            std::fs::remove_file(&p).map_err(|e| IoError::os(&p, "remove an earlier frame", e))?;
            removed.push(p);
        }
    }
    Ok(MovieFiles { written, removed })
}

/// A GIF frame delay: whole hundredths of a second, 1 to 65535.
fn gif_delay(fps: f64) -> u16 {
    (100.0 / fps).round().clamp(1.0, u16::MAX as f64) as u16
}

/// An APNG frame delay `num/den` seconds (both u16, den > 0) as close to `1/fps` as they
/// hold: hundredths from 1 fps up to 655.35, thousandths of a frame above (exact for whole
/// rates up to 1000), whole seconds below 0.0015 fps (clamped at 65535 s).
fn apng_delay(fps: f64) -> (u16, u16) {
    let max = u16::MAX as f64;
    if fps >= 1.0 {
        if fps * 100.0 <= max {
            (100, (fps * 100.0).round() as u16)
        } else {
            (1, fps.round().min(max) as u16)
        }
    } else if 100.0 / fps <= max {
        ((100.0 / fps).round() as u16, 100)
    } else {
        ((1.0 / fps).round().clamp(1.0, max) as u16, 1)
    }
}

/// The warnings of a movie at `fps` in `format`: a frame rate the format cannot store.
fn rate_warnings(format: &MovieFormat, fps: f64) -> Vec<String> {
    let (played, what) = match format {
        MovieFormat::Gif => (
            100.0 / gif_delay(fps) as f64,
            "GIF frame delays are whole hundredths of a second from 0.01 to 655.35 s",
        ),
        MovieFormat::Apng => {
            let (num, den) = apng_delay(fps);
            (
                den as f64 / num as f64,
                "APNG frame delays are at most 65535 s",
            )
        }
        _ => return Vec::new(),
    };
    // Clamped, not merely rounded: off by more than a rounding of the delay can explain.
    let clamped = match format {
        MovieFormat::Gif => !(100.0 / u16::MAX as f64..=100.0).contains(&fps),
        _ => fps < 1.0 / u16::MAX as f64,
    };
    if clamped {
        vec![format!(
            "{what}: {fps} fps plays at {} fps (use an animated .png or a video for the rate \
             asked)",
            (played * 1e4).round() / 1e4
        )]
    } else {
        Vec::new()
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
fn write_gif(path: &Path, w: usize, h: usize, frames: &[Vec<u8>], delay: u16) -> Result<()> {
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
    let (num, den) = apng_delay(fps);
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
        assert_eq!(sequence_path("f%02d.png", 12), PathBuf::from("f12.png"));
        assert_eq!(sequence_path("f%02d.png", 123), PathBuf::from("f123.png"));
    }

    /// Issue 28: a `%` followed by `d` anywhere in the path made a PNG sequence (`100%done.gif`,
    /// `pct%dir/`), and `%100000d` panicked (format width out of range). Only a `%0Nd` in the
    /// file name is a pattern; ambiguous or impossible ones are errors naming the path.
    #[test]
    fn only_a_zero_padded_pattern_in_the_file_name_numbers_frames() {
        let f = |p: &str| MovieFormat::from_path(Path::new(p));
        assert_eq!(f("100%done.gif").unwrap(), MovieFormat::Gif);
        assert_eq!(f("out/50%d.mp4").unwrap(), MovieFormat::Video);
        assert_eq!(f("pct%dir/movie.gif").unwrap(), MovieFormat::Gif);
        assert_eq!(
            f("pct%dir/").unwrap(),
            MovieFormat::PngSequence {
                pattern: "pct%dir/frame_%04d.png".into()
            }
        );
        assert_eq!(
            sequence_path("pct%dir/frame_%04d.png", 7),
            PathBuf::from("pct%dir/frame_0007.png")
        );
        assert_eq!(
            sequence_path("a%05d/f_%03d.png", 7),
            PathBuf::from("a%05d/f_007.png")
        );
        assert_eq!(
            f("x/f_%020d.png").unwrap(),
            MovieFormat::PngSequence {
                pattern: "x/f_%020d.png".into()
            }
        );
        for (bad, words) in [
            ("f_%100000d.png", "zero-padded `%04d`"),
            ("f_%d.png", "zero-padded `%04d`"),
            ("100%done.png", "zero-padded `%04d`"),
            ("f_%0100000d.png", "1 to 20 digits"),
            ("f_%021d.png", "1 to 20 digits"),
            ("f_%04d.gif", "end the name in .png"),
            ("f_%04d_%03d.png", "two frame patterns"),
        ] {
            let e = f(bad).unwrap_err().to_string();
            assert!(e.contains(bad) && e.contains(words), "{bad}: {e}");
        }
    }

    fn names(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    /// Issue 28: re-running a shorter movie into a folder left the last run's later frames;
    /// the folder now holds exactly this movie's frames (other files are kept), and a movie
    /// abandoned half-way leaves the previous one whole and no temporary files.
    #[test]
    fn a_sequence_replaces_the_last_run_whole_or_not_at_all() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("frames");
        let s = MovieSettings::default();
        let run = |n: usize, v: f32| {
            let mut m = MovieWriter::create(&out, 4, 3, n, &s).unwrap();
            for _ in 0..n {
                m.push(&frame(4, 3, v)).unwrap();
            }
            m.finish().unwrap()
        };
        let first = run(5, 0.2);
        assert_eq!(first.written.len(), 5);
        assert!(first.removed.is_empty());
        std::fs::write(out.join("notes.txt"), b"mine").unwrap();
        std::fs::write(out.join("frame_00012.png"), b"not this pattern's").unwrap();
        let second = run(3, 0.9);
        assert_eq!(
            second.removed,
            vec![out.join("frame_0003.png"), out.join("frame_0004.png")]
        );
        assert_eq!(
            names(&out),
            [
                "frame_0000.png",
                "frame_0001.png",
                "frame_00012.png",
                "frame_0002.png",
                "notes.txt"
            ]
        );
        let want = std::fs::read(&second.written[0]).unwrap();
        // Abandoned after two of four frames: the previous movie is untouched, nothing staged
        // is left.
        let mut m = MovieWriter::create(&out, 4, 3, 4, &s).unwrap();
        m.push(&frame(4, 3, 0.5)).unwrap();
        m.push(&frame(4, 3, 0.5)).unwrap();
        assert!(names(&out).iter().any(|n| n.contains(".tmp-")));
        drop(m);
        assert_eq!(names(&out).len(), 5);
        assert!(names(&out).iter().all(|n| !n.contains("tmp")));
        assert_eq!(std::fs::read(out.join("frame_0000.png")).unwrap(), want);
        // A folder this writer created is removed again when the movie is abandoned.
        let fresh = dir.path().join("fresh");
        let mut m = MovieWriter::create(&fresh, 4, 3, 2, &s).unwrap();
        m.push(&frame(4, 3, 0.5)).unwrap();
        assert!(m.finish().is_err());
        assert!(!fresh.exists());
    }

    /// Issue 28: GIF and APNG frame delays clamped silently above 100 and 655 fps and below
    /// 1/655 fps. APNG now stores every rate in (1/65535, 1000] (whole rates exactly); what
    /// still clamps draws a warning.
    #[test]
    fn frame_rates_a_format_cannot_store_are_warned() {
        let dir = tempfile::tempdir().unwrap();
        let warn = |name: &str, fps: f64| {
            let s = MovieSettings {
                fps,
                ..MovieSettings::default()
            };
            MovieWriter::create(dir.path().join(name), 4, 4, 1, &s)
                .unwrap()
                .warnings()
                .to_vec()
        };
        for fps in [24.0, 100.0, 0.0016, 1.0] {
            assert!(warn("a.gif", fps).is_empty(), "{fps}");
        }
        let w = warn("a.gif", 240.0);
        assert!(
            w.len() == 1 && w[0].contains("240 fps plays at 100 fps"),
            "{w:?}"
        );
        let w = warn("a.gif", 0.001);
        assert!(
            w.len() == 1 && w[0].contains("0.001 fps plays at 0.0015 fps"),
            "{w:?}"
        );
        for fps in [1000.0, 655.0, 700.0, 1.0 / 655.0, 0.001, 1.0 / 60000.0] {
            assert!(warn("a.png", fps).is_empty(), "{fps}");
        }
        assert_eq!(apng_delay(1000.0), (1, 1000));
        assert_eq!(apng_delay(24.0), (100, 2400));
        assert_eq!(apng_delay(0.001), (1000, 1));
        let w = warn("a.apng", 1e-5);
        assert!(w.len() == 1 && w[0].contains("at most 65535 s"), "{w:?}");
        assert!(warn("frames/", 1000.0).is_empty());
    }

    #[test]
    fn a_background_outside_zero_to_one_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        for bg in [[f32::NAN, 0.0, 0.0], [2.0; 3]] {
            let s = MovieSettings {
                png: PngSettings {
                    background: bg,
                    ..PngSettings::default()
                },
                ..MovieSettings::default()
            };
            let out = dir.path().join("m.gif");
            let e = MovieWriter::create(&out, 4, 4, 1, &s)
                .err()
                .unwrap()
                .to_string();
            assert!(e.contains("red is") && e.contains("[0, 1]"), "{e}");
        }
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
        let files = m.finish().unwrap().written;
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
