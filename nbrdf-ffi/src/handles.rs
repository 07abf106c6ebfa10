//! What the two handles hold, and how each is made: an `NbrdfMaterial` (a network, a spatially
//! varying material or a table, told apart on load) and an `NbrdfSampler` (a strategy validated from `NbrdfSamplerParams`,
//! tabulated from a material for `NBRDF_SAMPLING_TABULATED`). The exported functions of each
//! are in [`crate::material`] and [`crate::sampler`], which build on this module and not on
//! each other.

use crate::vocabulary::{unknown_kind, NbrdfSamplingKind};
use nbrdf_core::brdf::Brdf;
use nbrdf_core::error::regular_file_size;
use nbrdf_core::merl::{N_PHI_D, N_THETA_D, N_THETA_H};
use nbrdf_core::network::{ActiveUnits, Spectral};
use nbrdf_core::sampling::tabulated::TableConfig;
use nbrdf_core::sampling::{SamplingStrategy, TabulatedSampler};
use nbrdf_core::textured::{NeuralMaterial, TexturedNbrdf};
use nbrdf_core::{MerlTable, Nbrdf, NbrdfError};
use nbrdf_ffi_common::{Failure, FailureKind, FfiResult};
use std::ffi::{CStr, CString};
use std::io::Read;
use std::path::Path;
use std::sync::{Arc, OnceLock};

/// A material: a neural BRDF or a spatially varying neural material (`*.nbrdf.json`, the latter
/// with its latent texture) or a MERL-format table (`.binary`), loaded by `nbrdf_material_load`.
/// Immutable: one handle may be used by many threads at once.
pub struct NbrdfMaterial {
    source: Source,
    /// The material's name (empty for a table), for `NbrdfMaterialInfo::name`.
    name: CString,
    /// A network's `base` as JSON text, for `nbrdf_material_base`.
    base: Option<CString>,
}

enum Source {
    Network(Box<LoadedNetwork>),
    Merl(MerlTable),
    Textured(Box<TexturedNbrdf>),
}

/// How the functions taking texture coordinates see a material: a textured one reads its
/// texture at each hit; a homogeneous one is the same at every hit and samples the lobes its
/// file stores (cosine without, and for a table).
pub(crate) enum AtHits<'a> {
    Textured(&'a TexturedNbrdf),
    Everywhere {
        brdf: &'a dyn Brdf,
        sampling: SamplingStrategy,
    },
}

/// A network as the file stores it and, made on first use, the proof of which hidden units can
/// fire and the network without the others (what eval, sample and tables evaluate). Lazy
/// because the proof is most of a load's time (tens of milliseconds) and an evaluator that
/// keeps every unit (the plugin's kernel shared by many materials) never asks for it.
pub(crate) struct LoadedNetwork {
    pub(crate) network: Nbrdf,
    proved: OnceLock<Proved>,
}

pub(crate) struct Proved {
    pub(crate) active: ActiveUnits,
    pub(crate) renderer: Nbrdf,
}

impl LoadedNetwork {
    pub(crate) fn proved(&self) -> &Proved {
        self.proved.get_or_init(|| {
            let active = self.network.active_units();
            let renderer = self.network.with_units(&active);
            Proved { active, renderer }
        })
    }
}

/// Whether the file at `path` starts with a MERL table's header (resolutions 90, 90, 180 as
/// little-endian int32), the rule that tells tables from networks. Files that cannot be
/// inspected (missing, special, unreadable) are not: the network reader reports them.
fn starts_like_merl(path: &Path) -> bool {
    if regular_file_size(path, u64::MAX, "a material").is_err() {
        return false; // before opening: a FIFO would block
    }
    let header: Vec<u8> = [N_THETA_H, N_THETA_D, N_PHI_D]
        .iter()
        .flat_map(|&n| (n as i32).to_le_bytes())
        .collect();
    let mut head = Vec::with_capacity(header.len());
    std::fs::File::open(path)
        .and_then(|file| file.take(header.len() as u64).read_to_end(&mut head))
        .is_ok_and(|_| head == header)
}

impl NbrdfMaterial {
    pub(crate) fn load(path: &Path) -> Result<Self, NbrdfError> {
        if starts_like_merl(path) {
            return Ok(NbrdfMaterial {
                source: Source::Merl(MerlTable::read(path)?),
                name: CString::default(),
                base: None,
            });
        }
        let c_name = |name: &str| CString::new(name.replace('\0', "")).unwrap_or_default();
        Ok(match NeuralMaterial::load(path)? {
            NeuralMaterial::Homogeneous(network) => NbrdfMaterial {
                name: c_name(&network.name),
                base: network.base.as_ref().map(|base| c_name(&base.to_string())),
                source: Source::Network(Box::new(LoadedNetwork {
                    network,
                    proved: OnceLock::new(),
                })),
            },
            NeuralMaterial::Textured(textured) => NbrdfMaterial {
                name: c_name(textured.name()),
                base: None,
                source: Source::Textured(Box::new(textured)),
            },
        })
    }

    /// What eval, sample and the tabulated sampler evaluate; an error for a textured material,
    /// which has no value without texture coordinates.
    pub(crate) fn brdf(&self) -> FfiResult<&dyn Brdf> {
        match &self.source {
            Source::Network(loaded) => Ok(&loaded.proved().renderer),
            Source::Merl(table) => Ok(table),
            Source::Textured(_) => Err(Failure::invalid(
                "the material is spatially varying (file format version 4): evaluate and \
                 sample it at texture coordinates with nbrdf_material_eval_uv and \
                 nbrdf_material_sample_uv",
            )),
        }
    }

    /// What `nbrdf_material_eval_uv` and `nbrdf_material_sample_uv` evaluate and sample.
    pub(crate) fn at_hits(&self) -> AtHits<'_> {
        match &self.source {
            Source::Textured(textured) => AtHits::Textured(textured),
            Source::Network(loaded) => AtHits::Everywhere {
                brdf: &loaded.proved().renderer,
                sampling: loaded
                    .network
                    .sampling_strategy()
                    .unwrap_or(SamplingStrategy::Cosine),
            },
            Source::Merl(table) => AtHits::Everywhere {
                brdf: table,
                sampling: SamplingStrategy::Cosine,
            },
        }
    }

    /// How to tabulate the material for `NBRDF_SAMPLING_TABULATED`: with the cosine weight a
    /// network file stores (`nbrdf fit-phong`), if any.
    pub(crate) fn table_config(&self) -> TableConfig {
        match &self.source {
            Source::Network(loaded) => loaded.network.table_config(),
            Source::Merl(_) | Source::Textured(_) => TableConfig::default(),
        }
    }

    /// The material's name (empty for a table), NUL-terminated.
    pub(crate) fn name(&self) -> &CStr {
        &self.name
    }

    /// A network's `base` (JSON text, NUL-terminated), if its file has one.
    pub(crate) fn base(&self) -> Option<&CStr> {
        self.base.as_deref()
    }

    /// The network, or `None` for a table or a textured material.
    pub(crate) fn network(&self) -> Option<&LoadedNetwork> {
        match &self.source {
            Source::Network(loaded) => Some(loaded),
            Source::Merl(_) | Source::Textured(_) => None,
        }
    }

    /// The spatially varying material, or `None` for the other kinds.
    pub(crate) fn textured(&self) -> Option<&TexturedNbrdf> {
        match &self.source {
            Source::Textured(textured) => Some(textured),
            Source::Network(_) | Source::Merl(_) => None,
        }
    }

    /// The spectral basis whose coefficients a spectral network or textured material outputs,
    /// `None` for RGB materials and tables.
    pub(crate) fn spectral(&self) -> Option<&Spectral> {
        match &self.source {
            Source::Network(loaded) => loaded.network.spectral.as_ref(),
            Source::Textured(textured) => textured.decoder().spectral(),
            Source::Merl(_) => None,
        }
    }

    /// The network, or an error naming what the material is instead.
    pub(crate) fn loaded_network(&self) -> FfiResult<&LoadedNetwork> {
        match &self.source {
            Source::Network(loaded) => Ok(loaded),
            Source::Merl(_) => Err(Failure::invalid(
                "the material is a MERL table, not a network",
            )),
            Source::Textured(_) => Err(Failure::invalid(
                "the material is spatially varying (file format version 4), not a homogeneous \
                 network",
            )),
        }
    }
}

/// The parameters of an importance-sampling strategy (`nbrdf_sampler_create`). Each kind reads
/// only its own fields: `NBRDF_SAMPLING_PHONG` `exponent` and `specular_weight`;
/// `NBRDF_SAMPLING_TWO_LOBE` those and `exponent2`, `specular_weight2`
/// (`specular_weight + specular_weight2 <= 1`); `NBRDF_SAMPLING_ANISOTROPIC_PHONG` `exponent`
/// (`n_u`), `exponent_v` (`n_v`) and `specular_weight`; the others none. Exponents are finite in
/// [0, 1e6] (`MAX_EXPONENT`), weights in [0, 1].
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NbrdfSamplerParams {
    /// An `NbrdfSamplingKind` value.
    pub kind: i32,
    pub exponent: f32,
    pub specular_weight: f32,
    pub exponent2: f32,
    pub specular_weight2: f32,
    pub exponent_v: f32,
}

impl NbrdfSamplerParams {
    /// Cosine sampling, every parameter zero.
    pub fn cosine() -> Self {
        NbrdfSamplerParams {
            kind: NbrdfSamplingKind::NBRDF_SAMPLING_COSINE as i32,
            exponent: 0.0,
            specular_weight: 0.0,
            exponent2: 0.0,
            specular_weight2: 0.0,
            exponent_v: 0.0,
        }
    }

    /// The strategy the parameters describe, validated by the core; `material` is tabulated
    /// for `NBRDF_SAMPLING_TABULATED` (and read by no other kind).
    fn strategy(&self, material: Option<&NbrdfMaterial>) -> FfiResult<SamplingStrategy> {
        let kind =
            NbrdfSamplingKind::from_code(self.kind).ok_or_else(|| unknown_kind(self.kind))?;
        let f = f64::from;
        let strategy = match kind {
            NbrdfSamplingKind::NBRDF_SAMPLING_UNIFORM => SamplingStrategy::Uniform,
            NbrdfSamplingKind::NBRDF_SAMPLING_COSINE => SamplingStrategy::Cosine,
            NbrdfSamplingKind::NBRDF_SAMPLING_PHONG => SamplingStrategy::Phong {
                exponent: f(self.exponent),
                specular_weight: f(self.specular_weight),
            },
            NbrdfSamplingKind::NBRDF_SAMPLING_TWO_LOBE => SamplingStrategy::TwoLobe {
                exponent1: f(self.exponent),
                weight1: f(self.specular_weight),
                exponent2: f(self.exponent2),
                weight2: f(self.specular_weight2),
            },
            NbrdfSamplingKind::NBRDF_SAMPLING_ANISOTROPIC_PHONG => SamplingStrategy::anisotropic(
                f(self.exponent),
                f(self.exponent_v),
                f(self.specular_weight),
            ),
            NbrdfSamplingKind::NBRDF_SAMPLING_TABULATED => {
                let material = material.ok_or_else(|| Failure {
                    kind: FailureKind::NullPointer,
                    message: "argument `material` is a null pointer (a tabulated sampler is \
                              tabulated from its material)"
                        .into(),
                })?;
                let table =
                    TabulatedSampler::from_brdf(material.brdf()?, &material.table_config())?;
                SamplingStrategy::Tabulated(Arc::new(table))
            }
        };
        Ok(strategy.validated()?)
    }
}

/// An importance sampler (`nbrdf_sampler_create`): for `nbrdf_material_sample` with any
/// material, and `nbrdf_sampler_pdf`. Immutable: one handle may be used by many threads at once.
pub struct NbrdfSampler {
    strategy: SamplingStrategy,
}

impl NbrdfSampler {
    /// The sampler `params` describe (see [`NbrdfSamplerParams`]); `material` is read only by
    /// `NBRDF_SAMPLING_TABULATED`.
    pub(crate) fn new(
        params: &NbrdfSamplerParams,
        material: Option<&NbrdfMaterial>,
    ) -> FfiResult<Self> {
        Ok(NbrdfSampler {
            strategy: params.strategy(material)?,
        })
    }

    pub(crate) fn strategy(&self) -> &SamplingStrategy {
        &self.strategy
    }
}
