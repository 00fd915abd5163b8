//! The isochoric invariants of the decoupled (Abaqus/ANSYS-form) models and their derivatives
//! with respect to F, written in `H = F - I` so that small strains keep full relative precision.
//!
//! ```text
//! Ī1 = J^(-2/3) I1,   I1 = tr C,                       C = F^T F,  J = det F
//! Ī2 = J^(-4/3) I2,   I2 = (I1^2 - tr C^2) / 2
//! dĪ1/dF = A1 = J^(-2/3) 2F - 2/3 Ī1 G                 G = F^{-T}
//! dĪ2/dF = A2 = J^(-4/3) 2F (I1 I - C) - 4/3 Ī2 G
//! d²Ī1/dF dF = 2 J^(-2/3) II + 2/3 Ī1 T - 4/9 Ī1 G⊗G - 2/3 (A1⊗G + G⊗A1)
//! d²Ī2/dF dF = J^(-4/3) d²I2 + 4/3 Ī2 T - 16/9 Ī2 G⊗G - 4/3 (A2⊗G + G⊗A2)
//! d²I2 (ij)(kl) = 4 F_ij F_kl + 2 I1 δ_ik δ_jl - 2 δ_ik C_lj - 2 F_il F_kj - 2 B_ik δ_jl
//! ```
//!
//! with `II` the 9x9 identity, `T_(ij)(kl) = G_il G_kj`, `(X⊗Y)_(ij)(kl) = X_ij Y_kl` and
//! `B = F F^T` (tangents in the flattening of [`super`]). Near F = I both `Ī - 3` and `A` are
//! differences of first-order terms; they are expanded below so that only second-order
//! (resp. first-order) quantities are added.

use super::law::VolumeState;
use super::{Mat3, Tangent};
use crate::error::{Error, Result};

/// F-dependent quantities shared by the invariants at one `H = F - I`.
pub struct Kinematics {
    pub h: Mat3,
    pub f: Mat3,
    /// `G = F^{-T}`.
    pub g: Mat3,
    /// `J = det F` and `J - 1` (accurate near 1).
    pub j: f64,
    pub jm1: f64,
    /// `J - 1 - tr H = ((tr H)^2 - tr H^2)/2 + det H`, second order in H.
    q: f64,
    /// `y = J^(1/3) - 1`, so that `J^(2/3) = (1 + y)^2` expands without cancellation.
    y: f64,
    /// `J^(-2/3)`.
    pub j23: f64,
}

/// An isochoric invariant `Ī`, `Ī - 3` (accurate near F = I, Ī = 3 at F = I) and `A = dĪ/dF`.
pub struct BarInvariant {
    pub value: f64,
    pub minus_3: f64,
    pub gradient: Mat3,
}

impl Kinematics {
    /// `None` when `J <= 0`.
    pub fn new(h: &Mat3) -> Option<Self> {
        Some(Self::at(h, &VolumeState::new(h)?))
    }

    /// From the volume state of the same `H` (computed once by the element kernels).
    pub fn at(h: &Mat3, volume: &VolumeState) -> Self {
        // J - 1 = tr H + q; and J^(1/3) - 1 = (J - 1) / (c^2 + c + 1) with c = J^(1/3), free of
        // the cancellation of c - 1.
        let cube_root = volume.j.cbrt();
        Kinematics {
            h: *h,
            f: Mat3::identity() + h,
            g: volume.gt,
            j: volume.j,
            jm1: volume.jm1,
            q: volume.jm1 - h.trace(),
            y: volume.jm1 / (cube_root * cube_root + cube_root + 1.0),
            j23: 1.0 / (cube_root * cube_root),
        }
    }

    /// The volume state these kinematics were built from.
    pub fn volume(&self) -> VolumeState {
        VolumeState {
            gt: self.g,
            j: self.j,
            jm1: self.jm1,
        }
    }

    /// `F - G = H + G H^T` (because `G H^T = G F^T - G = I - G`), first order in H.
    fn f_minus_g(&self) -> Mat3 {
        self.h + self.g * self.h.transpose()
    }

    /// `Ī1 - 3 = J^(-2/3) (|H|^2 - 2 q + 3 y^2 + 2 y^3)`: `I1 - 3 = 2 tr H + |H|^2` and
    /// `3 J^(2/3) - 3 = 2 (J - 1) - 3 y^2 - 2 y^3` from `J = (1 + y)^3`; the `2 tr H` cancel.
    pub fn bar_i1(&self) -> BarInvariant {
        let hh = self.h.norm_squared();
        let y = self.y;
        let minus_3 = self.j23 * (hh - 2.0 * self.q + y * y * (3.0 + 2.0 * y));
        let i1_minus_3 = 2.0 * self.h.trace() + hh;
        // 2F - 2/3 I1 G = 2 (F - G) - 2/3 (I1 - 3) G.
        let gradient = self.j23 * (2.0 * self.f_minus_g() - (2.0 / 3.0 * i1_minus_3) * self.g);
        BarInvariant {
            value: 3.0 + minus_3,
            minus_3,
            gradient,
        }
    }

    /// `Ī2 - 3 = J^(-4/3) (2|H|^2 - 4 q + (e^2 - |E|^2)/2 - 6 y^2 - 8 y^3 - 3 y^4)` with
    /// `E = C - I = H + H^T + H^T H` and `e = tr E`: `I2 - 3 = 2 e + (e^2 - |E|^2)/2` and
    /// `3 J^(4/3) - 3 = 4 (J - 1) + 6 y^2 + 8 y^3 + 3 y^4`; the first-order terms cancel.
    pub fn bar_i2(&self) -> BarInvariant {
        let h = &self.h;
        let e_mat = h + h.transpose() + h.transpose() * h;
        let e = e_mat.trace();
        let second = 0.5 * (e * e - e_mat.norm_squared());
        let i2_minus_3 = 2.0 * e + second;
        let y = self.y;
        let j43 = self.j23 * self.j23;
        let minus_3 = j43
            * (2.0 * h.norm_squared() - 4.0 * self.q + second
                - y * y * (6.0 + y * (8.0 + 3.0 * y)));
        // 2F (I1 I - C) - 4/3 I2 G = 4 (F - G) + 2 F (e I - E) - 4/3 (I2 - 3) G.
        let gradient = j43
            * (4.0 * self.f_minus_g() + 2.0 * self.f * (Mat3::identity() * e - e_mat)
                - (4.0 / 3.0 * i2_minus_3) * self.g);
        BarInvariant {
            value: 3.0 + minus_3,
            minus_3,
            gradient,
        }
    }
}

fn flat(m: &Mat3) -> [f64; 9] {
    std::array::from_fn(|k| m[(k / 3, k % 3)])
}

/// `first d²Ī1/dF dF + second A1⊗A1 + vol_a G⊗G - vol_b T` (9x9): the whole tangent of an energy
/// `Ψ(Ī1) + h(J)` with `first = Ψ'`, `second = Ψ''`, `vol_a = h'' J^2 + h' J`, `vol_b = h' J`
/// (see [`super::volumetric_tangent`]), in one pass over the 81 entries.
pub fn bar_i1_tangent(
    kin: &Kinematics,
    i1: &BarInvariant,
    first: f64,
    second: f64,
    vol_a: f64,
    vol_b: f64,
) -> Tangent {
    let g = flat(&kin.g);
    let a1 = flat(&i1.gradient);
    let identity = 2.0 * first * kin.j23;
    let c_t = 2.0 / 3.0 * first * i1.value - vol_b;
    let c_gg = -4.0 / 9.0 * first * i1.value + vol_a;
    let c_cross = -2.0 / 3.0 * first;
    // Entry (a, b) = g_a u_b + a1_a w_b + c_t T_ab, the cross and outer terms grouped by row factor.
    let u: [f64; 9] = std::array::from_fn(|b| c_gg * g[b] + c_cross * a1[b]);
    let w: [f64; 9] = std::array::from_fn(|b| c_cross * g[b] + second * a1[b]);
    let mut t = Tangent::zeros();
    for k in 0..3 {
        for l in 0..3 {
            let col = 3 * k + l;
            for i in 0..3 {
                for j in 0..3 {
                    let row = 3 * i + j;
                    t[(row, col)] =
                        g[row] * u[col] + a1[row] * w[col] + c_t * g[3 * i + l] * g[3 * k + j];
                }
            }
            t[(col, col)] += identity;
        }
    }
    t
}

/// Adds `coeff d²Ī2/dF dF` (9x9) to `t`.
pub fn add_bar_i2_hessian(kin: &Kinematics, i2: &BarInvariant, coeff: f64, t: &mut Tangent) {
    let f = &kin.f;
    let c = f.transpose() * f;
    let b = f * f.transpose();
    let j43 = kin.j23 * kin.j23;
    let g = flat(&kin.g);
    let a2 = flat(&i2.gradient);
    let ff = flat(f);
    let c_t = coeff * 4.0 / 3.0 * i2.value;
    let c_swap = -2.0 * coeff * j43;
    // The outer products grouped by row factor: g_a u_b + a2_a w_b + F_a z_b.
    let u: [f64; 9] =
        std::array::from_fn(|k| coeff * (-16.0 / 9.0 * i2.value * g[k] - 4.0 / 3.0 * a2[k]));
    let w: [f64; 9] = std::array::from_fn(|k| coeff * -4.0 / 3.0 * g[k]);
    let z: [f64; 9] = std::array::from_fn(|k| 4.0 * coeff * j43 * ff[k]);
    for k in 0..3 {
        for l in 0..3 {
            let col = 3 * k + l;
            for i in 0..3 {
                for j in 0..3 {
                    let row = 3 * i + j;
                    t[(row, col)] += g[row] * u[col]
                        + a2[row] * w[col]
                        + ff[row] * z[col]
                        + c_t * g[3 * i + l] * g[3 * k + j]
                        + c_swap * ff[3 * i + l] * ff[3 * k + j];
                }
            }
        }
    }
    // The Kronecker-delta terms 2 I1 δ_ik δ_jl - 2 δ_ik C_lj - 2 B_ik δ_jl, on their support only.
    let diagonal = 2.0 * coeff * j43 * c.trace();
    for i in 0..3 {
        for j in 0..3 {
            let row = 3 * i + j;
            t[(row, row)] += diagonal;
            for m in 0..3 {
                t[(row, 3 * i + m)] += c_swap * c[(m, j)];
                t[(row, 3 * m + j)] += c_swap * b[(i, m)];
            }
        }
    }
}

/// How a decoupled model shares its volumetric energy `kappa/2 (J - 1)^2` (`kappa = 2/d1`, Pa)
/// between its rest part and its primary volumetric term (the one the mixed formulation turns
/// into the pressure field):
///
/// ```text
/// kappa_s = a kappa / (a + kappa),   a = 2 mu0 / 3          (mu0: small-strain shear modulus)
/// W_rest  = W_iso + kappa_s/2 (J - 1)^2,   primary term (kappa - kappa_s)/2 (J - 1)^2
/// kappa - kappa_s = kappa^2 / (a + kappa)
/// ```
///
/// An isochoric energy has no stiffness against dilation, so without this share the mixed
/// formulation's displacement block would have none either, and Newton's method wanders far
/// from the solution on nearly incompressible bodies (as does the standard formulation, whose
/// primary term's Hessian is taken at pressure iterates). The compressible Neo-Hookean's rest part carries the same `2 mu/3` through
/// its `-mu ln J`. `kappa_s -> a` for nearly incompressible materials and stays below `kappa`,
/// so the primary term keeps a positive modulus for every `d1 > 0`. The energy is unchanged; the
/// mixed compliance is `1/(kappa - kappa_s) = d1/2 + a d1^2/4`, which still vanishes as d1 -> 0.
#[derive(Clone, Copy, Debug)]
pub struct BulkSplit {
    /// `kappa_s` (Pa), kept in the rest part.
    pub rest: f64,
    /// `kappa - kappa_s` (Pa), the primary volumetric term's modulus.
    pub primary: f64,
    /// `a` and `kappa` (Pa).
    a: f64,
    kappa: f64,
}

impl BulkSplit {
    /// From the small-strain shear modulus `mu0 > 0` (Pa) and `d1 > 0` (1/Pa).
    #[inline]
    pub fn new(shear: f64, d1: f64) -> Self {
        let kappa = 2.0 / d1;
        let a = 2.0 / 3.0 * shear;
        let share = kappa / (a + kappa);
        BulkSplit {
            rest: a * share,
            primary: kappa * share,
            a,
            kappa,
        }
    }

    /// `d kappa_s / d theta_k` for every parameter, from `d mu0 / d theta_k` and
    /// `d kappa / d theta_k`.
    pub fn rest_gradient(&self, d_shear: &[f64], d_bulk: &[f64]) -> Vec<f64> {
        // d kappa_s / d a = (kappa / (a + kappa))^2, d kappa_s / d kappa = (a / (a + kappa))^2.
        let sum = self.a + self.kappa;
        let d_rest_d_shear = 2.0 / 3.0 * (self.kappa / sum).powi(2);
        let d_rest_d_bulk = (self.a / sum).powi(2);
        d_shear
            .iter()
            .zip(d_bulk)
            .map(|(s, b)| d_rest_d_shear * s + d_rest_d_bulk * b)
            .collect()
    }

    /// Adds the derivatives of the rest part's `kappa_s/2 (J - 1)^2` with respect to every
    /// parameter, `(J - 1)^2/2 dkappa_s` to `energy` and `(J - 1) J F^{-T} dkappa_s` to `stress`.
    pub fn add_rest_param_gradient(
        &self,
        volume: &VolumeState,
        d_shear: &[f64],
        d_bulk: &[f64],
        energy: &mut [f64],
        stress: &mut [Mat3],
    ) {
        let x = volume.jm1;
        let jg = volume.j * volume.gt;
        for (k, d) in self.rest_gradient(d_shear, d_bulk).into_iter().enumerate() {
            energy[k] += 0.5 * x * x * d;
            stress[k] += (x * d) * jg;
        }
    }

    /// `d (kappa - kappa_s) / d theta_k`.
    pub fn primary_gradient(&self, d_shear: &[f64], d_bulk: &[f64]) -> Vec<f64> {
        let rest = self.rest_gradient(d_shear, d_bulk);
        d_bulk.iter().zip(rest).map(|(b, r)| b - r).collect()
    }
}

/// Checks a model's parameter slice: its length against `names` and every value finite.
pub fn check_params(names: &[&str], params: &[f64]) -> Result<()> {
    if params.len() != names.len() {
        return Err(Error::shape(
            "params",
            format!("{} values [{}]", names.len(), names.join(", ")),
            format!("{} values", params.len()),
        ));
    }
    for (name, &value) in names.iter().zip(params) {
        if !value.is_finite() {
            return Err(Error::invalid(name, "a finite value", value));
        }
    }
    Ok(())
}

/// `d1 > 0`: shared by every decoupled model (`kappa = 2/d1`; the mixed formulation's compliance
/// `d1/2` makes `d1 -> 0` the incompressible limit, but `d1 = 0` itself has no bulk modulus).
pub fn check_d1(d1: f64) -> Result<()> {
    if d1 > 0.0 {
        Ok(())
    } else {
        Err(Error::invalid(
            "d1",
            "a compressibility > 0 in 1/Pa (bulk modulus 2/d1; d1 -> 0 is incompressible)",
            d1,
        ))
    }
}
