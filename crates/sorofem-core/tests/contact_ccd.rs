//! Continuous collision detection: exact times of impact on analytic cases, no false negatives
//! on random trajectories (checked by dense sampling of the true distance), conservative and
//! terminating on grazing and parallel motions, and a whole-configuration step bound after which
//! nothing intersects.
mod common;

use common::{contact_scene, Rng};
use sorofem_core::contact::broad_phase::swept_candidates;
use sorofem_core::contact::ccd::*;
use sorofem_core::contact::check::{find_intersection, minimum_distance};
use sorofem_core::contact::distance::{edge_edge_distance, point_triangle_distance, Vec3};
use sorofem_core::contact::{Plane, Sphere};

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol * b.abs().max(1.0)
}

#[test]
fn analytic_times_of_impact() {
    let plane = Plane::try_new([0.0, 0.0, 0.1], [0.0, 0.0, 2.0]).unwrap();
    let p0 = Vec3::new(0.1, 0.2, 0.6);
    let dp = Vec3::new(0.3, -0.1, -1.0);
    assert!(close(
        point_plane_toi(&p0, &dp, &plane, 0.0).unwrap(),
        0.5,
        1e-15
    ));
    assert!(close(
        point_plane_toi(&p0, &dp, &plane, 0.1).unwrap(),
        0.45,
        1e-15
    ));
    assert_eq!(point_plane_toi(&p0, &(-dp), &plane, 0.1), None);
    assert_eq!(
        point_plane_toi(&p0, &Vec3::new(1.0, 0.0, 0.0), &plane, 0.1),
        None
    );
    assert_eq!(point_plane_toi(&p0, &(0.4 * dp), &plane, 0.0), None); // reaches it at t = 1.25
    assert_eq!(
        point_plane_toi(&Vec3::new(0.0, 0.0, 0.1), &dp, &plane, 0.1),
        Some(0.0)
    );
    // A tilted plane: signed distance n . (p - q) with n = (1, 1, 1)/sqrt 3.
    let tilted = Plane::try_new([0.0; 3], [1.0, 1.0, 1.0]).unwrap();
    let p0 = Vec3::new(1.0, 1.0, 1.0);
    let t = point_plane_toi(&p0, &Vec3::new(-4.0, -4.0, -4.0), &tilted, 0.0).unwrap();
    assert!(close(t, 0.25, 1e-15), "{t}");

    let sphere = Sphere::try_new([1.0, -1.0, 0.5], 0.3).unwrap();
    let c = sphere.center;
    // Head-on from 1 m above the surface at 2 m per step: contact at 0.5.
    let p0 = c + Vec3::new(0.0, 0.0, 1.3);
    let dp = Vec3::new(0.0, 0.0, -2.0);
    assert!(close(
        point_sphere_toi(&p0, &dp, &sphere, 0.0).unwrap(),
        0.5,
        1e-14
    ));
    assert!(close(
        point_sphere_toi(&p0, &dp, &sphere, 0.1).unwrap(),
        0.45,
        1e-14
    ));
    // Oblique, with lateral offset b < r: contact when |(b, 0, z0 - 2 t)| = r.
    let b = 0.2;
    let p0 = c + Vec3::new(b, 0.0, 1.3);
    let expected = (1.3 - (0.3f64 * 0.3 - b * b).sqrt()) / 2.0;
    assert!(close(
        point_sphere_toi(&p0, &dp, &sphere, 0.0).unwrap(),
        expected,
        1e-14
    ));
    // Passing beside it (b > r), moving away, and too slow to arrive: no contact.
    assert_eq!(
        point_sphere_toi(&(c + Vec3::new(0.31, 0.0, 1.3)), &dp, &sphere, 0.0),
        None
    );
    assert_eq!(point_sphere_toi(&p0, &(-dp), &sphere, 0.0), None);
    assert_eq!(point_sphere_toi(&p0, &(0.3 * dp), &sphere, 0.0), None);

    // Additive CCD: a point falling on a triangle at constant speed stops exactly where its
    // distance is eta d0, whether the point or the triangle moves.
    let tri = [
        Vec3::new(-1.0, -1.0, 0.0),
        Vec3::new(2.0, -1.0, 0.0),
        Vec3::new(0.0, 2.0, 0.0),
    ];
    let x = [Vec3::new(0.1, 0.2, 1.0), tri[0], tri[1], tri[2]];
    let fall = [
        Vec3::new(0.0, 0.0, -2.0),
        Vec3::zeros(),
        Vec3::zeros(),
        Vec3::zeros(),
    ];
    let rise = [
        Vec3::zeros(),
        Vec3::new(0.0, 0.0, 2.0),
        Vec3::new(0.0, 0.0, 2.0),
        Vec3::new(0.0, 0.0, 2.0),
    ];
    for eta in [0.1, 1e-3] {
        for dx in [&fall, &rise] {
            let t = point_triangle_toi(&x, dx, eta).unwrap();
            assert!(close(t, 0.5 * (1.0 - eta), 1e-12), "eta {eta}: {t}");
        }
    }
    // Edge-edge: crossing edges 1 m apart closing at 2 m per step.
    let x = [
        Vec3::new(-1.0, 0.0, 0.0),
        Vec3::new(1.0, 0.0, 0.0),
        Vec3::new(0.2, -1.0, 1.0),
        Vec3::new(0.2, 1.0, 1.0),
    ];
    let dx = [
        Vec3::zeros(),
        Vec3::zeros(),
        Vec3::new(0.0, 0.0, -2.0),
        Vec3::new(0.0, 0.0, -2.0),
    ];
    let t = edge_edge_toi(&x, &dx, 0.1).unwrap();
    assert!(close(t, 0.45, 1e-12), "{t}");
}

/// Random stencil trajectories: the returned time is safe (dense sampling of the true distance
/// never goes below eta^2 d0 before it, the distance at it is at least eta d0), and is never
/// later than a contact planted on the trajectory.
#[test]
fn no_false_negatives_on_random_trajectories() {
    let mut rng = Rng::new(21);
    let eta = DEFAULT_MIN_SEPARATION;
    let mut collided = [0usize; 2];
    for trial in 0..400 {
        let edge_edge = trial % 2 == 1;
        let mut x: [Vec3; 4] =
            std::array::from_fn(|_| Vec3::new(rng.next(), rng.next(), rng.next()));
        let dx: [Vec3; 4] =
            std::array::from_fn(|_| Vec3::new(rng.next(), rng.next(), rng.next()) * 1.5);
        let distance = |y: &[Vec3; 4]| {
            if edge_edge {
                edge_edge_distance(&y[0], &y[1], &y[2], &y[3]).sqrt()
            } else {
                point_triangle_distance(&y[0], &y[1], &y[2], &y[3]).sqrt()
            }
        };
        // Every third trial plants a contact at t_c: the point on the triangle, or the edges
        // crossing, at that time.
        let planted = (trial % 3 == 0).then(|| 0.2 + 0.7 * (rng.next() + 1.0) / 2.0);
        if let Some(tc) = planted {
            let (u, v) = ((rng.next() + 1.0) / 4.0, (rng.next() + 1.0) / 4.0);
            let at = |a: usize, x: &[Vec3; 4]| x[a] + tc * dx[a];
            if edge_edge {
                let pa = at(0, &x) + u * (at(1, &x) - at(0, &x));
                let pb = at(2, &x) + v * (at(3, &x) - at(2, &x));
                x[2] += pa - pb;
                x[3] += pa - pb;
            } else {
                let q = at(1, &x) + u * (at(2, &x) - at(1, &x)) + v * (at(3, &x) - at(1, &x));
                x[0] += q - at(0, &x);
            }
        }
        let d0 = distance(&x);
        if d0 < 1e-3 {
            continue;
        }
        let toi = if edge_edge {
            edge_edge_toi(&x, &dx, eta)
        } else {
            point_triangle_toi(&x, &dx, eta)
        };
        let end = toi.unwrap_or(1.0);
        let samples = 4000;
        let mut lowest = f64::INFINITY;
        for k in 0..=samples {
            let tau = end * k as f64 / samples as f64;
            let y: [Vec3; 4] = std::array::from_fn(|a| x[a] + tau * dx[a]);
            lowest = lowest.min(distance(&y));
        }
        assert!(
            lowest >= eta * eta * d0 * (1.0 - 1e-9),
            "trial {trial}: distance {lowest} before {end}"
        );
        if let Some(t) = toi {
            let y: [Vec3; 4] = std::array::from_fn(|a| x[a] + t * dx[a]);
            assert!(
                distance(&y) >= eta * d0 * (1.0 - 1e-9),
                "trial {trial}: distance at t"
            );
            collided[usize::from(edge_edge)] += 1;
        }
        if let Some(tc) = planted {
            let t = toi.unwrap_or_else(|| panic!("trial {trial}: planted contact at {tc} missed"));
            assert!(t <= tc, "trial {trial}: {t} after the contact at {tc}");
        }
    }
    assert!(
        collided.iter().all(|&c| c > 50),
        "too few contacts: {collided:?}"
    );
}

#[test]
fn grazing_and_parallel_motions_are_conservative_and_terminate() {
    let eta = DEFAULT_MIN_SEPARATION;
    let delta = 1e-3;
    // A point sliding 1 m over a triangle at height delta, parallel to it.
    let x = [
        Vec3::new(-0.5, 0.1, delta),
        Vec3::new(-1.0, -1.0, 0.0),
        Vec3::new(2.0, -1.0, 0.0),
        Vec3::new(0.0, 2.0, 0.0),
    ];
    let slide = [
        Vec3::new(1.0, 0.0, 0.0),
        Vec3::zeros(),
        Vec3::zeros(),
        Vec3::zeros(),
    ];
    assert_eq!(point_triangle_toi(&x, &slide, eta), None);
    // Descending to half the height on the way: safe, stopping at eta d0 at the latest.
    let sink = [
        Vec3::new(1.0, 0.0, -0.5 * delta),
        Vec3::zeros(),
        Vec3::zeros(),
        Vec3::zeros(),
    ];
    assert_eq!(point_triangle_toi(&x, &sink, eta), None);
    let dive = [
        Vec3::new(1.0, 0.0, -1.05 * delta),
        Vec3::zeros(),
        Vec3::zeros(),
        Vec3::zeros(),
    ];
    let t = point_triangle_toi(&x, &dive, eta).expect("crosses the plane at 0.95");
    assert!(t <= 0.95 && t > 0.5, "{t}");
    // Parallel edges sliding along each other delta apart, and approaching while sliding.
    let x = [
        Vec3::new(0.0, 0.0, 0.0),
        Vec3::new(1.0, 0.0, 0.0),
        Vec3::new(0.5, 0.0, delta),
        Vec3::new(1.5, 0.0, delta),
    ];
    let slide = [
        Vec3::zeros(),
        Vec3::zeros(),
        Vec3::new(-1.0, 0.0, 0.0),
        Vec3::new(-1.0, 0.0, 0.0),
    ];
    assert_eq!(edge_edge_toi(&x, &slide, eta), None);
    let press = slide.map(|d| {
        if d == Vec3::zeros() {
            d
        } else {
            d + Vec3::new(0.0, 0.0, -2.0 * delta)
        }
    });
    let t = edge_edge_toi(&x, &press, eta).expect("touches at 0.5");
    assert!((0.4..=0.5).contains(&t), "{t}");
    // Grazing a sphere delta away from its surface: no contact, but the distance drops below
    // eta d0, where the step stops.
    let sphere = Sphere::try_new([0.0; 3], 1.0).unwrap();
    let p0 = Vec3::new(-2.0, 1.0 + delta, 0.0);
    let graze = Vec3::new(4.0, 0.0, 0.0);
    assert_eq!(point_sphere_toi(&p0, &graze, &sphere, 0.0), None);
    let t = point_sphere_toi(&p0, &graze, &sphere, eta).unwrap();
    let d0 = sphere.signed_distance(&p0);
    assert!(close(
        sphere.signed_distance(&(p0 + t * graze)),
        eta * d0,
        1e-12
    ));
    let plane = Plane::try_new([0.0; 3], [0.0, 1.0, 0.0]).unwrap();
    assert_eq!(
        point_plane_toi(&p0, &Vec3::new(4.0, 0.0, 0.0), &plane, eta),
        None
    );
}

#[test]
fn max_step_keeps_the_whole_configuration_apart() {
    let (mesh, collision) = contact_scene(3, true);
    let body = mesh.rest_flat();
    let x0 = collision.vertices(&body).unwrap();
    let eta = DEFAULT_MIN_SEPARATION;
    // Falling 50 mm onto the plane 2 mm below (contact at 0.04), or moving 10 mm sideways into
    // the box 3 mm away (contact at 0.3), or both with a twist.
    let motions: [fn(&Vec3) -> Vec3; 3] = [
        |_| Vec3::new(0.0, 0.0, -0.05),
        |_| Vec3::new(0.01, 0.0, 0.0),
        |p| Vec3::new(0.01 + 0.1 * (p[2] - 0.05), 0.02 * p[0], -0.004),
    ];
    for (k, motion) in motions.iter().enumerate() {
        let dx: Vec<Vec3> = x0
            .iter()
            .enumerate()
            .map(|(v, p)| {
                if collision.is_obstacle_vertex(v) {
                    Vec3::zeros()
                } else {
                    motion(p)
                }
            })
            .collect();
        let x1: Vec<Vec3> = x0.iter().zip(&dx).map(|(a, b)| a + b).collect();
        assert!(
            find_intersection(&collision, &x1).is_some(),
            "motion {k} must collide"
        );
        let swept = swept_candidates(&collision, &x0, &x1, 0.0);
        let alpha = max_step(&collision, &swept, &x0, &dx, eta);
        assert!(alpha > 0.0 && alpha < 1.0, "motion {k}: {alpha}");
        for s in 0..=200 {
            let tau = alpha * s as f64 / 200.0;
            let x: Vec<Vec3> = x0.iter().zip(&dx).map(|(a, b)| a + tau * b).collect();
            assert!(
                find_intersection(&collision, &x).is_none(),
                "motion {k} at {tau}"
            );
            let (lowest, c) = minimum_distance(&collision, &swept, &x).unwrap();
            assert!(lowest > 0.0, "motion {k} at {tau}: {c:?} at {lowest}");
        }
        if k == 0 {
            assert!(
                close(alpha, 0.04 * (1.0 - eta), 1e-12),
                "plane-bound step {alpha}"
            );
        }
        if k == 1 {
            assert!(alpha <= 0.3 && alpha > 0.2, "box-bound step {alpha}");
        }
    }
}

/// A ball against a moving body triangle or edge: the returned time is never past a contact
/// (checked on a fine sampling of the motion), and no time means the gap stays above eta d0.
#[test]
fn ball_against_moving_triangles_and_edges_is_conservative() {
    let sphere = Sphere::try_new([0.0, 0.0, 0.0], 0.3).unwrap();
    let mut rng = Rng::new(21);
    let eta = 0.1;
    let (mut hits, mut misses) = (0, 0);
    let gap =
        |t: &[Vec3; 3]| point_triangle_distance(&sphere.center, &t[0], &t[1], &t[2]).sqrt() - 0.3;
    for _ in 0..400 {
        let x: [Vec3; 3] = std::array::from_fn(|_| {
            Vec3::new(rng.next(), rng.next(), rng.next()) * 0.4 + Vec3::new(0.0, 0.0, 0.6)
        });
        if gap(&x) <= 0.0 {
            continue;
        }
        let push = Vec3::new(
            0.2 * rng.next(),
            0.2 * rng.next(),
            -0.6 - 0.4 * rng.next().abs(),
        );
        let dx: [Vec3; 3] =
            std::array::from_fn(|_| push + Vec3::new(rng.next(), rng.next(), rng.next()) * 0.1);
        let at = |t: f64| -> [Vec3; 3] { std::array::from_fn(|a| x[a] + t * dx[a]) };
        let first_contact = (0..=2000)
            .map(|k| k as f64 / 2000.0)
            .find(|&t| gap(&at(t)) <= 0.0);
        match sphere_triangle_toi(&sphere, &x, &dx, eta) {
            Some(t) => {
                hits += 1;
                assert!(gap(&at(t)) > 0.0, "the bound touches");
                if let Some(contact) = first_contact {
                    assert!(t <= contact, "{t} after the contact at {contact}");
                }
            }
            None => {
                misses += 1;
                let lowest = (0..=2000)
                    .map(|k| gap(&at(k as f64 / 2000.0)))
                    .fold(f64::INFINITY, f64::min);
                assert!(lowest >= eta * gap(&x) * 0.999, "missed: {lowest}");
            }
        }
        let edge = [x[0], x[1]];
        if let Some(t) = sphere_edge_toi(&sphere, &edge, &[dx[0], dx[1]], eta) {
            let y = [edge[0] + t * dx[0], edge[1] + t * dx[1]];
            let d = edge_edge_distance(&y[0], &y[1], &sphere.center, &sphere.center);
            assert!(d.sqrt() > 0.3, "the edge bound touches");
        }
    }
    assert!(hits > 50 && misses > 10, "{hits} hits, {misses} misses");
}
