//! The tendon side of [`System`]: the extended state (full DOFs followed by the multipliers of
//! the displacement-controlled tendons, see `TendonConstraints`) in and out of a solve.

use super::System;
use crate::energy::TendonCommand;

impl System<'_> {
    /// Extends a full DOF vector by the multipliers: the last solve's (`warm`) or zero.
    pub(in crate::model) fn extend_state(&self, z: &mut Vec<f64>, warm: bool) {
        let tensions = if warm {
            self.constraints.current(&self.model.terms.tendons)
        } else {
            vec![0.0; self.constraints.len()]
        };
        z.truncate(self.constraints.offset);
        z.extend(tensions);
    }

    /// Ends a solve from the extended state `z`: after a success (`converged`) its multipliers
    /// become the tendons' tensions; after a failure the tendons keep those they started with
    /// (the next warm start's). Cuts `z` back to the full DOFs.
    pub(in crate::model) fn finish_state(
        &mut self,
        z: &mut Vec<f64>,
        converged: bool,
        start: &[f64],
    ) {
        if converged {
            self.constraints
                .set_tensions(&mut self.model.terms.tendons, z);
        } else {
            let mut restored = z[..self.constraints.offset].to_vec();
            restored.extend_from_slice(start);
            self.constraints
                .set_tensions(&mut self.model.terms.tendons, &restored);
        }
        if self.tendon_scale() != 1.0 {
            for tendon in &mut self.model.terms.tendons.tendons {
                if let TendonCommand::Tension(tension) = tendon.command {
                    tendon.tension = tension;
                }
            }
        }
        z.truncate(self.constraints.offset);
    }

    /// For a failed solve: what each displacement-controlled tendon reached at the extended
    /// state `z`, as `(cable, commanded pull, pull, tension)`.
    pub(in crate::model) fn tendon_states(&self, z: &[f64]) -> Vec<(usize, f64, f64, f64)> {
        let term = &self.model.terms.tendons;
        (self
            .constraints
            .tendons
            .iter()
            .zip(self.constraints.multipliers(z)))
        .map(|(&t, &tension)| {
            let tendon = &term.tendons[t];
            let TendonCommand::Pull(d) = tendon.command else {
                unreachable!("constraints are displacement-controlled tendons")
            };
            (term.cable_index(t), d, tendon.pull(z), tension)
        })
        .collect()
    }

    /// The full DOFs of the extended state `z`, after giving the tendons its multipliers.
    pub(super) fn full_dofs<'z>(&mut self, z: &'z [f64]) -> &'z [f64] {
        self.constraints
            .set_tensions(&mut self.model.terms.tendons, z);
        let scale = self.tendon_scale();
        if scale != 1.0 {
            for &t in &self.constraints.tendons {
                self.model.terms.tendons.tendons[t].tension *= scale;
            }
        }
        &z[..self.constraints.offset]
    }

    /// What a tendon's tension is multiplied by in the terms: a time step scales the internal
    /// energy by `1 + beta_K / h` (stiffness damping, [`StepTerms`]), but a tendon's force is its
    /// motor's, so its tension `T` enters as `T / (1 + beta_K / h)` and exerts `T` undamped.
    pub(super) fn tendon_scale(&self) -> f64 {
        1.0 / self.step.as_ref().map_or(1.0, |step| step.internal_scale)
    }

    /// Which displacement-controlled tendons carry tension at the extended state `z`: their
    /// `T L''` is in the Hessian, so a kept factorisation fits only while this set holds.
    pub(super) fn taut(&self, z: &[f64]) -> Vec<bool> {
        let multipliers = self.constraints.multipliers(z);
        multipliers.iter().map(|&t| t != 0.0).collect()
    }

    /// [`System::gradient_without_contact`] with the displacement-controlled tendons pulling
    /// with the tensions of the last solve as their motors exert them (the terms take a
    /// multiplier `T` as `T / (1 + beta_K / h)`, see [`System::tendon_scale`]).
    pub(super) fn gradient_at_motor_tensions(&mut self, z: &[f64]) -> Vec<f64> {
        let scale = self.tendon_scale();
        let tendons = &mut self.model.terms.tendons.tendons;
        let saved: Vec<f64> = self
            .constraints
            .tendons
            .iter()
            .map(|&t| tendons[t].tension)
            .collect();
        for &t in &self.constraints.tendons {
            tendons[t].tension *= scale;
        }
        let g = self.gradient_without_contact(z);
        let tendons = &mut self.model.terms.tendons.tendons;
        for (&t, tension) in self.constraints.tendons.iter().zip(saved) {
            tendons[t].tension = tension;
        }
        g
    }
}
