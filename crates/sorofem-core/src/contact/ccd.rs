//! Continuous collision detection along linear trajectories `x(t) = x0 + t dx`, `t` in [0, 1].
//!
//! Every function returns `None` when the stencil's distance stays above `eta d0` over the whole
//! step (`d0` its initial distance, `eta` in (0, 1) the minimum separation fraction), and
//! otherwise `Some(t)`: a time up to which the motion is safe, never later than the first
//! contact, at which the distance is still at least about `eta d0`. Analytic for a vertex
//! against a half-space or a ball (`t` is then exactly where the distance reaches `eta d0`, and
//! `eta = 0` gives the exact time of impact); additive CCD (Li, Kaufman and Jiang 2021) for
//! vertex-triangle and edge-edge stencils, which advances by steps `(1 - eta) d / l` (`l` a bound
//! on the rate at which the distance can shrink) and so can never step over a contact.
//! A stencil already touching (distance <= 0) returns `Some(0)`.

use super::collision_mesh::{Candidate, CollisionMesh};
use super::distance::{
    edge_edge_distance, feature_distance, point_edge_feature, point_triangle_distance, Vec3,
};
use super::obstacle::{Plane, Sphere};
use rayon::prelude::*;

/// IPC's minimum separation fraction (its additive CCD's conservative rescaling is 0.9).
pub const DEFAULT_MIN_SEPARATION: f64 = 0.1;

/// Additive CCD stops here (returning the safe time reached so far): grazing motions much longer
/// than the distance take `l / (eta (1 - eta) d0)` steps.
const MAX_ADDITIVE_STEPS: usize = 100_000;

/// Time at which the signed distance of `p0 + t dp` to the plane reaches `eta s0`.
pub fn point_plane_toi(p0: &Vec3, dp: &Vec3, plane: &Plane, eta: f64) -> Option<f64> {
    let s0 = plane.signed_distance(p0);
    if s0 <= 0.0 {
        return Some(0.0);
    }
    let rate = plane.normal.dot(dp);
    if rate >= 0.0 {
        return None;
    }
    let t = (1.0 - eta) * s0 / -rate;
    (t <= 1.0).then_some(t)
}

/// Time at which the distance of `p0 + t dp` to the sphere's surface reaches `eta s0`: the
/// first root of `|p0 + t dp - c|^2 = (r + eta s0)^2`.
pub fn point_sphere_toi(p0: &Vec3, dp: &Vec3, sphere: &Sphere, eta: f64) -> Option<f64> {
    let w = p0 - sphere.center;
    let s0 = w.norm() - sphere.radius;
    if s0 <= 0.0 {
        return Some(0.0);
    }
    let target = sphere.radius + eta * s0;
    let a = dp.norm_squared();
    let b = w.dot(dp);
    let c = w.norm_squared() - target * target;
    let discriminant = b * b - a * c;
    if b >= 0.0 || discriminant < 0.0 {
        return None;
    }
    // The smaller root, in the form that does not cancel (-b > 0, c > 0).
    let t = c / (-b + discriminant.sqrt());
    (t <= 1.0).then_some(t)
}

/// Additive CCD of a point `x[0]` and a triangle `x[1..4]` moving by `dx`.
pub fn point_triangle_toi(x: &[Vec3; 4], dx: &[Vec3; 4], eta: f64) -> Option<f64> {
    let d = centered(dx);
    let rate = d[0].norm() + d[1].norm().max(d[2].norm()).max(d[3].norm());
    additive_ccd(x, &d, rate, eta, |y| {
        point_triangle_distance(&y[0], &y[1], &y[2], &y[3])
    })
}

/// Additive CCD of the edges `x[0..2]` and `x[2..4]` moving by `dx`.
pub fn edge_edge_toi(x: &[Vec3; 4], dx: &[Vec3; 4], eta: f64) -> Option<f64> {
    let d = centered(dx);
    let rate = d[0].norm().max(d[1].norm()) + d[2].norm().max(d[3].norm());
    additive_ccd(x, &d, rate, eta, |y| {
        edge_edge_distance(&y[0], &y[1], &y[2], &y[3])
    })
}

/// Additive CCD of a ball (fixed) against a body triangle `x` moving by `dx`: the gap is the
/// distance from the centre to the triangle minus the radius, and it shrinks no faster than the
/// fastest vertex moves.
pub fn sphere_triangle_toi(
    sphere: &Sphere,
    x: &[Vec3; 3],
    dx: &[Vec3; 3],
    eta: f64,
) -> Option<f64> {
    let rate = dx.iter().map(|d| d.norm()).fold(0.0, f64::max);
    let y = [sphere.center, x[0], x[1], x[2]];
    let dy = [Vec3::zeros(), dx[0], dx[1], dx[2]];
    additive_ccd(&y, &dy, rate, eta, |y| {
        let gap = point_triangle_distance(&y[0], &y[1], &y[2], &y[3]).sqrt() - sphere.radius;
        gap.max(0.0).powi(2)
    })
}

/// [`sphere_triangle_toi`] for a body edge `x` moving by `dx`.
pub fn sphere_edge_toi(sphere: &Sphere, x: &[Vec3; 2], dx: &[Vec3; 2], eta: f64) -> Option<f64> {
    let rate = dx[0].norm().max(dx[1].norm());
    let y = [sphere.center, x[0], x[1], x[1]];
    let dy = [Vec3::zeros(), dx[0], dx[1], dx[1]];
    additive_ccd(&y, &dy, rate, eta, |y| {
        let feature = point_edge_feature(&y[0], &y[1], &y[2], [0, 1, 2]);
        let gap = feature_distance(&feature, &[&y[0], &y[1], &y[2]]).sqrt() - sphere.radius;
        gap.max(0.0).powi(2)
    })
}

/// The displacements minus their mean: distances do not change under a common translation, and
/// the centred ones give a tighter rate bound.
fn centered(dx: &[Vec3; 4]) -> [Vec3; 4] {
    let mean = (dx[0] + dx[1] + dx[2] + dx[3]) / 4.0;
    dx.map(|d| d - mean)
}

/// Advances `t` by `(1 - eta) d(t) / rate` (`rate` bounds `|d'(t)|`, so no contact is skipped)
/// until the distance at the next step would drop below `eta d0`.
fn additive_ccd(
    x0: &[Vec3; 4],
    dx: &[Vec3; 4],
    rate: f64,
    eta: f64,
    distance_squared: impl Fn(&[Vec3; 4]) -> f64,
) -> Option<f64> {
    let mut d = distance_squared(x0).sqrt();
    if d <= 0.0 {
        return Some(0.0);
    }
    if rate == 0.0 {
        return None;
    }
    let gap = eta * d;
    let mut t = 0.0;
    for _ in 0..MAX_ADDITIVE_STEPS {
        let step = (1.0 - eta) * d / rate;
        let next = t + step;
        let x: [Vec3; 4] = std::array::from_fn(|a| x0[a] + next * dx[a]);
        d = distance_squared(&x).sqrt();
        // The first step keeps d >= eta d0 by construction; later ones stop before dropping below.
        if t > 0.0 && d < gap {
            return Some(t);
        }
        t = next;
        if t > 1.0 {
            return None;
        }
    }
    Some(t)
}

/// CCD of one candidate for the motion of all vertices from `x0` by `dx`.
pub fn candidate_toi(
    mesh: &CollisionMesh,
    candidate: &Candidate,
    x0: &[Vec3],
    dx: &[Vec3],
    eta: f64,
) -> Option<f64> {
    let (ids, n) = candidate.vertices();
    let p: [Vec3; 4] = std::array::from_fn(|a| if a < n { x0[ids[a]] } else { Vec3::zeros() });
    let d: [Vec3; 4] = std::array::from_fn(|a| if a < n { dx[ids[a]] } else { Vec3::zeros() });
    match *candidate {
        Candidate::PointTriangle { .. } => point_triangle_toi(&p, &d, eta),
        Candidate::EdgeEdge { .. } => edge_edge_toi(&p, &d, eta),
        Candidate::PointPlane { obstacle, .. } => {
            point_plane_toi(&p[0], &d[0], mesh.plane(obstacle), eta)
        }
        Candidate::PointSphere { obstacle, .. } => {
            point_sphere_toi(&p[0], &d[0], mesh.sphere(obstacle), eta)
        }
        Candidate::TriangleSphere { obstacle, .. } => sphere_triangle_toi(
            mesh.sphere(obstacle),
            &[p[0], p[1], p[2]],
            &[d[0], d[1], d[2]],
            eta,
        ),
        Candidate::EdgeSphere { obstacle, .. } => {
            sphere_edge_toi(mesh.sphere(obstacle), &[p[0], p[1]], &[d[0], d[1]], eta)
        }
    }
}

/// The largest step `alpha` in [0, 1] such that moving every vertex from `x0` by `alpha dx` keeps
/// every candidate apart (at least about `eta` times its initial distance): the bound a line
/// search starts from. `candidates` must cover the motion ([`super::broad_phase::swept_candidates`]
/// from `x0` to `x0 + dx`).
pub fn max_step(
    mesh: &CollisionMesh,
    candidates: &[Candidate],
    x0: &[Vec3],
    dx: &[Vec3],
    eta: f64,
) -> f64 {
    candidates
        .par_iter()
        .filter_map(|c| candidate_toi(mesh, c, x0, dx, eta))
        .reduce(|| 1.0, f64::min)
}
