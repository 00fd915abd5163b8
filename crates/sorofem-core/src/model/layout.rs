//! Where each unknown lives in the full DOF vector, and the elimination order of the mixed
//! saddle-point system.

use std::ops::Range;

/// The full DOF vector: `3 n` node displacements (node-major, DOF `3 i + k` is coordinate `k` of
/// node `i`), then `3 f` displacements of the free cable nodes, then (mixed formulation) `n`
/// nodal pressures. Displacements are from the rest shape (m), pressures in Pa.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DofLayout {
    pub n_nodes: usize,
    pub n_free_nodes: usize,
    /// Whether nodal pressures follow the displacements (mixed formulation).
    pub pressures: bool,
}

impl DofLayout {
    /// Displacement DOFs of mesh nodes and free cable nodes: `3 (n + f)`, the pressures' offset.
    pub fn n_displacement(&self) -> usize {
        3 * self.n_nodes + 3 * self.n_free_nodes
    }

    pub fn n_full(&self) -> usize {
        self.n_displacement() + if self.pressures { self.n_nodes } else { 0 }
    }

    /// First full DOF of free cable node `i`.
    pub fn free_node(&self, i: usize) -> usize {
        3 * (self.n_nodes + i)
    }

    /// Full DOF of the first nodal pressure; `None` without pressures.
    pub fn pressure_offset(&self) -> Option<usize> {
        self.pressures.then(|| self.n_displacement())
    }

    /// The DOFs after the mesh nodes' displacements (free cable nodes, pressures): the part of
    /// an equilibrium a warm start carries over beside the node positions.
    pub fn extra(&self) -> Range<usize> {
        3 * self.n_nodes..self.n_full()
    }

    /// `true` for the three displacement DOFs of every fixed node.
    pub fn fixed_dofs(&self, fixed_nodes: &[usize]) -> Vec<bool> {
        let mut fixed = vec![false; self.n_full()];
        for &node in fixed_nodes {
            fixed[3 * node..3 * node + 3].fill(true);
        }
        fixed
    }
}

/// Elimination order of the mixed saddle-point system: nodes in fill-reducing (AMD) order, each
/// node's free displacements before its pressure, and the pressures of fixed nodes (which couple
/// to no displacement of their own) last. Every pressure pivot then carries `G K^{-1} G^T` and
/// not just the compliance `C = M_p / kappa`, which vanishes as nu -> 0.5.
///
/// `free_of_full[d]`: free index of full DOF `d` (`None` when fixed); `node_order`: the mesh
/// nodes in elimination order; `fixed[i]`: whether node `i` is fixed.
pub(crate) fn saddle_point_order(
    layout: &DofLayout,
    free_of_full: &[Option<usize>],
    node_order: &[usize],
    fixed: &[bool],
) -> Vec<usize> {
    let n = layout.n_nodes;
    let pressure_offset = layout.n_displacement();
    let mut order = Vec::with_capacity(free_of_full.len());
    // Free cable nodes carry no pressure: eliminate them first, like any displacement.
    order.extend((3 * n..pressure_offset).filter_map(|d| free_of_full[d]));
    for &node in node_order {
        for d in 3 * node..3 * node + 3 {
            order.extend(free_of_full[d]);
        }
        if !fixed[node] {
            order.extend(free_of_full[pressure_offset + node]);
        }
    }
    for node in (0..n).filter(|&i| fixed[i]) {
        order.extend(free_of_full[pressure_offset + node]);
    }
    order
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn free_cable_nodes_sit_between_node_displacements_and_pressures() {
        let layout = DofLayout {
            n_nodes: 5,
            n_free_nodes: 2,
            pressures: true,
        };
        assert_eq!(layout.n_displacement(), 21);
        assert_eq!(layout.free_node(1), 18);
        assert_eq!(layout.pressure_offset(), Some(21));
        assert_eq!(layout.n_full(), 26);
        assert_eq!(layout.extra(), 15..26);
        let standard = DofLayout {
            pressures: false,
            ..layout
        };
        assert_eq!((standard.n_full(), standard.pressure_offset()), (21, None));
    }
}
