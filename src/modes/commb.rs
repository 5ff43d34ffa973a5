//! Comm-B (DF20/21 MB field): only the register whose content identifies
//! itself. BDS 2,0 (aircraft identification) starts with 0x20 and carries a
//! callsign in the ES alphabet; any other register needs inference from
//! content and is left to later work.

use super::fields::decode_callsign;

/// The callsign of a BDS 2,0 reply, if `mb` is one.
pub fn bds20_callsign(mb: u64) -> Option<[u8; 8]> {
    if mb >> 48 != 0x20 {
        return None;
    }
    let cs = decode_callsign(mb);
    // Codes outside the alphabet, or a blank callsign, mean this is not BDS 2,0.
    (!cs.contains(&b'#') && cs != [b' '; 8]).then_some(cs)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::modes::fields::callsign_str;

    #[test]
    fn identification_register() {
        // DF20 from the beastblackbox capture; pyModeS reads AAR542.
        let mb = u64::from_str_radix("200414B5D32820", 16).unwrap();
        assert_eq!(callsign_str(&bds20_callsign(mb).unwrap()), "AAR542");
        assert_eq!(bds20_callsign(u64::from_str_radix("10000000000000", 16).unwrap()), None);
        assert_eq!(bds20_callsign(0x20 << 48), None);
    }
}
