//! `view --serve` as a hostile client meets it: silent and half-sent requests block nobody else
//! and are timed out, an endless request line is cut off instead of buffered, and only a
//! loopback `Host` is answered (no DNS rebinding).

use super::cli::{export_demo, temp, train_five_steps};
use std::io::{ErrorKind, Read, Write};
use std::net::TcpStream;
use std::process::{Child, Command, Stdio};
use std::time::Duration;

/// A running `view --serve` on a free port; killed when dropped.
struct Server {
    child: Child,
    address: String,
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn start(model: &std::path::Path, page: &std::path::Path) -> Server {
    let mut child = Command::new(env!("CARGO_BIN_EXE_bbsplat"))
        .args([
            "view",
            model.to_str().unwrap(),
            "-o",
            page.to_str().unwrap(),
            "--serve",
            "--port",
            "0",
        ])
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let lines = std::io::BufRead::lines(std::io::BufReader::new(child.stdout.take().unwrap()));
    let address = lines
        .map(|l| l.unwrap())
        .find_map(|l| {
            l.strip_prefix("serving on http://")
                .map(|r| r.split('/').next().unwrap().to_string())
        })
        .expect("the server prints its address");
    Server { child, address }
}

/// Sends `request` and reads the whole answer (the server closes after one response).
fn exchange(address: &str, request: &[u8]) -> Vec<u8> {
    let mut stream = TcpStream::connect(address).unwrap();
    stream.set_read_timeout(Some(Duration::from_secs(60))).unwrap();
    stream.write_all(request).unwrap();
    let mut response = Vec::new();
    stream.read_to_end(&mut response).unwrap();
    response
}

fn status(response: &[u8]) -> String {
    String::from_utf8_lossy(response)
        .lines()
        .next()
        .unwrap_or_default()
        .to_string()
}

#[test]
fn the_viewer_server_cannot_be_stalled_flooded_or_read_from_another_origin() {
    let root = temp("serve");
    let data = export_demo(&root, 16, 40);
    let model = train_five_steps(&data, &root.join("run"), 40);
    let page = root.join("view.html");
    let server = start(&model, &page);
    let address = server.address.clone();
    let port = address.rsplit(':').next().unwrap().to_string();
    let page_bytes = std::fs::read(&page).unwrap();

    // A silent client and one that stops halfway through its headers ...
    let mut silent = TcpStream::connect(&address).unwrap();
    let mut half = TcpStream::connect(&address).unwrap();
    half.write_all(b"GET / HTTP/1.1\r\nHost: local").unwrap();
    // ... do not keep a third from its page,
    let ok = exchange(&address, b"GET / HTTP/1.1\r\nHost: localhost\r\n\r\n");
    assert_eq!(status(&ok), "HTTP/1.1 200 OK");
    assert!(ok.ends_with(&page_bytes));
    // which was answered before either of them was (a server taking one client at a time
    // would have answered the silent one first, when its deadline ran out).
    silent.set_nonblocking(true).unwrap();
    let mut byte = [0u8; 1];
    assert_eq!(
        silent.read(&mut byte).map_err(|e| e.kind()),
        Err(ErrorKind::WouldBlock),
        "the silent client was answered before the good one"
    );
    silent.set_nonblocking(false).unwrap();
    // Both are answered 408 and closed once the request deadline has passed.
    for stream in [&mut silent, &mut half] {
        stream.set_read_timeout(Some(Duration::from_secs(60))).unwrap();
        let mut response = Vec::new();
        stream.read_to_end(&mut response).unwrap();
        assert_eq!(status(&response), "HTTP/1.1 408 Request Timeout");
    }

    // A request line without an end is cut off after a bounded size, not buffered whole: the
    // server closes the connection and the writes fail long before 64 MB are sent.
    let mut flood = TcpStream::connect(&address).unwrap();
    flood.set_write_timeout(Some(Duration::from_secs(60))).unwrap();
    flood.write_all(b"GET /").unwrap();
    let chunk = vec![b'a'; 64 * 1024];
    let sent = (0..1024).take_while(|_| flood.write_all(&chunk).is_ok()).count();
    assert!(sent < 1024, "all 64 MB of one request line were accepted");

    // Only a loopback Host is answered.
    for host in [
        "localhost",
        "LOCALHOST",
        "127.0.0.1",
        &format!("127.0.0.1:{port}"),
        &format!("localhost:{port}"),
    ] {
        let response = exchange(&address, format!("GET / HTTP/1.1\r\nHost: {host}\r\n\r\n").as_bytes());
        assert_eq!(status(&response), "HTTP/1.1 200 OK", "Host: {host}");
    }
    for request in [
        "GET / HTTP/1.1\r\nHost: attacker.example\r\n\r\n".to_string(),
        format!("GET / HTTP/1.1\r\nHost: attacker.example:{port}\r\n\r\n"),
        "GET / HTTP/1.1\r\nHost: localhost.attacker.example\r\n\r\n".to_string(),
        "GET / HTTP/1.1\r\nHost: 127.0.0.1.nip.io\r\n\r\n".to_string(),
        "GET / HTTP/1.1\r\nHost: [localhost]\r\n\r\n".to_string(),
        "GET / HTTP/1.1\r\nHost: localhost:80x\r\n\r\n".to_string(),
        "GET / HTTP/1.1\r\nHost: [::1]x\r\n\r\n".to_string(),
        "GET / HTTP/1.1\r\n\r\n".to_string(),
        "GET / HTTP/1.1\r\nHost: localhost\r\nHost: attacker.example\r\n\r\n".to_string(),
    ] {
        let response = exchange(&address, request.as_bytes());
        assert_eq!(status(&response), "HTTP/1.1 403 Forbidden", "{request:?}");
        assert!(!response.ends_with(&page_bytes));
    }
    let post = exchange(&address, b"POST / HTTP/1.1\r\nHost: localhost\r\n\r\n");
    assert_eq!(status(&post), "HTTP/1.1 405 Method Not Allowed");
    let other = exchange(&address, b"GET /../../etc/passwd HTTP/1.1\r\nHost: localhost\r\n\r\n");
    assert_eq!(status(&other), "HTTP/1.1 404 Not Found");
    // Still serving after all of that.
    let again = exchange(&address, b"GET /index.html?x=1 HTTP/1.1\r\nHost: localhost\r\n\r\n");
    assert!(again.ends_with(&page_bytes));
    drop(server);
    std::fs::remove_dir_all(&root).ok();
}
