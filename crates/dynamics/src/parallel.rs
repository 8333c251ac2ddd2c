//! Batched kernels over rows on all cores, each thread with a workspace of its own, and cancellation between rows:
//! Pinocchio's `parallel/` (`abaInParallel`) and `ModelPool`, for the crate's users and its Python bindings alike.
//!
//! A batch is `n` rows of numbers, `width` per row, written by a kernel `kernel(state, i, row)` that sees row `i`
//! alone; [`map_rows`] spreads the rows over the calling thread and rayon's pool in tasks of [`ROWS_PER_TASK`] rows,
//! each thread with the `state` its `init` made (a [`Pooled`] `Data` from a [`DataPool`], typically). A failure names
//! the lowest failing row, whatever the scheduling; a cancellation flag, read between rows, stops the batch there.
//!
//! ```
//! use legkit_dynamics::parallel::{self, DataPool};
//! use legkit_dynamics::{Joint, JointLimits, MassProperties, Model, Transform};
//! use nalgebra::{Matrix3, Vector3};
//!
//! let link = MassProperties::solid_box(1.0, Vector3::new(0.1, 0.1, 0.4), Vector3::new(0.0, 0.0, 0.2), &Matrix3::identity()).unwrap();
//! let mut model = Model::new(false, link, "base");
//! model.add_body(0, Joint::Revolute(Vector3::y()), Transform::identity(), link, "link", JointLimits::NONE).unwrap();
//! let n = 1000;
//! let q: Vec<f64> = (0..n).map(|i| i as f64 / n as f64).collect();
//! let (v, tau) = (vec![0.0; n], vec![0.5; n]);
//! let mut ddq = vec![0.0; n];
//! let pool = DataPool::new(&model);
//! parallel::aba(&pool, &q, &v, &tau, &mut ddq, None).unwrap();
//! let mut data = legkit_dynamics::Data::new(&model);
//! assert_eq!(ddq[700], legkit_dynamics::algorithms::aba(&model, &mut data, &q[700..701], &[0.0], &[0.5], None).unwrap()[0]);
//! // A row's error names the row.
//! let mut bad = q.clone();
//! bad[400] = f64::NAN;
//! let error = parallel::aba(&pool, &bad, &v, &tau, &mut ddq, None).unwrap_err();
//! assert_eq!(error.to_string(), "q[400]: element 0 is not finite (NaN)");
//! ```
//!
//! A kernel of one's own on [`map_rows`], here the torque that holds each pose of that link (its centre of mass 0.2
//! m above the hinge) against gravity, each thread with a `Data` of the pool:
//!
//! ```
//! # use legkit_dynamics::parallel::{self, DataPool};
//! # use legkit_dynamics::{algorithms, Joint, JointLimits, MassProperties, Model, Transform};
//! # use nalgebra::{Matrix3, Vector3};
//! # let link = MassProperties::solid_box(1.0, Vector3::new(0.1, 0.1, 0.4), Vector3::new(0.0, 0.0, 0.2), &Matrix3::identity()).unwrap();
//! # let mut model = Model::new(false, link, "base");
//! # model.add_body(0, Joint::Revolute(Vector3::y()), Transform::identity(), link, "link", JointLimits::NONE).unwrap();
//! let (n, pool) = (1000, DataPool::new(&model));
//! let q: Vec<f64> = (0..n).map(|i| i as f64 / n as f64).collect();
//! let mut hold = vec![0.0; n];
//! let gravity = |data: &mut parallel::Pooled<'_, '_>, i: usize, row: &mut [f64]| {
//!     row.copy_from_slice(algorithms::rnea(&model, data.data(), &q[i..i + 1], &[0.0], &[0.0], None)?.as_slice());
//!     Ok(())
//! };
//! parallel::map_rows(&mut hold, 1, 0, || pool.take(), gravity, None).unwrap();
//! assert!(hold.iter().zip(&q).all(|(tau, angle)| (tau + 9.81 * 0.2 * angle.sin()).abs() < 1e-12));
//! ```
//!
//! Items of any kind on [`on_all_threads`], the outputs in the items' order, each task with its thread's state (here
//! a buffer each thread fills again for every item it takes):
//!
//! ```
//! use legkit_dynamics::parallel;
//!
//! let items: Vec<u64> = (0..1000).collect();
//! let sums = parallel::on_all_threads(items, Vec::new, |buffer: &mut Vec<u64>, _, n| {
//!     buffer.clear();
//!     buffer.extend(1..=n);
//!     buffer.iter().sum::<u64>()
//! });
//! assert!(sums.iter().zip(0_u64..).all(|(&sum, n)| sum == n * (n + 1) / 2));
//! ```

use std::fmt;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Mutex;

use crate::algorithms;
use crate::model::{Data, Model};
use crate::Error;

/// Rows per parallel task: large enough that a task's setup (a workspace taken from the pool) is amortised.
pub const ROWS_PER_TASK: usize = 64;

/// A batch's failure: the lowest row that failed and its error, or a cancellation before `row` (the rows before it
/// are done; see [`map_rows`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RowError {
    /// The row that failed (or the first not done when cancelled).
    pub row: usize,
    /// Why: the kernel's error, or `Error::Numerical` with context "batch" when cancelled.
    pub error: Error,
}

impl fmt::Display for RowError {
    /// `argument[row]: reason`, e.g. `q[4]: element 2 is not finite (NaN)`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}[{}]: {}", self.error.argument(), self.row, self.error.reason())
    }
}

impl std::error::Error for RowError {}

/// Per-thread workspaces of one model (Pinocchio's `ModelPool`): a thread takes a `Data` for a batch's tasks and
/// hands it back when done, so that repeated batches allocate nothing once the pool holds one per thread.
#[derive(Debug)]
pub struct DataPool<'m> {
    model: &'m Model,
    free: Mutex<Vec<Data>>,
}

impl<'m> DataPool<'m> {
    /// An empty pool for `model`: workspaces are made as threads first ask for them.
    pub fn new(model: &'m Model) -> Self {
        Self { model, free: Mutex::new(Vec::new()) }
    }

    /// The model the pool's workspaces are for.
    pub fn model(&self) -> &'m Model {
        self.model
    }

    /// A free workspace, or a new one; back to the pool when the [`Pooled`] is dropped.
    pub fn take(&self) -> Pooled<'_, 'm> {
        let free = self.free.lock().unwrap_or_else(|poisoned| poisoned.into_inner()).pop();
        Pooled { pool: self, data: Some(free.unwrap_or_else(|| Data::new(self.model))) }
    }
}

/// A workspace taken from a [`DataPool`], handed back to it when dropped.
#[derive(Debug)]
pub struct Pooled<'p, 'm> {
    pool: &'p DataPool<'m>,
    data: Option<Data>,
}

impl Pooled<'_, '_> {
    /// The workspace.
    pub fn data(&mut self) -> &mut Data {
        self.data.as_mut().expect("present until dropped")
    }
}

impl Drop for Pooled<'_, '_> {
    fn drop(&mut self) {
        if let Some(data) = self.data.take() {
            self.pool.free.lock().unwrap_or_else(|poisoned| poisoned.into_inner()).push(data);
        }
    }
}

/// Evaluates `kernel(state, i, row)` for each row of `out` (`width` numbers per row; row `i` is batch row `first + i`,
/// so that a batch may run in pieces), in tasks of [`ROWS_PER_TASK`] rows shared by the calling thread and rayon's
/// pool ([`on_all_threads`]; each thread with its own `state` from `init`). `cancel`, if given, is read before each
/// row: once set, no new row starts and the batch fails with the first row not done. A failure names the lowest
/// failing row, so the error does not depend on scheduling.
pub fn map_rows<S, I, K>(out: &mut [f64], width: usize, first: usize, init: I, kernel: K, cancel: Option<&AtomicBool>) -> Result<(), RowError>
where
    I: Fn() -> S + Sync,
    K: Fn(&mut S, usize, &mut [f64]) -> Result<(), Error> + Sync,
{
    if width == 0 {
        return Ok(());
    }
    let cancelled = || cancel.is_some_and(|flag| flag.load(Ordering::Relaxed));
    let first_failure = |state: &mut S, first_row: usize, rows: &mut [f64]| {
        rows.chunks_mut(width).enumerate().find_map(|(j, row)| {
            let i = first_row + j;
            if cancelled() {
                return Some(RowError { row: i, error: Error::numerical("batch", "cancelled") });
            }
            kernel(state, i, row).err().map(|error| RowError { row: i, error })
        })
    };
    let failure = if out.len() / width < 2 * ROWS_PER_TASK {
        first_failure(&mut init(), first, out)
    } else {
        let tasks: Vec<&mut [f64]> = out.chunks_mut(ROWS_PER_TASK * width).collect();
        let failures = on_all_threads(tasks, &init, |state, k, rows| first_failure(state, first + k * ROWS_PER_TASK, rows));
        failures.into_iter().flatten().min_by_key(|failure| failure.row)
    };
    failure.map_or(Ok(()), Err)
}

/// `task(state, k, item)` for every item `k`, on the calling thread and rayon's pool together, each taking the next
/// item no one has taken (each thread with its own `state` from `init`); the outputs in the items' order. The caller
/// starts at once: in a closed loop the pool's threads are asleep, and waking one costs 0.3-0.4 ms, so it joins for
/// whatever is left (handing all the work to the pool, as a parallel iterator does, waits for the wake-up first).
pub fn on_all_threads<T: Send, S, R: Send>(items: Vec<T>, init: impl Fn() -> S + Sync, task: impl Fn(&mut S, usize, T) -> R + Sync) -> Vec<R> {
    let slots: Vec<Mutex<(Option<T>, Option<R>)>> = items.into_iter().map(|item| Mutex::new((Some(item), None))).collect();
    let next = AtomicUsize::new(0);
    let work = || {
        let mut state = None;
        loop {
            let k = next.fetch_add(1, Ordering::Relaxed);
            let Some(slot) = slots.get(k) else { break };
            let mut slot = slot.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
            let item = slot.0.take().expect("each item is taken once");
            slot.1 = Some(task(state.get_or_insert_with(&init), k, item));
        }
    };
    rayon::in_place_scope(|scope| {
        for _ in 1..rayon::current_num_threads().min(slots.len()) {
            scope.spawn(|_| work());
        }
        work();
    });
    slots.into_iter().map(|slot| slot.into_inner().unwrap_or_else(|poisoned| poisoned.into_inner()).1.expect("every item is done")).collect()
}

/// `rows x width` numbers of `argument`, or an error naming it.
fn rows_of(argument: &'static str, x: &[f64], width: usize, rows: usize) -> Result<(), RowError> {
    if Some(x.len()) == width.checked_mul(rows) {
        return Ok(());
    }
    Err(RowError { row: 0, error: Error::invalid(argument, format!("expected {rows} rows of {width} numbers, got {} numbers", x.len())) })
}

/// Forward dynamics ([`algorithms::aba`], checked) of every row of `q` (nq numbers each), `v` and `tau` (nv each) into
/// the rows of `ddq`, on all cores with the pool's workspaces (Pinocchio's `abaInParallel`); `cancel` as in
/// [`map_rows`]. A row's error is its own (`q[4]: ...`); sizes that do not make whole rows fail at row 0.
pub fn aba(pool: &DataPool<'_>, q: &[f64], v: &[f64], tau: &[f64], ddq: &mut [f64], cancel: Option<&AtomicBool>) -> Result<(), RowError> {
    let model = pool.model();
    let (nq, nv) = (model.nq(), model.nv());
    // The rows counted on the output, or on q for a model without velocity coordinates.
    let rows = ddq.len().checked_div(nv).or_else(|| q.len().checked_div(nq)).unwrap_or(0);
    rows_of("q", q, nq, rows)?;
    rows_of("v", v, nv, rows)?;
    rows_of("tau", tau, nv, rows)?;
    map_rows(
        ddq,
        nv,
        0,
        || pool.take(),
        |data, i, out| {
            let (q, v, tau) = (&q[i * nq..(i + 1) * nq], &v[i * nv..(i + 1) * nv], &tau[i * nv..(i + 1) * nv]);
            out.copy_from_slice(algorithms::aba(model, data.data(), q, v, tau, None)?.as_slice());
            Ok(())
        },
        cancel,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Joint, JointLimits, MassProperties, Transform};
    use nalgebra::{Matrix3, Vector3};

    /// A floating chain of `n` boxes.
    fn chain(n: usize) -> Model {
        let body = MassProperties::solid_box(1.0, Vector3::new(0.1, 0.1, 0.3), Vector3::new(0.0, 0.0, 0.15), &Matrix3::identity()).unwrap();
        let mut model = Model::new(true, body, "base");
        for i in 1..=n {
            let axis = if i % 2 == 0 { Vector3::x() } else { Vector3::y() };
            model
                .add_body(
                    i - 1,
                    Joint::Revolute(axis),
                    Transform::from_translation(Vector3::new(0.0, 0.0, 0.3)),
                    body,
                    &format!("l{i}"),
                    JointLimits::NONE,
                )
                .unwrap();
        }
        model
    }

    /// `rows` states: the neutral configuration with joint angles and velocities that vary by row.
    fn states(model: &Model, rows: usize) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
        let (nq, nv) = (model.nq(), model.nv());
        let neutral = model.neutral();
        let mut q = Vec::with_capacity(rows * nq);
        for r in 0..rows {
            q.extend(neutral.iter().enumerate().map(|(k, x)| if k >= 7 { (0.37 * (r * nq + k) as f64).sin() } else { *x }));
        }
        let v = (0..rows * nv).map(|k| (0.11 * k as f64).cos()).collect();
        let tau = (0..rows * nv).map(|k| (0.05 * k as f64).sin()).collect();
        (q, v, tau)
    }

    #[test]
    fn a_parallel_batch_gives_the_serial_loops_numbers() {
        let model = chain(12);
        let rows = 3 * ROWS_PER_TASK + 5;
        let (q, v, tau) = states(&model, rows);
        let nv = model.nv();
        let mut parallel = vec![f64::NAN; rows * nv];
        aba(&DataPool::new(&model), &q, &v, &tau, &mut parallel, None).unwrap();
        let mut data = Data::new(&model);
        for r in 0..rows {
            let nq = model.nq();
            let serial =
                algorithms::aba(&model, &mut data, &q[r * nq..(r + 1) * nq], &v[r * nv..(r + 1) * nv], &tau[r * nv..(r + 1) * nv], None).unwrap();
            assert_eq!(&parallel[r * nv..(r + 1) * nv], serial.as_slice(), "row {r}");
        }
    }

    #[test]
    fn the_lowest_failing_row_is_named_whatever_the_scheduling() {
        let model = chain(3);
        let rows = 4 * ROWS_PER_TASK;
        let (mut q, v, tau) = states(&model, rows);
        let nq = model.nq();
        for bad in [rows - 3, ROWS_PER_TASK + 7, 2 * ROWS_PER_TASK] {
            q[bad * nq + 8] = f64::NAN;
        }
        let mut out = vec![0.0; rows * model.nv()];
        let failure = aba(&DataPool::new(&model), &q, &v, &tau, &mut out, None).unwrap_err();
        assert_eq!(failure.row, ROWS_PER_TASK + 7);
        assert_eq!(failure.error.argument(), "q");
        assert_eq!(failure.to_string(), format!("q[{}]: element 8 is not finite (NaN)", ROWS_PER_TASK + 7));
        let error = aba(&DataPool::new(&model), &q[1..], &v, &tau, &mut out, None).unwrap_err();
        assert_eq!((error.row, error.error.argument()), (0, "q"));
    }

    #[test]
    fn a_set_cancellation_flag_stops_the_batch_before_its_rows() {
        let model = chain(3);
        let rows = 4 * ROWS_PER_TASK;
        let (q, v, tau) = states(&model, rows);
        let mut out = vec![f64::NAN; rows * model.nv()];
        let failure = aba(&DataPool::new(&model), &q, &v, &tau, &mut out, Some(&AtomicBool::new(true))).unwrap_err();
        assert_eq!((failure.row, failure.error.argument()), (0, "batch"));
        assert!(out.iter().all(|x| x.is_nan()), "no row ran");
        // Set while the batch runs (by its 100th row): the rows after it do not run.
        let (flag, done) = (AtomicBool::new(false), AtomicUsize::new(0));
        let mut out = vec![0.0; rows];
        let failure = map_rows(
            &mut out,
            1,
            0,
            || (),
            |_, _, row| {
                if done.fetch_add(1, Ordering::Relaxed) == 99 {
                    flag.store(true, Ordering::Relaxed);
                }
                row[0] = 1.0;
                Ok(())
            },
            Some(&flag),
        )
        .unwrap_err();
        assert_eq!(failure.error.argument(), "batch");
        assert!(done.load(Ordering::Relaxed) < rows, "{} rows ran after the flag was set", done.load(Ordering::Relaxed));
    }

    #[test]
    fn the_pool_hands_its_workspaces_back() {
        let model = chain(2);
        let pool = DataPool::new(&model);
        drop(pool.take());
        drop(pool.take());
        assert_eq!(pool.free.lock().unwrap().len(), 1);
        let (a, b) = (pool.take(), pool.take());
        drop((a, b));
        assert_eq!(pool.free.lock().unwrap().len(), 2);
    }
}
