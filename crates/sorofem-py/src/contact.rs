//! Contact plumbing: the obstacle and contact checks, the ipctk comparison hook of the tests, and
//! the contact entries of solve and simulate results.

use crate::convert;
use crate::errors::{guarded, to_py, IntoPyResult};
use numpy::{PyArray1, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use sorofem_core::model::ContactFrame;
use sorofem_core::Orientation;

/// The contact forces of a state as a dict: "forces" (n, 3), "obstacle_forces" (k, 3) N,
/// "min_distance" (k,) m (NaN: nothing within the report radius), "active" (k,), and for
/// self-contact "self_active" (stencils within dhat) and "self_min_distance" (m, NaN: nothing
/// within the report radius or no self-contact).
pub fn forces_to_dict<'py>(
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
    d.set_item("self_active", forces.self_active)?;
    d.set_item(
        "self_min_distance",
        forces.self_min_distance.unwrap_or(f64::NAN),
    )?;
    Ok(d)
}

/// The contact entries of a trajectory with obstacles: "forces" (frames, n, 3) and
/// "obstacle_forces" (frames, k, 3) N, "translations" (frames, k, 3) m, "min_distance"
/// (frames, k) m, "active" (frames, k), "iterate_min_distances" (one per accepted iterate, m).
pub fn trajectory_to_dict<'py>(
    py: Python<'py>,
    contact: &[ContactFrame],
    iterate_min_distances: &[f64],
    n: usize,
) -> PyResult<Bound<'py, PyDict>> {
    let frames = contact.len();
    let k = contact.first().map_or(0, |c| c.translations.len());
    let gather = |f: &dyn Fn(&ContactFrame) -> Vec<f64>| -> Vec<f64> {
        contact.iter().flat_map(f).collect()
    };
    let nodal = gather(&|c| c.forces.nodal.as_flattened().to_vec());
    let per_obstacle = gather(&|c| c.forces.per_obstacle.as_flattened().to_vec());
    let translations = gather(&|c| c.translations.as_flattened().to_vec());
    let distances = gather(&|c| {
        c.forces
            .min_distance
            .iter()
            .map(|d| d.unwrap_or(f64::NAN))
            .collect()
    });
    let active: Vec<i64> = contact
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
    d.set_item("iterate_min_distances", iterate_min_distances.to_vec())?;
    Ok(d)
}

/// The obstacles of a list of dicts (see [`convert::obstacle_spec`]).
pub fn obstacle_specs(
    py: Python<'_>,
    obstacles: &Bound<'_, PyList>,
) -> PyResult<Vec<sorofem_core::contact::ObstacleSpec>> {
    obstacles
        .iter()
        .enumerate()
        .map(|(k, item)| convert::obstacle_spec(k, &item))
        .collect::<Result<Vec<_>, _>>()
        .py(py)
}

/// The contact kernels at one configuration of four points `x` (4, 3), for the comparison with
/// ipctk in the tests: squared point-triangle and edge-edge distances (point 0 and triangle
/// 1-3; edges 0-1 and 2-3) with gradients (12,) and Hessians (12, 12), the edge-edge mollifier
/// (threshold from `x` itself), and the barrier b(d; dhat^2) and its two derivatives at the
/// point-triangle distance d.
#[pyfunction]
pub fn _contact_reference<'py>(
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
        return Err(to_py(
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
pub fn check_obstacle<'py>(
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

/// Checks obstacles against a body mesh at rest (each apart from it, and the body's surface
/// apart from itself with self-contact: the error names the obstacle, the node or triangle and
/// the distance) and the contact settings; returns {"dhat": m}, the activation distance in
/// force (the default when `dhat` is None).
#[pyfunction]
#[pyo3(signature = (points, tets, obstacles, dhat = None, self_contact = false))]
pub fn check_contact<'py>(
    py: Python<'py>,
    points: &Bound<'py, PyAny>,
    tets: &Bound<'py, PyAny>,
    obstacles: &Bound<'py, PyList>,
    dhat: Option<f64>,
    self_contact: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let (mesh, _) = crate::mesh::build(py, points, tets, Orientation::Reject)?;
    let setup = sorofem_core::contact::ContactSetup {
        obstacles: obstacle_specs(py, obstacles)?,
        dhat,
        self_contact,
        ..Default::default()
    };
    let term = guarded(py, || {
        sorofem_core::contact::ContactTerm::try_new(&mesh, setup)
    })?;
    let out = PyDict::new(py);
    out.set_item("dhat", term.dhat())?;
    Ok(out)
}
