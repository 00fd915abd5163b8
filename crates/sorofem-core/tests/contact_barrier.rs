//! The barrier, its adaptive stiffness and the stencil potential: derivatives against central
//! differences (vertex-triangle, edge-edge with and without the mollifier, plane, sphere, and
//! the assembled sum), and the PSD projection of stencil Hessians.
mod common;

use common::{check_gradient, check_jacobian, contact_scene, Rng};
use nalgebra::{DMatrix, SMatrix};
use sorofem_core::contact::barrier::*;
use sorofem_core::contact::broad_phase::candidates;
use sorofem_core::contact::distance::Vec3;
use sorofem_core::contact::potential::{candidate_squared_distance, is_mollified};
use sorofem_core::contact::{
    project_to_psd, project_translation_invariant_to_psd, symmetric_eigen, BarrierPotential,
    Candidate, CollisionMesh, Obstacle, Plane, Sphere,
};
use sorofem_core::energy::HessianMode;

#[test]
fn barrier_derivatives_and_smoothness_at_dhat() {
    let dhat2 = 1e-6;
    for k in 1..60 {
        let d = dhat2 * k as f64 / 60.0;
        let h = 1e-7 * d;
        let fd1 = (barrier(d + h, dhat2) - barrier(d - h, dhat2)) / (2.0 * h);
        let fd2 = (barrier_gradient(d + h, dhat2) - barrier_gradient(d - h, dhat2)) / (2.0 * h);
        let (g, hh) = (barrier_gradient(d, dhat2), barrier_hessian(d, dhat2));
        assert!(
            (fd1 - g).abs() <= 1e-6 * g.abs().max(1e-12),
            "b' at {d}: {fd1} vs {g}"
        );
        assert!(
            (fd2 - hh).abs() <= 1e-6 * hh.abs().max(1e-6),
            "b'' at {d}: {fd2} vs {hh}"
        );
        assert!(barrier(d, dhat2) > 0.0 && g < 0.0 && hh > 0.0);
    }
    // C2 at dhat: with d = dhat2 (1 - e), b ~ e^3 dhat2^2, b' ~ -3 e^2 dhat2 and b'' ~ 6 e.
    let e = 1e-6;
    let below = dhat2 * (1.0 - e);
    assert!(barrier(below, dhat2) < 2.0 * e.powi(3) * dhat2 * dhat2);
    assert!((barrier_gradient(below, dhat2) / (-3.0 * e * e * dhat2) - 1.0).abs() < 1e-3);
    assert!((barrier_hessian(below, dhat2) / (6.0 * e) - 1.0).abs() < 1e-3);
    assert_eq!(barrier(dhat2, dhat2), 0.0);
    assert_eq!(barrier(0.0, dhat2), f64::INFINITY);
    // The normal force is the derivative of the energy along the unsquared distance.
    let (kappa, s) = (3e4, 4e-4);
    let force = normal_force_magnitude(s * s, dhat2, kappa);
    let h = 1e-9;
    let fd = -(kappa * barrier((s + h).powi(2), dhat2) - kappa * barrier((s - h).powi(2), dhat2))
        / (2.0 * h);
    assert!((force - fd).abs() < 1e-6 * force, "{force} vs {fd}");
}

#[test]
fn adaptive_stiffness() {
    let bounds = StiffnessBounds::new(0.5, 1e-3, 0.02, 1e11);
    assert!(bounds.min > 0.0 && (bounds.max / bounds.min - 100.0).abs() < 1e-12);
    // The initial stiffness cancels the other forces along the barrier gradient.
    let grad_barrier = [1.0, -2.0, 0.5, 0.0];
    for target in [2.0 * bounds.min, 10.0 * bounds.min, 99.0 * bounds.min] {
        let grad_energy: Vec<f64> = grad_barrier
            .iter()
            .zip([0.3, 0.1, -0.2, 5.0])
            .map(|(g, orthogonal_part)| -target * g + orthogonal_part * bounds.min)
            .collect();
        let kappa = initial_barrier_stiffness(&grad_energy, &grad_barrier, bounds);
        // The orthogonal part is orthogonal: 0.3 - 0.2 - 0.1 + 0 = 0.
        assert!(
            (kappa - target).abs() < 1e-10 * target,
            "{kappa} vs {target}"
        );
    }
    let pushing: Vec<f64> = grad_barrier.iter().map(|g| g * bounds.min).collect();
    assert_eq!(
        initial_barrier_stiffness(&pushing, &grad_barrier, bounds),
        bounds.min
    );
    let strong: Vec<f64> = grad_barrier.iter().map(|g| -1e3 * g * bounds.min).collect();
    assert_eq!(
        initial_barrier_stiffness(&strong, &grad_barrier, bounds),
        bounds.max
    );
    assert_eq!(
        initial_barrier_stiffness(&strong, &[0.0; 4], bounds),
        bounds.min
    );
    // Doubling only while the minimum distance is tiny and shrinking, up to the maximum.
    let (diag, scale): (f64, f64) = (0.5, 1e-9);
    let tiny = (0.1 * scale * diag).powi(2);
    assert_eq!(
        update_barrier_stiffness(tiny, 0.5 * tiny, 3.0, 100.0, diag, scale),
        6.0
    );
    assert_eq!(
        update_barrier_stiffness(tiny, 2.0 * tiny, 3.0, 100.0, diag, scale),
        3.0
    );
    assert_eq!(
        update_barrier_stiffness(1.0, 0.5 * tiny, 3.0, 100.0, diag, scale),
        3.0
    );
    assert_eq!(
        update_barrier_stiffness(tiny, 0.5 * tiny, 80.0, 100.0, diag, scale),
        100.0
    );
}

/// A collision mesh whose rest positions (nodes 0..8) set the mollifier thresholds, with a plane
/// (obstacle 0) and a sphere (obstacle 1).
fn stencil_mesh(rest: &[[f64; 3]]) -> CollisionMesh {
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

/// The stencil's gradient and both Hessians (exact: against differences of the gradient;
/// projected: PSD, equal to the eigenvalue clamp of the exact one).
fn check_stencil(
    name: &str,
    potential: &BarrierPotential,
    mesh: &CollisionMesh,
    c: &Candidate,
    x: &[f64],
) {
    let n = x.len();
    let energy = |y: &[f64]| {
        potential.stencil_energy(mesh, c, &to_points(y), None, None, HessianMode::Exact)
    };
    let gradient = |y: &[f64]| {
        let mut g = vec![0.0; n];
        potential.stencil_energy(
            mesh,
            c,
            &to_points(y),
            Some(&mut g),
            None,
            HessianMode::Exact,
        );
        g
    };
    let mut g = vec![f64::NAN; n];
    let mut h = vec![f64::NAN; n * n];
    let value = potential.stencil_energy(
        mesh,
        c,
        &to_points(x),
        Some(&mut g),
        Some(&mut h),
        HessianMode::Exact,
    );
    assert!(
        value > 0.0 && value.is_finite(),
        "{name}: inactive or touching ({value})"
    );
    check_gradient(
        &format!("{name} gradient"),
        x,
        1e-7,
        energy,
        &g,
        1e-5,
        1e-10,
    );
    check_jacobian(
        &format!("{name} Hessian"),
        x,
        1e-7,
        gradient,
        &h,
        1e-5,
        1e-8,
    );
    let mut projected = vec![f64::NAN; n * n];
    potential.stencil_energy(
        mesh,
        c,
        &to_points(x),
        None,
        Some(&mut projected),
        HessianMode::Projected,
    );
    let exact = DMatrix::from_row_slice(n, n, &h);
    let reference = {
        let eig = exact.clone().symmetric_eigen();
        let clamped = eig.eigenvalues.map(|l| l.max(0.0));
        &eig.eigenvectors * DMatrix::from_diagonal(&clamped) * eig.eigenvectors.transpose()
    };
    let projected = DMatrix::from_row_slice(n, n, &projected);
    let scale = exact.abs().max();
    assert!(
        (&projected - &reference).abs().max() <= 1e-9 * scale,
        "{name}: projected Hessian differs from the clamped exact one"
    );
    let lowest = projected.symmetric_eigen().eigenvalues.min();
    assert!(
        lowest >= -1e-12 * scale,
        "{name}: projected eigenvalue {lowest}"
    );
}

#[test]
fn stencil_derivatives_match_finite_differences() {
    let mut rng = Rng::new(7);
    let rest: Vec<[f64; 3]> = (0..8)
        .map(|_| [rng.next(), rng.next(), rng.next()])
        .collect();
    let mesh = stencil_mesh(&rest);
    let potential = BarrierPotential::try_new(0.5, 1e3).unwrap();
    let dhat2 = 0.25;
    let mut counts = [0usize; 7];
    let mut trials = 0;
    while counts.iter().any(|&c| c < 15) {
        trials += 1;
        assert!(
            trials < 20_000,
            "too few active random stencils: {counts:?}"
        );
        let x = rng.vec(12, 0.6);
        let p = to_points(&x);
        let pt = Candidate::PointTriangle {
            point: 0,
            triangle: [1, 2, 3],
        };
        let ee = Candidate::EdgeEdge {
            a: [4, 5],
            b: [6, 7],
        };
        for (slot, c, size) in [(0, pt, 12), (1, ee, 12)] {
            let d = candidate_squared_distance(&mesh, &c, &p);
            if d > 1e-3 * dhat2 && d < 0.9 * dhat2 && counts[slot] < 15 {
                check_stencil(&format!("{c:?}"), &potential, &mesh, &c, &x[..size]);
                counts[slot] += 1;
            }
        }
        // Nearly parallel edges under the mollifier threshold (from the rest edges 4-5, 6-7).
        let ea = Vec3::from(rest[5]) - Vec3::from(rest[4]);
        let offset = Vec3::new(rng.next(), rng.next(), rng.next()) * 0.3;
        let twist = Vec3::new(rng.next(), rng.next(), rng.next()) * 0.02;
        let near: Vec<Vec3> = vec![
            p[0],
            p[0] + ea,
            p[0] + offset,
            p[0] + offset + ea * 0.8 + twist,
        ];
        let flat: Vec<f64> = near.iter().flat_map(|v| [v[0], v[1], v[2]]).collect();
        let d = candidate_squared_distance(&mesh, &ee, &near);
        if is_mollified(&mesh, [4, 5], [6, 7], &near)
            && d > 1e-3 * dhat2
            && d < 0.9 * dhat2
            && counts[2] < 15
        {
            check_stencil("mollified edge-edge", &potential, &mesh, &ee, &flat);
            counts[2] += 1;
        }
        // A ball against a triangle and an edge whose interiors are closest to its centre.
        for (slot, c, size) in [
            (
                5,
                Candidate::TriangleSphere {
                    triangle: [0, 1, 2],
                    obstacle: 1,
                },
                9,
            ),
            (
                6,
                Candidate::EdgeSphere {
                    edge: [0, 1],
                    obstacle: 1,
                },
                6,
            ),
        ] {
            let s = sorofem_core::contact::potential::candidate_distance(&mesh, &c, &p[..size / 3]);
            let mut g = vec![0.0; size];
            let active = potential.stencil_energy(
                &mesh,
                &c,
                &p[..size / 3],
                Some(&mut g),
                None,
                HessianMode::Exact,
            ) > 0.0;
            if active && s > 0.03 && s < 0.45 && counts[slot] < 15 {
                check_stencil(&format!("{c:?}"), &potential, &mesh, &c, &x[..size]);
                counts[slot] += 1;
            }
        }
        for (slot, obstacle) in [(3, 0), (4, 1)] {
            let c = if obstacle == 0 {
                Candidate::PointPlane { point: 0, obstacle }
            } else {
                Candidate::PointSphere { point: 0, obstacle }
            };
            let s = sorofem_core::contact::potential::candidate_distance(&mesh, &c, &p[..1]);
            if s > 0.03 && s < 0.45 && counts[slot] < 15 {
                check_stencil(&format!("{c:?}"), &potential, &mesh, &c, &x[..3]);
                counts[slot] += 1;
            }
        }
    }
}

/// The fixed-size eigensolver reconstructs random, rank-deficient and repeated-eigenvalue
/// symmetric matrices with orthonormal eigenvectors.
#[test]
fn symmetric_eigensolver() {
    let mut rng = Rng::new(13);
    let check = |a: &SMatrix<f64, 12, 12>, name: &str| {
        let rows: [[f64; 12]; 12] = std::array::from_fn(|i| std::array::from_fn(|j| a[(i, j)]));
        let (w, q) = symmetric_eigen(&rows);
        let q = SMatrix::<f64, 12, 12>::from_fn(|i, j| q[i][j]);
        let w = SMatrix::<f64, 12, 12>::from_diagonal(&w.into());
        let scale = a.abs().max().max(1e-300);
        assert!(
            (q * w * q.transpose() - a).abs().max() <= 1e-13 * scale,
            "{name}: reconstruction"
        );
        assert!(
            (q.transpose() * q - SMatrix::<f64, 12, 12>::identity())
                .abs()
                .max()
                <= 1e-13,
            "{name}: orthonormality"
        );
    };
    for trial in 0..100 {
        let a = SMatrix::<f64, 12, 12>::from_fn(|_, _| rng.next());
        check(&(a + a.transpose()), &format!("random {trial}"));
        let b = SMatrix::<f64, 4, 12>::from_fn(|_, _| rng.next());
        check(&(b.transpose() * b), &format!("rank 4, {trial}"));
        // Eigenvalues -1 (x3), 0 (x5), 2 (x4) in a random basis.
        let sym = a + a.transpose();
        let rows: [[f64; 12]; 12] = std::array::from_fn(|i| std::array::from_fn(|j| sym[(i, j)]));
        let (_, basis) = symmetric_eigen(&rows);
        let v = SMatrix::<f64, 12, 12>::from_fn(|i, j| basis[i][j]);
        let d = SMatrix::<f64, 12, 12>::from_fn(|i, j| {
            if i != j {
                0.0
            } else if i < 3 {
                -1.0
            } else if i < 8 {
                0.0
            } else {
                2.0
            }
        });
        check(&(v * d * v.transpose()), &format!("repeated {trial}"));
    }
    check(&SMatrix::<f64, 12, 12>::zeros(), "zero");
    check(&SMatrix::<f64, 12, 12>::identity(), "identity");
}

#[test]
fn projection_clamps_negative_eigenvalues_and_keeps_psd_matrices() {
    let mut rng = Rng::new(11);
    for _ in 0..50 {
        let a = SMatrix::<f64, 12, 12>::from_fn(|_, _| rng.next());
        let mut symmetric = a + a.transpose();
        let scale = symmetric.abs().max();
        project_to_psd(&mut symmetric);
        let lowest = symmetric.symmetric_eigen().eigenvalues.min();
        assert!(
            lowest >= -1e-12 * scale,
            "eigenvalue {lowest} after projection"
        );
        // Already PSD (here of rank 6): unchanged.
        let b = SMatrix::<f64, 6, 12>::from_fn(|_, _| rng.next());
        let psd = b.transpose() * b;
        let mut projected = psd;
        project_to_psd(&mut projected);
        assert!((projected - psd).abs().max() <= 1e-12 * psd.abs().max());
        // A matrix zero on rigid translations (as distance Hessians are): the reduced
        // projection equals the full one.
        let mut c = SMatrix::<f64, 12, 9>::zeros();
        for a in 0..3 {
            for i in 0..3 {
                for p in 0..4 {
                    // Column (a, i) of a basis orthogonal to translations: point weights summing to 0.
                    let weight = [
                        [1.0, -1.0, 0.0, 0.0],
                        [0.5, 0.5, -2.0, 1.0],
                        [0.3, -1.2, 0.2, 0.7],
                    ][a][p];
                    c[(3 * p + i, 3 * a + i)] = weight * (1.0 + 0.1 * rng.next());
                }
            }
        }
        // Re-centre each column's point weights so they sum to zero exactly.
        for col in 0..9 {
            let i = col % 3;
            let mean = (0..4).map(|p| c[(3 * p + i, col)]).sum::<f64>() / 4.0;
            for p in 0..4 {
                c[(3 * p + i, col)] -= mean;
            }
        }
        let core = SMatrix::<f64, 9, 9>::from_fn(|_, _| rng.next());
        let invariant = c * (core + core.transpose()) * c.transpose();
        let (mut full, mut reduced) = (invariant, invariant);
        project_to_psd(&mut full);
        project_translation_invariant_to_psd(&mut reduced);
        assert!((full - reduced).abs().max() <= 1e-12 * invariant.abs().max());
    }
}

#[test]
fn assembled_gradient_and_hessian_match_finite_differences() {
    let (mesh, collision) = contact_scene(2, true);
    let potential = BarrierPotential::try_new(0.005, 1e8).unwrap();
    let mut rng = Rng::new(3);
    let body: Vec<f64> = mesh
        .rest_flat()
        .iter()
        .map(|v| v + 5e-4 * rng.next())
        .collect();
    let x = collision.vertices(&body).unwrap();
    let found = candidates(&collision, &x, potential.dhat());
    let kinds = |f: fn(&Candidate) -> bool| found.iter().filter(|c| f(c)).count();
    assert!(kinds(|c| matches!(c, Candidate::PointPlane { .. })) > 0);
    assert!(kinds(|c| matches!(c, Candidate::PointSphere { .. })) > 0);
    assert!(kinds(|c| matches!(c, Candidate::PointTriangle { .. })) > 0);
    assert!(kinds(|c| matches!(c, Candidate::EdgeEdge { .. })) > 0);
    let assembled = potential.assemble(&collision, &found, &x, Some(HessianMode::Exact));
    assert!(assembled.energy > 0.0 && assembled.energy.is_finite());
    let n = 3 * mesh.n_nodes();
    let energy = |y: &[f64]| {
        let x = collision.vertices(y).unwrap();
        potential.energy(&collision, &found, &x)
    };
    check_gradient(
        "assembled gradient",
        &body,
        1e-7,
        energy,
        &assembled.gradient[..n],
        1e-5,
        1e-8,
    );
    let mut dense = vec![0.0; n * n];
    for (r, c, v) in assembled.hessians.iter().flat_map(|h| h.entries()) {
        if r < n && c < n {
            dense[r * n + c] += v;
        }
    }
    let gradient = |y: &[f64]| {
        let x = collision.vertices(y).unwrap();
        potential.assemble(&collision, &found, &x, None).gradient[..n].to_vec()
    };
    check_jacobian(
        "assembled Hessian",
        &body,
        1e-7,
        gradient,
        &dense,
        1e-5,
        1e-2,
    );
}

/// A contact term's barrier at unit stiffness (what IPC's balanced stiffness and its
/// derivatives read): its Hessian over the body's DOFs, applied by `hessian_product` to each
/// unit vector, against central differences of its gradient, for a block within `dhat` of a
/// tilted plane below and a sphere above (the obstacles' rows are not DOFs and are left out).
#[test]
fn unit_barrier_hessian_product_matches_central_differences() {
    use sorofem_core::contact::{ContactSetup, ContactTerm, ObstacleSpec};
    use sorofem_core::TetMesh;
    let lift = 2e-4;
    let mesh = TetMesh::box_mesh([0.1; 3], [3; 3], [0.0, 0.0, lift]).unwrap();
    let obstacle = |obstacle| ObstacleSpec {
        obstacle,
        friction: 0.0,
        path: Vec::new(),
    };
    let radius = 0.02;
    let setup = ContactSetup {
        obstacles: vec![
            obstacle(Obstacle::Plane(
                Plane::try_new([0.0, 0.0, 0.0], [0.002, 0.001, 1.0]).unwrap(),
            )),
            obstacle(Obstacle::Sphere(
                Sphere::try_new([0.05, 0.05, 0.1 + lift + 3e-4 + radius], radius).unwrap(),
            )),
        ],
        dhat: Some(1e-3),
        ..Default::default()
    };
    let term = ContactTerm::try_new(&mesh, setup).unwrap();
    let mut rng = Rng::new(11);
    let n3 = 3 * mesh.n_nodes();
    let z = rng.vec(n3, 2e-5);
    let at = term.unit_barrier(&z, true);
    assert!(at.finite && at.hessians.len() > 4, "too little within dhat");
    // Column j of the Hessian is its product with the unit vector e_j (row-major: symmetric).
    let mut hessian = vec![0.0; n3 * n3];
    for j in 0..n3 {
        let mut unit = vec![0.0; n3];
        unit[j] = 1.0;
        for (i, value) in at.hessian_product(&unit).into_iter().enumerate() {
            hessian[i * n3 + j] = value;
        }
    }
    check_jacobian(
        "unit barrier Hessian",
        &z,
        1e-8,
        |x| term.unit_barrier(x, false).gradient,
        &hessian,
        1e-5,
        0.0,
    );
}
