//! The one error type of the crate: bad input, named by the argument it came from, a size that cannot be
//! allocated, or a computation that failed on valid input (a diverging simulation).

use std::fmt;

/// Why a call failed; every fallible function of the crate returns it. Its `Display` is "argument: reason", the
/// message the Python bindings raise.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Error {
    /// An argument's value is out of its domain (non-finite, negative mass, non-physical inertia, ...).
    InvalidArgument {
        /// The argument's name, as the caller spells it.
        argument: &'static str,
        /// What is wrong with its value.
        reason: String,
    },
    /// A computation failed on valid input (`context` names it, e.g. "step"): a RuntimeError in Python.
    Numerical {
        /// The computation that failed.
        context: &'static str,
        /// How it failed.
        reason: String,
    },
    /// What the argument asks for cannot be allocated (the reason gives the size): a MemoryError in Python.
    TooLarge {
        /// The argument whose size it is.
        argument: &'static str,
        /// The size asked for.
        reason: String,
    },
}

impl Error {
    /// An [`Error::InvalidArgument`].
    pub fn invalid(argument: &'static str, reason: impl Into<String>) -> Self {
        Error::InvalidArgument { argument, reason: reason.into() }
    }

    /// An [`Error::Numerical`].
    pub fn numerical(context: &'static str, reason: impl Into<String>) -> Self {
        Error::Numerical { context, reason: reason.into() }
    }

    /// An [`Error::TooLarge`].
    pub fn too_large(argument: &'static str, reason: impl Into<String>) -> Self {
        Error::TooLarge { argument, reason: reason.into() }
    }

    /// The argument (or, for a numerical failure, the computation) the error is about.
    pub fn argument(&self) -> &'static str {
        match self {
            Error::InvalidArgument { argument, .. } | Error::Numerical { context: argument, .. } | Error::TooLarge { argument, .. } => argument,
        }
    }

    /// What went wrong, without the argument's name.
    pub fn reason(&self) -> &str {
        match self {
            Error::InvalidArgument { reason, .. } | Error::Numerical { reason, .. } | Error::TooLarge { reason, .. } => reason,
        }
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::InvalidArgument { argument, reason } | Error::Numerical { context: argument, reason } | Error::TooLarge { argument, reason } => {
                write!(f, "{argument}: {reason}")
            }
        }
    }
}

impl std::error::Error for Error {}

/// The crate's result type.
pub type Result<T> = std::result::Result<T, Error>;
