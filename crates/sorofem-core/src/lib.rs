//! sorofem-core: finite elements for nearly incompressible, cable-driven soft robots.
//!
//! Units are SI (m, Pa, kg/m^3, N) and every array is `f64`. Degrees of freedom are node-major:
//! DOF `3 i + k` is coordinate `k` of node `i`; nodal pressures (mixed formulation) follow after
//! the `3 n` displacement DOFs.
//!
//! The pieces, bottom up: [`mesh::TetMesh`] (geometry and validation), [`material`] (pure 3x3
//! constitutive functions), [`energy`] (element kernels: value, gradient, Hessian), [`assembly`]
//! (the one parallel loop over elements), [`linear`] (sparse Cholesky / LDL^T with a reusable
//! symbolic analysis), [`newton`] (Newton with line search and load stepping) and [`model`]
//! (a body ready to be solved many times).

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
pub mod sensitivity;

pub use error::{Error, Result};
pub use mesh::{Orientation, TetMesh};
pub use model::{
    Damping, Formulation, Loads, Material, Model, PressureMass, Solution, SolveOptions, Trajectory,
};
pub use newton::SolveReport;
