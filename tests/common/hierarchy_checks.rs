//! Checks of a hierarchical frame shared by the hierarchy's tests (tests/hierarchy/update.rs)
//! and the randomized differential test (tests/animation_random.rs): its stored pairs are what a
//! fresh computation on its geometry gives, they partition the pairs of leaves, and the pair
//! tree's leaves are they.

use galerkin_radiosity::hierarchy::coupling::{self, Coupling, Weight};
use galerkin_radiosity::hierarchy::touch;
use galerkin_radiosity::hierarchy::tree::NodeId;
use galerkin_radiosity::hierarchy::{HierarchicalFrame, HierarchySettings, Lighting, link_context};
use galerkin_radiosity::quadrature::GaussLegendre;
use galerkin_radiosity::scene::Scene;

/// Every link of `h` recomputed from scratch on `scene` at `frame` (new occluders, new context)
/// gives the very coupling the link holds; every blocked pair is still blocked and every idle
/// pair still carries nothing. Returns how many of each were checked.
pub fn check_pairs(
    h: &HierarchicalFrame,
    scene: &Scene,
    frame: f64,
    hs: &HierarchySettings,
) -> (usize, usize, usize) {
    let tree = &h.hierarchy.tree;
    let lit = Lighting::new(scene, frame, &tree.faces);
    let rule = GaussLegendre::new(scene.settings.quadrature_order);
    let ctx = link_context(scene, hs, &rule, lit.occluders.as_ref());
    for l in &h.hierarchy.links {
        let weight = match l.coupling {
            Coupling::Constants { .. } => Weight::Light,
            _ => Weight::Full,
        };
        let c = coupling::compute_as(&ctx, tree, l.a, l.b, weight);
        let fresh =
            c.coupling.unwrap_or_else(|| panic!("link {}-{} carries nothing when computed again", l.a, l.b));
        match (&l.coupling, &fresh) {
            (Coupling::Surfaces(x), Coupling::Surfaces(y)) => {
                assert_eq!(x, y, "frame {frame}: surface link {}-{} is stale", l.a, l.b)
            }
            (Coupling::Constants { ab: x, ba: u }, Coupling::Constants { ab: y, ba: v }) => {
                assert_eq!((x, u), (y, v), "frame {frame}: light link {}-{} is stale", l.a, l.b)
            }
            (
                Coupling::Clusters { transmittance: x, partial: p },
                Coupling::Clusters { transmittance: y, partial: q },
            ) => {
                assert_eq!((x, p), (y, q), "frame {frame}: cluster link {}-{} is stale", l.a, l.b)
            }
            _ => panic!("frame {frame}: link {}-{} changed kind", l.a, l.b),
        }
    }
    // A blocked or idle pair does not say whether it was computed light or in full: it must be
    // so under one of the two.
    let under_either = |a, b, test: &dyn Fn(&coupling::Computed) -> bool| {
        [Weight::Light, Weight::Full].into_iter().any(|w| test(&coupling::compute_as(&ctx, tree, a, b, w)))
    };
    for &(a, b) in &h.hierarchy.blocked {
        assert!(
            under_either(a, b, &|c| c.coupling.is_none() && c.blocked),
            "frame {frame}: blocked pair {a}-{b} is not blocked now"
        );
    }
    for &(a, b) in &h.hierarchy.idle_pairs() {
        assert!(
            under_either(a, b, &|c| c.coupling.is_none()),
            "frame {frame}: idle pair {a}-{b} carries light now"
        );
    }
    (h.hierarchy.links.len(), h.hierarchy.blocked.len(), h.hierarchy.idle_pairs().len())
}

/// Links, blocked and idle pairs together cover every pair of leaves of different faces exactly
/// once (as a pair of a node above each): nothing is linked twice, nothing is lost.
pub fn check_partition(h: &HierarchicalFrame) {
    let tree = &h.hierarchy.tree;
    let mut leaves = Vec::new();
    tree.leaves_below(tree.root, &mut leaves);
    let mut index = vec![usize::MAX; tree.nodes.len()];
    for (i, &l) in leaves.iter().enumerate() {
        index[l as usize] = i;
    }
    // Each pair adds one to every pair of leaves below its two ends: a dense count, L^2 work in
    // all when the pairs partition.
    let n = leaves.len();
    let mut count = vec![0u8; n * n];
    let pairs = h.hierarchy.links.iter().map(|l| (l.a, l.b)).chain(h.hierarchy.blocked.iter().copied());
    let (mut below_a, mut below_b) = (Vec::new(), Vec::new());
    for (a, b) in pairs.chain(h.hierarchy.idle_pairs()) {
        below_a.clear();
        below_b.clear();
        tree.leaves_below(a, &mut below_a);
        tree.leaves_below(b, &mut below_b);
        for &p in &below_a {
            for &q in &below_b {
                // A node paired with itself (a cluster's own interactions) covers each pair once.
                if a == b && p >= q {
                    continue;
                }
                let (i, j) =
                    (index[p as usize].min(index[q as usize]), index[p as usize].max(index[q as usize]));
                count[i * n + j] = count[i * n + j].saturating_add(1);
            }
        }
    }
    let face = |id: NodeId| tree.node(id).surface().unwrap().face;
    for i in 0..n {
        for j in i + 1..n {
            let want = u8::from(face(leaves[i]) != face(leaves[j]));
            let got = count[i * n + j];
            assert_eq!(got, want, "leaves {} and {} are covered {got} times", leaves[i], leaves[j]);
        }
    }
}

/// With the pair tree kept, its leaves are the stored pairs (links, blocked, idle), each once:
/// the record an update coarsens by is the refinement that made the pairs.
pub fn check_pair_tree(h: &HierarchicalFrame) {
    let tree = &h.hierarchy.tree;
    let Some(mut leaves) = h.hierarchy.splits.leaves(tree, |a, b| touch::neutral(tree, a, b)) else { return };
    let mut stored: Vec<(NodeId, NodeId)> = h.hierarchy.links.iter().map(|l| (l.a, l.b)).collect();
    stored.extend(&h.hierarchy.blocked);
    stored.extend(&h.hierarchy.idle_pairs());
    leaves.sort_unstable();
    stored.sort_unstable();
    assert!(!leaves.is_empty(), "an empty pair tree");
    assert_eq!(leaves, stored, "the pair tree's leaves are not the stored pairs");
}
