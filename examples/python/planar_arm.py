"""The paper's planar arm with a retina, written in plain NumPy as a smspace.PythonAgent.

Three links of length 1 and a retina hinge (section 3.1 of Laflaquière et al. 2015):
the retina sits at the end of the arm, looks along the sum of the joint angles, and
each of its 6 cells senses sum over the lights in front of exp(-(cell - projection)^2)
/ distance. The engine calls ``sense`` with a batch of motor rows at a time (the
sensory tracer asks for the 2N + 1 readings of a Jacobian at once).

Run it (after installing the package, see the README):

    python examples/python/planar_arm.py

It traces the same starts with this agent and with the built-in ``planar-arm`` in
the same lights, by the sensory method, and prints how far apart the kernel sets are.
"""

import numpy as np

import smspace

LINKS = np.array([1.0, 1.0, 1.0])
CELLS = np.linspace(-1.0, 1.0, 6)  # retina cells on the image line, focal length 1


def pose(motors: np.ndarray) -> np.ndarray:
    """The retina's (x, y, alpha) for motor rows (B, 4)."""
    theta = np.cumsum(motors[:, :3], axis=1)
    x = (LINKS * np.cos(theta)).sum(axis=1)
    y = (LINKS * np.sin(theta)).sum(axis=1)
    total = motors.sum(axis=1)
    inside = (total >= -np.pi) & (total < np.pi)  # wrapped into [-pi, pi) only if needed
    alpha = np.where(inside, total, (total + np.pi) % (2 * np.pi) - np.pi)
    return np.stack([x, y, alpha], axis=1)


def make_sense(lights: np.ndarray):
    """The retina's law in an environment of point lights (L, 2)."""

    def sense(motors: np.ndarray) -> np.ndarray:
        x, y, alpha = pose(motors).T
        dx = lights[None, :, 0] - x[:, None]  # (B, L)
        dy = lights[None, :, 1] - y[:, None]
        cos_a, sin_a = np.cos(alpha)[:, None], np.sin(alpha)[:, None]
        forward = cos_a * dx + sin_a * dy
        lateral = -sin_a * dx + cos_a * dy
        seen = forward > 0
        projection = np.where(seen, -lateral / np.where(seen, forward, 1.0), 0.0)
        weight = np.where(seen, 1.0 / np.sqrt(dx * dx + dy * dy), 0.0)
        offsets = CELLS[None, None, :] - projection[:, :, None]  # (B, L, K)
        return (np.exp(-offsets**2) * weight[:, :, None]).sum(axis=1)

    return sense


def numpy_arm(lights: np.ndarray) -> smspace.PythonAgent:
    """The arm as a PythonAgent: 4 hinges, 6 sensors, and its pose as ground truth."""
    return smspace.PythonAgent(
        sense=make_sense(lights), n_motors=4, n_sensors=6, pose=pose, name="numpy-arm"
    )


if __name__ == "__main__":
    builtin = smspace.Agent.preset("planar-arm")
    lights = builtin.lights(1)  # the built-in arm's default environment (seed 1)
    agent = numpy_arm(lights)
    found = smspace.explore(builtin, n=200, seed=1)
    ours = smspace.trace(agent, found.motors, method="sensory")
    theirs = smspace.trace(builtin, found.motors, method="sensory", env=1)
    same_rows = np.array_equal(ours.kept, theirs.kept)
    gap = np.abs(ours.sets - theirs.sets).max() if same_rows else float("nan")
    print(f"traced {len(ours)} and {len(theirs)} sets; same rows kept: {same_rows}; "
          f"largest difference between the kernel sets: {gap:.2e} rad")
    D = smspace.distances(ours)
    print("Betti numbers of the NumPy arm's sets:", smspace.analyze(D, poses=found.poses[ours.kept])["betti"])
