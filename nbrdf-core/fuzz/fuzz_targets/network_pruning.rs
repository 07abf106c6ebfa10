//! Leaving out the hidden units that `network/pruning.rs` proves dead must change no value above
//! the horizon. Networks are drawn to sit on the edge of that proof: narrow (1-24 units), biases
//! shifted toward dead units, weights from tiny to near float32's limit with fuzzer-placed
//! extremes (float32's largest values, powers of two up to 2^127, subnormals), isotropic or
//! anisotropic. Each accepted network is evaluated full and pruned at the fixed pairs, pairs
//! near the horizon and the normal, and fuzzer-chosen pairs.

#![no_main]

use arbitrary::Arbitrary;
use libfuzzer_sys::fuzz_target;
use nbrdf_core::network::{parameter_count_for, Nbrdf};
use nbrdf_core_fuzz::{
    check_pruning, fixed_pairs, grazing_pairs, pairs_from_components, unit_value,
};

#[derive(Arbitrary, Debug, Clone, Copy)]
enum Value {
    Float(f32),
    /// `sign * 2^exponent`, up to float32's largest powers of two.
    PowerOfTwo {
        negative: bool,
        exponent: i8,
    },
    F32Max,
    NegativeF32Max,
    Subnormal,
    Zero,
}

impl Value {
    fn get(self) -> f32 {
        match self {
            Value::Float(x) => x,
            Value::PowerOfTwo { negative, exponent } => {
                let x = 2f32.powi(i32::from(exponent));
                if negative {
                    -x
                } else {
                    x
                }
            }
            Value::F32Max => f32::MAX,
            Value::NegativeF32Max => -f32::MAX,
            Value::Subnormal => 1e-45,
            Value::Zero => 0.0,
        }
    }
}

#[derive(Arbitrary, Debug)]
struct Input {
    hidden: u8,
    anisotropic: bool,
    weight_seed: u64,
    /// Weights uniform in `(-2^s, 2^s)`, `s` in [-8, 31].
    weight_scale: u8,
    /// Added to every bias of the two hidden layers (after the replacements), in units of the
    /// weight scale / 8.
    bias_shift: [i8; 2],
    /// Values replaced in the flat parameter list `W1 b1 W2 b2 W3 b3` (index modulo its length).
    replacements: Vec<(u16, Value)>,
    directions: Vec<[f32; 6]>,
}

fn parameters(input: &Input, hidden: usize, scale: f32) -> Vec<f32> {
    let mut params: Vec<f32> = (0..parameter_count_for(hidden) as u64)
        .map(|k| unit_value(input.weight_seed, k) * scale)
        .collect();
    for &(position, value) in input.replacements.iter().take(16) {
        let i = usize::from(position) % params.len();
        params[i] = value.get();
    }
    params
}

fuzz_target!(|input: Input| {
    let hidden = 1 + usize::from(input.hidden) % 24;
    let scale = 2f32.powi(i32::from(input.weight_scale % 40) - 8);
    let Ok(mut net) = Nbrdf::from_flat("fuzz", hidden, &parameters(&input, hidden, scale)) else {
        return; // non-finite replacements: refused, which the other targets check
    };
    net.anisotropic = input.anisotropic;
    for (layer, shift) in net.layers.iter_mut().zip(input.bias_shift) {
        for b in &mut layer.bias {
            *b += f32::from(shift) * scale / 8.0;
        }
    }
    let mut pairs = fixed_pairs();
    pairs.extend(grazing_pairs());
    pairs.extend(pairs_from_components(
        &input.directions[..input.directions.len().min(16)],
    ));
    check_pruning(&net, &pairs);
});
