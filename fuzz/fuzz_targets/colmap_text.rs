//! Fuzz target: the COLMAP text parsers (first byte selects cameras/images/points3D.txt).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    bbsplat::scene::fuzz::colmap_text(data);
});
