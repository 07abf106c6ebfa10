//! The embedded fit figures: the names of the 100 MERL materials and their SGD and ABC parameters.

/// The 100 MERL material names, sorted.
pub fn material_names() -> Vec<&'static str> {
    todo!()
}
