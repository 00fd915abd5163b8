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

/// The contact forces of a state as a dict: "forces" (n, 3), "obstacle_forces" (k, 3) N,
/// "min_distance" (k,) m (NaN: nothing within the report radius), "active" (k,).
fn contact_forces_to_dict<'py>(
    py: Python<'py>,
    forces: &sorofem_core::contact::ContactForces,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item(
        "forces",
        convert::points_to_numpy(py, forces.nodal.as_flattened()),
    )?;
    d.set_item(
        "obstacle_forces",
        convert::points_to_numpy(py, forces.per_obstacle.as_flattened()),
    )?;
    let distances: Vec<f64> = forces
        .min_distance
        .iter()
        .map(|d| d.unwrap_or(f64::NAN))
        .collect();
    d.set_item("min_distance", PyArray1::from_vec(py, distances))?;
    let active: Vec<i64> = forces.active.iter().map(|&a| a as i64).collect();
    d.set_item("active", PyArray1::from_vec(py, active))?;
    Ok(d)
}

/// The contact kernels at one configuration of four points `x` (4, 3), for the comparison with
/// ipctk in the tests: squared point-triangle and edge-edge distances (point 0 and triangle
/// 1-3; edges 0-1 and 2-3) with gradients (12,) and Hessians (12, 12), the edge-edge mollifier
/// (threshold from `x` itself), and the barrier b(d; dhat^2) and its two derivatives at the
/// point-triangle distance d.
#[pyfunction]
fn _contact_reference<'py>(
    py: Python<'py>,
    x: &Bound<'py, PyAny>,
    dhat: f64,
) -> PyResult<Bound<'py, PyDict>> {
    use sorofem_core::contact::barrier::{barrier, barrier_gradient, barrier_hessian};
    use sorofem_core::contact::distance::{
        edge_edge_feature, edge_edge_mollifier_derivatives, edge_edge_mollifier_threshold,
        feature_distance_derivatives, point_triangle_feature, Derivatives,
    };
    use sorofem_core::contact::Vec3;
    let points = convert::points("x", x).py(py)?;
    if points.len() != 4 {
        return Err(errors::to_py(
            py,
            sorofem_core::Error::shape("x", "shape (4, 3)", format!("shape ({}, 3)", points.len())),
        ));
    }
    let p: Vec<Vec3> = points.iter().map(|&q| Vec3::from(q)).collect();
    let r: Vec<&Vec3> = p.iter().collect();
    let out = PyDict::new(py);
    let put = |name: &str, d: &Derivatives<12>| -> PyResult<()> {
        let entry = PyDict::new(py);
        entry.set_item("value", d.value)?;
        entry.set_item("gradient", PyArray1::from_slice(py, d.gradient.as_slice()))?;
        let hessian = PyArray1::from_slice(py, d.hessian.as_slice()).reshape([12, 12])?;
        // nalgebra stores column-major: the transpose of the row-major reshape (symmetric anyway).
        entry.set_item("hessian", hessian.transpose()?)?;
        out.set_item(name, entry)
    };
    let pt = feature_distance_derivatives(&point_triangle_feature(r[0], r[1], r[2], r[3]), &r);
    put("point_triangle", &pt)?;
    put(
        "edge_edge",
        &feature_distance_derivatives(&edge_edge_feature(r[0], r[1], r[2], r[3]), &r),
    )?;
    let eps_x = edge_edge_mollifier_threshold(r[0], r[1], r[2], r[3]);
    put(
        "mollifier",
        &edge_edge_mollifier_derivatives(r[0], r[1], r[2], r[3], eps_x),
    )?;
    out.set_item("mollifier_threshold", eps_x)?;
    let dhat2 = dhat * dhat;
    out.set_item(
        "barrier",
        (
            barrier(pt.value, dhat2),
            barrier_gradient(pt.value, dhat2),
            barrier_hessian(pt.value, dhat2),
        ),
    )?;
    Ok(out)
}

/// Checks an obstacle description (see the binding's `obstacle_spec`) as the core will build
/// it; returns {"closed": bool, "vertices": (n, 3) m, "triangles": (m, 3)} for boxes and
/// meshes, {"closed": True} for planes and spheres.
#[pyfunction]
fn check_obstacle<'py>(
    py: Python<'py>,
    obstacle: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyDict>> {
    use sorofem_core::contact::Obstacle;
    let spec = convert::obstacle_spec(0, obstacle).py(py)?;
    let out = PyDict::new(py);
    match &spec.obstacle {
        Obstacle::Mesh(mesh) => {
            out.set_item("closed", mesh.is_closed())?;
            let flat: Vec<f64> = mesh
                .vertices()
                .iter()
                .flat_map(|v| [v[0], v[1], v[2]])
                .collect();
            out.set_item("vertices", convert::points_to_numpy(py, &flat))?;
            out.set_item("triangles", convert::faces_to_numpy(py, mesh.triangles()))?;
        }
        Obstacle::Plane(_) | Obstacle::Sphere(_) => out.set_item("closed", true)?,
    }
    Ok(out)
}

/// Checks obstacles against a body mesh at rest (each apart from it: the error names the
/// obstacle, the node or triangle and the distance) and the contact settings; returns
/// {"dhat": m}, the activation distance in force (the default when `dhat` is None).
#[pyfunction]
#[pyo3(signature = (points, tets, obstacles, dhat = None))]
fn check_contact<'py>(
    py: Python<'py>,
    points: &Bound<'py, PyAny>,
    tets: &Bound<'py, PyAny>,
    obstacles: &Bound<'py, PyList>,
    dhat: Option<f64>,
) -> PyResult<Bound<'py, PyDict>> {
    let (mesh, _) = build_mesh(py, points, tets, Orientation::Reject)?;
    let obstacles = obstacles
        .iter()
        .enumerate()
        .map(|(k, item)| convert::obstacle_spec(k, &item))
        .collect::<Result<Vec<_>, _>>()
        .py(py)?;
    let setup = sorofem_core::contact::ContactSetup {
        obstacles,
        dhat,
        ..Default::default()
    };
    let term = py
        .detach(|| sorofem_core::contact::ContactTerm::try_new(&mesh, setup))
        .py(py)?;
    let out = PyDict::new(py);
    out.set_item("dhat", term.dhat())?;
    Ok(out)
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
        match &solution.contact {
            Some(contact) => {
                let d = contact_forces_to_dict(py, &contact.forces)?;
                d.set_item("stiffness", contact.stiffness)?;
                d.set_item("dhat", contact.dhat)?;
                d.set_item(
                    "iterate_min_distances",
                    contact.iterate_min_distances.clone(),
                )?;
                out.set_item("contact", d)?
            }
            None => out.set_item("contact", py.None())?,
        }
        Ok(out)
    }

    /// Sets (replaces) the obstacles: a list of dicts (see the binding's `obstacle_spec`:
    /// "kind" and its geometry, "friction", "path"), the activation distance `dhat` (m), the
    /// reference barrier stiffness (J/m^4), the static friction slip (m) and the dynamic friction
    /// velocity (m/s); `None` takes the core's defaults. An empty list removes contact.
    #[pyo3(signature = (obstacles, dhat = None, stiffness = None, friction_slip = None, friction_velocity = None))]
    fn set_contact(
        &mut self,
        py: Python<'_>,
        obstacles: &Bound<'_, PyList>,
        dhat: Option<f64>,
        stiffness: Option<f64>,
        friction_slip: Option<f64>,
        friction_velocity: Option<f64>,
    ) -> PyResult<()> {
        let obstacles = obstacles
            .iter()
            .enumerate()
            .map(|(k, item)| convert::obstacle_spec(k, &item))
            .collect::<Result<Vec<_>, _>>()
            .py(py)?;
        let setup = sorofem_core::contact::ContactSetup {
            obstacles,
            dhat,
            stiffness,
            friction_slip,
            friction_velocity,
        };
        let inner = &mut self.inner;
        py.detach(|| inner.set_contact(setup)).py(py)
    }

    /// The contact settings in force: {"dhat": m, "stiffness": J/m^4 or None before the first
    /// solve, "n_obstacles"}, or None without obstacles.
    fn contact_settings<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        let Some(contact) = self.inner.contact() else {
            return Ok(None);
        };
        let d = PyDict::new(py);
        d.set_item("dhat", contact.dhat())?;
        d.set_item("stiffness", contact.reference_stiffness())?;
        d.set_item("n_obstacles", contact.n_obstacles())?;
        Ok(Some(d))
    }

    /// Contact forces at node positions (n, 3), m: a dict with "forces" (n, 3) and
    /// "obstacle_forces" (k, 3) in N (exerted on the body), "min_distance" (k,) m (NaN: nothing
    /// near), "active" (k,); None without obstacles.
    fn contact_forces<'py>(
        &self,
        py: Python<'py>,
        positions: &Bound<'py, PyAny>,
    ) -> PyResult<Option<Bound<'py, PyDict>>> {
        let positions: Vec<f64> = convert::points("positions", positions)
            .py(py)?
            .into_iter()
            .flatten()
            .collect();
        match self.inner.contact_forces(&positions).py(py)? {
            Some(forces) => Ok(Some(contact_forces_to_dict(py, &forces)?)),
            None => Ok(None),
        }
    }

    /// `d(w . F_k)/dx` (n, 3) at the last equilibrium: the gradient of the force obstacle
    /// `obstacle` exerts on the body, along `weights` (3,), with respect to the node positions.
    fn contact_force_gradient<'py>(
        &self,
        py: Python<'py>,
        obstacle: usize,
        weights: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let w = convert::vec3("weights", weights).py(py)?;
        let g = self.inner.contact_force_gradient(obstacle, w).py(py)?;
        Ok(convert::points_to_numpy(py, &g))
    }

    /// Checks every accepted Newton iterate for intersections in full (a test diagnostic): one
    /// records a minimum distance of -inf.
    fn set_contact_audit(&mut self, on: bool) {
        self.inner.set_contact_audit(on);
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
        if !trajectory.contact.is_empty() {
            let frames = trajectory.contact.len();
            let k = trajectory.contact[0].translations.len();
            let nodal: Vec<f64> = trajectory
                .contact
                .iter()
                .flat_map(|c| c.forces.nodal.iter().flatten().copied())
                .collect();
            let per_obstacle: Vec<f64> = trajectory
                .contact
                .iter()
                .flat_map(|c| c.forces.per_obstacle.iter().flatten().copied())
                .collect();
            let translations: Vec<f64> = trajectory
                .contact
                .iter()
                .flat_map(|c| c.translations.iter().flatten().copied())
                .collect();
            let distances: Vec<f64> = trajectory
                .contact
                .iter()
                .flat_map(|c| c.forces.min_distance.iter().map(|d| d.unwrap_or(f64::NAN)))
                .collect();
            let active: Vec<i64> = trajectory
                .contact
                .iter()
                .flat_map(|c| c.forces.active.iter().map(|&a| a as i64))
                .collect();
            let d = PyDict::new(py);
            d.set_item(
                "forces",
                PyArray1::from_vec(py, nodal).reshape([frames, n, 3])?,
            )?;
            d.set_item(
                "obstacle_forces",
                PyArray1::from_vec(py, per_obstacle).reshape([frames, k, 3])?,
            )?;
            d.set_item(
                "translations",
                PyArray1::from_vec(py, translations).reshape([frames, k, 3])?,
            )?;
            d.set_item(
                "min_distance",
                PyArray1::from_vec(py, distances).reshape([frames, k])?,
            )?;
            d.set_item(
                "active",
                PyArray1::from_vec(py, active).reshape([frames, k])?,
            )?;
            d.set_item(
                "iterate_min_distances",
                trajectory.iterate_min_distances.clone(),
            )?;
            out.set_item("contact", d)?;
        }
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
    m.add_function(wrap_pyfunction!(_contact_reference, m)?)?;
    m.add_function(wrap_pyfunction!(check_obstacle, m)?)?;
    m.add_function(wrap_pyfunction!(check_contact, m)?)?;
    m.add_class::<Model>()?;
    Ok(())
}
