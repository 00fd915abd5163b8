//! The Newton view of a model: its registry's terms plus the loads at a load factor (and, for a
//! time step, the inertia and damping), with the merit, directions and auxiliary iterates that
//! [`crate::newton`] asks of it. Statics and dynamics both solve through it.
//!
//! Displacement-controlled tendons add their multipliers to the state ([`TendonConstraints`]):
//! a solve's state is the full DOF vector followed by one tension per such tendon, and its
//! residual the free DOFs' followed by one complementarity row per tendon.

use super::tendons::TendonConstraints;
use super::{Formulation, Model};
use crate::contact::ccd::DEFAULT_MIN_SEPARATION;
use crate::energy::pressure_iterates::{PressureIterates, PressureLinearisations};
use crate::energy::{HessianMode, TendonCommand};
use crate::error::Result;
use crate::newton::{AuxiliaryIterates, Merit, NewtonOptions, NewtonProblem};
use crate::report::Timings;
use std::time::Instant;

mod reuse;
mod tendon_state;
mod warp;

pub(crate) use reuse::FactorReuse;

/// The Newton view of a model at a load factor.
pub(super) struct System<'a> {
    pub(super) model: &'a mut Model,
    /// External forces (N, full DOFs) at load factor 1, and at the current factor.
    pub(super) full_load: Vec<f64>,
    load: Vec<f64>,
    load_free_norm: f64,
    /// The least reference norm of the relative residual (N): a solve continuing from a
    /// converged state (a friction re-lag) is measured against the first solve's reference,
    /// not against its own leftover residual, which sits at round-off.
    pub(super) reference_floor: f64,
    prescribed: Vec<[f64; 3]>,
    /// Inertia and damping of an implicit Euler step, when the solve is one.
    step: Option<StepTerms>,
    /// [`NewtonOptions::pressure_iterates`] (standard formulation only).
    pressure_iterates: bool,
    /// The element pressures linearised at the current iterate, when `linearised_at_iterate`
    /// (swapped in from those the Hessian pass there recorded).
    linearised_pressures: PressureLinearisations,
    linearised_at_iterate: bool,
    /// The element pressure iterates of the current iterate (the model's elastic term holds
    /// those of the state last moved to with `AuxiliaryIterates::trial`).
    pressure_base: Vec<f64>,
    /// The model's Hessian scratch holds the exact Hessian at the state last evaluated.
    hessian_prepared: bool,
    /// The displacement-controlled tendons, whose multipliers follow the full DOFs in the state.
    pub(super) constraints: TendonConstraints,
    /// How this solve treats the model's contact, and what it measured (when there is contact).
    pub(super) contact: Option<ContactSolve>,
    /// Directions from a kept factorisation (dynamics), when set ([`System::keep_factorizations`]).
    pub(super) reuse: Option<FactorReuse>,
}

/// When the friction of a solve is lagged (see [`crate::contact::ContactTerm::lag_friction`]).
#[derive(Clone, Debug)]
pub(super) enum FrictionLag {
    /// Statics: at the start of every load step, from its state. The slip is measured from
    /// there too, or from `origin` (a full DOF vector) when given: lagging again at an
    /// equilibrium keeps measuring from the load step's start.
    LoadStep { origin: Option<Vec<f64>> },
    /// Dynamics: lagged by the caller before the solve (at the start of the time step).
    Fixed,
}

/// The contact side of one solve.
pub(super) struct ContactSolve {
    pub(super) friction: FrictionLag,
    /// Dynamics: the time step's start state (full DOFs), where IPC's initial stiffness
    /// balances the other forces of the step; statics keep the reference stiffness (`None`), so
    /// that a solve's result is a smooth function of the parameters (sensitivities, inverse
    /// problems). The step's start, not Newton's (extrapolated, then cut short of contact): the
    /// stiffness is then a smooth function of the step's start and of the parameters, which the
    /// trajectory derivatives differentiate.
    pub(super) balance_at: Option<Vec<f64>>,
    /// The stencils' Hessians are always projected, even in the exact Newton direction.
    pub(super) project: bool,
    /// The full DOF vector the last load step started from.
    pub(super) load_step_start: Vec<f64>,
    /// Minimum squared distance (m^2) at the last evaluated state and at the last accepted
    /// iterate.
    last_min_d2: f64,
    accepted_min_d2: f64,
    /// Minimum distance (m) at every accepted iterate (`+inf`: nothing within `dhat`; `-inf`:
    /// the audit found an intersection).
    pub(super) iterate_min_distances: Vec<f64>,
    /// The state last evaluated, kept for the audit (see [`crate::contact::ContactTerm::set_audit`]).
    last_z: Vec<f64>,
    /// Seconds in contact passes (broad phase, stencils, scatter) and in the step bounds.
    pub(super) seconds: f64,
    /// [`crate::contact::ContactPass::active_set`] at the state last evaluated.
    active_set: u64,
}

impl ContactSolve {
    /// Whether the last accepted iterate has a stencil within `dhat`.
    pub(super) fn within_dhat(&self) -> bool {
        self.accepted_min_d2.is_finite()
    }

    pub(super) fn new(friction: FrictionLag, balance_at: Option<Vec<f64>>) -> Self {
        ContactSolve {
            friction,
            balance_at,
            project: false,
            load_step_start: Vec::new(),
            last_min_d2: f64::INFINITY,
            accepted_min_d2: f64::INFINITY,
            iterate_min_distances: Vec::new(),
            last_z: Vec::new(),
            seconds: 0.0,
            active_set: 0,
        }
    }
}

/// The pressure iterates belong to one solve: the model's Hessians are exact again afterwards
/// (sensitivities, the next solve), whichever way the solve ended.
impl Drop for System<'_> {
    fn drop(&mut self) {
        self.model.terms.elastic.pressure_iterates = None;
    }
}

/// What implicit Euler adds to the energy of a step of length `h` (free DOFs `d`, `u` their
/// values, `u_n` those at the step's start):
///
/// ```text
/// E(z) = 1/2 sum_d inertia_d (u_d - predicted_d)^2 + 1/2 sum_d mass_damping_d (u_d - u_n,d)^2
///      + internal_scale Pi_int(z) - start_force . (u - u_n)
/// ```
///
/// with `inertia = m / h^2`, `mass_damping = alpha_M m / h`, `internal_scale = 1 + beta_K / h`
/// and `start_force = beta_K / h F(z_n)` (F the internal force, displacement rows only): its
/// stationarity is `M (u - u_n - h v_n) / h^2 + alpha_M M (u - u_n) / h + F(z) + beta_K (F(z) -
/// F(z_n)) / h = f`. The Rayleigh stiffness damping is `beta_K` times the rate of the internal
/// force over the step, which is `beta_K K(u) v` as h -> 0 (docs/theory.md, "Dynamics").
pub(super) struct StepTerms {
    pub(super) inertia: Vec<f64>,
    pub(super) predicted: Vec<f64>,
    pub(super) previous: Vec<f64>,
    pub(super) mass_damping: Vec<f64>,
    pub(super) internal_scale: f64,
    /// `beta_K / h F(z_n)` on the free DOFs (empty without stiffness damping).
    pub(super) start_force: Vec<f64>,
}

impl StepTerms {
    fn energy(&self, free: &[f64]) -> f64 {
        let mut e = 0.0;
        for d in 0..free.len() {
            let a = free[d] - self.predicted[d];
            let b = free[d] - self.previous[d];
            e += 0.5 * (self.inertia[d] * a * a + self.mass_damping[d] * b * b);
        }
        for ((f, x), y) in self.start_force.iter().zip(free).zip(&self.previous) {
            e -= f * (x - y);
        }
        e
    }

    fn add_gradient(&self, free: &[f64], g: &mut [f64]) {
        for d in 0..free.len() {
            g[d] += self.inertia[d] * (free[d] - self.predicted[d])
                + self.mass_damping[d] * (free[d] - self.previous[d]);
        }
        for (gi, f) in g.iter_mut().zip(&self.start_force) {
            *gi -= f;
        }
    }

    /// Adds the inertia and mass damping to the diagonal (each column's first entry) of the
    /// Hessian's values in `pattern` (the internal terms' already scaled by `internal_scale`).
    fn add_hessian(&self, pattern: &crate::linear::LowerPattern, hessian: &mut [f64]) {
        for d in 0..self.inertia.len() {
            hessian[pattern.col_ptr[d]] += self.inertia[d] + self.mass_damping[d];
        }
    }
}

impl<'a> System<'a> {
    pub(super) fn new(
        model: &'a mut Model,
        full_load: Vec<f64>,
        prescribed: Vec<[f64; 3]>,
        step: Option<StepTerms>,
        options: &NewtonOptions,
    ) -> Self {
        let pressure_iterates =
            options.pressure_iterates && model.formulation == Formulation::Standard;
        let constraints = TendonConstraints::new(
            &model.terms.tendons,
            model.layout.n_full(),
            model.constraint_weight,
        );
        System {
            model,
            full_load,
            load: Vec::new(),
            load_free_norm: 0.0,
            reference_floor: 0.0,
            prescribed,
            step,
            pressure_iterates,
            linearised_pressures: PressureLinearisations::new(0),
            linearised_at_iterate: false,
            pressure_base: Vec::new(),
            hessian_prepared: false,
            constraints,
            contact: None,
            reuse: None,
        }
    }
}

impl System<'_> {
    /// Takes directions from `reuse`'s kept factorisation. Pressure iterates only shape the
    /// Hessians Newton builds, and a kept factorisation serves iterates whose Hessians are never
    /// built: moving the iterates would cost an element pass per iteration for nothing, so the
    /// Hessians built here take their volumetric stiffness at `kappa c(J)`.
    pub(super) fn keep_factorizations(&mut self, reuse: FactorReuse) {
        self.reuse = Some(reuse);
        self.pressure_iterates = false;
    }

    fn n_nodes(&self) -> usize {
        self.model.mesh.n_nodes()
    }

    fn is_mixed(&self) -> bool {
        matches!(self.model.formulation, Formulation::Mixed { .. })
    }

    /// Takes the pressure linearisation the last Hessian pass recorded as that of the current
    /// iterate (the caller knows the pass was there).
    fn take_recorded_linearisation(&mut self) {
        if let Some(iterates) = &mut self.model.terms.elastic.pressure_iterates {
            std::mem::swap(&mut self.linearised_pressures, &mut iterates.recorded);
            self.linearised_at_iterate = true;
        }
    }

    /// Adds the contact's energy, gradient (when `gradient` is not empty) and Hessian (when
    /// given) at `z`; returns the contact energy (0 without contact).
    fn add_contact(
        &mut self,
        z: &[f64],
        gradient: &mut [f64],
        hessian: Option<(&mut [f64], HessianMode)>,
    ) -> f64 {
        let (Some(term), Some(solve)) = (&self.model.terms.contact, &mut self.contact) else {
            return 0.0;
        };
        let t0 = Instant::now();
        let hessian = hessian.map(|(values, mode)| {
            (
                values,
                if solve.project {
                    HessianMode::Projected
                } else {
                    mode
                },
            )
        });
        let pass = term.add_to(&self.model.assembler, z, gradient, hessian);
        solve.last_min_d2 = pass.min_squared_distance;
        solve.active_set = pass.active_set;
        if term.audit() {
            solve.last_z = z.to_vec();
        }
        solve.seconds += t0.elapsed().as_secs_f64();
        pass.energy
    }

    /// The gradient (N, free DOFs) of everything but contact at `z`: what the contact's
    /// initial stiffness balances.
    pub(super) fn gradient_without_contact(&self, z: &[f64]) -> Vec<f64> {
        let eval = self
            .model
            .assembler
            .evaluate(&self.model.terms.internal(), z, true, None);
        let mut g = eval.gradient;
        let mut energy = eval.energy;
        self.scale_internal(&mut energy, &mut g, None);
        for (gi, &d) in g.iter_mut().zip(self.model.assembler.full_of_free()) {
            *gi -= self.load[d];
        }
        if let Some(step) = &self.step {
            step.add_gradient(&self.free_values(z), &mut g);
        }
        g
    }

    /// Scales the internal terms' energy, gradient and Hessian values by the step's
    /// `internal_scale` (`1 + beta_K / h`, see [`StepTerms`]). Contact is added after: Rayleigh
    /// damping is the body's, and the barrier's forces stay the contact forces.
    fn scale_internal(&self, energy: &mut f64, gradient: &mut [f64], hessian: Option<&mut [f64]>) {
        let scale = self.step.as_ref().map_or(1.0, |step| step.internal_scale);
        if scale != 1.0 {
            *energy *= scale;
            gradient.iter_mut().for_each(|v| *v *= scale);
            if let Some(hessian) = hessian {
                hessian.iter_mut().for_each(|v| *v *= scale);
            }
        }
    }

    /// The active contacts at the state last evaluated (0 without contact).
    fn active_contacts(&self) -> u64 {
        self.contact.as_ref().map_or(0, |c| c.active_set)
    }

    fn free_values(&self, z: &[f64]) -> Vec<f64> {
        self.model
            .assembler
            .full_of_free()
            .iter()
            .map(|&d| z[d])
            .collect()
    }

    /// `-H^{-1} g` with the model's stored factorisation (in the mixed formulation `g`'s
    /// pressure rows carry the pressure weight, which the solve takes back out); with
    /// displacement-controlled tendons, the bordered step of the extended state `z` through
    /// that factorisation, the multipliers' increments appended. `None` when the bordered step
    /// gives non-finite values.
    fn solve_with_factor(&self, z: &[f64], g: &[f64], timings: &mut Timings) -> Option<Vec<f64>> {
        let t0 = Instant::now();
        let n_free = self.model.assembler.n_free();
        let mut d: Vec<f64> = g[..n_free].iter().map(|v| -v).collect();
        if self.is_mixed() {
            let n = self.n_nodes();
            d[n_free - n..]
                .iter_mut()
                .for_each(|v| *v /= self.model.pressure_weight);
        }
        // The constrained tendons' forces come out of the residual: the bordered step puts
        // them back at their new multipliers.
        let term = &self.model.terms.tendons;
        let full = &z[..self.constraints.offset];
        for (i, &tension) in self.constraints.multipliers(z).iter().enumerate() {
            if tension != 0.0 {
                let row = (self.constraints).jacobian_row(term, i, full, &self.model.assembler);
                for (di, ri) in d.iter_mut().zip(row) {
                    *di += tension * ri;
                }
            }
        }
        if self.reuse.as_ref().is_some_and(|r| r.refine) {
            self.model.factor.solve_refined_in_place(&mut d);
        } else {
            self.model.factor.solve_in_place(&mut d);
        }
        if !self.constraints.is_empty() {
            let model = &*self.model;
            let step = (self.constraints).bordered_step(
                &model.terms.tendons,
                z,
                &model.assembler,
                &model.factor,
                d,
            );
            let Some((dx, tensions)) = step else {
                timings.solve += t0.elapsed().as_secs_f64();
                return None;
            };
            d = dx;
            let current = self.constraints.multipliers(z);
            d.extend(tensions.iter().zip(current).map(|(new, old)| new - old));
        }
        timings.solve += t0.elapsed().as_secs_f64();
        Some(d)
    }

    /// Whether `d` may serve as a direction for gradient `g`: a descent direction of the energy
    /// (energy merit). No inertia test for residual merits: for the mixed formulation the
    /// condensed curvature `du^T A du + dp^T C dp` cancels catastrophically when the pressure
    /// (and so `K_geo(p)`) is large, and a step constrained by tendons need not descend the
    /// energy; finite values only.
    fn is_usable(&self, d: &[f64], g: &[f64]) -> bool {
        if self.merit() != Merit::Energy {
            d.iter().all(|v| v.is_finite())
        } else {
            d.iter().zip(g).map(|(a, b)| a * b).sum::<f64>() < 0.0
        }
    }

    /// Whether kept-factor directions are refined by secant pairs (see [`FactorReuse`]): the
    /// update needs an energy merit and the same energy at every iterate (a contact's barrier
    /// stiffness may change between them).
    fn learns_secants(&self) -> bool {
        self.merit() == Merit::Energy && self.contact.is_none() && self.step.is_some()
    }

    /// The merit (see [`NewtonProblem::merit_and_gradient`]) from the terms' energy and
    /// gradient at `z` (internal terms scaled, contact added).
    fn merit_at(&self, z: &[f64], energy: f64, gradient: Vec<f64>) -> (f64, Vec<f64>) {
        if !energy.is_finite() {
            return (f64::INFINITY, vec![f64::INFINITY; gradient.len()]);
        }
        let mut g = gradient;
        for (gi, &d) in g.iter_mut().zip(self.model.assembler.full_of_free()) {
            *gi -= self.load[d];
        }
        let free_values = self.step.as_ref().map(|_| self.free_values(z));
        if let (Some(step), Some(free)) = (&self.step, &free_values) {
            step.add_gradient(free, &mut g);
        }
        if self.is_mixed() {
            let n = self.n_nodes();
            let len = g.len();
            g[len - n..]
                .iter_mut()
                .for_each(|v| *v *= self.model.pressure_weight);
        }
        if self.merit() != Merit::Energy {
            g.extend(self.constraints.residual_rows(&self.model.terms.tendons, z));
            if g.iter().any(|v| !v.is_finite()) {
                return (f64::INFINITY, g);
            }
            return (0.5 * g.iter().map(|v| v * v).sum::<f64>(), g);
        }
        let external: f64 = self.load.iter().zip(z.iter()).map(|(f, x)| f * x).sum();
        let mut energy = energy - external;
        if let (Some(step), Some(free)) = (&self.step, &free_values) {
            energy += step.energy(free);
        }
        (energy, g)
    }
}

impl NewtonProblem for System<'_> {
    /// Standard: the potential energy. Mixed: half the squared weighted residual of the
    /// saddle-point system. The pressure is a Lagrange multiplier, so the mixed energy has no
    /// minimum to descend to, and eliminating p through `C p = phi` would amplify the
    /// second-order constraint error of every step by lambda (tiny steps as nu -> 0.5).
    ///
    /// The residual merit's non-monotone factor: half the squared residual may grow 100-fold
    /// (the residual 10-fold) over the recent maximum, so that full Newton steps of the
    /// saddle-point system are accepted far from the solution, where the Armijo test on the
    /// residual would creep in 1/16 steps.
    ///
    /// Displacement-controlled tendons make the problem a saddle point too (the multipliers have
    /// no energy to descend): the residual merit, with their complementarity rows.
    fn merit(&self) -> Merit {
        if self.is_mixed() || !self.constraints.is_empty() {
            Merit::Residual {
                nonmonotone_factor: 100.0,
            }
        } else {
            Merit::Energy
        }
    }

    fn set_load_factor(&mut self, factor: f64, z: &mut [f64]) {
        self.load = self.full_load.iter().map(|f| f * factor).collect();
        self.load_free_norm = self
            .model
            .assembler
            .full_of_free()
            .iter()
            .map(|&d| self.load[d] * self.load[d])
            .sum::<f64>()
            .sqrt();
        for (&node, u) in self.model.fixed_nodes.iter().zip(&self.prescribed) {
            for k in 0..3 {
                z[3 * node + k] = factor * u[k];
            }
        }
        // The motors' commands are loads: pulls and tensions grow with the factor.
        self.constraints.factor = factor;
        let scale = self.tendon_scale();
        for tendon in &mut self.model.terms.tendons.tendons {
            if let TendonCommand::Tension(tension) = tendon.command {
                tendon.tension = factor * tension * scale;
            }
        }
    }

    fn load_norm(&self) -> f64 {
        self.load_free_norm.max(self.reference_floor)
    }

    /// The merit (see [`NewtonProblem::merit`]) and the gradient of the energy minus the loads; in the
    /// mixed formulation the volume-constraint rows (m^3) are multiplied by the pressure weight
    /// so that they are forces too.
    fn merit_and_gradient(&mut self, z: &mut [f64]) -> (f64, Vec<f64>) {
        self.hessian_prepared = false;
        let full = self.full_dofs(z);
        let mut eval =
            self.model
                .assembler
                .evaluate(&self.model.terms.internal(), full, true, None);
        if eval.energy.is_finite() {
            self.scale_internal(&mut eval.energy, &mut eval.gradient, None);
            eval.energy += self.add_contact(full, &mut eval.gradient, None);
        }
        self.merit_at(z, eval.energy, eval.gradient)
    }

    fn merit_gradient_and_hessian(&mut self, z: &mut [f64]) -> (f64, Vec<f64>) {
        if self.cover_self_contact(z).is_err() {
            return self.merit_and_gradient(z); // `direction` reports the error
        }
        let full = self.full_dofs(z);
        let mut eval = std::mem::take(&mut self.model.hessian_scratch);
        self.model.assembler.evaluate_into(
            &self.model.terms.internal(),
            full,
            true,
            Some(HessianMode::Exact),
            &mut eval,
        );
        if eval.energy.is_finite() {
            let mut gradient = std::mem::take(&mut eval.gradient);
            self.scale_internal(&mut eval.energy, &mut gradient, Some(&mut eval.hessian));
            eval.energy += self.add_contact(
                full,
                &mut gradient,
                Some((&mut eval.hessian, HessianMode::Exact)),
            );
            eval.gradient = gradient;
        }
        let (energy, gradient) = (eval.energy, std::mem::take(&mut eval.gradient));
        self.model.hessian_scratch = eval;
        self.hessian_prepared = energy.is_finite();
        self.merit_at(z, energy, gradient)
    }

    fn direction(
        &mut self,
        z: &[f64],
        g: &[f64],
        projected: bool,
        timings: &mut Timings,
    ) -> Result<Option<Vec<f64>>> {
        let g_norm = g.iter().map(|v| v * v).sum::<f64>().sqrt();
        if !projected {
            if let Some(d) = self.kept_direction(z, g, g_norm, timings) {
                return Ok(Some(d));
            }
        }
        let mode = if projected {
            HessianMode::Projected
        } else {
            HessianMode::Exact
        };
        let t0 = Instant::now();
        self.cover_self_contact(z)?;
        let full = self.full_dofs(z);
        let mut eval = std::mem::take(&mut self.model.hessian_scratch);
        if !(self.hessian_prepared && mode == HessianMode::Exact) {
            self.model.assembler.evaluate_into(
                &self.model.terms.internal(),
                full,
                false,
                Some(mode),
                &mut eval,
            );
            self.take_recorded_linearisation();
            let mut hessian = std::mem::take(&mut eval.hessian);
            self.scale_internal(&mut 0.0, &mut [], Some(&mut hessian));
            self.add_contact(full, &mut [], Some((&mut hessian, mode)));
            eval.hessian = hessian;
        }
        self.hessian_prepared = false;
        if let Some(step) = &self.step {
            step.add_hessian(self.model.assembler.pattern(), &mut eval.hessian);
        }
        timings.assembly += t0.elapsed().as_secs_f64();
        let pattern = self.model.assembler.pattern();
        let t0 = Instant::now();
        let ok = if self.reuse.is_some() {
            self.factor_kept(&eval.hessian, g, timings)
        } else {
            self.model.factor.factor(pattern, &eval.hessian)
        };
        let contact_set = self.active_contacts();
        let seconds = t0.elapsed().as_secs_f64();
        self.model.hessian_scratch = eval;
        let ok = ok?;
        timings.factorization += seconds;
        timings.factorizations += 1;
        let taut = self.taut(z);
        let x = self.learns_secants().then(|| self.free_values(z));
        let rotate = self.reuse.as_ref().is_some_and(|r| r.rotate);
        let warp = (ok && rotate && self.contact.is_none() && self.constraints.is_empty())
            .then(|| warp::WarpReference::new(&self.model.mesh, &z[..3 * self.n_nodes()]));
        if let Some(reuse) = &mut self.reuse {
            reuse.warp = warp;
            reuse.rotations = None;
            reuse.secants.clear();
            if let Some(x) = x {
                reuse.secants.record(x, g);
            }
            reuse.kept = ok.then(|| self.model.factor.generation());
            reuse.contact_set = contact_set;
            reuse.last_norm = Some(g_norm);
            reuse.taut = taut;
        }
        if !ok {
            timings.failed_factorization += seconds;
            timings.failed_factorizations += 1;
            return Ok(None);
        }
        let d = self.solve_with_factor(z, g, timings);
        let usable = d.as_ref().is_some_and(|d| self.is_usable(d, g));
        if !usable {
            timings.failed_factorization += seconds;
            timings.failed_factorizations += 1;
            if let Some(reuse) = &mut self.reuse {
                reuse.kept = None;
            }
        }
        Ok(d.filter(|_| usable))
    }

    fn step(&self, z: &mut [f64], d: &[f64], t: f64) {
        let free = self.model.assembler.full_of_free();
        for (&full, di) in free.iter().zip(d) {
            z[full] += t * di;
        }
        let offset = self.constraints.offset;
        for (i, di) in d[free.len()..].iter().enumerate() {
            z[offset + i] += t * di;
        }
    }

    fn constraints_met(&self, z: &[f64]) -> bool {
        self.constraints.met(&self.model.terms.tendons, z)
    }

    /// No mesh node may move farther than the rest mesh's bounding-box diagonal in one step:
    /// such steps start at the largest power of two within that bound (seven trials fewer in
    /// the first iteration of the 1 m cantilever at 48x8x8 cells, whose linear step moves its
    /// tip 24 m). Within it, contact bounds the step by continuous collision detection, so that
    /// no iterate intersects.
    fn step_bound(&mut self, z: &[f64], d: &[f64]) -> f64 {
        let n = self.n_nodes();
        let mut squared = vec![0.0; n];
        for (&full, di) in self.model.assembler.full_of_free().iter().zip(d) {
            if full < 3 * n {
                squared[full / 3] += di * di;
            }
        }
        let longest = squared.iter().fold(0.0f64, |m, &v| m.max(v)).sqrt();
        let mut bound: f64 = 1.0;
        while longest * bound > self.model.mesh.diameter() && bound > 1e-12 {
            bound *= 0.5;
        }
        if let (Some(term), Some(solve)) = (&self.model.terms.contact, &mut self.contact) {
            let t0 = Instant::now();
            let mut dz = vec![0.0; 3 * n];
            for (&full, di) in self.model.assembler.full_of_free().iter().zip(d) {
                if full < 3 * n {
                    dz[full] = bound * di;
                }
            }
            let full = &z[..self.constraints.offset];
            bound *= term.max_step(full, &dz, DEFAULT_MIN_SEPARATION);
            solve.seconds += t0.elapsed().as_secs_f64();
        }
        bound
    }

    fn reuses_factorizations(&self) -> bool {
        self.reuse.is_some()
    }

    fn auxiliary(&mut self) -> Option<&mut dyn AuxiliaryIterates> {
        if self.pressure_iterates || self.contact.is_some() {
            Some(self)
        } else {
            None
        }
    }
}

/// The element pressure iterates of [`NewtonOptions::pressure_iterates`], and the contact's
/// lagged friction (at load step starts) and adaptive barrier stiffness.
impl AuxiliaryIterates for System<'_> {
    fn start(&mut self, z: &[f64]) {
        if self.contact.is_some() {
            self.start_contact(&z[..self.constraints.offset]);
        }
        if self.pressure_iterates {
            self.pressure_base = self.model.terms.elastic.pressures_at(z);
            self.model.terms.elastic.pressure_iterates =
                Some(PressureIterates::new(self.pressure_base.clone()));
            // Swapped with the recorded ones: both sized for every tet.
            if self.linearised_pressures.n_tets() != self.pressure_base.len() {
                self.linearised_pressures = PressureLinearisations::new(self.pressure_base.len());
            }
            self.linearised_at_iterate = false;
        }
    }

    fn trial(&mut self, z: &[f64], d: &[f64], t: f64) {
        if self.pressure_iterates {
            let mut dz = vec![0.0; z.len()];
            for (&full, di) in self.model.assembler.full_of_free().iter().zip(d) {
                dz[full] = *di;
            }
            if !self.linearised_at_iterate {
                self.linearised_pressures = self.model.terms.elastic.linearised_pressures(z);
                self.linearised_at_iterate = true;
            }
            if let Some(iterates) = &mut self.model.terms.elastic.pressure_iterates {
                iterates.values.clone_from(&self.pressure_base);
            }
            self.model
                .terms
                .elastic
                .advance_pressures(&self.linearised_pressures, &dz, t);
        }
    }

    fn commit(&mut self) -> bool {
        let changed = self.commit_contact();
        if let Some(iterates) = &self.model.terms.elastic.pressure_iterates {
            self.pressure_base.clone_from(&iterates.values);
            self.linearised_at_iterate = false;
            // Accepted where the line search built the next Hessian: that pass recorded the
            // linearisation at the new iterate.
            if self.hessian_prepared {
                self.take_recorded_linearisation();
            }
        }
        if changed {
            self.hessian_prepared = false;
        }
        changed
    }
}

impl System<'_> {
    /// The start of a load step (statics) or time step (dynamics): the friction lagged there
    /// (statics), the barrier stiffness balanced there (dynamics).
    fn start_contact(&mut self, z: &[f64]) {
        let balance = self.contact.as_ref().and_then(|c| c.balance_at.clone());
        let energy_gradient = balance.map(|at| {
            let g = self.gradient_at_motor_tensions(&at);
            (at, g)
        });
        let (Some(term), Some(solve)) = (&mut self.model.terms.contact, &mut self.contact) else {
            return;
        };
        let t0 = Instant::now();
        solve.load_step_start = z.to_vec();
        solve.accepted_min_d2 = f64::INFINITY;
        if let Some((at, g)) = energy_gradient {
            term.balance_stiffness(&self.model.assembler, &at, &g);
        }
        if let FrictionLag::LoadStep { origin } = &solve.friction {
            let slip = term.friction_slip();
            term.lag_friction(z, origin.as_deref().unwrap_or(z), slip);
        }
        solve.seconds += t0.elapsed().as_secs_f64();
    }

    /// After an accepted iterate: IPC's stiffness update. Returns whether it changed the merit.
    fn commit_contact(&mut self) -> bool {
        let (Some(term), Some(solve)) = (&mut self.model.terms.contact, &mut self.contact) else {
            return false;
        };
        let previous = solve.accepted_min_d2;
        solve.accepted_min_d2 = solve.last_min_d2;
        let distance = if term.audit() && term.intersects(&solve.last_z) {
            f64::NEG_INFINITY
        } else {
            solve.last_min_d2.sqrt()
        };
        solve.iterate_min_distances.push(distance);
        term.update_stiffness(previous, solve.last_min_d2)
    }
}
