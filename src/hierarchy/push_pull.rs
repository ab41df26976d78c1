//! The walk between a sweep's gathered light and the leaves' solution: what every node gathered
//! pushed down to the leaves with the two-scale relations ([`super::two_scale`]), `b = e + rho H`
//! set there, and the leaves' solution pulled back up (means, polynomials, cluster lobes); or the
//! pull alone ([`Walk::pull`]). The subtrees below the first levels of clusters are walked in
//! parallel: walked in turn it was a fifth of a sweep on a 30k-triangle model.

use std::marker::PhantomData;

use glam::DVec3;
use rayon::prelude::*;

use super::lobes::{self, Lobes};
use super::solve::Gathered;
use super::tree::{Kind, NodeId, Surface, Tree};
use super::two_scale::TwoScale;

/// Clusters at fewer than this many levels below the walk's start hand their children to other
/// threads: 2^8 subtrees and more for two threads to share, each large enough to be worth it.
const PARALLEL_LEVELS: usize = 8;

/// The node-indexed arrays a walk writes, shared by the threads that walk disjoint subtrees.
///
/// The walk's rule, on which its accessors' safety rests: node `i`'s entries are written only by
/// the visit of node `i`, and read by it and by its parent's visit, which comes after it (in the
/// same thread, or after the `rayon` join that waited for it). No two threads ever reach the
/// same node: the tree is a tree.
pub(super) struct Nodes<'a> {
    b: *mut [f64; 3],
    mean: *mut [f64; 3],
    lobes: *mut Lobes,
    nb: usize,
    len: usize,
    _arrays: PhantomData<&'a mut [f64; 3]>,
}

// SAFETY: the walk's rule above: no entry is reached by two threads at once.
unsafe impl Send for Nodes<'_> {}
unsafe impl Sync for Nodes<'_> {}

impl<'a> Nodes<'a> {
    pub fn new(b: &'a mut [[f64; 3]], mean: &'a mut [[f64; 3]], lobes: &'a mut [Lobes], nb: usize) -> Self {
        let len = mean.len();
        assert!(b.len() == len * nb && lobes.len() == len, "one entry per node in every array");
        Self {
            b: b.as_mut_ptr(),
            mean: mean.as_mut_ptr(),
            lobes: lobes.as_mut_ptr(),
            nb,
            len,
            _arrays: PhantomData,
        }
    }

    /// Node `i`'s coefficients.
    ///
    /// # Safety
    /// Only under the walk's rule ([`Nodes`]).
    #[allow(clippy::mut_from_ref)]
    unsafe fn b(&self, i: usize) -> &mut [[f64; 3]] {
        assert!(i < self.len);
        // SAFETY: in bounds (above); exclusive by the walk's rule.
        unsafe { std::slice::from_raw_parts_mut(self.b.add(i * self.nb), self.nb) }
    }

    /// Node `i`'s mean radiosity.
    ///
    /// # Safety
    /// Only under the walk's rule ([`Nodes`]).
    #[allow(clippy::mut_from_ref)]
    unsafe fn mean(&self, i: usize) -> &mut [f64; 3] {
        assert!(i < self.len);
        // SAFETY: as `b`.
        unsafe { &mut *self.mean.add(i) }
    }

    /// Node `i`'s intensity lobes.
    ///
    /// # Safety
    /// Only under the walk's rule ([`Nodes`]).
    #[allow(clippy::mut_from_ref)]
    unsafe fn lobes(&self, i: usize) -> &mut Lobes {
        assert!(i < self.len);
        // SAFETY: as `b`.
        unsafe { &mut *self.lobes.add(i) }
    }
}

/// How a walk sets a leaf from the light `H` that reached it.
#[derive(Clone, Copy)]
pub(super) enum Leaves<'a> {
    /// `b = e + rho bound H`: the solve, each leaf's reflectance scaled by its hemisphere bound
    /// (per node; empty: none, every factor 1; [`super::solve::State::bound_leaves`]).
    Solve { bound: &'a [f64] },
    /// `b = H`: the furnace, every surface white and dark, which makes a leaf's mean the sum of
    /// its form factors when every source is at `B = 1`.
    Furnace,
}

/// One walk over the tree.
pub(super) struct Walk<'a> {
    pub tree: &'a Tree,
    pub nodes: Nodes<'a>,
    /// Per leaf, `e^k + (rho E_d)^k` (`nodes x nb`).
    pub sources: &'a [[f64; 3]],
    /// How the leaves take what reaches them.
    pub leaves: Leaves<'a>,
    pub two_scale: &'a TwoScale,
    pub nb: usize,
}

/// What [`Walk::push`] starts from at the root, and hands below a face: no slope.
pub const NO_SLOPE: [DVec3; 3] = [DVec3::ZERO; 3];

impl Walk<'_> {
    /// Pushes what the subtree of `id` received (with `inherited` lobes and `pushed`
    /// coefficients from above) to its leaves, sets `b = e + rho H` there and, with `pull`,
    /// pulls; returns the leaves' area-weighted change of mean radiosity (summed in the same
    /// order whatever the threads, so that the solve stops at the same sweep). Without `pull`
    /// only the leaves' `b` and means are written, the nodes above them left as they were until
    /// a [`Walk::pull`]: for a sweep that the mixer changes before anything reads it (it pulled
    /// twice), and for the furnace, which reads the leaves alone.
    pub fn push(
        &self,
        id: NodeId,
        (inherited, slope): (&Lobes, &[DVec3; 3]),
        pushed: &[[f64; 3]],
        got: &Gathered,
        level: usize,
        pull: bool,
    ) -> f64 {
        let nb = self.nb;
        let i = id as usize;
        let node = &self.tree.nodes[i];
        let change = match &node.kind {
            Kind::Cluster { children } => {
                let mut l = *inherited;
                if let Some(own) = got.lobes.get(i) {
                    lobes::add(&mut l, own);
                }
                // What a planar cluster gathered is an irradiance over its plane: a constant at
                // its centroid and a slope, handed to each child at the child's centroid (the
                // slope inherited from a planar parent too, whose plane is this one's). The
                // centroid is the children's area-weighted, so that the slope moves no light.
                // (On the stack, as the surfaces' below: a heap vector per node and sweep was a
                // tenth of the push-pull.)
                let mut flat = [[0.0; 3]; crate::basis::MAX_LEN];
                let flat = &mut flat[..nb];
                flat.copy_from_slice(pushed);
                if let Some(own) = got.h.get(i * nb) {
                    for c in 0..3 {
                        flat[0][c] += own[c];
                    }
                }
                let mut g = if node.plane_normal.is_some() { *slope } else { [DVec3::ZERO; 3] };
                if let (Some(own), Some(_)) = (got.slopes.get(i), node.plane_normal) {
                    for c in 0..3 {
                        g[c] += own[c];
                    }
                }
                let sloped = g != [DVec3::ZERO; 3];
                let here = if sloped { self.tree.centroid(id) } else { DVec3::ZERO };
                let (flat, g) = (&*flat, &g);
                let child = |c: NodeId| {
                    let mut at = [[0.0; 3]; crate::basis::MAX_LEN];
                    let at = &mut at[..nb];
                    at.copy_from_slice(flat);
                    if sloped {
                        let d = self.tree.centroid(c) - here;
                        for ch in 0..3 {
                            at[0][ch] += g[ch].dot(d);
                        }
                    }
                    self.push(c, (&l, g), at, got, level + 1, pull)
                };
                if level < PARALLEL_LEVELS {
                    let parts: Vec<f64> = children.par_iter().map(|&c| child(c)).collect();
                    parts.iter().sum()
                } else {
                    children.iter().map(|&c| child(c)).sum()
                }
            }
            Kind::Surface(s) => {
                let mut h = [[0.0; 3]; crate::basis::MAX_LEN];
                let h = &mut h[..nb];
                h.copy_from_slice(pushed);
                if let Some(own) = got.h.get(i * nb..(i + 1) * nb) {
                    for k in 0..nb {
                        for c in 0..3 {
                            h[k][c] += own[k][c];
                        }
                    }
                }
                if s.depth == 0 {
                    let e = lobes::eval(inherited, s.normal);
                    for c in 0..3 {
                        h[0][c] += e[c];
                    }
                }
                match s.children {
                    None => {
                        // SAFETY: node `i`, in its own visit (the walk's rule).
                        let (b, before) = unsafe { (self.nodes.b(i), *self.nodes.mean(i)) };
                        match self.leaves {
                            Leaves::Solve { bound } => {
                                let f = bound.get(i).copied().unwrap_or(1.0);
                                let rho = self.tree.reflectance[s.face as usize].map(|r| r * f);
                                for k in 0..nb {
                                    for c in 0..3 {
                                        b[k][c] = self.sources[i * nb + k][c] + rho[c] * h[k][c];
                                    }
                                }
                            }
                            Leaves::Furnace => b.copy_from_slice(h),
                        }
                        let after = self.mean_of(s, i);
                        if !pull {
                            // SAFETY: as above.
                            unsafe { *self.nodes.mean(i) = after };
                        }
                        node.area * (0..3).map(|c| (after[c] - before[c]).abs()).fold(0.0, f64::max)
                    }
                    Some(children) => {
                        let mut change = 0.0;
                        for (q, &c) in children.iter().enumerate() {
                            let mut hq = [[0.0; 3]; crate::basis::MAX_LEN];
                            self.two_scale.push_add(q, h, &mut hq[..nb]);
                            change +=
                                self.push(c, (&lobes::ZERO, &NO_SLOPE), &hq[..nb], got, level + 1, pull);
                        }
                        change
                    }
                }
            }
        };
        if pull {
            self.pull_node(id);
        }
        change
    }

    /// Sets every node of the subtree of `id` above its leaves from its children (the pull half
    /// of [`Walk::push`], without its pushes).
    pub fn pull(&self, id: NodeId, level: usize) {
        let children = self.tree.children(id);
        if level < PARALLEL_LEVELS && self.tree.nodes[id as usize].is_cluster() {
            children.par_iter().for_each(|&c| self.pull(c, level + 1));
        } else {
            for &c in children {
                self.pull(c, level + 1);
            }
        }
        self.pull_node(id);
    }

    /// Sets node `id` from its children, which are set: a surface's polynomial as its
    /// quadrants' projection and its mean from theirs (a leaf's from its own polynomial), a
    /// face's intensity lobe from its mean, a cluster's mean and lobes as its children's sum.
    fn pull_node(&self, id: NodeId) {
        let nb = self.nb;
        let i = id as usize;
        let node = &self.tree.nodes[i];
        let children = self.tree.children(id);
        // SAFETY (every access below): node `i` in its own visit, its children after theirs (the
        // walk's rule).
        let mut power = [0.0; 3];
        for &c in children {
            let a = self.tree.nodes[c as usize].area;
            let m = unsafe { *self.nodes.mean(c as usize) };
            for ch in 0..3 {
                power[ch] += m[ch] * a;
            }
        }
        let from_children = power.map(|p| if node.area > 0.0 { p / node.area } else { 0.0 });
        match &node.kind {
            Kind::Cluster { children } => {
                let mut out = lobes::ZERO;
                for &c in children {
                    lobes::add(&mut out, unsafe { self.nodes.lobes(c as usize) });
                }
                unsafe {
                    *self.nodes.lobes(i) = out;
                    *self.nodes.mean(i) = from_children;
                }
            }
            Kind::Surface(s) => {
                // The mean from the leaves (area-weighted), which a pulled polynomial keeps only
                // where the area element is polynomial of the basis order.
                let mean = match s.children {
                    None => self.mean_of(s, i),
                    Some(children) => {
                        let part =
                            |q: usize| -> &[[f64; 3]] { unsafe { self.nodes.b(children[q] as usize) } };
                        let mut pulled = [[0.0; 3]; crate::basis::MAX_LEN];
                        self.two_scale.pull([part(0), part(1), part(2), part(3)], &mut pulled[..nb]);
                        unsafe { self.nodes.b(i) }.copy_from_slice(&pulled[..nb]);
                        from_children
                    }
                };
                unsafe { *self.nodes.mean(i) = mean };
                if s.depth == 0 {
                    let mut l = lobes::ZERO;
                    let f = node.area / std::f64::consts::PI;
                    lobes::add_lobe(&mut l, s.normal, mean.map(|m| m * f));
                    unsafe { *self.nodes.lobes(i) = l };
                }
            }
        }
    }

    /// Surface node `i`'s mean radiosity from its polynomial.
    fn mean_of(&self, s: &Surface, i: usize) -> [f64; 3] {
        let area: f64 = s.moments[0];
        // SAFETY: node `i`, in its own visit (the walk's rule).
        let b = unsafe { self.nodes.b(i) };
        let mut out = [0.0; 3];
        for (k, bk) in b.iter().enumerate() {
            for c in 0..3 {
                out[c] += s.moments[k] * bk[c];
            }
        }
        out.map(|x| if area > 0.0 { x / area } else { 0.0 })
    }
}
