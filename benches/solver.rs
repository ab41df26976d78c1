//! Solve time of progressive shooting: `cargo bench --bench solver [-- --runs N --frames F]`.
//!
//! Cornell box of ~1,000 patches, moving light, basis order 2 (9 functions per element), 2
//! threads. Two measurements, each alternated `runs` times in this one process so that machine
//! noise hits both sides alike:
//!
//! - **static**: frame 1 solved from emission by `System::solve` (the library) and by
//!   [`reference`], a copy of the solver before per-coefficient shooting (whole unshot vectors,
//!   row-major blocks), on a copy of the same links.
//! - **animation**: a `Session` driven through frames 1..=F; the sum of `FrameStats::solve_seconds`
//!   and `shots` over frames 2..=F (the Delta solves). Compare builds by running this bench at two
//!   commits; `--dump FILE` writes every frame's radiosity at three points of every face and `--compare A B` prints the
//!   worst difference per frame relative to the frame's peak.

use galerkin_radiosity::scene::Settings;
use galerkin_radiosity::scenes;
use galerkin_radiosity::session::{Method, Session};
use galerkin_radiosity::system::{System, no_progress};
use std::time::Instant;

fn arg<T: std::str::FromStr>(name: &str, default: T) -> T {
    let args: Vec<String> = std::env::args().collect();
    args.iter().position(|a| a == name).and_then(|i| args.get(i + 1)?.parse().ok()).unwrap_or(default)
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if let Some(i) = args.iter().position(|a| a == "--compare") {
        compare(&args[i + 1], &args[i + 2]);
        return;
    }
    let runs: usize = arg("--runs", 3);
    let frames: i64 = arg("--frames", 16);
    let dump: Option<String> = arg("--dump", String::new()).into();
    let settings = Settings { basis_order: 2, ..Settings::default() };
    let scene = scenes::cornell_box_moving_light(14, 48, settings);
    println!("{} threads", rayon::current_num_threads());

    // Static solve, library vs reference, alternated.
    let mut sys = System::build(&scene, 1.0, &no_progress).unwrap();
    let store = reference::Store::new(&sys);
    let (mut lib, mut refr) = (Vec::new(), Vec::new());
    for _ in 0..runs {
        let t = Instant::now();
        let st = sys.solve(scene.settings.tolerance, &|| false).unwrap();
        lib.push(t.elapsed().as_secs_f64());
        let t = Instant::now();
        let (shots, floats, b) = store.solve(&sys, scene.settings.tolerance);
        refr.push(t.elapsed().as_secs_f64());
        let peak = sys.solution.b.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
        let worst = b.iter().zip(&sys.solution.b).flat_map(|(x, y)| (0..3).map(move |c| (x[c] - y[c]).abs()));
        println!(
            "static: library {:.3} s ({} shots, {:.2e} floats read), reference {:.3} s ({shots} shots, {:.2e} floats read), worst coefficient difference {:.1e} of peak",
            lib.last().unwrap(),
            st.shots,
            st.floats_read as f64,
            refr.last().unwrap(),
            floats as f64,
            worst.fold(0.0, f64::max) / peak,
        );
    }
    let med = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let (l, r) = (med(&mut lib), med(&mut refr));
    println!("static median: library {l:.3} s, reference {r:.3} s, library / reference {:.2}", l / r);
    drop(store);
    drop(sys);

    // Animation: Delta solves of frames 2..=F.
    let mut solve = Vec::new();
    for run in 0..runs {
        let mut session = Session::new(scene.clone(), Method::Incremental).unwrap();
        let (mut first, mut seconds, mut shots, mut first_shots) = (0.0, 0.0, 0, 0);
        let mut values: Vec<f32> = Vec::new();
        for f in 1..=frames {
            let st = session.solve_frame(f as f64, &no_progress).unwrap();
            if f == 1 {
                (first, first_shots) = (st.solve_seconds, st.shots);
            } else {
                seconds += st.solve_seconds;
                shots += st.shots;
            }
            if run == 0 && dump.as_deref().is_some_and(|d| !d.is_empty()) {
                // The face polynomials at a few points (not the corners, which a corner gather
                // may replace).
                for (o, obj) in scene.objects.iter().enumerate() {
                    for f in 0..obj.faces.len() {
                        for (s, t) in [(0.5, 0.5), (0.1, 0.2), (0.9, 0.7)] {
                            let v = session.eval(o, f, s, t).unwrap();
                            values.extend(v.map(|x| x as f32));
                        }
                    }
                }
            }
        }
        if let Some(d) = dump.as_deref().filter(|d| !d.is_empty() && run == 0) {
            let bytes: Vec<u8> = values.iter().flat_map(|x| x.to_le_bytes()).collect();
            std::fs::write(d, bytes).unwrap();
        }
        let n = (frames - 1).max(1) as f64;
        println!(
            "animation: frame 1 solve {first:.3} s ({first_shots} shots); frames 2..={frames}: {:.4} s/frame solve, {:.0} shots/frame",
            seconds / n,
            shots as f64 / n
        );
        solve.push(seconds / n);
    }
    println!("animation median: {:.4} s/frame solve", med(&mut solve));
}

/// Worst difference per frame of two `--dump` files, relative to the frame's peak.
fn compare(a: &str, b: &str) {
    let read = |p: &str| -> Vec<f32> {
        std::fs::read(p).unwrap().chunks(4).map(|c| f32::from_le_bytes(c.try_into().unwrap())).collect()
    };
    let (a, b) = (read(a), read(b));
    assert_eq!(a.len(), b.len());
    let frames: usize = arg("--frames", 16);
    let per = a.len() / frames;
    for f in 0..frames {
        let (x, y) = (&a[f * per..(f + 1) * per], &b[f * per..(f + 1) * per]);
        let peak = y.iter().fold(0.0f32, |m, v| m.max(*v));
        let worst = x.iter().zip(y).map(|(p, q)| (p - q).abs()).fold(0.0f32, f32::max);
        println!("frame {}: worst {:.2e} of peak", f + 1, worst / peak);
    }
}

/// The solver as it was before per-coefficient shooting: whole unshot vectors, one `nb x nb`
/// row-major f32 block per receiver, read in full by every shot.
mod reference {
    use galerkin_radiosity::solver::power;
    use galerkin_radiosity::system::System;
    use rayon::prelude::*;

    pub struct Store {
        nb: usize,
        blocks: Vec<f32>,
        /// Per shooter: (receiver, block).
        receivers: Vec<Vec<(u32, u32)>>,
    }

    impl Store {
        pub fn new(sys: &System) -> Self {
            let links = &sys.links;
            let nb = links.nb();
            let mut blocks = Vec::with_capacity(2 * links.len() * nb * nb);
            let mut receivers = vec![Vec::new(); sys.elements.len()];
            for p in 0..links.len() as u32 {
                let pair = links.pair(p);
                for (recv, src) in [(pair.a, pair.b), (pair.b, pair.a)] {
                    receivers[src as usize].push((recv, (blocks.len() / (nb * nb)) as u32));
                    blocks.extend(links.block(p, recv).iter().copied());
                }
            }
            Self { nb, blocks, receivers }
        }

        /// Solves from emission; returns shots, floats read and `b`.
        pub fn solve(&self, sys: &System, tolerance: f64) -> (usize, u64, Vec<[f64; 3]>) {
            let nb = self.nb;
            let area = sys.areas();
            let n = area.len();
            let stop = tolerance * sys.emitted_power();
            let mut b = sys.emission.clone();
            let mut unshot = sys.emission.clone();
            let mut priority: Vec<f64> =
                (0..n).map(|e| power(&unshot[e * nb..(e + 1) * nb], area[e])).collect();
            let (mut shots, mut floats) = (0, 0u64);
            let threads = rayon::current_num_threads().max(1);
            loop {
                let total: f64 = priority.iter().sum();
                let best = priority.iter().copied().fold(0.0, f64::max);
                if total <= stop || best <= 0.0 {
                    return (shots, floats, b);
                }
                let mut shooters: Vec<(usize, Vec<[f64; 3]>)> = Vec::new();
                for e in 0..n {
                    if priority[e] >= 0.25 * best && priority[e] > 0.0 {
                        shooters.push((e, unshot[e * nb..(e + 1) * nb].to_vec()));
                        unshot[e * nb..(e + 1) * nb].fill([0.0; 3]);
                        priority[e] = 0.0;
                        floats += (self.receivers[e].len() * nb * nb) as u64;
                    }
                }
                shots += shooters.len();
                let chunk = shooters.len().div_ceil(2 * threads).max(1);
                let delta = shooters
                    .par_chunks(chunk)
                    .map(|batch| {
                        let mut buf = vec![[0.0f64; 3]; n * nb];
                        for (j, u) in batch {
                            self.shoot_one(&sys.reflectance, *j, u, &mut buf);
                        }
                        buf
                    })
                    .reduce_with(|mut a, b| {
                        for (x, y) in a.iter_mut().zip(&b) {
                            for c in 0..3 {
                                x[c] += y[c];
                            }
                        }
                        a
                    })
                    .unwrap_or_default();
                for e in 0..n {
                    let d = &delta[e * nb..(e + 1) * nb];
                    if d.iter().all(|v| *v == [0.0; 3]) {
                        continue;
                    }
                    for k in 0..nb {
                        for c in 0..3 {
                            b[e * nb + k][c] += d[k][c];
                            unshot[e * nb + k][c] += d[k][c];
                        }
                    }
                    priority[e] = power(&unshot[e * nb..(e + 1) * nb], area[e]);
                }
            }
        }

        fn shoot_one(&self, rho: &[[f64; 3]], j: usize, u: &[[f64; 3]], out: &mut [[f64; 3]]) {
            assert_eq!(self.nb, 9, "the reference is compiled for 9 basis functions");
            #[cfg(target_arch = "x86_64")]
            {
                if std::arch::is_x86_feature_detected!("avx512f") {
                    // SAFETY: the CPU has AVX-512F (checked above).
                    unsafe { self.shoot_avx512(rho, j, u, out) };
                    return;
                }
            }
            self.shoot_body::<9>(rho, j, u, out);
        }

        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx2,avx512f")]
        fn shoot_avx512(&self, rho: &[[f64; 3]], j: usize, u: &[[f64; 3]], out: &mut [[f64; 3]]) {
            self.shoot_body::<9>(rho, j, u, out);
        }

        #[inline(always)]
        fn shoot_body<const NB: usize>(
            &self,
            rho: &[[f64; 3]],
            j: usize,
            u: &[[f64; 3]],
            out: &mut [[f64; 3]],
        ) {
            let u: &[[f64; 3]; NB] = u.try_into().unwrap();
            let (out, _) = out.as_chunks_mut::<NB>();
            let recv = &self.receivers[j];
            let block = |b: u32| &self.blocks[b as usize * NB * NB..(b as usize + 1) * NB * NB];
            for (r, &(i, blk)) in recv.iter().enumerate() {
                if let Some(&(_, ahead)) = recv.get(r + 4) {
                    #[cfg(target_arch = "x86_64")]
                    for line in block(ahead).chunks(16) {
                        // SAFETY: prefetching is a hint on a live slice element.
                        unsafe {
                            std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(
                                line.as_ptr().cast(),
                            )
                        };
                    }
                }
                let (g, _) = block(blk).as_chunks::<NB>();
                let i = i as usize;
                let o = &mut out[i];
                let mut acc = [[0.0f64; NB]; 3];
                for l in 0..NB {
                    let col: [f64; NB] = std::array::from_fn(|k| g[k][l] as f64);
                    for c in 0..3 {
                        let ul = u[l][c];
                        for k in 0..NB {
                            acc[c][k] += col[k] * ul;
                        }
                    }
                }
                for k in 0..NB {
                    for c in 0..3 {
                        o[k][c] += rho[i][c] * acc[c][k];
                    }
                }
            }
        }
    }
}
