//! Tendons: inextensible lines that slide freely through guide points embedded in the body.
//!
//! A tendon's guide points `y_0 .. y_K` are affine in the DOFs like a cable's (`y = W z`, see
//! [`super::cable`]); its length is `L(z) = sum_k |y_{k+1} - y_k|` (m). Frictionless sliding
//! means one tension `T` (N) along the whole tendon, so the force on the body is `T dL/dz`: at an
//! inner guide point `T (e_in - e_out)`, with `e` the unit vectors of the segments along the
//! tendon. Per segment of length `l_k` and direction `n_k`:
//!
//! ```text
//! dl_k/dy_{k+1} = -dl_k/dy_k = n_k,      d2l_k/dy_{k+1}^2 = (I - n_k n_k^T) / l_k   (3 x 3)
//! ```
//!
//! so `d2L` is positive semi-definite and `T d2L` too for `T >= 0`.
//!
//! The motor commands either the tension (force control: the energy `T L(z)` (J), a load like
//! gravity) or the pulled length `d` (displacement control: the unilateral constraint
//! `g(z) = L(z) - (L0 - d) <= 0` whose multiplier is `T >= 0`, with `T g = 0`; the solver owns
//! the multiplier and the active set, see `crate::model` and docs/theory.md). Either way the
//! term below writes `T L`, `T dL/dz` and `T d2L/dz2` at each tendon's current `tension`: the
//! command, or the multiplier the solver has set.

use super::cable::{segment_dofs, segment_maps, segment_positions, Cable, PointMap};
use super::{HessianMode, ParamTerm, Term};
use nalgebra::{Matrix3, Vector3};

/// What a tendon's motor commands.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TendonCommand {
    /// Pulled length `d` (m) from the rest length: `L <= L0 - d`. Negative pays the tendon out.
    Pull(f64),
    /// Tension (N, >= 0).
    Tension(f64),
}

/// One tendon: its guide points (the last one is where it is tied), the rest length of each
/// segment (m) and its command.
#[derive(Clone, Debug)]
pub struct Tendon {
    pub points: Vec<PointMap>,
    pub rest_lengths: Vec<f64>,
    pub command: TendonCommand,
    /// The tension (N) the term acts with: the command's under force control, the multiplier
    /// under displacement control.
    pub tension: f64,
}

impl Tendon {
    /// Rest length `L0` (m): the sum of the segments' rest lengths.
    pub fn rest_length(&self) -> f64 {
        self.rest_lengths.iter().sum()
    }

    pub fn n_segments(&self) -> usize {
        self.points.len().saturating_sub(1)
    }

    /// Current length `L` (m) at the full DOF vector `z`.
    pub fn length(&self, z: &[f64]) -> f64 {
        self.points
            .windows(2)
            .map(|w| (w[1].position(z) - w[0].position(z)).norm())
            .sum()
    }

    /// The pulled length `L0 - L` (m) at `z`.
    pub fn pull(&self, z: &[f64]) -> f64 {
        self.rest_length() - self.length(z)
    }

    /// Adds `scale * dL/dz` to the full-DOF vector `out`: per segment `n_k` on its end point's
    /// DOFs and `-n_k` on its start point's, through the points' weights.
    pub fn add_length_gradient(&self, z: &[f64], scale: f64, out: &mut [f64]) {
        for w in self.points.windows(2) {
            let d = w[1].position(z) - w[0].position(z);
            let length = d.norm();
            if length == 0.0 {
                continue;
            }
            let n = d * (scale / length);
            for (sign, point) in [(-1.0, &w[0]), (1.0, &w[1])] {
                for (&b, &weight) in point.dof_blocks.iter().zip(&point.weights) {
                    for i in 0..3 {
                        out[b + i] += sign * weight * n[i];
                    }
                }
            }
        }
    }
}

impl Tendon {
    /// Adds `scale * d2L/dz2 v` to the full-DOF vector `out` (`v` full DOFs too): per segment
    /// `(I - n_k n_k^T) / l_k (dy_{k+1} - dy_k)` on its end point's DOFs and its negative on
    /// its start point's, `dy = W v` through the points' weights.
    pub fn add_length_hessian_product(&self, z: &[f64], scale: f64, v: &[f64], out: &mut [f64]) {
        let moved = |point: &super::cable::PointMap| -> Vector3<f64> {
            let mut dy = Vector3::zeros();
            for (&b, &weight) in point.dof_blocks.iter().zip(&point.weights) {
                dy += weight * Vector3::new(v[b], v[b + 1], v[b + 2]);
            }
            dy
        };
        for w in self.points.windows(2) {
            let d = w[1].position(z) - w[0].position(z);
            let length = d.norm();
            if length == 0.0 {
                continue;
            }
            let n = d / length;
            let change = moved(&w[1]) - moved(&w[0]);
            let product = (change - n * n.dot(&change)) * (scale / length);
            for (sign, point) in [(-1.0, &w[0]), (1.0, &w[1])] {
                for (&b, &weight) in point.dof_blocks.iter().zip(&point.weights) {
                    for i in 0..3 {
                        out[b + i] += sign * weight * product[i];
                    }
                }
            }
        }
    }
}

/// All segments of all tendons as one term: element = segment, with the stencil of a cable
/// segment (24 DOFs). Energy `T l_k` (J), `T` the tendon's [`Tendon::tension`].
pub struct TendonTerm {
    pub tendons: Vec<Tendon>,
    /// (tendon, segment) of each element.
    segments: Vec<(usize, usize)>,
    /// Index of each tendon among all the model's cables (springs and tendons), where its
    /// parameters sit in the `cable_*` parameter blocks, and the number of those cables.
    param_index: Vec<usize>,
    n_param_cables: usize,
}

impl TendonTerm {
    /// The tendons of a model with `n_param_cables` cables in all; `param_index[t]` is tendon
    /// t's index among them.
    pub fn new(tendons: Vec<Tendon>, param_index: Vec<usize>, n_param_cables: usize) -> Self {
        let segments = tendons
            .iter()
            .enumerate()
            .flat_map(|(t, tendon)| (0..tendon.n_segments()).map(move |k| (t, k)))
            .collect();
        TendonTerm {
            tendons,
            segments,
            param_index,
            n_param_cables,
        }
    }

    /// Tendon index of element (segment) `e`.
    pub fn tendon_of(&self, e: usize) -> usize {
        self.segments[e].0
    }

    /// Cable index (among all the model's cables) of tendon `t`.
    pub fn cable_index(&self, t: usize) -> usize {
        self.param_index[t]
    }

    fn endpoints(&self, e: usize) -> (&PointMap, &PointMap) {
        let (t, k) = self.segments[e];
        let points = &self.tendons[t].points;
        (&points[k], &points[k + 1])
    }

    /// `dl_e/dz` of segment `e` at its local DOF values `z` (24), and the segment's unit
    /// direction and length.
    fn segment_gradient(&self, e: usize, z: &[f64], out: &mut [f64]) -> (Vector3<f64>, f64) {
        let (p0, p1) = self.endpoints(e);
        let (_, weights) = segment_maps(p0, p1);
        let y = segment_positions(p0, p1, &weights, z);
        let d = y[1] - y[0];
        let length = d.norm();
        // A zero-length segment has no direction: the tendon cannot pull along it.
        let n = if length > 0.0 {
            d / length
        } else {
            Vector3::zeros()
        };
        for slot in 0..8 {
            let coefficient = weights[8 + slot] - weights[slot];
            for i in 0..3 {
                out[3 * slot + i] = coefficient * n[i];
            }
        }
        (n, length)
    }
}

impl Term for TendonTerm {
    fn stencil_size(&self) -> usize {
        3 * 2 * Cable::MAX_BLOCKS
    }

    fn n_elements(&self) -> usize {
        self.segments.len()
    }

    fn element_dofs(&self, e: usize, dofs: &mut [usize]) {
        let (p0, p1) = self.endpoints(e);
        let (blocks, _) = segment_maps(p0, p1);
        segment_dofs(&blocks, dofs);
    }

    fn element(
        &self,
        e: usize,
        z: &[f64],
        grad: Option<&mut [f64]>,
        hess: Option<&mut [f64]>,
        mode: HessianMode,
    ) -> f64 {
        let tension = self.tendons[self.tendon_of(e)].tension;
        let mut gradient = [0.0; 24];
        let (n, length) = self.segment_gradient(e, z, &mut gradient);
        if let Some(grad) = grad {
            for (g, dl) in grad.iter_mut().zip(&gradient) {
                *g = tension * dl;
            }
        }
        if let Some(hess) = hess {
            // T (I - n n^T) / l between the slots, scaled by their weight differences; a
            // (momentarily) negative multiplier is clamped in the projected Hessian.
            let curvature = match mode {
                HessianMode::Exact => tension,
                HessianMode::Projected => tension.max(0.0),
            };
            let scale = if length > 0.0 {
                curvature / length
            } else {
                0.0
            };
            let block: Matrix3<f64> = scale * (Matrix3::identity() - n * n.transpose());
            let (p0, p1) = self.endpoints(e);
            let (_, weights) = segment_maps(p0, p1);
            let coefficient: [f64; 8] =
                std::array::from_fn(|slot| weights[8 + slot] - weights[slot]);
            for a in 0..8 {
                for b in 0..8 {
                    let c = coefficient[a] * coefficient[b];
                    for i in 0..3 {
                        for j in 0..3 {
                            hess[(3 * a + i) * 24 + 3 * b + j] = c * block[(i, j)];
                        }
                    }
                }
            }
        }
        tension * length
    }
}

/// Parameters: `cable_tension` (N, per cable) of force-controlled tendons, whose energy `T L`
/// has `d(grad)/dT = dL/dz`; `cable_pull` (m, per cable) enters no gradient but the constraint
/// `g = L - (L0 - d)` (`dg/dd = 1`), which sensitivities add themselves. A displacement-controlled
/// tendon's tension is a multiplier (part of the state), not a parameter.
impl ParamTerm for TendonTerm {
    fn param_blocks(&self) -> Vec<(String, usize)> {
        let n = self.n_param_cables;
        vec![("cable_tension".into(), n), ("cable_pull".into(), n)]
    }

    fn element_param_count(&self) -> usize {
        1
    }

    fn element_params(&self, e: usize, params: &mut [(usize, usize)]) {
        params[0] = (0, self.param_index[self.tendon_of(e)]);
    }

    fn element_param_gradient(&self, e: usize, z: &[f64], out: &mut [f64]) {
        match self.tendons[self.tendon_of(e)].command {
            TendonCommand::Tension(_) => {
                self.segment_gradient(e, z, out);
            }
            TendonCommand::Pull(_) => out.fill(0.0),
        }
    }
}
