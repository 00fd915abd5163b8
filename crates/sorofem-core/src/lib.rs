//! sorofem-core: finite elements for nearly incompressible, cable-driven soft robots.
//!
//! Units are SI (m, Pa, kg/m^3, N) and every array is `f64`. Degrees of freedom are node-major:
//! DOF `3 i + k` is coordinate `k` of node `i`; the displacements of free cable nodes follow the
//! `3 n` node displacements, and nodal pressures (mixed formulation) come last
//! ([`model::DofLayout`]).
//!
//! The pieces, bottom up: [`mesh::TetMesh`] (geometry and validation, [`locate`] for points in
//! it), [`material`] (hyperelastic models as pure 3x3 functions), [`energy`] (element kernels:
//! value, gradient, Hessian, parameter derivatives), [`assembly`] (the one parallel loop over
//! elements), [`linear`] (sparse Cholesky / LDL^T with a reusable symbolic analysis),
//! [`newton`] (Newton with line search and load stepping), [`model`] (a body ready to be solved
//! many times, with its registry of energy terms) and [`sensitivity`] (forward and adjoint
//! derivatives of its equilibria). docs/architecture.md draws the layers and the path of a
//! solve.

pub mod assembly;
pub mod cables;
pub mod contact;
pub mod energy;
pub mod error;
pub mod linear;
pub mod locate;
pub mod material;
pub mod mesh;
pub mod model;
pub mod newton;
pub mod report;
pub mod sensitivity;
pub mod tolerance;

pub use error::{Error, Result};
pub use mesh::{Orientation, TetMesh};
pub use model::{
    Damping, DofLayout, DynamicsOptions, Formulation, Loads, Material, Model, PressureMass,
    Solution, SolveOptions, StepMethod, TermSpecs, Trajectory,
};
pub use report::{SolveReport, Timings};
