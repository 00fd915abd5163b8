//! Finite-difference checks of the Neo-Hookean density, stress and tangent.
mod common;

use common::{check_gradient, check_jacobian, Rng};
use sorofem_core::material::{project_to_psd, Mat3, NeoHookean, Volumetric};

fn random_f(rng: &mut Rng, amplitude: f64) -> Mat3 {
    Mat3::identity() + Mat3::from_iterator(rng.vec(9, amplitude))
}

fn flat(m: &Mat3) -> Vec<f64> {
    // Row-major: entry (i, j) at 3 i + j, the convention of the tangent.
    (0..9).map(|k| m[(k / 3, k % 3)]).collect()
}

fn unflat(v: &[f64]) -> Mat3 {
    Mat3::from_fn(|i, j| v[3 * i + j])
}

#[test]
fn stress_and_tangent_match_finite_differences() {
    let mut rng = Rng::new(7);
    for volumetric in [Volumetric::Log, Volumetric::Linear] {
        for trial in 0..20 {
            let material = NeoHookean {
                mu: 2.3e4,
                lambda: 4.1e5,
                volumetric,
            };
            let f = random_f(&mut rng, if trial < 10 { 0.2 } else { 0.5 });
            if f.determinant() < 0.2 {
                continue;
            }
            let r = material.response(&f, true).unwrap();
            check_gradient(
                "dpsi/dF",
                &flat(&f),
                1e-6,
                |x| material.energy_density(&unflat(x)),
                &flat(&r.stress),
                1e-7,
                0.0,
            );
            let tangent: Vec<f64> = (0..81)
                .map(|k| r.tangent.unwrap()[(k / 9, k % 9)])
                .collect();
            check_jacobian(
                "dP/dF",
                &flat(&f),
                1e-6,
                |x| flat(&material.response(&unflat(x), false).unwrap().stress),
                &tangent,
                1e-7,
                0.0,
            );
        }
    }
}

#[test]
fn shear_part_and_parameter_derivatives_match_finite_differences() {
    let mut rng = Rng::new(11);
    for volumetric in [Volumetric::Log, Volumetric::Linear] {
        let f = random_f(&mut rng, 0.3);
        let params = [3.0e4, 2.0e5];
        let density = |p: &[f64]| {
            NeoHookean {
                mu: p[0],
                lambda: p[1],
                volumetric,
            }
            .energy_density(&f)
        };
        let material = NeoHookean {
            mu: params[0],
            lambda: params[1],
            volumetric,
        };
        check_gradient(
            "dpsi/d(mu, lambda)",
            &params,
            1e-6,
            density,
            &material.energy_param_gradient(&f).unwrap(),
            1e-7,
            0.0,
        );
        let [dp_dmu, dp_dlambda] = material.stress_param_gradient(&f).unwrap();
        let mut jac = vec![0.0; 18];
        for k in 0..9 {
            jac[2 * k] = flat(&dp_dmu)[k];
            jac[2 * k + 1] = flat(&dp_dlambda)[k];
        }
        check_jacobian(
            "dP/d(mu, lambda)",
            &params,
            1e-6,
            |p| {
                flat(
                    &NeoHookean {
                        mu: p[0],
                        lambda: p[1],
                        volumetric,
                    }
                    .response(&f, false)
                    .unwrap()
                    .stress,
                )
            },
            &jac,
            1e-7,
            0.0,
        );
    }
}

#[test]
fn rest_state_is_stress_free_and_projection_is_psd() {
    let material = NeoHookean {
        mu: 1e4,
        lambda: 1e5,
        volumetric: Volumetric::Log,
    };
    let r = material.response(&Mat3::identity(), true).unwrap();
    assert!(r.energy.abs() < 1e-12 && r.stress.norm() < 1e-9);
    // Strong compression makes the tangent indefinite; the projection must fix it and nothing else.
    let f = Mat3::from_diagonal(&nalgebra::Vector3::new(0.3, 1.4, 1.2));
    let t = material.response(&f, true).unwrap().tangent.unwrap();
    let projected = project_to_psd(&t);
    let min_eig = nalgebra::SymmetricEigen::new(projected).eigenvalues.min();
    assert!(min_eig > -1e-9 * t.norm(), "{min_eig}");
    let pd = material
        .response(&Mat3::identity(), true)
        .unwrap()
        .tangent
        .unwrap();
    assert!((project_to_psd(&pd) - pd).norm() < 1e-9 * pd.norm());
}

#[test]
fn inverted_deformation_has_infinite_energy() {
    let material = NeoHookean {
        mu: 1e4,
        lambda: 1e5,
        volumetric: Volumetric::Log,
    };
    let f = Mat3::from_diagonal(&nalgebra::Vector3::new(-1.0, 1.0, 1.0));
    assert_eq!(material.energy_density(&f), f64::INFINITY);
}

/// The kernels' one-pass `pointwise` gives the energy and stress of `response` and `shear`, and
/// its (F^{-T}, J, c, c', c'') rebuild their tangent in the isotropic form
/// `mu I + alpha T + beta O` (the form the element Hessians use).
#[test]
fn pointwise_matches_response_and_shear() {
    let mut rng = Rng::new(19);
    for volumetric in [Volumetric::Log, Volumetric::Linear] {
        let material = NeoHookean {
            mu: 2.3e4,
            lambda: 4.1e5,
            volumetric,
        };
        for _ in 0..20 {
            let f = random_f(&mut rng, 0.3);
            let h = f - Mat3::identity();
            let full = material.response(&f, true).unwrap();
            let shear = material.shear(&f, false).unwrap();
            let p = material.pointwise(&h, true).unwrap();
            let q = material.pointwise(&h, false).unwrap();
            let close = |a: f64, b: f64, scale: f64| (a - b).abs() <= 1e-12 * scale;
            assert!(close(p.energy, full.energy, full.energy.abs()));
            assert!(close(q.energy, shear.energy, shear.energy.abs()));
            let s = full.stress.norm();
            assert!((p.stress - full.stress).norm() <= 1e-12 * s);
            assert!((q.stress - shear.stress).norm() <= 1e-12 * s);
            let (c, dc, d2c) = p.measure;
            let dh = material.lambda * c * dc;
            let d2h = material.lambda * (dc * dc + c * d2c);
            let (alpha, beta) = (material.mu - dh * p.j, d2h * p.j * p.j + dh * p.j);
            let t = full.tangent.unwrap();
            let g = p.gt;
            for i in 0..3 {
                for j in 0..3 {
                    for k in 0..3 {
                        for l in 0..3 {
                            let isotropic = if (i, j) == (k, l) { material.mu } else { 0.0 }
                                + alpha * g[(i, l)] * g[(k, j)]
                                + beta * g[(i, j)] * g[(k, l)];
                            assert!(close(isotropic, t[(3 * i + j, 3 * k + l)], t.norm()));
                        }
                    }
                }
            }
        }
    }
}

/// The closed-form SVD behind the Hessian projection: U and V rotations, F = U S V^T to
/// round-off, on random states and on states with double and nearly double singular values
/// (where it must either fall back or stay exact).
#[test]
fn rotation_svd_reconstructs_f() {
    use nalgebra::Rotation3;
    use sorofem_core::material::{rotation_svd, symmetric_eigenvalues};
    let mut rng = Rng::new(11);
    let mut cases: Vec<Mat3> = (0..400)
        .map(|k| random_f(&mut rng, if k % 2 == 0 { 0.3 } else { 0.9 }))
        .filter(|f| f.determinant() > 0.0)
        .collect();
    for (k, stretch) in [
        [1.0, 1.0, 1.0],
        [2.0, 1.0, 1.0],
        [1.0, 1.0, 0.5],
        [1.3, 1.3 + 1e-9, 0.7],
        [1.0 + 1e-13, 1.0, 1.0 - 1e-13],
        [3.0, 1.0, 0.02],
        [1.0, 0.5, 0.5 - 1e-7],
    ]
    .iter()
    .enumerate()
    {
        let u = Rotation3::from_euler_angles(0.4 * k as f64, -1.2, 0.3);
        let v = Rotation3::from_euler_angles(1.1, 0.5 * k as f64, -0.8);
        cases.push(u.matrix() * Mat3::from_diagonal(&(*stretch).into()) * v.matrix().transpose());
    }
    let mut closed_form = 0;
    for f in &cases {
        let Some((u, s, v)) = rotation_svd(f, &symmetric_eigenvalues(&(f.transpose() * f))) else {
            continue;
        };
        closed_form += 1;
        let scale = f.norm();
        for (name, q) in [("U", &u), ("V", &v)] {
            assert!(
                (q.transpose() * q - Mat3::identity()).norm() < 1e-12,
                "{name} not orthogonal: {f}"
            );
            assert!(
                (q.determinant() - 1.0).abs() < 1e-12,
                "{name} not a rotation: {f}"
            );
        }
        assert!(s.iter().all(|&x| x > 0.0), "{s:?}");
        let rebuilt = u * Mat3::from_diagonal(&s.into()) * v.transpose();
        assert!(
            (rebuilt - f).norm() < 1e-12 * scale,
            "F = {f}, rebuilt {rebuilt}"
        );
    }
    assert!(
        closed_form >= cases.len() - 2,
        "closed form used on {closed_form} of {}",
        cases.len()
    );
}
