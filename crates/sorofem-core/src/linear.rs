//! Sparse symmetric factorisations: the symbolic analysis (fill-reducing ordering, elimination
//! tree, supernodes) is done once per sparsity pattern; each Newton step only refactors numerically.

use crate::error::{Error, Result};
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::ldlt::factor::LdltRegularization;
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, LdltRef, LltRef, SymbolicCholesky, SymmetricOrdering,
};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Conj, MatMut, Side};

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

/// A reusable sparse Cholesky (`L L^T`, for positive definite systems) or `L D L^T` (for
/// quasi-definite saddle-point systems `[[A, B^T], [B, -C]]`, A and C positive definite).
///
/// The matrix is handed to faer already in elimination order: the permuted lower pattern and a
/// map from each stored entry to its permuted slot are computed once, so each factorisation
/// copies the values through that map instead of having faer permute (and re-sort) the whole
/// matrix every time (5 % of a hammerbot solve's profile).
pub struct SparseFactor {
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
}

impl SparseFactor {
    /// Symbolic analysis with an approximate-minimum-degree ordering.
    pub fn analyse(pattern: &LowerPattern) -> Result<Self> {
        Self::analyse_with_order(pattern, &amd_order(pattern)?)
    }

    /// Symbolic analysis with a given elimination order: `order[k]` is the unknown eliminated
    /// k-th. Saddle-point systems need one that eliminates each pressure after the displacements
    /// it couples to, so that no pivot is the (tiny) compliance alone.
    pub fn analyse_with_order(pattern: &LowerPattern, order: &[usize]) -> Result<Self> {
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
        Ok(SparseFactor {
            values: vec![0.0; symbolic.len_val()],
            symbolic,
            stored: Stored::None,
            scratch: None,
            order: order.to_vec(),
            permuted_values: vec![0.0; permuted.nnz()],
            permuted,
            slot,
        })
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

    /// Whether the numeric factorisation runs on one thread (leaving the other cores free).
    pub fn is_sequential(&self) -> bool {
        matches!(self.parallelism(), faer::Par::Seq)
    }

    /// Number of stored values in the factor (a measure of fill-in and memory).
    pub fn factor_nnz(&self) -> usize {
        self.values.len()
    }

    /// Numeric `L L^T`. Returns `Ok(false)` when the matrix is not numerically positive definite.
    pub fn factor_llt(&mut self, pattern: &LowerPattern, values: &[f64]) -> Result<bool> {
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
    pub fn factor_ldlt(&mut self, pattern: &LowerPattern, values: &[f64]) -> Result<bool> {
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
        let par = self.parallelism();
        let n = rhs.len();
        let req = self.symbolic.solve_in_place_scratch::<f64>(1, par);
        let mut mem = MemBuffer::new(req);
        let mut permuted: Vec<f64> = self.order.iter().map(|&i| rhs[i]).collect();
        let rhs_mat = MatMut::from_column_major_slice_mut(&mut permuted, n, 1);
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
        for (&i, &v) in self.order.iter().zip(&permuted) {
            rhs[i] = v;
        }
    }
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

    fn laplacian_1d(n: usize, shift: f64) -> (LowerPattern, Vec<f64>) {
        let mut col_ptr = vec![0];
        let mut row_idx = Vec::new();
        let mut values = Vec::new();
        for c in 0..n {
            row_idx.push(c);
            values.push(2.0 + shift);
            if c + 1 < n {
                row_idx.push(c + 1);
                values.push(-1.0);
            }
            col_ptr.push(row_idx.len());
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

    #[test]
    fn llt_solves_and_detects_indefinite() {
        let (p, v) = laplacian_1d(50, 0.0);
        let mut f = SparseFactor::analyse(&p).unwrap();
        assert!(f.factor_llt(&p, &v).unwrap());
        let x: Vec<f64> = (0..50).map(|i| (i as f64).sin()).collect();
        let mut b = p.symmetric_matvec(&v, &x);
        f.solve_in_place(&mut b);
        let err = b
            .iter()
            .zip(&x)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(err < 1e-10, "{err}");
        let (_, v_indef) = laplacian_1d(50, -3.0);
        assert!(!f.factor_llt(&p, &v_indef).unwrap());
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
        let mut f = SparseFactor::analyse(&p).unwrap();
        assert!(f.factor_ldlt(&p, &v).unwrap());
        let x = [0.3, -0.7];
        let mut b = p.symmetric_matvec(&v, &x);
        f.solve_in_place(&mut b);
        assert!(
            (b[0] - x[0]).abs() < 1e-9 && (b[1] - x[1]).abs() < 1e-9,
            "{b:?}"
        );
    }
}
