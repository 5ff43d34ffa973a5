//! Input format detection from the first bytes of a stream or file.
//!
//! Beast is recognised by a frame marker followed by a frame type; AVR by its
//! start characters; hex lines by a line holding a frame-length hex token. A
//! prefix matching none of them is not Mode S data, and callers say so.

use super::hexlines::parse_hex_line;

#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum InputFormat {
    Beast,
    Avr,
    Hex,
}

impl std::str::FromStr for InputFormat {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "beast" => Ok(Self::Beast),
            "avr" => Ok(Self::Avr),
            "hex" => Ok(Self::Hex),
            _ => Err(format!("unknown format {s:?} (expected beast, avr or hex)")),
        }
    }
}

/// Guesses the format from a prefix of the input (a few KiB is plenty).
pub fn detect_format(prefix: &[u8]) -> Option<InputFormat> {
    // Beast: at least two frame starts with a known type among the first bytes.
    let beast_starts = prefix
        .windows(2)
        .filter(|w| w[0] == 0x1a && matches!(w[1], b'1' | b'2' | b'3' | 0xe3 | 0xe4))
        .count();
    if beast_starts >= 2 || (beast_starts == 1 && prefix.len() < 64) {
        return Some(InputFormat::Beast);
    }
    let text = std::str::from_utf8(prefix).ok().or_else(|| {
        // A prefix may end inside a multi-byte character; trim and retry.
        std::str::from_utf8(&prefix[..prefix.len().saturating_sub(3)]).ok()
    })?;
    // The first meaningful line decides.
    let line = text.lines().map(str::trim).find(|l| !l.is_empty() && !l.starts_with('#'))?;
    if matches!(line.as_bytes()[0], b'*' | b'@' | b'%' | b'<')
        && super::avr::parse_avr_token(line.trim_end_matches(';').as_bytes()).is_some()
    {
        return Some(InputFormat::Avr);
    }
    parse_hex_line(line).map(|_| InputFormat::Hex)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn detects_each_format_and_rejects_other_data() {
        let mut beast = Vec::new();
        let f = crate::feed::frame_from_hex("5D4840D61F3A2B", 5, 9).unwrap();
        crate::feed::beast::encode(&f, &mut beast);
        crate::feed::beast::encode(&f, &mut beast);
        assert_eq!(detect_format(&beast), Some(InputFormat::Beast));
        assert_eq!(detect_format(b"*8D4840D6202CC371C32CE0576098;\n"), Some(InputFormat::Avr));
        assert_eq!(detect_format(b"1.0,8D4840D6202CC371C32CE0576098\n"), Some(InputFormat::Hex));
        assert_eq!(detect_format(b"[package]\nname = \"x\"\n"), None);
        assert_eq!(detect_format(&[0u8, 1, 2, 3, 255, 254]), None);
    }
}
