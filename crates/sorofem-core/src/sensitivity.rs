//! Sensitivities of a static equilibrium `r(z, theta) = grad Pi(z; theta) - f(theta) = 0`.
//!
//! Forward mode: `dz/dtheta . delta = -H^{-1} (dr/dtheta . delta)`. Adjoint mode: for a scalar
//! objective O(x), `dO/dtheta = -lambda^T dr/dtheta` with `H lambda = dO/dz`. H is the exact
//! Hessian at the solution (the saddle-point matrix in the mixed formulation, so pressures are
//! part of z and `dr/dlambda` acts on the pressure rows); one factorisation serves every
//! forward and adjoint solve until the model or its parameters change.
//!
//! Parameters: per-tet shear modulus `mu` and Lame `lambda` (Pa), per-tet density `rho`
//! (kg/m^3), gravity (m/s^2), and per cable its actuation alpha and stiffness (N/m).

use crate::energy::{HessianMode, Term};
use crate::error::{Error, Result};
use crate::model::{Formulation, Model};

/// A value per parameter: a gradient `dO/dtheta` or a direction `delta theta`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ParamVector {
    pub mu: Vec<f64>,
    pub lambda: Vec<f64>,
    pub density: Vec<f64>,
    pub gravity: [f64; 3],
    pub cable_actuation: Vec<f64>,
    pub cable_stiffness: Vec<f64>,
}

impl ParamVector {
    pub fn zeros(n_tets: usize, n_cables: usize) -> Self {
        ParamVector {
            mu: vec![0.0; n_tets],
            lambda: vec![0.0; n_tets],
            density: vec![0.0; n_tets],
            gravity: [0.0; 3],
            cable_actuation: vec![0.0; n_cables],
            cable_stiffness: vec![0.0; n_cables],
        }
    }
}

impl Model {
    /// Factors the exact Hessian at the last static solution (once per solution).
    fn prepare_sensitivities(&mut self) -> Result<()> {
        let Some((z, _)) = &self.last_state else {
            return Err(Error::invalid(
                "model",
                "a converged static solve before sensitivities",
                "no solution",
            ));
        };
        if self.factor_at_solution {
            return Ok(());
        }
        let eval =
            self.assembler
                .evaluate(&self.terms.internal(), z, false, Some(HessianMode::Exact));
        let ok = self
            .factor
            .factor(self.assembler.pattern(), &eval.hessian)?;
        if !ok {
            return Err(Error::LinearSolver {
                message: "the Hessian at the solution is singular or indefinite (an unstable equilibrium?): \
                          sensitivities are undefined there"
                    .into(),
            });
        }
        self.factor_at_solution = true;
        Ok(())
    }

    /// Contracts `dr/dtheta` with a full-DOF vector `w` (zeros on fixed DOFs): returns
    /// `w . dr/dtheta` for every parameter.
    fn contract_param_derivatives(&self, w: &[f64]) -> ParamVector {
        let (z, loads) = self.last_state.as_ref().expect("prepared");
        let m = self.mesh.n_tets();
        let mut out = ParamVector::zeros(m, self.n_cables());
        let s = self.terms.elastic.stencil_size();
        let (mut dofs, mut local, mut local_w) = (vec![0; s], vec![0.0; s], vec![0.0; s]);
        let (mut d_mu, mut d_lambda) = (vec![0.0; s], vec![0.0; s]);
        for e in 0..m {
            self.terms.elastic.element_dofs(e, &mut dofs);
            for a in 0..s {
                local[a] = z[dofs[a]];
                local_w[a] = w[dofs[a]];
            }
            self.terms
                .elastic
                .element_param_derivatives(e, &local, &mut d_mu, &mut d_lambda);
            out.mu[e] = d_mu.iter().zip(&local_w).map(|(a, b)| a * b).sum();
            out.lambda[e] = d_lambda.iter().zip(&local_w).map(|(a, b)| a * b).sum();
            // r = grad Pi - f with f_a = rho V / 4 g on each node a of the tet.
            let quarter = self.mesh.volumes()[e] / 4.0;
            for &node in &self.mesh.tets()[e] {
                for k in 0..3 {
                    out.density[e] -= quarter * loads.gravity[k] * w[3 * node + k];
                    out.gravity[k] -= self.density[e] * quarter * w[3 * node + k];
                }
            }
        }
        let n = self.mesh.n_nodes();
        for (i, &(_, mass)) in self.free_nodes.iter().enumerate() {
            for k in 0..3 {
                out.gravity[k] -= mass * w[3 * (n + i) + k];
            }
        }
        let s = self.terms.cables.stencil_size();
        let (mut dofs, mut local, mut d_alpha, mut d_k) =
            (vec![0; s], vec![0.0; s], vec![0.0; s], vec![0.0; s]);
        for e in 0..self.terms.cables.n_elements() {
            self.terms.cables.element_dofs(e, &mut dofs);
            for a in 0..s {
                local[a] = z[dofs[a]];
            }
            self.terms
                .cables
                .segment_param_derivatives(e, &local, &mut d_alpha, &mut d_k);
            let c = self.terms.cables.cable_of(e);
            for a in 0..s {
                out.cable_actuation[c] += d_alpha[a] * w[dofs[a]];
                out.cable_stiffness[c] += d_k[a] * w[dofs[a]];
            }
        }
        out
    }

    /// `dr/dtheta . delta` as a full-DOF vector.
    fn param_derivative_along(&self, delta: &ParamVector) -> Vec<f64> {
        let (z, loads) = self.last_state.as_ref().expect("prepared");
        let mut out = vec![0.0; z.len()];
        let m = self.mesh.n_tets();
        let s = self.terms.elastic.stencil_size();
        let (mut dofs, mut local) = (vec![0; s], vec![0.0; s]);
        let (mut d_mu, mut d_lambda) = (vec![0.0; s], vec![0.0; s]);
        for e in 0..m {
            let (dm, dl) = (
                delta.mu.get(e).copied().unwrap_or(0.0),
                delta.lambda.get(e).copied().unwrap_or(0.0),
            );
            if dm != 0.0 || dl != 0.0 {
                self.terms.elastic.element_dofs(e, &mut dofs);
                for a in 0..s {
                    local[a] = z[dofs[a]];
                }
                self.terms
                    .elastic
                    .element_param_derivatives(e, &local, &mut d_mu, &mut d_lambda);
                for a in 0..s {
                    out[dofs[a]] += dm * d_mu[a] + dl * d_lambda[a];
                }
            }
            let drho = delta.density.get(e).copied().unwrap_or(0.0);
            let quarter = self.mesh.volumes()[e] / 4.0;
            for &node in &self.mesh.tets()[e] {
                for k in 0..3 {
                    out[3 * node + k] -=
                        quarter * (drho * loads.gravity[k] + self.density[e] * delta.gravity[k]);
                }
            }
        }
        let n = self.mesh.n_nodes();
        for (i, &(_, mass)) in self.free_nodes.iter().enumerate() {
            for k in 0..3 {
                out[3 * (n + i) + k] -= mass * delta.gravity[k];
            }
        }
        let s = self.terms.cables.stencil_size();
        let (mut dofs, mut local, mut d_alpha, mut d_k) =
            (vec![0; s], vec![0.0; s], vec![0.0; s], vec![0.0; s]);
        for e in 0..self.terms.cables.n_elements() {
            let c = self.terms.cables.cable_of(e);
            let (da, dk) = (
                delta.cable_actuation.get(c).copied().unwrap_or(0.0),
                delta.cable_stiffness.get(c).copied().unwrap_or(0.0),
            );
            if da == 0.0 && dk == 0.0 {
                continue;
            }
            self.terms.cables.element_dofs(e, &mut dofs);
            for a in 0..s {
                local[a] = z[dofs[a]];
            }
            self.terms
                .cables
                .segment_param_derivatives(e, &local, &mut d_alpha, &mut d_k);
            for a in 0..s {
                out[dofs[a]] += da * d_alpha[a] + dk * d_k[a];
            }
        }
        out
    }

    /// Adjoint gradient of a scalar objective of the equilibrium node positions:
    /// `d_objective_d_positions` is `dO/dx` (3 n); returns `dO/dtheta` for every parameter.
    pub fn adjoint(&mut self, d_objective_d_positions: &[f64]) -> Result<ParamVector> {
        let n = self.mesh.n_nodes();
        if d_objective_d_positions.len() != 3 * n {
            return Err(Error::shape(
                "d_objective_d_positions",
                format!("({n}, 3)"),
                format!("{} values", d_objective_d_positions.len()),
            ));
        }
        crate::error::check_finite("d_objective_d_positions", d_objective_d_positions)?;
        self.prepare_sensitivities()?;
        let mut rhs: Vec<f64> = self
            .assembler
            .full_of_free()
            .iter()
            .map(|&d| {
                if d < 3 * n {
                    d_objective_d_positions[d]
                } else {
                    0.0
                }
            })
            .collect();
        self.factor.solve_in_place(&mut rhs);
        let mut w = vec![0.0; self.assembler.n_full()];
        for (&d, l) in self.assembler.full_of_free().iter().zip(&rhs) {
            w[d] = -l;
        }
        Ok(self.contract_param_derivatives(&w))
    }

    /// Forward sensitivity along a parameter direction: `(dx, dp)` with dx the change of the
    /// node positions (3 n, m per unit of the direction) and dp of the pressures (mixed only).
    pub fn forward(&mut self, direction: &ParamVector) -> Result<(Vec<f64>, Option<Vec<f64>>)> {
        self.prepare_sensitivities()?;
        let b = self.param_derivative_along(direction);
        let mut rhs: Vec<f64> = self
            .assembler
            .full_of_free()
            .iter()
            .map(|&d| -b[d])
            .collect();
        self.factor.solve_in_place(&mut rhs);
        let mut dz = vec![0.0; self.assembler.n_full()];
        for (&d, v) in self.assembler.full_of_free().iter().zip(&rhs) {
            dz[d] = *v;
        }
        let n = self.mesh.n_nodes();
        let pressure = matches!(self.formulation, Formulation::Mixed { .. })
            .then(|| dz[dz.len() - n..].to_vec());
        dz.truncate(3 * n);
        Ok((dz, pressure))
    }
}
