//! Static equilibria against exact and analytic answers: the patch test, Euler-Bernoulli, and
//! Newton's convergence on the paper's cantilevers.
mod common;

use common::{cantilever, solve_gravity, tip_displacement};
use sorofem_core::material::neo_hookean::lame_from_young;
use sorofem_core::{Formulation, Loads, Material, Model, PressureMass, SolveOptions, TetMesh};
use std::sync::Arc;

#[test]
fn patch_test_affine_boundary_motion_gives_homogeneous_solution() {
    for formulation in [
        Formulation::Standard,
        Formulation::Mixed {
            mass: PressureMass::Consistent,
        },
    ] {
        let mesh = Arc::new(TetMesh::box_mesh([1.0, 0.5, 0.5], [4, 3, 3], [0.0; 3]).unwrap());
        let boundary: Vec<usize> = mesh.nodes_where(|p| {
            p[0].abs() < 1e-9
                || (p[0] - 1.0).abs() < 1e-9
                || p[1].abs() < 1e-9
                || (p[1] - 0.5).abs() < 1e-9
                || p[2].abs() < 1e-9
                || (p[2] - 0.5).abs() < 1e-9
        });
        let affine = |p: &[f64; 3]| {
            [
                0.2 * p[0] + 0.05 * p[1],
                -0.04 * p[1] + 0.03 * p[2],
                0.1 * p[0] - 0.06 * p[2],
            ]
        };
        let prescribed: Vec<[f64; 3]> = boundary.iter().map(|&i| affine(&mesh.rest()[i])).collect();
        let fixed: Vec<i64> = boundary.iter().map(|&i| i as i64).collect();
        let m = mesh.n_tets();
        let mut model = Model::try_new(
            mesh.clone(),
            &fixed,
            formulation,
            sorofem_core::material::Volumetric::Log,
        )
        .unwrap();
        let (mu, lambda) = lame_from_young(1e5, 0.45);
        model
            .set_material(&Material {
                mu: vec![mu; m],
                lambda: vec![lambda; m],
                density: vec![0.0; m],
            })
            .unwrap();
        let loads = Loads {
            prescribed,
            ..Default::default()
        };
        let solution = model
            .solve(
                &loads,
                None,
                &SolveOptions {
                    load_steps: 2,
                    ..Default::default()
                },
            )
            .unwrap();
        for i in 0..mesh.n_nodes() {
            let u = affine(&mesh.rest()[i]);
            for k in 0..3 {
                let err = (solution.positions[3 * i + k] - mesh.rest()[i][k] - u[k]).abs();
                assert!(
                    err < 1e-10,
                    "{formulation:?}: node {i} off the affine field by {err:e}"
                );
            }
        }
    }
}

#[test]
fn slender_cantilever_matches_euler_bernoulli() {
    // L/h = 20, nu = 0 and a tip deflection of 0.6% of L: the linear, nearly shear-free regime.
    let (length, h, youngs, density, g): (f64, f64, f64, f64, f64) =
        (1.0, 0.05, 1e6, 1000.0, 9.81e-3);
    let q = density * g * h * h;
    let w_eb = q * length.powi(4) / (8.0 * youngs * h * h.powi(3) / 12.0);
    let ratios: Vec<f64> = [[80, 4, 4], [160, 8, 8]]
        .iter()
        .map(|&cells| {
            let mut model = cantilever(
                [length, h, h],
                cells,
                youngs,
                0.0,
                density,
                Formulation::Standard,
            );
            let solution = solve_gravity(&mut model, [0.0, 0.0, -g]);
            -tip_displacement(&model, &solution, length)[2] / w_eb
        })
        .collect();
    // P1 tets are stiff in bending and converge from below at about second order in h.
    let error_reduction = (1.0 - ratios[0]) / (1.0 - ratios[1]);
    eprintln!("w / w_EB = {ratios:?}, error reduced {error_reduction:.2}x by halving h");
    assert!(ratios[0] < ratios[1] && ratios[1] < 1.0);
    assert!(
        (ratios[1] - 1.0).abs() < 0.06,
        "finest mesh: w / w_EB = {}",
        ratios[1]
    );
    assert!(error_reduction > 3.0, "error reduction {error_reduction}");
    // Richardson extrapolation at second order: the continuum's deflection, which exceeds
    // Euler-Bernoulli by the shear term (h/L)^2 E / (3 kappa G) = 0.2 % (nu = 0, kappa = 5/6).
    let extrapolated = ratios[1] + (ratios[1] - ratios[0]) / 3.0;
    assert!(
        (extrapolated - 1.002).abs() < 0.01,
        "extrapolated w / w_EB = {extrapolated}"
    );
}

#[test]
fn paper_cantilevers_converge_quadratically_in_one_load_step() {
    // The targets (the paper's code needs 19 to 42 on the first).
    for (length, max_iterations) in [(0.4, 12), (1.0, 25)] {
        let mut model = cantilever(
            [length, 0.1, 0.1],
            [8, 2, 2],
            66e3,
            0.45,
            1080.0,
            Formulation::Standard,
        );
        let solution = solve_gravity(&mut model, [0.0, 0.0, -9.81]);
        let r = &solution.report;
        eprintln!(
            "L = {length}: {} iterations, {} projected, history {:?}",
            r.iterations, r.projected_steps, r.residual_history
        );
        assert!(r.converged && r.cutbacks == 0 && r.load_steps == 1);
        assert!(
            r.iterations <= max_iterations,
            "L = {length}: {} Newton iterations",
            r.iterations
        );
        let h = &r.residual_history;
        // Quadratic convergence: once below 1e-3 each step at least squares the residual (up to a constant).
        let last = h.len() - 1;
        assert!(h[last] <= 1e-8);
        assert!(
            h[last] < 10.0 * h[last - 1].powf(1.5) || h[last - 1] < 1e-6,
            "{h:?}"
        );
    }
}

/// Newton with element pressure iterates takes the volumetric part of its Hessians at those
/// iterates, not at lambda c(J): the equilibrium must be the one of the exact Hessian (same
/// energy, same gradient), reached in fewer iterations on the large-rotation cantilevers.
#[test]
fn pressure_iterates_reach_the_exact_hessians_equilibrium_in_fewer_iterations() {
    for (length, cells) in [(0.4, [8, 2, 2]), (1.0, [8, 2, 2]), (1.0, [16, 4, 4])] {
        let mut model = cantilever(
            [length, 0.1, 0.1],
            cells,
            66e3,
            0.45,
            1080.0,
            Formulation::Standard,
        );
        let loads = Loads {
            gravity: [0.0, 0.0, -9.81],
            ..Default::default()
        };
        let solve = |model: &mut Model, pressure_iterates: bool| {
            let options = SolveOptions {
                tolerance: 1e-10,
                pressure_iterates,
                ..Default::default()
            };
            model.solve(&loads, None, &options).unwrap()
        };
        let exact = solve(&mut model, false);
        let iterated = solve(&mut model, true);
        let rest = model.mesh().rest_flat().to_vec();
        let scale = exact
            .positions
            .iter()
            .zip(&rest)
            .fold(0.0f64, |m, (x, r)| m.max((x - r).abs()));
        let difference = exact
            .positions
            .iter()
            .zip(&iterated.positions)
            .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
        eprintln!(
            "L = {length} {cells:?}: {} iterations with pressure iterates, {} without; max |du| = {difference:.2e} of {scale:.3}",
            iterated.report.iterations, exact.report.iterations
        );
        assert!(difference <= 1e-7 * scale, "{difference} vs {scale}");
        assert!(iterated.report.iterations < exact.report.iterations);
    }
}

/// The element kernels' general path (what models without closed forms take) on the
/// Neo-Hookean cantilevers: the same Newton iterations and equilibrium as the closed forms, in
/// both formulations (large rotations, so the projected Hessian is exercised without pressure
/// iterates).
#[test]
fn general_material_path_reproduces_the_neo_hookean_closed_forms() {
    let mixed = Formulation::Mixed {
        mass: sorofem_core::PressureMass::Consistent,
    };
    for (formulation, nu, pressure_iterates) in [
        (Formulation::Standard, 0.45, true),
        (Formulation::Standard, 0.45, false),
        (mixed, 0.4999, true),
    ] {
        let mut model = cantilever([1.0, 0.1, 0.1], [8, 2, 2], 66e3, nu, 1080.0, formulation);
        let loads = Loads {
            gravity: [0.0, 0.0, -9.81],
            ..Default::default()
        };
        let options = SolveOptions {
            pressure_iterates,
            ..Default::default()
        };
        let closed = model.solve(&loads, None, &options).unwrap();
        model.set_closed_forms(false);
        let general = model.solve(&loads, None, &options).unwrap();
        let difference = closed
            .positions
            .iter()
            .zip(&general.positions)
            .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
        let (a, b) = (&closed.report, &general.report);
        eprintln!(
            "{formulation:?}, iterates {pressure_iterates}: {} / {} iterations ({} / {} projected), max |dx| {difference:.1e} m",
            a.iterations, b.iterations, a.projected_steps, b.projected_steps
        );
        assert_eq!(a.iterations, b.iterations);
        assert_eq!(a.projected_steps, b.projected_steps);
        assert!(difference < 1e-9, "{difference}");
    }
}

#[test]
fn inverted_or_bad_inputs_are_rejected_with_named_parameters() {
    let mesh = Arc::new(TetMesh::box_mesh([1.0, 0.1, 0.1], [2, 1, 1], [0.0; 3]).unwrap());
    let err = Model::try_new(
        mesh.clone(),
        &[0, 999],
        Formulation::Standard,
        sorofem_core::material::Volumetric::Log,
    )
    .err()
    .unwrap();
    assert!(
        err.to_string().contains("`fixed`") && err.to_string().contains("999"),
        "{err}"
    );
    let mut model = Model::try_new(
        mesh.clone(),
        &[0, 1],
        Formulation::Standard,
        sorofem_core::material::Volumetric::Log,
    )
    .unwrap();
    let m = mesh.n_tets();
    let err = model
        .set_material(&Material {
            mu: vec![1e4; m],
            lambda: vec![f64::INFINITY; m],
            density: vec![0.0; m],
        })
        .unwrap_err();
    assert!(err.to_string().contains("`lambda`"), "{err}");
    let err = model
        .set_material(&Material {
            mu: vec![1e4; m - 1],
            lambda: vec![1e5; m],
            density: vec![0.0; m],
        })
        .unwrap_err();
    assert!(err.to_string().contains("`mu`"), "{err}");
}

#[test]
fn nonconvergence_is_an_error_with_a_residual_history() {
    let mut model = cantilever(
        [1.0, 0.1, 0.1],
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
    let options = SolveOptions {
        max_iterations: 2,
        max_cutbacks: 1,
        ..Default::default()
    };
    match model.solve(&loads, None, &options) {
        Err(sorofem_core::Error::NotConverged { report, message }) => {
            assert!(
                !report.converged && !report.residual_history.is_empty(),
                "{message}"
            );
            assert!(message.contains("did not converge"));
        }
        other => panic!("expected NotConverged, got {other:?}"),
    }
}

#[test]
fn box_mesh_reproduces_the_paper_box2_tet() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/solidfem/box2.tet");
    let Ok(text) = std::fs::read_to_string(&path) else {
        // CI provides ../shared: there a missing file is a failure, elsewhere a loud skip.
        assert!(
            std::env::var_os("CI").is_none(),
            "{} not found; CI must provide ../shared/data/solidfem (the CI environment variable is set)",
            path.display()
        );
        eprintln!("SKIPPED: {} not found", path.display());
        return;
    };
    let mut points: Vec<[f64; 3]> = Vec::new();
    let mut tets: Vec<[usize; 4]> = Vec::new();
    for line in text.lines() {
        let f: Vec<&str> = line.split_whitespace().collect();
        match f.first() {
            Some(&"v") => points.push([0, 1, 2].map(|k| f[k + 1].parse().unwrap())),
            Some(&"t") => tets.push([0, 1, 2, 3].map(|k| f[k + 1].parse().unwrap())),
            _ => {}
        }
    }
    let mesh = TetMesh::box_mesh([0.4, 0.1, 0.1], [8, 2, 2], [0.0; 3]).unwrap();
    // Same nodes (in another numbering) and the same tets as sets of positions.
    let key = |p: &[f64; 3]| p.map(|v| (v * 1e6).round() as i64);
    let ours: std::collections::HashMap<[i64; 3], usize> = mesh
        .rest()
        .iter()
        .enumerate()
        .map(|(i, p)| (key(p), i))
        .collect();
    assert_eq!(ours.len(), points.len());
    let as_set = |t: [usize; 4]| {
        let mut s = t;
        s.sort_unstable();
        s
    };
    let theirs: std::collections::HashSet<[usize; 4]> = tets
        .iter()
        .map(|t| as_set(t.map(|i| ours[&key(&points[i])])))
        .collect();
    let mine: std::collections::HashSet<[usize; 4]> =
        mesh.tets().iter().map(|&t| as_set(t)).collect();
    assert_eq!(theirs, mine);
}
