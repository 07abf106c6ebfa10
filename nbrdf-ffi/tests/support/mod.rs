//! What the C ABI tests share: status codes, the last error, scratch files, a small network and a
//! smooth MERL table loaded through the C ABI as materials, samplers, planar arrays.

// Each test crate uses a part of this module.
#![allow(dead_code)]

use glam::Vec3;
use nbrdf_core::MerlTable;
use nbrdf_ffi::*;
use std::ffi::{CStr, CString};
use std::path::{Path, PathBuf};
use std::ptr::null_mut;

pub const OK: i32 = NbrdfStatus::NBRDF_OK as i32;
pub const NULL: i32 = NbrdfStatus::NBRDF_ERROR_NULL_POINTER as i32;
pub const INVALID: i32 = NbrdfStatus::NBRDF_ERROR_INVALID_ARGUMENT as i32;
pub const IO: i32 = NbrdfStatus::NBRDF_ERROR_IO as i32;
pub const FORMAT: i32 = NbrdfStatus::NBRDF_ERROR_FORMAT as i32;

pub fn last_error() -> String {
    // SAFETY: the library returns a valid NUL-terminated string.
    unsafe { CStr::from_ptr(nbrdf_last_error()) }
        .to_string_lossy()
        .into_owned()
}

/// A scratch directory unique to this call: tests run in parallel threads, and two of them
/// writing the same file let one read it half written.
pub fn scratch(name: &str) -> PathBuf {
    static CALLS: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let call = CALLS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let dir = std::env::temp_dir().join(format!(
        "nbrdf-ffi-test-{}-{name}-{call}",
        std::process::id()
    ));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

pub fn c_path(path: &Path) -> CString {
    CString::new(path.to_str().unwrap()).unwrap()
}

/// A small deterministic network of hidden width `hidden` with Blinn-Phong parameters, as JSON
/// text.
pub fn network_json(hidden: usize) -> String {
    let mut state = 12345_u32;
    let mut next = move || {
        state = state.wrapping_mul(1_103_515_245).wrapping_add(12345);
        ((state >> 8) as f32 / (1u32 << 24) as f32 - 0.5) * 0.8
    };
    let layer = |inputs: usize, outputs: usize, next: &mut dyn FnMut() -> f32| {
        let weights: Vec<String> = (0..inputs * outputs).map(|_| next().to_string()).collect();
        let bias: Vec<String> = (0..outputs).map(|_| next().to_string()).collect();
        format!(
            r#"{{"inputs": {inputs}, "outputs": {outputs}, "weights": [{}], "bias": [{}]}}"#,
            weights.join(", "),
            bias.join(", ")
        )
    };
    let layers = [
        layer(6, hidden, &mut next),
        layer(hidden, hidden, &mut next),
        layer(hidden, 3, &mut next),
    ];
    format!(
        r#"{{"format": "nbrdf", "version": 1, "name": "ffi-test", "layers": [{}],
            "sampling": {{"model": "blinn-phong", "exponent": 40.0, "specular_weight": 0.25, "source": "manual"}},
            "provenance": {{"source": "nbrdf-ffi tests"}}}}"#,
        layers.join(", ")
    )
}

/// A material handle, freed on drop.
pub struct Material(pub *mut NbrdfMaterial);

impl Drop for Material {
    fn drop(&mut self) {
        // SAFETY: the handle came from nbrdf_material_load.
        unsafe { nbrdf_material_free(self.0) }
    }
}

// SAFETY: the C contract: a material is immutable, so one handle may be used by many threads.
unsafe impl Sync for Material {}

impl Material {
    pub fn ptr(&self) -> *const NbrdfMaterial {
        self.0
    }

    pub fn info(&self) -> NbrdfMaterialInfo {
        let mut info = std::mem::MaybeUninit::uninit();
        // SAFETY: a live handle and a writable info; initialised by a successful call.
        unsafe {
            assert_eq!(
                nbrdf_material_info(self.0, info.as_mut_ptr()),
                OK,
                "{}",
                last_error()
            );
            info.assume_init()
        }
    }
}

/// Loads `path` through the C ABI.
pub fn load_material(path: &Path) -> Material {
    let mut handle = null_mut();
    // SAFETY: valid path and out pointer.
    let status = unsafe { nbrdf_material_load(c_path(path).as_ptr(), &mut handle) };
    assert_eq!(status, OK, "{}", last_error());
    assert!(!handle.is_null());
    Material(handle)
}

/// Loads the JSON text `json` through the C ABI; returns the handle and the file.
pub fn load_network_text(json: &str, name: &str) -> (Material, PathBuf) {
    let path = scratch(name).join("test.nbrdf.json");
    std::fs::write(&path, json).unwrap();
    (load_material(&path), path)
}

pub fn load_network(hidden: usize) -> (Material, PathBuf) {
    load_network_text(&network_json(hidden), &format!("net{hidden}"))
}

/// A smooth table (the value grows along each axis, with one unmeasured region), written to a
/// scratch file and loaded through the C ABI; also returned as the core's table.
pub fn load_smooth_merl() -> (Material, MerlTable) {
    let cells = nbrdf_core::merl::CELLS;
    let mut stored = vec![0.0_f64; 3 * cells];
    for (i, value) in stored.iter_mut().enumerate() {
        let (c, cell) = (i / cells, i % cells);
        *value = 100.0
            + (cell % 180) as f64 * 0.5
            + ((cell / 180) % 90) as f64
            + (cell / 16200) as f64 * 3.0
            + c as f64;
    }
    stored[..180].iter_mut().for_each(|v| *v = -1.0);
    let table = MerlTable::from_stored(stored).unwrap();
    let path = scratch("merl").join("smooth.binary");
    table.write(&path).unwrap();
    let handle = load_material(&path);
    std::fs::remove_file(&path).unwrap();
    (handle, table)
}

/// A sampler handle, freed on drop.
pub struct Sampler(pub *mut NbrdfSampler);

impl Drop for Sampler {
    fn drop(&mut self) {
        // SAFETY: the handle came from nbrdf_sampler_create.
        unsafe { nbrdf_sampler_free(self.0) }
    }
}

// SAFETY: the C contract: a sampler is immutable, so one handle may be used by many threads.
unsafe impl Sync for Sampler {}

impl Sampler {
    pub fn ptr(&self) -> *const NbrdfSampler {
        self.0
    }
}

/// Sampler parameters of `kind`, every parameter zero.
pub fn params(kind: NbrdfSamplingKind) -> NbrdfSamplerParams {
    NbrdfSamplerParams {
        kind: kind as i32,
        ..NbrdfSamplerParams::cosine()
    }
}

/// Phong sampler parameters.
pub fn phong(exponent: f32, specular_weight: f32) -> NbrdfSamplerParams {
    NbrdfSamplerParams {
        exponent,
        specular_weight,
        ..params(NbrdfSamplingKind::NBRDF_SAMPLING_PHONG)
    }
}

/// `nbrdf_sampler_create` of `params` for `material` (may be null): the status and the handle
/// (null on failure).
pub fn try_sampler(material: *const NbrdfMaterial, params: &NbrdfSamplerParams) -> (i32, Sampler) {
    let mut handle = 1 as *mut NbrdfSampler; // must be overwritten
                                             // SAFETY: valid pointers.
    let status = unsafe { nbrdf_sampler_create(material, params, &mut handle) };
    if status != OK {
        assert!(handle.is_null(), "a failed create left a handle");
    }
    (status, Sampler(handle))
}

/// A sampler that must be accepted.
pub fn sampler(material: *const NbrdfMaterial, params: &NbrdfSamplerParams) -> Sampler {
    let (status, sampler) = try_sampler(material, params);
    assert_eq!(status, OK, "{params:?}: {}", last_error());
    sampler
}

pub fn planar(vectors: impl Iterator<Item = Vec3> + Clone) -> Vec<f32> {
    let xs = vectors.clone().map(|v| v.x);
    let ys = vectors.clone().map(|v| v.y);
    let zs = vectors.map(|v| v.z);
    xs.chain(ys).chain(zs).collect()
}

/// Lane `i` of a planar array of `n` vectors.
pub fn lane(planar: &[f32], n: usize, i: usize) -> Vec3 {
    Vec3::new(planar[i], planar[n + i], planar[2 * n + i])
}

pub fn assert_close(a: f32, b: f32, what: &str) {
    assert!((a - b).abs() <= 1e-6 + 1e-5 * b.abs(), "{what}: {a} vs {b}");
}
