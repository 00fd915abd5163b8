//! A body ready to be solved many times: mesh, boundary conditions, formulation, the sparsity
//! pattern and the symbolic factorisation (built once), and the material (changeable).

use crate::assembly::Assembler;
use crate::cables::{embed, CableSpec, PointPlacement};
use crate::energy::elastic::{PressureCompliance, PressureIterates, PressureLinearisations};
use crate::energy::{CableTerm, ElasticTerm, GravityTerm, HessianMode, NodalForceTerm, Term};
pub use crate::energy::{Formulation as ElementFormulation, PressureMass};
use crate::error::{check_finite, Error, Result};
use crate::linear::SparseFactor;
use crate::material::{neo_hookean::von_mises, Volumetric};
use crate::mesh::TetMesh;
use crate::newton::{self, NewtonOptions, NewtonProblem, SolveReport, Timings};
use std::sync::Arc;
use std::time::Instant;

/// The discretisation of the volumetric response.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Formulation {
    /// Displacement-only P1 tetrahedra (locks as nu -> 0.5).
    Standard,
    /// P1 displacement + P1 nodal pressure, solved as a saddle-point system.
    Mixed { mass: PressureMass },
}

/// Per-tet material parameters: shear modulus and Lame's lambda (Pa), density (kg/m^3).
#[derive(Clone, Debug)]
pub struct Material {
    pub mu: Vec<f64>,
    pub lambda: Vec<f64>,
    pub density: Vec<f64>,
}

/// External loads of one solve. `prescribed` has one displacement (m) per fixed node, in the
/// order the fixed nodes were given; `nodal_forces` pairs node indices with forces (N).
#[derive(Clone, Debug, Default)]
pub struct Loads {
    pub gravity: [f64; 3],
    pub nodal_forces: Vec<(usize, [f64; 3])>,
    pub prescribed: Vec<[f64; 3]>,
}

pub type SolveOptions = NewtonOptions;

/// An equilibrium: positions (m, 3 n node-major), nodal pressures (Pa, mixed only), the
/// reaction force (N) at each fixed node (in the order they were given), the position (m) of
/// every cable point and the tension (N) of every cable segment, and the report.
#[derive(Clone, Debug)]
pub struct Solution {
    pub positions: Vec<f64>,
    pub pressure: Option<Vec<f64>>,
    pub reactions: Vec<[f64; 3]>,
    pub cable_points: Vec<Vec<[f64; 3]>>,
    pub cable_tensions: Vec<Vec<f64>>,
    pub report: SolveReport,
}

pub struct Model {
    pub(crate) mesh: Arc<TetMesh>,
    pub(crate) fixed_nodes: Vec<usize>,
    pub(crate) formulation: Formulation,
    pub(crate) elastic: ElasticTerm,
    pub(crate) cables: CableTerm,
    pub(crate) placements: Vec<Vec<PointPlacement>>,
    /// Rest position (m) and mass (kg) of each free cable node.
    pub(crate) free_nodes: Vec<([f64; 3], f64)>,
    pub(crate) density: Vec<f64>,
    pub(crate) assembler: Assembler,
    pub(crate) factor: SparseFactor,
    /// The Newton iterations' Hessian values, kept between assemblies (see
    /// [`crate::assembly::Assembler::evaluate_into`]).
    hessian_scratch: crate::assembly::Evaluation,
    /// Weight (Pa/m) of the volume-constraint residual rows (m^3) in the mixed residual norm,
    /// so that they are measured in N like the force rows: `mean(mu) / mean edge length`.
    pub(crate) pressure_weight: f64,
    /// Free-node displacements and pressures of the last solve: a warm start's starting guess.
    pub(crate) last_extra: Option<Vec<f64>>,
    pub(crate) material_set: bool,
    /// Full DOF vector and loads of the last static solve (what sensitivities differentiate).
    pub(crate) last_state: Option<(Vec<f64>, Loads)>,
    /// The factorisation holds the Hessian at `last_state` (not a Newton iterate's).
    pub(crate) factor_at_solution: bool,
}

impl Model {
    /// Builds the DOF layout, the sparsity pattern and its symbolic factorisation.
    pub fn try_new(
        mesh: Arc<TetMesh>,
        fixed_nodes: &[i64],
        formulation: Formulation,
        volumetric: Volumetric,
    ) -> Result<Self> {
        Self::try_new_with_cables(mesh, fixed_nodes, formulation, volumetric, &[])
    }

    /// [`Model::try_new`] with cables. Full DOFs: `3 n` node displacements, then `3 m` free cable
    /// node displacements, then (mixed) `n` nodal pressures.
    pub fn try_new_with_cables(
        mesh: Arc<TetMesh>,
        fixed_nodes: &[i64],
        formulation: Formulation,
        volumetric: Volumetric,
        cables: &[CableSpec],
    ) -> Result<Self> {
        let n = mesh.n_nodes();
        let mut fixed_set = vec![false; n];
        let mut fixed = Vec::with_capacity(fixed_nodes.len());
        for (position, &node) in fixed_nodes.iter().enumerate() {
            if node < 0 || node as usize >= n {
                return Err(Error::IndexOutOfRange {
                    param: "fixed".into(),
                    position,
                    index: node,
                    len: n,
                });
            }
            if fixed_set[node as usize] {
                return Err(Error::invalid(
                    "fixed",
                    "each node at most once",
                    format!("node {node} repeated"),
                ));
            }
            fixed_set[node as usize] = true;
            fixed.push(node as usize);
        }
        let n_tets = mesh.n_tets();
        let embedded = embed(&mesh, cables)?;
        let n_displacement = 3 * n + 3 * embedded.free_nodes.len();
        let element_formulation = match formulation {
            Formulation::Standard => ElementFormulation::Standard,
            Formulation::Mixed { mass } => ElementFormulation::Mixed {
                pressure_offset: n_displacement,
                mass,
            },
        };
        let elastic = ElasticTerm {
            mesh: mesh.clone(),
            mu: vec![1.0; n_tets],
            lambda: vec![1.0; n_tets],
            volumetric,
            formulation: element_formulation,
            pressure_iterates: None,
        };
        let n_full = match formulation {
            Formulation::Standard => n_displacement,
            Formulation::Mixed { .. } => n_displacement + n,
        };
        let cable_term = CableTerm::new(embedded.cables);
        let mut fixed_dofs = vec![false; n_full];
        for &node in &fixed {
            fixed_dofs[3 * node..3 * node + 3].fill(true);
        }
        let (assembler, factor) = match formulation {
            // The symbolic factorisation needs only the pattern: it runs beside the element plans.
            Formulation::Standard => {
                let (assembler, factor) =
                    Assembler::new_with(&fixed_dofs, &[&elastic, &cable_term], |pattern| {
                        SparseFactor::analyse(pattern)
                    });
                (assembler, factor?)
            }
            Formulation::Mixed { mass } => {
                let compliance = PressureCompliance {
                    elastic: &elastic,
                    mass,
                };
                let mut free_of_full = vec![None; n_full];
                for (index, d) in (0..n_full).filter(|&d| !fixed_dofs[d]).enumerate() {
                    free_of_full[d] = Some(index);
                }
                let (assembler, factor) =
                    Assembler::new_with(&fixed_dofs, &[&elastic, &cable_term], |pattern| {
                        // The pressure unknowns live on the nodes, so this pattern is the node graph.
                        let node_graph =
                            crate::assembly::pattern_of(&vec![false; n], &[&compliance]);
                        let node_order = crate::linear::amd_order(&node_graph)?;
                        let order = saddle_point_order(
                            &free_of_full,
                            &node_order,
                            &fixed_set,
                            n_displacement,
                        );
                        SparseFactor::analyse_with_order(pattern, &order)
                    });
                (assembler, factor?)
            }
        };
        Ok(Model {
            mesh,
            fixed_nodes: fixed,
            formulation,
            elastic,
            cables: cable_term,
            placements: embedded.placements,
            free_nodes: embedded.free_nodes,
            density: vec![0.0; n_tets],
            assembler,
            factor,
            hessian_scratch: Default::default(),
            pressure_weight: 1.0,
            last_extra: None,
            material_set: false,
            last_state: None,
            factor_at_solution: false,
        })
    }

    pub fn mesh(&self) -> &Arc<TetMesh> {
        &self.mesh
    }

    pub fn formulation(&self) -> Formulation {
        self.formulation
    }

    pub fn fixed_nodes(&self) -> &[usize] {
        &self.fixed_nodes
    }

    /// Number of Newton unknowns (free displacement DOFs plus pressures).
    pub fn n_free(&self) -> usize {
        self.assembler.n_free()
    }

    /// Rest length of each segment of each cable (m), between the points the cable is attached
    /// to (a snapped point sits on the mesh, not where the user put it).
    pub fn cable_rest_lengths(&self) -> Vec<Vec<f64>> {
        self.cables
            .cables
            .iter()
            .map(|c| c.rest_lengths.clone())
            .collect()
    }

    /// Where each cable point was placed (embedded, snapped, free node or anchor).
    pub fn cable_placements(&self) -> &[Vec<PointPlacement>] {
        &self.placements
    }

    pub fn n_cables(&self) -> usize {
        self.cables.cables.len()
    }

    /// Cable `cable` for modification (callers invalidate the last solution when they change it).
    fn cable_mut(&mut self, cable: usize) -> Result<&mut crate::energy::Cable> {
        let len = self.n_cables();
        self.cables
            .cables
            .get_mut(cable)
            .ok_or_else(|| Error::IndexOutOfRange {
                param: "cable".into(),
                position: 0,
                index: cable as i64,
                len,
            })
    }

    /// Sets cable `cable`'s actuation alpha (> 0; 1 = rest length, < 1 = pulled).
    pub fn set_actuation(&mut self, cable: usize, actuation: f64) -> Result<()> {
        if !(actuation > 0.0 && actuation.is_finite()) {
            return Err(Error::invalid(
                "actuation",
                "alpha > 0 (1 = rest, < 1 = pulled)",
                actuation,
            ));
        }
        let target = self.cable_mut(cable)?;
        if target.actuation != actuation {
            target.actuation = actuation;
            self.last_state = None;
        }
        Ok(())
    }

    /// Sets cable `cable`'s segment stiffness (N/m, > 0).
    pub fn set_cable_stiffness(&mut self, cable: usize, stiffness: f64) -> Result<()> {
        if !(stiffness > 0.0 && stiffness.is_finite()) {
            return Err(Error::invalid(
                "stiffness",
                "a finite stiffness > 0 N/m",
                stiffness,
            ));
        }
        let target = self.cable_mut(cable)?;
        if target.stiffness != stiffness {
            target.stiffness = stiffness;
            self.last_state = None;
        }
        Ok(())
    }

    /// The terms whose sum is the internal energy, in the assembler's order.
    pub(crate) fn terms(&self) -> [&dyn Term; 2] {
        [&self.elastic, &self.cables]
    }

    /// Sets per-tet parameters. Requires `mu > 0`, `0 <= lambda < inf` (`> 0` when mixed), `density >= 0`.
    pub fn set_material(&mut self, material: &Material) -> Result<()> {
        let m = self.mesh.n_tets();
        for (name, values) in [
            ("mu", &material.mu),
            ("lambda", &material.lambda),
            ("density", &material.density),
        ] {
            if values.len() != m {
                return Err(Error::shape(
                    name,
                    format!("{m} values (one per tet)"),
                    format!("{}", values.len()),
                ));
            }
            check_finite(name, values)?;
        }
        if let Some(e) = material.mu.iter().position(|&v| !(v > 0.0)) {
            return Err(Error::invalid(
                "mu",
                "shear modulus > 0 Pa",
                format!("{} at tet {e}", material.mu[e]),
            ));
        }
        // The mixed formulation divides by lambda (C = M_p / lambda); the standard one allows nu = 0.
        let mixed = matches!(self.formulation, Formulation::Mixed { .. });
        if let Some(e) =
            material
                .lambda
                .iter()
                .position(|&v| if mixed { !(v > 0.0) } else { !(v >= 0.0) })
        {
            let expected = if mixed {
                "Lame lambda > 0 Pa in the mixed formulation (0 < nu < 0.5; nu = 0.5 has no finite lambda and \
                 leaves the P1-P1 pressure modes uncontrolled)"
            } else {
                "Lame lambda >= 0 Pa (0 <= nu < 0.5)"
            };
            return Err(Error::invalid(
                "lambda",
                expected,
                format!("{} at tet {e}", material.lambda[e]),
            ));
        }
        if let Some(e) = material.density.iter().position(|&v| v < 0.0) {
            return Err(Error::invalid(
                "density",
                "density >= 0 kg/m^3",
                format!("{} at tet {e}", material.density[e]),
            ));
        }
        let changed = self.elastic.mu != material.mu
            || self.elastic.lambda != material.lambda
            || self.density != material.density;
        self.elastic.mu.clone_from(&material.mu);
        self.elastic.lambda.clone_from(&material.lambda);
        self.density.clone_from(&material.density);
        if matches!(self.formulation, Formulation::Mixed { .. }) {
            let m = m as f64;
            let mean_mu = material.mu.iter().sum::<f64>() / m;
            let mean_edge =
                (self.mesh.volumes().iter().sum::<f64>() / m * 6.0 * 2f64.sqrt()).cbrt();
            self.pressure_weight = mean_mu / mean_edge;
        }
        // New parameters make the last solution (and any factorisation at it) stale: sensitivities
        // then need a new solve rather than silently mixing old positions with new parameters.
        self.material_set = true;
        if changed {
            self.factor_at_solution = false;
            self.last_state = None;
        }
        Ok(())
    }

    /// Static equilibrium under `loads`, starting from `initial` positions (3 n, m) or the rest shape.
    /// Internally the unknowns are displacements from the rest shape. In the mixed formulation a
    /// warm start (`initial` given) also starts from the pressures of the previous solve.
    pub fn solve(
        &mut self,
        loads: &Loads,
        initial: Option<&[f64]>,
        options: &SolveOptions,
    ) -> Result<Solution> {
        if !self.material_set {
            return Err(Error::invalid(
                "material",
                "set_material() before solve()",
                "no material",
            ));
        }
        let n = self.mesh.n_nodes();
        check_finite("gravity", &loads.gravity)?;
        if loads.prescribed.len() != self.fixed_nodes.len() && !loads.prescribed.is_empty() {
            return Err(Error::shape(
                "prescribed",
                format!(
                    "({}, 3): one displacement per fixed node",
                    self.fixed_nodes.len()
                ),
                format!("({}, 3)", loads.prescribed.len()),
            ));
        }
        check_finite("prescribed", loads.prescribed.as_flattened())?;
        for (position, &(node, force)) in loads.nodal_forces.iter().enumerate() {
            if node >= n {
                return Err(Error::IndexOutOfRange {
                    param: "forces".into(),
                    position,
                    index: node as i64,
                    len: n,
                });
            }
            check_finite("forces", &force)?;
        }
        let mut z = vec![0.0; self.assembler.n_full()];
        match initial {
            Some(x) => {
                if x.len() != 3 * n {
                    return Err(Error::shape(
                        "initial",
                        format!("({n}, 3) positions"),
                        format!("{} values", x.len()),
                    ));
                }
                check_finite("initial", x)?;
                for (zi, (xi, ri)) in z.iter_mut().zip(x.iter().zip(self.mesh.rest_flat())) {
                    *zi = xi - ri;
                }
                // A warm start continues from the last equilibrium, free nodes and pressures included.
                if let Some(extra) = &self.last_extra {
                    z[3 * n..].copy_from_slice(extra);
                }
            }
            None => {}
        }
        let full_load = self.load_vector(loads);
        let prescribed = if loads.prescribed.is_empty() {
            vec![[0.0; 3]; self.fixed_nodes.len()]
        } else {
            loads.prescribed.clone()
        };
        let mut problem = System::new(self, full_load, prescribed, None, options);
        // Only the prescribed displacements are scaled by the load factor: the initial guess is
        // kept as given for the free DOFs, which is what warm starts need.
        // The Newton loop runs on a worker of the thread pool. On the calling thread, its
        // single-threaded factorisations left both workers asleep for 15 ms at a time, and every
        // element pass after one was about 1.5x slower (12k-tet cantilever, 2 cores).
        let report = rayon::scope(|_| newton::solve(&mut problem, &mut z, options))?;
        let full_load = std::mem::take(&mut problem.full_load);
        drop(problem);
        // Reaction = internal force minus applied load at the supports, so that the reactions
        // balance the loads: sum(reactions) + sum(loads) = 0 at equilibrium.
        let internal = self.assembler.full_gradient(&self.terms(), &z);
        let reactions = self
            .fixed_nodes
            .iter()
            .map(|&i| std::array::from_fn(|k| internal[3 * i + k] - full_load[3 * i + k]))
            .collect();
        self.last_state = Some((z.clone(), loads.clone()));
        self.factor_at_solution = false;
        let n_displacement = 3 * n + 3 * self.free_nodes.len();
        let pressure = matches!(self.formulation, Formulation::Mixed { .. })
            .then(|| z[n_displacement..].to_vec());
        self.last_extra = Some(z[3 * n..].to_vec());
        let cable_points = self
            .cables
            .cables
            .iter()
            .map(|cable| {
                (0..cable.points.len())
                    .map(|k| cable.position(k, &z).into())
                    .collect()
            })
            .collect();
        let cable_tensions = self
            .cables
            .cables
            .iter()
            .map(|cable| {
                (0..cable.n_segments())
                    .map(|k| cable.tension(k, &z))
                    .collect()
            })
            .collect();
        z.truncate(3 * n);
        for (zi, ri) in z.iter_mut().zip(self.mesh.rest_flat()) {
            *zi += ri;
        }
        Ok(Solution {
            positions: z,
            pressure,
            reactions,
            cable_points,
            cable_tensions,
            report,
        })
    }

    /// External load vector (N, full DOFs) of `loads`, free cable nodes' weight included.
    fn load_vector(&self, loads: &Loads) -> Vec<f64> {
        let n = self.mesh.n_nodes();
        let gravity = GravityTerm {
            mesh: self.mesh.clone(),
            density: self.density.clone(),
            gravity: loads.gravity,
        };
        let free_node_weights = self
            .free_nodes
            .iter()
            .enumerate()
            .map(|(i, &(_, mass))| (n + i, loads.gravity.map(|g| mass * g)));
        let point_forces: Vec<(usize, [f64; 3])> = loads
            .nodal_forces
            .iter()
            .copied()
            .chain(free_node_weights)
            .collect();
        let forces = NodalForceTerm {
            nodes: point_forces.iter().map(|f| f.0).collect(),
            forces: point_forces.iter().map(|f| f.1).collect(),
        };
        self.assembler.load_vector(&[&gravity, &forces])
    }

    /// Lumped mass (kg) of every full DOF: `rho V / 4` per tet and node, free cable nodes' own
    /// masses, zero for pressures.
    pub(crate) fn lumped_mass(&self) -> Vec<f64> {
        let n = self.mesh.n_nodes();
        let mut mass = vec![0.0; self.assembler.n_full()];
        for (e, tet) in self.mesh.tets().iter().enumerate() {
            let m = self.density[e] * self.mesh.volumes()[e] / 4.0;
            for &i in tet {
                for k in 0..3 {
                    mass[3 * i + k] += m;
                }
            }
        }
        for (i, &(_, m)) in self.free_nodes.iter().enumerate() {
            mass[3 * (n + i)..3 * (n + i) + 3].fill(m);
        }
        mass
    }

    /// Implicit Euler in time: each step minimises the incremental potential
    /// `1/2 |u - u_n - h v_n|_M^2 / h^2 + 1/2 |u - u_n|_D^2 / h + Pi(u)` (lumped mass M,
    /// Rayleigh damping `D = alpha_M M + beta_K K_n`), then `v = (u - u_n) / h`. A step whose
    /// Newton solve fails is split in two, up to six times. `actuation[s][c]` is cable c's
    /// alpha during step s. Starts from `initial_positions` (3 n, m; default rest; free cable nodes
    /// and pressures then continue from the last solve) at rest or with `initial_velocities`
    /// (3 n, m/s).
    #[allow(clippy::too_many_arguments)]
    pub fn simulate(
        &mut self,
        loads: &Loads,
        dt: f64,
        steps: usize,
        actuation: &[Vec<f64>],
        damping: Damping,
        initial_positions: Option<&[f64]>,
        initial_velocities: Option<&[f64]>,
        options: &SolveOptions,
        save_every: usize,
    ) -> Result<Trajectory> {
        if !self.material_set {
            return Err(Error::invalid(
                "material",
                "set_material() before simulate()",
                "no material",
            ));
        }
        if !(dt > 0.0 && dt.is_finite()) {
            return Err(Error::invalid("dt", "a time step > 0 s", dt));
        }
        if actuation.len() != steps || actuation.iter().any(|row| row.len() != self.n_cables()) {
            return Err(Error::shape(
                "actuation",
                format!(
                    "({steps}, {}): one alpha per step and cable",
                    self.n_cables()
                ),
                format!("{} rows", actuation.len()),
            ));
        }
        if !(damping.mass >= 0.0 && damping.stiffness >= 0.0) {
            return Err(Error::invalid(
                "damping",
                "Rayleigh coefficients >= 0",
                format!("{damping:?}"),
            ));
        }
        let n = self.mesh.n_nodes();
        let prescribed = if loads.prescribed.is_empty() {
            vec![[0.0; 3]; self.fixed_nodes.len()]
        } else {
            loads.prescribed.clone()
        };
        let full_load = self.load_vector(loads);
        let rest = self.mesh.rest_flat();
        let mut z = vec![0.0; self.assembler.n_full()];
        if let Some(x) = initial_positions {
            if x.len() != 3 * n {
                return Err(Error::shape(
                    "initial_positions",
                    format!("({n}, 3)"),
                    format!("{} values", x.len()),
                ));
            }
            check_finite("initial_positions", x)?;
            for i in 0..3 * n {
                z[i] = x[i] - rest[i];
            }
            // Continuing from a previous state: free cable nodes and pressures too.
            if let Some(extra) = &self.last_extra {
                z[3 * n..].copy_from_slice(extra);
            }
        }
        let free: Vec<usize> = self.assembler.full_of_free().to_vec();
        let mass_full = self.lumped_mass();
        let mass: Vec<f64> = free.iter().map(|&d| mass_full[d]).collect();
        let mut velocity = vec![0.0; free.len()];
        if let Some(v) = initial_velocities {
            if v.len() != 3 * n {
                return Err(Error::shape(
                    "initial_velocities",
                    format!("({n}, 3)"),
                    format!("{} values", v.len()),
                ));
            }
            check_finite("initial_velocities", v)?;
            for (f, &d) in free.iter().enumerate() {
                if d < 3 * n {
                    velocity[f] = v[d];
                }
            }
        }
        let diagonal: Vec<usize> = (0..free.len())
            .map(|f| {
                self.assembler
                    .pattern()
                    .position(f, f)
                    .expect("diagonal in pattern")
            })
            .collect();
        let n_free_displacement = match self.formulation {
            Formulation::Standard => free.len(),
            Formulation::Mixed { .. } => free.len() - n,
        };
        let step_options = SolveOptions {
            load_steps: 1,
            max_cutbacks: 0,
            ..options.clone()
        };
        let mut trajectory = Trajectory::default();
        let save =
            |model: &Model, z: &[f64], velocity: &[f64], t: f64, trajectory: &mut Trajectory| {
                trajectory.times.push(t);
                trajectory
                    .positions
                    .push((0..3 * n).map(|i| rest[i] + z[i]).collect());
                trajectory.cable_points.push(
                    model
                        .cables
                        .cables
                        .iter()
                        .map(|c| {
                            (0..c.points.len())
                                .map(|k| c.position(k, z).into())
                                .collect()
                        })
                        .collect(),
                );
                trajectory.kinetic_energy.push(
                    0.5 * mass
                        .iter()
                        .zip(velocity)
                        .map(|(m, v)| m * v * v)
                        .sum::<f64>(),
                );
            };
        save(self, &z, &velocity, 0.0, &mut trajectory);
        let mut time = 0.0;
        for (s, alphas) in actuation.iter().enumerate() {
            for (c, &alpha) in alphas.iter().enumerate() {
                self.set_actuation(c, alpha)?;
            }
            // Halve the step on failure: a queue of sub-steps that must add up to dt.
            let mut pending = vec![(dt, 0usize)];
            let mut iterations = 0;
            while let Some((h, depth)) = pending.pop() {
                let previous: Vec<f64> = free.iter().map(|&d| z[d]).collect();
                let predicted: Vec<f64> = previous
                    .iter()
                    .zip(&velocity)
                    .map(|(u, v)| u + h * v)
                    .collect();
                let stiffness_damping = if damping.stiffness > 0.0 {
                    let mut k = self
                        .assembler
                        .evaluate(&self.terms(), &z, false, Some(HessianMode::Projected))
                        .hessian;
                    let pattern = self.assembler.pattern();
                    for col in 0..pattern.n {
                        for p in pattern.col_ptr[col]..pattern.col_ptr[col + 1] {
                            let row = pattern.row_idx[p];
                            k[p] = if row < n_free_displacement && col < n_free_displacement {
                                k[p] * damping.stiffness / h
                            } else {
                                0.0
                            };
                        }
                    }
                    k
                } else {
                    Vec::new()
                };
                let step = StepTerms {
                    inertia: mass.iter().map(|m| m / (h * h)).collect(),
                    predicted: predicted.clone(),
                    previous: previous.clone(),
                    mass_damping: mass.iter().map(|m| damping.mass * m / h).collect(),
                    stiffness_damping,
                    diagonal: diagonal.clone(),
                };
                let mut trial = z.clone();
                for (f, &d) in free.iter().enumerate() {
                    if f < n_free_displacement {
                        trial[d] = predicted[f];
                    }
                }
                let mut problem = System::new(
                    self,
                    full_load.clone(),
                    prescribed.clone(),
                    Some(step),
                    options,
                );
                problem.model.cables.begin_step(h, &z);
                let outcome =
                    rayon::scope(|_| newton::solve(&mut problem, &mut trial, &step_options));
                problem.model.cables.end_step();
                drop(problem);
                match outcome {
                    Ok(report) => {
                        iterations += report.iterations;
                        for (f, &d) in free.iter().enumerate() {
                            velocity[f] = if f < n_free_displacement {
                                (trial[d] - previous[f]) / h
                            } else {
                                0.0
                            };
                        }
                        z = trial;
                    }
                    Err(Error::NotConverged { report, .. }) if depth < 6 => {
                        iterations += report.iterations;
                        trajectory.cutbacks += 1;
                        pending.push((h / 2.0, depth + 1));
                        pending.push((h / 2.0, depth + 1));
                    }
                    Err(Error::NotConverged { mut report, .. }) => {
                        let message = format!(
                            "time step {s} (t = {time:.4} s) did not converge even at dt = {h:.3e} s; last relative residuals: {:?}",
                            report.residual_history.iter().rev().take(5).rev().map(|r| format!("{r:.3e}")).collect::<Vec<_>>()
                        );
                        report.message = message.clone();
                        return Err(Error::NotConverged { message, report });
                    }
                    Err(other) => return Err(other),
                }
            }
            time += dt;
            trajectory.iterations.push(iterations);
            if (s + 1) % save_every.max(1) == 0 || s + 1 == steps {
                save(self, &z, &velocity, time, &mut trajectory);
            }
        }
        let mut v_nodes = vec![0.0; 3 * n];
        for (f, &d) in free.iter().enumerate() {
            if d < 3 * n {
                v_nodes[d] = velocity[f];
            }
        }
        trajectory.velocities = v_nodes;
        self.last_extra = Some(z[3 * n..].to_vec());
        self.last_state = None;
        self.factor_at_solution = false;
        Ok(trajectory)
    }

    /// Per-tet volume ratio `J = det F` and von Mises Cauchy stress (Pa) at `positions` (3 n).
    /// In the mixed formulation the stress uses the element's volumetric response
    /// `lambda c(J) c'(J) J` of the same energy, so both formulations report comparable stresses.
    pub fn element_fields(&self, positions: &[f64]) -> Result<(Vec<f64>, Vec<f64>)> {
        let n = self.mesh.n_nodes();
        if positions.len() != 3 * n {
            return Err(Error::shape(
                "positions",
                format!("({n}, 3)"),
                format!("{} values", positions.len()),
            ));
        }
        let u: Vec<f64> = positions
            .iter()
            .zip(self.mesh.rest_flat())
            .map(|(x, r)| x - r)
            .collect();
        let mut j = Vec::with_capacity(self.mesh.n_tets());
        let mut vm = Vec::with_capacity(self.mesh.n_tets());
        for e in 0..self.mesh.n_tets() {
            let f = self.mesh.deformation_gradient(e, &u);
            j.push(f.determinant());
            vm.push(
                self.elastic
                    .material(e)
                    .cauchy_stress(&f)
                    .map_or(f64::NAN, |s| von_mises(&s)),
            );
        }
        Ok((j, vm))
    }
}

/// Elimination order of the mixed saddle-point system: nodes in fill-reducing (AMD) order, each
/// node's free displacements before its pressure, and the pressures of fixed nodes (which couple
/// to no displacement of their own) last. Every pressure pivot then carries `G K^{-1} G^T` and
/// not just the compliance `C = M_p / lambda`, which vanishes as nu -> 0.5.
fn saddle_point_order(
    free_of_full: &[Option<usize>],
    node_order: &[usize],
    fixed: &[bool],
    pressure_offset: usize,
) -> Vec<usize> {
    let n = fixed.len();
    let mut order = Vec::with_capacity(free_of_full.len());
    // Free cable nodes carry no pressure: eliminate them first, like any displacement.
    order.extend((3 * n..pressure_offset).filter_map(|d| free_of_full[d]));
    for &node in node_order {
        for d in 3 * node..3 * node + 3 {
            order.extend(free_of_full[d]);
        }
        if !fixed[node] {
            order.extend(free_of_full[pressure_offset + node]);
        }
    }
    for node in (0..n).filter(|&i| fixed[i]) {
        order.extend(free_of_full[pressure_offset + node]);
    }
    order
}

/// The Newton view of a model at a load factor.
struct System<'a> {
    model: &'a mut Model,
    /// External forces (N, full DOFs) at load factor 1, and at the current factor.
    full_load: Vec<f64>,
    load: Vec<f64>,
    load_free_norm: f64,
    prescribed: Vec<[f64; 3]>,
    /// Inertia and damping of an implicit Euler step, when the solve is one.
    step: Option<StepTerms>,
    /// [`NewtonOptions::pressure_iterates`] (standard formulation only).
    pressure_iterates: bool,
    /// The element pressures linearised at the current iterate, when `linearised_at_iterate`
    /// (swapped in from those the Hessian pass there recorded).
    linearised_pressures: PressureLinearisations,
    linearised_at_iterate: bool,
    /// The element pressure iterates of the current iterate (the model's elastic term holds
    /// those of the state last moved to with `trial_iterates`).
    pressure_base: Vec<f64>,
    /// The model's Hessian scratch holds the exact Hessian at the state last evaluated.
    hessian_prepared: bool,
}

/// The pressure iterates belong to one solve: the model's Hessians are exact again afterwards
/// (sensitivities, the next solve), whichever way the solve ended.
impl Drop for System<'_> {
    fn drop(&mut self) {
        self.model.elastic.pressure_iterates = None;
    }
}

/// The quadratic terms implicit Euler adds to the energy (free DOFs `d`):
/// `1/2 sum_d inertia_d (u_d - predicted_d)^2 + 1/2 (u - previous)^T D (u - previous)` with
/// `inertia = m / h^2` and the Rayleigh damping `D = (alpha_M M + beta_K K_n) / h`, `K_n` the
/// projected (positive semi-definite) displacement Hessian at the start of the step.
struct StepTerms {
    inertia: Vec<f64>,
    predicted: Vec<f64>,
    previous: Vec<f64>,
    mass_damping: Vec<f64>,
    /// `beta_K / h K_n` in the Hessian's lower-triangle layout (empty without stiffness damping).
    stiffness_damping: Vec<f64>,
    diagonal: Vec<usize>,
}

impl StepTerms {
    fn energy(&self, free: &[f64], pattern: &crate::linear::LowerPattern) -> f64 {
        let mut e = 0.0;
        for d in 0..free.len() {
            let a = free[d] - self.predicted[d];
            let b = free[d] - self.previous[d];
            e += 0.5 * (self.inertia[d] * a * a + self.mass_damping[d] * b * b);
        }
        if !self.stiffness_damping.is_empty() {
            let delta: Vec<f64> = free
                .iter()
                .zip(&self.previous)
                .map(|(x, y)| x - y)
                .collect();
            let kd = pattern.symmetric_matvec(&self.stiffness_damping, &delta);
            e += 0.5 * kd.iter().zip(&delta).map(|(a, b)| a * b).sum::<f64>();
        }
        e
    }

    fn add_gradient(&self, free: &[f64], pattern: &crate::linear::LowerPattern, g: &mut [f64]) {
        for d in 0..free.len() {
            g[d] += self.inertia[d] * (free[d] - self.predicted[d])
                + self.mass_damping[d] * (free[d] - self.previous[d]);
        }
        if !self.stiffness_damping.is_empty() {
            let delta: Vec<f64> = free
                .iter()
                .zip(&self.previous)
                .map(|(x, y)| x - y)
                .collect();
            for (gi, kd) in g
                .iter_mut()
                .zip(pattern.symmetric_matvec(&self.stiffness_damping, &delta))
            {
                *gi += kd;
            }
        }
    }

    fn add_hessian(&self, hessian: &mut [f64]) {
        for (d, &p) in self.diagonal.iter().enumerate() {
            hessian[p] += self.inertia[d] + self.mass_damping[d];
        }
        for (h, k) in hessian.iter_mut().zip(&self.stiffness_damping) {
            *h += k;
        }
    }
}

/// Rayleigh damping `C = mass M + stiffness K` (1/s and s).
#[derive(Clone, Copy, Debug, Default)]
pub struct Damping {
    pub mass: f64,
    pub stiffness: f64,
}

/// Frames of a dynamic simulation.
#[derive(Clone, Debug, Default)]
pub struct Trajectory {
    pub times: Vec<f64>,
    /// Node positions (m, 3 n) per saved frame.
    pub positions: Vec<Vec<f64>>,
    pub cable_points: Vec<Vec<Vec<[f64; 3]>>>,
    /// Kinetic energy (J) per saved frame.
    pub kinetic_energy: Vec<f64>,
    /// Node velocities (m/s, 3 n) at the end.
    pub velocities: Vec<f64>,
    /// Newton iterations of every step (a cut step counts its sub-steps' sum).
    pub iterations: Vec<usize>,
    /// Times a step was halved after a Newton failure.
    pub cutbacks: usize,
}

impl<'a> System<'a> {
    fn new(
        model: &'a mut Model,
        full_load: Vec<f64>,
        prescribed: Vec<[f64; 3]>,
        step: Option<StepTerms>,
        options: &SolveOptions,
    ) -> Self {
        let pressure_iterates =
            options.pressure_iterates && model.formulation == Formulation::Standard;
        System {
            model,
            full_load,
            load: Vec::new(),
            load_free_norm: 0.0,
            prescribed,
            step,
            pressure_iterates,
            linearised_pressures: PressureLinearisations::new(0),
            linearised_at_iterate: false,
            pressure_base: Vec::new(),
            hessian_prepared: false,
        }
    }
}

impl System<'_> {
    fn n_nodes(&self) -> usize {
        self.model.mesh.n_nodes()
    }

    fn is_mixed(&self) -> bool {
        matches!(self.model.formulation, Formulation::Mixed { .. })
    }

    /// Takes the pressure linearisation the last Hessian pass recorded as that of the current
    /// iterate (the caller knows the pass was there).
    fn take_recorded_linearisation(&mut self) {
        if let Some(iterates) = &mut self.model.elastic.pressure_iterates {
            std::mem::swap(&mut self.linearised_pressures, &mut iterates.recorded);
            self.linearised_at_iterate = true;
        }
    }

    fn free_values(&self, z: &[f64]) -> Vec<f64> {
        self.model
            .assembler
            .full_of_free()
            .iter()
            .map(|&d| z[d])
            .collect()
    }

    /// The merit (see [`NewtonProblem::merit_and_gradient`]) from the terms' energy and
    /// gradient at `z`.
    fn merit(&self, z: &[f64], energy: f64, gradient: Vec<f64>) -> (f64, Vec<f64>) {
        if !energy.is_finite() {
            return (f64::INFINITY, vec![f64::INFINITY; gradient.len()]);
        }
        let mut g = gradient;
        for (gi, &d) in g.iter_mut().zip(self.model.assembler.full_of_free()) {
            *gi -= self.load[d];
        }
        let free_values = self.step.as_ref().map(|_| self.free_values(z));
        if let (Some(step), Some(free)) = (&self.step, &free_values) {
            step.add_gradient(free, self.model.assembler.pattern(), &mut g);
        }
        if self.is_mixed() {
            let n = self.n_nodes();
            let len = g.len();
            g[len - n..]
                .iter_mut()
                .for_each(|v| *v *= self.model.pressure_weight);
            if g.iter().any(|v| !v.is_finite()) {
                return (f64::INFINITY, g);
            }
            return (0.5 * g.iter().map(|v| v * v).sum::<f64>(), g);
        }
        let external: f64 = self.load.iter().zip(z.iter()).map(|(f, x)| f * x).sum();
        let mut energy = energy - external;
        if let (Some(step), Some(free)) = (&self.step, &free_values) {
            energy += step.energy(free, self.model.assembler.pattern());
        }
        (energy, g)
    }
}

impl NewtonProblem for System<'_> {
    fn n_free(&self) -> usize {
        self.model.assembler.n_free()
    }

    fn set_load_factor(&mut self, factor: f64, z: &mut [f64]) {
        self.load = self.full_load.iter().map(|f| f * factor).collect();
        self.load_free_norm = self
            .model
            .assembler
            .full_of_free()
            .iter()
            .map(|&d| self.load[d] * self.load[d])
            .sum::<f64>()
            .sqrt();
        for (&node, u) in self.model.fixed_nodes.iter().zip(&self.prescribed) {
            for k in 0..3 {
                z[3 * node + k] = factor * u[k];
            }
        }
    }

    fn load_norm(&self) -> f64 {
        self.load_free_norm
    }

    /// Merit, standard: the potential energy. Mixed: half the squared weighted residual of the
    /// saddle-point system. The pressure is a Lagrange multiplier, so the mixed energy has no
    /// minimum to descend to, and eliminating p through `C p = phi` would amplify the
    /// second-order constraint error of every step by lambda (tiny steps as nu -> 0.5).
    ///
    /// Gradient: of the energy minus the loads; in the mixed formulation the volume-constraint
    /// rows (m^3) are multiplied by the pressure weight so that they are forces too.
    fn merit_and_gradient(&mut self, z: &mut [f64]) -> (f64, Vec<f64>) {
        self.hessian_prepared = false;
        let eval = self
            .model
            .assembler
            .evaluate(&self.model.terms(), z, true, None);
        self.merit(z, eval.energy, eval.gradient)
    }

    fn merit_gradient_and_hessian(&mut self, z: &mut [f64]) -> (f64, Vec<f64>) {
        let mut eval = std::mem::take(&mut self.model.hessian_scratch);
        self.model.assembler.evaluate_into(
            &self.model.terms(),
            z,
            true,
            Some(HessianMode::Exact),
            &mut eval,
        );
        let (energy, gradient) = (eval.energy, std::mem::take(&mut eval.gradient));
        self.model.hessian_scratch = eval;
        self.hessian_prepared = energy.is_finite();
        self.merit(z, energy, gradient)
    }

    fn slope(&self, g: &[f64], d: &[f64]) -> f64 {
        if self.is_mixed() {
            // d is an exact Newton step of the residual g, so d/dt (|g|^2 / 2) = -|g|^2.
            -g.iter().map(|v| v * v).sum::<f64>()
        } else {
            g.iter().zip(d).map(|(a, b)| a * b).sum()
        }
    }

    fn merit_is_energy(&self) -> bool {
        !self.is_mixed()
    }

    fn nonmonotone_factor(&self) -> f64 {
        // Half the squared residual may grow 100-fold (the residual 10-fold) over the recent
        // maximum: full Newton steps of the saddle-point system are then accepted far from the
        // solution, where the Armijo test on the residual would creep in 1/16 steps.
        if self.is_mixed() {
            100.0
        } else {
            0.0
        }
    }

    fn direction(
        &mut self,
        z: &[f64],
        g: &[f64],
        projected: bool,
        timings: &mut Timings,
    ) -> Result<Option<Vec<f64>>> {
        let mode = if projected {
            HessianMode::Projected
        } else {
            HessianMode::Exact
        };
        let t0 = Instant::now();
        let mut eval = std::mem::take(&mut self.model.hessian_scratch);
        if !(self.hessian_prepared && mode == HessianMode::Exact) {
            self.model.assembler.evaluate_into(
                &self.model.terms(),
                z,
                false,
                Some(mode),
                &mut eval,
            );
            self.take_recorded_linearisation();
        }
        self.hessian_prepared = false;
        if let Some(step) = &self.step {
            step.add_hessian(&mut eval.hessian);
        }
        timings.assembly += t0.elapsed().as_secs_f64();
        let pattern = self.model.assembler.pattern();
        let t0 = Instant::now();
        let factor = &mut self.model.factor;
        let ok = match self.model.elastic.formulation {
            ElementFormulation::Standard => factor.factor_llt(pattern, &eval.hessian),
            ElementFormulation::Mixed { .. } => factor.factor_ldlt(pattern, &eval.hessian),
        };
        let seconds = t0.elapsed().as_secs_f64();
        self.model.hessian_scratch = eval;
        let ok = ok?;
        timings.factorization += seconds;
        timings.factorizations += 1;
        if !ok {
            timings.failed_factorization += seconds;
            timings.failed_factorizations += 1;
            return Ok(None);
        }
        let t0 = Instant::now();
        let mut d: Vec<f64> = g.iter().map(|v| -v).collect();
        if self.is_mixed() {
            let n = self.n_nodes();
            let len = d.len();
            d[len - n..]
                .iter_mut()
                .for_each(|v| *v /= self.model.pressure_weight);
        }
        self.model.factor.solve_in_place(&mut d);
        timings.solve += t0.elapsed().as_secs_f64();
        // No inertia test for the mixed formulation: the condensed curvature
        // du^T A du + dp^T C dp cancels catastrophically when the pressure (and so K_geo(p)) is
        // large.
        let usable = if self.is_mixed() {
            d.iter().all(|v| v.is_finite())
        } else {
            d.iter().zip(g).map(|(a, b)| a * b).sum::<f64>() < 0.0
        };
        if !usable {
            timings.failed_factorization += seconds;
            timings.failed_factorizations += 1;
        }
        Ok(usable.then_some(d))
    }

    fn start_iterates(&mut self, z: &[f64]) {
        if self.pressure_iterates {
            self.pressure_base = self.model.elastic.pressures_at(z);
            self.model.elastic.pressure_iterates =
                Some(PressureIterates::new(self.pressure_base.clone()));
            // Swapped with the recorded ones: both sized for every tet.
            if self.linearised_pressures.len() != self.pressure_base.len() {
                self.linearised_pressures = PressureLinearisations::new(self.pressure_base.len());
            }
            self.linearised_at_iterate = false;
        }
    }

    fn trial_iterates(&mut self, z: &[f64], d: &[f64], t: f64) {
        if self.pressure_iterates {
            let mut dz = vec![0.0; z.len()];
            for (&full, di) in self.model.assembler.full_of_free().iter().zip(d) {
                dz[full] = *di;
            }
            if !self.linearised_at_iterate {
                self.linearised_pressures = self.model.elastic.linearised_pressures(z);
                self.linearised_at_iterate = true;
            }
            if let Some(iterates) = &mut self.model.elastic.pressure_iterates {
                iterates.values.clone_from(&self.pressure_base);
            }
            self.model
                .elastic
                .advance_pressures(&self.linearised_pressures, &dz, t);
        }
    }

    fn commit_iterates(&mut self) {
        if let Some(iterates) = &self.model.elastic.pressure_iterates {
            self.pressure_base.clone_from(&iterates.values);
            self.linearised_at_iterate = false;
            // Accepted where the line search built the next Hessian: that pass recorded the
            // linearisation at the new iterate.
            if self.hessian_prepared {
                self.take_recorded_linearisation();
            }
        }
    }

    fn step(&self, z: &mut [f64], d: &[f64], t: f64) {
        for (&full, di) in self.model.assembler.full_of_free().iter().zip(d) {
            z[full] += t * di;
        }
    }

    /// No mesh node may move farther than the rest mesh's bounding-box diagonal in one step.
    fn step_bound(&self, d: &[f64]) -> f64 {
        let n = self.n_nodes();
        let mut squared = vec![0.0; n];
        for (&full, di) in self.model.assembler.full_of_free().iter().zip(d) {
            if full < 3 * n {
                squared[full / 3] += di * di;
            }
        }
        let longest = squared.iter().fold(0.0f64, |m, &v| m.max(v)).sqrt();
        if longest > self.model.mesh.diameter() {
            self.model.mesh.diameter() / longest
        } else {
            1.0
        }
    }
}
