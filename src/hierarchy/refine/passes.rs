//! Passes over the stored pairs (links, hidden pairs, idle pairs), in parallel pieces: the
//! entries a verdict takes out or a relink's test fails, and taking entries out by index.

use rayon::prelude::*;

/// The indices of `list`'s entries that `gone` says go, ascending (found in parallel).
pub(super) fn indices_where<T: Sync>(list: &[T], gone: impl Fn(&T) -> bool + Sync) -> Vec<usize> {
    // In pieces, each a plain loop, as [`failing`]'s (by entry, a parallel iterator's
    // `filter_map`: the verdicts 15% slower on the 30k-triangle part's stores).
    list.par_chunks(PASS_CHUNK)
        .enumerate()
        .flat_map_iter(|(k, piece)| {
            let first = k * PASS_CHUNK;
            piece.iter().enumerate().filter(|(_, x)| gone(x)).map(move |(j, _)| first + j).collect::<Vec<_>>()
        })
        .collect()
}

/// Takes the entries at `gone` (ascending indices) out of `list`, keeping the others in order,
/// and hands each to `removed` first. The runs kept between them move down whole, a `memmove`
/// each: `Vec::retain` moved them entry by entry, 1.6x slower on 15M links and 1.8x on 43M
/// hidden pairs with one in 300 taken out (`cargo bench --bench stores`), and an update of the
/// full monastery compacts each store once or twice.
pub fn take_out<T>(list: &mut Vec<T>, gone: &[usize], mut removed: impl FnMut(&T)) {
    let Some(&first) = gone.first() else { return };
    let len = list.len();
    assert!(
        gone.windows(2).all(|w| w[0] < w[1]) && gone[gone.len() - 1] < len,
        "indices ascending, in range"
    );
    for &i in gone {
        removed(&list[i]);
    }
    // SAFETY: the length is cut to `first` before anything moves, so a panicking drop leaks
    // the rest instead of dropping an entry twice. Entry `gone[k]` is dropped before the run
    // after it moves down by `k + 1` onto `write`, which stays below `gone[k]`: no entry is
    // read after it was dropped or overwritten, and `ptr::copy` allows the runs to overlap.
    unsafe {
        list.set_len(first);
        let base = list.as_mut_ptr();
        let mut write = first;
        for (k, &i) in gone.iter().enumerate() {
            std::ptr::drop_in_place(base.add(i));
            let next = gone.get(k + 1).copied().unwrap_or(len);
            let run = next - i - 1;
            std::ptr::copy(base.add(i + 1), base.add(write), run);
            write += run;
        }
        list.set_len(write);
    }
}

/// Stored pairs a pass over a store takes in one piece of work ([`failing`], [`indices_where`]).
const PASS_CHUNK: usize = 4096;

/// The indices, ascending, of the pairs whose load is above `skip_at_most` and which `fails`
/// says fail (`fails(index, load)`, which may rewrite the load). In parallel pieces of
/// [`PASS_CHUNK`] loads, each first compared with `skip_at_most` all together (a loop the
/// compiler vectorises), a piece with none above it left whole: a quick relink finds a few
/// hundred loads above its bar among tens of millions. (The pass by pair, a parallel iterator's
/// `filter_map`, took 0.09 s for the full monastery's 43.5M hidden pairs' loads; the same loop
/// by pieces, 0.02-0.03 s, measured apart on as many loads.) A NaN load is above any bar.
pub(super) fn failing(
    loads: &mut [f32],
    skip_at_most: f64,
    fails: impl Fn(usize, &mut f32) -> bool + Sync,
) -> Vec<usize> {
    loads
        .par_chunks_mut(PASS_CHUNK)
        .enumerate()
        .flat_map_iter(|(k, piece)| {
            let mut out = Vec::new();
            let above = |l: f32| l as f64 > skip_at_most || l.is_nan();
            if piece.iter().fold(false, |any, &l| any | above(l)) {
                let first = k * PASS_CHUNK;
                for (j, load) in piece.iter_mut().enumerate() {
                    if above(*load) && fails(first + j, load) {
                        out.push(first + j);
                    }
                }
            }
            out
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::rc::Rc;

    /// `take_out` leaves what `Vec::retain` leaves, in order, hands it the entries taken, and
    /// drops each taken entry once and no kept one (counted through `Rc`s), for random patterns:
    /// none, all, runs at either end, scattered.
    #[test]
    fn taking_out_by_index_keeps_what_retain_keeps() {
        let mut state = 0x853C_49E6_748F_EA9Bu64;
        let mut next = move |n: usize| {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((state >> 33) as usize) % n.max(1)
        };
        for round in 0..200 {
            let len = next(60);
            let tokens: Vec<Rc<usize>> = (0..len).map(Rc::new).collect();
            let share = [0, 1, 2, 10][round % 4];
            let gone: Vec<usize> = (0..len)
                .filter(|&i| match share {
                    0 => false,
                    1 => true,
                    2 => i < len / 3 || i + 2 >= len,
                    _ => next(10) < 3,
                })
                .collect();
            let mut list: Vec<Rc<usize>> = tokens.to_vec();
            let mut want = list.clone();
            let mut k = 0..;
            want.retain(|_| !gone.contains(&k.next().unwrap()));
            let mut handed = Vec::new();
            take_out(&mut list, &gone, |x| handed.push(**x));
            assert_eq!(handed, gone, "round {round}");
            assert_eq!(
                list.iter().map(|x| **x).collect::<Vec<_>>(),
                want.iter().map(|x| **x).collect::<Vec<_>>()
            );
            drop(want);
            for (i, t) in tokens.iter().enumerate() {
                // The test's own handle, and the list's for a kept entry.
                let held = if gone.contains(&i) { 1 } else { 2 };
                assert_eq!(Rc::strong_count(t), held, "round {round}, entry {i}");
            }
        }
    }

    /// `failing` finds, in order, the pairs a plain loop over every load finds (a load above the
    /// bar, NaN included, that the test fails), leaves the loads below the bar unread, and keeps
    /// what the test writes to a load; `indices_where` is a plain filter's indices. Over several
    /// pieces, the last one partly filled, with lone loads above the bar in otherwise quiet
    /// pieces, and with no bar (a full pass) as well.
    #[test]
    fn the_passes_by_pieces_find_what_a_plain_loop_finds() {
        let mut rng = crate::hierarchy::coupling::SplitMix(0x2545_F491_4F6C_DD1D);
        let mut next = move || rng.next();
        let len = 3 * PASS_CHUNK + 123;
        let mut loads: Vec<f32> = (0..len)
            .map(|_| match next() {
                r if r < 0.001 => f32::NAN,
                r if r < 0.01 => 1.5 * r as f32 * 100.0,
                r => 0.5 * r as f32,
            })
            .collect();
        // A quiet piece with one load above the bar, and a last piece whose only one is a NaN.
        loads[2 * PASS_CHUNK..].iter_mut().for_each(|l| *l = 0.1);
        (loads[2 * PASS_CHUNK + 9], loads[3 * PASS_CHUNK + 6]) = (0.9, f32::NAN);
        for bar in [0.6, f64::NEG_INFINITY] {
            // Fails every third index, and halves the load of every pair it is asked about.
            let fails = |i: usize, load: &mut f32| {
                *load *= 0.5;
                i.is_multiple_of(3)
            };
            let mut plain = loads.clone();
            let mut want = Vec::new();
            for (i, load) in plain.iter_mut().enumerate() {
                if (*load as f64 > bar || load.is_nan()) && fails(i, load) {
                    want.push(i);
                }
            }
            let mut pieces = loads.clone();
            let seen = std::sync::atomic::AtomicUsize::new(0);
            let got = failing(&mut pieces, bar, |i, load| {
                assert!(loads[i] as f64 > bar || loads[i].is_nan(), "load {i} below the bar was tested");
                seen.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                fails(i, load)
            });
            assert_eq!(got, want, "bar {bar}");
            assert!(want.len() > 3 && seen.into_inner() > want.len(), "too few tested");
            let same = |x: &f32, y: &f32| x.to_bits() == y.to_bits();
            assert!(plain.iter().zip(&pieces).all(|(x, y)| same(x, y)), "bar {bar}: the loads differ");
        }
        let want: Vec<usize> = (0..len).filter(|&i| loads[i] > 0.3).collect();
        assert_eq!(indices_where(&loads, |&l| l > 0.3), want);
    }
}
