//! Newton's method with a backtracking line search and load stepping with automatic cut-back.
//!
//! The solver minimises a merit energy over the free DOFs. Each iteration factors the exact
//! Hessian first (quadratic convergence); only when that is not positive definite (or, for
//! saddle-point systems, gives no descent direction) does it fall back to element-wise projected
//! Hessians. The line search never accepts a state with an inverted element (infinite energy).

use crate::error::{Error, Result};
use crate::report::{SolveReport, Timings};
use std::fmt;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

/// Newton settings.
#[derive(Clone, Debug, PartialEq)]
pub struct NewtonOptions {
    /// Stop when `||g|| <= tolerance * reference` (relative residual).
    pub tolerance: f64,
    /// Per load step.
    pub max_iterations: usize,
    /// Initial number of equal load increments.
    pub load_steps: usize,
    /// How many times in total an increment may be halved after a failure.
    pub max_cutbacks: usize,
    /// Standard formulation: Hessians take their volumetric stiffness at element pressure
    /// iterates (Newton's method on the element-wise perturbed-Lagrangian form of the same
    /// energy; see [`crate::energy::ElasticTerm::advance_pressures`]) rather than at
    /// `kappa c(J)`. Same solution, quadratic convergence, and fewer iterations when the body
    /// rotates (docs/theory.md, "Newton's method", has the counts). `false`: the exact Hessian
    /// of the energy. Time steps that keep their factorisation (modified Newton, linearly
    /// implicit) never use them (see `System::keep_factorizations`).
    pub pressure_iterates: bool,
    /// Asks the solve to stop ([`Error::Interrupted`]): polled at the start of every load step
    /// (and of every retry after a cut-back) and of every Newton iteration. Not a setting: it
    /// takes no part in comparing options.
    pub interrupt: Interrupt,
}

/// A request to stop a running solve, shared between the solve (which polls it) and whoever
/// may ask (a Ctrl-C watcher on another thread). The default asks never and costs nothing.
#[derive(Clone, Default)]
pub struct Interrupt(Option<Arc<AtomicBool>>);

impl Interrupt {
    /// A request not made yet; clones share it.
    pub fn new() -> Self {
        Interrupt(Some(Arc::new(AtomicBool::new(false))))
    }

    /// Asks every solve holding a clone of this to stop at its next poll.
    pub fn request(&self) {
        if let Some(flag) = &self.0 {
            flag.store(true, Ordering::Relaxed);
        }
    }

    pub fn is_requested(&self) -> bool {
        self.0
            .as_ref()
            .is_some_and(|flag| flag.load(Ordering::Relaxed))
    }
}

impl fmt::Debug for Interrupt {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.0 {
            None => write!(f, "Interrupt(never)"),
            Some(_) => write!(f, "Interrupt(requested: {})", self.is_requested()),
        }
    }
}

impl PartialEq for Interrupt {
    fn eq(&self, _other: &Self) -> bool {
        true
    }
}

impl NewtonOptions {
    /// Checks every setting; the error names the first bad one.
    pub fn validate(&self) -> Result<()> {
        if !(self.tolerance > 0.0 && self.tolerance.is_finite()) {
            return Err(Error::invalid(
                "tolerance",
                "a finite relative residual > 0",
                self.tolerance,
            ));
        }
        if self.max_iterations == 0 {
            return Err(Error::invalid(
                "max_iterations",
                "at least 1 Newton iteration per load step",
                self.max_iterations,
            ));
        }
        if self.load_steps == 0 {
            return Err(Error::invalid(
                "load_steps",
                "at least 1 load step",
                self.load_steps,
            ));
        }
        Ok(())
    }
}

impl Default for NewtonOptions {
    fn default() -> Self {
        NewtonOptions {
            tolerance: 1e-8,
            max_iterations: 50,
            load_steps: 1,
            max_cutbacks: 8,
            pressure_iterates: true,
            interrupt: Interrupt::default(),
        }
    }
}

/// What the line search measures progress by.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Merit {
    /// The energy whose Hessian the directions come from: its slope along `d` is `g . d`, and
    /// the Hessian's quadratic model predicts its decrease (which decides when a projected phase
    /// may return to the exact Hessian).
    Energy,
    /// Half the squared residual `|g|^2 / 2` (saddle-point problems, whose energy has no
    /// minimum). Its slope along an exact Newton step is `-|g|^2`. A trial is also accepted when
    /// its merit is at most `nonmonotone_factor` times the largest merit of the last five
    /// iterates and at most its square times the merit at the start of the load step: the
    /// Armijo test on a residual stalls far from the solution.
    Residual { nonmonotone_factor: f64 },
}

impl Merit {
    /// Derivative of the merit along `d` at `t = 0`, given the gradient `g` there.
    pub fn slope(&self, g: &[f64], d: &[f64]) -> f64 {
        match self {
            Merit::Energy => dot(g, d),
            // d is an exact Newton step of the residual g, so d/dt (|g|^2 / 2) = -|g|^2.
            Merit::Residual { .. } => -dot(g, g),
        }
    }

    fn nonmonotone_factor(&self) -> f64 {
        match self {
            Merit::Energy => 0.0,
            Merit::Residual { nonmonotone_factor } => *nonmonotone_factor,
        }
    }
}

/// A minimisation problem in the free DOFs, at a given load factor.
pub trait NewtonProblem {
    /// How the line search judges a step.
    fn merit(&self) -> Merit;
    /// Sets the load factor (0: unloaded, 1: full loads) and applies it to the fixed DOFs of `z`.
    fn set_load_factor(&mut self, factor: f64, z: &mut [f64]);
    /// Norm of the external load on the free DOFs at the current factor (N): the residual scale.
    fn load_norm(&self) -> f64;
    /// The merit (`+inf` when the state is inadmissible) and the gradient of the energy with
    /// respect to the free DOFs (the residual Newton drives to zero). Evaluated together
    /// because every accepted line-search trial needs both, and one pass over the elements
    /// costs little more than the energy alone.
    fn merit_and_gradient(&mut self, z: &mut [f64]) -> (f64, Vec<f64>);
    /// [`NewtonProblem::merit_and_gradient`] that also assembles the exact Hessian at `z` and
    /// keeps it for the next [`NewtonProblem::direction`] (which must then be at this `z`): one
    /// pass over the elements instead of two when the full step is expected to be accepted.
    fn merit_gradient_and_hessian(&mut self, z: &mut [f64]) -> (f64, Vec<f64>) {
        self.merit_and_gradient(z)
    }
    /// Newton direction in the free DOFs: solves `H d = -g` with the exact (`projected = false`)
    /// or the projected Hessian. `Ok(None)` when that Hessian gives no descent direction.
    fn direction(
        &mut self,
        z: &[f64],
        g: &[f64],
        projected: bool,
        timings: &mut Timings,
    ) -> Result<Option<Vec<f64>>>;
    /// Adds `t d` (free DOFs) to `z`.
    fn step(&self, z: &mut [f64], d: &[f64], t: f64);
    /// The largest step length `t <= 1` the line search may take along `d` from `z` (1: no
    /// bound): its first trial. Contact bounds it by continuous collision detection, so that no
    /// step length up to it makes the state intersect.
    fn step_bound(&mut self, _z: &[f64], _d: &[f64]) -> f64 {
        1.0
    }
    /// The iterates the problem carries besides `z`, if any.
    fn auxiliary(&mut self) -> Option<&mut dyn AuxiliaryIterates> {
        None
    }
    /// Whether `z` also meets the problem's own tolerances (exact constraints), which the
    /// relative residual test alone does not guarantee: an iterate converges when both hold.
    fn constraints_met(&self, _z: &[f64]) -> bool {
        true
    }
    /// Whether [`NewtonProblem::direction`] may solve with a factorisation kept from earlier
    /// iterates (modified Newton): a Hessian assembled beside a line-search trial would then
    /// often go unused, so none is.
    fn reuses_factorizations(&self) -> bool {
        false
    }
}

/// Iterates a problem carries besides `z` (the element pressures of
/// [`NewtonOptions::pressure_iterates`]): set at the start `z` of each load step, moved to the
/// trial `z + t d` (before it is evaluated, for the Hessian kept with it, and again once a step
/// is accepted), and the trial's kept as the next iterate's. The contact's barrier stiffness is
/// one too: its update at `commit` changes the merit of the accepted iterate, which is then
/// evaluated again.
pub trait AuxiliaryIterates {
    fn start(&mut self, z: &[f64]);
    fn trial(&mut self, z: &[f64], d: &[f64], t: f64);
    /// Keeps the trial's iterates; `true` when that changed the merit at the accepted iterate.
    fn commit(&mut self) -> bool;
}

fn norm(v: &[f64]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Solves from `z` (full DOFs) to the equilibrium at load factor 1; `z` holds the result.
pub fn solve(
    problem: &mut dyn NewtonProblem,
    z: &mut Vec<f64>,
    options: &NewtonOptions,
) -> Result<SolveReport> {
    let start = Instant::now();
    let mut report = SolveReport::default();
    options.validate()?;
    let mut reached = 0.0;
    let mut increment = 1.0 / options.load_steps as f64;
    while reached < 1.0 {
        // Round-off in the sum of equal increments (10 x 0.1 < 1) must not add a load step.
        let target = if reached + increment >= 1.0 - 1e-12 {
            1.0
        } else {
            reached + increment
        };
        let saved = z.clone();
        problem.set_load_factor(target, z);
        match newton_step(problem, z, options, &mut report, start)? {
            true => {
                reached = target;
                report.load_steps += 1;
            }
            false => {
                *z = saved;
                if report.cutbacks >= options.max_cutbacks {
                    report.timings.total = start.elapsed().as_secs_f64();
                    let message = format!(
                        "Newton did not converge at load factor {target:.4} after {} cut-backs; last relative residuals: {:?}",
                        report.cutbacks,
                        report.residual_history.iter().rev().take(5).rev().map(|r| format!("{r:.3e}")).collect::<Vec<_>>()
                    );
                    report.message = message.clone();
                    return Err(Error::NotConverged {
                        message,
                        report: Box::new(report),
                    });
                }
                report.cutbacks += 1;
                increment /= 2.0;
                problem.set_load_factor(reached, z);
            }
        }
    }
    report.converged = true;
    report.timings.total = start.elapsed().as_secs_f64();
    report.message = format!("converged in {} Newton iterations", report.iterations);
    Ok(report)
}

/// One Newton iteration at load factor 1 from `z` (a linearly implicit step): the direction,
/// then the line search along it, whatever the residual is afterwards (`report.converged`
/// says whether it is within the tolerance; `report.residual_history` has both residuals).
/// `Err(NotConverged)` when no direction or no step along it is found.
pub fn single_iteration(
    problem: &mut dyn NewtonProblem,
    z: &mut [f64],
    options: &NewtonOptions,
) -> Result<SolveReport> {
    let start = Instant::now();
    let mut report = SolveReport::default();
    options.validate()?;
    problem.set_load_factor(1.0, z);
    let once = NewtonOptions {
        max_iterations: 1,
        ..options.clone()
    };
    let converged = newton_step(problem, z, &once, &mut report, start)?;
    report.timings.total = start.elapsed().as_secs_f64();
    if !converged && report.step_lengths.is_empty() {
        let message = format!(
            "the linearly implicit step found no decrease along its direction (relative residual {:.3e})",
            report.residual_history.last().copied().unwrap_or(f64::NAN)
        );
        report.message = message.clone();
        return Err(Error::NotConverged {
            message,
            report: Box::new(report),
        });
    }
    report.converged = converged;
    report.load_steps = 1;
    report.message = "one linearised step".into();
    Ok(report)
}

/// Newton iterations at a fixed load factor. `Ok(false)` when they fail to converge;
/// `Err(Interrupted)` when [`NewtonOptions::interrupt`] asks to stop (`z` then holds the last
/// accepted iterate).
fn newton_step(
    problem: &mut dyn NewtonProblem,
    z: &mut [f64],
    options: &NewtonOptions,
    report: &mut SolveReport,
    started: Instant,
) -> Result<bool> {
    check_interrupt(options, report, started)?;
    // Element-wise work, like an assembly: timed as one.
    let t0 = Instant::now();
    if let Some(auxiliary) = problem.auxiliary() {
        auxiliary.start(z);
    }
    let (mut energy, mut g) = problem.merit_and_gradient(z);
    report.timings.assembly += t0.elapsed().as_secs_f64();
    if !energy.is_finite() {
        return Ok(false);
    }
    let reference = problem.load_norm().max(norm(&g));
    report.reference_norm = reference;
    let mut g_norm = norm(&g);
    report.residual_norm = g_norm;
    report.residual_history.push(if reference > 0.0 {
        g_norm / reference
    } else {
        0.0
    });
    report.energy_history.push(energy);
    let start_merit = energy;
    // Whether the next iteration tries the exact Hessian first. Once the exact Hessian has been
    // indefinite, the iterations stay with the projected one until a full step matches its
    // quadratic model (energy merits only: a residual merit's decrease is not that model's):
    // trying the exact one at every iterate of a large-rotation phase costs an assembly and a
    // failed factorisation each time for the same steps.
    let mut exact_next = true;
    // Whether the full-step trial also assembles the Hessian there (see below).
    let mut prepare_next = false;
    for _ in 0..options.max_iterations {
        if (g_norm <= options.tolerance * reference || reference == 0.0)
            && problem.constraints_met(z)
        {
            return Ok(true);
        }
        check_interrupt(options, report, started)?;
        report.iterations += 1;
        let mut direction = None;
        let mut projected = !exact_next;
        if exact_next {
            direction = problem.direction(z, &g, false, &mut report.timings)?;
            projected = direction.is_none();
        }
        if projected {
            report.projected_steps += 1;
            direction = problem.direction(z, &g, true, &mut report.timings)?;
        }
        let Some(d) = direction else {
            return Err(Error::LinearSolver {
                message:
                    "the projected Hessian is singular: is the body fixed against rigid motions, and is every free cable node held by a taut segment (slack segments carry no stiffness)?"
                        .into(),
            });
        };
        let t0 = Instant::now();
        let mut assembly_in_search = 0.0;
        let merit = problem.merit();
        let slope = merit.slope(&g, &d);
        // The largest merit of the last five iterates (and of this one), for the non-monotone
        // Armijo test of Grippo, Lampariello and Lucidi (1986): a trial must fall below it by the
        // Armijo decrease, not below the current merit, because the plain Armijo test cuts the
        // long rotating steps of large-rotation problems.
        let window_max = report
            .energy_history
            .iter()
            .rev()
            .take(5)
            .fold(energy, |m, &e| m.max(e));
        // Try the full Newton step first (unless bounded, below): starting from twice the last
        // accepted step saves rejected trials (cheap merit evaluations) but costs Newton
        // iterations (a factorisation each).
        //
        // Steps the problem bounds start at the bound: the halving would reject the longer ones
        // one by one, and a contact's collision bound must not be exceeded at all.
        let t0_bound = Instant::now();
        let bound = problem.step_bound(z, &d);
        report.timings.step_bound += t0_bound.elapsed().as_secs_f64();
        let mut t: f64 = bound.clamp(1e-12, 1.0);
        let mut accepted = false;
        let mut trial = z.to_vec();
        let prepare = prepare_next && !projected && !problem.reuses_factorizations();
        for _ in 0..40 {
            trial.copy_from_slice(z);
            problem.step(&mut trial, &d, t);
            let (e_trial, g_trial) = if prepare && t == 1.0 {
                let t1 = Instant::now();
                if let Some(auxiliary) = problem.auxiliary() {
                    auxiliary.trial(z, &d, t);
                }
                let evaluated = problem.merit_gradient_and_hessian(&mut trial);
                assembly_in_search += t1.elapsed().as_secs_f64();
                evaluated
            } else {
                problem.merit_and_gradient(&mut trial)
            };
            if e_trial.is_finite() {
                let factor = merit.nonmonotone_factor();
                // The factor test may not compound from window to window: never above factor^2
                // times the load step's starting merit, or the residual can grow window after
                // window (tests/regression_mixed_residual_growth.rs).
                if e_trial <= window_max + 1e-4 * t * slope
                    || (factor > 0.0
                        && e_trial <= factor * window_max
                        && e_trial <= factor * factor * start_merit)
                {
                    accepted = true;
                } else if (e_trial - energy).abs() <= 1e-11 * energy.abs().max(f64::MIN_POSITIVE) {
                    // The energy change is below its round-off: judge by the residual instead.
                    accepted = norm(&g_trial) < g_norm;
                }
                if accepted {
                    energy = e_trial;
                    g = g_trial;
                    break;
                }
            }
            t *= 0.5;
        }
        report.timings.line_search += t0.elapsed().as_secs_f64() - assembly_in_search;
        report.timings.assembly += assembly_in_search;
        if !accepted {
            return Ok(false);
        }
        // The decrease the quadratic model of the Hessian used predicts for the step t d
        // (H d = -g): -(t - t^2 / 2) g.d.
        let predicted = -(t - 0.5 * t * t) * slope;
        let previous = *report.energy_history.last().expect("the start is recorded");
        exact_next = !projected
            || merit != Merit::Energy
            || (t == 1.0 && previous - energy > 0.5 * predicted);
        let t0 = Instant::now();
        let mut merit_changed = false;
        if let Some(auxiliary) = problem.auxiliary() {
            if !(prepare && t == 1.0) {
                auxiliary.trial(z, &d, t);
            }
            merit_changed = auxiliary.commit();
        }
        z.copy_from_slice(&trial);
        if merit_changed {
            (energy, g) = problem.merit_and_gradient(z);
        }
        report.timings.assembly += t0.elapsed().as_secs_f64();
        report.step_lengths.push(t);
        // In the converging phase (a full step from an exact Hessian) the next full step is
        // likely accepted at once: its trial then assembles the Hessian there too, saving a
        // pass over the elements per iteration. Not when the next step probably converges (the
        // residual ratio squared says so): that Hessian would never be used.
        let new_norm = norm(&g);
        let ratio = new_norm / g_norm;
        prepare_next =
            t == 1.0 && !projected && new_norm * ratio * ratio > options.tolerance * reference;
        g_norm = new_norm;
        report.residual_norm = g_norm;
        report.residual_history.push(g_norm / reference);
        report.energy_history.push(energy);
    }
    Ok(g_norm <= options.tolerance * reference && problem.constraints_met(z))
}

/// `Err(Interrupted)` with the report so far when the interrupt has been requested.
fn check_interrupt(options: &NewtonOptions, report: &SolveReport, started: Instant) -> Result<()> {
    if !options.interrupt.is_requested() {
        return Ok(());
    }
    let mut report = report.clone();
    report.timings.total = started.elapsed().as_secs_f64();
    report.message = format!(
        "interrupted after {} Newton iterations{}",
        report.iterations,
        match report.residual_history.last() {
            Some(r) => format!(" (relative residual {r:.3e})"),
            None => String::new(),
        }
    );
    Err(Error::Interrupted {
        report: Box::new(report),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `E(x) = sqrt(1 + x^2)` from x = 10: the Newton step (x -> -1000) overshoots a
    /// hundredfold, as the first step of a slender cantilever under full gravity does.
    struct Hyperbola {
        bound: f64,
        evaluations: usize,
    }

    impl NewtonProblem for Hyperbola {
        fn merit(&self) -> Merit {
            Merit::Energy
        }
        fn set_load_factor(&mut self, _factor: f64, _z: &mut [f64]) {}
        fn load_norm(&self) -> f64 {
            0.0
        }
        fn merit_and_gradient(&mut self, z: &mut [f64]) -> (f64, Vec<f64>) {
            self.evaluations += 1;
            let r = (1.0 + z[0] * z[0]).sqrt();
            (r, vec![z[0] / r])
        }
        fn direction(
            &mut self,
            z: &[f64],
            g: &[f64],
            _projected: bool,
            _timings: &mut Timings,
        ) -> Result<Option<Vec<f64>>> {
            let hessian = (1.0 + z[0] * z[0]).powf(-1.5);
            Ok(Some(vec![-g[0] / hessian]))
        }
        fn step(&self, z: &mut [f64], d: &[f64], t: f64) {
            z[0] += t * d[0];
        }
        /// The largest power of two within the bound, as the model's diameter bound.
        fn step_bound(&mut self, _z: &[f64], d: &[f64]) -> f64 {
            let bound = (self.bound / d[0].abs()).min(1.0);
            let mut t: f64 = 1.0;
            while t > bound {
                t *= 0.5;
            }
            t
        }
    }

    #[test]
    fn a_step_bound_skips_the_trials_halving_would_reject() {
        let run = |bound: f64| {
            let mut problem = Hyperbola {
                bound,
                evaluations: 0,
            };
            let mut z = vec![10.0];
            let options = NewtonOptions {
                tolerance: 1e-10,
                ..Default::default()
            };
            let report = solve(&mut problem, &mut z, &options).unwrap();
            (report, z[0], problem.evaluations)
        };
        let (halving, x_halving, evaluations_halving) = run(f64::INFINITY);
        let (bounded, x_bounded, evaluations_bounded) = run(20.0);
        assert!(x_halving.abs() < 1e-8 && x_bounded.abs() < 1e-8);
        // The same accepted steps, the first one 1/64, found with fewer trials.
        assert_eq!(halving.step_lengths, bounded.step_lengths);
        assert_eq!(halving.step_lengths[0], 1.0 / 64.0);
        // Every step until |x| < 1 overshoots: 73 merit evaluations with plain halving.
        assert!(
            2 * evaluations_bounded < evaluations_halving,
            "{evaluations_bounded} vs {evaluations_halving}"
        );
    }

    /// [`Hyperbola`] that requests `interrupt` during its `at`-th direction solve, as a Ctrl-C
    /// watcher on another thread would while that iteration runs.
    struct InterruptedDuring {
        inner: Hyperbola,
        interrupt: Interrupt,
        at: usize,
        directions: usize,
    }

    impl NewtonProblem for InterruptedDuring {
        fn merit(&self) -> Merit {
            self.inner.merit()
        }
        fn set_load_factor(&mut self, factor: f64, z: &mut [f64]) {
            self.inner.set_load_factor(factor, z)
        }
        fn load_norm(&self) -> f64 {
            self.inner.load_norm()
        }
        fn merit_and_gradient(&mut self, z: &mut [f64]) -> (f64, Vec<f64>) {
            self.inner.merit_and_gradient(z)
        }
        fn direction(
            &mut self,
            z: &[f64],
            g: &[f64],
            projected: bool,
            timings: &mut Timings,
        ) -> Result<Option<Vec<f64>>> {
            self.directions += 1;
            if self.directions == self.at {
                self.interrupt.request();
            }
            self.inner.direction(z, g, projected, timings)
        }
        fn step(&self, z: &mut [f64], d: &[f64], t: f64) {
            self.inner.step(z, d, t)
        }
    }

    #[test]
    fn an_interrupt_stops_newton_at_the_next_iteration_with_the_report_so_far() {
        let options = NewtonOptions {
            tolerance: 1e-10,
            ..Default::default()
        };
        let mut z_full = vec![10.0];
        let full = solve(
            &mut Hyperbola {
                bound: f64::INFINITY,
                evaluations: 0,
            },
            &mut z_full,
            &options,
        )
        .unwrap();
        let at = 3;
        assert!(full.iterations > at + 2, "{} iterations", full.iterations);
        let interrupt = Interrupt::new();
        let mut problem = InterruptedDuring {
            inner: Hyperbola {
                bound: f64::INFINITY,
                evaluations: 0,
            },
            interrupt: interrupt.clone(),
            at,
            directions: 0,
        };
        let mut z = vec![10.0];
        let options = NewtonOptions {
            interrupt,
            ..options
        };
        let Err(Error::Interrupted { report }) = solve(&mut problem, &mut z, &options) else {
            panic!("the solve was not interrupted");
        };
        // Iteration `at` finishes (its step is taken); the next one does not start.
        assert_eq!(problem.directions, at);
        assert_eq!(report.iterations, at);
        assert!(!report.converged);
        assert_eq!(report.step_lengths, full.step_lengths[..at]);
        assert_eq!(report.residual_history, full.residual_history[..=at]);
        assert!(report
            .message
            .starts_with("interrupted after 3 Newton iterations"));
        // `z` is the last accepted iterate, the one the uninterrupted solve passed through.
        let mut x: f64 = 10.0;
        for &t in full.step_lengths.iter().take(at) {
            let r = (1.0 + x * x).sqrt();
            x -= t * (x / r) * (1.0 + x * x).powf(1.5);
        }
        assert!(
            (z[0] - x).abs() <= 1e-12 * x.abs().max(1.0),
            "{} vs {x}",
            z[0]
        );
    }

    #[test]
    fn an_interrupt_requested_before_the_solve_stops_it_before_any_work() {
        let interrupt = Interrupt::new();
        interrupt.request();
        let mut problem = Hyperbola {
            bound: f64::INFINITY,
            evaluations: 0,
        };
        let mut z = vec![10.0];
        let options = NewtonOptions {
            load_steps: 4,
            interrupt,
            ..Default::default()
        };
        let Err(Error::Interrupted { report }) = solve(&mut problem, &mut z, &options) else {
            panic!("the solve was not interrupted");
        };
        assert_eq!((report.iterations, problem.evaluations), (0, 0));
        assert_eq!(z, [10.0]);
        // A default interrupt is never requested, and options compare by their settings alone.
        assert!(!Interrupt::default().is_requested());
        assert_eq!(
            options,
            NewtonOptions {
                load_steps: 4,
                ..Default::default()
            }
        );
    }
}
