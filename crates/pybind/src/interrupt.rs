//! Long calls run in pieces of whole steps, each with the GIL released, and Python's signal handlers run
//! between pieces: Ctrl-C raises KeyboardInterrupt within about `PIECE` of work, and what was done before
//! it (whole steps) is kept.

use std::time::{Duration, Instant};

use pyo3::prelude::*;

/// The work per piece: short enough that Ctrl-C is answered at once, long enough that releasing and
/// retaking the GIL between pieces costs nothing.
const PIECE: Duration = Duration::from_millis(50);

/// Runs `run(k)`, which does the next `k` units of work (steps), until `total` units are done. Pieces start
/// at one unit and grow (doubling) while they take under half of `PIECE`, shrink when they take more; between
/// pieces, with the GIL held, Python's signal handlers run, and an exception they raise stops the work there.
/// `run` must give the same result whatever the pieces (k steps then m steps = k + m steps).
pub fn in_pieces<F>(py: Python<'_>, total: u64, mut run: F) -> PyResult<()>
where
    F: FnMut(u64) -> PyResult<()> + Send,
{
    let (mut done, mut piece) = (0, 1u64);
    while done < total {
        let k = piece.min(total - done);
        let started = Instant::now();
        py.detach(|| run(k))?;
        done += k;
        if done == total {
            break;
        }
        py.check_signals()?;
        let took = started.elapsed();
        if took < PIECE / 2 {
            piece = piece.saturating_mul(2);
        } else if took > PIECE {
            piece = (piece / 2).max(1);
        }
    }
    Ok(())
}
