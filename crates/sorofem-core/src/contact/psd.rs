//! Projection of small symmetric matrices (stencil Hessians, up to 12 x 12) onto the positive
//! semi-definite cone, with a fixed-size eigensolver: Householder reduction to tridiagonal form,
//! then implicit QR steps with Wilkinson shifts (Golub and Van Loan, sections 8.3.1 and 8.3.3).
//! Stencil Hessians of distances vanish on rigid translations, which removes 3 dimensions
//! before the eigensolver (cost about (9/12)^3 of the full one).

use nalgebra::SMatrix;

/// Clamps the negative eigenvalues of a symmetric matrix to zero, in place (unchanged when it is
/// already positive semi-definite): IPC's projection of each stencil Hessian, so that the
/// assembled Hessian gives a descent direction. Computed as `H - sum_{lambda < 0} lambda q q^T`.
pub fn project_to_psd<const N: usize>(h: &mut SMatrix<f64, N, N>) {
    let mut a = [[0.0; N]; N];
    for (i, row) in a.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = h[(i, j)];
        }
    }
    let (values, vectors) = symmetric_eigen(&a);
    for (k, &lambda) in values.iter().enumerate() {
        if lambda < 0.0 {
            for i in 0..N {
                let scaled = lambda * vectors[i][k];
                for j in 0..N {
                    h[(i, j)] -= scaled * vectors[j][k];
                }
            }
        }
    }
}

/// [`project_to_psd`] of the Hessian of a function of `N / 3` points (2 to 4) that does not
/// change when they all translate together, as every distance: the Hessian is zero on the 3
/// translations, so it is `B H' B^T` with `B` (`N x (N - 3)`) an orthonormal basis of the rest,
/// and the eigensolver works on `H'` (the clamp is the same).
pub fn project_translation_invariant_to_psd<const N: usize>(h: &mut SMatrix<f64, N, N>) {
    match N {
        6 => project_invariant::<N, 3>(h),
        9 => project_invariant::<N, 6>(h),
        12 => project_invariant::<N, 9>(h),
        _ => project_to_psd(h),
    }
}

/// `B = U (x) I3`, `U` the Helmert basis of the vectors orthogonal to `(1, ..., 1)` in `R^m`.
fn project_invariant<const N: usize, const R: usize>(h: &mut SMatrix<f64, N, N>) {
    debug_assert_eq!(R + 3, N);
    let m = N / 3;
    // u[p][a]: Helmert column a has 1 on points 0..=a, -(a + 1) on point a + 1, over its norm.
    let mut u = [[0.0; 3]; 4];
    for a in 0..m - 1 {
        let norm = (((a + 1) * (a + 2)) as f64).sqrt();
        for row in u.iter_mut().take(a + 1) {
            row[a] = 1.0 / norm;
        }
        u[a + 1][a] = -((a + 1) as f64) / norm;
    }
    let mut reduced = [[0.0; R]; R];
    for a in 0..m - 1 {
        for b in 0..m - 1 {
            for i in 0..3 {
                for j in 0..3 {
                    let mut sum = 0.0;
                    for p in 0..=(a + 1) {
                        for q in 0..=(b + 1) {
                            sum += u[p][a] * u[q][b] * h[(3 * p + i, 3 * q + j)];
                        }
                    }
                    reduced[3 * a + i][3 * b + j] = sum;
                }
            }
        }
    }
    let (values, vectors) = symmetric_eigen(&reduced);
    for (k, &lambda) in values.iter().enumerate() {
        if lambda < 0.0 {
            // The eigenvector of H: B y.
            let mut full = [0.0; N];
            for a in 0..m - 1 {
                for p in 0..=(a + 1) {
                    for i in 0..3 {
                        full[3 * p + i] += u[p][a] * vectors[3 * a + i][k];
                    }
                }
            }
            for i in 0..N {
                let scaled = lambda * full[i];
                for j in 0..N {
                    h[(i, j)] -= scaled * full[j];
                }
            }
        }
    }
}

/// Eigenvalues `w` (unordered) and orthonormal eigenvectors (the columns of `q`, row-major) of
/// a symmetric matrix `a` (all of it is read): `a = q diag(w) q^T`.
pub fn symmetric_eigen<const N: usize>(a: &[[f64; N]; N]) -> ([f64; N], [[f64; N]; N]) {
    let mut t = *a;
    let mut q = [[0.0; N]; N];
    for (i, row) in q.iter_mut().enumerate() {
        row[i] = 1.0;
    }
    tridiagonalize(&mut t, &mut q);
    diagonalize(&mut t, &mut q);
    (std::array::from_fn(|i| t[i][i]), q)
}

/// `t <- P t P` for Householder reflections `P = I - beta v v^T` zeroing each column below its
/// subdiagonal, with `q <- q P`: afterwards `a = q t q^T`, `t` tridiagonal.
fn tridiagonalize<const N: usize>(t: &mut [[f64; N]; N], q: &mut [[f64; N]; N]) {
    let mut v = [0.0; N];
    let mut w = [0.0; N];
    for k in 0..N.saturating_sub(2) {
        let x0 = t[k + 1][k];
        let tail: f64 = (k + 2..N).map(|i| t[i][k] * t[i][k]).sum();
        if tail == 0.0 {
            continue;
        }
        let norm = (x0 * x0 + tail).sqrt();
        let alpha = if x0 > 0.0 { -norm } else { norm };
        for i in k + 1..N {
            v[i] = t[i][k];
        }
        v[k + 1] -= alpha;
        let beta = 2.0 / (v[k + 1] * v[k + 1] + tail);
        // p = beta T v, w = p - (beta / 2) (v . p) v; then T <- T - v w^T - w v^T.
        let mut vp = 0.0;
        for i in k + 1..N {
            let p: f64 = (k + 1..N).map(|j| t[i][j] * v[j]).sum::<f64>() * beta;
            w[i] = p;
            vp += v[i] * p;
        }
        let half = 0.5 * beta * vp;
        for i in k + 1..N {
            w[i] -= half * v[i];
        }
        for i in k + 1..N {
            for j in k + 1..N {
                t[i][j] -= v[i] * w[j] + w[i] * v[j];
            }
        }
        t[k + 1][k] = alpha;
        t[k][k + 1] = alpha;
        for row in t.iter_mut().skip(k + 2) {
            row[k] = 0.0;
        }
        t[k][k + 2..].fill(0.0);
        for row in q.iter_mut() {
            let s: f64 = (k + 1..N).map(|j| row[j] * v[j]).sum::<f64>() * beta;
            for j in k + 1..N {
                row[j] -= s * v[j];
            }
        }
    }
}

/// Implicit symmetric QR steps with Wilkinson shifts on the tridiagonal `t` until it is
/// diagonal, accumulating the rotations into `q`. The rotations act on the diagonal `d` and
/// subdiagonal `e` alone (with the bulge `b` they chase down), about 20 flops each besides the
/// 4 N of `q`.
fn diagonalize<const N: usize>(t: &mut [[f64; N]; N], q: &mut [[f64; N]; N]) {
    if N < 2 {
        return;
    }
    let mut d: [f64; N] = std::array::from_fn(|i| t[i][i]);
    let mut e: [f64; N] = std::array::from_fn(|i| if i + 1 < N { t[i + 1][i] } else { 0.0 });
    // Off-diagonal entries below eps |T| are dropped: relative to the neighbouring diagonal
    // entries instead, the zero eigenvalues of rank-deficient stencil Hessians converge slowly.
    let norm = (0..N).fold(0.0f64, |m, i| m.max(d[i].abs() + e[i].abs()));
    let tolerance = f64::EPSILON * norm;
    let negligible = |_: &[f64; N], e: &[f64; N], i: usize| e[i].abs() <= tolerance;
    let mut hi = N - 1;
    for _ in 0..64 * N {
        // Deflate converged trailing eigenvalues.
        while hi > 0 && negligible(&d, &e, hi - 1) {
            e[hi - 1] = 0.0;
            hi -= 1;
        }
        if hi == 0 {
            break;
        }
        let mut lo = hi - 1;
        while lo > 0 && !negligible(&d, &e, lo - 1) {
            lo -= 1;
        }
        if lo > 0 {
            e[lo - 1] = 0.0;
        }
        // Wilkinson shift: the eigenvalue of the trailing 2 x 2 block closer to its last entry.
        let delta = 0.5 * (d[hi - 1] - d[hi]);
        let sign = if delta >= 0.0 { 1.0 } else { -1.0 };
        let mu = d[hi] - e[hi - 1] * e[hi - 1] / (delta + sign * delta.hypot(e[hi - 1]));
        let mut x = d[lo] - mu;
        let mut z = e[lo];
        for k in lo..hi {
            // Rotation G in the plane (k, k+1) with [c s; -s c]^T [x; z] = [r; 0], T <- G^T T G.
            let r = x.hypot(z);
            let (c, s) = if r == 0.0 {
                (1.0, 0.0)
            } else {
                (x / r, -z / r)
            };
            if k > lo {
                e[k - 1] = c * e[k - 1] - s * z;
            }
            let (dk, dk1, ek) = (d[k], d[k + 1], e[k]);
            d[k] = c * c * dk - 2.0 * c * s * ek + s * s * dk1;
            d[k + 1] = s * s * dk + 2.0 * c * s * ek + c * c * dk1;
            e[k] = c * s * (dk - dk1) + (c * c - s * s) * ek;
            for row in q.iter_mut() {
                let (a, b) = (row[k], row[k + 1]);
                row[k] = c * a - s * b;
                row[k + 1] = s * a + c * b;
            }
            if k + 1 < hi {
                x = e[k];
                z = -s * e[k + 1];
                e[k + 1] *= c;
            }
        }
    }
    for i in 0..N {
        t[i][i] = d[i];
    }
}
