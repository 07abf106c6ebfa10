//! Published analytic fits of the 100 MERL materials (DESIGN.md section 8), used to synthesise
//! MERL-format tables where the MERL database itself cannot be redistributed.
//!
//! * SGD: Bagher, Soler, Holzschuch, "Accurate fitting of measured reflectances using a Shifted
//!   Gamma micro-facet distribution", Computer Graphics Forum 31(4), 2012.
//! * ABC: Löw, Kronander, Ynnerman, Unger, "BRDF models for accurate and efficient rendering of
//!   glossy surfaces", ACM Transactions on Graphics 31(1), 2012.
//!
//! The fit figures are embedded from `nbrdf-core/data/` (as tabulated in J. Dupuy's public-domain
//! dj_brdf toolkit).

pub mod abc;
pub mod catalogue;
pub mod sgd;

use crate::brdf::Brdf;
use crate::error::Result;
use crate::merl::MerlTable;

pub use abc::AbcParams;
pub use sgd::SgdParams;

/// Which published model to use.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ModelKind {
    Sgd,
    Abc,
}

/// An analytic BRDF fit of one material.
#[derive(Clone, Debug)]
pub enum AnalyticBrdf {
    Sgd(SgdParams),
    Abc(AbcParams),
}

impl AnalyticBrdf {
    /// The fit of `material` under `model` from the embedded catalogue.
    pub fn from_catalogue(model: ModelKind, material: &str) -> Result<Self> {
        todo!()
    }

    /// `f_r(light, view)` in float64, zero at or below the horizon.
    pub fn eval_f64(&self, light: glam::DVec3, view: glam::DVec3) -> [f64; 3] {
        todo!()
    }

    /// The MERL-format table of this fit at cell-centre angles.
    pub fn tabulate(&self) -> MerlTable {
        todo!()
    }
}

impl Brdf for AnalyticBrdf {
    fn eval(&self, light: glam::Vec3, view: glam::Vec3) -> [f32; 3] {
        todo!()
    }
}
