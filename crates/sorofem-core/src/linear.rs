//! Sparse symmetric factorisations: the symbolic analysis (fill-reducing ordering, elimination
//! tree, supernodes) is done once per sparsity pattern; each Newton step only refactors numerically.

mod supernodal;

use crate::error::{Error, Result};
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::ldlt::factor::LdltRegularization;
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, LdltRef, LltRef, SymbolicCholesky, SymbolicCholeskyRaw,
    SymmetricOrdering,
};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Conj, MatMut, Par, Side};
use std::sync::Arc;
use supernodal::SolveSplit;

/// The lower triangle (row >= column) of a symmetric sparse matrix in compressed-column form,
/// rows sorted within each column.
#[derive(Clone, Debug)]
pub struct LowerPattern {
    pub n: usize,
    pub col_ptr: Vec<usize>,
    pub row_idx: Vec<usize>,
}

impl LowerPattern {
    pub fn nnz(&self) -> usize {
        self.row_idx.len()
    }

    /// Position of entry (row, col) with row >= col in the value array, if it is in the pattern.
    pub fn position(&self, row: usize, col: usize) -> Option<usize> {
        let start = self.col_ptr[col];
        let rows = &self.row_idx[start..self.col_ptr[col + 1]];
        rows.binary_search(&row).ok().map(|k| start + k)
    }

    /// The transpose's `(col_ptr, row_idx)`: the same matrix stored as its upper triangle.
    fn transpose(&self) -> (Vec<usize>, Vec<usize>) {
        let mut col_ptr = vec![0usize; self.n + 1];
        for &r in &self.row_idx {
            col_ptr[r + 1] += 1;
        }
        for c in 0..self.n {
            col_ptr[c + 1] += col_ptr[c];
        }
        let mut next = col_ptr.clone();
        let mut row_idx = vec![0usize; self.nnz()];
        // Columns in increasing order keep each transposed column's rows sorted.
        for c in 0..self.n {
            for &r in &self.row_idx[self.col_ptr[c]..self.col_ptr[c + 1]] {
                row_idx[next[r]] = c;
                next[r] += 1;
            }
        }
        (col_ptr, row_idx)
    }

    fn symbolic(&self) -> SymbolicSparseColMatRef<'_, usize> {
        SymbolicSparseColMatRef::new_checked(self.n, self.n, &self.col_ptr, None, &self.row_idx)
    }

    /// `y = A x` for the symmetric matrix whose lower triangle holds `values`.
    pub fn symmetric_matvec(&self, values: &[f64], x: &[f64]) -> Vec<f64> {
        let mut y = vec![0.0; self.n];
        for col in 0..self.n {
            for k in self.col_ptr[col]..self.col_ptr[col + 1] {
                let row = self.row_idx[k];
                y[row] += values[k] * x[col];
                if row != col {
                    y[col] += values[k] * x[row];
                }
            }
        }
        y
    }
}

/// Which numeric factorisation is currently stored.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Stored {
    None,
    Llt,
    Ldlt,
    /// `L L^T` in single precision (see [`SparseFactor::factor_single`]).
    LltSingle,
}

/// The relative residual `|b - A x| / |b|` at which [`SparseFactor::solve_to_precision`] stops
/// refining a single-precision solve: about a double-precision factorisation's own (1e-12 on
/// the hammerbot's time-step Hessians).
pub const REFINED_RESIDUAL: f64 = 1e-12;
/// A refinement that stops shrinking the residual tenfold has reached round-off; below this
/// relative residual that is accepted, above it the matrix is factorised in double precision.
pub const ROUND_OFF_RESIDUAL: f64 = 1e-10;
/// Refinements of one single-precision solve at most (the hammerbot's step Hessians need two:
/// relative residuals 5e-4, 4e-8, 3e-12).
pub const MAX_REFINEMENTS: usize = 6;

/// Which factorisation a [`SparseFactor`] computes, fixed at its analysis.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FactorKind {
    /// `L L^T`: symmetric positive definite matrices (the standard formulation's Hessian). Fails
    /// on the first non-positive pivot, which is how Newton tells an indefinite Hessian.
    Llt,
    /// `L D L^T` without pivoting: quasi-definite saddle-point matrices (the mixed formulation).
    Ldlt,
}

/// A reusable sparse Cholesky (`L L^T`, for positive definite systems) or `L D L^T` (for
/// quasi-definite saddle-point systems `[[A, B^T], [B, -C]]`, A and C positive definite).
///
/// The matrix is handed to faer already in elimination order: the permuted lower pattern and a
/// map from each stored entry to its permuted slot are computed once, so each factorisation
/// copies the values through that map instead of having faer permute (and re-sort) the whole
/// matrix every time (5 % of a hammerbot solve's profile).
pub struct SparseFactor {
    kind: FactorKind,
    analysis: Arc<Analysis>,
    values: Vec<f64>,
    stored: Stored,
    permuted_values: Vec<f64>,
    /// Single-precision values of `P A P^T` and of its factor (see
    /// [`SparseFactor::factor_single`]); empty until the first such factorisation.
    single_permuted: Vec<f32>,
    single_values: Vec<f32>,
    /// The numeric factorisation's workspace, kept: allocating and freeing its few MB at every
    /// factorisation cost page faults each time.
    scratch: Option<MemBuffer>,
    /// Numeric factorisations so far: tells a caller that kept this factor as an approximation
    /// whether it still holds the values it factored.
    generation: u64,
}

/// What a [`SparseFactor`]'s symbolic analysis fixes, shared by its siblings
/// ([`SparseFactor::sibling`]).
struct Analysis {
    symbolic: SymbolicCholesky<usize>,
    /// `order[k]`: the unknown eliminated k-th.
    order: Vec<usize>,
    /// The lower triangle of `P A P^T` (`(P A P^T)_ij = A_(order[i], order[j])`).
    permuted: LowerPattern,
    /// Slot in `permuted` of each stored entry of the caller's pattern.
    slot: Vec<usize>,
    /// Supernodal factors with two subtrees of similar size: how the triangular solves share
    /// the work between two threads.
    split: Option<SolveSplit>,
}

impl SparseFactor {
    /// Symbolic analysis with an approximate-minimum-degree ordering.
    pub fn analyse(pattern: &LowerPattern, kind: FactorKind) -> Result<Self> {
        Self::analyse_with_order(pattern, &amd_order(pattern)?, kind)
    }

    /// Symbolic analysis with a given elimination order: `order[k]` is the unknown eliminated
    /// k-th. Saddle-point systems need one that eliminates each pressure after the displacements
    /// it couples to, so that no pivot is the (tiny) compliance alone.
    pub fn analyse_with_order(
        pattern: &LowerPattern,
        order: &[usize],
        kind: FactorKind,
    ) -> Result<Self> {
        let n = pattern.n;
        let mut inverse = vec![usize::MAX; n];
        for (k, &i) in order.iter().enumerate() {
            if i < n {
                inverse[i] = k;
            }
        }
        if order.len() != n || inverse.contains(&usize::MAX) {
            return Err(Error::LinearSolver {
                message: "elimination order is not a permutation".into(),
            });
        }
        // Entry (r, c) of A goes to (max, min) of (inverse[r], inverse[c]) in P A P^T. Two
        // counting sorts place every entry: first by new row, then, visiting rows in increasing
        // order, by new column, which leaves each column's rows sorted.
        let nnz = pattern.nnz();
        let mut by_row = vec![0usize; n + 1];
        let mut new_entries = vec![(0usize, 0usize); nnz]; // (new row, new column) per entry
        for c in 0..n {
            for k in pattern.col_ptr[c]..pattern.col_ptr[c + 1] {
                let (a, b) = (inverse[pattern.row_idx[k]], inverse[c]);
                new_entries[k] = (a.max(b), a.min(b));
                by_row[a.max(b) + 1] += 1;
            }
        }
        for r in 0..n {
            by_row[r + 1] += by_row[r];
        }
        let mut next = by_row.clone();
        let mut row_order = vec![0usize; nnz];
        for (k, &(row, _)) in new_entries.iter().enumerate() {
            row_order[next[row]] = k;
            next[row] += 1;
        }
        let mut col_ptr = vec![0usize; n + 1];
        for &(_, col) in &new_entries {
            col_ptr[col + 1] += 1;
        }
        for c in 0..n {
            col_ptr[c + 1] += col_ptr[c];
        }
        let mut next = col_ptr.clone();
        let mut row_idx = vec![0usize; nnz];
        let mut slot = vec![0usize; nnz];
        for &k in &row_order {
            let (row, col) = new_entries[k];
            row_idx[next[col]] = row;
            slot[k] = next[col];
            next[col] += 1;
        }
        let permuted = LowerPattern {
            n,
            col_ptr,
            row_idx,
        };
        // faer takes an Identity-ordered matrix in the triangle it is given as is, and its
        // symbolic phase reads that as the upper one: hand it the transpose. The numeric phase
        // then gets the lower triangle, which the supernodal factorisation reads without a copy.
        let upper = permuted.transpose();
        let symbolic = factorize_symbolic_cholesky(
            SymbolicSparseColMatRef::new_checked(n, n, &upper.0, None, &upper.1),
            Side::Upper,
            SymmetricOrdering::Identity,
            Default::default(),
        )
        .map_err(|e| Error::LinearSolver {
            message: format!("symbolic analysis failed: {e:?}"),
        })?;
        let split = match symbolic.raw() {
            SymbolicCholeskyRaw::Supernodal(supernodal) => SolveSplit::new(supernodal),
            SymbolicCholeskyRaw::Simplicial(_) => None,
        };
        let analysis = Analysis {
            symbolic,
            order: order.to_vec(),
            permuted,
            slot,
            split,
        };
        Self::with_analysis(kind, Arc::new(analysis))
    }

    /// A factor with its own values and workspace for `analysis`, the workspace allocated and
    /// written now as well.
    fn with_analysis(kind: FactorKind, analysis: Arc<Analysis>) -> Result<Self> {
        let mut factor = SparseFactor {
            kind,
            values: written_zeros(analysis.symbolic.len_val()),
            permuted_values: written_zeros(analysis.permuted.nnz()),
            analysis,
            stored: Stored::None,
            generation: 0,
            scratch: None,
            single_permuted: Vec::new(),
            single_values: Vec::new(),
        };
        let par = factor.parallelism();
        let symbolic = &factor.analysis.symbolic;
        let req = match kind {
            FactorKind::Llt => {
                symbolic.factorize_numeric_llt_scratch::<f64>(par, Default::default())
            }
            FactorKind::Ldlt => {
                symbolic.factorize_numeric_ldlt_scratch::<f64>(par, Default::default())
            }
        };
        scratch_of(&mut factor.scratch, req)?.fill(std::mem::MaybeUninit::new(0));
        Ok(factor)
    }

    /// A second factor of the same analysis (the same pattern, kind and elimination order),
    /// with nothing factored: for a caller that factors one matrix while it still solves with
    /// this factor's.
    pub fn sibling(&self) -> Result<Self> {
        Self::with_analysis(self.kind, Arc::clone(&self.analysis))
    }

    /// Stored entries of the pattern this factor was analysed for.
    pub fn analysed_nnz(&self) -> usize {
        self.analysis.slot.len()
    }

    /// Copies `values` (in the caller's pattern) into elimination order.
    fn permute_values(&mut self, values: &[f64]) {
        assert_eq!(
            values.len(),
            self.analysis.slot.len(),
            "values of the analysed pattern"
        );
        for (&slot, &v) in self.analysis.slot.iter().zip(values) {
            self.permuted_values[slot] = v;
        }
    }

    /// Threads for the numeric factorisation and the triangular solves. faer's parallel
    /// supernodal factorisation only pays off on large factors: on this project's 2-core
    /// machine it was 1.9x slower than the sequential one at 0.9M and 1.4M factor values,
    /// 1.15x slower at 7.2M and 1.34x faster at 34M (see BENCHMARKS.md).
    fn parallelism(&self) -> faer::Par {
        const PARALLEL_FROM_FACTOR_VALUES: usize = 12_000_000;
        if self.values.len() >= PARALLEL_FROM_FACTOR_VALUES {
            faer::get_global_parallelism()
        } else {
            faer::Par::Seq
        }
    }

    /// Number of stored values in the factor (a measure of fill-in and memory).
    pub fn factor_nnz(&self) -> usize {
        self.values.len()
    }

    pub fn kind(&self) -> FactorKind {
        self.kind
    }

    /// How many numeric factorisations (successful or not) this factor has run: unchanged
    /// means it still holds the one a caller saw at that count.
    pub fn generation(&self) -> u64 {
        self.generation
    }

    /// Whether a numeric factorisation is stored (the last one succeeded).
    pub fn is_factored(&self) -> bool {
        self.stored != Stored::None
    }

    /// Numeric factorisation of the [`FactorKind`] chosen at analysis, of `values` in the
    /// analysed `pattern`. `Ok(false)` when the matrix has no such factorisation: not
    /// numerically positive definite (`L L^T`), a zero or non-finite pivot (`L D L^T`).
    pub fn factor(&mut self, pattern: &LowerPattern, values: &[f64]) -> Result<bool> {
        self.generation += 1;
        match self.kind {
            FactorKind::Llt => self.factor_llt(pattern, values),
            FactorKind::Ldlt => self.factor_ldlt(pattern, values),
        }
    }

    /// [`SparseFactor::factor`] in single precision (`L L^T` only; an `L D L^T` analysis
    /// factors in double precision). For callers that use the factorisation as an approximation
    /// anyway, as modified Newton does, or that refine its solves
    /// ([`SparseFactor::solve_to_precision`]): it takes 0.6 to 0.7 times the time of the
    /// double-precision one and its solves stream half the bytes, and its relative error, about
    /// `1e-7` times the condition number, is below the error of a factorisation kept from an
    /// earlier iterate.
    /// `Ok(false)` when the matrix is not numerically positive definite in single precision.
    pub fn factor_single(&mut self, pattern: &LowerPattern, values: &[f64]) -> Result<bool> {
        if self.kind != FactorKind::Llt {
            return self.factor(pattern, values);
        }
        self.generation += 1;
        debug_assert_eq!(
            pattern.nnz(),
            self.analysis.slot.len(),
            "the analysed pattern"
        );
        self.permute_values(values);
        if self.single_values.is_empty() {
            self.single_values = vec![0.0; self.values.len()];
        }
        self.single_permuted.clear();
        self.single_permuted
            .extend(self.permuted_values.iter().map(|&v| v as f32));
        if self.single_permuted.iter().any(|v| !v.is_finite()) {
            self.stored = Stored::None;
            return Ok(false);
        }
        let par = self.parallelism();
        let ok = numeric_llt(
            &self.analysis.symbolic,
            &mut self.scratch,
            self.analysis.permuted.symbolic(),
            &self.single_permuted,
            &mut self.single_values,
            par,
        )?;
        self.stored = if ok { Stored::LltSingle } else { Stored::None };
        Ok(ok)
    }

    /// Whether the stored factorisation is in single precision.
    pub fn is_single(&self) -> bool {
        self.stored == Stored::LltSingle
    }

    /// Numeric `L L^T`. Returns `Ok(false)` when the matrix is not numerically positive definite.
    fn factor_llt(&mut self, pattern: &LowerPattern, values: &[f64]) -> Result<bool> {
        debug_assert_eq!(
            pattern.nnz(),
            self.analysis.slot.len(),
            "the analysed pattern"
        );
        self.permute_values(values);
        self.factor_permuted_llt()
    }

    /// Numeric `L L^T` of the values already in elimination order (`permuted_values`).
    fn factor_permuted_llt(&mut self) -> Result<bool> {
        let par = self.parallelism();
        let ok = numeric_llt(
            &self.analysis.symbolic,
            &mut self.scratch,
            self.analysis.permuted.symbolic(),
            &self.permuted_values,
            &mut self.values,
            par,
        )?;
        self.stored = if ok { Stored::Llt } else { Stored::None };
        Ok(ok)
    }

    /// Numeric `L D L^T` without pivoting, in the order fixed by the symbolic analysis. Meant for
    /// quasi-definite saddle-point matrices `[[A, G^T], [G, -C]]` (A positive definite, C positive
    /// semi-definite), which have such a factorisation in any order. Returns `Ok(false)` on a zero
    /// or non-finite pivot; the caller checks the resulting direction (an indefinite A still
    /// factors, so inertia is the caller's concern).
    fn factor_ldlt(&mut self, pattern: &LowerPattern, values: &[f64]) -> Result<bool> {
        debug_assert_eq!(
            pattern.nnz(),
            self.analysis.slot.len(),
            "the analysed pattern"
        );
        self.permute_values(values);
        let par = self.parallelism();
        let mat = SparseColMatRef::new(self.analysis.permuted.symbolic(), &self.permuted_values);
        let req = self
            .analysis
            .symbolic
            .factorize_numeric_ldlt_scratch::<f64>(par, Default::default());
        let mem = scratch_of(&mut self.scratch, req)?;
        let result = self.analysis.symbolic.factorize_numeric_ldlt::<f64>(
            &mut self.values,
            mat,
            Side::Lower,
            LdltRegularization::default(),
            par,
            MemStack::new(mem),
            Default::default(),
        );
        self.stored = if result.is_ok() {
            Stored::Ldlt
        } else {
            Stored::None
        };
        Ok(result.is_ok())
    }

    /// Solves `A x = rhs` in place with the stored factorisation.
    pub fn solve_in_place(&self, rhs: &mut [f64]) {
        if self.stored == Stored::LltSingle {
            return self.solve_single_in_place(rhs, false);
        }
        let mut permuted: Vec<f64> = self.analysis.order.iter().map(|&i| rhs[i]).collect();
        self.solve_double_permuted(&mut permuted);
        for (&i, &v) in self.analysis.order.iter().zip(&permuted) {
            rhs[i] = v;
        }
    }

    /// Solves `A x = rhs` in place to a double-precision factorisation's accuracy. With one
    /// ([`SparseFactor::factor`]) this is [`SparseFactor::solve_in_place`]. With a single-precision
    /// factor ([`SparseFactor::factor_single`]) the solve is refined (`x += A^{-1} (b - A x)`, the
    /// residual in double precision against the matrix factored) until the relative residual
    /// `|b - A x| / |b|` is [`REFINED_RESIDUAL`], or stops shrinking tenfold per refinement below
    /// [`ROUND_OFF_RESIDUAL`]; where it does neither within [`MAX_REFINEMENTS`] (a matrix too
    /// ill-conditioned for single precision), the matrix is factorised again in double
    /// precision for this solve. Each refinement costs a single-precision solve and a
    /// matrix-vector product: for a caller that solves once or twice per factorisation, against
    /// a factorisation that takes 0.6 to 0.7 times the double-precision one's time.
    pub fn solve_to_precision(&self, rhs: &mut [f64]) -> Result<()> {
        if self.stored != Stored::LltSingle {
            self.solve_in_place(rhs);
            return Ok(());
        }
        let b: Vec<f64> = self.analysis.order.iter().map(|&i| rhs[i]).collect();
        if b.iter().all(|&v| v == 0.0) {
            rhs.fill(0.0);
            return Ok(());
        }
        let (mut x, relative) = self.refined_single_permuted(&b);
        if !(relative <= ROUND_OFF_RESIDUAL) {
            let mut double = self.sibling()?;
            double
                .permuted_values
                .copy_from_slice(&self.permuted_values);
            if !double.factor_permuted_llt()? {
                return Err(Error::LinearSolver {
                    message: "the matrix is not positive definite in double precision either"
                        .into(),
                });
            }
            x = b;
            double.solve_double_permuted(&mut x);
        }
        for (&i, v) in self.analysis.order.iter().zip(x) {
            rhs[i] = v;
        }
        Ok(())
    }

    /// `A^{-1} b` by the single-precision factor, refined as [`SparseFactor::solve_to_precision`]
    /// says, and its relative residual (`b`, nonzero, and the result in elimination order).
    fn refined_single_permuted(&self, b: &[f64]) -> (Vec<f64>, f64) {
        let norm = |v: &[f64]| v.iter().map(|a| a * a).sum::<f64>().sqrt();
        let scale = norm(b);
        let mut x = self.solve_single_permuted(b);
        let mut residual = self.permuted_residual(b, &x);
        let mut relative = norm(&residual) / scale;
        for _ in 0..MAX_REFINEMENTS {
            if relative <= REFINED_RESIDUAL {
                break;
            }
            for (x, dx) in x.iter_mut().zip(self.solve_single_permuted(&residual)) {
                *x += dx;
            }
            residual = self.permuted_residual(b, &x);
            let next = norm(&residual) / scale;
            let stalled = next > 0.1 * relative;
            relative = next;
            if stalled {
                break;
            }
        }
        (x, relative)
    }

    /// Solves in place with the double-precision factor, `permuted` in elimination order.
    fn solve_double_permuted(&self, permuted: &mut [f64]) {
        match (
            self.analysis.symbolic.raw(),
            &self.analysis.split,
            self.stored,
        ) {
            (SymbolicCholeskyRaw::Supernodal(supernodal), Some(split), Stored::Llt) => {
                split.solve(supernodal, &self.values, permuted)
            }
            _ => self.faer_solve_in_place(permuted),
        }
    }

    /// [`SparseFactor::solve_in_place`], followed by one step of iterative refinement when the
    /// factorisation is in single precision: `x += A^{-1} (b - A x)` with the residual in double
    /// precision against the matrix that was factored. The relative error, `e` (about `1e-7`
    /// times the condition number) after the plain solve, becomes about `e^2`, for the cost of a
    /// second solve and a matrix-vector product.
    pub fn solve_refined_in_place(&self, rhs: &mut [f64]) {
        if self.stored == Stored::LltSingle {
            self.solve_single_in_place(rhs, true);
        } else {
            self.solve_in_place(rhs);
        }
    }

    /// [`SparseFactor::solve_in_place`] with the single-precision factor (the right-hand side is
    /// rounded to single precision too: its error is the factor's), refined once if `refine`.
    fn solve_single_in_place(&self, rhs: &mut [f64], refine: bool) {
        let b: Vec<f64> = self.analysis.order.iter().map(|&i| rhs[i]).collect();
        let mut x = self.solve_single_permuted(&b);
        if refine {
            let residual = self.permuted_residual(&b, &x);
            for (x, dx) in x.iter_mut().zip(self.solve_single_permuted(&residual)) {
                *x += dx;
            }
        }
        for (&i, v) in self.analysis.order.iter().zip(x) {
            rhs[i] = v;
        }
    }

    /// `|b - A x| / |b|` for `x` from [`SparseFactor::solve_in_place`]: how accurately the
    /// stored factorisation solves with the matrix it factored (0 for `b = 0`).
    pub fn solve_residual(&self, rhs: &[f64]) -> f64 {
        let b: Vec<f64> = self.analysis.order.iter().map(|&i| rhs[i]).collect();
        let mut x = rhs.to_vec();
        self.solve_in_place(&mut x);
        let x: Vec<f64> = self.analysis.order.iter().map(|&i| x[i]).collect();
        let norm = |v: &[f64]| v.iter().map(|a| a * a).sum::<f64>().sqrt();
        let scale = norm(&b);
        if scale == 0.0 {
            return 0.0;
        }
        norm(&self.permuted_residual(&b, &x)) / scale
    }

    /// `b - A x` in elimination order, `A` the matrix of the last factorisation.
    fn permuted_residual(&self, b: &[f64], x: &[f64]) -> Vec<f64> {
        let ax = self
            .analysis
            .permuted
            .symmetric_matvec(&self.permuted_values, x);
        b.iter().zip(ax).map(|(b, a)| b - a).collect()
    }

    /// `A^{-1} b` with the single-precision factor, `b` and the result in elimination order.
    fn solve_single_permuted(&self, b: &[f64]) -> Vec<f64> {
        let mut permuted: Vec<f32> = b.iter().map(|&v| v as f32).collect();
        match (self.analysis.symbolic.raw(), &self.analysis.split) {
            (SymbolicCholeskyRaw::Supernodal(supernodal), Some(split)) => {
                split.solve(supernodal, &self.single_values, &mut permuted)
            }
            _ => {
                let par = self.parallelism();
                let n = permuted.len();
                let req = self.analysis.symbolic.solve_in_place_scratch::<f32>(1, par);
                let mut mem = MemBuffer::new(req);
                let rhs_mat = MatMut::from_column_major_slice_mut(&mut permuted, n, 1);
                LltRef::new(&self.analysis.symbolic, &self.single_values).solve_in_place_with_conj(
                    Conj::No,
                    rhs_mat,
                    par,
                    MemStack::new(&mut mem),
                );
            }
        }
        permuted.into_iter().map(f64::from).collect()
    }

    /// faer's solve, on a right-hand side already in elimination order.
    fn faer_solve_in_place(&self, permuted: &mut [f64]) {
        let par = self.parallelism();
        let n = permuted.len();
        let req = self.analysis.symbolic.solve_in_place_scratch::<f64>(1, par);
        let mut mem = MemBuffer::new(req);
        let rhs_mat = MatMut::from_column_major_slice_mut(permuted, n, 1);
        match self.stored {
            Stored::Llt => LltRef::new(&self.analysis.symbolic, &self.values)
                .solve_in_place_with_conj(Conj::No, rhs_mat, par, MemStack::new(&mut mem)),
            Stored::Ldlt => LdltRef::new(&self.analysis.symbolic, &self.values)
                .solve_in_place_with_conj(Conj::No, rhs_mat, par, MemStack::new(&mut mem)),
            Stored::None | Stored::LltSingle => {
                panic!("faer_solve_in_place called without a double-precision factorisation")
            }
        }
    }
}

/// faer's numeric `L L^T` of the lower triangle `values` (pattern `lower`, in elimination order)
/// into `factor`, in the precision `T`, with the workspace kept in `scratch`. `Ok(false)` on a
/// non-positive pivot, the numeric phase's only failure.
fn numeric_llt<T: faer::traits::RealField>(
    symbolic: &SymbolicCholesky<usize>,
    scratch: &mut Option<MemBuffer>,
    lower: SymbolicSparseColMatRef<'_, usize>,
    values: &[T],
    factor: &mut [T],
    par: Par,
) -> Result<bool> {
    let req = symbolic.factorize_numeric_llt_scratch::<T>(par, Default::default());
    let mem = scratch_of(scratch, req)?;
    let result = symbolic.factorize_numeric_llt::<T>(
        factor,
        SparseColMatRef::new(lower, values),
        Side::Lower,
        LltRegularization::default(),
        par,
        MemStack::new(mem),
        Default::default(),
    );
    Ok(result.is_ok())
}

/// `n` zeros in memory that has been written. A freshly allocated zero vector is usually mapped
/// lazily, page by page at first write: that would land in the first numeric factorisation
/// (7 ms of 21 at 12k tets, 11 of 33 at 18k), i.e. in the first Newton iteration, instead of
/// in the analysis that sizes the factor.
fn written_zeros(n: usize) -> Vec<f64> {
    let mut values = Vec::with_capacity(n);
    values.resize(n, 0.0);
    values
}

/// Approximate-minimum-degree elimination order of a symmetric pattern (`order[k]` = unknown
/// eliminated k-th).
pub fn amd_order(pattern: &LowerPattern) -> Result<Vec<usize>> {
    let n = pattern.n;
    let mut order = vec![0usize; n];
    let mut inverse = vec![0usize; n];
    let req = faer::sparse::linalg::amd::order_scratch::<usize>(n, pattern.nnz());
    let mut mem = MemBuffer::try_new(req).map_err(|_| oom())?;
    faer::sparse::linalg::amd::order(
        &mut order,
        &mut inverse,
        pattern.symbolic(),
        Default::default(),
        MemStack::new(&mut mem),
    )
    .map_err(|e| Error::LinearSolver {
        message: format!("AMD ordering failed: {e:?}"),
    })?;
    Ok(order)
}

/// `kept`, grown to at least `req` if needed.
fn scratch_of(
    kept: &mut Option<MemBuffer>,
    req: faer::dyn_stack::StackReq,
) -> Result<&mut MemBuffer> {
    if kept.as_ref().is_none_or(|mem| mem.len() < req.size_bytes()) {
        *kept = Some(MemBuffer::try_new(req).map_err(|_| oom())?);
    }
    Ok(kept.as_mut().expect("allocated above"))
}

fn oom() -> Error {
    Error::LinearSolver {
        message: "out of memory while allocating factorisation workspace".into(),
    }
}

#[cfg(test)]
mod tests;
