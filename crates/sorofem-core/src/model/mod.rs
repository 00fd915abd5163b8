//! A body ready to be solved many times: mesh, boundary conditions, formulation, the sparsity
//! pattern and the symbolic factorisation (built once), and the material (changeable).
//!
//! The pieces: [`layout`] (where each unknown lives), [`terms`] (the registry of energy terms),
//! `system` (the Newton view of a model), [`statics`] (equilibria), [`dynamics`] (implicit
//! Euler), `contact` (obstacles: setting them up, their forces); sensitivities are in
//! [`crate::sensitivity`].

mod contact;
pub mod dynamics;
pub mod layout;
pub mod statics;
mod system;
mod tendons;
pub(crate) mod terms;
pub mod trajectory;

pub use contact::ContactReport;
pub use dynamics::{ContactFrame, Damping, DynamicsOptions, StepMethod, Trajectory};
pub use layout::DofLayout;
pub use statics::{Loads, Solution};

use crate::assembly::{Assembler, Evaluation};
use crate::cables::{
    check_pull, check_tendon_command, embed, CableSlot, CableSpec, PointPlacement,
};
use crate::energy::elastic::PressureCompliance;
use crate::energy::TendonCommand;
pub use crate::energy::{Formulation as ElementFormulation, PressureMass};
use crate::error::{check_finite, Error, Result};
use crate::linear::{FactorKind, SparseFactor};
use crate::material::{shear_modulus, MaterialModel, Volumetric};
use crate::mesh::TetMesh;
use crate::newton::NewtonOptions;
use std::sync::Arc;
pub use terms::TermSpecs;
use terms::Terms;

/// The discretisation of the volumetric response.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Formulation {
    /// Displacement-only P1 tetrahedra (locks as nu -> 0.5).
    Standard,
    /// P1 displacement + P1 nodal pressure, solved as a saddle-point system.
    Mixed { mass: PressureMass },
}

/// Per-tet Neo-Hookean parameters: shear modulus and Lame's lambda (Pa), density (kg/m^3)
/// (see [`Model::set_material_model`] for any model).
#[derive(Clone, Debug)]
pub struct Material {
    pub mu: Vec<f64>,
    pub lambda: Vec<f64>,
    pub density: Vec<f64>,
}

pub type SolveOptions = NewtonOptions;

pub struct Model {
    pub(crate) mesh: Arc<TetMesh>,
    pub(crate) fixed_nodes: Vec<usize>,
    pub(crate) formulation: Formulation,
    pub(crate) layout: DofLayout,
    pub(crate) terms: Terms,
    /// The constructor's volumetric measure: the Neo-Hookean model's unless told otherwise.
    pub(crate) volumetric: Volumetric,
    pub(crate) assembler: Assembler,
    pub(crate) factor: SparseFactor,
    /// The Newton iterations' Hessian values, kept between assemblies (see
    /// [`crate::assembly::Assembler::evaluate_into`]).
    pub(crate) hessian_scratch: Evaluation,
    /// Weight (Pa/m) of the volume-constraint residual rows (m^3) in the mixed residual norm,
    /// so that they are measured in N like the force rows: `mean(mu) / mean edge length`.
    pub(crate) pressure_weight: f64,
    /// Weight `sigma` (N/m) of a tendon's constraint `g` (m) in the residual and in its active
    /// set test `T + sigma g > 0`: `mean(mu) * mean edge length`, the stiffness of one element.
    pub(crate) constraint_weight: f64,
    /// Free-node displacements and pressures of the last solve: a warm start's starting guess.
    pub(crate) last_extra: Option<Vec<f64>>,
    pub(crate) material_set: bool,
    /// Full DOF vector and loads of the last static solve (what sensitivities differentiate).
    pub(crate) last_state: Option<(Vec<f64>, Loads)>,
    /// The factorisation holds the Hessian at `last_state` (not a Newton iterate's).
    pub(crate) factor_at_solution: bool,
    /// Where the last simulation ended (see `dynamics::Continuation`).
    pub(crate) continuation: Option<dynamics::Continuation>,
    /// Symbolic analyses of the Hessian pattern so far: one at construction, one more each
    /// time self-contact couples DOFs the pattern lacked.
    pub(crate) symbolic_analyses: usize,
}

/// The symbolic factorisation of the Hessian `pattern`: approximate minimum degree (standard
/// formulation, `L L^T`), or displacements before pressures in the order of
/// [`layout::saddle_point_order`] (mixed, `L D L^T` without pivoting).
fn analyse_pattern(
    pattern: &crate::linear::LowerPattern,
    formulation: Formulation,
    layout: &DofLayout,
    terms: &Terms,
    fixed_dofs: &[bool],
    fixed_set: &[bool],
) -> Result<SparseFactor> {
    match formulation {
        Formulation::Standard => SparseFactor::analyse(pattern, FactorKind::Llt),
        Formulation::Mixed { mass } => {
            let compliance = PressureCompliance {
                elastic: &terms.elastic,
                mass,
            };
            let mut free_of_full = vec![None; layout.n_full()];
            for (index, d) in (0..layout.n_full()).filter(|&d| !fixed_dofs[d]).enumerate() {
                free_of_full[d] = Some(index);
            }
            // The pressure unknowns live on the nodes, so this pattern is the node graph.
            let n = layout.n_nodes;
            let node_graph = crate::assembly::pattern_of(&vec![false; n], &[&compliance]);
            let node_order = crate::linear::amd_order(&node_graph)?;
            let order = layout::saddle_point_order(layout, &free_of_full, &node_order, fixed_set);
            SparseFactor::analyse_with_order(pattern, &order, FactorKind::Ldlt)
        }
    }
}

impl Model {
    /// Builds the DOF layout, the sparsity pattern and its symbolic factorisation.
    pub fn try_new(
        mesh: Arc<TetMesh>,
        fixed_nodes: &[i64],
        formulation: Formulation,
        volumetric: Volumetric,
    ) -> Result<Self> {
        Self::try_new_with_cables(mesh, fixed_nodes, formulation, volumetric, &[])
    }

    /// [`Model::try_new`] with cables (see [`DofLayout`] for where their free nodes go).
    pub fn try_new_with_cables(
        mesh: Arc<TetMesh>,
        fixed_nodes: &[i64],
        formulation: Formulation,
        volumetric: Volumetric,
        cables: &[CableSpec],
    ) -> Result<Self> {
        let specs = TermSpecs {
            cables: cables.to_vec(),
        };
        Self::try_new_with_terms(mesh, fixed_nodes, formulation, volumetric, &specs)
    }

    /// [`Model::try_new`] with the terms `specs` describes beside elasticity and gravity.
    pub fn try_new_with_terms(
        mesh: Arc<TetMesh>,
        fixed_nodes: &[i64],
        formulation: Formulation,
        volumetric: Volumetric,
        specs: &TermSpecs,
    ) -> Result<Self> {
        let n = mesh.n_nodes();
        let mut fixed_set = vec![false; n];
        let mut fixed = Vec::with_capacity(fixed_nodes.len());
        for (position, &node) in fixed_nodes.iter().enumerate() {
            if node < 0 || node as usize >= n {
                return Err(Error::IndexOutOfRange {
                    param: "fixed".into(),
                    position,
                    index: node,
                    len: n,
                });
            }
            if fixed_set[node as usize] {
                return Err(Error::invalid(
                    "fixed",
                    "each node at most once",
                    format!("node {node} repeated"),
                ));
            }
            fixed_set[node as usize] = true;
            fixed.push(node as usize);
        }
        let embedded = embed(&mesh, &specs.cables)?;
        let layout = DofLayout {
            n_nodes: n,
            n_free_nodes: embedded.free_nodes.len(),
            pressures: matches!(formulation, Formulation::Mixed { .. }),
        };
        let terms = Terms::new(&mesh, &layout, formulation, volumetric, embedded, specs)?;
        let fixed_dofs = layout.fixed_dofs(&fixed);
        // The symbolic factorisation needs only the pattern: it runs beside the element plans.
        let (assembler, factor) = Assembler::new_with(&fixed_dofs, &terms.internal(), |pattern| {
            analyse_pattern(
                pattern,
                formulation,
                &layout,
                &terms,
                &fixed_dofs,
                &fixed_set,
            )
        });
        Ok(Model {
            mesh,
            fixed_nodes: fixed,
            formulation,
            layout,
            terms,
            volumetric,
            assembler,
            factor: factor?,
            hessian_scratch: Default::default(),
            symbolic_analyses: 1,
            pressure_weight: 1.0,
            constraint_weight: 1.0,
            last_extra: None,
            continuation: None,
            material_set: false,
            last_state: None,
            factor_at_solution: false,
        })
    }

    pub fn mesh(&self) -> &Arc<TetMesh> {
        &self.mesh
    }

    pub fn formulation(&self) -> Formulation {
        self.formulation
    }

    pub fn layout(&self) -> DofLayout {
        self.layout
    }

    /// The material model (Neo-Hookean with the constructor's volumetric measure until
    /// [`Model::set_material_model`] says otherwise).
    pub fn material_model(&self) -> MaterialModel {
        self.terms.elastic.material()
    }

    /// The constructor's volumetric measure: a Neo-Hookean material's unless its options say
    /// otherwise.
    pub fn volumetric(&self) -> Volumetric {
        self.volumetric
    }

    /// Whether the element kernels use a model's closed forms (Neo-Hookean: isotropic Hessian,
    /// analytic projection; on by default). Off sends every model through the general path of
    /// models without them: the same results to round-off, for tests and benchmarks.
    pub fn set_closed_forms(&mut self, on: bool) {
        self.terms.elastic.closed_forms = on;
    }

    /// Names of the material's parameters, in the order they are stored (one value per tet each).
    pub fn material_param_names(&self) -> Vec<String> {
        self.material_model().param_names()
    }

    pub fn fixed_nodes(&self) -> &[usize] {
        &self.fixed_nodes
    }

    /// Number of Newton unknowns (free displacement DOFs plus pressures).
    pub fn n_free(&self) -> usize {
        self.assembler.n_free()
    }

    /// Rest length of each segment of each cable (m), between the points the cable is attached
    /// to (a snapped point sits on the mesh, not where the user put it).
    pub fn cable_rest_lengths(&self) -> Vec<Vec<f64>> {
        (self.terms.slots.iter())
            .map(|slot| match *slot {
                CableSlot::Springs(i) => self.terms.cables.cables[i].rest_lengths.clone(),
                CableSlot::Tendon(i) => self.terms.tendons.tendons[i].rest_lengths.clone(),
            })
            .collect()
    }

    /// Where each cable point was placed (embedded, snapped, free node or anchor).
    pub fn cable_placements(&self) -> &[Vec<PointPlacement>] {
        &self.terms.placements
    }

    /// Number of cables, spring chains and tendons.
    pub fn n_cables(&self) -> usize {
        self.terms.slots.len()
    }

    /// Where cable `cable` lives, or `Err` naming it when out of range.
    pub fn cable_slot(&self, cable: usize) -> Result<CableSlot> {
        self.terms
            .slots
            .get(cable)
            .copied()
            .ok_or_else(|| Error::IndexOutOfRange {
                param: "cable".into(),
                position: 0,
                index: cable as i64,
                len: self.terms.slots.len(),
            })
    }

    /// Spring chain `cable` for modification (callers invalidate the last solution when they
    /// change it); `Err` for a tendon, naming `what` it does not have.
    fn cable_mut(&mut self, cable: usize, what: &str) -> Result<&mut crate::energy::Cable> {
        match self.cable_slot(cable)? {
            CableSlot::Springs(i) => Ok(&mut self.terms.cables.cables[i]),
            CableSlot::Tendon(_) => Err(Error::invalid(
                "cable",
                format!("a spring cable (a tendon has no {what}: set its pull or tension)"),
                format!("cable {cable}, a tendon"),
            )),
        }
    }

    /// Sets cable `cable`'s actuation alpha (> 0; 1 = rest length, < 1 = pulled).
    pub fn set_actuation(&mut self, cable: usize, actuation: f64) -> Result<()> {
        if !(actuation > 0.0 && actuation.is_finite()) {
            return Err(Error::invalid(
                "actuation",
                "alpha > 0 (1 = rest, < 1 = pulled)",
                actuation,
            ));
        }
        let target = self.cable_mut(cable, "actuation")?;
        if target.actuation != actuation {
            target.actuation = actuation;
            self.last_state = None;
        }
        Ok(())
    }

    /// Sets cable `cable`'s segment stiffness (N/m, > 0).
    pub fn set_cable_stiffness(&mut self, cable: usize, stiffness: f64) -> Result<()> {
        if !(stiffness > 0.0 && stiffness.is_finite()) {
            return Err(Error::invalid(
                "stiffness",
                "a finite stiffness > 0 N/m",
                stiffness,
            ));
        }
        let target = self.cable_mut(cable, "stiffness")?;
        if target.stiffness != stiffness {
            target.stiffness = stiffness;
            self.last_state = None;
        }
        Ok(())
    }

    /// Sets spring cable `cable`'s dashpot coefficient (N s/m, >= 0): the damping force
    /// `c dL/dt` along each segment in a simulation (statics do not see it).
    pub fn set_cable_damping(&mut self, cable: usize, damping: f64) -> Result<()> {
        if !(damping >= 0.0 && damping.is_finite()) {
            return Err(Error::invalid(
                "damping",
                "a finite dashpot coefficient >= 0 N s/m",
                damping,
            ));
        }
        let target = self.cable_mut(cable, "damping")?;
        if target.damping != damping {
            target.damping = damping;
            self.last_state = None;
        }
        Ok(())
    }

    /// Sets tendon `cable`'s command: a pull (m, shorter than its rest length) or a tension
    /// (N, >= 0). A tendon's tension from the last solve stays the next solve's starting
    /// multiplier (warm starts of a pull continuation).
    pub fn set_tendon_command(&mut self, cable: usize, command: TendonCommand) -> Result<()> {
        let CableSlot::Tendon(i) = self.cable_slot(cable)? else {
            return Err(Error::invalid(
                "cable",
                "a tendon (a spring cable is driven by its actuation alpha)",
                format!("cable {cable}, a spring cable"),
            ));
        };
        check_tendon_command(cable, command)?;
        let tendon = &mut self.terms.tendons.tendons[i];
        check_pull(cable, command, tendon.rest_length())?;
        if tendon.command != command {
            tendon.command = command;
            self.last_state = None;
        }
        Ok(())
    }

    /// Tendon `cable`'s command.
    pub fn tendon_command(&self, cable: usize) -> Result<TendonCommand> {
        match self.cable_slot(cable)? {
            CableSlot::Tendon(i) => Ok(self.terms.tendons.tendons[i].command),
            CableSlot::Springs(_) => Err(Error::invalid(
                "cable",
                "a tendon",
                format!("cable {cable}, a spring cable"),
            )),
        }
    }

    /// Sets a Neo-Hookean material (with the constructor's volumetric measure): per-tet `mu > 0`,
    /// `lambda >= 0` (`> 0` in the mixed formulation) and `density >= 0`.
    pub fn set_material(&mut self, material: &Material) -> Result<()> {
        let model = MaterialModel::NeoHookean {
            volumetric: self.volumetric,
        };
        let params = [
            ("mu".to_string(), material.mu.clone()),
            ("lambda".to_string(), material.lambda.clone()),
        ];
        self.set_material_model(model, &params, &material.density)
    }

    /// Sets the material model, its parameters by name (each one value per tet, every name of
    /// [`MaterialModel::param_names`] exactly once) and the density (kg/m^3, per tet, >= 0).
    /// Each tet's parameters are checked by the model ([`MaterialModel::try_at`]); errors name
    /// the parameter and the tet.
    pub fn set_material_model(
        &mut self,
        model: MaterialModel,
        params: &[(String, Vec<f64>)],
        density: &[f64],
    ) -> Result<()> {
        let m = self.mesh.n_tets();
        let names = model.param_names();
        if let Some((unknown, _)) = params.iter().find(|(name, _)| !names.contains(name)) {
            return Err(Error::invalid(
                "params",
                format!("the parameters {names:?} of the {} model", model.name()),
                format!("{unknown:?}"),
            ));
        }
        let mut columns = Vec::with_capacity(names.len());
        for name in &names {
            let mut given = params.iter().filter(|(n, _)| n == name);
            let (Some((_, values)), None) = (given.next(), given.next()) else {
                return Err(Error::invalid(
                    "params",
                    format!("each of {names:?} exactly once"),
                    format!(
                        "{name:?} {} times",
                        params.iter().filter(|(n, _)| n == name).count()
                    ),
                ));
            };
            columns.push(values);
        }
        let named = names
            .iter()
            .map(String::as_str)
            .zip(columns.iter().map(|c| c.as_slice()));
        for (name, values) in named.chain([("density", density)]) {
            if values.len() != m {
                return Err(Error::shape(
                    name,
                    format!("{m} values (one per tet)"),
                    format!("{}", values.len()),
                ));
            }
            check_finite(name, values)?;
        }
        let mixed = self.layout.pressures;
        let mut flat = Vec::with_capacity(m * names.len());
        let mut shear = 0.0;
        for e in 0..m {
            let start = flat.len();
            flat.extend(columns.iter().map(|c| c[e]));
            let material = model
                .try_at(&flat[start..], mixed)
                .map_err(|error| error.at_tet(e))?;
            shear += shear_modulus(&material);
        }
        if let Some(e) = density.iter().position(|&v| v < 0.0) {
            return Err(Error::invalid(
                "density",
                "density >= 0 kg/m^3",
                format!("{} at tet {e}", density[e]),
            ));
        }
        let (elastic, mass) = (&mut self.terms.elastic, &mut self.terms.mass);
        let changed =
            elastic.material() != model || elastic.params() != flat || mass.density != density;
        elastic.set_material(model, flat);
        mass.density = density.to_vec();
        let mean_shear = shear / m as f64;
        let mean_edge =
            (self.mesh.volumes().iter().sum::<f64>() / m as f64 * 6.0 * 2f64.sqrt()).cbrt();
        if mixed {
            self.pressure_weight = mean_shear / mean_edge;
        }
        self.constraint_weight = mean_shear * mean_edge;
        // New parameters make the last solution (and any factorisation at it) stale: sensitivities
        // then need a new solve rather than silently mixing old positions with new parameters.
        self.material_set = true;
        if changed {
            self.factor_at_solution = false;
            self.last_state = None;
        }
        Ok(())
    }

    /// `Err` naming `operation` until a material is set.
    fn require_material(&self, operation: &str) -> Result<()> {
        if self.material_set {
            Ok(())
        } else {
            Err(Error::invalid(
                "material",
                format!("set_material() or set_material_model() before {operation}()"),
                "no material",
            ))
        }
    }
}
