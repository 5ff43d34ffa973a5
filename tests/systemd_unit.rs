//! The shipped systemd unit's system-call filter lets through every call the
//! service makes on purpose. A call the filter leaves out kills the service
//! with SIGSYS (or fails, with `SystemCallErrorNumber=`), and only on the
//! installed system: the unit once denied `@resources`, which holds
//! `sched_setscheduler`, the one call `realtime_priority` makes, while its
//! comment promised realtime scheduling up to priority 10.
//!
//! The groups are expanded by the system's own `systemd-analyze
//! syscall-filter`; the assignments are applied as systemd does: the first
//! sets the mode (an allow list unless it starts with `~`), each later one
//! adds to or takes from the set.

use std::collections::{BTreeMap, BTreeSet};
use std::process::Command;

/// The calls the service makes itself, beyond what any program needs: the
/// realtime request, turning huge pages off, receive stamps on sockets,
/// batched datagram reads, and the allocator's page advice.
const NEEDED: [&str; 6] = ["sched_setscheduler", "prctl", "setsockopt", "recvmmsg", "madvise", "mmap"];

fn groups() -> Option<BTreeMap<String, Vec<String>>> {
    let out = Command::new("systemd-analyze").arg("syscall-filter").output().ok()?;
    if !out.status.success() {
        return None;
    }
    let mut groups: BTreeMap<String, Vec<String>> = BTreeMap::new();
    let mut current = None;
    for line in String::from_utf8_lossy(&out.stdout).lines() {
        if line.starts_with('@') {
            current = Some(line.trim().to_string());
            groups.entry(line.trim().to_string()).or_default();
        } else if let (Some(g), item) = (&current, line.trim()) {
            if !item.is_empty() && !item.starts_with('#') {
                groups.get_mut(g).expect("entered").push(item.to_string());
            }
        }
    }
    Some(groups)
}

fn expand(item: &str, groups: &BTreeMap<String, Vec<String>>, into: &mut BTreeSet<String>) {
    match groups.get(item) {
        Some(members) => members.iter().for_each(|m| expand(m, groups, into)),
        None => {
            into.insert(item.to_string());
        }
    }
}

#[test]
fn the_units_syscall_filter_allows_what_the_service_calls() {
    let Some(groups) = groups() else {
        eprintln!("SKIP: systemd-analyze not available; the unit's filter not checked");
        return;
    };
    let unit =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/systemd/fuse1090.service")).unwrap();
    let mut allow_list = None;
    let mut set = BTreeSet::new();
    for value in unit.lines().filter_map(|l| l.trim().strip_prefix("SystemCallFilter=")) {
        let (deny, items) = match value.strip_prefix('~') {
            Some(rest) => (true, rest),
            None => (false, value),
        };
        let mut calls = BTreeSet::new();
        items.split_whitespace().for_each(|i| expand(i, &groups, &mut calls));
        let allow_mode = *allow_list.get_or_insert(!deny);
        if deny == allow_mode {
            set.retain(|c| !calls.contains(c));
        } else {
            set.extend(calls);
        }
    }
    let allow_mode = allow_list.expect("the unit filters system calls");
    let refused: Vec<&str> = NEEDED.iter().copied().filter(|c| set.contains(*c) != allow_mode).collect();
    assert!(refused.is_empty(), "the unit's filter refuses {refused:?}");
    // What the unit means to refuse stays refused (so the reading above is systemd's).
    for call in ["reboot", "setpriority", "init_module"] {
        assert!(set.contains(call) != allow_mode, "the unit's filter lets {call} through");
    }
}
