//! The Haply Inverse Service stand-in (`fixtures/haply_service.py`) as a child process, for the
//! tests that need a service on loopback (`#[path]`-included; not every binary uses every item).
#![allow(dead_code)]

use std::io::{BufRead, BufReader};
use std::process::{Child, Command as Proc, Stdio};
use std::sync::mpsc::{channel, Receiver, RecvTimeoutError};
use std::time::Duration;

use coop_model::body::Vec3;

pub const SCRIPT: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/tests/fixtures/haply_service.py"
);
pub const WAIT: Duration = Duration::from_secs(10);

/// One line the mock printed.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    /// `FORCE x y z`: a force command reached it.
    Force(Vec3),
    /// `GARBAGE`: it is about to answer garbage.
    Garbage,
}

/// The mock service as a child process; killed (and reaped) on drop.
pub struct Service {
    child: Child,
    pub port: u16,
    pub events: Receiver<Event>,
}

impl Service {
    /// Starts it, or `None` (skip) when python3 lacks `websockets` and CI does not require it.
    pub fn start(args: &[&str]) -> Option<Self> {
        let mut child = Proc::new("python3")
            .arg(SCRIPT)
            .args(args)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("python3 runs");
        let mut out = BufReader::new(child.stdout.take().expect("stdout"));
        let mut first = String::new();
        out.read_line(&mut first)
            .expect("reading the mock's first line");
        let Some(port) = first.trim().strip_prefix("PORT ") else {
            let status = child.wait().expect("mock exits");
            assert_eq!(status.code(), Some(2), "mock failed to start: {first:?}");
            assert!(
                std::env::var_os("COOP_REQUIRE_MCAP_PY").is_none(),
                "python3 with websockets is required (pip install websockets)"
            );
            eprintln!("SKIPPED: python3 -c 'import websockets' fails");
            return None;
        };
        let port = port.parse().expect("a port");
        let (tx, events) = channel();
        std::thread::spawn(move || {
            for line in out.lines() {
                let Ok(line) = line else { break };
                let ev = if line == "GARBAGE" {
                    Event::Garbage
                } else if let Some(f) = line.strip_prefix("FORCE ") {
                    let v: Vec<f64> = f.split(' ').map(|x| x.parse().expect("a number")).collect();
                    Event::Force(Vec3::new(v[0], v[1], v[2]))
                } else {
                    continue;
                };
                if tx.send(ev).is_err() {
                    break;
                }
            }
        });
        Some(Self {
            child,
            port,
            events,
        })
    }

    pub fn url(&self) -> String {
        format!("ws://127.0.0.1:{}", self.port)
    }

    /// Waits for the next event, failing the test after `WAIT`.
    pub fn next(&self) -> Event {
        match self.events.recv_timeout(WAIT) {
            Ok(e) => e,
            Err(RecvTimeoutError::Timeout) => panic!("the mock printed nothing for {WAIT:?}"),
            Err(RecvTimeoutError::Disconnected) => panic!("the mock's output ended"),
        }
    }

    /// Waits until the mock reports receiving force `f`; returns the forces before it.
    pub fn wait_force(&self, f: Vec3) -> Vec<Vec3> {
        let mut before = Vec::new();
        loop {
            match self.next() {
                Event::Force(g) if g == f => return before,
                Event::Force(g) => before.push(g),
                Event::Garbage => {}
            }
        }
    }

    pub fn signal(&self, sig: &str) {
        let ok = Proc::new("kill")
            .args([sig, &self.child.id().to_string()])
            .status()
            .expect("kill runs")
            .success();
        assert!(ok, "kill {sig}");
    }

    pub fn kill(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Drop for Service {
    fn drop(&mut self) {
        self.signal_quiet();
        self.kill();
    }
}

impl Service {
    fn signal_quiet(&self) {
        let _ = Proc::new("kill")
            .args(["-CONT", &self.child.id().to_string()])
            .stderr(Stdio::null())
            .status();
    }
}
