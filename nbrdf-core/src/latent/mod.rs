//! The latent space of materials (DESIGN.md section 7): an autoencoder over flattened NBRDFs
//! trained with an image loss, a predictor of the Blinn-Phong sampling parameters from the
//! code, and the PCA baseline of Nielsen et al. 2015.

pub mod autoencoder;
pub mod mlp;
pub mod pca;
pub mod predictor;
pub mod sphere;
