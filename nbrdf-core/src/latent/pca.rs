//! The PCA baseline of the autoencoder (Nielsen, Jensen and Ramamoorthi 2015, "On optimal, minimal
//! BRDF sampling for reflectance acquisition"): tables mapped to
//! `ln((f cos_l cos_v + eps) / (f_med cos_l cos_v + eps))` relative to the per-cell median
//! `f_med` of the training materials, centred, and reduced to 32 principal components.
//!
//! Exactness and cost: with 80 training materials the principal directions are combinations of
//! the centred training rows, so the PCA is computed exactly from the 80 x 80 Gram matrix
//! `K = X X^T` (eigenvectors `a_k`, eigenvalues `l_k`; direction `u_k = X^T a_k / sqrt(l_k)`).
//! A reconstruction is `mu + X^T beta` with `beta = sum_k (u_k . (y - mu)) a_k / sqrt(l_k)`.
//! The rows are not the full 1.46M-cell tables but a fixed cell subset: the MERL grid at strides
//! (1, 2, 4) in (theta_h, theta_d, phi_d) - every theta_h, where highlights live - plus every
//! cell that the evaluation sphere looks up, cells with a direction below the horizon dropped.
//! The same subset is used for every material, so this is exact PCA of the tables restricted to
//! those cells; reconstructions are evaluated on the sphere's cells (nearest-cell lookup), in the
//! same image space as the autoencoder.

use crate::coords::{from_rusinkiewicz, to_rusinkiewicz};
use crate::merl::{self, N_PHI_D, N_THETA_D, N_THETA_H};
use crate::metrics::{self, Image};
use rayon::prelude::*;

/// `eps` of the log mapping (Nielsen et al.: 1e-3).
pub const EPS: f64 = 1e-3;
pub const COMPONENTS: usize = 32;

/// One lit pixel of the evaluation sphere: its cell and `cos(theta_l)`.
#[derive(Clone, Copy, Debug)]
struct Pixel {
    index: usize,
    cell: usize,
    cos: f64,
}

/// The evaluation sphere's lit pixels (the geometry of [`crate::metrics::render_sphere`]).
fn sphere_pixels(size: usize, light_theta: f64) -> Vec<Pixel> {
    metrics::sphere_pixels(size, light_theta)
        .into_iter()
        .filter(|p| p.light.z > 0.0 && p.view.z > 0.0)
        .map(|p| {
            let idx =
                merl::continuous_index(&to_rusinkiewicz(p.view.as_dvec3(), p.light.as_dvec3()));
            let cell = merl::cell_index(
                (idx[0].floor().max(0.0) as usize).min(N_THETA_H - 1),
                (idx[1].floor().max(0.0) as usize).min(N_THETA_D - 1),
                (idx[2].floor() as i64).rem_euclid(N_PHI_D as i64) as usize,
            );
            Pixel {
                index: p.index,
                cell,
                cos: p.light.z as f64,
            }
        })
        .collect()
}

/// `cos_l cos_v` at a cell centre, `None` below the horizon.
fn cell_cos_product(cell: usize) -> Option<f64> {
    let (h, d, p) = merl::cell_coordinates(cell);
    let (v, l) = from_rusinkiewicz(&merl::cell_centre_angles(h, d, p));
    (l.z > 0.0 && v.z > 0.0).then_some(l.z * v.z)
}

/// The cell subset (sorted, unique) for an evaluation sphere.
pub fn cell_subset(size: usize, light_theta: f64) -> Vec<usize> {
    let mut cells: Vec<usize> = Vec::new();
    for h in 0..N_THETA_H {
        for d in (0..N_THETA_D).step_by(2) {
            for p in (0..N_PHI_D).step_by(4) {
                cells.push(merl::cell_index(h, d, p));
            }
        }
    }
    cells.extend(sphere_pixels(size, light_theta).iter().map(|p| p.cell));
    cells.sort_unstable();
    cells.dedup();
    cells.retain(|&c| cell_cos_product(c).is_some());
    cells
}

/// The value of a material at a cell centre (`f_r`, linear RGB).
pub type CellValues<'a> = dyn Fn(usize) -> [f64; 3] + Sync + 'a;

/// A fitted PCA baseline.
pub struct Pca {
    pub cells: Vec<usize>,
    cos: Vec<f64>,
    /// Per cell and channel, `3 * cells`.
    median: Vec<f64>,
    mean: Vec<f64>,
    /// Centred mapped training rows.
    rows: Vec<Vec<f32>>,
    /// `(eigenvalue, eigenvector)` of the Gram matrix, largest first, `components` of them.
    eigen: Vec<(f64, Vec<f64>)>,
    size: usize,
    light_theta: f64,
}

fn values_on(cells: &[usize], f: &CellValues<'_>) -> Vec<f64> {
    let mut out = vec![0.0; 3 * cells.len()];
    out.par_chunks_mut(3)
        .zip(cells.par_iter())
        .for_each(|(o, &c)| {
            let v = f(c);
            for k in 0..3 {
                o[k] = if v[k].is_finite() { v[k].max(0.0) } else { 0.0 };
            }
        });
    out
}

impl Pca {
    /// Fits on the training materials (their cell values), `components` components.
    pub fn fit(
        train: &[&CellValues<'_>],
        components: usize,
        size: usize,
        light_theta: f64,
    ) -> Self {
        let cells = cell_subset(size, light_theta);
        let cos: Vec<f64> = cells
            .iter()
            .map(|&c| cell_cos_product(c).unwrap_or(0.0))
            .collect();
        let raw: Vec<Vec<f64>> = train.iter().map(|f| values_on(&cells, *f)).collect();
        let dims = 3 * cells.len();
        let n = raw.len();
        let median: Vec<f64> = (0..dims)
            .into_par_iter()
            .map(|j| {
                let mut col: Vec<f64> = raw.iter().map(|r| r[j]).collect();
                col.sort_by(f64::total_cmp);
                if n % 2 == 1 {
                    col[n / 2]
                } else {
                    0.5 * (col[n / 2 - 1] + col[n / 2])
                }
            })
            .collect();
        let mut pca = Pca {
            cells,
            cos,
            median,
            mean: vec![0.0; dims],
            rows: Vec::new(),
            eigen: Vec::new(),
            size,
            light_theta,
        };
        let mapped: Vec<Vec<f64>> = raw.iter().map(|r| pca.map(r)).collect();
        for j in 0..dims {
            pca.mean[j] = mapped.iter().map(|m| m[j]).sum::<f64>() / n as f64;
        }
        pca.rows = mapped
            .iter()
            .map(|m| {
                m.iter()
                    .zip(&pca.mean)
                    .map(|(x, mu)| (x - mu) as f32)
                    .collect()
            })
            .collect();
        let mut gram = vec![0.0f64; n * n];
        let pairs: Vec<(usize, usize)> = (0..n).flat_map(|i| (i..n).map(move |j| (i, j))).collect();
        let dots: Vec<f64> = pairs
            .par_iter()
            .map(|&(i, j)| {
                pca.rows[i]
                    .iter()
                    .zip(&pca.rows[j])
                    .map(|(a, b)| *a as f64 * *b as f64)
                    .sum()
            })
            .collect();
        for (&(i, j), &d) in pairs.iter().zip(&dots) {
            gram[i * n + j] = d;
            gram[j * n + i] = d;
        }
        let mut eigen = jacobi_eigen(&gram, n);
        eigen.retain(|(l, _)| *l > 1e-9 * eigen_max(&gram, n));
        eigen.truncate(components);
        pca.eigen = eigen;
        pca
    }

    pub fn components(&self) -> usize {
        self.eigen.len()
    }

    fn map(&self, raw: &[f64]) -> Vec<f64> {
        raw.iter()
            .enumerate()
            .map(|(j, &f)| {
                let c = self.cos[j / 3];
                ((f * c + EPS) / (self.median[j] * c + EPS)).ln()
            })
            .collect()
    }

    fn unmap(&self, j: usize, y: f64) -> f64 {
        let c = self.cos[j / 3];
        (((self.median[j] * c + EPS) * y.exp() - EPS) / c).max(0.0)
    }

    /// The reconstruction of a material on the cell subset (`f_r`, `3 * cells`).
    pub fn reconstruct(&self, material: &CellValues<'_>) -> Vec<f64> {
        let y = self.map(&values_on(&self.cells, material));
        let centred: Vec<f64> = y.iter().zip(&self.mean).map(|(a, m)| a - m).collect();
        // X y: one dot product per training row.
        let xy: Vec<f64> = self
            .rows
            .par_iter()
            .map(|r| r.iter().zip(&centred).map(|(a, b)| *a as f64 * b).sum())
            .collect();
        let n = self.rows.len();
        let mut beta = vec![0.0f64; n];
        for (l, a) in &self.eigen {
            // c_k = u_k . y = a_k . (X y) / sqrt(l_k); beta += c_k a_k / sqrt(l_k).
            let c = a.iter().zip(&xy).map(|(a, b)| a * b).sum::<f64>() / l;
            for (b, ai) in beta.iter_mut().zip(a) {
                *b += c * ai;
            }
        }
        (0..self.mean.len())
            .into_par_iter()
            .map(|j| {
                let y = self.mean[j]
                    + self
                        .rows
                        .iter()
                        .zip(&beta)
                        .map(|(r, b)| r[j] as f64 * b)
                        .sum::<f64>();
                self.unmap(j, y)
            })
            .collect()
    }

    /// The evaluation sphere of values on the cell subset (nearest-cell lookup), as
    /// [`crate::metrics::render_sphere`] renders a table.
    pub fn render(&self, values: &[f64]) -> Image {
        let n = self.size * self.size;
        let mut rgb: [Vec<f32>; 3] = std::array::from_fn(|_| vec![0.0f32; n]);
        for p in sphere_pixels(self.size, self.light_theta) {
            if let Ok(at) = self.cells.binary_search(&p.cell) {
                for (k, plane) in rgb.iter_mut().enumerate() {
                    plane[p.index] = (values[3 * at + k] * p.cos) as f32;
                }
            }
        }
        Image {
            size: self.size,
            rgb,
        }
    }

    /// A material's own values on the cell subset.
    pub fn values(&self, material: &CellValues<'_>) -> Vec<f64> {
        values_on(&self.cells, material)
    }
}

fn eigen_max(m: &[f64], n: usize) -> f64 {
    (0..n).map(|i| m[i * n + i]).fold(0.0, f64::max)
}

/// Eigen-decomposition of a symmetric `n x n` matrix by cyclic Jacobi rotations: pairs
/// `(eigenvalue, unit eigenvector)`, largest eigenvalue first.
pub fn jacobi_eigen(m: &[f64], n: usize) -> Vec<(f64, Vec<f64>)> {
    let mut a = m.to_vec();
    let mut v = vec![0.0f64; n * n];
    for i in 0..n {
        v[i * n + i] = 1.0;
    }
    for _sweep in 0..100 {
        let off: f64 = (0..n)
            .flat_map(|i| (0..n).filter(move |&j| j != i).map(move |j| (i, j)))
            .map(|(i, j)| a[i * n + j] * a[i * n + j])
            .sum();
        let scale: f64 = (0..n).map(|i| a[i * n + i] * a[i * n + i]).sum();
        if off <= 1e-24 * scale.max(f64::MIN_POSITIVE) {
            break;
        }
        for p in 0..n {
            for q in p + 1..n {
                let apq = a[p * n + q];
                if apq.abs() < 1e-300 {
                    continue;
                }
                let theta = (a[q * n + q] - a[p * n + p]) / (2.0 * apq);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for k in 0..n {
                    let (akp, akq) = (a[k * n + p], a[k * n + q]);
                    a[k * n + p] = c * akp - s * akq;
                    a[k * n + q] = s * akp + c * akq;
                }
                for k in 0..n {
                    let (apk, aqk) = (a[p * n + k], a[q * n + k]);
                    a[p * n + k] = c * apk - s * aqk;
                    a[q * n + k] = s * apk + c * aqk;
                }
                for k in 0..n {
                    let (vkp, vkq) = (v[k * n + p], v[k * n + q]);
                    v[k * n + p] = c * vkp - s * vkq;
                    v[k * n + q] = s * vkp + c * vkq;
                }
            }
        }
    }
    let mut out: Vec<(f64, Vec<f64>)> = (0..n)
        .map(|i| (a[i * n + i], (0..n).map(|k| v[k * n + i]).collect()))
        .collect();
    out.sort_by(|x, y| y.0.total_cmp(&x.0));
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn jacobi_diagonalises() {
        let m = [4.0, 1.0, 0.5, 1.0, 3.0, 0.2, 0.5, 0.2, 1.0];
        let e = jacobi_eigen(&m, 3);
        for (l, v) in &e {
            for i in 0..3 {
                let mv: f64 = (0..3).map(|k| m[i * 3 + k] * v[k]).sum();
                assert!((mv - l * v[i]).abs() < 1e-9);
            }
        }
        assert!(e[0].0 >= e[1].0 && e[1].0 >= e[2].0);
    }

    #[test]
    fn reconstructs_a_training_material_exactly_and_a_mix_well() {
        // Materials spanned by two "basis" reflectances in log space: PCA with 3 components
        // recovers a training member exactly.
        let make = |a: f64, b: f64| {
            move |cell: usize| {
                let (h, _, _) = merl::cell_coordinates(cell);
                let spec = (-(h as f64) / 10.0).exp();
                [a * 0.1 + b * spec, a * 0.2, b * spec + 0.05]
            }
        };
        let mats: Vec<Box<CellValues>> = (0..6)
            .map(|i| Box::new(make(0.5 + i as f64 * 0.3, 1.0 + (i % 3) as f64)) as Box<CellValues>)
            .collect();
        let refs: Vec<&CellValues> = mats.iter().map(|b| b.as_ref()).collect();
        let pca = Pca::fit(&refs, 5, 8, 45f64.to_radians());
        let truth = pca.values(refs[2]);
        let rec = pca.reconstruct(refs[2]);
        for (a, b) in truth.iter().zip(&rec) {
            assert!((a - b).abs() < 1e-4 * (1.0 + a.abs()), "{a} {b}");
        }
    }
}
