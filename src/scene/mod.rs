//! The validated scene: materials, objects (object-space meshes with a world placement that may
//! be keyed over frames), and solver settings.
//!
//! [`json`] reads the version-1 scene file; [`Scene::new`] validates any scene, however it was
//! made (JSON, the C ABI), so every entry point shares one set of checks.

pub mod json;
pub mod placement;
pub mod surface;
mod validate;

pub use placement::{Key, KeyTransform};
pub use surface::Surface;
pub use validate::{
    MAX_COORDINATE, MAX_EMISSION, MAX_FRAMES, MAX_THREADS, check_animation, check_frames, check_placed,
};

use glam::{DMat4, DVec3};

use crate::lights::{Light, World};

/// Solver settings. Defaults are documented in the README.
#[derive(Clone, Debug, PartialEq)]
pub struct Settings {
    /// Legendre degree per axis, 0..=3 (0: classic constant radiosity).
    pub basis_order: usize,
    /// Gauss-Legendre points per axis for a well-separated pair of patches.
    pub quadrature_order: usize,
    /// Progressive refinement stops when the unshot coefficients would deliver less than
    /// `tolerance` x emitted power in one bounce.
    pub tolerance: f64,
    /// Ray-cast visibility inside the kernel; `false` treats everything as mutually visible.
    pub visibility: bool,
    /// Visibility samples per axis of each patch (rays per link = this^4).
    pub visibility_samples: usize,
    /// Worker threads; 0 means one per core.
    pub threads: usize,
    /// Fewer quadrature points for well-separated pairs (README, "Quadrature"); off only for
    /// reference solutions.
    pub adaptive_quadrature: bool,
    /// Face corners report `B` gathered at the corner from the solution ([`crate::gather`]),
    /// with its own shadow rays, instead of the face polynomial's value there.
    pub corner_gather: bool,
    /// Faces of open surfaces reflect from both sides, as Cycles' diffuse surfaces do
    /// ([`crate::backs`]). Off (the default): every face is one-sided.
    pub reflecting_backs: bool,
    /// The memory a bake may plan to use, in MiB ([`crate::budget`]); 0: 80% of the memory
    /// available when the session starts.
    pub memory_budget_mb: u64,
    /// The hierarchical solve's one accuracy knob ([`crate::hierarchy`]): the largest share of
    /// the emitted power a link may carry without being refined (smaller is finer and slower).
    pub accuracy: f64,
    /// The lights' direct light projected on each element at preview quality (3 x 3 points
    /// instead of 6 x 6, [`crate::lights::direct`]): set by [`crate::session::Session`] for a
    /// live preview's frames, whose refinement projects it again in full. Not a scene file's
    /// setting.
    pub preview_lights: bool,
}

impl Default for Settings {
    fn default() -> Self {
        Self {
            basis_order: 2,
            quadrature_order: 4,
            tolerance: 1e-4,
            visibility: true,
            visibility_samples: 2,
            threads: 0,
            adaptive_quadrature: true,
            corner_gather: true,
            reflecting_backs: false,
            memory_budget_mb: 0,
            accuracy: crate::hierarchy::DEFAULT_ACCURACY,
            preview_lights: false,
        }
    }
}

#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    pub name: String,
    /// Diffuse reflectance per RGB channel, each in [0,1).
    pub reflectance: [f64; 3],
    /// Radiant exitance per RGB channel (W/m^2), >= 0.
    pub emission: [f64; 3],
}

/// A mesh in object space and its world placement.
#[derive(Clone, Debug, PartialEq)]
pub struct Object {
    pub name: String,
    pub vertices: Vec<DVec3>,
    /// Vertex indices per face, 3 or 4, counter-clockwise seen from the lit (front) side in
    /// object space; a mirroring placement keeps that side ([`placement::front_order`]).
    pub faces: Vec<Vec<u32>>,
    /// Material index per face.
    pub face_materials: Vec<u32>,
    /// World-from-object at frames without keys (and the base of translation keys).
    pub matrix: DMat4,
    /// Placement keys, sorted by frame.
    pub animation: Vec<Key>,
}

impl Object {
    /// World-from-object matrix at `frame`: keys interpolated linearly, held outside them.
    pub fn world_from_object(&self, frame: f64) -> DMat4 {
        placement::world_from_object(self.matrix, &self.animation, frame)
    }

    /// True when the placement at `frame` mirrors space (its faces are placed with reversed
    /// winding to keep their front side).
    pub fn mirrored_at(&self, frame: f64) -> bool {
        placement::mirrors(&self.world_from_object(frame))
    }

    /// True when the object's placement changes over some frame range.
    pub fn is_animated(&self) -> bool {
        !self.animation.is_empty()
    }
}

/// A material's emission keyed over frames (linear between keys, held outside).
#[derive(Clone, Debug, PartialEq)]
pub struct EmissionKey {
    pub frame: f64,
    pub emission: [f64; 3],
}

/// A validated scene. Construct with [`Scene::new`] or [`json::parse_scene`].
#[derive(Clone, Debug, PartialEq)]
pub struct Scene {
    pub settings: Settings,
    /// First and last frame, inclusive.
    pub frames: (i64, i64),
    pub materials: Vec<Material>,
    /// Emission keys per material (empty: constant emission).
    pub emission_keys: Vec<Vec<EmissionKey>>,
    pub objects: Vec<Object>,
    /// Faces skipped because their area is zero: (object, face).
    pub degenerate_faces: Vec<(usize, usize)>,
    /// Blender Light objects ([`crate::lights`]); set with [`Scene::with_lights`].
    pub lights: Vec<Light>,
    /// Blender's World as light from infinitely far ([`crate::lights::world`]); set with
    /// [`Scene::with_world`].
    pub world: Option<World>,
    /// Objects whose emitting faces emit from both sides, by object index (missing: one-sided;
    /// [`crate::lights`]'s `backs`); set with [`Scene::with_two_sided`].
    pub two_sided: Vec<bool>,
    /// Per object (empty: none at all): shading normals and per-face reflectance
    /// ([`surface`]); set with [`Scene::with_surfaces`].
    pub surfaces: Vec<Surface>,
}

impl Scene {
    /// More than one frame: an animation (the hierarchy keeps its pair tree for the updates,
    /// and the memory estimate counts it).
    pub fn is_animation(&self) -> bool {
        self.frames.0 != self.frames.1
    }

    /// Validates everything and records zero-area faces (which are skipped, with a warning).
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        settings: Settings,
        frames: (i64, i64),
        materials: Vec<Material>,
        emission_keys: Vec<Vec<EmissionKey>>,
        objects: Vec<Object>,
    ) -> crate::Result<Self> {
        let mut scene = Scene {
            settings,
            frames,
            materials,
            emission_keys,
            objects,
            degenerate_faces: Vec::new(),
            lights: Vec::new(),
            world: None,
            two_sided: Vec::new(),
            surfaces: Vec::new(),
        };
        validate::validate(&mut scene)?;
        Ok(scene)
    }

    /// The scene lit by `lights` too (validated; their keys sorted by frame).
    pub fn with_lights(mut self, mut lights: Vec<Light>) -> crate::Result<Self> {
        for l in &mut lights {
            l.animation.sort_by(|a, b| a.frame.total_cmp(&b.frame));
        }
        crate::lights::validate(&lights)?;
        self.lights = lights;
        Ok(self)
    }

    /// The scene lit by `world` too (validated; its keys sorted by frame).
    pub fn with_world(mut self, mut world: Option<World>) -> crate::Result<Self> {
        if let Some(w) = &mut world {
            w.animation.sort_by(|a, b| a.frame.total_cmp(&b.frame));
            w.validate()?;
        }
        self.world = world;
        Ok(self)
    }

    /// The scene with the emitting faces of `objects` (indices) emitting from both sides.
    pub fn with_two_sided(mut self, objects: &[usize]) -> crate::Result<Self> {
        let mut two_sided = vec![false; self.objects.len()];
        for &o in objects {
            *two_sided.get_mut(o).ok_or_else(|| {
                crate::error::invalid_scene!("two-sided object {o} out of range (0..{})", self.objects.len())
            })? = true;
        }
        self.two_sided = two_sided;
        Ok(self)
    }

    /// The scene with `surfaces` (one per object, or none), validated against the objects.
    pub fn with_surfaces(mut self, surfaces: Vec<Surface>) -> crate::Result<Self> {
        if !surfaces.is_empty() && surfaces.len() != self.objects.len() {
            return Err(crate::error::invalid_scene!(
                "{} surfaces for {} objects",
                surfaces.len(),
                self.objects.len()
            ));
        }
        for (o, (s, obj)) in surfaces.iter().zip(&self.objects).enumerate() {
            s.validate(obj, &format!("object {o} \"{}\"", obj.name))?;
        }
        self.surfaces = if surfaces.iter().all(Surface::is_empty) { Vec::new() } else { surfaces };
        Ok(self)
    }

    /// Replaces object `o`'s surface data (validated; on error nothing changes).
    pub fn set_surface(&mut self, o: usize, surface: Surface) -> crate::Result<()> {
        let Some(obj) = self.objects.get(o) else {
            return Err(crate::Error::InvalidArgument(format!(
                "object {o} out of range (0..{})",
                self.objects.len()
            )));
        };
        surface.validate(obj, &format!("object {o} \"{}\"", obj.name))?;
        if self.surfaces.is_empty() {
            if surface.is_empty() {
                return Ok(());
            }
            self.surfaces = vec![Surface::default(); self.objects.len()];
        }
        self.surfaces[o] = surface;
        Ok(())
    }

    /// The diffuse reflectance of face `f` of object `o`, whose material is `material`: the
    /// face's own where given ([`Surface::face_reflectance`]), else the material's.
    pub fn reflectance_of(&self, o: usize, f: usize, material: u32) -> [f64; 3] {
        self.surfaces
            .get(o)
            .and_then(|s| s.face_reflectance.get(f))
            .copied()
            .unwrap_or(self.materials[material as usize].reflectance)
    }

    /// Object `o`'s shading normals per face corner (empty: its faces' own).
    pub fn corner_normals(&self, o: usize) -> &[DVec3] {
        self.surfaces.get(o).map_or(&[], |s| &s.corner_normals)
    }

    /// Emission of material `m` at `frame`.
    pub fn emission_at(&self, m: usize, frame: f64) -> [f64; 3] {
        placement::emission_at(self.materials[m].emission, &self.emission_keys[m], frame)
    }

    /// Face `f` of object `o`'s emission colour scale ([`Surface::face_emission`]; 1 without).
    pub fn emission_scale(&self, o: usize, f: usize) -> [f64; 3] {
        self.surfaces.get(o).and_then(|s| s.face_emission.get(f)).copied().unwrap_or([1.0; 3])
    }

    /// Whether face `f` of object `o`, whose material is `material`, emits at some frame: at its
    /// material's base or at any of its keys, times the face's scale (not only at one frame: what
    /// depends on it must not change when a keyed light comes on).
    pub fn may_emit(&self, o: usize, f: usize, material: u32) -> bool {
        let m = material as usize;
        let scale = self.emission_scale(o, f);
        let lit = |e: [f64; 3]| e.iter().zip(scale).any(|(&x, s)| x * s > 0.0);
        lit(self.materials[m].emission) || self.emission_keys[m].iter().any(|k| lit(k.emission))
    }

    /// The exitance of face `f` of object `o`, whose material is `material`, at `frame`: the
    /// material's emission (keys included) times the face's scale ([`Scene::emission_scale`]).
    pub fn emission_of(&self, o: usize, f: usize, material: u32, frame: f64) -> [f64; 3] {
        scaled(self.emission_at(material as usize, frame), self.emission_scale(o, f))
    }

    /// Total number of faces over all objects.
    pub fn face_count(&self) -> usize {
        self.objects.iter().map(|o| o.faces.len()).sum()
    }
}

/// `e` times `scale` per channel (a face's emission scale on a material's emission).
pub fn scaled(e: [f64; 3], scale: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|c| e[c] * scale[c])
}
