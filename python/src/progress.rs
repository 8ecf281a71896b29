//! Long calls without the GIL: a batch runs on a thread of its own while the caller's thread
//! honours Ctrl-C and reports progress.

use std::sync::atomic::{AtomicBool, Ordering};

use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;
use tree_mech::runtime::batch::Watch;

/// Runs a batch (`run`, under `watch`) on a thread of its own with the GIL released, while
/// this thread waits for it: every 50 ms, and when it finishes, Ctrl-C is checked and
/// `progress(done, batch)` called with the GIL taken back for the moment. Ctrl-C or an
/// exception from `progress` stops the batch (`watch.stop`) and is returned.
pub(crate) fn watched<T: Send>(
    py: Python<'_>,
    run: impl FnOnce() -> T + Send,
    watch: &Watch,
    batch: usize,
    progress: Option<&Py<PyAny>>,
) -> PyResult<T> {
    let mut raised: Option<PyErr> = None;
    let result = py.detach(|| {
        let finished = AtomicBool::new(false);
        let waiting = std::thread::current();
        std::thread::scope(|scope| {
            let worker = scope.spawn(|| {
                let result = run();
                // Set before the wake-up: a wait that starts after it returns at once.
                finished.store(true, Ordering::Release);
                waiting.unpark();
                result
            });
            let mut reported = None;
            loop {
                let finished = finished.load(Ordering::Acquire);
                let done = watch.done.load(Ordering::Relaxed);
                let checked = Python::attach(|py| {
                    py.check_signals()?;
                    match progress {
                        Some(f) if reported != Some(done) => f.call1(py, (done, batch)).map(drop),
                        _ => Ok(()),
                    }
                });
                reported = Some(done);
                if let Err(e) = checked {
                    raised = Some(e);
                    watch.stop.store(true, Ordering::Relaxed);
                    break;
                }
                if finished {
                    break;
                }
                std::thread::park_timeout(std::time::Duration::from_millis(50));
            }
            worker.join()
        })
    });
    match (raised, result) {
        (Some(e), _) => Err(e),
        (None, Ok(result)) => Ok(result),
        (None, Err(_)) => Err(PyRuntimeError::new_err("a batch's thread panicked")),
    }
}
