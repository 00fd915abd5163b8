//! Squared distances between surface primitives (m^2), with gradients and Hessians with respect
//! to the coordinates of every point involved, as IPC uses them: the barrier acts on squared
//! distances, which are polynomial or rational in the coordinates.
//!
//! Four primitive pairs carry every case: point-point, point-line, point-plane and line-line.
//! A point-triangle or an edge-edge distance is one of them, chosen by the closest features
//! ([`point_triangle_feature`], [`edge_edge_feature`]); the choice is made on the current
//! positions and the derivatives are those of the chosen formula.
//!
//! Coordinates are ordered point after point: the gradient of a function of points
//! `(x_0, x_1, ...)` has entry `3 a + i` for coordinate `i` of point `a`, and the Hessian is the
//! matching square matrix.

use nalgebra::{Matrix3, SMatrix, SVector, Vector3};

pub type Vec3 = Vector3<f64>;

/// Value, gradient (length N) and Hessian (N x N) of a scalar function of N coordinates.
#[derive(Clone, Debug, PartialEq)]
pub struct Derivatives<const N: usize> {
    pub value: f64,
    pub gradient: SVector<f64, N>,
    pub hessian: SMatrix<f64, N, N>,
}

/// Lines closer to parallel than this (`|ea x eb|^2 < PARALLEL * |ea|^2 |eb|^2`, a sine of about
/// 1e-7) take their distance from the segment ends: the line-line formula divides by `|ea x eb|^2`.
/// The edge-edge mollifier has switched such pairs off long before (it is below 1e-10 there).
const PARALLEL: f64 = 1e-14;

/// Which two features of a stencil are closest, with their local point indices (positions in
/// the stencil: for a point-triangle stencil the point is 0 and the triangle 1, 2, 3; for an
/// edge-edge stencil edge a is 0, 1 and edge b is 2, 3).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Feature {
    /// Points `[p, q]`.
    PointPoint([usize; 2]),
    /// Point `p` and the line through `e0`, `e1`: `[p, e0, e1]`.
    PointLine([usize; 3]),
    /// Point `p` and the plane through `t0`, `t1`, `t2`: `[p, t0, t1, t2]`.
    PointPlane([usize; 4]),
    /// The line through `a0`, `a1` and the line through `b0`, `b1`: `[a0, a1, b0, b1]`.
    LineLine([usize; 4]),
}

impl Feature {
    /// Local indices of the points the distance depends on.
    pub fn points(&self) -> &[usize] {
        match self {
            Feature::PointPoint(p) => p,
            Feature::PointLine(p) => p,
            Feature::PointPlane(p) => p,
            Feature::LineLine(p) => p,
        }
    }
}

/// `|p - q|^2`.
pub fn point_point_distance(p: &Vec3, q: &Vec3) -> f64 {
    (p - q).norm_squared()
}

/// [`point_point_distance`] and its derivatives with respect to `(p, q)` (6 coordinates).
pub fn point_point_distance_derivatives(p: &Vec3, q: &Vec3) -> Derivatives<6> {
    let r = p - q;
    let mut gradient = SVector::<f64, 6>::zeros();
    gradient.fixed_rows_mut::<3>(0).copy_from(&(2.0 * r));
    gradient.fixed_rows_mut::<3>(3).copy_from(&(-2.0 * r));
    let mut hessian = SMatrix::<f64, 6, 6>::zeros();
    for i in 0..3 {
        hessian[(i, i)] = 2.0;
        hessian[(i + 3, i + 3)] = 2.0;
        hessian[(i, i + 3)] = -2.0;
        hessian[(i + 3, i)] = -2.0;
    }
    Derivatives {
        value: r.norm_squared(),
        gradient,
        hessian,
    }
}

/// Squared distance from `p` to the infinite line through `e0`, `e1`:
/// `|(p - e0) x (e1 - e0)|^2 / |e1 - e0|^2` (the cross-product form keeps its precision when `p`
/// is close to the line).
pub fn point_line_distance(p: &Vec3, e0: &Vec3, e1: &Vec3) -> f64 {
    let e = e1 - e0;
    (p - e0).cross(&e).norm_squared() / e.norm_squared()
}

/// [`point_line_distance`] and its derivatives with respect to `(p, e0, e1)` (9 coordinates).
pub fn point_line_distance_derivatives(p: &Vec3, e0: &Vec3, e1: &Vec3) -> Derivatives<9> {
    let (r, e) = (p - e0, e1 - e0);
    // f = s / q in the variables (r, e), s = |r x e|^2, q = |e|^2.
    let s = cross_squared_norm(&r, &e);
    let q = e.norm_squared();
    let mut dq = SVector::<f64, 6>::zeros();
    dq.fixed_rows_mut::<3>(3).copy_from(&(2.0 * e));
    let mut d2q = SMatrix::<f64, 6, 6>::zeros();
    for i in 3..6 {
        d2q[(i, i)] = 2.0;
    }
    let value = s.value / q;
    let gradient = s.gradient / q - dq * (s.value / (q * q));
    let cross = s.gradient * dq.transpose();
    let hessian = s.hessian / q - (cross + cross.transpose()) / (q * q)
        + dq * dq.transpose() * (2.0 * s.value / (q * q * q))
        - d2q * (s.value / (q * q));
    pull_back::<6, 9>(
        &[&[1.0, -1.0, 0.0], &[0.0, -1.0, 1.0]],
        value,
        &gradient,
        &hessian,
    )
}

/// Squared distance from `p` to the plane through `t0`, `t1`, `t2`: `((p - t0) . n)^2 / |n|^2`
/// with `n = (t1 - t0) x (t2 - t0)`.
pub fn point_plane_distance(p: &Vec3, t0: &Vec3, t1: &Vec3, t2: &Vec3) -> f64 {
    let n = (t1 - t0).cross(&(t2 - t0));
    (p - t0).dot(&n).powi(2) / n.norm_squared()
}

/// [`point_plane_distance`] and its derivatives with respect to `(p, t0, t1, t2)` (12).
pub fn point_plane_distance_derivatives(
    p: &Vec3,
    t0: &Vec3,
    t1: &Vec3,
    t2: &Vec3,
) -> Derivatives<12> {
    let f = triple_over_cross(&(p - t0), &(t1 - t0), &(t2 - t0));
    pull_back::<9, 12>(
        &[
            &[1.0, -1.0, 0.0, 0.0],
            &[0.0, -1.0, 1.0, 0.0],
            &[0.0, -1.0, 0.0, 1.0],
        ],
        f.value,
        &f.gradient,
        &f.hessian,
    )
}

/// Squared distance between the infinite lines through `a0`, `a1` and `b0`, `b1`:
/// `((b0 - a0) . n)^2 / |n|^2` with `n = (a1 - a0) x (b1 - b0)` (undefined for parallel lines).
pub fn line_line_distance(a0: &Vec3, a1: &Vec3, b0: &Vec3, b1: &Vec3) -> f64 {
    let n = (a1 - a0).cross(&(b1 - b0));
    (b0 - a0).dot(&n).powi(2) / n.norm_squared()
}

/// [`line_line_distance`] and its derivatives with respect to `(a0, a1, b0, b1)` (12).
pub fn line_line_distance_derivatives(
    a0: &Vec3,
    a1: &Vec3,
    b0: &Vec3,
    b1: &Vec3,
) -> Derivatives<12> {
    let f = triple_over_cross(&(b0 - a0), &(a1 - a0), &(b1 - b0));
    pull_back::<9, 12>(
        &[
            &[-1.0, 0.0, 1.0, 0.0],
            &[-1.0, 1.0, 0.0, 0.0],
            &[0.0, 0.0, -1.0, 1.0],
        ],
        f.value,
        &f.gradient,
        &f.hessian,
    )
}

/// Closest feature of the segment `[e0, e1]` to `p`, with the local indices `ids = [p, e0, e1]`.
pub fn point_edge_feature(p: &Vec3, e0: &Vec3, e1: &Vec3, ids: [usize; 3]) -> Feature {
    let e = e1 - e0;
    let length_squared = e.norm_squared();
    let t = if length_squared > 0.0 {
        (p - e0).dot(&e) / length_squared
    } else {
        0.0
    };
    if t <= 0.0 {
        Feature::PointPoint([ids[0], ids[1]])
    } else if t >= 1.0 {
        Feature::PointPoint([ids[0], ids[2]])
    } else {
        Feature::PointLine(ids)
    }
}

/// Closest features of the point `p` (local 0) and the triangle `t0, t1, t2` (local 1, 2, 3): the
/// plane when `p` projects inside the triangle, otherwise the closest of its three edges (whose
/// own closest feature is an end point or the edge's line). A degenerate (zero-area) triangle is
/// treated through its edges.
pub fn point_triangle_feature(p: &Vec3, t0: &Vec3, t1: &Vec3, t2: &Vec3) -> Feature {
    let t = [t0, t1, t2];
    let n = (t1 - t0).cross(&(t2 - t0));
    if n.norm_squared() > 0.0 {
        // (b - a) x n points out of the triangle across edge (a, b).
        let inside = (0..3).all(|i| {
            let (a, b) = (t[i], t[(i + 1) % 3]);
            (b - a).cross(&n).dot(&(p - a)) <= 0.0
        });
        if inside {
            return Feature::PointPlane([0, 1, 2, 3]);
        }
    }
    let points = [p, t0, t1, t2];
    let mut best = (f64::INFINITY, Feature::PointPoint([0, 1]));
    for i in 0..3 {
        let j = (i + 1) % 3;
        let feature = point_edge_feature(p, t[i], t[j], [0, 1 + i, 1 + j]);
        let d = feature_distance(&feature, &points);
        if d < best.0 {
            best = (d, feature);
        }
    }
    best.1
}

/// Closest features of the segments `[a0, a1]` (local 0, 1) and `[b0, b1]` (local 2, 3): the two
/// lines when their closest points are interior to both segments (and the lines are not nearly
/// parallel), otherwise the closest of the four point-segment pairs formed by one segment's end
/// points and the other segment. This is exact: the squared distance is a convex quadratic in
/// the segment parameters, minimised on the boundary of the parameter square unless its
/// unconstrained minimum lies inside.
pub fn edge_edge_feature(a0: &Vec3, a1: &Vec3, b0: &Vec3, b1: &Vec3) -> Feature {
    let (ea, eb, w) = (a1 - a0, b1 - b0, a0 - b0);
    let (a, b, c) = (ea.norm_squared(), ea.dot(&eb), eb.norm_squared());
    let (d, e) = (ea.dot(&w), eb.dot(&w));
    if a > 0.0 && c > 0.0 && ea.cross(&eb).norm_squared() >= PARALLEL * a * c {
        let den = a * c - b * b;
        let s = (b * e - c * d) / den;
        let t = (a * e - b * d) / den;
        if s > 0.0 && s < 1.0 && t > 0.0 && t < 1.0 {
            return Feature::LineLine([0, 1, 2, 3]);
        }
    }
    let points = [a0, a1, b0, b1];
    let options = [
        point_edge_feature(a0, b0, b1, [0, 2, 3]),
        point_edge_feature(a1, b0, b1, [1, 2, 3]),
        point_edge_feature(b0, a0, a1, [2, 0, 1]),
        point_edge_feature(b1, a0, a1, [3, 0, 1]),
    ];
    let mut best = (f64::INFINITY, options[0]);
    for feature in options {
        let dist = feature_distance(&feature, &points);
        if dist < best.0 {
            best = (dist, feature);
        }
    }
    best.1
}

/// Squared distance between a point and a triangle (closest features chosen by
/// [`point_triangle_feature`]).
pub fn point_triangle_distance(p: &Vec3, t0: &Vec3, t1: &Vec3, t2: &Vec3) -> f64 {
    let feature = point_triangle_feature(p, t0, t1, t2);
    feature_distance(&feature, &[p, t0, t1, t2])
}

/// Squared distance between two segments (closest features chosen by [`edge_edge_feature`]).
pub fn edge_edge_distance(a0: &Vec3, a1: &Vec3, b0: &Vec3, b1: &Vec3) -> f64 {
    let feature = edge_edge_feature(a0, a1, b0, b1);
    feature_distance(&feature, &[a0, a1, b0, b1])
}

/// Squared distance between the features, given the stencil's points.
pub fn feature_distance(feature: &Feature, x: &[&Vec3]) -> f64 {
    match *feature {
        Feature::PointPoint([p, q]) => point_point_distance(x[p], x[q]),
        Feature::PointLine([p, e0, e1]) => point_line_distance(x[p], x[e0], x[e1]),
        Feature::PointPlane([p, t0, t1, t2]) => point_plane_distance(x[p], x[t0], x[t1], x[t2]),
        Feature::LineLine([a0, a1, b0, b1]) => line_line_distance(x[a0], x[a1], x[b0], x[b1]),
    }
}

/// [`feature_distance`] with its derivatives with respect to all the stencil's coordinates
/// (`3 x.len() <= 12` of them; entries of points the feature does not involve are zero, as are
/// the unused entries past `3 x.len()`).
pub fn feature_distance_derivatives(feature: &Feature, x: &[&Vec3]) -> Derivatives<12> {
    match *feature {
        Feature::PointPoint([p, q]) => {
            scatter(&point_point_distance_derivatives(x[p], x[q]), &[p, q])
        }
        Feature::PointLine([p, e0, e1]) => scatter(
            &point_line_distance_derivatives(x[p], x[e0], x[e1]),
            &[p, e0, e1],
        ),
        Feature::PointPlane(ids) => scatter(
            &point_plane_distance_derivatives(x[ids[0]], x[ids[1]], x[ids[2]], x[ids[3]]),
            &ids,
        ),
        Feature::LineLine(ids) => scatter(
            &line_line_distance_derivatives(x[ids[0]], x[ids[1]], x[ids[2]], x[ids[3]]),
            &ids,
        ),
    }
}

/// The edge-edge mollifier's threshold `eps_x = 1e-3 |a1 - a0|^2 |b1 - b0|^2` (m^4), from the
/// rest positions of the two edges.
pub fn edge_edge_mollifier_threshold(a0: &Vec3, a1: &Vec3, b0: &Vec3, b1: &Vec3) -> f64 {
    1e-3 * (a1 - a0).norm_squared() * (b1 - b0).norm_squared()
}

/// IPC's mollifier of nearly parallel edges, `m(c) = (2 - c / eps_x) c / eps_x` for
/// `c < eps_x` and 1 beyond, as a function of `c = |(a1 - a0) x (b1 - b0)|^2` (m^4): C1 at
/// `eps_x`, zero for parallel edges. Returns `(m, dm/dc, d2m/dc2)`.
pub fn edge_edge_mollifier(c: f64, eps_x: f64) -> (f64, f64, f64) {
    if c < eps_x {
        let ratio = c / eps_x;
        (
            (2.0 - ratio) * ratio,
            2.0 / eps_x * (1.0 - ratio),
            -2.0 / (eps_x * eps_x),
        )
    } else {
        (1.0, 0.0, 0.0)
    }
}

/// `c = |(a1 - a0) x (b1 - b0)|^2` (m^4) and its derivatives with respect to `(a0, a1, b0, b1)`.
pub fn edge_edge_cross_squared_norm_derivatives(
    a0: &Vec3,
    a1: &Vec3,
    b0: &Vec3,
    b1: &Vec3,
) -> Derivatives<12> {
    let c = cross_squared_norm(&(a1 - a0), &(b1 - b0));
    pull_back::<6, 12>(
        &[&[-1.0, 1.0, 0.0, 0.0], &[0.0, 0.0, -1.0, 1.0]],
        c.value,
        &c.gradient,
        &c.hessian,
    )
}

/// The mollifier `m(c(x))` of [`edge_edge_mollifier`] with its derivatives with respect to
/// `(a0, a1, b0, b1)`; `eps_x` from [`edge_edge_mollifier_threshold`] on rest positions.
pub fn edge_edge_mollifier_derivatives(
    a0: &Vec3,
    a1: &Vec3,
    b0: &Vec3,
    b1: &Vec3,
    eps_x: f64,
) -> Derivatives<12> {
    let c = edge_edge_cross_squared_norm_derivatives(a0, a1, b0, b1);
    let (m, dm, d2m) = edge_edge_mollifier(c.value, eps_x);
    Derivatives {
        value: m,
        gradient: c.gradient * dm,
        hessian: c.hessian * dm + c.gradient * c.gradient.transpose() * d2m,
    }
}

/// `|a x b|^2` and its derivatives with respect to `(a, b)`.
fn cross_squared_norm(a: &Vec3, b: &Vec3) -> Derivatives<6> {
    let n = a.cross(b);
    // dn/da = -[b]x, dn/db = [a]x; the bilinear part n . (da x db) = -da^T [n]x db.
    let ja = -b.cross_matrix();
    let jb = a.cross_matrix();
    let mut gradient = SVector::<f64, 6>::zeros();
    gradient
        .fixed_rows_mut::<3>(0)
        .copy_from(&(2.0 * ja.transpose() * n));
    gradient
        .fixed_rows_mut::<3>(3)
        .copy_from(&(2.0 * jb.transpose() * n));
    let ab = 2.0 * ja.transpose() * jb - 2.0 * n.cross_matrix();
    let mut hessian = SMatrix::<f64, 6, 6>::zeros();
    set_block(&mut hessian, 0, 0, &(2.0 * ja.transpose() * ja));
    set_block(&mut hessian, 0, 1, &ab);
    set_block(&mut hessian, 1, 0, &ab.transpose());
    set_block(&mut hessian, 1, 1, &(2.0 * jb.transpose() * jb));
    Derivatives {
        value: n.norm_squared(),
        gradient,
        hessian,
    }
}

/// `(r . (u x v))^2 / |u x v|^2` and its derivatives with respect to `(r, u, v)`: the squared
/// distance of a point from a plane, or between two lines, in difference vectors.
fn triple_over_cross(r: &Vec3, u: &Vec3, v: &Vec3) -> Derivatives<9> {
    let n = u.cross(v);
    let s = r.dot(&n);
    let mut ds = SVector::<f64, 9>::zeros();
    ds.fixed_rows_mut::<3>(0).copy_from(&n);
    ds.fixed_rows_mut::<3>(3).copy_from(&v.cross(r));
    ds.fixed_rows_mut::<3>(6).copy_from(&r.cross(u));
    let mut d2s = SMatrix::<f64, 9, 9>::zeros();
    let (ru, rv, uv) = (-v.cross_matrix(), u.cross_matrix(), -r.cross_matrix());
    set_block(&mut d2s, 0, 1, &ru);
    set_block(&mut d2s, 1, 0, &ru.transpose());
    set_block(&mut d2s, 0, 2, &rv);
    set_block(&mut d2s, 2, 0, &rv.transpose());
    set_block(&mut d2s, 1, 2, &uv);
    set_block(&mut d2s, 2, 1, &uv.transpose());
    let c = cross_squared_norm(u, v);
    let q = c.value;
    let mut dq = SVector::<f64, 9>::zeros();
    dq.fixed_rows_mut::<6>(3).copy_from(&c.gradient);
    let mut d2q = SMatrix::<f64, 9, 9>::zeros();
    d2q.fixed_view_mut::<6, 6>(3, 3).copy_from(&c.hessian);
    let cross = ds * dq.transpose();
    Derivatives {
        value: s * s / q,
        gradient: ds * (2.0 * s / q) - dq * (s * s / (q * q)),
        hessian: ds * ds.transpose() * (2.0 / q) + d2s * (2.0 * s / q)
            - (cross + cross.transpose()) * (2.0 * s / (q * q))
            + dq * dq.transpose() * (2.0 * s * s / (q * q * q))
            - d2q * (s * s / (q * q)),
    }
}

fn set_block<const N: usize>(m: &mut SMatrix<f64, N, N>, a: usize, b: usize, block: &Matrix3<f64>) {
    m.fixed_view_mut::<3, 3>(3 * a, 3 * b).copy_from(block);
}

/// Derivatives with respect to difference vectors `y_k = sum_j coef[k][j] x_j` (A = 3 K
/// coordinates) turned into derivatives with respect to the points `x_j` (P = 3 M coordinates).
fn pull_back<const A: usize, const P: usize>(
    coef: &[&[f64]],
    value: f64,
    gradient: &SVector<f64, A>,
    hessian: &SMatrix<f64, A, A>,
) -> Derivatives<P> {
    debug_assert_eq!(3 * coef.len(), A);
    debug_assert!(coef.iter().all(|row| 3 * row.len() == P));
    let points = P / 3;
    let mut g = SVector::<f64, P>::zeros();
    let mut h = SMatrix::<f64, P, P>::zeros();
    for (k, row) in coef.iter().enumerate() {
        for (j, &c) in row.iter().enumerate() {
            if c != 0.0 {
                for i in 0..3 {
                    g[3 * j + i] += c * gradient[3 * k + i];
                }
            }
        }
    }
    for (k, row_k) in coef.iter().enumerate() {
        for (n, row_n) in coef.iter().enumerate() {
            let block = hessian.fixed_view::<3, 3>(3 * k, 3 * n);
            for j in 0..points {
                if row_k[j] == 0.0 {
                    continue;
                }
                for l in 0..points {
                    let c = row_k[j] * row_n[l];
                    if c != 0.0 {
                        let mut target = h.fixed_view_mut::<3, 3>(3 * j, 3 * l);
                        target += block * c;
                    }
                }
            }
        }
    }
    Derivatives {
        value,
        gradient: g,
        hessian: h,
    }
}

/// Places the derivatives of a function of points `ids[0], ids[1], ...` into a 12-coordinate
/// stencil.
fn scatter<const N: usize>(local: &Derivatives<N>, ids: &[usize]) -> Derivatives<12> {
    let mut gradient = SVector::<f64, 12>::zeros();
    let mut hessian = SMatrix::<f64, 12, 12>::zeros();
    for (a, &ia) in ids.iter().enumerate() {
        for i in 0..3 {
            gradient[3 * ia + i] = local.gradient[3 * a + i];
        }
        for (b, &ib) in ids.iter().enumerate() {
            hessian
                .fixed_view_mut::<3, 3>(3 * ia, 3 * ib)
                .copy_from(&local.hessian.fixed_view::<3, 3>(3 * a, 3 * b));
        }
    }
    Derivatives {
        value: local.value,
        gradient,
        hessian,
    }
}
