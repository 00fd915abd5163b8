//! Static equilibria: loads in, positions, pressures, reactions and cable states out.

use super::contact::ContactReport;
use super::system::{ContactSolve, FrictionLag, System};
use super::Model;
use crate::cables::CableSlot;
use crate::energy::{HessianMode, Term};
use crate::error::{check_finite, Error, Result};
use crate::material::{cauchy_stress, neo_hookean::von_mises};
use crate::newton::{self, NewtonOptions};
use crate::report::SolveReport;

/// External loads of one solve. `prescribed` has one displacement (m) per fixed node, in the
/// order the fixed nodes were given (empty: all zero); `nodal_forces` pairs node indices with
/// forces (N); gravity in m/s^2.
#[derive(Clone, Debug, Default)]
pub struct Loads {
    pub gravity: [f64; 3],
    pub nodal_forces: Vec<(usize, [f64; 3])>,
    pub prescribed: Vec<[f64; 3]>,
}

/// Times a static solve with friction lags it again at its equilibrium and solves once more (each
/// new solve starting there), until a solve needs no iteration: quasi-static friction whose
/// normal forces and directions are those of the equilibrium, not of the load step's start.
const MAX_FRICTION_LAGS: usize = 4;

/// An equilibrium: positions (m, 3 n node-major), nodal pressures (Pa, mixed only), the
/// reaction force (N) at each fixed node (in the order they were given), the position (m) of
/// every cable point and the tension (N) of every cable segment (a tendon's is the same on every
/// segment), each tendon's tension (N) and pull `L0 - L` (m) (`None` for spring cables), the
/// contact (with obstacles) and the report.
#[derive(Clone, Debug)]
pub struct Solution {
    pub positions: Vec<f64>,
    pub pressure: Option<Vec<f64>>,
    pub reactions: Vec<[f64; 3]>,
    pub cable_points: Vec<Vec<[f64; 3]>>,
    pub cable_tensions: Vec<Vec<f64>>,
    pub tendon_tensions: Vec<Option<f64>>,
    pub tendon_pulls: Vec<Option<f64>>,
    pub contact: Option<ContactReport>,
    pub report: SolveReport,
}

impl Model {
    /// Static equilibrium under `loads`, starting from `initial` positions (3 n, m) or the rest shape.
    /// Internally the unknowns are displacements from the rest shape. In the mixed formulation a
    /// warm start (`initial` given) also starts from the pressures of the previous solve.
    ///
    /// With obstacles (held where their paths start), every accepted iterate is apart from
    /// them, and friction is lagged at each load step's start, then again at the equilibrium
    /// (slip measured from the load step's start), up to four times.
    pub fn solve(
        &mut self,
        loads: &Loads,
        initial: Option<&[f64]>,
        options: &NewtonOptions,
    ) -> Result<Solution> {
        self.require_material("solve")?;
        self.check_loads(loads)?;
        let n = self.mesh.n_nodes();
        let mut z = self.start_state("initial", initial)?;
        if let Some(contact) = &mut self.terms.contact {
            contact.set_time(0.0);
            contact.clear_friction();
        }
        if initial.is_some() {
            self.check_apart("initial", &z)?;
        }
        self.prepare_contact();
        let full_load = self.load_vector(loads);
        let prescribed = self.prescribed(loads);
        let mut problem = System::new(self, full_load, prescribed, None, options);
        problem.extend_state(&mut z, initial.is_some());
        let start_tensions = z[problem.constraints.offset..].to_vec();
        if problem.model.terms.contact.is_some() {
            let lag = FrictionLag::LoadStep { origin: None };
            problem.contact = Some(ContactSolve::new(lag, None));
        }
        // Only the prescribed displacements are scaled by the load factor: the initial guess is
        // kept as given for the free DOFs, which is what warm starts need.
        // The Newton loop runs on a worker of the thread pool: from the calling thread, its
        // single-threaded factorisations let the workers fall asleep and the element passes
        // after them ran slower (docs/theory.md, "Newton's method").
        let outcome = solve_with_friction_lags(&mut problem, &mut z, options);
        let mut report = match outcome {
            Ok(report) => report,
            Err(error) => {
                let error = infeasible_pulls(error, &problem.tendon_states(&z));
                problem.finish_state(&mut z, false, &start_tensions);
                return Err(error);
            }
        };
        problem.finish_state(&mut z, true, &start_tensions);
        let full_load = std::mem::take(&mut problem.full_load);
        let contact_solve = problem.contact.take();
        drop(problem);
        let iterate_min_distances = match contact_solve {
            Some(solve) => {
                report.timings.contact = solve.seconds;
                solve.iterate_min_distances
            }
            None => Vec::new(),
        };
        // Reaction = internal force (contact included) minus applied load at the supports, so
        // that the reactions balance the loads and the contact forces: sum(reactions) +
        // sum(loads) + sum(contact forces) = 0 at equilibrium (with cable anchors' forces).
        let mut internal = self.assembler.full_gradient(&self.terms.internal(), &z);
        if let Some(contact) = &self.terms.contact {
            for (i, g) in contact.full_gradient(&z).into_iter().enumerate() {
                internal[i] += g;
            }
        }
        let reactions = self
            .fixed_nodes
            .iter()
            .map(|&i| std::array::from_fn(|k| internal[3 * i + k] - full_load[3 * i + k]))
            .collect();
        self.last_state = Some((z.clone(), loads.clone()));
        self.factor_at_solution = false;
        let pressure = self
            .layout
            .pressure_offset()
            .map(|offset| z[offset..].to_vec());
        self.last_extra = Some(z[self.layout.extra()].to_vec());
        let (cable_points, cable_tensions, tendon_tensions, tendon_pulls) = self.cable_states(&z);
        let contact = self.contact_report(&z, iterate_min_distances);
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
            tendon_tensions,
            tendon_pulls,
            contact,
            report,
        })
    }

    /// Per cable at the full DOF vector `z`: its points (m), its segments' tensions (N), and for
    /// a tendon its tension (N) and pull (m).
    #[allow(clippy::type_complexity)]
    pub(crate) fn cable_states(
        &self,
        z: &[f64],
    ) -> (
        Vec<Vec<[f64; 3]>>,
        Vec<Vec<f64>>,
        Vec<Option<f64>>,
        Vec<Option<f64>>,
    ) {
        let springs_points = self.terms.cables.points_at(z);
        let springs_tensions = self.terms.cables.tensions_at(z);
        let mut out = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for slot in &self.terms.slots {
            match *slot {
                CableSlot::Springs(i) => {
                    out.0.push(springs_points[i].clone());
                    out.1.push(springs_tensions[i].clone());
                    out.2.push(None);
                    out.3.push(None);
                }
                CableSlot::Tendon(i) => {
                    let tendon = &self.terms.tendons.tendons[i];
                    out.0
                        .push(tendon.points.iter().map(|p| p.position(z).into()).collect());
                    out.1.push(vec![tendon.tension; tendon.n_segments()]);
                    out.2.push(Some(tendon.tension));
                    out.3.push(Some(tendon.pull(z)));
                }
            }
        }
        out
    }

    /// Checks `loads` against the model: finite values, node indices in range, one prescribed
    /// displacement per fixed node (or none).
    pub(crate) fn check_loads(&self, loads: &Loads) -> Result<()> {
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
        Ok(())
    }

    /// The prescribed displacement of every fixed node (zero when `loads` gives none).
    pub(crate) fn prescribed(&self, loads: &Loads) -> Vec<[f64; 3]> {
        if loads.prescribed.is_empty() {
            vec![[0.0; 3]; self.fixed_nodes.len()]
        } else {
            loads.prescribed.clone()
        }
    }

    /// The full DOF vector a solve starts from: the rest state, or the node positions `initial`
    /// (3 n, m; the parameter is named `param` in errors) with the free cable nodes and
    /// pressures of the last solve, when there was one.
    pub(crate) fn start_state(&self, param: &str, initial: Option<&[f64]>) -> Result<Vec<f64>> {
        let n = self.mesh.n_nodes();
        let mut z = vec![0.0; self.layout.n_full()];
        if let Some(x) = initial {
            if x.len() != 3 * n {
                return Err(Error::shape(
                    param,
                    format!("({n}, 3) positions"),
                    format!("{} values", x.len()),
                ));
            }
            check_finite(param, x)?;
            for (zi, (xi, ri)) in z.iter_mut().zip(x.iter().zip(self.mesh.rest_flat())) {
                *zi = xi - ri;
            }
            if let Some(extra) = &self.last_extra {
                z[self.layout.extra()].copy_from_slice(extra);
            }
        }
        Ok(z)
    }

    /// External load vector (N, full DOFs) of `loads`, free cable nodes' weight included.
    pub(crate) fn load_vector(&self, loads: &Loads) -> Vec<f64> {
        self.assembler.load_vector(&self.terms.loads(loads).list())
    }

    /// Per-tet volume ratio `J = det F` and von Mises Cauchy stress (Pa) at `positions` (3 n).
    /// In the mixed formulation the stress uses the element's volumetric response
    /// `kappa c(J) c'(J) J` of the same energy, so both formulations report comparable stresses.
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
                cauchy_stress(&self.terms.elastic.element_material(e), &f)
                    .map_or(f64::NAN, |s| von_mises(&s)),
            );
        }
        Ok((j, vm))
    }

    /// Strain energy (J) of the elastic term at `positions` (3 n, m): the energy stored in the
    /// body (standard formulation; in the mixed one, the saddle-point energy at the last
    /// solve's pressures).
    pub fn strain_energy(&self, positions: &[f64]) -> Result<f64> {
        let n = self.mesh.n_nodes();
        if positions.len() != 3 * n {
            return Err(Error::shape(
                "positions",
                format!("({n}, 3)"),
                format!("{} values", positions.len()),
            ));
        }
        check_finite("positions", positions)?;
        let mut z = vec![0.0; self.layout.n_full()];
        for (zi, (x, r)) in z
            .iter_mut()
            .zip(positions.iter().zip(self.mesh.rest_flat()))
        {
            *zi = x - r;
        }
        if let Some(extra) = &self.last_extra {
            z[self.layout.extra()].copy_from_slice(extra);
        }
        let term = &self.terms.elastic;
        let s = term.stencil_size();
        let (mut dofs, mut local) = (vec![0; s], vec![0.0; s]);
        let mut energy = 0.0;
        for e in 0..term.n_elements() {
            term.element_dofs(e, &mut dofs);
            for (v, &d) in local.iter_mut().zip(&dofs) {
                *v = z[d];
            }
            energy += term.element(e, &local, None, None, HessianMode::Exact);
        }
        Ok(energy)
    }

    /// Seconds of each of `repeats` numeric factorisations of the exact Hessian at the last
    /// static solution (the rest state before any solve), with nothing running beside them: the
    /// bare cost a Newton iteration is measured against. A diagnostic for benchmarks.
    pub fn time_factorization(&mut self, repeats: usize) -> Result<Vec<f64>> {
        let z = match &self.last_state {
            Some((z, _)) => z.clone(),
            None => vec![0.0; self.layout.n_full()],
        };
        let eval =
            self.assembler
                .evaluate(&self.terms.internal(), &z, false, Some(HessianMode::Exact));
        let pattern = self.assembler.pattern();
        self.factor_at_solution = false;
        // On a pool worker, as in a solve (faer's parallel factorisation of large factors
        // pays for every task it starts from outside the pool).
        let factor = &mut self.factor;
        rayon::scope(|_| {
            (0..repeats)
                .map(|_| {
                    let t0 = std::time::Instant::now();
                    factor.factor(pattern, &eval.hessian)?;
                    Ok(t0.elapsed().as_secs_f64())
                })
                .collect()
        })
    }
}

/// A failed solve with displacement-controlled tendons: says which pulls the body could not
/// reach. `tendons` holds `(cable, commanded pull, pull, tension)` at the last equilibrium the
/// solver reached (the start of the increment that failed).
pub(super) fn infeasible_pulls(error: Error, tendons: &[(usize, f64, f64, f64)]) -> Error {
    let Error::NotConverged { message, report } = error else {
        return error;
    };
    let short: Vec<String> = (tendons.iter())
        .filter(|&&(_, commanded, reached, _)| commanded > 0.0 && reached < commanded)
        .map(|&(cable, commanded, reached, tension)| {
            format!(
                "cable {cable} commanded {commanded:.4e} m, reached {reached:.4e} m at {tension:.4e} N"
            )
        })
        .collect();
    if short.is_empty() {
        return Error::NotConverged { message, report };
    }
    Error::NotConverged {
        message: format!(
            "the tendon pull is infeasible: the body cannot shorten the tendon that much ({}); {message}",
            short.join("; ")
        ),
        report,
    }
}

/// Newton on the extended state `z`; with friction, solved again from each equilibrium
/// (see [`MAX_FRICTION_LAGS`]) and the records joined.
fn solve_with_friction_lags(
    problem: &mut System,
    z: &mut Vec<f64>,
    options: &NewtonOptions,
) -> Result<SolveReport> {
    let mut report = rayon::scope(|_| newton::solve(problem, z, options))?;
    if problem
        .model
        .terms
        .contact
        .as_ref()
        .is_some_and(|c| c.has_friction())
    {
        let solve = problem.contact.as_mut().expect("contact");
        let origin = solve.load_step_start.clone();
        solve.friction = FrictionLag::LoadStep {
            origin: Some(origin),
        };
        let again_options = NewtonOptions {
            load_steps: 1,
            ..options.clone()
        };
        problem.reference_floor = report.reference_norm;
        for _ in 0..MAX_FRICTION_LAGS {
            let again = rayon::scope(|_| newton::solve(problem, z, &again_options))?;
            let done = again.iterations == 0;
            absorb(&mut report, again);
            if done {
                break;
            }
        }
    }
    Ok(report)
}

/// Appends the record of a further solve from where `report`'s ended (a friction lag).
fn absorb(report: &mut SolveReport, more: SolveReport) {
    report.iterations += more.iterations;
    report.residual_history.extend(more.residual_history);
    report.energy_history.extend(more.energy_history);
    report.step_lengths.extend(more.step_lengths);
    report.projected_steps += more.projected_steps;
    report.residual_norm = more.residual_norm;
    report.reference_norm = more.reference_norm;
    let (t, m) = (&mut report.timings, more.timings);
    t.assembly += m.assembly;
    t.factorization += m.factorization;
    t.failed_factorization += m.failed_factorization;
    t.solve += m.solve;
    t.line_search += m.line_search;
    t.step_bound += m.step_bound;
    t.total += m.total;
    t.factorizations += m.factorizations;
    t.failed_factorizations += m.failed_factorizations;
    t.single_precision_factorizations += m.single_precision_factorizations;
    report.message = format!("converged in {} Newton iterations", report.iterations);
}
