//! The library's error type: one enum, each variant says what was wrong and where.

use std::fmt;

#[derive(Debug, Clone, PartialEq)]
pub enum Error {
    /// The input could not be read or parsed (file missing, malformed JSON).
    Input(String),
    /// The input parsed but is not a valid scene; the message names the object, face or field.
    InvalidScene(String),
    /// An argument of an API call is invalid (wrong length, out of range, null).
    InvalidArgument(String),
    /// The host asked to stop (progress callback or cancel flag).
    Cancelled,
    /// The bake's estimated memory is over the budget ([`crate::budget`]); the message gives
    /// both and what to change.
    OverBudget(String),
    /// A big allocation failed although the estimate was within the budget ([`crate::budget::try_vec`]);
    /// the message says what was being built and how much it asked for.
    OutOfMemory(String),
    /// A bug: a panic caught at the boundary, with its message.
    Internal(String),
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::Input(m) => write!(f, "cannot read input: {m}"),
            Error::InvalidScene(m) => write!(f, "invalid scene: {m}"),
            Error::InvalidArgument(m) => write!(f, "invalid argument: {m}"),
            Error::Cancelled => write!(f, "cancelled"),
            Error::OverBudget(m) => write!(f, "over the memory budget: {m}"),
            Error::OutOfMemory(m) => write!(f, "out of memory {m}"),
            Error::Internal(m) => write!(f, "internal error: {m}"),
        }
    }
}

impl std::error::Error for Error {}

pub type Result<T> = std::result::Result<T, Error>;

/// Shorthand for an `InvalidScene` error with a formatted message.
macro_rules! invalid_scene {
    ($($arg:tt)*) => { $crate::error::Error::InvalidScene(format!($($arg)*)) };
}
pub(crate) use invalid_scene;
