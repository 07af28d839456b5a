//! The study runner's web page (loopback by default): the experimenter's page with the progress
//! and the pause, resume and abort buttons, and each participant's questionnaire.
//!
//! | route | what |
//! |---|---|
//! | `GET /` | the experimenter's page (refreshes itself every 2 s) |
//! | `POST /control` | `action=pause`, `resume`, `repeat` (the last trial, again) or `abort`; `close` once the run has finished |
//! | `GET /status.json` | the progress as JSON |
//! | `GET /q/<participant>` | the questionnaire owed, or a page that waits for one |
//! | `POST /q/<participant>` | the answers: each question once, on its scale |
//!
//! HTTP/1.1, one request per connection (`Connection: close`), the request line and headers
//! parsed by `httparse`; at most 16 KiB of headers and 64 KiB of body, 5 s to send them. A request
//! that breaks a rule gets its status (400, 404, 405, 411, 413, 431) and a line saying why, and
//! changes nothing.

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use anyhow::Context;

use super::board::{Control, Shared};
use super::questionnaire::html;

/// Most header bytes a request may have.
const MAX_HEAD: usize = 16 * 1024;
/// Most body bytes.
const MAX_BODY: usize = 64 * 1024;
/// The whole request's time, from the connection's accept.
const REQUEST_TIME: Duration = Duration::from_secs(5);
/// Most connections served at once; more are answered 503 at once.
const MAX_CONNECTIONS: u64 = 64;

/// The server: its address and the experimenter's key.
#[derive(Debug)]
pub struct Server {
    /// Where it listens.
    pub addr: SocketAddr,
    /// What `/control` needs (`key=` in its form; the experimenter's page carries it): a page a
    /// participant or another site opens cannot pause, repeat or abort the study.
    pub key: String,
}

/// A key no one guesses: 128 bits from the standard library's per-process random hash keys.
fn fresh_key() -> String {
    use std::hash::{BuildHasher, Hasher};
    let half = || {
        let mut h = std::collections::hash_map::RandomState::new().build_hasher();
        h.write_u128(
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.as_nanos()),
        );
        h.finish()
    };
    format!("{:016x}{:016x}", half(), half())
}

/// A response: status, content type, body; or a redirect.
struct Reply {
    status: u16,
    kind: &'static str,
    body: String,
    location: Option<String>,
    /// The experimenter closed the page: the runner may exit once this reply is sent.
    closes: bool,
}

impl Reply {
    fn page(title: &str, body: &str, refresh: bool) -> Self {
        Self {
            status: 200,
            kind: "text/html; charset=utf-8",
            body: format!(
                "<!doctype html><html><head><meta charset=\"utf-8\"><title>{}</title>{}<style>body{{font-family:sans-serif;max-width:52em;margin:1em auto}}fieldset{{margin:.6em 0}}table{{border-collapse:collapse}}td,th{{padding:.2em .6em;border-bottom:1px solid #ccc}}</style></head><body>{body}</body></html>",
                html(title),
                if refresh {
                    "<meta http-equiv=\"refresh\" content=\"2\">"
                } else {
                    ""
                }
            ),
            location: None,
            closes: false,
        }
    }

    fn error(status: u16, why: &str) -> Self {
        Self {
            status,
            kind: "text/plain; charset=utf-8",
            body: format!("{why}\n"),
            location: None,
            closes: false,
        }
    }

    fn redirect(to: &str) -> Self {
        Self {
            status: 303,
            kind: "text/plain; charset=utf-8",
            body: String::new(),
            location: Some(to.to_owned()),
            closes: false,
        }
    }
}

/// Where a participant's answers go: `(participant, answers) -> Result`.
pub type Store =
    dyn Fn(&super::board::Pending, &[(String, u32)]) -> anyhow::Result<()> + Send + Sync;

impl Server {
    /// Listens on `addr` (port 0: any free one) and serves from a thread of its own for the
    /// process's life.
    ///
    /// # Errors
    /// The address cannot be bound.
    pub fn start(addr: &str, shared: Arc<Shared>, store: Arc<Store>) -> anyhow::Result<Self> {
        let listener = TcpListener::bind(addr)
            .with_context(|| format!("--serve {addr}: cannot listen there"))?;
        let addr = listener.local_addr()?;
        let key = fresh_key();
        let page = Arc::new(Page {
            shared,
            store,
            key: key.clone(),
            open: std::sync::Mutex::new(0),
        });
        std::thread::Builder::new()
            .name("study-web".into())
            .spawn(move || {
                for mut conn in listener.incoming().flatten() {
                    if !page.enter() {
                        let _ = conn.write_all(b"HTTP/1.1 503 Service Unavailable\r\nContent-Length: 0\r\nConnection: close\r\n\r\n");
                        continue;
                    }
                    // One thread per connection (at most MAX_CONNECTIONS, each given at most
                    // REQUEST_TIME to send its request): a slow client does not hold the page up.
                    let mine = Arc::clone(&page);
                    let spawned = std::thread::Builder::new()
                        .name("study-web-conn".into())
                        .spawn(move || {
                            serve(conn, &mine);
                            mine.leave();
                        });
                    if spawned.is_err() {
                        page.leave();
                    }
                }
            })?;
        Ok(Self { addr, key })
    }
}

/// What the connections share: the board, where answers go, the experimenter's key, and how
/// many connections are open.
struct Page {
    shared: Arc<Shared>,
    store: Arc<Store>,
    key: String,
    open: std::sync::Mutex<u64>,
}

impl Page {
    /// Counts a connection in; false when MAX_CONNECTIONS are open already.
    fn enter(&self) -> bool {
        let mut open = self
            .open
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if *open >= MAX_CONNECTIONS {
            return false;
        }
        *open += 1;
        true
    }

    /// Counts a connection out.
    fn leave(&self) {
        let mut open = self
            .open
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        *open = open.saturating_sub(1);
    }
}

/// Reads one request from `conn`, answers it, closes.
fn serve(mut conn: TcpStream, page: &Page) {
    let _ = conn.set_write_timeout(Some(REQUEST_TIME));
    let shared = &*page.shared;
    let reply = match read_request(&mut conn, std::time::Instant::now() + REQUEST_TIME) {
        Ok((method, path, body)) => route(&method, &path, &body, page),
        Err(r) => r,
    };
    let mut head = format!(
        "HTTP/1.1 {} {}\r\nContent-Type: {}\r\nContent-Length: {}\r\nConnection: close\r\nCache-Control: no-store\r\n",
        reply.status,
        reason(reply.status),
        reply.kind,
        reply.body.len()
    );
    if let Some(l) = &reply.location {
        head.push_str(&format!("Location: {l}\r\n"));
    }
    head.push_str("\r\n");
    let _ = conn.write_all(head.as_bytes());
    let _ = conn.write_all(reply.body.as_bytes());
    let _ = conn.flush();
    if reply.closes {
        // Only once the page saying so is sent: the runner exits on it.
        let _ = conn.shutdown(std::net::Shutdown::Both);
        shared.update(|b| b.closed = true);
    }
}

fn reason(status: u16) -> &'static str {
    match status {
        200 => "OK",
        303 => "See Other",
        400 => "Bad Request",
        403 => "Forbidden",
        404 => "Not Found",
        405 => "Method Not Allowed",
        409 => "Conflict",
        411 => "Length Required",
        413 => "Payload Too Large",
        431 => "Request Header Fields Too Large",
        500 => "Internal Server Error",
        503 => "Service Unavailable",
        _ => "Error",
    }
}

/// Reads into `chunk` before `deadline` (the whole request's, not each read's: a client
/// sending a byte now and then is cut off too).
fn read_by(
    conn: &mut TcpStream,
    chunk: &mut [u8],
    deadline: std::time::Instant,
) -> Result<usize, Reply> {
    let left = deadline.saturating_duration_since(std::time::Instant::now());
    if left.is_zero() {
        return Err(Reply::error(400, "the request did not arrive in time"));
    }
    let _ = conn.set_read_timeout(Some(left));
    conn.read(chunk)
        .map_err(|_| Reply::error(400, "the request did not arrive in time"))
}

/// The request's method, path and body, or the reply that refuses it.
fn read_request(
    conn: &mut TcpStream,
    deadline: std::time::Instant,
) -> Result<(String, String, String), Reply> {
    let mut buf = Vec::with_capacity(4096);
    let mut chunk = [0u8; 4096];
    loop {
        let n = read_by(conn, &mut chunk, deadline)?;
        if n == 0 {
            return Err(Reply::error(
                400,
                "the connection closed before the request's end",
            ));
        }
        buf.extend_from_slice(&chunk[..n]);
        let mut headers = [httparse::EMPTY_HEADER; 32];
        let mut req = httparse::Request::new(&mut headers);
        match req.parse(&buf) {
            Ok(httparse::Status::Complete(head_len)) => {
                let method = req.method.unwrap_or("").to_owned();
                let path = req.path.unwrap_or("/").to_owned();
                let length = req
                    .headers
                    .iter()
                    .find(|h| h.name.eq_ignore_ascii_case("content-length"))
                    .map(|h| {
                        std::str::from_utf8(h.value)
                            .ok()
                            .and_then(|v| v.trim().parse::<usize>().ok())
                            .ok_or_else(|| Reply::error(400, "Content-Length is not a number"))
                    })
                    .transpose()?;
                let length = match (method.as_str(), length) {
                    ("POST", None) => {
                        return Err(Reply::error(411, "a POST needs a Content-Length"))
                    }
                    (_, l) => l.unwrap_or(0),
                };
                if length > MAX_BODY {
                    return Err(Reply::error(413, "the body is larger than 64 KiB"));
                }
                let mut body = buf[head_len..].to_vec();
                while body.len() < length {
                    let n = read_by(conn, &mut chunk, deadline)?;
                    if n == 0 {
                        return Err(Reply::error(
                            400,
                            "the connection closed before the body's end",
                        ));
                    }
                    body.extend_from_slice(&chunk[..n]);
                }
                body.truncate(length);
                let body = String::from_utf8(body)
                    .map_err(|_| Reply::error(400, "the body is not UTF-8"))?;
                return Ok((method, path, body));
            }
            Ok(httparse::Status::Partial) if buf.len() <= MAX_HEAD => {}
            Ok(httparse::Status::Partial) | Err(httparse::Error::TooManyHeaders) => {
                return Err(Reply::error(431, "the request's headers are too large"))
            }
            Err(e) => return Err(Reply::error(400, &format!("not an HTTP request: {e}"))),
        }
    }
}

/// The value of `name` in a form or query string (`a=1&b=2`), decoded.
fn field(form: &str, name: &str) -> Option<String> {
    form.split('&').find_map(|p| {
        let (k, v) = p.split_once('=')?;
        (k == name)
            .then(|| super::questionnaire::url_decode(v).ok())
            .flatten()
    })
}

/// Answers one request.
fn route(method: &str, path: &str, body: &str, page: &Page) -> Reply {
    let (shared, store) = (&*page.shared, &*page.store);
    let (path, query) = path.split_once('?').unwrap_or((path, ""));
    let keyed = |form: &str| field(form, "key").is_some_and(|k| k == page.key);
    match (method, path) {
        ("GET", "/") => experimenter(shared, keyed(query).then_some(page.key.as_str())),
        ("GET", "/status.json") => Reply {
            status: 200,
            kind: "application/json",
            body: status_json(shared),
            location: None,
            closes: false,
        },
        ("POST", "/control") => {
            if !keyed(body) {
                return Reply::error(
                    403,
                    "the experimenter's key is missing or wrong (the address printed at the start carries it)",
                );
            }
            let action = field(body, "action").unwrap_or_default();
            let action = action.as_str();
            let to = match action {
                "pause" => Control::Paused,
                "resume" => Control::Running,
                "abort" => Control::Aborted,
                "repeat" => {
                    let ok = {
                        let b = shared.lock();
                        b.done > 0 && !b.finished
                    };
                    if !ok {
                        return Reply::error(
                            409,
                            "repeat: no trial has finished yet, or the run has",
                        );
                    }
                    shared.update(|b| b.repeat = true);
                    return Reply::redirect(&format!("/?key={}", page.key));
                }
                "close" => {
                    let finished = shared.lock().finished;
                    if !finished {
                        return Reply::error(
                            409,
                            "close: the run has not finished (abort it first)",
                        );
                    }
                    return Reply {
                        closes: true,
                        ..Reply::page(
                            "closed",
                            "<h1>Closed</h1><p id=\"closed\">The study runner has exited.</p>",
                            false,
                        )
                    };
                }
                other => {
                    return Reply::error(
                        400,
                        &format!("action {other:?}: pause, resume, repeat, abort or close"),
                    )
                }
            };
            shared.update(|b| {
                // An aborted run stays aborted.
                if b.control != Control::Aborted {
                    b.control = to;
                }
            });
            Reply::redirect(&format!("/?key={}", page.key))
        }
        (m, p) if p.starts_with("/q/") => {
            let who = match super::questionnaire::url_decode(&p[3..]) {
                Ok(w) => w,
                Err(e) => return Reply::error(400, &e),
            };
            match m {
                "GET" => questionnaire_page(shared, &who),
                "POST" => answer(shared, store, &who, body),
                _ => Reply::error(405, "GET or POST"),
            }
        }
        ("GET" | "POST", _) => Reply::error(
            404,
            "no such page: / is the experimenter's, /q/<participant> a questionnaire",
        ),
        _ => Reply::error(405, "GET or POST"),
    }
}

/// The experimenter's page; its buttons only with the key (`key`: it was given).
fn experimenter(shared: &Shared, key: Option<&str>) -> Reply {
    use std::fmt::Write;
    let b = shared.lock().clone();
    let mut s = format!(
        "<h1>Study {}</h1><p id=\"progress\">trial {} of {}{}</p><p id=\"now\">{}</p><p id=\"control\">{}</p>",
        html(&b.study),
        b.done,
        b.total,
        if b.finished { " — finished" } else { "" },
        html(&b.now),
        match b.control {
            Control::Running => "running",
            Control::Paused => "paused: no new block starts",
            Control::Aborted => "aborted: the run stops after the trials running (study run --resume goes on)",
        }
    );
    let buttons: &[(&str, &str)] = if key.is_none() {
        &[]
    } else if b.finished {
        &[("close", "Close")]
    } else {
        &[
            ("pause", "Pause"),
            ("resume", "Resume"),
            ("repeat", "Repeat the last trial"),
            ("abort", "Abort"),
        ]
    };
    for (action, label) in buttons {
        let _ = write!(
            s,
            "<form method=\"post\" action=\"/control\" style=\"display:inline\"><input type=\"hidden\" name=\"key\" value=\"{}\"><button name=\"action\" value=\"{action}\" id=\"{action}\">{label}</button></form> ",
            html(key.unwrap_or_default())
        );
    }
    let _ = write!(s, "<h2>Questionnaires owed</h2><ul id=\"owed\">");
    for p in &b.pending {
        let _ = write!(
            s,
            "<li><a href=\"/q/{0}\">{0}</a> ({1}, {2}, block {3})</li>",
            html(&p.participant),
            html(&p.group),
            html(&p.site),
            p.block
        );
    }
    let _ = write!(s, "</ul><h2>Last trials</h2><ol id=\"recent\">");
    for r in &b.recent {
        let _ = write!(s, "<li>{}</li>", html(r));
    }
    s.push_str("</ol>");
    Reply::page(&format!("study {}", b.study), &s, true)
}

fn status_json(shared: &Shared) -> String {
    let b = shared.lock().clone();
    serde_json::json!({
        "study": b.study,
        "done": b.done,
        "total": b.total,
        "now": b.now,
        "control": format!("{:?}", b.control).to_lowercase(),
        "finished": b.finished,
        "owed": b.pending.iter().map(|p| &p.participant).collect::<Vec<_>>(),
        "answered": b.answered,
        "recent": b.recent,
    })
    .to_string()
}

fn questionnaire_page(shared: &Shared, who: &str) -> Reply {
    let owed = shared
        .lock()
        .pending
        .iter()
        .find(|p| p.participant == who)
        .cloned();
    match (&shared.questionnaire, owed) {
        (Some(q), Some(p)) => Reply::page(
            "questionnaire",
            &format!(
                "<h1>Questionnaire</h1><p id=\"who\">{} — block {}</p><p>About the trials you just did.</p>{}",
                html(&p.participant),
                p.block,
                q.form(&format!("/q/{}", url_encode(who)), p.block)
            ),
            false,
        ),
        _ => Reply::page(
            "waiting",
            &format!(
                "<h1>Thank you</h1><p id=\"waiting\">{}: nothing to answer now. This page will show the next questionnaire when it is time.</p>",
                html(who)
            ),
            true,
        ),
    }
}

fn answer(shared: &Shared, store: &Store, who: &str, body: &str) -> Reply {
    let Some(q) = &shared.questionnaire else {
        return Reply::error(404, "this study asks no questionnaire");
    };
    // One answer at a time, from the check that it is owed to its removal: a form sent twice
    // is kept once.
    let _one = shared.answering();
    let Some(p) = shared
        .lock()
        .pending
        .iter()
        .find(|p| p.participant == who)
        .cloned()
    else {
        return Reply::error(409, &format!("{who}: no questionnaire is owed now"));
    };
    // The form names its block: one sent late (a page left open) is not filed under the next.
    let block = field(body, "block").unwrap_or_default();
    if block != p.block.to_string() {
        return Reply::error(
            409,
            &format!(
                "{who}: this form is for block {block:?}, and block {} is owed now",
                p.block
            ),
        );
    }
    let rest: Vec<&str> = body
        .split('&')
        .filter(|f| !f.starts_with("block="))
        .collect();
    let answers = match q.parse_answers(&rest.join("&")) {
        Ok(a) => a,
        Err(e) => return Reply::error(400, &e),
    };
    if let Err(e) = store(&p, &answers) {
        return Reply::error(500, &format!("the answers could not be kept: {e:#}"));
    }
    shared.update(|b| {
        b.pending.retain(|x| x != &p);
        b.answered += 1;
    });
    Reply::redirect(&format!("/q/{}", url_encode(who)))
}

/// `s` percent-encoded for a path segment (all but A-Z a-z 0-9 - . _ ~).
fn url_encode(s: &str) -> String {
    s.bytes()
        .map(|b| match b {
            b'A'..=b'Z' | b'a'..=b'z' | b'0'..=b'9' | b'-' | b'.' | b'_' | b'~' => {
                char::from(b).to_string()
            }
            _ => format!("%{b:02X}"),
        })
        .collect()
}

/// Where the answers of a run go: `DIR/questionnaires.csv`.
pub fn answers_path(out: &std::path::Path) -> PathBuf {
    out.join("questionnaires.csv")
}
