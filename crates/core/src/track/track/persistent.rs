//! An error a measurement shares with the aircraft's next ones (a site's
//! learnt offset in time differences, an MLAT fix's clock synchronisation),
//! counted as often as the track's memory holds measurements.
//!
//! Counted once, a filter taking such measurements as independent averages
//! the shared error away and claims to know the aircraft better than it
//! does; counted once for every measurement sharing it, it is right only
//! for a filter that forgets nothing. How many a filter remembers follows
//! from how sure it already is along what is measured
//! ([`Persistent::memory`]), and differs by direction: where two hyperbolas
//! cross at a shallow angle, or where an ADS-B track knows the aircraft to
//! metres across track and less along it, one combination is remembered far
//! longer than the other. So the count is taken direction by direction, in
//! the basis where the fresh noise is the identity and the prior diagonal.

use nalgebra::SMatrix;

use super::Persistent;

/// The persistent error `once` (one measurement's share) counted as the
/// track's memory holds measurements, direction by direction, given the
/// fresh noise `fresh` and the track's prior `state` in the measurement's
/// space; `count(n)` is the persistent error counted `n` times (capped by
/// how many measurements share it). The fresh noise is not included.
pub(super) fn counted<const M: usize>(
    fresh: &SMatrix<f64, M, M>,
    state: &SMatrix<f64, M, M>,
    once: &SMatrix<f64, M, M>,
    count: impl Fn(f64) -> SMatrix<f64, M, M>,
) -> SMatrix<f64, M, M> {
    let Some((t, t_inv, s)) = directions(fresh, state) else {
        // Not separable (a singular noise): the traces, as one direction.
        return count(Persistent::memory(state.trace(), fresh.trace(), once.trace()));
    };
    // In the directions' basis the fresh noise is the identity.
    let b = t * once * t.transpose();
    let factor: [f64; M] = std::array::from_fn(|i| {
        if b[(i, i)] <= 0.0 {
            return 1.0;
        }
        let n = Persistent::memory(s[i], 1.0, b[(i, i)]);
        let c = t * count(n) * t.transpose();
        c[(i, i)] / b[(i, i)]
    });
    let d = SMatrix::<f64, M, M>::from_fn(|i, j| b[(i, j)] * (factor[i] * factor[j]).sqrt());
    t_inv * d * t_inv.transpose()
}

/// The basis in which the fresh noise `r` is the identity and the prior
/// `state` diagonal: the transform `t` (basis = t * measured), its
/// inverse, and the prior's variances there.
#[allow(clippy::type_complexity)]
fn directions<const M: usize>(
    r: &SMatrix<f64, M, M>,
    state: &SMatrix<f64, M, M>,
) -> Option<(SMatrix<f64, M, M>, SMatrix<f64, M, M>, [f64; M])> {
    let l_inv = r.cholesky()?.l().try_inverse()?;
    let (vectors, values) = symmetric_eigen(&(l_inv * state * l_inv.transpose()))?;
    let t = vectors.transpose() * l_inv;
    let t_inv = t.try_inverse()?;
    Some((t, t_inv, values))
}

/// Eigenvectors (columns) and eigenvalues of a symmetric 1x1 or 2x2 matrix.
#[allow(clippy::type_complexity)]
fn symmetric_eigen<const M: usize>(a: &SMatrix<f64, M, M>) -> Option<(SMatrix<f64, M, M>, [f64; M])> {
    match M {
        1 => Some((SMatrix::identity(), std::array::from_fn(|_| a[(0, 0)]))),
        2 => {
            let (p, q, s) = (a[(0, 0)], a[(0, 1)], a[(1, 1)]);
            let (mean, half) = ((p + s) / 2.0, ((p - s) / 2.0).hypot(q));
            let values = [mean + half, mean - half];
            // The first eigenvector at angle theta: tan 2 theta = 2q / (p - s).
            let theta = 0.5 * (2.0 * q).atan2(p - s);
            let (sn, cs) = theta.sin_cos();
            let v = SMatrix::<f64, M, M>::from_fn(|i, j| match (i, j) {
                (0, 0) | (1, 1) => cs,
                (1, 0) => sn,
                _ => -sn,
            });
            Some((v, std::array::from_fn(|i| values[i])))
        }
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Matrix2;

    #[test]
    fn a_symmetric_two_by_two_has_its_eigenvectors() {
        let a = Matrix2::new(5.0, 2.0, 2.0, 2.0);
        let (v, values) = symmetric_eigen(&a).unwrap();
        for (i, value) in values.iter().enumerate() {
            let x = v.column(i).into_owned();
            assert!((a * x - x * *value).norm() < 1e-12, "{i}: {x} {value}");
        }
        assert!(values[0] > values[1]);
    }
}
