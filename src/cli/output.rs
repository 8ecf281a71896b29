//! The files the commands write: each checked before the run starts (its directory exists,
//! its extension fits, it is neither the model nor another output). A regular file (or a new
//! one) is written to a temporary file beside it and renamed into place only when complete —
//! a failed or interrupted run leaves no half file and never touches the model; a symbolic
//! link is followed, so the file it names is replaced and the link kept; a device, a FIFO or
//! a socket is written through, as `tee` or `cp` would, never replaced.

use std::path::{Path, PathBuf};

use plotters::drawing::DrawingAreaErrorKind;
use plotters_backend::DrawingErrorKind;
use plotters_bitmap::BitMapBackendError;

use super::interrupt;

/// One output file under way.
pub struct OutputFile {
    /// Where it is written: the temporary file, or the device itself.
    temp: PathBuf,
    /// The path renamed onto when complete (None: written through).
    target: Option<PathBuf>,
    /// The path as given, for messages.
    path: PathBuf,
    done: bool,
}

impl OutputFile {
    /// Checks `path` (given by option `--{what}`) and creates its temporary file, so a path
    /// that cannot be written fails now. `extension` is the one it must have, if any;
    /// `taken` are the model and the outputs already checked.
    pub fn new(
        path: &Path,
        what: &str,
        extension: Option<&str>,
        taken: &[&Path],
    ) -> Result<Self, String> {
        let shown = path.display();
        if let Some(ext) = extension {
            if !path
                .extension()
                .is_some_and(|e| e.eq_ignore_ascii_case(ext))
            {
                return Err(format!(
                    "--{what} `{shown}`: the file name must end in .{ext}"
                ));
            }
        }
        let resolved = resolve(path);
        if let Some(other) = taken.iter().find(|p| resolve(p) == resolved) {
            return Err(format!(
                "--{what} `{shown}` is the same file as `{}`: give each output its own path, apart from the model",
                other.display()
            ));
        }
        let target = follow_links(path).map_err(|e| format!("--{what} `{shown}`: {e}"))?;
        if let Ok(meta) = std::fs::metadata(&target) {
            if meta.is_dir() {
                return Err(format!("--{what} `{shown}` is a directory"));
            }
            if !meta.is_file() {
                // A device, FIFO or socket: written through, in place.
                return Ok(OutputFile {
                    temp: path.to_path_buf(),
                    target: None,
                    path: path.to_path_buf(),
                    done: false,
                });
            }
        }
        let temp =
            temporary_beside(&target).ok_or_else(|| format!("--{what} `{shown}` names no file"))?;
        let dir = temp.parent().unwrap_or(Path::new("."));
        if !dir.is_dir() {
            return Err(format!(
                "--{what} `{shown}`: the directory `{}` does not exist",
                dir.display()
            ));
        }
        std::fs::File::create(&temp).map_err(|e| format!("cannot write `{shown}`: {e}"))?;
        interrupt::remove_on_interrupt(&temp);
        Ok(OutputFile {
            temp,
            target: Some(target),
            path: path.to_path_buf(),
            done: false,
        })
    }

    /// Where to write while the run goes.
    pub fn temp(&self) -> &Path {
        &self.temp
    }

    /// The path the file will have.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Moves the finished file into place (a file written through is already there).
    pub fn commit(&mut self) -> Result<(), String> {
        if let Some(target) = &self.target {
            std::fs::rename(&self.temp, target)
                .map_err(|e| format!("cannot write `{}`: {e}", self.path.display()))?;
            interrupt::keep(&self.temp);
        }
        self.done = true;
        Ok(())
    }
}

impl Drop for OutputFile {
    /// An output never committed (the run failed) leaves nothing behind.
    fn drop(&mut self) {
        if !self.done && self.target.is_some() {
            let _ = std::fs::remove_file(&self.temp);
            interrupt::keep(&self.temp);
        }
    }
}

/// The file `path` names once its symbolic links are followed (the path itself where it is
/// none, or does not exist yet); a link to a missing file names that file.
fn follow_links(path: &Path) -> Result<PathBuf, String> {
    let mut at = path.to_path_buf();
    for _ in 0..40 {
        match std::fs::symlink_metadata(&at) {
            Ok(meta) if meta.file_type().is_symlink() => {
                let next = std::fs::read_link(&at).map_err(|e| e.to_string())?;
                at = match at.parent() {
                    Some(dir) if next.is_relative() => dir.join(next),
                    _ => next,
                };
            }
            _ => return Ok(at),
        }
    }
    Err("too many levels of symbolic links".into())
}

/// `.NAME.partial-PID.EXT` beside `target` (the extension kept: the image encoders choose
/// the format by it).
fn temporary_beside(target: &Path) -> Option<PathBuf> {
    let name = target.file_name()?;
    let dir = match target.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let mut temp_name = std::ffi::OsString::from(".");
    temp_name.push(name);
    temp_name.push(format!(".partial-{}", std::process::id()));
    if let Some(ext) = target.extension() {
        temp_name.push(".");
        temp_name.push(ext);
    }
    Some(dir.join(temp_name))
}

/// A path as the file system sees it: its directory resolved, so `x.csv` and `./x.csv` are
/// one file (the file itself need not exist).
fn resolve(path: &Path) -> PathBuf {
    if let Ok(p) = path.canonicalize() {
        return p;
    }
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    match (dir.canonicalize(), path.file_name()) {
        (Ok(d), Some(name)) => d.join(name),
        _ => path.to_path_buf(),
    }
}

/// An error of the drawing stack as a sentence (the bitmap backend's own `Display` is its
/// debug form, `ImageError(IoError(Os { … }))`).
pub trait Sentence {
    /// The error as a plain sentence.
    fn sentence(&self) -> String;
}

impl Sentence for String {
    fn sentence(&self) -> String {
        self.clone()
    }
}

impl Sentence for BitMapBackendError {
    fn sentence(&self) -> String {
        match self {
            BitMapBackendError::IOError(e) => e.to_string(),
            BitMapBackendError::ImageError(e) => e.to_string(),
            BitMapBackendError::GifEncodingError(e) => e.to_string(),
            BitMapBackendError::InvalidBuffer => "the picture buffer is invalid".into(),
        }
    }
}

impl Sentence for DrawingAreaErrorKind<BitMapBackendError> {
    fn sentence(&self) -> String {
        match self {
            DrawingAreaErrorKind::BackendError(DrawingErrorKind::DrawingError(b)) => b.sentence(),
            DrawingAreaErrorKind::BackendError(DrawingErrorKind::FontError(e)) => {
                format!("the font could not be used: {e}")
            }
            other => other.to_string(),
        }
    }
}

/// [`Sentence::sentence`] as a function, for `map_err`.
pub fn drawing_error(e: &dyn Sentence) -> String {
    e.sentence()
}
