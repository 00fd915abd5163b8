//! Cost of the contact pass (broad phase + barrier assembly with projected stencil Hessians) and
//! of the CCD step bound, single-threaded, on the ~2k-triangle surface of a 10k-tet block:
//! against a plane, and in self-contact (two blocks of one body 0.5 mm apart), beside a Newton
//! iteration of the same 10k-tet block without contact. CPU times of the one thread; prints,
//! asserts nothing about time.
//! Run with `cargo test --release -p sorofem-core --test contact_bench -- --ignored --nocapture`.
mod common;

use common::Rng;
use sorofem_core::contact::broad_phase::{candidates, swept_candidates};
use sorofem_core::contact::ccd::{max_step, DEFAULT_MIN_SEPARATION};
use sorofem_core::contact::{BarrierPotential, CollisionMesh, Obstacle, Plane, Vec3};
use sorofem_core::energy::HessianMode;
use sorofem_core::{Formulation, TetMesh};
use std::time::Instant;

/// CPU time of the calling thread (ms) from Linux's schedstat (time on the CPU, not waiting for
/// it: the machine is shared), or wall time where that is unavailable.
fn cpu_ms(start: &Instant) -> f64 {
    std::fs::read_to_string("/proc/thread-self/schedstat")
        .ok()
        .and_then(|s| s.split_whitespace().next()?.parse::<f64>().ok())
        .map_or_else(|| start.elapsed().as_secs_f64() * 1e3, |ns| ns * 1e-6)
}

/// Mean CPU time (ms) per call over at least 0.3 s of CPU (schedstat advances by scheduler
/// ticks, so single calls cannot be timed).
fn mean_ms(mut f: impl FnMut()) -> f64 {
    let clock = Instant::now();
    let start = cpu_ms(&clock);
    let mut calls = 0;
    while cpu_ms(&clock) - start < 300.0 || calls < 3 {
        f();
        calls += 1;
    }
    (cpu_ms(&clock) - start) / calls as f64
}

fn contact_pass(label: &str, collision: &CollisionMesh, body: &[f64], dhat: f64) {
    let x = collision.vertices(body).unwrap();
    let potential = BarrierPotential::try_new(dhat, 1e6).unwrap();
    let found = candidates(collision, &x, dhat);
    let assembled = potential.assemble(collision, &found, &x, Some(HessianMode::Projected));
    let active = assembled.hessians.len();
    let broad = mean_ms(|| {
        std::hint::black_box(candidates(collision, &x, dhat));
    });
    let assembly = mean_ms(|| {
        std::hint::black_box(potential.assemble(
            collision,
            &found,
            &x,
            Some(HessianMode::Projected),
        ));
    });
    let pass = mean_ms(|| {
        let found = candidates(collision, &x, dhat);
        std::hint::black_box(potential.assemble(
            collision,
            &found,
            &x,
            Some(HessianMode::Projected),
        ));
    });
    // A CCD bound for a step moving every body vertex by up to 2 dhat.
    let mut rng = Rng::new(1);
    let dx: Vec<Vec3> = (0..x.len())
        .map(|v| {
            if collision.is_obstacle_vertex(v) {
                Vec3::zeros()
            } else {
                Vec3::new(rng.next(), rng.next(), rng.next() - 0.5) * dhat
            }
        })
        .collect();
    let x1: Vec<Vec3> = x.iter().zip(&dx).map(|(a, b)| a + b).collect();
    let ccd = mean_ms(|| {
        let swept = swept_candidates(collision, &x, &x1, 0.0);
        std::hint::black_box(max_step(collision, &swept, &x, &dx, DEFAULT_MIN_SEPARATION));
    });
    println!(
        "{label}: {} surface triangles, {} candidates, {} active stencils; broad phase {broad:.2} ms, \
         barrier assembly {assembly:.2} ms, contact pass {pass:.2} ms, CCD step bound {ccd:.2} ms",
        collision.body_faces().len(),
        found.len(),
        active
    );
}

#[test]
#[ignore = "timing report; run explicitly"]
fn contact_pass_cost() {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    pool.install(|| {
        // The 10k-tet block (24 x 12 x 6 cells of 10 mm, 2016 surface triangles), 0.5 mm above a
        // plane with dhat = 1 mm: its 325 bottom nodes are in contact.
        let mesh = TetMesh::box_mesh([0.24, 0.12, 0.06], [24, 12, 6], [0.0, 0.0, 0.0005]).unwrap();
        let plane = Obstacle::Plane(Plane::try_new([0.0; 3], [0.0, 0.0, 1.0]).unwrap());
        let collision = CollisionMesh::from_tet_mesh(&mesh, vec![plane], false);
        contact_pass("block on a plane", &collision, &mesh.rest_flat(), 1e-3);
        let collision = CollisionMesh::from_tet_mesh(&mesh, vec![], true);
        contact_pass("same block, self-contact only (no pair within dhat)", &collision, &mesh.rest_flat(), 1e-3);

        // Self-contact: one body made of two 17 x 9 x 4 blocks (1028 triangles each), the upper
        // one 0.5 mm above the lower and shifted by half a cell.
        let lower = TetMesh::box_mesh([0.17, 0.09, 0.04], [17, 9, 4], [0.0; 3]).unwrap();
        let upper = TetMesh::box_mesh([0.17, 0.09, 0.04], [17, 9, 4], [0.005, 0.005, 0.0405]).unwrap();
        let n = lower.n_nodes();
        let mut rest: Vec<[f64; 3]> = lower.rest().to_vec();
        rest.extend_from_slice(upper.rest());
        let mut faces = lower.boundary_faces();
        faces.extend(upper.boundary_faces().iter().map(|f| f.map(|i| i + n)));
        let collision = CollisionMesh::try_new(&rest, &faces, vec![], true).unwrap();
        contact_pass("two blocks of one body, self-contact", &collision, rest.as_flattened(), 1e-3);

        // One Newton iteration of the same 10k-tet block without contact (clamped, gravity).
        let mut model = common::cantilever([0.24, 0.12, 0.06], [24, 12, 6], 1e6, 0.45, 1100.0, Formulation::Standard);
        let clock = Instant::now();
        let start = cpu_ms(&clock);
        let solution = common::solve_gravity(&mut model, [0.0, 0.0, -9.81]);
        let total = cpu_ms(&clock) - start;
        println!(
            "Newton without contact, 10k tets: {} iterations, {:.2} ms per iteration (solve {total:.1} ms)",
            solution.report.iterations,
            total / solution.report.iterations as f64
        );
    });
}
