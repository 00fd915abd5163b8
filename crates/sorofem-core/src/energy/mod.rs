//! Energy terms as local kernels. A term is a set of elements; each element touches a short list
//! of global DOFs (its stencil) and returns its energy, gradient and Hessian in those DOFs. The
//! [`crate::assembly::Assembler`] is the only code that loops over all elements.
//!
//! The displacement unknowns are displacements from the rest shape (m), not positions.

pub mod cable;
pub mod elastic;
pub mod loads;

pub use cable::{Cable, CableTerm, PointMap};
pub use elastic::{ElasticTerm, Formulation, PressureMass};
pub use loads::{GravityTerm, NodalForceTerm};

use crate::material::{Mat3, Tangent};
use nalgebra::Vector3;

/// How an element Hessian is formed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum HessianMode {
    /// The exact second derivative (quadratic Newton convergence; may be indefinite).
    Exact,
    /// Each element's material tangent projected to positive semi-definite (a descent direction
    /// is guaranteed; used when the exact Hessian is not positive definite).
    Projected,
}

/// One energy term made of elements.
pub trait Term: Sync {
    /// Number of DOFs one element touches.
    fn stencil_size(&self) -> usize;
    fn n_elements(&self) -> usize;
    /// Writes the global (full, before elimination of fixed DOFs) DOF indices of element `e`.
    fn element_dofs(&self, e: usize, dofs: &mut [usize]);
    /// Energy (J) of element `e` at its local DOF values `z`; when given, writes the gradient
    /// (length `s`) and the Hessian (`s x s`, row-major), `s = stencil_size()`. Returns `+inf` when
    /// the element is inverted, and then leaves the outputs unspecified.
    fn element(
        &self,
        e: usize,
        z: &[f64],
        grad: Option<&mut [f64]>,
        hess: Option<&mut [f64]>,
        mode: HessianMode,
    ) -> f64;
    /// Linear terms (loads) have a zero Hessian and are left out of the sparsity pattern.
    fn is_linear(&self) -> bool {
        false
    }
}

/// Adds `V sum_j P_ij g_aj` to `grad[3a + i]`: the nodal forces of a stress P on a tet.
pub(crate) fn add_tet_gradient(volume: f64, g: &[Vector3<f64>; 4], p: &Mat3, grad: &mut [f64]) {
    for a in 0..4 {
        let f = p * g[a] * volume;
        for i in 0..3 {
            grad[3 * a + i] += f[i];
        }
    }
}

/// Adds `V sum_jl A[3i+j, 3k+l] g_aj g_bl` to `hess[(3a+i) * stride + 3b+k]`.
pub(crate) fn add_tet_hessian(
    volume: f64,
    g: &[Vector3<f64>; 4],
    a: &Tangent,
    hess: &mut [f64],
    stride: usize,
) {
    for i in 0..3 {
        for k in 0..3 {
            let block = a.fixed_view::<3, 3>(3 * i, 3 * k);
            let w: [Vector3<f64>; 4] = std::array::from_fn(|b| block * g[b]);
            for aa in 0..4 {
                for b in 0..4 {
                    hess[(3 * aa + i) * stride + 3 * b + k] += volume * g[aa].dot(&w[b]);
                }
            }
        }
    }
}

/// Adds the Hessian of an isotropic tangent `A = mu I + alpha T + beta O` (with
/// `T_(ij)(kl) = G_il G_kj`, `O_(ij)(kl) = G_ij G_kl`, `G = F^{-T}`) without forming A:
/// block (a, b) is `V [mu (g_a . g_b) I + alpha w_b w_a^T + beta w_a w_b^T]`, `w_a = G g_a`.
/// Every Neo-Hookean tangent in this crate has this form; it costs a fifth of the general path.
#[allow(clippy::too_many_arguments)]
pub(crate) fn add_isotropic_tet_hessian(
    volume: f64,
    g: &[Vector3<f64>; 4],
    gt: &Mat3,
    mu: f64,
    alpha: f64,
    beta: f64,
    hess: &mut [f64],
    stride: usize,
) {
    let w: [Vector3<f64>; 4] = std::array::from_fn(|a| gt * g[a]);
    for a in 0..4 {
        for b in 0..4 {
            let diagonal = volume * mu * g[a].dot(&g[b]);
            for i in 0..3 {
                let row = (3 * a + i) * stride + 3 * b;
                for k in 0..3 {
                    hess[row + k] +=
                        volume * (alpha * w[b][i] * w[a][k] + beta * w[a][i] * w[b][k]);
                }
                hess[row + i] += diagonal;
            }
        }
    }
}
