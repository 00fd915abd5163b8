//! A kept factorisation rotated with the body (stiffness warping of its inverse, after Müller
//! et al., "Stable real-time deformations", SCA 2002).
//!
//! An energy that is invariant under rigid rotations (every elastic law, cables, lumped
//! inertia, gravity) has a Hessian that rotates with the body: at `x = Q x_k`,
//! `H(x) = Q H(x_k) Q^T` with `Q` acting on each node's three displacements. A kept factor of
//! `H(x_k)` therefore serves a rotated body as `R H(x_k)^{-1} R^T`, `R` block-diagonal of node
//! rotations. Without it, modified Newton on a swinging body loses its contraction to the
//! rotation alone: the rotated stiff directions of the kept factor land on the soft ones.

use crate::mesh::TetMesh;
use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;

/// The configuration `x_k` of a kept factorisation, as what its node rotations need: each tet's
/// inverse deformation gradient `F(x_k)^{-1}` (`F(x) F(x_k)^{-1} = D(x) D(x_k)^{-1}`, `D` the edge
/// matrix `[x_1 - x_0, x_2 - x_0, x_3 - x_0]`).
#[derive(Clone, Debug)]
pub(crate) struct WarpReference {
    inverse_gradients: Vec<Matrix3<f64>>,
}

/// The rotation of the polar decomposition `A = R S` of a matrix with positive determinant, by
/// Newton's iteration `R <- (R + R^{-T}) / 2` (Higham 1986), which converges quadratically from
/// `A` scaled to unit size; `None` for a matrix without one (singular, reflected, not finite).
fn polar_rotation(a: &Matrix3<f64>) -> Option<Matrix3<f64>> {
    let size = a.norm() / 3f64.sqrt();
    if !(size > 0.0 && size.is_finite() && a.determinant() > 0.0) {
        return None;
    }
    let mut r = a / size;
    for _ in 0..20 {
        let next = 0.5 * (r + r.try_inverse()?.transpose());
        let change = (next - r).norm();
        r = next;
        if change <= 1e-12 {
            return Some(r);
        }
    }
    None
}

impl WarpReference {
    /// The reference at nodal displacements `u` (m, 3 n); a tet degenerate there gets no
    /// weight in the rotations measured against it.
    pub(crate) fn new(mesh: &TetMesh, u: &[f64]) -> Self {
        WarpReference {
            inverse_gradients: (0..mesh.n_tets())
                .into_par_iter()
                .map(|e| {
                    (mesh.deformation_gradient(e, u))
                        .try_inverse()
                        .unwrap_or_else(Matrix3::zeros)
                })
                .collect(),
        }
    }

    /// Per node (`n`), the rotation from the reference configuration to displacements `u`:
    /// the polar rotation of `sum_t V_t F_t(x) F_t(x_k)^{-1}` over the tets `t` at the node
    /// (`V_t` rest volume), the identity where that sum has none.
    pub(crate) fn node_rotations(&self, mesh: &TetMesh, u: &[f64]) -> Vec<Matrix3<f64>> {
        let volumes = mesh.volumes();
        let tet_maps: Vec<Matrix3<f64>> = (0..mesh.n_tets())
            .into_par_iter()
            .map(|e| volumes[e] * mesh.deformation_gradient(e, u) * self.inverse_gradients[e])
            .collect();
        let mut sums = vec![Matrix3::zeros(); mesh.n_nodes()];
        for (tet, map) in mesh.tets().iter().zip(&tet_maps) {
            for &node in tet {
                sums[node] += map;
            }
        }
        sums.par_iter()
            .map(|sum| polar_rotation(sum).unwrap_or_else(Matrix3::identity))
            .collect()
    }
}

/// Applies the node rotations (their transposes when `transpose`) to the free-DOF vector `v`,
/// whose entries map to full DOFs by `full_of_free` (increasing). Only nodes with all three
/// displacements free are rotated; other entries (a partly fixed node, pressures, cable nodes)
/// are left as they are.
pub(crate) fn rotate_nodes(
    rotations: &[Matrix3<f64>],
    full_of_free: &[usize],
    v: &mut [f64],
    transpose: bool,
) {
    let n_displacements = 3 * rotations.len();
    let mut f = 0;
    while f < v.len() {
        let d = full_of_free[f];
        let whole_node = d < n_displacements
            && d % 3 == 0
            && full_of_free.get(f + 2) == Some(&(d + 2))
            && f + 2 < v.len();
        if !whole_node {
            f += 1;
            continue;
        }
        let r = &rotations[d / 3];
        let x = Vector3::new(v[f], v[f + 1], v[f + 2]);
        let y = if transpose { r.tr_mul(&x) } else { r * x };
        v[f..f + 3].copy_from_slice(y.as_slice());
        f += 3;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Rotation3;

    fn rotated(mesh: &TetMesh, q: &Matrix3<f64>) -> Vec<f64> {
        mesh.rest()
            .iter()
            .flat_map(|p| {
                let x = Vector3::from(*p);
                let y = q * x - x;
                [y[0], y[1], y[2]]
            })
            .collect()
    }

    /// A rigid rotation of the body is recovered at every node, also from a deformed reference.
    #[test]
    fn a_rigid_rotation_is_found_at_every_node() {
        let mesh = TetMesh::box_mesh([0.4, 0.1, 0.05], [4, 2, 1], [0.0; 3]).unwrap();
        let q = *Rotation3::from_euler_angles(0.3, -0.2, 0.5).matrix();
        let at_rest = WarpReference::new(&mesh, &vec![0.0; 3 * mesh.n_nodes()]);
        for r in at_rest.node_rotations(&mesh, &rotated(&mesh, &q)) {
            assert!((r - q).norm() < 1e-12, "{r} vs {q}");
        }
        // A stretched reference, rotated: the stretch is not a rotation.
        let stretch: Vec<f64> = (mesh.rest().iter())
            .flat_map(|p| [0.2 * p[0], 0.0, -0.1 * p[2]])
            .collect();
        let stretched = WarpReference::new(&mesh, &stretch);
        let moved: Vec<f64> = (mesh.rest().iter())
            .flat_map(|p| {
                let x = Vector3::from(*p);
                let y = q * (x + Vector3::new(0.2 * p[0], 0.0, -0.1 * p[2])) - x;
                [y[0], y[1], y[2]]
            })
            .collect();
        for r in stretched.node_rotations(&mesh, &moved) {
            assert!((r - q).norm() < 1e-12, "{r} vs {q}");
        }
    }

    /// The property the warp rests on, through the assembled Hessian of a deformed body turned
    /// rigidly: `H(Q x) v = R H(x) R^T v` with the node rotations found between the two.
    #[test]
    fn the_rotated_hessian_is_the_hessian_of_the_rotated_body() {
        use crate::assembly::Assembler;
        use crate::energy::{ElasticTerm, Formulation, HessianMode};
        use crate::material::Volumetric;
        use std::sync::Arc;
        let mesh = Arc::new(TetMesh::box_mesh([0.4, 0.1, 0.1], [4, 1, 1], [0.0; 3]).unwrap());
        let m = mesh.n_tets();
        let term = ElasticTerm::neo_hookean(
            mesh.clone(),
            &vec![2e4; m],
            &vec![2e5; m],
            Volumetric::Log,
            Formulation::Standard,
        );
        let assembler = Assembler::new(&vec![false; 3 * mesh.n_nodes()], &[&term]);
        // A bent and stretched state, then the same turned by 40 degrees about a skew axis.
        let bent: Vec<f64> = (mesh.rest().iter())
            .flat_map(|p| [0.1 * p[0], 0.0, -0.5 * p[0] * p[0] + 0.05 * p[2]])
            .collect();
        let q = *Rotation3::from_axis_angle(
            &nalgebra::Unit::new_normalize(Vector3::new(1.0, 2.0, -0.5)),
            0.7,
        )
        .matrix();
        let turned: Vec<f64> = (mesh.rest().iter().enumerate())
            .flat_map(|(i, p)| {
                let x = Vector3::from(*p);
                let y = q * (x + Vector3::new(bent[3 * i], bent[3 * i + 1], bent[3 * i + 2])) - x;
                [y[0], y[1], y[2]]
            })
            .collect();
        let rotations = WarpReference::new(&mesh, &bent).node_rotations(&mesh, &turned);
        let hessian =
            |u: &[f64]| (assembler.evaluate(&[&term], u, false, Some(HessianMode::Exact))).hessian;
        let pattern = assembler.pattern();
        let v: Vec<f64> = (0..pattern.n)
            .map(|k| ((k * 7919) % 13) as f64 - 6.0)
            .collect();
        let direct = pattern.symmetric_matvec(&hessian(&turned), &v);
        let mut warped = v.clone();
        rotate_nodes(&rotations, assembler.full_of_free(), &mut warped, true);
        let mut warped = pattern.symmetric_matvec(&hessian(&bent), &warped);
        rotate_nodes(&rotations, assembler.full_of_free(), &mut warped, false);
        let scale = direct.iter().fold(0.0f64, |a, b| a.max(b.abs()));
        for (a, b) in direct.iter().zip(&warped) {
            assert!((a - b).abs() <= 1e-10 * scale, "{a} vs {b}");
        }
    }

    /// A reflection or a collapse has no rotation: the identity stands in.
    #[test]
    fn a_matrix_without_a_polar_rotation_gives_none() {
        assert!(polar_rotation(&Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, -1.0))).is_none());
        assert!(polar_rotation(&Matrix3::zeros()).is_none());
        assert!(polar_rotation(&Matrix3::from_element(f64::NAN)).is_none());
        let q = *Rotation3::from_euler_angles(1.0, 0.4, -2.0).matrix();
        let s = Matrix3::new(2.0, 0.3, 0.0, 0.3, 1.0, 0.1, 0.0, 0.1, 0.5);
        assert!((polar_rotation(&(q * s)).unwrap() - q).norm() < 1e-12);
    }

    /// Whole free nodes rotate; partly fixed nodes and extra unknowns do not.
    #[test]
    fn only_whole_free_nodes_rotate() {
        let q = *Rotation3::from_euler_angles(0.0, 0.0, 0.5).matrix();
        let rotations = vec![q; 3];
        // Node 0 fixed, node 1 free, node 2 with its z fixed, then one pressure.
        let full_of_free = [3, 4, 5, 6, 7, 9];
        let mut v = vec![1.0, 0.0, 0.0, 1.0, 0.0, 7.0];
        rotate_nodes(&rotations, &full_of_free, &mut v, false);
        let expected = q * Vector3::new(1.0, 0.0, 0.0);
        assert!((Vector3::new(v[0], v[1], v[2]) - expected).norm() < 1e-15);
        assert_eq!(&v[3..], &[1.0, 0.0, 7.0]);
        rotate_nodes(&rotations, &full_of_free, &mut v, true);
        assert!((v[0] - 1.0).abs() < 1e-15 && v[1].abs() < 1e-15);
    }
}
