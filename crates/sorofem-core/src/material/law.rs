//! The interface every hyperelastic model implements: one file per model, pure functions of the
//! displacement gradient `H = F - I` and of named parameters; the element kernels, projection,
//! assembly and sensitivities are shared.
//!
//! Every model is written as the split
//!
//! ```text
//! W(F) = W_rest(F) + kappa/2 c(J)^2        (J/m^3 = Pa)
//! ```
//!
//! where `kappa/2 c(J)^2` is the model's primary volumetric term (`kappa` in Pa, `c` the
//! [`Volumetric`] measure) and `W_rest` everything else: the isochoric part of a decoupled model
//! (plus any higher-order volumetric terms, e.g. Yeoh's `(J - 1)^4 / d2`), or the shear part
//! `mu/2 (I1 - 3) - mu ln J` of the compressible Neo-Hookean. The standard formulation uses `W`
//! itself; the mixed formulation replaces `kappa/2 c^2` by `p c(J) - p^2 / (2 kappa)` with a
//! pressure field `p`, so `kappa` is the only volumetric parameter it sees.
//!
//! Parameters are a flat slice in the order of [`Hyperelastic::param_names`]; moduli in Pa,
//! compressibilities `d_i` in 1/Pa, exponents dimensionless. Each model has a fallible
//! constructor `try_new(params: &[f64]) -> Result<Self>` that validates the slice before any
//! work (errors name the parameter, e.g. `c10`, what was expected and what was given).

use super::neo_hookean::Response;
use super::{volumetric_tangent, Mat3, Volumetric};

/// Derivatives of the rest part with respect to each parameter, at fixed F:
/// `energy[k] = dW_rest/dtheta_k` (Pa per unit of theta_k) and `stress[k] = dP_rest/dtheta_k`.
#[derive(Clone, Debug, Default)]
pub struct RestParamGradient {
    pub energy: Vec<f64>,
    pub stress: Vec<Mat3>,
}

/// A hyperelastic model at one set of parameter values.
pub trait Hyperelastic {
    /// Parameter names in slice order, e.g. `["c10", "c01", "d1"]`.
    fn param_names(&self) -> Vec<String>;

    /// `W_rest`, its first Piola-Kirchhoff stress `P_rest = dW_rest/dF` (Pa) and, when asked,
    /// its tangent `dP_rest/dF` (9x9, see [`super::Tangent`]) at `H = F - I`. `None` when
    /// `J = det F <= 0`. Written in H so that small strains keep full relative precision.
    fn rest(&self, h: &Mat3, with_tangent: bool) -> Option<Response>;

    /// `kappa` (Pa) of the primary volumetric term `kappa/2 c(J)^2`.
    fn bulk(&self) -> f64;

    /// The measure `c(J)` of the primary volumetric term.
    fn volumetric(&self) -> Volumetric;

    /// [`RestParamGradient`] at `H = F - I`; `None` when `J <= 0`.
    fn rest_param_gradient(&self, h: &Mat3) -> Option<RestParamGradient>;

    /// `d kappa / d theta_k` for every parameter (Pa per unit of theta_k).
    fn bulk_param_gradient(&self) -> Vec<f64>;

    /// The full density `W = W_rest + kappa/2 c(J)^2` with stress and tangent (tests,
    /// homogeneous-deformation curves, output stresses). `None` when `J <= 0`.
    fn response(&self, h: &Mat3, with_tangent: bool) -> Option<Response> {
        let mut r = self.rest(h, with_tangent)?;
        let (gt, j) = super::inverse_transpose(&(Mat3::identity() + h))?;
        let (c, dc, d2c) = self
            .volumetric()
            .measure_near_one(super::neo_hookean::j_minus_one(h));
        let kappa = self.bulk();
        // h(J) = kappa/2 c^2, h' = kappa c c', h'' = kappa (c'^2 + c c'').
        let dh = kappa * c * dc;
        let d2h = kappa * (dc * dc + c * d2c);
        r.energy += 0.5 * kappa * c * c;
        r.stress += dh * j * gt;
        if let Some(t) = r.tangent.as_mut() {
            *t += volumetric_tangent(&gt, j, dh, d2h);
        }
        Some(r)
    }
}
