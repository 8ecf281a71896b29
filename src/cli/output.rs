//! The files `simulate` writes: each checked before the run starts (its directory exists, its
//! extension fits, it is neither the model nor another output), written to a temporary file
//! beside it, and renamed into place only when complete — a failed run leaves no half file
//! and never touches the model.

use std::path::{Path, PathBuf};

use plotters::drawing::DrawingAreaErrorKind;
use plotters_backend::DrawingErrorKind;
use plotters_bitmap::BitMapBackendError;

/// One output file under way.
pub struct OutputFile {
    path: PathBuf,
    temp: PathBuf,
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
        let Some(name) = path.file_name() else {
            return Err(format!("--{what} `{shown}` names no file"));
        };
        let dir = match path.parent() {
            Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
            _ => PathBuf::from("."),
        };
        if !dir.is_dir() {
            return Err(format!(
                "--{what} `{shown}`: the directory `{}` does not exist",
                dir.display()
            ));
        }
        if path.is_dir() {
            return Err(format!("--{what} `{shown}` is a directory"));
        }
        let resolved = resolve(path);
        if let Some(other) = taken.iter().find(|p| resolve(p) == resolved) {
            return Err(format!(
                "--{what} `{shown}` is the same file as `{}`: give each output its own path, apart from the model",
                other.display()
            ));
        }
        // The temporary keeps the extension: the image encoders choose the format by it.
        let mut temp_name = std::ffi::OsString::from(".");
        temp_name.push(name);
        temp_name.push(format!(".partial-{}", std::process::id()));
        if let Some(ext) = path.extension() {
            temp_name.push(".");
            temp_name.push(ext);
        }
        let temp = dir.join(temp_name);
        std::fs::File::create(&temp).map_err(|e| format!("cannot write `{shown}`: {e}"))?;
        Ok(OutputFile {
            path: path.to_path_buf(),
            temp,
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

    /// Moves the finished file into place.
    pub fn commit(mut self) -> Result<(), String> {
        std::fs::rename(&self.temp, &self.path)
            .map_err(|e| format!("cannot write `{}`: {e}", self.path.display()))?;
        self.done = true;
        Ok(())
    }
}

impl Drop for OutputFile {
    /// An output never committed (the run failed) leaves nothing behind.
    fn drop(&mut self) {
        if !self.done {
            let _ = std::fs::remove_file(&self.temp);
        }
    }
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
