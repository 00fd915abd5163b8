//! The registry of a model's energy terms: the one place that lists them. Assembly, Newton,
//! reactions, dynamics and sensitivities all iterate these lists, so a new term is added here
//! (a field, its construction, one line in each list it belongs to) and nowhere else in the
//! model.

use super::statics::Loads;
use crate::contact::ContactTerm;
use crate::energy::{
    CableTerm, ElasticTerm, GravityTerm, LumpedMass, NodalForceTerm, ParamTerm, PointGravityTerm,
    Term,
};

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
    pub mass: LumpedMass,
    pub contact: Option<ContactTerm>,
}

/// The loads of one solve as terms. They are linear in the displacements, so they enter Newton
/// as one load vector (scaled by the load factor) rather than through the assembler's passes.
pub(crate) struct LoadTerms<'a> {
    pub gravity: GravityTerm<'a>,
    pub point_gravity: PointGravityTerm<'a>,
    pub forces: NodalForceTerm,
}

impl Terms {
    /// The terms whose sum is the internal energy, in the assembler's order (the assembler is
    /// built from this list and every evaluation passes it again).
    pub fn internal(&self) -> [&dyn Term; 2] {
        [&self.elastic, &self.cables]
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
    pub fn parameterised<'a>(&'a self, loads: &'a LoadTerms<'a>) -> [&'a dyn ParamTerm; 4] {
        [
            &self.elastic,
            &loads.gravity,
            &loads.point_gravity,
            &self.cables,
        ]
    }
}

impl LoadTerms<'_> {
    /// The load terms, in the order their contributions are summed.
    pub fn list(&self) -> [&dyn Term; 3] {
        [&self.gravity, &self.point_gravity, &self.forces]
    }
}
