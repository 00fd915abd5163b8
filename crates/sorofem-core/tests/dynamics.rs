//! Implicit Euler dynamics: free fall follows the integrator's exact recurrence, and a damped
//! beam released from rest settles onto the static equilibrium.
mod common;

use common::{cantilever, tip_displacement};
use sorofem_core::material::Volumetric;
use sorofem_core::{Damping, Formulation, Loads, Material, Model, SolveOptions, TetMesh};
use std::sync::Arc;

#[test]
fn free_fall_follows_the_implicit_euler_recurrence() {
    let mesh = Arc::new(TetMesh::box_mesh([0.1, 0.1, 0.1], [2, 2, 2], [0.0; 3]).unwrap());
    let m = mesh.n_tets();
    let mut model =
        Model::try_new(mesh.clone(), &[], Formulation::Standard, Volumetric::Log).unwrap();
    model
        .set_material(&Material {
            mu: vec![1e4; m],
            lambda: vec![1e5; m],
            density: vec![1000.0; m],
        })
        .unwrap();
    let (dt, steps, g) = (0.01, 20, -9.81);
    let loads = Loads {
        gravity: [0.0, 0.0, g],
        ..Default::default()
    };
    let trajectory = model
        .simulate(
            &loads,
            dt,
            steps,
            &vec![vec![]; steps],
            Damping::default(),
            None,
            None,
            &SolveOptions::default(),
            1,
        )
        .unwrap();
    // v_{k+1} = v_k + dt g, x_{k+1} = x_k + dt v_{k+1}: x_k = g dt^2 k (k + 1) / 2, which is
    // g t^2 / 2 up to the O(dt) integrator error g t dt / 2.
    for (k, frame) in trajectory.positions.iter().enumerate() {
        let expected = g * dt * dt * (k * (k + 1)) as f64 / 2.0;
        for i in 0..mesh.n_nodes() {
            assert!(
                (frame[3 * i + 2] - mesh.rest()[i][2] - expected).abs() < 1e-12,
                "frame {k} node {i}"
            );
            assert!((frame[3 * i] - mesh.rest()[i][0]).abs() < 1e-12);
        }
        let t = k as f64 * dt;
        assert!((expected - 0.5 * g * t * t - 0.5 * g * t * dt).abs() < 1e-12);
    }
}

#[test]
fn damped_beam_settles_on_the_static_solution() {
    let mut model = cantilever(
        [0.4, 0.1, 0.1],
        [8, 2, 2],
        66e3,
        0.45,
        1080.0,
        Formulation::Standard,
    );
    let loads = Loads {
        gravity: [0.0, 0.0, -9.81],
        ..Default::default()
    };
    let static_solution = model.solve(&loads, None, &SolveOptions::default()).unwrap();
    let w_static = tip_displacement(&model, &static_solution, 0.4)[2];
    let steps = 400;
    let trajectory = model
        .simulate(
            &loads,
            0.01,
            steps,
            &vec![vec![]; steps],
            Damping {
                mass: 10.0,
                stiffness: 0.005,
            },
            None,
            None,
            &SolveOptions::default(),
            40,
        )
        .unwrap();
    let last = trajectory.positions.last().unwrap();
    let mesh = model.mesh().clone();
    let tip = mesh.nodes_in_box([0.4 - 1e-9, -1.0, -1.0], [0.4 + 1e-9, 1.0, 1.0]);
    let w_dynamic: f64 = tip
        .iter()
        .map(|&i| last[3 * i + 2] - mesh.rest()[i][2])
        .sum::<f64>()
        / tip.len() as f64;
    let ke = &trajectory.kinetic_energy;
    eprintln!("static tip {w_static:.5} m, dynamic after 4 s {w_dynamic:.5} m, kinetic energy {:?}, cutbacks {}", ke, trajectory.cutbacks);
    assert!(
        ((w_dynamic - w_static) / w_static).abs() < 1e-3,
        "{w_dynamic} vs {w_static}"
    );
    assert!(ke.last().unwrap() < &(1e-6 * ke.iter().cloned().fold(0.0, f64::max)));
}
