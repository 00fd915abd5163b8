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

    fn point_of(&self, e: usize, weights: &[f64; 4]) -> Vector3<f64> {
        let tet = self.mesh.tets()[e];
        (0..4)
            .map(|a| weights[a] * Vector3::from(self.mesh.rest()[tet[a]]))
            .sum()
    }

    /// The tet containing `p`, or else the closest one found within `search_radius` (m), with
    /// the point projected onto it by clamping its barycentric coordinates (`distance` > 0).
    /// `None` when no tet lies within the search radius.
    pub fn locate(&self, p: [f64; 3], search_radius: f64) -> Option<Location> {
        let p = Vector3::from(p);
        let inside_tolerance = -1e-10;
        let mut best: Option<Location> = None;
        let reach = (search_radius / self.cell).ceil() as isize;
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
                            let mut clamped = w.map(|v| v.max(0.0));
                            let sum: f64 = clamped.iter().sum();
                            clamped.iter_mut().for_each(|v| *v /= sum);
                            let distance = (self.point_of(e, &clamped) - p).norm();
                            if distance <= search_radius
                                && best.as_ref().is_none_or(|b| distance < b.distance)
                            {
                                best = Some(Location {
                                    tet: e,
                                    weights: clamped,
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
