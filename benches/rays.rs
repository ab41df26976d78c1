//! Shadow-ray throughput of our BVH (issue 2, item 4: choose the BVH by measurement):
//! `cargo bench --bench rays`. Same set-up as the measurements in
//! ../shared/notes/rust-dependencies.md (Cornell box of ~99k triangles, 1M segments between random
//! points of random facing patches, rayon on 2 threads, any-hit), so the Mrays/s compare with the
//! table there (parry3d 0.31 PLOC: 5.2; Embree 3: 14.6-18.5; bvh 0.13: 2.7-2.9).

use std::time::Instant;

use galerkin_radiosity::geometry::Patch;
use galerkin_radiosity::scene::Settings;
use galerkin_radiosity::scenes;
use galerkin_radiosity::system::build_elements;
use galerkin_radiosity::visibility::bvh::{Bvh, Triangle};
use glam::DVec3;
use rayon::prelude::*;

fn lcg(seed: &mut u64) -> f64 {
    *seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
    ((*seed >> 11) as f64) / ((1u64 << 53) as f64)
}

fn main() {
    // Walls 94 x 94 and blocks 23 x 23 per face: about 99k triangles.
    let scene = scenes::cornell_box(94, Settings { basis_order: 0, ..Settings::default() });
    let elements = build_elements(&scene, 1.0, galerkin_radiosity::basis::Basis::new(0));
    let patches: Vec<Patch> = elements.iter().map(|e| e.patch).collect();
    let mut tris = Vec::new();
    for (e, p) in patches.iter().enumerate() {
        for v in p.triangles() {
            tris.push(Triangle { v, element: e as u32 });
        }
    }
    let n_tris = tris.len();
    let start = Instant::now();
    let bvh = Bvh::build(tris);
    let build = start.elapsed().as_secs_f64();
    // Segments between random points of random pairs of patches that face each other.
    let mut seed = 1u64;
    let mut rays = Vec::with_capacity(1_000_000);
    while rays.len() < 1_000_000 {
        let i = (lcg(&mut seed) * patches.len() as f64) as usize;
        let j = (lcg(&mut seed) * patches.len() as f64) as usize;
        let (a, b) = (&patches[i], &patches[j]);
        let x = a.point(lcg(&mut seed), lcg(&mut seed));
        let y = b.point(lcg(&mut seed), lcg(&mut seed));
        let d: DVec3 = y - x;
        if a.centre_normal().dot(d) > 0.0 && b.centre_normal().dot(-d) > 0.0 {
            rays.push((x, d, i as u32, j as u32));
        }
    }
    for _ in 0..2 {
        let start = Instant::now();
        let blocked =
            rays.par_iter().filter(|(o, d, i, j)| bvh.occluded(*o, *d, 1e-9, 1.0 - 1e-9, *i, *j)).count();
        let secs = start.elapsed().as_secs_f64();
        println!(
            "{n_tris} triangles, BVH build {:.0} ms; {} rays ({:.1}% blocked) in {:.3} s: {:.2} Mrays/s on {} threads",
            build * 1e3,
            rays.len(),
            100.0 * blocked as f64 / rays.len() as f64,
            secs,
            rays.len() as f64 / secs / 1e6,
            rayon::current_num_threads()
        );
    }
}
