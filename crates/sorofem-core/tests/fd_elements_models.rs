//! Finite-difference checks of the elastic element kernels for the decoupled models
//! (Mooney-Rivlin, Yeoh, Ogden) on the general path: gradient and exact Hessian, standard and
//! mixed (pressure coupling included), and the derivatives of the element gradient with respect
//! to every material parameter. The models' own 3x3 laws are checked in `fd_material_models.rs`.
mod common;

use common::{check_jacobian, Rng};
use sorofem_core::energy::{ElasticTerm, Formulation, HessianMode, ParamTerm, PressureMass, Term};
use sorofem_core::material::MaterialModel;
use sorofem_core::mesh::TetMesh;
use std::sync::Arc;

fn small_mesh() -> Arc<TetMesh> {
    Arc::new(TetMesh::box_mesh([0.2, 0.1, 0.1], [2, 1, 1], [0.0; 3]).unwrap())
}

/// Each decoupled model with silicone-like parameters (Pa, 1/Pa), varied a little per tet.
fn models() -> Vec<(MaterialModel, Vec<f64>)> {
    vec![
        (MaterialModel::MooneyRivlin, vec![8e3, 2.5e3, 4e-6]),
        (
            MaterialModel::Yeoh,
            vec![1.2e4, -400.0, 30.0, 3e-6, 2e-5, 0.0],
        ),
        (
            MaterialModel::ogden(3).unwrap(),
            vec![1.9e3, -3.8, 2.2e4, 0.66, 3.6e3, 4.2, 3e-6],
        ),
        (MaterialModel::ogden(1).unwrap(), vec![2.4e4, 2.0, 3e-6]),
    ]
}

fn term(
    mesh: &Arc<TetMesh>,
    model: MaterialModel,
    base: &[f64],
    formulation: Formulation,
) -> ElasticTerm {
    let params = (0..mesh.n_tets())
        .flat_map(|e| base.iter().map(move |v| v * (1.0 + 0.03 * e as f64)))
        .collect();
    ElasticTerm::new(mesh.clone(), model, params, formulation)
}

fn deformed_state(mesh: &TetMesh, n_extra: usize, seed: u64) -> Vec<f64> {
    let mut rng = Rng::new(seed);
    let rest = mesh.rest_flat();
    let mut z = vec![0.0; rest.len()];
    for (i, v) in z.iter_mut().enumerate() {
        *v = 0.02 * rng.next() + if i % 3 == 0 { 0.15 * rest[i] } else { 0.0 };
    }
    z.extend(rng.vec(n_extra, 3e3));
    z
}

fn formulations(n: usize) -> [(Formulation, usize); 2] {
    [
        (Formulation::Standard, 0),
        (
            Formulation::Mixed {
                pressure_offset: 3 * n,
                mass: PressureMass::Consistent,
            },
            n,
        ),
    ]
}

#[test]
fn decoupled_element_gradients_and_hessians() {
    let mesh = small_mesh();
    for (model, base) in models() {
        for (formulation, extra) in formulations(mesh.n_nodes()) {
            let term = term(&mesh, model, &base, formulation);
            let z_full = deformed_state(&mesh, extra, 7);
            let s = term.stencil_size();
            let mut dofs = vec![0; s];
            for e in 0..term.n_elements() {
                term.element_dofs(e, &mut dofs);
                let z: Vec<f64> = dofs.iter().map(|&d| z_full[d]).collect();
                let mut grad = vec![0.0; s];
                let mut hess = vec![0.0; s * s];
                term.element(e, &z, Some(&mut grad), Some(&mut hess), HessianMode::Exact);
                let name = format!("{} {formulation:?} element {e}", model.name());
                let energy = |x: &[f64]| vec![term.element(e, x, None, None, HessianMode::Exact)];
                check_jacobian(
                    &format!("{name} gradient"),
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
                check_jacobian(
                    &format!("{name} Hessian"),
                    &z,
                    1e-7,
                    gradient,
                    &hess,
                    1e-6,
                    1e-10,
                );
                // The projected Hessian is symmetric positive semi-definite.
                let mut projected = vec![0.0; s * s];
                term.element(e, &z, None, Some(&mut projected), HessianMode::Projected);
                let block = nalgebra::DMatrix::from_fn(12, 12, |i, j| projected[i * s + j]);
                let sym = (&block - block.transpose()).abs().max();
                assert!(
                    sym <= 1e-9 * block.abs().max(),
                    "{name}: projected asymmetric by {sym}"
                );
                let low = block.symmetric_eigenvalues().min();
                assert!(
                    low >= -1e-9 * block.abs().max(),
                    "{name}: projected eigenvalue {low}"
                );
            }
        }
    }
}

/// `d(grad_e)/d(theta)` against central differences of the element gradient, each parameter
/// perturbed relative to its own size (the compressibilities are ~1e-6 1/Pa).
#[test]
fn decoupled_parameter_derivatives_of_element_gradients() {
    let mesh = small_mesh();
    for (model, base) in models() {
        for (formulation, extra) in formulations(mesh.n_nodes()) {
            let term = term(&mesh, model, &base, formulation);
            let z_full = deformed_state(&mesh, extra, 9);
            let (s, k) = (term.stencil_size(), term.element_param_count());
            let mut dofs = vec![0; s];
            for e in 0..term.n_elements() {
                term.element_dofs(e, &mut dofs);
                let z: Vec<f64> = dofs.iter().map(|&d| z_full[d]).collect();
                let mut d_grad = vec![0.0; k * s];
                term.element_param_gradient(e, &z, &mut d_grad);
                let theta = term.params()[e * k..(e + 1) * k].to_vec();
                // Relative coordinates r: theta_j = theta0_j (1 + r_j); absent Yeoh terms (0)
                // stay absent.
                let jacobian: Vec<f64> = (0..s * k)
                    .map(|ij| d_grad[(ij % k) * s + ij / k] * theta[ij % k])
                    .collect();
                let gradient_at = |r: &[f64]| {
                    let mut params = term.params().to_vec();
                    for j in 0..k {
                        params[e * k + j] = theta[j] * (1.0 + r[j]);
                    }
                    let mut shifted = term_like(&term, params);
                    shifted.pressure_iterates = None;
                    let mut g = vec![0.0; s];
                    shifted.element(e, &z, Some(&mut g), None, HessianMode::Exact);
                    g
                };
                check_jacobian(
                    &format!(
                        "{} {formulation:?} element {e} parameter derivatives",
                        model.name()
                    ),
                    &vec![0.0; k],
                    1e-6,
                    gradient_at,
                    &jacobian,
                    1e-6,
                    1e-12,
                );
            }
        }
    }
}

fn term_like(term: &ElasticTerm, params: Vec<f64>) -> ElasticTerm {
    ElasticTerm::new(term.mesh.clone(), term.material(), params, term.formulation)
}
