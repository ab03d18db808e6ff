//! FNV-1a, 64 bit: the one hash of the crate's checksums and fingerprints (checkpoints, run
//! records, scene marks, duplicate frames). Not cryptographic: it tells accidents apart, not
//! attacks.
//!
//! ```
//! use bbsplat::fnv::{BASIS, fnv1a, update};
//! assert_eq!(fnv1a(b""), BASIS);
//! assert_eq!(fnv1a(b"a"), 0xaf63_dc4c_8601_ec8c);
//! assert_eq!(update(fnv1a(b"ab"), b"c"), fnv1a(b"abc"));
//! ```

/// The offset basis: the hash of no bytes.
pub const BASIS: u64 = 0xcbf2_9ce4_8422_2325;

/// The FNV prime of 64 bits.
const PRIME: u64 = 0x0000_0100_0000_01b3;

/// The hash of `data`.
pub fn fnv1a(data: &[u8]) -> u64 {
    update(BASIS, data)
}

/// Continues the hash `h` over `data`.
pub fn update(h: u64, data: &[u8]) -> u64 {
    data.iter().fold(h, |h, &b| (h ^ b as u64).wrapping_mul(PRIME))
}
