"""Edge cases the random scenes of the other property tests never draw (issue 16): one copter, coincident and
overlapping bodies, rays parallel to and grazing a wall, an empty swarm, one-sample logs. Each must give the exact
answer where one exists (closed forms below), else finite numbers in range or a named error — never NaN where a
distance is expected, never a numba traceback."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from finkensim.arena import Arena
from finkensim.config import Config, ConfigError
from finkensim.sensors.ranging import RangingModel, ideal_ranges, ranging_readings
from finkensim.sensors.sonar_model import SonarModel
from finkensim.sensors.sonar import ideal_sonar
from finkensim.testing import strategies as fst

W, L = 3.0, 4.0


def rigid(n=1):
    cfg = Config().replace({"copters.n": n, "walls.bending": False})
    return cfg, Arena.from_config(cfg.arena, cfg.walls), SonarModel.from_config(cfg)


@settings(max_examples=60, deadline=None)
@given(st.floats(0.3, W - 0.3), st.floats(0.3, L - 0.3), st.sampled_from([0.0, math.pi / 2, math.pi, -math.pi / 2]))
@example(x=0.3125, y=0.9999999999999994, heading=0.0)  # a wall 1e-15 m inside the range limit (CI, 2026-11-28)
def test_one_copter_axis_aligned_reads_the_wall_distances(x, y, heading):
    """A lone copter facing along an axis: each sonar reads its distance to the wall it faces, minus the sonar
    offset (closed form; front, left, back, right turn with the heading)."""
    cfg, arena, sp = rigid()
    dist, kind, _ = ideal_sonar(np.array([[[x, y]]]), np.array([[heading]]), np.zeros((1, arena.n_plates)),
                                     arena, sp)
    walls = {0.0: W - x, math.pi / 2: L - y, math.pi: x, -math.pi / 2: y}  # distance along each world direction
    for k, mount in enumerate((0.0, math.pi / 2, math.pi, -math.pi / 2)):
        direction = math.remainder(heading + mount, 2 * math.pi)
        direction = -math.pi / 2 if math.isclose(direction, 3 * math.pi / 2) else direction
        key = min(walls, key=lambda a: abs(math.remainder(a - direction, 2 * math.pi)))
        want = min(walls[key] - sp.offset, sp.max_range)
        assert dist[0, 0, k] == pytest.approx(want, abs=1e-9)
        if abs(walls[key] - sp.offset - sp.max_range) > 1e-9:  # at the range limit itself hit or miss is a rounding tie
            assert kind[0, 0, k] == (1 if walls[key] - sp.offset <= sp.max_range else 0)


@settings(max_examples=40, deadline=None)
@given(st.floats(0.0, 1e-6), st.floats(0.5, 2.5))
def test_ray_parallel_to_and_grazing_a_wall(eps, x):
    """A copter whose body touches the south wall, heading along it (+x): the front ray runs parallel to the
    wall at the body's half-width and must hit the east wall, not the wall it grazes."""
    cfg, arena, sp = rigid()
    r = cfg.copters.radius
    dist, kind, _ = ideal_sonar(np.array([[[x, r + eps]]]), np.array([[0.0]]), np.zeros((1, arena.n_plates)),
                                     arena, sp)
    assert dist[0, 0, 0] == pytest.approx(min(W - x - sp.offset, sp.max_range), abs=1e-9)
    assert dist[0, 0, 3] == pytest.approx(r + eps - sp.offset, abs=1e-9)  # right sonar: the grazed wall itself


@settings(max_examples=40, deadline=None)
@given(st.floats(0.3, W - 0.3), st.floats(0.3, L - 0.3), st.floats(0.0, 0.2), st.floats(-math.pi, math.pi))
def test_coincident_and_overlapping_bodies_give_finite_readings(x, y, gap, yaw):
    """Two copters 0 … 0.2 m apart (bodies of 0.15 m overlap or coincide): every sonar and ranging value is a
    finite number within [0, max_range]; the ranging truth is their centre distance."""
    cfg, arena, sp = rigid(2)
    pos = np.array([[[x, y], [min(x + gap, W - 0.3), y]]])
    dist, kind, _ = ideal_sonar(pos, np.array([[yaw, -yaw]]), np.zeros((1, arena.n_plates)), arena, sp)
    assert np.all(np.isfinite(dist)) and np.all((dist >= 0) & (dist <= sp.max_range))
    true = ideal_ranges(pos, np.zeros((0, 2)), 2.5)
    assert true[0, 0, 1] == pytest.approx(pos[0, 1, 0] - pos[0, 0, 0], abs=1e-12)
    out = ranging_readings(pos, np.zeros((0, 2)), 1, np.array([0]), 0, RangingModel("mixture"))
    assert np.all(np.isfinite(out)) and np.all(out >= 0) and np.all(np.diag(out[0]) == 0)


def test_one_copter_ranging_is_its_zero_diagonal():
    out = ranging_readings(np.array([[[1.0, 1.0]]]), np.zeros((0, 2)), 0, np.array([0]), 0, RangingModel("mixture"))
    assert out.shape == (1, 1, 1) and out[0, 0, 0] == 0.0


def test_an_empty_swarm_is_a_named_config_error():
    with pytest.raises(ConfigError, match="copters.n"):
        Config().replace({"copters.n": 0})


def test_one_copter_world_and_swarm_run():
    import finkensim as fs

    cfg = fs.load_config({"copters": {"n": 1}})
    final, rec = fs.SwarmSim(cfg).rollout(fs.SwarmSim(cfg).init(n_envs=2, seed=0), n_steps=50)
    assert np.all(np.isfinite(rec.pose)) and rec.pose.shape == (50, 2, 1, 3)
    assert np.all((rec.pose[..., 0] >= 0) & (rec.pose[..., 0] <= W) & (rec.pose[..., 1] >= 0) & (rec.pose[..., 1] <= L))


def test_one_sample_log_saves_and_the_diagnosis_names_the_problem(tmp_path):
    import finkensim as fs
    from finkensim.flightlog import FlightLog, load, save
    from finkensim.gap.model.replay import GapInputError

    log = FlightLog(t=np.array([0.0]), arena=np.array([W, L]), pose=np.array([[[1.0, 1.0, 0.0]]]),
                    copter_ids=np.array(["a"]))
    save(log, tmp_path / "one.npz")
    assert load(tmp_path / "one.npz") == log
    with pytest.raises(GapInputError, match="1 sample; expected at least 5"):
        fs.diagnose([log], ["one"], Config())


def _exact_sonar(pos, yaw, mount, offset, radius, max_range):
    """Independent closed form (no finkensim geometry): distance from each sonar (origin offset along its direction)
    to the first rigid wall of the W x L rectangle or other copter's circle; max_range when beyond it. (N, S)."""
    N, S = pos.shape[0], mount.size
    out = np.empty((N, S))
    for n in range(N):
        for k in range(S):
            a = yaw[n] + mount[k]
            ux, uy = math.cos(a), math.sin(a)
            ox, oy = pos[n, 0] + offset * ux, pos[n, 1] + offset * uy
            ts = []
            if ux > 0:
                ts.append((W - ox) / ux)
            if ux < 0:
                ts.append(-ox / ux)
            if uy > 0:
                ts.append((L - oy) / uy)
            if uy < 0:
                ts.append(-oy / uy)
            for m in range(N):
                if m == n:
                    continue
                fx, fy = ox - pos[m, 0], oy - pos[m, 1]
                b = fx * ux + fy * uy
                c = fx * fx + fy * fy - radius * radius
                disc = b * b - c
                if disc >= 0 and c > 0:  # origin outside the circle: nearest intersection ahead
                    t = -b - math.sqrt(disc)
                    if t > 0:
                        ts.append(t)
            t = min(ts)
            out[n, k] = t if t <= max_range else max_range
    return out


@settings(max_examples=40, deadline=None)
@given(st.integers(1, 4), st.data())
def test_ideal_sonar_equals_an_independent_closed_form(n, data):
    """Random copters (bodies 1 mm apart or more: the public world-state strategy), random headings, rigid walls:
    the ray cast equals the closed form above, except rays that pass within 1 µm of a tangent or a corner (where
    either answer is right to rounding)."""
    cfg, arena, sp = rigid(n)
    r = cfg.copters.radius
    state = data.draw(fst.world_states(cfg, n_envs=1, separated=True, clearance=1e-3, moving=False, plates=False))
    pos, yaw = state.pos[0], state.yaw[0]
    dist, _, _ = ideal_sonar(pos[None], yaw[None], np.zeros((1, arena.n_plates)), arena, sp)
    want = _exact_sonar(pos, yaw, np.asarray(sp.mount_yaw), sp.offset, r, sp.max_range)
    close = np.isclose(dist[0], want, atol=1e-9)
    for nn, k in zip(*np.nonzero(~close)):  # a mismatch is only allowed on a tangent ray (grazing a body)
        a = yaw[nn] + sp.mount_yaw[k]
        o = pos[nn] + sp.offset * np.array([math.cos(a), math.sin(a)])
        u = np.array([math.cos(a), math.sin(a)])
        grazing = any(abs(abs((pos[m] - o) @ np.array([-u[1], u[0]])) - r) < 1e-6 for m in range(n) if m != nn)
        assert grazing, (nn, k, dist[0, nn, k], want[nn, k])
