//! Closed-form form factors (Howell's catalogue, ../shared/notes/references.md).

use galerkin_radiosity::basis::Basis;
use galerkin_radiosity::geometry::{Patch, Rect};
use galerkin_radiosity::kernel::samples::Samples;
use galerkin_radiosity::kernel::{PairContext, integrate_pair};
use galerkin_radiosity::quadrature::GaussLegendre;
use galerkin_radiosity::visibility::Visibility;
use glam::DVec3;

/// Patch-to-patch form factors `(F_ij, F_ji)` from the constant-basis kernel coefficient: for a
/// parallelogram receiver `G_ij^00 = F_ij`.
fn form_factors(pi: &Patch, pj: &Patch, order: usize) -> (f64, f64) {
    let rule = GaussLegendre::new(order);
    let ctx = PairContext { basis: Basis::new(0), rule: &rule, vis_axis: 1, adaptive: false };
    let si = Samples::new(pi, &Rect::UNIT, &rule, ctx.basis, 1);
    let sj = Samples::new(pj, &Rect::UNIT, &rule, ctx.basis, 1);
    let c = integrate_pair(&ctx, pi, pj, |second, _| if second { &sj } else { &si }, &Visibility::Full);
    (c.ij[0], c.ji[0])
}

fn quad(p: [[f64; 3]; 4]) -> Patch {
    Patch::from_corners(&p.map(DVec3::from_array))
}

fn howell_parallel(a: f64, b: f64, c: f64) -> f64 {
    let (x, y) = (a / c, b / c);
    let pi = std::f64::consts::PI;
    2.0 / (pi * x * y)
        * ((((1.0 + x * x) * (1.0 + y * y)) / (1.0 + x * x + y * y)).sqrt().ln()
            + x * (1.0 + y * y).sqrt() * (x / (1.0 + y * y).sqrt()).atan()
            + y * (1.0 + x * x).sqrt() * (y / (1.0 + x * x).sqrt()).atan()
            - x * x.atan()
            - y * y.atan())
}

#[test]
fn parallel_opposed_rectangles_match_howell_c11() {
    for &(a, b, c, want) in &[(1.0, 1.0, 1.0, 0.199825), (1.0, 1.5, 0.5, 0.475576), (2.0, 1.0, 3.0, 0.060331)]
    {
        assert!((howell_parallel(a, b, c) - want).abs() < 1e-6);
        // Receiver at z = 0 facing +z, source at z = c facing -z.
        let lo = quad([[0.0, 0.0, 0.0], [a, 0.0, 0.0], [a, b, 0.0], [0.0, b, 0.0]]);
        let hi = quad([[0.0, 0.0, c], [0.0, b, c], [a, b, c], [a, 0.0, c]]);
        let (f, back) = form_factors(&lo, &hi, 4);
        let rel = (f - want).abs() / want;
        eprintln!("C-11 ({a},{b},{c}): {f:.6} vs {want}, rel {rel:.2e}");
        assert!(rel < 1e-3, "F = {f}, want {want}");
        assert!((back - f).abs() < 1e-9, "equal areas: F_ji = F_ij");
    }
}

#[test]
fn perpendicular_rectangles_sharing_an_edge_match_howell_c14() {
    for &(w, h, l, want) in &[(1.0, 1.0, 1.0, 0.200044), (1.0, 2.0, 1.0, 0.232853)] {
        // Floor w x l (x in [0,w], y in [0,l]) facing +z; wall h x l at x = 0 facing +x.
        let floor = quad([[0.0, 0.0, 0.0], [w, 0.0, 0.0], [w, l, 0.0], [0.0, l, 0.0]]);
        let wall = quad([[0.0, 0.0, 0.0], [0.0, l, 0.0], [0.0, l, h], [0.0, 0.0, h]]);
        let (f, back) = form_factors(&floor, &wall, 4);
        let rel = (f - want).abs() / want;
        eprintln!("C-14 ({w},{h},{l}): {f:.6} vs {want}, rel {rel:.2e}");
        assert!(rel < 1e-3, "F = {f}, want {want}");
        // Reciprocity: A_i F_ij = A_j F_ji.
        assert!((w * l * f - h * l * back).abs() < 1e-3 * w * l * f);
    }
}

/// In a closed cube every patch's form factors sum to 1 (issue 2: within 0.1%), including the
/// near-singular pairs that share an edge or a corner. Patches are squares, so `G_ij^00 = F_ij`.
#[test]
fn closed_cube_form_factors_sum_to_one() {
    use galerkin_radiosity::scene::Settings;
    use galerkin_radiosity::scenes;
    use galerkin_radiosity::system::{System, no_progress};
    for n in [1, 2, 4] {
        let scene = scenes::closed_box(n, 0.5, 1.0, Settings { basis_order: 0, ..Settings::default() });
        let sys = System::build(&scene, 1.0, &no_progress).unwrap();
        let mut sums = vec![0.0f64; sys.elements.len()];
        for p in 0..sys.links.len() as u32 {
            let pair = sys.links.pair(p);
            sums[pair.a as usize] += sys.links.block(p, pair.a)[0] as f64;
            sums[pair.b as usize] += sys.links.block(p, pair.b)[0] as f64;
        }
        let worst = sums.iter().map(|s| (s - 1.0).abs()).fold(0.0, f64::max);
        eprintln!("cube {n}x{n} per face: worst |sum F - 1| = {worst:.1e}");
        assert!(worst < 1e-3, "{n}: {worst}");
    }
}
