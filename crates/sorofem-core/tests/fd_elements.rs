//! Finite-difference checks of the element kernels: elastic (standard and mixed, both volumetric
//! measures, exact Hessian including the pressure coupling G and geometric stiffness K_geo(p)),
//! the pressure compliance, gravity, and of the assembled global gradient and Hessian.
mod common;

use common::{check_gradient, check_jacobian, check_jacobian_blocks, Rng};
use sorofem_core::assembly::Assembler;
use sorofem_core::energy::elastic::{PressureCompliance, PressureIterates};
use sorofem_core::energy::{
    ElasticTerm, Formulation, GravityTerm, HessianMode, LumpedMass, ParamTerm, PressureMass, Term,
};
use sorofem_core::material::Volumetric;
use sorofem_core::mesh::TetMesh;
use std::sync::Arc;

fn small_mesh() -> Arc<TetMesh> {
    Arc::new(TetMesh::box_mesh([0.2, 0.1, 0.1], [2, 1, 1], [0.0; 3]).unwrap())
}

fn elastic(mesh: &Arc<TetMesh>, volumetric: Volumetric, formulation: Formulation) -> ElasticTerm {
    let m = mesh.n_tets();
    let mu: Vec<f64> = (0..m).map(|e| 2e4 * (1.0 + 0.1 * e as f64)).collect();
    let lambda: Vec<f64> = (0..m).map(|e| 3e5 * (1.0 + 0.05 * e as f64)).collect();
    ElasticTerm::neo_hookean(mesh.clone(), &mu, &lambda, volumetric, formulation)
}

/// Checks one term's element gradients and Hessians at perturbed states. DOFs from `extra_from`
/// on (pressures) form their own block of the Hessian check.
fn check_term_elements(name: &str, term: &dyn Term, z_full: &[f64], extra_from: usize) {
    let s = term.stencil_size();
    let mut dofs = vec![0; s];
    for e in 0..term.n_elements() {
        term.element_dofs(e, &mut dofs);
        let z: Vec<f64> = dofs.iter().map(|&d| z_full[d]).collect();
        let mut grad = vec![0.0; s];
        let mut hess = vec![0.0; s * s];
        term.element(e, &z, Some(&mut grad), Some(&mut hess), HessianMode::Exact);
        let energy = |x: &[f64]| term.element(e, x, None, None, HessianMode::Exact);
        check_gradient(
            &format!("{name} element {e} gradient"),
            &z,
            1e-7,
            energy,
            &grad,
            1e-6,
            1e-12,
        );
        let gradient = |x: &[f64]| {
            let mut g = vec![0.0; s];
            term.element(e, x, Some(&mut g), None, HessianMode::Exact);
            g
        };
        // The step is larger than the gradient check's: rounding in the large displacement rows
        // would otherwise blur the small pressure coupling (linear in the pressures).
        let block: Vec<usize> = dofs.iter().map(|&d| usize::from(d >= extra_from)).collect();
        check_jacobian_blocks(
            &format!("{name} element {e} Hessian"),
            &z,
            1e-6,
            gradient,
            &hess,
            &block,
            &block,
            1e-6,
            1e-15,
        );
        for a in 0..s {
            for b in 0..s {
                assert!(
                    (hess[a * s + b] - hess[b * s + a]).abs()
                        <= 1e-9 * hess[a * s + a].abs().max(1.0)
                );
            }
        }
    }
}

fn deformed_state(mesh: &TetMesh, n_extra: usize, seed: u64) -> Vec<f64> {
    let mut rng = Rng::new(seed);
    let rest = mesh.rest_flat();
    let mut z = vec![0.0; rest.len()];
    for (i, v) in z.iter_mut().enumerate() {
        // A smooth stretch plus noise keeps every element well inside J > 0.
        *v = 0.02 * rng.next() + if i % 3 == 0 { 0.1 * rest[i] } else { 0.0 };
    }
    z.extend(rng.vec(n_extra, 3e3));
    z
}

#[test]
fn standard_elastic_elements() {
    let mesh = small_mesh();
    for volumetric in [Volumetric::Log, Volumetric::Linear] {
        let mut term = elastic(&mesh, volumetric, Formulation::Standard);
        for closed_forms in [true, false] {
            term.closed_forms = closed_forms;
            let name = format!("standard (closed forms: {closed_forms})");
            check_term_elements(
                &name,
                &term,
                &deformed_state(&mesh, 0, 1),
                3 * mesh.n_nodes(),
            );
        }
    }
}

#[test]
fn mixed_elastic_elements_with_pressure_coupling() {
    let mesh = small_mesh();
    let n = mesh.n_nodes();
    for volumetric in [Volumetric::Log, Volumetric::Linear] {
        for mass in [PressureMass::Consistent, PressureMass::Lumped] {
            let mut term = elastic(
                &mesh,
                volumetric,
                Formulation::Mixed {
                    pressure_offset: 3 * n,
                    mass,
                },
            );
            for closed_forms in [true, false] {
                term.closed_forms = closed_forms;
                let name = format!("mixed (closed forms: {closed_forms})");
                check_term_elements(&name, &term, &deformed_state(&mesh, n, 2), 3 * n);
            }
            let compliance = PressureCompliance {
                elastic: &term,
                mass,
            };
            check_term_elements("compliance", &compliance, &Rng::new(3).vec(n, 1e3), 0);
        }
    }
}

/// `d(grad_e)/d(theta)` of every element against central differences of its gradient with the
/// element's material parameters perturbed, both formulations (the mixed one's `lambda` acts on
/// the pressure rows only).
#[test]
fn material_parameter_derivatives_of_element_gradients() {
    let mesh = small_mesh();
    let n = mesh.n_nodes();
    for (formulation, extra) in [
        (Formulation::Standard, 0),
        (
            Formulation::Mixed {
                pressure_offset: 3 * n,
                mass: PressureMass::Consistent,
            },
            n,
        ),
    ] {
        let term = elastic(&mesh, Volumetric::Log, formulation);
        let z_full = deformed_state(&mesh, extra, 5);
        let (s, k) = (term.stencil_size(), term.element_param_count());
        let mut dofs = vec![0; s];
        for e in 0..term.n_elements() {
            term.element_dofs(e, &mut dofs);
            let z: Vec<f64> = dofs.iter().map(|&d| z_full[d]).collect();
            let mut d_grad = vec![0.0; k * s];
            term.element_param_gradient(e, &z, &mut d_grad);
            // check_jacobian wants d grad_i / d theta_j at [i k + j].
            let jacobian: Vec<f64> = (0..s * k).map(|ij| d_grad[(ij % k) * s + ij / k]).collect();
            let theta = term.params()[e * k..(e + 1) * k].to_vec();
            let gradient_at = |x: &[f64]| {
                let mut params = term.params().to_vec();
                params[e * k..(e + 1) * k].copy_from_slice(x);
                let mut shifted = elastic(&mesh, Volumetric::Log, formulation);
                shifted.set_material(term.material(), params);
                let mut g = vec![0.0; s];
                shifted.element(e, &z, Some(&mut g), None, HessianMode::Exact);
                g
            };
            check_jacobian(
                &format!("{formulation:?} element {e} parameter derivatives"),
                &theta,
                1e-6,
                gradient_at,
                &jacobian,
                1e-6,
                1e-12,
            );
        }
    }
}

#[test]
fn gravity_element_is_the_lumped_weight() {
    let mesh = small_mesh();
    let mass = LumpedMass {
        mesh: mesh.clone(),
        density: vec![1000.0; mesh.n_tets()],
        points: vec![],
    };
    let term = GravityTerm {
        mass: &mass,
        gravity: [0.0, -9.81, 1.0],
    };
    check_term_elements(
        "gravity",
        &term,
        &deformed_state(&mesh, 0, 4),
        3 * mesh.n_nodes(),
    );
    let fixed = vec![false; 3 * mesh.n_nodes()];
    let assembler = Assembler::new(&fixed, &[]);
    let load = assembler.load_vector(&[&term]);
    let total_y: f64 = load.iter().skip(1).step_by(3).sum();
    assert!((total_y - (-9.81 * 1000.0 * 0.2 * 0.1 * 0.1)).abs() < 1e-12);
}

/// Both formulations of the elastic term on `mesh`, with the DOFs of the x = 0 face fixed:
/// `(formulation, term, fixed, number of extra unknowns)`.
fn clamped_at_x0(mesh: &Arc<TetMesh>) -> Vec<(Formulation, ElasticTerm, Vec<bool>, usize)> {
    let n = mesh.n_nodes();
    [
        Formulation::Standard,
        Formulation::Mixed {
            pressure_offset: 3 * n,
            mass: PressureMass::Consistent,
        },
    ]
    .into_iter()
    .map(|formulation| {
        let extra = if formulation == Formulation::Standard {
            0
        } else {
            n
        };
        let mut fixed = vec![false; 3 * n + extra];
        for node in mesh.nodes_in_box([-1e-9, -1.0, -1.0], [1e-9, 1.0, 1.0]) {
            fixed[3 * node..3 * node + 3].fill(true);
        }
        let term = elastic(mesh, Volumetric::Log, formulation);
        (formulation, term, fixed, extra)
    })
    .collect()
}

#[test]
fn assembled_gradient_and_hessian_with_fixed_dofs() {
    let mesh = small_mesh();
    for (_, term, fixed, extra) in clamped_at_x0(&mesh) {
        let assembler = Assembler::new(&fixed, &[&term]);
        let z0 = deformed_state(&mesh, extra, 5);
        let eval = assembler.evaluate(&[&term], &z0, true, Some(HessianMode::Exact));
        let free = assembler.full_of_free().to_vec();
        let with_free = |x: &[f64]| {
            let mut z = z0.clone();
            for (&d, v) in free.iter().zip(x) {
                z[d] = *v;
            }
            z
        };
        let x0: Vec<f64> = free.iter().map(|&d| z0[d]).collect();
        check_gradient(
            "assembled gradient",
            &x0,
            1e-7,
            |x| assembler.energy(&[&term], &with_free(x)),
            &eval.gradient,
            1e-6,
            1e-12,
        );
        let nf = free.len();
        let mut dense = vec![0.0; nf * nf];
        let p = assembler.pattern();
        for c in 0..nf {
            for k in p.col_ptr[c]..p.col_ptr[c + 1] {
                let r = p.row_idx[k];
                dense[r * nf + c] = eval.hessian[k];
                dense[c * nf + r] = eval.hessian[k];
            }
        }
        let block: Vec<usize> = free
            .iter()
            .map(|&d| usize::from(d >= 3 * mesh.n_nodes()))
            .collect();
        // A larger step than the element checks: the gradient is linear in the pressures, and
        // rounding in its large displacement rows would blur the small coupling block.
        check_jacobian_blocks(
            "assembled Hessian",
            &x0,
            1e-6,
            |x| {
                assembler
                    .evaluate(&[&term], &with_free(x), true, None)
                    .gradient
            },
            &dense,
            &block,
            &block,
            1e-6,
            1e-15,
        );
    }
}

/// Every stored entry of the parallel, chunk-coloured assembly against a plain serial dense sum of
/// all element matrices, on a mesh large enough for many chunks, with a cable whose consecutive
/// points share nodes (local pairs that land twice on one diagonal entry).
#[test]
fn parallel_assembly_matches_a_serial_dense_sum() {
    use sorofem_core::energy::{Cable, CableTerm, PointMap};
    let mesh = Arc::new(TetMesh::box_mesh([1.0, 0.2, 0.2], [16, 3, 3], [0.0; 3]).unwrap());
    let n = mesh.n_nodes();
    let node_near = |p: [f64; 3]| {
        (0..n)
            .min_by(|&a, &b| {
                let d = |i: usize| {
                    (0..3)
                        .map(|k| (mesh.rest()[i][k] - p[k]).powi(2))
                        .sum::<f64>()
                };
                d(a).total_cmp(&d(b))
            })
            .unwrap()
    };
    let points: Vec<PointMap> = (0..9)
        .map(|k| {
            let x = 0.1 * k as f64 + 0.05;
            let (a, b) = (node_near([x, 0.1, 0.1]), node_near([x + 0.07, 0.1, 0.1]));
            PointMap {
                offset: [x + 0.03, 0.1, 0.1],
                dof_blocks: vec![3 * a, 3 * b],
                weights: vec![0.6, 0.4],
            }
        })
        .collect();
    let cable = CableTerm::new(vec![Cable {
        rest_lengths: vec![0.08; points.len() - 1],
        points,
        stiffness: 1e3,
        actuation: 1.0,
        transition: 0.05,
        damping: 0.0,
    }]);
    for (formulation, term, fixed, extra) in clamped_at_x0(&mesh) {
        let terms: [&dyn Term; 2] = [&term, &cable];
        let assembler = Assembler::new(&fixed, &terms);
        // A stretch plus noise far below the cell size (0.0625 m): no element inverts.
        let mut rng = Rng::new(11);
        let rest = mesh.rest_flat();
        let mut z: Vec<f64> = (0..3 * n)
            .map(|i| 0.002 * rng.next() + if i % 3 == 0 { 0.1 * rest[i] } else { 0.0 })
            .collect();
        z.extend(rng.vec(extra, 3e3));
        for mode in [HessianMode::Exact, HessianMode::Projected] {
            let eval = assembler.evaluate(&terms, &z, true, Some(mode));
            let again = assembler.evaluate(&terms, &z, true, Some(mode));
            assert_eq!(eval.hessian, again.hessian, "assembly is not deterministic");
            let nf = assembler.n_free();
            let mut dense = vec![0.0; nf * nf];
            let mut gradient = vec![0.0; nf];
            let mut energy = 0.0;
            for t in terms {
                let s = t.stencil_size();
                let mut dofs = vec![0; s];
                let (mut g, mut h) = (vec![0.0; s], vec![0.0; s * s]);
                for e in 0..t.n_elements() {
                    t.element_dofs(e, &mut dofs);
                    let local: Vec<f64> = dofs.iter().map(|&d| z[d]).collect();
                    energy += t.element(e, &local, Some(&mut g), Some(&mut h), mode);
                    let free: Vec<Option<usize>> =
                        dofs.iter().map(|&d| assembler.free_of_full(d)).collect();
                    for a in 0..s {
                        let Some(r) = free[a] else { continue };
                        gradient[r] += g[a];
                        for b in 0..s {
                            if let Some(c) = free[b] {
                                dense[r * nf + c] += h[a * s + b];
                            }
                        }
                    }
                }
            }
            let scale = dense.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            let p = assembler.pattern();
            let mut stored = vec![false; nf * nf];
            for c in 0..nf {
                for k in p.col_ptr[c]..p.col_ptr[c + 1] {
                    let r = p.row_idx[k];
                    stored[r * nf + c] = true;
                    assert!(
                        (eval.hessian[k] - dense[r * nf + c]).abs() <= 1e-12 * scale,
                        "{formulation:?} {mode:?}: H[{r},{c}] = {} vs {}",
                        eval.hessian[k],
                        dense[r * nf + c]
                    );
                }
            }
            for r in 0..nf {
                for c in 0..=r {
                    assert!(
                        stored[r * nf + c] || dense[r * nf + c] == 0.0,
                        "({r},{c}) missing"
                    );
                }
            }
            let gscale = gradient.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            for (a, b) in eval.gradient.iter().zip(&gradient) {
                assert!((a - b).abs() <= 1e-12 * gscale);
            }
            assert!(energy.is_finite());
            assert!((eval.energy - energy).abs() <= 1e-12 * energy.abs());
        }
    }
}

/// The element pressure iterates of a Newton solve: where they are consistent (`lambda c(J)`),
/// the Hessian is the exact one; one full step along `dz` moves them by the derivative of
/// `lambda c(J(z + x dz))` at x = 0 (checked by central differences).
#[test]
fn pressure_iterates_are_consistent_and_linearise_the_volumetric_constraint() {
    let mesh = small_mesh();
    let n = mesh.n_nodes();
    let mut term = elastic(&mesh, Volumetric::Log, Formulation::Standard);
    let z = deformed_state(&mesh, 0, 21);
    let dz = deformed_state(&mesh, 0, 22);
    let fixed = vec![false; 3 * n];
    let assembler = Assembler::new(&fixed, &[&term]);
    let exact = assembler.evaluate(&[&term], &z, false, Some(HessianMode::Exact));
    term.pressure_iterates = Some(PressureIterates::new(term.pressures_at(&z)));
    let consistent = assembler.evaluate(&[&term], &z, false, Some(HessianMode::Exact));
    let scale = exact.hessian.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    for (a, b) in exact.hessian.iter().zip(&consistent.hessian) {
        assert!((a - b).abs() <= 1e-12 * scale, "{a} vs {b}");
    }
    let start = term.pressure_iterates.as_ref().unwrap().values.clone();
    let linearised = term.linearised_pressures(&z);
    // The Hessian pass recorded the same linearisation (Newton solves use that one).
    let recorded = &term.pressure_iterates.as_ref().unwrap().recorded;
    for e in 0..mesh.n_tets() {
        let (a, b) = (recorded.get(e), linearised.get(e));
        let close = |x: f64, y: f64| (x - y).abs() <= 1e-12 * y.abs().max(1.0);
        assert!(
            close(a.value, b.value),
            "tet {e}: {} vs {}",
            a.value,
            b.value
        );
        for (x, y) in a.gradient.iter().zip(&b.gradient) {
            assert!(close(*x, *y), "tet {e}: {x} vs {y}");
        }
    }
    term.advance_pressures(&linearised, &dz, 1.0);
    let moved: Vec<f64> = term
        .pressure_iterates
        .as_ref()
        .unwrap()
        .values
        .iter()
        .zip(&start)
        .map(|(p, p0)| p - p0)
        .collect();
    let along = |x: &[f64]| {
        let shifted: Vec<f64> = z.iter().zip(&dz).map(|(a, b)| a + x[0] * b).collect();
        term.pressures_at(&shifted)
    };
    check_jacobian("pressure update", &[0.0], 1e-6, along, &moved, 1e-6, 1e-9);
    // Half a step moves them half the way.
    term.pressure_iterates = Some(PressureIterates::new(start.clone()));
    term.advance_pressures(&linearised, &dz, 0.5);
    for ((p, p0), m) in term
        .pressure_iterates
        .as_ref()
        .unwrap()
        .values
        .iter()
        .zip(&start)
        .zip(&moved)
    {
        assert!((p - p0 - 0.5 * m).abs() <= 1e-12 * m.abs().max(1.0));
    }
}
