//! The shared finite-difference checker checks itself: it accepts an exact Jacobian and rejects
//! one whose small block (a millionth of the largest entry) is wrong by 1 %, which a tolerance
//! relative to the whole matrix would let through.
mod common;

use common::{check_jacobian, check_jacobian_blocks};

/// `f(x) = A x` with a 2 x 2 block of size 1 and a 2 x 2 block of size 1e-6 on the diagonal,
/// coupled by off-diagonal blocks of size 1e-3: `(A, labels)`.
fn two_scale_matrix() -> (Vec<f64>, Vec<usize>) {
    let a = vec![
        2.0, 0.5, 1e-3, 0.0, //
        0.5, 1.0, 0.0, 2e-3, //
        1e-3, 0.0, -3e-6, 1e-6, //
        0.0, 2e-3, 1e-6, -2e-6,
    ];
    (a, vec![0, 0, 1, 1])
}

fn apply(a: &[f64], x: &[f64]) -> Vec<f64> {
    (0..4)
        .map(|i| (0..4).map(|j| a[4 * i + j] * x[j]).sum())
        .collect()
}

#[test]
fn exact_jacobian_passes_block_by_block() {
    let (a, labels) = two_scale_matrix();
    let x0 = [0.3, -0.2, 0.7, 0.1];
    check_jacobian_blocks(
        "exact",
        &x0,
        1e-6,
        |x| apply(&a, x),
        &a,
        &labels,
        &labels,
        1e-6,
        1e-15,
    );
}

#[test]
#[should_panic(expected = "block (1, 1)")]
fn small_block_wrong_by_one_percent_fails() {
    let (a, labels) = two_scale_matrix();
    let mut wrong = a.clone();
    wrong[4 * 2 + 2] *= 1.01;
    check_jacobian_blocks(
        "perturbed",
        &[0.3, -0.2, 0.7, 0.1],
        1e-6,
        |x| apply(&a, x),
        &wrong,
        &labels,
        &labels,
        1e-6,
        1e-15,
    );
}

#[test]
#[should_panic(expected = "block (1, 1)")]
fn small_block_with_the_wrong_sign_fails() {
    let (a, labels) = two_scale_matrix();
    let mut wrong = a.clone();
    for k in [4 * 2 + 2, 4 * 2 + 3, 4 * 3 + 2, 4 * 3 + 3] {
        wrong[k] = -wrong[k];
    }
    check_jacobian_blocks(
        "sign",
        &[0.3, -0.2, 0.7, 0.1],
        1e-6,
        |x| apply(&a, x),
        &wrong,
        &labels,
        &labels,
        1e-6,
        1e-15,
    );
}

#[test]
#[should_panic(expected = "entry (0, 1)")]
fn a_wrong_large_entry_fails_the_whole_matrix_check() {
    let (a, _) = two_scale_matrix();
    let mut wrong = a.clone();
    wrong[1] *= 1.01;
    check_jacobian(
        "large",
        &[0.3, -0.2, 0.7, 0.1],
        1e-6,
        |x| apply(&a, x),
        &wrong,
        1e-6,
        0.0,
    );
}

#[test]
#[should_panic(expected = "NaN")]
fn a_nan_anywhere_fails() {
    let (a, labels) = two_scale_matrix();
    let nan_in_one_row = |x: &[f64]| {
        let mut y = apply(&a, x);
        y[3] = f64::NAN;
        y
    };
    check_jacobian_blocks(
        "nan",
        &[0.3, -0.2, 0.7, 0.1],
        1e-6,
        nan_in_one_row,
        &a,
        &labels,
        &labels,
        1e-6,
        1e-15,
    );
}

/// An exact all-zero block with `atol = 0` passes (its tolerance is 0, so the error ratio was
/// 0 / 0 = NaN, which failed the Mooney-Rivlin `d1` column of `dW_rest/dtheta`).
#[test]
fn an_exact_zero_block_passes_with_no_absolute_tolerance() {
    let (mut a, labels) = two_scale_matrix();
    for (i, j) in [
        (0, 2),
        (0, 3),
        (1, 2),
        (1, 3),
        (2, 0),
        (2, 1),
        (3, 0),
        (3, 1),
    ] {
        a[4 * i + j] = 0.0;
    }
    check_jacobian_blocks(
        "zero block",
        &[0.3, -0.2, 0.7, 0.1],
        1e-6,
        |x| apply(&a, x),
        &a,
        &labels,
        &labels,
        1e-6,
        0.0,
    );
}
