//! Taking pairs out of the hierarchy's stores: `cargo bench --bench stores [-- --quick]`.
//!
//! An update takes a move's pairs out of the links, their loads and the hidden pairs, and a
//! relink the pairs it splits, keeping the rest in order. Stores the size of the full
//! monastery's (15.4M links, 43.5M hidden pairs), one entry in 300 taken out at scattered
//! places; `Vec::retain` against `refine::take_out`, alternated round by round in one run, each
//! on a fresh copy. Prints docs/benchmarks.md's `store-compaction` block.

use std::time::Instant;

use galerkin_radiosity::hierarchy::coupling::{Coupling, Link};
use galerkin_radiosity::hierarchy::refine::take_out;

/// Seconds of `Vec::retain` and of `take_out` on copies of `store` without the entries `gone`.
fn time_both<T: Clone>(store: &[T], gone: &[usize]) -> (f64, f64) {
    let mut keep = vec![true; store.len()];
    for &i in gone {
        keep[i] = false;
    }
    let mut list = store.to_vec();
    let t = Instant::now();
    let mut k = keep.iter();
    list.retain(|_| *k.next().unwrap());
    let retain = t.elapsed().as_secs_f64();
    let kept = list.len();
    drop(list);
    let mut list = store.to_vec();
    let t = Instant::now();
    take_out(&mut list, gone, |_| {});
    let by_index = t.elapsed().as_secs_f64();
    assert_eq!(list.len(), kept);
    (retain, by_index)
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    let scale = if quick { 10 } else { 1 };
    let (links, pairs) = (15_400_000 / scale, 43_500_000 / scale);
    // Mostly constant links, some cluster links, a few with blocks (as the full monastery's).
    let store: Vec<Link> = (0..links as u32)
        .map(|i| Link {
            a: i,
            b: i.wrapping_mul(7),
            coupling: match i % 3000 {
                0 => Coupling::Surfaces(vec![1.0; 8].into()),
                k if k % 9 == 0 => Coupling::Clusters { transmittance: 1.0, partial: false },
                _ => Coupling::Constants { ab: 1.0, ba: 2.0 },
            },
        })
        .collect();
    let hidden: Vec<(u32, u32)> = (0..pairs as u32).map(|i| (i, i ^ 5)).collect();
    let gone = |n: usize| (0..n).filter(|i| i.wrapping_mul(2654435761) % 300 == 0).collect::<Vec<_>>();
    let (gone_links, gone_pairs) = (gone(links), gone(pairs));
    let rounds = if quick { 3 } else { 5 };
    let (mut l, mut p) = ((Vec::new(), Vec::new()), (Vec::new(), Vec::new()));
    for _ in 0..rounds {
        let (r, t) = time_both(&store, &gone_links);
        l.0.push(r);
        l.1.push(t);
        let (r, t) = time_both(&hidden, &gone_pairs);
        p.0.push(r);
        p.1.push(t);
    }
    println!(
        "Taking one entry in 300 out of a store, the others kept in order ({} threads, medians of {rounds} \
         rounds, each on a fresh copy):\n",
        rayon::current_num_threads()
    );
    println!("| store | entries | taken out | Vec::retain s | take_out s | x faster |");
    println!("|---|---|---|---|---|---|");
    for (name, n, taken, (r, t)) in [
        ("links (32 bytes each)", links, gone_links.len(), l),
        ("hidden pairs (8 bytes each)", pairs, gone_pairs.len(), p),
    ] {
        let (r, t) = (median(r), median(t));
        println!("| {name} | {n} | {taken} | {r:.4} | {t:.4} | {:.1}x |", r / t);
    }
}
