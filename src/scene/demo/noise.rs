//! A lattice hash for the demo scene's procedural noise, built on the crate's SplitMix64
//! finaliser so that a seed's textures never change under a dependency upgrade.
use crate::rng::mix64;

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
