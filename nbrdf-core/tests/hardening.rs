//! Hardening, the library side: what is refused (docs/hardening.md) and property
//! tests over degenerate directions. Each refusal is checked by its message, which names the
//! file, the position or the limit; each acceptance next to it by a value just inside.

use glam::Vec3;
use nbrdf_core::brdf::{Brdf, Directions, DirectionsMut, RgbMut};
use nbrdf_core::merl::{CELLS, NOT_MEASURED, SCALE};
use nbrdf_core::network::parameter_count_for;
use nbrdf_core::sampling::{self, SamplingStrategy, MAX_EXPONENT};
use nbrdf_core::{MerlTable, Nbrdf, NbrdfError};
use proptest::prelude::*;
use std::path::Path;
use std::sync::OnceLock;

fn merl_bytes(stored: &[f64]) -> Vec<u8> {
    let mut bytes: Vec<u8> = [90i32, 90, 180]
        .iter()
        .flat_map(|h| h.to_le_bytes())
        .collect();
    bytes.extend(stored.iter().flat_map(|v| v.to_le_bytes()));
    bytes
}

fn message<T: std::fmt::Debug>(result: nbrdf_core::Result<T>) -> String {
    result.expect_err("must be refused").to_string()
}

#[test]
fn exponents_above_the_cap_are_refused_by_every_path() {
    let bp = |exponent| SamplingStrategy::Phong {
        exponent,
        specular_weight: 0.5,
    };
    assert_eq!(MAX_EXPONENT, 1e6);
    assert!(bp(MAX_EXPONENT).validated().is_ok());
    let m = message(bp(2e6).validated());
    assert!(m.contains("1e6"), "{m}");
    // Through a network's stored sampling: the file names the problem and the limit.
    let net = Nbrdf::from_flat("n", 4, &vec![0.1; parameter_count_for(4)]).unwrap();
    let mut doc: serde_json::Value = serde_json::from_str(&net.to_json_string()).unwrap();
    doc["sampling"] = serde_json::json!({"model": "blinn-phong", "exponent": 2e6,
                                         "specular_weight": 0.5, "source": "manual"});
    let m = message(Nbrdf::from_json_str(
        &doc.to_string(),
        Path::new("x.nbrdf.json"),
    ));
    assert!(m.starts_with("x.nbrdf.json: ") && m.contains("1e6"), "{m}");
    doc["sampling"]["exponent"] = 1e6.into();
    assert!(Nbrdf::from_json_str(&doc.to_string(), Path::new("x")).is_ok());
}

#[test]
fn tables_are_checked_in_the_precision_they_are_rendered_in() {
    let mut stored = vec![1.0; 3 * CELLS];
    // Green: finite in float64, but 1e300 x 1.15/1500 is far beyond float32.
    stored[CELLS + 5] = 1e300;
    let m = message(MerlTable::from_bytes(
        &merl_bytes(&stored),
        Path::new("huge.binary"),
    ));
    assert!(m.starts_with("huge.binary: value 1e300"), "{m}");
    assert!(m.contains("green channel") && m.contains("float32"), "{m}");
    assert!(message(MerlTable::from_stored(stored.clone())).contains("float32"));
    // Just inside float32 once scaled: accepted.
    stored[CELLS + 5] = f64::from(f32::MAX) / SCALE[1] * 0.999;
    assert!(MerlTable::from_stored(stored).is_ok());
}

#[test]
fn tables_without_a_valid_cell_are_refused() {
    let mut stored = vec![NOT_MEASURED; 3 * CELLS];
    let m = message(MerlTable::from_bytes(
        &merl_bytes(&stored),
        Path::new("empty.binary"),
    ));
    assert!(m.starts_with("empty.binary: no valid cell"), "{m}");
    // Two channels valid in every cell but never the third: still no valid cell.
    stored[..2 * CELLS].fill(1.0);
    assert!(message(MerlTable::from_stored(stored.clone())).contains("no valid cell"));
    stored[2 * CELLS + 7] = 0.0;
    assert!(MerlTable::from_stored(stored).is_ok());
}

#[test]
fn json_given_as_a_table_is_named() {
    let m = message(MerlTable::from_bytes(
        b"  {\"format\": \"nbrdf\"}",
        Path::new("n.json"),
    ));
    assert!(
        m.contains("this is JSON") && m.contains("not a MERL table"),
        "{m}"
    );
    // A binary file that merely starts with "{" is still described by its header.
    let m = message(MerlTable::from_bytes(&[1u8; 20], Path::new("b")));
    assert!(m.contains("header is"), "{m}");
}

#[test]
fn non_finite_json_tokens_are_named_with_their_position() {
    for (text, token, at) in [
        ("{\"a\": [1,\n NaN]}", "NaN", "line 2 column 2"),
        ("{\"a\": Infinity}", "Infinity", "line 1 column 7"),
        ("{\"a\": -Infinity}", "Infinity", "line 1 column"),
    ] {
        let m = message(Nbrdf::from_json_str(text, Path::new("w.json")));
        assert!(
            m.contains(&format!("{token} is not valid JSON")) && m.contains(at),
            "{m}"
        );
    }
    // Other syntax errors are not blamed on NaN.
    let m = message(Nbrdf::from_json_str("{\"a\": [1,", Path::new("w.json")));
    assert!(
        m.contains("not valid JSON (truncated") && !m.contains("NaN"),
        "{m}"
    );
}

#[test]
fn special_and_misdirected_files_are_refused_without_reading_them() {
    let dir = std::env::temp_dir().join(format!("nbrdf-hardening-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    // A directory, and on Unix a FIFO (opening it would block) and /dev/zero (endless).
    let mut specials = vec![dir.clone()];
    #[cfg(unix)]
    {
        let fifo = dir.join("fifo");
        let made = std::process::Command::new("mkfifo").arg(&fifo).status();
        if made.is_ok_and(|s| s.success()) {
            specials.push(fifo);
        }
        specials.push("/dev/zero".into());
    }
    for path in &specials {
        for m in [message(MerlTable::read(path)), message(Nbrdf::load(path))] {
            assert!(
                m.contains("not a regular file") || m.contains("a directory"),
                "{m}"
            );
        }
    }
    // A MERL table given as a network.
    let table = dir.join("t.binary");
    let mut stored = vec![0.5; 3 * CELLS];
    stored[0] = NOT_MEASURED;
    MerlTable::from_stored(stored)
        .unwrap()
        .write(&table)
        .unwrap();
    let m = message(Nbrdf::load(&table));
    assert!(
        m.contains("this is a MERL table (binary), not an NBRDF network JSON"),
        "{m}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn the_json_size_cap_is_checked_before_reading() {
    let dir = std::env::temp_dir().join(format!("nbrdf-hardening-big-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let big = dir.join("big.nbrdf.json");
    // A sparse file: its size is past the cap, nothing is written or read.
    let file = std::fs::File::create(&big).unwrap();
    file.set_len(nbrdf_core::error::MAX_JSON_BYTES + 1).unwrap();
    let m = message(Nbrdf::load(&big));
    assert!(m.contains("more than the"), "{m}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn usage_errors_are_their_own_kind() {
    use nbrdf_core::ops::limits;
    let e = limits::check_range("--resolution", 100_000, 1, limits::MAX_RESOLUTION).unwrap_err();
    assert!(matches!(e, NbrdfError::Usage(_)));
}

// ---------------------------------------------------------------------------------------------
// Property tests: degenerate directions never give NaN or negative values, and the single and
// batched paths agree.

/// A direction that is anything but a nice unit vector: zero, NaN, infinite, huge, tiny, below
/// the horizon, or just unnormalised.
fn degenerate_direction() -> impl Strategy<Value = Vec3> {
    let component = prop_oneof![
        Just(0.0f32),
        Just(f32::NAN),
        Just(f32::INFINITY),
        Just(f32::NEG_INFINITY),
        Just(f32::MAX),
        Just(-f32::MAX),
        Just(f32::MIN_POSITIVE),
        Just(1e-30f32),
        -2.0f32..2.0,
        -1e20f32..1e20,
    ];
    [component.clone(), component.clone(), component].prop_map(Vec3::from_array)
}

fn unit_direction() -> impl Strategy<Value = Vec3> {
    (-1.0f32..1.0, -1.0f32..1.0, -1.0f32..1.0)
        .prop_filter("non-zero", |(x, y, z)| x * x + y * y + z * z > 1e-6)
        .prop_map(|(x, y, z)| Vec3::new(x, y, z).normalize())
}

fn any_direction() -> impl Strategy<Value = Vec3> {
    prop_oneof![degenerate_direction(), unit_direction()]
}

fn test_network() -> &'static Nbrdf {
    static NET: OnceLock<Nbrdf> = OnceLock::new();
    NET.get_or_init(|| {
        let n = parameter_count_for(6);
        let params: Vec<f32> = (0..n)
            .map(|i| ((i * 37 % 19) as f32 - 9.0) * 0.05)
            .collect();
        Nbrdf::from_flat("p", 6, &params).unwrap()
    })
}

fn test_table() -> &'static MerlTable {
    static TABLE: OnceLock<MerlTable> = OnceLock::new();
    TABLE.get_or_init(|| {
        let stored: Vec<f64> = (0..3 * CELLS)
            .map(|k| {
                if k % 97 == 0 {
                    NOT_MEASURED
                } else {
                    (k % 13) as f64 * 0.1
                }
            })
            .collect();
        MerlTable::from_stored(stored).unwrap()
    })
}

fn sane(rgb: [f32; 3]) -> bool {
    rgb.iter().all(|x| x.is_finite() && *x >= 0.0)
}

/// `eval` times the clamped cosine of the normalised light, the contract of `eval_cos_batch`.
fn eval_cos(brdf: &dyn Brdf, view: Vec3, light: Vec3) -> [f32; 3] {
    let l = light.as_dvec3();
    let len = l.length();
    let cos = if l.is_finite() && len > 0.0 && len.is_finite() {
        (l.z / len).max(0.0)
    } else {
        0.0
    };
    brdf.eval(view, light).map(|f| (f64::from(f) * cos) as f32)
}

fn batch_eval_cos(brdf: &dyn Brdf, pairs: &[(Vec3, Vec3)]) -> Vec<[f32; 3]> {
    let n = pairs.len();
    let col = |f: &dyn Fn(&(Vec3, Vec3)) -> f32| pairs.iter().map(f).collect::<Vec<f32>>();
    let (vx, vy, vz) = (col(&|p| p.0.x), col(&|p| p.0.y), col(&|p| p.0.z));
    let (lx, ly, lz) = (col(&|p| p.1.x), col(&|p| p.1.y), col(&|p| p.1.z));
    let (mut r, mut g, mut b) = (vec![-1.0; n], vec![-1.0; n], vec![-1.0; n]);
    brdf.eval_cos_batch(
        Directions {
            x: &vx,
            y: &vy,
            z: &vz,
        },
        Directions {
            x: &lx,
            y: &ly,
            z: &lz,
        },
        RgbMut {
            r: &mut r,
            g: &mut g,
            b: &mut b,
        },
    );
    (0..n).map(|i| [r[i], g[i], b[i]]).collect()
}

fn close(a: [f32; 3], b: [f32; 3]) -> bool {
    a.iter()
        .zip(&b)
        .all(|(x, y)| (x - y).abs() <= 1e-4 * (1.0 + x.abs().max(y.abs())))
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn degenerate_directions_evaluate_sanely(
        pairs in prop::collection::vec((any_direction(), any_direction()), 1..16)
    ) {
        let (net, table) = (test_network(), test_table());
        for brdf in [net as &dyn Brdf, table as &dyn Brdf] {
            let batch = batch_eval_cos(brdf, &pairs);
            for (&(view, light), got) in pairs.iter().zip(&batch) {
                let single = brdf.eval(view, light);
                prop_assert!(sane(single), "eval({view}, {light}) = {single:?}");
                prop_assert!(sane(*got), "batch({view}, {light}) = {got:?}");
                let expected = eval_cos(brdf, view, light);
                prop_assert!(close(expected, *got), "({view}, {light}): {expected:?} vs {got:?}");
            }
        }
    }

    #[test]
    fn degenerate_directions_sample_sanely(
        view in any_direction(),
        light in any_direction(),
        u in [-0.5f32..1.5, -0.5f32..1.5, -0.5f32..1.5],
        exponent in prop_oneof![Just(0.0), Just(MAX_EXPONENT), 0.0f64..1e4],
        weight in 0.0f64..=1.0,
    ) {
        let table = test_table();
        for strategy in [
            SamplingStrategy::Uniform,
            SamplingStrategy::Cosine,
            SamplingStrategy::Phong { exponent, specular_weight: weight },
        ] {
            let pdf = strategy.pdf(view, light);
            prop_assert!(pdf.is_finite() && pdf >= 0.0, "{strategy:?} pdf({view}, {light}) = {pdf}");
            let s = strategy.sample(view, u);
            prop_assert!(s.light.is_finite() && s.pdf.is_finite() && s.pdf >= 0.0, "{s:?}");
            if s.pdf > 0.0 {
                prop_assert!((s.light.length() - 1.0).abs() < 1e-4 && s.light.z > 0.0);
                prop_assert_eq!(s.pdf, strategy.pdf(view, s.light));
            }
            // The batch functions agree with the single ones.
            let (vx, vy, vz) = ([view.x], [view.y], [view.z]);
            let (lx, ly, lz) = ([light.x], [light.y], [light.z]);
            let mut out = [-1.0f32];
            sampling::pdf_batch(
                &strategy,
                Directions { x: &vx, y: &vy, z: &vz },
                Directions { x: &lx, y: &ly, z: &lz },
                &mut out,
            );
            prop_assert_eq!(out[0], pdf);
            let (ux, uy, uz) = ([u[0]], [u[1]], [u[2]]);
            let (mut ox, mut oy, mut oz) = ([0.0f32], [0.0f32], [0.0f32]);
            let (mut r, mut g, mut b) = ([-1.0f32], [-1.0f32], [-1.0f32]);
            let mut bpdf = [-1.0f32];
            sampling::sample_batch(
                &strategy,
                table,
                Directions { x: &vx, y: &vy, z: &vz },
                Directions { x: &ux, y: &uy, z: &uz },
                DirectionsMut { x: &mut ox, y: &mut oy, z: &mut oz },
                RgbMut { r: &mut r, g: &mut g, b: &mut b },
                &mut bpdf,
            );
            prop_assert!(sane([r[0], g[0], b[0]]), "weight {:?}", [r[0], g[0], b[0]]);
            prop_assert_eq!(bpdf[0], s.pdf);
        }
    }
}

/// The six direction components of `pairs` (views' x, y, z, then lights'), component `k` cut to
/// its first `lengths[k]` lanes.
fn uneven_columns(pairs: &[(Vec3, Vec3)], lengths: [usize; 6]) -> [Vec<f32>; 6] {
    let component = |k: usize| -> Vec<f32> {
        pairs
            .iter()
            .take(lengths[k])
            .map(|(v, l)| if k < 3 { v[k] } else { l[k - 3] })
            .collect()
    };
    [0, 1, 2, 3, 4, 5].map(component)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// Every batched entry point (`eval_cos_batch` of tables and networks, `pdf_batch`,
    /// `sample_batch`) processes the common prefix of slices of different lengths, components
    /// included, equal to the single calls there, and leaves the rest alone: no panic.
    #[test]
    fn uneven_batches_process_their_common_prefix(
        pairs in prop::collection::vec((unit_direction(), unit_direction()), 12),
        lengths in [0usize..=12, 0usize..=12, 0usize..=12, 0usize..=12, 0usize..=12, 0usize..=12],
        out_lengths in [0usize..=12, 0usize..=12, 0usize..=12],
    ) {
        let cols = uneven_columns(&pairs, lengths);
        let view = Directions { x: &cols[0], y: &cols[1], z: &cols[2] };
        let light = Directions { x: &cols[3], y: &cols[4], z: &cols[5] };
        let n = lengths.iter().chain(&out_lengths).copied().min().unwrap_or(0);
        let untouched = |c: &[f32]| c[n.min(c.len())..].iter().all(|&x| x == -1.0);
        for brdf in [test_network() as &dyn Brdf, test_table() as &dyn Brdf] {
            let [mut r, mut g, mut b] = out_lengths.map(|len| vec![-1.0f32; len]);
            brdf.eval_cos_batch(view, light, RgbMut { r: &mut r, g: &mut g, b: &mut b });
            for (i, &(v, l)) in pairs.iter().take(n).enumerate() {
                let want = eval_cos(brdf, v, l);
                prop_assert!(close(want, [r[i], g[i], b[i]]), "lane {i}: {want:?}");
            }
            prop_assert!(untouched(&r) && untouched(&g) && untouched(&b));
        }
        let strategy = SamplingStrategy::Phong { exponent: 40.0, specular_weight: 0.5 };
        let mut pdf = vec![-1.0f32; out_lengths[0]];
        sampling::pdf_batch(&strategy, view, light, &mut pdf);
        let n_pdf = lengths.iter().copied().chain([out_lengths[0]]).min().unwrap_or(0);
        for (i, &(v, l)) in pairs.iter().take(n_pdf).enumerate() {
            prop_assert_eq!(pdf[i], strategy.pdf(v, l));
        }
        prop_assert!(pdf[n_pdf..].iter().all(|&x| x == -1.0));
        // The lights' columns serve as the random numbers (folded into [0, 1)).
        let u: Vec<Vec<f32>> = cols[3..].iter().map(|c| c.iter().map(|x| x.abs() * 0.99).collect()).collect();
        let [mut ox, mut oy, mut oz] = out_lengths.map(|len| vec![0.0f32; len]);
        let [mut r, mut g, mut b] = out_lengths.map(|len| vec![-1.0f32; len]);
        let mut spdf = vec![-1.0f32; out_lengths[1]];
        sampling::sample_batch(
            &strategy,
            test_network(),
            view,
            Directions { x: &u[0], y: &u[1], z: &u[2] },
            DirectionsMut { x: &mut ox, y: &mut oy, z: &mut oz },
            RgbMut { r: &mut r, g: &mut g, b: &mut b },
            &mut spdf,
        );
        let n_sample = n.min(out_lengths[1]);
        for i in 0..n_sample {
            let s = strategy.sample(pairs[i].0, [u[0][i], u[1][i], u[2][i]]);
            prop_assert_eq!(spdf[i], s.pdf);
            prop_assert_eq!([ox[i], oy[i], oz[i]], s.light.to_array());
        }
        prop_assert!(spdf[n_sample..].iter().all(|&x| x == -1.0));
        prop_assert!(untouched(&r) && untouched(&g) && untouched(&b));
    }
}
