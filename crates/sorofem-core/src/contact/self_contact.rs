//! Self-contact: which stencils are the body against itself, and the couplings they add to
//! the Hessian pattern ahead of contact.

use super::broad_phase::candidates;
use super::collision_mesh::Candidate;
use super::potential::candidate_squared_distance;
use super::term::ContactTerm;

/// The reach of the self-contact couplings the Hessian pattern is given ahead of contact, as a
/// fraction of the mean boundary edge length (see [`ContactTerm::self_coupling_reach`]).
pub const SELF_COUPLING_REACH_PER_EDGE: f64 = 0.25;

impl ContactTerm {
    /// How far (m) ahead of contact self-contact couplings enter the Hessian pattern:
    /// [`SELF_COUPLING_REACH_PER_EDGE`] mean boundary edges, and at least `dhat`.
    pub fn self_coupling_reach(&self) -> f64 {
        (SELF_COUPLING_REACH_PER_EDGE * self.mean_edge()).max(self.dhat())
    }

    /// The body node pairs `[a, b]` the self-contact stencils closer than
    /// [`ContactTerm::self_coupling_reach`] couple at `z` (empty without self-contact).
    pub fn self_couplings(&self, z: &[f64]) -> Vec<[usize; 2]> {
        if !self.self_contact() {
            return Vec::new();
        }
        let x = self.positions(z);
        let reach = self.self_coupling_reach();
        let near = |c: &Candidate| {
            let (p, n) = c.positions(&x);
            candidate_squared_distance(self.collision_mesh(), c, &p[..n]) < reach * reach
        };
        let mut pairs: Vec<[usize; 2]> = candidates(self.collision_mesh(), &x, reach)
            .iter()
            .filter(|c| self.is_self(c) && near(c))
            .flat_map(|c| {
                let (ids, _) = c.vertices();
                (0..4).flat_map(move |a| (0..a).map(move |b| [ids[a], ids[b]]))
            })
            .collect();
        pairs.sort_unstable();
        pairs.dedup();
        pairs
    }

    /// Whether a stencil is self-contact (two body primitives).
    pub(super) fn is_self(&self, candidate: &Candidate) -> bool {
        let (ids, n) = candidate.vertices();
        matches!(
            candidate,
            Candidate::PointTriangle { .. } | Candidate::EdgeEdge { .. }
        ) && ids[..n].iter().all(|&v| v < self.collision_mesh().n_body())
    }
}
