//! CRC-24 parity of Mode S (generator 0xFFF409) and the single-bit error table.
//!
//! The *syndrome* is the CRC of the data bits XOR the transmitted parity: zero
//! for a clean DF11/17/18, the interrogator code for DF11, the aircraft address
//! for address/parity replies (DF0/4/5/16/20/21). CRC is linear, so a single
//! flipped bit `k` always yields the same syndrome; precomputing those lets us
//! correct one bit with a lookup.

use crc::{Algorithm, Crc, Table};

const MODE_S: Algorithm<u32> = Algorithm {
    width: 24,
    poly: 0xFF_F409,
    init: 0,
    refin: false,
    refout: false,
    xorout: 0,
    check: 0x05_4268,
    residue: 0,
};

// Slice-by-16 tables: the frames are short, so table width buys more than size costs.
static CRC24: Crc<u32, Table<16>> = Crc::<u32, Table<16>>::new(&MODE_S);

/// Syndrome of a 7- or 14-byte frame (0 for other lengths).
#[inline]
pub fn syndrome(frame: &[u8]) -> u32 {
    let n = frame.len();
    if n < 4 {
        return 0;
    }
    let parity = ((frame[n - 3] as u32) << 16) | ((frame[n - 2] as u32) << 8) | frame[n - 1] as u32;
    CRC24.checksum(&frame[..n - 3]) ^ parity
}

/// Syndromes of every single-bit error in a 112-bit frame, excluding the
/// five DF bits: correcting those would turn one kind of message into another.
pub struct SingleBitTable {
    // (syndrome, bit index from the MSB of byte 0), sorted by syndrome.
    entries: Vec<(u32, u8)>,
}

impl Default for SingleBitTable {
    fn default() -> Self {
        Self::new()
    }
}

impl SingleBitTable {
    pub fn new() -> Self {
        let mut entries = Vec::with_capacity(107);
        for bit in 5..112u8 {
            let mut f = [0u8; 14];
            f[(bit / 8) as usize] = 0x80 >> (bit % 8);
            entries.push((syndrome(&f), bit));
        }
        entries.sort_unstable();
        SingleBitTable { entries }
    }

    /// The bit whose flip explains `syn`, if one does.
    pub fn lookup(&self, syn: u32) -> Option<u8> {
        self.entries.binary_search_by_key(&syn, |e| e.0).ok().map(|i| self.entries[i].1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bytes(hex: &str) -> Vec<u8> {
        (0..hex.len()).step_by(2).map(|i| u8::from_str_radix(&hex[i..i + 2], 16).unwrap()).collect()
    }

    #[test]
    fn clean_extended_squitter_has_zero_syndrome() {
        assert_eq!(syndrome(&bytes("8D406B902015A678D4D220AA4BDA")), 0);
        assert_eq!(CRC24.checksum(b"123456789"), MODE_S.check);
    }

    #[test]
    fn address_parity_recovers_address() {
        // DF20 and DF21 from pyModeS' sample data, whose ICAO column we must reproduce.
        assert_eq!(syndrome(&bytes("A00015B7C26E1370AA00005DD34A")), 0x4D010D);
        assert_eq!(syndrome(&bytes("A8000D9FA55A032DBFFC000D8123")), 0x406674);
    }

    #[test]
    fn every_single_bit_error_is_found() {
        let table = SingleBitTable::new();
        let good = bytes("8D406B902015A678D4D220AA4BDA");
        for bit in 5..112 {
            let mut bad = good.clone();
            bad[bit / 8] ^= 0x80 >> (bit % 8);
            assert_eq!(table.lookup(syndrome(&bad)), Some(bit as u8));
        }
        let mut two = good.clone();
        two[6] ^= 0x11;
        assert_eq!(table.lookup(syndrome(&two)), None);
    }
}
