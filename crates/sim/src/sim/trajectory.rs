//! Aircraft kinematics: a start state and segments of constant turn rate,
//! acceleration and vertical rate, integrated on the WGS-84 ellipsoid in
//! 0.1 s steps (midpoint rule, local meridian and prime-vertical radii), so
//! flights are accurate anywhere on Earth except within metres of a pole.

use super::scenario::{Segment, StartState};
use fuse1090_core::geo::radii;

pub const STEP_S: f64 = 0.1;

/// One truth sample.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sample {
    pub lat: f64,
    pub lon: f64,
    pub alt_m: f64,
    /// East, north, up velocity (m/s).
    pub vel: [f64; 3],
}

/// Samples every [`STEP_S`] from `t0` (scenario seconds).
#[derive(Clone, Debug)]
pub struct Trajectory {
    pub t0: f64,
    pub samples: Vec<Sample>,
}

impl Trajectory {
    /// Flies `segments` from `start` for `duration_s`; after the last segment
    /// the aircraft goes on straight and level. Speed never goes below zero
    /// and altitude never below the start's when on the ground.
    pub fn fly(start: &StartState, segments: &[Segment], t0: f64, duration_s: f64, on_ground: bool) -> Self {
        let steps = (duration_s / STEP_S).round().max(0.0) as usize;
        let mut lat = start.lat.to_radians();
        let mut lon = start.lon.to_radians();
        let mut h = start.alt_m;
        let mut v = start.speed_mps;
        let mut psi = start.heading_deg.to_radians();
        let mut vr = if on_ground { 0.0 } else { start.vrate_mps };
        let mut samples = Vec::with_capacity(steps + 1);
        let mut seg = 0;
        let mut seg_end = segments.first().map_or(f64::INFINITY, |s| s.duration_s);
        let mut t = 0.0;
        let push = |samples: &mut Vec<Sample>, lat: f64, lon: f64, h: f64, v: f64, psi: f64, vr: f64| {
            samples.push(Sample {
                lat: lat.to_degrees(),
                lon: (lon.to_degrees() + 540.0).rem_euclid(360.0) - 180.0,
                alt_m: h,
                vel: [v * psi.sin(), v * psi.cos(), vr],
            })
        };
        push(&mut samples, lat, lon, h, v, psi, vr);
        for _ in 0..steps {
            while t >= seg_end - 1e-9 && seg < segments.len() {
                seg += 1;
                seg_end += segments.get(seg).map_or(f64::INFINITY, |s| s.duration_s);
            }
            let (turn, accel, vrate) = match segments.get(seg) {
                Some(s) => (s.turn_dps.to_radians(), s.accel_mps2, s.vrate_mps),
                None => (0.0, 0.0, 0.0),
            };
            if !on_ground && !segments.is_empty() {
                vr = vrate;
            }
            // Midpoint: speed and heading halfway through the step.
            let v_mid = (v + 0.5 * accel * STEP_S).max(0.0);
            let psi_mid = psi + 0.5 * turn * STEP_S;
            let (m, n) = radii(lat);
            let dn = v_mid * psi_mid.cos() * STEP_S;
            let de = v_mid * psi_mid.sin() * STEP_S;
            let h_mid = h + 0.5 * vr * STEP_S;
            let lat_mid = lat + 0.5 * dn / (m + h_mid);
            let (m, n) = if lat_mid != lat { radii(lat_mid) } else { (m, n) };
            lat += dn / (m + h_mid);
            lon += de / ((n + h_mid) * lat_mid.cos());
            h += vr * STEP_S;
            if on_ground {
                h = start.alt_m;
            }
            v = (v + accel * STEP_S).max(0.0);
            psi += turn * STEP_S;
            t += STEP_S;
            push(&mut samples, lat, lon, h, v, psi, vr);
        }
        Trajectory { t0, samples }
    }

    pub fn t_end(&self) -> f64 {
        self.t0 + (self.samples.len().saturating_sub(1)) as f64 * STEP_S
    }

    /// Linear interpolation at `t` (scenario seconds); `None` outside.
    pub fn at(&self, t: f64) -> Option<Sample> {
        let x = (t - self.t0) / STEP_S;
        if x < -1e-9 || x > (self.samples.len() - 1) as f64 + 1e-9 {
            return None;
        }
        let i = (x.floor().max(0.0) as usize).min(self.samples.len().saturating_sub(2));
        let a = self.samples[i];
        let Some(&b) = self.samples.get(i + 1) else {
            return Some(a);
        };
        let f = (x - i as f64).clamp(0.0, 1.0);
        let lerp = |p: f64, q: f64| p + (q - p) * f;
        let dlon = ((b.lon - a.lon + 540.0).rem_euclid(360.0)) - 180.0;
        Some(Sample {
            lat: lerp(a.lat, b.lat),
            lon: (a.lon + dlon * f + 540.0).rem_euclid(360.0) - 180.0,
            alt_m: lerp(a.alt_m, b.alt_m),
            vel: [lerp(a.vel[0], b.vel[0]), lerp(a.vel[1], b.vel[1]), lerp(a.vel[2], b.vel[2])],
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use fuse1090_core::geo::distance_m;

    fn start(lat: f64, lon: f64, heading: f64) -> StartState {
        StartState { lat, lon, alt_m: 3000.0, speed_mps: 120.0, heading_deg: heading, vrate_mps: 0.0 }
    }

    #[test]
    fn straight_flight_covers_speed_times_time_anywhere() {
        for (lat, lon, hdg) in [(0.0, 0.0, 90.0), (60.0, 30.0, 45.0), (-45.0, 179.99, 90.0), (80.0, 0.0, 0.0)]
        {
            let tr = Trajectory::fly(&start(lat, lon, hdg), &[], 0.0, 100.0, false);
            let a = tr.samples[0];
            let b = *tr.samples.last().unwrap();
            let d = distance_m(a.lat, a.lon, b.lat, b.lon);
            // Distance at 3 km height along the ground: 12 km scaled by R/(R+h), within 0.5%.
            assert!((d - 12_000.0).abs() < 60.0, "{lat},{lon}: {d}");
        }
    }

    #[test]
    fn turn_rate_and_acceleration() {
        let segs = [
            Segment { duration_s: 10.0, turn_dps: 0.0, accel_mps2: 3.0, vrate_mps: 0.0 },
            Segment { duration_s: 10.0, turn_dps: -3.0, accel_mps2: 0.0, vrate_mps: 5.0 },
        ];
        let tr = Trajectory::fly(&start(43.0, 1.0, 90.0), &segs, 0.0, 30.0, false);
        let s10 = tr.at(10.0).unwrap();
        assert!((s10.vel[0].hypot(s10.vel[1]) - 150.0).abs() < 1e-6);
        let s20 = tr.at(20.0).unwrap();
        let heading = s20.vel[0].atan2(s20.vel[1]).to_degrees();
        assert!((heading - 60.0).abs() < 1e-6, "{heading}");
        assert!((s20.alt_m - 3050.0).abs() < 1e-6);
        // Level again after the segments.
        assert!((tr.at(30.0).unwrap().alt_m - 3050.0).abs() < 1e-6);
        // Interpolation between samples.
        let mid = tr.at(5.05).unwrap();
        assert!((mid.vel[0] - 135.15).abs() < 0.01, "{mid:?}");
        assert!(tr.at(30.01).is_none() && tr.at(-0.01).is_none());
    }
}
