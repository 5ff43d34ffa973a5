//! What a measurement must be before any filter sees it: finite values, a
//! covariance that is one, a time near the present and a speed an aircraft
//! can fly. Anything else is rejected and counted by its reason (a hostile
//! or broken feed must not reach a filter, where one NaN spoils a track).

use super::{FuseStats, MAX_SPEED_MPS};
use crate::track::{Measurement, Observation};

/// Whether `m`, arriving at `now`, may go in; counted in `stats` when not.
pub(super) fn valid(m: &Measurement, now: f64, max_time_error_s: f64, stats: &mut FuseStats) -> bool {
    let finite = m.t.is_finite()
        && match m.obs {
            Observation::Position { lat, lon, cov_en, height, time_sigma_s, adsb_echo, .. } => {
                lat.is_finite()
                    && lon.is_finite()
                    && lat.abs() <= 90.0
                    && cov_en.iter().all(|v| v.is_finite())
                    && cov_en.cholesky().is_some()
                    && height.is_none_or(|(h, v)| h.is_finite() && v > 0.0 && v.is_finite())
                    && time_sigma_s.is_finite()
                    && (0.0..=1.0).contains(&adsb_echo)
            }
            Observation::Velocity { v_en, cov, climb } => {
                v_en.iter().all(|v| v.is_finite())
                    && cov.cholesky().is_some()
                    && climb.is_none_or(|(c, v)| c.is_finite() && v > 0.0 && v.is_finite())
            }
            Observation::Height { h: z, var } | Observation::Climb { rate: z, var } => {
                z.is_finite() && var > 0.0 && var.is_finite()
            }
            Observation::Tdoa { n, sites, persistent } => {
                (2..=3).contains(&n)
                    && sites[..n as usize].iter().all(|(p, t, s)| {
                        p.iter().all(|v| v.is_finite()) && t.is_finite() && *s > 0.0 && s.is_finite()
                    })
                    && persistent[..n as usize].iter().all(|p| {
                        p.var_s2.is_finite()
                            && p.var_s2 >= 0.0
                            && p.shared_by.is_finite()
                            && p.shared_by >= 1.0
                    })
            }
        };
    if !finite {
        stats.rejected_non_finite += 1;
        return false;
    }
    if (m.t - now).abs() > max_time_error_s {
        stats.rejected_time += 1;
        return false;
    }
    if let Observation::Velocity { v_en, .. } = m.obs {
        if v_en.norm() > MAX_SPEED_MPS {
            stats.rejected_speed += 1;
            return false;
        }
    }
    true
}
