//! The one global loop over elements. Element kernels run in parallel (rayon) into a per-element
//! buffer; the lower triangle of the sparse Hessian is then gathered from it in parallel, each
//! stored entry summing its element contributions in element order through lists computed once,
//! when the assembler is built (deterministic, no atomics). The gradient and energy sums are
//! serial (12 values per element, cheap).
//!
//! DOFs are "full" (all `3 n` displacements plus any extra unknowns such as pressures) or "free"
//! (the full DOFs minus the fixed ones, in increasing order); the Newton unknowns are the free ones.

use crate::energy::{HessianMode, Term};
use crate::linear::LowerPattern;
use rayon::prelude::*;

const FIXED: u32 = u32::MAX;

/// Sparsity pattern and scatter maps for a fixed list of terms with a fixed set of free DOFs.
pub struct Assembler {
    n_full: usize,
    free_of_full: Vec<u32>,
    full_of_free: Vec<usize>,
    pattern: LowerPattern,
    /// Per term: free index of each local DOF (`n_el * s`, FIXED when eliminated).
    local_free: Vec<Vec<u32>>,
    /// Per term: for each stored Hessian entry `p`, the local Hessian entries that add into it,
    /// `gather_index[gather_ptr[p]..gather_ptr[p + 1]]`, each the offset of element `e`'s entry
    /// `(a, b)` in the per-element buffer, `e (1 + s + s^2) + 1 + s + a s + b`, in
    /// increasing element order.
    gather: Vec<Gather>,
}

/// Compressed lists of element-Hessian entries per stored Hessian entry.
struct Gather {
    ptr: Vec<u32>,
    index: Vec<u32>,
}

/// Energy (J), reduced gradient (free DOFs) and optionally the Hessian's lower-triangle values.
pub struct Evaluation {
    pub energy: f64,
    pub gradient: Vec<f64>,
    pub hessian: Vec<f64>,
}

impl Assembler {
    /// Builds the pattern of the Hessian of `terms` restricted to the DOFs with `fixed[d] == false`.
    /// Later evaluations must pass terms with the same structure, in the same order.
    pub fn new(fixed: &[bool], terms: &[&dyn Term]) -> Self {
        let n_full = fixed.len();
        let mut free_of_full = vec![FIXED; n_full];
        let mut full_of_free = Vec::new();
        for d in 0..n_full {
            if !fixed[d] {
                free_of_full[d] = full_of_free.len() as u32;
                full_of_free.push(d);
            }
        }
        let n_free = full_of_free.len();
        let local_free: Vec<Vec<u32>> = terms
            .iter()
            .map(|term| {
                let s = term.stencil_size();
                let mut out = vec![FIXED; term.n_elements() * s];
                out.par_chunks_mut(s).enumerate().for_each_init(
                    || vec![0usize; s],
                    |dofs, (e, chunk)| {
                        term.element_dofs(e, dofs);
                        for (slot, &d) in chunk.iter_mut().zip(dofs.iter()) {
                            *slot = free_of_full[d];
                        }
                    },
                );
                out
            })
            .collect();

        let mut columns: Vec<Vec<u32>> = vec![Vec::new(); n_free];
        for (term, free) in terms.iter().zip(&local_free) {
            if term.is_linear() {
                continue;
            }
            let s = term.stencil_size();
            for element in free.chunks(s) {
                for &r in element {
                    for &c in element {
                        if r != FIXED && c != FIXED && r >= c {
                            columns[c as usize].push(r);
                        }
                    }
                }
            }
        }
        let mut col_ptr = Vec::with_capacity(n_free + 1);
        let mut row_idx = Vec::new();
        col_ptr.push(0);
        for (c, mut rows) in columns.into_iter().enumerate() {
            rows.push(c as u32); // keep every diagonal, even of DOFs no term touches
            rows.sort_unstable();
            rows.dedup();
            row_idx.extend(rows.into_iter().map(|r| r as usize));
            col_ptr.push(row_idx.len());
        }
        let pattern = LowerPattern {
            n: n_free,
            col_ptr,
            row_idx,
        };

        let gather = terms
            .iter()
            .zip(&local_free)
            .map(|(term, free)| {
                if term.is_linear() {
                    return Gather {
                        ptr: vec![0; pattern.nnz() + 1],
                        index: Vec::new(),
                    };
                }
                let s = term.stencil_size();
                // Counting sort of (position, local entry) pairs by position keeps each list in
                // element order.
                let positions: Vec<u32> = free
                    .par_chunks(s)
                    .flat_map_iter(|element| {
                        let pattern = &pattern;
                        (0..s * s).map(move |ab| {
                            let (r, c) = (element[ab / s], element[ab % s]);
                            if r != FIXED && c != FIXED && r >= c {
                                pattern
                                    .position(r as usize, c as usize)
                                    .expect("pair in pattern")
                                    as u32
                            } else {
                                FIXED
                            }
                        })
                    })
                    .collect();
                assert!(
                    positions.len() < FIXED as usize,
                    "element Hessian entries exceed u32 indexing"
                );
                let mut ptr = vec![0u32; pattern.nnz() + 1];
                for &p in &positions {
                    if p != FIXED {
                        ptr[p as usize + 1] += 1;
                    }
                }
                for k in 0..pattern.nnz() {
                    ptr[k + 1] += ptr[k];
                }
                let mut next = ptr.clone();
                let mut index = vec![0u32; ptr[pattern.nnz()] as usize];
                // Store where the entry sits in the per-element buffer of an evaluation with a
                // Hessian (energy, s gradient values, s * s Hessian values per element): a
                // division per gathered entry would cost as much as the whole gather.
                let stride = 1 + s + s * s;
                assert!(
                    term.n_elements() * stride < FIXED as usize,
                    "per-element buffer exceeds u32 indexing"
                );
                for (local, &p) in positions.iter().enumerate() {
                    if p != FIXED {
                        let (e, ab) = (local / (s * s), local % (s * s));
                        index[next[p as usize] as usize] = (e * stride + 1 + s + ab) as u32;
                        next[p as usize] += 1;
                    }
                }
                Gather { ptr, index }
            })
            .collect();
        Assembler {
            n_full,
            free_of_full,
            full_of_free,
            pattern,
            local_free,
            gather,
        }
    }

    pub fn n_full(&self) -> usize {
        self.n_full
    }

    pub fn n_free(&self) -> usize {
        self.full_of_free.len()
    }

    pub fn pattern(&self) -> &LowerPattern {
        &self.pattern
    }

    /// Full DOF index of each free DOF.
    pub fn full_of_free(&self) -> &[usize] {
        &self.full_of_free
    }

    /// Free index of a full DOF, `None` when it is fixed.
    pub fn free_of_full(&self, d: usize) -> Option<usize> {
        let f = self.free_of_full[d];
        (f != FIXED).then_some(f as usize)
    }

    /// Total energy of `terms` at the full DOF vector `z`; `+inf` if any element is inverted.
    pub fn energy(&self, terms: &[&dyn Term], z: &[f64]) -> f64 {
        self.evaluate(terms, z, false, None).energy
    }

    /// Energy, reduced gradient and (when `hessian` is `Some(mode)`) the Hessian values in the
    /// order of [`Assembler::pattern`]. Deterministic: the sums are done serially in element order.
    pub fn evaluate(
        &self,
        terms: &[&dyn Term],
        z: &[f64],
        gradient: bool,
        hessian: Option<HessianMode>,
    ) -> Evaluation {
        assert_eq!(z.len(), self.n_full, "full DOF vector length");
        let mut out = Evaluation {
            energy: 0.0,
            gradient: if gradient || hessian.is_some() {
                vec![0.0; self.n_free()]
            } else {
                Vec::new()
            },
            hessian: if hessian.is_some() {
                vec![0.0; self.pattern.nnz()]
            } else {
                Vec::new()
            },
        };
        for (t, term) in terms.iter().enumerate() {
            out.energy += self.add_term(t, *term, z, &mut out, hessian);
            if !out.energy.is_finite() {
                out.energy = f64::INFINITY;
                return out;
            }
        }
        out
    }

    fn add_term(
        &self,
        t: usize,
        term: &dyn Term,
        z: &[f64],
        out: &mut Evaluation,
        hessian: Option<HessianMode>,
    ) -> f64 {
        let s = term.stencil_size();
        let want_grad = !out.gradient.is_empty();
        let want_hess = hessian.is_some() && !term.is_linear();
        let mode = hessian.unwrap_or(HessianMode::Exact);
        let stride = 1 + if want_grad { s } else { 0 } + if want_hess { s * s } else { 0 };
        let mut work = vec![0.0; term.n_elements() * stride];
        work.par_chunks_mut(stride).enumerate().for_each_init(
            || (vec![0usize; s], vec![0.0; s]),
            |(dofs, local), (e, slot)| {
                term.element_dofs(e, dofs);
                for (v, &d) in local.iter_mut().zip(dofs.iter()) {
                    *v = z[d];
                }
                let (energy, rest) = slot.split_first_mut().expect("stride >= 1");
                let (grad, hess) = rest.split_at_mut(if want_grad { s } else { 0 });
                *energy = term.element(
                    e,
                    local,
                    want_grad.then_some(grad),
                    want_hess.then_some(hess),
                    mode,
                );
            },
        );
        let free = &self.local_free[t];
        let mut energy = 0.0;
        for (e, slot) in work.chunks(stride).enumerate() {
            energy += slot[0];
            if !energy.is_finite() {
                return f64::INFINITY;
            }
            if want_grad {
                for a in 0..s {
                    let f = free[e * s + a];
                    if f != FIXED {
                        out.gradient[f as usize] += slot[1 + a];
                    }
                }
            }
        }
        if want_hess {
            let gather = &self.gather[t];
            debug_assert_eq!(
                stride,
                1 + s + s * s,
                "the gather offsets assume this layout"
            );
            out.hessian
                .par_chunks_mut(4096)
                .enumerate()
                .for_each(|(chunk, values)| {
                    let first = chunk * 4096;
                    for (k, value) in values.iter_mut().enumerate() {
                        let p = first + k;
                        let range = gather.ptr[p] as usize..gather.ptr[p + 1] as usize;
                        let sum: f64 = gather.index[range]
                            .iter()
                            .map(|&offset| work[offset as usize])
                            .sum();
                        *value += sum;
                    }
                });
        }
        energy
    }

    /// Gradient of `terms` with respect to every full DOF, fixed ones included (N): the internal
    /// forces, from which reactions at supports follow. Serial; meant for post-processing.
    pub fn full_gradient(&self, terms: &[&dyn Term], z: &[f64]) -> Vec<f64> {
        let mut out = vec![0.0; self.n_full];
        for term in terms {
            let s = term.stencil_size();
            let mut dofs = vec![0usize; s];
            let mut local = vec![0.0; s];
            let mut grad = vec![0.0; s];
            for e in 0..term.n_elements() {
                term.element_dofs(e, &mut dofs);
                for (v, &d) in local.iter_mut().zip(&dofs) {
                    *v = z[d];
                }
                term.element(e, &local, Some(&mut grad), None, HessianMode::Exact);
                for (g, &d) in grad.iter().zip(&dofs) {
                    out[d] += g;
                }
            }
        }
        out
    }

    /// The external forces (N, full DOFs) of linear terms: minus their gradient.
    pub fn load_vector(&self, terms: &[&dyn Term]) -> Vec<f64> {
        debug_assert!(terms.iter().all(|t| t.is_linear()));
        self.full_gradient(terms, &vec![0.0; self.n_full])
            .into_iter()
            .map(|g| -g)
            .collect()
    }
}
