//! A body ready to be solved many times: mesh, boundary conditions, formulation, the sparsity
//! pattern and the symbolic factorisation (built once), and the material (changeable).

use crate::assembly::Assembler;
use crate::energy::elastic::PressureCompliance;
use crate::energy::{ElasticTerm, GravityTerm, HessianMode, NodalForceTerm};
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

/// An equilibrium: positions (m, 3 n node-major), nodal pressures (Pa, mixed only) and the report.
#[derive(Clone, Debug)]
pub struct Solution {
    pub positions: Vec<f64>,
    pub pressure: Option<Vec<f64>>,
    pub report: SolveReport,
}

/// Factorised pressure compliance `C` (mixed formulation): `p* = C^{-1} phi(x)`.
struct PressureSolver {
    assembler: Assembler,
    factor: SparseFactor,
}

pub struct Model {
    mesh: Arc<TetMesh>,
    fixed_nodes: Vec<usize>,
    formulation: Formulation,
    elastic: ElasticTerm,
    density: Vec<f64>,
    assembler: Assembler,
    factor: SparseFactor,
    pressure: Option<PressureSolver>,
    material_set: bool,
}

impl Model {
    /// Builds the DOF layout, the sparsity pattern and its symbolic factorisation.
    pub fn try_new(
        mesh: Arc<TetMesh>,
        fixed_nodes: &[i64],
        formulation: Formulation,
        volumetric: Volumetric,
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
        let element_formulation = match formulation {
            Formulation::Standard => ElementFormulation::Standard,
            Formulation::Mixed { mass } => ElementFormulation::Mixed {
                pressure_offset: 3 * n,
                mass,
            },
        };
        let elastic = ElasticTerm {
            mesh: mesh.clone(),
            mu: vec![1.0; n_tets],
            lambda: vec![1.0; n_tets],
            volumetric,
            formulation: element_formulation,
        };
        let n_full = match formulation {
            Formulation::Standard => 3 * n,
            Formulation::Mixed { .. } => 4 * n,
        };
        let mut fixed_dofs = vec![false; n_full];
        for &node in &fixed {
            fixed_dofs[3 * node..3 * node + 3].fill(true);
        }
        let assembler = Assembler::new(&fixed_dofs, &[&elastic]);
        let factor = SparseFactor::analyse(assembler.pattern())?;
        let pressure = match formulation {
            Formulation::Standard => None,
            Formulation::Mixed { mass } => {
                let compliance = PressureCompliance {
                    elastic: &elastic,
                    mass,
                };
                let assembler = Assembler::new(&vec![false; n], &[&compliance]);
                let factor = SparseFactor::analyse(assembler.pattern())?;
                Some(PressureSolver { assembler, factor })
            }
        };
        Ok(Model {
            mesh,
            fixed_nodes: fixed,
            formulation,
            elastic,
            density: vec![0.0; n_tets],
            assembler,
            factor,
            pressure,
            material_set: false,
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
        self.elastic.mu.clone_from(&material.mu);
        self.elastic.lambda.clone_from(&material.lambda);
        self.density.clone_from(&material.density);
        if let (Some(pressure), Formulation::Mixed { mass }) =
            (self.pressure.as_mut(), self.formulation)
        {
            let compliance = PressureCompliance {
                elastic: &self.elastic,
                mass,
            };
            let zero = vec![0.0; self.mesh.n_nodes()];
            let c =
                pressure
                    .assembler
                    .evaluate(&[&compliance], &zero, false, Some(HessianMode::Exact));
            if !pressure
                .factor
                .factor_llt(pressure.assembler.pattern(), &c.hessian)?
            {
                return Err(Error::LinearSolver {
                    message: "pressure mass matrix is not positive definite".into(),
                });
            }
        }
        self.material_set = true;
        Ok(())
    }

    /// Static equilibrium under `loads`, starting from `initial` positions (3 n, m) or the rest shape.
    /// Internally the unknowns are displacements from the rest shape.
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
            }
            None => {}
        }
        let gravity = GravityTerm {
            mesh: self.mesh.clone(),
            density: self.density.clone(),
            gravity: loads.gravity,
        };
        let forces = NodalForceTerm {
            nodes: loads.nodal_forces.iter().map(|f| f.0).collect(),
            forces: loads.nodal_forces.iter().map(|f| f.1).collect(),
        };
        let full_load = self.assembler.load_vector(&[&gravity, &forces]);
        let prescribed = if loads.prescribed.is_empty() {
            vec![[0.0; 3]; self.fixed_nodes.len()]
        } else {
            loads.prescribed.clone()
        };
        let mut problem = System {
            model: self,
            full_load,
            load: Vec::new(),
            load_free_norm: 0.0,
            prescribed,
        };
        // Only the prescribed displacements are scaled by the load factor: the initial guess is
        // kept as given for the free DOFs, which is what warm starts need.
        let report = newton::solve(&mut problem, &mut z, options)?;
        let pressure =
            matches!(self.formulation, Formulation::Mixed { .. }).then(|| z[3 * n..].to_vec());
        z.truncate(3 * n);
        for (zi, ri) in z.iter_mut().zip(self.mesh.rest_flat()) {
            *zi += ri;
        }
        Ok(Solution {
            positions: z,
            pressure,
            report,
        })
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

/// The Newton view of a model at a load factor.
struct System<'a> {
    model: &'a mut Model,
    /// External forces (N, full DOFs) at load factor 1, and at the current factor.
    full_load: Vec<f64>,
    load: Vec<f64>,
    load_free_norm: f64,
    prescribed: Vec<[f64; 3]>,
}

impl System<'_> {
    fn n_nodes(&self) -> usize {
        self.model.mesh.n_nodes()
    }

    /// Replaces the pressures in `z` by their optimum `p* = C^{-1} phi(x)` (mixed only).
    fn update_pressure(&mut self, z: &mut [f64]) -> bool {
        let n = self.n_nodes();
        let Some(pressure) = self.model.pressure.as_ref() else {
            return true;
        };
        z[3 * n..].fill(0.0);
        let eval = self
            .model
            .assembler
            .evaluate(&[&self.model.elastic], z, true, None);
        if !eval.energy.is_finite() {
            return false;
        }
        // Pressure DOFs are never fixed and come last, so they are the last n free DOFs.
        let mut phi = eval.gradient[eval.gradient.len() - n..].to_vec();
        pressure.factor.solve_in_place(&mut phi);
        z[3 * n..].copy_from_slice(&phi);
        true
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

    fn merit(&mut self, z: &mut [f64]) -> f64 {
        let external: f64 = self.load.iter().zip(z.iter()).map(|(f, x)| f * x).sum();
        if self.model.pressure.is_some() {
            if !self.update_pressure(z) {
                return f64::INFINITY;
            }
            // Pi_c(x) = Pi(x, p*) = W_mu(x) + 1/2 phi^T p*, evaluated directly at p*.
        }
        self.model.assembler.energy(&[&self.model.elastic], z) - external
    }

    fn gradient(&mut self, z: &[f64]) -> Vec<f64> {
        let mut g = self
            .model
            .assembler
            .evaluate(&[&self.model.elastic], z, true, None)
            .gradient;
        for (gi, &d) in g.iter_mut().zip(self.model.assembler.full_of_free()) {
            *gi -= self.load[d];
        }
        if self.model.pressure.is_some() {
            // At p = p* the pressure rows of the gradient vanish up to round-off; the Newton
            // residual is the displacement part.
            let n = self.n_nodes();
            let len = g.len();
            g[len - n..].fill(0.0);
        }
        g
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
        let eval = self
            .model
            .assembler
            .evaluate(&[&self.model.elastic], z, false, Some(mode));
        timings.assembly += t0.elapsed().as_secs_f64();
        let pattern = self.model.assembler.pattern();
        let t0 = Instant::now();
        let ok = match self.model.formulation {
            Formulation::Standard => self.model.factor.factor_llt(pattern, &eval.hessian)?,
            Formulation::Mixed { .. } => {
                let n_displacement = self.n_free() - self.n_nodes();
                self.model
                    .factor
                    .factor_ldlt(pattern, &eval.hessian, n_displacement)?;
                true
            }
        };
        timings.factorization += t0.elapsed().as_secs_f64();
        if !ok {
            return Ok(None);
        }
        let t0 = Instant::now();
        let mut d: Vec<f64> = g.iter().map(|v| -v).collect();
        self.model.factor.solve_in_place(&mut d);
        timings.solve += t0.elapsed().as_secs_f64();
        let slope: f64 = d.iter().zip(g).map(|(a, b)| a * b).sum();
        if !(slope < 0.0) {
            return Ok(None);
        }
        Ok(Some(d))
    }

    fn step(&self, z: &mut [f64], d: &[f64], t: f64) {
        for (&full, di) in self.model.assembler.full_of_free().iter().zip(d) {
            z[full] += t * di;
        }
    }
}
