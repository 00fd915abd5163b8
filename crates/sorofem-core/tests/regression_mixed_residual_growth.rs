//! Regression: the mixed formulation's non-monotone line search let the residual grow
//! window after window (each step may raise the squared residual 100-fold over the last five
//! iterates), so that the 1 m cantilever on the uniform Kuhn split, in 10 load steps, drove its
//! first load step's residual up 1e5-fold, failed after 50 iterations, cut back and needed 150
//! in all. The growth is now capped at 100 times the load step's starting residual.
mod common;

use common::clamped_at_x0;
use sorofem_core::{Formulation, Loads, Orientation, PressureMass, SolveOptions, TetMesh};
use std::sync::Arc;

/// A box of hexahedra each split into the six tets around its main diagonal, the same in every
/// hex (the locking study's uniform split), on the node grid of [`TetMesh::box_mesh`] (node
/// (i, j, k) is `i + (nx+1) (j + (ny+1) k)`), whose split is mirrored from hex to hex instead.
fn kuhn_box(size: [f64; 3], cells: [usize; 3]) -> TetMesh {
    let [nx, ny, nz] = cells;
    let grid = TetMesh::box_mesh(size, cells, [0.0; 3]).unwrap();
    let index = |c: [usize; 3]| (c[0] + (nx + 1) * (c[1] + (ny + 1) * c[2])) as i64;
    let orders = [
        [0, 1, 2],
        [0, 2, 1],
        [1, 0, 2],
        [1, 2, 0],
        [2, 0, 1],
        [2, 1, 0],
    ];
    let mut tets = Vec::new();
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                for order in orders {
                    let mut corner = [i, j, k];
                    let mut tet = [index(corner); 4];
                    for (slot, axis) in order.into_iter().enumerate() {
                        corner[axis] += 1;
                        tet[slot + 1] = index(corner);
                    }
                    tets.push(tet);
                }
            }
        }
    }
    TetMesh::try_new(grid.rest().to_vec(), &tets, Orientation::Reorient)
        .unwrap()
        .0
}

#[test]
fn mixed_residual_growth_is_capped_within_a_load_step() {
    let mesh = Arc::new(kuhn_box([1.0, 0.1, 0.1], [20, 2, 2]));
    let mut model = clamped_at_x0(
        mesh,
        66e3,
        0.45,
        1080.0,
        Formulation::Mixed {
            mass: PressureMass::Consistent,
        },
    );
    let loads = Loads {
        gravity: [0.0, 0.0, -9.81],
        ..Default::default()
    };
    let options = SolveOptions {
        load_steps: 10,
        ..Default::default()
    };
    let report = model.solve(&loads, None, &options).unwrap().report;
    eprintln!(
        "{} iterations, {} cut-backs, {} load steps",
        report.iterations, report.cutbacks, report.load_steps
    );
    assert_eq!(report.cutbacks, 0);
    assert_eq!(report.load_steps, 10);
    assert!(report.iterations <= 80, "{} iterations", report.iterations);
}
