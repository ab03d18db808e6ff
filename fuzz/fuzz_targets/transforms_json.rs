//! Fuzz target: the NeRF-synthetic / instant-ngp transforms.json parser.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    bbsplat::scene::fuzz::transforms(data);
});
