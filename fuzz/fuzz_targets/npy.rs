//! Fuzz target: the `.npy` reader and the LLFF pose parser.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    bbsplat::scene::fuzz::npy(data);
});
