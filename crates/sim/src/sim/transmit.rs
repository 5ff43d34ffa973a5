//! What an aircraft transmits and when: DF17 squitters at their DO-260B rates
//! (positions ~2 Hz alternating even/odd, velocity ~2 Hz, identification
//! ~0.2 Hz, operational status ~0.4 Hz, target state ~1 Hz; surface positions
//! 2 Hz moving, 0.2 Hz still), DF11 acquisition squitters ~1 Hz, and
//! DF4/5/20/21 replies at the interrogation rate. Broadcast positions carry
//! the GNSS error that goes with the NACp (and a spoofer's offset); the
//! signal always leaves from the true position.

use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

use super::scenario::{Air, Aircraft};
use super::trajectory::{Sample, Trajectory};
use fuse1090_core::geo::{displace, FT_TO_M};
use fuse1090_core::modes::commb::Bds;
use fuse1090_core::modes::cpr::encode as cpr_encode;
use fuse1090_core::modes::encode::{
    ac13_q, df11, df17, id13, me_airborne_position, me_identification, me_operational_status,
    me_surface_position, me_target_state, me_velocity, movement_code, surveillance_reply,
};
use fuse1090_core::modes::nic::{nacp_epu_m, nacv_bounds, R95_PER_SIGMA};

const MS_TO_KT: f64 = 3600.0 / 1852.0;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    Position,
    Velocity,
    Ident,
    Status,
    TargetState,
    AllCall,
    Reply,
}

struct Schedule {
    kind: Kind,
    period_s: f64,
    next: f64,
}

/// A frame leaving an aircraft.
pub struct Transmission {
    /// Scenario time of emission (s).
    pub t: f64,
    pub bytes: [u8; 14],
    pub len: usize,
    /// Where the signal really leaves from.
    pub true_pos: Sample,
}

pub struct Transmitter {
    pub hex: u32,
    spec: Aircraft,
    schedules: Vec<Schedule>,
    next_odd: bool,
    reply_cycle: u8,
    /// The Comm-B registers DF20/21 replies carry, one at random each.
    commb: Vec<Bds>,
    /// GNSS error state (east, north, up; m) and when it was last advanced.
    gnss: [f64; 3],
    gnss_t: f64,
    sigma_m: f64,
    baro_offset_m: f64,
    air: Air,
    rng: ChaCha8Rng,
}

/// NACv 95% bound (m/s) as a per-axis sigma: unknown (0) as NACv 1, out
/// of range as NACv 4.
fn nacv_sigma(nac_v: u8) -> f64 {
    let bound = match nac_v {
        0 => 10.0,
        n => nacv_bounds(n).map_or(0.3, |(h95, _)| h95),
    };
    bound / R95_PER_SIGMA
}

impl Transmitter {
    pub fn new(
        spec: &Aircraft,
        default_interrogation_hz: f64,
        commb: &[Bds],
        baro_offset_m: f64,
        air: &Air,
        mut rng: ChaCha8Rng,
    ) -> Self {
        let r = spec.rates;
        let mut rates = vec![
            (Kind::AllCall, r.df11_hz.unwrap_or(1.0)),
            (Kind::Reply, r.interrogation_hz.unwrap_or(default_interrogation_hz)),
        ];
        if spec.adsb {
            // Surface positions drop to 0.2 Hz when still; see `emit`.
            rates.extend([
                (Kind::Position, r.position_hz.unwrap_or(2.0)),
                (Kind::Velocity, r.velocity_hz.unwrap_or(if spec.on_ground { 0.0 } else { 2.0 })),
                (Kind::Ident, r.ident_hz.unwrap_or(0.2)),
                (Kind::Status, r.status_hz.unwrap_or(0.4)),
                (Kind::TargetState, r.target_state_hz.unwrap_or(if spec.on_ground { 0.0 } else { 1.0 })),
            ]);
        }
        let schedules = rates
            .into_iter()
            .filter(|&(_, hz)| hz > 0.0)
            .map(|(kind, hz)| Schedule {
                kind,
                period_s: 1.0 / hz,
                next: spec.start_s + rng.gen::<f64>() / hz,
            })
            .collect();
        let sigma_m =
            spec.pos_sigma_m.unwrap_or_else(|| nacp_epu_m(spec.nac_p).unwrap_or(1852.0) / R95_PER_SIGMA);
        let gnss = [0.0; 3].map(|_: f64| sigma_m * rng.sample::<f64, _>(StandardNormal));
        Transmitter {
            hex: spec.hex,
            spec: spec.clone(),
            schedules,
            next_odd: rng.gen(),
            reply_cycle: 0,
            commb: commb.to_vec(),
            gnss,
            gnss_t: spec.start_s,
            sigma_m,
            baro_offset_m,
            air: air.clone(),
            rng,
        }
    }

    /// When the next transmission is due (scenario s).
    pub fn next_time(&self) -> f64 {
        self.schedules.iter().map(|s| s.next).fold(f64::INFINITY, f64::min)
    }

    fn advance_gnss(&mut self, t: f64) {
        let dt = (t - self.gnss_t).max(0.0);
        self.gnss_t = t;
        let tau = self.spec.gnss_tau_s;
        let phi = if tau > 0.0 { (-dt / tau).exp() } else { 0.0 };
        let q = self.sigma_m * (1.0 - phi * phi).sqrt();
        for e in &mut self.gnss {
            *e = phi * *e + q * self.rng.sample::<f64, _>(StandardNormal);
        }
    }

    /// Produces the transmission due now, or `None` when the aircraft is not flying at that time.
    pub fn emit(&mut self, traj: &Trajectory) -> Option<Transmission> {
        let i = (0..self.schedules.len())
            .min_by(|&a, &b| self.schedules[a].next.total_cmp(&self.schedules[b].next))?;
        let t = self.schedules[i].next;
        let kind = self.schedules[i].kind;
        let truth = traj.at(t);
        let mut period = self.schedules[i].period_s;
        if kind == Kind::Position && self.spec.on_ground {
            // Surface positions: 2 Hz moving, 0.2 Hz standing still.
            let moving = truth.is_some_and(|s| s.vel[0].hypot(s.vel[1]) > 0.5);
            period = if moving { period } else { period.max(5.0) };
        }
        // Real transponders dither their squitter times by about +/-20%.
        self.schedules[i].next = t + period * self.rng.gen_range(0.8..1.2);
        let s = truth?;
        let addr = self.hex;
        let ca = if self.spec.on_ground { 4 } else { 5 };
        let baro_ft = ((s.alt_m - self.baro_offset_m) / FT_TO_M).round() as i32;
        let frame: Vec<u8> = match kind {
            Kind::Position => {
                self.advance_gnss(t);
                let odd = self.next_odd;
                self.next_odd = !odd;
                let [de, dn] = self.spec.spoof_offset_m.unwrap_or([0.0, 0.0]);
                let (lat, lon, _) =
                    displace(s.lat, s.lon, s.alt_m, [de + self.gnss[0], dn + self.gnss[1], 0.0]);
                if self.spec.on_ground {
                    let gs = s.vel[0].hypot(s.vel[1]) * MS_TO_KT;
                    let track = (gs > 1.0).then(|| s.vel[0].atan2(s.vel[1]).to_degrees());
                    df17(
                        ca,
                        addr,
                        me_surface_position(7, movement_code(gs), track, cpr_encode(lat, lon, odd, true)),
                    )
                    .to_vec()
                } else {
                    let me = me_airborne_position(11, Some(baro_ft), 0, cpr_encode(lat, lon, odd, false));
                    df17(ca, addr, me).to_vec()
                }
            }
            Kind::Velocity => {
                let sv = nacv_sigma(self.spec.nac_v);
                let mut n = || sv * self.rng.sample::<f64, _>(StandardNormal);
                let (ve, vn) = ((s.vel[0] + n()) * MS_TO_KT, (s.vel[1] + n()) * MS_TO_KT);
                let vr = (s.vel[2] / FT_TO_M * 60.0).round() as i32;
                let diff = (self.baro_offset_m / FT_TO_M).round() as i32;
                df17(ca, addr, me_velocity(ve, vn, Some(vr), true, self.spec.nac_v, Some(diff))).to_vec()
            }
            Kind::Ident => df17(ca, addr, me_identification(0xA3, &self.spec.callsign)).to_vec(),
            Kind::Status => {
                df17(ca, addr, me_operational_status(self.spec.on_ground, 2, 0, self.spec.nac_p, 3)).to_vec()
            }
            Kind::TargetState => df17(ca, addr, me_target_state(self.spec.nac_p, 3)).to_vec(),
            Kind::AllCall => df11(ca, addr, 0).to_vec(),
            Kind::Reply => {
                self.reply_cycle = (self.reply_cycle + 1) % 4;
                let fs = if self.spec.on_ground { 1 } else { 0 };
                let alt = ac13_q(baro_ft).unwrap_or(0);
                let squawk = u16::from_str_radix(&self.spec.squawk, 16).unwrap_or(0x1000);
                match self.reply_cycle {
                    0 => surveillance_reply(4, fs, alt, addr, None),
                    1 => surveillance_reply(5, fs, id13(squawk), addr, None),
                    2 => surveillance_reply(20, fs, alt, addr, Some(self.commb_register(traj, t))),
                    _ => surveillance_reply(21, fs, id13(squawk), addr, Some(self.commb_register(traj, t))),
                }
            }
        };
        let mut bytes = [0u8; 14];
        bytes[..frame.len()].copy_from_slice(&frame);
        Some(Transmission { t, bytes, len: frame.len(), true_pos: s })
    }

    /// The MB of the next DF20/21 reply: one of the registers, filled
    /// from the aircraft's state (see [`super::commb`]).
    fn commb_register(&mut self, traj: &Trajectory, t: f64) -> u64 {
        // Which register an interrogator asks for does not depend on whether
        // it asked for the altitude (DF20) or the identity (DF21) with it.
        let bds = match self.commb.len() {
            1 => self.commb[0],
            n => self.commb[self.rng.gen_range(0..n)],
        };
        if bds == Bds::B20 {
            return (0x20u64 << 48) | (me_identification(0xA0, &self.spec.callsign) & 0xFFFF_FFFF_FFFF);
        }
        // A transponder answers from its register, which the avionics refresh
        // every 1.3 s at the most (ICAO Doc 9871): the values are up to that old.
        let lag_s = self.rng.gen_range(0.0..fuse1090_core::modes::commb::REFRESH_S);
        let (air, baro) = (&self.air, self.baro_offset_m);
        let filled = super::commb::register(bds, traj, t - lag_s, baro, air);
        // Just after the aircraft appeared, its state now.
        filled.or_else(|| super::commb::register(bds, traj, t, baro, air)).unwrap_or(0)
    }
}
