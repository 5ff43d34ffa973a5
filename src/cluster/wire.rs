//! What travels between a cluster's roles, as bytes: batches of frames
//! (by hand: the hot path, 18 bytes of header per frame and no allocation
//! per frame), and the sync and checkpoint records (postcard: rare, and
//! serde keeps them in step with their types).
//!
//! Sans-IO: no NATS here, so every decoder is tested against hostile bytes.

use serde::{Deserialize, Serialize};

use crate::feed::capture::CaptureFrame;
use crate::feed::RawFrame;
use crate::mlat::shared::SyncNote;
use crate::modes::crc::syndrome;

/// A frame batch's first bytes: "F1", then the format version.
const MAGIC: [u8; 3] = *b"F1\x01";
/// Per frame: receiver (u16), arrival (f64), timestamp (48 bits), signal, length.
const FRAME_HEAD: usize = 2 + 8 + 6 + 1 + 1;

/// Why a message could not be read.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum WireError {
    BadMagic,
    Truncated,
    BadLength(u8),
    Postcard(String),
}

impl std::fmt::Display for WireError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            WireError::BadMagic => write!(f, "not a fuse1090 frame batch (magic)"),
            WireError::Truncated => write!(f, "frame batch truncated"),
            WireError::BadLength(n) => write!(f, "frame of {n} bytes (2, 7 or 14 expected)"),
            WireError::Postcard(e) => write!(f, "{e}"),
        }
    }
}

impl std::error::Error for WireError {}

/// The aircraft address a frame is about, as every receiver's copy of it
/// gives it: in clear for DF11/17/18, the parity's syndrome for
/// address/parity replies. `None` for Mode A/C (no address).
pub fn frame_address(frame: &RawFrame) -> Option<u32> {
    let b = frame.bytes();
    if b.len() < 7 {
        return None;
    }
    let clear = || (b[1] as u32) << 16 | (b[2] as u32) << 8 | b[3] as u32;
    match b[0] >> 3 {
        11 | 17 | 18 => Some(clear()),
        _ => Some(syndrome(b)),
    }
}

/// The partition (of `n`) an address belongs to: a multiplicative hash, so
/// that addresses allocated in blocks (one country's) spread evenly.
pub fn partition_of(addr: u32, n: u32) -> u32 {
    (((addr.wrapping_mul(0x9E37_79B1) >> 8) as u64 * n as u64) >> 24) as u32
}

/// Appends frames to a batch.
pub struct BatchWriter {
    pub bytes: Vec<u8>,
    pub frames: usize,
}

impl Default for BatchWriter {
    fn default() -> Self {
        BatchWriter { bytes: MAGIC.to_vec(), frames: 0 }
    }
}

impl BatchWriter {
    pub fn push(&mut self, f: &CaptureFrame) {
        let b = &mut self.bytes;
        b.extend_from_slice(&(f.rx as u16).to_le_bytes());
        b.extend_from_slice(&f.arrival.to_le_bytes());
        b.extend_from_slice(&f.frame.timestamp.to_le_bytes()[..6]);
        b.push(f.frame.signal);
        let data = f.frame.bytes();
        b.push(data.len() as u8);
        b.extend_from_slice(data);
        self.frames += 1;
    }

    /// The batch so far, and an empty one in its place.
    pub fn take(&mut self) -> Vec<u8> {
        self.frames = 0;
        std::mem::replace(&mut self.bytes, MAGIC.to_vec())
    }
}

/// Reads a batch's frames in order; a malformed batch is an error (the
/// frames before it were read).
pub fn read_batch(bytes: &[u8], mut each: impl FnMut(CaptureFrame)) -> Result<usize, WireError> {
    let mut rest = bytes.strip_prefix(&MAGIC[..]).ok_or(WireError::BadMagic)?;
    let mut n = 0;
    while !rest.is_empty() {
        if rest.len() < FRAME_HEAD {
            return Err(WireError::Truncated);
        }
        let rx = u16::from_le_bytes([rest[0], rest[1]]) as usize;
        let arrival = f64::from_le_bytes(rest[2..10].try_into().expect("8 bytes"));
        let mut ts = [0u8; 8];
        ts[..6].copy_from_slice(&rest[10..16]);
        let (signal, len) = (rest[16], rest[17]);
        if !matches!(len, 2 | 7 | 14) {
            return Err(WireError::BadLength(len));
        }
        let end = FRAME_HEAD + len as usize;
        if rest.len() < end {
            return Err(WireError::Truncated);
        }
        let frame = RawFrame::new(&rest[FRAME_HEAD..end], u64::from_le_bytes(ts), signal)
            .ok_or(WireError::BadLength(len))?;
        each(CaptureFrame { arrival, rx, frame });
        n += 1;
        rest = &rest[end..];
    }
    Ok(n)
}

/// A worker's notes on the clocks for one batch of one partition, with the
/// data time the partition has been processed to.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SyncBatch {
    pub partition: u32,
    pub watermark: f64,
    pub notes: Vec<SyncNote>,
}

/// A partition's checkpoint: its aircraft's track numbers and the next
/// number, so that a worker taking it over keeps them.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Checkpoint {
    pub ids: Vec<(u32, u64)>,
    pub next_id: u64,
}

pub fn encode<T: Serialize>(v: &T) -> Vec<u8> {
    postcard::to_stdvec(v).expect("plain data serialises")
}

pub fn decode<'a, T: Deserialize<'a>>(b: &'a [u8]) -> Result<T, WireError> {
    postcard::from_bytes(b).map_err(|e| WireError::Postcard(e.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(hex: &str, ts: u64) -> RawFrame {
        let b: Vec<u8> =
            (0..hex.len()).step_by(2).map(|i| u8::from_str_radix(&hex[i..i + 2], 16).unwrap()).collect();
        RawFrame::new(&b, ts, 77).unwrap()
    }

    #[test]
    fn a_batch_reads_back_the_frames_written() {
        let frames = [
            CaptureFrame {
                arrival: 1.7e9 + 0.123456789,
                rx: 3,
                frame: frame("8D4840D6202CC371C32CE0576098", 0xFFFF_FFFF_FFFF),
            },
            CaptureFrame { arrival: 1.7e9 + 0.2, rx: 65535, frame: frame("5D4840D6202CC3", 12) },
            CaptureFrame { arrival: 1.7e9 + 0.3, rx: 0, frame: frame("2000", 0) },
        ];
        let mut w = BatchWriter::default();
        frames.iter().for_each(|f| w.push(f));
        let bytes = w.take();
        let mut back = Vec::new();
        assert_eq!(read_batch(&bytes, |f| back.push(f)), Ok(3));
        assert_eq!(back, frames);
        assert_eq!(w.frames, 0);
    }

    #[test]
    fn hostile_batches_are_errors_not_panics() {
        let mut w = BatchWriter::default();
        w.push(&CaptureFrame { arrival: 1.0, rx: 1, frame: frame("8D4840D6202CC371C32CE0576098", 5) });
        let good = w.take();
        assert_eq!(read_batch(b"XX\x01", |_| {}), Err(WireError::BadMagic));
        assert_eq!(read_batch(&good[..good.len() - 1], |_| {}), Err(WireError::Truncated));
        let mut bad = good.clone();
        bad[3 + 17] = 9;
        assert_eq!(read_batch(&bad, |_| {}), Err(WireError::BadLength(9)));
        // Every truncation and every single byte changed: an answer, never a panic.
        for cut in 0..good.len() {
            let _ = read_batch(&good[..cut], |_| {});
        }
        for k in 0..good.len() {
            let mut b = good.clone();
            b[k] ^= 0xFF;
            let _ = read_batch(&b, |_| {});
        }
        assert!(decode::<SyncBatch>(&[0xFF; 5]).is_err());
    }

    #[test]
    fn every_copy_of_a_transmission_lands_in_one_partition() {
        // DF17 in clear; a DF4 reply whose parity carries the same address.
        let adsb = frame("8D4840D6202CC371C32CE0576098", 0);
        assert_eq!(frame_address(&adsb), Some(0x4840D6));
        let mut df4 = [0x20u8, 0x00, 0x05, 0x18, 0, 0, 0];
        let crc = syndrome(&df4);
        let ap = crc ^ 0x4840D6;
        df4[4..7].copy_from_slice(&ap.to_be_bytes()[1..]);
        assert_eq!(frame_address(&RawFrame::new(&df4, 0, 0).unwrap()), Some(0x4840D6));
        assert_eq!(frame_address(&frame("2000", 0)), None);
        // Partitions spread a block of addresses evenly.
        let mut counts = [0u32; 7];
        for addr in 0x400000..0x400000 + 7000 {
            counts[partition_of(addr, 7) as usize] += 1;
        }
        assert!(counts.iter().all(|&c| (800..1200).contains(&c)), "{counts:?}");
    }
}
