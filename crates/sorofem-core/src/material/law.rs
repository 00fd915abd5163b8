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
//! with a share of its volumetric energy that gives the rest part a stiffness against dilation
//! (see [`super::isochoric::BulkSplit`]) and any higher-order volumetric terms (e.g. Yeoh's
//! `(J - 1)^4 / d2`), or the shear part `mu/2 (I1 - 3) - mu ln J` of the compressible
//! Neo-Hookean. The standard formulation uses `W`
//! itself; the mixed formulation replaces `kappa/2 c^2` by `p c(J) - p^2 / (2 kappa)` with a
//! pressure field `p`, so `kappa` is the only volumetric parameter it sees.
//!
//! Parameters are a flat slice in the order of [`Hyperelastic::param_names`]; moduli in Pa,
//! compressibilities `d_i` in 1/Pa, exponents dimensionless. Each model has a fallible
//! constructor `try_new(params: &[f64]) -> Result<Self>` that validates the slice before any
//! work (errors name the parameter, e.g. `c10`, what was expected and what was given).

use super::neo_hookean::{j_minus_one, Response};
use super::{inverse_transpose, volumetric_tangent, Mat3, Volumetric};

/// `G = F^{-T}`, `J = det F` and `J - 1` (accurate near 1) at one `H = F - I`: computed once per
/// element by the kernels and shared with the model.
#[derive(Clone, Copy, Debug)]
pub struct VolumeState {
    pub gt: Mat3,
    pub j: f64,
    pub jm1: f64,
}

impl VolumeState {
    /// `None` when `J <= 0`.
    #[inline]
    pub fn new(h: &Mat3) -> Option<Self> {
        let (gt, j) = inverse_transpose(&(Mat3::identity() + h))?;
        Some(VolumeState {
            gt,
            j,
            jm1: j_minus_one(h),
        })
    }
}

/// A volumetric energy density `v(J)` added to `W_rest` in the same pass (Pa): its value, the
/// slope `v'(J)` the stress takes (`dv/dF = v' J F^{-T}`) and the slope and curvature the tangent
/// takes (`dP/dF = (v'' J^2 + v' J) G (x) G - v' J G_il G_kj`, see [`volumetric_tangent`]). The
/// tangent's slope differs from the stress's when the standard formulation's Hessian is taken at
/// a pressure iterate; the mixed formulation's `p c(J)` is such a term too.
#[derive(Clone, Copy, Debug, Default)]
pub struct VolumetricTerm {
    pub energy: f64,
    pub stress_slope: f64,
    pub tangent_slope: f64,
    pub tangent_curvature: f64,
}

impl VolumetricTerm {
    /// This term plus `kappa/2 (J - 1)^2` (`x = J - 1`): a quadratic in `J - 1` with slope
    /// `kappa x` and curvature `kappa`.
    pub fn plus_quadratic(self, kappa: f64, x: f64) -> Self {
        VolumetricTerm {
            energy: self.energy + 0.5 * kappa * x * x,
            stress_slope: self.stress_slope + kappa * x,
            tangent_slope: self.tangent_slope + kappa * x,
            tangent_curvature: self.tangent_curvature + kappa,
        }
    }

    /// `kappa/2 c(J)^2` exactly, from `(c, c', c'')`.
    pub fn quadratic(kappa: f64, (c, dc, d2c): (f64, f64, f64)) -> Self {
        let slope = kappa * c * dc;
        VolumetricTerm {
            energy: 0.5 * kappa * c * c,
            stress_slope: slope,
            tangent_slope: slope,
            tangent_curvature: kappa * (dc * dc + c * d2c),
        }
    }
}

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

    /// `W_rest + v(J)` with its stress and, when asked, tangent, for a volumetric term `v` (see
    /// [`VolumetricTerm`]) at the state `volume` of the same `H`: what the element kernels call, so
    /// that a model can fold `v` into the pass that builds its own tangent (Yeoh and Mooney-Rivlin
    /// do; by default the rest response plus [`volumetric_tangent`]). `None` when `J <= 0`.
    fn rest_with_volumetric(
        &self,
        h: &Mat3,
        volume: &VolumeState,
        volumetric: &VolumetricTerm,
        with_tangent: bool,
    ) -> Option<Response> {
        let mut r = self.rest(h, with_tangent)?;
        r.energy += volumetric.energy;
        r.stress += (volumetric.stress_slope * volume.j) * volume.gt;
        if let Some(t) = r.tangent.as_mut() {
            *t += volumetric_tangent(
                &volume.gt,
                volume.j,
                volumetric.tangent_slope,
                volumetric.tangent_curvature,
            );
        }
        Some(r)
    }

    /// The full density `W = W_rest + kappa/2 c(J)^2` with stress and tangent (tests,
    /// homogeneous-deformation curves, output stresses). `None` when `J <= 0`.
    fn response(&self, h: &Mat3, with_tangent: bool) -> Option<Response> {
        let volume = VolumeState::new(h)?;
        let measure = self.volumetric().measure_near_one(volume.jm1);
        let volumetric = VolumetricTerm::quadratic(self.bulk(), measure);
        self.rest_with_volumetric(h, &volume, &volumetric, with_tangent)
    }
}
