//! Ctrl-C (and SIGTERM, SIGHUP): the first asks the command to stop — a run ends at its next
//! sample and leaves no half-written output, `optimize` writes its best plan so far — and a
//! second stops at once, removing the outputs still under way. Either way the process exits
//! with status 130, as a shell reports an interrupted command.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Mutex;

/// Set by the first signal.
static REQUESTED: AtomicBool = AtomicBool::new(false);

/// The temporary files of outputs under way, removed by a second signal.
static PARTIALS: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

/// The exit status of an interrupted command (128 + SIGINT).
pub const STATUS: u8 = 130;

/// Installs the handler (once, before any work starts). A platform that refuses it leaves
/// the default: the signal ends the process.
pub fn install() {
    let _ = ctrlc::set_handler(|| {
        if REQUESTED.swap(true, Ordering::SeqCst) {
            remove_partials();
            std::process::exit(i32::from(STATUS));
        }
        eprintln!("interrupted: stopping (interrupt again to stop at once)");
    });
}

/// Whether a stop was asked for.
pub fn requested() -> bool {
    REQUESTED.load(Ordering::Relaxed)
}

/// `Err` with a sentence once a stop was asked for: a long loop calls it at each step.
pub fn check() -> Result<(), String> {
    if requested() {
        Err("interrupted".into())
    } else {
        Ok(())
    }
}

/// Registers a temporary output file, to be removed if the process is stopped at once.
pub fn remove_on_interrupt(path: &Path) {
    partials().push(path.to_path_buf());
}

/// Forgets a temporary file (renamed into place, or removed).
pub fn keep(path: &Path) {
    partials().retain(|p| p != path);
}

fn partials() -> std::sync::MutexGuard<'static, Vec<PathBuf>> {
    PARTIALS
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner())
}

fn remove_partials() {
    for path in partials().drain(..) {
        let _ = std::fs::remove_file(path);
    }
}
