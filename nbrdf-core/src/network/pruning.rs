//! Hidden units that no pair of directions above the horizon can switch on, proved by interval
//! arithmetic, and the narrower network without them (docs/design.md section 4). A dead unit
//! outputs exactly 0, so dropping its row and column changes no value the renderer uses.
//!
//! A proof, not sampling: a unit that fires only in a small corner would be missed by finite
//! samples. Boxes of the input domain (`theta_h`, `theta_d` in `[0, pi/2]`, `phi_d` and for
//! anisotropic networks `phi_h` over the circle, both directions above the horizon:
//! `cos theta_h cos theta_d >= sin theta_h sin theta_d |cos phi_d|`) are bounded layer by layer
//! and split where a candidate may be positive, within a budget of boxes and work; a unit is
//! inactive only when every box bounds it at or below `-margin`, margins far above float32's
//! rounding. What the budget cannot settle stays.
//!
//! Twin: none (the plugin takes the proof from the C library: `nbrdf_material_network`, and
//! `nbrdf_material_active_units` for new weights). Tests: `network::tests` and the fuzz target
//! `network_pruning`.

use super::{Layer, Nbrdf, INPUTS};
use crate::coords::{network_input_from_angles_for, RusinkiewiczAngles};
use crate::fastmath::Unfused;
use std::f64::consts::{FRAC_PI_2, PI, TAU};

/// Which hidden units can fire: `hidden1[k]` for unit `k` of the first hidden layer,
/// `hidden2[k]` of the second. `true` also for units that could not be proved dead.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ActiveUnits {
    pub hidden1: Vec<bool>,
    pub hidden2: Vec<bool>,
}

impl ActiveUnits {
    /// Number of units proved inactive, per hidden layer.
    pub fn inactive_counts(&self) -> [usize; 2] {
        let dead = |units: &[bool]| units.iter().filter(|&&active| !active).count();
        [dead(&self.hidden1), dead(&self.hidden2)]
    }
}

/// Absolute widening of every input interval (float32 inputs are within ~1e-6 of the exact ones).
const INPUT_MARGIN: f64 = 1e-5;
/// Widening of each pre-activation bound, relative to `|b| + sum |w| max|x|` (float32 sums of 21
/// products round within ~1e-6 of that).
const RELATIVE_MARGIN: f64 = 1e-5;
/// Splits along every axis of a box before a still-open box is given up on.
const MAX_DEPTH: u32 = 10;
/// Boxes bounded at most; beyond it the remaining candidates stay active.
const BOX_BUDGET: usize = 200_000;
/// Interval multiply-adds spent at most, so that loading a very wide network (a box costs
/// `6 h1 + h1 h2 + 3 h2` of them) proves less instead of taking minutes; the paper's 21-wide
/// networks stay within [`BOX_BUDGET`].
const WORK_BUDGET: usize = 200_000_000;

/// Boxes bounded at most for hidden widths `h1, h2`: [`BOX_BUDGET`], fewer where the boxes'
/// work would exceed [`WORK_BUDGET`], and at least one (the whole domain).
pub(crate) fn box_budget(widths: [usize; 2]) -> usize {
    let [h1, h2] = widths;
    let work_per_box = super::INPUTS
        .saturating_mul(h1)
        .saturating_add(h1.saturating_mul(h2))
        .saturating_add(h2.saturating_mul(3))
        .max(1);
    (WORK_BUDGET / work_per_box).clamp(1, BOX_BUDGET)
}

/// A box of the input domain: `theta_h, phi_h, theta_d, phi_d` (`phi_h` fixed at 0 for
/// isotropic networks).
#[derive(Clone, Copy, Debug)]
struct Domain {
    lo: [f64; 4],
    hi: [f64; 4],
}

#[derive(Clone, Copy, Debug)]
struct Interval {
    lo: f64,
    hi: f64,
}

impl Interval {
    fn new(lo: f64, hi: f64) -> Self {
        Interval { lo, hi }
    }

    fn mul(self, other: Interval) -> Interval {
        let products = [
            self.lo * other.lo,
            self.lo * other.hi,
            self.hi * other.lo,
            self.hi * other.hi,
        ];
        Interval::new(
            products.iter().copied().fold(f64::INFINITY, f64::min),
            products.iter().copied().fold(f64::NEG_INFINITY, f64::max),
        )
    }

    fn abs(self) -> Interval {
        if self.lo >= 0.0 {
            self
        } else if self.hi <= 0.0 {
            Interval::new(-self.hi, -self.lo)
        } else {
            Interval::new(0.0, self.hi.max(-self.lo))
        }
    }

    fn magnitude(self) -> f64 {
        self.lo.abs().max(self.hi.abs())
    }
}

/// The exact range of `sin` on `[a, b]` for `0 <= a <= b <= 2 pi + pi/2`.
fn sin_range(a: f64, b: f64) -> Interval {
    let (sa, sb) = (a.sin(), b.sin());
    let mut range = Interval::new(sa.min(sb), sa.max(sb));
    let contains = |x: f64| a <= x && x <= b;
    if contains(FRAC_PI_2) || contains(FRAC_PI_2 + TAU) {
        range.hi = 1.0;
    }
    if contains(1.5 * PI) {
        range.lo = -1.0;
    }
    range
}

fn cos_range(a: f64, b: f64) -> Interval {
    sin_range(a + FRAC_PI_2, b + FRAC_PI_2)
}

impl Domain {
    fn whole(anisotropic: bool) -> Self {
        let phi_h = if anisotropic { TAU } else { 0.0 };
        Domain {
            lo: [0.0; 4],
            hi: [FRAC_PI_2, phi_h, FRAC_PI_2, TAU],
        }
    }

    fn centre(&self) -> [f64; 4] {
        std::array::from_fn(|k| 0.5 * (self.lo[k] + self.hi[k]))
    }

    /// Whether both directions are above the horizon at a point (the light's elevation is
    /// `cos th cos td - sin th sin td cos pd`, the view's the same with `+`).
    fn above_horizon(angles: [f64; 4]) -> bool {
        let [theta_h, _, theta_d, phi_d] = angles;
        theta_h.cos() * theta_d.cos() >= theta_h.sin() * theta_d.sin() * phi_d.cos().abs()
    }

    /// Whether some point of the box may have both directions above the horizon.
    fn may_be_above_horizon(&self) -> bool {
        let cos_h = cos_range(self.lo[0], self.hi[0]);
        let sin_h = sin_range(self.lo[0], self.hi[0]);
        let cos_d = cos_range(self.lo[2], self.hi[2]);
        let sin_d = sin_range(self.lo[2], self.hi[2]);
        let cos_p = cos_range(self.lo[3], self.hi[3]).abs();
        let slack = cos_h.mul(cos_d).hi - sin_h.mul(sin_d).mul(cos_p).lo;
        slack >= -INPUT_MARGIN
    }

    /// Bounds of each network input over the box, widened by [`INPUT_MARGIN`].
    fn input_bounds(&self) -> [Interval; INPUTS] {
        let sin_h = sin_range(self.lo[0], self.hi[0]);
        let cos_h = cos_range(self.lo[0], self.hi[0]);
        let sin_d = sin_range(self.lo[2], self.hi[2]);
        let exact = [
            sin_h.mul(cos_range(self.lo[1], self.hi[1])),
            sin_h.mul(sin_range(self.lo[1], self.hi[1])),
            cos_h,
            sin_d.mul(cos_range(self.lo[3], self.hi[3])),
            sin_d.mul(sin_range(self.lo[3], self.hi[3])),
            cos_range(self.lo[2], self.hi[2]),
        ];
        exact.map(|x| Interval::new(x.lo - INPUT_MARGIN, x.hi + INPUT_MARGIN))
    }

    /// The halves along every axis of positive width (8 children, 16 for anisotropic networks).
    fn children(&self) -> Vec<Domain> {
        let axes: Vec<usize> = (0..4).filter(|&k| self.hi[k] > self.lo[k]).collect();
        let mut children = Vec::with_capacity(1 << axes.len());
        for mask in 0..(1usize << axes.len()) {
            let mut child = *self;
            for (bit, &axis) in axes.iter().enumerate() {
                let middle = 0.5 * (self.lo[axis] + self.hi[axis]);
                if mask >> bit & 1 == 0 {
                    child.hi[axis] = middle;
                } else {
                    child.lo[axis] = middle;
                }
            }
            children.push(child);
        }
        children
    }
}

/// Bounds of `x W + b` over input bounds, widened by [`RELATIVE_MARGIN`]. Returns the largest
/// `|b| + sum |w| max|x|` of the outputs, which bounds every partial sum of their evaluation.
fn affine_bounds(layer: &Layer, x: &[Interval], out: &mut Vec<Interval>) -> f64 {
    out.clear();
    let mut largest = 0.0f64;
    for o in 0..layer.outputs {
        let bias = f64::from(layer.bias[o]);
        let (mut lo, mut hi, mut scale) = (bias, bias, bias.abs());
        for (i, xi) in x.iter().enumerate() {
            let w = f64::from(layer.weights[i * layer.outputs + o]);
            lo += (w * xi.lo).min(w * xi.hi);
            hi += (w * xi.lo).max(w * xi.hi);
            scale += w.abs() * xi.magnitude();
        }
        let margin = RELATIVE_MARGIN * scale;
        out.push(Interval::new(lo - margin, hi + margin));
        largest = largest.max(scale);
    }
    largest
}

fn relu_bounds(z: &[Interval]) -> Vec<Interval> {
    z.iter()
        .map(|z| Interval::new(z.lo.max(0.0), z.hi.max(0.0)))
        .collect()
}

/// Whether some partial sum of a hidden layer may leave float32's range somewhere in the domain
/// (bounded over the whole of it). The proof is about exact sums: a float32 sum whose positive
/// terms overflow to `+inf` before its negative ones are added fires although its exact value
/// is negative, so there the float32 evaluation is not what was proved.
fn float32_may_overflow(layers: &[Layer; 3], anisotropic: bool) -> bool {
    let (mut first, mut second) = (Vec::new(), Vec::new());
    let scale1 = affine_bounds(
        &layers[0],
        &Domain::whole(anisotropic).input_bounds(),
        &mut first,
    );
    let scale2 = affine_bounds(&layers[1], &relu_bounds(&first), &mut second);
    // A quarter of float32's largest value leaves room for the rounding of 100s of terms.
    scale1.max(scale2) >= f64::from(f32::MAX) / 4.0
}

/// Evaluates the network at a point of the domain as a renderer does, leaving both hidden
/// layers' outputs in `hidden` (positive exactly for the units that fire there). `phi_h` is 0
/// throughout an isotropic network's domain, so the anisotropic input serves both.
fn fire_at(
    layers: &[Layer; 3],
    [theta_h, phi_h, theta_d, phi_d]: [f64; 4],
    hidden: &mut [Vec<f32>; 2],
) {
    let angles = RusinkiewiczAngles {
        theta_h,
        phi_h,
        theta_d,
        phi_d,
    };
    let x = network_input_from_angles_for(true, &angles);
    let [h1, h2] = hidden;
    // Only the hidden activations matter here: no output is computed.
    super::kernel::eval_input_generic::<Unfused>(layers, &x, h1, h2, &mut []);
}

/// The hidden units of a `6 -> h1 -> h2 -> 3` network that some pair of directions above the
/// horizon may activate (see the module documentation). Layers whose shapes do not chain, or
/// with a parameter that is not finite (whose interval bounds would prove nothing), give every
/// unit active, and so do layers whose float32 sums may overflow ([`float32_may_overflow`]).
pub fn active_units(layers: &[Layer; 3], anisotropic: bool) -> ActiveUnits {
    let widths = [layers[0].outputs, layers[1].outputs];
    let all_active = ActiveUnits {
        hidden1: vec![true; widths[0]],
        hidden2: vec![true; widths[1]],
    };
    // The proof is about hidden units: it holds for any number of outputs (RGB or spectral).
    if super::format::shape_problem(layers, layers[2].outputs).is_some()
        || super::format::value_problem(layers).is_some()
        || float32_may_overflow(layers, anisotropic)
    {
        return all_active;
    }
    // candidate[l][k]: unit k of hidden layer l not yet seen positive nor given up on.
    let mut candidate = [vec![true; widths[0]], vec![true; widths[1]]];
    let mut stack = vec![(Domain::whole(anisotropic), 0u32)];
    let mut bounded = 0usize;
    let budget = box_budget(widths);
    let (mut first, mut second) = (Vec::new(), Vec::new());
    let mut hidden = [vec![0.0; widths[0]], vec![0.0; widths[1]]];
    while let Some((domain, depth)) = stack.pop() {
        if !candidate.iter().flatten().any(|&c| c) {
            break;
        }
        if !domain.may_be_above_horizon() {
            continue;
        }
        let centre = domain.centre();
        if Domain::above_horizon(centre) {
            fire_at(layers, centre, &mut hidden);
            clear_fired(&mut candidate, &hidden);
        }
        bounded += 1;
        affine_bounds(&layers[0], &domain.input_bounds(), &mut first);
        affine_bounds(&layers[1], &relu_bounds(&first), &mut second);
        let open = open_units(&candidate, [&first, &second]);
        if open.is_empty() {
            continue;
        }
        if depth >= MAX_DEPTH || bounded + stack.len() >= budget {
            for (l, k) in open {
                candidate[l][k] = false;
            }
            continue;
        }
        stack.extend(
            domain
                .children()
                .into_iter()
                .map(|child| (child, depth + 1)),
        );
    }
    active_from_dead(all_active, &candidate)
}

/// Drops from the candidates the units `hidden` (a point's hidden outputs) shows firing.
fn clear_fired(candidate: &mut [Vec<bool>; 2], hidden: &[Vec<f32>; 2]) {
    for (flags, values) in candidate.iter_mut().zip(hidden) {
        for (flag, &value) in flags.iter_mut().zip(values) {
            *flag &= value <= 0.0;
        }
    }
}

/// The `(layer, unit)` candidates whose pre-activation `bounds` over a box may be positive:
/// those the box does not prove dead.
fn open_units(candidate: &[Vec<bool>; 2], bounds: [&Vec<Interval>; 2]) -> Vec<(usize, usize)> {
    bounds
        .iter()
        .enumerate()
        .flat_map(|(l, bounds)| {
            let candidate = &candidate[l];
            bounds
                .iter()
                .enumerate()
                .filter(move |&(k, z)| candidate[k] && z.hi > 0.0)
                .map(move |(k, _)| (l, k))
        })
        .collect()
}

/// The active units once the search ends: all but the `dead` ones (candidates left), keeping a
/// layer's first unit when all of it is dead, since a layer needs a width.
fn active_from_dead(all_active: ActiveUnits, dead: &[Vec<bool>; 2]) -> ActiveUnits {
    let mut active = all_active;
    for (flags, dead) in [&mut active.hidden1, &mut active.hidden2]
        .into_iter()
        .zip(dead)
    {
        for (flag, &dead) in flags.iter_mut().zip(dead) {
            *flag = !dead;
        }
        if flags.iter().all(|&a| !a) {
            flags[0] = true;
        }
    }
    active
}

impl Nbrdf {
    /// The hidden units some pair of directions above the horizon may activate
    /// ([`active_units`]).
    pub fn active_units(&self) -> ActiveUnits {
        active_units(&self.layers, self.anisotropic)
    }

    /// The same BRDF on every pair of directions above the horizon, without the hidden units
    /// that can never fire there: the network to evaluate for rendering. Not for raw inputs
    /// off the hemisphere ([`Nbrdf::eval_input`] of arbitrary vectors, tabulation at angles
    /// with a direction below the horizon), where a dropped unit may fire.
    pub fn without_inactive_units(&self) -> Nbrdf {
        self.with_units(&self.active_units())
    }

    /// The network restricted to the units `active` keeps: [`Nbrdf::without_inactive_units`]
    /// when `active` is [`Nbrdf::active_units`], for callers that also hand the proof on (the C
    /// library gives it to the plugin's kernels) and so run it once. `active` has this network's
    /// hidden widths.
    pub fn with_units(&self, active: &ActiveUnits) -> Nbrdf {
        let mut pruned = self.clone();
        pruned.layers = keep_units(&self.layers, active);
        pruned
    }
}

/// The layers restricted to the active units: columns of layer 1 and rows of layer 2 for the
/// first hidden layer, columns of layer 2 and rows of layer 3 for the second.
fn keep_units(layers: &[Layer; 3], active: &ActiveUnits) -> [Layer; 3] {
    let kept = |flags: &[bool]| -> Vec<usize> {
        flags
            .iter()
            .enumerate()
            .filter_map(|(k, &a)| a.then_some(k))
            .collect()
    };
    let (rows1, rows2) = (kept(&active.hidden1), kept(&active.hidden2));
    let all_inputs: Vec<usize> = (0..layers[0].inputs).collect();
    let all_outputs: Vec<usize> = (0..layers[2].outputs).collect();
    [
        select(&layers[0], &all_inputs, &rows1),
        select(&layers[1], &rows1, &rows2),
        select(&layers[2], &rows2, &all_outputs),
    ]
}

fn select(layer: &Layer, inputs: &[usize], outputs: &[usize]) -> Layer {
    Layer {
        inputs: inputs.len(),
        outputs: outputs.len(),
        weights: inputs
            .iter()
            .flat_map(|&i| {
                outputs
                    .iter()
                    .map(move |&o| layer.weights[i * layer.outputs + o])
            })
            .collect(),
        bias: outputs.iter().map(|&o| layer.bias[o]).collect(),
    }
}
