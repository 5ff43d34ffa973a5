//! A velocity report as a track measures it: turned from the aircraft's
//! own east/north into the plane's axes, gated against the track's own
//! velocity, and applied as a linear measurement of the velocity.

use super::*;

impl Track {
    pub(super) fn velocity(&mut self, t: f64, dt: f64, v_en: Vector2<f64>, cov: Matrix2<f64>) -> Outcome {
        let gate = self.gate;
        // Reported in the aircraft's own east/north: turned into the
        // plane's axes (they differ by the meridians' convergence,
        // a third of a degree 20 km east or west at mid latitudes).
        let r = match (self.state.plane, &self.state.imm) {
            (Some(plane), Some(imm)) => {
                let x = imm.mean();
                let (lat, lon) = plane.to_geodetic(x[0], x[1]);
                plane.from_local(lat, lon)
            }
            _ => Matrix2::identity(),
        };
        let vm = kf::velocity(r * v_en, r * cov * r.transpose());
        match &mut self.state.imm {
            None => Outcome::Early,
            Some(imm) => match imm.prepare(dt) {
                // A velocity far outside the track's own: left out, not applied.
                prep if {
                    let (nu, s) = prep.combined().innovation(&vm);
                    !gate.admits(Gate::nis(&nu, &s))
                } =>
                {
                    Outcome::Gated
                }
                prep => match (prep.combined(), imm.update(&prep, &vm)) {
                    (pred, Some(step)) => {
                        if self.keep_gain {
                            self.gain = gain(&pred, &step.estimate).map(|a| (t, a));
                        }
                        Outcome::Applied { nis: 0.0 }
                    }
                    (_, None) => {
                        tracing::warn!("track filter went numerically bad on a velocity; restarting");
                        self.state.imm = None;
                        self.state.plane = None;
                        self.restarts += 1;
                        Outcome::Restarted
                    }
                },
            },
        }
    }
}
