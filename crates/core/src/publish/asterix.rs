//! ASTERIX category 062 (SDPS system track data, edition 1.18) records.
//!
//! Items sent, in UAP order: I062/010 data source (SAC/SIC), /015 service,
//! /070 time of track information, /105 WGS-84 position, /185 Cartesian
//! velocity (east, north), /060 Mode 3/A when known, /380 aircraft-derived
//! data (target address, and the callsign in its ID subfield), /040 track
//! number, /080 track status (MON, SRC, CNF, CST and the per-technology
//! ages bits), /290 update ages (ES and MLT, only for what was received),
//! /136 measured flight level when known, /500 estimated accuracies (APC
//! and COV as 1-sigma of the filter's own covariance, APW the same in
//! degrees). Data blocks carry several records up to a size limit; one
//! block is one datagram.

use crate::fuse::TrackReport;

/// Category byte.
pub const CAT: u8 = 62;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Source {
    pub sac: u8,
    pub sic: u8,
    pub service: u8,
}

/// ICAO 6-bit characters of a callsign, 8 characters in 6 bytes.
fn callsign6(flight: &str) -> [u8; 6] {
    let mut bits: u64 = 0;
    let chars: Vec<u8> = flight.bytes().chain(std::iter::repeat(b' ')).take(8).collect();
    for c in chars {
        let v = match c {
            b'A'..=b'Z' => c - b'A' + 1,
            b'a'..=b'z' => c - b'a' + 1,
            b'0'..=b'9' => c,
            _ => 32,
        } as u64;
        bits = (bits << 6) | (v & 0x3f);
    }
    let b = bits.to_be_bytes();
    [b[2], b[3], b[4], b[5], b[6], b[7]]
}

/// Mode 3/A code from its octal digits (the hex-digit form used internally).
fn mode3a(squawk: u16) -> u16 {
    let d = |shift: u16| (squawk >> shift) & 0x7;
    (d(12) << 9) | (d(8) << 6) | (d(4) << 3) | d(0)
}

fn wgs84(deg: f64) -> [u8; 4] {
    ((deg * (1u64 << 25) as f64 / 180.0).round() as i32).to_be_bytes()
}

fn sat_i16(v: f64) -> [u8; 2] {
    (v.round().clamp(i16::MIN as f64, i16::MAX as f64) as i16).to_be_bytes()
}

fn sat_u16(v: f64) -> [u8; 2] {
    (v.round().clamp(0.0, u16::MAX as f64) as u16).to_be_bytes()
}

fn sat_u8(v: f64) -> u8 {
    v.round().clamp(0.0, 255.0) as u8
}

/// I062/080's four octets for a track fed by ADS-B and/or MLAT, its height
/// known or not. An estimate from too few receivers for a fix (`sparse`,
/// a particle cloud or the track it started) is sent as a tentative track
/// (CNF): CAT062 has no bit for it, and a consumer should not take it for
/// a confirmed one; its kilometres of uncertainty are in I062/500.
fn track_status(adsb: bool, mlat: bool, alt_known: bool, sparse: bool) -> [u8; 4] {
    let src_alt: u8 = match (alt_known, adsb) {
        (false, _) => 0,
        (true, true) => 1,  // GNSS (ADS-B geometric or corrected baro)
        (true, false) => 7, // multilateration
    };
    let mono = (adsb != mlat) as u8;
    let o1 = (mono << 7) | (src_alt << 2) | ((sparse as u8) << 1) | 1;
    let o4 = (1 << 6) | (1 << 5) | ((!mlat as u8) << 4) | ((!adsb as u8) << 3);
    [o1, 1, 1, o4]
}

/// One CAT062 record (FSPEC and items) for a track.
pub fn record(src: Source, r: &TrackReport, ages: [Option<f64>; 2]) -> Vec<u8> {
    let e = &r.est;
    let mut items: Vec<(usize, Vec<u8>)> = Vec::with_capacity(14);
    items.push((1, vec![src.sac, src.sic]));
    items.push((3, vec![src.service]));
    let tod = (e.t.rem_euclid(86_400.0) * 128.0).round() as u32 % (86_400 * 128);
    items.push((4, tod.to_be_bytes()[1..].to_vec()));
    items.push((5, [wgs84(e.lat), wgs84(e.lon)].concat()));
    items.push((7, [sat_i16(e.vel_enu[0] * 4.0), sat_i16(e.vel_enu[1] * 4.0)].concat()));
    if let Some(sq) = r.squawk {
        items.push((9, mode3a(sq).to_be_bytes().to_vec()));
    }
    // I062/380: ADR always, ID when the callsign is known.
    let mut i380 = vec![0x80];
    i380.extend_from_slice(&r.addr.to_be_bytes()[1..]);
    if let Some(f) = r.flight.as_deref().filter(|f| !f.is_empty()) {
        i380[0] |= 0x40;
        i380.extend_from_slice(&callsign6(f));
    }
    items.push((11, i380));
    items.push((12, ((r.id & 0xffff) as u16).to_be_bytes().to_vec()));
    let (adsb_age, mlat_age) = (ages[0], ages[1]);
    items.push((
        13,
        track_status(adsb_age.is_some(), mlat_age.is_some(), e.alt_m.is_some(), r.sparse).to_vec(),
    ));
    // I062/290: ES and MLT ages (1/4 s), only what was received.
    let mut i290 = vec![0u8, 0u8];
    let mut ages_bytes = Vec::new();
    if let Some(a) = adsb_age {
        i290[0] |= 0x04;
        ages_bytes.push(sat_u8(a * 4.0));
    }
    if let Some(a) = mlat_age {
        i290[0] |= 0x01;
        i290[1] |= 0x20;
        ages_bytes.push(sat_u8(a * 4.0));
    }
    if !ages_bytes.is_empty() {
        if i290[1] == 0 {
            i290.pop();
        }
        i290.extend(ages_bytes);
        items.push((14, i290));
    }
    if let Some(ft) = r.alt_baro_ft {
        items.push((17, sat_i16(ft as f64 / 25.0).to_vec()));
    }
    // I062/500: APC (sigma x, y), COV (signed root of the xy covariance), APW.
    let c = e.cov_en();
    let (sx, sy) = (c[0][0].max(0.0).sqrt(), c[1][1].max(0.0).sqrt());
    let cxy = c[0][1].signum() * c[0][1].abs().sqrt();
    let lat_r = e.lat.to_radians();
    let (m, n) = crate::geo::radii(lat_r);
    let sigma_lat = (sy / m).to_degrees();
    let sigma_lon = (sx / (n * lat_r.cos().max(1e-6))).to_degrees();
    let deg16 = |d: f64| sat_u16(d * (1u64 << 25) as f64 / 180.0);
    let mut i500 = vec![0xe0];
    i500.extend_from_slice(&sat_u16(sx * 2.0));
    i500.extend_from_slice(&sat_u16(sy * 2.0));
    i500.extend_from_slice(&sat_i16(cxy * 2.0));
    i500.extend_from_slice(&deg16(sigma_lat));
    i500.extend_from_slice(&deg16(sigma_lon));
    items.push((27, i500));
    encode(&items)
}

/// FSPEC (with FX bits) followed by the items, given as (FRN, bytes) in FRN order.
fn encode(items: &[(usize, Vec<u8>)]) -> Vec<u8> {
    let max_frn = items.iter().map(|(f, _)| *f).max().unwrap_or(1);
    let octets = max_frn.div_ceil(7);
    let mut fspec = vec![0u8; octets];
    for (frn, _) in items {
        let bit = frn - 1;
        fspec[bit / 7] |= 0x80 >> (bit % 7);
    }
    for o in fspec.iter_mut().take(octets - 1) {
        *o |= 1;
    }
    let mut out = fspec;
    for (_, b) in items {
        out.extend_from_slice(b);
    }
    out
}

/// Packs records into data blocks (category, length, records) of at most
/// `max_bytes` each (a record larger than that gets a block of its own).
pub fn blocks(records: &[Vec<u8>], max_bytes: usize) -> Vec<Vec<u8>> {
    let mut out = Vec::new();
    let mut cur: Vec<u8> = Vec::new();
    let close = |cur: &mut Vec<u8>, out: &mut Vec<Vec<u8>>| {
        if cur.len() > 3 {
            let len = cur.len() as u16;
            cur[1..3].copy_from_slice(&len.to_be_bytes());
            out.push(std::mem::take(cur));
        }
    };
    for r in records {
        if !cur.is_empty() && cur.len() + r.len() > max_bytes {
            close(&mut cur, &mut out);
        }
        if cur.is_empty() {
            cur.extend_from_slice(&[CAT, 0, 0]);
        }
        cur.extend_from_slice(r);
    }
    close(&mut cur, &mut out);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fields_encode_as_the_standard_says() {
        // "FUSION1 ": F=6 U=21 S=19 I=9 O=15 N=14 1=49 ' '=32.
        let b = callsign6("FUSION1");
        let bits = u64::from_be_bytes([0, 0, b[0], b[1], b[2], b[3], b[4], b[5]]);
        let chars: Vec<u64> = (0..8).rev().map(|k| (bits >> (6 * k)) & 0x3f).collect();
        assert_eq!(chars, [6, 21, 19, 9, 15, 14, 49, 32]);
        assert_eq!(mode3a(0x7700), 0o7700);
        assert_eq!(mode3a(0x1234), 0o1234);
        assert_eq!(wgs84(90.0), (1i32 << 24).to_be_bytes());
        // FSPEC: FRN 1, 3 and 12 set: two octets, FX on the first.
        let e = encode(&[(1, vec![9]), (3, vec![8]), (12, vec![7])]);
        assert_eq!(e, vec![0b1010_0001, 0b0000_1000, 9, 8, 7]);
        let blocks = blocks(&[vec![1; 600], vec![2; 600], vec![3; 600]], 1400);
        assert_eq!(blocks.len(), 2);
        assert_eq!(u16::from_be_bytes([blocks[0][1], blocks[0][2]]) as usize, blocks[0].len());
        assert_eq!(blocks[0][0], 62);
        // I062/080: MON for one technology, SRC, CNF only for a sparse
        // estimate, and the per-technology "no detection" bits of octet 4.
        assert_eq!(track_status(true, true, true, false), [0b0000_0101, 1, 1, 0b0110_0000]);
        assert_eq!(track_status(false, true, true, true), [0b1001_1111, 1, 1, 0b0110_1000]);
        assert_eq!(track_status(true, false, false, false), [0b1000_0001, 1, 1, 0b0111_0000]);
    }
}
