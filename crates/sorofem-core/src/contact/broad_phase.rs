//! Broad phase: the candidate stencils whose bounding boxes overlap, from a bounding-volume
//! hierarchy (median split, rebuilt per call: a few thousand primitives build in well under a
//! millisecond, and a rebuilt tree stays tight however far the body moved).
//!
//! A vertex's box spans its positions at the start and end of a motion (one point for the static
//! query); an edge's or triangle's box spans its vertices' boxes. A pair is a candidate when the
//! query box (vertex or edge), inflated by `inflation` on every side, overlaps the other box.
//! Statically with `inflation = dhat` this keeps every pair closer than `dhat` (their per-axis
//! gaps are then below `dhat`); over a motion it keeps every pair whose swept boxes come within
//! `inflation`, which includes every pair that collides on the way.
//!
//! Pairs: body vertex - obstacle triangle, obstacle vertex - body triangle, body edge - obstacle
//! edge, body vertex - analytic obstacle, body triangle and edge - ball, and with self-contact
//! body vertex - body triangle and
//! body edge - body edge, leaving out the adjacent ones (a vertex of the triangle, edges sharing a
//! vertex).

use super::collision_mesh::{Candidate, CollisionMesh};
use super::distance::Vec3;
use super::obstacle::Obstacle;
use rayon::prelude::*;

/// An axis-aligned box (m).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    pub min: Vec3,
    pub max: Vec3,
}

impl Aabb {
    pub fn empty() -> Self {
        Aabb {
            min: Vec3::repeat(f64::INFINITY),
            max: Vec3::repeat(f64::NEG_INFINITY),
        }
    }

    pub fn of_segment(a: &Vec3, b: &Vec3) -> Self {
        Aabb {
            min: a.inf(b),
            max: a.sup(b),
        }
    }

    pub fn merged(&self, other: &Aabb) -> Self {
        Aabb {
            min: self.min.inf(&other.min),
            max: self.max.sup(&other.max),
        }
    }

    pub fn inflated(&self, r: f64) -> Self {
        Aabb {
            min: self.min.add_scalar(-r),
            max: self.max.add_scalar(r),
        }
    }

    pub fn overlaps(&self, other: &Aabb) -> bool {
        (0..3).all(|a| self.min[a] <= other.max[a] && other.min[a] <= self.max[a])
    }

    fn center(&self) -> Vec3 {
        0.5 * (self.min + self.max)
    }

    /// Lowest signed distance to `plane` over the box (m).
    fn plane_distance(&self, point: &Vec3, normal: &Vec3) -> f64 {
        let half = 0.5 * (self.max - self.min);
        normal.dot(&(self.center() - point)) - normal.abs().dot(&half)
    }

    /// Distance from `x` to the box (m), 0 inside.
    fn point_distance(&self, x: &Vec3) -> f64 {
        let closest = x.sup(&self.min).inf(&self.max);
        (x - closest).norm()
    }
}

const LEAF_SIZE: usize = 4;

/// A bounding-volume hierarchy over a list of boxes.
pub struct Bvh {
    nodes: Vec<Node>,
    items: Vec<u32>,
    /// The boxes in the order of `items`.
    boxes: Vec<Aabb>,
}

struct Node {
    aabb: Aabb,
    /// Leaf: `items[start..start + count]`; inner node (count == 0): children `start` and
    /// `start + 1`.
    start: u32,
    count: u32,
}

impl Bvh {
    pub fn new(boxes: &[Aabb]) -> Self {
        let mut bvh = Bvh {
            nodes: Vec::with_capacity(2 * boxes.len() / LEAF_SIZE + 1),
            items: (0..boxes.len() as u32).collect(),
            boxes: Vec::new(),
        };
        let centers: Vec<Vec3> = boxes.iter().map(Aabb::center).collect();
        bvh.nodes.push(Node {
            aabb: Aabb::empty(),
            start: 0,
            count: 0,
        });
        if !boxes.is_empty() {
            bvh.build(0, 0, boxes.len(), boxes, &centers);
        }
        bvh.boxes = bvh.items.iter().map(|&i| boxes[i as usize]).collect();
        bvh
    }

    fn build(&mut self, node: usize, start: usize, end: usize, boxes: &[Aabb], centers: &[Vec3]) {
        let items = &mut self.items[start..end];
        let aabb = items
            .iter()
            .fold(Aabb::empty(), |b, &i| b.merged(&boxes[i as usize]));
        self.nodes[node].aabb = aabb;
        if end - start <= LEAF_SIZE {
            self.nodes[node].start = start as u32;
            self.nodes[node].count = (end - start) as u32;
            return;
        }
        let spread = items.iter().fold(Aabb::empty(), |b, &i| {
            let c = centers[i as usize];
            b.merged(&Aabb::of_segment(&c, &c))
        });
        let extent = spread.max - spread.min;
        let axis = extent.imax();
        let mid = (end - start) / 2;
        items.select_nth_unstable_by(mid, |&a, &b| {
            centers[a as usize][axis].total_cmp(&centers[b as usize][axis])
        });
        let left = self.nodes.len();
        for _ in 0..2 {
            self.nodes.push(Node {
                aabb: Aabb::empty(),
                start: 0,
                count: 0,
            });
        }
        self.nodes[node].start = left as u32;
        self.nodes[node].count = 0;
        self.build(left, start, start + mid, boxes, centers);
        self.build(left + 1, start + mid, end, boxes, centers);
    }

    /// Calls `hit(i)` for every box `i` that overlaps `query`.
    pub fn query(&self, query: &Aabb, mut hit: impl FnMut(usize)) {
        if self.items.is_empty() {
            return;
        }
        let mut stack = [0u32; 64];
        let mut top = 1;
        while top > 0 {
            top -= 1;
            let node = &self.nodes[stack[top] as usize];
            if !node.aabb.overlaps(query) {
                continue;
            }
            if node.count > 0 {
                let leaf = node.start as usize..(node.start + node.count) as usize;
                for (&i, aabb) in self.items[leaf.clone()].iter().zip(&self.boxes[leaf]) {
                    if aabb.overlaps(query) {
                        hit(i as usize);
                    }
                }
            } else {
                stack[top] = node.start;
                stack[top + 1] = node.start + 1;
                top += 2;
            }
        }
    }
}

/// The boxes of the primitives of a motion from `x0` to `x1`.
struct Boxes<'a> {
    x0: &'a [Vec3],
    x1: &'a [Vec3],
}

impl Boxes<'_> {
    fn vertex(&self, v: usize) -> Aabb {
        Aabb::of_segment(&self.x0[v], &self.x1[v])
    }

    fn edge(&self, e: &[usize; 2]) -> Aabb {
        self.vertex(e[0]).merged(&self.vertex(e[1]))
    }

    fn face(&self, f: &[usize; 3]) -> Aabb {
        self.vertex(f[0])
            .merged(&self.vertex(f[1]))
            .merged(&self.vertex(f[2]))
    }
}

/// Candidates at the positions `x` (all vertices, see [`CollisionMesh`]) whose boxes come within
/// `dhat` (m): a superset of the stencils closer than `dhat`.
pub fn candidates(mesh: &CollisionMesh, x: &[Vec3], dhat: f64) -> Vec<Candidate> {
    swept_candidates(mesh, x, x, dhat)
}

/// Candidates of the linear motion from `x0` to `x1` whose swept boxes come within `inflation`
/// (m): a superset of the stencils that collide during the motion (with `inflation >= 0`).
pub fn swept_candidates(
    mesh: &CollisionMesh,
    x0: &[Vec3],
    x1: &[Vec3],
    inflation: f64,
) -> Vec<Candidate> {
    assert_eq!(x0.len(), mesh.n_vertices(), "positions of every vertex");
    assert_eq!(x1.len(), mesh.n_vertices(), "positions of every vertex");
    let boxes = Boxes { x0, x1 };
    let body_faces: Vec<Aabb> = mesh.body_faces().iter().map(|f| boxes.face(f)).collect();
    let obstacle_faces: Vec<Aabb> = mesh
        .obstacle_faces()
        .iter()
        .map(|f| boxes.face(f))
        .collect();
    let obstacle_edges: Vec<Aabb> = mesh
        .obstacle_edges()
        .iter()
        .map(|e| boxes.edge(e))
        .collect();
    let body_face_tree = Bvh::new(&body_faces);
    let obstacle_face_tree = Bvh::new(&obstacle_faces);
    let obstacle_edge_tree = Bvh::new(&obstacle_edges);
    let body_edges: Vec<Aabb> = mesh.body_edges().iter().map(|e| boxes.edge(e)).collect();
    let body_edge_tree = if mesh.self_contact() {
        Bvh::new(&body_edges)
    } else {
        Bvh::new(&[])
    };

    let mut out: Vec<Candidate> = mesh
        .body_vertices()
        .par_iter()
        .flat_map_iter(|&v| {
            let query = boxes.vertex(v).inflated(inflation);
            let mut found = Vec::new();
            analytic_candidates(mesh, v, &query, &mut found);
            obstacle_face_tree.query(&query, |f| {
                found.push(Candidate::PointTriangle {
                    point: v,
                    triangle: mesh.obstacle_faces()[f],
                })
            });
            if mesh.self_contact() {
                body_face_tree.query(&query, |f| {
                    let triangle = mesh.body_faces()[f];
                    if !triangle.contains(&v) {
                        found.push(Candidate::PointTriangle { point: v, triangle });
                    }
                });
            }
            found
        })
        .collect();
    sphere_candidates(mesh, &body_faces, &body_edges, inflation, &mut out);
    out.par_extend(mesh.obstacle_vertices().par_iter().flat_map_iter(|&v| {
        let query = boxes.vertex(v).inflated(inflation);
        let mut found = Vec::new();
        body_face_tree.query(&query, |f| {
            found.push(Candidate::PointTriangle {
                point: v,
                triangle: mesh.body_faces()[f],
            })
        });
        found
    }));
    out.par_extend(
        mesh.body_edges()
            .par_iter()
            .zip(body_edges.par_iter())
            .enumerate()
            .flat_map_iter(|(i, (&a, aabb))| {
                let query = aabb.inflated(inflation);
                let mut found = Vec::new();
                obstacle_edge_tree.query(&query, |j| {
                    found.push(Candidate::EdgeEdge {
                        a,
                        b: mesh.obstacle_edges()[j],
                    })
                });
                if mesh.self_contact() {
                    body_edge_tree.query(&query, |j| {
                        let b = mesh.body_edges()[j];
                        if i < j && !shares_vertex(&a, &b) {
                            found.push(Candidate::EdgeEdge { a, b });
                        }
                    });
                }
                found
            }),
    );
    out
}

/// [`swept_candidates`] by testing every pair: the reference the hierarchy is tested against.
pub fn brute_force_candidates(
    mesh: &CollisionMesh,
    x0: &[Vec3],
    x1: &[Vec3],
    inflation: f64,
) -> Vec<Candidate> {
    let boxes = Boxes { x0, x1 };
    let mut out = Vec::new();
    for &v in mesh.body_vertices() {
        let query = boxes.vertex(v).inflated(inflation);
        analytic_candidates(mesh, v, &query, &mut out);
        for &triangle in mesh.obstacle_faces() {
            if query.overlaps(&boxes.face(&triangle)) {
                out.push(Candidate::PointTriangle { point: v, triangle });
            }
        }
        if mesh.self_contact() {
            for &triangle in mesh.body_faces() {
                if !triangle.contains(&v) && query.overlaps(&boxes.face(&triangle)) {
                    out.push(Candidate::PointTriangle { point: v, triangle });
                }
            }
        }
    }
    let body_faces: Vec<Aabb> = mesh.body_faces().iter().map(|f| boxes.face(f)).collect();
    let body_edges: Vec<Aabb> = mesh.body_edges().iter().map(|e| boxes.edge(e)).collect();
    sphere_candidates(mesh, &body_faces, &body_edges, inflation, &mut out);
    for &v in mesh.obstacle_vertices() {
        let query = boxes.vertex(v).inflated(inflation);
        for &triangle in mesh.body_faces() {
            if query.overlaps(&boxes.face(&triangle)) {
                out.push(Candidate::PointTriangle { point: v, triangle });
            }
        }
    }
    for (i, a) in mesh.body_edges().iter().enumerate() {
        let query = boxes.edge(a).inflated(inflation);
        for b in mesh.obstacle_edges() {
            if query.overlaps(&boxes.edge(b)) {
                out.push(Candidate::EdgeEdge { a: *a, b: *b });
            }
        }
        if mesh.self_contact() {
            for b in &mesh.body_edges()[i + 1..] {
                if !shares_vertex(a, b) && query.overlaps(&boxes.edge(b)) {
                    out.push(Candidate::EdgeEdge { a: *a, b: *b });
                }
            }
        }
    }
    out
}

/// Body triangles and edges whose (inflated) boxes come within each ball: a few balls against
/// the surface, tested directly.
fn sphere_candidates(
    mesh: &CollisionMesh,
    face_boxes: &[Aabb],
    edge_boxes: &[Aabb],
    inflation: f64,
    out: &mut Vec<Candidate>,
) {
    for (k, obstacle) in mesh.obstacles().iter().enumerate() {
        let Obstacle::Sphere(sphere) = obstacle else {
            continue;
        };
        let near =
            |aabb: &Aabb| aabb.inflated(inflation).point_distance(&sphere.center) <= sphere.radius;
        for (triangle, aabb) in mesh.body_faces().iter().zip(face_boxes) {
            if near(aabb) {
                out.push(Candidate::TriangleSphere {
                    triangle: *triangle,
                    obstacle: k,
                });
            }
        }
        for (edge, aabb) in mesh.body_edges().iter().zip(edge_boxes) {
            if near(aabb) {
                out.push(Candidate::EdgeSphere {
                    edge: *edge,
                    obstacle: k,
                });
            }
        }
    }
}

fn shares_vertex(a: &[usize; 2], b: &[usize; 2]) -> bool {
    a.iter().any(|i| b.contains(i))
}

/// Analytic obstacles whose region comes within the (inflated) vertex box.
fn analytic_candidates(mesh: &CollisionMesh, v: usize, query: &Aabb, out: &mut Vec<Candidate>) {
    for (k, obstacle) in mesh.obstacles().iter().enumerate() {
        match obstacle {
            Obstacle::Plane(plane) => {
                if query.plane_distance(&plane.point, &plane.normal) <= 0.0 {
                    out.push(Candidate::PointPlane {
                        point: v,
                        obstacle: k,
                    });
                }
            }
            Obstacle::Sphere(sphere) => {
                if query.point_distance(&sphere.center) <= sphere.radius {
                    out.push(Candidate::PointSphere {
                        point: v,
                        obstacle: k,
                    });
                }
            }
            Obstacle::Mesh(_) => {}
        }
    }
}
