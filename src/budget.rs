//! The memory a bake will need, estimated before anything is allocated, and the budget it is
//! checked against (issue 23, item 1): a scene too large for the machine is refused at once with
//! one line, instead of aborting in the allocator minutes later (which, through the C ABI, takes
//! the host application and its unsaved work with it).
//!
//! The estimate is an upper bound of the big arrays, from counts known before the build:
//! - links: every pair of elements that may face each other ([`facing_pairs`]: counted, or
//!   bounded from a sample in large scenes; the store holds only those that are also unblocked),
//!   each `2 nb^2` f32 coefficients with the store's
//!   growth room, its pair record, adjacency and a visibility mask, twice over: the assembled rows
//!   are all held before they are stored, and a frame rebuilt from scratch is built beside the
//!   last frame's store;
//! - the corner gather: every corner point with a moment of `nb` f32 for every element;
//! - elements and the solver's coefficients (small next to the links);
//! - per-frame results kept until they are written (the CLI): every face mean, corner radiosity
//!   and corner irradiance as f32 and as JSON text.
//!
//! Series terms of the incremental update (a few KB per expanded pair, only where they pay) are
//! not counted.
//!
//! What still fails past the estimate (the machine had less than it said, or the series) fails
//! in the big allocations (the link rows and the link store) through [`try_vec`] and
//! [`try_reserve`]: an [`Error::OutOfMemory`], never an abort. Small allocations elsewhere still
//! abort when the system has nothing left at all.

use crate::error::{Error, Result};
use crate::geometry::Patch;
use crate::scene::Scene;

/// Bytes per MiB, the unit of the budget setting.
const MIB: u64 = 1 << 20;

/// The share of the machine's available memory a bake may plan to use by default.
pub const DEFAULT_SHARE: f64 = 0.8;

/// Bytes of JSON text per RGB value of the result file (three f32 in shortest form, commas,
/// brackets), a measured upper bound for radiosity values.
const JSON_BYTES_PER_VALUE: u64 = 48;

/// What a bake of a scene will need, by part, in bytes.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Estimate {
    pub links: u64,
    pub gather: u64,
    pub elements: u64,
    pub results: u64,
}

impl Estimate {
    pub fn total(&self) -> u64 {
        self.links.saturating_add(self.gather).saturating_add(self.elements).saturating_add(self.results)
    }
}

/// The estimate for `scene` baked over `frames` frames whose results are all kept (1 for a host
/// that reads each frame as it is solved).
pub fn estimate(scene: &Scene, frames: u64) -> Estimate {
    let elements = flat_elements(scene);
    estimate_for(scene, frames, elements.len() as u64, facing_pairs(&elements))
}

/// Pairs of `patches` that may face each other (each in front of the other's plane, as the
/// kernel's assembly culls them): counted when there are up to [`COUNTED_PAIRS`] pairs, else an
/// upper bound from a sample of [`SAMPLED_PAIRS`] pairs (the sampled share plus four standard
/// errors and 0.1%). Every pair was counted before, far above what a real mesh links: the
/// decimated monastery with its open surfaces' backs (6,053 elements) was refused at 28 GB and
/// used 2 GB.
pub fn facing_pairs(patches: &[Patch]) -> u64 {
    use rayon::prelude::*;
    let n = patches.len() as u64;
    if n.saturating_mul(n.saturating_sub(1)) / 2 > COUNTED_PAIRS {
        return sampled_facing_pairs(patches, SAMPLED_PAIRS);
    }
    let planes: Vec<_> = patches.par_iter().map(Patch::front_plane).collect();
    let faces = facing(patches, &planes);
    (0..patches.len())
        .into_par_iter()
        .map(|i| (i + 1..patches.len()).filter(|&j| faces(i, j)).count() as u64)
        .sum()
}

/// Whether elements `i` and `j` of `patches` (their planes `planes`) may face each other.
fn facing<'a>(
    patches: &'a [Patch],
    planes: &'a [Option<crate::geometry::FrontPlane>],
) -> impl Fn(usize, usize) -> bool + Sync + 'a {
    move |i, j| {
        planes[i].is_none_or(|p| p.any_in_front(&patches[j]))
            && planes[j].is_none_or(|p| p.any_in_front(&patches[i]))
    }
}

/// [`facing_pairs`]' bound from `samples` pairs drawn at random (a fixed sequence).
fn sampled_facing_pairs(patches: &[Patch], samples: u64) -> u64 {
    let n = patches.len() as u64;
    let all = n.saturating_mul(n.saturating_sub(1)) / 2;
    if n < 2 {
        return 0;
    }
    let planes: Vec<_> = patches.iter().map(Patch::front_plane).collect();
    let faces = facing(patches, &planes);
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    let mut next = || {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((state >> 33) % n) as usize
    };
    let (mut hits, mut drawn) = (0u64, 0u64);
    while drawn < samples {
        let (i, j) = (next(), next());
        if i != j {
            hits += faces(i, j) as u64;
            drawn += 1;
        }
    }
    let share = hits as f64 / samples as f64;
    let bound = share + 4.0 * (share * (1.0 - share) / samples as f64).sqrt() + 1e-3;
    (bound.min(1.0) * all as f64).ceil() as u64
}

/// [`facing_pairs`] counts every pair up to this many (about 0.1 s on two cores).
const COUNTED_PAIRS: u64 = 40_000_000;
/// ... and samples this many beyond.
const SAMPLED_PAIRS: u64 = 1 << 20;

/// The elements the flat path will solve: a face each, and with visibility on the parts of
/// the faces split where another object comes close or at a crease
/// ([`crate::contact_split::plan_with_creases`], at the first frame; up to twice the faces),
/// and the backs of open surfaces' faces ([`crate::backs`]).
fn flat_elements(scene: &Scene) -> Vec<Patch> {
    let (frame, basis) = (scene.frames.0 as f64, crate::basis::Basis::new(0));
    let faces = crate::system::build_elements(scene, frame, basis);
    let faces = crate::backs::with_backs(scene, frame, faces, basis, &[]);
    if !scene.settings.visibility || faces.is_empty() {
        return faces.iter().map(|e| e.patch).collect();
    }
    let parts = crate::contact_split::plan_with_creases(scene, &faces);
    faces.iter().zip(&parts).flat_map(|(f, parts)| parts.iter().map(|r| f.patch.sub_patch(r))).collect()
}

/// [`estimate`] with `n` elements of which `pairs` pairs may be linked.
fn estimate_for(scene: &Scene, frames: u64, n: u64, pairs: u64) -> Estimate {
    let s = &scene.settings;
    let nb = ((s.basis_order + 1) * (s.basis_order + 1)) as u64;
    // Coefficients with 1/16 growth room, the pair record (two ids and a visibility), its id in
    // both adjacency lists and the column's receiver list, and a partial mask (4 u64 boxed).
    let coefficients = 2 * nb * nb * 4 * 17 / 16;
    let per_pair = coefficients + 24 + 2 * 8 + 8 + 48;
    let links = pairs.saturating_mul(per_pair).saturating_mul(2);
    let corners: u64 = scene.objects.iter().flat_map(|o| &o.faces).map(|f| f.len() as u64).sum();
    let gather = if s.corner_gather {
        // Per (corner, source): the source id, its mode and nb f32 moments.
        corners.saturating_mul(n).saturating_mul(4 + 4 + 4 * nb)
    } else {
        0
    };
    // Elements (patch, moments, geometry samples), and the solution, unshot and emission
    // coefficients (three copies of RGB f64 per coefficient, and the saved copies of an update);
    // the lights' shadow rays kept for the next frame, per element and per corner point.
    let rays = kept_ray_bytes(scene);
    let elements = n
        .saturating_mul(1024 + nb * 8 * 4 + 6 * nb * 3 * 8 + rays)
        .saturating_add(corners.saturating_mul(rays / 8));
    let values = (scene.face_count() as u64).saturating_add(corners.saturating_mul(2));
    let results = frames.saturating_mul(values).saturating_mul(12 + JSON_BYTES_PER_VALUE);
    Estimate { links, gather, elements, results }
}

/// Bytes the lights' shadow rays kept between frames take per element or leaf
/// ([`crate::lights::kept`]): at each of its 36 projection points a section of 4 bytes per source
/// and a bit per ray, about 250 rays under a World at Medium (the 851-face room's 8.9k a face;
/// as the square of the quality's visibility samples), 16 per soft light; a gathered point, with
/// twice the World's strata per axis, about an eighth of this.
fn kept_ray_bytes(scene: &Scene) -> u64 {
    let world = u64::from(scene.world.is_some());
    let lights = scene.lights.len() as u64;
    if world + lights == 0 {
        return 0;
    }
    let v = scene.settings.visibility_samples.max(1) as u64;
    36 * (4 * (world + lights) + (250 * v * v / 4 * world + 16 * v * v / 4 * lights) / 8) + 64
}

/// The budget in bytes: `memory_budget_mb` when set (non-zero), else [`DEFAULT_SHARE`] of the
/// memory the system reports available (`MemAvailable` in `/proc/meminfo`); `None` when neither
/// is known (no check).
pub fn budget_bytes(memory_budget_mb: u64) -> Option<u64> {
    if memory_budget_mb > 0 {
        return Some(memory_budget_mb.saturating_mul(MIB));
    }
    available_bytes().map(|a| (a as f64 * DEFAULT_SHARE) as u64)
}

/// `MemAvailable` of `/proc/meminfo`, in bytes (Linux; `None` elsewhere).
fn available_bytes() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib.saturating_mul(1024))
}

/// Refuses `scene` baked over `frames` kept frames when its estimate exceeds the budget, with
/// one line giving both and what to change.
pub fn check(scene: &Scene, frames: u64) -> Result<()> {
    let Some(budget) = budget_bytes(scene.settings.memory_budget_mb) else { return Ok(()) };
    let e = estimate(scene, frames);
    if e.total() <= budget {
        return Ok(());
    }
    let mb = |b: u64| b.div_ceil(MIB);
    let source = if scene.settings.memory_budget_mb > 0 {
        "settings.memory_budget_mb".to_owned()
    } else {
        format!("{:.0}% of the memory available", DEFAULT_SHARE * 100.0)
    };
    Err(Error::OverBudget(format!(
        "this bake needs up to {} MB (links {} MB, corner gather {} MB, elements {} MB, results {} MB) \
         but the budget is {} MB ({source}); use fewer faces or a lower settings.basis_order, \
         turn corner_gather off, bake fewer frames at once, or raise memory_budget_mb",
        mb(e.total()),
        mb(e.links),
        mb(e.gather),
        mb(e.elements),
        mb(e.results),
        mb(budget),
    )))
}

/// Links per face a hierarchical bake plans for at accuracy 1e-3 ([`hierarchical_estimate`]):
/// measured 122 on the full monastery (15.2M links, 124,707 faces), 205 on the modelled Cornell
/// box (3,279 links, 16 faces), 58 on the decimated monastery at order 1 (docs/benchmarks.md,
/// "Hierarchy").
const HIERARCHY_LINKS_PER_FACE: f64 = 160.0;

/// How the links grow as the accuracy tightens: the Cornell box's 514, 3,279 and 18,912 links at
/// 1e-2, 1e-3 and 1e-4 are about a power of 0.76 of 1 / accuracy.
const HIERARCHY_LINK_GROWTH: f64 = 0.76;

/// Blocked and idle pairs the hierarchy keeps per link (for the gather and for updates): 6.3 on
/// the full monastery (43.7M and 51.0M for 15.2M links).
const HIERARCHY_KEPT_PAIRS_PER_LINK: u64 = 7;

/// Links with all their coefficients at accuracy 1e-3, whatever the scene's size: every other
/// surface link is light (one `G^00` each way, `hierarchy::coupling::LIGHT_SHARE`), so a full
/// link carries a share of the bar and their number follows the accuracy, not the faces
/// (the Cornell box: about 3,000; the full monastery: 5,049 with blocks).
const HIERARCHY_FULL_LINKS: f64 = 20_000.0;

/// Bytes of the pair tree an animation keeps (`hierarchy::pair_tree`), per link: 15.6 MB for the
/// decimated monastery's 137k links (629k inner pairs for 910k links, blocked and idle pairs, in
/// a table of 17-byte slots at most 7/8 full).
const HIERARCHY_PAIR_TREE_PER_LINK: u64 = 130;

/// Bytes an animation's hierarchical corner gather keeps per face corner for the next frame
/// (`hierarchy::gather::KeptGather`), at most its cap: measured 4 KB on the 1,079-patch
/// moving-light box at order 2, 41 KB on the decimated monastery (its sources are many more).
const HIERARCHY_KEPT_GATHER_PER_CORNER: u64 = 48 << 10;

/// What a hierarchical bake ([`crate::session::Method::Hierarchical`]) will need. Its links grow
/// about linearly with the faces, not with their pairs, and how many there are is known only
/// once the oracle has decided them: the links are `faces x` [`HIERARCHY_LINKS_PER_FACE`] scaled
/// by `(1e-3 / accuracy)^`[`HIERARCHY_LINK_GROWTH`]. Each link has its record (twice: the
/// vector's growth room), its two entries of the solve's incoming lists, its packed constant
/// terms, and [`HIERARCHY_KEPT_PAIRS_PER_LINK`] blocked or idle pairs (twice); of them at most
/// [`HIERARCHY_FULL_LINKS`] (scaled alike) also hold two `nb x nb` f32 blocks, their allocation
/// and the solve's packed copy. Nodes are two per face (the face and its share of the clusters)
/// and one per full link (the quadrants split where the light asks for them: 2,785 leaves for
/// 3,279 links on the modelled Cornell box), each its record, moments, the solve's three
/// coefficient vectors and its mixer's columns. An animation (a scene of more than one frame)
/// also keeps the pair tree ([`HIERARCHY_PAIR_TREE_PER_LINK`]) and, with the corner gather, its
/// sources' values ([`HIERARCHY_KEPT_GATHER_PER_CORNER`], within their cap of an eighth of the
/// budget, twice: the last frame's and the next), and an update holds the last frame's nodes
/// and solution beside the new ones. Elements and results as [`estimate`]. Against the measured
/// peaks: the full monastery at order 1, 2.2 GB (4.3 GB estimated without the gather); a
/// 9,912-face crop of it, 104 MB (0.33 GB).
pub fn hierarchical_estimate(scene: &Scene, frames: u64) -> Estimate {
    let s = &scene.settings;
    let nb = ((s.basis_order + 1) * (s.basis_order + 1)) as u64;
    let faces = (scene.face_count() - scene.degenerate_faces.len()) as u64;
    // Elements and results as the flat path's without its contact split (the hierarchy splits
    // faces by its own rule, counted in its nodes).
    let flat = estimate_for(scene, frames, faces, 0);
    let growth = (1e-3 / s.accuracy.clamp(1e-12, 1.0)).powf(HIERARCHY_LINK_GROWTH);
    let link_count = faces.saturating_mul((HIERARCHY_LINKS_PER_FACE * growth).max(1.0) as u64);
    let full_count = link_count.min((HIERARCHY_FULL_LINKS * growth) as u64);
    let per_link = 2 * size_of::<crate::hierarchy::coupling::Link>() as u64
        + 2 * 8
        + 2 * 8
        + 2 * 8 * HIERARCHY_KEPT_PAIRS_PER_LINK;
    let per_full_link = 2 * nb * nb * 4 + 16 + 2 * nb * nb * 4;
    let animated = scene.is_animation();
    let pair_tree = if animated { HIERARCHY_PAIR_TREE_PER_LINK } else { 0 };
    let links = link_count
        .saturating_mul(per_link + pair_tree)
        .saturating_add(full_count.saturating_mul(per_full_link));
    let nodes = faces.saturating_mul(2).saturating_add(full_count);
    // The solve's Anderson mixer holds `2 depth + 4` copies of the leaves' coefficients
    // (`hierarchy::solve::sweep::Accelerated`); most nodes are leaves.
    let mixer = (2 * crate::hierarchy::solve::ANDERSON_DEPTH as u64 + 4) * nb * 3 * 8;
    let per_node =
        size_of::<crate::hierarchy::tree::Node>() as u64 + 16 + nb * 8 + 3 * nb * 3 * 8 + mixer + 64;
    let copies = if animated { 2 } else { 1 };
    // Each leaf's shadow rays toward the lights, the last frame's and the next's.
    let per_node = per_node + kept_ray_bytes(scene);
    let elements = flat.elements.saturating_add(nodes.saturating_mul(per_node).saturating_mul(copies));
    // The corner gather keeps nothing between points but its values, which the results count;
    // an animation's keeps its sources' values for the next frame, within their cap, and holds
    // the last frame's while it makes them.
    let gather = if animated && s.corner_gather {
        let corners: u64 = scene.objects.iter().flat_map(|o| &o.faces).map(|f| f.len() as u64).sum();
        let cap = crate::hierarchy::gather::KeptGather::cap(budget_bytes(s.memory_budget_mb)) as u64;
        2 * corners.saturating_mul(HIERARCHY_KEPT_GATHER_PER_CORNER).min(cap)
    } else {
        0
    };
    Estimate { links, gather, elements, results: flat.results }
}

/// [`check`] for [`crate::session::Method::Hierarchical`], with [`hierarchical_estimate`].
pub fn check_hierarchical(scene: &Scene, frames: u64) -> Result<()> {
    let Some(budget) = budget_bytes(scene.settings.memory_budget_mb) else { return Ok(()) };
    let e = hierarchical_estimate(scene, frames);
    if e.total() <= budget {
        return Ok(());
    }
    let mb = |b: u64| b.div_ceil(MIB);
    let source = if scene.settings.memory_budget_mb > 0 {
        "settings.memory_budget_mb".to_owned()
    } else {
        format!("{:.0}% of the memory available", DEFAULT_SHARE * 100.0)
    };
    Err(Error::OverBudget(format!(
        "this hierarchical bake may need up to {} MB (links {} MB, nodes and elements {} MB, results {} MB) \
         but the budget is {} MB ({source}); use fewer faces, a larger settings.accuracy or a lower \
         settings.basis_order, bake fewer frames at once, or raise memory_budget_mb",
        mb(e.total()),
        mb(e.links),
        mb(e.elements),
        mb(e.results),
        mb(budget),
    )))
}

/// The error for `bytes` that could not be had while building `what`; one line, with what to
/// change.
pub fn out_of_memory(what: &str, bytes: u64) -> Error {
    Error::OutOfMemory(format!(
        "while building {what}: could not allocate {} MB more; use fewer faces or a lower basis \
         order (a lower memory budget refuses such bakes before they start)",
        bytes.div_ceil(MIB)
    ))
}

/// An empty vector with room for `len` values of `T`, or [`Error::OutOfMemory`] naming `what`.
pub fn try_vec<T>(len: usize, what: &str) -> Result<Vec<T>> {
    let mut v = Vec::new();
    try_reserve(&mut v, len, what)?;
    Ok(v)
}

/// `len` copies of `value`, or [`Error::OutOfMemory`] naming `what` (`vec![value; len]` that
/// returns the allocator's refusal).
pub fn try_filled<T: Clone>(len: usize, value: T, what: &str) -> Result<Vec<T>> {
    let mut v = try_vec(len, what)?;
    v.resize(len, value);
    Ok(v)
}

/// `v.try_reserve(additional)` (amortised growth, as `push` does), with the failure as
/// [`Error::OutOfMemory`] naming `what`.
pub fn try_reserve<T>(v: &mut Vec<T>, additional: usize, what: &str) -> Result<()> {
    v.try_reserve(additional).map_err(|_| out_of_memory(what, bytes_for::<T>(v.len(), additional)))
}

/// `v.try_reserve_exact(additional)`, with the failure as [`Error::OutOfMemory`] naming `what`.
pub fn try_reserve_exact<T>(v: &mut Vec<T>, additional: usize, what: &str) -> Result<()> {
    v.try_reserve_exact(additional).map_err(|_| out_of_memory(what, bytes_for::<T>(v.len(), additional)))
}

/// The bytes of `len + additional` values of `T` (saturating: the request may be past `usize`).
fn bytes_for<T>(len: usize, additional: usize) -> u64 {
    (len as u64).saturating_add(additional as u64).saturating_mul(size_of::<T>() as u64)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Settings;
    use crate::scenes;

    #[test]
    fn the_estimate_bounds_the_cornell_box_links_and_scales_with_the_pairs() {
        let scene = scenes::cornell_box(4, Settings::default());
        let e = estimate(&scene, 1);
        // The link store of the built frame is below the (doubled) estimate.
        let sys = crate::system::System::build(&scene, 0.0, &crate::system::no_progress).unwrap();
        assert!(sys.links.memory_bytes() as u64 * 2 <= e.links, "{} vs {e:?}", sys.links.memory_bytes());
        // The pairs counted are those the kernel's assembly considers (every pair it links is
        // among them), fewer than all.
        let patches = flat_elements(&scene);
        let counted = facing_pairs(&patches);
        let may_face = crate::kernel::assemble::may_face;
        let brute = (0..patches.len())
            .flat_map(|i| (i + 1..patches.len()).map(move |j| (i, j)))
            .filter(|&(i, j)| may_face(&patches[i], &patches[j]) && may_face(&patches[j], &patches[i]))
            .count() as u64;
        let n = patches.len() as u64;
        assert_eq!(counted, brute);
        assert!(sys.links.len() as u64 <= counted && counted < n * (n - 1) / 2, "{counted} of {n}");
        // The sampled bound holds the count, within 2% of all pairs.
        let sampled = sampled_facing_pairs(&patches, 1 << 16);
        assert!(counted <= sampled && sampled < counted + n * (n - 1) / 100, "{sampled} against {counted}");
    }

    #[test]
    fn the_hierarchical_estimate_counts_the_pair_tree_of_an_animation() {
        let scene = scenes::cornell_box_animated(2, 8, Settings::default());
        let mut still = scene.clone();
        still.frames = (scene.frames.0, scene.frames.0);
        let (animated, one) = (hierarchical_estimate(&scene, 1), hierarchical_estimate(&still, 1));
        let hs = crate::hierarchy::HierarchySettings {
            keep_pair_tree: true,
            ..crate::hierarchy::HierarchySettings::of(&scene.settings)
        };
        let frame = crate::hierarchy::solve_frame(&scene, 1.0, &hs, &crate::system::no_progress).unwrap();
        let kept = frame.stats.pair_tree_bytes as u64;
        assert!(frame.stats.pair_tree > 0, "no pair tree kept");
        assert!(
            kept <= animated.links - one.links,
            "pair tree {kept} B, estimated {}",
            animated.links - one.links
        );
        assert!(animated.elements > one.elements, "an update's two frames of nodes are not counted");
    }

    #[test]
    fn the_hierarchical_estimate_bounds_a_frame_of_the_cornell_box() {
        let scene = scenes::cornell_box(4, Settings::default());
        let e = hierarchical_estimate(&scene, 1);
        let hs = crate::hierarchy::HierarchySettings::of(&scene.settings);
        let frame = crate::hierarchy::solve_frame(&scene, 0.0, &hs, &crate::system::no_progress).unwrap();
        let s = &frame.stats;
        assert!(s.link_bytes as u64 * 2 <= e.links, "{s:?} vs {e:?}");
        let nodes = s.nodes as u64 * size_of::<crate::hierarchy::tree::Node>() as u64;
        assert!(nodes <= e.elements, "{s:?} vs {e:?}");
        // Linear in the faces: at 60,000 faces, under a fiftieth of the flat method's pairs.
        let big = scenes::cornell_box(100, Settings::default());
        assert!(hierarchical_estimate(&big, 1).total() * 50 < estimate(&big, 1).total());
    }

    #[test]
    fn a_budget_set_in_megabytes_is_used_as_is() {
        assert_eq!(budget_bytes(3), Some(3 * MIB));
        let mut scene = scenes::cornell_box(4, Settings::default());
        scene.settings.memory_budget_mb = 1;
        let Err(Error::OverBudget(m)) = check(&scene, 1) else { panic!("not refused") };
        assert!(m.contains("but the budget is 1 MB (settings.memory_budget_mb)"), "{m}");
        scene.settings.memory_budget_mb = 1 << 20;
        check(&scene, 1).unwrap();
    }

    #[test]
    fn an_allocation_no_machine_can_give_is_an_error_not_an_abort() {
        // 2^60 bytes (1 EiB): below isize::MAX, so the allocator itself is asked and refuses.
        let Err(Error::OutOfMemory(m)) = try_vec::<u64>(1 << 57, "the links") else {
            panic!("an exabyte was reserved")
        };
        let line = Error::OutOfMemory(m).to_string();
        assert!(
            line.starts_with(
                "out of memory while building the links: could not allocate 1099511627776 MB more;"
            ),
            "{line}"
        );
        assert!(!line.contains('\n'));
        // Past usize (a capacity overflow, not an allocator failure): the same error.
        let mut v = vec![0u8; 8];
        assert!(matches!(try_reserve(&mut v, usize::MAX, "rows"), Err(Error::OutOfMemory(_))));
        assert!(matches!(try_reserve_exact(&mut v, usize::MAX - 4, "rows"), Err(Error::OutOfMemory(_))));
        assert_eq!(v, [0; 8], "a failed reservation keeps the vector");
        // What fits is reserved as asked.
        let v = try_vec::<f32>(1000, "rows").unwrap();
        assert!(v.capacity() >= 1000 && v.is_empty());
    }
}
