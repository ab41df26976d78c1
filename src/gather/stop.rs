//! The corner gather's cancel, progress and allocation failures: the host asked at most every
//! [`POLL_INTERVAL`], shared by the flat gather and the hierarchy's.

use crate::error::{Error, Result};
use crate::system::Progress;

/// How often the gather asks the host whether to go on (and reports progress): every corner and
/// every step of a moment's subdivision looks at the flag, one of them calls the host when this
/// much time has passed, so a cancel is seen within about this long (the solve's is one batch).
const POLL_INTERVAL: std::time::Duration = std::time::Duration::from_millis(10);

/// The gather's cancel and progress: the host's callback, called at most every
/// [`POLL_INTERVAL`] from whichever thread looks first, and what it said.
pub(crate) struct Stop<'a> {
    progress: Progress<'a>,
    start: std::time::Instant,
    /// Microseconds after `start` of the last call of `progress`.
    last_poll: std::sync::atomic::AtomicU64,
    cancelled: std::sync::atomic::AtomicBool,
    /// Points gathered so far, of `total`.
    pub done: std::sync::atomic::AtomicUsize,
    total: usize,
    /// A row's allocation the allocator refused ([`crate::budget::try_vec`]): the gather stops
    /// (as cancelled) and returns it.
    failed: std::sync::Mutex<Option<Error>>,
}

impl<'a> Stop<'a> {
    /// The stop of a gather of `total` points.
    pub fn new(progress: Progress<'a>, total: usize) -> Self {
        Stop {
            progress,
            start: std::time::Instant::now(),
            last_poll: 0.into(),
            cancelled: false.into(),
            done: 0.into(),
            total,
            failed: None.into(),
        }
    }

    /// The gather's outcome once its rows are done: the allocation error that stopped it, else
    /// `Cancelled` when the host asked to stop (a cancel seen inside a row cut it short without
    /// an error), else `Ok`.
    pub fn outcome(&self) -> Result<()> {
        if let Some(e) = self.failed.lock().unwrap_or_else(|p| p.into_inner()).take() {
            return Err(e);
        }
        if self.cancelled.load(std::sync::atomic::Ordering::Relaxed) {
            return Err(Error::Cancelled);
        }
        Ok(())
    }

    /// Room for `len` values, or `None` after stopping the gather with the allocation's error.
    pub fn vec<T>(&self, len: usize) -> Option<Vec<T>> {
        crate::budget::try_vec(len, "the corner gather's rows")
            .map_err(|e| {
                self.failed.lock().unwrap_or_else(|p| p.into_inner()).get_or_insert(e);
                self.cancelled.store(true, std::sync::atomic::Ordering::Relaxed);
            })
            .ok()
    }

    /// Whether the host asked to stop; asks it again when [`POLL_INTERVAL`] has passed.
    pub fn stopped(&self) -> bool {
        use std::sync::atomic::Ordering::Relaxed;
        if self.cancelled.load(Relaxed) {
            return true;
        }
        // The clock is read on one call in 32 per thread: a step of `moments` costs more than
        // a flag load but can be cheaper than a clock read.
        thread_local!(static CALLS: std::cell::Cell<u32> = const { std::cell::Cell::new(0) });
        if CALLS.with(|c| {
            c.set(c.get().wrapping_add(1));
            c.get() % 32 != 0
        }) {
            return false;
        }
        let now = self.start.elapsed().as_micros() as u64;
        let last = self.last_poll.load(Relaxed);
        if now.saturating_sub(last) < POLL_INTERVAL.as_micros() as u64
            || self.last_poll.compare_exchange(last, now, Relaxed, Relaxed).is_err()
        {
            return false;
        }
        let fraction = self.done.load(Relaxed) as f64 / self.total.max(1) as f64;
        if !(self.progress)(fraction.min(1.0), "corner gather") {
            self.cancelled.store(true, Relaxed);
        }
        self.cancelled.load(Relaxed)
    }
}
