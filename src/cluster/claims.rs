//! Which partitions a worker holds: claimed, renewed, taken over from a
//! worker that stopped renewing, and handed back to one that joined.
//!
//! A claim is a key created only if absent and renewed at its revision, so
//! two workers never hold one partition. Each worker holds up to its share
//! of the partitions among the live workers (registered, renewed like the
//! claims). When a worker joins, the share falls, and each worker above it
//! hands its highest partitions back: it stops consuming them, its
//! processing drops their cores and checkpoints their track numbers, their
//! results are stored and acknowledged, and only then is the claim deleted
//! (at the revision it last renewed, so a claim that went to another worker
//! meanwhile is never deleted). Until then the claim is renewed: a partition
//! being handed back is nobody else's yet. The new holder's consumer starts
//! from the acknowledgement floor, so nothing is lost and nothing done twice
//! but what was in flight.

use std::collections::HashMap;
use std::sync::mpsc;
use std::time::Duration;

use anyhow::{Context, Result};
use async_nats::jetstream::kv;
use futures_util::StreamExt;

use super::consume::keep_consuming;
use super::outage::retry;
use super::wire::{self, Checkpoint};
use super::worker::ToCore;
use super::{ClusterConfig, Nats};

/// The processing's word that a partition handed back has its results
/// stored and acknowledged: its claim may go.
pub(super) type Handed = tokio::sync::mpsc::UnboundedReceiver<u32>;

/// Claims partitions, renews the claims, consumes the claimed ones, and
/// hands back those above the worker's share.
pub(super) async fn claim_partitions(
    nats: std::sync::Arc<Nats>,
    cfg: ClusterConfig,
    id: String,
    to_core: mpsc::Sender<ToCore>,
    mut handed: Handed,
) -> Result<()> {
    let every = Duration::from_secs_f64(cfg.lease_s / 3.0);
    // Registered a while before claiming, so that workers started together share evenly.
    retry("registering the worker", || nats.workers.put(&id, id.clone().into())).await?;
    tokio::time::sleep(every * 2).await;
    let mut owned: Owned = HashMap::new();
    // Partitions being handed back, at their claims' revisions.
    let mut leaving: HashMap<u32, u64> = HashMap::new();
    let mut tick = tokio::time::interval(every);
    // After NATS was away, every claim and registration may have aged out
    // on the server: two leases of quiet in which each worker takes back
    // its own before any claims more (the first back would count itself
    // alone and take every partition, the others' cores thrown away). An
    // outage shows as a retry, or as a lost connection where none was
    // needed (the client held the requests until it was back).
    let outages = || super::outage::retries() + super::outage::disconnects();
    let (mut outages_seen, mut quiet_until) = (outages(), tokio::time::Instant::now());
    loop {
        tokio::select! {
            _ = tick.tick() => {}
            p = handed.recv() => {
                let Some(p) = p else { return Ok(()) };
                if let Some(rev) = leaving.remove(&p) {
                    let key = p.to_string();
                    match nats.claims.delete_expect_revision(&key, Some(rev)).await {
                        Ok(()) => tracing::info!(partition = p, worker = %id, "partition handed back"),
                        // Taken meanwhile (it aged out): the taker holds it.
                        Err(e) => tracing::warn!(partition = p, error = %e, "handed-back claim not deleted"),
                    }
                }
                continue;
            }
        }
        retry("renewing the worker's registration", || nats.workers.put(&id, id.clone().into())).await?;
        let lost = renew_all(&nats, &id, &mut owned, &mut leaving).await;
        if outages() != outages_seen {
            outages_seen = outages();
            quiet_until = tokio::time::Instant::now() + Duration::from_secs_f64(2.0 * cfg.lease_s);
        }
        for p in lost {
            leaving.remove(&p);
            if let Some((_, stop)) = owned.remove(&p) {
                let _ = stop.send(true);
            }
            let _ = to_core.send(ToCore::Drop(p));
        }
        if tokio::time::Instant::now() < quiet_until {
            continue;
        }
        let live = retry("listing the workers", || count_keys(&nats.workers)).await?.max(1) as u32;
        let share = cfg.partitions.div_ceil(live) as usize;
        hand_back(&mut owned, &mut leaving, share, &to_core, &id);
        claim_more(&nats, &cfg, &id, share, &mut owned, &leaving, &to_core).await;
    }
}

/// The partitions a worker owns: each one's claim revision and its
/// consumer's stop.
type Owned = HashMap<u32, (u64, tokio::sync::watch::Sender<bool>)>;

/// Every claim held renewed; returns those found taken by another worker.
async fn renew_all(nats: &Nats, id: &str, owned: &mut Owned, leaving: &mut HashMap<u32, u64>) -> Vec<u32> {
    let mut lost = Vec::new();
    let held =
        owned.iter_mut().map(|(&p, (rev, _))| (p, rev)).chain(leaving.iter_mut().map(|(&p, r)| (p, r)));
    for (p, rev) in held {
        match tokio::time::timeout(super::outage::ATTEMPT, renew(nats, p, id, *rev)).await {
            Ok(Ok(Some(r))) => *rev = r,
            Ok(Err(e)) => {
                tracing::warn!(partition = p, error = %e, "partition claim lost");
                lost.push(p);
            }
            // No answer is not a refusal: kept, and renewed next time
            // (or found taken then).
            Ok(Ok(None)) | Err(_) => super::outage::count_retry(),
        }
    }
    lost
}

/// Unclaimed partitions claimed, lowest first, up to `share` held (those
/// being handed back counted), each with its checkpoint and a consumer.
async fn claim_more(
    nats: &std::sync::Arc<Nats>,
    cfg: &ClusterConfig,
    id: &str,
    share: usize,
    owned: &mut Owned,
    leaving: &HashMap<u32, u64>,
    to_core: &mpsc::Sender<ToCore>,
) {
    for p in 0..cfg.partitions {
        if owned.len() + leaving.len() >= share {
            break;
        }
        if owned.contains_key(&p) || leaving.contains_key(&p) {
            continue;
        }
        if let Ok(rev) = nats.claims.create(p.to_string(), id.to_string().into()).await {
            let cp = match nats.checkpoints.get(p.to_string()).await {
                Ok(Some(b)) => wire::decode::<Checkpoint>(&b).unwrap_or_default(),
                _ => Checkpoint::default(),
            };
            let _ = to_core.send(ToCore::Take(p, cp));
            let (stop_tx, stop_rx) = tokio::sync::watch::channel(false);
            tokio::spawn(keep_consuming(nats.clone(), cfg.clone(), p, to_core.clone(), stop_rx));
            owned.insert(p, (rev, stop_tx));
            tracing::info!(partition = p, worker = %id, "partition claimed");
        }
    }
}

/// The partitions above `share`, highest first, stop being consumed and go
/// to the processing to be handed back; their claims stay (renewed) until
/// the processing says their results are stored.
fn hand_back(
    owned: &mut Owned,
    leaving: &mut HashMap<u32, u64>,
    share: usize,
    to_core: &mpsc::Sender<ToCore>,
    id: &str,
) {
    let excess = owned.len().saturating_sub(share);
    let mut mine: Vec<u32> = owned.keys().copied().collect();
    mine.sort_unstable();
    for p in mine.into_iter().rev().take(excess) {
        let (rev, stop) = owned.remove(&p).expect("owned");
        let _ = stop.send(true);
        leaving.insert(p, rev);
        let _ = to_core.send(ToCore::Release(p));
        tracing::info!(partition = p, worker = %id, share, "handing a partition back: a worker joined");
    }
}

/// A claim renewed at its revision; or, when it has aged out on the server
/// (NATS away longer than the lease) and nobody took it meanwhile, made
/// again, so the partition keeps its worker and its tracks. `None` when
/// NATS could not say who holds it: kept, and renewed next time.
async fn renew(nats: &Nats, p: u32, id: &str, rev: u64) -> Result<Option<u64>> {
    let refused = match nats.claims.update(p.to_string(), id.to_string().into(), rev).await {
        Ok(r) => return Ok(Some(r)),
        Err(e) => e,
    };
    let Ok(entry) = nats.claims.entry(p.to_string()).await else { return Ok(None) };
    match entry.filter(|en| en.operation == kv::Operation::Put) {
        // Aged out (or deleted): nobody holds it.
        None => Ok(Some(nats.claims.create(p.to_string(), id.to_string().into()).await?)),
        // Still ours, at a revision the server kept (one from before it restarted).
        Some(en) if en.value.as_ref() == id.as_bytes() => {
            Ok(Some(nats.claims.update(p.to_string(), id.to_string().into(), en.revision).await?))
        }
        Some(_) => Err(refused.into()),
    }
}

async fn count_keys(store: &kv::Store) -> Result<usize> {
    let mut keys = store.keys().await.context("cannot list the workers")?;
    let mut n = 0;
    while let Some(k) = keys.next().await {
        k.context("listing the workers")?;
        n += 1;
    }
    Ok(n)
}
