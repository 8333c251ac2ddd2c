//! Long calls run in pieces of whole steps, each with the GIL released, and Python's signal handlers run
//! between pieces: Ctrl-C raises KeyboardInterrupt within about `PIECE` of work, and what was done before
//! it (whole steps) is kept. Work that cannot be cut in pieces runs on a thread of its own (`on_worker`, or
//! `interruptible` for work that borrows from the caller and undoes itself when stopped).

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{self, RecvTimeoutError};
use std::sync::Arc;
use std::time::{Duration, Instant};

use legkit_dynamics::validate::cancellable;
use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;

/// The work per piece: short enough that Ctrl-C is answered at once, long enough that releasing and
/// retaking the GIL between pieces costs nothing.
const PIECE: Duration = Duration::from_millis(50);

/// The time one unit of work (a step) took last, kept by the object that does the work, so that a call
/// repeated with the same count (a control loop stepping 50 steps at a time) runs as one piece rather than
/// growing its pieces again each time (each piece wakes a batch's threads anew).
#[derive(Debug, Default)]
pub struct Pace(AtomicU64);

impl Pace {
    /// Units that fill about one `PIECE` (one until a unit has been timed).
    fn units_per_piece(&self) -> u64 {
        (PIECE.as_nanos() as u64).checked_div(self.0.load(Ordering::Relaxed)).map_or(1, |units| units.max(1))
    }

    /// Whether `units` take no more than one `PIECE` at the pace last measured (unknown: no, so a first call of a
    /// size not yet timed runs where Ctrl-C can stop it).
    pub fn fits_one_piece(&self, units: u64) -> bool {
        self.0.load(Ordering::Relaxed) != 0 && units <= self.units_per_piece()
    }

    pub fn record(&self, took: Duration, units: u64) {
        let unit = (took.as_nanos() / u128::from(units.max(1))).clamp(1, u128::from(u64::MAX)) as u64;
        self.0.store(unit, Ordering::Relaxed);
    }
}

/// Runs `run(k)`, which does the next `k` units of work (steps), until `total` units are done, in pieces of
/// about `PIECE` at the `pace` last measured (one unit first when it is not known yet); between pieces, with
/// the GIL held, Python's signal handlers run, and an exception they raise stops the work there.
/// `run` must give the same result whatever the pieces (k steps then m steps = k + m steps).
pub fn in_pieces<F>(py: Python<'_>, total: u64, pace: &Pace, mut run: F) -> PyResult<()>
where
    F: FnMut(u64) -> PyResult<()> + Send,
{
    // One step is one piece whatever the pace: not worth timing.
    if total == 1 {
        return py.detach(|| run(1));
    }
    let mut done = 0;
    while done < total {
        let k = pace.units_per_piece().min(total - done);
        let started = Instant::now();
        py.detach(|| run(k))?;
        pace.record(started.elapsed(), k);
        done += k;
        if done < total {
            py.check_signals()?;
        }
    }
    Ok(())
}

/// Python's signal handlers, run at most once a `PIECE` from a loop that holds the GIL and has no count of its work
/// to cut into pieces (rounds until a network falls silent).
pub struct SignalCheck(Instant);

impl Default for SignalCheck {
    fn default() -> Self {
        SignalCheck(Instant::now())
    }
}

impl SignalCheck {
    /// Runs the handlers if a `PIECE` has passed since they last ran; an exception they raise is returned.
    pub fn poll(&mut self, py: Python<'_>) -> PyResult<()> {
        if self.0.elapsed() >= PIECE {
            py.check_signals()?;
            self.0 = Instant::now();
        }
        Ok(())
    }
}

/// The stack of a worker: MJCF's passes recurse once per level of nesting, about 3 KB a level, up to
/// `mjcf::MAX_DEPTH` (1000) levels; reserved, and touched only as deep as a file nests.
const WORKER_STACK: usize = 16 << 20;

/// `work()` on a thread of its own, the caller waiting for it with the GIL released and running Python's
/// signal handlers every `PIECE`: for work that has no steps to stop between (loading a file). On Ctrl-C the
/// caller raises KeyboardInterrupt at once and cancels the work (`validate::cancellable`: the loaders check
/// the flag every few thousand elements and stop), whose result is dropped, so it must change nothing the
/// caller can see. A panic in it is a RuntimeError naming `what`.
pub fn on_worker<T, F>(py: Python<'_>, what: &str, work: F) -> PyResult<T>
where
    T: Send + 'static,
    F: FnOnce() -> T + Send + 'static,
{
    let (sender, mut receiver) = mpsc::channel();
    let cancel = Arc::new(AtomicBool::new(false));
    let flag = Arc::clone(&cancel);
    std::thread::Builder::new()
        .name(what.to_owned())
        .stack_size(WORKER_STACK)
        .spawn(move || {
            // The caller may have gone (interrupted): then nobody wants the result.
            let _ = sender.send(cancellable(flag, work));
        })
        .map_err(|e| PyRuntimeError::new_err(format!("{what}: cannot start a thread: {e}")))?;
    loop {
        let received;
        (receiver, received) = receive(py, receiver);
        match received {
            Ok(result) => return Ok(result),
            Err(RecvTimeoutError::Timeout) => py.check_signals().inspect_err(|_| cancel.store(true, Ordering::Relaxed))?,
            Err(RecvTimeoutError::Disconnected) => return Err(PyRuntimeError::new_err(format!("{what}: failed inside a dependency (a panic)"))),
        }
    }
}

/// `work(flag)` on a scoped thread of its own, so that it may borrow from the caller, which waits with the GIL released
/// and runs Python's signal handlers every `PIECE`, as in `on_worker`. On Ctrl-C the caller sets `flag` and waits for
/// the work to stop before raising KeyboardInterrupt: the work checks the flag between bounded units
/// (`validate::check_cancelled`; the worker runs under `cancellable(flag, ..)`, and work spread over other threads must
/// run under it there too) and must leave everything as it was when it stops. A panic in it is a RuntimeError naming
/// `what`.
pub fn interruptible<T, F>(py: Python<'_>, what: &str, work: F) -> PyResult<T>
where
    T: Send,
    F: FnOnce(&Arc<AtomicBool>) -> T + Send,
{
    let cancel = Arc::new(AtomicBool::new(false));
    let (sender, mut receiver) = mpsc::channel();
    std::thread::scope(|scope| {
        let flag = Arc::clone(&cancel);
        let worker = std::thread::Builder::new()
            .name(what.to_owned())
            .stack_size(WORKER_STACK)
            .spawn_scoped(scope, move || {
                let _ = sender.send(cancellable(Arc::clone(&flag), || work(&flag)));
            })
            .map_err(|e| PyRuntimeError::new_err(format!("{what}: cannot start a thread: {e}")))?;
        let mut interrupted = None;
        let result = loop {
            let received;
            (receiver, received) = receive(py, receiver);
            match received {
                Ok(result) => break Some(result),
                Err(RecvTimeoutError::Timeout) if interrupted.is_none() => {
                    interrupted = py.check_signals().inspect_err(|_| cancel.store(true, Ordering::Relaxed)).err();
                }
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => break None,
            }
        };
        // The worker has sent its result or panicked: it ends at once.
        let _ = py.detach(|| worker.join());
        match (interrupted, result) {
            (Some(interrupt), _) => Err(interrupt),
            (None, Some(result)) => Ok(result),
            (None, None) => Err(PyRuntimeError::new_err(format!("{what}: failed inside a dependency (a panic)"))),
        }
    })
}

/// What `receiver` brings within one `PIECE`, waited for with the GIL released; the receiver goes with the wait and
/// comes back (it may not be shared between threads, only moved).
fn receive<T: Send>(py: Python<'_>, receiver: mpsc::Receiver<T>) -> (mpsc::Receiver<T>, Result<T, RecvTimeoutError>) {
    py.detach(move || {
        let received = receiver.recv_timeout(PIECE);
        (receiver, received)
    })
}
