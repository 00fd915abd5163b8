//! Contact as a term of a model: IPC's barrier over the candidate stencils of the current
//! positions plus lagged friction, evaluated at a full DOF vector `z` (node displacements from
//! the rest shape, m, node-major) and added into the free DOFs of an [`Assembler`].
//!
//! Every stencil of body-obstacle contact couples the DOFs of one boundary triangle at most (a
//! body vertex against an obstacle triangle, plane or sphere; an obstacle vertex against a body
//! triangle; a body edge against an obstacle edge), and the elastic term couples those already:
//! the assembler's fixed pattern holds every entry of a contact Hessian, so contact needs no new
//! symbolic factorisation. Self-contact (body vertex - body triangle, body edge - body edge,
//! never two primitives sharing a vertex) couples surface points far apart in the mesh: before
//! a Hessian is assembled, the model adds the couplings of the self-contact candidates within
//! [`ContactTerm::self_coupling_reach`] (wider than `dhat`, so that the pattern grows once or
//! twice per solve, not per new contact) and analyses again only when the pattern grew.

use super::broad_phase::{candidates, swept_candidates};
use super::ccd::{
    candidate_toi, max_step, point_plane_toi, point_sphere_toi, sphere_edge_toi,
    sphere_triangle_toi,
};
use super::check::{check_no_intersection, minimum_distance};
use super::collision_mesh::{Candidate, CollisionMesh};
use super::distance::Vec3;
use super::friction::{lag_friction, FrictionStencil};
use super::obstacle::Obstacle;
use super::potential::{candidate_squared_distance, BarrierPotential};
use super::segment::SegmentCache;
use super::stencil::{FreeScatter, Stencil};
use crate::assembly::Assembler;
use crate::energy::HessianMode;
use crate::error::{check_finite, Error, Result};
use crate::mesh::TetMesh;
use rayon::prelude::*;

mod stiffness;

pub use stiffness::{free_values, UnitBarrier};

/// The default activation distance `dhat` as a fraction of the mean boundary edge length.
pub const DHAT_PER_EDGE: f64 = 1e-2;
/// The default friction slip `eps_u` of static solves (m) as a fraction of `dhat`: the tangential
/// displacement over a load step below which friction is the stiff (sticking) branch.
pub const SLIP_PER_DHAT: f64 = 0.1;
/// IPC's default friction velocity `eps_v` (m/s) of dynamics: `eps_u = eps_v dt`.
pub const DEFAULT_FRICTION_VELOCITY: f64 = 1e-3;
/// The adaptive barrier stiffness stays within `[kappa_ref, MAX_STIFFNESS_RATIO kappa_ref]`
/// (IPC's range is 100-fold).
pub const MAX_STIFFNESS_RATIO: f64 = 100.0;
/// IPC's threshold of the stiffness update, relative to the scene's bounding-box diagonal.
const STIFFNESS_UPDATE_SCALE: f64 = 1e-9;

/// An obstacle of a model: its geometry (at time 0), the Coulomb friction coefficient between
/// it and the body, and the path it follows in dynamics.
#[derive(Clone, Debug)]
pub struct ObstacleSpec {
    pub obstacle: Obstacle,
    /// Friction coefficient `mu >= 0` (0: frictionless).
    pub friction: f64,
    /// Keyframes `(time s, translation m)` of a prescribed rigid translation, piecewise linear,
    /// held before the first and after the last; empty: the obstacle stays where it is.
    pub path: Vec<(f64, [f64; 3])>,
}

/// What a model's contact is made of, as [`crate::Model::set_contact`] takes it.
#[derive(Clone, Debug)]
pub struct ContactSetup {
    pub obstacles: Vec<ObstacleSpec>,
    /// Activation distance (m); default [`DHAT_PER_EDGE`] times the mean boundary edge length.
    pub dhat: Option<f64>,
    /// Reference barrier stiffness `kappa_ref` (J/m^4); default
    /// [`ContactTerm::default_stiffness`] from the material at the first solve.
    pub stiffness: Option<f64>,
    /// Static solves' friction slip `eps_u` (m); default [`SLIP_PER_DHAT`] `dhat`.
    pub friction_slip: Option<f64>,
    /// Dynamics' friction velocity `eps_v` (m/s); default [`DEFAULT_FRICTION_VELOCITY`].
    pub friction_velocity: Option<f64>,
    /// Whether the body's boundary surface may touch itself (frictionless self-contact).
    pub self_contact: bool,
    /// Whether the barrier stiffness adapts (IPC: balanced at each solve's or step's start,
    /// doubled while gaps keep shrinking, within `[kappa_ref, MAX_STIFFNESS_RATIO kappa_ref]`)
    /// or stays at `kappa_ref`. A fixed stiffness makes every solve a smooth function of the
    /// parameters and of the start state, so that trajectory derivatives through contact are
    /// exact; the adaptive one converges more robustly where gaps close fast.
    pub adaptive_stiffness: bool,
}

impl Default for ContactSetup {
    /// No obstacle, no self-contact, the defaults of every setting, an adaptive stiffness.
    fn default() -> Self {
        ContactSetup {
            obstacles: Vec::new(),
            dhat: None,
            stiffness: None,
            friction_slip: None,
            friction_velocity: None,
            self_contact: false,
            adaptive_stiffness: true,
        }
    }
}

/// The result of one contact pass: energy (J; `+inf` when a stencil touches) and the smallest
/// squared distance (m^2) over the stencils within `dhat` (`+inf` without any).
#[derive(Clone, Copy, Debug)]
pub struct ContactPass {
    pub energy: f64,
    pub min_squared_distance: f64,
    /// Fingerprint of the active stencils (barrier within `dhat`, lagged friction): unchanged,
    /// a factorisation kept from an earlier pass covers the same contacts.
    pub active_set: u64,
}

/// Contact forces at one state. Forces are those the obstacles exert on the body, `-grad` of the
/// barrier and friction potentials (N).
#[derive(Clone, Debug, Default)]
pub struct ContactForces {
    /// Per body node (`n_nodes`).
    pub nodal: Vec<[f64; 3]>,
    /// Total per obstacle.
    pub per_obstacle: Vec<[f64; 3]>,
    /// Smallest distance (m) to each obstacle over the stencils within the report radius
    /// ([`ContactTerm::report_radius`]); `None` when nothing of the body is that close.
    pub min_distance: Vec<Option<f64>>,
    /// Stencils closer than `dhat` per obstacle.
    pub active: Vec<usize>,
    /// Self-contact: the stencils closer than `dhat`, and the smallest distance (m) between
    /// non-adjacent surface primitives within the report radius (`None`: none that close, or
    /// no self-contact). Its forces are in `nodal` and sum to zero (internal forces).
    pub self_active: usize,
    pub self_min_distance: Option<f64>,
}

/// Contact of a body with its obstacles, as a term of its model.
#[derive(Clone, Debug)]
pub struct ContactTerm {
    /// Obstacles at zero translation, and where they are now.
    rest: CollisionMesh,
    mesh: CollisionMesh,
    friction: Vec<f64>,
    paths: Vec<Vec<(f64, Vec3)>>,
    translations: Vec<Vec3>,
    rest_nodes: Vec<f64>,
    dhat: f64,
    /// The barrier stiffness of the current solve (J/m^4), and the one solves start from.
    stiffness: f64,
    reference_stiffness: Option<f64>,
    /// See [`ContactTerm::balanced_stiffness`].
    balanced_stiffness: Option<f64>,
    /// See [`ContactSetup::adaptive_stiffness`].
    adaptive_stiffness: bool,
    friction_slip: f64,
    friction_velocity: f64,
    /// The lagged friction stencils of the current step, and their slip `eps_u` (m).
    friction_stencils: Vec<FrictionStencil>,
    lagged_slip: f64,
    bbox_diagonal: f64,
    mean_edge: f64,
    /// Check every accepted iterate for intersections in full (see [`ContactTerm::set_audit`]).
    audit: bool,
    /// The barrier's candidates along the last direction [`ContactTerm::max_step`] bounded.
    segment: SegmentCache,
}

impl ContactTerm {
    /// Contact of the body `mesh` with `setup`'s obstacles, and with itself when
    /// `setup.self_contact`. Checks every value and that nothing touches the body at rest (the
    /// error names the obstacle, the node or triangle, and the distance).
    pub fn try_new(mesh: &TetMesh, setup: ContactSetup) -> Result<Self> {
        let mut geometry = Vec::with_capacity(setup.obstacles.len());
        let mut friction = Vec::new();
        let mut paths = Vec::new();
        for (k, spec) in setup.obstacles.into_iter().enumerate() {
            if !(spec.friction.is_finite() && spec.friction >= 0.0) {
                return Err(Error::invalid(
                    &format!("obstacles[{k}].friction"),
                    "a finite friction coefficient >= 0",
                    spec.friction,
                ));
            }
            let mut path = Vec::with_capacity(spec.path.len());
            for (i, &(t, translation)) in spec.path.iter().enumerate() {
                check_finite(&format!("obstacles[{k}].path"), &[t])?;
                check_finite(&format!("obstacles[{k}].path"), &translation)?;
                if i > 0 && t < spec.path[i - 1].0 {
                    return Err(Error::invalid(
                        &format!("obstacles[{k}].path"),
                        "keyframe times that do not decrease",
                        format!("{t} s after {} s", spec.path[i - 1].0),
                    ));
                }
                path.push((t, Vec3::from(translation)));
            }
            geometry.push(spec.obstacle);
            friction.push(spec.friction);
            paths.push(path);
        }
        let rest = CollisionMesh::from_tet_mesh(mesh, geometry, setup.self_contact);
        let edges = rest.body_edges();
        let mean_edge = edges
            .iter()
            .map(|e| (rest.rest()[e[0]] - rest.rest()[e[1]]).norm())
            .sum::<f64>()
            / edges.len().max(1) as f64;
        let dhat = match setup.dhat {
            Some(dhat) if !(dhat.is_finite() && dhat > 0.0) => {
                return Err(Error::invalid("dhat", "a finite distance > 0 (m)", dhat))
            }
            Some(dhat) => dhat,
            None => DHAT_PER_EDGE * mean_edge,
        };
        let positive = |name: &str, value: Option<f64>, units: &str| -> Result<Option<f64>> {
            match value {
                Some(v) if !(v.is_finite() && v > 0.0) => Err(Error::invalid(
                    name,
                    format!("a finite value > 0 ({units})"),
                    v,
                )),
                other => Ok(other),
            }
        };
        let reference_stiffness = positive("contact stiffness", setup.stiffness, "J/m^4")?;
        let friction_slip =
            positive("friction_slip", setup.friction_slip, "m")?.unwrap_or(SLIP_PER_DHAT * dhat);
        let friction_velocity = positive("friction_velocity", setup.friction_velocity, "m/s")?
            .unwrap_or(DEFAULT_FRICTION_VELOCITY);
        let n = mesh.n_nodes();
        let translations = vec![Vec3::zeros(); paths.len()];
        let mut term = ContactTerm {
            mesh: rest.clone(),
            rest,
            friction,
            paths,
            translations,
            rest_nodes: mesh.rest_flat(),
            dhat,
            stiffness: reference_stiffness.unwrap_or(1.0),
            reference_stiffness,
            balanced_stiffness: None,
            adaptive_stiffness: setup.adaptive_stiffness,
            friction_slip,
            friction_velocity,
            friction_stencils: Vec::new(),
            lagged_slip: friction_slip,
            bbox_diagonal: 0.0,
            mean_edge,
            audit: false,
            segment: SegmentCache::default(),
        };
        term.set_time(0.0);
        term.bbox_diagonal = term.scene_diagonal();
        check_no_intersection(&term.mesh, &term.positions(&vec![0.0; 3 * n]))?;
        Ok(term)
    }

    pub fn dhat(&self) -> f64 {
        self.dhat
    }

    pub fn self_contact(&self) -> bool {
        self.mesh.self_contact()
    }

    pub fn n_obstacles(&self) -> usize {
        self.friction.len()
    }

    /// The geometry at the current obstacle positions.
    pub fn collision_mesh(&self) -> &CollisionMesh {
        &self.mesh
    }

    /// Mean length of the body's boundary edges at rest (m).
    pub fn mean_edge(&self) -> f64 {
        self.mean_edge
    }

    /// A diagnostic for tests: solves check every accepted iterate for intersections with
    /// [`super::check::find_intersection`] (every body node, edge and triangle, not only the
    /// stencils within `dhat`) and record one as a minimum distance of `-inf`.
    pub fn set_audit(&mut self, on: bool) {
        self.audit = on;
    }

    pub fn audit(&self) -> bool {
        self.audit
    }

    /// Whether the body at `z` touches or intersects an obstacle (the audit's test).
    pub fn intersects(&self, z: &[f64]) -> bool {
        super::check::find_intersection(&self.mesh, &self.positions(z)).is_some()
    }

    /// Whether any obstacle has friction.
    pub fn has_friction(&self) -> bool {
        self.friction.iter().any(|&mu| mu > 0.0)
    }

    pub fn friction_slip(&self) -> f64 {
        self.friction_slip
    }

    pub fn friction_velocity(&self) -> f64 {
        self.friction_velocity
    }

    /// Whether an obstacle moves.
    pub fn has_moving_obstacles(&self) -> bool {
        self.paths.iter().any(|p| p.len() > 1)
    }

    /// Moves every obstacle to where its path puts it at time `t` (s).
    pub fn set_time(&mut self, t: f64) {
        self.translations = (0..self.paths.len())
            .map(|k| self.translation_at(k, t))
            .collect();
        self.mesh = self.rest.moved(&self.translations);
        self.segment.clear();
    }

    /// Obstacle `k`'s translation (m) at time `t` (s).
    pub fn translation_at(&self, k: usize, t: f64) -> Vec3 {
        let path = &self.paths[k];
        match path.iter().position(|&(time, _)| time > t) {
            None => path.last().map_or(Vec3::zeros(), |p| p.1),
            Some(0) => path[0].1,
            Some(i) => {
                let ((t0, a), (t1, b)) = (path[i - 1], path[i]);
                a + (b - a) * ((t - t0) / (t1 - t0))
            }
        }
    }

    /// Positions (m) of every collision vertex at the full DOF vector `z` (its first `3 n`
    /// entries): the body nodes, then the obstacles' vertices where they are now.
    pub fn positions(&self, z: &[f64]) -> Vec<Vec3> {
        let body: Vec<f64> = self
            .rest_nodes
            .iter()
            .zip(z)
            .map(|(rest, u)| rest + u)
            .collect();
        self.mesh.vertices(&body).expect("z holds every node")
    }

    fn barrier(&self) -> BarrierPotential {
        BarrierPotential::try_new(self.dhat, self.stiffness).expect("validated dhat and stiffness")
    }

    /// The obstacle a stencil belongs to (`None` for self-contact).
    pub fn obstacle_of(&self, candidate: &Candidate) -> Option<usize> {
        match *candidate {
            Candidate::PointPlane { obstacle, .. }
            | Candidate::PointSphere { obstacle, .. }
            | Candidate::TriangleSphere { obstacle, .. }
            | Candidate::EdgeSphere { obstacle, .. } => Some(obstacle),
            Candidate::PointTriangle { .. } | Candidate::EdgeEdge { .. } => {
                let (ids, n) = candidate.vertices();
                ids[..n]
                    .iter()
                    .find_map(|&v| self.mesh.obstacle_of_vertex(v))
            }
        }
    }

    /// The barrier stencils within `dhat` at positions `x`, with their Hessians when asked.
    /// `None` when a stencil touches or intersects.
    fn barrier_stencils(&self, x: &[Vec3], hessian: Option<HessianMode>) -> Option<Vec<Stencil>> {
        let found = (self.segment.candidates_at(x, self.dhat))
            .unwrap_or_else(|| candidates(&self.mesh, x, self.dhat));
        let potential = self.barrier();
        let dhat2 = self.dhat * self.dhat;
        let stencils: Vec<Stencil> = found
            .par_iter()
            .filter_map(|c| {
                let (p, n) = c.positions(x);
                if candidate_squared_distance(&self.mesh, c, &p[..n]) >= dhat2 {
                    return None;
                }
                let mut stencil = Stencil {
                    candidate: *c,
                    energy: 0.0,
                    gradient: [0.0; 12],
                    hessian: vec![0.0; if hessian.is_some() { 9 * n * n } else { 0 }],
                };
                stencil.energy = potential.stencil_energy(
                    &self.mesh,
                    c,
                    &p[..n],
                    Some(&mut stencil.gradient[..3 * n]),
                    hessian.map(|_| &mut stencil.hessian[..]),
                    hessian.unwrap_or(HessianMode::Exact),
                );
                Some(stencil)
            })
            .collect();
        stencils
            .iter()
            .all(|s| s.energy.is_finite())
            .then_some(stencils)
    }

    /// The lagged friction stencils at positions `x`.
    fn friction_stencils(&self, x: &[Vec3], hessian: Option<HessianMode>) -> Vec<Stencil> {
        self.friction_stencils
            .par_iter()
            .map(|f| {
                let (p, n) = f.candidate.positions(x);
                let mut stencil = Stencil {
                    candidate: f.candidate,
                    energy: 0.0,
                    gradient: [0.0; 12],
                    hessian: vec![0.0; if hessian.is_some() { 9 * n * n } else { 0 }],
                };
                stencil.energy = f.energy(
                    &p[..n],
                    self.lagged_slip,
                    Some(&mut stencil.gradient[..3 * n]),
                    hessian.map(|_| &mut stencil.hessian[..]),
                    hessian.unwrap_or(HessianMode::Exact),
                );
                stencil
            })
            .collect()
    }

    /// Adds the contact energy's gradient (into `gradient`, free DOFs, when it is not empty) and
    /// Hessian (into `hessian`'s values in the assembler's pattern, with the stencils' exact or
    /// projected Hessians) at the full DOF vector `z`.
    pub fn add_to(
        &self,
        assembler: &Assembler,
        z: &[f64],
        gradient: &mut [f64],
        hessian: Option<(&mut [f64], HessianMode)>,
    ) -> ContactPass {
        let x = self.positions(z);
        let mode = hessian.as_ref().map(|(_, mode)| *mode);
        let Some(barrier) = self.barrier_stencils(&x, mode) else {
            return ContactPass {
                energy: f64::INFINITY,
                min_squared_distance: 0.0,
                active_set: 0,
            };
        };
        let friction = self.friction_stencils(&x, mode);
        let min_squared_distance = barrier
            .iter()
            .map(|s| {
                let (p, n) = s.candidate.positions(&x);
                candidate_squared_distance(&self.mesh, &s.candidate, &p[..n])
            })
            .fold(f64::INFINITY, f64::min);
        let scatter = FreeScatter {
            assembler,
            n_body: self.mesh.n_body(),
        };
        let mut energy = 0.0;
        let mut values = hessian.map(|(values, _)| values);
        for stencil in barrier.iter().chain(&friction) {
            energy += stencil.energy;
            if !gradient.is_empty() {
                scatter.add_gradient(stencil, gradient);
            }
            if let Some(values) = values.as_deref_mut() {
                scatter.add_hessian(stencil, values);
            }
        }
        ContactPass {
            energy,
            min_squared_distance,
            active_set: Candidate::fingerprint(
                barrier.iter().chain(&friction).map(|s| s.candidate),
            ),
        }
    }

    /// Gradient (N) of the contact energy with respect to every node displacement (`3 n`,
    /// fixed nodes included) at `z`: minus the contact forces.
    pub fn full_gradient(&self, z: &[f64]) -> Vec<f64> {
        let forces = self.forces(z);
        forces.nodal.iter().flat_map(|f| f.map(|v| -v)).collect()
    }

    /// Lags friction for the next step: normal forces, closest points and tangent bases from the
    /// state `z_lag`, the tangential slip measured from the state `z_origin` (both full DOF
    /// vectors), with the slip `eps_u` (m) of the smoothed static branch.
    pub fn lag_friction(&mut self, z_lag: &[f64], z_origin: &[f64], slip: f64) {
        self.lagged_slip = slip;
        if !self.has_friction() {
            self.friction_stencils.clear();
            return;
        }
        let x = self.positions(z_lag);
        let origin = self.positions(z_origin);
        let found = candidates(&self.mesh, &x, self.dhat);
        let mu = |c: &Candidate| self.obstacle_of(c).map_or(0.0, |k| self.friction[k]);
        let mut stencils = lag_friction(&self.mesh, &found, &x, &self.barrier(), mu);
        for stencil in &mut stencils {
            let (p, n) = stencil.candidate.positions(&origin);
            stencil.start[..n].copy_from_slice(&p[..n]);
        }
        self.friction_stencils = stencils;
    }

    /// Drops the lagged friction (a step without friction history).
    pub fn clear_friction(&mut self) {
        self.friction_stencils.clear();
    }

    /// The largest step `alpha` in [0, 1] along the full-DOF direction `dz` from `z` that keeps
    /// every stencil apart (additive CCD, analytic for planes and spheres), each at least about
    /// `eta` times its starting distance. With self-contact, keeps the barrier's candidates
    /// along `dz` for the evaluations on it (see [`super::segment`]).
    pub fn max_step(&self, z: &[f64], dz: &[f64], eta: f64) -> f64 {
        let x0 = self.positions(z);
        let n_body = self.mesh.n_body();
        let dx: Vec<Vec3> = (0..x0.len())
            .map(|v| {
                if v < n_body {
                    Vec3::new(dz[3 * v], dz[3 * v + 1], dz[3 * v + 2])
                } else {
                    Vec3::zeros()
                }
            })
            .collect();
        let x1: Vec<Vec3> = x0.iter().zip(&dx).map(|(a, b)| a + b).collect();
        let swept = swept_candidates(&self.mesh, &x0, &x1, 0.0);
        // Against obstacles alone the broad phase is cheap (few, mostly analytic candidates)
        // and keeping them costs more than it saves; a self-contact surface pairs tens of
        // thousands of neighbouring primitives at every evaluation.
        if self.self_contact() {
            self.segment.set(&self.mesh, &x0, &dx, self.dhat);
        }
        max_step(&self.mesh, &swept, &x0, &dx, eta)
    }

    /// How many candidates an evaluation at the full DOF vector `z` takes from the direction
    /// [`ContactTerm::max_step`] last bounded (`None`: `z` is off it, and the evaluation runs
    /// the broad phase). A diagnostic.
    pub fn kept_candidates(&self, z: &[f64]) -> Option<usize> {
        self.segment
            .candidates_at(&self.positions(z), self.dhat)
            .map(|found| found.len())
    }

    /// The fraction in [0, 1] of the obstacles' motion from where they are now to where their
    /// paths put them at time `t` that keeps them apart from the body held at `z` (1: the whole
    /// motion is safe).
    pub fn obstacle_motion_bound(&self, z: &[f64], t: f64, eta: f64) -> f64 {
        let target: Vec<Vec3> = (0..self.paths.len())
            .map(|k| self.translation_at(k, t))
            .collect();
        let shift: Vec<Vec3> = target
            .iter()
            .zip(&self.translations)
            .map(|(a, b)| a - b)
            .collect();
        if shift.iter().all(|s| s.norm() == 0.0) {
            return 1.0;
        }
        let x0 = self.positions(z);
        let mut bound: f64 = 1.0;
        // Planes and spheres: each body surface vertex moves by minus the obstacle's shift
        // relative to it.
        for (k, obstacle) in self.mesh.obstacles().iter().enumerate() {
            let relative = -shift[k];
            if relative.norm() == 0.0 {
                continue;
            }
            let toi = |v: &usize| match obstacle {
                Obstacle::Plane(plane) => point_plane_toi(&x0[*v], &relative, plane, eta),
                Obstacle::Sphere(sphere) => point_sphere_toi(&x0[*v], &relative, sphere, eta),
                Obstacle::Mesh(_) => None,
            };
            let mut t = self
                .mesh
                .body_vertices()
                .par_iter()
                .filter_map(toi)
                .reduce(|| 1.0, f64::min);
            if let Obstacle::Sphere(sphere) = obstacle {
                let faces = self.mesh.body_faces().par_iter().filter_map(|f| {
                    sphere_triangle_toi(sphere, &f.map(|v| x0[v]), &[relative; 3], eta)
                });
                let edges = self.mesh.body_edges().par_iter().filter_map(|e| {
                    sphere_edge_toi(sphere, &e.map(|v| x0[v]), &[relative; 2], eta)
                });
                t = t.min(faces.chain(edges).reduce(|| 1.0, f64::min));
            }
            bound = bound.min(t);
        }
        // Meshes: their vertices move, the body stays.
        let dx: Vec<Vec3> = (0..x0.len())
            .map(|v| {
                self.mesh
                    .obstacle_of_vertex(v)
                    .map_or(Vec3::zeros(), |k| shift[k])
            })
            .collect();
        if dx.iter().any(|d| d.norm() > 0.0) {
            let x1: Vec<Vec3> = x0.iter().zip(&dx).map(|(a, b)| a + b).collect();
            let swept: Vec<Candidate> = swept_candidates(&self.mesh, &x0, &x1, 0.0)
                .into_iter()
                .filter(|c| {
                    matches!(
                        c,
                        Candidate::PointTriangle { .. } | Candidate::EdgeEdge { .. }
                    )
                })
                .collect();
            let t = swept
                .par_iter()
                .filter_map(|c| candidate_toi(&self.mesh, c, &x0, &dx, eta))
                .reduce(|| 1.0, f64::min);
            bound = bound.min(t);
        }
        bound
    }

    /// How far (m) [`ContactForces::min_distance`] looks: a twentieth of the scene's diagonal,
    /// and at least `dhat`.
    pub fn report_radius(&self) -> f64 {
        (0.05 * self.bbox_diagonal).max(self.dhat)
    }

    /// The contact forces at `z`, per node and per obstacle, the minimum distance to each
    /// obstacle and the active stencils. Barrier stencils that touch (only possible at a state
    /// no solve accepted) count with zero force.
    pub fn forces(&self, z: &[f64]) -> ContactForces {
        let x = self.positions(z);
        let n_nodes = self.mesh.n_body();
        let n_obstacles = self.n_obstacles();
        let mut out = ContactForces {
            nodal: vec![[0.0; 3]; n_nodes],
            per_obstacle: vec![[0.0; 3]; n_obstacles],
            min_distance: vec![None; n_obstacles],
            active: vec![0; n_obstacles],
            self_active: 0,
            self_min_distance: None,
        };
        let barrier = self.barrier_stencils(&x, None).unwrap_or_default();
        let friction = self.friction_stencils(&x, None);
        for (stencil, is_barrier) in barrier
            .iter()
            .map(|s| (s, true))
            .chain(friction.iter().map(|s| (s, false)))
        {
            let obstacle = self.obstacle_of(&stencil.candidate);
            match (is_barrier, obstacle) {
                (true, Some(k)) => out.active[k] += 1,
                (true, None) => out.self_active += 1,
                _ => {}
            }
            let (ids, n) = stencil.candidate.vertices();
            for (a, &v) in ids[..n].iter().enumerate() {
                if v >= n_nodes {
                    continue;
                }
                for i in 0..3 {
                    let force = -stencil.gradient[3 * a + i];
                    out.nodal[v][i] += force;
                    if let Some(k) = obstacle {
                        out.per_obstacle[k][i] += force;
                    }
                }
            }
        }
        let near = candidates(&self.mesh, &x, self.report_radius());
        for k in 0..n_obstacles {
            let own: Vec<Candidate> = near
                .iter()
                .filter(|c| self.obstacle_of(c) == Some(k))
                .copied()
                .collect();
            out.min_distance[k] = minimum_distance(&self.mesh, &own, &x)
                .map(|(d, _)| d)
                .filter(|&d| d <= self.report_radius());
        }
        let own: Vec<Candidate> = near.iter().filter(|c| self.is_self(c)).copied().collect();
        out.self_min_distance = minimum_distance(&self.mesh, &own, &x)
            .map(|(d, _)| d)
            .filter(|&d| d <= self.report_radius());
        out
    }

    /// `d(w . F_k)/dz` over the node displacements (`3 n`, N/m per unit of `w`): the derivative
    /// of the total force `F_k` obstacle `k` exerts on the body (barrier only: friction is
    /// lagged) along the weights `w`, at `z`. What a target on a contact force needs of the
    /// adjoint.
    pub fn force_gradient(&self, z: &[f64], obstacle: usize, w: [f64; 3]) -> Vec<f64> {
        let x = self.positions(z);
        let n_nodes = self.mesh.n_body();
        let mut out = vec![0.0; 3 * n_nodes];
        let stencils = self
            .barrier_stencils(&x, Some(HessianMode::Exact))
            .unwrap_or_default();
        for stencil in stencils
            .iter()
            .filter(|s| self.obstacle_of(&s.candidate) == Some(obstacle))
        {
            // F = -sum_a g_a over the body vertices a, so d(w . F)/dx_b = -sum_a w^T H_ab.
            let (ids, n) = stencil.candidate.vertices();
            let size = 3 * n;
            for (b, &vb) in ids[..n].iter().enumerate() {
                if vb >= n_nodes {
                    continue;
                }
                for j in 0..3 {
                    let mut value = 0.0;
                    for (a, &va) in ids[..n].iter().enumerate() {
                        if va >= n_nodes {
                            continue;
                        }
                        for (i, wi) in w.iter().enumerate() {
                            value -= wi * stencil.hessian[(3 * a + i) * size + 3 * b + j];
                        }
                    }
                    out[3 * vb + j] += value;
                }
            }
        }
        out
    }

    /// The diagonal of the bounding box of the body at rest and the obstacles' vertices (m);
    /// planes and spheres count with their point and centre.
    fn scene_diagonal(&self) -> f64 {
        let mut lo = Vec3::repeat(f64::INFINITY);
        let mut hi = Vec3::repeat(f64::NEG_INFINITY);
        for p in self.mesh.rest() {
            lo = lo.inf(p);
            hi = hi.sup(p);
        }
        (hi - lo).norm()
    }
}
