//! Rayleigh damping against the closed-form implicit Euler recurrence of a one-DOF oscillator.
//!
//! One tetrahedron, three nodes clamped, the fourth at the origin moved along the diagonal
//! `d = (1, 1, 1) / sqrt 3`: the tet is symmetric under permutations of the axes, so the node
//! stays on the diagonal. For the corner tet of edge `L` (`V = L^3 / 6`, `grad N_0 = -(1, 1, 1) / L`)
//! the displacement `q d` is a uniaxial strain `-sqrt(3) q / L` along `d`: stiffness
//! `k = 3 V (lambda + 2 mu) / L^2` at small strain, lumped mass `m = rho V / 4`. Implicit Euler with
//! Rayleigh damping `c = alpha_M m + beta_K k` gives `v' = (m v - h k q) / (m + h c + h^2 k)`,
//! `q' = q + h v'`. At an amplitude of 1e-9 L the material is linear to about 1e-9.
use sorofem_core::material::Volumetric;
use sorofem_core::{
    Damping, Formulation, Loads, Material, Model, Orientation, SolveOptions, TetMesh,
};
use std::sync::Arc;

const EDGE: f64 = 0.1;
const MU: f64 = 22.76e3;
const LAMBDA: f64 = 204.8e3;
const DENSITY: f64 = 1080.0;
const DT: f64 = 1e-3;
const STEPS: usize = 30;

fn corner_tet() -> Model {
    let points = vec![
        [0.0, 0.0, 0.0],
        [EDGE, 0.0, 0.0],
        [0.0, EDGE, 0.0],
        [0.0, 0.0, EDGE],
    ];
    let (mesh, _) = TetMesh::try_new(points, &[[0, 1, 2, 3]], Orientation::Reject).unwrap();
    let mut model = Model::try_new(
        Arc::new(mesh),
        &[1, 2, 3],
        Formulation::Standard,
        Volumetric::Log,
    )
    .unwrap();
    model
        .set_material(&Material {
            mu: vec![MU],
            lambda: vec![LAMBDA],
            density: vec![DENSITY],
        })
        .unwrap();
    model
}

/// `(q_n)` of the recurrence from `(q0, v0)`.
fn implicit_euler(q0: f64, v0: f64, k: f64, m: f64, c: f64) -> Vec<f64> {
    let (mut q, mut v) = (vec![q0], v0);
    for _ in 0..STEPS {
        let last = *q.last().unwrap();
        v = (m * v - DT * k * last) / (m + DT * c + DT * DT * k);
        q.push(last + DT * v);
    }
    q
}

#[test]
fn rayleigh_damping_follows_the_one_dof_recurrence() {
    let volume = EDGE.powi(3) / 6.0;
    let k = 3.0 * volume * (LAMBDA + 2.0 * MU) / (EDGE * EDGE);
    let m = DENSITY * volume / 4.0;
    let d = 1.0 / 3f64.sqrt();
    let amplitude = 1e-9 * EDGE;
    for (alpha_m, beta_k) in [(100.0, 0.0), (0.0, 1e-3), (100.0, 1e-3)] {
        let mut model = corner_tet();
        let mut initial = vec![
            0.0, 0.0, 0.0, EDGE, 0.0, 0.0, 0.0, EDGE, 0.0, 0.0, 0.0, EDGE,
        ];
        initial[..3].fill(amplitude * d);
        let trajectory = model
            .simulate(
                &Loads::default(),
                DT,
                STEPS,
                &vec![vec![]; STEPS],
                Damping {
                    mass: alpha_m,
                    stiffness: beta_k,
                },
                Some(&initial),
                None,
                &SolveOptions {
                    tolerance: 1e-12,
                    ..Default::default()
                },
                1,
            )
            .unwrap();
        let expected = implicit_euler(amplitude, 0.0, k, m, alpha_m * m + beta_k * k);
        let undamped = implicit_euler(amplitude, 0.0, k, m, 0.0);
        let mut damping_effect: f64 = 0.0;
        for (frame, (q, q_free)) in trajectory
            .positions
            .iter()
            .zip(expected.iter().zip(&undamped))
        {
            // The node sits at the origin: its positions are its displacements.
            for x in &frame[..3] {
                assert!(
                    (x - q * d).abs() < 1e-6 * amplitude,
                    "alpha_M {alpha_m}, beta_K {beta_k}: {x} vs {}",
                    q * d
                );
            }
            damping_effect = damping_effect.max((q - q_free).abs());
        }
        assert!(damping_effect > 1e-2 * amplitude);
    }
}
