//! Brute-force irradiance at every face corner of a scene file, beside the corner gather's, to
//! find where the gather (or the solution it reads) goes wrong on real meshes (issue 19).
//!
//!     cargo run --release --example corner_truth -- SCENE.json OUT.csv [--rays N] [--stride K]
//!         [--near D --second N2] [--light-cells M] [--object NAME] [--inset I]
//!
//! Per corner (every `K`-th face corner; the point and normal the gather uses), in grey (the
//! mean of the three channels):
//! - `h_ours`: the gather's irradiance `H` (`B = E + rho H`); `h_ours_dir`: the same gather of a
//!   solution holding only the emitters' `B` (its direct light);
//! - `h_dir`: the emitters' light by brute force: each emitter cut into `M x M` rectangles, each
//!   rectangle's exact point-to-polygon form factor times one shadow ray to its centre, against
//!   every element's triangles (the hull's too);
//! - `h_ind`: the rest by `N` stratified cosine-weighted rays, each taking the solved polynomial
//!   of the nearest element it hits (front side; 0 from behind), emitters left to `h_dir`;
//! - `h_ind2`: as `h_ind`, but a hit nearer than `D` takes `B` gathered at the hit point by the
//!   same brute force (`N2` rays, the polynomials one bounce further): the answer the solution's
//!   polynomials would give if they followed the contact shadows next to the corner;
//! - `back`: the fraction of rays that hit a face from behind; `near`: the share of `h_ind` from
//!   hits nearer than `D`.
//!
//! So `h_ours - (h_dir + h_ind)` is the gather's own error against its solution, and
//! `(h_dir + h_ind2) - (h_dir + h_ind)` what the polynomials near the corner miss.

use std::io::Write;

use galerkin_radiosity::gather::{INSET, shading_point};
use galerkin_radiosity::geometry::{Aabb, Patch, Rect};
use galerkin_radiosity::kernel::point::point_to_polygon;
use galerkin_radiosity::scene::json::read_scene;
use galerkin_radiosity::system::{System, corner_params, no_progress};
use galerkin_radiosity::visibility::bvh::{Bvh, Triangle, Visitor};
use glam::DVec3;
use rayon::prelude::*;

struct Args {
    scene: String,
    out: String,
    rays: usize,
    stride: usize,
    near: f64,
    second: usize,
    light_cells: usize,
    /// Only this object's corners (all objects when empty).
    object: String,
    /// The brute force's points this far inside their face (in its parameter domain; the
    /// gather's `INSET` unless told): `h_ours` stays the gather's own.
    inset: f64,
}

fn args() -> Args {
    let mut a = std::env::args().skip(1);
    let scene = a.next().expect("SCENE.json");
    let out = a.next().expect("OUT.csv");
    let mut r = Args {
        scene,
        out,
        rays: 1024,
        stride: 1,
        near: 0.0,
        second: 64,
        light_cells: 32,
        object: String::new(),
        inset: INSET,
    };
    while let Some(k) = a.next() {
        let v = a.next().expect("a value");
        match k.as_str() {
            "--rays" => r.rays = v.parse().unwrap(),
            "--stride" => r.stride = v.parse().unwrap(),
            "--near" => r.near = v.parse().unwrap(),
            "--second" => r.second = v.parse().unwrap(),
            "--light-cells" => r.light_cells = v.parse().unwrap(),
            "--object" => r.object = v,
            "--inset" => r.inset = v.parse().unwrap(),
            _ => panic!("unknown option {k}"),
        }
    }
    r
}

/// The nearest triangle a ray meets (either side), as the BVH's visitor.
struct Nearest {
    o: DVec3,
    d: DVec3,
    inv: DVec3,
    t_min: f64,
    best: f64,
    hit: Option<usize>,
    skip: u32,
}

impl Visitor for Nearest {
    fn accept(&self, b: &Aabb, _: DVec3, _: DVec3) -> bool {
        let t0 = (b.min - self.o) * self.inv;
        let t1 = (b.max - self.o) * self.inv;
        let near = t0.min(t1).max_element().max(self.t_min);
        let far = t0.max(t1).min_element().min(self.best);
        near <= far
    }
    fn visit(&mut self, index: usize, t: &Triangle) {
        if t.element == self.skip {
            return;
        }
        if let Some(h) = ray_triangle(t, self.o, self.d)
            && h > self.t_min
            && h < self.best
        {
            self.best = h;
            self.hit = Some(index);
        }
    }
}

/// Moeller-Trumbore: the ray parameter of the hit, either side.
fn ray_triangle(t: &Triangle, o: DVec3, d: DVec3) -> Option<f64> {
    let (e1, e2) = (t.v[1] - t.v[0], t.v[2] - t.v[0]);
    let p = d.cross(e2);
    let det = e1.dot(p);
    if det.abs() < 1e-300 {
        return None;
    }
    let s = o - t.v[0];
    let u = s.dot(p) / det;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = s.cross(e1);
    let v = d.dot(q) / det;
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    Some(e2.dot(q) / det)
}

struct World<'a> {
    sys: &'a System,
    bvh: Bvh,
    emitters: Vec<usize>,
    eps: f64,
    grey: Vec<f64>,
    light_cells: usize,
}

fn grey(v: [f64; 3]) -> f64 {
    (v[0] + v[1] + v[2]) / 3.0
}

/// A small deterministic generator (splitmix64).
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// An orthonormal frame around `n`.
fn frame(n: DVec3) -> (DVec3, DVec3) {
    let a = if n.x.abs() < 0.9 { DVec3::X } else { DVec3::Y };
    let u = n.cross(a).normalize();
    (u, n.cross(u))
}

impl World<'_> {
    fn visible(&self, x: DVec3, y: DVec3, i: u32, j: u32) -> bool {
        !self.bvh.occluded(x, y - x, 1e-9, 1.0 - 1e-9, i, j)
    }

    /// The emitters' irradiance at `x` (on element `i`): exact form factors of `M x M` pieces
    /// of each, one shadow ray each.
    fn direct(&self, x: DVec3, n: DVec3, i: usize) -> f64 {
        let m = self.light_cells;
        let mut h = 0.0;
        for &j in &self.emitters {
            if j == i {
                continue;
            }
            let patch = &self.sys.elements[j].patch;
            for a in 0..m {
                for b in 0..m {
                    let r = Rect {
                        s0: a as f64 / m as f64,
                        s1: (a + 1) as f64 / m as f64,
                        t0: b as f64 / m as f64,
                        t1: (b + 1) as f64 / m as f64,
                    };
                    let sub = patch.sub_patch(&r);
                    let f = point_to_polygon(x, n, &sub.corners, sub.centre_normal());
                    if f <= 0.0 {
                        continue;
                    }
                    let (s, t) = r.map(0.5, 0.5);
                    if self.visible(x, patch.point(s, t), i as u32, j as u32) {
                        h += f * grey(self.sys.eval(j, s, t));
                    }
                }
            }
        }
        h
    }

    /// The nearest hit of the ray from `x` (on `i`) along `d` on a front, or on a back where the
    /// face has one (`galerkin_radiosity::backs`): (element, s, t, distance), or `Err(true)`
    /// for a face without a back met from behind, `Err(false)` for a miss.
    fn trace(&self, x: DVec3, d: DVec3, i: usize) -> Result<(usize, f64, f64, f64), bool> {
        let mut v = Nearest {
            o: x,
            d,
            inv: d.recip(),
            t_min: self.eps,
            best: f64::INFINITY,
            hit: None,
            skip: i as u32,
        };
        self.bvh.visit(&mut v);
        let k = v.hit.ok_or(false)?;
        let e = self.bvh.triangles()[k].element as usize;
        let patch: &Patch = &self.sys.elements[e].patch;
        let y = x + v.best * d;
        let (s, t) = patch.locate(y);
        let (s, t) = (s.clamp(0.0, 1.0), t.clamp(0.0, 1.0));
        if patch.area_vector(s, t).dot(d) >= 0.0 {
            // The back part holding the hit point, if the face has a back.
            let el = &self.sys.elements[e];
            let start = self
                .sys
                .elements
                .partition_point(|b| (b.object, b.face, b.back) < (el.object, el.face, true));
            return self.sys.elements[start..]
                .iter()
                .take_while(|b| (b.object, b.face, b.back) == (el.object, el.face, true))
                .enumerate()
                .find_map(|(k, b)| {
                    let (s, t) = b.patch.locate(y);
                    let inside = (-1e-9..=1.0 + 1e-9).contains(&s) && (-1e-9..=1.0 + 1e-9).contains(&t);
                    inside.then_some((start + k, s.clamp(0.0, 1.0), t.clamp(0.0, 1.0), v.best))
                })
                .ok_or(true);
        }
        Ok((e, s, t, v.best))
    }

    /// `(h_ind, back fraction, near share, h_ind2)` at `x` (on `i`), and `h_ind2` for each of
    /// `NEAR_SCALES` times `near` (the last split by whether the hit is on the corner's object).
    #[allow(clippy::too_many_arguments)]
    fn indirect(
        &self,
        x: DVec3,
        n: DVec3,
        i: usize,
        rays: usize,
        near: f64,
        second: usize,
        seed: u64,
    ) -> ([f64; 4], [f64; NEAR_SCALES.len() + 2]) {
        let (u, w) = frame(n);
        let side = (rays as f64).sqrt().ceil() as usize;
        let mut rng = Rng(seed);
        let (mut sum, mut near_sum, mut back, mut count) = (0.0, 0.0, 0, 0);
        let mut sums2 = [0.0; NEAR_SCALES.len() + 2];
        let object = self.sys.elements[i].object;
        let far = near * NEAR_SCALES[NEAR_SCALES.len() - 1];
        for a in 0..side {
            for b in 0..side {
                let (r1, r2) = ((a as f64 + rng.next()) / side as f64, (b as f64 + rng.next()) / side as f64);
                // Cosine-weighted: pdf cos / pi, so each ray's B averages to the irradiance.
                let (r, phi) = (r1.sqrt(), 2.0 * std::f64::consts::PI * r2);
                let d = u * (r * phi.cos()) + w * (r * phi.sin()) + n * (1.0 - r1).max(0.0).sqrt();
                count += 1;
                match self.trace(x, d, i) {
                    Ok((e, s, t, dist)) => {
                        if self.emitters.contains(&e) {
                            continue;
                        }
                        let b = grey(self.sys.eval(e, s, t));
                        sum += b;
                        if dist < near {
                            near_sum += b;
                        }
                        let again = if second > 0 && dist < far {
                            let patch = &self.sys.elements[e].patch;
                            let (y, ny) = (patch.point(s, t), patch.area_vector(s, t).normalize());
                            let h = self.direct(y, ny, e)
                                + self.indirect(y, ny, e, second, 0.0, 0, rng.0 ^ 0x5bd1).0[0];
                            grey(self.sys.emission[e * self.sys.basis.len()]) + self.grey[e] * h
                        } else {
                            b
                        };
                        for (k, scale) in NEAR_SCALES.iter().enumerate() {
                            sums2[k] += if dist < near * scale { again } else { b };
                        }
                        let same = self.sys.elements[e].object == object;
                        sums2[NEAR_SCALES.len()] += if dist < far && same { again } else { b };
                        sums2[NEAR_SCALES.len() + 1] += if dist < far && !same { again } else { b };
                    }
                    Err(true) => back += 1,
                    Err(false) => {}
                }
            }
        }
        let c = count as f64;
        let at_near = sums2[NEAR_SCALES.iter().position(|&s| s == 1.0).unwrap()];
        (
            [sum / c, back as f64 / c, if sum > 0.0 { near_sum / sum } else { 0.0 }, at_near / c],
            sums2.map(|x| x / c),
        )
    }
}

/// `h_ind2` is also written with the near distance scaled by each of these (the last two
/// columns: the largest, re-gathering only hits on the corner's own object, then on others).
const NEAR_SCALES: [f64; 5] = [0.25, 0.5, 1.0, 2.0, 4.0];

fn main() {
    let args = args();
    let scene = read_scene(std::path::Path::new(&args.scene)).expect("scene");
    let frame = scene.frames.0 as f64;
    let mut sys = System::build(&scene, frame, &no_progress).expect("build");
    sys.solve(scene.settings.tolerance, &|| false).expect("solve");
    sys.gather_corners(&scene, frame, &no_progress).expect("gather");
    let h_ours = sys.corner_irradiance.clone().expect("gathered");
    let nb = sys.basis.len();
    let emitters: Vec<usize> =
        (0..sys.elements.len()).filter(|&e| sys.emission[e * nb].iter().any(|&x| x > 0.0)).collect();
    // The same gather of a solution holding only the emitters' B: its direct light.
    let full = sys.solution.b.clone();
    for (k, b) in sys.solution.b.iter_mut().enumerate() {
        if !emitters.contains(&(k / nb)) {
            *b = [0.0; 3];
        }
    }
    sys.gather_corners(&scene, frame, &no_progress).expect("gather");
    let h_ours_dir = sys.corner_irradiance.clone().expect("gathered");
    sys.solution.b = full;

    let mut tris = Vec::new();
    // The fronts' triangles: a back is its face met from behind (`World::trace`).
    for (e, el) in sys.elements.iter().enumerate().filter(|(_, el)| !el.back) {
        for v in el.patch.triangles() {
            tris.push(Triangle { v, element: e as u32 });
        }
    }
    let bounds = sys.elements.iter().fold(Aabb::EMPTY, |b, e| b.union(e.patch.bounds()));
    let world = World {
        sys: &sys,
        bvh: Bvh::build(tris),
        emitters,
        eps: 1e-9 * bounds.diagonal().length(),
        grey: sys.elements.iter().map(|e| grey(e.reflectance(&scene))).collect(),
        light_cells: args.light_cells,
    };
    // Every face corner: (object, face, k, element, s, t).
    let mut corners = Vec::new();
    let mut index = 0usize;
    for (o, obj) in scene.objects.iter().enumerate() {
        let mut within = 0usize;
        for (f, face) in obj.faces.iter().enumerate() {
            for (k, (s, t)) in corner_params(face.len()).into_iter().enumerate() {
                let s = if face.len() == 3 && t == 1.0 { 0.5 } else { s };
                let (si, ti) = (s.clamp(args.inset, 1.0 - args.inset), t.clamp(args.inset, 1.0 - args.inset));
                if index.is_multiple_of(args.stride)
                    && (args.object.is_empty() || args.object == obj.name)
                    && let Some(at) = sys.element_of_face(o, f, si, ti)
                {
                    corners.push((o, f, k, within, at));
                }
                index += 1;
                within += 1;
            }
        }
    }
    let done = std::sync::atomic::AtomicUsize::new(0);
    let rows: Vec<String> = corners
        .par_iter()
        .map(|&(o, f, k, c, (e, s, t))| {
            let patch = &sys.elements[e].patch;
            let (x, n) = shading_point(patch, s, t, None);
            let dir = world.direct(x, n, e);
            let seed = (o as u64) << 40 ^ (c as u64) << 8 ^ 0x1234;
            let ([ind, back, near, ind2], scales) =
                world.indirect(x, n, e, args.rays, args.near, args.second, seed);
            let scales: Vec<String> = scales.iter().map(|v| format!("{v:.7}")).collect();
            let finished = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
            if finished.is_multiple_of(500) {
                eprintln!("{finished} / {}", corners.len());
            }
            format!(
                "{o},{f},{k},{c},{e},{:.9},{:.9},{:.9},{:.7},{:.7},{:.7},{:.7},{:.7},{:.7},{:.7},{:.7},{:.7},{:.5},{:.5},{:.4},{}",
                x.x,
                x.y,
                x.z,
                n.x,
                n.y,
                n.z,
                grey(h_ours[o][c]),
                grey(h_ours_dir[o][c]),
                dir,
                ind,
                ind2,
                world.grey[e],
                back,
                near,
                patch.area(),
                scales.join(","),
            )
        })
        .collect();
    let mut out = std::fs::File::create(&args.out).expect("OUT.csv");
    writeln!(out, "object,face,k,corner,element,x,y,z,nx,ny,nz,h_ours,h_ours_dir,h_dir,h_ind,h_ind2,rho,back,near,area,n025,n05,n1,n2,n4,n4self,n4other")
        .unwrap();
    for r in rows {
        writeln!(out, "{r}").unwrap();
    }
    let names: Vec<&str> = scene.objects.iter().map(|o| o.name.as_str()).collect();
    eprintln!("objects: {names:?}");
}
