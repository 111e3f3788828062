//! Selections on any mesh, on a 4 × 4 × 4 box of 10 cm whose node counts are known: the boundary,
//! what a camera sees (the normal test and self-occlusion), balls, landmarks from a file,
//! intersections, and the errors.

use augsim_mesh::{self as mesh, Ball, Camera, Mesh, Near, NodeSelection};

const SIDE: f64 = 0.1;

fn cube() -> Mesh {
    mesh::box_tet([0.0; 3], [SIDE; 3], [4, 4, 4]).unwrap()
}

fn camera(view: Option<[f64; 3]>, position: Option<[f64; 3]>, max_angle_deg: f64) -> NodeSelection {
    NodeSelection::Facing(Camera { view, position, max_angle_deg })
}

#[test]
fn the_surface_is_every_node_but_the_inner_ones() {
    let m = cube();
    assert_eq!(NodeSelection::Surface.select(&m).unwrap().len(), 5 * 5 * 5 - 3 * 3 * 3);
}

#[test]
fn a_camera_above_sees_the_top_face() {
    let m = cube();
    let top = camera(Some([0.0, 0.0, -1.0]), None, 90.0).select(&m).unwrap();
    assert_eq!(top.len(), 25);
    assert!(top.iter().all(|&n| (m.nodes[n][2] - SIDE).abs() < 1e-12));
    // Within 30 degrees: the edge nodes (normals at 45 and 55 degrees) are left out.
    assert_eq!(camera(Some([0.0, 0.0, -1.0]), None, 30.0).select(&m).unwrap().len(), 9);
    // From a position above the centre: the same face.
    assert_eq!(camera(None, Some([0.05, 0.05, 1.0]), 90.0).select(&m).unwrap(), top);
}

#[test]
fn nodes_behind_the_organ_are_hidden() {
    let m = cube();
    // Every normal accepted (180 degrees): only the line of sight decides. From far along
    // (1, 1, 1), the three faces at x, y, z = SIDE are seen (3 × 25 − 3 × 5 + 1 nodes); the nodes
    // of the three other faces are hidden by the cube itself.
    let seen = camera(Some([-1.0, -1.0, -1.0]), None, 180.0).select(&m).unwrap();
    assert_eq!(seen.len(), 3 * 25 - 3 * 5 + 1);
    assert!(seen.iter().all(|&n| m.nodes[n].iter().any(|&x| (x - SIDE).abs() < 1e-12)));
}

#[test]
fn balls_landmarks_and_intersections() {
    let m = cube();
    let dir = tempfile::tempdir().unwrap();
    // A ball of 3 cm at a corner: the corner and its 3 neighbours at 2.5 cm.
    let corner = NodeSelection::Ball(Ball { centre: [0.0; 3], radius: 0.03 });
    assert_eq!(corner.select(&m).unwrap().len(), 4);
    // Landmarks from a CSV file, and inline.
    std::fs::write(dir.path().join("landmarks.csv"), "x,y,z\n0.05,0.05,0.05\n").unwrap();
    let near = |surface: bool, points: Vec<[f64; 3]>| {
        NodeSelection::Near(Near { points, file: Some(dir.path().join("landmarks.csv")), distance: 0.026, surface })
    };
    // The centre and its 6 neighbours at 2.5 cm.
    assert_eq!(near(false, vec![]).select(&m).unwrap().len(), 7);
    // With a landmark on the top face's centre, boundary nodes only: that node and its 4
    // neighbours on the face (the one below it is inside).
    assert_eq!(near(true, vec![[0.05, 0.05, SIDE]]).select(&m).unwrap().len(), 5);
    // The surface within 3 cm of a corner: the 4 nodes of the ball, all on the boundary.
    let both = NodeSelection::Intersection(vec![NodeSelection::Surface, corner]);
    assert_eq!(both.select(&m).unwrap().len(), 4);
}

#[test]
fn selections_that_cannot_work_say_why() {
    let m = cube();
    let error = |s: NodeSelection| s.select(&m).unwrap_err().to_string();
    assert!(error(camera(None, None, 90.0)).contains("a camera needs"));
    let e = error(camera(Some([0.0; 3]), None, 90.0));
    assert!(e.contains("a camera needs") && e.contains("got view [0.0, 0.0, 0.0] and position none"), "{e}");
    // An empty selection is named in words, as a scenario file gives it.
    let ball = NodeSelection::Ball(Ball { centre: [1.0; 3], radius: 0.01 });
    let e = error(ball.clone());
    assert!(e.contains("selection ball of radius 0.01 m about [1.0, 1.0, 1.0] picks no node"), "{e}");
    assert!(!e.contains("millimetres"), "{e}");
    // One in millimetres on a mesh in metres: its unit is asked about.
    let e = error(NodeSelection::Ball(Ball { centre: [0.0, -90.0, 0.0], radius: 30.0 }));
    assert!(e.contains("picks no node (the mesh spans") && e.contains("are these in millimetres?"), "{e}");
    let away = NodeSelection::Box { min: [9.0; 3], max: [10.0; 3] };
    let e = error(NodeSelection::Union(vec![NodeSelection::Surface, away.clone()]));
    assert!(e.contains("selection box [9.0, 9.0, 9.0] to [10.0, 10.0, 10.0] picks no node"), "{e}");
    let both = NodeSelection::Intersection(vec![away, ball, NodeSelection::Region("visible".into())]);
    assert_eq!(
        both.to_string(),
        "intersection of (box [9.0, 9.0, 9.0] to [10.0, 10.0, 10.0]; ball of radius 0.01 m about [1.0, 1.0, 1.0]; \
         region 'visible')"
    );
    let missing =
        NodeSelection::Near(Near { points: vec![], file: Some("missing.csv".into()), distance: 0.01, surface: false });
    assert!(error(missing).contains("missing.csv"));
    let none = NodeSelection::Near(Near { points: vec![], file: None, distance: 0.01, surface: false });
    assert!(error(none).contains("no landmark"));
}
