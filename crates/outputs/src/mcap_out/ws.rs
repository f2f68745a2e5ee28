//! The MCAP output's channels served live over Foxglove's WebSocket
//! protocol (`tortwin live --foxglove`), with Foxglove's own SDK (the
//! `foxglove` crate): the Foxglove app connects to `ws://HOST:PORT` and
//! gets the same topics, schemas and message bytes the MCAP output holds,
//! so the shipped layout shows either.
//!
//! A viewer that connects late has missed `/twin/section` (written once, at
//! the recording's start): the server sends it the latest one when it
//! subscribes. Everything else comes with every train.

use std::sync::{Arc, Mutex, PoisonError};

use foxglove::websocket::{ChannelView, Client, ServerListener};
use foxglove::{Context, PartialMetadata, RawChannel, Schema, WebSocketServerHandle};

use super::Topic;

/// Messages queued per client before the oldest are dropped (a viewer too
/// slow to keep up loses old trains, not the twin's time). A train is
/// about ten messages; a field of a 1.5 km section about 60 kB.
const BACKLOG: usize = 4096;

/// How long a stopping server still serves its connected clients: a queue
/// of [`BACKLOG`] messages crosses a network in well under a second.
const LINGER: std::time::Duration = std::time::Duration::from_secs(2);

/// A Foxglove WebSocket server publishing the MCAP output's channels.
pub struct FoxgloveServer {
    address: String,
    host: String,
    context: Arc<Context>,
    handle: Option<WebSocketServerHandle>,
    shared: Arc<Shared>,
}

/// What the server and its listener share.
struct Shared {
    channels: Mutex<Channels>,
    /// The latest `/twin/section` message and its log_time.
    section: Mutex<Option<(Vec<u8>, u64)>>,
}

/// The advertised channels, in [`Topic::ALL`]'s order, and whether
/// `/twin/field` has a line's schema.
#[derive(Default)]
struct Channels {
    raw: Vec<Arc<RawChannel>>,
    line: bool,
}

/// The server could not start (the address is taken or not an address) or
/// advertise its channels.
#[derive(Debug, thiserror::Error)]
#[error("cannot serve Foxglove's WebSocket protocol on {address}: {reason}")]
pub struct FoxgloveServerError {
    pub address: String,
    pub reason: String,
}

impl FoxgloveServer {
    /// Listens on `address` (`HOST:PORT`; port 0 takes a free one, see
    /// [`FoxgloveServer::port`]) on a runtime of its own.
    pub fn start(address: &str) -> Result<FoxgloveServer, FoxgloveServerError> {
        let error = |reason: String| FoxgloveServerError {
            address: address.to_owned(),
            reason,
        };
        let (host, port) = address
            .rsplit_once(':')
            .ok_or_else(|| error("not HOST:PORT".to_owned()))?;
        let port: u16 = port
            .parse()
            .map_err(|_| error(format!("port {port:?} is not a number of 0 to 65535")))?;
        let host = host.trim_start_matches('[').trim_end_matches(']');
        let context = Context::new();
        let shared = Arc::new(Shared {
            channels: Mutex::new(Channels::default()),
            section: Mutex::new(None),
        });
        let version = env!("CARGO_PKG_VERSION");
        let handle = context
            .websocket_server()
            .name(format!("tortwin {version}"))
            .bind(host, port)
            .message_backlog_size(BACKLOG)
            .listener(shared.clone())
            .start_blocking()
            .map_err(|e| error(e.to_string()))?;
        let server = FoxgloveServer {
            address: address.to_owned(),
            host: host.to_owned(),
            context,
            handle: Some(handle),
            shared,
        };
        server.advertise(false)?;
        Ok(server)
    }

    /// Where clients connect: `ws://HOST:PORT`, with the port it took.
    pub fn url(&self) -> String {
        let port = self.handle.as_ref().map_or(0, WebSocketServerHandle::port);
        match self.host.contains(':') {
            true => format!("ws://[{}]:{port}", self.host),
            false => format!("ws://{}:{port}", self.host),
        }
    }

    /// Advertises the channels for a recording of a section, or of a line
    /// (`line`: `/twin/field` with a line's schema, [`super::LINE_FIELD_SCHEMA`]):
    /// all of them the first time (when the server starts, so that viewers
    /// can subscribe before the first recording), and `/twin/field` again
    /// when a recording of the other kind follows.
    pub fn advertise(&self, line: bool) -> Result<(), FoxgloveServerError> {
        let mut channels = lock(&self.shared.channels);
        if !channels.raw.is_empty() && channels.line == line {
            return Ok(());
        }
        let build = |topic: Topic| {
            self.context
                .channel_builder(topic.name())
                .message_encoding("json")
                .schema(Schema::new(
                    topic.schema_name(),
                    "jsonschema",
                    topic.schema(line).as_bytes(),
                ))
                .build_raw()
        };
        let result = if channels.raw.is_empty() {
            Topic::ALL
                .into_iter()
                .map(build)
                .collect::<Result<Vec<_>, _>>()
                .map(|raw| channels.raw = raw)
        } else {
            let field = Topic::Field as usize;
            channels.raw[field].close();
            build(Topic::Field).map(|raw| channels.raw[field] = raw)
        };
        // The server's own context holds only these channels, each topic
        // once (the old `/twin/field` is closed before its successor).
        result.map_err(|e| FoxgloveServerError {
            address: self.address.clone(),
            reason: format!("advertising the channels: {e}"),
        })?;
        channels.line = line;
        Ok(())
    }

    /// Sends a message, serialized as the MCAP output writes it, to the
    /// clients subscribed to its topic.
    pub(super) fn publish(&self, topic: Topic, log_time_ns: u64, json: &[u8]) {
        if topic == Topic::Section {
            *lock(&self.shared.section) = Some((json.to_vec(), log_time_ns));
        }
        let channels = lock(&self.shared.channels);
        if let Some(channel) = channels.raw.get(topic as usize) {
            channel.log_with_meta(json, PartialMetadata::with_log_time(log_time_ns));
        }
    }

    /// Stops serving: the clients are disconnected, after `LINGER` for
    /// them to take what is queued (the SDK's stop drops it).
    pub fn stop(mut self) {
        if let Some(handle) = self.handle.take() {
            if handle.client_count() > 0 {
                std::thread::sleep(LINGER);
            }
            handle.stop().wait_blocking();
        }
    }
}

impl Drop for FoxgloveServer {
    fn drop(&mut self) {
        if let Some(handle) = self.handle.take() {
            handle.stop().detach_all();
        }
    }
}

impl ServerListener for Shared {
    /// A viewer that subscribes to `/twin/section` gets the latest one.
    fn on_subscribe(&self, client: Client, channel: ChannelView) {
        if channel.topic() != Topic::Section.name() {
            return;
        }
        let section = lock(&self.section).clone();
        let channels = lock(&self.channels);
        if let (Some((json, log_time_ns)), Some(raw)) =
            (section, channels.raw.get(Topic::Section as usize))
        {
            raw.log_with_meta_to_sink(
                &json,
                PartialMetadata::with_log_time(log_time_ns),
                client.sink_id(),
            );
        }
    }
}

/// A lock whose holder panicked still holds consistent data here (whole
/// values are swapped in).
fn lock<T>(mutex: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    mutex.lock().unwrap_or_else(PoisonError::into_inner)
}
