//! What multilateration has learnt about one receiver, as the operator and
//! the track stream see it (`{"type":"receiver",...}`, once a minute and at
//! the end of a run): its state, and its timing as the data shows it.
//!
//! Fields not known yet are `None` (absent in the JSON): a receiver is
//! learning until enough of its copies went into fixes or its clock pairs.

/// A receiver's standing in multilateration.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum RxState {
    /// Too little seen yet to say.
    Learning,
    Ok,
    Excluded,
}

impl RxState {
    pub fn name(self) -> &'static str {
        match self {
            RxState::Learning => "learning",
            RxState::Ok => "ok",
            RxState::Excluded => "excluded",
        }
    }
}

/// Why a receiver is out of the fixes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Exclusion {
    /// Its clock pairs keep rejecting its measurements (a broken or
    /// unstable clock): still synchronised, readmitted when they hold.
    SyncFailing,
    /// Its survey says its declared position is wrong (and `self_survey`
    /// is off, so the surveyed one is not used instead).
    Misplaced,
    /// Its time keeps jumping: a counter restarting all the time (or
    /// sending random timestamps), a GPS time off by whole seconds.
    TimeJumps,
}

impl Exclusion {
    pub fn name(self) -> &'static str {
        match self {
            Exclusion::SyncFailing => "sync_failing",
            Exclusion::Misplaced => "misplaced",
            Exclusion::TimeJumps => "time_jumps",
        }
    }
}

/// One receiver in a line of text (the run report, the service's log):
/// `id=state/sigma/offset/outliers[/east,north+-sigma]`, `-` where unknown.
pub fn summary(r: &ReceiverReport, id: &str) -> String {
    let ns = |v: Option<f64>, plus: bool| match (v, plus) {
        (Some(v), true) => format!("{v:+.0}ns"),
        (Some(v), false) => format!("{v:.0}ns"),
        (None, _) => "-".into(),
    };
    let state = match r.reason {
        Some(why) => format!("{}({})", r.state.name(), why.name()),
        None => r.state.name().to_string(),
    };
    let mut s = format!(
        "{id}={}/{}/{}/{}",
        state,
        ns(r.sigma_ns, false),
        ns(r.offset_ns, true),
        r.outlier_rate.map_or("-".into(), |o| format!("{:.1}%", 100.0 * o))
    );
    if let (Some([e, n]), Some(sigma)) = (r.position_offset_en_m, r.position_offset_sigma_m) {
        s += &format!("/{e:+.0},{n:+.0}m+-{sigma:.0}");
    }
    s
}

#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ReceiverReport {
    /// Data time of the report (s).
    pub t: f64,
    /// The receiver's index (its id is the core's to name).
    pub rx: usize,
    pub state: RxState,
    /// Why it is excluded.
    pub reason: Option<Exclusion>,
    /// Its timing sigma (ns), the Gaussian core, from its fixes' residuals.
    pub sigma_ns: Option<f64>,
    /// GPS-timed: its constant offset against the network's other GPS-timed receivers (ns).
    pub offset_ns: Option<f64>,
    /// The share of its copies that are late (multipath) by its learnt
    /// model, and their mean extra delay (ns).
    pub outlier_rate: Option<f64>,
    pub late_delay_ns: Option<f64>,
    /// Where the traffic says its antenna is against its declared position
    /// ([east, north] m), and that estimate's sigma (m).
    pub position_offset_en_m: Option<[f64; 2]>,
    pub position_offset_sigma_m: Option<f64>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_receiver_in_one_word_with_dashes_for_what_is_unknown() {
        let mut r = ReceiverReport {
            t: 0.0,
            rx: 0,
            state: RxState::Ok,
            reason: None,
            sigma_ns: Some(75.4),
            offset_ns: Some(-47.6),
            outlier_rate: Some(0.0899),
            late_delay_ns: Some(420.0),
            position_offset_en_m: Some([116.2, -82.7]),
            position_offset_sigma_m: Some(4.4),
        };
        assert_eq!(summary(&r, "n06"), "n06=ok/75ns/-48ns/9.0%/+116,-83m+-4");
        (r.state, r.offset_ns, r.outlier_rate, r.position_offset_en_m) =
            (RxState::Learning, None, None, None);
        assert_eq!(summary(&r, "n07"), "n07=learning/75ns/-/-");
        (r.state, r.reason) = (RxState::Excluded, Some(Exclusion::Misplaced));
        assert_eq!(summary(&r, "n07"), "n07=excluded(misplaced)/75ns/-/-");
    }
}
