//! Sensitivities of a static equilibrium `r(z, theta) = grad Pi(z; theta) - f(theta) = 0`.
//!
//! Forward mode: `dz/dtheta . delta = -H^{-1} (dr/dtheta . delta)`. Adjoint mode: for a scalar
//! objective O(x), `dO/dtheta = -lambda^T dr/dtheta` with `H lambda = dO/dz`. H is the exact
//! Hessian at the solution (the saddle-point matrix in the mixed formulation, so pressures are
//! part of z and `dr/dkappa` acts on the pressure rows); one factorisation serves every
//! forward and adjoint solve until the model or its parameters change.
//!
//! With obstacles, H holds the contact Hessian at the solution (the barrier at the solve's
//! stiffness, and the friction lagged there): exact for frictionless contact, whose barrier is
//! smooth; with friction the lag's own dependence on the parameters is left out.
//!
//! `dr/dtheta` comes from the terms of the model's registry that have parameters
//! ([`crate::energy::ParamTerm`]), element by element: nothing here is specific to a term.
//! Parameters are named blocks: the material's parameters (per tet, Pa or as the model
//! declares), `density` (per tet, kg/m^3), `gravity` (3, m/s^2), `cable_actuation` and
//! `cable_stiffness` (per cable, 1 and N/m; spring cables), `cable_tension` and `cable_pull`
//! (per cable, N and m; tendons under force and displacement control).
//!
//! A displacement-controlled tendon taut at the solution (`T > 0`) is an active constraint
//! `g = L(z) - (L0 - d) = 0` with multiplier T, which stays active under small changes: the
//! system is bordered, `[[H, J^T], [J, 0]] [dz; dT] = -[dr/dtheta; dg/dtheta] delta`, and solved
//! through the Schur complement `S = J H^{-1} J^T` with the same factorisation of H
//! (`dg/dd = 1`). The adjoint is the transposed system: `mu = S^{-1} J H^{-1} dO/dz`,
//! `lambda = H^{-1} (dO/dz - J^T mu)`, and `dO/dd = -mu`. A slack tendon (`T = 0`) is inactive.

use crate::energy::{HessianMode, ParamTerm, TendonCommand};
use crate::error::{Error, Result};
use crate::linear::SparseFactor;
use crate::model::Model;
use rayon::prelude::*;

/// A value per parameter, in named blocks: a gradient `dO/dtheta` or a direction
/// `delta theta`. [`Model::param_zeros`] gives a model's blocks.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ParamVector {
    pub blocks: Vec<(String, Vec<f64>)>,
}

impl ParamVector {
    /// The block named `name`.
    pub fn get(&self, name: &str) -> Option<&[f64]> {
        self.blocks
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| v.as_slice())
    }

    /// The block named `name`, to fill in.
    pub fn get_mut(&mut self, name: &str) -> Option<&mut Vec<f64>> {
        self.blocks
            .iter_mut()
            .find(|(n, _)| n == name)
            .map(|(_, v)| v)
    }
}

/// Where each parameter block sits in one flat vector, and where each term's blocks are.
pub(crate) struct ParamLayout {
    /// Name, offset and length of every block, in order of first appearance.
    pub(crate) blocks: Vec<(String, usize, usize)>,
    /// Per term, the flat offset of each of its blocks.
    pub(crate) term_offsets: Vec<Vec<usize>>,
    pub(crate) len: usize,
}

impl ParamLayout {
    /// Blocks of the same name in several terms are one parameter (and must agree in length).
    pub(crate) fn new(terms: &[&dyn ParamTerm]) -> Self {
        let mut layout = ParamLayout {
            blocks: Vec::new(),
            term_offsets: Vec::new(),
            len: 0,
        };
        for term in terms {
            let mut offsets = Vec::new();
            for (name, len) in term.param_blocks() {
                let offset = match layout.blocks.iter().find(|b| b.0 == name) {
                    Some(&(_, offset, known)) => {
                        assert_eq!(known, len, "parameter block {name:?} with two lengths");
                        offset
                    }
                    None => {
                        layout.blocks.push((name, layout.len, len));
                        layout.len += len;
                        layout.len - len
                    }
                };
                offsets.push(offset);
            }
            layout.term_offsets.push(offsets);
        }
        layout
    }

    pub(crate) fn unflatten(&self, flat: &[f64]) -> ParamVector {
        ParamVector {
            blocks: self
                .blocks
                .iter()
                .map(|(name, offset, len)| (name.clone(), flat[*offset..offset + len].to_vec()))
                .collect(),
        }
    }

    /// The flat vector of `p`, whose blocks must be among this layout's (missing ones are zero).
    pub(crate) fn flatten(&self, p: &ParamVector) -> Result<Vec<f64>> {
        let mut flat = vec![0.0; self.len];
        for (name, values) in &p.blocks {
            let Some(&(_, offset, len)) = self.blocks.iter().find(|b| &b.0 == name) else {
                let known: Vec<&str> = self.blocks.iter().map(|b| b.0.as_str()).collect();
                return Err(Error::invalid(
                    "direction",
                    format!("parameter names among {known:?}"),
                    format!("{name:?}"),
                ));
            };
            if values.len() != len {
                return Err(Error::shape(
                    &format!("direction[{name:?}]"),
                    format!("({len},)"),
                    format!("({},)", values.len()),
                ));
            }
            crate::error::check_finite(&format!("direction[{name:?}]"), values)?;
            flat[offset..offset + len].copy_from_slice(values);
        }
        Ok(flat)
    }
}

/// Terms with fewer elements run their loops on the calling thread: a parallel region costs
/// more than the work (waking the pool's threads, tens of microseconds on a busy machine).
const PARALLEL_FROM_ELEMENTS: usize = 2048;

/// Runs `body(scratch, (e, out))` for every element `e` of `term`, `out` the e-th chunk of
/// `outputs` (`chunk` values each): in parallel for large terms, each thread with its own
/// [`ElementScratch`].
fn for_each_element<T: Send>(
    term: &dyn ParamTerm,
    outputs: &mut [T],
    chunk: usize,
    body: impl Fn(&mut ElementScratch, (usize, &mut [T])) + Sync,
) {
    if term.n_elements() >= PARALLEL_FROM_ELEMENTS {
        (outputs.par_chunks_mut(chunk).enumerate())
            .for_each_init(|| ElementScratch::new(term), |s, item| body(s, item));
    } else {
        let mut scratch = ElementScratch::new(term);
        for item in outputs.chunks_mut(chunk).enumerate() {
            body(&mut scratch, item);
        }
    }
}

/// Per-thread buffers of one term's element loop.
struct ElementScratch {
    dofs: Vec<usize>,
    local: Vec<f64>,
    params: Vec<(usize, usize)>,
    gradient: Vec<f64>,
    /// The direction's value of each parameter (forward mode).
    weights: Vec<f64>,
}

impl ElementScratch {
    fn new(term: &dyn ParamTerm) -> Self {
        let (s, k) = (term.stencil_size(), term.element_param_count());
        ElementScratch {
            dofs: vec![0; s],
            local: vec![0.0; s],
            params: vec![(0, 0); k],
            gradient: vec![0.0; k * s],
            weights: vec![0.0; k],
        }
    }

    /// Element `e`'s DOFs, its local values of `z` and its parameters.
    fn gather(&mut self, term: &dyn ParamTerm, e: usize, z: &[f64]) {
        term.element_dofs(e, &mut self.dofs);
        for (v, &d) in self.local.iter_mut().zip(&self.dofs) {
            *v = z[d];
        }
        term.element_params(e, &mut self.params);
    }
}

/// An active tendon constraint at the solution: its cable, `J` (free DOFs) and `H^{-1} J^T`.
pub(crate) struct ActiveTendon {
    pub(crate) cable: usize,
    pub(crate) row: Vec<f64>,
    pub(crate) solved: Vec<f64>,
}

/// `S^{-1} rhs` for the Schur complement `S_ij = J_i . H^{-1} J_j` of the active tendons.
pub(crate) fn schur_solve(active: &[ActiveTendon], rhs: Vec<f64>) -> Result<Vec<f64>> {
    let m = active.len();
    let schur = nalgebra::DMatrix::from_fn(m, m, |i, j| dot(&active[i].row, &active[j].solved));
    schur
        .lu()
        .solve(&nalgebra::DVector::from_vec(rhs))
        .filter(|x| x.iter().all(|v| v.is_finite()))
        .map(|x| x.as_slice().to_vec())
        .ok_or_else(|| Error::LinearSolver {
            message: "the taut tendons' constraints are dependent at the solution (two tendons along the same path?): their tension sensitivities are undefined".into(),
        })
}

pub(crate) fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Adds `w . d(grad_term)/dtheta` at the full DOF vector `z` to `flat` (the parameters laid out
/// by a [`ParamLayout`], `offsets` this term's block offsets there). The element kernels run in
/// parallel (large terms); their values are summed in element order.
pub(crate) fn add_contraction(
    term: &dyn ParamTerm,
    offsets: &[usize],
    z: &[f64],
    w: &[f64],
    flat: &mut [f64],
) {
    let (s, k) = (term.stencil_size(), term.element_param_count());
    if k == 0 || term.n_elements() == 0 {
        return;
    }
    let mut contributions = vec![(0usize, 0.0f64); term.n_elements() * k];
    for_each_element(term, &mut contributions, k, |scratch, (e, out)| {
        scratch.gather(term, e, z);
        term.element_param_gradient(e, &scratch.local, &mut scratch.gradient);
        for (j, slot) in out.iter_mut().enumerate() {
            let (block, index) = scratch.params[j];
            let row = &scratch.gradient[j * s..(j + 1) * s];
            let value = row.iter().zip(&scratch.dofs).map(|(g, &d)| g * w[d]).sum();
            *slot = (offsets[block] + index, value);
        }
    });
    for (index, value) in contributions {
        flat[index] += value;
    }
}

/// Adds `scale d(grad_term)/dtheta . delta` (full DOFs) at the full DOF vector `z` to `out`
/// (`delta` laid out as in [`add_contraction`]). Elements whose parameters `delta` leaves
/// unchanged are skipped.
pub(crate) fn add_derivative_along(
    term: &dyn ParamTerm,
    offsets: &[usize],
    z: &[f64],
    delta: &[f64],
    scale: f64,
    out: &mut [f64],
) {
    let (s, k) = (term.stencil_size(), term.element_param_count());
    if k == 0 || term.n_elements() == 0 {
        return;
    }
    let mut local_out = vec![0.0; term.n_elements() * s];
    for_each_element(term, &mut local_out, s, |scratch, (e, out)| {
        scratch.gather(term, e, z);
        for (weight, &(block, index)) in scratch.weights.iter_mut().zip(&scratch.params) {
            *weight = delta[offsets[block] + index];
        }
        out.fill(0.0);
        if scratch.weights.iter().all(|&v| v == 0.0) {
            return;
        }
        term.element_param_gradient(e, &scratch.local, &mut scratch.gradient);
        for (j, &weight) in scratch.weights.iter().enumerate() {
            for (o, g) in out.iter_mut().zip(&scratch.gradient[j * s..(j + 1) * s]) {
                *o += weight * g;
            }
        }
    });
    let mut dofs = vec![0; s];
    for (e, values) in local_out.chunks(s).enumerate() {
        term.element_dofs(e, &mut dofs);
        for (&d, v) in dofs.iter().zip(values) {
            out[d] += scale * v;
        }
    }
}

impl Model {
    /// The displacement-controlled tendons taut at the last solution, with `H^{-1} J^T` from
    /// the factorisation there.
    pub(crate) fn active_tendons(&self) -> Result<Vec<ActiveTendon>> {
        let (z, _) = self.last_state.as_ref().expect("prepared");
        self.active_tendons_at(z, &self.factor)
    }

    /// The displacement-controlled tendons taut at the full DOF vector `z`, with `H^{-1} J^T`
    /// from `factor` (of the Hessian there, solved to double precision).
    pub(crate) fn active_tendons_at(
        &self,
        z: &[f64],
        factor: &SparseFactor,
    ) -> Result<Vec<ActiveTendon>> {
        let term = &self.terms.tendons;
        let free = self.assembler.full_of_free();
        (term.tendons.iter().enumerate())
            .filter(|(_, t)| matches!(t.command, TendonCommand::Pull(_)) && t.tension > 0.0)
            .map(|(i, tendon)| {
                let mut full = vec![0.0; z.len()];
                tendon.add_length_gradient(z, 1.0, &mut full);
                let row: Vec<f64> = free.iter().map(|&d| full[d]).collect();
                let mut solved = row.clone();
                factor.solve_to_precision(&mut solved)?;
                Ok(ActiveTendon {
                    cable: term.cable_index(i),
                    row,
                    solved,
                })
            })
            .collect()
    }

    /// The model's parameters, all zero: the material's parameters (per tet), `density` (per
    /// tet), `gravity` (3), `cable_actuation` and `cable_stiffness` (per cable).
    pub fn param_zeros(&self) -> ParamVector {
        let loads = self.terms.loads(&Default::default());
        let layout = ParamLayout::new(&self.terms.parameterised(&loads));
        layout.unflatten(&vec![0.0; layout.len])
    }

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
        let z = z.clone();
        self.cover_self_contact(&z)?;
        let mut eval =
            self.assembler
                .evaluate(&self.terms.internal(), &z, false, Some(HessianMode::Exact));
        self.add_contact_hessian(&z, &mut eval.hessian, HessianMode::Exact);
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

    /// `w . dr/dtheta` for every parameter, from a full-DOF vector `w` (zeros on fixed DOFs).
    /// The element kernels run in parallel (large terms); their values are summed in element
    /// order.
    fn contract_param_derivatives(&self, w: &[f64]) -> ParamVector {
        let (z, loads) = self.last_state.as_ref().expect("prepared");
        let load_terms = self.terms.loads(loads);
        let terms = self.terms.parameterised(&load_terms);
        let layout = ParamLayout::new(&terms);
        let mut flat = vec![0.0; layout.len];
        for (term, offsets) in terms.iter().zip(&layout.term_offsets) {
            add_contraction(*term, offsets, z, w, &mut flat);
        }
        layout.unflatten(&flat)
    }

    /// `dr/dtheta . delta` as a full-DOF vector. Elements whose parameters `delta` leaves
    /// unchanged are skipped.
    fn param_derivative_along(&self, delta: &ParamVector) -> Result<Vec<f64>> {
        let (z, loads) = self.last_state.as_ref().expect("prepared");
        let load_terms = self.terms.loads(loads);
        let terms = self.terms.parameterised(&load_terms);
        let layout = ParamLayout::new(&terms);
        let delta = layout.flatten(delta)?;
        let mut out = vec![0.0; z.len()];
        for (term, offsets) in terms.iter().zip(&layout.term_offsets) {
            add_derivative_along(*term, offsets, z, &delta, 1.0, &mut out);
        }
        Ok(out)
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
        let active = self.active_tendons()?;
        let mut multipliers = Vec::new();
        if !active.is_empty() {
            multipliers = schur_solve(&active, active.iter().map(|a| dot(&a.row, &rhs)).collect())?;
            for (a, mu) in active.iter().zip(&multipliers) {
                for (l, s) in rhs.iter_mut().zip(&a.solved) {
                    *l -= mu * s;
                }
            }
        }
        let mut w = vec![0.0; self.layout.n_full()];
        for (&d, l) in self.assembler.full_of_free().iter().zip(&rhs) {
            w[d] = -l;
        }
        let mut gradient = self.contract_param_derivatives(&w);
        let pulls = gradient.get_mut("cable_pull").expect("the tendons' block");
        for (a, mu) in active.iter().zip(&multipliers) {
            pulls[a.cable] -= mu;
        }
        Ok(gradient)
    }

    /// Forward sensitivity along a parameter direction (any of the blocks of
    /// [`Model::param_zeros`]; missing blocks are zero): `(dx, dp)` with dx the change of the
    /// node positions (3 n, m per unit of the direction) and dp of the pressures (mixed only).
    pub fn forward(&mut self, direction: &ParamVector) -> Result<(Vec<f64>, Option<Vec<f64>>)> {
        self.forward_with_tensions(direction)
            .map(|(dx, dp, _)| (dx, dp))
    }

    /// [`Model::forward`] and the change of each tendon's tension (N per unit of the
    /// direction; `None` for spring cables): the direction's own under force control, the
    /// multiplier's under displacement control (0 when slack).
    #[allow(clippy::type_complexity)]
    pub fn forward_with_tensions(
        &mut self,
        direction: &ParamVector,
    ) -> Result<(Vec<f64>, Option<Vec<f64>>, Vec<Option<f64>>)> {
        self.prepare_sensitivities()?;
        let b = self.param_derivative_along(direction)?;
        let mut rhs: Vec<f64> = self
            .assembler
            .full_of_free()
            .iter()
            .map(|&d| -b[d])
            .collect();
        self.factor.solve_in_place(&mut rhs);
        let n_cables = self.n_cables();
        let block = |name: &str| {
            direction
                .get(name)
                .map_or(vec![0.0; n_cables], |v| v.to_vec())
        };
        let (pulls, given_tensions) = (block("cable_pull"), block("cable_tension"));
        let mut tensions: Vec<Option<f64>> = (0..n_cables)
            .map(|c| match self.tendon_command(c) {
                Ok(TendonCommand::Tension(_)) => Some(given_tensions[c]),
                Ok(TendonCommand::Pull(_)) => Some(0.0),
                Err(_) => None,
            })
            .collect();
        let active = self.active_tendons()?;
        if !active.is_empty() {
            let schur_rhs = (active.iter())
                .map(|a| dot(&a.row, &rhs) + pulls[a.cable])
                .collect();
            let changes = schur_solve(&active, schur_rhs)?;
            for (a, dt) in active.iter().zip(&changes) {
                for (x, s) in rhs.iter_mut().zip(&a.solved) {
                    *x -= dt * s;
                }
                tensions[a.cable] = Some(*dt);
            }
        }
        let mut dz = vec![0.0; self.layout.n_full()];
        for (&d, v) in self.assembler.full_of_free().iter().zip(&rhs) {
            dz[d] = *v;
        }
        let pressure = self
            .layout
            .pressure_offset()
            .map(|offset| dz[offset..].to_vec());
        dz.truncate(3 * self.mesh.n_nodes());
        Ok((dz, pressure, tensions))
    }
}
