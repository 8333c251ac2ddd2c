//! Argument checks shared by the kernels and the bindings: each returns the value it accepts or an error
//! naming the argument.

use std::path::Path;

use nalgebra::{Matrix3, Vector3};

use crate::{Error, Result};

/// `value` if finite; an error on `argument` otherwise.
pub fn finite(argument: &'static str, value: f64) -> Result<f64> {
    if value.is_finite() {
        Ok(value)
    } else {
        Err(Error::invalid(argument, format!("must be finite, got {value}")))
    }
}

/// `v` if every component is finite; an error on `argument` otherwise.
pub fn finite_vector(argument: &'static str, v: Vector3<f64>) -> Result<Vector3<f64>> {
    if v.iter().all(|x| x.is_finite()) {
        Ok(v)
    } else {
        Err(Error::invalid(argument, format!("must be finite, got [{}, {}, {}]", v.x, v.y, v.z)))
    }
}

/// A finite, non-zero direction, returned normalised.
pub(crate) fn direction(argument: &'static str, v: Vector3<f64>) -> Result<Vector3<f64>> {
    let v = finite_vector(argument, v)?;
    let norm = v.norm();
    if norm > 0.0 && norm.is_finite() {
        Ok(v / norm)
    } else {
        Err(Error::invalid(argument, "must be a non-zero direction vector"))
    }
}

pub(crate) fn finite_matrix(argument: &'static str, m: &Matrix3<f64>) -> Result<()> {
    if m.iter().all(|x| x.is_finite()) {
        Ok(())
    } else {
        Err(Error::invalid(argument, "must be finite"))
    }
}

/// A proper rotation: orthonormal with determinant +1, to 1e-9.
pub(crate) fn rotation(argument: &'static str, r: &Matrix3<f64>) -> Result<()> {
    finite_matrix(argument, r)?;
    let orthogonality = (r.transpose() * r - Matrix3::identity()).abs().max();
    if orthogonality > 1e-9 || r.determinant() < 0.0 {
        return Err(Error::invalid(argument, format!("must be a rotation matrix (R^T R = I, det R = +1); |R^T R - I| = {orthogonality:.3e}")));
    }
    Ok(())
}

/// The number of elements of an array of `shape`, each `element_bytes` long, if it can exist at all (at
/// most `isize::MAX` bytes, as Rust and NumPy allow); `Error::TooLarge` naming `argument` otherwise.
pub fn array_len(argument: &'static str, shape: &[usize], element_bytes: usize) -> Result<usize> {
    let len = shape.iter().try_fold(1usize, |n, &d| n.checked_mul(d));
    match len.filter(|n| n.checked_mul(element_bytes).is_some_and(|b| b <= isize::MAX as usize)) {
        Some(len) => Ok(len),
        None => Err(Error::too_large(argument, format!("an array of shape {shape:?} is beyond any memory (more than {} bytes)", isize::MAX))),
    }
}

/// An empty vector with room for `len` values, or `Error::TooLarge` naming `argument` when the allocator
/// refuses them (where an infallible allocation would abort the process).
pub fn with_capacity<T>(argument: &'static str, len: usize) -> Result<Vec<T>> {
    let mut vec = Vec::new();
    vec.try_reserve_exact(len).map_err(|_| {
        let bytes = len.saturating_mul(std::mem::size_of::<T>());
        Error::too_large(argument, format!("cannot allocate {bytes} bytes ({len} values)"))
    })?;
    Ok(vec)
}

/// Whether `bytes` can be allocated now (they are reserved and freed at once, untouched): the check before
/// work that allocates infallibly (a dependency's) and that at most `bytes` bound.
pub fn headroom(bytes: usize) -> bool {
    Vec::<u8>::new().try_reserve_exact(bytes).is_ok()
}

/// `len` zeros, refused as `with_capacity` refuses them. Allocated zeroed (calloc): the system maps the pages as they
/// are first written, so a large output costs nothing until the work fills it, and work that stops early (Ctrl-C)
/// never pays for the rest; `filled` would write every zero first, seconds for gigabytes, before the work begins.
pub fn zeros(argument: &'static str, len: usize) -> Result<Vec<f64>> {
    // The allocator's answer, before `vec!`, which aborts on a refusal; below a megabyte a refusal is not a request's
    // doing, and a single call's output is spared a second allocation.
    if len > 1 << 17 {
        with_capacity::<f64>(argument, len)?;
    }
    Ok(vec![0.0; len])
}

/// `len` copies of `value`, allocated as `with_capacity` does.
pub fn filled<T: Clone>(argument: &'static str, len: usize, value: T) -> Result<Vec<T>> {
    let mut vec = with_capacity(argument, len)?;
    vec.resize(len, value);
    Ok(vec)
}

/// The bytes of the regular file at `path`; anything else (a FIFO, a device, a folder) is refused before it is
/// opened, as reading one may block forever or never end. A file too large for memory is `Error::TooLarge`.
pub(crate) fn read_regular_file(argument: &'static str, path: &Path) -> Result<Vec<u8>> {
    let fail = |reason: String| Error::invalid(argument, format!("{}: {reason}", path.display()));
    let metadata = std::fs::metadata(path).map_err(|e| fail(format!("cannot read it: {e}")))?;
    if !metadata.is_file() {
        return Err(fail("not a regular file".into()));
    }
    std::fs::read(path).map_err(|e| match e.kind() {
        std::io::ErrorKind::OutOfMemory => {
            Error::too_large(argument, format!("{}: cannot allocate {} bytes to read it", path.display(), metadata.len()))
        }
        _ => fail(format!("cannot read it: {e}")),
    })
}

thread_local! {
    /// The flag that cancels the work of this thread (`cancellable`), if any.
    static CANCEL: std::cell::RefCell<Option<std::sync::Arc<std::sync::atomic::AtomicBool>>> = const { std::cell::RefCell::new(None) };
}

/// Runs `work` on this thread so that `check_cancelled` fails once `flag` is set: a caller that stopped
/// waiting (Ctrl-C) ends work it no longer wants (loading a file) instead of letting it run to its end.
pub fn cancellable<T>(flag: std::sync::Arc<std::sync::atomic::AtomicBool>, work: impl FnOnce() -> T) -> T {
    let previous = CANCEL.with(|cancel| cancel.replace(Some(flag)));
    let result = work();
    CANCEL.with(|cancel| cancel.replace(previous));
    result
}

/// `Error::Numerical` (its context `what`) when this thread's work has been cancelled (see `cancellable`);
/// a relaxed atomic load, cheap enough to call every few thousand elements of a loop.
pub(crate) fn check_cancelled(what: &'static str) -> Result<()> {
    let cancelled = CANCEL.with(|cancel| cancel.borrow().as_ref().is_some_and(|flag| flag.load(std::sync::atomic::Ordering::Relaxed)));
    if cancelled {
        Err(Error::numerical(what, "cancelled (the caller was interrupted)"))
    } else {
        Ok(())
    }
}

/// Loop iterations between two `check_cancelled` calls in loaders: each iteration is a few microseconds at
/// most, so a cancelled load stops within milliseconds.
pub(crate) const CANCEL_INTERVAL: usize = 1024;
