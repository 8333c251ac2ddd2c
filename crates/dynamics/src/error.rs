//! The one error type of the crate: bad input, named by the argument it came from.

use std::fmt;

#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Error {
    /// An argument's value is out of its domain (non-finite, negative mass, non-physical inertia, ...).
    InvalidArgument { argument: &'static str, reason: String },
}

impl Error {
    pub fn invalid(argument: &'static str, reason: impl Into<String>) -> Self {
        Error::InvalidArgument { argument, reason: reason.into() }
    }

    pub fn argument(&self) -> &'static str {
        match self {
            Error::InvalidArgument { argument, .. } => argument,
        }
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::InvalidArgument { argument, reason } => write!(f, "{argument}: {reason}"),
        }
    }
}

impl std::error::Error for Error {}

pub type Result<T> = std::result::Result<T, Error>;
