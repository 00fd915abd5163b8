//! Broad phase: the hierarchy returns exactly the brute-force candidate set (static and swept,
//! on perturbed meshes and random triangle soups), the set contains every pair closer than
//! dhat, and adjacent or obstacle-obstacle pairs are left out.
mod common;

use common::{contact_scene, Rng};
use sorofem_core::contact::broad_phase::{brute_force_candidates, candidates, swept_candidates};
use sorofem_core::contact::distance::{edge_edge_distance, point_triangle_distance, Vec3};
use sorofem_core::contact::{Candidate, CollisionMesh, Obstacle, ObstacleMesh, Plane, Sphere};

fn sorted(mut c: Vec<Candidate>) -> Vec<Candidate> {
    c.sort_unstable();
    c
}

fn perturbed(collision: &CollisionMesh, rest: &[f64], amplitude: f64, rng: &mut Rng) -> Vec<Vec3> {
    let body: Vec<f64> = rest.iter().map(|v| v + amplitude * rng.next()).collect();
    collision.vertices(&body).unwrap()
}

fn random_soup(rng: &mut Rng, self_contact: bool) -> (CollisionMesh, Vec<f64>) {
    let n = 60;
    let rest: Vec<[f64; 3]> = (0..n)
        .map(|_| [0.1 * rng.next(), 0.1 * rng.next(), 0.1 * rng.next() + 0.05])
        .collect();
    let pick = |rng: &mut Rng| ((rng.next() + 1.0) * 0.5 * n as f64) as usize % n;
    let mut faces = Vec::new();
    while faces.len() < 90 {
        let f = [pick(rng), pick(rng), pick(rng)];
        if f[0] != f[1] && f[1] != f[2] && f[0] != f[2] {
            faces.push(f);
        }
    }
    let obstacles = vec![
        Obstacle::Plane(Plane::try_new([0.0, 0.0, -0.02], [0.1, 0.0, 1.0]).unwrap()),
        Obstacle::Sphere(Sphere::try_new([0.05, 0.0, 0.1], 0.03).unwrap()),
        Obstacle::Mesh(ObstacleMesh::cuboid([-0.02, -0.02, 0.0], [0.03, 0.03, 0.04]).unwrap()),
        Obstacle::Mesh(
            ObstacleMesh::oriented_box(
                [-0.05, 0.05, 0.06],
                [0.03, 0.01, 0.02],
                [[0.8, -0.6, 0.0], [0.6, 0.8, 0.0], [0.0, 0.0, 1.0]],
            )
            .unwrap(),
        ),
    ];
    let collision = CollisionMesh::try_new(&rest, &faces, obstacles, self_contact).unwrap();
    (collision, rest.as_flattened().to_vec())
}

#[test]
fn hierarchy_equals_brute_force() {
    let mut rng = Rng::new(5);
    let mut total = 0;
    for trial in 0..12 {
        let self_contact = trial % 3 != 2;
        let (collision, rest) = if trial % 2 == 0 {
            let (mesh, collision) = contact_scene(3, self_contact);
            (collision, mesh.rest_flat())
        } else {
            random_soup(&mut rng, self_contact)
        };
        let x0 = perturbed(&collision, &rest, 0.01, &mut rng);
        let x1 = perturbed(&collision, &rest, 0.03, &mut rng);
        for inflation in [0.0, 0.002, 0.01] {
            let fast = sorted(candidates(&collision, &x0, inflation));
            let reference = sorted(brute_force_candidates(&collision, &x0, &x0, inflation));
            assert_eq!(
                fast, reference,
                "trial {trial}, static, inflation {inflation}"
            );
            let fast = sorted(swept_candidates(&collision, &x0, &x1, inflation));
            let reference = sorted(brute_force_candidates(&collision, &x0, &x1, inflation));
            assert_eq!(
                fast, reference,
                "trial {trial}, swept, inflation {inflation}"
            );
            let mut unique = fast.clone();
            unique.dedup();
            assert_eq!(
                unique.len(),
                fast.len(),
                "trial {trial}: duplicate candidates"
            );
            total += fast.len();
        }
    }
    assert!(total > 10_000, "too few candidates to be a test: {total}");
}

#[test]
fn candidates_contain_every_close_pair_and_no_adjacent_one() {
    let mut rng = Rng::new(9);
    let dhat = 0.004;
    for trial in 0..4 {
        let (collision, rest) = random_soup(&mut rng, true);
        let x = perturbed(&collision, &rest, 0.005 * trial as f64, &mut rng);
        let found = candidates(&collision, &x, dhat);
        let set: std::collections::HashSet<Candidate> = found.iter().copied().collect();
        for c in &found {
            let (ids, n) = c.vertices();
            assert!(
                ids[..n].iter().any(|&v| !collision.is_obstacle_vertex(v)),
                "obstacle-obstacle pair {c:?}"
            );
            match c {
                Candidate::PointTriangle { point, triangle } => {
                    assert!(!triangle.contains(point), "adjacent {c:?}")
                }
                Candidate::EdgeEdge { a, b } => {
                    assert!(!a.iter().any(|v| b.contains(v)), "adjacent {c:?}")
                }
                _ => {}
            }
        }
        let mut close = 0;
        let points: Vec<usize> = collision
            .body_vertices()
            .iter()
            .chain(collision.obstacle_vertices())
            .copied()
            .collect();
        let faces: Vec<[usize; 3]> = collision
            .body_faces()
            .iter()
            .chain(collision.obstacle_faces())
            .copied()
            .collect();
        for &p in &points {
            for &t in &faces {
                let both_obstacle =
                    collision.is_obstacle_vertex(p) && collision.is_obstacle_vertex(t[0]);
                if t.contains(&p) || both_obstacle {
                    continue;
                }
                let d = point_triangle_distance(&x[p], &x[t[0]], &x[t[1]], &x[t[2]]);
                if d < dhat * dhat {
                    close += 1;
                    assert!(set.contains(&Candidate::PointTriangle {
                        point: p,
                        triangle: t
                    }));
                }
            }
        }
        let edges: Vec<[usize; 2]> = collision
            .body_edges()
            .iter()
            .chain(collision.obstacle_edges())
            .copied()
            .collect();
        for (i, a) in edges.iter().enumerate() {
            for b in &edges[i + 1..] {
                if collision.is_obstacle_vertex(a[0]) || a.iter().any(|v| b.contains(v)) {
                    continue;
                }
                let d = edge_edge_distance(&x[a[0]], &x[a[1]], &x[b[0]], &x[b[1]]);
                if d < dhat * dhat {
                    close += 1;
                    assert!(
                        set.contains(&Candidate::EdgeEdge { a: *a, b: *b }),
                        "{a:?} {b:?}"
                    );
                }
            }
        }
        for &v in collision.body_vertices() {
            for (k, obstacle) in collision.obstacles().iter().enumerate() {
                let (s, c) = match obstacle {
                    Obstacle::Plane(p) => (
                        p.signed_distance(&x[v]),
                        Candidate::PointPlane {
                            point: v,
                            obstacle: k,
                        },
                    ),
                    Obstacle::Sphere(s) => (
                        s.signed_distance(&x[v]),
                        Candidate::PointSphere {
                            point: v,
                            obstacle: k,
                        },
                    ),
                    Obstacle::Mesh(_) => continue,
                };
                if s < dhat {
                    close += 1;
                    assert!(set.contains(&c), "{c:?} at {s}");
                }
            }
        }
        assert!(close > 0, "trial {trial}: no close pair");
    }
}
