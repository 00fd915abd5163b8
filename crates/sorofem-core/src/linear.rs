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
pub struct SparseFactor {
    symbolic: SymbolicCholesky<usize>,
    values: Vec<f64>,
    stored: Stored,
    /// Expected pivot signs for LDL^T: +1 for displacement rows, -1 for pressure rows.
    signs: Vec<i8>,
}

impl SparseFactor {
    /// Symbolic analysis with an approximate-minimum-degree ordering.
    pub fn analyse(pattern: &LowerPattern) -> Result<Self> {
        let symbolic = factorize_symbolic_cholesky(
            pattern.symbolic(),
            Side::Lower,
            SymmetricOrdering::Amd,
            Default::default(),
        )
        .map_err(|e| Error::LinearSolver {
            message: format!("symbolic analysis failed: {e:?}"),
        })?;
        let values = vec![0.0; symbolic.len_val()];
        Ok(SparseFactor {
            symbolic,
            values,
            stored: Stored::None,
            signs: Vec::new(),
        })
    }

    /// Number of stored values in the factor (a measure of fill-in and memory).
    pub fn factor_nnz(&self) -> usize {
        self.values.len()
    }

    /// Numeric `L L^T`. Returns `Ok(false)` when the matrix is not numerically positive definite.
    pub fn factor_llt(&mut self, pattern: &LowerPattern, values: &[f64]) -> Result<bool> {
        let par = faer::get_global_parallelism();
        let mat = SparseColMatRef::new(pattern.symbolic(), values);
        let req = self
            .symbolic
            .factorize_numeric_llt_scratch::<f64>(par, Default::default());
        let mut mem = MemBuffer::try_new(req).map_err(|_| oom())?;
        let result = self.symbolic.factorize_numeric_llt::<f64>(
            &mut self.values,
            mat,
            Side::Lower,
            LltRegularization::default(),
            par,
            MemStack::new(&mut mem),
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

    /// Numeric `L D L^T` of a quasi-definite matrix whose first `n_positive` unknowns have
    /// positive pivots and the rest negative ones. Tiny pivots of the wrong sign are regularised
    /// (by `delta`, relative to the matrix scale) rather than failing.
    pub fn factor_ldlt(
        &mut self,
        pattern: &LowerPattern,
        values: &[f64],
        n_positive: usize,
    ) -> Result<()> {
        let par = faer::get_global_parallelism();
        if self.signs.len() != pattern.n {
            self.signs = (0..pattern.n)
                .map(|i| if i < n_positive { 1 } else { -1 })
                .collect();
        }
        let scale = values.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let mat = SparseColMatRef::new(pattern.symbolic(), values);
        let req = self
            .symbolic
            .factorize_numeric_ldlt_scratch::<f64>(par, Default::default());
        let mut mem = MemBuffer::try_new(req).map_err(|_| oom())?;
        let regularization = LdltRegularization {
            dynamic_regularization_signs: Some(&self.signs),
            dynamic_regularization_delta: scale * 1e-14,
            dynamic_regularization_epsilon: scale * 1e-20,
        };
        self.symbolic
            .factorize_numeric_ldlt::<f64>(
                &mut self.values,
                mat,
                Side::Lower,
                regularization,
                par,
                MemStack::new(&mut mem),
                Default::default(),
            )
            .map_err(|e| Error::LinearSolver {
                message: format!("LDL^T failed: {e:?}"),
            })?;
        self.stored = Stored::Ldlt;
        Ok(())
    }

    /// Solves `A x = rhs` in place with the stored factorisation.
    pub fn solve_in_place(&self, rhs: &mut [f64]) {
        let par = faer::get_global_parallelism();
        let n = rhs.len();
        let req = self.symbolic.solve_in_place_scratch::<f64>(1, par);
        let mut mem = MemBuffer::new(req);
        let rhs_mat = MatMut::from_column_major_slice_mut(rhs, n, 1);
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
        f.factor_ldlt(&p, &v, 1).unwrap();
        let x = [0.3, -0.7];
        let mut b = p.symmetric_matvec(&v, &x);
        f.solve_in_place(&mut b);
        assert!(
            (b[0] - x[0]).abs() < 1e-9 && (b[1] - x[1]).abs() < 1e-9,
            "{b:?}"
        );
    }
}
