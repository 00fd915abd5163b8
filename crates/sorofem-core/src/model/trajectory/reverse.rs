//! The sub-steps of a differentiated run from the last back, with the states they start and end
//! at: a segment's states are recomputed from its checkpoint when the sweep reaches it, with the
//! forward pass's sub-step lengths (see the module docs of `trajectory`).

use super::sub_steps::SubStep;
use super::Checkpoint;
use crate::error::Result;
use crate::model::dynamics::{StepSetup, StepState, MAX_CONTRACTION};
use crate::model::system::FactorReuse;
use crate::model::Model;

/// One sub-step of the run and the states around it.
pub(super) struct ReversedSubStep {
    /// Its index among the run's sub-steps (0: the run's first).
    pub(super) index: usize,
    /// The time step it belongs to.
    pub(super) step: usize,
    /// Whether it is its time step's last: only those end on a frame the objective reads.
    pub(super) last_of_step: bool,
    pub(super) sub: SubStep,
    pub(super) start: StepState,
    pub(super) end: StepState,
    /// The tendons' tensions at its start and at its end.
    pub(super) start_tensions: Vec<f64>,
    pub(super) tensions: Vec<f64>,
}

/// An iterator (by [`ReversedSubSteps::next`], which needs the model) over the run's sub-steps,
/// last first. It holds one segment's `every + 1` states at a time (its two ends copies of
/// checkpoints); each sub-step it returns carries copies of its own two.
pub(super) struct ReversedSubSteps<'a> {
    checkpoints: &'a [Checkpoint],
    plans: &'a [Vec<SubStep>],
    actuation: &'a [Vec<f64>],
    every: usize,
    dt: f64,
    /// Segments not loaded yet: the next one to load is `unloaded - 1`.
    unloaded: usize,
    /// The loaded segment's sub-step states (its checkpoint first, the next checkpoint last)
    /// with the tendons' tensions there, its sub-steps as (time step, whether the step's last,
    /// sub-step), the run's sub-steps before it and how many of its own are not yet returned.
    states: Vec<(StepState, Vec<f64>)>,
    subs: Vec<(usize, bool, SubStep)>,
    before: usize,
    left: usize,
}

impl<'a> ReversedSubSteps<'a> {
    /// `plans[s]`: time step s's sub-steps in the forward pass; `checkpoints[j]`: the state at
    /// the start of time step `j every`, the last one the run's end.
    pub(super) fn new(
        checkpoints: &'a [Checkpoint],
        plans: &'a [Vec<SubStep>],
        actuation: &'a [Vec<f64>],
        every: usize,
        dt: f64,
    ) -> Self {
        Self {
            checkpoints,
            plans,
            actuation,
            every,
            dt,
            unloaded: checkpoints.len().saturating_sub(1),
            states: Vec::new(),
            subs: Vec::new(),
            before: 0,
            left: 0,
        }
    }

    /// The next sub-step back, None after the run's first. Recomputing a segment runs the
    /// model's Newton solves (its factor, its terms' commands and tensions are changed).
    pub(super) fn next(
        &mut self,
        model: &mut Model,
        setup: &StepSetup,
    ) -> Result<Option<ReversedSubStep>> {
        while self.left == 0 {
            if self.unloaded == 0 {
                return Ok(None);
            }
            self.unloaded -= 1;
            self.load(model, setup, self.unloaded)?;
        }
        self.left -= 1;
        let i = self.left;
        let (step, last_of_step, sub) = self.subs[i];
        let (end, tensions) = &self.states[i + 1];
        Ok(Some(ReversedSubStep {
            index: self.before + i,
            step,
            last_of_step,
            sub,
            start: self.states[i].0.clone(),
            end: end.clone(),
            start_tensions: self.states[i].1.clone(),
            tensions: tensions.clone(),
        }))
    }

    /// Recomputes segment `segment`'s sub-step states from its checkpoint.
    fn load(&mut self, model: &mut Model, setup: &StepSetup, segment: usize) -> Result<()> {
        let (checkpoint, next) = (&self.checkpoints[segment], &self.checkpoints[segment + 1]);
        let steps = self.actuation.len();
        let first = segment * self.every;
        let last = (first + self.every).min(steps);
        let mut state = checkpoint.state.clone();
        for (tendon, &t) in (model.terms.tendons.tendons.iter_mut()).zip(&checkpoint.tensions) {
            tendon.tension = t;
        }
        // The last sub-step's end is the next checkpoint: it is not recomputed.
        self.states.clear();
        self.states
            .push((state.clone(), checkpoint.tensions.clone()));
        let mut reuse = FactorReuse::new(MAX_CONTRACTION);
        for (s, commands) in self.actuation.iter().enumerate().take(last).skip(first) {
            let plan = if s + 1 == last {
                &self.plans[s][..self.plans[s].len() - 1]
            } else {
                &self.plans[s][..]
            };
            if plan.is_empty() {
                continue;
            }
            let states = &mut self.states;
            model.converged_sub_steps(
                setup,
                &mut state,
                self.dt,
                s,
                commands,
                &mut reuse,
                Some(plan),
                |model, _, end, _| {
                    states.push((end.clone(), model.tendon_tensions()));
                    Ok(())
                },
            )?;
        }
        self.states
            .push((next.state.clone(), next.tensions.clone()));
        let plans = self.plans;
        self.before = plans[..first].iter().map(Vec::len).sum();
        self.subs = (first..last)
            .flat_map(|s| {
                let count = plans[s].len();
                plans[s]
                    .iter()
                    .enumerate()
                    .map(move |(i, sub)| (s, i + 1 == count, *sub))
            })
            .collect();
        self.left = self.subs.len();
        Ok(())
    }
}
