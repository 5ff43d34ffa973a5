use super::*;

#[test]
fn inverse_edges_hold_across_distant_epochs_and_large_drift() {
    // Receiver 1's clock runs 100 ppm fast and its local time is 5,000 s
    // ahead of receiver 0's: converting 1 -> 0 must not depend on which
    // index is lower.
    let mut s = ClockSync::new(PairParams::default());
    s.add_receiver(ClockKind::Beast12, "b");
    s.add_receiver(ClockKind::Beast12, "b");
    let clock1 = |t0: f64| 5000.0 + t0 * (1.0 + 100e-6);
    let g = [0.0; 4];
    for k in 0..20 {
        let t0 = 100.0 + k as f64 * 0.5;
        s.observe(
            &[LocalCopy { rx: 0, t: t0 }, LocalCopy { rx: 1, t: clock1(t0) }],
            &[0.0; 2],
            &[1e-18; 2],
            &g,
            t0,
        );
    }
    let t0 = 111.0;
    for copies in [
        [LocalCopy { rx: 0, t: t0 }, LocalCopy { rx: 1, t: clock1(t0) }],
        [LocalCopy { rx: 1, t: clock1(t0) }, LocalCopy { rx: 0, t: t0 }],
    ] {
        let (times, root) = s.common_time(&copies, t0);
        let (a, b) = (times[0].unwrap().0, times[1].unwrap().0);
        assert!((a - b).abs() < 1e-9, "root {root}: {a} vs {b}");
    }
}

#[test]
fn gps_peers_are_the_gps_receivers_a_receiver_shares_pairs_with() {
    // 0 and 3 GPS-timed, 1 and 2 counter-timed, 4 counter-timed and heard
    // with no GPS receiver.
    let mut s = ClockSync::new(PairParams::default());
    for c in [ClockKind::Gps, ClockKind::Beast12, ClockKind::Beast12, ClockKind::Gps, ClockKind::Beast12] {
        s.add_receiver(c, "r");
    }
    let copies = |rxs: &[usize]| rxs.iter().map(|&rx| LocalCopy { rx, t: 10.0 }).collect::<Vec<_>>();
    for (k, rxs) in [vec![3, 1], vec![2, 0, 1], vec![1, 3], vec![4, 2]].into_iter().enumerate() {
        let n = rxs.len();
        s.observe(&copies(&rxs), &vec![0.0; n], &vec![1e-18; n], &vec![0.0; n * n], 10.0 + k as f64);
    }
    assert_eq!(s.gps_peers(1), &[0, 3]);
    assert_eq!(s.gps_peers(2), &[0]);
    assert_eq!(s.gps_peers(4), &[] as &[usize]);
    // A GPS receiver's own list holds no GPS receiver: their pairs are not filtered.
    assert_eq!(s.gps_peers(0), &[] as &[usize]);
    // A restart drops the receiver's pairs, and it from the others' lists.
    s.reset_receiver(0);
    assert_eq!(s.gps_peers(1), &[3]);
    assert_eq!(s.gps_peers(2), &[] as &[usize]);
    s.reset_receiver(1);
    assert_eq!(s.gps_peers(1), &[] as &[usize]);
}

#[test]
fn a_reference_share_is_the_aircrafts_share_of_recent_sync() {
    let mut r = Reference::default();
    // One aircraft only: known as the whole of it from the first.
    r.note(7);
    assert_eq!(r.share_of(7), 1.0);
    for _ in 0..50 {
        r.note(7);
    }
    assert_eq!((r.share_of(7), r.share_of(8)), (1.0, 0.0));
    // Then two in turn: each about half.
    for _ in 0..100 {
        r.note(8);
        r.note(7);
    }
    assert!((r.share_of(7) - 0.5).abs() < 0.05, "{r:?}");
    // Then another alone: the first forgotten within the memory.
    for _ in 0..40 {
        r.note(9);
    }
    assert!(r.share_of(9) > 0.8 && r.share_of(7) < 0.1, "{r:?}");
    // Many aircraft in turn: none stands out.
    for k in 0..200 {
        r.note(100 + k % 10);
    }
    assert!((0..10).all(|k| r.share_of(100 + k) < 0.25), "{r:?}");
}

#[test]
fn a_chain_of_pairs_puts_everyone_on_the_gps_clock() {
    let mut s = ClockSync::new(PairParams::default());
    s.add_receiver(ClockKind::Beast12, "b"); // 0: offset +100 s from true time
    s.add_receiver(ClockKind::Gps, "g"); // 1
    s.add_receiver(ClockKind::Beast12, "b"); // 2: offset -50 s
    let offsets = [100.0, 0.0, -50.0];
    let var = [1e-16; 3];
    let g = [0.0; 9];
    // Sync transmissions at equal range: times are true time plus offset.
    for k in 0..10 {
        let t = 1000.0 + k as f64;
        let copies: Vec<LocalCopy> = (0..3).map(|r| LocalCopy { rx: r, t: t + offsets[r] }).collect();
        s.observe(&copies, &[1000.0; 3], &var, &g, t);
    }
    let t = 1010.5;
    let copies: Vec<LocalCopy> =
        (0..3).map(|r| LocalCopy { rx: r, t: t + offsets[r] + r as f64 * 1e-6 }).collect();
    let (times, root) = s.common_time(&copies, t);
    assert_eq!(copies[root].rx, 1, "the GPS receiver is the root");
    for (r, x) in times.iter().enumerate() {
        let (tt, v) = x.unwrap();
        assert!((tt - (t + r as f64 * 1e-6)).abs() < 1e-9, "{r}: {tt}");
        assert!(v < 1e-15);
    }
    assert_eq!(s.stats.outliers, 0);
}

#[test]
fn a_counter_reached_through_either_gps_receiver_gets_the_same_network_time() {
    // Two GPS receivers with biases of +250 ns and -300 ns, learnt; a
    // counter synchronised with each. Its time must not depend on which
    // of them the tree reaches it through, nor on which is the root.
    let mut s = ClockSync::new(PairParams::default());
    s.add_receiver(ClockKind::Gps, "g1");
    s.add_receiver(ClockKind::Gps, "g2");
    s.add_receiver(ClockKind::Beast12, "c");
    let clock = [250e-9, -300e-9, 40.0];
    s.set_gps_bias(0, clock[0]);
    s.set_gps_bias(1, clock[1]);
    s.set_gps_bias(2, 1.0);
    assert_eq!(s.gps_bias(2), 0.0, "a counter has no GPS bias");
    let var = [1e-18; 3];
    let g = [0.0; 9];
    for k in 0..10 {
        let t = 1000.0 + k as f64;
        let copies: Vec<LocalCopy> = (0..3).map(|r| LocalCopy { rx: r, t: t + clock[r] }).collect();
        s.observe(&copies, &[1000.0; 3], &var, &g, t);
    }
    let t = 1010.5;
    for pair in [[0, 2], [1, 2], [0, 1]] {
        let copies: Vec<LocalCopy> = pair.iter().map(|&r| LocalCopy { rx: r, t: t + clock[r] }).collect();
        let (times, _) = s.common_time(&copies, t);
        for (c, x) in copies.iter().zip(&times) {
            let (tt, _) = x.unwrap();
            assert!((tt - t).abs() < 1e-10, "receiver {} through {pair:?}: off by {:e} s", c.rx, tt - t);
        }
    }
}
