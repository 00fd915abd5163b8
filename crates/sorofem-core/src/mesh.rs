//! Tetrahedral meshes: validated rest geometry, per-element shape gradients, boundary and queries.

use crate::error::{check_finite, Error, Result};
use crate::tolerance::DEGENERATE_TET_VOLUME;
use nalgebra::{Matrix3, Vector3};
use std::collections::HashMap;

/// What to do with a tetrahedron whose nodes are ordered with negative orientation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Orientation {
    /// Swap its last two nodes so that its volume is positive, and report its index.
    Reorient,
    /// Reject the mesh with [`Error::InvertedTet`].
    Reject,
}

/// A linear tetrahedral mesh in its rest configuration.
///
/// Invariants (established by [`TetMesh::try_new`]): every tetrahedron has positive volume, every
/// index is in range, every coordinate is finite.
#[derive(Clone, Debug)]
pub struct TetMesh {
    rest: Vec<[f64; 3]>,
    tets: Vec<[usize; 4]>,
    volumes: Vec<f64>,
    /// Gradients of the four linear shape functions of each tet, in 1/m: F = sum_a x_a (x) g_a.
    shape_gradients: Vec<[Vector3<f64>; 4]>,
}

fn signed_volume(p: &[[f64; 3]], t: &[usize; 4]) -> f64 {
    let d = |a: usize| Vector3::from(p[t[a]]) - Vector3::from(p[t[0]]);
    Matrix3::from_columns(&[d(1), d(2), d(3)]).determinant() / 6.0
}

fn longest_edge(p: &[[f64; 3]], t: &[usize; 4]) -> f64 {
    let mut longest: f64 = 0.0;
    for a in 0..4 {
        for b in a + 1..4 {
            longest = longest.max((Vector3::from(p[t[a]]) - Vector3::from(p[t[b]])).norm());
        }
    }
    longest
}

impl TetMesh {
    /// Validates and builds a mesh from node coordinates (m) and 0-based tetrahedra.
    ///
    /// Returns the mesh and the indices of the tets that were reoriented (empty with
    /// [`Orientation::Reject`]).
    pub fn try_new(
        rest: Vec<[f64; 3]>,
        tets_in: &[[i64; 4]],
        orientation: Orientation,
    ) -> Result<(Self, Vec<usize>)> {
        if rest.is_empty() {
            return Err(Error::shape("points", "at least 4 nodes (n, 3)", "0 nodes"));
        }
        if tets_in.is_empty() {
            return Err(Error::shape(
                "tets",
                "at least one tetrahedron (m, 4)",
                "0 tetrahedra",
            ));
        }
        check_finite("points", rest.as_flattened())?;
        let n = rest.len();
        let m = tets_in.len();
        let (mut tets, mut volumes, mut shape_gradients) = (
            Vec::with_capacity(m),
            Vec::with_capacity(m),
            Vec::with_capacity(m),
        );
        let mut reoriented = Vec::new();
        // One pass: indices, distinct nodes, volume, orientation, shape gradients.
        for (e, t) in tets_in.iter().enumerate() {
            let mut tet = [0usize; 4];
            for a in 0..4 {
                if t[a] < 0 || t[a] as usize >= n {
                    return Err(Error::IndexOutOfRange {
                        param: "tets".into(),
                        position: 4 * e + a,
                        index: t[a],
                        len: n,
                    });
                }
                tet[a] = t[a] as usize;
            }
            if (0..4).any(|a| (a + 1..4).any(|b| tet[a] == tet[b])) {
                return Err(Error::DegenerateTet {
                    tet: e,
                    volume: 0.0,
                    threshold: 0.0,
                });
            }
            let mut volume = signed_volume(&rest, &tet);
            let threshold = DEGENERATE_TET_VOLUME * longest_edge(&rest, &tet).powi(3);
            if volume.abs() <= threshold {
                return Err(Error::DegenerateTet {
                    tet: e,
                    volume,
                    threshold,
                });
            }
            if volume < 0.0 {
                match orientation {
                    Orientation::Reject => return Err(Error::InvertedTet { tet: e, volume }),
                    Orientation::Reorient => {
                        tet.swap(2, 3);
                        volume = -volume;
                        reoriented.push(e);
                    }
                }
            }
            let d = |a: usize| Vector3::from(rest[tet[a]]) - Vector3::from(rest[tet[0]]);
            let dm = Matrix3::from_columns(&[d(1), d(2), d(3)]);
            // Non-degeneracy was checked above, so the inverse exists.
            let dm_inv = dm.try_inverse().expect("non-degenerate tetrahedron");
            let g1 = dm_inv.row(0).transpose();
            let g2 = dm_inv.row(1).transpose();
            let g3 = dm_inv.row(2).transpose();
            shape_gradients.push([-(g1 + g2 + g3), g1, g2, g3]);
            tets.push(tet);
            volumes.push(volume);
        }
        Ok((
            TetMesh {
                rest,
                tets,
                volumes,
                shape_gradients,
            },
            reoriented,
        ))
    }

    /// A box `[origin, origin + size]` of `cells[0] x cells[1] x cells[2]` hexahedra, each split into
    /// six tetrahedra around one of its diagonals (Kuhn subdivision), mirrored from hex to hex so
    /// that the split is conforming and symmetric (the paper's `box2.tet` pattern).
    ///
    /// Node `(i, j, k)` has index `i + (nx + 1) (j + (ny + 1) k)`. The 8x2x2 box has 81 nodes and 192 tets.
    pub fn box_mesh(size: [f64; 3], cells: [usize; 3], origin: [f64; 3]) -> Result<Self> {
        for a in 0..3 {
            if !(size[a] > 0.0 && size[a].is_finite()) {
                return Err(Error::invalid(
                    "size",
                    "three positive lengths (m)",
                    format!("{size:?}"),
                ));
            }
            if cells[a] == 0 {
                return Err(Error::invalid(
                    "cells",
                    "three positive cell counts",
                    format!("{cells:?}"),
                ));
            }
        }
        check_finite("origin", &origin)?;
        let [nx, ny, nz] = cells;
        let node = |i: usize, j: usize, k: usize| (i + (nx + 1) * (j + (ny + 1) * k)) as i64;
        let mut points = Vec::with_capacity((nx + 1) * (ny + 1) * (nz + 1));
        for k in 0..=nz {
            for j in 0..=ny {
                for i in 0..=nx {
                    points.push([
                        origin[0] + size[0] * i as f64 / nx as f64,
                        origin[1] + size[1] * j as f64 / ny as f64,
                        origin[2] + size[2] * k as f64 / nz as f64,
                    ]);
                }
            }
        }
        const PERMUTATIONS: [[usize; 3]; 6] = [
            [0, 1, 2],
            [0, 2, 1],
            [1, 0, 2],
            [1, 2, 0],
            [2, 0, 1],
            [2, 1, 0],
        ];
        let mut tets = Vec::with_capacity(6 * nx * ny * nz);
        for k in 0..nz {
            for j in 0..ny {
                for i in 0..nx {
                    // Mirror every other hex so that neighbouring diagonals alternate: the mesh is
                    // then symmetric about the box's mid-planes (no spurious twist of a beam under
                    // symmetric loads) and identical to the paper's box2.tet.
                    let flip = [i % 2, 1 - j % 2, k % 2];
                    for perm in PERMUTATIONS {
                        let mut corner = [i + flip[0], j + flip[1], k + flip[2]];
                        let mut tet = [node(corner[0], corner[1], corner[2]); 4];
                        for (step, &axis) in perm.iter().enumerate() {
                            corner[axis] = if flip[axis] == 1 {
                                corner[axis] - 1
                            } else {
                                corner[axis] + 1
                            };
                            tet[step + 1] = node(corner[0], corner[1], corner[2]);
                        }
                        tets.push(tet);
                    }
                }
            }
        }
        // Odd permutations come out negatively oriented; reorienting them is expected here.
        Ok(TetMesh::try_new(points, &tets, Orientation::Reorient)?.0)
    }

    pub fn n_nodes(&self) -> usize {
        self.rest.len()
    }

    pub fn n_tets(&self) -> usize {
        self.tets.len()
    }

    /// Rest coordinates (m), one `[x, y, z]` per node.
    pub fn rest(&self) -> &[[f64; 3]] {
        &self.rest
    }

    pub fn tets(&self) -> &[[usize; 4]] {
        &self.tets
    }

    /// Length (m) of the diagonal of the rest coordinates' axis-aligned bounding box.
    pub fn diameter(&self) -> f64 {
        let mut low = [f64::INFINITY; 3];
        let mut high = [f64::NEG_INFINITY; 3];
        for p in &self.rest {
            for k in 0..3 {
                low[k] = low[k].min(p[k]);
                high[k] = high[k].max(p[k]);
            }
        }
        (0..3)
            .map(|k| (high[k] - low[k]).powi(2))
            .sum::<f64>()
            .sqrt()
    }

    /// Rest volumes (m^3), one per tet, all positive.
    pub fn volumes(&self) -> &[f64] {
        &self.volumes
    }

    /// Shape-function gradients (1/m) of tet `e`: `F = sum_a x_a g_a^T`.
    pub fn shape_gradients(&self, e: usize) -> &[Vector3<f64>; 4] {
        &self.shape_gradients[e]
    }

    /// Deformation gradient `F = I + sum_a u_a g_a^T` of tet `e` for nodal displacements `u`
    /// (m, 3 n values, node-major).
    pub fn deformation_gradient(&self, e: usize, u: &[f64]) -> Matrix3<f64> {
        let mut f = Matrix3::identity();
        for (a, &node) in self.tets[e].iter().enumerate() {
            let ua = Vector3::new(u[3 * node], u[3 * node + 1], u[3 * node + 2]);
            f += ua * self.shape_gradients[e][a].transpose();
        }
        f
    }

    /// Boundary triangles (faces belonging to exactly one tet), oriented with outward normals,
    /// sorted.
    pub fn boundary_faces(&self) -> Vec<[usize; 3]> {
        self.boundary().into_iter().map(|(face, _)| face).collect()
    }

    /// [`TetMesh::boundary_faces`] with the tet each face belongs to.
    pub fn boundary(&self) -> Vec<([usize; 3], usize)> {
        // Outward faces of a positively oriented tet (0, 1, 2, 3).
        const FACES: [[usize; 3]; 4] = [[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]];
        let mut count: HashMap<[usize; 3], (usize, [usize; 3], usize)> = HashMap::new();
        for (e, tet) in self.tets.iter().enumerate() {
            for face in FACES {
                let oriented = [tet[face[0]], tet[face[1]], tet[face[2]]];
                let mut key = oriented;
                key.sort_unstable();
                count
                    .entry(key)
                    .and_modify(|c| c.0 += 1)
                    .or_insert((1, oriented, e));
            }
        }
        let mut faces: Vec<([usize; 3], usize)> = count
            .into_values()
            .filter(|(c, _, _)| *c == 1)
            .map(|(_, face, owner)| (face, owner))
            .collect();
        faces.sort_unstable();
        faces
    }

    /// Checks the corners of a query box: finite, `min <= max` componentwise.
    pub fn check_box(min: [f64; 3], max: [f64; 3]) -> Result<()> {
        check_finite("min", &min)?;
        check_finite("max", &max)?;
        if (0..3).any(|a| min[a] > max[a]) {
            return Err(Error::invalid(
                "min, max",
                "min <= max componentwise",
                format!("{min:?} and {max:?}"),
            ));
        }
        Ok(())
    }

    /// Nodes with `min <= x <= max` componentwise, in increasing order.
    pub fn nodes_in_box(&self, min: [f64; 3], max: [f64; 3]) -> Vec<usize> {
        self.nodes_where(|p| (0..3).all(|a| p[a] >= min[a] && p[a] <= max[a]))
    }

    /// Nodes within `tolerance * diameter()` of the plane through `point` with normal `normal`
    /// (any non-zero length): the tolerance is relative to the mesh size, so the same value
    /// works in metres and millimetres ([`crate::tolerance::ON_PLANE`] is the usual one).
    pub fn nodes_on_plane(
        &self,
        point: [f64; 3],
        normal: [f64; 3],
        tolerance: f64,
    ) -> Result<Vec<usize>> {
        check_finite("point", &point)?;
        let n = Vector3::from(normal);
        let len = n.norm();
        if !(len > 0.0 && len.is_finite()) {
            return Err(Error::invalid(
                "normal",
                "a non-zero finite vector",
                format!("{normal:?}"),
            ));
        }
        if !(tolerance >= 0.0 && tolerance.is_finite()) {
            return Err(Error::invalid(
                "tolerance",
                "a finite tolerance >= 0 (relative to the mesh size)",
                tolerance,
            ));
        }
        let n = n / len;
        let p0 = Vector3::from(point);
        let distance = tolerance * self.diameter();
        Ok(self.nodes_where(|p| (Vector3::from(*p) - p0).dot(&n).abs() <= distance))
    }

    pub fn nodes_where(&self, predicate: impl Fn(&[f64; 3]) -> bool) -> Vec<usize> {
        (0..self.n_nodes())
            .filter(|&i| predicate(&self.rest[i]))
            .collect()
    }

    /// Rest positions as one flat node-major vector of length `3 n`.
    pub fn rest_flat(&self) -> Vec<f64> {
        self.rest.as_flattened().to_vec()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn diameter_is_the_bounding_box_diagonal() {
        let mesh = TetMesh::box_mesh([0.4, 0.1, 0.2], [4, 1, 2], [1.0, -2.0, 0.5]).unwrap();
        assert!((mesh.diameter() - (0.16f64 + 0.01 + 0.04).sqrt()).abs() < 1e-15);
    }

    #[test]
    fn box_has_paper_counts_and_closed_boundary() {
        let mesh = TetMesh::box_mesh([0.4, 0.1, 0.1], [8, 2, 2], [0.0; 3]).unwrap();
        assert_eq!(mesh.n_nodes(), 81);
        assert_eq!(mesh.n_tets(), 192);
        let volume: f64 = mesh.volumes().iter().sum();
        assert!((volume - 0.004).abs() < 1e-15);
        // A closed surface: by the divergence theorem sum of outward area vectors vanishes and
        // (1/3) sum x . n A equals the volume.
        let faces = mesh.boundary_faces();
        let p = |i: usize| Vector3::from(mesh.rest()[i]);
        let mut area_sum = Vector3::zeros();
        let mut enclosed = 0.0;
        for f in &faces {
            let n = (p(f[1]) - p(f[0])).cross(&(p(f[2]) - p(f[0]))) / 2.0;
            area_sum += n;
            enclosed += p(f[0]).dot(&n) / 3.0;
        }
        assert!(area_sum.norm() < 1e-14);
        assert!((enclosed - 0.004).abs() < 1e-14);
        // Surface of an 8x2x2 grid: 2*(8*2 + 8*2 + 2*2) quads, 2 triangles each.
        assert_eq!(faces.len(), 2 * 2 * (16 + 16 + 4));
        // Each face's owner has all three of its nodes.
        for (face, owner) in mesh.boundary() {
            assert!(face.iter().all(|i| mesh.tets()[owner].contains(i)));
        }
    }

    #[test]
    fn nodes_on_plane_take_a_tolerance_relative_to_the_mesh_size() {
        // The same box in metres and in millimetres gives the same nodes.
        for scale in [1.0, 1e3] {
            let mesh =
                TetMesh::box_mesh([0.4 * scale, 0.1 * scale, 0.1 * scale], [8, 2, 2], [0.0; 3])
                    .unwrap();
            let end = mesh.nodes_on_plane([0.4 * scale, 0.0, 0.0], [2.0, 0.0, 0.0], 1e-9);
            assert_eq!(end.unwrap().len(), 9);
            // A plane 0.5 % of the diagonal (0.42 m) away from the first cross-section at x = 0.05.
            let near = mesh.nodes_on_plane([0.052 * scale, 0.0, 0.0], [1.0, 0.0, 0.0], 5e-3);
            assert_eq!(near.unwrap().len(), 9);
        }
        let mesh = TetMesh::box_mesh([1.0; 3], [1, 1, 1], [0.0; 3]).unwrap();
        assert!(mesh.nodes_on_plane([0.0; 3], [0.0; 3], 1e-9).is_err());
        assert!(mesh
            .nodes_on_plane([0.0; 3], [1.0, 0.0, 0.0], -1.0)
            .is_err());
    }
}
