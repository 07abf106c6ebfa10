//! The latent texture and its lookup, as Mitsuba's `bitmap` texture does it (docs/textured.md,
//! "Lookup"): the hit's UV through `to_uv`, then the wrap mode, then nearest or bilinear
//! filtering between texel centres at `(i + 1/2) / width`. Positions are rounded to float32 once,
//! like Dr.Jit's `fmadd(uv, resolution, -1/2)`, and texel indices are wrapped in float64, so a
//! UV of any finite size reads some texel instead of overflowing an integer.

use crate::error::{NbrdfError, Result};
use crate::fastmath::MulAdd;

/// The largest width or height of a latent texture (docs/formats.md).
pub const MAX_TEXTURE_SIDE: usize = 16384;
/// The most values (texels times channels) a latent texture holds: 1 GiB of float32.
pub const MAX_TEXTURE_VALUES: usize = 1 << 28;

/// What happens to texel indices outside the texture: Mitsuba's `bitmap` `wrap_mode`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WrapMode {
    /// Periodic: index `i` reads `i mod width`.
    Repeat,
    /// Periodic with every other period reflected (`... c b a | a b c | c b a ...`).
    Mirror,
    /// The edge texel continues outwards.
    Clamp,
}

/// How texels are combined: Mitsuba's `bitmap` `filter_type`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FilterMode {
    /// Bilinear between the four nearest texel centres.
    Bilinear,
    /// The texel the position falls in.
    Nearest,
}

impl WrapMode {
    /// The file's (and Mitsuba's) name.
    pub fn name(self) -> &'static str {
        match self {
            WrapMode::Repeat => "repeat",
            WrapMode::Mirror => "mirror",
            WrapMode::Clamp => "clamp",
        }
    }

    pub fn parse(name: &str) -> Option<Self> {
        [WrapMode::Repeat, WrapMode::Mirror, WrapMode::Clamp]
            .into_iter()
            .find(|mode| mode.name() == name)
    }

    /// Texel index `i` (an integer in float64) wrapped into `[0, size)`. Float64 holds every
    /// float32 integer exactly and `rem_euclid` is exact, so huge indices wrap correctly.
    fn wrap(self, i: f64, size: usize) -> usize {
        let n = size as f64;
        let wrapped = match self {
            WrapMode::Clamp => i.clamp(0.0, n - 1.0),
            WrapMode::Repeat => i.rem_euclid(n),
            WrapMode::Mirror => {
                let m = i.rem_euclid(2.0 * n);
                if m < n {
                    m
                } else {
                    2.0 * n - 1.0 - m
                }
            }
        };
        (wrapped as usize).min(size - 1)
    }
}

impl FilterMode {
    /// The file's (and Mitsuba's) name.
    pub fn name(self) -> &'static str {
        match self {
            FilterMode::Bilinear => "bilinear",
            FilterMode::Nearest => "nearest",
        }
    }

    pub fn parse(name: &str) -> Option<Self> {
        [FilterMode::Bilinear, FilterMode::Nearest]
            .into_iter()
            .find(|mode| mode.name() == name)
    }
}

/// Mitsuba's `to_uv`: a 3x3 matrix applied to `(u, v, 1)`, of which the first two rows are used
/// (`u' = m00 u + m01 v + m02`, `v' = m10 u + m11 v + m12`); the last row is `(0, 0, 1)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UvTransform {
    pub matrix: [[f32; 3]; 3],
}

impl UvTransform {
    pub const IDENTITY: UvTransform = UvTransform {
        matrix: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
    };

    /// Why the matrix is unusable (non-finite, or not affine), if it is.
    pub fn problem(&self) -> Option<String> {
        if self.matrix.iter().flatten().any(|m| !m.is_finite()) {
            return Some("to_uv has a non-finite entry".into());
        }
        if self.matrix[2] != [0.0, 0.0, 1.0] {
            return Some(format!(
                "to_uv's last row is {:?}, expected [0, 0, 1] (an affine map of (u, v, 1))",
                self.matrix[2]
            ));
        }
        None
    }

    #[inline(always)]
    pub fn apply(&self, [u, v]: [f32; 2]) -> [f32; 2] {
        let [r0, r1, _] = self.matrix;
        [r0[0] * u + r0[1] * v + r0[2], r1[0] * u + r1[1] * v + r1[2]]
    }
}

/// How a material reads its texture: `to_uv`, wrap mode and filter.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UvMapping {
    pub to_uv: UvTransform,
    pub wrap: WrapMode,
    pub filter: FilterMode,
}

impl Default for UvMapping {
    /// Mitsuba's `bitmap` defaults: identity, repeat, bilinear.
    fn default() -> Self {
        UvMapping {
            to_uv: UvTransform::IDENTITY,
            wrap: WrapMode::Repeat,
            filter: FilterMode::Bilinear,
        }
    }
}

/// The texels a lookup reads (indices `y * width + x`) and their weights: one texel of weight 1
/// (nearest) or four, in Dr.Jit's corner order `(x0, y0), (x1, y0), (x0, y1), (x1, y1)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Footprint {
    texels: [usize; 4],
    weights: [f32; 4],
    count: usize,
}

impl Footprint {
    /// The texels read, `y * width + x`.
    pub fn texels(&self) -> &[usize] {
        &self.texels[..self.count]
    }

    /// Their weights, summing to 1 (up to rounding).
    pub fn weights(&self) -> &[f32] {
        &self.weights[..self.count]
    }
}

impl UvMapping {
    /// The footprint of the hit's `uv` on a `width x height` texture, or `None` where `to_uv`
    /// gives a non-finite coordinate or one whose position overflows float32: a bad texel.
    pub fn footprint(&self, width: usize, height: usize, uv: [f32; 2]) -> Option<Footprint> {
        let [u, v] = self.to_uv.apply(uv);
        let ([x0, x1], [wx0, wx1]) = self.axis(u, width)?;
        let ([y0, y1], [wy0, wy1]) = self.axis(v, height)?;
        Some(match self.filter {
            FilterMode::Nearest => Footprint {
                texels: [y0 * width + x0; 4],
                weights: [1.0, 0.0, 0.0, 0.0],
                count: 1,
            },
            FilterMode::Bilinear => Footprint {
                texels: [
                    y0 * width + x0,
                    y0 * width + x1,
                    y1 * width + x0,
                    y1 * width + x1,
                ],
                weights: [wx0 * wy0, wx1 * wy0, wx0 * wy1, wx1 * wy1],
                count: 4,
            },
        })
    }

    /// The two texel indices along one axis and their weights (nearest: the texel, weight 1).
    #[inline(always)]
    fn axis(&self, coord: f32, size: usize) -> Option<([usize; 2], [f32; 2])> {
        let offset = match self.filter {
            FilterMode::Bilinear => -0.5,
            FilterMode::Nearest => 0.0,
        };
        // Rounded to float32 once, as by a fused multiply-add: the product of a float32 and a
        // side below 2^15 is exact in float64, and so is the offset below 2^52.
        let position = (f64::from(coord) * size as f64 + offset) as f32;
        if !position.is_finite() {
            return None;
        }
        let base = position.floor();
        let w1 = position - base;
        let i0 = self.wrap.wrap(f64::from(base), size);
        let i1 = self.wrap.wrap(f64::from(base) + 1.0, size);
        Some(([i0, i1], [1.0 - w1, w1]))
    }
}

/// A `width x height` texture of named float32 channels, texel-major (`texels[(y * width + x) *
/// channels + k]`), row `y = 0` at `v = 0`: the first row of the EXR file, as Mitsuba's
/// `bitmap` reads it. Values may be non-finite (the material is 0 where such a texel is read).
#[derive(Clone, Debug, PartialEq)]
pub struct LatentTexture {
    width: usize,
    height: usize,
    channel_names: Vec<String>,
    texels: Vec<f32>,
}

impl LatentTexture {
    /// A texture of `channel_names.len()` channels; `texels` holds `width * height` texels of
    /// that many values each. Sizes beyond [`MAX_TEXTURE_SIDE`] or [`MAX_TEXTURE_VALUES`] and
    /// empty or repeated channel names are refused.
    pub fn new(
        width: usize,
        height: usize,
        channel_names: Vec<String>,
        texels: Vec<f32>,
    ) -> Result<Self> {
        if let Some(problem) = size_problem(width, height, channel_names.len()) {
            return Err(NbrdfError::InvalidArgument(problem));
        }
        for (k, name) in channel_names.iter().enumerate() {
            if name.is_empty() || channel_names[..k].contains(name) {
                return Err(NbrdfError::InvalidArgument(format!(
                    "latent texture channel {k}: name '{name}' is empty or repeated"
                )));
            }
        }
        let expected = width * height * channel_names.len();
        if texels.len() != expected {
            return Err(NbrdfError::InvalidArgument(format!(
                "latent texture of {width} x {height} texels and {} channels needs {expected} \
                 values, got {}",
                channel_names.len(),
                texels.len()
            )));
        }
        Ok(LatentTexture {
            width,
            height,
            channel_names,
            texels,
        })
    }

    pub fn width(&self) -> usize {
        self.width
    }

    pub fn height(&self) -> usize {
        self.height
    }

    pub fn channel_names(&self) -> &[String] {
        &self.channel_names
    }

    pub fn channel_count(&self) -> usize {
        self.channel_names.len()
    }

    /// All values, texel-major.
    pub fn texels(&self) -> &[f32] {
        &self.texels
    }

    /// The channel values of texel `(x, y)`.
    pub fn texel(&self, x: usize, y: usize) -> &[f32] {
        let k = self.channel_count();
        let at = (y * self.width + x) * k;
        &self.texels[at..at + k]
    }

    /// The channels `first..first + out.len()` filtered over `footprint`, `sum_t w_t c_t`
    /// accumulated in corner order as Dr.Jit does; a non-finite texel in the footprint makes the
    /// result non-finite (`0 * NaN` is NaN), which callers treat as a bad texel. Callers pass a
    /// footprint of this texture's size and `first + out.len()` at most the channel count.
    #[inline(always)]
    pub(super) fn filter_into<M: MulAdd>(
        &self,
        footprint: &Footprint,
        first: usize,
        out: &mut [f32],
    ) {
        let k = self.channel_count();
        out.fill(0.0);
        for (&texel, &weight) in footprint.texels().iter().zip(footprint.weights()) {
            let values = &self.texels[texel * k + first..][..out.len()];
            for (o, &c) in out.iter_mut().zip(values) {
                *o = M::mul_add(c, weight, *o);
            }
        }
    }

    /// Every channel at the hit's `uv` (portable arithmetic), or `None` for a bad texel: a
    /// non-finite mapped coordinate or a non-finite value in the footprint.
    pub fn lookup(&self, mapping: &UvMapping, uv: [f32; 2]) -> Option<Vec<f32>> {
        let footprint = mapping.footprint(self.width, self.height, uv)?;
        let mut out = vec![0.0; self.channel_count()];
        self.filter_into::<crate::fastmath::Unfused>(&footprint, 0, &mut out);
        out.iter().all(|c| c.is_finite()).then_some(out)
    }
}

/// Why a `width x height` texture of `channels` channels is refused, if it is.
pub(super) fn size_problem(width: usize, height: usize, channels: usize) -> Option<String> {
    if !(1..=MAX_TEXTURE_SIDE).contains(&width) || !(1..=MAX_TEXTURE_SIDE).contains(&height) {
        return Some(format!(
            "latent texture of {width} x {height} texels: width and height must be in [1, \
             {MAX_TEXTURE_SIDE}]"
        ));
    }
    if channels == 0 {
        return Some("latent texture without channels".into());
    }
    if width * height * channels > MAX_TEXTURE_VALUES {
        return Some(format!(
            "latent texture of {width} x {height} texels and {channels} channels holds more \
             than {MAX_TEXTURE_VALUES} values"
        ));
    }
    None
}
