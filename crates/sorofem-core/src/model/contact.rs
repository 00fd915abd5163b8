//! A model's obstacles: setting them up, the reference barrier stiffness, what a solve reports
//! of its contact, and what reactions and sensitivities need of it.

use super::system::System;
use super::Model;
use crate::contact::check::find_intersection;
use crate::contact::{ContactForces, ContactSetup, ContactTerm};
use crate::energy::HessianMode;
use crate::error::{Error, Result};
use crate::material::shear_modulus;

/// The contact of a solved state.
#[derive(Clone, Debug, Default)]
pub struct ContactReport {
    pub forces: ContactForces,
    /// The barrier stiffness the solve ended with (J/m^4) and the activation distance (m).
    pub stiffness: f64,
    pub dhat: f64,
    /// The minimum distance (m) between the body and its obstacles at every accepted Newton
    /// iterate, over the stencils within `dhat` (`+inf` when there was none): all positive, as
    /// the line search never accepts an intersecting state.
    pub iterate_min_distances: Vec<f64>,
}

impl Model {
    /// Sets (replaces) the model's obstacles and contact settings; no obstacles and no
    /// self-contact removes contact. Errors name the bad value, or the obstacle that touches the
    /// body at rest (with the node or triangle and the distance).
    pub fn set_contact(&mut self, setup: ContactSetup) -> Result<()> {
        self.terms.contact = if setup.obstacles.is_empty() && !setup.self_contact {
            None
        } else {
            Some(ContactTerm::try_new(&self.mesh, setup)?)
        };
        self.last_state = None;
        self.factor_at_solution = false;
        Ok(())
    }

    /// Makes the Hessian pattern hold the couplings of every self-contact stencil near the body
    /// at the full DOF vector `z` (within [`ContactTerm::self_coupling_reach`]), and analyses
    /// the grown pattern afresh when it lacked some: a symbolic analysis per growth, never per
    /// Newton iteration, and reused by every later solve. Returns whether the pattern grew
    /// (Hessian values and factorisations of the old one are then stale). Without self-contact
    /// the pattern holds every contact coupling already and nothing happens.
    pub(crate) fn cover_self_contact(&mut self, z: &[f64]) -> Result<bool> {
        let Some(term) = self.terms.contact.as_ref().filter(|t| t.self_contact()) else {
            return Ok(false);
        };
        let mut entries = Vec::new();
        for [a, b] in term.self_couplings(z) {
            for i in 0..3 {
                for j in 0..3 {
                    let free = (self.assembler.free_of_full(3 * a + i))
                        .zip(self.assembler.free_of_full(3 * b + j));
                    if let Some((r, c)) = free {
                        entries.push((r.max(c), r.min(c)));
                    }
                }
            }
        }
        if !self.assembler.add_entries(&entries) {
            return Ok(false);
        }
        let fixed_dofs = self.layout.fixed_dofs(&self.fixed_nodes);
        let mut fixed_set = vec![false; self.mesh.n_nodes()];
        for &node in &self.fixed_nodes {
            fixed_set[node] = true;
        }
        self.factor = super::analyse_pattern(
            self.assembler.pattern(),
            self.formulation,
            &self.layout,
            &self.terms,
            &fixed_dofs,
            &fixed_set,
        )?;
        self.symbolic_analyses += 1;
        self.factor_at_solution = false;
        Ok(true)
    }

    /// Symbolic analyses of the Hessian pattern since the model was built (one at construction,
    /// one per growth of the pattern by self-contact).
    pub fn symbolic_analyses(&self) -> usize {
        self.symbolic_analyses
    }

    /// Turns the contact audit on or off (see [`ContactTerm::set_audit`]); no effect without
    /// obstacles.
    pub fn set_contact_audit(&mut self, on: bool) {
        if let Some(term) = &mut self.terms.contact {
            term.set_audit(on);
        }
    }

    /// The contact term, when the model has obstacles.
    pub fn contact(&self) -> Option<&ContactTerm> {
        self.terms.contact.as_ref()
    }

    /// Fixes the reference barrier stiffness at the first solve that needs it, from the mean
    /// shear modulus of the material then (see [`ContactTerm::default_stiffness`]): later
    /// solves, for other parameters too, keep it, so that results are smooth in the parameters.
    pub(crate) fn prepare_contact(&mut self) {
        let Some(term) = &self.terms.contact else {
            return;
        };
        let reference = term.reference_stiffness().unwrap_or_else(|| {
            let m = self.mesh.n_tets();
            let mean = (0..m)
                .map(|e| shear_modulus(&self.terms.elastic.element_material(e)))
                .sum::<f64>()
                / m as f64;
            term.default_stiffness(mean)
        });
        let term = self.terms.contact.as_mut().expect("checked above");
        term.set_reference_stiffness(reference);
        term.set_stiffness(reference);
    }

    /// `Err` naming `param` when the body at the full DOF vector `z` touches or intersects an
    /// obstacle where the obstacles are now.
    pub(crate) fn check_apart(&self, param: &str, z: &[f64]) -> Result<()> {
        let Some(term) = &self.terms.contact else {
            return Ok(());
        };
        match find_intersection(term.collision_mesh(), &term.positions(z)) {
            None => Ok(()),
            Some(intersection) => Err(Error::invalid(
                param,
                "positions apart from every obstacle",
                format!("{}: {intersection}", intersection.param()),
            )),
        }
    }

    /// The contact forces, minimum distances and active stencils at node `positions` (3 n, m),
    /// with the obstacles where they are now and the friction of the last solve; `None`
    /// without obstacles.
    pub fn contact_forces(&self, positions: &[f64]) -> Result<Option<ContactForces>> {
        let Some(term) = &self.terms.contact else {
            return Ok(None);
        };
        let z = self.displacements_of("positions", positions)?;
        Ok(Some(term.forces(&z)))
    }

    /// What a solve reports of its contact at the full DOF vector `z`.
    pub(crate) fn contact_report(
        &self,
        z: &[f64],
        iterate_min_distances: Vec<f64>,
    ) -> Option<ContactReport> {
        let term = self.terms.contact.as_ref()?;
        Some(ContactReport {
            forces: term.forces(z),
            stiffness: term.stiffness(),
            dhat: term.dhat(),
            iterate_min_distances,
        })
    }

    /// `d(w . F_k)/dx` (3 n, N/m per unit of `w`) at the last static solution: the derivative of
    /// the total force obstacle `obstacle` exerts on the body, along `w`, with respect to the
    /// node positions. With [`Model::adjoint`] it gives the parameter gradient of an objective
    /// on that force.
    pub fn contact_force_gradient(&self, obstacle: usize, w: [f64; 3]) -> Result<Vec<f64>> {
        let Some(term) = &self.terms.contact else {
            return Err(Error::invalid(
                "obstacle",
                "a model with obstacles",
                "no obstacles",
            ));
        };
        if obstacle >= term.n_obstacles() {
            return Err(Error::IndexOutOfRange {
                param: "obstacle".into(),
                position: 0,
                index: obstacle as i64,
                len: term.n_obstacles(),
            });
        }
        crate::error::check_finite("weights", &w)?;
        let Some((z, _)) = &self.last_state else {
            return Err(Error::invalid(
                "model",
                "a converged static solve before contact force gradients",
                "no solution",
            ));
        };
        Ok(term.force_gradient(z, obstacle, w))
    }

    /// Adds the contact Hessian at `z` into Hessian values of the assembler's pattern.
    pub(crate) fn add_contact_hessian(&self, z: &[f64], values: &mut [f64], mode: HessianMode) {
        if let Some(term) = &self.terms.contact {
            term.add_to(&self.assembler, z, &mut [], Some((values, mode)));
        }
    }

    /// The full DOF vector's node displacements (3 n) of node `positions` (3 n, m).
    fn displacements_of(&self, param: &str, positions: &[f64]) -> Result<Vec<f64>> {
        let n = self.mesh.n_nodes();
        if positions.len() != 3 * n {
            return Err(Error::shape(
                param,
                format!("({n}, 3)"),
                format!("{} values", positions.len()),
            ));
        }
        crate::error::check_finite(param, positions)?;
        Ok(positions
            .iter()
            .zip(self.mesh.rest_flat())
            .map(|(x, r)| x - r)
            .collect())
    }
}

impl System<'_> {
    /// [`Model::cover_self_contact`] at the state `z` before a Hessian is assembled there; a
    /// factorisation kept for reuse belongs to the old pattern and is dropped when it grew.
    pub(super) fn cover_self_contact(&mut self, z: &[f64]) -> Result<()> {
        if self.model.cover_self_contact(z)? {
            if let Some(reuse) = &mut self.reuse {
                reuse.kept = None;
            }
        }
        Ok(())
    }
}
