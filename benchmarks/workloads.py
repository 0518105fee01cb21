"""Benchmark workloads: (a) the comparison workload, (b) the full FINken workload.

(a) **Comparison workload** — the scene the peers (VMAS, a plain NumPy version) can also run:
N copters (radius 0.15 m) in a 3 m × 4 m box with 4 straight walls; every step each copter casts
4 sonar rays (0°, 90°, 180°, 270° from its heading, first hit on a wall segment or another copter's
circle, clamped to 3 m), the pairwise centre distances (N × N) are computed, and a reactive
controller turns that into a kinematic update (no noise):

    ω = k_turn·(s_left − s_right) + swirl
    v = v_max · clip((s_front − stop)/slow, 0.1, 1) · clip(d_nearest/sep, 0.2, 1)
    ψ ← wrap(ψ + ω dt);  p ← clip(p + v (cos ψ, sin ψ) dt, [r, W − r] × [r, L − r])

The observations of the last step are left in ``sonar`` (B, N, 4) and ``dist`` (B, N, N), as an
environment would return them. Two implementations that agree to rounding
(``tests/test_bench_quick.py`` checks): :func:`compare_rollout` (numba: one compiled loop over T
steps, ``prange`` over environments, using ``finkensim.kernels.geometry.ray_segment / ray_circle``)
and :func:`numpy_rollout` (plain vectorised NumPy over B, N and the rays, one Python iteration per
step). VMAS runs the same scene in ``benchmarks/peers/vmas_scenario.py``.

(b) **Full FINken workload** — 16-plate bending walls, sonars with the Rayleigh error model and
geometric cross-talk, 2.5 m virtual ranging with the K = 100 mixture, the inertial sensor and the
attraction–repulsion behaviour: :class:`FinkenWorkload` uses ``finkensim.swarm`` (compiled closed
loop) when it is importable, and otherwise the stand-in :class:`FinkenStandIn`: ``World.rollout``
(random-walk controller, per-step) followed by the batched sensors over the recorded trajectory
(ultrasonic, ranging, IMU) — the same sensing work per step, but open loop and without the
behaviour's own cost.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from finkensim.kernels.geometry import ray_circle, ray_segment


class CompareParams(NamedTuple):
    """Constants of the comparison workload (SI units)."""

    width: float = 3.0
    length: float = 4.0
    radius: float = 0.15
    max_range: float = 3.0
    dt: float = 0.05
    v_max: float = 0.5
    k_turn: float = 1.0
    swirl: float = 0.3
    stop: float = 0.3
    slow: float = 1.0
    sep: float = 0.5


def box_walls(width: float, length: float):
    """The 4 straight walls of the box as segments: (wa (4, 2), wb (4, 2)) m."""
    c = np.array([[0.0, 0.0], [width, 0.0], [width, length], [0.0, length]])
    return np.ascontiguousarray(c), np.ascontiguousarray(np.roll(c, -1, axis=0))


def compare_init(n: int, b: int, p: CompareParams = CompareParams(), seed: int = 0):
    """Initial state: pos (B, N, 2) uniform in the box (no overlap check), yaw (B, N) uniform."""
    rng = np.random.default_rng(seed)
    pos = np.empty((b, n, 2))
    pos[..., 0] = rng.uniform(p.radius, p.width - p.radius, (b, n))
    pos[..., 1] = rng.uniform(p.radius, p.length - p.radius, (b, n))
    yaw = rng.uniform(-np.pi, np.pi, (b, n))
    return pos, yaw


def compare_buffers(n: int, b: int):
    """Observation buffers: sonar (B, N, 4) m, dist (B, N, N) m."""
    return np.zeros((b, n, 4)), np.zeros((b, n, n))


# ---------------------------------------------------------------------------------------------
# (a) numba


@njit(cache=True, inline="always")
def _clip(x, lo, hi):
    return min(hi, max(lo, x))


@njit(cache=True, inline="always")
def compare_step_env(pos, yaw, wa, wb, p, sonar, dist):
    """One step of one environment, in place: sense (4 rays, pairwise distances), decide, move."""
    N = pos.shape[0]
    for i in range(N):
        c = np.cos(yaw[i])
        s = np.sin(yaw[i])
        ox = pos[i, 0]
        oy = pos[i, 1]
        for k in range(4):
            # headings 0°, 90°, 180°, 270°: the unit vector rotated by k quarter turns (exact)
            if k == 0:
                dx, dy = c, s
            elif k == 1:
                dx, dy = -s, c
            elif k == 2:
                dx, dy = -c, -s
            else:
                dx, dy = s, -c
            best = p.max_range
            for w in range(wa.shape[0]):
                t = ray_segment(ox, oy, dx, dy, wa[w, 0], wa[w, 1], wb[w, 0], wb[w, 1], False)
                if t < best:
                    best = t
            for j in range(N):
                if j != i:
                    t = ray_circle(ox, oy, dx, dy, pos[j, 0], pos[j, 1], p.radius, False)
                    if t < best:
                        best = t
            sonar[i, k] = best
    for i in range(N):
        dist[i, i] = 0.0
        for j in range(i + 1, N):
            ddx = pos[i, 0] - pos[j, 0]
            ddy = pos[i, 1] - pos[j, 1]
            d = np.sqrt(ddx * ddx + ddy * ddy)
            dist[i, j] = d
            dist[j, i] = d
    for i in range(N):
        nearest = np.inf
        for j in range(N):
            if j != i and dist[i, j] < nearest:
                nearest = dist[i, j]
        w = p.k_turn * (sonar[i, 1] - sonar[i, 3]) + p.swirl
        v = p.v_max * _clip((sonar[i, 0] - p.stop) / p.slow, 0.1, 1.0) * _clip(nearest / p.sep, 0.2, 1.0)
        a = (yaw[i] + w * p.dt + np.pi) % (2.0 * np.pi) - np.pi
        yaw[i] = a
        pos[i, 0] = _clip(pos[i, 0] + v * np.cos(a) * p.dt, p.radius, p.width - p.radius)
        pos[i, 1] = _clip(pos[i, 1] + v * np.sin(a) * p.dt, p.radius, p.length - p.radius)


@njit(cache=True, parallel=True)
def compare_rollout(pos, yaw, wa, wb, p, n_steps, sonar, dist):
    """``n_steps`` steps of B environments (pos (B, N, 2), yaw (B, N) updated in place)."""
    for b in prange(pos.shape[0]):
        for _ in range(n_steps):
            compare_step_env(pos[b], yaw[b], wa, wb, p, sonar[b], dist[b])


# ---------------------------------------------------------------------------------------------
# (a) plain vectorised NumPy


def numpy_step(pos, yaw, wa, wb, p: CompareParams, sonar, dist):
    """One step of B environments, vectorised over (B, N, rays, walls/copters); same rule as the kernel."""
    B, N, _ = pos.shape
    c = np.cos(yaw)
    s = np.sin(yaw)
    dirs = np.stack([np.stack([c, s], -1), np.stack([-s, c], -1), np.stack([-c, -s], -1), np.stack([s, -c], -1)],
                    axis=2)  # (B, N, 4, 2)
    dx = dirs[..., 0][..., None]  # (B, N, 4, 1)
    dy = dirs[..., 1][..., None]
    ox = pos[..., 0][:, :, None, None]
    oy = pos[..., 1][:, :, None, None]
    # walls: ray–segment by Cramer's rule, (B, N, 4, W)
    ex = wb[:, 0] - wa[:, 0]
    ey = wb[:, 1] - wa[:, 1]
    wx = wa[:, 0] - ox
    wy = wa[:, 1] - oy
    with np.errstate(divide="ignore", invalid="ignore"):
        den = dx * ey - dy * ex
        t = (wx * ey - wy * ex) / den
        sg = (wx * dy - wy * dx) / den
    hit = (den != 0.0) & (t >= 0.0) & (sg >= 0.0) & (sg <= 1.0)
    best = np.minimum(np.where(hit, t, np.inf).min(-1), p.max_range)  # (B, N, 4)
    # copters: ray–circle per ray direction, (B, N, N) each (origin i, circle j)
    fx = pos[:, :, None, 0] - pos[:, None, :, 0]
    fy = pos[:, :, None, 1] - pos[:, None, :, 1]
    cc = fx * fx + fy * fy - p.radius * p.radius
    eye = np.eye(N, dtype=bool)
    for k in range(4):
        bb = fx * dirs[:, :, k, 0][..., None] + fy * dirs[:, :, k, 1][..., None]
        disc = bb * bb - cc
        with np.errstate(invalid="ignore"):
            sq = np.sqrt(disc)
        t1 = -bb - sq
        t2 = -bb + sq
        tc = np.where(t1 >= 0.0, t1, np.where(t2 >= 0.0, t2, np.inf))
        tc[(disc < 0.0) | eye] = np.inf
        best[:, :, k] = np.minimum(best[:, :, k], tc.min(-1))
    sonar[...] = best
    dist[...] = np.sqrt(fx * fx + fy * fy)
    nearest = np.where(eye, np.inf, dist).min(-1) if N > 1 else np.full((B, N), np.inf)
    w = p.k_turn * (best[..., 1] - best[..., 3]) + p.swirl
    v = p.v_max * np.clip((best[..., 0] - p.stop) / p.slow, 0.1, 1.0) * np.clip(nearest / p.sep, 0.2, 1.0)
    a = np.mod(yaw + w * p.dt + np.pi, 2.0 * np.pi) - np.pi
    yaw[...] = a
    pos[..., 0] = np.clip(pos[..., 0] + v * np.cos(a) * p.dt, p.radius, p.width - p.radius)
    pos[..., 1] = np.clip(pos[..., 1] + v * np.sin(a) * p.dt, p.radius, p.length - p.radius)


def numpy_rollout(pos, yaw, wa, wb, p: CompareParams, n_steps, sonar, dist):
    for _ in range(n_steps):
        numpy_step(pos, yaw, wa, wb, p, sonar, dist)


class CompareWorkload:
    """Workload (a) for one (N, B) and implementation ``impl`` ∈ {"finkensim", "numpy"}.

    ``run(T)`` advances T steps; all state and observation arrays are allocated in ``__init__``
    (from Python, so tracemalloc sees them).
    """

    def __init__(self, n: int, b: int, impl: str = "finkensim", seed: int = 0):
        self.p = CompareParams()
        self.n, self.b, self.impl = n, b, impl
        self.wa, self.wb = box_walls(self.p.width, self.p.length)
        self.pos, self.yaw = compare_init(n, b, self.p, seed)
        self.sonar, self.dist = compare_buffers(n, b)
        if impl not in ("finkensim", "numpy"):
            raise ValueError(f"impl = {impl!r}: expected 'finkensim' or 'numpy'")

    def run(self, n_steps: int) -> None:
        if self.impl == "finkensim":
            compare_rollout(self.pos, self.yaw, self.wa, self.wb, self.p, int(n_steps), self.sonar, self.dist)
        else:
            numpy_rollout(self.pos, self.yaw, self.wa, self.wb, self.p, int(n_steps), self.sonar, self.dist)


# ---------------------------------------------------------------------------------------------
# (b) full FINken workload


def finken_config(n: int, b: int, width: float = 3.0, length: float = 4.0, simulation: dict | None = None):
    """The full FINken configuration for N copters and B environments in a width × length m arena (defaults
    otherwise: 16 plates per wall, bending, Rayleigh sonar with geometric cross-talk, 2.5 m mixture ranging, IMU
    on, attraction–repulsion behaviour); ``simulation``: more [simulation] keys. The start separation shrinks with N
    so crowded boxes place fast."""
    from finkensim.config import load_config

    area = width * length
    sep = min(0.5, 0.6 * math.sqrt(area / max(n, 1)))
    return load_config({
        "arena": {"width": float(width), "length": float(length)},
        "copters": {"n": int(n), "min_separation": float(sep)},
        "simulation": {"n_envs": int(b), "seed": 1, **(simulation or {})},
        "walls": {"n_segments": 16, "bending": True},
        "behaviour": {"kind": "attraction_repulsion"},
        "sonar": {"enabled": True, "error": "rayleigh", "crosstalk": "geometric"},
        "ranging": {"enabled": True, "error": "mixture", "max_range": 2.5},
        "imu": {"enabled": True},
    })


def swarm_status() -> str | None:
    """None if ``finkensim.swarm`` is importable, else why not ("finkensim.swarm missing" or the error)."""
    try:
        import finkensim.swarm  # noqa: F401
    except ModuleNotFoundError as e:
        if e.name in ("finkensim.swarm",):
            return "finkensim.swarm missing"
        return f"finkensim.swarm import failed: {e}"
    except Exception as e:  # noqa: BLE001 - reported in the table, not raised
        return f"finkensim.swarm import failed: {type(e).__name__}: {e}"
    return None


class FinkenSwarm:
    """Workload (b) through ``finkensim.swarm`` (the compiled closed-loop rollout):
    ``SwarmSim(cfg).init(n_envs, seed)`` then ``rollout(state, n_steps, record=False)`` (only the
    per-episode counters are kept, so the run measures the step, not the recording)."""

    def __init__(self, n: int, b: int):
        import warnings

        import finkensim.swarm as sw

        cls = getattr(sw, "SwarmSim", None) or getattr(sw, "Swarm", None)
        if cls is None:
            public = [k for k in dir(sw) if not k.startswith("_")]
            raise RuntimeError(f"finkensim.swarm has no SwarmSim class (found: {public})")
        self.cfg = finken_config(n, b)
        self.n, self.b = n, b
        self.sim = cls(self.cfg)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            self.state = self.sim.init(n_envs=b, seed=1)

    def run(self, n_steps: int) -> None:
        out = self.sim.rollout(self.state, int(n_steps), record=False)
        self.state = out[0] if isinstance(out, tuple) else out


class FinkenStandIn:
    """Stand-in for workload (b) while ``finkensim.swarm`` is missing: the world rollout
    (bending walls, random-walk controller) for T steps, then the batched sensors over the recorded
    trajectory — ultrasonic (Rayleigh + geometric cross-talk) and IMU in one call each over all T × B
    states, ranging (mixture, 2.5 m) once per recorded step. Open loop: the sensor readings do not
    feed back into the commands, and the attraction–repulsion controller's own cost is missing."""

    def __init__(self, n: int, b: int):
        from finkensim.sensors.imu import ImuModel
        from finkensim.sensors.ranging import RangingModel
        from finkensim.sensors.sonar import SonarModel
        from finkensim.world import World

        self.cfg = finken_config(n, b)
        self.world = World(self.cfg)
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            self.state = self.world.init(n_envs=b, seed=1)
        self.sonar = SonarModel.from_config(self.cfg)
        self.ranging = RangingModel.from_config(self.cfg.ranging)
        self.imu = ImuModel.from_config(self.cfg.imu, self.world.dt)
        self.n, self.b = n, b
        self._imu_bias = np.zeros((b, n, 3))

    def run(self, n_steps: int) -> None:
        from finkensim.sensors.imu import imu_from_trajectory
        from finkensim.sensors.ranging import ranging_readings
        from finkensim.sensors.sonar import sonar_from_trajectory

        s0 = self.state
        from finkensim.behaviours.open_loop import RandomWalk

        self.state, traj = self.world.rollout(s0, int(n_steps), controller=RandomWalk(self.cfg), record=True)
        sonar_from_trajectory(traj, self.world.arena, self.sonar, s0.seed, s0.env_ids, s0.step)
        out = None
        for t in range(int(n_steps)):
            out = ranging_readings(traj.pose[t, :, :, :2], self.ranging.beacons, s0.seed, s0.env_ids, s0.step + t,
                                   self.ranging, out=out)
        imu_from_trajectory(traj, self.imu, s0.seed, s0.env_ids, s0.step, bias=self._imu_bias)


def finken_workload(n: int, b: int):
    """(workload object, label): ``finkensim.swarm`` when importable, else the stand-in."""
    if swarm_status() is None:
        return FinkenSwarm(n, b), "finkensim.swarm"
    return FinkenStandIn(n, b), "stand-in: World.rollout + batched sensors"
