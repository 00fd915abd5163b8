//! Times the phases of one static solve on a `.tet` mesh (developer tool, not a benchmark of
//! record: `make bench` writes BENCHMARKS.md).
//!
//! cargo run --release --example profile_static -- ../shared/data/solidfem/hammerbot_fine.tet 0.01
use sorofem_core::assembly::Assembler;
use sorofem_core::energy::{ElasticTerm, Formulation as ElementFormulation, HessianMode};
use sorofem_core::linear::{FactorKind, SparseFactor};
use sorofem_core::material::{neo_hookean::lame_from_young, Volumetric};
use sorofem_core::{Formulation, Loads, Material, Model, Orientation, SolveOptions, TetMesh};
use std::sync::Arc;
use std::time::Instant;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let path = args
        .get(1)
        .expect("usage: profile_static FILE.tet SCALE [mixed]");
    let scale: f64 = args.get(2).map_or(1.0, |s| s.parse().unwrap());
    let mixed = args.get(3).is_some_and(|s| s == "mixed");
    let text = std::fs::read_to_string(path).unwrap();
    let mut points = Vec::new();
    let mut tets = Vec::new();
    for line in text.lines() {
        let f: Vec<&str> = line.split_whitespace().collect();
        match f.first() {
            Some(&"v") => points.push([0, 1, 2].map(|k| f[k + 1].parse::<f64>().unwrap() * scale)),
            Some(&"t") => tets.push([0, 1, 2, 3].map(|k| f[k + 1].parse::<i64>().unwrap())),
            _ => {}
        }
    }
    let t = Instant::now();
    let (mesh, _) = TetMesh::try_new(points, &tets, Orientation::Reorient).unwrap();
    println!("mesh build {:.4} s", t.elapsed().as_secs_f64());
    let mesh = Arc::new(mesh);
    let xmin = mesh
        .rest()
        .iter()
        .map(|p| p[0])
        .fold(f64::INFINITY, f64::min);
    let fixed: Vec<i64> = mesh
        .nodes_in_box([xmin - 1e-9, -1e9, -1e9], [xmin + 1e-9, 1e9, 1e9])
        .iter()
        .map(|&i| i as i64)
        .collect();
    let m = mesh.n_tets();
    // Hammerbot defaults; PROFILE_E / PROFILE_NU / PROFILE_RHO / PROFILE_GRAVITY_AXIS override.
    let env = |name: &str, default: f64| {
        std::env::var(name).map_or(default, |v| v.parse::<f64>().expect(name))
    };
    let (mu, lambda) = lame_from_young(
        env("PROFILE_E", 100e3),
        env("PROFILE_NU", if mixed { 0.4999 } else { 0.4 }),
    );
    let mut gravity = [0.0; 3];
    gravity[env("PROFILE_GRAVITY_AXIS", 1.0) as usize] = -env("PROFILE_G", 9.8);
    let formulation = if mixed {
        Formulation::Mixed {
            mass: sorofem_core::PressureMass::Consistent,
        }
    } else {
        Formulation::Standard
    };
    // PROFILE_BUILDS=N builds the model N extra times first (for profiling the build).
    for _ in 0..env("PROFILE_BUILDS", 0.0) as usize {
        let t = Instant::now();
        Model::try_new(mesh.clone(), &fixed, formulation.clone(), Volumetric::Log).unwrap();
        println!("model build {:.4} s", t.elapsed().as_secs_f64());
    }
    let t = Instant::now();
    let mut model = Model::try_new(mesh.clone(), &fixed, formulation, Volumetric::Log).unwrap();
    println!(
        "nodes {} tets {} fixed {} free {}; model build {:.4} s",
        mesh.n_nodes(),
        m,
        fixed.len(),
        model.n_free(),
        t.elapsed().as_secs_f64()
    );
    // PROFILE_GENERAL=1: the element kernels' general path instead of the Neo-Hookean closed
    // forms (what models without closed forms cost).
    let general = std::env::var_os("PROFILE_GENERAL").is_some();
    model.set_closed_forms(!general);
    model
        .set_material(&Material {
            mu: vec![mu; m],
            lambda: vec![lambda; m],
            density: vec![env("PROFILE_RHO", 1070.0); m],
        })
        .unwrap();
    let mut deformed = vec![0.0; 3 * mesh.n_nodes()];
    let solves = env("PROFILE_SOLVES", 3.0) as usize;
    for _ in 0..solves {
        let t = Instant::now();
        let s = model
            .solve(
                &Loads {
                    gravity,
                    ..Default::default()
                },
                None,
                &SolveOptions {
                    load_steps: env("PROFILE_LOAD_STEPS", 1.0) as usize,
                    ..Default::default()
                },
            )
            .unwrap();
        let r = &s.report;
        for (d, (x, x0)) in deformed
            .iter_mut()
            .zip(s.positions.iter().zip(mesh.rest().iter().flatten()))
        {
            *d = x - x0;
        }
        println!(
            "solve {:.4} s, {} iterations; assembly {:.4} factorization {:.4} solve {:.4} line search {:.4}",
            t.elapsed().as_secs_f64(), r.iterations, r.timings.assembly, r.timings.factorization, r.timings.solve, r.timings.line_search
        );
        if std::env::var_os("SOROFEM_HISTORY").is_some() {
            println!("  projected steps {}", r.projected_steps);
            for (k, res) in r.residual_history.iter().enumerate() {
                let step = r.step_lengths.get(k).copied().unwrap_or(f64::NAN);
                println!("  {k:3} residual {res:.3e} step {step:.4}");
            }
        }
    }
    // The bare factorisation the benchmark measures an iteration against (median of five).
    let mut bare = model.time_factorization(5).unwrap();
    bare.sort_by(f64::total_cmp);
    println!("bare factorization {:.4} ms", bare[2] * 1e3);
    if std::env::var_os("PROFILE_SOLVES_ONLY").is_some() {
        return;
    }
    // Isolated kernels.
    let n = mesh.n_nodes();
    let mut term = ElasticTerm::neo_hookean(
        mesh.clone(),
        &vec![mu; m],
        &vec![lambda; m],
        Volumetric::Log,
        ElementFormulation::Standard,
    );
    term.closed_forms = !general;
    let mut fixed_dofs = vec![false; 3 * n];
    for &i in &fixed {
        fixed_dofs[3 * i as usize..3 * i as usize + 3].fill(true);
    }
    let t = Instant::now();
    let assembler = Assembler::new(&fixed_dofs, &[&term]);
    println!(
        "assembler build {:.4} s, nnz(lower) {}",
        t.elapsed().as_secs_f64(),
        assembler.pattern().nnz()
    );
    let z = vec![0.0; 3 * n];
    let reps = 20;
    let t = Instant::now();
    for _ in 0..reps {
        std::hint::black_box(assembler.energy(&[&term], &z));
    }
    println!(
        "energy      {:.3} ms",
        t.elapsed().as_secs_f64() * 1e3 / reps as f64
    );
    let t = Instant::now();
    for _ in 0..reps {
        std::hint::black_box(assembler.evaluate(&[&term], &z, true, None));
    }
    println!(
        "gradient    {:.3} ms",
        t.elapsed().as_secs_f64() * 1e3 / reps as f64
    );
    let t = Instant::now();
    let mut h = Vec::new();
    for _ in 0..reps {
        h = assembler
            .evaluate(&[&term], &z, true, Some(HessianMode::Exact))
            .hessian;
    }
    println!(
        "hessian     {:.3} ms",
        t.elapsed().as_secs_f64() * 1e3 / reps as f64
    );
    let t = Instant::now();
    for _ in 0..reps {
        std::hint::black_box(assembler.evaluate(
            &[&term],
            &deformed,
            true,
            Some(HessianMode::Exact),
        ));
    }
    println!(
        "hessian at the solution {:.3} ms",
        t.elapsed().as_secs_f64() * 1e3 / reps as f64
    );
    let t = Instant::now();
    let mut factor = SparseFactor::analyse(assembler.pattern(), FactorKind::Llt).unwrap();
    println!(
        "analyse     {:.3} ms, factor nnz {}",
        t.elapsed().as_secs_f64() * 1e3,
        factor.factor_nnz()
    );
    let t = Instant::now();
    for _ in 0..reps {
        assert!(factor.factor(assembler.pattern(), &h).unwrap());
    }
    println!(
        "llt         {:.3} ms",
        t.elapsed().as_secs_f64() * 1e3 / reps as f64
    );
    let (mut t_h, mut t_f) = (0.0, 0.0);
    for _ in 0..reps {
        let t = Instant::now();
        let e = assembler.evaluate(&[&term], &deformed, true, Some(HessianMode::Exact));
        t_h += t.elapsed().as_secs_f64();
        let t = Instant::now();
        assert!(factor.factor(assembler.pattern(), &e.hessian).unwrap());
        t_f += t.elapsed().as_secs_f64();
    }
    println!(
        "alternating: hessian {:.3} ms, llt {:.3} ms",
        t_h * 1e3 / reps as f64,
        t_f * 1e3 / reps as f64
    );
    let mut rhs = vec![1.0; assembler.n_free()];
    let t = Instant::now();
    for _ in 0..reps {
        factor.solve_in_place(&mut rhs);
    }
    println!(
        "solve       {:.3} ms",
        t.elapsed().as_secs_f64() * 1e3 / reps as f64
    );
}
