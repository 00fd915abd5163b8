//! The gradient of an objective of a whole trajectory by the discrete adjoint of its implicit
//! Euler steps (docs/theory.md, "Trajectory adjoint").
//!
//! Step k (length h, free DOFs u, the mixed formulation's pressures among them; a sub-step of
//! its own length where the simulation halved a step, see `sub_steps`) ends where its
//! residual vanishes:
//!
//! ```text
//! r_k = M (u_{k+1} - u_k - h v_k) / h^2 + alpha_M M (u_{k+1} - u_k) / h
//!     + s F(z_{k+1}) + T(z_{k+1}) + D_k + kappa_k grad B(z_{k+1}) - f - beta_K / h P F(z_k) = 0,
//!                                                                     v_k = (u_k - u_{k-1}) / h
//! ```
//!
//! with `s = 1 + beta_K / h`, F the elastic and spring-cable force (N), T the tendons' force,
//! D_k the cables' dashpots (`dashpot`: they depend on the step's start too), B the contact
//! barrier (frictionless; at the step's end, its adaptive stiffness `kappa_k` balanced at the
//! step's start: a function of `z_k`, `u_{k-1}` and the parameters, see `balance`), f the
//! loads and P the projection on the displacement rows. For
//! `J = sum_k phi_k(x_k)` the adjoint states `lambda_k` (one per step, free DOFs) solve, from
//! the last step back,
//!
//! ```text
//! H_k lambda_k = dphi_{k+1}/du + (2 M / h^2 + alpha_M M / h) lambda_{k+1} - M / h^2 lambda_{k+2}
//!              + beta_K / h K_F(z_{k+1}) P lambda_{k+1} - (dD_{k+1}/du_{k+1})^T lambda_{k+1}
//! ```
//!
//! (`H_k = dr_k/du_{k+1}`, the step's own Hessian at its converged end, the dashpots' and the
//! barrier's exact Hessians in it; taut displacement-controlled tendons border it as in
//! [`crate::sensitivity`]; with equal lengths: where they differ the inertial coefficients are
//! `M (1 / h_{k+1}^2 + 1 / (h_{k+1} h_k) + alpha_M / h_{k+1})` and `M / (h_{k+2} h_{k+1})`), and
//! `dJ/dtheta = -sum_k lambda_k . dr_k/dtheta`, whose parameter derivatives come from the
//! registry's [`crate::energy::ParamTerm`]s (at `z_{k+1}`, and at `z_k` for the start force),
//! from the lumped mass (`density`) and from the damping coefficients.
//!
//! Memory: the states of every `every`-th step and the last are kept (checkpoints; by default
//! all of them while they fit [`STATE_VALUES_BUDGET`]) and the states inside a segment are
//! recomputed from its checkpoint in the backward sweep (`reverse`), so at most
//! `ceil(steps / every) + 1` checkpoints, one segment's `every + 1` states and the 4 states around
//! the two sub-steps in flight are held, of `n_full + n_free` values each (`every ~ sqrt(steps)`:
//! about `2 sqrt(steps)` states; `every = 1` keeps every state and recomputes none), besides the
//! node positions of every step that the objective reads (`(steps + 1) 3 n`).
//!
//! Time: the backward sweep factorises every sub-step's Hessian once, in single precision where
//! it is positive definite there (`L L^T`), on one thread; beside it the other thread takes the
//! later sub-step's solve, refined to a double-precision factorisation's residual
//! ([`SparseFactor::solve_to_precision`]), and contractions, whose factor is already there (two
//! factors take turns), and assembles the elastic Hessian at the sub-step's start.
//!
//! [`Model::trajectory_sensitivity`] (in `forward`) differentiates the same steps forwards:
//! the change of every frame along given parameter directions (a Jacobian for least squares).

mod balance;
mod dashpot;
mod forward;
mod reverse;
mod step_end;
mod sub_steps;
mod sweep;

pub use forward::TrajectoryDirection;

use self::balance::BalanceAdjoint;
use self::reverse::ReversedSubSteps;
use self::step_end::{add_to, singular_step, CABLES, ELASTIC};
use self::sub_steps::SubStep;
use self::sweep::{FactoredStep, Sweep};
use super::dynamics::{
    Damping, DynamicsOptions, StepMethod, StepSetup, StepState, MAX_CONTRACTION,
};
use super::system::FactorReuse;
use super::{Loads, Model};
use crate::assembly::Evaluation;
use crate::cables::CableSlot;
use crate::energy::{HessianMode, TendonCommand};
use crate::error::{check_finite, Error, Result};
use crate::linear::SparseFactor;
use crate::newton::NewtonOptions;
use crate::sensitivity::{add_contraction, dot, schur_solve, ParamLayout, ParamVector};

/// The states (f64 values) the backward sweep may keep before it recomputes segments from
/// checkpoints: 64 Mi values, 512 MiB (1000 steps of the 9k-tet hammerbot are 14 Mi).
const STATE_VALUES_BUDGET: usize = 64 << 20;

/// The default interval between checkpoints of a run of `steps` steps whose states hold
/// `values_per_state` values each: 1 (every state kept, none recomputed) while the
/// `steps + 1` states fit [`STATE_VALUES_BUDGET`], else `ceil(sqrt(steps))` (about
/// `2 sqrt(steps)` states held, one recomputation of every step).
fn default_checkpoint_interval(steps: usize, values_per_state: usize) -> usize {
    if (steps + 1).saturating_mul(values_per_state) <= STATE_VALUES_BUDGET {
        1
    } else {
        ((steps as f64).sqrt().ceil() as usize).max(1)
    }
}

/// `dJ/dtheta` of a trajectory objective.
#[derive(Clone, Debug, Default)]
pub struct TrajectoryGradient {
    /// The parameter blocks of [`Model::param_zeros`], summed over the steps (`cable_actuation`,
    /// `cable_tension` and `cable_pull` too: the gradient of a command held over the run).
    pub params: ParamVector,
    /// `dJ/d command[s][c]`: each step's alpha (spring cables), pull (m) or tension (N).
    pub actuation: Vec<Vec<f64>>,
    /// `dJ/d alpha_M` (per 1/s) and `dJ/d beta_K` (per s).
    pub mass_damping: f64,
    pub stiffness_damping: f64,
    /// `dJ/dc` of every cable's dashpot coefficient (per N s/m; 0 for tendons, which have none).
    pub cable_damping: Vec<f64>,
}

/// A run's node positions (m, 3 n per frame, the initial one first) and Newton iterations
/// per step.
#[derive(Clone, Debug, Default)]
pub struct RecordedPositions {
    pub positions: Vec<Vec<f64>>,
    pub iterations: Vec<usize>,
    /// Steps with a barrier stiffness IPC balanced strictly inside its bounds at their start
    /// (some stencil within `dhat` there), whose change the derivatives follow (`balance`).
    pub balanced_stiffness_steps: usize,
    /// Steps the run halved (see `sub_steps`): the derivatives are those of the simulation where
    /// a small change of the parameters keeps the halvings.
    pub split_steps: usize,
}

/// The state at the start of a step and the tendons' tensions there.
#[derive(Clone)]
struct Checkpoint {
    state: StepState,
    tensions: Vec<f64>,
}

/// What a step's derivatives need of its converged end besides the state: the tendons' tensions,
/// the barrier stiffness the step converged with (J/m^4; 0 without contact) and the time (s,
/// where the obstacles were).
struct StepEnd<'a> {
    tensions: &'a [f64],
    barrier_stiffness: f64,
    balanced_stiffness: Option<f64>,
    time: f64,
}

impl Model {
    /// The gradient of an objective `J(x_0, ..., x_steps)` (its value is the caller's) along the
    /// simulation of [`Model::simulate_with`] with these arguments, every step solved by modified Newton to
    /// `newton.tolerance` (the adjoint is exact at converged states only). `objective` receives
    /// the node positions of every frame (3 n each, m) and returns `dJ/dx` of every frame
    /// (`(steps + 1) 3 n` values, J's unit per m), or `None` to stop (its error is the caller's).
    /// `checkpoint_every` (0: [`default_checkpoint_interval`]) sets the memory (see the module docs).
    ///
    /// Contact (obstacles, self-contact) is differentiated without friction: the barrier at the
    /// step's end, with IPC's adaptive stiffness balanced at the step's start followed through
    /// its dependence on that start and on the parameters (its doublings within the step held;
    /// `balance`). Spring cables' dashpots are differentiated, their coefficients among the
    /// parameters.
    ///
    /// A step is halved as [`Model::simulate_with`] halves it (where Newton fails or a moving
    /// obstacle would run into the body over it: `sub_steps`), and the derivatives follow its
    /// sub-steps. Not differentiated (an error names it): friction.
    #[allow(clippy::too_many_arguments)]
    pub fn trajectory_gradient<F>(
        &mut self,
        loads: &Loads,
        dt: f64,
        actuation: &[Vec<f64>],
        damping: Damping,
        initial_positions: Option<&[f64]>,
        initial_velocities: Option<&[f64]>,
        newton: &NewtonOptions,
        checkpoint_every: usize,
        objective: F,
    ) -> Result<(RecordedPositions, TrajectoryGradient)>
    where
        F: FnOnce(&RecordedPositions) -> Option<Vec<f64>>,
    {
        let steps = actuation.len();
        let setup =
            self.differentiable_setup(loads, dt, actuation, damping, newton, StepMethod::Modified)?;
        self.continuation = None;
        let saved_tensions = self.tendon_tensions();
        let (mut state, _) = self.start_of_run(&setup, initial_positions, initial_velocities)?;
        let every = match checkpoint_every {
            0 => default_checkpoint_interval(steps, state.z.len() + state.velocity.len()),
            k => k,
        };
        let mut record = RecordedPositions {
            positions: vec![self.node_positions(&state.z)],
            iterations: Vec::with_capacity(steps),
            balanced_stiffness_steps: 0,
            split_steps: 0,
        };
        let mut checkpoints = Vec::new();
        let mut plans = Vec::with_capacity(steps);
        let mut reuse = FactorReuse::new(MAX_CONTRACTION);
        for (s, commands) in actuation.iter().enumerate() {
            if s % every == 0 {
                checkpoints.push(Checkpoint {
                    state: state.clone(),
                    tensions: self.tendon_tensions(),
                });
            }
            let plan = self.recorded_step(
                &setup,
                &mut state,
                dt,
                (s, commands.as_slice()),
                &mut reuse,
                &mut record,
                |_, _, _, _| Ok(()),
            )?;
            plans.push(plan);
        }
        // The last state closes the last segment: no segment recomputes its own end.
        checkpoints.push(Checkpoint {
            state,
            tensions: self.tendon_tensions(),
        });
        let n3 = 3 * self.mesh.n_nodes();
        let d_positions = objective(&record)
            .ok_or_else(|| Error::invalid("objective", "a derivative for every frame", "none"))?;
        if d_positions.len() != (steps + 1) * n3 {
            return Err(Error::shape(
                "objective",
                format!("({}, {}, 3)", steps + 1, n3 / 3),
                format!("{} values", d_positions.len()),
            ));
        }
        check_finite("objective", &d_positions)?;
        let gradient = self.backward(
            &setup,
            loads,
            dt,
            actuation,
            &checkpoints,
            &plans,
            every,
            &d_positions,
        );
        self.last_state = None;
        self.factor_at_solution = false;
        for (tendon, t) in self.terms.tendons.tendons.iter_mut().zip(saved_tensions) {
            tendon.tension = t;
        }
        Ok((record, gradient?))
    }

    /// Friction is lagged at every step's start (its force depends on the start through the
    /// lagged normal forces and slip basis, and is not the gradient of an energy of the end):
    /// its derivatives are not implemented, so a body with friction is refused.
    /// The step set-up of a differentiated run (every frame saved, solved by `method`), after
    /// checking that it has steps and nothing the derivatives do not cover.
    pub(super) fn differentiable_setup(
        &mut self,
        loads: &Loads,
        dt: f64,
        actuation: &[Vec<f64>],
        damping: Damping,
        newton: &NewtonOptions,
        method: StepMethod,
    ) -> Result<StepSetup> {
        if actuation.is_empty() {
            return Err(Error::invalid("steps", "at least one time step", 0));
        }
        self.check_differentiable()?;
        let options = DynamicsOptions {
            newton: newton.clone(),
            method,
            save_every: 1,
        };
        self.step_setup(loads, dt, actuation.len(), actuation, damping, &options)
    }

    fn check_differentiable(&self) -> Result<()> {
        if self
            .terms
            .contact
            .as_ref()
            .is_some_and(|c| c.has_friction())
        {
            return Err(Error::invalid(
                "friction",
                "frictionless contact (trajectory gradients through lagged friction are not implemented)",
                "an obstacle with friction > 0",
            ));
        }
        Ok(())
    }

    /// The barrier stiffness of the last step (J/m^4; 0 without contact).
    fn barrier_stiffness(&self) -> f64 {
        self.terms.contact.as_ref().map_or(0.0, |c| c.stiffness())
    }

    /// Each spring cable's index among all the model's cables.
    fn spring_cable_indices(&self) -> Vec<usize> {
        let mut out = vec![0; self.terms.cables.cables.len()];
        for (c, slot) in self.terms.slots.iter().enumerate() {
            if let CableSlot::Springs(i) = slot {
                out[*i] = c;
            }
        }
        out
    }

    fn tendon_tensions(&self) -> Vec<f64> {
        self.terms
            .tendons
            .tendons
            .iter()
            .map(|t| t.tension)
            .collect()
    }

    fn node_positions(&self, z: &[f64]) -> Vec<f64> {
        let rest = self.mesh.rest_flat();
        rest.iter().zip(z).map(|(x, u)| x + u).collect()
    }

    /// The adjoint sweep over the run's sub-steps, last first. Step k's solve and contractions
    /// run beside step k - 1's factorisation (two factors take turns): that factorisation
    /// needs step k - 1's states only, not `lambda_k`, and, sequential, leaves the other core
    /// free. It is in single precision, which moves work from it to the refined solves beside
    /// it (the factorisation takes 0.6 to 0.7 of the time, two refinements on the hammerbot).
    #[allow(clippy::too_many_arguments)]
    fn backward(
        &mut self,
        setup: &StepSetup,
        loads: &Loads,
        dt: f64,
        actuation: &[Vec<f64>],
        checkpoints: &[Checkpoint],
        plans: &[Vec<SubStep>],
        every: usize,
        d_positions: &[f64],
    ) -> Result<TrajectoryGradient> {
        let steps = actuation.len();
        let n_free = setup.free.len();
        let beta_k = setup.damping.stiffness;
        let layout = {
            let load_terms = self.terms.loads(loads);
            ParamLayout::new(&self.terms.parameterised(&load_terms))
        };
        let mut sweep = Sweep {
            flat: vec![0.0; layout.len],
            actuation: vec![vec![0.0; self.n_cables()]; steps],
            mass_damping: 0.0,
            stiffness_damping: 0.0,
            cable_damping: vec![0.0; self.n_cables()],
            next: vec![0.0; n_free],
            after_next: vec![0.0; n_free],
            next_h: dt,
            after_next_h: dt,
            start_force_term: vec![0.0; n_free],
            start_weights: None,
            load_weights: vec![0.0; self.layout.n_full()],
            balance_row: vec![0.0; n_free],
            balance_next: vec![0.0; n_free],
            balance_after_next: vec![0.0; n_free],
            balance_tensions: vec![0.0; self.n_cables()],
        };
        let mut stream = ReversedSubSteps::new(checkpoints, plans, actuation, every, dt);
        let mut factors = [self.factor.sibling()?, self.factor.sibling()?];
        let mut factored: Option<FactoredStep> = None;
        let mut slot = 0;
        while let Some(step) = stream.next(self, setup)? {
            self.set_step_commands(&actuation[step.step])?;
            let step_end = StepEnd {
                tensions: &step.tensions,
                barrier_stiffness: step.sub.barrier_stiffness,
                balanced_stiffness: step.sub.balanced_stiffness,
                time: step.sub.end_time,
            };
            let elastic_end = factored.as_ref().map(|f| &f.start_elastic);
            let (z0, z1) = (&step.start.z, &step.end.z);
            let prepared =
                self.prepare_step_end(setup, step.sub.h, (z0, z1), &step_end, elastic_end)?;
            let balance = self.stiffness_balance(&step_end, (z0, z1), &step.start_tensions);
            let nnz = self.assembler.pattern().nnz();
            if let Some(later) = &mut factored {
                if later.start_elastic.hessian.len() != nnz {
                    // Self-contact grew the pattern since: its products need the grown one.
                    later.start_elastic = self.internal_at(
                        &later.step.start.z,
                        ELASTIC,
                        true,
                        Some(HessianMode::Exact),
                    );
                }
                self.enter_adjoint_step(actuation, beta_k, later)?;
            }
            if factors[slot].analysed_nnz() != nnz {
                factors[slot] = self.factor.sibling()?;
            }
            // The elastic term at the step's start: the end of the step before (its Hessian
            // then) and the start force of this one (its Hessian with stiffness damping).
            let start_hessian = (step.index > 0 || beta_k > 0.0).then_some(HessianMode::Exact);
            let [first, second] = &mut factors;
            let (free, busy) = if slot == 0 {
                (first, &*second)
            } else {
                (second, &*first)
            };
            let model = &*self;
            let (ok, start_elastic) = rayon::join(
                || {
                    let pattern = model.assembler.pattern();
                    Ok(free.factor_single(pattern, &prepared.hessian)?
                        || free.factor(pattern, &prepared.hessian)?)
                },
                || -> Result<Evaluation> {
                    if let Some(later) = &factored {
                        let frame = model.objective_frame(later, d_positions);
                        model
                            .adjoint_step(setup, loads, &layout, busy, later, frame, &mut sweep)?;
                    }
                    Ok(model.internal_at(z0, ELASTIC, true, start_hessian))
                },
            );
            if !ok? {
                return Err(singular_step(step.index));
            }
            factored = Some(FactoredStep {
                step,
                damped_force: prepared.damped_force,
                dashpots: prepared.dashpots,
                start_elastic: start_elastic?,
                slot,
                balance,
            });
            slot = 1 - slot;
        }
        if let Some(first) = &factored {
            self.enter_adjoint_step(actuation, beta_k, first)?;
            let frame = self.objective_frame(first, d_positions);
            self.adjoint_step(
                setup,
                loads,
                &layout,
                &factors[first.slot],
                first,
                frame,
                &mut sweep,
            )?;
        }
        // The loads' parameter derivatives do not depend on the state: one contraction with
        // the sum of every step's weights.
        let load_terms = self.terms.loads(loads);
        let terms = self.terms.parameterised(&load_terms);
        for (term, offsets) in terms.iter().zip(&layout.term_offsets) {
            if term.is_linear() {
                let z = &checkpoints[0].state.z;
                add_contraction(*term, offsets, z, &sweep.load_weights, &mut sweep.flat);
            }
        }
        Ok(TrajectoryGradient {
            params: layout.unflatten(&sweep.flat),
            actuation: sweep.actuation,
            mass_damping: sweep.mass_damping,
            stiffness_damping: sweep.stiffness_damping,
            cable_damping: sweep.cable_damping,
        })
    }

    /// Sets the commands and the tendons of `factored`'s sub-step as its adjoint step reads
    /// them (the factorisation of the sub-step before may have left another's).
    fn enter_adjoint_step(
        &mut self,
        actuation: &[Vec<f64>],
        beta_k: f64,
        factored: &FactoredStep,
    ) -> Result<()> {
        let at = &factored.step;
        self.set_step_commands(&actuation[at.step])?;
        self.set_step_end_tensions(&at.tensions, 1.0 + beta_k / at.sub.h);
        Ok(())
    }

    /// `dJ/dx` of the frame a sub-step ends on (3 n values); None for a time step's sub-steps
    /// before its last (they end between frames).
    fn objective_frame<'a>(
        &self,
        factored: &FactoredStep,
        d_positions: &'a [f64],
    ) -> Option<&'a [f64]> {
        let n3 = 3 * self.mesh.n_nodes();
        let s = factored.step.step;
        factored
            .step
            .last_of_step
            .then(|| &d_positions[(s + 1) * n3..(s + 2) * n3])
    }

    /// Step k of the adjoint sweep, its Hessian factorised in `factor` and the model's commands
    /// and tendons as [`Model::set_step_end_tensions`] leaves them for it: `lambda_k`, then its
    /// share of every derivative.
    #[allow(clippy::too_many_arguments)]
    fn adjoint_step(
        &self,
        setup: &StepSetup,
        loads: &Loads,
        layout: &ParamLayout,
        factor: &SparseFactor,
        factored: &FactoredStep,
        d_frame: Option<&[f64]>,
        sweep: &mut Sweep,
    ) -> Result<()> {
        let FactoredStep {
            step: at,
            damped_force,
            dashpots,
            start_elastic,
            balance,
            ..
        } = factored;
        let (k, h) = (at.index, at.sub.h);
        let (start, end) = (&at.start, &at.end);
        let n3 = 3 * self.mesh.n_nodes();
        let (alpha_m, beta_k) = (setup.damping.mass, setup.damping.stiffness);
        let scale = 1.0 + beta_k / h;
        let (z0, z1) = (&start.z, &end.z);
        let n_free = setup.free.len();
        let start_hessian = (beta_k > 0.0).then_some(HessianMode::Exact);
        // Step k + 1's residual depends on u_{k+1} through its inertia, M (u_{k+2} - u_{k+1}) /
        // h_{k+1}^2 - M v_{k+1} / h_{k+1} with v_{k+1} = (u_{k+1} - u_k) / h_k, and step k + 2's
        // through v_{k+2}: the steps' lengths differ where a step was split.
        let (hn, han) = (sweep.next_h, sweep.after_next_h);
        let mut lambda: Vec<f64> = (0..n_free)
            .map(|f| {
                let d = setup.free[f];
                let m = setup.mass[f];
                let objective = match d_frame {
                    Some(frame) if d < n3 => frame[d],
                    _ => 0.0,
                };
                objective + m * (1.0 / (hn * hn) + 1.0 / (hn * h) + alpha_m / hn) * sweep.next[f]
                    - m / (han * hn) * sweep.after_next[f]
                    + sweep.start_force_term[f]
                    + sweep.balance_row[f]
                    - m / (hn * h) * sweep.balance_next[f]
                    + m / (han * hn) * sweep.balance_after_next[f]
            })
            .collect();
        factor.solve_to_precision(&mut lambda)?;
        // Taut displacement-controlled tendons: lambda meets their constraints' rows with the
        // next step's balance's dJ/dT (zero without one), and dJ/d pull = -mu.
        let active = self.active_tendons_at(z1, factor)?;
        let mut pull_gradients = Vec::new();
        if !active.is_empty() {
            let mu = schur_solve(
                &active,
                active
                    .iter()
                    .map(|a| dot(&a.row, &lambda) - sweep.balance_tensions[a.cable])
                    .collect(),
            )?;
            for (a, m) in active.iter().zip(&mu) {
                for (l, s) in lambda.iter_mut().zip(&a.solved) {
                    *l -= m * s;
                }
                pull_gradients.push((a.cable, -m));
            }
        }

        // The balanced stiffness's weight: J moves by -w |b|^2 d kappa_0 through it.
        let balance_weight = balance
            .as_ref()
            .map(|b| (b, b.weight(&lambda)))
            .filter(|&(_, w)| w != 0.0);
        // The start force beta_K / h P F(z_k), the tendons out of the internal force (the
        // elastic term's part assembled beside the factorisation).
        let start_hessian = if balance_weight.is_some() && k > 0 {
            Some(HessianMode::Exact)
        } else {
            start_hessian
        };
        let start_cables = self
            .has_cables()
            .then(|| self.internal_at(z0, CABLES, true, start_hessian));
        let mut start_force = start_elastic.gradient.clone();
        if let Some(cables) = &start_cables {
            add_to(&mut start_force, &cables.gradient);
        }
        let projected: Vec<f64> = (0..n_free)
            .map(|f| {
                if f < setup.n_displacement {
                    lambda[f]
                } else {
                    0.0
                }
            })
            .collect();
        sweep.start_force_term = if beta_k > 0.0 {
            let pattern = self.assembler.pattern();
            let mut product = pattern.symmetric_matvec(&start_elastic.hessian, &projected);
            if let Some(cables) = &start_cables {
                add_to(
                    &mut product,
                    &pattern.symmetric_matvec(&cables.hessian, &projected),
                );
            }
            product.iter().map(|v| beta_k / h * v).collect()
        } else {
            vec![0.0; n_free]
        };

        let mut at_end = vec![0.0; z1.len()];
        let mut at_start = vec![0.0; z1.len()];
        for (f, &d) in setup.free.iter().enumerate() {
            at_end[d] = -lambda[f];
            at_start[d] = beta_k / h * projected[f];
        }
        let BalanceAdjoint {
            weights: balance_weights,
            next: balance_next,
            row: balance_row,
        } = match balance_weight {
            Some((balance, w)) => self.balance_adjoint(
                setup,
                (balance, w),
                (k, start, h),
                start_elastic,
                start_cables.as_ref(),
            ),
            None => BalanceAdjoint::none(n_free),
        };
        if !dashpots.is_empty() {
            // at_end is -lambda: the coupling to the start enters lambda_{k-1}'s right-hand
            // side as +c / h dL/dz(z_k) (dL/dz(z_{k+1}) . lambda_k).
            let mut coupling = vec![0.0; z1.len()];
            dashpots.add_start_transpose(&at_end, &mut coupling);
            for (term, &d) in sweep.start_force_term.iter_mut().zip(&setup.free) {
                *term -= coupling[d];
            }
            dashpots.add_damping_contraction(h, &at_end, &mut sweep.cable_damping);
        }
        let load_terms = self.terms.loads(loads);
        let terms = self.terms.parameterised(&load_terms);
        let mut flat = vec![0.0; layout.len];
        // The registry's order: elastic, gravity, point gravity, spring cables, tendons. The
        // elastic and spring-cable forces carry the internal scale and the start force. The
        // elastic force's derivatives at z_{k+1} take step k + 1's start weights along, in one
        // pass; the loads' (linear: the same at every state) are contracted once with the sum
        // of every step's weights (`Model::backward`).
        add_to(&mut sweep.load_weights, &at_end);
        if let Some(weights) = &balance_weights {
            add_to(&mut sweep.load_weights, weights);
        }
        // The commanded tensions' share of g at z_k (the pulled ones' is the multipliers').
        let tendon_weights =
            (balance_weights.clone()).filter(|_| !self.terms.tendons.tendons.is_empty());
        // The internal terms' weights at z_k: the start force's and the balance's.
        let start_weights = match (beta_k > 0.0, balance_weights) {
            (true, Some(mut weights)) => {
                add_to(&mut weights, &at_start);
                Some(weights)
            }
            (true, None) => Some(at_start),
            (false, weights) => weights,
        };
        let scaled: Vec<f64> = at_end.iter().map(|v| scale * v).collect();
        let mut elastic_weights = scaled.clone();
        if let Some(later_start) = sweep.start_weights.take() {
            add_to(&mut elastic_weights, &later_start);
        }
        for (i, (term, offsets)) in terms.iter().zip(&layout.term_offsets).enumerate() {
            match i {
                0 => add_contraction(*term, offsets, z1, &elastic_weights, &mut flat),
                3 => add_contraction(*term, offsets, z1, &scaled, &mut flat),
                _ if term.is_linear() => {}
                _ => add_contraction(*term, offsets, z1, &at_end, &mut flat),
            }
            let start_too = i == 3 || (i == 0 && k == 0);
            if let (true, Some(weights)) = (start_too, &start_weights) {
                add_contraction(*term, offsets, z0, weights, &mut flat);
            }
            if let (4, Some(weights)) = (i, &tendon_weights) {
                add_contraction(*term, offsets, z0, weights, &mut flat);
            }
        }
        if k > 0 {
            sweep.start_weights = start_weights;
        }
        // The lumped mass: d(M a)/d rho_e = V_e / 4 a on each of the tet's nodes.
        let mut inertial = vec![0.0; z1.len()];
        for (f, &d) in setup.free.iter().enumerate().take(setup.n_displacement) {
            let acceleration =
                (end.velocity[f] - start.velocity[f]) / h + alpha_m * end.velocity[f];
            // The balance's -M v_k / h, weighted by w b.
            inertial[d] = -lambda[f] * acceleration - balance_next[f] * start.velocity[f] / h;
        }
        let (_, density_offset, _) = layout
            .blocks
            .iter()
            .find(|b| b.0 == "density")
            .cloned()
            .expect("the gravity term's density block");
        for (e, tet) in self.mesh.tets().iter().enumerate() {
            let share = self.terms.mass.nodal_volume(e);
            let sum: f64 = tet
                .iter()
                .flat_map(|&a| (0..3).map(move |i| 3 * a + i))
                .map(|d| inertial[d])
                .sum();
            flat[density_offset + e] += share * sum;
        }
        let pull_offset = layout
            .blocks
            .iter()
            .find(|b| b.0 == "cable_pull")
            .expect("the tendons' block")
            .1;
        for (c, g) in pull_gradients {
            flat[pull_offset + c] += g;
            sweep.actuation[at.step][c] += g;
        }
        for c in 0..self.n_cables() {
            let block = match self.cable_slot(c)? {
                crate::cables::CableSlot::Springs(_) => "cable_actuation",
                crate::cables::CableSlot::Tendon(_) => match self.tendon_command(c)? {
                    TendonCommand::Tension(_) => "cable_tension",
                    TendonCommand::Pull(_) => continue,
                },
            };
            let offset = layout
                .blocks
                .iter()
                .find(|b| b.0 == block)
                .expect("cable block")
                .1;
            sweep.actuation[at.step][c] += flat[offset + c];
        }
        for (total, v) in sweep.flat.iter_mut().zip(&flat) {
            *total += v;
        }
        for (f, l) in lambda.iter().enumerate() {
            let velocity = end.velocity[f];
            sweep.mass_damping -= l * setup.mass[f] * velocity;
            let start_force = if f < setup.n_displacement {
                start_force[f]
            } else {
                0.0
            };
            sweep.stiffness_damping -= l * (damped_force[f] - start_force) / h;
        }
        sweep.after_next = std::mem::replace(&mut sweep.next, lambda);
        sweep.after_next_h = std::mem::replace(&mut sweep.next_h, h);
        sweep.balance_after_next = std::mem::replace(&mut sweep.balance_next, balance_next);
        sweep.balance_row = balance_row;
        self.pulled_tension_weights(
            balance_weight,
            &at.start_tensions,
            &mut sweep.balance_tensions,
        );
        Ok(())
    }
}

#[cfg(test)]
mod tests;
