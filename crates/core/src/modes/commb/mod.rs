//! Comm-B (the 56-bit MB field of DF20/21 replies): which register a reply
//! carries, and its fields.
//!
//! A reply does not say which register it holds: the interrogation that
//! asked for it did, and a receiver hears only the answer. BDS 1,0, 2,0 and
//! 3,0 name themselves in their first byte; every other register must be
//! recognised from its content. So inference runs in two steps, kept apart:
//! [`registers`] says which registers' layouts the MB fits (status bits,
//! reserved bits, ranges), and [`evidence`] weighs each fitting register by
//! how its fields agree with each other and with what is known of the
//! aircraft ([`Known`]). A register is named only when the evidence for it
//! clearly outweighs every other's; otherwise the reply is reported as
//! ambiguous with its candidates, never guessed.

pub mod air;
pub mod encode;
mod evidence;
mod json;
mod memory;
pub mod registers;

use smallvec::SmallVec;

pub use json::CommbFields;
pub use memory::{CommbStats, Memory, ReplyContext};
pub use registers::{Bds40, Bds44, Bds45, Bds50, Bds60, GICB_REGISTERS};

/// The longest a transponder's register waits for the avionics to refresh
/// it (s, ICAO Doc 9871, for the registers read for surveillance): a reply's
/// values are up to that old.
pub const REFRESH_S: f64 = 1.3;

/// A Comm-B register, by its BDS code.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Bds {
    B10,
    B17,
    B20,
    B30,
    B40,
    B44,
    B45,
    B50,
    B60,
}

impl Bds {
    /// As written in the `decode` output: "5,0".
    pub fn as_str(self) -> &'static str {
        match self {
            Bds::B10 => "1,0",
            Bds::B17 => "1,7",
            Bds::B20 => "2,0",
            Bds::B30 => "3,0",
            Bds::B40 => "4,0",
            Bds::B44 => "4,4",
            Bds::B45 => "4,5",
            Bds::B50 => "5,0",
            Bds::B60 => "6,0",
        }
    }
}

impl std::str::FromStr for Bds {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        Candidates::ALL
            .into_iter()
            .find(|b| b.as_str() == s)
            .ok_or_else(|| format!("{s:?} is not a Comm-B register"))
    }
}

/// One register's content.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Register {
    /// BDS 1,0, data link capability.
    DataLink,
    /// BDS 1,7, the GICB capability map (bits 1-24, [`GICB_REGISTERS`]).
    Capability(u32),
    /// BDS 2,0, the callsign.
    Identification([u8; 8]),
    /// BDS 3,0, an ACAS resolution advisory.
    AcasRa,
    SelectedVertical(Bds40),
    MeteoRoutine(Bds44),
    MeteoHazard(Bds45),
    TrackTurn(Bds50),
    HeadingSpeed(Bds60),
}

impl Register {
    pub fn bds(&self) -> Bds {
        match self {
            Register::DataLink => Bds::B10,
            Register::Capability(_) => Bds::B17,
            Register::Identification(_) => Bds::B20,
            Register::AcasRa => Bds::B30,
            Register::SelectedVertical(_) => Bds::B40,
            Register::MeteoRoutine(_) => Bds::B44,
            Register::MeteoHazard(_) => Bds::B45,
            Register::TrackTurn(_) => Bds::B50,
            Register::HeadingSpeed(_) => Bds::B60,
        }
    }
}

/// A velocity known of the aircraft from elsewhere (ADS-B, or an earlier
/// track and turn report), `age_s` before this reply.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct KnownVelocity {
    pub track_deg: f64,
    pub gs_kt: f64,
    pub age_s: f64,
}

/// What is known of the aircraft apart from the MB.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Known {
    /// Barometric altitude (ft) and its age (s): the DF20 reply's own, or a recent one.
    pub alt_ft: Option<(i32, f64)>,
    pub velocity: Option<KnownVelocity>,
}

/// A set of registers (the candidates of an ambiguous reply).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Candidates(u16);

impl Candidates {
    const ALL: [Bds; 9] =
        [Bds::B10, Bds::B17, Bds::B20, Bds::B30, Bds::B40, Bds::B44, Bds::B45, Bds::B50, Bds::B60];

    pub fn contains(self, b: Bds) -> bool {
        self.0 & (1 << b as u16) != 0
    }

    /// In BDS order.
    pub fn iter(self) -> impl Iterator<Item = Bds> {
        Self::ALL.into_iter().filter(move |&b| self.contains(b))
    }
}

impl FromIterator<Bds> for Candidates {
    fn from_iter<I: IntoIterator<Item = Bds>>(iter: I) -> Self {
        Candidates(iter.into_iter().fold(0, |m, b| m | 1 << b as u16))
    }
}

/// What a reply's MB is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Inference {
    Identified(Register),
    /// Several registers fit and nothing decides between them.
    Ambiguous(Candidates),
    /// Registers fit its layout, but each contradicts what is known.
    Contradicted(Candidates),
    /// It fits no register's layout (or is all zero).
    NoRegister,
}

/// Points by which the best candidate must lead every other (about a
/// likelihood ratio of 27: see [`evidence`]).
const DECISIVE_LEAD: i32 = 3;

/// Which register `mb` holds, given what is known of its aircraft.
pub fn infer(mb: u64, known: &Known) -> Inference {
    if mb == 0 {
        return Inference::NoRegister;
    }
    // The self-naming registers: a first byte and a layout both matching by
    // chance is far rarer than any register fitting by chance.
    if let Some(cs) = registers::bds20(mb) {
        return Inference::Identified(Register::Identification(cs));
    }
    if registers::bds10(mb) {
        return Inference::Identified(Register::DataLink);
    }
    if registers::bds30(mb) {
        return Inference::Identified(Register::AcasRa);
    }
    let fitting: SmallVec<[Register; 6]> = [
        registers::bds17(mb).map(Register::Capability),
        registers::bds40(mb).map(Register::SelectedVertical),
        registers::bds44(mb).map(Register::MeteoRoutine),
        registers::bds45(mb).map(Register::MeteoHazard),
        registers::bds50(mb).map(Register::TrackTurn),
        registers::bds60(mb).map(Register::HeadingSpeed),
    ]
    .into_iter()
    .flatten()
    .collect();
    if fitting.is_empty() {
        return Inference::NoRegister;
    }
    let assessed: SmallVec<[(Register, i32); 6]> = fitting
        .iter()
        .filter_map(|r| {
            let a = evidence::assess(r, known);
            (!a.contradicted).then_some((*r, a.points))
        })
        .collect();
    if assessed.is_empty() {
        return Inference::Contradicted(fitting.iter().map(Register::bds).collect());
    }
    let best = assessed.iter().map(|&(_, p)| p).max().expect("not empty");
    let leaders = assessed.iter().filter(|&&(_, p)| p == best).count();
    let runner_up = assessed.iter().map(|&(_, p)| p).filter(|&p| p < best).max();
    if leaders == 1 && runner_up.is_none_or(|p| best - p >= DECISIVE_LEAD) {
        let (reg, _) = assessed.iter().find(|&&(_, p)| p == best).expect("a leader");
        return Inference::Identified(*reg);
    }
    // Candidates far behind the leaders are not worth naming.
    Inference::Ambiguous(
        assessed.iter().filter(|&&(_, p)| best - p < DECISIVE_LEAD).map(|(r, _)| r.bds()).collect(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::modes::fields::callsign_str;

    #[test]
    fn identification_register() {
        // DF20 from the beastblackbox capture; pyModeS reads AAR542.
        let mb = u64::from_str_radix("200414B5D32820", 16).unwrap();
        assert_eq!(callsign_str(&registers::bds20(mb).unwrap()), "AAR542");
        assert_eq!(registers::bds20(u64::from_str_radix("10000000000000", 16).unwrap()), None);
        assert_eq!(registers::bds20(0x20 << 48), None);
    }

    #[test]
    fn registers_named_only_on_clear_evidence() {
        let at = |alt| Known { alt_ft: Some((alt, 0.0)), velocity: None };
        // A heading and speed report whose IAS and Mach fit its altitude.
        match infer(0x8F39F91A7E27C4, &at(5_450)) {
            Inference::Identified(Register::HeadingSpeed(r)) => assert_eq!(r.ias_kt, Some(252)),
            other => panic!("{other:?}"),
        }
        // At FL300 the same IAS and Mach contradict each other: whatever else fits remains.
        assert!(!matches!(
            infer(0x8F39F91A7E27C4, &at(30_000)),
            Inference::Identified(Register::HeadingSpeed(_))
        ));
        assert_eq!(infer(0, &Known::default()), Inference::NoRegister);
    }
}
