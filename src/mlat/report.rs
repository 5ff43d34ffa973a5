//! What multilateration has learnt about one receiver, as the operator and
//! the track stream see it (`{"type":"receiver",...}`, once a minute and at
//! the end of a run): its state, and its timing as the data shows it.
//!
//! Fields not known yet are `None` (absent in the JSON): a receiver is
//! learning until enough of its copies went into fixes or its clock pairs.

/// A receiver's standing in multilateration.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
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

#[derive(Clone, Debug, PartialEq)]
pub struct ReceiverReport {
    /// Data time of the report (s).
    pub t: f64,
    /// The receiver's index (its id is the core's to name).
    pub rx: usize,
    pub state: RxState,
    /// Why it is excluded.
    pub reason: Option<&'static str>,
    /// Its timing sigma (ns), the Gaussian core, from its fixes' residuals.
    pub sigma_ns: Option<f64>,
    /// GPS-timed: its constant offset against the network's other GPS-timed receivers (ns).
    pub offset_ns: Option<f64>,
    /// The share of its copies left out of fixes as outliers.
    pub outlier_rate: Option<f64>,
    /// Where the traffic says its antenna is against its declared position
    /// ([east, north] m), and that estimate's sigma (m).
    pub position_offset_en_m: Option<[f64; 2]>,
    pub position_offset_sigma_m: Option<f64>,
}
