//! Tolerances of the geometric queries, in one place. Each is relative to a length scale of
//! the mesh, so the same value works for a mesh in metres or in millimetres.

/// Tets with `|volume|` at most this times (longest edge)^3 count as degenerate (a regular tet
/// has 0.118).
pub const DEGENERATE_TET_VOLUME: f64 = 1e-12;

/// A point whose barycentric weights in a tet are all at least `-INSIDE_TET` lies in it
/// (weights are dimensionless: round-off on a shared face must not leave a point in no tet).
pub const INSIDE_TET: f64 = 1e-10;

/// The usual tolerance of [`crate::mesh::TetMesh::nodes_on_plane`]: a node is on a plane within
/// this fraction of the mesh's bounding-box diagonal.
pub const ON_PLANE: f64 = 1e-9;
