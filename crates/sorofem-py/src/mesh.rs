//! `Mesh`: a mesh validated once, with its geometric queries; and the original module-level
//! mesh functions, which build a mesh per call.

use crate::convert;
use crate::errors::{guarded, IntoPyResult};
use numpy::{PyArray1, PyArray2, PyArrayMethods};
use pyo3::prelude::*;
use sorofem_core::{Orientation, TetMesh};
use std::sync::Arc;

/// A validated tetrahedral mesh in its rest configuration (points in m, tets positively
/// oriented). Models built from it share it.
#[pyclass(module = "sorofem._core", name = "Mesh", frozen)]
pub struct Mesh {
    pub inner: Arc<TetMesh>,
    reoriented: Vec<usize>,
}

pub fn build(
    py: Python<'_>,
    points: &Bound<'_, PyAny>,
    tets: &Bound<'_, PyAny>,
    orientation: Orientation,
) -> PyResult<(TetMesh, Vec<usize>)> {
    let points = convert::points("points", points).py(py)?;
    let tets = convert::tets("tets", tets).py(py)?;
    guarded(py, || TetMesh::try_new(points, &tets, orientation))
}

impl Mesh {
    /// A Python handle on a mesh the core already holds.
    pub fn shared(inner: Arc<TetMesh>) -> Self {
        Mesh {
            inner,
            reoriented: Vec::new(),
        }
    }
}

fn indices_to_numpy<'py>(py: Python<'py>, indices: &[usize]) -> Bound<'py, PyArray1<i64>> {
    PyArray1::from_vec(py, indices.iter().map(|&i| i as i64).collect())
}

#[pymethods]
impl Mesh {
    /// Validates `points` (n, 3) and `tets` (m, 4); orientation "reorient" (swap the last two
    /// nodes of inverted tets, listed in `reoriented`) or "reject" (MeshError).
    #[new]
    #[pyo3(signature = (points, tets, orientation = "reorient"))]
    fn new(
        py: Python<'_>,
        points: &Bound<'_, PyAny>,
        tets: &Bound<'_, PyAny>,
        orientation: &str,
    ) -> PyResult<Self> {
        let orientation = convert::orientation(orientation).py(py)?;
        let (mesh, reoriented) = build(py, points, tets, orientation)?;
        Ok(Mesh {
            inner: Arc::new(mesh),
            reoriented,
        })
    }

    /// A box `[origin, origin + size]` of `cells` hexahedra, 6 tets each.
    #[staticmethod]
    #[pyo3(name = "box")]
    fn box_(
        py: Python<'_>,
        size: &Bound<'_, PyAny>,
        cells: &Bound<'_, PyAny>,
        origin: &Bound<'_, PyAny>,
    ) -> PyResult<Self> {
        let mesh = box_of(py, size, cells, origin)?;
        Ok(Mesh {
            inner: Arc::new(mesh),
            reoriented: Vec::new(),
        })
    }

    /// Rest coordinates (n, 3), m (a copy).
    #[getter]
    fn points<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        convert::points_to_numpy(py, self.inner.rest().as_flattened())
    }

    /// Tetrahedra (m, 4), positively oriented (a copy).
    #[getter]
    fn tets<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<i64>> {
        convert::tets_to_numpy(py, self.inner.tets())
    }

    /// Rest volume of each tet (m,), m^3.
    #[getter]
    fn volumes<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, self.inner.volumes())
    }

    /// Indices of the tets that were inverted in the input and reoriented.
    #[getter]
    fn reoriented<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<i64>> {
        indices_to_numpy(py, &self.reoriented)
    }

    #[getter]
    fn n_nodes(&self) -> usize {
        self.inner.n_nodes()
    }

    #[getter]
    fn n_tets(&self) -> usize {
        self.inner.n_tets()
    }

    /// Length of the bounding-box diagonal, m: the length scale of relative tolerances.
    #[getter]
    fn diameter(&self) -> f64 {
        self.inner.diameter()
    }

    /// Outward-oriented boundary triangles (k, 3) and the tet each belongs to (k,).
    fn boundary_faces<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<(Bound<'py, PyArray2<i64>>, Bound<'py, PyArray1<i64>>)> {
        let mesh = self.inner.clone();
        let boundary = guarded(py, move || Ok(mesh.boundary()))?;
        let faces: Vec<[usize; 3]> = boundary.iter().map(|b| b.0).collect();
        let owners: Vec<usize> = boundary.iter().map(|b| b.1).collect();
        Ok((
            convert::faces_to_numpy(py, &faces),
            indices_to_numpy(py, &owners),
        ))
    }

    /// Sorted indices of the nodes inside the closed box `[min, max]` (each (3,), m).
    #[pyo3(signature = (min, max))]
    fn nodes_in_box<'py>(
        &self,
        py: Python<'py>,
        min: &Bound<'py, PyAny>,
        max: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArray1<i64>>> {
        let (min, max) = (
            convert::vec3("min", min).py(py)?,
            convert::vec3("max", max).py(py)?,
        );
        let mesh = self.inner.clone();
        let nodes = guarded(py, move || {
            TetMesh::check_box(min, max)?;
            Ok(mesh.nodes_in_box(min, max))
        })?;
        Ok(indices_to_numpy(py, &nodes))
    }

    /// Sorted indices of the nodes within `tol * diameter` of the plane through `point` with
    /// normal `normal` (any non-zero length): the tolerance is relative to the mesh size.
    #[pyo3(signature = (point, normal, tol = sorofem_core::tolerance::ON_PLANE))]
    fn nodes_on_plane<'py>(
        &self,
        py: Python<'py>,
        point: &Bound<'py, PyAny>,
        normal: &Bound<'py, PyAny>,
        tol: f64,
    ) -> PyResult<Bound<'py, PyArray1<i64>>> {
        let (point, normal) = (
            convert::vec3("point", point).py(py)?,
            convert::vec3("normal", normal).py(py)?,
        );
        let mesh = self.inner.clone();
        let nodes = guarded(py, move || mesh.nodes_on_plane(point, normal, tol))?;
        Ok(indices_to_numpy(py, &nodes))
    }

    /// Where each of `points` (k, 3) lies: the tet containing it (or, within `search_radius` m
    /// outside the mesh, the closest one; -1 when none), its barycentric weights in that tet
    /// (k, 4; of the closest point when outside) and the distance to that point (k,), m.
    #[pyo3(signature = (points, search_radius = 0.0))]
    #[allow(clippy::type_complexity)]
    fn locate<'py>(
        &self,
        py: Python<'py>,
        points: &Bound<'py, PyAny>,
        search_radius: f64,
    ) -> PyResult<(
        Bound<'py, PyArray1<i64>>,
        Bound<'py, PyArray2<f64>>,
        Bound<'py, PyArray1<f64>>,
    )> {
        let points = convert::points("points", points).py(py)?;
        let mesh = self.inner.clone();
        let located = guarded(py, move || {
            sorofem_core::locate::locate_points(&mesh, &points, search_radius)
        })?;
        let tets: Vec<i64> = (located.iter())
            .map(|l| l.as_ref().map_or(-1, |l| l.tet as i64))
            .collect();
        let weights: Vec<f64> = (located.iter())
            .flat_map(|l| l.as_ref().map_or([f64::NAN; 4], |l| l.weights))
            .collect();
        let distances: Vec<f64> = (located.iter())
            .map(|l| l.as_ref().map_or(f64::INFINITY, |l| l.distance))
            .collect();
        Ok((
            PyArray1::from_vec(py, tets),
            PyArray1::from_vec(py, weights).reshape([located.len(), 4])?,
            PyArray1::from_vec(py, distances),
        ))
    }

    fn __repr__(&self) -> String {
        format!(
            "Mesh({} nodes, {} tets)",
            self.inner.n_nodes(),
            self.inner.n_tets()
        )
    }
}

fn box_of(
    py: Python<'_>,
    size: &Bound<'_, PyAny>,
    cells: &Bound<'_, PyAny>,
    origin: &Bound<'_, PyAny>,
) -> PyResult<TetMesh> {
    let size = convert::vec3("size", size).py(py)?;
    let cells = convert::indices("cells", cells).py(py)?;
    let origin = convert::vec3("origin", origin).py(py)?;
    guarded(py, move || {
        if cells.len() != 3 || cells.iter().any(|&c| c < 1) {
            return Err(sorofem_core::Error::invalid(
                "cells",
                "three positive cell counts",
                format!("{cells:?}"),
            ));
        }
        TetMesh::box_mesh(
            size,
            [cells[0] as usize, cells[1] as usize, cells[2] as usize],
            origin,
        )
    })
}

/// Box mesh `[origin, origin + size]` with `cells` hexahedra split into 6 tets each.
#[pyfunction]
pub fn box_mesh<'py>(
    py: Python<'py>,
    size: &Bound<'py, PyAny>,
    cells: &Bound<'py, PyAny>,
    origin: &Bound<'py, PyAny>,
) -> PyResult<(Bound<'py, PyArray2<f64>>, Bound<'py, PyArray2<i64>>)> {
    let mesh = box_of(py, size, cells, origin)?;
    Ok((
        convert::points_to_numpy(py, &mesh.rest_flat()),
        convert::tets_to_numpy(py, mesh.tets()),
    ))
}

/// Validates a mesh; returns the (possibly reoriented) tets and the indices of reoriented ones.
#[pyfunction]
#[pyo3(signature = (points, tets, orientation = "reorient"))]
pub fn check_mesh<'py>(
    py: Python<'py>,
    points: &Bound<'py, PyAny>,
    tets: &Bound<'py, PyAny>,
    orientation: &str,
) -> PyResult<(Bound<'py, PyArray2<i64>>, Bound<'py, PyArray1<i64>>)> {
    let orientation = convert::orientation(orientation).py(py)?;
    let (mesh, reoriented) = build(py, points, tets, orientation)?;
    Ok((
        convert::tets_to_numpy(py, mesh.tets()),
        indices_to_numpy(py, &reoriented),
    ))
}

/// Rest volumes (m^3) of a valid mesh.
#[pyfunction]
pub fn rest_volumes<'py>(
    py: Python<'py>,
    points: &Bound<'py, PyAny>,
    tets: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let (mesh, _) = build(py, points, tets, Orientation::Reject)?;
    Ok(PyArray1::from_slice(py, mesh.volumes()))
}

/// Outward-oriented boundary triangles of a valid mesh.
#[pyfunction]
pub fn boundary_faces<'py>(
    py: Python<'py>,
    points: &Bound<'py, PyAny>,
    tets: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyArray2<i64>>> {
    let (mesh, _) = build(py, points, tets, Orientation::Reject)?;
    Ok(convert::faces_to_numpy(py, &mesh.boundary_faces()))
}
