//! Static closed forms through the public `Model`: the von Mises stress of homogeneous
//! deformations and the weight of a body made of two materials.
mod common;

use sorofem_core::material::Volumetric;
use sorofem_core::{Formulation, Loads, Material, Model, PressureMass, SolveOptions, TetMesh};
use std::sync::Arc;

const MU: f64 = 22.76e3;
const LAMBDA: f64 = 204.8e3;

/// A unit cube of 2 x 2 x 2 cells with every boundary node at `F X` and the interior free.
fn homogeneous(f: [[f64; 3]; 3], formulation: Formulation) -> (Model, Vec<f64>) {
    let mesh = Arc::new(TetMesh::box_mesh([1.0; 3], [2, 2, 2], [0.0; 3]).unwrap());
    let boundary =
        mesh.nodes_where(|p| p.iter().any(|&v| v.abs() < 1e-9 || (v - 1.0).abs() < 1e-9));
    let map = |p: &[f64; 3]| -> [f64; 3] {
        [0, 1, 2].map(|i| (0..3).map(|j| f[i][j] * p[j]).sum::<f64>())
    };
    let prescribed = boundary
        .iter()
        .map(|&i| {
            let (x, p) = (map(&mesh.rest()[i]), mesh.rest()[i]);
            [x[0] - p[0], x[1] - p[1], x[2] - p[2]]
        })
        .collect();
    let fixed: Vec<i64> = boundary.iter().map(|&i| i as i64).collect();
    let mut model = Model::try_new(mesh.clone(), &fixed, formulation, Volumetric::Log).unwrap();
    let m = mesh.n_tets();
    model
        .set_material(&Material {
            mu: vec![MU; m],
            lambda: vec![LAMBDA; m],
            density: vec![0.0; m],
        })
        .unwrap();
    let loads = Loads {
        prescribed,
        ..Default::default()
    };
    let options = SolveOptions {
        tolerance: 1e-12,
        ..Default::default()
    };
    let solution = model.solve(&loads, None, &options).unwrap();
    for i in 0..mesh.n_nodes() {
        let x = map(&mesh.rest()[i]);
        for (position, expected) in solution.positions[3 * i..3 * i + 3].iter().zip(x) {
            assert!((position - expected).abs() < 1e-12);
        }
    }
    (model, solution.positions)
}

/// Von Mises of `sigma = (mu (B - I) + lambda c c' J I) / J`: its deviatoric part is
/// `mu dev(B) / J`, so 0 for a dilation, `mu |s^2 - 1| / s` for the uniaxial strain
/// `diag(s, 1, 1)` and `mu gamma sqrt(3 + gamma^2)` for the simple shear `I + gamma e_x e_y^T`.
#[test]
fn von_mises_of_homogeneous_deformations() {
    let (s, gamma) = (1.2f64, 0.3f64);
    let cases = [
        ([[1.1, 0.0, 0.0], [0.0, 1.1, 0.0], [0.0, 0.0, 1.1]], 0.0),
        (
            [[s, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            MU * (s * s - 1.0) / s,
        ),
        (
            [[1.0, gamma, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            MU * gamma * (3.0 + gamma * gamma).sqrt(),
        ),
    ];
    for formulation in [
        Formulation::Standard,
        Formulation::Mixed {
            mass: PressureMass::Consistent,
        },
    ] {
        for (f, expected) in cases {
            let (model, positions) = homogeneous(f, formulation);
            let (_, von_mises) = model.element_fields(&positions).unwrap();
            for vm in von_mises {
                assert!(
                    (vm - expected).abs() < 1e-9 * MU,
                    "{formulation:?} {f:?}: {vm} vs {expected}"
                );
            }
        }
    }
}

/// A 0.4 m bar, 1000 kg/m^3 for x < 0.2 m and 3000 beyond: the supports carry
/// `g (1000 + 3000) V / 2`, V / 2 per half from the box size alone.
#[test]
fn reactions_carry_the_weight_of_a_two_density_bar() {
    let mesh = Arc::new(TetMesh::box_mesh([0.4, 0.1, 0.1], [8, 2, 2], [0.0; 3]).unwrap());
    let density: Vec<f64> = mesh
        .tets()
        .iter()
        .map(|t| {
            let x = t.iter().map(|&i| mesh.rest()[i][0]).sum::<f64>() / 4.0;
            if x < 0.2 {
                1000.0
            } else {
                3000.0
            }
        })
        .collect();
    let m = mesh.n_tets();
    let mut model = common::clamped_at_x0(mesh, 3e5, 0.3, 0.0, Formulation::Standard);
    let (mu, lambda) = sorofem_core::material::neo_hookean::lame_from_young(3e5, 0.3);
    model
        .set_material(&Material {
            mu: vec![mu; m],
            lambda: vec![lambda; m],
            density,
        })
        .unwrap();
    let g = -9.81;
    let solution = common::solve_gravity(&mut model, [0.0, 0.0, g]);
    let weight = g * (1000.0 + 3000.0) * 0.004 / 2.0;
    let total: [f64; 3] = [0, 1, 2].map(|k| solution.reactions.iter().map(|r| r[k]).sum::<f64>());
    assert!(total[0].abs() < 1e-10 * weight.abs() && total[1].abs() < 1e-10 * weight.abs());
    assert!(
        (total[2] + weight).abs() < 1e-10 * weight.abs(),
        "{} vs {}",
        total[2],
        -weight
    );
}

/// Point forces on the free end of a clamped bar: the supports return them, force and moment
/// about the origin at the deformed positions (1e-10), and the term's gradient is the
/// derivative of its energy `-f . u`.
#[test]
fn reactions_return_nodal_forces_and_their_moment() {
    use sorofem_core::energy::{HessianMode, NodalForceTerm, Term};
    let mesh = Arc::new(TetMesh::box_mesh([0.4, 0.1, 0.1], [8, 2, 2], [0.0; 3]).unwrap());
    let tip = mesh.nodes_in_box([0.4 - 1e-9, -1.0, -1.0], [0.4 + 1e-9, 1.0, 1.0]);
    let nodal_forces: Vec<(usize, [f64; 3])> = tip
        .iter()
        .enumerate()
        .map(|(k, &i)| (i, [-0.3, 0.2 + 0.01 * k as f64, -0.5]))
        .collect();
    let mut model = common::clamped_at_x0(mesh.clone(), 3e5, 0.3, 0.0, Formulation::Standard);
    let loads = Loads {
        nodal_forces: nodal_forces.clone(),
        ..Default::default()
    };
    let options = SolveOptions {
        tolerance: 1e-12,
        ..Default::default()
    };
    let solution = model.solve(&loads, None, &options).unwrap();
    let x = |i: usize| [0, 1, 2].map(|k| solution.positions[3 * i + k]);
    let cross = |a: [f64; 3], b: [f64; 3]| {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    };
    let (mut force, mut moment) = ([0.0; 3], [0.0; 3]);
    for (&i, r) in model.fixed_nodes().iter().zip(&solution.reactions) {
        let m = cross(x(i), *r);
        for k in 0..3 {
            force[k] += r[k];
            moment[k] += m[k];
        }
    }
    for &(i, f) in &nodal_forces {
        let m = cross(x(i), f);
        for k in 0..3 {
            force[k] += f[k];
            moment[k] += m[k];
        }
    }
    assert!(
        force.iter().chain(&moment).all(|v| v.abs() < 1e-10),
        "unbalanced: force {force:?}, moment {moment:?}"
    );
    let term = NodalForceTerm {
        nodes: nodal_forces.iter().map(|&(i, _)| i).collect(),
        forces: nodal_forces.iter().map(|&(_, f)| f).collect(),
    };
    let mut dofs = vec![0; term.stencil_size()];
    for e in 0..term.n_elements() {
        term.element_dofs(e, &mut dofs);
        assert_eq!(
            dofs,
            (3 * term.nodes[e]..3 * term.nodes[e] + 3).collect::<Vec<_>>()
        );
        let z = [0.01, -0.02, 0.03];
        let mut grad = vec![0.0; 3];
        term.element(e, &z, Some(&mut grad), None, HessianMode::Exact);
        let energy = |u: &[f64]| term.element(e, u, None, None, HessianMode::Exact);
        common::check_gradient("nodal force", &z, 1e-6, energy, &grad, 1e-9, 1e-15);
        let f = term.forces[e];
        assert!((energy(&z) + f[0] * z[0] + f[1] * z[1] + f[2] * z[2]).abs() < 1e-15);
    }
}
