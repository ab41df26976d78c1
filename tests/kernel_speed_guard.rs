//! The fast paths of the kernel build (grouped visibility traversals, per-element facing data,
//! f32 rows handed to the link store) give exactly what the per-pair API the animation update
//! uses gives: `compute_pair` for every pair, bit for bit after the f32 conversion.

use galerkin_radiosity::basis::Basis;
use galerkin_radiosity::geometry::Patch;
use galerkin_radiosity::kernel::PairContext;
use galerkin_radiosity::kernel::assemble::{ElementGeometry, compute_pair};
use galerkin_radiosity::quadrature::GaussLegendre;
use galerkin_radiosity::scene::Settings;
use galerkin_radiosity::scenes;
use galerkin_radiosity::system::{System, no_progress};
use galerkin_radiosity::visibility::Occluders;

#[test]
fn assembled_links_equal_compute_pair() {
    for order in [0, 2] {
        let scene = scenes::cornell_box(5, Settings { basis_order: order, ..Settings::default() });
        let sys = System::build(&scene, 1.0, &no_progress).unwrap();
        let s = &scene.settings;
        let rule = GaussLegendre::new(s.quadrature_order);
        let ctx = PairContext {
            basis: Basis::new(order),
            rule: &rule,
            vis_axis: s.visibility_samples,
            adaptive: s.adaptive_quadrature,
        };
        let patches: Vec<Patch> = sys.elements.iter().map(|e| e.patch).collect();
        let occ = Occluders::new(&patches, s.visibility_samples);
        let geom = ElementGeometry::new(&patches, &ctx);
        let n = patches.len();
        let mut stored = 0;
        for i in 0..n {
            for j in (i + 1)..n {
                let want = compute_pair(&ctx, &geom, Some(&occ), i, j);
                let got = sys.links.find(i as u32, j as u32);
                match (want, got) {
                    (None, None) => {}
                    (Some((c, vis)), Some(p)) => {
                        stored += 1;
                        assert_eq!(sys.links.pair(p).visibility, vis, "pair {i} {j}");
                        let f32s = |v: &[f64]| v.iter().map(|&x| x as f32).collect::<Vec<_>>();
                        assert_eq!(sys.links.block(p, i as u32), f32s(&c.ij), "pair {i} {j}");
                        assert_eq!(sys.links.block(p, j as u32), f32s(&c.ji), "pair {i} {j}");
                    }
                    (w, g) => panic!("pair {i} {j}: compute_pair {:?}, store {:?}", w.is_some(), g),
                }
            }
        }
        assert_eq!(stored, sys.links.len());
    }
}
