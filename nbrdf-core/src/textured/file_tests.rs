//! Validation, the material file and its texture: round trips at float16 and float32, dispatch
//! between the two kinds of file, and each refusal naming the file and the field.

use super::tests::{mapping, material};
use super::*;
use crate::network::{Layer, Nbrdf};
use serde_json::{json, Value};
use std::path::{Path, PathBuf};

/// A fresh folder for one test's files.
pub(super) fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("nbrdf-textured-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A material whose texture values are multiples of 1/64 in `[-2, 2]` (exact in float16) and
/// whose lobe values are too.
fn dyadic_material() -> TexturedNbrdf {
    let m = material(
        8,
        8,
        4,
        SamplingChannels::one_lobe(),
        mapping(WrapMode::Mirror, FilterMode::Nearest),
        21,
    );
    let texels = m
        .texture()
        .texels()
        .iter()
        .map(|&c| (c * 64.0).round() / 64.0)
        .collect();
    let names = m.texture().channel_names().to_vec();
    let texture = LatentTexture::new(8, 8, names, texels).unwrap();
    let mapping = UvMapping {
        to_uv: UvTransform {
            matrix: [[2.0, 0.5, 0.25], [0.0, 1.5, -0.125], [0.0, 0.0, 1.0]],
        },
        ..*m.mapping()
    };
    TexturedNbrdf::new(
        "dyadic",
        m.decoder().clone(),
        texture,
        mapping,
        SamplingChannels::one_lobe(),
        "dyadic.latent.exr",
    )
    .unwrap()
    .with_provenance(json!({"trainer": "test"}))
}

#[test]
fn a_saved_material_loads_back_equal_at_float16_and_float32() {
    let dir = scratch("round-trip");
    let m = dyadic_material();
    let path = dir.join("dyadic.nbrdf.json");
    m.save(&path, TexturePrecision::Half).unwrap();
    assert_eq!(TexturedNbrdf::load(&path).unwrap(), m);
    // The file holds float16 channels under their names.
    let meta = exr::meta::MetaData::read_from_file(dir.join("dyadic.latent.exr"), false).unwrap();
    let channels = &meta.headers[0].channels.list;
    let names: Vec<String> = channels.iter().map(|c| c.name.to_string()).collect();
    assert_eq!(
        names,
        ["latent.0", "latent.1", "latent.2", "latent.3", "lobe.n", "lobe.w"]
    );
    assert!(channels
        .iter()
        .all(|c| c.sample_type == exr::meta::attribute::SampleType::F16));
    let json: Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    assert_eq!(json["version"], 4);
    assert_eq!(
        json["latent"],
        json!({"path": "dyadic.latent.exr", "width": 8, "height": 8, "channels": 4, "wrap": "mirror",
               "filter": "nearest", "to_uv": [[2.0, 0.5, 0.25], [0.0, 1.5, -0.125], [0.0, 0.0, 1.0]]})
    );
    assert_eq!(
        json["sampling"],
        json!({"model": "blinn-phong", "exponent_encoding": "log1p",
                                         "lobes": [{"exponent": "lobe.n", "weight": "lobe.w"}]})
    );

    // Arbitrary float32 values survive a float32 file exactly, and float16 rounds them.
    let original = material(
        5,
        3,
        4,
        SamplingChannels::two_lobes(),
        UvMapping::default(),
        22,
    );
    let path = dir.join("float.nbrdf.json");
    original.save(&path, TexturePrecision::Float).unwrap();
    assert_eq!(TexturedNbrdf::load(&path).unwrap(), original);
    original.save(&path, TexturePrecision::Half).unwrap();
    let halved = TexturedNbrdf::load(&path).unwrap();
    for (h, o) in halved
        .texture()
        .texels()
        .iter()
        .zip(original.texture().texels())
    {
        assert!(
            (h - o).abs() <= 2f32.powi(-11) * o.abs().max(2f32.powi(-14)),
            "{h} vs {o}"
        );
    }
}

#[test]
fn each_kind_of_file_loads_as_its_kind_and_is_refused_as_the_other() {
    let dir = scratch("dispatch");
    let textured = dir.join("t.nbrdf.json");
    dyadic_material()
        .save(&textured, TexturePrecision::Half)
        .unwrap();
    let network = dir.join("n.nbrdf.json");
    Nbrdf::random("n", 8, 1).save(&network).unwrap();

    assert!(matches!(
        NeuralMaterial::load(&textured).unwrap(),
        NeuralMaterial::Textured(_)
    ));
    assert!(matches!(
        NeuralMaterial::load(&network).unwrap(),
        NeuralMaterial::Homogeneous(_)
    ));
    let error = Nbrdf::load(&textured).unwrap_err().to_string();
    assert!(
        error.contains("t.nbrdf.json")
            && error.contains("version 4 is a spatially varying material"),
        "{error}"
    );
    let error = TexturedNbrdf::load(&network).unwrap_err().to_string();
    assert!(
        error.contains("n.nbrdf.json")
            && error.contains("homogeneous NBRDF network (format version 1)"),
        "{error}"
    );
    let error = NeuralMaterial::load(dir.join("none.nbrdf.json"))
        .unwrap_err()
        .to_string();
    assert!(error.contains("none.nbrdf.json"), "{error}");
}

/// The JSON of a saved material with `edit` applied, loaded: the error's text.
fn load_edited(dir: &Path, edit: impl Fn(&mut Value)) -> String {
    let path = dir.join("edited.nbrdf.json");
    let mut json: Value = serde_json::from_str(&dyadic_material().to_json_string()).unwrap();
    edit(&mut json);
    std::fs::write(&path, serde_json::to_string(&json).unwrap()).unwrap();
    let error = TexturedNbrdf::load(&path).unwrap_err().to_string();
    assert!(
        error.contains("edited.nbrdf.json"),
        "the error does not name the file: {error}"
    );
    error
}

#[test]
fn bad_json_fields_are_refused_naming_the_field() {
    let dir = scratch("json");
    dyadic_material()
        .save(dir.join("dyadic.nbrdf.json"), TexturePrecision::Half)
        .unwrap();
    type Edit = fn(&mut Value);
    let cases: Vec<(&str, Edit)> = vec![
        ("missing field \"latent\"", |j| {
            j.as_object_mut().unwrap().remove("latent");
        }),
        ("missing field \"name\"", |j| {
            j.as_object_mut().unwrap().remove("name");
        }),
        ("missing field \"latent.path\"", |j| {
            j["latent"].as_object_mut().unwrap().remove("path");
        }),
        ("latent.width: invalid type", |j| {
            j["latent"]["width"] = "8".into()
        }),
        (
            "latent.width, latent.height: latent texture of 0 x 8 texels",
            |j| j["latent"]["width"] = 0.into(),
        ),
        (
            "latent.wrap \"periodic\": expected \"repeat\", \"mirror\" or \"clamp\"",
            |j| j["latent"]["wrap"] = "periodic".into(),
        ),
        (
            "latent.filter \"cubic\": expected \"bilinear\" or \"nearest\"",
            |j| j["latent"]["filter"] = "cubic".into(),
        ),
        ("latent.to_uv must be 3 rows of 3 numbers", |j| {
            j["latent"]["to_uv"] = json!([[1, 0], [0, 1]])
        }),
        ("latent.to_uv's last row", |j| {
            j["latent"]["to_uv"][2] = json!([0, 1, 1])
        }),
        ("latent.to_uv has a non-finite entry", |j| {
            j["latent"]["to_uv"][0][0] = json!(1e39)
        }),
        ("latent is \"x\", expected an object", |j| {
            j["latent"] = "x".into()
        }),
        (
            "layer 1 has 10 inputs, expected 6 direction features + latent.channels = 9",
            |j| j["latent"]["channels"] = 3.into(),
        ),
        ("layer 2 weight 3 is not finite", |j| {
            j["layers"][1]["weights"][3] = json!(-1e39)
        }),
        ("layers: invalid type", |j| j["layers"] = json!([1, 2])),
        ("sampling.model \"ggx\": only \"blinn-phong\"", |j| {
            j["sampling"]["model"] = "ggx".into()
        }),
        ("sampling.exponent_encoding \"linear\"", |j| {
            j["sampling"]["exponent_encoding"] = "linear".into()
        }),
        ("sampling.lobes has 3 lobes, at most 2", |j| {
            let lobe = j["sampling"]["lobes"][0].clone();
            j["sampling"]["lobes"] = json!([lobe.clone(), lobe.clone(), lobe]);
        }),
        ("sampling.lobes[0].weight 'latent.2' is already", |j| {
            j["sampling"]["lobes"][0]["weight"] = "latent.2".into()
        }),
        ("missing field \"sampling.lobes\"", |j| {
            j["sampling"].as_object_mut().unwrap().remove("lobes");
        }),
        ("unsupported version 5", |j| j["version"] = 5.into()),
        ("homogeneous NBRDF network (format version 3)", |j| {
            j["version"] = 3.into()
        }),
        ("format is \"keras\"", |j| j["format"] = "keras".into()),
        // The texture named by the file, and what the file says about it.
        ("latent.path \"missing.exr\"", |j| {
            j["latent"]["path"] = "missing.exr".into()
        }),
        (
            "8 x 8 texels, but latent.width x latent.height is 8 x 7",
            |j| j["latent"]["height"] = 7.into(),
        ),
        ("no channel 'lobe.n1'", |j| {
            j["sampling"]["lobes"] = json!([
            {"exponent": "lobe.n1", "weight": "lobe.w"}])
        }),
        ("unexpected channel 'lobe.n'", |j| {
            j.as_object_mut().unwrap().remove("sampling");
        }),
    ];
    for (message, edit) in cases {
        let error = load_edited(&dir, edit);
        assert!(error.contains(message), "{error}\n  lacks: {message}");
    }
    let path = dir.join("nan.nbrdf.json");
    let mut json: Value = serde_json::from_str(&dyadic_material().to_json_string()).unwrap();
    json["latent"]["to_uv"][0][2] = json!(12345.5);
    let text = serde_json::to_string(&json)
        .unwrap()
        .replace("12345.5", "NaN");
    std::fs::write(&path, text).unwrap();
    let error = TexturedNbrdf::load(&path).unwrap_err().to_string();
    assert!(error.contains("NaN is not valid JSON"), "{error}");
}

#[test]
fn bad_textures_are_refused_naming_the_file_and_the_field() {
    let dir = scratch("exr");
    let m = dyadic_material();
    let json = dir.join("m.nbrdf.json");
    let exr_path = dir.join("dyadic.latent.exr");
    let load = || TexturedNbrdf::load(&json).unwrap_err().to_string();
    m.save(&json, TexturePrecision::Half).unwrap();

    let renamed = |names: Vec<&str>, values: usize| {
        let names = names.into_iter().map(String::from).collect();
        LatentTexture::new(8, 8, names, vec![0.5; 64 * values]).unwrap()
    };
    let cases: Vec<(LatentTexture, &str)> = vec![
        (
            renamed(
                vec![
                    "latent.0", "latent.1", "latent.2", "latent.3", "lobe.n", "lobe.w", "R",
                ],
                7,
            ),
            "unexpected channel 'R'",
        ),
        (
            renamed(
                vec!["latent.0", "latent.1", "latent.2", "latent.3", "lobe.n"],
                5,
            ),
            "no channel 'lobe.w'",
        ),
        (
            renamed(
                vec![
                    "latent.0", "latent.1", "latent.3", "latent.4", "lobe.n", "lobe.w",
                ],
                6,
            ),
            "no channel 'latent.2'",
        ),
    ];
    for (texture, message) in cases {
        texture
            .write_exr(&exr_path, TexturePrecision::Half)
            .unwrap();
        let error = load();
        assert!(
            error.contains("m.nbrdf.json") && error.contains("latent.path \"dyadic.latent.exr\""),
            "{error}"
        );
        assert!(
            error.contains("dyadic.latent.exr") && error.contains(message),
            "{error}\n  lacks: {message}"
        );
    }
    std::fs::write(&exr_path, b"v/1\x01 this is not an OpenEXR file").unwrap();
    assert!(load().contains("not a readable OpenEXR file"), "{}", load());
    std::fs::remove_file(&exr_path).unwrap();
    std::fs::create_dir(&exr_path).unwrap();
    assert!(
        load().contains("a directory; expected a latent texture"),
        "{}",
        load()
    );
    std::fs::remove_dir(&exr_path).unwrap();
    assert!(
        load().contains("latent.path \"dyadic.latent.exr\""),
        "{}",
        load()
    );

    // Integer channels are not latent values.
    let channels = m
        .texture()
        .channel_names()
        .iter()
        .map(|name| {
            let samples = if name == "lobe.w" {
                exr::prelude::FlatSamples::U32(vec![1; 64])
            } else {
                exr::prelude::FlatSamples::F32(vec![0.5; 64])
            };
            exr::prelude::AnyChannel::new(name.as_str(), samples)
        })
        .collect();
    let layer = exr::prelude::Layer::new(
        (8, 8),
        exr::prelude::LayerAttributes::default(),
        exr::prelude::Encoding::UNCOMPRESSED,
        exr::prelude::AnyChannels::sort(channels),
    );
    use exr::prelude::traits::WritableImage;
    exr::prelude::Image::from_layer(layer)
        .write()
        .to_file(&exr_path)
        .unwrap();
    assert!(
        load().contains("channel 'lobe.w' holds 32-bit integers"),
        "{}",
        load()
    );

    // Non-finite texels load, and give 0 where they are read.
    let mut texels = m.texture().texels().to_vec();
    texels[0] = f32::NAN;
    let names = m.texture().channel_names().to_vec();
    LatentTexture::new(8, 8, names, texels)
        .unwrap()
        .write_exr(&exr_path, TexturePrecision::Half)
        .unwrap();
    let holey = TexturedNbrdf::load(&json).unwrap();
    let (view, light) = (Vec3::new(0.1, 0.2, 0.9), Vec3::new(0.3, -0.1, 0.8));
    // The UVs that `to_uv` maps to the middle of texel (0, 0) and of texel (4, 4).
    let inverse = |mapped: f64| {
        let v = (mapped + 0.125) / 1.5;
        [((mapped - 0.25 - 0.5 * v) / 2.0) as f32, v as f32]
    };
    let (at_texel_0, at_texel_36) = (inverse(1.0 / 16.0), inverse(9.0 / 16.0));
    assert_eq!(holey.footprint(at_texel_0).unwrap().texels()[0], 0);
    assert_eq!(holey.texture().lookup(holey.mapping(), at_texel_0), None);
    assert!(m.texture().lookup(m.mapping(), at_texel_0).is_some());
    assert_eq!(holey.eval_cos(at_texel_0, view, light), [0.0; 3]);
    assert_eq!(holey.footprint(at_texel_36).unwrap().texels()[0], 36);
    assert_eq!(
        holey.eval_cos(at_texel_36, view, light),
        m.eval_cos(at_texel_36, view, light)
    );
}

#[test]
fn bad_shapes_are_refused_naming_the_field() {
    let layer = |inputs: usize, outputs: usize| Layer {
        inputs,
        outputs,
        weights: vec![0.1; inputs * outputs],
        bias: vec![0.0; outputs],
    };
    let cases: Vec<(Vec<Layer>, usize, &str)> = vec![
        (
            vec![layer(9, 8), layer(8, 3)],
            4,
            "layer 1 has 9 inputs, expected 6 direction features + latent.channels = 10",
        ),
        (
            vec![layer(10, 8), layer(7, 3)],
            4,
            "layer 2 has 7 inputs, expected 8",
        ),
        (
            vec![layer(10, 8), layer(8, 4)],
            4,
            "the last, has 4 outputs",
        ),
        (vec![layer(10, 300), layer(300, 3)], 4, "expected 1 to 256"),
        (vec![], 4, "0 layers"),
        (vec![layer(6, 3)], 0, "latent.channels 0 must be in [1, 32]"),
        (vec![layer(39, 3)], 33, "latent.channels 33"),
    ];
    for (layers, channels, message) in cases {
        let error = Decoder::new(layers, channels, false, None)
            .unwrap_err()
            .to_string();
        assert!(error.contains(message), "{error} lacks {message}");
    }
    let mut nan = layer(10, 3);
    nan.weights[4] = f32::NAN;
    let error = Decoder::new(vec![nan], 4, false, None)
        .unwrap_err()
        .to_string();
    assert!(error.contains("layer 1 weight 4 is not finite"), "{error}");

    let m = material(
        4,
        4,
        2,
        SamplingChannels::one_lobe(),
        UvMapping::default(),
        1,
    );
    let texture = || m.texture().clone();
    let make = |mapping: UvMapping, sampling: SamplingChannels| {
        TexturedNbrdf::new(
            "x",
            m.decoder().clone(),
            texture(),
            mapping,
            sampling,
            "x.exr",
        )
        .unwrap_err()
        .to_string()
    };
    let skewed = UvMapping {
        to_uv: UvTransform {
            matrix: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.5, 0.0, 1.0]],
        },
        ..UvMapping::default()
    };
    assert!(make(skewed, SamplingChannels::one_lobe()).contains("latent.to_uv's last row"));
    let infinite = UvMapping {
        to_uv: UvTransform {
            matrix: [[f32::INFINITY, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        },
        ..UvMapping::default()
    };
    assert!(make(infinite, SamplingChannels::one_lobe())
        .contains("latent.to_uv has a non-finite entry"));
    assert!(make(UvMapping::default(), SamplingChannels::two_lobes())
        .contains("expected latent.0, latent.1, lobe.n1"));
    let clash = SamplingChannels::new(vec![LobeChannels {
        exponent: "latent.1".into(),
        weight: "w".into(),
    }])
    .unwrap();
    assert!(make(UvMapping::default(), clash)
        .contains("sampling.lobes[0].exponent 'latent.1' is already"));
    let spaced = SamplingChannels::new(vec![LobeChannels {
        exponent: "lobe n".into(),
        weight: "w".into(),
    }])
    .unwrap();
    assert!(
        make(UvMapping::default(), spaced).contains("sampling.lobes[0].exponent 'lobe n' must be")
    );
    assert!(
        SamplingChannels::new(vec![SamplingChannels::one_lobe().lobes()[0].clone(); 3]).is_none()
    );
    assert!(LatentTexture::new(0, 4, vec!["a".into()], vec![]).is_err());
    assert!(LatentTexture::new(2, 2, vec!["a".into(), "a".into()], vec![0.0; 8]).is_err());
    assert!(LatentTexture::new(2, 2, vec!["a".into()], vec![0.0; 5]).is_err());
}
