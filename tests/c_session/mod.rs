//! A scene handed to `gr_session_new` as a host would: its materials and objects flattened into
//! the C ABI's arrays.

use std::ptr::null_mut;

use galerkin_radiosity::ffi::*;
use galerkin_radiosity::scene::Scene;

/// `gr_session_new` of `scene` with `settings`: its status and the session (null unless OK).
pub fn new_session(scene: &Scene, settings: &GrSettings) -> (GrStatus, *mut GrSession) {
    let reflectance: Vec<f32> =
        scene.materials.iter().flat_map(|m| m.reflectance.map(|x| x as f32)).collect();
    let emission: Vec<f32> = scene.materials.iter().flat_map(|m| m.emission.map(|x| x as f32)).collect();
    let (mut vertex_counts, mut vertices, mut face_counts) = (Vec::new(), Vec::new(), Vec::new());
    let (mut face_vertex_counts, mut indices, mut face_materials) = (Vec::new(), Vec::new(), Vec::new());
    for o in &scene.objects {
        vertex_counts.push(o.vertices.len() as u32);
        vertices.extend(o.vertices.iter().flat_map(|v| v.to_array().map(|x| x as f32)));
        face_counts.push(o.faces.len() as u32);
        for face in &o.faces {
            face_vertex_counts.push(face.len() as u32);
            indices.extend(face);
        }
        face_materials.extend(&o.face_materials);
    }
    let mut out = null_mut();
    let status = unsafe {
        gr_session_new(
            settings,
            scene.materials.len() as u32,
            reflectance.as_ptr(),
            emission.as_ptr(),
            scene.objects.len() as u32,
            vertex_counts.as_ptr(),
            vertices.as_ptr(),
            face_counts.as_ptr(),
            face_vertex_counts.as_ptr(),
            indices.as_ptr(),
            face_materials.as_ptr(),
            std::ptr::null(),
            vertices.len(),
            indices.len(),
            &mut out,
        )
    };
    (status, out)
}
