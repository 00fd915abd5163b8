//! `sorofem._core`: the Python face of sorofem-core. Plumbing only: conversions live in
//! `convert`, error mapping in `errors`, and every function here forwards to the core.

mod convert;
mod errors;

use errors::{report_to_dict, IntoPyResult};
use numpy::{PyArray1, PyArray2, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use sorofem_core::material::Volumetric;
use sorofem_core::{
    Formulation, Loads, Material, Orientation, PressureMass, SolveOptions, TetMesh,
};
use std::sync::Arc;

fn build_mesh(
    py: Python<'_>,
    points: &Bound<'_, PyAny>,
    tets: &Bound<'_, PyAny>,
    orientation: Orientation,
) -> PyResult<(TetMesh, Vec<usize>)> {
    let points = convert::points("points", points).py(py)?;
    let tets = convert::tets("tets", tets).py(py)?;
    py.detach(|| TetMesh::try_new(points, &tets, orientation))
        .py(py)
}

fn orientation_from(py: Python<'_>, name: &str) -> PyResult<Orientation> {
    match name {
        "reorient" => Ok(Orientation::Reorient),
        "reject" => Ok(Orientation::Reject),
        other => Err(errors::to_py(
            py,
            sorofem_core::Error::invalid(
                "orientation",
                "\"reorient\" or \"reject\"",
                format!("{other:?}"),
            ),
        )),
    }
}

/// Box mesh `[origin, origin + size]` with `cells` hexahedra split into 6 tets each.
#[pyfunction]
fn box_mesh<'py>(
    py: Python<'py>,
    size: &Bound<'py, PyAny>,
    cells: &Bound<'py, PyAny>,
    origin: &Bound<'py, PyAny>,
) -> PyResult<(Bound<'py, PyArray2<f64>>, Bound<'py, PyArray2<i64>>)> {
    let size = convert::vec3("size", size).py(py)?;
    let cells = convert::indices("cells", cells).py(py)?;
    if cells.len() != 3 || cells.iter().any(|&c| c < 1) {
        return Err(errors::to_py(
            py,
            sorofem_core::Error::invalid(
                "cells",
                "three positive cell counts",
                format!("{cells:?}"),
            ),
        ));
    }
    let origin = convert::vec3("origin", origin).py(py)?;
    let mesh = TetMesh::box_mesh(
        size,
        [cells[0] as usize, cells[1] as usize, cells[2] as usize],
        origin,
    )
    .py(py)?;
    Ok((
        convert::points_to_numpy(py, &mesh.rest_flat()),
        convert::tets_to_numpy(py, mesh.tets()),
    ))
}

/// Validates a mesh; returns the (possibly reoriented) tets and the indices of reoriented ones.
#[pyfunction]
#[pyo3(signature = (points, tets, orientation = "reorient"))]
fn check_mesh<'py>(
    py: Python<'py>,
    points: &Bound<'py, PyAny>,
    tets: &Bound<'py, PyAny>,
    orientation: &str,
) -> PyResult<(Bound<'py, PyArray2<i64>>, Bound<'py, PyArray1<i64>>)> {
    let orientation = orientation_from(py, orientation)?;
    let (mesh, reoriented) = build_mesh(py, points, tets, orientation)?;
    let reoriented: Vec<i64> = reoriented.into_iter().map(|e| e as i64).collect();
    Ok((
        convert::tets_to_numpy(py, mesh.tets()),
        PyArray1::from_vec(py, reoriented),
    ))
}

/// Rest volumes (m^3) of a valid mesh.
#[pyfunction]
fn rest_volumes<'py>(
    py: Python<'py>,
    points: &Bound<'py, PyAny>,
    tets: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let (mesh, _) = build_mesh(py, points, tets, Orientation::Reject)?;
    Ok(PyArray1::from_slice(py, mesh.volumes()))
}

/// Outward-oriented boundary triangles of a valid mesh.
#[pyfunction]
fn boundary_faces<'py>(
    py: Python<'py>,
    points: &Bound<'py, PyAny>,
    tets: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyArray2<i64>>> {
    let (mesh, _) = build_mesh(py, points, tets, Orientation::Reject)?;
    Ok(convert::faces_to_numpy(py, &mesh.boundary_faces()))
}

/// Loads from numpy: gravity (3,), nodal forces (n, 3), prescribed displacements (k, 3).
fn loads_from(
    py: Python<'_>,
    n: usize,
    gravity: &Bound<'_, PyAny>,
    forces: &Bound<'_, PyAny>,
    prescribed: &Bound<'_, PyAny>,
) -> PyResult<Loads> {
    let gravity = convert::vec3("gravity", gravity).py(py)?;
    let forces = convert::points("forces", forces).py(py)?;
    if forces.len() != n {
        return Err(errors::to_py(
            py,
            sorofem_core::Error::shape(
                "forces",
                format!("({n}, 3)"),
                format!("({}, 3)", forces.len()),
            ),
        ));
    }
    let nodal_forces = forces
        .into_iter()
        .enumerate()
        .filter(|(_, f)| f.iter().any(|&v| v != 0.0))
        .collect();
    let prescribed = convert::points("prescribed", prescribed).py(py)?;
    Ok(Loads {
        gravity,
        nodal_forces,
        prescribed,
    })
}

/// A parameter vector as a dict: `"material"` maps each material parameter name to its per-tet
/// values, every other block sits under its own name ("density", "gravity", "cable_actuation",
/// "cable_stiffness"), and the keys of the original API stay: "mu", "lam" (Neo-Hookean) and
/// "rho" (density).
fn param_vector_to_dict<'py>(
    py: Python<'py>,
    p: &sorofem_core::sensitivity::ParamVector,
    material_names: &[String],
) -> PyResult<Bound<'py, PyDict>> {
    let out = PyDict::new(py);
    let material = PyDict::new(py);
    for (name, values) in &p.blocks {
        let array = PyArray1::from_slice(py, values);
        if material_names.contains(name) {
            material.set_item(name, &array)?;
        } else {
            out.set_item(name, &array)?;
        }
        if let Some(alias) = legacy_param_key(name) {
            out.set_item(alias, array)?;
        }
    }
    out.set_item("material", material)?;
    Ok(out)
}

/// The original API's key of a parameter block, where it had one.
fn legacy_param_key(name: &str) -> Option<&'static str> {
    match name {
        "mu" => Some("mu"),
        "lambda" => Some("lam"),
        "density" => Some("rho"),
        _ => None,
    }
}

/// A body ready to be solved many times (see sorofem.model.Body, which owns one).
#[pyclass(module = "sorofem._core")]
struct Model {
    inner: sorofem_core::Model,
}

#[pymethods]
impl Model {
    #[new]
    #[pyo3(signature = (points, tets, fixed, formulation = "standard", options = None, cables = None))]
    fn new(
        py: Python<'_>,
        points: &Bound<'_, PyAny>,
        tets: &Bound<'_, PyAny>,
        fixed: &Bound<'_, PyAny>,
        formulation: &str,
        options: Option<&Bound<'_, PyDict>>,
        cables: Option<&Bound<'_, PyList>>,
    ) -> PyResult<Self> {
        let cable_specs = match cables {
            Some(list) => list
                .iter()
                .enumerate()
                .map(|(c, item)| convert::cable_spec(c, &item))
                .collect::<Result<Vec<_>, _>>()
                .py(py)?,
            None => Vec::new(),
        };
        let (mesh, _) = build_mesh(py, points, tets, Orientation::Reject)?;
        let fixed = convert::indices("fixed", fixed).py(py)?;
        let option = |key: &str| -> PyResult<Option<String>> {
            match options {
                Some(o) => o.get_item(key)?.map(|v| v.extract::<String>()).transpose(),
                None => Ok(None),
            }
        };
        let volumetric = match option("volumetric")?.as_deref() {
            None | Some("log") => Volumetric::Log,
            Some("linear") => Volumetric::Linear,
            Some(other) => {
                return Err(errors::to_py(
                    py,
                    sorofem_core::Error::invalid(
                        "volumetric",
                        "\"log\" (c = ln J) or \"linear\" (c = J - 1)",
                        format!("{other:?}"),
                    ),
                ))
            }
        };
        let mass = match option("pressure_mass")?.as_deref() {
            None | Some("consistent") => PressureMass::Consistent,
            Some("lumped") => PressureMass::Lumped,
            Some(other) => {
                return Err(errors::to_py(
                    py,
                    sorofem_core::Error::invalid(
                        "pressure_mass",
                        "\"consistent\" or \"lumped\"",
                        format!("{other:?}"),
                    ),
                ))
            }
        };
        let formulation = match formulation {
            "standard" => Formulation::Standard,
            "mixed" => Formulation::Mixed { mass },
            other => {
                return Err(errors::to_py(
                    py,
                    sorofem_core::Error::invalid(
                        "formulation",
                        "\"standard\" or \"mixed\"",
                        format!("{other:?}"),
                    ),
                ))
            }
        };
        let mesh = Arc::new(mesh);
        let inner = py
            .detach(|| {
                sorofem_core::Model::try_new_with_cables(
                    mesh,
                    &fixed,
                    formulation,
                    volumetric,
                    &cable_specs,
                )
            })
            .py(py)?;
        Ok(Model { inner })
    }

    /// Per-tet shear modulus, Lame lambda (Pa) and density (kg/m^3).
    fn set_material(
        &mut self,
        py: Python<'_>,
        mu: &Bound<'_, PyAny>,
        lam: &Bound<'_, PyAny>,
        rho: &Bound<'_, PyAny>,
    ) -> PyResult<()> {
        let m = Some(self.inner.mesh().n_tets());
        let material = Material {
            mu: convert::vector("mu", mu, m).py(py)?,
            lambda: convert::vector("lam", lam, m).py(py)?,
            density: convert::vector("rho", rho, m).py(py)?,
        };
        let inner = &mut self.inner;
        py.detach(|| inner.set_material(&material)).py(py)
    }

    /// Sets the material model by name ("neo_hookean", "mooney_rivlin", "yeoh", "ogden"), its
    /// parameters as a dict of per-tet arrays by name (see `material_param_names`), the density
    /// (m,) kg/m^3, and the model's options ("neo_hookean": "volumetric", default the
    /// constructor's; "ogden": "terms").
    #[pyo3(signature = (model, params, density, options = None))]
    fn set_material_model(
        &mut self,
        py: Python<'_>,
        model: &str,
        params: &Bound<'_, PyDict>,
        density: &Bound<'_, PyAny>,
        options: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<()> {
        let m = self.inner.mesh().n_tets();
        let model = convert::material_model(model, options, self.inner.volumetric()).py(py)?;
        let params = convert::material_params(params, m).py(py)?;
        let density = convert::vector("density", density, Some(m)).py(py)?;
        let inner = &mut self.inner;
        py.detach(|| inner.set_material_model(model, &params, &density))
            .py(py)
    }

    /// The material's parameter names, in storage order.
    #[getter]
    fn material_param_names(&self) -> Vec<String> {
        self.inner.material_param_names()
    }

    /// Static equilibrium; returns a dict with "positions", "pressure", "reactions" (one row per
    /// fixed node, N), "cable_points" (per cable (k, 3), m), "cable_tensions" (per cable (k-1,),
    /// N) and the report entries.
    #[pyo3(signature = (gravity, forces, prescribed, initial = None, tolerance = 1e-8, max_iterations = 50, load_steps = 1))]
    #[allow(clippy::too_many_arguments)]
    fn solve<'py>(
        &mut self,
        py: Python<'py>,
        gravity: &Bound<'py, PyAny>,
        forces: &Bound<'py, PyAny>,
        prescribed: &Bound<'py, PyAny>,
        initial: Option<&Bound<'py, PyAny>>,
        tolerance: f64,
        max_iterations: usize,
        load_steps: usize,
    ) -> PyResult<Bound<'py, PyDict>> {
        let n = self.inner.mesh().n_nodes();
        let loads = loads_from(py, n, gravity, forces, prescribed)?;
        let initial = initial
            .filter(|i| !i.is_none())
            .map(|i| convert::points("initial", i))
            .transpose()
            .py(py)?;
        let initial_flat: Option<Vec<f64>> = initial.map(|p| p.into_iter().flatten().collect());
        let options = SolveOptions {
            tolerance,
            max_iterations,
            load_steps,
            ..Default::default()
        };
        let inner = &mut self.inner;
        let solution = py
            .detach(|| inner.solve(&loads, initial_flat.as_deref(), &options))
            .py(py)?;
        let out = report_to_dict(py, &solution.report)?;
        out.set_item(
            "positions",
            convert::points_to_numpy(py, &solution.positions),
        )?;
        out.set_item(
            "reactions",
            convert::points_to_numpy(py, solution.reactions.as_flattened()),
        )?;
        let cable_points: Vec<_> = solution
            .cable_points
            .iter()
            .map(|c| convert::points_to_numpy(py, c.as_flattened()))
            .collect();
        out.set_item("cable_points", cable_points)?;
        let tensions: Vec<_> = solution
            .cable_tensions
            .iter()
            .map(|t| PyArray1::from_slice(py, t))
            .collect();
        out.set_item("cable_tensions", tensions)?;
        match solution.pressure {
            Some(p) => out.set_item("pressure", PyArray1::from_vec(py, p))?,
            None => out.set_item("pressure", py.None())?,
        }
        Ok(out)
    }

    /// Implicit Euler dynamics; returns a dict with "times", "positions" (frames, n, 3),
    /// "velocities" (n, 3), "cable_points", "kinetic_energy", "iterations", "cutbacks".
    #[pyo3(signature = (gravity, forces, prescribed, dt, steps, actuation, mass_damping = 0.0, stiffness_damping = 0.0, initial_positions = None, initial_velocities = None, tolerance = 1e-8, max_iterations = 50, save_every = 1))]
    #[allow(clippy::too_many_arguments)]
    fn simulate<'py>(
        &mut self,
        py: Python<'py>,
        gravity: &Bound<'py, PyAny>,
        forces: &Bound<'py, PyAny>,
        prescribed: &Bound<'py, PyAny>,
        dt: f64,
        steps: usize,
        actuation: &Bound<'py, PyAny>,
        mass_damping: f64,
        stiffness_damping: f64,
        initial_positions: Option<&Bound<'py, PyAny>>,
        initial_velocities: Option<&Bound<'py, PyAny>>,
        tolerance: f64,
        max_iterations: usize,
        save_every: usize,
    ) -> PyResult<Bound<'py, PyDict>> {
        let n = self.inner.mesh().n_nodes();
        let loads = loads_from(py, n, gravity, forces, prescribed)?;
        let actuation =
            convert::matrix("actuation", actuation, Some(self.inner.n_cables())).py(py)?;
        let flat = |param: &str, a: Option<&Bound<'py, PyAny>>| -> PyResult<Option<Vec<f64>>> {
            a.filter(|a| !a.is_none())
                .map(|a| convert::points(param, a).map(|p| p.into_iter().flatten().collect()))
                .transpose()
                .py(py)
        };
        let x0 = flat("initial_positions", initial_positions)?;
        let v0 = flat("initial_velocities", initial_velocities)?;
        let options = SolveOptions {
            tolerance,
            max_iterations,
            ..Default::default()
        };
        let damping = sorofem_core::Damping {
            mass: mass_damping,
            stiffness: stiffness_damping,
        };
        let inner = &mut self.inner;
        let trajectory = py
            .detach(|| {
                inner.simulate(
                    &loads,
                    dt,
                    steps,
                    &actuation,
                    damping,
                    x0.as_deref(),
                    v0.as_deref(),
                    &options,
                    save_every,
                )
            })
            .py(py)?;
        let out = PyDict::new(py);
        out.set_item("times", PyArray1::from_slice(py, &trajectory.times))?;
        let frames = trajectory.positions.len();
        let flat_positions: Vec<f64> = trajectory.positions.into_iter().flatten().collect();
        out.set_item(
            "positions",
            PyArray1::from_vec(py, flat_positions).reshape([frames, n, 3])?,
        )?;
        out.set_item(
            "velocities",
            convert::points_to_numpy(py, &trajectory.velocities),
        )?;
        let cable_points: Vec<Vec<_>> = trajectory
            .cable_points
            .iter()
            .map(|frame| {
                frame
                    .iter()
                    .map(|c| convert::points_to_numpy(py, c.as_flattened()))
                    .collect()
            })
            .collect();
        out.set_item("cable_points", cable_points)?;
        out.set_item(
            "kinetic_energy",
            PyArray1::from_slice(py, &trajectory.kinetic_energy),
        )?;
        out.set_item("iterations", trajectory.iterations)?;
        out.set_item("cutbacks", trajectory.cutbacks)?;
        Ok(out)
    }

    /// Seconds of each of `repeats` bare numeric factorisations of the Hessian at the last
    /// equilibrium (benchmark diagnostic).
    fn time_factorization(&mut self, py: Python<'_>, repeats: usize) -> PyResult<Vec<f64>> {
        let inner = &mut self.inner;
        py.detach(|| inner.time_factorization(repeats)).py(py)
    }

    /// Adjoint gradient of a scalar objective of the last equilibrium's node positions:
    /// `d_objective_d_positions` (n, 3) -> dict of dO/dtheta ("mu", "lam", "rho" per tet,
    /// "gravity" (3,), "cable_actuation", "cable_stiffness" per cable).
    fn adjoint<'py>(
        &mut self,
        py: Python<'py>,
        d_objective_d_positions: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let g: Vec<f64> = convert::points("d_objective_d_positions", d_objective_d_positions)
            .py(py)?
            .into_iter()
            .flatten()
            .collect();
        let inner = &mut self.inner;
        let gradient = py.detach(|| inner.adjoint(&g)).py(py)?;
        param_vector_to_dict(py, &gradient, &self.inner.material_param_names())
    }

    /// Forward sensitivity along a parameter direction (dict with any of the adjoint's keys):
    /// returns {"dx": (n, 3), "dp": (n,) or None}.
    fn forward<'py>(
        &mut self,
        py: Python<'py>,
        direction: &Bound<'py, PyDict>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let delta = convert::param_direction(direction, &self.inner.param_zeros()).py(py)?;
        let inner = &mut self.inner;
        let (dx, dp) = py.detach(|| inner.forward(&delta)).py(py)?;
        let out = PyDict::new(py);
        out.set_item("dx", convert::points_to_numpy(py, &dx))?;
        match dp {
            Some(p) => out.set_item("dp", PyArray1::from_vec(py, p))?,
            None => out.set_item("dp", py.None())?,
        }
        Ok(out)
    }

    /// Per-tet J and von Mises stress (Pa) at positions (n, 3).
    fn element_fields<'py>(
        &self,
        py: Python<'py>,
        positions: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let positions: Vec<f64> = convert::points("positions", positions)
            .py(py)?
            .into_iter()
            .flatten()
            .collect();
        let (j, vm) = self.inner.element_fields(&positions).py(py)?;
        let out = PyDict::new(py);
        out.set_item("J", PyArray1::from_vec(py, j))?;
        out.set_item("von_mises", PyArray1::from_vec(py, vm))?;
        Ok(out)
    }

    #[getter]
    fn n_free(&self) -> usize {
        self.inner.n_free()
    }

    /// Sets cable `cable`'s actuation alpha (1 = rest, < 1 = pulled).
    fn set_actuation(&mut self, py: Python<'_>, cable: usize, actuation: f64) -> PyResult<()> {
        self.inner.set_actuation(cable, actuation).py(py)
    }

    /// Sets cable `cable`'s segment stiffness (N/m).
    fn set_cable_stiffness(
        &mut self,
        py: Python<'_>,
        cable: usize,
        stiffness: f64,
    ) -> PyResult<()> {
        self.inner.set_cable_stiffness(cable, stiffness).py(py)
    }

    /// Rest length (m) of each segment, per cable, between the attached points.
    fn cable_rest_lengths(&self) -> Vec<Vec<f64>> {
        self.inner.cable_rest_lengths()
    }

    /// Where each cable point was placed: per cable, a list of
    /// ("embedded", tet, distance) | ("free", index, 0.0) | ("anchor", -1, 0.0).
    fn cable_placements(&self) -> Vec<Vec<(String, i64, f64)>> {
        use sorofem_core::cables::PointPlacement;
        self.inner
            .cable_placements()
            .iter()
            .map(|cable| {
                cable
                    .iter()
                    .map(|p| match *p {
                        PointPlacement::Embedded { tet, distance } => {
                            ("embedded".to_string(), tet as i64, distance)
                        }
                        PointPlacement::Free { index } => ("free".to_string(), index as i64, 0.0),
                        PointPlacement::Anchor => ("anchor".to_string(), -1, 0.0),
                    })
                    .collect()
            })
            .collect()
    }
}

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(box_mesh, m)?)?;
    m.add_function(wrap_pyfunction!(check_mesh, m)?)?;
    m.add_function(wrap_pyfunction!(rest_volumes, m)?)?;
    m.add_function(wrap_pyfunction!(boundary_faces, m)?)?;
    m.add_class::<Model>()?;
    Ok(())
}
