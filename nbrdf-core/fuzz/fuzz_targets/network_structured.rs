//! Networks written as JSON from a structural description: widths on both sides of the kernel's
//! stack-scratch limit (64), one shape edit at most, extreme values (float32 limits, subnormals,
//! values that overflow float32, NaN), sampling parameters and nested provenance. Most inputs
//! are well-formed JSON, so the fuzzer spends its time in validation and evaluation rather than
//! in the JSON syntax. Tame networks are also checked for agreement between the single and the
//! batched evaluation. (Pruning has its own target, `network_pruning`: its proof costs ~50x an
//! evaluation here.)

#![no_main]

use arbitrary::Arbitrary;
use libfuzzer_sys::fuzz_target;
use nbrdf_core::network::Nbrdf;
use nbrdf_core_fuzz::{
    check_error_names_origin, check_evaluations, fixed_pairs, pairs_from_components, unit_value,
};
use std::fmt::Write;
use std::path::Path;

const ORIGIN: &str = "fuzz/structured.nbrdf.json";

#[derive(Arbitrary, Debug, Clone, Copy)]
enum Number {
    Float(f32),
    /// `{mantissa}e{exponent}`: any JSON number, including ones outside float32's range.
    Decimal {
        mantissa: i32,
        exponent: i16,
    },
    F32Max,
    AboveF32Max,
    Subnormal,
    NegativeZero,
    Nan,
}

impl Number {
    fn write(self, out: &mut String) {
        match self {
            // Non-finite floats print as NaN / inf: not JSON, which is part of what is tested.
            Number::Float(x) => write!(out, "{x:?}"),
            Number::Decimal { mantissa, exponent } => write!(out, "{mantissa}e{exponent}"),
            Number::F32Max => write!(out, "{:?}", f32::MAX),
            Number::AboveF32Max => write!(out, "3.5e38"),
            Number::Subnormal => write!(out, "1e-45"),
            Number::NegativeZero => write!(out, "-0.0"),
            Number::Nan => write!(out, "NaN"),
        }
        .expect("writing to a String cannot fail");
    }

    /// The value JSON readers would see, for deciding whether a network is tame.
    fn magnitude(self) -> f64 {
        match self {
            Number::Float(x) => f64::from(x).abs(),
            Number::Decimal { mantissa, exponent } => {
                f64::from(mantissa).abs() * 10f64.powi(i32::from(exponent))
            }
            Number::F32Max | Number::AboveF32Max | Number::Nan => f64::INFINITY,
            Number::Subnormal | Number::NegativeZero => 0.0,
        }
    }
}

#[derive(Arbitrary, Debug)]
enum Header {
    Valid,
    OtherFormat,
    Version(u64),
    VersionAsString,
    Missing,
}

#[derive(Arbitrary, Debug)]
enum ShapeEdit {
    Inputs(u64),
    Outputs(u64),
    DropWeight,
    ExtraWeight,
    DropBias,
    ExtraBias,
    DropLayer,
    ExtraLayer,
}

#[derive(Arbitrary, Debug)]
struct Sampling {
    known_model: bool,
    exponent: Number,
    specular_weight: Number,
}

#[derive(Arbitrary, Debug)]
struct Input {
    header: Header,
    hidden: [u8; 2],
    weight_seed: u64,
    /// Weights are uniform in `(-2^s, 2^s)`, `s` in [-16, 111]: from tame to near float32's limit.
    weight_scale: u8,
    /// Values replaced in the flat parameter list `W1 b1 W2 b2 W3 b3` (index modulo its length).
    replacements: Vec<(u16, Number)>,
    edit: Option<(u8, ShapeEdit)>,
    sampling: Option<Sampling>,
    provenance_depth: u8,
    directions: Vec<[f32; 6]>,
}

struct LayerText {
    inputs: u64,
    outputs: u64,
    weights: Vec<Number>,
    bias: Vec<Number>,
}

fn layers(input: &Input) -> (Vec<LayerText>, bool) {
    let h1 = 1 + u64::from(input.hidden[0]) % 96;
    let h2 = 1 + u64::from(input.hidden[1]) % 96;
    let scale = 2f32.powi(i32::from(input.weight_scale % 128) - 16);
    let mut k = 0u64;
    let mut layer = |inputs: u64, outputs: u64| {
        let mut values = |n: u64| -> Vec<Number> {
            (0..n)
                .map(|_| {
                    k += 1;
                    Number::Float(unit_value(input.weight_seed, k) * scale)
                })
                .collect()
        };
        LayerText {
            inputs,
            outputs,
            weights: values(inputs * outputs),
            bias: values(outputs),
        }
    };
    let mut stack = vec![layer(6, h1), layer(h1, h2), layer(h2, 3)];
    let total: usize = stack.iter().map(|l| l.weights.len() + l.bias.len()).sum();
    let mut tame = scale <= 0.25 && h1 <= 32 && h2 <= 32;
    for &(position, number) in input.replacements.iter().take(16) {
        let mut i = usize::from(position) % total;
        tame &= number.magnitude() <= 0.25;
        for l in stack.iter_mut() {
            if i < l.weights.len() {
                l.weights[i] = number;
                break;
            }
            i -= l.weights.len();
            if i < l.bias.len() {
                l.bias[i] = number;
                break;
            }
            i -= l.bias.len();
        }
    }
    if let Some((which, edit)) = &input.edit {
        let l = usize::from(*which) % 3;
        match *edit {
            ShapeEdit::Inputs(n) => stack[l].inputs = n,
            ShapeEdit::Outputs(n) => stack[l].outputs = n,
            ShapeEdit::DropWeight => drop(stack[l].weights.pop()),
            ShapeEdit::ExtraWeight => stack[l].weights.push(Number::Float(0.5)),
            ShapeEdit::DropBias => drop(stack[l].bias.pop()),
            ShapeEdit::ExtraBias => stack[l].bias.push(Number::Float(0.5)),
            ShapeEdit::DropLayer => drop(stack.remove(l)),
            ShapeEdit::ExtraLayer => stack.insert(l, layer(6, 6)),
        }
    }
    (stack, tame)
}

fn write_numbers(out: &mut String, numbers: &[Number]) {
    out.push('[');
    for (i, n) in numbers.iter().enumerate() {
        if i > 0 {
            out.push(',');
        }
        n.write(out);
    }
    out.push(']');
}

fn json(input: &Input, stack: &[LayerText]) -> String {
    let mut out = String::from("{");
    match input.header {
        Header::Valid => out.push_str("\"format\":\"nbrdf\",\"version\":1,"),
        Header::OtherFormat => out.push_str("\"format\":\"keras\",\"version\":1,"),
        Header::Version(v) => write!(out, "\"format\":\"nbrdf\",\"version\":{v},").unwrap(),
        Header::VersionAsString => out.push_str("\"format\":\"nbrdf\",\"version\":\"1\","),
        Header::Missing => {}
    }
    out.push_str("\"name\":\"fuzz\",\"layers\":[");
    for (i, l) in stack.iter().enumerate() {
        if i > 0 {
            out.push(',');
        }
        write!(
            out,
            "{{\"inputs\":{},\"outputs\":{},\"weights\":",
            l.inputs, l.outputs
        )
        .unwrap();
        write_numbers(&mut out, &l.weights);
        out.push_str(",\"bias\":");
        write_numbers(&mut out, &l.bias);
        out.push('}');
    }
    out.push(']');
    if let Some(s) = &input.sampling {
        let model = if s.known_model { "blinn-phong" } else { "ggx" };
        write!(out, ",\"sampling\":{{\"model\":\"{model}\",\"exponent\":").unwrap();
        s.exponent.write(&mut out);
        out.push_str(",\"specular_weight\":");
        s.specular_weight.write(&mut out);
        out.push_str(",\"source\":\"fuzz\"}");
    }
    let depth = usize::from(input.provenance_depth);
    out.push_str(",\"provenance\":{\"nested\":");
    out.push_str(&"[".repeat(depth));
    out.push_str(&"]".repeat(depth));
    out.push_str("}}");
    out
}

fuzz_target!(|input: Input| {
    let (stack, tame) = layers(&input);
    let text = json(&input, &stack);
    let net = match Nbrdf::from_json_str(&text, Path::new(ORIGIN)) {
        Ok(net) => net,
        Err(error) => return check_error_names_origin(&error, ORIGIN),
    };
    let fixed = fixed_pairs();
    let mut pairs = fixed.clone();
    pairs.extend(pairs_from_components(
        &input.directions[..input.directions.len().min(16)],
    ));
    let (single, batch) = check_evaluations(&net, &pairs, None);
    if !tame {
        return;
    }
    // Same network, same arithmetic up to summation order: the two paths must agree closely.
    for (i, (light, _)) in fixed.iter().enumerate() {
        let len = light.as_dvec3().length();
        let cos = if len > 0.0 && len.is_finite() {
            (light.as_dvec3().z / len).max(0.0)
        } else {
            0.0
        };
        for c in 0..3 {
            let (a, b) = (f64::from(single[i][c]) * cos, f64::from(batch[i][c]));
            assert!(
                (a - b).abs() <= 1e-3 * a.abs().max(b.abs()) + 1e-6,
                "pair {i} {:?}: eval * cos = {a}, eval_cos_batch = {b} (channel {c})",
                fixed[i]
            );
        }
    }
});
