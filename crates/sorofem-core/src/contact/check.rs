//! Diagnostics: the minimum distance over the candidates, and intersections between the body and
//! its obstacles (to reject a rest configuration that starts in contact, with a message naming
//! the obstacle, the node or triangle, and the distance).

use super::broad_phase::{Aabb, Bvh};
use super::collision_mesh::{Candidate, CollisionMesh};
use super::distance::{point_triangle_distance, Vec3};
use super::obstacle::{winding_number, Obstacle};
use super::potential::candidate_distance;
use crate::error::{Error, Result};
use rayon::prelude::*;
use std::fmt;

/// The smallest distance (m) over the candidates at positions `x`, with its candidate (signed
/// for analytic obstacles); `None` without candidates.
pub fn minimum_distance(
    mesh: &CollisionMesh,
    candidates: &[Candidate],
    x: &[Vec3],
) -> Option<(f64, Candidate)> {
    candidates
        .par_iter()
        .map(|c| {
            let (p, n) = c.positions(x);
            (candidate_distance(mesh, c, &p[..n]), *c)
        })
        .min_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)))
}

/// How the body meets an obstacle.
#[derive(Clone, Debug, PartialEq)]
pub enum Intersection {
    /// Body node `node` touches or is inside obstacle `obstacle`: its signed distance (m) is
    /// `distance <= 0` (minus the distance to the obstacle's surface when inside a mesh).
    Node {
        obstacle: usize,
        node: usize,
        distance: f64,
    },
    /// A body edge crosses an obstacle triangle, or an obstacle edge crosses a body triangle
    /// (vertex ids of [`CollisionMesh`]).
    EdgeTriangle {
        obstacle: usize,
        edge: [usize; 2],
        triangle: [usize; 3],
    },
    /// A point of the obstacle (a mesh vertex, a sphere's centre) lies inside the body.
    InsideBody { obstacle: usize, point: Vec3 },
    /// A ball meets body triangle `triangle` between its vertices: the distance from its
    /// centre to the triangle minus its radius is `distance <= 0` (m).
    Triangle {
        obstacle: usize,
        triangle: [usize; 3],
        distance: f64,
    },
    /// With self-contact: a body edge meets a body triangle it shares no vertex with.
    SelfEdgeTriangle {
        edge: [usize; 2],
        triangle: [usize; 3],
    },
}

impl Intersection {
    /// The obstacle met (`None`: the body meets itself).
    pub fn obstacle(&self) -> Option<usize> {
        match self {
            Intersection::Node { obstacle, .. }
            | Intersection::EdgeTriangle { obstacle, .. }
            | Intersection::InsideBody { obstacle, .. }
            | Intersection::Triangle { obstacle, .. } => Some(*obstacle),
            Intersection::SelfEdgeTriangle { .. } => None,
        }
    }

    /// The input this intersection makes wrong: `obstacles[k]`, or `self_contact`.
    pub fn param(&self) -> String {
        self.obstacle()
            .map_or("self_contact".into(), |k| format!("obstacles[{k}]"))
    }
}

impl fmt::Display for Intersection {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Intersection::Node { node, distance, .. } => {
                write!(f, "body node {node} at signed distance {distance:.3e} m")
            }
            Intersection::EdgeTriangle { edge, triangle, .. } => {
                write!(f, "edge {edge:?} crossing triangle {triangle:?}")
            }
            Intersection::SelfEdgeTriangle { edge, triangle } => write!(
                f,
                "body edge {edge:?} meeting body triangle {triangle:?} (the surface meets itself)"
            ),
            Intersection::Triangle {
                triangle, distance, ..
            } => write!(
                f,
                "body triangle {triangle:?} at signed distance {distance:.3e} m"
            ),
            Intersection::InsideBody { point, .. } => write!(
                f,
                "obstacle point ({:.4e}, {:.4e}, {:.4e}) m inside the body",
                point[0], point[1], point[2]
            ),
        }
    }
}

/// The first intersection (in obstacle order, then of the body with itself when self-contact is
/// on) between the body at positions `x` (all vertices) and its obstacles, touching included;
/// `None` when they are apart. Closed obstacle meshes also catch a body node inside them, and
/// closed bodies an obstacle inside them.
pub fn find_intersection(mesh: &CollisionMesh, x: &[Vec3]) -> Option<Intersection> {
    let body_faces = mesh.body_faces();
    let body_closed = super::obstacle::edges_and_closedness(body_faces).1;
    let inside_body = |p: &Vec3| body_closed && winding_number(x, body_faces, p).abs() > 0.5;
    for (k, obstacle) in mesh.obstacles().iter().enumerate() {
        let found = match obstacle {
            Obstacle::Plane(plane) => mesh.body_vertices().iter().find_map(|&v| {
                let distance = plane.signed_distance(&x[v]);
                (distance <= 0.0).then_some(Intersection::Node {
                    obstacle: k,
                    node: v,
                    distance,
                })
            }),
            Obstacle::Sphere(sphere) => mesh
                .body_vertices()
                .iter()
                .find_map(|&v| {
                    let distance = sphere.signed_distance(&x[v]);
                    (distance <= 0.0).then_some(Intersection::Node {
                        obstacle: k,
                        node: v,
                        distance,
                    })
                })
                .or_else(|| {
                    mesh.body_faces().iter().find_map(|t| {
                        let distance =
                            point_triangle_distance(&sphere.center, &x[t[0]], &x[t[1]], &x[t[2]])
                                .sqrt()
                                - sphere.radius;
                        (distance <= 0.0).then_some(Intersection::Triangle {
                            obstacle: k,
                            triangle: *t,
                            distance,
                        })
                    })
                })
                .or_else(|| {
                    inside_body(&sphere.center).then_some(Intersection::InsideBody {
                        obstacle: k,
                        point: sphere.center,
                    })
                }),
            Obstacle::Mesh(obstacle_mesh) => {
                mesh_intersection(mesh, x, k, obstacle_mesh.is_closed(), &inside_body)
            }
        };
        if found.is_some() {
            return found;
        }
    }
    if mesh.self_contact() {
        return self_intersection(mesh, x);
    }
    None
}

/// The first body edge that meets a body triangle it shares no vertex with (touching
/// included): where a surface passes through itself, an edge of one sheet crosses a triangle of
/// the other.
pub fn self_intersection(mesh: &CollisionMesh, x: &[Vec3]) -> Option<Intersection> {
    let faces = mesh.body_faces();
    let boxes: Vec<Aabb> = faces
        .iter()
        .map(|f| Aabb::of_segment(&x[f[0]], &x[f[1]]).merged(&Aabb::of_segment(&x[f[2]], &x[f[2]])))
        .collect();
    let tree = Bvh::new(&boxes);
    mesh.body_edges().par_iter().find_map_first(|e| {
        let mut hit = None;
        tree.query(&Aabb::of_segment(&x[e[0]], &x[e[1]]), |i| {
            let f = faces[i];
            if hit.is_none()
                && !f.contains(&e[0])
                && !f.contains(&e[1])
                && segment_meets_triangle(&x[e[0]], &x[e[1]], [&x[f[0]], &x[f[1]], &x[f[2]]])
            {
                hit = Some(Intersection::SelfEdgeTriangle {
                    edge: *e,
                    triangle: f,
                });
            }
        });
        hit
    })
}

/// [`find_intersection`] as an error naming the obstacle (`obstacles[k]`), for rest
/// configurations.
pub fn check_no_intersection(mesh: &CollisionMesh, x: &[Vec3]) -> Result<()> {
    match find_intersection(mesh, x) {
        None => Ok(()),
        Some(intersection) => Err(Error::invalid(
            &intersection.param(),
            "a body apart from its obstacles and from itself in its rest configuration",
            intersection,
        )),
    }
}

fn mesh_intersection(
    mesh: &CollisionMesh,
    x: &[Vec3],
    k: usize,
    closed: bool,
    inside_body: &dyn Fn(&Vec3) -> bool,
) -> Option<Intersection> {
    let owned = |v: usize| mesh.obstacle_of_vertex(v) == Some(k);
    let faces: Vec<[usize; 3]> = mesh
        .obstacle_faces()
        .iter()
        .filter(|f| owned(f[0]))
        .copied()
        .collect();
    let edges: Vec<[usize; 2]> = mesh
        .obstacle_edges()
        .iter()
        .filter(|e| owned(e[0]))
        .copied()
        .collect();
    for &v in mesh.body_vertices() {
        let surface = faces
            .iter()
            .map(|f| point_triangle_distance(&x[v], &x[f[0]], &x[f[1]], &x[f[2]]))
            .fold(f64::INFINITY, f64::min)
            .sqrt();
        let inside = closed && winding_number(x, &faces, &x[v]).abs() > 0.5;
        if surface == 0.0 || inside {
            return Some(Intersection::Node {
                obstacle: k,
                node: v,
                distance: -surface,
            });
        }
    }
    let crossing = |edges: &[[usize; 2]], faces: &[[usize; 3]]| {
        let boxes: Vec<Aabb> = faces
            .iter()
            .map(|f| {
                Aabb::of_segment(&x[f[0]], &x[f[1]]).merged(&Aabb::of_segment(&x[f[2]], &x[f[2]]))
            })
            .collect();
        let tree = Bvh::new(&boxes);
        edges.iter().find_map(|e| {
            let mut hit = None;
            tree.query(&Aabb::of_segment(&x[e[0]], &x[e[1]]), |i| {
                let f = faces[i];
                if hit.is_none()
                    && segment_meets_triangle(&x[e[0]], &x[e[1]], [&x[f[0]], &x[f[1]], &x[f[2]]])
                {
                    hit = Some(Intersection::EdgeTriangle {
                        obstacle: k,
                        edge: *e,
                        triangle: f,
                    });
                }
            });
            hit
        })
    };
    crossing(mesh.body_edges(), &faces)
        .or_else(|| crossing(&edges, mesh.body_faces()))
        .or_else(|| {
            let first = faces.first().map(|f| x[f[0]])?;
            inside_body(&first).then_some(Intersection::InsideBody {
                obstacle: k,
                point: first,
            })
        })
}

/// Whether the closed segment `[a, b]` meets the closed triangle `t` (touching included).
fn segment_meets_triangle(a: &Vec3, b: &Vec3, t: [&Vec3; 3]) -> bool {
    let n = (t[1] - t[0]).cross(&(t[2] - t[0]));
    let (sa, sb) = (n.dot(&(a - t[0])), n.dot(&(b - t[0])));
    if (sa > 0.0 && sb > 0.0) || (sa < 0.0 && sb < 0.0) {
        return false;
    }
    if sa == 0.0 && sb == 0.0 {
        // Coplanar: touching when either end lies in the triangle or the segment meets an edge;
        // the distance functions decide.
        let d = super::distance::edge_edge_distance;
        return point_triangle_distance(a, t[0], t[1], t[2]) == 0.0
            || point_triangle_distance(b, t[0], t[1], t[2]) == 0.0
            || (0..3).any(|i| d(a, b, t[i], t[(i + 1) % 3]) == 0.0);
    }
    let p = a + (b - a) * (sa / (sa - sb));
    (0..3).all(|i| {
        let (u, v) = (t[i], t[(i + 1) % 3]);
        (v - u).cross(&(p - u)).dot(&n) >= 0.0
    })
}
