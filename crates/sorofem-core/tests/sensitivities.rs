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
    let shift = |base: &[f64], name: &str| -> Vec<f64> {
        let d = delta.get(name).unwrap();
        base.iter().zip(d).map(|(b, d)| b + e * d).collect()
    };
    let shifted = Material {
        mu: shift(&setup.material.mu, "mu"),
        lambda: shift(&setup.material.lambda, "lambda"),
        density: shift(&setup.material.density, "density"),
    };
    setup.model.set_material(&shifted).unwrap();
    setup
        .model
        .set_actuation(0, shift(&[0.9], "cable_actuation")[0])
        .unwrap();
    setup
        .model
        .set_cable_stiffness(0, shift(&[2e3], "cable_stiffness")[0])
        .unwrap();
    let mut loads = setup.loads.clone();
    loads.gravity = std::array::from_fn(|k| shift(&setup.loads.gravity, "gravity")[k]);
    let options = SolveOptions {
        tolerance: 1e-12,
        ..Default::default()
    };
    let s = setup.model.solve(&loads, None, &options).unwrap();
    s.positions.iter().zip(c).map(|(x, ci)| x * ci).sum()
}

/// One direction per parameter block of `model`, random where per tet.
fn directions(model: &Model, rng: &mut Rng) -> Vec<(&'static str, ParamVector)> {
    let m = model.mesh().n_tets();
    let (mu, lambda) = lame_from_young(66e3, 0.45);
    let zero = model.param_zeros();
    let along = |name: &str, values: Vec<f64>| {
        let mut delta = zero.clone();
        *delta.get_mut(name).unwrap() = values;
        delta
    };
    vec![
        ("mu", along("mu", rng.vec(m, 0.1 * mu))),
        ("lambda", along("lambda", rng.vec(m, 0.1 * lambda))),
        ("density", along("density", rng.vec(m, 100.0))),
        ("gravity", along("gravity", vec![0.3, -0.2, 0.5])),
        ("cable actuation", along("cable_actuation", vec![0.05])),
        ("cable stiffness", along("cable_stiffness", vec![200.0])),
    ]
}

fn dot(a: &ParamVector, b: &ParamVector) -> f64 {
    let mut sum = 0.0;
    for (name, x) in &a.blocks {
        let y = b.get(name).unwrap();
        sum += x.iter().zip(y).map(|(p, q)| p * q).sum::<f64>();
    }
    sum
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
        let mut rng = Rng::new(21);
        let c = rng.vec(3 * n, 1.0);
        for (name, delta) in directions(&setup.model, &mut rng) {
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
    assert!(setup.model.forward(&setup.model.param_zeros()).is_err());
}
