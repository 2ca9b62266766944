//! Traffic state (speed, acceleration, heading, yaw rate, size) from each agent's history, robust to missing steps.

use crate::class::AgentClass;
use crate::frame::Frame;
use crate::transform::{wrap_angle, AgentPose};
use serde::{Deserialize, Serialize};

/// Below this speed (m/s) the direction of motion is too noisy to define a heading.
pub const MIN_MOVING_SPEED_MPS: f64 = 0.2;

/// From this speed (m/s) up, [`HeadingSource::MotionWhenMoving`] takes the direction of motion over a measured
/// heading: at 2 Hz an agent this fast has moved 0.5 m between the last two steps.
pub const MOTION_HEADING_MIN_SPEED_MPS: f64 = 1.0;

/// Where the heading of each agent's frame (its agent-centric frame, the crops, the neighbours' relative headings)
/// comes from (`InputSpec::heading`, contract 5).
///
/// Measured headings follow conventions that differ between sources and even between recordings of one source
/// (ApolloScape's heading column agrees with the direction of motion in some recordings and is reversed, mirrored or
/// turned by 90° in others), and a heading off by 180° turns the agent's frame around.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum HeadingSource {
    /// The frame's measured heading where it has one, else the direction of motion (contracts 1–4).
    #[default]
    Measured,
    /// The direction of motion for agents moving at least [`MOTION_HEADING_MIN_SPEED_MPS`]; the measured heading,
    /// where there is one, only for slower agents.
    MotionWhenMoving,
    /// The direction of motion (else of the observed displacement, else 0), measured headings ignored.
    Motion,
}

/// One agent's state at t_obs, in the world frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrafficState {
    /// Last observed position (world metres).
    pub position: [f64; 2],
    /// Velocity at t_obs (world m/s): given, or from the last two valid steps.
    pub velocity: [f64; 2],
    /// |velocity| in m/s.
    pub speed: f64,
    /// Tangential acceleration in m/s² (0 with fewer than three valid steps).
    pub acceleration: f64,
    /// Heading in world radians: given, else the direction of motion, else the direction of the whole observed
    /// displacement, else 0.
    pub heading: f64,
    /// Rate of change of the direction of motion, rad/s (0 when not moving or too few steps).
    pub yaw_rate: f64,
    /// Length in metres.
    pub length: f64,
    /// Width in metres.
    pub width: f64,
}

impl TrafficState {
    /// The agent-centric frame at t_obs.
    pub fn pose(&self) -> AgentPose {
        AgentPose::new(self.position, self.heading)
    }
}

fn finite_diff(a: [f64; 2], b: [f64; 2], dt: f64) -> [f64; 2] {
    [(b[0] - a[0]) / dt, (b[1] - a[1]) / dt]
}

/// The traffic state of every agent of a frame whose steps are `dt_s` seconds apart, headings as measured
/// ([`HeadingSource::Measured`]).
pub fn traffic_states(frame: &Frame, dt_s: f64) -> Vec<TrafficState> {
    traffic_states_with(frame, dt_s, HeadingSource::Measured)
}

/// [`traffic_states`] with the headings taken from `source`.
pub fn traffic_states_with(frame: &Frame, dt_s: f64, source: HeadingSource) -> Vec<TrafficState> {
    let pos = frame.positions();
    let mask = frame.mask();
    (0..frame.len())
        .map(|i| {
            let valid: Vec<usize> = (0..frame.steps()).filter(|&s| mask[[i, s]]).collect();
            let p = |s: usize| [pos[[i, s, 0]], pos[[i, s, 1]]];
            // `Frame` guarantees at least one valid step.
            let last = valid.last().copied().unwrap_or(0);
            let velocity_between = |a: usize, b: usize| finite_diff(p(a), p(b), (b - a) as f64 * dt_s);
            let n = valid.len();
            let v_hist = (n >= 2).then(|| velocity_between(valid[n - 2], last));
            let v_prev = (n >= 3).then(|| velocity_between(valid[n - 3], valid[n - 2]));
            let velocity = frame.velocities()[i].or(v_hist).unwrap_or([0.0, 0.0]);
            let speed = velocity[0].hypot(velocity[1]);
            let mut acceleration = 0.0;
            let mut yaw_rate = 0.0;
            if let (Some(v1), Some(v0)) = (v_hist, v_prev) {
                // Velocities live at the midpoints of their segments.
                let span = (last as f64 - valid[n - 3] as f64) * 0.5 * dt_s;
                let (s1, s0) = (v1[0].hypot(v1[1]), v0[0].hypot(v0[1]));
                acceleration = (s1 - s0) / span;
                if s1 >= MIN_MOVING_SPEED_MPS && s0 >= MIN_MOVING_SPEED_MPS {
                    yaw_rate = wrap_angle(v1[1].atan2(v1[0]) - v0[1].atan2(v0[0])) / span;
                }
            }
            let first = p(valid[0]);
            let disp = [p(last)[0] - first[0], p(last)[1] - first[1]];
            let from_motion = || {
                if speed >= MIN_MOVING_SPEED_MPS {
                    velocity[1].atan2(velocity[0])
                } else if disp[0].hypot(disp[1]) >= MIN_MOVING_SPEED_MPS * dt_s * n as f64 {
                    disp[1].atan2(disp[0])
                } else {
                    0.0
                }
            };
            let heading = match (source, frame.headings()[i]) {
                (HeadingSource::Measured, Some(h)) => h,
                (HeadingSource::MotionWhenMoving, Some(h)) if speed < MOTION_HEADING_MIN_SPEED_MPS => h,
                _ => from_motion(),
            };
            TrafficState {
                position: p(last),
                velocity,
                speed,
                acceleration,
                heading: wrap_angle(heading),
                yaw_rate,
                length: frame.lengths()[i],
                width: frame.widths()[i],
            }
        })
        .collect()
}

/// The moving agents [`HeadingCheck::disagrees`] needs to judge headings by the motion.
pub const HEADING_CHECK_MIN_MOVING: usize = 3;
/// The median disagreement, in degrees, above which [`HeadingCheck::disagrees`].
pub const HEADING_CHECK_MAX_MEDIAN_DEG: f64 = 45.0;

/// How well a frame's measured headings follow its agents' motion ([`check_headings`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeadingCheck {
    /// Agents with a measured heading moving at least [`MOTION_HEADING_MIN_SPEED_MPS`].
    pub moving: usize,
    /// Median angle in degrees between those agents' measured headings and their direction of motion.
    pub median_error_deg: f64,
    /// The largest magnitude of a measured heading (radians, if they are radians): beyond 2π, degrees passed as
    /// radians, unless the agents moving confirm the headings (logs also store radians unwrapped past 2π).
    pub largest_rad: f64,
}

/// With too few agents moving to judge the headings, the magnitude beyond which they are taken for degrees: 6π.
/// Logs' radians unwrapped past 2π stay below it (the shared Waymo scenarios reach 17.3 rad, 2.75π), while degrees
/// exceed it for any heading beyond 19°.
pub const HEADING_CHECK_UNWRAPPED_MAX_RAD: f64 = 3.0 * std::f64::consts::TAU;

impl HeadingCheck {
    /// Whether some measured heading exceeds 2π in magnitude.
    pub fn beyond_two_pi(&self) -> bool {
        self.largest_rad > std::f64::consts::TAU + 1e-6
    }

    /// Whether enough agents move ([`HEADING_CHECK_MIN_MOVING`]) for their motion to judge the headings.
    pub fn judged_by_motion(&self) -> bool {
        self.moving >= HEADING_CHECK_MIN_MOVING
    }

    /// Whether the headings are most likely in another convention: enough moving agents to judge and a median
    /// disagreement over [`HEADING_CHECK_MAX_MEDIAN_DEG`], or, with too few to judge, values beyond
    /// [`HEADING_CHECK_UNWRAPPED_MAX_RAD`] that the moving agents there are (compared modulo 2π) do not confirm.
    /// Headings that follow the motion are radians even when unwrapped past 2π, and so are headings within three
    /// turns of a frame whose agents stand (a quiet moment of a Waymo log).
    pub fn disagrees(&self) -> bool {
        if self.judged_by_motion() {
            self.median_error_deg > HEADING_CHECK_MAX_MEDIAN_DEG
        } else {
            let confirmed = self.moving > 0 && self.median_error_deg <= HEADING_CHECK_MAX_MEDIAN_DEG;
            self.largest_rad > HEADING_CHECK_UNWRAPPED_MAX_RAD && !confirmed
        }
    }
}

/// Compares a frame's measured headings with its agents' direction of motion, for a model that takes measured
/// headings: headings in another convention (degrees, compass bearings, reversed) turn every agent-centric frame.
/// `None` when no agent has a measured heading.
pub fn check_headings(frame: &Frame, dt_s: f64) -> Option<HeadingCheck> {
    check_frame(frame, dt_s, true, false).0
}

/// [`check_headings`] and [`check_speeds`], those asked for, from one computation of the frame's traffic states
/// (headings from the motion).
pub fn check_frame(
    frame: &Frame,
    dt_s: f64,
    headings: bool,
    speeds: bool,
) -> (Option<HeadingCheck>, Option<SpeedCheck>) {
    let given: Vec<(usize, f64)> = frame.headings().iter().enumerate().filter_map(|(i, h)| h.map(|h| (i, h))).collect();
    let headings = headings && !given.is_empty();
    if !headings && !speeds {
        return (None, None);
    }
    let states = traffic_states_with(frame, dt_s, HeadingSource::Motion);
    (headings.then(|| headings_against(&given, &states)), speeds.then(|| speeds_by_class(frame, &states)).flatten())
}

/// [`check_headings`] of the measured headings `given` (agent index, heading) against the `states` from the motion.
fn headings_against(given: &[(usize, f64)], states: &[TrafficState]) -> HeadingCheck {
    let mut errors: Vec<f64> = given
        .iter()
        .filter(|(i, _)| states[*i].speed >= MOTION_HEADING_MIN_SPEED_MPS)
        .map(|(i, h)| wrap_angle(h - states[*i].heading).abs().to_degrees())
        .collect();
    let median_error_deg = median(&mut errors).unwrap_or(0.0);
    let largest_rad = given.iter().map(|(_, h)| h.abs()).fold(0.0, f64::max);
    HeadingCheck { moving: errors.len(), median_error_deg, largest_rad }
}

/// The median of `values` (the mean of the middle two for an even count; sorts them), None when empty.
fn median(values: &mut [f64]) -> Option<f64> {
    values.sort_by(f64::total_cmp);
    let n = values.len();
    match n {
        0 => None,
        _ if n % 2 == 1 => Some(values[n / 2]),
        _ => Some((values[n / 2 - 1] + values[n / 2]) / 2.0),
    }
}

/// The moving agents of a class [`SpeedCheck::implausible`] needs to judge its speeds.
pub const SPEED_CHECK_MIN_MOVING: usize = 3;

/// The fastest plausible median speed, m/s, of a class's moving agents (at least [`MIN_MOVING_SPEED_MPS`]): a
/// crowd running a race or on skateboards, motorcycles (which several sources count as cyclists), traffic on a
/// motorway stay below it, while the same agents in pixels (10-50 to the metre from a drone or a fixed camera) or
/// centimetres exceed it several times. On the shared data's sources the largest median was 0.65 of it (Stanford
/// Drone's pedestrians), 0.56 (ApolloScape's cyclists, motorcycles among them) and 0.23 (vehicles).
pub fn plausible_median_speed_mps(class: AgentClass) -> f64 {
    match class {
        AgentClass::Vehicle => 70.0,
        AgentClass::Cyclist => 35.0,
        AgentClass::Pedestrian => 6.0,
    }
}

/// A frame's speeds against what its agents' classes can do ([`check_speeds`]): positions in another unit than
/// metres (pixels, centimetres), or times in another unit than the model's steps, make every agent implausibly fast.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpeedCheck {
    /// The class whose median speed is furthest beyond its [`plausible_median_speed_mps`].
    pub class: AgentClass,
    /// Its agents moving at least [`MIN_MOVING_SPEED_MPS`].
    pub moving: usize,
    /// Their median speed, in the frame's units per second.
    pub median_speed: f64,
}

impl SpeedCheck {
    /// Whether enough agents of the class move ([`SPEED_CHECK_MIN_MOVING`]) and their median speed exceeds
    /// [`plausible_median_speed_mps`].
    pub fn implausible(&self) -> bool {
        self.moving >= SPEED_CHECK_MIN_MOVING && self.median_speed > plausible_median_speed_mps(self.class)
    }
}

/// The speeds of a frame's moving agents, per class, against [`plausible_median_speed_mps`]: the class furthest
/// beyond its bound (or nearest below it) among those with [`SPEED_CHECK_MIN_MOVING`] moving agents; `None` when no
/// class has that many.
pub fn check_speeds(frame: &Frame, dt_s: f64) -> Option<SpeedCheck> {
    check_frame(frame, dt_s, false, true).1
}

/// [`check_speeds`] from the frame's traffic `states`.
fn speeds_by_class(frame: &Frame, states: &[TrafficState]) -> Option<SpeedCheck> {
    AgentClass::ALL
        .iter()
        .filter_map(|&class| {
            let mut speeds: Vec<f64> = (states.iter().zip(frame.classes()))
                .filter(|(s, c)| **c == class && s.speed >= MIN_MOVING_SPEED_MPS)
                .map(|(s, _)| s.speed)
                .collect();
            if speeds.len() < SPEED_CHECK_MIN_MOVING {
                return None;
            }
            let median_speed = median(&mut speeds)?;
            Some(SpeedCheck { class, moving: speeds.len(), median_speed })
        })
        .max_by(|a, b| {
            let beyond = |c: &SpeedCheck| c.median_speed / plausible_median_speed_mps(c.class);
            beyond(a).total_cmp(&beyond(b))
        })
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::{array, Array3};

    #[test]
    fn constant_acceleration_along_y() {
        // y = t² (dt = 1): velocities 1, 3, 5 at midpoints → speed 5 at the end, acceleration 2, heading +y.
        let p = Array3::from_shape_fn((1, 4, 2), |(_, t, d)| if d == 1 { (t * t) as f64 } else { 0.0 });
        let f = Frame::new(p, None, vec![AgentClass::Cyclist]).unwrap();
        let s = traffic_states(&f, 1.0)[0];
        assert_eq!(s.velocity, [0.0, 5.0]);
        assert!((s.acceleration - 2.0).abs() < 1e-12);
        assert!((s.heading - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        assert_eq!(s.length, 1.8);
    }

    #[test]
    fn missing_steps_use_the_real_time_gap() {
        let p = array![[[0.0, 0.0], [f64::NAN, f64::NAN], [2.0, 0.0], [3.0, 0.0]]];
        let mask = array![[true, false, false, true]];
        let f = Frame::new(p, Some(mask), vec![AgentClass::Pedestrian]).unwrap();
        let s = traffic_states(&f, 0.5)[0];
        // 3 m over 3 steps of 0.5 s.
        assert!((s.speed - 2.0).abs() < 1e-12);
        assert_eq!(s.acceleration, 0.0);
        assert_eq!(s.position, [3.0, 0.0]);
    }

    #[test]
    fn single_step_agent_is_at_rest() {
        let f = Frame::new(Array3::from_elem((1, 1, 2), 4.0), None, vec![AgentClass::Pedestrian]).unwrap();
        let s = traffic_states(&f, 0.4)[0];
        assert_eq!((s.speed, s.heading, s.yaw_rate), (0.0, 0.0, 0.0));
    }

    #[test]
    fn given_values_win() {
        let p = Array3::from_shape_fn((1, 3, 2), |(_, t, d)| if d == 0 { t as f64 } else { 0.0 });
        let f = Frame::new(p, None, vec![AgentClass::Vehicle])
            .unwrap()
            .with_headings(&[1.0])
            .unwrap()
            .with_velocities(array![[0.0, 3.0]].view())
            .unwrap();
        let s = traffic_states(&f, 1.0)[0];
        assert_eq!((s.heading, s.velocity, s.speed), (1.0, [0.0, 3.0], 3.0));
    }

    #[test]
    fn heading_sources() {
        // Agent 0 drives +x at 2 m/s with a measured heading reversed (π, as in some ApolloScape recordings); agent 1
        // creeps +x at 0.5 m/s with a measured heading of 1 rad; agent 2 has no measured heading and drives +y.
        let speeds = [[2.0, 0.0], [0.5, 0.0], [0.0, 2.0]];
        let p = Array3::from_shape_fn((3, 3, 2), |(i, t, d)| speeds[i][d] * t as f64 + 10.0 * i as f64);
        let f = Frame::new(p, None, vec![AgentClass::Vehicle; 3])
            .unwrap()
            .with_headings(&[std::f64::consts::PI, 1.0, f64::NAN])
            .unwrap();
        let headings = |source| traffic_states_with(&f, 1.0, source).iter().map(|s| s.heading).collect::<Vec<_>>();
        let up = std::f64::consts::FRAC_PI_2;
        assert_eq!(headings(HeadingSource::Measured), vec![std::f64::consts::PI, 1.0, up]);
        assert_eq!(headings(HeadingSource::MotionWhenMoving), vec![0.0, 1.0, up]);
        assert_eq!(headings(HeadingSource::Motion), vec![0.0, 0.0, up]);
        assert_eq!(traffic_states(&f, 1.0), traffic_states_with(&f, 1.0, HeadingSource::Measured));
    }

    #[test]
    fn heading_checks() {
        // Two agents drive +x at 2 m/s, one +y; a slow one and one without a heading do not count.
        let speeds = [[2.0, 0.0], [2.0, 0.0], [0.0, 2.0], [0.1, 0.0], [2.0, 0.0]];
        let p = Array3::from_shape_fn((5, 3, 2), |(i, t, d)| speeds[i][d] * t as f64 + 10.0 * i as f64);
        let f =
            |h: [f64; 5]| Frame::new(p.clone(), None, vec![AgentClass::Vehicle; 5]).unwrap().with_headings(&h).unwrap();
        let up = std::f64::consts::FRAC_PI_2;
        let ok = check_headings(&f([0.0, 0.05, up + 0.1, 3.0, f64::NAN]), 1.0).unwrap();
        assert_eq!((ok.moving, ok.beyond_two_pi(), ok.disagrees()), (3, false, false));
        assert!((ok.median_error_deg - 0.05f64.to_degrees()).abs() < 1e-9);
        // Reversed headings, and degrees passed as radians.
        let reversed = check_headings(&f([3.1, 3.1, -up, 0.0, f64::NAN]), 1.0).unwrap();
        assert!(reversed.median_error_deg > 170.0 && reversed.disagrees());
        let degrees = check_headings(&f([0.0, 0.0, 90.0, 0.0, f64::NAN]), 1.0).unwrap();
        assert!(degrees.beyond_two_pi());
        // ... which the motion judges: 0° is 0 rad, so two of the three moving agents agree and the median holds.
        assert!(!degrees.disagrees());
        let all_degrees = check_headings(&f([180.0, 180.0, 90.0, 0.0, f64::NAN]), 1.0).unwrap();
        assert!(all_degrees.beyond_two_pi() && all_degrees.disagrees());
        // Radians unwrapped past 2π that follow the motion: beyond 2π, yet confirmed by the three moving agents.
        let tau = std::f64::consts::TAU;
        let unwrapped = check_headings(&f([2.0 * tau, 2.0 * tau, up + tau, 0.0, f64::NAN]), 1.0).unwrap();
        assert!(unwrapped.beyond_two_pi() && !unwrapped.disagrees());
        // Too few moving agents to judge the median: beyond 6π decides, unless the few moving agents agree with the
        // headings modulo 2π (unwrapped radians, issue 28: "disagree by 0°, some exceed 2π" was a false warning).
        let slow = |h: f64, moving: usize, err: f64| HeadingCheck { moving, median_error_deg: err, largest_rad: h };
        assert!(slow(90.0, 0, 0.0).disagrees() && !slow(1.0, 0, 0.0).disagrees());
        assert!(!slow(8.95, 2, 0.0).disagrees());
        assert!(slow(90.0, 2, 120.0).disagrees());
        // A quiet moment of a Waymo log, every agent standing, its radians unwrapped up to 10.5: not degrees.
        assert!(!slow(10.52, 0, 0.0).disagrees() && slow(10.52, 0, 0.0).beyond_two_pi());
        assert!(slow(19.0, 0, 0.0).disagrees());
        let none = Frame::new(p.clone(), None, vec![AgentClass::Vehicle; 5]).unwrap();
        assert_eq!(check_headings(&none, 1.0), None);
    }

    #[test]
    fn speed_checks() {
        // Four pedestrians walking +x at 1.4 m/s and one standing; two cars at 15 m/s (too few to judge).
        let walk = |scale: f64| {
            let speeds = [1.4, 1.2, 1.5, 1.3, 0.0, 15.0, 15.0];
            let p = Array3::from_shape_fn((7, 4, 2), |(i, t, d)| {
                scale * if d == 0 { speeds[i] * 0.4 * t as f64 } else { 3.0 * i as f64 }
            });
            let mut classes = vec![AgentClass::Pedestrian; 5];
            classes.extend([AgentClass::Vehicle; 2]);
            Frame::new(p, None, classes).unwrap()
        };
        let metres = check_speeds(&walk(1.0), 0.4).unwrap();
        assert_eq!((metres.class, metres.moving), (AgentClass::Pedestrian, 4));
        assert!((metres.median_speed - 1.35).abs() < 1e-9 && !metres.implausible());
        // The same scene in pixels of a camera at 25 px/m: 34 px/s walkers.
        let pixels = check_speeds(&walk(25.0), 0.4).unwrap();
        assert!(pixels.implausible() && (pixels.median_speed - 33.75).abs() < 1e-9);
        // In centimetres the cars are 1,500 cm/s, yet too few to judge; the walkers decide.
        assert_eq!(check_speeds(&walk(100.0), 0.4).unwrap().class, AgentClass::Pedestrian);
        // Standing agents alone, or too few moving ones, say nothing.
        let still = Frame::new(Array3::zeros((5, 4, 2)), None, vec![AgentClass::Pedestrian; 5]).unwrap();
        assert_eq!(check_speeds(&still, 0.4), None);
        let few = SpeedCheck { class: AgentClass::Cyclist, moving: 2, median_speed: 90.0 };
        assert!(!few.implausible());
        assert!(SpeedCheck { moving: 3, ..few }.implausible());
        assert!(!SpeedCheck { class: AgentClass::Vehicle, moving: 3, median_speed: 40.0 }.implausible());
    }
}
