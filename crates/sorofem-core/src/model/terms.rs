//! The registry of a model's energy terms: the one list that assembly, Newton, dynamics and
//! sensitivities iterate.

use crate::energy::{CableTerm, ElasticTerm, Term};

/// Every energy term of a model.
pub(crate) struct Terms {
    pub elastic: ElasticTerm,
    pub cables: CableTerm,
}

impl Terms {
    /// The terms whose sum is the internal energy, in the assembler's order (the assembler is
    /// built from this list and every evaluation passes it again).
    pub fn internal(&self) -> [&dyn Term; 2] {
        [&self.elastic, &self.cables]
    }
}
