//! Rigid obstacles: analytic half-spaces and spheres, and triangle surfaces (a box is one with 12
//! triangles). Positions in m.

use super::distance::Vec3;
use crate::error::{check_finite, Error, Result};
use nalgebra::Matrix3;
use std::collections::HashMap;

/// Triangles with area below this fraction of (longest edge)^2 are degenerate (an equilateral
/// triangle has 0.43).
const DEGENERACY_RATIO: f64 = 1e-12;

/// The half-space `{x : n . (x - point) >= 0}`; the body stays on the side the unit normal `n`
/// points to, and its signed distance `n . (x - point)` must stay positive.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Plane {
    pub point: Vec3,
    /// Unit outward normal (pointing towards the body).
    pub normal: Vec3,
}

impl Plane {
    /// A plane through `point` (m) with normal direction `normal` (any length > 0, normalised).
    pub fn try_new(point: [f64; 3], normal: [f64; 3]) -> Result<Self> {
        check_finite("plane.point", &point)?;
        check_finite("plane.normal", &normal)?;
        let n = Vec3::from(normal);
        let length = n.norm();
        if length == 0.0 {
            return Err(Error::invalid(
                "plane.normal",
                "a nonzero vector",
                "[0, 0, 0]",
            ));
        }
        Ok(Plane {
            point: Vec3::from(point),
            normal: n / length,
        })
    }

    /// `n . (x - point)` (m): positive on the body's side.
    pub fn signed_distance(&self, x: &Vec3) -> f64 {
        self.normal.dot(&(x - self.point))
    }
}

/// A solid ball; the body stays outside.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sphere {
    pub center: Vec3,
    /// Radius (m), > 0.
    pub radius: f64,
}

impl Sphere {
    pub fn try_new(center: [f64; 3], radius: f64) -> Result<Self> {
        check_finite("sphere.center", &center)?;
        if !(radius.is_finite() && radius > 0.0) {
            return Err(Error::invalid(
                "sphere.radius",
                "a finite radius > 0 (m)",
                radius,
            ));
        }
        Ok(Sphere {
            center: Vec3::from(center),
            radius,
        })
    }

    /// `|x - center| - radius` (m): positive outside.
    pub fn signed_distance(&self, x: &Vec3) -> f64 {
        (x - self.center).norm() - self.radius
    }
}

/// A rigid triangle surface. Closed surfaces (every edge shared by exactly two triangles) bound
/// a solid the body must stay out of; open ones are one-sided sheets the body must not cross.
#[derive(Clone, Debug, PartialEq)]
pub struct ObstacleMesh {
    vertices: Vec<Vec3>,
    triangles: Vec<[usize; 3]>,
    edges: Vec<[usize; 2]>,
    closed: bool,
}

impl ObstacleMesh {
    /// Validates vertices (m) and 0-based triangles: indices in range, no degenerate triangle.
    pub fn try_new(vertices: Vec<[f64; 3]>, triangles: &[[i64; 3]]) -> Result<Self> {
        if vertices.len() < 3 || triangles.is_empty() {
            return Err(Error::shape(
                "obstacle mesh",
                "at least 3 vertices (n, 3) and 1 triangle (m, 3)",
                format!(
                    "{} vertices and {} triangles",
                    vertices.len(),
                    triangles.len()
                ),
            ));
        }
        check_finite("obstacle.vertices", vertices.as_flattened())?;
        let vertices: Vec<Vec3> = vertices.into_iter().map(Vec3::from).collect();
        let mut checked = Vec::with_capacity(triangles.len());
        for (f, t) in triangles.iter().enumerate() {
            let mut tri = [0usize; 3];
            for a in 0..3 {
                if t[a] < 0 || t[a] as usize >= vertices.len() {
                    return Err(Error::IndexOutOfRange {
                        param: "obstacle.triangles".into(),
                        position: 3 * f + a,
                        index: t[a],
                        len: vertices.len(),
                    });
                }
                tri[a] = t[a] as usize;
            }
            let [p0, p1, p2] = tri.map(|i| vertices[i]);
            let area = 0.5 * (p1 - p0).cross(&(p2 - p0)).norm();
            let longest = (p1 - p0).norm().max((p2 - p1).norm()).max((p0 - p2).norm());
            if area <= DEGENERACY_RATIO * longest * longest || longest == 0.0 {
                return Err(Error::invalid(
                    "obstacle.triangles",
                    format!(
                        "triangles of nonzero area (> {:.1e} x longest edge^2)",
                        DEGENERACY_RATIO
                    ),
                    format!("triangle {f} {tri:?} with area {area:.3e} m^2"),
                ));
            }
            checked.push(tri);
        }
        let (edges, closed) = edges_and_closedness(&checked);
        Ok(ObstacleMesh {
            vertices,
            triangles: checked,
            edges,
            closed,
        })
    }

    /// The axis-aligned box `[min, max]` (m) as 12 outward-oriented triangles.
    pub fn cuboid(min: [f64; 3], max: [f64; 3]) -> Result<Self> {
        check_finite("box.min", &min)?;
        check_finite("box.max", &max)?;
        if (0..3).any(|a| max[a] <= min[a]) {
            return Err(Error::invalid(
                "box",
                "max > min in every coordinate",
                format!("min {min:?}, max {max:?}"),
            ));
        }
        let center = [0, 1, 2].map(|a| 0.5 * (min[a] + max[a]));
        let half = [0, 1, 2].map(|a| 0.5 * (max[a] - min[a]));
        Self::oriented_box(
            center,
            half,
            [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        )
    }

    /// The box `center + R diag(half_extents) [-1, 1]^3` (m) as 12 outward-oriented triangles;
    /// `rotation` (rows of R) must be a rotation matrix.
    pub fn oriented_box(
        center: [f64; 3],
        half_extents: [f64; 3],
        rotation: [[f64; 3]; 3],
    ) -> Result<Self> {
        check_finite("box.center", &center)?;
        check_finite("box.half_extents", &half_extents)?;
        check_finite("box.rotation", rotation.as_flattened())?;
        if half_extents.iter().any(|&h| h <= 0.0) {
            return Err(Error::invalid(
                "box.half_extents",
                "positive half extents (m)",
                format!("{half_extents:?}"),
            ));
        }
        let r = Matrix3::from_row_slice(rotation.as_flattened());
        let orthogonality = (r.transpose() * r - Matrix3::identity()).abs().max();
        if orthogonality > 1e-9 || r.determinant() < 0.0 {
            return Err(Error::invalid(
                "box.rotation",
                "a proper rotation matrix (R^T R = I, det R = 1)",
                format!("{rotation:?}"),
            ));
        }
        let c = Vec3::from(center);
        // Corner k has coordinate signs from the bits of k (bit a set: +half_extents[a]).
        let vertices: Vec<[f64; 3]> = (0..8)
            .map(|k| {
                let local = Vec3::from([0, 1, 2].map(|a| {
                    if k >> a & 1 == 1 {
                        half_extents[a]
                    } else {
                        -half_extents[a]
                    }
                }));
                (c + r * local).into()
            })
            .collect();
        const TRIANGLES: [[i64; 3]; 12] = [
            [0, 2, 3],
            [0, 3, 1], // z = -h
            [4, 5, 7],
            [4, 7, 6], // z = +h
            [0, 1, 5],
            [0, 5, 4], // y = -h
            [2, 6, 7],
            [2, 7, 3], // y = +h
            [0, 4, 6],
            [0, 6, 2], // x = -h
            [1, 3, 7],
            [1, 7, 5], // x = +h
        ];
        Self::try_new(vertices, &TRIANGLES)
    }

    pub fn vertices(&self) -> &[Vec3] {
        &self.vertices
    }

    pub fn triangles(&self) -> &[[usize; 3]] {
        &self.triangles
    }

    /// Unique edges `[i, j]`, `i < j`, in increasing order.
    pub fn edges(&self) -> &[[usize; 2]] {
        &self.edges
    }

    /// Every edge is shared by exactly two triangles with opposite orientations.
    pub fn is_closed(&self) -> bool {
        self.closed
    }

    /// Generalized winding number of the surface around `x`: about 1 inside a closed,
    /// outward-oriented surface, 0 outside (the sum of the triangles' signed solid angles over
    /// 4 pi, each from Van Oosterom and Strackee's formula).
    pub fn winding_number(&self, x: &Vec3) -> f64 {
        winding_number(&self.vertices, &self.triangles, x)
    }
}

/// [`ObstacleMesh::winding_number`] of any triangle list.
pub fn winding_number(vertices: &[Vec3], triangles: &[[usize; 3]], x: &Vec3) -> f64 {
    let mut total = 0.0;
    for t in triangles {
        let [a, b, c] = t.map(|i| vertices[i] - x);
        let (la, lb, lc) = (a.norm(), b.norm(), c.norm());
        let numerator = a.dot(&b.cross(&c));
        let denominator = la * lb * lc + a.dot(&b) * lc + a.dot(&c) * lb + b.dot(&c) * la;
        total += 2.0 * numerator.atan2(denominator);
    }
    total / (4.0 * std::f64::consts::PI)
}

/// Unique edges of a triangle list and whether every edge is used once in each direction.
pub(crate) fn edges_and_closedness(triangles: &[[usize; 3]]) -> (Vec<[usize; 2]>, bool) {
    let mut directed: HashMap<[usize; 2], usize> = HashMap::new();
    for t in triangles {
        for a in 0..3 {
            *directed.entry([t[a], t[(a + 1) % 3]]).or_insert(0) += 1;
        }
    }
    let closed = directed
        .iter()
        .all(|(&[i, j], &count)| count == 1 && directed.get(&[j, i]) == Some(&1));
    let mut edges: Vec<[usize; 2]> = directed
        .keys()
        .map(|&[i, j]| [i.min(j), i.max(j)])
        .collect();
    edges.sort_unstable();
    edges.dedup();
    (edges, closed)
}

/// An obstacle the body must not touch.
#[derive(Clone, Debug, PartialEq)]
pub enum Obstacle {
    Plane(Plane),
    Sphere(Sphere),
    Mesh(ObstacleMesh),
}
