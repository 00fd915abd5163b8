//! The one mapping from the core's error enum (and from a panic, which would be a bug) onto the
//! exception classes of `sorofem.errors`.

use pyo3::prelude::*;
use pyo3::sync::PyOnceLock;
use pyo3::types::{PyDict, PyTuple, PyType};
use sorofem_core::{Error, SolveReport, Timings};
use std::panic::{catch_unwind, AssertUnwindSafe};

/// Converts a core error into the matching `sorofem.errors` exception. A `ParameterError`
/// carries the parameter's name in `.parameter`; a `ConvergenceError` the report in `.report`.
pub fn to_py(py: Python<'_>, error: Error) -> PyErr {
    let class = match &error {
        Error::Shape { .. } => "ShapeError",
        Error::NonFinite { .. } | Error::IndexOutOfRange { .. } => "InputError",
        Error::DegenerateTet { .. } | Error::InvertedTet { .. } => "MeshError",
        Error::InvalidParameter { .. } => "ParameterError",
        Error::NotConverged { .. } => "ConvergenceError",
        Error::LinearSolver { .. } => "SolverError",
        Error::Interrupted { .. } => "Interrupted",
    };
    let message = error.to_string();
    let build = || -> PyResult<PyErr> {
        let module = py.import("sorofem.errors")?;
        let exception = match &error {
            Error::InvalidParameter { param, .. } => module
                .getattr(class)?
                .call1((message.clone(), param.clone()))?,
            _ => module.getattr(class)?.call1((message.clone(),))?,
        };
        if let Error::NotConverged { report, .. } | Error::Interrupted { report } = &error {
            exception.setattr("report", report_to_dict(py, report)?)?;
        }
        Ok(PyErr::from_value(exception))
    };
    build().unwrap_or_else(|e| e)
}

pub trait IntoPyResult<T> {
    fn py(self, py: Python<'_>) -> PyResult<T>;
}

impl<T> IntoPyResult<T> for Result<T, Error> {
    fn py(self, py: Python<'_>) -> PyResult<T> {
        self.map_err(|e| to_py(py, e))
    }
}

/// Runs a call into the core without the GIL, and makes sure nothing but a `sorofem.errors`
/// exception comes back: a core error maps through [`to_py`], and a panic (a bug in the core;
/// it must never reach Python as a `PanicException`, which escapes `except Exception`) becomes
/// an [`internal_error`].
pub fn guarded<T: Send>(
    py: Python<'_>,
    call: impl FnOnce() -> Result<T, Error> + Send,
) -> PyResult<T> {
    match py.detach(|| catch_unwind(AssertUnwindSafe(call))) {
        Ok(result) => result.py(py),
        Err(payload) => Err(from_panic(py, payload)),
    }
}

/// The [`internal_error`] of a panic's payload.
pub fn from_panic(py: Python<'_>, payload: Box<dyn std::any::Any + Send>) -> PyErr {
    let what = payload
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| payload.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "a panic without a message".into());
    internal_error(py, &what)
}

static INTERNAL_ERROR: PyOnceLock<Py<PyType>> = PyOnceLock::new();

/// `sorofem._core.InternalError`, a subclass of `sorofem.errors.SolverError` (so of
/// `SorofemError` and `RuntimeError`), created on first use.
pub fn internal_error_type(py: Python<'_>) -> PyResult<&Bound<'_, PyType>> {
    let class = INTERNAL_ERROR.get_or_try_init(py, || -> PyResult<Py<PyType>> {
        let base = py.import("sorofem.errors")?.getattr("SolverError")?;
        let namespace = PyDict::new(py);
        namespace.set_item("__module__", "sorofem._core")?;
        namespace.set_item(
            "__doc__",
            "An internal error of sorofem's core (a bug): the message says where. Please report it.",
        )?;
        let bases = PyTuple::new(py, [base])?;
        let class = py
            .import("builtins")?
            .getattr("type")?
            .call1(("InternalError", bases, namespace))?;
        Ok(class.cast_into::<PyType>()?.unbind())
    })?;
    Ok(class.bind(py))
}

fn internal_error(py: Python<'_>, what: &str) -> PyErr {
    let message = format!(
        "internal error in sorofem's core (a bug, please report it with the call that raised it): {what}"
    );
    match internal_error_type(py).and_then(|class| class.call1((message.clone(),))) {
        Ok(exception) => PyErr::from_value(exception),
        Err(e) => e,
    }
}

pub fn report_to_dict<'py>(py: Python<'py>, report: &SolveReport) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("converged", report.converged)?;
    d.set_item("iterations", report.iterations)?;
    d.set_item("residual_history", report.residual_history.clone())?;
    d.set_item("energy_history", report.energy_history.clone())?;
    d.set_item("step_lengths", report.step_lengths.clone())?;
    d.set_item("load_steps", report.load_steps)?;
    d.set_item("cutbacks", report.cutbacks)?;
    d.set_item("projected_steps", report.projected_steps)?;
    d.set_item("factorizations", report.timings.factorizations)?;
    d.set_item(
        "failed_factorizations",
        report.timings.failed_factorizations,
    )?;
    d.set_item(
        "single_precision_factorizations",
        report.timings.single_precision_factorizations,
    )?;
    d.set_item("residual_norm", report.residual_norm)?;
    d.set_item("reference_norm", report.reference_norm)?;
    d.set_item("message", report.message.clone())?;
    d.set_item("timings", timings_to_dict(py, &report.timings)?)?;
    Ok(d)
}

/// Seconds per phase (the counts are reported beside them).
pub fn timings_to_dict<'py>(py: Python<'py>, timings: &Timings) -> PyResult<Bound<'py, PyDict>> {
    let t = PyDict::new(py);
    t.set_item("assembly", timings.assembly)?;
    t.set_item("factorization", timings.factorization)?;
    t.set_item("solve", timings.solve)?;
    t.set_item("line_search", timings.line_search)?;
    t.set_item("failed_factorization", timings.failed_factorization)?;
    t.set_item("contact", timings.contact)?;
    t.set_item("step_bound", timings.step_bound)?;
    t.set_item("total", timings.total)?;
    Ok(t)
}
