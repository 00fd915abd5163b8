//! Modified Newton across the solves of a simulation: a kept factorisation, rotated with the
//! body and refined by the secant pairs of the current solve (L-BFGS with the rotated kept
//! factor as its initial inverse).

use super::warp::{rotate_nodes, WarpReference};
use super::System;
use crate::error::Result;
use crate::linear::FactorKind;
use crate::report::Timings;
use nalgebra::Matrix3;
use std::time::Instant;

/// The largest relative residual `|H x - g| / |g|` a single-precision factorisation's solve may
/// leave for it to be kept (see `System::factor_kept`): at this level the error of its directions
/// is still small against that of a factorisation kept from an earlier iterate (docs/theory.md,
/// "Dynamics", has the levels measured on this project's bodies).
const MAX_SINGLE_PRECISION_RESIDUAL: f64 = 1e-3;

impl System<'_> {
    /// Factors `hessian` (free DOFs, the assembler's pattern) for [`FactorReuse`]. A kept
    /// factorisation only approximates the Hessians it serves, so it is computed in single
    /// precision ([`crate::linear::SparseFactor::factor_single`]) while that is accurate: its
    /// solve of `H x = g` (`g`: the merit gradient, whose free rows are used) must leave a
    /// residual below [`MAX_SINGLE_PRECISION_RESIDUAL`] of `|g|`, and the matrix must be
    /// definite in single precision. Otherwise it is factored in double precision, as is every
    /// later one of the simulation. Mixed formulations (`L D L^T`) and displacement-controlled
    /// tendons are always factored in double precision. Returns whether the factorisation
    /// succeeded.
    pub(super) fn factor_kept(
        &mut self,
        hessian: &[f64],
        g: &[f64],
        timings: &mut Timings,
    ) -> Result<bool> {
        let pattern = self.model.assembler.pattern();
        // The bordered step of displacement-controlled tendons solves for the tendons' whole
        // forces, not for the residual: a single-precision error there would not shrink with
        // the residual, and the iterations would stall at it.
        let double = self.reuse.as_ref().is_some_and(|r| r.double_precision)
            || self.model.factor.kind() != FactorKind::Llt
            || !self.constraints.is_empty();
        if !double
            && self.model.factor.factor_single(pattern, hessian)?
            && self.model.factor.solve_residual(&g[..pattern.n]) <= MAX_SINGLE_PRECISION_RESIDUAL
        {
            timings.single_precision_factorizations += 1;
            return Ok(true);
        }
        let ok = self.model.factor.factor(pattern, hessian)?;
        if ok && !double {
            if let Some(reuse) = &mut self.reuse {
                reuse.double_precision = true;
            }
        }
        Ok(ok)
    }

    /// A direction from the kept factorisation of [`FactorReuse`], when there is one, the
    /// residual fell enough since the last direction, the same tendons are taut as where it was
    /// factorised and it gives a usable direction.
    pub(super) fn kept_direction(
        &mut self,
        z: &[f64],
        g: &[f64],
        g_norm: f64,
        timings: &mut Timings,
    ) -> Option<Vec<f64>> {
        let reuse = self.reuse.as_ref()?;
        let slow = reuse
            .last_norm
            .is_some_and(|last| g_norm > reuse.max_ratio * last);
        if slow
            || reuse.kept != Some(self.model.factor.generation())
            || reuse.taut != self.taut(z)
            || reuse.contact_set != self.active_contacts()
        {
            return None;
        }
        if let (None, Some(warp)) = (&reuse.rotations, &reuse.warp) {
            let t0 = Instant::now();
            let rotations = warp.node_rotations(&self.model.mesh, &z[..3 * self.n_nodes()]);
            self.reuse.as_mut().expect("checked above").rotations = Some(rotations);
            timings.assembly += t0.elapsed().as_secs_f64();
        }
        let rotations = self.reuse.as_mut().and_then(|r| r.rotations.take());
        let d = if self.learns_secants() {
            let x = self.free_values(z);
            let reuse = self.reuse.as_mut().expect("checked above");
            reuse.secants.record(x, g);
            let secants = std::mem::take(&mut reuse.secants);
            // The rotated solve gives -H_0^{-1} q; the update needs +H_0^{-1} q.
            let d = secants.apply_inverse(g, |q| {
                self.rotated_solve(z, q, rotations.as_deref(), timings)
                    .map(|d| d.into_iter().map(|v| -v).collect())
            });
            self.reuse.as_mut().expect("checked above").secants = secants;
            d.map(|d| d.into_iter().map(|v| -v).collect())
        } else {
            self.rotated_solve(z, g, rotations.as_deref(), timings)
        };
        self.reuse.as_mut().expect("checked above").rotations = rotations;
        let d = d?;
        let usable = self.is_usable(&d, g);
        let reuse = self.reuse.as_mut().expect("checked above");
        if !usable {
            return None;
        }
        reuse.last_norm = Some(g_norm);
        reuse.reused += 1;
        Some(d)
    }

    /// `-H_0^{-1} g` of the kept factorisation rotated with the body, `R K^{-1} R^T`
    /// ([`super::warp`]); the plain kept solve without `rotations`.
    fn rotated_solve(
        &self,
        z: &[f64],
        g: &[f64],
        rotations: Option<&[Matrix3<f64>]>,
        timings: &mut Timings,
    ) -> Option<Vec<f64>> {
        let Some(rotations) = rotations else {
            return self.solve_with_factor(z, g, timings);
        };
        let full_of_free = self.model.assembler.full_of_free();
        let mut q = g.to_vec();
        rotate_nodes(rotations, full_of_free, &mut q, true);
        let mut d = self.solve_with_factor(z, &q, timings)?;
        rotate_nodes(rotations, full_of_free, &mut d, false);
        Some(d)
    }
}

/// Modified Newton for a sequence of solves (the steps of a simulation): directions
/// `d = -H_kept^{-1} g` from a factorisation kept across iterations and solves, until the
/// residual falls by less than `max_ratio` in an iteration (or the kept factor gives no
/// descent direction, or the active contacts changed); the next direction then factorises the
/// Hessian at its iterate.
///
/// Without contact and displacement-controlled tendons (and with `rotate`), the kept factor is
/// rotated with the body ([`super::warp`]): by the node rotations from where it was factorised
/// to the current solve's first iterate that uses it.
///
/// Where the merit is the energy (standard formulation, no displacement-controlled tendon, no
/// contact), each direction corrects the kept factor by the secant pairs of the iterates since
/// it was factorised in the current solve ([`SecantPairs`]): the kept Hessian's drift over a
/// step is then learnt instead of costing linear convergence.
#[derive(Clone, Debug)]
pub(crate) struct FactorReuse {
    /// The model factor's [`crate::linear::SparseFactor::generation`] when it was kept.
    pub(crate) kept: Option<u64>,
    /// The active contacts the kept factorisation holds ([`crate::contact::ContactPass::active_set`];
    /// 0 without contact): a stencil that became active since has no curvature in it, and its
    /// direction would run into the obstacle up to the collision bound.
    pub(crate) contact_set: u64,
    /// The residual norm at the last direction of the current solve.
    pub(crate) last_norm: Option<f64>,
    pub(crate) max_ratio: f64,
    /// Directions computed with the kept factorisation.
    pub(crate) reused: usize,
    /// Which displacement-controlled tendons were taut where it was factorised (see
    /// `System::taut`): when the active set changes, the next direction refactorises.
    pub(crate) taut: Vec<bool>,
    /// The current solve's secant pairs since the kept factorisation.
    pub(crate) secants: SecantPairs,
    /// Whether factorisations are in double precision: from the first single-precision one
    /// that was not accurate enough on, for the rest of the simulation (see
    /// `System::factor_kept`).
    pub(crate) double_precision: bool,
    /// Whether solves with a single-precision factorisation take a step of iterative refinement
    /// ([`crate::linear::SparseFactor::solve_refined_in_place`]): for steps that take one
    /// direction and keep its error, as a linearly implicit step does; iterations to a
    /// tolerance remove it anyway.
    pub(crate) refine: bool,
    /// Whether the kept factorisation rotates with the body (modified Newton). Not for a
    /// linearly implicit step: it keeps its one direction's error, and the rotation keeps
    /// a factorisation for more steps, which on the hammerbot's swing multiplied that error.
    pub(crate) rotate: bool,
    /// The configuration the kept factorisation was computed at, for its rotation with the
    /// body; `None` where that does not apply (contact, displacement-controlled tendons, no
    /// `rotate`).
    pub(crate) warp: Option<WarpReference>,
    /// The node rotations from `warp` to the current solve's first kept-factor iterate (one
    /// rotation per solve: the secant pairs follow the rest of the solve's drift).
    pub(crate) rotations: Option<Vec<Matrix3<f64>>>,
}

impl FactorReuse {
    pub(crate) fn new(max_ratio: f64) -> Self {
        FactorReuse {
            kept: None,
            contact_set: 0,
            last_norm: None,
            max_ratio,
            reused: 0,
            taut: Vec::new(),
            secants: SecantPairs::default(),
            double_precision: false,
            refine: false,
            rotate: false,
            warp: None,
            rotations: None,
        }
    }

    /// Forgets what belongs to one solve (the next has its own energy), and sets how the step
    /// uses the kept factorisation: a linearly implicit step's one direction is refined, modified
    /// Newton's are rotated.
    pub(crate) fn start_solve(&mut self, linearly_implicit: bool) {
        self.refine = linearly_implicit;
        self.rotate = !linearly_implicit;
        self.last_norm = None;
        self.secants.clear();
        self.rotations = None;
    }
}

/// How many secant pairs the inverse update keeps: more than a step's iterations need.
const MAX_PAIRS: usize = 8;

/// A pair is used only when its curvature `s.y` is at least this fraction of `|s| |y|`, which
/// keeps the update's inverse positive definite and well conditioned.
const MIN_CURVATURE: f64 = 1e-10;

/// The secant pairs `s_k = x_(k+1) - x_k`, `y_k = g_(k+1) - g_k` (free DOFs) of one solve's
/// iterates, for the L-BFGS two-loop recursion (Nocedal and Wright, *Numerical Optimization*,
/// algorithm 7.4) around an initial inverse Hessian.
#[derive(Clone, Debug, Default)]
pub(crate) struct SecantPairs {
    pairs: Vec<(Vec<f64>, Vec<f64>, f64)>,
    last: Option<(Vec<f64>, Vec<f64>)>,
}

impl SecantPairs {
    pub(crate) fn clear(&mut self) {
        self.pairs.clear();
        self.last = None;
    }

    /// Records the iterate `x` with gradient `g`; with the previous one, a pair.
    pub(crate) fn record(&mut self, x: Vec<f64>, g: &[f64]) {
        if let Some((x0, g0)) = self.last.take() {
            let s: Vec<f64> = x.iter().zip(&x0).map(|(a, b)| a - b).collect();
            let y: Vec<f64> = g.iter().zip(&g0).map(|(a, b)| a - b).collect();
            let sy = dot(&s, &y);
            if sy > MIN_CURVATURE * (dot(&s, &s) * dot(&y, &y)).sqrt() {
                if self.pairs.len() == MAX_PAIRS {
                    self.pairs.remove(0);
                }
                self.pairs.push((s, y, 1.0 / sy));
            }
        }
        self.last = Some((x, g.to_vec()));
    }

    #[cfg(test)]
    fn is_empty(&self) -> bool {
        self.pairs.is_empty()
    }

    /// `H^{-1} g` of the updated inverse, given `initial(q) = H_0^{-1} q`; `None` when the
    /// initial inverse fails.
    pub(crate) fn apply_inverse(
        &self,
        g: &[f64],
        initial: impl FnOnce(&[f64]) -> Option<Vec<f64>>,
    ) -> Option<Vec<f64>> {
        let mut q = g.to_vec();
        let mut alphas = Vec::with_capacity(self.pairs.len());
        for (s, y, rho) in self.pairs.iter().rev() {
            let alpha = rho * dot(s, &q);
            q.iter_mut().zip(y).for_each(|(qi, yi)| *qi -= alpha * yi);
            alphas.push(alpha);
        }
        let mut r = initial(&q)?;
        for ((s, y, rho), alpha) in self.pairs.iter().zip(alphas.iter().rev()) {
            let beta = rho * dot(y, &r);
            r.iter_mut()
                .zip(s)
                .for_each(|(ri, si)| *ri += (alpha - beta) * si);
        }
        Some(r)
    }
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    const A: [[f64; 3]; 3] = [[4.0, 1.0, 0.0], [1.0, 3.0, 0.5], [0.0, 0.5, 2.0]];

    fn times_a(x: &[f64]) -> Vec<f64> {
        (0..3)
            .map(|i| (0..3).map(|j| A[i][j] * x[j]).sum())
            .collect()
    }

    fn solve_a(b: &[f64]) -> Vec<f64> {
        // Gauss-Seidel converges for this diagonally dominant A.
        let mut x = vec![0.0; 3];
        for _ in 0..200 {
            for i in 0..3 {
                let off: f64 = (0..3).filter(|&j| j != i).map(|j| A[i][j] * x[j]).sum();
                x[i] = (b[i] - off) / A[i][i];
            }
        }
        x
    }

    fn quadratic_pairs() -> SecantPairs {
        let mut secants = SecantPairs::default();
        for x in [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.2, 1.0, 1.0],
        ] {
            secants.record(x.to_vec(), &times_a(&x));
        }
        secants
    }

    /// The update meets the secant equation of its newest pair: H^{-1} y = s, from any
    /// positive definite initial inverse.
    #[test]
    fn the_newest_secant_equation_holds() {
        let secants = quadratic_pairs();
        let (s, y) = ([-0.8, 0.0, 1.0], times_a(&[-0.8, 0.0, 1.0]));
        let x = secants
            .apply_inverse(&y, |q| Some(q.to_vec()))
            .expect("identity");
        for (xi, si) in x.iter().zip(s) {
            assert!((xi - si).abs() < 1e-12, "{x:?} vs {s:?}");
        }
    }

    /// Pairs of a quadratic leave its exact inverse unchanged (each already meets them).
    #[test]
    fn an_exact_initial_inverse_is_kept() {
        let secants = quadratic_pairs();
        let g = [0.3, -0.7, 1.1];
        let x = secants
            .apply_inverse(&g, |q| Some(solve_a(q)))
            .expect("solve");
        for (xi, ti) in x.iter().zip(solve_a(&g)) {
            assert!((xi - ti).abs() < 1e-12, "{xi} vs {ti}");
        }
    }

    /// A pair without positive curvature is not used.
    #[test]
    fn a_pair_of_negative_curvature_is_skipped() {
        let mut secants = SecantPairs::default();
        secants.record(vec![0.0, 0.0], &[0.0, 0.0]);
        secants.record(vec![1.0, 0.0], &[-1.0, 0.0]);
        assert!(secants.is_empty());
    }
}
