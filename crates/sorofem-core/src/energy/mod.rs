//! Energy terms as local kernels. A term is a set of elements; each element touches a short list
//! of global DOFs (its stencil) and returns its energy, gradient and Hessian in those DOFs. The
//! [`crate::assembly::Assembler`] is the only code that loops over all elements.
//!
//! The displacement unknowns are displacements from the rest shape (m), not positions.

pub mod cable;
pub mod elastic;
pub mod loads;
pub mod pressure_iterates;
pub mod tendon;

pub use cable::{Cable, CableTerm, PointMap};
pub use elastic::{ElasticTerm, Formulation, PressureMass};
pub use loads::{GravityTerm, LumpedMass, NodalForceTerm, PointGravityTerm};
pub use tendon::{Tendon, TendonCommand, TendonTerm};

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
    /// (length `s`) and the Hessian (`s x s`, row-major), `s = stencil_size()`, every entry (the
    /// assembler reuses its buffers without zeroing them). Returns `+inf` when the element is
    /// inverted, and then leaves the outputs unspecified.
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

/// A term whose gradient depends on parameters (material constants, density, gravity, cable
/// actuation and stiffness): what sensitivities need of it, so that they need no code of their
/// own per term.
///
/// The parameters form named blocks; blocks of the same name in several terms are one parameter
/// (gravity acts on the tets and on the free cable nodes alike).
pub trait ParamTerm: Term {
    /// Name and length of each of the term's parameter blocks, e.g. `("gravity", 3)`.
    fn param_blocks(&self) -> Vec<(String, usize)>;
    /// Number of parameters the gradient of one element depends on.
    fn element_param_count(&self) -> usize;
    /// Writes the parameters element `e` depends on, each as `(block, index)`: the position of
    /// its block in [`ParamTerm::param_blocks`] and its index within the block.
    fn element_params(&self, e: usize, params: &mut [(usize, usize)]);
    /// `d(grad_e)/d(theta_k)` at the element's local DOF values `z`, for each of its parameters
    /// `theta_k` in the order of [`ParamTerm::element_params`]: writes every entry of
    /// `out` (`element_param_count() x stencil_size()`, row-major; units of the gradient per
    /// unit of the parameter).
    fn element_param_gradient(&self, e: usize, z: &[f64], out: &mut [f64]);
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

/// Writes `V sum_jl A[3i+j, 3k+l] g_aj g_bl` to `hess[(3a+i) * stride + 3b+k]` (the first 12
/// rows and columns; every entry, no zeroing needed): the element Hessian of a symmetric 9x9
/// material tangent A, with `g_0 = -(g_1 + g_2 + g_3)` (how [`TetMesh`](crate::mesh::TetMesh)
/// builds it). With `W_b[3i+j, k] = V sum_l A[3i+j, 3k+l] g_bl` for nodes 1 to 3, the blocks
/// among them are `K_ab[i, k] = sum_j g_aj W_b[3i+j, k]` (only `a >= b` computed, the others
/// their transposes as A is symmetric), and node 0's blocks follow from `g_0`: `H_a0 = -sum_b
/// K_ab`, `H_0b` its transpose, `H_00 = sum_ab K_ab`. About 400 products instead of 1300.
pub(crate) fn set_tet_hessian(
    volume: f64,
    g: &[Vector3<f64>; 4],
    a: &Tangent,
    hess: &mut [f64],
    stride: usize,
) {
    let mut w = [[[0.0; 3]; 9]; 3];
    for (b, w_b) in w.iter_mut().enumerate() {
        let gb = g[b + 1] * volume;
        for k in 0..3 {
            let (c0, c1, c2) = (a.column(3 * k), a.column(3 * k + 1), a.column(3 * k + 2));
            for (row, w_row) in w_b.iter_mut().enumerate() {
                w_row[k] = c0[row] * gb[0] + c1[row] * gb[1] + c2[row] * gb[2];
            }
        }
    }
    // blocks[a][b]: node a + 1's rows, node b + 1's columns.
    let mut blocks = [[Mat3::zeros(); 3]; 3];
    for (aa, ga) in g[1..].iter().enumerate() {
        for (b, w_b) in w.iter().enumerate().take(aa + 1) {
            let block = Mat3::from_fn(|i, k| {
                ga[0] * w_b[3 * i][k] + ga[1] * w_b[3 * i + 1][k] + ga[2] * w_b[3 * i + 2][k]
            });
            blocks[aa][b] = block;
            blocks[b][aa] = block.transpose();
        }
    }
    let mut put = |a: usize, b: usize, block: &Mat3| {
        for i in 0..3 {
            for k in 0..3 {
                hess[(3 * a + i) * stride + 3 * b + k] = block[(i, k)];
            }
        }
    };
    let mut corner = Mat3::zeros();
    for (aa, row) in blocks.iter().enumerate() {
        let row_sum = -(row[0] + row[1] + row[2]);
        for (b, block) in row.iter().enumerate() {
            put(aa + 1, b + 1, block);
        }
        put(aa + 1, 0, &row_sum);
        put(0, aa + 1, &row_sum.transpose());
        corner -= row_sum;
    }
    put(0, 0, &corner);
}

/// Writes the displacement block (the first 12 rows and columns of a `stride`-wide element
/// Hessian) of an isotropic tangent `A = mu I + alpha T + beta O` (with `T_(ij)(kl) = G_il G_kj`,
/// `O_(ij)(kl) = G_ij G_kl`, `G = F^{-T}`), minus the given eigenmodes `(lambda, Q)` of A, without
/// forming A: block (a, b) is
/// `V [mu (g_a . g_b) I + alpha w_b w_a^T + beta w_a w_b^T - sum_k lambda_k q_ka q_kb^T]` with
/// `w_a = G g_a` and `q_ka = Q_k g_a`. Every Neo-Hookean tangent in this crate has this form; it
/// costs a fifth of the general path. Overwrites (no zeroing needed) and computes the blocks
/// `a >= b` only, mirroring the rest.
#[allow(clippy::too_many_arguments)]
pub(crate) fn set_isotropic_tet_hessian(
    volume: f64,
    g: &[Vector3<f64>; 4],
    gt: &Mat3,
    mu: f64,
    alpha: f64,
    beta: f64,
    removed_modes: &[(f64, Mat3)],
    hess: &mut [f64],
    stride: usize,
) {
    let w: [Vector3<f64>; 4] = std::array::from_fn(|a| gt * g[a]);
    let (va, vb) = (volume * alpha, volume * beta);
    // Blocks a >= b first (diagonal blocks are symmetric), then the modes, then the mirror.
    for a in 0..4 {
        for b in 0..=a {
            let diagonal = volume * mu * g[a].dot(&g[b]);
            for i in 0..3 {
                let row = (3 * a + i) * stride + 3 * b;
                for k in 0..3 {
                    hess[row + k] = va * w[b][i] * w[a][k] + vb * w[a][i] * w[b][k];
                }
                hess[row + i] += diagonal;
            }
        }
    }
    for (lambda, q) in removed_modes {
        let scaled = volume * lambda;
        let qg: [Vector3<f64>; 4] = std::array::from_fn(|a| q * g[a]);
        for a in 0..4 {
            for b in 0..=a {
                for i in 0..3 {
                    let row = (3 * a + i) * stride + 3 * b;
                    for k in 0..3 {
                        hess[row + k] -= scaled * qg[a][i] * qg[b][k];
                    }
                }
            }
        }
    }
    for a in 1..4 {
        for b in 0..a {
            for i in 0..3 {
                for k in 0..3 {
                    hess[(3 * b + k) * stride + 3 * a + i] = hess[(3 * a + i) * stride + 3 * b + k];
                }
            }
        }
    }
}

/// [`set_isotropic_tet_hessian`] with the tangent's negative eigenvalues clamped to zero (see
/// [`crate::material::isotropic_tangent_negative_modes`]): each negative mode `(lambda, Q)` is
/// taken back out. The result is the Hessian of the projected tangent, positive semi-definite
/// per element.
#[allow(clippy::too_many_arguments)]
pub(crate) fn set_projected_isotropic_tet_hessian(
    volume: f64,
    g: &[Vector3<f64>; 4],
    f: &Mat3,
    gt: &Mat3,
    mu: f64,
    alpha: f64,
    beta: f64,
    hess: &mut [f64],
    stride: usize,
) {
    let mut modes = [(0.0, Mat3::zeros()); 9];
    let n = crate::material::isotropic_tangent_negative_modes(f, mu, alpha, beta, &mut modes);
    set_isotropic_tet_hessian(volume, g, gt, mu, alpha, beta, &modes[..n], hess, stride);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::{project_to_psd, Tangent};
    use nalgebra::Rotation3;

    /// Adds `V sum_jl A[3i+j, 3k+l] g_aj g_bl` to `hess[(3a+i) * stride + 3b+k]`, term by term:
    /// the reference the element Hessians of [`set_tet_hessian`] and the isotropic shortcuts are
    /// tested against.
    fn add_tet_hessian(
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

    /// The blocked element Hessian (node 0's blocks from the others) against the term-by-term
    /// sum, on a symmetric tangent, with a stride of 16 (the mixed formulation's) whose pressure entries
    /// must stay untouched.
    #[test]
    fn tet_hessian_matches_the_term_by_term_sum() {
        let (g1, g2, g3) = (
            Vector3::new(1.3, 0.2, 0.1),
            Vector3::new(-0.1, 0.5, -0.3),
            Vector3::new(0.2, 0.0, 0.4),
        );
        let g = [-(g1 + g2 + g3), g1, g2, g3];
        let m = Tangent::from_fn(|r, c| ((r * 7 + c * 3) % 11) as f64 - 5.0 + 0.1 * (r * c) as f64);
        let a = m + m.transpose();
        let mut reference = vec![0.0; 256];
        add_tet_hessian(0.7, &g, &a, &mut reference, 16);
        let mut blocked = vec![f64::NAN; 256];
        set_tet_hessian(0.7, &g, &a, &mut blocked, 16);
        let scale = reference.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        for row in 0..16 {
            for col in 0..16 {
                let (x, y) = (blocked[row * 16 + col], reference[row * 16 + col]);
                if row < 12 && col < 12 {
                    assert!((x - y).abs() <= 1e-14 * scale, "({row}, {col}): {x} vs {y}");
                } else {
                    assert!(x.is_nan(), "({row}, {col}) written");
                }
            }
        }
    }

    /// The analytic projection against a 9x9 eigendecomposition of the same tangent, over
    /// compressed, stretched and sheared states and both signs of alpha and beta (the mixed
    /// formulation's beta follows the sign of the pressure).
    #[test]
    fn analytic_projection_matches_the_eigendecomposition() {
        let g: [Vector3<f64>; 4] = [
            Vector3::new(-1.0, -0.5, -0.2),
            Vector3::new(1.0, 0.0, 0.1),
            Vector3::new(0.0, 0.5, -0.3),
            Vector3::new(0.0, 0.0, 0.4),
        ];
        let mut projected_states = 0;
        for (k, stretch) in [
            [1.0, 1.0, 1.0],
            [0.5, 0.7, 1.2],
            [0.3, 0.9, 0.95],
            [1.5, 1.8, 2.0],
            [2.5, 0.6, 1.0],
            [1.0, 1.0, 0.999],
        ]
        .iter()
        .enumerate()
        {
            let u = Rotation3::from_euler_angles(0.3 * k as f64, 1.1, -0.4);
            let v = Rotation3::from_euler_angles(-0.7, 0.2 * k as f64, 0.9);
            let shear = Mat3::new(1.0, 0.2, 0.0, 0.0, 1.0, -0.1, 0.05, 0.0, 1.0);
            let f = u.matrix() * Mat3::from_diagonal(&Vector3::from(*stretch)) * v.matrix() * shear;
            let gt = f.try_inverse().unwrap().transpose();
            for (mu, alpha, beta) in [
                (1.0, 1.0, 10.0),
                (1.0, 3.0, 10.0),
                (1.0, -4.0, 10.0),
                (1.0, 0.5, -3.0),
                (2.0, -1.0, -0.5),
            ] {
                let mut a = Tangent::identity() * mu;
                for i in 0..3 {
                    for j in 0..3 {
                        for kk in 0..3 {
                            for l in 0..3 {
                                a[(3 * i + j, 3 * kk + l)] += alpha * gt[(i, l)] * gt[(kk, j)]
                                    + beta * gt[(i, j)] * gt[(kk, l)];
                            }
                        }
                    }
                }
                let reference_tangent = project_to_psd(&a);
                projected_states += usize::from(reference_tangent != a);
                let mut reference = vec![0.0; 144];
                add_tet_hessian(0.7, &g, &reference_tangent, &mut reference, 12);
                let mut analytic = vec![f64::NAN; 144];
                set_projected_isotropic_tet_hessian(
                    0.7,
                    &g,
                    &f,
                    &gt,
                    mu,
                    alpha,
                    beta,
                    &mut analytic,
                    12,
                );
                let scale = reference.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                for (x, y) in analytic.iter().zip(&reference) {
                    assert!(
                        (x - y).abs() <= 1e-10 * scale,
                        "stretch {stretch:?}, (mu, alpha, beta) = ({mu}, {alpha}, {beta}): {x} vs {y}"
                    );
                }
            }
        }
        assert!(
            projected_states >= 10,
            "too few indefinite cases: {projected_states}"
        );
    }
}
