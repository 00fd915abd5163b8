//! Building cables from user input: embed each point in the mesh (barycentric weights through the
//! [`PointLocator`]), snap points just outside, and turn the rest into free nodes or errors.
//! A cable is a chain of springs bonded to the body ([`Cable`]) or a tendon sliding through
//! guide points ([`Tendon`]).

use crate::energy::{Cable, PointMap, Tendon, TendonCommand};
use crate::error::{check_finite, Error, Result};
use crate::locate::PointLocator;
use crate::mesh::TetMesh;

/// What to do with a cable point farther than `snap_tolerance` from the mesh.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Outside {
    /// It becomes a free node: three extra unknowns with their own mass.
    FreeNode,
    /// The model is rejected.
    Error,
}

/// How a cable acts on the body.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum CableModel {
    /// A chain of unilateral springs bonded to the body at every point (stiffness, actuation,
    /// transition and damping apply).
    Springs,
    /// An inextensible tendon sliding through its guide points, driven by its command (only the
    /// points, `anchor_first` and `snap_tolerance` apply; guide points cannot be free nodes).
    Tendon(TendonCommand),
}

/// Where cable `c` of a model lives: spring chain or tendon number `i` of its kind.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CableSlot {
    Springs(usize),
    Tendon(usize),
}

/// A cable as the user describes it.
#[derive(Clone, Debug)]
pub struct CableSpec {
    pub model: CableModel,
    /// Ordered rest positions of the cable points (m), at least two.
    pub points: Vec<[f64; 3]>,
    /// Stiffness of each segment spring (N/m), > 0.
    pub stiffness: f64,
    /// Actuation alpha > 0: rest lengths are scaled by it (1: rest, < 1: pulled).
    pub actuation: f64,
    /// Width of the slack-taut transition as a fraction of each segment's rest length.
    pub transition: f64,
    /// The first point is fixed in the world (the motor) instead of attached to the body.
    pub anchor_first: bool,
    /// Points within this distance (m) outside the mesh snap onto the closest tet.
    pub snap_tolerance: f64,
    pub outside: Outside,
    /// Mass of each free node (kg).
    pub free_node_mass: f64,
    /// Dashpot coefficient of each segment (N s/m): a damping force `c dL/dt` along the segment
    /// in time integration; no effect on static solves.
    pub damping: f64,
}

impl CableSpec {
    /// A spring chain.
    pub fn new(points: Vec<[f64; 3]>, stiffness: f64, actuation: f64) -> Self {
        CableSpec {
            model: CableModel::Springs,
            points,
            stiffness,
            actuation,
            transition: 1e-3,
            anchor_first: false,
            snap_tolerance: 0.0,
            outside: Outside::Error,
            free_node_mass: 0.0,
            damping: 0.0,
        }
    }

    /// A tendon through `points` (the last one is where it is tied) under `command`.
    pub fn tendon(points: Vec<[f64; 3]>, command: TendonCommand) -> Self {
        CableSpec {
            model: CableModel::Tendon(command),
            ..CableSpec::new(points, 1.0, 1.0)
        }
    }
}

/// Where each cable point ended up.
#[derive(Clone, Debug, PartialEq)]
pub enum PointPlacement {
    /// Inside (distance 0) or snapped onto (distance > 0, m) tet `tet`.
    Embedded { tet: usize, distance: f64 },
    /// Free node number `index` (among all cables' free nodes).
    Free { index: usize },
    /// Fixed in the world.
    Anchor,
}

/// Cables embedded in a mesh, plus the free nodes they created.
#[derive(Clone, Debug, Default)]
pub struct EmbeddedCables {
    /// The spring chains and the tendons, each in the order given; `slots[c]` says where spec
    /// `c` went.
    pub cables: Vec<Cable>,
    pub tendons: Vec<Tendon>,
    pub slots: Vec<CableSlot>,
    pub placements: Vec<Vec<PointPlacement>>,
    /// Rest position (m) and mass (kg) of each free node.
    pub free_nodes: Vec<([f64; 3], f64)>,
}

/// Embeds `specs` in `mesh`. Free node `i` owns full DOFs `3 n + 3 i .. 3 n + 3 i + 3`.
pub fn embed(mesh: &TetMesh, specs: &[CableSpec]) -> Result<EmbeddedCables> {
    let mut out = EmbeddedCables::default();
    if specs.is_empty() {
        return Ok(out);
    }
    let locator = PointLocator::new(mesh);
    let n = mesh.n_nodes();
    for (c, spec) in specs.iter().enumerate() {
        let name = |field: &str| format!("cables[{c}].{field}");
        if spec.points.len() < 2 {
            return Err(Error::shape(
                &name("points"),
                "at least 2 points (k, 3)",
                format!("{} points", spec.points.len()),
            ));
        }
        check_finite(&name("points"), spec.points.as_flattened())?;
        for (field, value, ok) in [
            (
                "stiffness",
                spec.stiffness,
                spec.stiffness > 0.0 && spec.stiffness.is_finite(),
            ),
            (
                "actuation",
                spec.actuation,
                spec.actuation > 0.0 && spec.actuation.is_finite(),
            ),
            (
                "transition",
                spec.transition,
                spec.transition > 0.0 && spec.transition < 1.0,
            ),
            (
                "snap_tolerance",
                spec.snap_tolerance,
                spec.snap_tolerance >= 0.0 && spec.snap_tolerance.is_finite(),
            ),
            (
                "free_node_mass",
                spec.free_node_mass,
                spec.free_node_mass >= 0.0 && spec.free_node_mass.is_finite(),
            ),
            (
                "damping",
                spec.damping,
                spec.damping >= 0.0 && spec.damping.is_finite(),
            ),
        ] {
            let applies = spec.model == CableModel::Springs || field == "snap_tolerance";
            if applies && !ok {
                let expected = match field {
                    "transition" => "a fraction in (0, 1)",
                    "snap_tolerance" | "free_node_mass" | "damping" => "a finite value >= 0",
                    _ => "a finite value > 0",
                };
                return Err(Error::invalid(&name(field), expected, value));
            }
        }
        if let CableModel::Tendon(command) = spec.model {
            check_tendon_command(c, command)?;
            if spec.outside == Outside::FreeNode {
                return Err(Error::invalid(
                    &name("outside"),
                    "\"error\" for a tendon (it slides through its guide points, which must lie in the body or be the anchor: a free guide point would have no stiffness along the tendon)",
                    "\"free\"",
                ));
            }
        }
        let mut maps = Vec::with_capacity(spec.points.len());
        let mut placements = Vec::with_capacity(spec.points.len());
        for (k, &p) in spec.points.iter().enumerate() {
            if k == 0 && spec.anchor_first {
                maps.push(PointMap {
                    offset: p,
                    dof_blocks: vec![],
                    weights: vec![],
                });
                placements.push(PointPlacement::Anchor);
                continue;
            }
            match locator.locate(p, spec.snap_tolerance) {
                Some(location) => {
                    let tet = mesh.tets()[location.tet];
                    let rest = mesh.rest();
                    // The rest position of the material point the weights describe.
                    let offset: [f64; 3] = std::array::from_fn(|i| {
                        (0..4).map(|a| location.weights[a] * rest[tet[a]][i]).sum()
                    });
                    maps.push(PointMap {
                        offset,
                        dof_blocks: tet.iter().map(|&i| 3 * i).collect(),
                        weights: location.weights.to_vec(),
                    });
                    placements.push(PointPlacement::Embedded {
                        tet: location.tet,
                        distance: location.distance,
                    });
                }
                None if spec.outside == Outside::FreeNode => {
                    let index = out.free_nodes.len();
                    out.free_nodes.push((p, spec.free_node_mass));
                    maps.push(PointMap {
                        offset: p,
                        dof_blocks: vec![3 * (n + index)],
                        weights: vec![1.0],
                    });
                    placements.push(PointPlacement::Free { index });
                }
                None => {
                    return Err(Error::invalid(
                        &format!("cables[{c}].points[{k}]"),
                        format!(
                            "a point inside the mesh or within snap_tolerance = {} m of it (or outside = \"free\")",
                            spec.snap_tolerance
                        ),
                        format!("{p:?}, outside the mesh"),
                    ));
                }
            }
        }
        let rest_lengths: Vec<f64> = maps
            .windows(2)
            .map(|w| {
                (0..3)
                    .map(|i| (w[1].offset[i] - w[0].offset[i]).powi(2))
                    .sum::<f64>()
                    .sqrt()
            })
            .collect();
        if let Some(k) = rest_lengths.iter().position(|&l| !(l > 0.0)) {
            return Err(Error::invalid(
                &name("points"),
                "distinct consecutive points (segments of positive length)",
                format!("points {k} and {} coincide", k + 1),
            ));
        }
        match spec.model {
            CableModel::Springs => {
                out.slots.push(CableSlot::Springs(out.cables.len()));
                out.cables.push(Cable {
                    points: maps,
                    rest_lengths,
                    stiffness: spec.stiffness,
                    actuation: spec.actuation,
                    transition: spec.transition,
                    damping: spec.damping,
                });
            }
            CableModel::Tendon(command) => {
                let tendon = Tendon {
                    points: maps,
                    rest_lengths,
                    command,
                    tension: 0.0,
                };
                check_pull(c, command, tendon.rest_length())?;
                out.slots.push(CableSlot::Tendon(out.tendons.len()));
                out.tendons.push(tendon);
            }
        }
        out.placements.push(placements);
    }
    Ok(out)
}

/// Checks a tendon command on its own: a finite pull, or a finite tension >= 0.
pub(crate) fn check_tendon_command(c: usize, command: TendonCommand) -> Result<()> {
    match command {
        TendonCommand::Pull(d) if !d.is_finite() => Err(Error::invalid(
            &format!("cables[{c}].pull"),
            "a finite pulled length (m)",
            d,
        )),
        TendonCommand::Tension(t) if !(t >= 0.0 && t.is_finite()) => Err(Error::invalid(
            &format!("cables[{c}].tension"),
            "a finite tension >= 0 N (a tendon cannot push)",
            t,
        )),
        _ => Ok(()),
    }
}

/// Checks a pull against the tendon's rest length `rest_length` (m): it must leave some length.
pub(crate) fn check_pull(c: usize, command: TendonCommand, rest_length: f64) -> Result<()> {
    match command {
        TendonCommand::Pull(d) if d >= rest_length => Err(Error::invalid(
            &format!("cables[{c}].pull"),
            format!("a pull shorter than the tendon's rest length {rest_length:.6} m"),
            format!("{d} m"),
        )),
        _ => Ok(()),
    }
}
