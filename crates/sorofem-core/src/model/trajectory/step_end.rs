//! Step k's Hessian at its converged end, factorised for both sweeps (the adjoint and the
//! forward sensitivity), with the internal terms evaluated apart so that the elastic term's
//! Hessian at a state can serve the two steps that meet there.

use super::dashpot::StepDashpots;
use super::StepEnd;
use crate::assembly::{Assembler, Evaluation};
use crate::energy::{HessianMode, TendonCommand};
use crate::error::{Error, Result};
use crate::model::dynamics::StepSetup;
use crate::model::terms::Terms;
use crate::model::Model;

/// Which of the internal terms (elastic, spring cables, tendons: [`Terms::internal`]'s order)
/// an evaluation takes.
pub(super) const ELASTIC: [bool; 3] = [true, false, false];
pub(super) const CABLES: [bool; 3] = [false, true, false];
const CABLES_AND_TENDONS: [bool; 3] = [false, true, true];

pub(super) fn add_to(total: &mut [f64], part: &[f64]) {
    total.iter_mut().zip(part).for_each(|(t, p)| *t += p);
}

impl Model {
    /// The internal terms `which` selects (see [`ELASTIC`]) at the full DOF vector `z`.
    pub(super) fn internal_at(
        &self,
        z: &[f64],
        which: [bool; 3],
        gradient: bool,
        hessian: Option<HessianMode>,
    ) -> Evaluation {
        self.assembler
            .evaluate_selected(&self.terms.internal(), &which, z, gradient, hessian)
    }

    /// Whether the model has spring cables or tendons.
    pub(super) fn has_cables(&self) -> bool {
        !(self.terms.cables.cables.is_empty() && self.terms.tendons.tendons.is_empty())
    }
    /// The tendons as step k's solve had them at its end (`tensions`, the step's own), their
    /// tensions (multipliers or commands) divided by the internal scale `1 + beta_K / h`: their
    /// force is the motor's, not damped. With the step's commands
    /// ([`Model::set_step_commands`]) this is what the step's derivatives read of the tendons.
    pub(super) fn set_step_end_tensions(&mut self, tensions: &[f64], scale: f64) {
        for (tendon, &t) in self.terms.tendons.tendons.iter_mut().zip(tensions) {
            tendon.tension = match tendon.command {
                TendonCommand::Pull(_) => t / scale,
                TendonCommand::Tension(command) => command / scale,
            };
        }
    }

    /// Step k's Hessian `H_k = dr_k/du_{k+1}` at its converged end `z1` (from `z0`; the step's
    /// commands set, the tendons as [`Model::set_step_end_tensions`] leaves them, the cables'
    /// dashpots on, the contact barrier's exact Hessian with the obstacles where they are at
    /// the step's end and the stiffness the step converged with), in the assembler's pattern,
    /// with the damped internal force `F(z1)` that beta_K scales (free DOFs, N; the tendons'
    /// force and the dashpots' out) and the step's dashpots. `elastic`: the elastic term's
    /// gradient and exact Hessian at `z1` when already assembled (as the start of step k + 1;
    /// assembled afresh when self-contact has grown the pattern since).
    pub(super) fn prepare_step_end(
        &mut self,
        setup: &StepSetup,
        h: f64,
        (z0, z1): (&[f64], &[f64]),
        end: &StepEnd,
        elastic: Option<&Evaluation>,
    ) -> Result<PreparedStepEnd> {
        let (alpha_m, beta_k) = (setup.damping.mass, setup.damping.stiffness);
        let scale = 1.0 + beta_k / h;
        self.set_step_end_tensions(end.tensions, scale);
        if let Some(contact) = &mut self.terms.contact {
            contact.set_time(end.time);
            contact.set_stiffness(end.barrier_stiffness);
        }
        self.cover_self_contact(z1)?;
        let nnz = self.assembler.pattern().nnz();
        let mut eval = match elastic {
            Some(elastic) if elastic.hessian.len() == nnz => elastic.clone(),
            _ => self.internal_at(z1, ELASTIC, true, Some(HessianMode::Exact)),
        };
        if self.has_cables() {
            // The dashpots as the step's solve had them (over h + beta_K: see
            // `Model::time_step`).
            self.terms.cables.begin_step(h + beta_k, z0);
            let cables = self.internal_at(z1, CABLES_AND_TENDONS, true, Some(HessianMode::Exact));
            self.terms.cables.end_step();
            add_to(&mut eval.gradient, &cables.gradient);
            add_to(&mut eval.hessian, &cables.hessian);
        }
        eval.hessian.iter_mut().for_each(|v| *v *= scale);
        // Contact after the scaling: Rayleigh damping is the body's, not the barrier's.
        self.add_contact_hessian(z1, &mut eval.hessian, HessianMode::Exact);
        // The diagonal is each column's first entry of the lower pattern.
        let col_ptr = &self.assembler.pattern().col_ptr;
        for (f, &m) in setup.mass.iter().enumerate() {
            eval.hessian[col_ptr[f]] += m / (h * h) + alpha_m * m / h;
        }
        // The damped internal force at the end (what beta_K scales): the tendons' and the
        // dashpots' out (the dashpots' force c dL/dt does not change with beta_K).
        let dashpots =
            StepDashpots::new(&self.terms.cables, &self.spring_cable_indices(), h, z0, z1);
        let mut damped_force = eval.gradient;
        let mut other_force = vec![0.0; z1.len()];
        for tendon in &self.terms.tendons.tendons {
            tendon.add_length_gradient(z1, tendon.tension, &mut other_force);
        }
        dashpots.add_force(1.0 / scale, &mut other_force);
        for (g, &d) in damped_force.iter_mut().zip(&setup.free) {
            *g -= other_force[d];
        }
        Ok(PreparedStepEnd {
            hessian: eval.hessian,
            damped_force,
            dashpots,
        })
    }

    /// Factors step k's Hessian ([`Model::prepare_step_end`], without an elastic term assembled
    /// before) in the model's factor and returns the damped internal force and the dashpots.
    /// `beside` runs on another thread while the (sequential) factorisation does; it sees the
    /// assembler and the terms, not the factor.
    pub(super) fn factor_step_end<R: Send>(
        &mut self,
        setup: &StepSetup,
        h: f64,
        k: usize,
        (z0, z1): (&[f64], &[f64]),
        end: &StepEnd,
        beside: impl FnOnce(&Assembler, &Terms) -> R + Send,
    ) -> Result<(Vec<f64>, StepDashpots, R)> {
        let prepared = self.prepare_step_end(setup, h, (z0, z1), end, None)?;
        let (factor, assembler, terms) = (&mut self.factor, &self.assembler, &self.terms);
        let (factored, beside) = rayon::join(
            || factor.factor(assembler.pattern(), &prepared.hessian),
            || beside(assembler, terms),
        );
        if !factored? {
            return Err(singular_step(k));
        }
        Ok((prepared.damped_force, prepared.dashpots, beside))
    }
}

/// The error of a step whose Hessian at its end has no factorisation.
pub(super) fn singular_step(k: usize) -> Error {
    Error::LinearSolver {
        message: format!("the Hessian of time step {k} is singular at its end: the trajectory derivatives are undefined there"),
    }
}

/// Step k's Hessian at its end and what its derivatives need besides (see
/// [`Model::prepare_step_end`]).
pub(super) struct PreparedStepEnd {
    /// `H_k` in the assembler's lower pattern.
    pub(super) hessian: Vec<f64>,
    /// The damped internal force `F(z_{k+1})` (free DOFs, N).
    pub(super) damped_force: Vec<f64>,
    pub(super) dashpots: StepDashpots,
}
