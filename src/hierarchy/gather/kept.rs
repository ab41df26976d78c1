//! What a frame's corner gather keeps for the next one (issue 21 item 3): per corner point, the
//! part of each source's light that depends on geometry alone.
//!
//! A source cast from the point gives moments `m^l = integral_S g V Gamma_l dA` (a surface, and
//! with a foot the form factor of its ball), or a transmittance (a cluster). They depend on the
//! point, the source's patch and the occluders in the shaft between them, never on the solution:
//! the frame's light is `sum_l m^l b_S^l` with this frame's `b`. So a later frame takes a
//! source's kept values again where
//! - the point is where it was (its face did not move: the same position and normal, bit for
//!   bit),
//! - the source did not move (no face at or below it moved), and
//! - no moved face's swept box, the bounds of its old and new place, meets what the source's
//!   integration reads ([`crate::hierarchy::touch::Touch::spares`]). Taken whole by the Gauss
//!   rule (a far or coarse cast, a cluster's transmittance), a source casts segments from the
//!   point to points on it, each tested against every triangle: a triangle outside the convex
//!   hull of the point and the source's box meets none of them ([`Reach::Hull`]). Integrated
//!   by [`super::near`]'s recursion, it also reads shaft queries, whose candidate lists decide
//!   how each part is taken; a shaft's planes are conservative, and may keep a triangle outside
//!   the hull, but never one outside the box around the point and the source ([`Reach::Box`]).
//!   So the same rays meet the same triangles, the same lists are found, and the values are
//!   what a fresh gather computes, bit for bit.
//!
//! The ranking that decides how each source is taken ([`super::rank`]) reads the solution, so
//! it runs every frame; its own per-source values (the unoccluded form factor, near, touched)
//! read no occluder and are kept while neither end moved. A source is found by its place in the
//! point's list of the frame before (the same order, unless links changed) and taken only for
//! the same way ([`How`]). A foot ([`super::surface`]) is a point of its own: its gather keeps
//! its sources alike, below the source it stands on. Values are kept in f32, and a fresh gather
//! rounds to f32 alike. A node keeps its id and its patch for the tree's life (the quadtrees only
//! grow, [`crate::hierarchy::update`]), so an id names the same source frame after frame.
//!
//! On the moving-light box a fresh gather was about 80% of an updated frame; kept, the gather
//! takes 2.4x less (docs/benchmarks.md, `box-gather`), and what it still computes is mostly the
//! light's own sources, which change every frame.

use std::sync::Arc;

use glam::DVec3;

use super::Mode;
use crate::geometry::Aabb;
use crate::hierarchy::touch::{Reach, Touch};
use crate::hierarchy::tree::{NodeId, Tree};
use crate::lights::direct::DirectLight;
use crate::lights::kept::Outcomes;

/// At most this many bytes are kept, whatever the memory budget: points past it are gathered
/// afresh next frame.
const MAX_BYTES: usize = 512 << 20;

/// How a source was taken from the point: its kept values hold only for the same way.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum How {
    /// A surface by [`super::near`]'s recursion (or the exhaustive one), without and with a
    /// foot's ball (the ball's form factor after the moments).
    Near,
    NearFoot,
    /// A surface whole by the Gauss rule with rays through the BVH ([`super::far`]).
    Far,
    /// A surface by one Gauss sum with rays, by the far rule and by the near one scaled to the
    /// exact form factor ([`super::rank`]'s coarse cast).
    Coarse,
    CoarseNear,
    /// A cluster by its transmittance from the point.
    Cluster,
}

impl How {
    /// Values kept for a source taken this way, with `nb` basis functions: the moments (and a
    /// ball's form factor), or a transmittance.
    pub(super) fn len(self, nb: usize) -> usize {
        match self {
            How::NearFoot => nb + 1,
            How::Near | How::Far | How::Coarse | How::CoarseNear => nb,
            How::Cluster => 1,
        }
    }
}

/// The gather's kept values of every corner point of a frame.
pub struct KeptGather {
    mode: Mode,
    nb: usize,
    /// Per face: it emitted when these values were gathered.
    emitting: Vec<bool>,
    /// Per corner point (in [`crate::gather::corner_points`]' order); `None` past the cap, or
    /// for a point with no sources (buried, an emitter's own).
    points: Vec<Option<KeptPoint>>,
    bytes: usize,
    /// The lights the points' direct light was taken from (set by the frame that keeps this).
    pub lights: Option<Arc<DirectLight>>,
}

impl KeptGather {
    pub(super) fn new(mode: Mode, nb: usize, emitting: Vec<bool>, points: Vec<Option<KeptPoint>>) -> Self {
        let bytes = points.iter().flatten().map(KeptPoint::bytes).sum();
        Self { mode, nb, emitting, points, bytes, lights: None }
    }

    /// Per node of `tree`: a surface whose face emits now (`emitting`, per face) and did not
    /// when these values were gathered, or the reverse.
    pub(super) fn lit_or_dimmed(&self, tree: &Tree, emitting: &[bool]) -> Vec<bool> {
        let flipped: Vec<bool> =
            emitting.iter().enumerate().map(|(f, &e)| self.emitting.get(f) != Some(&e)).collect();
        if !flipped.contains(&true) {
            return Vec::new();
        }
        tree.nodes.iter().map(|n| n.surface().is_some_and(|s| flipped[s.face as usize])).collect()
    }

    /// The kept point `k` for a gather in `mode` with `nb` basis functions.
    pub(super) fn point(&self, k: usize, mode: Mode, nb: usize) -> Option<&KeptPoint> {
        if mode != self.mode || nb != self.nb {
            return None;
        }
        self.points.get(k)?.as_ref()
    }

    /// Bytes held.
    pub fn bytes(&self) -> usize {
        self.bytes
    }

    /// The cap on the bytes a gather keeps under a memory budget of `budget` bytes (`None`:
    /// none known): an eighth of it, at most [`MAX_BYTES`].
    pub fn cap(budget: Option<u64>) -> usize {
        budget.map_or(MAX_BYTES, |b| (b / 8).min(MAX_BYTES as u64) as usize)
    }
}

/// One point's kept values: where it was, and per source it listed (in the order it listed
/// them) its ranking values ([`Memo::listed`]) and how it was cast, if it was, with its values.
/// 16 bytes a source, and the values of those cast.
pub(super) struct KeptPoint {
    x: DVec3,
    n: DVec3,
    sources: Vec<NodeId>,
    /// Per source: its unoccluded form factor.
    form_factors: Vec<f32>,
    /// Per source: what it is to the point, how it was cast and where its values start.
    entries: Vec<Entry>,
    values: Vec<f32>,
    /// The feet's own points, by the source they stand on.
    feet: Vec<(NodeId, KeptPoint)>,
    /// The outcomes of the point's shadow rays toward the lights ([`crate::lights::kept`]).
    direct: Outcomes,
}

/// A listed source's record beside its form factor.
#[derive(Clone, Copy)]
struct Entry {
    /// The ranking's second value ([`Memo::listed`]), exact in a byte.
    what: i8,
    /// How it was cast ([`NOT_CAST`] if it was not).
    how: u8,
    /// Where its values ([`How::len`] of them) start in `values`.
    at: u32,
}

/// [`Entry::how`] of a source taken without rays from the point.
const NOT_CAST: u8 = u8::MAX;

impl KeptPoint {
    /// An empty point with room for as many values as `previous` holds (a point keeps about
    /// the same sources frame after frame: growing the vectors and shrinking them after was a
    /// tenth of an updated frame's gather).
    fn like(previous: Option<&KeptPoint>) -> Self {
        let room = |n: fn(&KeptPoint) -> usize| previous.map_or(0, n);
        Self {
            x: DVec3::NAN,
            n: DVec3::NAN,
            sources: Vec::with_capacity(room(|p| p.sources.len())),
            form_factors: Vec::with_capacity(room(|p| p.sources.len())),
            entries: Vec::with_capacity(room(|p| p.sources.len())),
            values: Vec::with_capacity(room(|p| p.values.len())),
            feet: Vec::with_capacity(room(|p| p.feet.len())),
            direct: Outcomes::default(),
        }
    }

    fn foot(&self, source: NodeId) -> Option<&KeptPoint> {
        let k = self.feet.binary_search_by_key(&source, |(s, _)| *s).ok()?;
        Some(&self.feet[k].1)
    }

    pub(super) fn bytes(&self) -> usize {
        let own = std::mem::size_of::<Self>()
            + self.sources.capacity() * 4
            + self.form_factors.capacity() * 4
            + self.entries.capacity() * std::mem::size_of::<Entry>()
            + self.values.capacity() * 4
            + self.direct.bytes();
        own + self.feet.iter().map(|(_, f)| 4 + f.bytes()).sum::<usize>()
    }
}

/// Where a point's sources sat in its last frame's list: at the cursor, as a rule (the sources
/// are listed in the same order frame after frame unless links changed), else found through an
/// index of that list, sorted the first time a source is out of order.
struct Finder {
    cursor: usize,
    index: Option<Vec<(NodeId, u32)>>,
}

impl Finder {
    fn slot_of(&mut self, previous: &KeptPoint, source: NodeId) -> Option<usize> {
        let k = if previous.sources.get(self.cursor) == Some(&source) {
            self.cursor
        } else {
            let index = self.index.get_or_insert_with(|| {
                let mut index: Vec<(NodeId, u32)> =
                    previous.sources.iter().enumerate().map(|(i, &s)| (s, i as u32)).collect();
                index.sort_unstable();
                index
            });
            let i = index.binary_search_by_key(&source, |&(s, _)| s).ok()?;
            index[i].1 as usize
        };
        self.cursor = k + 1;
        Some(k)
    }
}

/// What changed since the kept values were gathered, for telling which still hold: the moves
/// (`touch`; `None` when nothing moved, an emission change alone), and the surface nodes whose
/// face started or stopped emitting (an emitter's rectangles are integrated with their
/// penumbrae split, [`super::surface`]'s `gauss`, so its values are not a dark face's).
#[derive(Clone, Copy)]
pub struct Changes<'a> {
    touch: Option<&'a Touch<'a>>,
    /// Per node (empty: none).
    lit_or_dimmed: &'a [bool],
}

impl<'a> Changes<'a> {
    /// The changes of moves tested by `touch`, emission not yet compared.
    pub fn of(touch: Option<&'a Touch<'a>>) -> Self {
        Self { touch, lit_or_dimmed: &[] }
    }

    /// These changes with the nodes that started or stopped emitting
    /// ([`KeptGather::lit_or_dimmed`]).
    pub(super) fn with_lit_or_dimmed<'b>(self, lit_or_dimmed: &'b [bool]) -> Changes<'b>
    where
        'a: 'b,
    {
        Changes { touch: self.touch, lit_or_dimmed }
    }

    fn spares(&self, x: DVec3, source: NodeId, how: How) -> bool {
        let reach = match how {
            How::Near | How::NearFoot => Reach::Box,
            How::Far | How::Coarse | How::CoarseNear | How::Cluster => Reach::Hull,
        };
        !self.lit_or_dimmed.get(source as usize).copied().unwrap_or(false)
            && self.touch.is_none_or(|t| t.spares(x, source, reach))
    }

    /// The boxes the moves since the kept values swept (none: nothing moved).
    pub(super) fn swept(&self) -> &'a [Aabb] {
        self.touch.map_or(&[], |t| t.swept())
    }

    fn unmoved(&self, source: NodeId) -> bool {
        self.touch.is_none_or(|t| t.unmoved(source))
    }
}

/// Counts of one gather's sources: taken from the frame before, and computed.
#[derive(Clone, Copy, Debug, Default)]
pub struct Reuse {
    pub kept: u64,
    pub computed: u64,
}

/// One point's gather: its kept values from the frame before (already checked to be at the
/// same place), and the values it keeps for the next frame.
pub(super) struct Memo<'k> {
    /// The point's kept values and what changed since they were gathered.
    previous: Option<(&'k KeptPoint, Changes<'k>)>,
    nb: usize,
    keeping: Option<KeptPoint>,
    finder: Finder,
    pub reuse: Reuse,
}

/// A source's values, at most the moments and one more.
pub(super) type Values = [f64; crate::basis::MAX_LEN + 1];

/// A value as it is kept: in f32, which a fresh gather rounds to alike, so that kept values are
/// the fresh ones bit for bit. (The corners are written in f32; a moment's rounding, 6e-8 of it,
/// is below what they resolve, and halves what is kept.)
fn to_f32(x: f64) -> f32 {
    x as f32
}

/// Where a listed source sits in the previous point's kept values and in this point's.
#[derive(Clone, Copy, Debug)]
pub(super) struct Slot {
    previous: u32,
    own: u32,
}

impl Slot {
    /// A source of a gather that neither takes nor keeps values (the exhaustive one).
    pub const NONE: Slot = Slot { previous: u32::MAX, own: u32::MAX };
}

impl<'k> Memo<'k> {
    /// A point's memo: `previous` is the point's kept values, taken where the changes with them
    /// spare them; with `keep`, it keeps this frame's.
    pub fn new(previous: Option<(&'k KeptPoint, Changes<'k>)>, nb: usize, keep: bool) -> Self {
        let keeping = keep.then(|| KeptPoint::like(previous.map(|p| p.0)));
        Self { previous, nb, keeping, finder: Finder { cursor: 0, index: None }, reuse: Reuse::default() }
    }

    /// The point's place: kept values of a point elsewhere are not taken.
    pub fn at(&mut self, x: DVec3, n: DVec3) {
        if self.previous.is_some_and(|(p, _)| p.x != x || p.n != n) {
            self.previous = None;
        }
        if let Some(k) = &mut self.keeping {
            (k.x, k.n) = (x, n);
        }
    }

    /// Lists `source` among the point's, with its two values for the ranking (a surface's
    /// unoccluded form factor and what it is to the point), which read no occluder: the kept
    /// ones while neither the point nor the source moved, else `compute`d. Returns its slot,
    /// for [`Memo::values`].
    pub fn listed(&mut self, source: NodeId, compute: impl FnOnce() -> [f64; 2]) -> ([f64; 2], Slot) {
        let previous = self.previous.and_then(|(p, c)| Some((p, c, self.finder.slot_of(p, source)?)));
        let ranked = match previous {
            Some((p, c, k)) if c.unmoved(source) => {
                [f64::from(p.form_factors[k]), f64::from(p.entries[k].what)]
            }
            _ => {
                let [form_factor, what] = compute();
                [to_f32(form_factor) as f64, what]
            }
        };
        let own = match &mut self.keeping {
            Some(k) => {
                k.sources.push(source);
                k.form_factors.push(ranked[0] as f32);
                // (The ranking's second value is -1 or a sum of two flags.)
                k.entries.push(Entry { what: ranked[1] as i8, how: NOT_CAST, at: 0 });
                k.sources.len() as u32 - 1
            }
            None => u32::MAX,
        };
        (ranked, Slot { previous: previous.map_or(u32::MAX, |(_, _, k)| k as u32), own })
    }

    /// The values of the source at `slot` taken as `how` ([`How::len`] of them): the kept ones
    /// where they hold, else `compute`d (into zeros).
    pub fn values(
        &mut self,
        slot: Slot,
        source: NodeId,
        how: How,
        compute: impl FnOnce(&mut [f64]),
    ) -> Values {
        let mut v = [0.0; crate::basis::MAX_LEN + 1];
        let len = how.len(self.nb);
        let kept = match self.previous {
            Some((p, c)) if slot.previous != u32::MAX => {
                let e = p.entries[slot.previous as usize];
                let at = e.at as usize;
                (e.how == how as u8 && c.spares(p.x, source, how)).then(|| &p.values[at..at + len])
            }
            _ => None,
        };
        match kept {
            Some(k) => {
                for (v, &k) in v.iter_mut().zip(k) {
                    *v = f64::from(k);
                }
                self.reuse.kept += 1;
            }
            None => {
                compute(&mut v[..len]);
                for v in &mut v[..len] {
                    *v = to_f32(*v) as f64;
                }
                self.reuse.computed += 1;
            }
        }
        if let (Some(k), true) = (&mut self.keeping, slot.own != u32::MAX) {
            let e = &mut k.entries[slot.own as usize];
            (e.how, e.at) = (how as u8, k.values.len() as u32);
            k.values.extend(v[..len].iter().map(|&v| v as f32));
        }
        v
    }

    /// The memo of the foot on `source`.
    pub fn foot(&self, source: NodeId) -> Memo<'k> {
        let previous = self.previous.and_then(|(p, c)| Some((p.foot(source)?, c)));
        Memo::new(previous, self.nb, self.keeping.is_some())
    }

    /// The lights' direct irradiance at the point `(x, n)` on face `f`, its shadow rays taken from
    /// the point's kept outcomes where `kept` is given (the kept values' lights cast alike: the
    /// boxes the moves since swept, and the sources placed otherwise since) and no box meets a
    /// ray, but for the changed sources' rays; the outcomes kept for the next frame. The same
    /// irradiance as [`DirectLight::irradiance`], bit for bit.
    pub fn direct(
        &mut self,
        lights: &DirectLight,
        (x, n, f): (DVec3, DVec3, u32),
        kept: Option<(&[Aabb], &[bool])>,
    ) -> [f64; 3] {
        let last = kept.and(self.previous.map(|(p, _)| &p.direct));
        let (swept, changed) = kept.unwrap_or((&[], &[]));
        let (irradiance, outcomes, _) = lights.irradiance_keeping(x, n, f, (last, changed), swept);
        if let Some(k) = &mut self.keeping {
            k.direct = outcomes;
        }
        irradiance
    }

    /// Keeps the foot on `source`'s gather, done with `foot`.
    pub fn keep_foot(&mut self, source: NodeId, foot: Memo) {
        self.reuse.kept += foot.reuse.kept;
        self.reuse.computed += foot.reuse.computed;
        if let (Some(k), Some(f)) = (&mut self.keeping, foot.into_kept()) {
            k.feet.push((source, f));
        }
    }

    /// The point's kept values; `None` when not keeping or when it listed no source.
    pub fn into_kept(self) -> Option<KeptPoint> {
        let mut k = self.keeping?;
        if k.sources.is_empty() && k.feet.is_empty() {
            return None;
        }
        k.feet.sort_unstable_by_key(|(s, _)| *s);
        // A first frame's vectors grew by doubling; a later frame's were sized from the last.
        if k.values.capacity() > k.values.len() + k.values.len() / 4 {
            k.sources.shrink_to_fit();
            k.form_factors.shrink_to_fit();
            k.entries.shrink_to_fit();
            k.values.shrink_to_fit();
        }
        Some(k)
    }
}
