//! The one global loop over elements. Element kernels run in parallel (rayon) and add their
//! gradient and Hessian straight into the global arrays, through positions computed once when
//! the assembler is built.
//!
//! Parallel writes without atomics or per-element buffers come from a two-colouring of element
//! chunks: the free DOFs are numbered by breadth-first level sets of the Hessian's graph (from a
//! pseudo-peripheral DOF), every element is filed under the lowest level among its free DOFs, and
//! the elements are cut into chunks of consecutive levels. The free DOFs of one element are
//! pairwise coupled, so they span at most two adjacent levels: chunk `i` touches levels
//! `[L_i, L_{i+1}]` and shares no DOF with chunk `i + 2`. The even chunks run in parallel, then
//! the odd ones. Each stored entry therefore receives its contributions in an order fixed by the
//! mesh and the chunking alone (not by the thread count or scheduling): results are deterministic.
//!
//! This replaced writing every element's values to a buffer and gathering them per entry: that
//! buffer (about 11 MB for the 9k-tet hammerbot, beyond the caches) was refilled right after
//! each factorisation had evicted everything; without it a hammerbot Newton iteration's
//! assembly went from 6.7 to 4.0 ms.
//!
//! DOFs are "full" (all `3 n` displacements plus any extra unknowns such as pressures) or "free"
//! (the full DOFs minus the fixed ones, in increasing order); the Newton unknowns are the free ones.

use crate::energy::{HessianMode, Term};
use crate::linear::LowerPattern;
use rayon::prelude::*;
use std::ops::Range;

const FIXED: u32 = u32::MAX;
/// Flag on a Hessian position: the local pair (a, b), a != b, maps to a diagonal entry and so
/// adds twice (as (a, b) and as (b, a)).
const TWICE: u32 = 1 << 31;
/// Elements are cut into about this many chunks (a constant, so that the summation order, and
/// with it every bit of the result, does not depend on the machine).
const TARGET_CHUNKS: usize = 16;

/// Sparsity pattern and scatter maps for a fixed list of terms with a fixed set of free DOFs.
pub struct Assembler {
    n_full: usize,
    free_of_full: Vec<u32>,
    full_of_free: Vec<usize>,
    pattern: LowerPattern,
    plans: Vec<TermPlan>,
}

/// How one term's elements are visited and where their values go.
struct TermPlan {
    /// Element indices, chunk by chunk, ascending within a chunk.
    order: Vec<u32>,
    /// `chunks[colour]`: ranges of `order`; chunks of one colour share no free DOF.
    chunks: [Vec<Range<usize>>; 2],
    /// Free index of each local DOF, `s` per element in `order` (FIXED when eliminated).
    local_free: Vec<u32>,
    /// Per element in `order`, for each local pair `a >= b` (row-major lower triangle), the
    /// position of the stored entry `(max(r, c), min(r, c))` in the Hessian values, possibly
    /// flagged TWICE; FIXED when either DOF is eliminated. Empty for linear terms.
    positions: Vec<u32>,
    /// Per element in `order`: all positions valid and unflagged (the fast path).
    plain: Vec<bool>,
}

/// Energy (J), reduced gradient (free DOFs) and optionally the Hessian's lower-triangle values.
#[derive(Clone, Default)]
pub struct Evaluation {
    pub energy: f64,
    pub gradient: Vec<f64>,
    pub hessian: Vec<f64>,
}

/// A slice written from several threads at indices that the chunk colouring keeps disjoint.
struct SharedSlice {
    ptr: *mut f64,
    len: usize,
}

// SAFETY: concurrent `add`s only ever target indices owned by one chunk of the running colour
// (see the module docs), so no two threads touch the same element.
unsafe impl Sync for SharedSlice {}
unsafe impl Send for SharedSlice {}

impl SharedSlice {
    fn new(values: &mut [f64]) -> Self {
        SharedSlice {
            ptr: values.as_mut_ptr(),
            len: values.len(),
        }
    }

    /// # Safety
    /// No other thread may access index `i` during the call.
    #[inline(always)]
    unsafe fn add(&self, i: usize, value: f64) {
        assert!(i < self.len);
        *self.ptr.add(i) += value;
    }

    /// # Safety
    /// As [`SharedSlice::add`], and `i` must be in bounds.
    #[inline(always)]
    unsafe fn add_unchecked(&self, i: usize, value: f64) {
        debug_assert!(i < self.len);
        *self.ptr.add(i) += value;
    }
}

/// Breadth-first level of every vertex of the symmetric graph whose lower triangle is `pattern`,
/// from a pseudo-peripheral start in each connected component (levels continue across
/// components). Adjacent vertices differ by at most one level.
fn bfs_levels(pattern: &LowerPattern) -> Vec<u32> {
    let n = pattern.n;
    let mut degree = vec![0usize; n + 1];
    for c in 0..n {
        for &r in &pattern.row_idx[pattern.col_ptr[c]..pattern.col_ptr[c + 1]] {
            if r != c {
                degree[r + 1] += 1;
                degree[c + 1] += 1;
            }
        }
    }
    for v in 0..n {
        degree[v + 1] += degree[v];
    }
    let ptr = degree;
    let mut next = ptr.clone();
    let mut adjacency = vec![0u32; ptr[n]];
    for c in 0..n {
        for &r in &pattern.row_idx[pattern.col_ptr[c]..pattern.col_ptr[c + 1]] {
            if r != c {
                adjacency[next[r]] = c as u32;
                next[r] += 1;
                adjacency[next[c]] = r as u32;
                next[c] += 1;
            }
        }
    }
    const UNSEEN: u32 = u32::MAX;
    let mut level = vec![UNSEEN; n];
    let mut queue = Vec::with_capacity(n);
    // Levels from `start` within its component, starting at `base`; returns the last vertex
    // reached (one of the farthest) and the highest level.
    let sweep = |start: usize, base: u32, level: &mut Vec<u32>, queue: &mut Vec<u32>| {
        queue.clear();
        queue.push(start as u32);
        level[start] = base;
        let mut head = 0;
        while head < queue.len() {
            let v = queue[head] as usize;
            head += 1;
            for &w in &adjacency[ptr[v]..ptr[v + 1]] {
                if level[w as usize] == UNSEEN {
                    level[w as usize] = level[v] + 1;
                    queue.push(w);
                }
            }
        }
        let last = *queue.last().expect("start is queued") as usize;
        (last, level[last], queue.clone())
    };
    let mut base = 0;
    for v in 0..n {
        if level[v] != UNSEEN {
            continue;
        }
        let (far, _, component) = sweep(v, base, &mut level, &mut queue);
        for &w in &component {
            level[w as usize] = UNSEEN;
        }
        let (_, top, _) = sweep(far, base, &mut level, &mut queue);
        base = top + 1;
    }
    level
}

impl Assembler {
    /// Builds the pattern of the Hessian of `terms` restricted to the DOFs with `fixed[d] == false`.
    /// Later evaluations must pass terms with the same structure, in the same order.
    pub fn new(fixed: &[bool], terms: &[&dyn Term]) -> Self {
        Self::new_with(fixed, terms, |_| ()).0
    }

    /// [`Assembler::new`], running `analyse` on the finished pattern (e.g. the symbolic
    /// factorisation, single-threaded) at the same time as the element plans are built.
    pub fn new_with<T: Send>(
        fixed: &[bool],
        terms: &[&dyn Term],
        analyse: impl FnOnce(&LowerPattern) -> T + Send,
    ) -> (Self, T) {
        let n_full = fixed.len();
        let (free_of_full, full_of_free) = free_numbering(fixed);
        let local_free = local_free_indices(terms, &free_of_full);
        let pattern = lower_pattern(full_of_free.len(), terms, &local_free);
        let (analysis, plans) = rayon::join(
            || analyse(&pattern),
            || {
                let level = bfs_levels(&pattern);
                terms
                    .iter()
                    .zip(local_free)
                    .map(|(term, free)| TermPlan::new(*term, free, &pattern, &level))
                    .collect()
            },
        );
        (
            Assembler {
                n_full,
                free_of_full,
                full_of_free,
                pattern,
                plans,
            },
            analysis,
        )
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

    /// Adds the entries `(row, col)` (free indices, `row >= col`) missing from the pattern: the
    /// couplings of stencils no term declares (self-contact between distant surface points).
    /// The element plans keep their order and colouring (those follow the DOFs, not the stored
    /// positions) and only their positions are renumbered. Returns whether the pattern grew:
    /// Hessian values and factorisations of the old pattern are then stale.
    pub fn add_entries(&mut self, entries: &[(usize, usize)]) -> bool {
        let mut extra: Vec<(usize, usize)> = entries
            .iter()
            .filter(|&&(r, c)| self.pattern.position(r, c).is_none())
            .map(|&(r, c)| (c, r))
            .collect();
        if extra.is_empty() {
            return false;
        }
        extra.sort_unstable();
        extra.dedup();
        let old = &self.pattern;
        let mut col_ptr = Vec::with_capacity(old.n + 1);
        let mut row_idx = Vec::with_capacity(old.nnz() + extra.len());
        let mut moved = vec![0u32; old.nnz()];
        let mut next_extra = extra.iter().peekable();
        col_ptr.push(0);
        for c in 0..old.n {
            let mut added: Vec<usize> = Vec::new();
            while let Some(&&(col, row)) = next_extra.peek() {
                if col != c {
                    break;
                }
                added.push(row);
                next_extra.next();
            }
            let rows = old.col_ptr[c]..old.col_ptr[c + 1];
            let (mut i, mut j) = (rows.start, 0);
            while i < rows.end || j < added.len() {
                if j == added.len() || (i < rows.end && old.row_idx[i] < added[j]) {
                    moved[i] = row_idx.len() as u32;
                    row_idx.push(old.row_idx[i]);
                    i += 1;
                } else {
                    row_idx.push(added[j]);
                    j += 1;
                }
            }
            col_ptr.push(row_idx.len());
        }
        assert!(
            row_idx.len() < TWICE as usize,
            "Hessian entries exceed 31-bit indexing"
        );
        for plan in &mut self.plans {
            for p in plan.positions.iter_mut().filter(|p| **p != FIXED) {
                *p = moved[(*p & !TWICE) as usize] | (*p & TWICE);
            }
        }
        self.pattern = LowerPattern {
            n: old.n,
            col_ptr,
            row_idx,
        };
        true
    }

    /// Total energy of `terms` at the full DOF vector `z`; `+inf` if any element is inverted.
    pub fn energy(&self, terms: &[&dyn Term], z: &[f64]) -> f64 {
        self.evaluate(terms, z, false, None).energy
    }

    /// Energy, reduced gradient (empty unless `gradient`) and (when `hessian` is `Some(mode)`)
    /// the Hessian values in the order of [`Assembler::pattern`]. Deterministic: every sum runs
    /// in an order fixed when the assembler was built.
    pub fn evaluate(
        &self,
        terms: &[&dyn Term],
        z: &[f64],
        gradient: bool,
        hessian: Option<HessianMode>,
    ) -> Evaluation {
        let mut out = Evaluation::default();
        self.evaluate_into(terms, z, gradient, hessian, &mut out);
        out
    }

    /// [`Assembler::evaluate`] into `out`, reusing its arrays: a Newton iteration's Hessian
    /// values take megabytes, which need not be allocated (and page-faulted in) afresh.
    pub fn evaluate_into(
        &self,
        terms: &[&dyn Term],
        z: &[f64],
        gradient: bool,
        hessian: Option<HessianMode>,
        out: &mut Evaluation,
    ) {
        let all = vec![true; terms.len()];
        self.evaluate_selected_into(terms, &all, z, gradient, hessian, out);
    }

    /// [`Assembler::evaluate`] of the terms whose entry in `selected` is true (`terms` still
    /// lists every term of the assembler, in its order): a sum split into parts that are
    /// evaluated at different times.
    pub fn evaluate_selected(
        &self,
        terms: &[&dyn Term],
        selected: &[bool],
        z: &[f64],
        gradient: bool,
        hessian: Option<HessianMode>,
    ) -> Evaluation {
        let mut out = Evaluation::default();
        self.evaluate_selected_into(terms, selected, z, gradient, hessian, &mut out);
        out
    }

    fn evaluate_selected_into(
        &self,
        terms: &[&dyn Term],
        selected: &[bool],
        z: &[f64],
        gradient: bool,
        hessian: Option<HessianMode>,
        out: &mut Evaluation,
    ) {
        assert_eq!(z.len(), self.n_full, "full DOF vector length");
        assert_eq!(terms.len(), self.plans.len(), "terms of the assembler");
        assert_eq!(selected.len(), terms.len(), "one selection per term");
        let zeroed = |values: &mut Vec<f64>, len: usize| {
            values.clear();
            values.resize(len, 0.0);
        };
        out.energy = 0.0;
        zeroed(&mut out.gradient, if gradient { self.n_free() } else { 0 });
        let nnz = if hessian.is_some() {
            self.pattern.nnz()
        } else {
            0
        };
        zeroed(&mut out.hessian, nnz);
        let chosen = (self.plans.iter().zip(terms)).zip(selected);
        for ((plan, term), _) in chosen.filter(|(_, &on)| on) {
            debug_assert_eq!(
                plan.order.len(),
                term.n_elements(),
                "term structure changed"
            );
            out.energy += plan.add_term(*term, z, out, hessian);
            if !out.energy.is_finite() {
                out.energy = f64::INFINITY;
                return;
            }
        }
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

/// The Hessian pattern of `terms` over the DOFs with `fixed[d] == false`, as
/// [`Assembler::pattern`] would give it, without the element plans.
pub fn pattern_of(fixed: &[bool], terms: &[&dyn Term]) -> LowerPattern {
    let (free_of_full, full_of_free) = free_numbering(fixed);
    lower_pattern(
        full_of_free.len(),
        terms,
        &local_free_indices(terms, &free_of_full),
    )
}

/// Free index of every full DOF (FIXED when fixed) and full index of every free DOF.
fn free_numbering(fixed: &[bool]) -> (Vec<u32>, Vec<usize>) {
    let mut free_of_full = vec![FIXED; fixed.len()];
    let mut full_of_free = Vec::new();
    for (d, &is_fixed) in fixed.iter().enumerate() {
        if !is_fixed {
            free_of_full[d] = full_of_free.len() as u32;
            full_of_free.push(d);
        }
    }
    (free_of_full, full_of_free)
}

/// Per term, the free index of every local DOF, in element order (FIXED when eliminated).
fn local_free_indices(terms: &[&dyn Term], free_of_full: &[u32]) -> Vec<Vec<u32>> {
    terms
        .iter()
        .map(|term| {
            let s = term.stencil_size();
            let mut out = vec![FIXED; term.n_elements() * s];
            out.par_chunks_mut(s.max(1)).enumerate().for_each_init(
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
        .collect()
}

/// The lower triangle of the union of the element couplings of the nonlinear terms, plus every
/// diagonal (even of DOFs no term touches). Built column by column in parallel from a
/// DOF-to-element incidence.
fn lower_pattern(n_free: usize, terms: &[&dyn Term], local_free: &[Vec<u32>]) -> LowerPattern {
    // Incidence: for each free DOF, the (term, element) pairs touching it, as flat element
    // slots `(t, e)` packed into one u64 each.
    let mut count = vec![0usize; n_free + 1];
    for (term, free) in terms.iter().zip(local_free) {
        if term.is_linear() {
            continue;
        }
        for &d in free {
            if d != FIXED {
                count[d as usize + 1] += 1;
            }
        }
    }
    for v in 0..n_free {
        count[v + 1] += count[v];
    }
    let mut next = count.clone();
    let mut incident = vec![(0u32, 0u32); count[n_free]];
    for (t, (term, free)) in terms.iter().zip(local_free).enumerate() {
        if term.is_linear() {
            continue;
        }
        let s = term.stencil_size();
        for (e, element) in free.chunks(s.max(1)).enumerate() {
            for &d in element {
                if d != FIXED {
                    incident[next[d as usize]] = (t as u32, e as u32);
                    next[d as usize] += 1;
                }
            }
        }
    }
    // A per-thread marker (`seen[r] == c` once row r is in column c) drops the repeats (each
    // neighbour shows up in several elements) before the sort, which then sorts a third as much.
    let columns: Vec<Vec<u32>> = (0..n_free)
        .into_par_iter()
        .map_init(
            || vec![u32::MAX; n_free],
            |seen, c| {
                let mut rows = vec![c as u32];
                for &(t, e) in &incident[count[c]..count[c + 1]] {
                    let s = terms[t as usize].stencil_size();
                    let element = &local_free[t as usize][e as usize * s..(e as usize + 1) * s];
                    for &r in element {
                        if r != FIXED && r as usize > c && seen[r as usize] != c as u32 {
                            seen[r as usize] = c as u32;
                            rows.push(r);
                        }
                    }
                }
                rows.sort_unstable();
                rows
            },
        )
        .collect();
    let mut col_ptr = Vec::with_capacity(n_free + 1);
    col_ptr.push(0);
    let mut total = 0;
    for rows in &columns {
        total += rows.len();
        col_ptr.push(total);
    }
    let mut row_idx = Vec::with_capacity(total);
    for rows in columns {
        row_idx.extend(rows.into_iter().map(|r| r as usize));
    }
    LowerPattern {
        n: n_free,
        col_ptr,
        row_idx,
    }
}

impl TermPlan {
    fn new(term: &dyn Term, free: Vec<u32>, pattern: &LowerPattern, level: &[u32]) -> Self {
        let s = term.stencil_size();
        let n_el = term.n_elements();
        // The lowest level of each element's free DOFs; elements without free DOFs (their
        // energy still counts) go to level 0. A term whose elements span more than two
        // adjacent levels (a linear term coupling DOFs the Hessian does not) runs serially.
        let mut element_level = vec![0u32; n_el];
        let mut colourable = true;
        for (e, element) in free.chunks(s.max(1)).enumerate() {
            let levels = element
                .iter()
                .filter(|&&d| d != FIXED)
                .map(|&d| level[d as usize]);
            let (low, high) = levels.fold((u32::MAX, 0), |(lo, hi), l| (lo.min(l), hi.max(l)));
            if low != u32::MAX {
                element_level[e] = low;
                colourable &= high - low <= 1;
            }
        }
        // Chunk boundaries at level boundaries, about n_el / TARGET_CHUNKS elements each.
        let n_levels = element_level.iter().max().map_or(0, |&l| l as usize + 1);
        let mut per_level = vec![0usize; n_levels];
        for &l in &element_level {
            per_level[l as usize] += 1;
        }
        let mut chunk_of_level = vec![0u32; n_levels];
        let target = n_el.div_ceil(TARGET_CHUNKS).max(1);
        let (mut chunk, mut filled) = (0u32, 0usize);
        for (l, &k) in per_level.iter().enumerate() {
            if filled >= target {
                chunk += 1;
                filled = 0;
            }
            chunk_of_level[l] = chunk;
            filled += k;
        }
        let n_chunks = if colourable { chunk as usize + 1 } else { 1 };
        let chunk_of = |e: usize| {
            if colourable {
                chunk_of_level[element_level[e] as usize] as usize
            } else {
                0
            }
        };
        // Stable counting sort of the elements by chunk.
        let mut start = vec![0usize; n_chunks + 1];
        for e in 0..n_el {
            start[chunk_of(e) + 1] += 1;
        }
        for c in 0..n_chunks {
            start[c + 1] += start[c];
        }
        let mut next = start.clone();
        let mut order = vec![0u32; n_el];
        for e in 0..n_el {
            let c = chunk_of(e);
            order[next[c]] = e as u32;
            next[c] += 1;
        }
        let mut chunks = [Vec::new(), Vec::new()];
        for c in 0..n_chunks {
            chunks[c % 2].push(start[c]..start[c + 1]);
        }
        let local_free: Vec<u32> = order
            .iter()
            .flat_map(|&e| free[e as usize * s..(e as usize + 1) * s].iter().copied())
            .collect();
        let positions = if term.is_linear() {
            Vec::new()
        } else {
            assert!(
                pattern.nnz() < TWICE as usize,
                "Hessian entries exceed 31-bit indexing"
            );
            let pairs = s * (s + 1) / 2;
            let mut positions = vec![FIXED; n_el * pairs];
            positions
                .par_chunks_mut(pairs.max(1))
                .zip(local_free.par_chunks(s.max(1)))
                .for_each(|(out, element)| {
                    let mut k = 0;
                    for a in 0..s {
                        for b in 0..=a {
                            let (r, c) = (element[a], element[b]);
                            if r != FIXED && c != FIXED {
                                let (row, col) = (r.max(c) as usize, r.min(c) as usize);
                                let p = pattern.position(row, col).expect("pair in pattern") as u32;
                                out[k] = if a != b && r == c { p | TWICE } else { p };
                            }
                            k += 1;
                        }
                    }
                });
            positions
        };
        let plain = if positions.is_empty() {
            vec![false; n_el]
        } else {
            let pairs = s * (s + 1) / 2;
            positions
                .chunks(pairs.max(1))
                .map(|element| element.iter().all(|&p| p & TWICE == 0))
                .collect()
        };
        TermPlan {
            order,
            chunks,
            local_free,
            positions,
            plain,
        }
    }

    /// Adds this term's gradient and Hessian into `out` and returns its energy.
    fn add_term(
        &self,
        term: &dyn Term,
        z: &[f64],
        out: &mut Evaluation,
        hessian: Option<HessianMode>,
    ) -> f64 {
        let s = term.stencil_size();
        let pairs = s * (s + 1) / 2;
        let want_grad = !out.gradient.is_empty();
        let want_hess = hessian.is_some() && !term.is_linear();
        let mode = hessian.unwrap_or(HessianMode::Exact);
        let gradient = SharedSlice::new(&mut out.gradient);
        let values = SharedSlice::new(&mut out.hessian);
        let run_chunk = |range: &Range<usize>| -> f64 {
            let mut dofs = vec![0usize; s];
            let mut local = vec![0.0; s];
            let mut grad = vec![0.0; s];
            let mut hess = vec![0.0; s * s];
            let mut energy = 0.0;
            for k in range.clone() {
                let e = self.order[k] as usize;
                term.element_dofs(e, &mut dofs);
                for (v, &d) in local.iter_mut().zip(dofs.iter()) {
                    *v = z[d];
                }
                energy += term.element(
                    e,
                    &local,
                    want_grad.then_some(&mut grad[..]),
                    want_hess.then_some(&mut hess[..]),
                    mode,
                );
                if want_grad {
                    for (&f, &g) in self.local_free[k * s..(k + 1) * s].iter().zip(&grad) {
                        if f != FIXED {
                            // SAFETY: DOF f belongs to this chunk's colour class alone.
                            unsafe { gradient.add(f as usize, g) };
                        }
                    }
                }
                if want_hess && self.plain[k] {
                    // No eliminated DOF, no repeated DOF: every pair lands once, unflagged.
                    let positions = &self.positions[k * pairs..(k + 1) * pairs];
                    let mut p = 0;
                    for a in 0..s {
                        for &h in &hess[a * s..a * s + a + 1] {
                            // SAFETY: as for the gradient; positions < nnz by construction.
                            unsafe { values.add_unchecked(positions[p] as usize, h) };
                            p += 1;
                        }
                    }
                } else if want_hess {
                    let positions = &self.positions[k * pairs..(k + 1) * pairs];
                    let mut p = 0;
                    for a in 0..s {
                        let row = &hess[a * s..a * s + a + 1];
                        for &h in row {
                            let position = positions[p];
                            p += 1;
                            if position != FIXED {
                                let twice = position & TWICE != 0;
                                // SAFETY: as for the gradient.
                                unsafe {
                                    values.add(
                                        (position & !TWICE) as usize,
                                        if twice { 2.0 * h } else { h },
                                    )
                                };
                            }
                        }
                    }
                }
            }
            energy
        };
        let mut energy = 0.0;
        for colour in &self.chunks {
            let energies: Vec<f64> = if colour.len() > 1 {
                colour.par_iter().map(run_chunk).collect()
            } else {
                colour.iter().map(run_chunk).collect()
            };
            energy += energies.iter().sum::<f64>();
        }
        energy
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::energy::{ElasticTerm, Formulation};
    use crate::material::Volumetric;
    use crate::mesh::TetMesh;
    use std::collections::HashSet;
    use std::sync::Arc;

    #[test]
    fn chunks_of_one_colour_share_no_free_dof() {
        let mesh = Arc::new(TetMesh::box_mesh([1.0, 0.2, 0.1], [20, 4, 2], [0.0; 3]).unwrap());
        let m = mesh.n_tets();
        let term = ElasticTerm::neo_hookean(
            mesh.clone(),
            &vec![1.0; m],
            &vec![1.0; m],
            Volumetric::Log,
            Formulation::Standard,
        );
        let mut fixed = vec![false; 3 * mesh.n_nodes()];
        fixed[..9].fill(true);
        let assembler = Assembler::new(&fixed, &[&term]);
        let plan = &assembler.plans[0];
        let s = term.stencil_size();
        assert!(
            plan.chunks[0].len() + plan.chunks[1].len() >= 8,
            "too few chunks"
        );
        let mut seen_elements = HashSet::new();
        for colour in &plan.chunks {
            let mut owner = std::collections::HashMap::new();
            for (c, range) in colour.iter().enumerate() {
                for k in range.clone() {
                    assert!(seen_elements.insert(plan.order[k]));
                    for &f in &plan.local_free[k * s..(k + 1) * s] {
                        if f != FIXED {
                            let first = *owner.entry(f).or_insert(c);
                            assert_eq!(first, c, "DOF {f} in two chunks of one colour");
                        }
                    }
                }
            }
        }
        assert_eq!(seen_elements.len(), m);
    }
}
