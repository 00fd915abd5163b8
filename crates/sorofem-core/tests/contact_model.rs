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
    for (b, f) in balance.iter_mut().zip(contact.forces.per_obstacle[0]) {
        *b += f;
    }
    let residual = balance.iter().map(|v| v.abs()).fold(0.0, f64::max);
    assert!(residual <= 1e-8 * weight, "balance {balance:?}");
    assert!(contact.iterate_min_distances.iter().all(|&d| d > 0.0));
}

/// The cantilever of the previous test on its plane, frictionless: `c . x` and the plane's
/// normal force at the equilibrium for the shear moduli `mu` and gravity `g`.
fn pressed_cantilever() -> (Model, Vec<f64>) {
    let mut model = cantilever(
        [0.4, 0.1, 0.1],
        [8, 2, 2],
        66e3,
        0.45,
        1080.0,
        Formulation::Standard,
    );
    model
        .set_contact(ContactSetup {
            obstacles: vec![plane([0.0, 0.0, -0.13], [0.0, 0.0, 1.0], 0.0)],
            ..Default::default()
        })
        .unwrap();
    let m = model.mesh().n_tets();
    let (mu, _) = lame_from_young(66e3, 0.45);
    let mut rng = common::Rng::new(3);
    let mus = (0..m).map(|_| mu * (1.0 + 0.2 * rng.next())).collect();
    (model, mus)
}

#[test]
fn sensitivities_through_frictionless_contact_match_finite_differences() {
    let (mut model, mus) = pressed_cantilever();
    let m = model.mesh().n_tets();
    let (_, lambda) = lame_from_young(66e3, 0.45);
    let mut rng = common::Rng::new(5);
    let c: Vec<f64> = rng.vec(3 * model.mesh().n_nodes(), 1.0);
    let dmu: Vec<f64> = (0..m).map(|_| 2e3 * rng.next()).collect();
    let dg = [0.3, -0.2, 1.0];
    let options = SolveOptions {
        tolerance: 1e-12,
        ..Default::default()
    };
    // O(e) = (c . x, F_z) at mu + e dmu, g + e dg.
    let solve_at = |model: &mut Model, e: f64| -> (f64, f64) {
        let shifted: Vec<f64> = mus.iter().zip(&dmu).map(|(a, b)| a + e * b).collect();
        model
            .set_material(&Material {
                mu: shifted,
                lambda: vec![lambda; m],
                density: vec![1080.0; m],
            })
            .unwrap();
        let loads = Loads {
            gravity: std::array::from_fn(|k| [0.0, 0.0, -G][k] + e * dg[k]),
            ..Default::default()
        };
        let s = model.solve(&loads, None, &options).unwrap();
        let contact = s.contact.unwrap();
        assert!(contact.forces.active[0] > 0);
        (
            s.positions.iter().zip(&c).map(|(x, ci)| x * ci).sum(),
            contact.forces.per_obstacle[0][2],
        )
    };
    let h = 1e-3;
    let (plus, minus) = (solve_at(&mut model, h), solve_at(&mut model, -h));
    let fd = (
        (plus.0 - minus.0) / (2.0 * h),
        (plus.1 - minus.1) / (2.0 * h),
    );
    solve_at(&mut model, 0.0);
    let mut delta = model.param_zeros();
    *delta.get_mut("mu").unwrap() = dmu.clone();
    *delta.get_mut("gravity").unwrap() = dg.to_vec();
    let dot = |g: &sorofem_core::sensitivity::ParamVector| -> f64 {
        g.get("mu")
            .unwrap()
            .iter()
            .zip(&dmu)
            .map(|(a, b)| a * b)
            .sum::<f64>()
            + g.get("gravity")
                .unwrap()
                .iter()
                .zip(&dg)
                .map(|(a, b)| a * b)
                .sum::<f64>()
    };
    let (dx, _) = model.forward(&delta).unwrap();
    let forward: f64 = dx.iter().zip(&c).map(|(a, b)| a * b).sum();
    let adjoint = dot(&model.adjoint(&c).unwrap());
    let force_weights = model.contact_force_gradient(0, [0.0, 0.0, 1.0]).unwrap();
    let force_adjoint = dot(&model.adjoint(&force_weights).unwrap());
    println!(
        "c.x: forward {forward:.8e}, adjoint {adjoint:.8e}, FD {:.8e}; F_z: adjoint {force_adjoint:.8e}, FD {:.8e}",
        fd.0, fd.1
    );
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-5 * a.abs().max(b.abs());
    assert!(close(forward, fd.0) && close(adjoint, fd.0));
    assert!(close(force_adjoint, fd.1));
}
