//! Contact distances: every gradient and Hessian against central differences on random
//! configurations, near the closest-feature boundaries and for nearly parallel edges; the
//! classified point-triangle and edge-edge distances against dense sampling of the primitives.
mod common;

use common::{check_gradient, check_jacobian, Rng};
use sorofem_core::contact::distance::*;

/// Central-difference step (relative to max(1, |x|)).
const H: f64 = 1e-6;

fn points(x: &[f64]) -> Vec<Vec3> {
    x.chunks_exact(3)
        .map(|p| Vec3::new(p[0], p[1], p[2]))
        .collect()
}

/// Checks `derivatives(x)` (value, gradient, Hessian) of a function of the points `x` against
/// central differences of its value and gradient.
fn check_derivatives<const N: usize>(
    name: &str,
    x0: &[f64],
    h: f64,
    derivatives: impl Fn(&[Vec3]) -> Derivatives<N>,
) {
    let d = derivatives(&points(x0));
    check_gradient(
        &format!("{name} gradient"),
        x0,
        h,
        |x| derivatives(&points(x)).value,
        d.gradient.as_slice(),
        1e-6,
        1e-12,
    );
    // Row-major Hessian; the matrix is symmetric, so the column-major slice serves as well.
    check_jacobian(
        &format!("{name} Hessian"),
        x0,
        h,
        |x| derivatives(&points(x)).gradient.as_slice().to_vec(),
        d.hessian.as_slice(),
        1e-6,
        1e-10,
    );
    assert!(
        (d.hessian - d.hessian.transpose()).abs().max() <= 1e-12 * d.hessian.abs().max(),
        "{name}: Hessian not symmetric"
    );
}

#[test]
fn primitive_distance_derivatives_match_finite_differences() {
    let mut rng = Rng::new(1);
    for trial in 0..40 {
        let x = rng.vec(12, 1.0);
        check_derivatives(&format!("point-point {trial}"), &x[..6], H, |p| {
            point_point_distance_derivatives(&p[0], &p[1])
        });
        check_derivatives(&format!("point-line {trial}"), &x[..9], H, |p| {
            point_line_distance_derivatives(&p[0], &p[1], &p[2])
        });
        check_derivatives(&format!("point-plane {trial}"), &x, H, |p| {
            point_plane_distance_derivatives(&p[0], &p[1], &p[2], &p[3])
        });
        check_derivatives(&format!("line-line {trial}"), &x, H, |p| {
            line_line_distance_derivatives(&p[0], &p[1], &p[2], &p[3])
        });
        check_derivatives(&format!("edge cross norm {trial}"), &x, H, |p| {
            edge_edge_cross_squared_norm_derivatives(&p[0], &p[1], &p[2], &p[3])
        });
        // The values agree with independent formulas.
        let p = points(&x);
        let e = p[2] - p[1];
        let r = p[0] - p[1];
        let line = r.norm_squared() - r.dot(&e).powi(2) / e.norm_squared();
        let d = point_line_distance_derivatives(&p[0], &p[1], &p[2]).value;
        assert!(
            (d - line).abs() <= 1e-12 * r.norm_squared(),
            "{d} vs {line}"
        );
        let n = (p[2] - p[1]).cross(&(p[3] - p[1])).normalize();
        let plane = (p[0] - p[1]).dot(&n).powi(2);
        let d = point_plane_distance(&p[0], &p[1], &p[2], &p[3]);
        assert!(
            (d - plane).abs() <= 1e-12 * r.norm_squared().max(1.0),
            "{d} vs {plane}"
        );
    }
}

/// Dense sampling of the triangle (barycentric grid) and of the segment pair (parameter grid).
fn sampled_point_triangle(p: &[Vec3]) -> f64 {
    let m = 300;
    let mut best = f64::INFINITY;
    for i in 0..=m {
        for j in 0..=(m - i) {
            let (u, v) = (i as f64 / m as f64, j as f64 / m as f64);
            let q = p[1] + u * (p[2] - p[1]) + v * (p[3] - p[1]);
            best = best.min((p[0] - q).norm_squared());
        }
    }
    best
}

fn sampled_edge_edge(p: &[Vec3]) -> f64 {
    let m = 400;
    let mut best = f64::INFINITY;
    for i in 0..=m {
        let a = p[0] + (i as f64 / m as f64) * (p[1] - p[0]);
        for j in 0..=m {
            let b = p[2] + (j as f64 / m as f64) * (p[3] - p[2]);
            best = best.min((a - b).norm_squared());
        }
    }
    best
}

#[test]
fn classified_distances_are_the_true_minima() {
    let mut rng = Rng::new(2);
    let mut seen_pt = std::collections::HashSet::new();
    let mut seen_ee = std::collections::HashSet::new();
    for _ in 0..300 {
        let p = points(&rng.vec(12, 1.0));
        let size = 2.0 * 3f64.sqrt();
        let feature = point_triangle_feature(&p[0], &p[1], &p[2], &p[3]);
        seen_pt.insert(std::mem::discriminant(&feature));
        let d = point_triangle_distance(&p[0], &p[1], &p[2], &p[3]);
        let sampled = sampled_point_triangle(&p);
        // The exact minimum is below every sample and within one grid cell of the best.
        assert!(
            d <= sampled + 1e-14,
            "point-triangle {d} above sampled {sampled}"
        );
        assert!(
            sampled.sqrt() - d.sqrt() <= size / 300.0,
            "point-triangle {d} vs {sampled}"
        );
        let feature = edge_edge_feature(&p[0], &p[1], &p[2], &p[3]);
        seen_ee.insert(std::mem::discriminant(&feature));
        let d = edge_edge_distance(&p[0], &p[1], &p[2], &p[3]);
        let sampled = sampled_edge_edge(&p);
        assert!(
            d <= sampled + 1e-14,
            "edge-edge {d} above sampled {sampled}"
        );
        assert!(
            sampled.sqrt() - d.sqrt() <= size / 400.0,
            "edge-edge {d} vs {sampled}"
        );
    }
    assert_eq!(seen_pt.len(), 3, "point-triangle cases: point, line, plane");
    assert_eq!(seen_ee.len(), 3, "edge-edge cases: point, line, line-line");
}

/// Stencil derivatives at points just on either side of a classification boundary: each side's
/// formula is differentiated correctly, and value and gradient are continuous across (the
/// squared distance is C1 there).
#[test]
fn derivatives_near_classification_boundaries() {
    let stencil = |x: &[f64], ee: bool| -> Derivatives<12> {
        let p = points(x);
        let r: Vec<&Vec3> = p.iter().collect();
        let feature = if ee {
            edge_edge_feature(r[0], r[1], r[2], r[3])
        } else {
            point_triangle_feature(r[0], r[1], r[2], r[3])
        };
        feature_distance_derivatives(&feature, &r)
    };
    let t = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.2, 0.9, 0.0];
    // Point-triangle: the projection crosses edge t0-t1 (y = 0), the boundary between that
    // edge's region and vertex t1's (x = 1), and the boundary between vertex t1's region and
    // edge t1-t2's (along the edge's outward normal from t1).
    let normal = Vec3::new(0.9, 0.8, 0.0).normalize();
    let along = Vec3::new(-0.8, 0.9, 0.0).normalize();
    let cases: [(&str, Vec3, [Vec3; 2]); 3] = [
        (
            "edge t0-t1",
            Vec3::new(0.4, 0.0, 0.3),
            [Vec3::new(0.0, 1e-4, 0.0), Vec3::new(0.0, -1e-4, 0.0)],
        ),
        (
            "vertex t1 / edge t0-t1",
            Vec3::new(1.0, 0.0, 0.3),
            [Vec3::new(-1e-4, -1e-4, 0.0), Vec3::new(1e-4, -1e-4, 0.0)],
        ),
        (
            "vertex t1 / edge t1-t2",
            Vec3::new(1.0, 0.0, 0.3),
            [1e-3 * normal + 1e-4 * along, 1e-3 * normal - 1e-4 * along],
        ),
    ];
    for (name, base, offsets) in cases {
        let mut sides = Vec::new();
        let mut features = Vec::new();
        for offset in offsets {
            let q = base + offset;
            let mut x = vec![q[0], q[1], q[2]];
            x.extend_from_slice(&t);
            let p = points(&x);
            features.push(point_triangle_feature(&p[0], &p[1], &p[2], &p[3]));
            let d = stencil(&x, false);
            check_gradient(
                &format!("point-triangle near {name}"),
                &x,
                1e-8,
                |y| stencil(y, false).value,
                d.gradient.as_slice(),
                1e-5,
                1e-12,
            );
            check_jacobian(
                &format!("point-triangle Hessian near {name}"),
                &x,
                1e-8,
                |y| stencil(y, false).gradient.as_slice().to_vec(),
                d.hessian.as_slice(),
                1e-5,
                1e-9,
            );
            sides.push(d);
        }
        assert_ne!(
            features[0], features[1],
            "{name}: both sides classified alike"
        );
        let jump = (sides[0].gradient - sides[1].gradient).norm();
        assert!(jump < 1e-3, "{name}: gradient jumps by {jump}");
    }
    // Edge-edge: edge b's closest point crosses the end a1 of edge a.
    let mut sides = Vec::new();
    for shift in [-1e-4, 1e-4] {
        let x = [
            0.0,
            0.0,
            0.0,
            1.0,
            0.0,
            0.0, //
            1.0 + shift,
            -0.5,
            0.2,
            1.0 + shift,
            0.5,
            0.25,
        ];
        let d = stencil(&x, true);
        check_gradient(
            "edge-edge near an end point",
            &x,
            1e-8,
            |y| stencil(y, true).value,
            d.gradient.as_slice(),
            1e-5,
            1e-12,
        );
        check_jacobian(
            "edge-edge Hessian near an end point",
            &x,
            1e-8,
            |y| stencil(y, true).gradient.as_slice().to_vec(),
            d.hessian.as_slice(),
            1e-5,
            1e-9,
        );
        sides.push(d);
    }
    assert!((sides[0].value - sides[1].value).abs() < 1e-6);
    assert!((sides[0].gradient - sides[1].gradient).norm() < 1e-3);
}

#[test]
fn nearly_parallel_edges() {
    // Edges 0.01 m apart at angles from 1e-2 down to exactly parallel: the classified distance
    // stays the true one, line-line derivatives stay accurate while used, and the mollifier is
    // differentiated correctly below its threshold.
    for angle in [1e-2, 1e-3, 1e-5, 1e-8, 0.0] {
        let (s, c) = (f64::sin(angle), f64::cos(angle));
        let x = [
            0.0,
            0.0,
            0.0,
            1.0,
            0.0,
            0.0, //
            0.1,
            0.01,
            0.0,
            0.1 + c,
            0.01 + s,
            0.0,
        ];
        let p = points(&x);
        let d = edge_edge_distance(&p[0], &p[1], &p[2], &p[3]);
        let sampled = sampled_edge_edge(&p);
        assert!(
            d <= sampled + 1e-14 && sampled.sqrt() - d.sqrt() < 1e-3,
            "angle {angle}"
        );
        if angle >= 1e-3 {
            let f = |p: &[Vec3]| line_line_distance_derivatives(&p[0], &p[1], &p[2], &p[3]);
            let mut y = x;
            y[8] = 0.02; // lift edge b off edge a's plane: a line-line distance
            y[11] = 0.02;
            check_derivatives(&format!("line-line at angle {angle}"), &y, 1e-7, f);
        }
        let eps_x = edge_edge_mollifier_threshold(&p[0], &p[1], &p[2], &p[3]);
        let cross = (p[1] - p[0]).cross(&(p[3] - p[2])).norm_squared();
        let expected_mollified = cross < eps_x;
        assert_eq!(expected_mollified, angle < 0.0317, "angle {angle}");
        let m = |p: &[Vec3]| edge_edge_mollifier_derivatives(&p[0], &p[1], &p[2], &p[3], eps_x);
        if angle > 0.0 && angle < 0.03 {
            check_derivatives(&format!("mollifier at angle {angle}"), &x, H, m);
        }
    }
}

#[test]
fn mollifier_is_c1_at_its_threshold() {
    let eps = 0.3;
    for c in [0.0, 0.05, 0.1, 0.2, 0.29] {
        let (m, dm, d2m) = edge_edge_mollifier(c, eps);
        let h = 1e-6;
        let fd =
            (edge_edge_mollifier(c + h, eps).0 - edge_edge_mollifier(c - h, eps).0) / (2.0 * h);
        let fd2 =
            (edge_edge_mollifier(c + h, eps).1 - edge_edge_mollifier(c - h, eps).1) / (2.0 * h);
        assert!(
            (fd - dm).abs() < 1e-8 && (fd2 - d2m).abs() < 1e-6,
            "c = {c}"
        );
        assert!((0.0..=1.0).contains(&m));
    }
    let below = edge_edge_mollifier(eps * (1.0 - 1e-12), eps);
    let above = edge_edge_mollifier(eps * (1.0 + 1e-12), eps);
    assert!((below.0 - above.0).abs() < 1e-10 && (below.1 - above.1).abs() < 1e-9);
    assert_eq!(edge_edge_mollifier(0.0, eps).0, 0.0);
}
