//! The assembler's evaluation of a selection of its terms.

use sorofem_core::assembly::Assembler;
use sorofem_core::energy::{ElasticTerm, Formulation, HessianMode, Term};
use sorofem_core::material::Volumetric;
use sorofem_core::mesh::TetMesh;
use std::sync::Arc;

/// Evaluations of complementary selections of the terms add up to the whole.
#[test]
fn selected_terms_add_up_to_all_terms() {
    let mesh = Arc::new(TetMesh::box_mesh([1.0, 0.2, 0.1], [6, 2, 2], [0.0; 3]).unwrap());
    let m = mesh.n_tets();
    let term = |modulus: f64| {
        let formulation = Formulation::Standard;
        let (mu, lambda) = (vec![modulus; m], vec![2.0 * modulus; m]);
        ElasticTerm::neo_hookean(mesh.clone(), &mu, &lambda, Volumetric::Log, formulation)
    };
    let (soft, stiff) = (term(1.0), term(3.0));
    let terms: [&dyn Term; 2] = [&soft, &stiff];
    let mut fixed = vec![false; 3 * mesh.n_nodes()];
    fixed[..9].fill(true);
    let assembler = Assembler::new(&fixed, &terms);
    let z: Vec<f64> = (0..fixed.len()).map(|d| 1e-3 * (d as f64).sin()).collect();
    let hessian = Some(HessianMode::Exact);
    let all = assembler.evaluate(&terms, &z, true, hessian);
    let first = assembler.evaluate_selected(&terms, &[true, false], &z, true, hessian);
    let second = assembler.evaluate_selected(&terms, &[false, true], &z, true, hessian);
    assert!((first.energy + second.energy - all.energy).abs() <= 1e-12 * all.energy.abs());
    for (whole, (a, b)) in [
        (&all.gradient, (&first.gradient, &second.gradient)),
        (&all.hessian, (&first.hessian, &second.hessian)),
    ] {
        let scale = whole.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        assert!(scale > 0.0);
        for (w, (x, y)) in whole.iter().zip(a.iter().zip(b.iter())) {
            assert!((x + y - w).abs() <= 1e-12 * scale, "{x} + {y} vs {w}");
        }
        // The second term alone is three times the first (its moduli are).
        for (x, y) in a.iter().zip(b.iter()) {
            assert!((3.0 * x - y).abs() <= 1e-12 * scale, "3 x {x} vs {y}");
        }
    }
}
