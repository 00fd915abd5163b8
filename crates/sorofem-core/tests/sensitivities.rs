//! Forward and adjoint sensitivities of static equilibria against central differences of
//! re-solved equilibria, for every parameter kind and both formulations.
mod common;

use common::{check_directional, Rng};
use sorofem_core::cables::CableSpec;
use sorofem_core::material::neo_hookean::lame_from_young;
use sorofem_core::material::Volumetric;
use sorofem_core::sensitivity::ParamVector;
use sorofem_core::{Formulation, Loads, Material, Model, PressureMass, SolveOptions, TetMesh};
use std::sync::Arc;

struct Setup {
    model: Model,
    material: Material,
    loads: Loads,
}

fn setup(formulation: Formulation) -> Setup {
    let mesh = Arc::new(TetMesh::box_mesh([0.4, 0.1, 0.1], [4, 2, 2], [0.0; 3]).unwrap());
    let clamp: Vec<i64> = mesh
        .nodes_in_box([-1e-9, -1.0, -1.0], [1e-9, 1.0, 1.0])
        .iter()
        .map(|&i| i as i64)
        .collect();
    let cable = CableSpec::new(
        (0..=8).map(|k| [0.05 * k as f64, 0.05, 0.02]).collect(),
        2e3,
        0.9,
    );
    let m = mesh.n_tets();
    let model =
        Model::try_new_with_cables(mesh, &clamp, formulation, Volumetric::Log, &[cable]).unwrap();
    let (mu, lambda) = lame_from_young(66e3, 0.45);
    let mut rng = Rng::new(9);
    // Heterogeneous so that per-element derivatives are not all alike.
    let material = Material {
        mu: (0..m).map(|_| mu * (1.0 + 0.2 * rng.next())).collect(),
        lambda: (0..m).map(|_| lambda * (1.0 + 0.2 * rng.next())).collect(),
        density: (0..m).map(|_| 1080.0 * (1.0 + 0.2 * rng.next())).collect(),
    };
    Setup {
        model,
        material,
        loads: Loads {
            gravity: [0.5, -1.0, -9.81],
            ..Default::default()
        },
    }
}

/// Objective O(x) = c . x with a fixed random c, evaluated at the equilibrium for parameters
/// `base + e delta`.
fn objective(setup: &mut Setup, c: &[f64], delta: &ParamVector, e: f64) -> f64 {
    let m = setup.material.mu.len();
    let shifted = Material {
        mu: (0..m)
            .map(|i| setup.material.mu[i] + e * delta.mu[i])
            .collect(),
        lambda: (0..m)
            .map(|i| setup.material.lambda[i] + e * delta.lambda[i])
            .collect(),
        density: (0..m)
            .map(|i| setup.material.density[i] + e * delta.density[i])
            .collect(),
    };
    setup.model.set_material(&shifted).unwrap();
    setup
        .model
        .set_actuation(0, 0.9 + e * delta.cable_actuation[0])
        .unwrap();
    setup
        .model
        .set_cable_stiffness(0, 2e3 + e * delta.cable_stiffness[0])
        .unwrap();
    let mut loads = setup.loads.clone();
    for k in 0..3 {
        loads.gravity[k] += e * delta.gravity[k];
    }
    let options = SolveOptions {
        tolerance: 1e-12,
        ..Default::default()
    };
    let s = setup.model.solve(&loads, None, &options).unwrap();
    s.positions.iter().zip(c).map(|(x, ci)| x * ci).sum()
}

fn directions(m: usize, rng: &mut Rng) -> Vec<(&'static str, ParamVector)> {
    let zero = ParamVector::zeros(m, 1);
    let (mu, lambda) = lame_from_young(66e3, 0.45);
    vec![
        (
            "mu",
            ParamVector {
                mu: rng.vec(m, 0.1 * mu),
                ..zero.clone()
            },
        ),
        (
            "lambda",
            ParamVector {
                lambda: rng.vec(m, 0.1 * lambda),
                ..zero.clone()
            },
        ),
        (
            "density",
            ParamVector {
                density: rng.vec(m, 100.0),
                ..zero.clone()
            },
        ),
        (
            "gravity",
            ParamVector {
                gravity: [0.3, -0.2, 0.5],
                ..zero.clone()
            },
        ),
        (
            "cable actuation",
            ParamVector {
                cable_actuation: vec![0.05],
                ..zero.clone()
            },
        ),
        (
            "cable stiffness",
            ParamVector {
                cable_stiffness: vec![200.0],
                ..zero.clone()
            },
        ),
    ]
}

fn dot(a: &ParamVector, b: &ParamVector) -> f64 {
    let v = |x: &[f64], y: &[f64]| x.iter().zip(y).map(|(p, q)| p * q).sum::<f64>();
    v(&a.mu, &b.mu)
        + v(&a.lambda, &b.lambda)
        + v(&a.density, &b.density)
        + v(&a.gravity, &b.gravity)
        + v(&a.cable_actuation, &b.cable_actuation)
        + v(&a.cable_stiffness, &b.cable_stiffness)
}

#[test]
fn adjoint_and_forward_sensitivities_match_central_differences() {
    for formulation in [
        Formulation::Standard,
        Formulation::Mixed {
            mass: PressureMass::Consistent,
        },
    ] {
        let mut setup = setup(formulation);
        let n = setup.model.mesh().n_nodes();
        let m = setup.model.mesh().n_tets();
        let mut rng = Rng::new(21);
        let c = rng.vec(3 * n, 1.0);
        for (name, delta) in directions(m, &mut rng) {
            // Analytic, at the base point.
            objective(&mut setup, &c, &delta, 0.0);
            let gradient = setup.model.adjoint(&c).unwrap();
            let adjoint = dot(&gradient, &delta);
            let (dx, _) = setup.model.forward(&delta).unwrap();
            let forward: f64 = dx.iter().zip(&c).map(|(a, b)| a * b).sum();
            let label = format!("{formulation:?} {name}");
            eprintln!("{label}: adjoint {adjoint:.6e}, forward {forward:.6e}");
            assert!(
                adjoint.abs() > 1e-8,
                "{label}: a vanishing derivative would make this check vacuous"
            );
            check_directional(
                &format!("{label} adjoint"),
                &[0.0],
                &[1.0],
                1e-3,
                |e| objective(&mut setup, &c, &delta, e[0]),
                adjoint,
                1e-5,
            );
            assert!(
                (forward - adjoint).abs() <= 1e-9 * adjoint.abs().max(1e-300),
                "{label}: forward {forward} vs adjoint {adjoint}"
            );
        }
    }
}

#[test]
fn sensitivities_refuse_a_solution_older_than_the_parameters() {
    let mut setup = setup(Formulation::Standard);
    let n = setup.model.mesh().n_nodes();
    let m = setup.model.mesh().n_tets();
    let c = vec![1.0; 3 * n];
    let loads = setup.loads.clone();
    setup.model.set_material(&setup.material).unwrap();
    setup
        .model
        .solve(&loads, None, &SolveOptions::default())
        .unwrap();
    // Re-setting the same material keeps the solution; changing it or a cable makes it stale.
    setup.model.set_material(&setup.material).unwrap();
    assert!(setup.model.adjoint(&c).is_ok());
    let stiffer = Material {
        mu: setup.material.mu.iter().map(|v| 1.1 * v).collect(),
        ..setup.material.clone()
    };
    setup.model.set_material(&stiffer).unwrap();
    let err = setup.model.adjoint(&c).unwrap_err().to_string();
    assert!(err.contains("static solve"), "{err}");
    setup
        .model
        .solve(&loads, None, &SolveOptions::default())
        .unwrap();
    setup.model.set_actuation(0, 0.8).unwrap();
    assert!(setup.model.forward(&ParamVector::zeros(m, 1)).is_err());
}
