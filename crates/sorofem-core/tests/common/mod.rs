//! Shared test support: the one central-difference checker every derivative test goes through,
//! a reproducible random generator, and small model builders.
#![allow(dead_code)]

/// Deterministic pseudo-random numbers in [-1, 1) (xorshift), so failures are reproducible.
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Rng(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
    }
    pub fn next(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    }
    pub fn vec(&mut self, n: usize, scale: f64) -> Vec<f64> {
        (0..n).map(|_| scale * self.next()).collect()
    }
}

/// Checks an analytic Jacobian `jac` (m x n, row-major) of `f: R^n -> R^m` at `x0` against central
/// differences with step `h` (relative to max(1, |x_i|)). Fails with the worst entry when
/// `|fd - analytic| > rtol * max|analytic| + atol`, the maximum over the whole matrix: use
/// [`check_jacobian_blocks`] when parts of the matrix differ in size by orders of magnitude.
pub fn check_jacobian(
    name: &str,
    x0: &[f64],
    h: f64,
    f: impl Fn(&[f64]) -> Vec<f64>,
    jac: &[f64],
    rtol: f64,
    atol: f64,
) {
    let m = f(x0).len();
    check_jacobian_blocks(
        name,
        x0,
        h,
        f,
        jac,
        &vec![0; m],
        &vec![0; x0.len()],
        rtol,
        atol,
    );
}

/// [`check_jacobian`] block by block: `row_block[i]` and `col_block[j]` label the block of each
/// row and column (e.g. 0 for displacements, 1 for pressures), and every entry is held to
/// `rtol * max|analytic|` over its own (row block, column block) plus `atol`. So a block a
/// million times smaller than the rest (the pressure-pressure block of the mixed element next to
/// its stiffness) is checked to the same relative accuracy; `atol` must then lie below the
/// smallest block that matters.
#[allow(clippy::too_many_arguments)]
pub fn check_jacobian_blocks(
    name: &str,
    x0: &[f64],
    h: f64,
    f: impl Fn(&[f64]) -> Vec<f64>,
    jac: &[f64],
    row_block: &[usize],
    col_block: &[usize],
    rtol: f64,
    atol: f64,
) {
    let n = x0.len();
    let m = f(x0).len();
    assert_eq!(
        jac.len(),
        m * n,
        "{name}: analytic Jacobian has the wrong size"
    );
    assert_eq!(
        (row_block.len(), col_block.len()),
        (m, n),
        "{name}: one block label per row and per column"
    );
    let mut scale = std::collections::HashMap::<(usize, usize), f64>::new();
    for i in 0..m {
        for j in 0..n {
            let s = scale.entry((row_block[i], col_block[j])).or_insert(0.0);
            *s = s.max(jac[i * n + j].abs());
        }
    }
    // The worst entry relative to its tolerance: (error / tolerance, i, j, fd, analytic, scale).
    let mut worst = (0.0, 0, 0, 0.0, 0.0, 0.0);
    let mut x = x0.to_vec();
    for j in 0..n {
        let step = h * x0[j].abs().max(1.0);
        x[j] = x0[j] + step;
        let fp = f(&x);
        x[j] = x0[j] - step;
        let fm = f(&x);
        x[j] = x0[j];
        for i in 0..m {
            let fd = (fp[i] - fm[i]) / (2.0 * step);
            let block_scale = scale[&(row_block[i], col_block[j])];
            let error = (fd - jac[i * n + j]).abs();
            // An exact match passes even where the tolerance is 0 (an all-zero block with
            // atol = 0); a NaN (from either side) is the worst of all.
            let ratio = if error == 0.0 {
                0.0
            } else {
                error / (rtol * block_scale + atol)
            };
            if ratio.is_nan() || ratio > worst.0 {
                worst = (ratio, i, j, fd, jac[i * n + j], block_scale);
            }
        }
    }
    let (ratio, i, j, fd, an, block_scale) = worst;
    assert!(
        ratio <= 1.0,
        "{name}: entry ({i}, {j}) finite difference {fd:.10e} vs analytic {an:.10e} (error {:.3e}, {ratio:.3e} times the tolerance; block ({}, {}) of scale {block_scale:.3e})",
        (fd - an).abs(),
        row_block[i],
        col_block[j]
    );
}

/// Gradient check of a scalar function through [`check_jacobian`].
pub fn check_gradient(
    name: &str,
    x0: &[f64],
    h: f64,
    f: impl Fn(&[f64]) -> f64,
    grad: &[f64],
    rtol: f64,
    atol: f64,
) {
    check_jacobian(name, x0, h, |x| vec![f(x)], grad, rtol, atol);
}

/// Directional check: `d/de f(x0 + e v)` at e = 0 by central differences against `analytic`.
pub fn check_directional(
    name: &str,
    x0: &[f64],
    v: &[f64],
    h: f64,
    mut f: impl FnMut(&[f64]) -> f64,
    analytic: f64,
    rtol: f64,
) {
    let mut at = |e: f64| -> f64 {
        let x: Vec<f64> = x0.iter().zip(v).map(|(a, b)| a + e * b).collect();
        f(&x)
    };
    let fd = (at(h) - at(-h)) / (2.0 * h);
    assert!(
        (fd - analytic).abs() <= rtol * analytic.abs().max(fd.abs()),
        "{name}: directional derivative finite difference {fd:.10e} vs analytic {analytic:.10e}"
    );
}

use sorofem_core::material::neo_hookean::lame_from_young;
use sorofem_core::{Formulation, Loads, Material, Model, Solution, SolveOptions, TetMesh};
use std::sync::Arc;

/// A box cantilever clamped at x = 0 with a uniform material.
pub fn cantilever(
    size: [f64; 3],
    cells: [usize; 3],
    youngs: f64,
    nu: f64,
    density: f64,
    formulation: Formulation,
) -> Model {
    let mesh = Arc::new(TetMesh::box_mesh(size, cells, [0.0; 3]).unwrap());
    clamped_at_x0(mesh, youngs, nu, density, formulation)
}

/// A model of `mesh` clamped on its nodes at x = 0, with a uniform material.
pub fn clamped_at_x0(
    mesh: Arc<TetMesh>,
    youngs: f64,
    nu: f64,
    density: f64,
    formulation: Formulation,
) -> Model {
    let fixed: Vec<i64> = mesh
        .nodes_in_box([-1e-9, -1.0, -1.0], [1e-9, 1.0, 1.0])
        .iter()
        .map(|&i| i as i64)
        .collect();
    let m = mesh.n_tets();
    let mut model = Model::try_new(
        mesh,
        &fixed,
        formulation,
        sorofem_core::material::Volumetric::Log,
    )
    .unwrap();
    let (mu, lambda) = lame_from_young(youngs, nu);
    model
        .set_material(&Material {
            mu: vec![mu; m],
            lambda: vec![lambda; m],
            density: vec![density; m],
        })
        .unwrap();
    model
}

pub fn solve_gravity(model: &mut Model, gravity: [f64; 3]) -> Solution {
    let loads = Loads {
        gravity,
        ..Default::default()
    };
    model.solve(&loads, None, &SolveOptions::default()).unwrap()
}

/// Mean displacement of the nodes on the free end face x = L (m, per axis).
pub fn tip_displacement(model: &Model, solution: &Solution, length: f64) -> [f64; 3] {
    let mesh = model.mesh();
    let tip = mesh.nodes_in_box([length - 1e-9, -1.0, -1.0], [length + 1e-9, 1.0, 1.0]);
    let mut u = [0.0; 3];
    for &i in &tip {
        for k in 0..3 {
            u[k] += (solution.positions[3 * i + k] - mesh.rest()[i][k]) / tip.len() as f64;
        }
    }
    u
}

use sorofem_core::contact::{CollisionMesh, Obstacle, ObstacleMesh, Plane, Sphere};

/// A 0.1 m cube of `cells^3` hexahedra (split into tets) whose bottom face is 2 mm above the plane
/// z = 0, whose top centre is 3 mm below a 20 mm sphere, and whose side x = 0.1 is 3 mm from a box
/// obstacle (obstacles 0, 1 and 2 of the collision mesh).
pub fn contact_scene(cells: usize, self_contact: bool) -> (TetMesh, CollisionMesh) {
    let mesh = TetMesh::box_mesh([0.1; 3], [cells; 3], [0.0, 0.0, 0.002]).unwrap();
    let obstacles = vec![
        Obstacle::Plane(Plane::try_new([0.0; 3], [0.0, 0.0, 1.0]).unwrap()),
        Obstacle::Sphere(Sphere::try_new([0.05, 0.05, 0.102 + 0.003 + 0.02], 0.02).unwrap()),
        Obstacle::Mesh(ObstacleMesh::cuboid([0.103, 0.02, 0.03], [0.15, 0.08, 0.07]).unwrap()),
    ];
    let collision = CollisionMesh::from_tet_mesh(&mesh, obstacles, self_contact);
    (mesh, collision)
}
