//! The one mapping from the core's error enum onto the exception classes of `sorofem.errors`.

use pyo3::prelude::*;
use pyo3::types::PyDict;
use sorofem_core::{Error, SolveReport};

/// Converts a core error into the matching `sorofem.errors` exception.
pub fn to_py(py: Python<'_>, error: Error) -> PyErr {
    let class = match &error {
        Error::Shape { .. } => "ShapeError",
        Error::NonFinite { .. } | Error::IndexOutOfRange { .. } => "InputError",
        Error::DegenerateTet { .. } | Error::InvertedTet { .. } => "MeshError",
        Error::InvalidParameter { .. } => "ParameterError",
        Error::NotConverged { .. } => "ConvergenceError",
        Error::LinearSolver { .. } => "SolverError",
    };
    let message = error.to_string();
    let build = || -> PyResult<PyErr> {
        let module = py.import("sorofem.errors")?;
        let exception = module.getattr(class)?.call1((message.clone(),))?;
        if let Error::NotConverged { report, .. } = &error {
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
    d.set_item("residual_norm", report.residual_norm)?;
    d.set_item("reference_norm", report.reference_norm)?;
    d.set_item("message", report.message.clone())?;
    let t = PyDict::new(py);
    t.set_item("assembly", report.timings.assembly)?;
    t.set_item("factorization", report.timings.factorization)?;
    t.set_item("solve", report.timings.solve)?;
    t.set_item("line_search", report.timings.line_search)?;
    t.set_item("failed_factorization", report.timings.failed_factorization)?;
    t.set_item("total", report.timings.total)?;
    d.set_item("timings", t)?;
    Ok(d)
}
