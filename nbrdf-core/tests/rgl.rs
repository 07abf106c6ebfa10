//! The RGL `.bsdf` reader on synthetic tensor files written by the tests: a valid measurement
//! whose tables are constant (so Mitsuba's `measured` evaluates to a closed form whatever the
//! warps do), and malformed variants that must be refused with an error naming file and field.
//! Agreement with Mitsuba itself on the real measurements is `tests/test_rgl_reader.py`.

use glam::Vec3;
use nbrdf_core::rgl::tensor::{write_tensor_file, DType, TensorFile};
use nbrdf_core::rgl::RglMeasurement;
use nbrdf_core::{Brdf, NbrdfError};
use std::path::PathBuf;

const N_THETA: usize = 4;
const RES: usize = 8;
const RGB: [f32; 3] = [0.2, 0.5, -0.01];
const NDF: f32 = 3.0;
const SIGMA: f32 = 0.75;

fn f32_bytes(values: &[f32]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

/// The fields of a small isotropic measurement with constant tables, as (name, dtype, shape,
/// data); `edit` may change them before they are written.
struct Fields(Vec<(String, DType, Vec<usize>, Vec<u8>)>);

impl Fields {
    fn valid(jacobian: bool) -> Fields {
        let theta: Vec<f32> = (0..N_THETA)
            .map(|i| i as f32 / (N_THETA - 1) as f32 * std::f32::consts::FRAC_PI_2)
            .collect();
        // A non-constant VNDF, so that the inverse warp does real work.
        let vndf: Vec<f32> = (0..N_THETA * RES * RES)
            .map(|i| 1.0 + (i % 7) as f32)
            .collect();
        let rgb: Vec<f32> = (0..N_THETA)
            .flat_map(|_| {
                RGB.iter()
                    .flat_map(|&c| std::iter::repeat(c).take(RES * RES))
            })
            .collect();
        Fields(vec![
            (
                "version".into(),
                DType::UInt32,
                vec![2],
                [1u32, 0].iter().flat_map(|v| v.to_le_bytes()).collect(),
            ),
            (
                "description".into(),
                DType::UInt8,
                vec![9],
                b"synthetic".to_vec(),
            ),
            ("phi_i".into(), DType::Float32, vec![1], f32_bytes(&[0.0])),
            (
                "theta_i".into(),
                DType::Float32,
                vec![N_THETA],
                f32_bytes(&theta),
            ),
            (
                "sigma".into(),
                DType::Float32,
                vec![2, 16],
                f32_bytes(&[SIGMA; 32]),
            ),
            (
                "ndf".into(),
                DType::Float32,
                vec![2, 16],
                f32_bytes(&[NDF; 32]),
            ),
            (
                "vndf".into(),
                DType::Float32,
                vec![1, N_THETA, RES, RES],
                f32_bytes(&vndf),
            ),
            (
                "luminance".into(),
                DType::Float32,
                vec![1, N_THETA, RES, RES],
                f32_bytes(&vec![1.0; N_THETA * RES * RES]),
            ),
            (
                "rgb".into(),
                DType::Float32,
                vec![1, N_THETA, 3, RES, RES],
                f32_bytes(&rgb),
            ),
            (
                "jacobian".into(),
                DType::UInt8,
                vec![1],
                vec![jacobian as u8],
            ),
        ])
    }

    fn set(mut self, name: &str, dtype: DType, shape: Vec<usize>, data: Vec<u8>) -> Fields {
        let field = self.0.iter_mut().find(|f| f.0 == name).expect("field");
        *field = (name.into(), dtype, shape, data);
        self
    }

    fn without(mut self, name: &str) -> Fields {
        self.0.retain(|f| f.0 != name);
        self
    }

    fn bytes(&self) -> Vec<u8> {
        let refs: Vec<(&str, DType, &[usize], &[u8])> = self
            .0
            .iter()
            .map(|(n, d, s, b)| (n.as_str(), *d, s.as_slice(), b.as_slice()))
            .collect();
        write_tensor_file(&refs)
    }
}

fn parse(bytes: Vec<u8>) -> Result<RglMeasurement, NbrdfError> {
    let file = TensorFile::parse(bytes, PathBuf::from("synthetic.bsdf"))?;
    RglMeasurement::from_tensor_file(&file)
}

/// The error of loading `bytes`, which must name the file and contain every one of `needles`.
fn refused(bytes: Vec<u8>, needles: &[&str]) {
    let message = match parse(bytes) {
        Ok(_) => panic!("accepted a malformed file (expected an error with {needles:?})"),
        Err(e) => e.to_string(),
    };
    assert!(
        message.contains("synthetic.bsdf"),
        "error does not name the file: {message}"
    );
    for needle in needles {
        assert!(
            message.contains(needle),
            "error lacks '{needle}': {message}"
        );
    }
}

fn direction(theta: f32, phi: f32) -> Vec3 {
    Vec3::new(
        theta.sin() * phi.cos(),
        theta.sin() * phi.sin(),
        theta.cos(),
    )
}

fn directions() -> Vec<(Vec3, Vec3)> {
    let mut pairs = Vec::new();
    for i in 0..9 {
        for j in 0..9 {
            let view = direction(0.05 + 0.17 * i as f32, 0.7 * i as f32 - 2.0);
            let light = direction(0.02 + 0.173 * j as f32, 1.3 * j as f32 + 0.4);
            pairs.push((view, light));
        }
    }
    // Exact mirror directions (half vector = normal) and grazing ones.
    pairs.push((
        direction(0.6, 0.3),
        direction(0.6, 0.3 + std::f32::consts::PI),
    ));
    pairs.push((direction(1.56, -1.0), direction(1.5, 2.0)));
    pairs
}

#[test]
fn constant_tables_evaluate_to_the_closed_form() {
    for jacobian in [false, true] {
        let m = parse(Fields::valid(jacobian).bytes()).expect("valid file");
        assert_eq!(m.description(), "synthetic");
        assert!(m.is_isotropic());
        let scale = if jacobian { NDF / (4.0 * SIGMA) } else { 1.0 };
        for (view, light) in directions() {
            let cosine_weighted = m.eval_cos_f32(view, light);
            let f_r = m.eval(view, light);
            for c in 0..3 {
                let expected = RGB[c] * scale;
                assert!(
                    (cosine_weighted[c] - expected).abs() <= 1e-6 * expected.abs(),
                    "{view} {light}: {cosine_weighted:?}"
                );
                let expected_f = expected as f64 / light.z as f64;
                assert!(
                    (f_r[c] - expected_f).abs() <= 1e-6 * expected_f.abs(),
                    "{f_r:?} vs {expected_f}"
                );
            }
            // The Brdf trait clamps the out-of-gamut channel and accepts directions that are
            // not unit length.
            let trait_value = Brdf::eval(&m, 3.0 * view, 2.0 * light);
            assert!((trait_value[0] as f64 - f_r[0]).abs() <= 1e-5 * f_r[0]);
            assert_eq!(trait_value[2], 0.0);
        }
    }
}

#[test]
fn below_the_horizon_is_zero() {
    let m = parse(Fields::valid(true).bytes()).unwrap();
    let up = direction(0.4, 0.2);
    let down = Vec3::new(0.3, 0.1, -0.9).normalize();
    let horizon = Vec3::new(1.0, 0.0, 0.0);
    for (view, light) in [
        (up, down),
        (down, up),
        (horizon, up),
        (up, horizon),
        (Vec3::ZERO, up),
    ] {
        assert_eq!(m.eval_cos_f32(view, light), [0.0; 3]);
        assert_eq!(m.eval(view, light), [0.0; 3]);
        assert_eq!(Brdf::eval(&m, view, light), [0.0; 3]);
    }
    assert_eq!(Brdf::eval(&m, Vec3::new(f32::NAN, 0.0, 1.0), up), [0.0; 3]);
    assert_eq!(
        Brdf::eval(&m, Vec3::new(f32::INFINITY, 0.0, 1.0), up),
        [0.0; 3]
    );
}

#[test]
fn load_reads_a_file_and_names_it_in_errors() {
    let dir = std::env::temp_dir().join(format!("nbrdf-rgl-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("constant.bsdf");
    std::fs::write(&path, Fields::valid(true).bytes()).unwrap();
    assert!(RglMeasurement::load(&path).is_ok());
    let missing = dir.join("absent.bsdf");
    let message = RglMeasurement::load(&missing).unwrap_err().to_string();
    assert!(message.contains("absent.bsdf"), "{message}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn truncated_files_are_refused() {
    let bytes = Fields::valid(true).bytes();
    for len in [0, 5, 17, 40, 200, bytes.len() / 2, bytes.len() - 1] {
        refused(bytes[..len].to_vec(), &[]);
    }
    refused(
        bytes[..bytes.len() - 1].to_vec(),
        &["jacobian", "past the end"],
    );
}

#[test]
fn bad_headers_are_refused() {
    let mut bytes = Fields::valid(true).bytes();
    bytes[0] = b'T';
    refused(bytes, &["tensor_file"]);
    // A field count the file cannot hold: refused before anything is allocated for it.
    let mut bytes = Fields::valid(true).bytes();
    bytes[14..18].copy_from_slice(&u32::MAX.to_le_bytes());
    refused(bytes, &["fields"]);
    let mut bytes = Fields::valid(true).bytes();
    bytes[13] = 3;
    refused(bytes, &["version"]);
}

#[test]
fn oversized_shapes_are_refused_without_allocating() {
    // Shapes whose byte size overflows, or merely exceeds the file: both checked up front.
    for shape in [
        vec![1usize << 40, 1 << 40, 1 << 40],
        vec![usize::MAX / 2, 3],
        vec![1 << 30],
    ] {
        let fields = Fields::valid(true).set("ndf", DType::Float32, shape, f32_bytes(&[NDF; 32]));
        refused(fields.bytes(), &["ndf", "past the end"]);
    }
}

#[test]
fn wrong_dtypes_shapes_and_values_are_refused() {
    let cases: Vec<(Fields, &[&str])> = vec![
        (
            Fields::valid(true).set("ndf", DType::Float64, vec![2, 16], vec![0; 256]),
            &["ndf", "float64", "float32"],
        ),
        (
            Fields::valid(true).set("jacobian", DType::Float32, vec![1], f32_bytes(&[1.0])),
            &["jacobian", "uint8"],
        ),
        (
            Fields::valid(true).set(
                "rgb",
                DType::Float32,
                vec![1, N_THETA, 3, RES, RES - 1],
                vec![0; 4 * N_THETA * 3 * RES * (RES - 1)],
            ),
            &["rgb", "shape"],
        ),
        (
            Fields::valid(true).set(
                "vndf",
                DType::Float32,
                vec![1, N_THETA - 1, RES, RES],
                vec![0; 4 * (N_THETA - 1) * RES * RES],
            ),
            &["vndf", "shape"],
        ),
        (
            Fields::valid(true).set(
                "luminance",
                DType::Float32,
                vec![1, N_THETA, RES],
                vec![0; 4 * N_THETA * RES],
            ),
            &["luminance", "dimensions"],
        ),
        (
            Fields::valid(true).set(
                "sigma",
                DType::Float32,
                vec![1, 16],
                f32_bytes(&[SIGMA; 16]),
            ),
            &["sigma", "shape"],
        ),
        (
            Fields::valid(true).set(
                "theta_i",
                DType::Float32,
                vec![N_THETA],
                f32_bytes(&[0.0, 0.5, 0.4, 1.5]),
            ),
            &["theta_i", "increasing"],
        ),
        (
            Fields::valid(true).set("sigma", DType::Float32, vec![2, 16], f32_bytes(&[0.0; 32])),
            &["sigma", "positive"],
        ),
        (
            Fields::valid(true).set("jacobian", DType::UInt8, vec![1], vec![7]),
            &["jacobian", "0 or 1"],
        ),
        (
            Fields::valid(true).set(
                "vndf",
                DType::Float32,
                vec![1, N_THETA, RES, RES],
                vec![0; 4 * N_THETA * RES * RES],
            ),
            &["vndf", "integrates to zero"],
        ),
        (Fields::valid(true).without("vndf"), &["vndf", "missing"]),
        (Fields::valid(true).without("rgb"), &["rgb", "missing"]),
    ];
    for (fields, needles) in cases {
        refused(fields.bytes(), needles);
    }
    let mut ndf = vec![NDF; 32];
    ndf[5] = f32::NAN;
    refused(
        Fields::valid(true)
            .set("ndf", DType::Float32, vec![2, 16], f32_bytes(&ndf))
            .bytes(),
        &["ndf", "finite"],
    );
}

#[test]
fn batches_match_single_evaluations() {
    use nbrdf_core::brdf::{Directions, RgbMut};
    let m = parse(Fields::valid(true).bytes()).unwrap();
    let pairs: Vec<(Vec3, Vec3)> = (0..3000)
        .map(|i| directions()[i % directions().len()])
        .collect();
    let planar = |pick: fn(&(Vec3, Vec3)) -> Vec3| -> Vec<f32> {
        let v: Vec<Vec3> = pairs.iter().map(pick).collect();
        v.iter()
            .map(|d| d.x)
            .chain(v.iter().map(|d| d.y))
            .chain(v.iter().map(|d| d.z))
            .collect()
    };
    let (views, lights) = (planar(|p| p.0), planar(|p| p.1));
    let (view, light) = (
        Directions::from_planar(&views).unwrap(),
        Directions::from_planar(&lights).unwrap(),
    );
    let mut raw = vec![f32::NAN; 3 * pairs.len()];
    let mut clamped = vec![f32::NAN; 3 * pairs.len()];
    m.eval_cos_batch_f32(view, light, RgbMut::from_planar(&mut raw).unwrap());
    Brdf::eval_cos_batch(&m, view, light, RgbMut::from_planar(&mut clamped).unwrap());
    let n = pairs.len();
    for (i, (v, l)) in pairs.iter().enumerate() {
        let single = m.eval_cos_f32(*v, *l);
        assert_eq!([raw[i], raw[n + i], raw[2 * n + i]], single);
        let normalised = m.eval_cos_f32(v.normalize_or_zero(), l.normalize_or_zero());
        assert_eq!(
            [clamped[i], clamped[n + i], clamped[2 * n + i]],
            normalised.map(|x| x.max(0.0))
        );
    }
}

#[test]
fn batches_with_uneven_components_evaluate_their_common_prefix() {
    use nbrdf_core::brdf::{Directions, RgbMut};
    let m = parse(Fields::valid(true).bytes()).unwrap();
    let (v, l) = directions()[0];
    let repeat = |x: f32| vec![x; 6];
    let (vx, vy, vz) = (repeat(v.x), repeat(v.y), repeat(v.z));
    let (lx, ly, lz) = (repeat(l.x), repeat(l.y), repeat(l.z));
    let view = Directions {
        x: &vx,
        y: &vy[..4],
        z: &vz,
    };
    let light = Directions {
        x: &lx,
        y: &ly,
        z: &lz[..5],
    };
    let single = m.eval_cos_f32(v, l);
    let mut planar = vec![-1.0f32; 18];
    m.eval_cos_batch_f32(view, light, RgbMut::from_planar(&mut planar).unwrap());
    let mut clamped = vec![-1.0f32; 18];
    Brdf::eval_cos_batch(&m, view, light, RgbMut::from_planar(&mut clamped).unwrap());
    // The raw values keep the measurement's out-of-gamut negatives; the trait clamps them.
    for (out, expect) in [(&planar, single), (&clamped, single.map(|x| x.max(0.0)))] {
        for c in 0..3 {
            let channel = &out[6 * c..6 * (c + 1)];
            assert!(channel[..4].iter().all(|&x| x == expect[c]), "{out:?}");
            assert_eq!(&channel[4..], &[-1.0, -1.0], "past the prefix: {out:?}");
        }
    }
    // Output channels of different lengths: the prefix shrinks to the shortest one.
    let (mut r, mut g, mut b) = (vec![-1.0f32; 6], vec![-1.0f32; 3], vec![-1.0f32; 6]);
    m.eval_cos_batch_f32(
        view,
        light,
        RgbMut {
            r: &mut r,
            g: &mut g,
            b: &mut b,
        },
    );
    for (c, channel) in [&r, &g, &b].into_iter().enumerate() {
        assert!(channel[..3].iter().all(|&x| x == single[c]), "{channel:?}");
        assert!(channel[3..].iter().all(|&x| x == -1.0), "{channel:?}");
    }
}

/// Training straight from a measurement file (`nbrdf train X.bsdf`): the source is recognised by
/// content and the network learns the closed form of the constant synthetic measurement.
#[cfg(feature = "train")]
mod train_from_source {
    use super::*;
    use nbrdf_core::coords::{to_rusinkiewicz, RusinkiewiczAngles};
    use nbrdf_core::merl::PhiFold;
    use nbrdf_core::ops::train_network::{train_network, NetworkKind, TrainRequest};
    use nbrdf_core::source::{rgl_target, RglFold, TrainingSource, GRAZING_COS};
    use nbrdf_core::train::{Anisotropy, TrainConfig};
    use nbrdf_core::Nbrdf;

    fn temp_dir(tag: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("nbrdf-source-{tag}-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    #[test]
    fn a_measurement_file_trains_to_its_closed_form() {
        let dir = temp_dir("train");
        let path = dir.join("constant"); // no extension: the content decides
        std::fs::write(&path, Fields::valid(false).bytes()).unwrap();
        let output = dir.join("constant.nbrdf.json");
        let request = TrainRequest {
            source: path.clone(),
            phi_fold: PhiFold::default(),
            rgl_fold: RglFold::AsMeasured,
            output: Some(output.clone()),
            name: None,
            config: TrainConfig {
                samples: 6000,
                max_epochs: 80,
                batch: 64,
                seed: 1,
                ..TrainConfig::fixed_budget()
            },
            anisotropy: Anisotropy::Auto,
            network_kind: NetworkKind::Auto,
            scale_samples: false,
            threads: None,
        };
        let report = train_network(&request, &mut |_| {}).unwrap().report;
        assert!(
            report.best_validation_loss < 1e-2
                && report.best_validation_loss < 0.1 * report.history[0].1,
            "{:?}",
            report.history
        );
        let network = Nbrdf::load(&output).unwrap();
        let p = &network.provenance;
        assert_eq!(p["source_kind"], "rgl-measurement");
        assert_eq!(p["rgl_fold"], "as-measured");
        assert!(p["source"].as_str().unwrap().ends_with("constant"));
        // f cos(theta_light) is the stored RGB (negative blue clamped to 0) in every direction.
        for (view, light) in directions() {
            if view.z < 0.2 || light.z < 0.2 {
                continue;
            }
            let f = Brdf::eval(&network, view, light);
            for c in 0..3 {
                let got = f[c] * light.z;
                let want = RGB[c].max(0.0);
                assert!(
                    (got - want).abs() < 0.1 * want + 0.01,
                    "{view} {light}: {got} vs {want}"
                );
            }
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// The synthetic measurement over five incident azimuths (`-pi..pi`): an anisotropic file.
    fn anisotropic_fields() -> Fields {
        let n_phi = 5;
        let phi: Vec<f32> = (0..n_phi)
            .map(|i| (i as f32 / 2.0 - 1.0) * std::f32::consts::PI)
            .collect();
        let iso = Fields::valid(false);
        let per_phi = |name: &str| -> Vec<u8> {
            let data = &iso.0.iter().find(|f| f.0 == name).unwrap().3;
            data.repeat(n_phi)
        };
        let (vndf, luminance, rgb) = (per_phi("vndf"), per_phi("luminance"), per_phi("rgb"));
        iso.set("phi_i", DType::Float32, vec![n_phi], f32_bytes(&phi))
            .set("vndf", DType::Float32, vec![n_phi, N_THETA, RES, RES], vndf)
            .set(
                "luminance",
                DType::Float32,
                vec![n_phi, N_THETA, RES, RES],
                luminance,
            )
            .set(
                "rgb",
                DType::Float32,
                vec![n_phi, N_THETA, 3, RES, RES],
                rgb,
            )
    }

    /// `--anisotropy auto` follows the file's isotropic flag; on/off force it. An anisotropic
    /// network is written as format version 2 and records the decision.
    #[test]
    fn anisotropy_follows_the_measurement_unless_forced() {
        let dir = temp_dir("aniso");
        let files = [
            ("iso", Fields::valid(false).bytes()),
            ("aniso", anisotropic_fields().bytes()),
        ];
        let cases = [
            ("iso", Anisotropy::Auto, false),
            ("aniso", Anisotropy::Auto, true),
            ("aniso", Anisotropy::Off, false),
            ("iso", Anisotropy::On, true),
        ];
        for (name, bytes) in &files {
            std::fs::write(dir.join(name), bytes).unwrap();
        }
        assert!(!parse(anisotropic_fields().bytes()).unwrap().is_isotropic());
        for (name, anisotropy, expect) in cases {
            let output = dir.join(format!("{name}-{}.nbrdf.json", anisotropy.as_str()));
            let request = TrainRequest {
                source: dir.join(name),
                phi_fold: PhiFold::default(),
                rgl_fold: RglFold::AsMeasured,
                output: Some(output.clone()),
                name: None,
                config: TrainConfig {
                    samples: 500,
                    max_epochs: 1,
                    batch: 64,
                    ..TrainConfig::fixed_budget()
                },
                anisotropy,
                network_kind: NetworkKind::Auto,
                scale_samples: true,
                threads: None,
            };
            let report = train_network(&request, &mut |_| {}).unwrap().report;
            // The default-count scaling: five times the samples for the fourth angle.
            let samples = if expect { 2500 } else { 500 };
            assert_eq!(report.train_samples, samples, "{name} {anisotropy:?}");
            let text = std::fs::read_to_string(&output).unwrap();
            let json: serde_json::Value = serde_json::from_str(&text).unwrap();
            assert_eq!(json["version"], if expect { 2 } else { 1 }, "{name}");
            assert_eq!(json["provenance"]["anisotropic"], expect);
            assert_eq!(Nbrdf::load(&output).unwrap().anisotropic, expect);
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn the_reciprocal_mean_averages_both_directions() {
        let m = parse(Fields::valid(false).bytes()).unwrap();
        let measured = rgl_target(&m, RglFold::AsMeasured);
        let mean = rgl_target(&m, RglFold::ReciprocalMean);
        for (view, light) in directions() {
            let angles: RusinkiewiczAngles = to_rusinkiewicz(view.as_dvec3(), light.as_dvec3());
            let (cv, cl) = (view.z as f64, light.z as f64);
            let a = measured(&angles).unwrap();
            let b = mean(&angles);
            if cv < GRAZING_COS || cl < GRAZING_COS {
                assert!(b.is_none());
                continue;
            }
            let b = b.unwrap();
            for c in 0..3 {
                let rgb = RGB[c].max(0.0) as f64;
                let tol = 1e-4 * (rgb / cl.min(cv)).max(1e-6);
                assert!((a[c] - rgb / cl).abs() < tol, "{a:?}");
                let want = 0.5 * (rgb / cl + rgb / cv);
                assert!((b[c] - want).abs() < tol, "{b:?} vs {want}");
            }
        }
    }

    fn open_error(name: &str, bytes: &[u8]) -> String {
        let dir = temp_dir("sniff");
        let path = dir.join(name);
        std::fs::write(&path, bytes).unwrap();
        let message = match TrainingSource::open(&path) {
            Ok(_) => panic!("{name} opened"),
            Err(e) => e.to_string(),
        };
        std::fs::remove_dir_all(&dir).unwrap();
        assert!(message.contains(name), "{message}");
        message
    }

    #[test]
    fn sources_are_told_apart_by_content_and_errors_name_the_file() {
        let json = open_error("net.bsdf", br#"{"name": "x", "layers": []}"#);
        assert!(json.contains("JSON"), "{json}");
        assert!(open_error("empty.binary", b"").contains("empty"));
        let tensor = Fields::valid(true).bytes();
        open_error("truncated.bsdf", &tensor[..tensor.len() / 2]);
        let merl_header: Vec<u8> = [90i32, 90, 180]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        assert!(open_error("short.binary", &merl_header).contains("truncated"));
        let missing =
            std::env::temp_dir().join(format!("nbrdf-absent-{}.bsdf", std::process::id()));
        let message = TrainingSource::open(&missing).err().unwrap().to_string();
        assert!(message.contains("nbrdf-absent-"), "{message}");
        // A valid tensor file named like a table is still a measurement.
        let dir = temp_dir("kind");
        let path = dir.join("table.binary");
        std::fs::write(&path, &tensor).unwrap();
        let source = TrainingSource::open(&path).unwrap();
        assert_eq!(source.kind(), "rgl-measurement");
        assert_eq!(source.path(), path.as_path());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}

/// Tables whose evaluation would leave the float32 range are refused (found by the rgl fuzz
/// targets: an infinite Jacobian scale gave NaN where the reflectance was zero, and huge
/// reflectances gave infinities).
#[test]
fn tables_beyond_the_float32_range_are_refused() {
    let tiny_sigma = Fields::valid(true)
        .set("ndf", DType::Float32, vec![2, 16], f32_bytes(&[1.8e25; 32]))
        .set(
            "sigma",
            DType::Float32,
            vec![2, 16],
            f32_bytes(&[2.35e-38; 32]),
        );
    refused(tiny_sigma.bytes(), &["rgb", "float32 range"]);
    // A subnormal area interpolates to 0 (a NaN at normal incidence, found by rgl_structured).
    let subnormal_sigma = Fields::valid(true).set(
        "sigma",
        DType::Float32,
        vec![2, 16],
        f32_bytes(&[1e-45; 32]),
    );
    refused(subnormal_sigma.bytes(), &["sigma", "smallest normal"]);
    let cells = N_THETA * 3 * RES * RES;
    // The Jacobian scale is 30 / (4 * 0.75) = 10 here.
    let huge_rgb = Fields::valid(true)
        .set("ndf", DType::Float32, vec![2, 16], f32_bytes(&[30.0; 32]))
        .set(
            "rgb",
            DType::Float32,
            vec![1, N_THETA, 3, RES, RES],
            f32_bytes(&vec![1e38; cells]),
        );
    refused(huge_rgb.bytes(), &["rgb", "float32 range"]);
    // Without the Jacobian the scale is 1: the largest float32 reflectance still evaluates.
    let largest = Fields::valid(false).set(
        "rgb",
        DType::Float32,
        vec![1, N_THETA, 3, RES, RES],
        f32_bytes(&vec![3e38; cells]),
    );
    let m = parse(largest.bytes()).unwrap();
    let value = m.eval_cos_f32(direction(0.3, 0.0), direction(0.4, 2.0));
    assert!(
        value.iter().all(|v| v.is_finite() && *v > 1e38),
        "{value:?}"
    );
}

/// `f = f cos / cos` saturates at the largest float instead of overflowing as the light reaches
/// the horizon, where float32 cosines go down to 1e-45.
#[test]
fn reflectance_at_the_horizon_saturates_instead_of_overflowing() {
    let m = parse(Fields::valid(true).bytes()).unwrap();
    let view = direction(0.5, 0.3);
    for z in [1e-7f32, 1e-30, 1e-38, 1e-45] {
        let light = Vec3::new(1.0, 0.0, z);
        let f = Brdf::eval(&m, view, light);
        assert!(f.iter().all(|v| v.is_finite() && *v >= 0.0), "z {z}: {f:?}");
    }
    let f = Brdf::eval(&m, view, Vec3::new(1.0, 0.0, 1e-45));
    assert!(f[1] == f32::MAX, "{f:?}");
}

/// A VNDF row without density (real measurements have them: cc_ibiza_sunset_rgb) makes the
/// inverse warp divide 0 by 0 where the half vector is the normal, a NaN in Mitsuba (found by
/// rgl_reader); the position in such a row is taken as 0, and constant tables still evaluate to
/// their closed form there.
#[test]
fn a_vndf_row_without_density_evaluates_to_the_closed_form() {
    let mut vndf: Vec<f32> = (0..N_THETA * RES * RES)
        .map(|i| 1.0 + (i % 7) as f32)
        .collect();
    // The rows around phi_m - phi_i = 0 (u = 0.5) of the slice of theta_i = 0.
    vndf[3 * RES..5 * RES].fill(0.0);
    let zero_row = Fields::valid(true).set(
        "vndf",
        DType::Float32,
        vec![1, N_THETA, RES, RES],
        f32_bytes(&vndf),
    );
    let m = parse(zero_row.bytes()).unwrap();
    let up = Vec3::Z;
    let value = m.eval_cos_f32(up, up);
    for c in 0..3 {
        let expected = RGB[c] * NDF / (4.0 * SIGMA);
        assert!(
            (value[c] - expected).abs() <= 1e-6 * expected.abs(),
            "{value:?}"
        );
    }
}

/// Grazing directions on opposite sides have a half vector too short to normalise in float32
/// (found by rgl_structured): no NaN, no reflection.
#[test]
fn opposite_grazing_directions_give_zero() {
    let m = parse(Fields::valid(true).bytes()).unwrap();
    let (view, light) = (Vec3::new(-1.0, 0.0, 1e-30), Vec3::new(1.0, 0.0, 1e-30));
    assert_eq!(m.eval_cos_f32(view, light), [0.0; 3]);
    assert_eq!(Brdf::eval(&m, view, light), [0.0; 3]);
}

/// Spectral files (`*_spec.bsdf`): `wavelengths` and `spectra` instead of `rgb`.
mod spectral {
    use super::*;
    use nbrdf_core::source::{rgl_target, RglFold, TrainingSource};
    use nbrdf_core::spectrum::SrgbProjection;

    /// The sampled spectrum, the same in every cell and incident direction (so the tables are
    /// constant along all but the wavelength axis and evaluate to a closed form).
    const WAVELENGTHS: [f32; 5] = [360.0, 450.0, 550.0, 700.0, 830.0];
    const SPECTRUM: [f32; 5] = [0.1, 0.6, 0.3, 0.9, 0.2];

    fn spectral_fields(jacobian: bool, wavelengths: &[f32], spectrum: &[f32]) -> Fields {
        let spectra: Vec<f32> = (0..N_THETA)
            .flat_map(|_| {
                spectrum
                    .iter()
                    .flat_map(|&c| std::iter::repeat(c).take(RES * RES))
            })
            .collect();
        let mut fields = Fields::valid(jacobian).without("rgb").0;
        let shape = vec![1, N_THETA, spectrum.len(), RES, RES];
        fields.push(("spectra".into(), DType::Float32, shape, f32_bytes(&spectra)));
        let n = wavelengths.len();
        let wavelengths = f32_bytes(wavelengths);
        fields.push(("wavelengths".into(), DType::Float32, vec![n], wavelengths));
        Fields(fields)
    }

    fn valid(jacobian: bool) -> RglMeasurement {
        parse(spectral_fields(jacobian, &WAVELENGTHS, &SPECTRUM).bytes()).expect("valid file")
    }

    /// The spectrum's piecewise-linear interpolant, in float64.
    fn interpolated(l: f64) -> f64 {
        let k = WAVELENGTHS
            .windows(2)
            .position(|w| l <= w[1] as f64)
            .unwrap();
        let (l0, l1) = (WAVELENGTHS[k] as f64, WAVELENGTHS[k + 1] as f64);
        let t = (l - l0) / (l1 - l0);
        (1.0 - t) * SPECTRUM[k] as f64 + t * SPECTRUM[k + 1] as f64
    }

    #[test]
    fn per_wavelength_values_interpolate_the_spectrum() {
        for jacobian in [false, true] {
            let m = valid(jacobian);
            assert_eq!(m.spectra().unwrap().wavelengths(), WAVELENGTHS);
            let scale = if jacobian {
                (NDF / (4.0 * SIGMA)) as f64
            } else {
                1.0
            };
            let queries = [360.0, 400.0, 450.0, 517.3, 699.9, 830.0];
            let mut out = [f32::NAN; 6];
            for (view, light) in directions().into_iter().take(80) {
                m.eval_spectrum_cos_f32(view, light, &queries, &mut out)
                    .unwrap();
                for (q, got) in queries.iter().zip(out) {
                    let want = interpolated(*q as f64) * scale;
                    assert!(
                        (got as f64 - want).abs() <= 2e-6 * want,
                        "{q}: {got} vs {want}"
                    );
                }
            }
        }
    }

    /// Outside the measured range, and at wavelengths that are not numbers, there is no
    /// measurement: 0, never NaN (Mitsuba clamps to the end values there instead).
    #[test]
    fn wavelengths_outside_the_measurement_or_not_finite_give_zero() {
        let narrow = [450.0, 550.0, 700.0];
        let m = parse(spectral_fields(true, &narrow, &[0.6, 0.3, 0.9]).bytes()).unwrap();
        let queries = [
            449.9,
            700.1,
            360.0,
            830.0,
            -5.0,
            f32::NAN,
            f32::INFINITY,
            -f32::INFINITY,
        ];
        let mut out = [1.0f32; 8];
        let (view, light) = directions()[10];
        m.eval_spectrum_cos_f32(view, light, &queries, &mut out)
            .unwrap();
        assert_eq!(out, [0.0; 8]);
        // The extra query is ignored, the output past the common prefix untouched.
        let mut short = [7.0f32; 1];
        m.eval_spectrum_cos_f32(view, light, &[450.0, 500.0], &mut short)
            .unwrap();
        assert!(short[0] > 0.5);
        // Below the horizon: zero at every wavelength.
        let down = Vec3::new(0.3, 0.1, -0.9).normalize();
        m.eval_spectrum_cos_f32(down, light, &narrow, &mut out)
            .unwrap();
        assert_eq!(&out[..3], &[0.0; 3]);
    }

    #[test]
    fn rgb_files_have_no_spectra() {
        let m = parse(Fields::valid(true).bytes()).unwrap();
        assert!(m.spectra().is_none());
        let (view, light) = directions()[0];
        let mut out = [3.0f32];
        let message = m
            .eval_spectrum_cos_f32(view, light, &[500.0], &mut out)
            .unwrap_err()
            .to_string();
        assert!(message.contains("RGB measurement") && message.contains("synthetic.bsdf"));
        assert_eq!(out, [3.0]);
    }

    /// Everything RGB (eval, the Brdf trait, the training target) sees the sRGB projection.
    #[test]
    fn rgb_evaluation_is_the_srgb_projection() {
        let projection = SrgbProjection::new(&WAVELENGTHS.map(f64::from)).unwrap();
        let rgb = projection.project(&SPECTRUM);
        // A saturated spectrum: the projection has a clearly coloured, positive value.
        assert!(
            rgb.iter().all(|&c| c > 0.05) && (rgb[0] - rgb[1]).abs() > 0.02,
            "{rgb:?}"
        );
        let m = valid(false);
        let source = TrainingSource::Rgl(Box::new(valid(false)));
        assert_eq!(source.kind(), "rgl-spectral-measurement");
        let target = rgl_target(&m, RglFold::AsMeasured);
        for (view, light) in directions() {
            if view.z <= 0.0 || light.z <= 0.0 {
                continue;
            }
            let cosine_weighted = m.eval_cos_f32(view, light);
            for c in 0..3 {
                assert!((cosine_weighted[c] as f64 - rgb[c]).abs() <= 1e-6 * rgb[c]);
            }
            let angles = nbrdf_core::coords::to_rusinkiewicz(view.into(), light.into());
            let f = target(&angles).unwrap();
            let (_, l) = nbrdf_core::coords::from_rusinkiewicz(&angles);
            let cos = l.as_vec3().z as f64;
            for c in 0..3 {
                assert!(
                    (f[c] * cos - rgb[c]).abs() <= 1e-5 * rgb[c],
                    "{f:?} vs {rgb:?}"
                );
            }
        }
    }

    /// A spectral network trained on the reciprocal mean gets all the pairs it asked for: the
    /// pairs left out at grazing angles are replaced, as the RGB trainer replaces them.
    #[test]
    fn the_spectral_reciprocal_mean_trains_on_the_full_sample_count() {
        use nbrdf_core::merl::PhiFold;
        use nbrdf_core::ops::train_network::{train_network, NetworkKind, TrainRequest};
        use nbrdf_core::train::dataset::AngularSampling;
        use nbrdf_core::train::{Anisotropy, TrainConfig};
        let dir = std::env::temp_dir().join(format!("nbrdf-spectral-mean-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("synthetic_spec.bsdf");
        std::fs::write(
            &path,
            spectral_fields(false, &WAVELENGTHS, &SPECTRUM).bytes(),
        )
        .unwrap();
        for (fold, sampling) in [
            (RglFold::ReciprocalMean, AngularSampling::Uniform),
            (RglFold::ReciprocalMean, AngularSampling::Adaptive),
            (RglFold::AsMeasured, AngularSampling::Uniform),
        ] {
            let request = TrainRequest {
                source: path.clone(),
                phi_fold: PhiFold::default(),
                rgl_fold: fold,
                output: Some(dir.join(format!("{}.nbrdf.json", fold.as_str()))),
                name: None,
                config: TrainConfig {
                    samples: 4000,
                    max_epochs: 1,
                    batch: 64,
                    sampling,
                    ..TrainConfig::fixed_budget()
                },
                anisotropy: Anisotropy::Auto,
                network_kind: NetworkKind::Spectral,
                scale_samples: false,
                threads: None,
            };
            let report = train_network(&request, &mut |_| {}).unwrap().report;
            let counts = (report.train_samples, report.validation_samples);
            assert_eq!(counts, (4000, 400), "{fold:?} {sampling}");
            assert_eq!(report.dropped_invalid, 0, "{fold:?} {sampling}");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn inconsistent_or_bad_wavelengths_are_refused_naming_the_field() {
        let five = spectral_fields(true, &WAVELENGTHS, &SPECTRUM);
        // The spectra's wavelength axis against the wavelengths field.
        let fewer = five.set(
            "wavelengths",
            DType::Float32,
            vec![4],
            f32_bytes(&WAVELENGTHS[..4]),
        );
        refused(
            fewer.bytes(),
            &["\"spectra\"", "4 (wavelengths)", "[1, 4, 5, 8, 8]"],
        );
        for (wavelengths, needles) in [
            (
                vec![360.0, 550.0, 450.0, 700.0, 830.0],
                vec!["\"wavelengths\"", "strictly increasing"],
            ),
            (
                vec![360.0, 450.0, 450.0, 700.0, 830.0],
                vec!["\"wavelengths\"", "strictly increasing"],
            ),
            (
                vec![360.0, 450.0, f32::NAN, 700.0, 830.0],
                vec!["\"wavelengths\"", "finite"],
            ),
            (
                vec![360.0, 450.0, 550.0, f32::INFINITY, 830.0],
                vec!["\"wavelengths\"", "finite"],
            ),
            (
                vec![0.36, 0.45, 0.55, 0.7, 0.83],
                vec!["\"wavelengths\"", "nanometres"],
            ),
        ] {
            let fields = spectral_fields(true, &wavelengths, &SPECTRUM);
            refused(fields.bytes(), &needles);
        }
        let one = spectral_fields(true, &[550.0], &[0.5]);
        refused(one.bytes(), &["\"wavelengths\"", "at least 2"]);
        // Wavelengths without spectra; wavelengths of the wrong type or rank.
        let no_spectra = spectral_fields(true, &WAVELENGTHS, &SPECTRUM).without("spectra");
        refused(no_spectra.bytes(), &["\"spectra\"", "missing"]);
        let as_f64: Vec<u8> = WAVELENGTHS
            .iter()
            .flat_map(|v| (*v as f64).to_le_bytes())
            .collect();
        let typed = spectral_fields(true, &WAVELENGTHS, &SPECTRUM).set(
            "wavelengths",
            DType::Float64,
            vec![5],
            as_f64,
        );
        refused(typed.bytes(), &["\"wavelengths\"", "dtype"]);
        let rank = spectral_fields(true, &WAVELENGTHS, &SPECTRUM).set(
            "wavelengths",
            DType::Float32,
            vec![5, 1],
            f32_bytes(&WAVELENGTHS),
        );
        refused(rank.bytes(), &["\"wavelengths\"", "dimensions"]);
        // Non-finite spectra are refused like non-finite RGB.
        let mut spectrum = SPECTRUM;
        spectrum[2] = f32::NAN;
        refused(
            spectral_fields(true, &WAVELENGTHS, &spectrum).bytes(),
            &["\"spectra\"", "finite"],
        );
        // Neither rgb nor wavelengths: not a measurement.
        refused(
            Fields::valid(true).without("rgb").bytes(),
            &["\"rgb\"", "not an RGL measurement"],
        );
    }

    /// Spectra whose projection (not their samples) leaves the float32 range are refused: red
    /// weighs the samples other than 450 nm by about 1.12 in all.
    #[test]
    fn huge_spectra_are_refused() {
        let spectrum = [3.2e38, 0.0, 3.2e38, 3.2e38, 3.2e38];
        assert!(parse(spectral_fields(false, &WAVELENGTHS, &[3.2e38; 5]).bytes()).is_ok());
        refused(
            spectral_fields(false, &WAVELENGTHS, &spectrum).bytes(),
            &["\"spectra\"", "float32"],
        );
    }
}
