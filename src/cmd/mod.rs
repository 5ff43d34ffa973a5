//! Subcommands of the `fuse1090` binary. Each drives the library; none holds
//! processing logic of its own.

pub mod decode;
