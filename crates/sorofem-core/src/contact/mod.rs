//! Contact by Incremental Potential Contact (IPC; Li et al. 2020): a log barrier on the squared
//! distances between surface primitives, a broad phase, continuous collision detection that
//! bounds each step so that no iterate intersects, and smoothed lagged friction.
//!
//! The pieces, bottom up: [`distance`] (squared distances and their derivatives, closest-feature
//! classification, the parallel-edge mollifier), [`barrier`] (the barrier and its adaptive
//! stiffness), [`obstacle`] (planes, spheres, triangle surfaces), [`collision_mesh`] (the
//! body's surface and its obstacles in one vertex numbering; the [`Candidate`] stencils),
//! [`broad_phase`], [`potential`] (barrier energy per stencil), [`friction`], [`ccd`] (time of
//! impact and the largest safe step) and [`check`] (minimum distance, rest intersections).
//!
//! Positions are in m; the barrier acts on squared distances (m^2), with activation distance
//! `dhat` (m).

pub mod barrier;
pub mod broad_phase;
pub mod ccd;
pub mod check;
pub mod collision_mesh;
pub mod distance;
pub mod friction;
pub mod obstacle;
pub mod potential;

pub use barrier::StiffnessBounds;
pub use collision_mesh::{Candidate, CollisionMesh};
pub use distance::{Feature, Vec3};
pub use obstacle::{Obstacle, ObstacleMesh, Plane, Sphere};
pub use potential::BarrierPotential;

use nalgebra::{DMatrix, SMatrix, SymmetricEigen};

/// Clamps the negative eigenvalues of a symmetric matrix to zero, in place (unchanged when it is
/// already positive semi-definite): IPC's projection of each stencil Hessian, so that the
/// assembled Hessian gives a descent direction.
pub fn project_to_psd<const N: usize>(h: &mut SMatrix<f64, N, N>) {
    // Positive definite stencils (about half of the barrier's) skip the eigendecomposition.
    if nalgebra::linalg::Cholesky::new(*h).is_some() {
        return;
    }
    let eig = SymmetricEigen::new(DMatrix::from_column_slice(N, N, h.as_slice()));
    if eig.eigenvalues.iter().all(|&l| l >= 0.0) {
        return;
    }
    let mut clamped = eig.eigenvectors.clone();
    for (k, &l) in eig.eigenvalues.iter().enumerate() {
        let scale = l.max(0.0);
        clamped.column_mut(k).scale_mut(scale);
    }
    let projected = clamped * eig.eigenvectors.transpose();
    h.copy_from_slice(projected.as_slice());
}
