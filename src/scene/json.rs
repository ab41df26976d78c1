//! The version-1 scene file (README, "Scene JSON") and the result file the CLI writes.

use glam::{DMat4, DVec3};
use serde::{Deserialize, Serialize};

use super::{EmissionKey, Key, KeyTransform, Material, Object, Scene, Settings};
use crate::error::{Error, Result, invalid_scene};

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SceneFile {
    version: u32,
    settings: SettingsFile,
    frames: Option<[i64; 2]>,
    materials: Vec<MaterialFile>,
    objects: Vec<ObjectFile>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SettingsFile {
    basis_order: usize,
    quadrature_order: Option<usize>,
    tolerance: Option<f64>,
    visibility: Option<bool>,
    visibility_samples: Option<usize>,
    threads: Option<usize>,
    adaptive_quadrature: Option<bool>,
    corner_gather: Option<bool>,
    memory_budget_mb: Option<u64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct MaterialFile {
    name: Option<String>,
    reflectance: [f64; 3],
    #[serde(default)]
    emission: [f64; 3],
    #[serde(default)]
    emission_keys: Vec<EmissionKeyFile>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct EmissionKeyFile {
    frame: f64,
    emission: [f64; 3],
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ObjectFile {
    name: Option<String>,
    vertices: Vec<[f64; 3]>,
    faces: Vec<Vec<i64>>,
    #[serde(default)]
    material: i64,
    face_materials: Option<Vec<i64>>,
    matrix: Option<[f64; 16]>,
    #[serde(default)]
    animation: Vec<KeyFile>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct KeyFile {
    frame: f64,
    translation: Option<[f64; 3]>,
    matrix: Option<[f64; 16]>,
}

/// A row-major 4x4 (as written in the file) to glam's column-major matrix.
fn matrix_from_row_major(m: &[f64; 16]) -> DMat4 {
    DMat4::from_cols_array(m).transpose()
}

fn index(value: i64, what: &str, len: usize, place: &str) -> Result<u32> {
    if value < 0 || value as usize >= len {
        return Err(invalid_scene!("{place}: {what} {value} out of range (0..{len})"));
    }
    Ok(value as u32)
}

/// Parses and validates a version-1 scene file.
pub fn parse_scene(text: &str) -> Result<Scene> {
    let file: SceneFile = serde_json::from_str(text).map_err(|e| Error::Input(format!("scene JSON: {e}")))?;
    if file.version != 1 {
        return Err(invalid_scene!(
            "unsupported scene version {} (this build reads version 1)",
            file.version
        ));
    }
    let d = Settings::default();
    let s = file.settings;
    let settings = Settings {
        basis_order: s.basis_order,
        quadrature_order: s.quadrature_order.unwrap_or(d.quadrature_order),
        tolerance: s.tolerance.unwrap_or(d.tolerance),
        visibility: s.visibility.unwrap_or(d.visibility),
        visibility_samples: s.visibility_samples.unwrap_or(d.visibility_samples),
        threads: s.threads.unwrap_or(d.threads),
        adaptive_quadrature: s.adaptive_quadrature.unwrap_or(d.adaptive_quadrature),
        corner_gather: s.corner_gather.unwrap_or(d.corner_gather),
        memory_budget_mb: s.memory_budget_mb.unwrap_or(d.memory_budget_mb),
    };
    let mut materials = Vec::new();
    let mut emission_keys = Vec::new();
    for (m, mat) in file.materials.into_iter().enumerate() {
        materials.push(Material {
            name: mat.name.unwrap_or_else(|| format!("material {m}")),
            reflectance: mat.reflectance,
            emission: mat.emission,
        });
        let mut keys: Vec<EmissionKey> = mat
            .emission_keys
            .into_iter()
            .map(|k| EmissionKey { frame: k.frame, emission: k.emission })
            .collect();
        keys.sort_by(|a, b| a.frame.total_cmp(&b.frame));
        emission_keys.push(keys);
    }
    let n_materials = materials.len();
    let mut objects = Vec::new();
    for (o, obj) in file.objects.into_iter().enumerate() {
        let name = obj.name.unwrap_or_else(|| format!("object {o}"));
        let place = format!("object \"{name}\"");
        let vertices: Vec<DVec3> = obj.vertices.iter().map(|v| DVec3::from_array(*v)).collect();
        let mut faces = Vec::with_capacity(obj.faces.len());
        for (f, face) in obj.faces.iter().enumerate() {
            let face_place = format!("{place} face {f}");
            let idx = face
                .iter()
                .map(|&v| index(v, "vertex index", vertices.len(), &face_place))
                .collect::<Result<Vec<u32>>>()?;
            faces.push(idx);
        }
        let default_material = index(obj.material, "material", n_materials, &place)?;
        let face_materials = match obj.face_materials {
            None => vec![default_material; faces.len()],
            Some(fm) => {
                if fm.len() != faces.len() {
                    return Err(invalid_scene!(
                        "{place}: face_materials has {} entries for {} faces",
                        fm.len(),
                        faces.len()
                    ));
                }
                fm.iter()
                    .enumerate()
                    .map(|(f, &m)| index(m, "material", n_materials, &format!("{place} face {f}")))
                    .collect::<Result<Vec<u32>>>()?
            }
        };
        let mut animation = Vec::new();
        for (k, key) in obj.animation.iter().enumerate() {
            let transform = match (key.translation, key.matrix) {
                (Some(t), None) => KeyTransform::Translation(DVec3::from_array(t)),
                (None, Some(m)) => KeyTransform::Matrix(matrix_from_row_major(&m)),
                _ => {
                    return Err(invalid_scene!(
                        "{place} animation key {k}: give exactly one of \"translation\" or \"matrix\""
                    ));
                }
            };
            animation.push(Key { frame: key.frame, transform });
        }
        animation.sort_by(|a, b| a.frame.total_cmp(&b.frame));
        objects.push(Object {
            name,
            vertices,
            faces,
            face_materials,
            matrix: obj.matrix.map(|m| matrix_from_row_major(&m)).unwrap_or(DMat4::IDENTITY),
            animation,
        });
    }
    let frames = match file.frames {
        Some([a, b]) => (a, b),
        None => (1, 1),
    };
    Scene::new(settings, frames, materials, emission_keys, objects)
}

/// Reads and parses a scene file.
pub fn read_scene(path: &std::path::Path) -> Result<Scene> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::Input(format!("{}: {e}", path.display())))?;
    parse_scene(&text)
}

/// One object's radiosity at one frame, as written to the result file.
#[derive(Serialize, Deserialize, Clone, Debug)]
pub struct ObjectResult {
    pub name: String,
    /// Area-mean radiosity per face (W/m^2, RGB).
    pub face_radiosity: Vec<[f32; 3]>,
    /// Radiosity at each face corner, faces in order, corners in face order.
    pub corner_radiosity: Vec<[f32; 3]>,
}

#[derive(Serialize, Deserialize, Clone, Debug)]
pub struct FrameResult {
    pub frame: i64,
    pub objects: Vec<ObjectResult>,
    pub stats: serde_json::Value,
}

#[derive(Serialize, Deserialize, Clone, Debug)]
pub struct ResultFile {
    pub frames: Vec<FrameResult>,
    pub stats: serde_json::Value,
}

/// Writes a scene as a version-1 scene file (placement keys included).
pub fn scene_to_json(scene: &Scene) -> String {
    use serde_json::json;
    let row_major = |m: &DMat4| m.transpose().to_cols_array().to_vec();
    let s = &scene.settings;
    let materials: Vec<_> = scene
        .materials
        .iter()
        .zip(&scene.emission_keys)
        .map(|(m, keys)| {
            let keys: Vec<_> = keys.iter().map(|k| json!({"frame": k.frame, "emission": k.emission})).collect();
            json!({"name": m.name, "reflectance": m.reflectance, "emission": m.emission, "emission_keys": keys})
        })
        .collect();
    let objects: Vec<_> = scene
        .objects
        .iter()
        .map(|o| {
            let animation: Vec<_> = o
                .animation
                .iter()
                .map(|k| match &k.transform {
                    KeyTransform::Translation(t) => {
                        json!({"frame": k.frame, "translation": t.to_array()})
                    }
                    KeyTransform::Matrix(m) => json!({"frame": k.frame, "matrix": row_major(m)}),
                })
                .collect();
            json!({
                "name": o.name,
                "vertices": o.vertices.iter().map(|v| v.to_array()).collect::<Vec<_>>(),
                "faces": o.faces,
                "face_materials": o.face_materials,
                "matrix": row_major(&o.matrix),
                "animation": animation,
            })
        })
        .collect();
    let file = json!({
        "version": 1,
        "settings": {
            "basis_order": s.basis_order, "quadrature_order": s.quadrature_order, "tolerance": s.tolerance,
            "visibility": s.visibility, "visibility_samples": s.visibility_samples, "threads": s.threads, "adaptive_quadrature": s.adaptive_quadrature, "corner_gather": s.corner_gather,
            "memory_budget_mb": s.memory_budget_mb,
        },
        "frames": [scene.frames.0, scene.frames.1],
        "materials": materials,
        "objects": objects,
    });
    serde_json::to_string_pretty(&file).expect("a scene serializes")
}
