//! The drive model of the simulated TurtleBot3 Burger: linear motion along the path only.
//!
//! Owns: the robot's physical parameters ([`Params`], every value with its source in
//! `docs/book/src/simulation.md`) and one integration step ([`Robot::step`]). The commanded linear speed
//! is tracked by a velocity controller (proportional term with time constant `tau`, an
//! integral term that compensates steady loads up to `integral_limit`, anti-windup), whose
//! force is capped at the drive's force limit (motor torque or wheel traction, the smaller).
//! Grade and rolling resistance come from the terrain. Rolling resistance acts as Coulomb
//! friction: a robot at rest stays at rest (sticks) while the drive force minus the grade force
//! is within it; a stronger command raises the proportional force and can free it.

/// The robot's physical parameters (SI units).
#[derive(Debug, Clone, PartialEq)]
pub struct Params {
    /// kg: the Burger's mass.
    pub mass: f64,
    /// m/s²: gravity.
    pub gravity: f64,
    /// m/s: the Burger's top linear speed; commands are clamped to ±this.
    pub max_speed: f64,
    /// s: time constant of the speed controller's proportional response (gain = mass / tau).
    pub tau: f64,
    /// s: integral time of the speed controller.
    pub integral_time: f64,
    /// N: most force the integral term may hold (anti-windup limit).
    pub integral_limit: f64,
    /// N: drive force limit, min(motor torque · 2 / wheel radius, traction μ·m·g).
    pub force_limit: f64,
}

/// Physical constants the defaults are derived from (sources in docs/book/src/simulation.md).
pub mod source {
    /// kg, ROBOTIS TurtleBot3 Burger specification.
    pub const MASS: f64 = 1.0;
    /// m/s, ROBOTIS teleop `BURGER_MAX_LIN_VEL` and Nav2 `max_vel_x`.
    pub const MAX_SPEED: f64 = 0.22;
    /// m, `turtlebot3_bringup` burger.yaml `wheels.radius`.
    pub const WHEEL_RADIUS: f64 = 0.033;
    /// m, `turtlebot3_bringup` burger.yaml `wheels.separation`.
    pub const WHEEL_SEPARATION: f64 = 0.160;
    /// N·m, Dynamixel XL430-W250 stall torque at 11.1 V (ROBOTIS e-manual), one per wheel.
    pub const STALL_TORQUE: f64 = 1.4;
    /// Wheel-to-mat friction coefficient (rubber on foam; an assumption, see the docs).
    pub const TRACTION_MU: f64 = 0.5;
    /// Rolling-resistance coefficient of the yoga mat (an assumption, see the docs).
    pub const MAT_ROLLING: f64 = 0.02;
    /// m/s².
    pub const GRAVITY: f64 = 9.81;
}

impl Default for Params {
    fn default() -> Self {
        let torque_force = 2.0 * source::STALL_TORQUE / source::WHEEL_RADIUS;
        let traction_force = source::TRACTION_MU * source::MASS * source::GRAVITY;
        Params {
            mass: source::MASS,
            gravity: source::GRAVITY,
            max_speed: source::MAX_SPEED,
            tau: 0.5,
            integral_time: 1.0,
            // The integral term is sized to hold the speed against the mat's rolling
            // resistance on the flat, with a 25% reserve.
            integral_limit: 1.25 * source::MAT_ROLLING * source::MASS * source::GRAVITY,
            force_limit: torque_force.min(traction_force),
        }
    }
}

/// What the terrain presents at the robot's position.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ground {
    /// Slope dh/dx (rise over run; positive = uphill in the direction of travel).
    pub slope: f64,
    /// Rolling-resistance coefficient.
    pub rolling: f64,
}

/// The robot's state.
#[derive(Debug, Clone, PartialEq)]
pub struct Robot {
    pub params: Params,
    /// m along the path.
    pub x: f64,
    /// m/s along the path.
    pub v: f64,
    /// N held by the controller's integral term.
    integral: f64,
}

/// Below this speed (m/s) the robot counts as at rest.
const REST: f64 = 1e-9;

impl Robot {
    pub fn new(params: Params) -> Robot {
        Robot {
            params,
            x: 0.0,
            v: 0.0,
            integral: 0.0,
        }
    }

    /// Whether the robot is at rest.
    pub fn at_rest(&self) -> bool {
        self.v.abs() <= REST
    }

    /// Advance by `dt` seconds with speed command `command` (m/s) on `ground`.
    pub fn step(&mut self, command: f64, ground: Ground, dt: f64) {
        let p = &self.params;
        let command = if command.is_finite() {
            command.clamp(-p.max_speed, p.max_speed)
        } else {
            0.0
        };
        let gain = p.mass / p.tau;
        let error = command - self.v;
        self.integral = (self.integral + gain / p.integral_time * error * dt)
            .clamp(-p.integral_limit, p.integral_limit);
        let drive = (gain * error + self.integral).clamp(-p.force_limit, p.force_limit);
        let norm = (1.0 + ground.slope * ground.slope).sqrt();
        let (sin, cos) = (ground.slope / norm, 1.0 / norm);
        let grade_force = p.mass * p.gravity * sin;
        let rolling_force = ground.rolling.max(0.0) * p.mass * p.gravity * cos;
        let applied = drive - grade_force;
        if self.at_rest() {
            // Static: rolling resistance holds the robot while the applied force is within it.
            if applied.abs() <= rolling_force {
                self.v = 0.0;
                return;
            }
            let accel = (applied - applied.signum() * rolling_force) / p.mass;
            self.v = accel * dt;
        } else {
            let accel = (applied - self.v.signum() * rolling_force) / p.mass;
            let next = self.v + accel * dt;
            // Friction cannot reverse the motion within one step: stop at zero instead.
            self.v = if next * self.v < 0.0 && (applied.abs() <= rolling_force) {
                0.0
            } else {
                next
            };
        }
        self.x += self.v * dt;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const DT: f64 = 0.005;

    fn run(robot: &mut Robot, command: f64, ground: Ground, seconds: f64) {
        for _ in 0..(seconds / DT).round() as usize {
            robot.step(command, ground, DT);
        }
    }

    fn flat() -> Ground {
        Ground {
            slope: 0.0,
            rolling: source::MAT_ROLLING,
        }
    }

    #[test]
    fn flat_track_tracks_the_command() {
        for command in [0.015, 0.05, 0.1, 0.22] {
            let mut r = Robot::new(Params::default());
            run(&mut r, command, flat(), 15.0);
            assert!(
                (r.v - command).abs() < 1e-3,
                "command {command}: speed {}",
                r.v
            );
        }
        // Commands beyond the top speed are clamped.
        let mut r = Robot::new(Params::default());
        run(&mut r, 1.0, flat(), 15.0);
        assert!((r.v - source::MAX_SPEED).abs() < 1e-3, "{}", r.v);
    }

    #[test]
    fn the_command_is_reached_with_a_lag() {
        let mut r = Robot::new(Params::default());
        run(&mut r, 0.1, flat(), 0.25);
        assert!(r.v > 0.0 && r.v < 0.09, "after 0.25 s: {}", r.v);
    }

    #[test]
    fn grade_beyond_the_force_limit_sticks() {
        let p = Params::default();
        // A grade whose gravity force alone exceeds the force limit minus rolling resistance.
        let slope = 0.6;
        assert!(p.mass * p.gravity * slope / (1.0f64 + slope * slope).sqrt() > p.force_limit);
        let mut r = Robot::new(p);
        run(
            &mut r,
            0.22,
            Ground {
                slope,
                rolling: source::MAT_ROLLING,
            },
            10.0,
        );
        assert!(r.x <= 0.0, "no progress uphill: x = {}", r.x);
    }

    #[test]
    fn small_hill_sticks_a_weak_command_and_a_stronger_command_frees_it() {
        let hill = Ground {
            slope: 0.03,
            rolling: source::MAT_ROLLING,
        };
        let mut r = Robot::new(Params::default());
        run(&mut r, 0.05, hill, 20.0);
        assert!(r.at_rest(), "stuck at 0.05 m/s: v = {}", r.v);
        let x = r.x;
        run(&mut r, 0.05, hill, 20.0);
        assert_eq!(r.x, x, "stays stuck");
        run(&mut r, 0.2, hill, 5.0);
        assert!(!r.at_rest() && r.x > x + 0.05, "freed: x {} v {}", r.x, r.v);
    }
}
