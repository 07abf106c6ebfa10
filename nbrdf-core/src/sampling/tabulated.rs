//! The data-driven sampler (docs/design.md section 6): per band of view elevations, a
//! piecewise-constant density over the half vector, tabulated from the material's `f_r cos`
//! through the half-vector Jacobian, mixed with a defensive share `c` of cosine sampling:
//!
//! `pdf(l) = c l.z / pi + (1 - c) P_row(bin) / Ω(bin) / (4 v.h)`
//!
//! Bins run over `t = (1 - cos theta_h)^(1/4)` (dense near the normal, where sharp peaks are) and
//! `|phi_h - phi_v|` in `[0, pi]`: an isotropic material's `f_r cos` is the same on both sides
//! of the plane of incidence, so a bin stands for itself and its mirror image (`Ω` counts both)
//! and one bit of `u2` picks the side. The row is `floor(theta_v / (pi/2) rows)`, nothing is
//! interpolated, so the density of a sample is exact; a row averages the normalised densities
//! of views from its band's lower edge, which reaches every bin a view of the band can. A bin is
//! drawn through its row's alias table, the half vector uniform in solid angle within it.
//!
//! Twin: `mitsuba-plugin/nbrdf_mitsuba/jit/sampling.py` `TracedTable` (from the exported
//! [`TabulatedSampler::tables`]); held together by `tests/test_tabulated.py`.

use super::hemisphere::cosine_hemisphere;
use super::reflect;
use crate::brdf::Brdf;
use crate::error::{NbrdfError, Result};
use glam::DVec3;
use rayon::prelude::*;
use std::f64::consts::{FRAC_1_PI, FRAC_PI_2, PI, TAU};

/// Table size and mixture weight of a [`TabulatedSampler`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TableConfig {
    /// Bands of view elevation, uniform in `theta_v` over `[0, pi/2)`.
    pub rows: usize,
    /// Bins in `t = (1 - cos theta_h)^(1/4)` and in `|phi_h - phi_v|` over `[0, pi]` (each
    /// standing for itself and its mirror image); the default 48 x 16 was chosen on the MERL
    /// set (docs/results/sampling.md).
    pub theta_bins: usize,
    pub phi_bins: usize,
    /// Points per bin side when averaging the material over a bin.
    pub subsamples: usize,
    /// View elevations per row, from the band's lower edge, whose densities (each normalised)
    /// the row averages.
    pub views_per_row: usize,
    /// Weight of the defensive cosine component.
    pub cosine_weight: f64,
}

/// The defensive cosine weights `nbrdf fit-phong` compares; it stores the one of lowest
/// variance as `sampling.table_cosine_weight`. A glossy material's variance falls with the
/// weight (the cosine share is spent where `f_r` is small), a near-diffuse one's rises a little
/// (docs/results/sampling.md); below 0.02 a table that misses a view's lobe has too little to
/// fall back on.
pub const COSINE_WEIGHT_CANDIDATES: [f64; 3] = [0.1, 0.05, 0.02];

impl TableConfig {
    /// The default table with the cosine weight a network's file stores
    /// (`sampling.table_cosine_weight`), if any.
    pub fn with_stored_cosine_weight(stored: Option<f32>) -> Self {
        TableConfig {
            cosine_weight: stored.map_or(Self::default().cosine_weight, f64::from),
            ..Self::default()
        }
    }
}

impl Default for TableConfig {
    fn default() -> Self {
        TableConfig {
            rows: 16,
            theta_bins: 48,
            phi_bins: 16,
            subsamples: 3,
            views_per_row: 3,
            cosine_weight: 0.1,
        }
    }
}

/// The tabulated half-vector sampler (module docs). Immutable once built.
#[derive(Clone, Debug, PartialEq)]
pub struct TabulatedSampler {
    rows: usize,
    theta_bins: usize,
    phi_bins: usize,
    cosine_weight: f64,
    /// Probability of each bin (with its mirror image), row-major `[row][t][phi]`, summing to 1
    /// per row.
    mass: Vec<f64>,
    /// Per row, Walker's alias table over the row's bins (same layout as `mass`): a bin `k`
    /// drawn uniformly is kept with probability `alias_probability[k]`, else replaced by
    /// `alias[k]` (an index within the row), so a bin costs two lookups whatever the table's
    /// size, where a binary search in a CDF costs a chain of dependent ones (render times in
    /// docs/results/performance.md).
    alias_probability: Vec<f64>,
    alias: Vec<u32>,
}

/// The exported arrays of a [`TabulatedSampler`] (float32 copies for the Dr.Jit path).
#[derive(Clone, Debug, PartialEq)]
pub struct TableArrays {
    pub rows: usize,
    pub theta_bins: usize,
    pub phi_bins: usize,
    pub cosine_weight: f64,
    pub mass: Vec<f64>,
    pub alias_probability: Vec<f64>,
    pub alias: Vec<u32>,
}

/// Mean over RGB of `f_r(view, light)`, the quantity the table follows.
pub type MeanBrdf<'a> = dyn Fn(DVec3, DVec3) -> f64 + Sync + 'a;

/// The elevation row of a unit view direction (`v.z > 0`).
fn row_of(v: DVec3, rows: usize) -> usize {
    let theta_v = v.x.hypot(v.y).atan2(v.z);
    ((theta_v / FRAC_PI_2 * rows as f64) as usize).min(rows - 1)
}

/// `1 - cos(theta_h)` at the edge `k` of the `t` bins: `(k / bins)^4`.
fn bin_one_minus_cos(k: usize, bins: usize) -> f64 {
    let t = k as f64 / bins as f64;
    (t * t) * (t * t)
}

/// `(cos phi_v, sin phi_v)` of a view: the x axis of the frame in which `phi` is measured; +x
/// at the normal, where the azimuth is undefined (the Dr.Jit twin picks the same).
fn view_azimuth(v: DVec3) -> (f64, f64) {
    let len = v.x.hypot(v.y);
    if len > 0.0 {
        (v.x / len, v.y / len)
    } else {
        (1.0, 0.0)
    }
}

/// Walker's alias table of a probability vector (Vose's construction, deterministic): per bin
/// the probability of keeping it and the bin that replaces it otherwise. A bin of mass 0 is
/// never kept nor anyone's alias, so it is never drawn (its pdf is 0); rounding leftovers of
/// positive mass keep themselves.
fn alias_table(mass: &[f64]) -> (Vec<f64>, Vec<u32>) {
    let n = mass.len();
    let mut scaled: Vec<f64> = mass.iter().map(|&m| m * n as f64).collect();
    let mut probability = vec![0.0; n];
    let mut alias: Vec<u32> = (0..n as u32).collect();
    let (mut small, mut large): (Vec<usize>, Vec<usize>) = (0..n).partition(|&k| scaled[k] < 1.0);
    while let (Some(&s), Some(&l)) = (small.last(), large.last()) {
        small.pop();
        probability[s] = scaled[s].clamp(0.0, 1.0);
        alias[s] = l as u32;
        scaled[l] -= 1.0 - scaled[s];
        if scaled[l] < 1.0 {
            large.pop();
            small.push(l);
        }
    }
    let heaviest = (0..n).fold(0, |best, k| if mass[k] > mass[best] { k } else { best });
    for k in large.into_iter().chain(small) {
        if mass[k] > 0.0 {
            probability[k] = 1.0;
            alias[k] = k as u32;
        } else {
            probability[k] = 0.0;
            alias[k] = heaviest as u32;
        }
    }
    (probability, alias)
}

impl TabulatedSampler {
    /// Tabulates `f_r cos` of a BRDF (mean over RGB) for sampling.
    pub fn from_brdf(brdf: &dyn Brdf, config: &TableConfig) -> Result<Self> {
        let f = |v: DVec3, l: DVec3| {
            let rgb = brdf.eval(v.as_vec3(), l.as_vec3());
            rgb.iter().map(|&c| f64::from(c.max(0.0))).sum::<f64>() / 3.0
        };
        Self::build(&f, config)
    }

    /// Tabulates `mean_f(v, l) l.z 4 (v.h) 4 t^3` (`dω_h = 4 t^3 dt dphi`) averaged over each bin, per view
    /// normalised and averaged over the views of each row's band (module docs; views lie in
    /// the xz plane).
    pub fn build(mean_f: &MeanBrdf<'_>, config: &TableConfig) -> Result<Self> {
        let TableConfig {
            rows,
            theta_bins,
            phi_bins,
            subsamples,
            views_per_row: views,
            cosine_weight,
        } = *config;
        if rows == 0 || theta_bins == 0 || phi_bins == 0 || subsamples == 0 || views == 0 {
            return Err(NbrdfError::InvalidArgument(format!(
                "tabulated sampler: needs rows, theta bins, phi bins, subsamples and views per \
                 row (got {config:?})"
            )));
        }
        if !(0.0..1.0).contains(&cosine_weight) {
            return Err(NbrdfError::InvalidArgument(format!(
                "tabulated sampler: cosine weight {cosine_weight} must be in [0, 1)"
            )));
        }
        let (dt, dphi) = (1.0 / theta_bins as f64, PI / phi_bins as f64);
        // `f_r cos` over each bin for each of the `views` view elevations of each row, row-major
        // `[row][view][t][phi]`.
        let per_view: Vec<f64> = (0..rows * views * theta_bins * phi_bins)
            .into_par_iter()
            .map(|k| {
                let (r, c) = (
                    k / (views * theta_bins * phi_bins),
                    (k / (theta_bins * phi_bins)) % views,
                );
                let (i, j) = ((k / phi_bins) % theta_bins, k % phi_bins);
                let theta_v = (r as f64 + c as f64 / views as f64) / rows as f64 * FRAC_PI_2;
                let v = DVec3::new(theta_v.sin(), 0.0, theta_v.cos());
                let mut sum = 0.0;
                for a in 0..subsamples {
                    let t = (i as f64 + (a as f64 + 0.5) / subsamples as f64) * dt;
                    let one_minus_cos = (t * t) * (t * t);
                    let cos_h = 1.0 - one_minus_cos;
                    let sin_h = (one_minus_cos * (1.0 + cos_h)).sqrt();
                    for b in 0..subsamples {
                        let phi = (j as f64 + (b as f64 + 0.5) / subsamples as f64) * dphi;
                        let h = DVec3::new(sin_h * phi.cos(), sin_h * phi.sin(), cos_h);
                        let v_dot_h = v.dot(h);
                        let l = 2.0 * v_dot_h * h - v;
                        if v_dot_h <= 0.0 || l.z <= 0.0 {
                            continue;
                        }
                        let g = mean_f(v, l) * l.z * 4.0 * v_dot_h * 4.0 * t * t * t;
                        if g.is_finite() && g > 0.0 {
                            sum += g;
                        }
                    }
                }
                sum
            })
            .collect();
        // Each view's density normalised, then averaged over the band (module docs).
        let block = theta_bins * phi_bins;
        let mut cells = vec![0.0; rows * block];
        for (r, row_cells) in cells.chunks_exact_mut(block).enumerate() {
            for view in per_view[r * views * block..(r + 1) * views * block].chunks_exact(block) {
                let total: f64 = view.iter().sum();
                if total > 0.0 {
                    for (cell, &g) in row_cells.iter_mut().zip(view) {
                        *cell += g / total;
                    }
                }
            }
        }
        Ok(Self::from_weights(
            rows,
            theta_bins,
            phi_bins,
            cosine_weight,
            &cells,
        ))
    }

    /// The sampler of non-negative bin weights `[row][t][phi]` (rows that sum to 0 become
    /// uniform in `(t, phi)`).
    pub fn from_weights(
        rows: usize,
        theta_bins: usize,
        phi_bins: usize,
        cosine_weight: f64,
        weights: &[f64],
    ) -> Self {
        let row_len = theta_bins * phi_bins;
        let mut mass = Vec::with_capacity(rows * row_len);
        let mut alias_probability = Vec::with_capacity(rows * row_len);
        let mut alias = Vec::with_capacity(rows * row_len);
        for row in weights.chunks_exact(row_len).take(rows) {
            let clean = row
                .iter()
                .map(|&w| if w.is_finite() && w > 0.0 { w } else { 0.0 });
            let total: f64 = clean.clone().sum();
            let row_mass: Vec<f64> = if total > 0.0 {
                clean.map(|w| w / total).collect()
            } else {
                vec![1.0 / row_len as f64; row_len]
            };
            let (p, a) = alias_table(&row_mass);
            mass.extend(row_mass);
            alias_probability.extend(p);
            alias.extend(a);
        }
        TabulatedSampler {
            rows,
            theta_bins,
            phi_bins,
            cosine_weight,
            mass,
            alias_probability,
            alias,
        }
    }

    /// The arrays the Dr.Jit twin samples from.
    pub fn tables(&self) -> TableArrays {
        TableArrays {
            rows: self.rows,
            theta_bins: self.theta_bins,
            phi_bins: self.phi_bins,
            cosine_weight: self.cosine_weight,
            mass: self.mass.clone(),
            alias_probability: self.alias_probability.clone(),
            alias: self.alias.clone(),
        }
    }

    /// Weight of the defensive cosine component.
    pub fn cosine_weight(&self) -> f64 {
        self.cosine_weight
    }

    /// The same table mixed with another cosine weight (in `[0, 1)`).
    pub fn with_cosine_weight(&self, cosine_weight: f64) -> Result<Self> {
        if !(0.0..1.0).contains(&cosine_weight) {
            return Err(NbrdfError::InvalidArgument(format!(
                "tabulated sampler: cosine weight {cosine_weight} must be in [0, 1)"
            )));
        }
        Ok(TabulatedSampler {
            cosine_weight,
            ..self.clone()
        })
    }

    /// The bin (index within row `r`) of the rescaled uniform `u`, through the row's alias table.
    /// The Dr.Jit twin (`jit/sampling.py` `TracedTable.pick`) does the same in float32.
    fn pick(&self, r: usize, u: f64) -> usize {
        let n = self.theta_bins * self.phi_bins;
        let scaled = u * n as f64;
        let k = (scaled as usize).min(n - 1);
        let keep = scaled - (k as f64) < self.alias_probability[r * n + k];
        if keep {
            k
        } else {
            self.alias[r * n + k] as usize
        }
    }

    /// The direction before rounding to float32 (`v` unit, above the horizon; `u` in [0, 1]):
    /// `u0` picks the component and, rescaled, the table's bin; `u1` and `u2` place the half
    /// vector within the bin or its mirror image (module docs).
    pub(crate) fn sample_direction(&self, v: DVec3, [u0, u1, u2]: [f64; 3]) -> DVec3 {
        let c = self.cosine_weight;
        if u0 < c {
            return cosine_hemisphere(u1, u2);
        }
        let r = row_of(v, self.rows);
        let (nt, np) = (self.theta_bins, self.phi_bins);
        let bin = self.pick(r, (u0 - c) / (1.0 - c));
        let (mirrored, fp) = if u2 < 0.5 {
            (false, 2.0 * u2)
        } else {
            (true, 2.0 * u2 - 1.0)
        };
        let (i, j, ft) = (bin / np, bin % np, u1);
        // Uniform in solid angle within the bin: 1 - cos(theta_h) uniform between its edges.
        let (o0, o1) = (bin_one_minus_cos(i, nt), bin_one_minus_cos(i + 1, nt));
        let one_minus_cos = o0 + ft * (o1 - o0);
        let cos_h = 1.0 - one_minus_cos;
        let sin_h = (one_minus_cos * (1.0 + cos_h)).max(0.0).sqrt();
        let (sin_p, cos_p) = ((j as f64 + fp) / np as f64 * PI).sin_cos();
        let sin_p = if mirrored { -sin_p } else { sin_p };
        let (cx, cy) = view_azimuth(v);
        let h = DVec3::new(
            sin_h * (cos_p * cx - sin_p * cy),
            sin_h * (cos_p * cy + sin_p * cx),
            cos_h,
        );
        reflect(v, h)
    }

    /// Density per unit solid angle of `l` given `v` (both unit, above the horizon).
    pub(crate) fn density_f64(&self, v: DVec3, l: DVec3) -> f64 {
        let cosine = self.cosine_weight * l.z * FRAC_1_PI;
        let sum = v + l;
        let len = sum.length();
        if len.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
            return cosine;
        }
        let h = sum / len;
        let v_dot_h = v.dot(h);
        if v_dot_h <= 0.0 || h.z <= 0.0 {
            return cosine;
        }
        let t = ((h.x * h.x + h.y * h.y) / (1.0 + h.z)).sqrt().sqrt();
        let (nt, np) = (self.theta_bins, self.phi_bins);
        let (cx, cy) = view_azimuth(v);
        let phi = (cx * h.y - cy * h.x).atan2(cx * h.x + cy * h.y).abs();
        let i = ((t * nt as f64) as usize).min(nt - 1);
        let j = ((phi / PI * np as f64) as usize).min(np - 1);
        let r = row_of(v, self.rows);
        let p = self.mass[(r * nt + i) * np + j];
        // The bin and its mirror image.
        let solid_angle =
            (bin_one_minus_cos(i + 1, nt) - bin_one_minus_cos(i, nt)) * TAU / np as f64;
        cosine + (1.0 - self.cosine_weight) * p / solid_angle / (4.0 * v_dot_h)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::network::Nbrdf;
    use crate::rng::SplitMix64;
    use crate::sampling::tests::sample_mean;
    use crate::sampling::{uniform_hemisphere, SamplingStrategy};
    use std::f64::consts::PI;
    use std::sync::Arc;

    fn dir(theta_deg: f64, phi: f64) -> DVec3 {
        let t = theta_deg.to_radians();
        DVec3::new(t.sin() * phi.cos(), t.sin() * phi.sin(), t.cos())
    }

    /// A Blinn-Phong-like reflectance of exponent `n` over a diffuse base `kd`.
    fn phong(kd: f64, ks: f64, n: f64) -> impl Fn(DVec3, DVec3) -> f64 + Sync {
        move |v: DVec3, l: DVec3| {
            if v.z <= 0.0 || l.z <= 0.0 {
                return 0.0;
            }
            let h = (v + l).normalize();
            kd / PI + ks * (n + 2.0) / TAU * h.z.max(0.0).powf(n)
        }
    }

    fn strategy(f: &MeanBrdf<'_>) -> SamplingStrategy {
        SamplingStrategy::Tabulated(Arc::new(
            TabulatedSampler::build(f, &TableConfig::default()).unwrap(),
        ))
    }

    /// Integral of the pdf over the hemisphere by quadrature on a `theta` x `phi` grid dense
    /// near the mirror direction of `v` (midpoints in `t` of the half vector, as the table).
    fn pdf_integral(s: &SamplingStrategy, v: DVec3) -> f64 {
        weighted_pdf_integral(s, v, &|_| 1.0)
    }

    /// Calls `visit(l, dl)` for the light directions above the horizon of a midpoint rule over
    /// the half vector: dl = 4 (v.h) dω_h, dω_h = pi t sin(theta_h) dt dphi.
    fn visit_lights(v: DVec3, mut visit: impl FnMut(DVec3, f64)) {
        let (nt, np) = (1200, 720);
        for i in 0..nt {
            let t = (i as f64 + 0.5) / nt as f64;
            let theta_h = FRAC_PI_2 * t * t;
            let (sin_h, cos_h) = theta_h.sin_cos();
            for j in 0..np {
                let phi = (j as f64 + 0.5) / np as f64 * TAU;
                let h = DVec3::new(sin_h * phi.cos(), sin_h * phi.sin(), cos_h);
                let vh = v.dot(h);
                let l = 2.0 * vh * h - v;
                if vh <= 0.0 || l.z <= 0.0 {
                    continue;
                }
                visit(l, 4.0 * vh * PI * t * sin_h / nt as f64 * TAU / np as f64);
            }
        }
    }

    /// `int g(l) pdf(l) dl` over light directions above the horizon, by the same midpoint rule.
    fn weighted_pdf_integral(s: &SamplingStrategy, v: DVec3, g: &dyn Fn(DVec3) -> f64) -> f64 {
        let mut total = 0.0;
        visit_lights(v, |l, dl| total += g(l) * s.pdf_f64(v, l) * dl);
        total
    }

    /// Relative variance `int g^2 / p / (int g)^2 - 1` of sampling `g = f l.z` for the view
    /// `v`, by the midpoint rule of [`visit_lights`] (independent of the table's bins).
    fn relative_variance(s: &SamplingStrategy, v: DVec3, f: &MeanBrdf<'_>) -> f64 {
        let (mut integral, mut second) = (0.0, 0.0);
        visit_lights(v, |l, dl| {
            let g = f(v, l) * l.z;
            integral += g * dl;
            if g > 0.0 {
                second += g * g / s.pdf_f64(v, l) * dl;
            }
        });
        second / (integral * integral) - 1.0
    }

    /// A synthesised plastic (an SGD fit of the catalogue) whose reflectance grows steeply
    /// towards grazing `theta_d` over a diffuse base: every view of the grazing band, its lower
    /// edge included, samples better than the material's best single lobe (the one `nbrdf
    /// fit-phong` stores for the synthesised table). The band is normalised and includes its
    /// lower edge because, without either, its lowest views sampled worse than the lobe
    /// (docs/results/sampling.md).
    #[cfg(feature = "train")]
    #[test]
    fn every_view_of_the_grazing_band_samples_better_than_one_lobe() {
        use crate::analytic::{AnalyticBrdf, ModelKind};
        let sgd = AnalyticBrdf::from_catalogue(ModelKind::Sgd, "gray-plastic").unwrap();
        let f =
            |v: DVec3, l: DVec3| sgd.eval_f64(v, l).iter().map(|c| c.max(0.0)).sum::<f64>() / 3.0;
        let table = strategy(&f);
        let lobe = SamplingStrategy::Phong {
            exponent: 562.0,
            specular_weight: 0.35,
        };
        for theta in [84.4, 85.0, 86.5, 88.0, 89.5] {
            let v = dir(theta, 0.0);
            let (t, p) = (
                relative_variance(&table, v, &f),
                relative_variance(&lobe, v, &f),
            );
            assert!(t < p, "view {theta}: table {t}, lobe {p}");
        }
    }

    #[test]
    fn density_integrates_to_the_mass_above_the_horizon() {
        let glossy = phong(0.2, 0.8, 300.0);
        let s = strategy(&glossy);
        for v in [dir(0.0, 0.0), dir(40.0, 1.0), dir(80.0, -2.0)] {
            let total = pdf_integral(&s, v);
            // The table puts no mass below the horizon except in bins straddling it.
            assert!(total <= 1.0 + 2e-3 && total > 0.97, "{v}: {total}");
        }
    }

    #[test]
    fn sampled_pdf_equals_pdf_and_is_positive() {
        let mut rng = SplitMix64::from_state(4);
        for f in [phong(0.5, 0.0, 1.0), phong(0.05, 1.0, 2e4)] {
            let s = strategy(&f);
            let mut valid = 0;
            for _ in 0..4000 {
                let v = uniform_hemisphere(rng.next_f64(), rng.next_f64()).as_vec3();
                let u = [rng.next_f32(), rng.next_f32(), rng.next_f32()];
                let d = s.sample(v, u);
                assert!(d.light.is_finite() && d.pdf.is_finite() && d.pdf >= 0.0);
                assert_eq!(d.pdf, s.pdf(v, d.light));
                valid += usize::from(d.pdf > 0.0);
            }
            assert!(valid > 3000, "{valid}");
        }
    }

    /// Mean of `g` under the sampler against quadrature of `g pdf`.
    #[test]
    fn sample_means_match_pdf_quadrature() {
        let sharp = phong(0.1, 1.0, 2000.0);
        let s = strategy(&sharp);
        for v in [dir(30.0, 0.5), dir(87.0, 2.0)] {
            let r = DVec3::new(-v.x, -v.y, v.z);
            let tests: [&dyn Fn(DVec3) -> f64; 3] = [
                &|l: DVec3| l.z + 0.5 * l.x * l.x,
                &|l: DVec3| f64::from(u8::from(l.dot(r) > 0.99)),
                &|l: DVec3| f64::from(u8::from(l.x > 0.3 && l.y > 0.0)),
            ];
            for (k, g) in tests.iter().enumerate() {
                let exact = weighted_pdf_integral(&s, v, g);
                let (mean, sigma) = sample_mean(&s, v, g, 200_000, 40 + k as u64);
                assert!(
                    (mean - exact).abs() < 5.0 * sigma + 2e-3,
                    "v {v} test {k}: MC {mean} +- {sigma} vs quadrature {exact}"
                );
            }
        }
    }

    /// One bin stands for `phi` and `-phi`: the density is the same at a light direction and at
    /// its mirror image across the plane of incidence, and the sampler puts half of its table
    /// samples on each side.
    #[test]
    fn both_sides_of_the_plane_of_incidence_are_drawn_alike() {
        let table = TabulatedSampler::build(&phong(0.1, 1.0, 50.0), &TableConfig::default());
        let table = Arc::new(table.unwrap());
        let c = table.cosine_weight();
        let s = SamplingStrategy::Tabulated(table);
        let mut rng = SplitMix64::from_state(21);
        for _ in 0..200 {
            let v = uniform_hemisphere(rng.next_f64(), rng.next_f64());
            let l = uniform_hemisphere(rng.next_f64(), rng.next_f64());
            let normal_to_plane = DVec3::new(-v.y, v.x, 0.0).normalize_or_zero();
            let mirrored = l - 2.0 * l.dot(normal_to_plane) * normal_to_plane;
            let (a, b) = (s.pdf_f64(v, l), s.pdf_f64(v, mirrored));
            assert!((a - b).abs() <= 1e-9 * a.max(b), "{a} vs {b}");
        }
        let v = dir(40.0, 1.0);
        let side = DVec3::new(-v.y, v.x, 0.0);
        let (mut left, mut drawn) = (0u32, 0u32);
        for _ in 0..40_000 {
            let u = [rng.next_f32(), rng.next_f32(), rng.next_f32()];
            let d = s.sample(v.as_vec3(), u);
            if d.pdf > 0.0 && f64::from(u[0]) >= c {
                drawn += 1;
                left += u32::from(d.light.as_dvec3().dot(side) > 0.0);
            }
        }
        let share = f64::from(left) / f64::from(drawn);
        assert!((share - 0.5).abs() < 0.015, "{share} of {drawn}");
    }

    #[test]
    fn a_network_table_builds_and_samples() {
        let net = Nbrdf::random("n", 21, 7);
        let t = TabulatedSampler::from_brdf(&net, &TableConfig::default()).unwrap();
        let a = t.tables();
        assert_eq!(a.mass.len(), 16 * 48 * 16);
        for row in a.mass.chunks_exact(48 * 16) {
            assert!((row.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        }
        assert_eq!(a.alias_probability.len(), 16 * 48 * 16);
        assert_eq!(a.alias.len(), 16 * 48 * 16);
        let s = SamplingStrategy::Tabulated(Arc::new(t));
        let mut rng = SplitMix64::from_state(8);
        let v = dir(50.0, 0.3).as_vec3();
        let valid = (0..1000)
            .filter(|_| {
                let d = s.sample(v, [rng.next_f32(), rng.next_f32(), rng.next_f32()]);
                assert_eq!(d.pdf, s.pdf(v, d.light));
                d.pdf > 0.0
            })
            .count();
        assert!(valid > 800, "{valid}");
    }

    /// The probability of each bin under an alias table, summed the other way round (kept plus
    /// aliased-to), against the mass it was built from; zero-mass bins are never drawn.
    #[test]
    fn alias_tables_draw_each_bin_with_its_mass() {
        let mut rng = SplitMix64::from_state(11);
        let spiky: Vec<f64> = (0..1536)
            .map(|k| match k % 7 {
                0 => 0.0,
                1 => 1e3 * rng.next_f64(),
                _ => 1e-9 * rng.next_f64(),
            })
            .collect();
        let cases = [
            vec![1.0; 5],
            vec![0.0, 0.0, 3.0, 0.0],
            vec![1e-300, 1.0, 0.0, 1e-17, 2.0],
            spiky,
        ];
        for weights in cases {
            let total: f64 = weights.iter().sum();
            let mass: Vec<f64> = weights.iter().map(|w| w / total).collect();
            let (probability, alias) = alias_table(&mass);
            let n = mass.len() as f64;
            let mut drawn: Vec<f64> = probability.iter().map(|p| p / n).collect();
            for (k, (&p, &a)) in probability.iter().zip(&alias).enumerate() {
                assert!((0.0..=1.0).contains(&p));
                if a as usize != k {
                    drawn[a as usize] += (1.0 - p) / n;
                }
            }
            for (k, (&d, &m)) in drawn.iter().zip(&mass).enumerate() {
                assert!(
                    (d - m).abs() <= 1e-12 * m.max(1.0 / n),
                    "bin {k}: {d} vs {m}"
                );
                if m == 0.0 {
                    assert_eq!(d, 0.0, "bin {k} of mass 0 is drawn");
                }
            }
        }
    }

    #[test]
    fn bad_configs_are_errors() {
        let f = phong(0.5, 0.0, 1.0);
        for config in [
            TableConfig {
                rows: 0,
                ..TableConfig::default()
            },
            TableConfig {
                phi_bins: 0,
                ..TableConfig::default()
            },
            TableConfig {
                cosine_weight: 1.0,
                ..TableConfig::default()
            },
        ] {
            assert!(TabulatedSampler::build(&f, &config).is_err());
        }
        // A black material gives equal bin masses, still a density (part of its
        // mass reflects below the horizon).
        let black = |_: DVec3, _: DVec3| 0.0;
        let s = strategy(&black);
        let total = pdf_integral(&s, dir(20.0, 0.0));
        assert!(total > 0.3 && total <= 1.0 + 1e-3, "{total}");
    }
}
