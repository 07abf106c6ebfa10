//! Comparing two reflectances (docs/design.md section 11): images of a sphere under directional
//! lights (MAE, RMSE, PSNR on linear HDR pixels, SSIM on tone-mapped ones) and the log-space BRDF
//! error that training minimises.
//!
//! The sphere is the autoencoder's (section 7): orthographic, seen from `+z`, lit by one
//! directional light of unit irradiance per image, radiance `f_r(l, v) cos(theta_l)`. Metrics
//! cover the whole square image, background (black in both) included, as image metrics usually
//! do; the first material is the reference.

use crate::brdf::{Brdf, Directions, RgbMut};
use crate::coords::RusinkiewiczAngles;
use crate::error::{NbrdfError, Result};
use crate::merl::{MerlTable, PhiFold};
use crate::network::Nbrdf;
use crate::rng::{SplitMix64, Stream};
use crate::train::dataset::{directions, AngularSampling};
use glam::Vec3;
use serde::Serialize;

/// Light elevations of the comparison images, degrees from the normal of the sphere's centre.
pub const LIGHT_THETAS_DEG: [f64; 5] = [0.0, 30.0, 45.0, 60.0, 75.0];

/// A reflectance to compare: a MERL-format table or a network.
pub enum Material {
    Table(Box<MerlTable>),
    Network(Box<Nbrdf>),
}

impl Material {
    /// A network when the file name ends in `.json`, a MERL table otherwise.
    pub fn read(path: &std::path::Path) -> Result<Self> {
        Self::read_folded(path, PhiFold::Reciprocal)
    }

    /// As [`Material::read`], a table being read with the `phi_d` fold `fold`.
    pub fn read_folded(path: &std::path::Path, fold: PhiFold) -> Result<Self> {
        if path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("json"))
        {
            Ok(Material::Network(Box::new(Nbrdf::load(path)?)))
        } else {
            Ok(Material::Table(Box::new(
                MerlTable::read(path)?.with_phi_fold(fold),
            )))
        }
    }

    pub fn brdf(&self) -> &dyn Brdf {
        match self {
            Material::Table(t) => t.as_ref(),
            Material::Network(n) => n.as_ref(),
        }
    }

    /// `f_r` at a set of angles (`phi_h` ignored: both kinds are isotropic), `None` where a
    /// table has no data.
    pub fn value_at(&self, angles: &RusinkiewiczAngles) -> Option<[f64; 3]> {
        match self {
            Material::Table(t) => t.lookup_valid(angles),
            Material::Network(n) => Some(n.eval_at_angles(angles)),
        }
    }

    /// Whether the material depends on `phi_h` (an anisotropic network).
    pub fn is_anisotropic(&self) -> bool {
        matches!(self, Material::Network(n) if n.anisotropic)
    }
}

/// A linear RGB image, planar channels.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    pub size: usize,
    pub rgb: [Vec<f32>; 3],
}

/// A pixel of the evaluation sphere on the disk: index `py * size + px` and the view and light
/// directions in its local shading frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpherePixel {
    pub index: usize,
    pub view: Vec3,
    pub light: Vec3,
}

/// The pixels of a `size` x `size` orthographic view of the unit sphere from +z, lit from
/// `(sin t, 0, cos t)`, `t = light_theta` radians, in row order; the one geometry of every
/// sphere image (metrics, the autoencoder's loss, the PCA baseline). Directions may be below
/// the horizon near the terminator.
pub fn sphere_pixels(size: usize, light_theta: f64) -> Vec<SpherePixel> {
    sphere_pixels_window(size, light_theta, (0.0, 0.0), 1.0)
}

/// [`sphere_pixels`] of a square window of the view, centred on `centre` (image coordinates:
/// `x` right, `y` up, the sphere's outline the unit circle) with half side `half_width`; 1 and
/// the origin give the whole sphere, smaller windows zoom in (e.g. on the highlight).
pub fn sphere_pixels_window(
    size: usize,
    light_theta: f64,
    centre: (f32, f32),
    half_width: f32,
) -> Vec<SpherePixel> {
    let light_world = Vec3::new(light_theta.sin() as f32, 0.0, light_theta.cos() as f32);
    let mut out = Vec::new();
    for py in 0..size {
        for px in 0..size {
            let x = centre.0 + half_width * ((2.0 * (px as f32 + 0.5) / size as f32) - 1.0);
            let y = centre.1 + half_width * (1.0 - (2.0 * (py as f32 + 0.5) / size as f32));
            let r2 = x * x + y * y;
            if r2 >= 1.0 {
                continue;
            }
            let normal = Vec3::new(x, y, (1.0 - r2).sqrt());
            let (t, b) = normal.any_orthonormal_pair();
            let local = |w: Vec3| Vec3::new(w.dot(t), w.dot(b), w.dot(normal));
            out.push(SpherePixel {
                index: py * size + px,
                view: local(Vec3::Z),
                light: local(light_world),
            });
        }
    }
    out
}

/// Renders the sphere lit from `(sin t, 0, cos t)`, `t = light_theta` radians.
pub fn render_sphere(brdf: &dyn Brdf, size: usize, light_theta: f64) -> Image {
    let n_px = size * size;
    let (mut view, mut light) = (vec![0.0f32; 3 * n_px], vec![0.0f32; 3 * n_px]);
    // Off the sphere: a light below the horizon makes the pixel black in any BRDF.
    view[2 * n_px..].fill(1.0);
    light[2 * n_px..].fill(-1.0);
    for p in sphere_pixels(size, light_theta) {
        let (v, l, i) = (p.view, p.light, p.index);
        for (k, (vc, lc)) in [(v.x, l.x), (v.y, l.y), (v.z, l.z)].into_iter().enumerate() {
            view[k * n_px + i] = vc;
            light[k * n_px + i] = lc;
        }
    }
    let mut out = vec![0.0f32; 3 * n_px];
    // The buffers are 3 * n_px long by construction, so the planar splits cannot fail.
    let (Some(v), Some(l), Some(o)) = (
        Directions::from_planar(&view),
        Directions::from_planar(&light),
        RgbMut::from_planar(&mut out),
    ) else {
        unreachable!("buffers of 3 planes")
    };
    brdf.eval_cos_batch(v, l, o);
    let mut planes = out.chunks_exact(n_px).map(|c| {
        c.iter()
            .map(|v| if v.is_finite() { v.max(0.0) } else { 0.0 })
            .collect()
    });
    let rgb = std::array::from_fn(|_| planes.next().unwrap_or_default());
    Image { size, rgb }
}

/// Image errors of `test` against `reference`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ImageErrors {
    pub mae: f64,
    pub rmse: f64,
    /// PSNR with the reference image's maximum as the peak, `20 log10(max(reference) / rmse)`;
    /// infinite for identical images. (Not the `psnr` of `python/metrics.py`, whose peak is 1.)
    /// Serialised as `psnr`, the key the JSON reports and their readers use.
    #[serde(rename = "psnr")]
    pub psnr_peak_reference: f64,
    /// Mean SSIM over the RGB channels of the tone-mapped images.
    pub ssim: f64,
}

pub fn image_errors(reference: &Image, test: &Image) -> ImageErrors {
    let (mut abs, mut sq, mut peak, mut count) = (0.0f64, 0.0f64, 0.0f64, 0usize);
    for (r, t) in reference.rgb.iter().zip(&test.rgb) {
        for (&a, &b) in r.iter().zip(t) {
            let d = (a - b) as f64;
            abs += d.abs();
            sq += d * d;
            peak = peak.max(a as f64);
            count += 1;
        }
    }
    let n = count.max(1) as f64;
    let rmse = (sq / n).sqrt();
    let psnr_peak_reference = if rmse > 0.0 {
        20.0 * (peak.max(f64::MIN_POSITIVE) / rmse).log10()
    } else {
        f64::INFINITY
    };
    let ssim = (0..3)
        .map(|c| {
            ssim(
                &tone_map(&reference.rgb[c]),
                &tone_map(&test.rgb[c]),
                reference.size,
            )
        })
        .sum::<f64>()
        / 3.0;
    ImageErrors {
        mae: abs / n,
        rmse,
        psnr_peak_reference,
        ssim,
    }
}

/// docs/design.md's display transform `max(x, 1e-12)^(1/2.2)`, clipped to `[0, 1]` for SSIM's range.
fn tone_map(plane: &[f32]) -> Vec<f64> {
    plane
        .iter()
        .map(|&v| (v.max(1e-12) as f64).powf(1.0 / 2.2).min(1.0))
        .collect()
}

/// SSIM (Wang et al. 2004) with an 11x11 Gaussian window of sigma 1.5 (truncated at the image
/// border and renormalised), `K1 = 0.01`, `K2 = 0.03`, data range 1.
pub fn ssim(a: &[f64], b: &[f64], size: usize) -> f64 {
    const RADIUS: isize = 5;
    let (c1, c2) = (0.01f64.powi(2), 0.03f64.powi(2));
    let kernel: Vec<f64> = (-RADIUS..=RADIUS)
        .map(|d| (-(d * d) as f64 / (2.0 * 1.5 * 1.5)).exp())
        .collect();
    let mut total = 0.0;
    for y in 0..size as isize {
        for x in 0..size as isize {
            let (mut w_sum, mut ma, mut mb, mut aa, mut bb, mut ab) =
                (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
            for dy in -RADIUS..=RADIUS {
                for dx in -RADIUS..=RADIUS {
                    let (yy, xx) = (y + dy, x + dx);
                    if yy < 0 || xx < 0 || yy >= size as isize || xx >= size as isize {
                        continue;
                    }
                    let w = kernel[(dy + RADIUS) as usize] * kernel[(dx + RADIUS) as usize];
                    let i = yy as usize * size + xx as usize;
                    w_sum += w;
                    ma += w * a[i];
                    mb += w * b[i];
                    aa += w * a[i] * a[i];
                    bb += w * b[i] * b[i];
                    ab += w * a[i] * b[i];
                }
            }
            let (ma, mb) = (ma / w_sum, mb / w_sum);
            let (va, vb, cov) = (
                aa / w_sum - ma * ma,
                bb / w_sum - mb * mb,
                ab / w_sum - ma * mb,
            );
            total += ((2.0 * ma * mb + c1) * (2.0 * cov + c2))
                / ((ma * ma + mb * mb + c1) * (va + vb + c2));
        }
    }
    total / (size * size).max(1) as f64
}

/// Mean `|ln(1 + f_a cos) - ln(1 + f_b cos)|` over `samples` directions drawn with `sampling`
/// (seeded, so repeatable) and the three channels; directions where either material has no data
/// are skipped.
pub fn log_error(
    a: &Material,
    b: &Material,
    sampling: AngularSampling,
    samples: usize,
    seed: u64,
) -> Result<f64> {
    let (mut sum, mut kept) = (0.0f64, 0usize);
    // Over all four angles when either material depends on phi_h.
    let anisotropic = a.is_anisotropic() || b.is_anisotropic();
    let mut k = 0u64;
    while kept < samples {
        if k > 64 * samples as u64 + 4096 {
            return Err(NbrdfError::InvalidArgument(
                "the materials share almost no valid directions".into(),
            ));
        }
        let mut rng = SplitMix64::new(seed, Stream::Metrics, 4 * k);
        k += 1;
        let u = [
            rng.next_f64(),
            rng.next_f64(),
            rng.next_f64(),
            rng.next_f64(),
        ];
        let (view, light, angles) = directions(sampling, anisotropic, u);
        if light.z <= 0.0 || view.z <= 0.0 {
            continue;
        }
        let (Some(fa), Some(fb)) = (a.value_at(&angles), b.value_at(&angles)) else {
            continue;
        };
        for c in 0..3 {
            sum += ((fa[c] * light.z).ln_1p() - (fb[c] * light.z).ln_1p()).abs();
        }
        kept += 1;
    }
    Ok(sum / (3 * samples.max(1)) as f64)
}

/// Everything `nbrdf compare` reports.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Comparison {
    pub resolution: usize,
    /// Per light elevation, in the order of [`LIGHT_THETAS_DEG`].
    pub per_light: Vec<(f64, ImageErrors)>,
    pub mean: ImageErrors,
    pub log_error_adaptive: f64,
    pub log_error_uniform: f64,
}

/// Compares `test` against `reference`.
pub fn compare(
    reference: &Material,
    test: &Material,
    resolution: usize,
    samples: usize,
) -> Result<Comparison> {
    if resolution == 0 || samples == 0 {
        return Err(NbrdfError::InvalidArgument(
            "resolution and samples must be at least 1".into(),
        ));
    }
    let per_light: Vec<(f64, ImageErrors)> = LIGHT_THETAS_DEG
        .iter()
        .map(|&deg| {
            let t = deg.to_radians();
            let errors = image_errors(
                &render_sphere(reference.brdf(), resolution, t),
                &render_sphere(test.brdf(), resolution, t),
            );
            (deg, errors)
        })
        .collect();
    let n = per_light.len() as f64;
    let mean_of = |f: fn(&ImageErrors) -> f64| per_light.iter().map(|(_, e)| f(e)).sum::<f64>() / n;
    let mean = ImageErrors {
        mae: mean_of(|e| e.mae),
        rmse: mean_of(|e| e.rmse),
        psnr_peak_reference: mean_of(|e| e.psnr_peak_reference),
        ssim: mean_of(|e| e.ssim),
    };
    Ok(Comparison {
        resolution,
        per_light,
        mean,
        log_error_adaptive: log_error(reference, test, AngularSampling::Adaptive, samples, 0)?,
        log_error_uniform: log_error(reference, test, AngularSampling::Uniform, samples, 0)?,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lambert(albedo: f32) -> Material {
        // A one-hidden-unit network is awkward; a constant table is the simplest material.
        let v = (albedo / std::f32::consts::PI) as f64;
        Material::Table(Box::new(MerlTable::tabulate(move |_| [v; 3])))
    }

    #[test]
    fn identical_materials_have_no_error() {
        let a = lambert(0.5);
        let c = compare(&a, &a, 16, 200).unwrap();
        assert_eq!(c.mean.mae, 0.0);
        assert!(c.mean.psnr_peak_reference.is_infinite() && (c.mean.ssim - 1.0).abs() < 1e-12);
        assert_eq!(c.log_error_adaptive, 0.0);
    }

    #[test]
    fn darker_material_has_the_expected_errors() {
        let (a, b) = (lambert(0.5), lambert(0.25));
        let c = compare(&a, &b, 32, 500).unwrap();
        // Head-on light: radiance (albedo / pi) cos(theta) on the disk, pi/4 of the image.
        let head_on = c.per_light[0].1;
        let expect_mae = (0.25 / std::f64::consts::PI) * (2.0 / 3.0) * std::f64::consts::FRAC_PI_4;
        assert!(
            (head_on.mae - expect_mae).abs() < 0.05 * expect_mae,
            "{head_on:?} vs {expect_mae}"
        );
        assert!(c.mean.ssim < 0.999 && c.mean.ssim > 0.5, "{c:?}");
        assert!(c.log_error_adaptive > 0.0 && c.log_error_uniform > 0.0);
    }

    #[test]
    fn sphere_image_is_lit_only_on_the_disk() {
        let img = render_sphere(lambert(1.0).brdf(), 8, 0.0);
        assert_eq!(img.rgb[0][0], 0.0, "corner is background");
        let centre = img.rgb[0][3 * 8 + 3];
        assert!(
            (centre - 1.0 / std::f32::consts::PI).abs() < 0.05,
            "{centre}"
        );
    }
}
