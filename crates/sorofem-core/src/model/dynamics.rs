//! Dynamics: implicit Euler in time, each step a minimisation of the incremental potential
//! through the same Newton solver as statics.

use super::system::{ContactSolve, FrictionLag, StepTerms, System};
use super::{Loads, Model};
use crate::contact::ccd::DEFAULT_MIN_SEPARATION;
use crate::contact::ContactForces;
use crate::energy::HessianMode;
use crate::error::{Error, Result};
use crate::newton::{self, NewtonOptions};

/// How many times a time step may be halved (a step becomes at most 64 sub-steps).
const MAX_STEP_SPLITS: usize = 6;

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
    /// With obstacles: the contact at every saved frame.
    pub contact: Vec<ContactFrame>,
    /// With obstacles: the minimum distance (m) between the body and its obstacles at every
    /// accepted Newton iterate of every step (over the stencils within `dhat`, `+inf` when none).
    pub iterate_min_distances: Vec<f64>,
}

/// The contact of one saved frame: its forces and where each obstacle is (its translation from
/// its place at time 0, m).
#[derive(Clone, Debug, Default)]
pub struct ContactFrame {
    pub forces: ContactForces,
    pub translations: Vec<[f64; 3]>,
}

impl Model {
    /// Implicit Euler in time: each step minimises the incremental potential
    /// `1/2 |u - u_n - h v_n|_M^2 / h^2 + 1/2 |u - u_n|_D^2 / h + Pi(u)` (lumped mass M,
    /// Rayleigh damping `D = alpha_M M + beta_K K_n`), then `v = (u - u_n) / h`. A step whose
    /// Newton solve fails is split in two, up to six times. `actuation[s][c]` is cable c's
    /// alpha during step s. Starts from `initial_positions` (3 n, m; default rest; free cable nodes
    /// and pressures then continue from the last solve) at rest or with `initial_velocities`
    /// (3 n, m/s).
    ///
    /// Obstacles move along their paths; each step first moves them to where they are at its end
    /// (split, like a failed step, when that would make them touch the body), lags friction at
    /// the step's start (`eps_u = eps_v h`), starts Newton from the inertial prediction cut
    /// short of any contact, and balances the barrier stiffness there (IPC's initial stiffness).
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
        options: &NewtonOptions,
        save_every: usize,
    ) -> Result<Trajectory> {
        self.require_material("simulate")?;
        self.check_loads(loads)?;
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
        let prescribed = self.prescribed(loads);
        let full_load = self.load_vector(loads);
        let rest = self.mesh.rest_flat();
        let mut z = self.start_state("initial_positions", initial_positions)?;
        if let Some(contact) = &mut self.terms.contact {
            contact.set_time(0.0);
            contact.clear_friction();
        }
        self.check_apart("initial_positions", &z)?;
        self.prepare_contact();
        let free: Vec<usize> = self.assembler.full_of_free().to_vec();
        let mass_full = self.terms.mass.per_dof(self.layout.n_full());
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
            crate::error::check_finite("initial_velocities", v)?;
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
        // Pressures (mixed formulation) are never fixed and come last among the free DOFs.
        let n_free_displacement = free.len() - if self.layout.pressures { n } else { 0 };
        let step_options = NewtonOptions {
            load_steps: 1,
            max_cutbacks: 0,
            ..options.clone()
        };
        let mut trajectory = Trajectory::default();
        let save =
            |model: &Model, z: &[f64], velocity: &[f64], t: f64, trajectory: &mut Trajectory| {
                if let Some(contact) = &model.terms.contact {
                    trajectory.contact.push(ContactFrame {
                        forces: contact.forces(z),
                        translations: (0..contact.n_obstacles())
                            .map(|k| contact.translation_at(k, t).into())
                            .collect(),
                    });
                }
                trajectory.times.push(t);
                trajectory
                    .positions
                    .push((0..3 * n).map(|i| rest[i] + z[i]).collect());
                trajectory
                    .cable_points
                    .push(model.terms.cables.points_at(z));
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
            let mut sub_time = time;
            while let Some((h, depth)) = pending.pop() {
                // Obstacles move first, with the body where it is: a motion that would touch it
                // splits the step.
                if let Some(contact) = &mut self.terms.contact {
                    let end = sub_time + h;
                    if contact.obstacle_motion_bound(&z, end, DEFAULT_MIN_SEPARATION) < 1.0 {
                        if depth < MAX_STEP_SPLITS {
                            trajectory.cutbacks += 1;
                            pending.push((h / 2.0, depth + 1));
                            pending.push((h / 2.0, depth + 1));
                            continue;
                        }
                        return Err(Error::invalid(
                            "obstacles",
                            "paths along which the obstacles do not run into the body faster than it can move away",
                            format!(
                                "time step {s} (t = {time:.4} s): an obstacle would touch the body even at dt = {h:.3e} s"
                            ),
                        ));
                    }
                    contact.set_time(end);
                    let slip = contact.friction_velocity() * h;
                    contact.lag_friction(&z, &z, slip);
                }
                let previous: Vec<f64> = free.iter().map(|&d| z[d]).collect();
                let predicted: Vec<f64> = previous
                    .iter()
                    .zip(&velocity)
                    .map(|(u, v)| u + h * v)
                    .collect();
                let stiffness_damping = if damping.stiffness > 0.0 {
                    let mut k = self
                        .assembler
                        .evaluate(
                            &self.terms.internal(),
                            &z,
                            false,
                            Some(HessianMode::Projected),
                        )
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
                // The inertial prediction, cut short of any contact on the way.
                let mut reach = 1.0;
                if let Some(contact) = &self.terms.contact {
                    let mut dz = vec![0.0; 3 * n];
                    for (f, &d) in free.iter().enumerate() {
                        if d < 3 * n {
                            dz[d] = predicted[f] - previous[f];
                        }
                    }
                    reach = contact.max_step(&z, &dz, DEFAULT_MIN_SEPARATION);
                }
                let mut trial = z.clone();
                for (f, &d) in free.iter().enumerate() {
                    if f < n_free_displacement {
                        trial[d] = previous[f] + reach * (predicted[f] - previous[f]);
                    }
                }
                let mut problem = System::new(
                    self,
                    full_load.clone(),
                    prescribed.clone(),
                    Some(step),
                    options,
                );
                if problem.model.terms.contact.is_some() {
                    problem.contact = Some(ContactSolve::new(FrictionLag::Fixed, true));
                }
                problem.model.terms.cables.begin_step(h, &z);
                let outcome =
                    rayon::scope(|_| newton::solve(&mut problem, &mut trial, &step_options));
                problem.model.terms.cables.end_step();
                if let Some(solve) = problem.contact.take() {
                    trajectory
                        .iterate_min_distances
                        .extend(solve.iterate_min_distances);
                }
                drop(problem);
                if outcome.is_err() {
                    if let Some(contact) = &mut self.terms.contact {
                        contact.set_time(sub_time);
                    }
                }
                match outcome {
                    Ok(report) => {
                        sub_time += h;
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
                    Err(Error::NotConverged { report, .. }) if depth < MAX_STEP_SPLITS => {
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
}
