//! Fuzz target: the PLY point-cloud reader.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    bbsplat::scene::fuzz::ply(data);
});
