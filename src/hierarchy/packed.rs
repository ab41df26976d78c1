//! How the solve reads the links: packed by receiver, in the order a sweep reads them, and kept
//! from solve to solve and frame to frame ([`PackedLinks`]) so that a frame packs only what it
//! changed. Packing all 15M links of the full monastery took 1.2-1.3 s, twice an updated frame
//! (one solve per link-and-solve round), as long as its five sweeps.

use rayon::prelude::*;

use super::coupling::{Coupling, Link};
use super::solve::Gathered;
use super::tree::NodeId;
use crate::budget;
use crate::error::Result;

/// A cluster link as its receiver gathers it (eq. 1 with the source's intensity), the geometry
/// between the two nodes' centres worked out when the link is packed: neither end moves while the
/// link lives (a move takes out every link of a node holding a moved face,
/// [`super::update`]). Worked out in every sweep (a square root, and both nodes' records read at
/// random), it was a sixth of an updated frame of a 30k-triangle model.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClusterEntry {
    pub source: NodeId,
    /// The unit direction from the source's centre to the receiver's.
    pub w: [f32; 3],
    /// A planar source's projected area over pi towards `w` (its intensity is its mean radiosity
    /// times this); negative for a source that shoots through its lobes.
    pub emit: f32,
    /// What an intensity becomes at the receiver: the transmittance over `d^2`, times the
    /// cosine at the receiver when it is planar. Zero: a link taken out.
    pub scale: f32,
    /// For a planar cluster receiver, the relative slope of what arrives over its plane at its
    /// centroid (`grad H / H`, per unit length; [`crate::hierarchy::solve::cluster_entry`]);
    /// zero for any other.
    pub slope: [f32; 3],
}

impl ClusterEntry {
    /// An entry that delivers nothing (a link taken out, or ends at one place), from `source`.
    pub fn none(source: NodeId) -> Self {
        Self { source, w: [0.0; 3], emit: 0.0, scale: 0.0, slope: [0.0; 3] }
    }
}

/// How a packing works out a [`ClusterEntry`]: `(receiver, source, transmittance)`.
pub type ClusterGeometry<'a> = &'a (dyn Fn(NodeId, NodeId, f32) -> ClusterEntry + Sync);

/// Per node, the links it receives through: `(link, side)`, side 0 when it is the link's `a`.
pub struct Incoming {
    offsets: Vec<usize>,
    entries: Vec<(u32, u8)>,
}

impl Incoming {
    /// [`crate::Error::OutOfMemory`] when its lists cannot be had.
    pub fn new(nodes: usize, links: &[Link]) -> Result<Self> {
        let pairs: Vec<(NodeId, NodeId)> = budget::try_vec(links.len(), "the hierarchy's incoming links")?;
        let mut pairs = pairs;
        pairs.extend(links.iter().map(|l| (l.a, l.b)));
        Self::of_pairs(nodes, &pairs)
    }

    /// Per node, the pairs `(a, b)` of `pairs` it is an end of: `(pair, side)`;
    /// [`crate::Error::OutOfMemory`] when its lists cannot be had.
    pub fn of_pairs(nodes: usize, pairs: &[(NodeId, NodeId)]) -> Result<Self> {
        let what = "the hierarchy's incoming links";
        let mut count = budget::try_filled(nodes + 1, 0usize, what)?;
        for &(a, b) in pairs {
            count[a as usize + 1] += 1;
            count[b as usize + 1] += 1;
        }
        for i in 0..nodes {
            count[i + 1] += count[i];
        }
        let mut fill = budget::try_vec(count.len(), what)?;
        fill.extend_from_slice(&count);
        let mut entries = budget::try_filled(2 * pairs.len(), (0u32, 0u8), what)?;
        for (k, &(a, b)) in pairs.iter().enumerate() {
            for (node, side) in [(a, 0u8), (b, 1u8)] {
                entries[fill[node as usize]] = (k as u32, side);
                fill[node as usize] += 1;
            }
        }
        Ok(Self { offsets: count, entries })
    }

    pub(crate) fn of(&self, node: usize) -> &[(u32, u8)] {
        &self.entries[self.offsets[node]..self.offsets[node + 1]]
    }
}

/// Per receiving node, the blocks of its surface links (its side's `nb x nb`, row = its own
/// function) packed one after the other, with each link's source, its constant links' `G^00`
/// with theirs, and its cluster links' sources with their transmittance: a sweep reads them in
/// order and never the links themselves.
pub struct ReceivedBlocks {
    /// `offsets[r]..offsets[r + 1]`: node `r`'s links in `sources` (and, times `nb^2`, in `blocks`).
    offsets: Vec<usize>,
    sources: Vec<NodeId>,
    blocks: Vec<f32>,
    /// `constant_offsets[r]..constant_offsets[r + 1]`: node `r`'s constant links in `constants`.
    constant_offsets: Vec<usize>,
    constants: Vec<(NodeId, f32)>,
    /// `cluster_offsets[r]..cluster_offsets[r + 1]`: node `r`'s cluster links in `clusters`.
    /// (Looked up in the links, every incoming entry cost a cache miss: with the couplings'
    /// own passes, 15% of an updated frame of the full monastery.)
    cluster_offsets: Vec<usize>,
    clusters: Vec<ClusterEntry>,
    /// Per receiver (`nb` each), what its surface and constant links bring it from sources at
    /// `B = 1`: the first column of each block, and each constant link's `G^00` in the first
    /// row. The hemisphere bound's furnace reads these instead of every block
    /// ([`super::solve::State::bound_leaves`]).
    white: Vec<f64>,
    nb: usize,
}

impl ReceivedBlocks {
    /// The surface links' blocks by receiver, in [`Incoming`]'s order; [`crate::Error::OutOfMemory`]
    /// when the copy cannot be had.
    pub fn new(links: &[Link], incoming: &Incoming, nb: usize, geometry: ClusterGeometry) -> Result<Self> {
        let what = "the hierarchy's links packed for the solve";
        let nodes = incoming.offsets.len() - 1;
        let nb2 = nb * nb;
        // In parallel, counts then copies, each run of receivers written by one thread: the
        // links are read at random (a surface link's blocks are boxed), and done in turn this
        // took a third of the full monastery's solve (5.0 of 14.7 s; 2.8 s on two threads).
        let counts: Vec<[usize; 3]> = (0..nodes)
            .into_par_iter()
            .map(|r| {
                incoming.of(r).iter().fold([0; 3], |[s, c, x], &(l, _)| match links[l as usize].coupling {
                    Coupling::Surfaces(_) => [s + 1, c, x],
                    Coupling::Constants { .. } => [s, c + 1, x],
                    Coupling::Clusters { .. } => [s, c, x + 1],
                })
            })
            .collect();
        let mut offsets = budget::try_vec(nodes + 1, what)?;
        let mut constant_offsets = budget::try_vec(nodes + 1, what)?;
        let mut cluster_offsets = budget::try_vec(nodes + 1, what)?;
        let (mut count, mut constant_count, mut cluster_count) = (0, 0, 0);
        for &[s, c, x] in &counts {
            offsets.push(count);
            constant_offsets.push(constant_count);
            cluster_offsets.push(cluster_count);
            (count, constant_count, cluster_count) = (count + s, constant_count + c, cluster_count + x);
        }
        offsets.push(count);
        constant_offsets.push(constant_count);
        cluster_offsets.push(cluster_count);
        let mut sources = budget::try_filled(count, 0 as NodeId, what)?;
        let mut blocks = budget::try_filled(count.saturating_mul(nb2), 0.0f32, what)?;
        let mut constants = budget::try_filled(constant_count, (0 as NodeId, 0.0f32), what)?;
        let mut clusters = budget::try_filled(cluster_count, ClusterEntry::none(0), what)?;
        let mut white = budget::try_filled(nodes * nb, 0.0f64, what)?;
        // Receivers in runs of `RUN`, each run's part of the five outputs split off in order.
        const RUN: usize = 4096;
        let mut runs = Vec::with_capacity(nodes.div_ceil(RUN));
        let (mut src, mut blk) = (&mut sources[..], &mut blocks[..]);
        let (mut con, mut clu) = (&mut constants[..], &mut clusters[..]);
        let mut wht = &mut white[..];
        for r0 in (0..nodes).step_by(RUN) {
            let r1 = (r0 + RUN).min(nodes);
            let n = offsets[r1] - offsets[r0];
            let m = constant_offsets[r1] - constant_offsets[r0];
            let x = cluster_offsets[r1] - cluster_offsets[r0];
            let (s_run, s_rest) = std::mem::take(&mut src).split_at_mut(n);
            let (b_run, b_rest) = std::mem::take(&mut blk).split_at_mut(n * nb2);
            let (c_run, c_rest) = std::mem::take(&mut con).split_at_mut(m);
            let (x_run, x_rest) = std::mem::take(&mut clu).split_at_mut(x);
            let (w_run, w_rest) = std::mem::take(&mut wht).split_at_mut((r1 - r0) * nb);
            (src, blk, con, clu, wht) = (s_rest, b_rest, c_rest, x_rest, w_rest);
            runs.push((r0..r1, s_run, b_run, c_run, x_run, w_run));
        }
        runs.into_par_iter().for_each(|(receivers, src, blk, con, clu, wht)| {
            let (mut k, mut j, mut i) = (0, 0, 0);
            let first = receivers.start;
            for r in receivers {
                let white = &mut wht[(r - first) * nb..(r - first + 1) * nb];
                for &(l, side) in incoming.of(r) {
                    let link = &links[l as usize];
                    let source = if side == 0 { link.b } else { link.a };
                    match &link.coupling {
                        Coupling::Surfaces(both) => {
                            let side = side as usize;
                            src[k] = source;
                            let block = &both[side * nb2..(side + 1) * nb2];
                            blk[k * nb2..(k + 1) * nb2].copy_from_slice(block);
                            for (w, row) in white.iter_mut().zip(block.chunks_exact(nb)) {
                                *w += row[0] as f64;
                            }
                            k += 1;
                        }
                        Coupling::Constants { ab, ba } => {
                            let g = if side == 0 { *ab } else { *ba };
                            con[j] = (source, g);
                            white[0] += g as f64;
                            j += 1;
                        }
                        Coupling::Clusters { transmittance, .. } => {
                            clu[i] = geometry(r as NodeId, source, *transmittance);
                            i += 1;
                        }
                    }
                }
            }
        });
        Ok(Self {
            offsets,
            sources,
            blocks,
            constant_offsets,
            constants,
            cluster_offsets,
            clusters,
            white,
            nb,
        })
    }

    /// Receivers it has runs for (nodes added since have none).
    fn nodes(&self) -> usize {
        self.offsets.len() - 1
    }

    /// Entries it holds (one per link and side).
    fn entries(&self) -> usize {
        self.sources.len() + self.constants.len() + self.clusters.len()
    }

    /// Node `r`'s surface links: their sources and their blocks, `nb^2` each.
    pub(crate) fn of(&self, r: usize) -> (&[NodeId], &[f32]) {
        if r >= self.nodes() {
            return (&[], &[]);
        }
        let (a, b) = (self.offsets[r], self.offsets[r + 1]);
        let nb2 = self.nb * self.nb;
        (&self.sources[a..b], &self.blocks[a * nb2..b * nb2])
    }

    /// Node `r`'s constant links: their sources and `G^00`.
    pub(crate) fn constants_of(&self, r: usize) -> &[(NodeId, f32)] {
        if r >= self.nodes() {
            return &[];
        }
        &self.constants[self.constant_offsets[r]..self.constant_offsets[r + 1]]
    }

    /// What node `r`'s surface and constant links bring it from sources at `B = 1` (`nb`
    /// coefficients; none for a node added since).
    pub(crate) fn white_of(&self, r: usize) -> &[f64] {
        if r >= self.nodes() {
            return &[];
        }
        &self.white[r * self.nb..(r + 1) * self.nb]
    }

    /// Node `r`'s cluster links.
    pub(crate) fn clusters_of(&self, r: usize) -> &[ClusterEntry] {
        if r >= self.nodes() {
            return &[];
        }
        &self.clusters[self.cluster_offsets[r]..self.cluster_offsets[r + 1]]
    }

    /// Zeroes what receiver `r` gets from `s` (the link between them was taken out): `true` when
    /// it held such an entry. The entry's source becomes `r` itself, which no link joins to
    /// itself, so that a sweep reads a valid node and a later search for a source never finds it.
    fn zero(&mut self, receiver: NodeId, s: NodeId) -> bool {
        let r = receiver as usize;
        if r >= self.nodes() {
            return false;
        }
        let nb2 = self.nb * self.nb;
        let (a, b) = (self.offsets[r], self.offsets[r + 1]);
        if let Some(k) = self.sources[a..b].iter().position(|&x| x == s) {
            let block = &self.blocks[(a + k) * nb2..(a + k + 1) * nb2];
            for (w, row) in
                self.white[r * self.nb..(r + 1) * self.nb].iter_mut().zip(block.chunks_exact(self.nb))
            {
                *w -= row[0] as f64;
            }
            self.blocks[(a + k) * nb2..(a + k + 1) * nb2].fill(0.0);
            self.sources[a + k] = receiver;
            return true;
        }
        let (a, b) = (self.constant_offsets[r], self.constant_offsets[r + 1]);
        if let Some(e) = self.constants[a..b].iter_mut().find(|e| e.0 == s) {
            self.white[r * self.nb] -= e.1 as f64;
            *e = (receiver, 0.0);
            return true;
        }
        let (a, b) = (self.cluster_offsets[r], self.cluster_offsets[r + 1]);
        // (A cluster link from the receiver itself is skipped by the sweep: no distance.)
        if let Some(e) = self.clusters[a..b].iter_mut().find(|e| e.source == s) {
            *e = ClusterEntry::none(receiver);
            return true;
        }
        false
    }
}

/// What changed in [`super::refine::Hierarchy::links`] since [`PackedLinks`] last packed them:
/// every change to the links is recorded here by the hierarchy that makes it.
#[derive(Default)]
pub struct LinkChanges {
    /// The pairs of packed links taken out since.
    removed: Vec<(NodeId, NodeId)>,
    /// `links[fresh..]` were made since (links are only appended, and taking some out keeps the
    /// others' order).
    fresh: usize,
    /// Both ends of every link taken out since (packed or made since): receivers whose furnace
    /// rows the hemisphere bound must gather again ([`PackedLinks::furnace`]).
    ends: Vec<NodeId>,
    /// `links[unread..]` were made since [`PackedLinks::update`] last read the changes (a part
    /// of those since the packing, `links[fresh..]`): their ends are the furnace's too.
    unread: usize,
}

impl LinkChanges {
    /// Records that the links at `gone` (ascending indices) were taken out of `links` (not yet
    /// done).
    pub fn removing(&mut self, links: &[Link], gone: &[usize]) {
        let fresh = self.fresh.min(links.len());
        let before = self.removed.len();
        let packed = gone.iter().take_while(|&&i| i < fresh);
        self.removed.extend(packed.map(|&i| (links[i].a, links[i].b)));
        self.ends.extend(gone.iter().flat_map(|&i| [links[i].a, links[i].b]));
        let unread = self.unread.min(links.len());
        self.unread = unread - gone.iter().take_while(|&&i| i < unread).count();
        // The fresh ones now start where the packed ones left end.
        self.fresh = fresh - (self.removed.len() - before);
    }
}

/// The links as the sweeps read them: a packing of every link at some point (`main`), with the
/// entries of links taken out since zeroed in place, and the links made since packed apart
/// (`fresh`). Packed whole again once the changes reach a quarter of it.
pub struct PackedLinks {
    main: ReceivedBlocks,
    fresh: Option<ReceivedBlocks>,
    /// Entries of `main` zeroed.
    zeroed: usize,
    /// What the hemisphere bound's furnace gathered per node when it last ran, and the receivers
    /// whose links changed since ([`super::solve::State::bound_leaves`] gathers only theirs
    /// again; `None`: every row). Kept with the packing, from solve to solve and frame to frame,
    /// as it is: a row is what the node's links bring it.
    pub(super) furnace: Option<Gathered>,
    pub(super) changed: Vec<NodeId>,
}

impl PackedLinks {
    /// Every link of `links` packed anew; `changes` start from here.
    pub fn new(
        nodes: usize,
        links: &[Link],
        nb: usize,
        changes: &mut LinkChanges,
        geometry: ClusterGeometry,
    ) -> Result<Self> {
        let main = ReceivedBlocks::new(links, &Incoming::new(nodes, links)?, nb, geometry)?;
        *changes =
            LinkChanges { removed: Vec::new(), fresh: links.len(), ends: Vec::new(), unread: links.len() };
        Ok(Self { main, fresh: None, zeroed: 0, furnace: None, changed: Vec::new() })
    }

    /// Brings `packed` to `links` as `changes` say they changed, or packs them anew (none yet,
    /// another basis, or changes past a quarter of it, or `links` not as the changes say);
    /// [`crate::Error::OutOfMemory`] when a packing cannot be had.
    pub fn update(
        packed: &mut Option<Self>,
        nodes: usize,
        links: &[Link],
        nb: usize,
        changes: &mut LinkChanges,
        geometry: ClusterGeometry,
    ) -> Result<()> {
        let current = packed.take().filter(|p| p.main.nb == nb);
        let Some(mut p) = current else {
            *packed = Some(Self::new(nodes, links, nb, changes, geometry)?);
            return Ok(());
        };
        // The receivers whose rows the furnace must gather again: the ends of the links taken
        // out, and of those made since the changes were last read.
        let consistent = changes.fresh <= links.len() && changes.unread <= links.len();
        let made = &links[changes.unread.min(links.len())..];
        let more = changes.ends.len() + 2 * made.len();
        budget::try_reserve(&mut p.changed, more, "the hierarchy's changed receivers")?;
        p.changed.append(&mut changes.ends);
        p.changed.extend(made.iter().flat_map(|l| [l.a, l.b]));
        changes.unread = links.len();
        let fresh = links.len().saturating_sub(changes.fresh);
        let zeroed = p.zeroed + 2 * changes.removed.len();
        let live = p.main.entries().checked_sub(zeroed);
        // Each link is two entries (one per side); `links` not as the changes say, or more than
        // a quarter changed: pack anew (the furnace's rows kept, unless the changes were wrong).
        let trusted = consistent && live == Some(2 * changes.fresh);
        if !trusted || 4 * (zeroed + 2 * fresh) > p.main.entries() {
            let mut anew = Self::new(nodes, links, nb, changes, geometry)?;
            if trusted {
                (anew.furnace, anew.changed) = (p.furnace.take(), std::mem::take(&mut p.changed));
            }
            *packed = Some(anew);
            return Ok(());
        }
        for &(a, b) in &changes.removed {
            let found = p.main.zero(a, b) & p.main.zero(b, a);
            debug_assert!(found, "a packed link {a}-{b} taken out was not packed");
        }
        p.zeroed = zeroed;
        changes.removed.clear();
        let new = &links[changes.fresh..];
        p.fresh = if new.is_empty() {
            None
        } else {
            Some(ReceivedBlocks::new(new, &Incoming::new(nodes, new)?, nb, geometry)?)
        };
        *packed = Some(p);
        Ok(())
    }

    /// The packings a sweep reads, each receiver's runs summed in this order.
    pub(crate) fn parts(&self) -> impl Iterator<Item = &ReceivedBlocks> {
        std::iter::once(&self.main).chain(self.fresh.as_ref())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A link between `a` and `b` of each kind in turn, its numbers made from its ends.
    fn link(a: NodeId, b: NodeId, nb: usize) -> Link {
        let x = (a * 1000 + b) as f32;
        let coupling = match (a + b) % 3 {
            0 => Coupling::Surfaces((0..2 * nb * nb).map(|k| x + k as f32).collect()),
            1 => Coupling::Constants { ab: x, ba: -x },
            _ => Coupling::Clusters { transmittance: x, partial: a.is_multiple_of(2) },
        };
        Link { a, b, coupling }
    }

    /// A cluster entry made from its link's numbers alone (these links join no tree).
    fn geometry(_r: NodeId, source: NodeId, transmittance: f32) -> ClusterEntry {
        ClusterEntry { source, w: [0.0; 3], emit: 0.5, scale: transmittance, slope: [0.0; 3] }
    }

    /// Per receiver, what it gets from each source, over every part, zeroed entries left out.
    fn received(packed: &PackedLinks, nodes: usize) -> Vec<Vec<(NodeId, Vec<f32>)>> {
        (0..nodes)
            .map(|r| {
                let mut out = Vec::new();
                for p in packed.parts() {
                    let (sources, run) = p.of(r);
                    let nb2 = p.nb * p.nb;
                    for (k, &s) in sources.iter().enumerate() {
                        out.push((s, run[k * nb2..(k + 1) * nb2].to_vec()));
                    }
                    out.extend(p.constants_of(r).iter().map(|&(s, g)| (s, vec![g])));
                    out.extend(p.clusters_of(r).iter().map(|e| (e.source, vec![e.scale, e.emit])));
                }
                out.retain(|(s, _)| *s as usize != r);
                out.sort_by(|x, y| x.partial_cmp(y).unwrap());
                out
            })
            .collect()
    }

    /// Links taken out and made, frame after frame, with nodes added: the packing kept up to
    /// date by the changes holds what a packing of the links anew holds, receiver by receiver,
    /// both before and after it packs itself anew.
    #[test]
    fn a_packing_kept_up_to_date_holds_the_links() {
        let nb = 3;
        let mut nodes = 40usize;
        let mut links: Vec<Link> = Vec::new();
        let mut seed = 7u64;
        let mut random = move |n: usize| {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((seed >> 33) as usize) % n
        };
        let mut pairs = std::collections::HashSet::new();
        let mut add =
            |links: &mut Vec<Link>, nodes: usize, count: usize, random: &mut dyn FnMut(usize) -> usize| {
                while links.len() < count {
                    let (a, b) = (random(nodes) as NodeId, random(nodes) as NodeId);
                    if a != b && pairs.insert((a.min(b), a.max(b))) {
                        links.push(link(a.min(b), a.max(b), nb));
                    }
                }
            };
        add(&mut links, nodes, 200, &mut random);
        let mut changes = LinkChanges::default();
        let mut packed = None;
        PackedLinks::update(&mut packed, nodes, &links, nb, &mut changes, &geometry).unwrap();
        let mut repacked = 0;
        for round in 0..12 {
            // Some taken out (as a relink or a move does), some made, sometimes on new nodes.
            let keep: Vec<bool> = (0..links.len()).map(|_| random(10) != 0).collect();
            let gone: Vec<usize> = (0..links.len()).filter(|&i| !keep[i]).collect();
            changes.removing(&links, &gone);
            let mut k = keep.iter();
            links.retain(|_| *k.next().unwrap());
            if round % 3 == 2 {
                nodes += 5;
            }
            let count = links.len() + 15;
            add(&mut links, nodes, count, &mut random);
            let before = packed.as_ref().map(|p: &PackedLinks| p.main.entries());
            PackedLinks::update(&mut packed, nodes, &links, nb, &mut changes, &geometry).unwrap();
            let p = packed.as_ref().unwrap();
            if p.zeroed == 0 && p.fresh.is_none() && before.is_some() {
                repacked += 1;
            }
            let fresh = PackedLinks::new(nodes, &links, nb, &mut LinkChanges::default(), &geometry).unwrap();
            assert_eq!(received(p, nodes), received(&fresh, nodes), "round {round}");
        }
        assert!(repacked >= 1, "the changes never reached a quarter of the packing");
    }
}
