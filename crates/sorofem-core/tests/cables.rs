//! Cables: the unilateral spring's derivatives on both sides of and inside the slack-taut
//! transition, exact interpolation of affine motions, force balance, and actuation of a beam.
mod common;

use common::{check_gradient, check_jacobian, Rng};
use sorofem_core::cables::{embed, CableSpec, Outside, PointPlacement};
use sorofem_core::energy::{Cable, CableTerm, HessianMode, PointMap, Term};
use sorofem_core::material::neo_hookean::lame_from_young;
use sorofem_core::material::Volumetric;
use sorofem_core::{Formulation, Loads, Material, Model, SolveOptions, TetMesh};
use std::sync::Arc;

/// A two-segment cable: an anchor, a point embedded with weights over two blocks, a free node.
fn test_cable(actuation: f64) -> CableTerm {
    test_cable_with_damping(actuation, 0.0)
}

fn test_cable_with_damping(actuation: f64, damping: f64) -> CableTerm {
    let points = vec![
        PointMap {
            offset: [0.0, 0.0, 0.0],
            dof_blocks: vec![],
            weights: vec![],
        },
        PointMap {
            offset: [1.0, 0.1, 0.0],
            dof_blocks: vec![0, 3, 6, 9],
            weights: vec![0.1, 0.2, 0.3, 0.4],
        },
        PointMap {
            offset: [2.0, 0.0, 0.3],
            dof_blocks: vec![12],
            weights: vec![1.0],
        },
    ];
    let rest_lengths = vec![(1.0f64 + 0.01).sqrt(), (1.0f64 + 0.01 + 0.09).sqrt()];
    CableTerm::new(vec![Cable {
        points,
        rest_lengths,
        stiffness: 2e3,
        actuation,
        transition: 0.05,
        damping,
    }])
}

#[test]
fn cable_derivatives_in_slack_transition_and_taut_states() {
    // Stretch s / (transition width) of the first segment: slack, inside the transition, taut.
    let term = test_cable(1.0);
    let mut rng = Rng::new(3);
    let mut dofs = vec![0; 24];
    for (label, stretch) in [
        ("slack", -0.02),
        ("transition low", 0.01),
        ("transition high", 0.04),
        ("taut", 0.2),
    ] {
        for e in 0..term.n_elements() {
            term.element_dofs(e, &mut dofs);
            // Displace every block along the segment direction so that the length changes by about `stretch`.
            let mut z: Vec<f64> = rng.vec(24, 1e-3);
            for slot in 0..8 {
                z[3 * slot] += stretch * 0.5;
            }
            let mut grad = vec![0.0; 24];
            let mut hess = vec![0.0; 24 * 24];
            term.element(e, &z, Some(&mut grad), Some(&mut hess), HessianMode::Exact);
            let energy = |x: &[f64]| term.element(e, x, None, None, HessianMode::Exact);
            check_gradient(
                &format!("cable {label} segment {e} gradient"),
                &z,
                1e-7,
                energy,
                &grad,
                1e-6,
                1e-9,
            );
            let gradient = |x: &[f64]| {
                let mut g = vec![0.0; 24];
                term.element(e, x, Some(&mut g), None, HessianMode::Exact);
                g
            };
            check_jacobian(
                &format!("cable {label} segment {e} Hessian"),
                &z,
                1e-7,
                gradient,
                &hess,
                1e-5,
                1e-6,
            );
        }
    }
}

#[test]
fn dashpot_derivatives_when_segments_lengthen_and_shorten() {
    let mut term = test_cable_with_damping(0.95, 30.0);
    let mut rng = Rng::new(5);
    let start = rng.vec(15, 1e-2);
    term.begin_step(1e-3, &start);
    let mut dofs = vec![0; 24];
    for (label, change) in [("lengthening", 0.03), ("shortening", -0.03)] {
        for e in 0..term.n_elements() {
            term.element_dofs(e, &mut dofs);
            let mut z: Vec<f64> = dofs.iter().map(|&d| start[d]).collect();
            // The segment's far end moves along x, near the segment direction.
            for slot in 4..8 {
                z[3 * slot] += change;
            }
            let mut grad = vec![0.0; 24];
            let mut hess = vec![0.0; 24 * 24];
            term.element(e, &z, Some(&mut grad), Some(&mut hess), HessianMode::Exact);
            check_gradient(
                &format!("dashpot {label} segment {e} gradient"),
                &z,
                1e-7,
                |x: &[f64]| term.element(e, x, None, None, HessianMode::Exact),
                &grad,
                1e-6,
                1e-9,
            );
            check_jacobian(
                &format!("dashpot {label} segment {e} Hessian"),
                &z,
                1e-7,
                |x: &[f64]| {
                    let mut g = vec![0.0; 24];
                    term.element(e, x, Some(&mut g), None, HessianMode::Exact);
                    g
                },
                &hess,
                1e-5,
                1e-6,
            );
        }
    }
    // At the start of the step the dashpot adds no force.
    let z0 = vec![0.0; 15];
    let mut with = vec![0.0; 24];
    let mut without = vec![0.0; 24];
    term.begin_step(1e-3, &z0);
    term.element(0, &vec![0.0; 24], Some(&mut with), None, HessianMode::Exact);
    term.end_step();
    term.element(
        0,
        &vec![0.0; 24],
        Some(&mut without),
        None,
        HessianMode::Exact,
    );
    assert_eq!(with, without);
}

#[test]
fn unilateral_spring_is_c1_and_slack_is_force_free() {
    let w = 0.1;
    for s in [0.0, w] {
        let (below, above) = (
            sorofem_core::energy::cable::unilateral(s - 1e-12, w),
            sorofem_core::energy::cable::unilateral(s + 1e-12, w),
        );
        assert!(
            (below.0 - above.0).abs() < 1e-12
                && (below.1 - above.1).abs() < 1e-10
                && (below.2 - above.2).abs() < 1e-9
        );
    }
    assert_eq!(
        sorofem_core::energy::cable::unilateral(-0.3, w),
        (0.0, 0.0, 0.0)
    );
}

fn beam() -> Arc<TetMesh> {
    Arc::new(TetMesh::box_mesh([0.4, 0.1, 0.1], [8, 2, 2], [0.0; 3]).unwrap())
}

fn lower_edge_cable(actuation: f64) -> CableSpec {
    // Along the lower edge (z = 0.01 m above the bottom face), through the width's middle.
    let points = (0..=10).map(|k| [0.04 * k as f64, 0.05, 0.01]).collect();
    CableSpec::new(points, 1e4, actuation)
}

#[test]
fn embedding_interpolates_affine_motions_exactly_and_reports_placements() {
    let mesh = beam();
    let mut spec = lower_edge_cable(1.0);
    spec.points.push([0.45, 0.05, 0.01]); // 5 cm beyond the free end
    spec.snap_tolerance = 0.01;
    spec.outside = Outside::FreeNode;
    spec.points.insert(1, [0.02, 0.05, -0.005]); // 5 mm below the bottom: snapped
    let embedded = embed(&mesh, &[spec]).unwrap();
    let placements = &embedded.placements[0];
    assert!(matches!(placements[0], PointPlacement::Embedded { distance, .. } if distance == 0.0));
    // The snapped point lies on the tet (clamped barycentric coordinates), at least as far as the
    // true closest point (5 mm) and within the tolerance.
    assert!(
        matches!(placements[1], PointPlacement::Embedded { distance, .. } if distance >= 0.005 - 1e-12 && distance <= 0.01)
    );
    assert_eq!(placements.last(), Some(&PointPlacement::Free { index: 0 }));
    let cable = &embedded.cables[0];
    let n = mesh.n_nodes();
    let a = nalgebra::Matrix3::new(0.1, -0.2, 0.05, 0.3, 0.02, -0.1, 0.0, 0.15, -0.07);
    let b = nalgebra::Vector3::new(0.01, -0.02, 0.03);
    let mut z = vec![0.0; 3 * n + 3];
    for i in 0..n {
        let u = a * nalgebra::Vector3::from(mesh.rest()[i]) + b;
        z[3 * i..3 * i + 3].copy_from_slice(u.as_slice());
    }
    for (k, point) in cable.points.iter().enumerate().take(cable.points.len() - 1) {
        let y0 = nalgebra::Vector3::from(point.offset);
        let expected = y0 + a * y0 + b;
        assert!(
            (cable.position(k, &z) - expected).norm() < 1e-14,
            "point {k}"
        );
    }
    // Outside beyond tolerance and no free nodes allowed: an error naming the point.
    let mut strict = lower_edge_cable(1.0);
    strict.points.push([0.45, 0.05, 0.01]);
    let err = embed(&mesh, &[strict]).unwrap_err().to_string();
    assert!(err.contains("cables[0].points[11]"), "{err}");
}

fn model_with(cables: &[CableSpec], fixed: &[i64]) -> Model {
    let mesh = beam();
    let m = mesh.n_tets();
    let mut model =
        Model::try_new_with_cables(mesh, fixed, Formulation::Standard, Volumetric::Log, cables)
            .unwrap();
    let (mu, lambda) = lame_from_young(66e3, 0.45);
    model
        .set_material(&Material {
            mu: vec![mu; m],
            lambda: vec![lambda; m],
            density: vec![1080.0; m],
        })
        .unwrap();
    model
}

#[test]
fn rest_actuation_on_the_rest_shape_exerts_no_force() {
    let mut model = model_with(&[lower_edge_cable(1.0)], &[0, 1, 2]);
    let s = model
        .solve(&Loads::default(), None, &SolveOptions::default())
        .unwrap();
    assert!(s.cable_tensions[0].iter().all(|&t| t == 0.0));
    assert!(s.report.iterations == 0);
}

#[test]
fn cable_forces_balance_on_a_body_and_with_a_world_anchor() {
    let mesh = beam();
    let clamp: Vec<i64> = mesh
        .nodes_in_box([-1e-9, -1.0, -1.0], [1e-9, 1.0, 1.0])
        .iter()
        .map(|&i| i as i64)
        .collect();
    // Both ends embedded: the cable is internal, so the clamp reaction vanishes without gravity.
    let mut model = model_with(&[lower_edge_cable(0.7)], &clamp);
    let s = model
        .solve(&Loads::default(), None, &SolveOptions::default())
        .unwrap();
    let total: f64 = (0..3)
        .map(|k| s.reactions.iter().map(|r| r[k]).sum::<f64>().abs())
        .sum();
    let tension = s.cable_tensions[0][0];
    assert!(
        tension > 1.0 && total < 1e-8 * tension,
        "reaction {total} vs tension {tension}"
    );
    // Anchored to the world 5 cm behind the clamp: the clamp carries the anchor's pull.
    let mut anchored = lower_edge_cable(0.9);
    anchored.points.insert(0, [-0.05, 0.05, 0.01]);
    anchored.anchor_first = true;
    let mut model = model_with(&[anchored], &clamp);
    let s = model
        .solve(&Loads::default(), None, &SolveOptions::default())
        .unwrap();
    let y = &s.cable_points[0];
    let d = nalgebra::Vector3::from(y[0]) - nalgebra::Vector3::from(y[1]);
    let anchor_pull = d.normalize() * s.cable_tensions[0][0];
    for k in 0..3 {
        let reaction: f64 = s.reactions.iter().map(|r| r[k]).sum();
        assert!(
            (reaction + anchor_pull[k]).abs() < 1e-8 * anchor_pull.norm().max(1.0),
            "axis {k}: {reaction} vs {}",
            anchor_pull[k]
        );
    }
}

#[test]
fn pulled_lower_cable_bends_the_cantilever_towards_it() {
    let mesh = beam();
    let clamp: Vec<i64> = mesh
        .nodes_in_box([-1e-9, -1.0, -1.0], [1e-9, 1.0, 1.0])
        .iter()
        .map(|&i| i as i64)
        .collect();
    let tip = mesh.nodes_in_box([0.4 - 1e-9, -1.0, -1.0], [0.4 + 1e-9, 1.0, 1.0]);
    let mut model = model_with(&[lower_edge_cable(0.5)], &clamp);
    let s = model
        .solve(
            &Loads::default(),
            None,
            &SolveOptions {
                load_steps: 1,
                ..Default::default()
            },
        )
        .unwrap();
    let tip_z: f64 = tip
        .iter()
        .map(|&i| s.positions[3 * i + 2] - mesh.rest()[i][2])
        .sum::<f64>()
        / tip.len() as f64;
    eprintln!(
        "tip z displacement {tip_z:.4} m after {} iterations, tensions {:?}",
        s.report.iterations,
        &s.cable_tensions[0][..3]
    );
    assert!(tip_z < -0.05, "tip z {tip_z}");
}
