//! Displacement-controlled tendons as exact constraints of a Newton solve: the multipliers, the
//! active set and the bordered Newton step (the method is in docs/theory.md, "Tendons").
//!
//! Constraint `i` is tendon `tendons[i]` with `g_i(z) = L_i(z) - (L0_i - s d_i) <= 0`, `s` the
//! load factor, and multiplier `T_i >= 0` (its tension, N) with `T_i g_i = 0`. The multipliers
//! ride along the Newton state: the full DOF vector is extended by one entry per constraint
//! (`z[offset + i] = T_i`), and a Newton direction by their increments, so that the line search
//! moves both together and a cut-back restores both.

use crate::assembly::Assembler;
use crate::energy::{TendonCommand, TendonTerm};
use crate::linear::SparseFactor;
use nalgebra::{DMatrix, DVector};

/// A constraint met to this fraction of the tendon's rest length counts as met: the solve goes
/// on until every taut tendon's length is within it, whatever the residual tolerance.
pub(crate) const LENGTH_TOLERANCE: f64 = 1e-9;

/// The displacement-controlled tendons of one solve.
pub(super) struct TendonConstraints {
    /// Index in the model's [`TendonTerm`] of each constrained tendon.
    pub tendons: Vec<usize>,
    /// Where the multipliers start in the extended state (the full DOF count).
    pub offset: usize,
    /// `sigma` (N/m): the constraint rows of the residual are `min(T, -sigma g)` (N).
    pub weight: f64,
    /// The load factor the pulls are applied at.
    pub factor: f64,
}

impl TendonConstraints {
    /// The displacement-controlled tendons of `term`, multipliers after `offset` full DOFs.
    pub fn new(term: &TendonTerm, offset: usize, weight: f64) -> Self {
        let tendons = (term.tendons.iter().enumerate())
            .filter(|(_, t)| matches!(t.command, TendonCommand::Pull(_)))
            .map(|(i, _)| i)
            .collect();
        TendonConstraints {
            tendons,
            offset,
            weight,
            factor: 1.0,
        }
    }

    pub fn len(&self) -> usize {
        self.tendons.len()
    }

    pub fn is_empty(&self) -> bool {
        self.tendons.is_empty()
    }

    /// The multipliers (N) of the extended state `z`.
    pub fn multipliers<'z>(&self, z: &'z [f64]) -> &'z [f64] {
        &z[self.offset..self.offset + self.len()]
    }

    /// The multipliers of the last solve, the starting guess of a warm start.
    pub fn current(&self, term: &TendonTerm) -> Vec<f64> {
        self.tendons
            .iter()
            .map(|&t| term.tendons[t].tension)
            .collect()
    }

    /// Gives each constrained tendon its multiplier from `z` as its tension.
    pub fn set_tensions(&self, term: &mut TendonTerm, z: &[f64]) {
        for (&t, &tension) in self.tendons.iter().zip(self.multipliers(z)) {
            term.tendons[t].tension = tension;
        }
    }

    /// `g_i` (m) of every constraint at the extended state `z`.
    pub fn values(&self, term: &TendonTerm, z: &[f64]) -> Vec<f64> {
        self.tendons
            .iter()
            .map(|&t| {
                let tendon = &term.tendons[t];
                let TendonCommand::Pull(d) = tendon.command else {
                    unreachable!("constraints are displacement-controlled tendons")
                };
                tendon.length(z) - (tendon.rest_length() - self.factor * d)
            })
            .collect()
    }

    /// The constraint rows of the residual, `min(T_i, -sigma g_i)` (N): zero exactly when
    /// `T_i >= 0`, `g_i <= 0` and `T_i g_i = 0`.
    pub fn residual_rows(&self, term: &TendonTerm, z: &[f64]) -> Vec<f64> {
        let values = self.values(term, z);
        (self.multipliers(z).iter().zip(values))
            .map(|(&tension, g)| tension.min(-self.weight * g))
            .collect()
    }

    /// Whether every constraint holds to [`LENGTH_TOLERANCE`] of its tendon's rest length:
    /// no tendon longer than allowed, and none under tension while shorter.
    pub fn met(&self, term: &TendonTerm, z: &[f64]) -> bool {
        let values = self.values(term, z);
        (self.tendons.iter().zip(values).zip(self.multipliers(z))).all(|((&t, g), &tension)| {
            let tolerance = LENGTH_TOLERANCE * term.tendons[t].rest_length();
            g <= tolerance && (tension == 0.0 || g >= -tolerance)
        })
    }

    /// `dL_i/dz` of constraint `i` at `z`, on the free DOFs of `assembler`.
    pub fn jacobian_row(
        &self,
        term: &TendonTerm,
        i: usize,
        z: &[f64],
        assembler: &Assembler,
    ) -> Vec<f64> {
        let mut full = vec![0.0; self.offset];
        term.tendons[self.tendons[i]].add_length_gradient(z, 1.0, &mut full);
        assembler.full_of_free().iter().map(|&d| full[d]).collect()
    }

    /// The Newton step of the constrained system from `b = -H^{-1} r_0` (free DOFs), `r_0` the
    /// residual without the constrained tendons' forces, and the factorised `H` (the Hessian at
    /// the current multipliers): `(dx, T_new)` with
    ///
    /// ```text
    /// H dx + sum_{i in A} T_i J_i = -r_0,   J_i dx = -g_i (i in A),   T_i = 0 (i not in A)
    /// ```
    ///
    /// by the Schur complement `S = J_A H^{-1} J_A^T`: `T_A = S^{-1} (J_A b + g_A)`,
    /// `dx = b - H^{-1} J_A^T T_A` (one extra solve per active constraint). The active set
    /// starts as `{i : T_i + sigma g_i > 0}` (primal-dual active set) and drops every
    /// constraint whose new multiplier would be negative (the tendon would push) until none is.
    /// `None` when a solve gives non-finite values.
    pub fn bordered_step(
        &self,
        term: &TendonTerm,
        z: &[f64],
        assembler: &Assembler,
        factor: &SparseFactor,
        mut b: Vec<f64>,
    ) -> Option<(Vec<f64>, Vec<f64>)> {
        let values = self.values(term, z);
        let multipliers = self.multipliers(z);
        let mut active: Vec<usize> = (0..self.len())
            .filter(|&i| multipliers[i] + self.weight * values[i] > 0.0)
            .collect();
        let rows: Vec<Vec<f64>> = (0..self.len())
            .map(|i| self.jacobian_row(term, i, z, assembler))
            .collect();
        let solved: Vec<Option<Vec<f64>>> = (0..self.len())
            .map(|i| {
                active.contains(&i).then(|| {
                    let mut a = rows[i].clone();
                    factor.solve_in_place(&mut a);
                    a
                })
            })
            .collect();
        let mut tensions = vec![0.0; self.len()];
        loop {
            let m = active.len();
            if m == 0 {
                break;
            }
            let a = |j: usize| solved[active[j]].as_ref().expect("solved when active");
            let schur = DMatrix::from_fn(m, m, |i, j| dot(&rows[active[i]], a(j)));
            let rhs = DVector::from_fn(m, |i, _| dot(&rows[active[i]], &b) + values[active[i]]);
            let solution = schur.lu().solve(&rhs)?;
            if solution.iter().any(|v| !v.is_finite()) {
                return None;
            }
            if solution.iter().all(|&v| v >= 0.0) {
                for (j, &i) in active.iter().enumerate() {
                    tensions[i] = solution[j];
                }
                break;
            }
            active = (active.iter().zip(solution.iter()))
                .filter(|(_, &v)| v >= 0.0)
                .map(|(&i, _)| i)
                .collect();
        }
        for (i, &tension) in tensions.iter().enumerate() {
            if tension != 0.0 {
                let a = solved[i].as_ref().expect("solved when active");
                for (bj, aj) in b.iter_mut().zip(a) {
                    *bj -= tension * aj;
                }
            }
        }
        Some((b, tensions))
    }
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}
