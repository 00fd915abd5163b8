//! Tests of the sparse factorisations (`linear.rs`).

use super::*;

/// The Laplacian of a `dims[0] x dims[1] x dims[2]` grid (nearest neighbours: -1; diagonal:
/// 2 per dimension longer than one, plus `shift`).
fn grid_laplacian(dims: [usize; 3], shift: f64) -> (LowerPattern, Vec<f64>) {
    let n = dims.iter().product();
    let index = |i: usize, j: usize, l: usize| (i * dims[1] + j) * dims[2] + l;
    let diagonal = 2.0 * dims.iter().filter(|&&d| d > 1).count() as f64 + shift;
    let mut col_ptr = vec![0];
    let mut row_idx = Vec::new();
    let mut values = Vec::new();
    for i in 0..dims[0] {
        for j in 0..dims[1] {
            for l in 0..dims[2] {
                let mut entries = vec![(index(i, j, l), diagonal)];
                for (di, dj, dl) in [(1, 0, 0), (0, 1, 0), (0, 0, 1)] {
                    if i + di < dims[0] && j + dj < dims[1] && l + dl < dims[2] {
                        entries.push((index(i + di, j + dj, l + dl), -1.0));
                    }
                }
                entries.sort_by_key(|e| e.0);
                for (r, v) in entries {
                    row_idx.push(r);
                    values.push(v);
                }
                col_ptr.push(row_idx.len());
            }
        }
    }
    (
        LowerPattern {
            n,
            col_ptr,
            row_idx,
        },
        values,
    )
}

/// `max |a - b|`.
fn max_difference(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

#[test]
fn llt_solves_and_detects_indefinite() {
    let (p, v) = grid_laplacian([50, 1, 1], 0.0);
    let mut f = SparseFactor::analyse(&p, FactorKind::Llt).unwrap();
    assert!(f.factor(&p, &v).unwrap());
    let x: Vec<f64> = (0..50).map(|i| (i as f64).sin()).collect();
    let mut b = p.symmetric_matvec(&v, &x);
    f.solve_in_place(&mut b);
    let err = max_difference(&b, &x);
    assert!(err < 1e-10, "{err}");
    let (_, v_indef) = grid_laplacian([50, 1, 1], -3.0);
    assert!(!f.factor(&p, &v_indef).unwrap());
}

/// Single precision on the split supernodal path (14^3 grid) and on faer's (a chain): the
/// plain solve is accurate to single precision only, one refinement step to about its
/// square; `solve_residual` measures the plain solve; a double-precision factorisation
/// afterwards solves to double precision again.
#[test]
fn single_precision_factor_solves_and_refines() {
    for (dims, shift) in [([14, 14, 14], 0.1), ([50, 1, 1], 0.05)] {
        let (p, v) = grid_laplacian(dims, shift);
        let mut f = SparseFactor::analyse(&p, FactorKind::Llt).unwrap();
        let x: Vec<f64> = (0..p.n).map(|i| (0.37 * i as f64).sin()).collect();
        let b = p.symmetric_matvec(&v, &x);
        let generation = f.generation();
        assert!(f.factor_single(&p, &v).unwrap());
        assert!(f.is_single() && f.generation() == generation + 1);
        let mut plain = b.clone();
        f.solve_in_place(&mut plain);
        let plain_error = max_difference(&plain, &x);
        assert!(
            plain_error > 1e-9 && plain_error < 1e-3,
            "{dims:?}: {plain_error}"
        );
        let residual = f.solve_residual(&b);
        assert!(residual > 1e-10 && residual < 1e-5, "{dims:?}: {residual}");
        let mut refined = b.clone();
        f.solve_refined_in_place(&mut refined);
        let refined_error = max_difference(&refined, &x);
        assert!(
            refined_error < 1e-3 * plain_error,
            "{dims:?}: {refined_error} vs {plain_error}"
        );
        assert!(f.factor(&p, &v).unwrap() && !f.is_single());
        let mut double = b.clone();
        f.solve_in_place(&mut double);
        assert!(max_difference(&double, &x) < 1e-11);
        assert!(f.solve_residual(&b) < 1e-14);
    }
    let (p, v_indef) = grid_laplacian([50, 1, 1], -3.0);
    let mut f = SparseFactor::analyse(&p, FactorKind::Llt).unwrap();
    assert!(!f.factor_single(&p, &v_indef).unwrap());
}

/// `solve_to_precision` with a single-precision factor: on a well-conditioned matrix its
/// refinements reach a double-precision solve's residual; on one too ill-conditioned for
/// single precision (a chain of 200 shifted to 1e-5 of its smallest eigenvalue, condition
/// about 2e9, still positive definite in single precision: the refinements stall near 3e-9)
/// it stops refining, and the double-precision factorisation it falls back to solves as
/// `factor` would.
#[test]
fn single_precision_solves_refine_to_double_precision() {
    let chain_smallest = 2.0 - 2.0 * (std::f64::consts::PI / 201.0).cos();
    for (dims, shift, refined) in [
        ([14, 14, 14], 0.1, true),
        ([200, 1, 1], -(1.0 - 1e-5) * chain_smallest, false),
    ] {
        let (p, v) = grid_laplacian(dims, shift);
        let mut f = SparseFactor::analyse(&p, FactorKind::Llt).unwrap();
        let x: Vec<f64> = (0..p.n).map(|i| (0.37 * i as f64).sin()).collect();
        let b = p.symmetric_matvec(&v, &x);
        assert!(f.factor(&p, &v).unwrap());
        let mut double = b.clone();
        f.solve_in_place(&mut double);
        assert!(f.factor_single(&p, &v).unwrap());
        let permuted: Vec<f64> = f.analysis.order.iter().map(|&i| b[i]).collect();
        let (_, residual) = f.refined_single_permuted(&permuted);
        assert_eq!(
            residual <= REFINED_RESIDUAL,
            refined,
            "{dims:?}: {residual}"
        );
        assert_eq!(
            residual <= ROUND_OFF_RESIDUAL,
            refined,
            "{dims:?}: {residual}"
        );
        let mut solved = b.clone();
        f.solve_to_precision(&mut solved).unwrap();
        let scale = double.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let difference = max_difference(&solved, &double) / scale;
        assert!(difference < 1e-9, "{dims:?}: {difference}");
    }
    let (p, v) = grid_laplacian([50, 1, 1], 0.05);
    let mut f = SparseFactor::analyse(&p, FactorKind::Llt).unwrap();
    assert!(f.factor_single(&p, &v).unwrap());
    let mut zero = vec![0.0; p.n];
    f.solve_to_precision(&mut zero).unwrap();
    assert!(zero.iter().all(|&v| v == 0.0));
}

#[test]
fn split_supernodal_solves_match_the_matrix() {
    // 14^3 unknowns: a supernodal factor whose solves are split between two threads.
    let (p, v) = grid_laplacian([14, 14, 14], 0.1);
    let mut f = SparseFactor::analyse(&p, FactorKind::Llt).unwrap();
    let split = f.analysis.split.as_ref().expect("a supernodal factor");
    assert!(!split.groups[1].is_empty(), "the solves are split");
    let x: Vec<f64> = (0..p.n).map(|i| (0.37 * i as f64).sin()).collect();
    let b = p.symmetric_matvec(&v, &x);
    assert!(f.factor(&p, &v).unwrap());
    let mut solved = b.clone();
    f.solve_in_place(&mut solved);
    let err = max_difference(&solved, &x);
    assert!(err < 1e-11, "{err}");
}

#[test]
fn ldlt_solves_saddle_point() {
    // [[2, 1], [1, -1e-8]]
    let p = LowerPattern {
        n: 2,
        col_ptr: vec![0, 2, 3],
        row_idx: vec![0, 1, 1],
    };
    let v = vec![2.0, 1.0, -1e-8];
    let mut f = SparseFactor::analyse(&p, FactorKind::Ldlt).unwrap();
    assert!(f.factor(&p, &v).unwrap());
    let x = [0.3, -0.7];
    let mut b = p.symmetric_matvec(&v, &x);
    f.solve_in_place(&mut b);
    assert!(
        (b[0] - x[0]).abs() < 1e-9 && (b[1] - x[1]).abs() < 1e-9,
        "{b:?}"
    );
}
