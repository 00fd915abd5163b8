//! Self-contact of the body's boundary surface: the barrier's derivatives on the body against
//! itself (near-parallel edges included), the step bound that keeps every iterate free of
//! self-intersection, and a C-shaped body whose upper arm sags onto its lower arm: it rests on it
//! with self-contact and passes through it without, the self-contact forces are internal
//! (zero total force and moment) and the supports carry the weight.
mod common;

use common::{check_gradient, check_jacobian, Rng};
use nalgebra::DMatrix;
use sorofem_core::contact::broad_phase::{candidates, swept_candidates};
use sorofem_core::contact::ccd::{max_step, DEFAULT_MIN_SEPARATION};
use sorofem_core::contact::check::{minimum_distance, self_intersection};
use sorofem_core::contact::potential::{candidate_squared_distance, is_mollified};
use sorofem_core::contact::{
    BarrierPotential, Candidate, CollisionMesh, ContactSetup, ContactTerm, Vec3,
};
use sorofem_core::energy::HessianMode;
use sorofem_core::material::neo_hookean::lame_from_young;
use sorofem_core::{Formulation, Loads, Material, Model, Orientation, SolveOptions, TetMesh};
use std::sync::Arc;
use std::time::Instant;

const G: f64 = 9.81;

/// A C-shaped body: the box `[0, size]` of `cells` hexahedra without the slot of the hexes
/// `i >= 1, 1 <= k <= cells[2] - 2` (open towards +x) and without the second half of the top
/// layer: a lower arm (bottom layer), a spine at x < size[0] / cells[0] and an upper arm half
/// as long as the lower one, the slot between them `size[2] (cells[2] - 2) / cells[2]` high.
fn c_shape(size: [f64; 3], cells: [usize; 3]) -> TetMesh {
    let block = TetMesh::box_mesh(size, cells, [0.0; 3]).unwrap();
    let h = [0, 1, 2].map(|a| size[a] / cells[a] as f64);
    let kept: Vec<[usize; 4]> = block
        .tets()
        .iter()
        .filter(|t| {
            let c: Vec<f64> = (0..3)
                .map(|a| t.iter().map(|&v| block.rest()[v][a]).sum::<f64>() / 4.0)
                .collect();
            let (i, k) = ((c[0] / h[0]) as usize, (c[2] / h[2]) as usize);
            let slot = i >= 1 && k >= 1 && k + 2 <= cells[2];
            !(slot || (k + 1 == cells[2] && 2 * i >= cells[0]))
        })
        .copied()
        .collect();
    let mut index = vec![-1i64; block.n_nodes()];
    let mut points = Vec::new();
    for t in &kept {
        for &v in t {
            if index[v] < 0 {
                index[v] = points.len() as i64;
                points.push(block.rest()[v]);
            }
        }
    }
    let tets: Vec<[i64; 4]> = kept.iter().map(|t| t.map(|v| index[v])).collect();
    TetMesh::try_new(points, &tets, Orientation::Reorient)
        .unwrap()
        .0
}

const SIZE: [f64; 3] = [0.2, 0.02, 0.08];
const CELLS: [usize; 3] = [8, 1, 4];
/// The top of the lower arm and the bottom of the upper arm (m).
const LOWER_TOP: f64 = 0.02;
const UPPER_BOTTOM: f64 = 0.06;
/// The end of the upper arm (m).
const UPPER_END: f64 = 0.1;

/// The C-shape's rest positions with the upper arm (z >= UPPER_BOTTOM) lowered in proportion to
/// x beyond the spine, by `drop` (m) at its end: the arm rotated down about the spine.
fn lowered(mesh: &TetMesh, drop: f64) -> Vec<f64> {
    let h = SIZE[0] / CELLS[0] as f64;
    mesh.rest()
        .iter()
        .flat_map(|p| {
            let lift = if p[2] >= UPPER_BOTTOM - 1e-12 && p[0] > h {
                drop * (p[0] - h) / (UPPER_END - h)
            } else {
                0.0
            };
            [p[0], p[1], p[2] - lift]
        })
        .collect()
}

#[test]
fn self_contact_gradient_and_hessian_match_finite_differences() {
    let mesh = c_shape(SIZE, CELLS);
    let collision = CollisionMesh::from_tet_mesh(&mesh, Vec::new(), true);
    let dhat = 0.004;
    let potential = BarrierPotential::try_new(dhat, 1e6).unwrap();
    let mut rng = Rng::new(17);
    let gap = UPPER_BOTTOM - LOWER_TOP;
    // The arm's end 0.6 dhat above the lower arm, its end edge nearly parallel to the edge below
    // it (under the mollifier's threshold) after a 0.02 dhat jitter.
    let body: Vec<f64> = lowered(&mesh, gap - 0.6 * dhat)
        .iter()
        .map(|v| v + 0.02 * dhat * rng.next())
        .collect();
    let x = collision.vertices(&body).unwrap();
    let found = candidates(&collision, &x, dhat);
    let active: Vec<Candidate> = found
        .iter()
        .filter(|c| {
            let (p, n) = c.positions(&x);
            candidate_squared_distance(&collision, c, &p[..n]) < dhat * dhat
        })
        .copied()
        .collect();
    let point_triangle = active
        .iter()
        .filter(|c| matches!(c, Candidate::PointTriangle { .. }))
        .count();
    let mollified = active
        .iter()
        .filter(|c| match c {
            Candidate::EdgeEdge { a, b } => {
                let (p, _) = c.positions(&x);
                is_mollified(&collision, *a, *b, &p)
            }
            _ => false,
        })
        .count();
    let edge_edge = active.len() - point_triangle;
    println!(
        "{} candidates, active: {point_triangle} point-triangle, {edge_edge} edge-edge ({mollified} mollified)",
        found.len()
    );
    assert!(point_triangle > 0 && edge_edge > mollified && mollified > 0);
    let assembled = potential.assemble(&collision, &found, &x, Some(HessianMode::Exact));
    assert!(assembled.energy > 0.0 && assembled.energy.is_finite());
    let n = 3 * mesh.n_nodes();
    let energy = |y: &[f64]| potential.energy(&collision, &found, &collision.vertices(y).unwrap());
    check_gradient(
        "self-contact gradient",
        &body,
        1e-8,
        energy,
        &assembled.gradient,
        1e-5,
        0.0,
    );
    let dense = |hessians: &[sorofem_core::contact::potential::StencilHessian]| {
        let mut out = vec![0.0; n * n];
        for (r, c, v) in hessians.iter().flat_map(|h| h.entries()) {
            out[r * n + c] += v;
        }
        out
    };
    let gradient = |y: &[f64]| {
        let x = collision.vertices(y).unwrap();
        potential.assemble(&collision, &found, &x, None).gradient
    };
    check_jacobian(
        "self-contact Hessian",
        &body,
        1e-8,
        gradient,
        &dense(&assembled.hessians),
        1e-5,
        0.0,
    );
    // Projected: every stencil's Hessian is PSD, so is their sum.
    let projected = potential.assemble(&collision, &found, &x, Some(HessianMode::Projected));
    let matrix = DMatrix::from_row_slice(n, n, &dense(&projected.hessians));
    // (A Cholesky factorisation of the slightly shifted matrix: nalgebra's dense eigensolver
    // does not converge on this matrix, mostly zero rows.)
    let shift = 1e-10 * matrix.abs().max();
    assert!(
        (matrix + DMatrix::identity(n, n) * shift)
            .cholesky()
            .is_some(),
        "the projected self-contact Hessian is not positive semi-definite"
    );
    // Translation and rotation invariance: the self-contact forces sum to zero, and so do their
    // moments.
    let (mut force, mut moment) = (Vec3::zeros(), Vec3::zeros());
    for (v, p) in x.iter().enumerate() {
        let f = -Vec3::new(
            assembled.gradient[3 * v],
            assembled.gradient[3 * v + 1],
            assembled.gradient[3 * v + 2],
        );
        force += f;
        moment += p.cross(&f);
    }
    let magnitude = assembled.gradient.iter().map(|g| g.abs()).sum::<f64>();
    assert!(force.norm() <= 1e-12 * magnitude, "total force {force:?}");
    assert!(
        moment.norm() <= 1e-12 * magnitude * SIZE[0],
        "moment {moment:?}"
    );
}

#[test]
fn the_step_bound_keeps_the_surface_from_passing_through_itself() {
    let mesh = c_shape(SIZE, CELLS);
    let collision = CollisionMesh::from_tet_mesh(&mesh, Vec::new(), true);
    let gap = UPPER_BOTTOM - LOWER_TOP;
    let x0 = collision.vertices(&mesh.rest_flat()).unwrap();
    let eta = DEFAULT_MIN_SEPARATION;
    // The upper arm swung down through the lower arm: straight (its bottom parallel to the lower
    // arm's top, contact at 1 / 3 of the step) and with a twist.
    let twist = |p: &Vec3| Vec3::new(0.0, 0.3 * (p[0] - 0.025), 0.0);
    for (k, twisted) in [false, true].into_iter().enumerate() {
        let target = lowered(&mesh, 3.0 * gap);
        let dx: Vec<Vec3> = x0
            .iter()
            .enumerate()
            .map(|(v, p)| {
                let down = Vec3::new(0.0, 0.0, target[3 * v + 2] - p[2]);
                if twisted && down.norm() > 0.0 {
                    down + twist(p)
                } else {
                    down
                }
            })
            .collect();
        let x1: Vec<Vec3> = x0.iter().zip(&dx).map(|(a, b)| a + b).collect();
        assert!(
            self_intersection(&collision, &x1).is_some(),
            "motion {k} must pass through"
        );
        let swept = swept_candidates(&collision, &x0, &x1, 0.0);
        let alpha = max_step(&collision, &swept, &x0, &dx, eta);
        println!("motion {k}: step bound {alpha:.4}");
        assert!(alpha > 0.0 && alpha < 1.0 / 3.0, "motion {k}: {alpha}");
        for s in 0..=100 {
            let tau = alpha * s as f64 / 100.0;
            let x: Vec<Vec3> = x0.iter().zip(&dx).map(|(a, b)| a + tau * b).collect();
            assert!(
                self_intersection(&collision, &x).is_none(),
                "motion {k} at {tau}"
            );
            let (lowest, c) = minimum_distance(&collision, &swept, &x).unwrap();
            assert!(lowest > 0.0, "motion {k} at {tau}: {c:?} at {lowest}");
        }
    }
}

/// The C-shape clamped on its bottom face, with a soft material.
fn clamped_c_shape() -> Model {
    let mesh = Arc::new(c_shape(SIZE, CELLS));
    let fixed: Vec<i64> = mesh
        .nodes_in_box([-1.0, -1.0, -1e-9], [1.0, 1.0, 1e-9])
        .iter()
        .map(|&i| i as i64)
        .collect();
    let m = mesh.n_tets();
    let mut model = Model::try_new(
        mesh,
        &fixed,
        Formulation::Standard,
        sorofem_core::material::Volumetric::Log,
    )
    .unwrap();
    let (mu, lambda) = lame_from_young(YOUNGS, 0.45);
    model
        .set_material(&Material {
            mu: vec![mu; m],
            lambda: vec![lambda; m],
            density: vec![DENSITY; m],
        })
        .unwrap();
    model
}

const YOUNGS: f64 = 30e3;
const DENSITY: f64 = 1080.0;

#[test]
fn an_arm_sags_onto_its_own_body() {
    let loads = Loads {
        gravity: [0.0, 0.0, -G],
        ..Default::default()
    };
    let options = SolveOptions::default();
    let lowest_upper = |model: &Model, positions: &[f64]| {
        let h = SIZE[0] / CELLS[0] as f64;
        (0..model.mesh().n_nodes())
            .filter(|&i| {
                let p = model.mesh().rest()[i];
                p[2] >= UPPER_BOTTOM - 1e-12 && p[0] > h + 1e-12
            })
            .map(|i| positions[3 * i + 2])
            .fold(f64::INFINITY, f64::min)
    };
    // Without self-contact the arm passes through the lower arm: the test is not vacuous.
    let mut free = clamped_c_shape();
    let t0 = Instant::now();
    let through = free.solve(&loads, None, &options).unwrap();
    let seconds_free = t0.elapsed().as_secs_f64();
    let sag = lowest_upper(&free, &through.positions);
    let displacements = |model: &Model, positions: &[f64]| -> Vec<f64> {
        let rest = model.mesh().rest_flat();
        positions.iter().zip(rest).map(|(x, r)| x - r).collect()
    };
    let audit = ContactTerm::try_new(
        free.mesh(),
        ContactSetup {
            self_contact: true,
            ..Default::default()
        },
    )
    .unwrap();
    assert!(sag < LOWER_TOP, "free arm's lowest point {sag}");
    assert!(audit.intersects(&displacements(&free, &through.positions)));

    let mut model = clamped_c_shape();
    model
        .set_contact(ContactSetup {
            self_contact: true,
            ..Default::default()
        })
        .unwrap();
    let t0 = Instant::now();
    let first = model.solve(&loads, None, &options).unwrap();
    let seconds = t0.elapsed().as_secs_f64();
    println!(
        "timings free {:?}\nwith self-contact {:?}",
        through.report.timings, first.report.timings
    );
    let first_analyses = model.symbolic_analyses();
    // Again from the rest shape with every accepted iterate checked for self-intersection in
    // full (the audit records -inf for one).
    model.set_contact_audit(true);
    let solution = model.solve(&loads, None, &options).unwrap();
    let contact = solution.contact.as_ref().unwrap();
    let resting = lowest_upper(&model, &solution.positions);
    println!(
        "free: lowest {sag:.4e} m in {} iterations; self-contact: lowest {resting:.4e} m in {} \
         iterations, {} active, min distance {:?}, dhat {:.3e}, {} symbolic analyses, \
         time ratio {:.2}",
        through.report.iterations,
        solution.report.iterations,
        contact.forces.self_active,
        contact.forces.self_min_distance,
        contact.dhat,
        first_analyses,
        seconds / seconds_free
    );
    // Resting on the lower arm (whose top sinks a little under the load), apart from it.
    assert!(resting > sag + 0.5 * (LOWER_TOP - sag) && resting < LOWER_TOP + contact.dhat);
    assert!(!audit.intersects(&displacements(&model, &solution.positions)));
    assert!(contact.forces.self_active > 0);
    let gap = contact.forces.self_min_distance.unwrap();
    assert!(gap > 0.0 && gap < contact.dhat);
    assert!(contact.iterate_min_distances.iter().all(|&d| d > 0.0));
    // Internal forces: zero total force and moment.
    let (mut force, mut moment) = (Vec3::zeros(), Vec3::zeros());
    let mut magnitude = 0.0;
    for (i, f) in contact.forces.nodal.iter().enumerate() {
        let f = Vec3::from(*f);
        let p = Vec3::new(
            solution.positions[3 * i],
            solution.positions[3 * i + 1],
            solution.positions[3 * i + 2],
        );
        force += f;
        moment += p.cross(&f);
        magnitude += f.norm();
    }
    let weight = DENSITY * model.mesh().volumes().iter().sum::<f64>() * G;
    let arm_weight = DENSITY * G * (UPPER_END - 0.025) * SIZE[1] * 0.02;
    assert!(
        magnitude > 0.1 * arm_weight,
        "contact force {magnitude} vs the arm's weight {arm_weight}"
    );
    assert!(
        force.norm() <= 1e-10 * magnitude,
        "total self-contact force {force:?}"
    );
    assert!(
        moment.norm() <= 1e-10 * magnitude * SIZE[0],
        "total self-contact moment {moment:?}"
    );
    // Supports + weight = 0: self-contact adds nothing to the balance.
    let mut balance = Vec3::new(0.0, 0.0, -weight);
    for r in &solution.reactions {
        balance += Vec3::from(*r);
    }
    assert!(balance.norm() <= 1e-8 * weight, "balance {balance:?}");
    // The grown pattern served the second solve: no new analysis.
    assert_eq!(model.symbolic_analyses(), first_analyses);
}

/// The candidates kept along a bounded direction give the barrier of a fresh broad phase at
/// every point of it (and off it the term runs the broad phase again): the upper arm moved
/// down from 3 dhat above the lower arm to 1 dhat through it, the contact forces compared at
/// points up to the step bound, where stencils are within dhat.
#[test]
fn candidates_kept_along_a_direction_give_the_barrier_of_a_fresh_broad_phase() {
    let mesh = c_shape(SIZE, CELLS);
    let dhat = 0.004;
    let term = ContactTerm::try_new(
        &mesh,
        ContactSetup {
            self_contact: true,
            dhat: Some(dhat),
            stiffness: Some(1e6),
            ..Default::default()
        },
    )
    .unwrap();
    let gap = UPPER_BOTTOM - LOWER_TOP;
    let rest = mesh.rest_flat();
    let minus =
        |a: &[f64], b: &[f64]| -> Vec<f64> { a.iter().zip(b).map(|(x, y)| x - y).collect() };
    let start = lowered(&mesh, gap - 3.0 * dhat);
    let z0 = minus(&start, &rest);
    let dz = minus(&lowered(&mesh, gap + dhat), &start);
    let alpha = term.max_step(&z0, &dz, DEFAULT_MIN_SEPARATION);
    assert!(alpha > 0.5 && alpha < 1.0, "step bound {alpha}");
    let fresh = term.clone(); // a clone keeps no candidates
    let at = |t: f64| -> Vec<f64> { z0.iter().zip(&dz).map(|(a, d)| a + t * d).collect() };
    let mut active = 0.0_f64;
    for t in [0.0, 0.25 * alpha, 0.5 * alpha, 0.99 * alpha] {
        let z = at(t);
        let kept = term.kept_candidates(&z);
        assert!(
            kept.is_some() && fresh.kept_candidates(&z).is_none(),
            "t = {t}"
        );
        let (g, reference) = (term.full_gradient(&z), fresh.full_gradient(&z));
        let scale = reference.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
        let error = g
            .iter()
            .zip(&reference)
            .fold(0.0_f64, |m, (a, b)| m.max((a - b).abs()));
        println!(
            "t = {t:.3}: {} kept candidates, |g| {scale:.3e} N, difference {error:.1e} N",
            kept.unwrap()
        );
        assert!(error <= 1e-12 * scale, "t = {t}: {error} against {scale}");
        active = active.max(scale);
    }
    assert!(active > 0.0, "no stencil within dhat along the direction");
    // Off the direction by 1e-6 dhat: not kept, and the same forces as a fresh pass.
    let mut off = at(0.5 * alpha);
    off[3 * mesh.n_nodes() - 1] += 1e-6 * dhat;
    assert!(term.kept_candidates(&off).is_none());
    assert_eq!(term.full_gradient(&off), fresh.full_gradient(&off));
}
