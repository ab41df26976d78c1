//! Writing the changed pairs into the store: stored pairs rewritten in parallel, new pairs
//! appended one by one (rare), each with its visibility and its series, counted by the reason it
//! changed.

use crate::error::Result;
use crate::links::{PairId, ReplacedBlocks};
use crate::system::System;

use super::pairs::{PairUpdate, Reason, SeriesAction, UpdateBatch};
use super::{AnimationState, UpdateStats, mark_visibility_change};

/// The pairs written this frame, with their new blocks `[G_ij | G_ji]` (in their batches).
pub(super) struct Written<'b> {
    /// Stored pairs rewritten: the pair, the element `i` its blocks start from, the blocks.
    pub(super) rewrites: Vec<(PairId, u32, &'b [f32])>,
    /// New pairs `(i, j)` and their blocks.
    pub(super) fresh: Vec<(u32, u32, &'b [f32])>,
}

/// Writes the pairs of `batches` (taking their updates) into `sys`'s store and their series and
/// visibility changes into `state`, with the stored blocks they replace in `replaced`.
pub(super) fn write_store<'b>(
    sys: &mut System,
    state: &mut AnimationState,
    batches: &'b mut [UpdateBatch],
    replaced: &mut ReplacedBlocks,
    stats: &mut UpdateStats,
) -> Result<Written<'b>> {
    let nb = sys.basis.len();
    let n2 = nb * nb;
    let updates: Vec<Vec<PairUpdate>> = batches.iter_mut().map(|b| std::mem::take(&mut b.updates)).collect();
    let mut rewrites: Vec<(PairId, u32, &'b [f32])> = Vec::with_capacity(updates.iter().map(Vec::len).sum());
    let mut fresh: Vec<(u32, u32, &'b [f32])> = Vec::new();
    let batches: &'b [UpdateBatch] = batches;
    let in_order = batches
        .iter()
        .zip(updates)
        .flat_map(|(b, us)| us.into_iter().enumerate().map(move |(k, u)| (b, k, u)));
    for (batch, k, u) in in_order {
        match u.reason {
            Reason::Series => stats.links_series += 1,
            Reason::Bound => stats.recomputed_bound += 1,
            Reason::Direction => stats.recomputed_direction += 1,
            Reason::HalfSpace => stats.recomputed_half_space += 1,
            Reason::Visibility => stats.recomputed_visibility += 1,
            Reason::NonTranslation => stats.recomputed_non_translation += 1,
            Reason::Translation => stats.recomputed_translation += 1,
        }
        if u.reason != Reason::Series {
            stats.links_recomputed += 1;
        }
        let blocks = &batch.blocks[2 * n2 * k..][..2 * n2];
        let p = match u.id {
            Some(p) => {
                if sys.links.pair(p).visibility != u.vis {
                    mark_visibility_change(state, p);
                }
                sys.links.set_visibility(p, u.vis);
                rewrites.push((p, u.i, blocks));
                p
            }
            None => {
                let wide: Vec<f64> = blocks.iter().map(|&x| x as f64).collect();
                let p = sys.links.push(u.i, u.j, &wide[..n2], &wide[n2..], u.vis);
                state.index.insert(u.i, u.j, p);
                mark_visibility_change(state, p);
                fresh.push((u.i, u.j, blocks));
                p
            }
        };
        if state.series.len() <= p as usize {
            state.series.resize_with(p as usize + 1, || None);
        }
        match u.series {
            SeriesAction::Keep => {}
            SeriesAction::Drop => state.series[p as usize] = None,
            SeriesAction::Set(ser) => {
                // Series are stored with the pair's own orientation (a, b).
                debug_assert_eq!(sys.links.pair(p).a, u.i);
                stats.series_expanded += 1;
                state.series[p as usize] = Some(ser);
            }
        }
    }
    sys.links.replace_blocks(&rewrites, replaced)?;
    Ok(Written { rewrites, fresh })
}
