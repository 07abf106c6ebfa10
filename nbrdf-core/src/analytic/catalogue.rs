//! The embedded fit figures: the names of the 100 MERL materials and their SGD and ABC parameters.
//!
//! `data/merl_fits.json` is compiled into the binary and parsed once, on first use. Several
//! materials are known under two names (MERL's file name and the name used in the SGD paper);
//! every lookup here accepts either, ignoring ASCII case.

use super::{AbcParams, SgdParams};
use serde::Deserialize;
use std::sync::OnceLock;

const FITS_JSON: &str = include_str!("../../data/merl_fits.json");

/// The whole embedded file.
#[derive(Clone, Debug, Deserialize)]
pub struct Catalogue {
    /// Citation of the fits.
    pub about: String,
    pub sgd: SgdSection,
    pub abc: AbcSection,
}

#[derive(Clone, Debug, Deserialize)]
pub struct SgdSection {
    pub source: String,
    pub fields: String,
    pub materials: Vec<SgdFit>,
}

#[derive(Clone, Debug, Deserialize)]
pub struct AbcSection {
    pub source: String,
    pub materials: Vec<AbcFit>,
}

/// One SGD fit (Bagher et al. 2012), every parameter per RGB channel.
#[derive(Clone, Debug, Deserialize)]
pub struct SgdFit {
    pub name: String,
    #[serde(default)]
    pub alias: Option<String>,
    #[serde(flatten)]
    pub params: SgdParams,
    /// The fitting residual published with the fit.
    pub fit_error: [f64; 3],
}

/// One ABC fit (Löw et al. 2012).
#[derive(Clone, Debug, Deserialize)]
pub struct AbcFit {
    pub name: String,
    #[serde(flatten)]
    pub params: AbcParams,
}

/// The parsed catalogue.
pub fn catalogue() -> &'static Catalogue {
    static CATALOGUE: OnceLock<Catalogue> = OnceLock::new();
    // The file is part of the source tree and covered by tests: failing to parse it is a build
    // defect, not a user error.
    CATALOGUE.get_or_init(|| {
        serde_json::from_str(FITS_JSON).expect("embedded data/merl_fits.json is valid")
    })
}

/// The 100 MERL material names, sorted.
pub fn material_names() -> Vec<&'static str> {
    let mut names: Vec<&'static str> = catalogue()
        .sgd
        .materials
        .iter()
        .map(|m| m.name.as_str())
        .collect();
    names.sort_unstable();
    names
}

/// The catalogue name of `name`, which may be an alias or differ in ASCII case.
pub fn canonical_name(name: &str) -> Option<&'static str> {
    let name = name.trim();
    let cat = catalogue();
    let sgd = cat.sgd.materials.iter().find(|m| {
        m.name.eq_ignore_ascii_case(name)
            || m.alias
                .as_deref()
                .is_some_and(|a| a.eq_ignore_ascii_case(name))
    });
    sgd.map(|m| m.name.as_str()).or_else(|| {
        let abc = cat
            .abc
            .materials
            .iter()
            .find(|m| m.name.eq_ignore_ascii_case(name));
        abc.map(|m| m.name.as_str())
    })
}

/// The other name of a material, if it has one.
pub fn alias(name: &str) -> Option<&'static str> {
    sgd_fit(name).and_then(|m| m.alias.as_deref())
}

pub fn sgd_fit(name: &str) -> Option<&'static SgdFit> {
    let name = canonical_name(name)?;
    catalogue().sgd.materials.iter().find(|m| m.name == name)
}

pub fn abc_fit(name: &str) -> Option<&'static AbcFit> {
    let name = canonical_name(name)?;
    catalogue().abc.materials.iter().find(|m| m.name == name)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hundred_sorted_unique_names_in_both_models() {
        let names = material_names();
        assert_eq!(names.len(), 100);
        assert!(names.windows(2).all(|w| w[0] < w[1]), "sorted and unique");
        let mut abc: Vec<&str> = catalogue()
            .abc
            .materials
            .iter()
            .map(|m| m.name.as_str())
            .collect();
        abc.sort_unstable();
        assert_eq!(names, abc);
        assert!(names.contains(&"gold-metallic-paint") && names.contains(&"yellow-phenolic"));
        assert!(catalogue().about.contains("Bagher") && catalogue().about.contains("Low"));
    }

    #[test]
    fn lookups_accept_aliases_and_case() {
        assert_eq!(canonical_name("metallic-gold"), Some("gold-metallic-paint"));
        assert_eq!(
            canonical_name("Gold-Metallic-Paint"),
            Some("gold-metallic-paint")
        );
        assert_eq!(canonical_name("alum-bronze"), Some("alum-bronze"));
        assert_eq!(canonical_name("no-such-material"), None);
        assert_eq!(alias("gold-metallic-paint"), Some("metallic-gold"));
        assert_eq!(alias("alum-bronze"), None);
        let by_alias = abc_fit("metallic-gold").expect("alias resolves for ABC too");
        assert_eq!(by_alias.name, "gold-metallic-paint");
        assert_eq!(
            sgd_fit("fabric-beige").map(|m| m.name.as_str()),
            Some("beige-fabric")
        );
    }

    #[test]
    fn figures_are_parsed_into_the_right_fields() {
        // Literal figures from the file (first and last material of each model).
        let s = sgd_fit("alum-bronze").unwrap();
        assert_eq!(s.params.rho_d, [0.0478786, 0.0313514, 0.0200638]);
        assert_eq!(s.params.theta0, [0.205635, 0.066289, -0.0661091]);
        assert_eq!(s.fit_error, [0.100735, 0.0878706, 0.0861907]);
        let a = &abc_fit("alum-bronze").unwrap().params;
        assert_eq!(a.kd, [0.024514, 0.022346, 0.01622]);
        assert_eq!(a.a, [51.714554, 37.932693, 27.373095]);
        assert_eq!((a.b, a.c, a.ior), (10482.133789, 0.816737, 2.236525));
        for m in &catalogue().sgd.materials {
            let p = &m.params;
            let all = [
                p.rho_d, p.rho_s, p.alpha, p.p, p.f0, p.f1, p.kap, p.lambda, p.c, p.k, p.theta0,
            ];
            assert!(all.iter().flatten().all(|x| x.is_finite()), "{}", m.name);
            assert!(p.alpha.iter().all(|&x| x > 0.0), "{}", m.name);
        }
        for m in &catalogue().abc.materials {
            assert!(m.params.ior >= 1.0 && m.params.b >= 0.0, "{}", m.name);
        }
    }
}
