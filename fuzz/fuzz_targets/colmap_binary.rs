//! Fuzz target: the COLMAP binary parsers (first byte selects cameras/images/points3D.bin).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    bbsplat::scene::fuzz::colmap_binary(data);
});
