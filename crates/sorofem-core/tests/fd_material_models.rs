//! Finite-difference and analytic checks of the Mooney-Rivlin, Yeoh and Ogden models through the
//! `Hyperelastic` interface: energy -> stress -> tangent, parameter derivatives, the rest state,
//! the small-strain limit, objectivity and isotropy, and the identities between the models.
mod common;

use common::{check_gradient, check_jacobian, Rng};
use nalgebra::{Rotation3, Vector3};
use sorofem_core::material::{Hyperelastic, Mat3, MooneyRivlin, NeoHookean, Ogden, Tangent, Yeoh};

fn flat(m: &Mat3) -> Vec<f64> {
    // Row-major: entry (i, j) at 3 i + j, the convention of the tangent.
    (0..9).map(|k| m[(k / 3, k % 3)]).collect()
}

fn unflat(v: &[f64]) -> Mat3 {
    Mat3::from_fn(|i, j| v[3 * i + j])
}

fn tangent_flat(t: &Tangent) -> Vec<f64> {
    (0..81).map(|k| t[(k / 9, k % 9)]).collect()
}

#[derive(Clone, Copy, Debug)]
enum Kind {
    MooneyRivlin,
    Yeoh,
    Ogden,
}

fn build(kind: Kind, params: &[f64]) -> sorofem_core::Result<Box<dyn Hyperelastic>> {
    Ok(match kind {
        Kind::MooneyRivlin => Box::new(MooneyRivlin::try_new(params)?),
        Kind::Yeoh => Box::new(Yeoh::try_new(params)?),
        Kind::Ogden => Box::new(Ogden::try_new(params)?),
    })
}

/// Parameter sets with silicone-like moduli (1e4 Pa) and a bulk modulus ten times the shear one,
/// including the sign patterns fits produce (c01 < 0, c20 < 0, negative exponents, alpha = 1).
fn parameter_sets() -> Vec<(Kind, Vec<f64>)> {
    vec![
        (Kind::MooneyRivlin, vec![2.0e4, 5.0e3, 4.0e-6]),
        (Kind::MooneyRivlin, vec![3.0e4, -6.0e3, 4.0e-6]),
        (Kind::Yeoh, vec![2.0e4, -1.5e3, 2.0e2, 5.0e-6, 0.0, 0.0]),
        (
            Kind::Yeoh,
            vec![1.2e4, 8.0e2, -40.0, 8.0e-6, 2.0e-6, 1.0e-6],
        ),
        (Kind::Ogden, vec![4.0e4, 2.5, 5.0e-6]),
        (Kind::Ogden, vec![3.0e4, 1.0, 6.0e-6]),
        (Kind::Ogden, vec![3.0e4, 1.8, 1.0e4, -2.2, 5.0e-6]),
        (
            Kind::Ogden,
            vec![2.5e4, 1.3, 6.0e2, 5.0, -4.0e2, -2.0, 5.0e-6],
        ),
        (Kind::Ogden, vec![-1.0e3, 8.0, 2.0e4, 0.7, 5.0e-6]),
    ]
}

fn rotation(rng: &mut Rng) -> Mat3 {
    let axis_angle = Vector3::new(rng.next(), rng.next(), rng.next()) * 2.5;
    *Rotation3::new(axis_angle).matrix()
}

/// `R diag(stretch) Q^T` with random rotations R, Q.
fn rotated_stretch(rng: &mut Rng, stretch: [f64; 3]) -> Mat3 {
    let (r, q) = (rotation(rng), rotation(rng));
    r * Mat3::from_diagonal(&Vector3::from(stretch)) * q.transpose()
}

/// The deformations every model is checked at: near rest, moderate and large random strains,
/// compression, rotations times stretches, and two, three and nearly equal principal stretches.
fn deformations(rng: &mut Rng) -> Vec<(String, Mat3)> {
    let mut cases = vec![("rest".to_string(), Mat3::identity())];
    for (label, amplitude) in [("near rest", 1e-3), ("moderate", 0.2), ("large", 0.5)] {
        let mut found = 0;
        while found < 3 {
            let f = Mat3::identity() + Mat3::from_iterator(rng.vec(9, amplitude));
            if f.determinant() > 0.3 {
                cases.push((format!("{label} {found}"), f));
                found += 1;
            }
        }
    }
    let stretches: [(&str, [f64; 3]); 13] = [
        ("compression", [0.7, 0.8, 0.9]),
        ("uniaxial compression", [0.6, 1.15, 1.2]),
        ("rotation times stretch", [1.6, 0.9, 1.1]),
        ("pure rotation", [1.0, 1.0, 1.0]),
        ("two equal", [1.3, 1.3, 0.8]),
        ("two equal compressed", [0.7, 0.9, 0.9]),
        ("three equal", [1.1, 1.1, 1.1]),
        ("three equal compressed", [0.85, 0.85, 0.85]),
        ("clustered", [1.1, 1.1 + 1e-7, 1.1 - 1e-7]),
        ("tightly clustered", [1.1, 1.1 + 3e-8, 1.1 - 1e-8]),
        ("nearly equal", [1.2, 1.2 + 1e-8, 0.9]),
        ("nearly three equal", [1.0, 1.0 + 1e-8, 1.0 - 1e-8]),
        ("near rest, equal", [1.0 + 1e-3, 1.0 + 1e-3, 1.0 - 2e-3]),
    ];
    for (label, s) in stretches {
        cases.push((label.to_string(), rotated_stretch(rng, s)));
    }
    cases
}

/// Energy -> stress and stress -> tangent by central differences, for `rest` and `response`;
/// the tangent is also symmetric.
fn check_derivatives(name: &str, model: &dyn Hyperelastic, f: &Mat3, full: bool) {
    let eval = |x: &Mat3, tangent: bool| {
        let h = x - Mat3::identity();
        if full {
            model.response(&h, tangent)
        } else {
            model.rest(&h, tangent)
        }
        .unwrap()
    };
    let r = eval(f, true);
    let t = r.tangent.unwrap();
    // Where P vanishes (the rest state, pure rotations) the difference quotient's own error is
    // all that is left: truncation of order |A| h^2 and round-off of order eps |A| |H|^2 / h (the
    // energy is evaluated from terms of size |A| |H|^2), an absolute floor on those scales.
    check_gradient(
        &format!("{name}: dW/dF"),
        &flat(f),
        1e-6,
        |x| eval(&unflat(x), false).energy,
        &flat(&r.stress),
        1e-7,
        t.norm() * (1e-11 + 1e-9 * (f - Mat3::identity()).norm_squared()),
    );
    check_jacobian(
        &format!("{name}: dP/dF"),
        &flat(f),
        1e-6,
        |x| flat(&eval(&unflat(x), false).stress),
        &tangent_flat(&t),
        1e-7,
        0.0,
    );
    let asymmetry = (t - t.transpose()).norm();
    assert!(
        asymmetry <= 1e-12 * t.norm(),
        "{name}: tangent asymmetric by {asymmetry:.3e} (norm {:.3e})",
        t.norm()
    );
}

#[test]
fn energy_stress_and_tangent_match_finite_differences() {
    let mut rng = Rng::new(23);
    let cases = deformations(&mut rng);
    for (kind, params) in parameter_sets() {
        let model = build(kind, &params).unwrap();
        for (label, f) in &cases {
            for full in [false, true] {
                let part = if full { "response" } else { "rest" };
                let name = format!("{kind:?} {params:?} {part} at {label}");
                check_derivatives(&name, model.as_ref(), f, full);
            }
        }
    }
}

#[test]
fn parameter_derivatives_match_finite_differences() {
    let mut rng = Rng::new(29);
    let cases = deformations(&mut rng);
    for (kind, params) in parameter_sets() {
        let model = build(kind, &params).unwrap();
        // Every parameter is varied relative to its value (the compressibilities are ~1e-6).
        let scaled =
            |x: &[f64]| -> Vec<f64> { x.iter().zip(&params).map(|(s, p)| s * p).collect() };
        let ones = vec![1.0; params.len()];
        let n = params.len();
        for (label, f) in &cases {
            let h = f - Mat3::identity();
            let name = format!("{kind:?} {params:?} at {label}");
            let g = model.rest_param_gradient(&h).unwrap();
            assert_eq!(g.energy.len(), n);
            assert_eq!(g.stress.len(), n);
            let energy: Vec<f64> = (0..n).map(|k| g.energy[k] * params[k]).collect();
            check_gradient(
                &format!("{name}: dW_rest/dtheta"),
                &ones,
                1e-6,
                |x| {
                    build(kind, &scaled(x))
                        .unwrap()
                        .rest(&h, false)
                        .unwrap()
                        .energy
                },
                &energy,
                1e-7,
                1e-12 * model.rest(&h, false).unwrap().energy.abs(),
            );
            let mut jac = vec![0.0; 9 * n];
            for k in 0..n {
                for (entry, v) in flat(&g.stress[k]).iter().enumerate() {
                    jac[entry * n + k] = v * params[k];
                }
            }
            check_jacobian(
                &format!("{name}: dP_rest/dtheta"),
                &ones,
                1e-6,
                |x| {
                    flat(
                        &build(kind, &scaled(x))
                            .unwrap()
                            .rest(&h, false)
                            .unwrap()
                            .stress,
                    )
                },
                &jac,
                1e-7,
                0.0,
            );
        }
        let bulk: Vec<f64> = model
            .bulk_param_gradient()
            .iter()
            .zip(&params)
            .map(|(d, p)| d * p)
            .collect();
        check_gradient(
            &format!("{kind:?} {params:?}: dkappa/dtheta"),
            &ones,
            1e-6,
            |x| build(kind, &scaled(x)).unwrap().bulk(),
            &bulk,
            1e-7,
            0.0,
        );
        assert_eq!(model.param_names().len(), n);
    }
}

/// `P(I) = 0` and a symmetric tangent at rest, for the rest part and the full density.
#[test]
fn rest_state_is_stress_free_with_a_symmetric_tangent() {
    for (kind, params) in parameter_sets() {
        let model = build(kind, &params).unwrap();
        for r in [
            model.rest(&Mat3::zeros(), true).unwrap(),
            model.response(&Mat3::zeros(), true).unwrap(),
        ] {
            let t = r.tangent.unwrap();
            assert_eq!(r.energy, 0.0, "{kind:?} {params:?}");
            assert!(
                r.stress.norm() <= 1e-15 * t.norm(),
                "{kind:?} {params:?}: P(I) = {}",
                r.stress
            );
            assert!((t - t.transpose()).norm() <= 1e-14 * t.norm());
        }
    }
}

/// `mu (II + T) + (K - 2 mu / 3) I⊗I` with `T_(ij)(kl) = δ_il δ_kj`: linear isotropic elasticity.
fn linear_elastic_tangent(mu: f64, bulk: f64) -> Tangent {
    let delta = |a: usize, b: usize| if a == b { 1.0 } else { 0.0 };
    Tangent::from_fn(|r, c| {
        let (i, j, k, l) = (r / 3, r % 3, c / 3, c % 3);
        mu * (delta(i, k) * delta(j, l) + delta(i, l) * delta(k, j))
            + (bulk - 2.0 / 3.0 * mu) * delta(i, j) * delta(k, l)
    })
}

/// The small-strain shear modulus of each parameter set as the issue states it.
fn shear_modulus(kind: Kind, p: &[f64]) -> f64 {
    match kind {
        Kind::MooneyRivlin => 2.0 * (p[0] + p[1]),
        Kind::Yeoh => 2.0 * p[0],
        Kind::Ogden => p[..p.len() - 1].iter().step_by(2).sum(),
    }
}

#[test]
fn small_strain_limit_is_linear_elasticity() {
    for (kind, params) in parameter_sets() {
        let model = build(kind, &params).unwrap();
        let d1 = params[model.param_names().iter().position(|n| n == "d1").unwrap()];
        let expected = linear_elastic_tangent(shear_modulus(kind, &params), 2.0 / d1);
        let t = model
            .response(&Mat3::zeros(), true)
            .unwrap()
            .tangent
            .unwrap();
        let err = (t - expected).norm();
        assert!(
            err <= 1e-10 * expected.norm(),
            "{kind:?} {params:?}: tangent at rest off linear elasticity by {err:.3e}"
        );
        // The primary volumetric term is the part of 2/d1 the rest part does not carry
        // (BulkSplit): kappa_s = a kappa / (a + kappa), a = 2 mu / 3.
        let (a, kappa) = (2.0 / 3.0 * shear_modulus(kind, &params), 2.0 / d1);
        let primary = kappa - a * kappa / (a + kappa);
        assert!((model.bulk() - primary).abs() <= 1e-14 * kappa);
        assert!(model.bulk() > 0.0 && model.bulk() < kappa);
    }
}

/// At `H = s H0` with `s = 1e-6`, `W / s^2` and `P / s` approach the quadratic form and linear map
/// of the rest tangent to O(s): the energy keeps full relative precision at small strain (a naive
/// `J^(-2/3) I1 - 3` loses it to round-off of order 1e-16 / s^2 = 1e-4).
#[test]
fn tiny_strains_keep_relative_precision() {
    let mut rng = Rng::new(31);
    let s = 1e-6;
    for (kind, params) in parameter_sets() {
        let model = build(kind, &params).unwrap();
        for _ in 0..3 {
            let h0 = Mat3::from_iterator(rng.vec(9, 0.5));
            for full in [false, true] {
                let eval = |h: &Mat3, t: bool| {
                    if full {
                        model.response(h, t)
                    } else {
                        model.rest(h, t)
                    }
                    .unwrap()
                };
                let a0 = eval(&Mat3::zeros(), true).tangent.unwrap();
                let x = nalgebra::SVector::<f64, 9>::from_vec(flat(&h0));
                let linear = a0 * x;
                let quadratic = 0.5 * x.dot(&linear);
                let r = eval(&(h0 * s), false);
                let energy_err = (r.energy / (s * s) - quadratic).abs() / quadratic.abs();
                let stress_err =
                    (nalgebra::SVector::<f64, 9>::from_vec(flat(&r.stress)) / s - linear).norm()
                        / linear.norm();
                assert!(
                    energy_err < 2e-5 && stress_err < 2e-5,
                    "{kind:?} {params:?} (full {full}): relative errors energy {energy_err:.2e}, stress {stress_err:.2e}"
                );
            }
        }
    }
}

/// The energies are exactly the formulas, evaluated here the naive way from the
/// invariants and the eigenvalues of C at strains where that is accurate.
#[test]
fn energies_match_their_defining_formulas() {
    let mut rng = Rng::new(37);
    let cases = deformations(&mut rng);
    for (kind, p) in parameter_sets() {
        let model = build(kind, &p).unwrap();
        // Where W is of order round-off the relative comparison says nothing.
        let informative = cases
            .iter()
            .filter(|(l, _)| !l.contains("rest") && !l.contains("nearly") && l != "pure rotation");
        for (label, f) in informative {
            let c = f.transpose() * f;
            let j = f.determinant();
            let i1 = c.trace();
            let i2 = 0.5 * (i1 * i1 - (c * c).trace());
            let (b1, b2) = (j.powf(-2.0 / 3.0) * i1, j.powf(-4.0 / 3.0) * i2);
            let expected = match kind {
                Kind::MooneyRivlin => {
                    p[0] * (b1 - 3.0) + p[1] * (b2 - 3.0) + (j - 1.0).powi(2) / p[2]
                }
                Kind::Yeoh => {
                    let mut w = (1..=3)
                        .map(|i| p[i - 1] * (b1 - 3.0).powi(i as i32))
                        .sum::<f64>();
                    for (i, &d) in p[3..].iter().enumerate() {
                        if d != 0.0 {
                            w += (j - 1.0).powi(2 * (i as i32 + 1)) / d;
                        }
                    }
                    w
                }
                Kind::Ogden => {
                    let stretches = c
                        .symmetric_eigenvalues()
                        .map(|c| c.sqrt() * j.powf(-1.0 / 3.0));
                    let terms = (p.len() - 1) / 2;
                    (0..terms)
                        .map(|t| {
                            let (mu, alpha) = (p[2 * t], p[2 * t + 1]);
                            2.0 * mu / (alpha * alpha)
                                * (stretches.map(|l| l.powf(alpha)).sum() - 3.0)
                        })
                        .sum::<f64>()
                        + (j - 1.0).powi(2) / p[p.len() - 1]
                }
            };
            let w = model
                .response(&(f - Mat3::identity()), false)
                .unwrap()
                .energy;
            assert!(
                (w - expected).abs() <= 1e-10 * expected.abs(),
                "{kind:?} {p:?} at {label}: W = {w:.15e}, formula {expected:.15e}"
            );
        }
    }
}

/// `W(R F) = W(F)`, `P(R F) = R P(F)` (objectivity) and `W(F Q) = W(F)`, `P(F Q) = P(F) Q`
/// (isotropy) for random rotations R, Q.
#[test]
fn objective_and_isotropic() {
    let mut rng = Rng::new(41);
    let cases = deformations(&mut rng);
    for (kind, params) in parameter_sets() {
        let model = build(kind, &params).unwrap();
        for (label, f) in &cases {
            let (r, q) = (rotation(&mut rng), rotation(&mut rng));
            let at = |x: &Mat3| model.response(&(x - Mat3::identity()), false).unwrap();
            let base = at(f);
            // Rotating F makes H = F - I of order one, whose energy carries round-off of order
            // eps |A| |F|^2 (A the tangent) whatever the strain: the tolerances' floor.
            let stiffness = model
                .response(&Mat3::zeros(), true)
                .unwrap()
                .tangent
                .unwrap()
                .norm();
            let energy_tol = 1e-11 * base.energy.abs() + 1e-13 * stiffness * f.norm_squared();
            let stress_tol = 1e-10 * base.stress.norm() + 1e-13 * stiffness * f.norm();
            for (what, w, p) in [
                (
                    "objectivity",
                    at(&(r * f)),
                    r.transpose() * at(&(r * f)).stress,
                ),
                (
                    "isotropy",
                    at(&(f * q)),
                    at(&(f * q)).stress * q.transpose(),
                ),
            ] {
                assert!(
                    (w.energy - base.energy).abs() <= energy_tol,
                    "{kind:?} {params:?} {what} at {label}: W {:.15e} vs {:.15e}",
                    w.energy,
                    base.energy
                );
                assert!(
                    (p - base.stress).norm() <= stress_tol,
                    "{kind:?} {params:?} {what} at {label}: stress off by {:.3e}",
                    (p - base.stress).norm()
                );
            }
        }
    }
}

/// Two models agree in energy, stress and tangent (full density) at every test deformation.
fn assert_same_model(name: &str, a: &dyn Hyperelastic, b: &dyn Hyperelastic) {
    let mut rng = Rng::new(43);
    for (label, f) in deformations(&mut rng) {
        let h = f - Mat3::identity();
        let (ra, rb) = (a.response(&h, true).unwrap(), b.response(&h, true).unwrap());
        let (ta, tb) = (ra.tangent.unwrap(), rb.tangent.unwrap());
        let scale = ta.norm();
        assert!(
            (ra.energy - rb.energy).abs() <= 1e-12 * scale,
            "{name} at {label}: W {:.15e} vs {:.15e}",
            ra.energy,
            rb.energy
        );
        assert!(
            (ra.stress - rb.stress).norm() <= 1e-12 * scale,
            "{name} at {label}: stress differs by {:.3e}",
            (ra.stress - rb.stress).norm()
        );
        assert!(
            (ta - tb).norm() <= 1e-11 * scale,
            "{name} at {label}: tangent differs by {:.3e} of {scale:.3e}",
            (ta - tb).norm()
        );
        assert_eq!(a.bulk(), b.bulk());
    }
}

/// Ogden `alpha = 2` is Mooney-Rivlin `c10 = mu/2`; `alpha = -2` is `c01 = mu/2` (because
/// `sum λ̄_i^-2 = Ī2` when `λ̄1 λ̄2 λ̄3 = 1`); the two together are the full Mooney-Rivlin.
/// Yeoh with `c20 = c30 = 0` (no d2, d3 terms) is Mooney-Rivlin with `c01 = 0`.
#[test]
fn models_reduce_to_each_other() {
    let (mu1, mu2, d1) = (3.0e4, 8.0e3, 5.0e-6);
    let mr = |p: &[f64]| MooneyRivlin::try_new(p).unwrap();
    let ogden = |p: &[f64]| Ogden::try_new(p).unwrap();
    assert_same_model(
        "Ogden alpha = 2",
        &ogden(&[mu1, 2.0, d1]),
        &mr(&[mu1 / 2.0, 0.0, d1]),
    );
    assert_same_model(
        "Ogden alpha = -2",
        &ogden(&[mu2, -2.0, d1]),
        &mr(&[0.0, mu2 / 2.0, d1]),
    );
    assert_same_model(
        "Ogden alpha = 2, -2",
        &ogden(&[mu1, 2.0, mu2, -2.0, d1]),
        &mr(&[mu1 / 2.0, mu2 / 2.0, d1]),
    );
    assert_same_model(
        "Yeoh c20 = c30 = 0",
        &Yeoh::try_new(&[mu1, 0.0, 0.0, d1, 0.0, 0.0]).unwrap(),
        &mr(&[mu1, 0.0, d1]),
    );
}

/// `d2 = 0` and `d3 = 0` mean "no such term": the energy is that of a vanishing `1/d` term.
#[test]
fn yeoh_zero_higher_compressibility_means_no_term() {
    let f = Mat3::new(1.2, 0.1, 0.0, -0.05, 0.8, 0.2, 0.1, 0.0, 0.9);
    let h = f - Mat3::identity();
    let with = |d2: f64, d3: f64| {
        Yeoh::try_new(&[2e4, -1e3, 1e2, 5e-6, d2, d3])
            .unwrap()
            .response(&h, false)
            .unwrap()
            .energy
    };
    let absent = with(0.0, 0.0);
    assert!((absent - with(1e300, 1e300)).abs() <= 1e-14 * absent);
    assert!(with(1e-6, 0.0) > absent && with(0.0, 1e-6) > absent);
}

#[test]
fn bad_parameters_name_the_parameter() {
    let nan = f64::NAN;
    let cases: [(Kind, Vec<f64>, &str); 18] = [
        (Kind::MooneyRivlin, vec![1e4, -2e4, 1e-6], "c10"),
        (Kind::MooneyRivlin, vec![1e4, 0.0, 0.0], "d1"),
        (Kind::MooneyRivlin, vec![1e4, 0.0, -1e-6], "d1"),
        (Kind::MooneyRivlin, vec![nan, 0.0, 1e-6], "c10"),
        (Kind::MooneyRivlin, vec![1e4, f64::INFINITY, 1e-6], "c01"),
        (Kind::MooneyRivlin, vec![1e4, 1e-6], "params"),
        (Kind::Yeoh, vec![0.0, 0.0, 0.0, 1e-6, 0.0, 0.0], "c10"),
        (Kind::Yeoh, vec![-1e4, 1e5, 0.0, 1e-6, 0.0, 0.0], "c10"),
        (Kind::Yeoh, vec![1e4, 0.0, 0.0, 0.0, 0.0, 0.0], "d1"),
        (Kind::Yeoh, vec![1e4, 0.0, 0.0, 1e-6, -1e-6, 0.0], "d2"),
        (Kind::Yeoh, vec![1e4, 0.0, 0.0, 1e-6, 0.0, nan], "d3"),
        (Kind::Yeoh, vec![1e4, 0.0, 0.0, 1e-6], "params"),
        (Kind::Ogden, vec![1e4, 0.0, 1e-6], "alpha:0"),
        (Kind::Ogden, vec![1e4, 2.0, -1e4, 3.0, 1e-6], "mu:0"),
        (Kind::Ogden, vec![1e4, 2.0, 1e4, nan, 1e-6], "alpha:1"),
        (Kind::Ogden, vec![1e4, 2.0, 0.0], "d1"),
        (Kind::Ogden, vec![1e4, 2.0, 1e4, 1e-6], "params"),
        (
            Kind::Ogden,
            vec![1e4, 2.0, 1e4, 2.0, 1e4, 2.0, 1e4, 2.0, 1e-6],
            "params",
        ),
    ];
    for (kind, params, name) in cases {
        let message = match build(kind, &params) {
            Ok(_) => panic!("{kind:?} {params:?} accepted"),
            Err(e) => e.to_string(),
        };
        assert!(
            message.starts_with(&format!("`{name}`: expected")),
            "{kind:?} {params:?}: {message}"
        );
    }
    let message = Ogden::try_from_terms(&[1e4, 1e3], &[2.0], 1e-6)
        .unwrap_err()
        .to_string();
    assert!(message.starts_with("`alpha`: expected"), "{message}");
    let message = Ogden::try_from_terms(&[1e4; 4], &[2.0; 4], 1e-6)
        .unwrap_err()
        .to_string();
    assert!(message.starts_with("`mu`: expected"), "{message}");
}

/// Kernel cost per call relative to `NeoHookean::response(f, true)` (printed, not asserted:
/// speed is measured by benchmarks). Each ratio is the fastest of interleaved rounds of both
/// kernels, so that load from other processes affects them alike. Run with
/// `cargo test --release -p sorofem-core --test fd_material_models -- --ignored --nocapture`.
#[test]
#[ignore]
fn kernel_cost_relative_to_neo_hookean() {
    use std::hint::black_box;
    use std::time::Instant;
    let mut rng = Rng::new(47);
    let hs: Vec<Mat3> = (0..64)
        .map(|_| Mat3::from_iterator(rng.vec(9, 0.3)))
        .filter(|h| (Mat3::identity() + h).determinant() > 0.3)
        .collect();
    let calls = 2_000;
    let time = |f: &dyn Fn(&Mat3) -> f64| {
        let start = Instant::now();
        let mut acc = 0.0;
        for k in 0..calls {
            acc += f(black_box(&hs[k % hs.len()]));
        }
        black_box(acc);
        start.elapsed().as_secs_f64() / calls as f64
    };
    let neo = NeoHookean {
        mu: 4e4,
        lambda: 4e5,
        volumetric: sorofem_core::material::Volumetric::Linear,
    };
    let neo_kernel = |h: &Mat3| {
        let r = neo.response(&(Mat3::identity() + h), true).unwrap();
        r.tangent.unwrap()[(0, 0)]
    };
    for (kind, params) in parameter_sets() {
        let model = build(kind, &params).unwrap();
        for full in [false, true] {
            let kernel = |h: &Mat3| {
                let r = if full {
                    model.response(h, true)
                } else {
                    model.rest(h, true)
                };
                r.unwrap().tangent.unwrap()[(0, 0)]
            };
            let (mut reference, mut t) = (f64::INFINITY, f64::INFINITY);
            for _ in 0..250 {
                reference = reference.min(time(&neo_kernel));
                t = t.min(time(&kernel));
            }
            let part = if full { "response" } else { "rest" };
            println!(
                "{kind:?} {params:?} {part}: {:.0} ns vs {:.0} ns, {:.2}x",
                t * 1e9,
                reference * 1e9,
                t / reference
            );
        }
    }
}
