//! `trajectory_gradient`: the core's trajectory adjoint, the objective called back into Python.

use crate::convert;
use crate::errors::{guarded, IntoPyResult};
use crate::model::Model;
use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray1};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::sync::Mutex;

/// The gradient of a trajectory objective (see `Model::trajectory_gradient` in the core).
/// `objective(positions (steps + 1, n, 3)) -> d objective / d positions` as a flat float64
/// array of `(steps + 1) 3 n` values (checked by the caller). Returns {"positions",
/// "iterations", "params" (as `Model.adjoint`), "actuation" (steps, cables), "mass_damping",
/// "stiffness_damping", "cable_damping" (cables)}. An exception of the objective propagates
/// unchanged.
#[pyfunction]
#[pyo3(signature = (model, gravity, forces, prescribed, dt, actuation, objective, mass_damping = 0.0, stiffness_damping = 0.0, initial_positions = None, initial_velocities = None, tolerance = None, max_iterations = None, checkpoint_every = 0))]
#[allow(clippy::too_many_arguments)]
pub fn trajectory_gradient<'py>(
    py: Python<'py>,
    mut model: PyRefMut<'py, Model>,
    gravity: &Bound<'py, PyAny>,
    forces: &Bound<'py, PyAny>,
    prescribed: &Bound<'py, PyAny>,
    dt: f64,
    actuation: &Bound<'py, PyAny>,
    objective: Py<PyAny>,
    mass_damping: f64,
    stiffness_damping: f64,
    initial_positions: Option<&Bound<'py, PyAny>>,
    initial_velocities: Option<&Bound<'py, PyAny>>,
    tolerance: Option<f64>,
    max_iterations: Option<usize>,
    checkpoint_every: usize,
) -> PyResult<Bound<'py, PyDict>> {
    let n = model.inner.mesh().n_nodes();
    let run = Run::new(
        py,
        &model,
        [gravity, forces, prescribed, actuation],
        (mass_damping, stiffness_damping),
        (initial_positions, initial_velocities),
        (tolerance, max_iterations),
    )?;
    let raised: Mutex<Option<PyErr>> = Mutex::new(None);
    let call = |record: &sorofem_core::model::trajectory::RecordedPositions| -> Option<Vec<f64>> {
        Python::attach(|py| {
            let frames = record.positions.len();
            let positions: Vec<f64> = record.positions.iter().flatten().copied().collect();
            let result = PyArray1::from_vec(py, positions)
                .reshape([frames, n, 3])
                .and_then(|array| objective.call1(py, (array,)))
                .and_then(|out| {
                    let array: PyReadonlyArray1<f64> = out.extract(py)?;
                    Ok(array.as_slice()?.to_vec())
                });
            result
                .map_err(|err| *raised.lock().expect("one thread") = Some(err))
                .ok()
        })
    };
    let inner = &mut model.inner;
    let outcome = guarded(py, || {
        inner.trajectory_gradient(
            &run.loads,
            dt,
            &run.actuation,
            run.damping,
            run.x0.as_deref(),
            run.v0.as_deref(),
            &run.newton,
            checkpoint_every,
            call,
        )
    });
    if let Some(err) = raised.lock().expect("one thread").take() {
        return Err(err);
    }
    let (record, gradient) = outcome?;
    let out = record_dict(py, record, n)?;
    let names = model.inner.material_param_names();
    out.set_item(
        "params",
        convert::param_vector_to_dict(py, &gradient.params, &names)?,
    )?;
    out.set_item("actuation", gradient.actuation)?;
    out.set_item("mass_damping", gradient.mass_damping)?;
    out.set_item("stiffness_damping", gradient.stiffness_damping)?;
    out.set_item("cable_damping", gradient.cable_damping)?;
    Ok(out)
}

/// The trajectory of `trajectory_gradient` and its forward sensitivities (see
/// `Model::trajectory_sensitivity` in the core): `directions` is a list of dicts with the keys
/// of `Model.forward`'s direction and optionally "mass_damping" (1/s), "stiffness_damping" (s)
/// and "cable_damping" (N s/m, one per cable). Returns {"positions" (steps + 1, n, 3),
/// "iterations", "dx" (directions, steps + 1, n, 3)}.
#[pyfunction]
#[pyo3(signature = (model, gravity, forces, prescribed, dt, actuation, directions, mass_damping = 0.0, stiffness_damping = 0.0, initial_positions = None, initial_velocities = None, tolerance = None, max_iterations = None))]
#[allow(clippy::too_many_arguments)]
pub fn trajectory_sensitivity<'py>(
    py: Python<'py>,
    mut model: PyRefMut<'py, Model>,
    gravity: &Bound<'py, PyAny>,
    forces: &Bound<'py, PyAny>,
    prescribed: &Bound<'py, PyAny>,
    dt: f64,
    actuation: &Bound<'py, PyAny>,
    directions: Vec<Bound<'py, PyDict>>,
    mass_damping: f64,
    stiffness_damping: f64,
    initial_positions: Option<&Bound<'py, PyAny>>,
    initial_velocities: Option<&Bound<'py, PyAny>>,
    tolerance: Option<f64>,
    max_iterations: Option<usize>,
) -> PyResult<Bound<'py, PyDict>> {
    let n = model.inner.mesh().n_nodes();
    let run = Run::new(
        py,
        &model,
        [gravity, forces, prescribed, actuation],
        (mass_damping, stiffness_damping),
        (initial_positions, initial_velocities),
        (tolerance, max_iterations),
    )?;
    let zeros = model.inner.param_zeros();
    let mut deltas = Vec::with_capacity(directions.len());
    for direction in &directions {
        let params = direction.copy()?;
        let coefficient = |key: &str| -> PyResult<f64> {
            let value = params
                .get_item(key)?
                .map(|v| v.extract::<f64>())
                .transpose()?;
            if value.is_some() {
                params.del_item(key)?;
            }
            Ok(value.unwrap_or(0.0))
        };
        let (mass, stiffness) = (
            coefficient("mass_damping")?,
            coefficient("stiffness_damping")?,
        );
        let cable_damping = match params.get_item("cable_damping")? {
            Some(values) => {
                params.del_item("cable_damping")?;
                convert::vector("cable_damping", &values, Some(model.inner.n_cables())).py(py)?
            }
            None => Vec::new(),
        };
        deltas.push(sorofem_core::model::trajectory::TrajectoryDirection {
            params: convert::param_direction(&params, &zeros).py(py)?,
            mass_damping: mass,
            stiffness_damping: stiffness,
            cable_damping,
        });
    }
    let inner = &mut model.inner;
    let (record, changes) = guarded(py, || {
        inner.trajectory_sensitivity(
            &run.loads,
            dt,
            &run.actuation,
            run.damping,
            run.x0.as_deref(),
            run.v0.as_deref(),
            &run.newton,
            &deltas,
        )
    })?;
    let frames = record.positions.len();
    let out = record_dict(py, record, n)?;
    let count = changes.len();
    let dx: Vec<f64> = changes.into_iter().flatten().flatten().collect();
    out.set_item(
        "dx",
        PyArray1::from_vec(py, dx).reshape([count, frames, n, 3])?,
    )?;
    Ok(out)
}

/// The arguments both entry points share, converted: loads, the actuation schedule (steps,
/// cables), the start (flat 3 n positions and velocities, when given), Newton's settings per
/// step and the Rayleigh damping.
struct Run {
    loads: sorofem_core::Loads,
    actuation: Vec<Vec<f64>>,
    x0: Option<Vec<f64>>,
    v0: Option<Vec<f64>>,
    newton: sorofem_core::SolveOptions,
    damping: sorofem_core::Damping,
}

impl Run {
    fn new<'py>(
        py: Python<'py>,
        model: &Model,
        [gravity, forces, prescribed, actuation]: [&Bound<'py, PyAny>; 4],
        (mass, stiffness): (f64, f64),
        (initial_positions, initial_velocities): (
            Option<&Bound<'py, PyAny>>,
            Option<&Bound<'py, PyAny>>,
        ),
        (tolerance, max_iterations): (Option<f64>, Option<usize>),
    ) -> PyResult<Self> {
        let n = model.inner.mesh().n_nodes();
        let flat = |param: &str, a: Option<&Bound<'py, PyAny>>| -> PyResult<Option<Vec<f64>>> {
            a.filter(|a| !a.is_none())
                .map(|a| convert::points(param, a).map(|p| p.into_iter().flatten().collect()))
                .transpose()
                .py(py)
        };
        Ok(Run {
            loads: convert::loads(py, n, gravity, forces, prescribed)?,
            actuation: convert::matrix("actuation", actuation, Some(model.inner.n_cables()))
                .py(py)?,
            x0: flat("initial_positions", initial_positions)?,
            v0: flat("initial_velocities", initial_velocities)?,
            newton: Model::solve_options(py, None, tolerance, max_iterations, None)?,
            damping: sorofem_core::Damping { mass, stiffness },
        })
    }
}

/// {"positions" (frames, n, 3), "iterations", "balanced_stiffness_steps", "split_steps"} of a
/// recorded trajectory.
fn record_dict<'py>(
    py: Python<'py>,
    record: sorofem_core::model::trajectory::RecordedPositions,
    n: usize,
) -> PyResult<Bound<'py, PyDict>> {
    let out = PyDict::new(py);
    let frames = record.positions.len();
    let positions: Vec<f64> = record.positions.into_iter().flatten().collect();
    out.set_item(
        "positions",
        PyArray1::from_vec(py, positions).reshape([frames, n, 3])?,
    )?;
    out.set_item("iterations", record.iterations)?;
    out.set_item("balanced_stiffness_steps", record.balanced_stiffness_steps)?;
    out.set_item("split_steps", record.split_steps)?;
    Ok(out)
}
