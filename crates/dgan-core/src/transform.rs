//! Agent-centric SE(2) transforms: world frame ↔ an agent's frame at t_obs (origin at its last observed
//! position, x along its heading, y to its left).

use nalgebra::{Isometry2, Point2, Vector2};

/// The pose of an agent's frame in the world: `world_T_agent`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AgentPose {
    iso: Isometry2<f64>,
}

impl AgentPose {
    /// A frame with its origin at `origin` (world metres) and its x axis at `heading_rad` from the world x axis.
    pub fn new(origin: [f64; 2], heading_rad: f64) -> Self {
        Self { iso: Isometry2::new(Vector2::new(origin[0], origin[1]), heading_rad) }
    }

    /// Origin in the world frame.
    pub fn origin(&self) -> [f64; 2] {
        [self.iso.translation.x, self.iso.translation.y]
    }

    /// Heading of the frame's x axis in the world frame, radians in (-π, π].
    pub fn heading(&self) -> f64 {
        self.iso.rotation.angle()
    }

    /// A world point expressed in this agent's frame.
    pub fn to_local(&self, world: [f64; 2]) -> [f64; 2] {
        let p = self.iso.inverse_transform_point(&Point2::new(world[0], world[1]));
        [p.x, p.y]
    }

    /// A point of this agent's frame expressed in the world frame.
    pub fn to_world(&self, local: [f64; 2]) -> [f64; 2] {
        let p = self.iso.transform_point(&Point2::new(local[0], local[1]));
        [p.x, p.y]
    }

    /// A world vector (velocity, displacement) rotated into this agent's frame.
    pub fn vector_to_local(&self, world: [f64; 2]) -> [f64; 2] {
        let v = self.iso.rotation.inverse_transform_vector(&Vector2::new(world[0], world[1]));
        [v.x, v.y]
    }

    /// A vector of this agent's frame rotated into the world frame.
    pub fn vector_to_world(&self, local: [f64; 2]) -> [f64; 2] {
        let v = self.iso.rotation.transform_vector(&Vector2::new(local[0], local[1]));
        [v.x, v.y]
    }
}

/// Wraps an angle into (-π, π].
pub fn wrap_angle(a: f64) -> f64 {
    let two_pi = std::f64::consts::TAU;
    let mut w = a.rem_euclid(two_pi);
    if w > std::f64::consts::PI {
        w -= two_pi;
    }
    w
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn world_local_round_trip(
            ox in -5000.0..5000.0f64, oy in -5000.0..5000.0f64, h in -10.0..10.0f64,
            px in -5000.0..5000.0f64, py in -5000.0..5000.0f64,
        ) {
            let pose = AgentPose::new([ox, oy], h);
            let back = pose.to_world(pose.to_local([px, py]));
            prop_assert!((back[0] - px).abs() < 1e-9 && (back[1] - py).abs() < 1e-9);
            let v = pose.vector_to_world(pose.vector_to_local([px, py]));
            prop_assert!((v[0] - px).abs() < 1e-9 && (v[1] - py).abs() < 1e-9);
        }

        #[test]
        fn wrapped_angles_are_in_range(a in -100.0..100.0f64) {
            let w = wrap_angle(a);
            prop_assert!(w > -std::f64::consts::PI - 1e-12 && w <= std::f64::consts::PI + 1e-12);
            prop_assert!(((a - w) / std::f64::consts::TAU).fract().abs() < 1e-9
                || (1.0 - ((a - w) / std::f64::consts::TAU).fract().abs()) < 1e-9);
        }
    }

    #[test]
    fn heading_aligned_frame() {
        // An agent at (10, 5) heading north (+y): a point 2 m north of it is 2 m ahead (x), one 1 m west is on its left (y).
        let pose = AgentPose::new([10.0, 5.0], std::f64::consts::FRAC_PI_2);
        let ahead = pose.to_local([10.0, 7.0]);
        assert!((ahead[0] - 2.0).abs() < 1e-12 && ahead[1].abs() < 1e-12);
        let left = pose.to_local([9.0, 5.0]);
        assert!(left[0].abs() < 1e-12 && (left[1] - 1.0).abs() < 1e-12);
    }
}
