//! Smoothed lagged friction: the mollifier's derivatives, the lagged frames (closest-point
//! weights reproduce the distance, tangent bases are orthonormal and orthogonal to the normal),
//! stencil gradients and Hessians against central differences in the static and sliding
//! regimes, and Coulomb's law in the sliding limit.
mod common;

use common::{check_gradient, check_jacobian, Rng};
use nalgebra::DMatrix;
use sorofem_core::contact::barrier::normal_force_magnitude;
use sorofem_core::contact::friction::*;
use sorofem_core::contact::potential::candidate_squared_distance;
use sorofem_core::contact::{
    BarrierPotential, Candidate, CollisionMesh, Obstacle, Plane, Sphere, Vec3,
};
use sorofem_core::energy::HessianMode;

#[test]
fn mollifier_derivatives() {
    let eps = 2e-3;
    for k in 1..40 {
        let y = 2.0 * eps * k as f64 / 40.0 + 1e-5;
        let h = 1e-8;
        let fd0 = (friction_f0(y + h, eps) - friction_f0(y - h, eps)) / (2.0 * h);
        let fd1 = (friction_f1(y + h, eps) - friction_f1(y - h, eps)) / (2.0 * h);
        let f1 = friction_f1(y, eps);
        assert!((fd0 - f1).abs() < 1e-7, "f0' at {y}");
        let df1 = friction_f2(y, eps) * y * y + friction_f1_over_y(y, eps);
        assert!(
            (fd1 - df1).abs() < 1e-5 * (1.0 / eps),
            "f1' at {y}: {fd1} vs {df1}"
        );
        assert!((friction_f1_over_y(y, eps) * y - f1).abs() < 1e-14);
        assert!((0.0..=1.0).contains(&f1));
    }
    // C1 of f1 (so C2 of f0) at eps, and the limit 2 / eps of f1 / y at 0.
    let (below, above) = (eps * (1.0 - 1e-9), eps * (1.0 + 1e-9));
    assert!((friction_f0(below, eps) - friction_f0(above, eps)).abs() < 1e-11);
    assert!((friction_f1(below, eps) - friction_f1(above, eps)).abs() < 1e-8);
    assert_eq!(friction_f1_over_y(0.0, eps), 2.0 / eps);
}

fn mesh(rest: &[[f64; 3]]) -> CollisionMesh {
    CollisionMesh::try_new(
        rest,
        &[[0, 1, 2]],
        vec![
            Obstacle::Plane(Plane::try_new([0.0, 0.0, -0.2], [0.3, 0.1, 1.0]).unwrap()),
            Obstacle::Sphere(Sphere::try_new([0.1, -0.2, 0.0], 0.4).unwrap()),
        ],
        true,
    )
    .unwrap()
}

fn to_points(x: &[f64]) -> Vec<Vec3> {
    x.chunks_exact(3)
        .map(|p| Vec3::new(p[0], p[1], p[2]))
        .collect()
}

#[test]
fn lagged_frames_and_stencil_derivatives() {
    let mut rng = Rng::new(31);
    let rest: Vec<[f64; 3]> = (0..8)
        .map(|_| [rng.next(), rng.next(), rng.next()])
        .collect();
    let mesh = mesh(&rest);
    let barrier = BarrierPotential::try_new(0.5, 1e3).unwrap();
    let eps_u = 1e-3;
    let candidates = [
        Candidate::PointTriangle {
            point: 0,
            triangle: [1, 2, 3],
        },
        Candidate::EdgeEdge {
            a: [4, 5],
            b: [6, 7],
        },
        Candidate::PointPlane {
            point: 0,
            obstacle: 0,
        },
        Candidate::PointSphere {
            point: 0,
            obstacle: 1,
        },
    ];
    let mut counts = [0usize; 4];
    let mut features = std::collections::HashSet::new();
    let mut trials = 0;
    while counts.iter().any(|&c| c < 20) {
        trials += 1;
        assert!(trials < 20_000, "too few active stencils: {counts:?}");
        let x_t: Vec<Vec3> = (0..8)
            .map(|_| Vec3::new(rng.next(), rng.next(), rng.next()) * 0.6)
            .collect();
        for (slot, c) in candidates.iter().enumerate() {
            let (ids, n) = c.vertices();
            let local_t: Vec<Vec3> = ids[..n].iter().map(|&i| x_t[i]).collect();
            let d = candidate_squared_distance(&mesh, c, &local_t);
            if counts[slot] >= 20 || !(1e-3..=0.2).contains(&d) {
                continue;
            }
            let stencil = FrictionStencil::lag(&mesh, c, &x_t, &barrier, 0.4).unwrap();
            counts[slot] += 1;
            // Frame: orthonormal basis; for surface stencils the weighted closest points span
            // the distance and are orthogonal to the basis.
            let p = stencil.basis;
            assert!(
                (p.transpose() * p - nalgebra::Matrix2::identity())
                    .abs()
                    .max()
                    < 1e-12
            );
            if slot < 2 {
                let gap: Vec3 = (0..n).map(|a| stencil.weights[a] * local_t[a]).sum();
                assert!(
                    (gap.norm_squared() - d).abs() < 1e-10 * d.max(1e-3),
                    "{c:?}"
                );
                assert!(
                    (p.transpose() * gap).norm() < 1e-9 * gap.norm().max(1e-6),
                    "{c:?}"
                );
                let f = match c {
                    Candidate::PointTriangle { .. } => {
                        sorofem_core::contact::distance::point_triangle_feature(
                            &local_t[0],
                            &local_t[1],
                            &local_t[2],
                            &local_t[3],
                        )
                    }
                    _ => sorofem_core::contact::distance::edge_edge_feature(
                        &local_t[0],
                        &local_t[1],
                        &local_t[2],
                        &local_t[3],
                    ),
                };
                features.insert(std::mem::discriminant(&f));
            }
            let dhat2 = barrier.dhat().powi(2);
            assert_eq!(
                stencil.normal_force,
                normal_force_magnitude(d, dhat2, barrier.stiffness())
            );
            // Derivatives in both regimes: slips well below and well above eps_u.
            for amplitude in [0.2 * eps_u, 20.0 * eps_u] {
                let x: Vec<f64> = local_t
                    .iter()
                    .flat_map(|v| [v[0], v[1], v[2]])
                    .map(|v| v + amplitude * rng.next())
                    .collect();
                let size = x.len();
                let energy = |y: &[f64]| {
                    stencil.energy(&to_points(y), eps_u, None, None, HessianMode::Exact)
                };
                let gradient = |y: &[f64]| {
                    let mut g = vec![0.0; size];
                    stencil.energy(&to_points(y), eps_u, Some(&mut g), None, HessianMode::Exact);
                    g
                };
                let mut g = vec![f64::NAN; size];
                let mut h = vec![f64::NAN; size * size];
                stencil.energy(
                    &to_points(&x),
                    eps_u,
                    Some(&mut g),
                    Some(&mut h),
                    HessianMode::Exact,
                );
                let name = format!("{c:?} slip {amplitude}");
                check_gradient(&name, &x, 1e-9, energy, &g, 1e-5, 1e-9);
                check_jacobian(&name, &x, 1e-9, gradient, &h, 1e-5, 1e-6);
                let mut projected = vec![f64::NAN; size * size];
                stencil.energy(
                    &to_points(&x),
                    eps_u,
                    None,
                    Some(&mut projected),
                    HessianMode::Projected,
                );
                let scale = h.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                for (a, b) in h.iter().zip(&projected) {
                    assert!(
                        (a - b).abs() <= 1e-10 * scale,
                        "{name}: projection changed a PSD Hessian"
                    );
                }
                let lowest = DMatrix::from_row_slice(size, size, &h)
                    .symmetric_eigen()
                    .eigenvalues
                    .min();
                assert!(lowest >= -1e-10 * scale, "{name}: eigenvalue {lowest}");
            }
        }
    }
    assert_eq!(
        features.len(),
        4,
        "point-point, point-line, point-plane and line-line frames"
    );
}

#[test]
fn sliding_on_a_plane_follows_coulomb() {
    let mesh = CollisionMesh::try_new(
        &[[0.0, 0.0, 1e-3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        &[[0, 1, 2]],
        vec![Obstacle::Plane(
            Plane::try_new([0.0; 3], [0.0, 0.0, 1.0]).unwrap(),
        )],
        false,
    )
    .unwrap();
    let barrier = BarrierPotential::try_new(2e-3, 1e9).unwrap();
    let x_t = mesh.rest().to_vec();
    let c = Candidate::PointPlane {
        point: 0,
        obstacle: 0,
    };
    let mu = 0.5;
    let stencil = FrictionStencil::lag(&mesh, &c, &x_t, &barrier, mu).unwrap();
    let lambda = stencil.normal_force;
    assert!(lambda > 0.0);
    let eps_u = 1e-5;
    let direction = Vec3::new(0.6, -0.8, 0.0);
    for (slip, expected) in [(1e-3, mu * lambda), (0.5 * eps_u, mu * lambda * 0.75)] {
        // A normal motion does not count: only the tangential part slips.
        let x = [x_t[0] + slip * direction + Vec3::new(0.0, 0.0, 3e-4)];
        let mut g = [0.0; 3];
        stencil.energy(&x, eps_u, Some(&mut g), None, HessianMode::Exact);
        let force = -Vec3::from(g);
        assert!(
            (force.norm() - expected).abs() < 1e-12 * expected,
            "slip {slip}: {force:?}"
        );
        assert!(
            (force.normalize() + direction).norm() < 1e-12,
            "opposes the slip"
        );
    }
}
