//! The link store: kernel coefficients between elements, independent of how elements relate to
//! faces (one element per face today; elements below faces with hierarchical refinement).
//!
//! A *pair* `(a, b)` holds both directed links: `G_ab` (receiver `a`, source `b`) and `G_ba`, each
//! `nb x nb` f32 with rows indexed by the receiver's basis function. Pairs are recomputed in
//! place by the animation update; a pair that starts or stops interacting is added or emptied.
//!
//! Storage is by *shooter*: for element `j` and its basis function `l`, one contiguous column
//! stream holds `G_ij^{kl}` (k = 0..nb) for every receiver `i` of `j`, in [`LinkStore::receivers_of`]
//! order. Shooting one unshot coefficient `l` of `j` then reads `nb` consecutive floats per
//! receiver and nothing else (the solver shoots coefficient by coefficient, most often `l = 0`);
//! a row-major block per pair would cost the whole block's cache lines. [`LinkStore::block`] and
//! [`LinkStore::blocks_f64`] still give row-major blocks.
//!
//! Once the receivers' areas are given ([`LinkStore::set_receiver_areas`]), the store also keeps
//! per column its *transfer* `T_j^l = sum_i area_i sum_k |G_ij^{kl}|`: the power one unit of
//! `b_j^l` delivers in one bounce, which the solver ranks shots by. Every write of coefficients
//! updates it for the columns it touches.
//!
//! It also keeps per element `i` the sum `S_i = sum_j G_ij^00` of its row (the hemisphere bound's
//! sum, [`crate::hemisphere`]), updated by every write, so that an animation frame costs the bound
//! O(changed pairs) instead of a pass over each changed receiver's row. The sum is held exactly,
//! as an integer: each f32 `G^00` is taken on a fixed grid of `2^-G00_FRACTION_BITS` (exact for
//! every value above ~7e-18, the rest truncated deterministically) and the grid values are added
//! and subtracted as `i128`. Integer sums do not depend on order, so a sum kept through any
//! sequence of writes equals the sum of the store's current values recomputed from scratch, bit
//! for bit (no drift, whatever the frames); [`LinkStore::row_sum`] rounds it once to f64, i.e.
//! correctly rounded, which is within a few ulps of a sequential f64 sum.

use crate::budget;
use crate::error::Result;
use crate::visibility::Visibility;

pub type ElementId = u32;
pub type PairId = u32;

/// [`LinkStore::extend_rows`] leaves each shooter's columns room for `1 / GROWTH_ROOM` more
/// receivers, plus 4.
const GROWTH_ROOM: usize = 16;

/// What the store is called in an out-of-memory message.
const STORE: &str = "the link store";

/// The grid of the kept row sums (module docs): `G^00` in units of `2^-80`.
const G00_FRACTION_BITS: i32 = 80;

/// Magnitudes above this are clamped on the grid, so that `2^20` pairs of a row cannot overflow
/// the `i128` (`2^(27 + 80 + 20) = 2^127`). A mean form factor is at most a few units.
const G00_CLAMP: f64 = (1u64 << 27) as f64;

/// `g` on the row sums' grid: exact for f32 values whose last bit is at least `2^-80`.
#[inline]
fn g00_fixed(g: f32) -> i128 {
    // (Scaling by a power of two is exact in f64; the cast truncates toward zero, NaN to 0.)
    ((g as f64).clamp(-G00_CLAMP, G00_CLAMP) * (G00_FRACTION_BITS as f64).exp2()) as i128
}

/// How many block writes ahead [`LinkStore::replace_blocks`] prefetches.
const PREFETCH_WRITES: usize = 2;

#[derive(Clone, Debug)]
pub struct Pair {
    pub a: ElementId,
    pub b: ElementId,
    pub visibility: Visibility,
}

/// Pairs `(a, b)` of one element `a`, for [`LinkStore::extend_rows`].
#[derive(Clone, Debug, Default)]
pub struct LinkRow {
    pub a: ElementId,
    pub sources: Vec<ElementId>,
    /// `[G_ab | G_ba]` per source, f32 row-major, `2 nb^2` each.
    pub coeffs: Vec<f32>,
    pub visibility: Vec<Visibility>,
}

#[derive(Clone, Debug, Default)]
pub struct LinkStore {
    nb: usize,
    pairs: Vec<Pair>,
    /// Per pair: the slot of `G_ab` among `b`'s receivers and of `G_ba` among `a`'s.
    slots: Vec<[u32; 2]>,
    /// Per element: the pairs it belongs to.
    adjacency: Vec<Vec<PairId>>,
    /// Pairs added, or whose visibility changed, since [`LinkStore::take_visibility_changes`]
    /// last ran; `None` when unknown (never taken, or more were logged than there are pairs).
    visibility_changes: Option<Vec<PairId>>,
    /// Per element, in `adjacency` order: the other element of the pair, which receives what this
    /// one shoots.
    receivers: Vec<Vec<ElementId>>,
    /// `[shooter * nb + l]`: column `l` of `G_receiver,shooter` for each receiver of the shooter,
    /// in `receivers` order, `nb` floats each (index `k`, the receiver's function).
    columns: Vec<Vec<f32>>,
    /// `[shooter * nb + l]`: `T_shooter^l` (module docs), empty until areas are given.
    transfer: Vec<f64>,
    /// The receiver areas `transfer` is weighted with.
    areas: Vec<f64>,
    /// Per element `i`: `S_i = sum_j G_ij^00` on the grid of [`g00_fixed`] (module docs).
    g00_sums: Vec<i128>,
}

/// `sum_k |G^{kl}|` of one receiver's part of a column: its share of `T` before the area.
fn magnitude(g: &[f32]) -> f64 {
    g.iter().map(|x| x.abs() as f64).sum()
}

/// Areas within this relative difference of those `transfer` was weighted with keep it (a
/// rotated element's area changes in its last bits).
const AREA_TOLERANCE: f64 = 1e-9;

impl LinkStore {
    pub fn new(n_elements: usize, nb: usize) -> Self {
        Self {
            nb,
            pairs: Vec::new(),
            visibility_changes: None,
            slots: Vec::new(),
            adjacency: vec![Vec::new(); n_elements],
            receivers: vec![Vec::new(); n_elements],
            columns: vec![Vec::new(); n_elements * nb],
            transfer: Vec::new(),
            areas: Vec::new(),
            g00_sums: vec![0; n_elements],
        }
    }

    /// `S_i = sum_j G_ij^00` over every pair of element `i` (module docs; the hemisphere bound's
    /// sum, [`crate::hemisphere::row_sum`]), kept through every write.
    #[inline]
    pub fn row_sum(&self, i: ElementId) -> f64 {
        self.g00_sums[i as usize] as f64 * (-G00_FRACTION_BITS as f64).exp2()
    }

    /// Moves receiver `i`'s kept row sum from `old` to `new` `G^00`.
    #[inline]
    fn move_row_sum(&mut self, i: ElementId, old: f32, new: f32) {
        let s = &mut self.g00_sums[i as usize];
        *s = s.wrapping_sub(g00_fixed(old)).wrapping_add(g00_fixed(new));
    }

    /// Weights the transfers `T_j^l` with these receiver areas (element order), recomputing them
    /// all (one pass over the store, in parallel) unless the areas are those already used.
    pub fn set_receiver_areas(&mut self, areas: &[f64]) {
        use rayon::prelude::*;
        assert_eq!(areas.len(), self.receivers.len(), "one area per element");
        let same = self.areas.len() == areas.len()
            && self
                .areas
                .iter()
                .zip(areas)
                .all(|(a, b)| (a - b).abs() <= AREA_TOLERANCE * a.abs().max(b.abs()));
        if same {
            return;
        }
        self.areas = areas.to_vec();
        let nb = self.nb;
        let (receivers, columns) = (&self.receivers, &self.columns);
        self.transfer = (0..receivers.len() * nb)
            .into_par_iter()
            .map(|c| {
                let column = columns[c].chunks_exact(nb);
                receivers[c / nb].iter().zip(column).map(|(&r, g)| areas[r as usize] * magnitude(g)).sum()
            })
            .collect();
    }

    /// `T_e^l` for `l = 0..nb` of each element `e`, at `[e * nb + l]`: the power a unit of
    /// `b_e^l` delivers in one bounce (module docs). Empty until
    /// [`LinkStore::set_receiver_areas`].
    pub fn transfers(&self) -> &[f64] {
        &self.transfer
    }

    /// Basis functions per element.
    pub fn nb(&self) -> usize {
        self.nb
    }

    pub fn len(&self) -> usize {
        self.pairs.len()
    }

    pub fn is_empty(&self) -> bool {
        self.pairs.is_empty()
    }

    pub fn pairs(&self) -> &[Pair] {
        &self.pairs
    }

    pub fn pair(&self, p: PairId) -> &Pair {
        &self.pairs[p as usize]
    }

    /// Pairs that element `e` belongs to.
    pub fn pairs_of(&self, e: ElementId) -> &[PairId] {
        &self.adjacency[e as usize]
    }

    /// Adds a pair with its two blocks (`ab`, `ba`, f64 `nb x nb` row-major each).
    pub fn push(
        &mut self,
        a: ElementId,
        b: ElementId,
        ab: &[f64],
        ba: &[f64],
        visibility: Visibility,
    ) -> PairId {
        let id = self.pairs.len() as PairId;
        self.pairs.push(Pair { a, b, visibility });
        self.link(a, b, id);
        self.log_visibility_change(id);
        self.move_row_sum(a, 0.0, ab[0] as f32);
        self.move_row_sum(b, 0.0, ba[0] as f32);
        let nb = self.nb;
        // G_ab is shot by b, G_ba by a; both go to the end of the shooter's columns.
        for (shooter, receiver, g) in [(b, a, ab), (a, b, ba)] {
            for l in 0..nb {
                let column = (0..nb).map(|k| g[k * nb + l] as f32);
                let start = self.columns[shooter as usize * nb + l].len();
                self.columns[shooter as usize * nb + l].extend(column);
                if !self.transfer.is_empty() {
                    let added = &self.columns[shooter as usize * nb + l][start..];
                    self.transfer[shooter as usize * nb + l] +=
                        self.areas[receiver as usize] * magnitude(added);
                }
            }
        }
        id
    }

    fn link(&mut self, a: ElementId, b: ElementId, id: PairId) {
        debug_assert_eq!(self.slots.len(), id as usize);
        self.slots.push([self.receivers[b as usize].len() as u32, self.receivers[a as usize].len() as u32]);
        self.adjacency[a as usize].push(id);
        self.adjacency[b as usize].push(id);
        self.receivers[b as usize].push(a);
        self.receivers[a as usize].push(b);
    }

    /// What element `e` shoots to, in [`LinkStore::pairs_of`] order.
    pub fn receivers_of(&self, e: ElementId) -> &[ElementId] {
        &self.receivers[e as usize]
    }

    /// Column `l` of every block element `e` shoots through: for the `r`-th receiver `i` of
    /// [`LinkStore::receivers_of`], `G_ie^{kl}` at `r * nb + k`.
    #[inline]
    pub fn shooter_column(&self, e: ElementId, l: usize) -> &[f32] {
        &self.columns[e as usize * self.nb + l]
    }

    /// Where `G_receiver,other` of pair `p` lives: the shooter and the receiver's slot among the
    /// shooter's receivers.
    #[inline]
    pub fn slot(&self, p: PairId, receiver: ElementId) -> (usize, usize) {
        let pair = &self.pairs[p as usize];
        let [ab, ba] = self.slots[p as usize];
        if pair.a == receiver { (pair.b as usize, ab as usize) } else { (pair.a as usize, ba as usize) }
    }

    /// Column `l` of `G_receiver,other` of pair `p`: `nb` floats, index `k`.
    #[inline]
    pub fn column(&self, p: PairId, receiver: ElementId, l: usize) -> &[f32] {
        let (shooter, slot) = self.slot(p, receiver);
        &self.columns[shooter * self.nb + l][slot * self.nb..(slot + 1) * self.nb]
    }

    /// Adds rows of pairs `(a, b_k)` with their f32 blocks `[G_ab | G_ba]` one pair after the other
    /// (`2 nb^2` each), in row order then `b` order: as [`LinkStore::push`] one by one, with the
    /// coefficients copied in parallel (one shooter per task). The big arrays are reserved
    /// first ([`crate::budget::try_reserve`]): when the allocator refuses, the error is returned
    /// and the store is as it was, except for spare capacity.
    pub fn extend_rows(&mut self, mut rows: Vec<LinkRow>) -> Result<()> {
        use rayon::prelude::*;
        let nb = self.nb;
        let n2 = nb * nb;
        let first = self.pairs.len();
        let added: usize = rows.iter().map(|r| r.sources.len()).sum();
        // Where each new pair's blocks are: (row, index in row).
        let mut origin: Vec<(u32, u32)> = budget::try_vec(added, STORE)?;
        budget::try_reserve(&mut self.pairs, added, STORE)?;
        budget::try_reserve(&mut self.slots, added, STORE)?;
        // The columns: each shooter's new receivers (and room), counted from the rows.
        let mut new_of = vec![0usize; self.receivers.len()];
        for row in &rows {
            new_of[row.a as usize] += row.sources.len();
            for &b in &row.sources {
                new_of[b as usize] += 1;
            }
        }
        let old_len: Vec<usize> = self.receivers.iter().map(Vec::len).collect();
        self.columns.par_chunks_mut(nb).enumerate().try_for_each(|(e, cols)| {
            if new_of[e] == 0 {
                return Ok(());
            }
            // Room for the pairs an animation adds later (`push`): growing every column of a
            // shooter on its first new pair (a copy and fresh pages each) cost one frame of the
            // moving-light box 42-54 ms for its 1,132 new pairs.
            let room = (old_len[e] + new_of[e]) / GROWTH_ROOM + 4;
            cols.iter_mut().try_for_each(|col| budget::try_reserve_exact(col, (new_of[e] + room) * nb, STORE))
        })?;
        for (ri, row) in rows.iter_mut().enumerate() {
            debug_assert_eq!(row.coeffs.len(), row.sources.len() * 2 * n2);
            for (k, (&b, v)) in row.sources.iter().zip(row.visibility.drain(..)).enumerate() {
                let id = self.pairs.len() as PairId;
                self.pairs.push(Pair { a: row.a, b, visibility: v });
                self.link(row.a, b, id);
                self.log_visibility_change(id);
                origin.push((ri as u32, k as u32));
                let g = &row.coeffs[k * 2 * n2..];
                self.move_row_sum(row.a, 0.0, g[0]);
                self.move_row_sum(b, 0.0, g[n2]);
            }
        }
        let (adjacency, pairs) = (&self.adjacency, &self.pairs);
        self.columns.par_chunks_mut(nb).enumerate().for_each(|(e, cols)| {
            let new = &adjacency[e][old_len[e]..];
            for &p in new {
                let (ri, k) = origin[p as usize - first];
                let row = &rows[ri as usize];
                // The block e shoots through: G_ba (second half) when e is the row's a.
                let half = if pairs[p as usize].a == e as ElementId { n2 } else { 0 };
                let g = &row.coeffs[k as usize * 2 * n2 + half..][..n2];
                for (l, col) in cols.iter_mut().enumerate() {
                    col.extend((0..nb).map(|k| g[k * nb + l]));
                }
            }
        });
        if !self.areas.is_empty() {
            let areas = std::mem::take(&mut self.areas);
            self.set_receiver_areas(&areas);
        }
        Ok(())
    }

    /// Replaces the coefficients of many stored pairs at once: for each `(p, r, g)`,
    /// `g = [G_r,other | G_other,r]` (f32, `nb x nb` row-major each), with the columns written in
    /// parallel, one shooter per task. The blocks they replace, read from the cache lines being
    /// written, go to `replaced` (whose buffers are reused from call to call). Visibility is left
    /// as it is ([`LinkStore::set_visibility`]). Its buffers are reserved before anything is
    /// written ([`crate::budget::try_reserve`]): when the allocator refuses, the error is returned
    /// and the store is as it was.
    pub fn replace_blocks(
        &mut self,
        items: &[(PairId, ElementId, &[f32])],
        replaced: &mut ReplacedBlocks,
    ) -> Result<()> {
        use rayon::prelude::*;
        let nb = self.nb;
        let n2 = nb * nb;
        // The writes by shooter (a counting sort): (item, slot, half of the item's blocks).
        let n = self.receivers.len();
        let mut start = budget::try_filled(n + 1, 0usize, STORE)?;
        for &(p, ..) in items {
            let pair = &self.pairs[p as usize];
            start[pair.a as usize + 1] += 1;
            start[pair.b as usize + 1] += 1;
        }
        for e in 0..n {
            start[e + 1] += start[e];
        }
        let mut fill: Vec<usize> = budget::try_vec(n + 1, STORE)?;
        fill.extend_from_slice(&start);
        let mut writes = budget::try_filled(2 * items.len(), (0u32, 0u32, 0u32), STORE)?;
        let len = 2 * items.len() * n2;
        replaced.position.clear();
        budget::try_reserve(&mut replaced.position, 2 * items.len(), STORE)?;
        replaced.old.clear();
        budget::try_reserve(&mut replaced.old, len, STORE)?;
        let mut parts = budget::try_vec(n, STORE)?;
        let weighted = !self.transfer.is_empty();
        let mut unweighted = budget::try_filled(if weighted { 0 } else { n * nb }, 0.0f64, STORE)?;
        replaced.n2 = n2;
        replaced.position.resize(2 * items.len(), 0);
        for (k, &(p, r, _)) in items.iter().enumerate() {
            let other = self.other(p, r);
            for (half, receiver) in [(0, r), (1, other)] {
                let (shooter, slot) = self.slot(p, receiver);
                writes[fill[shooter]] = (k as u32, slot as u32, half);
                replaced.position[2 * k + half as usize] = fill[shooter] as u32;
                fill[shooter] += 1;
            }
        }
        // The old blocks in write order, so that each shooter's task owns a contiguous part.
        let mut rest = &mut replaced.old.spare_capacity_mut()[..len];
        for e in 0..n {
            let (part, tail) = rest.split_at_mut((start[e + 1] - start[e]) * n2);
            parts.push(part);
            rest = tail;
        }
        // Each task also moves its shooter's transfers by the change of its columns.
        let transfer = if weighted { &mut self.transfer } else { &mut unweighted };
        let (receivers, areas) = (&self.receivers, &self.areas);
        let tasks = self.columns.par_chunks_mut(nb).zip(parts).zip(transfer.par_chunks_mut(nb));
        tasks.enumerate().for_each(|(e, ((cols, old), transfer))| {
            let writes = &writes[start[e]..start[e + 1]];
            for (x, (&(k, slot, half), old)) in writes.iter().zip(old.chunks_exact_mut(n2)).enumerate() {
                // Each write lands on `nb` scattered lines and reads a block computed elsewhere:
                // ask for both ahead.
                if let Some(&(k, slot, half)) = writes.get(x + PREFETCH_WRITES) {
                    crate::simd::prefetch(&items[k as usize].2[half as usize * n2..][..n2]);
                    for col in cols.iter() {
                        crate::simd::prefetch(&col[slot as usize * nb..][..nb]);
                    }
                }
                let g = &items[k as usize].2[half as usize * n2..][..n2];
                let slot = slot as usize;
                for (l, col) in cols.iter_mut().enumerate() {
                    let (mut was, mut now) = (0.0f64, 0.0f64);
                    for (kk, dst) in col[slot * nb..(slot + 1) * nb].iter_mut().enumerate() {
                        was += dst.abs() as f64;
                        now += g[kk * nb + l].abs() as f64;
                        old[kk * nb + l].write(*dst);
                        *dst = g[kk * nb + l];
                    }
                    if weighted {
                        // (A sum of magnitudes: the clamp only stops rounding below zero.)
                        let area = areas[receivers[e][slot] as usize];
                        transfer[l] = (transfer[l] + area * (now - was)).max(0.0);
                    }
                }
            }
        });
        // SAFETY: the parts cover the first `len` spare entries, one `n2` chunk per write, and
        // every chunk had all of its `nb x nb` entries written above.
        unsafe { replaced.old.set_len(len) };
        // The receivers' row sums, from the entries `G^00` (index 0 of each block) written and
        // replaced; serial, as one receiver's sum may move in many shooters' tasks.
        for (k, &(p, r, g)) in items.iter().enumerate() {
            for (half, receiver) in [(0, r), (1, self.other(p, r))] {
                self.move_row_sum(receiver, replaced.get(k, half)[0], g[half * n2]);
            }
        }
        Ok(())
    }

    pub fn set_visibility(&mut self, p: PairId, visibility: Visibility) {
        if self.pairs[p as usize].visibility != visibility {
            self.pairs[p as usize].visibility = visibility;
            self.log_visibility_change(p);
        }
    }

    /// The pairs added, or whose visibility changed, since the last call (each at least once,
    /// in no particular order), or `None` when that is not known: before the first call, or
    /// when more changes than pairs piled up between calls. What the corner gather reads to keep
    /// a corner's sources without re-deriving them ([`crate::gather`]).
    pub fn take_visibility_changes(&mut self) -> Option<Vec<PairId>> {
        self.visibility_changes.replace(Vec::new())
    }

    fn log_visibility_change(&mut self, p: PairId) {
        if let Some(log) = &mut self.visibility_changes {
            // Bounded: a log nobody takes (the gather off) stops at "unknown".
            if log.len() >= self.pairs.len().max(1024) {
                self.visibility_changes = None;
            } else {
                log.push(p);
            }
        }
    }

    /// The block with `receiver` as receiver, `G_receiver,other`, row-major (row = receiver
    /// function), copied out of the column store.
    pub fn block(&self, p: PairId, receiver: ElementId) -> Vec<f32> {
        let nb = self.nb;
        let (shooter, slot) = self.slot(p, receiver);
        let mut g = vec![0.0; nb * nb];
        for l in 0..nb {
            let col = &self.columns[shooter * nb + l][slot * nb..(slot + 1) * nb];
            for (k, &x) in col.iter().enumerate() {
                g[k * nb + l] = x;
            }
        }
        g
    }

    /// The other element of pair `p`.
    #[inline]
    pub fn other(&self, p: PairId, e: ElementId) -> ElementId {
        let pair = &self.pairs[p as usize];
        if pair.a == e { pair.b } else { pair.a }
    }

    /// Bytes held by coefficients and pair records.
    pub fn memory_bytes(&self) -> usize {
        self.columns.iter().map(|c| c.len() * 4).sum::<usize>()
            + self.pairs.len() * std::mem::size_of::<Pair>()
            + self.pairs.len() * std::mem::size_of::<[u32; 2]>()
            + 2 * self.pairs.len() * (std::mem::size_of::<PairId>() + std::mem::size_of::<ElementId>())
    }
}

impl LinkStore {
    /// The pair joining `a` and `b`, if stored.
    pub fn find(&self, a: ElementId, b: ElementId) -> Option<PairId> {
        let (short, other) = if self.adjacency[a as usize].len() <= self.adjacency[b as usize].len() {
            (a, b)
        } else {
            (b, a)
        };
        self.adjacency[short as usize].iter().copied().find(|&p| self.other(p, short) == other)
    }

    /// Both blocks of a pair as f64 row-major, oriented as `(G_ab, G_ba)` for the given `a`.
    pub fn blocks_f64(&self, p: PairId, a: ElementId) -> (Vec<f64>, Vec<f64>) {
        let b = self.other(p, a);
        let ab = self.block(p, a).iter().map(|&x| x as f64).collect();
        let ba = self.block(p, b).iter().map(|&x| x as f64).collect();
        (ab, ba)
    }
}

/// The blocks [`LinkStore::replace_blocks`] replaced.
#[derive(Default)]
pub struct ReplacedBlocks {
    n2: usize,
    /// In write order.
    old: Vec<f32>,
    /// Per item and half (`2 k + half`): its place in `old`.
    position: Vec<u32>,
}

impl ReplacedBlocks {
    /// The old block of item `k`: half 0 is `G_r,other`, half 1 `G_other,r` (row-major).
    pub fn get(&self, k: usize, half: usize) -> &[f32] {
        &self.old[self.position[2 * k + half] as usize * self.n2..][..self.n2]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A block whose entries name it: `pair`, receiver and index.
    fn block(nb: usize, pair: usize, receiver: u32, scale: f64) -> Vec<f64> {
        (0..nb * nb).map(|x| scale * (1000 * pair + 100 * receiver as usize + x) as f64).collect()
    }

    /// The log lists added pairs and real visibility changes, is unknown before it is first
    /// taken, and gives up (unknown) rather than grow past the number of pairs.
    #[test]
    fn visibility_changes_are_logged_between_takes() {
        let nb = 1;
        let mut store = LinkStore::new(3, nb);
        let zero = [0.0];
        store.push(0, 1, &zero, &zero, Visibility::Full);
        assert_eq!(store.take_visibility_changes(), None, "unknown before the first take");
        store.push(1, 2, &zero, &zero, Visibility::Full);
        store.set_visibility(0, Visibility::Full); // unchanged: not logged
        store.set_visibility(0, Visibility::Blocked);
        assert_eq!(store.take_visibility_changes(), Some(vec![1, 0]));
        assert_eq!(store.take_visibility_changes(), Some(vec![]));
        for k in 0..2000 {
            let vis = if k % 2 == 0 { Visibility::Full } else { Visibility::Blocked };
            store.set_visibility(0, vis);
        }
        assert_eq!(store.take_visibility_changes(), None, "more changes than pairs: unknown");
        store.set_visibility(1, Visibility::Blocked);
        assert_eq!(store.take_visibility_changes(), Some(vec![1]));
    }

    #[test]
    fn replace_blocks_writes_the_new_and_returns_the_old_in_either_orientation() {
        let nb = 4;
        let n2 = nb * nb;
        let mut store = LinkStore::new(4, nb);
        let pairs = [(0u32, 1u32), (2, 1), (0, 3), (3, 2)];
        for (k, &(a, b)) in pairs.iter().enumerate() {
            store.push(a, b, &block(nb, k, a, 1.0), &block(nb, k, b, 1.0), Visibility::Full);
        }
        // Pair 1 given from its `a` side, pair 3 from its `b` side, pair 0 left alone.
        let new: Vec<(PairId, ElementId, Vec<f32>)> = [(1u32, 2u32), (3, 2)]
            .iter()
            .map(|&(p, r)| {
                let other = store.other(p, r);
                let g: Vec<f32> = block(nb, p as usize, r, -1.0)
                    .into_iter()
                    .chain(block(nb, p as usize, other, -1.0))
                    .map(|x| x as f32)
                    .collect();
                (p, r, g)
            })
            .collect();
        let items: Vec<(PairId, ElementId, &[f32])> = new.iter().map(|(p, r, g)| (*p, *r, &g[..])).collect();
        let before: Vec<Vec<f32>> = items
            .iter()
            .flat_map(|&(p, r, _)| [store.block(p, r), store.block(p, store.other(p, r))])
            .collect();
        let untouched = (store.block(0, 0), store.block(0, 1), store.block(2, 0), store.block(2, 3));
        let mut replaced = ReplacedBlocks::default();
        store.replace_blocks(&items, &mut replaced).unwrap();
        for (k, &(p, r, g)) in items.iter().enumerate() {
            assert_eq!(store.block(p, r), g[..n2]);
            assert_eq!(store.block(p, store.other(p, r)), g[n2..]);
            assert_eq!(replaced.get(k, 0), &before[2 * k][..]);
            assert_eq!(replaced.get(k, 1), &before[2 * k + 1][..]);
        }
        assert_eq!(untouched, (store.block(0, 0), store.block(0, 1), store.block(2, 0), store.block(2, 3)));
    }

    /// Every row's `S_i` recomputed on the grid over the store as it is.
    fn fresh_row_sums(store: &LinkStore) -> Vec<i128> {
        (0..store.receivers.len() as ElementId)
            .map(|i| store.pairs_of(i).iter().map(|&p| g00_fixed(store.column(p, i, 0)[0])).sum())
            .collect()
    }

    /// The kept row sums follow pushes, whole rows and rewrites (one pair emptied, one rewritten
    /// twice, values spanning 30 orders of magnitude, one below the grid) and equal a recomputation
    /// from the final values bit for bit, and a sequential f64 sum within its rounding bound.
    #[test]
    fn row_sums_follow_every_write_exactly() {
        let nb = 4;
        let n2 = nb * nb;
        let mut store = LinkStore::new(5, nb);
        // G^00 of pair k's two blocks: a spread of magnitudes, so that an f64 running sum rounds.
        let g00 = |k: usize, side: usize| 0.37 * 10f64.powi(-(((7 * k + 3 * side) % 31) as i32)) + 1e-3;
        let with_g00 = |k: usize, side: usize, r: u32| {
            let mut g = block(nb, k, r, 1e-4);
            g[0] = g00(k, side);
            g
        };
        store.push(0, 1, &with_g00(0, 0, 0), &with_g00(0, 1, 1), Visibility::Full);
        store.push(2, 1, &with_g00(1, 0, 2), &with_g00(1, 1, 1), Visibility::Full);
        let mut rows = Vec::new();
        for (a, sources) in [(3u32, vec![0u32, 1, 2]), (4, vec![0, 2, 3])] {
            let mut coeffs = Vec::new();
            for (k, &b) in sources.iter().enumerate() {
                let pair = 10 + a as usize * 3 + k;
                coeffs.extend(with_g00(pair, 0, a).iter().chain(&with_g00(pair, 1, b)).map(|&x| x as f32));
            }
            let visibility = vec![Visibility::Full; sources.len()];
            rows.push(LinkRow { a, sources, coeffs, visibility });
        }
        store.extend_rows(rows).unwrap();
        assert_eq!(store.g00_sums, fresh_row_sums(&store));
        let mut tiny: Vec<f32> = (0..2 * n2).map(|x| 1e-3 * x as f32).collect();
        tiny[0] = 1e-30; // below the grid: truncated to 0, in both sums alike
        let zero = vec![0.0f32; 2 * n2];
        let big: Vec<f32> = (0..2 * n2).map(|x| 0.5 + 1e-2 * x as f32).collect();
        let mut replaced = ReplacedBlocks::default();
        store.replace_blocks(&[(1, 1, &big[..]), (3, 3, &zero[..])], &mut replaced).unwrap();
        store.replace_blocks(&[(1, 2, &tiny[..]), (5, 0, &big[..])], &mut replaced).unwrap();
        assert_eq!(store.g00_sums, fresh_row_sums(&store));
        for i in 0..5 {
            let terms: Vec<f64> =
                store.pairs_of(i).iter().map(|&p| store.column(p, i, 0)[0] as f64).collect();
            let sequential: f64 = terms.iter().sum();
            let magnitude: f64 = terms.iter().map(|x| x.abs()).sum();
            let slack = terms.len() as f64 * (f64::EPSILON * magnitude + (-80f64).exp2());
            let kept = store.row_sum(i);
            assert!((kept - sequential).abs() <= slack, "row {i}: kept {kept} sequential {sequential}");
            assert!(kept > 0.0);
        }
    }

    /// `T_j^l` recomputed from scratch over the store as it is.
    fn fresh_transfers(store: &LinkStore) -> Vec<f64> {
        let mut fresh = store.clone();
        let areas = std::mem::take(&mut fresh.areas);
        fresh.set_receiver_areas(&areas);
        fresh.transfer
    }

    #[test]
    fn transfers_follow_replaced_and_added_blocks() {
        let nb = 4;
        let mut store = LinkStore::new(5, nb);
        for (k, &(a, b)) in [(0u32, 1u32), (2, 1), (0, 3), (3, 2)].iter().enumerate() {
            // Signed entries: the transfer sums magnitudes.
            let sign = |x: f64| if (x as usize).is_multiple_of(3) { -x } else { x };
            let ab: Vec<f64> = block(nb, k, a, 1e-3).into_iter().map(sign).collect();
            store.push(a, b, &ab, &block(nb, k, b, 1e-3), Visibility::Full);
        }
        let areas = [1.0, 2.0, 0.5, 3.0, 4.0];
        store.set_receiver_areas(&areas);
        assert!(store.transfers().iter().any(|&t| t > 0.0));
        assert_eq!(store.transfers(), fresh_transfers(&store));
        // Rewrite two pairs (one to zero), then add one: the kept transfers move with them.
        let g1: Vec<f32> = (0..2 * nb * nb).map(|x| 0.01 * x as f32 - 0.1).collect();
        let g3 = vec![0.0f32; 2 * nb * nb];
        store.replace_blocks(&[(1, 2, &g1[..]), (3, 3, &g3[..])], &mut ReplacedBlocks::default()).unwrap();
        store.push(4, 0, &block(nb, 9, 4, 2e-3), &block(nb, 9, 0, 2e-3), Visibility::Full);
        let (kept, fresh) = (store.transfers().to_vec(), fresh_transfers(&store));
        for (k, f) in kept.iter().zip(&fresh) {
            assert!((k - f).abs() <= 1e-12 * f.abs().max(1.0), "kept {k} fresh {f}");
        }
        // New areas reweigh everything; the same areas (to rounding) keep the transfers.
        let scaled: Vec<f64> = areas.iter().map(|a| 2.0 * a).collect();
        store.set_receiver_areas(&scaled);
        for (k, f) in store.transfers().iter().zip(&fresh) {
            assert!((k - 2.0 * f).abs() <= 1e-12 * f.abs().max(1.0));
        }
        let before = store.transfers().to_vec();
        store.set_receiver_areas(&scaled.iter().map(|a| a * (1.0 + 1e-14)).collect::<Vec<_>>());
        assert_eq!(store.transfers(), before);
    }
}
