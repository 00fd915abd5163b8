//! The one error type of the core. Every message names the parameter, what was expected and what
//! was given, so that the Python layer can show it unchanged.

use crate::report::SolveReport;
use std::fmt;

pub type Result<T> = std::result::Result<T, Error>;

#[derive(Debug, Clone)]
pub enum Error {
    /// An array has the wrong length or shape.
    Shape {
        param: String,
        expected: String,
        given: String,
    },
    /// A value that must be finite is NaN or infinite.
    NonFinite {
        param: String,
        index: usize,
        value: f64,
    },
    /// An index refers past the end of what it indexes.
    IndexOutOfRange {
        param: String,
        position: usize,
        index: i64,
        len: usize,
    },
    /// A tetrahedron with (numerically) zero volume.
    DegenerateTet {
        tet: usize,
        volume: f64,
        threshold: f64,
    },
    /// A tetrahedron with negative volume when reorientation was not allowed.
    InvertedTet { tet: usize, volume: f64 },
    /// A scalar or option outside its admissible range.
    InvalidParameter {
        param: String,
        expected: String,
        given: String,
    },
    /// Newton did not reach the tolerance; the report holds the residual history.
    NotConverged {
        message: String,
        report: Box<SolveReport>,
    },
    /// A linear solve is impossible: the sparse analysis or factorisation failed (out of
    /// memory, a bad elimination order), or a matrix that must be definite is not: the
    /// projected Hessian in Newton (a body free to move rigidly, a free cable node held by no
    /// taut segment) or the Hessian at an equilibrium for sensitivities (an unstable one).
    /// An indefinite exact Hessian during Newton is no error: Newton falls back to the
    /// projected one.
    LinearSolver { message: String },
    /// The solve was asked to stop ([`crate::newton::NewtonOptions::interrupt`]); the report
    /// holds what it did until then.
    Interrupted { report: Box<SolveReport> },
}

impl Error {
    pub fn shape(param: &str, expected: impl Into<String>, given: impl Into<String>) -> Self {
        Error::Shape {
            param: param.into(),
            expected: expected.into(),
            given: given.into(),
        }
    }

    pub fn invalid(param: &str, expected: impl Into<String>, given: impl fmt::Display) -> Self {
        Error::InvalidParameter {
            param: param.into(),
            expected: expected.into(),
            given: given.to_string(),
        }
    }

    /// The error of a per-tet value, saying which tet: `given` gains " at tet {e}".
    pub fn at_tet(self, e: usize) -> Self {
        match self {
            Error::InvalidParameter {
                param,
                expected,
                given,
            } => Error::InvalidParameter {
                param,
                expected,
                given: format!("{given} at tet {e}"),
            },
            other => other,
        }
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::Shape { param, expected, given } => {
                write!(f, "`{param}`: expected {expected}, given {given}")
            }
            Error::NonFinite { param, index, value } => {
                write!(f, "`{param}`: expected finite values, given {value} at flat index {index}")
            }
            Error::IndexOutOfRange { param, position, index, len } => write!(
                f,
                "`{param}`: expected indices in 0..{len}, given {index} at position {position}"
            ),
            Error::DegenerateTet { tet, volume, threshold } => write!(
                f,
                "`tets`: tetrahedron {tet} is degenerate: volume {volume:.3e} m^3, expected |volume| > {threshold:.3e} m^3"
            ),
            Error::InvertedTet { tet, volume } => write!(
                f,
                "`tets`: tetrahedron {tet} is inverted (volume {volume:.3e} m^3 < 0); expected positive orientation \
                 (pass orientation=\"reorient\" to fix it automatically)"
            ),
            Error::InvalidParameter { param, expected, given } => {
                write!(f, "`{param}`: expected {expected}, given {given}")
            }
            Error::NotConverged { message, .. } => write!(f, "{message}"),
            Error::LinearSolver { message } => write!(f, "sparse solver: {message}"),
            Error::Interrupted { report } => write!(f, "{}", report.message),
        }
    }
}

impl std::error::Error for Error {}

/// Checks that every value is finite; `param` names the array in the error.
pub fn check_finite(param: &str, values: &[f64]) -> Result<()> {
    match values.iter().position(|v| !v.is_finite()) {
        Some(index) => Err(Error::NonFinite {
            param: param.into(),
            index,
            value: values[index],
        }),
        None => Ok(()),
    }
}
