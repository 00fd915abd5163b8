//! Tendons: length derivatives, sliding, exact displacement control (pull met, slack when
//! pushed, quadratic convergence), agreement of the two commands, work and energy, force
//! balance with an anchored motor, the axial bar against T L / (E A), both formulations,
//! dynamics, bad input and sensitivities.
mod common;

use common::{check_directional, check_gradient, check_jacobian, Rng};
use sorofem_core::assembly::Assembler;
use sorofem_core::cables::CableSpec;
use sorofem_core::energy::{HessianMode, PointMap, Tendon, TendonCommand, TendonTerm, Term};
use sorofem_core::material::neo_hookean::lame_from_young;
use sorofem_core::material::Volumetric;
use sorofem_core::sensitivity::ParamVector;
use sorofem_core::{
    Damping, DynamicsOptions, Error, Formulation, Loads, Material, Model, PressureMass, Solution,
    SolveOptions, StepMethod, TetMesh,
};
use std::sync::Arc;

const GRAVITY: [f64; 3] = [0.0, 0.0, -9.81];
const MIXED: Formulation = Formulation::Mixed {
    mass: PressureMass::Consistent,
};

/// A `size` box clamped at x = 0 with cables, E (Pa), nu, rho = 1080 kg/m^3.
fn box_model(
    size: [f64; 3],
    cells: [usize; 3],
    cables: &[CableSpec],
    formulation: Formulation,
    youngs: f64,
    nu: f64,
) -> Model {
    let mesh = Arc::new(TetMesh::box_mesh(size, cells, [0.0; 3]).unwrap());
    let fixed: Vec<i64> = mesh
        .nodes_in_box([-1e-9, -1.0, -1.0], [1e-9, 1.0, 1.0])
        .iter()
        .map(|&i| i as i64)
        .collect();
    let m = mesh.n_tets();
    let mut model =
        Model::try_new_with_cables(mesh, &fixed, formulation, Volumetric::Log, cables).unwrap();
    let (mu, lambda) = lame_from_young(youngs, nu);
    model
        .set_material(&Material {
            mu: vec![mu; m],
            lambda: vec![lambda; m],
            density: vec![1080.0; m],
        })
        .unwrap();
    model
}

/// The 0.4 x 0.1 x 0.1 m beam (8x2x2 cells, E = 66 kPa, nu = 0.45) clamped at x = 0.
fn beam(cables: &[CableSpec], formulation: Formulation) -> Model {
    box_model([0.4, 0.1, 0.1], [8, 2, 2], cables, formulation, 66e3, 0.45)
}

/// A tendon along the beam at height `z` (1 cm inside its upper or lower face), 9 guide points.
fn tendon_at(z: f64, command: TendonCommand) -> CableSpec {
    let points = (0..9)
        .map(|k| [0.01 + 0.0475 * k as f64, 0.05, z])
        .collect();
    CableSpec::tendon(points, command)
}

const UPPER: f64 = 0.09;
const LOWER: f64 = 0.01;

fn options(tolerance: f64) -> SolveOptions {
    SolveOptions {
        tolerance,
        ..Default::default()
    }
}

fn solve(model: &mut Model, gravity: [f64; 3], tolerance: f64) -> Solution {
    let loads = Loads {
        gravity,
        ..Default::default()
    };
    model.solve(&loads, None, &options(tolerance)).unwrap()
}

fn max_difference(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).fold(0.0, |m, (x, y)| m.max((x - y).abs()))
}

fn max_displacement(model: &Model, positions: &[f64]) -> f64 {
    let rest = model.mesh().rest_flat();
    max_difference(positions, &rest)
}

/// A bent tendon: an anchor, a guide point over four blocks, one on its own block, the end on
/// two blocks.
fn bent_tendon(tension: f64) -> TendonTerm {
    let points = vec![
        PointMap {
            offset: [0.0, 0.0, 0.0],
            dof_blocks: vec![],
            weights: vec![],
        },
        PointMap {
            offset: [1.0, 0.2, 0.0],
            dof_blocks: vec![0, 3, 6, 9],
            weights: vec![0.1, 0.2, 0.3, 0.4],
        },
        PointMap {
            offset: [1.5, 1.0, 0.3],
            dof_blocks: vec![12],
            weights: vec![1.0],
        },
        PointMap {
            offset: [0.8, 1.6, 0.1],
            dof_blocks: vec![15, 18],
            weights: vec![0.7, 0.3],
        },
    ];
    let rest_lengths = points
        .windows(2)
        .map(|w| {
            (0..3)
                .map(|i| (w[1].offset[i] - w[0].offset[i]).powi(2))
                .sum::<f64>()
                .sqrt()
        })
        .collect();
    let tendon = Tendon {
        points,
        rest_lengths,
        command: TendonCommand::Tension(tension),
        tension,
    };
    TendonTerm::new(vec![tendon], vec![0], 1)
}

#[test]
fn tendon_length_energy_and_parameter_derivatives_match_central_differences() {
    let term = bent_tendon(3.5);
    let mut rng = Rng::new(5);
    let mut dofs = vec![0; 24];
    for e in 0..term.n_elements() {
        term.element_dofs(e, &mut dofs);
        let z = rng.vec(24, 0.05);
        let mut grad = vec![0.0; 24];
        let mut hess = vec![0.0; 24 * 24];
        let energy = term.element(e, &z, Some(&mut grad), Some(&mut hess), HessianMode::Exact);
        assert!(energy > 0.0);
        let value = |x: &[f64]| term.element(e, x, None, None, HessianMode::Exact);
        check_gradient(
            &format!("segment {e} gradient"),
            &z,
            1e-7,
            value,
            &grad,
            1e-7,
            1e-10,
        );
        let gradient = |x: &[f64]| {
            let mut g = vec![0.0; 24];
            term.element(e, x, Some(&mut g), None, HessianMode::Exact);
            g
        };
        check_jacobian(
            &format!("segment {e} Hessian"),
            &z,
            1e-6,
            gradient,
            &hess,
            1e-6,
            1e-9,
        );
        // T (I - n n^T) / l is positive semi-definite: x^T H x >= 0.
        for _ in 0..10 {
            let x = rng.vec(24, 1.0);
            let quadratic: f64 = (0..24)
                .map(|i| (0..24).map(|j| x[i] * hess[i * 24 + j] * x[j]).sum::<f64>())
                .sum();
            assert!(quadratic >= -1e-12, "segment {e}: x^T H x = {quadratic}");
        }
        // d(grad)/dT = dl/dz (force control).
        let mut d_tension = vec![0.0; 24];
        sorofem_core::energy::ParamTerm::element_param_gradient(&term, e, &z, &mut d_tension);
        for (a, b) in d_tension.iter().zip(&grad) {
            assert!((a * 3.5 - b).abs() <= 1e-12 * b.abs().max(1.0));
        }
    }
    // dL/dz of the whole tendon on the full DOFs.
    let tendon = &term.tendons[0];
    let z = rng.vec(21, 0.05);
    let mut gradient = vec![0.0; 21];
    tendon.add_length_gradient(&z, 1.0, &mut gradient);
    check_gradient(
        "tendon length",
        &z,
        1e-7,
        |x| tendon.length(x),
        &gradient,
        1e-7,
        1e-10,
    );
    // d2L/dz2 v: the derivative of dL/dz along v, by central differences.
    let v = rng.vec(21, 1.0);
    let mut product = vec![0.0; 21];
    tendon.add_length_hessian_product(&z, 2.5, &v, &mut product);
    for (i, &analytic) in product.iter().enumerate() {
        check_directional(
            &format!("tendon length Hessian product, row {i}"),
            &z,
            &v,
            1e-6,
            |x| {
                let mut g = vec![0.0; 21];
                tendon.add_length_gradient(x, 2.5, &mut g);
                g[i]
            },
            analytic,
            1e-6,
        );
    }
}

#[test]
fn force_at_a_guide_point_is_the_tension_times_the_turn_of_the_tendon() {
    // Guide point 2 sits alone on block 12: the tendon's force there is all the gradient's.
    let tension = 2.5;
    let term = bent_tendon(tension);
    let mut rng = Rng::new(8);
    let z = rng.vec(21, 0.05);
    let assembler = Assembler::new(&[false; 21], &[&term]);
    let gradient = assembler.full_gradient(&[&term], &z);
    let tendon = &term.tendons[0];
    let y: Vec<_> = (0..4).map(|k| tendon.points[k].position(&z)).collect();
    let e_in = (y[2] - y[1]).normalize();
    let e_out = (y[3] - y[2]).normalize();
    // dL/dy_2 = e_in - e_out: the body feels -T (e_in - e_out), towards the inside of the turn.
    let expected = tension * (e_in - e_out);
    for i in 0..3 {
        assert!(
            (gradient[12 + i] - expected[i]).abs() < 1e-12,
            "component {i}: {} vs {}",
            gradient[12 + i],
            expected[i]
        );
    }
    // The same tension on both sides: the force is along the bisector of the turn, and its
    // components along e_in and e_out have equal size (a spring chain's need not).
    let (along_in, along_out) = (expected.dot(&e_in), expected.dot(&e_out));
    assert!((along_in + along_out).abs() < 1e-12);
}

#[test]
fn a_pull_is_met_exactly_with_quadratic_convergence_in_both_formulations() {
    for formulation in [Formulation::Standard, MIXED] {
        for pull in [0.005, 0.02, 0.06] {
            let mut model = beam(&[tendon_at(UPPER, TendonCommand::Pull(pull))], formulation);
            let s = solve(&mut model, GRAVITY, 1e-8);
            let (tension, reached) = (s.tendon_tensions[0].unwrap(), s.tendon_pulls[0].unwrap());
            let label = format!("{formulation:?}, pull {pull}");
            assert!(
                (reached - pull).abs() <= 1e-9 * pull,
                "{label}: reached {reached}"
            );
            assert!(tension > 0.0, "{label}: taut, tension {tension}");
            assert!(s.cable_tensions[0].iter().all(|&t| t == tension));
            // Quadratic: each of the last two steps squares the relative residual (or better).
            let h = &s.report.residual_history;
            let n = h.len();
            assert!(n >= 3, "{label}: {h:?}");
            for k in [n - 2, n - 1] {
                if h[k - 1] < 1e-2 {
                    assert!(
                        h[k].ln() / h[k - 1].ln() >= 1.7,
                        "{label}: not quadratic: {h:?}"
                    );
                }
            }
        }
    }
}

#[test]
fn a_push_leaves_the_tendon_slack_and_the_body_as_without_it() {
    let tolerance = 1e-12;
    let mut free = beam(&[], Formulation::Standard);
    let reference = solve(&mut free, GRAVITY, tolerance);
    for pull in [-0.01, 0.0] {
        // The lower face shortens under gravity: a tendon there, not pulled, goes slack.
        let mut model = beam(
            &[tendon_at(LOWER, TendonCommand::Pull(pull))],
            Formulation::Standard,
        );
        let s = solve(&mut model, GRAVITY, tolerance);
        assert_eq!(s.tendon_tensions[0], Some(0.0), "pull {pull}");
        assert!(s.tendon_pulls[0].unwrap() > pull, "pull {pull}: slack");
        let scale = max_displacement(&free, &reference.positions);
        let difference = max_difference(&s.positions, &reference.positions);
        eprintln!(
            "pull {pull}: {difference:.3e} m from the tendon-free solution (scale {scale:.3e} m)"
        );
        assert!(
            difference <= 1e-10 * scale,
            "pull {pull}: {difference:.3e} m from the tendon-free solution (scale {scale:.3e})"
        );
    }
}

#[test]
fn tension_and_pull_commands_give_the_same_equilibrium() {
    let tolerance = 1e-12;
    for formulation in [Formulation::Standard, MIXED] {
        let tension = 20.0;
        let mut forced = beam(
            &[tendon_at(UPPER, TendonCommand::Tension(tension))],
            formulation,
        );
        let by_tension = solve(&mut forced, GRAVITY, tolerance);
        let pull = by_tension.tendon_pulls[0].unwrap();
        assert_eq!(by_tension.tendon_tensions[0], Some(tension));
        let mut pulled = beam(&[tendon_at(UPPER, TendonCommand::Pull(pull))], formulation);
        let by_pull = solve(&mut pulled, GRAVITY, tolerance);
        let found = by_pull.tendon_tensions[0].unwrap();
        assert!(
            (found - tension).abs() <= 1e-7 * tension,
            "{formulation:?}: tension {found} for the pull {pull} that {tension} N gives"
        );
        let scale = max_displacement(&forced, &by_tension.positions);
        let difference = max_difference(&by_pull.positions, &by_tension.positions);
        eprintln!(
            "{formulation:?}: pull {pull:.6e} m; tension {found:.12} N for {tension} N; displacements differ by {difference:.3e} m (scale {scale:.3e})"
        );
        assert!(
            difference <= 1e-9 * scale,
            "{formulation:?}: displacements differ by {difference:.3e} m (scale {scale:.3e})"
        );
    }
}

#[test]
fn the_work_of_the_tendon_is_the_strain_energy_it_stores() {
    // Gravity off: the tendon is the only load, so int T dd = W(d).
    let mut model = beam(
        &[tendon_at(LOWER, TendonCommand::Pull(0.0))],
        Formulation::Standard,
    );
    let steps = 40;
    let final_pull = 0.03;
    let (mut work, mut last_tension, mut positions) = (0.0, 0.0, None::<Vec<f64>>);
    for k in 1..=steps {
        let pull = final_pull * k as f64 / steps as f64;
        model
            .set_tendon_command(0, TendonCommand::Pull(pull))
            .unwrap();
        let s = model
            .solve(&Loads::default(), positions.as_deref(), &options(1e-10))
            .unwrap();
        let tension = s.tendon_tensions[0].unwrap();
        work += 0.5 * (tension + last_tension) * final_pull / steps as f64;
        last_tension = tension;
        positions = Some(s.positions);
    }
    let energy = model.strain_energy(positions.as_deref().unwrap()).unwrap();
    eprintln!("work {work:.6e} J, strain energy {energy:.6e} J, final tension {last_tension:.4} N");
    assert!(
        (work - energy).abs() <= 1e-3 * energy,
        "work {work:.6e} J vs strain energy {energy:.6e} J"
    );
}

#[test]
fn supports_motor_and_weight_balance() {
    for command in [TendonCommand::Pull(0.02), TendonCommand::Tension(30.0)] {
        let mut tendon = tendon_at(UPPER, command);
        tendon.points.insert(0, [-0.03, 0.05, 0.11]);
        tendon.anchor_first = true;
        let mut model = beam(&[tendon], Formulation::Standard);
        let s = solve(&mut model, GRAVITY, 1e-10);
        let tension = s.tendon_tensions[0].unwrap();
        assert!(tension > 0.0);
        let mass: f64 = 1080.0 * model.mesh().volumes().iter().sum::<f64>();
        let weight = GRAVITY.map(|g| mass * g);
        // The tendon pulls the body towards the motor at its first guide point.
        let points = &s.cable_points[0];
        let to_motor: [f64; 3] = std::array::from_fn(|i| points[0][i] - points[1][i]);
        let length = to_motor.iter().map(|v| v * v).sum::<f64>().sqrt();
        let norm = weight.iter().map(|v| v * v).sum::<f64>().sqrt();
        for i in 0..3 {
            let reactions: f64 = s.reactions.iter().map(|r| r[i]).sum();
            let total = reactions + weight[i] + tension * to_motor[i] / length;
            eprintln!("{command:?} axis {i}: reactions {reactions:.6} N, imbalance {total:.3e} N");
            assert!(
                total.abs() <= 1e-8 * norm,
                "{command:?}, axis {i}: imbalance {total:.3e} N of a {norm:.3} N weight"
            );
        }
    }
}

#[test]
fn an_axial_tendon_shortens_a_slender_bar_by_tl_over_ea() {
    // nu = 0: uniaxial stress; the mean end-face displacement under a point load at the face's
    // centre is that of a uniform traction (Betti), T L / (E A) in the linear regime.
    let (length, side, youngs, tension) = (1.0, 0.05, 1e6, 0.05);
    let centre = side / 2.0;
    let mut tendon = CableSpec::tendon(
        vec![
            [-0.01, centre, centre],
            [0.0, centre, centre],
            [length, centre, centre],
        ],
        TendonCommand::Tension(tension),
    );
    tendon.anchor_first = true;
    let mut model = box_model(
        [length, side, side],
        [40, 4, 4],
        &[tendon],
        Formulation::Standard,
        youngs,
        0.0,
    );
    let s = solve(&mut model, [0.0; 3], 1e-10);
    let tip = model
        .mesh()
        .nodes_in_box([length - 1e-9, -1.0, -1.0], [length + 1e-9, 1.0, 1.0]);
    let rest = model.mesh().rest();
    let shortening = -tip
        .iter()
        .map(|&i| s.positions[3 * i] - rest[i][0])
        .sum::<f64>()
        / tip.len() as f64;
    let expected = tension * length / (youngs * side * side);
    eprintln!("mean shortening {shortening:.6e} m vs T L / (E A) = {expected:.6e} m");
    assert!(
        (shortening - expected).abs() <= 0.02 * expected,
        "mean shortening {shortening:.6e} m vs T L / (E A) = {expected:.6e} m"
    );
}

#[test]
fn a_pulled_tendon_holds_its_length_in_every_time_step() {
    let mut model = beam(
        &[tendon_at(UPPER, TendonCommand::Pull(0.0))],
        Formulation::Standard,
    );
    let steps = 10;
    let pulls: Vec<Vec<f64>> = (0..steps).map(|s| vec![0.002 * (s + 1) as f64]).collect();
    let loads = Loads {
        gravity: GRAVITY,
        ..Default::default()
    };
    let trajectory = model
        .simulate(
            &loads,
            0.01,
            steps,
            &pulls,
            Damping::default(),
            None,
            None,
            &options(1e-8),
            1,
        )
        .unwrap();
    for (frame, pulled) in trajectory.tendon_pulls.iter().enumerate().skip(1) {
        let (pulled, tension) = (pulled[0].unwrap(), trajectory.tendon_tensions[frame][0]);
        let commanded = pulls[frame - 1][0];
        assert!(
            (pulled - commanded).abs() <= 1e-9 * 0.38 || tension == Some(0.0),
            "frame {frame}: pulled {pulled} for {commanded}, tension {tension:?}"
        );
    }
    let last = trajectory.tendon_tensions.last().unwrap()[0].unwrap();
    assert!(last > 0.0, "the tendon ends taut: {last}");
}

/// Every step method keeps a pulled tendon's multiplier in its state: Newton and modified Newton
/// (whose kept factorisation borders the tendon rows anew at each direction and is refactorised
/// when the tendon goes taut) hold the pull to the length tolerance and agree on the tension to
/// the Newton tolerance; a linearly implicit step meets the linearised constraint, so the pull
/// to second order in the step's motion. With stiffness damping the tendon still pulls with its
/// tension: once the body is at rest it is the static solve's.
#[test]
fn a_pulled_tendon_holds_its_length_in_every_step_method() {
    let loads = Loads {
        gravity: GRAVITY,
        ..Default::default()
    };
    let (ramp, hold) = (10, 300);
    let pulls: Vec<Vec<f64>> = (0..ramp + hold)
        .map(|s| vec![0.002 * (s + 1).min(ramp) as f64])
        .collect();
    let damping = Damping {
        mass: 20.0,
        stiffness: 0.002,
    };
    let run = |method: StepMethod| {
        let mut model = beam(
            &[tendon_at(UPPER, TendonCommand::Pull(0.0))],
            Formulation::Standard,
        );
        let dynamics = DynamicsOptions {
            newton: options(1e-10),
            method,
            save_every: 1,
        };
        let trajectory = model
            .simulate_with(
                &loads,
                0.01,
                pulls.len(),
                &pulls,
                damping,
                None,
                None,
                &dynamics,
            )
            .unwrap();
        let statics = {
            model
                .set_tendon_command(0, TendonCommand::Pull(0.02))
                .unwrap();
            solve(&mut model, GRAVITY, 1e-10)
        };
        (trajectory, statics.tendon_tensions[0].unwrap())
    };
    let mut tensions = Vec::new();
    for method in [
        StepMethod::Newton,
        StepMethod::Modified,
        StepMethod::LinearlyImplicit,
    ] {
        let (trajectory, static_tension) = run(method);
        let tolerance = match method {
            StepMethod::LinearlyImplicit => 1e-5,
            _ => 1e-9 * 0.38,
        };
        for (frame, pulled) in trajectory.tendon_pulls.iter().enumerate().skip(1) {
            let (pulled, tension) = (pulled[0].unwrap(), trajectory.tendon_tensions[frame][0]);
            let commanded = pulls[frame - 1][0];
            assert!(
                (pulled - commanded).abs() <= tolerance || tension == Some(0.0),
                "{method:?}, frame {frame}: pulled {pulled} for {commanded}, tension {tension:?}"
            );
        }
        let last = trajectory.tendon_tensions.last().unwrap()[0].unwrap();
        assert!(
            (last - static_tension).abs() <= 1e-3 * static_tension,
            "{method:?}: tension at rest {last} N, static {static_tension} N"
        );
        tensions.push(trajectory.tendon_tensions);
    }
    for (newton, modified) in tensions[0].iter().zip(&tensions[1]) {
        let (a, b) = (newton[0].unwrap(), modified[0].unwrap());
        assert!((a - b).abs() <= 1e-6 * a.abs().max(1e-3), "{a} vs {b}");
    }
}

fn expect_invalid(result: Result<Model, Error>, param: &str) {
    match result {
        Err(Error::InvalidParameter { param: p, .. }) | Err(Error::Shape { param: p, .. }) => {
            assert_eq!(p, param)
        }
        Err(other) => panic!("{param}: unexpected error {other}"),
        Ok(_) => panic!("{param}: accepted"),
    }
}

#[test]
fn bad_tendons_are_refused_naming_the_parameter() {
    let mesh = Arc::new(TetMesh::box_mesh([0.4, 0.1, 0.1], [4, 2, 2], [0.0; 3]).unwrap());
    let build = |spec: CableSpec| {
        Model::try_new_with_cables(
            mesh.clone(),
            &[0],
            Formulation::Standard,
            Volumetric::Log,
            &[spec],
        )
    };
    let line = |n: usize| -> Vec<[f64; 3]> {
        (0..n)
            .map(|k| [0.01 + 0.38 * k as f64 / (n - 1).max(1) as f64, 0.05, 0.05])
            .collect()
    };
    expect_invalid(
        build(CableSpec::tendon(line(1), TendonCommand::Pull(0.0))),
        "cables[0].points",
    );
    let mut coincident = line(3);
    coincident[2] = coincident[1];
    expect_invalid(
        build(CableSpec::tendon(coincident, TendonCommand::Pull(0.0))),
        "cables[0].points",
    );
    let mut outside = line(3);
    outside[1][2] = 0.2;
    expect_invalid(
        build(CableSpec::tendon(outside, TendonCommand::Pull(0.0))),
        "cables[0].points[1]",
    );
    expect_invalid(
        build(CableSpec::tendon(line(3), TendonCommand::Pull(0.38))),
        "cables[0].pull",
    );
    expect_invalid(
        build(CableSpec::tendon(line(3), TendonCommand::Tension(-1.0))),
        "cables[0].tension",
    );
    let mut free = CableSpec::tendon(line(3), TendonCommand::Pull(0.0));
    free.outside = sorofem_core::cables::Outside::FreeNode;
    expect_invalid(build(free), "cables[0].outside");
    // Commands go to the right kind of cable.
    let mut model = build(CableSpec::tendon(line(3), TendonCommand::Pull(0.0))).unwrap();
    assert!(matches!(
        model.set_actuation(0, 0.9),
        Err(Error::InvalidParameter { .. })
    ));
    assert!(matches!(
        model.set_tendon_command(0, TendonCommand::Pull(0.5)),
        Err(Error::InvalidParameter { param, .. }) if param == "cables[0].pull"
    ));
    let mut springs = build(CableSpec::new(line(3), 1e3, 1.0)).unwrap();
    assert!(matches!(
        springs.set_tendon_command(0, TendonCommand::Tension(1.0)),
        Err(Error::InvalidParameter { .. })
    ));
}

#[test]
fn an_infeasible_pull_is_reported_as_such() {
    // The tied end would have to pass through the clamped face.
    let (length, side) = (0.2, 0.05);
    let mut tendon = CableSpec::tendon(
        vec![[-0.05, 0.025, 0.025], [length, 0.025, 0.025]],
        TendonCommand::Pull(0.24),
    );
    tendon.anchor_first = true;
    let mut model = box_model(
        [length, side, side],
        [8, 2, 2],
        &[tendon],
        Formulation::Standard,
        1e5,
        0.3,
    );
    let loads = Loads::default();
    match model.solve(&loads, None, &options(1e-8)) {
        Err(Error::NotConverged { message, .. }) => {
            eprintln!("{message}");
            assert!(message.contains("infeasible"), "{message}");
            assert!(!message.contains("NaN"), "{message}");
        }
        Err(other) => panic!("unexpected error {other}"),
        Ok(s) => panic!("converged to pull {:?}", s.tendon_pulls),
    }
}

/// The beam with a pulled tendon on top (taut), a tensioned one below and a paid-out one (slack),
/// solved at `base + e delta`; objective `c . x`.
struct Setup {
    model: Model,
    material: Material,
}

const PULL: f64 = 0.02;
const TENSION: f64 = 15.0;

fn sensitivity_setup(formulation: Formulation) -> Setup {
    let mut side = tendon_at(LOWER, TendonCommand::Pull(-0.02));
    for p in &mut side.points {
        p[1] = 0.02;
    }
    let cables = [
        tendon_at(UPPER, TendonCommand::Pull(PULL)),
        tendon_at(LOWER, TendonCommand::Tension(TENSION)),
        side,
    ];
    let model = box_model([0.4, 0.1, 0.1], [4, 2, 2], &cables, formulation, 66e3, 0.45);
    let (mu, lambda) = lame_from_young(66e3, 0.45);
    let mut rng = Rng::new(4);
    let m = model.mesh().n_tets();
    let material = Material {
        mu: (0..m).map(|_| mu * (1.0 + 0.2 * rng.next())).collect(),
        lambda: (0..m).map(|_| lambda * (1.0 + 0.2 * rng.next())).collect(),
        density: vec![1080.0; m],
    };
    Setup { model, material }
}

fn objective(setup: &mut Setup, c: &[f64], delta: &ParamVector, e: f64) -> (f64, Solution) {
    let shift = |base: f64, name: &str, i: usize| base + e * delta.get(name).unwrap()[i];
    let material = Material {
        mu: (setup.material.mu.iter().enumerate())
            .map(|(i, &v)| shift(v, "mu", i))
            .collect(),
        lambda: (setup.material.lambda.iter().enumerate())
            .map(|(i, &v)| shift(v, "lambda", i))
            .collect(),
        density: setup.material.density.clone(),
    };
    let model = &mut setup.model;
    model.set_material(&material).unwrap();
    let commands = [
        TendonCommand::Pull(shift(PULL, "cable_pull", 0)),
        TendonCommand::Tension(shift(TENSION, "cable_tension", 1)),
        TendonCommand::Pull(shift(-0.02, "cable_pull", 2)),
    ];
    for (c, command) in commands.into_iter().enumerate() {
        model.set_tendon_command(c, command).unwrap();
    }
    let loads = Loads {
        gravity: GRAVITY,
        ..Default::default()
    };
    let s = model.solve(&loads, None, &options(1e-12)).unwrap();
    (s.positions.iter().zip(c).map(|(x, ci)| x * ci).sum(), s)
}

#[test]
fn sensitivities_with_tendons_match_central_differences() {
    for formulation in [Formulation::Standard, MIXED] {
        let mut setup = sensitivity_setup(formulation);
        let n = setup.model.mesh().n_nodes();
        let m = setup.model.mesh().n_tets();
        let mut rng = Rng::new(17);
        let c = rng.vec(3 * n, 1.0);
        let zero = setup.model.param_zeros();
        let along = |name: &str, values: Vec<f64>| {
            let mut delta = zero.clone();
            *delta.get_mut(name).unwrap() = values;
            delta
        };
        let (mu, _) = lame_from_young(66e3, 0.45);
        let directions = [
            ("mu", along("mu", rng.vec(m, 0.1 * mu))),
            ("taut pull", along("cable_pull", vec![0.002, 0.0, 0.0])),
            ("tension", along("cable_tension", vec![0.0, 1.5, 0.0])),
            ("slack pull", along("cable_pull", vec![0.0, 0.0, 0.002])),
        ];
        for (name, delta) in directions {
            let (_, base) = objective(&mut setup, &c, &delta, 0.0);
            assert!(base.tendon_tensions[0].unwrap() > 0.0);
            assert_eq!(base.tendon_tensions[2], Some(0.0));
            let gradient = setup.model.adjoint(&c).unwrap();
            let adjoint: f64 = (gradient.blocks.iter())
                .map(|(block, values)| {
                    let d = delta.get(block).unwrap();
                    values.iter().zip(d).map(|(a, b)| a * b).sum::<f64>()
                })
                .sum();
            let (dx, _, dtension) = setup.model.forward_with_tensions(&delta).unwrap();
            let forward: f64 = dx.iter().zip(&c).map(|(a, b)| a * b).sum();
            let label = format!("{formulation:?} {name}");
            if name == "slack pull" {
                assert!(adjoint.abs() <= 1e-12 && forward.abs() <= 1e-12, "{label}");
                continue;
            }
            assert!(adjoint.abs() > 1e-8, "{label}: vacuous");
            check_directional(
                &format!("{label} adjoint"),
                &[0.0],
                &[1.0],
                1e-3,
                |e| objective(&mut setup, &c, &delta, e[0]).0,
                adjoint,
                1e-5,
            );
            assert!(
                (forward - adjoint).abs() <= 1e-8 * adjoint.abs(),
                "{label}: forward {forward} vs adjoint {adjoint}"
            );
            // The tension's sensitivity against a central difference too.
            let tension = |e: f64, setup: &mut Setup| {
                objective(setup, &c, &delta, e).1.tendon_tensions[0].unwrap()
            };
            let h = 1e-3;
            let fd = (tension(h, &mut setup) - tension(-h, &mut setup)) / (2.0 * h);
            let analytic = dtension[0].unwrap();
            assert!(
                (fd - analytic).abs() <= 1e-5 * fd.abs().max(1e-6),
                "{label}: dT/de {analytic} vs central difference {fd}"
            );
        }
    }
}
