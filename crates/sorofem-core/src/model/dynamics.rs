//! Dynamics: implicit Euler in time, each step a minimisation of the incremental potential
//! through the same Newton solver as statics (docs/theory.md, "Dynamics", has the equations,
//! the step methods and their measured accuracy).

use super::statics::infeasible_pulls;
use super::system::{ContactSolve, FactorReuse, FrictionLag, StepTerms, System};
use super::{Loads, Model};
use crate::cables::CableSlot;
use crate::contact::ccd::DEFAULT_MIN_SEPARATION;
use crate::contact::ContactForces;
use crate::energy::TendonCommand;
use crate::error::{Error, Result};
use crate::newton::{self, NewtonOptions};
use crate::report::{SolveReport, Timings};

/// How many times a time step may be halved (a step becomes at most 64 sub-steps).
pub(crate) const MAX_STEP_SPLITS: usize = 6;

/// Rayleigh damping: `mass` alpha_M (1/s), `stiffness` beta_K (s).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Damping {
    pub mass: f64,
    pub stiffness: f64,
}

/// How each time step's minimisation is solved.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum StepMethod {
    /// Newton's method with a fresh factorisation of the step's Hessian at every iteration.
    Newton,
    /// Modified Newton: directions from a factorisation kept across iterations and steps,
    /// refactorised where the residual falls by less than a quarter in an iteration. Converges
    /// to the same tolerance as [`StepMethod::Newton`], so the trajectories agree to it.
    #[default]
    Modified,
    /// One iteration of [`StepMethod::Modified`] per step, converged or not (the linearised
    /// step of SOFA's implicit Euler, with a kept factorisation): fast and less accurate; each
    /// step's remaining residual is reported. With contact, a step that ends within `dhat` of
    /// an obstacle (or that the collision bound cuts short) is completed by modified Newton.
    LinearlyImplicit,
}

impl StepMethod {
    /// Lower-case names, as the Python API takes them.
    pub fn name(self) -> &'static str {
        match self {
            StepMethod::Newton => "newton",
            StepMethod::Modified => "modified",
            StepMethod::LinearlyImplicit => "linearly_implicit",
        }
    }

    pub fn from_name(name: &str) -> Result<Self> {
        [
            StepMethod::Newton,
            StepMethod::Modified,
            StepMethod::LinearlyImplicit,
        ]
        .into_iter()
        .find(|m| m.name() == name)
        .ok_or_else(|| {
            Error::invalid(
                "method",
                "'newton', 'modified' or 'linearly_implicit'",
                format!("{name:?}"),
            )
        })
    }
}

/// The residual must fall at least this much per modified-Newton iteration, or the next one
/// refactorises. Lower refactorises more often (each costs an assembly and a factorisation,
/// several kept-factor iterations' worth); higher lets slow linear convergence run on.
pub(crate) const MAX_CONTRACTION: f64 = 0.25;

/// The settings of a simulation besides its loads, schedule, damping and start.
#[derive(Clone, Debug)]
pub struct DynamicsOptions {
    /// Each step's Newton settings (`load_steps` and `max_cutbacks` are not used: a failed
    /// step is halved instead).
    pub newton: NewtonOptions,
    pub method: StepMethod,
    /// Save every this many steps (the initial and the last state are always saved).
    pub save_every: usize,
}

impl Default for DynamicsOptions {
    fn default() -> Self {
        DynamicsOptions {
            newton: NewtonOptions::default(),
            method: StepMethod::default(),
            save_every: 1,
        }
    }
}

/// Frames of a dynamic simulation.
#[derive(Clone, Debug, Default)]
pub struct Trajectory {
    pub times: Vec<f64>,
    /// Node positions (m, 3 n) per saved frame.
    pub positions: Vec<Vec<f64>>,
    pub cable_points: Vec<Vec<Vec<[f64; 3]>>>,
    /// Per saved frame, each tendon's tension (N) and pull (m) (`None` for spring cables).
    pub tendon_tensions: Vec<Vec<Option<f64>>>,
    pub tendon_pulls: Vec<Vec<Option<f64>>>,
    /// Kinetic energy (J) per saved frame.
    pub kinetic_energy: Vec<f64>,
    /// Node velocities (m/s, 3 n) at the end.
    pub velocities: Vec<f64>,
    /// Newton iterations of every step (a cut step counts its sub-steps' sum).
    pub iterations: Vec<usize>,
    /// Numeric factorisations of every step (the same way).
    pub factorizations: Vec<usize>,
    /// The relative residual every step ended with (its last sub-step's): below the tolerance
    /// unless the method is [`StepMethod::LinearlyImplicit`].
    pub residuals: Vec<f64>,
    /// Times a step was halved after a Newton failure (or an obstacle's motion).
    pub cutbacks: usize,
    /// Seconds per phase over all steps.
    pub timings: Timings,
    /// With obstacles: the contact at every saved frame.
    pub contact: Vec<ContactFrame>,
    /// With obstacles: the minimum distance (m) between the body and its obstacles at every
    /// accepted Newton iterate of every step (over the stencils within `dhat`, `+inf` when none).
    pub iterate_min_distances: Vec<f64>,
}

/// The contact of one saved frame: its forces and where each obstacle is (its translation from
/// its place at time 0, m).
#[derive(Clone, Debug, Default)]
pub struct ContactFrame {
    pub forces: ContactForces,
    pub translations: Vec<[f64; 3]>,
}

/// The state between two steps: every unknown (full DOFs), the velocity of the free ones, and
/// the step before (for the extrapolated start).
#[derive(Clone, Debug)]
pub(crate) struct StepState {
    pub(crate) z: Vec<f64>,
    pub(crate) velocity: Vec<f64>,
    pub(crate) before: Option<StepBefore>,
}

/// The free values and velocities at the start of the last step, and its length.
#[derive(Clone, Debug)]
pub(crate) struct StepBefore {
    values: Vec<f64>,
    velocity: Vec<f64>,
    h: f64,
}

/// Where the last simulation ended, so that one continuing it (starting from its final
/// positions and velocities, as a chunked run does) goes on exactly as a single run would: the
/// state the positions alone do not carry (pressures, free cable nodes and their velocities,
/// the step before) and the kept factorisation.
#[derive(Clone, Debug)]
pub(crate) struct Continuation {
    positions: Vec<f64>,
    velocities: Vec<f64>,
    state: StepState,
    reuse: FactorReuse,
}

/// What does not change from step to step of one simulation.
pub(crate) struct StepSetup {
    /// Full DOF of each free DOF.
    pub(crate) free: Vec<usize>,
    /// Mass (kg) of each free DOF (zero on pressures).
    pub(crate) mass: Vec<f64>,
    /// Free DOFs that are displacements (the pressures, mixed only, come after them).
    pub(crate) n_displacement: usize,
    pub(crate) full_load: Vec<f64>,
    prescribed: Vec<[f64; 3]>,
    pub(crate) damping: Damping,
    method: StepMethod,
    newton: NewtonOptions,
}

impl Model {
    /// [`Model::simulate_with`] with the default [`StepMethod`].
    #[allow(clippy::too_many_arguments)]
    pub fn simulate(
        &mut self,
        loads: &Loads,
        dt: f64,
        steps: usize,
        actuation: &[Vec<f64>],
        damping: Damping,
        initial_positions: Option<&[f64]>,
        initial_velocities: Option<&[f64]>,
        options: &NewtonOptions,
        save_every: usize,
    ) -> Result<Trajectory> {
        let options = DynamicsOptions {
            newton: options.clone(),
            save_every,
            ..Default::default()
        };
        self.simulate_with(
            loads,
            dt,
            steps,
            actuation,
            damping,
            initial_positions,
            initial_velocities,
            &options,
        )
    }

    /// Implicit Euler in time: step n minimises the incremental potential (see
    /// [`super::system::StepTerms`]) `1/2 |u - u_n - h v_n|_M^2 / h^2 + 1/2 alpha_M |u - u_n|_M^2
    /// / h + Pi(u) + beta_K / h (Pi_int(u) - F(u_n) . u)` (lumped mass M, Rayleigh damping
    /// alpha_M and beta_K), then `v = (u - u_n) / h`. Each step starts Newton from the
    /// quadratic extrapolation of the last three states. A step whose solve fails is split in
    /// two, up to six times. `actuation[s][c]` is cable c's command during step s: its alpha
    /// (spring cables), its pull (m) or its tension (N) (tendons, whichever their command is).
    /// A displacement-controlled tendon is an exact constraint of every step, as in statics,
    /// whatever the step method. Starts from `initial_positions` (3 n, m; default rest; free
    /// cable nodes and pressures then continue from the last solve) at rest or with `initial_velocities` (3 n, m/s); a simulation that
    /// starts where the last one ended (its final positions and velocities) continues it
    /// exactly (see `Continuation`).
    ///
    /// Obstacles move along their paths; each step first moves them to where they are at its end
    /// (split, like a failed step, when that would make them touch the body), lags friction at
    /// the step's start (`eps_u = eps_v h`), balances the barrier stiffness there (IPC's
    /// initial stiffness) and starts Newton from its start cut short of any contact. Every step
    /// method bounds its line search by continuous collision detection; modified Newton
    /// refactorises when the active contacts change.
    #[allow(clippy::too_many_arguments)]
    pub fn simulate_with(
        &mut self,
        loads: &Loads,
        dt: f64,
        steps: usize,
        actuation: &[Vec<f64>],
        damping: Damping,
        initial_positions: Option<&[f64]>,
        initial_velocities: Option<&[f64]>,
        options: &DynamicsOptions,
    ) -> Result<Trajectory> {
        let setup = self.step_setup(loads, dt, steps, actuation, damping, options)?;
        let start = self.start_of_run(&setup, initial_positions, initial_velocities)?;
        self.integrate(&setup, dt, actuation, options.save_every, start)
    }

    /// The steps of a simulation from `start`.
    pub(crate) fn integrate(
        &mut self,
        setup: &StepSetup,
        dt: f64,
        actuation: &[Vec<f64>],
        save_every: usize,
        start: (StepState, FactorReuse),
    ) -> Result<Trajectory> {
        let (mut state, mut reuse) = start;
        let steps = actuation.len();
        let n = self.mesh.n_nodes();
        let mut trajectory = Trajectory::default();
        self.save_frame(setup, &state, 0.0, &mut trajectory);
        let mut time = 0.0;
        for (s, alphas) in actuation.iter().enumerate() {
            self.set_step_commands(alphas)?;
            // Halve the step on failure: a queue of sub-steps that must add up to dt.
            let mut pending = vec![(dt, 0usize)];
            let (mut iterations, mut factorizations, mut residual) = (0, 0, 0.0);
            let mut sub_time = time;
            while let Some((h, depth)) = pending.pop() {
                // Obstacles move first, with the body where it is: a motion that would touch it
                // splits the step.
                if self.obstacle_splits_step(&state.z, sub_time + h, (s, time), (h, depth))? {
                    trajectory.cutbacks += 1;
                    pending.extend([(h / 2.0, depth + 1), (h / 2.0, depth + 1)]);
                    continue;
                }
                if let Some(contact) = &mut self.terms.contact {
                    contact.set_time(sub_time + h);
                    let slip = contact.friction_velocity() * h;
                    contact.lag_friction(&state.z, &state.z, slip);
                }
                let outcome = self.time_step(
                    setup,
                    &mut state,
                    h,
                    &mut reuse,
                    &mut trajectory.iterate_min_distances,
                );
                if outcome.is_ok() {
                    sub_time += h;
                } else if let Some(contact) = &mut self.terms.contact {
                    contact.set_time(sub_time);
                }
                let report = match &outcome {
                    Ok(report) => report,
                    Err(Error::NotConverged { report, .. }) => report,
                    Err(_) => &SolveReport::default(),
                };
                iterations += report.iterations;
                factorizations += report.timings.factorizations;
                add_timings(&mut trajectory.timings, &report.timings);
                match outcome {
                    Ok(report) => {
                        residual = report.residual_history.last().copied().unwrap_or(0.0);
                    }
                    Err(Error::NotConverged { .. }) if depth < MAX_STEP_SPLITS => {
                        trajectory.cutbacks += 1;
                        pending.extend([(h / 2.0, depth + 1), (h / 2.0, depth + 1)]);
                    }
                    Err(Error::NotConverged { report, .. }) => {
                        return Err(unconverged_step(report, s, time, h));
                    }
                    Err(other) => return Err(other),
                }
            }
            time += dt;
            trajectory.iterations.push(iterations);
            trajectory.factorizations.push(factorizations);
            trajectory.residuals.push(residual);
            if (s + 1) % save_every.max(1) == 0 || s + 1 == steps {
                self.save_frame(setup, &state, time, &mut trajectory);
            }
        }
        let velocities = setup.node_velocities(n, &state.velocity);
        trajectory.velocities = velocities.clone();
        self.last_extra = Some(state.z[3 * n..].to_vec());
        self.last_state = None;
        self.factor_at_solution = false;
        self.continuation = Some(Continuation {
            positions: trajectory.positions.last().cloned().unwrap_or_default(),
            velocities,
            state,
            reuse,
        });
        Ok(trajectory)
    }

    /// Whether a sub-step of length `h` (halved `depth` times so far) of time step `s` (from
    /// `time`, s) that ends at `end` (s) must be halved again: an obstacle would run into the
    /// body, held at the full DOF vector `z`, over it. An error once it has been halved
    /// [`MAX_STEP_SPLITS`] times.
    pub(crate) fn obstacle_splits_step(
        &self,
        z: &[f64],
        end: f64,
        (s, time): (usize, f64),
        (h, depth): (f64, usize),
    ) -> Result<bool> {
        let Some(contact) = &self.terms.contact else {
            return Ok(false);
        };
        if !(contact.obstacle_motion_bound(z, end, DEFAULT_MIN_SEPARATION) < 1.0) {
            return Ok(false);
        }
        if depth < MAX_STEP_SPLITS {
            return Ok(true);
        }
        Err(Error::invalid(
            "obstacles",
            "paths along which the obstacles do not run into the body faster than it can move away",
            format!("time step {s} (t = {time:.4} s): an obstacle would touch the body even at dt = {h:.3e} s"),
        ))
    }

    /// Sets every cable's command of one step: `values[c]` is cable c's alpha (spring cables),
    /// pull (m) or tension (N) (tendons, whichever their command is).
    pub(crate) fn set_step_commands(&mut self, values: &[f64]) -> Result<()> {
        for (c, &value) in values.iter().enumerate() {
            match self.cable_slot(c)? {
                CableSlot::Springs(_) => self.set_actuation(c, value)?,
                CableSlot::Tendon(_) => {
                    let command = match self.tendon_command(c)? {
                        TendonCommand::Pull(_) => TendonCommand::Pull(value),
                        TendonCommand::Tension(_) => TendonCommand::Tension(value),
                    };
                    self.set_tendon_command(c, command)?;
                }
            }
        }
        Ok(())
    }

    /// Checks the arguments of a simulation and gathers what its steps share.
    pub(crate) fn step_setup(
        &self,
        loads: &Loads,
        dt: f64,
        steps: usize,
        actuation: &[Vec<f64>],
        damping: Damping,
        options: &DynamicsOptions,
    ) -> Result<StepSetup> {
        self.require_material("simulate")?;
        self.check_loads(loads)?;
        options.newton.validate()?;
        if !(dt > 0.0 && dt.is_finite()) {
            return Err(Error::invalid("dt", "a time step > 0 s", dt));
        }
        if actuation.len() != steps || actuation.iter().any(|row| row.len() != self.n_cables()) {
            return Err(Error::shape(
                "actuation",
                format!(
                    "({steps}, {}): one alpha per step and cable",
                    self.n_cables()
                ),
                format!("{} rows", actuation.len()),
            ));
        }
        for (name, value) in [
            ("mass_damping", damping.mass),
            ("stiffness_damping", damping.stiffness),
        ] {
            if !(value >= 0.0 && value.is_finite()) {
                return Err(Error::invalid(
                    name,
                    "a finite Rayleigh coefficient >= 0",
                    value,
                ));
            }
        }
        let n = self.mesh.n_nodes();
        let free: Vec<usize> = self.assembler.full_of_free().to_vec();
        let mass_full = self.terms.mass.per_dof(self.layout.n_full());
        let mass: Vec<f64> = free.iter().map(|&d| mass_full[d]).collect();
        // Pressures (mixed formulation) are never fixed and come last among the free DOFs.
        let n_displacement = free.len() - if self.layout.pressures { n } else { 0 };
        Ok(StepSetup {
            free,
            mass,
            n_displacement,
            full_load: self.load_vector(loads),
            prescribed: self.prescribed(loads),
            damping,
            method: options.method,
            newton: NewtonOptions {
                load_steps: 1,
                max_cutbacks: 0,
                ..options.newton.clone()
            },
        })
    }

    /// The state a simulation starts from, and the factorisation it may keep: the end of the
    /// last simulation when it continues it, else `initial_positions` and `initial_velocities`.
    pub(crate) fn start_of_run(
        &mut self,
        setup: &StepSetup,
        initial_positions: Option<&[f64]>,
        initial_velocities: Option<&[f64]>,
    ) -> Result<(StepState, FactorReuse)> {
        let n = self.mesh.n_nodes();
        if let Some(v) = initial_velocities {
            if v.len() != 3 * n {
                return Err(Error::shape(
                    "initial_velocities",
                    format!("({n}, 3)"),
                    format!("{} values", v.len()),
                ));
            }
            crate::error::check_finite("initial_velocities", v)?;
        }
        let z = self.start_state("initial_positions", initial_positions)?;
        if let Some(contact) = &mut self.terms.contact {
            contact.set_time(0.0);
            contact.clear_friction();
        }
        self.check_apart("initial_positions", &z)?;
        self.prepare_contact();
        if let (Some(x), Some(v), Some(last)) = (
            initial_positions,
            initial_velocities,
            self.continuation.take(),
        ) {
            if x == last.positions.as_slice() && v == last.velocities.as_slice() {
                return Ok((last.state, last.reuse));
            }
        }
        let mut velocity = vec![0.0; setup.free.len()];
        if let Some(v) = initial_velocities {
            for (f, &d) in setup.free.iter().enumerate() {
                if d < 3 * n {
                    velocity[f] = v[d];
                }
            }
        }
        let state = StepState {
            z,
            velocity,
            before: None,
        };
        Ok((state, FactorReuse::new(MAX_CONTRACTION)))
    }

    fn save_frame(
        &self,
        setup: &StepSetup,
        state: &StepState,
        t: f64,
        trajectory: &mut Trajectory,
    ) {
        let n = self.mesh.n_nodes();
        let rest = self.mesh.rest_flat();
        if let Some(contact) = &self.terms.contact {
            trajectory.contact.push(ContactFrame {
                forces: contact.forces(&state.z),
                translations: (0..contact.n_obstacles())
                    .map(|k| contact.translation_at(k, t).into())
                    .collect(),
            });
        }
        trajectory.times.push(t);
        trajectory
            .positions
            .push((0..3 * n).map(|i| rest[i] + state.z[i]).collect());
        let (points, _, tensions, pulls) = self.cable_states(&state.z);
        trajectory.cable_points.push(points);
        trajectory.tendon_tensions.push(tensions);
        trajectory.tendon_pulls.push(pulls);
        trajectory.kinetic_energy.push(
            0.5 * (setup.mass.iter().zip(&state.velocity))
                .map(|(m, v)| m * v * v)
                .sum::<f64>(),
        );
    }

    /// One implicit Euler step of length `h` from `state`, solved by the setup's method with
    /// the factorisation `reuse` keeps; `state` moves to its end when it converges. With
    /// obstacles (already where they are at the step's end, friction lagged) the minimum
    /// distance at every accepted iterate goes to `iterate_min_distances`.
    pub(crate) fn time_step(
        &mut self,
        setup: &StepSetup,
        state: &mut StepState,
        h: f64,
        reuse: &mut FactorReuse,
        iterate_min_distances: &mut Vec<f64>,
    ) -> Result<SolveReport> {
        let previous: Vec<f64> = setup.free.iter().map(|&d| state.z[d]).collect();
        let step = self.step_terms(setup, state, &previous, h);
        let mut trial = state.z.clone();
        // The extrapolation amplifies the errors a linearly implicit step leaves in the
        // velocities; it starts from the inertial prediction instead.
        let before = match setup.method {
            StepMethod::LinearlyImplicit => None,
            _ => state.before.as_ref(),
        };
        for (f, &d) in setup.free.iter().enumerate() {
            trial[d] = setup.start_value(f, &previous, &state.velocity, before, h);
        }
        self.cut_short_of_contact(setup, &state.z, &mut trial);
        let mut problem = System::new(
            self,
            setup.full_load.clone(),
            setup.prescribed.clone(),
            Some(step),
            &setup.newton,
        );
        if setup.method != StepMethod::Newton {
            reuse.start_solve(setup.method == StepMethod::LinearlyImplicit);
            problem.keep_factorizations(reuse.clone());
        }
        if problem.model.terms.contact.is_some() {
            problem.contact = Some(ContactSolve::new(FrictionLag::Fixed, Some(state.z.clone())));
        }
        // The step scales the internal energy, dashpots included, by 1 + beta_K / h; a dashpot
        // over h + beta_K keeps their force at c dL/dt.
        problem
            .model
            .terms
            .cables
            .begin_step(h + setup.damping.stiffness, &state.z);
        problem.extend_state(&mut trial, true);
        let start_tensions = trial[problem.constraints.offset..].to_vec();
        let outcome = rayon::scope(|_| match setup.method {
            StepMethod::LinearlyImplicit => {
                let once = newton::single_iteration(&mut problem, &mut trial, &setup.newton);
                // One linearisation cannot balance a barrier (its force at the step's end can
                // exceed the body's weight a billion-fold): a step that ends within dhat of an
                // obstacle, or that the collision bound cut short, is completed by modified
                // Newton.
                let near = problem.contact.as_ref().is_some_and(|c| c.within_dhat());
                match once {
                    Ok(first)
                        if !first.converged
                            && problem.contact.is_some()
                            && (near || first.step_lengths.first().is_some_and(|&t| t < 1.0)) =>
                    {
                        newton::solve(&mut problem, &mut trial, &setup.newton)
                            .map(|rest| chain_reports(first, rest))
                    }
                    other => other,
                }
            }
            _ => newton::solve(&mut problem, &mut trial, &setup.newton),
        });
        problem.model.terms.cables.end_step();
        let outcome =
            outcome.map_err(|error| infeasible_pulls(error, &problem.tendon_states(&trial)));
        problem.finish_state(&mut trial, outcome.is_ok(), &start_tensions);
        if let Some(kept) = problem.reuse.take() {
            *reuse = kept;
        }
        let contact = problem.contact.take();
        drop(problem);
        let mut outcome = outcome;
        if let Some(solve) = contact {
            iterate_min_distances.extend(solve.iterate_min_distances);
            if let Ok(report) = &mut outcome {
                report.timings.contact = solve.seconds;
            }
        }
        // A failed step, or a single iteration that reduced the residual too little, says the
        // kept factorisation no longer fits: the next step starts with a fresh one (a linearly
        // implicit step has no second iteration in which to notice).
        let contracted = match &outcome {
            Ok(report) => match report.residual_history.as_slice() {
                [first, .., last] => *last <= MAX_CONTRACTION * first,
                _ => true,
            },
            Err(_) => false,
        };
        if !contracted {
            reuse.kept = None;
        }
        if outcome.is_ok() {
            let velocity = std::mem::take(&mut state.velocity);
            state.velocity = (0..setup.free.len())
                .map(|f| {
                    if f < setup.n_displacement {
                        (trial[setup.free[f]] - previous[f]) / h
                    } else {
                        0.0
                    }
                })
                .collect();
            state.before = Some(StepBefore {
                values: previous,
                velocity,
                h,
            });
            state.z = trial;
        }
        outcome
    }

    /// Moves the displacements of a step's start `trial` back toward the step's start `z` (full
    /// DOFs) until they are clear of every contact on the way (continuous collision detection):
    /// Newton must start apart.
    fn cut_short_of_contact(&self, setup: &StepSetup, z: &[f64], trial: &mut [f64]) {
        let Some(contact) = &self.terms.contact else {
            return;
        };
        let n = self.mesh.n_nodes();
        let mut dz = vec![0.0; 3 * n];
        for &d in setup.free[..setup.n_displacement]
            .iter()
            .filter(|&&d| d < 3 * n)
        {
            dz[d] = trial[d] - z[d];
        }
        let reach = contact.max_step(z, &dz, DEFAULT_MIN_SEPARATION);
        if reach < 1.0 {
            for &d in &setup.free[..setup.n_displacement] {
                trial[d] = z[d] + reach * (trial[d] - z[d]);
            }
        }
    }

    /// The inertia and damping of a step of length `h` from `state` (`previous`: its free
    /// values). The stiffness damping's start force is the internal force at the step's start
    /// with the step's actuation; the tendons' forces are the motors', not the body's, and are
    /// not damped (see `System::tendon_scale`).
    pub(super) fn step_terms(
        &self,
        setup: &StepSetup,
        state: &StepState,
        previous: &[f64],
        h: f64,
    ) -> StepTerms {
        let (alpha_m, beta_k) = (setup.damping.mass, setup.damping.stiffness);
        let start_force = if beta_k > 0.0 {
            let mut force = self
                .assembler
                .evaluate(&self.terms.internal(), &state.z, true, None)
                .gradient;
            let mut tendon_force = vec![0.0; state.z.len()];
            for tendon in &self.terms.tendons.tendons {
                tendon.add_length_gradient(&state.z, tendon.tension, &mut tendon_force);
            }
            for (f, &d) in force.iter_mut().zip(&setup.free) {
                *f -= tendon_force[d];
            }
            force.iter_mut().for_each(|f| *f *= beta_k / h);
            force[setup.n_displacement..].fill(0.0);
            force
        } else {
            Vec::new()
        };
        StepTerms {
            inertia: setup.mass.iter().map(|m| m / (h * h)).collect(),
            predicted: (previous.iter().zip(&state.velocity))
                .map(|(u, v)| u + h * v)
                .collect(),
            previous: previous.to_vec(),
            mass_damping: setup.mass.iter().map(|m| alpha_m * m / h).collect(),
            internal_scale: 1.0 + beta_k / h,
            start_force,
        }
    }
}

impl StepSetup {
    /// Where Newton starts free DOF `f` of a step of length `h`: displacements on the
    /// parabola through the last three states (`u_n + h v_n + h^2 (v_n - v_(n-1)) / h_(n-1)`),
    /// pressures on the line through the last two; without a step before, the inertial
    /// prediction `u_n + h v_n` and the last pressures.
    fn start_value(
        &self,
        f: usize,
        previous: &[f64],
        velocity: &[f64],
        before: Option<&StepBefore>,
        h: f64,
    ) -> f64 {
        let u = previous[f];
        match before {
            None if f < self.n_displacement => u + h * velocity[f],
            None => u,
            Some(before) if f < self.n_displacement => {
                u + h * velocity[f] + h * h * (velocity[f] - before.velocity[f]) / before.h
            }
            Some(before) => u + h * (u - before.values[f]) / before.h,
        }
    }

    /// Node velocities (3 n) from the free DOFs' velocities.
    pub(crate) fn node_velocities(&self, n: usize, velocity: &[f64]) -> Vec<f64> {
        let mut v = vec![0.0; 3 * n];
        for (f, &d) in self.free.iter().enumerate() {
            if d < 3 * n {
                v[d] = velocity[f];
            }
        }
        v
    }
}

/// One report of a solve continued by another from where it ended.
fn chain_reports(first: SolveReport, rest: SolveReport) -> SolveReport {
    let mut report = rest;
    report.iterations += first.iterations;
    report.projected_steps += first.projected_steps;
    add_timings(&mut report.timings, &first.timings);
    for (all, head) in [
        (&mut report.residual_history, first.residual_history),
        (&mut report.energy_history, first.energy_history),
        (&mut report.step_lengths, first.step_lengths),
    ] {
        all.splice(0..0, head);
    }
    report
}

/// Adds `b`'s seconds and counts to `a`'s.
fn add_timings(a: &mut Timings, b: &Timings) {
    a.assembly += b.assembly;
    a.factorization += b.factorization;
    a.failed_factorization += b.failed_factorization;
    a.solve += b.solve;
    a.line_search += b.line_search;
    a.total += b.total;
    a.factorizations += b.factorizations;
    a.failed_factorizations += b.failed_factorizations;
    a.single_precision_factorizations += b.single_precision_factorizations;
    a.contact += b.contact;
    a.step_bound += b.step_bound;
}

/// The error of time step `s` (from `time`, s) whose Newton solve failed at the sub-step length
/// `h` it may not be halved below, with its last residuals.
pub(crate) fn unconverged_step(mut report: Box<SolveReport>, s: usize, time: f64, h: f64) -> Error {
    // Without a residual the step never had a finite energy: its start state (extrapolated
    // from the last steps' velocities) inverts an element.
    let why = if report.residual_history.is_empty() {
        "the step's start state (extrapolated from the velocities) inverts an element, so its energy is not finite: the motion is too fast for this dt or step method".to_string()
    } else {
        let last = report.residual_history.iter().rev().take(5).rev();
        format!(
            "last relative residuals: {:?}",
            last.map(|r| format!("{r:.3e}")).collect::<Vec<_>>()
        )
    };
    let message =
        format!("time step {s} (t = {time:.4} s) did not converge even at dt = {h:.3e} s; {why}");
    report.message = message.clone();
    Error::NotConverged { message, report }
}
