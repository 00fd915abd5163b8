//! The mixed displacement-pressure formulation: exact answers, robustness as nu -> 0.5, and
//! equilibrium (reactions balance the weight) in both formulations.
mod common;

use common::{cantilever, solve_gravity, tip_displacement};
use sorofem_core::material::neo_hookean::lame_from_young;
use sorofem_core::material::Volumetric;
use sorofem_core::{Formulation, Loads, Material, Model, PressureMass, SolveOptions, TetMesh};
use std::sync::Arc;

const MIXED: Formulation = Formulation::Mixed {
    mass: PressureMass::Consistent,
};

#[test]
fn uniform_dilation_gives_the_analytic_pressure() {
    // x -> diag(1.1, 1, 1) x on every boundary node: J = 1.1 everywhere and the constraint
    // C p = phi gives p = lambda c(J) exactly (M_p 1 = sum_e V_e / 4 per node).
    for (volumetric, c) in [(Volumetric::Log, 1.1f64.ln()), (Volumetric::Linear, 0.1)] {
        // Consistent pressure mass only: with the lumped one, P1-P1 at nu = 0.4999 and every boundary
        // node prescribed, Newton from the unstretched interior lands on another equilibrium with
        // oscillating nodal pressures (a known weakness of lumped nodal-pressure tets).
        for mass in [PressureMass::Consistent] {
            let mesh = Arc::new(TetMesh::box_mesh([1.0, 1.0, 1.0], [3, 3, 3], [0.0; 3]).unwrap());
            let boundary =
                mesh.nodes_where(|p| p.iter().any(|&v| v.abs() < 1e-9 || (v - 1.0).abs() < 1e-9));
            let fixed: Vec<i64> = boundary.iter().map(|&i| i as i64).collect();
            let prescribed = boundary
                .iter()
                .map(|&i| [0.1 * mesh.rest()[i][0], 0.0, 0.0])
                .collect();
            let mut model = Model::try_new(
                mesh.clone(),
                &fixed,
                Formulation::Mixed { mass },
                volumetric,
            )
            .unwrap();
            let (mu, lambda) = lame_from_young(1e5, 0.4999);
            let m = mesh.n_tets();
            model
                .set_material(&Material {
                    mu: vec![mu; m],
                    lambda: vec![lambda; m],
                    density: vec![0.0; m],
                })
                .unwrap();
            let options = SolveOptions {
                tolerance: 1e-12,
                ..Default::default()
            };
            let solution = model
                .solve(
                    &Loads {
                        prescribed,
                        ..Default::default()
                    },
                    None,
                    &options,
                )
                .unwrap();
            let expected = lambda * c;
            for (i, p) in solution.pressure.unwrap().iter().enumerate() {
                assert!(
                    (p - expected).abs() < 1e-8 * expected.abs(),
                    "{volumetric:?} {mass:?}: node {i}: p = {p}, expected {expected}"
                );
            }
        }
    }
}

#[test]
fn nearly_incompressible_cantilever_converges_as_fast_as_the_compressible_standard_one() {
    let mut standard = cantilever(
        [0.4, 0.1, 0.1],
        [8, 2, 2],
        66e3,
        0.45,
        1080.0,
        Formulation::Standard,
    );
    let reference_iterations = solve_gravity(&mut standard, [0.0, 0.0, -9.81])
        .report
        .iterations;
    for nu in [0.4999, 0.4999999] {
        let mut mixed = cantilever([0.4, 0.1, 0.1], [8, 2, 2], 100e3, nu, 1080.0, MIXED);
        let solution = solve_gravity(&mut mixed, [0.0, 0.0, -9.81]);
        let r = &solution.report;
        eprintln!("nu = {nu}: mixed {} iterations (standard at nu = 0.45: {reference_iterations}); residuals {:?}", r.iterations, r.residual_history);
        assert!(r.converged && r.cutbacks == 0);
        assert!(
            r.iterations <= reference_iterations,
            "nu = {nu}: {} > {reference_iterations}",
            r.iterations
        );
        assert!(r.residual_history.last().unwrap() <= &1e-8);
    }
}

#[test]
fn mixed_and_standard_agree_for_compressible_material_under_refinement() {
    let mut gaps = Vec::new();
    for cells in [[8, 2, 2], [16, 4, 4]] {
        let tip = |formulation| {
            let mut model = cantilever([0.4, 0.1, 0.1], cells, 66e3, 0.3, 1080.0, formulation);
            let s = solve_gravity(&mut model, [0.0, 0.0, -0.981]);
            tip_displacement(&model, &s, 0.4)[2]
        };
        let (standard, mixed) = (tip(Formulation::Standard), tip(MIXED));
        gaps.push(((mixed - standard) / mixed).abs());
    }
    eprintln!("relative gap standard vs mixed: {gaps:?}");
    assert!(gaps[1] < 0.6 * gaps[0] && gaps[1] < 0.06, "{gaps:?}");
}

#[test]
fn reactions_balance_the_weight_in_both_formulations() {
    for formulation in [Formulation::Standard, MIXED] {
        let mut model = cantilever([0.4, 0.1, 0.1], [8, 2, 2], 66e3, 0.45, 1080.0, formulation);
        let solution = solve_gravity(&mut model, [0.0, -3.0, -9.81]);
        let weight = 1080.0 * 0.4 * 0.1 * 0.1;
        let total: Vec<f64> = (0..3)
            .map(|k| solution.reactions.iter().map(|r| r[k]).sum())
            .collect();
        for (k, g) in [0.0, -3.0, -9.81].iter().enumerate() {
            let err = (total[k] + weight * g).abs();
            assert!(
                err < 1e-6 * weight * 9.81,
                "{formulation:?}: reaction {k} = {}, weight component {}",
                total[k],
                weight * g
            );
        }
    }
}

#[test]
fn incompressible_limit_is_rejected_in_the_mixed_formulation() {
    let mesh = Arc::new(TetMesh::box_mesh([1.0, 0.1, 0.1], [2, 1, 1], [0.0; 3]).unwrap());
    let m = mesh.n_tets();
    let mut model = Model::try_new(mesh, &[0, 1, 2, 3], MIXED, Volumetric::Log).unwrap();
    let set = |model: &mut Model, lambda: f64| {
        model
            .set_material(&Material {
                mu: vec![1e4; m],
                lambda: vec![lambda; m],
                density: vec![0.0; m],
            })
            .unwrap_err()
            .to_string()
    };
    let zero = set(&mut model, 0.0);
    assert!(
        zero.contains("`lambda`") && zero.contains("mixed"),
        "{zero}"
    );
    let infinite = set(&mut model, f64::INFINITY);
    assert!(
        infinite.contains("`lambda`") && infinite.contains("finite"),
        "{infinite}"
    );
}
