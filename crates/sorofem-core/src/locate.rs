//! Point location in a tetrahedral mesh through a uniform grid of tet bounding boxes: which tet
//! contains a point, and its barycentric coordinates (used to embed cables and markers).

use crate::mesh::TetMesh;
use nalgebra::Vector3;

/// Where a point lies relative to the mesh.
#[derive(Clone, Debug, PartialEq)]
pub struct Location {
    pub tet: usize,
    /// Barycentric weights of the tet's nodes (sum 1, all >= 0 after snapping).
    pub weights: [f64; 4],
    /// Distance (m) from the query point to the point the weights describe: 0 inside the mesh.
    pub distance: f64,
}

/// A uniform grid over the mesh's bounding box; each cell lists the tets whose bounding boxes
/// overlap it. Cells are about twice the mean tet size, so a cell holds a few dozen tets.
pub struct PointLocator<'a> {
    mesh: &'a TetMesh,
    origin: Vector3<f64>,
    cell: f64,
    dims: [usize; 3],
    cells: Vec<Vec<u32>>,
}

impl<'a> PointLocator<'a> {
    pub fn new(mesh: &'a TetMesh) -> Self {
        let rest = mesh.rest();
        let mut lo = Vector3::repeat(f64::INFINITY);
        let mut hi = Vector3::repeat(f64::NEG_INFINITY);
        for p in rest {
            lo = lo.inf(&Vector3::from(*p));
            hi = hi.sup(&Vector3::from(*p));
        }
        let mean_volume = mesh.volumes().iter().sum::<f64>() / mesh.n_tets() as f64;
        let cell = 2.0 * mean_volume.cbrt().max(1e-12);
        let dims: [usize; 3] =
            std::array::from_fn(|a| (((hi[a] - lo[a]) / cell).ceil() as usize).clamp(1, 512));
        let mut cells = vec![Vec::new(); dims[0] * dims[1] * dims[2]];
        let mut locator = PointLocator {
            mesh,
            origin: lo,
            cell,
            dims,
            cells: Vec::new(),
        };
        for (e, tet) in mesh.tets().iter().enumerate() {
            let mut tlo = Vector3::repeat(f64::INFINITY);
            let mut thi = Vector3::repeat(f64::NEG_INFINITY);
            for &i in tet {
                tlo = tlo.inf(&Vector3::from(rest[i]));
                thi = thi.sup(&Vector3::from(rest[i]));
            }
            let (a, b) = (locator.cell_of(&tlo), locator.cell_of(&thi));
            for k in a[2]..=b[2] {
                for j in a[1]..=b[1] {
                    for i in a[0]..=b[0] {
                        cells[i + dims[0] * (j + dims[1] * k)].push(e as u32);
                    }
                }
            }
        }
        locator.cells = cells;
        locator
    }

    fn cell_of(&self, p: &Vector3<f64>) -> [usize; 3] {
        std::array::from_fn(|a| {
            (((p[a] - self.origin[a]) / self.cell).floor().max(0.0) as usize).min(self.dims[a] - 1)
        })
    }

    /// Barycentric coordinates of `p` in tet `e` (may be negative outside it).
    pub fn barycentric(&self, e: usize, p: &Vector3<f64>) -> [f64; 4] {
        let x0 = Vector3::from(self.mesh.rest()[self.mesh.tets()[e][0]]);
        let g = self.mesh.shape_gradients(e);
        let d = p - x0;
        [1.0 + g[0].dot(&d), g[1].dot(&d), g[2].dot(&d), g[3].dot(&d)]
    }

    /// Barycentric weights (all >= 0) of the point of tet `e` closest to `p`, which lies
    /// outside it, and the distance (m) to that point: the closest point over its four faces.
    fn closest_point(&self, e: usize, p: &Vector3<f64>) -> ([f64; 4], f64) {
        let tet = self.mesh.tets()[e];
        let x: [Vector3<f64>; 4] = std::array::from_fn(|a| Vector3::from(self.mesh.rest()[tet[a]]));
        let mut best = (f64::INFINITY, [0.0; 4]);
        for skip in 0..4 {
            let face: Vec<usize> = (0..4).filter(|&a| a != skip).collect();
            let (u, v, w) = closest_on_triangle(p, &x[face[0]], &x[face[1]], &x[face[2]]);
            let q = u * x[face[0]] + v * x[face[1]] + w * x[face[2]];
            let distance = (q - p).norm();
            if distance < best.0 {
                let mut weights = [0.0; 4];
                weights[face[0]] = u;
                weights[face[1]] = v;
                weights[face[2]] = w;
                best = (distance, weights);
            }
        }
        (best.1, best.0)
    }

    /// The tet containing `p`, or else the closest one found within `search_radius` (m), with
    /// the point projected onto its closest point (`distance` > 0, the exact point-to-tet
    /// distance).
    /// `None` when no tet lies within the search radius.
    pub fn locate(&self, p: [f64; 3], search_radius: f64) -> Option<Location> {
        let p = Vector3::from(p);
        let inside_tolerance = -crate::tolerance::INSIDE_TET;
        let mut best: Option<Location> = None;
        // Rings beyond the grid hold no cell: a huge radius must not loop over them.
        let widest = self.dims.iter().copied().max().unwrap_or(1) as f64;
        let reach = (search_radius / self.cell).ceil().min(widest) as isize;
        let center = self.cell_of(&p);
        for ring in 0..=reach.max(0) {
            for dk in -ring..=ring {
                for dj in -ring..=ring {
                    for di in -ring..=ring {
                        if di.abs().max(dj.abs()).max(dk.abs()) != ring {
                            continue;
                        }
                        let idx = [
                            center[0] as isize + di,
                            center[1] as isize + dj,
                            center[2] as isize + dk,
                        ];
                        if (0..3).any(|a| idx[a] < 0 || idx[a] >= self.dims[a] as isize) {
                            continue;
                        }
                        let cell = idx[0] as usize
                            + self.dims[0] * (idx[1] as usize + self.dims[1] * idx[2] as usize);
                        for &e in &self.cells[cell] {
                            let e = e as usize;
                            let w = self.barycentric(e, &p);
                            if w.iter().all(|&v| v >= inside_tolerance) {
                                let sum: f64 = w.iter().map(|v| v.max(0.0)).sum();
                                return Some(Location {
                                    tet: e,
                                    weights: w.map(|v| v.max(0.0) / sum),
                                    distance: 0.0,
                                });
                            }
                            let (weights, distance) = self.closest_point(e, &p);
                            if distance <= search_radius
                                && best.as_ref().is_none_or(|b| distance < b.distance)
                            {
                                best = Some(Location {
                                    tet: e,
                                    weights,
                                    distance,
                                });
                            }
                        }
                    }
                }
            }
            // A hit in ring r may still be beaten by a tet in ring r + 1, but not beyond.
            if best
                .as_ref()
                .is_some_and(|b| b.distance < ring as f64 * self.cell)
            {
                break;
            }
        }
        best
    }
}

/// Locates each of `points` (m) in `mesh` with one [`PointLocator`]: `None` for a point farther
/// than `search_radius` (m) from every tet.
pub fn locate_points(
    mesh: &TetMesh,
    points: &[[f64; 3]],
    search_radius: f64,
) -> crate::error::Result<Vec<Option<Location>>> {
    crate::error::check_finite("points", points.as_flattened())?;
    if !(search_radius >= 0.0 && search_radius.is_finite()) {
        return Err(crate::error::Error::invalid(
            "search_radius",
            "a finite distance >= 0 m",
            search_radius,
        ));
    }
    let locator = PointLocator::new(mesh);
    Ok(points
        .iter()
        .map(|&p| locator.locate(p, search_radius))
        .collect())
}

/// Barycentric coordinates `(u, v, w)` (>= 0, sum 1) of the point of triangle `abc` closest to
/// `p`: the Voronoi-region walk over vertices, edges and face (Ericson, Real-Time Collision
/// Detection, 5.1.5).
fn closest_on_triangle(
    p: &Vector3<f64>,
    a: &Vector3<f64>,
    b: &Vector3<f64>,
    c: &Vector3<f64>,
) -> (f64, f64, f64) {
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(&ap), ac.dot(&ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return (1.0, 0.0, 0.0);
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(&bp), ac.dot(&bp));
    if d3 >= 0.0 && d4 <= d3 {
        return (0.0, 1.0, 0.0);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let t = d1 / (d1 - d3);
        return (1.0 - t, t, 0.0);
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(&cp), ac.dot(&cp));
    if d6 >= 0.0 && d5 <= d6 {
        return (0.0, 0.0, 1.0);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let t = d2 / (d2 - d6);
        return (1.0 - t, 0.0, t);
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let t = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return (0.0, 1.0 - t, t);
    }
    let denominator = 1.0 / (va + vb + vc);
    let (v, w) = (vb * denominator, vc * denominator);
    (1.0 - v - w, v, w)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Orientation;

    fn unit_tet() -> TetMesh {
        let points = vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
        ];
        TetMesh::try_new(points, &[[0, 1, 2, 3]], Orientation::Reorient)
            .unwrap()
            .0
    }

    /// A search radius far beyond the mesh searched ring after ring of the grid past its end
    /// (`isize::MAX` rings for an infinite-looking radius): the rings stop at the grid's edge.
    #[test]
    fn a_huge_search_radius_stops_at_the_grid() {
        let mesh = unit_tet();
        let hit = super::locate_points(&mesh, &[[10.0, 10.0, 10.0]], 1e300).unwrap();
        let hit = hit[0].as_ref().expect("the tet is within the radius");
        // The closest point is the centre (1/3, 1/3, 1/3) of the slanted face.
        let expected = 3f64.sqrt() * (10.0 - 1.0 / 3.0);
        assert!((hit.distance - expected).abs() < 1e-12, "{hit:?}");
        assert!(hit
            .weights
            .iter()
            .skip(1)
            .all(|w| (w - 1.0 / 3.0).abs() < 1e-12));
    }

    #[test]
    fn snapping_projects_onto_the_closest_point_of_the_tet() {
        let mesh = unit_tet();
        let locator = PointLocator::new(&mesh);
        // Below the face y = 0, over its interior: clamping the barycentric coordinates would
        // give (0.25, 0, 0.25) at distance 1.06; the closest point is (0.5, 0, 0.5) at 1.
        let hit = locator.locate([0.5, -1.0, 0.5], 2.0).unwrap();
        assert!((hit.distance - 1.0).abs() < 1e-12, "{hit:?}");
        let q = locator.barycentric(0, &Vector3::new(0.5, 0.0, 0.5));
        for a in 0..4 {
            assert!((hit.weights[a] - q[a]).abs() < 1e-12, "{hit:?}");
        }
        // Beyond a vertex and beyond an edge.
        let vertex = locator.locate([2.0, -1.0, -1.0], 3.0).unwrap();
        assert!(
            (vertex.distance - 3f64.sqrt()).abs() < 1e-12
                && (vertex.weights[1] - 1.0).abs() < 1e-12
        );
        let edge = locator.locate([0.5, -1.0, -1.0], 3.0).unwrap();
        assert!((edge.distance - 2f64.sqrt()).abs() < 1e-12, "{edge:?}");
        // Out of reach.
        assert!(locator.locate([0.5, -1.0, 0.5], 0.9).is_none());
    }

    #[test]
    fn triangle_regions() {
        let (a, b, c) = (
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(1.0, 0.0, 0.0),
            Vector3::new(0.0, 1.0, 0.0),
        );
        let cases = [
            ([0.2, 0.2, 5.0], [0.2, 0.2, 0.0]),
            ([-1.0, -1.0, 0.0], [0.0, 0.0, 0.0]),
            ([2.0, -0.5, 1.0], [1.0, 0.0, 0.0]),
            ([0.5, -3.0, 0.0], [0.5, 0.0, 0.0]),
            ([1.0, 1.0, 0.0], [0.5, 0.5, 0.0]),
            ([-2.0, 0.5, 0.0], [0.0, 0.5, 0.0]),
            ([-0.5, 2.0, 0.0], [0.0, 1.0, 0.0]),
        ];
        for (p, expected) in cases {
            let (u, v, w) = closest_on_triangle(&Vector3::from(p), &a, &b, &c);
            let q = u * a + v * b + w * c;
            assert!(
                (q - Vector3::from(expected)).norm() < 1e-12,
                "{p:?} -> {q:?}"
            );
            assert!(u >= 0.0 && v >= 0.0 && w >= 0.0 && (u + v + w - 1.0).abs() < 1e-12);
        }
    }
}
