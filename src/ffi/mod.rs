//! The C ABI (issue 4), in the style of rustls-ffi: opaque handles, a status enum, every body
//! inside a panic boundary, out-parameters written only on success, every pointer NULL-checked
//! and every buffer passed with its length. `include/galerkin_radiosity.h` is generated from
//! these modules by cbindgen (`cbindgen.toml`; `GR_UPDATE_HEADER=1 cargo test --test header`).
//!
//! - [`error`]: `GrStatus` and the thread-local message behind `gr_last_error`.
//! - [`panic`](mod@panic): the boundary.
//! - [`settings`]: `GrSettings`, `GrMethod`.
//! - [`session`]: `GrSession` and its functions.
//! - [`lights`]: `GrLight` and `gr_session_set_lights` (Blender Light objects).
//! - [`builder`]: `GrSceneBuilder` and `GrMesh`, the scene one call at a time (ABI version 2).
//! - `sized`: the `struct_size` rule by which structs grow without breaking.
//! - [`surface`]: `gr_session_set_object_surface` (smooth-shading normals, per-face reflectance),
//!   `gr_session_set_object_face_emission` (per-face emission colour scale).

pub mod builder;
pub mod error;
pub mod lights;
pub mod panic;
pub mod session;
pub mod settings;
mod sized;
pub mod surface;

use std::ffi::{CStr, c_char};

pub use builder::{
    GrMesh, GrSceneBuilder, gr_mesh_default, gr_scene_builder_add_light, gr_scene_builder_add_material,
    gr_scene_builder_add_mesh, gr_scene_builder_build, gr_scene_builder_free, gr_scene_builder_new,
    gr_scene_builder_set_settings,
};
pub use error::{GrStatus, gr_last_error};
pub use lights::{
    GrLight, GrLightKind, GrLightShape, gr_light_default, gr_session_set_lights, gr_session_set_two_sided,
    gr_session_set_world,
};
pub use panic::run_in_boundary;
pub use session::{
    GrProgressFn, GrSession, gr_session_cancel, gr_session_corner_count, gr_session_corner_irradiance,
    gr_session_corner_radiosity, gr_session_eval, gr_session_eval_irradiance, gr_session_face_count,
    gr_session_face_radiosity, gr_session_frame_stats_json, gr_session_free, gr_session_new,
    gr_session_object_count, gr_session_refine, gr_session_set_material_emission,
    gr_session_set_object_matrix, gr_session_set_preview, gr_session_solve_frame,
};
pub use settings::{GrMethod, GrSettings, gr_settings_default};
pub use surface::{gr_session_set_object_face_emission, gr_session_set_object_surface};

/// The version of this C ABI. It changes only when a declaration in this header changes
/// incompatibly; check it after loading the library. Version 2: `GrSettings` begins with
/// `struct_size` (its layout changed), the scene builder and `GrMesh`, `GR_STATUS_OUT_OF_MEMORY`.
/// From version 2 on the ABI grows without breaking: new functions, new fields at the end of the
/// sized structs (read only when the caller's `struct_size` covers them) and new status codes
/// (treat an unknown one as an error) leave the version as it is.
pub const GR_ABI_VERSION: u32 = 3;

const VERSION: &CStr = match CStr::from_bytes_with_nul(concat!(env!("CARGO_PKG_VERSION"), "\0").as_bytes()) {
    Ok(v) => v,
    Err(_) => panic!("the crate version contains a NUL"),
};

/// Returns the ABI version, `GR_ABI_VERSION` (3).
#[unsafe(no_mangle)]
pub extern "C" fn gr_abi_version() -> u32 {
    GR_ABI_VERSION
}

/// Returns the library's version (the crate's, e.g. "0.1.0") as a static NUL-terminated string;
/// do not free it.
#[unsafe(no_mangle)]
pub extern "C" fn gr_version_string() -> *const c_char {
    VERSION.as_ptr()
}
