//! Arbitrary bytes as a `.npy` file: every reader returns an array or an error, never
//! panics, and never allocates more than the file holds.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|bytes: &[u8]| {
    let dir = tempfile::tempdir().expect("a temporary folder");
    let path = dir.path().join("input.npy");
    std::fs::write(&path, bytes).expect("the input is written");
    if let Ok(array) = smspace::io::read_f64(&path) {
        assert!(array.iter().all(|x| x.is_finite()));
    }
    let _ = smspace::io::read_i64(&path);
    let _ = smspace::io::read_matrix(&path, None, "(M, N)");
    let _ = smspace::io::read_cube(&path, "(M, P, N)");
});
