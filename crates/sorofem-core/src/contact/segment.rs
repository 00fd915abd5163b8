//! The barrier's candidates along one Newton direction, found once and kept for every
//! evaluation on it (the line search's trials and the next iteration's Hessian).
//!
//! For the segment `x(t) = x0 + t dx`, `t` in `[0, 1]`, a stencil's distance moves by at most
//! the motion of its two sides: `d(t) >= d(x0) - 2 m`, where `m` is the largest `|dx_v|` of its
//! vertices (a point of a triangle or an edge is a convex combination of its vertices, so it
//! moves no more than they do). The candidates whose swept boxes come within `dhat` and whose
//! bound reaches below `dhat` hold every stencil closer than `dhat` at any point of the
//! segment: the evaluations there test those few instead of running the broad phase and
//! testing the tens of thousands of neighbouring primitives a self-contact surface gives it.

use std::sync::Mutex;

use super::broad_phase::swept_candidates;
use super::collision_mesh::{Candidate, CollisionMesh};
use super::distance::Vec3;
use super::potential::candidate_squared_distance;
use rayon::prelude::*;

/// How far (as a fraction of `dhat`) positions may lie off the segment and still use its
/// candidates: well above the round-off between `x0 + t dx` and the iterate the solver formed,
/// and added to every bound.
const OFF_SEGMENT: f64 = 1e-9;

/// The candidates of one segment of positions (m).
#[derive(Debug)]
struct Segment {
    x0: Vec<Vec3>,
    dx: Vec<Vec3>,
    /// The vertex and axis of the largest motion, which gives an iterate's `t`.
    pivot: (usize, usize),
    found: Vec<Candidate>,
}

/// The candidates of the current Newton direction, when one was set (see
/// [`SegmentCache::set`]); cleared when the obstacles move. Cloning gives an empty cache.
#[derive(Debug, Default)]
pub(super) struct SegmentCache(Mutex<Option<Segment>>);

impl Clone for SegmentCache {
    fn clone(&self) -> Self {
        SegmentCache::default()
    }
}

impl SegmentCache {
    /// Finds and keeps the candidates of the segment from `x0` by `dx` (every collision vertex;
    /// obstacles' `dx` zero) within `dhat` (m).
    pub(super) fn set(&self, mesh: &CollisionMesh, x0: &[Vec3], dx: &[Vec3], dhat: f64) {
        let x1: Vec<Vec3> = x0.iter().zip(dx).map(|(a, b)| a + b).collect();
        let margin = OFF_SEGMENT * dhat;
        let found = swept_candidates(mesh, x0, &x1, dhat + 2.0 * margin)
            .into_par_iter()
            .filter(|c| {
                let (ids, n) = c.vertices();
                let (p, _) = c.positions(x0);
                let motion = ids[..n].iter().map(|&v| dx[v].norm()).fold(0.0, f64::max);
                let d0 = candidate_squared_distance(mesh, c, &p[..n]).sqrt();
                d0 - 2.0 * motion - 2.0 * margin < dhat
            })
            .collect();
        let pivot = dx
            .iter()
            .enumerate()
            .flat_map(|(v, d)| (0..3).map(move |k| ((v, k), d[k].abs())))
            .fold(((0, 0), 0.0), |best, c| if c.1 > best.1 { c } else { best })
            .0;
        *self.0.lock().expect("segment cache") = Some(Segment {
            x0: x0.to_vec(),
            dx: dx.to_vec(),
            pivot,
            found,
        });
    }

    pub(super) fn clear(&self) {
        *self.0.lock().expect("segment cache") = None;
    }

    /// The kept candidates when `x` lies on the kept segment (within [`OFF_SEGMENT`] `dhat`).
    pub(super) fn candidates_at(&self, x: &[Vec3], dhat: f64) -> Option<Vec<Candidate>> {
        let guard = self.0.lock().expect("segment cache");
        let segment = guard.as_ref()?;
        if segment.x0.len() != x.len() {
            return None;
        }
        let (v, k) = segment.pivot;
        let t = match segment.dx[v][k] {
            0.0 => 0.0,
            d => ((x[v][k] - segment.x0[v][k]) / d).clamp(0.0, 1.0),
        };
        let margin = OFF_SEGMENT * dhat;
        let near = |a: &Vec3, b: &Vec3| (a - b).amax() <= margin / 3.0;
        let on = x
            .par_iter()
            .zip(&segment.x0)
            .zip(&segment.dx)
            .all(|((x, x0), dx)| near(x, &(x0 + t * dx)));
        on.then(|| segment.found.clone())
    }
}
