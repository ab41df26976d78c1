//! Faces of one object split where they meet at a concave crease (`contact_split`'s crease
//! rule, issue 19's monastery: a wall standing on a platform), against brute force.
//!
//! An L of one object: a grey 1 m wall, one face, standing on the edge of a black 1 m platform
//! (4 x 4 faces). A 0.6 m light low beside the platform, below its plane, shines at the wall over
//! the platform's far edge: the platform shadows the wall next to the crease (dark up to 0.1 m,
//! a penumbra up to 0.7 m). The wall sees only the light and the platform (black; a plane does
//! not see itself), so its exact radiosity is `B(y) = rho E_d(y)`, by brute force (the light cut
//! into 32 x 32 pieces, each piece's exact point-to-polygon form factor times one shadow ray to
//! its centre through the platform's triangles). The platform is black and the light below its
//! plane, so a platform corner's exact irradiance is the wall's `B` seen from it, integrated here
//! over 64 x 64 pieces of the wall.
//!
//! Faces of one object did not split each other (a mesh's smooth neighbours touch along every
//! edge), and the contact split's `FINEST` rule keeps a face larger than twice the triangle that
//! comes close, so the wall stayed one quadratic, which cannot follow the contact shadow: 22.8%
//! relative RMS error on the wall, 10.9% on the platform corners' gathered irradiance (worst
//! 23.7%). Split at the crease (the wall in 40 elements): 9.9% and 2.6% (worst 4.8%).
//!
//! The light is 4 x 4 faces. The kernel sees an emitter through its 2 x 2 visibility cells, so
//! with the light as one face the split wall's penumbra comes out in four steps, and the split
//! measured worse than one quadratic (29.0% and 19.0%, split finer than now): the split follows a
//! shadow only as far as the light's visibility samples resolve it. On the monastery a 4 x 4
//! light changed nothing (17.87% against 17.77%), so the library's emitters stay whole.

use galerkin_radiosity::geometry::Patch;
use galerkin_radiosity::scene::{Object, Scene};
use galerkin_radiosity::scenes::{facing, merge, subdivided_quad};
use galerkin_radiosity::visibility::bvh::Triangle;
use glam::DVec3;

#[path = "common/brute_force.rs"]
mod brute_force;

const RHO: f64 = 0.7;
const EXITANCE: f64 = 10.0;

/// A 0.6 m light quad 2 m from the wall, below the platform's plane, facing the wall.
fn light_corners() -> [DVec3; 4] {
    let p = |y, z| DVec3::new(2.0, y, z);
    facing([p(0.2, -0.7), p(0.8, -0.7), p(0.8, -0.1), p(0.2, -0.1)], DVec3::new(0.0, 0.5, 0.5), false)
}

/// The wall (face 0, one quad at x = 0 facing +x, grey) and the platform (faces 1.., z = 0
/// facing +z, black) as one object.
fn l_shape() -> Object {
    let w = |y, z| DVec3::new(0.0, y, z);
    let wall = subdivided_quad(
        "wall",
        facing([w(0., 0.), w(1., 0.), w(1., 1.), w(0., 1.)], DVec3::new(1.0, 0.5, 0.5), false),
        1,
        0,
    );
    let p = |x, y| DVec3::new(x, y, 0.0);
    let platform = subdivided_quad(
        "platform",
        facing([p(0., 0.), p(1., 0.), p(1., 1.), p(0., 1.)], DVec3::new(0.5, 0.5, 1.0), false),
        4,
        1,
    );
    merge("L", vec![wall, platform])
}

fn scene() -> Scene {
    // The light as 4 x 4 faces: the kernel sees an emitter through 2 x 2 visibility samples per
    // element, which would draw the penumbra on the split wall as four steps (see the module doc).
    let light = subdivided_quad("light", light_corners(), 4, 2);
    brute_force::grey_black_light(RHO, EXITANCE, vec![l_shape(), light])
}

/// The platform's triangles, for the brute force's shadow rays.
fn platform_triangles() -> Vec<Triangle> {
    let mut l = l_shape();
    l.faces.remove(0);
    brute_force::triangles_of(&l)
}

/// The wall's exact `B` at `(y, z)`.
fn wall_truth(y: f64, z: f64, platform: &[Triangle]) -> f64 {
    let light = Patch::from_corners(&light_corners());
    let p = DVec3::new(1e-9, y, z);
    RHO * EXITANCE * brute_force::direct_light(&light, p, DVec3::X, platform, 32).form_factor
}

#[test]
fn faces_of_one_object_split_at_a_concave_crease() {
    let scene = scene();
    let sys = brute_force::gathered(&scene);
    let wall_elements = sys.elements.iter().filter(|e| e.object == 0 && e.face == 0).count();
    let platform = platform_triangles();
    let object = &scene.objects[0];
    let corners: Vec<DVec3> = object.faces[0].iter().map(|&v| object.vertices[v as usize]).collect();
    let wall = Patch::from_corners(&corners);

    // The wall's polynomials on a 30 x 30 grid of points, against brute force.
    let (mut sq, mut sum, mut min, mut n) = (0.0, 0.0, f64::INFINITY, 0);
    for i in 0..30 {
        for j in 0..30 {
            let (s, t) = ((i as f64 + 0.5) / 30.0, (j as f64 + 0.5) / 30.0);
            let q = wall.point(s, t);
            let (e, ls, lt) = sys.element_of_face(0, 0, s, t).expect("the wall has an element there");
            let ours = sys.eval(e, ls, lt)[0];
            let truth = wall_truth(q.y, q.z, &platform);
            sq += (ours - truth).powi(2);
            sum += truth;
            min = min.min(ours);
            n += 1;
        }
    }
    let wall_error = (sq / n as f64).sqrt() / (sum / n as f64);

    // The platform's corners off the crease row, gathered, against the wall's exact B seen from
    // them (64 x 64 pieces of the wall, midpoint rule).
    let m = 64;
    let pieces: Vec<(DVec3, f64)> = (0..m * m)
        .map(|k| {
            let (y, z) = (((k / m) as f64 + 0.5) / m as f64, ((k % m) as f64 + 0.5) / m as f64);
            (DVec3::new(0.0, y, z), wall_truth(y, z, &platform) / (m * m) as f64)
        })
        .collect();
    let irradiance = sys.corner_irradiance.as_ref().expect("the corners are gathered");
    let (mut sq, mut sum, mut worst, mut count, mut corner) = (0.0, 0.0, 0.0f64, 0, 0);
    for face in &object.faces {
        for &v in face {
            let ours = irradiance[0][corner][0];
            corner += 1;
            let p = object.vertices[v as usize];
            if p.z != 0.0 || p.x < 0.2 {
                continue; // the wall's corners, and the crease row (the kernel's peak at the crease)
            }
            let exact: f64 = pieces
                .iter()
                .map(|(w, b_da)| {
                    let d = *w - p;
                    let r2 = d.length_squared();
                    b_da * d.z * (-d.x) / (std::f64::consts::PI * r2 * r2)
                })
                .sum();
            sq += (ours - exact).powi(2);
            sum += exact;
            worst = worst.max((ours - exact).abs());
            count += 1;
        }
    }
    let mean = sum / count as f64;
    let gather_error = (sq / count as f64).sqrt() / mean;
    let worst = worst / mean;
    eprintln!(
        "wall against brute force: {:.2}% relative RMS error (lowest B {min:.4}, {wall_elements} elements); \
         {count} platform corners' irradiance: {:.2}%, worst {:.2}% (of their mean {mean:.4})",
        100.0 * wall_error,
        100.0 * gather_error,
        100.0 * worst
    );
    assert!(wall_elements > 1, "the wall is split at the crease");
    assert!(wall_error < 0.15, "the wall {wall_error} from brute force (one quadratic: 0.228)");
    assert!(gather_error < 0.05, "the platform's corners {gather_error} from brute force (0.109 unsplit)");
    assert!(worst < 0.10, "the worst platform corner {worst} from brute force (0.237 unsplit)");
}
