//! The derivatives of IPC's adaptive barrier stiffness through a step. Sub-step k balances its
//! stiffness at its start `z_k` (see `System::start_contact`), with the obstacles where they
//! are at its end:
//!
//! ```text
//! kappa_0 = -(b . g) / |b|^2,    b = grad B(z_k),
//! g = F(z_k) + sum_t T_t dL_t/dz(z_k) - f - M v_k / h   (b's rows)
//! ```
//!
//! with B the barrier at unit stiffness, F the elastic and spring-cable forces, f the loads
//! (free DOFs) and `T_t` tendon t's tension as its motor exerts it at the step's start: its
//! command under force control, the multiplier the sub-step before ended with under
//! displacement control. On the body's rows the step's other terms cancel at `z_k`: the mass damping
//! `alpha_M M (u - u_k) / h` vanishes there, the stiffness damping's start force is `beta_K / h
//! F(z_k)` against the internal scale's `beta_K / h F(z_k)`, and the dashpots' force and its
//! total derivative vanish. Newton doubles the stiffness m times while gaps keep shrinking (m is
//! held, as the halvings are: piecewise constant), so the step converges with `kappa =
//! 2^m kappa_0`, or at the bound's maximum, where it no longer moves. The differential is
//!
//! ```text
//! d kappa_0 = -[ (H_B(z_k) (g + 2 kappa_0 b) + K(z_k) b + sum_t T_t d2L_t/dz2 b) . dz_k
//!               - M b / (h h_{k-1}) . (du_k - du_{k-1}) + sum_t (b . dL_t/dz) dT_t
//!               + b . dg/dtheta dtheta ] / |b|^2
//! ```
//!
//! (`H_B` the barrier's exact Hessian, K the elastic and spring-cable Hessian, `v_k = (u_k -
//! u_{k-1}) / h_{k-1}`; `dT_t` the change of a pulled tendon's multiplier at the end of the
//! sub-step before, a commanded tension's being among dtheta), and the step's residual moves by
//! `2^m grad B(z_{k+1}) d kappa_0`. Where the balance was clamped at a bound the stiffness is a
//! constant and nothing is added.

use super::step_end::add_to;
use super::StepEnd;
use crate::assembly::Evaluation;
use crate::contact::{free_values, UnitBarrier};
use crate::energy::TendonCommand;
use crate::model::dynamics::{StepSetup, StepState};
use crate::model::Model;
use crate::sensitivity::dot;

/// One sub-step's balanced stiffness and what its derivatives need.
pub(super) struct StiffnessBalance {
    /// `kappa_0` (J/m^4).
    kappa: f64,
    /// `b = grad B(z_k)` on the free DOFs and `|b|^2`.
    pub(super) start: Vec<f64>,
    norm2: f64,
    /// `dr_k / d kappa_0 = 2^m grad B(z_{k+1})` on the free DOFs.
    pub(super) end: Vec<f64>,
    /// The barrier at `z_k`, its stencils' Hessians among it.
    barrier: UnitBarrier,
    /// Each tendon's tension at `z_k` as its motor exerts it (N), and `b . dL/dz(z_k)` (m^3:
    /// the balance's change per N of it).
    tensions: Vec<f64>,
    pub(super) tendon_rows: Vec<f64>,
}

impl StiffnessBalance {
    /// The weight `w = (lambda . dr_k/d kappa_0) / |b|^2` of the adjoint state `lambda` (free
    /// DOFs): through this step's balance J moves by `-w |b|^2 d kappa_0` ([`BalanceAdjoint`]).
    pub(super) fn weight(&self, lambda: &[f64]) -> f64 {
        dot(lambda, &self.end) / self.norm2
    }

    /// `b` over the full DOFs (`n_full` values) times `scale`.
    pub(super) fn start_full(&self, setup: &StepSetup, n_full: usize, scale: f64) -> Vec<f64> {
        let mut out = vec![0.0; n_full];
        for (f, &d) in setup.free.iter().enumerate() {
            out[d] = scale * self.start[f];
        }
        out
    }

    /// `d kappa_0` from the bracket of its differential (the module docs), `|b|^2 d kappa_0 =
    /// -along`.
    pub(super) fn kappa_change(&self, along: f64) -> f64 {
        -along / self.norm2
    }
}

/// A balance's share of the adjoint sweep at sub-step k, its weight w: `J` moves by `-w |b|^2
/// d kappa_0 = w (row . dz_k - M b / (h h_{k-1}) . (du_k - du_{k-1}) + b . dg/dtheta dtheta)`.
pub(super) struct BalanceAdjoint {
    /// `w b` (full DOFs): the weights of g's parameter derivatives, the step's terms' at `z_k`.
    pub(super) weights: Option<Vec<f64>>,
    /// `w b` (free DOFs), for the inertia's share of steps k - 1 and k - 2.
    pub(super) next: Vec<f64>,
    /// `w row` (free DOFs; zero at the run's first sub-step, whose start is data).
    pub(super) row: Vec<f64>,
}

impl BalanceAdjoint {
    pub(super) fn none(n_free: usize) -> Self {
        BalanceAdjoint {
            weights: None,
            next: vec![0.0; n_free],
            row: vec![0.0; n_free],
        }
    }
}

impl Model {
    /// The stiffness the last step balanced strictly inside its bounds (J/m^4), which the
    /// derivatives follow.
    pub(super) fn differentiated_balance(&self) -> Option<f64> {
        self.terms.contact.as_ref()?.balanced_stiffness()
    }

    /// `dJ/dT` of each pulled tendon's multiplier at `z_k` through the balance `balance` with
    /// weight `w` (per cable into `out`, N^-1 in J's unit: `w b . dL/dz`; zero for slack or
    /// commanded tendons, and everywhere without a balance): the right-hand side of the step
    /// before's constraint rows.
    pub(super) fn pulled_tension_weights(
        &self,
        balance: Option<(&StiffnessBalance, f64)>,
        start_tensions: &[f64],
        out: &mut [f64],
    ) {
        out.fill(0.0);
        let Some((balance, w)) = balance else {
            return;
        };
        for (t, cable) in self.taut_pulls(start_tensions) {
            out[cable] = w * balance.tendon_rows[t];
        }
    }

    /// The pulled tendons taut at a sub-step's start (`start_tensions`: their multipliers
    /// there), as (tendon, cable): those whose multiplier the balance reads as a state.
    pub(super) fn taut_pulls<'a>(
        &'a self,
        start_tensions: &'a [f64],
    ) -> impl Iterator<Item = (usize, usize)> + 'a {
        let term = &self.terms.tendons;
        (term.tendons.iter().enumerate())
            .filter(move |(t, tendon)| {
                matches!(tendon.command, TendonCommand::Pull(_)) && start_tensions[*t] > 0.0
            })
            .map(|(t, _)| (t, term.cable_index(t)))
    }

    /// The share of the balance `balance` with weight `w` ([`StiffnessBalance::weight`]) of
    /// sub-step `k` (from `start`, of length `h`), the elastic and spring-cable terms at its
    /// start given (gradients, and exact Hessians where `k > 0`).
    pub(super) fn balance_adjoint(
        &self,
        setup: &StepSetup,
        (balance, w): (&StiffnessBalance, f64),
        (k, start, h): (usize, &StepState, f64),
        start_elastic: &Evaluation,
        start_cables: Option<&Evaluation>,
    ) -> BalanceAdjoint {
        let mut share = BalanceAdjoint::none(setup.free.len());
        share.weights = Some(balance.start_full(setup, start.z.len(), w));
        share.next = balance.start.iter().map(|b| w * b).collect();
        if k > 0 {
            let pattern = self.assembler.pattern();
            let mut forces = start_elastic.gradient.clone();
            let mut stiffness_b = pattern.symmetric_matvec(&start_elastic.hessian, &balance.start);
            if let Some(cables) = start_cables {
                add_to(&mut forces, &cables.gradient);
                add_to(
                    &mut stiffness_b,
                    &pattern.symmetric_matvec(&cables.hessian, &balance.start),
                );
            }
            share.row = self.balance_state_row(setup, balance, (start, h), &forces, &stiffness_b);
            share.row.iter_mut().for_each(|v| *v *= w);
        }
        share
    }

    /// The balance of the sub-step ending at `end` (from `z0` to `z1`), with the obstacles where
    /// they are at its end (the caller has moved them); `None` where its stiffness does not
    /// move with the state: clamped, capped after doublings, not adaptive, or no contact.
    /// `start_tensions`: the tendons' tensions at `z0` (the pulled ones' multipliers; commanded
    /// ones are read from the commands set for the step).
    pub(super) fn stiffness_balance(
        &self,
        end: &StepEnd,
        (z0, z1): (&[f64], &[f64]),
        start_tensions: &[f64],
    ) -> Option<StiffnessBalance> {
        let contact = self.terms.contact.as_ref()?;
        let kappa = end.balanced_stiffness?;
        if end.barrier_stiffness >= contact.stiffness_bounds().max {
            return None;
        }
        let barrier = contact.unit_barrier(z0, true);
        let start = free_values(&self.assembler, &barrier.gradient);
        let norm2 = dot(&start, &start);
        let doubling = end.barrier_stiffness / kappa;

        let mut at_end = free_values(&self.assembler, &contact.unit_barrier(z1, false).gradient);
        at_end.iter_mut().for_each(|v| *v *= doubling);
        let tendons = &self.terms.tendons.tendons;
        let tensions: Vec<f64> = (tendons.iter().zip(start_tensions))
            .map(|(tendon, &t)| match tendon.command {
                TendonCommand::Tension(command) => command,
                TendonCommand::Pull(_) => t,
            })
            .collect();
        let tendon_rows = tendons
            .iter()
            .map(|tendon| {
                let mut gradient = vec![0.0; z0.len()];
                tendon.add_length_gradient(z0, 1.0, &mut gradient);
                dot(&free_values(&self.assembler, &gradient), &start)
            })
            .collect();
        (norm2 > 0.0).then_some(StiffnessBalance {
            kappa,
            start,
            norm2,
            end: at_end,
            barrier,
            tensions,
            tendon_rows,
        })
    }

    /// `H_B(z_k) (g + 2 kappa_0 b) + K(z_k) b + sum_t T_t d2L_t/dz2 b` on the free DOFs:
    /// `|b|^2 d kappa_0`'s part along `dz_k` besides the inertia (`-M b / (h h_{k-1})`, added
    /// by the callers, who know the lengths). `forces`: F(z_k) (elastic and spring cables, free
    /// DOFs); `stiffness_b`: `K(z_k) b`; `start` the sub-step's start state, `h` its length.
    pub(super) fn balance_state_row(
        &self,
        setup: &StepSetup,
        balance: &StiffnessBalance,
        (start, h): (&StepState, f64),
        forces: &[f64],
        stiffness_b: &[f64],
    ) -> Vec<f64> {
        let z0 = &start.z;
        let (mut tendon_force, mut tendon_product) = (vec![0.0; z0.len()], vec![0.0; z0.len()]);
        let b_full = balance.start_full(setup, z0.len(), 1.0);
        for (tendon, &tension) in self.terms.tendons.tendons.iter().zip(&balance.tensions) {
            if tension != 0.0 {
                tendon.add_length_gradient(z0, tension, &mut tendon_force);
                tendon.add_length_hessian_product(z0, tension, &b_full, &mut tendon_product);
            }
        }
        let n3 = balance.barrier.gradient.len();
        let mut shifted = vec![0.0; n3];
        for (f, &d) in setup.free.iter().enumerate().take(setup.n_displacement) {
            if d < n3 {
                let g = forces[f] + tendon_force[d]
                    - setup.full_load[d]
                    - setup.mass[f] * start.velocity[f] / h;
                shifted[d] = g + 2.0 * balance.kappa * balance.start[f];
            }
        }
        let product = balance.barrier.hessian_product(&shifted);
        let mut row = stiffness_b.to_vec();
        for (f, &d) in setup.free.iter().enumerate() {
            row[f] += tendon_product[d];
            if d < n3 {
                row[f] += product[d];
            }
        }
        row
    }
}
