//! The stations' recordings in the simulator's layout, so a real run is measured by the same
//! metrics and drawn by the same plots as a simulated one.

use anyhow::bail;
use coop_model::body::Vec3;
use coop_model::method::EnergyAccount;
use coop_model::scenario::Scenario;
use coop_model::sim::{
    AdoptionEvent, ForceSteps, Mode, ObjectTrace, RunResult, SiteTask, SiteTrace,
};
use coop_model::task::Outcome;
use coop_transport::recording::{Recording, SampleMsg};

/// Turns the stations' recordings into the simulator's run layout: every site's trace on the
/// scenario's sample grid from the session's time 0 (each value the newest recorded at or before
/// the grid time), adoptions, and message counts. `epochs` is time 0 per recording, in its
/// station's clock (on one machine, one value; across machines each station's translation).
///
/// # Errors
/// A recording without samples, or not one time 0 per recording.
pub fn run_from_recordings(
    sc: &Scenario,
    recs: &[Recording],
    epochs: &[u64],
) -> anyhow::Result<RunResult> {
    if epochs.len() != recs.len() {
        bail!(
            "{} recordings but {} times 0 (one per recording)",
            recs.len(),
            epochs.len()
        );
    }
    let rate = sc.sample_rate_hz;
    let samples = (sc.duration_s * rate).round() as usize + 1;
    let t: Vec<f64> = (0..samples).map(|k| k as f64 / rate).collect();
    let mut sites = Vec::new();
    let mut adoptions = Vec::new();
    let mut messages = (0u64, 0u64, 0u64);
    for (i, (r, &epoch_ns)) in recs.iter().zip(epochs).enumerate() {
        sites.push(site_trace(sc, i, r, &t, epoch_ns)?);
        for a in &r.adoptions {
            adoptions.push(AdoptionEvent {
                t_s: (a.t_ns as f64 - epoch_ns as f64) * 1e-9,
                site: i,
                from: a.from,
                jump_m: a.jump_m,
                age_s: a.age_s,
                force_step_n: 0.0,
                energy_j: f64::NAN,
                work_j: f64::NAN,
                clipped_j: f64::NAN,
            });
        }
        if let Some(s) = &r.status {
            messages.0 += s.published * (recs.len() as u64).saturating_sub(1);
            messages.1 += s.received;
            messages.2 += s.emulated_lost;
        }
    }
    adoptions.sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
    Ok(RunResult {
        mode: Mode::Distributed(sc.method),
        t,
        sites,
        adoptions,
        energy: vec![EnergyAccount::default(); recs.len()],
        mech_energy: vec![(0.0, 0.0); recs.len()],
        messages,
        rollback: vec![None; recs.len()],
        force_steps: vec![ForceSteps::default(); recs.len()],
        servo_ticks: Vec::new(),
        refused: 0,
        tasks: recs.iter().map(site_task).collect(),
        task: sc.task.done.is_some() || !sc.task.fail.is_empty(),
    })
}

/// A station's task as its recording says: the last outcome its servo judged (`/task`); its
/// participant's grip and steps stay in the station (none here).
fn site_task(r: &Recording) -> SiteTask {
    let outcome = match r.tasks.last() {
        Some(m) if m.outcome == "done" => Outcome::Done(m.at_s),
        Some(m) if m.outcome == "failed" => Outcome::Failed(
            m.at_s,
            m.failed_by
                .strip_prefix("fail[")
                .and_then(|k| k.trim_end_matches(']').parse().ok()),
        ),
        _ => Outcome::Running,
    };
    SiteTask {
        outcome,
        grip: None,
        steps: None,
    }
}

/// Site `i`'s trace from its recording `r` on the grid `t` (s from time 0, `epoch_ns` in its
/// station's clock).
fn site_trace(
    sc: &Scenario,
    i: usize,
    r: &Recording,
    t: &[f64],
    epoch_ns: u64,
) -> anyhow::Result<SiteTrace> {
    if r.samples.is_empty() {
        bail!("the recording of site {} has no samples", sc.site[i].name);
    }
    let mut tr = SiteTrace::default();
    if let Some(st) = &r.status {
        // What the station put: site reports and tool tracks (`WireKind` order).
        tr.puts = [st.traffic.sent_msgs[0], st.traffic.sent_msgs[1]];
        tr.sent_bytes = st.traffic.sent_bytes[0] + st.traffic.sent_bytes[1];
    }
    let at = |tk: f64| epoch_ns as f64 + tk * 1e9;
    for s in resample(&r.samples, t, at) {
        tr.obj_pos.push(Vec3::from(s.pos));
        tr.obj_vel.push(Vec3::from(s.vel));
        tr.obj_rot.push(s.rot);
        tr.tool_pos.push(Vec3::from(s.tool_pos));
        tr.f_desired.push(Vec3::from(s.f_desired));
        tr.f_measured.push(Vec3::from(s.f_measured));
        tr.f_on_object.push(Vec3::from(s.f_object));
        tr.touching.push(s.touching);
    }
    if sc.objects.len() > 1 {
        other_objects(sc, i, r, t, at, &mut tr)?;
    }
    Ok(tr)
}

/// A world of several: every other object of site `i`'s recording (named in the world's order) into
/// `tr`, and which of them the tool touches.
fn other_objects(
    sc: &Scenario,
    i: usize,
    r: &Recording,
    t: &[f64],
    at: impl Fn(f64) -> f64 + Copy,
    tr: &mut SiteTrace,
) -> anyhow::Result<()> {
    if r.others.len() + 1 != sc.objects.len() {
        bail!(
            "the recording of site {} has {} objects, scenario {:?} {}",
            sc.site[i].name,
            r.others.len() + 1,
            sc.name,
            sc.objects.len()
        );
    }
    tr.touched = tr.touching.iter().map(|&t| u16::from(t)).collect();
    for (k, o) in r.others.iter().enumerate() {
        if o.samples.is_empty() {
            bail!(
                "the recording of site {} has no samples of object {}",
                sc.site[i].name,
                o.name
            );
        }
        let mut ob = ObjectTrace::default();
        for (j, s) in resample(&o.samples, t, at).enumerate() {
            ob.pos.push(Vec3::from(s.pos));
            ob.vel.push(Vec3::from(s.vel));
            ob.rot.push(s.rot);
            if s.touching {
                tr.touched[j] |= 1 << (k + 1);
            }
        }
        tr.others.push(ob);
    }
    // Whether the user touches an object: any of them, as the simulator has it.
    for (t, &bits) in tr.touching.iter_mut().zip(&tr.touched) {
        *t = bits != 0;
    }
    Ok(())
}

/// The sample of `samples` (in time order, not empty) in force at each time of `t` (`at` gives
/// a time of `t` in the recording's clock, ns): the last one at or before it, else the first.
fn resample<'a>(
    samples: &'a [SampleMsg],
    t: &'a [f64],
    at: impl Fn(f64) -> f64 + 'a,
) -> impl Iterator<Item = &'a SampleMsg> + 'a {
    let mut k = 0usize;
    t.iter().map(move |&tk| {
        let at = at(tk);
        while k + 1 < samples.len() && (samples[k + 1].t_ns as f64) <= at {
            k += 1;
        }
        &samples[k]
    })
}
