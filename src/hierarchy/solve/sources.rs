//! The leaves' sources: each leaf's emission and the lights' `rho E_d` projected on its basis,
//! and the lights' shadow rays kept from frame to frame ([`LeafRays`]).

use rayon::prelude::*;

use super::State;
use crate::geometry::Aabb;
use crate::hierarchy::tree::{NodeId, Tree};
use crate::lights::direct::{DirectLight, KeptRays};
use crate::lights::kept::Outcomes;

/// The lights' shadow rays of the leaves' projections ([`crate::lights::kept`]): this frame's
/// outcomes per node, and the last frame's with what moved since, taken where no move can have
/// changed them.
#[derive(Default)]
pub struct LeafRays {
    /// Per node, its projection's outcomes this frame (empty for inner nodes and clusters).
    now: Vec<Outcomes>,
    last: Option<LastRays>,
    /// Rays traced and taken from the last frame's, over this frame's projections.
    pub counts: KeptRays,
}

struct LastRays {
    outcomes: Vec<Outcomes>,
    /// Per face, whether it moved since.
    moved_faces: Vec<bool>,
    /// Boxes holding the moved faces' old and new places.
    swept: Vec<Aabb>,
    /// Per source, whether it was placed otherwise since ([`DirectLight::changed_sources`]).
    changed: Vec<bool>,
}

impl LeafRays {
    /// The rays to keep after `last`, this frame's of a tree cloned from that frame's (node ids
    /// hold), `lights` casting alike as `last_lights` did ([`DirectLight::changed_sources`]: the
    /// sources placed otherwise cast their rays again); otherwise none are taken.
    pub fn after(
        last: LeafRays,
        (lights, last_lights): (Option<&DirectLight>, Option<&DirectLight>),
        moved_faces: &[bool],
        swept: &[Aabb],
    ) -> Self {
        let changed = match (lights, last_lights) {
            (Some(a), Some(b)) => a.changed_sources(b),
            _ => None,
        };
        let last = changed.map(|changed| LastRays {
            outcomes: last.now,
            moved_faces: moved_faces.to_vec(),
            swept: swept.to_vec(),
            changed,
        });
        LeafRays { now: Vec::new(), last, counts: KeptRays::default() }
    }

    /// This frame's outcomes alone (the last frame's dropped), for the frame to keep.
    pub fn into_kept(self) -> LeafRays {
        LeafRays { now: self.now, ..Default::default() }
    }
}

impl State {
    /// Computes the sources of every leaf that has none yet: the face material's exitance on
    /// `k = 0` and the lights' `rho E_d` projected on the leaf's basis (eq. 4).
    pub fn add_sources(&mut self, tree: &Tree, emission: &[[f64; 3]], lights: Option<&DirectLight>) {
        self.add_sources_keeping(tree, emission, lights, &mut LeafRays::default());
    }

    /// [`State::add_sources`], keeping the leaves' shadow rays in `rays` for the next frame and
    /// taking its last frame's where they hold ([`LeafRays`]): the same sources, bit for bit.
    pub fn add_sources_keeping(
        &mut self,
        tree: &Tree,
        emission: &[[f64; 3]],
        lights: Option<&DirectLight>,
        rays: &mut LeafRays,
    ) {
        let nb = self.nb;
        let todo: Vec<usize> = (0..tree.nodes.len())
            .filter(|&id| {
                !self.has_sources[id]
                    && tree.children(id as NodeId).is_empty()
                    && !tree.nodes[id].is_cluster()
            })
            .collect();
        // (A preview's lights take a coarser rule: `Settings::preview_lights`.)
        let rule = lights.map_or_else(DirectLight::projection_rule, DirectLight::rule);
        let (last, swept) = match (&rays.last, lights) {
            (Some(last), Some(lights)) => (Some(last), lights.swept_for_rays(&last.swept)),
            _ => (None, Vec::new()),
        };
        let changed = last.map_or(&[][..], |l| &l.changed[..]);
        let computed: Vec<(Vec<[f64; 3]>, Outcomes, KeptRays)> = todo
            .par_iter()
            .map(|&id| {
                let s = tree.nodes[id].surface().expect("leaves are surfaces");
                let f = s.face as usize;
                let mut out = vec![[0.0; 3]; nb];
                out[0] = emission[f];
                let Some(lights) = lights else { return (out, Outcomes::default(), KeptRays::default()) };
                // A node's id and patch hold from frame to frame where its face did not move.
                let kept = last.filter(|l| !l.moved_faces[f]).and_then(|l| l.outcomes.get(id));
                let rho = tree.reflectance[f];
                let (outcomes, counts) = lights.project_onto_keeping(
                    &s.patch,
                    s.face,
                    rho,
                    tree.basis,
                    &rule,
                    &mut out,
                    (kept, &swept, changed),
                );
                (out, outcomes, counts)
            })
            .collect();
        if lights.is_some() && rays.now.len() < tree.nodes.len() {
            rays.now.resize_with(tree.nodes.len(), Outcomes::default);
        }
        for (&id, (src, outcomes, counts)) in todo.iter().zip(computed) {
            self.sources[id * nb..(id + 1) * nb].copy_from_slice(&src);
            self.has_sources[id] = true;
            if lights.is_some() {
                rays.now[id] = outcomes;
            }
            rays.counts.add(counts);
        }
    }

    /// The sources' power, `sum over leaves of area x mean source` (largest channel): the
    /// oracle's and the stopping test's reference.
    pub fn source_power(&self, tree: &Tree) -> f64 {
        let nb = self.nb;
        let mut leaves = Vec::new();
        tree.leaves_below(tree.root, &mut leaves);
        leaves
            .iter()
            .map(|&id| {
                let s = tree.nodes[id as usize].surface().expect("leaves are surfaces");
                let src = &self.sources[id as usize * nb..(id as usize + 1) * nb];
                (0..3).map(|c| (0..nb).map(|k| s.moments[k] * src[k][c]).sum::<f64>()).fold(0.0, f64::max)
            })
            .sum()
    }

    /// Largest channel of each node's mean radiosity: the oracle's `B`.
    pub fn radiosity_estimate(&self) -> Vec<f64> {
        self.mean.iter().map(|m| m.iter().copied().fold(0.0, f64::max)).collect()
    }

    /// Forgets every leaf's sources, for a frame whose emission, lights or geometry changed
    /// ([`State::add_sources`] computes them again).
    pub fn clear_sources(&mut self) {
        self.has_sources.iter_mut().for_each(|h| *h = false);
        self.sources.iter_mut().for_each(|s| *s = [0.0; 3]);
    }
}
