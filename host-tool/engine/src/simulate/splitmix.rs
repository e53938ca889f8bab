//! The random stream of [`super::synth`]: SplitMix64 (Steele, Lea, Flood
//! 2014) with the exact formulas of `trueaxis-test-support`'s generator,
//! which the synthetic mill drew from before it moved into the simulator —
//! copied so the engine needs that crate only for its tests, and checked
//! against it below so every data set stays bit-identical.

use std::f64::consts::TAU;

/// SplitMix64: a 64-bit counter through a finaliser.
#[derive(Clone, Debug)]
pub(super) struct SplitMix64(pub(super) u64);

impl SplitMix64 {
    /// The next 64 random bits.
    pub(super) fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in (0, 1): the top 53 bits plus half a step, never 0.
    pub(super) fn unit_open(&mut self) -> f64 {
        ((self.next_u64() >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }

    /// A standard normal by Box–Muller (one of the pair), from two
    /// [`unit_open`](Self::unit_open) draws.
    pub(super) fn normal(&mut self) -> f64 {
        let (u1, u2) = (self.unit_open(), self.unit_open());
        (-2.0 * u1.ln()).sqrt() * (TAU * u2).cos()
    }
}

#[cfg(test)]
mod tests {
    use super::SplitMix64;

    /// The copy draws the same bits as the test crates' generator, for
    /// every method the synthetic mill uses, interleaved as it uses them.
    #[test]
    fn the_stream_is_test_support_s_bit_for_bit() {
        for seed in [
            0,
            1,
            0x5EED,
            7u64.wrapping_mul(0x2545_F491_4F6C_DD1D) ^ 0x5EED,
            u64::MAX,
        ] {
            let mut ours = SplitMix64(seed);
            let mut theirs = trueaxis_test_support::SplitMix64::new(seed);
            for i in 0..1000 {
                match i % 3 {
                    0 => assert_eq!(ours.next_u64(), theirs.next_u64()),
                    1 => assert_eq!(ours.unit_open().to_bits(), theirs.unit_open().to_bits()),
                    _ => assert_eq!(ours.normal().to_bits(), theirs.normal().to_bits()),
                }
            }
        }
    }

    /// The published first outputs of SplitMix64 from seed 0.
    #[test]
    fn the_stream_is_splitmix64() {
        let mut r = SplitMix64(0);
        assert_eq!(r.next_u64(), 0xE220_A839_7B1D_CDAF);
        assert_eq!(r.next_u64(), 0x6E78_9E6A_A1B9_65F4);
    }
}
