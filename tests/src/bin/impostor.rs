//! Fakes a station that speaks for a site it is not: a zenoh client holding one site's
//! certificate (or none) that puts on another site's state key, declares a queryable for that
//! site's clock (answering an hour ahead) and its presence token.
//!
//! On the other site's key it puts two things: 5 bytes of garbage, and well-formed, plausible
//! states of that site ([`forgery::forged_state`]: sequence [`forgery::FORGED_SEQ`], the
//! time now, the object at rest at POS), which a receiver's checks would take if they arrived, so
//! only the access control keeps them from its physics. To show its link works, it also puts the
//! garbage on its own site's state key: a station that receives any garbage counts it as a
//! `length` refusal, so where it arrives is visible in counters.
//!
//! `impostor CONNECT CA CERT KEY SESSION AS FORGE FORGE_INDEX POS`: CERT and KEY `-` for none;
//! FORGE_INDEX the forged site's index in the scenario, POS `x,y,z` in m. Prints
//! `connected <zid>` then `done` after 200 rounds of its puts 10 ms apart, and exits 0; prints
//! `refused: <why>` and exits 3 when it cannot connect.

use std::time::Duration;

use coop_transport::network::{config, Mode, NetworkConfig, Tls};
use coop_transport::{keys, wire};
use zenoh::Wait;

// The forgery's one definition, which the tests look for (this fixture is built by `coop-tools`
// too, where `coop_tests` is only a dev-dependency, so it includes the file).
#[path = "../forgery.rs"]
mod forgery;

fn main() -> std::process::ExitCode {
    let a: Vec<String> = std::env::args().skip(1).collect();
    let usage = || {
        eprintln!("usage: impostor CONNECT CA CERT|- KEY|- SESSION AS FORGE FORGE_INDEX X,Y,Z");
        std::process::ExitCode::from(2)
    };
    let [connect, ca, cert, key, session, me, forge, index, pos] = a.as_slice() else {
        return usage();
    };
    let Ok(index) = index.parse::<usize>() else {
        return usage();
    };
    let pos: Vec<f64> = pos.split(',').filter_map(|x| x.parse().ok()).collect();
    let Ok(pos) = <[f64; 3]>::try_from(pos) else {
        return usage();
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
    let garbage = [wire::VERSION, 2, 3, 4, 5];
    let (theirs, mine) = (keys::state(session, 0, forge), keys::state(session, 0, me));
    for _ in 0..200 {
        let forged = forgery::forged_state(index, coop_rt::timer::monotonic_ns(), pos);
        let _ = z.put(&theirs, forged).wait();
        let _ = z.put(&theirs, garbage.to_vec()).wait();
        let _ = z.put(&mine, garbage.to_vec()).wait();
        // Pacing, so the messages spread over 2 s of the session (not a wait for anything).
        std::thread::sleep(Duration::from_millis(10));
    }
    println!("done");
    let _ = z.close().wait();
    std::process::ExitCode::SUCCESS
}
