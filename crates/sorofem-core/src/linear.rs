//! Sparse symmetric factorisations: the symbolic analysis (fill-reducing ordering, elimination
//! tree, supernodes) is done once per sparsity pattern; each Newton step only refactors numerically.

use crate::error::{Error, Result};
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::ldlt::factor::LdltRegularization;
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::linalg::matmul::matmul;
use faer::linalg::triangular_solve::{
    solve_lower_triangular_in_place, solve_upper_triangular_in_place,
};
use faer::reborrow::{Reborrow, ReborrowMut};
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, supernodal::SymbolicSupernodalCholesky, LdltRef, LltRef,
    SymbolicCholesky, SymbolicCholeskyRaw, SymmetricOrdering,
};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Accum, Conj, MatMut, MatRef, Par, Side};

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
}

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
    symbolic: SymbolicCholesky<usize>,
    values: Vec<f64>,
    stored: Stored,
    /// `order[k]`: the unknown eliminated k-th.
    order: Vec<usize>,
    /// The lower triangle of `P A P^T` (`(P A P^T)_ij = A_(order[i], order[j])`).
    permuted: LowerPattern,
    /// Slot in `permuted` of each stored entry of the caller's pattern.
    slot: Vec<usize>,
    permuted_values: Vec<f64>,
    /// The numeric factorisation's workspace, kept: allocating and freeing its few MB at every
    /// factorisation cost page faults each time.
    scratch: Option<MemBuffer>,
    /// Supernodal factors with two subtrees of similar size: how the triangular solves share
    /// the work between two threads.
    split: Option<SolveSplit>,
    /// Numeric factorisations so far: tells a caller that kept this factor as an approximation
    /// whether it still holds the values it factored.
    generation: u64,
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
        let mut factor = SparseFactor {
            kind,
            split,
            values: written_zeros(symbolic.len_val()),
            symbolic,
            stored: Stored::None,
            generation: 0,
            scratch: None,
            order: order.to_vec(),
            permuted_values: written_zeros(permuted.nnz()),
            permuted,
            slot,
        };
        // The numeric factorisations' workspace, allocated and written now as well.
        let par = factor.parallelism();
        let req = match kind {
            FactorKind::Llt => factor
                .symbolic
                .factorize_numeric_llt_scratch::<f64>(par, Default::default()),
            FactorKind::Ldlt => factor
                .symbolic
                .factorize_numeric_ldlt_scratch::<f64>(par, Default::default()),
        };
        scratch_of(&mut factor.scratch, req)?.fill(std::mem::MaybeUninit::new(0));
        Ok(factor)
    }

    /// Copies `values` (in the caller's pattern) into elimination order.
    fn permute_values(&mut self, values: &[f64]) {
        assert_eq!(
            values.len(),
            self.slot.len(),
            "values of the analysed pattern"
        );
        for (&slot, &v) in self.slot.iter().zip(values) {
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

    /// Numeric `L L^T`. Returns `Ok(false)` when the matrix is not numerically positive definite.
    fn factor_llt(&mut self, pattern: &LowerPattern, values: &[f64]) -> Result<bool> {
        debug_assert_eq!(pattern.nnz(), self.slot.len(), "the analysed pattern");
        self.permute_values(values);
        let par = self.parallelism();
        let mat = SparseColMatRef::new(self.permuted.symbolic(), &self.permuted_values);
        let req = self
            .symbolic
            .factorize_numeric_llt_scratch::<f64>(par, Default::default());
        let mem = scratch_of(&mut self.scratch, req)?;
        let result = self.symbolic.factorize_numeric_llt::<f64>(
            &mut self.values,
            mat,
            Side::Lower,
            LltRegularization::default(),
            par,
            MemStack::new(mem),
            Default::default(),
        );
        match result {
            Ok(_) => {
                self.stored = Stored::Llt;
                Ok(true)
            }
            // The only failure of the numeric phase is a non-positive pivot.
            Err(_) => {
                self.stored = Stored::None;
                Ok(false)
            }
        }
    }

    /// Numeric `L D L^T` without pivoting, in the order fixed by the symbolic analysis. Meant for
    /// quasi-definite saddle-point matrices `[[A, G^T], [G, -C]]` (A positive definite, C positive
    /// semi-definite), which have such a factorisation in any order. Returns `Ok(false)` on a zero
    /// or non-finite pivot; the caller checks the resulting direction (an indefinite A still
    /// factors, so inertia is the caller's concern).
    fn factor_ldlt(&mut self, pattern: &LowerPattern, values: &[f64]) -> Result<bool> {
        debug_assert_eq!(pattern.nnz(), self.slot.len(), "the analysed pattern");
        self.permute_values(values);
        let par = self.parallelism();
        let mat = SparseColMatRef::new(self.permuted.symbolic(), &self.permuted_values);
        let req = self
            .symbolic
            .factorize_numeric_ldlt_scratch::<f64>(par, Default::default());
        let mem = scratch_of(&mut self.scratch, req)?;
        let result = self.symbolic.factorize_numeric_ldlt::<f64>(
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
        let mut permuted: Vec<f64> = self.order.iter().map(|&i| rhs[i]).collect();
        match (self.symbolic.raw(), &self.split, self.stored) {
            (SymbolicCholeskyRaw::Supernodal(supernodal), Some(split), Stored::Llt) => {
                split.solve(supernodal, &self.values, &mut permuted)
            }
            _ => self.faer_solve_in_place(&mut permuted),
        }
        for (&i, &v) in self.order.iter().zip(&permuted) {
            rhs[i] = v;
        }
    }

    /// faer's solve, on a right-hand side already in elimination order.
    fn faer_solve_in_place(&self, permuted: &mut [f64]) {
        let par = self.parallelism();
        let n = permuted.len();
        let req = self.symbolic.solve_in_place_scratch::<f64>(1, par);
        let mut mem = MemBuffer::new(req);
        let rhs_mat = MatMut::from_column_major_slice_mut(permuted, n, 1);
        match self.stored {
            Stored::Llt => LltRef::new(&self.symbolic, &self.values).solve_in_place_with_conj(
                Conj::No,
                rhs_mat,
                par,
                MemStack::new(&mut mem),
            ),
            Stored::Ldlt => LdltRef::new(&self.symbolic, &self.values).solve_in_place_with_conj(
                Conj::No,
                rhs_mat,
                par,
                MemStack::new(&mut mem),
            ),
            Stored::None => panic!("solve_in_place called without a successful factorisation"),
        }
    }
}

/// How the triangular solves of a supernodal factor share the work between two threads: two
/// groups of disjoint subtrees of the supernodal elimination tree, whose sweeps touch only their
/// own unknowns and those of the supernodes above them (`top`), which are swept alone.
///
/// Why: one right-hand side makes each sweep a stream through the whole factor with little
/// arithmetic per value read, and the other core is idle meanwhile. On this project's 2-core
/// machine the split solve takes 0.85 ms instead of faer's 1.15 ms on the 12k-tet cantilever's
/// factor (0.54 instead of 0.73 ms on the hammerbot's). Used for `L L^T` only: on the mixed
/// formulation's `L D L^T` factor (hammerbot, pressures eliminated last) it was slower than
/// faer's (1.95 against 1.6 ms).
struct SolveSplit {
    /// Supernodes of each group, and of the top, ascending (children before parents).
    groups: [Vec<usize>; 2],
    top: Vec<usize>,
    /// Unknowns (in elimination order) of group 1's supernodes, and of the top's.
    second_rows: Vec<usize>,
    top_rows: Vec<usize>,
}

impl SolveSplit {
    /// Splits off the top of the tree until its subtrees fall into two groups of about equal
    /// factor size (greedy, largest first), keeping the split with the least critical path
    /// `max(group sizes) + top size`. None when that saves under a fifth of the factor.
    fn new(symbolic: &SymbolicSupernodalCholesky<usize>) -> Option<Self> {
        let n_super = symbolic.n_supernodes();
        let (begin, end) = (symbolic.supernode_begin(), symbolic.supernode_end());
        let (value_ptr, row_ptr, rows) = (
            symbolic.col_ptr_for_val(),
            symbolic.col_ptr_for_row_idx(),
            symbolic.row_idx(),
        );
        let mut supernode_of = vec![0usize; symbolic.nrows()];
        for s in 0..n_super {
            supernode_of[begin[s]..end[s]].fill(s);
        }
        let mut children = vec![Vec::new(); n_super];
        let mut roots = Vec::new();
        let mut weight: Vec<f64> = (0..n_super)
            .map(|s| (value_ptr[s + 1] - value_ptr[s]) as f64)
            .collect();
        for s in 0..n_super {
            let m = end[s] - begin[s];
            let below = (value_ptr[s + 1] - value_ptr[s]) / m - m;
            if below == 0 {
                roots.push(s);
            } else {
                // The parent is the supernode of the first row below the diagonal block; it
                // comes after s, so the weights accumulate in one ascending pass.
                let parent = supernode_of[rows[row_ptr[s]]];
                children[parent].push(s);
                weight[parent] += weight[s];
            }
        }
        let total: f64 = roots.iter().map(|&r| weight[r]).sum();
        let mut candidates = roots;
        let mut top = Vec::new();
        let mut top_weight = 0.0;
        let mut best: Option<(f64, [Vec<usize>; 2], Vec<usize>)> = None;
        for _ in 0..n_super {
            candidates.sort_by(|a, b| weight[*b].total_cmp(&weight[*a]));
            let mut bins = [(0.0, Vec::new()), (0.0, Vec::new())];
            for &c in &candidates {
                let lighter = usize::from(bins[1].0 < bins[0].0);
                bins[lighter].0 += weight[c];
                bins[lighter].1.push(c);
            }
            let path = bins[0].0.max(bins[1].0) + top_weight;
            if best.as_ref().is_none_or(|b| path < b.0) {
                let [(_, first), (_, second)] = bins;
                best = Some((path, [first, second], top.clone()));
            }
            if top_weight > 0.5 * total {
                break;
            }
            let Some(&heaviest) = candidates.first() else {
                break;
            };
            candidates.remove(0);
            top.push(heaviest);
            top_weight +=
                weight[heaviest] - children[heaviest].iter().map(|&c| weight[c]).sum::<f64>();
            candidates.extend(&children[heaviest]);
        }
        let (path, subtree_roots, mut top) = best.expect("at least one candidate split");
        if path > 0.8 * total {
            return None;
        }
        let groups = subtree_roots.map(|group_roots| {
            let mut members = Vec::new();
            let mut stack = group_roots;
            while let Some(s) = stack.pop() {
                members.push(s);
                stack.extend(&children[s]);
            }
            members.sort_unstable();
            members
        });
        top.sort_unstable();
        let rows_of = |supernodes: &[usize]| -> Vec<usize> {
            supernodes.iter().flat_map(|&s| begin[s]..end[s]).collect()
        };
        Some(SolveSplit {
            second_rows: rows_of(&groups[1]),
            top_rows: rows_of(&top),
            groups,
            top,
        })
    }

    /// `L L^T x = b` for one right-hand side `x` in elimination order.
    fn solve(&self, symbolic: &SymbolicSupernodalCholesky<usize>, values: &[f64], x: &mut [f64]) {
        let factor = SupernodalFactor { symbolic, values };
        // Forward: group 1 works on a copy in which the top's unknowns start at zero, so that
        // they collect its updates to be added to group 0's.
        let mut second = x.to_vec();
        for &r in &self.top_rows {
            second[r] = 0.0;
        }
        rayon::join(
            || factor.forward(&self.groups[0], x),
            || factor.forward(&self.groups[1], &mut second),
        );
        for &r in &self.second_rows {
            x[r] = second[r];
        }
        for &r in &self.top_rows {
            x[r] += second[r];
        }
        factor.forward(&self.top, x);
        factor.backward(&self.top, x);
        second.copy_from_slice(x);
        rayon::join(
            || factor.backward(&self.groups[0], x),
            || factor.backward(&self.groups[1], &mut second),
        );
        for &r in &self.second_rows {
            x[r] = second[r];
        }
    }
}

/// A numeric supernodal Cholesky factor. Each supernode's values are a column-major block: its
/// `m` diagonal columns over the rows below them (its pattern).
struct SupernodalFactor<'a> {
    symbolic: &'a SymbolicSupernodalCholesky<usize>,
    values: &'a [f64],
}

impl SupernodalFactor<'_> {
    /// `(first unknown, width m, block height, block, pattern)` of supernode `s`.
    fn block(&self, s: usize) -> (usize, usize, usize, &[f64], &[usize]) {
        let sym = self.symbolic;
        let (start, end) = (sym.supernode_begin()[s], sym.supernode_end()[s]);
        let m = end - start;
        let block = &self.values[sym.col_ptr_for_val()[s]..sym.col_ptr_for_val()[s + 1]];
        let height = block.len() / m;
        let row_start = sym.col_ptr_for_row_idx()[s];
        let pattern = &sym.row_idx()[row_start..row_start + height - m];
        (start, m, height, block, pattern)
    }

    /// `x <- L^{-1} x` over the given supernodes (ascending).
    fn forward(&self, supernodes: &[usize], x: &mut [f64]) {
        let mut below = Vec::new();
        for &s in supernodes {
            let (start, m, height, block, pattern) = self.block(s);
            below.clear();
            below.resize(pattern.len(), 0.0);
            if m >= WIDE_SUPERNODE {
                let l = MatRef::from_column_major_slice(block, height, m);
                let (diagonal, lower) = l.split_at_row(m);
                let mut top = MatMut::from_column_major_slice_mut(&mut x[start..start + m], m, 1);
                solve_lower_triangular_in_place(diagonal, top.rb_mut(), Par::Seq);
                let below_mat = MatMut::from_column_major_slice_mut(&mut below, height - m, 1);
                matmul(below_mat, Accum::Replace, lower, top.rb(), 1.0, Par::Seq);
            } else {
                for j in 0..m {
                    let column = &block[j * height..(j + 1) * height];
                    let xj = x[start + j] / column[j];
                    x[start + j] = xj;
                    for (xi, l) in x[start + j + 1..start + m]
                        .iter_mut()
                        .zip(&column[j + 1..m])
                    {
                        *xi -= l * xj;
                    }
                    for (acc, l) in below.iter_mut().zip(&column[m..]) {
                        *acc += l * xj;
                    }
                }
            }
            for (&row, acc) in pattern.iter().zip(&below) {
                x[row] -= acc;
            }
        }
    }

    /// `x <- L^{-T} x` over the given supernodes (visited descending).
    fn backward(&self, supernodes: &[usize], x: &mut [f64]) {
        let mut below = Vec::new();
        for &s in supernodes.iter().rev() {
            let (start, m, height, block, pattern) = self.block(s);
            below.clear();
            below.extend(pattern.iter().map(|&row| x[row]));
            if m >= WIDE_SUPERNODE {
                let l = MatRef::from_column_major_slice(block, height, m);
                let (diagonal, lower) = l.split_at_row(m);
                let mut top = MatMut::from_column_major_slice_mut(&mut x[start..start + m], m, 1);
                let below_mat = MatRef::from_column_major_slice(&below, height - m, 1);
                matmul(
                    top.rb_mut(),
                    Accum::Add,
                    lower.transpose(),
                    below_mat,
                    -1.0,
                    Par::Seq,
                );
                solve_upper_triangular_in_place(diagonal.transpose(), top, Par::Seq);
            } else {
                for j in (0..m).rev() {
                    let column = &block[j * height..(j + 1) * height];
                    let mut xj = x[start + j] - dot(&column[m..], &below);
                    xj -= dot(&column[j + 1..m], &x[start + j + 1..start + m]);
                    x[start + j] = xj / column[j];
                }
            }
        }
    }
}

/// Supernodes at least this wide go through faer's dense kernels (vectorised for the running
/// CPU); narrower ones through plain loops, which skip the kernels' dispatch.
const WIDE_SUPERNODE: usize = 8;

/// `a . b` with eight partial sums, so that it vectorises.
fn dot(a: &[f64], b: &[f64]) -> f64 {
    let mut partial = [0.0; 8];
    let (a_chunks, b_chunks) = (a.chunks_exact(8), b.chunks_exact(8));
    let tail: f64 = a_chunks
        .remainder()
        .iter()
        .zip(b_chunks.remainder())
        .map(|(x, y)| x * y)
        .sum();
    for (x, y) in a_chunks.zip(b_chunks) {
        for k in 0..8 {
            partial[k] += x[k] * y[k];
        }
    }
    partial.iter().sum::<f64>() + tail
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
mod tests {
    use super::*;

    /// The Laplacian of a `dims[0] x dims[1] x dims[2]` grid (nearest neighbours: -1; diagonal:
    /// 2 per dimension longer than one, plus `shift`).
    fn grid_laplacian(dims: [usize; 3], shift: f64) -> (LowerPattern, Vec<f64>) {
        let n = dims.iter().product();
        let index = |i: usize, j: usize, l: usize| (i * dims[1] + j) * dims[2] + l;
        let diagonal = 2.0 * dims.iter().filter(|&&d| d > 1).count() as f64 + shift;
        let mut col_ptr = vec![0];
        let mut row_idx = Vec::new();
        let mut values = Vec::new();
        for i in 0..dims[0] {
            for j in 0..dims[1] {
                for l in 0..dims[2] {
                    let mut entries = vec![(index(i, j, l), diagonal)];
                    for (di, dj, dl) in [(1, 0, 0), (0, 1, 0), (0, 0, 1)] {
                        if i + di < dims[0] && j + dj < dims[1] && l + dl < dims[2] {
                            entries.push((index(i + di, j + dj, l + dl), -1.0));
                        }
                    }
                    entries.sort_by_key(|e| e.0);
                    for (r, v) in entries {
                        row_idx.push(r);
                        values.push(v);
                    }
                    col_ptr.push(row_idx.len());
                }
            }
        }
        (
            LowerPattern {
                n,
                col_ptr,
                row_idx,
            },
            values,
        )
    }

    /// `max |a - b|`.
    fn max_difference(a: &[f64], b: &[f64]) -> f64 {
        a.iter()
            .zip(b)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f64::max)
    }

    #[test]
    fn llt_solves_and_detects_indefinite() {
        let (p, v) = grid_laplacian([50, 1, 1], 0.0);
        let mut f = SparseFactor::analyse(&p, FactorKind::Llt).unwrap();
        assert!(f.factor(&p, &v).unwrap());
        let x: Vec<f64> = (0..50).map(|i| (i as f64).sin()).collect();
        let mut b = p.symmetric_matvec(&v, &x);
        f.solve_in_place(&mut b);
        let err = max_difference(&b, &x);
        assert!(err < 1e-10, "{err}");
        let (_, v_indef) = grid_laplacian([50, 1, 1], -3.0);
        assert!(!f.factor(&p, &v_indef).unwrap());
    }

    #[test]
    fn split_supernodal_solves_match_the_matrix() {
        // 14^3 unknowns: a supernodal factor whose solves are split between two threads.
        let (p, v) = grid_laplacian([14, 14, 14], 0.1);
        let mut f = SparseFactor::analyse(&p, FactorKind::Llt).unwrap();
        let split = f.split.as_ref().expect("a supernodal factor");
        assert!(!split.groups[1].is_empty(), "the solves are split");
        let x: Vec<f64> = (0..p.n).map(|i| (0.37 * i as f64).sin()).collect();
        let b = p.symmetric_matvec(&v, &x);
        assert!(f.factor(&p, &v).unwrap());
        let mut solved = b.clone();
        f.solve_in_place(&mut solved);
        let err = max_difference(&solved, &x);
        assert!(err < 1e-11, "{err}");
    }

    #[test]
    fn ldlt_solves_saddle_point() {
        // [[2, 1], [1, -1e-8]]
        let p = LowerPattern {
            n: 2,
            col_ptr: vec![0, 2, 3],
            row_idx: vec![0, 1, 1],
        };
        let v = vec![2.0, 1.0, -1e-8];
        let mut f = SparseFactor::analyse(&p, FactorKind::Ldlt).unwrap();
        assert!(f.factor(&p, &v).unwrap());
        let x = [0.3, -0.7];
        let mut b = p.symmetric_matvec(&v, &x);
        f.solve_in_place(&mut b);
        assert!(
            (b[0] - x[0]).abs() < 1e-9 && (b[1] - x[1]).abs() < 1e-9,
            "{b:?}"
        );
    }
}
