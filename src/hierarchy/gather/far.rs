//! The far sources and clusters cast from the point with rays.
//!
//! A far source (at least [`super::NEAR_RATIO`] of its radius from the point) cast in full is
//! taken whole by the Gauss rule, as the exhaustive gather takes it; a cluster by its intensity
//! towards the point times the point's own transmittance to it. Past the bright sources
//! ([`super::rank`]) a cluster takes its link's transmittance `T` where the link's rays agreed
//! (all arrived, or the pair is blocked), and the point's own where they did not
//! ([`Gather::dim_cluster`]): a cluster link's `T` is shared by every face of its receiving
//! cluster. With `T` everywhere, the ceiling corners under a light fixture 1 cm below the
//! ceiling took 5% of a lit corner's light, where the exhaustive gather has 0.05%
//! (tests/hierarchy/gather_modes.rs).

use glam::DVec3;

use super::kept::{How, Memo, Slot};
use super::sources::{Linked, Via};
use super::surface::{Rays, Source};
use super::{Counters, FAR_RATIO, Gather, Received, Receiver};
use crate::geometry::Rect;
use crate::hierarchy::coupling::{Coupling, SplitMix, kernel_weighted_rays, sample_point};
use crate::hierarchy::tree::NodeId;

impl Gather<'_> {
    /// The light of the cluster source `linked`, one the ranking takes coarsely, at the point,
    /// from `light`, what it would bring unoccluded ([`Self::cluster_light`]): that times its
    /// link's transmittance where the link's rays all arrived or all were blocked (a blocked
    /// pair: nothing), times the point's own ([`Self::cluster_cast`])
    /// where the link saw it partly. A partial link's transmittance is a mean over its
    /// receiving cluster, and the point may see anything from none to all of the source: a
    /// ceiling corner under a light fixture 1 cm below the ceiling, whose cluster's links
    /// carried 0.005, or one at the fixture's edge that sees half the room.
    pub(super) fn dim_cluster(
        &self,
        rx: &Receiver,
        (linked, slot): (Linked, Slot),
        light: [f64; 3],
        memo: &mut Memo,
    ) -> [f64; 3] {
        match linked.via {
            Via::Blocked => [0.0; 3],
            Via::Link { index } => match &self.inputs.links[index as usize].coupling {
                Coupling::Clusters { partial: true, .. } => {
                    self.cluster_cast_lit(rx, (linked.source, slot), light, memo)
                }
                Coupling::Clusters { transmittance, partial: false } => {
                    let t = *transmittance as f64;
                    light.map(|h| h * t)
                }
                // (A cluster's links are cluster links.)
                Coupling::Surfaces(_) | Coupling::Constants { .. } => light,
            },
        }
    }

    /// Adds the far source `source`'s light at the point to `got`, with its own rays: a surface's
    /// moments by the Gauss rule, a cluster's intensity times the point's transmittance.
    pub(super) fn far_cast(
        &self,
        rx: &Receiver,
        (source, slot): (NodeId, Slot),
        got: &mut Received,
        memo: &mut Memo,
    ) {
        let tree = self.inputs.tree;
        let node = tree.node(source);
        match node.surface() {
            Some(s) => {
                let nb = tree.basis.len();
                let m = memo.values(slot, source, How::Far, |m| {
                    let far = rx.x.distance(node.centre) >= FAR_RATIO * node.radius;
                    let rule = if far { &self.far_rule } else { &self.rule };
                    let src = Source { face: s.face, patch: &s.patch };
                    self.gauss(rx, src, &Rect::UNIT, rule, Rays::Bvh, &mut m[..nb]);
                });
                got.add(self.light(source, &m[..nb]), m[0]);
            }
            None => got.add(self.cluster_cast(rx, (source, slot), memo), 0.0),
        }
    }

    /// `sum_l m^l b^l` of the surface node `source`.
    pub(super) fn light(&self, source: NodeId, m: &[f64]) -> [f64; 3] {
        let b = self.inputs.state.coefficients(source);
        let mut h = [0.0; 3];
        for (m, b) in m.iter().zip(b) {
            for c in 0..3 {
                h[c] += m * b[c];
            }
        }
        h
    }

    /// The cluster `source`'s light at the point unoccluded: its intensity towards the point over
    /// the squared distance, times the cosine there.
    pub(super) fn cluster_light(&self, rx: &Receiver, source: NodeId) -> [f64; 3] {
        let ns = self.inputs.tree.node(source);
        let v = rx.x - ns.centre;
        let d2 = v.length_squared();
        if d2 <= 0.0 {
            return [0.0; 3];
        }
        let w = v / d2.sqrt();
        let cos = (-rx.n.dot(w)).max(0.0);
        if cos == 0.0 {
            return [0.0; 3];
        }
        let intensity = crate::hierarchy::lobes::eval(self.inputs.state.lobes(source), w);
        intensity.map(|i| i * cos / d2)
    }

    /// The cluster `source`'s light at the point with the point's own transmittance: rays from
    /// the point to points of the cluster facing it (the link's own transmittance is between the
    /// two nodes, blind to the shadows inside the receiving node).
    pub(super) fn cluster_cast(
        &self,
        rx: &Receiver,
        (source, slot): (NodeId, Slot),
        memo: &mut Memo,
    ) -> [f64; 3] {
        self.cluster_cast_lit(rx, (source, slot), self.cluster_light(rx, source), memo)
    }

    /// [`Self::cluster_cast`] with the cluster's unoccluded light at the point, `light`,
    /// already worked out ([`Self::cluster_light`]).
    fn cluster_cast_lit(
        &self,
        rx: &Receiver,
        (source, slot): (NodeId, Slot),
        light: [f64; 3],
        memo: &mut Memo,
    ) -> [f64; 3] {
        // The intensity first: a dark cluster costs no rays.
        if light == [0.0; 3] {
            return light;
        }
        let t = memo.values(slot, source, How::Cluster, |v| v[0] = self.point_transmittance(rx, source))[0];
        light.map(|l| l * t)
    }

    /// The transmittance from the point to the cluster `source`: [`kernel_weighted_rays`] to
    /// points below it (area-weighted), the ratio of the sampled kernel to the model
    /// [`Self::cluster_light`] evaluates at the centre, as the links' own.
    fn point_transmittance(&self, rx: &Receiver, source: NodeId) -> f64 {
        let centre = self.inputs.tree.node(source).centre;
        let seed = rx.x.to_array().iter().fold(source as u64, |h, c| h.rotate_left(21) ^ c.to_bits());
        let mut rng = SplitMix(seed ^ 0x2545_F491_4F6C_DD1D);
        let corner: (u32, DVec3, DVec3) = (rx.face, rx.x, rx.n);
        let rays = kernel_weighted_rays(self.inputs.occluders, rx.x, centre, || {
            (corner, sample_point(self.inputs.tree, source, &mut rng))
        });
        if self.inputs.occluders.is_some() {
            Counters::add(&self.counters.rays, rays.facing as u64);
        }
        rays.weighted
    }
}
