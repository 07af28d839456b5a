//! Fakes a station that speaks for a site it is not: a zenoh client holding one site's
//! certificate (or none) that puts on another site's state key, declares a queryable for that
//! site's clock (answering an hour ahead) and its presence token. To show its link works, it also
//! puts on its own site's state key. Everything it puts is 5 bytes of garbage, so a station that
//! receives any of it counts it as a `length` refusal: where it arrives is visible in counters.
//!
//! `impostor CONNECT CA CERT KEY SESSION AS FORGE`: CERT and KEY `-` for none. Prints
//! `connected <zid>` then `done` after 200 puts of each kind 10 ms apart, and exits 0; prints
//! `refused: <why>` and exits 3 when it cannot connect.

use std::time::Duration;

use coop_transport::network::{config, Mode, NetworkConfig, Tls};
use coop_transport::{keys, wire};
use zenoh::Wait;

fn main() -> std::process::ExitCode {
    let a: Vec<String> = std::env::args().skip(1).collect();
    let [connect, ca, cert, key, session, me, forge] = a.as_slice() else {
        eprintln!("usage: impostor CONNECT CA CERT|- KEY|- SESSION AS FORGE");
        return std::process::ExitCode::from(2);
    };
    let file = |f: &String| (f != "-").then(|| f.into());
    let net = NetworkConfig {
        listen: vec![],
        connect: vec![connect.clone()],
        mode: Mode::Client,
        tls: Some(Tls {
            root_ca_certificate: Some(ca.into()),
            connect_certificate: file(cert),
            connect_private_key: file(key),
            enable_mtls: true,
            ..Tls::default()
        }),
        ..NetworkConfig::default()
    };
    let z = match config(&net)
        .map_err(|e| e.to_string())
        .and_then(|c| zenoh::open(c).wait().map_err(|e| e.to_string()))
    {
        Ok(z) => z,
        Err(why) => {
            println!("refused: {why}");
            return std::process::ExitCode::from(3);
        }
    };
    println!("connected {}", z.zid());
    let ahead = || coop_rt::timer::monotonic_ns() + 3_600_000_000_000;
    let clock = keys::clock(session, forge);
    let reply_key = clock.clone();
    let _queryable = z
        .declare_queryable(clock)
        .callback(move |q| {
            let _ = q
                .reply(reply_key.as_str(), wire::encode_u64(ahead()).to_vec())
                .wait();
        })
        .wait();
    let _token = z
        .liveliness()
        .declare_token(keys::presence(session, forge))
        .wait();
    let garbage = [1u8, 2, 3, 4, 5];
    for _ in 0..200 {
        let _ = z
            .put(keys::state(session, 0, forge), garbage.to_vec())
            .wait();
        let _ = z.put(keys::state(session, 0, me), garbage.to_vec()).wait();
        // Pacing, so the messages spread over 2 s of the session (not a wait for anything).
        std::thread::sleep(Duration::from_millis(10));
    }
    println!("done");
    let _ = z.close().wait();
    std::process::ExitCode::SUCCESS
}
