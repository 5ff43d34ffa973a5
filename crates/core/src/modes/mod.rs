//! Mode S stage: frames in, decoded messages out.
//!
//! Laid out like rs1090: bit-level field codings ([`fields`], [`crc`],
//! [`cpr`], [`nic`]), one module per message family ([`velocity`],
//! [`status`]), the stateless frame decoder ([`message`]) and, on top, the
//! stateful [`Decoder`] that owns policy (error correction, aircraft table,
//! CPR pairing and plausibility). [`json`] renders the `decode` output.

pub mod commb;
pub mod cpr;
pub mod crc;
pub mod decoder;
pub mod encode;
pub mod fields;
pub mod json;
pub mod message;
pub mod nic;
pub mod status;
pub mod velocity;

pub use decoder::{CprMethod, DecodeStats, Decoded, Decoder, DecoderConfig, PositionFix};
pub use message::{decode, Body, Es, Extended, FrameError, Message, Parity};
