//! Neo-Hookean elasticity of linear tetrahedra, in the standard (displacement) and the mixed
//! (displacement + pressure) formulation.
//!
//! Standard: `E_e = V_e psi(F_e)` with `psi = mu/2 (I1 - 3) - mu ln J + lambda/2 c(J)^2`.
//!
//! Mixed: the volumetric energy `lambda/2 c^2` is replaced by its perturbed-Lagrangian form
//! `p c(J) - p^2 / (2 lambda)`, with `p` interpolated from nodal pressures (P1, continuous):
//! `E_e = V_e [psi_mu(F_e) + q_e c(J_e)] - 1/2 p_e^T C_e p_e`, `q_e` the mean of the element's four
//! nodal pressures and `C_e = M_e / lambda_e` its pressure mass (consistent
//! `V/20 (1 + delta_ab)` or lumped `V/4 delta_ab`, m^3). Summed over elements this is
//! `W_mu(x) + p^T phi(x) - 1/2 p^T C p` with the nodal constraint `phi_i = sum_e V_e/4 c(J_e)`.
//! Eliminating p (`C p = phi`) gives back `W_mu + 1/2 phi^T C^{-1} phi`, which tends to the standard
//! energy as the mesh is refined, so both formulations solve the same continuum model.

use super::{
    add_tet_gradient, set_isotropic_tet_hessian, set_projected_isotropic_tet_hessian, HessianMode,
    ParamTerm, Term,
};
use crate::material::{NeoHookean, Volumetric};
use crate::mesh::TetMesh;
use rayon::prelude::*;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

/// The pressure mass matrix `M_p` of the mixed formulation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PressureMass {
    /// `int N_a N_b dV`: the exact P1 mass matrix.
    Consistent,
    /// Row-summed: `V/4` per node and element; makes `C` diagonal.
    Lumped,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Formulation {
    Standard,
    /// Nodal pressure unknowns start at full DOF index `pressure_offset` (= 3 n_nodes).
    Mixed {
        pressure_offset: usize,
        mass: PressureMass,
    },
}

/// One tet's pressure `lambda c(J)` (Pa) at a state and its derivative with respect to the
/// displacement gradient `H = F - I`: `dp/dH = lambda c'(J) J F^{-T}` (Pa, row-major), so that
/// `dp = dp/dH : dH` with `dH = sum_a du_a g_a^T`.
#[derive(Clone, Copy, Debug)]
pub struct LinearisedPressure {
    pub value: f64,
    pub gradient: [f64; 9],
}

impl LinearisedPressure {
    /// From the quantities an element kernel has at hand: `lambda` (Pa), `F^{-T}`, `J` and
    /// `(c(J), c'(J))`. An inverted tet (`J <= 0`) gets a NaN value, which
    /// [`ElasticTerm::advance_pressures`] leaves alone.
    fn new(lambda: f64, gt: &crate::material::Mat3, j: f64, c: f64, dc: f64) -> Self {
        if !(j > 0.0) {
            return LinearisedPressure {
                value: f64::NAN,
                gradient: [0.0; 9],
            };
        }
        let scale = lambda * dc * j;
        LinearisedPressure {
            value: lambda * c,
            gradient: std::array::from_fn(|k| scale * gt[(k / 3, k % 3)]),
        }
    }
}

/// [`LinearisedPressure`]s of all tets at one state. The standard element kernel writes the
/// entry of its tet whenever it builds a Hessian with pressure iterates (it has `F^{-T}`, `J` and
/// `c(J)` at hand then), so a Newton step's pressure update needs no element pass of its own;
/// the cells are atomic because the assembler's threads write them, each tet from one thread.
pub struct PressureLinearisations {
    cells: Vec<[AtomicU64; 10]>,
}

impl PressureLinearisations {
    pub fn new(n_tets: usize) -> Self {
        PressureLinearisations {
            cells: (0..n_tets)
                .map(|_| std::array::from_fn(|_| AtomicU64::new(0)))
                .collect(),
        }
    }

    pub fn len(&self) -> usize {
        self.cells.len()
    }

    pub fn is_empty(&self) -> bool {
        self.cells.is_empty()
    }

    pub fn get(&self, e: usize) -> LinearisedPressure {
        let cell = &self.cells[e];
        let value = |k: usize| f64::from_bits(cell[k].load(Ordering::Relaxed));
        LinearisedPressure {
            value: value(0),
            gradient: std::array::from_fn(|k| value(k + 1)),
        }
    }

    fn set(&self, e: usize, linearised: &LinearisedPressure) {
        let cell = &self.cells[e];
        cell[0].store(linearised.value.to_bits(), Ordering::Relaxed);
        for (slot, v) in cell[1..].iter().zip(&linearised.gradient) {
            slot.store(v.to_bits(), Ordering::Relaxed);
        }
    }
}

/// The element pressures a Newton solve builds the standard formulation's Hessians with.
pub struct PressureIterates {
    /// `p_e` (Pa), one per tet.
    pub values: Vec<f64>,
    /// Written by every Hessian built with these iterates: the pressures linearised at the
    /// state of the last one.
    pub recorded: PressureLinearisations,
}

impl PressureIterates {
    pub fn new(values: Vec<f64>) -> Self {
        let recorded = PressureLinearisations::new(values.len());
        PressureIterates { values, recorded }
    }
}

/// Elastic energy of all tets. `mu` and `lambda` are per tet (Pa).
pub struct ElasticTerm {
    pub mesh: Arc<TetMesh>,
    pub mu: Vec<f64>,
    pub lambda: Vec<f64>,
    pub volumetric: Volumetric,
    pub formulation: Formulation,
    /// Standard formulation: element pressures `p_e` (Pa, one per tet) at which the Hessian
    /// takes its volumetric part, `lambda c'^2 dJ dJ + p_e (c'' dJ dJ + c' d2J)`, instead of at
    /// `p_e = lambda c(J_e)`; energy and gradient are unchanged. Newton solves set them (see
    /// [`ElasticTerm::pressures_at`], [`ElasticTerm::advance_pressures`]); `None` gives the
    /// exact Hessian.
    pub pressure_iterates: Option<PressureIterates>,
}

impl ElasticTerm {
    pub fn material(&self, e: usize) -> NeoHookean {
        NeoHookean {
            mu: self.mu[e],
            lambda: self.lambda[e],
            volumetric: self.volumetric,
        }
    }

    /// Local pressure mass `C_e = M_e / lambda_e` entry (a, b).
    fn compliance(&self, e: usize, a: usize, b: usize, mass: PressureMass) -> f64 {
        let v = self.mesh.volumes()[e] / self.lambda[e];
        match mass {
            PressureMass::Consistent => v / 20.0 * if a == b { 2.0 } else { 1.0 },
            PressureMass::Lumped => {
                if a == b {
                    v / 4.0
                } else {
                    0.0
                }
            }
        }
    }

    /// The element pressures `lambda_e c(J_e)` (Pa, one per tet) of the energy itself at the
    /// full DOF vector `z`: the pressure iterates a Newton solve starts from. Standard
    /// formulation; `+inf` for an inverted tet.
    pub fn pressures_at(&self, z: &[f64]) -> Vec<f64> {
        (0..self.mesh.n_tets())
            .into_par_iter()
            .map(|e| {
                let (_, j, c, _) = self.volume_state(e, z);
                if j > 0.0 {
                    self.lambda[e] * c
                } else {
                    f64::INFINITY
                }
            })
            .collect()
    }

    /// Each tet's pressure `lambda c(J)` and its derivative at the full DOF vector `z`: what
    /// [`ElasticTerm::advance_pressures`] moves the pressure iterates with. Standard
    /// formulation. (Newton solves get these recorded by the Hessian pass instead.)
    pub fn linearised_pressures(&self, z: &[f64]) -> PressureLinearisations {
        let linearised = PressureLinearisations::new(self.mesh.n_tets());
        (0..self.mesh.n_tets()).into_par_iter().for_each(|e| {
            let (gt, j, c, dc) = self.volume_state(e, z);
            linearised.set(e, &LinearisedPressure::new(self.lambda[e], &gt, j, c, dc));
        });
        linearised
    }

    /// Moves the pressure iterates the step `t dz` (full DOFs) from the state `linearised`
    /// describes, as Newton's method on the element-wise (P1-P0) perturbed-Lagrangian form of the
    /// energy, `W_mu(u) + sum_e V_e [p_e c(J_e) - p_e^2 / (2 lambda_e)]`, moves its pressures: the
    /// linearised constraint `p_e = lambda_e (c(J_e) + c'(J_e) dJ_e)`, `dJ_e = J_e F_e^{-T} : dH_e`,
    /// gives the full step, of which `t` is taken. Eliminating `p_e` from that form gives back
    /// the standard energy, so the solution is the same; the iterates differ from `lambda c(J)`
    /// only while the linearised volume change is off, as when a rotation makes the
    /// displacement update stretch elements spuriously.
    pub fn advance_pressures(&mut self, linearised: &PressureLinearisations, dz: &[f64], t: f64) {
        let Some(mut iterates) = self.pressure_iterates.take() else {
            return;
        };
        iterates
            .values
            .par_iter_mut()
            .enumerate()
            .for_each(|(e, p)| {
                let linear = linearised.get(e);
                let dh = self.displacement_gradient_of(e, dz);
                let mut full = linear.value;
                for (k, gradient) in linear.gradient.iter().enumerate() {
                    full += gradient * dh[(k / 3, k % 3)];
                }
                if full.is_finite() {
                    *p += t * (full - *p);
                }
            });
        self.pressure_iterates = Some(iterates);
    }

    /// `(F^{-T}, J, c(J), c'(J))` of tet `e` at the full DOF vector `z`; `J <= 0` (and the rest
    /// unspecified) for an inverted tet.
    fn volume_state(&self, e: usize, z: &[f64]) -> (crate::material::Mat3, f64, f64, f64) {
        let h = self.displacement_gradient_of(e, z);
        match crate::material::inverse_transpose(&(crate::material::Mat3::identity() + h)) {
            Some((gt, j)) => {
                let (c, dc, _) = self
                    .volumetric
                    .measure_near_one(crate::material::neo_hookean::j_minus_one(&h));
                (gt, j, c, dc)
            }
            None => (crate::material::Mat3::zeros(), 0.0, 0.0, 0.0),
        }
    }

    /// [`ElasticTerm::displacement_gradient`] of tet `e` from the full DOF vector `z`.
    fn displacement_gradient_of(&self, e: usize, z: &[f64]) -> crate::material::Mat3 {
        let tet = self.mesh.tets()[e];
        let mut u = [0.0; 12];
        for (a, &node) in tet.iter().enumerate() {
            u[3 * a..3 * a + 3].copy_from_slice(&z[3 * node..3 * node + 3]);
        }
        self.displacement_gradient(e, &u)
    }

    /// `H = F - I = sum_a u_a g_a^T` from the element's nodal displacements (m). Working with
    /// displacements and H rather than positions and F keeps the stress accurate to round-off
    /// relative to |H|, so small loads converge to tight relative tolerances.
    fn displacement_gradient(&self, e: usize, u: &[f64]) -> crate::material::Mat3 {
        let g = self.mesh.shape_gradients(e);
        let mut f = crate::material::Mat3::zeros();
        for a in 0..4 {
            let ua = nalgebra::Vector3::new(u[3 * a], u[3 * a + 1], u[3 * a + 2]);
            f += ua * g[a].transpose();
        }
        f
    }

    fn standard_element(
        &self,
        e: usize,
        z: &[f64],
        grad: Option<&mut [f64]>,
        hess: Option<&mut [f64]>,
        mode: HessianMode,
    ) -> f64 {
        let h = self.displacement_gradient(e, z);
        let material = self.material(e);
        let Some(r) = material.pointwise(&h, true) else {
            return f64::INFINITY;
        };
        let volume = self.mesh.volumes()[e];
        let g = self.mesh.shape_gradients(e);
        if let Some(grad) = grad {
            grad.fill(0.0);
            add_tet_gradient(volume, g, &r.stress, grad);
        }
        if let Some(hess) = hess {
            let (gt, j) = (r.gt, r.j);
            let (c, dc, d2c) = r.measure;
            let pressure = match &self.pressure_iterates {
                Some(iterates) => {
                    let linearised = LinearisedPressure::new(material.lambda, &gt, j, c, dc);
                    iterates.recorded.set(e, &linearised);
                    iterates.values[e]
                }
                None => material.lambda * c,
            };
            let dh = pressure * dc;
            let d2h = material.lambda * dc * dc + pressure * d2c;
            let (mu, alpha, beta) = (material.mu, material.mu - dh * j, d2h * j * j + dh * j);
            match mode {
                HessianMode::Exact => {
                    set_isotropic_tet_hessian(volume, g, &gt, mu, alpha, beta, &[], hess, 12)
                }
                HessianMode::Projected => {
                    let f = crate::material::Mat3::identity() + h;
                    set_projected_isotropic_tet_hessian(
                        volume, g, &f, &gt, mu, alpha, beta, hess, 12,
                    )
                }
            }
        }
        volume * r.energy
    }

    fn mixed_element(
        &self,
        e: usize,
        z: &[f64],
        grad: Option<&mut [f64]>,
        hess: Option<&mut [f64]>,
        mode: HessianMode,
        mass: PressureMass,
    ) -> f64 {
        let h = self.displacement_gradient(e, z);
        let Some(shear) = self.material(e).pointwise(&h, false) else {
            return f64::INFINITY;
        };
        let (gt, j) = (shear.gt, shear.j);
        let volume = self.mesh.volumes()[e];
        let g = self.mesh.shape_gradients(e);
        let p = &z[12..16];
        let q = 0.25 * (p[0] + p[1] + p[2] + p[3]);
        let (c, dc, d2c) = shear.measure;
        let mut cp = [0.0; 4];
        for a in 0..4 {
            for b in 0..4 {
                cp[a] += self.compliance(e, a, b, mass) * p[b];
            }
        }
        let energy =
            volume * (shear.energy + q * c) - 0.5 * (0..4).map(|a| p[a] * cp[a]).sum::<f64>();
        // d(V c(J))/dx_b = V c'(J) J F^{-T} g_b, shared by the gradient and the coupling block.
        let dvol_stress = dc * j * gt;
        if let Some(grad) = grad {
            grad.fill(0.0);
            add_tet_gradient(volume, g, &(shear.stress + q * dvol_stress), grad);
            for a in 0..4 {
                grad[12 + a] = 0.25 * volume * c - cp[a];
            }
        }
        if let Some(hess) = hess {
            let (dh, d2h) = (q * dc, q * d2c);
            let mu = self.mu[e];
            let (alpha, beta) = (mu - dh * j, d2h * j * j + dh * j);
            match mode {
                // Only the displacement block is projected: the saddle point stays a saddle point.
                HessianMode::Projected => set_projected_isotropic_tet_hessian(
                    volume,
                    g,
                    &(crate::material::Mat3::identity() + h),
                    &gt,
                    mu,
                    alpha,
                    beta,
                    hess,
                    16,
                ),
                HessianMode::Exact => {
                    set_isotropic_tet_hessian(volume, g, &gt, mu, alpha, beta, &[], hess, 16)
                }
            }
            for b in 0..4 {
                let coupling = dvol_stress * g[b] * (0.25 * volume);
                for i in 0..3 {
                    for a in 0..4 {
                        hess[(3 * b + i) * 16 + 12 + a] = coupling[i];
                        hess[(12 + a) * 16 + 3 * b + i] = coupling[i];
                    }
                }
            }
            for a in 0..4 {
                for b in 0..4 {
                    hess[(12 + a) * 16 + 12 + b] = -self.compliance(e, a, b, mass);
                }
            }
        }
        energy
    }
}

impl Term for ElasticTerm {
    fn stencil_size(&self) -> usize {
        match self.formulation {
            Formulation::Standard => 12,
            Formulation::Mixed { .. } => 16,
        }
    }

    fn n_elements(&self) -> usize {
        self.mesh.n_tets()
    }

    fn element_dofs(&self, e: usize, dofs: &mut [usize]) {
        let tet = self.mesh.tets()[e];
        for (a, &node) in tet.iter().enumerate() {
            for k in 0..3 {
                dofs[3 * a + k] = 3 * node + k;
            }
        }
        if let Formulation::Mixed {
            pressure_offset, ..
        } = self.formulation
        {
            for (a, &node) in tet.iter().enumerate() {
                dofs[12 + a] = pressure_offset + node;
            }
        }
    }

    fn element(
        &self,
        e: usize,
        z: &[f64],
        grad: Option<&mut [f64]>,
        hess: Option<&mut [f64]>,
        mode: HessianMode,
    ) -> f64 {
        match self.formulation {
            Formulation::Standard => self.standard_element(e, z, grad, hess, mode),
            Formulation::Mixed { mass, .. } => self.mixed_element(e, z, grad, hess, mode, mass),
        }
    }
}

/// The pressure compliance `1/2 p^T C p` with `C = sum_e M_e / lambda_e`, on the nodal pressure
/// DOFs alone (indices 0..n_nodes). Its Hessian is `C`, assembled once per material.
pub struct PressureCompliance<'a> {
    pub elastic: &'a ElasticTerm,
    pub mass: PressureMass,
}

impl Term for PressureCompliance<'_> {
    fn stencil_size(&self) -> usize {
        4
    }
    fn n_elements(&self) -> usize {
        self.elastic.mesh.n_tets()
    }
    fn element_dofs(&self, e: usize, dofs: &mut [usize]) {
        dofs.copy_from_slice(&self.elastic.mesh.tets()[e]);
    }
    fn element(
        &self,
        e: usize,
        p: &[f64],
        grad: Option<&mut [f64]>,
        hess: Option<&mut [f64]>,
        _: HessianMode,
    ) -> f64 {
        let mut cp = [0.0; 4];
        for a in 0..4 {
            for b in 0..4 {
                cp[a] += self.elastic.compliance(e, a, b, self.mass) * p[b];
            }
        }
        if let Some(grad) = grad {
            grad.copy_from_slice(&cp);
        }
        if let Some(hess) = hess {
            for a in 0..4 {
                for b in 0..4 {
                    hess[4 * a + b] = self.elastic.compliance(e, a, b, self.mass);
                }
            }
        }
        0.5 * (0..4).map(|a| p[a] * cp[a]).sum::<f64>()
    }
}

impl ElasticTerm {
    /// Parameter derivatives of element `e`'s gradient at local DOFs `z`: writes
    /// `d(grad_e)/d(mu_e)` and `d(grad_e)/d(lambda_e)` (each of length `stencil_size()`).
    ///
    /// Standard: `V (F - F^{-T}) g_a` and `V c c' J F^{-T} g_a`. Mixed: the shear part gives the
    /// same mu-derivative on the displacement rows, while lambda only enters the compliance
    /// `C_e = M_e / lambda`, so `d(grad_p)/d(lambda) = C_e p / lambda` and nothing on the
    /// displacement rows (differentiating `lambda/2 c^2` there instead is the classic mistake).
    pub fn element_param_derivatives(
        &self,
        e: usize,
        z: &[f64],
        d_mu: &mut [f64],
        d_lambda: &mut [f64],
    ) {
        d_mu.fill(0.0);
        d_lambda.fill(0.0);
        let h = self.displacement_gradient(e, z);
        let f = crate::material::Mat3::identity() + h;
        let Some([dp_dmu, dp_dlambda]) = self.material(e).stress_param_gradient(&f) else {
            return;
        };
        let volume = self.mesh.volumes()[e];
        let g = self.mesh.shape_gradients(e);
        add_tet_gradient(volume, g, &dp_dmu, &mut d_mu[..12]);
        match self.formulation {
            Formulation::Standard => add_tet_gradient(volume, g, &dp_dlambda, &mut d_lambda[..12]),
            Formulation::Mixed { mass, .. } => {
                let p = &z[12..16];
                for a in 0..4 {
                    d_lambda[12 + a] = (0..4)
                        .map(|b| self.compliance(e, a, b, mass) * p[b])
                        .sum::<f64>()
                        / self.lambda[e];
                }
            }
        }
    }
}

impl ParamTerm for ElasticTerm {
    fn param_blocks(&self) -> Vec<(String, usize)> {
        let m = self.mesh.n_tets();
        vec![("mu".into(), m), ("lambda".into(), m)]
    }
    fn element_param_count(&self) -> usize {
        2
    }
    fn element_params(&self, e: usize, params: &mut [(usize, usize)]) {
        params.copy_from_slice(&[(0, e), (1, e)]);
    }
    fn element_param_gradient(&self, e: usize, z: &[f64], out: &mut [f64]) {
        let (d_mu, d_lambda) = out.split_at_mut(self.stencil_size());
        self.element_param_derivatives(e, z, d_mu, d_lambda);
    }
}
