//! Obstacles and diagnostics: box meshes (closed, outward, winding numbers), bad input with
//! clear errors, rest intersections naming the obstacle and the node or triangle, and the
//! minimum distance.
mod common;

use common::contact_scene;
use sorofem_core::contact::broad_phase::candidates;
use sorofem_core::contact::check::{
    check_no_intersection, find_intersection, minimum_distance, Intersection,
};
use sorofem_core::contact::{
    BarrierPotential, Candidate, CollisionMesh, Obstacle, ObstacleMesh, Plane, Sphere, Vec3,
};
use sorofem_core::TetMesh;

#[test]
fn boxes_are_closed_outward_triangle_meshes() {
    let rotation = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]];
    for mesh in [
        ObstacleMesh::cuboid([0.0, 0.0, 0.0], [1.0, 2.0, 3.0]).unwrap(),
        ObstacleMesh::oriented_box([0.5, 1.0, 1.5], [1.0, 0.5, 1.5], rotation).unwrap(),
    ] {
        assert_eq!(mesh.triangles().len(), 12);
        assert_eq!(mesh.edges().len(), 18);
        assert!(mesh.is_closed());
        // Signed volume by the divergence theorem: positive for outward normals, = 6 m^3.
        let volume: f64 = mesh
            .triangles()
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| mesh.vertices()[i]);
                a.dot(&b.cross(&c)) / 6.0
            })
            .sum();
        assert!((volume - 6.0).abs() < 1e-12, "{volume}");
        assert!((mesh.winding_number(&Vec3::new(0.5, 1.0, 1.5)) - 1.0).abs() < 1e-12);
        assert!(mesh.winding_number(&Vec3::new(0.5, 1.0, 3.2)).abs() < 1e-12);
        assert!(mesh.winding_number(&Vec3::new(-5.0, 7.0, 1.0)).abs() < 1e-12);
    }
    let open = ObstacleMesh::try_new(
        vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0]],
        &[[0, 1, 2], [1, 3, 2]],
    )
    .unwrap();
    assert!(!open.is_closed());
}

#[test]
fn bad_input_is_named() {
    let message = |r: Result<_, sorofem_core::Error>| r.map(|_: ()| ()).unwrap_err().to_string();
    let m = message(Plane::try_new([0.0; 3], [0.0; 3]).map(|_| ()));
    assert!(m.contains("plane.normal") && m.contains("nonzero"), "{m}");
    let m = message(Sphere::try_new([0.0; 3], -1.0).map(|_| ()));
    assert!(m.contains("sphere.radius") && m.contains("-1"), "{m}");
    let m = message(Sphere::try_new([f64::NAN, 0.0, 0.0], 1.0).map(|_| ()));
    assert!(m.contains("sphere.center"), "{m}");
    let m = message(ObstacleMesh::cuboid([0.0; 3], [1.0, 0.0, 1.0]).map(|_| ()));
    assert!(m.contains("box") && m.contains("max > min"), "{m}");
    let m = message(
        ObstacleMesh::try_new(
            vec![[0.0; 3], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]],
            &[[0, 1, 2]],
        )
        .map(|_| ()),
    );
    assert!(
        m.contains("obstacle.triangles") && m.contains("triangle 0"),
        "{m}"
    );
    let m = message(
        ObstacleMesh::try_new(
            vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
            &[[0, 1, 3]],
        )
        .map(|_| ()),
    );
    assert!(
        m.contains("obstacle.triangles") && m.contains("given 3"),
        "{m}"
    );
    let m = message(
        ObstacleMesh::oriented_box(
            [0.0; 3],
            [1.0; 3],
            [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]],
        )
        .map(|_| ()),
    );
    assert!(m.contains("box.rotation"), "{m}");
    for dhat in [0.0, -1e-3, f64::NAN] {
        let m = message(BarrierPotential::try_new(dhat, 1.0).map(|_| ()));
        assert!(m.contains("dhat"), "{m}");
    }
    let m = message(BarrierPotential::try_new(1e-3, 0.0).map(|_| ()));
    assert!(m.contains("barrier stiffness"), "{m}");
    let (_, collision) = contact_scene(1, false);
    let m = message(collision.vertices(&[0.0; 5]).map(|_| ()));
    assert!(
        m.contains("positions") && m.contains("given 5 values"),
        "{m}"
    );
}

fn block_with(obstacle: Obstacle) -> (TetMesh, CollisionMesh) {
    let mesh = TetMesh::box_mesh([0.1; 3], [2; 3], [0.0; 3]).unwrap();
    let collision = CollisionMesh::from_tet_mesh(
        &mesh,
        vec![
            Obstacle::Plane(Plane::try_new([0.0, 0.0, -1.0], [0.0, 0.0, 1.0]).unwrap()),
            obstacle,
        ],
        false,
    );
    (mesh, collision)
}

#[test]
fn rest_intersections_name_the_obstacle_node_and_distance() {
    // Apart: the scene's obstacles are 2-3 mm away.
    let (mesh, collision) = contact_scene(2, false);
    let x = collision.vertices(&mesh.rest_flat()).unwrap();
    assert_eq!(find_intersection(&collision, &x), None);
    check_no_intersection(&collision, &x).unwrap();

    // A plane cutting the block at z = 0.03: node 0 (the origin) is 30 mm below it.
    let (mesh, collision) = block_with(Obstacle::Plane(
        Plane::try_new([0.0, 0.0, 0.03], [0.0, 0.0, 1.0]).unwrap(),
    ));
    let x = collision.vertices(&mesh.rest_flat()).unwrap();
    match find_intersection(&collision, &x) {
        Some(Intersection::Node {
            obstacle: 1,
            node: 0,
            distance,
        }) => assert!((distance + 0.03).abs() < 1e-15),
        other => panic!("{other:?}"),
    }
    let m = check_no_intersection(&collision, &x)
        .unwrap_err()
        .to_string();
    assert!(
        m.contains("obstacles[1]") && m.contains("body node 0") && m.contains("-3.000e-2 m"),
        "{m}"
    );

    // A sphere around the top corner (0.1, 0.1, 0.1) (node 26 of the 3 x 3 x 3 grid).
    let (mesh, collision) = block_with(Obstacle::Sphere(
        Sphere::try_new([0.11, 0.11, 0.11], 0.02).unwrap(),
    ));
    let x = collision.vertices(&mesh.rest_flat()).unwrap();
    match find_intersection(&collision, &x) {
        Some(Intersection::Node {
            obstacle: 1,
            node: 26,
            distance,
        }) => {
            assert!((distance - (0.01 * 3f64.sqrt() - 0.02)).abs() < 1e-15)
        }
        other => panic!("{other:?}"),
    }
    // A sphere dipping into the top face between its nodes: found on a triangle.
    let (mesh, collision) = block_with(Obstacle::Sphere(
        Sphere::try_new([0.025, 0.025, 0.11], 0.015).unwrap(),
    ));
    let x = collision.vertices(&mesh.rest_flat()).unwrap();
    match find_intersection(&collision, &x) {
        Some(Intersection::Triangle {
            obstacle: 1,
            distance,
            ..
        }) => assert!((distance + 0.005).abs() < 1e-12, "{distance}"),
        other => panic!("{other:?}"),
    }
    // A sphere inside the block touches no node: it is found inside the body.
    let (mesh, collision) = block_with(Obstacle::Sphere(
        Sphere::try_new([0.05, 0.05, 0.05], 0.01).unwrap(),
    ));
    let x = collision.vertices(&mesh.rest_flat()).unwrap();
    assert!(matches!(
        find_intersection(&collision, &x),
        Some(Intersection::InsideBody { obstacle: 1, .. })
    ));

    // A box containing the corner node 26, one crossing an edge without containing a node, and
    // one inside the block.
    let (mesh, collision) = block_with(Obstacle::Mesh(
        ObstacleMesh::cuboid([0.09; 3], [0.2; 3]).unwrap(),
    ));
    let x = collision.vertices(&mesh.rest_flat()).unwrap();
    match find_intersection(&collision, &x) {
        Some(Intersection::Node {
            obstacle: 1,
            node: 26,
            distance,
        }) => assert!((distance + 0.01).abs() < 1e-12),
        other => panic!("{other:?}"),
    }
    let thin = ObstacleMesh::cuboid([0.02, 0.07, 0.09], [0.03, 0.2, 0.2]).unwrap();
    let (mesh, collision) = block_with(Obstacle::Mesh(thin));
    let x = collision.vertices(&mesh.rest_flat()).unwrap();
    assert!(matches!(
        find_intersection(&collision, &x),
        Some(Intersection::EdgeTriangle { obstacle: 1, .. })
    ));
    let (mesh, collision) = block_with(Obstacle::Mesh(
        ObstacleMesh::cuboid([0.04; 3], [0.06; 3]).unwrap(),
    ));
    let x = collision.vertices(&mesh.rest_flat()).unwrap();
    assert!(matches!(
        find_intersection(&collision, &x),
        Some(Intersection::InsideBody { obstacle: 1, .. })
    ));
}

#[test]
fn minimum_distance_is_the_closest_gap() {
    let (mesh, collision) = contact_scene(2, true);
    let x = collision.vertices(&mesh.rest_flat()).unwrap();
    let found = candidates(&collision, &x, 0.01);
    let (d, c) = minimum_distance(&collision, &found, &x).unwrap();
    // The bottom is 2 mm above the plane (closer than the sphere's and the box's 3 mm).
    assert!((d - 0.002).abs() < 1e-15, "{d}");
    assert!(matches!(c, Candidate::PointPlane { obstacle: 0, .. }));
    // Lifted by 1.5 mm the top centre node is closest, 1.5 mm below the sphere.
    let lifted: Vec<f64> = mesh
        .rest_flat()
        .iter()
        .enumerate()
        .map(|(i, v)| if i % 3 == 2 { v + 0.0015 } else { *v })
        .collect();
    let x = collision.vertices(&lifted).unwrap();
    let found = candidates(&collision, &x, 0.01);
    let (d, c) = minimum_distance(&collision, &found, &x).unwrap();
    assert!((d - 0.0015).abs() < 1e-15, "sphere gap {d}");
    assert!(
        matches!(c, Candidate::PointSphere { obstacle: 1, .. }),
        "{c:?}"
    );
    assert_eq!(minimum_distance(&collision, &[], &x), None);
}
