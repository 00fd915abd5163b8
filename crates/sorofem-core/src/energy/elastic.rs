//! Hyperelasticity of linear tetrahedra, in the standard (displacement) and the mixed
//! (displacement + pressure) formulation, for any [`Hyperelastic`] model written as
//! `W = W_rest + kappa/2 c(J)^2` (see [`crate::material::law`]).
//!
//! Standard: `E_e = V_e W(F_e)`.
//!
//! Mixed: the volumetric energy `kappa/2 c^2` is replaced by its perturbed-Lagrangian form
//! `p c(J) - p^2 / (2 kappa)`, with `p` interpolated from nodal pressures (P1, continuous):
//! `E_e = V_e [W_rest(F_e) + q_e c(J_e)] - 1/2 p_e^T C_e p_e`, `q_e` the mean of the element's
//! four nodal pressures and `C_e = M_e / kappa_e` its pressure mass (consistent
//! `V/20 (1 + delta_ab)` or lumped `V/4 delta_ab`, m^3). Summed over elements this is
//! `W_rest(x) + p^T phi(x) - 1/2 p^T C p` with the nodal constraint `phi_i = sum_e V_e/4 c(J_e)`.
//! Eliminating p (`C p = phi`) gives back `W_rest + 1/2 phi^T C^{-1} phi`, which tends to the
//! standard energy as the mesh is refined, so both formulations solve the same continuum model.
//!
//! The Neo-Hookean model has closed forms that the element kernels use (its tangent is
//! isotropic: [`super::set_isotropic_tet_hessian`] and the analytic projection); other models
//! go through their 9x9 tangent, the volumetric term folded into the model's own pass
//! ([`Hyperelastic::rest_with_volumetric`], [`super::set_tet_hessian`], [`project_to_psd`]).

pub use super::pressure_iterates::{LinearisedPressure, PressureIterates, PressureLinearisations};
use super::{
    add_tet_gradient, set_isotropic_tet_hessian, set_projected_isotropic_tet_hessian,
    set_tet_hessian, HessianMode, ParamTerm, Term,
};
use crate::material::neo_hookean::j_minus_one;
use crate::material::{
    inverse_transpose, project_to_psd, ElementMaterial, Hyperelastic, Mat3, MaterialModel,
    NeoHookean, Tangent, VolumeState, Volumetric, VolumetricTerm,
};
use crate::mesh::TetMesh;
use nalgebra::Vector3;
use rayon::prelude::*;
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
    /// Nodal pressure unknowns start at full DOF index `pressure_offset`, after the
    /// displacements of the mesh nodes and of any free cable nodes
    /// (see `model/layout.rs`).
    Mixed {
        pressure_offset: usize,
        mass: PressureMass,
    },
}

/// Elastic energy of all tets: one [`MaterialModel`] with per-tet parameters.
pub struct ElasticTerm {
    pub mesh: Arc<TetMesh>,
    material: MaterialModel,
    /// Per-tet parameters, flat: tet e's are `params[e n_p..(e + 1) n_p]`, `n_p` the model's
    /// parameter count, in the order of [`MaterialModel::param_names`].
    params: Vec<f64>,
    /// `kappa` (Pa) of each tet's primary volumetric term.
    bulk: Vec<f64>,
    pub formulation: Formulation,
    /// Standard formulation: element pressures `p_e` (Pa, one per tet) at which the Hessian
    /// takes its volumetric part, `kappa c'^2 dJ dJ + p_e (c'' dJ dJ + c' d2J)`, instead of at
    /// `p_e = kappa c(J_e)`; energy and gradient are unchanged. Newton solves set them (see
    /// [`ElasticTerm::pressures_at`], [`ElasticTerm::advance_pressures`]); `None` gives the
    /// exact Hessian.
    pub pressure_iterates: Option<PressureIterates>,
    /// Whether models with closed forms (Neo-Hookean) use them; `false` sends every model
    /// through the general path (tests and benchmarks compare the two).
    pub closed_forms: bool,
}

impl ElasticTerm {
    /// `params`: `n_tets x n_params` values, tet-major (validated by the caller, see
    /// [`MaterialModel::try_at`]).
    pub fn new(
        mesh: Arc<TetMesh>,
        material: MaterialModel,
        params: Vec<f64>,
        formulation: Formulation,
    ) -> Self {
        let mut term = ElasticTerm {
            mesh,
            material,
            params: Vec::new(),
            bulk: Vec::new(),
            formulation,
            pressure_iterates: None,
            closed_forms: true,
        };
        term.set_material(material, params);
        term
    }

    /// A Neo-Hookean term with per-tet `mu` and `lambda` (Pa).
    pub fn neo_hookean(
        mesh: Arc<TetMesh>,
        mu: &[f64],
        lambda: &[f64],
        volumetric: Volumetric,
        formulation: Formulation,
    ) -> Self {
        let params = mu.iter().zip(lambda).flat_map(|(&m, &l)| [m, l]).collect();
        Self::new(
            mesh,
            MaterialModel::NeoHookean { volumetric },
            params,
            formulation,
        )
    }

    /// Replaces the model and its per-tet parameters (`n_tets x n_params`, tet-major).
    pub fn set_material(&mut self, material: MaterialModel, params: Vec<f64>) {
        assert_eq!(
            params.len(),
            self.mesh.n_tets() * material.n_params(),
            "one parameter set per tet"
        );
        self.material = material;
        self.params = params;
        self.bulk = (0..self.mesh.n_tets())
            .map(|e| self.element_material(e).bulk())
            .collect();
    }

    pub fn material(&self) -> MaterialModel {
        self.material
    }

    /// The per-tet parameters, `n_tets x n_params`, tet-major.
    pub fn params(&self) -> &[f64] {
        &self.params
    }

    /// The material of tet `e`.
    #[inline]
    pub fn element_material(&self, e: usize) -> ElementMaterial {
        let n = self.material.n_params();
        self.material.at(&self.params[e * n..(e + 1) * n])
    }

    /// Local pressure mass `C_e = M_e / kappa_e` entry (a, b).
    fn compliance(&self, e: usize, a: usize, b: usize, mass: PressureMass) -> f64 {
        let v = self.mesh.volumes()[e] / self.bulk[e];
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

    /// `C_e p` for the element's nodal pressures `p`.
    fn compliance_times(&self, e: usize, p: &[f64], mass: PressureMass) -> [f64; 4] {
        let mut cp = [0.0; 4];
        for (a, cp_a) in cp.iter_mut().enumerate() {
            for (b, p_b) in p.iter().enumerate() {
                *cp_a += self.compliance(e, a, b, mass) * p_b;
            }
        }
        cp
    }

    /// The element pressures `kappa_e c(J_e)` (Pa, one per tet) of the energy itself at the
    /// full DOF vector `z`: the pressure iterates a Newton solve starts from. Standard
    /// formulation; `+inf` for an inverted tet.
    pub fn pressures_at(&self, z: &[f64]) -> Vec<f64> {
        (0..self.mesh.n_tets())
            .into_par_iter()
            .map(|e| {
                let (_, j, c, _) = self.volume_state(e, z);
                if j > 0.0 {
                    self.bulk[e] * c
                } else {
                    f64::INFINITY
                }
            })
            .collect()
    }

    /// Each tet's pressure `kappa c(J)` and its derivative at the full DOF vector `z`: what
    /// [`ElasticTerm::advance_pressures`] moves the pressure iterates with. Standard
    /// formulation. (Newton solves get these recorded by the Hessian pass instead.)
    pub fn linearised_pressures(&self, z: &[f64]) -> PressureLinearisations {
        let linearised = PressureLinearisations::new(self.mesh.n_tets());
        (0..self.mesh.n_tets()).into_par_iter().for_each(|e| {
            let (gt, j, c, dc) = self.volume_state(e, z);
            linearised.set(e, &LinearisedPressure::new(self.bulk[e], &gt, j, c, dc));
        });
        linearised
    }

    /// Moves the pressure iterates the step `t dz` (full DOFs) from the state `linearised`
    /// describes, as Newton's method on the element-wise (P1-P0) perturbed-Lagrangian form of the
    /// energy, `W_rest(u) + sum_e V_e [p_e c(J_e) - p_e^2 / (2 kappa_e)]`, moves its pressures:
    /// the linearised constraint `p_e = kappa_e (c(J_e) + c'(J_e) dJ_e)`,
    /// `dJ_e = J_e F_e^{-T} : dH_e`, gives the full step, of which `t` is taken. Eliminating `p_e`
    /// from that form gives back the standard energy, so the solution is the same; the iterates
    /// differ from `kappa c(J)` only while the linearised volume change is off, as when a
    /// rotation makes the displacement update stretch elements spuriously.
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
    fn volume_state(&self, e: usize, z: &[f64]) -> (Mat3, f64, f64, f64) {
        let h = self.displacement_gradient_of(e, z);
        match inverse_transpose(&(Mat3::identity() + h)) {
            Some((gt, j)) => {
                let (c, dc, _) = self.material.volumetric().measure_near_one(j_minus_one(&h));
                (gt, j, c, dc)
            }
            None => (Mat3::zeros(), 0.0, 0.0, 0.0),
        }
    }

    /// [`ElasticTerm::displacement_gradient`] of tet `e` from the full DOF vector `z`.
    fn displacement_gradient_of(&self, e: usize, z: &[f64]) -> Mat3 {
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
    fn displacement_gradient(&self, e: usize, u: &[f64]) -> Mat3 {
        let g = self.mesh.shape_gradients(e);
        let mut f = Mat3::zeros();
        for a in 0..4 {
            let ua = Vector3::new(u[3 * a], u[3 * a + 1], u[3 * a + 2]);
            f += ua * g[a].transpose();
        }
        f
    }

    /// The pressure the standard Hessian takes its volumetric part at: the iterate when there
    /// are iterates (recording the linearisation at this state for them), else `kappa c(J)`.
    fn hessian_pressure(&self, e: usize, kappa: f64, gt: &Mat3, j: f64, c: f64, dc: f64) -> f64 {
        match &self.pressure_iterates {
            Some(iterates) => {
                let linearised = LinearisedPressure::new(kappa, gt, j, c, dc);
                iterates.recorded.set(e, &linearised);
                iterates.values[e]
            }
            None => kappa * c,
        }
    }

    /// Standard formulation, Neo-Hookean closed forms.
    fn standard_neo_hookean(
        &self,
        e: usize,
        material: &NeoHookean,
        z: &[f64],
        grad: Option<&mut [f64]>,
        hess: Option<&mut [f64]>,
        mode: HessianMode,
    ) -> f64 {
        let h = self.displacement_gradient(e, z);
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
            let pressure = self.hessian_pressure(e, material.lambda, &gt, j, c, dc);
            let dh = pressure * dc;
            let d2h = material.lambda * dc * dc + pressure * d2c;
            let (mu, alpha, beta) = (material.mu, material.mu - dh * j, d2h * j * j + dh * j);
            match mode {
                HessianMode::Exact => {
                    set_isotropic_tet_hessian(volume, g, &gt, mu, alpha, beta, &[], hess, 12)
                }
                HessianMode::Projected => {
                    let f = Mat3::identity() + h;
                    set_projected_isotropic_tet_hessian(
                        volume, g, &f, &gt, mu, alpha, beta, hess, 12,
                    )
                }
            }
        }
        volume * r.energy
    }

    /// Standard formulation, any model: the rest part and the volumetric term `kappa/2 c(J)^2`
    /// in one pass of the model ([`Hyperelastic::rest_with_volumetric`]), the element Hessian
    /// from the resulting 9x9 tangent.
    fn standard_general(
        &self,
        e: usize,
        material: &impl Hyperelastic,
        z: &[f64],
        grad: Option<&mut [f64]>,
        hess: Option<&mut [f64]>,
        mode: HessianMode,
    ) -> f64 {
        let h = self.displacement_gradient(e, z);
        let Some(state) = VolumeState::new(&h) else {
            return f64::INFINITY;
        };
        let kappa = self.bulk[e];
        let measure = material.volumetric().measure_near_one(state.jm1);
        let mut volumetric = VolumetricTerm::quadratic(kappa, measure);
        if hess.is_some() {
            let (c, dc, d2c) = measure;
            let pressure = self.hessian_pressure(e, kappa, &state.gt, state.j, c, dc);
            volumetric.tangent_slope = pressure * dc;
            volumetric.tangent_curvature = kappa * dc * dc + pressure * d2c;
        }
        let Some(r) = material.rest_with_volumetric(&h, &state, &volumetric, hess.is_some()) else {
            return f64::INFINITY;
        };
        let volume = self.mesh.volumes()[e];
        let g = self.mesh.shape_gradients(e);
        if let Some(grad) = grad {
            grad.fill(0.0);
            add_tet_gradient(volume, g, &r.stress, grad);
        }
        if let (Some(hess), Some(tangent)) = (hess, r.tangent) {
            set_tangent_tet_hessian(volume, g, &tangent, mode, hess, 12);
        }
        volume * r.energy
    }

    /// Mixed formulation, Neo-Hookean closed forms for the displacement block.
    #[allow(clippy::too_many_arguments)]
    fn mixed_neo_hookean(
        &self,
        e: usize,
        material: &NeoHookean,
        z: &[f64],
        grad: Option<&mut [f64]>,
        hess: Option<&mut [f64]>,
        mode: HessianMode,
        mass: PressureMass,
    ) -> f64 {
        let h = self.displacement_gradient(e, z);
        let Some(shear) = material.pointwise(&h, false) else {
            return f64::INFINITY;
        };
        let (gt, j) = (shear.gt, shear.j);
        let volume = self.mesh.volumes()[e];
        let g = self.mesh.shape_gradients(e);
        let p = &z[12..16];
        let q = 0.25 * (p[0] + p[1] + p[2] + p[3]);
        let (c, dc, d2c) = shear.measure;
        let cp = self.compliance_times(e, p, mass);
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
            let mu = material.mu;
            let (alpha, beta) = (mu - dh * j, d2h * j * j + dh * j);
            match mode {
                // Only the displacement block is projected: the saddle point stays a saddle point.
                HessianMode::Projected => set_projected_isotropic_tet_hessian(
                    volume,
                    g,
                    &(Mat3::identity() + h),
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
            self.set_pressure_blocks(e, volume, g, &dvol_stress, mass, hess);
        }
        energy
    }

    /// Mixed formulation, any model: `p c(J)` folded into the model's pass as the volumetric term
    /// (see [`ElasticTerm::standard_general`]).
    #[allow(clippy::too_many_arguments)]
    fn mixed_general(
        &self,
        e: usize,
        material: &impl Hyperelastic,
        z: &[f64],
        grad: Option<&mut [f64]>,
        hess: Option<&mut [f64]>,
        mode: HessianMode,
        mass: PressureMass,
    ) -> f64 {
        let h = self.displacement_gradient(e, z);
        let Some(state) = VolumeState::new(&h) else {
            return f64::INFINITY;
        };
        let p = &z[12..16];
        let q = 0.25 * (p[0] + p[1] + p[2] + p[3]);
        let (c, dc, d2c) = material.volumetric().measure_near_one(state.jm1);
        let volumetric = VolumetricTerm {
            energy: q * c,
            stress_slope: q * dc,
            tangent_slope: q * dc,
            tangent_curvature: q * d2c,
        };
        let Some(r) = material.rest_with_volumetric(&h, &state, &volumetric, hess.is_some()) else {
            return f64::INFINITY;
        };
        let volume = self.mesh.volumes()[e];
        let g = self.mesh.shape_gradients(e);
        let cp = self.compliance_times(e, p, mass);
        let energy = volume * r.energy - 0.5 * (0..4).map(|a| p[a] * cp[a]).sum::<f64>();
        if let Some(grad) = grad {
            grad.fill(0.0);
            add_tet_gradient(volume, g, &r.stress, grad);
            for a in 0..4 {
                grad[12 + a] = 0.25 * volume * c - cp[a];
            }
        }
        if let (Some(hess), Some(tangent)) = (hess, r.tangent) {
            set_tangent_tet_hessian(volume, g, &tangent, mode, hess, 16);
            let dvol_stress = dc * state.j * state.gt;
            self.set_pressure_blocks(e, volume, g, &dvol_stress, mass, hess);
        }
        energy
    }

    /// The mixed element Hessian's coupling blocks `d(grad_u)/dp` (and their transpose) and its
    /// compliance block `-C_e`.
    fn set_pressure_blocks(
        &self,
        e: usize,
        volume: f64,
        g: &[Vector3<f64>; 4],
        dvol_stress: &Mat3,
        mass: PressureMass,
        hess: &mut [f64],
    ) {
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
}

/// Writes the displacement block of a `stride`-wide element Hessian from a model's whole 9x9
/// tangent `A` (rest and volumetric parts): exact, or with `A` projected to positive
/// semi-definite first ([`project_to_psd`]: its negative eigenvalues clamped to zero, so that the
/// element Hessian `V B^T A B` is positive semi-definite too).
fn set_tangent_tet_hessian(
    volume: f64,
    g: &[Vector3<f64>; 4],
    tangent: &Tangent,
    mode: HessianMode,
    hess: &mut [f64],
    stride: usize,
) {
    match mode {
        HessianMode::Exact => set_tet_hessian(volume, g, tangent, hess, stride),
        HessianMode::Projected => {
            set_tet_hessian(volume, g, &project_to_psd(tangent), hess, stride)
        }
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
        let material = self.element_material(e);
        match (self.formulation, material) {
            (Formulation::Standard, ElementMaterial::NeoHookean(m)) if self.closed_forms => {
                self.standard_neo_hookean(e, &m, z, grad, hess, mode)
            }
            (Formulation::Mixed { mass, .. }, ElementMaterial::NeoHookean(m))
                if self.closed_forms =>
            {
                self.mixed_neo_hookean(e, &m, z, grad, hess, mode, mass)
            }
            (Formulation::Standard, m) => self.standard_general(e, &m, z, grad, hess, mode),
            (Formulation::Mixed { mass, .. }, m) => {
                self.mixed_general(e, &m, z, grad, hess, mode, mass)
            }
        }
    }
}

/// The pressure compliance `1/2 p^T C p` with `C = sum_e M_e / kappa_e`, on the nodal pressure
/// DOFs alone (indices 0..n_nodes). Its Hessian is `C`; its pattern is the node graph.
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
        let cp = self.elastic.compliance_times(e, p, self.mass);
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

/// The material's parameters, one block per name with one value per tet.
///
/// Standard: `d(grad_a)/d(theta_k) = V (dP_rest/dtheta_k + dkappa/dtheta_k c c' J F^{-T}) g_a`.
/// Mixed: the rest part gives the same displacement rows, while `kappa` only enters the
/// compliance `C_e = M_e / kappa`, so `d(grad_p)/d(theta_k) = (C_e p / kappa) dkappa/dtheta_k`
/// and nothing on the displacement rows (differentiating `kappa/2 c^2` there instead is the
/// classic mistake).
impl ParamTerm for ElasticTerm {
    fn param_blocks(&self) -> Vec<(String, usize)> {
        let m = self.mesh.n_tets();
        (self.material.param_names().into_iter())
            .map(|name| (name, m))
            .collect()
    }
    fn element_param_count(&self) -> usize {
        self.material.n_params()
    }
    fn element_params(&self, e: usize, params: &mut [(usize, usize)]) {
        for (k, param) in params.iter_mut().enumerate() {
            *param = (k, e);
        }
    }
    fn element_param_gradient(&self, e: usize, z: &[f64], out: &mut [f64]) {
        out.fill(0.0);
        let material = self.element_material(e);
        let h = self.displacement_gradient(e, z);
        let (Some(rest), Some((gt, j))) = (
            material.rest_param_gradient(&h),
            inverse_transpose(&(Mat3::identity() + h)),
        ) else {
            return;
        };
        let bulk = material.bulk_param_gradient();
        let (c, dc, _) = material.volumetric().measure_near_one(j_minus_one(&h));
        let volume = self.mesh.volumes()[e];
        let g = self.mesh.shape_gradients(e);
        let s = self.stencil_size();
        for (k, row) in out.chunks_mut(s).enumerate() {
            match self.formulation {
                Formulation::Standard => {
                    let stress = rest.stress[k] + (bulk[k] * c * dc * j) * gt;
                    add_tet_gradient(volume, g, &stress, &mut row[..12]);
                }
                Formulation::Mixed { mass, .. } => {
                    add_tet_gradient(volume, g, &rest.stress[k], &mut row[..12]);
                    if bulk[k] != 0.0 {
                        let cp = self.compliance_times(e, &z[12..16], mass);
                        for a in 0..4 {
                            row[12 + a] = cp[a] / self.bulk[e] * bulk[k];
                        }
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `max |x - y| <= tol max |x|`.
    fn close(x: &[f64], y: &[f64], tol: f64) -> bool {
        let scale = x.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        x.iter().zip(y).all(|(p, q)| (p - q).abs() <= tol * scale)
    }

    /// The general path on a Neo-Hookean model against its closed forms: energy, gradient and
    /// both Hessians of every tet of a small box at large random displacements (and pressures),
    /// both formulations, both volumetric measures, with and without pressure iterates.
    #[test]
    fn general_path_matches_the_neo_hookean_closed_forms() {
        let mesh = Arc::new(TetMesh::box_mesh([0.3, 0.1, 0.1], [3, 1, 1], [0.0; 3]).unwrap());
        let m = mesh.n_tets();
        let mu: Vec<f64> = (0..m).map(|e| 2e4 * (1.0 + 0.1 * e as f64)).collect();
        let lambda: Vec<f64> = (0..m).map(|e| 3e5 * (1.0 + 0.05 * e as f64)).collect();
        let (mut compared, mut projected) = (0, 0);
        for formulation in [
            Formulation::Standard,
            Formulation::Mixed {
                pressure_offset: 0,
                mass: PressureMass::Consistent,
            },
        ] {
            for volumetric in [Volumetric::Log, Volumetric::Linear] {
                for iterates in [false, true] {
                    let mut term = ElasticTerm::neo_hookean(
                        mesh.clone(),
                        &mu,
                        &lambda,
                        volumetric,
                        formulation,
                    );
                    let s = term.stencil_size();
                    if iterates && formulation == Formulation::Standard {
                        let values = (0..m).map(|e| 1e3 * e as f64).collect();
                        term.pressure_iterates = Some(PressureIterates::new(values));
                    }
                    for e in 0..m {
                        // Displacements (m) large enough that some exact Hessians are
                        // indefinite, then pressures (Pa).
                        let z: Vec<f64> = (0..s)
                            .map(|k| {
                                let v = ((e * 31 + k * 17) % 23) as f64 / 11.0 - 1.0;
                                if k >= 12 {
                                    2e4 * v
                                } else {
                                    0.04 * v
                                }
                            })
                            .collect();
                        let mut exact = Vec::new();
                        for mode in [HessianMode::Exact, HessianMode::Projected] {
                            let mut results = Vec::new();
                            for closed_forms in [true, false] {
                                term.closed_forms = closed_forms;
                                let (mut grad, mut hess) = (vec![0.0; s], vec![f64::NAN; s * s]);
                                let energy =
                                    term.element(e, &z, Some(&mut grad), Some(&mut hess), mode);
                                results.push((energy, grad, hess));
                            }
                            let (a, b) = (&results[0], &results[1]);
                            assert!(a.0.is_finite(), "tet {e} inverted");
                            assert!((a.0 - b.0).abs() <= 1e-12 * a.0.abs(), "energy of tet {e}");
                            assert!(close(&a.1, &b.1, 1e-12), "gradient of tet {e}");
                            assert!(close(&a.2, &b.2, 1e-9), "{mode:?} Hessian of tet {e}");
                            match mode {
                                HessianMode::Exact => exact = a.2.clone(),
                                HessianMode::Projected => {
                                    projected += usize::from(!close(&exact, &a.2, 1e-9))
                                }
                            }
                            compared += 1;
                        }
                    }
                }
            }
        }
        assert_eq!(compared, 2 * 2 * 2 * 2 * m);
        assert!(projected >= 4, "too few indefinite cases: {projected}");
    }
}
