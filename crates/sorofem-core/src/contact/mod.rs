//! Contact by Incremental Potential Contact (IPC; Li et al. 2020): a log barrier on the squared
//! distances between surface primitives, a broad phase, continuous collision detection that
//! bounds each step so that no iterate intersects, and smoothed lagged friction.
//!
//! The pieces, bottom up: [`distance`] (squared distances and their derivatives, closest-feature
//! classification, the parallel-edge mollifier), [`barrier`] (the barrier and its adaptive
//! stiffness), [`obstacle`] (planes, spheres, triangle surfaces), [`collision_mesh`] (the
//! body's surface and its obstacles in one vertex numbering; the [`Candidate`] stencils),
//! [`broad_phase`], [`potential`] (barrier energy per stencil), [`friction`], [`ccd`] (time of
//! impact and the largest safe step), [`check`] (minimum distance, rest intersections) and
//! [`term`] (contact as a term of a model: the barrier and lagged friction added into the free
//! DOFs, the CCD step bound, the stiffness updates, the contact forces).
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
mod psd;
mod segment;
pub mod self_contact;
mod stencil;
pub mod term;

pub use barrier::StiffnessBounds;
pub use collision_mesh::{Candidate, CollisionMesh};
pub use distance::{Feature, Vec3};
pub use obstacle::{Obstacle, ObstacleMesh, Plane, Sphere};
pub use potential::BarrierPotential;
pub use psd::{project_to_psd, project_translation_invariant_to_psd, symmetric_eigen};
pub use term::{free_values, ContactForces, ContactSetup, ContactTerm, ObstacleSpec, UnitBarrier};
