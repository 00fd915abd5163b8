//! Issue 20, item 12: a solve asked to stop ([`NewtonOptions::interrupt`]) returns
//! `Error::Interrupted` with its report, and leaves the model as a failed solve does: the next
//! solve gives the uninterrupted answer. (The stop at the next Newton iteration is tested in
//! `newton.rs`; the Ctrl-C path end to end in tests/test_reliability_signals.py.)
mod common;

use common::cantilever;
use sorofem_core::newton::Interrupt;
use sorofem_core::{Damping, Error, Formulation, Loads, PressureMass, SolveOptions};

fn requested() -> SolveOptions {
    let interrupt = Interrupt::new();
    interrupt.request();
    SolveOptions {
        load_steps: 3,
        interrupt,
        ..Default::default()
    }
}

#[test]
fn an_interrupted_static_solve_reports_it_and_leaves_the_model_as_it_was() {
    for formulation in [
        Formulation::Standard,
        Formulation::Mixed {
            mass: PressureMass::Consistent,
        },
    ] {
        let new_model = || {
            cantilever(
                [0.1, 0.02, 0.02],
                [8, 2, 2],
                66e3,
                0.45,
                1080.0,
                formulation,
            )
        };
        let loads = Loads {
            gravity: [0.0, 0.0, -9.81],
            ..Default::default()
        };
        let mut model = new_model();
        match model.solve(&loads, None, &requested()) {
            Err(Error::Interrupted { report }) => {
                assert_eq!(report.iterations, 0);
                assert!(!report.converged);
                assert!(report
                    .message
                    .starts_with("interrupted after 0 Newton iterations"));
            }
            other => panic!("expected Interrupted, got {other:?}"),
        }
        let after = model.solve(&loads, None, &SolveOptions::default()).unwrap();
        let fresh = new_model()
            .solve(&loads, None, &SolveOptions::default())
            .unwrap();
        assert_eq!(after.report.iterations, fresh.report.iterations);
        let worst = (after.positions.iter().zip(&fresh.positions))
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(worst < 1e-12, "{worst} m");
    }
}

#[test]
fn an_interrupted_simulation_reports_it() {
    let mut model = cantilever(
        [0.1, 0.02, 0.02],
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
    let outcome = model.simulate(
        &loads,
        1e-3,
        10,
        &vec![vec![]; 10],
        Damping::default(),
        None,
        None,
        &requested(),
        1,
    );
    assert!(
        matches!(outcome, Err(Error::Interrupted { .. })),
        "{outcome:?}"
    );
}
