//! Fuzz target: the `.npz` reader and the NeuS/IDR camera decomposition.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    bbsplat::scene::fuzz::npz(data);
});
