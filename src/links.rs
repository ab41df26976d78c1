//! The link store: kernel coefficients between elements, independent of how elements relate to
//! faces (one element per face today; elements below faces with hierarchical refinement).
//!
//! A *pair* `(a, b)` holds both directed links: `G_ab` (receiver `a`, source `b`) and `G_ba`, each
//! `nb x nb` f32 with rows indexed by the receiver's basis function. Pairs are recomputed in
//! place by the animation update; a pair that starts or stops interacting is added or emptied.

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
    /// `[G_ab | G_ba]` per source, f32, `2 nb^2` each.
    pub coeffs: Vec<f32>,
    pub visibility: Vec<Visibility>,
}

#[derive(Clone, Debug, Default)]
pub struct LinkStore {
    nb: usize,
    pairs: Vec<Pair>,
    /// `2 nb^2` per pair: `G_ab` then `G_ba`.
    coeffs: Vec<f32>,
    /// Per element: the pairs it belongs to.
    adjacency: Vec<Vec<PairId>>,
    /// Per element, in `adjacency` order: the other element and the block it receives from this
    /// one, so that shooting reads neither the pair records nor the other block.
    sources: Vec<Vec<Neighbour>>,
}

/// An element's partner in a pair, as seen by a shooter: who receives, and from which block.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Neighbour {
    /// The receiving element.
    pub receiver: ElementId,
    /// Index of the `nb x nb` block `G_receiver,shooter` (offset `block * nb^2` in the store).
    pub block: u32,
}

impl LinkStore {
    pub fn new(n_elements: usize, nb: usize) -> Self {
        Self {
            nb,
            pairs: Vec::new(),
            coeffs: Vec::new(),
            adjacency: vec![Vec::new(); n_elements],
            sources: vec![Vec::new(); n_elements],
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

    /// Adds a pair with its two blocks (`ab`, `ba`, f64 `nb x nb` each).
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
        self.coeffs.extend(ab.iter().chain(ba).map(|&x| x as f32));
        self.link(a, b, id);
        id
    }

    fn link(&mut self, a: ElementId, b: ElementId, id: PairId) {
        self.adjacency[a as usize].push(id);
        self.adjacency[b as usize].push(id);
        // G_ab (block 2 id) is received by a from b; G_ba (2 id + 1) by b from a.
        self.sources[b as usize].push(Neighbour { receiver: a, block: 2 * id });
        self.sources[a as usize].push(Neighbour { receiver: b, block: 2 * id + 1 });
    }

    /// What element `e` shoots to: each partner with the block it receives through, in
    /// [`LinkStore::pairs_of`] order.
    pub fn receivers_of(&self, e: ElementId) -> &[Neighbour] {
        &self.sources[e as usize]
    }

    /// Block number `block` (see [`Neighbour::block`]), `nb x nb`, row = receiver function.
    #[inline]
    pub fn block_at(&self, block: u32) -> &[f32] {
        let n2 = self.nb * self.nb;
        &self.coeffs[block as usize * n2..(block as usize + 1) * n2]
    }

    /// Adds rows of pairs `(a, b_k)` with their f32 blocks `[G_ab | G_ba]` one pair after the other
    /// (`2 nb^2` each), in row order then `b` order: as [`LinkStore::push`] one by one, with the
    /// coefficients copied in parallel.
    pub fn extend_rows(&mut self, rows: Vec<LinkRow>) {
        use rayon::prelude::*;
        let block = 2 * self.nb * self.nb;
        let total: usize = rows.iter().map(|r| r.coeffs.len()).sum();
        let start = self.coeffs.len();
        if start == 0 {
            // Zeroed by the allocator (untouched pages), filled by the threads below.
            self.coeffs = vec![0.0f32; total];
        } else {
            self.coeffs.resize(start + total, 0.0);
        }
        let mut dest: Vec<&mut [f32]> = Vec::with_capacity(rows.len());
        let mut rest = &mut self.coeffs[start..];
        for r in &rows {
            let (head, tail) = rest.split_at_mut(r.coeffs.len());
            dest.push(head);
            rest = tail;
        }
        dest.into_par_iter().zip(&rows).for_each(|(d, r)| d.copy_from_slice(&r.coeffs));
        let pairs: usize = rows.iter().map(|r| r.sources.len()).sum();
        self.pairs.reserve(pairs);
        for LinkRow { a, sources: bs, coeffs, visibility: vis } in rows {
            debug_assert_eq!(coeffs.len(), bs.len() * block);
            for (b, v) in bs.into_iter().zip(vis) {
                let id = self.pairs.len() as PairId;
                self.pairs.push(Pair { a, b, visibility: v });
                self.link(a, b, id);
            }
        }
    }

    /// Replaces a pair's coefficients and visibility.
    pub fn set(&mut self, p: PairId, ab: &[f64], ba: &[f64], visibility: Visibility) {
        let n2 = self.nb * self.nb;
        let block = &mut self.coeffs[p as usize * 2 * n2..(p as usize + 1) * 2 * n2];
        for (dst, src) in block.iter_mut().zip(ab.iter().chain(ba)) {
            *dst = *src as f32;
        }
        self.pairs[p as usize].visibility = visibility;
    }

    /// The block with `receiver` as receiver: `G_receiver,other`.
    #[inline]
    pub fn block(&self, p: PairId, receiver: ElementId) -> &[f32] {
        let n2 = self.nb * self.nb;
        let base = p as usize * 2 * n2;
        if self.pairs[p as usize].a == receiver {
            &self.coeffs[base..base + n2]
        } else {
            &self.coeffs[base + n2..base + 2 * n2]
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
        self.coeffs.len() * 4
            + self.pairs.len() * std::mem::size_of::<Pair>()
            + 2 * self.pairs.len() * std::mem::size_of::<Neighbour>()
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

    /// Both blocks of a pair as f64, oriented as `(G_ab, G_ba)` for the given `a`.
    pub fn blocks_f64(&self, p: PairId, a: ElementId) -> (Vec<f64>, Vec<f64>) {
        let b = self.other(p, a);
        let ab = self.block(p, a).iter().map(|&x| x as f64).collect();
        let ba = self.block(p, b).iter().map(|&x| x as f64).collect();
        (ab, ba)
    }
}
