//! What you simulate is what you run: a site of `paper.toml` and of `stack.toml`, for each of the
//! four methods, is run in the simulator (through the stations' wire), and every physics tick of
//! it is replayed through a station's physics loop over real shared-memory rings, with the same
//! inputs: the tool sample the servo would have put, the site reports and tool tracks that
//! arrived, the same clock. The station's copy must be the simulator's to the bit after every
//! tick, and every report and track it puts must be the one the simulator put.

use coop_model::drive::Put;
use coop_model::method::{Report, WorldCopy};
use coop_model::scenario::{MethodName, Scenario};
use coop_model::sim::{self, period_ns, Mode, ProbedTick};
use coop_rt::msg::{ObjectSample, SiteReport, ToolSample, ToolTrack};
use coop_rt::physics::{PhysicsLoop, PhysicsRings, PhysicsTiming};
use coop_rt::shm::station::{Names, RingSlots, StationSegments};
use coop_rt::shm::{Consumer, Producer};
use coop_tests::load_scenario;
use coop_transport::wire::StationWire;

/// A station's physics loop for `site` of `sc` under `method`, with the other ends of its rings.
struct Station {
    physics: PhysicsLoop,
    tool_in: Producer<ToolSample>,
    remote_in: Producer<SiteReport>,
    tracks_in: Producer<ToolTrack>,
    reports: Consumer<SiteReport>,
    tracks_out: Consumer<ToolTrack>,
    objects: Consumer<ObjectSample>,
    /// The station's segments, as its supervisor creates them (kept alive with the loop).
    _segments: StationSegments,
}

fn station(sc: &Scenario, site: usize, method: MethodName, tag: &str) -> Station {
    let session = format!("ls{}", std::process::id());
    let names = Names::of(&session, tag).expect("segment names");
    let segs = StationSegments::create(&names, &RingSlots::default()).expect("segments");
    let spec = &sc.site[site];
    let mut physics = PhysicsLoop::new(
        site,
        sc.method(site, method),
        sc.world(),
        sc.start_copy(),
        PhysicsRings {
            tools: segs.tool.consumer().expect("consumer"),
            remote: segs.remote.consumer().expect("consumer"),
            objects: segs.object.producer().expect("producer"),
            reports: segs.report.producer().expect("producer"),
            trace: None,
            tracks_out: Some(segs.track_out.producer().expect("producer")),
            tracks_in: Some(segs.track_in.consumer().expect("consumer")),
        },
        PhysicsTiming {
            period_ns: period_ns(spec.physics_rate_hz),
            report_period_ns: period_ns(spec.report_rate_hz),
            // The simulator's clock: time 0 is the session's.
            start_ns: 0,
            trace_period_ns: period_ns(sc.sample_rate_hz),
            report_seq: 0,
        },
    );
    physics.set_tick_origin(0);
    Station {
        physics,
        tool_in: segs.tool.producer().expect("producer"),
        remote_in: segs.remote.producer().expect("producer"),
        tracks_in: segs.track_in.producer().expect("producer"),
        reports: segs.report.consumer().expect("consumer"),
        tracks_out: segs.track_out.consumer().expect("consumer"),
        objects: segs.object.consumer().expect("consumer"),
        _segments: segs,
    }
}

/// The copy's every number, exactly (`{:?}` of a float round-trips it, sign of zero included).
fn bits(copy: &WorldCopy) -> String {
    format!("{:?}", copy.objects())
}

/// Replays `probed` (site `site` of `sc`) through a station's loop; the first difference, if any.
fn replay(
    sc: &Scenario,
    site: usize,
    method: MethodName,
    probed: &[ProbedTick],
    tag: &str,
) -> Result<usize, String> {
    let mut st = station(sc, site, method, tag);
    let mut puts = 0;
    for (k, p) in probed.iter().enumerate() {
        let mut sample = ToolSample {
            t_ns: p.tool.t_ns,
            seq: k as u64 + 1,
            tool_pos: p.tool.pos.into(),
            tool_vel: p.tool.vel.into(),
            ..ToolSample::default()
        };
        sample.set_contacts(&p.own[..sc.objects.len()]);
        st.tool_in.push(sample).expect("tool ring has room");
        for (n, (from, r)) in p.states.iter().enumerate() {
            let laid = SiteReport::new(*from, n as u64 + 1, r);
            st.remote_in.push(laid).expect("remote ring has room");
        }
        for (from, r) in &p.tracks {
            let Report::Tools(t) = r else {
                return Err(format!("tick {k}: a track that is not tools: {r:?}"));
            };
            let laid = ToolTrack::new(*from, t.seq, p.t_ns, t);
            st.tracks_in.push(laid).expect("track ring has room");
        }
        st.physics.step(p.t_ns);
        while st.objects.pop().is_ok() {}
        if bits(st.physics.copy()) != bits(&p.copy) {
            return Err(format!(
                "tick {k} at {} ns: the station's copy\n{:?}\nthe simulator's\n{:?}",
                p.t_ns,
                st.physics.copy().objects(),
                p.copy.objects()
            ));
        }
        for put in &p.puts {
            let same = match put {
                Put::Report { seq, report } => {
                    let ours = st
                        .reports
                        .pop()
                        .map_err(|_| format!("tick {k}: no report"))?;
                    ours == SiteReport::new(site, *seq, report)
                }
                Put::Track(t) => {
                    let ours = st
                        .tracks_out
                        .pop()
                        .map_err(|_| format!("tick {k}: no track"))?;
                    ours == ToolTrack::new(site, t.seq, p.t_ns, t)
                }
            };
            if !same {
                return Err(format!(
                    "tick {k}: the station put another message than {put:?}"
                ));
            }
            puts += 1;
        }
        if st.reports.pop().is_ok() || st.tracks_out.pop().is_ok() {
            return Err(format!("tick {k}: the station put more than the simulator"));
        }
    }
    Ok(puts)
}

fn lockstep(file: &str, method: MethodName) {
    let sc = load_scenario(file);
    for site in 0..sc.site.len().min(2) {
        let (_, probed) = sim::run_probing_site(&sc, Mode::Distributed(method), site, &StationWire);
        let received: usize = probed.iter().map(|p| p.states.len() + p.tracks.len()).sum();
        assert!(
            probed.len() > 1000 && received > 0,
            "{file} {}: the run should have ticks and receptions to compare ({} ticks, {received} received)",
            method.as_str(),
            probed.len()
        );
        let tag = format!("{}{}{site}", &file[..2], &method.as_str()[..2]);
        match replay(&sc, site, method, &probed, &tag) {
            Ok(puts) => assert!(puts > 0, "{file} {}: nothing put", method.as_str()),
            Err(e) => panic!("{file} {} site {site}: {e}", method.as_str()),
        }
    }
}

#[test]
fn paper_toml_runs_the_same_bits_on_a_station_as_in_the_simulator_for_naive() {
    lockstep("paper.toml", MethodName::Naive);
}

#[test]
fn paper_toml_runs_the_same_bits_on_a_station_as_in_the_simulator_for_paper() {
    lockstep("paper.toml", MethodName::Paper);
}

#[test]
fn paper_toml_runs_the_same_bits_on_a_station_as_in_the_simulator_for_timewarp() {
    lockstep("paper.toml", MethodName::Timewarp);
}

#[test]
fn paper_toml_runs_the_same_bits_on_a_station_as_in_the_simulator_for_coupled() {
    lockstep("paper.toml", MethodName::Coupled);
}

#[test]
fn stack_toml_runs_the_same_bits_on_a_station_as_in_the_simulator_for_naive() {
    lockstep("stack.toml", MethodName::Naive);
}

#[test]
fn stack_toml_runs_the_same_bits_on_a_station_as_in_the_simulator_for_paper() {
    lockstep("stack.toml", MethodName::Paper);
}

#[test]
fn stack_toml_runs_the_same_bits_on_a_station_as_in_the_simulator_for_timewarp() {
    lockstep("stack.toml", MethodName::Timewarp);
}

#[test]
fn stack_toml_runs_the_same_bits_on_a_station_as_in_the_simulator_for_coupled() {
    lockstep("stack.toml", MethodName::Coupled);
}
