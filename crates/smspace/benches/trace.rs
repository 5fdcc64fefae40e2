//! Benchmarks of kernel-set tracing (filled in by the foundation issue).
fn main() {}
