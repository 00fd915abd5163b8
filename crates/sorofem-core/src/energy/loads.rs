//! External loads: gravity on the lumped masses and nodal forces. Both are linear in the
//! displacements u (m), so their Hessian vanishes; their energy is minus the work of the load,
//! `-f . u`.

use super::{HessianMode, ParamTerm, Term};
use crate::mesh::TetMesh;
use std::sync::Arc;

/// Lumped masses: each tet gives `rho V / 4` (kg) to each of its four nodes, and point masses
/// (free cable nodes) sit on their own three DOFs. The one place the lumping rule is written:
/// gravity, the inertia of dynamics and their sensitivities all read it from here.
#[derive(Clone, Debug)]
pub struct LumpedMass {
    pub mesh: Arc<TetMesh>,
    /// Density per tet (kg/m^3).
    pub density: Vec<f64>,
    /// First full DOF and mass (kg) of each point mass.
    pub points: Vec<(usize, f64)>,
}

impl LumpedMass {
    /// The share of tet `e`'s volume (m^3) lumped to each of its nodes, `V_e / 4`: the mass
    /// each node receives per unit density.
    pub fn nodal_volume(&self, e: usize) -> f64 {
        self.mesh.volumes()[e] / 4.0
    }

    /// `rho_e V_e / 4`: the mass (kg) tet `e` gives each of its nodes.
    pub fn tet_nodal_mass(&self, e: usize) -> f64 {
        self.density[e] * self.nodal_volume(e)
    }

    /// The mass (kg) of every one of `n_full` DOFs (zero for DOFs without mass, e.g. pressures).
    pub fn per_dof(&self, n_full: usize) -> Vec<f64> {
        let mut mass = vec![0.0; n_full];
        for (e, tet) in self.mesh.tets().iter().enumerate() {
            let m = self.tet_nodal_mass(e);
            for &i in tet {
                for k in 0..3 {
                    mass[3 * i + k] += m;
                }
            }
        }
        for &(first, m) in &self.points {
            mass[first..first + 3].fill(m);
        }
        mass
    }
}

/// Gravity `g` (m/s^2) on the tets' lumped masses: the energy of tet e is
/// `-rho_e V_e / 4 sum_a g . u_a` (J). Parameters: `density` (per tet) and `gravity` (3).
pub struct GravityTerm<'a> {
    pub mass: &'a LumpedMass,
    pub gravity: [f64; 3],
}

impl Term for GravityTerm<'_> {
    fn stencil_size(&self) -> usize {
        12
    }
    fn n_elements(&self) -> usize {
        self.mass.mesh.n_tets()
    }
    fn element_dofs(&self, e: usize, dofs: &mut [usize]) {
        for (a, &node) in self.mass.mesh.tets()[e].iter().enumerate() {
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
        let nodal_mass = self.mass.tet_nodal_mass(e);
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

impl ParamTerm for GravityTerm<'_> {
    fn param_blocks(&self) -> Vec<(String, usize)> {
        vec![
            ("density".into(), self.mass.mesh.n_tets()),
            ("gravity".into(), 3),
        ]
    }
    fn element_param_count(&self) -> usize {
        4
    }
    fn element_params(&self, e: usize, params: &mut [(usize, usize)]) {
        params.copy_from_slice(&[(0, e), (1, 0), (1, 1), (1, 2)]);
    }
    /// `d(grad)/d(rho_e) = -V_e/4 g` on every node, `d(grad)/d(g_k) = -rho_e V_e/4` on
    /// component k of every node.
    fn element_param_gradient(&self, e: usize, _z: &[f64], out: &mut [f64]) {
        out.fill(0.0);
        let (per_density, nodal_mass) = (self.mass.nodal_volume(e), self.mass.tet_nodal_mass(e));
        for a in 0..4 {
            for k in 0..3 {
                out[3 * a + k] = -per_density * self.gravity[k];
                out[12 * (1 + k) + 3 * a + k] = -nodal_mass;
            }
        }
    }
}

/// Gravity `g` (m/s^2) on the point masses (free cable nodes): energy `-m_i g . u_i` (J), one
/// element per point. Parameter: `gravity` (3), the same as [`GravityTerm`]'s.
pub struct PointGravityTerm<'a> {
    pub mass: &'a LumpedMass,
    pub gravity: [f64; 3],
}

impl Term for PointGravityTerm<'_> {
    fn stencil_size(&self) -> usize {
        3
    }
    fn n_elements(&self) -> usize {
        self.mass.points.len()
    }
    fn element_dofs(&self, e: usize, dofs: &mut [usize]) {
        let first = self.mass.points[e].0;
        for (k, dof) in dofs.iter_mut().enumerate() {
            *dof = first + k;
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
        let f = self.gravity.map(|g| self.mass.points[e].1 * g);
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

impl ParamTerm for PointGravityTerm<'_> {
    fn param_blocks(&self) -> Vec<(String, usize)> {
        vec![("gravity".into(), 3)]
    }
    fn element_param_count(&self) -> usize {
        3
    }
    fn element_params(&self, _e: usize, params: &mut [(usize, usize)]) {
        params.copy_from_slice(&[(0, 0), (0, 1), (0, 2)]);
    }
    /// `d(grad)/d(g_k) = -m_i` on component k.
    fn element_param_gradient(&self, e: usize, _z: &[f64], out: &mut [f64]) {
        out.fill(0.0);
        for k in 0..3 {
            out[3 * k + k] = -self.mass.points[e].1;
        }
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
