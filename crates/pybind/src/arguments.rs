//! The pyo3 path every binding is generated against (`#[pyfunction(crate = "crate::arguments")]`, and
//! `#[pyo3(crate = "crate::arguments")]` on each `#[pymethods]`): pyo3 itself, except that an argument that
//! fails to convert raises an error whose message starts with the argument's name, "dt: must be real number,
//! not str". pyo3 names it only in a note ("while processing 'dt'"), which `str(e)` leaves out and Python 3.10,
//! the oldest the wheel supports, does not print. A bool given for a number is a TypeError too, as in the Python
//! layers: pyo3 reads `dt=True` as 1.0; so is a complex NumPy scalar, whose real part pyo3 would take.

pub use pyo3::*;

/// pyo3's macro support, with the argument extractors below in place of its own.
pub mod impl_ {
    pub use pyo3::impl_::*;

    /// The extractors the macros call for each argument: pyo3's, with [`named`] applied to their errors.
    pub mod extract_argument {
        pub use pyo3::impl_::extract_argument::*;

        use pyo3::exceptions::{PyOverflowError, PyTypeError, PyValueError};
        use pyo3::impl_::extract_argument as upstream;
        use pyo3::prelude::*;

        /// `error` with `name` prefixed to its message, unless the message already names it (the
        /// hand-written extractors do). Only TypeError, ValueError and OverflowError, whose message is their
        /// single argument, are reworded; any other error keeps pyo3's note.
        #[cold]
        fn named(py: Python<'_>, name: &str, error: PyErr) -> PyErr {
            let reworded =
                error.is_instance_of::<PyTypeError>(py) || error.is_instance_of::<PyValueError>(py) || error.is_instance_of::<PyOverflowError>(py);
            if !reworded {
                return upstream::argument_extraction_error(py, name, error);
            }
            let value = error.value(py);
            let message = value.str().map(|m| m.to_string()).unwrap_or_default();
            let names_it = message.strip_prefix(name).is_some_and(|rest| !rest.starts_with(|c: char| c.is_alphanumeric() || c == '_'));
            if !names_it && value.setattr("args", (format!("{name}: {message}"),)).is_err() {
                return upstream::argument_extraction_error(py, name, error);
            }
            error
        }

        pub fn extract_argument<'a, 'holder, 'py, T, const F: bool>(
            obj: Borrowed<'a, 'py, PyAny>, holder: &'holder mut T::Holder, arg_name: &str,
        ) -> PyResult<T>
        where
            T: PyFunctionArgument<'a, 'holder, 'py, F>,
        {
            if is_number::<T>() {
                if let Some(kind) = crate::convert::not_real(&obj) {
                    return Err(PyTypeError::new_err(format!("{arg_name}: expected a real number, got {kind}")));
                }
            }
            T::extract(obj, holder).map_err(|e| named(obj.py(), arg_name, e.into()))
        }

        /// Whether `T` is a number type (or an optional one), which pyo3 would fill from a bool or a complex NumPy scalar.
        fn is_number<T>() -> bool {
            let name = std::any::type_name::<T>();
            let name = name.strip_prefix("core::option::Option<").and_then(|n| n.strip_suffix('>')).unwrap_or(name);
            matches!(name, "f64" | "f32" | "usize" | "u64" | "u32" | "i64" | "i32")
        }

        pub fn extract_required_argument<'a, 'holder, 'py, T, const F: bool>(
            obj: Option<Borrowed<'a, 'py, PyAny>>, holder: &'holder mut T::Holder, arg_name: &str,
        ) -> PyResult<T>
        where
            T: PyFunctionArgument<'a, 'holder, 'py, F>,
        {
            match obj {
                Some(obj) => extract_argument(obj, holder, arg_name),
                // pyo3 has checked that every required argument is present before extracting any.
                None => upstream::extract_required_argument(obj, holder, arg_name),
            }
        }

        pub fn extract_argument_with_default<'a, 'holder, 'py, T, const F: bool>(
            obj: Option<Borrowed<'a, 'py, PyAny>>, holder: &'holder mut T::Holder, arg_name: &str, default: fn() -> T,
        ) -> PyResult<T>
        where
            T: PyFunctionArgument<'a, 'holder, 'py, F>,
        {
            match obj {
                Some(obj) => extract_argument(obj, holder, arg_name),
                None => Ok(default()),
            }
        }
    }
}
