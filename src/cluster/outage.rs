//! NATS away for a while (the server restarted, the network cut): every
//! role keeps what it holds and tries again, so that a short outage costs
//! the cluster time, not data and not its processes.
//!
//! The client reconnects by itself and keeps what is published meanwhile
//! in its own bounded buffer; what this module adds is the other half:
//! a store whose acknowledgement did not come is published again (its
//! message id makes a second copy of one already stored a no-op within the
//! streams' duplicate window), a key-value operation that failed is tried
//! again, and a consumer that failed is made again where it was. Each
//! keeps trying for [`OUTAGE`] of wall time from its first failure, backing
//! off, and only then fails its role (the process exits, for its supervisor
//! to restart; a worker's partitions are taken over meanwhile). Every try
//! again is counted ([`retries`]) and the first of an outage logged.

use std::fmt::Display;
use std::future::{Future, IntoFuture};
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use anyhow::{anyhow, Result};
use async_nats::jetstream::context::PublishError;
use async_nats::jetstream::publish::PublishAck;
use async_nats::jetstream::{self, consumer::pull, consumer::DeliverPolicy};
use async_nats::HeaderMap;
use bytes::Bytes;
use futures_util::StreamExt;

use super::Nats;

/// How long a role keeps trying while NATS is away before it gives up.
pub const OUTAGE: Duration = Duration::from_secs(60);

/// How long one try may take before it counts as failed: a request sent
/// into a connection that then broke gets no answer, and the client's own
/// timeout (5 s) is longer than a worker's lease.
pub const ATTEMPT: Duration = Duration::from_secs(2);

/// The first wait between tries, doubled up to [`LONGEST_WAIT`].
const FIRST_WAIT: Duration = Duration::from_millis(100);
const LONGEST_WAIT: Duration = Duration::from_secs(2);

static RETRIES: AtomicU64 = AtomicU64::new(0);
static DISCONNECTS: AtomicU64 = AtomicU64::new(0);

/// One operation that will be tried again (by its caller).
pub fn count_retry() {
    RETRIES.fetch_add(1, Ordering::Relaxed);
}

/// Operations this process tried again since it started.
pub fn retries() -> u64 {
    RETRIES.load(Ordering::Relaxed)
}

/// The client lost its connection (it reconnects by itself). Counted apart
/// from the retries: an outage shorter than a request's timeout costs no
/// retry (the client holds the request and sends it once connected), yet
/// the server may have aged out claims and registrations meanwhile.
pub fn count_disconnect() {
    DISCONNECTS.fetch_add(1, Ordering::Relaxed);
}

/// Times this process's client lost its connection since it started.
pub fn disconnects() -> u64 {
    DISCONNECTS.load(Ordering::Relaxed)
}

/// `op` until it succeeds, or fails for [`OUTAGE`] after its first failure.
pub async fn retry<T, E: Display, F: Future<Output = Result<T, E>>>(
    what: &str,
    mut op: impl FnMut() -> F,
) -> Result<T> {
    let mut since: Option<Instant> = None;
    let mut wait = FIRST_WAIT;
    loop {
        let error = match tokio::time::timeout(ATTEMPT, op()).await {
            Ok(Ok(v)) => {
                if let Some(t0) = since {
                    tracing::info!(after_s = t0.elapsed().as_secs_f64(), "{what}: NATS answers again");
                }
                return Ok(v);
            }
            Ok(Err(e)) => e.to_string(),
            Err(_) => format!("no answer within {} s", ATTEMPT.as_secs()),
        };
        let t0 = *since.get_or_insert_with(|| {
            tracing::warn!(error, "{what} failed: trying again for up to {} s", OUTAGE.as_secs());
            Instant::now()
        });
        if t0.elapsed() >= OUTAGE {
            return Err(anyhow!("{what}: NATS away for {} s: {error}", OUTAGE.as_secs()));
        }
        count_retry();
        tokio::time::sleep(wait).await;
        wait = (wait * 2).min(LONGEST_WAIT);
    }
}

/// A publication sent to a stream, its storage to be confirmed later (so
/// that many overlap), with what it takes to send it again. The wait for
/// its acknowledgement runs from when it was sent, on a task of its own:
/// awaited one after the other, the acknowledgements an outage lost each
/// took the client's whole timeout in turn (hundreds in flight, minutes).
pub struct Storing {
    subject: String,
    headers: HeaderMap,
    payload: Bytes,
    ack: tokio::task::JoinHandle<Result<PublishAck, PublishError>>,
}

impl Nats {
    /// Sends `payload` to `subject` with `headers` (which should hold a
    /// message id, so that sending again stores it once).
    pub async fn send(&self, subject: String, headers: HeaderMap, payload: Bytes) -> Result<Storing> {
        let ack = retry("publishing", || {
            self.js.publish_with_headers(subject.clone(), headers.clone(), payload.clone())
        })
        .await?;
        let ack = tokio::spawn(ack.into_future());
        Ok(Storing { subject, headers, payload, ack })
    }

    /// Sends and waits until stored.
    pub async fn store(&self, subject: String, headers: HeaderMap, payload: Bytes, what: &str) -> Result<()> {
        self.send(subject, headers, payload).await?.stored(self, what).await
    }
}

impl Storing {
    /// Waits until the stream has stored it, sending it again while its
    /// acknowledgement does not come.
    pub async fn stored(self, nats: &Nats, what: &str) -> Result<()> {
        let Storing { subject, headers, payload, ack } = self;
        if matches!(ack.await, Ok(Ok(_))) {
            return Ok(());
        }
        count_retry();
        retry(what, || async {
            nats.js.publish_with_headers(subject.clone(), headers.clone(), payload.clone()).await?.await
        })
        .await
        .map(drop)
    }
}

/// The messages of a pull consumer of `stream`, made again after the one
/// it follows failed, from the first message not yet handed out: exact
/// where the consumer acknowledges nothing (the clock, the publisher, the
/// receivers' declarations), whose server-side position may have passed
/// messages the failed client had fetched but not handed out.
pub struct Follow {
    stream: jetstream::stream::Stream,
    config: pull::Config,
    what: &'static str,
    /// The stream sequence of the first message not yet handed out.
    next_seq: Option<u64>,
    msgs: Option<pull::Stream>,
}

impl Follow {
    /// Starts following. With `fresh`, a durable consumer of that name is
    /// made anew from the configured start; without, one that exists
    /// carries on where it was.
    pub async fn start(
        stream: &jetstream::stream::Stream,
        config: pull::Config,
        fresh: bool,
        what: &'static str,
    ) -> Result<Follow> {
        let durable = config.durable_name.clone();
        let consumer = match (&durable, fresh) {
            (Some(name), false) => stream.get_or_create_consumer(name, config.clone()).await,
            (Some(name), true) => {
                let _ = stream.delete_consumer(name).await;
                stream.create_consumer(config.clone()).await
            }
            (None, _) => stream.create_consumer(config.clone()).await,
        };
        let consumer = consumer.map_err(|e| anyhow!("cannot consume {what}: {e}"))?;
        let msgs = pulls(&consumer).await.map_err(|e| anyhow!("cannot consume {what}: {e}"))?;
        Ok(Follow { stream: stream.clone(), config, what, next_seq: None, msgs: Some(msgs) })
    }

    /// The next message, or `None` when the stream of messages ends.
    pub async fn next(&mut self) -> Option<Result<jetstream::Message>> {
        loop {
            let msgs = match &mut self.msgs {
                Some(m) => m,
                None => match self.again().await {
                    Ok(m) => self.msgs.insert(m),
                    Err(e) => return Some(Err(e)),
                },
            };
            match msgs.next().await? {
                Ok(m) => {
                    if let Ok(info) = m.info() {
                        self.next_seq = Some(info.stream_sequence + 1);
                    }
                    return Some(Ok(m));
                }
                Err(e) => {
                    tracing::warn!(error = %e, "{}: consumer failed, making it again", self.what);
                    self.msgs = None;
                }
            }
        }
    }

    /// A consumer like the first, from the first message not handed out.
    async fn again(&self) -> Result<pull::Stream> {
        let mut config = self.config.clone();
        if let Some(seq) = self.next_seq {
            config.deliver_policy = DeliverPolicy::ByStartSequence { start_sequence: seq };
        }
        retry(self.what, || async {
            if let Some(name) = &config.durable_name {
                let _ = self.stream.delete_consumer(name).await;
            }
            let consumer = self.stream.create_consumer(config.clone()).await.map_err(anyhow::Error::from)?;
            pulls(&consumer).await.map_err(anyhow::Error::from)
        })
        .await
    }
}

/// A pull consumer's messages, each pull request short-lived: a request the
/// server forgot when it restarted is replaced within a second, and a
/// consumer that stopped answering (its heartbeats missing) fails within
/// two, where the client's defaults (30 s and 15 s) left a role waiting.
pub async fn pulls(
    consumer: &jetstream::consumer::PullConsumer,
) -> Result<pull::Stream, jetstream::consumer::StreamError> {
    consumer.stream().expires(PULL_EXPIRES).heartbeat(PULL_HEARTBEAT).messages().await
}

const PULL_EXPIRES: Duration = Duration::from_secs(1);
const PULL_HEARTBEAT: Duration = Duration::from_millis(500);
