//! The simulator's wire: every put goes through a station's encode and decode.
//!
//! [`StationWire`] is what `sim` runs with: a site report is laid out as the physics loop lays
//! it in its ring ([`SiteReport::new`]), encoded as the network process encodes it, decoded and
//! checked as a receiving network process does, and converted back as the receiving physics
//! loop converts it; a tool track the same way. So a simulated receiver takes what a station's
//! would, and the bytes counted are the bytes encoded. What it cannot do is a receiver's checks
//! against its own clock ([`crate::admit`]: the time window, the sender's clock offset), which
//! need a station's clocks.

use coop_model::drive::Put;
use coop_model::sim::{Carried, Wire};
use coop_rt::msg::{SiteReport, ToolTrack};

/// The stations' codec as the simulator's wire (see the module docs). The sender's time is the
/// simulator's (a station's CLOCK_MONOTONIC is larger: a track's time varint a byte or two
/// longer).
#[derive(Debug, Clone, Copy, Default)]
pub struct StationWire;

impl Wire for StationWire {
    fn carry(&self, site: usize, t_ns: u64, put: &Put) -> Carried {
        let (bytes, decoded) = match put {
            Put::Report { seq, report } => {
                let bytes = super::encode(&SiteReport::new(site, *seq, report));
                let decoded = super::decode(&bytes).ok().and_then(|r| r.report());
                (bytes.len() as u64, decoded)
            }
            Put::Track(tools) => {
                let bytes = super::encode_track(&ToolTrack::new(site, tools.seq, t_ns, tools));
                let decoded = super::decode_track(&bytes).ok().and_then(|t| t.report());
                (bytes.len() as u64, decoded)
            }
        };
        match decoded {
            Some((from, report)) if from == site => Carried::Taken { report, bytes },
            _ => Carried::Refused { bytes },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use coop_model::body::{BodyState, Vec3};
    use coop_model::method::track::ToolReport;
    use coop_model::method::Report;
    use coop_model::world::MAX_SITES;

    #[test]
    fn a_state_and_a_track_arrive_as_a_station_would_take_them_and_cost_their_encoded_bytes() {
        let state = Report::State {
            object: 0,
            t_s: 1.25,
            state: BodyState::at_rest(Vec3::new(0.1, -0.2, 0.04)),
            accel: Vec3::new(0.0, 0.0, -3.27),
            included: [1.0; MAX_SITES],
        };
        let put = Put::Report {
            seq: 3,
            report: state,
        };
        let Carried::Taken { report, bytes } = StationWire.carry(1, 1_250_000_000, &put) else {
            panic!("a valid state is taken");
        };
        assert_eq!(report, state);
        let encoded = crate::wire::encode(&SiteReport::new(1, 3, &state)).len() as u64;
        assert_eq!(bytes, encoded);

        let mut tools = ToolReport {
            first_tick: 10,
            count: 2,
            seq: 4,
            ..ToolReport::NONE
        };
        tools.positions[0] = [1, 2, 3];
        tools.positions[1] = [1, 2, 4];
        let Carried::Taken { report, .. } = StationWire.carry(1, 9, &Put::Track(tools)) else {
            panic!("a valid track is taken");
        };
        assert_eq!(report, Report::Tools(tools));
    }

    #[test]
    fn a_report_a_station_would_refuse_is_refused_and_its_bytes_still_count() {
        let bad = Report::State {
            object: 0,
            t_s: 1.0,
            state: BodyState::at_rest(Vec3::zeros()),
            accel: Vec3::new(0.0, f64::NAN, 0.0),
            included: [0.0; MAX_SITES],
        };
        let put = Put::Report {
            seq: 1,
            report: bad,
        };
        assert!(matches!(
            StationWire.carry(0, 0, &put),
            Carried::Refused { bytes } if bytes > 0
        ));
    }
}
