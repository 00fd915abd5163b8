//! Forward (tangent-linear) sensitivities of a trajectory: the change of every frame's node
//! positions along given parameter directions, by differentiating each implicit Euler step
//! (the step residual `r_k` of the module above). Along a direction `delta` (the parameter
//! blocks and the Rayleigh coefficients), the free DOFs' change solves, step after step,
//!
//! ```text
//! H_k du_{k+1} = (2 M / h^2 + alpha_M M / h) du_k - M / h^2 du_{k-1}
//!              + beta_K / h P K_F(z_k) du_k - dD_k/du_k du_k - dr_k/dtheta . delta,
//!                                                                 du_0 = du_{-1} = 0
//! ```
//!
//! (with the lengths equal; after a halved step, `M (1 / h_k^2 + 1 / (h_k h_{k-1}) +
//! alpha_M / h_k) du_k - M / (h_k h_{k-1}) du_{k-1}`),
//! with `H_k` the step's own Hessian at its converged end (the dashpots' and the contact
//! barrier's in it; taut displacement-controlled tendons bordering it, their pulls held, as in
//! [`crate::sensitivity`]), `K_F` the Hessian of the damped internal force and `D_k` the
//! dashpots' force (`dashpot`); a barrier stiffness balanced at the step's start adds
//! `-2^m grad B(z_{k+1}) d kappa_0` (`balance`). The initial state is data: it does not move
//! with the parameters.
//! Cost: one extra factorisation per step and one solve per direction and step; memory: the
//! positions' change of every frame and direction (`directions (steps + 1) 3 n` values).

use super::{RecordedPositions, StepEnd};
use crate::energy::HessianMode;
use crate::error::{Error, Result};
use crate::model::dynamics::{Damping, StepMethod, StepSetup, StepState, MAX_CONTRACTION};
use crate::model::system::FactorReuse;
use crate::model::{Loads, Model};
use crate::newton::NewtonOptions;
use crate::sensitivity::{add_derivative_along, dot, schur_solve, ParamLayout, ParamVector};

/// A direction in parameter space: the blocks of [`Model::param_zeros`] (missing ones are
/// zero), the changes of alpha_M (1/s) and beta_K (s), and those of the cables' dashpot
/// coefficients (N s/m, one per cable, tendons' ignored; empty: none).
#[derive(Clone, Debug, Default)]
pub struct TrajectoryDirection {
    pub params: ParamVector,
    pub mass_damping: f64,
    pub stiffness_damping: f64,
    pub cable_damping: Vec<f64>,
}

/// One direction as the forward sweep carries it: its parameter blocks laid out flat, and the
/// free DOFs' change at the last two frames.
struct Tangent {
    delta: Vec<f64>,
    mass_damping: f64,
    stiffness_damping: f64,
    /// Per cable (N s/m).
    cable_damping: Vec<f64>,
    current: Vec<f64>,
    previous: Vec<f64>,
    /// The change of each pulled tendon's multiplier at the last frame (per cable, N; zero
    /// where slack).
    tension_change: Vec<f64>,
}

impl Model {
    /// The simulation of [`Model::trajectory_gradient`] (every step by modified Newton to
    /// `newton.tolerance`) and, per direction, the change of every frame's node positions
    /// along it: `[direction][frame]`, 3 n values each (m per unit of the direction; frame 0
    /// is all zeros).
    ///
    /// Contact and dashpots as in [`Model::trajectory_gradient`] (the balanced barrier
    /// stiffness followed), halved steps through their sub-steps; not differentiated (an error
    /// names it): friction.
    #[allow(clippy::too_many_arguments, clippy::type_complexity)]
    pub fn trajectory_sensitivity(
        &mut self,
        loads: &Loads,
        dt: f64,
        actuation: &[Vec<f64>],
        damping: Damping,
        initial_positions: Option<&[f64]>,
        initial_velocities: Option<&[f64]>,
        newton: &NewtonOptions,
        directions: &[TrajectoryDirection],
    ) -> Result<(RecordedPositions, Vec<Vec<Vec<f64>>>)> {
        let setup =
            self.differentiable_setup(loads, dt, actuation, damping, newton, StepMethod::Modified)?;
        let layout = {
            let load_terms = self.terms.loads(loads);
            ParamLayout::new(&self.terms.parameterised(&load_terms))
        };
        let n_free = setup.free.len();
        let n_cables = self.n_cables();
        let mut tangents = directions
            .iter()
            .map(|d| {
                let cable_damping = match d.cable_damping.len() {
                    0 => vec![0.0; n_cables],
                    n if n == n_cables => d.cable_damping.clone(),
                    n => {
                        return Err(Error::shape(
                            "cable_damping",
                            format!("({n_cables},): one value per cable"),
                            format!("{n} values"),
                        ))
                    }
                };
                crate::error::check_finite("cable_damping", &cable_damping)?;
                Ok(Tangent {
                    delta: layout.flatten(&d.params)?,
                    mass_damping: d.mass_damping,
                    stiffness_damping: d.stiffness_damping,
                    cable_damping,
                    current: vec![0.0; n_free],
                    previous: vec![0.0; n_free],
                    tension_change: vec![0.0; n_cables],
                })
            })
            .collect::<Result<Vec<_>>>()?;
        self.continuation = None;
        let saved_tensions = self.tendon_tensions();
        let n3 = 3 * self.mesh.n_nodes();
        let mut record = RecordedPositions::default();
        let mut changes: Vec<Vec<Vec<f64>>> =
            directions.iter().map(|_| vec![vec![0.0; n3]]).collect();
        let mut sweep = || -> Result<()> {
            let (mut state, _) =
                self.start_of_run(&setup, initial_positions, initial_velocities)?;
            record.positions.push(self.node_positions(&state.z));
            let mut reuse = FactorReuse::new(MAX_CONTRACTION);
            // The length of the sub-step before (the run's first has no predecessor: du_0 = 0)
            // and the tendons' tensions where it ended.
            let mut previous_h = dt;
            let mut start_tensions = self.tendon_tensions();
            for (s, commands) in actuation.iter().enumerate() {
                self.recorded_step(
                    &setup,
                    &mut state,
                    dt,
                    (s, commands.as_slice()),
                    &mut reuse,
                    &mut record,
                    |model, start, end, sub| {
                        let tensions = model.tendon_tensions();
                        let step_end = StepEnd {
                            tensions: &tensions,
                            barrier_stiffness: sub.barrier_stiffness,
                            balanced_stiffness: sub.balanced_stiffness,
                            time: sub.end_time,
                        };
                        model.tangent_step(
                            &setup,
                            loads,
                            &layout,
                            (sub.h, previous_h),
                            s,
                            (start, &start_tensions),
                            end,
                            &step_end,
                            &mut tangents,
                        )?;
                        previous_h = sub.h;
                        start_tensions.clone_from(&tensions);
                        // The next step's solve starts from the tensions it solved for, not
                        // the scaled ones.
                        for (tendon, &t) in model.terms.tendons.tendons.iter_mut().zip(&tensions) {
                            tendon.tension = t;
                        }
                        Ok(())
                    },
                )?;
                for (frames, tangent) in changes.iter_mut().zip(&tangents) {
                    let mut frame = vec![0.0; n3];
                    for (&d, &v) in setup
                        .free
                        .iter()
                        .zip(&tangent.current)
                        .take(setup.n_displacement)
                    {
                        if d < n3 {
                            frame[d] = v;
                        }
                    }
                    frames.push(frame);
                }
            }
            Ok(())
        };
        let outcome = sweep();
        self.last_state = None;
        self.factor_at_solution = false;
        for (tendon, t) in self.terms.tendons.tendons.iter_mut().zip(saved_tensions) {
            tendon.tension = t;
        }
        outcome?;
        Ok((record, changes))
    }

    /// Step k of the forward sweep (a sub-step of time step `k` where it was split; `previous_h`
    /// the length of the one before): every direction's `du_{k+1}` from the step's Hessian at
    /// its end.
    #[allow(clippy::too_many_arguments)]
    fn tangent_step(
        &mut self,
        setup: &StepSetup,
        loads: &Loads,
        layout: &ParamLayout,
        (h, previous_h): (f64, f64),
        k: usize,
        (start, start_tensions): (&StepState, &[f64]),
        end: &StepState,
        step_end: &StepEnd,
        tangents: &mut [Tangent],
    ) -> Result<()> {
        if tangents.is_empty() {
            return Ok(());
        }
        let (alpha_m, beta_k) = (setup.damping.mass, setup.damping.stiffness);
        let scale = 1.0 + beta_k / h;
        let (z0, z1) = (&start.z, &end.z);
        let n_free = setup.free.len();
        // The start force beta_K / h P F(z_k), the tendons out of the internal force: assembled
        // beside the factorisation.
        let balanced = step_end.balanced_stiffness.is_some();
        let start_hessian = (beta_k > 0.0 || balanced).then_some(HessianMode::Exact);
        let (damped_force, dashpots, start_eval) =
            self.factor_step_end(setup, h, k, (z0, z1), step_end, |assembler, terms| {
                let without_tendons = [true, true, false];
                assembler.evaluate_selected(
                    &terms.internal(),
                    &without_tendons,
                    z0,
                    true,
                    start_hessian,
                )
            })?;
        self.last_state = Some((z1.clone(), loads.clone()));
        let active = self.active_tendons()?;
        // The balanced barrier stiffness (`balance`): its change is -(row . du_k - M b / (h
        // h_{k-1}) . (du_k - du_{k-1}) + b . dg/dtheta delta) / |b|^2.
        let balance = (self.stiffness_balance(step_end, (z0, z1), start_tensions)).map(|balance| {
            let stiffness_b = self
                .assembler
                .pattern()
                .symmetric_matvec(&start_eval.hessian, &balance.start);
            let row = self.balance_state_row(
                setup,
                &balance,
                (start, h),
                &start_eval.gradient,
                &stiffness_b,
            );
            (balance, row)
        });
        let load_terms = self.terms.loads(loads);
        let terms = self.terms.parameterised(&load_terms);
        let density_offset = layout
            .blocks
            .iter()
            .find(|b| b.0 == "density")
            .expect("the gravity term's density block")
            .1;
        let n_full = z1.len();
        for tangent in tangents.iter_mut() {
            // dr_k/dtheta . delta: every term at the end (the elastic and spring-cable forces
            // carry the internal scale, and their start force enters with -beta_K / h), the
            // lumped mass through the density, and the damping coefficients.
            let mut at_end = vec![0.0; n_full];
            let mut at_start = vec![0.0; n_full];
            for (i, (term, offsets)) in terms.iter().zip(&layout.term_offsets).enumerate() {
                let internal = i == 0 || i == 3;
                let weight = if internal { scale } else { 1.0 };
                add_derivative_along(*term, offsets, z1, &tangent.delta, weight, &mut at_end);
                if internal && beta_k > 0.0 {
                    add_derivative_along(*term, offsets, z0, &tangent.delta, 1.0, &mut at_start);
                }
            }
            let mut nodal_mass = vec![0.0; n_full];
            for (e, tet) in self.mesh.tets().iter().enumerate() {
                let change = self.terms.mass.nodal_volume(e) * tangent.delta[density_offset + e];
                if change != 0.0 {
                    for d in tet.iter().flat_map(|&a| (0..3).map(move |i| 3 * a + i)) {
                        nodal_mass[d] += change;
                    }
                }
            }
            // The dashpots: their coefficients' change, and the coupling to the step's start
            // (+c / h dL/dz(z_{k+1}) (dL/dz(z_k) . du_k), displacement rows).
            let mut dashpot_start = vec![0.0; n_full];
            if !dashpots.is_empty() {
                dashpots.add_damping_along(h, &tangent.cable_damping, &mut at_end);
                let mut current = vec![0.0; n_full];
                for (&d, &v) in setup.free.iter().zip(&tangent.current) {
                    current[d] = v;
                }
                dashpots.add_start_product(&current, &mut dashpot_start);
            }
            let kappa_change = balance.as_ref().map(|(balance, row)| {
                let mut forces = vec![0.0; n_full];
                for (term, offsets) in terms.iter().zip(&layout.term_offsets) {
                    add_derivative_along(*term, offsets, z0, &tangent.delta, 1.0, &mut forces);
                }
                let mut along = dot(row, &tangent.current);
                for (t, cable) in self.taut_pulls(start_tensions) {
                    along += balance.tendon_rows[t] * tangent.tension_change[cable];
                }
                for (f, &d) in setup.free.iter().enumerate().take(setup.n_displacement) {
                    let b = balance.start[f];
                    let inertia = setup.mass[f] / (h * previous_h);
                    along += b
                        * (forces[d]
                            - nodal_mass[d] * start.velocity[f] / h
                            - inertia * (tangent.current[f] - tangent.previous[f]));
                }
                (&balance.end, balance.kappa_change(along))
            });
            let start_stiffness = if beta_k > 0.0 {
                self.assembler
                    .pattern()
                    .symmetric_matvec(&start_eval.hessian, &tangent.current)
            } else {
                vec![0.0; n_free]
            };
            let mut rhs: Vec<f64> = (0..n_free)
                .map(|f| {
                    let d = setup.free[f];
                    let m = setup.mass[f];
                    let displacement = f < setup.n_displacement;
                    let v1 = end.velocity[f];
                    let mut derivative = at_end[d] + tangent.mass_damping * m * v1;
                    let mut start_force = 0.0;
                    if displacement {
                        let acceleration = (v1 - start.velocity[f]) / h + alpha_m * v1;
                        derivative += nodal_mass[d] * acceleration - beta_k / h * at_start[d];
                        start_force = start_eval.gradient[f];
                    }
                    derivative += tangent.stiffness_damping * (damped_force[f] - start_force) / h;
                    let previous = m
                        * (1.0 / (h * h) + 1.0 / (h * previous_h) + alpha_m / h)
                        * tangent.current[f]
                        - m / (h * previous_h) * tangent.previous[f]
                        + if displacement {
                            beta_k / h * start_stiffness[f]
                        } else {
                            0.0
                        }
                        + dashpot_start[d];
                    let balance = kappa_change.map_or(0.0, |(end, change)| end[f] * change);
                    previous - derivative - balance
                })
                .collect();
            self.factor.solve_in_place(&mut rhs);
            // The multipliers' change dT (H du + A^T dT = rhs, A du = 0).
            tangent.tension_change.fill(0.0);
            if !active.is_empty() {
                let multipliers =
                    schur_solve(&active, active.iter().map(|a| dot(&a.row, &rhs)).collect())?;
                for (a, mu) in active.iter().zip(&multipliers) {
                    for (x, s) in rhs.iter_mut().zip(&a.solved) {
                        *x -= mu * s;
                    }
                    tangent.tension_change[a.cable] = *mu;
                }
            }
            tangent.previous = std::mem::replace(&mut tangent.current, rhs);
        }
        Ok(())
    }
}
