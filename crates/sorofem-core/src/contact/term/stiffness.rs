//! The barrier stiffness of a contact term: IPC's adaptive one (balanced against the other
//! forces at a solve's or step's start, doubled while gaps keep shrinking, within
//! `[kappa_ref, MAX_STIFFNESS_RATIO kappa_ref]`) or one held at `kappa_ref`.

use super::{ContactTerm, MAX_STIFFNESS_RATIO, STIFFNESS_UPDATE_SCALE};
use crate::assembly::Assembler;
use crate::contact::barrier::{
    balanced_barrier_stiffness, barrier_gradient, update_barrier_stiffness, StiffnessBounds,
};
use crate::contact::broad_phase::candidates;
use crate::contact::potential::{BarrierPotential, StencilHessian};
use crate::energy::HessianMode;

/// The barrier at unit stiffness, `B(z) = sum_k b(d_k; dhat^2)` (J per J/m^4), at one state:
/// its gradient on the body's node DOFs (`3 n_body`, m^4 per m) and, when asked for, its
/// stencils' exact Hessians (over collision vertices; the obstacles' rows are not DOFs).
#[derive(Clone, Debug, Default)]
pub struct UnitBarrier {
    pub gradient: Vec<f64>,
    pub hessians: Vec<StencilHessian>,
    /// Whether no stencil touches (the barrier is finite).
    pub finite: bool,
}

impl UnitBarrier {
    /// `H_B v` on the body's node DOFs (`v` and the result `3 n_body`).
    pub fn hessian_product(&self, v: &[f64]) -> Vec<f64> {
        let n = v.len();
        let mut out = vec![0.0; n];
        for stencil in &self.hessians {
            for (row, col, value) in stencil.entries() {
                if row < n && col < n {
                    out[row] += value * v[col];
                }
            }
        }
        out
    }
}

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
    /// gradient best balances `energy_gradient` (N, free DOFs) at `z`. Records the balanced
    /// value when it lies strictly inside the bounds ([`ContactTerm::balanced_stiffness`]).
    pub fn balance_stiffness(&mut self, assembler: &Assembler, z: &[f64], energy_gradient: &[f64]) {
        self.balanced_stiffness = None;
        let unit = self.unit_barrier(z, false);
        if !unit.finite {
            return;
        }
        let barrier = free_values(assembler, &unit.gradient);
        let bounds = self.stiffness_bounds();
        match balanced_barrier_stiffness(energy_gradient, &barrier) {
            Some(kappa) if kappa > bounds.min && kappa < bounds.max => {
                self.balanced_stiffness = Some(kappa);
                self.stiffness = kappa;
            }
            Some(kappa) => self.stiffness = kappa.clamp(bounds.min, bounds.max),
            None => self.stiffness = bounds.min,
        }
    }

    /// The stiffness the last [`ContactTerm::balance_stiffness`] balanced when it lay strictly
    /// inside the bounds (J/m^4): `-(grad B . g) / |grad B|^2`, a smooth function of the state
    /// and of the other forces there. `None` when it was clamped or nothing was within `dhat`.
    pub fn balanced_stiffness(&self) -> Option<f64> {
        self.balanced_stiffness
    }

    /// The barrier at unit stiffness at the full DOF vector `z`, with the obstacles where they
    /// are now (see [`UnitBarrier`]).
    pub fn unit_barrier(&self, z: &[f64], hessian: bool) -> UnitBarrier {
        let unit = BarrierPotential::try_new(self.dhat, 1.0).expect("dhat > 0");
        let x = self.positions(z);
        let found = candidates(&self.mesh, &x, self.dhat);
        let mode = hessian.then_some(HessianMode::Exact);
        let mut assembled = unit.assemble(&self.mesh, &found, &x, mode);
        assembled.gradient.truncate(3 * self.rest.n_body());
        UnitBarrier {
            finite: assembled.energy.is_finite(),
            gradient: assembled.gradient,
            hessians: assembled.hessians,
        }
    }
}

/// The free DOFs' entries of `full` (the first DOFs of the full vector; the rest are 0).
pub fn free_values(assembler: &Assembler, full: &[f64]) -> Vec<f64> {
    let mut out = vec![0.0; assembler.n_free()];
    for (d, &v) in full.iter().enumerate() {
        if let Some(f) = assembler.free_of_full(d) {
            out[f] = v;
        }
    }
    out
}
