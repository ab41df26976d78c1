//! A corner next to where another closed piece of its object crosses its face is not buried
//! (issue 19, pybullet's teddy): the differential test, against brute force.
//!
//! The teddy is 15 convex hulls of one object that meet at nearly coplanar faces (the cut
//! planes of its decomposition, faces up to 23 cm), where a hull's surface crosses a face of
//! another 0.1-0.5 mm from its vertex. The gather's buried test took its point a thousandth of
//! the way to the face's centre (`solids::test_point`, so that a point lifted off a concave edge
//! stays out of its own solid): on a 23 cm face that step crossed into the other hull, and a
//! corner whose gathered point is outside, and which Cycles bakes lit, came out black (7 of the
//! teddy's 2,100 corners, 24% of its squared error against Cycles; docs/validation-real.md,
//! "Teddy").
//!
//! Here: a 1 x 1 x 0.1 m grey slab, its top face one quad, and a black block of the same object
//! standing through it with a side wall 1.25 mm from the top face's corner at the origin: the
//! corner's gathered point (1 mm in along both edges) is outside the block, the point a
//! thousandth of the way to the face's centre (1.5 mm in) inside it. Under a light quad centred
//! over the corner, the only light the corner receives is the light's own (the block is black,
//! the slab convex), so its exact `B` is `rho E_d`, `E_d` by brute force (the light cut into
//! 64 x 64 pieces, each piece's exact point-to-polygon form factor times one shadow ray to its
//! centre through the block's triangles). Before the rule that both points must be buried, the
//! corner was black; a corner of the block inside the slab stays black.

use galerkin_radiosity::geometry::Patch;
use galerkin_radiosity::scene::Scene;
use galerkin_radiosity::scenes::{box_mesh, merge, subdivided_quad};
use galerkin_radiosity::visibility::bvh::Triangle;
use glam::DVec3;

#[path = "common/brute_force.rs"]
mod brute_force;

const RHO: f64 = 0.7;
const EXITANCE: f64 = 10.0;
const LIGHT_HALF: f64 = 0.25;
const LIGHT_HEIGHT: f64 = 1.0;
/// The block's wall, this far from the slab's corner along x.
const WALL: f64 = 1.25e-3;
const BLOCK_MIN: DVec3 = DVec3::new(WALL, -0.2, 0.05);
const BLOCK_MAX: DVec3 = DVec3::new(0.5, 0.5, 0.3);

fn light_corners() -> [DVec3; 4] {
    brute_force::ceiling_light(LIGHT_HALF, LIGHT_HEIGHT)
}

fn scene() -> Scene {
    let slab = box_mesh("slab", DVec3::ZERO, DVec3::new(1.0, 1.0, 0.1), 1, false, 0);
    let block = box_mesh("block", BLOCK_MIN, BLOCK_MAX, 1, false, 1);
    // One object of two closed pieces, as the teddy's hulls are (the contact split, which only
    // splits faces by other objects, leaves the slab's top one face).
    let hulls = merge("hulls", vec![slab, block]);
    let light = subdivided_quad("light", light_corners(), 1, 2);
    brute_force::grey_black_light(RHO, EXITANCE, vec![hulls, light])
}

/// `E_d` at `y` (normal +z) by brute force, shadowed by `occluders`.
fn direct(y: DVec3, occluders: &[Triangle]) -> f64 {
    let light = Patch::from_corners(&light_corners());
    EXITANCE * brute_force::direct_light(&light, y, DVec3::Z, occluders, 64).form_factor
}

#[test]
fn a_corner_beside_a_crossing_piece_is_lit() {
    let scene = scene();
    let sys = brute_force::gathered(&scene);
    let results = sys.face_results(&scene, 1.0);
    let obj = &scene.objects[0];
    let block = brute_force::triangles_of(&box_mesh("block", BLOCK_MIN, BLOCK_MAX, 1, false, 1));
    let (mut checked, mut corner) = (0, 0);
    for (f, face) in obj.faces.iter().enumerate() {
        let top = obj.face_materials[f] == 0
            && face.iter().all(|&v| (obj.vertices[v as usize].z - 0.1).abs() < 1e-12);
        for &v in face {
            let p = obj.vertices[v as usize];
            let value = results[0].corner_radiosity[corner][0] as f64;
            if top && p.x.abs() < 1e-12 && p.y.abs() < 1e-12 {
                // The gathered point: a thousandth of the face's parameters in along both edges.
                let exact = RHO * direct(p + DVec3::new(1e-3, 1e-3, 1e-9), &block);
                let at_vertex = RHO * direct(p + DVec3::Z * 1e-9, &block);
                eprintln!(
                    "slab's top corner at {p}: B {value:.4}, brute force {exact:.4} (at the vertex {at_vertex:.4})"
                );
                assert!(exact > 0.3 * RHO * EXITANCE * 0.1, "the reference itself is lit: {exact}");
                assert!((value - exact).abs() < 0.05 * exact, "B {value} against brute force {exact}");
                checked += 1;
            }
            if obj.face_materials[f] == 1 && p.z < 0.1 && p.x > WALL && p.y > 0.0 {
                // A corner of the block inside the slab.
                assert!(value.abs() < 1e-6, "the block's corner at {p} inside the slab: {value}");
                checked += 1;
            }
            corner += 1;
        }
    }
    assert_eq!(checked, 1 + 3, "the slab's corner and the block's buried corner on three faces");
}
