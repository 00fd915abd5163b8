//! Contact in dynamics: fast impacts that no accepted iterate may pass through (audited in full),
//! Coulomb's law on an incline, and obstacles moving along prescribed paths.
use sorofem_core::contact::{ContactSetup, Obstacle, ObstacleMesh, ObstacleSpec, Plane};
use sorofem_core::material::neo_hookean::lame_from_young;
use sorofem_core::{
    Damping, DynamicsOptions, Formulation, Loads, Material, Model, SolveOptions, StepMethod,
    TetMesh, Trajectory,
};
use std::sync::Arc;

const G: f64 = 9.81;

fn block(size: f64, cells: usize, origin: [f64; 3], youngs: f64, density: f64) -> Model {
    let mesh = Arc::new(TetMesh::box_mesh([size; 3], [cells; 3], origin).unwrap());
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

fn spec(obstacle: Obstacle, friction: f64, path: Vec<(f64, [f64; 3])>) -> ObstacleSpec {
    ObstacleSpec {
        obstacle,
        friction,
        path,
    }
}

fn run(
    model: &mut Model,
    gravity: [f64; 3],
    dt: f64,
    steps: usize,
    v0: Option<&[f64]>,
) -> Trajectory {
    let loads = Loads {
        gravity,
        ..Default::default()
    };
    model
        .simulate(
            &loads,
            dt,
            steps,
            &vec![Vec::new(); steps],
            Damping::default(),
            None,
            v0,
            &SolveOptions::default(),
            1,
        )
        .unwrap()
}

fn mean_position(model: &Model, positions: &[f64]) -> [f64; 3] {
    let n = model.mesh().n_nodes();
    let mut c = [0.0; 3];
    for i in 0..n {
        for k in 0..3 {
            c[k] += positions[3 * i + k] / n as f64;
        }
    }
    c
}

#[test]
fn a_fast_falling_block_never_passes_through_the_floor_in_any_step_method() {
    // 5 m/s with dt = 10 ms: the prediction moves the block 5 cm per step, 2.5 times the gap.
    let mut factorizations = Vec::new();
    for method in [
        StepMethod::Newton,
        StepMethod::Modified,
        StepMethod::LinearlyImplicit,
    ] {
        let mut model = block(0.04, 3, [0.0, 0.0, 0.02], 1e5, 1000.0);
        model
            .set_contact(ContactSetup {
                obstacles: vec![spec(
                    Obstacle::Plane(Plane::try_new([0.0; 3], [0.0, 0.0, 1.0]).unwrap()),
                    0.0,
                    Vec::new(),
                )],
                ..Default::default()
            })
            .unwrap();
        model.set_contact_audit(true);
        let n = model.mesh().n_nodes();
        let v0: Vec<f64> = (0..3 * n)
            .map(|d| if d % 3 == 2 { -5.0 } else { 0.0 })
            .collect();
        let steps = 20;
        let options = DynamicsOptions {
            method,
            ..Default::default()
        };
        let trajectory = model
            .simulate_with(
                &Loads {
                    gravity: [0.0, 0.0, -G],
                    ..Default::default()
                },
                0.01,
                steps,
                &vec![Vec::new(); steps],
                Damping::default(),
                None,
                Some(&v0),
                &options,
            )
            .unwrap();
        let distances = &trajectory.iterate_min_distances;
        assert!(!distances.is_empty());
        assert!(
            distances.iter().all(|&d| d > 0.0),
            "{method:?}: an iterate touched: {distances:?}"
        );
        assert!(
            distances.iter().any(|&d| d.is_finite()),
            "{method:?}: never came within dhat"
        );
        for frame in &trajectory.positions {
            let lowest = (0..n)
                .map(|i| frame[3 * i + 2])
                .fold(f64::INFINITY, f64::min);
            assert!(lowest > 0.0, "{method:?}");
        }
        // The floor carries the block's weight at the end, whatever the method.
        let last = trajectory.contact.last().unwrap();
        let weight = G * 1000.0 * 0.04f64.powi(3);
        println!(
            "{method:?}: floor force {:.4} N (weight {weight:.4} N), {} factorisations, {} iterations",
            last.forces.per_obstacle[0][2],
            trajectory.factorizations.iter().sum::<usize>(),
            trajectory.iterations.iter().sum::<usize>()
        );
        let force = last.forces.per_obstacle[0][2];
        assert!(
            (force - weight).abs() < 0.05 * weight,
            "{method:?}: {force} N"
        );
        factorizations.push(trajectory.factorizations.iter().sum::<usize>());
    }
    assert!(factorizations[1] <= factorizations[0], "{factorizations:?}");
}

#[test]
fn a_block_thrown_onto_a_sharp_box_edge_never_intersects_it() {
    // A box turned 45 degrees about x: its top is an edge along x at z = 0.
    let half = 0.02;
    let (c, s) = (
        std::f64::consts::FRAC_1_SQRT_2,
        std::f64::consts::FRAC_1_SQRT_2,
    );
    let ridge = ObstacleMesh::oriented_box(
        [0.02, 0.02, -half * std::f64::consts::SQRT_2],
        [0.05, half, half],
        [[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]],
    )
    .unwrap();
    let mut model = block(0.04, 4, [0.0, 0.003, 0.005], 1e5, 1000.0);
    model
        .set_contact(ContactSetup {
            obstacles: vec![spec(Obstacle::Mesh(ridge), 0.0, Vec::new())],
            ..Default::default()
        })
        .unwrap();
    model.set_contact_audit(true);
    let n = model.mesh().n_nodes();
    let v0: Vec<f64> = (0..3 * n)
        .map(|d| if d % 3 == 2 { -3.0 } else { 0.0 })
        .collect();
    let trajectory = run(&mut model, [0.0, 0.0, -G], 0.005, 10, Some(&v0));
    let distances = &trajectory.iterate_min_distances;
    assert!(
        distances.iter().all(|&d| d > 0.0),
        "an iterate touched: {distances:?}"
    );
    assert!(
        distances.iter().any(|&d| d.is_finite()),
        "never came within dhat"
    );
    let contact = model.contact().unwrap();
    let last = trajectory.positions.last().unwrap();
    let z: Vec<f64> = last
        .iter()
        .zip(model.mesh().rest_flat())
        .map(|(x, r)| x - r)
        .collect();
    assert!(!contact.intersects(&z));
}

/// A stiff block on the plane z = 0 under gravity tilted by `theta`, with friction `mu`: the
/// position of its centre along the slope at every step of `dt`.
fn incline_path(theta: f64, mu: f64, dt: f64, steps: usize) -> Vec<f64> {
    let mut model = block(0.05, 2, [0.0, 0.0, 5e-5], 1e6, 1000.0);
    model
        .set_contact(ContactSetup {
            obstacles: vec![spec(
                Obstacle::Plane(Plane::try_new([0.0; 3], [0.0, 0.0, 1.0]).unwrap()),
                mu,
                Vec::new(),
            )],
            ..Default::default()
        })
        .unwrap();
    let gravity = [G * theta.sin(), 0.0, -G * theta.cos()];
    let trajectory = run(&mut model, gravity, dt, steps, None);
    trajectory
        .positions
        .iter()
        .map(|x| mean_position(&model, x)[0])
        .collect()
}

#[test]
fn a_block_on_an_incline_sticks_below_the_friction_angle_and_slides_above_it() {
    // The block starts within dhat of the plane, away from its resting gap: it settles in the
    // first steps, then sticks or slides steadily. The acceleration is measured over the last
    // 20 steps (implicit Euler's second differences are exact for a constant acceleration).
    let (mu, dt, steps): (f64, f64, usize) = (0.5, 0.01, 40);
    let late = |x: &[f64]| {
        let (a, b, c) = (x[steps - 20], x[steps - 10], x[steps]);
        let speed = (c - a) / (20.0 * dt);
        let acceleration = (c - 2.0 * b + a) / (10.0 * dt).powi(2);
        (speed, acceleration)
    };
    let theta = 0.8 * mu.atan();
    let (speed, _) = late(&incline_path(theta, mu, dt, steps));
    println!("below the friction angle: late speed {speed:.3e} m/s");
    // Smoothed friction creeps below eps_v = 1 mm/s (IPC's default).
    assert!(speed.abs() < 1e-3, "{speed}");
    let theta = 1.3 * mu.atan();
    let (speed, acceleration) = late(&incline_path(theta, mu, dt, steps));
    let coulomb = G * (theta.sin() - mu * theta.cos());
    println!("above: speed {speed:.3e} m/s, acceleration {acceleration:.4} vs Coulomb {coulomb:.4} m/s^2");
    assert!(
        (acceleration - coulomb).abs() < 0.02 * coulomb,
        "{acceleration} vs {coulomb}"
    );
}

#[test]
fn a_rising_floor_lifts_a_block_resting_on_it() {
    let mut model = block(0.04, 2, [0.0, 0.0, 1e-4], 1e5, 1000.0);
    let rise = 0.01;
    model
        .set_contact(ContactSetup {
            obstacles: vec![spec(
                Obstacle::Plane(Plane::try_new([0.0; 3], [0.0, 0.0, 1.0]).unwrap()),
                0.0,
                vec![(0.0, [0.0; 3]), (0.1, [0.0, 0.0, rise])],
            )],
            ..Default::default()
        })
        .unwrap();
    let trajectory = run(&mut model, [0.0, 0.0, -G], 0.01, 30, None);
    let n = model.mesh().n_nodes();
    let last = trajectory.positions.last().unwrap();
    let lowest = (0..n)
        .map(|i| last[3 * i + 2])
        .fold(f64::INFINITY, f64::min);
    let dhat = model.contact().unwrap().dhat();
    println!("lowest node at {lowest:.4e} m, floor at {rise} m, dhat {dhat:.2e}");
    assert!(lowest > rise && lowest < rise + dhat, "{lowest}");
    let frame = trajectory.contact.last().unwrap();
    assert_eq!(frame.translations[0], [0.0, 0.0, rise]);
}

/// A block falls onto a floor and rests there. With the adaptive stiffness, IPC balances it
/// against the block's weight and inertia at the starts of the steps in contact, above
/// `kappa_ref` (resting, the balance returns about the stiffness the last step rested with:
/// 1.0005 `kappa_ref` here); with `adaptive_stiffness: false` it stays at `kappa_ref` in every
/// step, and the block still never passes through the floor.
#[test]
fn a_fixed_barrier_stiffness_stays_at_its_reference_through_a_landing() {
    let reference = 1e8;
    let mut last = Vec::new();
    for adaptive_stiffness in [true, false] {
        let mut model = block(0.04, 3, [0.0, 0.0, 0.001], 1e5, 1000.0);
        model
            .set_contact(ContactSetup {
                obstacles: vec![spec(
                    Obstacle::Plane(Plane::try_new([0.0; 3], [0.0, 0.0, 1.0]).unwrap()),
                    0.5,
                    Vec::new(),
                )],
                stiffness: Some(reference),
                adaptive_stiffness,
                ..Default::default()
            })
            .unwrap();
        model.set_contact_audit(true);
        let trajectory = run(&mut model, [0.0, 0.0, -G], 0.005, 20, None);
        assert!(
            trajectory.iterate_min_distances.iter().all(|&d| d > 0.0),
            "an iterate touched the floor"
        );
        assert!(
            trajectory
                .iterate_min_distances
                .iter()
                .any(|&d| d.is_finite()),
            "never came within dhat"
        );
        last.push(model.contact().unwrap().stiffness());
    }
    println!(
        "last step's kappa: adaptive {:.3e}, fixed {:.3e}",
        last[0], last[1]
    );
    assert!(last[0] > reference, "{last:?}");
    assert_eq!(last[1], reference);
}
