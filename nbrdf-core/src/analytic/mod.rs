//! Published analytic fits of the 100 MERL materials (docs/design.md section 8), used to synthesise
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

use crate::brdf::{Brdf, Directions, RgbMut};
use crate::error::{NbrdfError, Result};
use crate::merl::{self, MerlTable};
use glam::DVec3;
use std::fmt;
use std::str::FromStr;

pub use abc::AbcParams;
pub use sgd::SgdParams;

/// Floor for the cosines in the `1 / (l.z v.z)` factor of both models. Without it, directions
/// skimming the horizon (l.z -> 0+) send the specular term to infinity; the floor only acts
/// within 0.00006 degrees of the horizon.
pub const MIN_COS: f64 = 1e-6;

/// Which published model to use.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ModelKind {
    Sgd,
    Abc,
}

impl ModelKind {
    pub const ALL: [ModelKind; 2] = [ModelKind::Sgd, ModelKind::Abc];

    /// The lower-case name used on the command line and in file names.
    pub fn name(self) -> &'static str {
        match self {
            ModelKind::Sgd => "sgd",
            ModelKind::Abc => "abc",
        }
    }
}

impl fmt::Display for ModelKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for ModelKind {
    type Err = NbrdfError;

    fn from_str(s: &str) -> Result<Self> {
        ModelKind::ALL
            .into_iter()
            .find(|m| m.name().eq_ignore_ascii_case(s.trim()))
            .ok_or_else(|| {
                NbrdfError::InvalidArgument(format!("unknown model '{s}' (expected sgd or abc)"))
            })
    }
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
        let unknown = || NbrdfError::UnknownMaterial {
            name: material.to_string(),
        };
        Ok(match model {
            ModelKind::Sgd => AnalyticBrdf::Sgd(
                catalogue::sgd_fit(material)
                    .ok_or_else(unknown)?
                    .params
                    .clone(),
            ),
            ModelKind::Abc => AnalyticBrdf::Abc(
                catalogue::abc_fit(material)
                    .ok_or_else(unknown)?
                    .params
                    .clone(),
            ),
        })
    }

    pub fn model(&self) -> ModelKind {
        match self {
            AnalyticBrdf::Sgd(_) => ModelKind::Sgd,
            AnalyticBrdf::Abc(_) => ModelKind::Abc,
        }
    }

    /// `f_r(view, light)` in float64, zero at or below the horizon.
    pub fn eval_f64(&self, view: glam::DVec3, light: glam::DVec3) -> [f64; 3] {
        match self {
            AnalyticBrdf::Sgd(p) => p.eval_f64(view, light),
            AnalyticBrdf::Abc(p) => p.eval_f64(view, light),
        }
    }

    /// The MERL-format table of this fit at cell-centre angles.
    pub fn tabulate(&self) -> MerlTable {
        MerlTable::tabulate(|angles| {
            let (view, light) = crate::coords::from_rusinkiewicz(angles);
            // A centre with a direction below the horizon has no reflectance: MerlTable::tabulate
            // stores non-finite values as not measured (as real MERL files and RGL tabulations
            // do), so trilinear lookups near grazing angles leave those cells out instead of
            // blending in zeros.
            if light.z <= 0.0 || view.z <= 0.0 {
                return [f64::NAN; 3];
            }
            self.eval_f64(view, light)
        })
    }
}

impl Brdf for AnalyticBrdf {
    fn eval(&self, view: glam::Vec3, light: glam::Vec3) -> [f32; 3] {
        merl::to_f32_rgb(self.eval_f64(view.as_dvec3(), light.as_dvec3()))
    }

    fn eval_cos_batch(&self, view: Directions<'_>, light: Directions<'_>, out: RgbMut<'_>) {
        merl::parallel_eval_cos(view, light, out, |v, l| self.eval_f64(v, l));
    }
}

/// The unit view, light and half vectors of a pair above the horizon, and `c = l . h`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Geometry {
    pub l: DVec3,
    pub v: DVec3,
    pub h: DVec3,
    pub c: f64,
}

impl Geometry {
    /// `l.z v.z`, floored (see [`MIN_COS`]).
    pub fn cos_product(&self) -> f64 {
        self.l.z.max(MIN_COS) * self.v.z.max(MIN_COS)
    }
}

/// `None` when either direction is at or below the horizon, zero-length or not finite.
pub(crate) fn geometry(view: DVec3, light: DVec3) -> Option<Geometry> {
    let l = light.try_normalize()?;
    let v = view.try_normalize()?;
    if l.z <= 0.0 || v.z <= 0.0 {
        return None;
    }
    // l.z, v.z > 0 keeps l + v away from zero.
    let h = (l + v).try_normalize()?;
    Some(Geometry {
        l,
        v,
        h,
        c: l.dot(h).clamp(0.0, 1.0),
    })
}

/// Models fitted to data can go negative (a fitted Fresnel term) or, with degenerate
/// parameters, non-finite; a reflectance is neither.
pub(crate) fn finite_non_negative(x: f64) -> f64 {
    if x.is_finite() && x > 0.0 {
        x
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::coords::spherical_direction;
    use crate::merl::{cell_centre_angles, cell_index, Interpolation, CELLS, SCALE};
    use proptest::prelude::*;
    use std::f64::consts::{FRAC_PI_2, PI};

    fn assert_close(got: [f64; 3], expect: [f64; 3], what: &str) {
        for c in 0..3 {
            let tol = 1e-10 * expect[c].abs().max(1e-12);
            assert!(
                (got[c] - expect[c]).abs() <= tol,
                "{what} channel {c}: {got:?} vs {expect:?}"
            );
        }
    }

    fn fit(model: ModelKind, name: &str) -> AnalyticBrdf {
        AnalyticBrdf::from_catalogue(model, name).expect("catalogue material")
    }

    #[test]
    fn sgd_at_normal_incidence_matches_the_closed_form() {
        // l = v = z: theta_h = 0, c = 1, so F = f0 - f1, a = alpha, D = kap e^-alpha / (pi alpha^p),
        // and G1(z) = 1 + lambda (1 - exp(c (0 - theta0)^k)) for theta0 < 0.
        let p = SgdParams {
            rho_d: [0.1, 0.2, 0.3],
            rho_s: [0.5, 0.0, 1.0],
            alpha: [0.2, 0.2, 0.05],
            p: [0.5, 0.5, 1.0],
            f0: [0.3, 0.3, 0.04],
            f1: [0.1, 0.1, -0.5],
            kap: [2.0, 2.0, 40.0],
            lambda: [1.0, 1.0, 0.0],
            c: [0.5, 0.5, 3.0],
            k: [2.0, 2.0, 1.0],
            theta0: [-0.2, -0.2, 0.3],
        };
        let g1 = 1.0 + 1.0 * (1.0 - (0.5f64 * 0.04).exp());
        let d0 = 2.0 * (-0.2f64).exp() / (PI * 0.2f64.sqrt());
        let d2 = 40.0 * (-0.05f64).exp() / (PI * 0.05);
        let expect = [
            (0.1 + 0.5 * 0.2 * d0 * g1 * g1) / PI,
            0.2 / PI,
            (0.3 + 1.0 * 0.54 * d2) / PI,
        ];
        assert_close(p.eval_f64(DVec3::Z, DVec3::Z), expect, "literal SGD");
        // The same for a catalogue material, against a value computed independently (Python,
        // straight from the formula in docs/design.md section 8).
        let gold = fit(ModelKind::Sgd, "gold-metallic-paint");
        let expect = [0.4546033027531401, 0.3258174854525016, 0.10925637224999782];
        assert_close(
            gold.eval_f64(DVec3::Z, DVec3::Z),
            expect,
            "gold-metallic-paint SGD",
        );
    }

    #[test]
    fn abc_at_normal_incidence_matches_the_closed_form() {
        // l = v = z: c = 1, G = 1, D = A, F = ((n - 1) / (n + 1))^2.
        let p = AbcParams {
            kd: [0.1, 0.0, 0.5],
            a: [2.0, 30.0, 0.0],
            b: 50.0,
            c: 1.5,
            ior: 1.5,
        };
        let expect = [0.1 / PI + 0.04 * 2.0 / PI, 0.04 * 30.0 / PI, 0.5 / PI];
        assert_close(p.eval_f64(DVec3::Z, DVec3::Z), expect, "literal ABC");
        let green = fit(ModelKind::Abc, "green-metallic-paint");
        let expect = [
            0.08717972433457062,
            0.16214065153611185,
            0.17326264950134024,
        ];
        assert_close(
            green.eval_f64(DVec3::Z, DVec3::Z),
            expect,
            "green-metallic-paint ABC",
        );
    }

    #[test]
    fn off_axis_values_match_an_independent_reference() {
        // l at (theta 0.5, phi 0.3), v at (theta 0.7, phi 2.9): theta_h = 0.2041, c = 0.8386.
        // Reference values computed in Python from the formulas of docs/design.md section 8.
        let (l, v) = (spherical_direction(0.5, 0.3), spherical_direction(0.7, 2.9));
        let cases = [
            (
                ModelKind::Sgd,
                "gold-metallic-paint",
                [0.1656005013773451, 0.11582353359728105, 0.03751704784618992],
            ),
            (
                ModelKind::Sgd,
                "silver-paint",
                [0.14943050211547376, 0.1410563131946373, 0.13641680188564503],
            ),
            (
                ModelKind::Sgd,
                "alum-bronze",
                [
                    0.03220678776892334,
                    0.05352065374644348,
                    0.055624890141721534,
                ],
            ),
            (
                ModelKind::Abc,
                "green-metallic-paint",
                [0.031821069706460724, 0.064681226935878, 0.07037156118302688],
            ),
            (
                ModelKind::Abc,
                "alum-bronze",
                [
                    0.05252655088383099,
                    0.039917700175520106,
                    0.02883563908758136,
                ],
            ),
            (
                ModelKind::Abc,
                "gold-metallic-paint",
                [0.1673714918382728, 0.11372754549880557, 0.04098999864490436],
            ),
        ];
        for (model, name, expect) in cases {
            assert_close(
                fit(model, name).eval_f64(v, l),
                expect,
                &format!("{model} {name}"),
            );
        }
    }

    #[test]
    fn catalogue_lookup_errors_and_aliases() {
        let err = AnalyticBrdf::from_catalogue(ModelKind::Abc, "unobtainium").unwrap_err();
        assert!(matches!(err, NbrdfError::UnknownMaterial { ref name } if name == "unobtainium"));
        assert!(err.to_string().contains("list-materials"));
        let (l, v) = (spherical_direction(0.5, 0.3), spherical_direction(0.7, 2.9));
        for model in ModelKind::ALL {
            let a = fit(model, "metallic-gold").eval_f64(v, l);
            assert_eq!(a, fit(model, "gold-metallic-paint").eval_f64(v, l));
            assert_eq!(fit(model, "alum-bronze").model(), model);
        }
        assert_eq!("SGD".parse::<ModelKind>().unwrap(), ModelKind::Sgd);
        assert!("ggx".parse::<ModelKind>().is_err());
    }

    /// Directions from the pole to a hair above the horizon, all around.
    fn test_directions() -> Vec<DVec3> {
        let thetas = [
            0.0,
            0.2,
            0.7,
            1.1,
            1.4,
            1.55,
            FRAC_PI_2 - 1e-4,
            FRAC_PI_2 - 1e-9,
            FRAC_PI_2 - 1e-15,
        ];
        let phis = [0.0, 0.9, 2.0, PI, 4.4];
        thetas
            .iter()
            .flat_map(|&t| phis.iter().map(move |&p| spherical_direction(t, p)))
            .collect()
    }

    #[test]
    fn every_material_is_finite_and_non_negative_including_grazing() {
        let dirs = test_directions();
        for name in catalogue::material_names() {
            for model in ModelKind::ALL {
                let brdf = fit(model, name);
                for &l in &dirs {
                    for &v in &dirs {
                        let f = brdf.eval_f64(v, l);
                        assert!(
                            f.iter().all(|x| x.is_finite() && *x >= 0.0),
                            "{model} {name} {l} {v}: {f:?}"
                        );
                        let f32 = brdf.eval(v.as_vec3(), l.as_vec3());
                        assert!(
                            f32.iter().all(|x| x.is_finite() && *x >= 0.0),
                            "{model} {name}: {f32:?}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn zero_below_the_horizon_and_on_degenerate_input() {
        let up = spherical_direction(0.4, 1.0);
        let bad = [
            DVec3::new(0.5, 0.5, -0.1),
            DVec3::X,
            DVec3::ZERO,
            DVec3::new(f64::NAN, 0.0, 1.0),
            DVec3::new(0.0, f64::INFINITY, 1.0),
        ];
        for model in ModelKind::ALL {
            let brdf = fit(model, "silver-paint");
            for b in bad {
                assert_eq!(brdf.eval_f64(up, b), [0.0; 3], "{model} {b}");
                assert_eq!(brdf.eval_f64(b, up), [0.0; 3], "{model} {b}");
            }
            // Non-unit input is normalised.
            let f = brdf.eval_f64(0.1 * spherical_direction(0.9, 2.0), 3.0 * up);
            assert_close(
                f,
                brdf.eval_f64(spherical_direction(0.9, 2.0), up),
                "scaled input",
            );
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(200))]
        #[test]
        fn both_models_are_reciprocal(
            material in 0usize..100, tl in 0.0..FRAC_PI_2, pl in -PI..PI, tv in 0.0..FRAC_PI_2, pv in -PI..PI
        ) {
            let name = catalogue::material_names()[material];
            let (l, v) = (spherical_direction(tl, pl), spherical_direction(tv, pv));
            for model in ModelKind::ALL {
                let brdf = fit(model, name);
                let (a, b) = (brdf.eval_f64(v, l), brdf.eval_f64(l, v));
                for c in 0..3 {
                    prop_assert!((a[c] - b[c]).abs() <= 1e-9 * a[c].abs().max(1e-300), "{model} {name}: {a:?} vs {b:?}");
                }
            }
        }
    }

    #[test]
    fn tabulation_holds_the_model_at_cell_centres() {
        let brdf = fit(ModelKind::Sgd, "gold-metallic-paint");
        let table = brdf.tabulate();
        let mut checked = 0;
        for index in (0..CELLS)
            .step_by(997)
            .chain([0, CELLS - 1, cell_index(0, 45, 90)])
        {
            let (h, d, p) = crate::merl::cell_coordinates(index);
            let angles = cell_centre_angles(h, d, p);
            let (v, l) = crate::coords::from_rusinkiewicz(&angles);
            if l.z <= 0.0 || v.z <= 0.0 {
                assert_eq!(
                    table.cell(index),
                    None,
                    "{h} {d} {p} lies below the horizon"
                );
                continue;
            }
            let expect = brdf.eval_f64(v, l);
            let cell = table
                .cell(index)
                .expect("cells above the horizon are valid");
            for c in 0..3 {
                assert!(
                    (cell[c] - expect[c]).abs() <= 1e-12 * expect[c],
                    "{h} {d} {p}: {cell:?} vs {expect:?}"
                );
                assert_eq!(table.stored()[c * CELLS + index], expect[c] / SCALE[c]);
            }
            // The continuous index of a centre is i + 0.5 up to rounding, so neighbours leak in at
            // the 1e-15 level.
            let looked_up = table.lookup(&angles, Interpolation::Trilinear);
            for c in 0..3 {
                assert!(
                    (looked_up[c] - expect[c]).abs() <= 1e-9 * expect[c] + 1e-10,
                    "{looked_up:?} vs {expect:?}"
                );
            }
            checked += 1;
        }
        assert!(checked > 1000);
        // Cells whose light direction is below the horizon are not measured.
        let below = cell_index(89, 89, 0);
        let (_, l) = crate::coords::from_rusinkiewicz(&cell_centre_angles(89, 89, 0));
        assert!(l.z < 0.0);
        assert_eq!(table.cell(below), None);
        assert_eq!(table.stored()[below], crate::merl::NOT_MEASURED);
    }
}
