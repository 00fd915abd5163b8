//! IPC's log barrier on squared distances and its adaptive stiffness.
//!
//! With `d` a squared distance (m^2) and `dhat2 = dhat^2` the squared activation distance,
//! `b(d) = -(d - dhat2)^2 ln(d / dhat2)` for `0 < d < dhat2` and 0 beyond: it grows without bound
//! as `d -> 0` and is C2 at `dhat2` (value, slope and curvature vanish there). The contact energy
//! is `kappa sum_k b(d_k)` over the active stencils, with `kappa` in J/m^4.

/// `b(d)` (m^4); `+inf` for `d <= 0` (touching or intersecting), 0 for `d >= dhat2`.
pub fn barrier(d: f64, dhat2: f64) -> f64 {
    if d <= 0.0 {
        f64::INFINITY
    } else if d < dhat2 {
        -(d - dhat2).powi(2) * (d / dhat2).ln()
    } else {
        0.0
    }
}

/// `db/dd = -2 (d - dhat2) ln(d / dhat2) - (d - dhat2)^2 / d` (m^2), `<= 0`; 0 for `d >= dhat2`.
/// Only meaningful for `d > 0`.
pub fn barrier_gradient(d: f64, dhat2: f64) -> f64 {
    if d < dhat2 {
        let gap = d - dhat2;
        -2.0 * gap * (d / dhat2).ln() - gap * gap / d
    } else {
        0.0
    }
}

/// `d2b/dd2 = -2 ln(d / dhat2) - 4 (d - dhat2) / d + (d - dhat2)^2 / d^2` (dimensionless), `> 0`
/// below `dhat2`; 0 for `d >= dhat2`. Only meaningful for `d > 0`.
pub fn barrier_hessian(d: f64, dhat2: f64) -> f64 {
    if d < dhat2 {
        let ratio = (d - dhat2) / d;
        -2.0 * (d / dhat2).ln() - 4.0 * ratio + ratio * ratio
    } else {
        0.0
    }
}

/// The normal force magnitude of one stencil, `lambda = -kappa db/dd * 2 sqrt(d)` (N): the
/// derivative of the stencil's energy with respect to the (unsquared) distance, as IPC's
/// friction uses it.
pub fn normal_force_magnitude(d: f64, dhat2: f64, stiffness: f64) -> f64 {
    -stiffness * barrier_gradient(d, dhat2) * 2.0 * d.sqrt()
}

/// Admissible range `[min, max]` of the barrier stiffness (J/m^4).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StiffnessBounds {
    pub min: f64,
    pub max: f64,
}

impl StiffnessBounds {
    /// IPC's range: `min = scale m / (4 d0 b''(d0))` with `d0 = (1e-8 diagonal)^2` (or
    /// `dhat^2 / 2` if that is larger than `dhat^2`), and `max = 100 min`.
    ///
    /// - `bbox_diagonal`: diagonal of the bounding box of the scene (m), > 0.
    /// - `dhat`: activation distance (m), > 0.
    /// - `average_mass`: a representative nodal mass `m` (kg), e.g. the body's mass over its
    ///   nodes.
    /// - `scale`: IPC's `1e11` (1/s^2).
    pub fn new(bbox_diagonal: f64, dhat: f64, average_mass: f64, scale: f64) -> Self {
        let dhat2 = dhat * dhat;
        let mut d0 = (1e-8 * bbox_diagonal).powi(2);
        if d0 >= dhat2 {
            d0 = 0.5 * dhat2;
        }
        let min = scale * average_mass / (4.0 * d0 * barrier_hessian(d0, dhat2));
        StiffnessBounds {
            min,
            max: 100.0 * min,
        }
    }
}

/// IPC's initial barrier stiffness: the `kappa` that best balances the other forces,
/// `argmin_kappa |grad_energy + kappa grad_barrier|^2 = -(grad_barrier . grad_energy) /
/// |grad_barrier|^2`, clamped to `bounds`; `bounds.min` when no barrier is active.
///
/// - `grad_energy`: gradient of the energy without contact (N), over the free DOFs.
/// - `grad_barrier`: gradient of `sum_k b(d_k)` (unit stiffness, m^3), same DOFs.
pub fn initial_barrier_stiffness(
    grad_energy: &[f64],
    grad_barrier: &[f64],
    bounds: StiffnessBounds,
) -> f64 {
    balanced_barrier_stiffness(grad_energy, grad_barrier)
        .map_or(bounds.min, |kappa| kappa.clamp(bounds.min, bounds.max))
}

/// The unclamped balance of [`initial_barrier_stiffness`], `-(grad_barrier . grad_energy) /
/// |grad_barrier|^2` (J/m^4); `None` without a barrier gradient.
pub fn balanced_barrier_stiffness(grad_energy: &[f64], grad_barrier: &[f64]) -> Option<f64> {
    let norm2: f64 = grad_barrier.iter().map(|g| g * g).sum();
    if norm2 == 0.0 {
        return None;
    }
    let dot: f64 = grad_barrier
        .iter()
        .zip(grad_energy)
        .map(|(b, e)| b * e)
        .sum();
    Some(-dot / norm2)
}

/// IPC's stiffness update, once per Newton iteration: when the minimum squared distance is
/// below `(epsilon_scale diagonal)^2` and has shrunk since the previous iteration, the barrier is
/// struggling and `kappa` doubles (up to `max`); otherwise it is kept.
///
/// - `previous_min_d2`, `min_d2`: minimum squared distances (m^2) at the previous and current
///   iterates.
/// - `epsilon_scale`: IPC's `1e-9`, relative to `bbox_diagonal` (m).
pub fn update_barrier_stiffness(
    previous_min_d2: f64,
    min_d2: f64,
    stiffness: f64,
    max: f64,
    bbox_diagonal: f64,
    epsilon_scale: f64,
) -> f64 {
    let threshold = (epsilon_scale * bbox_diagonal).powi(2);
    if previous_min_d2 < threshold && min_d2 < threshold && min_d2 < previous_min_d2 {
        (2.0 * stiffness).min(max)
    } else {
        stiffness
    }
}
