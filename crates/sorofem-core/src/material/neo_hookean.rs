//! Compressible Neo-Hookean material.
//!
//! `psi(F) = mu/2 (I1 - 3) - mu ln J + lambda/2 c(J)^2` (J/m^3 = Pa), with `I1 = tr(F^T F)`,
//! `J = det F` and `c(J) = ln J` ([`Volumetric::Log`], the paper's model) or `c(J) = J - 1`
//! ([`Volumetric::Linear`]). The split into a shear part `psi_mu` and a volumetric part
//! `lambda/2 c^2` is what the mixed formulation replaces by `p c(J) - p^2/(2 lambda)`: as a
//! [`Hyperelastic`] model, `W_rest = psi_mu` and `kappa = lambda`.
//!
//! Its inherent `response`, `shear` and `energy_density` take F; the [`Hyperelastic`] methods
//! take `H = F - I`.

use super::{
    inverse_transpose, volumetric_tangent, Hyperelastic, Mat3, RestParamGradient, Tangent,
};
use crate::error::{Error, Result};

/// The volumetric measure `c(J)` enforced by the volumetric energy (or the mixed constraint).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Volumetric {
    /// `c(J) = ln J`, energy `lambda/2 (ln J)^2`.
    Log,
    /// `c(J) = J - 1`, energy `lambda/2 (J - 1)^2`.
    Linear,
}

impl Volumetric {
    /// `(c(J), c'(J), c''(J))`.
    pub fn measure(self, j: f64) -> (f64, f64, f64) {
        self.measure_near_one(j - 1.0)
    }

    /// [`Volumetric::measure`] from `J - 1`, accurate when J is close to 1.
    pub fn measure_near_one(self, jm1: f64) -> (f64, f64, f64) {
        let j = 1.0 + jm1;
        match self {
            Volumetric::Log => (jm1.ln_1p(), 1.0 / j, -1.0 / (j * j)),
            Volumetric::Linear => (jm1, 1.0, 0.0),
        }
    }
}

/// `det(I + H) - 1 = tr H + ((tr H)^2 - tr H^2) / 2 + det H`, free of cancellation for small H.
pub fn j_minus_one(h: &Mat3) -> f64 {
    let tr = h.trace();
    tr + 0.5 * (tr * tr - (h * h).trace()) + h.determinant()
}

/// Parameters of one element: shear modulus `mu` and Lame's first parameter `lambda`, both Pa.
#[derive(Clone, Copy, Debug)]
pub struct NeoHookean {
    pub mu: f64,
    pub lambda: f64,
    pub volumetric: Volumetric,
}

/// Value, first Piola-Kirchhoff stress (Pa) and tangent of an energy density at one F.
pub struct Response {
    pub energy: f64,
    pub stress: Mat3,
    pub tangent: Option<Tangent>,
}

/// What an element kernel needs at one `H = F - I`, from one inverse and one logarithm.
pub struct Pointwise {
    /// `psi` (Pa), or `psi_mu` alone when the volumetric part was left out.
    pub energy: f64,
    /// First Piola-Kirchhoff stress of the same energy (Pa).
    pub stress: Mat3,
    /// `F^{-T}`.
    pub gt: Mat3,
    /// `J = det F`.
    pub j: f64,
    /// `(c(J), c'(J), c''(J))` of the volumetric measure.
    pub measure: (f64, f64, f64),
}

impl NeoHookean {
    /// Parameter names, in the order of [`NeoHookean::try_new`]'s slice.
    pub const PARAM_NAMES: [&'static str; 2] = ["mu", "lambda"];

    /// From `[mu, lambda]` (Pa): `mu > 0`, `lambda >= 0` (nu = 0 is allowed), both finite.
    pub fn try_new(params: &[f64], volumetric: Volumetric) -> Result<Self> {
        let [mu, lambda] = params else {
            return Err(Error::shape(
                "params",
                "2 values: mu, lambda",
                format!("{} values", params.len()),
            ));
        };
        if !(*mu > 0.0 && mu.is_finite()) {
            return Err(Error::invalid("mu", "shear modulus > 0 Pa", mu));
        }
        if !(*lambda >= 0.0 && lambda.is_finite()) {
            return Err(Error::invalid(
                "lambda",
                "Lame lambda >= 0 Pa (0 <= nu < 0.5)",
                lambda,
            ));
        }
        Ok(NeoHookean {
            mu: *mu,
            lambda: *lambda,
            volumetric,
        })
    }

    /// Energy density and stress at `H = F - I` (with or without the volumetric part
    /// `lambda/2 c(J)^2`), plus the quantities the isotropic tangent is built from. The same
    /// values as [`NeoHookean::response_from_displacement_gradient`] and
    /// [`NeoHookean::shear_from_displacement_gradient`], for about half their cost. `None` for
    /// J <= 0.
    pub fn pointwise(&self, h: &Mat3, with_volumetric: bool) -> Option<Pointwise> {
        let (gt, j) = inverse_transpose(&(Mat3::identity() + h))?;
        let jm1 = j_minus_one(h);
        let log_j = jm1.ln_1p();
        let mu = self.mu;
        // psi_mu / mu = (tr H - (J - 1)) + |H|^2/2 + ((J - 1) - ln J): see shear_from_displacement_gradient.
        let mut energy = mu * ((h.trace() - jm1) + 0.5 * h.norm_squared() + (jm1 - log_j));
        let mut stress = mu * (h + gt * h.transpose());
        let measure = match self.volumetric {
            Volumetric::Log => {
                let inv = 1.0 / (1.0 + jm1);
                (log_j, inv, -inv * inv)
            }
            Volumetric::Linear => (jm1, 1.0, 0.0),
        };
        if with_volumetric {
            let (c, dc, _) = measure;
            energy += 0.5 * self.lambda * c * c;
            stress += (self.lambda * c * dc * j) * gt;
        }
        Some(Pointwise {
            energy,
            stress,
            gt,
            j,
            measure,
        })
    }

    /// Shear part `psi_mu = mu/2 (I1 - 3) - mu ln J`, its stress `mu (F - F^{-T})` and tangent
    /// `mu I + mu G_il G_kj` (G = F^{-T}). `None` for J <= 0.
    pub fn shear(&self, f: &Mat3, with_tangent: bool) -> Option<Response> {
        self.shear_from_displacement_gradient(&(f - Mat3::identity()), with_tangent)
    }

    /// [`NeoHookean::shear`] from the displacement gradient `H = F - I`. Written without the
    /// cancellations of `F - F^{-T}` and `ln det F` near F = I (`F - F^{-T} = H + F^{-T} H^T`,
    /// `J - 1` and `I1 - 3` expanded in H), so small strains keep full relative precision.
    pub fn shear_from_displacement_gradient(
        &self,
        h: &Mat3,
        with_tangent: bool,
    ) -> Option<Response> {
        let f = Mat3::identity() + h;
        let (g, _) = inverse_transpose(&f)?;
        let jm1 = j_minus_one(h);
        let mu = self.mu;
        // psi_mu / mu = tr H + |H|^2 / 2 - ln J = (tr H - (J - 1)) + |H|^2/2 + ((J - 1) - ln J).
        let energy = mu * ((h.trace() - jm1) + 0.5 * h.norm_squared() + (jm1 - jm1.ln_1p()));
        let stress = mu * (h + g * h.transpose());
        let tangent = with_tangent.then(|| {
            let mut t = Tangent::zeros();
            for i in 0..3 {
                for jj in 0..3 {
                    t[(3 * i + jj, 3 * i + jj)] += mu;
                    for k in 0..3 {
                        for l in 0..3 {
                            t[(3 * i + jj, 3 * k + l)] += mu * g[(i, l)] * g[(k, jj)];
                        }
                    }
                }
            }
            t
        });
        Some(Response {
            energy,
            stress,
            tangent,
        })
    }

    /// The full density `psi = psi_mu + lambda/2 c(J)^2` with stress and tangent. `None` for J <= 0.
    pub fn response(&self, f: &Mat3, with_tangent: bool) -> Option<Response> {
        self.response_from_displacement_gradient(&(f - Mat3::identity()), with_tangent)
    }

    /// [`NeoHookean::response`] from `H = F - I` (see [`NeoHookean::shear_from_displacement_gradient`]).
    pub fn response_from_displacement_gradient(
        &self,
        h: &Mat3,
        with_tangent: bool,
    ) -> Option<Response> {
        let mut r = self.shear_from_displacement_gradient(h, with_tangent)?;
        let (g, j) = inverse_transpose(&(Mat3::identity() + h))?;
        let (c, dc, d2c) = self.volumetric.measure_near_one(j_minus_one(h));
        // h(J) = lambda/2 c^2, h' = lambda c c', h'' = lambda (c'^2 + c c'').
        let dh = self.lambda * c * dc;
        let d2h = self.lambda * (dc * dc + c * d2c);
        r.energy += 0.5 * self.lambda * c * c;
        r.stress += dh * j * g;
        if let Some(t) = r.tangent.as_mut() {
            *t += volumetric_tangent(&g, j, dh, d2h);
        }
        Some(r)
    }

    /// `psi(F)` in Pa, `+inf` when the element is inverted (J <= 0).
    pub fn energy_density(&self, f: &Mat3) -> f64 {
        self.response(f, false).map_or(f64::INFINITY, |r| r.energy)
    }

    /// Cauchy stress `sigma = P F^T / J` (Pa).
    pub fn cauchy_stress(&self, f: &Mat3) -> Option<Mat3> {
        let r = self.response(f, false)?;
        Some(r.stress * f.transpose() / f.determinant())
    }

    /// Derivatives of `psi` with respect to `(mu, lambda)` at fixed F: `((I1-3)/2 - ln J, c^2/2)`.
    pub fn energy_param_gradient(&self, f: &Mat3) -> Option<[f64; 2]> {
        let (_, j) = inverse_transpose(f)?;
        let c = self.volumetric.measure(j).0;
        Some([0.5 * (f.norm_squared() - 3.0) - j.ln(), 0.5 * c * c])
    }

    /// Derivatives of `P` with respect to `(mu, lambda)`: `(F - F^{-T}, c c' J F^{-T})`.
    pub fn stress_param_gradient(&self, f: &Mat3) -> Option<[Mat3; 2]> {
        let (g, j) = inverse_transpose(f)?;
        let (c, dc, _) = self.volumetric.measure(j);
        Some([f - g, c * dc * j * g])
    }
}

impl Hyperelastic for NeoHookean {
    fn param_names(&self) -> Vec<String> {
        Self::PARAM_NAMES.map(String::from).to_vec()
    }

    /// `psi_mu`, see [`NeoHookean::shear_from_displacement_gradient`].
    fn rest(&self, h: &Mat3, with_tangent: bool) -> Option<Response> {
        self.shear_from_displacement_gradient(h, with_tangent)
    }

    fn bulk(&self) -> f64 {
        self.lambda
    }

    fn volumetric(&self) -> Volumetric {
        self.volumetric
    }

    /// `psi_mu / mu = (tr H - (J - 1)) + |H|^2/2 + ((J - 1) - ln J)` and
    /// `P_mu / mu = H + F^{-T} H^T` for mu; nothing for lambda (it is `kappa`).
    fn rest_param_gradient(&self, h: &Mat3) -> Option<RestParamGradient> {
        let (g, _) = inverse_transpose(&(Mat3::identity() + h))?;
        let jm1 = j_minus_one(h);
        Some(RestParamGradient {
            energy: vec![
                (h.trace() - jm1) + 0.5 * h.norm_squared() + (jm1 - jm1.ln_1p()),
                0.0,
            ],
            stress: vec![h + g * h.transpose(), Mat3::zeros()],
        })
    }

    fn bulk_param_gradient(&self) -> Vec<f64> {
        vec![0.0, 1.0]
    }
}

/// Von Mises equivalent stress of a Cauchy stress tensor (Pa).
pub fn von_mises(sigma: &Mat3) -> f64 {
    let s = sigma - Mat3::identity() * (sigma.trace() / 3.0);
    (1.5 * s.norm_squared()).sqrt()
}

/// Lame parameters from Young's modulus (Pa) and Poisson's ratio: `(mu, lambda)`.
pub fn lame_from_young(youngs_modulus: f64, poisson_ratio: f64) -> (f64, f64) {
    let (e, nu) = (youngs_modulus, poisson_ratio);
    (
        e / (2.0 * (1.0 + nu)),
        e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)),
    )
}
