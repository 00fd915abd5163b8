//! What a solve reports: convergence, the residual history and where the time went. Its own
//! module so that the error type (which carries a report) and the solver both depend on it
//! without depending on each other.

/// Seconds spent per phase of a solve.
#[derive(Clone, Debug, Default)]
pub struct Timings {
    pub assembly: f64,
    /// All numeric factorisations, the failed ones included.
    pub factorization: f64,
    /// The part of `factorization` spent in factorisations that failed (matrix not positive
    /// definite): `(factorization - failed_factorization) / (factorizations -
    /// failed_factorizations)` is the cost of one bare numeric factorisation.
    pub failed_factorization: f64,
    pub solve: f64,
    pub line_search: f64,
    /// The part of `assembly` and `line_search` spent on contact: broad phase, barrier and
    /// friction stencils, their scatter into the free DOFs.
    pub contact: f64,
    /// The line search's step bounds (the contact's continuous collision detection), part of
    /// `line_search`.
    pub step_bound: f64,
    pub total: f64,
    /// Numeric factorisations, and how many of them failed or gave no descent direction.
    pub factorizations: usize,
    pub failed_factorizations: usize,
    /// Those of `factorizations` computed in single precision (the kept factorisations of
    /// modified Newton; see `crate::linear::SparseFactor::factor_single`).
    pub single_precision_factorizations: usize,
}

/// What happened during a solve: enough to judge convergence and where the time went.
#[derive(Clone, Debug, Default)]
pub struct SolveReport {
    pub converged: bool,
    /// Newton iterations over all load steps (including those of failed, cut-back steps).
    pub iterations: usize,
    /// `||g|| / reference` at every iterate, over all load steps (the first entry of each step
    /// is its starting point).
    pub residual_history: Vec<f64>,
    /// The line search's merit at the same iterates (see [`crate::newton::Merit`]): the
    /// potential energy (J) when the merit is the energy (standard formulation), half the squared
    /// weighted residual (N^2) when it is the residual (mixed formulation).
    pub energy_history: Vec<f64>,
    /// Accepted line-search step length of every Newton iteration (1 = full Newton step).
    pub step_lengths: Vec<f64>,
    /// Accepted load steps.
    pub load_steps: usize,
    /// Times a load step failed and was halved.
    pub cutbacks: usize,
    /// Iterations that used the projected (PSD) Hessian.
    pub projected_steps: usize,
    /// Final `||g||` in the units of the gradient (N) and the reference it was divided by.
    pub residual_norm: f64,
    pub reference_norm: f64,
    pub timings: Timings,
    pub message: String,
}
