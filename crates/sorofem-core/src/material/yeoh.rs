//! Decoupled Yeoh material (the Abaqus/ANSYS form).
//!
//! `W(F) = sum_{i=1..3} c_i0 (Ī1 - 3)^i + sum_{i=1..3} (J - 1)^(2i) / d_i` (Pa), with
//! `Ī1 = J^(-2/3) I1` (see [`super::isochoric`]); `c_i0` in Pa, `d_i` in 1/Pa, and `d2 = 0` or
//! `d3 = 0` meaning that term is absent. Small-strain shear modulus `mu = 2 c10`, bulk modulus
//! `kappa = 2 / d1`. In the split of [`Hyperelastic`], `W_rest` holds the isochoric part, the
//! share [`BulkSplit`] of `(J - 1)^2 / d1` and the `d2`, `d3` terms, and the rest of
//! `(J - 1)^2 / d1` is the primary volumetric term (so in the mixed formulation the `d2`, `d3`
//! terms stay displacement-based: they have no stiffness at `J = 1` and cannot lock).

use super::isochoric::{bar_i1_tangent, check_d1, check_params, BulkSplit, Kinematics};
use super::law::{Hyperelastic, RestParamGradient, VolumeState, VolumetricTerm};
use super::neo_hookean::Response;
use super::{Mat3, Volumetric};
use crate::error::{Error, Result};

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
    /// Parameter names, in the order of [`Yeoh::try_new`]'s slice.
    pub const PARAM_NAMES: [&'static str; 6] = ["c10", "c20", "c30", "d1", "d2", "d3"];

    /// From `[c10, c20, c30, d1, d2, d3]`. Requires `c10 > 0` (the small-strain shear modulus is
    /// `2 c10`); `c20`, `c30` of any sign (fits commonly give `c20 < 0` for the softening at
    /// moderate strain); `d1 > 0` (see [`check_d1`]); `d2, d3 >= 0` with 0 meaning no term
    /// (a negative one would make `(J - 1)^(2i) / d_i` unbounded below); every value finite.
    pub fn try_new(params: &[f64]) -> Result<Self> {
        check_params(&Self::PARAM_NAMES, params)?;
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

    /// The share of `(J - 1)^2 / d1` in the rest part.
    fn split(&self) -> BulkSplit {
        BulkSplit::new(2.0 * self.c10, self.d1)
    }

    /// `d mu0 / d theta` and `d kappa / d theta` (`mu0 = 2 c10`, `kappa = 2 / d1`).
    fn moduli_gradients(&self) -> ([f64; 6], [f64; 6]) {
        let d_bulk = -2.0 / (self.d1 * self.d1);
        (
            [2.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            [0.0, 0.0, 0.0, d_bulk, 0.0, 0.0],
        )
    }

    /// `W_rest + v(J)` with stress and tangent (see [`Hyperelastic::rest_with_volumetric`]).
    fn evaluate(&self, kin: &Kinematics, extra: &VolumetricTerm, with_tangent: bool) -> Response {
        let extra = &extra.plus_quadratic(self.split().rest, kin.jm1);
        let i1 = kin.bar_i1();
        let x = i1.minus_3;
        let psi = x * (self.c10 + x * (self.c20 + x * self.c30));
        let dpsi = self.c10 + x * (2.0 * self.c20 + 3.0 * x * self.c30);
        let (vol, dvol, d2vol) = self.higher_volumetric(kin.jm1);
        let j = kin.j;
        let tangent = with_tangent.then(|| {
            let d2psi = 2.0 * self.c20 + 6.0 * x * self.c30;
            let slope = dvol + extra.tangent_slope;
            let curvature = d2vol + extra.tangent_curvature;
            bar_i1_tangent(
                kin,
                &i1,
                dpsi,
                d2psi,
                curvature * j * j + slope * j,
                slope * j,
            )
        });
        Response {
            energy: psi + vol + extra.energy,
            stress: dpsi * i1.gradient + ((dvol + extra.stress_slope) * j) * kin.g,
            tangent,
        }
    }
}

impl Hyperelastic for Yeoh {
    fn param_names(&self) -> Vec<String> {
        Self::PARAM_NAMES.map(String::from).to_vec()
    }

    fn rest(&self, h: &Mat3, with_tangent: bool) -> Option<Response> {
        let kin = Kinematics::new(h)?;
        Some(self.evaluate(&kin, &VolumetricTerm::default(), with_tangent))
    }

    /// The volumetric term goes into the one pass over the tangent's 81 entries.
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
        let mut energy = vec![x, x * x, x * x * x, 0.0, e2, e3];
        let mut stress = vec![
            i1.gradient,
            (2.0 * x) * i1.gradient,
            (3.0 * x * x) * i1.gradient,
            Mat3::zeros(),
            s2,
            s3,
        ];
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
