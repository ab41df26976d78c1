//! `GrSettings` and `GrMethod`: the solver settings as a C struct.

use super::error::{Failure, GrStatus};
use super::panic::boundary;
use crate::scene::Settings;
use crate::session::Method;

/// How each frame after the first is computed.
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum GrMethod {
    /// The incremental update: series for translated links, exact recompute at discontinuities,
    /// progressive shooting of the differences.
    Incremental = 0,
    /// Incremental, but every changed link recomputed by quadrature.
    Exact = 1,
    /// Every frame from scratch.
    Full = 2,
    /// The hierarchy of clusters and elements below faces, for scenes of 10^4 faces and more;
    /// `accuracy` is its knob. A frame after the first is updated from the one before (the
    /// links a move touched linked again, the solve warm-started); corners are gathered with
    /// `corner_gather`, else read from the leaves' polynomials.
    Hierarchical = 3,
}

/// Solver settings. Fill with `gr_settings_default`, then change what you need.
///
/// The struct grows at its end only: a library that adds fields reads those past
/// `struct_size` as their defaults, so a host built against an older header keeps working
/// (ABI version 2 on). A `struct_size` larger than the library's `GrSettings` (a host built
/// against a newer header) or smaller than version 2's is `GR_STATUS_INVALID_ARGUMENT`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GrSettings {
    /// `sizeof(GrSettings)` of the header the host was built with; set by `gr_settings_default`.
    pub struct_size: u32,
    /// Legendre degree per axis, 0..=3 (0: classic constant radiosity). Default 2.
    pub basis_order: u32,
    /// Gauss-Legendre points per axis for a well-separated pair of patches, 1..=16, more than
    /// `basis_order` (fewer cannot integrate the basis products). Default 4.
    pub quadrature_order: u32,
    /// 1: ray-cast visibility; 0: everything sees everything. Other values are invalid.
    /// Default 1.
    pub visibility: u32,
    /// Visibility samples per axis of each patch, 1..=4 (rays per link = this^4). Default 2.
    pub visibility_samples: u32,
    /// Worker threads, at most 1024; 0 means one per core. Default 0.
    pub threads: u32,
    /// How frames after the first are computed. Default `GR_METHOD_INCREMENTAL`.
    pub method: GrMethod,
    /// 1: face corners report radiosity gathered at the corner with its own shadow rays (sharp
    /// contact shadows, corners hidden under objects go dark; costs about one kernel build per
    /// frame); 0: the face polynomial at the corner. Other values are invalid. Default 1.
    pub corner_gather: u32,
    /// Progressive refinement stops when the unshot coefficients would deliver less than this
    /// fraction of the emitted power in one bounce, in (0,1). Default 1e-4.
    pub tolerance: f64,
    /// The memory a session may plan to use, in MiB: a scene whose estimate is over it is
    /// refused by `gr_session_new` and `gr_scene_builder_build` with `GR_STATUS_INVALID_SCENE`
    /// ("over the memory budget"),
    /// at once. 0: 80% of the memory available (`MemAvailable`) when the session is made.
    /// Default 0.
    pub memory_budget_mb: u64,
    /// `GR_METHOD_HIERARCHICAL`'s accuracy: the largest share of the emitted power a link may
    /// carry unrefined, in (0,1); smaller is finer and slower. Default 1e-3. (Since ABI
    /// version 3: read only when `struct_size` covers it.)
    pub accuracy: f64,
    /// 1: open surfaces (a sheet, a ground plane, a mesh with holes) reflect light from both
    /// sides, as Blender's diffuse surfaces do; 0: only from their front (the side their
    /// normal faces). Closed meshes are the same either way. Other values are invalid.
    /// Default 0. (Read only when `struct_size` covers it.)
    pub reflecting_backs: u32,
}

impl GrSettings {
    /// The library's defaults.
    pub fn new() -> Self {
        let d = Settings::default();
        Self {
            struct_size: size_of::<GrSettings>() as u32,
            basis_order: d.basis_order as u32,
            quadrature_order: d.quadrature_order as u32,
            tolerance: d.tolerance,
            visibility: u32::from(d.visibility),
            visibility_samples: d.visibility_samples as u32,
            threads: d.threads as u32,
            method: GrMethod::Incremental,
            corner_gather: u32::from(d.corner_gather),
            memory_budget_mb: d.memory_budget_mb,
            accuracy: d.accuracy,
            reflecting_backs: u32::from(d.reflecting_backs),
        }
    }
}

impl Default for GrSettings {
    fn default() -> Self {
        Self::new()
    }
}

/// `sizeof(GrSettings)` of ABI version 2, the first with `struct_size`: every field since is
/// read only when `struct_size` covers it (`accuracy`, version 3; `reflecting_backs`).
const SETTINGS_V2_SIZE: usize = 48;
const _: () = assert!(std::mem::offset_of!(GrSettings, accuracy) == SETTINGS_V2_SIZE);

/// Reads settings written by C, where `method` and `visibility` may hold any 32-bit value.
/// Range checks of the numbers are the scene's (`GR_STATUS_INVALID_SCENE`).
///
/// # Safety
/// `p` is NULL or points to a readable `GrSettings`.
pub(crate) unsafe fn read_settings(p: *const GrSettings) -> Result<(Settings, Method), Failure> {
    if p.is_null() {
        return Err(Failure::null("settings"));
    }
    if !p.is_aligned() {
        return Err(Failure::invalid("settings is not aligned for GrSettings"));
    }
    // SAFETY: p is non-null, aligned and readable: its first field is there in every version.
    let size = unsafe { (&raw const (*p).struct_size).read() };
    super::sized::check("settings", size, SETTINGS_V2_SIZE, size_of::<GrSettings>(), "gr_settings_default")?;
    // SAFETY: p is non-null, aligned and readable. `method` is read as the u32 it is in C, never
    // as a `GrMethod`, so an unknown value is not undefined behaviour.
    let (
        basis_order,
        quadrature_order,
        tolerance,
        visibility,
        visibility_samples,
        threads,
        method,
        gather,
        budget,
    ) = unsafe {
        (
            (&raw const (*p).basis_order).read(),
            (&raw const (*p).quadrature_order).read(),
            (&raw const (*p).tolerance).read(),
            (&raw const (*p).visibility).read(),
            (&raw const (*p).visibility_samples).read(),
            (&raw const (*p).threads).read(),
            (&raw const (*p).method).cast::<u32>().read(),
            (&raw const (*p).corner_gather).read(),
            (&raw const (*p).memory_budget_mb).read(),
        )
    };
    // SAFETY: as above; `accuracy` lies inside the caller's struct when `size` covers it.
    let accuracy = if size as usize >= std::mem::offset_of!(GrSettings, accuracy) + size_of::<f64>() {
        unsafe { (&raw const (*p).accuracy).read() }
    } else {
        Settings::default().accuracy
    };
    // SAFETY: as above, for `reflecting_backs`.
    let backs = if size as usize >= std::mem::offset_of!(GrSettings, reflecting_backs) + size_of::<u32>() {
        unsafe { (&raw const (*p).reflecting_backs).read() }
    } else {
        u32::from(Settings::default().reflecting_backs)
    };
    let method = match method {
        0 => Method::Incremental,
        1 => Method::Exact,
        2 => Method::Full,
        3 => Method::Hierarchical,
        m => {
            return Err(Failure::invalid(format!("settings.method {m} is not a GrMethod (0 to 3)")));
        }
    };
    let visibility = match visibility {
        0 => false,
        1 => true,
        v => {
            return Err(Failure::invalid(format!("settings.visibility {v} is neither 0 nor 1")));
        }
    };
    let corner_gather = match gather {
        0 => false,
        1 => true,
        v => {
            return Err(Failure::invalid(format!("settings.corner_gather {v} is neither 0 nor 1")));
        }
    };
    let reflecting_backs = match backs {
        0 => false,
        1 => true,
        v => {
            return Err(Failure::invalid(format!("settings.reflecting_backs {v} is neither 0 nor 1")));
        }
    };
    let settings = Settings {
        basis_order: basis_order as usize,
        quadrature_order: quadrature_order as usize,
        tolerance,
        visibility,
        visibility_samples: visibility_samples as usize,
        threads: threads as usize,
        corner_gather,
        memory_budget_mb: budget,
        accuracy,
        reflecting_backs,
        // Settings the C struct does not carry keep the library's defaults.
        ..Settings::default()
    };
    Ok((settings, method))
}

/// Writes the library's default settings to `*out` (`GR_METHOD_INCREMENTAL`).
///
/// # Safety
/// `out` is NULL or points to a writable `GrSettings`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn gr_settings_default(out: *mut GrSettings) -> GrStatus {
    boundary("gr_settings_default", || {
        if out.is_null() {
            return Err(Failure::null("out"));
        }
        if !out.is_aligned() {
            return Err(Failure::invalid("out is not aligned for GrSettings"));
        }
        // SAFETY: out is non-null, aligned and writable.
        unsafe { out.write(GrSettings::new()) };
        Ok(())
    })
}
