//! The time steps of a differentiated run as the simulation takes them: a step over which a
//! moving obstacle would run into the body, or whose Newton solve fails, is halved (up to
//! [`MAX_STEP_SPLITS`] times, as `Model::integrate` does), and the derivatives follow its
//! sub-steps, each an implicit Euler step of its own length. The lengths depend on the state
//! only through these decisions, so the run is smooth in the parameters wherever a small change
//! does not change them. The backward sweep replays the forward pass's lengths from a
//! checkpoint instead of deciding again: its states agree with the forward pass's to the
//! tolerance only, and a decision at its threshold could differ.

use crate::error::{Error, Result};
use crate::model::dynamics::{unconverged_step, StepSetup, StepState, MAX_STEP_SPLITS};
use crate::model::system::FactorReuse;
use crate::model::Model;

use super::RecordedPositions;

/// One converged sub-step of a time step.
#[derive(Clone, Copy, Debug)]
pub(super) struct SubStep {
    /// Its length (s).
    pub(super) h: f64,
    /// The time at its end (s): where the obstacles were.
    pub(super) end_time: f64,
    /// The barrier stiffness it converged with (J/m^4; 0 without contact).
    pub(super) barrier_stiffness: f64,
    /// The stiffness balanced at its start where the derivatives follow it (J/m^4; see
    /// [`Model::differentiated_balance`]).
    pub(super) balanced_stiffness: Option<f64>,
}

impl Model {
    /// Time step `s` (from `s dt`, with the cable commands `commands`) from `state`, solved to
    /// the tolerance by the setup's method with the factorisation `reuse` keeps, as sub-steps:
    /// the lengths `plan` (a forward pass's, replayed without deciding) or, without one, `dt`
    /// halved where an obstacle would run into the body or Newton fails. After every sub-step
    /// `each(model, start, end, sub_step)` sees the states it started from and ended at.
    /// Returns the sub-steps and the Newton iterations of the converged ones.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn converged_sub_steps(
        &mut self,
        setup: &StepSetup,
        state: &mut StepState,
        dt: f64,
        s: usize,
        commands: &[f64],
        reuse: &mut FactorReuse,
        plan: Option<&[SubStep]>,
        mut each: impl FnMut(&mut Model, &StepState, &StepState, &SubStep) -> Result<()>,
    ) -> Result<(Vec<SubStep>, usize)> {
        self.set_step_commands(commands)?;
        let time = s as f64 * dt;
        // A stack of (length, halvings so far); a replayed plan is never halved again.
        let mut pending: Vec<(f64, usize)> = match plan {
            Some(plan) => plan.iter().rev().map(|p| (p.h, MAX_STEP_SPLITS)).collect(),
            None => vec![(dt, 0)],
        };
        let (mut done, mut iterations, mut sub_time) = (Vec::new(), 0, time);
        while let Some((h, depth)) = pending.pop() {
            let end_time = sub_time + h;
            if plan.is_none()
                && self.obstacle_splits_step(&state.z, end_time, (s, time), (h, depth))?
            {
                pending.extend([(h / 2.0, depth + 1), (h / 2.0, depth + 1)]);
                continue;
            }
            if let Some(contact) = &mut self.terms.contact {
                contact.set_time(end_time);
            }
            let start = state.clone();
            match self.time_step(setup, state, h, reuse, &mut Vec::new()) {
                Ok(report) => {
                    iterations += report.iterations;
                    sub_time = end_time;
                    let sub = SubStep {
                        h,
                        end_time,
                        barrier_stiffness: self.barrier_stiffness(),
                        balanced_stiffness: self.differentiated_balance(),
                    };
                    each(self, &start, state, &sub)?;
                    done.push(sub);
                }
                Err(Error::NotConverged { .. }) if plan.is_none() && depth < MAX_STEP_SPLITS => {
                    if let Some(contact) = &mut self.terms.contact {
                        contact.set_time(sub_time);
                    }
                    pending.extend([(h / 2.0, depth + 1), (h / 2.0, depth + 1)]);
                }
                Err(Error::NotConverged { report, .. }) => {
                    return Err(unconverged_step(report, s, time, h));
                }
                Err(other) => return Err(other),
            }
        }
        Ok((done, iterations))
    }

    /// Time step `step = (s, commands)` of a differentiated run's forward pass, by
    /// [`Model::converged_sub_steps`] (deciding its halvings, `each` after every sub-step), with
    /// its frame, iterations, halvings and balanced barrier stiffnesses added to `record`.
    /// Returns its sub-steps.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn recorded_step(
        &mut self,
        setup: &StepSetup,
        state: &mut StepState,
        dt: f64,
        (s, commands): (usize, &[f64]),
        reuse: &mut FactorReuse,
        record: &mut RecordedPositions,
        mut each: impl FnMut(&mut Model, &StepState, &StepState, &SubStep) -> Result<()>,
    ) -> Result<Vec<SubStep>> {
        let mut followed = false;
        let (plan, iterations) = self.converged_sub_steps(
            setup,
            state,
            dt,
            s,
            commands,
            reuse,
            None,
            |model, start, end, sub| {
                followed |= sub.balanced_stiffness.is_some();
                each(model, start, end, sub)
            },
        )?;
        record.iterations.push(iterations);
        record.positions.push(self.node_positions(&state.z));
        record.balanced_stiffness_steps += usize::from(followed);
        record.split_steps += usize::from(plan.len() > 1);
        Ok(plan)
    }
}
