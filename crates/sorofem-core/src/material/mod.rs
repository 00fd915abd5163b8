//! Constitutive laws as pure functions of the deformation gradient F (3x3, dimensionless).
//!
//! Flattening convention for 3x3 tensors: entry (i, j) is component `3 i + j` of a 9-vector, so
//! a fourth-order tangent dP/dF is a 9x9 matrix `A[3i+j, 3k+l] = dP_ij / dF_kl`.
//!
//! Every model is one file implementing [`Hyperelastic`]; [`MaterialModel`] (the models a body
//! can be made of) and [`ElementMaterial`] (one element's model at its parameters) list them,
//! one arm each.

pub mod isochoric;
pub mod law;
pub mod mooney_rivlin;
pub mod neo_hookean;
pub mod ogden;
pub mod yeoh;

pub use law::{Hyperelastic, RestParamGradient, VolumeState, VolumetricTerm};
pub use mooney_rivlin::MooneyRivlin;
pub use neo_hookean::{NeoHookean, Response, Volumetric};
pub use ogden::Ogden;
pub use yeoh::Yeoh;

use crate::error::{Error, Result};

/// The hyperelastic models a body can be made of, with their model-wide options. Per-element
/// parameters are stored apart, flat, in the order of [`MaterialModel::param_names`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MaterialModel {
    /// Compressible Neo-Hookean ([`NeoHookean`]): `mu`, `lambda` (Pa).
    NeoHookean { volumetric: Volumetric },
    /// Decoupled Mooney-Rivlin ([`MooneyRivlin`]): `c10`, `c01` (Pa), `d1` (1/Pa).
    MooneyRivlin,
    /// Decoupled Yeoh ([`Yeoh`]): `c10`, `c20`, `c30` (Pa), `d1`, `d2`, `d3` (1/Pa).
    Yeoh,
    /// Decoupled Ogden ([`Ogden`]) of `terms` (1 to 3) terms: `mu:p` (Pa), `alpha:p`, then `d1`
    /// (1/Pa). Build it with [`MaterialModel::ogden`].
    Ogden { terms: usize },
}

impl MaterialModel {
    /// The Ogden model of `terms` terms; an error unless `1 <= terms <= 3`.
    pub fn ogden(terms: usize) -> Result<Self> {
        if (1..=ogden::MAX_TERMS).contains(&terms) {
            Ok(MaterialModel::Ogden { terms })
        } else {
            Err(Error::invalid("terms", "1, 2 or 3 Ogden terms", terms))
        }
    }

    /// The model's name as the bindings spell it.
    pub fn name(&self) -> &'static str {
        match self {
            MaterialModel::NeoHookean { .. } => "neo_hookean",
            MaterialModel::MooneyRivlin => "mooney_rivlin",
            MaterialModel::Yeoh => "yeoh",
            MaterialModel::Ogden { .. } => "ogden",
        }
    }

    /// Parameter names, in storage order.
    pub fn param_names(&self) -> Vec<String> {
        let names: &[&str] = match self {
            MaterialModel::NeoHookean { .. } => &NeoHookean::PARAM_NAMES,
            MaterialModel::MooneyRivlin => &MooneyRivlin::PARAM_NAMES,
            MaterialModel::Yeoh => &Yeoh::PARAM_NAMES,
            MaterialModel::Ogden { terms } => return Ogden::param_names_of(*terms),
        };
        names.iter().map(|s| s.to_string()).collect()
    }

    /// The number of parameters per element (cheap: element kernels ask it).
    #[inline]
    pub fn n_params(&self) -> usize {
        match self {
            MaterialModel::NeoHookean { .. } => NeoHookean::PARAM_NAMES.len(),
            MaterialModel::MooneyRivlin => MooneyRivlin::PARAM_NAMES.len(),
            MaterialModel::Yeoh => Yeoh::PARAM_NAMES.len(),
            MaterialModel::Ogden { terms } => 2 * terms + 1,
        }
    }

    /// The measure `c(J)` of the primary volumetric term (the same for every element): the
    /// decoupled models' is `J - 1`.
    pub fn volumetric(&self) -> Volumetric {
        match self {
            MaterialModel::NeoHookean { volumetric } => *volumetric,
            _ => Volumetric::Linear,
        }
    }

    /// One element's material from its parameters (`n_params()` values, already validated by
    /// [`MaterialModel::try_at`]).
    #[inline]
    pub fn at(&self, params: &[f64]) -> ElementMaterial {
        match *self {
            MaterialModel::NeoHookean { volumetric } => ElementMaterial::NeoHookean(NeoHookean {
                mu: params[0],
                lambda: params[1],
                volumetric,
            }),
            MaterialModel::MooneyRivlin => ElementMaterial::MooneyRivlin(MooneyRivlin {
                c10: params[0],
                c01: params[1],
                d1: params[2],
            }),
            MaterialModel::Yeoh => ElementMaterial::Yeoh(Yeoh {
                c10: params[0],
                c20: params[1],
                c30: params[2],
                d1: params[3],
                d2: params[4],
                d3: params[5],
            }),
            MaterialModel::Ogden { .. } => ElementMaterial::Ogden(Ogden::from_validated(params)),
        }
    }

    /// [`MaterialModel::at`] after the model's own checks, and for the mixed formulation (whose
    /// pressure compliance is `M_p / kappa`) a positive finite `kappa`. Errors name the
    /// parameter.
    ///
    /// The decoupled models need `d1 > 0` in both formulations: `kappa = 2 / d1`, so the mixed
    /// compliance is `d1 / 2` and `d1 -> 0` approaches incompressibility, but `d1 = 0` has no
    /// bulk modulus for the standard formulation nor a pressure mode control for the P1-P1 mixed
    /// one. Yeoh's higher terms `(J - 1)^4 / d2` and `(J - 1)^6 / d3` stay in the rest part in
    /// the mixed formulation (evaluated from the displacements): they have no stiffness at
    /// `J = 1`, so they cannot lock, and only the primary term becomes the pressure field.
    pub fn try_at(&self, params: &[f64], mixed: bool) -> Result<ElementMaterial> {
        let n = self.n_params();
        if params.len() != n {
            return Err(Error::shape(
                "params",
                format!("{n} values [{}]", self.param_names().join(", ")),
                format!("{} values", params.len()),
            ));
        }
        match *self {
            MaterialModel::NeoHookean { volumetric } => {
                let material = NeoHookean::try_new(params, volumetric)?;
                if mixed && !(material.lambda > 0.0) {
                    return Err(Error::invalid(
                        "lambda",
                        "Lame lambda > 0 Pa in the mixed formulation (0 < nu < 0.5; nu = 0.5 has no finite \
                         lambda and leaves the P1-P1 pressure modes uncontrolled)",
                        material.lambda,
                    ));
                }
                Ok(ElementMaterial::NeoHookean(material))
            }
            MaterialModel::MooneyRivlin => {
                MooneyRivlin::try_new(params).map(ElementMaterial::MooneyRivlin)
            }
            MaterialModel::Yeoh => Yeoh::try_new(params).map(ElementMaterial::Yeoh),
            MaterialModel::Ogden { .. } => Ogden::try_new(params).map(ElementMaterial::Ogden),
        }
    }
}

/// One element's material: a model at its parameter values.
#[derive(Clone, Copy, Debug)]
pub enum ElementMaterial {
    NeoHookean(NeoHookean),
    MooneyRivlin(MooneyRivlin),
    Yeoh(Yeoh),
    Ogden(Ogden),
}

/// `$body` with `$m` bound to the model of every arm of an [`ElementMaterial`].
macro_rules! each_model {
    ($material:expr, $m:ident => $body:expr) => {
        match $material {
            ElementMaterial::NeoHookean($m) => $body,
            ElementMaterial::MooneyRivlin($m) => $body,
            ElementMaterial::Yeoh($m) => $body,
            ElementMaterial::Ogden($m) => $body,
        }
    };
}

impl Hyperelastic for ElementMaterial {
    fn param_names(&self) -> Vec<String> {
        each_model!(self, m => m.param_names())
    }
    #[inline]
    fn rest(&self, h: &Mat3, with_tangent: bool) -> Option<Response> {
        each_model!(self, m => m.rest(h, with_tangent))
    }
    #[inline]
    fn rest_with_volumetric(
        &self,
        h: &Mat3,
        volume: &VolumeState,
        volumetric: &VolumetricTerm,
        with_tangent: bool,
    ) -> Option<Response> {
        each_model!(self, m => m.rest_with_volumetric(h, volume, volumetric, with_tangent))
    }
    #[inline]
    fn bulk(&self) -> f64 {
        each_model!(self, m => m.bulk())
    }
    #[inline]
    fn volumetric(&self) -> Volumetric {
        each_model!(self, m => Hyperelastic::volumetric(m))
    }
    fn rest_param_gradient(&self, h: &Mat3) -> Option<RestParamGradient> {
        each_model!(self, m => m.rest_param_gradient(h))
    }
    fn bulk_param_gradient(&self) -> Vec<f64> {
        each_model!(self, m => m.bulk_param_gradient())
    }
}

/// The small-strain shear modulus (Pa) of an isotropic model: `dP_01/dF_01` at rest, to which
/// the volumetric term contributes nothing.
pub fn shear_modulus(material: &impl Hyperelastic) -> f64 {
    material
        .rest(&Mat3::zeros(), true)
        .and_then(|r| r.tangent)
        .map_or(f64::NAN, |t| t[(1, 1)])
}

/// Cauchy stress `sigma = P F^T / J` (Pa) of the full density at F; `None` when `J <= 0`.
pub fn cauchy_stress(material: &impl Hyperelastic, f: &Mat3) -> Option<Mat3> {
    let r = material.response(&(f - Mat3::identity()), false)?;
    Some(r.stress * f.transpose() / f.determinant())
}

use nalgebra::{Matrix3, SMatrix, SymmetricEigen};

pub type Mat3 = Matrix3<f64>;
/// dP/dF as a 9x9 matrix (see the module docs for the index convention).
pub type Tangent = SMatrix<f64, 9, 9>;

/// Clamps the negative eigenvalues of a symmetric tangent to zero, so that the element Hessian
/// `V B^T A B` built from it is positive semi-definite (used when the exact Hessian is indefinite).
pub fn project_to_psd(a: &Tangent) -> Tangent {
    // Most elements of an indefinite Hessian are themselves definite: a 9x9 Cholesky
    // (about 250 flops) tells, and spares them the eigendecomposition (about 30x dearer).
    if nalgebra::linalg::Cholesky::new(*a).is_some() {
        return *a;
    }
    let eig = SymmetricEigen::new(*a);
    if eig.eigenvalues.iter().all(|&l| l >= 0.0) {
        return *a;
    }
    let mut clamped = eig.eigenvalues;
    clamped.iter_mut().for_each(|l| *l = l.max(0.0));
    eig.eigenvectors * SMatrix::<f64, 9, 9>::from_diagonal(&clamped) * eig.eigenvectors.transpose()
}

/// `F^{-T}` and `J = det F`; `None` when the element is inverted or flat (J <= 0).
///
/// From the cofactor matrix: its rows are cross products of the rows of F, `F^{-T} = cof F / J`
/// and `J` is a row of F dotted with its cofactor row (one pass, no separate determinant).
pub fn inverse_transpose(f: &Mat3) -> Option<(Mat3, f64)> {
    let rows = [
        f.row(0).transpose(),
        f.row(1).transpose(),
        f.row(2).transpose(),
    ];
    let cof = [
        rows[1].cross(&rows[2]),
        rows[2].cross(&rows[0]),
        rows[0].cross(&rows[1]),
    ];
    let j = rows[0].dot(&cof[0]);
    if !(j > 0.0) {
        return None;
    }
    let inv_j = 1.0 / j;
    Some((
        Mat3::from_rows(&[
            (cof[0] * inv_j).transpose(),
            (cof[1] * inv_j).transpose(),
            (cof[2] * inv_j).transpose(),
        ]),
        j,
    ))
}

/// The tangent of a volumetric energy density `h(J)`: with `G = F^{-T}`,
/// `dP_ij/dF_kl = (h'' J^2 + h' J) G_ij G_kl - h' J G_il G_kj`.
pub fn volumetric_tangent(g: &Mat3, j: f64, dh: f64, d2h: f64) -> Tangent {
    let a = d2h * j * j + dh * j;
    let b = dh * j;
    let mut t = Tangent::zeros();
    for i in 0..3 {
        for jj in 0..3 {
            for k in 0..3 {
                for l in 0..3 {
                    t[(3 * i + jj, 3 * k + l)] =
                        a * g[(i, jj)] * g[(k, l)] - b * g[(i, l)] * g[(k, jj)];
                }
            }
        }
    }
    t
}

/// The negative eigenpairs `(lambda_k, Q_k)` (`|Q_k| = 1`, Frobenius) of the isotropic tangent
/// `A = mu I + alpha T + beta O` at F, with `T_(ij)(kl) = G_il G_kj`, `O_(ij)(kl) = G_ij G_kl`,
/// `G = F^{-T}`: every Neo-Hookean tangent in this crate has this form.
///
/// With `F = U S V^T` and `d = 1/s`, A is block diagonal in the basis `u_i v_j^T` (Smith, de Goes
/// and Kim, "Analytic eigensystems for isotropic distortion energies", 2019): for each pair
/// `i < j` a twist mode `(u_i v_j^T - u_j v_i^T)/sqrt 2` with eigenvalue `mu - alpha d_i d_j` and
/// a flip mode `(u_i v_j^T + u_j v_i^T)/sqrt 2` with `mu + alpha d_i d_j`; on the stretches
/// `sum_i y_i u_i v_i^T` the 3x3 block `mu I + alpha diag(d^2) + beta d d^T`. So projecting A to
/// positive semi-definite costs a 3x3 SVD for the (few) indefinite elements and nothing for the
/// others, instead of a 9x9 eigendecomposition. Returns how many of `out` were written.
pub fn isotropic_tangent_negative_modes(
    f: &Mat3,
    mu: f64,
    alpha: f64,
    beta: f64,
    out: &mut [(f64, Mat3); 9],
) -> usize {
    // A cheap test on the singular values from the eigenvalues of F^T F first: most elements
    // are definite. The margin keeps round-off in that closed form from hiding a negative mode.
    let s2 = symmetric_eigenvalues(&(f.transpose() * f));
    let scale = mu.abs() + alpha.abs() + beta.abs();
    let margin = 1e-6 * scale;
    if s2.iter().all(|&v| v > 0.0) {
        let d: [f64; 3] = s2.map(|v| 1.0 / v.sqrt());
        let pairs_definite = [(0, 1), (0, 2), (1, 2)]
            .iter()
            .all(|&(i, j)| mu - alpha.abs() * d[i] * d[j] > margin);
        let block = stretch_block(mu, alpha, beta, &d);
        if pairs_definite && block_definite(&block, margin) {
            return 0;
        }
    }
    let (u, singular_values, v) = rotation_svd(f, &s2).unwrap_or_else(|| {
        let svd = f.svd(true, true);
        let (u, v_t) = (svd.u.expect("U requested"), svd.v_t.expect("V requested"));
        (u, svd.singular_values.into(), v_t.transpose())
    });
    let d: [f64; 3] = singular_values.map(|s| 1.0 / s);
    let mut n = 0;
    let outer = |a: usize, b: usize| u.column(a) * v.column(b).transpose();
    for (i, j) in [(0, 1), (0, 2), (1, 2)] {
        let coupling = alpha * d[i] * d[j];
        for (lambda, sign) in [(mu - coupling, -1.0), (mu + coupling, 1.0)] {
            if lambda < 0.0 {
                out[n] = (
                    lambda,
                    (outer(i, j) + sign * outer(j, i)) * std::f64::consts::FRAC_1_SQRT_2,
                );
                n += 1;
            }
        }
    }
    let block = stretch_block(mu, alpha, beta, &d);
    if block_definite(&block, 0.0) {
        return n;
    }
    let eig = nalgebra::SymmetricEigen::new(block);
    for k in 0..3 {
        if eig.eigenvalues[k] < 0.0 {
            let y = eig.eigenvectors.column(k);
            out[n] = (
                eig.eigenvalues[k],
                outer(0, 0) * y[0] + outer(1, 1) * y[1] + outer(2, 2) * y[2],
            );
            n += 1;
        }
    }
    n
}

/// `F = U diag(s) V^T` with `U`, `V` rotations and `s` positive, for `det F > 0`, from the
/// eigenvalues `c_eigenvalues` (largest first) of `C = F^T F` as [`symmetric_eigenvalues`] gives
/// them. The eigenvector of the best separated eigenvalue comes first, by cross products of the
/// rows of `C - lambda I` (that eigenvalue is also the one the closed form gets accurately; a
/// Rayleigh quotient refines it once); the other two from a Jacobi rotation of C restricted to
/// the orthogonal plane, which needs no eigenvalue at all and so stays accurate however close
/// they are. `U` follows from `F V` by Gram-Schmidt. About a tenth of the cost of an iterative
/// SVD. `None` (the caller falls back to the iterative SVD) when the three eigenvalues coincide
/// to round-off or `F V` is too close to rank deficient for Gram-Schmidt.
pub fn rotation_svd(f: &Mat3, c_eigenvalues: &[f64; 3]) -> Option<(Mat3, [f64; 3], Mat3)> {
    use nalgebra::Vector3;
    let c = f.transpose() * f;
    let [largest, middle, smallest] = *c_eigenvalues;
    if !(largest - smallest > 1e-12 * largest.abs()) {
        return None;
    }
    // The null vector of C - lambda I (rank 2 for a simple eigenvalue): the largest cross
    // product of two of its rows.
    let null_vector = |lambda: f64| -> Option<Vector3<f64>> {
        let m = c - Mat3::identity() * lambda;
        let rows = [
            m.row(0).transpose(),
            m.row(1).transpose(),
            m.row(2).transpose(),
        ];
        let candidates = [
            rows[0].cross(&rows[1]),
            rows[0].cross(&rows[2]),
            rows[1].cross(&rows[2]),
        ];
        let best = candidates
            .iter()
            .max_by(|a, b| a.norm_squared().total_cmp(&b.norm_squared()))?;
        let norm = best.norm();
        (norm > 0.0 && norm.is_finite()).then(|| best / norm)
    };
    let first_is_largest = largest - middle >= middle - smallest;
    let first = null_vector(if first_is_largest { largest } else { smallest })?;
    let first = null_vector(first.dot(&(c * first))).unwrap_or(first);
    // Orthonormal e1, e2 spanning the plane orthogonal to `first`, then the Jacobi rotation that
    // diagonalises [[e1.C e1, e1.C e2], [e1.C e2, e2.C e2]]: `wide` takes the larger eigenvalue.
    let helper = if first.x.abs() < 0.6 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let e1 = (helper - first * first.dot(&helper)).normalize();
    let e2 = first.cross(&e1);
    let (ce1, ce2) = (c * e1, c * e2);
    let (a, b, d) = (e1.dot(&ce1), e1.dot(&ce2), e2.dot(&ce2));
    let (sin, cos) = (0.5 * (2.0 * b).atan2(a - d)).sin_cos();
    let wide = e1 * cos + e2 * sin;
    // The third column as a cross product makes det V = +1.
    let (v_largest, v_middle, v_smallest) = if first_is_largest {
        (first, wide, first.cross(&wide))
    } else {
        let narrow = e2 * cos - e1 * sin;
        (narrow.cross(&first), narrow, first)
    };
    let v = Mat3::from_columns(&[v_largest, v_middle, v_smallest]);
    let columns = f * v;
    let (b0, b1, b2) = (columns.column(0), columns.column(1), columns.column(2));
    let s0 = b0.norm();
    let u0 = b0 / s0;
    let b1_orthogonal = b1 - u0 * u0.dot(&b1);
    let s1 = b1_orthogonal.norm();
    if !(s1 > 1e-8 * s0) || !s0.is_finite() {
        return None;
    }
    let u1 = b1_orthogonal / s1;
    let u2 = u0.cross(&u1);
    let s2 = u2.dot(&b2);
    if !(s2 > 0.0) {
        return None;
    }
    Some((Mat3::from_columns(&[u0, u1, u2]), [s0, s1, s2], v))
}

/// `mu I + alpha diag(d^2) + beta d d^T`: the tangent on the stretch modes.
fn stretch_block(mu: f64, alpha: f64, beta: f64, d: &[f64; 3]) -> Mat3 {
    let dv = nalgebra::Vector3::from(*d);
    Mat3::from_diagonal(&dv.component_mul(&dv)) * alpha
        + dv * dv.transpose() * beta
        + Mat3::identity() * mu
}

/// Whether a symmetric 3x3 matrix exceeds `margin` I (leading principal minors).
fn block_definite(m: &Mat3, margin: f64) -> bool {
    let shifted = m - Mat3::identity() * margin;
    let minor2 = shifted[(0, 0)] * shifted[(1, 1)] - shifted[(0, 1)] * shifted[(1, 0)];
    shifted[(0, 0)] > 0.0 && minor2 > 0.0 && shifted.determinant() > 0.0
}

/// Eigenvalues of a symmetric 3x3 matrix in closed form (trigonometric solution of the
/// characteristic cubic), accurate to round-off relative to the matrix norm.
pub fn symmetric_eigenvalues(c: &Mat3) -> [f64; 3] {
    let off = c[(0, 1)].powi(2) + c[(0, 2)].powi(2) + c[(1, 2)].powi(2);
    let q = c.trace() / 3.0;
    let diag = (c[(0, 0)] - q).powi(2) + (c[(1, 1)] - q).powi(2) + (c[(2, 2)] - q).powi(2);
    let p = ((diag + 2.0 * off) / 6.0).sqrt();
    if p == 0.0 {
        return [q; 3];
    }
    let b = (c - Mat3::identity() * q) / p;
    let r = (0.5 * b.determinant()).clamp(-1.0, 1.0);
    let phi = r.acos() / 3.0;
    let largest = q + 2.0 * p * phi.cos();
    let smallest = q + 2.0 * p * (phi + 2.0 * std::f64::consts::FRAC_PI_3).cos();
    [largest, 3.0 * q - largest - smallest, smallest]
}
