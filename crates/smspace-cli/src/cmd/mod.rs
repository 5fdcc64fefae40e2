//! One module per subcommand: each has an `Args` struct (clap) and a `run` function.

pub mod analyze;
pub mod common;
pub mod compare;
pub mod distances;
pub mod embed;
pub mod env;
pub mod explore;
pub mod invariance;
pub mod learn;
pub mod run;
pub mod sense;
pub mod simulate;
pub mod trace;
