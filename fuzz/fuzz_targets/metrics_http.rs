//! Fuzz target: arbitrary bytes as what a client sends to the HTTP server
//! (`/metrics`, the `/data/` documents and the map's files), served over an
//! in-memory stream by the same connection code as a socket; whatever comes
//! back is read to the end. It must never panic or hang (the client's side
//! is closed after the bytes).
#![no_main]

use libfuzzer_sys::fuzz_target;
use tokio::io::{AsyncReadExt, AsyncWriteExt};

fuzz_target!(|data: &[u8]| {
    let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
    let handle = metrics_exporter_prometheus::PrometheusBuilder::new().build_recorder().handle();
    rt.block_on(async {
        let (mut client, server) = tokio::io::duplex(64 * 1024);
        let routes = fuse1090::live::http::Routes {
            metrics: Some(handle),
            web: Some(std::sync::Arc::new(fuse1090::live::web::WebData::default())),
        };
        let served = tokio::spawn(fuse1090::live::http::connection(server, std::sync::Arc::new(routes)));
        let _ = client.write_all(data).await;
        let _ = client.shutdown().await;
        let mut answer = Vec::new();
        let _ = client.read_to_end(&mut answer).await;
        let _ = served.await;
    });
});
