//! A small HTTP/1.1 server for pages served to a browser on the same machine (`view --serve`),
//! made so that no client can stall it or read it from another origin:
//!
//! - it listens on 127.0.0.1 only;
//! - each connection is served on its own thread, at most [`MAX_CLIENTS`] at once (more are
//!   answered `503` at once), so a silent or half-open client blocks nobody else;
//! - a request's line and headers must arrive within [`REQUEST_DEADLINE`] (`408` after) and fit
//!   in [`MAX_REQUEST_BYTES`] (`431` past it: nothing larger is buffered), and every read and
//!   write has a timeout;
//! - the `Host` header must name this machine's loopback (`localhost`, `127.0.0.1` or `[::1]`,
//!   with or without the port), else `403`: a web page the user visits cannot read the page
//!   through DNS rebinding, where its own host name is made to resolve to 127.0.0.1;
//! - only `GET` (and `HEAD`) of a path the handler knows is answered; one request per
//!   connection (`Connection: close`).

use anyhow::{Context, Result};
use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

/// Connections served at once.
pub const MAX_CLIENTS: usize = 32;

/// Largest request line plus headers, bytes.
pub const MAX_REQUEST_BYTES: usize = 16 * 1024;

/// Time a client has to send its whole request line and headers.
pub const REQUEST_DEADLINE: Duration = Duration::from_secs(5);

/// Timeout of each write of the response.
pub const WRITE_TIMEOUT: Duration = Duration::from_secs(10);

/// A response: status line text (`200 OK`), content type and body.
pub struct Response {
    /// Status code and reason, e.g. `200 OK`.
    pub status: &'static str,
    /// `Content-Type`.
    pub content_type: &'static str,
    /// The body.
    pub body: Arc<Vec<u8>>,
}

impl Response {
    fn empty(status: &'static str) -> Self {
        Self {
            status,
            content_type: "text/plain; charset=utf-8",
            body: Arc::new(status.as_bytes().to_vec()),
        }
    }
}

/// Answers a `GET` of `path` (the request target, query included), or `None` for `404`.
pub type Handler = dyn Fn(&str) -> Option<Response> + Send + Sync;

/// Binds 127.0.0.1:`port` (0: any free port).
pub fn bind(port: u16) -> Result<TcpListener> {
    TcpListener::bind(("127.0.0.1", port)).with_context(|| format!("binding 127.0.0.1:{port}"))
}

/// Serves `listener` with `handler` until the process ends.
pub fn serve(listener: TcpListener, handler: Arc<Handler>) -> Result<()> {
    let active = Arc::new(AtomicUsize::new(0));
    for stream in listener.incoming() {
        let Ok(mut stream) = stream else { continue };
        if active.fetch_add(1, Ordering::SeqCst) >= MAX_CLIENTS {
            active.fetch_sub(1, Ordering::SeqCst);
            let _ = stream.set_write_timeout(Some(WRITE_TIMEOUT));
            let _ = write_response(&mut stream, &Response::empty("503 Service Unavailable"), false);
            continue;
        }
        let (slot, handler) = (Arc::clone(&active), Arc::clone(&handler));
        let spawned = std::thread::Builder::new().name("bbsplat-http".into()).spawn(move || {
            answer(stream, &*handler);
            slot.fetch_sub(1, Ordering::SeqCst);
        });
        if spawned.is_err() {
            // No thread to serve it: the connection is dropped with the closure, and its slot is
            // given back here.
            active.fetch_sub(1, Ordering::SeqCst);
        }
    }
    Ok(())
}

/// Why a request head was not read.
enum HeadError {
    /// The client closed or broke the connection: nobody to answer.
    Gone,
    /// Answer with this status.
    Status(&'static str),
}

/// Reads the request line and headers of `stream` within the deadline and the size bound.
fn read_head(stream: &mut TcpStream) -> Result<Vec<u8>, HeadError> {
    let start = Instant::now();
    let mut head = Vec::with_capacity(1024);
    let mut chunk = [0u8; 2048];
    loop {
        let left = REQUEST_DEADLINE.saturating_sub(start.elapsed());
        if left.is_zero() {
            return Err(HeadError::Status("408 Request Timeout"));
        }
        stream
            .set_read_timeout(Some(left))
            .map_err(|_| HeadError::Status("500 Internal Server Error"))?;
        let n = match stream.read(&mut chunk) {
            Ok(0) => return Err(HeadError::Gone),
            Ok(n) => n,
            Err(e) if matches!(e.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut) => {
                return Err(HeadError::Status("408 Request Timeout"));
            }
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(_) => return Err(HeadError::Gone),
        };
        let searched_from = head.len().saturating_sub(3);
        head.extend_from_slice(&chunk[..n]);
        if let Some(end) = head[searched_from..].windows(4).position(|w| w == b"\r\n\r\n") {
            head.truncate(searched_from + end);
            return Ok(head);
        }
        if head.len() > MAX_REQUEST_BYTES {
            return Err(HeadError::Status("431 Request Header Fields Too Large"));
        }
    }
}

/// True when `host` (a `Host` header's value) names the loopback: `localhost`, `127.0.0.1` or
/// `[::1]`, with or without a port.
pub fn is_loopback_host(host: &str) -> bool {
    let host = host.trim();
    // The name and what follows it: nothing, or `:port`.
    let (name, rest) = match host.strip_prefix('[') {
        Some(bracketed) => match bracketed.split_once(']') {
            Some((inside, rest)) => (inside, rest),
            None => return false,
        },
        None => host.find(':').map_or((host, ""), |i| host.split_at(i)),
    };
    let port_ok = match rest.strip_prefix(':') {
        None => rest.is_empty(),
        Some(p) => !p.is_empty() && p.len() <= 5 && p.bytes().all(|b| b.is_ascii_digit()),
    };
    let loopback = if host.starts_with('[') {
        name == "::1"
    } else {
        name.eq_ignore_ascii_case("localhost") || name == "127.0.0.1"
    };
    port_ok && loopback
}

/// The response to a request head (request line and headers, without the blank line).
fn respond(head: &[u8], handler: &Handler) -> (Response, bool) {
    let Ok(text) = std::str::from_utf8(head) else {
        return (Response::empty("400 Bad Request"), false);
    };
    let mut lines = text.split("\r\n");
    let request_line = lines.next().unwrap_or_default();
    let mut parts = request_line.split(' ');
    let (method, target) = (parts.next().unwrap_or_default(), parts.next().unwrap_or_default());
    let hosts: Vec<&str> = lines
        .filter_map(|l| l.split_once(':'))
        .filter(|(name, _)| name.trim().eq_ignore_ascii_case("host"))
        .map(|(_, value)| value)
        .collect();
    let head_only = method == "HEAD";
    if hosts.len() != 1 || !is_loopback_host(hosts[0]) {
        return (Response::empty("403 Forbidden"), head_only);
    }
    if method != "GET" && !head_only {
        return (Response::empty("405 Method Not Allowed"), false);
    }
    match handler(target) {
        Some(response) => (response, head_only),
        None => (Response::empty("404 Not Found"), head_only),
    }
}

fn write_response(stream: &mut TcpStream, response: &Response, head_only: bool) -> std::io::Result<()> {
    let header = format!(
        "HTTP/1.1 {}\r\nContent-Type: {}\r\nContent-Length: {}\r\nCache-Control: no-store\r\nConnection: close\r\n\r\n",
        response.status,
        response.content_type,
        response.body.len()
    );
    stream.write_all(header.as_bytes())?;
    if !head_only {
        stream.write_all(&response.body)?;
    }
    stream.flush()
}

/// Serves one connection: one request, one response, then the connection is closed.
fn answer(mut stream: TcpStream, handler: &Handler) {
    if stream.set_write_timeout(Some(WRITE_TIMEOUT)).is_err() {
        return;
    }
    let (response, head_only) = match read_head(&mut stream) {
        Ok(head) => respond(&head, handler),
        Err(HeadError::Gone) => return,
        Err(HeadError::Status(status)) => (Response::empty(status), false),
    };
    let _ = write_response(&mut stream, &response, head_only);
    let _ = stream.shutdown(std::net::Shutdown::Both);
}
