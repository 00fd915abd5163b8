//! Triangular solves with a supernodal Cholesky factor, split between two threads, in double
//! or single precision.

use faer::linalg::matmul::matmul;
use faer::linalg::triangular_solve::{
    solve_lower_triangular_in_place, solve_upper_triangular_in_place,
};
use faer::reborrow::{Reborrow, ReborrowMut};
use faer::sparse::linalg::cholesky::supernodal::SymbolicSupernodalCholesky;
use faer::{Accum, MatMut, MatRef, Par};

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
pub(super) struct SolveSplit {
    /// Supernodes of each group, and of the top, ascending (children before parents).
    pub(super) groups: [Vec<usize>; 2],
    top: Vec<usize>,
    /// Unknowns (in elimination order) of group 1's supernodes, and of the top's.
    second_rows: Vec<usize>,
    top_rows: Vec<usize>,
}

impl SolveSplit {
    /// Splits off the top of the tree until its subtrees fall into two groups of about equal
    /// factor size (greedy, largest first), keeping the split with the least critical path
    /// `max(group sizes) + top size`. None when that saves under a fifth of the factor.
    pub(super) fn new(symbolic: &SymbolicSupernodalCholesky<usize>) -> Option<Self> {
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
    pub(super) fn solve<T: FactorScalar>(
        &self,
        symbolic: &SymbolicSupernodalCholesky<usize>,
        values: &[T],
        x: &mut [T],
    ) {
        let factor = SupernodalFactor { symbolic, values };
        // Forward: group 1 works on a copy in which the top's unknowns start at zero, so that
        // they collect its updates to be added to group 0's.
        let mut second = x.to_vec();
        for &r in &self.top_rows {
            second[r] = T::zero();
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
struct SupernodalFactor<'a, T> {
    symbolic: &'a SymbolicSupernodalCholesky<usize>,
    values: &'a [T],
}

/// The precisions a factor is stored in.
pub(super) trait FactorScalar: faer::traits::RealField + Copy + Send + Sync {}
impl FactorScalar for f64 {}
impl FactorScalar for f32 {}

impl<T: FactorScalar> SupernodalFactor<'_, T> {
    /// `(first unknown, width m, block height, block, pattern)` of supernode `s`.
    fn block(&self, s: usize) -> (usize, usize, usize, &[T], &[usize]) {
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
    fn forward(&self, supernodes: &[usize], x: &mut [T]) {
        let mut below = Vec::new();
        for &s in supernodes {
            let (start, m, height, block, pattern) = self.block(s);
            below.clear();
            below.resize(pattern.len(), T::zero());
            if m >= WIDE_SUPERNODE {
                let l = MatRef::from_column_major_slice(block, height, m);
                let (diagonal, lower) = l.split_at_row(m);
                let mut top = MatMut::from_column_major_slice_mut(&mut x[start..start + m], m, 1);
                solve_lower_triangular_in_place(diagonal, top.rb_mut(), Par::Seq);
                let below_mat = MatMut::from_column_major_slice_mut(&mut below, height - m, 1);
                matmul(
                    below_mat,
                    Accum::Replace,
                    lower,
                    top.rb(),
                    T::one(),
                    Par::Seq,
                );
            } else {
                for j in 0..m {
                    let column = &block[j * height..(j + 1) * height];
                    let xj = x[start + j] / column[j];
                    x[start + j] = xj;
                    for (xi, &l) in x[start + j + 1..start + m]
                        .iter_mut()
                        .zip(&column[j + 1..m])
                    {
                        *xi -= l * xj;
                    }
                    for (acc, &l) in below.iter_mut().zip(&column[m..]) {
                        *acc += l * xj;
                    }
                }
            }
            for (&row, &acc) in pattern.iter().zip(&below) {
                x[row] -= acc;
            }
        }
    }

    /// `x <- L^{-T} x` over the given supernodes (visited descending).
    fn backward(&self, supernodes: &[usize], x: &mut [T]) {
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
                    -T::one(),
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
fn dot<T: FactorScalar>(a: &[T], b: &[T]) -> T {
    let mut partial = [T::zero(); 8];
    let (a_chunks, b_chunks) = (a.chunks_exact(8), b.chunks_exact(8));
    let mut tail = T::zero();
    for (&x, &y) in a_chunks.remainder().iter().zip(b_chunks.remainder()) {
        tail += x * y;
    }
    for (x, y) in a_chunks.zip(b_chunks) {
        for k in 0..8 {
            partial[k] += x[k] * y[k];
        }
    }
    partial.iter().fold(T::zero(), |sum, &p| sum + p) + tail
}
