//! Decoupled Mooney-Rivlin material (the Abaqus/ANSYS form).
//!
//! `W(F) = c10 (Ī1 - 3) + c01 (Ī2 - 3) + (J - 1)^2 / d1` (Pa), with `Ī1 = J^(-2/3) I1`,
//! `Ī2 = J^(-4/3) I2` (see [`super::isochoric`]); `c10`, `c01` in Pa, `d1` in 1/Pa. Small-strain
//! shear modulus `mu = 2 (c10 + c01)`, bulk modulus `kappa = 2 / d1`. In the split of
//! [`Hyperelastic`], `W_rest` is the isochoric part with the share [`BulkSplit`] of the
//! volumetric energy, and the rest of `(J - 1)^2 / d1` is the primary volumetric term.

use super::isochoric::{
    add_bar_i2_hessian, bar_i1_tangent, check_d1, check_params, BulkSplit, Kinematics,
};
use super::law::{Hyperelastic, RestParamGradient, VolumeState, VolumetricTerm};
use super::neo_hookean::Response;
use super::{Mat3, Volumetric};
use crate::error::{Error, Result};

/// Mooney-Rivlin coefficients `c10`, `c01` (Pa) and compressibility `d1` (1/Pa).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MooneyRivlin {
    pub c10: f64,
    pub c01: f64,
    pub d1: f64,
}

impl MooneyRivlin {
    /// Parameter names, in the order of [`MooneyRivlin::try_new`]'s slice.
    pub const PARAM_NAMES: [&'static str; 3] = ["c10", "c01", "d1"];

    /// From `[c10, c01, d1]`. Requires `c10 + c01 > 0` (a positive small-strain shear modulus;
    /// the individual signs are free because published fits often have `c01 < 0`, and stability
    /// at large strain is a property of the fit's range, not of the signs) and `d1 > 0` (see
    /// [`check_d1`]); every value finite.
    pub fn try_new(params: &[f64]) -> Result<Self> {
        check_params(&Self::PARAM_NAMES, params)?;
        let (c10, c01, d1) = (params[0], params[1], params[2]);
        if c10 + c01 <= 0.0 {
            return Err(Error::invalid(
                "c10",
                format!("c10 + c01 > 0 in Pa (shear modulus 2 (c10 + c01); c01 = {c01})"),
                c10,
            ));
        }
        check_d1(d1)?;
        Ok(MooneyRivlin { c10, c01, d1 })
    }

    /// The share of `(J - 1)^2 / d1` in the rest part.
    fn split(&self) -> BulkSplit {
        BulkSplit::new(2.0 * (self.c10 + self.c01), self.d1)
    }

    /// `d mu0 / d theta` and `d kappa / d theta` (`mu0 = 2 (c10 + c01)`, `kappa = 2 / d1`).
    fn moduli_gradients(&self) -> ([f64; 3], [f64; 3]) {
        ([2.0, 2.0, 0.0], [0.0, 0.0, -2.0 / (self.d1 * self.d1)])
    }

    /// `W_rest + v(J)` with stress and tangent (see [`Hyperelastic::rest_with_volumetric`]).
    fn evaluate(&self, kin: &Kinematics, extra: &VolumetricTerm, with_tangent: bool) -> Response {
        let extra = &extra.plus_quadratic(self.split().rest, kin.jm1);
        let i1 = kin.bar_i1();
        let i2 = kin.bar_i2();
        let j = kin.j;
        let tangent = with_tangent.then(|| {
            let (slope, curvature) = (extra.tangent_slope, extra.tangent_curvature);
            let vol_a = curvature * j * j + slope * j;
            let mut t = bar_i1_tangent(kin, &i1, self.c10, 0.0, vol_a, slope * j);
            add_bar_i2_hessian(kin, &i2, self.c01, &mut t);
            t
        });
        Response {
            energy: self.c10 * i1.minus_3 + self.c01 * i2.minus_3 + extra.energy,
            stress: self.c10 * i1.gradient
                + self.c01 * i2.gradient
                + (extra.stress_slope * j) * kin.g,
            tangent,
        }
    }
}

impl Hyperelastic for MooneyRivlin {
    fn param_names(&self) -> Vec<String> {
        Self::PARAM_NAMES.map(String::from).to_vec()
    }

    fn rest(&self, h: &Mat3, with_tangent: bool) -> Option<Response> {
        let kin = Kinematics::new(h)?;
        Some(self.evaluate(&kin, &VolumetricTerm::default(), with_tangent))
    }

    /// The volumetric term goes into the pass that builds the `Ī1` part of the tangent.
    fn rest_with_volumetric(
        &self,
        h: &Mat3,
        volume: &VolumeState,
        volumetric: &VolumetricTerm,
        with_tangent: bool,
    ) -> Option<Response> {
        Some(self.evaluate(&Kinematics::at(h, volume), volumetric, with_tangent))
    }

    /// `kappa - kappa_s` of [`BulkSplit`].
    fn bulk(&self) -> f64 {
        self.split().primary
    }

    fn volumetric(&self) -> Volumetric {
        Volumetric::Linear
    }

    fn rest_param_gradient(&self, h: &Mat3) -> Option<RestParamGradient> {
        let kin = Kinematics::new(h)?;
        let i1 = kin.bar_i1();
        let i2 = kin.bar_i2();
        let mut energy = vec![i1.minus_3, i2.minus_3, 0.0];
        let mut stress = vec![i1.gradient, i2.gradient, Mat3::zeros()];
        let (d_shear, d_bulk) = self.moduli_gradients();
        self.split().add_rest_param_gradient(
            &kin.volume(),
            &d_shear,
            &d_bulk,
            &mut energy,
            &mut stress,
        );
        Some(RestParamGradient { energy, stress })
    }

    fn bulk_param_gradient(&self) -> Vec<f64> {
        let (d_shear, d_bulk) = self.moduli_gradients();
        self.split().primary_gradient(&d_shear, &d_bulk)
    }
}
