//! `SolveOptions`: Newton's settings as one validated object.

use crate::errors::IntoPyResult;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use sorofem_core::SolveOptions as CoreOptions;

/// Newton settings, checked once when built (a bad value raises ParameterError naming it).
#[pyclass(module = "sorofem._core", name = "SolveOptions", frozen, eq)]
#[derive(Clone, PartialEq)]
pub struct SolveOptions {
    pub inner: CoreOptions,
}

#[pymethods]
impl SolveOptions {
    #[new]
    #[pyo3(signature = (tolerance = 1e-8, max_iterations = 50, load_steps = 1, max_cutbacks = 8, pressure_iterates = true))]
    fn new(
        py: Python<'_>,
        tolerance: f64,
        max_iterations: usize,
        load_steps: usize,
        max_cutbacks: usize,
        pressure_iterates: bool,
    ) -> PyResult<Self> {
        let inner = CoreOptions {
            tolerance,
            max_iterations,
            load_steps,
            max_cutbacks,
            pressure_iterates,
            ..Default::default()
        };
        inner.validate().py(py)?;
        Ok(SolveOptions { inner })
    }

    /// Relative residual at which Newton stops.
    #[getter]
    fn tolerance(&self) -> f64 {
        self.inner.tolerance
    }

    /// Newton iterations per load step.
    #[getter]
    fn max_iterations(&self) -> usize {
        self.inner.max_iterations
    }

    /// Initial number of equal load increments.
    #[getter]
    fn load_steps(&self) -> usize {
        self.inner.load_steps
    }

    /// How many times in total a load increment may be halved after a failure.
    #[getter]
    fn max_cutbacks(&self) -> usize {
        self.inner.max_cutbacks
    }

    /// Whether the standard formulation's Hessians use element pressure iterates.
    #[getter]
    fn pressure_iterates(&self) -> bool {
        self.inner.pressure_iterates
    }

    /// The settings as a dict (the constructor's keyword arguments).
    fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        d.set_item("tolerance", self.inner.tolerance)?;
        d.set_item("max_iterations", self.inner.max_iterations)?;
        d.set_item("load_steps", self.inner.load_steps)?;
        d.set_item("max_cutbacks", self.inner.max_cutbacks)?;
        d.set_item("pressure_iterates", self.inner.pressure_iterates)?;
        Ok(d)
    }

    fn __repr__(&self) -> String {
        let o = &self.inner;
        format!(
            "SolveOptions(tolerance={:e}, max_iterations={}, load_steps={}, max_cutbacks={}, pressure_iterates={})",
            o.tolerance,
            o.max_iterations,
            o.load_steps,
            o.max_cutbacks,
            if o.pressure_iterates { "True" } else { "False" }
        )
    }
}
