//! The hemisphere bound: a furnace (every surface at `B = 1`) gathered with the solve's own links
//! gives each leaf its form factors summed, and a leaf whose sum is too large takes its
//! reflectance scaled down ([`State::bound_leaves`], [`bound_of`]).

use glam::DVec3;
use rayon::prelude::*;

use super::sweep::slope_rows;
use super::{Gathered, State};
use crate::budget;
use crate::error::{Error, Result};
use crate::hierarchy::lobes::{self, Lobes};
use crate::hierarchy::packed::PackedLinks;
use crate::hierarchy::push_pull::{Leaves, NO_SLOPE, Nodes, Walk};
use crate::hierarchy::tree::{Kind, NodeId, Tree};

impl State {
    /// Sets each leaf's hemisphere bound for the links `packed` ([`crate::hemisphere`]): the
    /// form factors from a point to everything it sees sum to at most 1, but the links' can
    /// exceed it (coplanar duplicate or crossing faces, quadrature next to a contact, a near
    /// cluster link's kernel ratio), and above `1 / rho` a surface creates light and the solve
    /// diverges (RenderPark's office: docs/validation-real.md). A leaf's sum `S` is what it
    /// gathers, through its own links and those pushed down from its ancestors, when every
    /// surface is at `B = 1`: one sweep of a furnace with the solve's own gather and push, so
    /// that `S` is the sum the sweeps apply. A leaf then takes its reflectance times
    /// [`bound_of`]`(S)`. What each node gathered is kept with the packing, and gathered again
    /// only at the receivers whose links changed since ([`PackedLinks::changed`]): the furnace
    /// ran before every solve, two or three a frame, and its gather over every cluster link was
    /// most of it on the 30k-triangle monastery (27-48 ms of 50-70). `check`: gather every row
    /// too, and fail where a kept one differs. `leaves`: the tree's. Returns the rows gathered.
    pub(super) fn bound_leaves(
        &mut self,
        tree: &Tree,
        leaves: &[NodeId],
        packed: &mut PackedLinks,
        check: bool,
    ) -> Result<usize> {
        let (nb, n) = (self.nb, tree.nodes.len());
        let what = "the hierarchy's hemisphere bound";
        let mut white = self.white(tree)?;
        let kept = packed.furnace.take();
        let mut changed = std::mem::take(&mut packed.changed);
        let incremental = kept.is_some();
        let mut rows = kept.unwrap_or_else(Gathered::empty);
        let gathered_rows =
            white.furnace_gather(tree, packed, &mut rows, incremental.then_some(&mut changed))?;
        if check {
            let mut whole = Gathered::empty();
            white.furnace_gather(tree, packed, &mut whole, None)?;
            check_rows(&rows, &whole)?;
        }
        let gathered = &rows;
        let zero = [[0.0; 3]; crate::basis::MAX_LEN];
        // The push writes the leaves' `b` and means over the white state's (it reads none of
        // them): the furnace's leaf means are the sums `S`.
        white.b = budget::try_filled(n * nb, [0.0; 3], what)?;
        let walk = Walk {
            tree,
            nodes: Nodes::new(&mut white.b, &mut white.mean, &mut white.lobes, nb),
            // (A furnace has none.)
            sources: &[],
            leaves: Leaves::Furnace,
            two_scale: &white.two_scale,
            nb,
        };
        walk.push(tree.root, (&lobes::ZERO, &NO_SLOPE), &zero[..nb], gathered, 0, false);
        let mut bound = budget::try_filled(n, 1.0, what)?;
        for &id in leaves {
            let face = tree.nodes[id as usize].surface().expect("leaves are surfaces").face;
            let rho = tree.reflectance[face as usize].iter().copied().fold(0.0, f64::max);
            // (The channels alike: the furnace's sources are grey.)
            bound[id as usize] = bound_of(white.mean[id as usize][0], rho);
        }
        self.bound = bound;
        changed.clear();
        (packed.furnace, packed.changed) = (Some(rows), changed);
        Ok(gathered_rows)
    }

    /// The furnace's sources: a state of this one's basis with every surface at `B = 1`, so
    /// that every node's mean is 1 (0 without area) and a cluster's lobes are the sum of its
    /// faces' cosine lobes of intensity `A / pi`: what the pull of `b = (1, 0, ...)` from the
    /// leaves gives, worked out over the clusters and faces alone (that pull through every
    /// quadtree node was a third of a furnace on the moving-light box). Its `b` is empty: the
    /// furnace reads only the sources' means and lobes ([`State::furnace_gather`]).
    /// [`crate::Error::OutOfMemory`] when it cannot be had.
    fn white(&self, tree: &Tree) -> Result<State> {
        let n = tree.nodes.len();
        let what = "the hierarchy's hemisphere bound";
        let mut mean = budget::try_filled(n, [0.0; 3], what)?;
        for (m, node) in mean.iter_mut().zip(&tree.nodes) {
            if node.area > 0.0 {
                *m = [1.0; 3];
            }
        }
        let mut lobes = budget::try_filled(n, lobes::ZERO, what)?;
        // The clusters and faces, parents before children; then set from the faces up.
        let mut order = Vec::new();
        let mut stack = vec![tree.root];
        while let Some(id) = stack.pop() {
            order.push(id);
            if tree.nodes[id as usize].is_cluster() {
                stack.extend_from_slice(tree.children(id));
            }
        }
        for &id in order.iter().rev() {
            let node = &tree.nodes[id as usize];
            let mut l = lobes::ZERO;
            match &node.kind {
                Kind::Cluster { children } => {
                    children.iter().for_each(|&c| lobes::add(&mut l, &lobes[c as usize]))
                }
                Kind::Surface(s) => {
                    let f = node.area / std::f64::consts::PI;
                    lobes::add_lobe(&mut l, s.normal, mean[id as usize].map(|m| m * f));
                }
            }
            lobes[id as usize] = l;
        }
        Ok(State {
            nb: self.nb,
            b: Vec::new(),
            sources: Vec::new(),
            has_sources: Vec::new(),
            mean,
            lobes,
            bound: Vec::new(),
            two_scale: self.two_scale.clone(),
        })
    }

    /// [`State::gather`] for a furnace, a state whose every surface is at `B = 1` (`b = (1, 0,
    /// ...)` at every surface node, the pull keeping the constant): what a receiver's surface
    /// and constant links bring is then a sum the packing keeps (its blocks' first columns and
    /// its `G^00`s, [`crate::hierarchy::packed::ReceivedBlocks::white_of`]), read instead of
    /// every block; cluster links read the sources' means and lobes as a sweep does. Into `out`:
    /// every row, or with `changed` the rows of those receivers and of the nodes `out` does not
    /// hold yet (the others as they are), unless they are a quarter of the nodes or more.
    /// Returns the rows gathered.
    fn furnace_gather(
        &self,
        tree: &Tree,
        packed: &PackedLinks,
        out: &mut Gathered,
        changed: Option<&mut Vec<NodeId>>,
    ) -> Result<usize> {
        let (nb, n) = (self.nb, tree.nodes.len());
        let what = "the hierarchy's gathered light";
        let held = out.lobes.len();
        let some = match changed {
            Some(list) if out.h.len() == held * nb && held <= n => {
                list.extend(held as NodeId..n as NodeId);
                list.sort_unstable();
                list.dedup();
                (list.len() < n / 4).then_some(&*list)
            }
            _ => None,
        };
        let more = n * nb - out.h.len().min(n * nb);
        budget::try_reserve(&mut out.h, more, what)?;
        budget::try_reserve(&mut out.lobes, n - held.min(n), what)?;
        let built = tree.built();
        let more_slopes = built - out.slopes.len().min(built);
        budget::try_reserve(&mut out.slopes, more_slopes, what)?;
        out.h.resize(n * nb, [0.0; 3]);
        out.lobes.resize(n, lobes::ZERO);
        out.slopes.resize(built, [DVec3::ZERO; 3]);
        let Some(rows) = some else {
            let slopes = slope_rows(&mut out.slopes, n);
            out.h.par_chunks_mut(nb).zip(out.lobes.par_iter_mut()).zip(slopes).enumerate().for_each(
                |(r, ((hr, lr), sr))| {
                    let slope = self.furnace_row(tree, packed, r, hr, lr);
                    if let Some(sr) = sr {
                        *sr = slope;
                    }
                },
            );
            return Ok(n);
        };
        let gathered: Vec<([[f64; 3]; crate::basis::MAX_LEN], Lobes, [DVec3; 3])> = rows
            .par_iter()
            .map(|&r| {
                let (mut hr, mut lr) = ([[0.0; 3]; crate::basis::MAX_LEN], lobes::ZERO);
                let slope = self.furnace_row(tree, packed, r as usize, &mut hr[..nb], &mut lr);
                (hr, lr, slope)
            })
            .collect();
        for (&r, (hr, lr, slope)) in rows.iter().zip(gathered) {
            let r = r as usize;
            out.h[r * nb..(r + 1) * nb].copy_from_slice(&hr[..nb]);
            out.lobes[r] = lr;
            if let Some(sr) = out.slopes.get_mut(r) {
                *sr = slope;
            }
        }
        Ok(rows.len())
    }

    /// What receiver `r` gathers in a furnace ([`State::furnace_gather`]), into `hr` and `lr`;
    /// returns its slope (a planar cluster's, [`Gathered::slopes`]).
    fn furnace_row(
        &self,
        tree: &Tree,
        packed: &PackedLinks,
        r: usize,
        hr: &mut [[f64; 3]],
        lr: &mut Lobes,
    ) -> [DVec3; 3] {
        hr.fill([0.0; 3]);
        *lr = lobes::ZERO;
        let mut h0 = [0.0f64; 3];
        let mut slope = [DVec3::ZERO; 3];
        let planar = tree.nodes[r].plane_normal.is_some();
        for blocks in packed.parts() {
            for (h, &w) in hr.iter_mut().zip(blocks.white_of(r)) {
                for c in 0..3 {
                    h[c] += w;
                }
            }
            for e in blocks.clusters_of(r) {
                self.cluster_arrival(e, planar, (&mut h0, &mut slope), lr);
            }
        }
        for c in 0..3 {
            hr[0][c] += h0[c];
        }
        slope
    }
}

/// How far above 1 a leaf's form-factor sum may stay unbounded ([`bound_of`]).
const BOUND_SLACK: f64 = 0.05;

/// The factor a leaf whose links' form factors sum to `sum` takes its reflectance `rho` (its
/// largest channel) with: 1 up to `1 + BOUND_SLACK` (less for a near-white leaf: up to
/// `(1 + rho) / (2 rho)`, so that `rho x sum` stays below `(1 + rho) / 2 < 1`), the flat solve's
/// `1 / sum` above ([`crate::hemisphere::bound`]). Every solve converges either way. The
/// hierarchy's links miss the exact sum by a few percent both ways (the Cornell box's leaves up
/// to 1.08), and bounded from 1 on, the upward half of that error alone went: a closed box at
/// rho 0.95 returned 4.9% less than `E / (1 - rho)`. Coincident faces sum to 2 and more
/// (RenderPark's office: up to 2.6), and are bounded in full.
fn bound_of(sum: f64, rho: f64) -> f64 {
    let kept = if rho > 0.0 { (1.0 + BOUND_SLACK).min((1.0 + rho) / (2.0 * rho)) } else { 1.0 + BOUND_SLACK };
    if sum > kept { 1.0 / sum } else { 1.0 }
}
/// Where the furnace's kept rows ([`State::bound_leaves`]) differ from the same rows gathered
/// whole: by more than the rounding of a source's white state pulled again after a split.
fn check_rows(kept: &Gathered, whole: &Gathered) -> Result<()> {
    let largest = |x: &[f64]| x.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let scale = whole.h.iter().chain(whole.lobes.iter().flatten()).map(|x| largest(x)).fold(1e-300, f64::max);
    let apart = kept.h.len() != whole.h.len()
        || kept.lobes.len() != whole.lobes.len()
        || kept.h.iter().flatten().zip(whole.h.iter().flatten()).any(|(a, b)| (a - b).abs() > 1e-12 * scale)
        || kept.lobes.iter().zip(&whole.lobes).any(|(a, b)| {
            a.iter().flatten().zip(b.iter().flatten()).any(|(x, y)| (x - y).abs() > 1e-12 * scale)
        })
        || slopes_apart(&kept.slopes, &whole.slopes);
    if apart {
        return Err(Error::Internal("the hemisphere bound's kept furnace rows are not the furnace's".into()));
    }
    Ok(())
}

/// Whether two furnaces' slopes differ by more than rounding (of the largest, per unit length).
fn slopes_apart(kept: &[[DVec3; 3]], whole: &[[DVec3; 3]]) -> bool {
    let scale = whole.iter().flatten().map(|g| g.abs().max_element()).fold(1e-300, f64::max);
    kept.len() != whole.len()
        || kept
            .iter()
            .flatten()
            .zip(whole.iter().flatten())
            .any(|(a, b)| (*a - *b).abs().max_element() > 1e-12 * scale)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hierarchy::{HierarchySettings, solve_frame};
    use crate::scene::Settings;
    use crate::system::no_progress;

    /// The furnace's white state ([`State::white`], worked out over the clusters and faces) is
    /// the pull of `b = (1, 0, ...)` from every leaf, and the furnace's own gather on it (no
    /// reads of the sources' rows) is the sweeps' gather of that pulled state: on the decimated
    /// monastery, whose links are of all three kinds.
    #[test]
    fn the_furnace_gather_is_the_gather_of_a_white_state() {
        let path =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/real/monastery_scene.json");
        let mut scene = crate::scene::json::read_scene(&path).unwrap();
        scene.settings = Settings { basis_order: 1, corner_gather: false, ..scene.settings };
        let h = solve_frame(&scene, 0.0, &HierarchySettings::of(&scene.settings), &no_progress).unwrap();
        let s = &h.stats;
        assert!(s.cluster_links > 0 && s.constant_links > 0 && s.surface_links > 0, "{s:?}");
        let (tree, packed) = (&h.hierarchy.tree, h.hierarchy.packed.as_ref().unwrap());
        let white = State::new(tree).white(tree).unwrap();
        let mut pulled = State::new(tree);
        let mut leaves = Vec::new();
        tree.leaves_below(tree.root, &mut leaves);
        for &id in &leaves {
            pulled.b[id as usize * pulled.nb] = [1.0; 3];
        }
        pulled.refresh(tree);
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * (1.0 + a.abs());
        for (x, y) in white.mean.iter().zip(&pulled.mean) {
            assert!((0..3).all(|c| close(x[c], y[c])), "mean {x:?} vs pulled {y:?}");
        }
        let lit = pulled.lobes.iter().filter(|l| l[0][0] != 0.0).count();
        assert!(lit > tree.faces.len(), "only {lit} lobes");
        for (x, y) in white.lobes.iter().zip(&pulled.lobes) {
            assert!((0..9).all(|k| (0..3).all(|c| close(x[k][c], y[k][c]))), "lobe {x:?} vs pulled {y:?}");
        }
        let empty = Gathered::empty;
        let (mut swept, mut furnace) = (empty(), empty());
        pulled.gather(tree, packed, &mut swept).unwrap();
        white.furnace_gather(tree, packed, &mut furnace, None).unwrap();
        let mut nonzero = 0;
        for (x, y) in swept.h.iter().zip(&furnace.h) {
            nonzero += usize::from(x[0] != 0.0);
            assert!((0..3).all(|c| close(x[c], y[c])), "{x:?} vs {y:?}");
        }
        for (x, y) in swept.lobes.iter().zip(&furnace.lobes) {
            assert!((0..9).all(|k| (0..3).all(|c| close(x[k][c], y[k][c]))), "{x:?} vs {y:?}");
        }
        assert!(nonzero > 100, "only {nonzero} nodes gathered anything");
    }
}
