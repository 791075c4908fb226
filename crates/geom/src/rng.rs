//! Seeded, platform-independent random numbers: every stochastic step takes a seed, and the
//! same seed gives the same output on every machine (ChaCha8, not the OS generator).

use rand::SeedableRng;

/// The random generator used everywhere in irmirror.
pub type Rng = rand_chacha::ChaCha8Rng;

/// A generator for `seed`, decorrelated per `stream` (e.g. one stream per restart or thread).
pub fn seeded(seed: u64, stream: u64) -> Rng {
    let mut rng = Rng::seed_from_u64(seed);
    rng.set_stream(stream);
    rng
}
