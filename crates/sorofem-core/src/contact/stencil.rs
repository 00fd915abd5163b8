//! One active stencil of a contact pass, and how its values land in the free DOFs of an
//! assembler.

use super::collision_mesh::Candidate;
use crate::assembly::Assembler;

/// One active stencil of a pass: its energy, gradient (`3 n`) and optionally its Hessian
/// (`3 n x 3 n` row-major) over [`Candidate::vertices`].
pub(super) struct Stencil {
    pub(super) candidate: Candidate,
    pub(super) energy: f64,
    pub(super) gradient: [f64; 12],
    pub(super) hessian: Vec<f64>,
}

/// Adds stencil values into the free DOFs of an assembler: obstacle vertices and fixed DOFs are
/// not unknowns and drop out.
pub(super) struct FreeScatter<'a> {
    pub(super) assembler: &'a Assembler,
    pub(super) n_body: usize,
}

impl FreeScatter<'_> {
    /// Free index of coordinate `k` of stencil vertex `v`, when it is one.
    fn free(&self, v: usize, k: usize) -> Option<usize> {
        (v < self.n_body)
            .then(|| self.assembler.free_of_full(3 * v + k))
            .flatten()
    }

    pub(super) fn add_gradient(&self, stencil: &Stencil, gradient: &mut [f64]) {
        let (ids, n) = stencil.candidate.vertices();
        for (a, &v) in ids[..n].iter().enumerate() {
            for k in 0..3 {
                if let Some(f) = self.free(v, k) {
                    gradient[f] += stencil.gradient[3 * a + k];
                }
            }
        }
    }

    pub(super) fn add_hessian(&self, stencil: &Stencil, values: &mut [f64]) {
        let (ids, n) = stencil.candidate.vertices();
        let size = 3 * n;
        let pattern = self.assembler.pattern();
        for r in 0..size {
            let Some(row) = self.free(ids[r / 3], r % 3) else {
                continue;
            };
            for c in 0..size {
                let Some(col) = self.free(ids[c / 3], c % 3) else {
                    continue;
                };
                if row >= col {
                    let position = pattern.position(row, col).expect(
                        "the pattern holds every contact coupling (Model::cover_self_contact)",
                    );
                    values[position] += stencil.hessian[r * size + c];
                }
            }
        }
    }
}
