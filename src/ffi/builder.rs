//! `GrSceneBuilder`: a scene put together one call at a time (issue 22, item 1), so that the
//! ABI can take new kinds of input (a light, a setting, a mesh field) without changing a
//! signature: materials, meshes (`GrMesh`, which carries its own size) and lights are added,
//! settings set, then `gr_scene_builder_build` validates the whole scene and makes a session.
//! Adding checks the arrays of the call (lengths, indices); the scene's own rules (finite
//! vertices, reflectance ranges, areas) are checked by the build, with the same messages as
//! `gr_session_new`.

use std::ptr::null;

use super::error::{Failure, GrStatus};
use super::lights::{GrLight, read_light};
use super::panic::{boundary, boundary_value};
use super::session::{GrSession, array, matrix_from_row_major, rgb};
use super::settings::{GrSettings, read_settings};
use crate::lights::Light;
use crate::scene::{Material, Object, Settings};
use crate::session::Method;

/// A scene being built. Create with `gr_scene_builder_new`, release with
/// `gr_scene_builder_free` (building does not consume it). Not for use from two threads at once.
pub struct GrSceneBuilder {
    settings: Settings,
    method: Method,
    materials: Vec<Material>,
    objects: Vec<Object>,
    lights: Vec<Light>,
}

/// One mesh object for `gr_scene_builder_add_mesh`. Fill with `gr_mesh_default`, then set the
/// arrays; they are read during the call only. Like `GrSettings` it grows at its end only, and
/// fields past the caller's `struct_size` take their defaults.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct GrMesh {
    /// `sizeof(GrMesh)` of the header the host was built with; set by `gr_mesh_default`.
    pub struct_size: u32,
    /// Vertices; `vertices` holds 3 floats per vertex (object space).
    pub vertex_count: u32,
    pub vertices: *const f32,
    /// Faces; `face_vertex_counts` (3 or 4 each) and `face_materials` (an index returned by
    /// `gr_scene_builder_add_material`) hold one entry per face.
    pub face_count: u32,
    pub face_vertex_counts: *const u32,
    pub face_materials: *const u32,
    /// The vertex indices of every face in order, counter-clockwise seen from the lit (front)
    /// side; `face_indices_len` is the sum of `face_vertex_counts`.
    pub face_indices: *const u32,
    pub face_indices_len: usize,
    /// 16 floats, row-major world-from-object, or NULL for identity.
    pub matrix: *const f32,
}

/// `sizeof(GrMesh)` of its first version (ABI version 2).
const MESH_V2_SIZE: usize = 64;
const _: () = assert!(size_of::<GrMesh>() == MESH_V2_SIZE || size_of::<usize>() != 8);

/// # Safety
/// `b` is NULL or a live builder, not used elsewhere during the call.
unsafe fn builder<'a>(b: *mut GrSceneBuilder) -> Result<&'a mut GrSceneBuilder, Failure> {
    if b.is_null() {
        return Err(Failure::null("builder"));
    }
    // SAFETY: per the contract, a live builder with no other reference during the call.
    Ok(unsafe { &mut *b })
}

/// Writes an index to `out` (NULL allowed: the caller does not want it).
///
/// # Safety
/// `out` is NULL or points to a writable `u32`.
unsafe fn write_index(out: *mut u32, index: usize) -> Result<(), Failure> {
    let index = u32::try_from(index).map_err(|_| Failure::invalid("more than 2^32 - 1 entries"))?;
    if !out.is_null() {
        // SAFETY: non-null and writable per the contract.
        unsafe { out.write_unaligned(index) };
    }
    Ok(())
}

/// Creates an empty scene builder with the library's default settings (`gr_settings_default`)
/// and writes it to `*out`.
///
/// # Safety
/// `out` is NULL or points to a writable `GrSceneBuilder *`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn gr_scene_builder_new(out: *mut *mut GrSceneBuilder) -> GrStatus {
    boundary("gr_scene_builder_new", || {
        if out.is_null() {
            return Err(Failure::null("out"));
        }
        let b = Box::new(GrSceneBuilder {
            settings: Settings::default(),
            method: Method::Incremental,
            materials: Vec::new(),
            objects: Vec::new(),
            lights: Vec::new(),
        });
        // SAFETY: non-null, writable per the contract.
        unsafe { out.write_unaligned(Box::into_raw(b)) };
        Ok(())
    })
}

/// Sets the settings of the sessions this builder makes (copied; `GR_STATUS_INVALID_ARGUMENT`
/// for an unknown enum value or a `struct_size` this library cannot read). Their ranges are
/// checked by the build.
///
/// # Safety
/// `b` is NULL or a live builder; `settings` is NULL or points to a readable `GrSettings` of
/// at least `settings->struct_size` bytes.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn gr_scene_builder_set_settings(
    b: *mut GrSceneBuilder,
    settings: *const GrSettings,
) -> GrStatus {
    boundary("gr_scene_builder_set_settings", || {
        let b = unsafe { builder(b) }?;
        let (settings, method) = unsafe { read_settings(settings) }?;
        (b.settings, b.method) = (settings, method);
        Ok(())
    })
}

/// Adds a material: `reflectance` and `emission` 3 floats each (RGB; reflectance in [0,1),
/// emission radiant exitance in W/m^2). Its index (0, 1, ... in the order added) goes to
/// `*out_index` unless that is NULL. Named "material N" in messages.
///
/// # Safety
/// `b` is NULL or a live builder; `reflectance` and `emission` are NULL or point to 3 readable
/// floats; `out_index` is NULL or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn gr_scene_builder_add_material(
    b: *mut GrSceneBuilder,
    reflectance: *const f32,
    emission: *const f32,
    out_index: *mut u32,
) -> GrStatus {
    boundary("gr_scene_builder_add_material", || {
        let b = unsafe { builder(b) }?;
        if reflectance.is_null() {
            return Err(Failure::null("reflectance"));
        }
        if emission.is_null() {
            return Err(Failure::null("emission"));
        }
        let r = unsafe { array(reflectance, 3, "reflectance") }?;
        let e = unsafe { array(emission, 3, "emission") }?;
        let index = b.materials.len();
        unsafe { write_index(out_index, index) }?;
        b.materials.push(Material {
            name: format!("material {index}"),
            reflectance: rgb(r),
            emission: rgb(e),
        });
        Ok(())
    })
}

/// Writes an empty `GrMesh` (no vertices, no faces, identity matrix) with `struct_size` set.
///
/// # Safety
/// `out` is NULL or points to a writable `GrMesh`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn gr_mesh_default(out: *mut GrMesh) -> GrStatus {
    boundary("gr_mesh_default", || {
        if out.is_null() {
            return Err(Failure::null("out"));
        }
        let mesh = GrMesh {
            struct_size: size_of::<GrMesh>() as u32,
            vertex_count: 0,
            vertices: null(),
            face_count: 0,
            face_vertex_counts: null(),
            face_materials: null(),
            face_indices: null(),
            face_indices_len: 0,
            matrix: null(),
        };
        // SAFETY: non-null, writable per the contract.
        unsafe { out.write_unaligned(mesh) };
        Ok(())
    })
}

/// Adds a mesh object (copied); its index (0, 1, ... in the order added: the `object` of the
/// session's functions) goes to `*out_index` unless that is NULL. Named "object N" in messages.
/// `GR_STATUS_INVALID_ARGUMENT` when `face_indices_len` disagrees with `face_vertex_counts`;
/// indices and materials out of range are found by the build (`GR_STATUS_INVALID_SCENE`).
///
/// # Safety
/// `b` is NULL or a live builder; `mesh` is NULL or points to a readable `GrMesh` whose
/// pointers hold the lengths it gives; `out_index` is NULL or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn gr_scene_builder_add_mesh(
    b: *mut GrSceneBuilder,
    mesh: *const GrMesh,
    out_index: *mut u32,
) -> GrStatus {
    boundary("gr_scene_builder_add_mesh", || {
        let b = unsafe { builder(b) }?;
        if mesh.is_null() {
            return Err(Failure::null("mesh"));
        }
        let index = b.objects.len();
        let object =
            unsafe { read_mesh(mesh, index) }.map_err(|f| f.prefixed(&format!("object {index}: ")))?;
        unsafe { write_index(out_index, index) }?;
        b.objects.push(object);
        Ok(())
    })
}

/// The object `index` described by `mesh`.
///
/// # Safety
/// As `gr_scene_builder_add_mesh`'s `mesh`, non-NULL.
unsafe fn read_mesh(mesh: *const GrMesh, index: usize) -> Result<Object, Failure> {
    // SAFETY: non-null and readable: its first field is there in every version.
    let size = unsafe { mesh.cast::<u32>().read_unaligned() };
    super::sized::check("mesh", size, MESH_V2_SIZE, size_of::<GrMesh>(), "gr_mesh_default")?;
    // SAFETY: at least the version-2 size is readable (checked), and that is all of it.
    let m = unsafe { mesh.read_unaligned() };
    let (nv, nf) = (m.vertex_count as usize, m.face_count as usize);
    let vertices = unsafe { array(m.vertices, 3 * nv, "mesh.vertices") }?;
    let counts = unsafe { array(m.face_vertex_counts, nf, "mesh.face_vertex_counts") }?;
    let materials = unsafe { array(m.face_materials, nf, "mesh.face_materials") }?;
    let total: u64 = counts.iter().map(|&c| u64::from(c)).sum();
    if total != m.face_indices_len as u64 {
        return Err(Failure::invalid(format!(
            "mesh.face_indices_len is {} but mesh.face_vertex_counts sum to {total}",
            m.face_indices_len
        )));
    }
    let indices = unsafe { array(m.face_indices, m.face_indices_len, "mesh.face_indices") }?;
    let matrix = if m.matrix.is_null() {
        glam::DMat4::IDENTITY
    } else {
        matrix_from_row_major(unsafe { array(m.matrix, 16, "mesh.matrix") }?)
    };
    let mut faces = Vec::with_capacity(nf);
    let mut start = 0usize;
    for &k in counts {
        faces.push(indices[start..start + k as usize].to_vec());
        start += k as usize;
    }
    Ok(Object {
        name: format!("object {index}"),
        vertices: vertices
            .chunks_exact(3)
            .map(|p| glam::DVec3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2])))
            .collect(),
        faces,
        face_materials: materials.to_vec(),
        matrix,
        animation: Vec::new(),
    })
}

/// Adds a light (copied; fill it with `gr_light_default`). Named `lights[N]` in messages;
/// `GR_STATUS_INVALID_ARGUMENT` for an unknown kind or shape or a wrong `struct_size`. The
/// session's `gr_session_set_lights` replaces the list later.
///
/// # Safety
/// `b` is NULL or a live builder; `light` is NULL or points to a readable `GrLight` (its
/// `struct_size` bytes: an older header's smaller struct is read with defaults beyond it).
#[unsafe(no_mangle)]
pub unsafe extern "C" fn gr_scene_builder_add_light(
    b: *mut GrSceneBuilder,
    light: *const GrLight,
) -> GrStatus {
    boundary("gr_scene_builder_add_light", || {
        let b = unsafe { builder(b) }?;
        if light.is_null() {
            return Err(Failure::null("light"));
        }
        // SAFETY: non-null and readable (its `struct_size` bytes) per the contract.
        let light = unsafe { read_light(b.lights.len(), light) }?;
        b.lights.push(light);
        Ok(())
    })
}

/// Validates the scene built so far and creates a session from it, written to `*out`; the
/// builder is left as it is (free it with `gr_scene_builder_free`, or build again).
/// `GR_STATUS_INVALID_SCENE` (the message names the object, face, light or field) when the
/// scene fails validation or its estimated memory is over the budget. `*out` is written only
/// on success.
///
/// # Safety
/// `b` is NULL or a live builder; `out` is NULL or points to a writable `GrSession *`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn gr_scene_builder_build(
    b: *mut GrSceneBuilder,
    out: *mut *mut GrSession,
) -> GrStatus {
    boundary("gr_scene_builder_build", || {
        let b = unsafe { builder(b) }?;
        if out.is_null() {
            return Err(Failure::null("out"));
        }
        let session = GrSession::create(
            b.settings.clone(),
            b.method,
            b.materials.clone(),
            b.objects.clone(),
            b.lights.clone(),
        )?;
        // SAFETY: non-null, writable per the contract.
        unsafe { out.write_unaligned(Box::into_raw(session)) };
        Ok(())
    })
}

/// Releases a builder (NULL is ignored). Sessions it built are independent of it.
///
/// # Safety
/// `b` is NULL or a live builder, not used afterwards.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn gr_scene_builder_free(b: *mut GrSceneBuilder) {
    boundary_value((), || {
        if !b.is_null() {
            // SAFETY: a pointer from gr_scene_builder_new, freed once per the contract.
            drop(unsafe { Box::from_raw(b) });
        }
    })
}
