//! Decoupled Mooney-Rivlin material (the Abaqus/ANSYS form).
//!
//! `W(F) = c10 (Ī1 - 3) + c01 (Ī2 - 3) + (J - 1)^2 / d1` (Pa), with `Ī1 = J^(-2/3) I1`,
//! `Ī2 = J^(-4/3) I2` (see [`super::isochoric`]); `c10`, `c01` in Pa, `d1` in 1/Pa. Small-strain
//! shear modulus `mu = 2 (c10 + c01)`, bulk modulus `kappa = 2 / d1`. In the split of
//! [`Hyperelastic`], `W_rest` is the isochoric part and `kappa/2 (J - 1)^2` the volumetric one.

use super::isochoric::{add_bar_i2_hessian, bar_i1_tangent, check_d1, check_params, Kinematics};
use super::law::{Hyperelastic, RestParamGradient};
use super::neo_hookean::Response;
use super::{Mat3, Volumetric};
use crate::error::{Error, Result};

const PARAM_NAMES: [&str; 3] = ["c10", "c01", "d1"];

/// Mooney-Rivlin coefficients `c10`, `c01` (Pa) and compressibility `d1` (1/Pa).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MooneyRivlin {
    pub c10: f64,
    pub c01: f64,
    pub d1: f64,
}

impl MooneyRivlin {
    /// From `[c10, c01, d1]`. Requires `c10 + c01 > 0` (a positive small-strain shear modulus;
    /// the individual signs are free because published fits often have `c01 < 0`, and stability
    /// at large strain is a property of the fit's range, not of the signs) and `d1 > 0` (see
    /// [`check_d1`]); every value finite.
    pub fn try_new(params: &[f64]) -> Result<Self> {
        check_params(&PARAM_NAMES, params)?;
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
}

impl Hyperelastic for MooneyRivlin {
    fn param_names(&self) -> Vec<String> {
        PARAM_NAMES.iter().map(|s| s.to_string()).collect()
    }

    fn rest(&self, h: &Mat3, with_tangent: bool) -> Option<Response> {
        let kin = Kinematics::new(h)?;
        let i1 = kin.bar_i1();
        let i2 = kin.bar_i2();
        let tangent = with_tangent.then(|| {
            let mut t = bar_i1_tangent(&kin, &i1, self.c10, 0.0, 0.0, 0.0);
            add_bar_i2_hessian(&kin, &i2, self.c01, &mut t);
            t
        });
        Some(Response {
            energy: self.c10 * i1.minus_3 + self.c01 * i2.minus_3,
            stress: self.c10 * i1.gradient + self.c01 * i2.gradient,
            tangent,
        })
    }

    fn bulk(&self) -> f64 {
        2.0 / self.d1
    }

    fn volumetric(&self) -> Volumetric {
        Volumetric::Linear
    }

    fn rest_param_gradient(&self, h: &Mat3) -> Option<RestParamGradient> {
        let kin = Kinematics::new(h)?;
        let i1 = kin.bar_i1();
        let i2 = kin.bar_i2();
        Some(RestParamGradient {
            energy: vec![i1.minus_3, i2.minus_3, 0.0],
            stress: vec![i1.gradient, i2.gradient, Mat3::zeros()],
        })
    }

    fn bulk_param_gradient(&self) -> Vec<f64> {
        vec![0.0, 0.0, -2.0 / (self.d1 * self.d1)]
    }
}
