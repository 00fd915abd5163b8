//! The barrier potential on stencils: `kappa b(d)` per candidate, with `d` the squared distance
//! between its closest features (mollified for nearly parallel edges), as IPC's original
//! formulation sums it over vertex-triangle and edge-edge pairs.
//!
//! [`BarrierPotential::stencil_energy`] has the shape of an element kernel of
//! [`crate::energy::Term`]: it takes the positions of one stencil's vertices and writes every
//! entry of its gradient (length `3 n`) and Hessian (`3 n x 3 n`, row-major), `n` the number of
//! vertices of the stencil ([`Candidate::vertices`]).

use super::barrier::{barrier, barrier_gradient, barrier_hessian};
use super::collision_mesh::{Candidate, CollisionMesh};
use super::distance::{
    edge_edge_feature, edge_edge_mollifier, edge_edge_mollifier_derivatives,
    edge_edge_mollifier_threshold, feature_distance, feature_distance_derivatives,
    line_line_distance_derivatives, point_edge_feature, point_line_distance_derivatives,
    point_plane_distance_derivatives, point_point_distance_derivatives, point_triangle_feature,
    Derivatives, Feature, Vec3,
};
use super::psd::{project_to_psd, project_translation_invariant_to_psd};
use crate::energy::HessianMode;
use crate::error::{Error, Result};
use nalgebra::Matrix3;
use rayon::prelude::*;

/// `kappa sum_k b(d_k; dhat^2)` over the candidates (J).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BarrierPotential {
    dhat: f64,
    stiffness: f64,
}

/// Energy (J), gradient over all vertices (`3 n_vertices`, N) and the Hessians of the active
/// stencils (N/m), as [`BarrierPotential::assemble`] returns them.
#[derive(Clone, Debug, Default)]
pub struct Assembled {
    pub energy: f64,
    pub gradient: Vec<f64>,
    pub hessians: Vec<StencilHessian>,
}

/// The Hessian of one stencil: `3 n x 3 n` row-major in the first `9 n^2` entries of `values`,
/// over the coordinates of `candidate.vertices()`.
#[derive(Clone, Debug)]
pub struct StencilHessian {
    pub candidate: Candidate,
    pub values: [f64; 144],
}

impl StencilHessian {
    /// `(row, column, value)` in the global numbering `3 v + k` of [`CollisionMesh`].
    pub fn entries(&self) -> impl Iterator<Item = (usize, usize, f64)> + '_ {
        let (ids, n) = self.candidate.vertices();
        let size = 3 * n;
        (0..size * size).map(move |k| {
            let (r, c) = (k / size, k % size);
            (
                3 * ids[r / 3] + r % 3,
                3 * ids[c / 3] + c % 3,
                self.values[k],
            )
        })
    }
}

impl BarrierPotential {
    /// Activation distance `dhat` (m) and stiffness `kappa` (J/m^4), both finite and > 0.
    pub fn try_new(dhat: f64, stiffness: f64) -> Result<Self> {
        if !(dhat.is_finite() && dhat > 0.0) {
            return Err(Error::invalid("dhat", "a finite distance > 0 (m)", dhat));
        }
        if !(stiffness.is_finite() && stiffness > 0.0) {
            return Err(Error::invalid(
                "barrier stiffness",
                "a finite value > 0 (J/m^4)",
                stiffness,
            ));
        }
        Ok(BarrierPotential { dhat, stiffness })
    }

    pub fn dhat(&self) -> f64 {
        self.dhat
    }

    pub fn stiffness(&self) -> f64 {
        self.stiffness
    }

    /// The same potential with another stiffness (the adaptive update changes it).
    pub fn with_stiffness(&self, stiffness: f64) -> Result<Self> {
        Self::try_new(self.dhat, stiffness)
    }

    /// Energy (J) of one stencil at the positions `local` of its vertices (as
    /// [`Candidate::positions`] gives them); when given, writes the gradient (`3 n`, N) and the
    /// Hessian (`3 n x 3 n` row-major, N/m), every entry. Returns `+inf` when the stencil touches
    /// or intersects (distance <= 0, or a vertex on the wrong side of a plane or inside a
    /// sphere), leaving the outputs unspecified. `HessianMode::Projected` clamps the negative
    /// eigenvalues of the stencil's Hessian to zero.
    pub fn stencil_energy(
        &self,
        mesh: &CollisionMesh,
        candidate: &Candidate,
        local: &[Vec3],
        mut grad: Option<&mut [f64]>,
        mut hess: Option<&mut [f64]>,
        mode: HessianMode,
    ) -> f64 {
        let size = 3 * local.len();
        if let Some(g) = grad.as_deref_mut() {
            g[..size].fill(0.0);
        }
        if let Some(h) = hess.as_deref_mut() {
            h[..size * size].fill(0.0);
        }
        let dhat2 = self.dhat * self.dhat;
        let x: Vec<&Vec3> = local.iter().collect();
        match *candidate {
            Candidate::PointTriangle { .. } => {
                let feature = point_triangle_feature(x[0], x[1], x[2], x[3]);
                let d = feature_distance(&feature, &x);
                if d <= 0.0 {
                    return f64::INFINITY;
                }
                if d >= dhat2 {
                    return 0.0;
                }
                self.feature_barrier(&feature, &x, grad, hess, mode)
            }
            Candidate::EdgeEdge { a, b } => {
                let feature = edge_edge_feature(x[0], x[1], x[2], x[3]);
                let d = feature_distance(&feature, &x);
                if d <= 0.0 {
                    return f64::INFINITY;
                }
                if d >= dhat2 {
                    return 0.0;
                }
                let rest = mesh.rest();
                let eps_x = edge_edge_mollifier_threshold(
                    &rest[a[0]],
                    &rest[a[1]],
                    &rest[b[0]],
                    &rest[b[1]],
                );
                let c = (x[1] - x[0]).cross(&(x[3] - x[2])).norm_squared();
                if c >= eps_x {
                    return self.feature_barrier(&feature, &x, grad, hess, mode);
                }
                let m = edge_edge_mollifier_derivatives(x[0], x[1], x[2], x[3], eps_x);
                let b = self.barrier_of(
                    &feature_distance_derivatives(&feature, &x),
                    HessianMode::Exact,
                );
                let mut hessian = b.hessian * m.value
                    + m.gradient * b.gradient.transpose()
                    + b.gradient * m.gradient.transpose()
                    + m.hessian * b.value;
                if mode == HessianMode::Projected {
                    project_translation_invariant_to_psd(&mut hessian);
                }
                let mollified = Derivatives {
                    value: m.value * b.value,
                    gradient: b.gradient * m.value + m.gradient * b.value,
                    hessian,
                };
                write(&mollified, &[0, 1, 2, 3], size, grad, hess);
                mollified.value
            }
            Candidate::PointPlane { obstacle, .. } => {
                let plane = mesh.plane(obstacle);
                let s = plane.signed_distance(x[0]);
                self.radial_barrier(s, None, &plane.normal, grad, hess, mode)
            }
            Candidate::PointSphere { obstacle, .. } => {
                let sphere = mesh.sphere(obstacle);
                let r = x[0] - sphere.center;
                let rho = r.norm();
                if rho == 0.0 {
                    return f64::INFINITY;
                }
                self.radial_barrier(rho - sphere.radius, Some(rho), &(r / rho), grad, hess, mode)
            }
            Candidate::TriangleSphere { obstacle, .. } => {
                let sphere = mesh.sphere(obstacle);
                let c = sphere.center;
                match point_triangle_feature(&c, x[0], x[1], x[2]) {
                    Feature::PointPlane(_) => {
                        let d = point_plane_distance_derivatives(&c, x[0], x[1], x[2]);
                        self.sphere_barrier::<12, 9>(&d, sphere.radius, grad, hess, mode)
                    }
                    // An edge or a vertex is closest: their own stencils count it.
                    other => inactive_sphere_stencil(&other, &[&c, x[0], x[1], x[2]], sphere),
                }
            }
            Candidate::EdgeSphere { obstacle, .. } => {
                let sphere = mesh.sphere(obstacle);
                let c = sphere.center;
                match point_edge_feature(&c, x[0], x[1], [0, 1, 2]) {
                    Feature::PointLine(_) => {
                        let d = point_line_distance_derivatives(&c, x[0], x[1]);
                        self.sphere_barrier::<9, 6>(&d, sphere.radius, grad, hess, mode)
                    }
                    other => inactive_sphere_stencil(&other, &[&c, x[0], x[1]], sphere),
                }
            }
        }
    }

    /// The barrier of a ball against a body feature, from the derivatives of the squared
    /// distance `d` between the ball's centre (the first three of the `N` coordinates, fixed)
    /// and the feature (the other `M = N - 3`): with the gap `s = sqrt(d) - r`,
    /// `grad s = grad d / (2 sqrt d)`, `hess s = hess d / (2 sqrt d) - grad d grad d^T / (4 d^1.5)`,
    /// gradient `2 kappa b'(s^2) s grad s` and Hessian
    /// `kappa ((4 s^2 b'' + 2 b') grad s grad s^T + 2 s b' hess s)`.
    fn sphere_barrier<const N: usize, const M: usize>(
        &self,
        d: &Derivatives<N>,
        radius: f64,
        grad: Option<&mut [f64]>,
        hess: Option<&mut [f64]>,
        mode: HessianMode,
    ) -> f64 {
        let root = d.value.sqrt();
        let s = root - radius;
        if s <= 0.0 {
            return f64::INFINITY;
        }
        let dhat2 = self.dhat * self.dhat;
        let gap2 = s * s;
        if gap2 >= dhat2 {
            return 0.0;
        }
        let k = self.stiffness;
        let (db, d2b) = (barrier_gradient(gap2, dhat2), barrier_hessian(gap2, dhat2));
        let g = d.gradient.fixed_rows::<M>(3).into_owned();
        let grad_s = g / (2.0 * root);
        if let Some(out) = grad {
            let value = grad_s * (2.0 * k * db * s);
            out[..M].copy_from_slice(value.as_slice());
        }
        if let Some(out) = hess {
            let h = d.hessian.fixed_view::<M, M>(3, 3).into_owned();
            let hess_s = h / (2.0 * root) - g * g.transpose() / (4.0 * root * d.value);
            let mut value = grad_s * grad_s.transpose() * (k * (4.0 * gap2 * d2b + 2.0 * db))
                + hess_s * (2.0 * k * s * db);
            if mode == HessianMode::Projected {
                project_to_psd(&mut value);
            }
            for i in 0..M {
                for j in 0..M {
                    out[i * M + j] = value[(i, j)];
                }
            }
        }
        k * barrier(gap2, dhat2)
    }

    /// The barrier of one feature distance, written into the stencil's outputs.
    fn feature_barrier(
        &self,
        feature: &Feature,
        x: &[&Vec3],
        grad: Option<&mut [f64]>,
        hess: Option<&mut [f64]>,
        mode: HessianMode,
    ) -> f64 {
        let size = 3 * x.len();
        let ids = feature.points();
        let p = |k: usize| x[ids[k]];
        if grad.is_none() && hess.is_none() {
            return self.stiffness * barrier(feature_distance(feature, x), self.dhat * self.dhat);
        }
        match feature {
            Feature::PointPoint(_) => {
                let b = self.barrier_of(&point_point_distance_derivatives(p(0), p(1)), mode);
                write(&b, ids, size, grad, hess);
                b.value
            }
            Feature::PointLine(_) => {
                let b = self.barrier_of(&point_line_distance_derivatives(p(0), p(1), p(2)), mode);
                write(&b, ids, size, grad, hess);
                b.value
            }
            Feature::PointPlane(_) => {
                let d = point_plane_distance_derivatives(p(0), p(1), p(2), p(3));
                let b = self.barrier_of(&d, mode);
                write(&b, ids, size, grad, hess);
                b.value
            }
            Feature::LineLine(_) => {
                let d = line_line_distance_derivatives(p(0), p(1), p(2), p(3));
                let b = self.barrier_of(&d, mode);
                write(&b, ids, size, grad, hess);
                b.value
            }
        }
    }

    /// `kappa b(d(x))` from the derivatives of `d`: gradient `kappa b' grad d`, Hessian
    /// `kappa (b'' grad d grad d^T + b' hess d)`.
    fn barrier_of<const N: usize>(&self, d: &Derivatives<N>, mode: HessianMode) -> Derivatives<N> {
        let dhat2 = self.dhat * self.dhat;
        let k = self.stiffness;
        let (db, d2b) = (
            barrier_gradient(d.value, dhat2),
            barrier_hessian(d.value, dhat2),
        );
        let mut hessian = d.gradient * d.gradient.transpose() * (k * d2b) + d.hessian * (k * db);
        if mode == HessianMode::Projected {
            project_translation_invariant_to_psd(&mut hessian);
        }
        Derivatives {
            value: k * barrier(d.value, dhat2),
            gradient: d.gradient * (k * db),
            hessian,
        }
    }

    /// The barrier of a one-vertex stencil whose distance is a signed `s` along the unit
    /// direction `q` (half-space: `rho = None`, the direction is fixed; ball: `rho = |x - c|`,
    /// `q = (x - c) / rho`). With `d = s^2`: gradient `2 kappa b' s q`, Hessian
    /// `kappa (4 s^2 b'' + 2 b') q q^T + 2 kappa b' (s / rho) (I - q q^T)`.
    fn radial_barrier(
        &self,
        s: f64,
        rho: Option<f64>,
        q: &Vec3,
        grad: Option<&mut [f64]>,
        hess: Option<&mut [f64]>,
        mode: HessianMode,
    ) -> f64 {
        if s <= 0.0 {
            return f64::INFINITY;
        }
        let dhat2 = self.dhat * self.dhat;
        let d = s * s;
        if d >= dhat2 {
            return 0.0;
        }
        let k = self.stiffness;
        let (db, d2b) = (barrier_gradient(d, dhat2), barrier_hessian(d, dhat2));
        if let Some(g) = grad {
            for i in 0..3 {
                g[i] = 2.0 * k * db * s * q[i];
            }
        }
        if let Some(h) = hess {
            let mut normal = k * (4.0 * d * d2b + 2.0 * db);
            let mut tangential = rho.map_or(0.0, |rho| 2.0 * k * db * s / rho);
            if mode == HessianMode::Projected {
                normal = normal.max(0.0);
                tangential = tangential.max(0.0);
            }
            let qq = q * q.transpose();
            let m = qq * normal + (Matrix3::identity() - qq) * tangential;
            for i in 0..3 {
                for j in 0..3 {
                    h[3 * i + j] = m[(i, j)];
                }
            }
        }
        k * barrier(d, dhat2)
    }

    /// Total energy (J) over the candidates at positions `x` (all vertices); `+inf` if any
    /// stencil touches or intersects.
    pub fn energy(&self, mesh: &CollisionMesh, candidates: &[Candidate], x: &[Vec3]) -> f64 {
        candidates
            .par_iter()
            .map(|c| {
                let (p, n) = c.positions(x);
                self.stencil_energy(mesh, c, &p[..n], None, None, HessianMode::Exact)
            })
            .sum()
    }

    /// Energy, gradient and stencil Hessians over the candidates at positions `x` (all
    /// vertices); the Hessians only when `hessian` is `Some`. Stencils farther than `dhat` are
    /// skipped. The energy is `+inf` (and the rest unspecified) if any stencil touches.
    pub fn assemble(
        &self,
        mesh: &CollisionMesh,
        candidates: &[Candidate],
        x: &[Vec3],
        hessian: Option<HessianMode>,
    ) -> Assembled {
        let dhat2 = self.dhat * self.dhat;
        let active: Vec<(f64, [f64; 12], StencilHessian)> = candidates
            .par_iter()
            .filter_map(|c| {
                let (p, n) = c.positions(x);
                if candidate_squared_distance(mesh, c, &p[..n]) >= dhat2 {
                    return None;
                }
                let mut g = [0.0; 12];
                let mut h = StencilHessian {
                    candidate: *c,
                    values: [0.0; 144],
                };
                let value = self.stencil_energy(
                    mesh,
                    c,
                    &p[..n],
                    Some(&mut g[..3 * n]),
                    hessian.is_some().then_some(&mut h.values[..9 * n * n]),
                    hessian.unwrap_or(HessianMode::Exact),
                );
                Some((value, g, h))
            })
            .collect();
        let mut out = Assembled {
            energy: 0.0,
            gradient: vec![0.0; 3 * x.len()],
            hessians: Vec::with_capacity(if hessian.is_some() { active.len() } else { 0 }),
        };
        for (value, g, h) in active {
            out.energy += value;
            let (ids, n) = h.candidate.vertices();
            for a in 0..n {
                for i in 0..3 {
                    out.gradient[3 * ids[a] + i] += g[3 * a + i];
                }
            }
            if hessian.is_some() {
                out.hessians.push(h);
            }
        }
        out
    }
}

/// The squared distance (m^2) the barrier of a stencil acts on, at the positions `local` of
/// its vertices: between the closest features for vertex-triangle and edge-edge stencils, the
/// squared signed distance for analytic obstacles, and 0 when a vertex is on the wrong side of
/// a plane or inside a sphere.
pub fn candidate_squared_distance(
    mesh: &CollisionMesh,
    candidate: &Candidate,
    local: &[Vec3],
) -> f64 {
    let s = candidate_distance(mesh, candidate, local);
    if s <= 0.0 {
        0.0
    } else {
        s * s
    }
}

/// The distance (m) of a stencil: unsigned between surface features, signed (negative when
/// penetrating) for analytic obstacles (for a ball against a triangle or an edge: the distance
/// from its centre to the nearest point of the feature, minus the radius).
pub fn candidate_distance(mesh: &CollisionMesh, candidate: &Candidate, local: &[Vec3]) -> f64 {
    let x: Vec<&Vec3> = local.iter().collect();
    match *candidate {
        Candidate::PointTriangle { .. } => {
            let feature = point_triangle_feature(x[0], x[1], x[2], x[3]);
            feature_distance(&feature, &x).sqrt()
        }
        Candidate::EdgeEdge { .. } => {
            let feature = edge_edge_feature(x[0], x[1], x[2], x[3]);
            feature_distance(&feature, &x).sqrt()
        }
        Candidate::PointPlane { obstacle, .. } => mesh.plane(obstacle).signed_distance(x[0]),
        Candidate::PointSphere { obstacle, .. } => mesh.sphere(obstacle).signed_distance(x[0]),
        Candidate::TriangleSphere { obstacle, .. } => {
            let sphere = mesh.sphere(obstacle);
            let feature = point_triangle_feature(&sphere.center, x[0], x[1], x[2]);
            feature_distance(&feature, &[&sphere.center, x[0], x[1], x[2]]).sqrt() - sphere.radius
        }
        Candidate::EdgeSphere { obstacle, .. } => {
            let sphere = mesh.sphere(obstacle);
            let feature = point_edge_feature(&sphere.center, x[0], x[1], [0, 1, 2]);
            feature_distance(&feature, &[&sphere.center, x[0], x[1]]).sqrt() - sphere.radius
        }
    }
}

/// A ball stencil whose closest body feature belongs to another stencil: no energy of its own,
/// `+inf` when the ball touches that feature.
fn inactive_sphere_stencil(
    feature: &Feature,
    x: &[&Vec3],
    sphere: &super::obstacle::Sphere,
) -> f64 {
    if feature_distance(feature, x).sqrt() - sphere.radius <= 0.0 {
        f64::INFINITY
    } else {
        0.0
    }
}

/// Whether an edge-edge stencil is mollified at these positions (for tests and diagnostics):
/// `|ea x eb|^2 < eps_x` from the rest positions.
pub fn is_mollified(mesh: &CollisionMesh, a: [usize; 2], b: [usize; 2], local: &[Vec3]) -> bool {
    let rest = mesh.rest();
    let eps_x = edge_edge_mollifier_threshold(&rest[a[0]], &rest[a[1]], &rest[b[0]], &rest[b[1]]);
    let c = (local[1] - local[0])
        .cross(&(local[3] - local[2]))
        .norm_squared();
    edge_edge_mollifier(c, eps_x).0 < 1.0
}

/// Adds the derivatives of a function of the stencil points `ids` into the stencil's outputs
/// (`size` coordinates).
fn write<const N: usize>(
    local: &Derivatives<N>,
    ids: &[usize],
    size: usize,
    grad: Option<&mut [f64]>,
    hess: Option<&mut [f64]>,
) {
    if let Some(g) = grad {
        for (a, &ia) in ids.iter().enumerate() {
            for i in 0..3 {
                g[3 * ia + i] = local.gradient[3 * a + i];
            }
        }
    }
    if let Some(h) = hess {
        for (a, &ia) in ids.iter().enumerate() {
            for (b, &ib) in ids.iter().enumerate() {
                for i in 0..3 {
                    for j in 0..3 {
                        h[(3 * ia + i) * size + 3 * ib + j] = local.hessian[(3 * a + i, 3 * b + j)];
                    }
                }
            }
        }
    }
}
