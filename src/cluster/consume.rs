//! A claimed partition's frame batches, read from JetStream for the
//! worker's processing: one durable pull consumer per partition, made again
//! from the acknowledgement floor whenever the partition changes hands or
//! the consumer fails, so that what a lost worker had in hand comes first.

use std::sync::mpsc;
use std::sync::Arc;
use std::time::Duration;

use anyhow::{Context, Result};
use async_nats::jetstream::consumer::{pull, AckPolicy, DeliverPolicy};
use futures_util::StreamExt;

use super::worker::{Batch, ToCore};
use super::{header, ClusterConfig, Nats};

/// Consumes a claimed partition until told to stop; a consumer that fails
/// (NATS lost a while, the consumer deleted) is made again a second later
/// from the acknowledgement floor: a partition left claimed but unread
/// would hold the whole cluster back (the clock waits for it).
pub(super) async fn keep_consuming(
    nats: Arc<Nats>,
    cfg: ClusterConfig,
    p: u32,
    to_core: mpsc::Sender<ToCore>,
    stop: tokio::sync::watch::Receiver<bool>,
) {
    while !*stop.borrow() {
        match consume(nats.clone(), cfg.clone(), p, to_core.clone(), stop.clone()).await {
            Ok(()) => return,
            Err(e) => tracing::error!(partition = p, "partition consumer failed, starting again: {e:#}"),
        }
        tokio::time::sleep(Duration::from_secs(1)).await;
    }
}

/// A claimed partition's batches, in order from the first not acknowledged:
/// the durable consumer is made again from its acknowledgement floor, so
/// the batches a lost worker had in hand come first, not after ack_wait.
async fn consume(
    nats: Arc<Nats>,
    cfg: ClusterConfig,
    p: u32,
    to_core: mpsc::Sender<ToCore>,
    mut stop: tokio::sync::watch::Receiver<bool>,
) -> Result<()> {
    let name = format!("{}-part-{p}", cfg.name);
    let floor = match nats.frames.consumer_info(&name).await {
        Ok(info) => Some(info.ack_floor.stream_sequence),
        Err(_) => None,
    };
    let deliver_policy = match floor {
        Some(f) if f > 0 => DeliverPolicy::ByStartSequence { start_sequence: f + 1 },
        _ => DeliverPolicy::All,
    };
    if floor.is_some() {
        nats.frames.delete_consumer(&name).await.context("cannot reset a taken-over partition's consumer")?;
    }
    let consumer = nats
        .frames
        .create_consumer(pull::Config {
            durable_name: Some(name.clone()),
            filter_subject: nats.names.frames(p),
            ack_policy: AckPolicy::Explicit,
            ack_wait: Duration::from_secs_f64(cfg.lease_s * 10.0),
            // Beyond the ingest's publications in flight: a batch that
            // NATS lost and the ingest sent again comes after that many
            // later ones, which wait for it unacknowledged.
            max_ack_pending: 1024,
            deliver_policy,
            ..Default::default()
        })
        .await
        .with_context(|| format!("cannot consume partition {p}"))?;
    let mut msgs = super::outage::pulls(&consumer).await?;
    loop {
        tokio::select! {
            // Told already (the claim lost while this consumer was being
            // made) counts too: `changed` waits for the next telling, and
            // a consumer left running after its claim went to another
            // worker fought that worker's consumer for the partition.
            _ = async { stop.wait_for(|stopped| *stopped).await.is_ok() } => return Ok(()),
            m = msgs.next() => {
                let Some(m) = m else { return Ok(()) };
                let m = m.map_err(|e| anyhow::anyhow!("partition {p}: {e}"))?;
                let t = super::header_f64(&m.message, header::TIME).unwrap_or(f64::NAN);
                let receivers = super::header_f64(&m.message, header::RECEIVERS).unwrap_or(0.0) as usize;
                let end = super::is_end(&m.message);
                if !t.is_finite() {
                    tracing::warn!(partition = p, "frame batch without its time: skipped");
                    m.ack().await.map_err(|e| anyhow::anyhow!("ack: {e}"))?;
                    if to_core.send(ToCore::Bad).is_err() {
                        return Ok(());
                    }
                    continue;
                }
                let seq = m.info().map_or(0, |i| i.stream_sequence);
                if to_core.send(ToCore::Batch(Box::new(Batch { p, seq, t, receivers, end, msg: m }))).is_err() {
                    return Ok(());
                }
            }
        }
    }
}
