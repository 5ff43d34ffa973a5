//! The fused tracks as SBS / BaseStation text, the port-30003 convention
//! that Virtual Radar Server, PlanePlotter and many scripts read: one line
//! per message, 22 comma-separated fields, `\r\n` at the end, laid out as
//! dump1090 writes them (`tests/live_dump1090.rs` compares the two on the
//! same traffic).
//!
//! Each publication of a fused track becomes a position line (MSG,3 in the
//! air, MSG,2 on the surface) and, once the velocity is known, a velocity
//! line (MSG,4); the callsign (MSG,1) and squawk (MSG,6) are repeated when
//! they change and every [`REPEAT_S`], not at every position, as a
//! transponder repeats them; an aircraft known only by multilateration also
//! gets its replies' altitude as MSG,5. The writer remembers per aircraft
//! only whether it is on the surface and what it last said, aged out with
//! the aircraft and bounded in number.
//!
//! Fields: 1 `MSG`, 2 its type, 3-4 session and aircraft ids (`1`), 5 the
//! address (6 upper-case hex digits), 6 flight id (`1`), 7-8 date and time
//! the estimate is of, 9-10 date and time it was written (UTC,
//! `yyyy/mm/dd` and `hh:mm:ss.mmm`), 11 callsign (padded to 8), 12 altitude
//! (ft, barometric), 13 ground speed (kt), 14 track (degrees), 15-16
//! latitude and longitude (5 decimals), 17 vertical rate (ft/min), 18 squawk,
//! 19-21 alert, emergency and SPI (not kept: empty), 22 on the ground (`-1`)
//! or not (`0`), empty when not known.

use std::collections::HashMap;
use std::fmt::Write;

use crate::core::Event;
use crate::fuse::TrackReport;
use crate::fuse::TrackSource;
use crate::publish::readout::readout;

/// Callsign and squawk lines are repeated this often (s) when unchanged.
pub const REPEAT_S: f64 = 10.0;
/// An aircraft is forgotten this long (s) after its last track.
const FORGET_S: f64 = 60.0;
/// The most aircraft remembered; a new one beyond it is written without
/// memory (its callsign and squawk at every position).
pub const MAX_AIRCRAFT: usize = 100_000;

#[derive(Clone, Debug, Default)]
struct Seen {
    /// Its newest ADS-B position was a surface one.
    surface: Option<bool>,
    ident: Option<(String, f64)>,
    squawk: Option<(u16, f64)>,
    last: f64,
}

/// Writes SBS lines from the published events.
#[derive(Default)]
pub struct SbsWriter {
    aircraft: HashMap<u32, Seen>,
    next_sweep: f64,
}

impl SbsWriter {
    pub fn new() -> SbsWriter {
        SbsWriter::default()
    }

    /// Appends the lines for `events`, published at `now` (Unix s).
    pub fn write(&mut self, events: &[Event], now: f64, out: &mut String) {
        for ev in events {
            match ev {
                Event::Position(p) => {
                    if let Some(s) = self.aircraft.get_mut(&p.addr) {
                        s.surface = Some(p.surface);
                    } else if self.aircraft.len() < MAX_AIRCRAFT {
                        self.aircraft
                            .insert(p.addr, Seen { surface: Some(p.surface), last: now, ..Seen::default() });
                    }
                }
                Event::Track(r) if r.source == TrackSource::Fused => self.track(r, now, out),
                _ => {}
            }
        }
        if now >= self.next_sweep {
            self.next_sweep = now + REPEAT_S;
            self.aircraft.retain(|_, s| now - s.last <= FORGET_S);
        }
    }

    fn track(&mut self, r: &TrackReport, now: f64, out: &mut String) {
        let mut scratch = Seen::default();
        let seen = if self.aircraft.len() < MAX_AIRCRAFT || self.aircraft.contains_key(&r.addr) {
            self.aircraft.entry(r.addr).or_default()
        } else {
            &mut scratch
        };
        seen.last = now;
        let ro = readout(r);
        let est = &r.est;
        let ground = match seen.surface {
            Some(true) => "-1",
            Some(false) => "0",
            None => "",
        };
        let head = Head { addr: r.addr, t: est.t, now };
        let alt = r.alt_baro_ft.map(|a| a.to_string()).unwrap_or_default();
        let (lat, lon) = (format!("{:.5}", est.lat), format!("{:.5}", est.lon));
        let gs = ro.gs_kt().map(|v| format!("{v:.0}")).unwrap_or_default();
        let track = ro.track_deg.map(|v| format!("{:.0}", v.round() % 360.0)).unwrap_or_default();
        let rate = ro.geom_rate_fpm.map(|v| v.to_string()).unwrap_or_default();
        if seen.surface == Some(true) {
            head.line(out, 2, ["", "", &gs, &track, &lat, &lon, "", "", "", "", "", ground]);
        } else {
            head.line(out, 3, ["", &alt, "", "", &lat, &lon, "", "", "", "", "", ground]);
            if ro.gs_kt().is_some() {
                head.line(out, 4, ["", "", &gs, &track, "", "", &rate, "", "", "", "", ground]);
            }
        }
        let flight = r.flight.as_deref().filter(|f| !f.is_empty()).map(|f| format!("{f:<8}"));
        if let Some(f) = &flight {
            if due(&seen.ident, f, now) {
                head.line(out, 1, [f, "", "", "", "", "", "", "", "", "", "", ground]);
                seen.ident = Some((f.clone(), now));
            }
        }
        if let Some(sq) = r.squawk {
            if due(&seen.squawk, &sq, now) {
                let code = format!("{sq:04x}");
                head.line(out, 6, ["", "", "", "", "", "", "", &code, "", "", "", ground]);
                seen.squawk = Some((sq, now));
            }
        }
        // Multilateration gives no altitude of its own: the replies' is the
        // surveillance altitude, which is what MSG,5 carries.
        if !ro.adsb && !alt.is_empty() {
            let f = flight.as_deref().unwrap_or("");
            head.line(out, 5, [f, &alt, "", "", "", "", "", "", "", "", "", ground]);
        }
    }
}

/// Whether a value is to be said again: new, changed, or last said
/// [`REPEAT_S`] ago.
fn due<T: PartialEq>(last: &Option<(T, f64)>, value: &T, now: f64) -> bool {
    !matches!(last, Some((v, at)) if v == value && now - at < REPEAT_S)
}

/// The first ten fields of every line of one aircraft at one time.
struct Head {
    addr: u32,
    t: f64,
    now: f64,
}

impl Head {
    fn line(&self, out: &mut String, kind: u8, fields: [&str; 12]) {
        let _ = write!(out, "MSG,{kind},1,1,{:06X},1,", self.addr);
        push_time(out, self.t);
        out.push(',');
        push_time(out, self.now);
        for f in fields {
            out.push(',');
            out.push_str(f);
        }
        out.push_str("\r\n");
    }
}

/// `yyyy/mm/dd,hh:mm:ss.mmm` (UTC) of a Unix time.
fn push_time(out: &mut String, unix_s: f64) {
    let ms = (unix_s * 1000.0).round().max(0.0) as i64;
    let (days, ms_of_day) = (ms.div_euclid(86_400_000), ms.rem_euclid(86_400_000));
    let (y, m, d) = civil_from_days(days);
    let s = ms_of_day / 1000;
    let _ = write!(
        out,
        "{y:04}/{m:02}/{d:02},{:02}:{:02}:{:02}.{:03}",
        s / 3600,
        s / 60 % 60,
        s % 60,
        ms_of_day % 1000
    );
}

/// The proleptic Gregorian date of a day count since 1970-01-01 (Howard
/// Hinnant's algorithm: eras of 400 years, years starting in March).
fn civil_from_days(z: i64) -> (i64, u32, u32) {
    let z = z + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let m = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    (yoe + era * 400 + i64::from(m <= 2), m, d)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::publish::test_report::{position, report, Source};

    #[test]
    fn times_are_utc_dates_and_milliseconds() {
        let mut s = String::new();
        push_time(&mut s, 0.0);
        assert_eq!(s, "1970/01/01,00:00:00.000");
        s.clear();
        // 2024-02-29 23:59:59.999 UTC, a leap day.
        push_time(&mut s, 1_709_251_199.999);
        assert_eq!(s, "2024/02/29,23:59:59.999");
        s.clear();
        push_time(&mut s, 1_795_661_480.8);
        assert_eq!(s, "2026/11/26,02:51:20.800");
    }

    #[test]
    fn callsigns_are_repeated_when_changed_or_due() {
        let at = |v: &str, t| Some((v.to_string(), t));
        assert!(due(&None, &"A".to_string(), 0.0));
        assert!(!due(&at("A", 0.0), &"A".to_string(), REPEAT_S - 0.1));
        assert!(due(&at("A", 0.0), &"A".to_string(), REPEAT_S));
        assert!(due(&at("A", 0.0), &"B".to_string(), 1.0));
    }

    fn lines(w: &mut SbsWriter, events: &[Event], now: f64) -> Vec<Vec<String>> {
        let mut text = String::new();
        w.write(events, now, &mut text);
        assert!(text.ends_with("\r\n"));
        text.split("\r\n")
            .filter(|l| !l.is_empty())
            .map(|l| l.split(',').map(String::from).collect())
            .collect()
    }

    #[test]
    fn an_airborne_track_is_position_velocity_callsign_and_squawk() {
        let mut w = SbsWriter::new();
        let r = report(0x3C6DD4, 1_700_000_000.0, &[Source::Adsb]);
        let got = lines(&mut w, &[Event::Track(Box::new(r.clone()))], 1_700_000_000.25);
        let kinds: Vec<&str> = got.iter().map(|f| f[1].as_str()).collect();
        assert_eq!(kinds, ["3", "4", "1", "6"]);
        assert!(got.iter().all(|f| f.len() == 22 && f[0] == "MSG" && f[4] == "3C6DD4"));
        assert_eq!(got[0][6..10], ["2023/11/14", "22:13:20.000", "2023/11/14", "22:13:20.250"]);
        // Altitude, latitude, longitude; airborne not known from a position.
        assert_eq!(
            (got[0][11].as_str(), got[0][14].as_str(), got[0][15].as_str()),
            ("3200", "43.50000", "1.25000")
        );
        // 194 kt towards 45 degrees, climbing 984 ft/min.
        assert_eq!((got[1][12].as_str(), got[1][13].as_str(), got[1][16].as_str()), ("194", "45", "984"));
        assert_eq!(got[2][10], "AFR12   ");
        assert_eq!(got[3][17], "7001");
        // Within REPEAT_S, the callsign and squawk are not said again.
        let again = lines(&mut w, &[Event::Track(Box::new(r))], 1_700_000_001.0);
        assert_eq!(again.iter().map(|f| f[1].as_str()).collect::<Vec<_>>(), ["3", "4"]);
    }

    #[test]
    fn a_surface_aircraft_gets_msg2_and_an_mlat_one_its_replies_altitude() {
        let mut w = SbsWriter::new();
        let position = position(1, 10.0, true);
        let events = [Event::Position(position), Event::Track(Box::new(report(1, 10.0, &[Source::Adsb])))];
        let got = lines(&mut w, &events, 10.0);
        assert_eq!(got[0][1], "2");
        assert_eq!((got[0][11].as_str(), got[0][12].as_str(), got[0][21].as_str()), ("", "194", "-1"));
        let got = lines(&mut w, &[Event::Track(Box::new(report(2, 10.0, &[Source::Mlat])))], 10.0);
        let msg5 = got.iter().find(|f| f[1] == "5").expect("MSG,5");
        assert_eq!((msg5[10].as_str(), msg5[11].as_str()), ("AFR12   ", "3200"));
    }
}
