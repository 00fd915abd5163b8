//! What can touch what: the body's boundary surface, the obstacles, and the collision
//! candidates (stencils) between them.
//!
//! Vertices are numbered in one sequence: the body's nodes `0..n_body` (all of them, so that a
//! body vertex id is its node index and its DOFs are `3 v + k`), then the vertices of the mesh
//! obstacles in the order given. Functions taking positions take `x: &[Vec3]` over that whole
//! sequence ([`CollisionMesh::vertices`] builds it).

use super::distance::Vec3;
use super::obstacle::{edges_and_closedness, Obstacle, Plane, Sphere};
use crate::error::{check_finite, Error, Result};
use crate::mesh::TetMesh;

/// One stencil of the contact potential: a pair of primitives that may come within `dhat`.
/// Vertex ids follow the numbering of [`CollisionMesh`]; `obstacle` indexes
/// [`CollisionMesh::obstacles`] and must name a plane (`PointPlane`) or a sphere (the `...Sphere`
/// stencils), as the broad phase makes them (the kernels panic otherwise).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Candidate {
    /// A vertex and a triangle (body vertex vs body or obstacle triangle, or obstacle vertex vs
    /// body triangle).
    PointTriangle { point: usize, triangle: [usize; 3] },
    /// Two edges, at least one of the body; `a` is the body's when only one is.
    EdgeEdge { a: [usize; 2], b: [usize; 2] },
    /// A body vertex and the analytic half-space `obstacles[obstacle]`.
    PointPlane { point: usize, obstacle: usize },
    /// A body vertex and the analytic ball `obstacles[obstacle]`.
    PointSphere { point: usize, obstacle: usize },
    /// A body triangle and the analytic ball `obstacles[obstacle]`: active when the ball's
    /// centre projects inside the triangle (otherwise an edge or a vertex is closest, and their
    /// own stencils count it), so that a ball cannot slip between the vertices of a coarse
    /// surface.
    TriangleSphere {
        triangle: [usize; 3],
        obstacle: usize,
    },
    /// A body edge and the analytic ball `obstacles[obstacle]`: active when the centre projects
    /// inside the edge.
    EdgeSphere { edge: [usize; 2], obstacle: usize },
}

impl Candidate {
    /// A hash of a set of stencils, whatever their order: equal for the same stencils.
    pub fn fingerprint(stencils: impl Iterator<Item = Candidate>) -> u64 {
        let mut sorted: Vec<Candidate> = stencils.collect();
        sorted.sort_unstable();
        let mut hasher = std::collections::hash_map::DefaultHasher::new();
        std::hash::Hash::hash(&sorted, &mut hasher);
        std::hash::Hasher::finish(&hasher)
    }

    /// The stencil's vertex ids (the first `n` entries of the array are used): `[p, t0, t1, t2]`,
    /// `[a0, a1, b0, b1]`, `[p]`, `[t0, t1, t2]` or `[e0, e1]`.
    pub fn vertices(&self) -> ([usize; 4], usize) {
        match *self {
            Candidate::PointTriangle { point, triangle: t } => ([point, t[0], t[1], t[2]], 4),
            Candidate::EdgeEdge { a, b } => ([a[0], a[1], b[0], b[1]], 4),
            Candidate::PointPlane { point, .. } | Candidate::PointSphere { point, .. } => {
                ([point, 0, 0, 0], 1)
            }
            Candidate::TriangleSphere { triangle: t, .. } => ([t[0], t[1], t[2], 0], 3),
            Candidate::EdgeSphere { edge: e, .. } => ([e[0], e[1], 0, 0], 2),
        }
    }

    /// Positions of the stencil's vertices (the first `n` of them, as in [`Candidate::vertices`]).
    pub fn positions(&self, x: &[Vec3]) -> ([Vec3; 4], usize) {
        let (ids, n) = self.vertices();
        let mut p = [Vec3::zeros(); 4];
        for a in 0..n {
            p[a] = x[ids[a]];
        }
        (p, n)
    }
}

/// The contact geometry of one body and its obstacles (immutable; rest positions in m).
#[derive(Clone, Debug)]
pub struct CollisionMesh {
    n_body: usize,
    rest: Vec<Vec3>,
    body_vertices: Vec<usize>,
    body_edges: Vec<[usize; 2]>,
    body_faces: Vec<[usize; 3]>,
    obstacle_vertices: Vec<usize>,
    obstacle_edges: Vec<[usize; 2]>,
    obstacle_faces: Vec<[usize; 3]>,
    /// For each mesh obstacle: its index in `obstacles` and the first id of its vertices.
    mesh_obstacle_offsets: Vec<(usize, usize)>,
    obstacles: Vec<Obstacle>,
    self_contact: bool,
}

impl CollisionMesh {
    /// The boundary of a tetrahedral body, its obstacles and whether the body may touch itself.
    pub fn from_tet_mesh(mesh: &TetMesh, obstacles: Vec<Obstacle>, self_contact: bool) -> Self {
        let faces = mesh.boundary_faces();
        Self::try_new(mesh.rest(), &faces, obstacles, self_contact)
            .expect("a validated tet mesh has a valid boundary")
    }

    /// A body with rest node positions `rest_nodes` (m) whose boundary is `faces` (node indices,
    /// outward orientation), its obstacles, and whether self-contact is on.
    pub fn try_new(
        rest_nodes: &[[f64; 3]],
        faces: &[[usize; 3]],
        obstacles: Vec<Obstacle>,
        self_contact: bool,
    ) -> Result<Self> {
        check_finite("rest nodes", rest_nodes.as_flattened())?;
        let n_body = rest_nodes.len();
        for (f, face) in faces.iter().enumerate() {
            for (a, &i) in face.iter().enumerate() {
                if i >= n_body {
                    return Err(Error::IndexOutOfRange {
                        param: "surface faces".into(),
                        position: 3 * f + a,
                        index: i as i64,
                        len: n_body,
                    });
                }
            }
        }
        let mut rest: Vec<Vec3> = rest_nodes.iter().map(|&p| Vec3::from(p)).collect();
        let body_faces = faces.to_vec();
        let (body_edges, _) = edges_and_closedness(&body_faces);
        let mut body_vertices: Vec<usize> = body_faces.iter().flatten().copied().collect();
        body_vertices.sort_unstable();
        body_vertices.dedup();
        let mut obstacle_vertices = Vec::new();
        let mut obstacle_edges = Vec::new();
        let mut obstacle_faces = Vec::new();
        let mut mesh_obstacle_offsets = Vec::new();
        for (k, obstacle) in obstacles.iter().enumerate() {
            if let Obstacle::Mesh(mesh) = obstacle {
                let offset = rest.len();
                mesh_obstacle_offsets.push((k, offset));
                rest.extend_from_slice(mesh.vertices());
                obstacle_vertices.extend(offset..offset + mesh.vertices().len());
                obstacle_edges.extend(mesh.edges().iter().map(|e| e.map(|i| i + offset)));
                obstacle_faces.extend(mesh.triangles().iter().map(|t| t.map(|i| i + offset)));
            }
        }
        Ok(CollisionMesh {
            n_body,
            rest,
            body_vertices,
            body_edges,
            body_faces,
            obstacle_vertices,
            obstacle_edges,
            obstacle_faces,
            mesh_obstacle_offsets,
            obstacles,
            self_contact,
        })
    }

    /// Number of body nodes (the first vertex ids).
    pub fn n_body(&self) -> usize {
        self.n_body
    }

    /// Number of vertices: body nodes and mesh-obstacle vertices.
    pub fn n_vertices(&self) -> usize {
        self.rest.len()
    }

    /// Positions of all vertices at rest (m): the body's rest nodes, then the obstacles' vertices
    /// where this geometry holds them.
    pub fn rest(&self) -> &[Vec3] {
        &self.rest
    }

    /// Body nodes on the boundary surface, increasing.
    pub fn body_vertices(&self) -> &[usize] {
        &self.body_vertices
    }

    pub fn body_edges(&self) -> &[[usize; 2]] {
        &self.body_edges
    }

    pub fn body_faces(&self) -> &[[usize; 3]] {
        &self.body_faces
    }

    pub fn obstacle_vertices(&self) -> &[usize] {
        &self.obstacle_vertices
    }

    pub fn obstacle_edges(&self) -> &[[usize; 2]] {
        &self.obstacle_edges
    }

    pub fn obstacle_faces(&self) -> &[[usize; 3]] {
        &self.obstacle_faces
    }

    pub fn obstacles(&self) -> &[Obstacle] {
        &self.obstacles
    }

    pub fn self_contact(&self) -> bool {
        self.self_contact
    }

    /// Whether vertex `v` belongs to an obstacle (its position is prescribed, not a DOF).
    pub fn is_obstacle_vertex(&self, v: usize) -> bool {
        v >= self.n_body
    }

    /// Index in [`CollisionMesh::obstacles`] of the mesh obstacle owning vertex `v`
    /// (`None` for body vertices).
    pub fn obstacle_of_vertex(&self, v: usize) -> Option<usize> {
        if v < self.n_body {
            return None;
        }
        self.mesh_obstacle_offsets
            .iter()
            .rev()
            .find(|(_, offset)| *offset <= v)
            .map(|(k, _)| *k)
    }

    pub(crate) fn plane(&self, obstacle: usize) -> &Plane {
        match &self.obstacles[obstacle] {
            Obstacle::Plane(plane) => plane,
            other => panic!("obstacle {obstacle} is not a plane: {other:?}"),
        }
    }

    pub(crate) fn sphere(&self, obstacle: usize) -> &Sphere {
        match &self.obstacles[obstacle] {
            Obstacle::Sphere(sphere) => sphere,
            other => panic!("obstacle {obstacle} is not a sphere: {other:?}"),
        }
    }

    /// The same geometry with obstacle `k` translated by `translations[k]` (m): its mesh
    /// vertices, a plane's point, a sphere's centre. The body is unchanged. Moving obstacles
    /// follow prescribed paths this way, one copy per time step.
    pub fn moved(&self, translations: &[Vec3]) -> Self {
        assert_eq!(
            translations.len(),
            self.obstacles.len(),
            "one translation per obstacle"
        );
        let mut out = self.clone();
        for (k, (obstacle, t)) in out.obstacles.iter_mut().zip(translations).enumerate() {
            match obstacle {
                Obstacle::Plane(plane) => plane.point += t,
                Obstacle::Sphere(sphere) => sphere.center += t,
                Obstacle::Mesh(mesh) => {
                    let (_, offset) = self
                        .mesh_obstacle_offsets
                        .iter()
                        .find(|(index, _)| *index == k)
                        .expect("every mesh obstacle has an offset");
                    for v in &mut out.rest[*offset..offset + mesh.vertices().len()] {
                        *v += t;
                    }
                }
            }
        }
        out
    }

    /// Positions of all vertices: the body's from `body` (flat, `3 n_body`, m), the obstacles'
    /// where this geometry holds them (see [`CollisionMesh::moved`]).
    pub fn vertices(&self, body: &[f64]) -> Result<Vec<Vec3>> {
        if body.len() != 3 * self.n_body {
            return Err(Error::shape(
                "positions",
                format!("{} values (3 x {} nodes)", 3 * self.n_body, self.n_body),
                format!("{} values", body.len()),
            ));
        }
        let mut x: Vec<Vec3> = body
            .chunks_exact(3)
            .map(|p| Vec3::new(p[0], p[1], p[2]))
            .collect();
        x.extend_from_slice(&self.rest[self.n_body..]);
        Ok(x)
    }
}
