//! Field codings shared by several downlink formats: the 13-bit altitude code
//! (AC13, with its 25 ft Q-bit form and the Gillham 100 ft form), the 12-bit
//! airborne-position altitude (AC12), the 13-bit identity code (squawk) and the
//! 6-bit callsign alphabet.

/// AC13 (DF0/4/16/20) to feet; `None` when absent or invalid.
pub fn decode_ac13(ac13: u16) -> Option<i32> {
    let ac13 = ac13 & 0x1FFF;
    if ac13 == 0 {
        return None;
    }
    let m_bit = ac13 & 0x0040 != 0;
    if m_bit {
        // Metric altitude: 12 bits of metres once M is removed.
        let n = ((ac13 & 0x1F80) >> 1) | (ac13 & 0x003F);
        return Some((n as f64 * 3.28084).round() as i32);
    }
    if ac13 & 0x0010 != 0 {
        // Q=1: 25 ft steps, 11 bits once M and Q are removed.
        let n = ((ac13 & 0x1F80) >> 2) | ((ac13 & 0x0020) >> 1) | (ac13 & 0x000F);
        return Some(n as i32 * 25 - 1000);
    }
    gillham(ac13)
}

/// AC12 (airborne position) to feet: AC13 with the M bit left out.
pub fn decode_ac12(ac12: u16) -> Option<i32> {
    let ac12 = ac12 & 0x0FFF;
    decode_ac13(((ac12 & 0x0FC0) << 1) | (ac12 & 0x003F))
}

#[inline]
fn bit(v: u16, n: u32) -> u16 {
    (v >> n) & 1
}

/// Gillham (Mode C) altitude in AC13 bit order:
/// C1 A1 C2 A2 C4 A4 M B1 Q B2 D2 B4 D4 (bit 12 down to bit 0).
fn gillham(ac13: u16) -> Option<i32> {
    let (c1, a1, c2, a2, c4, a4) =
        (bit(ac13, 12), bit(ac13, 11), bit(ac13, 10), bit(ac13, 9), bit(ac13, 8), bit(ac13, 7));
    let (b1, b2, d2, b4, d4) = (bit(ac13, 5), bit(ac13, 3), bit(ac13, 2), bit(ac13, 1), bit(ac13, 0));
    // 500 ft steps: reflected Gray code D2 D4 A1 A2 A4 B1 B2 B4.
    let gray500 = (d2 << 7) | (d4 << 6) | (a1 << 5) | (a2 << 4) | (a4 << 3) | (b1 << 2) | (b2 << 1) | b4;
    let n500 = gray_to_binary(gray500) as i32;
    // 100 ft steps: C1 C2 C4 = 001 011 010 110 100 for 1..=5, a Gray code in
    // which the fifth step (100) reads as 7; 000, 101 and 111 are not used.
    let mut n100 = match gray_to_binary((c1 << 2) | (c2 << 1) | c4) {
        n @ 1..=4 => n as i32,
        7 => 5,
        _ => return None,
    };
    if n500 % 2 == 1 {
        n100 = 6 - n100;
    }
    Some(n500 * 500 + n100 * 100 - 1300)
}

fn gray_to_binary(mut g: u16) -> u16 {
    let mut b = 0;
    while g != 0 {
        b ^= g;
        g >>= 1;
    }
    b
}

/// ID13 (DF5/21, TC28) to the four octal squawk digits packed as 0xABCD
/// nibbles, i.e. 7700 is 0x7700.
pub fn decode_id13(id13: u16) -> u16 {
    let (c1, a1, c2, a2, c4, a4) =
        (bit(id13, 12), bit(id13, 11), bit(id13, 10), bit(id13, 9), bit(id13, 8), bit(id13, 7));
    let (b1, d1, b2, d2, b4, d4) =
        (bit(id13, 5), bit(id13, 4), bit(id13, 3), bit(id13, 2), bit(id13, 1), bit(id13, 0));
    let a = (a4 << 2) | (a2 << 1) | a1;
    let b = (b4 << 2) | (b2 << 1) | b1;
    let c = (c4 << 2) | (c2 << 1) | c1;
    let d = (d4 << 2) | (d2 << 1) | d1;
    (a << 12) | (b << 8) | (c << 4) | d
}

/// The squawk as its four digits.
pub fn squawk_string(squawk: u16) -> String {
    format!("{squawk:04X}")
}

const CALLSIGN_CHARS: &[u8; 64] = b"#ABCDEFGHIJKLMNOPQRSTUVWXYZ##### ###############0123456789######";

/// Eight 6-bit characters from the low 48 bits of `bits`; `#` marks codes
/// that are not part of the alphabet.
pub fn decode_callsign(bits: u64) -> [u8; 8] {
    let mut out = [b' '; 8];
    for (i, c) in out.iter_mut().enumerate() {
        let code = (bits >> (42 - 6 * i)) & 0x3F;
        *c = CALLSIGN_CHARS[code as usize];
    }
    out
}

/// The callsign with trailing spaces removed, as published.
pub fn callsign_str(cs: &[u8; 8]) -> &str {
    std::str::from_utf8(cs).unwrap_or("").trim_end()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn q_bit_altitude() {
        // 0xC38 with Q=1 -> 38000 ft (ICAO Annex 10 example as used by most decoders).
        assert_eq!(decode_ac12(0xC38), Some(38000));
        assert_eq!(decode_ac13(0), None);
    }

    #[test]
    fn gillham_altitudes_cover_the_code() {
        // Every Gillham code that decodes must land on a 100 ft step and each
        // 100 ft step from -1200 ft up to 126700 ft must have exactly one code.
        let mut seen = std::collections::HashMap::new();
        for code in 0u16..0x2000 {
            if code & 0x0050 != 0 || code == 0 {
                continue; // M or Q set: not Gillham
            }
            if let Some(ft) = gillham(code) {
                assert_eq!(ft.rem_euclid(100), 0);
                *seen.entry(ft).or_insert(0) += 1;
            }
        }
        assert_eq!(seen.get(&-1200), Some(&1));
        for ft in (-1200..=126_700).step_by(100) {
            assert_eq!(seen.get(&ft), Some(&1), "{ft} ft");
        }
    }

    #[test]
    fn gillham_known_values() {
        // C4 alone (bit 8) is the lowest code, -1200 ft; C1 alone (bit 12) is
        // the fifth 100 ft step of the same 500 ft band.
        assert_eq!(gillham(0x0100), Some(-1200));
        assert_eq!(gillham(0x1000), Some(-800));
        // C2 (bit 10) with B4 (bit 1): odd 500 ft band 1, so the 100 ft count
        // runs backwards: 3 -> 3, i.e. -500 ft.
        assert_eq!(gillham(0x0402), Some(-500));
    }

    #[test]
    fn squawks() {
        // 7700: A=7 (a4 a2 a1 set), B=7, C=0, D=0.
        let id = (1 << 11) | (1 << 9) | (1 << 7) | (1 << 5) | (1 << 3) | (1 << 1);
        assert_eq!(squawk_string(decode_id13(id)), "7700");
        assert_eq!(squawk_string(decode_id13(1 << 4)), "0001");
    }

    #[test]
    fn callsign() {
        // "KLM1023 " from the ME of 8D4840D6202CC371C32CE0576098.
        let me: u64 = 0x202CC371C32CE0;
        assert_eq!(callsign_str(&decode_callsign(me & 0xFFFF_FFFF_FFFF)), "KLM1023");
    }
}
