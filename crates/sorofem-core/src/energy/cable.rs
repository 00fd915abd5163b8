//! Cables: chains of unilateral springs between material points, free nodes or world anchors.
//!
//! Segment k joins points `y_k` and `y_{k+1}` (m). Its stretch is `s = L - alpha l_k` (m), with
//! `L = |y_{k+1} - y_k|`, `l_k` the rest length and `alpha` the actuation (1: rest, < 1: pulled).
//! The energy `k psi(s)` (J, `k` the segment stiffness in N/m) is unilateral and smooth:
//!
//! ```text
//! psi(s) = 0                          s <= 0        (slack: no force)
//!        = s^3 / (6 w)                0 <= s <= w   (transition)
//!        = (s - w/2)^2 / 2 + w^2/24   s >= w        (taut: a linear spring)
//! ```
//!
//! so the tension `k psi'(s)` is C1 and rises from 0 to `k (s - w/2)` across a transition of width
//! `w = transition * l_k`. Each point is an affine function of the DOFs, `y = y0 + sum_a w_a u_a`:
//! barycentric weights of the tet that contains a material point, weight 1 on a free node's own
//! DOFs, or no DOFs for a world anchor. Gradient and Hessian are mapped through those weights
//! (`f = W^T f_y`, `K = W^T K_y W`); `K_y` is positive semi-definite because `psi'' >= 0` and
//! `psi' >= 0`.
//!
//! In time integration a segment with dashpot coefficient `c` (N s/m) also resists the rate of
//! change of its length. Implicit Euler over a step `h` from lengths `L_n` is the minimiser of the
//! incremental potential plus `c / (2 h) (L - L_n)^2` (J), whose gradient is the damping force
//! `c (L - L_n) / h dL/dy`, exactly `c dL/dt` at the end of the step. Its Hessian
//! `c / h [n n^T + (L - L_n) / L (I - n n^T)]` loses definiteness when the segment shortens; the
//! projected Hessian clamps `L - L_n` at zero.

use super::{HessianMode, ParamTerm, Term};
use nalgebra::{Matrix3, Vector3};

/// Where a cable point is: `y = offset + sum_i weights[i] * u[dof_blocks[i]]` (3-vectors).
#[derive(Clone, Debug, PartialEq)]
pub struct PointMap {
    /// Rest position for material points and free nodes (m); the fixed position of an anchor.
    pub offset: [f64; 3],
    /// First full DOF of each 3-DOF block the point depends on (`3 i` for node i).
    pub dof_blocks: Vec<usize>,
    pub weights: Vec<f64>,
}

impl PointMap {
    /// The point's position (m) given the full DOF vector `z`.
    pub fn position(&self, z: &[f64]) -> Vector3<f64> {
        let mut y = Vector3::from(self.offset);
        for (&b, &w) in self.dof_blocks.iter().zip(&self.weights) {
            y += w * Vector3::new(z[b], z[b + 1], z[b + 2]);
        }
        y
    }
}

/// One cable: its points, per-segment rest lengths (m), stiffness (N/m), actuation and
/// transition width (fraction of the rest length).
#[derive(Clone, Debug)]
pub struct Cable {
    pub points: Vec<PointMap>,
    pub rest_lengths: Vec<f64>,
    pub stiffness: f64,
    pub actuation: f64,
    pub transition: f64,
    /// Dashpot coefficient per segment (N s/m); acts only within a time step.
    pub damping: f64,
}

/// `(psi, psi', psi'')` of the unilateral spring at stretch `s` with transition width `w`.
pub fn unilateral(s: f64, w: f64) -> (f64, f64, f64) {
    if s <= 0.0 {
        (0.0, 0.0, 0.0)
    } else if s <= w {
        (s * s * s / (6.0 * w), s * s / (2.0 * w), s / w)
    } else {
        let t = s - 0.5 * w;
        (0.5 * t * t + w * w / 24.0, t, 1.0)
    }
}

impl Cable {
    /// Maximum number of DOF blocks one point may touch (a tet has 4 nodes).
    pub const MAX_BLOCKS: usize = 4;

    pub fn n_segments(&self) -> usize {
        self.points.len().saturating_sub(1)
    }

    /// Current position of point `k` given the full DOF vector.
    pub fn position(&self, k: usize, z: &[f64]) -> Vector3<f64> {
        self.points[k].position(z)
    }

    /// Tension (N) of segment `k` at the full DOF vector `z`.
    pub fn tension(&self, k: usize, z: &[f64]) -> f64 {
        let length = (self.position(k + 1, z) - self.position(k, z)).norm();
        let rest = self.rest_lengths[k];
        self.stiffness * unilateral(length - self.actuation * rest, self.transition * rest).1
    }
}

/// All segments of all cables as one term. Element = segment; its stencil is the DOF blocks of
/// both endpoints, padded to `2 * MAX_BLOCKS` blocks with weight 0 (so all elements share one size).
pub struct CableTerm {
    pub cables: Vec<Cable>,
    /// (cable, segment) of each element.
    segments: Vec<(usize, usize)>,
    /// Index of each cable among all the model's cables (springs and tendons), where its
    /// parameters sit in the `cable_*` parameter blocks, and the number of those cables.
    param_index: Vec<usize>,
    n_param_cables: usize,
    /// The time step (s) and each segment's length at its start (m) while a dynamic step is
    /// being solved; `None` in static solves.
    dashpot: Option<(f64, Vec<f64>)>,
}

impl CableTerm {
    pub fn new(cables: Vec<Cable>) -> Self {
        let n = cables.len();
        Self::with_param_index(cables, (0..n).collect(), n)
    }

    /// The cables of a model that also has other cables (tendons): `param_index[c]` is cable
    /// c's index among all `n_param_cables` of them.
    pub fn with_param_index(
        cables: Vec<Cable>,
        param_index: Vec<usize>,
        n_param_cables: usize,
    ) -> Self {
        let segments = cables
            .iter()
            .enumerate()
            .flat_map(|(c, cable)| (0..cable.n_segments()).map(move |k| (c, k)))
            .collect();
        CableTerm {
            cables,
            segments,
            param_index,
            n_param_cables,
            dashpot: None,
        }
    }

    /// Starts an implicit Euler step of length `h` (s) from the full DOF vector `z`: the dashpots
    /// resist length changes from here on. [`CableTerm::end_step`] switches them off.
    pub fn begin_step(&mut self, h: f64, z: &[f64]) {
        let lengths = self
            .segments
            .iter()
            .map(|&(c, k)| {
                let cable = &self.cables[c];
                (cable.position(k + 1, z) - cable.position(k, z)).norm()
            })
            .collect();
        self.dashpot = Some((h, lengths));
    }

    pub fn end_step(&mut self) {
        self.dashpot = None;
    }

    /// Blocks and weights of both endpoints, padded: `(blocks, weights)` of length 8.
    fn endpoint_maps(&self, e: usize) -> ([Option<usize>; 8], [f64; 16]) {
        let (c, k) = self.segments[e];
        let cable = &self.cables[c];
        segment_maps(&cable.points[k], &cable.points[k + 1])
    }

    /// Both endpoints' positions from segment `e`'s local DOFs (slot s holds `z[3 s..3 s + 3]`),
    /// and the padded weights of [`CableTerm::endpoint_maps`].
    fn endpoint_positions(&self, e: usize, z: &[f64]) -> ([Vector3<f64>; 2], [f64; 16]) {
        let (c, k) = self.segments[e];
        let cable = &self.cables[c];
        let (_, weights) = self.endpoint_maps(e);
        let y = segment_positions(&cable.points[k], &cable.points[k + 1], &weights, z);
        (y, weights)
    }
}

/// The stencil of a segment from point `p0` to `p1`: the DOF blocks of both endpoints, padded to
/// `2 * MAX_BLOCKS` slots (`None` where a point has fewer), and `weights[end * 8 + slot]`, the
/// weight of slot `slot` in endpoint `end`'s position (0 for the other endpoint's slots).
pub(crate) fn segment_maps(p0: &PointMap, p1: &PointMap) -> ([Option<usize>; 8], [f64; 16]) {
    let mut blocks = [None; 8];
    let mut weights = [0.0; 16];
    for (end, point) in [p0, p1].into_iter().enumerate() {
        for (slot, (&b, &w)) in point.dof_blocks.iter().zip(&point.weights).enumerate() {
            blocks[end * 4 + slot] = Some(b);
            weights[end * 8 + end * 4 + slot] = w;
        }
    }
    (blocks, weights)
}

/// The global DOFs of a segment's stencil (24): padding slots repeat a real DOF with weight 0
/// so that every index is valid.
pub(crate) fn segment_dofs(blocks: &[Option<usize>; 8], dofs: &mut [usize]) {
    let fallback = blocks.iter().flatten().next().copied().unwrap_or(0);
    for (slot, b) in blocks.iter().enumerate() {
        let base = b.unwrap_or(fallback);
        for i in 0..3 {
            dofs[3 * slot + i] = base + i;
        }
    }
}

/// Both endpoints' positions (m) from a segment's local DOFs `z` (slot s holds
/// `z[3 s..3 s + 3]`) and the weights of [`segment_maps`].
pub(crate) fn segment_positions(
    p0: &PointMap,
    p1: &PointMap,
    weights: &[f64; 16],
    z: &[f64],
) -> [Vector3<f64>; 2] {
    let mut y = [Vector3::from(p0.offset), Vector3::from(p1.offset)];
    for (end, y_end) in y.iter_mut().enumerate() {
        for slot in 0..8 {
            let w = weights[end * 8 + slot];
            if w != 0.0 {
                *y_end += w * Vector3::new(z[3 * slot], z[3 * slot + 1], z[3 * slot + 2]);
            }
        }
    }
    y
}

impl Term for CableTerm {
    fn stencil_size(&self) -> usize {
        3 * 2 * Cable::MAX_BLOCKS
    }

    fn n_elements(&self) -> usize {
        self.segments.len()
    }

    fn element_dofs(&self, e: usize, dofs: &mut [usize]) {
        let (blocks, _) = self.endpoint_maps(e);
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
        let (c, k) = self.segments[e];
        let cable = &self.cables[c];
        let (y, weights) = self.endpoint_positions(e, z);
        let d = y[1] - y[0];
        let length = d.norm();
        let rest = cable.rest_lengths[k];
        let (psi, dpsi, d2psi) =
            unilateral(length - cable.actuation * rest, cable.transition * rest);
        let stiffness = cable.stiffness;
        // Dashpot: energy c/(2h) dL^2, force and curvature along the segment (see module docs).
        let (mut energy, mut force, mut axial, mut transverse) = (
            stiffness * psi,
            stiffness * dpsi,
            stiffness * d2psi,
            stiffness * dpsi,
        );
        if let Some((h, start_lengths)) = &self.dashpot {
            if cable.damping > 0.0 {
                let rate = cable.damping / h;
                let change = length - start_lengths[e];
                energy += 0.5 * rate * change * change;
                force += rate * change;
                axial += rate;
                transverse += rate
                    * match mode {
                        HessianMode::Exact => change,
                        HessianMode::Projected => change.max(0.0),
                    };
            }
        }
        if grad.is_none() && hess.is_none() {
            return energy;
        }
        // A zero-length taut segment has no direction; it cannot occur with alpha > 0 (s < 0).
        let n = if length > 0.0 {
            d / length
        } else {
            Vector3::zeros()
        };
        // Derivative of y1 - y0 with respect to slot s: coefficient (w1_s - w0_s) times identity.
        let coefficient: [f64; 8] = std::array::from_fn(|slot| weights[8 + slot] - weights[slot]);
        if let Some(grad) = grad {
            let f = force * n;
            for slot in 0..8 {
                for i in 0..3 {
                    grad[3 * slot + i] = coefficient[slot] * f[i];
                }
            }
        }
        if let Some(hess) = hess {
            let geometric = if length > 0.0 {
                transverse / length
            } else {
                0.0
            };
            let nn = n * n.transpose();
            let block: Matrix3<f64> = axial * nn + geometric * (Matrix3::identity() - nn);
            for a in 0..8 {
                for b in 0..8 {
                    let scale = coefficient[a] * coefficient[b];
                    for i in 0..3 {
                        for j in 0..3 {
                            hess[(3 * a + i) * 24 + 3 * b + j] = scale * block[(i, j)];
                        }
                    }
                }
            }
        }
        energy
    }
}

impl CableTerm {
    /// The position (m) of every point of every cable at the full DOF vector `z`.
    pub fn points_at(&self, z: &[f64]) -> Vec<Vec<[f64; 3]>> {
        self.cables
            .iter()
            .map(|cable| {
                (0..cable.points.len())
                    .map(|k| cable.position(k, z).into())
                    .collect()
            })
            .collect()
    }

    /// The tension (N) of every segment of every cable at the full DOF vector `z`.
    pub fn tensions_at(&self, z: &[f64]) -> Vec<Vec<f64>> {
        self.cables
            .iter()
            .map(|cable| {
                (0..cable.n_segments())
                    .map(|k| cable.tension(k, z))
                    .collect()
            })
            .collect()
    }

    /// Cable index of element (segment) `e`.
    pub fn cable_of(&self, e: usize) -> usize {
        self.segments[e].0
    }

    /// Derivatives of segment `e`'s gradient (local DOFs `z`, length 24) with respect to its
    /// cable's actuation alpha and stiffness k: `-k psi''(s) l (dL/dz)` and `psi'(s) (dL/dz)`.
    pub fn segment_param_derivatives(
        &self,
        e: usize,
        z: &[f64],
        d_actuation: &mut [f64],
        d_stiffness: &mut [f64],
    ) {
        let (c, k) = self.segments[e];
        let cable = &self.cables[c];
        let stiffness = cable.stiffness;
        debug_assert!(
            self.dashpot.is_none(),
            "parameter derivatives are for static states"
        );
        // The gradient is linear in k, so d(grad)/dk = grad / k.
        self.element(e, z, Some(d_stiffness), None, HessianMode::Exact);
        d_stiffness.iter_mut().for_each(|v| *v /= stiffness);
        let (y, weights) = self.endpoint_positions(e, z);
        let d = y[1] - y[0];
        let length = d.norm();
        let rest = cable.rest_lengths[k];
        let (_, _, d2psi) = unilateral(length - cable.actuation * rest, cable.transition * rest);
        let n = if length > 0.0 {
            d / length
        } else {
            Vector3::zeros()
        };
        let f = -stiffness * d2psi * rest * n;
        for slot in 0..8 {
            let coefficient = weights[8 + slot] - weights[slot];
            for i in 0..3 {
                d_actuation[3 * slot + i] = coefficient * f[i];
            }
        }
    }
}

impl ParamTerm for CableTerm {
    fn param_blocks(&self) -> Vec<(String, usize)> {
        let n = self.n_param_cables;
        vec![("cable_actuation".into(), n), ("cable_stiffness".into(), n)]
    }
    fn element_param_count(&self) -> usize {
        2
    }
    fn element_params(&self, e: usize, params: &mut [(usize, usize)]) {
        let c = self.param_index[self.cable_of(e)];
        params.copy_from_slice(&[(0, c), (1, c)]);
    }
    fn element_param_gradient(&self, e: usize, z: &[f64], out: &mut [f64]) {
        let (d_actuation, d_stiffness) = out.split_at_mut(self.stencil_size());
        self.segment_param_derivatives(e, z, d_actuation, d_stiffness);
    }
}
