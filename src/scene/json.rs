//! The version-1 scene file (README, "Scene JSON") and the result file the CLI writes.

use glam::{DMat4, DVec3};
use serde::{Deserialize, Serialize};

use super::{EmissionKey, Key, KeyTransform, Material, Object, Scene, Settings};
use crate::error::{Error, Result, invalid_scene};
use crate::lights::{AreaShape, Environment, Light, LightKey, LightKind, World, WorldKey};

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SceneFile {
    version: u32,
    settings: SettingsFile,
    frames: Option<[i64; 2]>,
    materials: Vec<MaterialFile>,
    objects: Vec<ObjectFile>,
    #[serde(default)]
    lights: Vec<LightFile>,
    world: Option<WorldFile>,
}

/// Blender's World (README of the add-on, "The World"; [`crate::lights::world`]).
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct WorldFile {
    color: Option<[f64; 3]>,
    strength: Option<f64>,
    image: Option<ImageFile>,
    #[serde(default)]
    animation: Vec<WorldKeyFile>,
}

/// An equirectangular image: `width x height` RGB triples, bottom row first.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ImageFile {
    width: usize,
    height: usize,
    pixels: Vec<[f32; 3]>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct WorldKeyFile {
    frame: f64,
    color: Option<[f64; 3]>,
    strength: Option<f64>,
}

fn parse_world(f: WorldFile) -> World {
    let mut world = World::uniform(f.color.unwrap_or([1.0; 3]), f.strength.unwrap_or(1.0));
    world.image = f
        .image
        .map(|i| std::sync::Arc::new(Environment { width: i.width, height: i.height, pixels: i.pixels }));
    world.animation = f
        .animation
        .into_iter()
        .map(|k| WorldKey { frame: k.frame, color: k.color, strength: k.strength })
        .collect();
    world
}

/// A Blender Light object (README of the add-on, "Lights"; [`crate::lights`]).
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct LightFile {
    name: Option<String>,
    #[serde(rename = "type")]
    kind: String,
    /// World-from-light, row-major; or `position` (and `direction`, default straight down).
    matrix: Option<[f64; 16]>,
    position: Option<[f64; 3]>,
    direction: Option<[f64; 3]>,
    /// Watts (point, spot, area).
    power: Option<f64>,
    /// W/m^2 (sun).
    strength: Option<f64>,
    color: Option<[f64; 3]>,
    radius: Option<f64>,
    /// Point and spot of radius > 0: a disk facing the receiver (true, Blender's default) or a
    /// sphere (false).
    soft_falloff: Option<bool>,
    spot_size: Option<f64>,
    spot_blend: Option<f64>,
    angle: Option<f64>,
    shape: Option<String>,
    size: Option<[f64; 2]>,
    #[serde(default)]
    animation: Vec<LightKeyFile>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct LightKeyFile {
    frame: f64,
    matrix: Option<[f64; 16]>,
    position: Option<[f64; 3]>,
    direction: Option<[f64; 3]>,
    power: Option<f64>,
    strength: Option<f64>,
    color: Option<[f64; 3]>,
    spot_size: Option<f64>,
    spot_blend: Option<f64>,
    radius: Option<f64>,
    soft_falloff: Option<bool>,
    angle: Option<f64>,
    size: Option<[f64; 2]>,
}

/// A light's world-from-light matrix from the file's `matrix`, or `position` and `direction`
/// (local -Z along it).
fn light_matrix(
    place: &str,
    matrix: Option<[f64; 16]>,
    position: Option<[f64; 3]>,
    direction: Option<[f64; 3]>,
) -> Result<Option<DMat4>> {
    if let Some(m) = matrix {
        if position.is_some() || direction.is_some() {
            return Err(invalid_scene!(
                "{place}: give \"matrix\" or \"position\" and \"direction\", not both"
            ));
        }
        return Ok(Some(matrix_from_row_major(&m)));
    }
    if position.is_none() && direction.is_none() {
        return Ok(None);
    }
    let d = DVec3::from_array(direction.unwrap_or([0.0, 0.0, -1.0]));
    if !(d.is_finite() && d.length() > 0.0) {
        return Err(invalid_scene!("{place}: direction {d:?} must be finite and non-zero"));
    }
    let z = -d.normalize();
    let helper = if z.x.abs() < 0.9 { DVec3::X } else { DVec3::Y };
    let x = helper.cross(z).normalize();
    let y = z.cross(x);
    let t = DVec3::from_array(position.unwrap_or([0.0; 3]));
    Ok(Some(DMat4::from_cols(x.extend(0.0), y.extend(0.0), z.extend(0.0), t.extend(1.0))))
}

fn parse_light(l: usize, f: LightFile) -> Result<Light> {
    let name = f.name.unwrap_or_else(|| format!("light {l}"));
    let place = format!("light \"{name}\"");
    let kind = LightKind::parse(&f.kind)
        .ok_or_else(|| invalid_scene!("{place}: type \"{}\" is not point, spot, sun or area", f.kind))?;
    let power = match (kind, f.power, f.strength) {
        (LightKind::Sun, None, Some(s)) | (LightKind::Sun, Some(s), None) => s,
        (LightKind::Sun, _, _) => return Err(invalid_scene!("{place}: a sun needs \"strength\" (W/m^2)")),
        (_, Some(p), None) => p,
        _ => return Err(invalid_scene!("{place}: a {} light needs \"power\" (W)", kind.name())),
    };
    let matrix = light_matrix(&place, f.matrix, f.position, f.direction)?.unwrap_or(DMat4::IDENTITY);
    let mut light = Light::new(&name, kind, matrix, power);
    if let Some(c) = f.color {
        light.base.color = c;
    }
    light.base.spot_size = f.spot_size.unwrap_or(light.base.spot_size);
    light.base.spot_blend = f.spot_blend.unwrap_or(light.base.spot_blend);
    light.base.radius = f.radius.unwrap_or(light.base.radius);
    light.base.soft_falloff = f.soft_falloff.unwrap_or(light.base.soft_falloff);
    light.base.angle = f.angle.unwrap_or(light.base.angle);
    if let Some(shape) = f.shape {
        light.shape = AreaShape::parse(&shape).ok_or_else(|| {
            invalid_scene!("{place}: shape \"{shape}\" is not square, rectangle, disk or ellipse")
        })?;
    }
    light.base.size = f.size.unwrap_or(light.base.size);
    for (k, key) in f.animation.into_iter().enumerate() {
        let kp = format!("{place} animation key {k}");
        light.animation.push(LightKey {
            frame: key.frame,
            matrix: light_matrix(&kp, key.matrix, key.position, key.direction)?,
            color: key.color,
            power: key.power.or(key.strength),
            spot_size: key.spot_size,
            spot_blend: key.spot_blend,
            radius: key.radius,
            soft_falloff: key.soft_falloff,
            angle: key.angle,
            size: key.size,
        });
    }
    Ok(light)
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
    reflecting_backs: Option<bool>,
    memory_budget_mb: Option<u64>,
    accuracy: Option<f64>,
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
    /// Its emitting faces emit from both sides ([`Scene::two_sided`]).
    #[serde(default)]
    two_sided: bool,
    /// Shading normal per face corner (smooth shading; `[0,0,0]`: the face's own), object space.
    #[serde(default)]
    corner_normals: Vec<[f64; 3]>,
    /// Reflectance per face, overriding the face's material's (a texture's mean over the face).
    #[serde(default)]
    face_reflectance: Vec<[f64; 3]>,
    /// Emission colour scale per face, multiplying the face's material's emission (an Emission
    /// Color texture's mean over the face).
    #[serde(default)]
    face_emission: Vec<[f64; 3]>,
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
        reflecting_backs: s.reflecting_backs.unwrap_or(d.reflecting_backs),
        memory_budget_mb: s.memory_budget_mb.unwrap_or(d.memory_budget_mb),
        accuracy: s.accuracy.unwrap_or(d.accuracy),
        preview_lights: false,
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
    let mut two_sided = Vec::new();
    let mut surfaces = Vec::new();
    for (o, obj) in file.objects.into_iter().enumerate() {
        if obj.two_sided {
            two_sided.push(o);
        }
        surfaces.push(super::Surface {
            corner_normals: obj.corner_normals.iter().map(|n| DVec3::from_array(*n)).collect(),
            face_reflectance: obj.face_reflectance.clone(),
            face_emission: obj.face_emission.clone(),
        });
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
    let lights =
        file.lights.into_iter().enumerate().map(|(l, f)| parse_light(l, f)).collect::<Result<_>>()?;
    Scene::new(settings, frames, materials, emission_keys, objects)?
        .with_lights(lights)?
        .with_world(file.world.map(parse_world))?
        .with_two_sided(&two_sided)?
        .with_surfaces(surfaces)
}

/// Reads and parses a scene file.
pub fn read_scene(path: &std::path::Path) -> Result<Scene> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::Input(format!("{}: {e}", path.display())))?;
    parse_scene(&text)
}

/// One object's radiosity at one frame, as written to the result file.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct ObjectResult {
    pub name: String,
    /// Area-mean radiosity per face (W/m^2, RGB).
    pub face_radiosity: Vec<[f32; 3]>,
    /// Radiosity at each face corner, faces in order, corners in face order.
    pub corner_radiosity: Vec<[f32; 3]>,
    /// The irradiance `H` (W/m^2, RGB) at the same corners: the light the surface receives,
    /// `B = E + rho H`, so that a material's own reflectance times `H` is the reflected part of
    /// `B`. Gathered with the corners; from the face polynomials (corner gather off, the
    /// hierarchy) it is `(B - E) / rho` per channel, 0 where `rho` is below [`MIN_REFLECTANCE`].
    #[serde(default)]
    pub corner_irradiance: Vec<[f32; 3]>,
}

/// Below this reflectance a channel's irradiance is not derived from `B` (`(B - E) / rho`
/// would amplify rounding): it reads 0.
pub const MIN_REFLECTANCE: f64 = 1e-4;

/// `(B - E) / rho` per channel, 0 where `rho` is below [`MIN_REFLECTANCE`]: the irradiance of
/// a point whose radiosity came from a polynomial rather than the gather.
pub fn irradiance_from_radiosity(b: [f64; 3], e: [f64; 3], rho: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|c| if rho[c] < MIN_REFLECTANCE { 0.0 } else { (b[c] - e[c]) / rho[c] })
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

/// An object's `corner_normals`, `face_reflectance` and `face_emission`, where it has them.
fn surface_to_json(object: &mut serde_json::Value, surface: Option<&super::Surface>) {
    let Some(s) = surface else { return };
    if !s.corner_normals.is_empty() {
        object["corner_normals"] =
            serde_json::json!(s.corner_normals.iter().map(|n| n.to_array()).collect::<Vec<_>>());
    }
    if !s.face_reflectance.is_empty() {
        object["face_reflectance"] = serde_json::json!(s.face_reflectance);
    }
    if !s.face_emission.is_empty() {
        object["face_emission"] = serde_json::json!(s.face_emission);
    }
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
        .enumerate()
        .map(|(i, o)| {
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
            let mut object = json!({
                "name": o.name,
                "vertices": o.vertices.iter().map(|v| v.to_array()).collect::<Vec<_>>(),
                "faces": o.faces,
                "face_materials": o.face_materials,
                "matrix": row_major(&o.matrix),
                "animation": animation,
                "two_sided": scene.two_sided.get(i).copied().unwrap_or(false),
            });
            surface_to_json(&mut object, scene.surfaces.get(i));
            object
        })
        .collect();
    let lights: Vec<_> = scene
        .lights
        .iter()
        .map(|l| {
            let animation: Vec<_> = l
                .animation
                .iter()
                .map(|k| {
                    let mut key = json!({"frame": k.frame});
                    if let Some(m) = &k.matrix {
                        key["matrix"] = json!(row_major(m));
                    }
                    if let Some(c) = k.color {
                        key["color"] = json!(c);
                    }
                    // Only the fields the key sets: a field left out keeps the light's own.
                    let numbers = [
                        ("power", k.power),
                        ("spot_size", k.spot_size),
                        ("spot_blend", k.spot_blend),
                        ("radius", k.radius),
                        ("angle", k.angle),
                    ];
                    for (field, v) in numbers {
                        if let Some(v) = v {
                            key[field] = json!(v);
                        }
                    }
                    if let Some(v) = k.soft_falloff {
                        key["soft_falloff"] = json!(v);
                    }
                    if let Some(v) = k.size {
                        key["size"] = json!(v);
                    }
                    key
                })
                .collect();
            let b = &l.base;
            let mut light = json!({
                "name": l.name, "type": l.kind.name(), "matrix": row_major(&b.matrix), "color": b.color,
                "radius": b.radius, "soft_falloff": b.soft_falloff, "spot_size": b.spot_size, "spot_blend": b.spot_blend, "angle": b.angle,
                "shape": l.shape.name(), "size": b.size, "animation": animation,
            });
            light[if l.kind == LightKind::Sun { "strength" } else { "power" }] = json!(b.power);
            light
        })
        .collect();
    let mut file = json!({
        "version": 1,
        "settings": {
            "basis_order": s.basis_order, "quadrature_order": s.quadrature_order, "tolerance": s.tolerance,
            "visibility": s.visibility, "visibility_samples": s.visibility_samples, "threads": s.threads, "adaptive_quadrature": s.adaptive_quadrature, "corner_gather": s.corner_gather, "reflecting_backs": s.reflecting_backs, "accuracy": s.accuracy,
            "memory_budget_mb": s.memory_budget_mb,
        },
        "frames": [scene.frames.0, scene.frames.1],
        "materials": materials,
        "objects": objects,
        "lights": lights,
    });
    if let Some(w) = &scene.world {
        let animation: Vec<_> = w
            .animation
            .iter()
            .map(|k| {
                let mut key = json!({"frame": k.frame});
                if let Some(c) = k.color {
                    key["color"] = json!(c);
                }
                if let Some(s) = k.strength {
                    key["strength"] = json!(s);
                }
                key
            })
            .collect();
        let mut world = json!({"color": w.color, "strength": w.strength, "animation": animation});
        if let Some(i) = &w.image {
            world["image"] = json!({"width": i.width, "height": i.height, "pixels": i.pixels});
        }
        file["world"] = world;
    }
    serde_json::to_string_pretty(&file).expect("a scene serializes")
}
