//! The reflectance that fits and searches read ([`crate::train::dataset::TargetFn`]): `f_r` by
//! Rusinkiewicz angles. A table's is [`crate::train::table_target`]; a network's is here, so
//! that the phong fit, the lobe search and the predictor's labels all evaluate it one way.

use crate::coords::RusinkiewiczAngles;
use crate::metrics::Material;
use crate::network::Nbrdf;
use crate::train::dataset::TargetFn;

/// `f_r` of `net` at a set of angles (`phi_h` ignored: the network is isotropic); never `None`.
pub fn network_target(net: &Nbrdf) -> impl Fn(&RusinkiewiczAngles) -> Option<[f64; 3]> + Sync + '_ {
    move |angles| Some(net.eval_at_angles(angles))
}

/// `f_r` of a material read for comparisons and fits: a table's trilinear lookup where it has
/// data ([`crate::train::table_target`]), a network's [`network_target`].
pub fn material_target(material: &Material) -> Box<TargetFn<'_>> {
    match material {
        Material::Table(table) => Box::new(crate::train::table_target(table)),
        Material::Network(net) => Box::new(network_target(net)),
    }
}
