//! Contact in the model's solves: bodies resting on and pressed against obstacles, against
//! force balance, analytic answers and the guarantee that no accepted iterate intersects.
mod common;

use common::{cantilever, tip_displacement};
use sorofem_core::contact::{ContactSetup, Obstacle, ObstacleSpec, Plane};
use sorofem_core::material::neo_hookean::lame_from_young;
use sorofem_core::{Formulation, Loads, Material, Model, SolveOptions, TetMesh};
use std::sync::Arc;

const G: f64 = 9.81;

fn plane(point: [f64; 3], normal: [f64; 3], friction: f64) -> ObstacleSpec {
    ObstacleSpec {
        obstacle: Obstacle::Plane(Plane::try_new(point, normal).unwrap()),
        friction,
        path: Vec::new(),
    }
}

fn free_block(size: f64, cells: usize, lift: f64, youngs: f64, density: f64) -> Model {
    let mesh = Arc::new(TetMesh::box_mesh([size; 3], [cells; 3], [0.0, 0.0, lift]).unwrap());
    let m = mesh.n_tets();
    let mut model = Model::try_new(
        mesh,
        &[],
        Formulation::Standard,
        sorofem_core::material::Volumetric::Log,
    )
    .unwrap();
    let (mu, lambda) = lame_from_young(youngs, 0.45);
    model
        .set_material(&Material {
            mu: vec![mu; m],
            lambda: vec![lambda; m],
            density: vec![density; m],
        })
        .unwrap();
    model
}

#[test]
fn a_block_resting_on_a_table_carries_its_weight() {
    let (size, density) = (0.1, 1080.0);
    // The mean boundary edge is about 3 cm: dhat about 0.3 mm; the block starts 0.1 mm up.
    let mut model = free_block(size, 4, 1e-4, 66e3, density);
    model
        .set_contact(ContactSetup {
            obstacles: vec![plane([0.0; 3], [0.0, 0.0, 1.0], 0.5)],
            ..Default::default()
        })
        .unwrap();
    let loads = Loads {
        gravity: [0.0, 0.0, -G],
        ..Default::default()
    };
    let solution = model.solve(&loads, None, &SolveOptions::default()).unwrap();
    let contact = solution.contact.as_ref().unwrap();
    let weight = density * size.powi(3) * G;
    let total = contact.forces.per_obstacle[0];
    println!(
        "{} iterations, force {total:?} vs weight {weight}, min distance {:?}, active {:?}, kappa {:.3e}",
        solution.report.iterations,
        contact.forces.min_distance,
        contact.forces.active,
        contact.stiffness
    );
    assert!((total[2] - weight).abs() <= 1e-6 * weight, "{total:?}");
    assert!(total[0].abs() <= 1e-6 * weight && total[1].abs() <= 1e-6 * weight);
    let gap = contact.forces.min_distance[0].unwrap();
    assert!(gap > 0.0 && gap < contact.dhat, "gap {gap}");
    assert!(contact.iterate_min_distances.iter().all(|&d| d > 0.0));
}

#[test]
fn a_cantilever_sags_onto_a_plane_below_its_tip() {
    let (length, density) = (0.4, 1080.0);
    let mut free = cantilever(
        [length, 0.1, 0.1],
        [8, 2, 2],
        66e3,
        0.45,
        density,
        Formulation::Standard,
    );
    let loads = Loads {
        gravity: [0.0, 0.0, -G],
        ..Default::default()
    };
    let free_solution = free.solve(&loads, None, &SolveOptions::default()).unwrap();
    let free_tip = tip_displacement(&free, &free_solution, length);
    let floor = -0.5 * free_tip[2].abs();
    let mut model = cantilever(
        [length, 0.1, 0.1],
        [8, 2, 2],
        66e3,
        0.45,
        density,
        Formulation::Standard,
    );
    model
        .set_contact(ContactSetup {
            obstacles: vec![plane([0.0, 0.0, floor], [0.0, 0.0, 1.0], 0.0)],
            ..Default::default()
        })
        .unwrap();
    let solution = model.solve(&loads, None, &SolveOptions::default()).unwrap();
    let contact = solution.contact.as_ref().unwrap();
    let lowest = (0..model.mesh().n_nodes())
        .map(|i| solution.positions[3 * i + 2])
        .fold(f64::INFINITY, f64::min);
    println!(
        "free tip {:.4e} m in {} iterations; on the plane at {floor:.4e}: lowest {lowest:.4e}, {} iterations, force {:?}, active {:?}",
        free_tip[2], free_solution.report.iterations, solution.report.iterations,
        contact.forces.per_obstacle[0], contact.forces.active
    );
    assert!(lowest > floor && lowest < floor + contact.dhat);
    // Supports + contact + weight = 0.
    let weight = density * length * 0.01 * G;
    let mut balance = [0.0, 0.0, -weight];
    for r in &solution.reactions {
        for k in 0..3 {
            balance[k] += r[k];
        }
    }
    for k in 0..3 {
        balance[k] += contact.forces.per_obstacle[0][k];
    }
    let residual = balance.iter().map(|v| v.abs()).fold(0.0, f64::max);
    assert!(residual <= 1e-8 * weight, "balance {balance:?}");
    assert!(contact.iterate_min_distances.iter().all(|&d| d > 0.0));
}
