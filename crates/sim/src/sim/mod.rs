//! The synthetic world: receivers with imperfect clocks and networks,
//! aircraft flying scripted or random trajectories and transmitting at real
//! rates, propagation at the speed of light in air. Writes a capture (what
//! the receivers would have sent us) and the truth (where everything really
//! was). Deterministic: the same scenario and seed give the same bytes.
//!
//! Each receiver and aircraft draws from its own seeded random stream, and
//! transmissions are processed in emission order, so the output depends only
//! on the scenario.

pub mod clock;
pub mod commb;
pub mod scenario;
pub mod trajectory;
pub mod transmit;

use std::cmp::Reverse;
use std::collections::BinaryHeap;
use std::io::Write;

use anyhow::Result;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

use clock::ClockModel;
use fuse1090_core::feed::capture::{CaptureWriter, ReceiverDecl};
use fuse1090_core::feed::RawFrame;
use fuse1090_core::geo::{displace, ecef_distance, geodetic_to_ecef};
use scenario::{Aircraft, Receiver, Scenario, Segment, StartState};
use trajectory::{Trajectory, STEP_S};
use transmit::{Transmission, Transmitter};

/// Speed of light in air near the ground (refractive index 1.0003).
pub const C_AIR: f64 = 299_792_458.0 / 1.0003;

/// Independent random stream `stream` of a scenario seed.
fn rng(seed: u64, stream: u64) -> ChaCha8Rng {
    let mut r = ChaCha8Rng::seed_from_u64(seed);
    r.set_stream(stream);
    r
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SimStats {
    pub receivers: usize,
    pub aircraft: usize,
    pub transmissions: u64,
    pub receptions: u64,
    /// Receptions that took a reflected path (late).
    pub multipath: u64,
    pub truth_lines: u64,
}

struct RxSim {
    spec: Receiver,
    ecef: [f64; 3],
    clock: ClockModel,
    delay: Normal<f64>,
    bursts: Vec<(f64, f64)>,
    last_arrival: f64,
    rng: ChaCha8Rng,
}

/// A uniformly random point in a disk (km) around a centre.
fn random_in_disk(r: &mut ChaCha8Rng, lat: f64, lon: f64, radius_km: f64) -> (f64, f64) {
    let d = radius_km * 1000.0 * r.gen::<f64>().sqrt();
    let a = r.gen_range(0.0..std::f64::consts::TAU);
    let (la, lo, _) = displace(lat, lon, 0.0, [d * a.sin(), d * a.cos(), 0.0]);
    (la, lo)
}

/// Every receiver of a scenario, receiver fields expanded (deterministic).
pub fn all_receivers(s: &Scenario) -> Vec<Receiver> {
    let mut out = s.receiver.clone();
    for (k, f) in s.receiver_field.iter().enumerate() {
        let mut r = rng(s.seed, 1_000_000 + k as u64);
        for i in 0..f.count {
            let (lat, lon) = random_in_disk(&mut r, f.center_lat, f.center_lon, f.radius_km);
            let gps = r.gen::<f64>() < f.gps_share;
            out.push(Receiver {
                id: format!("{}{}", f.id_prefix, i + 1),
                lat,
                lon,
                alt_m: r.gen_range(20.0..400.0),
                clock: if gps {
                    fuse1090_core::feed::capture::ClockKind::Gps
                } else {
                    fuse1090_core::feed::capture::ClockKind::Beast12
                },
                clock_offset_s: None,
                drift_ppm: if gps { 0.0 } else { r.gen_range(-f.max_drift_ppm..=f.max_drift_ppm) },
                drift_walk_ppm: if gps { 0.0 } else { 0.001 },
                jitter_ns: f.jitter_ns,
                bias_ns: 0.0,
                multipath_prob: 0.0,
                multipath_delay_ns: 0.0,
                resets_s: Vec::new(),
                position_error_m: [0.0; 3],
                range_km: f.range_km,
                loss: f.loss,
                delay_ms: r.gen_range(10.0..80.0),
                delay_spread_ms: 5.0,
                burst_per_min: 0.0,
                burst_s: 1.0,
                burst_ms: 0.0,
            });
        }
    }
    out
}

/// Expands random traffic into aircraft.
fn all_aircraft(s: &Scenario) -> Vec<Aircraft> {
    let mut out = s.aircraft.clone();
    for (k, tr) in s.traffic.iter().enumerate() {
        let mut r = rng(s.seed, 2_000_000 + k as u64);
        for i in 0..tr.count {
            let (lat, lon) = random_in_disk(&mut r, tr.center_lat, tr.center_lon, tr.radius_km);
            let alt = r.gen_range(tr.alt_m[0]..=tr.alt_m[1]);
            let mut segments = Vec::new();
            let mut t = 0.0;
            let mut h = alt;
            while t < s.duration_s {
                let d = r.gen_range(20.0..90.0);
                let seg = match r.gen_range(0..6) {
                    0 | 1 => Segment { duration_s: d, turn_dps: 0.0, accel_mps2: 0.0, vrate_mps: 0.0 },
                    2 => Segment {
                        duration_s: d,
                        turn_dps: r.gen_range(-3.0..3.0),
                        accel_mps2: 0.0,
                        vrate_mps: 0.0,
                    },
                    3 => Segment {
                        duration_s: d,
                        turn_dps: 0.0,
                        accel_mps2: r.gen_range(-0.5..0.5),
                        vrate_mps: 0.0,
                    },
                    _ => {
                        let vr: f64 = r.gen_range(-10.0..10.0);
                        let vr = if h + vr * d < tr.alt_m[0] || h + vr * d > tr.alt_m[1] { -vr } else { vr };
                        h += vr * d;
                        Segment { duration_s: d, turn_dps: 0.0, accel_mps2: 0.0, vrate_mps: vr }
                    }
                };
                // Keep speeds inside the range: no acceleration that would leave it.
                segments.push(seg);
                t += d;
            }
            let spoof = i >= tr.count - tr.spoofers;
            let mode_s_only = i < tr.mode_s_only;
            let spoof_offset_m = spoof.then(|| {
                let d = tr.spoof_offset_m[(i + tr.spoofers - tr.count) % tr.spoof_offset_m.len()];
                let a: f64 = r.gen_range(0.0..std::f64::consts::TAU);
                [d * a.sin(), d * a.cos()]
            });
            out.push(Aircraft {
                hex: tr.first_hex + i as u32,
                callsign: format!("SIM{}", i + 1),
                adsb: !mode_s_only,
                nac_p: tr.nac_p,
                nac_v: 2,
                pos_sigma_m: None,
                gnss_tau_s: 0.0,
                on_ground: false,
                squawk: format!("{:04o}", 0o1000 + (i % 0o6000)),
                start: StartState {
                    lat,
                    lon,
                    alt_m: alt,
                    speed_mps: r.gen_range(tr.speed_mps[0]..=tr.speed_mps[1]),
                    heading_deg: r.gen_range(0.0..360.0),
                    vrate_mps: 0.0,
                },
                segments: segments
                    .into_iter()
                    .map(|mut sg| {
                        sg.accel_mps2 = if tr.speed_mps[0] == tr.speed_mps[1] { 0.0 } else { sg.accel_mps2 };
                        sg
                    })
                    .collect(),
                spoof_offset_m,
                rates: Default::default(),
                start_s: 0.0,
                end_s: None,
            });
        }
    }
    out
}

/// Radio horizon (m) between heights (m) over a smooth 4/3 Earth.
fn radio_horizon_m(h1: f64, h2: f64) -> f64 {
    4_120.0 * (h1.max(0.0).sqrt() + h2.max(0.0).sqrt()) + 5_000.0
}

/// A configuration that gives fuse1090 every receiver's true position and
/// timing (`[[receiver]]` with `[receiver.timing]`): an oracle run with it
/// shows what learning the network costs against knowing it.
pub fn oracle_config(s: &Scenario) -> String {
    use std::fmt::Write as _;
    let mut out = String::from(
        "# Every receiver's true position and timing in this scenario, for an oracle run:\n\
         # fuse1090 run --config oracle.toml --capture capture.txt --output OUT\n",
    );
    for r in all_receivers(s) {
        // The timestamps' rounding is noise too: a counter's 12 MHz tick,
        // a GPS time's nanosecond. A counter's constant offset is its clock's.
        let (tick_s, offset_ns) = match r.clock {
            fuse1090_core::feed::capture::ClockKind::Beast12 => (1.0 / 12e6, 0.0),
            fuse1090_core::feed::capture::ClockKind::Gps => (1e-9, r.bias_ns),
        };
        let sigma_ns = ((r.jitter_ns * 1e-9).powi(2) + tick_s * tick_s / 12.0).sqrt() * 1e9;
        let _ = write!(
            out,
            "\n[[receiver]]\nid = \"{}\"\nlat = {:.8}\nlon = {:.8}\nalt_m = {:.2}\nclock = \"{}\"\n\
             [receiver.timing]\nsigma_ns = {:.3}\noffset_ns = {:.3}\nlate_rate = {}\nlate_delay_ns = {}\n",
            r.id,
            r.lat,
            r.lon,
            r.alt_m,
            r.clock.name(),
            sigma_ns,
            offset_ns,
            r.multipath_prob,
            if r.multipath_prob > 0.0 { r.multipath_delay_ns } else { 300.0 },
        );
    }
    out
}

/// Runs the scenario, writing the capture and the truth.
pub fn simulate(s: &Scenario, capture: impl Write, truth: impl Write) -> Result<SimStats> {
    let receivers = all_receivers(s);
    let aircraft = all_aircraft(s);
    let mut stats = SimStats { receivers: receivers.len(), aircraft: aircraft.len(), ..Default::default() };

    let mut cap = CaptureWriter::new(capture, &format!("fuse1090 sim, seed {}", s.seed))?;
    let mut rxs = Vec::with_capacity(receivers.len());
    for (i, r) in receivers.iter().enumerate() {
        let rx = RxSim::new(s, i, r);
        let (dlat, dlon, dalt) = displace(r.lat, r.lon, r.alt_m, r.position_error_m);
        cap.receiver(&ReceiverDecl { id: r.id.clone(), lat: dlat, lon: dlon, alt: dalt, clock: r.clock })?;
        rxs.push(rx);
    }

    let trajectories: Vec<Trajectory> = aircraft
        .iter()
        .map(|a| {
            let end = a.end_s.unwrap_or(s.duration_s).min(s.duration_s);
            Trajectory::fly(&a.start, &a.segments, a.start_s, (end - a.start_s).max(0.0), a.on_ground)
        })
        .collect();
    let mut transmitters: Vec<Transmitter> = aircraft
        .iter()
        .enumerate()
        .map(|(i, a)| {
            let rng = rng(s.seed, 20_000 + i as u64);
            Transmitter::new(a, s.interrogation_hz, &s.commb, s.baro_offset_m, &s.air, rng)
        })
        .collect();

    // Transmissions in emission order; receptions written in arrival order.
    // A reception arrives after its emission, so once emissions have reached
    // time T everything that arrived by T is final and can be written.
    let ns = |t: f64| (t * 1e9).round() as i64;
    let mut due: BinaryHeap<Reverse<(i64, usize)>> =
        transmitters.iter().enumerate().map(|(i, tx)| Reverse((ns(tx.next_time()), i))).collect();
    let mut pending: BinaryHeap<Reverse<(i64, u64, usize, RawFrame)>> = BinaryHeap::new();
    let mut seq = 0u64;
    let write_until = |pending: &mut BinaryHeap<Reverse<(i64, u64, usize, RawFrame)>>,
                       cap: &mut CaptureWriter<_>,
                       limit: i64|
     -> Result<()> {
        while pending.peek().is_some_and(|Reverse(p)| p.0 <= limit) {
            let Reverse((arr, _, rx, frame)) = pending.pop().expect("peeked");
            cap.frame(s.start_unix + arr as f64 * 1e-9, rx, &frame)?;
        }
        Ok(())
    };
    while let Some(Reverse((t_ns, i))) = due.pop() {
        let t = t_ns as f64 * 1e-9;
        if t > s.duration_s {
            continue;
        }
        let tx = &mut transmitters[i];
        if let Some(x) = tx.emit(&trajectories[i]) {
            stats.transmissions += 1;
            let p = x.true_pos;
            let from = geodetic_to_ecef(p.lat, p.lon, p.alt_m);
            for (ri, rx) in rxs.iter_mut().enumerate() {
                if let Some((arrival, frame)) = rx.receive(&x, from, &mut stats) {
                    seq += 1;
                    pending.push(Reverse((ns(arrival), seq, ri, frame)));
                }
            }
        }
        let next = tx.next_time();
        if next <= s.duration_s {
            due.push(Reverse((ns(next), i)));
        }
        write_until(&mut pending, &mut cap, t_ns)?;
    }
    write_until(&mut pending, &mut cap, i64::MAX)?;
    cap.into_inner().flush()?;
    stats.truth_lines = write_truth(s, &receivers, &aircraft, &trajectories, truth)?;
    Ok(stats)
}

impl RxSim {
    /// Receiver `i` of the scenario: its clock, network delay and delay
    /// bursts drawn from its own random stream.
    fn new(s: &Scenario, i: usize, r: &Receiver) -> RxSim {
        let mut g = rng(s.seed, 10_000 + i as u64);
        let clock = ClockModel::new(r, s.start_unix, s.duration_s, &mut g);
        let mut bursts = Vec::new();
        if r.burst_per_min > 0.0 {
            let mut t = 0.0;
            loop {
                t += -(1.0 - g.gen::<f64>()).ln() * 60.0 / r.burst_per_min;
                if t > s.duration_s {
                    break;
                }
                bursts.push((t, t + r.burst_s));
            }
        }
        RxSim {
            spec: r.clone(),
            ecef: geodetic_to_ecef(r.lat, r.lon, r.alt_m),
            clock,
            delay: Normal::new(r.delay_ms * 1e-3, r.delay_spread_ms * 1e-3).expect("finite"),
            bursts,
            last_arrival: f64::NEG_INFINITY,
            rng: g,
        }
    }

    /// This receiver's copy of a transmission sent from `from` (ECEF): when
    /// it reaches the server (scenario time) and the frame with the
    /// receiver's timestamp; `None` when out of range, below the horizon,
    /// or lost.
    fn receive(&mut self, x: &Transmission, from: [f64; 3], stats: &mut SimStats) -> Option<(f64, RawFrame)> {
        let d = ecef_distance(from, self.ecef);
        if d > self.spec.range_km * 1000.0 || d > radio_horizon_m(x.true_pos.alt_m, self.spec.alt_m) {
            return None;
        }
        if self.spec.loss > 0.0 && self.rng.gen::<f64>() < self.spec.loss {
            return None;
        }
        let toa = x.t + d / C_AIR;
        // Drawn only for a receiver with multipath, so that every
        // other receiver's random stream is as it was.
        let late = self.spec.multipath_prob > 0.0 && self.rng.gen::<f64>() < self.spec.multipath_prob;
        let reflected = if late {
            -(1.0 - self.rng.gen::<f64>()).ln() * self.spec.multipath_delay_ns * 1e-9
        } else {
            0.0
        };
        let ts = self.clock.timestamp(toa + self.spec.bias_ns * 1e-9 + reflected, &mut self.rng);
        stats.multipath += late as u64;
        let mut delay = self.delay.sample(&mut self.rng).max(2e-4);
        if self.bursts.iter().any(|&(a, b)| a <= toa && toa < b) {
            delay += self.spec.burst_ms * 1e-3;
        }
        // One TCP stream per receiver: frames arrive in the order sent.
        let arrival = (toa + delay).max(self.last_arrival);
        self.last_arrival = arrival;
        let signal = (255.0 - 40.0 * (d / 1000.0 + 1.0).log10()).clamp(1.0, 255.0) as u8;
        let frame = RawFrame::new(&x.bytes[..x.len], ts, signal).expect("valid length");
        stats.receptions += 1;
        Some((arrival, frame))
    }
}

/// The truth file: each receiver's true timing and position error, who is
/// who, then where everyone was every 0.1 s. Returns the truth lines written.
fn write_truth(
    s: &Scenario,
    receivers: &[Receiver],
    aircraft: &[Aircraft],
    trajectories: &[Trajectory],
    mut truth: impl Write,
) -> Result<u64> {
    for r in receivers {
        let e = r.position_error_m;
        writeln!(
            truth,
            "{{\"type\":\"receiver\",\"id\":\"{}\",\"clock\":\"{}\",\"sigma_ns\":{},\"offset_ns\":{},\
             \"multipath_prob\":{},\"multipath_delay_ns\":{},\"position_offset_en_m\":[{},{}]}}",
            r.id,
            r.clock.name(),
            r.jitter_ns,
            r.bias_ns,
            r.multipath_prob,
            r.multipath_delay_ns,
            // Where the antenna is relative to where it is declared (no -0).
            0.0 - e[0],
            0.0 - e[1]
        )?;
    }
    for a in aircraft {
        writeln!(
            truth,
            "{{\"type\":\"equipage\",\"hex\":\"{:06X}\",\"adsb\":{},\"nac_p\":{}}}",
            a.hex, a.adsb, a.nac_p
        )?;
        if a.spoof_offset_m.is_some() && a.adsb {
            writeln!(truth, "{{\"type\":\"spoof\",\"hex\":\"{:06X}\"}}", a.hex)?;
        }
    }
    let mut lines = 0;
    let steps = (s.duration_s / STEP_S).round() as usize;
    for k in 0..=steps {
        let t = k as f64 * STEP_S;
        for (a, tr) in aircraft.iter().zip(trajectories) {
            let Some(p) =
                tr.samples.get(((t - tr.t0) / STEP_S).round() as usize).filter(|_| t >= tr.t0 - 1e-9)
            else {
                continue;
            };
            writeln!(
                truth,
                "{{\"type\":\"truth\",\"hex\":\"{:06X}\",\"t\":{:.3},\"lat\":{:.8},\"lon\":{:.8},\"alt_m\":{:.2},\
                 \"vel_enu\":[{:.3},{:.3},{:.3}]}}",
                a.hex,
                s.start_unix + t,
                p.lat,
                p.lon,
                p.alt_m,
                p.vel[0],
                p.vel[1],
                p.vel[2]
            )?;
            lines += 1;
        }
    }
    truth.flush()?;
    Ok(lines)
}
