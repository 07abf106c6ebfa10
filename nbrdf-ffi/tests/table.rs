//! The tabulated sampler (`NBRDF_SAMPLING_TABULATED`) as a C caller sees it: created from a
//! network and from a MERL table, its samples, pdfs and arrays against nbrdf-core's `tabulated`
//! module called directly, its pdf against a quadrature over the sphere and the rate of valid
//! samples, and bad calls (error status and message, no panic).
//!
//! The checks hold for any table size and cosine weight: they read the shape from
//! `nbrdf_sampler_info`, never from constants of nbrdf-core.

mod support;

use glam::Vec3;
use nbrdf_core::brdf::Brdf;
use nbrdf_core::rng::SplitMix64;
use nbrdf_core::sampling::tabulated::{TableConfig, TabulatedSampler};
use nbrdf_core::{Nbrdf, SamplingStrategy};
use nbrdf_ffi::*;
use std::f64::consts::TAU;
use std::ptr::{null, null_mut};
use std::sync::Arc;
use support::*;

fn tabulated() -> NbrdfSamplerParams {
    params(NbrdfSamplingKind::NBRDF_SAMPLING_TABULATED)
}

/// The tabulated sampler of `material`.
fn table_of(material: &Material) -> Sampler {
    sampler(material.ptr(), &tabulated())
}

/// The outputs of an `nbrdf_material_sample` call.
struct Samples {
    light: Vec<f32>,
    weight: Vec<f32>,
    pdf: Vec<f32>,
}

/// Samples `material` with `table` for planar `view` and `u`; asserts success.
fn sample(material: &Material, table: &Sampler, view: &[f32], u: &[f32]) -> Samples {
    let n = view.len() / 3;
    let mut s = Samples {
        light: vec![f32::NAN; 3 * n],
        weight: vec![f32::NAN; 3 * n],
        pdf: vec![f32::NAN; n],
    };
    // SAFETY: live handles, 3 n floats per array but the pdfs' n.
    let status = unsafe {
        nbrdf_material_sample(
            material.ptr(),
            table.ptr(),
            view.as_ptr(),
            u.as_ptr(),
            n,
            s.light.as_mut_ptr(),
            s.weight.as_mut_ptr(),
            s.pdf.as_mut_ptr(),
        )
    };
    assert_eq!(status, OK, "{}", last_error());
    s
}

/// `nbrdf_sampler_pdf` of planar `view` and `light` (`n` lanes).
fn table_pdf(table: &Sampler, view: &[f32], light: &[f32], n: usize) -> Vec<f32> {
    let mut pdf = vec![f32::NAN; n];
    // SAFETY: a live handle, 3 n floats per input and n for the output.
    let status =
        unsafe { nbrdf_sampler_pdf(table.0, view.as_ptr(), light.as_ptr(), n, pdf.as_mut_ptr()) };
    assert_eq!(status, OK, "{}", last_error());
    pdf
}

fn spherical(theta: f64, phi: f64) -> Vec3 {
    Vec3::new(
        (theta.sin() * phi.cos()) as f32,
        (theta.sin() * phi.sin()) as f32,
        theta.cos() as f32,
    )
}

/// Views over the hemisphere, from the normal to grazing, at several azimuths (the sampler
/// rotates with the view's azimuth).
fn views(n: usize) -> Vec<Vec3> {
    (0..n)
        .map(|i| {
            let t = (i as f64 + 0.5) / n as f64;
            spherical(t * 1.56, 2.39996 * i as f64)
        })
        .collect()
}

fn uniforms(n: usize, seed: u64) -> Vec<Vec3> {
    let mut rng = SplitMix64::from_state(seed);
    (0..n)
        .map(|_| Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()))
        .collect()
}

/// Shape, arrays, samples, weights and pdfs of a table built through the C ABI agree with
/// nbrdf-core's `TabulatedSampler` built from the same material; the pdf of each sample, asked
/// again, is the pdf the sample returned.
fn check_against_core(brdf: &dyn Brdf, material: &Material) {
    let table = &table_of(material);
    let core = TabulatedSampler::from_brdf(brdf, &TableConfig::default()).unwrap();
    let arrays = core.tables();

    let mut info = NbrdfSamplerInfo::default();
    // SAFETY: a live handle and a writable info.
    assert_eq!(unsafe { nbrdf_sampler_info(table.0, &mut info) }, OK);
    assert_eq!(
        info,
        NbrdfSamplerInfo {
            kind: NbrdfSamplingKind::NBRDF_SAMPLING_TABULATED as i32,
            rows: arrays.rows as u32,
            theta_bins: arrays.theta_bins as u32,
            phi_bins: arrays.phi_bins as u32,
            cosine_weight: arrays.cosine_weight as f32,
        }
    );
    check_arrays(table, &info, &arrays);

    let strategy = SamplingStrategy::Tabulated(Arc::new(core));
    let n = 512;
    let (vs, us) = (views(n), uniforms(n, 11));
    let (view, u) = (planar(vs.iter().copied()), planar(us.iter().copied()));
    let s = sample(material, table, &view, &u);
    let mut valid = 0;
    for i in 0..n {
        let expected = strategy.sample(vs[i], us[i].to_array());
        let light = lane(&s.light, n, i);
        assert_eq!(light, expected.light, "lane {i}");
        assert_eq!(s.pdf[i], expected.pdf, "lane {i}");
        let f = brdf.eval(vs[i], light);
        let cos = nbrdf_core::brdf::cos_theta_light(light);
        for (c, f) in f.iter().enumerate() {
            let w = s.weight[c * n + i];
            if expected.pdf > 0.0 {
                assert_close(w, f * cos / expected.pdf, &format!("lane {i} weight {c}"));
            } else {
                assert_eq!(w, 0.0, "lane {i}: an invalid sample has weight 0");
            }
        }
        valid += usize::from(expected.pdf > 0.0);
    }
    assert!(valid > n / 2, "{valid} valid samples of {n}");
    assert_eq!(table_pdf(table, &view, &s.light, n), s.pdf);

    // Light directions other than the samples, some of them below the horizon.
    let lights = uniforms(n, 12)
        .into_iter()
        .map(|r| spherical(f64::from(r.x).acos() * 2.0 - 0.3, f64::from(r.y) * TAU))
        .collect::<Vec<_>>();
    let pdf = table_pdf(table, &view, &planar(lights.iter().copied()), n);
    for i in 0..n {
        assert_eq!(pdf[i], strategy.pdf(vs[i], lights[i]), "lane {i}");
        if lights[i].z <= 0.0 {
            assert_eq!(pdf[i], 0.0, "lane {i} below the horizon");
        }
    }
}

/// `nbrdf_sampler_table` writes exactly the documented sizes, the core's values (probabilities
/// as float32), and per row a probability distribution whose alias table draws each bin with
/// its mass (counted the other way round: kept plus aliased to).
fn check_arrays(
    table: &Sampler,
    info: &NbrdfSamplerInfo,
    core: &nbrdf_core::sampling::tabulated::TableArrays,
) {
    let (rows, nt, np) = (
        info.rows as usize,
        info.theta_bins as usize,
        info.phi_bins as usize,
    );
    let len = rows * nt * np;
    // One sentinel past each documented size: the call must not write there.
    let mut mass = vec![-7.0f32; len + 1];
    let mut probability = vec![-7.0f32; len + 1];
    let mut alias = vec![u32::MAX; len + 1];
    // SAFETY: a live handle and buffers of the documented sizes.
    let status = unsafe {
        nbrdf_sampler_table(
            table.0,
            mass.as_mut_ptr(),
            probability.as_mut_ptr(),
            alias.as_mut_ptr(),
            len,
        )
    };
    assert_eq!(status, OK, "{}", last_error());
    for (buffer, expected) in [(&mass, &core.mass), (&probability, &core.alias_probability)] {
        let (values, sentinel) = buffer.split_at(len);
        assert_eq!(sentinel, [-7.0], "written past the documented size");
        let expected: Vec<f32> = expected.iter().map(|&v| v as f32).collect();
        assert_eq!(values, &expected[..]);
    }
    assert_eq!(alias[len], u32::MAX, "written past the documented size");
    assert_eq!(&alias[..len], &core.alias[..]);
    let row_len = nt * np;
    for r in 0..rows {
        let row = r * row_len..(r + 1) * row_len;
        let row_mass = &mass[row.clone()];
        let total: f64 = row_mass.iter().map(|&m| f64::from(m)).sum();
        assert!((total - 1.0).abs() < 1e-5, "row {r}: mass {total}");
        assert!(row_mass.iter().all(|&m| m >= 0.0));
        let mut drawn: Vec<f64> = probability[row.clone()]
            .iter()
            .map(|&p| f64::from(p) / row_len as f64)
            .collect();
        for (k, (&p, &a)) in probability[row.clone()].iter().zip(&alias[row]).enumerate() {
            assert!((0.0..=1.0).contains(&p), "row {r} bin {k}: {p}");
            assert!((a as usize) < row_len, "row {r} bin {k}: alias {a}");
            if a as usize != k {
                drawn[a as usize] += (1.0 - f64::from(p)) / row_len as f64;
            }
        }
        for (k, (&d, &m)) in drawn.iter().zip(row_mass).enumerate() {
            assert!(
                (d - f64::from(m)).abs() <= 1e-6,
                "row {r} bin {k}: drawn {d} vs mass {m}"
            );
        }
    }
}

/// `int pdf(l) dl` over the whole sphere by the midpoint rule in `(cos theta, phi)` (the
/// directions below the horizon included: the pdf must be 0 there), through `nbrdf_sampler_pdf`.
fn sphere_integral(table: &Sampler, view: Vec3) -> f64 {
    let (n_cos, n_phi) = (500, 1000);
    let lights: Vec<Vec3> = (0..n_cos * n_phi)
        .map(|k| {
            let (a, b) = (k / n_phi, k % n_phi);
            let cos = -1.0 + 2.0 * (a as f64 + 0.5) / n_cos as f64;
            spherical(cos.acos(), TAU * (b as f64 + 0.5) / n_phi as f64)
        })
        .collect();
    let n = lights.len();
    let view = planar(std::iter::repeat(view).take(n));
    let pdf = table_pdf(table, &view, &planar(lights.iter().copied()), n);
    let cell = 2.0 / n_cos as f64 * TAU / n_phi as f64;
    let mut total = 0.0;
    for (l, &p) in lights.iter().zip(&pdf) {
        assert!(p.is_finite() && p >= 0.0, "pdf {p} at {l}");
        if l.z <= 0.0 {
            assert_eq!(p, 0.0, "pdf below the horizon at {l}");
        }
        total += f64::from(p) * cell;
    }
    total
}

/// The pdf integrates over the sphere to the probability that a sample is valid (samples whose
/// half vector reflects below the horizon have pdf 0), which is close to 1; that rate is
/// measured from `nbrdf_material_sample`.
fn check_pdf_integral(material: &Material) {
    let table = &table_of(material);
    for view in [
        spherical(0.15, 0.4),
        spherical(0.8, 2.0),
        spherical(1.3, -1.0),
    ] {
        let integral = sphere_integral(table, view);
        let m = 100_000;
        let u = planar(uniforms(m, 21).into_iter());
        let s = sample(
            material,
            table,
            &planar(std::iter::repeat(view).take(m)),
            &u,
        );
        let rate = s.pdf.iter().filter(|&&p| p > 0.0).count() as f64 / m as f64;
        let sigma = (rate * (1.0 - rate) / m as f64).sqrt();
        assert!(
            (integral - rate).abs() < 4.0 * sigma + 1e-3,
            "view {view}: integral {integral}, valid samples {rate} +- {sigma}"
        );
        assert!(
            integral > 0.98 && integral < 1.001,
            "view {view}: {integral}"
        );
    }
}

#[test]
fn network_tables_agree_with_the_core() {
    let (network, path) = load_network(5);
    check_against_core(&Nbrdf::load(&path).unwrap(), &network);
}

#[test]
fn merl_tables_agree_with_the_core() {
    let (merl, core) = load_smooth_merl();
    check_against_core(&core, &merl);
}

#[test]
fn network_table_pdf_integrates_to_the_valid_sample_rate() {
    check_pdf_integral(&load_network(5).0);
}

#[test]
fn merl_table_pdf_integrates_to_the_valid_sample_rate() {
    check_pdf_integral(&load_smooth_merl().0);
}

/// One table serves another material's sampling too (the table is only a density): the weights
/// are then those of the other material.
#[test]
fn a_table_samples_any_material() {
    let (network, path) = load_network(5);
    let (merl, merl_core) = load_smooth_merl();
    let table = table_of(&network);
    let n = 64;
    let (view, u) = (
        planar(views(n).into_iter()),
        planar(uniforms(n, 5).into_iter()),
    );
    let from_network = sample(&network, &table, &view, &u);
    let from_merl = sample(&merl, &table, &view, &u);
    assert_eq!(from_network.light, from_merl.light);
    assert_eq!(from_network.pdf, from_merl.pdf);
    let network_core = Nbrdf::load(&path).unwrap();
    for i in (0..n).filter(|&i| from_merl.pdf[i] > 0.0) {
        let (v, l) = (lane(&view, n, i), lane(&from_merl.light, n, i));
        let cos = nbrdf_core::brdf::cos_theta_light(l);
        for (weights, brdf) in [
            (&from_network.weight, &network_core as &dyn Brdf),
            (&from_merl.weight, &merl_core),
        ] {
            let f = brdf.eval(v, l);
            for c in 0..3 {
                let expected = f[c] * cos / from_merl.pdf[i];
                assert_close(
                    weights[c * n + i],
                    expected,
                    &format!("lane {i} channel {c}"),
                );
            }
        }
    }
}

/// Directions that are not finite or not above the horizon are invalid lanes (pdf 0, weight 0),
/// as with every other sampler: the call succeeds, and so do the other lanes of the batch. NaN
/// uniforms are clamped like any out-of-range uniform (the core's `sample`).
#[test]
fn non_finite_lanes_are_invalid_samples_not_failures() {
    let (network, path) = load_network(5);
    let table = table_of(&network);
    let core =
        TabulatedSampler::from_brdf(&Nbrdf::load(&path).unwrap(), &TableConfig::default()).unwrap();
    let strategy = SamplingStrategy::Tabulated(Arc::new(core));
    let nan = f32::NAN;
    let views = [
        Vec3::new(nan, 0.0, 1.0),
        Vec3::new(0.0, 0.0, f32::INFINITY),
        Vec3::new(0.3, 0.1, -0.9),
        Vec3::ZERO,
        Vec3::new(0.3, 0.1, 0.9),
        Vec3::new(0.3, 0.1, 0.9),
    ];
    let us = [
        Vec3::splat(0.5),
        Vec3::splat(0.5),
        Vec3::splat(0.5),
        Vec3::splat(0.5),
        Vec3::new(nan, nan, nan),
        Vec3::new(0.7, 0.2, 0.9),
    ];
    let n = views.len();
    let (view, u) = (planar(views.into_iter()), planar(us.into_iter()));
    let s = sample(&network, &table, &view, &u);
    for i in 0..4 {
        assert_eq!(s.pdf[i], 0.0, "lane {i}");
        assert!((0..3).all(|c| s.weight[c * n + i] == 0.0), "lane {i}");
    }
    for i in 4..n {
        let expected = strategy.sample(views[i], us[i].to_array());
        assert_eq!(lane(&s.light, n, i), expected.light, "lane {i}");
        assert_eq!(s.pdf[i], expected.pdf, "lane {i}");
        assert!((0..3).all(|c| s.weight[c * n + i].is_finite()), "lane {i}");
    }
    let lights = [
        Vec3::new(nan, 0.0, 1.0),
        Vec3::new(0.0, nan, 1.0),
        Vec3::new(0.0, 0.0, f32::INFINITY),
        Vec3::new(0.0, 0.0, -1.0),
        Vec3::ZERO,
        Vec3::Z,
    ];
    let pdf = table_pdf(&table, &view, &planar(lights.into_iter()), n);
    for i in 0..n {
        assert_eq!(pdf[i], strategy.pdf(views[i], lights[i]), "lane {i}");
        assert!(pdf[i].is_finite(), "lane {i}");
    }
    assert!(pdf[..5].iter().all(|&p| p == 0.0), "{pdf:?}");
    assert!(pdf[5] > 0.0);
}

#[test]
fn null_pointers_name_the_argument() {
    let (network, _) = load_network(4);
    let table = table_of(&network);
    let tab = table.ptr();
    let check = |status: i32, argument: &str| {
        assert_eq!(status, NULL, "argument {argument}: {}", last_error());
        let message = last_error();
        assert!(message.contains(&format!("`{argument}`")), "{message}");
    };
    let mut buf = [0.0_f32; 1];
    let bp = buf.as_mut_ptr();
    let mut alias_buffer = [0_u32; 1];
    let ap = alias_buffer.as_mut_ptr();
    // SAFETY: every pointer is null or valid; the calls fail before touching the arrays' sizes.
    unsafe {
        // A failed create leaves NULL in `*out`, never a stale pointer.
        let mut out = 1 as *mut NbrdfSampler;
        check(
            nbrdf_sampler_create(null(), &tabulated(), &mut out),
            "material",
        );
        assert!(out.is_null());
        assert!(last_error().contains("tabulated"), "{}", last_error());
        check(nbrdf_sampler_table(null(), bp, bp, ap, 1), "sampler");
        check(nbrdf_sampler_table(tab, null_mut(), bp, ap, 1), "out_mass");
        check(
            nbrdf_sampler_table(tab, bp, null_mut(), ap, 1),
            "out_alias_probability",
        );
        check(nbrdf_sampler_table(tab, bp, bp, null_mut(), 1), "out_alias");
    }
}

#[test]
fn bad_sizes_kinds_and_alignment_are_invalid_arguments() {
    let (network, _) = load_network(4);
    let table = table_of(&network);
    let buf = [0.0_f32; 8];
    let mut out = [0.0_f32; 8];
    let (b, o) = (buf.as_ptr(), out.as_mut_ptr());
    let misaligned = b.cast::<u8>().wrapping_add(1).cast::<f32>();
    let huge = usize::MAX / 2;
    let mut info = NbrdfSamplerInfo::default();
    // SAFETY: a live handle and a writable info.
    assert_eq!(unsafe { nbrdf_sampler_info(table.0, &mut info) }, OK);
    let len = (info.rows * info.theta_bins * info.phi_bins) as usize;
    let (mut mass, mut probability, mut alias) =
        (vec![7.0f32; len], vec![7.0f32; len], vec![7u32; len]);
    let (mp, pp, ap) = (
        mass.as_mut_ptr(),
        probability.as_mut_ptr(),
        alias.as_mut_ptr(),
    );
    let cosine = sampler(null(), &params(NbrdfSamplingKind::NBRDF_SAMPLING_COSINE));
    // SAFETY: every call is rejected before any array is read or written.
    unsafe {
        assert_eq!(nbrdf_sampler_pdf(table.0, b, b, huge, o), INVALID);
        assert!(
            last_error().starts_with("nbrdf_sampler_pdf: "),
            "{}",
            last_error()
        );
        assert_eq!(
            nbrdf_material_sample(network.0, table.0, b, b, huge, o, o, o),
            INVALID
        );
        assert!(
            last_error().starts_with("nbrdf_material_sample: "),
            "{}",
            last_error()
        );
        assert_eq!(nbrdf_sampler_pdf(table.0, misaligned, b, 1, o), INVALID);
        assert!(last_error().contains("`view`"), "{}", last_error());
        let misaligned_table = table.0.cast::<u8>().wrapping_add(1).cast::<NbrdfSampler>();
        assert_eq!(nbrdf_sampler_pdf(misaligned_table, b, b, 1, o), INVALID);
        assert!(last_error().contains("`sampler`"), "{}", last_error());
        // The arrays' length must be the table's.
        for wrong in [0, len - 1, len + 1] {
            assert_eq!(nbrdf_sampler_table(table.0, mp, pp, ap, wrong), INVALID);
            assert!(last_error().contains("`len`"), "{}", last_error());
        }
        // Other kinds have no table.
        assert_eq!(nbrdf_sampler_table(cosine.0, mp, pp, ap, len), INVALID);
        assert!(last_error().contains("no table"), "{}", last_error());
        // Empty batches touch nothing and succeed.
        assert_eq!(nbrdf_sampler_pdf(table.0, b, b, 0, o), OK);
        assert_eq!(
            nbrdf_material_sample(network.0, table.0, b, b, 0, o, o, o),
            OK
        );
    }
    // A refused call writes nothing.
    assert!(mass.iter().chain(&probability).all(|&v| v == 7.0));
    assert!(alias.iter().all(|&v| v == 7));
}

/// A file whose sampling names `tabulated` as its default reports kind 4, the kind
/// `nbrdf_sampler_create` tabulates the material for; a file naming none reports -1.
#[test]
fn the_default_sampling_may_be_tabulated() {
    let text = network_json(4).replace(
        r#""source": "manual"}"#,
        r#""source": "manual", "default": "tabulated"}"#,
    );
    let (tabulated, _) = load_network_text(&text, "default-tabulated");
    let (plain, _) = load_network(4);
    assert_eq!(
        tabulated.info().default_sampling,
        NbrdfSamplingKind::NBRDF_SAMPLING_TABULATED as i32
    );
    assert_eq!(plain.info().default_sampling, -1);
}

/// A sampler is immutable: threads sampling and evaluating the same handles at once get what
/// one thread gets alone.
#[test]
fn one_table_serves_many_threads() {
    let (network, _) = load_network(4);
    let table = table_of(&network);
    let n = 256;
    let (view, u) = (
        planar(views(n).into_iter()),
        planar(uniforms(n, 9).into_iter()),
    );
    let alone = sample(&network, &table, &view, &u);
    std::thread::scope(|scope| {
        let handles: Vec<_> = (0..4)
            .map(|_| scope.spawn(|| sample(&network, &table, &view, &u)))
            .collect();
        for handle in handles {
            let s = handle.join().unwrap();
            assert_eq!((s.light, s.pdf), (alone.light.clone(), alone.pdf.clone()));
        }
    });
}
