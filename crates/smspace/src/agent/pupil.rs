//! The pupil (after the paper's conclusion): an aperture motor that scales
//! every cell's input, on the paper's arm and on chains.
//!
//! `[agent.retina] aperture = [low, high]` adds one bounded motor `a ∈ [low, high]`,
//! the last, to a body (the arm or a chain) of `n` motors: with the body's law
//! `s_body(m_1..m_n)`, the agent senses
//!
//! ```text
//! s(m_1, …, m_n, a) = a · s_body(m_1, …, m_n) .
//! ```
//!
//! The aperture does not move the retina: the **ground truth** stays the body's pose
//! (`(x, y, alpha)` in the plane), whose Jacobian has a zero column for the aperture.
//! It does change the sensations, so the configuration the sensations determine is the
//! pose *and* the aperture ([`Agent::sensed_configuration`]): both tracing methods hold
//! both fixed, and the kernel sets of the 5-motor planar pupil arm are curves
//! (`k = 5 − (3 + 1) = 1`), the paper's conclusion's agent that captures the aperture
//! "without distinction". The `kinematic` method constrains `(pose, aperture)`; it does
//! not use the pose alone, whose level sets are `kernel × aperture range` (2-D: what
//! `[kernel] spatial = "compensable"` builds from the agent's own data).

use super::{
    Agent, AgentError, CoordinateKind, Environment, LightRegion, LightSpace, Motor, MotorSpace,
    Observer, PoseCoordinate, PoseSpace, Workspace,
};
use crate::params::InvalidParameter;

/// Checks an aperture range `[low, high]`: finite, `0 < low < high` (`key` names it in
/// the error, e.g. `retina.aperture`).
pub(crate) fn check_aperture(key: &'static str, range: [f64; 2]) -> Result<(), AgentError> {
    let [low, high] = range;
    if low.is_finite() && high.is_finite() && 0.0 < low && low < high {
        return Ok(());
    }
    Err(InvalidParameter::new(
        "agent",
        key,
        format!("{range:?}"),
        "an aperture is a range [low, high] of scalings of the retina's input with 0 < low < high, e.g. [0.5, 1.5]",
    )
    .into())
}

/// A body (the arm or a chain) with an aperture motor, the last (module docs).
#[derive(Debug, Clone)]
pub struct Pupil<A> {
    body: A,
    aperture: [f64; 2],
    sensed: SensedPose<A>,
}

/// The configuration a pupil agent's sensations determine: the body's pose, then the
/// aperture (a linear coordinate named `aperture`).
#[derive(Debug, Clone)]
struct SensedPose<A> {
    body: A,
}

impl<A: Agent + Observer + Clone + 'static> Pupil<A> {
    /// `body` with an aperture motor of range `aperture = [low, high]` (`0 < low < high`).
    /// The body's ground truth must hold every tangent coordinate of its pose fixed
    /// (the arm's and every chain's do), so that the aperture is the last constrained
    /// coordinate of the sensed configuration.
    pub fn new(body: A, aperture: [f64; 2]) -> Result<Self, AgentError> {
        check_aperture("retina.aperture", aperture)?;
        let poses = body.pose_space();
        if body.configuration_dim() != poses.tangent_dim() {
            return Err(AgentError::Inconsistent {
                agent: body.name().to_owned(),
                reason: format!(
                    "a pupil needs a body whose motors change every pose coordinate, but {} of {} change",
                    body.configuration_dim(),
                    poses.tangent_dim()
                ),
            });
        }
        Ok(Self {
            sensed: SensedPose { body: body.clone() },
            body,
            aperture,
        })
    }

    /// The body without its aperture.
    pub fn body(&self) -> &A {
        &self.body
    }

    /// The aperture's range `[low, high]`.
    pub fn aperture(&self) -> [f64; 2] {
        self.aperture
    }
}

/// Writes the body's `T × n` pose Jacobian as the first rows of a `rows × (n + 1)`
/// one whose aperture column is zero.
fn widen_jacobian<O: Observer + ?Sized>(
    body: &O,
    n: usize,
    motors: &[f64],
    jacobian: &mut [f64],
    pose: &mut [f64],
) {
    let t = body.pose_space().tangent_dim();
    let mut narrow = vec![0.0; t * n];
    body.pose_jacobian(&motors[..n], &mut narrow, pose);
    for (row, values) in narrow.chunks_exact(n).enumerate() {
        let wide = &mut jacobian[row * (n + 1)..(row + 1) * (n + 1)];
        wide[..n].copy_from_slice(values);
        wide[n] = 0.0;
    }
}

impl<A: Agent + Observer + Clone + 'static> Agent for Pupil<A> {
    fn motor_dim(&self) -> usize {
        self.body.motor_dim() + 1
    }

    fn sensor_dim(&self) -> usize {
        self.body.sensor_dim()
    }

    /// `a · s_body(m_1..m_n)`.
    fn sense(&self, environment: &Environment, motors: &[f64], sensors: &mut [f64]) {
        let n = self.body.motor_dim();
        self.body.sense(environment, &motors[..n], sensors);
        let aperture = motors[n];
        sensors.iter_mut().for_each(|s| *s *= aperture);
    }

    fn name(&self) -> &str {
        self.body.name()
    }

    /// The body's motors, then the aperture, bounded by its range.
    fn motor_space(&self) -> MotorSpace {
        let mut motors = self.body.motor_space().motors().to_vec();
        let [low, high] = self.aperture;
        motors.push(Motor::Bounded { low, high });
        MotorSpace::new(motors).expect("the body's motors and a checked aperture")
    }

    fn ground_truth(&self) -> Option<&dyn Observer> {
        Some(self)
    }

    /// The body's pose and the aperture (module docs).
    fn sensed_configuration(&self) -> Option<&dyn Observer> {
        Some(&self.sensed)
    }

    fn attribute_motors(&self) -> Vec<usize> {
        vec![self.body.motor_dim()]
    }

    fn default_workspace(&self) -> Option<Workspace> {
        self.body.default_workspace()
    }

    fn skeleton(&self, motors: &[f64]) -> Vec<[f64; 2]> {
        self.body.skeleton(&motors[..self.body.motor_dim()])
    }

    fn default_light_region(&self) -> LightRegion {
        self.body.default_light_region()
    }

    fn default_light_count(&self) -> usize {
        self.body.default_light_count()
    }

    fn light_space(&self) -> LightSpace {
        self.body.light_space()
    }

    fn default_light_heights(&self) -> [f64; 2] {
        self.body.default_light_heights()
    }
}

/// The ground truth: the body's pose; the aperture's column of the Jacobian is zero.
impl<A: Agent + Observer + Clone + 'static> Observer for Pupil<A> {
    fn pose_space(&self) -> PoseSpace {
        self.body.pose_space()
    }

    fn pose(&self, motors: &[f64], pose: &mut [f64]) {
        self.body.pose(&motors[..self.body.motor_dim()], pose);
    }

    fn configuration_dim(&self) -> usize {
        self.body.configuration_dim()
    }

    fn pose_jacobian(&self, motors: &[f64], jacobian: &mut [f64], pose: &mut [f64]) {
        widen_jacobian(&self.body, self.body.motor_dim(), motors, jacobian, pose);
    }

    /// The body's inverse kinematics, with the aperture at the middle of its range.
    fn inverse_kinematics(&self, pose: &[f64]) -> Option<Vec<f64>> {
        let mut motors = self.body.inverse_kinematics(pose)?;
        motors.push(0.5 * (self.aperture[0] + self.aperture[1]));
        Some(motors)
    }
}

/// The body's pose, then the aperture: `C + 1` constrained coordinates.
impl<A: Agent + Observer + Clone + 'static> Observer for SensedPose<A> {
    fn pose_space(&self) -> PoseSpace {
        let mut coordinates: Vec<PoseCoordinate> = self.body.pose_space().into();
        coordinates.push(PoseCoordinate::new("aperture", CoordinateKind::Linear));
        PoseSpace::new(coordinates).expect("the body's pose has no coordinate named aperture")
    }

    fn pose(&self, motors: &[f64], pose: &mut [f64]) {
        let n = self.body.motor_dim();
        let d = self.body.pose_space().dim();
        self.body.pose(&motors[..n], &mut pose[..d]);
        pose[d] = motors[n];
    }

    fn configuration_dim(&self) -> usize {
        self.body.configuration_dim() + 1
    }

    fn pose_jacobian(&self, motors: &[f64], jacobian: &mut [f64], pose: &mut [f64]) {
        let n = self.body.motor_dim();
        let space = self.body.pose_space();
        let (t, d) = (space.tangent_dim(), space.dim());
        widen_jacobian(&self.body, n, motors, jacobian, &mut pose[..d]);
        let last = &mut jacobian[t * (n + 1)..(t + 1) * (n + 1)];
        last.fill(0.0);
        last[n] = 1.0;
        pose[d] = motors[n];
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::agent::{ArmParams, PlanarArm};
    use approx::assert_abs_diff_eq;

    fn pupil() -> Pupil<PlanarArm> {
        Pupil::new(PlanarArm::new(&ArmParams::default()).unwrap(), [0.5, 1.5]).unwrap()
    }

    #[test]
    fn the_aperture_scales_the_sensations_and_leaves_the_pose() {
        let (agent, arm) = (pupil(), PlanarArm::new(&ArmParams::default()).unwrap());
        let env = Environment::from_lights(vec![[4.0, 0.5], [3.5, -1.0], [5.0, 1.0]]);
        let m = [0.3, -0.4, 0.2, 0.1];
        let (mut body, mut scaled) = ([0.0; 6], [0.0; 6]);
        arm.sense(&env, &m, &mut body);
        agent.sense(&env, &[0.3, -0.4, 0.2, 0.1, 1.25], &mut scaled);
        for (b, s) in body.iter().zip(&scaled) {
            assert_abs_diff_eq!(1.25 * b, *s, epsilon = 1e-15);
        }
        let mut pose = [0.0; 3];
        agent.pose(&[0.3, -0.4, 0.2, 0.1, 0.7], &mut pose);
        assert_eq!(pose, arm.planar_pose(&m).to_array());
        assert_eq!(agent.motor_dim(), 5);
        assert_eq!(
            agent.motor_space().motors()[4],
            Motor::Bounded {
                low: 0.5,
                high: 1.5
            }
        );
    }

    #[test]
    fn the_sensed_configuration_holds_the_aperture_and_its_jacobian_is_exact() {
        let agent = pupil();
        let sensed = agent.sensed_configuration().unwrap();
        assert_eq!(sensed.configuration_dim(), 4);
        assert_eq!(agent.configuration_dim(), 3);
        let m = [0.3, -0.4, 0.2, 0.1, 0.9];
        let (mut j, mut pose) = ([0.0; 20], [0.0; 4]);
        sensed.pose_jacobian(&m, &mut j, &mut pose);
        let mut direct = [0.0; 4];
        sensed.pose(&m, &mut direct);
        // The arm's Jacobian writes its pose by suffix sums: equal to within rounding.
        for (a, b) in pose.iter().zip(&direct) {
            assert_abs_diff_eq!(a, b, epsilon = 1e-12);
        }
        assert_eq!(pose[3], 0.9);
        // Central differences of the sensed pose, column by column.
        for k in 0..5 {
            let (mut plus, mut minus) = (m, m);
            plus[k] += 1e-6;
            minus[k] -= 1e-6;
            let (mut a, mut b) = ([0.0; 4], [0.0; 4]);
            sensed.pose(&plus, &mut a);
            sensed.pose(&minus, &mut b);
            for row in 0..4 {
                assert_abs_diff_eq!((a[row] - b[row]) / 2e-6, j[row * 5 + k], epsilon = 1e-7);
            }
        }
        // The ground truth's aperture column is zero.
        let (mut g, mut p) = ([1.0; 15], [0.0; 3]);
        agent.pose_jacobian(&m, &mut g, &mut p);
        assert!((0..3).all(|row| g[row * 5 + 4] == 0.0));
        let ik = agent.inverse_kinematics(&[2.0, 0.3, 0.5]).unwrap();
        assert_eq!((ik.len(), ik[4]), (5, 1.0));
    }

    #[test]
    fn a_bad_aperture_is_named() {
        for range in [[0.0, 1.0], [1.0, 0.5], [f64::NAN, 1.0], [-1.0, 1.0]] {
            let err =
                Pupil::new(PlanarArm::new(&ArmParams::default()).unwrap(), range).unwrap_err();
            let located = err.invalid_parameter().unwrap();
            assert_eq!((located.table, located.key), ("agent", "retina.aperture"));
        }
    }
}
