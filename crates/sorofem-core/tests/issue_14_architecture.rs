//! Regressions of issue 14 (architecture): rules written once now apply everywhere.
mod common;

use common::cantilever;
use sorofem_core::material::{MaterialModel, Volumetric};
use sorofem_core::{Damping, Error, Formulation, Loads, SolveOptions};

/// `simulate` checked none of its loads: a nodal force on a node past the mesh panicked inside
/// the force term, and a NaN gravity gave a NaN trajectory. It now shares `solve`'s checks.
#[test]
fn simulate_rejects_the_loads_solve_rejects() {
    let mut model = cantilever(
        [0.4, 0.1, 0.1],
        [4, 1, 1],
        66e3,
        0.45,
        1080.0,
        Formulation::Standard,
    );
    let n = model.mesh().n_nodes();
    let simulate = |model: &mut sorofem_core::Model, loads: &Loads| {
        model.simulate(
            loads,
            0.01,
            2,
            &[vec![], vec![]],
            Damping::default(),
            None,
            None,
            &SolveOptions::default(),
            1,
        )
    };
    let past_the_mesh = Loads {
        nodal_forces: vec![(n, [0.0, 0.0, 1.0])],
        ..Default::default()
    };
    let err = simulate(&mut model, &past_the_mesh).unwrap_err();
    assert!(
        matches!(&err, Error::IndexOutOfRange { param, .. } if param == "forces"),
        "{err}"
    );
    let nan_gravity = Loads {
        gravity: [0.0, f64::NAN, 0.0],
        ..Default::default()
    };
    let err = simulate(&mut model, &nan_gravity).unwrap_err();
    assert!(
        matches!(&err, Error::NonFinite { param, .. } if param == "gravity"),
        "{err}"
    );
}

/// Material parameters are checked by the model they belong to, and the error names the
/// parameter and the tet; names are matched exactly once each.
#[test]
fn material_parameters_are_validated_by_name() {
    let mut model = cantilever(
        [0.4, 0.1, 0.1],
        [4, 1, 1],
        66e3,
        0.45,
        1080.0,
        Formulation::Mixed {
            mass: sorofem_core::PressureMass::Consistent,
        },
    );
    let m = model.mesh().n_tets();
    let neo_hookean = MaterialModel::NeoHookean {
        volumetric: Volumetric::Log,
    };
    assert_eq!(model.material_param_names(), ["mu", "lambda"]);
    let density = vec![1000.0; m];
    // mu = 20 kPa everywhere but at tet 3.
    let params = |mu_at_3: f64, lambda: f64| {
        let mut mu = vec![2e4; m];
        mu[3] = mu_at_3;
        vec![
            ("mu".to_string(), mu),
            ("lambda".to_string(), vec![lambda; m]),
        ]
    };
    let message = |result: sorofem_core::Result<()>| result.unwrap_err().to_string();
    let err = message(model.set_material_model(neo_hookean, &params(-2e4, 1e5), &density));
    assert!(err.contains("`mu`") && err.contains("at tet 3"), "{err}");
    // lambda = 0 (nu = 0) is a valid standard material but not a mixed one.
    let err = message(model.set_material_model(neo_hookean, &params(2e4, 0.0), &density));
    assert!(err.contains("`lambda`") && err.contains("mixed"), "{err}");
    let mut unknown = params(2e4, 1e5);
    unknown.push(("c10".into(), vec![1.0; m]));
    let err = message(model.set_material_model(neo_hookean, &unknown, &density));
    assert!(err.contains("\"c10\""), "{err}");
    let missing = &params(2e4, 1e5)[..1];
    let err = message(model.set_material_model(neo_hookean, missing, &density));
    assert!(err.contains("\"lambda\" 0 times"), "{err}");
    model
        .set_material_model(neo_hookean, &params(2e4, 1e5), &density)
        .unwrap();
}

/// Forward sensitivities take any of the model's parameter blocks by name and reject others
/// (they used to read missing or short blocks as zero).
#[test]
fn forward_directions_name_the_models_parameters() {
    let mut model = cantilever(
        [0.4, 0.1, 0.1],
        [4, 1, 1],
        66e3,
        0.45,
        1080.0,
        Formulation::Standard,
    );
    let loads = Loads {
        gravity: [0.0, 0.0, -9.81],
        ..Default::default()
    };
    model.solve(&loads, None, &SolveOptions::default()).unwrap();
    let zeros = model.param_zeros();
    let names: Vec<&str> = zeros.blocks.iter().map(|(n, _)| n.as_str()).collect();
    assert_eq!(
        names,
        [
            "mu",
            "lambda",
            "density",
            "gravity",
            "cable_actuation",
            "cable_stiffness",
            "cable_tension",
            "cable_pull"
        ]
    );
    let mut bogus = zeros.clone();
    bogus.blocks.push(("c10".into(), vec![1.0]));
    assert!(model
        .forward(&bogus)
        .unwrap_err()
        .to_string()
        .contains("c10"));
    let mut short = zeros.clone();
    short.get_mut("gravity").unwrap().pop();
    assert!(matches!(
        model.forward(&short).unwrap_err(),
        Error::Shape { .. }
    ));
    // Blocks left out are zero: gravity alone is the full direction with only gravity set.
    let mut along_g = sorofem_core::sensitivity::ParamVector::default();
    along_g
        .blocks
        .push(("gravity".into(), vec![0.0, 0.0, -9.81]));
    let mut full = zeros.clone();
    *full.get_mut("gravity").unwrap() = vec![0.0, 0.0, -9.81];
    let (dx, _) = model.forward(&along_g).unwrap();
    assert!(dx.iter().any(|v| v.abs() > 1e-6));
    assert_eq!(dx, model.forward(&full).unwrap().0);
}
