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

use crate::visibility::Visibility;

pub type ElementId = u32;
pub type PairId = u32;

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
    /// Per element, in `adjacency` order: the other element of the pair, which receives what this
    /// one shoots.
    receivers: Vec<Vec<ElementId>>,
    /// `[shooter * nb + l]`: column `l` of `G_receiver,shooter` for each receiver of the shooter,
    /// in `receivers` order, `nb` floats each (index `k`, the receiver's function).
    columns: Vec<Vec<f32>>,
}

impl LinkStore {
    pub fn new(n_elements: usize, nb: usize) -> Self {
        Self {
            nb,
            pairs: Vec::new(),
            slots: Vec::new(),
            adjacency: vec![Vec::new(); n_elements],
            receivers: vec![Vec::new(); n_elements],
            columns: vec![Vec::new(); n_elements * nb],
        }
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
        let nb = self.nb;
        // G_ab is shot by b, G_ba by a; both go to the end of the shooter's columns.
        for (shooter, g) in [(b, ab), (a, ba)] {
            for l in 0..nb {
                self.columns[shooter as usize * nb + l].extend((0..nb).map(|k| g[k * nb + l] as f32));
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
    fn slot(&self, p: PairId, receiver: ElementId) -> (usize, usize) {
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
    /// coefficients copied in parallel (one shooter per task).
    pub fn extend_rows(&mut self, mut rows: Vec<LinkRow>) {
        use rayon::prelude::*;
        let nb = self.nb;
        let n2 = nb * nb;
        let first = self.pairs.len();
        // Where each new pair's blocks are: (row, index in row).
        let mut origin: Vec<(u32, u32)> = Vec::with_capacity(rows.iter().map(|r| r.sources.len()).sum());
        let old_len: Vec<usize> = self.receivers.iter().map(Vec::len).collect();
        for (ri, row) in rows.iter_mut().enumerate() {
            debug_assert_eq!(row.coeffs.len(), row.sources.len() * 2 * n2);
            for (k, (&b, v)) in row.sources.iter().zip(row.visibility.drain(..)).enumerate() {
                let id = self.pairs.len() as PairId;
                self.pairs.push(Pair { a: row.a, b, visibility: v });
                self.link(row.a, b, id);
                origin.push((ri as u32, k as u32));
            }
        }
        let (adjacency, pairs) = (&self.adjacency, &self.pairs);
        self.columns.par_chunks_mut(nb).enumerate().for_each(|(e, cols)| {
            let new = &adjacency[e][old_len[e]..];
            if new.is_empty() {
                return;
            }
            for col in cols.iter_mut() {
                col.reserve_exact(new.len() * nb);
            }
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
    }

    /// Replaces a pair's coefficients (`ab`, `ba`, f64 row-major) and visibility.
    pub fn set(&mut self, p: PairId, ab: &[f64], ba: &[f64], visibility: Visibility) {
        let nb = self.nb;
        let Pair { a, b, .. } = self.pairs[p as usize];
        for (receiver, g) in [(a, ab), (b, ba)] {
            let (shooter, slot) = self.slot(p, receiver);
            for l in 0..nb {
                let col = &mut self.columns[shooter * nb + l][slot * nb..(slot + 1) * nb];
                for (k, dst) in col.iter_mut().enumerate() {
                    *dst = g[k * nb + l] as f32;
                }
            }
        }
        self.pairs[p as usize].visibility = visibility;
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

    /// [`LinkStore::block`] widened to f64 into `out` (`nb * nb`), without allocating.
    pub fn block_into(&self, p: PairId, receiver: ElementId, out: &mut [f64]) {
        let nb = self.nb;
        let (shooter, slot) = self.slot(p, receiver);
        for l in 0..nb {
            let col = &self.columns[shooter * nb + l][slot * nb..(slot + 1) * nb];
            for (k, &x) in col.iter().enumerate() {
                out[k * nb + l] = x as f64;
            }
        }
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
