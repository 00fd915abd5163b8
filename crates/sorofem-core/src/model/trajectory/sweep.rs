//! What the backward sweep of `Model::backward` holds: the factorised sub-step beside the
//! next one's factorisation, and what it carries from step to step.

use super::balance::StiffnessBalance;
use super::dashpot::StepDashpots;
use super::reverse::ReversedSubStep;
use crate::assembly::Evaluation;

/// A sub-step of the backward sweep whose Hessian is factorised, with what its adjoint step
/// needs besides (see `Model::prepare_step_end`).
pub(super) struct FactoredStep {
    pub(super) step: ReversedSubStep,
    pub(super) damped_force: Vec<f64>,
    pub(super) dashpots: StepDashpots,
    /// The elastic term's gradient and Hessian at the sub-step's start (exact; none at the
    /// run's start without stiffness damping).
    pub(super) start_elastic: Evaluation,
    /// Which of the sweep's two factors holds its Hessian.
    pub(super) slot: usize,
    /// Its balanced barrier stiffness, where the derivatives follow it.
    pub(super) balance: Option<StiffnessBalance>,
}

/// What the backward sweep carries from step to step.
pub(super) struct Sweep {
    pub(super) flat: Vec<f64>,
    pub(super) actuation: Vec<Vec<f64>>,
    pub(super) mass_damping: f64,
    pub(super) stiffness_damping: f64,
    pub(super) cable_damping: Vec<f64>,
    /// `lambda_{k+1}` and `lambda_{k+2}` (free DOFs), and the lengths of steps k + 1 and
    /// k + 2 (s).
    pub(super) next: Vec<f64>,
    pub(super) after_next: Vec<f64>,
    pub(super) next_h: f64,
    pub(super) after_next_h: f64,
    /// `beta_K / h K_F(z_{k+1}) P lambda_{k+1}` and the dashpots' `c / h dL/dz(z_{k+1})
    /// (dL/dz(z_{k+2}) . lambda_{k+1})`.
    pub(super) start_force_term: Vec<f64>,
    /// `beta_K / h P lambda_{k+1}` (full DOFs): the weights of the elastic force's parameter
    /// derivatives at `z_{k+1}` as step k + 1's start force, contracted with step k's.
    pub(super) start_weights: Option<Vec<f64>>,
    /// The sum over the steps so far of the loads' weights `-lambda_k` (full DOFs).
    pub(super) load_weights: Vec<f64>,
    /// Step k + 1's balanced stiffness (`balance`): `w (H_B (g + 2 kappa_0 b) + K b)` at
    /// `z_{k+1}`, and `w b` of steps k + 1 and k + 2 (free DOFs, zero without one), with `w =
    /// lambda . dr/d kappa_0 / |b|^2` their weights.
    pub(super) balance_row: Vec<f64>,
    pub(super) balance_next: Vec<f64>,
    pub(super) balance_after_next: Vec<f64>,
    /// Step k + 1's balance's `dJ/dT` of each pulled tendon's multiplier at `z_{k+1}` (per
    /// cable: `w b . dL/dz`; zero where none).
    pub(super) balance_tensions: Vec<f64>,
}
