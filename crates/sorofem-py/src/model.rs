//! `Model`: a body ready to be solved many times (sorofem.model.Body owns one). Every call into
//! the core goes through [`guarded`], or, when Ctrl-C should stop it (solves, time
//! integration), [`interruptible`].

use crate::convert;
use crate::errors::{guarded, report_to_dict, timings_to_dict, to_py, IntoPyResult};
use crate::interrupt::interruptible;
use crate::mesh::Mesh;
use crate::options::SolveOptions;
use numpy::{PyArray1, PyArray2, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use sorofem_core::energy::TendonCommand;
use sorofem_core::{Material, SolveOptions as CoreOptions, TetMesh};
use std::sync::Arc;

/// A body ready to be solved many times (see sorofem.model.Body, which owns one).
#[pyclass(module = "sorofem._core")]
pub struct Model {
    pub(crate) inner: sorofem_core::Model,
}

impl Model {
    fn build(
        py: Python<'_>,
        mesh: Arc<TetMesh>,
        fixed: &Bound<'_, PyAny>,
        formulation: &str,
        options: Option<&Bound<'_, PyDict>>,
        cables: Option<&Bound<'_, PyList>>,
        terms: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Self> {
        let specs = convert::term_specs(terms, cables).py(py)?;
        let fixed = convert::indices("fixed", fixed).py(py)?;
        let volumetric = match convert::string_option(options, "volumetric").py(py)? {
            Some(name) => convert::volumetric(&name).py(py)?,
            None => sorofem_core::material::Volumetric::Log,
        };
        let mass = match convert::string_option(options, "pressure_mass").py(py)? {
            Some(name) => convert::pressure_mass(&name).py(py)?,
            None => sorofem_core::PressureMass::Consistent,
        };
        let formulation = convert::formulation(formulation, mass).py(py)?;
        let inner = guarded(py, || {
            sorofem_core::Model::try_new_with_terms(mesh, &fixed, formulation, volumetric, &specs)
        })?;
        Ok(Model { inner })
    }

    /// The Newton settings of a solve: `options`, or else the keyword arguments (not both).
    pub(crate) fn solve_options(
        py: Python<'_>,
        options: Option<&SolveOptions>,
        tolerance: Option<f64>,
        max_iterations: Option<usize>,
        load_steps: Option<usize>,
    ) -> PyResult<CoreOptions> {
        let keywords = tolerance.is_some() || max_iterations.is_some() || load_steps.is_some();
        match options {
            Some(_) if keywords => Err(to_py(
                py,
                sorofem_core::Error::invalid(
                    "options",
                    "either a SolveOptions or the keyword arguments tolerance, max_iterations, load_steps",
                    "both",
                ),
            )),
            Some(options) => Ok(options.inner.clone()),
            None => {
                let defaults = CoreOptions::default();
                let options = CoreOptions {
                    tolerance: tolerance.unwrap_or(defaults.tolerance),
                    max_iterations: max_iterations.unwrap_or(defaults.max_iterations),
                    load_steps: load_steps.unwrap_or(defaults.load_steps),
                    ..defaults
                };
                options.validate().py(py)?;
                Ok(options)
            }
        }
    }
}

#[pymethods]
impl Model {
    #[new]
    #[pyo3(signature = (points, tets, fixed, formulation = "standard", options = None, cables = None, terms = None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        points: &Bound<'_, PyAny>,
        tets: &Bound<'_, PyAny>,
        fixed: &Bound<'_, PyAny>,
        formulation: &str,
        options: Option<&Bound<'_, PyDict>>,
        cables: Option<&Bound<'_, PyList>>,
        terms: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Self> {
        let (mesh, _) = crate::mesh::build(py, points, tets, sorofem_core::Orientation::Reject)?;
        Self::build(
            py,
            Arc::new(mesh),
            fixed,
            formulation,
            options,
            cables,
            terms,
        )
    }

    /// A model of `mesh` (shared, not copied); the other arguments as for the constructor.
    #[staticmethod]
    #[pyo3(signature = (mesh, fixed, formulation = "standard", options = None, cables = None, terms = None))]
    fn from_mesh(
        py: Python<'_>,
        mesh: &Mesh,
        fixed: &Bound<'_, PyAny>,
        formulation: &str,
        options: Option<&Bound<'_, PyDict>>,
        cables: Option<&Bound<'_, PyList>>,
        terms: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Self> {
        Self::build(
            py,
            mesh.inner.clone(),
            fixed,
            formulation,
            options,
            cables,
            terms,
        )
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
        guarded(py, || inner.set_material(&material))
    }

    /// Sets the material model by name ("neo_hookean", "mooney_rivlin", "yeoh", "ogden"), its
    /// parameters as a dict of per-tet arrays by name (see `material_param_names`), the density
    /// (m,) kg/m^3, and the model's options ("neo_hookean": "volumetric", default the
    /// constructor's; "ogden": "terms", 1 to 3).
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
        guarded(py, || inner.set_material_model(model, &params, &density))
    }

    /// The material model's name ("neo_hookean", "mooney_rivlin", "yeoh", "ogden").
    #[getter]
    fn material_model(&self) -> &'static str {
        self.inner.material_model().name()
    }

    /// The material's parameter names, in storage order.
    #[getter]
    fn material_param_names(&self) -> Vec<String> {
        self.inner.material_param_names()
    }

    /// The mesh the model is built on (shared).
    #[getter]
    fn mesh(&self) -> Mesh {
        Mesh::shared(self.inner.mesh().clone())
    }

    /// Static equilibrium; returns a dict with "positions", "pressure", "reactions" (one row per
    /// fixed node, N), "cable_points" (per cable (k, 3), m), "cable_tensions" (per cable (k-1,),
    /// N) and the report entries.
    /// Newton settings: `options` (a SolveOptions) or the keyword arguments `tolerance`
    /// (default 1e-8), `max_iterations` (50, per load step) and `load_steps` (1).
    #[pyo3(signature = (gravity, forces, prescribed, initial = None, tolerance = None, max_iterations = None, load_steps = None, *, options = None))]
    #[allow(clippy::too_many_arguments)]
    fn solve<'py>(
        &mut self,
        py: Python<'py>,
        gravity: &Bound<'py, PyAny>,
        forces: &Bound<'py, PyAny>,
        prescribed: &Bound<'py, PyAny>,
        initial: Option<&Bound<'py, PyAny>>,
        tolerance: Option<f64>,
        max_iterations: Option<usize>,
        load_steps: Option<usize>,
        options: Option<PyRef<'py, SolveOptions>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let n = self.inner.mesh().n_nodes();
        let loads = convert::loads(py, n, gravity, forces, prescribed)?;
        let initial = initial
            .filter(|i| !i.is_none())
            .map(|i| convert::points("initial", i))
            .transpose()
            .py(py)?;
        let initial_flat: Option<Vec<f64>> = initial.map(|p| p.into_iter().flatten().collect());
        let options = Self::solve_options(
            py,
            options.as_deref(),
            tolerance,
            max_iterations,
            load_steps,
        )?;
        let inner = &mut self.inner;
        let solution = interruptible(py, |interrupt| {
            let options = CoreOptions {
                interrupt,
                ..options
            };
            inner.solve(&loads, initial_flat.as_deref(), &options)
        })?;
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
        out.set_item("tendon_tensions", &solution.tendon_tensions)?;
        out.set_item("tendon_pulls", &solution.tendon_pulls)?;
        match solution.pressure {
            Some(p) => out.set_item("pressure", PyArray1::from_vec(py, p))?,
            None => out.set_item("pressure", py.None())?,
        }
        match &solution.contact {
            Some(contact) => {
                let d = crate::contact::forces_to_dict(py, &contact.forces)?;
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
    /// velocity (m/s), whether the body's surface may touch itself and whether the barrier
    /// stiffness adapts; `None` takes the core's defaults. An empty list without self-contact
    /// removes contact.
    #[pyo3(signature = (obstacles, dhat = None, stiffness = None, friction_slip = None, friction_velocity = None, self_contact = false, adaptive_stiffness = true))]
    #[allow(clippy::too_many_arguments)] // the keyword arguments of the Python call
    fn set_contact(
        &mut self,
        py: Python<'_>,
        obstacles: &Bound<'_, PyList>,
        dhat: Option<f64>,
        stiffness: Option<f64>,
        friction_slip: Option<f64>,
        friction_velocity: Option<f64>,
        self_contact: bool,
        adaptive_stiffness: bool,
    ) -> PyResult<()> {
        let setup = sorofem_core::contact::ContactSetup {
            obstacles: crate::contact::obstacle_specs(py, obstacles)?,
            dhat,
            stiffness,
            friction_slip,
            friction_velocity,
            self_contact,
            adaptive_stiffness,
        };
        let inner = &mut self.inner;
        guarded(py, || inner.set_contact(setup))
    }

    /// The contact settings in force: {"dhat": m, "stiffness": J/m^4 or None before the first
    /// solve, "adaptive_stiffness", "n_obstacles"}, or None without obstacles.
    fn contact_settings<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        let Some(contact) = self.inner.contact() else {
            return Ok(None);
        };
        let d = PyDict::new(py);
        d.set_item("dhat", contact.dhat())?;
        d.set_item("stiffness", contact.reference_stiffness())?;
        d.set_item("adaptive_stiffness", contact.adaptive_stiffness())?;
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
        let inner = &self.inner;
        match guarded(py, || inner.contact_forces(&positions))? {
            Some(forces) => Ok(Some(crate::contact::forces_to_dict(py, &forces)?)),
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
        let inner = &self.inner;
        let g = guarded(py, || inner.contact_force_gradient(obstacle, w))?;
        Ok(convert::points_to_numpy(py, &g))
    }

    /// Checks every accepted Newton iterate for intersections in full (a test diagnostic): one
    /// records a minimum distance of -inf.
    fn set_contact_audit(&mut self, on: bool) {
        self.inner.set_contact_audit(on);
    }

    /// Implicit Euler dynamics; returns a dict with "times", "positions" (frames, n, 3),
    /// "velocities" (n, 3), "cable_points", "kinetic_energy", "iterations", "factorizations",
    /// "residuals" (per step), "cutbacks" and "timings". Newton settings per time step:
    /// `options` (its `load_steps` and `max_cutbacks` do not apply: a failed step is halved,
    /// up to six times) or the keyword arguments `tolerance` and `max_iterations`; `method`
    /// "newton", "modified" or "linearly_implicit".
    #[pyo3(signature = (gravity, forces, prescribed, dt, steps, actuation, mass_damping = 0.0, stiffness_damping = 0.0, initial_positions = None, initial_velocities = None, tolerance = None, max_iterations = None, save_every = 1, *, options = None, method = "modified"))]
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
        tolerance: Option<f64>,
        max_iterations: Option<usize>,
        save_every: usize,
        options: Option<PyRef<'py, SolveOptions>>,
        method: &str,
    ) -> PyResult<Bound<'py, PyDict>> {
        let n = self.inner.mesh().n_nodes();
        let loads = convert::loads(py, n, gravity, forces, prescribed)?;
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
        let options = sorofem_core::DynamicsOptions {
            newton: Self::solve_options(py, options.as_deref(), tolerance, max_iterations, None)?,
            method: sorofem_core::StepMethod::from_name(method).py(py)?,
            save_every,
        };
        let damping = sorofem_core::Damping {
            mass: mass_damping,
            stiffness: stiffness_damping,
        };
        let inner = &mut self.inner;
        let trajectory = interruptible(py, |interrupt| {
            let options = sorofem_core::DynamicsOptions {
                newton: CoreOptions {
                    interrupt,
                    ..options.newton
                },
                ..options
            };
            inner.simulate_with(
                &loads,
                dt,
                steps,
                &actuation,
                damping,
                x0.as_deref(),
                v0.as_deref(),
                &options,
            )
        })?;
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
        out.set_item("tendon_tensions", &trajectory.tendon_tensions)?;
        out.set_item("tendon_pulls", &trajectory.tendon_pulls)?;
        out.set_item(
            "kinetic_energy",
            PyArray1::from_slice(py, &trajectory.kinetic_energy),
        )?;
        out.set_item("iterations", trajectory.iterations)?;
        out.set_item("factorizations", trajectory.factorizations)?;
        out.set_item("residuals", trajectory.residuals)?;
        out.set_item("cutbacks", trajectory.cutbacks)?;
        out.set_item(
            "single_precision_factorizations",
            trajectory.timings.single_precision_factorizations,
        )?;
        if !trajectory.contact.is_empty() {
            let contact = crate::contact::trajectory_to_dict(
                py,
                &trajectory.contact,
                &trajectory.iterate_min_distances,
                n,
            )?;
            out.set_item("contact", contact)?;
        }
        out.set_item("timings", timings_to_dict(py, &trajectory.timings)?)?;
        Ok(out)
    }

    /// Seconds of each of `repeats` bare numeric factorisations of the Hessian at the last
    /// equilibrium (benchmark diagnostic).
    fn time_factorization(&mut self, py: Python<'_>, repeats: usize) -> PyResult<Vec<f64>> {
        let inner = &mut self.inner;
        guarded(py, || inner.time_factorization(repeats))
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
        let gradient = guarded(py, || inner.adjoint(&g))?;
        convert::param_vector_to_dict(py, &gradient, &self.inner.material_param_names())
    }

    /// Forward sensitivity along a parameter direction (dict with any of the adjoint's keys):
    /// returns {"dx": (n, 3), "dp": (n,) or None, "dtension": per cable, the tendon's tension
    /// change (N) or None for a spring cable}.
    fn forward<'py>(
        &mut self,
        py: Python<'py>,
        direction: &Bound<'py, PyDict>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let delta = convert::param_direction(direction, &self.inner.param_zeros()).py(py)?;
        let inner = &mut self.inner;
        let (dx, dp, dtension) = guarded(py, || inner.forward_with_tensions(&delta))?;
        let out = PyDict::new(py);
        out.set_item("dx", convert::points_to_numpy(py, &dx))?;
        out.set_item("dtension", dtension)?;
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
        let inner = &self.inner;
        let (j, vm) = guarded(py, || inner.element_fields(&positions))?;
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
        let inner = &mut self.inner;
        guarded(py, || inner.set_actuation(cable, actuation))
    }

    /// Sets cable `cable`'s segment stiffness (N/m).
    fn set_cable_stiffness(
        &mut self,
        py: Python<'_>,
        cable: usize,
        stiffness: f64,
    ) -> PyResult<()> {
        let inner = &mut self.inner;
        guarded(py, || inner.set_cable_stiffness(cable, stiffness))
    }

    /// Sets spring cable `cable`'s dashpot coefficient (N s/m).
    fn set_cable_damping(&mut self, py: Python<'_>, cable: usize, damping: f64) -> PyResult<()> {
        let inner = &mut self.inner;
        guarded(py, || inner.set_cable_damping(cable, damping))
    }

    /// Sets tendon `cable`'s command: `kind` "pull" (m) or "tension" (N).
    fn set_tendon_command(
        &mut self,
        py: Python<'_>,
        cable: usize,
        kind: &str,
        value: f64,
    ) -> PyResult<()> {
        let command = match kind {
            "pull" => TendonCommand::Pull(value),
            "tension" => TendonCommand::Tension(value),
            other => {
                return Err(to_py(
                    py,
                    sorofem_core::Error::invalid(
                        "kind",
                        "\"pull\" or \"tension\"",
                        format!("{other:?}"),
                    ),
                ))
            }
        };
        let inner = &mut self.inner;
        guarded(py, || inner.set_tendon_command(cable, command))
    }

    /// Strain energy (J) of the body at positions (n, 3): the elastic term alone.
    fn strain_energy(&self, py: Python<'_>, positions: &Bound<'_, PyAny>) -> PyResult<f64> {
        let positions: Vec<f64> = convert::points("positions", positions)
            .py(py)?
            .into_iter()
            .flatten()
            .collect();
        let inner = &self.inner;
        guarded(py, || inner.strain_energy(&positions))
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
