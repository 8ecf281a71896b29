//! Memory asked for before it is taken: a run, a batch, a solve or a model's dense matrices
//! whose size is known in advance is checked against what the machine has free, so a request
//! too large is an error naming what and how much — not an abort in the allocator (which
//! Rust's `Vec` cannot report, and which would end a Python interpreter with it).

use crate::error::SimError;

/// The bytes this process may still take: the smaller of the system's available memory
/// (`MemAvailable` in `/proc/meminfo`) and its cgroup's remaining limit (a container's
/// memory cap), or None where neither can be read (then nothing is refused).
pub fn available() -> Option<f64> {
    let system = std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|text| {
            text.lines()
                .find_map(|l| l.strip_prefix("MemAvailable:"))
                .and_then(|rest| {
                    rest.trim()
                        .trim_end_matches("kB")
                        .trim()
                        .parse::<f64>()
                        .ok()
                })
        })
        .map(|kb| kb * 1024.0);
    let read = |path: &str| {
        std::fs::read_to_string(path)
            .ok()
            .and_then(|t| t.trim().parse::<f64>().ok())
    };
    let cgroup = match (
        read("/sys/fs/cgroup/memory.max"),
        read("/sys/fs/cgroup/memory.current"),
    ) {
        (Some(max), Some(current)) => Some((max - current).max(0.0)),
        _ => None,
    };
    match (system, cgroup) {
        (Some(a), Some(b)) => Some(a.min(b)),
        (a, b) => a.or(b),
    }
}

/// `Ok` if `bytes` fit in what is free (see [`available`]); else [`SimError::OutOfMemory`]
/// naming `what` (a phrase: "the run's 1e8 recorded samples of 5 numbers"), and `advice`.
pub fn check(bytes: f64, what: impl FnOnce() -> String, advice: &str) -> Result<(), SimError> {
    match available() {
        Some(free) if bytes > free => Err(SimError::OutOfMemory {
            what: what(),
            bytes,
            available: free,
            advice: advice.to_string(),
        }),
        _ => Ok(()),
    }
}
