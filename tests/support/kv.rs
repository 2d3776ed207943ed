//! A JetStream key-value bucket opened by a plain NATS client, outside the binary: what the
//! NATS tests read (and, for the spec channel's, write as someone without the operator's key
//! could) to check what the processes left in their buckets.

use async_nats::jetstream::kv::Store;

/// Run `f` on bucket `bucket` of the server at `addr` (`127.0.0.1:PORT` or a `nats://` URL),
/// on a runtime of its own.
pub fn with_bucket<T>(addr: &str, bucket: &str, f: impl AsyncFnOnce(Store) -> T) -> T {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    rt.block_on(async {
        let client = async_nats::connect(addr).await.unwrap();
        let kv = async_nats::jetstream::new(client)
            .get_key_value(bucket)
            .await
            .unwrap();
        f(kv).await
    })
}

/// Every live key of `kv`, sorted.
pub async fn keys(kv: &Store) -> Vec<String> {
    use futures_util::StreamExt;
    let mut keys: Vec<String> = kv
        .keys()
        .await
        .unwrap()
        .filter_map(|k| async { k.ok() })
        .collect()
        .await;
    keys.sort();
    keys
}
