//! `[alerts] post_url`: each alert's JSON POSTed to a plain-HTTP endpoint
//! (a webhook, a relay to a chat or a control room) on a thread of its
//! own, so that a slow or absent receiver never holds the twin up. A POST
//! that fails is said on stderr and dropped: the alert is still in the
//! MCAP output and on `--json`.

use std::io::{Read as _, Write as _};
use std::net::{TcpStream, ToSocketAddrs};
use std::sync::mpsc::{channel, Receiver, Sender};
use std::thread::JoinHandle;
use std::time::Duration;

use tortwin_engine::sink::{Alert, Sink, SinkResult};

/// How long a POST may take to connect, send and be answered.
const TIMEOUT: Duration = Duration::from_secs(5);

/// A [`Sink`] that POSTs every alert to `url`.
pub(crate) struct AlertPoster {
    to_thread: Option<Sender<String>>,
    thread: Option<JoinHandle<()>>,
}

impl AlertPoster {
    /// `url`: `http://HOST[:PORT][/PATH]` (checked by the configuration).
    pub(crate) fn start(url: &str) -> AlertPoster {
        let (to_thread, from_engine) = channel::<String>();
        let url = url.to_string();
        let thread = std::thread::Builder::new()
            .name("tortwin-alert-post".into())
            .spawn(move || post_all(&url, &from_engine))
            .ok();
        AlertPoster {
            to_thread: Some(to_thread),
            thread,
        }
    }
}

impl Drop for AlertPoster {
    fn drop(&mut self) {
        // The alerts queued are sent before the follower stops.
        drop(self.to_thread.take());
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl Sink for AlertPoster {
    fn alert(&mut self, alert: &Alert) -> SinkResult {
        let body = super::live::alert_line(alert)?;
        if let Some(tx) = &self.to_thread {
            let _ = tx.send(body);
        }
        Ok(())
    }
}

fn post_all(url: &str, bodies: &Receiver<String>) {
    for body in bodies {
        if let Err(e) = post(url, &body) {
            eprintln!("warning: POST of an alert to {url} failed: {e}");
        }
    }
}

/// One POST; `Ok` on a 2xx answer.
fn post(url: &str, body: &str) -> Result<(), String> {
    let rest = url.strip_prefix("http://").ok_or("not an http:// URL")?;
    let (authority, path) = match rest.find('/') {
        Some(i) => (&rest[..i], &rest[i..]),
        None => (rest, "/"),
    };
    let with_port = match authority.rsplit_once(':') {
        Some((_, port)) if port.parse::<u16>().is_ok() => authority.to_string(),
        _ => format!("{authority}:80"),
    };
    let address = with_port
        .to_socket_addrs()
        .map_err(|e| format!("{authority}: {e}"))?
        .next()
        .ok_or_else(|| format!("{authority}: no address"))?;
    let mut stream =
        TcpStream::connect_timeout(&address, TIMEOUT).map_err(|e| format!("connect: {e}"))?;
    stream
        .set_read_timeout(Some(TIMEOUT))
        .map_err(|e| e.to_string())?;
    stream
        .set_write_timeout(Some(TIMEOUT))
        .map_err(|e| e.to_string())?;
    let request = format!(
        "POST {path} HTTP/1.1\r\nHost: {authority}\r\nContent-Type: application/json\r\n\
         Content-Length: {}\r\nConnection: close\r\nUser-Agent: tortwin/{}\r\n\r\n{body}",
        body.len(),
        env!("CARGO_PKG_VERSION")
    );
    stream
        .write_all(request.as_bytes())
        .map_err(|e| format!("send: {e}"))?;
    let mut answer = Vec::new();
    let _ = stream.take(4096).read_to_end(&mut answer);
    let answer = String::from_utf8_lossy(&answer);
    let status = answer
        .lines()
        .next()
        .and_then(|l| l.split_whitespace().nth(1))
        .and_then(|s| s.parse::<u16>().ok())
        .ok_or("no HTTP answer")?;
    match status {
        200..=299 => Ok(()),
        s => Err(format!("the receiver answered {s}")),
    }
}
