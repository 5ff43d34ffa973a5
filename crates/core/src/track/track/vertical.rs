//! The vertical channel: height and climb rate in a two-state Kalman
//! filter of its own, beside the horizontal IMM (heights come from other
//! sources and at other times than positions, and a barometric height's
//! bias must not leak into the plane).

use super::*;

/// Vertical channel: WGS-84 height and climb rate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Vertical {
    pub x: Vector2<f64>,
    pub p: Matrix2<f64>,
    /// Heights left out by the gate since the last one taken.
    gated_heights: u8,
}

impl Vertical {
    pub(super) fn predict(&mut self, dt: f64, q: f64) {
        let f = Matrix2::new(1.0, dt, 0.0, 1.0);
        let qm = Matrix2::new(dt.powi(3) / 3.0, dt * dt / 2.0, dt * dt / 2.0, dt) * q;
        self.x = f * self.x;
        self.p = f * self.p * f.transpose() + qm;
    }

    pub(super) fn new(h: f64, var: f64) -> Vertical {
        Vertical { x: Vector2::new(h, 0.0), p: Matrix2::new(var, 0.0, 0.0, 25.0), gated_heights: 0 }
    }

    /// Applies a height (row 0) or climb rate (row 1); an outlier beyond the
    /// 4.5-sigma gate is left out. Heights gated `VERTICAL_RESTART` times in
    /// a row start the channel again on the newest: an aircraft levelling
    /// off or starting a climb without climb rates to say so (Mode S only)
    /// leaves a channel that believed its precise heights behind, and
    /// without a restart it never came back (tma-busy with the region's
    /// GNSS-baro difference, 8 m heights: a kilometre off for minutes).
    /// Returns whether it was taken.
    pub(super) fn update(&mut self, row: usize, z: f64, var: f64) -> bool {
        let s = self.p[(row, row)] + var;
        let nu = z - self.x[row];
        if !(s > 0.0 && s.is_finite()) || nu * nu / s > 4.5 * 4.5 {
            if row == 0 {
                self.gated_heights += 1;
                if self.gated_heights >= VERTICAL_RESTART {
                    *self = Vertical::new(z, var);
                }
            }
            return false;
        }
        if row == 0 {
            self.gated_heights = 0;
        }
        let k = self.p.column(row) / s;
        self.x += k * nu;
        let ikh = Matrix2::identity()
            - k * Vector2::new((row == 0) as u8 as f64, (row == 1) as u8 as f64).transpose();
        self.p = ikh * self.p * ikh.transpose() + k * var * k.transpose();
        true
    }
}

impl Track {
    /// A vertical measurement: height (row 0) or climb rate (row 1).
    ///
    /// Heights as uncertain as a barometric altitude without the GNSS
    /// difference carry an offset that persists (pressure, temperature):
    /// averaging many of them would not remove it, so they only keep the
    /// channel within their own uncertainty, never below it.
    /// Returns whether the channel took it (a climb rate beyond the gate,
    /// or before any height, is not).
    pub(super) fn vertical(&mut self, t: f64, row: usize, z: f64, var: f64) -> bool {
        let taken = match &mut self.state.vertical {
            Some(v) => {
                v.predict(t - self.state.t_v, self.cfg.vertical_q);
                // A biased height kept out is not an outlier.
                (row == 0 && var >= BIASED_HEIGHT_VAR && v.p[(0, 0)] < var) || v.update(row, z, var)
            }
            None if row == 0 => {
                self.state.vertical = Some(Vertical::new(z, var));
                true
            }
            None => return false,
        };
        self.state.t_v = t;
        taken
    }
}
