//! A corner point's row of the gather: which sources it has, how each one's visibility is
//! decided ([`Mode`]), and which of its kept moments still hold after a frame's changes
//! ([`Gather::row`]). Computing a moment is [`super::moments`]'s.

use glam::DVec3;

use super::{Foot, GAUSS_RATIO, Gather, Linked, Mode, Receiver, Row, Touch, VisKind, shading_point};
use crate::geometry::{Aabb, Rect};
use crate::links::ElementId;
use crate::visibility::shaft::Shaft;
use crate::visibility::{Visibility, cell_of};

impl Gather<'_> {
    /// The sources and moments of the point at local `(s,t)` of element `i`, reusing `previous`
    /// (this point's row of the kept gather) where allowed; also how many moments were computed.
    /// `normal`: the point's shading normal where it is not the element's own.
    pub(super) fn row(
        &self,
        i: usize,
        s: f64,
        t: f64,
        normal: Option<DVec3>,
        previous: Option<Row>,
        feet: bool,
    ) -> (Row, usize) {
        let sys = self.sys;
        let patch = &self.patches[i];
        let (x, n) = shading_point(patch, s, t, normal);
        let previous = previous.filter(|_| !self.moved[i]);
        // Whether an occluder comes near changes only where a moved triangle, old or new, can
        // enter the query box (`Occluders::any_near`): else the kept row's answer holds.
        let r = self.radii[i];
        let query = Aabb { min: x - DVec3::splat(r + self.eps), max: x + DVec3::splat(r + self.eps) };
        let near = match &previous {
            Some(p) if !self.swept_union.overlaps(&query) => p.near,
            _ => self.occluders.is_some_and(|o| o.any_near(x, n, r, i as u32)),
        };
        let rx = Receiver { x, n, element: i as u32, cell: cell_of(s, t, self.cells_per_axis) };
        let previous = previous.filter(|p| p.near == near);
        let faces_corner = |j: usize| j != i && self.planes[j].is_none_or(|f| f.any_in_front(patch));
        if let Some((p, modes)) =
            previous.as_ref().and_then(|p| Some((p, self.settled(&rx, i, near, p, faces_corner)?)))
        {
            let visit_all =
                near || self.movers.len() + self.emitters.len() + modes.len() > p.sources.len() / 4;
            let previous = previous.expect("checked above");
            return self.update_settled(&rx, previous, &modes, visit_all, feet);
        }
        let wanted = self.wanted(&rx, i, near, self.element_links(i), faces_corner);
        // Touched sources are found when a foot is needed (a fresh moment, a kept foot).
        let touch = |j: u32| if feet { self.touch(&rx, i, j as usize) } else { None };
        let nb = sys.basis.len();
        // The common case: the same sources, decided the same way: update the row in place.
        let same = |p: &Row| {
            p.sources.len() == wanted.len()
                && wanted.iter().zip(p.sources.iter().zip(&p.modes)).all(|(w, (&j, &mode))| *w == (j, mode))
        };
        if previous.as_ref().is_some_and(same) {
            let mut row = previous.expect("checked above");
            let mut old_feet = std::mem::take(&mut row.feet);
            let mut computed = 0;
            for (k, &(j, mode)) in wanted.iter().enumerate() {
                let old_foot = old_feet.iter().position(|f| f.element == j).map(|k| old_feet.swap_remove(k));
                computed += if self.unchanged(&rx, j as usize, mode) {
                    match old_foot {
                        Some(_) => self.keep_foot(j, touch(j), old_foot, &mut row.feet),
                        None => 0,
                    }
                } else {
                    let moments = &mut row.moments[k * nb..(k + 1) * nb];
                    self.fresh_entry(&rx, (j, mode), touch(j), old_foot, moments, &mut row.feet)
                };
            }
            return (row, computed);
        }
        let (Some(sources), Some(modes), Some(moments)) =
            (self.stop.vec(wanted.len()), self.stop.vec(wanted.len()), self.stop.vec(wanted.len() * nb))
        else {
            return (Row::default(), 0);
        };
        let mut row = Row { near, sources, modes, moments, feet: Vec::new() };
        let mut computed = 0;
        let (previous, mut previous_feet) = match previous {
            Some(mut p) => {
                let feet = std::mem::take(&mut p.feet);
                (Some(p), feet)
            }
            None => (None, Vec::new()),
        };
        // Both lists are sorted: with each kept source once, a cursor finds what the binary
        // search would (with repeats, which one it finds is the search's choice).
        let unique = previous.as_ref().is_some_and(|p| p.sources.windows(2).all(|w| w[0] < w[1]));
        let mut cursor = 0;
        for (j, mode) in wanted {
            let old_foot =
                previous_feet.iter().position(|f| f.element == j).map(|k| previous_feet.swap_remove(k));
            let kept = previous.as_ref().and_then(|p| {
                let k = if unique {
                    while p.sources.get(cursor).is_some_and(|&s| s < j) {
                        cursor += 1;
                    }
                    (p.sources.get(cursor) == Some(&j)).then_some(cursor)?
                } else {
                    p.sources.binary_search(&j).ok()?
                };
                (p.modes[k] == mode && self.unchanged(&rx, j as usize, mode))
                    .then(|| &p.moments[k * nb..(k + 1) * nb])
            });
            computed += match kept {
                Some(old) => {
                    row.moments.extend_from_slice(old);
                    match old_foot {
                        Some(_) => self.keep_foot(j, touch(j), old_foot, &mut row.feet),
                        None => 0,
                    }
                }
                None => {
                    let at = row.moments.len();
                    row.moments.resize(at + nb, 0.0);
                    self.fresh_entry(
                        &rx,
                        (j, mode),
                        touch(j),
                        old_foot,
                        &mut row.moments[at..],
                        &mut row.feet,
                    )
                }
            };
            row.sources.push(j);
            row.modes.push(mode);
        }
        (row, computed)
    }

    /// Whether the kept row `p` of a point `rx` of element `i` (not moved, `near` as before) has
    /// the sources [`Gather::wanted`] would give now, without deriving them, and which of its
    /// entries (index, new mode) change how their visibility is decided. That holds when no pair
    /// of the element with a non-emitter was added (`links_added`), each source whose pair
    /// changed visibility is still a source exactly when it was (its mode may change: a mask
    /// row, open to masked; near an occluder every source has rays whatever its link), and no
    /// moved element entered or left the sources by turning towards or away from the corner.
    /// Only moved elements can turn; a moved non-emitter in a row that is not near is a source
    /// through its link alone. `None` is always safe (the caller then derives the sources).
    pub(super) fn settled(
        &self,
        rx: &Receiver,
        i: usize,
        near: bool,
        p: &Row,
        faces_corner: impl Fn(usize) -> bool,
    ) -> Option<Vec<(usize, Mode)>> {
        if self.links_added[i] {
            return None;
        }
        let mut modes = Vec::new();
        if !near {
            for &(j, pair) in self.source_changes.of(i) {
                let mode = self.link_mode(rx, i, &Linked { j, pair, kind: self.kinds[pair as usize] });
                match (p.sources.binary_search(&j), mode) {
                    (Ok(k), Some(mode)) => {
                        if p.modes[k] != mode {
                            modes.push((k, mode));
                        }
                    }
                    (Err(_), None) => {}
                    _ => return None,
                }
            }
        }
        let turned = self.movers.iter().any(|&j| {
            let j = j as usize;
            if !near && !self.is_emitter[j] {
                return false;
            }
            // Near: a source that faces the corner now is wanted whatever its link, and one in
            // the row that no longer faces it may be there through a link: both hold only if
            // membership and facing agree. An emitter (not near) is a source iff it faces.
            p.sources.binary_search(&(j as u32)).is_ok() != faces_corner(j)
        });
        (!turned).then_some(modes)
    }

    /// A settled row ([`Gather::settled`]) brought to this frame: what [`Gather::row`] does to a
    /// kept row with the same sources, the entries in `modes` taking their new mode. It visits
    /// only the entries that can have changed (those, moved sources, and those with rays: every
    /// one near an occluder, else the emitters) unless `visit_all`. The others keep their
    /// moments, and their feet update themselves.
    pub(super) fn update_settled(
        &self,
        rx: &Receiver,
        mut row: Row,
        modes: &[(usize, Mode)],
        visit_all: bool,
        feet: bool,
    ) -> (Row, usize) {
        let nb = self.sys.basis.len();
        let i = rx.element as usize;
        let touch = |j: u32| if feet { self.touch(rx, i, j as usize) } else { None };
        let mut old_feet = std::mem::take(&mut row.feet);
        let mut computed = 0;
        for &(k, mode) in modes {
            row.modes[k] = mode;
        }
        let mut visit = |row: &mut Row, k: usize| {
            let (j, mode) = (row.sources[k], row.modes[k]);
            let old_foot = old_feet.iter().position(|f| f.element == j).map(|x| old_feet.swap_remove(x));
            let new_mode = modes.iter().any(|&(x, _)| x == k);
            computed += if !new_mode && self.unchanged(rx, j as usize, mode) {
                match old_foot {
                    Some(_) => self.keep_foot(j, touch(j), old_foot, &mut row.feet),
                    None => 0,
                }
            } else {
                let (moments, feet) = (&mut row.moments[k * nb..(k + 1) * nb], &mut row.feet);
                self.fresh_entry(rx, (j, mode), touch(j), old_foot, moments, feet)
            };
        };
        if visit_all {
            for k in 0..row.sources.len() {
                visit(&mut row, k);
            }
        } else {
            let emitters = self.emitters.iter().map(|&e| e as u32);
            let mut entries: Vec<usize> = self
                .movers
                .iter()
                .copied()
                .chain(emitters)
                .filter_map(|j| row.sources.binary_search(&j).ok())
                .chain(modes.iter().map(|&(k, _)| k))
                .collect();
            entries.sort_unstable();
            entries.dedup();
            for k in entries {
                visit(&mut row, k);
            }
        }
        // The entries not visited are unchanged: their feet update themselves.
        for foot in std::mem::take(&mut old_feet) {
            let j = foot.element;
            computed += self.keep_foot(j, touch(j), Some(foot), &mut row.feet);
        }
        // In source order, as `row` lists them.
        row.feet.sort_unstable_by_key(|f| f.element);
        (row, computed)
    }

    /// The sources linked with element `i`, emitters left out, sorted by element, with the kind
    /// of their visibility: read once per element and frame, on first use, shared by the
    /// element's corners. (The store holds each pair of elements once.)
    pub(super) fn element_links(&self, i: usize) -> &[Linked] {
        self.links[i].get_or_init(|| {
            let sys = self.sys;
            let (pairs, others) =
                (sys.links.pairs_of(i as ElementId), sys.links.receivers_of(i as ElementId));
            assert_eq!(pairs.len(), others.len());
            // (A refused allocation stops the gather, which returns the error: this element's
            // corners are not used.)
            let Some(mut out) = self.stop.vec::<Linked>(pairs.len()) else { return Vec::new() };
            // (`receivers_of` lists the other element of each pair, in `pairs_of` order: read
            // in sequence, with the kinds, instead of from the pair records all over the store)
            for (&p, &j) in pairs.iter().zip(others) {
                if self.is_emitter[j as usize] {
                    continue;
                }
                out.push(Linked { j, pair: p, kind: self.kinds[p as usize] });
            }
            if !out.is_sorted_by_key(|l| l.j) {
                out.sort_unstable_by_key(|l| l.j);
            }
            debug_assert!(out.windows(2).all(|w| w[0].j < w[1].j), "element {i} linked twice to a source");
            out
        })
    }

    /// How the visibility of linked source `l` is decided from the (not near) corner `rx` of
    /// element `i`; `None` leaves it out (blocked).
    pub(super) fn link_mode(&self, rx: &Receiver, i: usize, l: &Linked) -> Option<Mode> {
        if self.occluders.is_none() {
            return Some(Mode::Open);
        }
        match l.kind {
            VisKind::Full => Some(Mode::Open),
            VisKind::Blocked => None,
            VisKind::Partial => {
                let pair = self.sys.links.pair(l.pair);
                Some(Mode::Mask(self.mask_row(&pair.visibility, rx.cell, pair.a == i as u32)))
            }
        }
    }

    /// The sources of the corner `rx` of element `i` and how each one's visibility is decided,
    /// sorted by element, merged from `links` (sorted, each source once) and the emitters. Direct
    /// light makes the sharpest shadows, and a corner can sit in a penumbra that none of its
    /// element's visibility samples is in: emitters are always sources, with rays. Next to an
    /// occluder the corner may see what no sample of its element sees, and the store holds no
    /// link for a pair blocked everywhere: every element facing the corner is a source.
    pub(super) fn wanted(
        &self,
        rx: &Receiver,
        i: usize,
        near: bool,
        links: &[Linked],
        faces_corner: impl Fn(usize) -> bool,
    ) -> Vec<(u32, Mode)> {
        if near {
            // Every linked source, and every other element facing the corner, all with rays
            // (near implies occluders).
            let mut wanted = Vec::with_capacity(links.len().max(self.patches.len() / 2));
            let mut next = links.iter().map(|l| l.j).peekable();
            for j in 0..self.patches.len() {
                let linked = next.next_if_eq(&(j as u32)).is_some();
                if linked || faces_corner(j) {
                    wanted.push((j as u32, Mode::Rays));
                }
            }
            // (links to elements past the last one cannot exist)
            debug_assert!(next.peek().is_none());
            return wanted;
        }
        let emitter_mode = if self.occluders.is_some() { Mode::Rays } else { Mode::Open };
        let mut emitters = self.emitters.iter().filter(|&&j| faces_corner(j)).map(|&j| j as u32).peekable();
        let mut wanted = Vec::with_capacity(links.len() + self.emitters.len());
        for l in links {
            while let Some(e) = emitters.next_if(|&e| e < l.j) {
                wanted.push((e, emitter_mode));
            }
            if let Some(mode) = self.link_mode(rx, i, l) {
                wanted.push((l.j, mode));
            }
        }
        wanted.extend(emitters.map(|e| (e, emitter_mode)));
        wanted
    }

    /// Computes the moments of source `j` into `moments` and, when the corner touches `j`, its
    /// foot (updating `old_foot`'s row) into `feet`; returns how many moments were computed.
    pub(super) fn fresh_entry(
        &self,
        rx: &Receiver,
        (j, mode): (u32, Mode),
        touch: Option<Touch>,
        old_foot: Option<Foot>,
        moments: &mut [f32],
        feet: &mut Vec<Foot>,
    ) -> usize {
        use crate::basis::MAX_LEN as MAX_NB;
        let mut m = [0.0; MAX_NB];
        let m = &mut m[..moments.len()];
        let mut weight = 0.0;
        let ball = touch.map(|t| (super::Ball { radius: t.radius, foot: (t.s, t.t) }, &mut weight));
        self.moments(rx, j as usize, &Rect::UNIT, mode, 0, m, ball);
        for (o, v) in moments.iter_mut().zip(m.iter()) {
            *o = *v as f32;
        }
        let mut computed = 1;
        if let (Some(t), true) = (touch, weight > 0.0) {
            let (row, n) = self.row(j as usize, t.s, t.t, None, old_foot.map(|f| f.row), false);
            computed += n;
            feet.push(Foot { element: j, weight: weight as f32, row, at: (t.s, t.t) });
        }
        computed
    }

    /// A kept entry of source `j`: its foot keeps its weight (it goes with the moments) and its
    /// own row updates itself; returns how many moments that computed.
    pub(super) fn keep_foot(
        &self,
        j: u32,
        touch: Option<Touch>,
        old_foot: Option<Foot>,
        feet: &mut Vec<Foot>,
    ) -> usize {
        let (Some(t), Some(foot)) = (touch, old_foot) else { return 0 };
        let (row, computed) = self.row(j as usize, t.s, t.t, None, Some(foot.row), false);
        feet.push(Foot { row, at: (t.s, t.t), ..foot });
        computed
    }

    /// A kept moment of source `j` still holds: the source did not move and, when its visibility
    /// comes from rays, no moving object's swept bounds entered the shaft between the corner and
    /// the source (the corner's element and the mode are checked by the caller; a mask or open
    /// moment depends on nothing else).
    pub(super) fn unchanged(&self, rx: &Receiver, j: usize, mode: Mode) -> bool {
        if self.moved[j] {
            return false;
        }
        if mode != Mode::Rays {
            return true;
        }
        let (bounds, point) = (self.patches[j].bounds(), Aabb { min: rx.x, max: rx.x });
        // A box wholly outside the shaft has every box inside it outside: when the union of the
        // swept boxes is (by the exact bounds test, or by a plane with the rounding margin), so
        // is each of them, and the per-box tests would all say so.
        if !self.swept_union.overlaps(&point.union(bounds)) {
            return true;
        }
        if !Shaft::between_may_contain_box(&point, &bounds, &self.swept_union, self.union_eps) {
            return true;
        }
        if !self.swept.iter().any(|s| Shaft::between_may_contain_box(&point, &bounds, s, self.eps)) {
            return true;
        }
        // A swept box enters the shaft. 95% of such moments came out bit-identical on the
        // moving-light box (the light hides the same parts of the ceiling patches around it, or
        // none): the moment holds if each of its rays meets the moved triangles at their old
        // places exactly when it meets them at the new ones. Its rays are known without
        // integrating when `moments` takes the source whole, far from the corner and not
        // touched by it: one ray to each of the source's Gauss nodes.
        let Some(moved) = self.moved_occluders else { return false };
        let (centre, radius) = self.patches[j].sub_patch(&Rect::UNIT).bounding_sphere();
        // An emitter's moment also casts rays to its rectangle's corners and to the parts of its
        // penumbra (PENUMBRA_DEPTH), which the Gauss nodes' rays alone do not tell: it is
        // recomputed (thirteen rays, where it has no penumbra).
        let whole = rx.x.distance(centre) >= GAUSS_RATIO * radius && !self.is_emitter[j];
        whole
            && self.touch(rx, rx.element as usize, j).is_none()
            && moved.meet_alike(rx.x, &bounds, &self.nodes[j].position, self.eps)
    }

    /// The link's visibility bits from the corner's cell to each of the source's cells.
    pub(super) fn mask_row(&self, vis: &Visibility, corner: usize, corner_is_a: bool) -> u16 {
        mask_row(vis, self.cells_per_axis * self.cells_per_axis, corner, corner_is_a)
    }
}

/// The link's visibility bits from the corner's cell to each of the source's `cells` cells: bit `s`
/// is `vis.at(corner, s)` (`vis.at(s, corner)` when the corner's element is `b`) is not zero.
fn mask_row(vis: &Visibility, cells: usize, corner: usize, corner_is_a: bool) -> u16 {
    if let Visibility::Partial(words) = vis
        && cells <= 16
    {
        // The bits `Visibility::at` reads, without going through f64: the corner's row is
        // `cells` consecutive bits (one shift while they sit in one word), its column every
        // `cells`-th bit.
        let bit = |i: usize| (words[i / 64] >> (i % 64)) & 1;
        if corner_is_a {
            let first = corner * cells;
            if first % 64 + cells <= 64 {
                return ((words[first / 64] >> (first % 64)) & ((1u64 << cells) - 1)) as u16;
            }
            return (0..cells).fold(0u16, |m, s| m | (bit(first + s) as u16) << s);
        }
        return (0..cells).fold(0u16, |m, s| m | (bit(s * cells + corner) as u16) << s);
    }
    (0..cells).fold(0u16, |bits, s| {
        let seen = if corner_is_a { vis.at(corner, s, cells) } else { vis.at(s, corner, cells) };
        bits | (u16::from(seen > 0.0) << s)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The bits read straight from the words are those `Visibility::at` gives, both ways round,
    /// also for a row that straddles two words.
    #[test]
    fn mask_row_is_visibility_at() {
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        for m in 1..=4 {
            let cells = m * m;
            for _ in 0..50 {
                let vis = Visibility::Partial(Box::new([next(), next(), next(), next()]));
                for corner in 0..cells {
                    for corner_is_a in [true, false] {
                        let want = (0..cells).fold(0u16, |bits, s| {
                            let seen =
                                if corner_is_a { vis.at(corner, s, cells) } else { vis.at(s, corner, cells) };
                            bits | (u16::from(seen > 0.0) << s)
                        });
                        assert_eq!(mask_row(&vis, cells, corner, corner_is_a), want, "m {m} corner {corner}");
                    }
                }
            }
        }
        for vis in [Visibility::Full, Visibility::Blocked] {
            assert_eq!(mask_row(&vis, 16, 3, true), if vis == Visibility::Full { 0xffff } else { 0 });
        }
    }
}
