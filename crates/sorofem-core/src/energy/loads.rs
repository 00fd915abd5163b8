//! External loads: gravity and nodal forces. Both are linear in the positions, so their Hessian
//! vanishes; their energy is minus the work of the load, `-f . u` (u: displacements, m).

use super::{HessianMode, Term};
use crate::mesh::TetMesh;
use std::sync::Arc;

/// Gravity with a lumped mass: each tet gives `rho V / 4` (kg) to each of its nodes, so the
/// energy of tet e is `-rho_e V_e / 4 sum_a g . u_a` (J), g in m/s^2.
pub struct GravityTerm {
    pub mesh: Arc<TetMesh>,
    /// Density per tet (kg/m^3).
    pub density: Vec<f64>,
    pub gravity: [f64; 3],
}

impl Term for GravityTerm {
    fn stencil_size(&self) -> usize {
        12
    }
    fn n_elements(&self) -> usize {
        self.mesh.n_tets()
    }
    fn element_dofs(&self, e: usize, dofs: &mut [usize]) {
        for (a, &node) in self.mesh.tets()[e].iter().enumerate() {
            for k in 0..3 {
                dofs[3 * a + k] = 3 * node + k;
            }
        }
    }
    fn element(
        &self,
        e: usize,
        z: &[f64],
        grad: Option<&mut [f64]>,
        _: Option<&mut [f64]>,
        _: HessianMode,
    ) -> f64 {
        let nodal_mass = self.density[e] * self.mesh.volumes()[e] / 4.0;
        let mut energy = 0.0;
        for a in 0..4 {
            for k in 0..3 {
                energy -= nodal_mass * self.gravity[k] * z[3 * a + k];
            }
        }
        if let Some(grad) = grad {
            for a in 0..4 {
                for k in 0..3 {
                    grad[3 * a + k] = -nodal_mass * self.gravity[k];
                }
            }
        }
        energy
    }
    fn is_linear(&self) -> bool {
        true
    }
}

/// Point forces (N) on nodes: energy `-sum_i f_i . u_i`; one element per loaded node.
pub struct NodalForceTerm {
    pub nodes: Vec<usize>,
    pub forces: Vec<[f64; 3]>,
}

impl Term for NodalForceTerm {
    fn stencil_size(&self) -> usize {
        3
    }
    fn n_elements(&self) -> usize {
        self.nodes.len()
    }
    fn element_dofs(&self, e: usize, dofs: &mut [usize]) {
        for k in 0..3 {
            dofs[k] = 3 * self.nodes[e] + k;
        }
    }
    fn element(
        &self,
        e: usize,
        z: &[f64],
        grad: Option<&mut [f64]>,
        _: Option<&mut [f64]>,
        _: HessianMode,
    ) -> f64 {
        let f = self.forces[e];
        if let Some(grad) = grad {
            for k in 0..3 {
                grad[k] = -f[k];
            }
        }
        -(f[0] * z[0] + f[1] * z[1] + f[2] * z[2])
    }
    fn is_linear(&self) -> bool {
        true
    }
}
