//! `sorofem._core`: the Python face of sorofem-core. Plumbing only: conversions live in
//! `convert`, error mapping in `errors`, and every class forwards to the core: `Mesh` (`mesh`),
//! `Model` (`model`), `SolveOptions` (`options`), `trajectory_gradient` and
//! `trajectory_sensitivity` (`trajectory`); the
//! obstacle and contact checks in `contact`; long calls that Ctrl-C stops in `interrupt`.

mod contact;
mod convert;
mod errors;
mod interrupt;
mod mesh;
mod model;
mod options;
mod trajectory;

use errors::IntoPyResult;
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// The parameter names of a material model ("neo_hookean", "mooney_rivlin", "yeoh", "ogden" with
/// options {"terms": n}), in storage order.
#[pyfunction]
#[pyo3(signature = (model, options = None))]
fn material_param_names(
    py: Python<'_>,
    model: &str,
    options: Option<&Bound<'_, PyDict>>,
) -> PyResult<Vec<String>> {
    let model =
        convert::material_model(model, options, sorofem_core::material::Volumetric::Log).py(py)?;
    Ok(model.param_names())
}

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(mesh::box_mesh, m)?)?;
    m.add_function(wrap_pyfunction!(mesh::check_mesh, m)?)?;
    m.add_function(wrap_pyfunction!(mesh::rest_volumes, m)?)?;
    m.add_function(wrap_pyfunction!(mesh::boundary_faces, m)?)?;
    m.add_function(wrap_pyfunction!(material_param_names, m)?)?;
    m.add_function(wrap_pyfunction!(contact::_contact_reference, m)?)?;
    m.add_function(wrap_pyfunction!(contact::check_obstacle, m)?)?;
    m.add_function(wrap_pyfunction!(contact::check_contact, m)?)?;
    m.add_function(wrap_pyfunction!(trajectory::trajectory_gradient, m)?)?;
    m.add_function(wrap_pyfunction!(trajectory::trajectory_sensitivity, m)?)?;
    m.add_class::<mesh::Mesh>()?;
    m.add_class::<model::Model>()?;
    m.add_class::<options::SolveOptions>()?;
    m.add("InternalError", errors::internal_error_type(m.py())?)?;
    Ok(())
}
