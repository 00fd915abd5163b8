//! Constitutive laws as pure functions of the deformation gradient F (3x3, dimensionless).
//!
//! Flattening convention for 3x3 tensors: entry (i, j) is component `3 i + j` of a 9-vector, so
//! a fourth-order tangent dP/dF is a 9x9 matrix `A[3i+j, 3k+l] = dP_ij / dF_kl`.

pub mod neo_hookean;

pub use neo_hookean::{NeoHookean, Volumetric};

use nalgebra::{Matrix3, SMatrix, SymmetricEigen};

pub type Mat3 = Matrix3<f64>;
/// dP/dF as a 9x9 matrix (see the module docs for the index convention).
pub type Tangent = SMatrix<f64, 9, 9>;

/// Clamps the negative eigenvalues of a symmetric tangent to zero, so that the element Hessian
/// `V B^T A B` built from it is positive semi-definite (used when the exact Hessian is indefinite).
pub fn project_to_psd(a: &Tangent) -> Tangent {
    // Most elements of an indefinite Hessian are themselves definite: a 9x9 Cholesky
    // (about 250 flops) tells, and spares them the eigendecomposition (about 30x dearer).
    if nalgebra::linalg::Cholesky::new(*a).is_some() {
        return *a;
    }
    let eig = SymmetricEigen::new(*a);
    if eig.eigenvalues.iter().all(|&l| l >= 0.0) {
        return *a;
    }
    let mut clamped = eig.eigenvalues;
    clamped.iter_mut().for_each(|l| *l = l.max(0.0));
    eig.eigenvectors * SMatrix::<f64, 9, 9>::from_diagonal(&clamped) * eig.eigenvectors.transpose()
}

/// `F^{-T}` and `J = det F`; `None` when the element is inverted or flat (J <= 0).
pub fn inverse_transpose(f: &Mat3) -> Option<(Mat3, f64)> {
    let j = f.determinant();
    if !(j > 0.0) {
        return None;
    }
    f.try_inverse().map(|inv| (inv.transpose(), j))
}

/// The tangent of a volumetric energy density `h(J)`: with `G = F^{-T}`,
/// `dP_ij/dF_kl = (h'' J^2 + h' J) G_ij G_kl - h' J G_il G_kj`.
pub fn volumetric_tangent(g: &Mat3, j: f64, dh: f64, d2h: f64) -> Tangent {
    let a = d2h * j * j + dh * j;
    let b = dh * j;
    let mut t = Tangent::zeros();
    for i in 0..3 {
        for jj in 0..3 {
            for k in 0..3 {
                for l in 0..3 {
                    t[(3 * i + jj, 3 * k + l)] =
                        a * g[(i, jj)] * g[(k, l)] - b * g[(i, l)] * g[(k, jj)];
                }
            }
        }
    }
    t
}
