//! Decoupled Yeoh material (the Abaqus/ANSYS form).
//!
//! `W(F) = sum_{i=1..3} c_i0 (Ī1 - 3)^i + sum_{i=1..3} (J - 1)^(2i) / d_i` (Pa), with
//! `Ī1 = J^(-2/3) I1` (see [`super::isochoric`]); `c_i0` in Pa, `d_i` in 1/Pa, and `d2 = 0` or
//! `d3 = 0` meaning that term is absent. Small-strain shear modulus `mu = 2 c10`, bulk modulus
//! `kappa = 2 / d1`. In the split of [`Hyperelastic`], `kappa/2 (J - 1)^2` is the primary
//! volumetric term and `W_rest` holds the isochoric part and the `d2`, `d3` terms.

use super::isochoric::{bar_i1_tangent, check_d1, check_params, Kinematics};
use super::law::{Hyperelastic, RestParamGradient};
use super::neo_hookean::Response;
use super::{Mat3, Volumetric};
use crate::error::{Error, Result};

const PARAM_NAMES: [&str; 6] = ["c10", "c20", "c30", "d1", "d2", "d3"];

/// Yeoh coefficients `c10`, `c20`, `c30` (Pa) and compressibilities `d1`, `d2`, `d3` (1/Pa).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Yeoh {
    pub c10: f64,
    pub c20: f64,
    pub c30: f64,
    pub d1: f64,
    pub d2: f64,
    pub d3: f64,
}

/// `1/d` for a higher-order compressibility, 0 for an absent term (`d = 0`).
fn inverse_or_absent(d: f64) -> f64 {
    if d == 0.0 {
        0.0
    } else {
        1.0 / d
    }
}

impl Yeoh {
    /// From `[c10, c20, c30, d1, d2, d3]`. Requires `c10 > 0` (the small-strain shear modulus is
    /// `2 c10`); `c20`, `c30` of any sign (fits commonly give `c20 < 0` for the softening at
    /// moderate strain); `d1 > 0` (see [`check_d1`]); `d2, d3 >= 0` with 0 meaning no term
    /// (a negative one would make `(J - 1)^(2i) / d_i` unbounded below); every value finite.
    pub fn try_new(params: &[f64]) -> Result<Self> {
        check_params(&PARAM_NAMES, params)?;
        let [c10, c20, c30, d1, d2, d3] = std::array::from_fn(|k| params[k]);
        if c10 <= 0.0 {
            return Err(Error::invalid(
                "c10",
                "c10 > 0 in Pa (shear modulus 2 c10)",
                c10,
            ));
        }
        check_d1(d1)?;
        for (name, d) in [("d2", d2), ("d3", d3)] {
            if d < 0.0 {
                return Err(Error::invalid(
                    name,
                    "a compressibility >= 0 in 1/Pa (0 means no such term)",
                    d,
                ));
            }
        }
        Ok(Yeoh {
            c10,
            c20,
            c30,
            d1,
            d2,
            d3,
        })
    }

    /// The higher-order volumetric energy `h(J) = (J-1)^4/d2 + (J-1)^6/d3` with `h'` and `h''`.
    fn higher_volumetric(&self, jm1: f64) -> (f64, f64, f64) {
        let (inv2, inv3) = (inverse_or_absent(self.d2), inverse_or_absent(self.d3));
        let x2 = jm1 * jm1;
        let x3 = x2 * jm1;
        let x4 = x2 * x2;
        (
            x4 * (inv2 + inv3 * x2),
            x3 * (4.0 * inv2 + 6.0 * inv3 * x2),
            x2 * (12.0 * inv2 + 30.0 * inv3 * x2),
        )
    }
}

impl Hyperelastic for Yeoh {
    fn param_names(&self) -> Vec<String> {
        PARAM_NAMES.iter().map(|s| s.to_string()).collect()
    }

    fn rest(&self, h: &Mat3, with_tangent: bool) -> Option<Response> {
        let kin = Kinematics::new(h)?;
        let i1 = kin.bar_i1();
        let x = i1.minus_3;
        let psi = x * (self.c10 + x * (self.c20 + x * self.c30));
        let dpsi = self.c10 + x * (2.0 * self.c20 + 3.0 * x * self.c30);
        let (vol, dvol, d2vol) = self.higher_volumetric(kin.jm1);
        let j = kin.j;
        let tangent = with_tangent.then(|| {
            let d2psi = 2.0 * self.c20 + 6.0 * x * self.c30;
            bar_i1_tangent(&kin, &i1, dpsi, d2psi, d2vol * j * j + dvol * j, dvol * j)
        });
        Some(Response {
            energy: psi + vol,
            stress: dpsi * i1.gradient + (dvol * j) * kin.g,
            tangent,
        })
    }

    fn bulk(&self) -> f64 {
        2.0 / self.d1
    }

    fn volumetric(&self) -> Volumetric {
        Volumetric::Linear
    }

    /// At `d2 = 0` (resp. `d3 = 0`) the term is absent and its derivatives are reported as 0:
    /// the parameter is inactive there (the energy is not differentiable in `d2` at 0).
    fn rest_param_gradient(&self, h: &Mat3) -> Option<RestParamGradient> {
        let kin = Kinematics::new(h)?;
        let i1 = kin.bar_i1();
        let x = i1.minus_3;
        let jm1 = kin.jm1;
        let jg = kin.j * kin.g;
        // d/dd of (J-1)^n / d is -(J-1)^n / d^2, with stress -n (J-1)^(n-1) J G / d^2.
        let compressibility = |d: f64, n: i32| -> (f64, Mat3) {
            if d == 0.0 {
                return (0.0, Mat3::zeros());
            }
            let inv2 = 1.0 / (d * d);
            (
                -jm1.powi(n) * inv2,
                (-(n as f64) * jm1.powi(n - 1) * inv2) * jg,
            )
        };
        let (e2, s2) = compressibility(self.d2, 4);
        let (e3, s3) = compressibility(self.d3, 6);
        Some(RestParamGradient {
            energy: vec![x, x * x, x * x * x, 0.0, e2, e3],
            stress: vec![
                i1.gradient,
                (2.0 * x) * i1.gradient,
                (3.0 * x * x) * i1.gradient,
                Mat3::zeros(),
                s2,
                s3,
            ],
        })
    }

    fn bulk_param_gradient(&self) -> Vec<f64> {
        vec![0.0, 0.0, 0.0, -2.0 / (self.d1 * self.d1), 0.0, 0.0]
    }
}
