//! What the spring cables' dashpots add to a step of the trajectory derivatives. A segment of
//! length `L` with dashpot `c` (N s/m) adds to step k's residual (see [`crate::energy::CableTerm`];
//! the step's `1 + beta_K / h` scaling and the dashpot's `h + beta_K` cancel)
//!
//! ```text
//! D_k = c / h (L(z_{k+1}) - L(z_k)) dL/dz(z_{k+1})                       (N)
//! ```
//!
//! whose Hessian in `z_{k+1}` is the cable term's own (assembled with the dashpot switched on);
//! besides it the step's residual depends on its start, `dD_k/dz_k = -c / h dL/dz(z_{k+1})
//! dL/dz(z_k)^T`, and on the coefficient, `dD_k/dc = (L(z_{k+1}) - L(z_k)) / h dL/dz(z_{k+1})`.

use crate::energy::{Cable, CableTerm};
use nalgebra::Vector3;

/// `dL/dz` of one segment as (full DOF, value) pairs (a DOF may repeat).
type LengthGradient = Vec<(usize, f64)>;

/// One damped segment between a step's start and end.
struct Segment {
    /// The cable's index among all the model's cables.
    cable: usize,
    /// `c / h` (N/m).
    rate: f64,
    /// `L(z_{k+1}) - L(z_k)` (m).
    change: f64,
    start: LengthGradient,
    end: LengthGradient,
}

/// The damped segments of step k (`z0 = z_k`, `z1 = z_{k+1}`, full DOFs).
pub(super) struct StepDashpots {
    segments: Vec<Segment>,
}

impl StepDashpots {
    /// `model_index[i]`: spring cable i's index among all the model's cables.
    pub(super) fn new(
        cables: &CableTerm,
        model_index: &[usize],
        h: f64,
        z0: &[f64],
        z1: &[f64],
    ) -> Self {
        let mut segments = Vec::new();
        for (i, cable) in cables.cables.iter().enumerate() {
            if cable.damping <= 0.0 {
                continue;
            }
            for k in 0..cable.n_segments() {
                let (l0, start) = length_gradient(cable, k, z0);
                let (l1, end) = length_gradient(cable, k, z1);
                segments.push(Segment {
                    cable: model_index[i],
                    rate: cable.damping / h,
                    change: l1 - l0,
                    start,
                    end,
                });
            }
        }
        StepDashpots { segments }
    }

    pub(super) fn is_empty(&self) -> bool {
        self.segments.is_empty()
    }

    /// Adds `scale D_k` (full DOFs) to `out`.
    pub(super) fn add_force(&self, scale: f64, out: &mut [f64]) {
        for s in &self.segments {
            scatter(&s.end, scale * s.rate * s.change, out);
        }
    }

    /// Adds `-(dD_k/dz_k)^T w = c / h dL/dz(z_k) (dL/dz(z_{k+1}) . w)` to `out` (full DOFs):
    /// the adjoint's coupling of step k to its start.
    pub(super) fn add_start_transpose(&self, w: &[f64], out: &mut [f64]) {
        for s in &self.segments {
            scatter(&s.start, s.rate * gather(&s.end, w), out);
        }
    }

    /// Adds `-(dD_k/dz_k) dz = c / h dL/dz(z_{k+1}) (dL/dz(z_k) . dz)` to `out` (full DOFs):
    /// the forward sensitivity's coupling of step k to its start.
    pub(super) fn add_start_product(&self, dz: &[f64], out: &mut [f64]) {
        for s in &self.segments {
            scatter(&s.end, s.rate * gather(&s.start, dz), out);
        }
    }

    /// Adds `w . dD_k/dc` to `per_cable[cable]` (per the model's cables).
    pub(super) fn add_damping_contraction(&self, h: f64, w: &[f64], per_cable: &mut [f64]) {
        for s in &self.segments {
            per_cable[s.cable] += s.change / h * gather(&s.end, w);
        }
    }

    /// Adds `sum_c delta[c] dD_k/dc` (delta per the model's cables, N s/m) to `out`.
    pub(super) fn add_damping_along(&self, h: f64, delta: &[f64], out: &mut [f64]) {
        for s in &self.segments {
            scatter(&s.end, delta[s.cable] * s.change / h, out);
        }
    }
}

/// Segment k's length (m) and `dL/dz` at the full DOF vector `z`: `n` on its end point's DOFs
/// and `-n` on its start point's, through the points' weights (`n` the unit direction).
fn length_gradient(cable: &Cable, k: usize, z: &[f64]) -> (f64, LengthGradient) {
    let d = cable.position(k + 1, z) - cable.position(k, z);
    let length = d.norm();
    let n = if length > 0.0 {
        d / length
    } else {
        Vector3::zeros()
    };
    let mut gradient = Vec::new();
    for (point, sign) in [(&cable.points[k], -1.0), (&cable.points[k + 1], 1.0)] {
        for (&b, &w) in point.dof_blocks.iter().zip(&point.weights) {
            for i in 0..3 {
                gradient.push((b + i, sign * w * n[i]));
            }
        }
    }
    (length, gradient)
}

fn gather(gradient: &LengthGradient, w: &[f64]) -> f64 {
    gradient.iter().map(|&(d, g)| g * w[d]).sum()
}

fn scatter(gradient: &LengthGradient, scale: f64, out: &mut [f64]) {
    for &(d, g) in gradient {
        out[d] += scale * g;
    }
}
