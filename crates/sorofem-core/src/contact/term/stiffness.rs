//! The barrier stiffness of a contact term: IPC's adaptive one (balanced against the other
//! forces at a solve's or step's start, doubled while gaps keep shrinking, within
//! `[kappa_ref, MAX_STIFFNESS_RATIO kappa_ref]`) or one held at `kappa_ref`.

use super::{ContactTerm, MAX_STIFFNESS_RATIO, STIFFNESS_UPDATE_SCALE};
use crate::assembly::Assembler;
use crate::contact::barrier::{
    barrier_gradient, initial_barrier_stiffness, update_barrier_stiffness, StiffnessBounds,
};
use crate::contact::broad_phase::candidates;
use crate::contact::potential::BarrierPotential;

impl ContactTerm {
    /// The barrier stiffness of the current solve (J/m^4).
    pub fn stiffness(&self) -> f64 {
        self.stiffness
    }

    pub fn set_stiffness(&mut self, stiffness: f64) {
        self.stiffness = stiffness;
    }

    /// The stiffness solves start from (J/m^4), once known (given, or set at the first solve).
    pub fn reference_stiffness(&self) -> Option<f64> {
        self.reference_stiffness
    }

    pub fn set_reference_stiffness(&mut self, stiffness: f64) {
        self.reference_stiffness = Some(stiffness);
    }

    /// The default `kappa_ref` (J/m^4) for a material of mean shear modulus `shear_modulus`
    /// (Pa): a node pushed onto an obstacle with the force `mu h^2` (`h` the mean boundary edge
    /// length; about the force that strains the material around the node by a third) rests at
    /// `dhat / 10`, i.e. `kappa = mu h^2 / (-b'(d) 2 sqrt(d))` at `d = (dhat / 10)^2`. Smaller
    /// forces leave wider gaps (below `dhat`), larger ones narrower: the gap, and so the error in
    /// the positions, stays a fraction of `dhat` for the forces a soft body carries.
    pub fn default_stiffness(&self, shear_modulus: f64) -> f64 {
        let s = 0.1 * self.dhat;
        let force = shear_modulus * self.mean_edge * self.mean_edge;
        force / (-barrier_gradient(s * s, self.dhat * self.dhat) * 2.0 * s)
    }

    /// The range the adaptive stiffness moves in: `[kappa_ref, 100 kappa_ref]`; `kappa_ref`
    /// alone when it does not adapt ([`ContactSetup::adaptive_stiffness`]).
    pub fn stiffness_bounds(&self) -> StiffnessBounds {
        let min = self.reference_stiffness.unwrap_or(self.stiffness);
        let ratio = if self.adaptive_stiffness {
            MAX_STIFFNESS_RATIO
        } else {
            1.0
        };
        StiffnessBounds {
            min,
            max: ratio * min,
        }
    }

    /// See [`ContactSetup::adaptive_stiffness`].
    pub fn adaptive_stiffness(&self) -> bool {
        self.adaptive_stiffness
    }

    /// IPC's update after an accepted Newton iterate (minimum squared distances before and after
    /// it, m^2): doubles the stiffness while the gaps keep shrinking below `1e-9` of the scene's
    /// diagonal. Returns whether the stiffness changed.
    pub fn update_stiffness(&mut self, previous_min_d2: f64, min_d2: f64) -> bool {
        let updated = update_barrier_stiffness(
            previous_min_d2,
            min_d2,
            self.stiffness,
            self.stiffness_bounds().max,
            self.bbox_diagonal,
            STIFFNESS_UPDATE_SCALE,
        );
        let changed = updated != self.stiffness;
        self.stiffness = updated;
        changed
    }

    /// IPC's initial stiffness: the `kappa` within [`ContactTerm::stiffness_bounds`] whose barrier
    /// gradient best balances `energy_gradient` (N, free DOFs) at `z`.
    pub fn balance_stiffness(&mut self, assembler: &Assembler, z: &[f64], energy_gradient: &[f64]) {
        let unit = BarrierPotential::try_new(self.dhat, 1.0).expect("dhat > 0");
        let x = self.positions(z);
        let found = candidates(&self.mesh, &x, self.dhat);
        let assembled = unit.assemble(&self.mesh, &found, &x, None);
        let mut barrier = vec![0.0; assembler.n_free()];
        for v in 0..self.rest.n_body() {
            for k in 0..3 {
                if let Some(f) = assembler.free_of_full(3 * v + k) {
                    barrier[f] = assembled.gradient[3 * v + k];
                }
            }
        }
        if assembled.energy.is_finite() {
            self.stiffness =
                initial_barrier_stiffness(energy_gradient, &barrier, self.stiffness_bounds());
        }
    }
}
