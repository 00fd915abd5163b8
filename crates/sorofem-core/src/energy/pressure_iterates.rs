//! Element pressure iterates of the standard formulation: the pressures `p_e` at which Newton
//! builds the volumetric part of the Hessian (see [`super::ElasticTerm::advance_pressures`]),
//! and the linearisation of `kappa c(J)` that moves them.

use crate::material::Mat3;
use std::sync::atomic::{AtomicU64, Ordering};

/// One tet's pressure `kappa c(J)` (Pa) at a state and its derivative with respect to the
/// displacement gradient `H = F - I`: `dp/dH = kappa c'(J) J F^{-T}` (Pa, row-major), so that
/// `dp = dp/dH : dH` with `dH = sum_a du_a g_a^T`.
#[derive(Clone, Copy, Debug)]
pub struct LinearisedPressure {
    pub value: f64,
    pub gradient: [f64; 9],
}

impl LinearisedPressure {
    /// From the quantities an element kernel has at hand: `kappa` (Pa), `F^{-T}`, `J` and
    /// `(c(J), c'(J))`. An inverted tet (`J <= 0`) gets a NaN value, which
    /// [`super::ElasticTerm::advance_pressures`] leaves alone.
    pub(crate) fn new(kappa: f64, gt: &Mat3, j: f64, c: f64, dc: f64) -> Self {
        if !(j > 0.0) {
            return LinearisedPressure {
                value: f64::NAN,
                gradient: [0.0; 9],
            };
        }
        let scale = kappa * dc * j;
        LinearisedPressure {
            value: kappa * c,
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

    /// Number of tets.
    pub fn n_tets(&self) -> usize {
        self.cells.len()
    }

    pub fn get(&self, e: usize) -> LinearisedPressure {
        let cell = &self.cells[e];
        let value = |k: usize| f64::from_bits(cell[k].load(Ordering::Relaxed));
        LinearisedPressure {
            value: value(0),
            gradient: std::array::from_fn(|k| value(k + 1)),
        }
    }

    pub(crate) fn set(&self, e: usize, linearised: &LinearisedPressure) {
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
