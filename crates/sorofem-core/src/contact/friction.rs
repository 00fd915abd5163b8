//! IPC's smoothed, lagged Coulomb friction.
//!
//! For each active stencil, the start of the step fixes (lags) its normal force magnitude
//! `lambda` (N), its closest-point weights `w` and its tangent basis `P` (3 x 2, orthonormal
//! columns orthogonal to the contact normal). The tangential relative displacement over the
//! step is `u = P^T sum_a w_a (x_a - x_a^t)` (m, a 2-vector) and the friction potential is
//! `D = mu lambda f0(|u|)` (J), whose gradient is the friction force: of magnitude
//! `mu lambda f1(|u|)`, opposing the slip, with the mollifier
//! `f1(y) = 2 y / eps_u - y^2 / eps_u^2` below `eps_u` and 1 beyond (static friction is the
//! stiff branch below `eps_u`, a slip in m per step; in dynamics `eps_u = eps_v h`).
//! With `P`, `w` and `lambda` fixed, `u` is linear in the positions and the Hessian
//! `mu lambda T [f2 u u^T + f1 / |u| I] T^T` (`T = w (x) P`) is positive semi-definite.

use super::barrier::normal_force_magnitude;
use super::collision_mesh::{Candidate, CollisionMesh};
use super::distance::{
    edge_edge_feature, point_edge_feature, point_triangle_feature, Feature, Vec3,
};
use super::potential::{candidate_squared_distance, BarrierPotential};
use crate::energy::HessianMode;
use nalgebra::{Matrix2, Matrix3x2, SymmetricEigen, Vector2};

/// `f0(y) = -y^3 / (3 eps^2) + y^2 / eps + eps / 3` for `y < eps`, `y` beyond (m): the smoothed
/// `|u|`, C2 at `eps`.
pub fn friction_f0(y: f64, eps: f64) -> f64 {
    if y >= eps {
        y
    } else {
        y * y * (1.0 - y / (3.0 * eps)) / eps + eps / 3.0
    }
}

/// `f1 = f0' = 2 y / eps - y^2 / eps^2` for `y < eps`, 1 beyond (dimensionless).
pub fn friction_f1(y: f64, eps: f64) -> f64 {
    if y >= eps {
        1.0
    } else {
        y * (2.0 - y / eps) / eps
    }
}

/// `f1(y) / y`, with its limit `2 / eps` at `y = 0` (1/m).
pub fn friction_f1_over_y(y: f64, eps: f64) -> f64 {
    if y >= eps {
        1.0 / y
    } else {
        (2.0 - y / eps) / eps
    }
}

/// `(f1'(y) y - f1(y)) / y^3`: `-1 / (eps^2 y)` below `eps`, `-1 / y^3` beyond (1/m^3); it
/// multiplies `u u^T`, whose norm is `y^2`, so the product stays bounded at `y = 0`.
pub fn friction_f2(y: f64, eps: f64) -> f64 {
    if y >= eps {
        -1.0 / (y * y * y)
    } else {
        -1.0 / (eps * eps * y)
    }
}

/// One lagged friction stencil.
#[derive(Clone, Debug, PartialEq)]
pub struct FrictionStencil {
    pub candidate: Candidate,
    /// Closest-point weights of the stencil's vertices: the relative displacement is
    /// `sum_a w_a (x_a - x_a^t)` (unused entries 0).
    pub weights: [f64; 4],
    /// Tangent basis (orthonormal columns, orthogonal to the normal at the start of the step).
    pub basis: Matrix3x2<f64>,
    /// Normal force magnitude at the start of the step (N).
    pub normal_force: f64,
    /// Friction coefficient.
    pub mu: f64,
    /// Positions of the stencil's vertices at the start of the step (m).
    pub start: [Vec3; 4],
}

impl FrictionStencil {
    /// Lags a candidate at the start-of-step positions `x_t` (all vertices); `None` when it is
    /// not active (distance >= dhat, or touching). As in IPC, `lambda = -kappa b'(d) 2 sqrt(d)`
    /// leaves out the edge-edge mollifier, and the closest features are those at `x_t`.
    pub fn lag(
        mesh: &CollisionMesh,
        candidate: &Candidate,
        x_t: &[Vec3],
        barrier: &BarrierPotential,
        mu: f64,
    ) -> Option<Self> {
        let (p, n) = candidate.positions(x_t);
        let d = candidate_squared_distance(mesh, candidate, &p[..n]);
        let dhat2 = barrier.dhat() * barrier.dhat();
        if d <= 0.0 || d >= dhat2 {
            return None;
        }
        let normal_force = normal_force_magnitude(d, dhat2, barrier.stiffness());
        let (weights, basis) = match *candidate {
            Candidate::PointTriangle { .. } => {
                let feature = point_triangle_feature(&p[0], &p[1], &p[2], &p[3]);
                feature_frame(&feature, &p)
            }
            Candidate::EdgeEdge { .. } => {
                let feature = edge_edge_feature(&p[0], &p[1], &p[2], &p[3]);
                feature_frame(&feature, &p)
            }
            Candidate::PointPlane { obstacle, .. } => (
                [1.0, 0.0, 0.0, 0.0],
                complement_basis(&mesh.plane(obstacle).normal),
            ),
            Candidate::PointSphere { obstacle, .. } => (
                [1.0, 0.0, 0.0, 0.0],
                complement_basis(&(p[0] - mesh.sphere(obstacle).center)),
            ),
            // Ball stencils carry friction where they carry the barrier: when the centre
            // projects inside the feature. The centre is fixed: its weight drops out.
            Candidate::TriangleSphere { obstacle, .. } => {
                let q = [mesh.sphere(obstacle).center, p[0], p[1], p[2]];
                let feature = point_triangle_feature(&q[0], &q[1], &q[2], &q[3]);
                if !matches!(feature, Feature::PointPlane(_)) {
                    return None;
                }
                let (w, basis) = feature_frame(&feature, &q);
                ([w[1], w[2], w[3], 0.0], basis)
            }
            Candidate::EdgeSphere { obstacle, .. } => {
                let q = [mesh.sphere(obstacle).center, p[0], p[1], p[1]];
                let feature = point_edge_feature(&q[0], &q[1], &q[2], [0, 1, 2]);
                if !matches!(feature, Feature::PointLine(_)) {
                    return None;
                }
                let (w, basis) = feature_frame(&feature, &q);
                ([w[1], w[2], 0.0, 0.0], basis)
            }
        };
        Some(FrictionStencil {
            candidate: *candidate,
            weights,
            basis,
            normal_force,
            mu,
            start: p,
        })
    }

    /// Tangential relative displacement `u` (m) at the stencil's current positions `local`.
    pub fn tangential_displacement(&self, local: &[Vec3]) -> Vector2<f64> {
        let mut relative = Vec3::zeros();
        for (a, x) in local.iter().enumerate() {
            relative += self.weights[a] * (x - self.start[a]);
        }
        self.basis.transpose() * relative
    }

    /// Friction potential `mu lambda f0(|u|)` (J) at the stencil's current positions `local`
    /// (`n` vertices); when given, writes the gradient (`3 n`, N) and the Hessian (`3 n x 3 n`
    /// row-major, N/m), every entry. `HessianMode::Projected` clamps the inner 2 x 2 matrix's
    /// negative eigenvalues (there are none for `lambda >= 0`).
    pub fn energy(
        &self,
        local: &[Vec3],
        eps_u: f64,
        grad: Option<&mut [f64]>,
        hess: Option<&mut [f64]>,
        mode: HessianMode,
    ) -> f64 {
        let size = 3 * local.len();
        let u = self.tangential_displacement(local);
        let y = u.norm();
        let scale = self.mu * self.normal_force;
        if let Some(g) = grad {
            let force = self.basis * (u * (scale * friction_f1_over_y(y, eps_u)));
            for (a, w) in self.weights.iter().take(local.len()).enumerate() {
                for i in 0..3 {
                    g[3 * a + i] = w * force[i];
                }
            }
        }
        if let Some(h) = hess {
            let mut inner = Matrix2::identity() * friction_f1_over_y(y, eps_u);
            if y > 0.0 {
                inner += u * u.transpose() * friction_f2(y, eps_u);
            }
            inner *= scale;
            if mode == HessianMode::Projected {
                let eig = SymmetricEigen::new(inner);
                let clamped = eig.eigenvalues.map(|l| l.max(0.0));
                inner = eig.eigenvectors
                    * Matrix2::from_diagonal(&clamped)
                    * eig.eigenvectors.transpose();
            }
            let block = self.basis * inner * self.basis.transpose();
            for (a, wa) in self.weights.iter().take(local.len()).enumerate() {
                for (b, wb) in self.weights.iter().take(local.len()).enumerate() {
                    for i in 0..3 {
                        for j in 0..3 {
                            h[(3 * a + i) * size + 3 * b + j] = wa * wb * block[(i, j)];
                        }
                    }
                }
            }
        }
        scale * friction_f0(y, eps_u)
    }
}

/// Lags every active candidate at `x_t` with the coefficient `mu(candidate)`, skipping those
/// with `mu == 0`.
pub fn lag_friction(
    mesh: &CollisionMesh,
    candidates: &[Candidate],
    x_t: &[Vec3],
    barrier: &BarrierPotential,
    mu: impl Fn(&Candidate) -> f64,
) -> Vec<FrictionStencil> {
    candidates
        .iter()
        .filter_map(|c| {
            let m = mu(c);
            if m == 0.0 {
                return None;
            }
            FrictionStencil::lag(mesh, c, x_t, barrier, m)
        })
        .collect()
}

/// Closest-point weights and tangent basis of a surface stencil's closest features.
fn feature_frame(feature: &Feature, p: &[Vec3; 4]) -> ([f64; 4], Matrix3x2<f64>) {
    let mut w = [0.0; 4];
    match *feature {
        Feature::PointPoint([a, b]) => {
            w[a] = 1.0;
            w[b] = -1.0;
            (w, complement_basis(&(p[a] - p[b])))
        }
        Feature::PointLine([a, e0, e1]) => {
            let e = p[e1] - p[e0];
            let alpha = (p[a] - p[e0]).dot(&e) / e.norm_squared();
            w[a] = 1.0;
            w[e0] = -(1.0 - alpha);
            w[e1] = -alpha;
            let second = e.cross(&(p[a] - p[e0]));
            (
                w,
                Matrix3x2::from_columns(&[e.normalize(), second.normalize()]),
            )
        }
        Feature::PointPlane([a, t0, t1, t2]) => {
            let (e1, e2) = (p[t1] - p[t0], p[t2] - p[t0]);
            let r = p[a] - p[t0];
            // Barycentric coordinates of the projection: the 2 x 2 normal equations.
            let gram = Matrix2::new(e1.dot(&e1), e1.dot(&e2), e1.dot(&e2), e2.dot(&e2));
            let beta = gram.try_inverse().map_or(Vector2::zeros(), |g| {
                g * Vector2::new(e1.dot(&r), e2.dot(&r))
            });
            w[a] = 1.0;
            w[t0] = -(1.0 - beta[0] - beta[1]);
            w[t1] = -beta[0];
            w[t2] = -beta[1];
            let normal = e1.cross(&e2);
            (
                w,
                Matrix3x2::from_columns(&[e1.normalize(), normal.cross(&e1).normalize()]),
            )
        }
        Feature::LineLine([a0, a1, b0, b1]) => {
            let (ea, eb, r) = (p[a1] - p[a0], p[b1] - p[b0], p[a0] - p[b0]);
            let (a, b, c) = (ea.dot(&ea), ea.dot(&eb), eb.dot(&eb));
            let (d, e) = (ea.dot(&r), eb.dot(&r));
            let den = a * c - b * b;
            let s = (b * e - c * d) / den;
            let t = (a * e - b * d) / den;
            w[a0] = 1.0 - s;
            w[a1] = s;
            w[b0] = -(1.0 - t);
            w[b1] = -t;
            let normal = ea.cross(&eb);
            (
                w,
                Matrix3x2::from_columns(&[ea.normalize(), normal.cross(&ea).normalize()]),
            )
        }
    }
}

/// An orthonormal basis of the plane orthogonal to `n` (any length > 0): crossed with the
/// coordinate axis least aligned with it.
pub fn complement_basis(n: &Vec3) -> Matrix3x2<f64> {
    let axis = Vec3::ith(n.abs().imin(), 1.0);
    let first = n.cross(&axis).normalize();
    let second = n.cross(&first).normalize();
    Matrix3x2::from_columns(&[first, second])
}
