//! The crate's one random number generator: SplitMix64 (Steele, Lea and Flood 2014), small,
//! dependency-free and identical on every platform.
//!
//! Training must be reproducible for a seed whatever the thread count, so its draws are
//! addressed by `(seed, stream, counter)` ([`SplitMix64::new`]) instead of coming from a shared
//! sequential generator: sample `k` of the data set, say, always sees the same uniforms, whichever
//! thread draws it. Tests and benchmarks that only need a fixed stream start from a raw state
//! ([`SplitMix64::from_state`]).

const GOLDEN_GAMMA: u64 = 0x9e37_79b9_7f4a_7c15;

/// The SplitMix64 output function: a bijective 64-bit mixer with good avalanche.
#[inline]
pub fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// Independent stream keys derived from one user seed, one per purpose, so that e.g. changing
/// the number of samples does not change the initial weights.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stream {
    TrainSamples = 1,
    ValidationSamples = 2,
    Init = 3,
    Shuffle = 4,
    FitSamples = 5,
    Metrics = 6,
    /// The autoencoder and predictor (split, initialisation, shuffling).
    Latent = 7,
}

/// A sequential SplitMix64 generator.
#[derive(Clone, Debug)]
pub struct SplitMix64 {
    state: u64,
}

impl SplitMix64 {
    /// The generator of `stream` under `seed`, positioned at `counter` draws from its start.
    pub fn new(seed: u64, stream: Stream, counter: u64) -> Self {
        let base = mix64(seed ^ mix64(stream as u64 + 1));
        Self::from_state(base.wrapping_add(counter.wrapping_mul(GOLDEN_GAMMA)))
    }

    /// The plain generator whose state starts at `state` (the textbook SplitMix64 seeding).
    pub fn from_state(state: u64) -> Self {
        SplitMix64 { state }
    }

    #[inline]
    pub fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(GOLDEN_GAMMA);
        mix64(self.state)
    }

    /// Uniform in `[0, 1)`, 24 bits so that every value is exactly representable.
    #[inline]
    pub fn next_f32(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 * (1.0 / (1u64 << 24) as f32)
    }

    /// Uniform in `[0, 1)` with 53 random bits.
    #[inline]
    pub fn next_f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform integer in `[0, n)` (Lemire's multiply-shift; the bias is below 2^-32 for the
    /// data set sizes used here, and it keeps the shuffle branch-free and reproducible).
    #[inline]
    pub fn below(&mut self, n: u64) -> u64 {
        ((self.next_u64() as u128 * n as u128) >> 64) as u64
    }

    /// Fisher-Yates shuffle.
    pub fn shuffle<T>(&mut self, items: &mut [T]) {
        for i in (1..items.len()).rev() {
            let j = self.below(i as u64 + 1) as usize;
            items.swap(i, j);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counter_addresses_the_sequence() {
        let mut a = SplitMix64::new(7, Stream::Init, 0);
        for _ in 0..5 {
            a.next_u64();
        }
        let mut b = SplitMix64::new(7, Stream::Init, 5);
        assert_eq!(a.next_u64(), b.next_u64());
    }

    #[test]
    fn streams_differ_and_uniforms_are_in_range() {
        let mut a = SplitMix64::new(7, Stream::Init, 0);
        let mut b = SplitMix64::new(7, Stream::Shuffle, 0);
        assert_ne!(a.next_u64(), b.next_u64());
        let mean = (0..10_000)
            .map(|_| a.next_f64())
            .inspect(|u| assert!((0.0..1.0).contains(u)))
            .sum::<f64>()
            / 1e4;
        assert!((mean - 0.5).abs() < 0.02);
    }

    /// The published reference output of SplitMix64 seeded with 1234567 (Vigna's splitmix64.c).
    #[test]
    fn matches_the_reference_sequence() {
        let mut rng = SplitMix64::from_state(1_234_567);
        let want = [
            6_457_827_717_110_365_317u64,
            3_203_168_211_198_807_973,
            9_817_491_932_198_370_423,
        ];
        for w in want {
            assert_eq!(rng.next_u64(), w);
        }
    }

    #[test]
    fn shuffle_is_a_permutation() {
        let mut v: Vec<u32> = (0..1000).collect();
        SplitMix64::new(1, Stream::Shuffle, 0).shuffle(&mut v);
        assert_ne!(v, (0..1000).collect::<Vec<_>>());
        v.sort_unstable();
        assert_eq!(v, (0..1000).collect::<Vec<_>>());
    }
}
