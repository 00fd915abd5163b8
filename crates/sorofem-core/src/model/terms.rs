//! The registry of a model's energy terms: the one place that lists them. Assembly, Newton,
//! reactions, dynamics and sensitivities all iterate these lists, so a new term is added here
//! (its input in [`TermSpecs`], a field of [`Terms`], its construction, one line in each list it
//! belongs to) and nowhere else in the model.

use super::layout::DofLayout;
use super::statics::Loads;
use super::Formulation;
use crate::cables::{CableSlot, CableSpec, EmbeddedCables, PointPlacement};
use crate::contact::ContactTerm;
use crate::energy::{
    CableTerm, ElasticTerm, Formulation as ElementFormulation, GravityTerm, LumpedMass,
    NodalForceTerm, ParamTerm, PointGravityTerm, TendonTerm, Term,
};
use crate::error::Result;
use crate::material::Volumetric;
use crate::mesh::TetMesh;
use std::sync::Arc;

/// What a model is built with beyond its mesh, supports and material: the input of every
/// optional term.
#[derive(Clone, Debug, Default)]
pub struct TermSpecs {
    pub cables: Vec<CableSpec>,
}

/// Every energy term of a model, and the lumped mass that gravity and inertia act on.
///
/// Contact is a term whose stencils change with the positions, so the assembler's fixed element
/// plans cannot hold it: the Newton system (`system.rs`) adds it after the assembler's pass,
/// into the same gradient and Hessian values (see [`ContactTerm::add_to`]), and reactions and
/// sensitivities add it where they add the internal terms. Its parameters (`dhat`, the barrier
/// stiffness) are not among the sensitivities' parameters.
pub(crate) struct Terms {
    pub elastic: ElasticTerm,
    pub cables: CableTerm,
    /// Tendons at their current tensions (commands, or the solver's multipliers).
    pub tendons: TendonTerm,
    pub mass: LumpedMass,
    /// Contact with obstacles (and the body itself), set by `Model::set_contact`.
    pub contact: Option<ContactTerm>,
    /// Where each cable point was placed.
    pub placements: Vec<Vec<PointPlacement>>,
    /// Where each cable (in the order given) lives: spring chain or tendon.
    pub slots: Vec<CableSlot>,
}

/// The loads of one solve as terms. They are linear in the displacements, so they enter Newton
/// as one load vector (scaled by the load factor) rather than through the assembler's passes.
pub(crate) struct LoadTerms<'a> {
    pub gravity: GravityTerm<'a>,
    pub point_gravity: PointGravityTerm<'a>,
    pub forces: NodalForceTerm,
}

impl Terms {
    /// The terms of a model on `mesh` with DOFs `layout`: Neo-Hookean elasticity (parameters
    /// set later), the cables `embedded` from `specs.cables` (their free nodes already in
    /// `layout`), and the lumped mass (densities set later).
    pub fn new(
        mesh: &Arc<TetMesh>,
        layout: &DofLayout,
        formulation: Formulation,
        volumetric: Volumetric,
        embedded: EmbeddedCables,
        _specs: &TermSpecs,
    ) -> Result<Self> {
        let n_tets = mesh.n_tets();
        let n_cables = embedded.slots.len();
        let index_of = |springs: bool| -> Vec<usize> {
            (embedded.slots.iter().enumerate())
                .filter(|(_, slot)| matches!(slot, CableSlot::Springs(_)) == springs)
                .map(|(c, _)| c)
                .collect()
        };
        let (spring_index, tendon_index) = (index_of(true), index_of(false));
        let element_formulation = match formulation {
            Formulation::Standard => ElementFormulation::Standard,
            Formulation::Mixed { mass } => ElementFormulation::Mixed {
                pressure_offset: layout.n_displacement(),
                mass,
            },
        };
        Ok(Terms {
            elastic: ElasticTerm::neo_hookean(
                mesh.clone(),
                &vec![1.0; n_tets],
                &vec![1.0; n_tets],
                volumetric,
                element_formulation,
            ),
            cables: CableTerm::with_param_index(embedded.cables, spring_index, n_cables),
            tendons: TendonTerm::new(embedded.tendons, tendon_index, n_cables),
            mass: LumpedMass {
                mesh: mesh.clone(),
                density: vec![0.0; n_tets],
                points: (embedded.free_nodes.iter().enumerate())
                    .map(|(i, &(_, mass))| (layout.free_node(i), mass))
                    .collect(),
            },
            contact: None,
            placements: embedded.placements,
            slots: embedded.slots,
        })
    }

    /// The terms whose sum is the internal energy, in the assembler's order (the assembler is
    /// built from this list and every evaluation passes it again).
    pub fn internal(&self) -> [&dyn Term; 3] {
        [&self.elastic, &self.cables, &self.tendons]
    }

    /// The loads of `loads` as terms (gravity on the tets and the free cable nodes, nodal forces).
    pub fn loads<'a>(&'a self, loads: &Loads) -> LoadTerms<'a> {
        LoadTerms {
            gravity: GravityTerm {
                mass: &self.mass,
                gravity: loads.gravity,
            },
            point_gravity: PointGravityTerm {
                mass: &self.mass,
                gravity: loads.gravity,
            },
            forces: NodalForceTerm {
                nodes: loads.nodal_forces.iter().map(|f| f.0).collect(),
                forces: loads.nodal_forces.iter().map(|f| f.1).collect(),
            },
        }
    }

    /// Every term with parameters, internal and external: what sensitivities differentiate.
    pub fn parameterised<'a>(&'a self, loads: &'a LoadTerms<'a>) -> [&'a dyn ParamTerm; 5] {
        [
            &self.elastic,
            &loads.gravity,
            &loads.point_gravity,
            &self.cables,
            &self.tendons,
        ]
    }
}

impl LoadTerms<'_> {
    /// The load terms, in the order their contributions are summed.
    pub fn list(&self) -> [&dyn Term; 3] {
        [&self.gravity, &self.point_gravity, &self.forces]
    }
}
