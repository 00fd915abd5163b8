//! Decoupled Ogden material with 1 to 3 terms (the Abaqus/ANSYS form).
//!
//! `W(F) = sum_p 2 mu_p / alpha_p^2 (λ̄1^alpha_p + λ̄2^alpha_p + λ̄3^alpha_p - 3) + (J - 1)^2 / d1`
//! (Pa), with `λ̄_i = J^(-1/3) λ_i` and `λ_i` the principal stretches; `mu_p` in Pa, `alpha_p`
//! dimensionless, `d1` in 1/Pa. Small-strain shear modulus `mu = sum_p mu_p`, bulk modulus
//! `kappa = 2 / d1` (in the split of [`Hyperelastic`], `W_rest` is the isochoric part with the
//! share [`BulkSplit`] of the volumetric energy). In this convention `alpha = 2` is `c10 = mu/2` and `alpha = -2` is
//! `c01 = mu/2` of Mooney-Rivlin (`sum_i λ̄_i^-2 = Ī2` because `λ̄1 λ̄2 λ̄3 = 1`).
//!
//! Written in the log stretches `l_i = ln λ_i` and their deviatoric parts
//! `l̄_i = l_i - (l_1 + l_2 + l_3)/3`, with `e_i = exp(alpha l̄_i)` per term:
//!
//! ```text
//! W_rest = sum_p 2 mu_p/alpha_p^2 sum_i (e_i - 1 - alpha_p l̄_i)        (sum_i l̄_i = 0)
//! tau_i  = dW_rest/dl_i = sum_p 2 mu_p/alpha_p (e_i - S̄/3),  S̄ = sum_i e_i
//! P      = U diag(tau_i / λ_i) V^T                          (F = U diag(λ) V^T)
//! ```
//!
//! The tangent is block diagonal in the basis `u_a v_b^T` (Smith, de Goes and Kim 2019): the
//! stretch block `d²W/dλ_a dλ_b`, and for each pair a < b the flip and twist modes
//! `(u_a v_b^T ± u_b v_a^T)/sqrt 2` with eigenvalues `(psi_a - psi_b)/(λ_a - λ_b)` and
//! `(psi_a + psi_b)/(λ_a + λ_b)`, `psi_i = tau_i / λ_i`. The flip eigenvalue is evaluated in
//! closed form without the division,
//!
//! ```text
//! (psi_a - psi_b)/(λ_a - λ_b) = 1/(λ_a λ_b) sum_p 2 mu_p/alpha_p
//!     (exp(alpha_p (l̄_a + l̄_b)/2) sinh((alpha_p - 1) u/2) / sinh(u/2) + S̄/3),  u = l_a - l_b
//! ```
//!
//! whose limit at `u = 0` is `alpha_p - 1`: equal stretches (the rest state) are regular points,
//! and the eigenvectors chosen inside a repeated eigenspace do not matter.

use super::isochoric::{check_d1, check_params, BulkSplit};
use super::law::{Hyperelastic, RestParamGradient, VolumeState, VolumetricTerm};
use super::neo_hookean::{j_minus_one, Response};
use super::{symmetric_eigenvalues, volumetric_tangent, Mat3, Tangent, Volumetric};
use crate::error::{Error, Result};
use nalgebra::{SymmetricEigen, Vector3};

/// The most terms a model may have.
pub const MAX_TERMS: usize = 3;
const NAMES: [[&str; 2]; MAX_TERMS] = [
    ["mu:0", "alpha:0"],
    ["mu:1", "alpha:1"],
    ["mu:2", "alpha:2"],
];

/// Ogden terms `(mu_p, alpha_p)` (Pa, dimensionless) and compressibility `d1` (1/Pa).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ogden {
    terms: usize,
    mu: [f64; MAX_TERMS],
    alpha: [f64; MAX_TERMS],
    d1: f64,
}

impl Ogden {
    /// From `[mu:0, alpha:0, (mu:1, alpha:1, (mu:2, alpha:2)), d1]`; the number of terms is
    /// `(params.len() - 1) / 2`. Requires per term `alpha_p != 0` (the term divides by it) and
    /// `sum_p mu_p > 0` (a positive small-strain shear modulus), `d1 > 0` (see [`check_d1`]),
    /// every value finite. The per-term condition `mu_p > 0` (every term then has a nonnegative
    /// energy, since `sum_i λ̄_i^alpha >= 3` by the AM-GM inequality; it is Ogden's `mu_p alpha_p > 0`
    /// in his convention `mu_p^Ogden = 2 mu_p / alpha_p`) is sufficient for stability but not
    /// required: published multi-term fits of silicones mix signs, and their stable range is
    /// what the fit reports.
    pub fn try_new(params: &[f64]) -> Result<Self> {
        let n = params.len();
        if !(n % 2 == 1 && (3..=2 * MAX_TERMS + 1).contains(&n)) {
            return Err(Error::shape(
                "params",
                "3, 5 or 7 values [mu:0, alpha:0, ..., d1] (1 to 3 Ogden terms)",
                format!("{n} values"),
            ));
        }
        let terms = (n - 1) / 2;
        let names: Vec<&str> = NAMES[..terms]
            .iter()
            .flatten()
            .copied()
            .chain(["d1"])
            .collect();
        check_params(&names, params)?;
        let mut model = Ogden {
            terms,
            mu: [0.0; MAX_TERMS],
            alpha: [0.0; MAX_TERMS],
            d1: params[n - 1],
        };
        for p in 0..terms {
            model.mu[p] = params[2 * p];
            model.alpha[p] = params[2 * p + 1];
            if model.alpha[p] == 0.0 {
                return Err(Error::invalid(
                    NAMES[p][1],
                    "a nonzero exponent",
                    model.alpha[p],
                ));
            }
        }
        let shear: f64 = model.mu().iter().sum();
        if shear <= 0.0 {
            let moduli: Vec<&str> = NAMES[..terms].iter().map(|[mu, _]| *mu).collect();
            return Err(Error::invalid(
                "mu:0",
                format!("{} > 0 in Pa (the shear modulus)", moduli.join(" + ")),
                format!("a sum of {shear}"),
            ));
        }
        check_d1(model.d1)?;
        Ok(model)
    }

    /// The parameter names of a model of `terms` terms (1 to 3), in slice order:
    /// `mu:0, alpha:0, ..., d1`.
    pub fn param_names_of(terms: usize) -> Vec<String> {
        NAMES[..terms.min(MAX_TERMS)]
            .iter()
            .flatten()
            .map(|s| s.to_string())
            .chain(["d1".to_string()])
            .collect()
    }

    /// From a slice [`Ogden::try_new`] has accepted before (the element kernels' hot path: no checks).
    #[inline]
    pub(crate) fn from_validated(params: &[f64]) -> Self {
        let terms = (params.len() - 1) / 2;
        let mut model = Ogden {
            terms,
            mu: [0.0; MAX_TERMS],
            alpha: [1.0; MAX_TERMS],
            d1: params[params.len() - 1],
        };
        for p in 0..terms {
            model.mu[p] = params[2 * p];
            model.alpha[p] = params[2 * p + 1];
        }
        model
    }

    /// From the term lists `mu` (Pa) and `alpha` of equal length 1 to 3, and `d1` (1/Pa).
    pub fn try_from_terms(mu: &[f64], alpha: &[f64], d1: f64) -> Result<Self> {
        if mu.len() != alpha.len() {
            return Err(Error::shape(
                "alpha",
                format!("as many exponents as moduli `mu` ({})", mu.len()),
                format!("{} exponents", alpha.len()),
            ));
        }
        if !(1..=MAX_TERMS).contains(&mu.len()) {
            return Err(Error::shape(
                "mu",
                "1 to 3 Ogden terms",
                format!("{} terms", mu.len()),
            ));
        }
        let params: Vec<f64> = mu
            .iter()
            .zip(alpha)
            .flat_map(|(&m, &a)| [m, a])
            .chain([d1])
            .collect();
        Self::try_new(&params)
    }

    /// The moduli `mu_p` (Pa).
    pub fn mu(&self) -> &[f64] {
        &self.mu[..self.terms]
    }

    /// The exponents `alpha_p`.
    pub fn alpha(&self) -> &[f64] {
        &self.alpha[..self.terms]
    }

    /// Compressibility `d1` (1/Pa).
    pub fn d1(&self) -> f64 {
        self.d1
    }
}

/// The principal frame of `F = U diag(λ) V^T` from the eigen-decomposition of `C - I`
/// (accurate log stretches at small strain, orthonormal V however close the stretches are).
struct Principal {
    f: Mat3,
    v: Mat3,
    stretch: [f64; 3],
    log_stretch: [f64; 3],
    /// `l̄_i = l_i - mean(l)`.
    deviatoric: [f64; 3],
}

impl Principal {
    fn new(h: &Mat3) -> Option<Self> {
        let jm1 = j_minus_one(h);
        if jm1.is_nan() || jm1 <= -1.0 {
            return None;
        }
        let (c_minus_1, v) = symmetric_eigen(&(h + h.transpose() + h.transpose() * h));
        let mut log_stretch = [0.0; 3];
        for (l, &c_minus_1) in log_stretch.iter_mut().zip(c_minus_1.iter()) {
            if c_minus_1.is_nan() || c_minus_1 <= -1.0 {
                return None;
            }
            *l = 0.5 * c_minus_1.ln_1p();
        }
        let mean = log_stretch.iter().sum::<f64>() / 3.0;
        Some(Principal {
            f: Mat3::identity() + h,
            v,
            stretch: c_minus_1.map(|x| (1.0 + x).sqrt()),
            log_stretch,
            deviatoric: log_stretch.map(|l| l - mean),
        })
    }

    /// `F V diag(s_i / λ_i^2) V^T`: the stress `U diag(s_i / λ_i) V^T` of principal Kirchhoff
    /// values `s_i`, without forming U.
    fn stress(&self, s: &[f64; 3]) -> Mat3 {
        let d = Vector3::from_fn(|i, _| s[i] / (self.stretch[i] * self.stretch[i]));
        self.f * self.v * Mat3::from_diagonal(&d) * self.v.transpose()
    }
}

/// Eigenvalues and orthonormal eigenvectors (columns, same order) of a symmetric 3x3 matrix.
///
/// The technique of [`super::rotation_svd`], applied to `E = C - I` (so that small strains keep
/// their relative precision): the best separated eigenvector from cross products of the rows of
/// `E - lambda I`, the other two by a Jacobi rotation in the orthogonal plane (accurate however
/// close they are), the eigenvalues as Rayleigh quotients. An eigenvector's error, of order
/// `eps |E| / gap`, moves the stress by that times the gap, so it stays at round-off; only when
/// all three eigenvalues agree to 1e-6 relative does the iterative solver take over.
fn symmetric_eigen(e: &Mat3) -> ([f64; 3], Mat3) {
    let estimates = symmetric_eigenvalues(e);
    let spread = estimates[0] - estimates[2];
    let scale = estimates[0].abs().max(estimates[2].abs());
    if spread > 1e-6 * scale {
        if let Some(decomposition) = closed_form_eigen(e, &estimates) {
            return decomposition;
        }
    }
    let eig = SymmetricEigen::new(*e);
    (eig.eigenvalues.into(), eig.eigenvectors)
}

fn closed_form_eigen(e: &Mat3, estimates: &[f64; 3]) -> Option<([f64; 3], Mat3)> {
    let [largest, middle, smallest] = *estimates;
    let null_vector = |lambda: f64| -> Option<Vector3<f64>> {
        let m = e - Mat3::identity() * lambda;
        let rows = [
            m.row(0).transpose(),
            m.row(1).transpose(),
            m.row(2).transpose(),
        ];
        let best = [
            rows[0].cross(&rows[1]),
            rows[0].cross(&rows[2]),
            rows[1].cross(&rows[2]),
        ]
        .into_iter()
        .max_by(|a, b| a.norm_squared().total_cmp(&b.norm_squared()))?;
        let norm = best.norm();
        (norm > 0.0 && norm.is_finite()).then(|| best / norm)
    };
    let first = null_vector(if largest - middle >= middle - smallest {
        largest
    } else {
        smallest
    })?;
    let first = null_vector(first.dot(&(e * first))).unwrap_or(first);
    let helper = if first.x.abs() < 0.6 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let e1 = (helper - first * first.dot(&helper)).normalize();
    let e2 = first.cross(&e1);
    let (ee1, ee2) = (e * e1, e * e2);
    let (a, b, d) = (e1.dot(&ee1), e1.dot(&ee2), e2.dot(&ee2));
    let (sin, cos) = (0.5 * (2.0 * b).atan2(a - d)).sin_cos();
    let second = e1 * cos + e2 * sin;
    let third = e2 * cos - e1 * sin;
    let rayleigh = |v: &Vector3<f64>| v.dot(&(e * v));
    Some((
        [rayleigh(&first), rayleigh(&second), rayleigh(&third)],
        Mat3::from_columns(&[first, second, third]),
    ))
}

/// `1/k!` for k = 2..=17.
const INVERSE_FACTORIALS: [f64; 16] = {
    let mut c = [0.0; 16];
    let mut factorial = 1.0;
    let mut k = 2;
    while k <= 17 {
        factorial *= k as f64;
        c[k - 2] = 1.0 / factorial;
        k += 1;
    }
    c
};

/// `e^u - 1 - u` without cancellation for small |u| (Taylor series below 1/2, whose dropped
/// terms are below 1e-17 relative there).
fn exp_m1_minus_arg(u: f64) -> f64 {
    if u.abs() >= 0.5 {
        return u.exp_m1() - u;
    }
    let tail = INVERSE_FACTORIALS
        .iter()
        .rev()
        .fold(0.0, |sum, &c| sum * u + c);
    tail * u * u
}

/// `sinh(beta u / 2) / sinh(u / 2)`, `beta` at `u = 0`: the divided difference
/// `(a^beta - b^beta)/(a - b)` of a power, scaled by `(a b)^((1 - beta)/2)`, with `u = ln(a/b)`.
fn sinh_ratio(beta: f64, u: f64) -> f64 {
    if u.abs() < 1e-30 {
        beta
    } else {
        (0.5 * beta * u).sinh() / (0.5 * u).sinh()
    }
}

/// One term's `e_i - 1` per principal direction and `S̄ - 3`.
fn term_values(alpha: f64, deviatoric: &[f64; 3]) -> ([f64; 3], f64) {
    let em1 = deviatoric.map(|l| (alpha * l).exp_m1());
    let s_minus_3 = deviatoric
        .iter()
        .map(|&l| exp_m1_minus_arg(alpha * l))
        .sum();
    (em1, s_minus_3)
}

/// `(e_i - 1) - (S̄ - 3)/3 = e_i - S̄/3`, first order in the strain.
fn deviator(em1: &[f64; 3]) -> [f64; 3] {
    let mean = (em1[0] + em1[1] + em1[2]) / 3.0;
    em1.map(|x| x - mean)
}

impl Ogden {
    /// The share of `(J - 1)^2 / d1` in the rest part.
    fn split(&self) -> BulkSplit {
        BulkSplit::new(self.mu().iter().sum(), self.d1)
    }

    /// `d mu0 / d theta` and `d kappa / d theta` (`mu0 = sum_p mu_p`, `kappa = 2 / d1`).
    fn moduli_gradients(&self) -> (Vec<f64>, Vec<f64>) {
        let n = 2 * self.terms + 1;
        let mut d_shear = vec![0.0; n];
        let mut d_bulk = vec![0.0; n];
        for p in 0..self.terms {
            d_shear[2 * p] = 1.0;
        }
        d_bulk[n - 1] = -2.0 / (self.d1 * self.d1);
        (d_shear, d_bulk)
    }

    /// The isochoric part `W_iso` with its stress and tangent (see the module docs).
    fn isochoric(&self, h: &Mat3, with_tangent: bool) -> Option<Response> {
        let pr = Principal::new(h)?;
        let lbar = &pr.deviatoric;
        let mut energy = 0.0;
        let mut tau = [0.0; 3];
        // d tau_a / d l_b, and the flip eigenvalue times λ_a λ_b per pair (0,1), (0,2), (1,2).
        let mut dtau = [[0.0; 3]; 3];
        let mut flip = [0.0; 3];
        const PAIRS: [(usize, usize); 3] = [(0, 1), (0, 2), (1, 2)];
        for (&mu, &alpha) in self.mu().iter().zip(self.alpha()) {
            let (em1, s_minus_3) = term_values(alpha, lbar);
            energy += 2.0 * mu / (alpha * alpha) * s_minus_3;
            let dev = deviator(&em1);
            let c = 2.0 * mu / alpha;
            for a in 0..3 {
                tau[a] += c * dev[a];
            }
            if with_tangent {
                let e = em1.map(|x| 1.0 + x);
                let s_bar = 3.0 + s_minus_3;
                for a in 0..3 {
                    for b in 0..3 {
                        let diagonal = if a == b { e[a] } else { 0.0 };
                        dtau[a][b] += 2.0 * mu * (diagonal - (e[a] + e[b]) / 3.0 + s_bar / 9.0);
                    }
                }
                for (k, &(a, b)) in PAIRS.iter().enumerate() {
                    let u = pr.log_stretch[a] - pr.log_stretch[b];
                    flip[k] +=
                        c * ((e[a] * e[b]).sqrt() * sinh_ratio(alpha - 1.0, u) + s_bar / 3.0);
                }
            }
        }
        let stress = pr.stress(&tau);
        let tangent = with_tangent.then(|| {
            let s = &pr.stretch;
            let psi = [tau[0] / s[0], tau[1] / s[1], tau[2] / s[2]];
            let inv = Vector3::from_fn(|i, _| 1.0 / s[i]);
            let u = pr.f * pr.v * Mat3::from_diagonal(&inv);
            // The basis u_a v_b^T (index 3a + b), flattened: basis[3a + b][3i + j] = U_ia V_jb.
            let basis: [[f64; 9]; 9] = std::array::from_fn(|x| {
                std::array::from_fn(|r| u[(r / 3, x / 3)] * pr.v[(r % 3, x % 3)])
            });
            // A = E M E^T with E = [basis] and M the block-diagonal tangent in that basis; the
            // columns of E M first (M has at most three nonzeros per column), then A by symmetry.
            let mut em = [[0.0; 9]; 9];
            for b in 0..3 {
                for a in 0..3 {
                    let mut m_ab = dtau[a][b] / (s[a] * s[b]);
                    if a == b {
                        m_ab -= psi[a] / s[a];
                    }
                    for r in 0..9 {
                        em[4 * b][r] += m_ab * basis[4 * a][r];
                    }
                }
            }
            for (k, &(a, b)) in PAIRS.iter().enumerate() {
                let flip = flip[k] / (s[a] * s[b]);
                let twist = (psi[a] + psi[b]) / (s[a] + s[b]);
                let (same, swapped) = (0.5 * (flip + twist), 0.5 * (flip - twist));
                let (ab, ba) = (3 * a + b, 3 * b + a);
                for r in 0..9 {
                    em[ab][r] = same * basis[ab][r] + swapped * basis[ba][r];
                    em[ba][r] = same * basis[ba][r] + swapped * basis[ab][r];
                }
            }
            let mut t = Tangent::zeros();
            for col in 0..9 {
                for row in 0..=col {
                    let value = (0..9).map(|x| em[x][row] * basis[x][col]).sum::<f64>();
                    t[(row, col)] = value;
                    t[(col, row)] = value;
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
}

impl Hyperelastic for Ogden {
    fn param_names(&self) -> Vec<String> {
        Self::param_names_of(self.terms)
    }

    fn rest(&self, h: &Mat3, with_tangent: bool) -> Option<Response> {
        let volume = VolumeState::new(h)?;
        self.rest_with_volumetric(h, &volume, &VolumetricTerm::default(), with_tangent)
    }

    /// The isochoric part, then the share [`BulkSplit`] of `(J - 1)^2 / d1` and `v(J)` together.
    fn rest_with_volumetric(
        &self,
        h: &Mat3,
        volume: &VolumeState,
        volumetric: &VolumetricTerm,
        with_tangent: bool,
    ) -> Option<Response> {
        let mut r = self.isochoric(h, with_tangent)?;
        let v = volumetric.plus_quadratic(self.split().rest, volume.jm1);
        r.energy += v.energy;
        r.stress += (v.stress_slope * volume.j) * volume.gt;
        if let Some(t) = r.tangent.as_mut() {
            *t += volumetric_tangent(&volume.gt, volume.j, v.tangent_slope, v.tangent_curvature);
        }
        Some(r)
    }

    /// `kappa - kappa_s` of [`BulkSplit`].
    fn bulk(&self) -> f64 {
        self.split().primary
    }

    fn volumetric(&self) -> Volumetric {
        Volumetric::Linear
    }

    fn rest_param_gradient(&self, h: &Mat3) -> Option<RestParamGradient> {
        let pr = Principal::new(h)?;
        let lbar = &pr.deviatoric;
        let mut energy = Vec::with_capacity(2 * self.terms + 1);
        let mut stress = Vec::with_capacity(2 * self.terms + 1);
        for (&mu, &alpha) in self.mu().iter().zip(self.alpha()) {
            let (em1, s_minus_3) = term_values(alpha, lbar);
            let dev = deviator(&em1);
            // dS̄/dalpha = sum_i l̄_i e_i = sum_i l̄_i (e_i - 1), second order in the strain.
            let ds: f64 = (0..3).map(|i| lbar[i] * em1[i]).sum();
            let weighted: [f64; 3] = std::array::from_fn(|i| lbar[i] * (1.0 + em1[i]));
            let weighted_mean = weighted.iter().sum::<f64>() / 3.0;
            let a2 = alpha * alpha;
            energy.push(2.0 / a2 * s_minus_3);
            energy.push(mu * (-4.0 / (a2 * alpha) * s_minus_3 + 2.0 / a2 * ds));
            stress.push(pr.stress(&dev.map(|x| 2.0 / alpha * x)));
            let dtau: [f64; 3] = std::array::from_fn(|i| {
                2.0 * mu * (-dev[i] / a2 + (weighted[i] - weighted_mean) / alpha)
            });
            stress.push(pr.stress(&dtau));
        }
        energy.push(0.0);
        stress.push(Mat3::zeros());
        let (d_shear, d_bulk) = self.moduli_gradients();
        let volume = VolumeState::new(h)?;
        self.split()
            .add_rest_param_gradient(&volume, &d_shear, &d_bulk, &mut energy, &mut stress);
        Some(RestParamGradient { energy, stress })
    }

    fn bulk_param_gradient(&self) -> Vec<f64> {
        let (d_shear, d_bulk) = self.moduli_gradients();
        self.split().primary_gradient(&d_shear, &d_bulk)
    }
}
