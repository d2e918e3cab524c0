//! A tiny deterministic random source (SplitMix64) and a lattice hash for procedural noise.
//! Written out here rather than taken from a crate so that the demo scene a seed produces can
//! never change under a dependency upgrade.

/// SplitMix64: small, fast and good enough to jitter a scene layout.
#[derive(Clone, Debug)]
pub struct SplitMix64 {
    state: u64,
}

impl SplitMix64 {
    pub fn new(seed: u64) -> Self {
        SplitMix64 { state: seed }
    }

    pub fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        mix64(self.state)
    }

    /// Uniform in [0, 1), from the top 53 bits so every value is exactly representable.
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform in [lo, hi).
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }

    /// Fisher-Yates shuffle.
    pub fn shuffle<T>(&mut self, items: &mut [T]) {
        for i in (1..items.len()).rev() {
            let j = (self.next_u64() % (i as u64 + 1)) as usize;
            items.swap(i, j);
        }
    }
}

/// The SplitMix64 finaliser: a bijective scramble of 64 bits.
fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// A value in [0, 1) for an integer lattice point; `salt` gives independent lattices.
pub fn lattice_hash(x: i64, y: i64, z: i64, salt: u64) -> f64 {
    // Odd multipliers spread each coordinate over all bits; one finaliser pass then mixes
    // them, which is plenty for texture noise (and this runs ~100 times per pixel).
    let h = (x as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ (y as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F)
        ^ (z as u64).wrapping_mul(0x1656_67B1_9E37_79F9)
        ^ salt.wrapping_mul(0x27D4_EB2F_1656_67C5);
    (mix64(h) >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_seed_same_sequence_and_different_seeds_differ() {
        let a: Vec<u64> = std::iter::repeat_with({
            let mut r = SplitMix64::new(7);
            move || r.next_u64()
        })
        .take(8)
        .collect();
        let mut r = SplitMix64::new(7);
        let b: Vec<u64> = (0..8).map(|_| r.next_u64()).collect();
        assert_eq!(a, b);
        let mut other = SplitMix64::new(8);
        assert!((0..8).all(|i| other.next_u64() != b[i]));
    }

    #[test]
    fn unit_values_cover_the_interval_without_leaving_it() {
        let mut r = SplitMix64::new(1);
        let values: Vec<f64> = (0..10_000).map(|_| r.unit()).collect();
        assert!(values.iter().all(|v| (0.0..1.0).contains(v)));
        let mean = values.iter().sum::<f64>() / values.len() as f64;
        assert!((mean - 0.5).abs() < 0.02, "mean {mean}");
        assert!(values.iter().any(|&v| v < 0.01) && values.iter().any(|&v| v > 0.99));
    }

    #[test]
    fn shuffle_is_a_permutation() {
        let mut r = SplitMix64::new(3);
        let mut items: Vec<u32> = (0..20).collect();
        r.shuffle(&mut items);
        assert_ne!(items, (0..20).collect::<Vec<_>>());
        items.sort();
        assert_eq!(items, (0..20).collect::<Vec<_>>());
    }

    #[test]
    fn lattice_hash_depends_on_every_coordinate_and_the_salt() {
        let base = lattice_hash(1, 2, 3, 0);
        assert_eq!(base, lattice_hash(1, 2, 3, 0));
        for other in [
            lattice_hash(0, 2, 3, 0),
            lattice_hash(1, 0, 3, 0),
            lattice_hash(1, 2, 0, 0),
            lattice_hash(1, 2, 3, 1),
        ] {
            assert_ne!(base, other);
        }
        assert!((0.0..1.0).contains(&lattice_hash(-5, i64::MAX, i64::MIN, u64::MAX)));
    }
}
