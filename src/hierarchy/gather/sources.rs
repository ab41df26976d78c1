//! A point's sources: the links (and blocked pairs) of its leaf and of every ancestor.
//!
//! The push hands what a node gathered down to all its descendants ([`super::super::solve`]), so
//! the links of a corner's leaf, of the surfaces above it up to its face and of the clusters
//! above the face up to the root partition what the corner sees, each source once.
//!
//! A cluster high in the tree links with thousands of nodes, and every corner below it would
//! inherit them all: 4,400 sources a corner on a 10k-face crop of the monastery, most of them
//! dim and far. For the fast gather ([`super::Mode::Fast`]) a cluster's sources are split once
//! per gather into a *head*, the few brightest at the cluster (by the light they would bring its
//! centre unoccluded), which each point takes as its own sources, and a *tail*, summed into
//! irradiance lobes as the solve sums them (each source's intensity towards the cluster times
//! its link's transmittance) and evaluated at each point's normal: the far light through the
//! hierarchy, at the cost of the cluster's shared visibility for what the tail brings.

use rayon::prelude::*;

use crate::error::Result;
use crate::hierarchy::coupling::{Coupling, Link};
use crate::hierarchy::lobes::{self, Lobes};
use crate::hierarchy::packed::Incoming;
use crate::hierarchy::solve::State;
use crate::hierarchy::tree::{Kind, NodeId, Tree};

/// A cluster's head holds its brightest sources until the rest bring at most this share of the
/// light its sources would bring its centre unoccluded...
const HEAD_SHARE: f64 = 0.01;

/// ...or this many. The tail has no visibility from the point: a model's light on itself (its
/// own faces and the ground linked with its cluster) must be in the head. Measured on the bunny
/// at accuracy 1e-4 against Cycles per corner (tests/hierarchy.rs; the exhaustive gather 5.39%):
/// 10% and 16 8.11%, 1% and 64 5.46%, no tail 5.36%. In a room lit indirectly the light is
/// spread over hundreds of sources and 64 cut the head long before the share: the room of
/// tools/validate_real.py on `--hierarchy`, every corner against Cycles, 9.77% with 64, 8.47%
/// with 128, 7.88% with 256, 7.83% with 512 (the exhaustive gather 7.71%), its ceiling 6.87 ->
/// 3.16%; the 10k-face monastery crop's fast gather 512M -> 515M rays (docs/benchmarks.md, "A
/// cluster's head").
const HEAD_MAX: usize = 512;

/// How the solve took a source's light to the receiving node.
#[derive(Clone, Copy, Debug)]
pub enum Via {
    /// Link `index` of [`super::Inputs::links`].
    Link { index: u32 },
    /// A pair whose sampled rays were all blocked: nothing, in the solve.
    Blocked,
}

/// One source of a point.
#[derive(Clone, Copy, Debug)]
pub struct Linked {
    pub source: NodeId,
    pub via: Via,
}

/// A cluster's sources split ([`Sources::each`]): the head, a point's own, and the tail's lobes.
struct Split {
    head: Vec<Linked>,
    tail: Lobes,
}

/// Per node its links and blocked pairs, and its parent.
pub struct Sources<'a> {
    links: &'a [Link],
    blocked_pairs: &'a [(NodeId, NodeId)],
    incoming: Incoming,
    blocked: Incoming,
    /// Per node, its parent (the root's is itself).
    parent: Vec<NodeId>,
    /// Per node, its index in `split`, or `u32::MAX`: a surface, or every source listed.
    split_of: Vec<u32>,
    split: Vec<Split>,
}

impl<'a> Sources<'a> {
    /// The sources of every node; with `split`, the clusters' split into head and tail.
    pub fn new(
        tree: &Tree,
        state: &State,
        links: &'a [Link],
        blocked_pairs: &'a [(NodeId, NodeId)],
        split: bool,
    ) -> Result<Self> {
        let mut parent: Vec<NodeId> = (0..tree.nodes.len() as NodeId).collect();
        for (id, node) in tree.nodes.iter().enumerate() {
            let children: &[NodeId] = match &node.kind {
                Kind::Cluster { children } => children,
                Kind::Surface(s) => s.children.as_ref().map_or(&[], |c| c),
            };
            for &c in children {
                parent[c as usize] = id as NodeId;
            }
        }
        let mut sources = Self {
            links,
            blocked_pairs,
            incoming: Incoming::new(tree.nodes.len(), links)?,
            blocked: Incoming::of_pairs(tree.nodes.len(), blocked_pairs)?,
            parent,
            split_of: vec![u32::MAX; tree.nodes.len()],
            split: Vec::new(),
        };
        if split {
            let clusters: Vec<NodeId> = (0..tree.nodes.len() as NodeId)
                .filter(|&id| tree.node(id).is_cluster() && sources.listed(id).next().is_some())
                .collect();
            sources.split = clusters.par_iter().map(|&id| sources.split_cluster(tree, state, id)).collect();
            for (k, &id) in clusters.iter().enumerate() {
                sources.split_of[id as usize] = k as u32;
            }
        }
        Ok(sources)
    }

    /// Calls `f` with every source of the points of `leaf`, from the leaf up to the root (links
    /// before blocked pairs at each node; of a split cluster its head), and `tail` with each
    /// split cluster's tail lobes; stops early when `f` returns `false`.
    pub fn each(&self, leaf: NodeId, mut f: impl FnMut(Linked) -> bool, mut tail: impl FnMut(&Lobes)) {
        let mut node = leaf;
        loop {
            match self.split.get(self.split_of[node as usize] as usize) {
                Some(split) => {
                    tail(&split.tail);
                    for &linked in &split.head {
                        if !f(linked) {
                            return;
                        }
                    }
                }
                None => {
                    for linked in self.listed(node) {
                        if !f(linked) {
                            return;
                        }
                    }
                }
            }
            let up = self.parent[node as usize];
            if up == node {
                return;
            }
            node = up;
        }
    }

    /// The sources node `receiver` is linked with, links first.
    fn listed(&self, receiver: NodeId) -> impl Iterator<Item = Linked> + '_ {
        let links = self.incoming.of(receiver as usize).iter().map(move |&(index, side)| {
            let link = &self.links[index as usize];
            let source = if side == 0 { link.b } else { link.a };
            Linked { source, via: Via::Link { index } }
        });
        let blocked = self.blocked.of(receiver as usize).iter().map(move |&(k, side)| {
            let (a, b) = self.blocked_pairs[k as usize];
            let source = if side == 0 { b } else { a };
            Linked { source, via: Via::Blocked }
        });
        links.chain(blocked)
    }

    /// The cluster `id`'s sources split into head and tail (see the module's comment), with the
    /// solve's cluster transfer: a planar source's exact cosine, another's intensity lobes,
    /// towards the centre.
    fn split_cluster(&self, tree: &Tree, state: &State, id: NodeId) -> Split {
        let receiver = tree.node(id);
        // (source, direction towards the receiver, intensity / d^2, transmittance, ranking)
        let mut valued: Vec<(Linked, glam::DVec3, [f64; 3], f64, f64)> = self
            .listed(id)
            .filter_map(|linked| {
                let s = tree.node(linked.source);
                let v = receiver.centre - s.centre;
                let d2 = v.length_squared();
                if d2 <= 0.0 {
                    return None;
                }
                let w = v / d2.sqrt();
                let intensity = match s.plane_normal {
                    Some(n) => {
                        let f = s.area * n.dot(w).max(0.0) / std::f64::consts::PI;
                        state.mean[linked.source as usize].map(|m| m * f)
                    }
                    None => lobes::eval(state.lobes(linked.source), w),
                };
                let arriving = intensity.map(|i| i / d2);
                let t = match linked.via {
                    Via::Link { index, .. } => match &self.links[index as usize].coupling {
                        Coupling::Clusters { transmittance, .. } => *transmittance as f64,
                        // (A cluster receives through cluster links only.)
                        Coupling::Surfaces(_) | Coupling::Constants { .. } => 1.0,
                    },
                    Via::Blocked => 0.0,
                };
                Some((linked, w, arriving, t, arriving.iter().sum::<f64>()))
            })
            .collect();
        valued.sort_unstable_by(|a, b| b.4.total_cmp(&a.4));
        let mut rest: f64 = valued.iter().map(|v| v.4).sum();
        let bar = HEAD_SHARE * rest;
        let mut split = Split { head: Vec::new(), tail: lobes::ZERO };
        for (linked, w, arriving, t, value) in valued {
            if rest > bar && split.head.len() < HEAD_MAX && value > 0.0 {
                split.head.push(linked);
            } else if t > 0.0 {
                lobes::add_lobe(&mut split.tail, -w, arriving.map(|a| a * t));
            }
            rest -= value;
        }
        split
    }
}
